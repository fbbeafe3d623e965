"""Options of the staged calibration (:mod:`bridge.calibration.fit`): stages, bounds, scales.

Parameters are the study's symbols (:data:`tiv_model.params.SYMBOLS`); their units and
validity ranges come from :data:`tiv_model.params.PARAMETER_INFO`, the search bounds and the
fixed/free choice from :class:`CalibrationOptions` (the role lmfit's ``Parameters`` plays
elsewhere; ARCHITECTURE.md says why this project keeps its own).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from tiv_model.params import (
    DEFAULT_OPTIONS,
    PARAMETER_INFO,
    SYMBOLS,
    TABLE1,
    ModelOptions,
    Parameters,
)

STAGES = ("compressibility", "elastic", "fabric")
#: Parameters (study symbols) fitted in each stage, before removing the fixed ones.
STAGE_PARAMETERS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "compressibility": ("N", "lambda_star"),
        "elastic": ("k", "g", "n", "r", "omega"),
        "fabric": ("c", "s", "z", "M"),
    }
)
#: Default search bounds (study symbols).
DEFAULT_BOUNDS: Mapping[str, tuple[float, float]] = MappingProxyType(
    {
        "k": (0.1, 1e5),
        "g": (0.1, 1e5),
        "n": (0.0, 0.95),
        "r": (0.0, 5.0),
        "N": (1.0 + 1e-6, 50.0),
        "lambda_star": (1e-4, 3.0),
        "M": (0.05, 3.0),
        "c": (0.0, 200.0),
        "s": (1e-3, 200.0),
        "z": (1.0 + 1e-6, 200.0),
        "omega": (0.0, 1e3),
    }
)
#: Default residual scales (one standard deviation of the data, in the residual's units).
DEFAULT_SCALES: Mapping[str, float] = MappingProxyType(
    {"ln_specific_volume": 0.01, "ln_modulus": 0.05, "fabric": 0.01, "stress_ratio": 0.02}
)
FABRIC_SERIES = ("fabric", "stress_ratio", "specific_volume")
ELASTIC_MODULI = ("e_oed_v", "e_oed_h", "e_cross")
INITIAL_FABRIC = ("zero", "measured")
_SYMBOL_TO_NAME = {sym: name for name, sym in SYMBOLS.items()}
UNITS = {sym: PARAMETER_INFO[name][1] for name, sym in SYMBOLS.items()}


class CalibrationError(RuntimeError):
    """A calibration stage could not be set up or did not succeed; the message says why."""


class ModelFailureError(CalibrationError):
    """The model cannot be run on a stage's paths, at its starting parameters or at every
    parameter set the fit tried (a limit point along a path, a parameter outside the model's
    domain): the data, not the set-up, stop that stage. ``stage``: the stage's name."""

    def __init__(self, stage: str, message: str) -> None:
        super().__init__(message)
        self.stage = stage

    def __reduce__(self):  # picklable across processes (the args are not the __init__'s)
        return type(self), (self.stage, str(self))


