"""Connected components of an undirected graph given by its edges, in NumPy alone.

Mesh checks (validation, components, boundary loops) need connected components on every file
opened; SciPy's ``csgraph`` brings ``scipy.sparse.linalg`` and ``scipy.linalg`` with it, about
0.2 s of imports, which is most of a small command's start-up (issue 25: ``stylize3d info``
≤ 0.5 s). This is the same result without them: union by the smaller root (hooking) and pointer
jumping, vectorized (O(log n) rounds of O(edges) work on meshes), with SciPy's labels —
components numbered in the order of their smallest vertex. When SciPy's ``csgraph`` is already
loaded (the app, every method), its compiled traversal is used: 4.5× faster at 233k vertices
(0.034 vs 0.15 s), the same labels (tested).
"""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["connected_components"]


def connected_components(n: int, i, j, backend: str = "auto") -> tuple[int, np.ndarray]:
    """``(count, labels)`` of the graph on ``n`` nodes with undirected edges ``(i[k], j[k])``,
    exactly as ``scipy.sparse.csgraph.connected_components(..., directed=False)`` gives them
    (component k holds the k-th smallest of the components' smallest nodes). ``backend``:
    "numpy", "scipy", or "auto" (SciPy when it is already imported, else NumPy)."""
    n = int(n)
    i = np.asarray(i, dtype=np.int64).ravel()
    j = np.asarray(j, dtype=np.int64).ravel()
    if i.shape != j.shape:
        raise ValueError("i and j must have the same length")
    if n == 0:
        return 0, np.zeros(0, dtype=np.int32)
    if i.size and (min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= n):
        raise ValueError("edge endpoints must be in [0, n)")
    if backend == "scipy" or (backend == "auto" and "scipy.sparse.csgraph" in sys.modules):
        import scipy.sparse as sp
        from scipy.sparse.csgraph import connected_components as scipy_cc

        G = sp.coo_matrix((np.ones(i.size, np.int8), (i, j)), shape=(n, n))
        count, labels = scipy_cc(G, directed=False)
        return int(count), labels.astype(np.int32)
    if backend not in ("auto", "numpy"):
        raise ValueError(f"backend must be auto, numpy or scipy, not {backend!r}")
    parent = np.arange(n, dtype=np.int64)
    keep = i != j
    i, j = i[keep], j[keep]
    while i.size:
        pi, pj = parent[i], parent[j]   # roots (parent is flat after the jumping below)
        lo, hi = np.minimum(pi, pj), np.maximum(pi, pj)
        differ = lo != hi
        if not differ.any():
            break
        lo, hi = lo[differ], hi[differ]
        i, j = i[differ], j[differ]      # edges inside one component are done
        np.minimum.at(parent, hi, lo)    # hook each root under the smallest root it touches
        while True:                      # pointer jumping until every node points at a root
            up = parent[parent]
            if np.array_equal(up, parent):
                break
            parent = up
    roots, labels = np.unique(parent, return_inverse=True)
    return int(roots.size), labels.astype(np.int32).ravel()
