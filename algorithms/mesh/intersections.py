"""Self-intersections of a triangle mesh (libigl's exact predicates): the one implementation
that Paparazzi's remeshing, the subdivision guard and the command lines' reports use.

libigl keeps Python's lock for the whole test (36 ms on a 14.6k-vertex mesh, 3.3 s on 1.6M
triangles): :func:`intersecting_pairs` runs it in the desktop app's helper process
(:mod:`algorithms.offload`), :func:`intersecting_pairs_here` in this one.
"""

from __future__ import annotations

import numpy as np

from .. import offload

__all__ = ["count_self_intersections", "intersecting_pairs", "intersecting_pairs_here",
           "crossings_not_in_parents", "new_crossing_pairs"]


def intersecting_pairs_here(V, F) -> np.ndarray:
    """(k, 2) int64 intersecting face pairs (neighbours that only share a vertex or an edge do
    not count), computed in this process."""
    import igl.predicates

    found, IF, _ = igl.predicates.find_self_intersections(
        np.ascontiguousarray(V, dtype=np.float64), np.ascontiguousarray(F, dtype=np.int64), False)
    return np.asarray(IF, np.int64).reshape(-1, 2) if found else np.zeros((0, 2), np.int64)


def intersecting_pairs(V, F) -> np.ndarray:
    """:func:`intersecting_pairs_here`, in the desktop app's helper process (the same bits)."""
    return offload.call(intersecting_pairs_here, np.ascontiguousarray(V, np.float64),
                        np.ascontiguousarray(F, np.int64))


def count_self_intersections(V, F) -> int:
    """Number of intersecting face pairs (libigl, exact predicates), in this process."""
    return int(len(intersecting_pairs_here(V, F)))


def new_crossing_pairs(pairs: np.ndarray, levels: int, parent_pairs: np.ndarray) -> np.ndarray:
    """The intersecting face pairs of a mesh subdivided ``levels`` times (children of face ``f``
    numbered ``4 f .. 4 f + 3`` at each level, as Loop, the network and butterfly number them)
    that are not inherited: their two parent faces of the unsubdivided mesh were not an
    intersecting pair there (``parent_pairs``)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if not len(pairs):
        return pairs
    par = np.sort(pairs // 4 ** int(levels), axis=1)
    known = np.sort(np.asarray(parent_pairs, np.int64).reshape(-1, 2), axis=1)
    if not len(known):
        return pairs
    base = int(max(par.max(), known.max())) + 1
    return pairs[~np.isin(par[:, 0] * base + par[:, 1], known[:, 0] * base + known[:, 1])]


def crossings_not_in_parents(pairs: np.ndarray, levels: int, parent_pairs: np.ndarray) -> int:
    """How many of ``pairs`` are new (:func:`new_crossing_pairs`)."""
    return int(len(new_crossing_pairs(pairs, levels, parent_pairs)))
