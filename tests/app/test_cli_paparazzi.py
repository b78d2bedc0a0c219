"""`stylize3d paparazzi`: JSON interface, reproducibility, plain errors (nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.mesh import icosphere, read_mesh, write_mesh
from algorithms.mesh.topology import is_manifold
from app.cli import main
from tests.conftest import drift_filter, runaway_filter

#: short runs that check the command's mechanics, not the filters' convergence (12 iterations
#: need not lower an energy; a run that does not fails with lowest_fallback on, tested below)
FAST = ["--iterations", "12", "--resolution", "32", "--remesh-every", "6",
        "--remesh-threshold", "0", "--monitor-every", "0", "--no-lowest-fallback"]


@pytest.fixture
def sphere(tmp_path):
    V, F = icosphere(2)
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    p = tmp_path / "in.obj"
    write_mesh(p, V, F)
    return p


def test_json_output_and_same_seed_same_result(sphere, tmp_path, capsys):
    out1, out2 = tmp_path / "a.obj", tmp_path / "b.obj"
    rc = main(["paparazzi", str(sphere), "-o", str(out1), "--filter", "quantize", "--json",
               "--seed", "5", *FAST])
    assert rc == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["iterations"] == 12 and rep["filter"] == "quantize"
    assert set(rep["seconds_split"]) == {"render", "filter", "derivative", "remesh", "monitor"}
    assert rep["manifold"] is True and rep["self_intersections"] is False
    assert rep["same_topology"] is True and rep["remeshes"] == 1
    assert rep["rollbacks"] == rep["rollbacks_whole"] == rep["put_back_vertices"] == 0
    assert rep["params"]["put_back_crossing_only"] is True
    assert np.isfinite(rep["final_monitor_energy"]) and np.isfinite(rep["initial_monitor_energy"])
    assert main(["paparazzi", str(sphere), "-o", str(out2), "--filter", "quantize", "--quiet",
                 "--seed", "5", *FAST]) == 0
    a, b = read_mesh(out1), read_mesh(out2)
    np.testing.assert_array_equal(a.V, b.V)
    np.testing.assert_array_equal(a.F, b.F)
    assert is_manifold(a.F)


def test_filter_flags_reach_the_filter(sphere, tmp_path, capsys):
    out = tmp_path / "s.obj"
    assert main(["paparazzi", str(sphere), "-o", str(out), "--filter", "slic", "--segments",
                 "30", "--compactness", "5", "--json", *FAST]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["filter_params"] == {"segments": 30, "compactness": 5.0}


def test_unreadable_target_image_is_a_plain_error_and_nothing_is_written(sphere, tmp_path, capsys):
    bad = tmp_path / "t.png"
    bad.write_text("not an image")
    out = tmp_path / "o.obj"
    rc = main(["paparazzi", str(sphere), "-o", str(out), "--filter", "target-image", "--image",
               str(bad), *FAST])
    err = capsys.readouterr().err
    assert rc != 0 and "cannot be read" in err and "Traceback" not in err
    assert not out.exists()


def test_non_manifold_mesh_is_refused_plainly(tmp_path, capsys):
    V, F = icosphere(1)
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
    V2 = np.vstack([V, [[2.0, 2.0, 2.0]]])
    p = tmp_path / "nm.obj"
    write_mesh(p, V2, F2)
    out = tmp_path / "o.obj"
    rc = main(["paparazzi", str(p), "-o", str(out), "--filter", "guided", *FAST])
    err = capsys.readouterr().err
    assert rc != 0 and "Traceback" not in err and "clean" in err.lower()
    assert not out.exists()


def test_out_of_range_parameters_are_refused(sphere, tmp_path, capsys):
    rc = main(["paparazzi", str(sphere), "-o", str(tmp_path / "o.obj"), "--filter", "guided",
               "--radius", "0"])
    assert rc != 0 and "Radius must be at least 1" in capsys.readouterr().err


PLUGIN = '''
from dataclasses import dataclass

import numpy as np

from algorithms.params import param
from algorithms.paparazzi import register_filter


@dataclass(frozen=True)
class Darken:
    test_gain: float = param(0.5, label="Gain", minimum=0.0, maximum=1.0,
                             tooltip="How much darker the target image is.")


@register_filter("test-plugin-darken", kind="iterative", params=Darken)
def darken(image, params, ctx):
    return image * params.test_gain
'''


def test_a_plugin_file_adds_a_filter_and_its_flags(sphere, tmp_path, capsys):
    from algorithms.paparazzi import filter_names, unregister_filter

    plugin = tmp_path / "darken.py"
    plugin.write_text(PLUGIN)
    out = tmp_path / "d.obj"
    try:
        # without the plugin the filter and its flag are unknown to argparse
        assert main(["paparazzi", str(sphere), "-o", str(out), "--filter",
                     "test-plugin-darken", *FAST]) == 2
        assert "invalid choice" in capsys.readouterr().err and not out.exists()
        rc = main(["paparazzi", str(sphere), "-o", str(out), "--plugin", str(plugin),
                   "--filter", "test-plugin-darken", "--test-gain", "0.25", "--json", *FAST])
        assert rc == 0
        rep = json.loads(capsys.readouterr().out)
        assert rep["filter"] == "test-plugin-darken"
        assert rep["filter_params"] == {"test_gain": 0.25}
        assert rep["manifold"] is True and out.exists()
        # the shape moved: darkening every view tilts faces away from the lights
        assert not np.allclose(read_mesh(out).V, read_mesh(sphere).V)
        # --help after --plugin lists the plugin's flag
        assert main(["paparazzi", "--plugin", str(plugin), "--help"]) == 0
        assert "--test-gain" in capsys.readouterr().out
    finally:
        unregister_filter("test-plugin-darken")
    assert "test-plugin-darken" not in filter_names()


@pytest.mark.parametrize("text, message", [
    ("import no_such_module_here\n", "could not be loaded (line 1): ModuleNotFoundError"),
    ("def broken(:\n", "could not be loaded (line 1): SyntaxError"),
    ("x = 1\n", "registered no image filter"),
    (None, "does not exist"),
])
def test_a_plugin_that_cannot_be_loaded_is_a_plain_error_and_nothing_is_written(
        sphere, tmp_path, capsys, text, message):
    from algorithms.paparazzi import filter_names

    before = filter_names()
    plugin = tmp_path / "bad_plugin.py"
    if text is not None:
        plugin.write_text(text)
    out = tmp_path / "o.obj"
    rc = main(["paparazzi", str(sphere), "-o", str(out), "--plugin", str(plugin), "--filter",
               "guided", *FAST])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert message in err and "Traceback" not in err and str(plugin) in err
    assert not out.exists()
    assert filter_names() == before


def test_the_report_logs_the_monitor_energy_averaged_over_16_views(sphere, tmp_path, capsys):
    # issue 23: the run report's monitor energies are the mean over the fixed monitor views
    # (not one view), the same numbers the optimizer computes for the input and the output
    from algorithms.paparazzi import Paparazzi, PaparazziParams

    out = tmp_path / "o.obj"
    assert main(["paparazzi", str(sphere), "-o", str(out), "--filter", "quantize", "--json",
                 "--seed", "2", *FAST]) == 0
    rep = json.loads(capsys.readouterr().out)
    d, o = read_mesh(sphere), read_mesh(out)
    pp = PaparazziParams(iterations=12, resolution=32, remesh_every=6, monitor_every=0, seed=2)
    run = Paparazzi(d.V, d.F, "quantize", None, pp)
    assert len(run.monitor_cameras()) == 16
    norm = lambda V: (V - run.center) / run.scale  # noqa: E731
    assert rep["initial_monitor_energy"] == pytest.approx(run.monitor_energy(norm(d.V), d.F))
    assert rep["final_monitor_energy"] == pytest.approx(run.monitor_energy(norm(o.V), o.F),
                                                        rel=1e-5)
    one = run.evaluate(norm(d.V), d.F, run.monitor_cameras()[0])[0]
    assert rep["initial_monitor_energy"] != pytest.approx(one)


def test_the_report_says_which_step_a_rough_scan_got(tmp_path, capsys):
    # issue 23, fifth pass: the guided filter's step on "auto" is its rough step on a noisy
    # scan; --no-rough-step keeps the filter's own; a typed learning rate is used as it is
    from algorithms.paparazzi.measures import noisy_scan
    from tests.conftest import ROOT

    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    noisy = tmp_path / "noisy.obj"
    write_mesh(noisy, noisy_scan(d.V, d.F, 0.3, seed=0), d.F)
    short = ["--iterations", "2", "--monitor-every", "0", "--no-lowest-fallback"]
    reports = {}
    for tag, extra in (("auto", []), ("off", ["--no-rough-step"]),
                       ("typed", ["--learning-rate", "3e-5"])):
        out = tmp_path / f"{tag}.obj"
        assert main(["paparazzi", str(noisy), "-o", str(out), "--filter", "guided", "--json",
                     *short, *extra]) == 0
        reports[tag] = json.loads(capsys.readouterr().out)
    assert reports["auto"]["rough_input"] is True
    assert reports["auto"]["learning_rate_used"] == pytest.approx(2e-4)
    assert reports["off"]["rough_input"] is False and reports["off"]["params"]["rough_step"] is False
    assert reports["off"]["learning_rate_used"] == pytest.approx(1e-5)
    assert reports["typed"]["rough_input"] is False
    assert reports["typed"]["learning_rate_used"] == pytest.approx(3e-5)
    # plain-text report
    assert main(["paparazzi", str(noisy), "-o", str(tmp_path / "t.obj"), "--filter", "guided",
                 *short]) == 0
    assert "step 0.0002 (rough surface)" in capsys.readouterr().out


def test_a_run_that_does_not_lower_its_energy_fails_and_writes_nothing(sphere, tmp_path,
                                                                       capsys):
    # the brief: a result that did not converge is a failure, never a warning. A filter whose
    # target runs away (it asks for ever more contrast) raises its energy at every step: with
    # lowest_fallback on (the default) the command exits 6, says so, and leaves the output as it
    # was; with --no-lowest-fallback it writes the last shape and reports its energy
    with runaway_filter("test-runaway"):
        out = tmp_path / "o.obj"
        out.write_text("keep me")
        args = ["paparazzi", str(sphere), "-o", str(out), "--overwrite", "--filter",
                "test-runaway", "--iterations", "30", "--resolution", "32",
                "--remesh-every", "0", "--monitor-every", "10"]
        assert main(args) == 6
        err = capsys.readouterr().err
        assert "did not lower the filter's energy" in err and "nothing was changed" in err
        assert out.read_text() == "keep me"
        assert main([*args, "--no-lowest-fallback", "--json"]) == 0
        rep = json.loads(capsys.readouterr().out)
        assert rep["final_monitor_energy"] > rep["initial_monitor_energy"]
        assert rep["kept_iteration"] == 30
        assert read_mesh(out).V.shape[1] == 3


def test_a_run_whose_energy_climbs_back_writes_its_lowest_shape_and_says_so(tmp_path, capsys):
    # a filter whose pull weakens and then grows (test_paparazzi_optimize.py's drift) ends
    # above its start: the command writes the lowest measured shape and reports which
    with drift_filter("test-drift-cli", growth=1000.0) as drift:
        src = tmp_path / "sphere.obj"
        write_mesh(src, *icosphere(2))
        args = ["paparazzi", str(src), "--filter", "test-drift-cli", "--iterations", "600",
                "--resolution", "32", "--remesh-every", "0", "--monitor-every", "25"]
        assert main([*args, "-o", str(tmp_path / "a.obj"), "--json"]) == 0
        rep = json.loads(capsys.readouterr().out)
        assert 0 < rep["kept_iteration"] < 600
        assert rep["final_monitor_energy"] < rep["initial_monitor_energy"]
        assert rep["last_monitor_energy"] >= rep["initial_monitor_energy"]
        drift["calls"] = 0
        assert main([*args, "-o", str(tmp_path / "b.obj")]) == 0
        out = capsys.readouterr().out
        assert f"(the shape of iteration {rep['kept_iteration']}, the lowest; the last " \
               f"one's {rep['last_monitor_energy']:.4g})" in out
        np.testing.assert_array_equal(read_mesh(tmp_path / "a.obj").V,
                                      read_mesh(tmp_path / "b.obj").V)


def test_a_shape_that_already_looks_filtered_is_refused_before_the_first_step(tmp_path, capsys):
    # a box's pictures are flat faces: the l0 filter changes them by far less than one grey
    # level, so there is nothing for it to do (on the corpus every such guided and l0 run raised
    # its energy and was refused after a whole run). The command refuses at once with exit 6,
    # says why and what else works, and leaves the output as it was
    from algorithms.mesh.primitives import cube

    V, F = cube(6)
    box = tmp_path / "box.obj"
    write_mesh(box, V, F)
    out = tmp_path / "o.obj"
    out.write_text("keep me")
    for name in ("l0", "guided"):
        assert main(["paparazzi", str(box), "-o", str(out), "--overwrite", "--filter",
                     name]) == 6
        err = capsys.readouterr().err
        assert f"already looks the way the {name} filter makes pictures look" in err
        assert "of a grey level on average (less than 1)" in err and "quantize" in err
        assert "monitor energy" not in err          # no progress line: no step was taken
        assert out.read_text() == "keep me"
    # the advice works: quantize changes the box
    assert main(["paparazzi", str(box), "-o", str(out), "--overwrite", "--filter", "quantize",
                 "--iterations", "100", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["final_monitor_energy"] < rep["initial_monitor_energy"]
