"""Engine state on the host: the names and meaning of the arrays of :meth:`Simulation.get_state`.

The state is a plain ``dict[str, numpy.ndarray]`` (so it can be copied, compared bit for bit and
written to a checkpoint by :mod:`dem_taichi.io.checkpoint`); its arrays are those of role
``state`` in :data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS`. Keys:

=================  ==============  ===========================================================
key                shape / dtype   meaning
=================  ==============  ===========================================================
reduced_position   (N, 2) real     centroid in cell units s (X = s ∘ L), not always in [0, 1);
                                   N bodies: rods, or discs of bonded rods
angle              (N,) real       θ, rod axis (cos θ, sin θ)
velocity           (N, 2) real     fluctuating centroid velocity at the half step
angular_velocity   (N,) real       ω at the half step
force, torque      (N, 2), (N,)    total pair force/torque at the current positions
ref_position       (N, 2) real     reduced centroids at the last neighbour-list build
ref_angle          (N,) real       angles at the last build
neighbours         (M, K) int32    half Verlet list entries j·25 + image code (kernels/layout.py)
tangential_spring  (M, K) real     ξ of each entry (scalar along t = (−n_y, n_x))
rolling_spring     (M, K) real     rolling spring ψ of each entry [rad]
(dem_taichi.physics.rolling);
                                   (1, K) of zeros without rolling resistance
neighbour_count    (M,) int32      used entries per disc
cell               (8,) real       L_x, L_y, lengths at the last build, time, trackers
flags              (12,) int32     kernel flags (see kernels/layout.py)
params             (31,) real      runtime parameters incl. the current strain rates
bond_intact        (N,) int32      bonded rods: 1 while the bond b—b+1 holds (rigid: unused)
attraction_        (R, 32) int32   the rods' attraction partners, row [n, partners...], n = -1
partners                           until state A (dem_taichi.physics.attraction); R = the rods
                                   with [long_range] attraction_pairs = "bonded_at_A", else 1
reference_lengths  (2,) float64    L0 of the logarithmic strain
step               () int64        steps done since the start of the run
full_list          () bool         neighbour list holds both directions (``gather`` execution)
=================  ==============  ===========================================================

A state saved by one execution mode can be restored into another: the neighbour list (and its
springs) is converted between the half and the full form.

The state restores a run exactly: resuming from it gives the same trajectory bit for bit (serial
execution) as not stopping.
"""

from __future__ import annotations

import numpy as np

from dem_taichi.engine.device_arrays import HOST_STATE_KEYS, STATE_ARRAYS
from dem_taichi.kernels import layout as L
from dem_taichi.physics.attraction import NOT_SET, unset_table

#: Keys of the state dict: the state arrays of
# :data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS`,
#: then the host values.
STATE_KEYS = tuple(spec.state_key for spec in STATE_ARRAYS) + HOST_STATE_KEYS


