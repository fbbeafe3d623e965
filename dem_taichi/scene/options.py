"""The scene of a command line: a scene, then a ``--preset``, then ``--set`` overrides.

Above :mod:`dem_taichi.scene.config` and :mod:`dem_taichi.scene.presets` (which config uses): the
command lines (:mod:`dem_taichi.cli.commands`, :mod:`dem_taichi.protocol.runner`) and Python callers
build the scene a run gets here.
"""

from __future__ import annotations

from typing import Any

from dem_taichi.scene.config import Scene, load_scene, scene_with_overrides
from dem_taichi.scene.presets import PRESETS, preset_keys

__all__ = ["with_preset", "scene_from_options", "add_preset_option"]


def with_preset(scene, name: str):
    """``scene`` with the preset ``name``'s keys replacing its own (the command line's rule),
    and ``[scene] preset`` set to ``name``. ``name = ""`` returns the scene unchanged."""
    if not name:
        return scene
    items = [f"{key}={_toml(value)}" for key, value in preset_keys(name).items()]
    return scene_with_overrides(scene, [*items, f'scene.preset="{name}"'])


def scene_from_options(scene, preset: str = "", overrides=()):
    """The scene of a command line: ``scene`` (a Scene, TOML path or built-in name), then the
    ``--preset`` (its keys replace the scene's), then the ``--set`` overrides (they win).
    Validated once, with the overrides in: a preset's key that a scene refuses beside one of
    its own (``--preset fast`` on the ``study`` scene, whose paths step at 5/3 Δt) loads when an
    override mends it (``--set protocol.path_time_step_factor=1``)."""
    loaded = scene if isinstance(scene, Scene) else load_scene(scene)
    if not preset:
        return scene_with_overrides(loaded, list(overrides))
    preset_keys(preset)  # an unknown name fails here, naming the allowed ones
    return scene_with_overrides(loaded, [f'scene.preset="{preset}"', *overrides])


def add_preset_option(parser) -> None:
    """The ``--preset`` option of a command line that takes a scene."""
    parser.add_argument(
        "--preset",
        choices=tuple(PRESETS),
        default="",
        help="speed–accuracy preset: its keys (dt_safety, loading rate, servo, tolerances) "
        "replace the scene's; --set still wins (default: the scene's own keys; "
        "benchmarks/results/speed_accuracy.md gives each one's cost and error)",
    )


def _toml(value: Any) -> str:
    return f'"{value}"' if isinstance(value, str) else repr(value)
