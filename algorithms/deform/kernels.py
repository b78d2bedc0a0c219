"""Compiled (Numba) kernels of the local-global ARAP core and of cubic stylization's local step.

Importing this module imports :mod:`numba`; callers import it lazily through
:func:`algorithms.deform.arap.compiled_kernels`, which falls back to the NumPy code when Numba is
missing or switched off. Every kernel is ``@njit(cache=True)`` with ``fastmath`` off (IEEE
arithmetic: no reassociation, no fused multiply-add contraction) and runs on one thread.

3x3 orthogonal Procrustes (:func:`procrustes_batch`). One-sided (Hestenes) Jacobi SVD of ``S``:
plane rotations ``V`` on the right make the columns of ``B = S V`` mutually orthogonal (cyclic
sweeps over the column pairs (1,2), (1,3), (2,3); a pair is rotated when
``(b_p . b_q)^2 > JACOBI_TOL^2 |b_p|^2 |b_q|^2``; the sweeps stop after one that rotated
nothing; quadratic convergence, 4-5 sweeps usually), so ``S = B V^T`` with
``B = [sigma_1 u_1, sigma_2 u_2, s_3 u_3]`` after sorting the columns by length. Then

* ``u_1 = b_1 / |b_1|`` (``v_1`` when ``S = 0``),
* ``u_2`` = ``b_2`` orthogonalized against ``u_1`` twice (classical Gram-Schmidt with
  re-orthogonalization: orthonormal to round-off even when ``b_2`` is tiny); when ``b_2`` vanishes
  (rank <= 1) a unit vector orthogonal to ``u_1`` made from ``v_2`` or ``v_3``,
* ``u_3 = u_1 x u_2`` (so ``det U = +1``; ``b_3 = s_3 u_3`` with a *signed* ``s_3``; rank 2 needs
  no special case),
* ``v_3`` is negated when ``det V = -1``,

and ``R = V U^T``. This is the thesis's det fix (Eq. 5.8): ``tr(R S) = sigma_1 + sigma_2 + s_3
det V = sigma_1 + sigma_2 + sign(det S) sigma_3``, the largest value a proper rotation reaches.
It equals the SVD-based NumPy code (:func:`algorithms.deform.arap.procrustes_rotations_numpy`)
to round-off where the maximizer is unique (``sigma_2 > 0`` and, when ``det S < 0``,
``sigma_2 > sigma_3``) and is always a rotation (orthonormal, ``det = +1`` to round-off); ``S = 0``
gives the identity, like NumPy; an ``S`` with a NaN or an infinity gives NaNs (NumPy's SVD
raises there). Each ``S`` is first scaled by a power of two (exact) so that its
largest entry is in [0.5, 1): no underflow or overflow in the squared norms.

Speed. The Jacobi sweeps run on blocks of ``BLOCK`` matrices stored lane by lane (structure of
arrays), so the compiler turns the square roots and divisions into SIMD instructions; a lane
whose pair needs no rotation gets the exact identity rotation (``c = 1, s = 0``), so every
matrix goes through exactly the operations it would go through alone: the result of one matrix
does not depend on which others share its block (the same input gives the same bits).

Cubic local step (:func:`admm_cube_local_step`): the per-vertex scaled ADMM of
:func:`algorithms.deform.cubic.admm_local_step` for a diagonal style matrix (cube, per-axis
lambda), compiled. It runs in waves like the NumPy code: wave ``k`` does ADMM iteration ``k`` of
every vertex that has not stopped yet (their R-steps as blocked Procrustes, then each vertex's
z-step, u-step, residuals, rho adaptation and stopping test), so each vertex's sequence of
updates is exactly the one of the NumPy code (see the docstring of :mod:`algorithms.deform.cubic`).

Local frames (``frames``, §5.4): the same kernel with ``z``, ``u`` in vertex ``i``'s frame ``Q_i``;
the R-step target becomes ``Q_i (z - u)`` and the z-step shrinks ``Q_i^T R n_i + u``. ``frames``
is ``None`` or an (n, 3, 3) array. Numba compiles one specialization per case and prunes the
``frames is None`` branches at compile time, so the run without frames is the same machine code
(and the same bits) as before frames existed.
"""

from __future__ import annotations

import math

import numpy as np
from .._numba import njit, prange

from ..compiled import use_threads

__all__ = [
    "BLOCK",
    "JACOBI_TOL",
    "JACOBI_MAX_SWEEPS",
    "procrustes_batch",
    "admm_cube_local_step",
    "arap_energy_terms",
    "rotate_normals",
    "frame_normals",
    "displacement_maxima",
    "block_covariances",
    "cube_after_solve",
    "block_rhs",
    "quadratic_form",
    "cube_l1_energy",
    "CHUNK",
]

JACOBI_TOL = 1e-15
"""A column pair counts as orthogonal when ``|b_p . b_q| <= JACOBI_TOL |b_p| |b_q|``."""
JACOBI_MAX_SWEEPS = 30
"""Safety cap on Jacobi sweeps (4-6 are usual; the cap is never reached on finite input)."""
BLOCK = 128
"""Matrices per Jacobi block (the block's 18 lanes arrays, 18 KiB, stay in the L1 cache)."""

CHUNK = 512
"""Items (vertices, cells) per work unit of the row-wise kernels; fixed, so the split of the
work does not depend on the number of threads."""

_TOL2 = JACOBI_TOL * JACOBI_TOL
_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)
_PAR = dict(_OPTS, parallel=True)


MIN_PARALLEL = 4
"""Work units (chunks or Jacobi blocks) below which a kernel runs serially even with threads: a
parallel launch wakes the other threads (tens of microseconds, much more on a busy machine)."""


def _par(n: int, unit: int) -> bool:
    """Run ``n`` items in units of ``unit`` on threads?"""
    return n > (MIN_PARALLEL - 1) * unit and use_threads()


