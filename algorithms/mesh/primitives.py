"""Simple meshes made from scratch: Platonic solids, spheres, tori, grids, organic samples.

Every closed primitive is manifold and **outward oriented** (counter-clockwise seen from
outside, positive signed volume). Shapes: ``V`` is ``(n, 3) float64``, ``F`` is ``(m, 3) int64``.

Sizes
-----
* Platonic solids from :func:`platonic_solid` (and :func:`tetrahedron`, :func:`octahedron`,
  :func:`icosahedron`, :func:`dodecahedron`) have all vertices on the unit sphere (circumradius 1).
* :func:`cube` is the axis-aligned cube ``[-size/2, size/2]^3`` (default ``[-1, 1]^3``).
* :func:`icosphere` has its vertices on the sphere of the given radius.
* :func:`grid` is the unit square ``[0, 1]^2`` in the plane ``z = 0``, facing ``+z``.
* :func:`organic_sample` shapes are normalized to the unit box (longest side 1, centred).
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError

__all__ = [
    "tetrahedron",
    "cube",
    "octahedron",
    "icosahedron",
    "dodecahedron",
    "platonic_solid",
    "icosphere",
    "torus",
    "grid",
    "organic_sample",
    "ORGANIC_SAMPLES",
    "PLATONIC_SOLIDS",
]

#: Names accepted by :func:`platonic_solid`.
PLATONIC_SOLIDS = ("tetrahedron", "cube", "octahedron", "icosahedron", "dodecahedron")
#: Names accepted by :func:`organic_sample`, with their genus.
ORGANIC_SAMPLES = {"blob": 0, "bumpy": 0, "pretzel": 2}


def _int_param(value, name: str, minimum: int, maximum: int | None = None) -> int:
    try:
        iv = int(value)
        if iv != value:
            raise ValueError
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a whole number, not {value!r}.") from None
    if iv < minimum or (maximum is not None and iv > maximum):
        rng = f"at least {minimum}" if maximum is None else f"between {minimum} and {maximum}"
        raise ParameterError(f"{name} must be {rng}, got {iv}.")
    return iv


def _pos_param(value, name: str) -> float:
    try:
        fv = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, not {value!r}.") from None
    if not (fv > 0 and np.isfinite(fv)):
        raise ParameterError(f"{name} must be a positive number, got {value!r}.")
    return fv


def _orient_outward_convex(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip faces of a convex, origin-centred polytope so their normals point away from 0."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", n, a + b + c) < 0
    F = F.copy()
    F[inward] = F[inward][:, [0, 2, 1]]
    return F


def tetrahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular tetrahedron inscribed in the unit sphere.

    Returns
    -------
    V : (4, 3) float64
    F : (4, 3) int64
    """
    V = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64)
    V /= np.sqrt(3.0)
    F = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], dtype=np.int64)
    return V, _orient_outward_convex(V, F)


def octahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular octahedron with vertices at ``+-e_x, +-e_y, +-e_z``.

    Returns
    -------
    V : (6, 3) float64
    F : (8, 3) int64
    """
    V = np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
    )
    F = np.array(
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]],
        dtype=np.int64,
    )
    return V, _orient_outward_convex(V, F)


def icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular icosahedron inscribed in the unit sphere.

    Returns
    -------
    V : (12, 3) float64
    F : (20, 3) int64
    """
    t = (1.0 + np.sqrt(5.0)) / 2.0
    V = np.array(
        [
            [-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
            [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
            [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1],
        ],
        dtype=np.float64,
    )  # fmt: skip
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    F = np.array(
        [
            [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
            [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
            [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
            [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
        ],
        dtype=np.int64,
    )  # fmt: skip
    return V, _orient_outward_convex(V, F)


def dodecahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular dodecahedron inscribed in the unit sphere, each pentagon split into 3 triangles.

    Returns
    -------
    V : (20, 3) float64
    F : (36, 3) int64
    """
    # vertices = face centres of the icosahedron (its dual), pushed to the unit sphere
    Vi, Fi = icosahedron()
    V = Vi[Fi].mean(axis=1)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    # each icosahedron vertex becomes a pentagon made of the centres of its 5 faces
    tris = []
    for v in range(Vi.shape[0]):
        faces = np.flatnonzero((Fi == v).any(axis=1))
        c = V[faces]
        normal = Vi[v]
        u = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(normal, u)
        ang = np.arctan2((c - normal) @ w, (c - normal) @ u)
        ring = faces[np.argsort(ang)]
        tris += [[ring[0], ring[i], ring[i + 1]] for i in range(1, 4)]
    F = np.array(tris, dtype=np.int64)
    return V, _orient_outward_convex(V, F)


def cube(subdivisions: int = 0, size: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward-oriented triangulated cube ``[-size/2, size/2]^3``.

    Parameters
    ----------
    subdivisions : int
        Each face is an ``(s+1) x (s+1)`` grid of squares with ``s = subdivisions``, each square
        split into two triangles; vertices along edges and corners are shared.
    size : float
        Side length (default 2: the cube ``[-1, 1]^3``).

    Returns
    -------
    V : (6 (s+1)^2 + 2, 3) float64
    F : (12 (s+1)^2, 3) int64
    """
    s = _int_param(subdivisions, "subdivisions", 0, 200)
    size = _pos_param(size, "size")
    k = s + 1
    # integer lattice coordinates 0..k on each face, welded exactly, then scaled
    a, b = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    a, b = a.ravel(), b.ravel()
    ii, jj = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    p00 = ii * (k + 1) + jj
    p10 = (ii + 1) * (k + 1) + jj
    p01 = ii * (k + 1) + jj + 1
    p11 = (ii + 1) * (k + 1) + jj + 1
    local_F = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    pts = []
    faces = []
    offset = 0
    for axis in range(3):
        for side in (0, k):
            P = np.zeros((a.size, 3), dtype=np.int64)
            u, v = (axis + 1) % 3, (axis + 2) % 3
            P[:, axis] = side
            P[:, u] = a
            P[:, v] = b
            pts.append(P)
            faces.append(local_F + offset)
            offset += a.size
    P = np.concatenate(pts)
    F = np.concatenate(faces)
    uniq, inverse = np.unique(P, axis=0, return_inverse=True)
    F = inverse.ravel()[F]
    V = (uniq.astype(np.float64) / k - 0.5) * size
    return V, _orient_outward_convex(V, F.astype(np.int64))


def platonic_solid(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A Platonic solid by name, inscribed in the unit sphere.

    Parameters
    ----------
    name : {'tetrahedron', 'cube', 'octahedron', 'icosahedron', 'dodecahedron'}
        (``'hexahedron'`` is accepted for the cube.)

    Returns
    -------
    V : (n, 3) float64
    F : (m, 3) int64
    """
    key = str(name).strip().lower()
    if key == "hexahedron":
        key = "cube"
    if key == "cube":
        V, F = cube()
        return V / np.sqrt(3.0), F
    makers = {
        "tetrahedron": tetrahedron,
        "octahedron": octahedron,
        "icosahedron": icosahedron,
        "dodecahedron": dodecahedron,
    }
    if key not in makers:
        raise ParameterError(
            f"Unknown Platonic solid {name!r}. Choose one of: {', '.join(PLATONIC_SOLIDS)}."
        )
    return makers[key]()


def _midpoint_split(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One 1-to-4 midpoint subdivision step (vectorized)."""
    from .topology import unique_edges

    E, EMAP, _ = unique_edges(F)
    n, m = V.shape[0], F.shape[0]
    mid = (V[E[:, 0]] + V[E[:, 1]]) / 2.0
    e = EMAP.reshape(3, m).T + n  # e[:, c] = new vertex on the edge opposite corner c
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    ea, eb, ec = e[:, 0], e[:, 1], e[:, 2]
    F2 = np.concatenate(
        [np.stack([a, ec, eb], 1), np.stack([b, ea, ec], 1), np.stack([c, eb, ea], 1),
         np.stack([ea, eb, ec], 1)]
    )  # fmt: skip
    return np.vstack([V, mid]), F2


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Sphere made by subdividing an icosahedron and projecting onto the sphere.

    Parameters
    ----------
    subdivisions : int
        Number of 1-to-4 splits (0 = icosahedron). Level ``k`` has ``10 * 4^k + 2`` vertices
        and ``20 * 4^k`` faces.
    radius : float
        Sphere radius (all vertices lie exactly on it, up to rounding).

    Returns
    -------
    V : (10 * 4^k + 2, 3) float64
    F : (20 * 4^k, 3) int64
    """
    k = _int_param(subdivisions, "subdivisions", 0, 8)
    r = _pos_param(radius, "radius")
    V, F = icosahedron()
    for _ in range(k):
        V, F = _midpoint_split(V, F)
        V /= np.linalg.norm(V, axis=1, keepdims=True)
    return V * r, F


def torus(
    R: float = 1.0, r: float = 0.35, n_major: int = 48, n_minor: int = 24
) -> tuple[np.ndarray, np.ndarray]:
    """Torus around the z axis (genus 1), outward oriented.

    Parameters
    ----------
    R : float
        Distance from the centre to the centre of the tube.
    r : float
        Tube radius (``0 < r < R``).
    n_major, n_minor : int
        Segments around the axis and around the tube (each at least 3).

    Returns
    -------
    V : (n_major * n_minor, 3) float64
    F : (2 * n_major * n_minor, 3) int64
    """
    R = _pos_param(R, "R")
    r = _pos_param(r, "r")
    if r >= R:
        raise ParameterError(f"The tube radius r ({r}) must be smaller than R ({R}).")
    nu = _int_param(n_major, "n_major", 3)
    nv = _int_param(n_minor, "n_minor", 3)
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.column_stack(
        [
            ((R + r * np.cos(W)) * np.cos(U)).ravel(),
            ((R + r * np.cos(W)) * np.sin(U)).ravel(),
            (r * np.sin(W)).ravel(),
        ]
    )
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return V, F


def grid(nx: int = 10, ny: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Flat triangulated unit square ``[0, 1]^2`` at ``z = 0`` with normals ``+z`` (has boundary).

    Parameters
    ----------
    nx, ny : int
        Number of squares along x and y (each split into two triangles).

    Returns
    -------
    V : ((nx + 1) * (ny + 1), 3) float64
        Vertex ``i * (ny + 1) + j`` is at ``(i / nx, j / ny, 0)``.
    F : (2 * nx * ny, 3) int64
    """
    nx = _int_param(nx, "nx", 1)
    ny = _int_param(ny, "ny", 1)
    x, y = np.meshgrid(np.arange(nx + 1) / nx, np.arange(ny + 1) / ny, indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a = i * (ny + 1) + j
    b = (i + 1) * (ny + 1) + j
    c = (i + 1) * (ny + 1) + j + 1
    d = i * (ny + 1) + j + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return V, F


# --------------------------------------------------------------------------------------------
# organic samples: marching cubes of implicit fields
# --------------------------------------------------------------------------------------------


def _smooth_min(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def _field_blob(P: np.ndarray) -> np.ndarray:
    """Blob: spheres blended with a smooth minimum (like metaballs); negative inside."""
    centers = np.array(
        [[0.0, 0.0, 0.0], [0.05, 0.62, 0.08], [0.52, 0.12, 0.05], [-0.5, 0.18, -0.05],
         [-0.12, -0.5, -0.25], [0.25, -0.3, 0.35]]
    )  # fmt: skip
    radii = np.array([0.46, 0.30, 0.22, 0.24, 0.26, 0.2])
    d = None
    for c, r in zip(centers, radii, strict=True):
        sphere = np.linalg.norm(P - c, axis=-1) - r
        d = sphere if d is None else _smooth_min(d, sphere, 0.18)
    return d


def _field_bumpy(P: np.ndarray) -> np.ndarray:
    """Sphere with big smooth lobes and small bumps all over (what the default Smooth removes):
    negative inside."""
    r = np.linalg.norm(P, axis=-1)
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    bumps = 0.11 * np.sin(6 * x) * np.sin(6 * y) * np.sin(6 * z) + 0.04 * np.cos(5 * (x + y - z))
    small = 0.025 * np.sin(21 * x + 1) * np.sin(21 * y + 2) * np.sin(21 * z + 3)
    return r - (0.78 + bumps + small)


def _field_pretzel(P: np.ndarray) -> np.ndarray:
    """Two tori blended side by side (genus 2): negative inside."""
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    R, r = 0.45, 0.17

    def torus_sdf(cx: float) -> np.ndarray:
        q = np.sqrt((x - cx) ** 2 + y**2) - R
        return np.sqrt(q**2 + z**2) - r

    return _smooth_min(torus_sdf(-0.42), torus_sdf(0.42), 0.12)


_FIELDS = {"blob": _field_blob, "bumpy": _field_bumpy, "pretzel": _field_pretzel}
_BOUNDS = {"blob": 1.3, "bumpy": 1.1, "pretzel": 1.2}
_RESOLUTION = {"blob": 56, "bumpy": 48, "pretzel": 58}


def _relax_on_surface(V: np.ndarray, F: np.ndarray, field, iterations: int = 8) -> np.ndarray:
    """Tangential Laplacian smoothing projected back onto the zero level set (better triangles)."""
    from .operators import vertex_normals
    from .topology import vertex_adjacency

    A = vertex_adjacency(F, V.shape[0])
    deg = np.asarray(A.sum(axis=1)).ravel()
    h = 1e-5
    for _ in range(iterations):
        N = vertex_normals(V, F)
        avg = (A @ V) / deg[:, None]
        delta = avg - V
        delta -= np.einsum("ij,ij->i", delta, N)[:, None] * N
        V = V + 0.5 * delta
        for _ in range(2):  # Newton steps back to f = 0
            f = field(V)
            g = np.stack(
                [(field(V + h * e) - field(V - h * e)) / (2 * h) for e in np.eye(3)], axis=1
            )
            V = V - (f / np.maximum(np.sum(g * g, axis=1), 1e-12))[:, None] * g
    return V


def organic_sample(name: str = "blob") -> tuple[np.ndarray, np.ndarray]:
    """Smooth organic test shapes made by the project (marching cubes of implicit fields).

    Parameters
    ----------
    name : {'blob', 'bumpy', 'pretzel'}
        ``'blob'``: smooth union of five metaballs (genus 0). ``'bumpy'``: a sphere with
        sinusoidal bumps (genus 0). ``'pretzel'``: two tori blended together (genus 2).

    Returns
    -------
    V : (n, 3) float64
        Normalized to the unit box (centred, longest side 1); a few thousand vertices.
    F : (m, 3) int64
        Closed, manifold, outward-oriented triangles.

    Notes
    -----
    After marching cubes (``skimage.measure.marching_cubes``) the mesh is cleaned with
    :func:`algorithms.mesh.validate.clean_mesh`, relaxed tangentially (vertices slide along the
    surface and are projected back onto the implicit surface, which evens out the slivers that
    marching cubes produces) and normalized with
    :func:`algorithms.mesh.operators.normalize_unit_box`.
    """
    key = str(name).strip().lower()
    if key not in _FIELDS:
        raise ParameterError(
            f"Unknown sample {name!r}. Choose one of: {', '.join(ORGANIC_SAMPLES)}."
        )
    from skimage.measure import marching_cubes

    from .operators import normalize_unit_box, signed_volume
    from .validate import clean_mesh

    field = _FIELDS[key]
    b = _BOUNDS[key]
    res = _RESOLUTION[key]
    ax = np.linspace(-b, b, res)
    X, Y, Z = np.meshgrid(ax, ax, ax, indexing="ij")
    vol = field(np.stack([X, Y, Z], axis=-1))
    spacing = (ax[1] - ax[0],) * 3
    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=spacing)
    V = verts - b
    F = faces.astype(np.int64)
    cleaned = clean_mesh(V, F)
    V, F = cleaned.V, cleaned.F
    V = _relax_on_surface(V, F, field)
    if signed_volume(V, F) < 0:
        F = F[:, [0, 2, 1]]
    V, _, _ = normalize_unit_box(V)
    return V, np.ascontiguousarray(F, dtype=np.int64)
