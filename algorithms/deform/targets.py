"""Target normals on the sphere for normal-driven shape analogies (thesis §6.3.1, §6.3.2).

A *target map* turns unit normals into target normals: ``T = target_map(N)`` with ``N`` and ``T``
of shape ``(k, 3)``. Through the Gauss map (§6.3.2) a normal of the input shape B *is* a point of
the unit sphere A, so a map defined on the sphere ("Ñ_A'" in the thesis) gives every vertex or
face of B its target by evaluating the map at its normal. Three maps share the one protocol
:class:`TargetMap`:

1. **Closest normals** (:class:`ClosestNormals`) of a convex style shape A' with few distinct face
   normals: a direction goes to the style normal with the largest dot product
   (:func:`closest_normal_targets`). The normals come from a named primitive
   (:func:`primitive_normals`: Platonic solids, prisms with any number of sides, a square
   pyramid) or from any closed convex user mesh (:func:`mesh_style_normals`: its face normals,
   merged within an angle tolerance with area weights).
2. **Spherical parameterization** (:class:`SphericalStyleMap`) of a genus-0 style shape: the
   shape is flowed to a sphere by conformalized mean curvature flow (Kazhdan et al. 2012; the
   project's :func:`algorithms.smoothing.smooth_iter` with ``flow="cmcf"``, time step 1e-3 of
   the surface area, at most 300 steps), centred at its area-weighted centroid and projected
   onto the unit sphere. The flow stops early once one step turns no projected vertex direction
   by more than ``direction_tol_deg`` (0.02°): from then on the shape is round and the map only
   slides slowly (measured steps: a cube 31, organic_sample("blob") 136, spot 178, an
   icosphere 1). A direction ``d`` goes to the normal of the style face whose spherical image
   contains ``d``.
3. **Normal capture** (:class:`CaptureSphere`), the geometric MatCap: regions painted on an
   icosphere, each with a target normal, saved as ``capture.json``.

Choices written down here:

* Ties in the closest normals (a direction exactly between two style normals) go to the style
  normal listed first. Zero rows of ``N`` (degenerate faces, isolated vertices) are returned as
  zero rows by every map (the analogy then has no normal term there).
* Primitive orientation: the cube's normals are the coordinate axes; Platonic solids are those
  of :mod:`algorithms.mesh.primitives`; prisms have their axis along ``z`` with one side facing
  ``+x``; the pyramid is the regular square pyramid with equilateral sides (Johnson solid J1),
  base facing ``-z`` and sides facing ``+-x``, ``+-y`` (inclined ``arctan(sqrt 2)`` = 54.7° to
  the base). ``rotation`` (a 3x3 rotation applied to the style normals) turns any of them.
* User meshes for closest normals must be closed and convex (their hull volume equals their
  volume within 0.1%): a concave shape has normals that no "closest normal" rule can reproduce,
  and the message points to the spherical parameterization. An inward-oriented mesh (negative
  volume) has its normals negated, and ``ClosestNormals.notes`` says so.
* Spherical parameterization point location: a KD-tree on the spherical face centroids gives
  the 8 nearest faces; the first whose cone contains ``d`` (all barycentric coordinates of the
  ray through ``d`` >= -1e-12) is taken, and where none does (flipped or very thin spherical
  triangles left by the flow) the candidate with the largest smallest barycentric coordinate.
  ``interpolate="face"`` (default) returns that style face's normal (piecewise constant, keeps
  the style's sharp features); ``"vertex"`` blends the style's area-weighted vertex normals with
  the clamped, renormalized barycentric coordinates (smooth). ``SphericalStyleMap.flipped_faces``
  counts the spherical triangles the flow turned inside out (0 for well-behaved shapes).
* Refusals: the spherical map needs one closed, manifold, genus-0 surface; anything else raises
  :class:`~algorithms.errors.InvalidMeshError` saying what is wrong and what to do. An
  inward-oriented style shape is reoriented (``notes`` says so).
* Capture spheres: the sphere is ``icosphere(subdivisions)``; every sphere vertex has a label
  (``-1`` = unpainted) and every label a unit target normal. A direction takes the label of the
  nearest sphere vertex; an unpainted direction is its own target (no change there).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from ..mesh.operators import face_areas, face_normals, signed_volume, vertex_normals
from ..mesh.primitives import dodecahedron, icosahedron, icosphere, octahedron, tetrahedron
from ..mesh.topology import boundary_loops, connected_components, genus, is_manifold

__all__ = [
    "TargetMap",
    "PRIMITIVES",
    "primitive_normals",
    "mesh_style_normals",
    "closest_normal_targets",
    "ClosestNormals",
    "SphericalStyleMap",
    "CaptureSphere",
    "CAPTURE_FORMAT",
    "unit_rows",
]

#: Names accepted by :func:`primitive_normals`.
PRIMITIVES = ("cube", "tetrahedron", "octahedron", "dodecahedron", "icosahedron",
              "triangular_prism", "hexagonal_prism", "prism", "pyramid")
#: The ``format`` tag of capture.json files.
CAPTURE_FORMAT = "stylize3d.normal-capture"


@runtime_checkable
class TargetMap(Protocol):
    """Anything that maps unit normals to target normals (the sphere's Ñ_A', §6.3.1).

    ``__call__(N)`` takes ``N`` (k, 3) float64 unit normals (zero rows allowed) and returns
    ``T`` (k, 3) float64 unit target normals (zero rows where ``N`` has zero rows).
    """

    def __call__(self, N: np.ndarray) -> np.ndarray: ...


def unit_rows(X: np.ndarray) -> np.ndarray:
    """Rows of ``X`` (k, 3) scaled to unit length; zero rows stay zero. Returns (k, 3) float64."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2:
        ln = np.linalg.norm(X, axis=-1, keepdims=True)
        out = np.zeros_like(X)
        np.divide(X, ln, out=out, where=ln > 0)
        return out
    ln = np.sqrt(np.einsum("ij,ij->i", X, X))
    inv = np.zeros_like(ln)
    np.divide(1.0, ln, out=inv, where=ln > 0)
    return X * inv[:, None]


