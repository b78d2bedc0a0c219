"""Subdivision of triangle meshes: Loop (ours, with libigl's rules and numbering) and mid-point
(libigl).

Both split every triangle into four per level: a mesh with ``n`` vertices, ``e`` edges and ``m``
faces becomes one with ``n + e`` vertices and ``4 m`` faces. The input must be edge-manifold
(every edge touches one or two faces); libigl's routines assume it and may misbehave otherwise,
so this is checked first and reported as :class:`~algorithms.errors.InvalidMeshError`.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from .topology import _EdgeData

__all__ = ["loop_subdivide", "loop_matrix", "midpoint_subdivide"]

#: Refuse to produce more faces than this (memory guard: 4**levels growth).
MAX_FACES = 20_000_000


def _prepare(V, F, levels, what: str) -> tuple[np.ndarray, np.ndarray, int]:
    try:
        lv = int(levels)
        if lv != levels:
            raise ValueError
    except (TypeError, ValueError):
        raise ParameterError(
            f"The number of {what} levels must be a whole number, not {levels!r}."
        ) from None
    if lv < 0:
        raise ParameterError(f"The number of {what} levels must be 0 or more, got {lv}.")
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InvalidMeshError(
            f"{what.capitalize()} needs V of shape (n, 3) and F of shape (m, 3); "
            f"got {V.shape} and {F.shape}."
        )
    if F.shape[0] == 0:
        raise InvalidMeshError(f"The mesh has no faces, so there is nothing to {what}.")
    if F.min() < 0 or F.max() >= V.shape[0]:
        raise InvalidMeshError(
            "Some faces refer to vertices that do not exist. Validate and clean the mesh first."
        )
    if not np.isfinite(V).all():
        raise InvalidMeshError(
            "Some vertices have NaN or infinite coordinates. Validate and clean the mesh first."
        )
    if ((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])).any():
        raise InvalidMeshError(
            "Some triangles use the same vertex twice. 'Clean' can remove them."
        )
    d = _EdgeData(F)
    if d.counts.max() > 2:
        raise InvalidMeshError(
            f"{int((d.counts > 2).sum())} edges are shared by more than two triangles "
            "(non-manifold), so the mesh cannot be subdivided. 'Clean' can remove the extra "
            "triangles."
        )
    if F.shape[0] * 4**lv > MAX_FACES:
        raise ParameterError(
            f"{lv} levels would create {F.shape[0] * 4**lv:,} triangles, more than the limit of "
            f"{MAX_FACES:,}. Use fewer levels."
        )
    return V, F, lv


def loop_subdivide(V, F, levels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Loop subdivision (smooth; vertices move): the rules and numbering of ``igl.loop``,
    computed here (:func:`loop_matrix`) so that any edge-manifold mesh, oriented or not, is safe.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
        Edge-manifold triangles.
    levels : int
        Number of subdivision steps (0 returns copies).

    Returns
    -------
    V_sub : (n_k, 3) float64 array
        The original vertices come first (moved by the Loop rules), then one new vertex per edge,
        per level. One level gives ``n + e`` vertices.
    F_sub : (m * 4**levels, 3) int64 array
    """
    V, F, lv = _prepare(V, F, levels, "subdivision")
    if lv == 0:
        return V.copy(), F.copy()
    for _ in range(lv):
        S, F = loop_matrix(F, len(V))
        V = np.ascontiguousarray(S @ V)
    return V, F


