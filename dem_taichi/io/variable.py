"""The record that spells one variable of a DEM results file, and the tables built of it.

:class:`Variable` carries a variable's name, dimensions, units, long_name and definition; the
history (:mod:`.history_schema`), the probes (:mod:`.probe_schema`) and the saved configurations
(:mod:`.configuration_schema`) are tuples of them. The unit system and the symbols of the
definitions are described in :mod:`dem_taichi.io.schema`, which re-exports every name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

#: Text stored as a global attribute so a file explains its own units.
DEM_UNIT_SYSTEM = (
    "dimensionless DEM units: length unit d = 1 (disc diameter), mass unit m = 1 (disc mass), "
    "time unit t0 = the scene's time unit; force unit m d / t0^2; 2D stress in force/length; "
    "every DEM quantity has units = '1' and its DEM dimension in the attribute dem_units"
)

COMPRESSION_POSITIVE = "compression_positive"

#: numpy dtype strings allowed in the schema ("str" is a variable-length string).
ALLOWED_DTYPES = ("f8", "f4", "i8", "i4", "i1", "str")

#: Fill values by dtype (NaN for floats, the most negative integer for integers).
FILL_VALUES: Mapping[str, Any] = MappingProxyType(
    {
        "f8": np.float64(np.nan),
        "f4": np.float32(np.nan),
        "i8": np.int64(np.iinfo(np.int64).min),
        "i4": np.int32(np.iinfo(np.int32).min),
        "i1": np.int8(-128),
        "str": "",
    }
)


@dataclass(frozen=True)
class Variable:
    """How one variable is spelled in a results file.

    ``units`` is a UDUNITS string (``"1"`` for dimensionless and for all DEM-unit quantities);
    ``dem_units`` names the DEM dimension of a DEM-unit quantity (empty for pure numbers).
    ``definition`` is given where several definitions exist in the literature (p and q in 2D,
    fabric, strains, coordination...). ``sign_convention`` is ``"compression_positive"`` for
    stresses, strains and strain rates. ``flag_values``/``flag_meanings`` follow CF §3.5.
    """

    name: str
    dims: tuple[str, ...]
    units: str
    long_name: str
    definition: str = ""
    dtype: str = "f8"
    sign_convention: str = ""
    dem_units: str = ""
    flag_values: tuple[int, ...] = ()
    flag_meanings: tuple[str, ...] = ()
    extra_attrs: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"variable name {self.name!r} must be an identifier")
        if self.dtype not in ALLOWED_DTYPES:
            raise ValueError(
                f"variable {self.name!r}: dtype {self.dtype!r} not allowed; use one of "
                f"{ALLOWED_DTYPES}"
            )
        if not self.units:
            raise ValueError(f"variable {self.name!r}: units must be a UDUNITS string, e.g. '1'")
        if len(self.flag_values) != len(self.flag_meanings):
            raise ValueError(
                f"variable {self.name!r}: {len(self.flag_values)} flag_values but "
                f"{len(self.flag_meanings)} flag_meanings"
            )
        for meaning in self.flag_meanings:
            if not meaning or any(ch.isspace() for ch in meaning):
                raise ValueError(
                    f"variable {self.name!r}: flag meaning {meaning!r} must be one word"
                )
        if self.sign_convention not in ("", COMPRESSION_POSITIVE):
            raise ValueError(
                f"variable {self.name!r}: sign_convention {self.sign_convention!r}; allowed: "
                f"'' or {COMPRESSION_POSITIVE!r}"
            )
        object.__setattr__(self, "dims", tuple(self.dims))
        object.__setattr__(self, "extra_attrs", MappingProxyType(dict(self.extra_attrs)))

    @property
    def numpy_dtype(self) -> np.dtype:
        """numpy dtype of the stored values (object for strings)."""
        return np.dtype(object) if self.dtype == "str" else np.dtype(self.dtype)

    @property
    def fill_value(self) -> Any:
        """The value stored where a record lacks this variable."""
        return FILL_VALUES[self.dtype]

    def attrs(self) -> dict[str, Any]:
        """The netCDF attributes of this variable (without ``_FillValue``)."""
        out: dict[str, Any] = {"units": self.units, "long_name": self.long_name}
        if self.dem_units:
            out["dem_units"] = self.dem_units
        if self.definition:
            out["definition"] = self.definition
        if self.sign_convention:
            out["sign_convention"] = self.sign_convention
        if self.flag_values:
            out["flag_values"] = np.array(self.flag_values, dtype=self.numpy_dtype)
            out["flag_meanings"] = " ".join(self.flag_meanings)
        out.update(self.extra_attrs)
        return out


def variable_table(variables: tuple[Variable, ...]) -> Mapping[str, Variable]:
    """Name → Variable, read-only; duplicate names rejected."""
    names = [v.name for v in variables]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"duplicate variable names in schema: {duplicates}")
    return MappingProxyType({v.name: v for v in variables})


def variables_by_name(
    variables: tuple[Variable, ...] | Mapping[str, Variable],
) -> dict[str, Variable]:
    """Name → Variable for a tuple or mapping of variables (duplicates rejected)."""
    if isinstance(variables, Mapping):
        return dict(variables)
    return dict(variable_table(tuple(variables)))
