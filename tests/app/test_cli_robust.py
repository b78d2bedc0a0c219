"""The CLI never shows a traceback, survives a closed pipe, and switches big meshes to progressive
meshes as the app does (issue 10)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from algorithms.deform import progressive
from algorithms.mesh import read_mesh
from app import cli
from tests.conftest import ROOT, shared_mesh


def test_unexpected_error_is_a_plain_message_with_a_crash_log(monkeypatch, capsys, tmp_path):
    def boom(args):
        raise RuntimeError("Factor is exactly singular")

    out = tmp_path / "o.obj"
    monkeypatch.setattr(cli, "cmd_cubic", boom)  # main() builds its parser after the patch
    code = cli.main(["cubic", str(shared_mesh("spot_lowres.obj")), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == cli.INTERNAL_ERROR_EXIT
    assert "Traceback" not in err and "nothing was written" in err
    assert "Factor is exactly singular" in err and "bug" in err
    log = err.split("the details are in ")[1].rstrip().rstrip(".")
    assert "RuntimeError" in open(log).read()
    assert not out.exists()


def test_out_of_memory_is_a_plain_message(monkeypatch, capsys, tmp_path):
    def hungry(args):
        raise MemoryError()

    monkeypatch.setattr(cli, "cmd_info", hungry)
    code = cli.main(["info", str(shared_mesh("spot_lowres.obj"))])
    err = capsys.readouterr().err
    assert code == cli.INTERNAL_ERROR_EXIT
    assert "out of memory" in err and "Traceback" not in err


def test_closed_pipe_prints_no_traceback():
    """`stylize3d info MESH --json | head` with a reader that is already gone."""
    p = subprocess.Popen([sys.executable, "-m", "app", "info", str(shared_mesh("bob.obj")),
                          "--json"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # the reader goes away before the command writes
    err = p.stderr.read().decode()
    p.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert p.returncode == 0


@pytest.fixture
def small_auto_threshold(monkeypatch):
    """Make 'big' mean more than 1,000 triangles so a small mesh takes the big-mesh path."""
    monkeypatch.setattr(progressive, "AUTO_PROGRESSIVE_FACES", 1000)


@pytest.mark.parametrize("command, extra", [("cubic", []), ("analogy", ["--style", "cube"])])
def test_big_mesh_goes_progressive_and_says_so(small_auto_threshold, capsys, tmp_path,
                                               command, extra):
    src = shared_mesh("spot_lowres.obj")  # 1,654 triangles > 1,000
    out = tmp_path / "o.obj"
    code = cli.main([command, str(src), "-o", str(out), "--json", *extra])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    d = json.loads(cap.out)
    # the copy has 20,000 triangles, or half the mesh's where that is fewer
    assert d["progressive_auto"] is True and d["progressive_faces"] == 1654 // 2
    assert "progressive meshes" in cap.err and "--no-progressive" in cap.err
    res = read_mesh(out)
    inp = read_mesh(src)
    assert res.F.shape == inp.F.shape and np.isfinite(res.V).all()
    assert np.abs(res.V - inp.V).max() > 1e-3  # it did stylize


def test_progressive_target_above_size_is_refused(small_auto_threshold, capsys, tmp_path):
    # more coarse triangles than spot has (1,654): a plain error, nothing written
    out = tmp_path / "o.obj"
    code = cli.main(["cubic", str(shared_mesh("spot_lowres.obj")), "-o", str(out),
                     "--progressive-faces", "5000"])
    err = capsys.readouterr().err
    assert code == 5 and "larger than the mesh" in err
    assert not out.exists()


@pytest.mark.parametrize("command, extra", [("cubic", []), ("analogy", ["--style", "cube"])])
def test_no_progressive_and_explicit_progressive(small_auto_threshold, capsys, tmp_path,
                                                 command, extra):
    src = str(shared_mesh("spot_lowres.obj"))
    code = cli.main([command, src, "-o", str(tmp_path / "a.obj"), "--json", "--no-progressive",
                     *extra])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    d = json.loads(cap.out)
    assert d["progressive_faces"] is None and d["progressive_auto"] is False
    assert "progressive meshes" not in cap.err
    code = cli.main([command, src, "-o", str(tmp_path / "b.obj"), "--json",
                     "--progressive-faces", "800", *extra])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    d = json.loads(cap.out)
    assert d["progressive_faces"] == 800 and d["progressive_auto"] is False
    code = cli.main([command, src, "-o", str(tmp_path / "c.obj"), "--no-progressive",
                     "--progressive-faces", "800", *extra])
    assert code == 5 and "contradict" in capsys.readouterr().err


def test_a_one_sided_mesh_runs_where_no_orientation_is_needed_and_clean_cuts_it(
        capsys, tmp_path):
    """Issue 38: a one-sided surface is not refused by the commands (cubic cubifies a Klein
    bottle, thesis Fig. 5.12); a method that needs an orientation says that --clean cuts it
    open, and with --clean it runs."""
    from algorithms.mesh import write_mesh
    from tests.conftest import mobius_strip

    V, F = mobius_strip(24)
    src = tmp_path / "strip.obj"
    write_mesh(src, V, F)
    assert cli.main(["cubic", str(src), "-o", str(tmp_path / "c.obj")]) == 0
    assert len(read_mesh(tmp_path / "c.obj").V) == len(V)  # as it is: not cut
    capsys.readouterr()
    code = cli.main(["smooth", str(src), "-o", str(tmp_path / "s.obj")])
    err = capsys.readouterr().err
    assert code != 0 and "--clean" in err and "one-sided" in err
    assert not (tmp_path / "s.obj").exists()
    assert cli.main(["smooth", str(src), "-o", str(tmp_path / "s.obj"), "--clean"]) == 0
    err = capsys.readouterr().err
    assert "Cut the one-sided surface open along" in err
    assert len(read_mesh(tmp_path / "s.obj").V) > len(V)
