"""CLI `stylize3d adversary`: JSON keys, outputs, plain errors (no traceback)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from algorithms.adversarial.shapes import SUBJECTS  # noqa: E402
from algorithms.mesh import read_mesh, write_mesh  # noqa: E402
from app.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def mug(tmp_path_factory):
    V, F, _ = SUBJECTS["coffee mug"]()
    path = tmp_path_factory.mktemp("adv") / "mug.obj"
    write_mesh(path, V, F)
    return path


def test_lighting_attack_json_and_lighting_file(mug, tmp_path, capsys):
    out = tmp_path / "light.json"
    code = main(["adversary", str(mug), "--mode", "lighting", "--views", "2", "--iterations", "1",
                 "--color", "0.93", "0.93", "0.9", "--label", "coffee mug", "-o", str(out),
                 "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    rep = json.loads(captured.out)
    assert set(rep) == {"views", "success_rate", "random_success_rate", "norm", "seconds"}
    assert len(rep["views"]) == 2
    assert set(rep["views"][0]) == {"label_before", "confidence_before", "label_after",
                                    "confidence_after", "success"}
    assert rep["views"][0]["label_before"] == "coffee mug"
    assert 0 < rep["norm"] <= 0.1 + 1e-12
    U = np.array(json.loads(out.read_text())["coefficients"])
    assert U.shape == (49, 3)
    # the written lighting starts the next attack (--lighting FILE.json); 0 iterations: the
    # views are classified under exactly that lighting
    from algorithms.adversarial.lighting_io import read_lighting

    np.testing.assert_array_equal(read_lighting(out), U)
    code = main(["adversary", str(mug), "--mode", "lighting", "--views", "1", "--iterations", "1",
                 "--lighting", str(out), "--label", "coffee mug", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert main(["adversary", str(mug), "--lighting", "Moonlight"]) == 5
    err = capsys.readouterr().err
    assert "Grace Cathedral" in err and "Traceback" not in err
    assert main(["adversary", str(mug), "--lighting", str(tmp_path / "missing.json")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_geometry_attack_writes_a_mesh_with_the_same_vertex_order(mug, tmp_path, capsys):
    out = tmp_path / "adv.obj"
    code = main(["adversary", str(mug), "--mode", "geometry", "--iterations", "1", "-o",
                 str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    a, b = read_mesh(mug), read_mesh(out)
    np.testing.assert_array_equal(a.F, b.F)
    size = (a.V.max(0) - a.V.min(0)).max()
    assert 0 < np.abs(b.V - a.V).max() <= 0.002 * size * (1 + 1e-5)
    assert "success rate" in capsys.readouterr().out


def test_plain_errors(mug, tmp_path, capsys):
    assert main(["adversary", str(mug), "--target", "cofee mug", "--iterations", "1"]) == 5
    err = capsys.readouterr().err
    assert "Did you mean" in err and "coffee mug" in err and "Traceback" not in err
    assert main(["adversary", str(mug), "-o", str(tmp_path / "x.obj")]) == 5
    assert ".json" in capsys.readouterr().err
    bad = tmp_path / "model.pt"
    bad.write_text("not a model")
    assert main(["adversary", str(mug), "--classifier", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "not a model file" in err and "Traceback" not in err
