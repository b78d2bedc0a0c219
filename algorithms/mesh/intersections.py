"""Self-intersections of a triangle mesh (libigl's exact predicates): the one implementation
that Paparazzi's remeshing, the subdivision guard and the command lines' reports use.

libigl keeps Python's lock for the whole test (36 ms on a 14.6k-vertex mesh, 3.3 s on 1.6M
triangles): :func:`intersecting_pairs` runs it in the desktop app's helper process
(:mod:`algorithms.offload`), :func:`intersecting_pairs_here` in this one.
"""

from __future__ import annotations

import numpy as np

from .. import offload

__all__ = ["count_self_intersections", "crossings_away_from", "crossings_not_in_parents",
           "intersecting_pairs", "intersecting_pairs_here", "new_crossing_pairs",
           "new_crossings_away_from"]


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


def new_crossings_away_from(pairs: np.ndarray, F, known_pairs: np.ndarray,
                            rings: int = 2) -> np.ndarray:
    """The intersecting face pairs of a deformed mesh with the triangles ``F`` (``pairs``) that
    are new crossings away from the crossings the mesh already had (``known_pairs``, of the
    same triangles before the deformation), as a (k, 2) array (each pair sorted).

    A pair counts unless it is one of ``known_pairs`` or both its faces lie within ``rings``
    vertex rings of faces that crossed before: where two sheets already passed through each
    other, any move shifts the crossing line onto neighbouring triangles, which is not a
    crossing the deformation made.
    """
    pairs = np.sort(np.asarray(pairs, np.int64).reshape(-1, 2), axis=1)
    known = np.sort(np.asarray(known_pairs, np.int64).reshape(-1, 2), axis=1)
    if not len(pairs) or not len(known):
        return pairs
    from .topology import vertex_face_adjacency

    F = np.asarray(F, np.int64)
    m = len(F)
    base = m + 1
    fresh = pairs[~np.isin(pairs[:, 0] * base + pairs[:, 1], known[:, 0] * base + known[:, 1])]
    VF = vertex_face_adjacency(F).tocsr()
    near = np.zeros(m, bool)
    near[known.ravel()] = True
    for _ in range(int(rings)):
        verts = np.unique(F[near].ravel())
        near[VF[verts].indices] = True
    return fresh[~(near[fresh[:, 0]] & near[fresh[:, 1]])]


def pairs_not_in(pairs: np.ndarray, known: np.ndarray) -> np.ndarray:
    """The rows of ``pairs`` (face index pairs, either order) that are not rows of ``known``."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    known = np.sort(np.asarray(known, np.int64).reshape(-1, 2), axis=1)
    if not len(pairs) or not len(known):
        return pairs
    p = np.sort(pairs, axis=1)
    base = int(max(p.max(), known.max())) + 1
    return pairs[~np.isin(p[:, 0] * base + p[:, 1], known[:, 0] * base + known[:, 1])]


def new_crossing_pairs_away(pairs: np.ndarray, levels: int, F0, parent_pairs: np.ndarray,
                            rings: int = 2) -> np.ndarray:
    """The intersecting face pairs of a mesh subdivided ``levels`` times from ``F0`` (children
    numbered as in :func:`new_crossing_pairs`) that are new away from the input's own crossings:
    :func:`new_crossings_away_from` applied to their parent pairs (a pair counts unless its
    parents crossed, or both parents lie within ``rings`` vertex rings of triangles that
    crossed: smoothing two sheets that already pass through each other moves their crossing
    line onto the neighbouring triangles' children)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if not len(pairs):
        return pairs
    par = np.sort(pairs // 4 ** int(levels), axis=1)
    keep = new_crossings_away_from(par, F0, parent_pairs, rings)
    base = len(F0) + 1
    return pairs[np.isin(par[:, 0] * base + par[:, 1], keep[:, 0] * base + keep[:, 1])]


def crossings_away_from(pairs: np.ndarray, F, known_pairs: np.ndarray, rings: int = 2) -> int:
    """How many of ``pairs`` are new crossings away from ``known_pairs``
    (:func:`new_crossings_away_from`)."""
    return int(len(new_crossings_away_from(pairs, F, known_pairs, rings)))
