"""Model parameters, options and solver settings (frozen, validated).

Symbols (the study's Table 1 names) and units
--------------------------------------------
p_r  reference_pressure            kPa   the only dimensional parameter
g    shear_stiffness_coefficient   1     G = g p_r (p/p_r)^n (p_c/p_r)^r on the isotropic axis
k    bulk_stiffness_coefficient    1     K = k p_r (p/p_r)^n (p_c/p_r)^r on the isotropic axis
n    stiffness_pressure_exponent   1     0 ≤ n < 1
r    stiffness_density_exponent    1     r ≥ 0
N    ncl_intercept                 1     specific volume of the NCL at p_c = p_r (N > 1)
λ*   compression_index             1     slope of ln v vs ln p_c
M    critical_stress_ratio         1     M > 0
c    fabric_rate                   1     rate of approach of β to β_b, c ≥ 0
s    bound_rate                    1     exponent of the bounding fabric law, s > 0
z    bound_ratio                   1     β_b saturates at M/z, z > 1 keeps β_s < M
ω    anisotropy_coefficient        1     ω ≥ 0, strength of the fabric in the energy
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import ParameterError

#: name -> (symbol, units, lower bound, lower inclusive, upper bound, upper inclusive, meaning)
PARAMETER_INFO: dict[str, tuple[str, str, float, bool, float, bool, str]] = {
    "reference_pressure": ("p_r", "kPa", 0.0, False, math.inf, False, "reference pressure"),
    "shear_stiffness_coefficient": (
        "g", "1", 0.0, False, math.inf, False, "shear stiffness coefficient"),
    "bulk_stiffness_coefficient": (
        "k", "1", 0.0, False, math.inf, False, "bulk stiffness coefficient"),
    "stiffness_pressure_exponent": (
        "n", "1", 0.0, True, 1.0, False, "pressure exponent of the elastic stiffness"),
    "stiffness_density_exponent": (
        "r", "1", 0.0, True, math.inf, False, "preconsolidation exponent of the stiffness"),
    "ncl_intercept": ("N", "1", 1.0, False, math.inf, False, "specific volume of the NCL at p_r"),
    "compression_index": ("lambda_star", "1", 0.0, False, math.inf, False,
                          "logarithmic compression index λ*"),
    "critical_stress_ratio": ("M", "1", 0.0, False, math.inf, False, "critical stress ratio"),
    "fabric_rate": ("c", "1", 0.0, True, math.inf, False, "rate of fabric evolution"),
    "bound_rate": ("s", "1", 0.0, False, math.inf, False, "rate of the bounding fabric law"),
    "bound_ratio": ("z", "1", 1.0, False, math.inf, False, "bounding fabric ratio, |β_b| ≤ M/z"),
    "anisotropy_coefficient": ("omega", "1", 0.0, True, math.inf, False,
                               "anisotropy coefficient ω of the free energy"),
}  # fmt: skip

SYMBOLS: dict[str, str] = {name: info[0] for name, info in PARAMETER_INFO.items()}

#: Largest magnitude of any parameter, and of the derived quantities in :data:`_DERIVED`: the
#: model takes powers and logarithms of products of parameters (k·p_r, (v/N)^X), which overflow
#: far from the parameter that caused it ("math domain error"); no calibrated value comes near
#: (the calibration's own search bounds stop at 1e5).
MAX_MAGNITUDE = 1.0e8

#: Derived quantities checked at construction: description, the symbols it depends on, value.
_DERIVED: tuple[tuple[str, str, Callable[[Any], float]], ...] = (
    ("energy exponent X = r/((n-1) lambda_star)", "r, n, lambda_star",
     lambda p: p.energy_exponent),
    ("bulk modulus scale k p_r", "k, p_r", lambda p: p.k * p.p_r),
    ("shear modulus scale g p_r", "g, p_r", lambda p: p.g * p.p_r),
)  # fmt: skip


@dataclass(frozen=True)
class Parameters:
    """TIV parameters (Table 1 symbols in brackets); validated on construction.

    Invalid values raise :class:`ParameterError` naming the parameter, its value and the allowed
    range, e.g. ``n ≥ 1``, ``z ≤ 1``, a negative stiffness or ``M ≤ 0``.
    """

    reference_pressure: float  # p_r, kPa
    shear_stiffness_coefficient: float  # g
    bulk_stiffness_coefficient: float  # k
    stiffness_pressure_exponent: float  # n
    stiffness_density_exponent: float  # r
    ncl_intercept: float  # N
    compression_index: float  # λ*
    critical_stress_ratio: float  # M
    fabric_rate: float  # c
    bound_rate: float  # s
    bound_ratio: float  # z
    anisotropy_coefficient: float  # ω

    def __post_init__(self) -> None:
        for name, (symbol, units, lo, lo_in, hi, hi_in, meaning) in PARAMETER_INFO.items():
            value = getattr(self, name)
            # any real scalar, numpy's included (values read back from netCDF are numpy scalars)
            if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
                raise ParameterError(
                    f"parameter {name} ({symbol}) must be a real number, got {value!r}"
                )
            value = float(value)
            object.__setattr__(self, name, value)
            ok_lo = value >= lo if lo_in else value > lo
            ok_hi = value <= hi if hi_in else value < hi
            if not (math.isfinite(value) and ok_lo and ok_hi):
                lo_s = f"{lo:g} {'≤' if lo_in else '<'} "
                hi_s = "" if math.isinf(hi) else f" {'≤' if hi_in else '<'} {hi:g}"
                raise ParameterError(
                    f"parameter {name} ({symbol}, {meaning}) = {value!r} is not allowed: "
                    f"need {lo_s}{symbol}{hi_s} (units: {units})"
                )
            if abs(value) > MAX_MAGNITUDE:
                raise ParameterError(
                    f"parameter {name} ({symbol}, {meaning}) = {value!r} is not allowed: "
                    f"need |{symbol}| <= {MAX_MAGNITUDE:g} (units: {units}; larger values "
                    "overflow the model's powers and logarithms)"
                )
        self._check_derived()

    def _check_derived(self) -> None:
        """Refuse parameters that are each allowed but whose combinations the model uses
        (:data:`_DERIVED`) are not finite or exceed :data:`MAX_MAGNITUDE`, naming them."""
        for what, symbols, compute in _DERIVED:
            try:
                value = compute(self)
            except (OverflowError, ZeroDivisionError):
                value = math.inf
            if not (math.isfinite(value) and abs(value) <= MAX_MAGNITUDE):
                raise ParameterError(
                    f"parameters {symbols}: the {what} = {value:g} is beyond "
                    f"{MAX_MAGNITUDE:g} in magnitude: change {symbols}"
                )

    # -- symbol access -------------------------------------------------------------------------
    @property
    def p_r(self) -> float:
        return self.reference_pressure

    @property
    def g(self) -> float:
        return self.shear_stiffness_coefficient

    @property
    def k(self) -> float:
        return self.bulk_stiffness_coefficient

    @property
    def n(self) -> float:
        return self.stiffness_pressure_exponent

    @property
    def r(self) -> float:
        return self.stiffness_density_exponent

    @property
    def N(self) -> float:  # noqa: N802 - the study's symbol
        return self.ncl_intercept

    @property
    def lambda_star(self) -> float:
        return self.compression_index

    @property
    def M(self) -> float:  # noqa: N802 - the study's symbol
        return self.critical_stress_ratio

    @property
    def c(self) -> float:
        return self.fabric_rate

    @property
    def s(self) -> float:
        return self.bound_rate

    @property
    def z(self) -> float:
        return self.bound_ratio

    @property
    def omega(self) -> float:
        return self.anisotropy_coefficient

    @property
    def energy_exponent(self) -> float:
        """X = r / ((n − 1) λ*), exponent of F(v) = (v/N)^X."""
        return self.r / ((self.n - 1.0) * self.lambda_star)

    @property
    def poisson_ratio(self) -> float:
        """Isotropic Poisson's ratio (3k − 2g)/(6k + 2g)."""
        return (3.0 * self.k - 2.0 * self.g) / (6.0 * self.k + 2.0 * self.g)

    @property
    def maximum_fabric(self) -> float:
        """M/z, the largest β_s the bounding law can reach."""
        return self.M / self.z

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def from_symbols(cls, values: Mapping[str, float]) -> Parameters:
        """Build from the study's symbols: p_r, g, k, n, r, N, lambda_star, M, c, s, z, omega."""
        by_symbol = {sym: name for name, sym in SYMBOLS.items()}
        unknown = sorted(set(values) - set(by_symbol))
        if unknown:
            raise ParameterError(
                f"unknown parameter symbol(s) {unknown}; allowed: {sorted(by_symbol)}"
            )
        missing = sorted(set(by_symbol) - set(values))
        if missing:
            raise ParameterError(f"missing parameter symbol(s) {missing}")
        return cls(**{by_symbol[sym]: val for sym, val in values.items()})

    def as_symbols(self) -> dict[str, float]:
        """The parameters keyed by the study's symbols."""
        return {sym: getattr(self, name) for name, sym in SYMBOLS.items()}

    def replace(self, **changes: float) -> Parameters:
        """A copy with some parameters changed (full names or symbols), validated again."""
        by_symbol = {sym: name for name, sym in SYMBOLS.items()}
        full = {by_symbol.get(key, key): val for key, val in changes.items()}
        unknown = sorted(set(full) - set(PARAMETER_INFO))
        if unknown:
            raise ParameterError(f"unknown parameter(s) {unknown}")
        return dataclasses.replace(self, **full)


