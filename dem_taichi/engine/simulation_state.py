"""The state of a :class:`dem_taichi.engine.simulation.Simulation`: copies, restores, runtime
parameters and checkpoints (a base class of ``Simulation``).

``get_state()``/``set_state()`` copy and restore every state array of
:data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS` (a restored state continues bit for bit;
states written before the bonded-rod model are upgraded by
:func:`dem_taichi.engine.state.upgrade_state`); ``set_parameters`` changes the runtime parameters
without recompiling; ``save_checkpoint`` and ``from_checkpoint`` write and read the state with the
scene (:mod:`dem_taichi.io.checkpoint`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from dem_taichi.engine.device_arrays import STATE_ARRAYS
from dem_taichi.engine.parameters import EngineParameters, Physics
from dem_taichi.engine.state import convert_neighbour_list, fit_rolling_spring, upgrade_state
from dem_taichi.kernels import layout as L
from dem_taichi.scene.config import Scene, scene_from_toml, scene_to_toml
from dem_taichi.scene.geometry import GasState, RodGeometry

__all__ = ["SimulationState"]

#: (device array, state key) of every state array, in the order of the state dict (a state
#: array always has its key: DeviceArray checks it).
_STATE_KEYS: tuple[tuple[str, str], ...] = tuple(
    (spec.name, spec.state_key) for spec in STATE_ARRAYS if spec.state_key is not None
)


class SimulationState:
    """State, parameters and checkpoints of a simulation (mixed into :class:`Simulation`)."""

    # What this base reads of the simulation, set by ``Simulation.__init__`` (declared for the
    # type checker only: annotations make no attribute).
    scene: Scene
    arch: str
    precision: str
    execution: str
    deterministic: bool
    a: dict[str, Any]  # the device arrays (Taichi ndarrays) by name
    body: RodGeometry
    physics: Physics
    full_list: bool
    n_rods: int
    n_discs: int
    n_bodies: int
    capacity: int
    step: int
    reference_lengths: np.ndarray
    _real: type[np.floating]
    _rates: np.ndarray
    _stage: str
    if TYPE_CHECKING:
        # Simulation's constructor and methods, and SimulationViews' cell lengths

        def __init__(
            self,
            scene: Scene,
            arch: str = "cpu",
            precision: str = "f64",
            deterministic: bool = False,
            execution: str | None = None,
            initial: GasState | None = None,
            neighbour_capacity: int | None = None,
        ) -> None: ...

        def _launch(self, kernel: Any, **scalars: Any) -> None: ...

        def _grow(self, capacity: int) -> None: ...

        @property
        def parameters(self) -> EngineParameters: ...

        @parameters.setter
        def parameters(self, values: EngineParameters) -> None: ...

        @property
        def cell_lengths(self) -> np.ndarray: ...

    def get_state(self) -> dict[str, np.ndarray]:
        """Numpy copies of the full state (see :mod:`dem_taichi.engine.state`)."""
        state = {key: self.a[name].to_numpy() for name, key in _STATE_KEYS}
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
        state = upgrade_state(state, n, self.a["params"].to_numpy())
        state = convert_neighbour_list(state, self.full_list, self.capacity)
        state = fit_rolling_spring(state, self.physics.rolling)
        capacity = state["neighbours"].shape[1]
        if capacity != self.capacity:
            self._grow(capacity)
        a = self.a
        for name, key in _STATE_KEYS:
            a[name].from_numpy(np.ascontiguousarray(state[key]))
        self.reference_lengths = np.array(state["reference_lengths"], dtype=np.float64)
        self.step = int(state["step"])
        params = EngineParameters.from_vector(state["params"])
        self._rates = np.array([params.rate_x, params.rate_y], dtype=float)
        # disc positions are derived: recompute them from the centroids
        from dem_taichi.kernels.common import place_all_discs

        self._launch(place_all_discs, ns=self.body.n_spheres)

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
    ) -> Self:
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
