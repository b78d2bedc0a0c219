"""The rasterizer: per pixel, the nearest face id (or -1), its depth and barycentric coordinates.

CPU only (no GL context, so it runs in CI and on headless servers). Visibility is a z-buffer
recomputed on every call (thesis 291-301: visibility is assumed fixed under infinitesimal
changes and refreshed by re-rendering every iteration).

Rules (identical in the compiled kernel, :mod:`algorithms.render.kernels`, and the NumPy code here)
-----------------------------------------------------------------------------------------------
* Vertices are mapped by :meth:`Camera.to_pixels` (pixel centres at integer coordinates).
* A pixel centre is covered by a triangle when its three screen-space barycentric coordinates are
  all ``>= 0`` (edges shared by two triangles are covered by both; the z-test decides).
* Depth: linear in screen space for orthographic cameras; for perspective cameras ``1/z`` is
  interpolated and the barycentrics are perspective-correct (``b_i ∝ w_i / z_i``), so they are the
  barycentric coordinates of the 3D point seen.
* The smallest depth ``> near`` wins; equal depths go to the lower face index.
* No back-face culling (open meshes show their back side); degenerate (zero screen area)
  triangles and triangles with a non-finite corner are skipped.

The compiled kernel goes through the project's one switch, :mod:`algorithms.compiled`. It gives
the same picture bit for bit, faster: it z-tests the faces of the nearer screen orientation first
(the front faces of a closed mesh seen from outside), then the others only where an 8 x 8 tile
they overlap is not already nearer (an exact occlusion test with a margin, not culling: open,
self-intersecting or enclosing meshes keep their visible back faces), with equal depths still
going to the lower face index (see :func:`algorithms.render.kernels.rasterize`).
"""

from __future__ import annotations

import numpy as np

from ..compiled import KernelModule
from .camera import Camera

__all__ = ["Raster", "rasterize", "compiled_kernels", "set_compiled_kernels"]

_KERNELS = KernelModule("algorithms.render.kernels")
_NO_BARY = np.empty((0, 0, 3))     # the compiled rasterizer leaves the barycentrics to Raster.bary


def compiled_kernels():
    """The compiled rasterizer module, or None (Numba missing or switched off)."""
    return _KERNELS.get()


def set_compiled_kernels(enabled: bool) -> bool:
    """Switch the compiled rasterizer on or off; returns the previous setting."""
    return _KERNELS.set(enabled)


class Raster:
    """What the rasterizer sees through one camera.

    Attributes
    ----------
    face_id : (H, W) int64, the nearest face under each pixel centre, -1 for background.
    depth : (H, W) float64 depth along the view direction (inf for background).
    bary : (H, W, 3) float64 barycentric coordinates of the seen point in its face (0 for background).
        The compiled rasterizer computes them on first access (flat shading never needs them)
        from its projected vertices and the faces it was given (do not change that ``F`` in
        place before reading them), by the same formulas as the z-test.
    camera : the camera used.
    """

    def __init__(self, face_id: np.ndarray, depth: np.ndarray, bary: np.ndarray | None,
                 camera: Camera, *, _lazy_bary=None, _candidates=None):
        self.face_id = face_id
        self.depth = depth
        self._bary = bary
        self.camera = camera
        self._lazy = _lazy_bary          # (Q, F), P = Q.T, while bary is not computed
        # sorted faces the compiled rasterizer z-tested (every face seen is one of them), for
        # the renderer's seen faces; None otherwise
        self._candidates = _candidates

    @property
    def bary(self) -> np.ndarray:
        if self._bary is None:
            Q, F = self._lazy
            kern = compiled_kernels()
            if kern is not None:
                b = np.empty(self.face_id.shape + (3,))
                kern.barycentrics_q(Q, F, self.face_id, self.camera.perspective, b)
            else:
                b = _barycentrics_numpy(Q.T, F, self.face_id, self.camera.perspective)
            self._bary, self._lazy = b, None
        return self._bary

    @bary.setter
    def bary(self, value: np.ndarray) -> None:
        self._bary, self._lazy = value, None

    def __repr__(self) -> str:
        return f"Raster({self.face_id.shape[1]}x{self.face_id.shape[0]}, camera={self.camera!r})"

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool, True where a face is seen."""
        return self.face_id >= 0

    def visible_faces(self) -> np.ndarray:
        """Sorted ids of the faces that cover at least one pixel."""
        ids = self.face_id[self.face_id >= 0]
        return np.unique(ids)


def rasterize(V, F, camera: Camera, *, backend: str = "auto") -> Raster:
    """Rasterize the triangle mesh ``(V (n, 3), F (m, 3))`` through ``camera``.

    ``backend``: "auto" (compiled when available), "compiled" or "numpy".
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    res = camera.resolution
    kern = compiled_kernels() if backend in ("auto", "compiled") else None
    if backend == "compiled" and kern is None:
        raise RuntimeError("the compiled rasterizer is not available (Numba missing or switched off)")
    if kern is not None:                      # the kernel writes every pixel
        face_id = np.empty((res, res), dtype=np.int64)
        depth = np.empty((res, res))
        V = np.ascontiguousarray(V).reshape(-1, 3)
        F = np.ascontiguousarray(F).reshape(-1, 3)
        Q = np.empty((3, len(V)))              # the projected vertices, P = Q.T
        cand = kern.project_rasterize(V, camera.position, camera._basis, camera.perspective,
                                      camera.projection_scale, res, camera.near, F, Q, face_id,
                                      depth, _NO_BARY)
        return Raster(face_id, depth, None, camera, _lazy_bary=(Q, F), _candidates=cand)
    else:
        face_id = np.full((res, res), -1, dtype=np.int64)
        depth = np.full((res, res), np.inf)
        bary = np.zeros((res, res, 3))
        P = camera.to_pixels(V)
        _rasterize_numpy(P, F, res, camera.perspective, camera.near, face_id, depth, bary)
    return Raster(face_id, depth, bary, camera)


