"""Self-intersections of a triangle mesh (libigl's exact predicates): the one implementation
that Paparazzi's remeshing, the subdivision guard and the command lines' reports use.

libigl keeps Python's lock for the whole test (36 ms on a 14.6k-vertex mesh, 3.3 s on 1.6M
triangles): :func:`intersecting_pairs` runs it in the desktop app's helper process
(:mod:`algorithms.offload`), :func:`intersecting_pairs_here` in this one.
"""

from __future__ import annotations

import numpy as np

from .. import offload
from ..compiled import KernelModule

_KERNELS = KernelModule("algorithms.mesh.intersection_kernels")

__all__ = ["count_self_intersections", "crossings_away_from", "crossings_not_in_parents",
           "intersecting_pairs", "intersecting_pairs_here", "intersecting_pairs_touching",
           "intersecting_pairs_touching_here", "new_crossing_pairs",
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


def _aabb_neighbours(V, F, faces: np.ndarray) -> np.ndarray:
    """(m,) bool: ``faces`` and every triangle whose bounding box may overlap the bounding box
    of one of them (a superset). The boxes are binned on a grid of cells twice the 90th
    percentile of the boxes' sizes: a box no larger than a cell covers at most 2 cells along
    each axis (its corner cells), so two overlapping boxes share a covered cell; the few
    larger boxes are always kept, and those among ``faces`` cover every cell in their range."""
    kern = _KERNELS.get() if len(F) else None
    if kern is not None:
        V = np.ascontiguousarray(V, dtype=np.float64)
        F = np.ascontiguousarray(F, dtype=np.int64)
        lo, hi, ext = np.empty((len(F), 3)), np.empty((len(F), 3)), np.empty(len(F))
        kern.face_boxes(V, F, lo, hi, ext)
    else:
        T = V[F]
        lo, hi = T.min(axis=1), T.max(axis=1)
        ext = (hi - lo).max(axis=1)
    size = 2.0 * float(np.quantile(ext, 0.9))
    origin = lo.min(axis=0)
    span = (hi.max(axis=0) - origin) / size if size > 0 else np.full(3, np.inf)
    if not np.isfinite(span).all() or float(np.prod(span + 2.0)) > 2.0 ** 60:
        return np.ones(len(F), dtype=bool)   # flat boxes or cell keys past int64: look at all
    big = ext > size / 1.01
    if kern is not None:
        status, near = kern.near_cells(lo, hi, np.ascontiguousarray(origin), size, big,
                                       np.ascontiguousarray(faces, dtype=np.bool_), 1 << 24,
                                       4 * len(F))
        if status == 0:
            return near
        if status == 2:                  # huge query boxes: the whole mesh is as cheap
            return np.ones(len(F), dtype=bool)
    clo = np.floor((lo - origin) / size).astype(np.int64)
    chi = np.floor((hi - origin) / size).astype(np.int64)
    dims = chi.max(axis=0) + 2

    def key(c0, c1, c2):
        return (c0 * dims[1] + c1) * dims[2] + c2

    keys = np.empty((8, len(F)), np.int64)
    for b in range(8):
        c = [np.where((b >> a) & 1, chi[:, a], clo[:, a]) for a in range(3)]
        keys[b] = key(*c)
    cells = [keys[:, faces & ~big].ravel()]
    count = 0
    for f in np.flatnonzero(faces & big):
        r = [np.arange(clo[f, a], chi[f, a] + 1) for a in range(3)]
        count += len(r[0]) * len(r[1]) * len(r[2])
        if count > 4 * len(F):          # huge query boxes: the whole mesh is as cheap
            return np.ones(len(F), dtype=bool)
        g = np.meshgrid(*r, indexing="ij")
        cells.append(key(*(x.ravel() for x in g)))
    marked = np.concatenate(cells)
    near = big | faces
    if not len(marked):
        return near
    if int(np.prod(dims)) <= 1 << 24:       # a table of the cells (at most 16 MB)
        table = np.zeros(int(np.prod(dims)), dtype=bool)
        table[marked] = True
        return near | table[keys].any(axis=0)
    marked = np.unique(marked)
    pos = np.minimum(np.searchsorted(marked, keys), len(marked) - 1)
    return near | (marked[pos] == keys).any(axis=0)


def intersecting_pairs_touching_here(V, F, faces) -> np.ndarray:
    """The pairs of :func:`intersecting_pairs_here` with at least one face among ``faces``
    (indices or an (m,) bool mask), the same pairs, found on those triangles and the ones whose
    bounding boxes may overlap theirs only (libigl's test on that part of the mesh: the same
    vertex indices, so neighbours are told apart as on the whole mesh)."""
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    mask = np.zeros(len(F), dtype=bool)
    mask[faces] = True
    if not mask.any():
        return np.zeros((0, 2), np.int64)
    part = np.flatnonzero(_aabb_neighbours(V, F, mask))
    IF = part[intersecting_pairs_here(V, F[part])]
    return IF[mask[IF].any(axis=1)] if len(IF) else IF


def intersecting_pairs_touching(V, F, faces) -> np.ndarray:
    """:func:`intersecting_pairs_touching_here`, in the desktop app's helper process."""
    return offload.call(intersecting_pairs_touching_here, np.ascontiguousarray(V, np.float64),
                        np.ascontiguousarray(F, np.int64), np.asarray(faces))


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
