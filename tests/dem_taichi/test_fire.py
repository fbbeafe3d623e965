"""The FIRE minimiser of the relaxations (issue 20; dem_taichi.kernels.fire).

States (module fixtures, smoke scene: 40 rods of 5 discs, friction μ = 0.5, long-range forces):
``jammed`` the gas compressed at ε̇ = 0.02 until p > 3 (past jamming, not relaxed: UFR ~ 1);
``static`` it relaxed with the damped dynamics to UFR < 1e-4; ``strained`` the static state
compressed isotropically by Δε = 2e-4 over 200 steps (a strain increment of a path).
"""

import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.engine.state import states_equal
from dem_taichi.kernels import layout
from dem_taichi.physics.forcelaw import pair_separation
from dem_taichi.scene.base import SceneError
from dem_taichi.scene.config import load_scene

UFR = 1e-4  # the protocol's relax_unbalanced_force
KE_PER_ROD = 1e-8  # the smoke scene's relax_kinetic_energy_per_rod
CHECK = 500  # the protocol's relax_check_steps


@pytest.fixture(scope="module")
def smoke():
    return load_scene("smoke")


@pytest.fixture(scope="module")
def fire_scene(smoke):
    return smoke.replace(integration={"relaxation": "fire"})


def _relax(sim, max_steps=40_000, check=CHECK):
    """Minimising calls of ``check`` steps until UFR < 1e-4 and KE/N < 1e-8 (as
    quasistatic.relax); returns (measures, steps)."""
    steps = 0
    while steps < max_steps:
        m = sim.run(check, CellControl.relaxation("relax"), output_every=check)
        steps += check
        ufr = m["unbalanced_force_ratio"]
        if math.isfinite(ufr) and ufr < UFR and m["kinetic_energy"] / sim.n_rods < KE_PER_ROD:
            return m, steps
    raise AssertionError(f"not relaxed after {steps} steps: UFR {ufr:.3g}")


@pytest.fixture(scope="module")
def states(smoke):
    sim = Simulation(smoke)
    for _ in range(1000):
        m = sim.run(100, CellControl.strain_rate(0.02, stage="isotropic_to_A"), output_every=100)
        if m["mean_stress"] > 3.0:
            break
    jammed = sim.get_state()
    _relax(sim)
    static = sim.get_state()
    sim.run(200, CellControl.strain_rate(2e-4 / (200 * sim.time_step)), output_every=200)
    return {"jammed": jammed, "static": static, "strained": sim.get_state()}


def _from(scene, state):
    sim = Simulation(scene)
    sim.set_state(state)
    return sim


def _centroid_difference(a, b) -> tuple[float, float]:
    """(rms centroid distance / d after removing the mean shift, max |Δθ| [rad]) of two
    simulations of the same rods in the same cell (minimum image)."""
    d = a.rod_positions() - b.rod_positions()
    lengths = a.cell_lengths
    d -= np.round(d / lengths) * lengths
    d -= d.mean(axis=0)
    angle = np.angle(np.exp(1j * (a.rod_angles() - b.rod_angles())))
    return float(np.sqrt((d * d).sum(axis=1).mean())), float(np.abs(angle).max())


