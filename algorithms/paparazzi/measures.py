"""Shape measures that say whether a filter did what it should (issue 12's acceptance).

* :func:`palette_fraction` -- area fraction of faces whose normal is within ``degrees`` of one of
  the 20 icosahedron face normals (quantization).
* :func:`planar_area_fraction` -- area fraction of faces whose dihedral angles with all their
  edge neighbours are below ``degrees`` (L0, SLIC: piecewise-planar shapes).
* :func:`flat_edge_fraction` -- share of the interior edge length along which the two faces meet
  at less than ``degrees`` (default 1). A second look at the same effect, one edge at a time:
  a face counts in :func:`planar_area_fraction` only if none of its three edges is a crease, so
  flat patches only a few triangles wide (SLIC's superpixels covered about 3 triangles of a
  13k-vertex spot with the former 0.3-wide views, about 38 at today's 1.0) add little there
  even when most of their edges are flat.
* :func:`crease_fraction` -- share of the length of the input's sharp edges (dihedral angle
  above ``sharp`` degrees, default 30) along which the output still has the input's angle within
  ``degrees`` (default 5): at three points of each sharp edge, points a quarter of the mean edge
  length inside each of its two faces are projected onto the output, and the angle between the
  output's normals there is compared with the input's dihedral angle. The output may have other
  triangles (Paparazzi remeshes), so it is measured on the surface, not per edge; a crease
  rounded over one ring of triangles puts both points on the rounding and fails.
* :func:`noisy_scan` -- a mesh with Gaussian noise along its vertex normals (issue 23's noisy
  scans: 0.3 mean edge lengths, a fixed seed), to test smoothing filters on.
* :func:`surface_distance` -- mean distance of one mesh's vertices to another mesh's surface
  (how far a result moved from its input, or how close it came back to a clean shape; works
  across remeshing).
* :func:`bending_energy` -- ``sum_i |(L V)_i|^2 / M_ii`` over the interior vertices (squared
  mean-curvature normal, cotangent Laplacian and barycentric mass of
  :mod:`algorithms.mesh.operators`; a discrete Willmore energy, invariant to scale; guided-filter
  smoothing lowers it). Boundary vertices are left out: there ``(L V)_i`` is not a curvature of
  the surface but mostly the turning of the boundary curve, which Paparazzi keeps fixed.
"""

from __future__ import annotations

import numpy as np

from ..mesh.operators import cotangent_laplacian_psd, face_areas, face_normals, mass_matrix
from ..mesh.topology import edge_flaps
from .filters import icosahedron_face_normals

__all__ = ["palette_fraction", "planar_area_fraction", "flat_edge_fraction",
           "crease_fraction", "bending_energy", "noisy_scan", "surface_distance"]


def palette_fraction(V, F, degrees: float = 15.0, palette=None) -> float:
    P = icosahedron_face_normals() if palette is None else np.asarray(palette, float)
    N = face_normals(V, F)
    A = face_areas(V, F)
    close = (N @ P.T).max(axis=1) >= np.cos(np.radians(degrees))
    return float(A[close].sum() / A.sum())


def _dihedral_angles(V, F):
    """``(E_inner (k, 2), f0 (k,), f1 (k,), angle (k,) in degrees)`` of the interior edges: the
    angle between the normals of the two faces at each edge."""
    N = face_normals(V, F)
    E, EMAP, EF, EI = edge_flaps(F)
    inner = (EF >= 0).all(axis=1)
    f0, f1 = EF[inner, 0], EF[inner, 1]
    ang = np.degrees(np.arccos(np.clip((N[f0] * N[f1]).sum(1), -1, 1)))
    return E[inner], f0, f1, ang


def planar_area_fraction(V, F, degrees: float = 3.0) -> float:
    A = face_areas(V, F)
    _, f0, f1, ang = _dihedral_angles(V, F)
    worst = np.zeros(len(F))
    np.maximum.at(worst, f0, ang)
    np.maximum.at(worst, f1, ang)
    return float(A[worst < degrees].sum() / A.sum())


def flat_edge_fraction(V, F, degrees: float = 1.0) -> float:
    V = np.asarray(V, float)
    E, _, _, ang = _dihedral_angles(V, F)
    L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    return float(L[ang < degrees].sum() / max(L.sum(), 1e-300))


def bending_energy(V, F) -> float:
    V = np.asarray(V, float)
    L = cotangent_laplacian_psd(V, F)
    M = mass_matrix(V, F).diagonal()
    LV = L @ V
    e = (LV ** 2).sum(1) / np.maximum(M, 1e-300)
    from ..mesh.topology import boundary_edges

    b = boundary_edges(F)
    if len(b):
        e[np.unique(b.ravel())] = 0.0
    return float(e.sum())


def crease_fraction(V0, F0, V1, F1, degrees: float = 5.0, sharp: float = 30.0) -> float:
    """See the module docstring; 1.0 when the input has no sharp edge."""
    import igl

    V0 = np.asarray(V0, float)
    F0 = np.asarray(F0, np.int64)
    V1 = np.ascontiguousarray(V1, float)
    F1 = np.ascontiguousarray(F1, np.int64)
    E, f0, f1, ang = _dihedral_angles(V0, F0)
    keep = ang > sharp
    if not keep.any():
        return 1.0
    E, f0, f1, ang = E[keep], f0[keep], f1[keep], ang[keep]
    L = np.linalg.norm(V0[E[:, 0]] - V0[E[:, 1]], axis=1)
    h = float(igl.edge_lengths(V0, F0).mean())
    C0 = V0[F0].mean(1)
    ok = np.zeros(len(E))
    for t in (0.2, 0.5, 0.8):
        P = (1 - t) * V0[E[:, 0]] + t * V0[E[:, 1]]
        sides = []
        for f in (f0, f1):
            d = C0[f] - P
            d -= ((d * (V0[E[:, 1]] - V0[E[:, 0]])).sum(1, keepdims=True)
                  / np.maximum(L[:, None] ** 2, 1e-300)) * (V0[E[:, 1]] - V0[E[:, 0]])
            d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
            Q = P + 0.25 * h * d
            _, I, _ = igl.point_mesh_squared_distance(Q, V1, F1)
            sides.append(face_normals(V1, F1)[np.asarray(I, np.int64)])
        out = np.degrees(np.arccos(np.clip((sides[0] * sides[1]).sum(1), -1, 1)))
        ok += (np.abs(out - ang) < degrees) / 3.0
    return float((L * ok).sum() / L.sum())


def noisy_scan(V, F, amount: float = 0.3, seed: int = 0) -> np.ndarray:
    """``V`` moved along its (area-weighted) vertex normals by Gaussian noise of standard
    deviation ``amount`` mean edge lengths, from ``numpy.random.default_rng(seed)``; ``F``
    unchanged. Boundary vertices move too."""
    import igl

    V = np.asarray(V, float)
    F = np.asarray(F, np.int64)
    from ..mesh.operators import vertex_normals

    h = float(igl.edge_lengths(V, F).mean())
    z = np.random.default_rng(seed).standard_normal(len(V))
    return V + (amount * h * z)[:, None] * vertex_normals(V, F)


def surface_distance(V, F, V_ref, F_ref) -> float:
    """Mean distance of the vertices ``V`` (``F``: only its referenced vertices count) to the
    surface ``(V_ref, F_ref)`` (:func:`algorithms.subdivision.metrics.point_surface_distances`)."""
    from ..subdivision.metrics import point_surface_distances

    V = np.asarray(V, float)
    used = np.unique(np.asarray(F, np.int64))
    return float(point_surface_distances(V[used], np.asarray(V_ref, float), F_ref).mean())
