"""The Qt-free recipe "Paparazzi" (app/recipes/paparazzi.py), run headless."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import write_mesh
from algorithms.mesh.primitives import icosphere
from algorithms.mesh.topology import is_manifold
from algorithms.paparazzi import Paparazzi, PaparazziParams, get_filter, unregister_filter
from algorithms.steps import Step
from app.document import MeshState
from app.recipes import get_recipe, outcome_hash, put_blob, put_blob_file, run
from app.recipes.paparazzi import (filter_options, monitor_points, paparazzi_result, rgb8)
from tests.conftest import runaway_filter

#: a short run: a few views, small images, remeshing and the monitor inside it; it checks the
#: recipe's mechanics, not convergence (six views need not lower an energy, and with
#: lowest_fallback on a run that does not fails: tested below)
SHORT = {"iterations": 6, "resolution": 32, "remesh_every": 3, "monitor_every": 2,
         "lowest_fallback": False}
BUILT_IN = ("guided", "quantize", "slic", "l0", "neural-style")


@pytest.fixture(scope="module")
def sphere():
    V, F = icosphere(2)
    # not a perfect sphere: filters have something to change
    V = V * (1.0 + 0.15 * np.sin(3.0 * V[:, :1]) * np.cos(2.0 * V[:, 1:2]))
    return MeshState.make(V, F)


def _same(a, b):
    np.testing.assert_array_equal(a.state.V, b.state.V)
    np.testing.assert_array_equal(a.state.F, b.state.F)
    assert a.state.V.tobytes() == b.state.V.tobytes()


def _square_png(path, size=24, seed=0):
    from PIL import Image

    rng = np.random.default_rng(seed)
    Image.fromarray((rng.random((size, size, 3)) * 255).astype(np.uint8)).save(path)
    return path


def test_registered_with_the_method_params_and_new_faces():
    r = get_recipe("paparazzi")
    assert r is get_recipe("Paparazzi") and r.name == "Paparazzi"
    assert r.changes_faces and r.deterministic and r.params_cls() is PaparazziParams
    assert r.result is paparazzi_result


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_built_in_filter_runs_headless_and_repeats_bit_for_bit(sphere, name):
    options = json.loads(json.dumps(filter_options(name, get_filter(name).params())))
    a = run("paparazzi", sphere, dict(SHORT, seed=3), options)
    b = run("paparazzi", sphere, dict(SHORT, seed=3), options)
    _same(a, b)
    assert outcome_hash(a.outcome) == outcome_hash(b.outcome)
    assert a.last.iteration == 6 and a.outcome["iterations"] == 6
    assert is_manifold(a.state.F) and np.isfinite(a.state.V).all()
    assert not np.array_equal(a.state.V, sphere.V) or a.state.F.shape != sphere.F.shape


def test_the_seed_is_the_only_randomness(sphere):
    a = run("paparazzi", sphere, dict(SHORT, seed=1), {"filter": "slic"})
    b = run("paparazzi", sphere, dict(SHORT, seed=2), {"filter": "slic"})
    assert a.state.V.shape != b.state.V.shape or not np.array_equal(a.state.V, b.state.V)


def test_same_as_the_optimizer_called_directly(sphere):
    """The recipe adds nothing of its own to the run: options -> the filter's Params."""
    from algorithms.paparazzi.filters import L0Params

    fp = L0Params(l0_lambda=0.02)
    res = run("paparazzi", sphere, dict(SHORT, seed=5), filter_options("l0", fp))
    last = None
    for last in Paparazzi(sphere.V, sphere.F, "l0", fp,
                          PaparazziParams(**dict(SHORT, seed=5))).steps():
        pass
    np.testing.assert_array_equal(res.state.V, last.V)
    np.testing.assert_array_equal(res.state.F, last.F)


