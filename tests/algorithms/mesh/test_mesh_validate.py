"""Tests for algorithms.mesh.validate: validate_mesh, MeshReport, clean_mesh."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from algorithms.errors import InvalidMeshError, MeshReadError, ParameterError
from algorithms.mesh.io import read_mesh
from algorithms.mesh.operators import signed_volume
from algorithms.mesh.primitives import cube, grid, icosphere, torus
from algorithms.mesh.validate import CleanResult, MeshIssue, MeshReport, clean_mesh, validate_mesh
from tests.conftest import mobius_strip, shared_mesh


# name -> (V, F, genus, boundary loops) from SOURCES.md
SHARED_TOPOLOGY = {
    "hand_lowres.obj": (810, 1602, 0, 1),
    "spot_lowres.obj": (829, 1654, 0, 0),
    "wingnut.obj": (3047, 6090, 0, 0),
    "fertility.off": (4494, 9000, 4, 0),
    "bob.obj": (5344, 10688, 1, 0),
    "fandisk.off": (7229, 14454, 0, 0),
    "rocker-arm.obj": (10044, 20088, 1, 0),
    "camelhead.off": (11381, 22704, 0, 1),
    "armadillo.obj": (14587, 29170, 0, 0),
    "stanford-bunny.obj": (35947, 69451, 0, 5),
    "koala.obj": (49999, 99994, 0, 0),
    "igea.ply": (134345, 268686, 0, 0),
}


def codes(report):
    return set(report.codes)


def soup_cube():
    """A cube whose six faces each have their own four corner vertices (24 vertices)."""
    V, F = cube()
    V2 = V[F].reshape(-1, 3)  # 36 corners ...
    F2 = np.arange(36).reshape(-1, 3)
    # ... then merge within each face pair of triangles only (keep 4 corners per square face)
    normals = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    side = np.argmax(np.abs(normals), axis=1) * 2 + (normals.max(axis=1) > 0)
    key = np.column_stack([np.repeat(side, 3), V2])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return V2[first], inverse.ravel()[F2]


def three_triangles_on_one_edge():
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], float)
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    return V, F


# --------------------------------------------------------------------------------------------
# bad inputs as files
# --------------------------------------------------------------------------------------------


def test_empty_file(tmp_path):
    (tmp_path / "empty.obj").write_bytes(b"")
    with pytest.raises(MeshReadError, match="is empty"):
        read_mesh(tmp_path / "empty.obj")


def test_random_bytes_file(tmp_path):
    (tmp_path / "noise.obj").write_bytes(np.random.default_rng(7).bytes(2000))
    with pytest.raises(MeshReadError, match="could not be read as an OBJ file"):
        read_mesh(tmp_path / "noise.obj")


def test_obj_with_nan_coordinate(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")
    mesh = read_mesh(path)
    report = validate_mesh(mesh.V, mesh.F, mesh.notes)
    issue = report.get("nonfinite")
    assert issue is not None and issue.severity == "error" and not issue.fixable
    assert issue.count == 1 and issue.indices.tolist() == [1]
    assert "invalid coordinates (NaN or infinity)" in issue.message and "vertex 1" in issue.message
    assert not report.ok


def test_unused_nan_vertex_is_fixable(tmp_path):
    V, F = icosphere(1)
    V = np.vstack([V, [[np.nan, 0, 0]]])
    report = validate_mesh(V, F)
    issue = report.get("nonfinite")
    assert issue.fixable and "'Clean' can simply delete it" in issue.message
    assert report.needs_cleaning
    res = clean_mesh(V, F)
    assert np.isfinite(res.V).all() and res.V.shape[0] == V.shape[0] - 1
    assert any("invalid coordinates" in a for a in res.actions)
    assert validate_mesh(res.V, res.F).ok


def test_obj_with_out_of_range_index(tmp_path):
    path = tmp_path / "oor.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 9\nf 1 4 3\n")
    mesh = read_mesh(path)
    report = validate_mesh(mesh.V, mesh.F)
    issue = report.get("index_out_of_range")
    assert issue.severity == "error" and not issue.fixable
    assert issue.count == 1 and issue.indices.tolist() == [2]
    assert "do not exist" in issue.message and "triangle 2 uses 8" in issue.message
    assert "numbered 0 to 3" in issue.message
    with pytest.raises(InvalidMeshError, match="remove invalid faces"):
        clean_mesh(mesh.V, mesh.F)
    res = clean_mesh(mesh.V, mesh.F, remove_invalid_faces=True)
    assert res.F.shape[0] == 3
    assert res.actions[0] == "Removed 1 triangle that referred to vertices that do not exist."
    assert validate_mesh(res.V, res.F).ok


def test_nonmanifold_mesh_file(tmp_path):
    V, F = three_triangles_on_one_edge()
    path = tmp_path / "fin.off"
    path.write_text("OFF\n5 3 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))
    mesh = read_mesh(path)
    report = validate_mesh(mesh.V, mesh.F)
    issue = report.get("nonmanifold_edges")
    assert issue.severity == "error" and issue.fixable and issue.count == 1
    assert issue.indices.tolist() == [[0, 1]]
    assert issue.message == (
        "1 edge is shared by more than two triangles (non-manifold). Methods need every edge to "
        "touch one or two triangles. 'Clean' can remove the extra triangles."
    )
    assert report.stats["manifold"] is False and report.stats["genus"] is None
    res = clean_mesh(mesh.V, mesh.F)
    assert res.F.shape[0] == 2
    np.testing.assert_array_equal(res.face_map, [0, 1])  # keeps one face per direction
    assert any("every edge touches at most two triangles" in a for a in res.actions)
    after = validate_mesh(res.V, res.F)
    assert after.ok and not after.needs_cleaning


def test_duplicate_vertices_cube_file(tmp_path):
    V, F = soup_cube()
    assert V.shape == (24, 3) and F.shape == (12, 3)
    path = tmp_path / "soup.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    mesh = read_mesh(path)
    report = validate_mesh(mesh.V, mesh.F)
    issue = report.get("duplicate_vertices")
    assert issue.severity == "warning" and issue.fixable and issue.count == 16
    assert "same position as another vertex" in issue.message and "'Clean' can merge them" in issue.message
    assert report.stats["components"] == 6 and report.stats["boundary_loops"] == 6
    res = clean_mesh(mesh.V, mesh.F)
    assert res.actions == ["Merged 16 duplicate vertices.", "Removed 16 unused vertices."]
    assert res.V.shape == (8, 3) and res.F.shape == (12, 3)
    after = validate_mesh(res.V, res.F)
    assert after.stats["closed"] and after.stats["genus"] == 0 and not after.needs_cleaning
    # vertex_map sends every copy to its merged vertex
    np.testing.assert_array_equal(res.V[res.vertex_map], mesh.V)


# --------------------------------------------------------------------------------------------
# individual checks
# --------------------------------------------------------------------------------------------


def test_clean_mesh_reports_nothing_to_fix():
    V, F = torus()
    report = validate_mesh(V, F)
    assert report.ok and not report.needs_cleaning
    assert codes(report) == {"genus"}
    res = clean_mesh(V, F)
    assert isinstance(res, CleanResult)
    assert res.actions == ["Nothing to fix: the mesh is clean."]
    np.testing.assert_array_equal(res.V, V)
    np.testing.assert_array_equal(res.F, F)
    np.testing.assert_array_equal(res.vertex_map, np.arange(V.shape[0]))
    np.testing.assert_array_equal(res.face_map, np.arange(F.shape[0]))


def test_bad_shape_and_empty():
    r = validate_mesh(np.zeros((4, 3)), np.array([[0, 1, 2, 3]]))
    assert codes(r) == {"bad_shape"} and "split polygons into triangles" in r.errors[0].message
    r = validate_mesh(np.zeros((4, 2)), np.array([[0, 1, 2]]))
    assert codes(r) == {"bad_shape"} and "(x, y, z)" in r.errors[0].message
    r = validate_mesh(np.zeros((4, 3)), np.array([[0, 1.5, 2]]))
    assert codes(r) == {"bad_shape"} and "whole-number" in r.errors[0].message
    r = validate_mesh([["a", "b", "c"]], [[0, 0, 0]])
    assert codes(r) == {"bad_shape"}
    r = validate_mesh(np.zeros((0, 3)), np.zeros((0, 3), int))
    assert codes(r) == {"empty"} and "no vertices and no triangles" in r.errors[0].message
    r = validate_mesh(np.zeros((3, 3)), np.zeros((0, 3), int))
    assert codes(r) == {"empty"} and not r.ok
    with pytest.raises(InvalidMeshError, match="empty"):
        clean_mesh(np.zeros((3, 3)), np.zeros((0, 3), int))
    with pytest.raises(InvalidMeshError, match="cannot be cleaned"):
        clean_mesh(np.zeros((3, 3)), np.zeros((2, 4), int))


def test_repeated_degenerate_duplicate_faces():
    V, F = icosphere(1)
    n = V.shape[0]
    V = np.vstack([V, [[0, 0, 0], [1, 1, 1], [2, 2, 2]]])  # collinear points
    F = np.vstack([F, [[0, 0, 1]], [[n, n + 1, n + 2]], F[[3]], F[[4]][:, [1, 0, 2]]])
    r = validate_mesh(V, F)
    m0 = icosphere(1)[1].shape[0]
    assert r.get("repeated_index_in_face").indices.tolist() == [m0]
    assert r.get("degenerate_faces").indices.tolist() == [m0 + 1]
    assert r.get("duplicate_faces").indices.tolist() == [m0 + 2, m0 + 3]
    assert "zero area" in r.get("degenerate_faces").message
    assert all(r.get(c).fixable and r.get(c).severity == "warning" for c in ("repeated_index_in_face", "degenerate_faces", "duplicate_faces"))
    res = clean_mesh(V, F)
    assert res.actions == [
        "Removed 1 triangle that used the same vertex twice.",
        "Removed 1 degenerate triangle (zero area).",
        "Removed 2 duplicate triangles.",
        "Removed 3 unused vertices.",
    ]
    np.testing.assert_array_equal(res.F, icosphere(1)[1])


def test_unreferenced_vertices():
    V, F = grid(3, 3)
    V = np.vstack([V, [[9, 9, 9], [8, 8, 8]]])
    r = validate_mesh(V, F)
    issue = r.get("unreferenced_vertices")
    assert issue.count == 2 and issue.indices.tolist() == [16, 17] and issue.fixable
    assert "not used by any triangle" in issue.message
    res = clean_mesh(V, F)
    assert res.actions == ["Removed 2 unused vertices."]
    assert res.vertex_map[-2:].tolist() == [-1, -1]


def test_nonmanifold_vertex_is_split():
    # two tetrahedra sharing one vertex
    V1, F1 = cube()
    Vt = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V = np.vstack([Vt, -Vt[1:]])
    F = np.vstack([Ft, np.where(Ft == 0, 0, Ft + 3)])
    r = validate_mesh(V, F)
    issue = r.get("nonmanifold_vertices")
    assert issue.severity == "error" and issue.fixable and issue.indices.tolist() == [0]
    assert "touch only at that point" in issue.message
    res = clean_mesh(V, F)
    assert res.V.shape[0] == 8
    assert any(a.startswith("Split 1 non-manifold vertex into 2") for a in res.actions)
    after = validate_mesh(res.V, res.F)
    assert after.ok and not after.needs_cleaning
    # the two copies coincide but stay separate: reported as info, not fixable
    dup = after.get("duplicate_vertices")
    assert dup.severity == "info" and not dup.fixable
    assert after.stats["components"] == 2 and after.stats["genus"] == 0


def test_inconsistent_and_inward_orientation():
    V, F = icosphere(2)
    Fb = F.copy()
    Fb[:5] = Fb[:5][:, [0, 2, 1]]
    r = validate_mesh(V, Fb)
    issue = r.get("inconsistent_orientation")
    assert issue.fixable and issue.severity == "warning" and issue.count > 0
    assert issue.indices.shape[1] == 2
    res = clean_mesh(V, Fb)
    assert signed_volume(res.V, res.F) > 0
    np.testing.assert_array_equal(res.F, F)
    # fully inside-out
    r = validate_mesh(V, F[:, [0, 2, 1]])
    issue = r.get("inward_orientation")
    assert issue is not None and issue.fixable and "inside-out" in issue.message
    res = clean_mesh(V, F[:, [0, 2, 1]])
    assert res.actions == ["Flipped 1 closed part that was inside-out (320 triangles), so normals point outwards."]
    assert signed_volume(res.V, res.F) > 0
    res = clean_mesh(V, F[:, [0, 2, 1]], orient_outward=False)
    assert signed_volume(res.V, res.F) < 0


def _strip(n=16, twist=True):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    half = t / 2 if twist else 0 * t
    ring = lambda w: np.column_stack([(1 + w * np.cos(half)) * np.cos(t),
                                      (1 + w * np.cos(half)) * np.sin(t), w * np.sin(half)])
    V = np.vstack([ring(-0.3), ring(0.3)])
    F = []
    for i in range(n):
        a, b = i, n + i
        c, d = ((i + 1, n + i + 1) if i < n - 1 else ((n, 0) if twist else (0, n)))
        F += [[a, c, b], [b, c, d]]
    return V, np.array(F)


def test_a_one_sided_surface_is_cut_open_along_its_seam_by_clean():
    V, F = _strip()
    r = validate_mesh(V, F)
    issue = r.get("one_sided")
    assert issue is not None and issue.fixable and "one-sided" in issue.message
    assert r.needs_cleaning and not r.blocking  # methods that need no orientation still run
    assert r.stats["orientable"] is False and r.stats["genus"] is None
    assert r.stats["boundary_loops"] == 1  # a Moebius strip has one border
    res = clean_mesh(V, F)
    assert any(a.startswith("Cut the one-sided surface open along ") for a in res.actions)
    assert not any(a.startswith("Not fixed") for a in res.actions), res.actions
    after = validate_mesh(res.V, res.F)
    assert "one_sided" not in after and "inconsistent_orientation" not in after
    assert after.stats["orientable"] is True
    assert not after.errors and not after.warnings and not after.needs_cleaning
    # the same triangles, in place: only the seam's vertices got a second copy
    assert len(res.F) == len(F) and len(V) < len(res.V) <= len(V) + 4
    np.testing.assert_array_equal(res.V[: len(V)], V)
    np.testing.assert_allclose(np.sort(res.V[res.F].reshape(len(F), -1), axis=1),
                               np.sort(V[F].reshape(len(F), -1), axis=1))
    # the cut seam: copies at one position, kept apart (merging would make it one-sided)
    dup = after.get("duplicate_vertices")
    assert dup is not None and not dup.fixable and "one-sided" in dup.message
    # every edge of the result has its two triangles agreeing: a real orientation
    Fr = res.F
    half = np.concatenate([Fr[:, [0, 1]], Fr[:, [1, 2]], Fr[:, [2, 0]]])
    assert len({tuple(h) for h in half.tolist()}) == len(half)
    # cleaning again changes nothing (the seam is not welded back)
    again = clean_mesh(res.V, res.F)
    assert again.actions == ["Nothing to fix: the mesh is clean."]
    # a two-sided strip with mixed orientation is only re-oriented, never cut
    V2, F2 = _strip(twist=False)
    F2[::3] = F2[::3][:, [0, 2, 1]]
    res2 = clean_mesh(V2, F2)
    assert not any("Cut" in a for a in res2.actions) and len(res2.V) == len(V2)
    assert validate_mesh(res2.V, res2.F).stats["orientable"] is True


def test_infos_components_boundary_genus():
    V1, F1 = icosphere(1)
    V2, F2 = grid(2, 2)
    V = np.vstack([V1, V2 + 3])
    F = np.vstack([F1, F2 + V1.shape[0]])
    r = validate_mesh(V, F, notes=["2 quads were split into triangles (fan triangulation)."])
    assert r.ok and not r.needs_cleaning
    assert r.get("multiple_components").count == 2
    assert r.get("boundary").count == 1 and "8 edges" in r.get("boundary").message
    assert r.get("genus").count == 0
    assert r.get("file_note").message.startswith("2 quads")
    assert [i.severity for i in r.issues] == ["info"] * 4
    s = r.stats
    assert (s["vertices"], s["faces"], s["components"], s["boundary_loops"], s["boundary_edges"]) == (51, 88, 2, 1, 8)
    assert s["manifold"] and not s["closed"] and s["genus"] == 0
    assert s["euler"] == 2 + 1


def test_report_api_summary_and_json():
    V, F = three_triangles_on_one_edge()
    V = np.vstack([V, [[7, 7, 7]]])
    r = validate_mesh(V, F)
    assert isinstance(r, MeshReport)
    assert [i.code for i in r.errors] == ["nonmanifold_edges"]
    assert [i.code for i in r.warnings] == ["unreferenced_vertices"]
    assert "nonmanifold_edges" in r and "genus" not in r
    assert r.get("nope") is None
    text = r.summary()
    assert "Mesh: 6 vertices, 3 triangles" in text and "Errors:" in text and "Warnings:" in text
    assert "Use 'Clean'" in text
    d = r.to_dict()
    json.dumps(d)  # JSON-safe
    assert d["ok"] is False and d["needs_cleaning"] is True
    assert d["issues"][0]["indices"] == [[0, 1]]
    assert isinstance(d["stats"]["vertices"], int)
    ok = validate_mesh(*icosphere(0))
    assert "No problems found." in ok.summary() and "genus 0" in ok.summary()
    json.dumps(ok.to_dict())


def test_to_dict_truncates_indices():
    V, F = grid(10, 10)
    V = np.vstack([V, np.ones((30, 3)) * np.arange(30)[:, None]])
    d = validate_mesh(V, F).to_dict()
    issue = next(i for i in d["issues"] if i["code"] == "unreferenced_vertices")
    assert len(issue["indices"]) == 20 and issue["indices_truncated"] and issue["count"] == 30
    assert all(type(x) is int for x in issue["indices"])


def test_mesh_issue_rejects_unknown_severity():
    with pytest.raises(ValueError):
        MeshIssue("x", "fatal", "msg")


def test_weld_tolerance():
    V, F = soup_cube()
    rng = np.random.default_rng(0)
    Vn = V + rng.normal(scale=1e-7, size=V.shape)
    assert validate_mesh(Vn, F).get("duplicate_vertices") is None  # not exactly coincident
    res = clean_mesh(Vn, F, weld_tolerance=1e-5)
    assert res.V.shape == (8, 3)
    assert res.actions[0] == "Merged 16 nearby (closer than 1e-05) vertices."
    with pytest.raises(ParameterError):
        clean_mesh(Vn, F, weld_tolerance=-1)


def test_remove_invalid_faces_with_nan_corners():
    V, F = icosphere(1)
    V = V.copy()
    V[0] = np.nan
    assert not validate_mesh(V, F).get("nonfinite").fixable
    res = clean_mesh(V, F)
    assert res.actions[0] == "Nothing could be fixed automatically."
    assert res.actions[1].startswith("Not fixed: ") and "NaN" in res.actions[1]
    res = clean_mesh(V, F, remove_invalid_faces=True)
    assert np.isfinite(res.V).all()
    assert "Removed 5 triangles with corners at invalid" in res.actions[0]
    after = validate_mesh(res.V, res.F)
    assert after.ok and after.stats["boundary_loops"] == 1


# --------------------------------------------------------------------------------------------
# shared meshes
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SHARED_TOPOLOGY))
def test_validate_shared_meshes_match_sources(name):
    mesh = read_mesh(shared_mesh(name))
    r = validate_mesh(mesh.V, mesh.F, mesh.notes)
    nv, nf, g, loops = SHARED_TOPOLOGY[name]
    s = r.stats
    assert (s["vertices"], s["faces"], s["genus"], s["boundary_loops"]) == (nv, nf, g, loops)
    assert s["manifold"] and s["components"] == 1 and s["orientable"]
    assert s["closed"] == (loops == 0)
    assert r.ok
    expected = {"genus"} | ({"boundary"} if loops else set())
    if name == "stanford-bunny.obj":
        expected |= {"unreferenced_vertices"}
        assert r.get("unreferenced_vertices").count == 1113
        assert s["boundary_edges"] == 223
    if name == "camelhead.off":
        assert s["boundary_edges"] == 56
    assert codes(r) == expected
    assert s["total_area"] > 0 and s["diagonal"] > 0
    json.dumps(r.to_dict())


def test_validate_igea():
    # speed is measured in benchmarks/mesh_core.py
    mesh = read_mesh(shared_mesh("igea.ply"))
    r = validate_mesh(mesh.V, mesh.F)
    assert r.ok and not r.needs_cleaning
    assert r.stats["genus"] == 0 and r.stats["closed"] and r.stats["faces"] == 268686


def test_clean_bunny():
    mesh = read_mesh(shared_mesh("stanford-bunny.obj"))
    res = clean_mesh(mesh.V, mesh.F)
    assert res.actions == ["Removed 1,113 unused vertices."]
    assert res.V.shape == (34834, 3) and res.F.shape == mesh.F.shape
    keep = res.vertex_map >= 0
    np.testing.assert_array_equal(res.V[res.vertex_map[keep]], mesh.V[keep])


# --------------------------------------------------------------------------------------------
# property test: clean fixes random corruption
# --------------------------------------------------------------------------------------------

BASES = {"icosphere": icosphere(1), "torus": torus(n_major=10, n_minor=6), "grid": grid(4, 3)}


@st.composite
def corrupted_meshes(draw):
    name = draw(st.sampled_from(sorted(BASES)))
    V, F = (a.copy() for a in BASES[name])
    n, m = V.shape[0], F.shape[0]
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    kinds = draw(st.lists(st.sampled_from(["dupv", "fin", "flip", "unref", "degen", "repeat", "dupf"]), min_size=1, max_size=5))
    V_list, F_list = [V], [F]
    nv = n
    for kind in kinds:
        Fc = np.vstack(F_list)
        if kind == "dupv":  # copy some vertices and let some faces use the copies
            k = int(rng.integers(1, 4))
            src = rng.choice(n, size=k, replace=False)
            V_list.append(V[src])
            copies = np.arange(nv, nv + k)
            nv += k
            faces = rng.choice(m, size=int(rng.integers(1, 5)), replace=False)
            for s, c in zip(src, copies):
                sub = F_list[0][faces]
                sub[sub == s] = c
                F_list[0][faces] = sub
        elif kind == "fin":  # an extra face on an existing edge
            f = int(rng.integers(0, m))
            a, b = Fc[f, 0], Fc[f, 1]
            Vc = np.vstack(V_list)  # a or b may be a copy made by an earlier "dupv"
            V_list.append(((Vc[a] + Vc[b]) / 2 + rng.normal(size=3))[None])
            F_list.append(np.array([[a, b, nv]]))
            nv += 1
        elif kind == "flip":
            faces = rng.choice(m, size=int(rng.integers(1, m // 3)), replace=False)
            F_list[0][faces] = F_list[0][faces][:, [0, 2, 1]]
        elif kind == "unref":
            k = int(rng.integers(1, 4))
            V_list.append(rng.normal(size=(k, 3)) * 5)
            nv += k
        elif kind == "degen":
            p, q = rng.normal(size=3), rng.normal(size=3)
            V_list.append(np.array([p, (p + q) / 2, q]))
            F_list.append(np.array([[nv, nv + 1, nv + 2]]))
            nv += 3
        elif kind == "repeat":
            a, b = rng.choice(n, size=2, replace=False)
            F_list.append(np.array([[a, a, b]]))
        elif kind == "dupf":
            f = int(rng.integers(0, m))
            F_list.append(Fc[[f]][:, [1, 2, 0]])
    return name, np.vstack(V_list), np.vstack(F_list), kinds


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(corrupted_meshes())
def test_clean_fixes_random_corruption(case):
    name, V, F, kinds = case
    before = validate_mesh(V, F)
    res = clean_mesh(V, F)
    after = validate_mesh(res.V, res.F)
    assert not after.needs_cleaning, (kinds, after.summary())
    assert after.ok, (kinds, after.summary())
    fixable_before = [i.code for i in before.issues if i.fixable and i.severity != "info"]
    if fixable_before:
        assert res.actions != ["Nothing to fix: the mesh is clean."]
    assert not any(a.startswith("Not fixed") for a in res.actions), res.actions
    # maps are consistent
    assert res.vertex_map.shape == (V.shape[0],) and res.face_map.shape == (res.F.shape[0],)
    ok = res.vertex_map >= 0
    np.testing.assert_array_equal(res.V[res.vertex_map[ok]], V[ok])
    if name != "grid":
        assert after.stats["closed"] or after.stats["boundary_loops"] > 0
        assert signed_volume(res.V, res.F) > 0 or not after.stats["closed"]


# ------------------------------------------------------------------------------ advice (issue 10)
def test_advice_never_offers_clean_for_what_clean_cannot_fix():
    V, F = torus()
    F = np.vstack([F, [[0, 1, len(V) + 3]]])  # a triangle that uses a vertex that does not exist
    report = validate_mesh(V, F)
    issue = report.get("index_out_of_range")
    assert issue is not None and not issue.fixable
    assert "Use 'Clean'" not in report.advice and "Use 'Clean'" not in report.summary()
    assert "'Clean' cannot fix: " in report.advice
    assert "export the model again" in report.advice and report.advice in report.summary()


def test_advice_splits_fixable_and_unfixable_problems():
    V, F = mobius_strip()
    V2 = np.vstack([V, [[5.0, 5.0, 5.0]]])  # an unused vertex: Clean fixes that
    F2 = np.vstack([F, [[0, 1, len(V2) + 3]]])  # and a broken triangle: Clean cannot
    report = validate_mesh(V2, F2)
    assert report.needs_cleaning
    assert report.advice.startswith("Use 'Clean' to fix: unused vertices")
    assert "one-sided surface" in report.advice.split("'Clean' cannot fix")[0]
    assert "'Clean' cannot fix: " in report.advice
    # a clean mesh needs no advice
    Vt, Ft = torus()
    assert validate_mesh(Vt, Ft).advice == ""
