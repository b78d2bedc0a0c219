"""The recipe "Analogies" (app/recipes/analogies.py), headless: styles from options, caching,
reproducibility, the capture-sphere strokes and their replay, the colour views."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from algorithms.deform.analogies import AnalogyParams, ShapeAnalogy
from algorithms.deform.targets import CaptureSphere, ClosestNormals, load_style
from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import icosphere, octahedron, torus, write_mesh
from app.document import MeshState
from app.recipes import get_recipe, put_blob, put_blob_file, run
from app.recipes.analogies import (CAPTURE, HUE_RANGE, angle_to_targets_view,
                                   apply_capture_stroke, capture_hash, capture_view_values,
                                   direction_hue, gaussian_curvature_view, replay_capture_edit,
                                   style_target_map, target_direction_view)

P = AnalogyParams(max_iterations=8)


@pytest.fixture(scope="module")
def state():
    V, F = icosphere(2)
    rng = np.random.default_rng(3)
    V = V * (1.0 + 0.05 * rng.standard_normal((len(V), 1)))  # a lumpy sphere
    return MeshState.make(V, F)


def painted_capture() -> dict:
    cap = CaptureSphere(3)
    cap.paint_cap([0, 0, 1], 40.0, [0, 1, 0])
    cap.paint_cap([1, 0, 0], 30.0, [0, 0, -1])
    return cap.to_dict()


def direct(state, tmap, params=P):
    last = None
    for last in ShapeAnalogy(state.V, state.F).steps(params, target_map=tmap):
        pass
    return last.V


def test_registered_under_panel_title_and_command():
    r = get_recipe("analogy")
    assert r is get_recipe("Analogies") and r.name == "Analogies" and r.command == "analogy"
    assert r.params_cls() is AnalogyParams and r.deterministic


def test_primitive_style_equals_shape_analogy_and_repeats_bit_for_bit(state):
    a = run("analogy", state, P, {"style": "dodecahedron"})
    b = run("analogy", state, P, {"style": "dodecahedron"})
    assert a.state.V.tobytes() == b.state.V.tobytes()
    assert a.state.V.tobytes() == direct(state, ClosestNormals.primitive("dodecahedron")).tobytes()
    assert a.outcome["iterations"] == 8 and a.outcome["mean_angle_to_targets"] >= 0
    default = run("analogy", state, {"max_iterations": 8}, {})  # no style: the cube
    cube = run("analogy", state, P, {"style": "cube"})
    assert default.state.V.tobytes() == cube.state.V.tobytes()
    assert not np.array_equal(default.state.V, a.state.V)


def test_cache_keeps_the_precomputation_for_the_same_arrays(state):
    cache: dict = {}
    first = run("analogy", state, P, {"style": "cube"}, cache=cache)
    sa = cache["analogy"][2]
    again = run("analogy", state, AnalogyParams(max_iterations=8, lam=2.0), {"style": "cube"},
                cache=cache)
    assert cache["analogy"][2] is sa
    copy = MeshState.make(state.V.copy(), state.F.copy())  # equal values: reused too
    run("analogy", copy, P, {"style": "cube"}, cache=cache)
    assert cache["analogy"][2] is sa
    # the reused precomputation gives the bits of a fresh one
    fresh = run("analogy", state, AnalogyParams(max_iterations=8, lam=2.0), {"style": "cube"})
    assert again.state.V.tobytes() == fresh.state.V.tobytes()
    moved = state.with_positions(first.state.V)
    run("analogy", moved, P, {"style": "cube"}, cache=cache)
    assert cache["analogy"][2] is not sa


def test_capture_style_from_options(state):
    cap = painted_capture()
    opts = {"style": CAPTURE, "capture": cap}
    a = run("analogy", state, P, json.loads(json.dumps(opts)))
    b = run("analogy", state, P, opts)
    assert a.state.V.tobytes() == b.state.V.tobytes()
    assert a.state.V.tobytes() == direct(state, CaptureSphere.from_dict(cap)).tobytes()
    assert not np.array_equal(a.state.V, state.V)
    with pytest.raises(ParameterError, match="capture"):
        run("analogy", state, P, {"style": CAPTURE})
    # the capture dict is ignored for other styles
    c = run("analogy", state, P, {"style": "cube", "capture": cap})
    assert c.state.V.tobytes() == run("analogy", state, P, {"style": "cube"}).state.V.tobytes()


def test_style_files_are_blobs(state, tmp_path):
    V, F = octahedron()
    path = tmp_path / "octa.obj"
    write_mesh(path, 3.0 * V, F)
    ref = put_blob_file(path)
    expected = direct(state, load_style(str(path))[0])
    path.unlink()  # only the stored bytes matter
    cache: dict = {}
    a = run("analogy", state, P, {"style": ref}, cache=cache)
    assert a.state.V.tobytes() == expected.tobytes()
    tmap, what = style_target_map({"style": ref}, cache)
    assert "octa.obj" in what and tmap is cache["styles"][(ref, "auto")][0]
    # a capture .json file
    cref = put_blob(json.dumps(painted_capture()).encode(), "mine.json")
    b = run("analogy", state, P, {"style": cref})
    assert b.state.V.tobytes() == direct(state, CaptureSphere.from_dict(painted_capture())
                                         ).tobytes()
    # refusals: a genus-1 style, a missing blob, a plain path, an unknown name
    Vt, Ft = torus()
    write_mesh(tmp_path / "torus.obj", Vt, Ft)
    with pytest.raises(InvalidMeshError, match="genus"):
        run("analogy", state, P, {"style": put_blob_file(tmp_path / "torus.obj")})
    with pytest.raises(ParameterError, match="missing"):
        run("analogy", state, P, {"style": "blob:" + "0" * 64 + "/gone.obj"})
    with pytest.raises(ParameterError, match="Unknown style"):
        run("analogy", state, P, {"style": str(tmp_path / "torus.obj")})
    with pytest.raises(ParameterError, match="Unknown style"):
        run("analogy", state, P, {"style": "sphere"})


def test_progressive_option_runs_on_a_coarse_copy():
    V, F = icosphere(4)
    st = MeshState.make(V, F)
    opts = {"style": "cube", "progressive": {"target_faces": 400, "preview_every": 0}}
    a = run("analogy", st, P, opts)
    b = run("analogy", st, P, opts)
    assert a.state.V.shape == V.shape and a.state.V.tobytes() == b.state.V.tobytes()
    full = run("analogy", st, P, {"style": "cube"})
    assert not np.array_equal(a.state.V, full.state.V)
    # closer to the cube than the input: normals near the axes
    ang0 = angle_to_targets_view(V, F, ClosestNormals.primitive("cube")).mean()
    assert angle_to_targets_view(a.state.V, F, ClosestNormals.primitive("cube")).mean() < ang0


# -- capture strokes --------------------------------------------------------------------------
def test_apply_capture_stroke_paints_one_region_per_stroke():
    before = CaptureSphere(3).to_dict()
    stroke = {"dabs": [[0, 0, 2.0], [0, 0.3, 1.0]], "radius": 0.1, "erase": False,
              "target": [1.0, 0.0, 0.0]}
    after = apply_capture_stroke(before, stroke)
    assert before == CaptureSphere(3).to_dict()  # the input is not changed
    cap = CaptureSphere.from_dict(after)
    assert cap.n_regions == 1
    d1 = np.array([0, 0, 1.0])
    d2 = np.array([0, 0.3, 1.0]) / np.linalg.norm([0, 0.3, 1.0])
    c = np.cos(0.1 * np.pi)
    expected = (cap.vertices @ d1 > c) | (cap.vertices @ d2 > c)
    np.testing.assert_array_equal(cap.labels >= 0, expected)
    np.testing.assert_array_equal(cap.targets, [[1.0, 0.0, 0.0]])
    # a second stroke: a new region, over the first where they overlap
    after2 = apply_capture_stroke(after, {**stroke, "dabs": [[0, 0, 1.0]], "target": [0, 0, -3]})
    cap2 = CaptureSphere.from_dict(after2)
    assert cap2.n_regions == 2 and (cap2.labels[cap.vertices @ d1 > c] == 1).all()
    # erasing keeps the regions' numbers
    erased = CaptureSphere.from_dict(apply_capture_stroke(after2, {**stroke, "erase": True}))
    assert not (erased.labels >= 0).any() and erased.n_regions == 2
    # a dab that takes no vertex still opens a region (as the brush always did)
    empty = apply_capture_stroke(before, {**stroke, "radius": 0.0})
    assert CaptureSphere.from_dict(empty).n_regions == 1
    with pytest.raises(ParameterError):
        apply_capture_stroke(before, {"dabs": [[0, 0, 1]]})


def test_replay_capture_edit_checks_the_hash():
    before = painted_capture()
    stroke = {"dabs": [[0.1, -0.9, 0.2]], "radius": 0.15, "erase": False, "target": [0, 0, 1]}
    after = apply_capture_stroke(before, stroke)
    h = hashlib.sha256(json.dumps(after, sort_keys=True).encode()).hexdigest()
    assert capture_hash(after) == h
    details = {"tool": "capture", "capture_before": before, "stroke": stroke,
               "capture_after_hash": h}
    assert replay_capture_edit(details)
    assert replay_capture_edit(json.loads(json.dumps(details)))
    assert not replay_capture_edit({**details, "stroke": {**stroke, "radius": 0.14}})
    assert not replay_capture_edit({**details, "capture_after_hash": capture_hash(before)})
    assert not replay_capture_edit({**details, "stroke": {"dabs": "nonsense"}})
    assert not replay_capture_edit({"stroke": stroke})
    assert not replay_capture_edit({**details, "capture_before": {"format": "other"}})


# -- colour views -----------------------------------------------------------------------------
def test_colour_views(state):
    cube = ClosestNormals.primitive("cube")
    ang = angle_to_targets_view(state.V, state.F, cube)
    assert ang.shape == (len(state.V),) and 0 <= ang.min() and ang.max() <= 60
    from algorithms.mesh import cube as cube_mesh

    Vc, Fc = cube_mesh(2)
    # a cube's vertex normals on its faces' interiors are the cube's normals: angle 0 there
    assert np.isclose(angle_to_targets_view(Vc, Fc, cube), 0.0, atol=1e-6).any()
    K, (lo, hi) = gaussian_curvature_view(state.V, state.F)
    assert K.shape == (len(state.V),) and lo == -hi and hi > 0 and np.isfinite(K).all()
    assert hi == np.percentile(np.abs(K), 95)
    assert K.mean() > 0  # a closed genus-0 shape: ∫K = 4π
    hue = target_direction_view(state.V, state.F, cube)
    T = cube.style_normals
    assert set(hue.tolist()) <= set(direction_hue(T).tolist())  # the six faces' colours
    assert len(set(direction_hue(T).tolist())) == 6  # different directions, colours
    assert (direction_hue(T) >= HUE_RANGE[0]).all() and (direction_hue(T) <= HUE_RANGE[1]).all()
    cap = CaptureSphere.from_dict(painted_capture())
    vals = capture_view_values(cap)
    assert np.isnan(vals[cap.labels < 0]).all()
    np.testing.assert_array_equal(vals[cap.labels == 0], direction_hue(np.array([[0, 1.0, 0]]))[0])
