"""Conservation laws and exact kinematics (no damping, no friction).

- total energy E = kinetic + contact + long-range potential over many collisions of a dense
  acidic gas: |E(t) − E(0)| ≤ 2e-3 · E_kin(0) (velocity Verlet at Δt = 0.05 t_c; the error is
  O(Δt²) and bounded, not drifting);
- linear momentum Σ M v conserved to round-off (pair forces are antisymmetric);
- angular momentum Σ (X × M v + I ω) conserved in an off-centre two-rod collision;
- a free rod rotates at constant ω: θ(t) = θ_0 + ω t and its discs follow.
"""

import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import Simulation
from dem_taichi.scene.config import scene_from_toml
from dem_taichi.scene.geometry import GasState

CONSERVATIVE = """
[scene]
seed = 11
[particles]
n_rods = {n_rods}
n_spheres = 5
initial_area_fraction = 0.2
initial_speed = 1.0
[contact]
k_n = 1.0e4
gamma_n = 0.0
friction = false
[long_range]
enabled = {long_range}
pattern = "acidic"
[integration]
dt_safety = 0.05
local_damping = 0.0
steps_per_call = 500
"""


@pytest.mark.parametrize("long_range", ["true", "false"])
def test_energy_and_momentum_are_conserved_over_many_collisions(long_range):
    scene = scene_from_toml(CONSERVATIVE.format(n_rods=40, long_range=long_range))
    sim = Simulation(scene)
    start = sim.measure()
    e0 = start["kinetic_energy"] + start["contact_energy"] + start["long_range_energy"]
    p0 = sim.get_state()["velocity"].sum(axis=0) * sim.geometry.mass
    worst = 0.0
    contacts_seen = 0
    for _ in range(100):
        m = sim.run(200, output_every=10**9)
        e = m["kinetic_energy"] + m["contact_energy"] + m["long_range_energy"]
        worst = max(worst, abs(e - e0))
        contacts_seen += m["n_contacts"]
    assert contacts_seen > 40  # many collisions happened (contacts seen in 100 samples)
    assert worst <= 2e-3 * start["kinetic_energy"]
    p = sim.get_state()["velocity"].sum(axis=0) * sim.geometry.mass
    assert np.abs(p - p0).max() <= 1e-10 * math.sqrt(start["kinetic_energy"] * 40)


def test_energy_error_is_second_order_in_the_time_step():
    errors = []
    for safety in (0.1, 0.05):
        scene = scene_from_toml(CONSERVATIVE.format(n_rods=20, long_range="true"))
        scene = scene.replace(integration={"dt_safety": safety})
        sim = Simulation(scene)
        m = sim.measure()
        e0 = m["kinetic_energy"] + m["contact_energy"] + m["long_range_energy"]
        worst = 0.0
        for _ in range(40):
            m = sim.run(int(250 * 0.1 / safety), output_every=10**9)
            e = m["kinetic_energy"] + m["contact_energy"] + m["long_range_energy"]
            worst = max(worst, abs(e - e0))
        errors.append(worst)
    # halving Δt divides the energy error by about 4 (allow 2.5 for the changing collision set)
    assert errors[1] < errors[0] / 2.5


def two_rods(velocities, positions, angles, omega=(0.0, 0.0)):
    return GasState(
        np.array([20.0, 20.0]),
        np.array(positions, dtype=float),
        np.array(angles, dtype=float),
        np.array(velocities, dtype=float),
        np.array(omega, dtype=float),
    )


def angular_momentum(sim):
    s = sim.get_state()
    x = s["reduced_position"] * sim.cell_lengths
    v = s["velocity"]
    return float(
        np.sum(sim.geometry.mass * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]))
        + np.sum(sim.geometry.inertia * s["angular_velocity"])
    )


def test_off_centre_collision_conserves_angular_momentum_and_spins_the_rods():
    scene = scene_from_toml(CONSERVATIVE.format(n_rods=2, long_range="false"))
    # rod B (vertical) hits the end disc of rod A (horizontal) off its centre
    gas = two_rods([[0.0, 0.0], [0.0, -1.0]], [[8.0, 8.0], [10.0, 11.5]], [0.0, math.pi / 2])
    sim = Simulation(scene, initial=gas)
    l0 = angular_momentum(sim)
    m0 = sim.measure()
    sim.run(int(1.5 / scene.time_step), output_every=10**9)
    m1 = sim.measure()
    s = sim.get_state()
    assert abs(s["angular_velocity"][0]) > 0.05  # the hit spun rod A
    assert angular_momentum(sim) == pytest.approx(l0, abs=1e-9)
    assert m1["kinetic_energy"] == pytest.approx(m0["kinetic_energy"], rel=1e-3)


def test_a_free_rod_rotates_rigidly_at_constant_angular_velocity():
    scene = scene_from_toml(
        "[particles]\nn_rods = 1\nn_spheres = 4\nspacing = 0.8\n"
        "[integration]\nlocal_damping = 0.0\nsteps_per_call = 64"
    )
    theta0, omega = 0.3, 2.5
    gas = GasState(np.array([15.0, 15.0]), np.array([[7.0, 7.0]]), np.array([theta0]),
                   np.array([[0.1, -0.2]]), np.array([omega]))  # fmt: skip
    sim = Simulation(scene, initial=gas)
    n = 1000
    sim.run(n, output_every=10**9)
    s = sim.get_state()
    t = n * scene.time_step
    assert s["angle"][0] == pytest.approx(theta0 + omega * t, rel=1e-12)
    assert s["angular_velocity"][0] == omega
    centre = s["reduced_position"][0] * 15.0
    np.testing.assert_allclose(centre, [7.0 + 0.1 * t, 7.0 - 0.2 * t], rtol=1e-12)
    discs = sim.a["disc_x"].to_numpy()
    axis = np.array([math.cos(theta0 + omega * t), math.sin(theta0 + omega * t)])
    expected = centre + np.outer((np.arange(4) - 1.5) * 0.8, axis)
    np.testing.assert_allclose(discs, expected, atol=1e-10)
    m = sim.measure()
    ke = 0.5 * 4 * (0.1**2 + 0.2**2) + 0.5 * sim.geometry.inertia * omega**2
    assert m["kinetic_energy"] == pytest.approx(ke, rel=1e-12)
