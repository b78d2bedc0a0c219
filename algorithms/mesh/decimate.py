"""Edge-collapse decimation recorded as a progressive mesh (Hoppe 1996; QSlim: Garland 1997).

:func:`decimate` collapses edges, cheapest first, until the mesh has ``target_faces`` triangles,
and **records every collapse** so that it can be undone again as a vertex split. The result, a
:class:`Decimation`, is a progressive mesh: the coarse mesh plus the list of collapses. Replaying
the collapses in reverse order (:meth:`Decimation.replay`) re-inserts the removed vertices one by
one and gives back the input faces exactly (same faces, same vertex ids, same face order); where
the re-inserted vertices go is decided by a caller-supplied ``position_fn`` (the original
positions by default). It serves affine progressive meshes (thesis §5.3.2, Alg. 4,
:mod:`algorithms.deform.progressive`) and, later, successive self-parameterization (ch. 4, 8).

A collapse ``(kept, removed)`` merges vertex ``removed`` into vertex ``kept``: the one or two
triangles on the edge disappear, every other triangle of ``removed`` uses ``kept`` instead, and
``kept`` moves to the merged position. Vertex and face ids never change: the coarse mesh is the
subset of surviving vertices and faces, renumbered (:attr:`Decimation.coarse_to_fine`,
:attr:`Decimation.coarse_faces`).

Strategies
----------
``"qslim"`` (default)
    Garland-Heckbert quadric error metric. Every vertex starts with the sum of the plane quadrics
    of its triangles, each weighted by the triangle's area; on the boundary, a plane through each
    boundary edge and perpendicular to its triangle is added with weight ``boundary_weight *
    |edge|^2`` so the boundary keeps its shape. An edge's cost is the error of the summed
    quadric at its merged position: the quadric's minimizer when the 3x3 system is well
    conditioned (``det A > 1e-9 trace(A)^3``) and the minimizer lies within one edge length of the
    midpoint, otherwise the best of the two endpoints and the midpoint.
``"midpoint"``
    Uniform mid-point collapse (shortest edge first, merged at the midpoint), the default
    coarsening of surface multigrid (ch. 8).

Where an endpoint must not move (see below) the merged vertex stays at that endpoint whatever the
strategy, and that endpoint is the one kept. Otherwise the endpoint closer to the merged position
is kept (the lower id on ties).

Validity checks (an edge failing one is skipped and looked at again after a neighbouring
collapse; the collapse order is otherwise the cost order of a binary heap):

* **Link condition** (Dey et al. 1999, with the boundary handled by a virtual vertex joined to the
  boundary): the endpoints' common neighbours are exactly the opposite corners of the edge's one
  or two triangles; an interior edge whose endpoints both lie on the boundary is never collapsed
  (it would pinch the surface); a boundary edge whose triangle closes a boundary loop of three
  edges is never collapsed; an interior opposite corner of valence 3 is never left with
  valence 2 (the tetrahedron case). Together these keep the mesh manifold and keep its genus,
  its number of boundary loops and its number of connected components.
* **Boundary stays boundary**: a boundary vertex is never merged into an interior one; an edge
  from a boundary vertex to an interior vertex keeps the boundary vertex where it is.
* **No flips, no degenerate triangles**: every triangle that survives the collapse but changes
  must keep its unit normal within ``acos(min_normal_dot)`` of where it was (default 0.2, about
  78 degrees) and a non-zero area (``|n| > 1e-12 |e|^2`` with ``e`` its unchanged edge).
* **Kept vertices** (``keep=``): these vertices are never removed and never moved (constraints of
  a later deformation live on them).

The target is a number of faces: collapses run while the mesh has more than ``target_faces``
triangles, so the result has ``target_faces`` or ``target_faces - 1`` (an interior collapse
removes two triangles). When no valid collapse is left first (a tetrahedron cannot be decimated,
a torus needs at least 14 triangles, ...), the run stops there and says so in
:attr:`Decimation.notes` (``reached_target`` is False).

Speed: quadrics, initial costs and merged positions are computed for all edges at once with
NumPy; the collapse loop runs compiled (:mod:`algorithms.mesh.decimate_kernel`, Numba: array
1-rings, an array heap) when Numba is there, else in plain Python over a heap with Python sets
(about 0.1 ms per collapse; ``engine="python"``, the reference the compiled loop is tested
against: the same collapses, except in the order of equal-cost edges). Measured here (2 shared
cores, loaded): rocker-arm Loop-subdivided 3x (1.29M triangles) -> 20k: compiled 23 s CPU and
1.3 GB peak, Python 170 s wall and 2.9 GB (``benchmarks/progressive.py``); bob -> 1k 0.16 s
against 1.2 s.
"""

from __future__ import annotations

import heapq
import math
from array import array
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from .topology import edge_flaps, nonmanifold_vertices, unique_edges

__all__ = ["STRATEGIES", "Decimation", "CollapseRecord", "decimate", "vertex_quadrics"]

STRATEGIES = ("qslim", "midpoint")

_DET_REL = 1e-9  # det(A) / trace(A)^3 below this: the quadric minimizer is not used
_DEGENERATE = 1e-24  # |n_new|^2 <= this * |e|^4: the new triangle is degenerate


