"""``stylize3d cubic`` with several λ in one run (the solver and progressive mesh built once),
and the automatic choice of progressive meshes saying why (issue 25)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.deform import progressive
from algorithms.deform.cubic import CubicParams
from algorithms.mesh import read_mesh
from app import cli
from tests.conftest import shared_mesh


def _json(capsys):
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err


def test_several_lambdas_share_the_preprocessing(capsys, tmp_path):
    src = str(shared_mesh("bob.obj"))
    out = str(tmp_path / "bob.ply")
    code = cli.main(["cubic", src, "-o", out, "--lambda", "0.2", "0.5", "--json", "--quiet",
                     "--progressive-faces", "3000"])
    assert code == 0
    d, _ = _json(capsys)
    assert [r["lambda"] for r in d["runs"]] == [0.2, 0.5]
    assert [r["output"] for r in d["runs"]] == [str(tmp_path / "bob_lambda0.2.ply"),
                                                str(tmp_path / "bob_lambda0.5.ply")]
    assert d["preprocess_seconds"] > 0 and d["progressive_faces"] == 3000
    assert "--progressive-faces 3000" in d["progressive_reason"]
    # the second λ is what a run with that λ alone gives, and more cubic than the first
    assert d["runs"][1]["l1_normals_after"] < d["runs"][0]["l1_normals_after"]
    single = str(tmp_path / "single.ply")
    assert cli.main(["cubic", src, "-o", single, "--lambda", "0.5", "--json", "--quiet",
                     "--progressive-faces", "3000"]) == 0
    one, _ = _json(capsys)
    assert one["l1_normals_after"] == d["runs"][1]["l1_normals_after"]
    assert np.array_equal(read_mesh(single).V, read_mesh(d["runs"][1]["output"]).V)


def test_several_lambdas_with_a_placeholder_and_refusals(capsys, tmp_path):
    src = str(shared_mesh("spot_lowres.obj"))
    code = cli.main(["cubic", src, "-o", str(tmp_path / "s-{lam}.obj"), "--lambda", "0.1",
                     "0.3", "--quiet"])
    assert code == 0
    assert (tmp_path / "s-0.1.obj").exists() and (tmp_path / "s-0.3.obj").exists()
    text = capsys.readouterr().out
    assert text.count("Stylized") == 2 and "on every triangle" in text
    # the same value twice, and an existing output, are refused before anything runs
    assert cli.main(["cubic", src, "-o", str(tmp_path / "t.obj"), "--lambda", "0.1",
                     "0.1"]) == 5
    assert cli.main(["cubic", src, "-o", str(tmp_path / "s-{lam}.obj"), "--lambda", "0.3",
                     "0.7"]) == 3
    assert not (tmp_path / "s-0.7.obj").exists()


def test_batch_jobs_take_one_lambda():
    from algorithms.errors import ParameterError
    from app.cli.deform import cubic_job

    parser = cli.build_parser("cubic")
    args = parser.parse_args(["cubic", "x.obj", "-o", "y.obj", "--lambda", "0.2", "0.4"])
    with pytest.raises(ParameterError):
        cubic_job(args, 1000)
    args = parser.parse_args(["cubic", "x.obj", "-o", "y.obj", "--lambda", "0.3"])
    assert cubic_job(args, 1000)[0].lam == 0.3


@pytest.mark.parametrize("threshold,expect", [(1000, True), (10_000, False)])
def test_automatic_choice_says_why(monkeypatch, capsys, tmp_path, threshold, expect):
    monkeypatch.setattr(progressive, "AUTO_PROGRESSIVE_FACES", threshold)
    src = str(shared_mesh("spot_lowres.obj"))  # 1,654 triangles
    assert cli.main(["cubic", src, "-o", str(tmp_path / "a.obj"), "--json"]) == 0
    d, err = _json(capsys)
    assert d["progressive_auto"] is expect
    assert "1,654 triangles" in d["progressive_reason"]
    assert f"{threshold:,}" in d["progressive_reason"]
    if expect:
        assert d["progressive_reason"] in err and "finishing on every triangle" in err
        assert d["progressive_finish"] is True and "--coarse-only" in err
    else:
        assert d["progressive_faces"] is None and "every triangle" in d["progressive_reason"]
        assert d["progressive_finish"] is None



def test_coarse_only_runs_the_copy_alone_and_says_so(capsys, tmp_path):
    """--coarse-only (issue 37): progressive meshes without the finish, said in the last line
    and in --json; it contradicts --no-progressive and the multigrid solver."""
    from algorithms.deform.progressive import ProgressiveCubic

    src = str(shared_mesh("spot_lowres.obj"))  # 1,654 triangles
    out = tmp_path / "a.obj"
    assert cli.main(["cubic", src, "-o", str(out), "--coarse-only", "--progressive-faces",
                     "800", "--lambda", "0.4", "--quiet"]) == 0
    line = capsys.readouterr().out
    assert "800-triangle copy alone" in line and "not finished on every triangle" in line
    got = read_mesh(str(out)).V
    V, F = read_mesh(src).V, read_mesh(src).F
    alone = ProgressiveCubic(V, F, target_faces=800).stylize(CubicParams(lam=0.4))
    np.testing.assert_allclose(got, alone, atol=1e-5 * np.ptp(V, axis=0).max())
    assert cli.main(["cubic", src, "-o", str(tmp_path / "b.obj"), "--progressive-faces", "800",
                     "--lambda", "0.4", "--json"]) == 0
    d, _ = _json(capsys)
    assert d["progressive_finish"] is True and d["progressive_faces"] == 800
    assert cli.main(["cubic", src, "-o", str(tmp_path / "c.obj"), "--progressive-faces", "800",
                     "--lambda", "0.4", "--quiet"]) == 0
    assert "then on every triangle from its result" in capsys.readouterr().out
    for bad in (["--no-progressive"], ["--global-solver", "multigrid"]):
        assert cli.main(["cubic", src, "-o", str(tmp_path / "d.obj"), "--coarse-only",
                         *bad]) == 5
        assert "--coarse-only" in capsys.readouterr().err


def test_saved_progressive_options_without_finish_replay_the_copy_alone():
    """A project or study log saved before ``finish`` existed ran the copy alone: its options
    (a progressive dict without the key) replay that, bit for bit; new options finish."""
    import app.recipes
    from algorithms.deform.progressive import ProgressiveCubic

    V, F = read_mesh(str(shared_mesh("spot_lowres.obj"))).V, read_mesh(
        str(shared_mesh("spot_lowres.obj"))).F
    old = {"target_faces": 800, "strategy": "qslim", "tikhonov": 1e-6, "lam_exponent": 0.0,
           "preview_every": 0}
    got = app.recipes.run("cubic", (V, F), {"lam": 0.4},
                          {"plane_axis": 0, "progressive": old, "multigrid": False}).state.V
    alone = ProgressiveCubic(V, F, target_faces=800).stylize(CubicParams(lam=0.4))
    np.testing.assert_array_equal(got, alone)
    new = app.recipes.run("cubic", (V, F), {"lam": 0.4},
                          {"plane_axis": 0, "progressive": {**old, "finish": True},
                           "multigrid": False})
    assert new.last.metrics["fine_iterations"] >= 1 and new.outcome["fine_iterations"] >= 1
    assert np.abs(new.state.V - alone).max() > 0


def test_above_the_finish_limit_the_copy_alone_runs_and_every_output_says_so(
        monkeypatch, capsys, tmp_path):
    """FINISH_MAX_FACES: a mesh too big to finish on every triangle (its factorization would
    exhaust a desktop's memory) gets the copy alone, and the line, --json and the recipe's
    last Step say so (crash-free: no run the system would kill)."""
    import app.recipes
    from algorithms.deform.progressive import ProgressiveCubic

    monkeypatch.setattr(progressive, "FINISH_MAX_FACES", 1000)
    src = str(shared_mesh("spot_lowres.obj"))  # 1,654 triangles
    assert cli.main(["cubic", src, "-o", str(tmp_path / "a.obj"), "--progressive-faces", "800",
                     "--lambda", "0.4", "--json"]) == 0
    d, _ = _json(capsys)
    assert d["progressive_finish"] is False
    assert "not finished on every triangle" in d["progressive_not_finished"]
    assert "1,654 triangles, more than 1,000" in d["progressive_not_finished"]
    assert cli.main(["cubic", src, "-o", str(tmp_path / "b.obj"), "--progressive-faces", "800",
                     "--lambda", "0.4", "--quiet"]) == 0
    line = capsys.readouterr().out
    assert "copy alone" in line and "not finished on every triangle: this mesh has" in line
    V, F = read_mesh(src).V, read_mesh(src).F
    run = app.recipes.run("cubic", (V, F), {"lam": 0.4},
                          {"plane_axis": 0, "multigrid": False,
                           "progressive": {"target_faces": 800, "finish": True,
                                           "preview_every": 0}})
    assert run.last.metrics["finish_skipped"] == 1.0 and "fine_iterations" not in run.last.metrics
    assert "not finished on every triangle" in run.last.message
    alone = ProgressiveCubic(V, F, target_faces=800).stylize(CubicParams(lam=0.4))
    np.testing.assert_array_equal(run.state.V, alone)
    assert cli.main(["analogy", src, "-o", str(tmp_path / "c.obj"), "--style", "cube",
                     "--progressive-faces", "800", "--json"]) == 0
    d, _ = _json(capsys)
    assert d["progressive_finish"] is False and d["progressive_not_finished"]
