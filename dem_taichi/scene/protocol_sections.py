"""Scene section of the virtual experiments' loading paths: ``[protocol]``
(docs/science/dem-model.md §1.6).

A frozen dataclass validated by :class:`dem_taichi.scene.base.SceneSection` (type, range,
choices; the message names the key and what is allowed); the scene loader
(:mod:`dem_taichi.scene.config`) knows it, so a scene carrying it loads from anywhere. The loaded
instance is ``scene.extensions["protocol"]``; :func:`protocol_settings` returns it, or the
defaults when a scene has no such section. The ``[probing]`` section is in
:mod:`dem_taichi.scene.probing_sections`; its names (:class:`ProbingConfig`,
:func:`probing_settings`) are also importable from here, where they were defined up to issue 21.

Units: DEM units (d = 1, disc mass = 1); stresses in force/length, compression positive; strains
logarithmic, compression positive. Every field's unit and a one-line description are in its
``metadata`` (``unit=``, ``doc=``), from which the documentation's scene reference is generated.
``stress_scale_kpa`` states what one DEM stress unit means in kPa (a reading of the results, not
an input of the physics).

Symbols: p = (σ_xx + σ_yy)/2, q = σ_yy − σ_xx, η = q/p, Z_m mechanical coordination number,
I inertial number, UFR unbalanced-force ratio (definitions: dem_taichi.io.schema).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from dem_taichi.scene.aggregation_keys import AGGREGATION_KEYS, check_aggregation_keys
from dem_taichi.scene.base import SceneError, SceneSection
from dem_taichi.scene.base import field_doc as _doc
from dem_taichi.scene.base import field_list as _list
from dem_taichi.scene.base import field_range as _range

# the [probing] section's names, defined here up to issue 21: every import of them keeps working
from dem_taichi.scene.probing_sections import ProbingConfig as ProbingConfig
from dem_taichi.scene.probing_sections import probing_settings as probing_settings
from dem_taichi.scene.servo_keys import SERVO_KEYS
from dem_taichi.scene.stability import check_time_step_factor
from dem_taichi.scene.transition_keys import TRANSITION_KEYS

__all__ = ["ProtocolConfig", "protocol_settings", "parse_number_list"]


def parse_number_list(text: str, key: str) -> tuple[float, ...]:
    """Parse a comma-separated list of numbers (``"0.5, 1.0"``; ``""`` → empty).

    Lists are written as strings so that every scene round-trips through ``scene_to_toml``.
    """
    if not text.strip():
        return ()
    values = []
    for item in text.split(","):
        try:
            value = float(item)
        except ValueError:
            raise SceneError(
                f'{key} = {text!r}: must be a comma-separated list of numbers, e.g. "0.5, 1.0"'
            ) from None
        if not math.isfinite(value):
            raise SceneError(f"{key} = {text!r}: {item.strip()!r} is not finite")
        values.append(value)
    return tuple(values)


@dataclass(frozen=True)
class ProtocolConfig(SceneSection):
    """``[protocol]``: the loading paths of the study (docs/science/dem-model.md §1.6,
    steps 1–3).

    Stages: gas → isotropic strain-controlled compression in increments, each relaxed, until the
    fluid–solid transition (state A) → A→B isotropic (σ_xx = σ_yy servo) up to
    ``target_mean_stress`` (state B) → A→C K0 (ε_xx = 0, σ_yy servo) until p reaches
    ``target_mean_stress`` (state C) → C→B at constant p, q → 0 (state B') → radial paths from A
    at each η of ``radial_stress_ratios`` up to ``target_mean_stress``.

    Fields (defaults in brackets):

    - ``stress_scale_kpa`` [1.0]: kPa per DEM stress unit (force/length), stated in the results.
    - ``target_mean_stress`` [100.0]: p at B and C and at the ends of the radial paths (DEM units).
    - ``path_increments`` [6]: relaxed stress increments (log-spaced in p) along A→B, A→C, radial.
    - ``unloading_increments`` [4]: relaxed increments of q (linear to 0) along C→B.
    - ``radial_stress_ratios`` [""]: comma-separated η = q/p of the radial paths ("" = none).
    - ``isotropic_end_stress`` [unset]: p at which the isotropic path ends, above
      ``target_mean_stress``. A→B reaches B as without it (bit for bit), then goes on in
      log-spaced increments no larger than its own up to this p, so that the study's window
      (1–200 kPa) has its upper end and E_v/p can be followed past B (the stress scale by the
      stiffness). The states past B belong to the isotropic path (stage ``A_to_B``, no label).
    - ``run_isotropic``, ``run_k0``, ``run_unloading`` [true]: which paths run (C→B needs K0).
    - ``compression_increment`` [0.02]: per-axis logarithmic strain of a compression increment
      towards A (coarse); refined by halving down to ``min_compression_increment`` [1e-5]
      when a candidate A is found (the sample is then restored to the previous relaxed state);
      halving stops early once a candidate has p ≤ ``transition_pressure_factor`` [4.0] ×
      ``pressure_tolerance`` (the transition is then resolved). Frictional rods without
      long-range forces jam abruptly: on the default scene (neutral) one increment of 0.0025
      jumps from p ≈ 0 to p ≈ 2500, hence the small floor [1e-5].
    - ``gas_strain_rate`` [0.05]: strain-rate cap (1/time) of the compression while p ≤
      ``pressure_tolerance`` (the inertial-number cap of [control] applies once p > 0).
    - ``pressure_tolerance`` [0.5]: relaxed static p above which a state carries load (DEM).
    - ``coordination_min`` [3.0]: Z_m at or above which the contact network is taken as
      percolating (2D rigid frictional bodies are isostatic at Z = d + 1 = 3).
    - ``confirm_increments`` [2]: relaxed increments after a candidate A over which p must stay
      above the tolerance (the transition rule "p stays positive").
    - ``confirm_increment`` [unset]: per-axis logarithmic strain of each of those increments
      (unset: the candidate's own increment h, up to ``compression_increment``). The
      confirmation only decides whether the candidate is A (the sample is then restored to
      it), so while the decision is the same, A and everything after it are bitwise the same;
      the steps are not: at p ≈ p_A the inertial-number cap makes a 0.02 increment the
      longest loading of the stage (paper scene, seed 3: 159,000 of its 518,000 steps).
    - ``max_compression_increments`` [400]: give up (error) after this many increments.
    - ``relax_unbalanced_force`` [1e-4]: UFR below which a state is relaxed (static).
    - ``relax_kinetic_energy_per_rod`` [1.0]: and kinetic energy per rod below this (energy).
      Loose by default: rattlers of a neutral packing carry no force, so local damping cannot
      take their kinetic energy and a tight bound (1e-8 was tried) is never met; UFR decides.
    - ``relax_check_steps`` [500]: steps between relaxation checks.
    - ``relax_max_steps`` [200000]: most steps of one relaxation (then it continues, recorded
      as not relaxed; or stops the run when the time step is past the local stability limit of
      the bodies that hold the unbalanced force: :func:`dem_taichi.protocol.quasistatic.relax`).
    - ``stress_tolerance`` [1e-3]: |σ − σ_target|/σ_target allowed at relaxed states.
    - ``path_stress_tolerance`` [unset = ``stress_tolerance``]: the same, at the relaxed states
      inside a path only: the states that end a path (B, C, B', R<k>_end) keep
      ``stress_tolerance``. An inner state is recorded with the stresses it has (λ*, the fabric
      and the probes use them, not the targets), so its target only spaces the states; the
      servo's exponential approach to a target costs ∝ ln(1/tolerance) and a relaxed check
      that misses by a creep of ~1e-3 costs a further approach
      (``benchmarks/results/protocol_profile.md``).
    - ``servo_time`` [2.0]: time constant T (time units) of the stress servo,
      ε̇ = C⁻¹ (σ_target − σ) / T, C the linear-response stiffness of the relaxed network (capped
      by the inertial-number rate).
    - ``servo_near_target`` [0.05], ``servo_stall_times`` [10.0], ``servo_time_max_factor``
      [64.0]: hunting detection. The servo counts the time since every |t − Wσ| first came
      within ``servo_near_target`` |t|; when it has not settled after ``servo_stall_times``
      servo times T and the sample still moves (UFR ≥ 100 × ``relax_unbalanced_force``), it
      doubles T (halves the gain) for the rest of the stage, at most up to
      ``servo_time_max_factor`` × ``servo_time``. A healthy exponential approach from 5 % to
      the check threshold (0.05 %) takes ln 100 ≈ 4.6 T, hence 10 T.
    - ``servo_stiffness`` ["elastic"]: the stiffness in the servo's rate law. "elastic": the
      linear-response stiffness C of the relaxed network at the start of each target (on a
      plastic path the approach is then slower than T by C/C_tangent). "secant": s C, s the
      measured secant/elastic ratio since loading began in the current direction, in
      [``servo_softening_min``, 1], estimated once the elastic prediction of the stress change
      exceeds ``servo_near_target`` of the target, reset to 1 when the residual changes sign
      (:class:`dem_taichi.protocol.servo.SecantStiffness`); the loading then runs near the
      inertial-number cap. The paper scene uses "secant"; the default stays "elastic" (the
      validation runs of the default scene were made with it).
    - ``servo_softening_min`` [0.01]: smallest s of the secant servo.
    - ``servo_check_steps`` [100]: steps between servo updates.
    - ``servo_max_steps`` [2000000]: most steps to reach one stress target (then an error).
    - ``unbalanced_force_max`` [0.1]: UFR limit while loading; above it the servo rate is
      halved, down to 0.1 × (and recovers by ×1.25 per check below it). Spikes from sudden
      rearrangements can exceed it whatever the rate; they are counted in the results.
    - ``inertial_number_safety`` [0.5]: the rates are capped at this fraction of the
      inertial-number limit of [control] (the stress can drop within a servo update), in the
      compression to A (once p > 0) and, unless the next key is set, in the stress servo.
    - ``servo_inertial_number_safety`` [unset = ``inertial_number_safety``]: the same fraction
      for the stress servo alone (the paths from A), so that the servo's loading rate can change
      while the preparation of A stays bit for bit the same. The `study` scenes set 1.0 with the
      secant servo (``benchmarks/results/study_servo.md``).
    - ``save_states`` [true]: write a checkpoint ``state_<label>.npz`` at every labelled state.
    - ``save_path_states`` [false]: also write ``path_<stage>_<increment>.npz`` at every relaxed
      increment of the paths from A (the intermediate states of A→B, A→C, C→B, radial), for
      frozen-network studies (``dem_taichi.response.flexible``, ``benchmarks/
      stiffness_anisotropy.py``). Needs ``save_states``.
    - ``load_steps_min`` [200]: fewest steps over which a strain increment is applied.

    Preparation of the gas before the compression to A (issue 19): the stage "aggregation" runs
    before "isotropic_to_A" when ``aggregation`` is "time" or "coordination". Its keys
    (``aggregation``, ``aggregation_time``, ``aggregation_coordination``,
    ``aggregation_max_time``, ``aggregation_area_fraction``, ``aggregation_speed``,
    ``aggregation_thermostat``, ``aggregation_thermostat_time``) are unset by default, so a scene
    without them runs (and writes its TOML and hash) as before; what each means, their metadata
    and their checks are in :mod:`dem_taichi.scene.aggregation_keys`.

    - ``pressure_tolerance_reduced`` [unset = use ``pressure_tolerance``]: the A criterion's
      tolerance in units of the attraction, P* = p d / F_max (F_max the larger of [long_range]
      f_max_edge and f_max_inner, d the disc diameter): the tolerance is then P* F_max / d, so
      scenes at different F_max are prepared alike. It replaces ``pressure_tolerance`` in the
      transition rule only (candidates, confirmation, the gas rate below it); the servo and the
      probes keep ``pressure_tolerance`` as the floor stress of their inertial-number rate caps.
      Refused when the scene has no long-range forces (disabled or neutral).
    """

    SECTION = "protocol"
    stress_scale_kpa: float = field(
        default=1.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc=(
                "kPa per DEM stress unit (force/length), stated in the results (a "
                "reading of them, not an input of the physics)"
            ),
            unit="kPa/(force/length)",
        ),
    )
    target_mean_stress: float = field(
        default=100.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="p at B and C and at the ends of the radial paths",
            unit="force/length",
        ),
    )
    path_increments: int = field(
        default=6,
        metadata=_range(
            1,
            1000,
            doc=("relaxed stress increments (log-spaced in p) along A→B, A→C and the radial paths"),
            unit="1",
        ),
    )
    unloading_increments: int = field(
        default=4,
        metadata=_range(1, 1000, doc="relaxed increments of q (linear to 0) along C→B", unit="1"),
    )
    radial_stress_ratios: str = field(
        default="",
        metadata=_list(doc='η = q/p of the radial paths from A, a list ("" = none)', unit="1"),
    )
    isotropic_end_stress: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                None,
                lo_open=True,
                doc=(
                    "p at which the isotropic path ends, above target_mean_stress: A→B goes "
                    "on past B in increments no larger (in ln p) than its own (unset: it ends "
                    "at B)"
                ),
                unit="force/length",
            ),
            "optional": True,
        },
    )
    run_isotropic: bool = field(default=True, metadata=_doc("run the isotropic path A→B", "-"))
    run_k0: bool = field(default=True, metadata=_doc("run the K0 path A→C (ε_xx = 0)", "-"))
    run_unloading: bool = field(
        default=True, metadata=_doc("run the unloading C→B at constant p (needs run_k0)", "-")
    )
    compression_increment: float = field(
        default=0.02, metadata=TRANSITION_KEYS["compression_increment"]
    )
    min_compression_increment: float = field(
        default=1e-5, metadata=TRANSITION_KEYS["min_compression_increment"]
    )
    transition_pressure_factor: float = field(
        default=4.0, metadata=TRANSITION_KEYS["transition_pressure_factor"]
    )
    gas_strain_rate: float = field(default=0.05, metadata=TRANSITION_KEYS["gas_strain_rate"])
    pressure_tolerance: float = field(default=0.5, metadata=TRANSITION_KEYS["pressure_tolerance"])
    coordination_min: float = field(default=3.0, metadata=TRANSITION_KEYS["coordination_min"])
    confirm_increments: int = field(default=2, metadata=TRANSITION_KEYS["confirm_increments"])
    confirm_increment: float | None = field(
        default=None, metadata=TRANSITION_KEYS["confirm_increment"]
    )
    max_compression_increments: int = field(
        default=400, metadata=TRANSITION_KEYS["max_compression_increments"]
    )
    relax_unbalanced_force: float = field(
        default=1e-4, metadata=TRANSITION_KEYS["relax_unbalanced_force"]
    )
    relax_kinetic_energy_per_rod: float = field(
        default=1.0, metadata=TRANSITION_KEYS["relax_kinetic_energy_per_rod"]
    )
    relax_check_steps: int = field(default=500, metadata=TRANSITION_KEYS["relax_check_steps"])
    relax_max_steps: int = field(default=200_000, metadata=TRANSITION_KEYS["relax_max_steps"])
    # the stress servo's keys (also unbalanced_force_max, inertial_number_safety below): their
    # metadata in scene/servo_keys.py
    stress_tolerance: float = field(default=1e-3, metadata=SERVO_KEYS["stress_tolerance"])
    path_stress_tolerance: float | None = field(
        default=None, metadata=SERVO_KEYS["path_stress_tolerance"]
    )
    servo_time: float = field(default=2.0, metadata=SERVO_KEYS["servo_time"])
    servo_near_target: float = field(default=0.05, metadata=SERVO_KEYS["servo_near_target"])
    servo_stall_times: float = field(default=10.0, metadata=SERVO_KEYS["servo_stall_times"])
    servo_time_max_factor: float = field(default=64.0, metadata=SERVO_KEYS["servo_time_max_factor"])
    servo_stiffness: str = field(default="elastic", metadata=SERVO_KEYS["servo_stiffness"])
    servo_softening_min: float = field(default=0.01, metadata=SERVO_KEYS["servo_softening_min"])
    servo_check_steps: int = field(default=100, metadata=SERVO_KEYS["servo_check_steps"])
    servo_max_steps: int = field(default=2_000_000, metadata=SERVO_KEYS["servo_max_steps"])
    load_steps_min: int = field(
        default=200,
        metadata=_range(
            1, doc="fewest steps over which a strain increment is applied", unit="steps"
        ),
    )
    unbalanced_force_max: float = field(default=0.1, metadata=SERVO_KEYS["unbalanced_force_max"])
    inertial_number_safety: float = field(
        default=0.5, metadata=SERVO_KEYS["inertial_number_safety"]
    )
    servo_inertial_number_safety: float | None = field(
        default=None, metadata=SERVO_KEYS["servo_inertial_number_safety"]
    )
    path_time_step_factor: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                4.0,
                lo_open=True,
                doc=(
                    "the paths from A (every branch and its probes) at this multiple of the "
                    "scene's Δt (unset: 1); the preparation (ageing, compression to A, the probes "
                    "at A) keeps the scene's Δt; check intervals stay in steps"
                ),
                unit="1",
            ),
            "optional": True,
        },
    )
    path_contact_damping: bool | None = field(
        default=None,
        metadata={
            **_doc(
                "the paths from A (every branch and its probes) with the scene's contact dashpot "
                "(unset or true) or without it (false: γ_n = γ_t = 0, the local damping alone); "
                "the preparation keeps it. The explicit dashpot lowers the leapfrog's stable "
                "step (benchmarks/results/period_two.md)",
                "-",
            ),
            "optional": True,
        },
    )
    save_states: bool = field(
        default=True,
        metadata=_doc("write a checkpoint state_<label>.npz at every labelled state", "-"),
    )
    save_path_states: bool = field(
        default=False,
        metadata=_doc(
            (
                "also write path_<stage>_<increment>.npz at every relaxed increment of "
                "the paths from A (needs save_states)"
            ),
            "-",
        ),
    )
    # the aggregation stage's keys (issue 19): metadata and checks in scene/aggregation_keys.py
    aggregation: str | None = field(default=None, metadata=AGGREGATION_KEYS["aggregation"])
    aggregation_time: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_time"]
    )
    aggregation_coordination: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_coordination"]
    )
    aggregation_max_time: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_max_time"]
    )
    aggregation_area_fraction: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_area_fraction"]
    )
    aggregation_speed: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_speed"]
    )
    aggregation_thermostat: str | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_thermostat"]
    )
    aggregation_thermostat_time: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_thermostat_time"]
    )
    aggregation_time_step_factor: float | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_time_step_factor"]
    )
    aggregation_rod_model: str | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_rod_model"]
    )
    aggregation_springs: str | None = field(
        default=None, metadata=AGGREGATION_KEYS["aggregation_springs"]
    )
    pressure_tolerance_reduced: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                None,
                lo_open=True,
                doc=("the A criterion's tolerance as P* = p d / F_max (unset: pressure_tolerance)"),
                unit="1",
            ),
            "optional": True,
        },
    )

    def check(self) -> None:
        check_aggregation_keys({key: getattr(self, key) for key in AGGREGATION_KEYS})
        if self.min_compression_increment > self.compression_increment:
            raise SceneError(
                f"[protocol] min_compression_increment = {self.min_compression_increment} > "
                f"compression_increment = {self.compression_increment}: allowed "
                "(0, compression_increment]"
            )
        ratios = parse_number_list(self.radial_stress_ratios, "[protocol] radial_stress_ratios")
        for eta in ratios:
            if not -2.0 < eta < 2.0:
                raise SceneError(
                    f"[protocol] radial_stress_ratios: η = {eta} out of range: allowed (-2, 2) "
                    "(both principal stresses must stay compressive: σ = p (1 ± η/2))"
                )
        end = self.isotropic_end_stress
        if end is not None and not end > self.target_mean_stress:
            raise SceneError(
                f"[protocol] isotropic_end_stress = {end!r} is not above target_mean_stress = "
                f"{self.target_mean_stress!r}: allowed (target_mean_stress, ∞), or leave it unset"
            )
        if self.save_path_states and not self.save_states:
            raise SceneError("[protocol] save_path_states = true needs save_states = true")
        if self.run_unloading and not self.run_k0:
            raise SceneError(
                "[protocol] run_unloading = true needs run_k0 = true (C→B starts at C)"
            )

    @property
    def aggregates(self) -> bool:
        """Whether the run has an aggregation stage before the compression to A."""
        return (self.aggregation or "none") != "none"

    def ages_rigid(self, scene) -> bool:
        """Whether the aggregation stage runs on a rigid twin of the scene's bonded rods
        (``aggregation_rod_model = "rigid"`` on bonded rods:
        :mod:`dem_taichi.protocol.rigid_ageing`)."""
        return self.aggregates and scene.bonded and self.aggregation_rod_model == "rigid"

    def check_scene(self, scene) -> None:
        """The checks that need the rest of the scene ([particles], [long_range]): an
        aggregation area fraction below the gas's, the cluster thermostat on bonded rods, a
        reduced pressure tolerance without long-range forces. Run with the whole-scene checks
        at load and by ``Scene.replace`` (:func:`dem_taichi.scene.config._check_scene`), and
        again by :func:`protocol_settings`."""
        phi = self.aggregation_area_fraction
        phi0 = scene.particles.initial_area_fraction
        if phi is not None and phi < phi0:
            raise SceneError(
                f"[protocol] aggregation_area_fraction = {phi!r} is below [particles] "
                f"initial_area_fraction = {phi0!r}: allowed [{phi0!r}, 1) (the gas is only "
                "compressed before ageing)"
            )
        if self.aggregation_rod_model == "bonded" and not scene.bonded:
            raise SceneError(
                "[protocol] aggregation_rod_model = 'bonded' needs bonded rods; this scene's "
                "[particles] rod_model = 'rigid': remove aggregation_rod_model or set "
                "rod_model = 'bonded'"
            )
        if self.aggregation_springs is not None and self.aggregation_rod_model != "rigid":
            # (on rigid rods, "rigid" is their own model and the key does nothing: the rigid
            # twin of a bonded scene is such a scene)
            raise SceneError(
                f"[protocol] aggregation_springs = {self.aggregation_springs!r} is used only "
                "when bonded rods age as rigid rods (aggregation_rod_model = 'rigid'): remove "
                "aggregation_springs or set aggregation_rod_model"
            )
        if (
            self.aggregation_thermostat == "clusters"
            and scene.bonded
            and self.aggregation_rod_model != "rigid"
        ):
            raise SceneError(
                "[protocol] aggregation_thermostat = 'clusters' needs rigid rods (a bonded "
                "rod's discs are bodies of their own); this scene's [particles] rod_model = "
                "'bonded': use rod_model = 'rigid', aggregation_rod_model = 'rigid' (age the "
                "gas as rigid rods), or another aggregation_thermostat"
            )
        # the ageing of bonded rods aged as rigid runs on the rigid twin: no bonds to hold
        aged_bonded = scene.bonded and not self.ages_rigid(scene)
        check_time_step_factor(
            scene, "aggregation_time_step_factor", self.aggregation_time_step_factor, aged_bonded
        )
        check_time_step_factor(
            scene, "path_time_step_factor", self.path_time_step_factor, scene.bonded, jammed=True
        )
        lr = scene.long_range
        if self.pressure_tolerance_reduced is not None and not (
            lr.enabled and lr.pattern in ("acidic", "basic")
        ):
            state = "enabled = false" if not lr.enabled else f"pattern = {lr.pattern!r}"
            raise SceneError(
                f"[protocol] pressure_tolerance_reduced = {self.pressure_tolerance_reduced!r} "
                f"needs long-range forces (P* = p d / F_max); this scene's [long_range] has "
                f"{state}: give pressure_tolerance instead"
            )

    def path_time_step(self, scene_time_step: float) -> float:
        """Δt of the paths from A: ``path_time_step_factor`` × the scene's Δt."""
        return scene_time_step * (self.path_time_step_factor or 1.0)

    def inner_stress_tolerance(self) -> float:
        """|σ − σ_target|/σ_target at the relaxed states inside a path: ``path_stress_tolerance``
        when set, else ``stress_tolerance``."""
        if self.path_stress_tolerance is None:
            return self.stress_tolerance
        return self.path_stress_tolerance

    def servo_safety(self) -> float:
        """The stress servo's fraction of [control] inertial_number_max:
        ``servo_inertial_number_safety`` when set, else ``inertial_number_safety``."""
        if self.servo_inertial_number_safety is None:
            return self.inertial_number_safety
        return self.servo_inertial_number_safety

    def transition_pressure_tolerance(self, scene) -> float:
        """The p above which a relaxed state carries load in the A criterion (DEM units):
        ``pressure_tolerance``, or P* F_max / d when ``pressure_tolerance_reduced`` = P* is set
        (F_max the larger of [long_range] f_max_edge, f_max_inner; d the disc diameter)."""
        if self.pressure_tolerance_reduced is None:
            return self.pressure_tolerance
        self.check_scene(scene)
        lr = scene.long_range
        f_max = max(lr.f_max_edge, lr.f_max_inner)
        return self.pressure_tolerance_reduced * f_max / scene.particles.diameter

    @property
    def radial_ratios(self) -> tuple[float, ...]:
        """η of the radial paths, parsed from ``radial_stress_ratios``."""
        return parse_number_list(self.radial_stress_ratios, "[protocol] radial_stress_ratios")


def protocol_settings(scene) -> ProtocolConfig:
    """The scene's ``[protocol]`` section, or the defaults when it has none; refuses
    (:class:`SceneError`, naming the key) a section that does not fit the rest of the scene
    (:meth:`ProtocolConfig.check_scene`)."""
    config = scene.extensions.get("protocol", ProtocolConfig())
    config.check_scene(scene)
    return config
