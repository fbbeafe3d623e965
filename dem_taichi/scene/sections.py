"""The core sections of a scene as frozen dataclasses: ``[scene]``, ``[particles]``,
``[contact]``, ``[bonds]``, ``[long_range]``, ``[van_der_waals]``, ``[integration]``,
``[control]``, ``[output]``. The four sections of the interactions (``[contact]``, ``[bonds]``,
``[long_range]``, ``[van_der_waals]``) are defined in :mod:`dem_taichi.scene.interaction_sections`
and re-exported here.

Each field carries its allowed range or choices in ``metadata`` (:mod:`dem_taichi.scene.base`),
checked by the generic loader of :mod:`dem_taichi.scene.config`, which documents every key and
re-exports these classes, and its unit and a one-line description (``unit=``, ``doc=``), from
which the scene reference of the documentation (``docs/reference/scene.md``) is generated.

Units: DEM units, disc diameter d = 1 (length), disc mass m = 1 (mass), the scene's time unit;
a 2D stiffness is a force per length, a 2D stress a force per length; "1" is a dimensionless
number, "-" a text or a switch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from dem_taichi.scene.base import SceneError, SceneSection
from dem_taichi.scene.base import field_choices as _choices
from dem_taichi.scene.base import field_doc as _doc
from dem_taichi.scene.base import field_range as _range
from dem_taichi.scene.interaction_sections import Bonds, Contact, LongRange, VanDerWaals
from dem_taichi.scene.presets import PRESET_NAMES

__all__ = [
    "SceneInfo",
    "Particles",
    "Bonds",
    "Contact",
    "LongRange",
    "VanDerWaals",
    "Integration",
    "Control",
    "Output",
]


@dataclass(frozen=True)
class SceneInfo(SceneSection):
    """``[scene]``: the scene's name, random seed, description and speed–accuracy preset."""

    SECTION = "scene"
    name: str = field(
        default="unnamed", metadata=_doc("name of the scene, written to the results", "-")
    )
    seed: int = field(
        default=0,
        metadata=_range(
            0, 2**31 - 1, doc="seed of the random gas (rod positions, angles, velocities)", unit="1"
        ),
    )
    description: str = field(default="", metadata=_doc("free text describing the scene", "-"))
    preset: str = field(
        default="",
        metadata=_choices(
            *PRESET_NAMES,
            doc="speed–accuracy preset (dem_taichi.scene.presets): fills the numerical keys of its "
            'group that the file does not give; "" = none',
        ),
    )


@dataclass(frozen=True)
class Particles(SceneSection):
    """``[particles]``: the sample, rods of discs in a periodic cell, and the rod model."""

    SECTION = "particles"
    n_rods: int = field(
        default=40, metadata=_range(1, 10_000_000, doc="number of rods in the cell", unit="1")
    )
    n_spheres: int = field(default=5, metadata=_range(1, 64, doc="discs per rod (n_s)", unit="1"))
    diameter: float = field(
        default=1.0,
        metadata=_range(
            0.0, None, lo_open=True, doc="disc diameter d (the unit of length)", unit="length"
        ),
    )
    spacing: float = field(
        default=1.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="distance between the centres of neighbouring discs of a rod (≤ diameter)",
            unit="length",
        ),
    )
    disc_mass: float = field(
        default=1.0,
        metadata=_range(
            0.0, None, lo_open=True, doc="mass m of one disc (the unit of mass)", unit="mass"
        ),
    )
    initial_area_fraction: float = field(
        default=0.15,
        metadata=_range(
            1.0e-3,
            0.5,
            doc="area fraction φ (solid area / cell area) of the random gas the run starts from; "
            "sets the initial cell size",
            unit="1",
        ),
    )
    initial_speed: float = field(
        default=0.01,
        metadata=_range(
            0.0,
            None,
            doc="rms of the random velocity components of the initial gas",
            unit="length/time",
        ),
    )
    rod_model: str = field(
        default="rigid",
        metadata=_choices(
            "rigid",
            "bonded",
            doc="'rigid': each rod one rigid clump of discs (cheapest, larger Δt); 'bonded': "
            "every disc a body, neighbours joined by elastic bonds ([bonds]), rods bend and "
            "may break (the study's MercuryDPM model)",
            unit="-",
        ),
    )

    def check(self) -> None:
        if self.rod_model == "bonded" and self.n_spheres < 2:
            raise SceneError(
                f"[particles] rod_model = 'bonded' needs n_spheres >= 2 (a rod of one disc has "
                f"no bonds); n_spheres = {self.n_spheres}"
            )
        if self.spacing > self.diameter:
            raise SceneError(
                f"[particles] spacing = {self.spacing} > diameter = {self.diameter}: "
                "discs of a rod must touch or overlap (allowed (0, diameter])"
            )


