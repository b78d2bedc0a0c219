"""Compiled (Numba) kernels of the neural-subdivision network's half-flap plumbing.

Loaded through the project's one switch (:mod:`algorithms.compiled`); without Numba, or with
``STYLIZE3D_NUMBA=0``, :class:`algorithms.subdivision.model.SubdivisionNet` runs the same
mathematics as plain PyTorch operations (tested to agree, and the hand-written backward passes
here are checked against PyTorch autograd of that code and by finite differences).

Why: a training step runs the three MLPs over ~15k half-flaps of a 150-300-vertex coarse mesh and
its first refinement. The MLPs were ~15 % of the step (profiled); most of the rest was several
hundred small PyTorch operations per step (gathers of the flap vertices, differential
coordinates, face normals, local frames, 3x3 batched products, averaging into vertices, and their
backward passes, advanced indexing's backward sorting its indices), each paying dispatch and
memory traffic. Here each of those stages is one loop over the half-flaps, forward and backward:
23.2 -> 12.8 ms per training step on armadillo's coarse meshes (one thread, quiet machine).

Half-flap ``h`` with vertices ``i, j, k, l`` (``l = k`` where the edge is on the boundary,
``has_l[h]`` false):

* ``a = Pj - Pi``, ``b = Pk - Pi``, ``c = Pl - Pi``;
* ``x = a / |a|``; face normals ``f1 = unit(a x b)`` (face i, j, k) and, when ``has_l``,
  ``f2 = unit(c x a)`` (face j, i, l); ``nz = f1 + f2``; ``z = unit(nz - (nz.x) x)``;
  ``y = z x x``; ``R = [x; y; z]`` (rows);
* ``loc[s] = R W[s]`` for ``W = [a, b, c, Di, Dj, Dk, Dl]``; on a boundary flap the two ``l``
  slots are the ``k`` slots turned by pi about the edge: ``loc[2] = diag(1, -1, -1) loc[1]``,
  ``loc[6] = diag(1, -1, -1) loc[5]``.

``unit(u) = u / max(|u|, 1e-12)`` as in the PyTorch code. The frame kernels take the constants
``one`` and ``eps`` typed like the arrays, so that float32 inputs are computed in float32 (1.25-1.5x
faster than promoting every operation to float64, measured; float64 inputs stay float64).
"""

from __future__ import annotations

import math

import numpy as np
from .._numba import njit

EPS = 1e-12  # the PyTorch path's clamp of a norm


@njit(cache=True, nogil=True, inline="always")
def _unit(u0, u1, u2, one, eps):  # pragma: no cover - compiled
    """(u / s, 1 / s, |u| > eps) with s = max(|u|, eps)."""
    nrm = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    r = one / max(nrm, eps)
    return u0 * r, u1 * r, u2 * r, r, nrm > eps


@njit(cache=True, nogil=True, inline="always")
def _unit_back(g0, g1, g2, e0, e1, e2, r, unclamped):  # pragma: no cover - compiled
    """Gradient wrt u of e = u / max(|u|, EPS) (= u r), given g = dE/de."""
    if unclamped:
        d = g0 * e0 + g1 * e1 + g2 * e2
        return (g0 - d * e0) * r, (g1 - d * e1) * r, (g2 - d * e2) * r
    return g0 * r, g1 * r, g2 * r


