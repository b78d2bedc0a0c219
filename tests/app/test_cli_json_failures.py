"""``--json``: a command prints exactly one JSON object on stdout, also when it fails before
its own output (issue 39, item 7): ``{"ok": false, "command", "error", "exit_code"}``."""

from __future__ import annotations

import json

import pytest

from tests.conftest import SAMPLES


def _run(capsys, argv):
    from app import cli

    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _one_object(out: str) -> dict:
    obj = json.loads(out)  # the whole of stdout is one JSON value
    assert isinstance(obj, dict)
    return obj


def test_an_unreadable_file(capsys, tmp_path):
    bad = tmp_path / "garbage.obj"
    bad.write_text("garbage\n")
    code, out, err = _run(capsys, ["info", str(bad), "--json"])
    assert code == 2
    obj = _one_object(out)
    assert obj == {"ok": False, "command": "info", "error": obj["error"], "exit_code": 2}
    assert "could not be read" in obj["error"] and obj["error"] in err


def test_a_missing_file_and_a_refused_batch(capsys, tmp_path):
    code, out, _ = _run(capsys, ["cubic", str(tmp_path / "nope.obj"), "-o",
                                 str(tmp_path / "o.obj"), "--json"])
    assert code == 2 and _one_object(out)["exit_code"] == 2
    code, out, _ = _run(capsys, ["batch", "cubic", str(SAMPLES / "blob.obj"), "-o",
                                 str(tmp_path / "out"), "--lambda", "0.2", "0.4", "--json"])
    obj = _one_object(out)
    assert code == 5 and obj["exit_code"] == 5 and obj["command"] == "batch"
    assert "one λ" in obj["error"]
    assert not (tmp_path / "out").exists()


def test_a_refusal_without_an_exception_still_gives_one_object(capsys, monkeypatch):
    from app import cli
    from app.cli.common import say

    def refuse(args):
        say("stylize3d info: the mesh is fine but something else is not.")
        return 4

    monkeypatch.setattr(cli, "cmd_info", refuse)
    code, out, _ = _run(capsys, ["info", str(SAMPLES / "blob.obj"), "--json"])
    assert code == 4
    assert _one_object(out) == {"ok": False, "command": "info", "exit_code": 4,
                                "error": "the mesh is fine but something else is not."}


def test_success_and_plain_mode_are_unchanged(capsys, tmp_path):
    code, out, _ = _run(capsys, ["info", str(SAMPLES / "blob.obj"), "--json"])
    obj = _one_object(out)
    assert code == 0 and obj["ok"] is True and "exit_code" not in obj
    bad = tmp_path / "garbage.obj"
    bad.write_text("garbage\n")
    code, out, err = _run(capsys, ["info", str(bad)])
    assert code == 2 and out == "" and "could not be read" in err


@pytest.mark.parametrize("argv", [["cubic", "{blob}", "-o", "{out}", "--lambda", "-1"],
                                  ["smooth", "{blob}", "-o", "{out}", "--iterations", "0"]])
def test_bad_parameters(capsys, tmp_path, argv):
    argv = [a.replace("{blob}", str(SAMPLES / "blob.obj")).replace("{out}",
                                                                    str(tmp_path / "o.obj"))
            for a in argv] + ["--json"]
    code, out, _ = _run(capsys, argv)
    obj = _one_object(out)
    assert code == 5 and obj["ok"] is False and obj["exit_code"] == 5 and obj["error"]
    assert not (tmp_path / "o.obj").exists()


def test_version(tmp_path):
    """``stylize3d --version`` (issue 39, item 10): the installed package's version, exit 0,
    no window."""
    import subprocess
    import sys

    import app
    from tests.conftest import ROOT

    p = subprocess.run([sys.executable, "-m", "app", "--version"], cwd=ROOT, timeout=60,
                       capture_output=True, text=True, env={"PATH": "/usr/bin:/bin",
                                                            "HOME": str(tmp_path)})
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == f"stylize3d {app.__version__}"


def test_info_says_ok_only_when_it_exits_0(capsys, tmp_path):
    """A mesh with inconsistently oriented triangles: valid, but every method wants it cleaned
    first: exit 4 and ``"ok": false`` (it said ``true`` before; issue 39, item 9)."""
    from algorithms.mesh import icosphere, write_mesh

    V, F = icosphere(1)
    F = F.copy()
    F[0] = F[0, ::-1]
    path = tmp_path / "flipped.obj"
    write_mesh(path, V, F)
    code, out, _ = _run(capsys, ["info", str(path), "--json"])
    obj = _one_object(out)
    assert code == 4 and obj["needs_cleaning"] is True
    assert obj["ok"] is False and obj["valid"] is True
    code, out, _ = _run(capsys, ["info", str(SAMPLES / "blob.obj"), "--json"])
    assert code == 0 and _one_object(out)["ok"] is True
