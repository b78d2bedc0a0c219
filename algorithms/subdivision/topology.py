"""Loop-topology refinement with edge ids, barycentric tracking and half-flaps (thesis §4.3-4.5).

Neural subdivision needs more than the positions libigl's ``upsample`` returns: which new vertex
sits on which edge (the EDGE step writes there), the half-flaps of every level (the operators'
input), and, for training data, where every vertex of every level lies on the coarse mesh
(``g`` of §4.3: a coarse face and barycentric coordinates). :func:`refine` does one 1-to-4 split
in the same way as :func:`algorithms.mesh.subdivision.midpoint_subdivide` (same vertex set, same
faces; tested against it), numbering the new vertex of edge ``e`` as ``n + e`` with the edges of
:func:`unique_edge_ids`.

Half-flap of the half-edge ``h = 3 f + c`` (corner ``c`` of face ``f``, from ``i = F[f, c]`` to
``j = F[f, c+1]``): the four vertices ``(i, j, k, l)``, ``k`` the third corner of ``f`` and ``l``
the third corner of the face across the edge. On a boundary edge there is no ``l``; the flap
is completed by mirroring ``k`` (rotating it by pi about the edge), a choice of ours (the thesis'
code handled closed meshes only) -- so boundary flaps look like symmetric interior flaps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["HalfFlaps", "half_flaps", "unique_edge_ids", "refine", "refine_barycentric",
           "locate_vertices", "igl_odd_order", "split_vertex_order"]


def unique_edge_ids(F: np.ndarray, n: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Undirected edges and the edge of every corner.

    Returns
    -------
    E : (e, 2) int64 edges (smaller id first), sorted.
    EF : (m, 3) int64, ``EF[f, c]`` is the edge (F[f, c], F[f, c+1]).
    """
    F = np.asarray(F, dtype=np.int64)
    n = int(F.max()) + 1 if n is None else int(n)
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    uk, inv = np.unique(key, return_inverse=True)
    E = np.stack([uk // n, uk % n], axis=1)
    return E, inv.reshape(-1, 3).astype(np.int64)


@dataclass
class HalfFlaps:
    """Index arrays of the half-flaps of one mesh (``H = 3 m`` half-edges).

    Attributes
    ----------
    n : number of vertices; F : (m, 3) int64.
    E : (e, 2) int64 undirected edges; EF : (m, 3) edge of every corner.
    ijkl : (H, 4) int64 flap vertices; ``ijkl[:, 3]`` is ``-1`` on boundary edges.
    twin_face : (H,) int64 face across the edge or -1.
    face : (H,) int64 face of the half-edge; edge : (H,) int64 its undirected edge.
    neighbours : (2 e', 2) int64 directed vertex pairs (both directions of every edge), for the
        uniform Laplacian; degree : (n,) float64.
    """

    n: int
    F: np.ndarray
    E: np.ndarray
    EF: np.ndarray
    ijkl: np.ndarray
    twin_face: np.ndarray
    face: np.ndarray
    edge: np.ndarray
    neighbours: np.ndarray
    degree: np.ndarray

    @property
    def boundary(self) -> np.ndarray:
        """(H,) bool: half-edges on the mesh boundary."""
        return self.twin_face < 0


def half_flaps(F: np.ndarray, n: int) -> HalfFlaps:
    """The half-flaps of a manifold, consistently oriented triangle mesh (see the module doc)."""
    F = np.ascontiguousarray(F, dtype=np.int64)
    m = len(F)
    E, EF = unique_edge_ids(F, n)
    src = F.reshape(-1)
    dst = F[:, [1, 2, 0]].reshape(-1)
    opp = F[:, [2, 0, 1]].reshape(-1)
    key = src * n + dst
    twin_key = dst * n + src
    order = np.argsort(key)
    sk = key[order]
    pos = np.minimum(np.searchsorted(sk, twin_key), len(sk) - 1)
    found = sk[pos] == twin_key
    twin = np.where(found, order[pos], -1)
    face = np.repeat(np.arange(m, dtype=np.int64), 3)
    twin_face = np.where(found, twin // 3, -1)
    l = np.where(found, opp[np.maximum(twin, 0)], -1)
    ijkl = np.stack([src, dst, opp, l], axis=1)
    nb = np.concatenate([E, E[:, ::-1]])
    degree = np.bincount(nb[:, 0], minlength=n).astype(np.float64)
    return HalfFlaps(n=int(n), F=F, E=E, EF=EF, ijkl=ijkl, twin_face=twin_face, face=face,
                     edge=EF.reshape(-1), neighbours=nb, degree=degree)


def refine(F: np.ndarray, n: int, EF: np.ndarray | None = None) -> np.ndarray:
    """One 1-to-4 split: the new vertex of edge ``e`` is ``n + e``.

    Face ``f = (a, b, c)`` with mid-points ``ab, bc, ca`` becomes faces ``4 f + 0..3``:
    ``(a, ab, ca)``, ``(ab, b, bc)``, ``(ca, bc, c)``, ``(ab, bc, ca)`` (orientation kept).

    Returns
    -------
    F_new : (4 m, 3) int64.
    """
    F = np.asarray(F, dtype=np.int64)
    if EF is None:
        _, EF = unique_edge_ids(F, n)
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    ab, bc, ca = n + EF[:, 0], n + EF[:, 1], n + EF[:, 2]
    return np.stack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1),
                     np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)], axis=1).reshape(-1, 3)