@njit(cache=True, nogil=True)
def flap_forward(V, D, ijkl, has_l, loc, R, one, eps):  # pragma: no cover - compiled
    """Local frames ``R (H, 3, 3)`` and the seven flap vectors in them, ``loc (H, 7, 3)``."""
    H = ijkl.shape[0]
    W = np.empty((7, 3), V.dtype)
    for h in range(H):
        i = ijkl[h, 0]
        j = ijkl[h, 1]
        k = ijkl[h, 2]
        l = ijkl[h, 3]
        for d in range(3):
            pi = V[i, d]
            W[0, d] = V[j, d] - pi
            W[1, d] = V[k, d] - pi
            W[2, d] = V[l, d] - pi
            W[3, d] = D[i, d]
            W[4, d] = D[j, d]
            W[5, d] = D[k, d]
            W[6, d] = D[l, d]
        a0, a1, a2 = W[0, 0], W[0, 1], W[0, 2]
        b0, b1, b2 = W[1, 0], W[1, 1], W[1, 2]
        c0, c1, c2 = W[2, 0], W[2, 1], W[2, 2]
        x0, x1, x2, _, _ = _unit(a0, a1, a2, one, eps)
        f0, f1, f2, _, _ = _unit(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0,
                                 one, eps)
        n0, n1, n2 = f0, f1, f2
        if has_l[h]:
            g0, g1, g2, _, _ = _unit(c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0,
                                     one, eps)
            n0 += g0
            n1 += g1
            n2 += g2
        p = n0 * x0 + n1 * x1 + n2 * x2
        z0, z1, z2, _, _ = _unit(n0 - p * x0, n1 - p * x1, n2 - p * x2, one, eps)
        y0 = z1 * x2 - z2 * x1
        y1 = z2 * x0 - z0 * x2
        y2 = z0 * x1 - z1 * x0
        R[h, 0, 0], R[h, 0, 1], R[h, 0, 2] = x0, x1, x2
        R[h, 1, 0], R[h, 1, 1], R[h, 1, 2] = y0, y1, y2
        R[h, 2, 0], R[h, 2, 1], R[h, 2, 2] = z0, z1, z2
        for s in range(7):
            w0, w1, w2 = W[s, 0], W[s, 1], W[s, 2]
            loc[h, s, 0] = x0 * w0 + x1 * w1 + x2 * w2
            loc[h, s, 1] = y0 * w0 + y1 * w1 + y2 * w2
            loc[h, s, 2] = z0 * w0 + z1 * w1 + z2 * w2
        if not has_l[h]:
            for s in (2, 6):
                loc[h, s, 0] = loc[h, s - 1, 0]
                loc[h, s, 1] = -loc[h, s - 1, 1]
                loc[h, s, 2] = -loc[h, s - 1, 2]


