"""Stages of a run: the labels of the ``stage`` history variable and their integer codes."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

#: Stage labels and their integer codes, in the order of the protocol
#: (docs/science/dem-model.md §1.6); stages
#: added later are appended at the end so the codes of the others keep their values (files
#: written before read the same): "aggregation" is the optional gas-ageing stage before
#: "isotropic_to_A" (:meth:`dem_taichi.protocol.paths.ProtocolRunner.aggregate`).
STAGE_CODES: Mapping[str, int] = MappingProxyType(
    {
        "gas": 0,
        "isotropic_to_A": 1,
        "A_to_B": 2,
        "A_to_C": 3,
        "C_to_B": 4,
        "radial": 5,
        "relax": 6,
        "probe": 7,
        "other": 8,
        "aggregation": 9,
    }
)
STAGE_LABELS: Mapping[int, str] = MappingProxyType({c: s for s, c in STAGE_CODES.items()})


def stage_code(label: str) -> int:
    """Integer code of a stage label; unknown labels fail naming the allowed ones."""
    try:
        return STAGE_CODES[label]
    except KeyError:
        raise ValueError(f"unknown stage {label!r}; allowed: {', '.join(STAGE_CODES)}") from None


def stage_label(code: int) -> str:
    """Stage label of an integer code; unknown codes fail naming the allowed ones."""
    try:
        return STAGE_LABELS[int(code)]
    except KeyError:
        raise ValueError(f"unknown stage code {code!r}; allowed: {dict(STAGE_LABELS)}") from None
