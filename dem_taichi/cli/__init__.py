"""The command line ``python -m dem_taichi run|protocol|sweep|snapshot|anisotropy ...``
(:mod:`~dem_taichi.cli.commands`; the console script ``dem-taichi``).
"""

from dem_taichi._moved import forward_attributes
from dem_taichi.cli.commands import main

__all__ = ["main"]

#: the other names of the former module ``dem_taichi.cli`` (now :mod:`dem_taichi.cli.commands`)
__getattr__ = forward_attributes(__name__)
