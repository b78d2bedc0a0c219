"""Compiled (Numba) collapse loop of :func:`algorithms.mesh.decimate.decimate`.

The same algorithm as the plain-Python loop in :mod:`algorithms.mesh.decimate` (cost order of a
binary heap keyed by ``(cost, push counter)``, the same link-condition, boundary, valence,
flip and degeneracy checks, the same records), with array data structures instead of Python
sets:

* per-vertex lists of incident (alive) triangles in one pool with per-vertex capacity (a list
  that outgrows its slot moves to the end of the pool, which doubles when full);
* set operations on 1-rings with generation-stamped marker arrays;
* a binary heap of entry ids (key ``(cost, id)``; ids increase with every push, so ties break
  in push order as in the Python loop); an entry stores only ``(cost, u, v, stamp_u,
  stamp_v)`` and the merged position is recomputed when it is popped (the same numbers: it
  depends only on the endpoints, whose stamps are unchanged);
* refused edges remembered per vertex (linked lists) and pushed again when a collapse touches
  one of their endpoints' neighbours, as the Python loop does.

The only difference: the Python loop visits a new 1-ring in Python's set order, this loop in
ascending vertex order, so equal-cost edges can collapse in a different order (tested: both
give valid, replayable decimations of the same quality; on bob, camelhead and wingnut the
records are identical). Speed, measured on the shared machine: bob 10.7k -> 1k triangles
0.16 s against 1.2 s for the Python loop; rocker-arm Loop x3 (1.29M) -> 20k 23 s CPU and
1.3 GB peak against 170 s wall and 2.9 GB (``benchmarks/progressive.py``).

Importing this module imports Numba; :mod:`algorithms.mesh.decimate` imports it lazily.
"""

from __future__ import annotations

import math

import numpy as np
from .._numba import njit

_DET_REL = 1e-9
_DEGENERATE = 1e-24
_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


@njit(**_OPTS)
def _grow_i(a, need):
    if need <= len(a):
        return a
    n = max(need, 2 * len(a), 16)
    b = np.empty(n, dtype=a.dtype)
    b[:len(a)] = a
    return b


@njit(**_OPTS)
def _grow_f(a, need):
    if need <= len(a):
        return a
    n = max(need, 2 * len(a), 16)
    b = np.empty(n, dtype=a.dtype)
    b[:len(a)] = a
    return b


