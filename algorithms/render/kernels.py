"""Compiled (Numba) kernels of the renderer: projection, rasterizer (two passes with an exact
tile occlusion test, see :func:`rasterize`), seen faces, painting, the per-face pixel sums and the
normal derivative of :mod:`algorithms.render.render` (with Lambertian shading folded in), and the
spherical-harmonics shading and its derivatives of :mod:`algorithms.render.sh`.

Importing this module imports :mod:`numba`; :mod:`algorithms.render.raster` loads it lazily
through :class:`algorithms.compiled.KernelModule` and falls back to its NumPy code when it
is unavailable or switched off (``STYLIZE3D_NUMBA=0``). ``@njit(cache=True, nogil=True)``, one
thread except the normal derivative's per-face terms (Numba threads, issue 25: the terms are
added up in face order afterwards, so the same bits for any thread count), ``fastmath`` off (no FMA contraction, so the projection is bit-identical to
:meth:`Camera.to_pixels`). Same rules as the NumPy code (see :mod:`algorithms.render.raster`):
pixel centres at integer coordinates, a pixel is covered when its three barycentric coordinates are
``>= 0``, the nearest depth ``> near`` wins, ties go to the lower face index. Each kernel's
formulas are derived in the docstring of the module whose NumPy code it replaces.
"""

from __future__ import annotations

import math

import numpy as np
from .._numba import njit, prange

from ..compiled import use_threads

VJP_CHUNK = 1024
"""Faces per work unit of the threaded normal derivative (fixed: the split does not depend on
the number of threads)."""

__all__ = ["project", "rasterize", "project_rasterize", "barycentrics", "barycentrics_q",
           "seen_faces", "seen_faces_among", "seen_lookup", "slot_paint", "face_normals",
           "lambert_colors", "lambert_render", "paint", "face_sums", "normal_vjp",
           "lambert_normal_vjp", "lambert_image_vjp",
           "sh_values_t", "sh_normal_vjp"]


@njit(cache=True, nogil=True, error_model="numpy")
def project(V, position, basis, perspective, scale, res, out):  # pragma: no cover - compiled
    """:meth:`Camera.to_pixels` of ``V (n, 3)`` into ``out (n, 3)`` (same operations in the same
    order: bit-identical). ``scale``: ``tan(fov / 2)`` (perspective) or ``width / 2``."""
    Q = np.empty((3, V.shape[0]))
    _project(V, position, basis, perspective, scale, res, Q)
    out[:, :] = Q.T


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _project(V, position, basis, perspective, scale, res, Q):  # pragma: no cover - compiled
    """:func:`project` into the rows of ``Q (3, n)`` (column, row, depth: contiguous, so that the
    loop vectorizes)."""
    px = position[0]
    py = position[1]
    pz = position[2]
    r00 = basis[0, 0]
    r01 = basis[0, 1]
    r02 = basis[0, 2]
    r10 = basis[1, 0]
    r11 = basis[1, 1]
    r12 = basis[1, 2]
    r20 = basis[2, 0]
    r21 = basis[2, 1]
    r22 = basis[2, 2]
    n = V.shape[0]
    Vf = V.reshape(-1)
    X = Q[0]
    Y = Q[1]
    Z = Q[2]
    if perspective:
        for i in range(n):
            dx = Vf[3 * i] - px
            dy = Vf[3 * i + 1] - py
            dz = Vf[3 * i + 2] - pz
            cx = dx * r00 + dy * r01 + dz * r02
            cy = dx * r10 + dy * r11 + dz * r12
            cz = dx * r20 + dy * r21 + dz * r22
            sx = cx / (cz * scale)
            sy = cy / (cz * scale)
            X[i] = (sx + 1.0) * 0.5 * res - 0.5
            Y[i] = (1.0 - sy) * 0.5 * res - 0.5
            Z[i] = cz
    else:
        for i in range(n):
            dx = Vf[3 * i] - px
            dy = Vf[3 * i + 1] - py
            dz = Vf[3 * i + 2] - pz
            cx = dx * r00 + dy * r01 + dz * r02
            cy = dx * r10 + dy * r11 + dz * r12
            cz = dx * r20 + dy * r21 + dz * r22
            sx = cx / scale
            sy = cy / scale
            X[i] = (sx + 1.0) * 0.5 * res - 0.5
            Y[i] = (1.0 - sy) * 0.5 * res - 0.5
            Z[i] = cz


@njit(cache=True, nogil=True, inline="always")
def _outcodes(Q, res):  # pragma: no cover - compiled
    """``(n,) uint8`` outcodes (:func:`_outcode`) of the projected vertices ``Q (3, n)``."""
    n = Q.shape[1]
    code = np.empty(n, np.uint8)
    hi = res - 1.0
    X = Q[0]
    Y = Q[1]
    for v in range(n):
        code[v] = _outcode(X[v], Y[v], hi)
    return code


@njit(cache=True, nogil=True, inline="always")
def _outcode(x, y, hi):  # pragma: no cover - compiled
    """Cohen-Sutherland outcode of a projected vertex: bits for left of column 0, right of column
    ``hi``, above row 0, below row ``hi`` (NaN: 0)."""
    k = 0
    if x < 0.0:
        k |= 1
    if x > hi:
        k |= 2
    if y < 0.0:
        k |= 4
    if y > hi:
        k |= 8
    return k


_LANES = 12      # pixels per vector step of a row: three 4-wide vectors, no remainder
_TILE = 3        # log2 of the tile side of the occlusion test (8 x 8 pixels)