def test_target_image_and_mesh_and_painting_are_blobs(sphere, tmp_path):
    from algorithms.paparazzi.filters import TargetImageParams, TargetMeshParams
    from algorithms.paparazzi.neural_style import NeuralStyleParams

    img = _square_png(tmp_path / "target.png")
    V2, F2 = icosphere(2)
    mesh = tmp_path / "target.obj"
    write_mesh(mesh, V2 * np.array([1.0, 0.7, 1.2]), F2)
    painting = _square_png(tmp_path / "painting.png", size=40, seed=1)
    cases = [("target-image", TargetImageParams(image=str(img)), "image", img),
             ("target-mesh", TargetMeshParams(target=str(mesh)), "target", mesh),
             ("neural-style", NeuralStyleParams(style_image=str(painting)), "style_image",
              painting)]
    for name, fp, field, path in cases:
        options = filter_options(name, fp)
        ref = options["filter_params"][field]
        assert ref == put_blob_file(path) and ref.startswith("blob:")
        assert str(tmp_path) not in json.dumps(options)   # no path of this machine
        a = run("paparazzi", sphere, dict(SHORT, seed=2), json.loads(json.dumps(options)))
        # the same run as with the file itself (the blob holds its bytes)
        last = None
        for last in Paparazzi(sphere.V, sphere.F, name, fp,
                              PaparazziParams(**dict(SHORT, seed=2))).steps():
            pass
        np.testing.assert_array_equal(a.state.V, last.V)
        assert a.state.V.shape != sphere.V.shape or not np.array_equal(a.state.V, sphere.V)
    # the files' content is what counts: another target gives another result
    other = filter_options("target-image", TargetImageParams(
        image=str(_square_png(tmp_path / "other.png", seed=7))))
    c = run("paparazzi", sphere, dict(SHORT, seed=2), other)
    first = run("paparazzi", sphere, dict(SHORT, seed=2),
                filter_options("target-image", TargetImageParams(image=str(img))))
    assert not np.array_equal(c.state.V, first.state.V)


def test_a_missing_blob_or_filter_says_so_plainly(sphere):
    options = {"filter": "target-image",
               "filter_params": {"image": "blob:" + "0" * 64 + "/lost.png"}}
    with pytest.raises(ParameterError, match="lost.png.*missing"):
        run("paparazzi", sphere, SHORT, options)
    with pytest.raises(ParameterError, match="no image filter called 'nope'"):
        run("paparazzi", sphere, SHORT, {"filter": "nope"})
    with pytest.raises(ParameterError, match="Unknown parameter"):
        run("paparazzi", sphere, SHORT, {"filter": "guided", "filter_params": {"bogus": 1}})


PLUGIN = '''
from dataclasses import dataclass

import numpy as np

from algorithms.params import param
from algorithms.paparazzi import register_filter


@dataclass(frozen=True)
class PosterizeParams:
    levels: int = param(3, label="Levels", minimum=2, maximum=64, tooltip="Colour levels.")


@register_filter("{name}", kind="iterative", params=PosterizeParams, resolution=32)
def posterize(image, params, ctx):
    return np.round(image * (params.levels - 1)) / (params.levels - 1)
'''


def test_a_plugin_filter_travels_as_a_blob_and_is_loaded_where_missing(sphere, tmp_path):
    from algorithms.paparazzi.filters import load_filter_plugin

    name = "test-recipe-posterize"
    src = tmp_path / "posterize.py"
    src.write_text(PLUGIN.replace("{name}", name))
    try:
        assert load_filter_plugin(src) == [name]
        spec = get_filter(name)
        options = filter_options(name, spec.params(levels=4))
        assert options["plugin"] == put_blob_file(src)
        a = run("paparazzi", sphere, SHORT, options)
        assert get_filter(name) is spec  # the registered one was the plug-in's: used as is
        # another process (a replay): the filter is not registered; the blob brings it back
        unregister_filter(name)
        src.unlink()
        b = run("paparazzi", sphere, SHORT, json.loads(json.dumps(options)))
        _same(a, b)
        assert get_filter(name) is not spec
        # a filter of the same name from another file is replaced by the run's own
        other = tmp_path / "other.py"
        other.write_text(PLUGIN.replace("{name}", name).replace("np.round", "np.floor"))
        load_filter_plugin(other)
        c = run("paparazzi", sphere, SHORT, options)
        _same(a, c)
        # without the plug-in file, a filter that is not registered cannot run
        unregister_filter(name)
        with pytest.raises(ParameterError, match=name):
            run("paparazzi", sphere, SHORT, {"filter": name})
        with pytest.raises(ParameterError, match="missing"):
            run("paparazzi", sphere, SHORT,
                dict(options, plugin="blob:" + "1" * 64 + "/gone.py"))
    finally:
        unregister_filter(name)
    # built-in filters carry no plug-in
    assert "plugin" not in filter_options("guided", get_filter("guided").params())


