"""The recipe "Spectral coarsening" run headless (app.recipes.run), Qt-free."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.errors import ParameterError

SMALL = {"m": 60, "k": 15, "max_iterations": 30, "balance_iterations": 10}


@pytest.fixture(scope="module")
def state():
    from algorithms.mesh.primitives import icosphere
    from app.document import MeshState

    V, F = icosphere(3)                       # 642 vertices: ARPACK's path (n > 200)
    V = V * np.array([1.3, 1.0, 0.8]) * (1 + 0.2 * V[:, :1])   # distinct eigenvalues
    return MeshState.make(V, F)


@pytest.fixture(scope="module")
def first(state):
    from app.recipes import run

    return run("Spectral coarsening", state, SMALL, {})


def _same_bits(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        if isinstance(a[key], np.ndarray):
            assert a[key].dtype == b[key].dtype and a[key].shape == b[key].shape, key
            assert a[key].tobytes() == b[key].tobytes(), key
        else:
            assert a[key] == b[key] and type(a[key]) is type(b[key]), key


def test_registered_by_title_and_command_as_an_analysis(state, first):
    from app.recipes import get_recipe

    r = get_recipe("coarsen")
    assert r is get_recipe("Spectral coarsening") and r.command == "coarsen"
    assert r.params_cls().__name__ == "CoarsenParams"
    assert first.state is state                      # the document does not change
    assert first.last.iteration >= 2 and first.last.message == "done"


def test_outcome_holds_the_comparison_and_no_timings(state, first):
    out = first.outcome
    n = len(state.V)
    assert (out["n"], out["m"], out["k"]) == (n, 60, 15)
    assert out["methods"] == ["ours", "qslim", "amg"] and out["notes"] == []
    assert not any("second" in k or "time" in k for k in out)
    assert out["fine.eigenvectors"].shape[0] == n and out["fine.eigenvalues"].shape == (16,)
    for name in out["methods"]:
        assert 0.0 < out[f"{name}.c_diag_score"] <= 1.0
        assert np.isfinite(out[f"{name}.eig_rel_error_mean"])
        assert out[f"{name}.C"].shape == (15, 15)
    assert out["ours.clusters"].shape == (n,) and out["ours.clusters"].dtype == np.int64
    assert np.array_equal(np.unique(out["ours.clusters"]), np.arange(60))
    assert out["ours.roots"].shape == (60,)
    # every root lies in its own cluster
    assert np.array_equal(out["ours.clusters"][out["ours.roots"]], np.arange(60))
    assert out["ours.iterations"] >= 1 and out["qslim.F"].dtype == np.int64
    # JSON-able but for the arrays; the study log's hash of it
    from app.recipes import outcome_hash

    json.dumps({k: v for k, v in out.items() if not isinstance(v, np.ndarray)})
    assert len(outcome_hash(out)) == 64


def test_outcome_matrices_are_the_comparisons(state, first):
    """The CSR arrays of the outcome give back the coarse operators of compare_coarsenings."""
    from algorithms.spectral.coarsen import CoarsenParams
    from algorithms.spectral.compare import compare_coarsenings_iter
    from app.recipes.spectral import comparison_outcome, outcome_matrix

    params = CoarsenParams(**SMALL)
    gen = compare_coarsenings_iter(state.V, state.F, "cotangent", params.m, params.k, params,
                                   eig_progress=True)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            cmp_ = stop.value
            break
    out = comparison_outcome(cmp_)
    _same_bits(out, first.outcome)
    for name in ("ours", "qslim", "amg"):
        for mat in ("L", "M", "P"):
            a, b = outcome_matrix(out, f"{name}.{mat}"), getattr(cmp_.methods[name], mat)
            assert a.shape == b.shape and abs(a - b).max() == 0
    G = outcome_matrix(out, "ours.G")
    assert G.nnz == cmp_.methods["ours"].extra["G"].nnz           # stored zeros kept
    assert abs(G - cmp_.methods["ours"].extra["G"]).max() == 0


def test_two_runs_with_the_same_seed_give_the_same_bits(state, first):
    from app.recipes import outcome_hash, run

    again = run("Spectral coarsening", state, SMALL, {})
    _same_bits(first.outcome, again.outcome)
    assert outcome_hash(first.outcome) == outcome_hash(again.outcome)
    # the seed is what decides: another seed draws other initial cluster roots
    other = run("Spectral coarsening", state, {**SMALL, "seed": 7}, {})
    assert not np.array_equal(other.outcome["ours.clusters"], first.outcome["ours.clusters"])
    assert outcome_hash(other.outcome) != outcome_hash(first.outcome)


def test_isolated_run_in_a_child_process_gives_the_same_outcome(state, first, monkeypatch):
    import app.recipes.spectral as mod
    from app.recipes import run

    calls = []
    real = mod.isolated_iter

    def spy(fn, *a, **k):
        calls.append(fn)
        return real(fn, *a, **k)
    monkeypatch.setattr(mod, "isolated_iter", spy)
    child = run("Spectral coarsening", state, SMALL, {"isolated": True})
    assert len(calls) == 1 and calls[0].__module__ == "algorithms.spectral.compare"
    # one BLAS thread in the child; on this machine its bits are the in-process run's
    _same_bits(child.outcome, first.outcome)


def test_options_operator_and_baselines(state):
    from app.recipes import run
    from app.recipes.spectral import spectral_options

    assert spectral_options(None) == {"operator": "cotangent", "alpha": 10.0,
                                      "compare": ["qslim", "amg"], "isolated": False}
    out = run("coarsen", state, SMALL, {"operator": "graph", "compare": ["amg"]}).outcome
    assert out["methods"] == ["ours", "amg"] and "qslim.C" not in out
    for bad, text in (({"operator": "cotan"}, "Unknown operator"),
                      ({"compare": ["ours"]}, "Unknown baseline"),
                      ({"compare": "amg"}, "list of baselines"),
                      ({"alpha": -1}, "positive"),
                      ({"operators": "graph"}, "no option")):
        with pytest.raises(ParameterError, match=text):
            spectral_options(bad)
    with pytest.raises(ParameterError, match="Unknown operator"):
        run("coarsen", state, SMALL, {"operator": "nope"})


def test_anisotropy_reaches_the_operator(state):
    from app.recipes import run

    a = run("coarsen", state, SMALL, {"operator": "anisotropic", "alpha": 70.0,
                                      "compare": []}).outcome
    b = run("coarsen", state, SMALL, {"operator": "anisotropic", "alpha": 10.0,
                                      "compare": []}).outcome
    assert not np.array_equal(a["fine.eigenvalues"], b["fine.eigenvalues"])


def test_view_functions(state, first):
    from app.recipes.spectral import (cluster_field, coarse_eigenpairs, fine_eigenfunction,
                                      heatmap_rgb, prolonged_eigenvector)

    out = first.outcome
    img = heatmap_rgb(np.eye(15), 30)
    assert img.shape == (30, 30, 3) and img.dtype == np.uint8
    assert tuple(img[0, 0]) == (38, 76, 165) and tuple(img[0, -1]) == (255, 255, 255)
    f = cluster_field(out)
    assert f.shape == (len(state.V),) and set(np.unique(f)) == set(range(60))
    # the same cluster, the same colour; the permutation is fixed
    same = out["ours.clusters"] == out["ours.clusters"][0]
    assert np.all(f[same] == f[0]) and np.array_equal(f, cluster_field(out))
    phi = fine_eigenfunction(out, 1)
    assert np.array_equal(phi, out["fine.eigenvectors"][:, 1])
    assert np.array_equal(fine_eigenfunction(out, 99), out["fine.eigenvectors"][:, -1])
    eigs = coarse_eigenpairs(out)
    assert eigs[1].shape == (60, 16)
    g = prolonged_eigenvector(out, 1, eigs)
    assert np.array_equal(g, prolonged_eigenvector(out, 1))
    corr = g @ phi / np.linalg.norm(g) / np.linalg.norm(phi)
    assert corr > 0.5       # the prolonged coarse eigenvector resembles the fine one


def test_a_cancelled_run_stops_its_child_process(state):
    import multiprocessing as mp

    from app.recipes import get_recipe

    r = get_recipe("coarsen")
    gen = r.steps(state, r.make_params(SMALL), {"isolated": True}, {})
    next(gen)                                     # the child runs
    assert any(p.name == "stylize3d-isolated" for p in mp.active_children())
    gen.close()
    assert not any(p.name == "stylize3d-isolated" and p.is_alive()
                   for p in mp.active_children())


# ---------------------------------------------------------------------------- issue 24 item 1
def test_one_progress_names_stages_counts_and_what_is_left(state):
    """Every streamed step is one progress (total 100, never backwards) whose message names
    the stage, its step of total where known and the time left, in at most 60 characters (the
    status bar shows 60); the stages come in order."""
    from app.recipes import get_recipe
    from app.recipes.spectral import STAGE_LABELS

    r = get_recipe("coarsen")
    steps = list(r.steps(state, r.make_params(SMALL), {}, {}))
    body = steps[:-1]
    assert all(s.total == 100 for s in steps)
    pct = [s.iteration for s in body]
    assert pct == sorted(pct) and pct[-1] <= 99 and steps[-1].iteration == 100
    assert all(0 < len(s.message) <= 60 for s in steps)
    order = []
    for s in body:
        label = next(v for k, v in STAGE_LABELS.items() if s.message.startswith(v))
        if not order or order[-1] != label:
            order.append(label)
    assert order == ["Eigenvectors", "Clustering the vertices", "Optimizing", "Balancing",
                     "Comparing"]
    opt = [s for s in body if s.message.startswith("Optimizing")]
    assert all(f"of at most {SMALL['max_iterations']}" in s.message for s in opt)
    assert all("energy" in s.metrics for s in opt)
    bal = [s for s in body if s.message.startswith("Balancing")]
    assert bal and all(f"of at most {SMALL['balance_iterations']}" in s.message for s in bal)
    assert any("QSlim" in s.message for s in body) and any("AMG" in s.message for s in body)
    assert not any(s.message.startswith("Iteration") for s in steps)


def test_estimate_grows_with_the_settings():
    """The estimate said before a run (cost model) grows with m, k and the iteration counts,
    and with the mesh; the text names the total."""
    from algorithms.spectral.coarsen import CoarsenParams
    from app.recipes.spectral import estimate_seconds, estimate_text

    def total(n, **kw):
        return sum(estimate_seconds(n, CoarsenParams(**kw), {"isolated": True}).values())

    base = total(3232, m=404)
    assert total(3232, m=600) > base
    assert total(3232, m=404, k=200) > base
    assert total(3232, m=404, balance_iterations=1000) > base
    assert total(3232, m=404, max_iterations=20) < base
    assert total(30000, m=404) > base
    text = estimate_text(3232, CoarsenParams(m=404), {"isolated": True})
    assert text.startswith("Estimated time: about") and "3,232-vertex" in text