@njit(**_OPTS)
def _edge_cost(u, v, P, Q, bnd, protect, midpoint):
    """(feasible, cost, keep_u, x, y, z) of collapsing edge (u, v) (twin of ``_Loop.entry``)."""
    au = protect[u] or (bnd[u] and not bnd[v])
    av = protect[v] or (bnd[v] and not bnd[u])
    if au and av:
        return False, 0.0, True, 0.0, 0.0, 0.0
    pu0, pu1, pu2 = P[u, 0], P[u, 1], P[u, 2]
    pv0, pv1, pv2 = P[v, 0], P[v, 1], P[v, 2]
    x = y = z = 0.0
    cost = 0.0
    if midpoint:
        ex, ey, ez = pv0 - pu0, pv1 - pu1, pv2 - pu2
        cost = ex * ex + ey * ey + ez * ez
        if au:
            x, y, z = pu0, pu1, pu2
        elif av:
            x, y, z = pv0, pv1, pv2
        else:
            x, y, z = 0.5 * (pu0 + pv0), 0.5 * (pu1 + pv1), 0.5 * (pu2 + pv2)
    else:
        a = Q[u, 0] + Q[v, 0]
        b = Q[u, 1] + Q[v, 1]
        c = Q[u, 2] + Q[v, 2]
        d = Q[u, 3] + Q[v, 3]
        e = Q[u, 4] + Q[v, 4]
        f = Q[u, 5] + Q[v, 5]
        g = Q[u, 6] + Q[v, 6]
        h = Q[u, 7] + Q[v, 7]
        i = Q[u, 8] + Q[v, 8]
        k = Q[u, 9] + Q[v, 9]
        if au or av:
            if au:
                x, y, z = pu0, pu1, pu2
            else:
                x, y, z = pv0, pv1, pv2
            cost = (a * x * x + 2 * b * x * y + 2 * c * x * z + d * y * y + 2 * e * y * z
                    + f * z * z + 2 * (g * x + h * y + i * z) + k)
        else:
            c00 = d * f - e * e
            c01 = c * e - b * f
            c02 = b * e - c * d
            det = a * c00 + b * c01 + c * c02
            tr = a + d + f
            done = False
            mx, my, mz = 0.5 * (pu0 + pv0), 0.5 * (pu1 + pv1), 0.5 * (pu2 + pv2)
            if tr > 0 and det > _DET_REL * tr * tr * tr:
                c11 = a * f - c * c
                c12 = b * c - a * e
                c22 = a * d - b * b
                x = -(c00 * g + c01 * h + c02 * i) / det
                y = -(c01 * g + c11 * h + c12 * i) / det
                z = -(c02 * g + c12 * h + c22 * i) / det
                ex, ey, ez = pv0 - pu0, pv1 - pu1, pv2 - pu2
                dx, dy, dz = x - mx, y - my, z - mz
                if dx * dx + dy * dy + dz * dz <= ex * ex + ey * ey + ez * ez:
                    cost = k + g * x + h * y + i * z
                    done = True
            if not done:
                best = 0.0
                for t in range(3):
                    if t == 0:
                        x1, y1, z1 = pu0, pu1, pu2
                    elif t == 1:
                        x1, y1, z1 = pv0, pv1, pv2
                    else:
                        x1, y1, z1 = mx, my, mz
                    cc = (a * x1 * x1 + 2 * b * x1 * y1 + 2 * c * x1 * z1 + d * y1 * y1
                          + 2 * e * y1 * z1 + f * z1 * z1 + 2 * (g * x1 + h * y1 + i * z1) + k)
                    if t == 0 or cc < best:
                        best, x, y, z = cc, x1, y1, z1
                cost = best
        if cost < 0.0:
            cost = 0.0
    if au:
        keep_u = True
    elif av:
        keep_u = False
    else:
        du = (x - pu0) ** 2 + (y - pu1) ** 2 + (z - pu2) ** 2
        dv = (x - pv0) ** 2 + (y - pv1) ** 2 + (z - pv2) ** 2
        keep_u = du <= dv
    return True, cost, keep_u, x, y, z


@njit(**_OPTS)
def _sift_up(heap, pos, ecost):
    item = heap[pos]
    c = ecost[item]
    while pos > 0:
        parent = (pos - 1) >> 1
        p = heap[parent]
        pc = ecost[p]
        if c < pc or (c == pc and item < p):
            heap[pos] = p
            pos = parent
        else:
            break
    heap[pos] = item


@njit(**_OPTS)
def _sift_down(heap, size, pos, ecost):
    item = heap[pos]
    c = ecost[item]
    while True:
        child = 2 * pos + 1
        if child >= size:
            break
        r = child + 1
        if r < size:
            a, b = heap[child], heap[r]
            if ecost[b] < ecost[a] or (ecost[b] == ecost[a] and b < a):
                child = r
        ch = heap[child]
        cc = ecost[ch]
        if cc < c or (cc == c and ch < item):
            heap[pos] = ch
            pos = child
        else:
            break
    heap[pos] = item