#: Table 1 of the study (TIV parameters calibrated on its DEM).
TABLE1 = Parameters(
    reference_pressure=100.0,
    shear_stiffness_coefficient=48.0,
    bulk_stiffness_coefficient=64.0,
    stiffness_pressure_exponent=0.17,
    stiffness_density_exponent=0.63,
    ncl_intercept=1.3,
    compression_index=0.25,
    critical_stress_ratio=1.1,
    fabric_rate=1.2,
    bound_rate=14.0,
    bound_ratio=5.4,
    anisotropy_coefficient=25.0,
)

BoundLaw = Callable[[np.ndarray, Parameters], np.ndarray]


def exponential_bound(stress_ratio, params: Parameters) -> np.ndarray:
    """Default bound law, f(η) = (M/z)(1 − exp(−s η/M)) / η, vectorised over η ≥ 0.

    The bounding fabric tensor is β_b = f(η) s/p, i.e. β_b = (M/z)[1 − exp(−s η/M)] r̂
    (docs/science/tiv-model.md §2.3). Guarded at η → 0 by the series (M/z) a (1 − x/2 + x²/6 −
    x³/24), a = s/M, x = a η, so that β_b is smooth at isotropic states.
    """
    eta = np.asarray(stress_ratio, dtype=float)
    a = params.s / params.M
    x = a * eta
    small = x < 1e-4
    safe = np.where(small, 1.0, eta)
    series = a * (1.0 - x / 2.0 + x * x / 6.0 - x**3 / 24.0)
    exact = -np.expm1(-np.where(small, 0.0, x)) / safe
    return params.maximum_fabric * np.where(small, series, exact)


