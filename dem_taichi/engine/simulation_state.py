"""The state of a :class:`dem_taichi.engine.simulation.Simulation`: copies, restores and
checkpoints (an object the simulation holds, ``sim.state_io``, built on its device arrays).

:meth:`SimulationState.get_state` and :meth:`SimulationState.restore` copy and restore every state
array of :data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS` (a restored state continues bit for
bit; states written before the bonded-rod model are upgraded by
:func:`dem_taichi.engine.state.upgrade_state`); what the simulation keeps beside its arrays (the
step, the strain reference, the rates) goes in as arguments and comes back as a
:class:`RestoredState`. :func:`checkpoint_meta` and :func:`checkpoint_start` are the two ends of a
checkpoint with its scene (:mod:`dem_taichi.io.checkpoint`); the simulation's
``save_checkpoint``/``from_checkpoint`` call them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from dem_taichi.engine.device_arrays import STATE_ARRAYS
from dem_taichi.engine.parameters import EngineParameters, Physics
from dem_taichi.engine.state import (
    convert_neighbour_list,
    fit_attraction_partners,
    fit_rolling_spring,
    upgrade_state,
)
from dem_taichi.kernels import layout as L
from dem_taichi.physics.attraction import NOT_SET, partner_pairs, partner_table
from dem_taichi.scene.config import Scene, scene_from_toml, scene_to_toml
from dem_taichi.scene.geometry import GasState, RodGeometry

__all__ = ["RestoredState", "SimulationState", "checkpoint_meta", "checkpoint_start"]

#: (device array, state key) of every state array, in the order of the state dict (a state
#: array always has its key: DeviceArray checks it).
_STATE_KEYS: tuple[tuple[str, str], ...] = tuple(
    (spec.name, spec.state_key) for spec in STATE_ARRAYS if spec.state_key is not None
)


@dataclass(frozen=True)
class RestoredState:
    """What a restored state sets beside the device arrays: the ``step``, the cell's
    ``reference_lengths`` of the logarithmic strains (length) and the strain ``rates`` (1/time)."""

    step: int
    reference_lengths: np.ndarray
    rates: np.ndarray


class SimulationState:
    """Copies and restores of a simulation's state arrays.

    ``arrays``: the simulation's device arrays by name (the dict itself); ``launch(kernel,
    **scalars)`` calls a kernel with its arrays; ``grow(capacity)`` grows the neighbour-list
    arrays; ``rod_model`` (the scene's, for messages), ``body`` (the engine's bodies),
    ``physics``, ``full_list`` (a full neighbour list), ``n_rods``, ``n_discs``, ``n_bodies`` and
    the numpy ``real`` type as the simulation has them.
    """

    def __init__(
        self,
        arrays: dict[str, Any],
        launch: Callable[..., None],
        grow: Callable[[int], None],
        rod_model: str,
        body: RodGeometry,
        physics: Physics,
        full_list: bool,
        n_rods: int,
        n_discs: int,
        n_bodies: int,
        real: type[np.floating],
        net_caps_from_start: bool = True,
    ) -> None:
        self.a = arrays
        self._launch = launch
        self._grow = grow
        self.rod_model = rod_model
        self.body = body
        self.physics = physics
        self.full_list = full_list
        self.n_rods, self.n_discs, self.n_bodies = n_rods, n_discs, n_bodies
        self._real = real
        #: whether the net caps act now (``[contact] cap_force``): from the start with "net"
        #: (``net_caps_from_start``), from state A on with "net_after_A"
        #: (:meth:`drop_attraction_caps`); a state key
        #: ``net_caps_on`` of the scenes that have the switch, and only of them
        self.net_caps_on = physics.net_caps and net_caps_from_start
        self._net_caps_from_start = net_caps_from_start

    def get_state(self, step: int, reference_lengths: np.ndarray) -> dict[str, np.ndarray]:
        """Numpy copies of the full state at ``step`` with the strain ``reference_lengths``
        (see :mod:`dem_taichi.engine.state`)."""
        state = {key: self.a[name].to_numpy() for name, key in _STATE_KEYS}
        if self.physics.net_caps:
            state["net_caps_on"] = np.array(self.net_caps_on)
        return state | {
            "reference_lengths": reference_lengths.copy(),
            "step": np.array(step, dtype=np.int64),
            "full_list": np.array(self.full_list),
        }

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Numpy copies of the bodies' velocities ((N, 2), length/time) and angular velocities
        ((N,), 1/time), as :meth:`get_state` has them, without copying the rest of the state."""
        return self.a["vel"].to_numpy(), self.a["omega"].to_numpy()

    def set_velocities(self, velocity: np.ndarray, angular_velocity: np.ndarray) -> None:
        """Write the bodies' velocities and angular velocities and nothing else: what
        :meth:`restore` of a state that differs from the current one only there does (the
        positions, springs and lists are left as they are), at a fraction of its cost. Shapes
        and precision as :meth:`velocities` gives them."""
        for name, key, value in (
            ("vel", "velocity", velocity),
            ("omega", "angular_velocity", angular_velocity),
        ):
            array = self.a[name]
            if value.shape != tuple(array.shape) or value.dtype != self._real:
                raise ValueError(
                    f"{key} of shape {value.shape} and type {value.dtype} does not fit this "
                    f"simulation ({tuple(array.shape)}, {np.dtype(self._real)})"
                )
            array.from_numpy(np.ascontiguousarray(value))

    def restore(self, state: dict[str, np.ndarray]) -> RestoredState:
        """Restore a state from :meth:`get_state` (same scene and precision) into the arrays;
        returns the step, strain reference and rates it carries."""
        n, m = self.n_bodies, self.n_discs
        if state["angle"].shape != (n,) or state["neighbours"].shape[0] != m:
            raise ValueError(
                f"state of {state['angle'].shape[0]} bodies does not fit this simulation ({n} "
                f"bodies: {self.n_rods} {self.rod_model} rods)"
            )
        if state["angle"].dtype != self._real:
            raise ValueError(
                f"state precision {state['angle'].dtype} differs from the simulation's "
                f"{np.dtype(self._real)}"
            )
        capacity_now = self.a["nbr"].shape[1]
        state = upgrade_state(state, n, self.a["params"].to_numpy())
        state = convert_neighbour_list(state, self.full_list, capacity_now)
        state = fit_rolling_spring(state, self.physics.rolling)
        state = fit_attraction_partners(state, self.n_rods if self.physics.partners else 1)
        capacity = state["neighbours"].shape[1]
        if capacity != capacity_now:
            self._grow(capacity)
        a = self.a
        for name, key in _STATE_KEYS:
            a[name].from_numpy(np.ascontiguousarray(state[key]))
        if self.physics.net_caps:  # a state without the key: the scene's start
            self.net_caps_on = bool(state.get("net_caps_on", self._net_caps_from_start))
        params = EngineParameters.from_vector(state["params"])
        restored = RestoredState(
            step=int(state["step"]),
            reference_lengths=np.array(state["reference_lengths"], dtype=np.float64),
            rates=np.array([params.rate_x, params.rate_y], dtype=float),
        )
        # disc positions are derived: recompute them from the centroids
        from dem_taichi.kernels.common import place_all_discs

        self._launch(place_all_discs, ns=self.body.n_spheres)
        return restored

    def partner_pairs(self) -> np.ndarray | None:
        """The rod pairs of the attraction-partner table ((P, 2)), or None while it is not set
        (or the scene has no partners: ``[long_range] attraction_pairs``)."""
        if not self.physics.partners:
            return None
        table = self.a["attraction_partners"].to_numpy()
        return None if np.all(table[:, 0] == NOT_SET) else partner_pairs(table)

    def set_partners(self, pairs: np.ndarray) -> None:
        """Set the partner table of the rod pairs ``pairs`` (:func:`dem_taichi.physics.
        attraction.partner_table`; ValueError for a rod with too many partners)."""
        self.a["attraction_partners"].from_numpy(
            partner_table(pairs, self.n_rods, L.PARTNER_COLUMNS)
        )

    def drop_attraction_caps(self) -> None:
        """From now on the net caps act (``[contact] cap_force = "net_after_A"``: the protocol
        calls it as each path leaves state A)."""
        if not self.physics.net_caps:
            raise ValueError(
                "drop_attraction_caps needs [contact] cap_force = 'net_after_A' (with friction "
                "or rolling resistance, and an attraction)"
            )
        self.net_caps_on = True

    def kernel_physics(self) -> Physics:
        """The switches the kernels run with: the scene's, except that attraction partners
        (``[long_range] attraction_pairs = "bonded_at_A"``) compile in only once they are set:
        until state A every pair attracts, and the kernels are then those of the scene without
        the option, so the gas, its ageing and A are the same bit for bit (a kernel compiled
        with the partner test rounds its sums in another order). Likewise the net caps of
        ``[contact] cap_force = "net_after_A"`` compile in only once switched on
        (:meth:`drop_attraction_caps`)."""
        physics = self.physics
        if physics.partners and self.partner_pairs() is None:
            physics = dataclasses.replace(physics, partners=False)
        if physics.net_caps and not self.net_caps_on:
            # [contact] cap_force = "net_after_A" before A: the study's caps, and the kernels
            # of the scene without the switch
            physics = dataclasses.replace(physics, net_caps=False)
        return physics

    def forget_contacts(self, time: float) -> None:
        """Empty the neighbour lists with their tangential and rolling springs (the contacts
        start afresh at the next list build) and set the cell's simulated ``time``: the rest of
        a fresh upload of bodies (:func:`dem_taichi.engine.device_allocation.upload_gas`)."""
        a = self.a
        for name in ("nbr_count", "old_count"):
            a[name].from_numpy(np.zeros(a[name].shape, dtype=np.int32))
        for name in ("nbr_xi", "nbr_psi", "old_xi", "old_psi"):
            a[name].from_numpy(np.zeros(a[name].shape, dtype=self._real))
        self.set_time(time)

    def carry_contacts(self, contacts: dict[str, np.ndarray]) -> None:
        """Put the neighbour lists of ``contacts`` (a state dict's ``neighbours``,
        ``tangential_spring``, ``rolling_spring`` and ``neighbour_count``, of bodies numbered
        disc for disc as this simulation's) as the current list, so that the next list build
        carries their tangential and rolling springs to the same disc pairs (matched by disc,
        whatever the periodic image): the contacts of a rigid twin handed back to bonded rods
        (:mod:`dem_taichi.protocol.rigid_ageing`). Call after :meth:`forget_contacts`, before
        the build; the capacity grows to fit."""
        count = np.asarray(contacts["neighbour_count"], dtype=np.int32)
        if count.shape != (self.n_discs,):
            raise ValueError(
                f"contacts of {count.shape[0]} discs do not fit this simulation "
                f"({self.n_discs} discs)"
            )
        full = bool(np.asarray(contacts.get("full_list", False)))
        if full != self.full_list:
            raise ValueError("contacts from a full (gather) list and a half list do not mix")
        width = int(count.max(initial=0))
        if width > self.a["nbr"].shape[1]:
            self._grow(width)
        a = self.a
        for name, key in (("nbr", "neighbours"), ("nbr_xi", "tangential_spring"),
                          ("nbr_psi", "rolling_spring")):  # fmt: skip
            target = np.zeros(a[name].shape, dtype=np.int32 if name == "nbr" else self._real)
            source = np.asarray(contacts[key])
            if source.shape[0] != target.shape[0]:
                raise ValueError(
                    f"contacts' {key} has {source.shape[0]} rows, this simulation's "
                    f"{target.shape[0]}: rolling resistance on in one scene and off in the other"
                )
            target[:, :width] = source[:, :width]
            a[name].from_numpy(target)
        a["nbr_count"].from_numpy(count)

    def set_time(self, time: float) -> None:
        """Set the cell's simulated ``time`` (the clock the measures report)."""
        cell = self.a["cell"].to_numpy()
        cell[L.C_TIME] = time
        self.a["cell"].from_numpy(cell)


