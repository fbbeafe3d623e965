"""Sweeps: many protocol runs over scene keys on Dask (:mod:`~dem_taichi.sweep.command`), their
spec, client, members and results.
"""

from dem_taichi._moved import forward_attributes

#: the names of the former module ``dem_taichi.sweep`` (now :mod:`dem_taichi.sweep.command`)
__getattr__ = forward_attributes(__name__)
