"""The DEM engine: plain-Python orchestration of the Taichi kernels.

Public API
----------
``Simulation(scene, arch="cpu", precision="f64", deterministic=False, execution=None)``
    ``scene``: a :class:`dem_taichi.scene.config.Scene`, a built-in scene name (``"smoke"``) or a
    TOML path.
    Builds the rods (a random gas from the scene, or ``initial=GasState``), allocates the arrays,
    builds the neighbour list and computes the forces.
``sim.run(n_steps, control=None, output_every=None, writer=None, progress=False, callback=None)``
    Advances ``n_steps`` time steps under a :class:`CellControl` (default: the cell held fixed);
    ``writer`` (e.g. :class:`dem_taichi.io.HistoryWriter`) gets ``sim.measure()`` every
    ``output_every`` steps and at the end; returns the last measures
    (:class:`dem_taichi.engine.measures.BondedMeasures`).
``sim.measure() -> BondedMeasures``
    The history variables of ``dem_taichi.io.schema`` (stress, p, q, v, fabric, Z, energies...),
    a typed dict (:class:`dem_taichi.engine.measures.Measures`, with the bonded variables for bonded
    rods: :class:`dem_taichi.engine.measures.BondedMeasures`).
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
``execution`` ("serial" | "parallel" | "gather" | "auto") and ``list_build`` choose the kernels
that advance the state: :mod:`dem_taichi.engine.launcher` says which and why.

Cell control and relaxations
----------------------------
A :class:`CellControl` prescribes a logarithmic strain rate per axis (stresses are held by the
protocol's servo) or marks a call as a relaxation, integrated with ``[integration] relaxation``
("damped" or "fire"; ``sim.fire_status()`` reports FIRE's last Δt, α and resets):
:mod:`dem_taichi.engine.control` says how.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Self

import numpy as np

from dem_taichi.engine.control import AxisControl, CellControl, step_count
from dem_taichi.engine.device_allocation import (
    allocate_arrays,
    grow_arrays,
    initial_capacity,
    upload_gas,
)
from dem_taichi.engine.failures import (
    BlowUpError,
    CapacityError,
    PeriodTwo,
    blowup_error,
    runaway_kinetic_energy,
)
from dem_taichi.engine.launcher import (
    advance,
    fire_constants,
    fire_status_of,
    launch,
    prime_forces_now,
)
from dem_taichi.engine.measures import BondedMeasures, Measures
from dem_taichi.engine.parameters import EngineParameters, Physics, resolve_scene
from dem_taichi.engine.runtime import ensure_runtime
from dem_taichi.engine.simulation_state import SimulationState, checkpoint_meta, checkpoint_start
from dem_taichi.engine.simulation_views import SimulationViews
from dem_taichi.engine.work_profile import WorkLedger, add_work, current_work
from dem_taichi.kernels import layout as L
from dem_taichi.physics.attraction import unset_table
from dem_taichi.physics.forcelaw import attracting_rod_pairs
from dem_taichi.physics.snapshot import NetworkSnapshot
from dem_taichi.scene.config import Scene, load_scene
from dem_taichi.scene.geometry import (
    GasState,
    bodies_from_rods,
    generate_gas,
)

__all__ = [
    "AxisControl",
    "CellControl",
    "Physics",
    "Simulation",
    "BlowUpError",
    "CapacityError",
]


class Simulation:
    """A periodic 2D assembly of rods of discs, rigid or bonded (see the module docstring).

    ``geometry`` is the rod's; ``body`` the geometry of the engine's bodies (the rod itself, or
    one disc of a bonded rod); ``n_rods`` rods, ``n_bodies`` bodies, ``n_discs`` discs.
    """

    def __init__(
        self,
        scene: Scene | str | Path,
        arch: str = "cpu",
        precision: str = "f64",
        deterministic: bool = False,
        execution: str | None = None,
        initial: GasState | None = None,
        neighbour_capacity: int | None = None,
        list_build: str | None = None,
    ) -> None:
        if not isinstance(scene, Scene):  # a built-in scene name or a TOML path
            scene = load_scene(scene)
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
        list_build = list_build or ("parallel" if arch == "gpu" else "serial")
        if list_build not in ("serial", "parallel"):
            raise ValueError(f"list_build = {list_build!r}: allowed values are serial|parallel")
        #: how the parallel and gather paths build the neighbour list (module docstring)
        self.list_build = list_build
        if scene.integration.relaxation_method == "fire" and execution != "serial":
            raise ValueError(
                f'[integration] relaxation = "fire" needs the serial execution; execution = '
                f"{execution!r} (arch {arch!r}, deterministic={deterministic}) has no FIRE kernel"
            )
        resolved = resolve_scene(scene)  # the scene read once for the engine
        self.geometry, self.body = resolved.geometry, resolved.body
        self.bonded = scene.bonded
        self.charge = resolved.species[0]
        self._pair_table = resolved.pair_table
        #: the rods' long-range strengths s_r ((N,)), or None when the rods are alike
        self.rod_strength = resolved.rod_strength
        self.physics = resolved.physics
        self.n_rods = scene.particles.n_rods
        self.n_discs = self.n_rods * self.geometry.n_spheres
        self.n_bodies = self.n_discs if self.bonded else self.n_rods
        self._real = self.runtime.numpy_real
        self._stage = "gas"
        #: a work ledger (:mod:`dem_taichi.engine.work_profile`) every ``run`` call adds to, or None
        self.work: WorkLedger | None = None
        self._rates = np.zeros(2)
        self._control = CellControl.fixed()
        self.timings: dict[str, float] = {"kernel": 0.0, "measure": 0.0, "host": 0.0}
        self.n_rebuild_calls = 0
        gas = initial if initial is not None else generate_gas(scene)
        gas = self._as_bodies(gas, "initial state")
        self.cutoff, self.list_radius = resolved.cutoff, resolved.list_radius
        #: the scene's runtime parameters (the device array ``params`` holds them, with the
        #: run-time changes since: :attr:`parameters`)
        self.scene_parameters = resolved.parameters
        capacity = neighbour_capacity or initial_capacity(
            self.list_radius, self.geometry.diameter, self.full_list
        )
        self._allocate(capacity, gas.cell_lengths)
        #: what the simulation reports (measures, rods, network), read from its arrays
        self.views = SimulationViews(
            self.a, self._launch, resolved.species, self.geometry, self.body, self.physics,
            self.full_list, self.n_rods, self.n_bodies, self.timings, resolved.rod_strength,
        )  # fmt: skip
        #: copies, restores and checkpoints of the state arrays
        self.state_io = SimulationState(
            self.a, self._launch, self._grow, scene.particles.rod_model, self.body, self.physics,
            self.full_list, self.n_rods, self.n_discs, self.n_bodies, self._real,
            net_caps_from_start=scene.contact.cap_force == "net",
        )  # fmt: skip
        upload_gas(self.a, gas, self._real, self.geometry.length, self.list_radius)
        self.reference_lengths = np.array(gas.cell_lengths, dtype=np.float64)
        self.step = 0
        self._sync_kernel_physics()
        self._prime()

    # ------------------------------------------------------------------------------------------
    # set-up
    def _allocate(self, capacity: int, cell_lengths: np.ndarray) -> None:
        """Allocate the device arrays (:mod:`dem_taichi.engine.device_allocation`) and set the
        constant ones and the runtime parameters."""
        import taichi as ti

        real = self.runtime.real
        n, m, ns = self.n_bodies, self.n_discs, self.body.n_spheres
        self.capacity = int(capacity)
        cells_axis = int(max(cell_lengths) / self.list_radius) + 2
        self._sizes = {"rods": n, "discs": m, "spheres": ns, "capacity": self.capacity}
        self._sizes["rolling_discs"] = m if self.physics.rolling else 1
        self._sizes["species"] = self.geometry.n_spheres
        self._sizes["strength_rods"] = self.n_rods if self.physics.strength else 1
        self._sizes["partner_rods"] = self.n_rods if self.physics.partners else 1
        self._sizes["cells"] = cells_axis
        # the parallel measure's block rows (kernels.measures.measure_sums_blocked); one unused
        # row on the serial path
        blocked = self.execution != "serial"
        self._sizes["measure_blocks"] = L.measure_block_rows(n, m, self.bonded) if blocked else 1
        self._dtypes = {"real": real, "i32": ti.i32}
        self.a: dict[str, Any] = allocate_arrays(self._sizes, self._dtypes)
        self.a["offsets"].from_numpy(self.body.offsets.astype(self._real))
        self.a["bond_intact"].from_numpy(np.ones(n, dtype=np.int32))
        self.a["charge"].from_numpy(self.charge.astype(np.int32))
        self.a["pair_table"].from_numpy(self._pair_table.astype(self._real))
        strength = self.rod_strength if self.rod_strength is not None else np.ones(1)
        self.a["rod_strength"].from_numpy(strength.astype(self._real))
        partners = unset_table(self._sizes["partner_rods"], L.PARTNER_COLUMNS)
        self.a["attraction_partners"].from_numpy(partners)
        for name in ("nbr_count", "old_count"):
            self.a[name].from_numpy(np.zeros(m, dtype=np.int32))
        self.a["nbr"].from_numpy(np.zeros((m, self.capacity), dtype=np.int32))
        for name in ("nbr_xi", "nbr_psi"):
            shape = self.a[name].shape
            self.a[name].from_numpy(np.zeros(shape, dtype=self._real))
        self.parameters = self.scene_parameters

    @property
    def parameters(self) -> EngineParameters:
        """The runtime parameters the kernels integrate with (the device array ``params``: the
        scene's, with the changes made since by :meth:`set_parameters`, the cell control or a
        restored state)."""
        return EngineParameters.from_vector(self.a["params"].to_numpy())

    @parameters.setter
    def parameters(self, values: EngineParameters) -> None:
        self.a["params"].from_numpy(values.vector(self._real))

    # ------------------------------------------------------------------------------------------
    # runtime parameters
    def set_parameters(self, **values: float) -> None:
        """Change runtime parameters by name (:data:`dem_taichi.engine.parameters.
        TUNABLE_PARAMETERS`: time_step, k_n, gamma_n, k_t, gamma_t, mu, local_damping)."""
        self.parameters = self.parameters.tuned(**values)

    def get_parameter(self, name: str) -> float:
        """The runtime parameter ``name`` (a field of
        :class:`dem_taichi.engine.parameters.EngineParameters`) the kernels integrate with."""
        if name not in L.PARAMETER_SLOTS:
            raise KeyError(f"unknown parameter {name!r}; allowed: {', '.join(L.PARAMETER_SLOTS)}")
        return float(getattr(self.parameters, name))

    @property
    def time_step(self) -> float:
        """Δt the kernels integrate with (the runtime parameter; the scene's until
        :meth:`set_parameters` changes it)."""
        return self.get_parameter("time_step")

    # ------------------------------------------------------------------------------------------
    # state and checkpoints (SimulationState)
    def get_state(self) -> dict[str, np.ndarray]:
        """Numpy copies of the full state (see :mod:`dem_taichi.engine.state`)."""
        return self.state_io.get_state(self.step, self.reference_lengths)

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the velocities alone (:meth:`SimulationState.velocities`)."""
        return self.state_io.velocities()

    def set_velocities(self, velocity: np.ndarray, angular_velocity: np.ndarray) -> None:
        """Write the velocities alone (:meth:`SimulationState.set_velocities`)."""
        self.state_io.set_velocities(velocity, angular_velocity)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` (same scene and precision)."""
        restored = self.state_io.restore(state)
        self.step, self.reference_lengths = restored.step, restored.reference_lengths
        self._rates = restored.rates
        self._sync_kernel_physics()

    @property
    def kernel_physics(self) -> Physics:
        """The switches the kernels are launched with (:meth:`SimulationState.kernel_physics`:
        the partner test only once the partners are set)."""
        return self.views.kernel_physics

    def _sync_kernel_physics(self) -> None:
        self.views.kernel_physics = self.state_io.kernel_physics()

    def load_gas(
        self,
        gas: GasState,
        step: int,
        time: float,
        contacts: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Replace the bodies and the cell by ``gas`` at ``step`` and simulated ``time``: the
        hand-over from a rigid-rod ageing to bonded rods (:mod:`dem_taichi.protocol.
        rigid_ageing`). ``gas`` holds this scene's bodies, or, for bonded rods, its rods (then
        made straight chains moving rigidly, :func:`~dem_taichi.scene.geometry.
        bodies_from_rods`). The runtime parameters (Δt, rates) and the strain reference are
        kept; the neighbour list is rebuilt and the forces are recomputed. The contacts start
        afresh (tangential and rolling springs at zero), unless ``contacts`` (the neighbour
        lists of a state dict whose discs are numbered as this scene's, e.g. the rigid twin's)
        gives the springs to carry to the same disc pairs."""
        gas = self._as_bodies(gas, "gas")
        upload_gas(self.a, gas, self._real, self.geometry.length, self.list_radius)
        self.state_io.forget_contacts(time)
        if contacts is not None:
            self.state_io.carry_contacts(contacts)
        self.step = int(step)
        self._prime()

    def _as_bodies(self, gas: GasState, what: str) -> GasState:
        """``gas`` as this simulation's bodies: a gas of rods made straight chains for bonded
        rods (:func:`~dem_taichi.scene.geometry.bodies_from_rods`); any other count refused,
        naming it ``what``."""
        if self.bonded and len(gas.angle) == self.n_rods:
            gas = bodies_from_rods(gas, self.geometry)
        if len(gas.angle) != self.n_bodies:
            raise ValueError(
                f"{what} of {len(gas.angle)} bodies does not fit this scene "
                f"({self.n_bodies} bodies: {self.n_rods} {self.scene.particles.rod_model} rods)"
            )
        return gas

    def set_strain_reference(self) -> None:
        """Take the current cell as L0 of the logarithmic strains."""
        self.reference_lengths = self.cell_lengths.astype(np.float64)

    def save_checkpoint(self, path: str | Path) -> Path:
        """Write the full state and the scene to ``path`` (``.npz``) atomically."""
        from dem_taichi.io.checkpoint import save_checkpoint

        meta = checkpoint_meta(
            self.scene, self.precision, self.arch, self.execution, self.deterministic,
            self._stage, self.step,
        )  # fmt: skip
        return save_checkpoint(path, self.get_state(), meta)

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, arch: str | None = None, precision: str | None = None
    ) -> Self:
        """A simulation continuing exactly from a checkpoint written by :meth:`save_checkpoint`."""
        from dem_taichi.io.checkpoint import load_checkpoint

        arrays, meta = load_checkpoint(path)
        scene, arguments = checkpoint_start(arrays, meta, arch, precision)
        sim = cls(scene, **arguments)
        sim.set_state(arrays)
        sim._stage = meta.get("stage", "other")
        return sim

    # ------------------------------------------------------------------------------------------
    # what the simulation reports (SimulationViews)
    @property
    def cell_lengths(self) -> np.ndarray:
        """Cell lengths (L_x, L_y), length."""
        return self.views.cell_lengths

    @property
    def time(self) -> float:
        """Simulated time since the start, time."""
        return self.views.time

    def body_positions(self) -> np.ndarray:
        """Body centroids (n_bodies, 2) wrapped into the cell [0, L)."""
        return self.views.body_positions()

    def body_angles(self) -> np.ndarray:
        """Body angles (n_bodies,), radian."""
        return self.views.body_angles()

    def rod_positions(self) -> np.ndarray:
        """Rod centroids (N, 2) wrapped into the cell (bonded rods: mean of the discs)."""
        return self.views.rod_positions()

    def rod_angles(self) -> np.ndarray:
        """Rod angles θ (N,), radian (bonded rods: of the end-to-end vector)."""
        return self.views.rod_angles()

    def disc_positions(self) -> np.ndarray:
        """Disc centres (M, 2), rod-major; not wrapped."""
        return self.views.disc_positions()

    @property
    def n_broken_bonds(self) -> int:
        """Bonds broken so far (0 for rigid rods)."""
        return self.views.n_broken_bonds

    @property
    def history_variables(self):
        """The history file's variables for this simulation (bonded rods add theirs)."""
        return self.views.history_variables

    def measure(self) -> BondedMeasures:
        """History measures (names of ``dem_taichi.io.schema``) now; see the module docstring."""
        return self.views.measure(self.step, self.reference_lengths, self._rates, self._stage)

    def stress(self) -> np.ndarray:
        """Stress tensor (2, 2), compression positive, from the current forces."""
        return self.views.stress()

    def period_two(self) -> PeriodTwo:
        """The bodies oscillating with a period of two steps (:meth:`SimulationViews.period_two`):
        a time step beyond their local stability limit; a relaxation removes it slowly if at
        all."""
        return self.views.period_two()

    def total_energy(self) -> float:
        """Kinetic + contact + long-range (+ bond) energy (for conservation checks)."""
        return self.views.total_energy(self.measure())

    def interacting_rod_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(rod i, rod j) of every interacting pair of discs on two rods, as the last measure
        left them (:meth:`SimulationViews.interacting_rod_pairs`)."""
        return self.views.interacting_rod_pairs()

    def snapshot(self) -> NetworkSnapshot:
        """The interacting network (:class:`dem_taichi.physics.snapshot.NetworkSnapshot`)."""
        return self.views.snapshot()

    def freeze_attraction(self) -> np.ndarray:
        """From now on, attraction only between the rods that attract each other now
        (``[long_range] attraction_pairs = "bonded_at_A"``; the protocol calls it at state A):
        the partner table of :mod:`dem_taichi.physics.attraction` from the rod pairs of
        :func:`dem_taichi.physics.forcelaw.attracting_rod_pairs` on the current network, set
        once (partners already set are kept: a second call changes nothing). The same pairs act
        at the state it is called on; from then on the kernels run with the partner test
        (:meth:`_sync_kernel_physics`), whose sums may round differently in the last bits.
        Returns the partner rod pairs (P, 2).

        Raises ValueError for a scene without the option, or a rod with more partners than
        :data:`dem_taichi.kernels.layout.PARTNER_CAPACITY`."""
        if not self.physics.partners:
            raise ValueError(
                "freeze_attraction needs [long_range] attraction_pairs = 'bonded_at_A' (and "
                "charged discs with the long-range law on)"
            )
        kept = self.state_io.partner_pairs()
        if kept is not None:
            return kept
        pairs = attracting_rod_pairs(self.snapshot())
        self.state_io.set_partners(pairs)
        self._sync_kernel_physics()
        return pairs

    def drop_attraction_caps(self) -> None:
        """From now on the contacts' sliding and rolling caps leave out the pair's attraction
        (``[contact] cap_force = "net_after_A"``, called by the protocol as each path leaves
        state A). The state's
        configuration and force arrays are kept, as by :meth:`freeze_attraction`: the next step
        evaluates the forces under the new caps (measures do at once). The switch is part of the
        state and its checkpoints. ValueError for a scene without the option."""
        self.state_io.drop_attraction_caps()
        self._sync_kernel_physics()

    def _launch(self, kernel, **scalars) -> None:
        """Call ``kernel`` with its scalars and the device arrays its parameters name
        (:func:`dem_taichi.engine.launcher.launch`)."""
        launch(self.a, kernel, **scalars)

    def recompute_forces(self) -> None:
        """Recompute forces/torques from the current positions, velocities and springs (ξ kept)."""
        self._prime()

    def _prime(self) -> None:
        prime_forces_now(self)

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
        """Grow the neighbour-list arrays to ``capacity`` entries per disc
        (:func:`dem_taichi.engine.device_allocation.grow_arrays`)."""
        self._sizes = grow_arrays(self.a, self._sizes, self._dtypes, capacity)
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
        rate_x, rate_y = self._rates
        self.parameters = self.parameters.with_changes(rate_x=rate_x, rate_y=rate_y)

    def _start_fire(self) -> None:
        """Set the FIRE array for a new minimisation (:func:`dem_taichi.engine.launcher.
        fire_constants`)."""
        fire = fire_constants(self.scene.integration.fire, self.time_step)
        self.a["fire"].from_numpy(fire.astype(self._real))

    def fire_status(self) -> dict[str, float]:
        """The FIRE minimiser's scalars after the last minimising call ("fire" scenes): the
        running Δt it reached, α, the steps, the velocity resets (P ≤ 0) and N+ / N−."""
        return fire_status_of(self.a["fire"].to_numpy())

    def _advance(self, n_steps: int, fire: bool = False) -> None:
        """Advance exactly ``n_steps`` (:func:`dem_taichi.engine.launcher.advance`)."""
        advance(self, n_steps, fire)

    def run(
        self,
        n_steps: int,
        control: CellControl | None = None,
        output_every: int | None = None,
        writer: Any = None,
        progress: bool = False,
        callback: Callable[[Simulation, Measures], None] | None = None,
    ) -> BondedMeasures:
        """Advance ``n_steps`` steps; returns the measures at the end (see module docstring).

        ``writer.append(measures)`` and ``callback(sim, measures)`` are called every
        ``output_every`` steps (default ``[output] every``) and at the end.

        A minimising control (``control.minimise``, :meth:`CellControl.relaxation`) on a scene
        with ``[integration] relaxation = "fire"`` runs the FIRE minimiser
        (:mod:`dem_taichi.kernels.fire`) for the call: a new minimisation from the current
        state, Δt growing to at most ``fire_dt_max`` × Δt within the call and back to Δt after
        it. Otherwise (every other control, and every call of a "damped" scene) the damped
        dynamics, the same steps whatever ``minimise`` says.
        """
        n_steps = step_count("n_steps", n_steps, 0)
        output_every = (
            self.scene.output.every
            if output_every is None
            else step_count("output_every", output_every, 1)
        )
        control = control or self._control
        self._control = control
        self._stage = control.stage
        fire = control.minimise and self.scene.integration.relaxation_method == "fire"
        if fire:
            self._start_fire()
        chunk = self.scene.integration.steps_per_call
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n_steps, unit="step", desc=control.stage, smoothing=0.1)
        measures: BondedMeasures | None = None
        done = 0
        next_output = output_every
        clock = _time.perf_counter
        kernel_seconds = measure_seconds = 0.0
        try:
            while done < n_steps:
                todo = min(chunk, n_steps - done, next_output - done)
                t0 = clock()
                self._set_rates(control.rates)
                self._advance(todo, fire)
                kernel_seconds += clock() - t0
                done += todo
                if bar is not None:
                    bar.update(todo)
                if done == next_output or done == n_steps:
                    next_output = done + output_every
                    t0 = clock()
                    measures = self.measure()
                    measure_seconds += clock() - t0
                    if writer is not None:
                        writer.append(measures)
                    if callback is not None:
                        callback(self, measures)
        finally:
            if bar is not None:
                bar.close()
            if self.work is not None:
                add_work(
                    self.work, control.stage, current_work(), done, kernel_seconds, measure_seconds
                )
        return measures if measures is not None else self.measure()
