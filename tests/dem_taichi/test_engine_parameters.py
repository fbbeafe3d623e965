"""The typed runtime parameters (dem_taichi.engine.parameters) and the kernels' slot table
(dem_taichi.kernels.layout.PARAMETER_SLOTS): one table, and the same numbers as before.

The reference vectors (tests/data/engine_parameters_760e3e2.npz) are what
``Simulation._default_params()`` produced at commit 760e3e2, before this object replaced it
(tests/data/engine_parameters_760e3e2.md: the script that wrote them).
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from dem_taichi.engine.parameters import (
    TUNABLE_PARAMETERS,
    EngineParameters,
    interaction_cutoff,
    resolve_parameters,
    resolve_physics,
    resolve_scene,
)
from dem_taichi.kernels import layout as L
from dem_taichi.scene.config import Scene, load_scene
from dem_taichi.scene.geometry import body_geometry, rod_geometry, species_parameters

REFERENCE = Path(__file__).resolve().parents[1] / "data" / "engine_parameters_760e3e2.npz"


def reference_scenes() -> dict[str, Scene]:
    """The scenes of the reference file (as its script built them)."""
    smoke = load_scene("smoke")
    bonded = load_scene("smoke_bonded")
    roll = {"rolling_stiffness": 2e4, "rolling_friction": 0.3}
    return {
        "default": load_scene("default"),
        "smoke": smoke,
        "smoke_bonded": bonded,
        "smoke_rolling": smoke.replace(contact=roll),
        "smoke_bonded_rolling": bonded.replace(contact=roll),
        "smoke_vdw_frictionless": smoke.replace(
            van_der_waals={"enabled": True}, contact={"friction": False}
        ),
        "smoke_vdw_only": smoke.replace(
            long_range={"enabled": False},
            van_der_waals={"enabled": True},
            contact={"gamma_t": 3.0},
        ),
    }


def resolved(scene: Scene) -> EngineParameters:
    """The parameters resolved as the Simulation resolves them (without building one)."""
    rod = rod_geometry(scene)
    charge, _, _ = species_parameters(scene)
    physics = resolve_physics(scene, charge, rod.n_spheres)
    cutoff = interaction_cutoff(scene, rod.diameter, physics)
    list_radius = cutoff + scene.integration.skin
    return resolve_parameters(scene, body_geometry(scene), physics, list_radius, cutoff)


def test_the_fields_are_the_slot_table_one_to_one():
    names = tuple(field.name for field in dataclasses.fields(EngineParameters))
    assert names == L.PARAMETER_SLOTS
    assert len(set(names)) == len(names) == L.N_PARAMS
    assert set(TUNABLE_PARAMETERS) <= set(names)


def test_every_slot_constant_is_derived_from_the_table():
    constants = {k: v for k, v in vars(L).items() if k.startswith("P_")}
    assert all(type(v) is int for v in constants.values())  # compile-time ints for Taichi
    # one constant per slot, each slot once: the kernels' names cover the table exactly
    assert sorted(constants.values()) == list(range(L.N_PARAMS))
    assert constants["P_MU"] == L.PARAMETER_SLOTS.index("mu")
    assert constants["P_RATE_Y"] == L.PARAMETER_SLOTS.index("rate_y")
    assert constants["P_ROLL_CAP"] == L.N_PARAMS - 1
    with pytest.raises(ValueError):
        L.parameter_slot("friction")


def test_the_vector_puts_each_field_in_its_slot_and_reads_back():
    distinct = EngineParameters(*[float(i + 1) for i in range(L.N_PARAMS)])
    vector = distinct.vector()
    assert np.array_equal(vector, np.arange(1.0, L.N_PARAMS + 1.0))
    assert vector[L.P_MU] == distinct.mu and vector[L.P_BOND_KB] == distinct.bond_k_b
    assert EngineParameters.from_vector(vector) == distinct
    assert distinct.vector(np.float32).dtype == np.float32
    with pytest.raises(ValueError, match="expected"):
        EngineParameters.from_vector(vector[:-3])  # an old state: upgrade_state first


@pytest.mark.parametrize("name", list(reference_scenes()))
def test_resolved_vectors_equal_the_old_default_params_slot_by_slot(name):
    with np.load(REFERENCE) as reference:
        assert sorted(reference.files) == sorted(reference_scenes())
        expected = reference[name]
    vector = resolved(reference_scenes()[name]).vector(np.float64)
    assert vector.shape == expected.shape
    for slot, field in enumerate(L.PARAMETER_SLOTS):
        assert vector[slot] == expected[slot], field
    assert vector.tobytes() == expected.tobytes()
    assert resolve_scene(reference_scenes()[name]).parameters.vector().tobytes() == vector.tobytes()


@pytest.mark.parametrize("name", ["smoke", "smoke_bonded_rolling"])
def test_a_simulation_starts_with_the_resolved_vector(name):
    from dem_taichi.engine.simulation import Simulation

    with np.load(REFERENCE) as reference:
        expected = reference[name]
    sim = Simulation(reference_scenes()[name])
    assert np.array_equal(sim.a["params"].to_numpy(), expected)
    assert sim.parameters == sim.scene_parameters == EngineParameters.from_vector(expected)
    sim.set_parameters(mu=0.25)
    assert sim.parameters == sim.scene_parameters.with_changes(mu=0.25)
    assert sim.a["params"].to_numpy()[L.P_MU] == 0.25


def test_changes_by_name_are_checked():
    params = resolved(load_scene("smoke"))
    assert params.tuned(mu=0.1, time_step=1e-4).mu == 0.1
    assert params.with_changes(rate_x=-0.5).rate_x == -0.5  # the control's rates may be < 0
    with pytest.raises(ValueError, match="unknown parameter 'mass'; allowed: gamma_n"):
        params.tuned(mass=2.0)  # not a run-time change: it follows from the geometry
    with pytest.raises(ValueError, match="must be finite and >= 0"):
        params.tuned(mu=-0.1)
    with pytest.raises(ValueError, match="must be finite and >= 0"):
        params.tuned(k_n=float("nan"))
    with pytest.raises(ValueError, match="unknown parameter 'stiffness'"):
        params.with_changes(stiffness=1.0)
