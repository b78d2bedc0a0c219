"""Recipe "Spectral coarsening" (thesis ch. 7): coarsen the mesh's operator with ours, QSlim and
AMG and score them. An analysis: the document never changes; the run's figures and arrays are
its outcome (:func:`comparison_outcome`), which the panel's views read.

Options (all optional; the defaults are the command line's):

* ``operator`` (str): the operator to coarsen, one of :data:`OPERATOR_NAMES`
  ("cotangent", "intrinsic_delaunay", "anisotropic", "graph", "point_cloud");
* ``alpha`` (float, default 10): the anisotropy of the "anisotropic" operator (the panel's
  "anisotropic (α 70)" passes 70; the other operators ignore it);
* ``compare`` (list of str, default ["qslim", "amg"]): the baselines run besides ours;
* ``isolated`` (bool, default False): run the computation in a child process
  (:func:`algorithms.steps.isolated_iter`). ARPACK, SciPy's sparse products and PyAMG hold
  Python's GIL for seconds, which freezes a window even from its worker thread: the panel asks
  for it. The child runs with one BLAS thread, so its last bits may differ from an in-process
  run's; a replay of the logged options runs where the original did.

Determinism: the random initial cluster roots (graph k-medoids) and PyAMG's Lloyd seeds come
from ``params.seed``; ARPACK's start vector is a fixed one (see
:func:`algorithms.spectral.coarsen.generalized_eigs`); the outcome holds no timings. Two runs
with the same (state, params, options) give the same bits on the same machine.

The view helpers below (:func:`heatmap_rgb`, :func:`cluster_field`, :func:`fine_eigenfunction`,
:func:`coarse_eigenpairs`, :func:`prolonged_eigenvector`) are plain NumPy functions of an
outcome; the panel calls them on the GUI thread.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from algorithms.steps import Step, isolated_iter
from app.recipes import Recipe, register, unchanged_result

#: the operators the recipe coarsens (algorithms.spectral.operators.build_operator's names)
OPERATOR_NAMES = ("cotangent", "intrinsic_delaunay", "anisotropic", "graph", "point_cloud")
#: ours first, then the baselines, in the order the panel shows them
METHODS = ("ours", "qslim", "amg")
BASELINES = ("qslim", "amg")
#: the metrics of every method in the outcome (``"<method>.<metric>"``)
METRICS = ("c_diag_score", "eig_rel_error_mean", "eig_rel_error_max")
DEFAULT_OPTIONS = {"operator": "cotangent", "alpha": 10.0, "compare": list(BASELINES),
                   "isolated": False}


@dataclass
class ComparisonStep(Step):
    """The recipe's last Step: ``outcome`` is the run's :func:`comparison_outcome`;
    ``seconds`` each method's time (kept out of the outcome, which a replay compares)."""

    outcome: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)


def spectral_options(options: dict | None) -> dict:
    """``options`` checked and completed with the defaults (module docstring); bad values raise
    ParameterError with a plain message."""
    from algorithms.errors import ParameterError

    o = {**DEFAULT_OPTIONS, **(options or {})}
    unknown = sorted(set(o) - set(DEFAULT_OPTIONS))
    if unknown:
        raise ParameterError(f"Spectral coarsening has no option {unknown[0]!r}; its options "
                             f"are {', '.join(DEFAULT_OPTIONS)}.")
    if o["operator"] not in OPERATOR_NAMES:
        raise ParameterError(f"Unknown operator {o['operator']!r}: choose one of "
                             f"{', '.join(OPERATOR_NAMES)}.")
    try:
        alpha = float(o["alpha"])
    except (TypeError, ValueError):
        alpha = float("nan")
    if not np.isfinite(alpha) or alpha <= 0:
        raise ParameterError(f"The anisotropy alpha must be a positive number (got "
                             f"{o['alpha']!r}).")
    compare = o["compare"]
    if isinstance(compare, str) or not all(isinstance(c, str) for c in compare):
        raise ParameterError("The option 'compare' is a list of baselines, e.g. "
                             "['qslim', 'amg'].")
    bad = [c for c in compare if c not in BASELINES]
    if bad:
        raise ParameterError(f"Unknown baseline {bad[0]!r}: compare with qslim and/or amg.")
    return {"operator": o["operator"], "alpha": alpha,
            "compare": [c for c in BASELINES if c in compare], "isolated": bool(o["isolated"])}


