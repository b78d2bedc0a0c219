"""Classic subdivision baselines of neural subdivision (thesis Table 4.2): Loop, modified
butterfly, mid-point.

Loop and mid-point are the project's libigl-backed :mod:`algorithms.mesh.subdivision`. The
modified butterfly scheme (Zorin, Schröder & Sweldens 1996, "Interpolating subdivision for meshes
with arbitrary topology") has no maintained Python implementation (libigl, gpytoolbox and
trimesh offer Loop and mid-point only), so it is written here on the topology of
:func:`algorithms.subdivision.topology.refine` (old vertices stay, vertex ``n + e`` on edge ``e``):

* interior edge (a, b), both ends interior of valence 6: the 8-point butterfly,
  ``1/2 (a + b) + 1/8 (c + d) - 1/16 (e + f + g + h)`` (the tension ``w = 0`` of Zorin et al.);
* one interior end of valence K != 6 (the other regular): that end's K-stencil,
  ``3/4 a + sum_j s_j v_j`` with ``v_0 = b`` and the neighbours in rotational order,
  K = 3: (5/12, -1/12, -1/12); K = 4: (3/8, 0, -1/8, 0); K >= 5:
  ``s_j = (1/4 + cos(2 pi j / K) + 1/2 cos(4 pi j / K)) / K``;
  both ends extraordinary: the average of the two stencils;
* boundary edges: the 4-point curve rule ``-1/16 p + 9/16 a + 9/16 b - 1/16 q`` along the
  boundary;
* interior edges touching the boundary (Zorin's special boundary stencils are not reproduced --
  our choice): one end interior, that end's K-stencil (any K); both ends on the boundary,
  Loop's edge rule ``3/8 (a + b) + 1/8 (c + d)``.
"""

from __future__ import annotations

import numpy as np

from ..mesh.subdivision import loop_subdivide, midpoint_subdivide
from .topology import half_flaps, refine

__all__ = ["loop_subdivide", "midpoint_subdivide", "butterfly_subdivide", "butterfly_weights",
           "subdivide_baseline", "BASELINES"]

BASELINES = ("loop", "butterfly", "midpoint")


def butterfly_weights(K: int) -> np.ndarray:
    """The modified-butterfly stencil ``s_0..s_{K-1}`` of an extraordinary vertex of valence K."""
    if K == 3:
        return np.array([5 / 12, -1 / 12, -1 / 12])
    if K == 4:
        return np.array([3 / 8, 0.0, -1 / 8, 0.0])
    j = np.arange(K)
    return (0.25 + np.cos(2 * np.pi * j / K) + 0.5 * np.cos(4 * np.pi * j / K)) / K


