"""Operators (PSD L, diagonal M) to coarsen: cotangent, intrinsic Delaunay, anisotropic
(Andreux et al. 2014), graph and point-cloud Laplacians. All return ``(L, M)`` with ``L``
symmetric positive semi-definite (the negative of libigl's sign convention)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import ParameterError
from ..mesh.operators import cotangent_laplacian_psd, mass_matrix

__all__ = ["OPERATORS", "build_operator", "cotangent_operator", "intrinsic_delaunay_operator",
           "anisotropic_operator", "tensor_laplacian", "graph_operator", "point_cloud_operator"]

OPERATORS = ("cotangent", "intrinsic_delaunay", "anisotropic", "graph", "point_cloud")


def _VF(V, F):
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    return V, F


def cotangent_operator(V, F):
    V, F = _VF(V, F)
    return cotangent_laplacian_psd(V, F), sp.csr_matrix(mass_matrix(V, F))


#: a triangle whose two shorter edges add up to less than (1 + this) times its longest edge has
#: its corners on a line: libigl's intrinsic edge flipping did not finish on such triangles (every
#: smoothed corpus mesh it failed on had 2 or more; a brain cortex whose closest triangle has
#: 1.3e-12 built in 0.4 s)
COLLAPSED_SLACK = 1e-12


def collapsed_triangles(V, F) -> np.ndarray:
    """Mask of the triangles whose three corners lie on a line (or coincide), measured on the
    edge lengths: ``(l_a + l_b - l_c) / l_c < COLLAPSED_SLACK`` for the longest edge ``l_c``."""
    V, F = _VF(V, F)
    ell = np.stack([np.linalg.norm(V[F[:, (k + 1) % 3]] - V[F[:, (k + 2) % 3]], axis=1)
                    for k in range(3)], axis=1)
    ell.sort(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        slack = (ell[:, 0] + ell[:, 1] - ell[:, 2]) / ell[:, 2]
    return ~(slack >= COLLAPSED_SLACK)   # NaN (a zero-length triangle) counts as collapsed


def intrinsic_delaunay_operator(V, F):
    """Cotangent Laplacian of the intrinsic Delaunay triangulation (libigl's edge flipping).

    Refused (InvalidMeshError) on a mesh with collapsed triangles (:func:`collapsed_triangles`):
    there libigl's flipping ran for minutes or past 4 GB of memory (measured on 7 smoothed
    corpus meshes with 2 to 75,670 such triangles, e.g. 2 on a Greek helmet); the cotangent
    operator works on them."""
    import igl

    from ..errors import InvalidMeshError
    V, F = _VF(V, F)
    bad = int(collapsed_triangles(V, F).sum())
    if bad:
        raise InvalidMeshError(
            f"{bad:,} triangle{'s' if bad > 1 else ''} of this mesh {'are' if bad > 1 else 'is'} "
            f"collapsed (the three corners lie on a line), and the intrinsic Delaunay operator "
            f"cannot be built on {'them' if bad > 1 else 'it'}. Use the cotangent operator, or "
            f"remove the collapsed triangles first.")
    L = igl.intrinsic_delaunay_cotmatrix(V, F)[0]
    return sp.csr_matrix(-L), sp.csr_matrix(mass_matrix(V, F))


def tensor_laplacian(V, F, slow_dirs, alpha: float):
    """Per-face tensor Laplacian L = Grad^T A D Grad with D = e1 e1^T / (1 + alpha) + e2 e2^T.

    ``slow_dirs`` (#F x 3) gives e1 per face (projected into the face plane and normalized);
    diffusion along it is ``1 + alpha`` times slower. alpha = 0 is the cotangent Laplacian.
    """
    import igl
    V, F = _VF(V, F)
    nf = len(F)
    Gr = igl.grad(V, F)                            # (3 nf, n), rows [x-block; y-block; z-block]
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area = 0.5 * np.linalg.norm(N, axis=1)
    N = N / np.maximum(2 * area, 1e-300)[:, None]
    e1 = np.asarray(slow_dirs, float)
    e1 = e1 - np.sum(e1 * N, axis=1)[:, None] * N
    nrm = np.linalg.norm(e1, axis=1)
    bad = nrm < 1e-12
    if bad.any():  # no direction: any in-plane one (the tensor is then isotropic-ish there)
        e1[bad] = V[F[bad, 1]] - V[F[bad, 0]]
        nrm[bad] = np.linalg.norm(e1[bad], axis=1)
    e1 /= np.maximum(nrm, 1e-300)[:, None]
    e2 = np.cross(N, e1)
    D = (e1[:, :, None] * e1[:, None, :]) / (1.0 + alpha) + e2[:, :, None] * e2[:, None, :]
    D *= area[:, None, None]
    f = np.arange(nf)
    rows = np.concatenate([a * nf + f for a in range(3) for b in range(3)])
    cols = np.concatenate([b * nf + f for a in range(3) for b in range(3)])
    vals = np.concatenate([D[:, a, b] for a in range(3) for b in range(3)])
    T = sp.csr_matrix((vals, (rows, cols)), shape=(3 * nf, 3 * nf))
    L = (Gr.T @ T @ Gr).tocsr()
    L = 0.5 * (L + L.T)
    L = L - sp.diags(np.asarray(L.sum(axis=1)).ravel())   # exact zero row sums
    return sp.csr_matrix(L), sp.csr_matrix(mass_matrix(V, F))


def anisotropic_operator(V, F, alpha: float = 10.0):
    """Anisotropic Laplacian of Andreux et al. 2014: diffusion along the maximum principal
    curvature direction slowed by 1 / (1 + alpha) (igl.principal_curvature directions)."""
    import igl
    V, F = _VF(V, F)
    if alpha < 0:
        raise ParameterError("the anisotropy alpha must be zero or positive.")
    PD1 = igl.principal_curvature(V, F)[0]          # maximal curvature direction per vertex
    # average the (sign-ambiguous) line field per face: align to the first corner
    d0 = PD1[F[:, 0]]
    acc = d0.copy()
    for c in (1, 2):
        d = PD1[F[:, c]]
        s = np.sign(np.sum(d * d0, axis=1))
        s[s == 0] = 1
        acc += s[:, None] * d
    return tensor_laplacian(V, F, acc, alpha)


def graph_operator(V, F):
    """Combinatorial graph Laplacian of the edge graph, identity mass."""
    import igl
    V, F = _VF(V, F)
    A = igl.adjacency_matrix(F).astype(float)
    A = sp.csr_matrix(A)
    A.data[:] = 1.0
    n = len(V)
    if A.shape[0] < n:
        A.resize((n, n))
    L = sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A
    return sp.csr_matrix(L), sp.identity(n, format="csr")


def point_cloud_operator(V, F=None, *, n_neighbors: int = 30):
    """Point-cloud Laplacian of Sharp & Crane 2020 (``robust_laplacian``, pinned 1.1.0).

    ``robust_laplacian.point_cloud_laplacian(P)`` builds the intrinsic Delaunay "tufted cover"
    of local triangulations of the ``n_neighbors`` nearest neighbours and returns ``(L, M)``
    with ``L`` already in our convention (symmetric positive semi-definite: positive diagonal,
    non-positive weights on most off-diagonals, zero row sums) and ``M`` a lumped diagonal
    mass. ``F`` is ignored: only the points are used.
    """
    try:
        import robust_laplacian  # type: ignore
    except ImportError as exc:
        raise ParameterError("the point-cloud Laplacian needs the optional package "
                             "'robust_laplacian', which is not installed; choose another "
                             "operator.") from exc
    P = np.ascontiguousarray(V, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 4:
        raise ParameterError(f"the point-cloud Laplacian needs at least 4 points in 3D; got an "
                             f"array of shape {P.shape}.")
    if not np.all(np.isfinite(P)):
        raise ParameterError("the point cloud has non-finite coordinates; remove those points.")
    L, M = robust_laplacian.point_cloud_laplacian(P, n_neighbors=int(min(n_neighbors,
                                                                          len(P) - 1)))
    L = sp.csr_matrix(L, dtype=np.float64)
    if L.diagonal().sum() < 0:   # guard against a sign change in a future release
        L = -L
    L = 0.5 * (L + L.T)
    mass = np.asarray(M.diagonal() if sp.issparse(M) else M, dtype=np.float64).ravel()
    return sp.csr_matrix(L), sp.diags(mass).tocsr()


def build_operator(V, F, name: str = "cotangent", *, alpha: float = 10.0):
    """(L, M, p, q) for an operator name in :data:`OPERATORS` (p, q: units for the distance)."""
    if name == "cotangent":
        return (*cotangent_operator(V, F), 0.0, 2.0)
    if name == "intrinsic_delaunay":
        return (*intrinsic_delaunay_operator(V, F), 0.0, 2.0)
    if name == "anisotropic":
        return (*anisotropic_operator(V, F, alpha), 0.0, 2.0)
    if name == "graph":
        return (*graph_operator(V, F), 0.0, 2.0)
    if name == "point_cloud":
        return (*point_cloud_operator(V, F), 0.0, 2.0)
    raise ParameterError(f"unknown operator '{name}'; choose one of {', '.join(OPERATORS)}.")
