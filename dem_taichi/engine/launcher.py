"""Which kernels advance a :class:`dem_taichi.engine.simulation.Simulation`, and their launches.

Execution
---------
``execution="serial"`` runs ``steps_per_call`` fused steps in one kernel call, on one thread
(launch overhead paid once per call: the fastest at the study's size on a CPU, measured in
benchmarks/bench_dem.py); it is bitwise deterministic. ``"parallel"`` launches three kernels per
step, parallel over rods and discs with atomic force scatter (for GPUs / very large N; not
bitwise reproducible). ``"gather"``: the same three kernels with a full neighbour list and a
per-rod gather of the pair forces (each pair evaluated twice, no atomics): deterministic in
parallel, for GPUs. ``"auto"``: serial on CPU, parallel on GPU. ``deterministic=True`` picks the
serial path on CPU and the gather path on GPU. (One launch per step instead of three was tried
on a GPU and reverted: +10 % at 1,520 rods, and the gather path no longer bitwise the serial
build's there; benchmarks/results/gpu_bench.md, run 6.)

``list_build`` (parallel and gather paths): ``"serial"`` builds the neighbour list on one thread
(:func:`dem_taichi.kernels.neighbours.rebuild_lists`), ``"parallel"`` with parallel loops
(:mod:`dem_taichi.kernels.parallel_lists`: the same list, entry for entry, so the same state bit
for bit on the deterministic gather path); ``None`` (default): parallel on a GPU, serial on a
CPU, whose threads pay a fixed cost per parallel loop (about 80 µs,
benchmarks/results/launch_bench.csv) that the dozen loops of the parallel build would add to
every step; on an H200 the one-thread build took 1 s at 24,320 rods, the parallel one < 0.1 ms
(benchmarks/results/gpu_bench.md). The serial path always builds serially.

A minimising call of a ``relaxation = "fire"`` scene runs the FIRE kernel
(:mod:`dem_taichi.kernels.fire`) instead, with the constants of :func:`fire_constants`.
"""

from __future__ import annotations

import time as _time
from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from dem_taichi.engine.device_arrays import kernel_parameters
from dem_taichi.engine.failures import CapacityError
from dem_taichi.engine.parameters import Physics
from dem_taichi.kernels import layout as L
from dem_taichi.scene.geometry import RodGeometry

__all__ = ["launch", "prime_forces_now", "advance", "fire_constants", "fire_status_of"]


class SimulationLike(Protocol):
    """What the launches use of a :class:`dem_taichi.engine.simulation.Simulation`."""

    a: dict[str, Any]
    body: RodGeometry  # the engine's bodies
    physics: Physics
    full_list: bool
    execution: str
    list_build: str
    timings: dict[str, float]
    step: int
    n_rebuild_calls: int

    @property
    def kernel_physics(self) -> Physics: ...  # the switches the kernels are launched with

    def _launch(self, kernel, **scalars) -> None: ...

    def _handle_flags(self, step_offset: int) -> bool: ...

    def _check_kinetic_energy(self) -> None: ...


def launch(arrays: Mapping[str, Any], kernel, **scalars) -> None:
    """Call ``kernel`` with its compile-time and scalar arguments (``scalars``, by name) and
    every device array its other parameters name
    (:data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS`)."""
    kernel(*[scalars[n] if n in scalars else arrays[n] for n in kernel_parameters(kernel)])


def prime_forces_now(sim: SimulationLike) -> None:
    """Build the neighbour list and compute the forces of ``sim``'s current state without
    moving (capacity grown and the build repeated on overflow)."""
    from dem_taichi.kernels.common import place_all_discs
    from dem_taichi.kernels.parallel_lists import prime_forces_parallel, rebuild_parallel
    from dem_taichi.kernels.step import prime_forces

    ns, full, phys = sim.body.n_spheres, sim.full_list, sim.kernel_physics
    for _ in range(8):
        if sim.execution != "serial" and sim.list_build == "parallel":
            sim._launch(place_all_discs, ns=ns)
            sim._launch(rebuild_parallel, ns=ns, full=full, phys=phys, advance=False)
            sim._launch(prime_forces_parallel, ns=ns, full=full, phys=phys)
        else:
            sim._launch(prime_forces, ns=ns, full=full, phys=phys)
        if not sim._handle_flags(0):
            return
    raise CapacityError("could not build the neighbour list")  # pragma: no cover


