"""Kernels of successive self-parameterization (:mod:`algorithms.mesh.selfparam`).

Plain loops over NumPy arrays, compiled with Numba (``@njit(cache=True)``, no fastmath) when it
is available and not switched off with ``STYLIZE3D_NUMBA=0``; otherwise the very same functions
run as (slow) Python. The mesh is a corner table: ``F`` (m, 3) triangles whose ids never change,
``FF[f, c]`` the triangle across edge ``c`` = (F[f, c], F[f, c+1]) (-1 on the boundary) and
``FFi[f, c]`` that edge's index in ``FF[f, c]``; ``vf[v]`` one live triangle of every live vertex.

See :mod:`algorithms.mesh.selfparam` for the method; this module only holds the machinery.
"""

from __future__ import annotations

import math

import numpy as np

from ..compiled import numba_wanted

_ENABLED = numba_wanted()
try:
    if not _ENABLED:
        raise ImportError
    from .._numba import njit  # noqa: F401

    COMPILED = True
except ImportError:  # pragma: no cover - exercised with STYLIZE3D_NUMBA=0
    COMPILED = False

    def njit(*args, **kwargs):
        if args and callable(args[0]):
            return args[0]
        return lambda f: f


CAP = 256  # largest 1-ring handled (faces); larger patches are refused ("valence")

# rejection counters (indices into the ``counts`` array)
R_LINK, R_PINCH, R_VALENCE, R_FLIP3D, R_QUALITY3D, R_UVFLIP, R_UVOVERLAP, R_UVQUALITY, \
    R_BORDER, R_SOLVE = range(10)
# case counters
C_INTERIOR, C_ONE_BOUNDARY, C_VAR1, C_VAR2, C_VAR3 = range(10, 15)
N_COUNTS = 15

# state slots
S_NF, S_K, S_HEAP, S_REBUILT, S_SINCE, S_NB, S_NA, S_NU, S_TAG, S_POPS, S_PUSHES = range(11)
N_STATE = 11

TWO_PI = 2.0 * math.pi
ANGLE_TOL = 1e-6


# ------------------------------------------------------------------------------ small helpers
@njit(cache=True, nogil=True)
def _corner(F, f, v):
    if F[f, 0] == v:
        return 0
    if F[f, 1] == v:
        return 1
    return 2


@njit(cache=True, nogil=True)
def _ring(v, F, FF, vf, faces, corners, verts, cap):
    """Ordered (counter-clockwise) faces and neighbours of ``v``.

    Returns (number of faces, number of neighbours, on boundary); -1 faces when above ``cap``.
    For a boundary vertex the neighbours run from one boundary neighbour to the other.
    """
    f0 = vf[v]
    f = f0
    boundary = False
    steps = 0
    while True:
        c = _corner(F, f, v)
        g = FF[f, c]
        if g < 0:
            boundary = True
            break
        if g == f0:
            break
        f = g
        steps += 1
        if steps > cap:
            return -1, 0, False
    start = f if boundary else f0
    nf = 0
    nv = 0
    f = start
    while True:
        if nf >= cap - 1:
            return -1, 0, boundary
        c = _corner(F, f, v)
        faces[nf] = f
        corners[nf] = c
        nf += 1
        verts[nv] = F[f, (c + 1) % 3]
        nv += 1
        g = FF[f, (c + 2) % 3]
        if g < 0:
            verts[nv] = F[f, (c + 2) % 3]
            nv += 1
            break
        if g == start:
            break
        f = g
    return nf, nv, boundary


@njit(cache=True, nogil=True)
def _quadric_err(q, x, y, z):
    return (q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + q[3] * y * y
            + 2 * q[4] * y * z + q[5] * z * z + 2 * (q[6] * x + q[7] * y + q[8] * z) + q[9])


@njit(cache=True, nogil=True)
def edge_cost(u, v, P, Q, bnd, protect, strategy, pos, qs):
    """Cost of collapsing (u, v), merged position into ``pos``; returns (cost, keep_u).

    strategy 0 = midpoint (squared length, midpoint), 1 = qslim (quadric minimizer, else best of
    endpoints and midpoint), 2 = vertex removal (best allowed endpoint by quadric error).
    Anchored endpoints (kept vertices; a boundary vertex joined to an interior one) do not move.
    """
    au = protect[u] or (bnd[u] and not bnd[v])
    av = protect[v] or (bnd[v] and not bnd[u])
    if au and av:
        return np.inf, True
    if strategy != 0:
        for k in range(10):
            qs[k] = Q[u, k] + Q[v, k]
    ex = P[v, 0] - P[u, 0]
    ey = P[v, 1] - P[u, 1]
    ez = P[v, 2] - P[u, 2]
    l2 = ex * ex + ey * ey + ez * ez
    mx = 0.5 * (P[u, 0] + P[v, 0])
    my = 0.5 * (P[u, 1] + P[v, 1])
    mz = 0.5 * (P[u, 2] + P[v, 2])
    cost = 0.0
    keep_u = True
    if au or av:
        w = u if au else v
        pos[0] = P[w, 0]
        pos[1] = P[w, 1]
        pos[2] = P[w, 2]
        keep_u = au
        if strategy == 0:
            cost = l2
        else:
            cost = _quadric_err(qs, pos[0], pos[1], pos[2])
    elif strategy == 0:
        pos[0] = mx
        pos[1] = my
        pos[2] = mz
        cost = l2
    elif strategy == 2:
        cu = _quadric_err(qs, P[u, 0], P[u, 1], P[u, 2])
        cv = _quadric_err(qs, P[v, 0], P[v, 1], P[v, 2])
        w = u if cu <= cv else v
        cost = min(cu, cv)
        pos[0] = P[w, 0]
        pos[1] = P[w, 1]
        pos[2] = P[w, 2]
        keep_u = w == u
    else:
        a, b, c, d, e, f = qs[0], qs[1], qs[2], qs[3], qs[4], qs[5]
        g, h, i = qs[6], qs[7], qs[8]
        c00 = d * f - e * e
        c01 = c * e - b * f
        c02 = b * e - c * d
        det = a * c00 + b * c01 + c * c02
        tr = a + d + f
        done = False
        if tr > 0 and det > 1e-9 * tr * tr * tr:
            c11 = a * f - c * c
            c12 = b * c - a * e
            c22 = a * d - b * b
            x = -(c00 * g + c01 * h + c02 * i) / det
            y = -(c01 * g + c11 * h + c12 * i) / det
            z = -(c02 * g + c12 * h + c22 * i) / det
            dx = x - mx
            dy = y - my
            dz = z - mz
            if dx * dx + dy * dy + dz * dz <= l2:
                pos[0] = x
                pos[1] = y
                pos[2] = z
                cost = _quadric_err(qs, x, y, z)
                done = True
        if not done:
            cu = _quadric_err(qs, P[u, 0], P[u, 1], P[u, 2])
            cv = _quadric_err(qs, P[v, 0], P[v, 1], P[v, 2])
            cm = _quadric_err(qs, mx, my, mz)
            if cm < min(cu, cv):
                pos[0] = mx
                pos[1] = my
                pos[2] = mz
                cost = cm
            elif cu <= cv:
                pos[0] = P[u, 0]
                pos[1] = P[u, 1]
                pos[2] = P[u, 2]
                cost = cu
            else:
                pos[0] = P[v, 0]
                pos[1] = P[v, 1]
                pos[2] = P[v, 2]
                cost = cv
        du = (pos[0] - P[u, 0]) ** 2 + (pos[1] - P[u, 1]) ** 2 + (pos[2] - P[u, 2]) ** 2
        dv = (pos[0] - P[v, 0]) ** 2 + (pos[1] - P[v, 1]) ** 2 + (pos[2] - P[v, 2]) ** 2
        keep_u = du <= dv
    if cost < 0.0:
        cost = 0.0
    return cost, keep_u


