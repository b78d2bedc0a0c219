"""One call for a CLI/GUI: coarsen a mesh operator with ours, QSlim and AMG and score them."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from ..errors import ParameterError, Stylize3DError
from .baselines import amg_baseline, qslim_baseline
from ..steps import with_progress
from .coarsen import CoarsenParams, CoarsenStep, coarsen, generalized_eigs
from .metrics import spectral_metrics
from .operators import build_operator

__all__ = ["MethodResult", "Comparison", "compare_coarsenings", "compare_coarsenings_iter"]

_SHORT = {"qslim": "QSlim", "amg": "AMG"}
_TITLES = {"qslim": "QSlim (simplify and rediscretize)", "amg": "AMG (smoothed aggregation)"}


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
    notes: list[str] = field(default_factory=list)  # plain-language remarks (skipped baselines)

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
                             methods=("ours", "qslim", "amg"), alpha: float = 10.0,
                             eig_progress: bool = False):
    """Generator form of :func:`compare_coarsenings` for the GUI: yields every optimizer
    :class:`~algorithms.spectral.coarsen.CoarsenStep` of ours and *returns* the
    :class:`Comparison` (``result = yield from compare_coarsenings_iter(...)``).

    With ``eig_progress=True`` the eigendecomposition of the fine operator (the long first
    stage) also streams: it runs on a helper thread and yields ``CoarsenStep``s with
    ``total=1000``, ``iteration`` = per-mille of its work done, ``energy`` NaN and the Lanczos
    step in ``message``; closing the generator then stops ARPACK at its next step."""
    params = params or CoarsenParams()
    k = int(k if k else round(m / 3))
    timings: dict[str, float] = {}
    t = time.perf_counter()
    L, M, p, q = build_operator(V, F, operator, alpha=alpha)
    timings["operator"] = time.perf_counter() - t
    n = L.shape[0]
    t = time.perf_counter()
    nnull = sp.csgraph.connected_components(L, directed=False)[0]
    if nnull >= m:   # checked before the (then large) eigendecomposition
        # m = nnull gives one node per part: a coarse operator with no non-zero eigenvalue,
        # nothing to compare (it crashed the scoring, issue 38)
        raise ParameterError(f"the mesh has {nnull} separate parts but only m = {m} coarse "
                             "nodes were asked for; ask for more than one per part, or remove "
                             "small loose parts first.")
    if not 1 <= k < m < n:
        raise ParameterError(f"need 1 <= k < m < n (here n = {n}, m = {m}, k = {k}); the "
                             "thesis recommends m > 2k.")
    ke = min(k + nnull, n - 1)
    if eig_progress:
        box: dict = {}
        yield CoarsenStep(0, 1000, float("nan"), message="Eigenvectors of the fine operator",
                          stage="eigenvectors")
        for st in with_progress(lambda progress: generalized_eigs(L, M, ke, progress=progress),
                                V, box):
            yield CoarsenStep(st.iteration, st.total, float("nan"),
                              message=f"Eigenvectors of the fine operator: {st.message}",
                              stage="eigenvectors")
        eigs = box["value"]
    else:
        eigs = generalized_eigs(L, M, ke)
    timings["eigendecomposition"] = time.perf_counter() - t
    out: dict[str, MethodResult] = {}
    if "ours" in methods:
        t = time.perf_counter()
        last = None
        if eig_progress:   # the (short) combinatorial stage, named
            yield CoarsenStep(0, None, float("nan"), message="Clustering the vertices",
                              stage="clustering")
        for last in _iter(L, M, m, k, replace(params, p=p, q=q), eigs):
            yield last
        secs = time.perf_counter() - t
        timings.update({f"ours_{a}": b for a, b in last.timings.items()})
        if eig_progress:
            yield CoarsenStep(0, None, float("nan"), message="Scoring ours",
                              stage="comparing")
        met = spectral_metrics(L, M, last.L, last.M, last.P, k, fine_eigs=eigs)
        out["ours"] = MethodResult("ours", last.L, last.M, last.P, met.as_dict(), secs,
                                   {"G": last.G, "K": last.K, "energy": last.energy}, met)
    notes: list[str] = []
    for name in ("qslim", "amg"):
        if name not in methods:
            continue
        if eig_progress:
            yield CoarsenStep(0, None, float("nan"), message=f"Comparing with {_SHORT[name]}",
                              stage="comparing")
        try:
            if name == "qslim":
                r = qslim_baseline(V, F, m, operator,
                                   **({"alpha": alpha} if operator == "anisotropic" else {}))
                extra = {"V": r.V, "F": r.F}
            else:
                r = amg_baseline(L, M, m, seed=params.seed)
                extra = {}
            met = spectral_metrics(L, M, r.L, r.M, r.P, k, fine_eigs=eigs)
        except Stylize3DError as exc:
            # a baseline that cannot handle this input (QSlim needs a manifold, consistently
            # oriented mesh) is left out and the user is told why; ours is still reported
            notes.append(f"{_TITLES[name]} was left out of the comparison: {exc}")
            continue
        except MemoryError:
            notes.append(f"{_TITLES[name]} was left out of the comparison: it ran out of "
                         "memory on this mesh.")
            continue
        out[name] = MethodResult(name, r.L, r.M, r.P, met.as_dict(), r.seconds, extra, met)
    for name, r in out.items():
        timings[name] = r.seconds
    return Comparison(n, m, k, operator, out, timings, fine_eigs=eigs, notes=notes)


def _iter(L, M, m, k, params, eigs):
    from .coarsen import coarsen_iter
    lam, phi = eigs
    # the optimizer uses the first k eigenvectors (constants included)
    yield from coarsen_iter(L, M, m, k, params, eigs=(lam[:k], phi[:, :k]))