@njit(cache=True, nogil=True)
def rasterize(P, F, res, perspective, near, face_id, depth, bary):  # pragma: no cover - compiled
    """Z-buffer ``F`` with vertices ``P (n, 3)`` = (column, row, depth) into ``face_id`` and
    ``depth (res, res)`` (C-contiguous; every pixel is written: -1 / inf for background) and,
    when ``bary`` has shape ``(res, res, 3)``, the barycentrics (an empty ``bary`` of shape
    ``(0, 0, 3)`` leaves them to :func:`barycentrics`). Returns the sorted ids of the faces that
    were rasterized (the only ones that can be seen: :func:`seen_faces_among`).

    Same picture as testing every face against every pixel centre of its bounding box in index
    order (the NumPy code), bit for bit; what is skipped cannot change it:

    * Outcodes (Cohen-Sutherland): a face whose three corners are all left of, right of, above or
      below the pixel centres is skipped after reading three bytes (NaN -> code 0); then the
      NumPy code's rejections (behind ``near``, non-finite corner, no pixel centre in the
      bounding box, zero or non-finite area).
    * Two passes: first the faces of one orientation in screen space (sign of the projected
      area), then the others, each in index order; the first pass is the orientation whose faces
      are nearer on average (area-weighted), i.e. the front faces of a closed mesh seen from
      outside. Equal depths go to the lower face index: within a pass by the index order, in the
      second pass also by comparing the index with the first pass's winner, so the passes do not
      change the picture.
    * Occlusion test of the second pass (usually the back faces): after the first pass, the
      farthest depth of each 8 x 8 tile (inf where a pixel is still background); a face whose
      smallest corner depth, less a margin far larger than the rounding of the interpolated
      depth (``1e-9 max |z_i|``), is beyond that of every tile its bounding box meets cannot win
      a pixel (the interpolated depth of a covered pixel is a convex combination of the corner
      depths, in ``1/z`` for perspective cameras: tested only when the corner depths are all
      positive) and is skipped. Nothing is culled by orientation: open meshes,
      self-intersecting meshes and cameras inside the mesh see their back faces as before.
    * Rows: each row's columns where the three edge functions can be ``>= 0`` are found from the
      edges' intersections with the row, widened by one pixel on each side (edges within 1e-6
      pixels of horizontal bound nothing); the exact test (the NumPy formulas, same operands and
      order) decides every pixel, 12 pixels at a time (vectorized; pixels outside the row's span
      are masked off)."""
    Q = P.T.copy()
    return _zbuffer(Q, F, _outcodes(Q, res), res, perspective, near, face_id, depth, bary)


@njit(cache=True, nogil=True)
def project_rasterize(V, position, basis, perspective, scale, res, near, F, Q, face_id, depth,
                      bary):  # pragma: no cover - compiled
    """:func:`project` of ``V`` into the rows of ``Q (3, n)`` (column, row, depth; ``P = Q.T``)
    and :func:`rasterize` of ``(P, F)``; returns what :func:`rasterize` returns."""
    _project(V, position, basis, perspective, scale, res, Q)
    return _zbuffer(Q, F, _outcodes(Q, res), res, perspective, near, face_id, depth, bary)