def _butterfly_level(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(V)
    hf = half_flaps(F, n)
    H = len(hf.ijkl)
    i, j, k, l = hf.ijkl.T
    twin_face = hf.twin_face
    # twin half-edge of every half-edge (-1 on the boundary)
    src, dst = i, j
    key = src * n + dst
    order = np.argsort(key)
    pos = np.minimum(np.searchsorted(key[order], dst * n + src), H - 1)
    twin = np.where(key[order][pos] == dst * n + src, order[pos], -1)
    prev = 3 * (np.arange(H) // 3) + (np.arange(H) + 2) % 3  # (k -> i) in the same face
    nxt = 3 * (np.arange(H) // 3) + (np.arange(H) + 1) % 3   # (j -> k)
    bnd_v = np.zeros(n, dtype=bool)
    bnd_v[i[twin < 0]] = True
    bnd_v[j[twin < 0]] = True
    valence = hf.degree.astype(np.int64)
    e = len(hf.E)
    # one representative half-edge per edge (the first one seen)
    rep = np.full(e, -1, dtype=np.int64)
    rep[hf.edge[::-1]] = np.arange(H)[::-1]
    h = rep
    a, b, c, d = i[h], j[h], k[h], l[h]
    out = 0.5 * (V[a] + V[b])
    is_b_edge = twin[h] < 0

    def wing(hh):  # third vertex of the face across half-edge hh (or -1)
        t = twin[hh]
        return np.where(t >= 0, k[np.maximum(t, 0)], -1)

    def stencil(hs):  # K-stencil around the source of half-edges hs (source interior)
        res = 0.75 * V[i[hs]]
        K = valence[i[hs]]
        cur = hs.copy()
        for step in range(int(K.max()) if len(K) else 0):
            live = step < K
            w = np.zeros(len(hs))
            for kk in np.unique(K[live]):
                sel = live & (K == kk)
                w[sel] = butterfly_weights(int(kk))[step]
            res += w[:, None] * V[j[cur]]
            nx = twin[prev[cur]]  # next outgoing half-edge around the source
            cur = np.where(live & (nx >= 0), nx, cur)
        return res

    inner = ~is_b_edge
    ba, bb = bnd_v[a], bnd_v[b]
    reg = inner & ~ba & ~bb & (valence[a] == 6) & (valence[b] == 6)
    if reg.any():
        hr = h[reg]
        wings = (wing(nxt[hr]) , wing(prev[hr]), wing(nxt[twin[hr]]), wing(prev[twin[hr]]))
        w = sum(V[x] for x in wings)
        out[reg] = (0.5 * (V[a[reg]] + V[b[reg]]) + 0.125 * (V[c[reg]] + V[d[reg]])
                    - 0.0625 * w)
    ext_a = inner & ~ba & ((valence[a] != 6) | bb) & ~reg
    ext_b = inner & ~bb & ((valence[b] != 6) | ba) & ~reg
    acc = np.zeros_like(out)
    cnt = np.zeros(e)
    if ext_a.any():
        acc[ext_a] += stencil(h[ext_a])
        cnt[ext_a] += 1
    if ext_b.any():
        acc[ext_b] += stencil(twin[h[ext_b]])
        cnt[ext_b] += 1
    has = cnt > 0
    out[has] = acc[has] / cnt[has, None]
    both_b = inner & ba & bb
    if both_b.any():
        out[both_b] = (0.375 * (V[a[both_b]] + V[b[both_b]])
                       + 0.125 * (V[c[both_b]] + V[d[both_b]]))
    if is_b_edge.any():
        nb = np.full(n, -1, dtype=np.int64)
        pb = np.full(n, -1, dtype=np.int64)
        bh = np.flatnonzero(twin < 0)
        nb[i[bh]] = j[bh]
        pb[j[bh]] = i[bh]
        ha = a[is_b_edge]
        hb = b[is_b_edge]
        p, q = pb[ha], nb[hb]
        out[is_b_edge] = (9 / 16 * (V[ha] + V[hb]) - 1 / 16 * (V[p] + V[q]))
    return np.concatenate([V, out]), refine(F, n, hf.EF)


def butterfly_subdivide(V, F, levels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Modified butterfly subdivision (interpolating; see the module docstring).

    Parameters
    ----------
    V : (n, 3) float, F : (m, 3) int -- a manifold, consistently oriented triangle mesh.
    levels : int >= 0.

    Returns
    -------
    V_sub : (n_k, 3) float64, the input vertices first, then one vertex per edge per level.
    F_sub : (m * 4**levels, 3) int64.
    """
    V, F = midpoint_subdivide(V, F, 0)  # the project's input checks
    from .data import LOOP_WORKS, check_manifold

    check_manifold(V, F, "Butterfly subdivision", LOOP_WORKS)
    for _ in range(int(levels)):
        V, F = _butterfly_level(V, F)
    return V, F


def subdivide_baseline(V, F, levels: int, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Loop, butterfly or mid-point subdivision by name."""
    if method == "loop":
        return loop_subdivide(V, F, levels)
    if method == "butterfly":
        return butterfly_subdivide(V, F, levels)
    if method == "midpoint":
        return midpoint_subdivide(V, F, levels)
    from ..errors import ParameterError

    raise ParameterError(f"Unknown subdivision method {method!r}; choose one of "
                         f"{', '.join(('neural',) + BASELINES)}.")