#: the stages of a run, in order, with the words the progress uses for them
STAGES = ("eigenvectors", "clustering", "optimizing", "balancing", "comparing")
STAGE_LABELS = {"eigenvectors": "Eigenvectors", "clustering": "Clustering the vertices",
                "optimizing": "Optimizing", "balancing": "Balancing", "comparing": "Comparing"}
#: NADAM iterations a run usually takes before its patience stops it (measured: 134 on a
#: 30k-vertex koala -> 500, 142 on armadillo, 180 on the blob sample)
TYPICAL_NADAM_ITERATIONS = 160

#: The cost model of :func:`estimate_seconds`, in seconds, calibrated on this project's
#: machine (2 cores) from CPU times of single-threaded runs (the machine was shared while it
#: was measured; ``benchmarks/spectral.py --estimate`` prints measured against modelled
#: figures): a 30k-vertex koala, m 500, k 100: ARPACK 3.9 s, one energy evaluation 30 ms,
#: clustering 0.9 s, QSlim 1.5 s, scoring 0.23 s per method; the blob sample: QSlim 0.23 s,
#: the child process's start 1.4 s. The terms:
#: eigenvectors ``eig * n * ke^2`` (ARPACK's shift-invert Lanczos, ke = k + parts),
#: clustering ``cluster * n``, one energy evaluation ``eval_n * n + eval_mmk * m^2 k``,
#: QSlim ``qslim * n``, AMG ``amg * n``, scoring ``score * m^2 k`` per method, and the child
#: process's start ``start`` plus loading Numba's kernels there ``kernels``. On a busy machine
#: the text multiplies the total by :func:`machine_slowdown`.
COST = {"eig": 1.3e-8, "cluster": 3.0e-5, "eval_n": 8.0e-7, "eval_mmk": 2.0e-10,
        "qslim": 6.0e-5, "amg": 4.0e-5, "score": 8.0e-9, "start": 1.4, "kernels": 1.5}


def machine_slowdown() -> float:
    """How much slower than on an idle machine a run goes now: ``0.7 load / cores`` when the
    1-minute load average exceeds the cores, else 1 (measured here: the panel's default on the
    blob took 5.3x the model at load 15 on 2 cores, armadillo 4.8x at load 13)."""
    import os

    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        return 1.0
    return max(1.0, 0.7 * load / max(1, os.cpu_count() or 1))


def estimate_seconds(n: int, params, options: dict | None = None, parts: int = 1
                     ) -> dict[str, float]:
    """Seconds each stage of a run on an ``n``-vertex mesh should take with ``params`` (a
    CoarsenParams) and ``options`` (see :data:`COST`; a model, good to a factor of about 1.5
    on a quiet machine). Keys: the :data:`STAGES` and "start"."""
    o = spectral_options(options)
    m = int(params.m)
    k = int(params.k or max(1, round(m / 3)))
    ke = k + max(1, int(parts))
    c = COST
    evals = min(int(params.max_iterations), TYPICAL_NADAM_ITERATIONS)
    per_eval = c["eval_n"] * n + c["eval_mmk"] * m * m * k
    compare = c["score"] * m * m * k
    for name in o["compare"]:
        compare += c[name] * n + c["score"] * m * m * k
    # a fresh child process: its start, then loading Numba and the compiled kernels
    return {"start": c["start"] + c["kernels"] if o["isolated"] else 0.0,
            "eigenvectors": c["eig"] * n * ke * ke,
            "clustering": c["cluster"] * n * min(1.0, params.clustering_iterations / 20),
            "optimizing": per_eval * (evals + 1),
            "balancing": per_eval * 1.07 * int(params.balance_iterations),
            "comparing": compare}


def format_seconds(seconds: float) -> str:
    """A duration in words for an estimate: "under a second", "8 s", "2 min"."""
    if seconds < 1.0:
        return "under a second"
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min"


def estimate_text(n: int, params, options: dict | None = None, parts: int = 1) -> str:
    """What a run will take, said before it starts (the panel shows it next to Run)."""
    est = estimate_seconds(n, params, options, parts)
    slow = machine_slowdown()
    total = sum(est.values()) * slow
    big = max(STAGES, key=lambda s: est[s])
    what = {"eigenvectors": "the eigenvectors", "clustering": "the clustering",
            "optimizing": "the optimization", "balancing": "the balancing",
            "comparing": "the comparison"}[big]
    busy = " while the computer is this busy" if slow > 1.5 else ""
    return (f"Estimated time: about {format_seconds(total)} on this {n:,}-vertex mesh{busy} "
            f"(mostly {what}).")