@njit(cache=True, nogil=True)
def _zbuffer(Q, F, code, res, perspective, near, face_id, depth, bary):  # pragma: no cover
    """:func:`rasterize` of the projected vertices ``Q (3, n)`` given their outcodes."""
    X = Q[0]
    Y = Q[1]
    Z = Q[2]
    hi = res - 1.0
    zbuf = depth.reshape(-1)           # flat views (C-contiguous): no view per row
    fbuf = face_id.reshape(-1)
    zbuf[:] = np.inf
    fbuf[:] = -1
    m = F.shape[0]
    neg = np.empty(m, np.int64)
    pos = np.empty(m, np.int64)
    box = np.empty((m, 4), np.int32)
    zlow = np.empty(m)
    nneg = 0
    npos = 0
    zneg = 0.0          # sums of |area| * (z0 + z1 + z2) and of |area| per orientation
    zpos = 0.0
    aneg = 0.0
    apos = 0.0
    for f in range(m):
        a = F[f, 0]
        b = F[f, 1]
        c = F[f, 2]
        if code[a] & code[b] & code[c]:
            continue
        x0 = X[a]
        y0 = Y[a]
        z0 = Z[a]
        x1 = X[b]
        y1 = Y[b]
        z1 = Z[b]
        x2 = X[c]
        y2 = Y[c]
        z2 = Z[c]
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
        if xmax < 0.0 or ymax < 0.0 or xmin > hi or ymin > hi:
            continue
        fi0 = math.ceil(max(ymin, 0.0))
        fi1 = math.floor(min(ymax, hi))
        fj0 = math.ceil(max(xmin, 0.0))
        fj1 = math.floor(min(xmax, hi))
        if fi1 < fi0 or fj1 < fj0:
            continue                    # no pixel centre in the bounding box (small faces)
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0 or not math.isfinite(area):
            continue
        zs = z0 + z1 + z2
        if area < 0.0:
            k = nneg
            neg[nneg] = f
            nneg += 1
            zneg -= area * zs
            aneg -= area
        else:
            k = m - 1 - npos
            pos[npos] = f
            npos += 1
            zpos += area * zs
            apos += area
        # the pixel box and the occlusion test's depth bound, kept for the passes (the
        # negative faces' from the start of the arrays, the positive faces' from the end)
        box[k, 0] = int(fi0)
        box[k, 1] = int(fi1)
        box[k, 2] = int(fj0)
        box[k, 3] = int(fj1)
        zmin = min(z0, min(z1, z2))
        if perspective and not zmin > 0.0:
            zlow[k] = -np.inf           # not tested (NaN: never occluded either)
        else:
            zlow[k] = zmin - 1e-9 * max(abs(z0), max(abs(z1), abs(z2)))
    first = neg
    nfirst = nneg
    second = pos
    nsecond = npos
    rev1 = False                        # whether the first list's boxes are stored from the end
    if zpos * aneg < zneg * apos:       # the positive faces are nearer on average
        first = pos
        nfirst = npos
        second = neg
        nsecond = nneg
        rev1 = True
    # The face and row loops are written out here, not in helper functions: Numba's inlining
    # of functions taking arrays adds reference counting (atomic) per call, per face and row.
    T = _TILE
    nt = (res + (1 << T) - 1) >> T
    tmax = np.full((nt, nt), -np.inf)
    # a lane count LLVM cannot bound (``res >> 40`` is 0): with a constant it unrolls the row
    # loop fully and then does not vectorize it. 12 = three 4-wide vectors and no scalar
    # remainder: most rows of these small faces take one step (measured, fandisk 256^2:
    # rasterize 0.80 -> 0.74 ms; 8 or 16 lanes about 0.80, 10 or 14 slower)
    L = max(_LANES, res >> 40)
    if res < L:
        L = res
    UL = np.uint64(L)
    kept = 0
    for pss in range(2):
        ties = pss == 1
        count = nfirst
        if ties:
            count = nsecond
            if nsecond > 0:
                _tile_maxima(zbuf, res, T, tmax)
        rev = rev1 != ties
        for q in range(count):
            f = second[q] if ties else first[q]
            k = m - 1 - q if rev else q
            i0 = np.int64(box[k, 0])
            i1 = np.int64(box[k, 1])
            j0 = np.int64(box[k, 2])
            j1 = np.int64(box[k, 3])
            if ties:
                # occlusion test (see the docstring); NaN depths are never occluded
                zlo = zlow[k]
                occluded = zlo > -np.inf
                ti = i0 >> T
                while occluded and ti <= i1 >> T:
                    tj = j0 >> T
                    while occluded and tj <= j1 >> T:
                        occluded = zlo > tmax[ti, tj]
                        tj += 1
                    ti += 1
                if occluded:
                    continue
                second[kept] = f
                kept += 1
            a = F[f, 0]
            b = F[f, 1]
            c = F[f, 2]
            x0 = X[a]
            y0 = Y[a]
            z0 = Z[a]
            x1 = X[b]
            y1 = Y[b]
            z1 = Z[b]
            x2 = X[c]
            y2 = Y[c]
            z2 = Z[c]
            area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
            inv = 1.0 / area
            # Edge from corner a to corner b (a = e + 1, b = e + 2 mod 3; w_e = 0 on it): at row
            # py it crosses column xa + (py - ya) k, k = (xb - xa) / (yb - ya); w_e >= 0 right of
            # it when (ya - yb) * area > 0 (a lower bound of the span), left of it otherwise.
            lx0 = -1e300
            ly0 = 0.0
            lk0 = 0.0
            lx1 = -1e300
            ly1 = 0.0
            lk1 = 0.0
            ux0 = 1e300
            uy0 = 0.0
            uk0 = 0.0
            ux1 = 1e300
            uy1 = 0.0
            uk1 = 0.0
            nl = 0
            nu = 0
            if j1 - j0 >= L:            # narrow boxes: no span needed (spans for boxes of 9
                #                             to 12 columns too measured slower)
                for e in range(3):
                    if e == 0:
                        xa = x1
                        ya = y1
                        xb = x2
                        yb = y2
                    elif e == 1:
                        xa = x2
                        ya = y2
                        xb = x0
                        yb = y0
                    else:
                        xa = x0
                        ya = y0
                        xb = x1
                        yb = y1
                    dy = yb - ya
                    if not abs(dy) >= 1e-6:
                        continue
                    k = (xb - xa) / dy
                    if (ya - yb) * area > 0.0:
                        if nl == 0:
                            lx0 = xa
                            ly0 = ya
                            lk0 = k
                        else:
                            lx1 = xa
                            ly1 = ya
                            lk1 = k
                        nl += 1
                    else:
                        if nu == 0:
                            ux0 = xa
                            uy0 = ya
                            uk0 = k
                        else:
                            ux1 = xa
                            uy1 = ya
                            uk1 = k
                        nu += 1
            fj0 = float(j0)
            fj1 = float(j1)
            for i in range(i0, i1 + 1):
                py = float(i)
                lo = j0
                hi = j1
                if nl + nu > 0:
                    tl = max(lx0 + (py - ly0) * lk0, lx1 + (py - ly1) * lk1)
                    tu = min(ux0 + (py - uy0) * uk0, ux1 + (py - uy1) * uk1)
                    flo = math.ceil(tl) - 1.0
                    fhi = math.floor(tu) + 1.0
                    if not (flo > fj0 and math.isfinite(tl)):   # overflow or NaN: the whole box
                        flo = fj0
                    if not (fhi < fj1 and math.isfinite(tu)):
                        fhi = fj1
                    if fhi < flo:
                        continue
                    lo = int(flo)
                    hi = int(fhi)
                # The exact coverage and depth test (the NumPy formulas) of pixels lo..hi: steps
                # of L pixels from min(s, res - L) (inside the row; pixels outside s..hi are
                # masked off), a loop of fixed length that vectorizes (unsigned indices: no
                # negative-index wraparound).
                a2 = y2 - py
                a1 = y1 - py
                a0 = y0 - py
                base = i * res
                s = lo
                while s <= hi:
                    b0 = min(s - (s & 3), res - L)   # 4-aligned: stores forward to loads
                    u = np.uint64(base + b0)
                    fs = float(s)
                    fh = float(hi)
                    fb = float(b0)
                    if perspective:
                        for t in range(UL):
                            px = fb + t
                            w0 = ((x1 - px) * a2 - (x2 - px) * a1) * inv
                            w1 = ((x2 - px) * a0 - (x0 - px) * a2) * inv
                            w2 = 1.0 - w0 - w1
                            z = 1.0 / (w0 / z0 + w1 / z1 + w2 / z2)
                            old = zbuf[u + t]
                            oldf = fbuf[u + t]
                            ok = ((px >= fs) & (px <= fh) & (w0 >= 0.0) & (w1 >= 0.0)
                                  & (w2 >= 0.0) & (z > near)
                                  & ((z < old) | (ties & (z == old) & (f < oldf))))
                            zbuf[u + t] = z if ok else old
                            fbuf[u + t] = f if ok else oldf
                    elif ties:            # orthographic, second pass
                        for t in range(UL):
                            px = fb + t
                            w0 = ((x1 - px) * a2 - (x2 - px) * a1) * inv
                            w1 = ((x2 - px) * a0 - (x0 - px) * a2) * inv
                            w2 = 1.0 - w0 - w1
                            z = w0 * z0 + w1 * z1 + w2 * z2
                            old = zbuf[u + t]
                            oldf = fbuf[u + t]
                            ok = ((px >= fs) & (px <= fh) & (w0 >= 0.0) & (w1 >= 0.0)
                                  & (w2 >= 0.0) & (z > near)
                                  & ((z < old) | ((z == old) & (f < oldf))))
                            zbuf[u + t] = z if ok else old
                            fbuf[u + t] = f if ok else oldf
                    else:
                        # orthographic, first pass: no ties to break (index order), no tie test
                        # (~1% faster; the same split of the perspective loop measured slower)
                        for t in range(UL):
                            px = fb + t
                            w0 = ((x1 - px) * a2 - (x2 - px) * a1) * inv
                            w1 = ((x2 - px) * a0 - (x0 - px) * a2) * inv
                            w2 = 1.0 - w0 - w1
                            z = w0 * z0 + w1 * z1 + w2 * z2
                            old = zbuf[u + t]
                            ok = ((px >= fs) & (px <= fh) & (w0 >= 0.0) & (w1 >= 0.0)
                                  & (w2 >= 0.0) & (z > near) & (z < old))
                            zbuf[u + t] = z if ok else old
                            fbuf[u + t] = f if ok else fbuf[u + t]
                    s = b0 + L
    # the faces rasterized, sorted (both lists are)
    out = np.empty(nfirst + kept, np.int64)
    ia = 0
    ib = 0
    for q in range(nfirst + kept):
        if ib >= kept or (ia < nfirst and first[ia] < second[ib]):
            out[q] = first[ia]
            ia += 1
        else:
            out[q] = second[ib]
            ib += 1
    if bary.shape[0] == res:
        for i in range(res):
            for j in range(res):
                _bary_at(Q, F, face_id[i, j], i, j, perspective, bary)
    return out


