"""Shared synthetic "DEM-like" results made by tiv_model with known parameters."""

import pytest

from bridge.series import Convention
from bridge.synthetic import synthetic_results
from tiv_model.params import TABLE1

#: Table 1 perturbed: the parameters the calibration must give back.
TRUTH = TABLE1.replace(
    g=40.0, k=70.0, n=0.2, r=0.5, N=1.35, lambda_star=0.22, M=1.0, c=1.5, s=10.0, z=6.0, omega=20.0
)
#: A convention that is not the identity (scale 50 kPa per DEM unit, fabric scale 2).
CONVENTION = Convention(stress_scale_kpa=50.0, name="triaxial", fabric_scale=2.0)


@pytest.fixture(scope="session")
def synthetic():
    """Isotropic, K0 (6 increments each) and unloading (3) paths with probes at every state."""
    return synthetic_results(TRUTH, convention=CONVENTION, increments=6, unloading_increments=3)
