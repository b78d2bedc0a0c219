"""Pluggable flat shading: per-face normals (+ optional per-face albedo) -> per-face colours.

A shading object implements the :class:`Shading` protocol:

* ``channels`` -- colours per pixel (3 for RGB, 1 for grey);
* ``face_colors(normals, camera, albedo=None) -> (k, C)``;
* ``face_colors_vjp(normals, camera, grad_colors, albedo=None) -> (grad_normals (k, 3),
  grad_albedo (k, C) or None)`` -- the vector-Jacobian product of ``face_colors``;
* optionally ``face_colors_with_state(normals, camera, albedo=None) -> (colours, state)``: the
  renderer then keeps ``state`` in :attr:`Rendering.state` for the shading's own derivatives
  (:class:`~algorithms.render.sh.SHShading` keeps the SH basis of the seen faces, so the lighting
  derivative is one matrix product).

The renderer (:func:`algorithms.render.render`) paints each pixel with the colour of its face, and
:func:`algorithms.render.image_vjp` pulls image gradients back through ``face_colors_vjp`` and the
analytic normal derivative. A new lighting model (e.g. spherical harmonics, issue 13) is a new
class with these two methods; the rasterizer and the geometry derivative are shared.

:class:`LambertianShading` -- m coloured directional lights (thesis Eq. at 308-312)
-------------------------------------------------------------------------------------
``colour_c = scale * n . sum_i l_i c_i^c + offset`` (times the face albedo when one is given),
unclamped. ``mapping="authors"`` (default) is the authors' ``(n . l + 1) / 2`` (scale 1/2,
offset 1/2: colours of unit normals stay in [0, 1] for axis lights); ``mapping="linear"`` is the
thesis's formula as printed (scale 1, offset 0). ``frame="camera"`` (default) gives the light
directions in the camera frame (x right, y up, z towards the viewer, i.e. ``-direction``);
``frame="world"`` in world coordinates (the quantization filter renders world-frame normals,
thesis 447-449). The default lights are red, green and blue along the camera's x, y and z axes:
an image of the normals in the camera frame (thesis 329, removes the shading ambiguity of 262-266).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import ParameterError
from .camera import Camera

__all__ = ["Shading", "LambertianShading", "light_frame", "MAPPINGS"]

MAPPINGS = {"authors": (0.5, 0.5), "linear": (1.0, 0.0)}


@runtime_checkable
class Shading(Protocol):
    channels: int

    def face_colors(self, normals: np.ndarray, camera: Camera,
                    albedo: np.ndarray | None = None) -> np.ndarray: ...

    def face_colors_vjp(self, normals: np.ndarray, camera: Camera, grad_colors: np.ndarray,
                        albedo: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray | None]: ...


def light_frame(camera: Camera) -> np.ndarray:
    """(3, 3) rows: the camera frame's x (right), y (up), z (towards the viewer) in world space."""
    b = camera.basis
    return np.stack([b[0], b[1], -b[2]])


class LambertianShading:
    """Flat Lambertian shading with m coloured directional lights (see the module docstring).

    Parameters
    ----------
    directions : (m, 3) light directions (normalized here); default the three camera axes.
    colors : (m, C) light colours; default the identity (red, green, blue).
    frame : "camera" or "world" -- the frame ``directions`` are given in.
    mapping : "authors" ((n.l + 1)/2) or "linear" (n.l).
    """

    def __init__(self, directions=None, colors=None, *, frame: str = "camera",
                 mapping: str = "authors"):
        if directions is None:
            directions = np.eye(3)
        L = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        nrm = np.linalg.norm(L, axis=1)
        if len(L) == 0 or not np.isfinite(L).all() or (nrm == 0).any():
            raise ParameterError("Light directions must be non-zero finite 3D vectors.")
        self.directions = L / nrm[:, None]
        if colors is None:
            colors = np.eye(len(L), 3) if len(L) == 3 else np.ones((len(L), 3))
        C = np.asarray(colors, dtype=np.float64)
        if C.ndim == 1:
            C = C[:, None]
        if C.shape[0] != len(L) or not np.isfinite(C).all():
            raise ParameterError("Give one colour per light (an (m, C) array of finite numbers).")
        self.colors = C
        if frame not in ("camera", "world"):
            raise ParameterError(f"Light frame must be 'camera' or 'world' (got {frame!r}).")
        if mapping not in MAPPINGS:
            raise ParameterError(f"Shading mapping must be one of {', '.join(MAPPINGS)} "
                                 f"(got {mapping!r}).")
        self.frame = frame
        self.mapping = mapping
        self.scale, self.offset = MAPPINGS[mapping]
        self.channels = int(C.shape[1])

    def light_matrix(self, camera: Camera) -> np.ndarray:
        """(3, C) ``M = sum_i l_i c_i^T`` in world coordinates (colour = scale n M + offset).
        Camera frame: ``M = R^T diag(1, 1, -1) L^T C`` with ``R`` the camera's rows (right, up,
        direction), i.e. ``(L light_frame)^T C`` in two small products."""
        K = self.directions.T @ self.colors
        if self.frame == "camera":
            K[2] = -K[2]
            return camera._basis.T @ K
        return K

    def face_colors(self, normals, camera, albedo=None):
        M = self.light_matrix(camera)
        col = self.scale * (np.asarray(normals) @ M) + self.offset
        if albedo is not None:
            col = col * albedo
        return col

    def face_colors_vjp(self, normals, camera, grad_colors, albedo=None):
        M = self.light_matrix(camera)
        g = np.asarray(grad_colors, dtype=np.float64)
        grad_albedo = None
        if albedo is not None:
            grad_albedo = g * (self.scale * (np.asarray(normals) @ M) + self.offset)
            g = g * albedo
        return self.scale * (g @ M.T), grad_albedo
