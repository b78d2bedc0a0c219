"""Compiled (Numba) kernels of spectral coarsening's energy and gradient (issue 25).

Imported lazily through :data:`algorithms.spectral.coarsen._KERNELS` (a
:class:`~algorithms.compiled.KernelModule`); :mod:`algorithms.spectral.coarsen` falls back to
SciPy's sparse products and NumPy when Numba is missing or switched off (``STYLIZE3D_NUMBA=0``).

Two kernels, each a parallel and a serial version compiled from the same per-row code (see
:mod:`algorithms.compiled`): every output row is computed by one thread, by the same operations
in the same order, so the results have the same bits for any thread count.

* :func:`csr_dense`: ``A @ X`` for a CSR matrix ``A`` and a dense C-ordered ``X`` (n2, k) -- the
  products ``G B``, ``L (G B)``, ``G^T (L G B)``, ``G W`` and ``L (G W)`` of the energy.
* :func:`pattern_dots`: ``g_z = P_i . Q_j + R_i . S_j`` for every stored entry ``z = (i, j)`` of
  a CSR pattern -- the gradient ``(L G W) B^T + (L G B) W^T`` evaluated on the pattern of ``G``
  only (App. 7.6.1), never the dense n x m product.

Neither uses BLAS: OpenBLAS's threads, when the machine's cores are busy with other work, made a
dot product of 215k numbers take 8-23 ms instead of 0.1 ms here.
"""

from __future__ import annotations

import numpy as np
from .._numba import njit, prange

from ..compiled import use_threads

__all__ = ["csr_dense", "pattern_dots", "spgemm_fixed", "pattern_rowdot", "sym_outer",
           "CHUNK"]

CHUNK = 256
"""Rows per work unit; fixed, so the split of the work does not depend on the thread count."""

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)
_PAR = dict(_OPTS, parallel=True)


@njit(**_OPTS)
def _csr_dense_rows(indptr, indices, data, X, r0, r1, out):
    k = X.shape[1]
    for i in range(r0, r1):
        for c in range(k):
            out[i, c] = 0.0
        for z in range(indptr[i], indptr[i + 1]):
            a = data[z]
            j = indices[z]
            for c in range(k):
                out[i, c] += a * X[j, c]


