"""Issue 39 item 5: UVs, normals and materials are kept where the triangles are kept, split
with them by subdivision, and never dropped without a word (line, --json, batch record)."""

from __future__ import annotations

import json

import numpy as np

from algorithms.mesh import read_mesh
from algorithms.mesh.attributes import read_attributes
from app.cli import main
from tests.conftest import ROOT

BOB = ROOT / "tests" / "data" / "bob.obj"   # a textured OBJ: 5,3xx UVs, normals, a material


def _attrs(path):
    m = read_mesh(path)
    return m, read_attributes(path, len(m.V), len(m.F))


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):out.rindex("}") + 1])


def test_cubic_keeps_uvs_materials_and_gives_new_normals(tmp_path, capsys):
    m0, a0 = _attrs(BOB)
    assert a0 is not None and a0.uv is not None and a0.normals and a0.material_names
    out = tmp_path / "bob-cubic.obj"
    assert main(["cubic", str(BOB), "-o", str(out), "--max-iterations", "3", "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["surface_attributes"]["kept"] is True
    m1, a1 = _attrs(out)
    np.testing.assert_array_equal(m1.F, m0.F)
    assert np.abs(m1.V - m0.V).max() > 0            # the shape moved ...
    np.testing.assert_array_equal(a1.uv, a0.uv)       # ... the UVs did not
    assert a1.material_names == a0.material_names and a1.mtllib == a0.mtllib and a1.normals


def test_subdivision_splits_the_uvs_and_a_format_without_uvs_says_so(tmp_path, capsys):
    _, a0 = _attrs(BOB)
    for method in ("loop", "butterfly"):
        out = tmp_path / f"bob-{method}.obj"
        assert main(["subdivide", str(BOB), "-o", str(out), "--method", method,
                     "--levels", "1"]) == 0
        assert "kept bob.obj's texture coordinates" in capsys.readouterr().err
        m1, a1 = _attrs(out)
        assert a1.uv.shape == (4 * len(a0.uv), 3, 2) and np.isfinite(a1.uv).all()
        # every child's UV triangle is a quarter of its parent's: the UVs were split, not moved
        def areas(uv):
            d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
            return np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / 2
        np.testing.assert_allclose(areas(a1.uv).sum(), areas(a0.uv).sum(), rtol=1e-9)
    ply = tmp_path / "bob.ply"
    assert main(["subdivide", str(BOB), "-o", str(ply), "--method", "loop", "--levels", "1",
                 "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["surface_attributes"]["kept"] is False
    assert "cannot hold them" in rep["surface_attributes"]["note"]


def test_a_method_that_remakes_the_triangles_says_what_it_dropped(tmp_path):
    from app.cli.attributes import carried_attributes

    m0, _ = _attrs(BOB)
    attrs, status = carried_attributes(BOB, m0, "Paparazzi remakes the triangles when it "
                                       "remeshes, so they have nowhere to go", tmp_path / "x.obj")
    assert attrs is None and status["kept"] is False
    assert status["note"].startswith("bob.obj's texture coordinates (UVs), normals, 1 material "
                                     "were dropped: Paparazzi remakes")


def test_batch_keeps_them_and_its_record_says_so(tmp_path):
    import shutil

    from app import batch

    lib = tmp_path / "lib"
    lib.mkdir()
    shutil.copy(BOB, lib / "bob.obj")
    job, _args = batch.parse_batch_args("smooth", [str(lib), "-o", str(tmp_path / "out")])
    s = batch.run_batch(job, [lib / "bob.obj"], tmp_path / "out", workers=1)
    assert s.done == 1
    rec = next(r for k, r in batch.read_report(tmp_path / "out" / "batch-report.jsonl").items()
               if k != "__task_ids__")
    assert rec["surface_attributes"]["kept"] is True and "kept bob.obj's" in rec["notes"][-1]
    _, a0 = _attrs(BOB)
    _, a1 = _attrs(tmp_path / "out" / "bob.obj")
    np.testing.assert_array_equal(a1.uv, a0.uv)


def test_ply_vertex_colours_are_kept_where_the_vertices_are(tmp_path, capsys):
    from algorithms.mesh import write_mesh
    from algorithms.mesh.io import ply_colors
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    C = np.clip(np.abs(V), 0, 1)
    src = tmp_path / "coloured.ply"
    write_mesh(src, V, F, vertex_colors=C)
    for ext in ("ply", "obj"):
        out = tmp_path / f"smooth.{ext}"
        assert main(["smooth", str(src), "-o", str(out)]) == 0
        assert "kept coloured.ply's vertex colours" in capsys.readouterr().err
        m = read_mesh(out)
        got = read_attributes(out, len(m.V), len(m.F)).vertex_colors if ext == "obj" else \
            ply_colors(out.read_bytes())[1]
        np.testing.assert_allclose(got, np.round(C * 255) / 255, atol=1e-6)
    out = tmp_path / "sub.ply"
    assert main(["subdivide", str(src), "-o", str(out), "--method", "loop", "--levels", "1"]) == 0
    assert "vertex colours were dropped: subdivision does not carry" in capsys.readouterr().err
