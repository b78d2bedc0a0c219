"""Successive self-parameterization: a bijective map from a fine mesh onto its decimation.

Thesis ch. 4 §4.4 and App. 4.8.2-4.8.3 (neural subdivision), ch. 8 §8.4.1-8.4.3 and App. 8.9.3
(surface multigrid). :func:`self_parameterize` collapses edges, cheapest first, until the mesh has
``target_faces`` triangles; for **every** collapse of an edge (i, j) into a new vertex k it
flattens, jointly, the edge 1-ring N(i, j) (before) and the vertex 1-ring N(k) (after) into one UV
domain whose boundary polygon they share (§8.4.2, Eq. 8.5: one joint variable U, the energy
E(before) + E(after)). A point of the fine mesh inside the edge 1-ring is carried to UV with its
barycentric coordinates in the old triangle and re-located in the new triangles there (Fig. 8.8);
points elsewhere are untouched. Composing the K single-collapse maps gives the map fine ->
coarse (Eq. 8.2); :meth:`SelfParameterization.prolongation` assembles the multigrid prolongation
(§8.4.5: 3 non-zeros per row, the barycentric coordinates).

Choices made where the text leaves room (all tested):

* **Energy**: LSCM (Lévy et al. 2002), written per triangle as the Cauchy-Riemann residuals of
  the linear map in an orthonormal frame of the 3D triangle, ``area * (|u_x - v_y|^2 + |u_y +
  v_x|^2)``. Its null space (similarities) is removed by pinning two vertices: interior edge, two
  vertices of the shared boundary polygon at their 3D distance; one endpoint on the boundary, that
  endpoint (shared by i/k) and one polygon vertex. ``flattening="arap"``: the ARAP energy of Liu
  et al. 2008 (``area * |J - R|^2`` per triangle, before and after), 10 local-global iterations
  (closed-form 2x2 rotations, prefactored dense Cholesky) started from the LSCM solution; the
  second pin's x is freed (ARAP fixes the scale itself); boundary-edge variants compare ARAP
  energies.
* **Boundary cases (§8.4.3)**. One endpoint on the mesh boundary: that endpoint stays where it is
  in 3D (whatever the strategy) and shares its UV variable with k (Fig. 8.11); the interior
  endpoint is free. A boundary edge a -> b (direction of its triangle; p the boundary vertex
  before a, q the one after b): the three joint variables of Fig. 8.12 -- k = a with (a, b, q)
  colinear, k = b with (p, a, b) colinear, and (p, a, k, b, q) colinear -- each solved with the
  colinear vertices on the x axis (``u_y = 0`` Dirichlet constraints, the first and last of them
  pinned at their 3D arc-length distance), the order along the line checked; the valid variant
  with the least energy is taken (the thesis takes the least energy; we skip variants that fail
  a check). An interior edge whose two endpoints are on the boundary is never collapsed.
* **Validity checks (App. 4.8.3)**, an edge failing one is skipped and tried again after a
  collapse next to it (and when the heap runs dry): link condition (and no valence-2 vertex, no
  closed 3-edge boundary loop); 3D face flips: every changed triangle keeps
  ``n_before . n_after > flip_delta`` (unit normals); quality ``Q = 4 sqrt(3) A / (l1^2 + l2^2 +
  l3^2) > min_quality`` for every new triangle in 3D and in UV; UV flips: every UV triangle before
  and after has positive signed area; UV overlap: angle sums -- 2 pi at i, j (before) and k
  (after) when inside the mesh, pi when on a straight boundary, and equal before and after at
  every vertex the two triangulations share (the shared polygon vertices and a shared endpoint;
  this is the angle-sum criterion applied to the polygon too, so the two triangulations tile the
  same simple polygon).
* **Strategies**: ``"midpoint"`` (shortest edge first, midpoint), ``"qslim"`` (Garland-Heckbert,
  as :mod:`algorithms.mesh.decimate`), ``"vertex_removal"`` (half-edge collapse: k is the endpoint
  with the smaller quadric error, so coarse vertices are fine vertices at their fine positions).
* **Points on edges and vertices**: a point exactly at a shared vertex is snapped to it; any other
  point is located in the new triangle where its smallest barycentric coordinate is largest,
  negative round-off is clamped and the coordinates renormalized (>= 0, sum 1 exactly to
  round-off). Every point ends in exactly one face.

* **Kept / surviving vertices** are not mapped exactly onto their coarse vertex: in an interior
  collapse the UV position of the merged vertex k is free in the joint energy, so the fine
  vertex i lands near k, not on it (measured weight on its own coarse vertex > 0.95 for
  ``keep``-protected vertices on an icosphere). Vertices of the shared polygon are mapped onto
  themselves exactly.

Report keys: ``collapses``, ``reached_target``, ``notes``, ``strategy``, ``flattening``,
``target_faces``, ``faces_fine/coarse``, ``vertices_fine/coarse``, ``rejections`` (attempts
refused, per check -- an edge retried later counts again:
link_condition, interior_edge_on_boundary, valence, face_flip, quality_3d, uv_flip, uv_overlap,
quality_uv, boundary_order, flattening_failed), ``cases`` (interior, one_endpoint_on_boundary and
the three boundary-edge variants taken), ``seconds`` (``seconds_collapse`` + ``seconds_map``),
``max_clamped`` (largest negative barycentric coordinate clamped while carrying the fine vertices;
~1e-16 when the new triangles tile the UV domain exactly), ``heap_pops``, ``compiled``.

Data kept for queries: every collapse's local faces (before and after, int32 face id + int16
local corners) and its UV coordinates (float64), about 350 bytes per collapse, so
:meth:`SelfParameterization.query` can carry any fine surface point to the coarse mesh
(App. 8.9.3), and :meth:`SelfParameterization.query_inverse` any coarse point back to the fine
mesh (the same log replayed last to first with before/after swapped; fine -> coarse -> fine
returns the same point to ~1e-9 of the bounding box, tested). The fine vertices are carried the
same way at the end (each as a corner of its first face; a point exactly on a shared vertex is
snapped, so every corner gives the same result).

Speed: the input check, the collapse loop (4-ary heap with lazy deletion, corner table), the
flattening (dense Cholesky of a ~25 x 25 system per variant) and the point replay are compiled
with Numba (:mod:`algorithms.mesh._selfparam_kernels`; ``STYLIZE3D_NUMBA=0`` runs the same code
as slow Python, 1-2 ms per collapse). Measured here (2 cores shared with other jobs, wall
time; timings vary up to ~3x with the load): midpoint + LSCM 11-30 us per collapse (igea 269k ->
67k faces 2.9 s total, 25 us per collapse; qslim 27 us; ARAP 34-39 us); hierarchy x0.25 per
level down to ~2k faces: fertility Loop-subdivided 4 times (1.15M vertices, 2.3M faces, 1.15M
collapses) 35 s, koala Loop-subdivided twice (800k vertices) 21 s, igea 4.3 s. The first call in
a process loads the compiled kernels (~0.3 s; ~25 s when they must be compiled after an update).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMeshError, ParameterError
from . import _selfparam_kernels as _k
from .decimate import check_collapse_input, vertex_quadrics

__all__ = ["SelfParameterization", "self_parameterize", "STRATEGIES", "lscm_joint_flatten"]

STRATEGIES = ("midpoint", "qslim", "vertex_removal")
FLATTENINGS = ("lscm", "arap")
ARAP_ITERATIONS = 10

_REJECTION_NAMES = {
    _k.R_LINK: "link_condition",
    _k.R_PINCH: "interior_edge_on_boundary",
    _k.R_VALENCE: "valence",
    _k.R_FLIP3D: "face_flip",
    _k.R_QUALITY3D: "quality_3d",
    _k.R_UVFLIP: "uv_flip",
    _k.R_UVOVERLAP: "uv_overlap",
    _k.R_UVQUALITY: "quality_uv",
    _k.R_BORDER: "boundary_order",
    _k.R_SOLVE: "flattening_failed",
}
_CASE_NAMES = {
    _k.C_INTERIOR: "interior",
    _k.C_ONE_BOUNDARY: "one_endpoint_on_boundary",
    _k.C_VAR1: "boundary_edge_k_at_first",
    _k.C_VAR2: "boundary_edge_k_at_second",
    _k.C_VAR3: "boundary_edge_colinear",
}


@dataclass
class _Stage:
    """The log of one self_parameterize run (per collapse: local faces before/after, UVs)."""

    K: int
    bptr: np.ndarray
    bface: np.ndarray
    bloc: np.ndarray
    aptr: np.ndarray
    aface: np.ndarray
    aloc: np.ndarray
    uptr: np.ndarray
    uv: np.ndarray
    m_fine: int
    face_remap: np.ndarray  # (m_fine,) coarse index of surviving faces, -1 otherwise
    worst: float = 0.0  # most negative coordinate clamped in the last carry()

    def carry(self, faces: np.ndarray, bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pf = np.array(faces, dtype=np.int64, copy=True)
        pb = np.array(bary, dtype=np.float64, copy=True)
        self.worst = 0.0
        if len(pf):
            self.worst = _k.replay(self.K, self.bptr, self.bface, self.bloc, self.aptr, self.aface,
                                   self.aloc, self.uptr, self.uv, self.m_fine, pf, pb, False)
        cf = self.face_remap[pf]
        if (cf < 0).any():  # pragma: no cover - would be a bug
            raise RuntimeError("self-parameterization lost a point")
        return cf, pb

    def carry_back(self, faces: np.ndarray, bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pf = np.flatnonzero(self.face_remap >= 0)[np.asarray(faces, dtype=np.int64)]
        pb = np.array(bary, dtype=np.float64, copy=True)
        self.worst = 0.0
        if len(pf):
            self.worst = _k.replay(self.K, self.aptr, self.aface, self.aloc, self.bptr, self.bface,
                                   self.bloc, self.uptr, self.uv, self.m_fine, pf, pb, True)
        return pf, pb


@dataclass
class SelfParameterization:
    """A fine mesh, its decimation and the bijective map between them.

    Attributes
    ----------
    V_fine : (n, 3) float64, F_fine : (mf, 3) int64 -- the input.
    V_coarse : (m, 3) float64, F_coarse : (k, 3) int64 -- the decimated mesh.
    coarse_to_fine : (m,) int64, fine vertex id of every coarse vertex.
    face : (n,) int64, the coarse face containing every fine vertex.
    bary : (n, 3) float64, its barycentric coordinates there (>= 0, sum 1).
    report : dict -- collapses, seconds, rejections per check, cases, reached_target, notes.

    Methods: :meth:`query` (fine points -> coarse), :meth:`query_inverse` (coarse points ->
    fine), :meth:`prolongation` (the (n, m) multigrid prolongation), :meth:`compose`.
    """

    V_fine: np.ndarray
    F_fine: np.ndarray
    V_coarse: np.ndarray
    F_coarse: np.ndarray
    coarse_to_fine: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    report: dict
    _stages: list = field(default_factory=list, repr=False)

    def query(self, fine_faces, fine_bary) -> tuple[np.ndarray, np.ndarray]:
        """Map points of the fine surface to the coarse mesh.

        Parameters
        ----------
        fine_faces : (q,) int, a face of :attr:`F_fine` per point.
        fine_bary : (q, 3) float, barycentric coordinates in it (>= 0, sum 1; round-off is
            clamped).

        Returns
        -------
        faces : (q,) int64 coarse faces; bary : (q, 3) float64 coordinates there.
        """
        f, b = self._check_points(fine_faces, fine_bary, len(self.F_fine), "fine")
        for st in self._stages:
            f, b = st.carry(f, b)
        return f, b

    def query_inverse(self, coarse_faces, coarse_bary) -> tuple[np.ndarray, np.ndarray]:
        """Map points of the coarse surface back to the fine mesh (the inverse map, §8.4.1).

        Parameters
        ----------
        coarse_faces : (q,) int, a face of :attr:`F_coarse` per point.
        coarse_bary : (q, 3) float, barycentric coordinates in it (>= 0, sum 1).

        Returns
        -------
        faces : (q,) int64 faces of :attr:`F_fine`; bary : (q, 3) float64 coordinates there.
        """
        f, b = self._check_points(coarse_faces, coarse_bary, len(self.F_coarse), "coarse")
        for st in reversed(self._stages):
            f, b = st.carry_back(f, b)
        return f, b

    def _check_points(self, faces, bary, nf, which):
        f = np.asarray(faces)
        b = np.asarray(bary, dtype=np.float64)
        if f.ndim != 1 or (f.size and f.dtype.kind not in "iu"):
            raise ParameterError(f"{which}_faces must be a 1-D array of face indices.")
        if b.shape != (len(f), 3):
            raise ParameterError(f"{which}_bary must have shape ({len(f)}, 3), got {b.shape}.")
        f = f.astype(np.int64)
        if len(f) and (f.min() < 0 or f.max() >= nf):
            raise ParameterError(f"Some query faces do not exist (the {which} mesh has {nf} "
                                 f"faces).")
        if not np.isfinite(b).all():
            raise ParameterError("The barycentric coordinates contain NaN or infinity.")
        if len(b) and (b.min() < -1e-6 or np.abs(b.sum(axis=1) - 1).max() > 1e-6):
            raise ParameterError("Barycentric coordinates must be non-negative and sum to 1.")
        b = np.clip(b, 0.0, None)
        b /= b.sum(axis=1, keepdims=True)
        return f, b

    def prolongation(self) -> sp.csr_matrix:
        """(n, m) CSR: row v holds the barycentric weights of fine vertex v on the coarse
        vertices of its coarse face (exactly 3 stored entries per row; rows sum to 1)."""
        return barycentric_prolongation(self.face, self.bary, self.F_coarse, len(self.V_coarse))

    def compose(self, coarser: "SelfParameterization") -> "SelfParameterization":
        """The map fine -> coarser.coarse, where ``coarser`` maps this coarse mesh further."""
        if (coarser.V_fine.shape != self.V_coarse.shape
                or coarser.F_fine.shape != self.F_coarse.shape
                or not np.array_equal(coarser.F_fine, self.F_coarse)
                or not np.array_equal(coarser.V_fine, self.V_coarse)):
            raise ParameterError("compose() needs a self-parameterization of this one's coarse "
                                 "mesh (coarser.V_fine/F_fine must be this V_coarse/F_coarse).")
        face, bary = coarser.query(self.face, self.bary)
        report = {"stages": [self.report, coarser.report],
                  "collapses": self.report.get("collapses", 0) + coarser.report.get("collapses", 0),
                  "seconds": self.report.get("seconds", 0.0) + coarser.report.get("seconds", 0.0),
                  "reached_target": bool(self.report.get("reached_target", True)
                                         and coarser.report.get("reached_target", True))}
        return SelfParameterization(
            V_fine=self.V_fine, F_fine=self.F_fine, V_coarse=coarser.V_coarse,
            F_coarse=coarser.F_coarse, coarse_to_fine=self.coarse_to_fine[coarser.coarse_to_fine],
            face=face, bary=bary, report=report, _stages=self._stages + coarser._stages)


# ------------------------------------------------------------------------------ building blocks
def barycentric_prolongation(face, bary, F_coarse, n_coarse: int) -> sp.csr_matrix:
    """The (n, n_coarse) CSR matrix of points given as (coarse face, barycentric coordinates):
    row i holds ``bary[i]`` on the three corners of ``F_coarse[face[i]]`` (exactly 3 stored
    entries per row, in column order; rows sum to 1 when the coordinates do)."""
    face = np.asarray(face, dtype=np.int64)
    n = len(face)
    indptr = np.arange(0, 3 * n + 1, 3, dtype=np.int64)
    P = sp.csr_matrix((np.asarray(bary, dtype=np.float64).reshape(-1).copy(),
                       np.asarray(F_coarse, dtype=np.int64)[face].reshape(-1), indptr),
                      shape=(n, int(n_coarse)))
    P.sort_indices()
    return P


def _corner_table(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """FF[f, c]: face across edge (F[f,c], F[f,c+1]) or -1; FFi: that edge's index there.

    Raises InvalidMeshError when a directed edge occurs twice (an edge with more than two
    triangles, or two neighbours oriented inconsistently).
    """
    m = len(F)
    src = F.reshape(-1)
    dst = F[:, [1, 2, 0]].reshape(-1)
    key = src * n + dst
    twin = dst * n + src
    order = np.argsort(key)
    sk = key[order]
    dup = np.flatnonzero(sk[1:] == sk[:-1])
    if dup.size:
        a, b = divmod(int(sk[dup[0]]), n)
        raise InvalidMeshError(
            f"The edge between vertices {a} and {b} is used twice in the same direction: it is "
            f"shared by more than two triangles (non-manifold), or its two triangles are "
            f"oriented inconsistently ({dup.size} such edges). Self-parameterization needs a "
            f"manifold, consistently oriented mesh; 'Clean' can fix both, except on a "
            f"one-sided part (like a Moebius strip), which must be deleted or cut in a mesh "
            f"editor.")
    pos = np.searchsorted(sk, twin)
    pos = np.minimum(pos, len(sk) - 1)
    found = sk[pos] == twin
    h = np.where(found, order[pos], -1)
    FF = np.where(found, h // 3, -1).reshape(m, 3).astype(np.int64)
    FFi = np.where(found, h % 3, -1).reshape(m, 3).astype(np.int64)
    return FF, FFi


def lscm_joint_flatten(X_before, F_before, X_after, F_after, shared, pins=None):
    """Joint LSCM flattening of two triangulations that share some vertices (Eq. 8.5).

    A small dense helper exposing the kernel used per collapse (for tests and inspection).

    Parameters
    ----------
    X_before : (nb, 3) positions of the vertices of the first patch (local ids 0..nb-1).
    F_before : (fb, 3) its triangles.
    X_after : (na, 3) positions of the vertices of the second patch.
    F_after : (fa, 3) its triangles (local ids 0..na-1).
    shared : (s, 2) int pairs (before id, after id) that are one joint variable.
    pins : two joint-variable pairs to pin (default: the first two shared), placed at (0, 0) and
        (their 3D distance, 0).

    Returns
    -------
    U_before : (nb, 2), U_after : (na, 2), energy : float.
    """
    Xb = np.asarray(X_before, dtype=np.float64)
    Xa = np.asarray(X_after, dtype=np.float64)
    Fb = np.asarray(F_before, dtype=np.int64)
    Fa = np.asarray(F_after, dtype=np.int64)
    shared = np.asarray(shared, dtype=np.int64).reshape(-1, 2)
    nb, na = len(Xb), len(Xa)
    var_b = np.arange(nb)
    var_a = np.full(na, -1)
    var_a[shared[:, 1]] = shared[:, 0]
    rest = var_a < 0
    var_a[rest] = nb + np.arange(rest.sum())
    nl = nb + int(rest.sum())
    H = np.zeros((2 * nl, 2 * nl))
    X = np.empty((3, 3))
    for t in Fb:
        X[:] = Xb[t]
        _k._lscm_add(H, X, var_b[t[0]], var_b[t[1]], var_b[t[2]])
    for t in Fa:
        X[:] = Xa[t]
        _k._lscm_add(H, X, var_a[t[0]], var_a[t[1]], var_a[t[2]])
    if pins is None:
        pins = shared[:2, 0]
    p0, p1 = int(pins[0]), int(pins[1])
    fixed = np.zeros(2 * nl, dtype=np.bool_)
    fixval = np.zeros(2 * nl)
    fixed[[2 * p0, 2 * p0 + 1, 2 * p1, 2 * p1 + 1]] = True
    fixval[2 * p1] = np.linalg.norm(Xb[p1] - Xb[p0])
    x = np.empty(2 * nl)
    ok, e = _k.lscm_solve(H, 2 * nl, fixed, fixval, x, np.empty((2 * nl, 2 * nl)),
                          np.empty(2 * nl), np.empty(2 * nl, dtype=np.int64))
    if not ok:
        raise ParameterError("The flattening system is singular (degenerate triangles?).")
    U = x.reshape(nl, 2)
    return U[var_b].copy(), U[var_a].copy(), float(e)


# ------------------------------------------------------------------------------ driver
def _check_arrays(V, F, target_faces) -> tuple[np.ndarray, np.ndarray, int]:
    """Shapes, numbers and target (the topology is checked while building the corner table)."""
    return check_collapse_input(V, F, target_faces, "Self-parameterization")


def self_parameterize(V, F, target_faces, *, strategy: str = "midpoint", flattening: str = "lscm",
                      keep=None, min_quality: float = 0.2, flip_delta: float = 0.2,
                      progress: Callable[[float], None] | None = None,
                      random_candidates: int = 0, seed: int | None = None
                      ) -> SelfParameterization:
    """Decimate to ``target_faces`` triangles while maintaining a bijective map fine -> coarse.

    Parameters
    ----------
    V : (n, 3) float64 positions; F : (mf, 3) int triangles (manifold, consistently oriented;
        closed or with boundary, any genus).
    target_faces : int, 1 <= target_faces <= mf.
    strategy : "midpoint" (default, ch. 8), "qslim" or "vertex_removal".
    flattening : "lscm" (default, conformal) or "arap" (as-rigid-as-possible, 10 local-global
        iterations started from the LSCM solution).
    keep : (k,) int, optional, vertices that must survive unmoved.
    min_quality : a collapse is refused if a new triangle has Q <= this in 3D or in UV (0.2).
    flip_delta : a collapse is refused if a changed triangle's unit normal n' has
        ``n . n' <= flip_delta`` (0.2).
    progress : optional ``callable(fraction)`` called now and then.
    random_candidates : int, 0 (default) collapses cheapest first (a priority queue); k > 0
        makes the collapses semi-random (thesis App. 4.8.5, neural subdivision's training data):
        each collapse tries the cheapest of k random edges (the thesis uses 100), where an edge
        is drawn as a random corner of a random live triangle (so a boundary edge is drawn half
        as often as an interior one). Stops (``reached_target`` False) after 2000 failed
        attempts in a row.
    seed : int, optional, seeds the semi-random draws (reproducible data).

    Returns
    -------
    SelfParameterization

    Raises
    ------
    InvalidMeshError for a mesh that is not a manifold triangle mesh (or has NaN);
    ParameterError for bad parameters. When no valid collapse is left before the target, the
    result says so (``report["reached_target"]`` False and a note).
    """
    if strategy not in STRATEGIES:
        raise ParameterError(f"Unknown decimation strategy {strategy!r}; choose one of "
                             f"{', '.join(STRATEGIES)}.")
    if flattening not in FLATTENINGS:
        raise ParameterError(f"Unknown flattening {flattening!r}; choose 'lscm' (least-squares "
                             f"conformal maps, default) or 'arap' (as-rigid-as-possible).")
    try:
        min_quality = float(min_quality)
        flip_delta = float(flip_delta)
    except (TypeError, ValueError):
        raise ParameterError("min_quality and flip_delta must be numbers.") from None
    if not 0.0 <= min_quality < 1.0:
        raise ParameterError(f"min_quality must lie in [0, 1) (got {min_quality}); the thesis "
                             f"uses 0.2.")
    if not -1.0 <= flip_delta < 1.0:
        raise ParameterError(f"flip_delta must lie in [-1, 1) (got {flip_delta}); the thesis "
                             f"uses 0.2.")
    if progress is not None and not callable(progress):
        raise ParameterError("progress must be a callable taking a fraction in [0, 1].")
    if isinstance(random_candidates, bool) or int(random_candidates) != random_candidates \
            or random_candidates < 0:
        raise ParameterError(f"random_candidates must be a whole number >= 0 (got "
                             f"{random_candidates!r}); the thesis draws 100 edges per collapse.")
    random_candidates = int(random_candidates)
    if random_candidates:
        _k.seed_random(int(seed) % (2**31 - 1) if seed is not None
                       else int(np.random.SeedSequence().entropy % (2**31 - 1)))
    t0 = time.perf_counter()
    V, F, target_faces = _check_arrays(V, F, target_faces)
    n, m = len(V), len(F)
    used = np.zeros(n, dtype=bool)
    used[F.reshape(-1)] = True
    if not used.all():
        raise InvalidMeshError(f"{int((~used).sum())} vertices are not used by any triangle (e.g. "
                               f"vertex {int(np.flatnonzero(~used)[0])}); every fine vertex needs "
                               f"a place on the coarse mesh. Run Clean to remove them first.")
    protect = np.zeros(n, dtype=np.bool_)
    if keep is not None:
        kk = np.asarray(keep).reshape(-1)
        if kk.size and (kk.dtype.kind not in "iu" or kk.min() < 0 or kk.max() >= n):
            raise ParameterError(f"'keep' must list existing vertex indices (the mesh has {n} "
                                 f"vertices).")
        protect[kk.astype(np.int64)] = True
    sid = STRATEGIES.index(strategy)

    FF, FFi = _corner_table(F, n)
    Fw = F.copy()
    vf = np.full(n, -1, dtype=np.int64)
    vf[F.reshape(-1)] = np.repeat(np.arange(m), 3)
    fans = _k.fan_sizes(F, FF, vf, n)
    bad = np.flatnonzero(fans != np.bincount(F.reshape(-1), minlength=n))
    if bad.size:
        raise InvalidMeshError(f"{bad.size} vertices join separate pieces of surface (non-manifold "
                               f"vertices, e.g. vertex {int(bad[0])}); self-parameterization "
                               f"needs a manifold mesh. 'Clean' can split them.")
    valive = vf >= 0  # unreferenced vertices take no part
    falive = np.ones(m, dtype=np.bool_)
    bnd = np.zeros(n, dtype=np.bool_)
    bf, bc = np.nonzero(FF < 0)
    bnd[F[bf, bc]] = True
    bnd[F[bf, (bc + 1) % 3]] = True
    P = V.copy()
    Q = vertex_quadrics(V, F) if sid != 0 else np.zeros((n, 10))
    stamp = np.zeros(n, dtype=np.int64)
    rej = np.zeros(n, dtype=np.bool_)
    loc = np.full(n, -1, dtype=np.int64)
    mark = np.zeros(n, dtype=np.int64)
    hcap = 3 * m + 64 * _k.CAP
    hk = np.empty((hcap, 4))
    st = np.zeros(_k.N_STATE, dtype=np.int64)
    st[_k.S_NF] = m
    counts = np.zeros(_k.N_COUNTS, dtype=np.int64)
    kmax = max(m - target_faces, 0) + 2
    bptr = np.zeros(kmax + 1, dtype=np.int64)
    aptr = np.zeros(kmax + 1, dtype=np.int64)
    uptr = np.zeros(kmax + 1, dtype=np.int64)
    # an interior collapse removes 2 faces and logs ~10 faces before, ~8 after, ~11 UVs
    est = (kmax // 2 + 1) * 11 + 8 * _k.CAP
    bface = np.empty(est, dtype=np.int32)
    bloc = np.empty((est, 3), dtype=np.int16)
    aface = np.empty(est, dtype=np.int32)
    aloc = np.empty((est, 3), dtype=np.int16)
    uv = np.empty((est, 2))

    todo = max(m - target_faces, 1)
    chunk = 20000 if progress is not None else 1 << 62
    while True:
        code = _k.collapse_loop(P, Q, Fw, FF, FFi, vf, falive, valive, bnd, protect, stamp, rej,
                                loc, mark, hk, st, counts,
                                bptr, bface, bloc, aptr, aface, aloc, uptr, uv,
                                sid, target_faces, min_quality, flip_delta, chunk,
                                FLATTENINGS.index(flattening), ARAP_ITERATIONS,
                                random_candidates)
        if code == 3:
            K = int(st[_k.S_K])
            frac = max((m - st[_k.S_NF]) / todo, 0.05)
            grow = int(max(len(bface) * 0.5, (st[_k.S_NB] / max(K, 1)) * (todo / frac - K)
                           if K else 0)) + 8 * _k.CAP
            bface = np.concatenate([bface, np.empty(grow, np.int32)])
            bloc = np.concatenate([bloc, np.empty((grow, 3), np.int16)])
            aface = np.concatenate([aface, np.empty(grow, np.int32)])
            aloc = np.concatenate([aloc, np.empty((grow, 3), np.int16)])
            uv = np.concatenate([uv, np.empty((grow, 2))])
            continue
        if progress is not None:
            progress(min(1.0, (m - st[_k.S_NF]) / todo))
        if code == 1:
            continue
        break
    reached = code == 0
    K = int(st[_k.S_K])
    notes = []
    if not reached:
        notes.append(f"Stopped at {int(st[_k.S_NF]):,} triangles instead of {target_faces:,}: no "
                     f"further edge could be collapsed without breaking a validity check "
                     f"(topology, flips, triangle quality or a bijective flattening).")
    coarse_to_fine = np.flatnonzero(valive & (vf >= 0))
    remap = np.full(n, -1, dtype=np.int64)
    remap[coarse_to_fine] = np.arange(len(coarse_to_fine))
    coarse_faces = np.flatnonzero(falive)
    face_remap = np.full(m, -1, dtype=np.int64)
    face_remap[coarse_faces] = np.arange(len(coarse_faces))
    Fc = remap[Fw[coarse_faces]]
    Vc = P[coarse_to_fine].copy()
    nB, nA, nU = int(st[_k.S_NB]), int(st[_k.S_NA]), int(st[_k.S_NU])

    def fit(a, k):  # release over-allocated buffers
        return a[:k].copy() if len(a) > 1.25 * k + 1024 else a[:k]

    stage = _Stage(K=K, bptr=fit(bptr, K + 1), bface=fit(bface, nB), bloc=fit(bloc, nB),
                   aptr=fit(aptr, K + 1), aface=fit(aface, nA), aloc=fit(aloc, nA),
                   uptr=fit(uptr, K + 1), uv=fit(uv, nU), m_fine=m, face_remap=face_remap)
    t1 = time.perf_counter()
    # carry every fine vertex: as a corner of one of its faces
    first_face = np.full(n, -1, dtype=np.int64)
    first_corner = np.zeros(n, dtype=np.int64)
    flat = F.reshape(-1)
    order = np.arange(3 * m)[::-1]
    first_face[flat[order]] = order // 3
    first_corner[flat[order]] = order % 3
    pb = np.zeros((n, 3))
    pb[np.arange(n), first_corner] = 1.0
    face, bary = stage.carry(first_face, pb)
    t2 = time.perf_counter()
    if stage.worst < -1e-9:
        notes.append(f"Some fine vertices fell outside the new triangles in the shared UV domain "
                     f"by up to {-stage.worst:.1e} (barycentric) and were clamped.")
    rejections = {name: int(counts[i]) for i, name in _REJECTION_NAMES.items()}
    cases = {name: int(counts[i]) for i, name in _CASE_NAMES.items()}
    report = {
        "collapses": K, "reached_target": bool(reached), "notes": notes,
        "strategy": strategy, "flattening": flattening, "target_faces": int(target_faces),
        "faces_fine": m, "faces_coarse": int(len(Fc)), "vertices_fine": n,
        "vertices_coarse": int(len(Vc)), "rejections": rejections, "cases": cases,
        "seconds": t2 - t0, "seconds_collapse": t1 - t0, "seconds_map": t2 - t1,
        "compiled": bool(_k.COMPILED),
        "max_clamped": float(-stage.worst), "heap_pops": int(st[_k.S_POPS]),
        "random_candidates": random_candidates,
    }
    return SelfParameterization(V_fine=V, F_fine=F, V_coarse=Vc, F_coarse=Fc,
                                coarse_to_fine=coarse_to_fine, face=face, bary=bary,
                                report=report, _stages=[stage])
