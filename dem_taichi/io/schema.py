"""One place that spells every variable of the DEM results files.

Three kinds of file are written by :mod:`dem_taichi.io.writers`:

- the **history** (one record per output step along the unlimited dimension ``time``),
- the **probes** dataset (dimensions ``probe``, ``amplitude``, ``voigt_i``, ``voigt_j``),
- saved **configurations** at chosen states (dimensions ``rod``, ``xy``).

Unit system (DEM units)
-----------------------
The engine works in a dimensionless system: the disc diameter d = 1 is the unit of length, the
disc mass m = 1 is the unit of mass, and the scene's time unit t0 is the unit of time (so the
force unit is m d / t0²). In 2D the stress is a force per unit length (m / t0²), an energy is a
force times a length. UDUNITS has no symbol for such a system, so every DEM quantity carries
``units = "1"`` (CF: dimensionless) and an extra attribute ``dem_units`` naming the DEM dimension
(``"length"``, ``"time"``, ``"1/time"``, ``"force/length"``, ``"energy"``...). A consumer that
wants physical units multiplies by a stated scale (e.g. the bridge's stress scale to kPa).

Symbols used in the definitions
-------------------------------
=========  ==========================================================================
σ_ab       Cauchy stress, 2D (force/length), compression positive
p, q       mean stress (σ_xx + σ_yy)/2 and deviatoric stress σ_yy − σ_xx (2D)
L_x, L_y   cell lengths; A = L_x L_y the cell area; L0 the reference length
ε_ab       logarithmic strain, compression positive: ε = −ln(L / L0)
v, e       specific volume A / A_solid and void ratio v − 1
β          rod-orientation fabric (1/N) Σ a ⊗ a, a the unit rod axis (tr β = 1)
Z, Z_m     coordination number (all rods) and mechanical coordination (rattlers removed)
I          inertial number max(|ε̇_xx|, |ε̇_yy|) d sqrt(ρ / p)
C_ij       2D stiffness in Voigt notation (xx, yy, xy), σ_i = C_ij ε_j, γ_xy = 2 ε_xy
=========  ==========================================================================

Sources: ``/work/shared/design/model.md`` §1.4–1.6 and the project's DEM interfaces note.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

#: Text stored as a global attribute so a file explains its own units.
DEM_UNIT_SYSTEM = (
    "dimensionless DEM units: length unit d = 1 (disc diameter), mass unit m = 1 (disc mass), "
    "time unit t0 = the scene's time unit; force unit m d / t0^2; 2D stress in force/length; "
    "every DEM quantity has units = '1' and its DEM dimension in the attribute dem_units"
)

COMPRESSION_POSITIVE = "compression_positive"

#: numpy dtype strings allowed in the schema ("str" is a variable-length string).
ALLOWED_DTYPES = ("f8", "f4", "i8", "i4", "i1", "str")

#: Fill values by dtype (NaN for floats, the most negative integer for integers).
FILL_VALUES: Mapping[str, Any] = MappingProxyType(
    {
        "f8": np.float64(np.nan),
        "f4": np.float32(np.nan),
        "i8": np.int64(np.iinfo(np.int64).min),
        "i4": np.int32(np.iinfo(np.int32).min),
        "i1": np.int8(-128),
        "str": "",
    }
)


@dataclass(frozen=True)
class Variable:
    """How one variable is spelled in a results file.

    ``units`` is a UDUNITS string (``"1"`` for dimensionless and for all DEM-unit quantities);
    ``dem_units`` names the DEM dimension of a DEM-unit quantity (empty for pure numbers).
    ``definition`` is given where several definitions exist in the literature (p and q in 2D,
    fabric, strains, coordination...). ``sign_convention`` is ``"compression_positive"`` for
    stresses, strains and strain rates. ``flag_values``/``flag_meanings`` follow CF §3.5.
    """

    name: str
    dims: tuple[str, ...]
    units: str
    long_name: str
    definition: str = ""
    dtype: str = "f8"
    sign_convention: str = ""
    dem_units: str = ""
    flag_values: tuple[int, ...] = ()
    flag_meanings: tuple[str, ...] = ()
    extra_attrs: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"variable name {self.name!r} must be an identifier")
        if self.dtype not in ALLOWED_DTYPES:
            raise ValueError(
                f"variable {self.name!r}: dtype {self.dtype!r} not allowed; use one of "
                f"{ALLOWED_DTYPES}"
            )
        if not self.units:
            raise ValueError(f"variable {self.name!r}: units must be a UDUNITS string, e.g. '1'")
        if len(self.flag_values) != len(self.flag_meanings):
            raise ValueError(
                f"variable {self.name!r}: {len(self.flag_values)} flag_values but "
                f"{len(self.flag_meanings)} flag_meanings"
            )
        for meaning in self.flag_meanings:
            if not meaning or any(ch.isspace() for ch in meaning):
                raise ValueError(
                    f"variable {self.name!r}: flag meaning {meaning!r} must be one word"
                )
        if self.sign_convention not in ("", COMPRESSION_POSITIVE):
            raise ValueError(
                f"variable {self.name!r}: sign_convention {self.sign_convention!r}; allowed: "
                f"'' or {COMPRESSION_POSITIVE!r}"
            )
        object.__setattr__(self, "dims", tuple(self.dims))
        object.__setattr__(self, "extra_attrs", MappingProxyType(dict(self.extra_attrs)))

    @property
    def numpy_dtype(self) -> np.dtype:
        """numpy dtype of the stored values (object for strings)."""
        return np.dtype(object) if self.dtype == "str" else np.dtype(self.dtype)

    @property
    def fill_value(self) -> Any:
        """The value stored where a record lacks this variable."""
        return FILL_VALUES[self.dtype]

    def attrs(self) -> dict[str, Any]:
        """The netCDF attributes of this variable (without ``_FillValue``)."""
        out: dict[str, Any] = {"units": self.units, "long_name": self.long_name}
        if self.dem_units:
            out["dem_units"] = self.dem_units
        if self.definition:
            out["definition"] = self.definition
        if self.sign_convention:
            out["sign_convention"] = self.sign_convention
        if self.flag_values:
            out["flag_values"] = np.array(self.flag_values, dtype=self.numpy_dtype)
            out["flag_meanings"] = " ".join(self.flag_meanings)
        out.update(self.extra_attrs)
        return out


def _by_name(variables: tuple[Variable, ...]) -> Mapping[str, Variable]:
    names = [v.name for v in variables]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"duplicate variable names in schema: {duplicates}")
    return MappingProxyType({v.name: v for v in variables})


# ---------------------------------------------------------------------------------------------
# Stages of a run (the `stage` history variable)
# ---------------------------------------------------------------------------------------------

#: Stage labels and their integer codes, in the order of the protocol (model.md §1.6).
STAGE_CODES: Mapping[str, int] = MappingProxyType(
    {
        "gas": 0,
        "isotropic_to_A": 1,
        "A_to_B": 2,
        "A_to_C": 3,
        "C_to_B": 4,
        "radial": 5,
        "relax": 6,
        "probe": 7,
        "other": 8,
    }
)
STAGE_LABELS: Mapping[int, str] = MappingProxyType({c: s for s, c in STAGE_CODES.items()})


def stage_code(label: str) -> int:
    """Integer code of a stage label; unknown labels fail naming the allowed ones."""
    try:
        return STAGE_CODES[label]
    except KeyError:
        raise ValueError(f"unknown stage {label!r}; allowed: {', '.join(STAGE_CODES)}") from None


def stage_label(code: int) -> str:
    """Stage label of an integer code; unknown codes fail naming the allowed ones."""
    try:
        return STAGE_LABELS[int(code)]
    except KeyError:
        raise ValueError(f"unknown stage code {code!r}; allowed: {dict(STAGE_LABELS)}") from None


# ---------------------------------------------------------------------------------------------
# History (dimension `time`, unlimited)
# ---------------------------------------------------------------------------------------------

TIME = ("time",)

_STRESS_DEF = (
    "sigma = (1/A) sum over inter-rod disc pairs of f_ij (x) (X_P - X_Q - shift): f_ij total "
    "force (contact, friction, long-range) on disc i of rod P from disc j of rod Q, branch vector "
    "between rod centroids (minimum image), A = L_x L_y; no kinetic term"
)

HISTORY_VARIABLES: tuple[Variable, ...] = (
    Variable(
        "step",
        TIME,
        "1",
        "time step index",
        dtype="i8",
        definition="number of integration steps since the start of the run",
    ),
    Variable(
        "time",
        TIME,
        "1",
        "simulated time",
        dem_units="time",
        definition="step * dt summed over the run (dt may change between stages)",
    ),
    Variable(
        "stage",
        TIME,
        "1",
        "stage of the virtual experiment",
        dtype="i4",
        definition="protocol stage the record belongs to (model.md 1.6)",
        flag_values=tuple(STAGE_CODES.values()),
        flag_meanings=tuple(STAGE_CODES),
    ),
    Variable("cell_length_x", TIME, "1", "periodic cell length along x", dem_units="length"),
    Variable("cell_length_y", TIME, "1", "periodic cell length along y", dem_units="length"),
    Variable(
        "strain_xx",
        TIME,
        "1",
        "horizontal logarithmic strain",
        definition="epsilon_xx = -ln(L_x / L0_x), L0 the cell length at the strain reference "
        "(start of the run unless the global attribute strain_reference says otherwise)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "strain_yy",
        TIME,
        "1",
        "vertical logarithmic strain",
        definition="epsilon_yy = -ln(L_y / L0_y), L0 the cell length at the strain reference "
        "(start of the run unless the global attribute strain_reference says otherwise)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "strain_rate_xx",
        TIME,
        "1",
        "horizontal cell strain rate",
        dem_units="1/time",
        definition="d(epsilon_xx)/dt = -(dL_x/dt) / L_x",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "strain_rate_yy",
        TIME,
        "1",
        "vertical cell strain rate",
        dem_units="1/time",
        definition="d(epsilon_yy)/dt = -(dL_y/dt) / L_y",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "stress_xx",
        TIME,
        "1",
        "horizontal normal stress",
        dem_units="force/length",
        definition=_STRESS_DEF + "; component xx",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "stress_yy",
        TIME,
        "1",
        "vertical normal stress",
        dem_units="force/length",
        definition=_STRESS_DEF + "; component yy",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "stress_xy",
        TIME,
        "1",
        "shear stress",
        dem_units="force/length",
        definition=_STRESS_DEF + "; symmetric part (sigma_xy + sigma_yx) / 2",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "mean_stress",
        TIME,
        "1",
        "mean stress p (2D)",
        dem_units="force/length",
        definition="p = (sigma_xx + sigma_yy) / 2 (2D mean of the in-plane normal stresses)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "deviatoric_stress",
        TIME,
        "1",
        "deviatoric stress q (2D)",
        dem_units="force/length",
        definition="q = sigma_yy - sigma_xx (vertical minus horizontal)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "specific_volume",
        TIME,
        "1",
        "specific volume v",
        definition="v = A / A_solid, A = L_x L_y, A_solid = n_rods * (n_s pi d^2 / 4 minus the "
        "lens overlaps of neighbouring discs of a rod when spacing < d)",
    ),
    Variable("void_ratio", TIME, "1", "void ratio e", definition="e = v - 1"),
    Variable(
        "fabric_xx",
        TIME,
        "1",
        "rod-orientation fabric, xx component",
        definition="beta = (1/N) sum over rods of a (x) a, a = (cos theta, sin theta) the unit "
        "rod axis; tr beta = 1, isotropic beta = I/2",
    ),
    Variable(
        "fabric_yy",
        TIME,
        "1",
        "rod-orientation fabric, yy component",
        definition="beta = (1/N) sum over rods of a (x) a, a the unit rod axis; component yy",
    ),
    Variable(
        "fabric_xy",
        TIME,
        "1",
        "rod-orientation fabric, xy component",
        definition="beta = (1/N) sum over rods of a (x) a, a the unit rod axis; component xy",
    ),
    Variable(
        "fabric_deviator",
        TIME,
        "1",
        "rod-orientation fabric deviator",
        definition="beta_yy - beta_xx (vertical minus horizontal; negative when rods lie down); "
        "sampling noise for N random rods sqrt(0.5/N)",
    ),
    Variable(
        "coordination_number",
        TIME,
        "1",
        "coordination number Z (rattlers included)",
        definition="Z = 2 n_contacts / N_rod: touching inter-rod disc pairs per rod, over all "
        "rods including rattlers",
    ),
    Variable(
        "mechanical_coordination_number",
        TIME,
        "1",
        "mechanical coordination number Z_m (rattlers removed)",
        definition="Z_m = 2 C_m / N_m: touching inter-rod disc pairs per rod over the N_m "
        "non-rattler rods, rattlers being rods with fewer than 2 touching disc pairs, removed "
        "with their contacts iteratively until none is left; 0 when N_m = 0",
    ),
    Variable(
        "n_contacts",
        TIME,
        "1",
        "number of contacts",
        dtype="i8",
        definition="inter-rod disc pairs in contact (overlap delta > 0)",
    ),
    Variable(
        "n_long_range_pairs",
        TIME,
        "1",
        "number of long-range interacting pairs",
        dtype="i8",
        definition="inter-rod disc pairs with a non-zero long-range force (charge product != 0 "
        "or van der Waals term on, and gap g <= g_max), touching pairs included",
    ),
    Variable(
        "kinetic_energy",
        TIME,
        "1",
        "kinetic energy of the fluctuating motion",
        dem_units="energy",
        definition="sum over rods of 1/2 M |v - v_affine|^2 + 1/2 J omega^2 (velocity relative "
        "to the affine cell flow)",
    ),
    Variable(
        "contact_energy",
        TIME,
        "1",
        "elastic energy of the contact springs",
        dem_units="energy",
        definition="sum over touching inter-rod disc pairs of 1/2 k_n delta^2 + 1/2 k_t |xi|^2",
    ),
    Variable(
        "long_range_energy",
        TIME,
        "1",
        "potential energy of the long-range forces",
        dem_units="energy",
        definition="sum over inter-rod disc pairs of U: s*1/2 k_a (g_max - g)^2 for "
        "0 < g <= g_max, s*(1/2 k_a g_max^2 + F_max delta) for delta >= 0, 0 beyond, s = c_i c_j "
        "(van der Waals term included with s = -1)",
    ),
    Variable(
        "unbalanced_force_ratio",
        TIME,
        "1",
        "unbalanced-force ratio",
        definition="mean over rods of |net force on the rod| divided by the mean over "
        "interacting inter-rod disc pairs of |pair force| (0 at static equilibrium)",
    ),
    Variable(
        "inertial_number",
        TIME,
        "1",
        "inertial number I",
        definition="I = max(|strain_rate_xx|, |strain_rate_yy|) d sqrt(rho / p), rho = rod "
        "mass / rod solid area (2D density), p the mean stress; NaN when p <= 0",
    ),
)

HISTORY: Mapping[str, Variable] = _by_name(HISTORY_VARIABLES)


# ---------------------------------------------------------------------------------------------
# Probes (dimensions probe, amplitude, voigt_i, voigt_j)
# ---------------------------------------------------------------------------------------------

PROBE = ("probe",)
VOIGT_ORDER = ("xx", "yy", "xy")
_VOIGT = {"voigt_order": " ".join(VOIGT_ORDER)}
_E_DYN = (
    "elastic plateau of the dynamic-probe degradation curve {curve} (rule in the dataset "
    "attribute plateau_rule)"
)
_E_OED = (
    "{sym} = d sigma_{a}{a} / d epsilon_{a}{a} with the other axis fixed (constrained modulus), "
    "average of +/- probes, relaxed to equilibrium"
)

PROBE_VARIABLES: tuple[Variable, ...] = (
    Variable(
        "state_label",
        PROBE,
        "1",
        "label of the probed state",
        dtype="str",
        definition="e.g. A, B, C or PATH_k for the k-th probe along a path",
    ),
    Variable(
        "path",
        PROBE,
        "1",
        "stage (path) along which the state lies",
        dtype="str",
        definition="one of the stage labels: " + " ".join(STAGE_CODES),
    ),
    Variable("step", PROBE, "1", "time step index of the probed state", dtype="i8"),
    Variable(
        "stress_xx",
        PROBE,
        "1",
        "horizontal normal stress at the probed state",
        dem_units="force/length",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "stress_yy",
        PROBE,
        "1",
        "vertical normal stress at the probed state",
        dem_units="force/length",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "mean_stress",
        PROBE,
        "1",
        "mean stress p (2D) at the probed state",
        dem_units="force/length",
        definition="p = (sigma_xx + sigma_yy) / 2",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "deviatoric_stress",
        PROBE,
        "1",
        "deviatoric stress q (2D) at the probed state",
        dem_units="force/length",
        definition="q = sigma_yy - sigma_xx",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "specific_volume",
        PROBE,
        "1",
        "specific volume v at the probed state",
        definition="v = A / A_solid",
    ),
    Variable(
        "fabric_deviator",
        PROBE,
        "1",
        "rod-orientation fabric deviator at the probed state",
        definition="beta_yy - beta_xx, beta = (1/N) sum a (x) a",
    ),
    Variable(
        "e_oed_v_dynamic",
        PROBE,
        "1",
        "vertical constrained modulus, dynamic probe",
        dem_units="force/length",
        definition=_E_OED.format(sym="E_oed,v", a="y")
        + "; "
        + _E_DYN.format(curve="e_oed_v_of_amplitude"),
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "e_oed_h_dynamic",
        PROBE,
        "1",
        "horizontal constrained modulus, dynamic probe",
        dem_units="force/length",
        definition=_E_OED.format(sym="E_oed,h", a="x")
        + "; "
        + _E_DYN.format(curve="e_oed_h_of_amplitude"),
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "e_oed_v_linear",
        PROBE,
        "1",
        "vertical constrained modulus, linear response",
        dem_units="force/length",
        definition="E_oed,v = C_yyyy = C_22 of stiffness_tensor_linear (zero amplitude)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "e_oed_h_linear",
        PROBE,
        "1",
        "horizontal constrained modulus, linear response",
        dem_units="force/length",
        definition="E_oed,h = C_xxxx = C_11 of stiffness_tensor_linear (zero amplitude)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "bulk_modulus_linear",
        PROBE,
        "1",
        "2D bulk modulus, linear response",
        dem_units="force/length",
        definition="K = dp / d(epsilon_xx + epsilon_yy) under isotropic strain "
        "= (C_11 + C_12 + C_21 + C_22) / 4",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "shear_modulus_linear",
        PROBE,
        "1",
        "2D shear modulus, linear response",
        dem_units="force/length",
        definition="G = d sigma_xy / d gamma_xy = C_33 (symmetric shear strain "
        "epsilon_xy = epsilon_yx = gamma_xy / 2, sigma_xy the symmetric part)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "pure_shear_modulus_linear",
        PROBE,
        "1",
        "2D pure-shear modulus, linear response",
        dem_units="force/length",
        definition="G_q = 1/2 d(sigma_xx - sigma_yy) / d(epsilon_xx - epsilon_yy) "
        "= (C_11 + C_22 - C_12 - C_21) / 4 (the modulus of q in 2D)",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "stiffness_tensor_linear",
        ("probe", "voigt_i", "voigt_j"),
        "1",
        "2D elastic stiffness tensor, linear response",
        dem_units="force/length",
        definition="C_ij with d sigma_i = C_ij d epsilon_j, Voigt order (xx, yy, xy), "
        "engineering shear strain gamma_xy = 2 epsilon_xy, non-affine relaxation of the "
        "interaction network included",
        sign_convention=COMPRESSION_POSITIVE,
        extra_attrs=_VOIGT,
    ),
    Variable(
        "amplitude",
        ("amplitude",),
        "1",
        "strain amplitude of the dynamic probes",
        definition="|delta epsilon| applied affinely along the probed axis",
    ),
    Variable(
        "e_oed_v_of_amplitude",
        ("probe", "amplitude"),
        "1",
        "vertical constrained modulus against probe amplitude",
        dem_units="force/length",
        definition="secant (sigma_yy(+d) - sigma_yy(-d)) / (2 d) with epsilon_xx fixed, relaxed",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "e_oed_h_of_amplitude",
        ("probe", "amplitude"),
        "1",
        "horizontal constrained modulus against probe amplitude",
        dem_units="force/length",
        definition="secant (sigma_xx(+d) - sigma_xx(-d)) / (2 d) with epsilon_yy fixed, relaxed",
        sign_convention=COMPRESSION_POSITIVE,
    ),
    Variable(
        "e_oed_v_elastic_limit",
        PROBE,
        "1",
        "largest vertical probe amplitude on the elastic plateau",
        definition="largest amplitude of e_oed_v_of_amplitude on the plateau picked by the rule "
        "in the dataset attribute plateau_rule",
    ),
    Variable(
        "e_oed_h_elastic_limit",
        PROBE,
        "1",
        "largest horizontal probe amplitude on the elastic plateau",
        definition="largest amplitude of e_oed_h_of_amplitude on the plateau picked by the rule "
        "in the dataset attribute plateau_rule",
    ),
)

PROBES: Mapping[str, Variable] = _by_name(PROBE_VARIABLES)


# ---------------------------------------------------------------------------------------------
# Saved configurations (states A, B, C...)
# ---------------------------------------------------------------------------------------------

CONFIGURATION_VARIABLES: tuple[Variable, ...] = (
    Variable(
        "rod_position",
        ("rod", "xy"),
        "1",
        "rod centroid position",
        dem_units="length",
        definition="centroid X_r of rod r inside the cell [0, L_x) x [0, L_y); xy = (x, y)",
    ),
    Variable(
        "rod_angle",
        ("rod",),
        "radian",
        "rod axis angle",
        definition="theta_r, rod axis a_r = (cos theta, sin theta), counter-clockwise from x",
    ),
    Variable(
        "cell_lengths",
        ("xy",),
        "1",
        "periodic cell lengths",
        dem_units="length",
        definition="(L_x, L_y)",
    ),
)

CONFIGURATION: Mapping[str, Variable] = _by_name(CONFIGURATION_VARIABLES)


def variables_by_name(
    variables: tuple[Variable, ...] | Mapping[str, Variable],
) -> dict[str, Variable]:
    """Name → Variable for a tuple or mapping of variables (duplicates rejected)."""
    if isinstance(variables, Mapping):
        return dict(variables)
    return dict(_by_name(tuple(variables)))