@njit(**_PAR)
def _csr_dense_par(indptr, indices, data, X, out):
    n = out.shape[0]
    for b in prange((n + CHUNK - 1) // CHUNK):
        _csr_dense_rows(indptr, indices, data, X, b * CHUNK, min(n, (b + 1) * CHUNK), out)


@njit(**_OPTS)
def _csr_dense_ser(indptr, indices, data, X, out):
    n = out.shape[0]
    for b in range((n + CHUNK - 1) // CHUNK):
        _csr_dense_rows(indptr, indices, data, X, b * CHUNK, min(n, (b + 1) * CHUNK), out)


def csr_dense(indptr, indices, data, X) -> np.ndarray:
    """``A @ X`` (n, k) for ``A`` in CSR (``indptr`` (n+1,), ``indices``, ``data``) and a dense
    (n2, k) ``X``; float64, C-ordered."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    out = np.empty((len(indptr) - 1, X.shape[1]))
    if use_threads():
        _csr_dense_par(indptr, indices, data, X, out)
    else:
        _csr_dense_ser(indptr, indices, data, X, out)
    return out


@njit(**_OPTS)
def _pattern_rows(indptr, indices, P, Q, R, S, r0, r1, out):
    k = P.shape[1]
    for i in range(r0, r1):
        for z in range(indptr[i], indptr[i + 1]):
            j = indices[z]
            acc = 0.0
            for c in range(k):
                acc += P[i, c] * Q[j, c] + R[i, c] * S[j, c]
            out[z] = acc


@njit(**_PAR)
def _pattern_par(indptr, indices, P, Q, R, S, out):
    n = len(indptr) - 1
    for b in prange((n + CHUNK - 1) // CHUNK):
        _pattern_rows(indptr, indices, P, Q, R, S, b * CHUNK, min(n, (b + 1) * CHUNK), out)


@njit(**_OPTS)
def _pattern_ser(indptr, indices, P, Q, R, S, out):
    n = len(indptr) - 1
    for b in range((n + CHUNK - 1) // CHUNK):
        _pattern_rows(indptr, indices, P, Q, R, S, b * CHUNK, min(n, (b + 1) * CHUNK), out)


def pattern_dots(indptr, indices, P, Q, R, S) -> np.ndarray:
    """``g_z = P[i] . Q[j] + R[i] . S[j]`` for every stored entry ``z`` (row i, column j) of a
    CSR pattern; P, R (n, k) and Q, S (m, k) float64. Returns (nnz,)."""
    P, Q, R, S = (np.ascontiguousarray(a, dtype=np.float64) for a in (P, Q, R, S))
    out = np.empty(int(indptr[-1]))
    if use_threads():
        _pattern_par(indptr, indices, P, Q, R, S, out)
    else:
        _pattern_ser(indptr, indices, P, Q, R, S, out)
    return out


@njit(**_OPTS)
def _spgemm_rows(ap, ai, ad, bp, bi, bd, cp, ci, ncols, r0, r1, out):
    marker = np.full(ncols, -1, dtype=np.int64)
    for i in range(r0, r1):
        for q in range(cp[i], cp[i + 1]):
            marker[ci[q]] = q
            out[q] = 0.0
        for za in range(ap[i], ap[i + 1]):
            a = ad[za]
            s = ai[za]
            for zb in range(bp[s], bp[s + 1]):
                out[marker[bi[zb]]] += a * bd[zb]
        for q in range(cp[i], cp[i + 1]):
            marker[ci[q]] = -1


@njit(**_PAR)
def _spgemm_par(ap, ai, ad, bp, bi, bd, cp, ci, ncols, out):
    n = len(cp) - 1
    for b in prange((n + CHUNK - 1) // CHUNK):
        _spgemm_rows(ap, ai, ad, bp, bi, bd, cp, ci, ncols, b * CHUNK,
                     min(n, (b + 1) * CHUNK), out)


@njit(**_OPTS)
def _spgemm_ser(ap, ai, ad, bp, bi, bd, cp, ci, ncols, out):
    n = len(cp) - 1
    for b in range((n + CHUNK - 1) // CHUNK):
        _spgemm_rows(ap, ai, ad, bp, bi, bd, cp, ci, ncols, b * CHUNK,
                     min(n, (b + 1) * CHUNK), out)


def spgemm_fixed(ap, ai, ad, bp, bi, bd, cp, ci, ncols) -> np.ndarray:
    """The stored values of ``C = A @ B`` on C's known pattern (``cp``, ``ci``: CSR, which must
    contain every product's position; e.g. the product of the patterns). A, B in CSR arrays;
    the terms of each entry are added in A's then B's storage order. Returns (nnz(C),)."""
    out = np.empty(int(cp[-1]))
    if use_threads():
        _spgemm_par(ap, ai, ad, bp, bi, bd, cp, ci, int(ncols), out)
    else:
        _spgemm_ser(ap, ai, ad, bp, bi, bd, cp, ci, int(ncols), out)
    return out


@njit(**_OPTS)
def _rowdot_rows(gp, gi, yp, yi, yd, Z, r0, r1, out):
    for i in range(r0, r1):
        for z in range(gp[i], gp[i + 1]):
            c = gi[z]
            acc = 0.0
            for y in range(yp[i], yp[i + 1]):
                acc += yd[y] * Z[c, yi[y]]
            out[z] = acc


@njit(**_PAR)
def _rowdot_par(gp, gi, yp, yi, yd, Z, out):
    n = len(gp) - 1
    for b in prange((n + CHUNK - 1) // CHUNK):
        _rowdot_rows(gp, gi, yp, yi, yd, Z, b * CHUNK, min(n, (b + 1) * CHUNK), out)


@njit(**_OPTS)
def _rowdot_ser(gp, gi, yp, yi, yd, Z, out):
    n = len(gp) - 1
    for b in range((n + CHUNK - 1) // CHUNK):
        _rowdot_rows(gp, gi, yp, yi, yd, Z, b * CHUNK, min(n, (b + 1) * CHUNK), out)


def pattern_rowdot(gp, gi, yp, yi, yd, Z) -> np.ndarray:
    """``g_z = sum_l Y[i, l] Z[j, l]`` for every stored entry ``z = (i, j)`` of the pattern
    (``gp``, ``gi``), Y in CSR (``yp``, ``yi``, ``yd``), Z dense (m, m): the entries of
    ``Y Z^T`` on the pattern (for a symmetric Z, of ``Y Z``). Returns (nnz,)."""
    Z = np.ascontiguousarray(Z, dtype=np.float64)
    out = np.empty(int(gp[-1]))
    if use_threads():
        _rowdot_par(gp, gi, yp, yi, yd, Z, out)
    else:
        _rowdot_ser(gp, gi, yp, yi, yd, Z, out)
    return out


@njit(**_OPTS)
def _sym_outer_rows(W, BT, WT, B, r0, r1, Z):
    m = Z.shape[1]
    k = W.shape[1]
    for i in range(r0, r1):
        for j in range(m):
            Z[i, j] = 0.0
        for c in range(k):
            w = W[i, c]
            b = B[i, c]
            for j in range(m):
                Z[i, j] += w * BT[c, j] + b * WT[c, j]


@njit(**_PAR)
def _sym_outer_par(W, BT, WT, B, Z):
    m = Z.shape[0]
    for r in prange((m + 31) // 32):
        _sym_outer_rows(W, BT, WT, B, r * 32, min(m, (r + 1) * 32), Z)


@njit(**_OPTS)
def _sym_outer_ser(W, BT, WT, B, Z):
    m = Z.shape[0]
    for r in range((m + 31) // 32):
        _sym_outer_rows(W, BT, WT, B, r * 32, min(m, (r + 1) * 32), Z)


def sym_outer(W, B) -> np.ndarray:
    """``Z = W B^T + B W^T`` (m, m) for W, B (m, k), without BLAS (the same bits for any
    thread count; a BLAS product's threads stalled on a busy machine: 30 ms for 404 x 135)."""
    W = np.ascontiguousarray(W, dtype=np.float64)
    B = np.ascontiguousarray(B, dtype=np.float64)
    BT = np.ascontiguousarray(B.T)
    WT = np.ascontiguousarray(W.T)
    Z = np.empty((W.shape[0], W.shape[0]))
    if use_threads():
        _sym_outer_par(W, BT, WT, B, Z)
    else:
        _sym_outer_ser(W, BT, WT, B, Z)
    return Z