def refine_barycentric(parent: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Carry, through :func:`refine`, each face's coarse face and its corners' coordinates there.

    Parameters
    ----------
    parent : (m,) int64 coarse face of every face.
    corners : (m, 3, 3) float64, barycentric coordinates (in ``parent``) of every face's corners.

    Returns
    -------
    parent (4 m,), corners (4 m, 3, 3) of the refined faces (ordered as :func:`refine`).
    """
    A, B, C = corners[:, 0], corners[:, 1], corners[:, 2]
    AB, BC, CA = 0.5 * (A + B), 0.5 * (B + C), 0.5 * (C + A)
    kids = np.stack([np.stack([A, AB, CA], 1), np.stack([AB, B, BC], 1),
                     np.stack([CA, BC, C], 1), np.stack([AB, BC, CA], 1)], axis=1)
    return np.repeat(parent, 4), kids.reshape(-1, 3, 3)


def locate_vertices(F: np.ndarray, n: int, parent: np.ndarray,
                    corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(coarse face, barycentric coordinates) of every vertex, read at its first face corner."""
    flat = F.reshape(-1)
    first = np.full(n, -1, dtype=np.int64)
    idx = np.arange(flat.size)[::-1]
    first[flat[idx]] = idx
    if (first < 0).any():
        raise ValueError("some vertices are not used by any face")
    return parent[first // 3], corners.reshape(-1, 3)[first]


def igl_odd_order(F: np.ndarray, n: int, E: np.ndarray) -> np.ndarray:
    """Where libigl's one-level ``upsample``/``loop`` put each of our edge vertices.

    Returns ``perm`` (e,) such that libigl's vertex ``n + perm[e]`` is our vertex ``n + e``.
    Found exactly by upsampling the integer coordinates ``(v, v^2, 0)``: a new vertex at
    ``((a + b) / 2, (a^2 + b^2) / 2)`` identifies the pair {a, b}.
    """
    import igl

    v = np.arange(n, dtype=np.float64)
    P = np.stack([v, v * v, np.zeros(n)], axis=1)
    NV, _ = igl.upsample(P, np.asarray(F, dtype=np.int64), 1)
    s = np.rint(2 * NV[n:, 0]).astype(np.int64)
    q = np.rint(2 * NV[n:, 1]).astype(np.int64)
    d = np.rint(np.sqrt(np.maximum(2 * q - s * s, 0))).astype(np.int64)
    a, b = (s - d) // 2, (s + d) // 2
    key_igl = a * n + b
    key_ours = E[:, 0] * n + E[:, 1]
    order = np.argsort(key_igl)
    pos = np.searchsorted(key_igl[order], key_ours)
    perm = order[np.minimum(pos, len(order) - 1)]
    if not np.array_equal(key_igl[perm], key_ours):
        raise RuntimeError("libigl's edge vertices do not match the mesh's edges")
    return perm


def _new_vertex_of_edges(F_fine: np.ndarray, n: int, E: np.ndarray) -> np.ndarray:
    """Index, in a 1-to-4 split ``F_fine`` (any vertex order with the ``n`` old vertices
    first) of a mesh, of the new vertex of each edge ``E`` -- read off the corner triangles
    (one old vertex, two new ones: each new one is on an edge from that old vertex)."""
    F_fine = np.asarray(F_fine, dtype=np.int64)
    corner = F_fine[(F_fine < n).sum(axis=1) == 1]
    old = np.where(corner < n, corner, -1).max(axis=1)
    ends: dict = {}
    for f, a in zip(corner.tolist(), old.tolist()):
        for v in f:
            if v >= n:
                ends.setdefault(v, set()).add(a)
    index = {tuple(sorted(s)): v for v, s in ends.items() if len(s) == 2}
    try:
        return np.array([index[(int(a), int(b))] for a, b in E], dtype=np.int64)
    except KeyError:
        raise ValueError("the fine mesh is not a 1-to-4 split of the coarse one") from None


def split_vertex_order(F0: np.ndarray, n0: int, fine_faces: list) -> np.ndarray:
    """For every vertex of ``len(fine_faces)`` levels of :func:`refine` of ``(F0, n0)``, its
    index in another program's levels of the same splits (``fine_faces[l]``: its faces of
    level ``l + 1``, old vertices first at every level, new ones in any order), e.g. the thesis
    author's outputs or ground truth. Returns ``order`` with ``ours[v] == theirs[order[v]]``."""
    F = np.asarray(F0, dtype=np.int64)
    n = int(n0)
    perm = np.arange(n)
    for Ff in fine_faces:
        E, EF = unique_edge_ids(F, n)
        perm = np.r_[perm, _new_vertex_of_edges(Ff, len(perm), np.sort(perm[E], axis=1))]
        F = refine(F, n, EF)
        n = len(perm)
    return perm
