"""Cubic stylization (thesis ch. 5: Eq. 5.1, local step §5.3.1, Alg. 3, controls §5.4, §5.6.1).

Energy (Eq. 5.1, with the controls of §5.4 and the style matrix of §5.6.1)::

    E(U, {R_i}) = ARAP(U, {R_i}) + sum_i a_i lam_i sum_j s_j |(B R_i n_i)_j|

* ARAP is the spokes-and-rims energy of :mod:`algorithms.deform.arap` (one shared core).
* ``n_i`` are the unit area-weighted vertex normals and ``a_i`` the barycentric vertex areas of the
  **input** mesh (after normalization).
* ``B`` (m x 3) is the style matrix: the identity for the cube, another preset of
  :data:`STYLE_PRESETS` or any user matrix (§5.6.1). ``s_j`` are per-row factors (per-axis
  lambda, §5.4: ``lam_x = lam * s_x``); ``lam_i`` is lambda or a per-vertex painted value.
* ``rotation`` (3 x 3, columns = the cube's axes; or ``rot_x/y/z`` degrees in the params, see
  :func:`rotation_from_degrees`) orients the cube: the norm is measured in that frame,
  ``||B Q^T R_i n_i||_1``. This equals rotating the mesh by ``Q^T``, stylizing, and rotating
  back (tested), which is what Fig. 5.14 does by rotating the input.
* ``frames`` ((n, 3, 3) rotations, columns = vertex ``i``'s cube axes) are per-vertex
  orientations, the thesis's ``n_i^local`` (§5.4, Fig. 5.23: different cube orientations for
  different parts): the term at vertex ``i`` is ``lam_i a_i ||B Q_i^T R_i n_i||_1``. ``rotation``
  is the special case ``Q_i = Q`` (tested to agree). **When both are given, the frames take
  precedence**: ``rotation`` and ``rot_x/y/z`` are then ignored (to combine them, pass
  ``Q @ Q_i``: frames given in the rotated cube's coordinates). Frames must be rotations:
  finite, orthonormal to 1e-6, determinant +1 (a reflection would give the same L1 ball but is
  refused as a likely mistake in the input). Progressive meshes (Alg. 4) do not take frames yet.

Local step (§5.3.1), for every vertex at once, scaled-form ADMM on ``z = R_i n_i``. For a
diagonal style matrix (cube, per-axis lambda) it runs as one compiled loop
(:func:`algorithms.deform.kernels.admm_cube_local_step`, Numba) when Numba is available; otherwise,
and for general style matrices, vectorized NumPy with a Python loop over the ADMM iterations on a
shrinking set of not-yet-converged vertices. Both do, per vertex::

    R <- Procrustes(S_i + rho n_i (z - u)^T)          (Eq. 5.4, 5.8; det fix)
    z <- argmin_z lam_i a_i ||B z||_1 + rho/2 ||R n_i + u - z||^2   (Eq. 5.5 / 5.9 / 5.10)
    u <- u + R n_i - z                                  (Eq. 5.6)
    r = ||R n_i - z||, s = rho ||z - z_prev||           (primal / dual residuals)
    rho *= tau, u /= tau  if r > mu s;  rho /= tau, u *= tau  if s > mu r   (Boyd et al. §3.4.1)
    stop when r < sqrt(3) eps_abs + eps_rel max(||R n_i||, ||z||)
          and s < sqrt(3) eps_abs + eps_rel ||rho u||   (Boyd et al. §3.3.1 with p = n = 3)

With local frames the ADMM variable is ``z = Q_i^T R n_i`` (``z``, ``u`` live in the local frame;
the L1 term is ``||B z||_1``): the R-step target becomes ``Q_i (z - u)``, i.e. Procrustes of
``S_i + rho n_i (Q_i (z - u))^T`` (``tr(R n (Q y)^T) = (Q^T R n) . y``), the z-step is the same
prox applied to ``Q_i^T R n_i + u``, and the u-step and the residuals are computed in the local
frame (``||Q_i^T R n_i|| = ||R n_i||``, so the stopping test and the rho adaptation read the same
numbers). ``rotation`` instead folds ``Q`` into the style matrix (``B Q^T``, world-frame z); the
two agree up to round-off. With a diagonal B the frames run in the compiled kernel (no frames:
unchanged code, same bits); otherwise in the NumPy loop.

``z``, ``u`` and ``rho`` start at 0, 0 and ``rho0`` and are warm-started per vertex across outer
iterations. Vertices with ``lam_i a_i = 0`` take the plain ARAP rotation (the exact minimizer).

The z-step. For the cube (and per-axis factors, B diagonal) it is the shrinkage of Eq. 5.9 with
per-axis thresholds. For a general B the thesis solves a small QP with CVXGEN; here it is solved
exactly and vectorized by :class:`L1Prox`: for the optimum ``z*`` let ``Z`` be the rows with
``(B z*)_j = 0`` and ``sigma = sign(B z*)``; then ``z*`` minimizes the smooth problem
``kappa sigma^T B z + 1/2 ||z - v||^2`` on the subspace ``{B_Z z = 0}``, whose solution is
``P (v - kappa B^T sigma)`` (P the orthogonal projector). Every such subspace of R^3 is R^3, a
plane ``b_j^perp``, a line ``b_j x b_k`` or the origin, and every realizable ``sigma`` is a region
of the hyperplane arrangement of B restricted to that subspace (O(m^2) of them, found
combinatorially). ``z*`` is the candidate of smallest true objective: exact up to round-off,
no tolerances, no iterations. (Equivalently ``z* = v - Proj_Z(v)`` with the zonotope
``Z = {B^T y : ||y||_inf <= kappa}``.)

Style presets (:data:`STYLE_PRESETS`). The normals are drawn to the minima of ``||B n||_1`` on
the unit sphere, which are the facet normals of the zonotope ``B^T [-1, 1]^m``; presets are named
by the polyhedron whose face directions are the **deepest** minima (tested):

* ``cube``: ``I`` (m = 3).
* ``octahedron``: the six face diagonals ``(1, +-1, 0)/sqrt 2`` ... (m = 6; a truncated
  octahedron: the 8 octahedral directions dominate, the 6 axis directions are weaker minima).
  No B gives the 8 directions alone (an octahedron is not a zonotope).
* ``rhombic_dodecahedron``: the four body diagonals ``(+-1, +-1, 1)/sqrt 3`` (m = 4, the thesis's
  m = 4 example of Fig. 5.24: rows are the octahedron's / tetrahedron's face normals; the
  result has the 12 face directions ``(1, 1, 0)/sqrt 2`` of a rhombic dodecahedron).
* ``rhombic_triacontahedron``: the six five-fold axes (rows = the dodecahedron's face normals,
  m = 6; 30 face directions on the two-fold axes).

No preset gives a dodecahedron: like the octahedron it is not a zonotope, and the nearest
candidate (the 15 two-fold axes, m = 15, whose deepest minima are the 12 dodecahedral directions)
leaves so many competing shallow minima (3-fold, 2-fold) that on a sphere the area near the
dodecahedral directions did not grow (9.5% -> 7.6% at lambda = 1). Any matrix can still be passed
as ``style_matrix``; the cost of the z-step grows with the number of arrangement regions (m = 15:
~360 candidates, ~0.6 s per 15k vertices, against ~0.06 s for m = 6).

Choices written down here:

* ``normalize`` (default on, as the authors' code): the mesh is moved and scaled to the unit box
  first (``rho0`` and ``eps_abs`` are absolute numbers, so they assume that scale) and the result
  is scaled back. Metrics (energies) are in the normalized frame.
* Translation null space: a connected component that nothing holds in some coordinate gets its
  lowest-index vertex pinned in that coordinate (``pin_one_vertex``, default, as the authors'
  code); with ``pin_one_vertex`` off the component is instead translated back after every global
  step so that its area-weighted centroid stays where it was (same optimum, no vertex privileged).
* Stopping (thesis: "the infinity norm of relative per vertex displacements" < 3e-3): the largest
  vertex move of an iteration divided by the largest total move from the input so far
  (:func:`algorithms.deform.arap.relative_displacement`); scale-free. With lambda = 0 nothing moves
  and the run stops after one iteration.
* Metrics: ``energy`` = E(U_k, R_k) after the global step (ARAP + the lambda-weighted L1 term;
  the ARAP part ``ArapSystem.energy_after_solve``: ``1/2 (tr C - U.b)`` from the solve's own
  right-hand side, equal to ``energy(exact=False)`` to round-off),
  ``arap``, ``l1``, ``displacement``, ``admm_iterations`` (mean inner iterations over the vertices
  that ran ADMM) and ``admm_iterations_max``.

* Round-off sensitivity: once a vertex's ADMM has converged its residuals are near round-off,
  and the rho adaptation (``r > mu s``, ``s > mu r``) compares such numbers. A relative change
  of 1e-15 anywhere (another summation order, the compiled kernels against NumPy, the input
  scaled by ``1 + 1e-15``) flips one of these decisions after ~15 iterations on spot, and the
  final vertices then differ by 1e-5 to 1e-4 of the bounding-box diagonal (measured on spot,
  bob, armadillo), with the same iteration count. Runs are deterministic: the same input on the
  same path gives the same bits.

* Where the authors' C++ differs (read, not copied) the thesis text wins: z and u start at 0
  (the code starts them at random values), rho0 = 1e-4 (code 1e-3), stop at 3e-3 (code 1e-3;
  its ratio is coordinate-wise, here per-vertex lengths), eps_pri uses sqrt(3) (code sqrt(6)).
  The ARAP weights are scaled to match the code's lambda (see :mod:`algorithms.deform.arap`).

TODO: affine progressive meshes (§5.3.2, Alg. 4) for meshes with millions of faces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from ..mesh.operators import barycentric_vertex_areas, normalize_unit_box, vertex_normals
from ..mesh.topology import connected_components
from ..params import param, validate_params
from ..steps import Step, run_to_end
from .arap import (
    ArapSystem,
    compiled_kernels,
    displacement_ratio,
    procrustes_rotations,
    relative_displacement,
)
from .collisions import HOLD_CROSSINGS_TOOLTIP

__all__ = [
    "STYLE_PRESETS",
    "CubicParams",
    "CubicStylizer",
    "AdmmState",
    "admm_vertices",
    "L1Prox",
    "shrinkage",
    "rotation_from_degrees",
    "admm_local_step",
    "validate_frames",
    "cubic_stylization_iter",
    "cubic_stylization",
    "mean_l1_of_normals",
]


# ------------------------------------------------------------------------------ style presets
def _unit_rows(B) -> np.ndarray:
    B = np.asarray(B, dtype=np.float64)
    return B / np.linalg.norm(B, axis=1, keepdims=True)


_PHI = (1.0 + 5.0 ** 0.5) / 2.0

STYLE_PRESETS: dict[str, np.ndarray] = {
    "cube": np.eye(3),
    "octahedron": _unit_rows([[1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1], [0, 1, 1],
                              [0, 1, -1]]),
    "rhombic_dodecahedron": _unit_rows([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]),
    "rhombic_triacontahedron": _unit_rows([[0, 1, _PHI], [0, 1, -_PHI], [1, _PHI, 0],
                                           [1, -_PHI, 0], [_PHI, 0, 1], [-_PHI, 0, 1]]),
}
"""Style matrices B (m x 3) by the polyhedron whose face directions the result takes (see the
module docstring)."""

for _B in STYLE_PRESETS.values():
    _B.setflags(write=False)


# ------------------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class CubicParams:
    """Parameters of cubic stylization (thesis defaults; see the module docstring)."""

    lam: float = param(
        0.2, label="λ (cubeness)", minimum=0.0, maximum=2.0, step=0.05, decimals=3,
        cli_aliases=("--lambda",),
        tooltip="How cubic the result becomes. 0 leaves the shape as it is; 0.2 is the paper's "
                "typical value; larger values flatten it into fewer, bigger faces.")
    style: str = param(
        "cube", label="Style", choices=tuple(STYLE_PRESETS),
        tooltip="Which polyhedron's faces the surface is drawn to. cube is the paper's method; "
                "the others use a style matrix inside the L1 norm (polyhedral stylization).")
    per_axis: bool = param(
        False, label="Per-axis λ",
        tooltip="Use the three factors below to make the shape more cubic along some axes than "
                "others (a rectangular-prism style). Cube style only.")
    axis_factor_x: float = param(
        1.0, label="x factor", minimum=0.0, maximum=10.0, step=0.1, decimals=2,
        tooltip="With per-axis λ on: λ along x is λ times this factor.")
    axis_factor_y: float = param(
        1.0, label="y factor", minimum=0.0, maximum=10.0, step=0.1, decimals=2,
        tooltip="With per-axis λ on: λ along y is λ times this factor.")
    axis_factor_z: float = param(
        1.0, label="z factor", minimum=0.0, maximum=10.0, step=0.1, decimals=2,
        tooltip="With per-axis λ on: λ along z is λ times this factor.")
    rot_x: float = param(
        0.0, label="Cube orientation x (°)", minimum=-180.0, maximum=180.0, step=5.0, decimals=1,
        tooltip="Turns the cube the shape is drawn to about the x axis (the mesh stays put).")
    rot_y: float = param(
        0.0, label="Cube orientation y (°)", minimum=-180.0, maximum=180.0, step=5.0, decimals=1,
        tooltip="Turns the cube the shape is drawn to about the y axis.")
    rot_z: float = param(
        0.0, label="Cube orientation z (°)", minimum=-180.0, maximum=180.0, step=5.0, decimals=1,
        tooltip="Turns the cube the shape is drawn to about the z axis.")
    max_iterations: int = param(
        1000, label="Max iterations", minimum=1, maximum=100000, step=10,
        cli_aliases=("--max-iters",),
        tooltip="Upper bound on local-global iterations; the run usually stops earlier on the "
                "tolerance below (about 100 iterations in the paper).")
    rel_displacement_tol: float = param(
        3e-3, label="Stop at relative move", minimum=0.0, maximum=1.0, step=1e-3, decimals=5,
        log_scale=True,
        tooltip="Stop when the largest vertex move of an iteration is this fraction of the "
                "largest total move so far. Smaller values run longer and converge further.")
    rho0: float = param(
        1e-4, label="ADMM ρ₀", minimum=1e-12, maximum=1e6, step=1e-4, decimals=8,
        log_scale=True, advanced=True,
        tooltip="Initial ADMM penalty of every vertex (adapted automatically afterwards).")
    eps_abs: float = param(
        1e-5, label="ADMM ε_abs", minimum=1e-14, maximum=1.0, step=1e-5, decimals=10,
        log_scale=True, advanced=True,
        tooltip="Absolute tolerance of the per-vertex ADMM. Increase it for very large λ to "
                "avoid bad local minima.")
    eps_rel: float = param(
        1e-3, label="ADMM ε_rel", minimum=1e-14, maximum=1.0, step=1e-4, decimals=10,
        log_scale=True, advanced=True,
        tooltip="Relative tolerance of the per-vertex ADMM.")
    mu: float = param(
        10.0, label="ADMM μ", minimum=1.0, maximum=1e6, step=1.0, advanced=True,
        tooltip="ρ is changed when one residual exceeds μ times the other.")
    tau: float = param(
        2.0, label="ADMM τ", minimum=1.0, maximum=100.0, step=0.5, advanced=True,
        tooltip="Factor by which ρ is increased or decreased.")
    admm_max_iter: int = param(
        100, label="ADMM max iterations", minimum=1, maximum=10000, step=10, advanced=True,
        tooltip="Upper bound on inner ADMM iterations per vertex and local step.")
    warm_start: bool = param(
        True, label="Warm start ADMM", advanced=True,
        tooltip="Reuse each vertex's ADMM state (z, u, ρ) from the previous iteration; much "
                "faster. Off restarts from zero every time.")
    normalize: bool = param(
        True, label="Normalize size",
        tooltip="Scale the mesh to a unit box before stylizing and back afterwards, so λ and "
                "the tolerances mean the same for any model size.")
    pin_one_vertex: bool = param(
        True, label="Pin one vertex",
        tooltip="Remove the free translation by holding one vertex (per part with no other "
                "constraint). Off: keep each part's centre where it was instead.")
    hold_crossings: bool = param(True, label="Keep from crossing itself",
                                 tooltip=HOLD_CROSSINGS_TOOLTIP)


def mean_l1_of_normals(V, F) -> float:
    """Area-weighted mean L1 norm of the unit vertex normals: 1 where the surface is axis-aligned,
    up to √3; the "cubeness" measure the tests and the CLI report (lower = cubier)."""
    N = vertex_normals(V, F)
    a = barycentric_vertex_areas(V, F)
    return float((a * np.abs(N).sum(axis=1)).sum() / a.sum())


def rotation_from_degrees(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rotation by ``rx`` about x, then ``ry`` about y, then ``rz`` about z (fixed axes, degrees).

    Returns
    -------
    (3, 3) float64 ``Rz @ Ry @ Rx``; used as the cube orientation (its columns are the cube's
    axes).
    """
    ax, ay, az = np.radians([rx, ry, rz])
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    Ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    Rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