def _as_normals(N, what: str = "normals") -> np.ndarray:
    N = np.asarray(N, dtype=np.float64)
    if N.ndim != 2 or N.shape[1] != 3:
        raise ParameterError(f"The {what} must be an (k, 3) array, got shape {N.shape}.")
    if not np.isfinite(N).all():
        raise ParameterError(f"The {what} contain NaN or infinite values.")
    return N


def _rotate(normals: np.ndarray, rotation) -> np.ndarray:
    if rotation is None:
        return normals
    Q = np.asarray(rotation, dtype=np.float64)
    if Q.shape != (3, 3) or not np.allclose(Q.T @ Q, np.eye(3), atol=1e-6) \
            or np.linalg.det(Q) < 0:
        raise ParameterError("The style orientation must be a 3×3 rotation matrix.")
    return normals @ Q.T


def _merge_normals(normals: np.ndarray, weights: np.ndarray, angle_tol_deg: float) -> np.ndarray:
    """Greedy clustering of unit normals: the heaviest unassigned normal seeds a cluster of all
    unassigned normals within ``angle_tol_deg``; the cluster's weighted mean is kept. One pass
    per distinct normal (style shapes have few)."""
    cos_tol = np.cos(np.radians(angle_tol_deg))
    keep = np.linalg.norm(normals, axis=1) > 0
    normals, weights = normals[keep], weights[keep]
    order = np.argsort(-weights, kind="stable")
    normals, weights = normals[order], weights[order]
    free = np.ones(len(normals), dtype=bool)
    out = []
    while free.any():
        seed = normals[np.argmax(free)]
        members = free & (normals @ seed >= cos_tol)
        members[np.argmax(free)] = True
        out.append((weights[members, None] * normals[members]).sum(axis=0))
        free &= ~members
    return unit_rows(np.array(out).reshape(-1, 3))


