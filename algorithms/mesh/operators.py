"""Geometric operators on triangle meshes: areas, normals, Laplacian, mass, normalization.

Shapes: ``V`` is ``(n, 3) float64``, ``F`` is ``(m, 3) int64``.

.. important:: **Sign convention of the cotangent Laplacian.**
   :func:`cotangent_laplacian` returns libigl's ``cotmatrix`` **unchanged**: it is **negative
   semi-definite** (off-diagonal ``L[i, j] = (cot a_ij + cot b_ij) / 2 >= 0`` for Delaunay
   meshes, diagonal ``L[i, i] = -sum_j L[i, j] <= 0``), so it matches every libigl and
   gptoolbox formula it is compared with, and ``M^-1 L`` approximates the (negative definite)
   Laplace-Beltrami operator. :func:`cotangent_laplacian_psd` returns ``-L``, the positive
   semi-definite version that energy minimizations (``x^T L x >= 0``) and solvers want.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMeshError, ParameterError

__all__ = [
    "face_areas",
    "face_normals",
    "vertex_normals",
    "barycentric_vertex_areas",
    "cotangent_laplacian",
    "cotangent_laplacian_psd",
    "mass_matrix",
    "signed_volume",
    "bounding_box_diagonal",
    "normalize_unit_box",
    "denormalize",
]


def _check(V, F) -> tuple[np.ndarray, np.ndarray]:
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise InvalidMeshError(f"Vertex positions must be an (n, 3) array, got shape {V.shape}.")
    if F.ndim != 2 or F.shape[1] != 3:
        raise InvalidMeshError(f"Faces must be an (m, 3) array of triangles, got shape {F.shape}.")
    F = F.astype(np.int64, copy=False)
    if F.size and (F.min() < 0 or F.max() >= V.shape[0]):
        raise InvalidMeshError(
            "Some faces refer to vertices that do not exist. Validate the mesh to see which."
        )
    return np.ascontiguousarray(V), np.ascontiguousarray(F)


def _cross(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unnormalized face normals (twice the area vector), (m, 3)."""
    a = V[F[:, 0]]
    return np.cross(V[F[:, 1]] - a, V[F[:, 2]] - a)


def face_areas(V, F) -> np.ndarray:
    """Triangle areas.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    (m,) float64 array
        Area of each triangle (``>= 0``).
    """
    V, F = _check(V, F)
    return 0.5 * np.linalg.norm(_cross(V, F), axis=1)


def face_normals(V, F) -> np.ndarray:
    """Unit face normals (right-hand rule on the corner order).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    (m, 3) float64 array
        Unit normals; degenerate (zero-area) faces get ``(0, 0, 0)``.
    """
    V, F = _check(V, F)
    N = _cross(V, F)
    ln = np.linalg.norm(N, axis=1)
    ok = ln > 0
    out = np.zeros_like(N)
    out[ok] = N[ok] / ln[ok, None]
    return out


def vertex_normals(V, F) -> np.ndarray:
    """Area-weighted unit vertex normals.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    (n, 3) float64 array
        For each vertex, the normalized sum of the area-weighted normals of its faces (same as
        ``igl.per_vertex_normals`` with area weighting). Unreferenced vertices, or vertices whose
        face normals cancel, get ``(0, 0, 0)``.
    """
    V, F = _check(V, F)
    N = _cross(V, F)  # length = 2 * area, so this is area weighting
    n = V.shape[0]
    out = np.column_stack(
        [np.bincount(F.ravel(), weights=np.repeat(N[:, k], 3), minlength=n) for k in range(3)]
    )
    ln = np.linalg.norm(out, axis=1)
    ok = ln > 0
    out[ok] /= ln[ok, None]
    out[~ok] = 0.0
    return out


def barycentric_vertex_areas(V, F) -> np.ndarray:
    """One third of the total area of the faces around each vertex.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    (n,) float64 array
        The diagonal of the barycentric mass matrix; sums to the total surface area.
    """
    A = face_areas(V, F)
    F = np.asarray(F, dtype=np.int64)
    return np.bincount(F.ravel(), weights=np.repeat(A / 3.0, 3), minlength=np.asarray(V).shape[0])


def cotangent_laplacian(V, F) -> sp.csr_matrix:
    """Cotangent Laplacian, **negative semi-definite** (libigl's ``cotmatrix`` unchanged).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix of float64
        Symmetric; ``L[i, j] = (cot alpha_ij + cot beta_ij) / 2`` for each edge ``ij`` (the
        angles opposite the edge), ``L[i, i] = -sum_{j != i} L[i, j]``. Rows sum to zero and
        ``x^T L x <= 0``. Use :func:`cotangent_laplacian_psd` for ``-L``.
    """
    V, F = _check(V, F)
    import igl  # local import keeps `import algorithms.mesh` light

    return _square(igl.cotmatrix(V, F), len(V))