# ------------------------------------------------------------------------------ heap
# A 4-ary min-heap of records ``hk[t] = (cost, u, v, stamp_u * 2^26 + stamp_v)`` (float64, exact):
# one 32-byte record per entry keeps every level of a sift in one or two cache lines.
_SMOD = 67108864  # 2**26: stamps are compared modulo this


@njit(cache=True, nogil=True)
def _hpush(hk, size, cost, u, v, su, sv):
    packed = float((su % _SMOD) * _SMOD + (sv % _SMOD))
    k = size
    while k > 0:
        p = (k - 1) >> 2
        if hk[p, 0] <= cost:
            break
        hk[k, 0] = hk[p, 0]
        hk[k, 1] = hk[p, 1]
        hk[k, 2] = hk[p, 2]
        hk[k, 3] = hk[p, 3]
        k = p
    hk[k, 0] = cost
    hk[k, 1] = u
    hk[k, 2] = v
    hk[k, 3] = packed
    return size + 1


@njit(cache=True, nogil=True)
def _hsift_down(hk, size, k):
    cost, u, v, pk = hk[k, 0], hk[k, 1], hk[k, 2], hk[k, 3]
    while True:
        c = 4 * k + 1
        if c >= size:
            break
        best = c
        bc = hk[c, 0]
        e = min(c + 4, size)
        for t in range(c + 1, e):
            if hk[t, 0] < bc:
                bc = hk[t, 0]
                best = t
        if bc >= cost:
            break
        hk[k, 0] = hk[best, 0]
        hk[k, 1] = hk[best, 1]
        hk[k, 2] = hk[best, 2]
        hk[k, 3] = hk[best, 3]
        k = best
    hk[k, 0] = cost
    hk[k, 1] = u
    hk[k, 2] = v
    hk[k, 3] = pk


@njit(cache=True, nogil=True)
def _hpop(hk, size):
    cost = hk[0, 0]
    u = int(hk[0, 1])
    v = int(hk[0, 2])
    pk = int(hk[0, 3])
    size -= 1
    if size > 0:
        hk[0, 0] = hk[size, 0]
        hk[0, 1] = hk[size, 1]
        hk[0, 2] = hk[size, 2]
        hk[0, 3] = hk[size, 3]
        _hsift_down(hk, size, 0)
    return cost, u, v, pk // _SMOD, pk % _SMOD, size


@njit(cache=True, nogil=True)
def _hcurrent(u, v, su, sv, valive, stamp):
    return valive[u] and valive[v] and stamp[u] % _SMOD == su and stamp[v] % _SMOD == sv