@njit(cache=True, nogil=True)
def flap_backward(V, D, ijkl, has_l, gloc, gR, gV, gD, one,
                  eps):  # pragma: no cover - compiled
    """Add to ``gV (n, 3)``, ``gD (n, 3)`` the gradients of ``<gloc, loc> + <gR, R>``."""
    H = ijkl.shape[0]
    W = np.empty((7, 3), V.dtype)
    G = np.empty((7, 3), V.dtype)
    gW = np.empty((7, 3), V.dtype)
    for h in range(H):
        i = ijkl[h, 0]
        j = ijkl[h, 1]
        k = ijkl[h, 2]
        l = ijkl[h, 3]
        hl = has_l[h]
        for d in range(3):
            pi = V[i, d]
            W[0, d] = V[j, d] - pi
            W[1, d] = V[k, d] - pi
            W[2, d] = V[l, d] - pi
            W[3, d] = D[i, d]
            W[4, d] = D[j, d]
            W[5, d] = D[k, d]
            W[6, d] = D[l, d]
        for s in range(7):
            for d in range(3):
                G[s, d] = gloc[h, s, d]
        if not hl:  # loc[2] = flip loc'[1] with W[2] = W[1]: the same as flipping its gradient
            for s in (2, 6):
                G[s, 1] = -G[s, 1]
                G[s, 2] = -G[s, 2]
        # ---- forward again (the lines of flap_forward, kept in registers rather than stored:
        # an array-taking helper shared by both would add reference counting per flap)
        a0, a1, a2 = W[0, 0], W[0, 1], W[0, 2]
        b0, b1, b2 = W[1, 0], W[1, 1], W[1, 2]
        c0, c1, c2 = W[2, 0], W[2, 1], W[2, 2]
        x0, x1, x2, sa, ka = _unit(a0, a1, a2, one, eps)
        f0, f1, f2, s1, k1 = _unit(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0,
                                   one, eps)
        n0, n1, n2 = f0, f1, f2
        e0 = e1 = e2 = one - one
        s2 = one
        k2 = False
        if hl:
            e0, e1, e2, s2, k2 = _unit(c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0,
                                       one, eps)
            n0 += e0
            n1 += e1
            n2 += e2
        p = n0 * x0 + n1 * x1 + n2 * x2
        w0 = n0 - p * x0
        w1 = n1 - p * x1
        w2 = n2 - p * x2
        z0, z1, z2, sw, kw = _unit(w0, w1, w2, one, eps)
        y0 = z1 * x2 - z2 * x1
        y1 = z2 * x0 - z0 * x2
        y2 = z0 * x1 - z1 * x0
        # ---- loc[s] = R W[s]: gW[s] = R^T G[s]; gR[r] += sum_s G[s, r] W[s]
        gx0 = gR[h, 0, 0]
        gx1 = gR[h, 0, 1]
        gx2 = gR[h, 0, 2]
        gy0 = gR[h, 1, 0]
        gy1 = gR[h, 1, 1]
        gy2 = gR[h, 1, 2]
        gz0 = gR[h, 2, 0]
        gz1 = gR[h, 2, 1]
        gz2 = gR[h, 2, 2]
        for s in range(7):
            q0, q1, q2 = G[s, 0], G[s, 1], G[s, 2]
            gW[s, 0] = x0 * q0 + y0 * q1 + z0 * q2
            gW[s, 1] = x1 * q0 + y1 * q1 + z1 * q2
            gW[s, 2] = x2 * q0 + y2 * q1 + z2 * q2
            gx0 += q0 * W[s, 0]
            gx1 += q0 * W[s, 1]
            gx2 += q0 * W[s, 2]
            gy0 += q1 * W[s, 0]
            gy1 += q1 * W[s, 1]
            gy2 += q1 * W[s, 2]
            gz0 += q2 * W[s, 0]
            gz1 += q2 * W[s, 1]
            gz2 += q2 * W[s, 2]
        # ---- y = z x x: dz += x x gy, dx += gy x z
        gz0 += x1 * gy2 - x2 * gy1
        gz1 += x2 * gy0 - x0 * gy2
        gz2 += x0 * gy1 - x1 * gy0
        gx0 += gy1 * z2 - gy2 * z1
        gx1 += gy2 * z0 - gy0 * z2
        gx2 += gy0 * z1 - gy1 * z0
        # ---- z = unit(w), w = nz - (nz.x) x
        gw0, gw1, gw2 = _unit_back(gz0, gz1, gz2, z0, z1, z2, sw, kw)
        q = gw0 * x0 + gw1 * x1 + gw2 * x2
        gn0 = gw0 - q * x0
        gn1 = gw1 - q * x1
        gn2 = gw2 - q * x2
        gx0 -= p * gw0 + q * n0
        gx1 -= p * gw1 + q * n1
        gx2 -= p * gw2 + q * n2
        # ---- x = unit(a)
        ga0, ga1, ga2 = _unit_back(gx0, gx1, gx2, x0, x1, x2, sa, ka)
        ga0 += gW[0, 0]
        ga1 += gW[0, 1]
        ga2 += gW[0, 2]
        gb0, gb1, gb2 = gW[1, 0], gW[1, 1], gW[1, 2]
        gc0, gc1, gc2 = gW[2, 0], gW[2, 1], gW[2, 2]
        # ---- f1 = unit(a x b): da += b x gm, db += gm x a
        gm0, gm1, gm2 = _unit_back(gn0, gn1, gn2, f0, f1, f2, s1, k1)
        ga0 += b1 * gm2 - b2 * gm1
        ga1 += b2 * gm0 - b0 * gm2
        ga2 += b0 * gm1 - b1 * gm0
        gb0 += gm1 * a2 - gm2 * a1
        gb1 += gm2 * a0 - gm0 * a2
        gb2 += gm0 * a1 - gm1 * a0
        if hl:  # f2 = unit(c x a): dc += a x gm, da += gm x c
            gm0, gm1, gm2 = _unit_back(gn0, gn1, gn2, e0, e1, e2, s2, k2)
            gc0 += a1 * gm2 - a2 * gm1
            gc1 += a2 * gm0 - a0 * gm2
            gc2 += a0 * gm1 - a1 * gm0
            ga0 += gm1 * c2 - gm2 * c1
            ga1 += gm2 * c0 - gm0 * c2
            ga2 += gm0 * c1 - gm1 * c0
        gV[j, 0] += ga0
        gV[j, 1] += ga1
        gV[j, 2] += ga2
        gV[k, 0] += gb0
        gV[k, 1] += gb1
        gV[k, 2] += gb2
        gV[l, 0] += gc0
        gV[l, 1] += gc1
        gV[l, 2] += gc2
        gV[i, 0] -= ga0 + gb0 + gc0
        gV[i, 1] -= ga1 + gb1 + gc1
        gV[i, 2] -= ga2 + gb2 + gc2
        for d in range(3):
            gD[i, d] += gW[3, d]
            gD[j, d] += gW[4, d]
            gD[k, d] += gW[5, d]
            gD[l, d] += gW[6, d]


