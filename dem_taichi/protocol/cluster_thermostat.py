"""A thermostat on the clusters' motion as wholes, for the aggregation stage (issue 19).

``[protocol] aggregation_thermostat = "clusters"``: at every check each cluster of rods (rods
joined by an interacting pair: a contact or a long-range force) gets a fresh centre-of-mass
velocity at the temperature of ``aggregation_speed`` (equipartition: U_c ~ N(0, speed²/n_c)
per component for a cluster of n_c rods of equal mass), and the rods' motion *relative* to their
cluster's centre of mass is left as it is. A free rod (a cluster of one) also gets a fresh spin
ω ~ N(0, speed² M/I); a larger cluster's rotation as a whole is not refreshed.

Why: the rescaling thermostat gave the loosest gels but keeps its energy in the modes that
dissipate least; the fresh draw ("resample") heats every mode, the clusters' internal ones
included, where friction and damping dissipate it (and the gels are denser); a partial refresh
("langevin") runs cold. This one heats only the clusters' motion as wholes, at the temperature,
like Brownian clusters: the test of whether heating the clusters' insides is what compacts the
gel (``benchmarks/results/study_clay_agitated.md``).

Pure numpy: :func:`cluster_labels`, :func:`cluster_velocities`; :func:`cluster_speed` applies
them to a simulation. Seeded by (seed, the step), so runs are deterministic and resumable.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from dem_taichi.engine.simulation import Simulation
from dem_taichi.protocol.quasistatic import equipartition_spin, rms_velocity_component

__all__ = ["cluster_labels", "cluster_velocities", "cluster_speed"]

#: the generator's stream tag ("CLUS"), beside the seed and the step
STREAM = 0x434C5553


def cluster_labels(n_rods: int, rod_i: np.ndarray, rod_j: np.ndarray) -> np.ndarray:
    """Cluster index (0 … n_clusters − 1) of every rod: the connected components of the graph
    of rods with an edge per pair (rod_i[k], rod_j[k]); a rod with no pair is its own cluster."""
    if n_rods <= 0:
        return np.zeros(0, dtype=np.int64)
    rod_i = np.asarray(rod_i, dtype=np.int64)
    rod_j = np.asarray(rod_j, dtype=np.int64)
    graph = coo_matrix((np.ones(rod_i.size), (rod_i, rod_j)), shape=(n_rods, n_rods))
    _, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64)


def cluster_velocities(
    velocity: np.ndarray, labels: np.ndarray, speed: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(new velocities, the clusters' new centre-of-mass velocities) for rods of equal mass:
    v_i ← v_i − V_c + U_c, V_c the mean velocity of rod i's cluster c, U_c ~ N(0, speed²/n_c)
    per component (n_c its rods), drawn in the order of the cluster index, then the mass-weighted
    mean of the U_c removed (total momentum zero)."""
    n_clusters = int(labels.max()) + 1 if labels.size else 0
    sizes = np.bincount(labels, minlength=n_clusters).astype(float)
    centre = np.zeros((n_clusters, 2))
    for axis in range(2):
        centre[:, axis] = np.bincount(labels, weights=velocity[:, axis], minlength=n_clusters)
    centre /= sizes[:, None]
    fresh = rng.normal(0.0, 1.0, size=(n_clusters, 2)) * (speed / np.sqrt(sizes))[:, None]
    fresh -= (sizes[:, None] * fresh).sum(axis=0) / sizes.sum()
    return velocity - centre[labels] + fresh[labels], fresh


def cluster_speed(sim: Simulation, speed: float, seed: int) -> float:
    """Refresh the clusters' centre-of-mass velocities (and the free rods' spins) of ``sim`` at
    the temperature of ``speed`` (module docstring); returns the rms velocity component before.
    The clusters are read from the interacting pairs the last measure left (the ageing measures
    at every check). Rigid rods only (a bonded rod's discs are bodies of their own)."""
    if sim.bonded:
        raise ValueError(
            "aggregation_thermostat = 'clusters' needs rigid rods ([particles] rod_model = 'rigid')"
        )
    velocity_now, omega_now = sim.velocities()
    velocity = np.asarray(velocity_now, dtype=float)
    before = rms_velocity_component(velocity)
    rod_i, rod_j = sim.interacting_rod_pairs()
    labels = cluster_labels(sim.n_rods, rod_i, rod_j)
    rng = np.random.Generator(np.random.PCG64([int(seed), STREAM, int(sim.step)]))
    new, _ = cluster_velocities(velocity, labels, speed, rng)
    omega = np.array(omega_now, dtype=float)
    free = np.bincount(labels)[labels] == 1
    spin = equipartition_spin(sim, speed)
    omega[free] = rng.normal(0.0, spin, size=int(free.sum()))
    sim.set_velocities(new.astype(velocity_now.dtype), omega.astype(omega_now.dtype))
    return before