# ------------------------------------------------------------------------------ Procrustes
@njit(**_OPTS)
def _load_lane(A, V, l, s00, s01, s02, s10, s11, s12, s20, s21, s22):
    """Store S (scaled by a power of two) column by column into lane l of A; V[:, l] = I."""
    m = max(abs(s00), abs(s01), abs(s02), abs(s10), abs(s11), abs(s12), abs(s20), abs(s21),
            abs(s22))
    f = 1.0
    g = 1.0
    if m > 0.0 and m < math.inf:
        # 2**k with k up to 1074 (subnormal m) overflows as one factor: apply it as two
        k = -math.frexp(m)[1]
        k1 = min(k, 1000)
        f = math.ldexp(1.0, k1)
        g = math.ldexp(1.0, k - k1)
    A[0, l], A[1, l], A[2, l] = s00 * f * g, s10 * f * g, s20 * f * g
    A[3, l], A[4, l], A[5, l] = s01 * f * g, s11 * f * g, s21 * f * g
    A[6, l], A[7, l], A[8, l] = s02 * f * g, s12 * f * g, s22 * f * g
    V[0, l], V[1, l], V[2, l] = 1.0, 0.0, 0.0
    V[3, l], V[4, l], V[5, l] = 0.0, 1.0, 0.0
    V[6, l], V[7, l], V[8, l] = 0.0, 0.0, 1.0


@njit(**_OPTS)
def _pair_block(A, V, p, q, nl):
    """One Jacobi rotation of columns p, q (rows p..p+2, q..q+2) in lanes 0..nl-1.

    Returns 1 when some lane was rotated, else 0.
    """
    ap0, ap1, ap2 = A[p], A[p + 1], A[p + 2]
    aq0, aq1, aq2 = A[q], A[q + 1], A[q + 2]
    vp0, vp1, vp2 = V[p], V[p + 1], V[p + 2]
    vq0, vq1, vq2 = V[q], V[q + 1], V[q + 2]
    anyrot = 0
    for l in range(nl):
        x0, x1, x2 = ap0[l], ap1[l], ap2[l]
        y0, y1, y2 = aq0[l], aq1[l], aq2[l]
        alpha = x0 * x0 + x1 * x1 + x2 * x2
        beta = y0 * y0 + y1 * y1 + y2 * y2
        gamma = x0 * y0 + x1 * y1 + x2 * y2
        rot = gamma * gamma > _TOL2 * (alpha * beta)
        zeta = (beta - alpha) / (2.0 * gamma)
        t = 1.0 / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
        t = -t if zeta < 0.0 else t
        t = t if rot else 0.0
        c = 1.0 / math.sqrt(1.0 + t * t)
        s = c * t
        ap0[l], ap1[l], ap2[l] = c * x0 - s * y0, c * x1 - s * y1, c * x2 - s * y2
        aq0[l], aq1[l], aq2[l] = s * x0 + c * y0, s * x1 + c * y1, s * x2 + c * y2
        w0, w1, w2 = vp0[l], vp1[l], vp2[l]
        z0, z1, z2 = vq0[l], vq1[l], vq2[l]
        vp0[l], vp1[l], vp2[l] = c * w0 - s * z0, c * w1 - s * z1, c * w2 - s * z2
        vq0[l], vq1[l], vq2[l] = s * w0 + c * z0, s * w1 + c * z1, s * w2 + c * z2
        anyrot |= rot
    return anyrot


@njit(**_OPTS)
def _sweeps_block(A, V, nl):
    """Cyclic Jacobi sweeps on lanes 0..nl-1 until a sweep rotates nothing."""
    for _ in range(JACOBI_MAX_SWEEPS):
        f = 0
        for k in range(3):  # pairs (1, 2), (1, 3), (2, 3): rows 0/3, 0/6, 3/6
            f |= _pair_block(A, V, (0, 0, 3)[k], (3, 6, 6)[k], nl)
        if f == 0:
            break


