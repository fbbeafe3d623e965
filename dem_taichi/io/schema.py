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

Sources: docs/science/dem-model.md §1.4–§1.6 and §1.8.

Where each part lives (every name stays importable from here)
--------------------------------------------------------------
- :mod:`.variable`: the :class:`Variable` record, dtypes and fill values, the unit-system text;
- :mod:`.stages`: the stage labels and codes of the ``stage`` variable;
- :mod:`.history_schema`, :mod:`.probe_schema`, :mod:`.configuration_schema`: the variables of
  each kind of file.
"""

from __future__ import annotations

from .configuration_schema import CONFIGURATION, CONFIGURATION_VARIABLES
from .history_schema import HISTORY, HISTORY_VARIABLES, TIME
from .probe_schema import PROBE, PROBE_VARIABLES, PROBES, VOIGT_ORDER
from .stages import STAGE_CODES, STAGE_LABELS, stage_code, stage_label
from .variable import (
    ALLOWED_DTYPES,
    COMPRESSION_POSITIVE,
    DEM_UNIT_SYSTEM,
    FILL_VALUES,
    Variable,
    variable_table,
    variables_by_name,
)

__all__ = [
    "ALLOWED_DTYPES",
    "COMPRESSION_POSITIVE",
    "CONFIGURATION",
    "CONFIGURATION_VARIABLES",
    "DEM_UNIT_SYSTEM",
    "FILL_VALUES",
    "HISTORY",
    "HISTORY_VARIABLES",
    "PROBE",
    "PROBES",
    "PROBE_VARIABLES",
    "STAGE_CODES",
    "STAGE_LABELS",
    "TIME",
    "VOIGT_ORDER",
    "Variable",
    "stage_code",
    "stage_label",
    "variable_table",
    "variables_by_name",
]
