"""Compiled (Numba) kernels of the surface multigrid solver: Gauss-Seidel sweeps and Alg. 10.

Importing this module imports :mod:`numba`; callers import it lazily through
:func:`algorithms.multigrid.relaxation.compiled_kernels`, which falls back to PyAMG's compiled
Gauss-Seidel (and a NumPy colouring) when Numba is missing or ``STYLIZE3D_NUMBA=0``. Every kernel
is ``@njit(cache=True)``, IEEE arithmetic (no ``fastmath``), one thread.

Right-hand sides are always 2-D ``(n, d)`` C-contiguous arrays (a scalar system is ``d = 1``);
the sweep updates all ``d`` columns of a row together (the row is read once).

Threads (issue 25): :func:`multicolor_sweeps` (the multi-colour smoother) updates the rows of
one colour in chunks of ``CHUNK`` rows on Numba's threads. Rows of one colour do not touch each
other, so each row's update reads the same values whatever thread runs it and whatever the
number of threads: the same bits as the serial loop (a twin compiled without ``parallel``, run
when :func:`algorithms.compiled.use_threads` says so). Lexicographic and block Gauss-Seidel are
sequential by nature and stay on one thread.
"""

from __future__ import annotations

import numpy as np
from .._numba import njit, prange

from ..compiled import use_threads

__all__ = ["gauss_seidel_sweeps", "greedy_coloring", "merge_strong_pairs",
           "block_gauss_seidel_sweeps", "multicolor_sweeps", "CHUNK"]

CHUNK = 256
"""Rows per work unit of :func:`multicolor_sweeps` (fixed: the split does not depend on the
number of threads)."""


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def merge_strong_pairs(n, ri, rj, max_block):
    """Union-find over the strong couplings ``(ri[t], rj[t])``, strongest first, never letting a
    block grow past ``max_block`` vertices. Returns each vertex's block root."""
    parent = np.arange(n)
    size = np.ones(n, dtype=np.int64)
    for t in range(ri.shape[0]):
        a = ri[t]
        b = rj[t]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a == b or size[a] + size[b] > max_block:
            continue
        if size[a] < size[b]:
            a, b = b, a
        parent[b] = a
        size[a] += size[b]
    for i in range(n):
        r = i
        while parent[r] != r:
            r = parent[r]
        parent[i] = r
    return parent


@njit(cache=True, nogil=True)
def block_gauss_seidel_sweeps(indptr, indices, data, bptr, bverts, iptr, inv, x, b, sweeps,
                              backward):
    """In place: block Gauss-Seidel sweeps; block ``c`` is ``bverts[bptr[c]:bptr[c+1]]`` and
    its inverse the row-major ``inv[iptr[c]:iptr[c+1]]``. Each block's rows are solved together:
    ``x_B += A_BB^-1 (b_B - A_B: x)``, blocks in ascending (or, ``backward``, descending) order."""
    nb = bptr.shape[0] - 1
    d = b.shape[1]
    mx = 1
    for c in range(nb):
        mx = max(mx, bptr[c + 1] - bptr[c])
    r = np.empty((mx, d))
    for s in range(sweeps):
        for t in range(nb):
            c = nb - 1 - t if backward else t
            p0 = bptr[c]
            m = bptr[c + 1] - p0
            for a in range(m):
                i = bverts[p0 + a]
                for q in range(d):
                    r[a, q] = b[i, q]
                for k in range(indptr[i], indptr[i + 1]):
                    j = indices[k]
                    v = data[k]
                    for q in range(d):
                        r[a, q] -= v * x[j, q]
            o = iptr[c]
            for a in range(m):
                i = bverts[p0 + a]
                for q in range(d):
                    acc = 0.0
                    for e in range(m):
                        acc += inv[o + a * m + e] * r[e, q]
                    x[i, q] += acc


@njit(cache=True, nogil=True)
def _color_rows(indptr, indices, data, inv, rows, lo, hi, x, b):
    """``x_i += (b_i - A_i: x) * inv_i`` for the rows ``rows[lo:hi]`` (one colour)."""
    d = b.shape[1]
    if d == 1:
        for t in range(lo, hi):
            i = rows[t]
            s = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                s += data[k] * x[indices[k], 0]
            x[i, 0] += (b[i, 0] - s) * inv[i]
        return
    acc = np.empty(d)
    for t in range(lo, hi):
        i = rows[t]
        for c in range(d):
            acc[c] = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            a = data[k]
            for c in range(d):
                acc[c] += a * x[j, c]
        for c in range(d):
            x[i, c] += (b[i, c] - acc[c]) * inv[i]


@njit(cache=True, nogil=True, parallel=True)
def _color_par(indptr, indices, data, inv, rows, lo, hi, x, b):
    for q in prange((hi - lo + CHUNK - 1) // CHUNK):
        _color_rows(indptr, indices, data, inv, rows, lo + q * CHUNK,
                    min(hi, lo + (q + 1) * CHUNK), x, b)


@njit(cache=True, nogil=True)
def _color_ser(indptr, indices, data, inv, rows, lo, hi, x, b):
    for q in range((hi - lo + CHUNK - 1) // CHUNK):
        _color_rows(indptr, indices, data, inv, rows, lo + q * CHUNK,
                    min(hi, lo + (q + 1) * CHUNK), x, b)


@njit(cache=True, nogil=True)
def _multicolor_sweeps_ser(indptr, indices, data, inv, cptr, rows, x, b, sweeps, backward):
    nc = cptr.shape[0] - 1
    for s in range(sweeps):
        for t in range(nc):
            c = nc - 1 - t if backward else t
            _color_ser(indptr, indices, data, inv, rows, cptr[c], cptr[c + 1], x, b)


def _multicolor_sweeps(indptr, indices, data, inv, cptr, rows, x, b, sweeps, backward, par):
    """The sweeps; with ``par`` driven from Python, colour by colour (a parallel kernel is
    only ever called from Python: :mod:`algorithms.compiled`, "cached kernels")."""
    if not par:
        _multicolor_sweeps_ser(indptr, indices, data, inv, cptr, rows, x, b, sweeps, backward)
        return
    nc = cptr.shape[0] - 1
    bounds = cptr.tolist()
    for s in range(sweeps):
        for t in range(nc):
            c = nc - 1 - t if backward else t
            lo, hi = bounds[c], bounds[c + 1]
            kernel = _color_par if hi - lo > CHUNK else _color_ser
            kernel(indptr, indices, data, inv, rows, lo, hi, x, b)


def multicolor_sweeps(indptr, indices, data, inv, cptr, rows, x, b, sweeps, backward):
    """In place: multi-colour Gauss-Seidel sweeps on ``A x = b`` (A in CSR).

    Colour ``c`` holds the rows ``rows[cptr[c]:cptr[c+1]]``; colours go in ascending (or,
    ``backward``, descending) order and each row of a colour gets
    ``x_i += (b_i - sum_j a_ij x_j) * inv_i`` (``inv_i = 1 / a_ii``, 0 for a zero diagonal).
    ``x``, ``b``: (n, d) float64. A colour's rows run on Numba's threads (same bits for any
    thread count: the rows of a colour do not touch each other).
    """
    _multicolor_sweeps(indptr, indices, data, inv, cptr, rows, x, b, int(sweeps),
                       bool(backward), use_threads())
