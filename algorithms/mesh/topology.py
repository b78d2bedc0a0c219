"""Combinatorial structure of triangle meshes: edges, flaps, half-edges, adjacency, boundary.

Everything here looks only at the faces ``F`` (``(m, 3) int64``), never at positions, and is
vectorized with NumPy / SciPy (no Python loop over faces or vertices).

Half-edge numbering (the same as libigl's ``unique_edge_map`` / ``edge_flaps``)
-----------------------------------------------------------------------------
A mesh with ``m`` faces has ``3m`` half-edges. Half-edge ``h = c * m + f`` belongs to face ``f``
and lies *opposite* corner ``c``; it runs from ``F[f, (c + 1) % 3]`` to ``F[f, (c + 2) % 3]``.
The next half-edge inside the same face is ``((c + 1) % 3) * m + f``. :func:`halfedges` returns
the ``(3m, 2)`` array of directed half-edges in this order.

Unique edges are rows ``E[e] = (i, j)`` with ``i < j``, sorted lexicographically.

Manifoldness
------------
*Edge-manifold*: every edge touches one or two faces. *Vertex-manifold*: the faces around every
vertex form a single fan (one disk or half-disk). Functions that need a manifold mesh say so and
raise :class:`~algorithms.errors.InvalidMeshError` with a plain-language message otherwise.
"""

from __future__ import annotations

import numpy as np
from .components import connected_components as _cc

from ..errors import InvalidMeshError

__all__ = [
    "touching_parts",
    "halfedges",
    "unique_edges",
    "edge_flaps",
    "halfedge_twins",
    "vertex_adjacency",
    "vertex_face_adjacency",
    "face_adjacency",
    "boundary_edges",
    "boundary_loops",
    "connected_components",
    "nonmanifold_edges",
    "nonmanifold_vertices",
    "is_edge_manifold",
    "is_vertex_manifold",
    "is_manifold",
    "euler_characteristic",
    "genus",
    "orient_consistently",
    "referenced_vertices",
]


# --------------------------------------------------------------------------------------------
# input checking and small internals
# --------------------------------------------------------------------------------------------


def _faces(F) -> np.ndarray:
    """Return F as a C-contiguous (m, 3) int64 array; raise InvalidMeshError if impossible."""
    arr = np.asarray(F)
    if arr.ndim != 2 or arr.shape[1] != 3:
        if arr.size == 0:
            return np.zeros((0, 3), dtype=np.int64)
        raise InvalidMeshError(
            f"Faces must be an (m, 3) array of triangle corner indices, got shape {arr.shape}."
        )
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise InvalidMeshError("Face indices must be whole numbers.")
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if arr.size and arr.min() < 0:
        raise InvalidMeshError(
            "Some faces use negative vertex indices. Validate the mesh to see which ones."
        )
    return arr


def _n_vertices(F: np.ndarray, n: int | None) -> int:
    need = int(F.max()) + 1 if F.size else 0
    if n is None:
        return need
    n = int(n)
    if n < need:
        raise InvalidMeshError(
            f"Faces refer to vertex {need - 1}, but the mesh has only {n} vertices."
        )
    return n


