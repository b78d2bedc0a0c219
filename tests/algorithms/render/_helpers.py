"""Shared by the renderer's derivative tests."""

from __future__ import annotations

import numpy as np


def interior_pixels(face_id: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood sees the same face: away from face edges and silhouettes,
    where a small vertex move changes the shading but not the visibility."""
    H, W = face_id.shape
    ok = face_id >= 0
    pad = np.pad(face_id, 1, constant_values=-2)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            ok &= pad[1 + di:1 + di + H, 1 + dj:1 + dj + W] == face_id
    return ok