def hyperbolic_tangent_bound(stress_ratio, params: Parameters) -> np.ndarray:
    """Alternative bound law f(η) = (M/z) tanh(s η/M) / η (same limits as the default)."""
    eta = np.asarray(stress_ratio, dtype=float)
    a = params.s / params.M
    x = a * eta
    small = x < 1e-4
    safe = np.where(small, 1.0, eta)
    series = a * (1.0 - x * x / 3.0)
    exact = np.tanh(np.where(small, 0.0, x)) / safe
    return params.maximum_fabric * np.where(small, series, exact)


#: Named bound laws selectable from the command line.
BOUND_LAWS: dict[str, BoundLaw] = {
    "exponential": exponential_bound,
    "tanh": hyperbolic_tangent_bound,
}


@dataclass(frozen=True)
class ModelOptions:
    """The uncertain parts of the model (docs/science/tiv-model.md §2), with the documented
    defaults.

    anisotropy:        "A" (default) ε̃ = ε^e − ω β_s sym(β·ε^e); "B" ε̃ = ε^e − ω (β:ε^e) β.
    constraint_forces: True (default, exact theory): p̂ = p − Λ_K, A = p_c/2 + c φ_β:(β_b − β);
                       False: Λ_K = 0, A = p_c/2.
    bound_law:         callable (η array, params) ↦ f(η) with β_b = f(η) s/p; default
                       :func:`exponential_bound`.
    """

    anisotropy: str = "A"
    constraint_forces: bool = True
    bound_law: BoundLaw = field(default=exponential_bound)

    def __post_init__(self) -> None:
        if self.anisotropy not in ("A", "B"):
            raise ParameterError(
                f"option anisotropy = {self.anisotropy!r} is not allowed: use 'A' or 'B'"
            )
        if not isinstance(self.constraint_forces, bool):
            raise ParameterError(
                f"option constraint_forces must be True or False, got {self.constraint_forces!r}"
            )
        if not callable(self.bound_law):
            raise ParameterError(f"option bound_law must be callable, got {self.bound_law!r}")

    @property
    def bound_law_name(self) -> str:
        for name, law in BOUND_LAWS.items():
            if law is self.bound_law:
                return name
        return getattr(self.bound_law, "__name__", repr(self.bound_law))

    def describe(self) -> dict[str, Any]:
        return {
            "anisotropy": self.anisotropy,
            "constraint_forces": int(self.constraint_forces),
            "bound_law": self.bound_law_name,
        }