# ------------------------------------------------------------------------------ z-step
def shrinkage(v: np.ndarray, kappa) -> np.ndarray:
    """Soft thresholding ``S_kappa(v)_j = (1 - kappa_j / |v_j|)_+ v_j`` (thesis Eq. 5.9).

    Parameters
    ----------
    v : (N, 3) float array.
    kappa : scalar, (N,), (3,) or (N, 3) non-negative thresholds (broadcast against ``v``;
        an (N,) array is one threshold per row).

    Returns
    -------
    (N, 3) float64, the minimizer of ``sum_j kappa_j |z_j| + 1/2 ||z - v||^2``.
    """
    v = np.asarray(v, dtype=np.float64)
    k = np.asarray(kappa, dtype=np.float64)
    if k.ndim == 1 and v.ndim == 2 and k.shape[0] == v.shape[0] and k.shape[0] != v.shape[1]:
        k = k[:, None]
    elif k.ndim == 1 and v.ndim == 2 and k.shape[0] == v.shape[0] == v.shape[1]:
        raise ValueError("ambiguous kappa shape; pass (N, 1) or (1, 3)")
    return np.sign(v) * np.maximum(np.abs(v) - k, 0.0)


def _sector_directions(c: np.ndarray, tol: float) -> np.ndarray:
    """Unit 2-vectors, one inside each sector of the central line arrangement ``{q: c_j . q = 0}``.

    ``c`` (h, 2) holds the rows' normals (all non-zero). Returns (s, 2).
    """
    if len(c) == 0:
        return np.array([[1.0, 0.0]])
    base = np.arctan2(c[:, 1], c[:, 0])
    ang = np.mod(np.concatenate([base + np.pi / 2, base - np.pi / 2]), 2 * np.pi)
    ang = np.sort(ang)
    keep = np.concatenate([[True], np.diff(ang) > tol])
    ang = ang[keep]
    if len(ang) > 1 and (ang[0] + 2 * np.pi - ang[-1]) <= tol:
        ang = ang[:-1]
    nxt = np.concatenate([ang[1:], [ang[0] + 2 * np.pi]])
    mid = (ang + nxt) / 2.0
    return np.column_stack([np.cos(mid), np.sin(mid)])