@njit(**_OPTS)
def _finish_lane(A, V, l):
    """The Procrustes rotation of lane l from its converged B = S V and V (row-major 9-tuple)."""
    a0, a1, a2 = A[0, l], A[1, l], A[2, l]
    b0, b1, b2 = A[3, l], A[4, l], A[5, l]
    c0, c1, c2 = A[6, l], A[7, l], A[8, l]
    va0, va1, va2 = V[0, l], V[1, l], V[2, l]
    vb0, vb1, vb2 = V[3, l], V[4, l], V[5, l]
    vc0, vc1, vc2 = V[6, l], V[7, l], V[8, l]
    na = a0 * a0 + a1 * a1 + a2 * a2
    nb = b0 * b0 + b1 * b1 + b2 * b2
    nc = c0 * c0 + c1 * c1 + c2 * c2
    if not (na + nb + nc < math.inf):  # S had a NaN or an infinity: no rotation to give
        nan = math.nan
        return nan, nan, nan, nan, nan, nan, nan, nan, nan
    # stable sort of the columns by length, longest first (ties keep their order)
    if nb > na:
        a0, a1, a2, b0, b1, b2 = b0, b1, b2, a0, a1, a2
        va0, va1, va2, vb0, vb1, vb2 = vb0, vb1, vb2, va0, va1, va2
        na, nb = nb, na
    if nc > nb:
        b0, b1, b2, c0, c1, c2 = c0, c1, c2, b0, b1, b2
        vb0, vb1, vb2, vc0, vc1, vc2 = vc0, vc1, vc2, vb0, vb1, vb2
        nb, nc = nc, nb
    if nb > na:
        a0, a1, a2, b0, b1, b2 = b0, b1, b2, a0, a1, a2
        va0, va1, va2, vb0, vb1, vb2 = vb0, vb1, vb2, va0, va1, va2
        na, nb = nb, na
    # u1
    sig1 = math.sqrt(na)
    if sig1 > 0.0:
        u10, u11, u12 = a0 / sig1, a1 / sig1, a2 / sig1
    else:
        u10, u11, u12 = va0, va1, va2
    # u2: the second column orthogonalized against u1, twice
    d = u10 * b0 + u11 * b1 + u12 * b2
    r0, r1, r2 = b0 - d * u10, b1 - d * u11, b2 - d * u12
    d = u10 * r0 + u11 * r1 + u12 * r2
    r0, r1, r2 = r0 - d * u10, r1 - d * u11, r2 - d * u12
    nr = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if not (nr > 1e-30 * sig1 and nr > 1e-150):
        # rank <= 1: any unit vector orthogonal to u1; from v2 or v3, whichever is less parallel
        d2 = u10 * vb0 + u11 * vb1 + u12 * vb2
        d3 = u10 * vc0 + u11 * vc1 + u12 * vc2
        if abs(d2) <= abs(d3):
            r0, r1, r2 = vb0 - d2 * u10, vb1 - d2 * u11, vb2 - d2 * u12
        else:
            r0, r1, r2 = vc0 - d3 * u10, vc1 - d3 * u11, vc2 - d3 * u12
        d = u10 * r0 + u11 * r1 + u12 * r2
        r0, r1, r2 = r0 - d * u10, r1 - d * u11, r2 - d * u12
        nr = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    u20, u21, u22 = r0 / nr, r1 / nr, r2 / nr
    # u3 = u1 x u2 (det U = +1)
    u30 = u11 * u22 - u12 * u21
    u31 = u12 * u20 - u10 * u22
    u32 = u10 * u21 - u11 * u20
    # det V = v1 . (v2 x v3) = +-1; make V proper
    detv = (va0 * (vb1 * vc2 - vb2 * vc1) + va1 * (vb2 * vc0 - vb0 * vc2)
            + va2 * (vb0 * vc1 - vb1 * vc0))
    if detv < 0.0:
        vc0, vc1, vc2 = -vc0, -vc1, -vc2
    # R = V U^T = sum_k v_k u_k^T
    return (va0 * u10 + vb0 * u20 + vc0 * u30, va0 * u11 + vb0 * u21 + vc0 * u31,
            va0 * u12 + vb0 * u22 + vc0 * u32,
            va1 * u10 + vb1 * u20 + vc1 * u30, va1 * u11 + vb1 * u21 + vc1 * u31,
            va1 * u12 + vb1 * u22 + vc1 * u32,
            va2 * u10 + vb2 * u20 + vc2 * u30, va2 * u11 + vb2 * u21 + vc2 * u31,
            va2 * u12 + vb2 * u22 + vc2 * u32)


@njit(**_OPTS)
def _store(R, i, r):
    R[i, 0, 0], R[i, 0, 1], R[i, 0, 2] = r[0], r[1], r[2]
    R[i, 1, 0], R[i, 1, 1], R[i, 1, 2] = r[3], r[4], r[5]
    R[i, 2, 0], R[i, 2, 1], R[i, 2, 2] = r[6], r[7], r[8]


@njit(**_OPTS)
def _procrustes_block(S, idx, b0, nl, R):
    """R[i] = Procrustes(S[i]) for the nl indices idx[b0:b0 + nl] (one Jacobi block)."""
    A = np.empty((9, BLOCK))
    V = np.empty((9, BLOCK))
    for l in range(nl):
        i = idx[b0 + l]
        _load_lane(A, V, l, S[i, 0, 0], S[i, 0, 1], S[i, 0, 2], S[i, 1, 0], S[i, 1, 1],
                   S[i, 1, 2], S[i, 2, 0], S[i, 2, 1], S[i, 2, 2])
    _sweeps_block(A, V, nl)
    for l in range(nl):
        _store(R, idx[b0 + l], _finish_lane(A, V, l))


