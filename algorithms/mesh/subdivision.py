"""Subdivision of triangle meshes (libigl): Loop and mid-point.

Both split every triangle into four per level: a mesh with ``n`` vertices, ``e`` edges and ``m``
faces becomes one with ``n + e`` vertices and ``4 m`` faces. The input must be edge-manifold
(every edge touches one or two faces); libigl's routines assume it and may misbehave otherwise,
so this is checked first and reported as :class:`~algorithms.errors.InvalidMeshError`.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from .topology import _EdgeData

__all__ = ["loop_subdivide", "midpoint_subdivide"]

#: Refuse to produce more faces than this (memory guard: 4**levels growth).
MAX_FACES = 20_000_000


def _prepare(V, F, levels, what: str) -> tuple[np.ndarray, np.ndarray, int]:
    try:
        lv = int(levels)
        if lv != levels:
            raise ValueError
    except (TypeError, ValueError):
        raise ParameterError(
            f"The number of {what} levels must be a whole number, not {levels!r}."
        ) from None
    if lv < 0:
        raise ParameterError(f"The number of {what} levels must be 0 or more, got {lv}.")
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InvalidMeshError(
            f"{what.capitalize()} needs V of shape (n, 3) and F of shape (m, 3); "
            f"got {V.shape} and {F.shape}."
        )
    if F.shape[0] == 0:
        raise InvalidMeshError(f"The mesh has no faces, so there is nothing to {what}.")
    if F.min() < 0 or F.max() >= V.shape[0]:
        raise InvalidMeshError(
            "Some faces refer to vertices that do not exist. Validate and clean the mesh first."
        )
    if not np.isfinite(V).all():
        raise InvalidMeshError(
            "Some vertices have NaN or infinite coordinates. Validate and clean the mesh first."
        )
    if ((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])).any():
        raise InvalidMeshError(
            "Some triangles use the same vertex twice. 'Clean' can remove them."
        )
    d = _EdgeData(F)
    if d.counts.max() > 2:
        raise InvalidMeshError(
            f"{int((d.counts > 2).sum())} edges are shared by more than two triangles "
            "(non-manifold), so the mesh cannot be subdivided. 'Clean' can remove the extra "
            "triangles."
        )
    if F.shape[0] * 4**lv > MAX_FACES:
        raise ParameterError(
            f"{lv} levels would create {F.shape[0] * 4**lv:,} triangles, more than the limit of "
            f"{MAX_FACES:,}. Use fewer levels."
        )
    return V, F, lv


def loop_subdivide(V, F, levels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Loop subdivision (smooth; vertices move), via ``igl.loop``.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
        Edge-manifold triangles.
    levels : int
        Number of subdivision steps (0 returns copies).

    Returns
    -------
    V_sub : (n_k, 3) float64 array
        The original vertices come first (moved by the Loop rules), then one new vertex per edge,
        per level. One level gives ``n + e`` vertices.
    F_sub : (m * 4**levels, 3) int64 array
    """
    V, F, lv = _prepare(V, F, levels, "subdivision")
    if lv == 0:
        return V.copy(), F.copy()
    import igl

    NV, NF = igl.loop(V, F, lv)
    return np.ascontiguousarray(NV, dtype=np.float64), np.ascontiguousarray(NF, dtype=np.int64)


def midpoint_subdivide(V, F, levels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Mid-point (linear) subdivision: the shape does not change, via ``igl.upsample``.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
        Edge-manifold triangles.
    levels : int
        Number of subdivision steps (0 returns copies).

    Returns
    -------
    V_sub : (n_k, 3) float64 array
        ``V`` unchanged, followed by the edge mid-points, per level (``n + e`` after one level).
    F_sub : (m * 4**levels, 3) int64 array
    """
    V, F, lv = _prepare(V, F, levels, "subdivision")
    if lv == 0:
        return V.copy(), F.copy()
    import igl

    NV, NF = igl.upsample(V, F, lv)
    return np.ascontiguousarray(NV, dtype=np.float64), np.ascontiguousarray(NF, dtype=np.int64)
