"""Offset surface and camera sampling (thesis 2.4.1, lines 255-260; defaults 325-329).

Offset surface
--------------
The level set ``{x : d(x) = sigma}`` of the signed distance ``d`` to the shape (normalized to
``[-1, 1]^3``), built as: signed distance on a regular grid (``igl.signed_distance`` with the
fast generalized winding number for the sign, so open meshes such as camelhead get a sensible
inside/outside), then scikit-image's marching cubes at level ``sigma``. The grid spacing is at
most ``sigma / 2`` (at least 24, at most 72 cells per side), which gives offset meshes of
10^3-10^4 vertices as the thesis reports; the offset mesh is only *sampled* (never optimized), so
it is not decimated further. Its faces are oriented outwards (positive signed volume).

Cameras
-------
:func:`sample_camera` draws a point area-uniformly on the offset mesh (a face with probability
proportional to its area, then a uniform point in it), takes the interpolated outward normal
there and puts a camera at the point looking along the *inward* normal, with a uniformly random
roll (up vector) -- thesis 255-257.

Monitor views
-------------
:func:`monitor_cameras` is the fixed set of views whose mean energy says whether a whole run
works (the thesis measures one fixed view, 353-356; one view sees a sixth of the shape at most
and can rise while the rest falls, so the run's monitor is an average over ``k`` >= 16 views):
``32 k`` area-uniform candidate points of the offset surface thinned to ``k`` by farthest-point
sampling (starting from the first candidate), so the views are spread over the whole cage,
each looking inwards with a random roll, all drawn from the given generator (same seed, same
views).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidMeshError
from ..render import Camera

__all__ = ["OffsetSurface", "offset_surface", "sample_camera", "monitor_cameras"]


@dataclass
class OffsetSurface:
    """The camera cage: a triangle mesh with outward unit vertex normals and face areas."""

    V: np.ndarray
    F: np.ndarray
    N: np.ndarray
    areas: np.ndarray
    sigma: float

    @property
    def cdf(self) -> np.ndarray:
        c = np.cumsum(self.areas)
        return c / c[-1]


def offset_surface(V, F, sigma: float, *, max_cells: int = 72) -> OffsetSurface:
    """The offset surface at distance ``sigma`` of ``(V, F)`` (see the module docstring)."""
    import igl
    from skimage.measure import marching_cubes

    from ..mesh.operators import face_areas, signed_volume, vertex_normals

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    lo = V.min(0) - sigma * 1.5
    hi = V.max(0) + sigma * 1.5
    extent = float((hi - lo).max())
    cells = int(np.clip(np.ceil(extent / (sigma / 2.0)), 24, max_cells))
    h = extent / cells
    counts = np.maximum(3, np.ceil((hi - lo) / h).astype(int) + 3)
    lo = lo - h
    axes = [lo[d] + h * np.arange(counts[d]) for d in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    # in slices: libigl keeps Python's lock for a whole call (0.3-1 s for the ~370k grid points),
    # which froze the app's window while a run started; between slices other threads run
    kind = igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER
    step = 1 << 15
    S = np.concatenate([np.asarray(igl.signed_distance(P[i:i + step], V, F, kind)[0]).reshape(-1)
                        for i in range(0, len(P), step)])
    S = S.reshape(tuple(counts))
    if not (S.min() < sigma < S.max()):
        raise InvalidMeshError("The camera offset surface could not be built for this mesh "
                               "(no level set at the chosen offset). Try another offset σ.")
    verts, faces, _, _ = marching_cubes(S, level=sigma, spacing=(h, h, h))
    Vo = verts + lo
    Fo = faces.astype(np.int64)
    A = face_areas(Vo, Fo)
    keep = A > 0
    Fo = Fo[keep]
    if signed_volume(Vo, Fo) < 0:
        Fo = Fo[:, ::-1].copy()
    N = vertex_normals(Vo, Fo)
    return OffsetSurface(Vo, Fo, N, face_areas(Vo, Fo), float(sigma))


def _sample_point(offset: OffsetSurface, rng: np.random.Generator):
    """An area-uniform point of the offset mesh: (face, barycentric weights)."""
    f = int(np.searchsorted(offset.cdf, rng.random(), side="right"))
    f = min(f, len(offset.F) - 1)
    r1, r2 = rng.random(2)
    s = np.sqrt(r1)
    return f, np.array([1 - s, s * (1 - r2), s * r2])


def _camera_at(offset: OffsetSurface, f: int, w: np.ndarray, rng: np.random.Generator, *,
               width: float, resolution: int, projection: str, fov: float) -> Camera:
    tri = offset.F[f]
    p = w @ offset.V[tri]
    n = w @ offset.N[tri]
    nn = np.linalg.norm(n)
    if nn < 1e-12:
        a, b, c = offset.V[tri]
        n = np.cross(b - a, c - a)
        nn = np.linalg.norm(n)
    d = -n / nn
    # random roll: a random unit vector orthogonal to d
    for _ in range(10):
        u = rng.standard_normal(3)
        u -= d * (u @ d)
        if np.linalg.norm(u) > 1e-6:
            break
    return Camera(p, d, u, projection=projection, width=width, fov=fov, resolution=resolution)


def sample_camera(offset: OffsetSurface, rng: np.random.Generator, *, width: float = 0.5,
                  resolution: int = 128, projection: str = "orthographic",
                  fov: float = 30.0) -> Camera:
    """A camera at an area-uniform random point of ``offset``, looking along the inward normal,
    with a random roll."""
    f, w = _sample_point(offset, rng)
    return _camera_at(offset, f, w, rng, width=width, resolution=resolution,
                      projection=projection, fov=fov)


def monitor_cameras(offset: OffsetSurface, k: int, rng: np.random.Generator, *,
                    width: float = 0.5, resolution: int = 128,
                    projection: str = "orthographic", fov: float = 30.0) -> list[Camera]:
    """``k`` fixed views spread over ``offset`` (module docstring, *Monitor views*)."""
    k = max(1, int(k))
    cand = [_sample_point(offset, rng) for _ in range(32 * k)]
    P = np.array([w @ offset.V[offset.F[f]] for f, w in cand])
    chosen = [0]
    d = np.linalg.norm(P - P[0], axis=1)
    while len(chosen) < min(k, len(P)):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(P - P[i], axis=1))
    return [_camera_at(offset, cand[i][0], cand[i][1], rng, width=width,
                       resolution=resolution, projection=projection, fov=fov) for i in chosen]
