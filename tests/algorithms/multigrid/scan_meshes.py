"""Meshes that look like real scans, made from clean meshes (tests and benchmarks of issue 10).

:func:`scan_like` cuts a few small holes (each the faces of a small vertex neighbourhood:
6-50 boundary edges), adds thin triangles (edges split very near one end: two needles per
split; vertices pushed towards an opposite edge: flat obtuse caps) and perturbs the positions
with a little noise along the normals. The result is a manifold, consistently oriented mesh
that ``validate_mesh`` accepts as it is (no degenerate triangles), with a minimum triangle
quality ``4 sqrt(3) A / sum l^2`` of about ``min_quality``.

:func:`many_handles` is a closed mesh of high genus (a grid of tubes), the kind of input on
which the hierarchy used to stall.
"""

from __future__ import annotations

import numpy as np

from algorithms.mesh.operators import face_areas, vertex_normals
from algorithms.mesh.topology import boundary_loops, unique_edges


def quality(V, F) -> np.ndarray:
    """Triangle quality ``4 sqrt(3) A / (l1^2 + l2^2 + l3^2)`` (1 equilateral, 0 degenerate)."""
    e = V[F[:, [1, 2, 0]]] - V[F[:, [2, 0, 1]]]
    return 4.0 * np.sqrt(3.0) * face_areas(V, F) / np.maximum((e ** 2).sum(axis=(1, 2)), 1e-300)


def _compact(V, F):
    used = np.unique(F)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return V[used].copy(), remap[F]


def _cut_holes(V, F, n_holes, rng):
    """Remove the faces around ``n_holes`` random vertices (their 1-ring or 2-ring)."""
    n = len(V)
    for _ in range(50 * n_holes):
        if n_holes == 0:
            break
        c = int(rng.integers(n))
        ring = np.unique(F[(F == c).any(axis=1)])
        if rng.random() < 0.5:
            ring = np.unique(F[np.isin(F, ring).any(axis=1)])
        drop = np.isin(F, ring).all(axis=1)
        if not drop.any():
            continue
        F2 = F[~drop]
        loops = boundary_loops(F2)
        old = boundary_loops(F)
        # one new simple loop of 6-50 edges, and the mesh stays manifold (no vertex on two loops)
        new_len = sum(len(lp) for lp in loops) - sum(len(lp) for lp in old)
        if len(loops) != len(old) + 1 or not 6 <= new_len <= 50:
            continue
        allv = np.concatenate(loops)
        if len(np.unique(allv)) != len(allv):
            continue
        F = F2
        n_holes -= 1
    return F


def _split_near_end(V, F, n_splits, t, rng):
    """Split interior edges at ``t`` of their length from one end: 2 needle triangles each."""
    V = list(V)
    F = F.copy()
    E, _, _ = unique_edges(F)
    touched = np.zeros(len(V) + n_splits, dtype=bool)  # one split per neighbourhood
    for e in E[rng.permutation(len(E))]:
        if n_splits == 0:
            break
        i, j = int(e[0]), int(e[1])
        fi = np.flatnonzero((F == i).any(axis=1) & (F == j).any(axis=1))
        if len(fi) != 2 or touched[np.unique(F[fi])].any():
            continue
        touched[np.unique(F[fi])] = True
        n_splits -= 1
        k = len(V)
        V.append((1 - t) * np.asarray(V[i]) + t * np.asarray(V[j]))
        new = []
        for f in fi:
            a, b, c = F[f]
            # rotate so that the edge is (a, b) in the face's order
            tri = [int(a), int(b), int(c)]
            while not ({tri[0], tri[1]} == {i, j}):
                tri = tri[1:] + tri[:1]
            a, b, c = tri
            F[f] = [a, k, c]
            new.append([k, b, c])
        F = np.vstack([F, np.asarray(new, dtype=np.int64)])
    return np.asarray(V), F