def test_non_manifold_input_and_broken_results_are_refused():
    V, F = icosphere(1)
    V2 = np.vstack([V, [[2.0, 2.0, 2.0]]])
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
    with pytest.raises(InvalidMeshError, match="2-manifold"):
        run("paparazzi", (V2, F2), SHORT, {"filter": "guided"})
    before = MeshState.make(V, F)
    with pytest.raises(InvalidMeshError, match="2-manifold"):
        paparazzi_result(before, _step(V2, F2))
    with pytest.raises(InvalidMeshError, match="invalid mesh"):
        paparazzi_result(before, _step(V * np.nan, F))
    # a result with the input's faces keeps its fields; new faces make a new mesh
    with_field = MeshState.make(V, F, {"mask": np.ones(len(V))})
    same = paparazzi_result(with_field, _step(V * 2.0, F.copy()))
    assert "mask" in same.fields and same.F is with_field.F
    Vs, Fs = icosphere(2)
    new = paparazzi_result(with_field, _step(Vs, Fs))
    assert new.F.shape == Fs.shape and not new.fields


def _step(V, F):
    s = Step(1, 1, V, {})
    s.F = F
    return s


def test_view_helpers():
    img = np.array([[[0.0], [1.0]], [[np.nan], [0.5]]])
    out = rgb8(img)
    assert out.dtype == np.uint8 and out.shape == (2, 2, 3) and out.flags.c_contiguous
    np.testing.assert_array_equal(out[..., 0], [[0, 255], [0, 128]])
    np.testing.assert_array_equal(rgb8(np.full((1, 1, 3), 2.0)), [[[255, 255, 255]]])
    hist = [(it, {"monitor_energy": 10.0 - it, "initial_monitor_energy": 10.0})
            for it in range(1, 8)]
    vals, started = monitor_points(hist[:4], 2, 7, False)
    assert vals == [10.0, 8.0, 6.0] and started
    vals, started = monitor_points(hist[4:], 2, 7, True)
    assert vals == [4.0, 3.0] and started       # 6, and the last (7)
    assert monitor_points([(1, {"energy": 1.0})], 1, 1, False) == ([], False)
    assert monitor_points(hist, 0, None, True) == ([], True)
    # an earlier, lower shape kept (lowest_fallback): the plot ends at the last shape's energy
    kept = hist[:6] + [(7, {"monitor_energy": 2.0, "last_monitor_energy": 12.0,
                            "initial_monitor_energy": 10.0})]
    assert monitor_points(kept, 2, 7, False)[0] == [10.0, 8.0, 6.0, 4.0, 12.0]


def test_options_are_json_and_blobs_only_for_readable_files(tmp_path):
    from algorithms.paparazzi.filters import TargetImageParams

    missing = str(tmp_path / "gone.png")
    opts = filter_options("target-image", TargetImageParams(image=missing))
    assert opts == {"filter": "target-image", "filter_params": {"image": missing}}
    ref = put_blob(b"abc", "x.png")
    assert filter_options("target-image", TargetImageParams(image=ref))["filter_params"] == \
        {"image": ref}
    json.dumps(filter_options("slic", get_filter("slic").params()))


@pytest.mark.parametrize("name, iterations, resolution, factor", [
    ("guided", 300, 0, 0.99), ("quantize", 60, 0, 0.95)])
def test_every_built_in_filter_lowers_its_energy_averaged_over_16_views(name, iterations,
                                                                        resolution, factor):
    # issue 23: the guided filter and quantize at their defaults (fewer iterations, no
    # remeshing, on a small bumpy shape) lower the mean of their energy over the 16 fixed
    # monitor views (quantize measured 960 -> 875 in 60 iterations). slic and
    # l0 need more iterations at 256 px than a unit test can afford (40 at 128 px: slic 8.51 ->
    # 8.58, l0 9.68 -> 9.54); their 1000-iteration runs at the command line's defaults on the
    # shared meshes: benchmarks/paparazzi_effects.py, docs/results/paparazzi.md
    from algorithms.mesh import loop_subdivide

    V, F = loop_subdivide(*icosphere(2), 1)
    V = V * (1.0 + 0.2 * np.sin(4.0 * V[:, :1]) * np.cos(3.0 * V[:, 1:2]))
    V = V + 0.004 * np.random.default_rng(0).standard_normal(V.shape)
    params = {"iterations": iterations, "remesh_every": 0, "monitor_every": 0,
              "resolution": resolution}
    res = run("paparazzi", MeshState.make(V, F), params, {"filter": name})
    o = res.outcome
    assert o["monitor_views"] == 16
    assert o["monitor_energy"] < factor * o["initial_monitor_energy"], o


