"""Compiled (Numba) replay of affine vertex splits (:class:`algorithms.deform.progressive.
AffineSplits`): the splits one at a time in reverse collapse order, exactly the arithmetic of
:meth:`~algorithms.deform.progressive.AffineSplits.apply_sequential` (weighted sums over the
1-ring; for the regularized splits the similarity prior ``s R g`` with ``R`` the Procrustes
rotation, det-fixed, of the rest ring onto the deformed ring).

One pass over the ring entries with no temporary arrays: 0.10-0.15 s CPU for the ~630k splits
of a 1.29M-triangle mesh (measured, ``benchmarks/progressive.py``; the batched NumPy replay in
waves of independent splits took 0.34 s at 1.07M before, and needs its schedule built first);
bob 5k splits 0.2 ms against 24-109 ms. The NumPy replay stays as the fallback without Numba. Importing this module imports Numba; the caller imports it lazily.
"""

from __future__ import annotations

import numpy as np
from .._numba import njit

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


@njit(**_OPTS)
def replay_splits(P, kept, removed, ring_ptr, ring, weights, reg_index, reg_q, reg_q_ptr,
                  reg_g):
    """Replay every split in place on ``P`` (n_fine, 3), whose coarse rows are set.

    ``weights`` (S, 2) per ring entry; ``reg_index`` (K,) the row of a regularized split in
    ``reg_g`` (nr, 3, 2) and ``reg_q_ptr`` (nr + 1,) into ``reg_q`` (rest ring vectors), or -1.
    """
    K = len(kept)
    S = np.empty((3, 3))
    R = np.empty((3, 3))
    for k in range(K - 1, -1, -1):
        c = kept[k]
        p0, p1, p2 = P[c, 0], P[c, 1], P[c, 2]
        k0 = k1 = k2 = 0.0
        r0 = r1 = r2 = 0.0
        a, b = ring_ptr[k], ring_ptr[k + 1]
        for e in range(a, b):
            nb = ring[e]
            d0, d1, d2 = P[nb, 0] - p0, P[nb, 1] - p1, P[nb, 2] - p2
            w0, w1 = weights[e, 0], weights[e, 1]
            k0 += w0 * d0
            k1 += w0 * d1
            k2 += w0 * d2
            r0 += w1 * d0
            r1 += w1 * d1
            r2 += w1 * d2
        r = reg_index[k]
        if r >= 0:
            S[:, :] = 0.0
            nrm = 0.0
            q0 = reg_q_ptr[r]
            for t in range(b - a):
                nb = ring[a + t]
                d0, d1, d2 = P[nb, 0] - p0, P[nb, 1] - p1, P[nb, 2] - p2
                qa, qb, qc = reg_q[q0 + t, 0], reg_q[q0 + t, 1], reg_q[q0 + t, 2]
                S[0, 0] += qa * d0
                S[0, 1] += qa * d1
                S[0, 2] += qa * d2
                S[1, 0] += qb * d0
                S[1, 1] += qb * d1
                S[1, 2] += qb * d2
                S[2, 0] += qc * d0
                S[2, 1] += qc * d1
                S[2, 2] += qc * d2
                nrm += qa * qa + qb * qb + qc * qc
            # R maximizing tr(R S): S = U diag(s) Vt -> R = Vt^T diag(1, 1, det) U^T
            U, sv, Vt = np.linalg.svd(S)
            det = np.linalg.det(Vt.T @ U.T)
            for i in range(3):
                for j in range(3):
                    R[i, j] = (Vt[0, i] * U[j, 0] + Vt[1, i] * U[j, 1]
                               + (1.0 if det >= 0 else -1.0) * Vt[2, i] * U[j, 2])
            tr = 0.0
            for i in range(3):
                for j in range(3):
                    tr += R[i, j] * S[j, i]
            scale = tr / nrm if nrm > 0 else tr
            g = reg_g[r]
            for i in range(3):
                ak = R[i, 0] * g[0, 0] + R[i, 1] * g[1, 0] + R[i, 2] * g[2, 0]
                ar = R[i, 0] * g[0, 1] + R[i, 1] * g[1, 1] + R[i, 2] * g[2, 1]
                if i == 0:
                    k0 += scale * ak
                    r0 += scale * ar
                elif i == 1:
                    k1 += scale * ak
                    r1 += scale * ar
                else:
                    k2 += scale * ak
                    r2 += scale * ar
        j = removed[k]
        P[j, 0] = p0 + r0
        P[j, 1] = p1 + r1
        P[j, 2] = p2 + r2
        P[c, 0] = p0 + k0
        P[c, 1] = p1 + k1
        P[c, 2] = p2 + k2
    return P

