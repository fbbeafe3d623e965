"""Validated frozen scene sections: :class:`SceneSection` and :class:`SceneError`.

The base of every section dataclass of a scene (:mod:`dem_taichi.config` for the engine's,
:mod:`dem_taichi.protocol_config` for the virtual experiments'): each field carries its allowed
range or choices in ``metadata`` (:func:`field_range`, :func:`field_choices`), checked after
construction, and an invalid value raises a :class:`SceneError` naming the key and what is
allowed. It imports nothing of the package, so every section module can build on it.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

__all__ = [
    "MAX_MAGNITUDE",
    "MIN_MAGNITUDE",
    "SceneError",
    "SceneSection",
    "field_range",
    "field_choices",
    "read_text_file",
]

#: Largest magnitude of any number of a scene, and smallest of a non-zero one. Scenes are in DEM
#: units (disc diameter d = 1, disc mass m = 1): no key needs more, and a product of three keys
#: (a force k_n·δ over a mass, an energy) then stays inside single precision (3.4e38, the
#: engine's ``precision = "f32"``) instead of overflowing where it is used, far from the key.
MAX_MAGNITUDE = 1.0e12
MIN_MAGNITUDE = 1.0e-12


class SceneError(ValueError):
    """An invalid scene: the message names the offending key and what is allowed."""


def read_text_file(path: str | Path, what: str, error: type[Exception] = SceneError) -> str:
    """The text of the UTF-8 file ``path``; ``error`` naming ``what`` (e.g. "scene file"), the
    file and the first bad byte when it is not UTF-8 text (a binary file, another encoding)."""
    data = Path(path).read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            f"{what} {str(path)!r} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
            f"{exc.start}): save it as UTF-8"
        ) from None


def _check_magnitude(key: str, value: float | int) -> None:
    """Refuse a number beyond the scale of a scene (:data:`MAX_MAGNITUDE`)."""
    size = abs(value)
    if size > MAX_MAGNITUDE or 0 < size < MIN_MAGNITUDE:
        raise SceneError(
            f"{key} = {value!r} is out of range: allowed magnitudes {MIN_MAGNITUDE:g} to "
            f"{MAX_MAGNITUDE:g} (or 0) for every number of a scene (DEM units, d = m = 1; "
            "products of keys must stay finite in single precision)"
        )


def field_range(lo=None, hi=None, lo_open=False, hi_open=False, doc=""):
    """``metadata`` of a numeric field allowed in [lo, hi] (``None``: unbounded; ``*_open``:
    the bound excluded)."""
    return {"range": (lo, hi, lo_open, hi_open), "doc": doc}


def field_list(doc=""):
    """Metadata of a text field that holds a list: a TOML array (``[0.2, 0.35]``, ``["A", "C"]``)
    is accepted as well as the comma-separated string (``"0.2, 0.35"``), and stored as the
    string."""
    return {"list": True, "doc": doc}


def _list_text(key: str, value) -> str:
    items = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int | float | str):
            raise SceneError(
                f'{key} = {value!r}: a list of numbers or strings, e.g. [0.2, 0.35] or "0.2, 0.35"'
            )
        items.append(item if isinstance(item, str) else repr(item))
    return ", ".join(items)


def field_choices(*values, doc=""):
    """``metadata`` of a field allowed to take one of ``values``."""
    return {"choices": tuple(values), "doc": doc}


def _describe_range(meta) -> str:
    lo, hi, lo_open, hi_open = meta["range"]
    left = "(" if lo_open else "["
    right = ")" if (hi_open or hi is None) else "]"
    return f"{left}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{right}"


class SceneSection:
    """Base of every section dataclass: validates field values after construction."""

    SECTION = ""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            key = f"[{self.SECTION}] {f.name}"
            if value is None:
                if f.metadata.get("optional"):
                    continue
                raise SceneError(f"{key} is required")
            kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
            kind = kind.replace(" | None", "")
            if kind == "bool":
                if not isinstance(value, bool):
                    raise SceneError(f"{key} = {value!r}: must be true or false")
            elif kind == "int":
                if isinstance(value, bool) or not isinstance(value, int):
                    raise SceneError(f"{key} = {value!r}: must be an integer")
            elif kind == "float":
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise SceneError(f"{key} = {value!r}: must be a number")
                if not math.isfinite(value):
                    raise SceneError(f"{key} = {value!r}: must be finite")
                object.__setattr__(self, f.name, float(value))
                value = float(value)
            elif kind == "str":
                if f.metadata.get("list") and isinstance(value, list | tuple):
                    value = _list_text(key, value)
                    object.__setattr__(self, f.name, value)
                if not isinstance(value, str):
                    raise SceneError(f"{key} = {value!r}: must be a string")
            if kind in ("int", "float"):
                self._check_range(key, value, f.metadata)
                _check_magnitude(key, value)
            if "choices" in f.metadata and value not in f.metadata["choices"]:
                allowed = " | ".join(str(c) for c in f.metadata["choices"])
                raise SceneError(f"{key} = {value!r}: allowed values are {allowed}")
        self.check()

    @staticmethod
    def _check_range(key: str, value: float | int, metadata) -> None:
        """Refuse ``value`` outside the field's ``range`` metadata (:func:`field_range`)."""
        if "range" in metadata:
            lo, hi, lo_open, hi_open = metadata["range"]
            bad = (lo is not None and (value < lo or (lo_open and value == lo))) or (
                hi is not None and (value > hi or (hi_open and value == hi))
            )
            if bad:
                raise SceneError(
                    f"{key} = {value!r} is out of range: allowed {_describe_range(metadata)}"
                )

    def check(self) -> None:
        """Cross-field checks of the section (override)."""
