"""Geometry-only multigrid hierarchy of a triangle mesh (thesis §8.4-8.5, Alg. 8 line 2).

:func:`surface_multigrid` coarsens the mesh level by level (face count × ``ratio`` per level, 0.25
by default) while the next level keeps at least ``min_vertices`` vertices (500 by default: the
estimate ``ratio * |V_h|`` must reach it), and stores one prolongation per level: a sparse
``|V_h| x |V_{h+1}|`` matrix with 3 non-zeros per row, the barycentric coordinates of each fine
vertex in a triangle of the coarse mesh (rows sum to 1, so constants are reproduced exactly).

Prolongation sources (pluggable, ``prolongation=``):

``"intrinsic"`` (default, the thesis's method)
    successive self-parameterization (:func:`algorithms.mesh.selfparam.self_parameterize`):
    every fine vertex is tracked through the collapses of a mid-point decimation and its
    barycentric coordinates on the coarse mesh come from the joint flattenings (§8.4.2-8.4.3).
``"closest_point"`` (the naive extrinsic baseline of Fig. 8.15)
    decimate with :func:`algorithms.mesh.decimate.decimate` and take, for every fine vertex,
    the closest point on the coarse mesh (``igl.point_mesh_squared_distance``) and its
    barycentric coordinates in that triangle (clamped to the triangle, renormalized).

Robustness on real meshes (our additions, issue 10; each recorded in ``report["notes"]``):

* **Seed vertices** (``seeded=True``, default with the intrinsic prolongation). Shortest-edge
  mid-point collapses make the coarse mesh uniform: on a graded mesh (a scan with a finely
  tessellated region, camelhead's 4 decades of vertex areas) the fine region loses nearly all
  its vertices at the first level, the coarse space cannot represent its error there and the
  V-cycle stalls (rate 0.85 on camelhead's screened Laplacian). Every level therefore keeps a
  maximal independent set of the vertex graph (:func:`spread_seeds`, about a quarter of the
  vertices, as dense as the mesh is) through ``self_parameterize(keep=...)``: an edge to a seed
  collapses into the seed, other edges at their mid-point, so every region loses about three
  vertices in four. The collapses are still shortest first and every validity check is kept.
* **Rough surfaces** (more than 20 % of neighbouring triangles at > 60 degrees: scan noise) are
  collapsed on :func:`smoothed_copy` of their geometry (5 uniform Laplacian steps); the 3D flip
  and quality checks otherwise refuse most collapses. The map's domain (the connectivity) is the
  same, so the prolongation is still a bijective barycentric map of the real mesh.
* **Stalls.** When a level removes less than half of the vertices it should, the collapses
  continue from where they stopped on a smoothed copy without seeds, then with relaxed 3D
  checks (quality 0.02 instead of 0.2, normals turning up to 120 degrees; the UV checks that make
  the map bijective are never relaxed); the two maps are composed. A coarsest level above 2,000
  vertices is reported with the refused checks.

Nothing here depends on a linear system: :meth:`SurfaceMultigrid.solver` builds the Galerkin
matrices ``A_{h+1} = P^T A_h P`` of a given matrix on the stored hierarchy (cheap, repeated every
time the matrix changes).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMeshError, ParameterError
from ..mesh.operators import face_normals
from ..mesh.selfparam import barycentric_prolongation, self_parameterize
from ..mesh.topology import edge_flaps, vertex_adjacency

__all__ = ["SurfaceMultigrid", "surface_multigrid", "barycentric_prolongation",
           "closest_point_prolongation", "PROLONGATIONS"]

PROLONGATIONS = ("intrinsic", "closest_point")

#: the coarsest level should be at most this big (its direct factorization runs every V-cycle)
COARSEST_TARGET = 2000
#: a level that removed fewer vertices than this fraction of the wanted number has stalled
STALL_FRACTION = 0.5
#: a surface is rough when more than this fraction of adjacent triangles meet at > 60 degrees
ROUGH_FRACTION = 0.2
#: relaxed checks of the last fallback (the thesis: quality 0.2, flip 0.2; UV bijectivity kept)
RELAXED_QUALITY, RELAXED_FLIP = 0.02, -0.5


def spread_seeds(F, n: int, seed: int = 0) -> np.ndarray:
    """A maximal independent set of the vertex graph (Luby's algorithm, fixed random priorities).

    No two seeds share an edge and every other vertex has a seed neighbour, so the seeds are
    spread like the vertices themselves: about a quarter of them on a triangle mesh, dense where
    the mesh is dense. Returns sorted vertex indices.
    """
    A = vertex_adjacency(F, n).tocoo()
    rows, cols = A.row, A.col
    pri = np.random.default_rng(seed).random(n)
    state = np.zeros(n, dtype=np.int8)  # 0 undecided, 1 seed, -1 not a seed
    used = np.zeros(n, dtype=bool)
    used[np.asarray(F).ravel()] = True
    state[~used] = -1
    while (state == 0).any():
        p = np.where(state == 0, pri, -1.0)
        best = np.full(n, -1.0)
        np.maximum.at(best, rows, p[cols])
        win = (state == 0) & (p > best)
        state[win] = 1
        lose = np.zeros(n, dtype=bool)
        lose[rows[win[cols]]] = True
        state[lose & (state == 0)] = -1
    return np.flatnonzero(state == 1)


def rough_fraction(V, F) -> float:
    """Fraction of interior edges whose two triangles' normals differ by more than 60 degrees."""
    N = face_normals(V, F)
    _, _, EF, _ = edge_flaps(F)
    ok = (EF >= 0).all(axis=1)
    if not ok.any():
        return 0.0
    d = np.einsum("ij,ij->i", N[EF[ok, 0]], N[EF[ok, 1]])
    return float((d < 0.5).mean())


def smoothed_copy(V, F, steps: int = 5) -> np.ndarray:
    """``steps`` uniform Laplacian smoothing steps (factor 1/2): the geometry the collapses of a
    rough surface are checked on (the connectivity, hence the map's domain, is unchanged)."""
    A = vertex_adjacency(F, len(V)).tocsr()
    deg = np.asarray(A.sum(axis=1)).ravel()
    inv = np.where(deg > 0, 1.0 / np.maximum(deg, 1), 0.0)[:, None]
    X = np.array(V, dtype=np.float64, copy=True)
    for _ in range(int(steps)):
        X = 0.5 * X + 0.5 * np.where(deg[:, None] > 0, (A @ X) * inv, X)
    return X


def _coarsen_level(Vh, Fh, target, strategy, seeded, progress, notes, level):
    """One level of self-parameterization with the fallbacks of issue 10 (see the module
    docstring); the reason of every fallback goes into ``notes``."""
    keep = spread_seeds(Fh, len(Vh)) if seeded else None
    rough = rough_fraction(Vh, Fh) > ROUGH_FRACTION
    Vg = smoothed_copy(Vh, Fh) if rough else Vh
    res = self_parameterize(Vg, Fh, target, strategy=strategy, keep=keep, progress=progress)
    if rough:
        res = replace(res, V_fine=Vh)
        notes.append(f"Level {level}: the surface is rough (more than "
                     f"{ROUGH_FRACTION:.0%} of neighbouring triangles meet at sharp angles), so "
                     f"the collapses were checked on a smoothed copy of its geometry.")
    wanted = len(Vh) - target / 2.0  # a closed mesh has about half as many vertices as faces
    attempts = [(True, 0.2, 0.2, "the collapses were continued on a smoothed copy of the "
                 "geometry, without seed vertices"),
                (True, RELAXED_QUALITY, RELAXED_FLIP,
                 f"the collapses were continued with relaxed checks (triangle quality "
                 f"> {RELAXED_QUALITY}, normals may turn by up to 120 degrees; the map stays "
                 f"bijective)")]
    for smooth, q, flip, what in attempts:
        removed = len(Vh) - len(res.V_coarse)
        if res.report.get("reached_target", True) or removed >= STALL_FRACTION * wanted:
            break
        Vp, Fp = res.V_coarse, res.F_coarse
        nxt = self_parameterize(smoothed_copy(Vp, Fp) if smooth else Vp, Fp, target,
                                strategy=strategy, min_quality=q, flip_delta=flip)
        nxt = replace(nxt, V_fine=Vp)
        notes.append(f"Level {level}: the collapses stalled at {len(Vp):,} vertices "
                     f"({removed:,} of about {int(wanted):,} removed); {what}: "
                     f"{len(nxt.V_coarse):,} vertices.")
        res = res.compose(nxt)
    return res


def _closest_barycentric(Q: np.ndarray, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest triangle of (V, F) for every point of Q and barycentric coordinates there."""
    import igl

    _, I, C = igl.point_mesh_squared_distance(np.ascontiguousarray(Q), np.ascontiguousarray(V),
                                              np.ascontiguousarray(F, dtype=np.int64))
    I = np.asarray(I, dtype=np.int64)
    B = igl.barycentric_coordinates(np.ascontiguousarray(C, dtype=np.float64),
                                    *(np.ascontiguousarray(V[F[I, k]]) for k in range(3)))
    B = np.where(np.isfinite(B), B, 1.0 / 3.0)  # degenerate coarse triangles: the centroid
    B = np.clip(B, 0.0, 1.0)
    B /= B.sum(axis=1, keepdims=True)
    return I, B


def closest_point_prolongation(V_fine, V_coarse, F_coarse) -> sp.csr_matrix:
    """Naive extrinsic prolongation: barycentric coordinates of the closest coarse point.

    Parameters
    ----------
    V_fine : (n, 3) fine vertex positions.
    V_coarse : (nc, 3), F_coarse : (mc, 3) the coarse mesh.

    Returns
    -------
    (n, nc) csr_matrix with 3 non-zeros per row (rows sum to 1).
    """
    V_fine = np.asarray(V_fine, dtype=np.float64)
    V_coarse = np.asarray(V_coarse, dtype=np.float64)
    F_coarse = np.asarray(F_coarse, dtype=np.int64)
    I, B = _closest_barycentric(V_fine, V_coarse, F_coarse)
    return barycentric_prolongation(I, B, F_coarse, len(V_coarse))


@dataclass
class SurfaceMultigrid:
    """A geometry-only multigrid hierarchy (build once per mesh, reuse for any matrix on it).

    Attributes
    ----------
    levels : list of (V, F), level 0 is the input mesh, the last one the coarsest.
    prolongations : list of csr matrices; ``prolongations[h]`` maps level ``h+1`` to level ``h``
        (shape ``|V_h| x |V_{h+1}|``, 3 non-zeros per row, rows sum to 1).
    build_seconds : wall time of the whole construction.
    report : per-level sizes and seconds, the prolongation source, self-parameterization reports.
    maps : with the intrinsic prolongation, the :class:`SelfParameterization` of each level
        (``maps[h]`` maps level ``h`` onto level ``h+1``; compose them or chain ``query`` to
        locate any fine surface point on any coarse level); empty for ``closest_point``.
    """

    levels: list
    prolongations: list
    build_seconds: float = 0.0
    report: dict = field(default_factory=dict)
    maps: list = field(default_factory=list)

    def locate(self, level: int, faces=None, bary=None):
        """Where points of the finest mesh lie on level ``level``: (coarse faces, barycentric
        coordinates). Points are given as (finest faces, barycentric coordinates); by default
        the centroid of every finest triangle. Needs the intrinsic prolongation."""
        if not 0 <= int(level) < self.n_levels:
            raise ParameterError(f"level must lie in 0..{self.n_levels - 1}.")
        if int(level) > len(self.maps):
            raise ParameterError("Locating points on coarse levels needs the intrinsic "
                                 "prolongation (the self-parameterization maps).")
        if faces is None:
            faces = np.arange(len(self.levels[0][1]), dtype=np.int64)
            bary = np.full((len(faces), 3), 1.0 / 3.0)
        faces = np.asarray(faces, dtype=np.int64)
        bary = np.asarray(bary, dtype=np.float64)
        for h in range(int(level)):
            faces, bary = self.maps[h].query(faces, bary)
        return faces, bary

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    @property
    def n_vertices(self) -> int:
        return len(self.levels[0][0])

    def solver(self, A, *, fixed=None, smoother: str = "block_gauss_seidel", presmooth: int = 2,
               postsmooth: int = 2, block: int | None = None):
        """Galerkin multigrid solver of ``A`` on this hierarchy (only the matrices are built).

        Parameters
        ----------
        A : (n, n) sparse symmetric positive (semi-)definite matrix, ``n = |V|`` or, with
            ``block=b``, ``n = b |V|`` with the **interleaved** ordering: unknown ``k`` of vertex
            ``i`` is row ``b*i + k`` (xyzxyz...; the prolongation is ``kron(P, I_b)``).
        fixed : (k,) int indices of Dirichlet unknowns (in A's numbering); their values are given
            to :meth:`MultigridSolver.solve` (``fixed_values``). The reduced system of App. 8.9.2.
        smoother : "block_gauss_seidel" (default: Gauss-Seidel with strongly coupled rows solved
            together, see :mod:`.relaxation`), "gauss_seidel" (serial, the thesis) or "multicolor"
            (App. 8.9.1).
        presmooth, postsmooth : relaxation sweeps before / after the coarse-grid correction.
        block : None or the number of unknowns per vertex.

        Returns
        -------
        MultigridSolver
        """
        from .solver import MultigridSolver

        return MultigridSolver.from_hierarchy(self, A, fixed=fixed, smoother=smoother,
                                              presmooth=presmooth, postsmooth=postsmooth,
                                              block=block)

    def block_prolongations(self, block: int | None) -> list:
        """The prolongations for ``block`` unknowns per vertex (interleaved: ``kron(P, I_b)``)."""
        if block in (None, 1):
            return list(self.prolongations)
        b = int(block)
        I = sp.identity(b, format="csr")
        return [sp.kron(P, I, format="csr") for P in self.prolongations]

    def __repr__(self) -> str:
        sizes = " -> ".join(f"{len(V):,}" for V, _ in self.levels)
        return (f"SurfaceMultigrid({self.n_levels} levels: {sizes} vertices, "
                f"{self.report.get('prolongation', '?')}, built in {self.build_seconds:.2f} s)")


def surface_multigrid(V, F, *, ratio: float = 0.25, min_vertices: int = 500,
                      strategy: str = "midpoint", prolongation: str = "intrinsic",
                      seeded: bool = True,
                      progress: Callable[[float, str], None] | None = None) -> SurfaceMultigrid:
    """Build the multigrid hierarchy of a triangle mesh (geometry only).

    Parameters
    ----------
    V : (n, 3) float64 vertex positions.
    F : (m, 3) int64 triangles (manifold, consistently oriented; boundaries and any genus allowed).
    ratio : face-count ratio between consecutive levels, in (0, 1) (0.25: thesis default).
    min_vertices : coarsen only while the next level would keep at least this many vertices
        (estimated as ``ratio * |V_h|``); a mesh smaller than ``min_vertices / ratio`` gets a
        single level (the solver is then a direct solve).
    strategy : decimation strategy ("midpoint": uniform mid-point collapse, the thesis default;
        "qslim").
    prolongation : "intrinsic" (successive self-parameterization) or "closest_point".
    seeded : keep a spread set of seed vertices on every level (intrinsic prolongation; our
        addition, see the module docstring): every region is coarsened by about ``ratio``, also
        on graded meshes. False: plain shortest-edge-first collapses (the thesis).
    progress : optional ``progress(fraction, message)`` called during and after each level.

    Returns
    -------
    SurfaceMultigrid
    """
    t0 = time.perf_counter()
    if prolongation not in PROLONGATIONS:
        raise ParameterError(f"Unknown prolongation {prolongation!r}; choose one of "
                             f"{', '.join(PROLONGATIONS)}.")
    if not 0.0 < float(ratio) < 1.0:
        raise ParameterError(f"The coarsening ratio must lie strictly between 0 and 1 (got {ratio}).")
    if int(min_vertices) < 3:
        raise ParameterError("min_vertices must be at least 3.")
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise InvalidMeshError("The multigrid hierarchy needs a triangle mesh: V (n, 3) and a "
                               "non-empty F (m, 3).")
    if F.min() < 0 or F.max() >= len(V):
        raise InvalidMeshError("Some faces refer to vertices that do not exist. Validate the "
                               "mesh first.")

    levels = [(V, F)]
    Ps: list = []
    maps: list = []
    per_level = [dict(level=0, vertices=len(V), faces=len(F), seconds=0.0)]
    notes: list[str] = []
    # rough number of levels, for progress
    n_expected = 0
    nv = len(V)
    while ratio * nv >= min_vertices:
        nv *= ratio
        n_expected += 1
    while True:
        Vh, Fh = levels[-1]
        if ratio * len(Vh) < min_vertices:
            break
        target = max(1, int(round(ratio * len(Fh))))
        t = time.perf_counter()
        entry: dict = dict(level=len(levels))
        if prolongation == "intrinsic":
            sub = None
            if progress is not None:
                done, total = len(Ps), max(1, n_expected)

                def sub(frac, _done=done, _total=total):
                    progress(min(1.0, (_done + float(frac)) / _total),
                             f"multigrid level {_done + 1}: self-parameterization")
            res = _coarsen_level(Vh, Fh, target, strategy, seeded, sub, notes, len(levels))
            Vc = np.ascontiguousarray(res.V_coarse, dtype=np.float64)
            Fc = np.ascontiguousarray(res.F_coarse, dtype=np.int64)
            P = sp.csr_matrix(res.prolongation(), dtype=np.float64)
            entry["selfparam"] = dict(getattr(res, "report", {}) or {})
        else:
            from ..mesh.decimate import decimate

            dec = decimate(Vh, Fh, target, strategy=strategy)
            Vc = np.ascontiguousarray(dec.V, dtype=np.float64)
            Fc = np.ascontiguousarray(dec.F, dtype=np.int64)
            P = closest_point_prolongation(Vh, Vc, Fc)
            if dec.notes:
                notes.extend(dec.notes)
        if len(Vc) >= len(Vh):
            notes.append(f"Level {len(levels)} could not be coarsened further; the hierarchy "
                         f"stops at {len(levels)} levels.")
            break
        levels.append((Vc, Fc))
        Ps.append(P)
        if prolongation == "intrinsic":
            maps.append(res)
        entry.update(vertices=len(Vc), faces=len(Fc), seconds=time.perf_counter() - t)
        per_level.append(entry)
        if progress is not None:
            progress(min(1.0, len(Ps) / max(1, n_expected)),
                     f"multigrid level {len(Ps)}: {len(Vc):,} vertices")
    seconds = time.perf_counter() - t0
    coarsest = len(levels[-1][0])
    if coarsest > max(COARSEST_TARGET, int(min_vertices / ratio)):
        last = per_level[-1].get("selfparam") or {}
        why = ", ".join(f"{k} {v:,}" for k, v in sorted(
            (last.get("rejections") or {}).items(), key=lambda kv: -kv[1]) if v)
        notes.append(f"The coarsest level keeps {coarsest:,} vertices (more than "
                     f"{COARSEST_TARGET:,}): no more edges could be collapsed without breaking "
                     f"the map's validity checks" + (f" (refused: {why})" if why else "") +
                     ". Its direct solve is the expensive part of every V-cycle.")
    report = dict(prolongation=prolongation, strategy=strategy, ratio=float(ratio),
                  min_vertices=int(min_vertices), levels=per_level, notes=notes,
                  build_seconds=seconds, seeded=bool(seeded and prolongation == "intrinsic"))
    return SurfaceMultigrid(levels=levels, prolongations=Ps, build_seconds=seconds, report=report,
                            maps=maps)
