"""The history file's variables: one record per output step along the unlimited ``time``.

Units and symbols: see :mod:`dem_taichi.io.schema`.
"""

from __future__ import annotations

from collections.abc import Mapping

from .stages import STAGE_CODES
from .variable import COMPRESSION_POSITIVE, Variable, variable_table

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
        definition="protocol stage the record belongs to (docs/science/dem-model.md §1.6)",
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

HISTORY: Mapping[str, Variable] = variable_table(HISTORY_VARIABLES)

#: Written by runs of bonded rods only (``[particles] rod_model = "bonded"``,
#: docs/science/dem-model.md §1.7);
#: there the stress, the unbalanced-force ratio and the kinetic energy also count the bonds and
#: the disc bodies.
BONDED_HISTORY_VARIABLES: tuple[Variable, ...] = (
    Variable(
        "bond_energy",
        TIME,
        "1",
        "elastic energy of the intra-rod bonds",
        dem_units="energy",
        definition="sum over intact bonds of 1/2 (k_bn e_n^2 + k_bt e_t^2 + kappa_b e_b^2) "
        "(stretch, shear and bending measures of dem_taichi.physics.bonds)",
    ),
    Variable(
        "n_broken_bonds",
        TIME,
        "1",
        "number of broken intra-rod bonds",
        dtype="i8",
        definition="bonds whose tension k_bn e_n exceeded [bonds] breakage_force (broken for "
        "good; the two discs then interact as any other pair)",
    ),
)