@njit(cache=True, nogil=True)
def slot_gather_sum(Z4, ijkl, out):  # pragma: no cover - compiled
    """``out[h] = sum_s Z4[ijkl[h, s], s]`` for ``Z4 (n, 4, C)``."""
    H = ijkl.shape[0]
    C = Z4.shape[2]
    for h in range(H):
        for c in range(C):
            out[h, c] = Z4[ijkl[h, 0], 0, c]
        for s in range(1, 4):
            v = ijkl[h, s]
            for c in range(C):
                out[h, c] += Z4[v, s, c]


@njit(cache=True, nogil=True)
def slot_scatter_add(g, ijkl, gZ4):  # pragma: no cover - compiled
    """The backward of :func:`slot_gather_sum`: ``gZ4[ijkl[h, s], s] += g[h]``."""
    H = ijkl.shape[0]
    C = g.shape[1]
    for h in range(H):
        for s in range(4):
            v = ijkl[h, s]
            for c in range(C):
                gZ4[v, s, c] += g[h, c]


@njit(cache=True, nogil=True)
def laplace(V, src, dst, deg, D):  # pragma: no cover - compiled
    """Differential coordinates ``D[v] = V[v] - mean of V over v's neighbours`` from the
    directed neighbour pairs ``(src, dst)`` and ``deg`` (>= 1)."""
    n = V.shape[0]
    for v in range(n):
        for d in range(3):
            D[v, d] = 0.0
    for e in range(src.shape[0]):
        s = src[e]
        t = dst[e]
        for d in range(3):
            D[s, d] += V[t, d]
    for v in range(n):
        w = 1.0 / deg[v]
        for d in range(3):
            D[v, d] = V[v, d] - D[v, d] * w


@njit(cache=True, nogil=True)
def laplace_backward(gD, src, dst, deg, gV):  # pragma: no cover - compiled
    """Add the gradient of ``<gD, D>`` (see :func:`laplace`) to ``gV``."""
    n = gD.shape[0]
    for v in range(n):
        for d in range(3):
            gV[v, d] += gD[v, d]
    for e in range(src.shape[0]):
        s = src[e]
        t = dst[e]
        w = 1.0 / deg[s]
        for d in range(3):
            gV[t, d] -= gD[s, d] * w


@njit(cache=True, nogil=True)
def pool(out, R, dst, inv_count, acc):  # pragma: no cover - compiled
    """Average the half-flaps' outputs into their vertices / edges: ``acc (N, C)`` (set) =
    sum over flaps h with ``dst[h] = v`` of ``[R[h]^T out[h, :3], out[h, 3:]] * inv_count[v]``
    (``inv_count`` = 1 / the number of flaps of ``v``)."""
    N = acc.shape[0]
    C = out.shape[1]
    for v in range(N):
        for c in range(C):
            acc[v, c] = 0.0
    for h in range(out.shape[0]):
        v = dst[h]
        w = inv_count[v]
        o0 = out[h, 0]
        o1 = out[h, 1]
        o2 = out[h, 2]
        for d in range(3):
            acc[v, d] += (o0 * R[h, 0, d] + o1 * R[h, 1, d] + o2 * R[h, 2, d]) * w
        for c in range(3, C):
            acc[v, c] += out[h, c] * w


@njit(cache=True, nogil=True)
def pool_backward(out, R, dst, inv_count, g, gout, gR):  # pragma: no cover - compiled
    """Gradients of ``<g, acc>`` (see :func:`pool`): ``gout (H, C)``, ``gR (H, 3, 3)`` (set)."""
    C = out.shape[1]
    for h in range(out.shape[0]):
        v = dst[h]
        w = inv_count[v]
        g0 = g[v, 0] * w
        g1 = g[v, 1] * w
        g2 = g[v, 2] * w
        for r in range(3):
            gout[h, r] = R[h, r, 0] * g0 + R[h, r, 1] * g1 + R[h, r, 2] * g2
            o = out[h, r]
            gR[h, r, 0] = o * g0
            gR[h, r, 1] = o * g1
            gR[h, r, 2] = o * g2
        for c in range(3, C):
            gout[h, c] = g[v, c] * w
