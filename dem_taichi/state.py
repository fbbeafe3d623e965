"""Engine state on the host: the names and meaning of the arrays of :meth:`Simulation.get_state`.

The state is a plain ``dict[str, numpy.ndarray]`` (so it can be copied, compared bit for bit and
written to a checkpoint by :mod:`dem_taichi.io.checkpoint`); its arrays are those of role
``state`` in :data:`dem_taichi.device_arrays.DEVICE_ARRAYS`. Keys:

=================  ==============  ===========================================================
key                shape / dtype   meaning
=================  ==============  ===========================================================
reduced_position   (N, 2) real     centroid in cell units s (X = s ∘ L), not always in [0, 1)
angle              (N,) real       θ, rod axis (cos θ, sin θ)
velocity           (N, 2) real     fluctuating centroid velocity at the half step
angular_velocity   (N,) real       ω at the half step
force, torque      (N, 2), (N,)    total pair force/torque at the current positions
ref_position       (N, 2) real     reduced centroids at the last neighbour-list build
ref_angle          (N,) real       angles at the last build
neighbours         (M, K) int32    half Verlet list entries j·25 + image code (kernels/layout.py)
tangential_spring  (M, K) real     ξ of each entry (scalar along t = (−n_y, n_x))
neighbour_count    (M,) int32      used entries per disc
cell               (8,) real       L_x, L_y, lengths at the last build, time, trackers
flags              (12,) int32     kernel flags (see kernels/layout.py)
params             (20,) real      runtime parameters incl. the current strain rates
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

from dem_taichi.device_arrays import HOST_STATE_KEYS, STATE_ARRAYS

#: Keys of the state dict: the state arrays of :data:`dem_taichi.device_arrays.DEVICE_ARRAYS`,
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