@dataclass(frozen=True)
class CalibrationOptions:
    """How to calibrate (defaults follow the study).

    reference_pressure: p_r (kPa), the only dimensional parameter, never fitted.
    model_options: the model's uncertain parts (anisotropy form, constraint forces, bound law).
    initial: starting values; parameters listed in ``fixed`` (study symbols) keep them.
    fit_critical_stress_ratio: fit M in the fabric stage from the K0 stress ratio (else fixed).
    omega_stage: ``"elastic"`` (default) or ``"fabric"`` (the study's grouping), where ω is fitted.
    initial_fabric: the model's fabric at A: ``"zero"`` (default, isotropic as in the model's
        standard start) or ``"measured"`` (the DEM's β at A; p_c from the rotated yield surface,
        :func:`bridge.runs.start_state`).
    fabric_series: K0 series fitted in the fabric stage, among ``FABRIC_SERIES``.
    fabric_paths: paths of the fabric stage: ``"k0"`` always; ``"radial"`` adds every radial
        path of the series (``radial_1``…, :func:`bridge.series.radial_series`), model runs from
        A along the DEM's stresses, fitting β (and v when ``fabric_series`` has it): paths at
        several η are what fix the bounding-fabric law (s, z) beyond the single η of K0.
    elastic_moduli: probe moduli fitted in the elastic stage, among ``ELASTIC_MODULI``
        (the cross term is used only where the probes have it).
    elastic_paths: probe paths of the elastic stage.
    compressibility_min_pressure: isotropic points with p below it (kPa) are not fitted.
    max_k0_increments: most increments of a model K0 run (more DEM points are interpolated).
    passes: most repetitions of the coupled stages (stops when no parameter changes by more
        than ``pass_tolerance``, relative, or absolute below 1e-6):
        compressibility and elastic (cheap) are cycled to a fixed point, then fabric runs once;
        with ``omega_stage="fabric"`` all three are cycled.
    scales: residual scales, keys of ``DEFAULT_SCALES``.
    bounds: per-symbol (low, high) overriding ``DEFAULT_BOUNDS``.
    penalty: residual value given to each point when a model run fails.
    method: :func:`scipy.optimize.least_squares` method of every stage: ``"dogbox"``
        (default: bounds as an active set; on the demo's fabric stage, where z sits at its
        bound, a third of the model runs of ``"trf"`` for the same cost) or ``"trf"`` (the
        method before issue 12).
    tolerance: xtol and gtol of the least squares (the profiles of
        :mod:`bridge.calibration.identifiability` refit with 1e-8).
    cost_tolerance: ftol, the relative decrease of the cost per step below which a stage
        stops. 1e-8, far below what matters statistically (a change of 1/(m − n) of the cost
        moves a profile by Δ ≈ 1); before issue 12 it was 1e-12 (as were xtol and gtol): in the
        paper scene's flat c–s–z valley the optimiser then took from 60 to the 1000 evaluations
        allowed depending on round-off, for costs within 1e-6 relative.
    max_evaluations: most residual evaluations of one stage fit (default 200 × (free + 1)).
    """

    reference_pressure: float = 100.0
    model_options: ModelOptions = DEFAULT_OPTIONS
    initial: Parameters = TABLE1
    fixed: tuple[str, ...] = ()
    fit_critical_stress_ratio: bool = True
    omega_stage: str = "elastic"
    initial_fabric: str = "zero"
    fabric_series: tuple[str, ...] = ("fabric", "stress_ratio")
    fabric_paths: tuple[str, ...] = ("k0", "radial")
    elastic_moduli: tuple[str, ...] = ELASTIC_MODULI
    elastic_paths: tuple[str, ...] = ("isotropic", "unloading")
    compressibility_min_pressure: float = 0.0
    max_k0_increments: int = 12
    passes: int = 12
    pass_tolerance: float = 1e-9
    scales: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_SCALES))
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    penalty: float = 1e3
    method: str = "dogbox"
    tolerance: float = 1e-10
    cost_tolerance: float = 1e-8
    max_evaluations: int | None = None

    def __post_init__(self) -> None:
        if self.method not in ("dogbox", "trf"):
            raise CalibrationError(f"option method = {self.method!r}: use 'dogbox' or 'trf'")
        if not (isinstance(self.reference_pressure, (int, float)) and self.reference_pressure > 0):
            raise CalibrationError(f"reference_pressure = {self.reference_pressure!r} must be > 0")
        allowed = set(SYMBOLS.values()) - {"p_r"}
        for name, values, ok in (
            ("fixed", self.fixed, allowed),
            ("fabric_series", self.fabric_series, set(FABRIC_SERIES)),
            ("fabric_paths", self.fabric_paths, {"k0", "radial"}),
            ("elastic_moduli", self.elastic_moduli, set(ELASTIC_MODULI)),
            ("elastic_paths", self.elastic_paths, {"isotropic", "unloading", "k0"}),
            ("scales", tuple(self.scales), set(DEFAULT_SCALES)),
            ("bounds", tuple(self.bounds), allowed),
        ):
            bad = sorted(set(values) - ok)
            if bad:
                raise CalibrationError(
                    f"option {name}: unknown entries {bad}; allowed {sorted(ok)}"
                )
        if self.omega_stage not in ("elastic", "fabric"):
            raise CalibrationError(
                f"option omega_stage = {self.omega_stage!r}: use 'elastic' or 'fabric'"
            )
        if self.initial_fabric not in INITIAL_FABRIC:
            raise CalibrationError(
                f"option initial_fabric = {self.initial_fabric!r}: use one of {INITIAL_FABRIC}"
            )
        if not self.fabric_series:
            raise CalibrationError("option fabric_series must name at least one K0 series")
        for key in ("passes", "max_k0_increments"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise CalibrationError(f"option {key} = {value!r} must be an integer ≥ 1")

    def start(self) -> Parameters:
        return self.initial.replace(p_r=float(self.reference_pressure))

    def bound(self, symbol: str) -> tuple[float, float]:
        bounds = self.bounds.get(symbol, DEFAULT_BOUNDS[symbol])  # a list, from a file
        return (bounds[0], bounds[1])

    def scale(self, key: str) -> float:
        return float(self.scales.get(key, DEFAULT_SCALES[key]))

    def free(self, stage: str) -> tuple[str, ...]:
        names = [s for s in STAGE_PARAMETERS[stage] if s not in self.fixed]
        if self.omega_stage == "fabric":
            names = [s for s in names if s != "omega"]
            if stage == "fabric" and "omega" not in self.fixed:
                names.append("omega")
        if stage == "fabric" and not self.fit_critical_stress_ratio:
            names = [s for s in names if s != "M"]
        return tuple(names)


__all__ = [
    "STAGES",
    "STAGE_PARAMETERS",
    "DEFAULT_BOUNDS",
    "DEFAULT_SCALES",
    "FABRIC_SERIES",
    "ELASTIC_MODULI",
    "INITIAL_FABRIC",
    "UNITS",
    "CalibrationError",
    "CalibrationOptions",
    "ModelFailureError",
]