def cotangent_laplacian_psd(V, F) -> sp.csr_matrix:
    """Positive semi-definite cotangent Laplacian, ``-cotangent_laplacian(V, F)``.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    (n, n) scipy.sparse.csr_matrix of float64
        Symmetric, ``x^T L x >= 0``, positive diagonal.
    """
    return -cotangent_laplacian(V, F)


def mass_matrix(V, F, kind: str = "barycentric") -> sp.csr_matrix:
    """Lumped (diagonal) mass matrix.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    kind : {'barycentric', 'voronoi'}
        ``'barycentric'``: one third of the incident face areas. ``'voronoi'``: mixed Voronoi
        areas (Meyer et al. 2003), as ``igl.massmatrix`` computes them.

    Returns
    -------
    M : (n, n) scipy.sparse.csr_matrix of float64
        Diagonal; its entries sum to the total surface area.
    """
    V, F = _check(V, F)
    import igl

    kinds = {
        "barycentric": igl.MASSMATRIX_TYPE_BARYCENTRIC,
        "voronoi": igl.MASSMATRIX_TYPE_VORONOI,
    }
    if kind not in kinds:
        raise ParameterError(
            f"Unknown mass matrix kind {kind!r}; use 'barycentric' or 'voronoi'."
        )
    return _square(igl.massmatrix(V, F, kinds[kind]), len(V))


def _square(A, n: int) -> sp.csr_matrix:
    """libigl sizes some operators by the largest index used in F: pad to (n, n) so vertices that
    no triangle uses (trailing loose points) get empty rows and columns."""
    A = sp.csr_matrix(A)
    if A.shape != (n, n):
        A = sp.csr_matrix((A.data, A.indices, A.indptr), shape=A.shape)
        A.resize((n, n))
    return A


def signed_volume(V, F) -> float:
    """Signed volume enclosed by a closed mesh (positive when the normals point outwards).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    float
        ``sum over faces of det(v0, v1, v2) / 6``. Only meaningful for closed meshes.
    """
    V, F = _check(V, F)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def bounding_box_diagonal(V) -> float:
    """Length of the diagonal of the axis-aligned bounding box of the finite points ``V (n, 3)``."""
    V = np.asarray(V, dtype=np.float64)
    V = V[np.isfinite(V).all(axis=1)] if V.size else V
    if V.shape[0] == 0:
        return 0.0
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def normalize_unit_box(V) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre the bounding box at the origin and scale its longest side to 1.

    Parameters
    ----------
    V : (n, 3) float array
        Finite vertex positions.

    Returns
    -------
    V_unit : (n, 3) float64 array
        ``(V - center) / scale``; fits in ``[-0.5, 0.5]^3`` with the longest side exactly 1.
    center : (3,) float64 array
        Centre of the original bounding box.
    scale : float
        Length of the longest side of the original bounding box (1.0 if it is 0, e.g. one point).

    See Also
    --------
    denormalize : the inverse, ``V_unit * scale + center``.
    """
    V = np.asarray(V, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] == 0:
        raise InvalidMeshError(f"Vertex positions must be a non-empty (n, 3) array, got {V.shape}.")
    if not np.isfinite(V).all():
        raise InvalidMeshError(
            "Some vertices have NaN or infinite coordinates; the mesh cannot be normalized. "
            "Validate and clean the mesh first."
        )
    lo, hi = V.min(axis=0), V.max(axis=0)
    center = (lo + hi) / 2.0
    scale = float((hi - lo).max())
    if scale <= 0.0:
        scale = 1.0
    return (V - center) / scale, center, scale


def denormalize(V_unit, center, scale: float) -> np.ndarray:
    """Undo :func:`normalize_unit_box`: return ``V_unit * scale + center`` as ``(n, 3) float64``."""
    return np.asarray(V_unit, dtype=np.float64) * float(scale) + np.asarray(center, np.float64)


def gaussian_curvature(V, F) -> np.ndarray:
    """Discrete Gaussian curvature: angle defect 2π − Σ(corner angles) divided by the Voronoi
    area (boundary vertices are not corrected).

    Returns
    -------
    (n,) float64 array; on a closed surface Σ K_i A_i = 2π χ (Gauss-Bonnet).
    """
    V, F = _check(V, F)
    ang = np.zeros(F.shape)
    for k in range(3):
        a = V[F[:, (k + 1) % 3]] - V[F[:, k]]
        b = V[F[:, (k + 2) % 3]] - V[F[:, k]]
        cos = (a * b).sum(1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1),
                                          1e-300)
        ang[:, k] = np.arccos(np.clip(cos, -1.0, 1.0))
    total = np.bincount(F.ravel(), weights=ang.ravel(), minlength=len(V))
    area = mass_matrix(V, F, "voronoi").diagonal()
    return (2 * np.pi - total) / np.maximum(area, 1e-300)
