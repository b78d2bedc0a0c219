"""Compiled (Numba) kernel of the rasterizer.

Importing this module imports :mod:`numba`; :mod:`algorithms.render.raster` loads it lazily
through :class:`algorithms.compiled.KernelModule` and falls back to its NumPy rasterizer when it
is unavailable or switched off (``STYLIZE3D_NUMBA=0``). ``@njit(cache=True)``, one thread,
``fastmath`` off. Same rules as the NumPy code (see :mod:`algorithms.render.raster`): pixel centres
at integer coordinates, a pixel is covered when its three barycentric coordinates are ``>= 0``,
the nearest depth ``> near`` wins, ties go to the lower face index.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["rasterize"]


@njit(cache=True, nogil=True)
def rasterize(P, F, res, perspective, near, face_id, depth, bary):  # pragma: no cover - compiled
    """Z-buffer ``F`` with vertices ``P (n, 3)`` = (column, row, depth) into the output arrays
    (``face_id`` filled with -1, ``depth`` with inf beforehand)."""
    m = F.shape[0]
    for f in range(m):
        a = F[f, 0]
        b = F[f, 1]
        c = F[f, 2]
        x0 = P[a, 0]
        y0 = P[a, 1]
        z0 = P[a, 2]
        x1 = P[b, 0]
        y1 = P[b, 1]
        z1 = P[b, 2]
        x2 = P[c, 0]
        y2 = P[c, 1]
        z2 = P[c, 2]
        if perspective:
            if z0 <= near or z1 <= near or z2 <= near:
                continue
        else:
            if z0 <= near and z1 <= near and z2 <= near:
                continue
        if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2)
                and math.isfinite(y0) and math.isfinite(y1) and math.isfinite(y2)):
            continue
        xmin = min(x0, min(x1, x2))
        xmax = max(x0, max(x1, x2))
        ymin = min(y0, min(y1, y2))
        ymax = max(y0, max(y1, y2))
        if xmax < 0.0 or ymax < 0.0 or xmin > res - 1.0 or ymin > res - 1.0:
            continue
        i0 = max(0, int(math.ceil(ymin)))
        i1 = min(res - 1, int(math.floor(ymax)))
        j0 = max(0, int(math.ceil(xmin)))
        j1 = min(res - 1, int(math.floor(xmax)))
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0 or not math.isfinite(area):
            continue
        inv = 1.0 / area
        # Edge functions are affine in the column: w_e(px) = a_e px + b_e(py). Each row's span
        # of columns where all three are >= 0 is found analytically, widened by one pixel on
        # each side, and the exact test below (the NumPy formulas) decides, so the result is
        # the same as testing the whole bounding box.
        a0 = -(y2 - y1) * inv
        a1 = -(y0 - y2) * inv
        for i in range(i0, i1 + 1):
            py = float(i)
            lo = float(j0)
            hi = float(j1)
            c0 = (x1 * (y2 - py) - x2 * (y1 - py)) * inv
            c1 = (x2 * (y0 - py) - x0 * (y2 - py)) * inv
            c2 = 1.0 - c0 - c1
            a2 = -a0 - a1
            empty = False
            for e in range(3):
                if e == 0:
                    a = a0
                    c = c0
                elif e == 1:
                    a = a1
                    c = c1
                else:
                    a = a2
                    c = c2
                if a == 0.0:
                    if c < -1e-12:
                        empty = True
                    continue
                t = min(max(-c / a, j0 - 2.0), j1 + 2.0)   # clamped: no int overflow
                if a > 0.0:
                    lo = max(lo, math.ceil(t) - 1.0)
                else:
                    hi = min(hi, math.floor(t) + 1.0)
            if empty or hi < lo:
                continue
            for j in range(int(lo), int(hi) + 1):
                px = float(j)
                w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) * inv
                w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) * inv
                w2 = 1.0 - w0 - w1
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                if perspective:
                    q0 = w0 / z0
                    q1 = w1 / z1
                    q2 = w2 / z2
                    s = q0 + q1 + q2
                    z = 1.0 / s
                    b0 = q0 * z
                    b1 = q1 * z
                    b2 = q2 * z
                else:
                    z = w0 * z0 + w1 * z1 + w2 * z2
                    b0 = w0
                    b1 = w1
                    b2 = w2
                if z <= near or z >= depth[i, j]:
                    continue
                depth[i, j] = z
                face_id[i, j] = f
                bary[i, j, 0] = b0
                bary[i, j, 1] = b1
                bary[i, j, 2] = b2
