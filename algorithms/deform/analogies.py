"""Normal-driven spherical shape analogies (thesis ch. 6: Eq. 6.3-6.5, Alg. 5, App. 6.7).

Energy (Eq. 6.3 with the change of variables ``n(V') -> R_k n_k``; regularizers of §6.4.1)::

    E(U, {R_k, s_k}) = sum_k sum_{cell k} w/2 ||s_k R_k d - d~||^2
                       + lam sum_k a_k ||s_k R_k n_k - t_k||^2

* ``k`` runs over the cells of the regularizer, all on the one ARAP core
  (:class:`algorithms.deform.arap.ArapSystem`):

  - ``"arap"``: one rotation per vertex, spokes-and-rims cells (Chao et al. 2010), ``n_k`` the
    input's unit area-weighted vertex normal, ``a_k`` its Voronoi area (mixed Voronoi, Meyer et
    al. 2003), ``s_k = 1``.
  - ``"farap"`` (Eq. 6.4, face-only ARAP): one rotation per triangle over the triangle's three
    edges, ``n_k`` the input face normal, ``a_k`` the face area, ``s_k = 1``. Every triangle
    edge sits in one cell instead of three, so at the same λ the normal term weighs three times
    more relative to the regularizer than with ``"arap"``.
  - ``"acap"`` (Eq. 6.5, as-conformal-as-possible): the ``"arap"`` cells with a per-cell scale.
    Eq. 6.5 writes the sum over ``k in F`` with the spokes-and-rims sets ``N_k`` of *vertices*;
    App. 6.7.3 builds it on the vertex local step, so the cells are the vertices' (documented
    reading).

* ``w/2 = cot/2`` per triangle edge and cell is the thesis's cotangent weight ``w_ij`` (the
  core's ``w`` is the full cotangent, see :mod:`algorithms.deform.arap`); with it ``E`` is
  exactly the energy the authors' MATLAB code evaluates (gptoolbox's ``cotangent``, i.e.
  ``cot/2``, per triangle; Voronoi ``massmatrix``) and their Procrustes matrix
  ``S_k/2 + lam a_k n_k t_k^T`` (DESIGN §5) is half of the one used here,
  ``S_k + 2 lam a_k n_k t_k^T`` (same rotations), so λ = 1 means what it means there.
* ``t_k`` are the target normals from a :class:`~algorithms.deform.targets.TargetMap` evaluated
  at normals through the Gauss map (§6.3.2).

Local step (App. 6.7.1): ``R_k`` = Procrustes of ``S_k + 2 lam a_k n_k t_k^T`` (det fix), batched
and compiled (:func:`~algorithms.deform.arap.procrustes_rotations`). ACAP (App. 6.7.3): the
isotropic Procrustes of the stacked vectors ``[E_k n_k] -> [E'_k t_k]`` with weights
``diag(W_k, lam a_k)``, ``W_k = w/2`` (Schönemann & Carroll 1970)::

    s_k = (tr(W_k E'_k^T R_k E_k) + lam a_k t_k^T R_k n_k) / (tr(W_k E_k^T E_k) + lam a_k)

The thesis prints the numerator's normal part as ``lam a_k n_k^T t_k`` and the denominator's as
``lam a_k n_k^T t_k``; setting ``dE/ds_k = 0`` gives ``t_k^T R_k n_k`` and
``lam a_k |n_k|^2 = lam a_k``, which is what is implemented (``ArapSystem.scaled_rotations`` with
``extra = 2 lam a_k n_k t_k^T`` and ``extra_weight = 2 lam a_k``).
Global step (App. 6.7.2): ``Q U = K^T [s_k R_k]^T``, ``Q`` prefactored once per regularizer.

Target modes (Alg. 5):

* fixed (default): ``T`` computed once from the input normals (lines 1-2).
* ``dynamic_targets`` (§6.4.2, line 9): after every global step ``T`` is recomputed from the
  current mesh's normals (vertex normals for vertex cells, face normals for face cells); the
  Procrustes term keeps the input normals ``n_k`` (they are what ``R_k`` rotates).
* ``polycube`` (§6.5.1): the precomputation moves into the loop: every iteration the current
  mesh becomes the rest shape (cotangent weights, ``K``, ``Q`` refactored, ``n_k``, ``a_k``) and
  the targets are the closest style normals of the current normals (the target map given, the
  cube when none is). Triangle-quality fix: after the global step every vertex of a triangle
  whose quality ``4 sqrt(3) A / sum |e|^2`` (1 for equilateral) is below ``polycube_quality``
  moves ``polycube_relax`` of the way to the average of its neighbours. Each iteration
  refactors the global matrix, so this mode is much slower per iteration. Use it with
  ``"farap"`` (measured on spot: 99.9% of the area within 10° of an axis after 150
  iterations; fandisk 100%): with vertex cells the vertex normals align (65-86% of the vertices
  within 10°) but the faces between them need not (7-70% of the area).
* developable (§6.5.2, App. 6.7.5), ``developable_threshold > 0``: the targets come from the
  shape itself, recomputed before every local step (:func:`developable_face_targets`): per
  vertex, the area-weighted covariance ``C = sum a_f n_f n_f^T / sum a_f`` of its one-ring
  face normals (trace 1; eigenvalues ``mu_1 <= mu_2 <= mu_3``). Where ``mu_2 <
  developable_threshold`` the one-ring is taken as flat and the normals are projected onto
  the principal axis (the two smallest components zeroed), elsewhere onto the plane of the two
  largest (the smallest zeroed: a ruled, cylinder- or cone-like star, Stein et al. 2018). Each
  face gets three projected normals (one per corner), normalized and averaged into its target.
  A larger threshold flattens more one-rings, so fewer creases remain between flatter pieces
  (measured on spot, farap, λ = 1000: 607 edges bent by more than 15° at 1e-4, 506 at the demo's
  3e-2; the median |angle defect| falls from 0.046 to 0.016 and 0.012). The threshold compares
  with the one-ring's normal spread, so it depends on the resolution: on fine meshes, whose
  one-rings turn by less than ~10°, 3e-2 flattens most one-rings (a normal smoothing).
  Vertex-cell regularizers use the normalized area-weighted average of the target face normals
  around each vertex; these barely differ from the current vertex normals, so the mode is
  meant for ``"farap"`` (as the thesis uses it, Fig. 6.20); with ``"arap"`` it changes little.
  The target map is not used in this mode.

Choices written down here:

* No normalization is needed: both terms scale with the square of the model's size (``w`` is
  dimensionless, ``a_k`` an area), so λ means the same for any size. The output is in the
  input's units.
* Translation null space: a connected component that no hard constraint holds in some
  coordinate gets its lowest-index vertex pinned there internally, and after every global step
  it is translated so that its area-weighted centroid stays at the input's (no vertex is
  privileged; the energy does not see translations).
* ACAP without hard constraints: the regularizer shrinks with the square of the shape's size, so
  nothing stops a slow global shrink (and the normal term pulls every scale towards
  ``t_k . R_k n_k <= 1``). With ``acap_keep_area`` (default on) every component that no hard
  constraint holds is scaled about its centroid after each global step so that its surface area
  stays the input's; components with constraints are never rescaled.
* Stopping (DESIGN §5, the authors' implementation): at most 350 iterations, stop when the
  largest vertex move of an iteration relative to the largest total move is below 2e-4
  (:func:`~algorithms.deform.arap.relative_displacement`).
* Metrics per step: ``energy`` (the whole E above with the rotations of this iteration and the
  positions after its global step; the regularizer from the precomputed operators),
  ``regularizer``, ``normal_term``, ``mean_angle_to_targets`` and ``max_angle_to_targets``
  (degrees between the current mesh's unit normals, of the same kind as ``n_k``, and the
  targets, the mean weighted by ``a_k``; elements with a zero normal or target are skipped),
  ``displacement``; ACAP adds ``scale_min``, ``scale_max``; PolyCube adds ``relaxed_vertices``.
* Per-vertex λ (``lam_per_vertex``, painted): face cells use the mean of their corners.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMeshError, ParameterError
from ..mesh.operators import mass_matrix
from ..mesh.topology import connected_components, vertex_adjacency
from ..params import param, validate_params
from ..steps import Step, run_to_end
from .arap import ArapSystem, procrustes_rotations, relative_displacement
from .collisions import HOLD_CROSSINGS_TOOLTIP
from .targets import ClosestNormals, TargetMap, unit_rows

__all__ = [
    "REGULARIZERS",
    "AnalogyParams",
    "ShapeAnalogy",
    "shape_analogy_iter",
    "shape_analogy",
    "developable_face_targets",
    "angles_to_targets",
    "triangle_quality",
]

#: Regularizers of §6.4.1 (``AnalogyParams.regularizer``).
REGULARIZERS = ("arap", "farap", "acap")


# ------------------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class AnalogyParams:
    """Parameters of normal-driven shape analogies (defaults: thesis and authors' code)."""

    lam: float = param(
        1.0, label="λ (style strength)", minimum=0.0, maximum=1e5, step=0.1, decimals=3,
        log_scale=True, cli_aliases=("--lambda",), slider_range=(0.0, 100.0),
        tooltip="How strongly the surface normals are pulled to the style's. 0 leaves the shape "
                "as it is; 1 is the paper's default; the slider spans 0 to 100, type larger "
                "values (the developable demo uses 1000).")
    regularizer: str = param(
        "arap", label="Regularizer", choices=REGULARIZERS,
        tooltip="arap: smooth, detail-preserving deformation. farap: face-only ARAP, allows sharp "
                "creases between triangles. acap: as-conformal-as-possible, keeps angles but "
                "lets regions grow or shrink.")
    dynamic_targets: bool = param(
        False, label="Dynamic targets", cli_aliases=("--dynamic",),
        tooltip="Recompute the target normals from the current shape after every iteration. "
                "Avoids some poor results (e.g. ears folding the wrong way) at the cost of "
                "drifting further from the input.")
    max_iterations: int = param(
        350, label="Max iterations", minimum=1, maximum=100000, step=10,
        cli_aliases=("--max-iters",),
        tooltip="Upper bound on local-global iterations; the run usually stops earlier on the "
                "tolerance below. About 10 iterations already look close to the final result.")
    rel_displacement_tol: float = param(
        2e-4, label="Stop at relative move", minimum=0.0, maximum=1.0, step=1e-4, decimals=6,
        log_scale=True,
        tooltip="Stop when the largest vertex move of an iteration is this fraction of the "
                "largest total move so far. 0 runs all iterations.")
    developable_threshold: float = param(
        0.0, label="Developable threshold", minimum=0.0, maximum=1.0, step=0.01, decimals=4,
        cli_aliases=("--developable",),
        tooltip="0: off. Above 0 the shape is made piecewise developable (bendable from paper) "
                "instead of following a style; larger values flatten more regions and give "
                "fewer, sharper creases. The paper's demo uses 0.03 with λ = 1000.")
    polycube: bool = param(
        False, label="PolyCube",
        tooltip="Keep deforming towards the style's face directions without preserving the "
                "input's details (a PolyCube shape with the cube style). Slower per iteration.")
    polycube_quality: float = param(
        0.1, label="PolyCube triangle quality", minimum=0.0, maximum=1.0, step=0.05, decimals=3,
        advanced=True,
        tooltip="In PolyCube mode, triangles whose shape quality (1 = equilateral) falls below "
                "this get their corners nudged towards their neighbours. 0 switches it off.")
    polycube_relax: float = param(
        0.1, label="PolyCube nudge", minimum=0.0, maximum=1.0, step=0.05, decimals=3,
        advanced=True,
        tooltip="How far (fraction of the way) the corners of poor triangles move towards the "
                "average of their neighbours in PolyCube mode.")
    acap_keep_area: bool = param(
        True, label="ACAP keeps area", advanced=True,
        tooltip="With the acap regularizer, rescale each part that nothing holds so its surface "
                "area stays the input's (otherwise the whole shape can slowly shrink).")
    hold_crossings: bool = param(True, label="Keep from crossing itself",
                                 tooltip=HOLD_CROSSINGS_TOOLTIP)


# ------------------------------------------------------------------------------ helpers
def _face_cross(U: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unnormalized face normals ``(m, 3)`` (length = twice the area)."""
    a = U[F[:, 0]]
    e1 = U[F[:, 1]] - a
    e2 = U[F[:, 2]] - a
    out = np.empty_like(e1)
    out[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    out[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    out[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return out


def angles_to_targets(N: np.ndarray, T: np.ndarray, weights: np.ndarray | None = None
                      ) -> tuple[float, float]:
    """Mean and largest angle (degrees) between unit normals and their targets.

    Parameters
    ----------
    N, T : (k, 3) float arrays of unit vectors (zero rows are skipped).
    weights : (k,) float, optional, weights of the mean (default uniform).

    Returns
    -------
    (mean, max) : floats in degrees (0, 0 when nothing is left).
    """
    N = np.asarray(N, np.float64)
    T = np.asarray(T, np.float64)
    ok = (np.einsum("ij,ij->i", N, N) > 0) & (np.einsum("ij,ij->i", T, T) > 0)
    if not ok.any():
        return 0.0, 0.0
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", N, T), -1.0, 1.0))
    w = np.ones(len(N)) if weights is None else np.asarray(weights, np.float64)
    w = w * ok
    sw = float(w.sum())
    mean = float(w @ ang) / sw if sw > 0 else float(ang[ok].mean())
    return float(np.degrees(mean)), float(np.degrees(ang[ok].max()))


def triangle_quality(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Shape quality ``4 sqrt(3) A / (|e_1|^2 + |e_2|^2 + |e_3|^2)`` of every triangle.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64.

    Returns
    -------
    (m,) float64 in [0, 1]: 1 for an equilateral triangle, 0 for a degenerate one.
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    P = V[F]
    l2 = ((P[:, [1, 2, 0]] - P) ** 2).sum(axis=2).sum(axis=1)
    A = 0.5 * np.linalg.norm(_face_cross(V, F), axis=1)
    q = np.zeros(len(F))
    np.divide(4.0 * np.sqrt(3.0) * A, l2, out=q, where=l2 > 0)
    return q


def developable_face_targets(V: np.ndarray, F: np.ndarray, threshold: float,
                             *, face_normals: np.ndarray | None = None,
                             areas: np.ndarray | None = None) -> np.ndarray:
    """Developable target face normals (thesis App. 6.7.5; see the module docstring).

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64, the current mesh.
    threshold : float
        One-rings whose middle normalized eigenvalue is below this are flattened (normals to one
        axis); the others keep the plane of the two largest eigenvectors.
    face_normals : (m, 3), areas : (m,), optional, when the caller has them already.

    Returns
    -------
    (m, 3) float64 unit target normals (a face whose projections cancel keeps its normal).
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    if face_normals is None or areas is None:
        X = _face_cross(V, F)
        areas = 0.5 * np.linalg.norm(X, axis=1)
        face_normals = unit_rows(X)
    Nf, a = np.asarray(face_normals, np.float64), np.asarray(areas, np.float64)
    outer = (a[:, None, None] * Nf[:, :, None] * Nf[:, None, :]).reshape(-1, 9)
    idx = F.ravel()
    C = np.column_stack([np.bincount(idx, weights=np.repeat(outer[:, k], 3), minlength=n)
                         for k in range(9)]).reshape(n, 3, 3)
    tr = np.trace(C, axis1=1, axis2=2)
    used = tr > 0
    mu = np.zeros((n, 3))
    E = np.tile(np.eye(3), (n, 1, 1))
    if used.any():
        mu_u, E_u = np.linalg.eigh(C[used] / tr[used, None, None])
        mu[used], E[used] = mu_u, E_u
    flat = used & (mu[:, 1] < threshold)
    # every corner (f, c) projects n_f with the frame of vertex F[f, c]
    Nc = np.repeat(Nf, 3, axis=0)  # (3m, 3), corner order f*3 + c
    Ev = E[idx]  # (3m, 3, 3): columns are eigenvectors, ascending
    fl = flat[idx]
    e_small = Ev[:, :, 0]
    e_large = Ev[:, :, 2]
    P = Nc - np.einsum("ij,ij->i", Nc, e_small)[:, None] * e_small
    P[fl] = np.einsum("ij,ij->i", Nc[fl], e_large[fl])[:, None] * e_large[fl]
    P = unit_rows(P)
    T = unit_rows(P.reshape(-1, 3, 3).sum(axis=1))
    bad = ~(np.abs(T).sum(axis=1) > 0)
    T[bad] = Nf[bad]
    return T


def _check_targets(T, k: int) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (k, 3):
        raise ParameterError(f"The style's target map returned an array of shape {T.shape}; "
                             f"it must return one 3D normal per input normal ({k}, 3).")
    if not np.isfinite(T).all():
        raise ParameterError("The style's target map returned NaN or infinite normals.")
    return unit_rows(T)


# ------------------------------------------------------------------------------ the method
class ShapeAnalogy:
    """Precomputed normal-driven shape analogy of one mesh with one set of constraints.

    Everything that depends only on the mesh and the constraints (normals, areas, the ARAP
    systems and their factorizations, one per kind of cell, built on first use) is kept;
    :meth:`steps` can be run again with another λ, regularizer, style or mode.

    Parameters
    ----------
    V : (n, 3) float64 input positions.
    F : (m, 3) int64 triangles.
    target_map : TargetMap, optional
        The style: maps unit normals ``(k, 3)`` to targets ``(k, 3)``
        (:class:`~algorithms.deform.targets.ClosestNormals`,
        :class:`~algorithms.deform.targets.SphericalStyleMap`,
        :class:`~algorithms.deform.targets.CaptureSphere`, or any callable). Can also be given
        to :meth:`steps`. Not needed for developable mode or with λ = 0 (the regularizer alone,
        with handles); PolyCube mode defaults to the cube.
    fixed : (k,) int, optional, vertices held at their input positions.
    handles : tuple (indices (h,), targets (h, 3)), optional, vertices moved to given positions
        (hard constraints).
    backend : SPDSolver backend ("auto", "cholmod", "superlu").

    Attributes
    ----------
    vertex_normals : (n, 3), vertex_areas : (n,) Voronoi, face_normals : (m, 3),
    face_areas : (m,), the input's (unit normals; areas in the input's units).
    last_scales : (n_cells,) float64 or None, ACAP scales of the last iteration run.
    """

    def __init__(self, V, F, target_map: TargetMap | None = None, *, fixed=None, handles=None,
                 backend: str = "auto"):
        V = np.array(V, dtype=np.float64, copy=True)
        F = np.ascontiguousarray(F, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise InvalidMeshError("Shape analogies need a triangle mesh with at least one "
                                   "triangle.")
        if not np.isfinite(V).all():
            raise InvalidMeshError("The mesh has NaN or infinite coordinates; run Clean first.")
        n = len(V)
        if F.min() < 0 or F.max() >= n:
            raise InvalidMeshError("Some faces refer to vertices that do not exist. "
                                   "Validate the mesh to see which.")
        self.V, self.F, self.n, self.m = V, F, n, len(F)
        self.target_map = target_map
        self.backend = backend

        X = _face_cross(V, F)
        self.face_areas = 0.5 * np.linalg.norm(X, axis=1)
        if not (self.face_areas > 0).all():
            bad = int((self.face_areas <= 0).sum())
            raise InvalidMeshError(f"The mesh has {bad} degenerate (zero-area) triangle"
                                   f"{'s' if bad != 1 else ''}, so its normals and cotangent "
                                   "weights are undefined. Run Clean first.")
        self.face_normals = unit_rows(X)
        self._incidence = sp.csr_matrix(
            (np.ones(3 * self.m), (F.ravel(), np.repeat(np.arange(self.m), 3))),
            shape=(n, self.m))
        self.vertex_normals = unit_rows(self._incidence @ X)
        self.vertex_areas = np.asarray(mass_matrix(V, F, "voronoi").diagonal(), np.float64)

        # constraints
        fixed = np.asarray([] if fixed is None else fixed, dtype=np.int64).reshape(-1)
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n):
            raise ParameterError(f"Some fixed vertices do not exist (the mesh has {n} vertices).")
        if handles is None:
            hidx, htgt = np.zeros(0, np.int64), np.zeros((0, 3))
        else:
            hidx = np.asarray(handles[0], dtype=np.int64).reshape(-1)
            htgt = np.asarray(handles[1], dtype=np.float64).reshape(-1, 3)
            if len(hidx) != len(htgt):
                raise ParameterError("Each handle needs exactly one target position.")
            if hidx.size and (hidx.min() < 0 or hidx.max() >= n):
                raise ParameterError(f"Some handles refer to vertices that do not exist (the "
                                     f"mesh has {n} vertices).")
            if not np.isfinite(htgt).all():
                raise ParameterError("Handle targets must be finite numbers.")
        known = V.copy()
        known[hidx] = htgt
        hard = np.union1d(fixed, hidx)
        referenced = np.zeros(n, dtype=bool)
        referenced[F.ravel()] = True
        ncomp, lab = connected_components(F, n, over="vertices")
        held = np.zeros((ncomp, 3), dtype=bool)
        held_any = np.zeros(ncomp, dtype=bool)
        if hard.size:
            held[lab[hard]] = True
            held_any[lab[hard]] = True
        has_faces = np.zeros(ncomp, dtype=bool)
        has_faces[lab[referenced]] = True
        free = has_faces[:, None] & ~held  # (ncomp, 3): coordinates only the pin holds
        # lowest-index referenced vertex of each component
        first = np.full(ncomp, n, np.int64)
        np.minimum.at(first, lab[referenced], np.flatnonzero(referenced))
        ci, ca = np.nonzero(free)
        pin_i, pin_a = first[ci], ca
        self._hard = hard
        self._pins = (pin_i, pin_a)
        self.known = known
        self._lab = lab
        self._ncomp = ncomp
        self._free = free.astype(np.float64)
        self._unheld = has_faces & ~held_any  # components that nothing holds at all
        self._recenter = bool(free.any())
        self._systems: dict[tuple, ArapSystem] = {}
        w = self.vertex_areas * referenced
        self._comp_area_w = np.bincount(lab, weights=w, minlength=ncomp)
        self._vw = w
        self._avg = None
        self._centroid0 = self._centroids(V)
        self._area0 = self._component_areas(V)
        self._adjacency = None
        self.last_scales: np.ndarray | None = None

    # ---------------------------------------------------------------- pieces
    def system(self, cells: str, rest: np.ndarray | None = None) -> ArapSystem:
        """The ARAP system of one kind of cells ("spokes_and_rims" or "faces") on the input
        (cached), or on ``rest (n, 3)`` (built anew; PolyCube mode)."""
        if rest is None and cells in self._systems:
            return self._systems[cells]
        pin_i, pin_a = self._pins
        s = ArapSystem(self.V if rest is None else rest, self.F, fixed=self._hard,
                       coord_constraints=(pin_i, pin_a), backend=self.backend, cells=cells)
        if rest is None:
            self._systems[cells] = s
        return s

    def _centroids(self, U: np.ndarray) -> np.ndarray:
        if self._avg is None:  # (ncomp, n): area-weighted averaging per component
            w = self._vw / np.maximum(self._comp_area_w, 1e-300)[self._lab]
            self._avg = sp.csr_matrix((w, (self._lab, np.arange(self.n))),
                                      shape=(self._ncomp, self.n))
        return np.asarray(self._avg @ U)

    def _per_vertex(self, X: np.ndarray) -> np.ndarray:
        """Spread per-component rows ``(ncomp, k)`` to the vertices ``(n, k)``."""
        return X[0][None, :] if self._ncomp == 1 else X[self._lab]

    def _component_areas(self, U: np.ndarray, X: np.ndarray | None = None) -> np.ndarray:
        X = _face_cross(U, self.F) if X is None else X
        a = 0.5 * np.sqrt(np.einsum("ij,ij->i", X, X))
        return np.bincount(self._lab[self.F[:, 0]], weights=a, minlength=self._ncomp)

    def _place(self, U: np.ndarray, keep_area: bool, X: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """Translate free components back to their input centroid (and rescale unheld ones to
        their input area when ``keep_area``). ``X`` (m, 3): ``_face_cross(U)`` if known.
        Returns the placed positions and the per-face area factor (None when nothing was
        scaled)."""
        if not self._recenter:
            return U, None
        c = self._centroids(U)
        face_factor = None
        if keep_area and self._unheld.any():
            area = self._component_areas(U, X)
            scale = np.ones(self._ncomp)
            ok = self._unheld & (area > 0)
            scale[ok] = np.sqrt(self._area0[ok] / area[ok])
            cv = self._per_vertex(c)
            U = cv + (U - cv) * self._per_vertex(scale[:, None])  # keeps c
            face_factor = (scale * scale)[self._lab[self.F[:, 0]]]
        return U + self._per_vertex((self._centroid0 - c) * self._free), face_factor

    def normals(self, U: np.ndarray, kind: str, X: np.ndarray | None = None,
                face_factor: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals and face areas of ``U (n, 3)``.

        Parameters
        ----------
        U : (n, 3) positions.
        kind : "faces" (face normals, (m, 3)) or "vertices" (area-weighted vertex normals,
            (n, 3)).
        X : (m, 3), optional, unnormalized face normals of ``U`` up to a per-face factor.
        face_factor : (m,), optional, area factor of ``X``'s faces (``U``'s area / ``X``'s).

        Returns
        -------
        N : (m, 3) or (n, 3) float64 unit normals; a : (m,) float64 face areas.
        """
        X = _face_cross(U, self.F) if X is None else X
        a = 0.5 * np.sqrt(np.einsum("ij,ij->i", X, X))
        if kind == "faces":
            inv = np.zeros_like(a)
            np.divide(0.5, a, out=inv, where=a > 0)
            N = X * inv[:, None]
        else:
            N = unit_rows(self._incidence @ X)
        return N, (a if face_factor is None else a * face_factor)

    def _relax_poor_triangles(self, U: np.ndarray, quality: float, relax: float
                              ) -> tuple[np.ndarray, int]:
        if quality <= 0 or relax <= 0:
            return U, 0
        q = triangle_quality(U, self.F)
        bad = q < quality
        if not bad.any():
            return U, 0
        move = np.zeros(self.n, dtype=bool)
        move[self.F[bad].ravel()] = True
        move[self._hard] = False
        if not move.any():
            return U, 0
        if self._adjacency is None:
            A = vertex_adjacency(self.F, self.n)
            deg = np.asarray(A.sum(axis=1)).ravel()
            self._adjacency = sp.diags(1.0 / np.maximum(deg, 1.0)) @ A
        avg = self._adjacency @ U
        U = U.copy()
        U[move] += relax * (avg[move] - U[move])
        return U, int(move.sum())

    # ---------------------------------------------------------------- the loop
    def steps(self, params: AnalogyParams = AnalogyParams(), *, target_map: TargetMap | None = None,
              lam_per_vertex=None, initial=None) -> Iterator[Step]:
        """Run Alg. 5, one :class:`~algorithms.steps.Step` per local-global iteration.

        Parameters
        ----------
        params : AnalogyParams.
        target_map : TargetMap, optional, overrides the one given at construction.
        lam_per_vertex : (n,) float, optional, λ per vertex (replaces ``params.lam``).
        initial : (n, 3) float, optional, positions the run starts from instead of the input's
            (a warm start, e.g. a coarse result put back on this mesh); fixed vertices and
            handles still take their prescribed positions.

        Yields
        ------
        Step with ``V`` (n, 3) in the input's units and the metrics listed in the module
        docstring; ``total`` is None while the run stops on ``rel_displacement_tol`` (> 0),
        else ``max_iterations``.
        """
        validate_params(params)
        tmap = self.target_map if target_map is None else target_map
        developable = params.developable_threshold > 0
        if params.polycube and tmap is None and not developable:
            tmap = ClosestNormals.primitive("cube")
        no_style = lam_per_vertex is None and params.lam == 0
        if tmap is None and not developable:
            if not no_style:
                raise ParameterError("Choose a style first: a primitive, a style shape or a "
                                     "normal capture (or turn on developable mode).")
            tmap = unit_rows  # λ = 0: the normal term vanishes, pure regularizer with handles
        if tmap is not None and not callable(tmap):
            raise ParameterError("The style must be a target map (a function from normals to "
                                 "target normals).")
        n, F = self.n, self.F
        if lam_per_vertex is None:
            lam_v = np.full(n, float(params.lam))
        else:
            lam_v = np.asarray(lam_per_vertex, dtype=np.float64).reshape(-1)
            if lam_v.shape != (n,):
                raise ParameterError(f"Per-vertex λ needs one value per vertex ({n}), "
                                     f"got {lam_v.size}.")
            if (lam_v < 0).any() or not np.isfinite(lam_v).all():
                raise ParameterError("Per-vertex λ must be finite and non-negative.")
        on_faces = params.regularizer == "farap"
        cells = "faces" if on_faces else "spokes_and_rims"
        kind = "faces" if on_faces else "vertices"
        lam_c = lam_v[F].mean(axis=1) if on_faces else lam_v
        acap = params.regularizer == "acap"
        keep_area = acap and params.acap_keep_area
        V, known = self.V, self.known

        def targets_for(U: np.ndarray, N_cur: np.ndarray, a_cur: np.ndarray,
                        X_cur: np.ndarray | None = None) -> np.ndarray:
            if developable:
                Nf, af = (N_cur, a_cur) if on_faces else self.normals(U, "faces", X_cur)
                Tf = developable_face_targets(U, F, params.developable_threshold,
                                              face_normals=Nf, areas=af)
                if on_faces:
                    return Tf
                return unit_rows(self._incidence @ (af[:, None] * Tf))
            return _check_targets(tmap(N_cur), len(N_cur))

        if params.polycube:
            system = None
        else:
            system = self.system(cells)
            n_in = self.face_normals if on_faces else self.vertex_normals
            a_in = self.face_areas if on_faces else self.vertex_areas
            lam_a = lam_c * a_in
        if initial is None:
            U = V.copy()
        else:
            U = np.array(initial, dtype=np.float64, copy=True)
            if U.shape != V.shape or not np.isfinite(U).all():
                raise ParameterError(f"The starting positions must be {n} finite points.")
        U[self._hard] = known[self._hard]
        N_cur, a_cur = self.normals(U, kind)
        T = targets_for(U, N_cur, a_cur)
        total = None if params.rel_displacement_tol > 0 else params.max_iterations
        S = system.covariances(U) if system is not None else None
        self.last_scales = None
        for it in range(1, params.max_iterations + 1):
            extra_metrics: dict[str, float] = {}
            if params.polycube:
                # the precomputation moves into the loop: the current shape is the rest shape
                try:
                    system = self.system(cells, rest=U)
                except InvalidMeshError:
                    raise InvalidMeshError(
                        f"PolyCube iteration {it} squashed some triangles flat, so the shape "
                        "cannot be deformed further. Raise 'PolyCube triangle quality' or "
                        "'PolyCube nudge', or lower λ, and run again.") from None
                n_in, a_in = N_cur, (a_cur if on_faces else np.asarray(
                    mass_matrix(U, F, "voronoi").diagonal(), np.float64))
                lam_a = lam_c * a_in
                S = system.covariances(U)
            # the core's covariances carry w = cot (twice the thesis's w_ij): the normal term's
            # Procrustes part is therefore 2 lam a n t^T (see the module docstring)
            if params.polycube or it == 1:
                wn = (2.0 * lam_a)[:, None] * n_in
                nn = np.einsum("ij,ij->i", n_in, n_in)
            extra = np.einsum("ka,kb->kab", wn, T)
            if acap:
                R, s = system.scaled_rotations(U, extra, 2.0 * lam_a * nn, covariances=S)
                M = R * s[:, None, None]
                self.last_scales = s
                extra_metrics["scale_min"] = float(s.min())
                extra_metrics["scale_max"] = float(s.max())
            else:
                S += extra
                R = procrustes_rotations(S)
                M = R
            Un = system.solve(system.rhs(M), known)
            X = _face_cross(Un, F)  # normals and areas; unchanged in direction by _place
            Un, face_factor = self._place(Un, keep_area, X)
            if params.polycube:
                Un, moved = self._relax_poor_triangles(Un, params.polycube_quality,
                                                       params.polycube_relax)
                extra_metrics["relaxed_vertices"] = float(moved)
                if moved:
                    X, face_factor = _face_cross(Un, F), None
            disp = relative_displacement(Un, U, V)
            U = Un
            S = system.covariances(U)
            e_reg = max(system.energy(U, M, exact=False, covariances=S), 0.0)
            # lam a ||M n - t||^2 = lam a (|M n|^2 + |t|^2) - tr(M extra)
            if acap:
                mn2 = nn * s * s
            else:
                mn2 = nn
            e_nrm = float(lam_a @ (mn2 + np.einsum("ij,ij->i", T, T))
                          - np.einsum("kab,kba->", M, extra))
            N_cur, a_cur = self.normals(U, kind, X, face_factor)
            if params.dynamic_targets or params.polycube or developable:
                T = targets_for(U, N_cur, a_cur, X)
            w_ang = self.face_areas if on_faces else self.vertex_areas
            mean_ang, max_ang = angles_to_targets(N_cur, T, w_ang)
            metrics = {
                "energy": e_reg + e_nrm,
                "regularizer": e_reg,
                "normal_term": e_nrm,
                "mean_angle_to_targets": mean_ang,
                "max_angle_to_targets": max_ang,
                "displacement": disp,
                **extra_metrics,
            }
            yield Step(iteration=it, total=total, V=U.copy(), metrics=metrics,
                       message=f"iteration {it}, mean angle to targets {mean_ang:.2f}°, "
                               f"relative move {disp:.2e}")
            if disp < params.rel_displacement_tol:
                break


def shape_analogy_iter(V, F, target_map: TargetMap | None = None,
                       params: AnalogyParams = AnalogyParams(), *, fixed=None, handles=None,
                       lam_per_vertex=None) -> Iterator[Step]:
    """Normal-driven shape analogy (thesis Alg. 5), one :class:`~algorithms.steps.Step` per
    iteration.

    Parameters
    ----------
    V : (n, 3) float64 input positions (not modified).
    F : (m, 3) int64 triangles (the output uses the same F).
    target_map : TargetMap, optional, the style (see :class:`ShapeAnalogy`).
    params : AnalogyParams.
    fixed : (k,) int, optional, vertices kept at their input positions.
    handles : tuple (indices (h,), targets (h, 3)), optional, point constraints.
    lam_per_vertex : (n,) float, optional, per-vertex λ.

    Yields
    ------
    Step; see :meth:`ShapeAnalogy.steps`.
    """
    validate_params(params)
    sa = ShapeAnalogy(V, F, target_map, fixed=fixed, handles=handles)
    yield from sa.steps(params, lam_per_vertex=lam_per_vertex)


def shape_analogy(V, F, target_map: TargetMap | None = None,
                  params: AnalogyParams = AnalogyParams(), **kwargs) -> np.ndarray:
    """Run :func:`shape_analogy_iter` to the end and return the (n, 3) stylized positions."""
    return run_to_end(shape_analogy_iter(V, F, target_map, params, **kwargs)).V