def _flatten_caps(V, F, n_caps, target_q, rng):
    """Push vertices towards the opposite edge of one of their triangles (obtuse flat caps)."""
    V = V.copy()
    loops = boundary_loops(F)
    bnd = np.zeros(len(V), dtype=bool)
    if loops:
        bnd[np.concatenate(loops)] = True
    done = 0
    for _ in range(20 * n_caps):
        if done == n_caps:
            break
        f = int(rng.integers(len(F)))
        c = int(rng.integers(3))
        v, a, b = F[f, c], F[f, (c + 1) % 3], F[f, (c + 2) % 3]
        inc = np.flatnonzero((F == v).any(axis=1))
        if bnd[v] or quality(V, F[inc]).min() < 0.3:
            continue
        foot = 0.5 * (V[a] + V[b])
        x0 = V[v].copy()
        ok = False
        for s in np.linspace(0.5, 0.98, 25):
            V[v] = (1 - s) * x0 + s * foot
            q = quality(V, F[inc])
            if q.min() <= target_q:
                ok = q.min() > 0.3 * target_q
                break
        if ok:
            done += 1
        else:
            V[v] = x0
    return V


def scan_like(V, F, *, holes: int = 2, needles: int = 150, caps: int = 60,
              min_quality: float = 0.02, noise: float = 0.05, seed: int = 0):
    """A scan-like copy of (V, F): holes, thin triangles and noise (see the module docstring).

    ``noise`` is relative to the mean edge length, along the vertex normals.
    """
    rng = np.random.default_rng(seed)
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    F = _cut_holes(V, F, holes, rng)
    V, F = _compact(V, F)
    E, _, _ = unique_edges(F)
    mean_edge = float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())
    V = V + noise * mean_edge * rng.standard_normal((len(V), 1)) * vertex_normals(V, F)
    # a needle of split fraction t has quality ~ 2 t q0 / (1 + ...): t ~ min_quality / 1.4
    V, F = _split_near_end(V, F, needles, 0.7 * min_quality, rng)
    V = _flatten_caps(V, F, caps, min_quality, rng)
    return V, F


def many_handles(nx: int = 6, ny: int = 6, res: int = 8):
    """A closed surface of genus ``nx * ny``: a thick plate pierced by a grid of square holes.

    Built as the boundary of a union of voxels (a plate ``(2 nx + 1) x (2 ny + 1)`` cells wide,
    one cell thick, every other cell removed), each voxel face split into ``res x res`` quads
    and triangulated, then the vertices are welded.
    """
    W, H = 2 * nx + 1, 2 * ny + 1
    solid = np.ones((W, H), dtype=bool)
    solid[1::2, 1::2] = False
    quads = []
    # faces of the voxel grid (x, y in cells, z in [0, 1]) on the boundary of the solid
    for x in range(W):
        for y in range(H):
            if not solid[x, y]:
                continue
            c = np.array([x, y, 0.0])
            quads.append((c, (1, 0, 0), (0, 1, 0), -1))      # bottom z=0 (outward -z)
            quads.append((c + [0, 0, 1], (1, 0, 0), (0, 1, 0), +1))
            for dx, dy, o, u, w, sgn in (
                    (-1, 0, (0, 0, 0), (0, 1, 0), (0, 0, 1), -1),
                    (1, 0, (1, 0, 0), (0, 1, 0), (0, 0, 1), +1),
                    (0, -1, (0, 0, 0), (1, 0, 0), (0, 0, 1), +1),
                    (0, 1, (0, 1, 0), (1, 0, 0), (0, 0, 1), -1)):
                xx, yy = x + dx, y + dy
                if 0 <= xx < W and 0 <= yy < H and solid[xx, yy]:
                    continue
                quads.append((c + np.asarray(o, float), u, w, sgn))
    Vs, Fs = [], []
    g = np.linspace(0.0, 1.0, res + 1)
    for origin, u, w, sgn in quads:
        u = np.asarray(u, float)
        w = np.asarray(w, float)
        P = origin[None, None, :] + g[:, None, None] * u + g[None, :, None] * w
        base = sum(len(v) for v in Vs)
        Vs.append(P.reshape(-1, 3))
        idx = base + np.arange((res + 1) ** 2).reshape(res + 1, res + 1)
        a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
        T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
        if sgn < 0:
            T = T[:, ::-1]
        Fs.append(T)
    V = np.concatenate(Vs)
    F = np.concatenate(Fs).astype(np.int64)
    key = np.round(V * res * 4).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    V = V[first]
    F = inv.reshape(-1)[F]
    return V, F
