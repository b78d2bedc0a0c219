"""The one local-global as-rigid-as-possible (ARAP) core (thesis ch. 5 Eq. 5.1, ch. 6 2112-2159).

Energy (Sorkine & Alexa 2007 with the "spokes and rims" cells of Chao et al. 2010)::

    E(U, {R_i}) = sum_i sum_{(j,k) in cell(i)} w_jk / 2 * || R_i d_jk - d~_jk ||^2

* ``cell(i)`` holds **every edge of every triangle incident to vertex i** (spokes and rims), so
  each triangle edge appears in the cells of the three corners of that triangle.
* ``w_jk`` is the cotangent weight of the edge *within that triangle*: ``cot`` of the angle
  opposite the edge in that triangle (twice libigl's ``cotmatrix_entries``). It is not summed
  over the two triangles of the edge: the two triangles contribute two separate cell entries.
* ``d_jk = v_k - v_j`` is the rest edge, ``d~_jk = u_k - u_j`` the deformed one.

Everything is precomputed once per mesh and constraint set:

* ``K`` (3n x n sparse): the per-vertex covariance ``S_i = sum w d d~^T`` of all vertices at once is
  ``(K @ U).reshape(n, 3, 3)``; the same ``K`` transposed gives the global right-hand side
  ``b = K^T [R_1^T; ...; R_n^T]``.
* ``Q = G^T W G`` (n x n): the global system matrix. With these weights ``Q = 6 * (-L)`` where ``L``
  is the cotangent Laplacian (each triangle edge sits in three cells, and ``cot = 2 * cot/2``).
* The global step ``Q U = b`` decouples into the three coordinates. Hard constraints are Dirichlet
  unknowns eliminated by :class:`algorithms.linalg.SPDSolver`: fixed vertices (all three
  coordinates) and per-coordinate constraints (coordinate ``d`` of vertex ``i`` equals ``c``; the
  thesis's plane constraints ``(U_i)_x = c``). Each coordinate whose constrained set differs gets
  its own factorization; coordinates sharing the same set share one. Soft point handles add
  ``sum_h k_h / 2 ||u_h - p_h||^2`` (a diagonal term, factored in too).

Choices written down here:

* The overall scale of the weights does not change ARAP deformations (rotations and positions
  are invariant to it) and makes libigl's SPOKES_AND_RIMS (weights ``cot/2 / 3``) a direct peer.
  It does matter once another term is added (cubic stylization's ``lambda``). ``w = cot`` per
  triangle gives every spoke ``ij`` the total weight ``cot a + cot b = 2 L_ij`` and every rim
  ``jk`` about ``L_jk`` (exactly when its two opposite angles are equal), which is what the
  authors' cubic-stylization code uses in its local step (``L_ij`` per half-edge of each incident
  face), so the thesis's ``lambda`` values (0.2 typical) keep their meaning. Unlike that code,
  the local and the global step here minimize the same energy.
* Rotations are the orthogonal Procrustes maximizers of ``tr(R S)``: ``S = U Sigma V^T``,
  ``R = V U^T``, with the sign of the last column of ``U`` (smallest singular value) flipped when
  ``det(V U^T) < 0`` (thesis Eq. 5.8). :func:`procrustes_rotations` runs a compiled one-sided
  Jacobi SVD (:mod:`algorithms.deform.kernels`, Numba) when Numba is installed and NumPy's
  batched SVD (:func:`procrustes_rotations_numpy`) otherwise; the two agree to round-off
  (tested). ``STYLIZE3D_NUMBA=0`` or :func:`set_compiled_kernels` switches the kernels off.
* ``rotations(U, extra)`` adds an ``(n, 3, 3)`` term to the covariances before Procrustes: the
  hook through which cubic stylization (ADMM, ``rho n (z - u)^T``) and shape analogies
  (``lambda a n t^T``) enter.
* Face cells (``cells="faces"``, the face-only ARAP of thesis Eq. 6.4, Zhao & Gortler 2016,
  Levi & Gotsman 2015): one rotation per triangle whose cell holds the three edges of that
  triangle, with the same per-triangle cotangent weights. Every triangle edge then sits in one
  cell instead of three, so ``Q = 2 * (-L)``; ``K`` is ``(3m, n)`` and every per-cell array
  (covariances, rotations, ``rest_covariance``) has ``n_cells = m`` rows. Vertex cells are the
  default and their results are unchanged.
* Per-cell scale (the as-conformal-as-possible energy of thesis Eq. 6.5, Bouaziz et al. 2012):
  :meth:`ArapSystem.scaled_rotations` solves the isotropic Procrustes problem of every cell
  (rotation as above, then the closed-form scale of Schönemann & Carroll 1970); the global step
  and the energy take the scaled rotations ``s_k R_k`` as they are (``rhs`` and ``energy`` accept
  any per-cell linear maps).
* Vertices that no triangle uses have no energy; they are always held where the given values put
  them (all three coordinates are Dirichlet), so the system stays definite.
* A connected component with no hard or soft constraint in some coordinate leaves the global
  system singular (the energy does not see translations). :class:`ArapSystem` refuses it with a
  message; callers pin a vertex (cubic stylization does) or add handles.
* Only axis-aligned plane constraints are supported (one coordinate = constant). A plane with a
  general normal would couple the three coordinates into one 3n system.
* ``arap_iter`` stops when the largest vertex move of an iteration, relative to the largest
  total move from the input so far, is below ``rel_displacement_tol`` (the same definition as
  cubic stylization uses).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMeshError, ParameterError
from ..compiled import KernelModule
from ..linalg import SPDSolver
from ..mesh.topology import connected_components
from ..params import param, validate_params
from ..steps import Step, run_to_end

__all__ = [
    "ArapSystem",
    "ArapParams",
    "arap_iter",
    "arap",
    "procrustes_rotations",
    "procrustes_rotations_numpy",
    "compiled_kernels",
    "set_compiled_kernels",
    "spokes_and_rims_cells",
    "face_cells",
    "relative_displacement",
    "CELL_KINDS",
]

HANDLE_MODES = ("hard", "soft")
#: The kinds of ARAP cells :class:`ArapSystem` accepts (``cells=``).
CELL_KINDS = ("spokes_and_rims", "faces")


_KERNELS = KernelModule("algorithms.deform.kernels")


def compiled_kernels():
    """The compiled kernels module (:mod:`algorithms.deform.kernels`), or None.

    None when Numba cannot be imported, when the environment variable ``STYLIZE3D_NUMBA`` is
    ``0``, or after :func:`set_compiled_kernels` (False). Imported lazily on first use, so that
    importing this module does not import Numba.
    """
    return _KERNELS.get()


def set_compiled_kernels(enabled: bool) -> bool:
    """Switch the compiled kernels on or off (for comparisons); returns the previous setting.

    Switching on where Numba is missing leaves them off (:func:`compiled_kernels` returns None).
    """
    return _KERNELS.set(enabled)


def procrustes_rotations(S: np.ndarray) -> np.ndarray:
    """Batched orthogonal Procrustes: the rotation maximizing ``tr(R_i S_i)`` for every ``i``.

    Parameters
    ----------
    S : (n, 3, 3) float array
        Covariance-like matrices (``S_i = sum w d d~^T`` for ARAP).

    Returns
    -------
    R : (n, 3, 3) float64 array
        Proper rotations (``det = +1``): with ``S_i = U Sigma V^T``, ``R_i = V U^T``, and the sign
        of the singular vector of the smallest singular value flipped where ``det(V U^T) < 0``.
        For ``S_i = 0`` the identity.

    Notes
    -----
    Uses the compiled one-sided Jacobi kernel (:func:`algorithms.deform.kernels.procrustes_batch`)
    when Numba is available, else :func:`procrustes_rotations_numpy` (batched LAPACK SVD). The
    two agree to round-off wherever the maximizer is unique; where it is not (rank <= 1, or
    ``det S < 0`` with the two smallest singular values equal) both return a maximizer.
    """
    S = np.asarray(S, dtype=np.float64)
    if S.ndim != 3 or S.shape[1:] != (3, 3):
        raise ValueError(f"S must have shape (n, 3, 3), got {S.shape}")
    kern = compiled_kernels()
    if kern is None:
        return procrustes_rotations_numpy(S)
    S = np.ascontiguousarray(S)
    R = np.empty_like(S)
    if len(S):
        kern.procrustes_batch(S, R)
    return R


def procrustes_rotations_numpy(S: np.ndarray) -> np.ndarray:
    """:func:`procrustes_rotations` by NumPy's batched SVD (the reference and the fallback)."""
    S = np.asarray(S, dtype=np.float64)
    if S.ndim != 3 or S.shape[1:] != (3, 3):
        raise ValueError(f"S must have shape (n, 3, 3), got {S.shape}")
    if S.shape[0] == 0:
        return np.zeros((0, 3, 3))
    U, _, Vt = np.linalg.svd(S)
    # R = V U^T = (U V^T)^T
    R = np.matmul(Vt.transpose(0, 2, 1), U.transpose(0, 2, 1))
    det = np.linalg.det(R)
    bad = det < 0
    if bad.any():
        Ub = U[bad].copy()
        Ub[:, :, 2] *= -1.0
        R[bad] = np.matmul(Vt[bad].transpose(0, 2, 1), Ub.transpose(0, 2, 1))
    return R


