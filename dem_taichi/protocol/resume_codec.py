"""A data-only encoding of the protocol's records: JSON for the structure, arrays apart.

Why: the resume files of a protocol run (:mod:`dem_taichi.protocol.resume`) hold the run's
records (lists of dicts of numbers and strings), its log (:class:`dem_taichi.protocol.records.
RunLog` and the dataclasses inside it) and the engine state (a dict of numpy arrays). A pickle
would store them in a few lines, but loading a pickle runs whatever code the file names; this
encoding can only ever build numbers, strings, lists, tuples, dicts, numpy arrays and numpy
scalars of numeric types, and instances of the dataclasses listed in :func:`_known_types`
(their ``__init__`` only, with their fields: no unknown field, and a missing one only where it
has a default, so that files written before a field was added still read). A branch from A
(:class:`dem_taichi.protocol.records.Branch`, the field ``branch`` of a ``BranchOutcome``) is
stored as its label, the text ``"radial 1 0.5"`` that earlier versions stored, and read back
with ``Branch.parse``: the files of either version read in the other.

:func:`encode` turns a value into a JSON-ready tree and a dict of arrays (``a0``, ``a1``...,
stored as npz members); :func:`decode` turns them back, bit for bit: floats are written by
``repr`` (exact), non-finite floats and numpy scalars by their bytes (NaN payloads and signs
kept), arrays with their dtype and shape. A tree that does not follow this layout raises
:class:`EncodingError` (a ``ValueError``) saying where.

Tags (a JSON object with a single key starting with ``$``): ``$float`` (hex bytes of a
non-finite float), ``$scalar`` ([dtype, hex bytes]), ``$array`` (name of the array member),
``$tuple`` (items), ``$dict`` ([[key, value], ...], for dicts whose keys are not all plain
strings, or not in sorted order: the checkpoint writes its JSON with sorted keys, so only a
pair list keeps another order, e.g. the labelled states of a run log, A, B, C, B′), ``$obj``
([type name, {field: value}]). A plain JSON object is a dict of strings.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    from dem_taichi.protocol.records import Branch

__all__ = ["EncodingError", "encode", "decode"]

#: numpy kinds that can be stored without pickles: bool, ints, unsigned, floats, complex,
#: fixed-width unicode and bytes (arrays only).
_ARRAY_KINDS = "biufcUS"
_SCALAR_KINDS = "biufc"
_TAGS = ("$float", "$scalar", "$array", "$tuple", "$dict", "$obj")
#: Fields of record types stored as the label of their :class:`Branch`, by type name.
_BRANCH_FIELDS = {"BranchOutcome": ("branch",)}


class EncodingError(ValueError):
    """A value that cannot be encoded, or a tree that is not a valid encoding (says where)."""


def _known_types() -> dict[str, type[DataclassInstance]]:
    """The dataclasses a resume file may hold, by name: the only classes :func:`decode`
    builds. Imported here, not at module level: the records import this package's modules."""
    from dem_taichi.analysis.arrays import Plateau, Transition
    from dem_taichi.protocol.probing import DegradationCurve, ProbeResult
    from dem_taichi.protocol.records import BranchOutcome, RelaxedState, RunLog, StageRecord
    from dem_taichi.response.linear import LinearResponse, SolverInfo

    types = (
        RunLog, StageRecord, RelaxedState, Transition, Plateau, DegradationCurve, ProbeResult,
        LinearResponse, SolverInfo, BranchOutcome,
    )  # fmt: skip
    return {cls.__name__: cls for cls in types}


# -- encoding -------------------------------------------------------------------------------
def encode(value: Any) -> tuple[Any, dict[str, np.ndarray]]:
    """``(tree, arrays)``: ``tree`` is JSON-serialisable (no NaN), ``arrays`` the numpy arrays
    it refers to by name. Raises :class:`EncodingError` for a value of another type."""
    arrays: dict[str, np.ndarray] = {}
    return _encode(value, arrays, "value"), arrays