@dataclass(frozen=True)
class SolverSettings:
    """Tolerances of the implicit integration.

    tolerance:          relative tolerance of the local Newton residuals (strain-like, 1)
    stress_tolerance:   relative tolerance of the mixed-control stress residual (× max(p, 1 kPa))
    max_iterations:     Newton iterations per local solve
    max_halvings:       how many times an increment may be halved before giving up
    minimum_pressure:   p_min (kPa): a state with p below it is rejected
    triaxial_fast_path: use the scalar axisymmetric solver (:mod:`tiv_model.triaxial`) when
                        state and control are axisymmetric (same equations, ~20× faster)
    jacobian:           "analytic" (default): the exact Jacobian of the implicit update;
                        "finite_difference": forward differences (the scheme before issue 12,
                        kept as the reference the tests compare with)
    mixed_control:      "monolithic" (default): one Newton on the local unknowns with the
                        stress residuals in place of the stress-controlled strain residuals
                        (the nested scheme is tried if it fails); "nested": an outer Newton on
                        the unknown strain components around the local solve (before issue 12)
    """

    tolerance: float = 1e-11
    stress_tolerance: float = 1e-9
    max_iterations: int = 40
    max_outer_iterations: int = 25
    max_halvings: int = 12
    minimum_pressure: float = 1e-6
    triaxial_fast_path: bool = True
    jacobian: str = "analytic"
    mixed_control: str = "monolithic"

    def __post_init__(self) -> None:
        for name, allowed in (
            ("jacobian", ("analytic", "finite_difference")),
            ("mixed_control", ("monolithic", "nested")),
        ):
            if getattr(self, name) not in allowed:
                raise ParameterError(
                    f"solver setting {name} = {getattr(self, name)!r}: use one of {allowed}"
                )
        for name in ("tolerance", "stress_tolerance", "minimum_pressure"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
                raise ParameterError(f"solver setting {name} = {value!r} must be > 0")
        for name in ("max_iterations", "max_outer_iterations", "max_halvings"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 0):
                raise ParameterError(f"solver setting {name} = {value!r} must be an integer ≥ 0")


#: Module-level defaults (frozen, safe to share as default arguments).
DEFAULT_OPTIONS = ModelOptions()
DEFAULT_SETTINGS = SolverSettings()
