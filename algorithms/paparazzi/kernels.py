"""Numba kernels of Paparazzi's filters (loaded through :mod:`algorithms.compiled`; the NumPy
code in :mod:`.filters` is the fallback and the reference of the tests).

:func:`guided_filter` is the whole fast guided filter (He and Sun 2015) of
:func:`algorithms.paparazzi.filters.guided_filter` in one pass over small arrays: at Paparazzi's
128 px with subsampling 4 the NumPy version spends its ~5-10 ms in the overhead of a few dozen
array operations, this one well under a millisecond.
"""

from __future__ import annotations

import numpy as np
from .._numba import njit


@njit(cache=True, nogil=True)
def _box(x, r):
    """Mean of every channel of ``x (h, w, K)`` over the (2r+1)^2 window clipped to the image."""
    h, w, K = x.shape
    S = np.zeros((h + 1, w + 1, K))
    for i in range(h):
        for j in range(w):
            for k in range(K):
                S[i + 1, j + 1, k] = x[i, j, k] + S[i, j + 1, k] + S[i + 1, j, k] - S[i, j, k]
    out = np.empty((h, w, K))
    for i in range(h):
        y0 = max(i - r, 0)
        y1 = min(i + r + 1, h)
        for j in range(w):
            x0 = max(j - r, 0)
            x1 = min(j + r + 1, w)
            n = float((y1 - y0) * (x1 - x0))
            for k in range(K):
                out[i, j, k] = (S[y1, x1, k] - S[y0, x1, k] - S[y1, x0, k] + S[y0, x0, k]) / n
    return out


@njit(cache=True, nogil=True)
def _solve3(A, B, C, X):
    """Solve ``A (3, 3) X = B (3, C)`` by LU with partial pivoting (as LAPACK's gesv)."""
    for c in range(3):
        for d in range(C):
            X[c, d] = B[c, d]
    for col in range(3):
        piv = col
        best = abs(A[col, col])
        for row in range(col + 1, 3):
            if abs(A[row, col]) > best:
                best = abs(A[row, col])
                piv = row
        if piv != col:
            for j in range(3):
                t = A[col, j]
                A[col, j] = A[piv, j]
                A[piv, j] = t
            for d in range(C):
                t = X[col, d]
                X[col, d] = X[piv, d]
                X[piv, d] = t
        for row in range(col + 1, 3):
            f = A[row, col] / A[col, col]
            for j in range(col, 3):
                A[row, j] -= f * A[col, j]
            for d in range(C):
                X[row, d] -= f * X[col, d]
    for col in range(2, -1, -1):
        for d in range(C):
            s = X[col, d]
            for j in range(col + 1, 3):
                s -= A[col, j] * X[j, d]
            X[col, d] = s / A[col, col]


