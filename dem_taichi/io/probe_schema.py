"""The probes dataset's variables (dimensions ``probe``, ``amplitude``, ``voigt_i``, ``voigt_j``).

Units and symbols: see :mod:`dem_taichi.io.schema`.
"""

from __future__ import annotations

from collections.abc import Mapping

from .stages import STAGE_CODES
from .variable import COMPRESSION_POSITIVE, Variable, variable_table

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

PROBES: Mapping[str, Variable] = variable_table(PROBE_VARIABLES)