# ------------------------------------------------------------------------------ quadrics
def vertex_quadrics(V: np.ndarray, F: np.ndarray, boundary_weight: float = 100.0) -> np.ndarray:
    """Garland-Heckbert quadrics of every vertex (area-weighted face planes + boundary planes).

    Parameters
    ----------
    V : (n, 3) float64 positions.
    F : (m, 3) int64 triangles (edge-manifold, consistently oriented for the boundary planes).
    boundary_weight : factor of the boundary constraint planes (weight ``factor * |edge|^2``).

    Returns
    -------
    Q : (n, 10) float64, per vertex ``(a00, a01, a02, a11, a12, a22, b0, b1, b2, c)``; the error
        of a point ``x`` is ``x^T A x + 2 b^T x + c``.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    Q = np.zeros((n, 10))
    if len(F) == 0:
        return Q
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(p1 - p0, p2 - p0)
    ln = np.linalg.norm(cr, axis=1)
    ok = ln > 0
    nrm = np.zeros_like(cr)
    nrm[ok] = cr[ok] / ln[ok, None]
    area = 0.5 * ln
    d = -(nrm * p0).sum(axis=1)
    q = _plane_quadrics(nrm, d, area)
    for c in range(3):
        for k in range(10):
            Q[:, k] += np.bincount(F[:, c], weights=q[:, k], minlength=n)
    if boundary_weight > 0:
        E, EMAP, counts = unique_edges(F)
        m = len(F)
        h = np.flatnonzero(counts[EMAP] == 1)
        if h.size:
            f = h % m
            c = h // m
            a = F[f, (c + 1) % 3]
            b = F[f, (c + 2) % 3]
            e = V[b] - V[a]
            pn = np.cross(e, nrm[f])
            pl = np.linalg.norm(pn, axis=1)
            good = pl > 0
            pn[good] /= pl[good, None]
            pn[~good] = 0.0
            pd = -(pn * V[a]).sum(axis=1)
            w = boundary_weight * (e * e).sum(axis=1)
            qb = _plane_quadrics(pn, pd, w)
            for k in range(10):
                Q[:, k] += np.bincount(a, weights=qb[:, k], minlength=n)
                Q[:, k] += np.bincount(b, weights=qb[:, k], minlength=n)
    return Q


def _plane_quadrics(nrm: np.ndarray, d: np.ndarray, w: np.ndarray) -> np.ndarray:
    x, y, z = nrm[:, 0], nrm[:, 1], nrm[:, 2]
    return w[:, None] * np.column_stack([x * x, x * y, x * z, y * y, y * z, z * z,
                                         d * x, d * y, d * z, d * d])


def _costs_vectorized(Q: np.ndarray, Pa: np.ndarray, Pb: np.ndarray, anchor_a: np.ndarray,
                      anchor_b: np.ndarray, strategy: str):
    """Costs, merged positions and 'keep a' flags of many edges (NumPy twin of ``_edge_entry``)."""
    k = len(Pa)
    mid = 0.5 * (Pa + Pb)
    if strategy == "midpoint":
        pos = mid.copy()
        cost = ((Pb - Pa) ** 2).sum(axis=1)
    else:
        a, b, c, d, e, f = (Q[:, i] for i in range(6))
        g, h, i_, qc = Q[:, 6], Q[:, 7], Q[:, 8], Q[:, 9]
        c00 = d * f - e * e
        c01 = c * e - b * f
        c02 = b * e - c * d
        c11 = a * f - c * c
        c12 = b * c - a * e
        c22 = a * d - b * b
        det = a * c00 + b * c01 + c * c02
        tr = a + d + f
        with np.errstate(divide="ignore", invalid="ignore"):
            x = -(c00 * g + c01 * h + c02 * i_) / det
            y = -(c01 * g + c11 * h + c12 * i_) / det
            z = -(c02 * g + c12 * h + c22 * i_) / det
        opt = np.column_stack([x, y, z])
        l2 = ((Pb - Pa) ** 2).sum(axis=1)
        use = (det > _DET_REL * tr ** 3) & (tr > 0) & np.isfinite(opt).all(axis=1)
        use &= ((opt - mid) ** 2).sum(axis=1) <= l2

        def err(p):
            px, py, pz = p[:, 0], p[:, 1], p[:, 2]
            return (a * px * px + 2 * b * px * py + 2 * c * px * pz + d * py * py
                    + 2 * e * py * pz + f * pz * pz + 2 * (g * px + h * py + i_ * pz) + qc)

        ca, cb, cm = err(Pa), err(Pb), err(mid)
        best = np.where(ca <= cb, 0, 1)
        best = np.where(cm < np.minimum(ca, cb), 2, best)
        cand = np.stack([Pa, Pb, mid], axis=1)
        pos = cand[np.arange(k), best]
        pos[use] = opt[use]
        with np.errstate(invalid="ignore", over="ignore"):  # x, y, z are NaN where not use
            cost = np.where(use, qc + g * x + h * y + i_ * z, np.choose(best, [ca, cb, cm]))
    pos[anchor_a] = Pa[anchor_a]
    pos[anchor_b] = Pb[anchor_b]
    if strategy != "midpoint":
        anch = anchor_a | anchor_b
        if anch.any():
            pa = pos[anch]
            qq = Q[anch]
            px, py, pz = pa[:, 0], pa[:, 1], pa[:, 2]
            cost[anch] = (qq[:, 0] * px * px + 2 * qq[:, 1] * px * py + 2 * qq[:, 2] * px * pz
                          + qq[:, 3] * py * py + 2 * qq[:, 4] * py * pz + qq[:, 5] * pz * pz
                          + 2 * (qq[:, 6] * px + qq[:, 7] * py + qq[:, 8] * pz) + qq[:, 9])
    cost = np.maximum(cost, 0.0)
    cost[anchor_a & anchor_b] = np.inf
    da = ((pos - Pa) ** 2).sum(axis=1)
    db = ((pos - Pb) ** 2).sum(axis=1)
    keep_a = np.where(anchor_a, True, np.where(anchor_b, False, da <= db))
    return cost, pos, keep_a


# ------------------------------------------------------------------------------ result
@dataclass
class CollapseRecord:
    """One edge collapse (and, read backwards, one vertex split). Ids are the input mesh's.

    Attributes
    ----------
    index : position in the collapse sequence (0 = first collapse).
    kept, removed : the surviving vertex and the vertex merged into it.
    kept_position, removed_position : (3,) their positions just before the collapse (the
        positions a split restores).
    merged_position : (3,) the position of ``kept`` just after the collapse.
    removed_faces : (r,) ids of the r = 1 (boundary edge) or 2 triangles that disappear.
    removed_face_vertices : (r, 3) their corners (in their orientation) before the collapse.
    changed_faces : (c,) ids of the triangles in which ``removed`` was replaced by ``kept``.
    changed_corners : (c,) the corner (0, 1, 2) of each changed triangle that was ``removed``.
    ring : (s,) neighbours of ``kept`` just after the collapse (the merged vertex's 1-ring).
    ring_kept, ring_removed : neighbours of ``kept`` / of ``removed`` just before (each
        contains the other endpoint).
    cost : the strategy's cost of the collapse.
    """

    index: int
    kept: int
    removed: int
    kept_position: np.ndarray
    removed_position: np.ndarray
    merged_position: np.ndarray
    removed_faces: np.ndarray
    removed_face_vertices: np.ndarray
    changed_faces: np.ndarray
    changed_corners: np.ndarray
    ring: np.ndarray
    ring_kept: np.ndarray
    ring_removed: np.ndarray
    cost: float


PositionFn = Callable[[CollapseRecord, np.ndarray], tuple]


@dataclass
class Decimation:
    """A progressive mesh: the coarse mesh and the recorded collapses (see the module docstring).

    Per-collapse data are stored in flat arrays (``K`` collapses); variable-length lists use CSR
    pointers (``*_ptr``, ``(K + 1,)``). :meth:`record` assembles one collapse as a
    :class:`CollapseRecord`.

    Attributes
    ----------
    V : (nc, 3) float64 coarse positions.
    F : (mc, 3) int64 coarse triangles (indices into ``V``).
    coarse_to_fine : (nc,) int64, the input vertex id of every coarse vertex (ascending).
    coarse_faces : (mc,) int64, the input face id of every coarse face (ascending).
    n_fine, m_fine : vertex and face counts of the input.
    kept, removed : (K,) int64 vertex ids (input numbering) of each collapse.
    kept_position, removed_position, merged_position : (K, 3) float64.
    cost : (K,) float64.
    removed_faces_ptr (K+1,), removed_faces (R,), removed_face_vertices (R, 3).
    changed_faces_ptr (K+1,), changed_faces (C,), changed_corners (C,) int8.
    ring_ptr (K+1,), ring (S,): the kept vertex's neighbours after each collapse.
    ring_kept_ptr, ring_kept, ring_removed_ptr, ring_removed: the endpoints' neighbours before.
    strategy : the strategy used; target_faces : the requested face count.
    reached_target : False when no valid collapse was left before the target.
    notes : plain-language remarks (e.g. why the target was not reached).
    """

    V: np.ndarray
    F: np.ndarray
    coarse_to_fine: np.ndarray
    coarse_faces: np.ndarray
    n_fine: int
    m_fine: int
    kept: np.ndarray
    removed: np.ndarray
    kept_position: np.ndarray
    removed_position: np.ndarray
    merged_position: np.ndarray
    cost: np.ndarray
    removed_faces_ptr: np.ndarray
    removed_faces: np.ndarray
    removed_face_vertices: np.ndarray
    changed_faces_ptr: np.ndarray
    changed_faces: np.ndarray
    changed_corners: np.ndarray
    ring_ptr: np.ndarray
    ring: np.ndarray
    ring_kept_ptr: np.ndarray
    ring_kept: np.ndarray
    ring_removed_ptr: np.ndarray
    ring_removed: np.ndarray
    strategy: str = "qslim"
    target_faces: int = 0
    reached_target: bool = True
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        """Number of collapses ``K``."""
        return len(self.kept)

    #: the arrays only :meth:`record` (so :meth:`replay` and :meth:`mesh_after`) reads
    RECORD_ONLY = ("kept_position", "removed_position", "merged_position", "cost",
                   "removed_faces_ptr", "removed_faces", "removed_face_vertices",
                   "changed_faces_ptr", "changed_faces", "changed_corners", "ring_kept_ptr",
                   "ring_kept", "ring_removed_ptr", "ring_removed")

    def drop_records(self) -> None:
        """Free the arrays that only the one-collapse-at-a-time records need (about 140 bytes
        per input triangle: 0.18 GB at 1.3M triangles). An affine progressive mesh keeps the
        collapses' order, endpoints and rings (its splits replay from those) and drops the
        rest once its split weights are fitted; :meth:`record`, :meth:`replay` and
        :meth:`mesh_after` then refuse."""
        for name in self.RECORD_ONLY:
            setattr(self, name, None)
        self.records_dropped = True

    def _need_records(self) -> None:
        if getattr(self, "records_dropped", False):
            raise ParameterError("This decimation's collapse records were freed "
                                 "(Decimation.drop_records); decimate again to replay it.")

    @property
    def fine_to_coarse(self) -> np.ndarray:
        """(n_fine,) int64: the coarse id of every surviving input vertex, -1 for removed ones."""
        out = np.full(self.n_fine, -1, dtype=np.int64)
        out[self.coarse_to_fine] = np.arange(len(self.coarse_to_fine))
        return out

    def record(self, k: int) -> CollapseRecord:
        """The ``k``-th collapse as a :class:`CollapseRecord`."""
        self._need_records()
        K = len(self)
        if not -K <= k < K:
            raise IndexError(f"collapse {k} does not exist (there are {K})")
        k = int(k) % K

        def seg(ptr, arr):
            return arr[ptr[k]:ptr[k + 1]]

        return CollapseRecord(
            index=k, kept=int(self.kept[k]), removed=int(self.removed[k]),
            kept_position=self.kept_position[k].copy(),
            removed_position=self.removed_position[k].copy(),
            merged_position=self.merged_position[k].copy(),
            removed_faces=seg(self.removed_faces_ptr, self.removed_faces).copy(),
            removed_face_vertices=seg(self.removed_faces_ptr, self.removed_face_vertices).copy(),
            changed_faces=seg(self.changed_faces_ptr, self.changed_faces).copy(),
            changed_corners=seg(self.changed_faces_ptr, self.changed_corners).astype(np.int64),
            ring=seg(self.ring_ptr, self.ring).copy(),
            ring_kept=seg(self.ring_kept_ptr, self.ring_kept).copy(),
            ring_removed=seg(self.ring_removed_ptr, self.ring_removed).copy(),
            cost=float(self.cost[k]))

    def clusters(self) -> np.ndarray:
        """(n_fine,) int64: the coarse vertex every input vertex was (eventually) merged into."""
        lab = self.fine_to_coarse
        kept, removed = self.kept, self.removed
        if _compiled_loop() is not None:
            return _KERNEL.get().propagate_clusters(lab, kept, removed)
        for k in range(len(self) - 1, -1, -1):
            lab[removed[k]] = lab[kept[k]]
        return lab

    def replay(self, coarse_positions=None, position_fn: PositionFn | None = None, *,
               until: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Undo the collapses in reverse order (vertex splits) down to collapse ``until``.

        Parameters
        ----------
        coarse_positions : (nc, 3) float, optional
            Positions of the coarse vertices to start from (default: :attr:`V`).
        position_fn : callable, optional
            ``position_fn(record, P) -> (p_kept, p_removed)`` is called before each split with
            the :class:`CollapseRecord` and the current positions ``P`` (n_fine, 3) (rows of
            vertices not inserted yet are NaN; ``record.ring`` are the current neighbours of
            ``record.kept``); it returns the new positions of the two endpoints. Default: the
            recorded positions (``record.kept_position``, ``record.removed_position``), which
            rebuilds the input exactly.
        until : int
            Stop after re-inserting collapse ``until`` (0 = all the way back to the input);
            ``until = K`` gives the coarse mesh in input numbering.

        Returns
        -------
        P : (n_fine, 3) float64 positions (NaN rows for vertices still removed).
        F : (m', 3) int64 triangles of that level in input vertex ids, ordered by input face
            id; for ``until = 0`` exactly the input faces.
        """
        self._need_records()
        K = len(self)
        if not 0 <= until <= K:
            raise ParameterError(f"'until' must be between 0 and {K} (got {until}).")
        P = np.full((self.n_fine, 3), np.nan)
        if coarse_positions is None:
            coarse_positions = self.V
        coarse_positions = np.asarray(coarse_positions, dtype=np.float64)
        if coarse_positions.shape != self.V.shape:
            raise ParameterError(f"The coarse positions must have shape {self.V.shape}, got "
                                 f"{coarse_positions.shape}.")
        P[self.coarse_to_fine] = coarse_positions
        Fw = np.full((self.m_fine, 3), -1, dtype=np.int64)
        Fw[self.coarse_faces] = self.coarse_to_fine[self.F]
        alive = np.zeros(self.m_fine, dtype=bool)
        alive[self.coarse_faces] = True
        for k in range(K - 1, until - 1, -1):
            c0, c1 = self.changed_faces_ptr[k], self.changed_faces_ptr[k + 1]
            Fw[self.changed_faces[c0:c1], self.changed_corners[c0:c1]] = self.removed[k]
            r0, r1 = self.removed_faces_ptr[k], self.removed_faces_ptr[k + 1]
            Fw[self.removed_faces[r0:r1]] = self.removed_face_vertices[r0:r1]
            alive[self.removed_faces[r0:r1]] = True
            if position_fn is None:
                P[self.kept[k]] = self.kept_position[k]
                P[self.removed[k]] = self.removed_position[k]
            else:
                pk, pr = position_fn(self.record(k), P)
                P[self.kept[k]] = pk
                P[self.removed[k]] = pr
        return P, Fw[alive]

    def mesh_after(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The mesh after the first ``k`` collapses, compacted.

        Returns
        -------
        V_k : (n_k, 3) float64 positions of the vertices alive at that level (ascending input id).
        F_k : (m_k, 3) int64 triangles indexing ``V_k``.
        """
        P, Fk = self.replay(until=k)
        ids = np.flatnonzero(~np.isnan(P[:, 0]))
        remap = np.full(self.n_fine, -1, dtype=np.int64)
        remap[ids] = np.arange(len(ids))
        return P[ids], remap[Fk]


# ------------------------------------------------------------------------------ driver
def check_collapse_input(V, F, target_faces, what: str = "Decimation"
                         ) -> tuple[np.ndarray, np.ndarray, int]:
    """Shapes, numbers and the target of an edge-collapse method (decimation, successive
    self-parameterization); ``what`` names the method in the messages. Returns float64 ``V``,
    int64 ``F`` and the target as an int."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise InvalidMeshError(f"{what} needs vertex positions as an (n, 3) array, got shape "
                               f"{V.shape}.")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise InvalidMeshError(f"{what} needs a triangle mesh with at least one triangle.")
    if F.dtype.kind not in "iu":
        raise InvalidMeshError("Face indices must be whole numbers.")
    F = np.ascontiguousarray(F, dtype=np.int64)
    if F.min() < 0 or F.max() >= len(V):
        raise InvalidMeshError(f"Some faces refer to vertices that do not exist (the mesh has "
                               f"{len(V)} vertices).")
    if not np.isfinite(V).all():
        raise InvalidMeshError("The mesh has NaN or infinite coordinates; run Clean first.")
    if ((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])).any():
        raise InvalidMeshError("Some triangles use the same vertex twice; run Clean first.")
    if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)):
        if isinstance(target_faces, float) and float(target_faces).is_integer():
            target_faces = int(target_faces)
        else:
            raise ParameterError(f"The target number of triangles must be a whole number (got "
                                 f"{target_faces!r}).")
    target_faces = int(target_faces)
    if target_faces < 1:
        raise ParameterError(f"The target number of triangles must be at least 1 (got "
                             f"{target_faces}).")
    if target_faces > len(F):
        raise ParameterError(f"The target of {target_faces:,} triangles is larger than the mesh "
                             f"itself ({len(F):,} triangles); decimation can only remove "
                             f"triangles. Choose a target below {len(F):,}.")
    return V, F, target_faces


