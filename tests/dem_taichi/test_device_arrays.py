"""The table of device arrays: every kernel's array parameter is declared in it, once."""

from __future__ import annotations

import inspect

import pytest

from dem_taichi.engine.device_arrays import (
    DEVICE_ARRAYS,
    STATE_ARRAYS,
    DeviceArray,
    kernel_parameters,
)
from dem_taichi.engine.state import STATE_KEYS

#: Compile-time and scalar kernel parameters the engine passes by name.
SCALARS = {"ns", "full", "phys", "n_steps", "count_step", "advance", "first", "n_rods", "chain"}


def test_names_and_state_keys_are_unique():
    names = [a.name for a in DEVICE_ARRAYS]
    assert len(names) == len(set(names))
    keys = [a.state_key for a in STATE_ARRAYS]
    assert len(keys) == len(set(keys))
    assert STATE_KEYS[: len(keys)] == tuple(keys)


def test_shapes_follow_the_sizes():
    sizes = {"rods": 3, "discs": 15, "spheres": 5, "species": 5, "capacity": 7, "cells": 4}
    sizes["rolling_discs"] = 1  # no rolling resistance: the rolling springs take one row
    sizes["strength_rods"] = 1  # rods alike: the strengths take one entry
    sizes["partner_rods"] = 1  # every pair attracts: one unused row of partners
    sizes["measure_blocks"] = 2
    shapes = {a.name: a.shape_for(sizes) for a in DEVICE_ARRAYS}
    assert shapes["pos"] == (3, 2) and shapes["nbr"] == (15, 7) and shapes["pair_out"] == (15, 7, 4)
    assert shapes["nbr_psi"] == (1, 7) and shapes["old_psi"] == (1, 7)
    assert shapes["cell_count"] == (4, 4) and shapes["pair_table"] == (5, 5, 3)
    assert shapes["rod_strength"] == (1,)
    assert shapes["attraction_partners"] == (1, 32)
    # bonded rods: the bodies are the discs, one disc per body, the species per place in a rod
    bonded = {"rods": 15, "discs": 15, "spheres": 1, "species": 5, "capacity": 7, "cells": 4}
    bonded["rolling_discs"] = 15  # with rolling resistance: one spring per list entry
    bonded["strength_rods"] = 3  # a spread of strengths: one per rod, not per body
    bonded["partner_rods"] = 3  # attraction only between the rods bonded at A: a row per rod
    bonded["measure_blocks"] = 3
    shapes = {a.name: a.shape_for(bonded) for a in DEVICE_ARRAYS}
    assert shapes["pos"] == (15, 2) and shapes["offsets"] == (1,) and shapes["charge"] == (5,)
    assert shapes["bond_intact"] == (15,) and shapes["nbr_psi"] == (15, 7)
    assert shapes["rod_strength"] == (3,)
    assert shapes["attraction_partners"] == (3, 32)
    assert shapes["block_sums"] == (3, 16)
    grown = {a.name for a in DEVICE_ARRAYS if a.grows}
    assert grown == {
        "nbr", "nbr_xi", "nbr_psi", "old_nbr", "old_xi", "old_psi", "pair_out", "pair_flags"
    }  # fmt: skip
    with pytest.raises(ValueError, match="state key"):
        DeviceArray("x", "real", ("rods",), "state")


def test_every_kernel_parameter_is_a_declared_array_or_a_scalar():
    pytest.importorskip("taichi")
    from dem_taichi.kernels import bonds, common, measures, neighbours, pairs, parallel, step
    from dem_taichi.kernels import coordination as coord
    from dem_taichi.kernels import parallel_lists as lists

    kernels = [
        obj
        for module in (bonds, common, coord, measures, neighbours, pairs, parallel, lists, step)
        for _, obj in inspect.getmembers(module, inspect.isfunction)
        if obj.__module__ == module.__name__ and hasattr(obj, "_primal")
    ]
    assert len(kernels) == 13
    declared = {a.name for a in DEVICE_ARRAYS}
    for kernel in kernels:
        unknown = set(kernel_parameters(kernel)) - declared - SCALARS
        assert not unknown, (kernel.__name__, unknown)


def test_every_kernel_array_parameter_has_the_dimension_of_the_table():
    pytest.importorskip("taichi")
    from dem_taichi.kernels import common, coordination, measures, parallel, parallel_lists, step

    shapes = {a.name: a.shape for a in DEVICE_ARRAYS}
    kernels = [step.run_steps_serial, parallel.rebuild_if_needed, parallel.kick_drift_parallel,
               parallel.forces_parallel, parallel.forces_gather, step.prime_forces,
               measures.measure_sums, common.place_all_discs, parallel_lists.rebuild_parallel,
               parallel_lists.prime_forces_parallel, measures.measure_sums_blocked,
               coordination.count_rod_contacts, coordination.remove_rattlers]  # fmt: skip
    checked = 0
    for kernel in kernels:
        for name, parameter in inspect.signature(kernel).parameters.items():
            if name in shapes:
                assert parameter.annotation.ndim == len(shapes[name]), (kernel.__name__, name)
                checked += 1
    assert checked > 100