def test_a_run_that_does_not_lower_its_energy_fails_after_its_last_step(sphere):
    # lowest_fallback on (the default): the recipe's generator raises EnergyNotLowered after the
    # last step, so every caller (panel, command line, replay, batch) fails and changes nothing;
    # off, the last shape is the result whatever its energy (old study logs replay so)
    from algorithms.paparazzi import EnergyNotLowered

    with runaway_filter("test-runaway-recipe", panel_iterations=700):
        params = {"iterations": 20, "resolution": 32, "remesh_every": 0, "monitor_every": 5}
        steps = []
        with pytest.raises(EnergyNotLowered, match="did not lower.*give it 700 or more"):
            for s in get_recipe("paparazzi").steps(sphere, PaparazziParams(**params),
                                                   {"filter": "test-runaway-recipe"}):
                steps.append(s)
        assert len(steps) == 20
        assert steps[-1].metrics["monitor_energy"] > steps[-1].metrics["initial_monitor_energy"]
        with pytest.raises(EnergyNotLowered):
            run("paparazzi", sphere, params, {"filter": "test-runaway-recipe"})
        res = run("paparazzi", sphere, dict(params, lowest_fallback=False),
                  {"filter": "test-runaway-recipe"})
        assert res.outcome["monitor_energy"] > res.outcome["initial_monitor_energy"]


@pytest.mark.parametrize("sample, name", [("blob.obj", "l0")])
def test_the_quick_look_of_a_filter_whose_energy_rises_first_lowers_it(sample, name):
    # issue 23, seventh pass: 100 iterations at 64 px end above the start on these (the run
    # fails); the filter's quick look (FilterSpec.quick_look: slic 300, l0 1000 iterations)
    # ends below (measured: blob l0 1.90 -> 1.27). The pretzel with slic was the other case
    # until the remeshing changed only what the run made worse (issue 38): its 100 iterations
    # now lower the energy too (test below)
    import dataclasses

    from algorithms.mesh import read_mesh
    from algorithms.paparazzi import EnergyNotLowered
    from app.panels.paparazzi import PaparazziPanelParams
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / sample)
    state = MeshState(V=d.V, F=d.F)
    generic = dataclasses.replace(PaparazziPanelParams(), iterations=100, resolution=64)
    with pytest.raises(EnergyNotLowered):
        run("Paparazzi", state, generic, {"filter": name, "filter_params": {}})
    quick = dataclasses.replace(generic, **get_filter(name).quick_look)
    steps = list(get_recipe("Paparazzi").steps(state, quick, {"filter": name,
                                                              "filter_params": {}}))
    m = steps[-1].metrics
    assert m["monitor_energy"] < m["initial_monitor_energy"], m


def test_slics_short_run_lowers_the_pretzels_energy_now_that_remeshing_leaves_its_triangles():
    """100 iterations at 64 px of slic on the pretzel sample ended above the start while every
    remeshing re-placed the pretzel's own bad triangles; with the remeshing changing only what
    the run made worse (WORSE_FACTOR) they end below it (measured 9.757 -> 9.546)."""
    import dataclasses

    from algorithms.mesh import read_mesh
    from app.panels.paparazzi import PaparazziPanelParams
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / "pretzel.obj")
    generic = dataclasses.replace(PaparazziPanelParams(), iterations=100, resolution=64)
    res = run("Paparazzi", MeshState(V=d.V, F=d.F), generic, {"filter": "slic",
                                                            "filter_params": {}})
    o = res.outcome
    assert o["monitor_energy"] < 0.99 * o["initial_monitor_energy"], o