class _Progress:
    """One progress for the whole run: each stage's share of the estimated time
    (:func:`estimate_seconds`), the elapsed time, and what is left (the estimate of the stages
    to come, scaled by how fast the stages so far went against their estimates)."""

    def __init__(self, est: dict[str, float]):
        import time

        self.est = est
        self.total = max(sum(est.values()), 1e-9)
        self.t0 = time.perf_counter()
        self.clock = time.perf_counter
        self.pct = 0

    def step(self, stage: str, fraction: float, detail: str = "") -> tuple[int, str]:
        done = self.est.get("start", 0.0)
        for s in STAGES:
            if s == stage:
                done += max(0.0, min(1.0, fraction)) * self.est[s]
                break
            done += self.est[s]
        self.pct = max(self.pct, min(99, int(100 * done / self.total)))
        elapsed = self.clock() - self.t0
        left = self.total - done
        if done > 0.05 * self.total:      # scale by the speed seen so far
            left *= elapsed / done
        label = STAGE_LABELS[stage] + (f": {detail}" if detail else "")
        tail = f" · {format_seconds(left)} left" if left >= 1.0 else ""
        text = (label + tail) if len(label + tail) <= 60 else label[:60]
        return self.pct, text


def spectral_steps(state, params, options: dict | None = None, cache: dict | None = None
                   ) -> Iterator[Step]:
    """The panel's Run: one progress for the whole run (``total`` 100, ``iteration`` the share
    of the estimated work done, ``message`` the stage, its step of total where known and an
    estimate of the time left, at most 60 characters), through the stages of
    :data:`STAGES`; the optimizer's steps carry the metric ``energy``; then a
    :class:`ComparisonStep` carrying the outcome. ``cache`` is not used (every run starts from
    the mesh)."""
    import re

    from algorithms.spectral.compare import compare_coarsenings_iter

    o = spectral_options(options)
    args = (state.V, state.F, o["operator"], params.m, params.k or None, params)
    kwargs = {"methods": ("ours", *o["compare"]), "alpha": o["alpha"], "eig_progress": True}
    prog = _Progress(estimate_seconds(len(state.V), params, o))
    if o["isolated"]:
        # in a child process: ARPACK, SciPy's sparse products and PyAMG hold the GIL for
        # seconds, which would freeze the window even from the worker thread
        gen = isolated_iter(compare_coarsenings_iter, *args, **kwargs)
    else:
        gen = compare_coarsenings_iter(*args, **kwargs)
    nadam_cap = max(1, int(params.max_iterations))
    typical = min(nadam_cap, TYPICAL_NADAM_ITERATIONS)
    balance_cap = max(1, int(params.balance_iterations))
    try:
        while True:
            try:
                cs = next(gen)
            except StopIteration as stop:
                out = comparison_outcome(stop.value)
                secs = {name: float(r.seconds) for name, r in stop.value.methods.items()}
                yield ComparisonStep(100, 100, state.V, {}, "done", outcome=out,
                                     seconds=secs)
                return
            stage = getattr(cs, "stage", "optimizing")
            if cs.done:      # ours' result (its best iterate): the comparison follows
                continue
            if stage == "eigenvectors":
                hit = re.search(r"Lanczos step (\d+) of about (\d+)", cs.message)
                detail = f"Lanczos step {hit[1]} of about {hit[2]}" if hit else ""
                pct, text = prog.step(stage, cs.iteration / 1000.0, detail)
            elif stage in ("clustering", "comparing"):
                detail = ""
                if stage == "comparing":     # "with QSlim", "with AMG", "scoring ours"
                    detail = cs.message.replace("Comparing ", "")
                    detail = detail[:1].lower() + detail[1:]
                pct, text = prog.step(stage, 0.0, detail)
            elif stage == "balancing":
                it = int(cs.metrics.get("balancing_iteration", 0))
                pct, text = prog.step(stage, it / balance_cap,
                                      f"iteration {it} of at most {balance_cap}")
            else:
                it = cs.iteration
                pct, text = prog.step(stage, min(0.95, it / typical),
                                      f"iteration {it} of at most {nadam_cap}")
            metrics = {"energy": cs.energy} if np.isfinite(cs.energy) else {}
            yield Step(pct, 100, state.V, metrics, text)
    finally:
        gen.close()   # a cancelled run stops the computation (and its child process) now


