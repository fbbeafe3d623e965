"""Shared fixtures of the tiv_model tests."""

import numpy as np
import pytest

from tiv_model.params import TABLE1, ModelOptions
from tiv_model.tensors import IDENTITY_MANDEL, deviator, triaxial_fabric

ALL_OPTIONS = [
    ModelOptions(anisotropy=form, constraint_forces=cf) for form in "AB" for cf in (True, False)
]


def option_id(options: ModelOptions) -> str:
    return f"{options.anisotropy}-{'cf' if options.constraint_forces else 'nocf'}"


@pytest.fixture(params=ALL_OPTIONS, ids=option_id)
def options(request) -> ModelOptions:
    return request.param


@pytest.fixture(params=["A", "B"])
def form(request) -> str:
    return request.param


def random_elastic_state(rng: np.random.Generator, max_fabric: float = 0.2):
    """A random elastic strain (compressive, mostly volumetric), specific volume and fabric."""
    eps_v = 10 ** rng.uniform(-4, -1.5)
    eps = eps_v / 3.0 * IDENTITY_MANDEL + 0.2 * eps_v * rng.standard_normal(6)
    v = rng.uniform(1.05, 3.0)
    beta = deviator(rng.standard_normal(6))
    beta *= rng.uniform(0.0, 1.0) * max_fabric / np.sqrt(1.5 * beta @ beta)
    return eps, v, beta


__all__ = ["TABLE1", "random_elastic_state", "triaxial_fabric"]
