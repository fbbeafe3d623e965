"""The variables of a saved configuration (states A, B, C...; dimensions ``rod``, ``xy``).

Units and symbols: see :mod:`dem_taichi.io.schema`.
"""

from __future__ import annotations

from collections.abc import Mapping

from .variable import Variable, variable_table

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

CONFIGURATION: Mapping[str, Variable] = variable_table(CONFIGURATION_VARIABLES)