@njit(cache=True, nogil=True)
def _tile_maxima(zbuf, res, T, tmax):  # pragma: no cover - compiled
    """``tmax (nt, nt)``: the largest depth of each ``2^T x 2^T`` tile of the flat depth buffer
    (column maxima of a tile row elementwise, which vectorizes, then per tile)."""
    nt = tmax.shape[0]
    colmax = np.empty(nt << T)
    colmax[res:] = -np.inf
    for ti in range(nt):
        r0 = ti << T
        r1 = min(res, r0 + (1 << T))
        colmax[:res] = zbuf[r0 * res:(r0 + 1) * res]
        for i in range(r0 + 1, r1):
            drow = zbuf[i * res:(i + 1) * res]
            for j in range(res):
                d = drow[j]
                colmax[j] = d if d > colmax[j] else colmax[j]
        for tj in range(nt):
            mx = -np.inf
            for j in range(tj << T, (tj + 1) << T):
                mx = colmax[j] if colmax[j] > mx else mx
            tmax[ti, tj] = mx


@njit(cache=True, nogil=True, inline="always")
def _bary_at(Q, F, f, i, j, perspective, bary):  # pragma: no cover - compiled
    """``bary[i, j]``: barycentrics of pixel ``(i, j)`` in face ``f`` (0 for ``f < 0``)."""
    if f < 0:
        bary[i, j, 0] = 0.0
        bary[i, j, 1] = 0.0
        bary[i, j, 2] = 0.0
        return
    a = F[f, 0]
    b = F[f, 1]
    c = F[f, 2]
    x0 = Q[0, a]
    y0 = Q[1, a]
    x1 = Q[0, b]
    y1 = Q[1, b]
    x2 = Q[0, c]
    y2 = Q[1, c]
    inv = 1.0 / ((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0))
    px = float(j)
    py = float(i)
    w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) * inv
    w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) * inv
    w2 = 1.0 - w0 - w1
    if perspective:
        q0 = w0 / Q[2, a]
        q1 = w1 / Q[2, b]
        q2 = w2 / Q[2, c]
        z = 1.0 / (q0 + q1 + q2)
        w0 = q0 * z
        w1 = q1 * z
        w2 = q2 * z
    bary[i, j, 0] = w0
    bary[i, j, 1] = w1
    bary[i, j, 2] = w2


@njit(cache=True, nogil=True)
def barycentrics(P, F, face_id, perspective, bary):  # pragma: no cover - compiled
    """``bary (H, W, 3)`` of the faces ``face_id`` seen (as :func:`rasterize` computes them)."""
    barycentrics_q(P.T.copy(), F, face_id, perspective, bary)


