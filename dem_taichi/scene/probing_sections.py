"""Scene section of the elastic probes: ``[probing]`` (docs/science/dem-model.md §1.6, step 4).

A frozen dataclass validated by :class:`dem_taichi.scene.base.SceneSection` (type, range,
choices; the message names the key and what is allowed); the scene loader
(:mod:`dem_taichi.scene.config`) knows it, so a scene carrying it loads from anywhere. The loaded
instance is ``scene.extensions["probing"]``; :func:`probing_settings` returns it, or the defaults
when a scene has no such section. The loading paths the probes run on are the ``[protocol]``
section (:mod:`dem_taichi.scene.protocol_sections`).

Units: DEM units (d = 1, disc mass = 1); strains logarithmic, compression positive. Every
field's unit and a one-line description are in its ``metadata`` (``unit=``, ``doc=``), from which
the documentation's scene reference is generated.

Symbols: UFR unbalanced-force ratio (definitions: dem_taichi.io.schema).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from dem_taichi.scene.base import SceneError, SceneSection
from dem_taichi.scene.base import field_choices as _choices
from dem_taichi.scene.base import field_doc as _doc
from dem_taichi.scene.base import field_list as _list
from dem_taichi.scene.base import field_range as _range

__all__ = ["ProbingConfig", "probing_settings"]


@dataclass(frozen=True)
class ProbingConfig(SceneSection):
    """``[probing]``: elastic probes at states of every path (docs/science/dem-model.md §1.6,
    step 4).

    Fields (defaults in brackets):

    - ``enabled`` [true]: probe at all.
    - ``states`` ["A, B, C, B'"]: labelled states probed (any of A, B, C, B', R<k>_end for the
      k-th radial path); "" = none.
    - ``every_n_increments`` [2]: also probe every n-th relaxed increment of each path (0 = only
      the labelled states).
    - ``dynamic`` [true]: run the dynamic strain probes (amplitude sweep).
    - ``dynamic_states`` ["all"]: where the dynamic sweep runs: "all" probed states, or a
      comma-separated list of probe labels (A, B, C, B', R<k>_end, or <path>_<increment> such
      as A_to_C_4 for an unlabelled increment); the linear-response probe runs at every probed
      state. On large scenes (``paper``) the sweep costs ~3000× the linear response, so it is
      kept at one state as the check of the linear response there.
    - ``amplitude_min`` [1e-9], ``amplitude_max`` [1e-3], ``amplitudes_per_decade`` [1]:
      the log-spaced strain amplitudes of the sweep (docs/science/dem-model.md §1.6:
      ≈1e-7…1e-3). The sweep starts at
      1e-9 because a state reached by monotonic loading sits on its yield surface: measured on
      the smoke scene at the end of K0 loading, the continued-loading branch (+Δε_yy) is
      already plastic at 1e-7 (secant 22e3 against 40e3 on reversal), the ± average agrees
      with the linear response only at 1e-8 and below.
    - ``apply_steps`` [200]: fewest steps over which a probe strain is applied (more when the
      inertial-number cap needs it).
    - ``relax_unbalanced_force`` [1e-7]: UFR at which a probe is relaxed (stricter than the path:
      a probe of 1e-6 changes σ by ~1e-4 relative).
    - ``linear_relax_unbalanced_force`` [unset = ``relax_unbalanced_force``]: UFR to which the
      copy of a state is relaxed before a probe that runs the linear response alone (no
      dynamic sweep at that state). The linear response is the network's Hessian at the state:
      it does not need the strict relaxation of the ± strain sweep. Measured on the 12
      labelled states of three 1520-rod runs (``benchmarks/results/probe_relaxation_P8.md``):
      1e-5 instead of 1e-7 changes E_oed,v and E_oed,h by at most 3.5e-5 relative and
      E_h/E_v by at most 4.6e-5, in 37 % of the relaxation steps.
    - ``relax_max_steps`` [60000]: most relaxation steps of one probe.
    - ``plateau_tolerance`` [0.02]: relative tolerance of the elastic-plateau rule
      (:func:`dem_taichi.analysis.arrays.elastic_plateau`).
    - ``linear`` [true]: run the linear-response probe.
    - ``sliding_contacts`` ["stuck"]: how contacts at the Coulomb cap respond in the
      linear-response probe ("stuck": spring k_t, the small-amplitude reversal branch that a
      ± probe mostly sees; "free": stay on the cap).
    """

    SECTION = "probing"
    enabled: bool = field(default=True, metadata=_doc("probe at all", "-"))
    states: str = field(
        default="A, B, C, B'",
        metadata=_list(doc='labelled states probed (A, B, C, B\', R<k>_end); "" = none', unit="-"),
    )
    every_n_increments: int = field(
        default=2,
        metadata=_range(
            0,
            doc=(
                "also probe every n-th relaxed increment of each path (0: only the labelled states)"
            ),
            unit="1",
        ),
    )
    dynamic: bool = field(
        default=True, metadata=_doc("run the dynamic strain probes (amplitude sweep)", "-")
    )
    dynamic_states: str = field(
        default="all",
        metadata=_list(
            doc=('where the dynamic sweep runs: "all" probed states, or a list of probe labels'),
            unit="-",
        ),
    )
    amplitude_min: float = field(
        default=1e-9,
        metadata=_range(
            0.0, 0.1, lo_open=True, doc="smallest strain amplitude of the dynamic sweep", unit="1"
        ),
    )
    amplitude_max: float = field(
        default=1e-3,
        metadata=_range(
            0.0, 0.1, lo_open=True, doc="largest strain amplitude of the dynamic sweep", unit="1"
        ),
    )
    amplitudes_per_decade: int = field(
        default=1,
        metadata=_range(1, 20, doc="log-spaced amplitudes per decade of the sweep", unit="1"),
    )
    apply_steps: int = field(
        default=200,
        metadata=_range(1, doc="fewest steps over which a probe strain is applied", unit="steps"),
    )
    relax_unbalanced_force: float = field(
        default=1e-7,
        metadata=_range(
            0.0,
            1.0,
            lo_open=True,
            doc="unbalanced-force ratio at which a probe is relaxed",
            unit="1",
        ),
    )
    linear_relax_unbalanced_force: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                1.0,
                lo_open=True,
                doc=(
                    "unbalanced-force ratio to which a state is relaxed before a probe by the "
                    "linear response alone (unset: relax_unbalanced_force)"
                ),
                unit="1",
            ),
            "optional": True,
        },
    )
    relax_max_steps: int = field(
        default=60_000, metadata=_range(1, doc="most relaxation steps of one probe", unit="steps")
    )
    plateau_tolerance: float = field(
        default=0.02,
        metadata=_range(
            0.0, 1.0, lo_open=True, doc="relative tolerance of the elastic-plateau rule", unit="1"
        ),
    )
    linear: bool = field(default=True, metadata=_doc("run the linear-response probe", "-"))
    sliding_contacts: str = field(
        default="stuck",
        metadata=_choices(
            "stuck",
            "free",
            doc=(
                "contacts at the Coulomb cap in the linear response: 'stuck' spring "
                "k_t, 'free' stay on the cap"
            ),
        ),
    )

    def check(self) -> None:
        if self.amplitude_min > self.amplitude_max:
            raise SceneError(
                f"[probing] amplitude_min = {self.amplitude_min} > amplitude_max = "
                f"{self.amplitude_max}: allowed (0, amplitude_max]"
            )

    @property
    def state_labels(self) -> tuple[str, ...]:
        """Labels of ``states``, parsed (comma-separated, blanks stripped)."""
        return tuple(s.strip() for s in self.states.split(",") if s.strip())

    @property
    def linear_only_relax_unbalanced_force(self) -> float:
        """The UFR of the relaxation before a probe by the linear response alone:
        ``linear_relax_unbalanced_force`` when set, else ``relax_unbalanced_force``."""
        if self.linear_relax_unbalanced_force is None:
            return self.relax_unbalanced_force
        return self.linear_relax_unbalanced_force

    def base_relax_unbalanced_force(self, label: str) -> float:
        """The UFR to which the copy of the state labelled ``label`` is relaxed before it is
        probed: ``relax_unbalanced_force`` where the dynamic sweep runs, else
        :attr:`linear_only_relax_unbalanced_force`."""
        if self.runs_dynamic(label):
            return self.relax_unbalanced_force
        return self.linear_only_relax_unbalanced_force

    def runs_dynamic(self, label: str) -> bool:
        """Whether the dynamic sweep runs at the probe labelled ``label``."""
        if not self.dynamic:
            return False
        if self.dynamic_states.strip() == "all":
            return True
        return label in {s.strip() for s in self.dynamic_states.split(",") if s.strip()}

    @property
    def amplitudes(self) -> tuple[float, ...]:
        """Log-spaced amplitudes from ``amplitude_min`` to ``amplitude_max`` (both included)."""
        lo, hi = math.log10(self.amplitude_min), math.log10(self.amplitude_max)
        n = max(int(round((hi - lo) * self.amplitudes_per_decade)), 0) + 1
        if n == 1:
            return (self.amplitude_min,)
        return tuple(10 ** (lo + (hi - lo) * k / (n - 1)) for k in range(n))


def probing_settings(scene) -> ProbingConfig:
    """The scene's ``[probing]`` section, or the defaults when it has none."""
    return scene.extensions.get("probing", ProbingConfig())
