"""Cameras of the one renderer: orthographic (the Paparazzi default) and perspective.

Conventions (tested in ``tests/algorithms/render/test_camera.py``)
------------------------------------------------------------------
* A camera has a ``position``, a viewing ``direction`` and an ``up`` hint (re-orthogonalized:
  only its component orthogonal to ``direction`` counts).
* Camera frame: ``x`` = right = ``direction x up`` normalized, ``y`` = true up = ``x x direction``,
  ``z`` = ``direction`` (depth grows away from the camera). :meth:`Camera.basis` returns these three
  unit vectors as rows, so ``(p - position) @ basis.T`` are a point's camera coordinates.
* Images are square, ``resolution x resolution`` pixels, row 0 at the top (largest ``y``),
  column 0 on the left (smallest ``x``). Pixel ``(i, j)`` is sampled at its centre.
* Orthographic: the view is a square of side ``width`` (world units) around the view axis; the
  thesis's default is 0.5 in the OpenGL canonical view volume, i.e. for a shape normalized to
  ``[-1, 1]^3`` (thesis 325-329). Everything with depth ``> near`` (default 0: in front of the
  camera) is seen; there is no far plane.
* Perspective: ``fov`` is the full angle (degrees) of the square view; a point at depth ``z`` maps
  to ``x / (z tan(fov/2))``. Triangles with a corner at depth ``<= near`` are skipped (no
  clipping; ``near`` defaults to 1e-3 world units for perspective cameras).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError

__all__ = ["Camera", "look_at", "PROJECTIONS"]

PROJECTIONS = ("orthographic", "perspective")


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ParameterError(f"The camera {what} must be three finite numbers (got {v!r}).")
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ParameterError(f"The camera {what} must not be the zero vector.")
    return v / n


@dataclass(frozen=True, eq=False)
class Camera:
    """A square camera. See the module docstring for the conventions.

    Attributes
    ----------
    position : (3,) float64, the eye point.
    direction : (3,) float64 unit viewing direction.
    up : (3,) float64 unit up vector, orthogonal to ``direction``.
    projection : "orthographic" or "perspective".
    width : orthographic view width in world units (thesis default 0.5).
    fov : perspective full view angle in degrees.
    resolution : pixels per side.
    near : smallest depth seen.
    """

    position: np.ndarray
    direction: np.ndarray
    up: np.ndarray
    projection: str = "orthographic"
    width: float = 0.5
    fov: float = 60.0
    resolution: int = 128
    near: float | None = None
    _basis: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        pos = np.asarray(self.position, dtype=np.float64).reshape(-1)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise ParameterError(f"The camera position must be three finite numbers (got {pos!r}).")
        d = _unit(self.direction, "direction")
        u = np.asarray(self.up, dtype=np.float64).reshape(-1)
        u = _unit(u, "up vector")
        u = u - d * float(d @ u)
        if np.linalg.norm(u) < 1e-9:
            raise ParameterError("The camera up vector is parallel to the view direction; "
                                 "choose an up vector that is not.")
        u /= np.linalg.norm(u)
        if self.projection not in PROJECTIONS:
            raise ParameterError(f"Camera projection must be one of {', '.join(PROJECTIONS)} "
                                 f"(got {self.projection!r}).")
        res = int(self.resolution)
        if res != self.resolution or res < 1 or res > 8192:
            raise ParameterError(f"Image resolution must be a whole number from 1 to 8192 "
                                 f"(got {self.resolution!r}).")
        if self.projection == "orthographic" and not (np.isfinite(self.width) and self.width > 0):
            raise ParameterError(f"The orthographic view width must be positive (got {self.width}).")
        if self.projection == "perspective" and not (0 < self.fov < 179):
            raise ParameterError(f"The perspective field of view must be between 0 and 179 degrees "
                                 f"(got {self.fov}).")
        near = self.near
        if near is None:
            near = 0.0 if self.projection == "orthographic" else 1e-3
        right = np.cross(d, u)
        right /= np.linalg.norm(right)
        up2 = np.cross(right, d)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "direction", d)
        object.__setattr__(self, "up", up2)
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "near", float(near))
        object.__setattr__(self, "_basis", np.stack([right, up2, d]))

    @property
    def basis(self) -> np.ndarray:
        """(3, 3) rows: right, up, direction (world -> camera rotation)."""
        return self._basis.copy()

    @property
    def perspective(self) -> bool:
        return self.projection == "perspective"

    def to_camera(self, P) -> np.ndarray:
        """Camera coordinates ``(k, 3)`` of world points ``P (k, 3)``.

        Written out per coordinate (not a BLAS product) so that the compiled projection of the
        rasterizer (:func:`algorithms.render.kernels.project`) is bit-identical to it."""
        D = np.asarray(P, dtype=np.float64).reshape(-1, 3) - self.position
        b = self._basis
        x, y, z = D[:, 0], D[:, 1], D[:, 2]
        out = np.empty_like(D)
        for r in range(3):
            out[:, r] = x * b[r, 0] + y * b[r, 1] + z * b[r, 2]
        return out

    @property
    def projection_scale(self) -> float:
        """``tan(fov / 2)`` (perspective) or ``width / 2`` (orthographic): screen coordinates in
        ``[-1, 1]`` are camera ``x / (z scale)`` or ``x / scale``."""
        if self.perspective:
            return float(np.tan(np.radians(self.fov) / 2.0))
        return self.width / 2.0

    def to_pixels(self, P) -> np.ndarray:
        """``(k, 3)``: column, row (continuous; pixel centres at integers) and depth of points."""
        C = self.to_camera(P)
        res = self.resolution
        t = self.projection_scale
        if self.perspective:
            with np.errstate(divide="ignore", invalid="ignore"):
                sx, sy = C[:, 0] / (C[:, 2] * t), C[:, 1] / (C[:, 2] * t)
        else:
            sx, sy = C[:, 0] / t, C[:, 1] / t
        out = np.empty_like(C)
        out[:, 0] = (sx + 1.0) * 0.5 * res - 0.5
        out[:, 1] = (1.0 - sy) * 0.5 * res - 0.5
        out[:, 2] = C[:, 2]
        return out

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions ``(res, res, 3)`` of the rays through the pixel centres."""
        res = self.resolution
        s = (np.arange(res) + 0.5) / res * 2.0 - 1.0  # -1..1 left to right
        sx = s[None, :].repeat(res, 0)
        sy = -s[:, None].repeat(res, 1)
        right, up, d = self._basis
        if self.perspective:
            t = np.tan(np.radians(self.fov) / 2.0)
            D = d + (sx[..., None] * t) * right + (sy[..., None] * t) * up
            D /= np.linalg.norm(D, axis=-1, keepdims=True)
            O = np.broadcast_to(self.position, D.shape).copy()
        else:
            h = self.width / 2.0
            O = self.position + (sx[..., None] * h) * right + (sy[..., None] * h) * up
            D = np.broadcast_to(d, O.shape).copy()
        return O, D

    def with_resolution(self, resolution: int) -> "Camera":
        """The same camera with another resolution."""
        return Camera(self.position, self.direction, self.up, self.projection, self.width,
                      self.fov, resolution, self.near)


def look_at(position, target, up=(0.0, 1.0, 0.0), **kwargs) -> Camera:
    """A camera at ``position`` looking at ``target`` (keyword arguments go to :class:`Camera`)."""
    position = np.asarray(position, dtype=np.float64)
    return Camera(position, np.asarray(target, dtype=np.float64) - position, up, **kwargs)
