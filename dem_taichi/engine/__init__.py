"""The DEM engine: :class:`~dem_taichi.engine.simulation.Simulation`, its state and views, the
device arrays, the Taichi runtime, cell control, the history measures, the work ledger and the
engine's errors.

Imports :mod:`dem_taichi.scene`, :mod:`dem_taichi.io`, :mod:`dem_taichi.kernels` and
:mod:`dem_taichi.physics` below it; nothing above.
"""

from dem_taichi._moved import forward_attributes

#: the names of the former module ``dem_taichi.engine`` (now :mod:`dem_taichi.engine.simulation`)
__getattr__ = forward_attributes(__name__)
