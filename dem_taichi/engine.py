"""The DEM engine: plain-Python orchestration of the Taichi kernels.

Public API
----------
``Simulation(scene, arch="cpu", precision="f64", deterministic=False, execution=None)``
    Builds the rods (a random gas from the scene, or ``initial=GasState``), allocates the arrays,
    builds the neighbour list and computes the forces.
``sim.run(n_steps, control=None, output_every=None, writer=None, progress=False, callback=None)``
    Advances ``n_steps`` time steps under a :class:`CellControl` (default: the cell held fixed);
    ``writer`` (e.g. :class:`dem_taichi.io.HistoryWriter`) gets ``sim.measure()`` every
    ``output_every`` steps and at the end; returns the last measures
    (:class:`dem_taichi.measures.Measures`).
``sim.measure() -> Measures``
    The history variables of ``dem_taichi.io.schema`` (stress, p, q, v, fabric, Z, energies...),
    a typed dict (:class:`dem_taichi.measures.Measures`).
``sim.snapshot() -> NetworkSnapshot``
    The interacting network for the linear-response probes.
``sim.get_state() / sim.set_state(state)``
    Numpy copies of the full state (tangential springs and neighbour lists included); restoring
    a state continues the run bit for bit. Use them to probe copies of a state.
``sim.save_checkpoint(path)`` / ``Simulation.from_checkpoint(path, arch=None, precision=None)``
``sim.set_parameters(k_n=..., mu=..., local_damping=..., time_step=...)``
    Runtime parameters (no recompilation).
``sim.set_strain_reference()``
    Resets L0 of the logarithmic strains to the current cell.

Execution
---------
``execution="serial"`` runs ``steps_per_call`` fused steps in one kernel call, on one thread
(launch overhead paid once per call: the fastest at the study's size on a CPU, measured in
benchmarks/bench_dem.py); it is bitwise deterministic. ``"parallel"`` launches three kernels per
step, parallel over rods and discs with atomic force scatter (for GPUs / very large N; not
bitwise reproducible). ``"gather"``: the same three kernels with a full neighbour list and a
per-rod gather of the pair forces (each pair evaluated twice, no atomics): deterministic in
parallel, for GPUs. ``"auto"``: serial on CPU, parallel on GPU. ``deterministic=True`` picks the
serial path on CPU and the gather path on GPU.

Cell control
------------
Each axis is strain-controlled: a prescribed logarithmic strain rate ε̇ = −L̇/L (compression
positive, 0 = fixed), applied exactly (L = L_0 exp(−ε̇ t)). Stresses are held by the
protocol's servo (:class:`dem_taichi.servo.StressServo`), which sets these rates from the
measured response; the engine has no servo of its own.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dem_taichi.bonds import rod_axes, unwrapped_chains
from dem_taichi.config import Scene, scene_from_toml, scene_to_toml
from dem_taichi.control import AxisControl, CellControl
from dem_taichi.device_arrays import DEVICE_ARRAYS, STATE_ARRAYS, kernel_parameters
from dem_taichi.failures import BlowUpError, CapacityError, blowup_error, runaway_kinetic_energy
from dem_taichi.kernels import layout as L
from dem_taichi.measures import Measures, history_record
from dem_taichi.network import interacting_entries, mechanical_coordination, network_snapshot
from dem_taichi.runtime import ensure_runtime
from dem_taichi.scene import (
    GasState,
    bodies_from_rods,
    body_geometry,
    generate_gas,
    pair_table,
    rod_geometry,
    species_parameters,
)
from dem_taichi.snapshot import NetworkSnapshot
from dem_taichi.state import convert_neighbour_list, upgrade_state

__all__ = [
    "AxisControl",
    "CellControl",
    "Physics",
    "Simulation",
    "BlowUpError",
    "CapacityError",
]


@dataclass(frozen=True)
class Physics:
    """Compile-time physics switches (a ``ti.template()``: physics switched off costs nothing).

    ``bonded``: bonded rods (every disc a body, :mod:`dem_taichi.kernels.bonds`); ``chain``: the
    discs per rod n_s (species by the place in the rod; for rigid rods also the discs per body).
    """

    friction: bool
    long_range: bool
    vdw: bool
    bonded: bool = False
    chain: int = 1


_PARAMETER_INDEX = {
    "time_step": L.P_DT,
    "k_n": L.P_KN,
    "gamma_n": L.P_GN,
    "k_t": L.P_KT,
    "gamma_t": L.P_GT,
    "mu": L.P_MU,
    "local_damping": L.P_ALPHA,
}


class Simulation:
    """A periodic 2D assembly of rods of discs, rigid or bonded (see the module docstring).

    ``geometry`` is the rod's; ``body`` the geometry of the engine's bodies (the rod itself, or
    one disc of a bonded rod); ``n_rods`` rods, ``n_bodies`` bodies, ``n_discs`` discs.
    """

    def __init__(
        self,
        scene: Scene,
        arch: str = "cpu",
        precision: str = "f64",
        deterministic: bool = False,
        execution: str | None = None,
        initial: GasState | None = None,
        neighbour_capacity: int | None = None,
    ) -> None:
        self.scene = scene
        self.runtime = ensure_runtime(arch, precision)
        self.arch, self.precision, self.deterministic = arch, precision, deterministic
        execution = execution or scene.integration.execution
        if execution not in ("auto", "serial", "parallel", "gather"):
            raise ValueError(
                f"execution = {execution!r}: allowed values are auto|serial|parallel|gather"
            )
        if deterministic and execution not in ("serial", "gather"):
            execution = "serial" if arch == "cpu" else "gather"
        elif execution == "auto":
            execution = "serial" if arch == "cpu" else "parallel"
        self.execution = execution
        self.full_list = execution == "gather"
        self.geometry = rod_geometry(scene)
        self.body = body_geometry(scene)
        self.bonded = scene.bonded
        charge, _, _ = species_parameters(scene)
        self.charge = charge
        lr_on = scene.long_range.enabled and bool(np.any(charge != 0))
        vdw_on = scene.van_der_waals.enabled and bool(np.any(charge != 0))
        friction_on = scene.contact.friction and scene.contact.k_t > 0
        self.physics = Physics(
            friction=friction_on, long_range=lr_on, vdw=vdw_on, bonded=self.bonded,
            chain=self.geometry.n_spheres,
        )  # fmt: skip
        self.n_rods = scene.particles.n_rods
        self.n_discs = self.n_rods * self.geometry.n_spheres
        self.n_bodies = self.n_discs if self.bonded else self.n_rods
        self._real = self.runtime.numpy_real
        self._stage = "gas"
        self._rates = np.zeros(2)
        self._control = CellControl.fixed()
        self.timings: dict[str, float] = {"kernel": 0.0, "measure": 0.0, "host": 0.0}
        self.n_rebuild_calls = 0
        gas = initial if initial is not None else generate_gas(scene)
        if self.bonded and len(gas.angle) == self.n_rods:
            gas = bodies_from_rods(gas, self.geometry)
        if len(gas.angle) != self.n_bodies:
            raise ValueError(
                f"initial state of {len(gas.angle)} bodies does not fit this scene "
                f"({self.n_bodies} bodies: {self.n_rods} {scene.particles.rod_model} rods)"
            )
        self.cutoff = self._cutoff()
        self.list_radius = self.cutoff + scene.integration.skin
        capacity = neighbour_capacity or self._initial_capacity()
        self._allocate(capacity, gas.cell_lengths)
        self._upload_gas(gas)
        self.reference_lengths = np.array(gas.cell_lengths, dtype=np.float64)
        self.step = 0
        self._prime()

    # ------------------------------------------------------------------------------------------
    # set-up
    def _cutoff(self) -> float:
        d = self.geometry.diameter
        reach = 0.0
        if self.physics.long_range:
            table = pair_table(self.scene)
            reach = max(reach, float(np.max(np.where(table[..., 0] != 0, table[..., 2], 0.0))))
        if self.physics.vdw:
            reach = max(reach, self.scene.van_der_waals.f_max / self.scene.van_der_waals.k)
        return d + reach

    def _initial_capacity(self) -> int:
        # half list: about half the discs within r_list of a disc at the densest packing
        r = self.list_radius / self.geometry.diameter
        return (2 if self.full_list else 1) * (int(2.2 * r * r) + 6)

    def _allocate(self, capacity: int, cell_lengths: np.ndarray) -> None:
        import taichi as ti

        real = self.runtime.real
        n, m, ns = self.n_bodies, self.n_discs, self.body.n_spheres
        nd = ti.ndarray
        self.capacity = int(capacity)
        cells_axis = int(max(cell_lengths) / self.list_radius) + 2
        self._sizes = {"rods": n, "discs": m, "spheres": ns, "capacity": self.capacity}
        self._sizes["species"] = self.geometry.n_spheres
        self._sizes["cells"] = cells_axis
        self._dtypes = {"real": real, "i32": ti.i32}
        self.a: dict[str, Any] = {
            spec.name: nd(self._dtypes[spec.dtype], spec.shape_for(self._sizes))
            for spec in DEVICE_ARRAYS
        }
        self.a["offsets"].from_numpy(self.body.offsets.astype(self._real))
        self.a["bond_intact"].from_numpy(np.ones(n, dtype=np.int32))
        self.a["charge"].from_numpy(self.charge.astype(np.int32))
        self.a["pair_table"].from_numpy(pair_table(self.scene).astype(self._real))
        for name in ("nbr_count", "old_count"):
            self.a[name].from_numpy(np.zeros(m, dtype=np.int32))
        self.a["nbr"].from_numpy(np.zeros((m, self.capacity), dtype=np.int32))
        self.a["nbr_xi"].from_numpy(np.zeros((m, self.capacity), dtype=self._real))
        self.a["params"].from_numpy(self._default_params())

    def _default_params(self) -> np.ndarray:
        s, geo = self.scene, self.body
        p = np.zeros(L.N_PARAMS)
        p[L.P_DT] = s.time_step
        p[L.P_KN] = s.contact.k_n
        p[L.P_GN] = s.gamma_n
        p[L.P_KT] = s.contact.k_t if self.physics.friction else 0.0
        p[L.P_GT] = s.contact.gamma_t
        p[L.P_MU] = s.contact.mu
        p[L.P_ALPHA] = s.integration.local_damping
        p[L.P_MASS] = geo.mass
        p[L.P_INERTIA] = geo.inertia
        p[L.P_DIAM] = geo.diameter
        p[L.P_RLIST] = self.list_radius
        p[L.P_SKIN] = s.integration.skin
        p[L.P_VDW_F] = s.van_der_waals.f_max
        p[L.P_VDW_K] = s.van_der_waals.k
        p[L.P_MAX_OFFSET] = geo.max_offset
        p[L.P_MAX_OVERLAP] = s.integration.max_overlap * geo.diameter
        p[L.P_REACH] = geo.length + self.list_radius
        p[L.P_CUT] = self.cutoff
        p[L.P_SPACING] = s.particles.spacing
        if self.bonded:
            b = s.bond_parameters
            p[[L.P_BOND_KN, L.P_BOND_KT, L.P_BOND_KB]] = b.k_n, b.k_t, b.k_b
            p[[L.P_BOND_GN, L.P_BOND_GT, L.P_BOND_GB]] = b.gamma_n, b.gamma_t, b.gamma_b
            p[L.P_BOND_BREAK] = b.breakage_force
        return p.astype(self._real)

    def _upload_gas(self, gas: GasState) -> None:
        cell_lengths = np.asarray(gas.cell_lengths, dtype=float)
        self._check_cell(cell_lengths)
        reduced = np.asarray(gas.position, dtype=float) / cell_lengths
        self.a["pos"].from_numpy(reduced.astype(self._real))
        self.a["angle"].from_numpy(np.asarray(gas.angle, dtype=self._real))
        self.a["vel"].from_numpy(np.asarray(gas.velocity, dtype=self._real))
        self.a["omega"].from_numpy(np.asarray(gas.angular_velocity, dtype=self._real))
        self.a["ref_pos"].from_numpy(reduced.astype(self._real))
        self.a["ref_angle"].from_numpy(np.asarray(gas.angle, dtype=self._real))
        cell = np.zeros(L.N_CELL)
        cell[[L.C_LX, L.C_LY]] = cell_lengths
        cell[[L.C_LBX, L.C_LBY]] = cell_lengths
        self.a["cell"].from_numpy(cell.astype(self._real))
        flags = np.zeros(L.N_FLAGS, dtype=np.int32)
        flags[L.F_FORCE_REBUILD] = 1
        self.a["flags"].from_numpy(flags)

    def _check_cell(self, cell_lengths: np.ndarray) -> None:
        reach = self.geometry.length + self.list_radius
        if np.min(cell_lengths) < 2.0 * self.list_radius + self.geometry.length:
            raise CapacityError(
                f"cell lengths {np.round(cell_lengths, 4).tolist()} are too small for the minimum "
                f"image with rods of length {self.geometry.length} and list radius "
                f"{self.list_radius:.3g} (need > {2 * self.list_radius + self.geometry.length:.3g}"
                f"; reach {reach:.3g}): use more rods ([particles] n_rods) or a smaller "
                "[integration] skin"
            )

    def _launch(self, kernel, **scalars) -> None:
        """Call ``kernel`` with its compile-time and scalar arguments (``scalars``, by name) and
        every device array its other parameters name (:data:`DEVICE_ARRAYS`)."""
        a = self.a
        kernel(*[scalars[n] if n in scalars else a[n] for n in kernel_parameters(kernel)])

    def recompute_forces(self) -> None:
        """Recompute forces/torques from the current positions, velocities and springs (ξ kept)."""
        self._prime()

    def _prime(self) -> None:
        from dem_taichi.kernels.step import prime_forces

        for _ in range(8):
            self._launch(
                prime_forces, ns=self.body.n_spheres, full=self.full_list, phys=self.physics
            )
            if not self._handle_flags(0):
                return
        raise CapacityError("could not build the neighbour list")  # pragma: no cover

    # ------------------------------------------------------------------------------------------
    # flags, capacity growth, blow-up
    def _handle_flags(self, step_offset: int) -> bool:
        """Check kernel flags; grow capacity on overflow (True: repeat), raise on blow-up."""
        flags = self.a["flags"].to_numpy()
        if flags[L.F_BLOWUP]:
            self._raise_blowup(flags, step_offset)
        if flags[L.F_OVERFLOW]:
            needed = int(flags[L.F_NEEDED])
            self._grow(int(needed * 1.25) + 2)
            flags = self.a["flags"].to_numpy()
            flags[L.F_OVERFLOW] = 0
            flags[L.F_STOP] = 0
            self.a["flags"].from_numpy(flags)
            return True
        return False

    def _grow(self, capacity: int) -> None:
        import taichi as ti

        limit = 4096
        if capacity > limit:
            raise CapacityError(
                f"a disc has {capacity} list neighbours (limit {limit}): the packing or the "
                "list radius is unphysical; reduce [integration] skin or the long-range range "
                "(f_max / k_a)"
            )
        sizes = dict(self._sizes, capacity=capacity)
        for spec in DEVICE_ARRAYS:
            if not spec.grows:
                continue
            shape = spec.shape_for(sizes)
            grown = ti.ndarray(self._dtypes[spec.dtype], shape)
            if spec.copy_on_growth:
                old = self.a[spec.name].to_numpy()
                new = np.zeros(shape, dtype=old.dtype)
                keep = min(capacity, old.shape[1])
                new[:, :keep] = old[:, :keep]
                grown.from_numpy(new)
            self.a[spec.name] = grown
        self._sizes = sizes
        self.capacity = capacity

    def _raise_blowup(self, flags: np.ndarray, step_offset: int) -> None:
        step = self.step + step_offset + int(flags[L.F_STEPS])
        code, index = int(flags[L.F_BLOWUP]), int(flags[L.F_BLOWUP_INDEX])
        raise blowup_error(code, index, step, self.scene.integration)

    def _check_kinetic_energy(self) -> None:
        v = self.a["vel"].to_numpy().astype(float)
        w = self.a["omega"].to_numpy().astype(float)
        ke = 0.5 * self.body.mass * np.sum(v * v) + 0.5 * self.body.inertia * np.sum(w * w)
        limit = self.scene.integration.max_kinetic_energy_per_rod * self.n_rods
        if not math.isfinite(ke) or ke > limit:
            raise runaway_kinetic_energy(ke, limit, self.step, self.scene.integration)

    # ------------------------------------------------------------------------------------------
    # stepping
    def _set_rates(self, rates: np.ndarray) -> None:
        self._rates = np.asarray(rates, dtype=float)
        params = self.a["params"].to_numpy()
        params[L.P_RATE_X], params[L.P_RATE_Y] = self._rates
        self.a["params"].from_numpy(params)

    def _advance(self, n_steps: int) -> None:
        """Advance exactly ``n_steps`` (growing capacities on overflow, raising on blow-up)."""
        from dem_taichi.kernels import step as K

        done = 0
        while done < n_steps:
            flags = self.a["flags"].to_numpy()
            flags[L.F_STEPS] = 0
            self.a["flags"].from_numpy(flags)
            todo = n_steps - done
            t0 = _time.perf_counter()
            ns = self.body.n_spheres
            if self.execution == "serial":
                self._launch(K.run_steps_serial, ns=ns, phys=self.physics, n_steps=todo)
            else:
                for _ in range(todo):
                    self._launch(K.rebuild_if_needed, ns=ns, full=self.full_list)
                    self._launch(K.kick_drift_parallel, ns=ns)
                    if self.full_list:
                        self._launch(K.forces_gather, ns=ns, phys=self.physics)
                    else:
                        self._launch(K.forces_parallel, ns=ns, phys=self.physics, count_step=1)
            steps_done = int(self.a["flags"].to_numpy()[L.F_STEPS])
            self.timings["kernel"] += _time.perf_counter() - t0
            grown = self._handle_flags(done)
            done += steps_done
            self.step += steps_done
            if grown:
                self.n_rebuild_calls += 1
            elif steps_done < todo:  # pragma: no cover - a stop without a recognised flag
                raise RuntimeError(f"kernel stopped after {steps_done} of {todo} steps")
        self._check_kinetic_energy()

    def run(
        self,
        n_steps: int,
        control: CellControl | None = None,
        output_every: int | None = None,
        writer: Any = None,
        progress: bool = False,
        callback: Callable[[Simulation, Measures], None] | None = None,
    ) -> Measures:
        """Advance ``n_steps`` steps; returns the measures at the end (see module docstring).

        ``writer.append(measures)`` and ``callback(sim, measures)`` are called every
        ``output_every`` steps (default ``[output] every``) and at the end.
        """
        if n_steps < 0:
            raise ValueError(f"n_steps must be >= 0, got {n_steps}")
        control = control or self._control
        self._control = control
        self._stage = control.stage
        output_every = output_every or self.scene.output.every
        chunk = self.scene.integration.steps_per_call
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n_steps, unit="step", desc=control.stage, smoothing=0.1)
        measures: Measures | None = None
        done = 0
        next_output = output_every
        try:
            while done < n_steps:
                todo = min(chunk, n_steps - done, next_output - done)
                self._set_rates(control.rates)
                self._advance(todo)
                done += todo
                if bar is not None:
                    bar.update(todo)
                if done == next_output or done == n_steps:
                    next_output = done + output_every
                    measures = self.measure()
                    if writer is not None:
                        writer.append(measures)
                    if callback is not None:
                        callback(self, measures)
        finally:
            if bar is not None:
                bar.close()
        return measures if measures is not None else self.measure()

    # ------------------------------------------------------------------------------------------
    # measures
    def _measure_sums(self) -> np.ndarray:
        from dem_taichi.kernels.measures import measure_sums

        t0 = _time.perf_counter()
        self._launch(measure_sums, ns=self.body.n_spheres, full=self.full_list, phys=self.physics)
        sums = self.a["measures"].to_numpy().astype(float)
        self.timings["measure"] += _time.perf_counter() - t0
        return sums

    @property
    def cell_lengths(self) -> np.ndarray:
        c = self.a["cell"].to_numpy().astype(float)
        return c[[L.C_LX, L.C_LY]]

    @property
    def time(self) -> float:
        return float(self.a["cell"].to_numpy()[L.C_TIME])

    def _stress_tensor(self, sums: np.ndarray | None = None) -> np.ndarray:
        sums = self._measure_sums() if sums is None else sums
        area = float(np.prod(self.cell_lengths))
        return np.array([[sums[L.M_SXX], sums[L.M_SXY]], [sums[L.M_SYX], sums[L.M_SYY]]]) / area

    def body_positions(self) -> np.ndarray:
        """Body centroids (n_bodies, 2) wrapped into the cell [0, L) (rods, or the discs of
        bonded rods)."""
        s = self.a["pos"].to_numpy().astype(float)
        return (s - np.floor(s)) * self.cell_lengths

    def body_angles(self) -> np.ndarray:
        return self.a["angle"].to_numpy().astype(float)

    def rod_positions(self) -> np.ndarray:
        """Rod centroids (N, 2) wrapped into the cell [0, L) (bonded rods: mean of the discs)."""
        if not self.bonded:
            return self.body_positions()
        return rod_axes(self.body_positions(), self.geometry.n_spheres, self.cell_lengths)[0]

    def rod_angles(self) -> np.ndarray:
        """Rod angles θ (N,) (bonded rods: of the end-to-end vector, in (−π, π])."""
        if not self.bonded:
            return self.body_angles()
        return rod_axes(self.body_positions(), self.geometry.n_spheres, self.cell_lengths)[1]

    def disc_positions(self) -> np.ndarray:
        """Disc centres (M, 2), rod-major (global disc index r n_s + s); not wrapped."""
        return self.a["disc_x"].to_numpy().astype(float)

    @property
    def n_broken_bonds(self) -> int:
        """Bonds broken so far (0 for rigid rods)."""
        if not self.bonded:
            return 0
        intact = self.a["bond_intact"].to_numpy()
        has_bond = np.arange(self.n_bodies) % self.geometry.n_spheres != self.geometry.n_spheres - 1
        return int(np.count_nonzero(has_bond & (intact == 0)))

    @property
    def history_variables(self):
        """The history file's variables for this simulation (bonded rods add theirs)."""
        from dem_taichi.io.history_schema import BONDED_HISTORY_VARIABLES, HISTORY_VARIABLES

        return HISTORY_VARIABLES + (BONDED_HISTORY_VARIABLES if self.bonded else ())

    def measure(self) -> Measures:
        """History measures (names of ``dem_taichi.io.schema``); see the module docstring."""
        from dem_taichi.io.schema import stage_code

        sums = self._measure_sums()
        n_bonds = self.n_rods * (self.geometry.n_spheres - 1) if self.bonded else 0
        record = history_record(
            sums,
            self._stress_tensor(sums),
            self.cell_lengths,
            self.reference_lengths,
            self._rates,
            self.rod_angles(),
            self.geometry,
            self.n_rods,
            self.step,
            self.time,
            stage_code(self._stage),
            self._mechanical_coordination(),
            n_bodies=self.n_bodies,
            n_bonds=n_bonds - int(round(sums[L.M_BROKEN])),
        )
        if self.bonded:
            record["bond_energy"] = float(sums[L.M_U_BOND])
            record["n_broken_bonds"] = int(round(sums[L.M_BROKEN]))
        return record

    def stress(self) -> np.ndarray:
        """Stress tensor (2, 2), compression positive, from the current forces."""
        return self._stress_tensor()

    def total_energy(self) -> float:
        """Kinetic + contact + long-range (+ bond) energy (for conservation checks)."""
        m = self.measure()
        bonds = m.get("bond_energy", 0.0)
        return m["kinetic_energy"] + m["contact_energy"] + m["long_range_energy"] + bonds

    # ------------------------------------------------------------------------------------------
    # network (dem_taichi.network)
    def _contact_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(disc i, list slot k, packed entry, flag bits) of every interacting list entry."""
        a = self.a
        counts, bits = a["nbr_count"].to_numpy(), a["pair_flags"].to_numpy()
        return interacting_entries(counts, bits, a["nbr"].to_numpy(), self.capacity)

    def _mechanical_coordination(self) -> float:
        i, _, packed, bits = self._contact_pairs()
        return mechanical_coordination(i, packed, bits, self.geometry.n_spheres, self.n_rods)

    def _snapshot_positions(self) -> np.ndarray:
        """Body centroids for the snapshot: wrapped, except that the discs of a bonded rod are
        made contiguous (each bond vector x_h − x_g, no shift)."""
        positions = self.body_positions()
        if not self.bonded:
            return positions
        chain = self.geometry.n_spheres
        return unwrapped_chains(positions, chain, self.cell_lengths).reshape(-1, 2)

    def _bond_network(self):
        """The bonds of a bonded simulation as a :class:`dem_taichi.snapshot.BondNetwork`."""
        from dem_taichi.bonds import chain_bonds
        from dem_taichi.snapshot import BondNetwork

        g = chain_bonds(self.n_rods, self.geometry.n_spheres)
        params = self.a["params"].to_numpy().astype(float)
        return BondNetwork(
            chain=self.geometry.n_spheres,
            g=g,
            intact=self.a["bond_intact"].to_numpy()[g] == 1,
            rest_length=float(params[L.P_SPACING]),
            k_n=float(params[L.P_BOND_KN]),
            k_t=float(params[L.P_BOND_KT]),
            k_b=float(params[L.P_BOND_KB]),
        )

    def snapshot(self) -> NetworkSnapshot:
        """The interacting network as a :class:`dem_taichi.snapshot.NetworkSnapshot`."""
        self._measure_sums()
        return network_snapshot(
            self._contact_pairs(),
            self.a["disc_x"].to_numpy().astype(float),
            self.a["nbr_xi"].to_numpy().astype(float),
            self.cell_lengths,
            self._snapshot_positions(),
            self.body_angles(),
            self.body,
            species_parameters(self.scene),
            self.a["params"].to_numpy().astype(float),
            self.physics.vdw,
            bonds=self._bond_network() if self.bonded else None,
        )

    # ------------------------------------------------------------------------------------------
    # state, parameters, checkpoints
    def get_state(self) -> dict[str, np.ndarray]:
        """Numpy copies of the full state (see :mod:`dem_taichi.state`)."""
        state = {spec.state_key: self.a[spec.name].to_numpy() for spec in STATE_ARRAYS}
        return state | {
            "reference_lengths": self.reference_lengths.copy(),
            "step": np.array(self.step, dtype=np.int64),
            "full_list": np.array(self.full_list),
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` (same scene and precision)."""
        n, m = self.n_bodies, self.n_discs
        if state["angle"].shape != (n,) or state["neighbours"].shape[0] != m:
            raise ValueError(
                f"state of {state['angle'].shape[0]} bodies does not fit this simulation ({n} "
                f"bodies: {self.n_rods} {self.scene.particles.rod_model} rods)"
            )
        if state["angle"].dtype != self._real:
            raise ValueError(
                f"state precision {state['angle'].dtype} differs from the simulation's "
                f"{np.dtype(self._real)}"
            )
        state = upgrade_state(state, n)
        state = convert_neighbour_list(state, self.full_list, self.capacity)
        capacity = state["neighbours"].shape[1]
        if capacity != self.capacity:
            self._grow(capacity)
        a = self.a
        for spec in STATE_ARRAYS:
            a[spec.name].from_numpy(np.ascontiguousarray(state[spec.state_key]))
        self.reference_lengths = np.array(state["reference_lengths"], dtype=np.float64)
        self.step = int(state["step"])
        params = state["params"]
        self._rates = np.array([params[L.P_RATE_X], params[L.P_RATE_Y]], dtype=float)
        # disc positions are derived: recompute them from the centroids
        from dem_taichi.kernels.common import place_all_discs

        self._launch(place_all_discs, ns=self.body.n_spheres)

    def set_parameters(self, **values: float) -> None:
        """Change runtime parameters: time_step, k_n, gamma_n, k_t, gamma_t, mu, local_damping."""
        params = self.a["params"].to_numpy()
        for name, value in values.items():
            if name not in _PARAMETER_INDEX:
                raise ValueError(
                    f"unknown parameter {name!r}; allowed: {', '.join(sorted(_PARAMETER_INDEX))}"
                )
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} = {value!r} must be finite and >= 0")
            params[_PARAMETER_INDEX[name]] = value
        self.a["params"].from_numpy(params)

    def get_parameter(self, name: str) -> float:
        return float(self.a["params"].to_numpy()[_PARAMETER_INDEX[name]])

    @property
    def time_step(self) -> float:
        """Δt the kernels integrate with (the runtime parameter; the scene's until
        :meth:`set_parameters` changes it)."""
        return self.get_parameter("time_step")

    def set_strain_reference(self) -> None:
        """Take the current cell as L0 of the logarithmic strains."""
        self.reference_lengths = self.cell_lengths.astype(np.float64)

    def save_checkpoint(self, path: str | Path) -> Path:
        """Write the full state and the scene to ``path`` (``.npz``) atomically."""
        from dem_taichi.io.checkpoint import save_checkpoint

        meta = {
            "scene_toml": scene_to_toml(self.scene),
            "precision": self.precision,
            "arch": self.arch,
            "execution": self.execution,
            "deterministic": self.deterministic,
            "stage": self._stage,
            "step": int(self.step),
        }
        return save_checkpoint(path, self.get_state(), meta)

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, arch: str | None = None, precision: str | None = None
    ) -> Simulation:
        """A simulation continuing exactly from a checkpoint written by :meth:`save_checkpoint`."""
        from dem_taichi.io.checkpoint import load_checkpoint

        arrays, meta = load_checkpoint(path)
        scene = scene_from_toml(meta["scene_toml"])
        precision = precision or meta["precision"]
        if precision != meta["precision"]:
            raise ValueError(
                f"checkpoint precision {meta['precision']} cannot be resumed as {precision}"
            )
        lengths = arrays["cell"][[L.C_LX, L.C_LY]].astype(float)
        reduced = arrays["reduced_position"].astype(float)
        gas = GasState(
            lengths,
            (reduced - np.floor(reduced)) * lengths,
            arrays["angle"].astype(float),
            arrays["velocity"].astype(float),
            arrays["angular_velocity"].astype(float),
        )
        sim = cls(
            scene,
            arch=arch or meta["arch"],
            precision=precision,
            deterministic=bool(meta.get("deterministic", False)),
            execution=meta.get("execution"),
            initial=gas,
            neighbour_capacity=arrays["neighbours"].shape[1],
        )
        sim.set_state(arrays)
        sim._stage = meta.get("stage", "other")
        return sim
