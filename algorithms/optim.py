"""First-order optimizer steps shared by the methods (one implementation per concept)."""

from __future__ import annotations

import numpy as np

__all__ = ["nadam_step"]


def nadam_step(g, m, v, t: int, lr: float, b1: float = 0.9, b2: float = 0.999,
               eps: float = 1e-8) -> np.ndarray:
    """One NAdam step (Dozat 2016, no momentum schedule): updates the moments ``m``, ``v`` in
    place and returns the displacement to subtract. ``t`` is the 1-based step count.

    Used by Paparazzi (β = 0.9, 0.999, the authors') and spectral coarsening (β = 0.9, 0.9, the
    authors' MATLAB)."""
    m *= b1
    m += (1 - b1) * g
    v *= b2
    v += (1 - b2) * g * g
    mhat = m / (1 - b1 ** t)
    vhat = v / (1 - b2 ** t)
    return lr * (b1 * mhat + (1 - b1) * g / (1 - b1 ** t)) / (np.sqrt(vhat) + eps)
