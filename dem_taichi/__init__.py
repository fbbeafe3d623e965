"""Taichi DEM engine for 2D assemblies of rods made of discs (rigid or bonded), with the
electro-chemical long-range forces of clay.

Importing this package does not initialise Taichi; only :mod:`dem_taichi.engine.runtime` calls
``ti.init`` (when a :class:`Simulation` is built). The public API::

    from dem_taichi import Simulation, load_scene, run_protocol
    sim = Simulation("smoke")                      # a built-in scene name, a TOML path or a Scene
    sim.run(1000)
    result = run_protocol("smoke", "runs/smoke")   # the virtual experiments
"""

from __future__ import annotations

from dem_taichi import _moved

__version__ = "0.1.0"

_moved.install()  # the old module paths (dem_taichi.forcelaw, ...) for one more release

__all__ = ["CellControl", "Scene", "SceneError", "Simulation", "load_scene", "run_protocol"]

#: public name -> module that defines it (imported on first use: ``import dem_taichi`` stays light)
_EXPORTS = {
    "CellControl": "dem_taichi.engine.control",
    "Scene": "dem_taichi.scene.config",
    "SceneError": "dem_taichi.scene.config",
    "Simulation": "dem_taichi.engine.simulation",
    "load_scene": "dem_taichi.scene.config",
    "run_protocol": "dem_taichi.protocol.runner",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'dem_taichi' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
