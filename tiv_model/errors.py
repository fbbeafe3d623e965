"""Typed errors of the TIV model.

Every error raised while integrating names the state at which it happened (mean stress p,
deviatoric stress q, specific volume v, fabric β), so that a failed run says where and why it
stopped instead of returning NaN.
"""

from __future__ import annotations

from typing import Any


class TivModelError(Exception):
    """Base class of every error raised by :mod:`tiv_model`."""

    def __init__(self, message: str, state: Any = None) -> None:
        self.state = state
        if state is not None and hasattr(state, "describe"):
            described = f"[state: {state.describe()}]"
            if described not in message:  # a wrapped error of the same state names it once
                message = f"{message} {described}"
        super().__init__(message)


class ParameterError(TivModelError, ValueError):
    """A model parameter, option or driver argument is outside its allowed range."""


class ConvergenceError(TivModelError, RuntimeError):
    """The implicit integration of an increment did not converge, even after substepping."""


class NonConvexEnergyError(TivModelError, ArithmeticError):
    """The free energy is not strictly convex at this fabric: ω β_s² ≥ 3/2."""


class SpecificVolumeBelowOneError(TivModelError, ArithmeticError):
    """The specific volume fell below 1 (negative void ratio): the model is unphysical there."""


class ControlError(TivModelError, ValueError):
    """A loading path cannot be followed as specified (e.g. stress ratio beyond its limit)."""