@njit(cache=True, nogil=True)
def guided_filter(I, p, radius, eps, s):
    """Colour-guided fast guided filter of ``p (H, W, C)`` with guide ``I (H, W, 3)``; the same
    arithmetic as the NumPy version (window sums in another order: equal to rounding)."""
    H, W, _ = I.shape
    C = p.shape[2]
    h = (H + s - 1) // s
    w = (W + s - 1) // s
    r = max(1, int(np.round(radius / s)))
    K = 3 + C + 3 * C + 9
    st = np.empty((h, w, K))
    for i in range(h):
        for j in range(w):
            for k in range(3):
                st[i, j, k] = I[i * s, j * s, k]
            for c in range(C):
                st[i, j, 3 + c] = p[i * s, j * s, c]
            for k in range(3):
                for c in range(C):
                    st[i, j, 3 + C + k * C + c] = I[i * s, j * s, k] * p[i * s, j * s, c]
            for k in range(3):
                for l in range(3):
                    st[i, j, 3 + 4 * C + 3 * k + l] = I[i * s, j * s, k] * I[i * s, j * s, l]
    m = _box(st, r)
    ab = np.empty((h, w, 3 * C + C))
    A = np.empty((3, 3))
    B = np.empty((3, C))
    X = np.empty((3, C))
    for i in range(h):
        for j in range(w):
            for k in range(3):
                for c in range(C):
                    B[k, c] = m[i, j, 3 + C + k * C + c] - m[i, j, k] * m[i, j, 3 + c]
                for l in range(3):
                    A[k, l] = m[i, j, 3 + 4 * C + 3 * k + l] - m[i, j, k] * m[i, j, l]
                A[k, k] += eps
            _solve3(A, B, C, X)
            for c in range(C):
                b = m[i, j, 3 + c]
                for k in range(3):
                    ab[i, j, k * C + c] = X[k, c]
                    b -= m[i, j, k] * X[k, c]
                ab[i, j, 3 * C + c] = b
    mab = _box(ab, r)
    out = np.empty((H, W, C))
    KK = 4 * C
    row = np.empty((W, KK))
    for i in range(H):
        y = min(max((i + 0.5) * (h / H) - 0.5, 0.0), h - 1.0)
        i0 = min(int(np.floor(y)), h - 1)
        i1 = min(i0 + 1, h - 1)
        wy = y - i0
        for j in range(W):
            x = min(max((j + 0.5) * (w / W) - 0.5, 0.0), w - 1.0)
            j0 = min(int(np.floor(x)), w - 1)
            j1 = min(j0 + 1, w - 1)
            wx = x - j0
            for k in range(KK):
                top = mab[i0, j0, k] * (1.0 - wx) + mab[i0, j1, k] * wx
                bot = mab[i1, j0, k] * (1.0 - wx) + mab[i1, j1, k] * wx
                row[j, k] = top * (1.0 - wy) + bot * wy
        for j in range(W):
            for c in range(C):
                v = row[j, 3 * C + c]
                for k in range(3):
                    v += I[i, j, k] * row[j, k * C + c]
                out[i, j, c] = v
    return out


@njit(cache=True, nogil=True)
def l0_gradient_step(S, thresh, out):
    """The spatial half of one L0 smoothing iteration (Xu et al. 2011) of ``S (C, H, W)`` with
    periodic boundaries, into ``out (C, H, W)``: the forward differences h (along W) and v (along
    H), set to zero at the pixels where ``sum_c h^2 + v^2 < thresh``, then their divergence
    ``(h[j-1] - h[j]) + (v[i-1] - v[i])``, in ``S``'s precision (the filter's float32; ``thresh``
    of the same type). The same arithmetic in the same order as the NumPy code of
    :func:`algorithms.paparazzi.filters.l0_smooth` (so the same bits; tested), in two passes:
    the per-pixel sum ``s`` (channels added in NumPy's order, ``((x0 + x1) + x2)``), then the
    divergence, which recomputes the four differences it needs from ``S`` (a difference is the
    same subtraction wherever it is made). 0.18 ms at 3 x 256 x 256 in float32 (three passes
    with stored differences: 0.27 ms; measured inside the filter, where the FFTs are most of it)."""
    C, H, W = S.shape
    s = np.empty((H, W), S.dtype)
    for i in range(H):
        i1 = i + 1 if i + 1 < H else 0
        for c in range(C):
            for j in range(W):
                h = S[c, i, j + 1 if j + 1 < W else 0] - S[c, i, j]
                v = S[c, i1, j] - S[c, i, j]
                if c == 0:
                    s[i, j] = h * h + v * v
                else:
                    s[i, j] = s[i, j] + (h * h + v * v)
    cut = np.empty((H, W), np.bool_)
    for i in range(H):
        for j in range(W):
            cut[i, j] = s[i, j] < thresh                 # (NaN: kept, as in NumPy)
    zero = S.dtype.type(0.0)
    for c in range(C):
        for i in range(H):
            i0 = i - 1 if i > 0 else H - 1
            i1 = i + 1 if i + 1 < H else 0
            for j in range(W):
                j0 = j - 1 if j > 0 else W - 1
                j1 = j + 1 if j + 1 < W else 0
                x = S[c, i, j]
                h = zero if cut[i, j] else S[c, i, j1] - x
                v = zero if cut[i, j] else S[c, i1, j] - x
                hl = zero if cut[i, j0] else x - S[c, i, j0]
                vu = zero if cut[i0, j] else x - S[c, i0, j]
                out[c, i, j] = (hl - h) + (vu - v)