def loop_matrix(F: np.ndarray, n: int):
    """One level of Loop subdivision as a sparse matrix: ``(S, F_sub)`` with ``V_sub = S @ V``.

    The rules of libigl's ``igl::loop`` (Loop 1987 with Warren's weights), and its numbering,
    so the result is the same bits as ``igl.loop`` on the meshes it handles
    (tests/algorithms/test_subdivision.py): new edge vertices are numbered in the order their
    edges first appear (face by face, edges 01, 12, 20) after the ``n`` old ones, and face
    ``f = (a, b, c)`` with edge vertices ``ab, bc, ca`` becomes ``[a, ab, ca], [b, bc, ab],
    [ab, bc, ca], [bc, c, ca]``.

    * an edge vertex: 3/8 of each end + 1/8 of each opposite corner; 1/2 of each end on a
      boundary edge;
    * an old interior vertex of valence k: ``1 - k * beta`` of itself + ``beta`` of each
      neighbour, ``beta = 3/16`` for k = 3 and ``3 / (8 k)`` otherwise;
    * an old boundary vertex: 3/4 of itself + 1/8 of each of its two boundary neighbours; a
      vertex where more than two boundary edges meet (two sheets touching) stays where it is.

    Built from undirected edges only, so it works on any edge-manifold mesh whatever the
    orientation of its triangles: ``igl.loop`` corrupted memory and aborted the process
    ("double free or corruption") on a Moebius strip, the input the app advises Loop for.
    """
    import scipy.sparse as sp

    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    opp = F[:, [2, 0, 1]].reshape(-1)  # the corner opposite each (face, edge)
    key = np.minimum(a, b) * n + np.maximum(a, b)
    uniq, first, inv, cnt = np.unique(key, return_index=True, return_inverse=True,
                                      return_counts=True)
    order = np.argsort(first, kind="stable")  # edges numbered by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    uniq, cnt, inv = uniq[order], cnt[order], rank[inv.reshape(-1)]
    E = np.stack(divmod(uniq, n), axis=1)
    ne = len(E)
    boundary = cnt == 1
    # edge vertices
    ei = np.arange(ne)
    w_end = np.where(boundary, 0.5, 3.0 / 8.0)
    inner = ~boundary[inv]
    rows = [ei, ei, inv[inner]]
    cols = [E[:, 0], E[:, 1], opp[inner]]
    vals = [w_end, w_end, np.full(int(inner.sum()), 1.0 / 8.0)]
    S_odd = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(ne, n))
    # old vertices
    deg = np.bincount(E.ravel(), minlength=n)
    bdeg = np.bincount(E[boundary].ravel(), minlength=n)
    beta = np.where(deg == 3, 3.0 / 16.0, 3.0 / (8.0 * np.maximum(deg, 1)))
    on_b = bdeg > 0
    corner = on_b & (bdeg != 2)
    centre = np.where(corner, 1.0, np.where(on_b, 0.75, 1.0 - deg * beta))
    rows, cols, vals = [np.arange(n)], [np.arange(n)], [centre]
    for s, t in ((0, 1), (1, 0)):
        i, j = E[:, s], E[:, t]
        k = ~on_b[i]
        rows += [i[k]]
        cols += [j[k]]
        vals += [beta[i[k]]]
        k = on_b[i] & ~corner[i] & boundary
        rows += [i[k]]
        cols += [j[k]]
        vals += [np.full(int(k.sum()), 1.0 / 8.0)]
    S_even = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(n, n))
    e = (n + inv).reshape(m, 3)  # the edge vertices of edges 01, 12, 20 of each face
    F_sub = np.stack([np.stack([F[:, 0], e[:, 0], e[:, 2]], 1),
                      np.stack([F[:, 1], e[:, 1], e[:, 0]], 1),
                      np.stack([e[:, 0], e[:, 1], e[:, 2]], 1),
                      np.stack([e[:, 1], F[:, 2], e[:, 2]], 1)], axis=1).reshape(-1, 3)
    return sp.vstack([S_even, S_odd]).tocsr(), np.ascontiguousarray(F_sub)


def midpoint_subdivide(V, F, levels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Mid-point (linear) subdivision: the shape does not change, via ``igl.upsample``.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
        Edge-manifold triangles.
    levels : int
        Number of subdivision steps (0 returns copies).

    Returns
    -------
    V_sub : (n_k, 3) float64 array
        ``V`` unchanged, followed by the edge mid-points, per level (``n + e`` after one level).
    F_sub : (m * 4**levels, 3) int64 array
    """
    V, F, lv = _prepare(V, F, levels, "subdivision")
    if lv == 0:
        return V.copy(), F.copy()
    import igl

    NV, NF = igl.upsample(V, F, lv)
    return np.ascontiguousarray(NV, dtype=np.float64), np.ascontiguousarray(NF, dtype=np.int64)