#: FIRE's parameters unless the scene sets ``[integration] fire_<name>``: Bitzek et al.'s (PRL 97,
#: 170201, 2006: N_min = N_delay 5, f_inc 1.1, f_dec 0.5, α_start 0.1, f_α 0.99) with
#: Δt_max = 1.5 Δt and Δt_min = Δt instead of 10 Δt and 0.02 Δt: a frictional rod packing is
#: unstable at 2 Δt (the default scene at dt_safety 0.15: a rod with several contacts has
#: rotational modes near the leapfrog bound), and Δt below the scene's stable one only slows
#: the minimisation. Measured on the default scene (benchmarks/bench_fire.py, issue 20): with
#: FIRE 2.0's values (N_delay 20, α_start 0.25, Δt_max 2 Δt, Δt_min 0.02 Δt) FIRE reset every
#: ~20 steps, Δt fell to Δt/2 and took 4.6x the damped steps after a strain increment; with
#: these, 3.7x fewer steps than the damped relaxation.
FIRE_DEFAULTS: dict[str, float] = {
    "dt_max": 1.5,
    "dt_min": 1.0,
    "n_delay": 5,
    "f_inc": 1.1,
    "f_dec": 0.5,
    "alpha_start": 0.1,
    "f_alpha": 0.99,
}


@dataclass(frozen=True)
class Integration(SceneSection):
    """``[integration]``: the time step, damping, neighbour list, execution mode, blow-up limits
    and the minimiser of the relaxations."""

    SECTION = "integration"
    dt_safety: float = field(
        default=0.15,
        metadata=_range(
            1.0e-3,
            0.5,
            doc="Δt / t_c (time step over contact duration); from 1e-3 (the discrete "
            "restitution model's set-up at load costs ∝ 1/dt_safety: 1 s at 1e-3, hours below "
            "1e-6)",
            unit="1",
        ),
    )
    local_damping: float = field(
        default=0.2,
        metadata=_range(
            0.0,
            1.0,
            hi_open=True,
            doc="local (Cundall) damping α: a force α|F| against each body's velocity, "
            "the same for the torque",
            unit="1",
        ),
    )
    steps_per_call: int = field(
        default=100,
        metadata=_range(
            1,
            1_000_000,
            doc="time steps per chunk between the host's checks (blow-up, neighbour capacity, "
            "output); serial mode fuses them in one kernel call",
            unit="steps",
        ),
    )
    skin: float = field(
        default=0.3,
        metadata=_range(
            0.0, None, lo_open=True, doc="Verlet skin of the neighbour list", unit="length"
        ),
    )
    execution: str = field(
        default="auto",
        metadata=_choices(
            "auto",
            "serial",
            "parallel",
            "gather",
            doc="kernel layout: 'serial' fused steps (CPU), 'parallel' atomic scatter, 'gather' "
            "deterministic per-body sums (GPUs); 'auto' serial on a CPU, parallel on a GPU",
        ),
    )
    max_overlap: float = field(
        default=0.2,
        metadata=_range(0.0, 1.0, lo_open=True, doc="blow-up bound on the overlap δ/d", unit="1"),
    )
    max_kinetic_energy_per_rod: float = field(
        default=1.0e3,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="blow-up bound on the kinetic energy per rod",
            unit="energy",
        ),
    )
    # The minimiser of the relaxations (issue 20). Every key below is optional and written to
    # the scene's TOML only when set, so scenes without them keep their text and hash; unset,
    # each takes the default of FIRE_DEFAULTS (Bitzek et al. 2006, but Δt_max and Δt_min).
    relaxation: str | None = field(
        default=None,
        metadata={
            **_choices(
                "damped",
                "fire",
                doc="how a minimising call (CellControl.relaxation(stage)) is integrated: "
                "'damped' (default): the damped dynamics of every other call, bit for bit; "
                "'fire': the FIRE minimiser (Bitzek et al. 2006 / FIRE 2.0; serial execution)",
                unit="-",
            ),
            "optional": True,
        },
    )
    fire_dt_max: float | None = field(
        default=None,
        metadata={
            **_range(
                1.0,
                2.0,
                doc="FIRE Δt_max / Δt (default 1.5; the papers' 10 is unstable for stiff "
                "contacts, and 2 for the default scene's frictional rods)",
                unit="1",
            ),
            "optional": True,
        },
    )
    fire_dt_min: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                1.0,
                lo_open=True,
                doc="FIRE Δt_min / Δt: the decrease stops there (1)",
                unit="1",
            ),
            "optional": True,
        },
    )
    fire_n_delay: int | None = field(
        default=None,
        metadata={
            **_range(
                0,
                100_000,
                doc="FIRE N_delay: steps with P > 0 before Δt grows; no Δt "
                "decrease during the first N_delay steps (5)",
                unit="steps",
            ),
            "optional": True,
        },
    )
    fire_f_inc: float | None = field(
        default=None,
        metadata={
            **_range(1.0, 2.0, doc="FIRE Δt growth factor f_inc (1.1)", unit="1"),
            "optional": True,
        },
    )
    fire_f_dec: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0, 1.0, lo_open=True, hi_open=True, doc="FIRE Δt factor on P ≤ 0 (0.5)", unit="1"
            ),
            "optional": True,
        },
    )
    fire_alpha_start: float | None = field(
        default=None,
        metadata={
            **_range(0.0, 1.0, hi_open=True, doc="FIRE mixing α after a reset (0.1)", unit="1"),
            "optional": True,
        },
    )
    fire_f_alpha: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0, 1.0, lo_open=True, doc="FIRE α decay factor f_α per step (0.99)", unit="1"
            ),
            "optional": True,
        },
    )

    def check(self) -> None:
        fire_keys = [name for name in FIRE_DEFAULTS if getattr(self, f"fire_{name}") is not None]
        if fire_keys and self.relaxation != "fire":
            raise SceneError(
                f"[integration] {', '.join('fire_' + k for k in fire_keys)}: used only with "
                f'relaxation = "fire" (relaxation = {self.relaxation or "damped"!r})'
            )
        if self.relaxation == "fire" and self.execution in ("parallel", "gather"):
            raise SceneError(
                f'[integration] relaxation = "fire" needs execution = "serial" (or "auto" on a '
                f"CPU); execution = {self.execution!r} has no FIRE kernel"
            )

    @property
    def relaxation_method(self) -> str:
        """``relaxation`` with its default: "damped" or "fire"."""
        return self.relaxation or "damped"

    @property
    def fire(self) -> dict[str, float]:
        """The FIRE parameters, defaults filled in (:data:`FIRE_DEFAULTS`): dt_max and dt_min
        as factors of the scene's Δt, n_delay, f_inc, f_dec, alpha_start, f_alpha."""
        return {
            name: default
            if getattr(self, f"fire_{name}") is None
            else getattr(self, f"fire_{name}")
            for name, default in FIRE_DEFAULTS.items()
        }


