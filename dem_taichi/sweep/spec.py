"""Sweep files: a grid or a list of protocol runs over scene keys, validated at load.

A sweep file is TOML with one ``[sweep]`` table (no Taichi, no Dask here)::

    [sweep]
    name = "smoke-seeds"      # optional; default: the file's stem
    scene = "smoke"           # built-in scene name, or a scene file (relative to this file)
    arch = "cpu"              # cpu | gpu                       (default cpu)
    precision = "f64"         # f64 | f32                       (default f64)
    workers = 1               # processes per member for the paths from A (default 1)

    [sweep.set]               # keys every member gets
    "protocol.run_unloading" = false

    [sweep.grid]              # the Cartesian product of these lists, in file order
    "scene.seed" = [1, 2, 3]

    [[sweep.members]]         # explicit members (each one combined with every grid point)
    name = "stiff_kt"         # optional; default: made from the member's own keys
    "contact.k_t" = 1.0e5

A key is ``"section.key"`` of the scene (``scene.seed``, ``particles.n_rods``,
``long_range.pattern``, ``protocol.radial_stress_ratios``, ...); written unquoted, TOML makes
it a nested table (``scene.seed = 1``), which is read the same. Precedence: the base scene,
then ``[sweep.set]``, then the member's keys, then the grid point's.

Every member's full scene is built and validated at load: an unknown key or an invalid value
fails with :class:`SweepError` naming the member, the key as written in the sweep file and what
the scene allows, before anything runs. A member's name is also the name of its run directory,
``DIR/members/<name>``: names (given or made from the keys) are unique, 1 to
:data:`MAX_NAME_LENGTH` characters of ``A-Z a-z 0-9 - _ . = +``, and neither ``.`` nor ``..``
(:func:`check_member_name`), so that no member's folder lies outside ``DIR/members``.

A sweep has at most :data:`MAX_MEMBERS` members (the grid's points times the listed members):
a larger one is refused with its size before any member is built (``max_members`` of
:func:`sweep_from_toml`, ``--max-members`` of the command line, raise the limit).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dem_taichi.scene.base import read_text_file
from dem_taichi.scene.config import (
    Scene,
    SceneError,
    builtin_scene_path,
    scene_from_dict,
    scene_to_toml,
)
from dem_taichi.scene.presets import set_keys

__all__ = [
    "MAX_MEMBERS",
    "MAX_NAME_LENGTH",
    "SweepError",
    "Member",
    "SweepSpec",
    "check_member_name",
    "load_sweep",
    "sweep_from_toml",
]

_SWEEP_KEYS = ("name", "scene", "arch", "precision", "workers", "set", "grid", "members")
_ARCHES = ("cpu", "gpu")
_PRECISIONS = ("f64", "f32")
_NAME = re.compile(r"^[A-Za-z0-9_.=+-]+$")
#: Longest member name (the name of its run directory; file systems allow 255 bytes).
MAX_NAME_LENGTH = 120
#: Most members a sweep may have unless ``max_members`` says otherwise: each member is a whole
#: protocol run (minutes to hours) and its scene is built and validated at load, so a grid of
#: 10⁸ points is a typo, not a plan.
MAX_MEMBERS = 10_000


class SweepError(SceneError):
    """An invalid sweep file: the message names the offending key and what is allowed."""


@dataclass(frozen=True)
class Member:
    """One protocol run of a sweep: its name, the keys it changes and its scene as TOML.

    ``overrides`` maps ``"section.key"`` to the value this member gets on top of the base
    scene (``[sweep.set]`` included); ``parameters`` are the keys that vary across the sweep
    (the grid's and the members' own), the coordinates of the combined dataset.
    """

    name: str
    overrides: dict[str, Any]
    parameters: dict[str, Any]
    scene_toml: str

    @property
    def scene_sha256(self) -> str:
        """SHA-256 (hex) of the member's full scene TOML (every key, defaults included)."""
        return hashlib.sha256(self.scene_toml.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class SweepSpec:
    """A loaded, validated sweep: its settings and its members in order."""

    name: str
    scene: str
    arch: str = "cpu"
    precision: str = "f64"
    workers: int = 1
    members: tuple[Member, ...] = ()
    source_text: str = field(default="", repr=False)

    def member(self, name: str) -> Member:
        for m in self.members:
            if m.name == name:
                return m
        raise KeyError(name)

    @property
    def parameter_keys(self) -> tuple[str, ...]:
        """Every key that varies across the members, in first-seen order."""
        keys: dict[str, None] = {}
        for m in self.members:
            keys.update(dict.fromkeys(m.parameters))
        return tuple(keys)


def check_member_name(name: Any, where: str) -> str:
    """``name`` if it is a safe member name (module docstring), else :class:`SweepError`
    naming ``where`` and the rule: the name becomes the folder ``DIR/members/<name>``, which a
    re-run may delete, so it must not leave ``DIR/members``."""
    rule = (
        f"allowed: 1 to {MAX_NAME_LENGTH} characters of A-Z a-z 0-9 - _ . = + (no path "
        "separator), not '.' or '..'"
    )
    if not isinstance(name, str) or not name:
        raise SweepError(f"{where} name = {name!r}: {rule}")
    if len(name) > MAX_NAME_LENGTH or not _NAME.match(name) or name in (".", ".."):
        shown = name if len(name) <= 60 else name[:57] + "..."
        raise SweepError(f"{where} name = {shown!r}: {rule}")
    return name


def _flatten(table: dict, where: str, prefix: str = "") -> dict[str, Any]:
    """``{"scene": {"seed": 1}}`` and ``{"scene.seed": 1}`` both → ``{"scene.seed": 1}``."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        full = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            out.update(_flatten(value, where, full))
        else:
            out[full] = value
    for key in out:
        parts = key.split(".")
        if len(parts) != 2 or not all(parts):
            raise SweepError(
                f'{where} "{key}": a key must be "section.key" of the scene, e.g. "scene.seed"'
            )
    return out


def _check_scalar(where: str, key: str, value: Any) -> None:
    if isinstance(value, list | dict):
        raise SweepError(
            f'{where} "{key}" = {value!r}: must be a single value (a list goes in [sweep.grid])'
        )


def _label(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    text = f"{value:g}".replace("+", "") if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9.-]+", "-", text).strip("-") or "x"


def _auto_name(parameters: dict[str, Any], ambiguous: set[str]) -> str:
    """``{"scene.seed": 2, "contact.mu": 0.2}`` → ``seed-2__mu-0.2`` (the section is kept,
    ``scene.seed-2``, for a key name that two sections of the sweep share)."""
    if not parameters:
        return "base"
    parts = []
    for key, value in parameters.items():
        short = key.split(".")[1]
        parts.append(f"{key if short in ambiguous else short}-{_label(value)}")
    return "__".join(parts)


def _base_scene_dict(scene: Any, folder: Path) -> tuple[str, dict]:
    if not isinstance(scene, str) or not scene:
        raise SweepError(
            f"[sweep] scene = {scene!r}: must be a built-in scene name or a scene file path"
        )
    path = Path(scene)
    if not path.is_absolute() and path.suffix:
        path = folder / path
    if not path.exists():
        if path.suffix or len(path.parts) > 1:
            raise SweepError(f"[sweep] scene = {scene!r}: scene file {str(path)!r} does not exist")
        try:
            path = builtin_scene_path(scene)
        except SceneError as exc:
            raise SweepError(f"[sweep] scene = {scene!r}: {exc}") from None
    try:
        return str(path), tomllib.loads(read_text_file(path, "[sweep] scene file", SweepError))
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"[sweep] scene = {scene!r}: invalid TOML in {path}: {exc}") from None


def _member_scene(base: dict, overrides: dict[str, Any]) -> Scene:
    data = set_keys(copy.deepcopy(base), overrides, where="sweep key")
    return scene_from_dict(data)


def _check_size(grid: dict[str, list], n_listed: int, max_members: int) -> None:
    """Refuse a sweep of more than ``max_members`` members, from the lists' lengths alone
    (before any member, or the grid's points, is built)."""
    size = max(1, n_listed)
    for values in grid.values():
        size *= len(values)
    if size > max_members:
        shape = " × ".join(str(len(v)) for v in grid.values()) or "0"
        listed = f" × {n_listed} [[sweep.members]]" if n_listed else ""
        raise SweepError(
            f"[sweep.grid] makes {size:,} members ({shape}{listed}): allowed at most "
            f"{max_members:,}; split the sweep, or raise the limit (--max-members, "
            "sweep_from_toml(max_members=...))"
        )


def sweep_from_toml(
    text: str,
    folder: str | Path = ".",
    default_name: str = "sweep",
    max_members: int = MAX_MEMBERS,
) -> SweepSpec:
    """Parse and validate a sweep file's text (``folder``: where relative scene paths start;
    ``max_members``: the most members allowed, :data:`MAX_MEMBERS` by default)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"invalid TOML: {exc}") from None
    extra = sorted(set(data) - {"sweep"})
    if extra or "sweep" not in data:
        raise SweepError(
            f"unknown table(s) {', '.join('[' + e + ']' for e in extra)}; allowed: [sweep]"
            if extra
            else "no [sweep] table; a sweep file has one [sweep] table"
        )
    sweep = data["sweep"]
    unknown = sorted(set(sweep) - set(_SWEEP_KEYS))
    if unknown:
        raise SweepError(
            f"[sweep] unknown key(s) {', '.join(unknown)}; allowed keys: {', '.join(_SWEEP_KEYS)}"
        )
    name = sweep.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SweepError(f"[sweep] name = {name!r}: must be a non-empty string")
    arch = sweep.get("arch", "cpu")
    if arch not in _ARCHES:
        raise SweepError(f"[sweep] arch = {arch!r}: allowed values are {' | '.join(_ARCHES)}")
    precision = sweep.get("precision", "f64")
    if precision not in _PRECISIONS:
        raise SweepError(
            f"[sweep] precision = {precision!r}: allowed values are {' | '.join(_PRECISIONS)}"
        )
    workers = sweep.get("workers", 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise SweepError(f"[sweep] workers = {workers!r}: allowed values are integers >= 1")
    if "scene" not in sweep:
        raise SweepError("[sweep] scene is required: a built-in scene name or a scene file path")
    scene_name = sweep["scene"]
    _, base = _base_scene_dict(scene_name, Path(folder))

    def table(key: str) -> dict:
        value = sweep.get(key, {})
        if not isinstance(value, dict):
            raise SweepError(f'[sweep.{key}] must be a table of "section.key" = value')
        return value

    common = _flatten(table("set"), "[sweep.set]")
    for key, value in common.items():
        _check_scalar("[sweep.set]", key, value)
    grid = _flatten(table("grid"), "[sweep.grid]")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise SweepError(
                f'[sweep.grid] "{key}" = {values!r}: must be a non-empty list of values'
            )
        for value in values:
            _check_scalar("[sweep.grid]", key, value)
    listed = sweep.get("members", [])
    if not isinstance(listed, list) or not all(isinstance(m, dict) for m in listed):
        raise SweepError(
            "[[sweep.members]] must be an array of tables (one [[sweep.members]] each)"
        )
    if not grid and not listed:
        raise SweepError("[sweep] has no members: give [sweep.grid] and/or [[sweep.members]]")
    explicit: list[tuple[str | None, dict[str, Any]]] = []
    for i, entry in enumerate(listed):
        where = f"[[sweep.members]] #{i + 1}"
        entry = dict(entry)
        given = entry.pop("name", None)
        if given is not None:
            check_member_name(given, where)
        keys = _flatten(entry, where)
        for key, value in keys.items():
            _check_scalar(where, key, value)
        explicit.append((given, keys))
    _check_size(grid, len(explicit), max_members)
    points = [dict(zip(grid, combo, strict=True)) for combo in itertools.product(*grid.values())]
    varied = set(grid).union(*(keys for _, keys in explicit))
    shorts = [k.split(".")[1] for k in varied]
    ambiguous = {s for s in shorts if shorts.count(s) > 1}
    members: list[Member] = []
    for given, own in explicit or [(None, {})]:
        for point in points or [{}]:
            parameters = {**own, **point}
            overrides = {**common, **parameters}
            if given is not None:
                member_name = given + ("__" + _auto_name(point, ambiguous) if point else "")
            else:
                member_name = _auto_name(parameters, ambiguous)
            where = ", ".join(f"{k} = {v!r}" for k, v in parameters.items()) or "no keys"
            check_member_name(member_name, f"member ({where}):")
            try:
                scene = _member_scene(base, overrides)
            except SceneError as exc:
                raise SweepError(f"member {member_name} ({where}): {exc}") from None
            members.append(Member(member_name, overrides, parameters, scene_to_toml(scene)))
    seen: dict[str, int] = {}
    for m in members:
        seen[m.name] = seen.get(m.name, 0) + 1
    twice = sorted(n for n, c in seen.items() if c > 1)
    if twice:
        raise SweepError(
            f"member name(s) {', '.join(twice)} given to more than one member: give each "
            '[[sweep.members]] its own name = "..."'
        )
    return SweepSpec(
        name=name,
        scene=str(scene_name),
        arch=arch,
        precision=precision,
        workers=workers,
        members=tuple(members),
        source_text=text,
    )


def load_sweep(path: str | Path, max_members: int = MAX_MEMBERS) -> SweepSpec:
    """Load and validate a sweep file (see the module docstring); raises :class:`SweepError`."""
    path = Path(path)
    if not path.exists():
        raise SweepError(f"sweep file {str(path)!r} does not exist")
    text = read_text_file(path, "sweep file", SweepError)
    return sweep_from_toml(text, path.parent, default_name=path.stem, max_members=max_members)
