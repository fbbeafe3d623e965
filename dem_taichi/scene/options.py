"""The scene of a command line: a scene, then a ``--preset``, then ``--set`` overrides.

Above :mod:`dem_taichi.scene.config` and :mod:`dem_taichi.scene.presets` (which config uses): the
command lines (:mod:`dem_taichi.cli.commands`, :mod:`dem_taichi.protocol.runner`) and Python callers
build the scene a run gets here.
"""

from __future__ import annotations

from dem_taichi.scene.config import Scene, load_scene, scene_with_overrides
from dem_taichi.scene.presets import PRESETS, preset_keys

__all__ = ["with_preset", "scene_from_options", "add_preset_option"]


def with_preset(scene, name: str, overrides=()):
    """``scene`` with the preset ``name``'s keys replacing its own (the command line's rule),
    ``[scene] preset`` set to ``name``, then ``overrides`` (``section.key=value``, they win),
    validated once with all of them in (:func:`~dem_taichi.scene.config.scene_with_overrides`,
    whose ``scene.preset`` writes the preset's keys first): a preset's key that a scene refuses
    beside one of its own (``fast`` on ``study``, whose paths step at 5/3 Δt) loads when an
    override mends it (``protocol.path_time_step_factor=1``). ``name = ""``: the overrides alone.
    """
    if not name:
        return scene_with_overrides(scene, list(overrides))
    preset_keys(name)  # an unknown name fails here, naming the allowed ones
    return scene_with_overrides(scene, [f'scene.preset="{name}"', *overrides])


def scene_from_options(scene, preset: str = "", overrides=()):
    """The scene of a command line: ``scene`` (a Scene, TOML path or built-in name), then the
    ``--preset`` (its keys replace the scene's), then the ``--set`` overrides (they win):
    :func:`with_preset`."""
    loaded = scene if isinstance(scene, Scene) else load_scene(scene)
    return with_preset(loaded, preset, overrides)


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
