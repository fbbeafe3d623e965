"""What a :class:`dem_taichi.engine.simulation.Simulation` reports: the history measures, the rods
of either model, the interaction network (an object the simulation holds, ``sim.views``, built on
its device arrays; numpy and the measure kernel, no state of its own: what changes as the run goes
— the step, the strain reference, the rates, the stage — is passed to :meth:`SimulationViews.
measure`).

``measure()`` is the history record (:class:`dem_taichi.engine.measures.Measures`; bonded rods add
:data:`dem_taichi.io.history_schema.BONDED_HISTORY_VARIABLES`); ``rod_positions()`` and
``rod_angles()`` are the rods' (bonded rods: mean of the discs and end-to-end vector), the
``body_*`` views the engine's bodies; ``snapshot()`` the :class:`NetworkSnapshot` the probes and
the servo use.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable
from typing import Any

import numpy as np

from dem_taichi.engine.failures import PeriodTwo, period_two_bodies
from dem_taichi.engine.measures import BondedMeasures, history_record
from dem_taichi.engine.network import interacting_entries, mechanical_coordination, network_snapshot
from dem_taichi.engine.parameters import EngineParameters, Physics
from dem_taichi.kernels import layout as L
from dem_taichi.physics.bonds import rod_axes, unwrapped_chains
from dem_taichi.physics.snapshot import NetworkSnapshot
from dem_taichi.scene.geometry import RodGeometry

__all__ = ["SimulationViews"]


class SimulationViews:
    """Measures, rods and network of a simulation, read from its device arrays.

    ``arrays``: the simulation's device arrays by name (the dict itself: a capacity growth
    replaces arrays in it); ``launch(kernel, **scalars)`` calls a kernel with its arrays;
    ``species`` (charge, F_max, k_a of each place in the rod), ``geometry`` (the rod's), ``body``
    (the engine's bodies), ``physics``, ``full_list`` (a full neighbour list), ``n_rods`` and
    ``n_bodies`` as the simulation has them; ``timings``: the simulation's seconds by kind, to
    which the measure kernel's are added; ``rod_strength``: the rods' long-range strengths (None:
    alike).
    """

    def __init__(
        self,
        arrays: dict[str, Any],
        launch: Callable[..., None],
        species: tuple[np.ndarray, np.ndarray, np.ndarray],
        geometry: RodGeometry,
        body: RodGeometry,
        physics: Physics,
        full_list: bool,
        n_rods: int,
        n_bodies: int,
        timings: dict[str, float],
        rod_strength: np.ndarray | None = None,
    ) -> None:
        self.a = arrays
        self._launch = launch
        self.species = species
        self.geometry = geometry
        self.body = body
        self.physics = physics
        #: the switches the measure kernels run with (the simulation's ``kernel_physics``)
        self.kernel_physics = physics
        self.bonded = physics.bonded
        self.full_list = full_list
        self.n_rods = n_rods
        self.n_bodies = n_bodies
        self.timings = timings
        self.rod_strength = rod_strength

    @property
    def parameters(self) -> EngineParameters:
        """The runtime parameters in the device array ``params``."""
        return EngineParameters.from_vector(self.a["params"].to_numpy())

    @property
    def _on_device(self) -> bool:
        """Whether the measures are summed in blocks and Z_m counted on the device: the parallel
        and gather paths (their block rows are allocated, > 1; the serial path has one). On a
        GPU one thread over every pair, or a host copy of the list, costs more than the 100
        steps between two measures (benchmarks/results/gpu_bench.md)."""
        return self.a["block_sums"].shape[0] > 1

    def _measure_sums(self) -> np.ndarray:
        from dem_taichi.kernels.measures import measure_sums, measure_sums_blocked

        t0 = _time.perf_counter()
        kernel = measure_sums_blocked if self._on_device else measure_sums
        self._launch(kernel, ns=self.body.n_spheres, full=self.full_list, phys=self.kernel_physics)
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

    def measure(
        self, step: int, reference_lengths: np.ndarray, rates: np.ndarray, stage: str
    ) -> BondedMeasures:
        """History measures (names of ``dem_taichi.io.schema``) at ``step``, the logarithmic
        strains from the cell ``reference_lengths``, the cell's strain ``rates`` (1/time) and the
        protocol ``stage``; see the module docstring."""
        from dem_taichi.io.schema import stage_code

        sums = self._measure_sums()
        n_bonds = self.n_rods * (self.geometry.n_spheres - 1) if self.bonded else 0
        record = history_record(
            sums,
            self._stress_tensor(sums),
            self.cell_lengths,
            reference_lengths,
            rates,
            self.rod_angles(),
            self.geometry,
            self.n_rods,
            step,
            self.time,
            stage_code(stage),
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

    def period_two(self) -> PeriodTwo:
        """The bodies oscillating with a period of two steps now, from the forces and half-step
        velocities (:func:`dem_taichi.engine.failures.period_two_bodies`)."""
        a, p = self.a, self.parameters
        n = self.n_bodies
        return period_two_bodies(
            a["force"].to_numpy()[:n], a["vel"].to_numpy()[:n], a["torque"].to_numpy()[:n],
            a["omega"].to_numpy()[:n], p.mass, p.inertia, p.time_step, p.local_damping,
        )  # fmt: skip

    @staticmethod
    def total_energy(m: BondedMeasures) -> float:
        """Kinetic + contact + long-range (+ bond) energy of the measures ``m`` (for conservation
        checks)."""
        bonds = m.get("bond_energy", 0.0)
        return m["kinetic_energy"] + m["contact_energy"] + m["long_range_energy"] + bonds

    # network (dem_taichi.engine.network)
    def _contact_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(disc i, list slot k, packed entry, flag bits) of every interacting list entry."""
        a = self.a
        counts, bits = a["nbr_count"].to_numpy(), a["pair_flags"].to_numpy()
        neighbours = a["nbr"].to_numpy()  # (discs, capacity): the capacity as grown so far
        return interacting_entries(counts, bits, neighbours, neighbours.shape[1])

    def interacting_rod_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(rod i, rod j) of every interacting list entry (a contact or a long-range force)
        between discs of two different rods, as the last measure left the flags; a pair of rods
        appears once per interacting pair of their discs."""
        i, _, packed, _ = self._contact_pairs()
        ns = self.geometry.n_spheres
        rod_i = (i // ns).astype(np.int64)
        rod_j = (packed // L.IMAGE_CODES // ns).astype(np.int64)
        other = rod_i != rod_j
        return rod_i[other], rod_j[other]

    def _mechanical_coordination(self) -> float:
        """Z_m: on the host from the copied list (the serial path), or counted on the device
        (the parallel and gather paths, :mod:`dem_taichi.kernels.coordination`: at 10⁵ rods
        the copy costs more than 100 GPU steps); the same integers, so the same value."""
        if not self._on_device:
            i, _, packed, bits = self._contact_pairs()
            return mechanical_coordination(i, packed, bits, self.geometry.n_spheres, self.n_rods)
        return self._device_coordination()

    def _device_coordination(self) -> float:
        from dem_taichi.kernels.coordination import count_rod_contacts, remove_rattlers

        chain, n_rods = self.geometry.n_spheres, self.n_rods
        first = 1
        while True:  # a round per layer of rattlers (a few)
            self._launch(count_rod_contacts, first=first, n_rods=n_rods, chain=chain)
            self._launch(remove_rattlers, n_rods=n_rods)
            first = 0
            removed, alive, counts = (int(c) for c in self.a["coordination"].to_numpy())
            if removed == 0:
                return counts / alive if alive else 0.0

    def _snapshot_positions(self) -> np.ndarray:
        """Body centroids for the snapshot: wrapped, except that the discs of a bonded rod are
        made contiguous (each bond vector x_h − x_g, no shift)."""
        positions = self.body_positions()
        if not self.bonded:
            return positions
        chain = self.geometry.n_spheres
        return unwrapped_chains(positions, chain, self.cell_lengths).reshape(-1, 2)

    def _bond_network(self):
        """The bonds of a bonded simulation as a
        :class:`dem_taichi.physics.snapshot.BondNetwork`."""
        from dem_taichi.physics.bonds import chain_bonds
        from dem_taichi.physics.snapshot import BondNetwork

        g = chain_bonds(self.n_rods, self.geometry.n_spheres)
        params = self.parameters
        return BondNetwork(
            chain=self.geometry.n_spheres,
            g=g,
            intact=self.a["bond_intact"].to_numpy()[g] == 1,
            rest_length=params.spacing,
            k_n=params.bond_k_n,
            k_t=params.bond_k_t,
            k_b=params.bond_k_b,
        )

    def snapshot(self) -> NetworkSnapshot:
        """The interacting network as a :class:`dem_taichi.physics.snapshot.NetworkSnapshot`."""
        self._measure_sums()
        return network_snapshot(
            self._contact_pairs(),
            self.a["disc_x"].to_numpy().astype(float),
            self.a["nbr_xi"].to_numpy().astype(float),
            self.cell_lengths,
            self._snapshot_positions(),
            self.body_angles(),
            self.body,
            (self.species[0].copy(), self.species[1].copy(), self.species[2].copy()),
            self.parameters,
            self.physics.vdw,
            bonds=self._bond_network() if self.bonded else None,
            rolling_springs=(
                self.a["nbr_psi"].to_numpy().astype(float) if self.physics.rolling else None
            ),
            rod_strength=None if self.rod_strength is None else self.rod_strength.copy(),
            attraction_partners=(
                self.a["attraction_partners"].to_numpy() if self.physics.partners else None
            ),
            cap_force="net" if self.kernel_physics.net_caps else "contact",
        )