@dataclass(frozen=True)
class Control(SceneSection):
    """``[control]``: the quasi-static rate cap and the engine's built-in compression run
    (``python -m dem_taichi run``). ``servo_gain`` of older scenes is accepted and dropped."""

    SECTION = "control"
    inertial_number_max: float = field(
        default=1.0e-3,
        metadata=_range(
            0.0,
            1.0,
            lo_open=True,
            doc="cap of the inertial number I = ε̇ d sqrt(ρ/p) of every strain rate "
            "(quasi-static loading)",
            unit="1",
        ),
    )
    compression_strain_rate: float = field(
        default=1.0e-3,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="strain rate of the built-in run's isotropic compression",
            unit="1/time",
        ),
    )
    target_specific_volume: float = field(
        default=2.2,
        metadata=_range(
            1.0,
            None,
            lo_open=True,
            doc="specific volume v = A / A_solid at which the built-in compression stops",
            unit="1",
        ),
    )
    relax_steps: int = field(
        default=5000,
        metadata=_range(
            0, doc="steps of relaxation at fixed cell after the built-in compression", unit="steps"
        ),
    )


@dataclass(frozen=True)
class Output(SceneSection):
    """``[output]``: how often the built-in run writes its history and checkpoints."""

    SECTION = "output"
    every: int = field(
        default=1000,
        metadata=_range(
            1,
            doc="steps between history records of the built-in run (and the default "
            "output_every of Simulation.run)",
            unit="steps",
        ),
    )
    checkpoint_every: int = field(
        default=0,
        metadata=_range(
            0, doc="steps between checkpoints of the built-in run (0: none)", unit="steps"
        ),
    )