def primitive_normals(name: str, n: int = 8, rotation=None) -> np.ndarray:
    """Distinct face normals of a convex style primitive.

    Parameters
    ----------
    name : str
        One of :data:`PRIMITIVES`: ``cube``, ``tetrahedron``, ``octahedron``, ``dodecahedron``,
        ``icosahedron``, ``triangular_prism`` (= ``prism`` with n = 3), ``hexagonal_prism``
        (n = 6), ``prism`` (an n-gon prism: cylinder-like for large n), ``pyramid`` (square
        pyramid with equilateral sides).
    n : int
        Number of sides of ``prism`` (3 to 256); ignored otherwise.
    rotation : (3, 3) float, optional
        Rotation applied to the normals (orients the style; see the module docstring).

    Returns
    -------
    (k, 3) float64 unit normals: cube 6, tetrahedron 4, octahedron 8, dodecahedron 12,
    icosahedron 20, n-gon prism n + 2, pyramid 5.
    """
    key = str(name).strip().lower().replace("-", "_").replace(" ", "_")
    if key in ("triangular_prism", "hexagonal_prism", "prism"):
        sides = {"triangular_prism": 3, "hexagonal_prism": 6}.get(key, n)
        if isinstance(sides, bool) or int(sides) != sides or not 3 <= int(sides) <= 256:
            raise ParameterError(f"A prism needs a whole number of sides from 3 to 256 "
                                 f"(got {sides!r}).")
        ang = 2.0 * np.pi * np.arange(int(sides)) / int(sides)
        side = np.column_stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)])
        N = np.vstack([side, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
    elif key == "cube":
        N = np.vstack([np.eye(3), -np.eye(3)])
    elif key == "pyramid":
        h = np.sqrt(2.0)  # apex height over a base of side 2 with equilateral sides
        side = unit_rows(np.array([[h, 0, 1], [-h, 0, 1], [0, h, 1], [0, -h, 1]], float))
        N = np.vstack([side, [[0.0, 0.0, -1.0]]])
    elif key in ("tetrahedron", "octahedron", "dodecahedron", "icosahedron"):
        V, F = {"tetrahedron": tetrahedron, "octahedron": octahedron,
                "dodecahedron": dodecahedron, "icosahedron": icosahedron}[key]()
        N = _merge_normals(face_normals(V, F), face_areas(V, F), 1e-3)
    else:
        raise ParameterError(f"Unknown style primitive {name!r}. Choose one of: "
                             f"{', '.join(PRIMITIVES)}.")
    return np.ascontiguousarray(_rotate(unit_rows(N), rotation))


def mesh_style_normals(V, F, *, angle_tol_deg: float = 1.0,
                       require_convex: bool = True) -> tuple[np.ndarray, bool]:
    """Distinct face normals of a closed convex user mesh (a style shape A' for closest normals).

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64
        The style mesh; closed, and convex when ``require_convex``.
    angle_tol_deg : float
        Face normals within this angle of each other are merged (area-weighted mean).
    require_convex : bool
        Refuse a mesh that is not convex (see the module docstring).

    Returns
    -------
    normals : (k, 3) float64 unit normals, heaviest (largest total face area) first.
    flipped : bool, True when the mesh was oriented inwards and its normals were negated.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) < 4:
        raise InvalidMeshError("The style shape must be a closed triangle mesh (at least four "
                               "triangles).")
    if not np.isfinite(V).all():
        raise InvalidMeshError("The style shape has NaN or infinite coordinates; clean it first.")
    if boundary_loops(F):
        raise InvalidMeshError("The style shape has holes (open borders). Closest-normal styles "
                               "need a closed convex shape; fill the holes first.")
    vol = signed_volume(V, F)
    flipped = vol < 0
    if require_convex:
        from scipy.spatial import ConvexHull

        try:
            hull = ConvexHull(V)
        except Exception:  # flat or degenerate point sets
            raise InvalidMeshError("The style shape is flat or degenerate; it has no volume, so "
                                   "it cannot serve as a closest-normal style.") from None
        if abs(abs(vol) - hull.volume) > 1e-3 * hull.volume:
            raise InvalidMeshError(
                "The style shape is not convex (its volume differs from its convex hull's), so "
                "'closest normals' cannot capture its style. Use the spherical parameterization "
                "(SphericalStyleMap) for concave or smooth style shapes.")
    N = face_normals(V, F)
    if flipped:
        N = -N
    return _merge_normals(N, face_areas(V, F), angle_tol_deg), bool(flipped)


def closest_normal_targets(N, style_normals) -> np.ndarray:
    """Snap each normal to the style normal with the largest dot product (§6.3.1, item 1).

    Parameters
    ----------
    N : (n, 3) float array, unit normals (zero rows allowed).
    style_normals : (k, 3) float array, unit style normals.

    Returns
    -------
    T : (n, 3) float64; ``T[i] = style_normals[argmax_j N[i] . style_normals[j]]`` (the first
    on ties); zero rows of ``N`` give zero rows.
    """
    N = _as_normals(N)
    S = _as_normals(style_normals, "style normals")
    if len(S) == 0:
        raise ParameterError("The style has no normals.")
    T = S[np.argmax(N @ S.T, axis=1)]
    T[~(np.abs(N).sum(axis=1) > 0)] = 0.0
    return T


@dataclass
class ClosestNormals:
    """Target map snapping normals to the closest of a fixed set of style normals.

    Parameters
    ----------
    style_normals : (k, 3) float array (normalized on construction).
    notes : list of str, things the user should be told (e.g. an inward style mesh was flipped).

    Examples
    --------
    >>> T = ClosestNormals.primitive("cube")(np.array([[0.9, 0.1, 0.0]]))
    >>> T.tolist()
    [[1.0, 0.0, 0.0]]
    """

    style_normals: np.ndarray
    notes: list[str] = field(default_factory=list)

    def __post_init__(self):
        S = unit_rows(_as_normals(self.style_normals, "style normals"))
        if len(S) == 0 or not (np.linalg.norm(S, axis=1) > 0).all():
            raise ParameterError("Style normals must be non-zero vectors (at least one).")
        self.style_normals = S

    @classmethod
    def primitive(cls, name: str, n: int = 8, rotation=None) -> "ClosestNormals":
        """Closest normals of a named primitive (see :func:`primitive_normals`)."""
        return cls(primitive_normals(name, n, rotation))

    @classmethod
    def from_mesh(cls, V, F, *, angle_tol_deg: float = 1.0, rotation=None) -> "ClosestNormals":
        """Closest normals of a closed convex user mesh (see :func:`mesh_style_normals`)."""
        N, flipped = mesh_style_normals(V, F, angle_tol_deg=angle_tol_deg)
        notes = ["The style shape was oriented inwards; its normals were turned outwards."] \
            if flipped else []
        return cls(_rotate(N, rotation), notes)

    def __call__(self, N: np.ndarray) -> np.ndarray:
        """Targets ``(k, 3)`` for the unit normals ``N (k, 3)``."""
        return closest_normal_targets(N, self.style_normals)


# ------------------------------------------------------------------------------ spherical map
class SphericalStyleMap:
    """Target map from a spherical parameterization of a genus-0 style shape (§6.3.1, item 2).

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64
        The style shape A': one closed, manifold, genus-0 surface.
    time_step : float
        cMCF time step as a fraction of the surface area (Kazhdan et al.; default 1e-3).
    max_steps : int
        At most this many flow steps (default 300).
    interpolate : {"face", "vertex"}
        Return the style face's normal, or the barycentric blend of the style's vertex normals.
    direction_tol_deg : float
        Stop the flow once a step turns no vertex direction (seen from the centroid) by more
        than this angle (0 runs all ``max_steps``).

    Attributes
    ----------
    sphere : (n, 3) float64, the style vertices on the unit sphere.
    style_face_normals : (m, 3), style_vertex_normals : (n, 3), unit normals of A'.
    steps_taken : int, cMCF steps run.
    flipped_faces : int, spherical triangles with the wrong orientation after the flow.
    notes : list of str, things the user should be told.

    Raises
    ------
    InvalidMeshError
        The shape is not one closed manifold genus-0 surface, or the flow collapsed it.
    """

    CANDIDATES = 8

    def __init__(self, V, F, *, time_step: float = 1e-3, max_steps: int = 300,
                 interpolate: str = "face", direction_tol_deg: float = 0.02):
        from scipy.spatial import cKDTree

        from ..smoothing import SmoothParams, smooth_iter

        V = np.array(V, dtype=np.float64, copy=True)
        F = np.array(F, dtype=np.int64, copy=True)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) < 4:
            raise InvalidMeshError("The style shape must be a closed triangle mesh (at least "
                                   "four triangles).")
        if not np.isfinite(V).all():
            raise InvalidMeshError("The style shape has NaN or infinite coordinates; clean it "
                                   "first.")
        if F.min() < 0 or F.max() >= len(V):
            raise InvalidMeshError("Some faces of the style shape refer to vertices that do not "
                                   "exist. Validate the mesh to see which.")
        if interpolate not in ("face", "vertex"):
            raise ParameterError(f"interpolate must be 'face' or 'vertex' (got {interpolate!r}).")
        if not (isinstance(max_steps, (int, np.integer)) and 1 <= max_steps <= 1000):
            raise ParameterError("The number of flow steps must be a whole number from 1 to "
                                 "1000.")
        ncomp, _ = connected_components(F)
        if ncomp != 1:
            raise InvalidMeshError(
                f"The style shape has {ncomp} separate parts; a spherical parameterization needs "
                "exactly one closed surface. Keep only the main part (Clean, or split the mesh).")
        if not is_manifold(F):
            raise InvalidMeshError("The style shape is not manifold (some edges or vertices are "
                                   "shared by too many triangles); clean it first.")
        if boundary_loops(F):
            raise InvalidMeshError("The style shape has holes (open borders); a spherical "
                                   "parameterization needs a closed surface. Fill the holes first.")
        g = genus(F)
        if g != 0:
            raise InvalidMeshError(
                f"The style shape has genus {g} (it has {g} handle{'s' if g != 1 else ''}, like a "
                "torus), so it cannot be mapped onto a sphere. Use a genus-0 shape (no handles) or "
                "a closest-normal primitive.")
        used = np.unique(F)
        if len(used) != len(V):  # drop loose points: they have no place on the sphere
            remap = np.full(len(V), -1, np.int64)
            remap[used] = np.arange(len(used))
            V, F = V[used], remap[F]
        self.notes: list[str] = []
        if signed_volume(V, F) < 0:
            F = F[:, [0, 2, 1]]
            self.notes.append("The style shape was oriented inwards; its normals were turned "
                              "outwards.")
        self.V, self.F = V, F
        self.interpolate = interpolate
        self.style_face_normals = face_normals(V, F)
        self.style_vertex_normals = vertex_normals(V, F)

        def directions(X: np.ndarray) -> np.ndarray:
            a = face_areas(X, F)
            c = (X[F].mean(axis=1) * a[:, None]).sum(axis=0) / max(a.sum(), 1e-300)
            return unit_rows(X - c)

        S = directions(V)
        self.steps_taken = 0
        cos_tol = np.cos(np.radians(float(direction_tol_deg)))
        sp_params = SmoothParams(flow="cmcf", step_size=float(time_step),
                                 iterations=int(max_steps), keep_size=True)
        for step in smooth_iter(V, F, sp_params):
            S_new = directions(step.V)
            self.steps_taken = step.iteration
            turned = float(np.einsum("ij,ij->i", S, S_new).min())
            S = S_new
            if direction_tol_deg > 0 and turned >= cos_tol:
                break
        if not (np.linalg.norm(S, axis=1) > 0).all():
            raise InvalidMeshError("The flow to the sphere collapsed part of the style shape. "
                                   "Remesh it more evenly and try again.")
        self.sphere = S
        P = S[F]  # (m, 3 corners, 3)
        M = P.transpose(0, 2, 1)  # columns = corners
        det = np.linalg.det(M)
        self.flipped_faces = int((det <= 0).sum())
        ok = np.abs(det) > 1e-300
        Minv = np.zeros_like(M)
        Minv[ok] = np.linalg.inv(M[ok])
        self._Minv = Minv
        self._tree = cKDTree(unit_rows(P.mean(axis=1)))

    def locate(self, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point location on the spherical mesh.

        Parameters
        ----------
        D : (k, 3) float array, directions (need not be unit; zero rows allowed).

        Returns
        -------
        faces : (k,) int64, the style face whose spherical image contains each direction.
        bary : (k, 3) float64, barycentric coordinates (clamped to >= 0, summing to 1).
        """
        D = unit_rows(_as_normals(D, "directions"))
        kq = min(self.CANDIDATES, len(self.F))
        _, cand = self._tree.query(D, k=kq)
        cand = cand.reshape(len(D), kq)
        lam = np.einsum("qkab,qb->qka", self._Minv[cand], D)  # (q, k, 3)
        score = lam.min(axis=2)
        inside = score >= -1e-12
        pick = np.where(inside.any(axis=1), np.argmax(inside, axis=1), np.argmax(score, axis=1))
        rows = np.arange(len(D))
        faces = cand[rows, pick]
        b = np.maximum(lam[rows, pick], 0.0)
        sb = b.sum(axis=1, keepdims=True)
        b = np.divide(b, sb, out=np.full_like(b, 1.0 / 3.0), where=sb > 0)
        return faces.astype(np.int64), b

    def __call__(self, N: np.ndarray) -> np.ndarray:
        """Targets ``(k, 3)`` for the unit normals ``N (k, 3)``."""
        N = _as_normals(N)
        if len(N) == 0:
            return np.zeros((0, 3))
        faces, b = self.locate(N)
        if self.interpolate == "face":
            T = self.style_face_normals[faces].copy()
        else:
            T = unit_rows(np.einsum("qc,qcx->qx", b, self.style_vertex_normals[self.F[faces]]))
        T[~(np.abs(N).sum(axis=1) > 0)] = 0.0
        return T


# ------------------------------------------------------------------------------ normal capture
class CaptureSphere:
    """A normal capture (§6.3.1, item 3): regions painted on a sphere, each with a target normal.

    Parameters
    ----------
    subdivisions : int
        The sphere is ``icosphere(subdivisions)`` (0 to 6; 3 gives 642 vertices).
    labels : (p,) int array, optional
        Region of every sphere vertex, ``-1`` = unpainted (default: all unpainted).
    targets : (L, 3) float array, optional
        Target normal of every region (normalized on construction).

    Attributes
    ----------
    vertices : (p, 3) float64 unit sphere vertices; faces : (q, 3) int64 (for drawing).
    labels : (p,) int64; targets : (L, 3) float64.
    """

    def __init__(self, subdivisions: int = 3, labels=None, targets=None):
        if isinstance(subdivisions, bool) or int(subdivisions) != subdivisions \
                or not 0 <= int(subdivisions) <= 6:
            raise ParameterError("The capture sphere's subdivision level must be a whole number "
                                 f"from 0 to 6 (got {subdivisions!r}).")
        self.subdivisions = int(subdivisions)
        self.vertices, self.faces = icosphere(self.subdivisions)
        p = len(self.vertices)
        self.labels = (np.full(p, -1, np.int64) if labels is None
                       else np.array(labels, dtype=np.int64).reshape(-1))
        T = np.zeros((0, 3)) if targets is None else _as_normals(
            np.asarray(targets, np.float64).reshape(-1, 3), "capture targets")
        self.targets = unit_rows(T)
        self._tree = None
        self._check()

    def _check(self) -> None:
        p, L = len(self.vertices), len(self.targets)
        if self.labels.shape != (p,):
            raise ParameterError(f"A capture sphere of level {self.subdivisions} needs one label "
                                 f"per sphere vertex ({p}), got {self.labels.size}.")
        if self.labels.size and (self.labels.min() < -1 or self.labels.max() >= L):
            raise ParameterError(f"Capture labels must be -1 (unpainted) or a region number "
                                 f"from 0 to {L - 1}.")
        if L and not (np.linalg.norm(self.targets, axis=1) > 0).all():
            raise ParameterError("Every painted region needs a non-zero target normal.")

    @property
    def n_regions(self) -> int:
        """Number of regions (labels ``0 .. n_regions - 1``)."""
        return len(self.targets)

    def paint(self, vertices, target, label: int | None = None) -> int:
        """Paint sphere vertices with a target normal.

        Parameters
        ----------
        vertices : (k,) int, sphere vertex indices.
        target : (3,) float, the target normal (normalized).
        label : int, optional, an existing region to extend (its target is replaced by
            ``target``); default: a new region.

        Returns
        -------
        int, the region's label.
        """
        idx = np.asarray(vertices, dtype=np.int64).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= len(self.vertices)):
            raise ParameterError("Some painted vertices are not on the capture sphere.")
        t = unit_rows(_as_normals(np.asarray(target, np.float64).reshape(1, 3), "target"))
        if not np.linalg.norm(t) > 0:
            raise ParameterError("The target normal of a region must be a non-zero vector.")
        if label is None:
            self.targets = np.vstack([self.targets, t])
            label = len(self.targets) - 1
        else:
            if not 0 <= int(label) < len(self.targets):
                raise ParameterError(f"There is no region {label}.")
            label = int(label)
            self.targets[label] = t[0]
        self.labels[idx] = label
        return label

    def paint_cap(self, direction, radius_degrees: float, target) -> int:
        """Paint every sphere vertex within ``radius_degrees`` of ``direction (3,)``; returns
        the new region's label."""
        d = unit_rows(_as_normals(np.asarray(direction, np.float64).reshape(1, 3), "direction"))
        inside = self.vertices @ d[0] >= np.cos(np.radians(float(radius_degrees)))
        return self.paint(np.flatnonzero(inside), target)

    def erase(self, vertices) -> None:
        """Mark sphere vertices ``(k,) int`` as unpainted (regions keep their numbers)."""
        self.labels[np.asarray(vertices, dtype=np.int64).reshape(-1)] = -1

    def nearest_vertex(self, D: np.ndarray) -> np.ndarray:
        """Index ``(k,) int64`` of the sphere vertex nearest to each direction ``D (k, 3)``."""
        from scipy.spatial import cKDTree

        if self._tree is None:
            self._tree = cKDTree(self.vertices)
        _, idx = self._tree.query(unit_rows(_as_normals(D, "directions")))
        return np.asarray(idx, dtype=np.int64).reshape(-1)

    def __call__(self, N: np.ndarray) -> np.ndarray:
        """Targets ``(k, 3)`` for the unit normals ``N (k, 3)`` (unpainted: ``N`` itself)."""
        N = _as_normals(N)
        T = unit_rows(N)
        if len(N) == 0 or len(self.targets) == 0:
            return T
        lab = self.labels[self.nearest_vertex(N)]
        painted = (lab >= 0) & (np.abs(N).sum(axis=1) > 0)
        T[painted] = self.targets[lab[painted]]
        return T

    # ---------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        """JSON-safe dict: ``{"format", "version", "subdivisions", "regions": [{"target":
        [x, y, z], "vertices": [...]}, ...]}``."""
        return {
            "format": CAPTURE_FORMAT,
            "version": 1,
            "subdivisions": self.subdivisions,
            "regions": [{"target": [float(x) for x in t],
                         "vertices": np.flatnonzero(self.labels == r).tolist()}
                        for r, t in enumerate(self.targets)],
        }

    @classmethod
    def from_dict(cls, data: dict) -> "CaptureSphere":
        """Inverse of :meth:`to_dict` (raises ParameterError on malformed data)."""
        try:
            if data.get("format") != CAPTURE_FORMAT:
                raise ValueError(f"its format tag is {data.get('format')!r}, "
                                 f"not {CAPTURE_FORMAT!r}")
            if int(data.get("version", 0)) != 1:
                raise ValueError(f"version {data.get('version')!r} is not supported")
            sub = data["subdivisions"]
            regions = list(data["regions"])
            targets = np.array([r["target"] for r in regions], dtype=np.float64).reshape(-1, 3)
            cap = cls(sub)
            for r, reg in enumerate(regions):
                idx = np.asarray(reg["vertices"], dtype=np.int64).reshape(-1)
                if idx.size and (idx.min() < 0 or idx.max() >= len(cap.vertices)):
                    raise ValueError(f"region {r} lists vertices that are not on the sphere")
                cap.labels[idx] = r
        except ParameterError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise ParameterError(f"This is not a valid normal capture: {e}.") from None
        cap.targets = unit_rows(_as_normals(targets, "capture targets"))
        cap._check()
        return cap

    def save(self, path) -> None:
        """Write ``capture.json`` (UTF-8 JSON of :meth:`to_dict`)."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1), encoding="utf-8")

    @classmethod
    def load(cls, path) -> "CaptureSphere":
        """Read a file written by :meth:`save` (raises ParameterError with a plain message)."""
        p = Path(path)
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ParameterError(f"The normal capture file {p} does not exist.") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ParameterError(f"The normal capture file {p} could not be read ({e}).") from None
        if not isinstance(data, dict):
            raise ParameterError(f"The normal capture file {p} is not a capture (wrong contents).")
        return cls.from_dict(data)


