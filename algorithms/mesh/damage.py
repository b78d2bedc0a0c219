"""Triangles a deformation folded over or collapsed (same triangles before and after).

One definition for the methods that keep from making them (the smoothing flows,
:mod:`algorithms.smoothing`) and for the corpus measurement that counts them as artefacts
(``benchmarks/corpus.py``, issue 38). The thresholds were set from what a person sees before
the corpus was first run, not tuned on it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["COLLAPSED_AREA", "FOLD_ANGLE", "FOLD_TURN", "collapsed_triangles",
           "folded_triangles"]

#: Degrees between a triangle's normal and a neighbour's above which it is turned back ...
FOLD_ANGLE = 120.0
#: ... when that angle also grew by at least this many degrees.
FOLD_TURN = 60.0
#: A triangle of less area than this times the squared bounding-box diagonal (of the input)
#: is collapsed (degenerate).
COLLAPSED_AREA = 1e-12


def _tiny(V0: np.ndarray) -> float:
    diag = float(np.linalg.norm(np.ptp(V0, axis=0))) or 1.0
    return COLLAPSED_AREA * diag * diag


def collapsed_triangles(V0, V, F) -> np.ndarray:
    """(m,) bool: triangles of ``F`` of (nearly) zero area at ``V`` that had area at ``V0``
    (below :data:`COLLAPSED_AREA` of the input's squared diagonal)."""
    from .operators import face_areas

    tiny = _tiny(np.asarray(V0))
    return (face_areas(V, F) <= tiny) & (face_areas(V0, F) > tiny)


def folded_triangles(V0, V, F) -> np.ndarray:
    """(m,) bool: triangles of ``F`` folded over at ``V`` against the input ``V0``.

    A triangle is folded over when, across at least two of its edges (across all of them if it
    has fewer neighbours), the angle between its normal and the neighbour's is above
    :data:`FOLD_ANGLE` and grew by at least :data:`FOLD_TURN`: it was turned back against the
    surface around it, as a flipped triangle is. Triangles of (nearly) zero area before or
    after have no normal to judge and are left to :func:`collapsed_triangles`.

    The comparison is edge by edge, with each angle measured against the same edge's angle in
    the input, so a sharp edge the input already had (a CAD part's 90-degree rims, a thin
    plate's knife edge) is no fold, and a triangle that hardly turned is never one.
    """
    import scipy.sparse as sp

    from .operators import face_areas, face_normals
    from .topology import face_adjacency

    V0 = np.asarray(V0)
    A = sp.triu(face_adjacency(F), k=1).tocoo()
    f, g = A.row, A.col
    N0, N = face_normals(V0, F), face_normals(V, F)
    tiny = _tiny(V0)
    ok = (face_areas(V0, F) > tiny) & (face_areas(V, F) > tiny)
    use = ok[f] & ok[g]
    f, g = f[use], g[use]
    before = np.degrees(np.arccos(np.clip((N0[f] * N0[g]).sum(axis=1), -1.0, 1.0)))
    after = np.degrees(np.arccos(np.clip((N[f] * N[g]).sum(axis=1), -1.0, 1.0)))
    back = (after > FOLD_ANGLE) & (after - before >= FOLD_TURN)
    m = len(F)
    n_nb = np.bincount(f, minlength=m) + np.bincount(g, minlength=m)
    n_back = np.bincount(f[back], minlength=m) + np.bincount(g[back], minlength=m)
    return ok & (n_nb > 0) & (n_back >= np.minimum(n_nb, 2))
