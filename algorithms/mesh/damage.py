"""Triangles a deformation folded over or collapsed (same triangles before and after).

One definition for the methods that keep from making them (the smoothing flows,
:mod:`algorithms.smoothing`) and for the corpus measurement that counts them as artefacts
(``benchmarks/corpus.py``, issue 38). The thresholds were set from what a person sees before
the corpus was first run, not tuned on it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["COLLAPSED_AREA", "Damage", "FOLD_ANGLE", "FOLD_TURN", "collapsed_triangles",
           "folded_triangles"]

#: Degrees between a triangle's normal and a neighbour's above which it is turned back ...
FOLD_ANGLE = 120.0
#: ... when that angle also grew by at least this many degrees.
FOLD_TURN = 60.0
#: A triangle of less area than this times the squared bounding-box diagonal (of the input)
#: is collapsed (degenerate).
COLLAPSED_AREA = 1e-12


class Damage:
    """The input's side of :func:`folded_triangles` and :func:`collapsed_triangles`, computed
    once for a mesh that is checked again and again (a smoothing flow checks every step)."""

    def __init__(self, V0, F):
        import scipy.sparse as sp

        from .operators import face_areas, face_normals
        from .topology import face_adjacency

        V0 = np.asarray(V0, dtype=np.float64)
        self.F = np.asarray(F, dtype=np.int64)
        diag = float(np.linalg.norm(np.ptp(V0, axis=0))) or 1.0
        self.tiny = COLLAPSED_AREA * diag * diag
        self.had_area = face_areas(V0, self.F) > self.tiny
        A = sp.triu(face_adjacency(self.F), k=1).tocoo()
        self.f, self.g = A.row, A.col
        N0 = face_normals(V0, self.F)
        self.before = np.degrees(np.arccos(np.clip((N0[self.f] * N0[self.g]).sum(axis=1),
                                                   -1.0, 1.0)))

    def collapsed(self, V) -> np.ndarray:
        """:func:`collapsed_triangles` at ``V``."""
        from .operators import face_areas

        return (face_areas(V, self.F) <= self.tiny) & self.had_area

    def folded(self, V) -> np.ndarray:
        """:func:`folded_triangles` at ``V``."""
        from .operators import face_areas, face_normals

        f, g = self.f, self.g
        N = face_normals(V, self.F)
        ok = self.had_area & (face_areas(V, self.F) > self.tiny)
        use = ok[f] & ok[g]
        after = np.degrees(np.arccos(np.clip((N[f[use]] * N[g[use]]).sum(axis=1), -1.0, 1.0)))
        back = (after > FOLD_ANGLE) & (after - self.before[use] >= FOLD_TURN)
        m = len(self.F)
        n_nb = np.bincount(f[use], minlength=m) + np.bincount(g[use], minlength=m)
        n_back = np.bincount(f[use][back], minlength=m) + np.bincount(g[use][back], minlength=m)
        return ok & (n_nb > 0) & (n_back >= np.minimum(n_nb, 2))


def collapsed_triangles(V0, V, F) -> np.ndarray:
    """(m,) bool: triangles of ``F`` of (nearly) zero area at ``V`` that had area at ``V0``
    (below :data:`COLLAPSED_AREA` of the input's squared diagonal)."""
    return Damage(V0, F).collapsed(V)


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
    return Damage(V0, F).folded(V)