def spokes_and_rims_cells(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray, np.ndarray]:
    """The spokes-and-rims cell entries of every vertex.

    Parameters
    ----------
    V : (n, 3) float64 rest positions.
    F : (m, 3) int64 triangles.

    Returns
    -------
    cell : (9m,) int64, the vertex whose cell the entry belongs to.
    tail, head : (9m,) int64, the edge's endpoints (the edge vector is ``V[head] - V[tail]``).
    weight : (9m,) float64, ``cot(angle opposite the edge in its triangle)``.

    Notes
    -----
    Entry ``9 f + 3 k + l`` is edge ``k`` (opposite corner ``k``) of triangle ``f`` in the cell
    of corner ``l`` of that triangle.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    P = V[F]  # (m, 3, 3)
    # corner k: edges to the two other corners
    a = P[:, [1, 2, 0]] - P  # (m, 3, 3): corner k -> k+1
    b = P[:, [2, 0, 1]] - P  # corner k -> k+2
    dot = np.einsum("fkc,fkc->fk", a, b)
    crs = np.linalg.norm(np.cross(a, b), axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = dot / crs  # (m, 3): cot of the angle at corner k
    tail_fk = F[:, [1, 2, 0]]  # edge opposite corner k goes from corner k+1 ...
    head_fk = F[:, [2, 0, 1]]  # ... to corner k+2
    cell = np.broadcast_to(F[:, None, :], (m, 3, 3)).reshape(-1)
    tail = np.broadcast_to(tail_fk[:, :, None], (m, 3, 3)).reshape(-1)
    head = np.broadcast_to(head_fk[:, :, None], (m, 3, 3)).reshape(-1)
    weight = np.broadcast_to(w[:, :, None], (m, 3, 3)).reshape(-1)
    return (np.ascontiguousarray(cell), np.ascontiguousarray(tail),
            np.ascontiguousarray(head), np.ascontiguousarray(weight))


def face_cells(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                    np.ndarray]:
    """The face-only ARAP cells: the three edges of every triangle, one cell per triangle.

    Parameters
    ----------
    V : (n, 3) float64 rest positions.
    F : (m, 3) int64 triangles.

    Returns
    -------
    cell : (3m,) int64, the triangle whose cell the entry belongs to.
    tail, head : (3m,) int64, the edge's endpoints (the edge vector is ``V[head] - V[tail]``).
    weight : (3m,) float64, ``cot(angle opposite the edge in its triangle)``.

    Notes
    -----
    Entry ``3 f + k`` is edge ``k`` (opposite corner ``k``, from corner ``k+1`` to ``k+2``) of
    triangle ``f``: the entries ``9 f + 3 k + l`` of :func:`spokes_and_rims_cells` with one ``l``.
    """
    cell, tail, head, w = spokes_and_rims_cells(V, F)
    keep = slice(0, None, 3)  # l = 0: each triangle edge once
    m = len(np.asarray(F))
    return (np.repeat(np.arange(m, dtype=np.int64), 3), np.ascontiguousarray(tail[keep]),
            np.ascontiguousarray(head[keep]), np.ascontiguousarray(w[keep]))


def relative_displacement(U_new: np.ndarray, U_old: np.ndarray, U_rest: np.ndarray,
                          floor: float = 1e-9) -> float:
    """Largest vertex move of one iteration relative to the largest total move from the rest.

    Parameters
    ----------
    U_new, U_old, U_rest : (n, 3) float arrays.
    floor : float
        The total move counts as at least ``floor`` times the bounding-box diagonal of
        ``U_rest``, so round-off moves of a shape that does not deform give a small ratio.

    Returns
    -------
    float
        ``max_i |U_new_i - U_old_i| / max(max_i |U_new_i - U_rest_i|, floor * diag)``.
    """
    U_new, U_old, U_rest = (np.asarray(a, dtype=np.float64) for a in (U_new, U_old, U_rest))
    kern = compiled_kernels()
    if (kern is not None and U_new.ndim == 2 and U_new.shape[1] == 3
            and U_new.shape == U_old.shape == U_rest.shape):
        step, total, diag = kern.displacement_maxima(*(np.ascontiguousarray(a)
                                                       for a in (U_new, U_old, U_rest)))
    else:
        step = float(np.linalg.norm(U_new - U_old, axis=1).max(initial=0.0))
        total = float(np.linalg.norm(U_new - U_rest, axis=1).max(initial=0.0))
        diag = None
    if step == 0.0:
        return 0.0
    if diag is None:
        diag = float(np.linalg.norm(np.ptp(U_rest, axis=0))) if len(U_rest) else 0.0
    return displacement_ratio(step, total, diag, floor)


def displacement_ratio(step: float, total: float, diag: float, floor: float = 1e-9) -> float:
    """:func:`relative_displacement` from its three maxima (the largest move of the iteration,
    the largest move from the rest, the rest's bounding-box diagonal)."""
    if step == 0.0:
        return 0.0
    total = max(total, floor * diag)
    return step / total if total > 0 else np.inf


#: triangles per chunk of :meth:`ArapSystem.energy` (exact)
ENERGY_CHUNK = 65536


def _summed_blocks(cell, tail, head, w, d, n: int, n_cells: int):
    """``K`` by 3x1 blocks (:meth:`ArapSystem._k_blocks`) from the per-term arrays: the terms
    ``+w d`` at (cell, head) and ``-w d`` at (cell, tail), summed per (cell, vertex)."""
    keys = np.concatenate([cell * n + head, cell * n + tail])
    uniq, inv = np.unique(keys, return_inverse=True)
    del keys
    inv = inv.reshape(-1)
    T = len(cell)
    val = np.empty((len(uniq), 3))
    for a in range(3):
        wd = w * d[:, a]
        val[:, a] = (np.bincount(inv[:T], weights=wd, minlength=len(uniq))
                     - np.bincount(inv[T:], weights=wd, minlength=len(uniq)))
    del inv
    ptr = np.concatenate([[0], np.cumsum(np.bincount(uniq // n, minlength=n_cells))])
    return (ptr.astype(np.int64), (uniq % n).astype(np.int64), np.ascontiguousarray(val))


def _spokes_and_rims_assembly(V: np.ndarray, F: np.ndarray, n: int):
    """``(blocks, rest_covariance, Q)`` of the spokes-and-rims cells, assembled per triangle.

    The same sums as :func:`_summed_blocks` and the per-term sums of :class:`ArapSystem` over the
    ``T = 9 m`` terms of :func:`spokes_and_rims_cells`, without building those terms: in a
    triangle every term of edge ``k`` is repeated for the cell of each of its three corners with
    the same value, so

    * the block of (cell of corner ``l``, vertex at corner ``j``) receives
      ``c_j = w_{j+1} d_{j+1} - w_{j+2} d_{j+2}`` (corner ``j`` is the head of edge ``j+1`` and
      the tail of edge ``j+2``), the same for every ``l``;
    * each corner's rest covariance receives ``sum_k w_k d_k d_k^T``;
    * each directed edge's weight in ``Q`` is ``3 w_k``.

    The (cell, vertex) pairs are the vertex-adjacency pattern with its diagonal (sorted by
    ``cell * n + vertex``, as :func:`_summed_blocks` orders them), so each sum is a
    ``bincount`` into that pattern. Peak memory is a few arrays of ``m`` rows: the term arrays
    (five of ``9 m`` rows, and ``np.unique`` over ``18 m`` keys) were the peak of the finished
    progressive path at 1.29M triangles (2.75 GB; 1.83 GB without them; issue 37).
    """
    m = len(F)
    P = V[F]                                            # (m, 3 corners, 3)
    tail_c, head_c = [1, 2, 0], [2, 0, 1]               # edge k: corner k+1 -> corner k+2
    a = P[:, tail_c] - P                                # corner k -> k+1
    b = P[:, head_c] - P                                # corner k -> k+2
    dot = np.einsum("fkc,fkc->fk", a, b)
    crs = np.linalg.norm(np.cross(a, b), axis=2)
    del a, b
    with np.errstate(divide="ignore", invalid="ignore"):
        w = dot / crs                                   # (m, 3): cot at corner k (edge k)
    del dot, crs
    if not np.isfinite(w).all():
        raise InvalidMeshError("The mesh has degenerate (zero-area) triangles, so the "
                               "cotangent weights are undefined. Run Clean first.")
    d = P[:, head_c] - P[:, tail_c]                     # (m, 3 edges, 3): rest edge vectors
    del P
    wd = w[:, :, None] * d
    # the pattern: every (i, j) of one triangle, i.e. the diagonal and both edge directions
    lo = np.minimum(F[:, tail_c], F[:, head_c]).ravel()
    hi = np.maximum(F[:, tail_c], F[:, head_c]).ravel()
    und = _sorted_unique(lo * n + hi)
    del lo, hi
    used = np.flatnonzero(np.bincount(F.ravel(), minlength=n))
    pattern = _sorted_unique(np.concatenate([und, (und % n) * n + und // n, used * n + used]))
    del und
    npat = len(pattern)
    diag_slot = np.zeros(n, dtype=np.int64)
    diag_slot[used] = np.searchsorted(pattern, used * n + used)
    # slot[l][j]: where (cell of corner l, vertex at corner j) of each triangle is summed
    slot = [[diag_slot[F[:, l]] if l == j else np.searchsorted(pattern, F[:, l] * n + F[:, j])
             for j in range(3)] for l in range(3)]
    del diag_slot

    val = np.zeros((npat, 3))
    qv = np.zeros(npat)
    for j in range(3):
        c = wd[:, head_c.index(j)] - wd[:, tail_c.index(j)]   # corner j: head / tail of edge
        for l in range(3):
            for ax in range(3):
                val[:, ax] += np.bincount(slot[l][j], weights=c[:, ax], minlength=npat)
        del c
    for k in range(3):
        t, h, wk = tail_c[k], head_c[k], 3.0 * w[:, k]
        for i, j, sgn in ((t, t, 1.0), (h, h, 1.0), (t, h, -1.0), (h, t, -1.0)):
            qv += sgn * np.bincount(slot[i][j], weights=wk, minlength=npat)
    del wd, slot
    rows, cols = pattern // n, pattern % n
    ptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))]).astype(np.int64)
    Q = sp.csc_matrix((qv, cols, ptr), shape=(n, n))   # symmetric: the CSR arrays are its CSC
    Q.has_sorted_indices = True
    C = np.zeros((n, 3, 3))
    for a_ in range(3):
        for b_ in range(a_, 3):
            s_ab = (w * d[:, :, a_] * d[:, :, b_]).sum(axis=1)   # sum_k w_k d_k d_k^T, per face
            for l in range(3):
                C[:, a_, b_] += np.bincount(F[:, l], weights=s_ab, minlength=n)
            C[:, b_, a_] = C[:, a_, b_]
    return (ptr, cols.astype(np.int64), val), C, Q


def _sorted_unique(x: np.ndarray) -> np.ndarray:
    """``np.unique(x)`` of an int64 array by sorting (several times faster here than
    ``np.unique`` of NumPy 2, measured on 4.5M keys)."""
    x = np.sort(x)
    keep = np.empty(len(x), dtype=bool)
    keep[:1] = True
    np.not_equal(x[1:], x[:-1], out=keep[1:])
    return x[keep]


def _as_index_array(x, n: int, what: str) -> np.ndarray:
    idx = np.asarray([] if x is None else x, dtype=np.int64).reshape(-1)
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ParameterError(f"Some {what} refer to vertices that do not exist "
                             f"(the mesh has {n} vertices).")
    return idx


class MultigridGlobalSolver:
    """The global step by multigrid: a drop-in for :class:`SPDSolver` in :class:`ArapSystem`.

    The connectivity and the matrix never change, so the Galerkin hierarchy is built once; each
    solve starts from the previous solution (consecutive ARAP iterates are close), which makes a
    global step a few V-cycles.
    """

    backend = "multigrid"

    def __init__(self, mg, A, fixed, *, rtol: float = 1e-7, maxiter: int = 200):
        self.fixed = np.asarray(fixed, dtype=np.int64)
        self.solver = mg.solver(A, fixed=self.fixed if self.fixed.size else None)
        self.rtol, self.maxiter = float(rtol), int(maxiter)
        self._last: np.ndarray | None = None
        self.cycles: list[int] = []

    def solve(self, b: np.ndarray, x_fixed: np.ndarray | None = None) -> np.ndarray:
        b = np.asarray(b, dtype=np.float64)
        x0 = self._last if self._last is not None and self._last.shape == b.shape else None
        x = self.solver.solve(b, x0=x0, rtol=self.rtol, maxiter=self.maxiter,
                              fixed_values=x_fixed if self.fixed.size else None)
        self.cycles.append(int(self.solver.last_info.get("cycles", 0)))
        self._last = x
        return x


class ArapSystem:
    """Precomputed ARAP local-global machinery for one mesh and one set of constraints.

    Parameters
    ----------
    V : (n, 3) float64 rest positions.
    F : (m, 3) int64 triangles.
    fixed : (k,) int, optional
        Vertices whose three coordinates are prescribed at solve time (fixed parts, hard handles).
    coord_constraints : tuple (indices (c,), axes (c,)), optional
        Hard per-coordinate constraints: coordinate ``axes[j]`` (0, 1, 2 for x, y, z) of vertex
        ``indices[j]`` is prescribed at solve time (plane constraints ``(U_i)_x = c``).
    soft_handles : tuple (indices (h,), weights (h,) or scalar), optional
        Soft point handles adding ``weights_h / 2 ||u_h - p_h||^2`` to the energy; targets ``p`` are
        given at solve time. Weights are absolute (compare with ``Q.diagonal()``).
    backend : str
        SPDSolver backend ("auto", "cholmod", "superlu"), or "multigrid": the global step by
        surface-multigrid V-cycles (thesis ch. 8) warm-started from the previous solution, for
        very large meshes where a factorization is too slow or too big.
    multigrid : SurfaceMultigrid, optional
        Hierarchy of this mesh for ``backend="multigrid"`` (built with defaults when omitted).
    multigrid_rtol : relative residual at which the V-cycles of one global step stop.
    cells : {"spokes_and_rims", "faces"}
        One rotation per vertex with its spokes-and-rims cell (default, ARAP), or one rotation
        per triangle with the triangle's three edges (face-only ARAP, thesis Eq. 6.4).

    Attributes
    ----------
    n : int, number of vertices.
    cells : str, the kind of cells.
    n_cells : int, number of cells (``n`` for spokes and rims, ``m`` for faces); every per-cell
        array below and every ``R`` passed in or returned has this many rows.
    K : (3 n_cells, n) csr_matrix, covariance operator (``S = (K @ U).reshape(n_cells, 3, 3)``).
    Q : (n, n) csc_matrix, global system matrix ``G^T W G`` (without soft-handle terms).
    rest_covariance : (n_cells, 3, 3), ``C_k = sum w d d^T``.
    constrained : (n, 3) bool, which coordinates are hard-constrained.
    referenced : (n,) bool, vertices used by at least one triangle.
    backend : str, the SPDSolver backend in use ("cholmod" or "superlu").
    """

    def __init__(self, V, F, *, fixed=None, coord_constraints=None, soft_handles=None,
                 backend: str = "auto", cells: str = "spokes_and_rims", multigrid=None,
                 multigrid_rtol: float = 1e-7):
        V = np.array(V, dtype=np.float64, copy=True)
        F = np.asarray(F, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise InvalidMeshError("ARAP needs a triangle mesh with at least one triangle.")
        if not np.isfinite(V).all():
            raise InvalidMeshError("The mesh has NaN or infinite coordinates; run Clean first.")
        n = len(V)
        if F.min() < 0 or F.max() >= n:
            raise InvalidMeshError("Some faces refer to vertices that do not exist. "
                                   "Validate the mesh to see which.")
        if cells not in CELL_KINDS:
            raise ParameterError(f"Unknown ARAP cells {cells!r}; use one of "
                                 f"{', '.join(CELL_KINDS)}.")
        self.V, self.F, self.n = V, F, n
        self.cells = cells
        self.n_cells = nc = n if cells == "spokes_and_rims" else len(F)
        # K[3 i + alpha, v] = sum_{t in cell i} w_t d_t[alpha] (G_t v), G_t = e_head - e_tail,
        # kept as its 3x1 blocks (duplicates summed once per (cell, vertex)), from which the
        # compiled kernels work; the sparse matrix itself (:attr:`K`) is built on first use.
        # The T per-term arrays are not kept (the exact energy recomputes them): at 1.3M
        # triangles they were 0.65 GB, K and its transpose 0.4 GB, and building K from the
        # terms directly held six arrays of 2 T entries at once (a 6 GB peak).
        self._blocks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._tblocks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._crows: tuple[np.ndarray, np.ndarray, sp.csr_matrix] | None = None
        self._K: sp.csr_matrix | None = None
        self._KT_: sp.csr_matrix | None = None
        if cells == "spokes_and_rims":
            # per triangle, without the 9 m term arrays (the set-up's peak memory)
            self._blocks, self.rest_covariance, self.Q = _spokes_and_rims_assembly(V, F, n)
        else:
            self._assemble_from_terms(*face_cells(V, F), n, nc)
        self._trace_rest_covariance = float(np.trace(self.rest_covariance, axis1=1,
                                                     axis2=2).sum())
        if compiled_kernels() is not None:
            self._kt_blocks()  # with the set-up, so the first run pays no more than the next

        self.referenced = np.zeros(n, dtype=bool)
        self.referenced[F.ravel()] = True

        # constraints
        constrained = np.zeros((n, 3), dtype=bool)
        fixed = _as_index_array(fixed, n, "fixed vertices")
        constrained[fixed] = True
        constrained[~self.referenced] = True
        if coord_constraints is not None:
            ci, ca = coord_constraints
            ci = _as_index_array(ci, n, "coordinate constraints")
            ca = np.asarray(ca, dtype=np.int64).reshape(-1)
            if ca.shape != ci.shape:
                raise ParameterError("Coordinate constraints need one axis per vertex index.")
            if ca.size and (ca.min() < 0 or ca.max() > 2):
                raise ParameterError("Coordinate constraint axes must be 0 (x), 1 (y) or 2 (z).")
            constrained[ci, ca] = True
        self.constrained = constrained

        soft_diag = np.zeros(n)
        self._soft_idx = np.zeros(0, dtype=np.int64)
        self._soft_w = np.zeros(0)
        if soft_handles is not None:
            si, sw = soft_handles
            si = _as_index_array(si, n, "soft handles")
            sw = np.broadcast_to(np.asarray(sw, dtype=np.float64), si.shape).copy()
            if (sw < 0).any() or not np.isfinite(sw).all():
                raise ParameterError("Soft handle weights must be finite and non-negative.")
            self._soft_idx, self._soft_w = si, sw
            np.add.at(soft_diag, si, sw)
        self._soft_diag = soft_diag

        self._check_definite()
        A = (self.Q + sp.diags(soft_diag)).tocsc() if soft_diag.any() else self.Q
        # group coordinates with identical constrained sets: one factorization per group
        self._groups: list[tuple[list[int], np.ndarray, SPDSolver]] = []
        done: list[int] = []
        for dim in range(3):
            if dim in done:
                continue
            same = [e for e in range(3) if e not in done
                    and np.array_equal(constrained[:, e], constrained[:, dim])]
            done += same
            fx = np.flatnonzero(constrained[:, dim])
            if backend == "multigrid":
                if multigrid is None:
                    from ..multigrid import surface_multigrid

                    multigrid = surface_multigrid(V, F)
                solver = MultigridGlobalSolver(multigrid, A, fx, rtol=multigrid_rtol)
            else:
                solver = SPDSolver(A, fx, backend=backend)
            self._groups.append((same, fx, solver))
        self.multigrid = multigrid
        self.backend = self._groups[0][2].backend

    def _assemble_from_terms(self, cell, tail, head, w, n: int, nc: int) -> None:
        """``_blocks``, ``rest_covariance`` and ``Q`` from per-term arrays (face cells)."""
        if not np.isfinite(w).all():
            raise InvalidMeshError("The mesh has degenerate (zero-area) triangles, so the "
                                   "cotangent weights are undefined. Run Clean first.")
        d = self.V[head] - self.V[tail]  # (T, 3) rest edges
        self._blocks = _summed_blocks(cell, tail, head, w, d, n, nc)
        # C_i = sum_{t in cell i} w d d^T (accumulated per entry: no (T, 9) array)
        self.rest_covariance = np.column_stack(
            [np.bincount(cell, weights=w * d[:, a] * d[:, b], minlength=nc)
             for a in range(3) for b in range(3)]).reshape(nc, 3, 3)
        # Q = G^T W G, from the weights summed per directed edge (tail, head)
        ekey, einv = np.unique(tail * n + head, return_inverse=True)
        ew = np.bincount(einv.reshape(-1), weights=w, minlength=len(ekey))
        del einv
        et, eh = ekey // n, ekey % n
        self.Q = sp.csc_matrix((np.concatenate([ew, ew, -ew, -ew]),
                                (np.concatenate([et, eh, et, eh]),
                                 np.concatenate([et, eh, eh, et]))), shape=(n, n))
        self.Q.sum_duplicates()

    def _check_definite(self) -> None:
        ncomp, lab = connected_components(self.F, self.n, over="vertices")
        anchored = self.constrained.copy()
        anchored[self._soft_idx[self._soft_w > 0]] = True
        for c in range(ncomp):
            verts = np.flatnonzero((lab == c) & self.referenced)
            if verts.size == 0:
                continue
            for dim in range(3):
                if not anchored[verts, dim].any():
                    raise ParameterError(
                        f"Part {c + 1} of the mesh (vertex {verts[0]} and {verts.size - 1} "
                        f"others) has nothing holding it in {'xyz'[dim]}: it could slide freely, "
                        "so the deformation is undefined. Fix a vertex or add a handle on it.")

    # ---------------------------------------------------------------- local step
    def covariances(self, U: np.ndarray) -> np.ndarray:
        """Per-cell covariances ``S_k = sum_{cell k} w d d~^T``.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.

        Returns
        -------
        (n_cells, 3, 3) float64; ``S_k[a, b] = sum w d[a] d~[b]``.
        """
        U = np.asarray(U, dtype=np.float64)
        kern = compiled_kernels()
        if kern is None:
            return np.asarray(self.K @ U).reshape(self.n_cells, 3, 3)
        ptr, col, val = self._k_blocks()
        S = np.empty((self.n_cells, 3, 3))
        kern.block_covariances(ptr, col, val, np.ascontiguousarray(U).reshape(self.n, 3), S)
        return S

    @property
    def K(self) -> sp.csr_matrix:
        """(3 n_cells, n) covariance operator, ``S = (K @ U).reshape(n_cells, 3, 3)`` (built
        from the blocks on first use)."""
        if self._K is None:
            self._K = self._k_from_blocks()
        return self._K

    @property
    def _KT(self) -> sp.csr_matrix:
        if self._KT_ is None:
            self._KT_ = self.K.T.tocsr()
        return self._KT_

    def _terms(self):
        """``(cell, tail, head, w, d)``: the per-term arrays of the cells (recomputed)."""
        cell, tail, head, w = (spokes_and_rims_cells(self.V, self.F)
                               if self.cells == "spokes_and_rims" else face_cells(self.V, self.F))
        return cell, tail, head, w, self.V[head] - self.V[tail]

    def _k_from_blocks(self) -> sp.csr_matrix:
        """``K`` as a CSR matrix (3 n_cells, n) built from :meth:`_k_blocks` (canonical: sorted
        column indices, no duplicates)."""
        ptr, col, val = self._k_blocks()
        counts = np.diff(ptr)
        row_counts = np.repeat(counts, 3)
        indptr = np.concatenate([[0], np.cumsum(row_counts)]).astype(np.int64)
        row = np.repeat(np.arange(3 * self.n_cells, dtype=np.int64), row_counts)
        blk = ptr[row // 3] + (np.arange(indptr[-1], dtype=np.int64) - indptr[row])
        K = sp.csr_matrix((val[blk, row % 3], col[blk], indptr),
                          shape=(3 * self.n_cells, self.n))
        K.has_canonical_format = True
        return K

    def _k_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``K`` stored by 3x1 blocks for the compiled kernels: for cell i, blocks
        ``ptr[i]:ptr[i+1]`` hold ``K[3 i + a, col[k]] = val[k, a]``."""
        if self._blocks is None:
            self._blocks = _summed_blocks(*self._terms(), self.n, self.n_cells)
        return self._blocks

    def _kt_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The same blocks in column order, for the gather of :meth:`rhs`: entries
        ``tptr[j]:tptr[j+1]`` are the blocks of column j (in increasing block index, so in
        increasing cell), ``tcell`` their cells and ``tval`` their values (contiguous copies,
        so the gather reads them sequentially)."""
        if self._tblocks is None:
            ptr, col, val = self._k_blocks()
            # The block pattern as a (cells x vertices) CSR matrix whose values are the block
            # indices; SciPy's CSR -> CSC conversion is a linear-time counting sort that keeps
            # the order of the rows within each column (the stable sort by column: at 1.3M
            # triangles 0.33 s instead of 0.58 s for argsort and repeat).
            nb = len(col)
            idx_t = np.int64 if max(nb, self.n, self.n_cells) >= 2**31 - 1 else np.int32
            pattern = sp.csr_matrix((np.arange(nb, dtype=np.int64), col.astype(idx_t, copy=False),
                                     ptr.astype(idx_t, copy=False)),
                                    shape=(self.n_cells, self.n))
            t = pattern.tocsc()
            tk = np.asarray(t.data, dtype=np.int64)
            self._tblocks = (t.indptr.astype(np.int64), t.indices.astype(np.int64),
                             np.ascontiguousarray(val[tk]))
        return self._tblocks

    def rotations(self, U: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """Optimal rotations of the local step.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        extra : (n_cells, 3, 3) float array, optional
            Added to the covariances before Procrustes (extra per-cell Procrustes terms: the
            maximized objective becomes ``tr(R_k (S_k + extra_k))``).

        Returns
        -------
        (n_cells, 3, 3) float64 proper rotations.
        """
        S = self.covariances(U)
        if extra is not None:
            S = S + np.asarray(extra, dtype=np.float64).reshape(self.n_cells, 3, 3)
        return procrustes_rotations(S)

    def scaled_rotations(self, U: np.ndarray, extra: np.ndarray | None = None,
                         extra_weight=None, *, covariances: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Local step with a per-cell scale: isotropic orthogonal Procrustes (ACAP, Eq. 6.5).

        Minimizes, for every cell ``k`` separately, over a rotation ``R_k`` and a scale
        ``s_k >= 0``::

            sum_{cell k} w/2 ||s_k R_k d - d~||^2 + (extra part)

        where the extra part is a set of further weighted vector pairs ``(x, y)`` with weights
        ``c`` (``sum c/2 ||s_k R_k x - y||^2``) given through ``extra = sum c x y^T`` and
        ``extra_weight = sum c |x|^2``. Schönemann & Carroll (1970): ``R_k`` is the Procrustes
        rotation of ``S_k + extra_k`` and
        ``s_k = max(tr(R_k (S_k + extra_k)), 0) / (tr(C_k) + extra_weight_k)``.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        extra : (n_cells, 3, 3) float array, optional (see above).
        extra_weight : (n_cells,) float array or scalar, optional (0 when omitted).
        covariances : (n_cells, 3, 3), optional, ``self.covariances(U)`` when already known.

        Returns
        -------
        R : (n_cells, 3, 3) float64 proper rotations.
        s : (n_cells,) float64 non-negative scales (1 where the cell's denominator is 0).
        """
        S = self.covariances(U) if covariances is None else np.asarray(covariances, np.float64)
        if extra is not None:
            S = S + np.asarray(extra, dtype=np.float64).reshape(self.n_cells, 3, 3)
        R = procrustes_rotations(S)
        num = np.einsum("kab,kba->k", R, S)
        den = np.trace(self.rest_covariance, axis1=1, axis2=2).copy()
        if extra_weight is not None:
            den = den + np.broadcast_to(np.asarray(extra_weight, np.float64), den.shape)
        s = np.ones(self.n_cells)
        ok = den > 0
        s[ok] = np.maximum(num[ok], 0.0) / den[ok]
        return R, s

    # ---------------------------------------------------------------- global step
    def rhs(self, R: np.ndarray) -> np.ndarray:
        """Right-hand side of the global step, ``b = K^T [R_1^T; ...; R_n^T]``.

        Parameters
        ----------
        R : (n_cells, 3, 3) float array (rotations, or any per-cell linear maps such as the
            scaled rotations ``s_k R_k``).

        Returns
        -------
        (n, 3) float64 ``b`` with ``Q U = b`` the unconstrained minimizer condition.
        """
        R = np.asarray(R, dtype=np.float64).reshape(self.n_cells, 3, 3)
        kern = compiled_kernels()
        if kern is None:
            return np.asarray(self._KT @ R.transpose(0, 2, 1).reshape(3 * self.n_cells, 3))
        tptr, tcell, tval = self._kt_blocks()
        b = np.empty((self.n, 3))
        kern.block_rhs(tptr, tcell, tval, np.ascontiguousarray(R), b)
        return b

    def solve(self, rhs: np.ndarray, fixed_values: np.ndarray | None = None,
              soft_targets: np.ndarray | None = None) -> np.ndarray:
        """Global step: minimize the energy over ``U`` subject to the hard constraints.

        Parameters
        ----------
        rhs : (n, 3) float64, usually ``self.rhs(R)`` (plus any extra linear terms).
        fixed_values : (n, 3) float array
            Prescribed positions; only the entries where ``self.constrained`` is True are read
            (fixed vertices, coordinate constraints, vertices used by no triangle). May be None
            only when nothing is constrained.
        soft_targets : (h, 3) float array, optional
            Targets of the soft handles, in the order given at construction.

        Returns
        -------
        U : (n, 3) float64; constrained entries equal ``fixed_values`` exactly.
        """
        b = np.asarray(rhs, dtype=np.float64).reshape(self.n, 3)
        if self._soft_idx.size:
            if soft_targets is None:
                raise ValueError("soft_targets is required when the system has soft handles")
            tgt = np.asarray(soft_targets, dtype=np.float64).reshape(-1, 3)
            b = b.copy()
            np.add.at(b, self._soft_idx, self._soft_w[:, None] * tgt)
        fv = None
        if self.constrained.any():
            if fixed_values is None:
                raise ValueError("fixed_values is required when the system has constraints")
            fv = np.asarray(fixed_values, dtype=np.float64).reshape(self.n, 3)
        if len(self._groups) == 1:  # the common case: one factorization, three right-hand sides
            _, fx, solver = self._groups[0]
            return solver.solve(b, fv[fx] if fx.size else None)
        U = np.empty((self.n, 3))
        for dims, fx, solver in self._groups:
            U[:, dims] = solver.solve(b[:, dims], fv[fx][:, dims] if fx.size else None)
        return U

    # ---------------------------------------------------------------- energy
    def energy(self, U: np.ndarray, R: np.ndarray, *, exact: bool = True,
               covariances: np.ndarray | None = None) -> float:
        """ARAP energy ``sum_k sum_{cell k} w/2 ||R_k d - d~||^2`` (soft handle terms excluded).

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        R : (n_cells, 3, 3) float array of per-cell rotations (or linear maps).
        exact : bool
            True (default): sum the residual of every cell entry (9 per triangle). False: the
            same value from the precomputed operators,
            ``1/2 sum tr(R C R^T) - sum tr(R S) + 1/2 tr(U^T Q U)``, several times faster but
            with an absolute round-off of about ``1e-16 * sum w |d|^2`` (it can read ~1e-15
            instead of 0 at the rest state); good for plotting.
        covariances : (n_cells, 3, 3) float array, optional
            ``self.covariances(U)`` when the caller has it already (used when ``exact`` is
            False).

        Returns
        -------
        float
        """
        U = np.asarray(U, dtype=np.float64)
        R = np.asarray(R, dtype=np.float64).reshape(self.n_cells, 3, 3)
        if not exact:
            S = self.covariances(U) if covariances is None else covariances
            kern = compiled_kernels()
            if kern is not None:
                # Q is symmetric: its CSC arrays are its CSR arrays
                quad_u = 0.5 * kern.quadratic_form(self.Q.indptr, self.Q.indices, self.Q.data,
                                                   np.ascontiguousarray(U))
                quad, lin = kern.arap_energy_terms(np.ascontiguousarray(R),
                                                   self.rest_covariance,
                                                   np.ascontiguousarray(S, dtype=np.float64))
                return float(0.5 * quad - lin + quad_u)
            quad_u = 0.5 * float(np.einsum("ij,ij->", U, self.Q @ U))
            e = (0.5 * np.einsum("nij,nij->", R @ self.rest_covariance, R)
                 - np.einsum("nij,nji->", R, S)
                 + quad_u)
            return float(e)
        # by chunks of triangles: the per-term arrays of a whole 1.3M-triangle mesh (R[cell]
        # alone 0.8 GB) would double the memory the run itself needs
        total = 0.0
        cells_of = spokes_and_rims_cells if self.cells == "spokes_and_rims" else face_cells
        for start in range(0, len(self.F), ENERGY_CHUNK):
            cell, tail, head, w = cells_of(self.V, self.F[start:start + ENERGY_CHUNK])
            if self.cells != "spokes_and_rims":
                cell = cell + start          # face cells are numbered within the chunk
            d = self.V[head] - self.V[tail]
            dt = U[head] - U[tail]
            Rd = np.einsum("tab,tb->ta", R[cell], d)
            total += float(0.5 * (w * ((Rd - dt) ** 2).sum(axis=1)).sum())
        return total

    def energy_after_solve(self, U: np.ndarray, R: np.ndarray, rhs: np.ndarray, *,
                           rotations: bool = False,
                           covariances: np.ndarray | None = None) -> float:
        """``energy(U, R, exact=False)`` right after a global step, in one dot product.

        For the local-global loops, which plot the energy after every global step.

        Parameters
        ----------
        U : (n, 3) float64, ``solve(rhs, ...)``, possibly moved afterwards by a translation of
            each connected part.
        R : (n_cells, 3, 3) the local step's rotations (or linear maps).
        rhs : (n, 3) ``self.rhs(R)``, exactly the right-hand side ``U`` was solved with.
        rotations : R are rotations (orthonormal to round-off).
        covariances : ``self.covariances(U)`` when the caller has it (used by the general path).

        Returns
        -------
        float, equal to ``energy(U, R, exact=False)`` to its round-off (about
        ``1e-16 * sum w |d|^2``).

        Notes
        -----
        Write ``b = rhs = K^T [R_1^T; ...]`` and ``S_i = K_i U``:

        * ``sum_i tr(R_i S_i) = U . b`` (the same sum regrouped), for any ``U``;
        * ``tr(R_i C_i R_i^T) = tr(C_i)`` for a rotation;
        * ``Q U = b`` on every unconstrained coordinate (that is the global step; a translation
          of a part changes neither side: ``Q`` and ``K`` map constants to zero), so
          ``U . Q U = U . b + sum_c U_c ((Q U)_c - b_c)`` over the constrained coordinates c,
          whose few rows of ``Q U`` are computed.

        So ``E = 1/2 tr C - U . b + 1/2 U . Q U = 1/2 (tr C - U . b + sum_c ...)``. Linear maps
        that are not rotations, an iterative backend (it meets ``Q U = b`` only to its
        tolerance) and soft handles (they add terms to the solved system) take the general
        path, :meth:`energy`.
        """
        U = np.ascontiguousarray(U, dtype=np.float64).reshape(self.n, 3)
        if (not rotations or self._soft_idx.size
                or self.backend not in ("cholmod", "superlu")):
            return self.energy(U, R, exact=False, covariances=covariances)
        b = np.asarray(rhs, dtype=np.float64).reshape(self.n, 3)
        e2 = self._trace_rest_covariance - float(np.einsum("ij,ij->", U, b))
        rows, mask, Q_rows = self._constrained_rows()
        if rows.size:
            e2 += float((U[rows] * (Q_rows @ U - b[rows]))[mask].sum())
        return 0.5 * e2

    def _constrained_rows(self) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
        """Vertices with a constrained coordinate, their (k, 3) mask and Q's rows (cached)."""
        if self._crows is None:
            rows = np.flatnonzero(self.constrained.any(axis=1))
            self._crows = (rows, self.constrained[rows], sp.csr_matrix(self.Q)[rows])
        return self._crows

    def soft_energy(self, U: np.ndarray, soft_targets: np.ndarray) -> float:
        """``sum_h k_h / 2 ||u_h - p_h||^2`` of the soft handles (0 when there are none)."""
        if not self._soft_idx.size:
            return 0.0
        diff = np.asarray(U)[self._soft_idx] - np.asarray(soft_targets).reshape(-1, 3)
        return float(0.5 * (self._soft_w * (diff ** 2).sum(axis=1)).sum())


@dataclass(frozen=True)
class ArapParams:
    """Parameters of plain ARAP deformation with point handles (see the module docstring)."""

    max_iterations: int = param(
        100, label="Max iterations", minimum=1, maximum=10000, step=1,
        tooltip="Upper bound on local-global iterations. Each one fits rotations, then solves "
                "for the positions.")
    rel_displacement_tol: float = param(
        1e-3, label="Stop at relative move", minimum=0.0, maximum=1.0, step=1e-4, decimals=5,
        log_scale=True,
        tooltip="Stop when the largest vertex move of an iteration is this fraction of the largest "
                "total move so far. 0 runs all iterations.")
    handle_mode: str = param(
        "hard", label="Handles", choices=HANDLE_MODES,
        tooltip="hard: handle vertices land exactly on their targets. soft: they are pulled "
                "towards them with the strength below.")
    soft_weight: float = param(
        1e3, label="Soft handle strength", minimum=1e-6, maximum=1e9, step=10.0, log_scale=True,
        advanced=True,
        tooltip="Stiffness of soft handles relative to the mesh's average stiffness per vertex. "
                "Larger values pull the handles closer to their targets.")


def arap_iter(V: np.ndarray, F: np.ndarray, handles, params: ArapParams = ArapParams(), *,
              fixed=None, initial: np.ndarray | None = None) -> Iterator[Step]:
    """ARAP deformation with point handles, one :class:`~algorithms.steps.Step` per iteration.

    Parameters
    ----------
    V : (n, 3) float64 rest positions (not modified).
    F : (m, 3) int64 triangles.
    handles : tuple (indices (k,) int, targets (k, 3) float)
        Handle vertices and where they should go.
    params : ArapParams.
    fixed : (f,) int, optional
        Vertices held at their rest positions.
    initial : (n, 3) float, optional
        Starting guess (default ``V`` with the handles moved to their targets).

    Yields
    ------
    Step with ``V`` (n, 3) and metrics ``energy`` (ARAP + soft-handle terms), ``arap`` and
    ``displacement`` (:func:`relative_displacement`); ``total`` is None while the run stops on
    ``rel_displacement_tol`` (> 0), else ``max_iterations``.
    """
    validate_params(params)
    V = np.array(V, dtype=np.float64, copy=True)
    n = len(V)
    hidx, htgt = handles if handles is not None else (np.zeros(0, np.int64), np.zeros((0, 3)))
    hidx = _as_index_array(hidx, n, "handles")
    htgt = np.asarray(htgt, dtype=np.float64).reshape(-1, 3)
    if len(htgt) != len(hidx):
        raise ParameterError("Each handle needs exactly one target position.")
    fixed = _as_index_array(fixed, n, "fixed vertices")
    known = V.copy()
    if params.handle_mode == "hard":
        known[hidx] = htgt
        system = ArapSystem(V, F, fixed=np.union1d(fixed, hidx))
        soft_targets = None
    else:
        # the stiffness scale: mean diagonal of Q over the vertices in use
        _, tail, head, w = spokes_and_rims_cells(V, np.asarray(F, np.int64))
        used = np.unique(np.asarray(F).ravel())
        qdiag = np.bincount(np.concatenate([tail, head]), weights=np.concatenate([w, w]),
                            minlength=n)
        k = params.soft_weight * float(np.mean(qdiag[used]))
        system = ArapSystem(V, F, fixed=fixed, soft_handles=(hidx, k))
        soft_targets = htgt
    if initial is None:
        U = V.copy()
        U[hidx] = htgt  # soft handles start at their targets too
    else:
        U = np.array(initial, dtype=np.float64, copy=True).reshape(n, 3)
    U[system.constrained] = known[system.constrained]
    # the run stops on the tolerance: the number of iterations is not known in advance
    total = None if params.rel_displacement_tol > 0 else params.max_iterations
    for it in range(1, params.max_iterations + 1):
        R = system.rotations(U)
        Un = system.solve(system.rhs(R), known, soft_targets)
        disp = relative_displacement(Un, U, V)
        U = Un
        e_arap = system.energy(U, R)
        e_soft = system.soft_energy(U, soft_targets) if soft_targets is not None else 0.0
        yield Step(iteration=it, total=total, V=U.copy(),
                   metrics={"energy": e_arap + e_soft, "arap": e_arap, "displacement": disp},
                   message=f"ARAP iteration {it}")
        if disp < params.rel_displacement_tol:
            break


def arap(V: np.ndarray, F: np.ndarray, handles, params: ArapParams = ArapParams(),
         **kwargs) -> np.ndarray:
    """Run :func:`arap_iter` to the end and return the final (n, 3) positions."""
    return run_to_end(arap_iter(V, F, handles, params, **kwargs)).V
