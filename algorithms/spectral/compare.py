"""One call for a CLI/GUI: coarsen a mesh operator with ours, QSlim and AMG and score them."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from .baselines import amg_baseline, qslim_baseline
from .coarsen import CoarsenParams, coarsen, generalized_eigs
from .metrics import spectral_metrics
from .operators import build_operator

__all__ = ["MethodResult", "Comparison", "compare_coarsenings", "compare_coarsenings_iter"]


@dataclass
class MethodResult:
    """One method's coarse operator and scores; ``spectral`` keeps the functional map C and the
    eigenvalues (for plots)."""

    name: str
    L: sp.csr_matrix
    M: sp.csr_matrix
    P: sp.csr_matrix
    metrics: dict[str, float]
    seconds: float
    extra: dict = field(default_factory=dict)
    spectral: object = None  # metrics.SpectralMetrics


@dataclass
class Comparison:
    n: int
    m: int
    k: int
    operator: str
    methods: dict[str, MethodResult]
    timings: dict[str, float]
    fine_eigs: tuple | None = None  # (eigenvalues (k',), eigenvectors (n, k')) of the fine operator

    def table(self) -> str:
        lines = [f"{'method':8s} {'m':>6s} {'C diag':>8s} {'eig mean':>9s} {'eig max':>9s} {'s':>7s}"]
        for r in self.methods.values():
            mt = r.metrics
            lines.append(f"{r.name:8s} {r.L.shape[0]:6d} {mt['c_diag_score']:8.3f} "
                         f"{mt['eig_rel_error_mean']:9.3g} {mt['eig_rel_error_max']:9.3g} "
                         f"{r.seconds:7.2f}")
        return "\n".join(lines)


def compare_coarsenings(V, F, operator: str = "cotangent", m: int = 500, k: int | None = None,
                        params: CoarsenParams | None = None, *,
                        methods=("ours", "qslim", "amg"), alpha: float = 10.0,
                        callback=None) -> Comparison:
    """Build (L, M) for ``operator`` on (V, F), coarsen to ``m`` rows with each method and
    measure the functional-map diagonality and eigenvalue errors over ``k`` eigenvectors
    (``k=None``: round(m/3)). ``callback(step)`` sees every optimizer step of ours."""
    gen = compare_coarsenings_iter(V, F, operator, m, k, params, methods=methods, alpha=alpha)
    while True:
        try:
            step = next(gen)
        except StopIteration as stop:
            return stop.value
        if callback is not None:
            callback(step)


def compare_coarsenings_iter(V, F, operator: str = "cotangent", m: int = 500,
                             k: int | None = None, params: CoarsenParams | None = None, *,
                             methods=("ours", "qslim", "amg"), alpha: float = 10.0):
    """Generator form of :func:`compare_coarsenings` for the GUI: yields every optimizer
    :class:`~algorithms.spectral.coarsen.CoarsenStep` of ours and *returns* the
    :class:`Comparison` (``result = yield from compare_coarsenings_iter(...)``)."""
    params = params or CoarsenParams()
    k = int(k if k else round(m / 3))
    timings: dict[str, float] = {}
    t = time.perf_counter()
    L, M, p, q = build_operator(V, F, operator, alpha=alpha)
    timings["operator"] = time.perf_counter() - t
    n = L.shape[0]
    t = time.perf_counter()
    nnull = sp.csgraph.connected_components(L, directed=False)[0]
    eigs = generalized_eigs(L, M, k + nnull)
    timings["eigendecomposition"] = time.perf_counter() - t
    out: dict[str, MethodResult] = {}
    if "ours" in methods:
        t = time.perf_counter()
        last = None
        for last in _iter(L, M, m, k, replace(params, p=p, q=q), eigs):
            yield last
        secs = time.perf_counter() - t
        timings.update({f"ours_{a}": b for a, b in last.timings.items()})
        met = spectral_metrics(L, M, last.L, last.M, last.P, k, fine_eigs=eigs)
        out["ours"] = MethodResult("ours", last.L, last.M, last.P, met.as_dict(), secs,
                                   {"G": last.G, "K": last.K, "energy": last.energy}, met)
    if "qslim" in methods:
        r = qslim_baseline(V, F, m, operator, **({"alpha": alpha} if operator == "anisotropic" else {}))
        met = spectral_metrics(L, M, r.L, r.M, r.P, k, fine_eigs=eigs)
        out["qslim"] = MethodResult("qslim", r.L, r.M, r.P, met.as_dict(), r.seconds,
                                    {"V": r.V, "F": r.F}, met)
    if "amg" in methods:
        r = amg_baseline(L, M, m, seed=params.seed)
        met = spectral_metrics(L, M, r.L, r.M, r.P, k, fine_eigs=eigs)
        out["amg"] = MethodResult("amg", r.L, r.M, r.P, met.as_dict(), r.seconds, {}, met)
    for name, r in out.items():
        timings[name] = r.seconds
    return Comparison(n, m, k, operator, out, timings, fine_eigs=eigs)


def _iter(L, M, m, k, params, eigs):
    from .coarsen import coarsen_iter
    lam, phi = eigs
    # the optimizer uses the first k eigenvectors (constants included)
    yield from coarsen_iter(L, M, m, k, params, eigs=(lam[:k], phi[:, :k]))
