"""Issue 39 item 11: ``stylize3d batch steps.toml INPUT... -o OUT``: each input through the
steps in order, equal to the commands run one after another by hand, resumable per step."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from algorithms.errors import Stylize3DError
from algorithms.mesh import read_mesh
from algorithms.mesh.attributes import read_attributes
from app.cli import main
from tests.conftest import ROOT, SAMPLES

STEPS = """
[[steps]]
command = "clean"

[[steps]]
command = "subdivide"
params = {{ method = "loop", levels = 1 }}

[[steps]]
command = "cubic"
params = {{ lam = {lam}, max_iterations = 5 }}
"""


def _records(path):
    return [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()]


@pytest.fixture
def lib(tmp_path):
    d = tmp_path / "lib"
    d.mkdir()
    shutil.copy(SAMPLES / "blob.obj", d)
    shutil.copy(ROOT / "tests" / "data" / "bob.obj", d)   # textured: UVs, normals, material
    return d


def test_steps_equal_the_commands_by_hand_and_resume_per_step(tmp_path, lib, capsys):
    steps = tmp_path / "steps.toml"
    steps.write_text(STEPS.format(lam=0.3))
    out = tmp_path / "out"
    assert main(["batch", str(steps), str(lib), "-o", str(out), "--workers", "1",
                 "--quiet"]) == 0
    # by hand: clean, subdivide, cubic, each reading the previous result
    h = tmp_path / "hand"
    h.mkdir()
    for name in ("blob.obj", "bob.obj"):
        assert main(["clean", str(lib / name), "-o", str(h / f"1-{name}")]) == 0
        assert main(["subdivide", str(h / f"1-{name}"), "-o", str(h / f"2-{name}"),
                     "--method", "loop", "--levels", "1"]) == 0
        assert main(["cubic", str(h / f"2-{name}"), "-o", str(h / f"3-{name}"), "--lambda",
                     "0.3", "--max-iterations", "5"]) == 0
        a, b = read_mesh(h / f"3-{name}"), read_mesh(out / name)
        np.testing.assert_array_equal(a.V, b.V)
        np.testing.assert_array_equal(a.F, b.F)
    capsys.readouterr()
    recs = {r["input"].rsplit("/", 1)[1]: r for r in _records(out / "batch-report.jsonl")}
    assert all(r["status"] == "done" and r["recipe"] == "clean > subdivide > cubic"
               and r["steps_reused"] == [] for r in recs.values())
    assert [s["step"] for s in recs["bob.obj"]["figures"]["steps"]] == ["clean", "subdivide",
                                                                         "cubic"]
    # the textured input kept its UVs through the steps (split by the subdivision)
    m0, m1 = read_mesh(lib / "bob.obj"), read_mesh(out / "bob.obj")
    a0 = read_attributes(lib / "bob.obj", len(m0.V), len(m0.F))
    a1 = read_attributes(out / "bob.obj", len(m1.V), len(m1.F))
    assert a1.uv.shape == (4 * len(a0.uv), 3, 2) and "kept bob.obj's" in \
        recs["bob.obj"]["notes"][-1]
    # the same command again: everything skipped
    assert main(["batch", str(steps), str(lib), "-o", str(out), "--workers", "1",
                 "--quiet"]) == 0
    assert [r["status"] for r in _records(out / "batch-report.jsonl")[-2:]] == ["skipped"] * 2
    # the last step's settings change: only it runs again, from the kept results of steps 1-2
    steps.write_text(STEPS.format(lam=0.5))
    assert main(["batch", str(steps), str(lib), "-o", str(out), "--workers", "1", "--quiet",
                 "--overwrite"]) == 0
    last = _records(out / "batch-report.jsonl")[-2:]
    assert [r["status"] for r in last] == ["done", "done"]
    assert all(r["steps_reused"] == [1, 2] for r in last), last
    assert main(["cubic", str(h / "2-blob.obj"), "-o", str(h / "3b-blob.obj"), "--lambda",
                 "0.5", "--max-iterations", "5"]) == 0
    np.testing.assert_array_equal(read_mesh(h / "3b-blob.obj").V, read_mesh(out / "blob.obj").V)


@pytest.mark.parametrize("text, words", [
    ("", "lists no steps"),
    ('[[steps]]\ncommand = "cubc"\n', "unknown command 'cubc'"),
    ('[[steps]]\ncommand = "cubic"\nparams = { lamda = 0.3 }\n', "lamda is not a setting"),
    ('[[steps]]\ncommand = "clean"\nparams = { x = 1 }\n', "clean takes no params"),
    ('[[steps]\n', "cannot be read as TOML"),
])
def test_a_bad_step_file_gets_a_plain_message(tmp_path, text, words):
    from app.batch.pipeline import read_pipeline

    p = tmp_path / "steps.toml"
    p.write_text(text)
    with pytest.raises(Stylize3DError, match=words):
        read_pipeline(p)


def test_a_step_that_cannot_take_the_mesh_says_which_step_and_what_to_add(tmp_path, capsys):
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    lib = tmp_path / "lib"
    lib.mkdir()
    write_mesh(lib / "doubled.obj", np.concatenate([V, V]), np.concatenate([F, F + len(V)]))
    steps = tmp_path / "steps.toml"
    steps.write_text('[[steps]]\ncommand = "smooth"\n')
    assert main(["batch", str(steps), str(lib), "-o", str(tmp_path / "out"), "--workers", "1",
                 "--quiet"]) == 1
    (r,) = _records(tmp_path / "out" / "batch-report.jsonl")
    assert r["status"] == "failed" and r["category"] == "invalid mesh"
    assert "Add a clean step before it" in r["message"] or "clean" in r["message"], r["message"]
    steps.write_text('[[steps]]\ncommand = "clean"\n\n[[steps]]\ncommand = "smooth"\n')
    assert main(["batch", str(steps), str(lib), "-o", str(tmp_path / "out"), "--workers", "1",
                 "--quiet"]) == 0  # the advice works