def _encode(value: Any, arrays: dict[str, np.ndarray], where: str) -> Any:
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int) and not isinstance(value, np.generic):
        return int(value)
    if isinstance(value, float) and not isinstance(value, np.generic):
        return float(value) if math.isfinite(value) else {"$float": struct.pack("<d", value).hex()}
    if isinstance(value, np.generic):
        return _encode_scalar(value, where)
    if isinstance(value, np.ndarray):
        return _encode_array(value, arrays, where)
    if isinstance(value, tuple):
        return {"$tuple": [_encode(v, arrays, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [_encode(v, arrays, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        return _encode_dict(value, arrays, where)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _encode_object(value, arrays, where)
    raise EncodingError(f"{where}: a {type(value).__name__} cannot be stored in a resume file")


def _encode_scalar(value: np.generic, where: str) -> dict:
    if value.dtype.kind not in _SCALAR_KINDS:
        raise EncodingError(f"{where}: numpy scalar of dtype {value.dtype} cannot be stored")
    return {"$scalar": [value.dtype.str, value.tobytes().hex()]}


def _encode_array(value: np.ndarray, arrays: dict[str, np.ndarray], where: str) -> dict:
    if value.dtype.kind not in _ARRAY_KINDS:
        raise EncodingError(f"{where}: array of dtype {value.dtype} cannot be stored (no pickles)")
    name = f"a{len(arrays)}"
    arrays[name] = value
    return {"$array": name}


def _encode_dict(value: dict, arrays: dict[str, np.ndarray], where: str) -> dict:
    keys = list(value)
    if all(isinstance(k, str) and not k.startswith("$") for k in keys) and keys == sorted(keys):
        return {k: _encode(v, arrays, f"{where}[{k!r}]") for k, v in value.items()}
    items = [
        [_encode(k, arrays, f"{where} key"), _encode(v, arrays, f"{where}[{k!r}]")]
        for k, v in value.items()
    ]
    return {"$dict": items}


def _encode_object(value: Any, arrays: dict[str, np.ndarray], where: str) -> dict:
    name = type(value).__name__
    if _known_types().get(name) is not type(value):
        raise EncodingError(f"{where}: {name} is not a record type a resume file may hold")
    branch_fields = _BRANCH_FIELDS.get(name, ())
    fields = {
        f.name: (
            _encode_branch(getattr(value, f.name), f"{where}.{f.name}")
            if f.name in branch_fields
            else _encode(getattr(value, f.name), arrays, f"{where}.{f.name}")
        )
        for f in dataclasses.fields(value)
    }
    return {"$obj": [name, fields]}


def _encode_branch(value: Any, where: str) -> str:
    from dem_taichi.protocol.records import Branch

    if not isinstance(value, Branch):
        raise EncodingError(f"{where}: {value!r} is not a Branch")
    return value.label


# -- decoding -------------------------------------------------------------------------------
def decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    """The value that :func:`encode` turned into ``(tree, arrays)``. Raises
    :class:`EncodingError` naming the place of the first thing that is not a valid encoding."""
    return _decode(tree, arrays, _known_types(), "value")


def _decode(tree: Any, arrays: dict, types: dict[str, type], where: str) -> Any:
    if tree is None or isinstance(tree, bool | str):
        return tree
    if isinstance(tree, int | float):
        return tree
    if isinstance(tree, list):
        return [_decode(v, arrays, types, f"{where}[{i}]") for i, v in enumerate(tree)]
    if not isinstance(tree, dict):
        raise EncodingError(f"{where}: unexpected {type(tree).__name__}")
    tags = [k for k in tree if k.startswith("$")]
    if not tags:
        return {k: _decode(v, arrays, types, f"{where}[{k!r}]") for k, v in tree.items()}
    if len(tree) != 1 or tags[0] not in _TAGS:
        raise EncodingError(f"{where}: unknown tag {sorted(tree)}")
    tag, body = tags[0], tree[tags[0]]
    if tag == "$float":
        return _decode_float(body, where)
    if tag == "$scalar":
        return _decode_scalar(body, where)
    if tag == "$array":
        if not isinstance(body, str) or body not in arrays:
            raise EncodingError(f"{where}: refers to a missing array {body!r}")
        return arrays[body]
    if tag == "$tuple":
        return tuple(_decode(_list(body, where), arrays, types, where))
    if tag == "$dict":
        return _decode_pairs(body, arrays, types, where)
    return _decode_object(body, arrays, types, where)


def _list(body: Any, where: str) -> list:
    if not isinstance(body, list):
        raise EncodingError(f"{where}: expected a list, found {type(body).__name__}")
    return body


def _bytes(text: Any, size: int, where: str) -> bytes:
    try:
        data = bytes.fromhex(text)
    except (TypeError, ValueError) as error:
        raise EncodingError(f"{where}: bad hex bytes ({error})") from None
    if len(data) != size:
        raise EncodingError(f"{where}: {len(data)} bytes where {size} are needed")
    return data


def _decode_float(body: Any, where: str) -> float:
    return struct.unpack("<d", _bytes(body, 8, where))[0]


def _decode_scalar(body: Any, where: str) -> np.generic:
    if not (isinstance(body, list) and len(body) == 2 and isinstance(body[0], str)):
        raise EncodingError(f"{where}: a scalar is [dtype, hex bytes]")
    try:
        dtype = np.dtype(body[0])
    except TypeError as error:
        raise EncodingError(f"{where}: bad dtype {body[0]!r} ({error})") from None
    if dtype.kind not in _SCALAR_KINDS:
        raise EncodingError(f"{where}: scalar dtype {dtype} is not allowed")
    return np.frombuffer(_bytes(body[1], dtype.itemsize, where), dtype=dtype)[0]


def _decode_pairs(body: Any, arrays: dict, types: dict[str, type], where: str) -> dict:
    out = {}
    for i, pair in enumerate(_list(body, where)):
        if not (isinstance(pair, list) and len(pair) == 2):
            raise EncodingError(f"{where}[{i}]: a dict item is [key, value]")
        key = _decode(pair[0], arrays, types, f"{where}[{i}] key")
        try:
            out[key] = _decode(pair[1], arrays, types, f"{where}[{key!r}]")
        except TypeError:  # an unhashable key (a list)
            raise EncodingError(f"{where}[{i}]: the key is not hashable") from None
    return out


def _decode_object(body: Any, arrays: dict, types: dict[str, type], where: str) -> Any:
    if not (isinstance(body, list) and len(body) == 2 and isinstance(body[1], dict)):
        raise EncodingError(f"{where}: an object is [type name, fields]")
    name, fields = body
    cls = types.get(name) if isinstance(name, str) else None
    if cls is None:
        raise EncodingError(f"{where}: {name!r} is not a record type a resume file may hold")
    expected = {f.name for f in dataclasses.fields(cls)}
    # a field added since the file was written takes its default (RunLog.work, added later)
    required = {
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    }
    if not required <= set(fields) <= expected:
        raise EncodingError(
            f"{where}: {name} fields {sorted(fields)} are not the expected {sorted(expected)}"
        )
    branch_fields = _BRANCH_FIELDS.get(name, ())
    values = {
        k: _decode_branch(v, f"{where}.{k}") if k in branch_fields
        else _decode(v, arrays, types, f"{where}.{k}")
        for k, v in fields.items()
    }  # fmt: skip
    return cls(**values)


def _decode_branch(tree: Any, where: str) -> Branch:
    from dem_taichi.protocol.records import Branch

    if not isinstance(tree, str):
        raise EncodingError(f"{where}: a branch is its label, found {type(tree).__name__}")
    try:
        return Branch.parse(tree)
    except ValueError as error:
        raise EncodingError(f"{where}: {error}") from None
