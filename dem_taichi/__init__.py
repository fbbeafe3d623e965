"""Taichi DEM engine for 2D assemblies of rigid rods made of discs, with clay long-range forces.

Importing this package does not initialise Taichi; only :mod:`dem_taichi.runtime` calls ``ti.init``.
"""

__version__ = "0.1.0"