def copy_state(state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Deep copy of a state dict."""
    return {key: np.array(value, copy=True) for key, value in state.items()}


def states_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    """True when two states are bitwise identical (same keys, dtypes, shapes and bytes)."""
    if set(a) != set(b):
        return False
    for key in a:
        x, y = np.asarray(a[key]), np.asarray(b[key])
        if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
            return False
    return True


def convert_neighbour_list(
    state: dict[str, np.ndarray], full_list: bool, capacity: int
) -> dict[str, np.ndarray]:
    """The state with its neighbour list in the half (i < j) or the full form (``full_list``),
    at least ``capacity`` entries per disc (the state itself when it is in that form already).

    The scalar tangential spring ξ is the same seen from both discs (t and the relative
    velocity both change sign), so a pair's entry is mirrored with its ξ unchanged and the
    image code negated; the rolling spring ψ (of ω_i − ω_j) changes sign.
    """
    full = bool(state.get("full_list", np.array(False)))
    if full == full_list:
        return state
    counts = state["neighbour_count"]
    entries = state["neighbours"]
    springs = state["tangential_spring"]
    rolling = state.get("rolling_spring")
    has_rolling = rolling is not None and rolling.shape[0] == len(counts)
    psi = rolling if rolling is not None and has_rolling else np.zeros(entries.shape)
    rows: list[list[tuple[int, float, float]]] = [[] for _ in range(len(counts))]
    for i, count in enumerate(counts):
        for k in range(int(count)):
            entry, xi, roll = int(entries[i, k]), springs[i, k], psi[i, k]
            j, code = divmod(entry, L.IMAGE_CODES)
            if full:
                if j > i:
                    rows[i].append((entry, xi, roll))
            else:
                rows[i].append((entry, xi, roll))
                mirrored = L.mirrored_image_code(code)
                rows[j].append((i * L.IMAGE_CODES + mirrored, xi, -roll))
    capacity = max(max((len(r) for r in rows), default=1), capacity)
    new_entries = np.zeros((len(counts), capacity), dtype=entries.dtype)
    new_springs = np.zeros((len(counts), capacity), dtype=springs.dtype)
    new_psi = np.zeros((len(counts), capacity), dtype=springs.dtype)
    for i, row in enumerate(rows):
        for k, (entry, xi, roll) in enumerate(row):
            new_entries[i, k], new_springs[i, k], new_psi[i, k] = entry, xi, roll
    converted = dict(state)
    converted["neighbours"] = new_entries
    converted["tangential_spring"] = new_springs
    if has_rolling:
        converted["rolling_spring"] = new_psi
    converted["neighbour_count"] = np.array([len(r) for r in rows], dtype=counts.dtype)
    converted["full_list"] = np.array(full_list)
    return converted


def fit_rolling_spring(state: dict[str, np.ndarray], rolling: bool) -> dict[str, np.ndarray]:
    """The state with its rolling springs in the shape of a simulation with (``rolling``) or
    without rolling resistance: (M, K) (zeros where the state has none: states written before
    rolling resistance, or by a simulation without it) or (1, K) of zeros.

    Raises ValueError for a state whose rolling springs are not all zero restored into a
    simulation without rolling resistance (they would be lost)."""
    entries = state["neighbours"]
    spring = state.get("rolling_spring")
    rows = entries.shape[0] if rolling else 1
    if spring is not None and spring.shape == (rows, entries.shape[1]):
        return state
    if spring is not None and not rolling and np.any(spring != 0.0):
        raise ValueError(
            "state carries rolling springs (rolling resistance at the contacts), this "
            "simulation has none: restore it into a scene with the same [contact] "
            "rolling_stiffness"
        )
    state = dict(state)
    state["rolling_spring"] = np.zeros((rows, entries.shape[1]), dtype=state["angle"].dtype)
    return state


def fit_attraction_partners(state: dict[str, np.ndarray], rows: int) -> dict[str, np.ndarray]:
    """The state with its attraction-partner table in the shape of a simulation with ``rows``
    rows (the rods with ``[long_range] attraction_pairs = "bonded_at_A"``, else 1): the state's
    own when it fits, else a table whose partners are not set (states written before the option,
    or by a simulation without it).

    Raises ValueError for a state whose partners are set (it went past state A with the option)
    restored into a simulation of another shape (they would be lost or misread)."""
    table = state.get("attraction_partners")
    if table is not None and table.shape == (rows, L.PARTNER_COLUMNS):
        return state
    if table is not None and np.any(table[:, 0] != NOT_SET):
        raise ValueError(
            "state carries the attraction partners set at state A ([long_range] "
            "attraction_pairs = 'bonded_at_A'), this simulation has "
            + ("none" if rows == 1 else f"{rows} rods")
            + ": restore it into a scene with the same rods and attraction_pairs"
        )
    state = dict(state)
    state["attraction_partners"] = unset_table(rows, L.PARTNER_COLUMNS)
    return state


def upgrade_state(
    state: dict[str, np.ndarray], n_bodies: int, params_now: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """A state written before the bonded-rod model (``params`` of 20 entries, no
    ``bond_intact``) or before rolling resistance (28 entries) in today's layout: the new
    parameters from ``params_now`` (the restoring simulation's, so that its bonds and rolling
    springs stay on; 0 without it), every bond intact (the rolling springs:
    :func:`fit_rolling_spring`). Today's states are returned as they are."""
    params = np.asarray(state["params"])
    if params.shape[0] == L.N_PARAMS and "bond_intact" in state:
        return state
    state = dict(state)
    if params.shape[0] < L.N_PARAMS:
        missing = np.zeros(L.N_PARAMS - params.shape[0], params.dtype)
        if params_now is not None:
            missing = np.asarray(params_now, dtype=params.dtype)[params.shape[0] :]
        state["params"] = np.concatenate([params, missing])
    if "bond_intact" not in state:
        state["bond_intact"] = np.ones(n_bodies, dtype=np.int32)
    return state