# ------------------------------------------------------------------------------ the outcome
def _csr_arrays(prefix: str, A) -> dict:
    """A sparse matrix as ``prefix.data / .indices / .indptr / .shape`` arrays (CSR, sorted
    column indices, stored zeros kept: the pattern of G is part of the result)."""
    import scipy.sparse as sp

    C = sp.csr_matrix(A, copy=True)
    C.sort_indices()
    return {f"{prefix}.data": np.ascontiguousarray(C.data, dtype=np.float64),
            f"{prefix}.indices": np.ascontiguousarray(C.indices, dtype=np.int64),
            f"{prefix}.indptr": np.ascontiguousarray(C.indptr, dtype=np.int64),
            f"{prefix}.shape": np.array(C.shape, dtype=np.int64)}


def outcome_matrix(outcome: dict, prefix: str):
    """The sparse matrix stored under ``prefix`` ("ours.L", "amg.M", "ours.G", ...)."""
    import scipy.sparse as sp

    shape = tuple(int(s) for s in outcome[f"{prefix}.shape"])
    return sp.csr_matrix((outcome[f"{prefix}.data"], outcome[f"{prefix}.indices"],
                          outcome[f"{prefix}.indptr"]), shape=shape)


def comparison_outcome(cmp_) -> dict:
    """The outcome of a run: a flat dict of numbers, strings and NumPy arrays, no timings.

    * ``n``, ``m``, ``k`` (int): fine size, asked coarse size, eigenvectors compared;
      ``methods`` (list of str): the methods that ran ("ours" first; a baseline that could not
      handle the mesh is left out); ``notes`` (list of str): why, in plain words;
    * ``fine.eigenvalues`` (k',), ``fine.eigenvectors`` (n, k'): the fine operator's first
      k' = k + (number of parts) eigenpairs, ascending, M-orthonormal;
    * per method: ``<method>.c_diag_score``, ``.eig_rel_error_mean``, ``.eig_rel_error_max``
      (float), ``<method>.C`` (k, k) functional map, ``<method>.eigenvalues`` the coarse
      operator's eigenvalues, ``<method>.L``, ``.M`` (coarse operator and mass) and ``.P``
      (m, n root selection) as CSR arrays (see :func:`outcome_matrix`);
    * ours also: ``ours.G`` (n, m) prolongation (CSR), ``ours.clusters`` (n,) int64 cluster of
      every fine vertex, ``ours.roots`` (m,) int64 fine vertex of every coarse node,
      ``ours.energy`` (float), ``ours.iterations`` / ``ours.balancing_iterations`` (int);
    * qslim also: ``qslim.V`` (m', 3), ``qslim.F`` (f', 3) int64, the decimated mesh.
    """
    out: dict = {"n": int(cmp_.n), "m": int(cmp_.m), "k": int(cmp_.k),
                 "methods": [name for name in METHODS if name in cmp_.methods],
                 "notes": [str(t) for t in getattr(cmp_, "notes", [])]}
    lam_f, phi_f = cmp_.fine_eigs
    out["fine.eigenvalues"] = np.array(lam_f, dtype=np.float64)
    out["fine.eigenvectors"] = np.array(phi_f, dtype=np.float64, order="C")
    for name in out["methods"]:
        r = cmp_.methods[name]
        for metric in METRICS:
            out[f"{name}.{metric}"] = float(r.metrics[metric])
        out[f"{name}.C"] = np.array(r.spectral.C, dtype=np.float64, order="C")
        out[f"{name}.eigenvalues"] = np.array(r.spectral.lam_coarse, dtype=np.float64)
        for mat in ("L", "M", "P"):
            out.update(_csr_arrays(f"{name}.{mat}", getattr(r, mat)))
    if "ours" in cmp_.methods:
        r = cmp_.methods["ours"]
        out.update(_csr_arrays("ours.G", r.extra["G"]))
        K = r.extra["K"].tocsc()
        out["ours.clusters"] = np.asarray(K.argmax(axis=0)).ravel().astype(np.int64)
        out["ours.roots"] = np.asarray(r.P.tocsr().argmax(axis=1)).ravel().astype(np.int64)
        out["ours.energy"] = float(r.extra["energy"])
        out["ours.iterations"] = int(cmp_.timings.get("ours_iterations", 0))
        out["ours.balancing_iterations"] = int(cmp_.timings.get("ours_balancing_iterations", 0))
    if "qslim" in cmp_.methods:
        ex = cmp_.methods["qslim"].extra
        out["qslim.V"] = np.array(ex["V"], dtype=np.float64, order="C")
        out["qslim.F"] = np.array(ex["F"], dtype=np.int64, order="C")
    return out


