"""Old module paths of ``dem_taichi`` (the flat layout of 0.1.0), kept for one release.

Up to 0.1.0 the package was one flat folder (``dem_taichi.forcelaw``, ``dem_taichi.engine``,
``dem_taichi.sweep_results``, ...). :data:`MOVED` maps each old module to its new one; importing
an old path gives the new module (the same object, so a patch of one is a patch of the other)
and a :class:`DeprecationWarning` that names the new path. Two cases:

- an old name that is no module any more (``dem_taichi.forcelaw``): :class:`MovedFinder`, a
  finder on :data:`sys.meta_path` installed by ``import dem_taichi``, aliases it to the new
  module (``python -m dem_taichi.anisotropy`` runs the new module too);
- an old module whose name is now a subpackage's (``dem_taichi.engine``, ``protocol``, ``sweep``,
  ``analysis``, ``cli``, ``scene``): the subpackage's ``__getattr__`` is
  :func:`forward_attributes`, which hands out the old module's names from the new one
  (``from dem_taichi.engine import Simulation``).

Standard library only: every layer may import this module; it imports none of them.
To be removed in the release after the next one.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from collections.abc import Callable
from types import CodeType, ModuleType
from typing import Any

__all__ = ["MOVED", "MovedFinder", "forward_attributes", "install"]

#: old module -> new module
MOVED: dict[str, str] = {
    "dem_taichi.forcelaw": "dem_taichi.physics.forcelaw",
    "dem_taichi.rolling": "dem_taichi.physics.rolling",
    "dem_taichi.bonds": "dem_taichi.physics.bonds",
    "dem_taichi.restitution": "dem_taichi.physics.restitution",
    "dem_taichi.snapshot": "dem_taichi.physics.snapshot",
    "dem_taichi.sections": "dem_taichi.scene.base",
    "dem_taichi.scene_sections": "dem_taichi.scene.sections",
    "dem_taichi.config": "dem_taichi.scene.config",
    "dem_taichi.protocol_config": "dem_taichi.scene.protocol_sections",
    "dem_taichi.presets": "dem_taichi.scene.presets",
    "dem_taichi.scene_options": "dem_taichi.scene.options",
    "dem_taichi.scene": "dem_taichi.scene.geometry",
    "dem_taichi.gas_placement": "dem_taichi.scene.gas_placement",
    "dem_taichi.engine": "dem_taichi.engine.simulation",
    "dem_taichi.engine_state": "dem_taichi.engine.simulation_state",
    "dem_taichi.engine_views": "dem_taichi.engine.simulation_views",
    "dem_taichi.state": "dem_taichi.engine.state",
    "dem_taichi.device_arrays": "dem_taichi.engine.device_arrays",
    "dem_taichi.runtime": "dem_taichi.engine.runtime",
    "dem_taichi.control": "dem_taichi.engine.control",
    "dem_taichi.measures": "dem_taichi.engine.measures",
    "dem_taichi.network": "dem_taichi.engine.network",
    "dem_taichi.failures": "dem_taichi.engine.failures",
    "dem_taichi.work_profile": "dem_taichi.engine.work_profile",
    "dem_taichi.analysis": "dem_taichi.analysis.arrays",
    "dem_taichi.findings": "dem_taichi.analysis.findings",
    "dem_taichi.figures": "dem_taichi.analysis.figures",
    "dem_taichi.mapped_window": "dem_taichi.analysis.mapped_window",
    "dem_taichi.stiffness_matrices": "dem_taichi.response.stiffness_matrices",
    "dem_taichi.linear_response": "dem_taichi.response.linear",
    "dem_taichi.flexible_response": "dem_taichi.response.flexible",
    "dem_taichi.bonded_response": "dem_taichi.response.bonded",
    "dem_taichi.anisotropy": "dem_taichi.response.anisotropy",
    "dem_taichi.protocol": "dem_taichi.protocol.runner",
    "dem_taichi.paths": "dem_taichi.protocol.paths",
    "dem_taichi.quasistatic": "dem_taichi.protocol.quasistatic",
    "dem_taichi.servo": "dem_taichi.protocol.servo",
    "dem_taichi.branches": "dem_taichi.protocol.branches",
    "dem_taichi.probing": "dem_taichi.protocol.probing",
    "dem_taichi.protocol_records": "dem_taichi.protocol.records",
    "dem_taichi.protocol_resume": "dem_taichi.protocol.resume",
    "dem_taichi.resume_codec": "dem_taichi.protocol.resume_codec",
    "dem_taichi.run_schedule": "dem_taichi.protocol.run_schedule",
    "dem_taichi.progress": "dem_taichi.protocol.progress",
    "dem_taichi.cost": "dem_taichi.protocol.cost",
    "dem_taichi.aggregation": "dem_taichi.protocol.aggregation",
    "dem_taichi.report": "dem_taichi.protocol.report",
    "dem_taichi.worker_lifetime": "dem_taichi.protocol.worker_lifetime",
    "dem_taichi.sweep": "dem_taichi.sweep.command",
    "dem_taichi.sweep_spec": "dem_taichi.sweep.spec",
    "dem_taichi.sweep_client": "dem_taichi.sweep.client",
    "dem_taichi.sweep_member": "dem_taichi.sweep.member",
    "dem_taichi.sweep_results": "dem_taichi.sweep.results",
    "dem_taichi.cli": "dem_taichi.cli.commands",
}


def _warn(old: str, new: str) -> None:
    # point the warning at the caller: skip this module's frames (the import system's frames
    # are skipped by the warnings module itself)
    level, frame = 2, sys._getframe(1)
    while frame is not None:
        filename = frame.f_code.co_filename
        if filename == __file__:
            level += 1
        elif not ("importlib" in filename and "_bootstrap" in filename):
            break
        frame = frame.f_back  # type: ignore[assignment]
    message = f"{old} moved to {new}; the old path goes in the next release"
    warnings.warn(message, DeprecationWarning, stacklevel=level)


class _AliasLoader(importlib.abc.Loader):
    """Loads an old module path as the module at its new path."""

    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        _warn(spec.name, self.new)
        return importlib.import_module(self.new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the new module ran when it was imported."""

    def get_code(self, fullname: str) -> CodeType | None:
        """The new module's code, for ``python -m OLD.PATH`` (runpy)."""
        # attributed to __main__, so that Python's default filters show it
        message = f"{fullname} moved to {self.new}; the old path goes in the next release"
        warnings.warn_explicit(message, DeprecationWarning, f"python -m {fullname}", 0, "__main__")
        spec = importlib.util.find_spec(self.new)
        assert spec is not None and isinstance(spec.loader, importlib.abc.InspectLoader)
        return spec.loader.get_code(self.new)


class MovedFinder(importlib.abc.MetaPathFinder):
    """Finds the old module paths of :data:`MOVED` that are no module any more."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None):
        new = MOVED.get(fullname)
        if new is None or new.startswith(fullname + "."):
            return None  # not moved, or now a subpackage (found by the ordinary finders)
        return importlib.util.spec_from_loader(fullname, _AliasLoader(new))


def install() -> None:
    """Put a :class:`MovedFinder` first on :data:`sys.meta_path` (once): first, so that no stale
    file of an old module (an earlier install, an editable install's path mapping) is found."""
    if not any(isinstance(finder, MovedFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())


def forward_attributes(package: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package`` that hands out the names of the old module of
    the same name from its new module, with a :class:`DeprecationWarning`."""
    new = MOVED[package]

    def __getattr__(name: str) -> Any:
        if name.startswith("__") or importlib.util.find_spec(f"{package}.{name}"):
            # a submodule (``from dem_taichi.scene import sections``): the import system loads it
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module = importlib.import_module(new)
        if not hasattr(module, name):
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        _warn(f"{package}.{name}", f"{new}.{name}")
        value = getattr(module, name)
        setattr(sys.modules[package], name, value)  # once: later look-ups find it directly
        return value

    return __getattr__
