"""benchmarks/corpus.py (issue 38): its classes on synthetic outcomes, its fold and spike
measures on made-up damage, and one end-to-end run of a folder of two small meshes (one of
them broken so that the advice to clean is followed), without pictures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from algorithms.mesh import cube, icosphere, write_mesh
from tests.conftest import load_benchmark

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def corpus():
    return load_benchmark("corpus")


def test_classes(corpus):
    c = corpus._classify
    ok = {"moved": 0.05, "faces_out": 100}
    assert c(None, 300, "", {}, None, True, 10, 300)[0] == "over time"
    assert c(70, 1, "stylize3d: an unexpected error", {}, None, True, 10, 300)[0] == "crash"
    assert c(-11, 1, "", {}, None, True, 10, 300)[0] == "crash"
    assert c(0, 1, "Traceback (most recent call last)", {}, ok, True, 10, 300)[0] == "crash"
    assert c(3, 1, "x cannot be processed", {}, None, True, 10, 300)[0] == "refused"
    assert c(0, 61, "", {}, ok, True, 10, 300)[0] == "over time"
    assert c(0, 61, "", {}, ok, True, 200_000, 300)[0] == "result"  # big meshes may take longer
    assert c(0, 1, "", {"method_used": "loop", "fallback": True}, ok, False, 10, 300)[0] == \
        "substitution"
    assert c(0, 1, "", {"runs": [{"fallback": True}]}, ok, False, 10, 300)[0] == "substitution"
    assert c(0, 1, "", {}, {"nan": True}, True, 10, 300)[0] == "artefact"
    assert c(0, 1, "", {}, {**ok, "degenerate_made": 3}, True, 10, 300)[0] == "artefact"
    assert c(0, 1, "", {}, {**ok, "folds_made": 1}, True, 10, 300)[0] == "artefact"
    assert c(0, 1, "", {}, {**ok, "folds_made": 1, "faces_out": 5000}, True, 10, 300)[0] == \
        "result"  # under 0.1 % of the triangles
    assert c(0, 1, "", {}, {**ok, "intersections_in": 2, "intersections_out": 3}, True, 10,
             300)[0] == "artefact"
    assert c(0, 1, "", {}, {**ok, "spike": 0.02}, True, 10, 300)[0] == "artefact"
    assert c(0, 1, "", {}, {"moved": 0.001}, True, 10, 300)[0] == "no effect"
    assert c(0, 1, "", {}, {"moved": 0.001}, False, 10, 300)[0] == "result"  # not a deformer
    assert c(0, 1, "", {}, ok, True, 10, 300)[0] == "result"


def test_the_setting_a_refusal_names_is_read(corpus):
    msg = ("This mesh has 280 vertices, and the coarse operator was to have 500 (--m, which "
           "must be fewer): ask for fewer: --m 140.")
    assert corpus.advised_setting(msg) == ["--m", "140"]
    assert corpus.advised_setting("use --step-size=0.001 instead") == ["--step-size", "0.001"]
    assert corpus.advised_setting("Run Clean first (stylize3d clean).") == []
    # settings named together are followed together; a later one in another clause is not
    msg = "This mesh has 1,740 separate parts ...: ask for --m 1750 --k 10 or more (one ..."
    assert corpus.advised_setting(msg) == ["--m", "1750", "--k", "10"]
    assert corpus.advised_setting("use --m 14, or --k 3") == ["--m", "14"]
    # a result's advice (smooth that barely moved the shape), with a value in e-notation
    msg = ("The shape changed little (at most 0.18 % of its size): it is already smooth at "
           "this step size. Raise --step-size (e.g. --step-size 1e-04) or --iterations to "
           "smooth more.")
    assert corpus.advised_setting(msg) == ["--step-size", "1e-04"]
    assert corpus.merge_settings(["--clean-x", "1", "--step-size", "1e-04"],
                                 ["--step-size", "1e-03"]) == ["--clean-x", "1",
                                                               "--step-size", "1e-03"]
    assert corpus.merge_settings([], ["--m", "81"]) == ["--m", "81"]


def test_folds_and_json_reading(corpus):
    V, F = icosphere(2)
    assert not corpus._folds_made(V, V, F).any()
    ring = np.unique(F[(F == 0).any(axis=1)])
    ring = ring[ring != 0]
    W = V.copy()
    W[0] += 2.0 * (V[ring[0]] - V[0])  # dragged past a neighbour: the far triangles fold over
    folded = np.flatnonzero(corpus._folds_made(V, W, F))
    assert folded.size == 2 and (F[folded] == 0).any(axis=1).all()
    W = V.copy()
    W[0] *= 0.5  # a deep pit is not a fold
    assert not corpus._folds_made(V, W, F).any()
    # a thin plate (a CAD part's wall): its rims' neighbourhoods face both ways, and a jitter
    # of a tenth of its thickness turns no triangle back (the first definition, "the normal
    # points away from the area-weighted normal of the triangles around its corners", called
    # about a fifth of its triangles folded here, and 18 of a tray's that turned by < 0.2 deg)
    P, G = cube(2)
    P = P * np.array([1.0, 1.0, 0.002])
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert not corpus._folds_made(P, P + rng.normal(scale=2e-4, size=P.shape), G).any()
    Q = P.copy()
    top = np.flatnonzero(P[:, 2] > 0)
    inner = top[(np.abs(P[top, 0]) < 0.9) & (np.abs(P[top, 1]) < 0.9)]
    Q[inner[0], 0] += 1.0  # dragged past its neighbour in the plane: triangles turn over
    folded = corpus._folds_made(P, Q, G)
    assert folded.any() and (G[folded] == inner[0]).any(axis=1).all()
    text = "progress\n{\n  \"a\": 1,\n  \"fallback\": true\n}\n"
    assert corpus._last_json(text) == {"a": 1, "fallback": True}
    assert corpus._last_json('x\n{"b": 2}\n') == {"b": 2} and corpus._last_json("none") == {}


def test_a_small_folder_end_to_end(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    V, F = icosphere(3)
    rng = np.random.default_rng(0)
    W = V + 0.03 * rng.standard_normal(V.shape)
    write_mesh(folder / "ball.obj", W, F)
    write_mesh(folder / "loose.obj", np.vstack([W, [[4.0, 4.0, 4.0]]]), F)  # an unused vertex
    write_mesh(folder / "small.obj", *icosphere(2))   # 162 vertices: coarsen asks for fewer
    out = tmp_path / "corpus.md"
    records = tmp_path / "records.json"
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "corpus.py"), "--corpus",
                        str(folder), "--methods", "smooth,coarsen", "--jobs", "2",
                        "--no-pictures",
                        "--out", str(out), "--json", str(records), "--work",
                        str(tmp_path / "work")], cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    recs = {(r["mesh"], r["method"]): r for r in json.loads(records.read_text())}
    ball, loose = recs["ball.obj", "smooth"], recs["loose.obj", "smooth"]
    assert ball["kind"] == "result" and ball["exit"] == 0
    assert loose["kind"] == "advice works" and loose["clean"]
    # coarsen's default (500 coarse nodes) on 162 vertices is refused with the value to use,
    # and that value works
    small = recs["small.obj", "coarsen"]
    assert small["kind"] == "advice works" and small["advice"] == "--m 81", small
    assert "--m 81" in small["refusal"] and not small["clean"]
    assert recs["ball.obj", "coarsen"]["kind"] == "result"
    page = out.read_text()
    assert "| ball.obj | 1,280 | ok | ok |" in page
    # (the smooth ball is already smooth: no visible effect)
    assert "| loose.obj | 1,280 | ok* |" in page and "| small.obj | 320 | - | ok* |" in page
    assert "| smooth | 1 | 1 | 0 | 1 |" in page and "| coarsen | 1 | 2 | 0 | 0 |" in page
    assert str(tmp_path) not in page