def checkpoint_meta(
    scene: Scene,
    precision: str,
    arch: str,
    execution: str,
    deterministic: bool,
    stage: str,
    step: int,
) -> dict[str, Any]:
    """The JSON metadata of a checkpoint: the scene's TOML, how the simulation ran, its stage and
    step (what :func:`checkpoint_start` reads back)."""
    return {
        "scene_toml": scene_to_toml(scene),
        "precision": precision,
        "arch": arch,
        "execution": execution,
        "deterministic": deterministic,
        "stage": stage,
        "step": int(step),
    }


def checkpoint_start(
    arrays: dict[str, np.ndarray], meta: dict[str, Any], arch: str | None, precision: str | None
) -> tuple[Scene, dict[str, Any]]:
    """The scene of a checkpoint (``arrays``, ``meta``: :func:`dem_taichi.io.checkpoint.
    load_checkpoint`) and the keyword arguments of the ``Simulation`` that continues it: ``arch``
    and ``precision`` (None: the checkpoint's; a precision other than the checkpoint's is
    refused), its execution, the gas of its bodies and its list capacity."""
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
    return scene, {
        "arch": arch or meta["arch"],
        "precision": precision,
        "deterministic": bool(meta.get("deterministic", False)),
        "execution": meta.get("execution"),
        "initial": gas,
        "neighbour_capacity": arrays["neighbours"].shape[1],
    }
