"""Compiled (Numba) kernels of the surface multigrid solver: Gauss-Seidel sweeps and Alg. 10.

Importing this module imports :mod:`numba`; callers import it lazily through
:func:`algorithms.multigrid.relaxation.compiled_kernels`, which falls back to PyAMG's compiled
Gauss-Seidel (and a NumPy colouring) when Numba is missing or ``STYLIZE3D_NUMBA=0``. Every kernel
is ``@njit(cache=True)``, IEEE arithmetic (no ``fastmath``), one thread.

Right-hand sides are always 2-D ``(n, d)`` C-contiguous arrays (a scalar system is ``d = 1``);
the sweep updates all ``d`` columns of a row together (the row is read once).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["gauss_seidel_sweeps", "greedy_coloring"]


@njit(cache=True)
def gauss_seidel_sweeps(indptr, indices, data, diag, x, b, sweeps, backward):
    """In place: ``sweeps`` Gauss-Seidel sweeps on ``A x = b`` (A in CSR, ``diag`` its diagonal).

    ``x_i <- x_i + (b_i - sum_j a_ij x_j) / a_ii`` row by row, ascending (``backward`` False) or
    descending row order. ``x``, ``b``: (n, d) float64. Rows with ``diag == 0`` are left alone.
    """
    n = b.shape[0]
    d = b.shape[1]
    if d == 1:
        for s in range(sweeps):
            for t in range(n):
                i = n - 1 - t if backward else t
                a_ii = diag[i]
                if a_ii == 0.0:
                    continue
                r = b[i, 0]
                for k in range(indptr[i], indptr[i + 1]):
                    r -= data[k] * x[indices[k], 0]
                x[i, 0] += r / a_ii
        return
    acc = np.empty(d)
    for s in range(sweeps):
        for t in range(n):
            i = n - 1 - t if backward else t
            a_ii = diag[i]
            if a_ii == 0.0:
                continue
            for c in range(d):
                acc[c] = b[i, c]
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                a = data[k]
                for c in range(d):
                    acc[c] -= a * x[j, c]
            for c in range(d):
                x[i, c] += acc[c] / a_ii


@njit(cache=True)
def greedy_coloring(indptr, indices, order):
    """Alg. 10 (thesis App. 8.9.1): greedy colouring with a move-to-back palette.

    Nodes are painted in ``order`` (descending degree); each takes the first palette colour not
    used by an already painted neighbour, and that colour moves to the back of the palette; when
    every palette colour is taken a new colour is appended. Returns (n,) int64 colours.
    """
    n = indptr.shape[0] - 1
    color = np.full(n, -1, dtype=np.int64)
    palette = np.empty(n + 1, dtype=np.int64)  # palette[0:k] in list order
    k = 0
    stamp = np.full(n + 1, -1, dtype=np.int64)  # stamp[c] == node: colour c is taken
    for t in range(n):
        i = order[t]
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if j != i and color[j] >= 0:
                stamp[color[j]] = i
        pos = -1
        for q in range(k):
            if stamp[palette[q]] != i:
                pos = q
                break
        if pos < 0:
            c = k
            palette[k] = c
            k += 1
        else:
            c = palette[pos]
            for q in range(pos, k - 1):
                palette[q] = palette[q + 1]
            palette[k - 1] = c
        color[i] = c
    return color