def _check_input(V, F, target_faces) -> tuple[np.ndarray, np.ndarray, int]:
    V, F, target_faces = check_collapse_input(V, F, target_faces, "Decimation")
    edge_flaps(F)  # raises a readable error for non-manifold edges / inconsistent orientation
    bad = nonmanifold_vertices(F, len(V))
    if bad.size:
        raise InvalidMeshError(f"{bad.size} vertices join separate pieces of surface (non-manifold "
                               f"vertices, e.g. vertex {int(bad[0])}); decimation needs a manifold "
                               f"mesh. 'Clean' can split them.")
    return V, F, target_faces


_KERNEL = None  # the algorithms.compiled.KernelModule of decimate_kernel, made on first use


def _compiled_loop():
    """The compiled collapse loop (:mod:`algorithms.mesh.decimate_kernel`), or None when Numba
    is missing or switched off (``STYLIZE3D_NUMBA=0``; :mod:`algorithms.compiled`)."""
    global _KERNEL
    if _KERNEL is None:
        from ..compiled import KernelModule

        _KERNEL = KernelModule("algorithms.mesh.decimate_kernel")
    module = _KERNEL.get()
    return None if module is None else module.collapse_loop


def _from_kernel(out, V, F, strategy: str, target: int) -> Decimation:
    """A :class:`Decimation` from the compiled loop's arrays."""
    (P, Fm, falive, alive, nf, reached, K, r_kept, r_removed, r_pos, r_cost, rf_cnt, rf_ids,
     rf_tri, cf_cnt, cf_ids, cf_corner, ring_cnt, ring, rk_cnt, rk, rr_cnt, rr) = out

    def ptr(cnt):
        p = np.zeros(len(cnt) + 1, dtype=np.int64)
        np.cumsum(cnt, out=p[1:])
        return p

    n = len(V)
    coarse_to_fine = np.flatnonzero(alive)
    remap = np.full(n, -1, dtype=np.int64)
    remap[coarse_to_fine] = np.arange(len(coarse_to_fine))
    coarse_faces = np.flatnonzero(falive)
    notes: list[str] = []
    if not reached:
        notes.append(f"Decimation stopped at {int(nf):,} triangles instead of {target:,}: "
                     f"no further edge could be collapsed without changing the topology or "
                     f"folding triangles over.")
    return Decimation(
        V=np.ascontiguousarray(P[coarse_to_fine]), F=remap[Fm[coarse_faces]],
        coarse_to_fine=coarse_to_fine, coarse_faces=coarse_faces, n_fine=n, m_fine=len(F),
        kept=r_kept.copy(), removed=r_removed.copy(),
        kept_position=r_pos[:, 0:3].copy(), removed_position=r_pos[:, 3:6].copy(),
        merged_position=r_pos[:, 6:9].copy(), cost=r_cost.copy(),
        removed_faces_ptr=ptr(rf_cnt), removed_faces=rf_ids.copy(),
        removed_face_vertices=rf_tri.reshape(-1, 3).copy(),
        changed_faces_ptr=ptr(cf_cnt), changed_faces=cf_ids.copy(),
        changed_corners=cf_corner.copy(),
        ring_ptr=ptr(ring_cnt), ring=ring.copy(),
        ring_kept_ptr=ptr(rk_cnt), ring_kept=rk.copy(),
        ring_removed_ptr=ptr(rr_cnt), ring_removed=rr.copy(),
        strategy=strategy, target_faces=target, reached_target=bool(reached), notes=notes)


