"""Numpy-only analysis of DEM results: the findings over arrays (:mod:`~dem_taichi.analysis.arrays`)
and over a run directory (:mod:`~dem_taichi.analysis.findings`), the mapped window
(:mod:`~dem_taichi.analysis.mapped_window`) and figures. No Taichi; imports
:mod:`dem_taichi.io` and :mod:`dem_taichi.scene` below it, never the engine.
"""

from dem_taichi._moved import forward_attributes

#: the names of the former module ``dem_taichi.analysis`` (now :mod:`dem_taichi.analysis.arrays`)
__getattr__ = forward_attributes(__name__)
