"""The model's errors name the state they happened at, once."""

from __future__ import annotations

from tiv_model.errors import ConvergenceError, TivModelError


class _State:
    def describe(self) -> str:
        return "p = 1.8 kPa, q = 1.9 kPa"


def test_an_error_names_its_state():
    assert str(TivModelError("failed", _State())) == "failed [state: p = 1.8 kPa, q = 1.9 kPa]"


def test_a_wrapped_error_of_the_same_state_names_it_once():
    inner = ConvergenceError("local step failed", _State())
    outer = ConvergenceError(f"increment failed; last local failure: {inner}", _State())
    assert str(outer).count("[state:") == 1
    other = TivModelError(f"driver stopped: {inner}", None)
    assert str(other).count("[state:") == 1