STYLE_MAP_MODES = ("auto", "closest", "spherical")


def load_style(spec: str, mode: str = "auto") -> tuple[TargetMap, str]:
    """The target map a user names: a primitive (``"cube"``, ``"hexagonal_prism"``, ...; see
    :data:`PRIMITIVES`), a normal-capture file (``*.json``), or a style mesh file.

    For a mesh, ``mode`` picks option 1 (``"closest"``: closest face normals, convex meshes only)
    or option 2 (``"spherical"``: cMCF spherical parameterization, any closed genus-0 mesh);
    ``"auto"`` uses closest normals when the mesh is convex and the spherical map otherwise.

    Returns
    -------
    (target map, a one-line description for the user)
    """
    from ..mesh.io import read_mesh

    if mode not in STYLE_MAP_MODES:
        raise ParameterError(f"Style map must be one of {', '.join(STYLE_MAP_MODES)}.")
    if spec in PRIMITIVES:
        return ClosestNormals.primitive(spec), f"closest normals of a {spec.replace('_', ' ')}"
    path = Path(spec)
    if path.suffix.lower() == ".json":
        cap = CaptureSphere.load(path)
        return cap, f"normal capture {path.name} ({cap.n_regions} painted regions)"
    if not path.exists():
        raise ParameterError(f"Unknown style '{spec}': use one of {', '.join(PRIMITIVES)}, a "
                             "capture .json file or a mesh file.")
    data = read_mesh(path)
    if mode in ("auto", "closest"):
        try:
            return (ClosestNormals.from_mesh(data.V, data.F),
                    f"closest normals of {path.name}")
        except InvalidMeshError:
            if mode == "closest":
                raise
    sm = SphericalStyleMap(data.V, data.F)
    return sm, f"spherical map of {path.name} ({sm.steps_taken} cMCF steps)"