def decimate(V, F, target_faces: int, *, strategy: str = "qslim", keep=None,
             boundary_weight: float = 100.0, min_normal_dot: float = 0.2,
             engine: str = "auto") -> Decimation:
    """Collapse edges until the mesh has ``target_faces`` triangles, recording every collapse.

    Parameters
    ----------
    V : (n, 3) float64 positions.
    F : (m, 3) int64 triangles; edge- and vertex-manifold, consistently oriented (closed, with
        boundary, any genus, several components).
    target_faces : int, 1 <= target_faces <= m.
    strategy : "qslim" (quadric error, default) or "midpoint" (shortest edge, mid-point).
    keep : (k,) int, optional, vertices that must survive unmoved.
    boundary_weight : weight of the boundary-preserving quadrics (qslim).
    min_normal_dot : a collapse is refused if a changed triangle's unit normal turns so that
        its dot product with the old one falls below this (0.2: about 78 degrees; -1 allows
        everything but degenerate triangles).
    engine : "auto" (the compiled loop when Numba is available, else plain Python),
        "compiled" or "python" (the reference; same checks, much slower).

    Returns
    -------
    Decimation (coarse mesh, collapse records, replay).

    Raises
    ------
    ParameterError for a bad target or strategy; InvalidMeshError for a mesh that is not a
    manifold triangle mesh.
    """
    if strategy not in STRATEGIES:
        raise ParameterError(f"Unknown decimation strategy {strategy!r}; choose one of "
                             f"{', '.join(STRATEGIES)}.")
    if engine not in ("auto", "compiled", "python"):
        raise ParameterError(f"Unknown decimation engine {engine!r}; choose auto, compiled or "
                             f"python.")
    if not -1.0 <= float(min_normal_dot) <= 1.0:
        raise ParameterError("min_normal_dot must lie between -1 and 1.")
    V, F, target_faces = _check_input(V, F, target_faces)
    n, m = len(V), len(F)
    protect = np.zeros(n, dtype=bool)
    if keep is not None:
        kk = np.asarray(keep, dtype=np.int64).reshape(-1)
        if kk.size and (kk.min() < 0 or kk.max() >= n):
            raise ParameterError(f"Some vertices to keep do not exist (the mesh has {n} "
                                 f"vertices).")
        protect[kk] = True

    E, EMAP, counts = unique_edges(F)
    bnd = np.zeros(n, dtype=bool)
    be = E[counts == 1]
    bnd[be.ravel()] = True
    Q = (vertex_quadrics(V, F, boundary_weight) if strategy == "qslim" else np.zeros((n, 10)))

    # initial heap, vectorized
    a, b = E[:, 0], E[:, 1]
    anch_a = protect[a] | (bnd[a] & ~bnd[b])
    anch_b = protect[b] | (bnd[b] & ~bnd[a])
    cost, pos, keep_a = _costs_vectorized(Q[a] + Q[b], V[a], V[b], anch_a, anch_b, strategy)
    feas = np.isfinite(cost)
    kernel = _compiled_loop() if engine != "python" else None
    if engine == "compiled" and kernel is None:
        raise ParameterError("The compiled decimation needs Numba, which is not available "
                             "(or STYLIZE3D_NUMBA=0).")
    if kernel is not None:
        del pos, keep_a
        out = kernel(V, F, Q, bnd, protect, a[feas].copy(), b[feas].copy(),
                     cost[feas].copy(), strategy == "midpoint", float(min_normal_dot),
                     int(target_faces))
        return _from_kernel(out, V, F, strategy, target_faces)
    zeros = [0] * int(feas.sum())
    heap = list(zip(cost[feas].tolist(), range(int(feas.sum())), a[feas].tolist(),
                    b[feas].tolist(), zeros, zeros, keep_a[feas].tolist(),
                    pos[feas, 0].tolist(), pos[feas, 1].tolist(), pos[feas, 2].tolist()))
    heapq.heapify(heap)

    state = _Loop(V, F, Q, bnd, protect, strategy, float(min_normal_dot))
    state.counter = len(heap)
    notes: list[str] = []
    reached = state.run(heap, target_faces)
    if not reached:
        notes.append(f"Decimation stopped at {state.nf:,} triangles instead of {target_faces:,}: "
                     f"no further edge could be collapsed without changing the topology or "
                     f"folding triangles over.")
    return state.result(strategy, target_faces, reached, notes)


