"""Hyperplastic (TIV) anisotropic clay model: potentials, integration, element tests.

Usable on its own: this package imports neither Taichi nor ``dem_taichi`` nor ``bridge``.
"""

__version__ = "0.1.0"