@njit(**_PAR)
def _procrustes_par(S, idx, R):
    m = idx.shape[0]
    for b in prange((m + BLOCK - 1) // BLOCK):
        _procrustes_block(S, idx, b * BLOCK, min(BLOCK, m - b * BLOCK), R)


@njit(**_OPTS)
def _procrustes_ser(S, idx, R):
    m = idx.shape[0]
    for b in range((m + BLOCK - 1) // BLOCK):
        _procrustes_block(S, idx, b * BLOCK, min(BLOCK, m - b * BLOCK), R)


def _procrustes_indices(S, idx, R, par):
    """R[i] = Procrustes(S[i]) for i in idx, blocks on threads when ``par`` (and there are
    at least ``MIN_PARALLEL`` blocks). Python: a parallel kernel is only ever called from
    Python (:mod:`algorithms.compiled`, "cached kernels")."""
    if par and idx.shape[0] > (MIN_PARALLEL - 1) * BLOCK:
        _procrustes_par(S, idx, R)
    else:
        _procrustes_ser(S, idx, R)


def procrustes_batch(S, R):
    """``R[i]`` = the rotation maximizing ``tr(R[i] S[i])``; S, R: (n, 3, 3) float64 (R written).
    Blocks of matrices run on Numba's threads (the same bits for any thread count)."""
    _procrustes_indices(S, np.arange(S.shape[0]), R, _par(S.shape[0], BLOCK))


# ------------------------------------------------------------------------------ cubic local step
@njit(**_OPTS)
def _shrink(v, k):
    """Soft thresholding of one number (thesis Eq. 5.9)."""
    if v > k:
        return v - k
    if v < -k:
        return v + k
    return 0.0


@njit(**_OPTS)
def _admm_block(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters, frames,
                active, b0, nl, done):
    """One ADMM iteration of the vertices active[b0:b0 + nl]; done[b0 + l] = its stopping test."""
    A = np.empty((9, BLOCK))
    V = np.empty((9, BLOCK))
    d0, d1, d2 = diag[0], diag[1], diag[2]
    # R-step: Procrustes of S + rho n (z - u)^T for the block's vertices
    for l in range(nl):
        i = active[b0 + l]
        rh = rho[i]
        w0, w1, w2 = rh * normals[i, 0], rh * normals[i, 1], rh * normals[i, 2]
        y0, y1, y2 = z[i, 0] - u[i, 0], z[i, 1] - u[i, 1], z[i, 2] - u[i, 2]
        if frames is not None:  # the target Q_i (z - u) in world coordinates
            y0, y1, y2 = (frames[i, 0, 0] * y0 + frames[i, 0, 1] * y1
                          + frames[i, 0, 2] * y2,
                          frames[i, 1, 0] * y0 + frames[i, 1, 1] * y1
                          + frames[i, 1, 2] * y2,
                          frames[i, 2, 0] * y0 + frames[i, 2, 1] * y1
                          + frames[i, 2, 2] * y2)
        _load_lane(A, V, l,
                   S[i, 0, 0] + w0 * y0, S[i, 0, 1] + w0 * y1, S[i, 0, 2] + w0 * y2,
                   S[i, 1, 0] + w1 * y0, S[i, 1, 1] + w1 * y1, S[i, 1, 2] + w1 * y2,
                   S[i, 2, 0] + w2 * y0, S[i, 2, 1] + w2 * y1, S[i, 2, 2] + w2 * y2)
    _sweeps_block(A, V, nl)
    for l in range(nl):
        i = active[b0 + l]
        r = _finish_lane(A, V, l)
        _store(R, i, r)
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        rn0 = r[0] * n0 + r[1] * n1 + r[2] * n2
        rn1 = r[3] * n0 + r[4] * n1 + r[5] * n2
        rn2 = r[6] * n0 + r[7] * n1 + r[8] * n2
        if frames is not None:  # R n in the local frame: Q_i^T R n
            rn0, rn1, rn2 = (frames[i, 0, 0] * rn0 + frames[i, 1, 0] * rn1
                             + frames[i, 2, 0] * rn2,
                             frames[i, 0, 1] * rn0 + frames[i, 1, 1] * rn1
                             + frames[i, 2, 1] * rn2,
                             frames[i, 0, 2] * rn0 + frames[i, 1, 2] * rn1
                             + frames[i, 2, 2] * rn2)
        z0, z1, z2 = z[i, 0], z[i, 1], z[i, 2]
        u0, u1, u2 = u[i, 0], u[i, 1], u[i, 2]
        rh = rho[i]
        # z-step: shrinkage with thresholds lam a / rho * diag
        kap = lam_a[i] / rh
        x0 = _shrink(rn0 + u0, kap * d0)
        x1 = _shrink(rn1 + u1, kap * d1)
        x2 = _shrink(rn2 + u2, kap * d2)
        # u-step and residuals
        u0, u1, u2 = u0 + rn0 - x0, u1 + rn1 - x1, u2 + rn2 - x2
        p0, p1, p2 = rn0 - x0, rn1 - x1, rn2 - x2
        res_p = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        q0, q1, q2 = x0 - z0, x1 - z1, x2 - z2
        res_d = rh * math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        eps_pri = e_abs + eps_rel * max(math.sqrt(rn0 * rn0 + rn1 * rn1 + rn2 * rn2),
                                        math.sqrt(x0 * x0 + x1 * x1 + x2 * x2))
        g0, g1, g2 = rh * u0, rh * u1, rh * u2
        eps_dual = e_abs + eps_rel * math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        done[b0 + l] = (res_p < eps_pri) and (res_d < eps_dual)
        if res_p > mu * res_d:
            rh = rh * tau
            u0, u1, u2 = u0 / tau, u1 / tau, u2 / tau
        elif res_d > mu * res_p:
            rh = rh / tau
            u0, u1, u2 = u0 * tau, u1 * tau, u2 * tau
        z[i, 0], z[i, 1], z[i, 2] = x0, x1, x2
        u[i, 0], u[i, 1], u[i, 2] = u0, u1, u2
        rho[i] = rh
        iters[i] += 1


@njit(**_PAR)
def _admm_wave_par(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters,
                   frames, active, m, done):
    for b in prange((m + BLOCK - 1) // BLOCK):
        _admm_block(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters,
                    frames, active, b * BLOCK, min(BLOCK, m - b * BLOCK), done)


@njit(**_OPTS)
def _admm_wave_ser(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters,
                   frames, active, m, done):
    for b in range((m + BLOCK - 1) // BLOCK):
        _admm_block(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters,
                    frames, active, b * BLOCK, min(BLOCK, m - b * BLOCK), done)


@njit(**_OPTS)
def _admm_split(use, iters, plain, active):
    """Zero ``iters``; the vertices not running ADMM into ``plain``, the others into
    ``active`` (in vertex order); returns their counts."""
    n_plain = 0
    n_active = 0
    for i in range(use.shape[0]):
        iters[i] = 0
        if use[i]:
            active[n_active] = i
            n_active += 1
        else:
            plain[n_plain] = i
            n_plain += 1
    return n_plain, n_active


@njit(**_OPTS)
def _admm_keep_active(active, done, n_active):
    """Keep the vertices that did not stop, in their order; returns how many."""
    n_next = 0
    for t in range(n_active):
        if not done[t]:
            active[n_next] = active[t]
            n_next += 1
    return n_next


@njit(**_OPTS)
def _admm_cube_local_step_ser(S, normals, lam_a, use, diag, z, u, rho, eps_abs, eps_rel, mu,
                              tau, max_iter, R, iters, frames):
    """The whole local step on one thread, in one compiled call (calls serial kernels only)."""
    n = S.shape[0]
    plain = np.empty(n, dtype=np.int64)
    active = np.empty(n, dtype=np.int64)
    done = np.empty(n, dtype=np.bool_)
    n_plain, n_active = _admm_split(use, iters, plain, active)
    _procrustes_ser(S, plain[:n_plain], R)
    e_abs = math.sqrt(3.0) * eps_abs
    for _ in range(max_iter):
        if n_active == 0:
            break
        _admm_wave_ser(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters,
                       frames, active, n_active, done)
        n_active = _admm_keep_active(active, done, n_active)


def _admm_cube_local_step(S, normals, lam_a, use, diag, z, u, rho, eps_abs, eps_rel, mu, tau,
                          max_iter, R, iters, frames, par):
    """The local step; with ``par`` the waves are driven from Python (a parallel kernel is only
    ever called from Python: :mod:`algorithms.compiled`, "cached kernels"), the same
    operations in the same order as :func:`_admm_cube_local_step_ser`."""
    if not par:
        _admm_cube_local_step_ser(S, normals, lam_a, use, diag, z, u, rho, eps_abs, eps_rel, mu,
                                  tau, max_iter, R, iters, frames)
        return
    n = S.shape[0]
    plain = np.empty(n, dtype=np.int64)
    active = np.empty(n, dtype=np.int64)
    done = np.empty(n, dtype=np.bool_)
    n_plain, n_active = _admm_split(use, iters, plain, active)
    _procrustes_indices(S, plain[:n_plain], R, par)
    e_abs = math.sqrt(3.0) * eps_abs
    for _ in range(int(max_iter)):
        if n_active == 0:
            break
        wave = _admm_wave_par if n_active > (MIN_PARALLEL - 1) * BLOCK else _admm_wave_ser
        wave(S, normals, lam_a, diag, z, u, rho, e_abs, eps_rel, mu, tau, R, iters, frames,
             active, n_active, done)             # late waves (a few vertices): serial
        n_active = _admm_keep_active(active, done, n_active)


def admm_cube_local_step(S, normals, lam_a, use, diag, z, u, rho, eps_abs, eps_rel, mu, tau,
                         max_iter, R, iters, frames=None):
    """Cubic stylization's local step for a diagonal style matrix, all vertices.

    Parameters
    ----------
    S : (n, 3, 3) covariances. normals : (n, 3). lam_a : (n,) ``lam_i a_i``.
    use : (n,) bool, vertices that run ADMM (the others get the plain Procrustes rotation).
    diag : (3,) non-negative diagonal of the style matrix (the per-axis thresholds' factors).
    z, u : (n, 3), rho : (n,) ADMM state, read and updated in place (warm start); in the local
        frames when ``frames`` is given.
    eps_abs, eps_rel, mu, tau : float; max_iter : int.
    R : (n, 3, 3) output rotations. iters : (n,) int64 output, ADMM iterations per vertex.
    frames : None or (n, 3, 3) rotations, columns = vertex i's cube axes (the L1 term is
        ``||diag Q_i^T R_i n_i||_1``).

    Each wave's blocks of vertices run on Numba's threads (the same bits for any thread count:
    a vertex's updates do not depend on its block).
    """
    _admm_cube_local_step(S, normals, lam_a, use, diag, z, u, rho, eps_abs, eps_rel, mu, tau,
                          max_iter, R, iters, frames, _par(S.shape[0], BLOCK))


# ------------------------------------------------------------------------------ small helpers
@njit(**_OPTS)
def rotate_normals(R, normals, out):
    """``out[i] = R[i] @ normals[i]`` for (n, 3, 3) R and (n, 3) normals, out."""
    for i in range(R.shape[0]):
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        for a in range(3):
            out[i, a] = R[i, a, 0] * n0 + R[i, a, 1] * n1 + R[i, a, 2] * n2


@njit(**_OPTS)
def frame_normals(R, normals, frames, out):
    """``out[i] = frames[i]^T @ R[i] @ normals[i]`` (R n in vertex i's local frame); (n, 3, 3)
    R and frames, (n, 3) normals and out."""
    for i in range(R.shape[0]):
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        r0 = R[i, 0, 0] * n0 + R[i, 0, 1] * n1 + R[i, 0, 2] * n2
        r1 = R[i, 1, 0] * n0 + R[i, 1, 1] * n1 + R[i, 1, 2] * n2
        r2 = R[i, 2, 0] * n0 + R[i, 2, 1] * n1 + R[i, 2, 2] * n2
        for a in range(3):
            out[i, a] = frames[i, 0, a] * r0 + frames[i, 1, a] * r1 + frames[i, 2, a] * r2


@njit(**_OPTS)
def _energy_terms_rows(R, C, S, lo, hi, quad, lin):
    for i in range(lo, hi):
        q = 0.0
        li = 0.0
        for a in range(3):
            for b in range(3):
                rc = R[i, a, 0] * C[i, 0, b] + R[i, a, 1] * C[i, 1, b] + R[i, a, 2] * C[i, 2, b]
                q += rc * R[i, a, b]
                li += R[i, a, b] * S[i, b, a]
        quad[i] = q
        lin[i] = li


@njit(**_PAR)
def _energy_terms_par(R, C, S, quad, lin):
    n = R.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        _energy_terms_rows(R, C, S, c * CHUNK, min(n, (c + 1) * CHUNK), quad, lin)


@njit(**_OPTS)
def _energy_terms_ser(R, C, S, quad, lin):
    n = R.shape[0]
    for c in range((n + CHUNK - 1) // CHUNK):
        _energy_terms_rows(R, C, S, c * CHUNK, min(n, (c + 1) * CHUNK), quad, lin)


@njit(**_OPTS)
def _sum_in_order(x):
    """``sum(x)`` added up in index order (whatever the thread count that filled ``x``)."""
    t = 0.0
    for i in range(x.shape[0]):
        t += x[i]
    return t


def _arap_energy_terms(R, C, S, par):
    if not par:
        return _arap_energy_terms_ser(R, C, S)
    n = R.shape[0]
    quad = np.empty(n)
    lin = np.empty(n)
    _energy_terms_par(R, C, S, quad, lin)
    return _sum_in_order(quad), _sum_in_order(lin)


@njit(**_OPTS)
def _arap_energy_terms_ser(R, C, S):
    n = R.shape[0]
    quad = np.empty(n)
    lin = np.empty(n)
    _energy_terms_ser(R, C, S, quad, lin)
    tq = 0.0
    tl = 0.0
    for i in range(n):  # one order, whatever the thread count
        tq += quad[i]
        tl += lin[i]
    return tq, tl


def arap_energy_terms(R, C, S):
    """``(sum_i tr(R_i C_i R_i^T), sum_i tr(R_i S_i))`` for (n, 3, 3) arrays R, C, S (per-cell
    terms on threads, added up in cell order)."""
    return _arap_energy_terms(R, C, S, _par(R.shape[0], CHUNK))


@njit(**_OPTS)
def _quadratic_rows(indptr, indices, data, U, lo, hi, out):
    for i in range(lo, hi):
        u0, u1, u2 = U[i, 0], U[i, 1], U[i, 2]
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            acc += data[k] * (u0 * U[j, 0] + u1 * U[j, 1] + u2 * U[j, 2])
        out[i] = acc


@njit(**_PAR)
def _quadratic_par(indptr, indices, data, U, out):
    n = U.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        _quadratic_rows(indptr, indices, data, U, c * CHUNK, min(n, (c + 1) * CHUNK), out)


@njit(**_OPTS)
def _quadratic_ser(indptr, indices, data, U, out):
    n = U.shape[0]
    for c in range((n + CHUNK - 1) // CHUNK):
        _quadratic_rows(indptr, indices, data, U, c * CHUNK, min(n, (c + 1) * CHUNK), out)


def _quadratic_form(indptr, indices, data, U, par):
    if not par:
        return _quadratic_form_ser(indptr, indices, data, U)
    out = np.empty(U.shape[0])
    _quadratic_par(indptr, indices, data, U, out)
    return _sum_in_order(out)


@njit(**_OPTS)
def _quadratic_form_ser(indptr, indices, data, U):
    out = np.empty(U.shape[0])
    _quadratic_ser(indptr, indices, data, U, out)
    return _sum_in_order(out)


def quadratic_form(indptr, indices, data, U):
    """``tr(U^T A U)`` for A in CSR (``indptr``, ``indices``, ``data``) and (n, 3) U (per-row
    terms on threads, added up in row order)."""
    return _quadratic_form(indptr, indices, data, U, _par(U.shape[0], CHUNK))


@njit(**_OPTS)
def _cube_l1_rows(R, normals, frames, diag, lam_a, lo, hi, out):
    d0, d1, d2 = diag[0], diag[1], diag[2]
    for i in range(lo, hi):
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        r0 = R[i, 0, 0] * n0 + R[i, 0, 1] * n1 + R[i, 0, 2] * n2
        r1 = R[i, 1, 0] * n0 + R[i, 1, 1] * n1 + R[i, 1, 2] * n2
        r2 = R[i, 2, 0] * n0 + R[i, 2, 1] * n1 + R[i, 2, 2] * n2
        if frames is not None:
            r0, r1, r2 = (frames[i, 0, 0] * r0 + frames[i, 1, 0] * r1 + frames[i, 2, 0] * r2,
                          frames[i, 0, 1] * r0 + frames[i, 1, 1] * r1 + frames[i, 2, 1] * r2,
                          frames[i, 0, 2] * r0 + frames[i, 1, 2] * r1 + frames[i, 2, 2] * r2)
        out[i] = lam_a[i] * (abs(r0 * d0) + abs(r1 * d1) + abs(r2 * d2))


@njit(**_PAR)
def _cube_l1_par(R, normals, frames, diag, lam_a, out):
    n = R.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        _cube_l1_rows(R, normals, frames, diag, lam_a, c * CHUNK, min(n, (c + 1) * CHUNK), out)


@njit(**_OPTS)
def _cube_l1_ser(R, normals, frames, diag, lam_a, out):
    n = R.shape[0]
    for c in range((n + CHUNK - 1) // CHUNK):
        _cube_l1_rows(R, normals, frames, diag, lam_a, c * CHUNK, min(n, (c + 1) * CHUNK), out)


def _cube_l1_energy(R, normals, frames, diag, lam_a, par):
    if not par:
        return _cube_l1_energy_ser(R, normals, frames, diag, lam_a)
    out = np.empty(R.shape[0])
    _cube_l1_par(R, normals, frames, diag, lam_a, out)
    return _sum_in_order(out)


@njit(**_OPTS)
def _cube_l1_energy_ser(R, normals, frames, diag, lam_a):
    out = np.empty(R.shape[0])
    _cube_l1_ser(R, normals, frames, diag, lam_a, out)
    return _sum_in_order(out)


def cube_l1_energy(R, normals, frames, diag, lam_a):
    """``sum_i lam_a[i] ||diag * (Q_i^T) R_i n_i||_1`` (cubic stylization's L1 term for a
    diagonal style; ``frames`` None or (n, 3, 3) Q_i); per-vertex terms on threads, added up in
    vertex order."""
    # serial: a memory-bound loop whose parallel launch cost more than it saved (20k
    # vertices: 0.075 ms on 1 thread, 0.099 ms on 2; benchmarks/cubic.py); same bits
    return _cube_l1_energy(R, normals, frames, diag, lam_a, False)


@njit(**_OPTS)
def _displacement_rows(U_new, U_old, U_rest, lo, hi, out):
    """out[0..8] = max step^2, max total^2, NaN seen, bbox of U_rest over rows lo..hi."""
    step2 = 0.0
    total2 = 0.0
    nan = False
    lo0 = lo1 = lo2 = math.inf
    hi0 = hi1 = hi2 = -math.inf
    for i in range(lo, hi):
        a0 = U_new[i, 0] - U_old[i, 0]
        a1 = U_new[i, 1] - U_old[i, 1]
        a2 = U_new[i, 2] - U_old[i, 2]
        b0 = U_new[i, 0] - U_rest[i, 0]
        b1 = U_new[i, 1] - U_rest[i, 1]
        b2 = U_new[i, 2] - U_rest[i, 2]
        sa = a0 * a0 + a1 * a1 + a2 * a2
        sb = b0 * b0 + b1 * b1 + b2 * b2
        nan |= (sa != sa) or (sb != sb)
        step2 = max(step2, sa)
        total2 = max(total2, sb)
        r0, r1, r2 = U_rest[i, 0], U_rest[i, 1], U_rest[i, 2]
        lo0, lo1, lo2 = min(lo0, r0), min(lo1, r1), min(lo2, r2)
        hi0, hi1, hi2 = max(hi0, r0), max(hi1, r1), max(hi2, r2)
    out[0], out[1], out[2] = step2, total2, 1.0 if nan else 0.0
    out[3], out[4], out[5], out[6], out[7], out[8] = lo0, lo1, lo2, hi0, hi1, hi2


@njit(**_PAR)
def _displacement_par(U_new, U_old, U_rest, parts):
    n = U_new.shape[0]
    for c in prange(parts.shape[0]):
        _displacement_rows(U_new, U_old, U_rest, c * CHUNK, min(n, (c + 1) * CHUNK), parts[c])


@njit(**_OPTS)
def _displacement_ser(U_new, U_old, U_rest, parts):
    n = U_new.shape[0]
    for c in range(parts.shape[0]):
        _displacement_rows(U_new, U_old, U_rest, c * CHUNK, min(n, (c + 1) * CHUNK), parts[c])


def _displacement_maxima(U_new, U_old, U_rest, par):
    if not par:
        return _displacement_maxima_ser(U_new, U_old, U_rest)
    n = U_new.shape[0]
    parts = np.empty(((n + CHUNK - 1) // CHUNK, 9))
    _displacement_par(U_new, U_old, U_rest, parts)
    return _combine_displacement(parts, n)


@njit(**_OPTS)
def _displacement_maxima_ser(U_new, U_old, U_rest):
    n = U_new.shape[0]
    parts = np.empty(((n + CHUNK - 1) // CHUNK, 9))
    _displacement_ser(U_new, U_old, U_rest, parts)
    return _combine_displacement(parts, n)


@njit(**_OPTS)
def _combine_displacement(parts, n):
    """(max step, max total, bbox diagonal) from the per-chunk rows of
    :func:`_displacement_rows`."""
    step2 = 0.0
    total2 = 0.0
    nan = False
    lo0 = lo1 = lo2 = math.inf
    hi0 = hi1 = hi2 = -math.inf
    for c in range(parts.shape[0]):  # maxima and minima: exact, in any order
        step2 = max(step2, parts[c, 0])
        total2 = max(total2, parts[c, 1])
        nan |= parts[c, 2] != 0.0
        lo0, lo1, lo2 = min(lo0, parts[c, 3]), min(lo1, parts[c, 4]), min(lo2, parts[c, 5])
        hi0, hi1, hi2 = max(hi0, parts[c, 6]), max(hi1, parts[c, 7]), max(hi2, parts[c, 8])
    diag = 0.0
    if n > 0:
        e0, e1, e2 = hi0 - lo0, hi1 - lo1, hi2 - lo2
        diag = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if nan:
        return math.nan, math.nan, diag
    return math.sqrt(step2), math.sqrt(total2), diag


def displacement_maxima(U_new, U_old, U_rest):
    """``(max_i |U_new_i - U_old_i|, max_i |U_new_i - U_rest_i|, |bbox diagonal of U_rest|)``
    for (n, 3) arrays (the first two NaN when any difference is NaN, like NumPy's ``max``)."""
    # serial, as cube_l1_energy (20k vertices: 0.062 ms on 1 thread, 0.085 ms on 2); exact
    return _displacement_maxima(U_new, U_old, U_rest, False)


@njit(**_OPTS)
def _covariance_rows(ptr, col, val, U, S, lo, hi):
    for i in range(lo, hi):
        s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
        for k in range(ptr[i], ptr[i + 1]):
            j = col[k]
            k0, k1, k2 = val[k, 0], val[k, 1], val[k, 2]
            x0, x1, x2 = U[j, 0], U[j, 1], U[j, 2]
            s00 += k0 * x0
            s01 += k0 * x1
            s02 += k0 * x2
            s10 += k1 * x0
            s11 += k1 * x1
            s12 += k1 * x2
            s20 += k2 * x0
            s21 += k2 * x1
            s22 += k2 * x2
        S[i, 0, 0], S[i, 0, 1], S[i, 0, 2] = s00, s01, s02
        S[i, 1, 0], S[i, 1, 1], S[i, 1, 2] = s10, s11, s12
        S[i, 2, 0], S[i, 2, 1], S[i, 2, 2] = s20, s21, s22


@njit(**_PAR)
def _covariances_par(ptr, col, val, U, S):
    n = ptr.shape[0] - 1
    for c in prange((n + CHUNK - 1) // CHUNK):
        _covariance_rows(ptr, col, val, U, S, c * CHUNK, min(n, (c + 1) * CHUNK))


@njit(**_OPTS)
def _covariances_ser(ptr, col, val, U, S):
    n = ptr.shape[0] - 1
    for c in range((n + CHUNK - 1) // CHUNK):
        _covariance_rows(ptr, col, val, U, S, c * CHUNK, min(n, (c + 1) * CHUNK))


def block_covariances(ptr, col, val, U, S):
    """``S[i, a, b] = sum_{k in ptr[i]:ptr[i+1]} val[k, a] U[col[k], b]`` (the product K U).

    ``(ptr, col, val)`` is K stored by 3x1 blocks: block k of vertex i holds
    ``K[3 i + a, col[k]] = val[k, a]``. S: (n, 3, 3) output. Chunks of cells on threads.
    """
    (_covariances_par if _par(S.shape[0], CHUNK) else _covariances_ser)(ptr, col, val, U, S)


@njit(**_OPTS)
def _cube_after_solve_rows(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old, U_rest,
                           scale, center, V_out, l1, parts, c, lo, hi):
    _covariance_rows(ptr, col, val, U, S, lo, hi)
    _cube_l1_rows(R, normals, frames, diag, lam_a, lo, hi, l1)
    _displacement_rows(U, U_old, U_rest, lo, hi, parts[c])
    c0, c1, c2 = center[0], center[1], center[2]
    for i in range(lo, hi):
        V_out[i, 0] = U[i, 0] * scale + c0
        V_out[i, 1] = U[i, 1] * scale + c1
        V_out[i, 2] = U[i, 2] * scale + c2


@njit(**_PAR)
def _cube_after_solve_par(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old, U_rest,
                          scale, center, V_out, l1, parts):
    n = U.shape[0]
    for c in prange(parts.shape[0]):
        _cube_after_solve_rows(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old,
                               U_rest, scale, center, V_out, l1, parts, c, c * CHUNK,
                               min(n, (c + 1) * CHUNK))


@njit(**_OPTS)
def _cube_after_solve_ser(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old, U_rest,
                          scale, center, V_out, l1, parts):
    n = U.shape[0]
    for c in range(parts.shape[0]):
        _cube_after_solve_rows(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old,
                               U_rest, scale, center, V_out, l1, parts, c, c * CHUNK,
                               min(n, (c + 1) * CHUNK))


def _cube_after_solve(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old, U_rest,
                      scale, center, V_out, par):
    if not par:
        return _cube_after_solve_all_ser(ptr, col, val, U, S, R, normals, frames, diag, lam_a,
                                         U_old, U_rest, scale, center, V_out)
    n = U.shape[0]
    l1 = np.empty(n)
    parts = np.empty(((n + CHUNK - 1) // CHUNK, 9))
    _cube_after_solve_par(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old,
                          U_rest, scale, center, V_out, l1, parts)
    return _after_solve_totals(l1, parts, n)


@njit(**_OPTS)
def _after_solve_totals(l1, parts, n):
    e_l1 = _sum_in_order(l1)  # vertex order, as cube_l1_energy
    step, total, bbox = _combine_displacement(parts, n)
    return e_l1, step, total, bbox


@njit(**_OPTS)
def _cube_after_solve_all_ser(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old,
                              U_rest, scale, center, V_out):
    n = U.shape[0]
    l1 = np.empty(n)
    parts = np.empty(((n + CHUNK - 1) // CHUNK, 9))
    _cube_after_solve_ser(ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old,
                          U_rest, scale, center, V_out, l1, parts)
    return _after_solve_totals(l1, parts, n)


def cube_after_solve(ptr, col, val, U, R, normals, frames, diag, lam_a, U_old, U_rest, scale,
                     center):
    """Cubic stylization's work after a global step, in one pass over the vertices (one
    parallel launch instead of one and three serial passes), for vertex cells (``n_cells ==
    n``):

    * ``S``: :func:`block_covariances` of ``U`` (the next local step's, the energy's);
    * ``e_l1``: :func:`cube_l1_energy` ``(R, normals, frames, diag, lam_a)``;
    * ``step, total, bbox``: :func:`displacement_maxima` ``(U, U_old, U_rest)``;
    * ``V_out = U * scale + center`` (the output in the input's units).

    Returns ``(S, V_out, e_l1, step, total, bbox)``; every number the same, bit for bit, as the
    separate kernels' (and for any thread count).
    """
    n = U.shape[0]
    S = np.empty((n, 3, 3))
    V_out = np.empty((n, 3))
    e_l1, step, total, bbox = _cube_after_solve(
        ptr, col, val, U, S, R, normals, frames, diag, lam_a, U_old, U_rest, float(scale),
        np.asarray(center, dtype=np.float64), V_out, _par(n, CHUNK))
    return S, V_out, e_l1, step, total, bbox


@njit(**_OPTS)
def _rhs_rows(tptr, tcell, tval, R, b, lo, hi):
    for j in range(lo, hi):
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for t in range(tptr[j], tptr[j + 1]):
            i = tcell[t]
            k0, k1, k2 = tval[t, 0], tval[t, 1], tval[t, 2]
            b0 += R[i, 0, 0] * k0 + R[i, 0, 1] * k1 + R[i, 0, 2] * k2
            b1 += R[i, 1, 0] * k0 + R[i, 1, 1] * k1 + R[i, 1, 2] * k2
            b2 += R[i, 2, 0] * k0 + R[i, 2, 1] * k1 + R[i, 2, 2] * k2
        b[j, 0] = b0
        b[j, 1] = b1
        b[j, 2] = b2


@njit(**_PAR)
def _rhs_par(tptr, tcell, tval, R, b):
    n = tptr.shape[0] - 1
    for c in prange((n + CHUNK - 1) // CHUNK):
        _rhs_rows(tptr, tcell, tval, R, b, c * CHUNK, min(n, (c + 1) * CHUNK))


@njit(**_OPTS)
def _rhs_ser(tptr, tcell, tval, R, b):
    n = tptr.shape[0] - 1
    for c in range((n + CHUNK - 1) // CHUNK):
        _rhs_rows(tptr, tcell, tval, R, b, c * CHUNK, min(n, (c + 1) * CHUNK))


def block_rhs(tptr, tcell, tval, R, b):
    """``b[j] = sum_{t in tptr[j]:tptr[j+1]} R[tcell[t]] tval[t]`` (the product K^T [R_1^T; ...]).

    A gather per vertex ``j`` (no scatter-add, so vertices can run on threads without races):
    entries ``tptr[j]:tptr[j+1]`` are the blocks of :func:`block_covariances`'s storage whose
    column is j, copied into column order (``tcell``: the block's cell, ``tval``: its 3 values)
    so the loop reads them sequentially and gathers only the rotations; they come in increasing
    cell, the order of a serial scatter over the cells (the same sums, term by term).
    b: (n, 3) output.
    """
    (_rhs_par if _par(b.shape[0], CHUNK) else _rhs_ser)(tptr, tcell, tval, R, b)
