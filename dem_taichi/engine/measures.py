"""The history record of one state: :class:`Measures`, what ``Simulation.measure()`` returns.

:func:`history_record` builds it from the measure kernel's sums. A ``TypedDict``: at run time a
plain ``dict`` (so records go unchanged to the history writers, JSON, ``|`` merges and other
processes), to a type checker a record whose every key and value type is declared, so a
misspelt key is an error before the run. The keys are the history variables of
:data:`dem_taichi.io.schema.HISTORY` (names, units and definitions there; a test checks the two
agree and that the engine fills every key).

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, q = σ_yy − σ_xx,
ε logarithmic strain (compression positive), v specific volume, Z (Z_m) (mechanical)
coordination number, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

import math
from typing import TypedDict

import numpy as np

from dem_taichi.kernels import layout as L

__all__ = ["BondedMeasures", "Measures", "history_record"]


class Measures(TypedDict):
    """One history record (DEM units; see the module docstring)."""

    step: int  # steps since the start of the run
    time: float
    stage: int  # code of dem_taichi.io.schema.STAGE_CODES
    cell_length_x: float
    cell_length_y: float
    strain_xx: float  # −ln(L_x/L_x0)
    strain_yy: float
    strain_rate_xx: float  # ε̇ of the last chunk
    strain_rate_yy: float
    stress_xx: float
    stress_yy: float
    stress_xy: float
    mean_stress: float  # p
    deviatoric_stress: float  # q
    specific_volume: float  # v
    void_ratio: float  # v − 1
    fabric_xx: float
    fabric_yy: float
    fabric_xy: float
    fabric_deviator: float  # β_yy − β_xx
    coordination_number: float  # Z
    mechanical_coordination_number: float  # Z_m, rattlers removed
    n_contacts: int
    n_long_range_pairs: int
    kinetic_energy: float
    contact_energy: float
    long_range_energy: float
    unbalanced_force_ratio: float  # UFR
    inertial_number: float  # I (NaN at p = 0)


class BondedMeasures(Measures, total=False):
    """The record of a simulation of bonded rods: :class:`Measures` and the variables of
    :data:`dem_taichi.io.history_schema.BONDED_HISTORY_VARIABLES`."""

    bond_energy: float  # Σ ½ k e² over the intact bonds
    n_broken_bonds: int


def history_record(
    sums: np.ndarray,
    stress: np.ndarray,
    lengths: np.ndarray,
    reference_lengths: np.ndarray,
    rates: np.ndarray,
    angles: np.ndarray,
    geometry,
    n_rods: int,
    step: int,
    time: float,
    stage: int,
    mechanical_coordination: float,
    n_bodies: int | None = None,
    n_bonds: int = 0,
) -> BondedMeasures:
    """The history record from the measure kernel's ``sums`` (slots ``layout.M_*``), the
    ``stress`` tensor (2, 2), the cell ``lengths`` and ``reference_lengths`` (L0 of the
    strains), the strain ``rates`` of the last chunk, the rod ``angles``, the rod ``geometry``
    and the counters; definitions of every entry in :data:`dem_taichi.io.schema.HISTORY`.
    ``n_bodies`` (default ``n_rods``) and ``n_bonds`` (intact bonds) of bonded rods enter the
    unbalanced-force ratio: mean body force over mean force of the pairs and bonds. Typed
    :class:`BondedMeasures`, whose bonded variables the caller adds for bonded rods."""
    area = float(np.prod(lengths))
    p = 0.5 * (stress[0, 0] + stress[1, 1])
    q = stress[1, 1] - stress[0, 0]
    v = area / (n_rods * geometry.solid_area)
    c, s = np.cos(angles), np.sin(angles)
    fxx, fyy, fxy = float(np.mean(c * c)), float(np.mean(s * s)), float(np.mean(c * s))
    n_contacts = int(round(sums[L.M_CONTACTS]))
    n_pairs = sums[L.M_INTERACTING] + n_bonds
    mean_pair = sums[L.M_SUM_PAIR_FORCE] / n_pairs if n_pairs > 0 else 0.0
    mean_rod = sums[L.M_SUM_ROD_FORCE] / (n_rods if n_bodies is None else n_bodies)
    unbalanced = mean_rod / mean_pair if mean_pair > 0 else float("nan")
    rho = geometry.mass / geometry.solid_area
    rate = float(np.max(np.abs(rates)))
    inertial = rate * geometry.diameter * math.sqrt(rho / p) if p > 0 else float("nan")
    return {
        "step": int(step),
        "time": time,
        "stage": stage,
        "cell_length_x": float(lengths[0]),
        "cell_length_y": float(lengths[1]),
        "strain_xx": float(-math.log(lengths[0] / reference_lengths[0])),
        "strain_yy": float(-math.log(lengths[1] / reference_lengths[1])),
        "strain_rate_xx": float(rates[0]),
        "strain_rate_yy": float(rates[1]),
        "stress_xx": float(stress[0, 0]),
        "stress_yy": float(stress[1, 1]),
        "stress_xy": float(0.5 * (stress[0, 1] + stress[1, 0])),
        "mean_stress": float(p),
        "deviatoric_stress": float(q),
        "specific_volume": float(v),
        "void_ratio": float(v - 1.0),
        "fabric_xx": fxx,
        "fabric_yy": fyy,
        "fabric_xy": fxy,
        "fabric_deviator": fyy - fxx,
        "coordination_number": 2.0 * n_contacts / n_rods,
        "mechanical_coordination_number": mechanical_coordination,
        "n_contacts": n_contacts,
        "n_long_range_pairs": int(round(sums[L.M_LONG_PAIRS])),
        "kinetic_energy": float(sums[L.M_KE_TRANS] + sums[L.M_KE_ROT]),
        "contact_energy": float(sums[L.M_U_CONTACT]),
        "long_range_energy": float(sums[L.M_U_LONG]),
        "unbalanced_force_ratio": float(unbalanced),
        "inertial_number": float(inertial),
    }