def _plane_basis(u: np.ndarray) -> np.ndarray:
    """(3, 2) orthonormal basis of the plane orthogonal to the unit vector ``u``."""
    a = np.eye(3)[int(np.argmin(np.abs(u)))]
    t1 = np.cross(u, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(u, t1)
    return np.column_stack([t1, t2])


class L1Prox:
    """Exact batched proximal map of ``kappa ||B z||_1`` in R^3 (the z-step of §5.6.1).

    ``prox(v, kappa)`` returns ``argmin_z kappa ||B z||_1 + 1/2 ||z - v||^2`` for every row of
    ``v``. See the module docstring for the method (enumeration of the sign patterns realized by
    the hyperplane arrangement of B; exact).

    Parameters
    ----------
    B : (m, 3) float array, the style matrix (rows that are zero are ignored).
    tol : relative tolerance deciding that two directions coincide when building the arrangement.
    closed_form : use the shrinkage formula when B is diagonal (default); False always uses the
        general enumeration (for testing).
    chunk : rows evaluated at once (bounds the temporary memory).

    Attributes
    ----------
    B : (m', 3) the non-zero rows.
    diagonal : (3,) or None, the absolute diagonal when B is diagonal (closed-form shrinkage).
    n_candidates : int, number of candidate patterns (0 for the diagonal fast path).
    """

    def __init__(self, B, tol: float = 1e-9, *, closed_form: bool = True, chunk: int = 512):
        B = np.asarray(B, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(B).all():
            raise ParameterError("The style matrix has NaN or infinite entries.")
        # a diagonal B (cube, per-axis factors, some of them 0) is the closed-form shrinkage
        is_diagonal = len(B) == 3 and np.all(B[~np.eye(3, dtype=bool)] == 0)
        diagonal = np.abs(np.diag(B)).copy() if is_diagonal else None
        norms = np.linalg.norm(B, axis=1)
        scale = float(norms.max(initial=0.0))
        B = B[norms > tol * scale] if scale > 0 else B[:0]
        self.B = B
        self.chunk = int(chunk)
        self.diagonal = None
        if closed_form and is_diagonal:
            self.diagonal = diagonal
        elif len(B) == 0:
            self.diagonal = np.zeros(3)
        self.n_candidates = 0
        if self.diagonal is None:
            self._build(tol)

    # -- candidates ---------------------------------------------------------------
    def _build(self, tol: float) -> None:
        B = self.B
        Bn = B / np.linalg.norm(B, axis=1, keepdims=True)
        m = len(B)
        projectors: list[np.ndarray] = []
        cands: dict[tuple[int, tuple[int, ...]], None] = {}

        def add(P: np.ndarray, sigmas) -> None:
            projectors.append(P)
            s_idx = len(projectors) - 1
            for sig in sigmas:
                cands[(s_idx, tuple(int(x) for x in sig))] = None

        # distinct row directions (up to sign) and distinct lines b_j x b_k
        dirs: list[np.ndarray] = []
        for b in Bn:
            if not any(np.linalg.norm(np.cross(b, d)) <= tol for d in dirs):
                dirs.append(b)
        lines: list[np.ndarray] = []
        for i in range(len(dirs)):
            for j in range(i + 1, len(dirs)):
                l_ = np.cross(dirs[i], dirs[j])
                l_ /= np.linalg.norm(l_)
                if not any(np.linalg.norm(np.cross(l_, e)) <= tol for e in lines):
                    lines.append(l_)

        def signs_at(p: np.ndarray, tangent: np.ndarray | None) -> list[np.ndarray]:
            """Sign vectors of the regions around direction p (tangent: (3, 2) basis at p)."""
            dp = Bn @ p
            through = np.abs(dp) <= tol
            base = np.sign(dp) * ~through
            if not through.any() or tangent is None:
                return [base]
            c = Bn[through] @ tangent  # (h, 2), rows through p restricted to the tangent plane
            out = []
            for q in _sector_directions(c, tol):
                s = base.copy()
                s[through] = np.sign(c @ q)
                out.append(s)
            return out

        # full space: regions of the arrangement, found around each of its rays
        full: list[np.ndarray] = []
        if lines:
            for l_ in lines:
                for p in (l_, -l_):
                    full += signs_at(p, _plane_basis(p))
        else:  # all rows parallel: two half-spaces
            full += [np.sign(Bn @ dirs[0]), -np.sign(Bn @ dirs[0])]
        add(np.eye(3), full)

        # planes orthogonal to each row direction
        for d in dirs:
            T = _plane_basis(d)
            c = Bn @ T  # (m, 2)
            vanish = np.linalg.norm(c, axis=1) <= tol
            sig = []
            for q in _sector_directions(c[~vanish], tol):
                s = np.zeros(m)
                s[~vanish] = np.sign(c[~vanish] @ q)
                sig.append(s)
            add(T @ T.T, sig)

        # lines through the origin
        for l_ in lines:
            dp = Bn @ l_
            s = np.sign(dp) * (np.abs(dp) > tol)
            add(np.outer(l_, l_), [s, -s])

        # the origin
        add(np.zeros((3, 3)), [np.zeros(m)])

        keys = list(cands)
        self._P = np.stack(projectors)  # (S, 3, 3)
        self._sub = np.array([k[0] for k in keys], dtype=np.int64)  # (C,)
        sig = np.array([k[1] for k in keys], dtype=np.float64)  # (C, m)
        # g_c = P B^T sigma
        self._g = np.einsum("cab,cb->ca", self._P[self._sub], sig @ B)  # (C, 3)
        self.n_candidates = len(keys)

    # -- evaluation ---------------------------------------------------------------
    def __call__(self, v: np.ndarray, kappa) -> np.ndarray:
        """Apply the proximal map.

        Parameters
        ----------
        v : (N, 3) float array.
        kappa : scalar or (N,) non-negative array.

        Returns
        -------
        z : (N, 3) float64.
        """
        v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
        kappa = np.broadcast_to(np.asarray(kappa, dtype=np.float64), (len(v),))
        if self.diagonal is not None:
            return shrinkage(v, kappa[:, None] * self.diagonal[None, :])
        out = np.empty_like(v)
        for s in range(0, len(v), self.chunk):
            vv, kk = v[s:s + self.chunk], kappa[s:s + self.chunk]
            Pv = np.einsum("sab,nb->nsa", self._P, vv)  # (N, S, 3)
            z = Pv[:, self._sub] - kk[:, None, None] * self._g[None]  # (N, C, 3)
            l1 = np.abs(z @ self.B.T).sum(axis=2)  # (N, C)
            f = kk[:, None] * l1 + 0.5 * ((z - vv[:, None, :]) ** 2).sum(axis=2)
            best = np.argmin(f, axis=1)
            out[s:s + self.chunk] = z[np.arange(len(vv)), best]
        return out

    def norm(self, x: np.ndarray) -> np.ndarray:
        """``||B x||_1`` of each row of ``x`` (N, 3) -> (N,)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        if self.diagonal is not None:
            return np.abs(x * self.diagonal).sum(axis=1)
        return np.abs(x @ self.B.T).sum(axis=1)


# ------------------------------------------------------------------------------ local step
@dataclass
class AdmmState:
    """Per-vertex ADMM variables kept between outer iterations (warm start).

    Attributes
    ----------
    z : (n, 3) consensus variable (``z = R n``).
    u : (n, 3) scaled dual variable.
    rho : (n,) penalty.
    """

    z: np.ndarray
    u: np.ndarray
    rho: np.ndarray

    @classmethod
    def initial(cls, n: int, rho0: float) -> "AdmmState":
        return cls(np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, float(rho0)))


def admm_vertices(lam_a: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n,) bool: the vertices whose local step runs ADMM (``lam_a > 0`` and a non-zero normal);
    the others take the plain ARAP rotation."""
    return (lam_a > 0) & (np.abs(normals).sum(axis=1) > 0)


def admm_local_step(S: np.ndarray, normals: np.ndarray, lam_a: np.ndarray, prox: L1Prox,
                    state: AdmmState, params: CubicParams,
                    frames: np.ndarray | None = None,
                    use: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The local step of cubic stylization for all vertices (thesis §5.3.1, Eq. 5.4-5.9).

    Parameters
    ----------
    S : (n, 3, 3) ARAP covariances ``sum w d d~^T`` at the current positions.
    normals : (n, 3) unit normals of the input (the vectors inside the L1 norm).
    lam_a : (n,) ``lam_i * a_i``; vertices with 0 take the plain ARAP rotation.
    prox : L1Prox of the (weighted, oriented) style matrix.
    state : AdmmState, updated in place (warm start); ``z``, ``u`` in the local frames when
        ``frames`` is given.
    params : CubicParams (rho0 is not used here; eps_abs, eps_rel, mu, tau, admm_max_iter are).
    frames : (n, 3, 3) rotations, optional, per-vertex local frames (columns = cube axes; see
        :func:`validate_frames`): the L1 term becomes ``||B Q_i^T R_i n_i||_1``. Not validated
        here.
    use : (n,) bool, optional, :func:`admm_vertices` of ``lam_a`` and ``normals`` when the caller
        has it (it does not change between iterations).

    Returns
    -------
    R : (n, 3, 3) rotations.
    iterations : (n,) int, ADMM iterations run per vertex (0 where ``lam_a == 0``).

    Notes
    -----
    With a diagonal style matrix (``prox.diagonal`` set) and Numba available this runs the
    compiled :func:`algorithms.deform.kernels.admm_cube_local_step`; otherwise the NumPy loop
    below. Both perform the same updates per vertex and agree to round-off (tested).
    """
    n = len(S)
    R = np.empty((n, 3, 3))
    iters = np.zeros(n, dtype=np.int64)
    if frames is not None:
        frames = np.ascontiguousarray(frames, dtype=np.float64)
    if use is None:
        use = admm_vertices(lam_a, normals)
    kern = compiled_kernels() if prox.diagonal is not None else None
    if kern is not None:
        # cube / per-axis: the compiled loop (the same updates per vertex, in waves)
        for name in ("z", "u", "rho"):
            a = getattr(state, name)
            if not (a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable):
                setattr(state, name, np.ascontiguousarray(a, dtype=np.float64))
        kern.admm_cube_local_step(
            np.ascontiguousarray(S, dtype=np.float64),
            np.ascontiguousarray(normals, dtype=np.float64),
            np.ascontiguousarray(lam_a, dtype=np.float64), use,
            np.ascontiguousarray(prox.diagonal, dtype=np.float64),
            state.z, state.u, state.rho, float(params.eps_abs), float(params.eps_rel),
            float(params.mu), float(params.tau), int(params.admm_max_iter), R, iters, frames)
        return R, iters
    plain = ~use
    if plain.any():
        R[plain] = procrustes_rotations(S[plain])
    active = np.flatnonzero(use)
    sqrt3 = np.sqrt(3.0)
    for _ in range(params.admm_max_iter):
        if active.size == 0:
            break
        z, u, rho = state.z[active], state.u[active], state.rho[active]
        nn = normals[active]
        if frames is None:
            M = S[active] + rho[:, None, None] * nn[:, :, None] * (z - u)[:, None, :]
            Ri = procrustes_rotations(M)
            Rn = np.einsum("kab,kb->ka", Ri, nn)
        else:  # z, u in the local frames: target Q (z - u), z-step on Q^T R n
            Qa = frames[active]
            y = np.einsum("kab,kb->ka", Qa, z - u)
            M = S[active] + rho[:, None, None] * nn[:, :, None] * y[:, None, :]
            Ri = procrustes_rotations(M)
            Rn = np.einsum("kba,kb->ka", Qa, np.einsum("kab,kb->ka", Ri, nn))
        z_new = prox(Rn + u, lam_a[active] / rho)
        u = u + Rn - z_new
        r = np.linalg.norm(Rn - z_new, axis=1)
        s = rho * np.linalg.norm(z_new - z, axis=1)
        eps_pri = sqrt3 * params.eps_abs + params.eps_rel * np.maximum(
            np.linalg.norm(Rn, axis=1), np.linalg.norm(z_new, axis=1))
        eps_dual = sqrt3 * params.eps_abs + params.eps_rel * np.linalg.norm(rho[:, None] * u,
                                                                            axis=1)
        done = (r < eps_pri) & (s < eps_dual)
        inc = r > params.mu * s
        dec = (s > params.mu * r) & ~inc
        rho = np.where(inc, rho * params.tau, np.where(dec, rho / params.tau, rho))
        u = np.where(inc[:, None], u / params.tau, np.where(dec[:, None], u * params.tau, u))
        R[active] = Ri
        state.z[active], state.u[active], state.rho[active] = z_new, u, rho
        iters[active] += 1
        active = active[~done]
    return R, iters


# ------------------------------------------------------------------------------ driver
FRAME_TOLERANCE = 1e-6
"""Largest entry of ``|Q_i^T Q_i - I|`` accepted for a local frame (whose determinant must then
be +1, not -1)."""


def validate_frames(frames, n: int) -> np.ndarray:
    """Check per-vertex local frames and return them as a C-contiguous (n, 3, 3) float64 array.

    Parameters
    ----------
    frames : (n, 3, 3) array-like, rotation matrices (columns = the cube axes at each vertex).
    n : int, number of vertices.

    Raises
    ------
    ParameterError
        Wrong shape, NaN / infinity, columns not orthonormal to :data:`FRAME_TOLERANCE`, or a
        reflection (determinant -1).
    """
    try:
        Q = np.array(frames, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError("Local frames must be an array of numbers: one 3×3 rotation "
                             "matrix per vertex.") from None
    if Q.shape != (n, 3, 3):
        raise ParameterError(f"Local frames need one 3×3 rotation matrix per vertex, shape "
                             f"({n}, 3, 3); got shape {Q.shape}.")

    def which(bad: np.ndarray, singular: str, plural: str) -> str:
        idx = np.flatnonzero(bad)
        if idx.size == 1:
            return f"The local frame of vertex {idx[0]} {singular}"
        return f"The local frames of {idx.size} vertices (the first is vertex {idx[0]}) {plural}"

    bad = ~np.isfinite(Q.reshape(n, 9)).all(axis=1)
    if bad.any():
        raise ParameterError(which(bad, "has", "have") + " NaN or infinite entries.")
    cols = [Q[:, :, k] for k in range(3)]
    err = np.zeros(n)  # max |Q^T Q - I| per frame, from the six column dot products
    for a in range(3):
        for b in range(a, 3):
            np.maximum(err, np.abs((cols[a] * cols[b]).sum(axis=1) - (a == b)), out=err)
    bad = err > FRAME_TOLERANCE
    if bad.any():
        raise ParameterError(
            which(bad, "is not a rotation", "are not rotations") + ": the columns are not "
            f"unit length and perpendicular (off by up to {err.max():.1e}; allowed "
            f"{FRAME_TOLERANCE:g}). Orthonormalize the frames first.")
    # orthonormal to 1e-6 leaves det = +-(1 +- 2e-6): the sign tells rotation from reflection
    det = (cols[0] * np.cross(cols[1], cols[2])).sum(axis=1)
    bad = det < 0.0
    if bad.any():
        raise ParameterError(
            which(bad, "is a reflection (determinant -1), not a rotation",
                  "are reflections (determinant -1), not rotations")
            + ". Negate one axis (column) of each reflection.")
    return np.ascontiguousarray(Q)


def _normalize_handles(handles, n: int):
    if handles is None:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    idx, tgt = handles
    idx = np.asarray(idx, dtype=np.int64).reshape(-1)
    tgt = np.asarray(tgt, dtype=np.float64).reshape(-1, 3)
    if len(idx) != len(tgt):
        raise ParameterError("Each handle needs exactly one target position.")
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ParameterError(f"Some handles refer to vertices that do not exist (the mesh has "
                             f"{n} vertices).")
    if not np.isfinite(tgt).all():
        raise ParameterError("Handle targets must be finite numbers.")
    return idx, tgt


class CubicStylizer:
    """Precomputed cubic stylization of one mesh with one set of constraints.

    Everything that depends only on the mesh and the constraints (normalization, normals, areas,
    the ARAP system and its factorizations) is built once; :meth:`steps` can then be run with
    different λ, styles, orientations or per-vertex λ without refactoring.

    Parameters
    ----------
    V : (n, 3) float64 input positions.
    F : (m, 3) int64 triangles.
    fixed : (k,) int, optional, vertices held at their input positions.
    handles : tuple (indices (h,), targets (h, 3)), optional, vertices moved to given positions
        (hard constraints).
    coord_constraints : tuple (indices (c,), axes (c,), values (c,)), optional
        Plane constraints: coordinate ``axes[j]`` of vertex ``indices[j]`` equals ``values[j]``
        (in the input's units).
    normalize, pin_one_vertex : bool, see :class:`CubicParams`.
    backend : SPDSolver backend.
    """

    def __init__(self, V, F, *, fixed=None, handles=None, coord_constraints=None,
                 normalize: bool = True, pin_one_vertex: bool = True, backend: str = "auto"):
        V = np.array(V, dtype=np.float64, copy=True)
        F = np.asarray(F, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise InvalidMeshError("Cubic stylization needs a triangle mesh with at least one "
                                   "triangle.")
        if not np.isfinite(V).all():
            raise InvalidMeshError("The mesh has NaN or infinite coordinates; run Clean first.")
        n = len(V)
        self.V, self.F, self.n = V, F, n
        self.normalize, self.pin_one_vertex = bool(normalize), bool(pin_one_vertex)
        if normalize:
            Vn, center, scale = normalize_unit_box(V)
        else:
            Vn, center, scale = V.copy(), np.zeros(3), 1.0
        self.center, self.scale = center, scale
        self.V_normalized = Vn

        fixed = np.asarray([] if fixed is None else fixed, dtype=np.int64).reshape(-1)
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n):
            raise ParameterError(f"Some fixed vertices do not exist (the mesh has {n} vertices).")
        hidx, htgt = _normalize_handles(handles, n)
        if coord_constraints is not None:
            ci, ca, cv = coord_constraints
            ci = np.asarray(ci, dtype=np.int64).reshape(-1)
            ca = np.asarray(ca, dtype=np.int64).reshape(-1)
            cv = np.broadcast_to(np.asarray(cv, dtype=np.float64), ci.shape).copy()
            if ca.shape != ci.shape:
                raise ParameterError("Plane constraints need one axis per vertex index.")
            if ca.size and (ca.min() < 0 or ca.max() > 2):
                raise ParameterError("Plane constraint axes must be 0 (x), 1 (y) or 2 (z).")
            if ci.size and (ci.min() < 0 or ci.max() >= n):
                raise ParameterError(f"Some plane constraints refer to vertices that do not "
                                     f"exist (the mesh has {n} vertices).")
            if not np.isfinite(cv).all():
                raise ParameterError("Plane constraint values must be finite numbers.")
        else:
            ci = ca = np.zeros(0, np.int64)
            cv = np.zeros(0)

        # exact values in input units (written back into every output)
        exact = V.copy()
        exact[hidx] = htgt
        exact[ci, ca] = cv
        known = Vn.copy()
        known[hidx] = (htgt - center) / scale
        known[ci, ca] = (cv - center[ca]) / scale
        constrained = np.zeros((n, 3), dtype=bool)
        constrained[fixed] = True
        constrained[hidx] = True
        constrained[ci, ca] = True

        # translation null space per component
        referenced = np.zeros(n, dtype=bool)
        referenced[F.ravel()] = True
        ncomp, lab = connected_components(F, n, over="vertices")
        pin_i, pin_a = [], []
        self._recenter: list[tuple[np.ndarray, np.ndarray, list[int]]] = []
        areas = barycentric_vertex_areas(Vn, F)
        for c in range(ncomp):
            verts = np.flatnonzero((lab == c) & referenced)
            if verts.size == 0:
                continue
            free_dims = [d for d in range(3) if not constrained[verts, d].any()]
            if not free_dims:
                continue
            for d in free_dims:
                pin_i.append(verts[0])
                pin_a.append(d)
            if not pin_one_vertex:
                w = areas[verts]
                w = w / w.sum() if w.sum() > 0 else np.full(len(verts), 1.0 / len(verts))
                self._recenter.append((verts, w, free_dims))
        pin_i = np.asarray(pin_i, dtype=np.int64)
        pin_a = np.asarray(pin_a, dtype=np.int64)
        constrained[pin_i, pin_a] = True
        #: vertices pinned in some coordinate to remove a part's free translation
        self.pinned = np.unique(pin_i) if pin_one_vertex else np.zeros(0, np.int64)
        exact_mask = constrained.copy()
        if not pin_one_vertex:
            exact_mask[pin_i, pin_a] = False  # pinned internally only, then translated
        self._exact_rows, self._exact_cols = np.nonzero(exact_mask)  # usually none
        # the recentring of each part as (vertices or a slice for all, weights, axes, weighted
        # rest centroid): no fancy indexing per iteration for the usual single-part mesh
        self._recenter = [(slice(None) if len(verts) == len(Vn)
                           and np.array_equal(verts, np.arange(len(Vn))) else verts,
                           w, slice(None) if list(dims) == [0, 1, 2] else dims,
                           w @ Vn[verts][:, dims])
                          for verts, w, dims in self._recenter]

        self.known = known
        self.exact = exact
        all_i = np.concatenate([ci, pin_i])
        all_a = np.concatenate([ca, pin_a])
        self.system = ArapSystem(Vn, F, fixed=np.union1d(fixed, hidx),
                                 coord_constraints=(all_i, all_a), backend=backend)
        self.normals = vertex_normals(Vn, F)
        self.areas = areas

    def _to_output(self, U: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``U`` in the input's units (``out``: that product, already computed), with the
        exactly prescribed coordinates copied from the input."""
        if out is None:
            out = U * self.scale + self.center
        if len(self._exact_rows):
            out[self._exact_rows, self._exact_cols] = self.exact[self._exact_rows,
                                                                 self._exact_cols]
        return out

    def style_prox(self, params: CubicParams, *, lam_axes=None, rotation=None,
                   style_matrix=None, frames=None) -> L1Prox:
        """The z-step operator for the weighted, oriented style matrix ``diag(s) B Q^T``.

        With ``frames`` (not None) the orientation is per vertex and handled by the local step:
        ``rotation`` and ``params.rot_x/y/z`` are ignored and the operator is for
        ``diag(s) B`` (the frames themselves are not used or checked here).
        """
        B = np.asarray(STYLE_PRESETS[params.style] if style_matrix is None else style_matrix,
                       dtype=np.float64)
        if B.ndim != 2 or B.shape[1] != 3 or len(B) == 0:
            raise ParameterError("The style matrix must have 3 columns and at least one row.")
        if lam_axes is not None:
            s = np.asarray(lam_axes, dtype=np.float64).reshape(-1)
            if len(s) != len(B):
                raise ParameterError(f"Per-axis λ needs one factor per row of the style matrix "
                                     f"({len(B)}), got {len(s)}.")
        elif params.per_axis:
            if len(B) != 3:
                raise ParameterError("Per-axis λ (x, y, z factors) works with the cube style "
                                     "only; pass one factor per row of the style matrix instead.")
            s = np.array([params.axis_factor_x, params.axis_factor_y, params.axis_factor_z])
        else:
            s = np.ones(len(B))
        if (s < 0).any() or not np.isfinite(s).all():
            raise ParameterError("Per-axis λ factors must be finite and non-negative.")
        B = s[:, None] * B
        if frames is not None:  # the frames take precedence over any global orientation
            return L1Prox(B)
        if rotation is None and (params.rot_x or params.rot_y or params.rot_z):
            rotation = rotation_from_degrees(params.rot_x, params.rot_y, params.rot_z)
        if rotation is not None:
            Q = np.asarray(rotation, dtype=np.float64)
            if Q.shape != (3, 3) or not np.allclose(Q.T @ Q, np.eye(3), atol=1e-6):
                raise ParameterError("The cube orientation must be a 3×3 rotation matrix.")
            B = B @ Q.T
        return L1Prox(B)

    def steps(self, params: CubicParams = CubicParams(), *, lam_per_vertex=None, lam_axes=None,
              rotation=None, style_matrix=None, frames=None, initial=None) -> Iterator[Step]:
        """Run Alg. 3, one :class:`~algorithms.steps.Step` per local-global iteration.

        Parameters
        ----------
        params : CubicParams (``normalize`` and ``pin_one_vertex`` are the stylizer's own).
        lam_per_vertex : (n,) float, optional, λ_i replacing ``params.lam`` (painted cubeness).
        lam_axes : (m,) float, optional, per-row factors of λ (one per row of the style matrix;
            for the cube: x, y, z). Overrides ``params.per_axis``.
        rotation : (3, 3) float, optional, the cube's axes as columns (overrides
            ``params.rot_x/y/z``).
        style_matrix : (m, 3) float, optional, overrides ``params.style``.
        frames : (n, 3, 3) float, optional, per-vertex local frames (rotation matrices, columns
            = the cube's axes at vertex i; thesis §5.4 ``n_i^local``): the L1 term at vertex i
            is ``||B Q_i^T R_i n_i||_1``. Takes precedence over ``rotation`` and
            ``params.rot_x/y/z``, which are then ignored. Must be finite, orthonormal to 1e-6
            and have determinant +1 (:func:`validate_frames`).
        initial : (n, 3) float, optional, positions (input units) the first local step starts
            from instead of the input's (a warm start, e.g. a coarse solution put back on this
            mesh); constrained coordinates still take their prescribed values.

        Yields
        ------
        Step with ``V`` (n, 3) in the input's units and metrics ``energy``, ``arap``, ``l1``,
        ``displacement``, ``admm_iterations``, ``admm_iterations_max``; ``total`` is None while
        the run stops on ``rel_displacement_tol`` (> 0), else ``max_iterations``.
        """
        validate_params(params)
        n = self.n
        if lam_per_vertex is None:
            lam = np.full(n, float(params.lam))
        else:
            lam = np.asarray(lam_per_vertex, dtype=np.float64).reshape(-1)
            if lam.shape != (n,):
                raise ParameterError(f"Per-vertex λ needs one value per vertex ({n}), "
                                     f"got {lam.size}.")
            if (lam < 0).any() or not np.isfinite(lam).all():
                raise ParameterError("Per-vertex λ must be finite and non-negative.")
        if frames is not None:
            frames = validate_frames(frames, n)
        else:
            # A global orientation of a cube-like (diagonal) style is the special case "every
            # frame = Q": the compiled cube kernel handles that, while folding Q into B would
            # send the z-step to the general polyhedral solver (about 12x slower). The two give
            # the same optimum (equal to round-off; tested).
            Q = rotation
            if Q is None and (params.rot_x or params.rot_y or params.rot_z):
                Q = rotation_from_degrees(params.rot_x, params.rot_y, params.rot_z)
            B0 = np.asarray(STYLE_PRESETS[params.style] if style_matrix is None
                            else style_matrix, dtype=np.float64)
            if (Q is not None and B0.shape == (3, 3) and np.count_nonzero(B0 - np.diag(np.diag(B0))) == 0
                    and not np.allclose(Q, np.eye(3), atol=0, rtol=0)):
                frames = validate_frames(np.broadcast_to(np.asarray(Q, dtype=np.float64),
                                                         (n, 3, 3)), n)
        prox = self.style_prox(params, lam_axes=lam_axes, rotation=rotation,
                               style_matrix=style_matrix, frames=frames)
        lam_a = lam * self.areas
        use = admm_vertices(lam_a, self.normals)
        system, known, Vn = self.system, self.known, self.V_normalized
        state = AdmmState.initial(n, params.rho0)
        if initial is None:
            U = Vn.copy()
        else:
            U = np.array(initial, dtype=np.float64, copy=True)
            if U.shape != (n, 3) or not np.isfinite(U).all():
                raise ParameterError(f"The starting positions must be {n} finite points.")
            U = (U - self.center) / self.scale
        U[system.constrained] = known[system.constrained]
        # the run stops on the tolerance: the number of iterations is not known in advance
        total_its = None if params.rel_displacement_tol > 0 else params.max_iterations
        kern = compiled_kernels()
        fused = kern is not None and prox.diagonal is not None and system.n_cells == n
        S = system.covariances(U)
        for it in range(1, params.max_iterations + 1):
            if not params.warm_start:
                state = AdmmState.initial(n, params.rho0)
            R, iters = admm_local_step(S, self.normals, lam_a, prox, state, params, frames, use)
            b = system.rhs(R)
            Un = system.solve(b, known)
            for verts, w, dims, rest_centroid in self._recenter:
                if isinstance(verts, slice):
                    Un[:, dims] += rest_centroid - w @ Un[:, dims]
                else:
                    Un[np.ix_(verts, dims)] += rest_centroid - w @ Un[verts][:, dims]
            if fused:
                # the covariances at the new positions (for the local step next), the L1 term,
                # the move and the output in one parallel pass over the vertices
                S, V_out, e_l1, step, total, bbox = kern.cube_after_solve(
                    *system._k_blocks(), Un, R, self.normals, frames, prox.diagonal, lam_a, U,
                    Vn, self.scale, self.center)
                disp = displacement_ratio(step, total, bbox)
                U = Un
            else:
                disp = relative_displacement(Un, U, Vn)
                U = Un
                S = system.covariances(U)
                V_out = None
            # U solves Q U = b up to translations of its parts and R are rotations: the
            # energy is one dot product
            e_arap = max(system.energy_after_solve(U, R, b, rotations=True, covariances=S), 0.0)
            if not fused:
                if kern is not None:
                    Rn = np.empty((n, 3))
                    if frames is None:
                        kern.rotate_normals(R, self.normals, Rn)
                    else:
                        kern.frame_normals(R, self.normals, frames, Rn)
                else:
                    Rn = np.einsum("kab,kb->ka", R, self.normals)
                    if frames is not None:  # in the local frames
                        Rn = np.einsum("kba,kb->ka", frames, Rn)
                e_l1 = float((lam_a * prox.norm(Rn)).sum())
            n_ran = np.count_nonzero(iters)  # vertices that ran ADMM (the others have 0)
            metrics = {
                "energy": e_arap + e_l1,
                "arap": e_arap,
                "l1": e_l1,
                "displacement": disp,
                "admm_iterations": float(iters.sum() / n_ran) if n_ran else 0.0,
                "admm_iterations_max": float(iters.max()) if n_ran else 0.0,
            }
            yield Step(iteration=it, total=total_its, V=self._to_output(U, V_out),
                       metrics=metrics, message=f"iteration {it}, relative move {disp:.2e}")
            if disp < params.rel_displacement_tol:
                break


def cubic_stylization_iter(V, F, params: CubicParams = CubicParams(), *, lam_per_vertex=None,
                           lam_axes=None, fixed=None, handles=None, coord_constraints=None,
                           rotation=None, style_matrix=None, frames=None,
                           backend: str = "auto") -> Iterator[Step]:
    """Cubic stylization (thesis Alg. 3), one :class:`~algorithms.steps.Step` per iteration.

    Parameters
    ----------
    V : (n, 3) float64 input positions (not modified).
    F : (m, 3) int64 triangles (never changed: the output uses the same F).
    params : CubicParams.
    lam_per_vertex : (n,) float, optional, per-vertex λ (replaces ``params.lam``).
    lam_axes : (m,) float, optional, per-axis factors of λ (one per style-matrix row).
    fixed : (k,) int, optional, vertices kept at their input positions.
    handles : tuple (indices (h,), targets (h, 3)), optional, point constraints.
    coord_constraints : tuple (indices, axes, values), optional, plane constraints.
    rotation : (3, 3), optional, the cube's axes as columns.
    style_matrix : (m, 3), optional, overrides ``params.style``.
    frames : (n, 3, 3), optional, per-vertex cube orientations (rotation matrices, columns =
        axes); take precedence over ``rotation`` (see :meth:`CubicStylizer.steps`).
    backend : global-step solver: "auto" (direct), "cholmod", "superlu" or "multigrid" (surface
        multigrid V-cycles, warm-started; see :class:`~algorithms.deform.arap.ArapSystem`).

    Yields
    ------
    Step; see :meth:`CubicStylizer.steps`.
    """
    validate_params(params)
    st = CubicStylizer(V, F, fixed=fixed, handles=handles, coord_constraints=coord_constraints,
                       normalize=params.normalize, pin_one_vertex=params.pin_one_vertex,
                       backend=backend)
    yield from st.steps(params, lam_per_vertex=lam_per_vertex, lam_axes=lam_axes,
                        rotation=rotation, style_matrix=style_matrix, frames=frames)


def cubic_stylization(V, F, params: CubicParams = CubicParams(), **kwargs) -> np.ndarray:
    """Run :func:`cubic_stylization_iter` to the end and return the (n, 3) stylized positions."""
    return run_to_end(cubic_stylization_iter(V, F, params, **kwargs)).V