def advance(sim: SimulationLike, n_steps: int, fire: bool = False) -> None:
    """Advance ``sim`` exactly ``n_steps`` (growing capacities on overflow, raising on
    blow-up); ``fire``: with the FIRE minimiser (fixed cell, serial execution)."""
    from dem_taichi.kernels import parallel as K
    from dem_taichi.kernels.parallel_lists import rebuild_parallel
    from dem_taichi.kernels.step import run_steps_serial

    rebuild = rebuild_parallel if sim.list_build == "parallel" else K.rebuild_if_needed
    build = {"advance": True} if sim.list_build == "parallel" else {}
    ns, full, phys = sim.body.n_spheres, sim.full_list, sim.kernel_physics
    done = 0
    while done < n_steps:
        flags = sim.a["flags"].to_numpy()
        flags[L.F_STEPS] = 0
        sim.a["flags"].from_numpy(flags)
        todo = n_steps - done
        t0 = _time.perf_counter()
        if fire:
            from dem_taichi.kernels.fire import run_steps_fire

            sim._launch(run_steps_fire, ns=ns, phys=phys, n_steps=todo)
        elif sim.execution == "serial":
            sim._launch(run_steps_serial, ns=ns, phys=phys, n_steps=todo)
        else:
            for _ in range(todo):
                sim._launch(rebuild, ns=ns, full=full, phys=phys, **build)
                sim._launch(K.kick_drift_parallel, ns=ns)
                if full:
                    sim._launch(K.forces_gather, ns=ns, phys=phys)
                else:
                    sim._launch(K.forces_parallel, ns=ns, phys=phys, count_step=1)
        steps_done = int(sim.a["flags"].to_numpy()[L.F_STEPS])
        sim.timings["kernel"] += _time.perf_counter() - t0
        grown = sim._handle_flags(done)
        done += steps_done
        sim.step += steps_done
        if grown:
            sim.n_rebuild_calls += 1
        elif steps_done < todo:  # pragma: no cover - a stop without a recognised flag
            raise RuntimeError(f"kernel stopped after {steps_done} of {todo} steps")
    sim._check_kinetic_energy()


def fire_constants(fire: Mapping[str, float], dt: float) -> np.ndarray:
    """The FIRE array (``layout.FIRE_*`` slots) for a new minimisation: the scene's FIRE
    parameters ``fire`` ([integration] fire), Δt_max and Δt_min as multiples of the current
    Δt ``dt``, α = α_start, the counters 0."""
    out = np.zeros(L.N_FIRE)
    out[L.FIRE_DT_MAX] = fire["dt_max"] * dt
    out[L.FIRE_DT_MIN] = fire["dt_min"] * dt
    out[L.FIRE_N_DELAY] = fire["n_delay"]
    out[L.FIRE_F_INC] = fire["f_inc"]
    out[L.FIRE_F_DEC] = fire["f_dec"]
    out[L.FIRE_ALPHA_START] = fire["alpha_start"]
    out[L.FIRE_F_ALPHA] = fire["f_alpha"]
    out[L.FIRE_ALPHA] = fire["alpha_start"]
    out[L.FIRE_DT] = dt
    out[L.FIRE_DT0] = dt
    return out


def fire_status_of(fire: np.ndarray) -> dict[str, float]:
    """The running Δt, α, steps, velocity resets (P ≤ 0) and N+ / N− of a FIRE array."""
    f = fire.astype(float)
    return {
        "dt": f[L.FIRE_DT], "alpha": f[L.FIRE_ALPHA], "steps": f[L.FIRE_STEPS],
        "resets": f[L.FIRE_RESETS], "n_positive": f[L.FIRE_N_POS],
        "n_negative": f[L.FIRE_N_NEG],
    }  # fmt: skip
