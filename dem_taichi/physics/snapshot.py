"""The numpy picture of a static rod network: :class:`NetworkSnapshot` (numpy only, no Taichi).

The engine exports it (``Simulation.snapshot()``); the pair laws of
:mod:`dem_taichi.physics.forcelaw`, the linear-response probes (:mod:`dem_taichi.response.linear`,
:mod:`dem_taichi.response.flexible`) and the fabrics of :mod:`dem_taichi.response.anisotropy` are
written against it. It sits below all of them, so none imports another to get the type
(``dem_taichi.response.linear.NetworkSnapshot`` is the same class, re-exported).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BondNetwork", "NetworkSnapshot"]


def _as_array(name: str, value, dtype, shape: tuple) -> np.ndarray:
    """Convert ``value`` to a read-only array of ``dtype`` and check its ``shape`` (-1 = any)."""
    array = np.array(value, dtype=dtype, copy=True)
    wrong = array.ndim != len(shape) or any(
        s != -1 and a != s for a, s in zip(array.shape, shape, strict=True)
    )
    if wrong:
        raise ValueError(f"NetworkSnapshot.{name}: shape {array.shape}, expected {shape} (-1=any)")
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class BondNetwork:
    """The intra-rod bonds of a snapshot of bonded rods (docs/science/dem-model.md §1.7,
    :mod:`dem_taichi.physics.bonds`).

    The snapshot's bodies are then discs (``n_spheres`` = 1, rod-major: disc s of rod r is body
    r·chain + s), their centroids contiguous along each rod (bond vector x_h − x_g, no shift).

    Attributes:
        chain: discs per rod n_s.
        g: (B,) lower disc of every bond (h = g + 1).
        intact: (B,) bool, the bond holds (broken bonds carry nothing).
        rest_length: s_0; k_n, k_t, k_b: stretch, shear, bending stiffness.
    """

    chain: int
    g: np.ndarray
    intact: np.ndarray
    rest_length: float
    k_n: float
    k_t: float
    k_b: float

    def __post_init__(self) -> None:
        put = object.__setattr__
        if int(self.chain) != self.chain or self.chain < 2:
            raise ValueError(f"BondNetwork.chain = {self.chain!r}: need an int >= 2")
        put(self, "chain", int(self.chain))
        g = _as_array("g", self.g, np.int64, (-1,))
        if np.any(g % self.chain == self.chain - 1):
            raise ValueError("BondNetwork.g: the last disc of a rod has no bond to the next")
        put(self, "g", g)
        put(self, "intact", _as_array("intact", self.intact, bool, (g.shape[0],)))
        for name in ("rest_length", "k_n", "k_t", "k_b"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"BondNetwork.{name} = {value!r}: need a finite value > 0")
            put(self, name, value)


@dataclass(frozen=True)
class NetworkSnapshot:
    """A static configuration of rigid rods of discs in a periodic rectangular cell, with its pairs.

    Conventions (docs/science/dem-model.md §1.8): disc ``s`` of rod ``r`` has global index
    ``g = r * n_spheres + s`` and sits at ``X_r + o_s a_r`` with ``o_s = (s - (n_s-1)/2) spacing``
    and ``a_r = (cos θ_r, sin θ_r)``. Pair ``p`` joins discs ``pair_i[p]`` and ``pair_j[p]`` of two
    different rods, with ``r_ij = x_i - x_j - pair_shift[p]`` the minimum image. Every inter-rod
    pair that currently interacts (contact or within long-range range) is listed once.

    Attributes (units: d = 1, disc mass = 1, forces in DEM force units):
        cell_lengths: (2,) L_x, L_y.
        rod_position: (N, 2) rod centroids.
        rod_angle: (N,) rod angles θ [rad].
        n_spheres, spacing, diameter, disc_mass: rod geometry and disc mass.
        charge: (n_s,) charge of disc s of every rod, in {-1, 0, 1}.
        f_max, k_a: (n_s,) species F_max [force] and k_a [force/length] of disc s.
        k_n, k_t, mu: contact normal/tangential stiffness [force/length] and friction coefficient.
        vdw_f_max, vdw_k: van der Waals-like F_W [force] and k_W [force/length] (0, 0 = off).
        pair_i, pair_j: (P,) global disc indices.
        pair_shift: (P, 2) periodic image shift.
        tangential_spring: (P, 2) tangential spring ξ (0 for non-contacts).
        sliding: (P,) bool, the contact is at the Coulomb cap.
        bonds: the bonds of bonded rods (:class:`BondNetwork`; then the bodies are discs and
            ``charge``, ``f_max``, ``k_a`` have one entry per place in a rod), None for rigid
            rods.
        rolling_spring: (P,) rolling spring ψ [rad] of each pair (:mod:`dem_taichi.physics.rolling`;
        0
            for non-contacts); None: all 0 (:attr:`pair_rolling_spring`).
        rolling_stiffness: κ_r = k_r d_eff² [force·length/rad] of the contacts' rolling springs
            (0: no rolling resistance).
        rolling_cap: μ_r d_eff [length], the rolling moment cap per unit contact force.
        rod_strength: (N_rods,) long-range strength s of every rod (the rods of n_s places: for
            bonded rods, disc // n_s), a pair's F_max and k_a multiplied by the harmonic mean of
            its two rods' s ([long_range] strength_spread); None: all 1.
        attraction_partners: (N_rods, C) int partner table of the rods (the rods of n_s places,
            as for ``rod_strength``): an attractive pair acts only between partners of a rod
            whose row is set ([long_range] attraction_pairs = "bonded_at_A",
            :mod:`dem_taichi.physics.attraction`); None: every pair attracts.
        cap_force: the normal force behind the sliding and rolling caps at contacts: "contact"
            the contact spring's f_c; "net" max(f_c − F_att, 0), F_att the pair's attraction
            (long-range and van der Waals) ([contact] cap_force).
    """

    cell_lengths: np.ndarray
    rod_position: np.ndarray
    rod_angle: np.ndarray
    n_spheres: int
    spacing: float
    diameter: float
    disc_mass: float
    charge: np.ndarray
    f_max: np.ndarray
    k_a: np.ndarray
    k_n: float
    k_t: float
    mu: float
    vdw_f_max: float
    vdw_k: float
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_shift: np.ndarray
    tangential_spring: np.ndarray
    sliding: np.ndarray
    bonds: BondNetwork | None = None
    rolling_spring: np.ndarray | None = None
    rolling_stiffness: float = 0.0
    rolling_cap: float = 0.0
    rod_strength: np.ndarray | None = None
    attraction_partners: np.ndarray | None = None
    cap_force: str = "contact"

    def __post_init__(self) -> None:
        put = object.__setattr__
        n_s = int(self.n_spheres)
        if n_s != self.n_spheres or n_s < 1:
            raise ValueError(f"NetworkSnapshot.n_spheres = {self.n_spheres!r}: need an int >= 1")
        put(self, "n_spheres", n_s)
        scalars = ("spacing", "diameter", "disc_mass", "k_n", "k_t", "mu", "vdw_f_max", "vdw_k")
        for name in (*scalars, "rolling_stiffness", "rolling_cap"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f"NetworkSnapshot.{name} = {value!r}: need a finite value >= 0")
            put(self, name, value)
        for name in ("diameter", "disc_mass"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"NetworkSnapshot.{name} = {getattr(self, name)!r}: need > 0")
        if n_s > 1 and self.spacing <= 0.0:
            raise ValueError(f"NetworkSnapshot.spacing = {self.spacing!r}: need > 0 with n_s > 1")
        if (self.vdw_f_max > 0.0) != (self.vdw_k > 0.0):
            raise ValueError(
                f"NetworkSnapshot.vdw_f_max = {self.vdw_f_max!r}, vdw_k = {self.vdw_k!r}: "
                "both > 0 (vdW on) or both 0 (off)"
            )

        cell = _as_array("cell_lengths", self.cell_lengths, float, (2,))
        if not np.all(np.isfinite(cell)) or np.any(cell <= 0.0):
            raise ValueError(f"NetworkSnapshot.cell_lengths = {cell}: need two finite values > 0")
        put(self, "cell_lengths", cell)
        position = _as_array("rod_position", self.rod_position, float, (-1, 2))
        n_rods = position.shape[0]
        put(self, "rod_position", position)
        put(self, "rod_angle", _as_array("rod_angle", self.rod_angle, float, (n_rods,)))
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(self.rod_angle))):
            raise ValueError("NetworkSnapshot.rod_position / rod_angle: non-finite values")

        n_species = n_s if self.bonds is None else self.bonds.chain
        if self.bonds is not None and n_s != 1:
            raise ValueError(
                f"NetworkSnapshot.n_spheres = {n_s} with bonds: the bodies of bonded rods are discs"
            )
        charge = _as_array("charge", self.charge, np.int64, (n_species,))
        if not np.all(np.isin(charge, (-1, 0, 1))):
            raise ValueError(f"NetworkSnapshot.charge = {charge}: values must be in {{-1, 0, 1}}")
        put(self, "charge", charge)
        for name in ("f_max", "k_a"):
            values = _as_array(name, getattr(self, name), float, (n_species,))
            if not np.all(np.isfinite(values)) or np.any(values < 0.0):
                raise ValueError(f"NetworkSnapshot.{name} = {values}: need finite values >= 0")
            put(self, name, values)
        charged = charge != 0
        if np.any(charged & ((self.f_max > 0.0) != (self.k_a > 0.0))):
            raise ValueError(
                f"NetworkSnapshot.f_max = {self.f_max}, k_a = {self.k_a}: a charged disc needs "
                "both > 0 (range g_max = F_max/k_a) or both 0"
            )

        if self.rod_strength is not None:
            n_chains = n_rods * n_s // n_species
            strength = _as_array("rod_strength", self.rod_strength, float, (n_chains,))
            if not np.all(np.isfinite(strength)) or np.any(strength <= 0.0):
                raise ValueError("NetworkSnapshot.rod_strength: need finite values > 0")
            put(self, "rod_strength", strength)

        if self.attraction_partners is not None:
            n_chains = n_rods * n_s // n_species
            table = _as_array(
                "attraction_partners", self.attraction_partners, np.int64, (n_chains, -1)
            )
            counts = table[:, 0]
            if table.shape[1] < 1 or np.any(counts < -1) or np.any(counts > table.shape[1] - 1):
                raise ValueError(
                    "NetworkSnapshot.attraction_partners: need rows [n, partners...] with -1 <= n "
                    "< the number of columns"
                )
            put(self, "attraction_partners", table)

        if self.cap_force not in ("contact", "net"):
            raise ValueError(
                f"NetworkSnapshot.cap_force = {self.cap_force!r}: allowed 'contact' or 'net'"
            )

        pair_i = _as_array("pair_i", self.pair_i, np.int64, (-1,))
        n_pairs = pair_i.shape[0]
        pair_j = _as_array("pair_j", self.pair_j, np.int64, (n_pairs,))
        n_discs = n_rods * n_s
        for name, index in (("pair_i", pair_i), ("pair_j", pair_j)):
            if n_pairs and (index.min() < 0 or index.max() >= n_discs):
                raise ValueError(
                    f"NetworkSnapshot.{name}: disc indices must lie in [0, {n_discs}) "
                    f"(N_rods * n_spheres), got range [{index.min()}, {index.max()}]"
                )
        if np.any(pair_i // n_s == pair_j // n_s):
            bad = int(np.flatnonzero(pair_i // n_s == pair_j // n_s)[0])
            raise ValueError(
                f"NetworkSnapshot.pair_i/pair_j: pair {bad} joins two discs of the same rod "
                "(intra-rod pairs never interact and must not be listed)"
            )
        put(self, "pair_i", pair_i)
        put(self, "pair_j", pair_j)
        shift = _as_array("pair_shift", self.pair_shift, float, (n_pairs, 2))
        spring = _as_array("tangential_spring", self.tangential_spring, float, (n_pairs, 2))
        if not (np.all(np.isfinite(shift)) and np.all(np.isfinite(spring))):
            raise ValueError("NetworkSnapshot.pair_shift / tangential_spring: non-finite values")
        put(self, "pair_shift", shift)
        put(self, "tangential_spring", spring)
        put(self, "sliding", _as_array("sliding", self.sliding, bool, (n_pairs,)))
        if self.rolling_spring is not None:
            rolling = _as_array("rolling_spring", self.rolling_spring, float, (n_pairs,))
            if not np.all(np.isfinite(rolling)):
                raise ValueError("NetworkSnapshot.rolling_spring: non-finite values")
            put(self, "rolling_spring", rolling)
        if self.bonds is not None:
            bonds = self.bonds
            if bonds.g.size and bonds.g.max() + 1 >= n_rods:
                raise ValueError(f"NetworkSnapshot.bonds.g: discs beyond the {n_rods} bodies")
            lo = np.minimum(pair_i, pair_j)
            bonded = np.zeros(n_rods, dtype=bool)
            bonded[bonds.g[bonds.intact]] = True
            if np.any((np.abs(pair_i - pair_j) == 1) & bonded[lo]):
                raise ValueError(
                    "NetworkSnapshot.pair_i/pair_j: a pair of bonded neighbours with the bond "
                    "intact (they interact through the bond only) is listed"
                )

    def species(self, disc: np.ndarray) -> np.ndarray:
        """Index into ``charge``/``f_max``/``k_a`` of every global disc index (its place s in
        its rod)."""
        return np.asarray(disc) % self.charge.shape[0]

    @property
    def pair_rolling_spring(self) -> np.ndarray:
        """(P,) ψ of every pair: ``rolling_spring``, or zeros where it is None."""
        if self.rolling_spring is None:
            return np.zeros(self.n_pairs)
        return self.rolling_spring

    @property
    def n_rods(self) -> int:
        """Number of rods N."""
        return int(self.rod_position.shape[0])

    @property
    def n_pairs(self) -> int:
        """Number of listed pairs P."""
        return int(self.pair_i.shape[0])