@njit(cache=True, nogil=True)
def _hheapify(hk, size):
    for t in range((size - 2) // 4, -1, -1):
        _hsift_down(hk, size, t)


@njit(cache=True, nogil=True)
def _hcompact(hk, size, valive, stamp):
    """Drop stale entries and re-heapify; returns the new size."""
    k = 0
    for t in range(size):
        u = int(hk[t, 1])
        v = int(hk[t, 2])
        pk = int(hk[t, 3])
        if _hcurrent(u, v, pk // _SMOD, pk % _SMOD, valive, stamp):
            for d in range(4):
                hk[k, d] = hk[t, d]
            k += 1
    _hheapify(hk, k)
    return k


# ------------------------------------------------------------------------------ geometry
@njit(cache=True, nogil=True)
def _quality3(ax, ay, az, bx, by, bz, cx, cy, cz):
    """4 sqrt(3) area / sum of squared edge lengths (1 equilateral, 0 degenerate)."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    area = 0.5 * math.sqrt(nx * nx + ny * ny + nz * nz)
    wx, wy, wz = cx - bx, cy - by, cz - bz
    s = ux * ux + uy * uy + uz * uz + vx * vx + vy * vy + vz * vz + wx * wx + wy * wy + wz * wz
    if s <= 0.0:
        return 0.0
    return 4.0 * math.sqrt(3.0) * area / s


@njit(cache=True, nogil=True)
def _quality2(ax, ay, bx, by, cx, cy):
    """Signed 2D quality (negative for clockwise triangles)."""
    ux, uy = bx - ax, by - ay
    vx, vy = cx - ax, cy - ay
    area = 0.5 * (ux * vy - uy * vx)
    wx, wy = cx - bx, cy - by
    s = ux * ux + uy * uy + vx * vx + vy * vy + wx * wx + wy * wy
    if s <= 0.0:
        return 0.0
    return 4.0 * math.sqrt(3.0) * area / s


@njit(cache=True, nogil=True)
def _lscm_add(H, X, l0, l1, l2):
    """Add one triangle's LSCM (conformal) energy to the dense normal matrix ``H``.

    ``X`` (3, 3) are the corner positions in 3D, ``l*`` the local vertex ids. Energy of the
    piecewise-linear map ``(u, v)``: area * |u_x - v_y|^2 + |u_y + v_x|^2 (Cauchy-Riemann
    residuals in an orthonormal frame of the triangle; zero exactly for orientation-preserving
    similarities). Returns False for a degenerate triangle (nothing added).
    """
    e1x = X[1, 0] - X[0, 0]
    e1y = X[1, 1] - X[0, 1]
    e1z = X[1, 2] - X[0, 2]
    l = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    if l <= 0.0:
        return False
    e1x /= l
    e1y /= l
    e1z /= l
    wx = X[2, 0] - X[0, 0]
    wy = X[2, 1] - X[0, 1]
    wz = X[2, 2] - X[0, 2]
    x2 = wx * e1x + wy * e1y + wz * e1z
    cx = e1y * wz - e1z * wy
    cy = e1z * wx - e1x * wz
    cz = e1x * wy - e1y * wx
    y2 = math.sqrt(cx * cx + cy * cy + cz * cz)
    area = 0.5 * l * y2
    if area <= 0.0:
        return False
    # local 2D corners (0,0), (l,0), (x2,y2); e_j = x_{j+2} - x_{j+1}
    ex0 = x2 - l
    ey0 = y2
    ex1 = 0.0 - x2
    ey1 = 0.0 - y2
    ex2 = l
    ey2 = 0.0
    s2 = 1.0 / (4.0 * area)
    # rows: r1 = sum(-ey u - ex v), r2 = sum(ex u - ey v)
    r1 = (-ey0, -ex0, -ey1, -ex1, -ey2, -ex2)
    r2 = (ex0, -ey0, ex1, -ey1, ex2, -ey2)
    idx = (2 * l0, 2 * l0 + 1, 2 * l1, 2 * l1 + 1, 2 * l2, 2 * l2 + 1)
    for a in range(6):
        ia = idx[a]
        ra1 = s2 * r1[a]
        ra2 = s2 * r2[a]
        for b in range(6):
            H[ia, idx[b]] += ra1 * r1[b] + ra2 * r2[b]
    return True


@njit(cache=True, nogil=True)
def lscm_solve(H, ncomp, fixed, fixval, x, A, rhs, free):
    """Minimize x^T H x over the components not fixed; writes ``x``; returns (ok, energy).

    Dense Cholesky of the free block (patches are small).
    """
    nf = 0
    for c in range(ncomp):
        if fixed[c]:
            x[c] = fixval[c]
        else:
            free[nf] = c
            nf += 1
    for a in range(nf):
        ca = free[a]
        s = 0.0
        for c in range(ncomp):
            if fixed[c]:
                s += H[ca, c] * fixval[c]
        rhs[a] = -s
        for b in range(nf):
            A[a, b] = H[ca, free[b]]
    # Cholesky in place (lower)
    for a in range(nf):
        s = A[a, a]
        for k in range(a):
            s -= A[a, k] * A[a, k]
        if not s > 1e-300:
            return False, np.inf
        d = math.sqrt(s)
        A[a, a] = d
        for b in range(a + 1, nf):
            t = A[b, a]
            for k in range(a):
                t -= A[b, k] * A[a, k]
            A[b, a] = t / d
    for a in range(nf):
        t = rhs[a]
        for k in range(a):
            t -= A[a, k] * rhs[k]
        rhs[a] = t / A[a, a]
    for a in range(nf - 1, -1, -1):
        t = rhs[a]
        for k in range(a + 1, nf):
            t -= A[k, a] * rhs[k]
        rhs[a] = t / A[a, a]
    for a in range(nf):
        x[free[a]] = rhs[a]
    e = 0.0
    for a in range(ncomp):
        s = 0.0
        for b in range(ncomp):
            s += H[a, b] * x[b]
        e += x[a] * s
    return True, e


@njit(cache=True, nogil=True)
def _tri_frame(X, G):
    """Gradients of the 3 hat functions in an orthonormal frame of triangle X (3, 3) -> G (2, 3);
    returns the area (0 for a degenerate triangle)."""
    e1x = X[1, 0] - X[0, 0]
    e1y = X[1, 1] - X[0, 1]
    e1z = X[1, 2] - X[0, 2]
    l = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    if l <= 0.0:
        return 0.0
    e1x /= l
    e1y /= l
    e1z /= l
    wx = X[2, 0] - X[0, 0]
    wy = X[2, 1] - X[0, 1]
    wz = X[2, 2] - X[0, 2]
    x2 = wx * e1x + wy * e1y + wz * e1z
    cx = e1y * wz - e1z * wy
    cy = e1z * wx - e1x * wz
    cz = e1x * wy - e1y * wx
    y2 = math.sqrt(cx * cx + cy * cy + cz * cz)
    area = 0.5 * l * y2
    if area <= 0.0:
        return 0.0
    # grad phi_j = rot90(e_j) / (2A), e_j = x_{j+2} - x_{j+1}; rot90(x, y) = (-y, x)
    d = 2.0 * area
    G[0, 0] = -(y2 - 0.0) / d
    G[1, 0] = (x2 - l) / d
    G[0, 1] = -(0.0 - y2) / d
    G[1, 1] = (0.0 - x2) / d
    G[0, 2] = -(0.0 - 0.0) / d
    G[1, 2] = (l - 0.0) / d
    return area


@njit(cache=True, nogil=True)
def arap_refine(U, nl, tl, tX, nt, fixed, fixval, iters, Hs, As, rhs, free, lin, Gs, At):
    """Local-global ARAP (Liu et al. 2008) on the joint patch, started from ``U`` (nl, 2).

    ``tl`` (nt, 3) local corners and ``tX`` (nt, 3, 3) 3D corners of all triangles (before and
    after); ``fixed``/``fixval`` the constrained components (2 L + d). Writes ``U``; returns
    (ok, energy) with energy = sum of area * |J - R|^2.
    """
    ncomp = 2 * nl
    for a in range(ncomp):
        for b in range(ncomp):
            Hs[a, b] = 0.0
    X = np.empty((3, 3))
    G = np.empty((2, 3))
    for t in range(nt):
        for c in range(3):
            for d in range(3):
                X[c, d] = tX[t, c, d]
        A = _tri_frame(X, G)
        At[t] = A
        for c in range(3):
            Gs[t, 0, c] = G[0, c]
            Gs[t, 1, c] = G[1, c]
        if A <= 0.0:
            continue
        for a in range(3):
            for b in range(3):
                w = A * (G[0, a] * G[0, b] + G[1, a] * G[1, b])
                Hs[2 * tl[t, a], 2 * tl[t, b]] += w
                Hs[2 * tl[t, a] + 1, 2 * tl[t, b] + 1] += w
    nf = 0
    for c in range(ncomp):
        if not fixed[c]:
            free[nf] = c
            nf += 1
    for a in range(nf):
        for b in range(nf):
            As[a, b] = Hs[free[a], free[b]]
    for a in range(nf):
        s = As[a, a]
        for k in range(a):
            s -= As[a, k] * As[a, k]
        if not s > 1e-300:
            return False, np.inf
        dd = math.sqrt(s)
        As[a, a] = dd
        for b in range(a + 1, nf):
            q = As[b, a]
            for k in range(a):
                q -= As[b, k] * As[a, k]
            As[b, a] = q / dd
    x = np.empty(ncomp)
    for L in range(nl):
        x[2 * L] = U[L, 0]
        x[2 * L + 1] = U[L, 1]
    for c in range(ncomp):
        if fixed[c]:
            x[c] = fixval[c]
    energy = 0.0
    for it in range(iters + 1):
        # local step: closest rotation to each Jacobian; energy at the current x
        for c in range(ncomp):
            lin[c] = 0.0
        energy = 0.0
        for t in range(nt):
            A = At[t]
            if A <= 0.0:
                continue
            j00 = 0.0
            j01 = 0.0
            j10 = 0.0
            j11 = 0.0
            for c in range(3):
                L = tl[t, c]
                j00 += x[2 * L] * Gs[t, 0, c]
                j01 += x[2 * L] * Gs[t, 1, c]
                j10 += x[2 * L + 1] * Gs[t, 0, c]
                j11 += x[2 * L + 1] * Gs[t, 1, c]
            th = math.atan2(j10 - j01, j00 + j11)
            cs = math.cos(th)
            sn = math.sin(th)
            r00, r01, r10, r11 = cs, -sn, sn, cs
            energy += A * ((j00 - r00) ** 2 + (j01 - r01) ** 2 + (j10 - r10) ** 2
                           + (j11 - r11) ** 2)
            for c in range(3):
                L = tl[t, c]
                lin[2 * L] += A * (Gs[t, 0, c] * r00 + Gs[t, 1, c] * r01)
                lin[2 * L + 1] += A * (Gs[t, 0, c] * r10 + Gs[t, 1, c] * r11)
        if it == iters:
            break
        # global step
        for a in range(nf):
            ca = free[a]
            q = lin[ca]
            for c in range(ncomp):
                if fixed[c]:
                    q -= Hs[ca, c] * x[c]
            rhs[a] = q
        for a in range(nf):
            q = rhs[a]
            for k in range(a):
                q -= As[a, k] * rhs[k]
            rhs[a] = q / As[a, a]
        for a in range(nf - 1, -1, -1):
            q = rhs[a]
            for k in range(a + 1, nf):
                q -= As[k, a] * rhs[k]
            rhs[a] = q / As[a, a]
        for a in range(nf):
            x[free[a]] = rhs[a]
    for L in range(nl):
        U[L, 0] = x[2 * L]
        U[L, 1] = x[2 * L + 1]
    return True, energy


@njit(cache=True, nogil=True)
def _angle(ax, ay, bx, by, cx, cy):
    """Angle at a of triangle (a, b, c) in 2D (unsigned)."""
    ux, uy = bx - ax, by - ay
    vx, vy = cx - ax, cy - ay
    return math.atan2(abs(ux * vy - uy * vx), ux * vx + uy * vy)


@njit(cache=True, nogil=True)
def check_uv(U, nl, bl, nb, al, na, inb, ina, expect, min_q, sb, sa):
    """UV validity of a joint flattening; returns 0 (valid) or a rejection code.

    ``bl`` (nb, 3) / ``al`` (na, 3): local corners of the faces before / after the collapse.
    ``inb`` / ``ina``: whether a local vertex is used before / after. ``expect[L]``: the angle
    sum a vertex used on one side only must have (2 pi inside the mesh, pi on a straight
    boundary). A vertex used on both sides must have the same angle sum on both.
    """
    for L in range(nl):
        sb[L] = 0.0
        sa[L] = 0.0
    for t in range(nb):
        a, b, c = bl[t, 0], bl[t, 1], bl[t, 2]
        ar = (U[b, 0] - U[a, 0]) * (U[c, 1] - U[a, 1]) - (U[b, 1] - U[a, 1]) * (U[c, 0] - U[a, 0])
        if not ar > 0.0:
            return R_UVFLIP
        sb[a] += _angle(U[a, 0], U[a, 1], U[b, 0], U[b, 1], U[c, 0], U[c, 1])
        sb[b] += _angle(U[b, 0], U[b, 1], U[c, 0], U[c, 1], U[a, 0], U[a, 1])
        sb[c] += _angle(U[c, 0], U[c, 1], U[a, 0], U[a, 1], U[b, 0], U[b, 1])
    for t in range(na):
        a, b, c = al[t, 0], al[t, 1], al[t, 2]
        q = _quality2(U[a, 0], U[a, 1], U[b, 0], U[b, 1], U[c, 0], U[c, 1])
        if not q > 0.0:
            return R_UVFLIP
        if not q > min_q:
            return R_UVQUALITY
        sa[a] += _angle(U[a, 0], U[a, 1], U[b, 0], U[b, 1], U[c, 0], U[c, 1])
        sa[b] += _angle(U[b, 0], U[b, 1], U[c, 0], U[c, 1], U[a, 0], U[a, 1])
        sa[c] += _angle(U[c, 0], U[c, 1], U[a, 0], U[a, 1], U[b, 0], U[b, 1])
    for L in range(nl):
        if inb[L] and ina[L]:
            if abs(sb[L] - sa[L]) > ANGLE_TOL:
                return R_UVOVERLAP
        elif inb[L]:
            if abs(sb[L] - expect[L]) > ANGLE_TOL:
                return R_UVOVERLAP
        elif ina[L]:
            if abs(sa[L] - expect[L]) > ANGLE_TOL:
                return R_UVOVERLAP
    return 0


@njit(cache=True, nogil=True)
def fan_sizes(F, FF, vf, n):
    """Number of faces reached by walking around every vertex from ``vf[v]`` (-1 if unused).

    On a manifold mesh this equals the vertex's face count; less means several fans meet at
    the vertex (a non-manifold vertex).
    """
    out = np.full(n, -1, dtype=np.int64)
    m = F.shape[0]
    for v in range(n):
        f0 = vf[v]
        if f0 < 0:
            continue
        # walk clockwise to the start of the fan
        f = f0
        boundary = False
        steps = 0
        while True:
            c = _corner(F, f, v)
            g = FF[f, c]
            if g < 0:
                boundary = True
                break
            if g == f0:
                break
            f = g
            steps += 1
            if steps > m:
                break
        start = f if boundary else f0
        cnt = 0
        f = start
        while True:
            cnt += 1
            c = _corner(F, f, v)
            g = FF[f, (c + 2) % 3]
            if g < 0 or g == start or cnt > m:
                break
            f = g
        out[v] = cnt
    return out


# ------------------------------------------------------------------------------ relocation
@njit(cache=True, nogil=True)
def relocate(b0, b1, b2, l0, l1, l2, U, al, aface, a0, a1, out):
    """Map a point (bary b in a before-face with locals l) through the shared UV domain.

    Writes (face id, bary0, bary1, bary2, smallest coordinate before clamping) into ``out`` (face
    id as float). A point exactly at a
    local vertex used after the collapse is snapped to that vertex (first after-face using it),
    so the result does not depend on which face the point was given in.
    """
    Lh = -1
    if b0 == 1.0 and b1 == 0.0 and b2 == 0.0:
        Lh = l0
    elif b1 == 1.0 and b0 == 0.0 and b2 == 0.0:
        Lh = l1
    elif b2 == 1.0 and b0 == 0.0 and b1 == 0.0:
        Lh = l2
    if Lh >= 0:
        for t in range(a0, a1):
            for c in range(3):
                if al[t, c] == Lh:
                    out[0] = aface[t]
                    out[1] = 0.0
                    out[2] = 0.0
                    out[3] = 0.0
                    out[1 + c] = 1.0
                    out[4] = 0.0
                    return
    x = b0 * U[l0, 0] + b1 * U[l1, 0] + b2 * U[l2, 0]
    y = b0 * U[l0, 1] + b1 * U[l1, 1] + b2 * U[l2, 1]
    best = -np.inf
    bt = a0
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    for t in range(a0, a1):
        p, q, r = al[t, 0], al[t, 1], al[t, 2]
        px, py = U[p, 0], U[p, 1]
        qx, qy = U[q, 0], U[q, 1]
        rx, ry = U[r, 0], U[r, 1]
        den = (qx - px) * (ry - py) - (qy - py) * (rx - px)
        if not den > 0.0:
            continue
        w0 = ((qx - x) * (ry - y) - (qy - y) * (rx - x)) / den
        w1 = ((rx - x) * (py - y) - (ry - y) * (px - x)) / den
        w2 = ((px - x) * (qy - y) - (py - y) * (qx - x)) / den
        m = min(w0, min(w1, w2))
        if m > best:
            best = m
            bt = t
            c0, c1, c2 = w0, w1, w2
    if c0 < 0.0:
        c0 = 0.0
    if c1 < 0.0:
        c1 = 0.0
    if c2 < 0.0:
        c2 = 0.0
    s = c0 + c1 + c2
    if not s > 0.0:
        c0, c1, c2, s = 1.0, 1.0, 1.0, 3.0
    out[4] = best
    out[0] = aface[bt]
    out[1] = c0 / s
    out[2] = c1 / s
    out[3] = c2 / s


@njit(cache=True, nogil=True)
def replay(K, bptr, bface, bloc, aptr, aface, aloc, uptr, uv, m, pf, pb, backwards):
    """Carry points (face ``pf``, bary ``pb``; modified in place) through ``K`` collapses.

    ``backwards`` runs the collapses last to first; call it with the before/after arrays swapped
    to carry coarse points back to the fine mesh (the inverse map).

    Returns the most negative barycentric coordinate clamped on the way (0 when none): a measure
    of how exactly the after-triangles tile the UV domain of the before-triangles.
    """
    npt = pf.shape[0]
    head = np.full(m, -1, dtype=np.int64)
    nxt = np.full(npt, -1, dtype=np.int64)
    for p in range(npt):
        f = pf[p]
        nxt[p] = head[f]
        head[f] = p
    tmp = np.empty(1024, dtype=np.int64)
    out = np.empty(5)
    worst = 0.0
    for cc in range(K):
        c = K - 1 - cc if backwards else cc
        u0 = uptr[c]
        U = uv[u0:uptr[c + 1]]
        a0 = aptr[c]
        a1 = aptr[c + 1]
        nt = 0
        for t in range(bptr[c], bptr[c + 1]):
            f = bface[t]
            p = head[f]
            while p >= 0:
                relocate(pb[p, 0], pb[p, 1], pb[p, 2], bloc[t, 0], bloc[t, 1], bloc[t, 2],
                         U, aloc, aface, a0, a1, out)
                pf[p] = int(out[0])
                if out[4] < worst:
                    worst = out[4]
                pb[p, 0] = out[1]
                pb[p, 1] = out[2]
                pb[p, 2] = out[3]
                if nt >= tmp.shape[0]:
                    t2 = np.empty(2 * tmp.shape[0], dtype=np.int64)
                    t2[:nt] = tmp[:nt]
                    tmp = t2
                tmp[nt] = p
                nt += 1
                p = nxt[p]
            head[f] = -1
        for s in range(nt):
            p = tmp[s]
            f = pf[p]
            nxt[p] = head[f]
            head[f] = p
    return worst


# ------------------------------------------------------------------------------ semi-random
RANDOM_MAX_FAILS = 2000  # failed semi-random attempts in a row before giving up


@njit(cache=True, nogil=True)
def seed_random(seed):
    """Seed the generator the semi-random collapses draw from (Numba's own, or NumPy's)."""
    np.random.seed(seed)


@njit(cache=True, nogil=True)
def _random_edge(F, falive, alist, nlist, P, Q, bnd, protect, strategy, pos, qs, k):
    """The cheapest of ``k`` random edges of live faces (-1, -1 when none has a finite cost)."""
    best = np.inf
    bu = -1
    bv = -1
    drawn = 0
    tries = 0
    while drawn < k and tries < 50 * k:
        tries += 1
        f = alist[np.random.randint(0, nlist)]
        if not falive[f]:
            continue
        drawn += 1
        c = np.random.randint(0, 3)
        u = F[f, c]
        v = F[f, (c + 1) % 3]
        cost, _k = edge_cost(u, v, P, Q, bnd, protect, strategy, pos, qs)
        if cost < best:
            best = cost
            bu = u
            bv = v
    return bu, bv


# ------------------------------------------------------------------------------ main loop
@njit(cache=True, nogil=True)
def _push_vertex_edges(w, skip, P, Q, F, FF, vf, bnd, protect, stamp, strategy,
                       hk, size, faces, corners, verts, pos, qs):
    nf, nv, _ = _ring(w, F, FF, vf, faces, corners, verts, CAP)
    if nf < 0:
        return size
    for t in range(nv):
        x = verts[t]
        if x == skip:
            continue
        cost, _k = edge_cost(w, x, P, Q, bnd, protect, strategy, pos, qs)
        if cost < np.inf and size < hk.shape[0]:
            size = _hpush(hk, size, cost, w, x, stamp[w], stamp[x])
    return size


@njit(cache=True, nogil=True)
def rebuild_heap(P, Q, F, FF, falive, valive, bnd, protect, stamp, strategy, hk):
    pos = np.empty(3)
    qs = np.empty(10)
    size = 0
    m = F.shape[0]
    for f in range(m):
        if not falive[f]:
            continue
        for c in range(3):
            g = FF[f, c]
            if g >= 0 and g < f:
                continue
            u = F[f, c]
            v = F[f, (c + 1) % 3]
            cost, _k = edge_cost(u, v, P, Q, bnd, protect, strategy, pos, qs)
            if cost < np.inf and size < hk.shape[0]:
                hk[size, 0] = cost
                hk[size, 1] = u
                hk[size, 2] = v
                hk[size, 3] = float((stamp[u] % _SMOD) * _SMOD + (stamp[v] % _SMOD))
                size += 1
    _hheapify(hk, size)
    return size


@njit(cache=True, nogil=True)
def collapse_loop(P, Q, F, FF, FFi, vf, falive, valive, bnd, protect, stamp, rej, loc, mark,
                  hk, st, counts,
                  bptr, bface, bloc, aptr, aface, aloc, uptr, uv,
                  strategy, target, min_q, min_dot, max_attempts, flattening, arap_iters,
                  random_candidates=0):
    """Collapse edges (cheapest first) with joint flattening until ``st[S_NF] <= target``.

    Returns 0 target reached, 1 attempt budget used (call again), 2 no valid collapse left,
    3 the log arrays need to grow (call again after growing them).

    ``random_candidates > 0`` (semi-random collapses, thesis App. 4.8.5): instead of the heap,
    each attempt draws that many random edges (a random live face and corner, with replacement)
    and tries the cheapest; after ``RANDOM_MAX_FAILS`` failed attempts in a row it returns 2.
    """
    ringA_f = np.empty(CAP, dtype=np.int64)
    ringA_c = np.empty(CAP, dtype=np.int64)
    ringA_v = np.empty(CAP + 1, dtype=np.int64)
    ringB_f = np.empty(CAP, dtype=np.int64)
    ringB_c = np.empty(CAP, dtype=np.int64)
    ringB_v = np.empty(CAP + 1, dtype=np.int64)
    tf = np.empty(CAP, dtype=np.int64)
    tc = np.empty(CAP, dtype=np.int64)
    tv = np.empty(CAP + 1, dtype=np.int64)
    pos = np.empty(3)
    qs = np.empty(10)
    LMAX = 2 * CAP + 4
    bfl = np.empty(2 * CAP, dtype=np.int64)
    bl = np.empty((2 * CAP, 3), dtype=np.int64)
    al = np.empty((2 * CAP, 3), dtype=np.int64)
    afl = np.empty(2 * CAP, dtype=np.int64)
    outer = np.empty(LMAX, dtype=np.int64)
    posb = np.empty((LMAX, 3))
    posa = np.empty((LMAX, 3))
    X = np.empty((3, 3))
    H = np.zeros((2 * LMAX, 2 * LMAX))
    Am = np.empty((2 * LMAX, 2 * LMAX))
    rhs = np.empty(2 * LMAX)
    free = np.empty(2 * LMAX, dtype=np.int64)
    fixed = np.zeros(2 * LMAX, dtype=np.bool_)
    fixval = np.zeros(2 * LMAX)
    xs = np.empty(2 * LMAX)
    Ubest = np.empty((LMAX, 2))
    Ucur = np.empty((LMAX, 2))
    inb = np.zeros(LMAX, dtype=np.bool_)
    ina = np.zeros(LMAX, dtype=np.bool_)
    expect = np.zeros(LMAX)
    sb = np.empty(LMAX)
    sa = np.empty(LMAX)
    shared = np.empty(2, dtype=np.int64)
    opp = np.empty(2, dtype=np.int64)
    tl = np.empty((4 * CAP, 3), dtype=np.int64)
    tX = np.empty((4 * CAP, 3, 3))
    Gs = np.empty((4 * CAP, 2, 3))
    At = np.empty(4 * CAP)
    lin = np.empty(2 * LMAX)

    attempts = 0
    size = st[S_HEAP]
    fails = 0
    alist = np.empty(F.shape[0] if random_candidates > 0 else 1, dtype=np.int64)
    nlist = -1  # the live-face list is built on the first semi-random attempt
    while st[S_NF] > target:
        if attempts >= max_attempts:
            st[S_HEAP] = size
            return 1
        if (st[S_NB] + 2 * CAP > bface.shape[0] or st[S_NA] + 2 * CAP > aface.shape[0]
                or st[S_NU] + LMAX > uv.shape[0] or st[S_K] + 2 > bptr.shape[0]):
            st[S_HEAP] = size
            return 3
        if random_candidates > 0:
            if fails >= RANDOM_MAX_FAILS:
                st[S_HEAP] = size
                return 2
            fails += 1
            if nlist < 0 or nlist > 2 * st[S_NF] + 16:
                nlist = 0
                for f in range(F.shape[0]):
                    if falive[f]:
                        alist[nlist] = f
                        nlist += 1
            u, v = _random_edge(F, falive, alist, nlist, P, Q, bnd, protect, strategy, pos, qs,
                                random_candidates)
            st[S_POPS] += 1
            if u < 0:
                continue
        else:
            if size == 0:
                if st[S_REBUILT] == 1 and st[S_SINCE] == 0:
                    st[S_HEAP] = 0
                    return 2
                rej[:] = False
                size = rebuild_heap(P, Q, F, FF, falive, valive, bnd, protect, stamp, strategy, hk)
                st[S_REBUILT] = 1
                st[S_SINCE] = 0
                if size == 0:
                    st[S_HEAP] = 0
                    return 2
                continue
            if size >= hk.shape[0] - 4 * CAP:
                size = _hcompact(hk, size, valive, stamp)
                if size >= hk.shape[0] - 4 * CAP:
                    size = rebuild_heap(P, Q, F, FF, falive, valive, bnd, protect, stamp, strategy,
                                        hk)
            cost, u, v, su, sv, size = _hpop(hk, size)
            st[S_POPS] += 1
            if not _hcurrent(u, v, su, sv, valive, stamp):
                continue
        attempts += 1
        cost, keep_u = edge_cost(u, v, P, Q, bnd, protect, strategy, pos, qs)
        if keep_u:
            i = u
            j = v
        else:
            i = v
            j = u
        nfi, nvi, bi = _ring(i, F, FF, vf, ringA_f, ringA_c, ringA_v, CAP)
        nfj, nvj, bj = _ring(j, F, FF, vf, ringB_f, ringB_c, ringB_v, CAP)
        if nfi < 0 or nfj < 0 or nfi + nfj > CAP:
            counts[R_VALENCE] += 1
            continue
        # shared faces and opposite corners
        ns = 0
        for t in range(nfi):
            f = ringA_f[t]
            if F[f, 0] == j or F[f, 1] == j or F[f, 2] == j:
                if ns < 2:
                    shared[ns] = f
                    opp[ns] = F[f, 0] + F[f, 1] + F[f, 2] - i - j
                ns += 1
        if ns == 0 or ns > 2:
            counts[R_LINK] += 1
            continue
        # link condition
        st[S_TAG] += 1
        tag = st[S_TAG]
        for t in range(nvi):
            mark[ringA_v[t]] = tag
        common = 0
        for t in range(nvj):
            w = ringB_v[t]
            if w != i and mark[w] == tag:
                common += 1
        ok = common == ns
        if ok and ns == 2 and opp[0] == opp[1]:
            ok = False
        if ok and ns == 2:
            if bi and bj:
                counts[R_PINCH] += 1
                continue
            for s in range(2):
                o = opp[s]
                if not bnd[o]:
                    no, _nv, _b = _ring(o, F, FF, vf, tf, tc, tv, CAP)
                    if no >= 0 and no <= 3:
                        ok = False
        if ok and ns == 1:
            f = shared[0]
            co = _corner(F, f, opp[0])
            if FF[f, co] < 0 and FF[f, (co + 2) % 3] < 0:
                ok = False
        if not ok:
            counts[R_LINK] += 1
            rej[u] = True
            rej[v] = True
            continue
        # 3D checks on the triangles that survive and change
        code = 0
        for side in range(2):
            if side == 0:
                nfs = nfi
                mv = i
            else:
                nfs = nfj
                mv = j
            for t in range(nfs):
                f = ringA_f[t] if side == 0 else ringB_f[t]
                if f == shared[0] or (ns == 2 and f == shared[1]):
                    continue
                c = _corner(F, f, mv)
                o1 = F[f, (c + 1) % 3]
                o2 = F[f, (c + 2) % 3]
                ex, ey, ez = P[o2, 0] - P[o1, 0], P[o2, 1] - P[o1, 1], P[o2, 2] - P[o1, 2]
                ax, ay, az = P[o1, 0] - P[mv, 0], P[o1, 1] - P[mv, 1], P[o1, 2] - P[mv, 2]
                nox, noy, noz = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
                bx, by, bz = P[o1, 0] - pos[0], P[o1, 1] - pos[1], P[o1, 2] - pos[2]
                nnx, nny, nnz = by * ez - bz * ey, bz * ex - bx * ez, bx * ey - by * ex
                nn2 = nnx * nnx + nny * nny + nnz * nnz
                no2 = nox * nox + noy * noy + noz * noz
                e2 = ex * ex + ey * ey + ez * ez
                if nn2 <= 1e-24 * e2 * e2:
                    code = R_QUALITY3D
                    break
                if no2 > 1e-24 * e2 * e2:
                    dot = nox * nnx + noy * nny + noz * nnz
                    if dot <= min_dot * math.sqrt(no2 * nn2):
                        code = R_FLIP3D
                        break
                q = _quality3(pos[0], pos[1], pos[2], P[o1, 0], P[o1, 1], P[o1, 2],
                              P[o2, 0], P[o2, 1], P[o2, 2])
                if not q > min_q:
                    code = R_QUALITY3D
                    break
            if code != 0:
                break
        if code != 0:
            counts[code] += 1
            rej[u] = True
            rej[v] = True
            continue
        # ---- local numbering: outer vertices 0..nb-1, then i, j, k
        nb = 0
        for t in range(nvi):
            w = ringA_v[t]
            if w != j and loc[w] < 0:
                loc[w] = nb
                outer[nb] = w
                nb += 1
        for t in range(nvj):
            w = ringB_v[t]
            if w != i and loc[w] < 0:
                loc[w] = nb
                outer[nb] = w
                nb += 1
        iL = nb
        jL = nb + 1
        nbf = 0
        for t in range(nfi):
            bfl[nbf] = ringA_f[t]
            nbf += 1
        for t in range(nfj):
            f = ringB_f[t]
            if f == shared[0] or (ns == 2 and f == shared[1]):
                continue
            bfl[nbf] = f
            nbf += 1
        for L in range(nb):
            w = outer[L]
            for d in range(3):
                posb[L, d] = P[w, d]
                posa[L, d] = P[w, d]
        for d in range(3):
            posb[iL, d] = P[i, d]
            posb[jL, d] = P[j, d]
        # boundary-edge data: a -> b the edge direction in its face, p before a, q after b
        nvar = 1
        aL = -1
        bL = -1
        pL = -1
        qL = -1
        va = -1
        vb = -1
        p = -1
        q = -1
        dpa = 0.0
        dab = 0.0
        dbq = 0.0
        if ns == 1:
            nvar = 3
            f = shared[0]
            ci = _corner(F, f, i)
            a_is_i = F[f, (ci + 1) % 3] == j
            if a_is_i:
                va, vb = i, j
            else:
                va, vb = j, i
            # p: boundary neighbour of va other than vb; q: of vb other than va
            if va == i:
                p = ringA_v[0] if ringA_v[0] != vb else ringA_v[nvi - 1]
                q = ringB_v[0] if ringB_v[0] != va else ringB_v[nvj - 1]
            else:
                p = ringB_v[0] if ringB_v[0] != vb else ringB_v[nvj - 1]
                q = ringA_v[0] if ringA_v[0] != va else ringA_v[nvi - 1]
            aL = iL if va == i else jL
            bL = jL if va == i else iL
            pL = loc[p]
            qL = loc[q]
            dpa = math.sqrt((P[p, 0] - P[va, 0]) ** 2 + (P[p, 1] - P[va, 1]) ** 2
                            + (P[p, 2] - P[va, 2]) ** 2)
            dab = math.sqrt((P[vb, 0] - P[va, 0]) ** 2 + (P[vb, 1] - P[va, 1]) ** 2
                            + (P[vb, 2] - P[va, 2]) ** 2)
            dbq = math.sqrt((P[q, 0] - P[vb, 0]) ** 2 + (P[q, 1] - P[vb, 1]) ** 2
                            + (P[q, 2] - P[vb, 2]) ** 2)
        best_e = np.inf
        best_code = R_SOLVE
        best_kL = -1
        best_var = -1
        best_nl = 0
        xpin = 0
        for var in range(nvar):
            # which local is k
            if ns == 2:
                if bi:
                    kL = iL
                elif bj:
                    kL = jL
                else:
                    kL = nb + 2
            elif var == 0:
                kL = aL
            elif var == 1:
                kL = bL
            else:
                kL = nb + 2
            nl = nb + 3 if kL == nb + 2 else nb + 2
            for d in range(3):
                posa[kL, d] = pos[d]
            # faces with local corners
            for t in range(nbf):
                f = bfl[t]
                for c in range(3):
                    w = F[f, c]
                    bl[t, c] = iL if w == i else (jL if w == j else loc[w])
            naf = 0
            for t in range(nbf):
                f = bfl[t]
                if f == shared[0] or (ns == 2 and f == shared[1]):
                    continue
                afl[naf] = f
                for c in range(3):
                    w = F[f, c]
                    al[naf, c] = kL if (w == i or w == j) else loc[w]
                naf += 1
            ncomp = 2 * nl
            for a in range(ncomp):
                for b in range(ncomp):
                    H[a, b] = 0.0
                fixed[a] = False
                fixval[a] = 0.0
            for L in range(nl):
                inb[L] = False
                ina[L] = False
            for t in range(nbf):
                for c in range(3):
                    L = bl[t, c]
                    inb[L] = True
                    for d in range(3):
                        X[c, d] = posb[L, d]
                _lscm_add(H, X, bl[t, 0], bl[t, 1], bl[t, 2])
            for t in range(naf):
                for c in range(3):
                    L = al[t, c]
                    ina[L] = True
                    for d in range(3):
                        X[c, d] = posa[L, d]
                _lscm_add(H, X, al[t, 0], al[t, 1], al[t, 2])
            # expected angle sums of one-sided vertices
            expect[iL] = math.pi if bi else TWO_PI
            expect[jL] = math.pi if bj else TWO_PI
            if kL == nb + 2:
                expect[kL] = math.pi if (bi or bj) else TWO_PI
            # constraints
            if ns == 2 and not (bi or bj):
                w0 = outer[0]
                w1 = outer[1]
                dd = math.sqrt((P[w1, 0] - P[w0, 0]) ** 2 + (P[w1, 1] - P[w0, 1]) ** 2
                               + (P[w1, 2] - P[w0, 2]) ** 2)
                fixed[0] = True
                fixed[1] = True
                fixed[2] = True
                fixed[3] = True
                fixval[2] = dd if dd > 0 else 1.0
                xpin = 2
            elif ns == 2:
                w0 = outer[0]
                ve = i if kL == iL else j
                dd = math.sqrt((P[w0, 0] - P[ve, 0]) ** 2 + (P[w0, 1] - P[ve, 1]) ** 2
                               + (P[w0, 2] - P[ve, 2]) ** 2)
                fixed[2 * kL] = True
                fixed[2 * kL + 1] = True
                fixed[0] = True
                fixed[1] = True
                fixval[0] = dd if dd > 0 else 1.0
                xpin = 0
            elif var == 0:  # k at a: (a, b, q) colinear
                fixed[2 * aL] = True
                fixed[2 * aL + 1] = True
                fixed[2 * qL] = True
                fixed[2 * qL + 1] = True
                fixval[2 * qL] = dab + dbq
                fixed[2 * bL + 1] = True
                xpin = 2 * qL
            elif var == 1:  # k at b: (p, a, b) colinear
                fixed[2 * pL] = True
                fixed[2 * pL + 1] = True
                fixed[2 * bL] = True
                fixed[2 * bL + 1] = True
                fixval[2 * bL] = dpa + dab
                fixed[2 * aL + 1] = True
                xpin = 2 * bL
            else:  # (p, a, k, b, q) colinear
                fixed[2 * pL] = True
                fixed[2 * pL + 1] = True
                fixed[2 * qL] = True
                fixed[2 * qL + 1] = True
                fixval[2 * qL] = dpa + dab + dbq
                fixed[2 * aL + 1] = True
                fixed[2 * bL + 1] = True
                fixed[2 * kL + 1] = True
                xpin = 2 * qL
            oks, e = lscm_solve(H, ncomp, fixed, fixval, xs, Am, rhs, free)
            if oks:
                for L in range(nl):
                    Ucur[L, 0] = xs[2 * L]
                    Ucur[L, 1] = xs[2 * L + 1]
            if oks and flattening == 1:
                # ARAP: start from LSCM, let the scale free (the second pin slides on its line)
                fixed[xpin] = False
                nt = 0
                for t in range(nbf):
                    for c in range(3):
                        L = bl[t, c]
                        tl[nt, c] = L
                        for d in range(3):
                            tX[nt, c, d] = posb[L, d]
                    nt += 1
                for t in range(naf):
                    for c in range(3):
                        L = al[t, c]
                        tl[nt, c] = L
                        for d in range(3):
                            tX[nt, c, d] = posa[L, d]
                    nt += 1
                oks, e = arap_refine(Ucur, nl, tl, tX, nt, fixed, fixval, arap_iters, H, Am,
                                     rhs, free, lin, Gs, At)
            if not oks:
                code = R_SOLVE
            else:
                code = 0
                if ns == 1:
                    # order along the straight boundary
                    xp = Ucur[pL, 0]
                    xa = Ucur[aL, 0]
                    xb = Ucur[bL, 0]
                    xq = Ucur[qL, 0]
                    xk = Ucur[kL, 0]
                    if var == 0:
                        good = xa < xb and xb < xq
                    elif var == 1:
                        good = xp < xa and xa < xb
                    else:
                        good = xp < xa and xa < xb and xb < xq and xp < xk and xk < xq
                    if not good:
                        code = R_BORDER
                if code == 0:
                    code = check_uv(Ucur, nl, bl, nbf, al, naf, inb, ina, expect, min_q, sb, sa)
            if code == 0:
                if e < best_e:
                    best_e = e
                    best_kL = kL
                    best_var = var
                    best_nl = nl
                    for L in range(nl):
                        Ubest[L, 0] = Ucur[L, 0]
                        Ubest[L, 1] = Ucur[L, 1]
            elif best_kL < 0:
                best_code = code
        if best_kL < 0:
            for L in range(nb):
                loc[outer[L]] = -1
            counts[best_code] += 1
            rej[u] = True
            rej[v] = True
            continue
        # ---- accepted: log the joint flattening
        kL = best_kL
        nl = best_nl
        if ns == 2:
            if bi or bj:
                counts[C_ONE_BOUNDARY] += 1
            else:
                counts[C_INTERIOR] += 1
        else:
            counts[C_VAR1 + best_var] += 1
        K = st[S_K]
        nB = st[S_NB]
        nA = st[S_NA]
        nU = st[S_NU]
        for t in range(nbf):
            f = bfl[t]
            bface[nB] = f
            for c in range(3):
                w = F[f, c]
                bloc[nB, c] = iL if w == i else (jL if w == j else loc[w])
            if not (f == shared[0] or (ns == 2 and f == shared[1])):
                aface[nA] = f
                for c in range(3):
                    w = F[f, c]
                    aloc[nA, c] = kL if (w == i or w == j) else loc[w]
                nA += 1
            nB += 1
        for L in range(nl):
            uv[nU, 0] = Ubest[L, 0]
            uv[nU, 1] = Ubest[L, 1]
            nU += 1
        bptr[K + 1] = nB
        aptr[K + 1] = nA
        uptr[K + 1] = nU
        st[S_NB] = nB
        st[S_NA] = nA
        st[S_NU] = nU
        st[S_K] = K + 1
        for L in range(nb):
            loc[outer[L]] = -1
        # ---- commit the collapse on the corner table
        for s in range(ns):
            f = shared[s]
            co = _corner(F, f, opp[s])
            g1 = FF[f, co]
            e1 = FFi[f, co]
            g2 = FF[f, (co + 2) % 3]
            e2 = FFi[f, (co + 2) % 3]
            if g1 >= 0:
                FF[g1, e1] = g2
                FFi[g1, e1] = e2
            if g2 >= 0:
                FF[g2, e2] = g1
                FFi[g2, e2] = e1
            falive[f] = False
            vf[opp[s]] = g1 if g1 >= 0 else g2
        for t in range(nfj):
            f = ringB_f[t]
            if f == shared[0] or (ns == 2 and f == shared[1]):
                continue
            F[f, ringB_c[t]] = i
        for t in range(nbf):
            f = bfl[t]
            if falive[f]:
                vf[i] = f
                break
        for d in range(3):
            P[i, d] = pos[d]
        for k in range(10):
            Q[i, k] += Q[j, k]
        bnd[i] = bi or bj
        valive[j] = False
        stamp[i] += 1
        stamp[j] += 1
        rej[i] = False
        rej[j] = False
        st[S_NF] -= ns
        st[S_SINCE] += 1
        fails = 0
        # ---- new candidate edges
        nfk, nvk, _b = _ring(i, F, FF, vf, ringA_f, ringA_c, ringA_v, CAP)
        if nfk >= 0 and random_candidates == 0:
            for t in range(nvk):
                w = ringA_v[t]
                if rej[w]:
                    rej[w] = False
                    stamp[w] += 1
                    size = _push_vertex_edges(w, i, P, Q, F, FF, vf, bnd, protect, stamp,
                                              strategy, hk, size,
                                              tf, tc, tv, pos, qs)
            for t in range(nvk):
                w = ringA_v[t]
                cst, _k = edge_cost(i, w, P, Q, bnd, protect, strategy, pos, qs)
                if cst < np.inf and size < hk.shape[0]:
                    size = _hpush(hk, size, cst, i, w, stamp[i], stamp[w])
    st[S_HEAP] = size
    return 0
