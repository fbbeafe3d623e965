"""The history record of one state: :class:`Measures`, what ``Simulation.measure()`` returns.

A ``TypedDict``: at run time a plain ``dict`` (so records go unchanged to the history writers,
JSON, ``|`` merges and other processes), to a type checker a record whose every key and value
type is declared, so a misspelt key is an error before the run. The keys are the history
variables of :data:`dem_taichi.io.schema.HISTORY` (names, units and definitions there; a test
checks the two agree and that the engine fills every key).

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, q = σ_yy − σ_xx,
ε logarithmic strain (compression positive), v specific volume, Z (Z_m) (mechanical)
coordination number, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

from typing import TypedDict

__all__ = ["Measures"]


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
