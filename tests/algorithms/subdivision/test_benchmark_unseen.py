"""benchmarks/subdivision_ablation.py --unseen (issue 36 item 3): the evaluation on shapes
nobody trained on -- which meshes it takes, that an excluded mesh does not change the others'
coarse meshes, and one small end-to-end table (two shared meshes, few samples)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import load_benchmark

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "tests" / "data"


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("subdivision_ablation")


def _args(tmp: Path, shared: Path, **kw):
    base = dict(corpus="", shared=str(shared), exclude="", out=str(tmp / "out"), compare=None,
                modes="guard,scale", author_off=False, samples=2_000, json_out="")
    base.update(kw)
    return argparse.Namespace(**base)


def _shared(tmp: Path, names) -> Path:
    d = tmp / "shared"
    d.mkdir(exist_ok=True)
    for n in names:
        shutil.copy(DATA / n, d / n)
    return d


def test_exclusion_keeps_the_other_coarse_meshes(bench, tmp_path):
    shared = _shared(tmp_path, ["hand_lowres.obj", "spot_lowres.obj"])
    items, refused = bench._unseen_meshes(_args(tmp_path, shared), tmp_path / "a")
    names = [i[0] for i in items]
    assert names == ["hand_lowres.obj", "spot_lowres.obj"]
    # every other shared mesh is simply not there: named as such
    assert refused["armadillo.obj"] == "not found"
    for _, V, F, Vc, Fc in items:
        assert 350 * 0.6 <= len(Vc) <= 450 * 1.5 and len(Vc) < len(V)
    ex, _ = bench._unseen_meshes(_args(tmp_path, shared, exclude="hand_lowres"),
                                 tmp_path / "b")
    assert [i[0] for i in ex] == ["spot_lowres.obj"]
    np.testing.assert_array_equal(ex[0][3], items[1][3])  # spot's draw did not move


def test_a_coarse_mesh_far_from_the_count_is_refused(bench, tmp_path):
    shared = _shared(tmp_path, ["hand_lowres.obj"])
    out = tmp_path / "out"
    bench._unseen_meshes(_args(tmp_path, shared), out)
    c = out / "unseen_coarse" / "hand_lowres.obj.npz"
    z = dict(np.load(c))
    keep = np.unique(z["cF"][:20])  # a 'coarse mesh' of a few vertices
    remap = np.full(len(z["cV"]), -1)
    remap[keep] = np.arange(len(keep))
    np.savez(c, V=z["V"], F=z["F"], cV=z["cV"][keep], cF=remap[z["cF"][:20]])
    items, refused = bench._unseen_meshes(_args(tmp_path, shared), out)
    assert not items and "QSlim stopped at" in refused["hand_lowres.obj"]


def test_table_end_to_end(bench, tmp_path, capsys):
    if not (bench.REF / "author_network" / "netparams.dat").exists():
        pytest.skip("the author's network is not here")
    shared = _shared(tmp_path, ["hand_lowres.obj", "spot_lowres.obj"])
    out = tmp_path / "fig.json"
    args = _args(tmp_path, shared, json_out=str(out))
    assert bench.unseen_table(args) == 0
    text = capsys.readouterr().out
    assert "| hand_lowres |" in text and "| mean |" in text
    assert "shipped guard: mean H" in text and "below the author's network (scale) on H" in text
    res = json.loads(out.read_text())
    assert res["meshes"] == ["hand_lowres.obj", "spot_lowres.obj"]
    for method in ("shipped guard", "shipped scale", "author scale", "Loop", "butterfly"):
        for m in res["meshes"]:
            r = res["results"][method][m]
            assert 0 < r["M"] < r["H"] < 20
    # the second run reads the cache: the same figures
    assert bench.unseen_table(args) == 0
    assert json.loads(out.read_text())["results"] == res["results"]
