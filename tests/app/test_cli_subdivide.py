"""CLI of neural subdivision: subdivide, subdivide-train, subdivide-eval (a separate process)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from tests.conftest import ROOT

HAND = ROOT / "tests" / "data" / "hand_lowres.obj"
SPOT = ROOT / "tests" / "data" / "spot_lowres.obj"


def stylize3d(*args, timeout=300, env=None):
    import os

    e = dict(os.environ, OMP_NUM_THREADS="1")
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "app", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=e)


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    d = tmp_path_factory.mktemp("train")
    w = d / "w.pt"
    r = stylize3d("subdivide-train", SPOT, "-o", w, "--coarse-meshes", 2, "--epochs", 2,
                  "--min-vertices", 60, "--max-vertices", 80, "--workers", 1,
                  "--cache-dir", d / "cache", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["coarse_meshes"] == 2 and out["epochs"] == 2
    assert out["best_epoch"] in (1, 2) and out["best_validation_loss"] > 0
    assert out["stopped_early"] is False and out["seconds_data"] >= 0
    assert "Traceback" not in r.stderr
    return w


@pytest.mark.parametrize("method", ["loop", "butterfly", "midpoint"])
def test_subdivide_baselines(tmp_path, method):
    out = tmp_path / "o.obj"
    r = stylize3d("subdivide", HAND, "-o", out, "--method", method, "--levels", 1, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    m = read_mesh(out)
    assert d["faces"] == len(m.F) == 4 * 1602 and d["method"] == method


def test_subdivide_neural_with_trained_weights_and_overwrite(tmp_path, weights):
    out = tmp_path / "n.obj"
    r = stylize3d("subdivide", HAND, "-o", out, "--weights", weights, "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["faces"] == 16 * 1602
    V = read_mesh(out).V
    assert np.isfinite(V).all()
    r = stylize3d("subdivide", HAND, "-o", out, "--weights", weights)
    assert r.returncode == 3 and "--overwrite" in r.stderr


def test_subdivide_plain_errors(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00garbage")
    r = stylize3d("subdivide", HAND, "-o", tmp_path / "x.obj", "--weights", bad)
    assert r.returncode == 2 and "not a Stylize3D" in r.stderr and "Traceback" not in r.stderr
    r = stylize3d("subdivide", HAND, "-o", tmp_path / "x.obj", "--levels", 5,
                  "--method", "loop")
    assert r.returncode == 5 and "levels" in r.stderr
    assert not (tmp_path / "x.obj").exists()


def test_subdivide_eval_json_keys(weights):
    r = stylize3d("subdivide-eval", weights, SPOT, "--samples", 5000, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for m in ("neural", "loop", "butterfly"):
        assert set(d["methods"][m]) == {"hausdorff", "mean_distance"}
        assert d["methods"][m]["hausdorff"] > 0
    assert 350 <= d["meshes"][0]["coarse_vertices"] <= 450
    r = stylize3d("subdivide-eval", weights, SPOT, "--target-vertices", "450-350")
    assert r.returncode == 5 and "350-450" in r.stderr