def _barycentrics_numpy(P, F, face_id, perspective) -> np.ndarray:
    """``(H, W, 3)`` barycentrics of the faces ``face_id`` seen, by the z-test's formulas."""
    bary = np.zeros(face_id.shape + (3,))
    seen = face_id >= 0
    if not seen.any():
        return bary
    py, px = (a.astype(np.float64) for a in np.nonzero(seen))
    X = P[F[face_id[seen]]]
    xs, ys = X[..., 0], X[..., 1]
    inv = 1.0 / ((xs[:, 1] - xs[:, 0]) * (ys[:, 2] - ys[:, 0])
                 - (xs[:, 2] - xs[:, 0]) * (ys[:, 1] - ys[:, 0]))
    w0 = ((xs[:, 1] - px) * (ys[:, 2] - py) - (xs[:, 2] - px) * (ys[:, 1] - py)) * inv
    w1 = ((xs[:, 2] - px) * (ys[:, 0] - py) - (xs[:, 0] - px) * (ys[:, 2] - py)) * inv
    W = np.stack([w0, w1, 1.0 - w0 - w1], 1)
    if perspective:
        q = W / X[..., 2]
        W = q * (1.0 / ((q[:, 0] + q[:, 1]) + q[:, 2]))[:, None]
    bary[seen] = W
    return bary


def _rasterize_numpy(P, F, res, perspective, near, face_id, depth, bary) -> None:
    """Vectorized z-buffer: every (face, pixel-in-bounding-box) pair, then the nearest per pixel."""
    if len(F) == 0:
        return
    X = P[F]  # (m, 3, 3): corner, (col, row, depth)
    x, y, z = X[..., 0], X[..., 1], X[..., 2]
    finite = np.isfinite(x).all(1) & np.isfinite(y).all(1)
    if perspective:
        ok = (z > near).all(1)
    else:
        ok = (z > near).any(1)
    with np.errstate(invalid="ignore"):
        area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
        j0 = np.maximum(0, np.ceil(x.min(1)))
        j1 = np.minimum(res - 1, np.floor(x.max(1)))
        i0 = np.maximum(0, np.ceil(y.min(1)))
        i1 = np.minimum(res - 1, np.floor(y.max(1)))
        keep = finite & ok & (area != 0) & (j1 >= j0) & (i1 >= i0)
    f = np.flatnonzero(keep)
    if len(f) == 0:
        return
    j0, j1, i0, i1 = (a[f].astype(np.int64) for a in (j0, j1, i0, i1))
    nx, ny = j1 - j0 + 1, i1 - i0 + 1
    counts = nx * ny
    fid = np.repeat(f, counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    local = np.arange(counts.sum()) - start
    nxr = np.repeat(nx, counts)
    px = (np.repeat(j0, counts) + local % nxr).astype(np.float64)
    py = (np.repeat(i0, counts) + local // nxr).astype(np.float64)
    xs, ys, zs = x[fid], y[fid], z[fid]
    inv = 1.0 / area[fid]
    w0 = ((xs[:, 1] - px) * (ys[:, 2] - py) - (xs[:, 2] - px) * (ys[:, 1] - py)) * inv
    w1 = ((xs[:, 2] - px) * (ys[:, 0] - py) - (xs[:, 0] - px) * (ys[:, 2] - py)) * inv
    w2 = 1.0 - w0 - w1
    inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    W = np.stack([w0, w1, w2], 1)[inside]
    fid, px, py, zs = fid[inside], px[inside], py[inside], zs[inside]
    if perspective:
        q = W / zs
        s = q.sum(1)
        zz = 1.0 / s
        B = q * zz[:, None]
    else:
        zz = (W * zs).sum(1)
        B = W
    front = zz > near
    fid, px, py, zz, B = fid[front], px[front], py[front], zz[front], B[front]
    pix = py.astype(np.int64) * res + px.astype(np.int64)
    order = np.lexsort((fid, zz, pix))
    pix_sorted = pix[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = pix_sorted[1:] != pix_sorted[:-1]
    win = order[first]
    p = pix[win]
    face_id.reshape(-1)[p] = fid[win]
    depth.reshape(-1)[p] = zz[win]
    bary.reshape(-1, 3)[p] = B[win]
