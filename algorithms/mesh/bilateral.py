"""Bilateral normal filtering for mesh denoising (Zheng, Fu, Au, Tai 2011, *Bilateral normal
filtering for mesh denoising*, IEEE TVCG 17(10)): the local iterative scheme.

A non-image peer of Paparazzi's guided filter (issue 23): it smooths a noisy surface while
keeping sharp creases, working on the mesh directly instead of on pictures of it.

1. **Normal filtering** (``normal_iterations`` times): each face normal becomes the normalized
   sum over its neighbours ``j`` (the faces sharing a vertex with it, itself included) of
   ``A_j W_s(|c_i - c_j|) W_r(|n_i - n_j|) n_j``: area ``A``, centroid ``c``, Gaussian weights
   ``W(x) = exp(-x^2 / (2 sigma^2))``. ``sigma_s`` defaults to the mean distance between the
   centroids of edge-adjacent faces (the paper's choice); ``sigma_r`` (the normal range,
   default 0.35, in the paper's 0.2-0.6) decides which normal differences count as an edge.
2. **Vertex update** (``vertex_iterations`` times, the paper's least-squares fit of the
   vertices to the filtered normals by gradient descent): ``x_i += 1/|F_i| sum_{f in F_i}
   n_f (n_f . (c_f - x_i))``, centroids recomputed each time. The filtered normals stay fixed.

Choices: boundary vertices stay where they are (as in Paparazzi); faces of zero area keep their
normal out of the sums (weight 0). ``bilateral_normal_filter_iter`` yields one :class:`Step`
per normal-filtering pass (``V`` unchanged; ``normal_change``: mean angle in degrees the normals
turned) and one per vertex update (``displacement``: mean vertex move of that update).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from ..params import param, validate_params
from ..steps import Step, run_to_end
from .operators import face_areas, face_normals
from .topology import boundary_edges, edge_flaps, vertex_face_adjacency

__all__ = ["BilateralNormalParams", "bilateral_normal_filter_iter", "bilateral_normal_filter",
           "filter_face_normals"]


@dataclass(frozen=True)
class BilateralNormalParams:
    sigma_r: float = param(0.35, label="Normal range σr", minimum=0.01, maximum=2.0,
                           decimals=3, tooltip="Normal differences (|n_i - n_j|) much larger "
                                               "than this count as a sharp edge and are kept.")
    sigma_s: float = param(0.0, label="Spatial σs", minimum=0.0, maximum=10.0, decimals=5,
                           tooltip="Spatial Gaussian width; 0 = the mean distance between the "
                                   "centroids of adjacent faces.")
    normal_iterations: int = param(20, label="Normal iterations", minimum=0, maximum=1000,
                                   tooltip="Bilateral filtering passes over the face normals.")
    vertex_iterations: int = param(10, label="Vertex iterations", minimum=0, maximum=1000,
                                   tooltip="Vertex updates fitting the surface to the filtered "
                                           "normals.")


def _face_neighbours(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(i, j)``: every ordered pair of faces sharing at least one vertex (``i == j``
    included)."""
    VF = vertex_face_adjacency(F)
    A = (VF.T @ VF).tocoo()
    return A.row.astype(np.int64), A.col.astype(np.int64)


def _default_sigma_s(V, F) -> float:
    _, _, EF, _ = edge_flaps(F)
    inner = (EF >= 0).all(axis=1)
    C = V[F].mean(1)
    d = np.linalg.norm(C[EF[inner, 0]] - C[EF[inner, 1]], axis=1)
    return float(d.mean()) if len(d) else 1.0


def _spatial_weights(V, F, pairs, sigma_s: float) -> np.ndarray:
    """``A_j W_s(|c_i - c_j|)`` of every face pair: what a normal pass does not change."""
    i, j = pairs
    C = V[F].mean(1)
    ds = ((C[i] - C[j]) ** 2).sum(1)
    return face_areas(V, F)[j] * np.exp(-ds / (2 * sigma_s ** 2))


def filter_face_normals(V, F, N, sigma_s: float, sigma_r: float, pairs=None,
                        spatial=None) -> np.ndarray:
    """One bilateral pass over the face normals ``N (m, 3)`` of ``(V, F)`` (step 1 of the
    module docstring); returns the new unit normals. ``pairs`` / ``spatial``: the face pairs
    and their spatial weights when the caller has them (the positions do not change between
    normal passes)."""
    V = np.asarray(V, float)
    F = np.asarray(F, np.int64)
    i, j = _face_neighbours(F) if pairs is None else pairs
    if spatial is None:
        spatial = _spatial_weights(V, F, (i, j), sigma_s)
    dr = ((N[i] - N[j]) ** 2).sum(1)
    w = spatial * np.exp(-dr / (2 * sigma_r ** 2))
    W = sp.csr_matrix((w, (i, j)), shape=(len(F), len(F)))
    out = np.asarray(W @ N)
    ln = np.linalg.norm(out, axis=1)
    ok = ln > 1e-300
    out[ok] /= ln[ok, None]
    out[~ok] = N[~ok]
    return out


def bilateral_normal_filter_iter(V, F, params: BilateralNormalParams | None = None
                                 ) -> Iterator[Step]:
    """The house generator form (module docstring)."""
    p = validate_params(params or BilateralNormalParams())
    V = np.array(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    sigma_s = p.sigma_s or _default_sigma_s(V, F)
    pairs = _face_neighbours(F)
    spatial = _spatial_weights(V, F, pairs, sigma_s)  # V is fixed while the normals filter
    N = face_normals(V, F)
    total = p.normal_iterations + p.vertex_iterations
    for k in range(1, p.normal_iterations + 1):
        N1 = filter_face_normals(V, F, N, sigma_s, p.sigma_r, pairs, spatial)
        turn = float(np.degrees(np.arccos(np.clip((N1 * N).sum(1), -1, 1))).mean())
        N = N1
        yield Step(k, total, V.copy(), {"normal_change": turn}, "filtering normals")
    VF = vertex_face_adjacency(F, len(V))
    count = np.asarray(VF.sum(axis=1)).ravel()
    free = count > 0
    b = boundary_edges(F)
    if len(b):
        free[np.unique(b.ravel())] = False
    for k in range(1, p.vertex_iterations + 1):
        C = V[F].mean(1)
        # per face: n_f (n_f . (c_f - x_i)) for each of its three corners i
        d = np.zeros_like(V)
        for c in range(3):
            proj = ((C - V[F[:, c]]) * N).sum(1, keepdims=True) * N
            np.add.at(d, F[:, c], proj)
        move = np.zeros_like(V)
        move[free] = d[free] / count[free, None]
        V = V + move
        yield Step(p.normal_iterations + k, total, V.copy(),
                   {"displacement": float(np.linalg.norm(move[free], axis=1).mean())
                    if free.any() else 0.0}, "updating vertices")


def bilateral_normal_filter(V, F, params: BilateralNormalParams | None = None) -> np.ndarray:
    """Run :func:`bilateral_normal_filter_iter` to the end; returns the new ``V``."""
    p = validate_params(params or BilateralNormalParams())
    if p.normal_iterations + p.vertex_iterations == 0:
        return np.array(V, dtype=np.float64)
    return run_to_end(bilateral_normal_filter_iter(V, F, p)).V
