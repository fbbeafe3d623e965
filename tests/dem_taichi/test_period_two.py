"""A time step past a body's local stability limit: the bounded period-two oscillation that the
relaxation barely removes (dem_taichi.engine.failures.period_two_bodies;
benchmarks/results/period_two.md).

The engine case is a periodic chain of four discs, each pressed by its two neighbours
(overlap 0.01 d): its stiffest mode, the discs moving in antiphase, has ω² = 4 k_n/m against the
2 k_n/m of the contact that sets Δt, and with the scene's contact dashpot (e_n = 0.5) and local
damping (0.2) its leapfrog step is unstable at dt_safety 0.3 but not at 0.15. The contacts open
during each cycle, which bounds the oscillation: the run does not diverge, and it does not relax.
"""

import numpy as np
import pytest

from dem_taichi.engine.failures import (
    PERIOD_TWO_SHARE,
    BlowUpError,
    period_two_bodies,
    period_two_error,
)
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.protocol.quasistatic import relax
from dem_taichi.scene.config import scene_from_toml
from dem_taichi.scene.geometry import GasState

DT, ALPHA, MASS, INERTIA = 2e-3, 0.2, 5.0, 10.0


def _orbit_velocity(force: np.ndarray, mass: float) -> np.ndarray:
    """The half-step velocity that the next kick reverses exactly (a steady period-two orbit)."""
    return -DT * (1.0 + ALPHA) * force / (2.0 * mass)


def test_a_body_whose_kick_reverses_its_velocity_is_found_and_weighted_by_its_force():
    force = np.array([[27.0, -4.0], [0.3, 0.1], [-2.0, 0.5], [0.0, 0.0]])
    velocity = np.array([
        _orbit_velocity(force[0], MASS),  # caught in the orbit
        [-30.0, -10.0],  # a slow mode being slowed down: its kick is ~1e-5 of its velocity
        -_orbit_velocity(force[2], MASS),  # the same size, but along its force: accelerating
        [1.0, 0.0],  # free flight
    ])  # fmt: skip
    found = period_two_bodies(force, velocity, np.zeros(4), np.zeros(4), MASS, INERTIA, DT, ALPHA)
    assert found.bodies.tolist() == [0]
    magnitude = np.hypot(force[:, 0], force[:, 1])
    assert found.share == pytest.approx(magnitude[0] / magnitude.sum())


def test_the_rotation_counts_too_and_a_breathing_orbit_is_inside_the_band():
    torque = np.array([4.0, -1.0])
    omega = -DT * (1.0 + ALPHA) * torque / (2.0 * INERTIA)
    omega[1] *= 1.4  # an orbit whose amplitude changes from step to step (ratio 1.4)
    force = np.array([[1.0, 0.0], [1.0, 0.0]])  # no translational signature
    found = period_two_bodies(force, np.zeros((2, 2)), torque, omega, MASS, INERTIA, DT, ALPHA)
    assert found.bodies.tolist() == [0, 1]
    assert found.share == 1.0


def test_a_static_state_has_no_share():
    found = period_two_bodies(
        np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), np.zeros(3), MASS, INERTIA, DT, ALPHA
    )
    assert found.bodies.size == 0 and found.share == 0.0


def chain_scene(dt_safety: float):
    return scene_from_toml(
        f"""
[particles]
n_rods = 4
n_spheres = 1
[contact]
k_n = 1.0e5
e_n = 0.5
friction = false
[long_range]
enabled = false
[integration]
local_damping = 0.2
steps_per_call = 50
dt_safety = {dt_safety}
"""
    )


def pressed_chain_on(dt_safety: float, **engine) -> Simulation:
    """Four discs in a row, each overlapping its two neighbours by about 0.01 d across the
    periodic cell, slightly out of place so that every mode starts; ``engine``: the
    simulation's options (``arch``, ``execution``)."""
    overlap = 0.01
    length = 4 * (1.0 - overlap)
    x = 0.5 + np.arange(4) * (1.0 - overlap) + np.array([0.0, 0.002, -0.001, 0.0005])
    gas = GasState(
        np.array([length, 6.0]), np.c_[x, np.full(4, 3.0)], np.zeros(4), np.zeros((4, 2)),
        np.zeros(4),
    )  # fmt: skip
    return Simulation(chain_scene(dt_safety), initial=gas, **engine)


def test_past_the_local_stability_limit_the_relaxation_stops_and_says_what_to_change():
    sim = pressed_chain_on(0.3)
    with pytest.raises(BlowUpError) as caught:
        relax(sim, "relax", 1e-4, 1e-6, 500, 6000)
    message = str(caught.value)
    assert "period of two time steps" in message
    assert "[integration] dt_safety from 0.3" in message
    found = sim.period_two()
    assert found.share >= PERIOD_TWO_SHARE and found.bodies.tolist() == [0, 1, 2, 3]
    # the reading of the signature: the next kick reverses each body's velocity
    before = sim.get_state()["velocity"][:, 0]
    sim.run(1, CellControl.relaxation("relax"), output_every=1)
    after = sim.get_state()["velocity"][:, 0]
    assert np.all(np.sign(after) == -np.sign(before))


def test_within_the_limit_the_same_chain_relaxes():
    sim = pressed_chain_on(0.15)
    measures, relaxed, steps = relax(sim, "relax", 1e-4, 1e-6, 500, 6000)
    assert relaxed and steps < 6000
    assert sim.period_two().bodies.size == 0


def test_the_message_names_the_path_time_step_factor_when_the_paths_integrate_at_a_multiple():
    sim = pressed_chain_on(0.15)
    found = period_two_bodies(
        np.ones((2, 2)), -np.ones((2, 2)) * DT * 1.2 / 2, np.zeros(2), np.zeros(2), 1.0, 1.0,
        DT, ALPHA,
    )  # fmt: skip
    error = period_two_error(found, "A_to_C", 10, 2.0 * sim.time_step, sim.time_step,
                             sim.scene.integration)  # fmt: skip
    assert "2 x the scene's" in str(error) and "path_time_step_factor" in str(error)
    assert "dt_safety" not in str(error)


GPU_SCRIPT = """
import json, sys
sys.path.insert(0, sys.argv[1])
from test_period_two import pressed_chain_on
from dem_taichi.engine.failures import BlowUpError
from dem_taichi.protocol.quasistatic import relax
result = {}
for dt_safety in (0.15, 0.3):
    sim = pressed_chain_on(dt_safety, arch="gpu", execution=sys.argv[2])
    try:
        relaxed = relax(sim, "relax", 1e-4, 1e-6, 500, 6000)[1]
        result[str(dt_safety)] = ["relaxed" if relaxed else "not relaxed", []]
    except BlowUpError:
        result[str(dt_safety)] = ["period two", sim.period_two().bodies.tolist()]
print(json.dumps(result))
"""


@pytest.mark.gpu
@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_on_a_gpu_the_chain_stops_and_relaxes_as_on_the_cpu(execution):
    """The period-two stop reads the device's arrays (in a subprocess: its own runtime)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from dem_taichi.engine.runtime import cuda_available

    if not cuda_available():
        pytest.skip("no CUDA device")
    out = subprocess.run(
        [sys.executable, "-c", GPU_SCRIPT, str(Path(__file__).parent), execution],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"0.15": ["relaxed", []], "0.3": ["period two", [0, 1, 2, 3]]}