@njit(**_OPTS)
def _heapify(heap, size, ecost):
    for pos in range(size // 2 - 1, -1, -1):
        _sift_down(heap, size, pos, ecost)


@njit(**_OPTS)
def collapse_loop(V, F, Q0, bnd0, protect, init_u, init_v, init_cost, midpoint, min_dot,
                  target):
    """Run the collapse loop. ``init_*``: the feasible edges and their costs (vectorized
    initial costs). Returns the final state and the records (see ``decimate._from_kernel``)."""
    n = V.shape[0]
    m = F.shape[0]
    P = V.copy()
    Q = Q0.copy()
    bnd = bnd0.copy()
    Fm = F.copy()
    falive = np.ones(m, dtype=np.bool_)
    alive = np.ones(n, dtype=np.bool_)
    stamp = np.zeros(n, dtype=np.int64)
    # incident faces
    deg = np.zeros(n, dtype=np.int64)
    for f in range(m):
        for c in range(3):
            deg[Fm[f, c]] += 1
    vcap = deg + 4
    vstart = np.zeros(n, dtype=np.int64)
    acc = 0
    for v in range(n):
        vstart[v] = acc
        acc += vcap[v]
    pool = np.empty(max(2 * acc, 16), dtype=np.int64)
    pool_end = acc
    vcnt = np.zeros(n, dtype=np.int64)
    for f in range(m):
        for c in range(3):
            v = Fm[f, c]
            pool[vstart[v] + vcnt[v]] = f
            vcnt[v] += 1
    # heap entries
    E0 = len(init_u)
    cap = max(2 * E0, 1024)
    ecost = np.empty(cap, dtype=np.float64)
    eu = np.empty(cap, dtype=np.int64)
    ev = np.empty(cap, dtype=np.int64)
    esu = np.empty(cap, dtype=np.int64)
    esv = np.empty(cap, dtype=np.int64)
    heap = np.empty(cap, dtype=np.int64)
    for e in range(E0):
        ecost[e] = init_cost[e]
        eu[e] = init_u[e]
        ev[e] = init_v[e]
        esu[e] = 0
        esv[e] = 0
        heap[e] = e
    n_entries = E0
    hsize = E0
    _heapify(heap, hsize, ecost)
    # refused edges: per-vertex linked lists of partners
    rej_head = np.full(n, -1, dtype=np.int64)
    rej_next = np.empty(1024, dtype=np.int64)
    rej_part = np.empty(1024, dtype=np.int64)
    n_rej = 0
    any_rej = False
    # set markers
    markI = np.zeros(n, dtype=np.int64)
    markJ = np.zeros(n, dtype=np.int64)
    markR = np.zeros(n, dtype=np.int64)
    gen = 0
    Ni = np.empty(256, dtype=np.int64)
    Nj = np.empty(256, dtype=np.int64)
    ring = np.empty(512, dtype=np.int64)
    newf = np.empty(512, dtype=np.int64)
    # records
    Kcap = max(n, 16)
    r_kept = np.empty(Kcap, dtype=np.int64)
    r_removed = np.empty(Kcap, dtype=np.int64)
    r_pos = np.empty((Kcap, 9), dtype=np.float64)
    r_cost = np.empty(Kcap, dtype=np.float64)
    rf_cnt = np.empty(Kcap, dtype=np.int64)
    cf_cnt = np.empty(Kcap, dtype=np.int64)
    ring_cnt = np.empty(Kcap, dtype=np.int64)
    rk_cnt = np.empty(Kcap, dtype=np.int64)
    rr_cnt = np.empty(Kcap, dtype=np.int64)
    rf_ids = np.empty(2 * Kcap, dtype=np.int64)
    rf_tri = np.empty(6 * Kcap, dtype=np.int64)
    cf_ids = np.empty(4 * Kcap, dtype=np.int64)
    cf_corner = np.empty(4 * Kcap, dtype=np.int8)
    ring_all = np.empty(8 * Kcap, dtype=np.int64)
    rk_all = np.empty(8 * Kcap, dtype=np.int64)
    rr_all = np.empty(8 * Kcap, dtype=np.int64)
    K = 0
    n_rf = n_cf = n_ring = n_rk = n_rr = 0
    shared = np.empty(8, dtype=np.int64)
    opp = np.empty(8, dtype=np.int64)

    nf = m
    collapsed_since_rebuild = 0
    rebuilt = False
    reached = True
    while nf > target:
        if hsize == 0:
            if rebuilt and collapsed_since_rebuild == 0:
                reached = False
                break
            # rebuild: every current edge once, refusals forgotten
            rej_head[:] = -1
            n_rej = 0
            any_rej = False
            for f in range(m):
                if not falive[f]:
                    continue
                for c in range(3):
                    u = Fm[f, c]
                    v = Fm[f, (c + 1) % 3]
                    if u > v:
                        # the twin half-edge (v, u) pushes it, unless (u, v) is a boundary edge
                        twin = False
                        for t in range(vcnt[u]):
                            g = pool[vstart[u] + t]
                            if g != f and (Fm[g, 0] == v or Fm[g, 1] == v or Fm[g, 2] == v):
                                twin = True
                                break
                        if twin:
                            continue
                    ok, cost, ku, x, y, z = _edge_cost(u, v, P, Q, bnd, protect, midpoint)
                    if not ok:
                        continue
                    if n_entries >= len(ecost):
                        nc = 2 * len(ecost)
                        ecost = _grow_f(ecost, nc)
                        eu = _grow_i(eu, nc)
                        ev = _grow_i(ev, nc)
                        esu = _grow_i(esu, nc)
                        esv = _grow_i(esv, nc)
                        heap = _grow_i(heap, nc)
                    e = n_entries
                    n_entries += 1
                    ecost[e] = cost
                    eu[e] = u
                    ev[e] = v
                    esu[e] = stamp[u]
                    esv[e] = stamp[v]
                    heap[hsize] = e
                    hsize += 1
            _heapify(heap, hsize, ecost)
            rebuilt = True
            collapsed_since_rebuild = 0
            if hsize == 0:
                reached = False
                break
            continue
        # pop
        e = heap[0]
        hsize -= 1
        if hsize > 0:
            heap[0] = heap[hsize]
            _sift_down(heap, hsize, 0, ecost)
        u = eu[e]
        v = ev[e]
        if not (alive[u] and alive[v]) or stamp[u] != esu[e] or stamp[v] != esv[e]:
            continue
        ok, cost, keep_u, x, y, z = _edge_cost(u, v, P, Q, bnd, protect, midpoint)
        cost = ecost[e]
        if keep_u:
            i, j = u, v
        else:
            i, j = v, u
        si, ci = vstart[i], vcnt[i]
        sj, cj = vstart[j], vcnt[j]
        ns = 0
        too_many = False
        for t in range(cj):
            f = pool[sj + t]
            if Fm[f, 0] == i or Fm[f, 1] == i or Fm[f, 2] == i:
                if ns >= 8:
                    too_many = True
                    break
                shared[ns] = f
                ns += 1
        if ns == 0:
            continue
        refuse = too_many
        # 1-rings
        if not refuse:
            gen += 1
            gI = gen
            nNi = 0
            for t in range(ci):
                f = pool[si + t]
                for c in range(3):
                    w = Fm[f, c]
                    if w != i and markI[w] != gI:
                        markI[w] = gI
                        if nNi >= len(Ni):
                            Ni = _grow_i(Ni, 2 * len(Ni))
                        Ni[nNi] = w
                        nNi += 1
            gen += 1
            gJ = gen
            nNj = 0
            for t in range(cj):
                f = pool[sj + t]
                for c in range(3):
                    w = Fm[f, c]
                    if w != j and markJ[w] != gJ:
                        markJ[w] = gJ
                        if nNj >= len(Nj):
                            Nj = _grow_i(Nj, 2 * len(Nj))
                        Nj[nNj] = w
                        nNj += 1
            # opposite corners: distinct, and exactly the common neighbours
            nopp = 0
            for s in range(ns):
                f = shared[s]
                o = Fm[f, 0] + Fm[f, 1] + Fm[f, 2] - i - j
                dup = False
                for t in range(nopp):
                    if opp[t] == o:
                        dup = True
                if not dup:
                    opp[nopp] = o
                    nopp += 1
            if nopp != ns:
                refuse = True
            else:
                common = 0
                for t in range(nNi):
                    if markJ[Ni[t]] == gJ:
                        common += 1
                if common != nopp:
                    refuse = True
        if not refuse:
            if ns == 2:
                if bnd[i] and bnd[j]:
                    refuse = True
                else:
                    for t in range(nopp):
                        o = opp[t]
                        if not bnd[o] and vcnt[o] <= 3:
                            refuse = True
                            break
            elif ns == 1:
                o = opp[0]
                cio = 0
                for t in range(ci):
                    f = pool[si + t]
                    if Fm[f, 0] == o or Fm[f, 1] == o or Fm[f, 2] == o:
                        cio += 1
                cjo = 0
                for t in range(cj):
                    f = pool[sj + t]
                    if Fm[f, 0] == o or Fm[f, 1] == o or Fm[f, 2] == o:
                        cjo += 1
                if cio == 1 and cjo == 1:
                    refuse = True
            else:
                refuse = True
        if not refuse:
            # geometry: no flips, no degenerate triangles
            for side in range(2):
                st = si if side == 0 else sj
                cn = ci if side == 0 else cj
                other = j if side == 0 else i
                for t in range(cn):
                    f = pool[st + t]
                    if Fm[f, 0] == other or Fm[f, 1] == other or Fm[f, 2] == other:
                        continue  # a shared triangle
                    t0, t1, t2 = Fm[f, 0], Fm[f, 1], Fm[f, 2]
                    if t0 == i or t0 == j:
                        mv, o1, o2 = t0, t1, t2
                    elif t1 == i or t1 == j:
                        mv, o1, o2 = t1, t2, t0
                    else:
                        mv, o1, o2 = t2, t0, t1
                    ex = P[o2, 0] - P[o1, 0]
                    ey = P[o2, 1] - P[o1, 1]
                    ez = P[o2, 2] - P[o1, 2]
                    ax = P[o1, 0] - P[mv, 0]
                    ay = P[o1, 1] - P[mv, 1]
                    az = P[o1, 2] - P[mv, 2]
                    nox, noy, noz = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
                    bx, by, bz = P[o1, 0] - x, P[o1, 1] - y, P[o1, 2] - z
                    nnx, nny, nnz = by * ez - bz * ey, bz * ex - bx * ez, bx * ey - by * ex
                    nn2 = nnx * nnx + nny * nny + nnz * nnz
                    e2 = ex * ex + ey * ey + ez * ez
                    if nn2 <= _DEGENERATE * e2 * e2:
                        refuse = True
                        break
                    no2 = nox * nox + noy * noy + noz * noz
                    if no2 > _DEGENERATE * e2 * e2:
                        dot = nox * nnx + noy * nny + noz * nnz
                        if dot <= min_dot * math.sqrt(no2 * nn2):
                            refuse = True
                            break
                if refuse:
                    break
        if refuse:
            # remember the pair on both sides (a set: no duplicates)
            if n_rej + 2 > len(rej_next):
                rej_next = _grow_i(rej_next, n_rej + 2)
                rej_part = _grow_i(rej_part, n_rej + 2)
            for side in range(2):
                a = u if side == 0 else v
                b = v if side == 0 else u
                r = rej_head[a]
                found = False
                while r >= 0:
                    if rej_part[r] == b:
                        found = True
                        break
                    r = rej_next[r]
                if not found:
                    rej_part[n_rej] = b
                    rej_next[n_rej] = rej_head[a]
                    rej_head[a] = n_rej
                    n_rej += 1
            any_rej = True
            continue

        # ---- collapse j into i at (x, y, z)
        if K >= len(r_kept):
            nk = 2 * len(r_kept)
            r_kept = _grow_i(r_kept, nk)
            r_removed = _grow_i(r_removed, nk)
            r_cost = _grow_f(r_cost, nk)
            rf_cnt = _grow_i(rf_cnt, nk)
            cf_cnt = _grow_i(cf_cnt, nk)
            ring_cnt = _grow_i(ring_cnt, nk)
            rk_cnt = _grow_i(rk_cnt, nk)
            rr_cnt = _grow_i(rr_cnt, nk)
            rp = np.empty((nk, 9))
            rp[:K] = r_pos[:K]
            r_pos = rp
        r_kept[K] = i
        r_removed[K] = j
        for c in range(3):
            r_pos[K, c] = P[i, c]
            r_pos[K, 3 + c] = P[j, c]
        r_pos[K, 6] = x
        r_pos[K, 7] = y
        r_pos[K, 8] = z
        r_cost[K] = cost
        # removed triangles (ascending ids)
        if ns == 2 and shared[1] < shared[0]:
            shared[0], shared[1] = shared[1], shared[0]
        rf_cnt[K] = ns
        rf_ids = _grow_i(rf_ids, n_rf + ns)
        rf_tri = _grow_i(rf_tri, 3 * (n_rf + ns))
        for s in range(ns):
            f = shared[s]
            rf_ids[n_rf] = f
            for c in range(3):
                rf_tri[3 * n_rf + c] = Fm[f, c]
            n_rf += 1
            for c in range(3):
                w = Fm[f, c]
                if w != i and w != j:  # drop f from the opposite corner's list
                    sw, cw = vstart[w], vcnt[w]
                    for t in range(cw):
                        if pool[sw + t] == f:
                            pool[sw + t] = pool[sw + cw - 1]
                            vcnt[w] = cw - 1
                            break
            falive[f] = False
        # new face list of i: i's faces and j's faces minus the shared ones; j's are changed
        nnew = 0
        need = ci + cj
        if need > len(newf):
            newf = _grow_i(newf, need)
        for t in range(ci):
            f = pool[si + t]
            if falive[f]:
                newf[nnew] = f
                nnew += 1
        nch0 = nnew
        for t in range(cj):
            f = pool[sj + t]
            if falive[f]:
                newf[nnew] = f
                nnew += 1
        changed = np.sort(newf[nch0:nnew])
        cf_cnt[K] = len(changed)
        cf_ids = _grow_i(cf_ids, n_cf + len(changed))
        if n_cf + len(changed) > len(cf_corner):
            cc8 = np.empty(max(2 * len(cf_corner), n_cf + len(changed)), dtype=np.int8)
            cc8[:n_cf] = cf_corner[:n_cf]
            cf_corner = cc8
        for t in range(len(changed)):
            f = changed[t]
            c = 0 if Fm[f, 0] == j else (1 if Fm[f, 1] == j else 2)
            Fm[f, c] = i
            cf_ids[n_cf] = f
            cf_corner[n_cf] = c
            n_cf += 1
        if nnew > vcap[i]:
            newcap = 2 * nnew
            if pool_end + newcap > len(pool):
                pool = _grow_i(pool, pool_end + newcap)
            vstart[i] = pool_end
            vcap[i] = newcap
            pool_end += newcap
        si = vstart[i]
        for t in range(nnew):
            pool[si + t] = newf[t]
        vcnt[i] = nnew
        vcnt[j] = 0
        alive[j] = False
        P[i, 0] = x
        P[i, 1] = y
        P[i, 2] = z
        for c in range(10):
            Q[i, c] += Q[j, c]
        bnd[i] = bnd[i] or bnd[j]
        stamp[i] += 1
        stamp[j] += 1
        nf -= ns
        # rings: after (Ni | Nj) - {i, j}, before Ni and Nj (ascending)
        gen += 1
        gR = gen
        nR = 0
        if nNi + nNj > len(ring):
            ring = _grow_i(ring, nNi + nNj)
        for t in range(nNi):
            w = Ni[t]
            if w != j and markR[w] != gR:
                markR[w] = gR
                ring[nR] = w
                nR += 1
        for t in range(nNj):
            w = Nj[t]
            if w != i and markR[w] != gR:
                markR[w] = gR
                ring[nR] = w
                nR += 1
        rs = np.sort(ring[:nR])
        ring_cnt[K] = nR
        ring_all = _grow_i(ring_all, n_ring + nR)
        ring_all[n_ring:n_ring + nR] = rs
        n_ring += nR
        rk_cnt[K] = nNi
        rk_all = _grow_i(rk_all, n_rk + nNi)
        rk_all[n_rk:n_rk + nNi] = np.sort(Ni[:nNi])
        n_rk += nNi
        rr_cnt[K] = nNj
        rr_all = _grow_i(rr_all, n_rr + nNj)
        rr_all[n_rr:n_rr + nNj] = np.sort(Nj[:nNj])
        n_rr += nNj
        K += 1
        collapsed_since_rebuild += 1
        # new heap entries: the merged vertex's edges, then refused edges around it
        for t in range(nR):
            w = rs[t]
            if True:
                ok, c2, ku, x2, y2, z2 = _edge_cost(i, w, P, Q, bnd, protect, midpoint)
                if ok:
                    if n_entries >= len(ecost):
                        nc = 2 * len(ecost)
                        ecost = _grow_f(ecost, nc)
                        eu = _grow_i(eu, nc)
                        ev = _grow_i(ev, nc)
                        esu = _grow_i(esu, nc)
                        esv = _grow_i(esv, nc)
                        heap = _grow_i(heap, nc)
                    en = n_entries
                    n_entries += 1
                    ecost[en] = c2
                    eu[en] = i
                    ev[en] = w
                    esu[en] = stamp[i]
                    esv[en] = stamp[w]
                    heap[hsize] = en
                    hsize += 1
                    _sift_up(heap, hsize - 1, ecost)
        if any_rej:
            for t in range(nR):
                w = rs[t]
                r = rej_head[w]
                rej_head[w] = -1
                while r >= 0:
                    t2 = rej_part[r]
                    r = rej_next[r]
                    if alive[t2] and t2 != i:
                        # the pair leaves t2's set too (it is pushed once, from here)
                        prev = -1
                        r2 = rej_head[t2]
                        while r2 >= 0:
                            if rej_part[r2] == w:
                                if prev < 0:
                                    rej_head[t2] = rej_next[r2]
                                else:
                                    rej_next[prev] = rej_next[r2]
                                break
                            prev = r2
                            r2 = rej_next[r2]
                        ok, c2, ku, x2, y2, z2 = _edge_cost(w, t2, P, Q, bnd, protect,
                                                            midpoint)
                        if ok:
                            if n_entries >= len(ecost):
                                nc = 2 * len(ecost)
                                ecost = _grow_f(ecost, nc)
                                eu = _grow_i(eu, nc)
                                ev = _grow_i(ev, nc)
                                esu = _grow_i(esu, nc)
                                esv = _grow_i(esv, nc)
                                heap = _grow_i(heap, nc)
                            en = n_entries
                            n_entries += 1
                            ecost[en] = c2
                            eu[en] = w
                            ev[en] = t2
                            esu[en] = stamp[w]
                            esv[en] = stamp[t2]
                            heap[hsize] = en
                            hsize += 1
                            _sift_up(heap, hsize - 1, ecost)
            rej_head[i] = -1
            rej_head[j] = -1
        # entries are never reused; compact the entry arrays when the heap holds few of them
        if n_entries > 4 * hsize + 1_000_000:
            newid = np.empty(hsize, dtype=np.int64)
            for t in range(hsize):
                newid[t] = heap[t]
            order = np.argsort(newid)
            # renumber live entries in increasing id order (keeps the tie-breaking order)
            ids = newid[order]
            for t in range(hsize):
                o = ids[t]
                ecost[t] = ecost[o]
                eu[t] = eu[o]
                ev[t] = ev[o]
                esu[t] = esu[o]
                esv[t] = esv[o]
            rank = np.empty(hsize, dtype=np.int64)
            for t in range(hsize):
                rank[order[t]] = t
            for t in range(hsize):
                heap[t] = rank[t]
            n_entries = hsize
    return (P, Fm, falive, alive, nf, reached, K, r_kept[:K], r_removed[:K], r_pos[:K],
            r_cost[:K], rf_cnt[:K], rf_ids[:n_rf], rf_tri[:3 * n_rf], cf_cnt[:K],
            cf_ids[:n_cf], cf_corner[:n_cf], ring_cnt[:K], ring_all[:n_ring], rk_cnt[:K],
            rk_all[:n_rk], rr_cnt[:K], rr_all[:n_rr])


@njit(**_OPTS)
def propagate_clusters(lab, kept, removed):
    """``lab[removed[k]] = lab[kept[k]]`` for k = K-1 .. 0 (:meth:`Decimation.clusters`)."""
    for k in range(len(kept) - 1, -1, -1):
        lab[removed[k]] = lab[kept[k]]
    return lab