class _Loop:
    """The sequential collapse loop (plain Python data structures for speed)."""

    def __init__(self, V, F, Q, bnd, protect, strategy, min_dot):
        n = len(V)
        self.n, self.m = n, len(F)
        self.P = V.tolist()
        self.Q = [tuple(r) for r in Q.tolist()]
        self.Fl = F.tolist()
        vf = [set() for _ in range(n)]
        for f, (x, y, z) in enumerate(self.Fl):
            vf[x].add(f)
            vf[y].add(f)
            vf[z].add(f)
        self.vf = vf
        self.alive = [True] * n
        self.falive = bytearray(b"\x01") * len(F)
        self.stamp = [0] * n
        self.bnd = bnd.tolist()
        self.protect = protect.tolist()
        self.midpoint = strategy == "midpoint"
        self.min_dot = min_dot
        self.nf = len(F)
        self.counter = 0
        self.rejected: dict[int, set] = {}
        # records
        self.r_kept = array("q")
        self.r_removed = array("q")
        self.r_pos = array("d")  # kept before, removed before, merged: 9 per collapse
        self.r_cost = array("d")
        self.rf_cnt = array("q")
        self.rf_ids = array("q")
        self.rf_tri = array("q")
        self.cf_cnt = array("q")
        self.cf_ids = array("q")
        self.cf_corner = array("b")
        self.ring_cnt = array("q")
        self.ring = array("q")
        self.rk_cnt = array("q")
        self.rk = array("q")
        self.rr_cnt = array("q")
        self.rr = array("q")

    # -- costs ------------------------------------------------------------------------
    def entry(self, u: int, v: int):
        """Heap entry of edge (u, v) with current data, or None if it can never collapse."""
        bnd, protect, P = self.bnd, self.protect, self.P
        au = protect[u] or (bnd[u] and not bnd[v])
        av = protect[v] or (bnd[v] and not bnd[u])
        if au and av:
            return None
        pu, pv = P[u], P[v]
        if self.midpoint:
            ex, ey, ez = pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]
            cost = ex * ex + ey * ey + ez * ez
            if au:
                x, y, z = pu
            elif av:
                x, y, z = pv
            else:
                x, y, z = 0.5 * (pu[0] + pv[0]), 0.5 * (pu[1] + pv[1]), 0.5 * (pu[2] + pv[2])
        else:
            qu, qv = self.Q[u], self.Q[v]
            a = qu[0] + qv[0]
            b = qu[1] + qv[1]
            c = qu[2] + qv[2]
            d = qu[3] + qv[3]
            e = qu[4] + qv[4]
            f = qu[5] + qv[5]
            g = qu[6] + qv[6]
            h = qu[7] + qv[7]
            i = qu[8] + qv[8]
            k = qu[9] + qv[9]
            if au or av:
                x, y, z = pu if au else pv
                cost = (a * x * x + 2 * b * x * y + 2 * c * x * z + d * y * y + 2 * e * y * z
                        + f * z * z + 2 * (g * x + h * y + i * z) + k)
            else:
                c00 = d * f - e * e
                c01 = c * e - b * f
                c02 = b * e - c * d
                det = a * c00 + b * c01 + c * c02
                tr = a + d + f
                done = False
                mx, my, mz = 0.5 * (pu[0] + pv[0]), 0.5 * (pu[1] + pv[1]), 0.5 * (pu[2] + pv[2])
                if tr > 0 and det > _DET_REL * tr * tr * tr:
                    c11 = a * f - c * c
                    c12 = b * c - a * e
                    c22 = a * d - b * b
                    x = -(c00 * g + c01 * h + c02 * i) / det
                    y = -(c01 * g + c11 * h + c12 * i) / det
                    z = -(c02 * g + c12 * h + c22 * i) / det
                    ex, ey, ez = pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]
                    dx, dy, dz = x - mx, y - my, z - mz
                    if dx * dx + dy * dy + dz * dz <= ex * ex + ey * ey + ez * ez:
                        cost = k + g * x + h * y + i * z
                        done = True
                if not done:
                    best = None
                    for (x1, y1, z1) in (pu, pv, (mx, my, mz)):
                        cc = (a * x1 * x1 + 2 * b * x1 * y1 + 2 * c * x1 * z1 + d * y1 * y1
                              + 2 * e * y1 * z1 + f * z1 * z1 + 2 * (g * x1 + h * y1 + i * z1) + k)
                        if best is None or cc < best:
                            best, x, y, z = cc, x1, y1, z1
                    cost = best
            if cost < 0.0:
                cost = 0.0
        if au:
            keep_u = True
        elif av:
            keep_u = False
        else:
            du = (x - pu[0]) ** 2 + (y - pu[1]) ** 2 + (z - pu[2]) ** 2
            dv = (x - pv[0]) ** 2 + (y - pv[1]) ** 2 + (z - pv[2]) ** 2
            keep_u = du <= dv
        self.counter += 1
        return (cost, self.counter, u, v, self.stamp[u], self.stamp[v], keep_u, x, y, z)

    def neighbours(self, v: int) -> set:
        s = set()
        Fl = self.Fl
        for f in self.vf[v]:
            s.update(Fl[f])
        s.discard(v)
        return s

    def reject(self, u: int, v: int) -> None:
        rej = self.rejected
        rej.setdefault(u, set()).add(v)
        rej.setdefault(v, set()).add(u)

    # -- loop ---------------------------------------------------------------------------
    def run(self, heap: list, target: int) -> bool:
        heappop, heappush = heapq.heappop, heapq.heappush
        alive, stamp, vf, Fl, P, bnd = self.alive, self.stamp, self.vf, self.Fl, self.P, self.bnd
        min_dot = self.min_dot
        collapsed_since_rebuild = 0
        rebuilt = False
        while self.nf > target:
            if not heap:
                if rebuilt and collapsed_since_rebuild == 0:
                    return False
                heap = self.rebuild()
                rebuilt = True
                collapsed_since_rebuild = 0
                if not heap:
                    return False
                continue
            cost, _, u, v, su, sv, keep_u, x, y, z = heappop(heap)
            if not (alive[u] and alive[v]) or stamp[u] != su or stamp[v] != sv:
                continue
            if keep_u:
                i, j = u, v
            else:
                i, j = v, u
            fi, fj = vf[i], vf[j]
            shared = fi & fj
            ns = len(shared)
            if ns == 0:
                continue
            Ni = self.neighbours(i)
            Nj = self.neighbours(j)
            opp = set()
            for f in shared:
                t = Fl[f]
                opp.add(t[0] + t[1] + t[2] - i - j)
            if len(opp) != ns or (Ni & Nj) != opp:
                self.reject(u, v)
                continue
            ok = True
            if ns == 2:
                if bnd[i] and bnd[j]:
                    ok = False
                else:
                    for o in opp:
                        if not bnd[o] and len(vf[o]) <= 3:
                            ok = False
                            break
            else:
                (o,) = opp
                if len(fi & vf[o]) == 1 and len(fj & vf[o]) == 1:
                    ok = False
            if not ok:
                self.reject(u, v)
                continue
            # geometry: no flips, no degenerate triangles
            for f in (fi | fj) - shared:
                t = Fl[f]
                if t[0] == i or t[0] == j:
                    mv, o1, o2 = t[0], t[1], t[2]
                elif t[1] == i or t[1] == j:
                    mv, o1, o2 = t[1], t[2], t[0]
                else:
                    mv, o1, o2 = t[2], t[0], t[1]
                p1, p2, pm = P[o1], P[o2], P[mv]
                ex, ey, ez = p2[0] - p1[0], p2[1] - p1[1], p2[2] - p1[2]
                # old normal: (p1 - pm) x (p2 - pm) = (p1 - pm) x e
                ax, ay, az = p1[0] - pm[0], p1[1] - pm[1], p1[2] - pm[2]
                nox, noy, noz = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
                bx, by, bz = p1[0] - x, p1[1] - y, p1[2] - z
                nnx, nny, nnz = by * ez - bz * ey, bz * ex - bx * ez, bx * ey - by * ex
                nn2 = nnx * nnx + nny * nny + nnz * nnz
                e2 = ex * ex + ey * ey + ez * ez
                if nn2 <= _DEGENERATE * e2 * e2:
                    ok = False
                    break
                no2 = nox * nox + noy * noy + noz * noz
                if no2 > _DEGENERATE * e2 * e2:
                    dot = nox * nnx + noy * nny + noz * nnz
                    if dot <= min_dot * math.sqrt(no2 * nn2):
                        ok = False
                        break
            if not ok:
                self.reject(u, v)
                continue
            self.collapse(i, j, (x, y, z), cost, shared, Ni, Nj)
            collapsed_since_rebuild += 1
            ring = self.last_ring
            for w in ring:
                ent = self.entry(i, w)
                if ent is not None:
                    heappush(heap, ent)
            rej = self.rejected
            if rej:
                for w in ring:
                    partners = rej.pop(w, None)
                    if partners:
                        for t2 in partners:
                            if alive[t2] and t2 != i:
                                rej.get(t2, set()).discard(w)
                                ent = self.entry(w, t2)
                                if ent is not None:
                                    heappush(heap, ent)
                rej.pop(i, None)
                rej.pop(j, None)
        return True

    def rebuild(self) -> list:
        """A fresh heap of every current edge (used when the heap runs dry)."""
        self.rejected.clear()
        seen = set()
        heap = []
        for f in range(self.m):
            if not self.falive[f]:
                continue
            t = self.Fl[f]
            for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                key = (u, v) if u < v else (v, u)
                if key in seen:
                    continue
                seen.add(key)
                ent = self.entry(*key)
                if ent is not None:
                    heap.append(ent)
        heapq.heapify(heap)
        return heap

    def collapse(self, i: int, j: int, pos, cost: float, shared: set, Ni: set, Nj: set) -> None:
        Fl, vf = self.Fl, self.vf
        pi, pj = self.P[i], self.P[j]
        self.r_kept.append(i)
        self.r_removed.append(j)
        self.r_pos.extend(pi)
        self.r_pos.extend(pj)
        self.r_pos.extend(pos)
        self.r_cost.append(cost)
        sh = sorted(shared)
        self.rf_cnt.append(len(sh))
        for f in sh:
            t = Fl[f]
            self.rf_ids.append(f)
            self.rf_tri.extend(t)
            for w in t:
                if w != i and w != j:
                    vf[w].discard(f)
            self.falive[f] = 0
        fi, fj = vf[i], vf[j]
        fj -= shared
        changed = sorted(fj)
        self.cf_cnt.append(len(changed))
        for f in changed:
            t = Fl[f]
            c = 0 if t[0] == j else (1 if t[1] == j else 2)
            t[c] = i
            self.cf_ids.append(f)
            self.cf_corner.append(c)
        fi -= shared
        fi |= fj
        vf[j] = set()
        self.alive[j] = False
        self.P[i] = list(pos)
        qi, qj = self.Q[i], self.Q[j]
        self.Q[i] = tuple(p + q for p, q in zip(qi, qj))
        self.bnd[i] = self.bnd[i] or self.bnd[j]
        self.stamp[i] += 1
        self.stamp[j] += 1
        self.nf -= len(sh)
        ring = (Ni | Nj)
        ring.discard(i)
        ring.discard(j)
        self.last_ring = ring
        self.ring_cnt.append(len(ring))
        self.ring.extend(sorted(ring))
        self.rk_cnt.append(len(Ni))
        self.rk.extend(sorted(Ni))
        self.rr_cnt.append(len(Nj))
        self.rr.extend(sorted(Nj))

    # -- result -------------------------------------------------------------------------
    def result(self, strategy, target, reached, notes) -> Decimation:
        def ptr(cnt):
            out = np.zeros(len(cnt) + 1, dtype=np.int64)
            np.cumsum(np.frombuffer(cnt, dtype=np.int64) if len(cnt) else np.zeros(0, np.int64),
                      out=out[1:])
            return out

        def ints(arr):
            return np.array(arr, dtype=np.int64) if len(arr) else np.zeros(0, np.int64)

        K = len(self.r_kept)
        pos = np.array(self.r_pos, dtype=np.float64).reshape(K, 9) if K else np.zeros((0, 9))
        alive = np.array(self.alive, dtype=bool)
        coarse_to_fine = np.flatnonzero(alive)
        remap = np.full(self.n, -1, dtype=np.int64)
        remap[coarse_to_fine] = np.arange(len(coarse_to_fine))
        falive = np.frombuffer(bytes(self.falive), dtype=np.uint8).astype(bool)
        coarse_faces = np.flatnonzero(falive)
        Fl = self.Fl
        Fc = remap[np.array([Fl[f] for f in coarse_faces], dtype=np.int64).reshape(-1, 3)]
        Vc = np.array([self.P[v] for v in coarse_to_fine], dtype=np.float64).reshape(-1, 3)
        return Decimation(
            V=Vc, F=Fc, coarse_to_fine=coarse_to_fine, coarse_faces=coarse_faces,
            n_fine=self.n, m_fine=self.m,
            kept=ints(self.r_kept), removed=ints(self.r_removed),
            kept_position=pos[:, 0:3].copy(), removed_position=pos[:, 3:6].copy(),
            merged_position=pos[:, 6:9].copy(),
            cost=np.array(self.r_cost, dtype=np.float64),
            removed_faces_ptr=ptr(self.rf_cnt), removed_faces=ints(self.rf_ids),
            removed_face_vertices=ints(self.rf_tri).reshape(-1, 3),
            changed_faces_ptr=ptr(self.cf_cnt), changed_faces=ints(self.cf_ids),
            changed_corners=np.array(self.cf_corner, dtype=np.int8),
            ring_ptr=ptr(self.ring_cnt), ring=ints(self.ring),
            ring_kept_ptr=ptr(self.rk_cnt), ring_kept=ints(self.rk),
            ring_removed_ptr=ptr(self.rr_cnt), ring_removed=ints(self.rr),
            strategy=strategy, target_faces=target, reached_target=reached, notes=notes)