def test_fire_relaxes_a_strain_increment_to_the_damped_static_state_in_fewer_steps(
    smoke, fire_scene, states
):
    """From the strained state both reach UFR < 1e-4, KE/N < 1e-8. Measured (this fixture):
    damped 4500 steps, p = 0.490, 79 contacts; FIRE 1000 steps, p = 0.562, 76 contacts;
    centroids 0.0043 d rms apart, angles 0.0028 rad at most. On an AVX-512 EPYC, whose smoke
    trajectory departs from the references' host (``codegen_host`` in test_protocol.py): damped
    4000 steps, p = 0.277, 81 contacts; FIRE 500 steps, p = 0.389, 80 contacts; centroids
    0.0008 d apart, angles 0.0006 rad. Stated tolerance: centroids < 0.01 d rms and angles
    < 0.01 rad, contacts within 5 %, p within a factor 1.5 (20 % before that host). The stress
    is the loosest because frictional static states depend on the path, not because of FIRE: the
    damped relaxation itself, from the same state, ends at p = 0.442, 0.475, 0.490, 0.563,
    0.560 with local damping α = 0.05, 0.1, 0.2, 0.5, 0.7 (measured); at p ≈ 0.5 the overlaps
    are δ ≈ 1e-5 d, so 1e-3 d in the centroids is tens of % in p. Steps: FIRE fewer than damped
    (4.5x here; asserted only as fewer)."""
    damped = _from(smoke, states["strained"])
    md, steps_damped = _relax(damped)
    fire = _from(fire_scene, states["strained"])
    mf, steps_fire = _relax(fire)
    print(f"damped {steps_damped} steps p {md['mean_stress']:.4g} contacts {md['n_contacts']}")
    print(f"FIRE {steps_fire} steps p {mf['mean_stress']:.4g} contacts {mf['n_contacts']}")
    rms, angle = _centroid_difference(damped, fire)
    print(f"centroids {rms:.3g} d rms apart, angles {angle:.3g} rad at most")
    assert rms < 0.01 * smoke.particles.diameter
    assert angle < 0.01
    assert abs(mf["n_contacts"] - md["n_contacts"]) <= 0.05 * md["n_contacts"]
    assert 1 / 1.5 < mf["mean_stress"] / md["mean_stress"] < 1.5
    assert steps_fire < steps_damped


def _check_springs(sim) -> int:
    """Every listed contact's stored spring obeys k_t |ξ| ≤ μ |f_c| (f_c the normal contact
    force of the same positions and velocities, from the measure kernel), non-contacts have
    ξ = 0; returns the number of contacts at the cap."""
    sim.measure()
    count = sim.a["nbr_count"].to_numpy()
    xi = sim.a["nbr_xi"].to_numpy()
    fc = sim.a["pair_out"].to_numpy()[..., 2]
    flags = sim.a["pair_flags"].to_numpy()
    listed = np.arange(xi.shape[1])[None, :] < count[:, None]
    contact = listed & ((flags & layout.PAIR_CONTACT) != 0)
    k_t, mu = sim.scene.contact.k_t, sim.scene.contact.mu
    cap = mu * np.abs(fc[contact])
    spring = k_t * np.abs(xi[contact])
    assert np.all(spring <= cap * (1 + 1e-9) + 1e-12), float(np.max(spring - cap))
    assert np.all(xi[listed & ~contact] == 0.0)
    return int(np.sum(spring >= cap * (1 - 1e-9)))


def test_tangential_springs_stay_within_the_coulomb_cap_during_a_fire_relaxation(
    fire_scene, states
):
    """From the jammed (unrelaxed, sliding) state, every 100 FIRE steps and at the end: each
    spring within μ|f_c| (contacts do reach the cap, so the check bites); at the end also by the
    numpy reference on the snapshot: k_t |ξ| ≤ μ k_n δ within 1 % (the dashpot part of f_c is
    ~1e-4 of it at rest)."""
    sim = _from(fire_scene, states["jammed"])
    at_cap = 0
    for _ in range(40):
        sim.run(100, CellControl.relaxation("relax"), output_every=100)
        at_cap += _check_springs(sim)
    assert at_cap > 0
    _relax(sim)
    _check_springs(sim)
    snap = sim.snapshot()
    delta = snap.diameter - np.linalg.norm(pair_separation(snap), axis=1)
    touching = delta > 0
    spring = snap.k_t * np.linalg.norm(snap.tangential_spring, axis=1)[touching]
    assert np.all(spring <= snap.mu * snap.k_n * delta[touching] * 1.01)
    assert touching.sum() > 0


def test_minimise_on_a_damped_scene_is_bitwise_a_fixed_cell_run(smoke, fire_scene, states):
    """relaxation = "damped" (the default): CellControl.relaxation(stage) runs exactly the steps
    of CellControl.fixed(stage); on a "fire" scene a non-minimising call is the damped step too."""
    runs = []
    for scene, control in (
        (smoke, CellControl.fixed("relax")),
        (smoke, CellControl.relaxation("relax")),
        (fire_scene, CellControl.fixed("relax")),
    ):
        sim = _from(scene, states["jammed"])
        sim.run(700, control, output_every=700)
        runs.append(sim.get_state())
    assert states_equal(runs[0], runs[1])
    assert states_equal(runs[0], runs[2])
    fire = _from(fire_scene, states["jammed"])
    fire.run(700, CellControl.relaxation("relax"), output_every=700)
    assert not states_equal(runs[0], fire.get_state())