def _unique_keys(key: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Like np.unique(key, return_index, return_inverse, return_counts) with one stable argsort.

    Returns (order, first, inverse, counts): ``order`` sorts ``key``; ``first[u]`` is the first
    (smallest) position of unique value ``u``.
    """
    order = np.argsort(key, kind="stable")
    sk = key[order]
    if sk.size == 0:
        z = np.zeros(0, dtype=np.int64)
        return order, z, z, z
    flag = np.empty(sk.size, dtype=bool)
    flag[0] = True
    np.not_equal(sk[1:], sk[:-1], out=flag[1:])
    group = np.cumsum(flag) - 1
    inverse = np.empty(sk.size, dtype=np.int64)
    inverse[order] = group
    starts = np.flatnonzero(flag)
    first = order[starts]
    counts = np.diff(np.append(starts, sk.size))
    return order, first, inverse, counts


def halfedges(F) -> np.ndarray:
    """Directed half-edges in libigl order.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.

    Returns
    -------
    H : (3m, 2) int64 array
        ``H[c * m + f] = (F[f, (c+1)%3], F[f, (c+2)%3])``, the half-edge of face ``f`` opposite
        corner ``c``.
    """
    F = _faces(F)
    return np.concatenate([F[:, [1, 2]], F[:, [2, 0]], F[:, [0, 1]]], axis=0)


class _EdgeData:
    """Internal bundle of unique-edge data computed once and reused."""

    __slots__ = ("F", "m", "H", "E", "EMAP", "counts", "order", "fwd", "first")

    def __init__(self, F: np.ndarray):
        self.F = F
        self.m = F.shape[0]
        self.H = np.concatenate([F[:, [1, 2]], F[:, [2, 0]], F[:, [0, 1]]], axis=0)
        lo = np.minimum(self.H[:, 0], self.H[:, 1])
        hi = np.maximum(self.H[:, 0], self.H[:, 1])
        n = int(hi.max()) + 1 if hi.size else 1
        key = lo * n + hi
        self.order, first, self.EMAP, self.counts = _unique_keys(key)
        self.first = first  # first half-edge of every unique edge
        self.E = np.stack([lo[first], hi[first]], axis=1) if first.size else np.zeros((0, 2),
                                                                                     np.int64)
        self.fwd = self.H[:, 0] == lo  # half-edge runs like its unique edge (low -> high)


def unique_edges(F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique undirected edges and the map from half-edges to them.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.

    Returns
    -------
    E : (e, 2) int64 array
        Unique edges, each row sorted (``E[:, 0] < E[:, 1]``), rows sorted lexicographically.
    EMAP : (3m,) int64 array
        ``EMAP[c * m + f]`` is the edge opposite corner ``c`` of face ``f`` (libigl's layout).
    counts : (e,) int64 array
        Number of faces touching each edge (1 = boundary, 2 = interior, >2 = non-manifold).
    """
    d = _EdgeData(_faces(F))
    return d.E, d.EMAP, d.counts


def edge_flaps(F) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edge flaps, like ``igl.edge_flaps``, for an edge-manifold, consistently oriented mesh.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.

    Returns
    -------
    E : (e, 2) int64 array
        Unique edges (see :func:`unique_edges`).
    EMAP : (3m,) int64 array
        Half-edge to edge map.
    EF : (e, 2) int64 array
        ``EF[e, 0]`` is the face in which edge ``e`` runs ``E[e,0] -> E[e,1]``; ``EF[e, 1]`` the
        face in which it runs ``E[e,1] -> E[e,0]``; ``-1`` where there is no such face (boundary).
    EI : (e, 2) int64 array
        ``EI[e, k]`` is the corner of face ``EF[e, k]`` opposite edge ``e`` (``-1`` if none).

    Raises
    ------
    InvalidMeshError
        If an edge touches more than two faces, or two faces on an edge run it in the same
        direction (inconsistent orientation).
    """
    d = _EdgeData(_faces(F))
    EF, EI = _flaps(d)
    return d.E, d.EMAP, EF, EI


def _flaps(d: _EdgeData) -> tuple[np.ndarray, np.ndarray]:
    if d.counts.size and d.counts.max() > 2:
        k = int((d.counts > 2).sum())
        raise InvalidMeshError(
            f"{k} edge{'s are' if k != 1 else ' is'} shared by more than two triangles "
            "(non-manifold). This operation needs every edge to touch one or two triangles; "
            "'Clean' can remove the extra triangles."
        )
    e = d.E.shape[0]
    slot = np.where(d.fwd, 0, 1)
    key = d.EMAP * 2 + slot
    if key.size and np.bincount(key, minlength=2 * e).max() > 1:
        raise InvalidMeshError(
            "Neighbouring triangles are oriented inconsistently (some normals point inwards, "
            "some outwards). 'Clean' (or --clean) re-orients them; a one-sided part (like a "
            "Moebius strip) it first cuts open along the seam where the orientation flips."
        )
    h = np.arange(3 * d.m)
    EF = np.full((e, 2), -1, dtype=np.int64)
    EI = np.full((e, 2), -1, dtype=np.int64)
    EF[d.EMAP, slot] = h % d.m if d.m else h
    EI[d.EMAP, slot] = h // d.m if d.m else h
    return EF, EI


def halfedge_twins(F) -> np.ndarray:
    """Opposite (twin) half-edge of every half-edge.

    Parameters
    ----------
    F : (m, 3) int array
        Edge-manifold, consistently oriented triangles.

    Returns
    -------
    twin : (3m,) int64 array
        ``twin[h]`` is the half-edge running the other way along the same edge (in the
        neighbouring face), or ``-1`` on the boundary. Numbering as in :func:`halfedges`.

    Raises
    ------
    InvalidMeshError
        For non-manifold edges or inconsistent orientation.
    """
    d = _EdgeData(_faces(F))
    return _twins(d)


def _twins(d: _EdgeData) -> np.ndarray:
    EF, EI = _flaps(d)
    slot = np.where(d.fwd, 0, 1)
    other_f = EF[d.EMAP, 1 - slot]
    other_c = EI[d.EMAP, 1 - slot]
    return np.where(other_f >= 0, other_c * d.m + other_f, -1)


# --------------------------------------------------------------------------------------------
# adjacency
# --------------------------------------------------------------------------------------------


def vertex_adjacency(F, n: int | None = None) -> sp.csr_matrix:
    """Vertex-vertex adjacency matrix (vertices joined by an edge).

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.
    n : int, optional
        Number of vertices (default ``F.max() + 1``); unreferenced vertices get empty rows.

    Returns
    -------
    A : (n, n) scipy.sparse.csr_matrix of float64
        Symmetric, ``A[i, j] = 1`` if ``i`` and ``j`` share an edge, zero diagonal.
    """
    import scipy.sparse as sp
    F = _faces(F)
    n = _n_vertices(F, n)
    d = _EdgeData(F)
    E = d.E[d.E[:, 0] != d.E[:, 1]]
    rows = np.concatenate([E[:, 0], E[:, 1]])
    cols = np.concatenate([E[:, 1], E[:, 0]])
    A = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    A.sort_indices()
    return A


def vertex_face_adjacency(F, n: int | None = None) -> sp.csr_matrix:
    """Vertex-face incidence matrix.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.
    n : int, optional
        Number of vertices (default ``F.max() + 1``).

    Returns
    -------
    VF : (n, m) scipy.sparse.csr_matrix of float64
        ``VF[v, f] = 1`` if face ``f`` uses vertex ``v``. ``VF.indices[VF.indptr[v]:
        VF.indptr[v+1]]`` lists the faces around ``v``.
    """
    import scipy.sparse as sp
    F = _faces(F)
    n = _n_vertices(F, n)
    m = F.shape[0]
    VF = sp.csr_matrix(
        (np.ones(3 * m), (F.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m)
    )
    VF.sum_duplicates()
    VF.data[:] = 1.0
    VF.sort_indices()
    return VF


def face_adjacency(F) -> sp.csr_matrix:
    """Face-face adjacency across edges.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.

    Returns
    -------
    A : (m, m) scipy.sparse.csr_matrix of float64
        Symmetric; ``A[f, g] = 1`` if faces ``f`` and ``g`` share an edge (on a non-manifold
        edge all its faces are mutually adjacent).
    """
    import scipy.sparse as sp
    d = _EdgeData(_faces(F))
    rows, cols = _edge_face_pairs(d)
    m = d.m
    A = sp.csr_matrix(
        (np.ones(2 * rows.size), (np.concatenate([rows, cols]), np.concatenate([cols, rows]))),
        shape=(m, m),
    )
    A.sum_duplicates()
    A.data[:] = 1.0
    A.setdiag(0)
    A.eliminate_zeros()
    return A


def _edge_face_pairs(d: _EdgeData) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of faces (f1, f2) sharing an edge; on a non-manifold edge, every pair of its faces."""
    m = max(d.m, 1)
    hs = d.order  # half-edges sorted by edge
    same = d.EMAP[hs[1:]] == d.EMAP[hs[:-1]]
    h1, h2 = hs[:-1][same], hs[1:][same]
    # consecutive pairs cover edges with two faces; add the missing pairs on busier edges
    busy = d.counts > 2
    if busy.any():
        starts = np.cumsum(d.counts) - d.counts  # position of each edge's first half-edge in hs
        extra1, extra2 = [], []
        for k in np.unique(d.counts[busy]):
            groups = starts[d.counts == k][:, None] + np.arange(k)  # (g, k) positions
            a, b = np.triu_indices(int(k), 2)  # pairs not already consecutive
            extra1.append(hs[groups[:, a]].ravel())
            extra2.append(hs[groups[:, b]].ravel())
        h1 = np.concatenate([h1, *extra1])
        h2 = np.concatenate([h2, *extra2])
    return h1 % m, h2 % m


# --------------------------------------------------------------------------------------------
# manifoldness
# --------------------------------------------------------------------------------------------


def nonmanifold_edges(F) -> np.ndarray:
    """Edges shared by more than two faces.

    Parameters
    ----------
    F : (m, 3) int array

    Returns
    -------
    (k, 2) int64 array
        The offending edges (rows sorted).
    """
    E, _, counts = unique_edges(F)
    return E[counts > 2]


def _corner_fans(d: _EdgeData, n: int, cut: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Label the fan of each corner.

    Corner ``c * m + f`` is vertex ``F[f, c]``. Corners at the same vertex in faces that share an
    edge through that vertex are linked; connected corners form a fan. ``cut`` ((e,) bool over
    the unique edges, optional): faces sharing a cut edge are not linked through it (the
    surface is cut open there).

    Returns (labels (3m,), fans_per_vertex (n,)).
    """
    m = d.m
    F = d.F
    if m == 0:
        return np.zeros(0, np.int64), np.zeros(n, np.int64)
    hs = d.order
    same = d.EMAP[hs[1:]] == d.EMAP[hs[:-1]]
    h1 = hs[:-1][same]
    h2 = hs[1:][same]
    if cut is not None:
        keep = ~cut[d.EMAP[h1]]
        h1, h2 = h1[keep], h2[keep]
    f1, c1 = h1 % m, h1 // m
    f2, c2 = h2 % m, h2 // m
    # endpoints of each half-edge as corners: start corner (c+1)%3, end corner (c+2)%3
    s1 = ((c1 + 1) % 3) * m + f1
    e1 = ((c1 + 2) % 3) * m + f1
    s2 = ((c2 + 1) % 3) * m + f2
    e2 = ((c2 + 2) % 3) * m + f2
    Fc = F.T.ravel()  # Fc[c*m + f] = F[f, c]
    same_dir = Fc[s1] == Fc[s2]
    a = np.concatenate([s1, e1])
    b = np.concatenate([np.where(same_dir, s2, e2), np.where(same_dir, e2, s2)])
    ncomp, labels = _cc(3 * m, a, b)
    # every fan (corner component) lives at a single vertex, so counting fans is a bincount
    vertex_of_fan = np.empty(ncomp, dtype=np.int64)
    vertex_of_fan[labels] = Fc
    fans = np.bincount(vertex_of_fan, minlength=n)
    return labels.astype(np.int64), fans


def nonmanifold_vertices(F, n: int | None = None) -> np.ndarray:
    """Vertices whose faces form more than one fan (e.g. two cones touching at their tips).

    Parameters
    ----------
    F : (m, 3) int array
    n : int, optional
        Number of vertices.

    Returns
    -------
    (k,) int64 array
        Sorted indices of non-manifold vertices. Unreferenced vertices are *not* included, and
        neither are vertices that are non-manifold only because they lie on a non-manifold edge
        (same convention as ``igl.is_vertex_manifold``).
    """
    F = _faces(F)
    n = _n_vertices(F, n)
    _, fans = _corner_fans(_EdgeData(F), n)
    return np.flatnonzero(fans > 1)


def is_edge_manifold(F) -> bool:
    """True if every edge touches at most two faces. ``F`` is ``(m, 3)``."""
    _, _, counts = unique_edges(F)
    return bool(counts.size == 0 or counts.max() <= 2)


def is_vertex_manifold(F, n: int | None = None) -> bool:
    """True if the faces around every referenced vertex form a single fan. ``F`` is ``(m, 3)``."""
    return nonmanifold_vertices(F, n).size == 0


def is_manifold(F) -> bool:
    """True if the mesh ``F (m, 3)`` is both edge- and vertex-manifold."""
    return is_edge_manifold(F) and is_vertex_manifold(F)


# --------------------------------------------------------------------------------------------
# boundary
# --------------------------------------------------------------------------------------------


def boundary_edges(F) -> np.ndarray:
    """Directed boundary half-edges (edges with exactly one face).

    Parameters
    ----------
    F : (m, 3) int array

    Returns
    -------
    (b, 2) int64 array
        Each row runs in the direction of its face, so with counter-clockwise faces the
        surface lies to the left.
    """
    d = _EdgeData(_faces(F))
    return d.H[d.counts[d.EMAP] == 1]


def boundary_loops(F) -> list[np.ndarray]:
    """Ordered boundary loops.

    Parameters
    ----------
    F : (m, 3) int array
        Edge-manifold, consistently oriented triangles.

    Returns
    -------
    list of (k_i,) int64 arrays
        One array of vertex indices per loop, in the direction of the faces' half-edges
        (``loop[i] -> loop[i+1]`` is an edge of a face; the same direction as
        ``igl.boundary_loop``). Each loop starts at its smallest vertex index; loops are sorted
        longest first (ties: by starting vertex). A closed mesh gives ``[]``.

    Raises
    ------
    InvalidMeshError
        If the mesh is not edge-manifold or not consistently oriented.

    Notes
    -----
    At a vertex where two boundary loops touch (a non-manifold vertex), the loops are separated
    by walking around the vertex through the faces, so each loop is a simple cycle of
    half-edges.
    """
    d = _EdgeData(_faces(F))
    twin = _twins(d)
    m = d.m
    bh = np.flatnonzero(twin < 0)
    if bh.size == 0:
        return []
    # next boundary half-edge: rotate around the end vertex through the faces
    cand = ((bh // m + 1) % 3) * m + bh % m  # next half-edge in the same face (leaves end vertex)
    pending = twin[cand] >= 0
    for _ in range(3 * m + 1):
        if not pending.any():
            break
        t = twin[cand[pending]]
        cand[pending] = ((t // m + 1) % 3) * m + t % m
        pending[pending] = twin[cand[pending]] >= 0
    pos = np.full(3 * m, -1, dtype=np.int64)
    pos[bh] = np.arange(bh.size)
    nxt = pos[cand]
    k = bh.size
    start_v = d.H[bh, 0]
    ncomp, lab = _cc(k, np.arange(k), nxt)
    # start of each loop: the boundary half-edge with the smallest start vertex
    key = lab * (int(start_v.max()) + 1) + start_v
    first_in_loop = np.full(ncomp, -1, dtype=np.int64)
    o = np.argsort(key, kind="stable")
    is_first = np.ones(k, dtype=bool)
    is_first[1:] = lab[o[1:]] != lab[o[:-1]]
    first_in_loop[lab[o[is_first]]] = o[is_first]
    is_start = np.zeros(k, dtype=bool)
    is_start[first_in_loop] = True
    # list ranking by pointer jumping over predecessors
    prev = np.empty(k, dtype=np.int64)
    prev[nxt] = np.arange(k)
    dist = np.where(is_start, 0, 1)
    ptr = np.where(is_start, np.arange(k), prev)
    while True:
        nptr = ptr[ptr]
        if np.array_equal(nptr, ptr):
            break
        dist = dist + np.where(ptr != nptr, dist[ptr], 0)
        ptr = nptr
    # ptr now points at the loop start; dist is the position within the loop
    order = np.lexsort((dist, lab))
    sizes = np.bincount(lab, minlength=ncomp)
    pieces = np.split(start_v[order], np.cumsum(sizes)[:-1])
    starts = np.array([p[0] for p in pieces])
    loop_order = np.lexsort((starts, -sizes))
    return [pieces[i].astype(np.int64) for i in loop_order]


# --------------------------------------------------------------------------------------------
# components, Euler characteristic, genus
# --------------------------------------------------------------------------------------------


def referenced_vertices(F, n: int | None = None) -> np.ndarray:
    """Boolean mask ``(n,)`` of vertices used by at least one face of ``F (m, 3)``."""
    F = _faces(F)
    n = _n_vertices(F, n)
    mask = np.zeros(n, dtype=bool)
    mask[F.ravel()] = True
    return mask


def connected_components(F, n: int | None = None, *, over: str = "faces") -> tuple[int, np.ndarray]:
    """Connected components (parts that share no vertex).

    Parameters
    ----------
    F : (m, 3) int array
        Triangles.
    n : int, optional
        Number of vertices (default ``F.max() + 1``).
    over : {'faces', 'vertices'}
        ``'faces'``: label every face; parts touching only at a vertex count as one component.
        ``'vertices'``: label every vertex ``0..n-1``; each unreferenced vertex is a component
        of its own.

    Returns
    -------
    count : int
        Number of components.
    labels : (m,) or (n,) int64 array
        Component of each face (or vertex), numbered ``0..count-1`` in order of first
        appearance.
    """
    F = _faces(F)
    n = _n_vertices(F, n)
    if over not in ("faces", "vertices"):
        raise ValueError(f"over must be 'faces' or 'vertices', not {over!r}")
    rows = np.concatenate([F[:, 0], F[:, 1]])
    cols = np.concatenate([F[:, 1], F[:, 2]])
    _, vlab = _cc(n, rows, cols)
    vlab = vlab.astype(np.int64)
    lab = vlab[F[:, 0]] if over == "faces" else vlab
    if lab.size == 0:
        return 0, lab
    return _relabel_by_first_appearance(lab)


def _relabel_by_first_appearance(lab: np.ndarray) -> tuple[int, np.ndarray]:
    """Map labels to 0..k-1 in order of first appearance; O(len) without sorting."""
    k = int(lab.max()) + 1
    first = np.full(k, lab.size, dtype=np.int64)
    first[lab[::-1]] = np.arange(lab.size)[::-1]  # last write wins -> smallest position
    used = first < lab.size
    order = np.argsort(first[used], kind="stable")
    rank = np.full(k, -1, dtype=np.int64)
    rank[np.flatnonzero(used)[order]] = np.arange(order.size)
    return int(order.size), rank[lab]


def euler_characteristic(F) -> int:
    """Euler characteristic ``chi = V - E + F``.

    Parameters
    ----------
    F : (m, 3) int array

    Returns
    -------
    int
        ``V`` counts only vertices used by some face (unreferenced vertices would each add 1),
        ``E`` the unique edges, ``F`` the faces. A closed genus-0 surface gives 2.
    """
    F = _faces(F)
    if F.shape[0] == 0:
        return 0
    nv = int(np.count_nonzero(np.bincount(F.ravel())))
    E, _, _ = unique_edges(F)
    return nv - E.shape[0] + F.shape[0]


def genus(F, n: int | None = None, *, per_component: bool = False):
    """Genus (number of handles) of a manifold, orientable mesh.

    For each connected component ``c`` (faces sharing vertices, see :func:`connected_components`)
    ``g_c = (2 - chi_c - b_c) / 2`` where ``chi_c`` is its Euler characteristic and ``b_c`` its
    number of boundary loops; the result is the **sum over components** (a mesh made of two
    tori has genus 2; a sphere and a torus, genus 1).

    Parameters
    ----------
    F : (m, 3) int array
        Edge- and vertex-manifold, orientable triangles.
    n : int, optional
        Number of vertices (unreferenced vertices are ignored).
    per_component : bool
        If True, return the ``(C,)`` int64 array of per-component genera instead of the sum.

    Returns
    -------
    int or (C,) int64 array

    Raises
    ------
    InvalidMeshError
        If the mesh is empty, not manifold, or not orientable (e.g. a Moebius strip).
    """
    F = _faces(F)
    n = _n_vertices(F, n)
    if F.shape[0] == 0:
        raise InvalidMeshError("The genus of an empty mesh is undefined: it has no faces.")
    d = _EdgeData(F)
    if d.counts.max() > 2:
        raise InvalidMeshError(
            "The genus is only defined for manifold meshes, but some edges are shared by more "
            "than two triangles. 'Clean' can fix this."
        )
    _, fans = _corner_fans(d, n)
    if (fans > 1).any():
        raise InvalidMeshError(
            "The genus is only defined for manifold meshes, but some vertices join separate "
            "pieces of surface. 'Clean' can fix this."
        )
    if not _orientation_data(d)[2]:
        raise InvalidMeshError(
            "The genus is only defined here for orientable surfaces; this mesh is not "
            "orientable (it has a Moebius-strip-like part)."
        )
    C, flab = connected_components(F, n)
    return _genus_from(d, n, C, flab, per_component)


def _genus_from(d: _EdgeData, n: int, C: int, flab: np.ndarray, per_component: bool = False):
    """Genus per component from precomputed edge data and face component labels."""
    F, m = d.F, d.m
    comp_of_vertex = np.full(n, -1, dtype=np.int64)
    comp_of_vertex[F.ravel()] = np.repeat(flab, 3)
    nv_c = np.bincount(comp_of_vertex[comp_of_vertex >= 0], minlength=C)
    ne_c = np.bincount(flab[d.first % m], minlength=C)
    nf_c = np.bincount(flab, minlength=C)
    chi = nv_c - ne_c + nf_c
    b_c = np.zeros(C, dtype=np.int64)
    bmask = d.counts == 1
    if bmask.any():
        # boundary loops = connected components of the boundary-edge graph (manifold input)
        BE = d.E[bmask]
        _, lab = _cc(n, BE[:, 0], BE[:, 1])
        loop_comp = np.unique(lab[BE[:, 0]].astype(np.int64) * C + comp_of_vertex[BE[:, 0]])
        b_c = np.bincount(loop_comp % C, minlength=C)
    g = (2 - chi - b_c) // 2
    return g.astype(np.int64) if per_component else int(g.sum())


# --------------------------------------------------------------------------------------------
# orientation
# --------------------------------------------------------------------------------------------


def _orientation_data(d: _EdgeData) -> tuple[np.ndarray, np.ndarray, bool]:
    """Propagate a consistent orientation over each edge-connected patch.

    Returns (flip (m,) bool, patch labels (m,), orientable). Requires edge-manifold input.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order
    m = d.m
    if m == 0:
        return np.zeros(0, bool), np.zeros(0, np.int64), True
    hs = d.order
    same = d.EMAP[hs[1:]] == d.EMAP[hs[:-1]]
    h1 = hs[:-1][same]
    h2 = hs[1:][same]
    f1, f2 = h1 % m, h2 % m
    rel = (d.fwd[h1] == d.fwd[h2]).astype(np.int8)  # 1: same direction -> one must flip
    selfpair = f1 == f2
    f1, f2, rel = f1[~selfpair], f2[~selfpair], rel[~selfpair]
    ncomp, lab = _cc(m, f1, f2)
    # virtual root m joined to the first face of every patch
    roots = np.full(ncomp, -1, dtype=np.int64)
    roots[lab[::-1]] = np.arange(m)[::-1]
    rows = np.concatenate([f1, f2, np.full(ncomp, m)])
    cols = np.concatenate([f2, f1, roots])
    G2 = sp.csr_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(m + 1, m + 1))
    _, pred = breadth_first_order(G2, m, directed=True, return_predecessors=True)
    pred = pred[:m].astype(np.int64)
    # relation of each face to its BFS parent
    big = m + 1
    pk = np.minimum(f1, f2) * big + np.maximum(f1, f2)
    korder = np.argsort(pk, kind="stable")
    pk_sorted = pk[korder]
    child = np.arange(m)
    par = pred
    is_root_child = par == m
    q = np.minimum(child, par) * big + np.maximum(child, par)
    loc = np.searchsorted(pk_sorted, q)
    loc = np.minimum(loc, max(pk_sorted.size - 1, 0))
    r = np.zeros(m, dtype=np.int8)
    if pk_sorted.size:
        r = np.where(is_root_child, 0, rel[korder[loc]]).astype(np.int8)
    # parity = XOR of relations on the path to the root (pointer jumping)
    parity = r.copy()
    ptr = np.where(is_root_child, child, par)
    while True:
        nptr = ptr[ptr]
        upd = ptr != nptr
        if not upd.any():
            break
        parity = parity ^ np.where(upd, parity[ptr], 0).astype(np.int8)
        ptr = nptr
    flip = parity.astype(bool)
    ok = (rel ^ parity[f1] ^ parity[f2]) == 0
    return flip, lab.astype(np.int64), bool(ok.all())


def _inconsistent_edges(d: _EdgeData, flip: np.ndarray) -> np.ndarray:
    """(e,) bool over the unique edges: interior edges whose two faces still disagree about the
    outside once the faces in ``flip`` are flipped (none on an orientable surface with the flips
    of :func:`_orientation_data`; on a one-sided one, a seam that makes it two-sided when cut).

    Around an interior manifold vertex the faces form a disc, which is orientable, so an even
    number of these edges meets there: the seam runs from boundary to boundary or closes on
    itself, and cutting it (:func:`_corner_fans` with ``cut``) separates every one of its edges.
    """
    hs = d.order
    same = d.EMAP[hs[1:]] == d.EMAP[hs[:-1]]
    h1, h2 = hs[:-1][same], hs[1:][same]
    bad = (d.fwd[h1] == d.fwd[h2]) ^ flip[h1 % d.m] ^ flip[h2 % d.m]
    out = np.zeros(len(d.counts), dtype=bool)
    out[d.EMAP[h1[bad]]] = True
    return out


def orient_consistently(F) -> tuple[np.ndarray, np.ndarray, bool]:
    """Re-orient faces so neighbours agree (breadth-first search over edge-adjacent faces).

    In every patch of faces connected through edges, the first face (smallest index) keeps its
    orientation and the others are flipped to agree with it. To make closed parts face outwards,
    see :func:`algorithms.mesh.validate.clean_mesh` (it uses the signed volume).

    Parameters
    ----------
    F : (m, 3) int array
        Edge-manifold triangles.

    Returns
    -------
    F_oriented : (m, 3) int64 array
        Faces with corners 1 and 2 swapped where flipped.
    flipped : (m,) bool array
        Which faces were flipped.
    orientable : bool
        False if some patch cannot be oriented consistently (a Moebius strip); then some edges
        remain inconsistent.

    Raises
    ------
    InvalidMeshError
        If an edge touches more than two faces.
    """
    F = _faces(F)
    d = _EdgeData(F)
    if d.counts.size and d.counts.max() > 2:
        raise InvalidMeshError(
            "Faces can only be re-oriented when every edge touches one or two triangles; some "
            "edges are shared by more. 'Clean' can remove the extra triangles."
        )
    flip, _, orientable = _orientation_data(d)
    G = F.copy()
    G[flip] = G[flip][:, [0, 2, 1]]
    return G, flip, orientable


def touching_parts(V, F, tol: float = 1e-3) -> tuple[int, int]:
    """``(parts, touching)``: the number of connected parts of the mesh (parts that share no
    vertex) and how many of them come within ``tol`` times the bounding-box diagonal of
    another part (a door against its car body, a window in its frame). A method that moves
    each part on its own (Cubic with several parts) can pull such parts apart."""
    from scipy.spatial import cKDTree

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if len(F) == 0:
        return 0, 0
    used = np.unique(F)
    n_parts, lab = connected_components(F, len(V), over="vertices")
    lab = lab[used]
    n_parts = len(np.unique(lab))
    if n_parts < 2:
        return n_parts, 0
    P = V[used]
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    if not diag > 0:
        return n_parts, 0
    pairs = cKDTree(P).query_pairs(tol * diag, output_type="ndarray")
    if not len(pairs):
        return n_parts, 0
    cross = pairs[lab[pairs[:, 0]] != lab[pairs[:, 1]]]
    return n_parts, int(len(np.unique(lab[cross.ravel()])))