@njit(cache=True, nogil=True)
def barycentrics_q(Q, F, face_id, perspective, bary):  # pragma: no cover - compiled
    """:func:`barycentrics` of the projected vertices ``Q (3, n)`` (``P = Q.T``)."""
    H, W = face_id.shape
    for i in range(H):
        for j in range(W):
            _bary_at(Q, F, face_id[i, j], i, j, perspective, bary)


@njit(cache=True, nogil=True)
def seen_faces(face_id, m, slot):  # pragma: no cover - compiled
    """Sorted ids of the faces seen in ``face_id (H, W)`` (of ``m`` faces); fills ``slot (H, W)``
    with each pixel's index into them (-1 for background). O(pixels + m)."""
    return seen_faces_among(face_id, np.arange(m), m, slot)


@njit(cache=True, nogil=True)
def seen_faces_among(face_id, cand, m, slot):  # pragma: no cover - compiled
    """:func:`seen_faces` when every face id in ``face_id`` is in ``cand`` (sorted; e.g. what
    :func:`rasterize` returned): O(pixels + len(cand)), whatever ``m``."""
    faces, lookup = seen_lookup(face_id, cand, m)
    fid = face_id.reshape(-1)
    sl = slot.reshape(-1)
    for p in range(fid.shape[0]):
        f = fid[p]
        sl[p] = lookup[f] if f >= 0 else -1
    return faces


@njit(cache=True, nogil=True)
def seen_lookup(face_id, cand, m):  # pragma: no cover - compiled
    """The sorted faces seen in ``face_id`` (every id in it is in the sorted ``cand``) and a
    lookup ``(m,)`` whose entry of each seen face is its index among them (other entries
    undefined): the first half of :func:`seen_faces_among`; :func:`slot_paint` does the rest."""
    lookup = np.empty(m, np.int64)
    for q in range(cand.shape[0]):
        lookup[cand[q]] = 0
    fid = face_id.reshape(-1)
    for p in range(fid.shape[0]):
        f = fid[p]
        if f >= 0:
            lookup[f] = 1
    faces = np.empty(cand.shape[0], np.int64)
    k = 0
    for q in range(cand.shape[0]):
        f = cand[q]
        if lookup[f] != 0:
            faces[k] = f
            lookup[f] = k
            k += 1
    return faces[:k].copy(), lookup


@njit(cache=True, nogil=True)
def slot_paint(face_id, lookup, colors, background, slot, image):  # pragma: no cover - compiled
    """``slot (H, W)`` from :func:`seen_lookup`'s lookup and :func:`paint` of ``image (H, W, C)``
    in the same pass over the pixels."""
    C = colors.shape[1]
    fid = face_id.reshape(-1)
    sl = slot.reshape(-1)
    img = image.reshape(-1)
    if C == 3:                          # RGB: unrolled
        for p in range(fid.shape[0]):
            f = fid[p]
            if f >= 0:
                s = lookup[f]
                sl[p] = s
                img[3 * p] = colors[s, 0]
                img[3 * p + 1] = colors[s, 1]
                img[3 * p + 2] = colors[s, 2]
            else:
                sl[p] = -1
                img[3 * p] = background
                img[3 * p + 1] = background
                img[3 * p + 2] = background
        return
    for p in range(fid.shape[0]):
        f = fid[p]
        if f >= 0:
            s = lookup[f]
            sl[p] = s
            for c in range(C):
                img[C * p + c] = colors[s, c]
        else:
            sl[p] = -1
            for c in range(C):
                img[C * p + c] = background


@njit(cache=True, nogil=True)
def lambert_render(V, F, face_id, cand, m, M, scale, offset, background):  # pragma: no cover
    """:func:`seen_lookup`, :func:`lambert_colors` and :func:`slot_paint` in one call. Returns
    the seen faces, their normals and colours, the slots ``(H, W)`` and the image
    ``(H, W, C)``."""
    faces, lookup = seen_lookup(face_id, cand, m)
    k = faces.shape[0]
    C = M.shape[1]
    N = np.empty((k, 3))
    colors = np.empty((k, C))
    lambert_colors(V, F, faces, M, scale, offset, N, colors)
    H, W = face_id.shape
    slot = np.empty((H, W), np.int64)
    image = np.empty((H, W, C))
    slot_paint(face_id, lookup, colors, background, slot, image)
    return faces, N, colors, slot, image


@njit(cache=True, nogil=True)
def face_normals(V, F, faces, out):  # pragma: no cover - compiled
    """Unit normals ``out (k, 3)`` of the faces ``F[faces]`` (zero for degenerate faces), as
    :func:`algorithms.render.render.face_unit_normals`."""
    _face_normals(V, F, faces, out)


@njit(cache=True, nogil=True)
def lambert_colors(V, F, faces, M, scale, offset, N, colors):  # pragma: no cover - compiled
    """:func:`face_normals` into ``N (k, 3)`` and ``colors (k, C) = scale (N M) + offset``
    (:class:`~algorithms.render.shading.LambertianShading` without albedo) in one loop."""
    _face_normals(V, F, faces, N)
    C = M.shape[1]
    for q in range(N.shape[0]):
        n0 = N[q, 0]
        n1 = N[q, 1]
        n2 = N[q, 2]
        for c in range(C):
            colors[q, c] = scale * (n0 * M[0, c] + n1 * M[1, c] + n2 * M[2, c]) + offset


