"""Baselines for spectral coarsening: QSlim decimation + rediscretization, and algebraic
multigrid (PyAMG aggregation, Galerkin coarsening). Each returns (L~, M~, P) comparable with
:func:`algorithms.spectral.metrics.spectral_metrics`."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import ParameterError

__all__ = ["BaselineResult", "qslim_baseline", "amg_baseline"]


@dataclass
class BaselineResult:
    L: sp.csr_matrix          # coarse operator (PSD)
    M: sp.csr_matrix          # coarse mass
    P: sp.csr_matrix          # (m, n) root selection for the functional map
    seconds: float
    V: np.ndarray | None = None   # coarse mesh (QSlim only)
    F: np.ndarray | None = None


def qslim_baseline(V, F, m: int, operator: str = "cotangent", **op_kw) -> BaselineResult:
    """Decimate to about ``m`` vertices with libigl's QSlim, rebuild the operator on the coarse
    mesh; P maps every coarse vertex to the nearest fine vertex."""
    import igl
    from scipy.spatial import cKDTree

    from .operators import build_operator
    t = time.perf_counter()
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    n = len(V)
    if not 3 <= m < n:
        raise ParameterError(f"QSlim needs 3 <= m < n (m={m}, n={n}).")
    target = max(4, int(round(len(F) * m / n)))
    out = igl.qslim(V, F.astype(np.int32), target)
    U, G = np.asarray(out[-4]), np.asarray(out[-3])
    # drop unreferenced vertices
    used = np.unique(G)
    remap = -np.ones(len(U), np.int64)
    remap[used] = np.arange(len(used))
    U, G = U[used], remap[G]
    Lc, Mc, _, _ = build_operator(U, G, operator, **op_kw)
    nearest = cKDTree(V).query(U)[1]
    P = sp.csr_matrix((np.ones(len(U)), (np.arange(len(U)), nearest)), shape=(len(U), n))
    return BaselineResult(Lc, Mc, P, time.perf_counter() - t, U, G)


def amg_baseline(L, M, m: int, *, seed: int = 0, smooth: bool = True) -> BaselineResult:
    """Algebraic multigrid Galerkin coarsening to ``m`` aggregates with PyAMG.

    Aggregates: PyAMG's Lloyd aggregation (ratio m/n) on the symmetric strength-of-connection
    graph; prolongator: the tentative (0/1 aggregate) prolongator T, smoothed by one damped
    Jacobi step (smoothed aggregation) so that T 1 = 1 keeps nodal values; L~ = T^T L T,
    M~ = T^T M T (Galerkin); P = the aggregate roots (Lloyd seeds).
    """
    import pyamg
    from pyamg.aggregation import lloyd_aggregation
    from pyamg.strength import symmetric_strength_of_connection
    t = time.perf_counter()
    L = sp.csr_matrix(L)
    n = L.shape[0]
    Mm = M if sp.issparse(M) else sp.diags(np.asarray(M, float))
    np.random.seed(seed)   # PyAMG's Lloyd seeding uses the global NumPy generator
    C = symmetric_strength_of_connection(L, theta=0.0)
    AggOp, seeds = lloyd_aggregation(C, ratio=m / n)
    AggOp = sp.csr_matrix(AggOp)
    AggOp.data[:] = 1.0
    T = AggOp
    if smooth:
        Dinv = sp.diags(1.0 / L.diagonal())
        S = (Dinv @ L).tocsr()
        rho = pyamg.util.linalg.approximate_spectral_radius(S)
        T = (T - (4.0 / 3.0 / rho) * (S @ T)).tocsr()
    Lc = (T.T @ L @ T).tocsr()
    Lc = 0.5 * (Lc + Lc.T)
    Mc = (T.T @ Mm @ T).tocsr()
    Mc = 0.5 * (Mc + Mc.T)
    mm = T.shape[1]
    seeds = np.asarray(seeds, np.int64)
    # root of each aggregate: its seed when it lies in it, else its first member
    agg_of = np.asarray(AggOp.argmax(axis=1)).ravel()
    roots = np.full(mm, -1, np.int64)
    ok = agg_of[seeds] < mm
    roots[agg_of[seeds[ok]]] = seeds[ok]
    missing = np.flatnonzero(roots < 0)
    if len(missing):
        first = np.full(mm, -1, np.int64)
        first[agg_of[::-1]] = np.arange(n)[::-1]
        roots[missing] = first[missing]
    P = sp.csr_matrix((np.ones(mm), (np.arange(mm), roots)), shape=(mm, n))
    return BaselineResult(sp.csr_matrix(Lc), sp.csr_matrix(Mc), P, time.perf_counter() - t)