def _spectral_outcome(last: Step) -> dict:
    return dict(getattr(last, "outcome", None) or {})


def _spectral_params():
    from algorithms.spectral.coarsen import CoarsenParams

    return CoarsenParams


# ------------------------------------------------------------------------------ the views
def suggested_coarse_size(n: int, m: int = 500) -> int:
    """The coarse size the panel proposes for an ``n``-vertex mesh (at most n / 8, see
    :func:`algorithms.spectral.coarsen.suggested_coarse_size`)."""
    from algorithms.spectral.coarsen import suggested_coarse_size as suggest

    return suggest(n, m)


def heatmap_rgb(C: np.ndarray, size: int = 140) -> np.ndarray:
    """|C| as a white-to-dark-blue picture: (size, size, 3) uint8, C's rows and columns
    sampled to ``size`` pixels (thesis Fig. 7.1)."""
    A = np.abs(np.asarray(C, dtype=np.float64))
    A = A / max(A.max(), 1e-12)
    k = A.shape[0]
    idx = (np.arange(size) * k // size).clip(0, k - 1)
    A = A[np.ix_(idx, idx)]
    rgb = np.empty(A.shape + (3,), dtype=np.uint8)
    rgb[..., 0] = (255 * (1 - 0.85 * A)).astype(np.uint8)
    rgb[..., 1] = (255 * (1 - 0.7 * A)).astype(np.uint8)
    rgb[..., 2] = (255 * (1 - 0.35 * A)).astype(np.uint8)
    return np.ascontiguousarray(rgb)


def cluster_field(outcome: dict) -> np.ndarray:
    """(n,) float: a colour index per fine vertex, its cluster shuffled by a fixed permutation
    of 0..m-1 so that neighbouring clusters get different colours of a categorical map."""
    m = int(outcome["m"])
    perm = np.random.default_rng(0).permutation(m).astype(float)
    return perm[outcome["ours.clusters"]]


def fine_eigenfunction(outcome: dict, i: int) -> np.ndarray:
    """(n,) the fine eigenfunction Φ_i (i = 1: the first non-constant one; clamped to those
    computed)."""
    phi = outcome["fine.eigenvectors"]
    return phi[:, min(int(i), phi.shape[1] - 1)]


def coarse_eigenpairs(outcome: dict):
    """(eigenvalues, eigenvectors) of ours' coarse operator, the first min(k + 1, m - 1);
    raises a project error with a plain message when they cannot be computed."""
    from algorithms.spectral.coarsen import generalized_eigs

    L, M = outcome_matrix(outcome, "ours.L"), outcome_matrix(outcome, "ours.M")
    return generalized_eigs(L, M, min(int(outcome["k"]) + 1, int(outcome["m"]) - 1))


def prolonged_eigenvector(outcome: dict, i: int, coarse_eigs=None) -> np.ndarray:
    """(n,) G φ~_i: ours' coarse eigenvector i prolonged to the fine mesh, signed like the fine
    Φ_i (eigenvectors have arbitrary signs). ``coarse_eigs``: :func:`coarse_eigenpairs`'s
    result, computed when not given."""
    phi_f = outcome["fine.eigenvectors"]
    j = min(int(i), phi_f.shape[1] - 1)
    phi_c = (coarse_eigs if coarse_eigs is not None else coarse_eigenpairs(outcome))[1]
    f = outcome_matrix(outcome, "ours.G") @ phi_c[:, min(j, phi_c.shape[1] - 1)]
    if f @ phi_f[:, j] < 0:
        f = -f
    return f


register(Recipe("Spectral coarsening", "coarsen", _spectral_params, spectral_steps,
                result=unchanged_result, outcome=_spectral_outcome,
                note="an analysis: the mesh does not change; the outcome holds the coarse "
                     "operators, eigenvalues, scores, clusters and roots"))