@njit(cache=True, nogil=True, inline="always")
def _face_normals(V, F, faces, out):  # pragma: no cover - compiled
    for q in range(faces.shape[0]):
        f = faces[q]
        a = F[f, 0]
        b = F[f, 1]
        c = F[f, 2]
        ux = V[b, 0] - V[a, 0]
        uy = V[b, 1] - V[a, 1]
        uz = V[b, 2] - V[a, 2]
        vx = V[c, 0] - V[a, 0]
        vy = V[c, 1] - V[a, 1]
        vz = V[c, 2] - V[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nrm > 0.0:
            out[q, 0] = nx / nrm
            out[q, 1] = ny / nrm
            out[q, 2] = nz / nrm
        else:
            out[q, 0] = 0.0
            out[q, 1] = 0.0
            out[q, 2] = 0.0


@njit(cache=True, nogil=True)
def paint(slot, colors, background, image):  # pragma: no cover - compiled
    """``image (H, W, C)``: each pixel the colour of its face, ``background`` elsewhere."""
    C = colors.shape[1]
    sl = slot.reshape(-1)
    img = image.reshape(-1, C)
    if C == 3:                          # RGB: unrolled
        for p in range(sl.shape[0]):
            s = sl[p]
            if s >= 0:
                img[p, 0] = colors[s, 0]
                img[p, 1] = colors[s, 1]
                img[p, 2] = colors[s, 2]
            else:
                img[p, 0] = background
                img[p, 1] = background
                img[p, 2] = background
        return
    for p in range(sl.shape[0]):
        s = sl[p]
        if s >= 0:
            for c in range(C):
                img[p, c] = colors[s, c]
        else:
            for c in range(C):
                img[p, c] = background


@njit(cache=True, nogil=True)
def face_sums(slot, G, out):  # pragma: no cover - compiled
    """``out (k, C)`` (zeroed beforehand) += the pixel gradients ``G (H, W, C)`` of each face,
    summed in pixel order (as ``np.bincount``). ``slot`` and ``G`` C-contiguous."""
    C = out.shape[1]
    sl = slot.reshape(-1)
    g = G.reshape(-1)
    if C == 3:                          # RGB: unrolled, flat indices
        for p in range(sl.shape[0]):
            s = sl[p]
            if s >= 0:
                out[s, 0] += g[3 * p]
                out[s, 1] += g[3 * p + 1]
                out[s, 2] += g[3 * p + 2]
        return
    for p in range(sl.shape[0]):
        s = sl[p]
        if s >= 0:
            for c in range(C):
                out[s, c] += g[C * p + c]


@njit(cache=True, nogil=True)
def _lambert_image_vjp_ser(V, F, slot, faces, G, A):  # pragma: no cover - compiled
    gc = np.zeros((faces.shape[0], G.shape[2]))
    face_sums(slot, G, gc)
    out = np.zeros((V.shape[0], 3))
    _normal_vjp_ser(V, F, faces, gc, A, out)
    return out


def lambert_image_vjp(V, F, slot, faces, G, A):
    """``dE/dV (n, 3)`` of Lambertian shading without albedo in one call: :func:`face_sums` of
    ``G (H, W, C)`` into ``gc``, then :func:`lambert_normal_vjp`."""
    if not _threads(faces.shape[0]):
        return _lambert_image_vjp_ser(V, F, slot, faces, G, A)
    gc = np.zeros((faces.shape[0], G.shape[2]))
    face_sums(slot, G, gc)
    out = np.zeros((V.shape[0], 3))
    _normal_vjp(V, F, faces, gc, A, out, True)
    return out


def normal_vjp(V, F, faces, g, out):
    """``out (n, 3)`` (zeroed beforehand) += ``sum_j sum_k -n_j (h_jk . g_j) / |h_jk|^2`` at the
    corners ``v_k`` of the faces ``faces`` (see :mod:`algorithms.render.render`)."""
    _normal_vjp(V, F, faces, g, np.empty((0, 0)), out, _threads(faces.shape[0]))


def lambert_normal_vjp(V, F, faces, gc, A, out):
    """:func:`normal_vjp` of ``g_j = A gc_j`` (``A (3, C)``, ``gc (k, C)``): the gradient of
    linear shading (colour ``= N M * scale + offset``: ``A = scale M``) in the same loop."""
    _normal_vjp(V, F, faces, gc, A, out, _threads(faces.shape[0]))


def _threads(k: int) -> bool:
    """Run the per-face part on threads: more than one chunk of faces and threads allowed."""
    return k > VJP_CHUNK and use_threads()


@njit(cache=True, nogil=True)
def _normal_vjp_terms(V, F, faces, g, A, lo, hi, T, ok):  # pragma: no cover - compiled
    """Faces ``faces[lo:hi]``: ``T[q, k]`` = the term of face q at its corner k, ``ok[q, k]``
    whether there is one (a degenerate face or corner adds nothing)."""
    X = np.empty((3, 3))
    lin = A.shape[0] == 3
    C = g.shape[1]
    for q in range(lo, hi):
        f = faces[q]
        ok[q, 0] = False
        ok[q, 1] = False
        ok[q, 2] = False
        for k in range(3):
            for d in range(3):
                X[k, d] = V[F[f, k], d]
        ux = X[1, 0] - X[0, 0]
        uy = X[1, 1] - X[0, 1]
        uz = X[1, 2] - X[0, 2]
        vx = X[2, 0] - X[0, 0]
        vy = X[2, 1] - X[0, 1]
        vz = X[2, 2] - X[0, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not nrm > 0.0:
            continue
        nx /= nrm
        ny /= nrm
        nz /= nrm
        if lin:
            gx = 0.0
            gy = 0.0
            gz = 0.0
            for c in range(C):
                gx += A[0, c] * g[q, c]
                gy += A[1, c] * g[q, c]
                gz += A[2, c] * g[q, c]
        else:
            gx = g[q, 0]
            gy = g[q, 1]
            gz = g[q, 2]
        for k in range(3):
            ka = (k + 1) % 3
            kb = (k + 2) % 3
            ex = X[kb, 0] - X[ka, 0]
            ey = X[kb, 1] - X[ka, 1]
            ez = X[kb, 2] - X[ka, 2]
            wx = X[k, 0] - X[ka, 0]
            wy = X[k, 1] - X[ka, 1]
            wz = X[k, 2] - X[ka, 2]
            ee = ex * ex + ey * ey + ez * ez
            t = (wx * ex + wy * ey + wz * ez) / (ee if ee > 0.0 else 1.0)
            hx = wx - t * ex
            hy = wy - t * ey
            hz = wz - t * ez
            hh = hx * hx + hy * hy + hz * hz
            if not hh > 0.0:
                continue
            s = -(hx * gx + hy * gy + hz * gz) / hh
            T[q, k, 0] = nx * s
            T[q, k, 1] = ny * s
            T[q, k, 2] = nz * s
            ok[q, k] = True


@njit(cache=True, nogil=True, parallel=True)
def _normal_vjp_terms_par(V, F, faces, g, A, T, ok):  # pragma: no cover - compiled
    m = faces.shape[0]
    for c in prange((m + VJP_CHUNK - 1) // VJP_CHUNK):
        _normal_vjp_terms(V, F, faces, g, A, c * VJP_CHUNK, min(m, (c + 1) * VJP_CHUNK), T, ok)


def _normal_vjp(V, F, faces, g, A, out, par):
    """:func:`normal_vjp` (``A`` empty) or :func:`lambert_normal_vjp`.

    The terms of the faces are computed first (on threads when ``par``: each face's by one
    thread, the same operations whatever the thread count), then added to ``out`` at the
    corners in face order, as one serial loop would: the same bits for any thread count.
    The parallel kernel is called from Python, never from a compiled function
    (:mod:`algorithms.compiled`, "cached kernels")."""
    if not par:
        _normal_vjp_ser(V, F, faces, g, A, out)
        return
    m = faces.shape[0]
    T = np.empty((m, 3, 3))
    ok = np.empty((m, 3), np.bool_)
    _normal_vjp_terms_par(V, F, faces, g, A, T, ok)
    _add_corner_terms(F, faces, T, ok, out)


@njit(cache=True, nogil=True)
def _normal_vjp_ser(V, F, faces, g, A, out):  # pragma: no cover - compiled
    m = faces.shape[0]
    T = np.empty((m, 3, 3))
    ok = np.empty((m, 3), np.bool_)
    _normal_vjp_terms(V, F, faces, g, A, 0, m, T, ok)
    _add_corner_terms(F, faces, T, ok, out)


@njit(cache=True, nogil=True)
def _add_corner_terms(F, faces, T, ok, out):  # pragma: no cover - compiled
    """``out[v] += T[q, k]`` at the corners ``v = F[faces[q], k]`` in face order."""
    m = faces.shape[0]
    for q in range(m):
        f = faces[q]
        for k in range(3):
            if ok[q, k]:
                v = F[f, k]
                out[v, 0] += T[q, k, 0]
                out[v, 1] += T[q, k, 1]
                out[v, 2] += T[q, k, 2]


# --------------------------------------------------------------------------------------------
# spherical harmonics (algorithms.render.sh): Y_j(n) = Kf_j Q_l^|m|(z) {Re, Im}((x + i y)^|m|)
# with Q_l^m = d^m P_l / dz^m by the associated-Legendre recurrence (without the (1 - z^2)^(m/2)
# factor, which is in |x + i y|^m), so dQ_l^m/dz = Q_l^(m+1).
# --------------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def _sh_scratch(d):  # pragma: no cover - compiled
    """The recurrence factors ``R[l, m, 0] = (2l - 1) / (l - m)``, ``R[l, m, 1] = (l + m - 1) /
    (l - m)`` (``l >= m + 2``), ``R[m, m, 0] = (2m - 1)!!``, ``R[m + 1, m, 0] = (2m + 1)!!`` (no
    division per face)."""
    R = np.zeros((d + 2, d + 2, 2))
    dfact = 1.0
    for m in range(d + 1):
        R[m, m, 0] = dfact
        R[m + 1, m, 0] = dfact * (2 * m + 1)
        for l in range(m + 2, d + 1):
            R[l, m, 0] = (2.0 * l - 1.0) / (l - m)
            R[l, m, 1] = (l + m - 1.0) / (l - m)
        dfact *= 2 * m + 1
    return R


@njit(cache=True, nogil=True)
def _unit(N, f):  # pragma: no cover - compiled
    x = N[f, 0]
    y = N[f, 1]
    z = N[f, 2]
    r = math.sqrt(x * x + y * y + z * z)
    if r > 0.0:
        return x / r, y / r, z / r
    return x, y, z


_BLOCK = 64


@njit(cache=True, nogil=True, inline="always")
def _sh_block(N, s, nb, d, R, x, y, z, Cm, Sm, Q):  # pragma: no cover - compiled
    """``(x + i y)^m = Cm + i Sm`` and ``Q[l, m] = d^m P_l/dz^m (z)`` (m <= l) for the faces
    ``s .. s + nb - 1``, face index last: unit normals
    ``x, y, z (B,)``, ``Cm, Sm (d + 1, B)``, ``Q (d + 2, d + 2, B)`` (``Q[l, l + 1] = 0``)."""
    for t in range(nb):
        x[t], y[t], z[t] = _unit(N, s + t)
        Cm[0, t] = 1.0
        Sm[0, t] = 0.0
    for m in range(1, d + 1):
        for t in range(nb):
            Cm[m, t] = Cm[m - 1, t] * x[t] - Sm[m - 1, t] * y[t]
            Sm[m, t] = Cm[m - 1, t] * y[t] + Sm[m - 1, t] * x[t]
    for m in range(d + 1):
        r = R[m, m, 0]
        for t in range(nb):
            Q[m, m, t] = r
        if m + 1 <= d:
            r = R[m + 1, m, 0]
            for t in range(nb):
                Q[m + 1, m, t] = r * z[t]
        for l in range(m + 2, d + 1):
            ra = R[l, m, 0]
            rb = R[l, m, 1]
            for t in range(nb):
                Q[l, m, t] = ra * z[t] * Q[l - 1, m, t] - rb * Q[l - 2, m, t]


@njit(cache=True, nogil=True)
def sh_normal_vjp(N, Gc, W, Kf, out):  # pragma: no cover - compiled
    """``out (k, 3) = P_n sum_j w_kj grad Y_j(n_k)`` with ``w_kj = sum_c Gc_kc W_jc`` and ``P_n``
    the projection onto the tangent plane of the unit normal (the gradient of ``Y(n/|n|)``):
    ``dY/dx = Kf Q_l^m m {Re, Im}((x + i y)^(m-1))``, ``dY/dy = Kf Q_l^m m {-Im, Re}(...)``
    (``d/dx (x + i y)^m = m (x + i y)^(m-1)``, ``d/dy = i m (x + i y)^(m-1)``),
    ``dY/dz = Kf Q_l^(m+1) {Re, Im}((x + i y)^m)``. Blocks of faces, face index innermost."""
    nc, C = W.shape
    k = N.shape[0]
    d = int(round(math.sqrt(nc))) - 1
    R = _sh_scratch(d)
    B = _BLOCK
    x = np.empty(B)
    y = np.empty(B)
    z = np.empty(B)
    Cm = np.empty((d + 1, B))
    Sm = np.empty((d + 1, B))
    Q = np.zeros((d + 2, d + 2, B))
    w = np.empty((nc, B))
    gx = np.empty(B)
    gy = np.empty(B)
    gz = np.empty(B)
    for s in range(0, k, B):
        nb = min(k, s + B) - s
        _sh_block(N, s, nb, d, R, x, y, z, Cm, Sm, Q)
        for j in range(nc):
            wj = w[j]
            if C == 3:
                w0 = W[j, 0]
                w1 = W[j, 1]
                w2 = W[j, 2]
                for t in range(nb):
                    wj[t] = Gc[s + t, 0] * w0 + Gc[s + t, 1] * w1 + Gc[s + t, 2] * w2
            else:
                for t in range(nb):
                    acc = 0.0
                    for c in range(C):
                        acc += Gc[s + t, c] * W[j, c]
                    wj[t] = acc
        for t in range(nb):
            gx[t] = 0.0
            gy[t] = 0.0
            gz[t] = 0.0
        for l in range(d + 1):
            base = l * l + l
            kb = Kf[base]
            for t in range(nb):
                gz[t] += w[base, t] * kb * Q[l, 1, t]
            for m in range(1, l + 1):
                kp = Kf[base + m]
                kn = Kf[base - m]
                for t in range(nb):
                    kc = w[base + m, t] * kp
                    ks = w[base - m, t] * kn
                    q = Q[l, m, t] * m
                    gx[t] += q * (kc * Cm[m - 1, t] + ks * Sm[m - 1, t])
                    gy[t] += q * (-kc * Sm[m - 1, t] + ks * Cm[m - 1, t])
                    gz[t] += Q[l, m + 1, t] * (kc * Cm[m, t] + ks * Sm[m, t])
        for t in range(nb):
            r = gx[t] * x[t] + gy[t] * y[t] + gz[t] * z[t]
            out[s + t, 0] = gx[t] - r * x[t]
            out[s + t, 1] = gy[t] - r * y[t]
            out[s + t, 2] = gz[t] - r * z[t]


@njit(cache=True, nogil=True)
def sh_values_t(N, Kf, W, Yt, irr):  # pragma: no cover - compiled
    """``Yt (nc, k)``: the basis at the unit normals ``n_k / |n_k|``, transposed (coefficient
    rows), and ``irr (k, C) = sum_j Y_j W_jc`` (the irradiance with ``W = A U``) while the block
    is in cache. Blocks of faces, the face index innermost (SIMD-friendly loops); the same
    operations for every block size (the block only changes the loop order)."""
    nc, k = Yt.shape
    C = W.shape[1]
    acc = np.empty((C, _BLOCK))
    d = int(round(math.sqrt(nc))) - 1
    R = _sh_scratch(d)
    B = _BLOCK
    x = np.empty(B)
    y = np.empty(B)
    z = np.empty(B)
    Cm = np.empty((d + 1, B))
    Sm = np.empty((d + 1, B))
    Q = np.zeros((d + 2, d + 2, B))
    for s in range(0, k, B):
        nb = min(k, s + B) - s
        _sh_block(N, s, nb, d, R, x, y, z, Cm, Sm, Q)
        for l in range(d + 1):
            base = l * l + l
            kf = Kf[base]
            for t in range(nb):
                Yt[base, s + t] = kf * Q[l, 0, t]
            for m in range(1, l + 1):
                kc = Kf[base + m]
                ks = Kf[base - m]
                for t in range(nb):
                    Yt[base + m, s + t] = kc * Q[l, m, t] * Cm[m, t]
                    Yt[base - m, s + t] = ks * Q[l, m, t] * Sm[m, t]
        for c in range(C):
            a = acc[c]
            for t in range(nb):
                a[t] = 0.0
            for j in range(nc):
                w = W[j, c]
                yj = Yt[j, s:s + nb]
                for t in range(nb):
                    a[t] += yj[t] * w
            for t in range(nb):
                irr[s + t, c] = a[t]
