"""Attraction partners: the rods a gel's bonds join at state A (numpy only, no Taichi).

``[long_range] attraction_pairs = "bonded_at_A"`` (a modelling option of ours; the study's law is
reversible, docs/science/dem-model.md §1.2): once state A is reached, a pair of discs of
opposite charge attracts only if its two rods attracted each other at A (at least one pair of
their discs of opposite charge within the range g_max). Repulsion is unchanged.

The partners are kept as a table of one row per rod: ``[n, partner rods 1..n, unused]``, with
n = -1 for a rod whose partners are not set (before A: every pair attracts). The engine holds
it as the device array ``attraction_partners`` (:mod:`dem_taichi.engine.device_arrays`, with the
number of columns of :mod:`dem_taichi.kernels.layout`), the kernels read it in
``pairs.pair_interaction`` and the numpy force law in
:func:`dem_taichi.physics.forcelaw.pair_parameters`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NOT_SET", "are_partners", "partner_pairs", "partner_table", "unset_table"]

#: the partner count of a rod whose partners are not set (every pair attracts)
NOT_SET = -1


def unset_table(n_rows: int, columns: int) -> np.ndarray:
    """A table of ``n_rows`` rods whose partners are not set: (n_rows, columns) of -1, int32."""
    return np.full((n_rows, columns), NOT_SET, dtype=np.int32)


def partner_table(rod_pairs: np.ndarray, n_rods: int, columns: int) -> np.ndarray:
    """The partner table of ``n_rods`` rods joined by ``rod_pairs`` ((P, 2) rod indices, each
    unordered pair once or more, a != b): row r = [n_r, its partners in increasing order, -1 ...].

    Raises ValueError when a rod has more than ``columns`` - 1 partners (say which, and how
    many)."""
    pairs = np.asarray(rod_pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n_rods):
        raise ValueError(f"rod_pairs: rod indices must lie in [0, {n_rods})")
    if np.any(pairs[:, 0] == pairs[:, 1]):
        raise ValueError("rod_pairs: a rod cannot be its own partner")
    both = np.unique(np.concatenate([pairs, pairs[:, ::-1]]), axis=0)
    counts = np.bincount(both[:, 0], minlength=n_rods)
    capacity = columns - 1
    if counts.size and counts.max() > capacity:
        rod = int(np.argmax(counts))
        raise ValueError(
            f"rod {rod} attracts {int(counts[rod])} rods at state A, more than the "
            f"{capacity} a rod can keep ([long_range] attraction_pairs = 'bonded_at_A')"
        )
    table = np.full((n_rods, columns), NOT_SET, dtype=np.int32)
    table[:, 0] = counts
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    place = np.arange(len(both)) - start[both[:, 0]]
    table[both[:, 0], 1 + place] = both[:, 1]
    return table


def are_partners(table: np.ndarray, rod_a: np.ndarray, rod_b: np.ndarray) -> np.ndarray:
    """Whether each pair of rods (``rod_a``, ``rod_b``) may attract under ``table``: True where
    rod a's partners are not set, else whether b is among them (as the kernel reads it)."""
    table = np.asarray(table)
    rod_a, rod_b = np.asarray(rod_a, dtype=np.int64), np.asarray(rod_b, dtype=np.int64)
    counts = table[rod_a, 0]
    columns = np.arange(1, table.shape[1])
    listed = (table[rod_a][:, 1:] == rod_b[:, None]) & (columns[None, :] <= counts[:, None])
    return (counts < 0) | listed.any(axis=1)


def partner_pairs(table: np.ndarray) -> np.ndarray:
    """The rod pairs (a, b), a < b, once each, that ``table`` joins: the inverse of
    :func:`partner_table` on the rows that are set, (P, 2) int."""
    table = np.asarray(table)
    counts = np.maximum(table[:, 0], 0)
    rows = np.repeat(np.arange(table.shape[0]), counts)
    place = np.arange(len(rows)) - np.repeat(np.cumsum(counts) - counts, counts)
    pairs = np.stack([rows, table[rows, 1 + place]], axis=1).astype(np.int64)
    return np.unique(np.sort(pairs, axis=1), axis=0).reshape(-1, 2)
