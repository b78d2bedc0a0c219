"""Implicit smoothing of vertex positions (the foundation's "Smooth" method).

Three flows, all backward Euler steps  (M - h L) V' = M V  with the cotangent Laplacian L
(negative semidefinite, libigl convention) and the barycentric mass matrix M:

* ``"laplacian"`` — implicit fairing (Desbrun et al. 1999) with L and M of the *input* mesh:
  the matrix never changes, so it is factored once and every step is two triangular solves.
* ``"cmcf"`` — conformalized mean curvature flow (Kazhdan et al. 2012): L of the input mesh,
  M of the current mesh (refactored every step). It avoids the neck pinches of plain MCF and is
  the flow later used for spherical parameterizations.
* ``"mcf"`` — implicit mean curvature flow: L and M of the current mesh each step.

Choices written down here (the thesis gives no smoothing method for the foundation):

* Defaults (issue 10): cMCF with step 1e-5 × area, 10 steps. The former default, the
  ``"laplacian"`` flow at 1e-4, turned armadillo's ears and feet into spikes (bending energy 328
  after the first step, 578 after ten): the input's fixed operator keeps pulling thin features
  along their length while the volume rescaling inflates the rest. cMCF at 1e-5 takes armadillo
  from 574 to 214 (ears, fingers and feet kept; the largest move of a step is 0.4 mean edge
  lengths) and spot from 77 to about 70 without merging the legs.

* The time step is dimensionless: h = ``step_size`` × (surface area of the input), so the
  same setting smooths a mesh the same amount whatever its units. The area is each part's own
  (connected component): a mesh of many parts is smoothed part by part as if each were alone.
  With the whole mesh's area a tiny part got a step thousands of times too large, collapsed
  to a point and made the system singular (the corpus of issue 38: abominevole, cycloidal,
  lato000, office_chair stopped with "Factor is exactly singular").
* ``fix_boundary`` is on by default (issue 38): on open meshes the flows pull the borders in,
  and the triangles along a free border collapsed to zero area within three steps on scans
  (Laurana50k, mountain of the corpus: bending energy NaN); closed meshes are not affected.
* ``keep_size`` (default on) undoes the shrinking of these flows after every step, as in
  Desbrun et al. 1999: the mesh is translated back to its area-weighted centroid and scaled back
  to its enclosed volume (closed meshes; noise adds much area but little volume, so this is the
  measure that keeps the size a user sees) or to its surface area (meshes with boundary).
  Without it a closed mesh shrinks towards a point, which surprises users. It is skipped while boundary
  vertices are fixed (rescaling would move them).
* ``fix_boundary`` pins boundary vertices (Dirichlet rows eliminated by the reduced system).
  Vertices used by no triangle have no mass and no stiffness; they are always pinned (they stay
  where they are) so the system stays definite. Degenerate triangles (zero area) make the
  cotangent weights infinite: they are refused with a message that points to Clean.
* ``hold_crossings`` (default on, issue 38): after every step, the self-intersections that the
  input did not have are found (away from the input's own crossings:
  :func:`~algorithms.mesh.intersections.new_crossings_away_from`), and the triangles the step
  folded over or collapsed (:mod:`algorithms.mesh.damage`); the corners of those triangles and
  one ring around them are then held where they were before the step (Dirichlet rows, like
  fixed boundary vertices) and the step is solved again, up to :data:`HOLD_ROUNDS` times while
  any is left; held vertices stay held for the rest of the run. Without it, smoothing at its
  defaults damaged 7 of the 52 meshes of the corpus (docs/results/corpus.md): thin walls and
  parts that nearly touch pulled through each other (counter, a CAD part, 7,466 crossing
  pairs), thin parts collapsed (beast: 1,329 triangles of zero area) and tiny CAD triangles
  turned over (block: 30); now none (pizza's last 3 crossings and 2 folds are put back towards
  the input at the end: :func:`~algorithms.deform.collisions.put_back`). A per-step hold, not
  the after-the-fact hold of cubic stylization
  (:func:`~algorithms.deform.collisions.hold_where_crossed`): a flow has no optimum to settle
  at, and vertices held only at the end let their neighbours flow on through them (fertility at
  step 1e-4: 57 crossings unheld; held at the end, the rerun had 200 at its 9th step). Meshes of
  more than :data:`~algorithms.deform.collisions.CHECK_MAX_FACES` triangles are not checked
  (the last Step says so).
* Metrics per step: ``bending_energy`` = Σᵢ Mᵢᵢ |Hᵢ|² with the
  mean curvature Hᵢ = |M⁻¹LV|ᵢ / 2 of the current mesh (the discrete Willmore energy ∫H² dA,
  4π for a round sphere; what a user sees fall as bumps disappear); ``displacement`` is the
  largest vertex move of the step relative to the bounding-box diagonal of the input, ``moved``
  the largest move since the input (same unit: what a user can see; the app says so when a run
  changed little); with ``hold_crossings``, ``crossings_checked`` (0: too big to check),
  ``crossings_made`` (the distinct crossing pairs the steps would have made, each counted once,
  at the step that first made it), ``crossings_left`` (after this step), ``folded_made`` and
  ``folded_left`` (the same for triangles folded over or collapsed) and ``held_vertices``,
  read by :func:`algorithms.deform.collisions.crossings_of`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from .errors import InvalidMeshError, ParameterError
from .linalg import SPDSolver
from .mesh.operators import cotangent_laplacian, face_areas, mass_matrix, signed_volume
from .mesh.topology import boundary_loops, connected_components
from .params import param, validate_params
from .steps import Step, run_to_end

__all__ = ["SmoothParams", "smooth_iter", "smooth", "FLOWS", "HOLD_ROUNDS", "noisy_test_field",
           "unit_area"]

FLOWS = ("laplacian", "cmcf", "mcf")
#: Times a step is solved again with more vertices held while it crosses the surface.
HOLD_ROUNDS = 3


@dataclass(frozen=True)
class SmoothParams:
    """Parameters of implicit smoothing (see the module docstring)."""

    flow: str = param(
        "cmcf", label="Flow", choices=FLOWS,
        tooltip="laplacian: fast implicit fairing with a fixed operator. cmcf: conformalized mean "
                "curvature flow, rounds shapes without pinching. mcf: classic mean curvature flow.")
    step_size: float = param(
        1e-5, label="Step size", minimum=1e-7, maximum=1.0, step=1e-6, decimals=7, log_scale=True,
        tooltip="How far each step smooths, relative to the surface area. Larger values smooth "
                "more per step; 1e-5 is gentle (removes bumps, keeps ears and fingers), 1e-4 "
                "strong, 1e-3 rounds the shape off.")
    iterations: int = param(
        10, label="Iterations", minimum=1, maximum=1000, step=1,
        tooltip="Number of smoothing steps. The viewport shows every step as it is computed.")
    keep_size: bool = param(
        True, label="Keep size",
        tooltip="Move and scale the result back to the original centre and surface area after "
                "every step, so the shape does not shrink.")
    fix_boundary: bool = param(
        True, label="Fix boundary",
        tooltip="Keep the vertices on open borders where they are (meshes with holes only). "
                "Off: the borders are smoothed too and shrink; the thin strips of triangles "
                "along them can collapse.")
    hold_crossings: bool = param(
        True, label="Keep from crossing itself",
        tooltip="Where a step would push the surface through itself (thin walls, parts that "
                "nearly touch) or fold triangles over or collapse them, hold those vertices "
                "where they were and smooth the rest; where it still crosses at the end, put "
                "the surface there back towards the input. Meshes of up to 200,000 triangles. "
                "Off: the flow as it is.")


def _centroid_and_area(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, float]:
    A = face_areas(V, F)
    total = float(A.sum())
    if total <= 0 or not np.isfinite(total):
        return V.mean(axis=0), 0.0
    C = (V[F].mean(axis=1) * A[:, None]).sum(axis=0) / total
    return C, total


def smooth_iter(V: np.ndarray, F: np.ndarray, params: SmoothParams = SmoothParams(), *,
                multigrid=None, multigrid_rtol: float = 1e-5) -> Iterator[Step]:
    """Yield one :class:`~algorithms.steps.Step` per smoothing step.

    Parameters
    ----------
    V : (n, 3) float64 vertex positions (not modified).
    F : (m, 3) int64 triangle indices.
    params : SmoothParams.
    multigrid : a :class:`~algorithms.multigrid.SurfaceMultigrid` of this mesh, optional. Each
        step's system is then solved by surface-multigrid V-cycles warm-started from the current
        positions, on the same hierarchy for every step (thesis Fig. 8.23: the matrix of mean
        curvature flow changes every step), instead of a new factorization.
    multigrid_rtol : relative residual at which the V-cycles of one step stop.

    Yields
    ------
    Step with ``V`` (n, 3) the positions after each step and metrics ``bending_energy``,
    ``displacement`` and ``moved`` (and ``cycles`` with ``multigrid``).
    """
    validate_params(params)
    V0 = np.array(V, dtype=np.float64, copy=True)
    F = np.asarray(F, dtype=np.int64)
    if V0.ndim != 2 or V0.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise InvalidMeshError("Smoothing needs a triangle mesh with at least one triangle.")
    if not np.isfinite(V0).all():
        raise InvalidMeshError("The mesh has NaN or infinite coordinates; run Clean first.")
    C0, area0 = _centroid_and_area(V0, F)
    closed = not boundary_loops(F)
    vol0 = abs(signed_volume(V0, F)) if closed else 0.0
    if area0 <= 0:
        raise InvalidMeshError("The mesh has zero surface area, so there is nothing to smooth.")
    diag = float(np.linalg.norm(V0.max(axis=0) - V0.min(axis=0)))
    # one time step per part (its own area): a small part (a screw, an eye, a fragment of a
    # scan) is smoothed as much as it would be alone, not collapsed to a point by a step sized
    # for the whole mesh. K couples only vertices of one part, so H K stays symmetric.
    n_parts, part = connected_components(F, len(V0), over="vertices")
    part_area = np.bincount(part[F[:, 0]], weights=face_areas(V0, F), minlength=n_parts)
    H = sp.diags(params.step_size * part_area[part])
    L0 = cotangent_laplacian(V0, F)
    if not np.isfinite(L0.data).all():
        raise InvalidMeshError("The mesh has degenerate (zero-area) triangles, so smoothing "
                               "weights are undefined. Run Clean first to remove them.")
    K0 = -L0  # positive semidefinite stiffness
    HK0 = H @ K0  # the time-stepped stiffness of the fixed operator (laplacian, cmcf): once

    used = np.zeros(len(V0), dtype=bool)
    used[F.ravel()] = True
    fixed = np.flatnonzero(~used)  # loose points: pinned
    if params.fix_boundary and not closed:
        loops = np.concatenate(boundary_loops(F)).astype(np.int64)
        fixed = np.union1d(fixed, loops)
    fixed_mask = np.zeros(len(V0), dtype=bool)
    fixed_mask[fixed] = True
    hold = _Hold(V0, F, fixed_mask) if params.hold_crossings else None

    def bending(X: np.ndarray) -> float:
        m = mass_matrix(X, F).diagonal()
        hn = (cotangent_laplacian(X, F) @ X)[used] / np.maximum(m[used], 1e-300)[:, None]
        return float((m[used] * np.einsum("ij,ij->i", hn, hn)).sum() / 4.0)

    if multigrid is not None and multigrid.n_vertices != len(V0):
        raise InvalidMeshError("The multigrid hierarchy was built on another mesh.")

    def factor(A, once: bool, pinned: np.ndarray):
        if multigrid is None:
            return SPDSolver(sp.csc_matrix(A), pinned, backend="auto-once" if once else "auto")
        return multigrid.solver(A, fixed=pinned if pinned.size else None)

    solver = None
    if params.flow == "laplacian":
        M0 = mass_matrix(V0, F)
        solver = factor(M0 + HK0, once=False, pinned=fixed)

    def solve_step(X, M, A, solver, pinned):
        """One backward Euler step with the vertices ``pinned`` where they are in ``X``."""
        if solver is None:
            try:
                solver = factor(A, once=params.flow != "laplacian", pinned=pinned)
            except RuntimeError as e:  # SuperLU: "Factor is exactly singular"
                if "singular" not in str(e):
                    raise
                # triangles of the current mesh collapsed (mcf at a large step, with the hold
                # off: fertility at 3e-4 after 7 steps)
                raise InvalidMeshError(
                    f"Smoothing collapsed part of the mesh at step {it} (its system became "
                    "singular): use a smaller Step size or fewer Iterations, or switch Keep "
                    "from crossing itself on.") from None
        if multigrid is None:
            return solver.solve(M @ X, X[pinned] if pinned.size else None), solver, {}
        Xn = solver.solve(M @ X, x0=X, rtol=multigrid_rtol, maxiter=200,
                          fixed_values=X[pinned] if pinned.size else None)
        return Xn, solver, {"cycles": float(solver.last_info["cycles"])}

    factored_held = 0  # held vertices when the laplacian flow's matrix was factored
    X = V0.copy()
    for it in range(1, params.iterations + 1):
        if params.flow == "laplacian":
            M, A = M0, M0 + HK0
            if hold is not None and hold.count != factored_held:
                solver, factored_held = None, hold.count  # more rows fixed: factor again
        else:
            M = mass_matrix(X, F)
            HK = HK0 if params.flow == "cmcf" else H @ -cotangent_laplacian(X, F)
            A, solver = M + HK, None
        pinned = fixed if hold is None else np.flatnonzero(fixed_mask | hold.held)
        Xn, solver, extra = solve_step(X, M, A, solver, pinned)
        for r in range(HOLD_ROUNDS + 1 if hold is not None else 0):
            if not hold.grow(Xn, may_grow=r < HOLD_ROUNDS):
                break
            # the step again, the vertices where it crossed held where they were before it
            Xn, solver, extra = solve_step(X, M, A, None, np.flatnonzero(fixed_mask | hold.held))
            factored_held = hold.count
        if hold is not None:
            extra.update(hold.figures())
        C, area = _centroid_and_area(Xn, F)
        if not np.isfinite(Xn).all() or area <= 0:
            raise InvalidMeshError(
                "Smoothing collapsed the mesh (its area became zero). Use a smaller step size.")
        if params.keep_size and not (params.fix_boundary and not closed):
            vol = abs(signed_volume(Xn, F)) if closed else 0.0
            if closed and vol0 > 0 and vol > 0:
                scale = (vol0 / vol) ** (1.0 / 3.0)
            else:
                scale = np.sqrt(area0 / area)
            Xn[used] = (Xn[used] - C) * scale + C0
        if hold is not None and it == params.iterations and hold.left:
            # crossings the held steps could not avoid: the surface there back towards the
            # input (issue 38: pizza's 3)
            Xn = hold.put_back(Xn, V0)
            extra.update(hold.figures())
        disp = float(np.linalg.norm(Xn - X, axis=1).max()) / max(diag, 1e-300)
        moved = float(np.linalg.norm(Xn - V0, axis=1).max()) / max(diag, 1e-300)
        X = Xn
        said = ""
        if hold is not None and it == params.iterations:
            from .deform.collisions import crossings_sentence

            said = crossings_sentence(extra, "smoothing")
        yield Step(iteration=it, total=params.iterations, V=X.copy(),
                   metrics={"bending_energy": bending(X),
                            "displacement": disp, "moved": moved, **extra},
                   message=said or f"step {it}/{params.iterations}")


class _Hold:
    """The vertices a flow holds where a step would cross the surface through itself, fold
    triangles over or collapse them (module docstring, ``hold_crossings``)."""

    def __init__(self, V0: np.ndarray, F: np.ndarray, fixed: np.ndarray):
        from .deform.collisions import CHECK_MAX_FACES
        from .mesh.topology import vertex_face_adjacency

        self.F, self.fixed = F, fixed
        self.held = np.zeros(len(V0), dtype=bool)
        self.check = len(F) <= CHECK_MAX_FACES
        self.seen: set[tuple[int, int]] = set()  # crossing pairs found
        self.seen_folded = np.zeros(len(F), dtype=bool)  # triangles found folded or collapsed
        self.left = self.left_folded = 0
        self.crossing = np.zeros((0, 2), np.int64)
        self.back = 0  # vertices put back towards the input at the end
        if self.check:
            from .mesh.intersections import intersecting_pairs_here

            from .mesh.damage import Damage

            self.known = intersecting_pairs_here(V0, F)
            self.VF = vertex_face_adjacency(F, len(V0)).tocsr()
            self.damage = Damage(V0, F)  # the input's side of the fold and collapse tests

    def _bad(self, X: np.ndarray) -> np.ndarray:
        """(k, 2) triangle pairs to hold at ``X``: the new crossing pairs, then each folded or
        collapsed triangle as a pair with itself."""
        from .mesh.intersections import intersecting_pairs_here, new_crossings_away_from

        bad = new_crossings_away_from(intersecting_pairs_here(X, self.F), self.F, self.known)
        self.crossing = bad  # the last check's crossings (a uniform rescale keeps them)
        self.seen.update(map(tuple, np.sort(bad, axis=1).tolist()))
        self.left = len(bad)
        folded = self.damage.folded(X) | self.damage.collapsed(X)
        self.seen_folded |= folded
        self.left_folded = int(folded.sum())
        f = np.flatnonzero(folded)
        return np.concatenate([np.asarray(bad, dtype=np.int64).reshape(-1, 2), np.c_[f, f]])

    @property
    def count(self) -> int:
        return int(self.held.sum())

    def grow(self, X: np.ndarray, may_grow: bool = True) -> bool:
        """Check ``X`` and hold more where it is damaged; False when it is not, when nothing
        new is to be held or ``may_grow`` is False."""
        if not self.check:
            return False
        from .deform.collisions import grow_held

        bad = self._bad(X)
        if not len(bad) or not may_grow:
            return False
        grown = grow_held(self.held, bad, self.F, self.VF, self.fixed)
        if np.array_equal(grown, self.held):
            return False
        self.held = grown
        return True

    def put_back(self, X: np.ndarray, V0: np.ndarray) -> np.ndarray:
        """``X`` (the positions of the last check, or those uniformly rescaled) with the
        surface around its crossings (and folded or collapsed triangles) blended back towards
        the input (:func:`algorithms.deform.collisions.put_back`), where that leaves fewer of
        them in all; else ``X``."""
        from .deform.collisions import put_back

        def folds(Y):
            f = np.flatnonzero(self.damage.folded(Y) | self.damage.collapsed(Y))
            return np.c_[f, f]

        if not len(self.crossing):
            return X
        bad = np.concatenate([np.asarray(self.crossing, np.int64).reshape(-1, 2), folds(X)])
        Y, n_back, count = put_back(X, V0, self.F, self.known, bad, self.fixed, more=folds,
                                    damage=self.damage)
        if count >= len(bad):
            return X
        folded_left = len(folds(Y))
        self.left, self.left_folded, self.back = count - folded_left, folded_left, n_back
        return Y

    def figures(self) -> dict:
        """The metrics of the module docstring after the last check."""
        if not self.check:
            return {"crossings_checked": 0.0}
        return {"crossings_checked": 1.0, "crossings_made": float(len(self.seen)),
                "crossings_left": float(self.left),
                "folded_made": float(self.seen_folded.sum()),
                "folded_left": float(self.left_folded), "held_vertices": float(self.held.sum()),
                **({"put_back_vertices": float(self.back)} if self.back else {})}


def smooth(V: np.ndarray, F: np.ndarray, params: SmoothParams = SmoothParams()) -> np.ndarray:
    """Run :func:`smooth_iter` to the end and return the final (n, 3) positions."""
    return run_to_end(smooth_iter(V, F, params)).V


def noisy_test_field(V: np.ndarray, F: np.ndarray, noise: float = 0.3,
                     seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth per-vertex test signal and a noisy copy of it, for data-smoothing demos.

    The clean signal is ``sin(2π x/ℓ) cos(2π y/ℓ) + 0.5 sin(2π z/ℓ)`` of the coordinates
    normalized by half the bounding-box diagonal ``ℓ`` (a few waves across any mesh, whatever
    its units); the noise is Gaussian with standard deviation ``noise`` × the clean signal's
    standard deviation (0 gives the clean signal back). Returns ``(clean, noisy)``, both (n,).
    """
    V = np.asarray(V, dtype=np.float64)
    if not noise >= 0:
        raise ParameterError("The noise level must be zero or positive.")
    lo, hi = V.min(axis=0), V.max(axis=0)
    ell = 0.5 * float(np.linalg.norm(hi - lo)) or 1.0
    X = (V - 0.5 * (lo + hi)) * (2.0 * np.pi / ell)
    clean = np.sin(X[:, 0]) * np.cos(X[:, 1]) + 0.5 * np.sin(X[:, 2])
    sd = float(clean.std()) or 1.0
    rng = np.random.default_rng(seed)
    return clean, clean + rng.normal(scale=noise * sd, size=len(V))


def unit_area(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``V`` scaled about the origin so that the surface has total area 1.

    Data smoothing's α (thesis Eq. 8.6) weighs a smoothness energy against an L2 term whose
    ratio depends on the mesh's units; building the operators on this copy makes one α do the
    same to a mesh whatever its size (the CLI and the panel do so).
    """
    V = np.asarray(V, dtype=np.float64)
    area = float(face_areas(V, F).sum())
    if not area > 0 or not np.isfinite(area):
        raise InvalidMeshError("The mesh has no area (all triangles are degenerate).")
    return V / np.sqrt(area)
