"""Numba kernels of Paparazzi's ``slic`` filter: scikit-image 0.26's masked 2-D SLIC, label for
label (loaded through :mod:`algorithms.compiled` by :func:`algorithms.paparazzi.slic.slic_labels`,
which prepares the picture with scikit-image's own ``rgb2lab`` and falls back to
``skimage.segmentation.slic`` where these kernels are off).

What is ported, with the same floating-point operations (float64, no fastmath, no FMA) as the
Cython / C code it replaces wherever a result is kept, so the same bits:

* :func:`rescale_masked` -- ``slic``'s rescaling of the picture to [0, 1] over the mask.
* :func:`kmeans2_yx` -- the 5 iterations of ``scipy.cluster.vq.kmeans2`` that
  ``skimage.segmentation.slic_superpixels._get_mask_centroids`` runs on the mask's pixel
  coordinates (``(z, y, x)`` with ``z = 0``): ``vq``'s naive loop (fewer than 5 features),
  distance ``fl(fl(dy^2) + fl(dx^2))`` (``0 + dz^2`` is exactly 0), nearest code, ties to the
  lowest code; ``update_cluster_means`` (an empty cluster keeps its code, as ``kmeans2``).
* :func:`slic_pass` -- one call of ``skimage.segmentation._slic._slic_cython`` for a picture of
  depth 1 with a mask, spacing 1 and SLIC-zero off: ``max_num_iter`` rounds of "each segment
  claims the mask pixels of its window ``centre +- 2 * step`` (``regular_grid``'s steps) it is
  nearer to than every segment before it" and "every segment moves to the mean of its pixels"
  (an empty one becomes NaN, 0 / 0, and never claims a pixel again), distance
  ``fl(fl(dy^2 + dx^2) * w) [+ fl(fl(t0^2 + t1^2) + t2^2)]`` with ``w = 1 / (step * step)``
  taken in C ``float`` as the Cython signature does. :func:`slic_2d` runs both of ``slic``'s
  passes (colourless, then with colour) and
* :func:`enforce_connectivity` -- ``_enforce_label_connectivity_cython`` in 2-D (its breadth-
  first search, neighbour order ``x+1, x-1, y+1, y-1``, the ``max_size`` cut and the merge of a
  small component into the last adjacent labelled one).

Where the work is saved, exactly. A round of the Cython (and a ``vq`` call) gives each pixel
the candidate of least distance, ties to the lowest segment (its in-order strict "nearer
than"), so the candidates may be visited in any order as long as each pixel keeps the least
``(d, k)``. The picture is cut into 16 x 16 tiles (:func:`_assign`); each tile takes the
segments whose windows reach it (rows and columns of tiles first), nearest first by a lower
bound of their distance over the tile (the spatial part at the tile's point nearest the
centre: rounding is monotone), and skips every segment whose bound exceeds the largest distance
its pixels already have. With windows four steps wide, a pixel of a 256 x 256 view with 100
segments is looked at by about 3 segments a round (5 with colour) instead of about 16, in loops
over the rows of a tile; in k-means' ``vq`` (every code a candidate) by
about 3 codes instead of all 100. The Z loop and the spacing products (``1 * v``) are gone, the
coordinate sums are sums of whole numbers (exact in any order), the colour sums run in raster
order along runs of one label, the mean colours of the first (colourless) pass are taken once
at its end (only the last ones are read), and the second pass skips its last mean update (only
the labels are returned). Measured (``benchmarks/slic_filter.py``, one thread): the kernels
take about 5.4 ms a 256 x 256 view where scikit-image's k-means and Cython take about 30.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)

TILE = 16
"""Tile side (pixels) of :func:`_assign` (8 and 32 were slower)."""

_DBL_MAX = np.finfo(np.float64).max
_DBL_MAX_BITS = int(np.array(_DBL_MAX).view(np.int64))


# ------------------------------------------------------------------ preparation
@njit(**_OPTS)
def rescale_masked(image, mask):
    """``slic``'s first step on ``image (H, W, 3)`` float64 with ``mask (H, W)``: a copy less
    the least masked value, divided by the masked range when it is not 0 (the same two IEEE
    operations per value). Returns ``(copy, ok)``; ``ok`` False (the copy unfinished) where a
    masked value is NaN or infinite (``slic`` raises there)."""
    H, W, C = image.shape
    out = np.empty((H, W, C))
    lo = np.inf
    hi = -np.inf
    for y in range(H):
        for x in range(W):
            if mask[y, x]:
                for c in range(C):
                    v = image[y, x, c]
                    if not np.isfinite(v):
                        return out, False
                    lo = min(lo, v)
                    hi = max(hi, v)
    span = hi - lo
    for y in range(H):
        for x in range(W):
            for c in range(C):
                v = image[y, x, c] - lo
                out[y, x, c] = v / span if hi != lo else v
    return out, True


# ------------------------------------------------------------------ tiles: the nearest segment
@njit(**_OPTS)
def _min_square(c, a, b):
    """``min fl((c - v)^2)`` over the integers ``v`` in ``[a, b)`` (``b > a``): at the two
    integers around ``c``, clamped (the rounded square is monotone in ``|c - v|``)."""
    f = np.floor(c)
    v0 = min(max(f, float(a)), float(b - 1))
    v1 = min(max(f + 1.0, float(a)), float(b - 1))
    t0 = c - v0
    t1 = c - v1
    return min(t0 * t0, t1 * t1)


@njit(**_OPTS)
def _tiles(img, mask):
    """The picture in tiles: ``(colour planes (3, tiles, T*T), start (tiles, T*T), tile has
    mask pixels (tiles,))``, tile ``ty * ntx + tx``, pixel ``r * T + c`` of each; ``start``: a
    pixel's distance before a round, ``DBL_MAX`` on the mask, -1 off it (and outside the
    picture), where no ``d >= 0`` can win."""
    _, H, W = img.shape
    T = TILE
    nty = (H + T - 1) // T
    ntx = (W + T - 1) // T
    planes = np.zeros((3, nty * ntx, T * T))
    start = np.full((nty * ntx, T * T), -1.0)
    has = np.zeros(nty * ntx, np.bool_)
    for y in range(H):
        for x in range(W):
            t = (y // T) * ntx + x // T
            i = (y % T) * T + x % T
            for ch in range(3):
                planes[ch, t, i] = img[ch, y, x]
            if mask[y, x]:
                start[t, i] = _DBL_MAX
                has[t] = True
    return planes, start, has


@njit(**_OPTS)
def _claim(best, bk, k, y0, x0, ry0, ry1, rx0, rx1, c_y, c_x, w, colour, L, A, B, c0, c1, c2):
    """One segment's claims on the pixels ``[ry0, ry1) x [rx0, rx1)`` (tile-local) of one tile
    whose top left pixel is ``(y0, x0)``: each pixel keeps the least ``(d, k)``."""
    T = TILE
    for r in range(ry0, ry1):
        t = c_y - float(y0 + r)
        dy = t * t
        for c in range(rx0, rx1):
            i = r * T + c
            u = c_x - float(x0 + c)
            d = (dy + u * u) * w
            if colour:
                t0 = L[i] - c0
                t1 = A[i] - c1
                t2 = B[i] - c2
                d = d + ((t0 * t0 + t1 * t1) + t2 * t2)
            b = best[i]
            kb = bk[i]
            up = (d < b) | ((d == b) & (k < kb))
            best[i] = d if up else b
            bk[i] = k if up else kb


@njit(**_OPTS)
def _largest(bits):
    """The largest of the tile's distances, as the int64 bits of a float64: monotone for
    non-negative floats, and the -1 off the mask is a negative integer."""
    m = bits[0]
    for i in range(1, bits.shape[0]):
        m = max(m, bits[i])
    return m


@njit(**_OPTS)
def _assign(planes, start, has, H, W, cy, cx, cc, live, ymin, ymax, xmin, xmax, w, colour,
            labels):
    """One round of "each pixel takes its nearest segment": every pixel that may take one
    (``start`` not -1, see :func:`_tiles`) and that the windows ``[ymin, ymax) x [xmin,
    xmax)`` of the ``live`` segments reach gets ``labels = k + 1`` for the least ``(d_k, k)``,
    ``d_k = fl(fl(dy^2 + dx^2) * w) [+ fl(fl(t0^2 + t1^2) + t2^2)]`` (``colour``); the others
    keep their labels. Returns whether any pixel took a segment.

    Per tile: the candidates are the segments whose windows meet it (found per row and per
    column of tiles), with a lower bound of their distance over the part of the tile in their
    window, ``lb_k = fl(fl(min dy^2 + min dx^2) * w)`` (rounding is monotone: no pixel's
    ``d_k`` is below it). The nearest candidate first; after each candidate whose window covers
    the whole tile, ``M`` := the tile's largest distance so far, and a candidate with
    ``lb_k > M`` can neither win nor tie anywhere in the tile and is skipped; the others are
    taken in order of ``lb_k`` (insertion sort of a few) until the next bound exceeds ``M``.
    Bounds and distances are compared as the int64 bits of non-negative floats (monotone; the
    -1 off the mask is a negative integer)."""
    K = cy.shape[0]
    T = TILE
    nty = (H + T - 1) // T
    ntx = (W + T - 1) // T
    best = np.empty(T * T)
    bk = np.empty(T * T, np.int64)
    bits = best.view(np.int64)
    cand = np.empty(K, np.int64)
    clb = np.empty(K)
    clb_bits = clb.view(np.int64)
    k2 = np.empty(K, np.int64)
    lb2 = np.empty(K, np.int64)
    rowk = np.empty(K, np.int64)
    rowy = np.empty(K)
    colx = np.empty((ntx, K))
    # each segment's least dx^2 in each column of tiles (inf: its window misses it)
    for tx in range(ntx):
        x0 = tx * T
        x1 = min(x0 + T, W)
        for k in range(K):
            if live[k] and xmin[k] < x1 and xmax[k] > x0:
                colx[tx, k] = _min_square(cx[k], max(x0, xmin[k]), min(x1, xmax[k]))
            else:
                colx[tx, k] = np.inf
    change = False
    for ty in range(nty):
        y0 = ty * T
        y1 = min(y0 + T, H)
        # the segments whose windows meet this row of tiles, with their least dy^2 in it
        nr = 0
        for k in range(K):
            if live[k] and ymin[k] < y1 and ymax[k] > y0:
                rowk[nr] = k
                rowy[nr] = _min_square(cy[k], max(y0, ymin[k]), min(y1, ymax[k]))
                nr += 1
        for tx in range(ntx):
            tile = ty * ntx + tx
            if not has[tile]:
                continue
            x0 = tx * T
            x1 = min(x0 + T, W)
            nc = 0
            for j in range(nr):
                k = rowk[j]
                dx2 = colx[tx, k]
                if dx2 == np.inf:
                    continue
                clb[nc] = (rowy[j] + dx2) * w
                cand[nc] = k
                nc += 1
            if nc == 0:
                continue
            best[:] = start[tile]
            bk[:] = -1
            L = planes[0, tile]
            A = planes[1, tile]
            B = planes[2, tile]
            q0 = 0
            for q in range(1, nc):
                if clb_bits[q] < clb_bits[q0]:
                    q0 = q
            k = cand[q0]
            M = _DBL_MAX_BITS
            n2 = -1                     # the others, not sorted yet
            q = 0
            while True:
                ry0 = max(y0, ymin[k])
                ry1 = min(y1, ymax[k])
                rx0 = max(x0, xmin[k])
                rx1 = min(x1, xmax[k])
                if ry0 == y0 and ry1 == y1 and rx0 == x0 and rx1 == x1:
                    # the whole tile (its pixels outside the picture take no segment)
                    _claim(best, bk, k, y0, x0, 0, y1 - y0, 0, x1 - x0, cy[k], cx[k], w,
                           colour, L, A, B, cc[k, 0], cc[k, 1], cc[k, 2])
                    M = _largest(bits)
                else:
                    _claim(best, bk, k, y0, x0, ry0 - y0, ry1 - y0, rx0 - x0, rx1 - x0, cy[k],
                           cx[k], w, colour, L, A, B, cc[k, 0], cc[k, 1], cc[k, 2])
                if n2 < 0:
                    n2 = 0
                    for r in range(nc):
                        if r == q0 or clb_bits[r] > M:
                            continue
                        lbr = clb_bits[r]
                        i = n2
                        while i > 0 and lb2[i - 1] > lbr:
                            lb2[i] = lb2[i - 1]
                            k2[i] = k2[i - 1]
                            i -= 1
                        lb2[i] = lbr
                        k2[i] = cand[r]
                        n2 += 1
                if q >= n2 or lb2[q] > M:
                    break               # sorted: so are all the others
                k = k2[q]
                q += 1
            claimed = 0
            for r in range(y1 - y0):
                lrow = labels[y0 + r, x0:x1]
                for c in range(x1 - x0):
                    k = bk[r * T + c]
                    lrow[c] = k + 1 if k >= 0 else lrow[c]
                    claimed += k >= 0
            if claimed > 0:
                change = True
    return change


# ------------------------------------------------------------------ k-means of the seeds
@njit(**_OPTS)
def kmeans2_yx(py, px, cy, cx, iterations, H, W):
    """``scipy.cluster.vq.kmeans2(data, codes, iter=iterations)`` for points ``(0, py, px)``
    (pixel coordinates of an ``H x W`` picture: whole numbers) and codes ``(0, cy, cx)``
    (``cy``, ``cx`` updated in place; float64): the same code book.

    ``vq`` computes, for each point and each code in order, ``d = 0; d += (c - p)^2`` over the
    three features and keeps the first code of least ``d``: with ``z = 0``, the least
    ``(fl(fl(dy^2) + fl(dx^2)), code)``. Here a round of :func:`_assign` (windows without
    bounds, ``w = 1``, no colour) settles it for every pixel of the tiles that hold points, and
    the points read their pixels' codes. The means are summed in point order (coordinates are
    whole numbers: exact sums) and divided by the count; a code without points keeps its place
    (``kmeans2``'s "warn" for empty clusters, without the warning)."""
    n = py.shape[0]
    K = cy.shape[0]
    T = TILE
    nty = (H + T - 1) // T
    ntx = (W + T - 1) // T
    start = np.full((nty * ntx, T * T), -1.0)
    has = np.zeros(nty * ntx, np.bool_)
    for i in range(n):
        y = int(py[i])
        x = int(px[i])
        start[(y // T) * ntx + x // T, (y % T) * T + x % T] = _DBL_MAX
        has[(y // T) * ntx + x // T] = True
    planes = np.empty((3, nty * ntx, T * T))    # no colours (never read)
    labels = np.zeros((H, W), np.int64)
    live = np.ones(K, np.bool_)
    ymin = np.zeros(K, np.int64)
    ymax = np.full(K, H, np.int64)
    xmin = np.zeros(K, np.int64)
    xmax = np.full(K, W, np.int64)
    cc = np.zeros((K, 3))
    sy = np.empty(K)
    sx = np.empty(K)
    cnt = np.empty(K, np.int64)
    for _ in range(iterations):
        _assign(planes, start, has, H, W, cy, cx, cc, live, ymin, ymax, xmin, xmax, 1.0, False,
                labels)
        sy[:] = 0.0
        sx[:] = 0.0
        cnt[:] = 0
        for i in range(n):
            j = labels[int(py[i]), int(px[i])] - 1
            sy[j] += py[i]
            sx[j] += px[i]
            cnt[j] += 1
        for j in range(K):
            if cnt[j] > 0:
                cy[j] = sy[j] / cnt[j]
                cx[j] = sx[j] / cnt[j]


# ------------------------------------------------------------------ SLIC passes
@njit(**_OPTS)
def _slic_pass(img, planes, start, has, cy, cx, cc, step_y, step_x, w, max_iter, ignore_color,
               last_update):
    """One ``_slic_cython`` call (module docstring) on ``img (3, H, W)`` (the Lab picture times
    ``1 / compactness``, one plane per channel; ``planes``, ``start``, ``has``: its tiles,
    :func:`_tiles`); segment ``k`` has centre ``(cy[k], cx[k])`` and colour ``cc[k]``
    (updated in place, as the Cython updates its ``segments``: NaN once empty). ``w``: the
    spatial weight ``1 / (step * step)``. Returns the labels ``(H, W)`` int64 (``k + 1``; 0
    off the mask and where no window ever reached).

    ``ignore_color``: the first pass (distances without colour); its colour means are taken
    once, from the final labels, which are the labels of its last mean update (a round without
    any claim changes nothing and ends the loop). ``last_update`` False: the update after the
    last round is skipped (its centres are never read; only the labels are).

    The Cython's round: ``distance = DBL_MAX``; for ``k`` in order, for each mask pixel of the
    window, ``if distance > d_k: label = k; distance = d_k``. A pixel thus ends with the least
    ``d_k`` over the segments whose windows reach it, the lowest ``k`` of equal ones, or keeps
    its label of the round before when no window reaches it (or no ``d_k < DBL_MAX``): a round
    of :func:`_assign`."""
    _, H, W = img.shape
    K = cy.shape[0]
    labels = np.zeros((H, W), np.int64)
    ymin = np.empty(K, np.int64)
    ymax = np.empty(K, np.int64)
    xmin = np.empty(K, np.int64)
    xmax = np.empty(K, np.int64)
    live = np.empty(K, np.bool_)
    colour = not ignore_color
    any_update = False
    for it in range(max_iter):
        # windows, as the Cython: <Py_ssize_t>max(c - 2 * step, 0), <Py_ssize_t>min(c + 2 *
        # step + 1, size) (a NaN centre: no window)
        for k in range(K):
            c_y = cy[k]
            c_x = cx[k]
            if c_y != c_y or c_x != c_x:
                live[k] = False
                continue
            live[k] = True
            v = c_y - 2 * step_y
            ymin[k] = int(0.0 if 0.0 > v else v)
            v = c_y + 2 * step_y + 1
            ymax[k] = int(float(H) if H < v else v)
            v = c_x - 2 * step_x
            xmin[k] = int(0.0 if 0.0 > v else v)
            v = c_x + 2 * step_x + 1
            xmax[k] = int(float(W) if W < v else v)
        if not _assign(planes, start, has, H, W, cy, cx, cc, live, ymin, ymax, xmin, xmax, w,
                       colour, labels):
            break
        if it == max_iter - 1 and not last_update:
            break
        _recompute(img, labels, cy, cx, cc, colour)
        any_update = True
    if ignore_color and any_update:
        _recompute(img, labels, cy, cx, cc, True)
    return labels


@njit(**_OPTS)
def _recompute(img, labels, cy, cx, cc, with_colour):
    """Each segment's new centre: the mean of its pixels' ``y``, ``x`` (and, ``with_colour``,
    colours); NaN for a segment without pixels (the Cython's ``0 / 0``). The colours are added
    in raster order onto the segment's sums, as the Cython adds them, a run of pixels of one
    segment in a row at a time (kept in registers: the same additions in the same order). The
    coordinates are integers and their sums exact (< 2^53) in any order. ``labels`` is 0 off
    the mask."""
    H, W = labels.shape
    K = cy.shape[0]
    n = np.zeros(K, np.int64)
    sy = np.zeros(K, np.int64)
    sx = np.zeros(K, np.int64)
    s = np.zeros((K, 3))
    for y in range(H):
        x = 0
        while x < W:
            lb = labels[y, x]
            e = x + 1
            while e < W and labels[y, e] == lb:
                e += 1
            if lb != 0:
                k = lb - 1
                m = e - x
                n[k] += m
                sy[k] += y * m
                sx[k] += (x + e - 1) * m // 2
                if with_colour:
                    s0 = s[k, 0]
                    s1 = s[k, 1]
                    s2 = s[k, 2]
                    for j in range(x, e):
                        s0 += img[0, y, j]
                        s1 += img[1, y, j]
                        s2 += img[2, y, j]
                    s[k, 0] = s0
                    s[k, 1] = s1
                    s[k, 2] = s2
            x = e
    for k in range(K):
        if n[k] == 0:
            cy[k] = np.nan
            cx[k] = np.nan
            if with_colour:
                cc[k, 0] = np.nan
                cc[k, 1] = np.nan
                cc[k, 2] = np.nan
        else:
            nf = float(n[k])
            cy[k] = float(sy[k]) / nf      # integer sums < 2^53: the Cython's float sums
            cx[k] = float(sx[k]) / nf
            if with_colour:
                cc[k, 0] = s[k, 0] / nf
                cc[k, 1] = s[k, 1] / nf
                cc[k, 2] = s[k, 2] / nf


@njit(**_OPTS)
def slic_2d(lab, mask, cy, cx, step_y, step_x, w, ratio, max_iter, min_size, max_size):
    """The rest of ``slic`` after the seeds (module docstring): ``lab (H, W, 3)`` the CIELAB
    picture, ``mask (H, W)`` bool, the seeds ``(cy, cx)`` (float64, modified), the window
    steps, the spatial weight ``w``, ``ratio = 1 / compactness``; the picture is multiplied by
    ``ratio`` (as ``image * ratio``), the colourless pass and the colour pass of
    ``_slic_cython`` run, and the connectivity is enforced. Returns the labels ``(H, W)``
    int64 (``start_label`` 1, 0 off the mask)."""
    H, W, _ = lab.shape
    img = np.empty((3, H, W))
    for y in range(H):
        for x in range(W):
            for c in range(3):
                img[c, y, x] = lab[y, x, c] * ratio
    planes, start, has = _tiles(img, mask)
    cc = np.zeros((cy.shape[0], 3))
    _slic_pass(img, planes, start, has, cy, cx, cc, step_y, step_x, w, max_iter, True, True)
    labels = _slic_pass(img, planes, start, has, cy, cx, cc, step_y, step_x, w, max_iter,
                        False, False)
    return enforce_connectivity(labels, min_size, max_size)


@njit(**_OPTS)
def slic_pass(img, mask, cy, cx, cc, step_y, step_x, w, max_iter, ignore_color):
    """``_slic_cython(image, mask, segments, step, max_iter, spacing=(1, 1, 1),
    slic_zero=False, start_label=1, ignore_color)`` for a picture of depth 1: ``img (3, H, W)``
    the picture (already times ``ratio``) one plane per channel, ``mask (H, W)`` bool, the
    segments' ``(z = 0,) cy, cx, cc`` updated in place as the Cython updates them, the steps
    of ``regular_grid((1, H, W), len(cy))``, ``w = 1 / (step * step)`` in C float
    (:func:`algorithms.paparazzi.slic.spatial_weight`). Returns the labels (``k + 1``, 0 off
    the mask). (For tests; :func:`slic_2d` runs both passes.)"""
    planes, start, has = _tiles(img, mask)
    return _slic_pass(img, planes, start, has, cy, cx, cc, step_y, step_x, w, max_iter,
                      ignore_color, True)


# ------------------------------------------------------------------ connectivity
@njit(**_OPTS)
def enforce_connectivity(segments, min_size, max_size):
    """``_enforce_label_connectivity_cython(segments[None], min_size, max_size, 1)[0]`` for
    ``segments (H, W)`` int64 (0: no label)."""
    H, W = segments.shape
    out = np.zeros((H, W), np.int64)
    ddx = (1, -1, 0, 0)
    ddy = (0, 0, 1, -1)
    coord = np.empty((max_size, 2), np.int64)
    current_new_label = 1
    for y in range(H):
        for x in range(W):
            if segments[y, x] == 0:
                continue
            if out[y, x] > 0:
                continue
            adjacent = current_new_label
            label = segments[y, x]
            out[y, x] = current_new_label
            size = 1
            visited = 0
            coord[0, 0] = y
            coord[0, 1] = x
            while visited < size and size < max_size:
                for i in range(4):
                    yy = coord[visited, 0] + ddy[i]
                    xx = coord[visited, 1] + ddx[i]
                    if 0 <= xx < W and 0 <= yy < H:
                        if segments[yy, xx] == label and out[yy, xx] == 0:
                            out[yy, xx] = current_new_label
                            coord[size, 0] = yy
                            coord[size, 1] = xx
                            size += 1
                            if size >= max_size:
                                break
                        elif out[yy, xx] > 0 and out[yy, xx] != current_new_label:
                            adjacent = out[yy, xx]
                visited += 1
            if size < min_size:
                for i in range(size):
                    out[coord[i, 0], coord[i, 1]] = adjacent
            else:
                current_new_label += 1
    return out