def test_the_time_step_is_the_scenes_after_a_fire_call(fire_scene, states):
    """Δt grows within the call (to at most fire_dt_max × Δt = 1.5 Δt) and is Δt after it."""
    sim = _from(fire_scene, states["strained"])
    dt = sim.time_step
    assert dt == fire_scene.time_step
    sim.run(300, CellControl.relaxation("relax"), output_every=150)
    status = sim.fire_status()
    assert dt < status["dt"] <= 1.5 * dt * (1 + 1e-12)
    assert status["steps"] == 300
    assert sim.time_step == dt
    assert sim.a["params"].to_numpy()[layout.P_DT] == dt
    before = sim.time
    sim.run(10, CellControl.fixed("relax"), output_every=10)
    assert sim.time - before == pytest.approx(10 * dt, rel=1e-12)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"relaxation": "newton"}, r"\[integration\] relaxation = 'newton': allowed values"),
        ({"relaxation": "fire", "fire_dt_max": 3.0}, r"\[integration\] fire_dt_max = 3.0 is out"),
        ({"relaxation": "fire", "fire_f_dec": 1.0}, r"\[integration\] fire_f_dec = 1.0 is out"),
        ({"relaxation": "fire", "fire_n_delay": 2.5}, r"\[integration\] fire_n_delay = 2.5: must"),
        ({"relaxation": "fire", "fire_alpha_start": -0.1}, r"fire_alpha_start = -0.1 is out"),
        ({"fire_f_inc": 1.2}, r"\[integration\] fire_f_inc: used only with relaxation = \"fire\""),
        ({"relaxation": "fire", "execution": "parallel"}, r"relaxation = \"fire\" needs execution"),
    ],
)
def test_bad_fire_keys_are_refused_at_load_in_one_line(smoke, changes, message):
    with pytest.raises(SceneError, match=message) as error:
        smoke.replace(integration=changes)
    assert "\n" not in str(error.value)


def test_fire_with_a_parallel_execution_or_a_moving_cell_is_refused(fire_scene):
    with pytest.raises(ValueError, match=r"relaxation = \"fire\" needs the serial execution"):
        Simulation(fire_scene, execution="gather")
    with pytest.raises(ValueError, match=r"minimise = True needs a fixed cell"):
        moving = CellControl.strain_rate(0.1)
        CellControl(moving.x, moving.y, "isotropic_to_A", minimise=True)


def test_the_scene_toml_of_a_damped_scene_is_unchanged(smoke, fire_scene):
    """The new keys are written only when set (run directories hash the scene's TOML)."""
    from dem_taichi.scene.config import scene_from_toml, scene_to_toml

    assert "relaxation" not in scene_to_toml(smoke) and "fire_" not in scene_to_toml(smoke)
    text = scene_to_toml(fire_scene.replace(integration={"fire_f_inc": 1.05}))
    assert 'relaxation = "fire"' in text and "fire_f_inc = 1.05" in text
    assert scene_from_toml(text).integration.fire["f_inc"] == 1.05
    assert fire_scene.integration.fire["dt_max"] == 1.5


@pytest.mark.slow
def test_fire_relaxes_bonded_rods():
    """Bonded rods (every disc a body joined by bonds): the same kernel path. From the smoke_bonded
    gas compressed past jamming (p > 3), FIRE reaches UFR < 1e-4 and KE/N < 1e-8, with Δt back
    to the scene's and the springs within the cap. Measured: damped 38 000 steps, FIRE 38 000
    (UFR < 1e-4 after ~28 000; the KE criterion binds: α decays to ~1e-3 over a 500-step call,
    and the bodies then move with little damping but the bonds'). ~30 s."""
    scene = load_scene("smoke_bonded")
    sim = Simulation(scene)
    for _ in range(2000):
        m = sim.run(100, CellControl.strain_rate(0.02, stage="isotropic_to_A"), output_every=100)
        if m["mean_stress"] > 3.0:
            break
    fire = _from(scene.replace(integration={"relaxation": "fire"}), sim.get_state())
    m, steps = _relax(fire, max_steps=60_000)
    print(f"bonded FIRE {steps} steps, p {m['mean_stress']:.4g}")
    assert fire.time_step == scene.time_step
    _check_springs(fire)
