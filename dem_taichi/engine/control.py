"""Cell control of the engine: a prescribed logarithmic strain rate per axis (plain Python).

ε̇ = −L̇/L, compression positive, 0 = the axis held; the engine applies it exactly
(L = L_0 exp(−ε̇ t)). Stresses are held by the protocol's servo
(:class:`dem_taichi.protocol.servo.StressServo`), which sets these rates; the engine has none of its
own.

``minimise``: the caller asks for a relaxation to a static state at fixed cell (rates 0). The
engine then integrates the call with the scene's ``[integration] relaxation``: the damped
dynamics (the default "damped", the same steps as :meth:`CellControl.fixed`, bit for bit) or
the FIRE minimiser ("fire", :mod:`dem_taichi.kernels.fire`).

:func:`step_count` checks the step counts a run is given (a clear error, not a silent no-op).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["AxisControl", "CellControl", "step_count"]


@dataclass(frozen=True)
class AxisControl:
    """Control of one cell axis: ``mode`` "strain_rate", ``value`` = ε̇ (compression positive).

    (The engine's own stress mode is gone: hold stresses with the protocol's servo,
    :class:`dem_taichi.protocol.servo.StressServo`.)
    """

    mode: str = "strain_rate"
    value: float = 0.0

    def __post_init__(self) -> None:
        if self.mode != "strain_rate":
            raise ValueError(
                f"mode = {self.mode!r}: allowed values are strain_rate (stresses are held by "
                "the protocol's servo, dem_taichi.protocol.servo.StressServo)"
            )
        if not math.isfinite(self.value):
            raise ValueError(f"control value must be finite, got {self.value}")


@dataclass(frozen=True)
class CellControl:
    """Per-axis cell control plus the stage label written with the history records.

    ``minimise``: a relaxation at fixed cell that the engine may integrate with the scene's
    minimiser (``[integration] relaxation``); only with both rates 0.
    """

    x: AxisControl = field(default_factory=AxisControl)
    y: AxisControl = field(default_factory=AxisControl)
    stage: str = "other"
    minimise: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.minimise, bool):
            raise ValueError(f"minimise = {self.minimise!r}: must be True or False")
        if self.minimise and (self.x.value != 0.0 or self.y.value != 0.0):
            raise ValueError(
                f"minimise = True needs a fixed cell (strain rates 0), got rates "
                f"({self.x.value}, {self.y.value}): use CellControl.relaxation(stage)"
            )

    @classmethod
    def fixed(cls, stage: str = "relax") -> CellControl:
        return cls(AxisControl("strain_rate", 0.0), AxisControl("strain_rate", 0.0), stage)

    @classmethod
    def relaxation(cls, stage: str = "relax") -> CellControl:
        """The cell held fixed and the call marked as a minimisation (``minimise=True``): the
        scene's ``[integration] relaxation`` decides how it is integrated ("damped": exactly
        :meth:`fixed`'s steps; "fire": the FIRE minimiser)."""
        zero = AxisControl("strain_rate", 0.0)
        return cls(zero, zero, stage, minimise=True)

    @classmethod
    def strain_rate(
        cls, rate_x: float, rate_y: float | None = None, stage: str = "other"
    ) -> CellControl:
        rate_y = rate_x if rate_y is None else rate_y
        return cls(AxisControl("strain_rate", rate_x), AxisControl("strain_rate", rate_y), stage)

    @property
    def rates(self) -> np.ndarray:
        """(ε̇_xx, ε̇_yy)."""
        return np.array([self.x.value, self.y.value], dtype=float)


def step_count(name: str, value: Any, low: int) -> int:
    """``value`` as a number of steps >= ``low``: an integer (numpy's too), or a float with a
    whole value such as ``1e4``; a ``ValueError`` naming ``name`` otherwise (NaN, inf, 2.5, a
    bool or a string would make :meth:`Simulation.run` do nothing, or loop, without a word)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} = {value!r}: must be an integer >= {low}")
    if isinstance(value, numbers.Integral):
        count = int(value)
    elif math.isfinite(value) and float(value).is_integer():
        count = int(float(value))
    else:
        raise ValueError(f"{name} = {value!r}: must be a whole number of steps >= {low}")
    if count < low:
        raise ValueError(f"{name} = {value!r} is out of range: allowed integers >= {low}")
    return count
