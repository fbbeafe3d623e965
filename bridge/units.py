"""Units of the variables the bridge reads from DEM results files, read and checked with pint.

Every variable that :mod:`bridge.series` takes from a history (``history.nc``,
``relaxed_states.nc``) or a probes file (``probes.nc``) passes through :func:`checked` first,
which parses its ``units`` attribute with :mod:`pint` (no string comparison) and converts the
values to DEM units, the units the conventions of :class:`bridge.series.Convention` start from.

Convention (the DEM writer's, :mod:`dem_taichi.io.schema`):

* **stresses and moduli** (``stress_*``, ``mean_stress``, ``deviatoric_stress``, ``e_oed_*``,
  ``stiffness_tensor_*``, ``*_modulus_*``) are accepted in

  - DEM units: ``units = "1"`` *and* ``dem_units = "force/length"`` (2D stress of the DEM);
    kPa = S × value with the stress scale S of the convention (the option, else the file's
    global attribute ``stress_scale_kpa``);
  - any pressure unit pint knows (``Pa``, ``kPa``, ``MPa``, ``GPa``, ``bar``, ``psi``,
    ``N/m^2``…): converted to kPa by pint, then to DEM units by 1/S (so the model sees
    kPa = S × (value in kPa / S) = the value in kPa, whatever S is; :func:`in_dem_units` tells
    the pipeline whether a scale is needed at all);

* **pure numbers** (``specific_volume``, ``fabric_deviator``) must be dimensionless
  (``"1"``, ``"%"``…; converted to 1).

Refused, with one line naming the file kind, the variable, its unit and what is allowed: a
unit pint cannot read (``"kpa"``, ``"N m-2"``), one of another dimension (a stress in ``"m"``,
a modulus in ``"kg"``, a 2D force/length such as ``"N/m"``, which needs a thickness), ``"1"``
on a stress without ``dem_units = "force/length"``, and a **missing or empty** ``units``
attribute: the DEM writer always writes one, so a file without it was made elsewhere and
guessing DEM units could silently scale a run by 1000 (the bug of issue 11).
"""

from __future__ import annotations

import functools

import numpy as np
import xarray as xr

#: The ``dem_units`` value of a DEM stress or modulus (2D: force per length).
DEM_STRESS_UNITS = "force/length"
#: The model's stress unit.
MODEL_STRESS_UNITS = "kPa"

STRESS = "stress"
MODULUS = "modulus"
NUMBER = "dimensionless"


class UnitsError(ValueError):
    """A variable of a DEM results file with a missing, unknown or incompatible unit."""


@functools.cache
def registry():
    """The one pint unit registry of the bridge (built on first use)."""
    import pint

    return pint.UnitRegistry()


def kind_of(name: str) -> str | None:
    """The kind of a variable the bridge reads: stress, modulus, dimensionless, or None (not
    a quantity: stage labels, codes, steps)."""
    if name.startswith("stress_") or name in ("mean_stress", "deviatoric_stress"):
        return STRESS
    if name.startswith(("e_oed_", "stiffness_tensor_")) or "_modulus_" in name:
        return MODULUS
    if name in ("specific_volume", "void_ratio") or name.startswith("fabric_"):
        return NUMBER
    return None


def _allowed(kind: str) -> str:
    if kind == NUMBER:
        return "allowed: a dimensionless unit ('1', '%')"
    return (
        "allowed: a pressure unit (Pa, kPa, MPa, GPa…, converted to kPa) or units '1' with "
        f"dem_units '{DEM_STRESS_UNITS}' (DEM units, times stress_scale_kpa)"
    )


def factor_to_dem_units(variable: xr.DataArray, name: str, stress_scale_kpa: float,
                        what: str = "file") -> float:  # fmt: skip
    """The factor that takes the stored values of ``variable`` to DEM units (1 for pure
    numbers), from its ``units`` (and ``dem_units``) attribute; :class:`UnitsError` if the
    unit is missing, unknown or not allowed for the variable's kind (module docstring)."""
    kind = kind_of(name)
    if kind is None:
        return 1.0
    units = variable.attrs.get("units")
    head = f"{what} variable {name!r} ({kind})"
    if units is None or not str(units).strip():
        raise UnitsError(
            f"{head} has no units attribute; {_allowed(kind)}; add it to the file (the DEM "
            "writer always writes one)"
        )
    units = str(units).strip()
    ureg = registry()
    try:
        quantity = ureg.Quantity(1.0, units)
    except Exception:  # pint raises several types for text it cannot parse
        raise UnitsError(f"{head} has units {units!r}, not a unit pint can read; "
                         f"{_allowed(kind)}") from None  # fmt: skip
    if kind == NUMBER:
        if not quantity.dimensionless:
            raise UnitsError(
                f"{head} has units {units!r} ({quantity.dimensionality}); {_allowed(kind)}"
            )
        return float(quantity.to("dimensionless").magnitude)
    if quantity.dimensionless:
        dem_units = str(variable.attrs.get("dem_units", "")).replace(" ", "")
        if dem_units != DEM_STRESS_UNITS:
            raise UnitsError(
                f"{head} has units {units!r} with dem_units {variable.attrs.get('dem_units')!r},"
                f" not a DEM stress; {_allowed(kind)}"
            )
        return float(quantity.to("dimensionless").magnitude)
    if quantity.check("[pressure]"):
        return float(quantity.to(MODEL_STRESS_UNITS).magnitude) / float(stress_scale_kpa)
    raise UnitsError(f"{head} has units {units!r} ({quantity.dimensionality}); {_allowed(kind)}")


def checked(ds: xr.Dataset, names, stress_scale_kpa: float, what: str = "file") -> xr.Dataset:
    """``ds`` with the variables ``names`` (those present) read in DEM units (module docstring):
    values converted, attributes ``units = "1"`` (+ ``dem_units``) stated; the others as they
    are. Raises :class:`UnitsError` for the first variable whose unit is not allowed."""
    out = ds.copy(deep=False)
    for name in names:
        if name not in ds.variables or kind_of(name) is None:
            continue
        variable = ds[name]
        factor = factor_to_dem_units(variable, name, stress_scale_kpa, what)
        attrs = dict(variable.attrs)
        attrs["units"] = "1"
        if kind_of(name) != NUMBER:
            attrs["dem_units"] = DEM_STRESS_UNITS
        if factor != 1.0 or attrs != variable.attrs:
            values = np.asarray(variable.values, dtype=float) * factor
            out[name] = variable.copy(data=values)
            out[name].attrs = attrs
    return out


def in_dem_units(ds: xr.Dataset, names) -> list[str]:
    """The variables among ``names`` (those present, stresses and moduli) whose ``units`` is
    not a pressure unit pint can read: DEM units, which need the stress scale (or units that
    :func:`checked` will refuse)."""
    out = []
    ureg = registry()
    for name in names:
        if name not in ds.variables or kind_of(name) in (None, NUMBER):
            continue
        try:
            pressure = ureg.Quantity(1.0, str(ds[name].attrs["units"])).check("[pressure]")
        except Exception:  # missing or unreadable: not a pressure
            pressure = False
        if not pressure:
            out.append(str(name))
    return out
