"""A light stand-in of a big mesh, drawn while the camera moves (Qt- and VTK-free, NumPy only).

Vertex clustering: the bounding box is cut into cubes whose size is chosen from the surface area
so that about ``target_faces / 2`` cubes hold vertices; each occupied cube becomes one vertex (the
mean of its vertices), each triangle is mapped onto cube vertices and kept when its three corners
land in three different cubes (duplicates dropped). O(n) and about 50 ms per million vertices —
unlike a quality decimation (QSlim) it needs no priority queue, which is what a proxy built at
the start of a drag can afford. Per-vertex values (colour fields) are averaged per cube, per-face
values are taken from the kept triangles, so a coloured mesh keeps its colours while it turns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Proxy", "cluster_proxy"]


@dataclass
class Proxy:
    V: np.ndarray          # (p, 3) positions of the stand-in
    F: np.ndarray          # (q, 3) its triangles
    cluster: np.ndarray    # (n,) the stand-in vertex of each original vertex
    kept: np.ndarray       # (q,) the original triangle each stand-in triangle comes from

    def vertex_values(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values of the original mesh averaged onto the stand-in's vertices."""
        values = np.asarray(values)
        count = np.bincount(self.cluster, minlength=len(self.V)).astype(np.float64)
        flat = values.reshape(len(values), -1).astype(np.float64)
        out = np.stack([np.bincount(self.cluster, weights=flat[:, j], minlength=len(self.V))
                        for j in range(flat.shape[1])], axis=1) / np.maximum(count, 1.0)[:, None]
        out = out.reshape((len(self.V),) + values.shape[1:])
        if np.issubdtype(values.dtype, np.integer):
            out = np.rint(out)
        return out.astype(values.dtype)

    def face_values(self, values: np.ndarray) -> np.ndarray:
        """Per-triangle values of the original mesh on the stand-in's triangles."""
        return np.asarray(values)[self.kept]


def _cluster(V: np.ndarray, F: np.ndarray, h: float) -> Proxy:
    lo = V.min(axis=0)
    ijk = np.floor((V - lo) / h).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    sk = key[order]
    start = np.empty(len(sk), dtype=bool)
    start[:1] = True
    np.not_equal(sk[1:], sk[:-1], out=start[1:])
    cluster = np.empty(len(key), dtype=np.int64)
    cluster[order] = np.cumsum(start) - 1
    p = int(cluster.max()) + 1 if len(cluster) else 0
    count = np.bincount(cluster, minlength=p).astype(np.float64)
    P = np.stack([np.bincount(cluster, weights=V[:, j], minlength=p) for j in range(3)],
                 axis=1) / count[:, None]
    C = cluster[F]
    ok = (C[:, 0] != C[:, 1]) & (C[:, 1] != C[:, 2]) & (C[:, 0] != C[:, 2])
    idx = np.flatnonzero(ok)
    S = np.sort(C[idx], axis=1)
    if p < 2_000_000:  # p³ < 2⁶³: one integer per triangle
        _, first = np.unique((S[:, 0] * p + S[:, 1]) * p + S[:, 2], return_index=True)
    else:
        _, first = np.unique(S, axis=0, return_index=True)
    kept = idx[np.sort(first)]
    return Proxy(P, C[kept], cluster, kept)


def cluster_proxy(V, F, target_faces: int = 40_000) -> Proxy:
    """A stand-in of (V, F) with about ``target_faces`` triangles (at most ~1.5× that); the mesh
    itself when it is already that small."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if len(F) <= target_faces:
        return Proxy(V, F, np.arange(len(V)), np.arange(len(F)))
    e = V[F]
    area = 0.5 * np.linalg.norm(np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]), axis=1).sum()
    h = float(np.sqrt(max(area, 1e-300) / (0.5 * target_faces)))
    proxy = _cluster(V, F, h)
    for _ in range(4):  # a few corrections of the cube size (faces ~ 1 / h²)
        ratio = len(proxy.F) / target_faces
        if 0.6 <= ratio <= 1.5:
            break
        h *= float(np.sqrt(ratio))
        proxy = _cluster(V, F, h)
    return proxy
