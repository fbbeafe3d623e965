"""Parameters, options and their validation."""

import math

import pytest

from tiv_model.errors import ParameterError
from tiv_model.params import (
    PARAMETER_INFO,
    TABLE1,
    ModelOptions,
    Parameters,
    SolverSettings,
    exponential_bound,
    hyperbolic_tangent_bound,
)


def test_table1_values_and_symbols():
    sym = TABLE1.as_symbols()
    assert sym == {
        "p_r": 100.0, "g": 48.0, "k": 64.0, "n": 0.17, "r": 0.63, "N": 1.3,
        "lambda_star": 0.25, "M": 1.1, "c": 1.2, "s": 14.0, "z": 5.4, "omega": 25.0,
    }  # fmt: skip
    assert Parameters.from_symbols(sym) == TABLE1
    assert TABLE1.poisson_ratio == pytest.approx(0.2, abs=1e-12)
    assert TABLE1.energy_exponent == pytest.approx(0.63 / (-0.83 * 0.25))


@pytest.mark.parametrize(
    ("symbol", "value", "fragment"),
    [
        ("n", 1.0, "n < 1"),
        ("n", 1.3, "n < 1"),
        ("n", -0.1, "0 ≤ n"),
        ("z", 1.0, "1 < z"),
        ("z", 0.5, "1 < z"),
        ("k", -64.0, "0 < k"),
        ("g", 0.0, "0 < g"),
        ("M", 0.0, "0 < M"),
        ("M", -1.1, "0 < M"),
        ("N", 0.9, "1 < N"),
        ("lambda_star", 0.0, "0 < lambda_star"),
        ("omega", -1.0, "0 ≤ omega"),
        ("p_r", math.nan, "p_r"),
        ("c", math.inf, "c"),
    ],
)
def test_invalid_parameters_fail_with_a_clear_message(symbol, value, fragment):
    with pytest.raises(ParameterError) as info:
        TABLE1.replace(**{symbol: value})
    text = str(info.value)
    assert fragment in text
    assert repr(float(value)) in text or str(value) in text


def test_non_numbers_and_unknown_names_rejected():
    with pytest.raises(ParameterError, match="real number"):
        TABLE1.replace(k="64")
    with pytest.raises(ParameterError, match="unknown"):
        TABLE1.replace(kappa=0.1)
    with pytest.raises(ParameterError, match="missing"):
        Parameters.from_symbols({"p_r": 100.0})


def test_every_parameter_has_units_and_bounds():
    for name, info in PARAMETER_INFO.items():
        assert hasattr(TABLE1, name)
        assert len(info) == 7


def test_options_validation():
    assert ModelOptions().anisotropy == "A" and ModelOptions().constraint_forces
    with pytest.raises(ParameterError, match="anisotropy"):
        ModelOptions(anisotropy="C")
    with pytest.raises(ParameterError, match="constraint_forces"):
        ModelOptions(constraint_forces="yes")
    with pytest.raises(ParameterError, match="bound_law"):
        ModelOptions(bound_law=3.0)
    with pytest.raises(ParameterError, match="tolerance"):
        SolverSettings(tolerance=-1.0)


@pytest.mark.parametrize("law", [exponential_bound, hyperbolic_tangent_bound])
def test_bound_laws_are_smooth_at_zero_and_saturate(law):
    # f(η) η is the magnitude of β_b; the series branch must join the closed form smoothly
    scale = TABLE1.M / TABLE1.z
    a = TABLE1.s / TABLE1.M
    for eta in (0.0, 1e-9, 5e-6, 7.857e-6, 7.858e-6, 1e-5, 1e-4):
        f = float(law(eta, TABLE1))
        if law is exponential_bound and eta > 0:
            exact = scale * -math.expm1(-a * eta) / eta
            assert f == pytest.approx(exact, rel=1e-13)
        assert f == pytest.approx(scale * a, rel=1e-3)
    assert float(law(50.0, TABLE1)) * 50.0 == pytest.approx(scale, rel=1e-12)


def test_numpy_scalars_are_real_numbers():
    """Values read back from netCDF are numpy scalars: accepted and stored as float."""
    import numpy as np

    from tiv_model.params import TABLE1

    changed = TABLE1.replace(g=np.float32(50.0), k=np.int64(70), n=np.float64(0.2))
    assert (changed.g, changed.k, changed.n) == (50.0, 70.0, 0.2)
    assert type(changed.g) is float and type(changed.k) is float
    with pytest.raises(ParameterError, match="real number"):
        TABLE1.replace(g=np.bool_(True))
    with pytest.raises(ParameterError, match="real number"):
        TABLE1.replace(g=np.array([50.0]))
