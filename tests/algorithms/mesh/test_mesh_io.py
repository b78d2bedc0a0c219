"""Tests for algorithms.mesh.io: reading, writing, atomicity, errors."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from algorithms.errors import MeshReadError, MeshWriteError
from algorithms.mesh import io as mio
from algorithms.mesh.io import (
    SUPPORTED_READ,
    SUPPORTED_WRITE,
    MeshData,
    file_filter,
    read_mesh,
    write_mesh,
)
from algorithms.mesh.primitives import cube, icosphere, torus
from tests.conftest import shared_mesh


# name -> (V, F) from SOURCES.md
SHARED_COUNTS = {
    "hand_lowres.obj": (810, 1602),
    "spot_lowres.obj": (829, 1654),
    "wingnut.obj": (3047, 6090),
    "fertility.off": (4494, 9000),
    "bob.obj": (5344, 10688),
    "fandisk.off": (7229, 14454),
    "rocker-arm.obj": (10044, 20088),
    "camelhead.off": (11381, 22704),
    "armadillo.obj": (14587, 29170),
    "stanford-bunny.obj": (35947, 69451),
    "koala.obj": (49999, 99994),
    "igea.ply": (134345, 268686),
}


def write_text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------------------
# shared meshes
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SHARED_COUNTS))
def test_read_shared_mesh_counts(name):
    mesh = read_mesh(shared_mesh(name))
    assert isinstance(mesh, MeshData)
    assert mesh.V.dtype == np.float64 and mesh.V.shape == (SHARED_COUNTS[name][0], 3)
    assert mesh.F.dtype == np.int64 and mesh.F.shape == (SHARED_COUNTS[name][1], 3)
    assert mesh.F.min() >= 0 and mesh.F.max() < mesh.V.shape[0]
    assert mesh.notes == []
    assert mesh.n_vertices == mesh.V.shape[0] and mesh.n_faces == mesh.F.shape[0]


@pytest.mark.parametrize("name", ["bob.obj", "spot_lowres.obj", "fertility.off", "camelhead.off", "igea.ply"])
def test_read_matches_libigl(name):
    igl = pytest.importorskip("igl")
    V_ref, F_ref = igl.read_triangle_mesh(str(shared_mesh(name)))
    mesh = read_mesh(shared_mesh(name))
    np.testing.assert_array_equal(mesh.F, F_ref)
    np.testing.assert_allclose(mesh.V, V_ref, rtol=0, atol=1e-12)


def test_read_igea_binary_ply():
    # speed is measured in benchmarks/mesh_core.py; here: the large binary PLY reads correctly
    mesh = read_mesh(shared_mesh("igea.ply"))
    assert mesh.V.shape == (134345, 3) and mesh.F.shape == (268686, 3)
    assert mesh.F.min() == 0 and mesh.F.max() == 134344 and np.isfinite(mesh.V).all()


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------


def test_obj_token_forms_polygons_and_relative_indices(tmp_path):
    text = (
        "# comment line\r\n"
        "mtllib foo.mtl\n"
        "o thing\n"
        "v 0 0 0\n"
        "v 1 0 0 1.0\n"  # w component ignored
        "v 1 1 0 0.5 0.5 0.5\n"  # colour ignored
        "  v 0 1 0\n"  # leading whitespace
        "vt 0 0\nvt 1 0\nvn 0 0 1\n"
        "v 0.5 2 \\\n 0\n"  # line continuation
        "f 1/1/1 2/2/1 3/1/1\n"
        "f 1//1 3//1 4//1 # trailing comment\n"
        "f -5 -4 -1\n"  # relative: vertices 1, 2, 5
        "f 1/1 2/2 3/1 4/2\n"  # quad
        "f 1 2 3 4 5\n"  # pentagon
        "l 1 2\n"
        "s off\n"
    )
    mesh = read_mesh(write_text(tmp_path / "m.obj", text))
    np.testing.assert_array_equal(
        mesh.V, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 2, 0]]
    )
    expected = [[0, 1, 2], [0, 2, 3], [0, 1, 4], [0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3], [0, 3, 4]]
    np.testing.assert_array_equal(mesh.F, expected)
    assert mesh.notes == ["1 quad and 1 polygon were split into triangles (fan triangulation)."]


def test_obj_quads_note_plural(tmp_path):
    V, _ = cube()
    lines = [f"v {x} {y} {z}" for x, y, z in V]
    lines += ["f 1 2 3 4", "f 5 6 7 8", "f 1 2 6 5"]
    mesh = read_mesh(write_text(tmp_path / "q.obj", "\n".join(lines)))
    assert mesh.F.shape == (6, 3)
    assert mesh.notes == ["3 quads were split into triangles (fan triangulation)."]


def test_obj_relative_indices_refer_to_vertices_defined_so_far(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 0 0 1\nf -4 -3 -1\n"
    mesh = read_mesh(write_text(tmp_path / "r.obj", text))
    np.testing.assert_array_equal(mesh.F, [[0, 1, 2], [0, 1, 3]])


def test_obj_face_index_zero_is_an_error(tmp_path):
    path = write_text(tmp_path / "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    with pytest.raises(MeshReadError, match=r"line 4: face index 0 .*OBJ counts vertices from 1"):
        read_mesh(path)


def test_obj_out_of_range_index_is_kept(tmp_path):
    path = write_text(tmp_path / "oor.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\nf -1 -2 -7\n")
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.F, [[0, 1, 8], [2, 1, -4]])


def test_obj_nan_coordinates_are_kept(tmp_path):
    path = write_text(tmp_path / "nan.obj", "v 0 0 nan\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n")
    mesh = read_mesh(path)
    assert np.isnan(mesh.V[0, 2]) and np.isinf(mesh.V[1, 2])


def test_obj_bad_number_reports_line(tmp_path):
    path = write_text(tmp_path / "bad.obj", "v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(MeshReadError, match=r"could not be read as an OBJ file: line 2: 'zero' is not a number"):
        read_mesh(path)


def test_obj_bad_face_token_reports_line(tmp_path):
    path = write_text(tmp_path / "badf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2.5 3\n")
    with pytest.raises(MeshReadError, match=r"line 5: '2.5' is not a valid vertex index"):
        read_mesh(path)


def test_obj_index_too_large_for_int64(tmp_path):
    path = write_text(tmp_path / "big.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n")
    with pytest.raises(MeshReadError, match="not a valid vertex index"):
        read_mesh(path)


def test_obj_vertex_with_two_coordinates(tmp_path):
    path = write_text(tmp_path / "v2.obj", "v 0 0 0\nv 1 0\nf 1 2 1\n")
    with pytest.raises(MeshReadError, match="line 2: a vertex .* needs three coordinates"):
        read_mesh(path)


def test_obj_faces_with_two_corners_are_skipped_with_note(tmp_path):
    path = write_text(tmp_path / "f2.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\nf 1 2 3\n")
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.F, [[0, 1, 2]])
    assert any("fewer than three corners" in n for n in mesh.notes)


def test_random_bytes_named_obj(tmp_path):
    rng = np.random.default_rng(0)
    for size in (50, 5000):
        path = tmp_path / f"noise{size}.obj"
        path.write_bytes(rng.integers(0, 256, size, dtype=np.uint8).tobytes())
        with pytest.raises(MeshReadError, match="could not be read as an OBJ file"):
            read_mesh(path)


def test_text_without_obj_content(tmp_path):
    path = write_text(tmp_path / "prose.obj", "Dear reader,\nthis is not a mesh.\n")
    with pytest.raises(MeshReadError, match=r"could not be read as an OBJ file: no vertex \('v'\) or face"):
        read_mesh(path)


# --------------------------------------------------------------------------------------------
# OFF
# --------------------------------------------------------------------------------------------


def test_off_variants(tmp_path):
    plain = "OFF\n# comment\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"
    m = read_mesh(write_text(tmp_path / "a.off", plain))
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [0, 2, 3]])
    coff = "COFF 4 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 1 1 1 255\n4 0 1 2 3 0.5 0.5 0.5\n"
    m = read_mesh(write_text(tmp_path / "b.off", coff))
    np.testing.assert_array_equal(m.V[2], [1, 1, 0])
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [0, 2, 3]])
    assert "1 quad was split" in m.notes[0]
    noff = "NOFF\r\n3 1 0\r\n0 0 0 0 0 1\r\n1 0 0 0 0 1\r\n0 1 0 0 0 1\r\n3 0 1 2 255 0 0\r\n"
    m = read_mesh(write_text(tmp_path / "c.off", noff))
    np.testing.assert_array_equal(m.V, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(m.F, [[0, 1, 2]])


def test_off_errors(tmp_path):
    with pytest.raises(MeshReadError, match="first line should be 'OFF'"):
        read_mesh(write_text(tmp_path / "a.off", "PLY\n3 1 0\n"))
    with pytest.raises(MeshReadError, match="announces 5 vertices"):
        read_mesh(write_text(tmp_path / "b.off", "OFF\n5 1 0\n0 0 0\n1 0 0\n"))
    with pytest.raises(MeshReadError, match="announces 2 faces"):
        read_mesh(write_text(tmp_path / "c.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"))
    with pytest.raises(MeshReadError, match="binary OFF files are not supported"):
        read_mesh(write_text(tmp_path / "d.off", "OFF BINARY\n"))
    with pytest.raises(MeshReadError, match="'x' is not a whole number|not a valid vertex index"):
        read_mesh(write_text(tmp_path / "e.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 x 2\n"))


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


def test_ply_ascii_with_extra_elements_and_properties(tmp_path):
    text = (
        "ply\nformat ascii 1.0\ncomment made by hand\n"
        "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty float nx\n"
        "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
        "element face 2\nproperty list uint8 int vertex_index\nproperty uchar flags\n"
        "end_header\n"
        "0 0 0 255 1\n1 0 0 0 1\n1 1 0 0 1\n0 1 0 0 1\n"
        "0 1\n"
        "3 0 1 2 7\n4 0 2 3 1 7\n"
    )
    m = read_mesh(write_text(tmp_path / "a.ply", text))
    np.testing.assert_array_equal(m.V, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [0, 2, 3], [0, 3, 1]])
    assert "1 quad" in m.notes[0]


def _ply_binary(endian: str, V, faces, vtype="f8", itype="u2", ctype="u1", extra_vertex=True,
                extra_element=True, vary_vertex_list=False) -> bytes:
    fmt = {"<": "binary_little_endian", ">": "binary_big_endian"}[endian]
    names = {"f8": "double", "f4": "float", "u2": "ushort", "i4": "int", "u1": "uchar", "u4": "uint", "i2": "short"}
    header = f"ply\nformat {fmt} 1.0\n"
    header += f"element vertex {len(V)}\n"
    header += "".join(f"property {names[vtype]} {c}\n" for c in "xyz")
    if extra_vertex:
        header += "property uchar alpha\nproperty list uchar float weights\n"
    if extra_element:
        header += "element material 2\nproperty short id\nproperty double shininess\n"
    header += f"element face {len(faces)}\nproperty list {names[ctype]} {names[itype]} vertex_indices\n"
    header += "end_header\n"
    body = b""
    for i, v in enumerate(V):
        body += np.array(v, dtype=endian + vtype).tobytes()
        if extra_vertex:
            k = i % 3 if vary_vertex_list else 2
            body += bytes([7]) + bytes([k]) + np.arange(k, dtype=endian + "f4").tobytes()
    if extra_element:
        for k in range(2):
            body += np.array([k], dtype=endian + "i2").tobytes() + np.array([1.5], dtype=endian + "f8").tobytes()
    for f in faces:
        body += np.array([len(f)], dtype=endian + ctype).tobytes() + np.array(f, dtype=endian + itype).tobytes()
    return header.encode() + body


@pytest.mark.parametrize("endian", ["<", ">"])
@pytest.mark.parametrize("vtype,itype,ctype", [("f8", "u2", "u1"), ("f4", "i4", "u4"), ("f8", "u4", "i2")])
def test_ply_binary_types_and_skipping(tmp_path, endian, vtype, itype, ctype):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5]])
    faces = [[0, 1, 2], [0, 2, 3]]
    path = tmp_path / "b.ply"
    path.write_bytes(_ply_binary(endian, V, faces, vtype, itype, ctype))
    m = read_mesh(path)
    np.testing.assert_array_equal(m.V, V)
    np.testing.assert_array_equal(m.F, faces)


def test_ply_binary_mixed_polygons(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 0.5, 0]])
    faces = [[0, 1, 2, 3], [0, 3, 4], [0, 1, 2]]
    path = tmp_path / "mixed.ply"
    path.write_bytes(_ply_binary("<", V, faces, extra_vertex=True))
    m = read_mesh(path)
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 1, 2]])
    assert m.notes == ["1 quad was split into triangles (fan triangulation)."]


@pytest.mark.parametrize("endian", ["<", ">"])
def test_ply_binary_variable_length_vertex_lists(tmp_path, endian):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5], [2, 2, 2]])
    faces = [[0, 1, 2], [0, 2, 3], [1, 4, 2, 0]]
    path = tmp_path / "vary.ply"
    path.write_bytes(_ply_binary(endian, V, faces, "f4", "i4", "u1", vary_vertex_list=True))
    m = read_mesh(path)
    np.testing.assert_array_equal(m.V, V.astype(np.float32))
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [0, 2, 3], [1, 4, 2], [1, 2, 0]])


def test_ply_tristrips(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 2, 0], [1, 2, 0]], float)
    strips = [0, 1, 2, 3, -1, 2, 3, 4, 5]
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
        "property float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n"
    )
    body = V.astype("<f4").tobytes() + np.array([len(strips)] + strips, "<i4").tobytes()
    path = tmp_path / "strip.ply"
    path.write_bytes(header.encode() + body)
    m = read_mesh(path)
    np.testing.assert_array_equal(m.F, [[0, 1, 2], [2, 1, 3], [2, 3, 4], [4, 3, 5]])
    assert "converted to 4 triangles" in m.notes[0]


def test_ply_truncated_binary(tmp_path):
    V, F = icosphere(1)
    path = tmp_path / "t.ply"
    write_mesh(path, V, F)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 10])
    with pytest.raises(MeshReadError, match="could not be read as a PLY file: the file ends early"):
        read_mesh(path)
    path.write_bytes(data[:300])
    with pytest.raises(MeshReadError, match="truncated"):
        read_mesh(path)


def test_ply_errors(tmp_path):
    with pytest.raises(MeshReadError, match="does not start with 'ply'"):
        read_mesh(write_text(tmp_path / "a.ply", "hello\n"))
    with pytest.raises(MeshReadError, match="no 'end_header'"):
        read_mesh(write_text(tmp_path / "b.ply", "ply\nformat ascii 1.0\n"))
    bad = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nend_header\n0 0\n1 0\n0 1\n"
    with pytest.raises(MeshReadError, match="no z property"):
        read_mesh(write_text(tmp_path / "c.ply", bad))
    points = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
    with pytest.raises(MeshReadError, match="3 vertices but no faces"):
        read_mesh(write_text(tmp_path / "d.ply", points))


# --------------------------------------------------------------------------------------------
# STL
# --------------------------------------------------------------------------------------------


def test_stl_ascii_welds_corners(tmp_path):
    V, F = cube()
    facets = []
    for f in F:
        facets.append("facet normal 0 0 0\n outer loop\n" + "".join(
            f"  vertex {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in V[f].tolist()) + " endloop\nendfacet\n")
    path = write_text(tmp_path / "c.stl", "solid cube\n" + "".join(facets) + "endsolid cube\n")
    m = read_mesh(path)
    assert m.V.shape == (8, 3) and m.F.shape == (12, 3)
    np.testing.assert_array_equal(m.V[m.F], V[F])
    assert "36 corners" in m.notes[0] and "8 shared vertices" in m.notes[0]


def test_stl_binary_roundtrip_and_header_starting_with_solid(tmp_path):
    V, F = torus(n_major=12, n_minor=8)
    V = V.astype(np.float32).astype(np.float64)  # STL stores float32
    path = tmp_path / "t.stl"
    write_mesh(path, V, F)
    data = bytearray(path.read_bytes())
    data[:5] = b"solid"  # some exporters do this in binary files
    path.write_bytes(bytes(data))
    m = read_mesh(path)
    np.testing.assert_array_equal(m.V[m.F], V[F])
    assert m.V.shape[0] == V.shape[0]
    assert "binary STL" in m.notes[0]


def test_stl_truncated_binary(tmp_path):
    V, F = cube()
    path = tmp_path / "c.stl"
    write_mesh(path, V, F)
    path.write_bytes(path.read_bytes()[:-20])
    with pytest.raises(MeshReadError, match="could not be read as an STL file: the file ends early"):
        read_mesh(path)


def test_stl_empty_solid(tmp_path):
    with pytest.raises(MeshReadError, match="no triangles"):
        read_mesh(write_text(tmp_path / "e.stl", "solid empty\nendsolid empty\n"))


# --------------------------------------------------------------------------------------------
# user mistakes
# --------------------------------------------------------------------------------------------


def test_missing_file_directory_extension(tmp_path):
    with pytest.raises(MeshReadError, match="does not exist"):
        read_mesh(tmp_path / "nope.obj")
    with pytest.raises(MeshReadError, match="is a folder"):
        read_mesh(tmp_path)
    write_text(tmp_path / "mesh.xyz", "1 2 3\n")
    with pytest.raises(MeshReadError, match=r"'\.xyz' file, which Stylize3D cannot read.*\.obj"):
        read_mesh(tmp_path / "mesh.xyz")
    write_text(tmp_path / "mesh", "1 2 3\n")
    with pytest.raises(MeshReadError, match="has no extension"):
        read_mesh(tmp_path / "mesh")
    with pytest.raises(MeshReadError, match="not a file name"):
        read_mesh(12.5)


@pytest.mark.parametrize("ext", SUPPORTED_READ)
def test_empty_and_blank_files(tmp_path, ext):
    for content in (b"", b"  \n\n  "):
        path = tmp_path / f"empty{ext}"
        path.write_bytes(content)
        with pytest.raises(MeshReadError, match="is empty"):
            read_mesh(path)


@pytest.mark.parametrize("ext", [".ply", ".off", ".stl"])
def test_random_bytes_other_formats(tmp_path, ext):
    path = tmp_path / f"noise{ext}"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(MeshReadError, match="could not be read as a"):
        read_mesh(path)


def test_vertices_without_faces(tmp_path):
    with pytest.raises(MeshReadError, match="2 vertices but no faces"):
        read_mesh(write_text(tmp_path / "p.obj", "v 0 0 0\nv 1 1 1\n"))


def test_uppercase_extension(tmp_path):
    m = read_mesh(write_text(tmp_path / "UP.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"))
    assert m.F.shape == (1, 3)


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def _random_mesh(seed=0):
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-5, 5, size=(50, 1))
    F = rng.integers(0, 50, size=(80, 3))
    return V, F


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
def test_roundtrip_exact(tmp_path, ext):
    V, F = _random_mesh()
    V[3] = [np.pi, -0.0, 1e-300]
    path = tmp_path / f"r{ext}"
    write_mesh(path, V, F)
    m = read_mesh(path)
    np.testing.assert_array_equal(m.V, V)
    np.testing.assert_array_equal(m.F, F)
    assert m.notes == []


def test_roundtrip_stl_float32(tmp_path):
    V, F = icosphere(2)
    path = tmp_path / "s.stl"
    write_mesh(path, V, F)
    m = read_mesh(path)
    np.testing.assert_array_equal(m.V[m.F], V.astype(np.float32).astype(np.float64)[F])
    assert m.V.shape == V.shape  # welded back to shared vertices
    assert len(path.read_bytes()) == 84 + 50 * F.shape[0]


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(*[st.floats(allow_nan=False, allow_infinity=False, width=64)] * 3),
        min_size=3,
        max_size=20,
    ),
    st.data(),
)
def test_roundtrip_property(tmp_path, points, data):
    V = np.array(points, dtype=np.float64)
    n = V.shape[0]
    F = np.array(
        data.draw(st.lists(st.tuples(*[st.integers(0, n - 1)] * 3), min_size=1, max_size=20))
    )
    for ext in (".obj", ".off", ".ply"):
        path = tmp_path / f"h{ext}"
        write_mesh(path, V, F)
        m = read_mesh(path)
        np.testing.assert_array_equal(m.V, V)
        np.testing.assert_array_equal(m.F, F)


def test_write_glb_is_valid(tmp_path):
    V, F = icosphere(1)
    V[0] = [0.0, 0.0, 0.0]  # irrelevant to validity; keep positions finite
    path = tmp_path / "s.glb"
    write_mesh(path, V, F)
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data)
    json_len, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON" and json_len % 4 == 0
    gltf = json.loads(data[20 : 20 + json_len].decode("utf-8"))
    bin_len, bin_type = struct.unpack_from("<I4s", data, 20 + json_len)
    assert bin_type == b"BIN\x00" and bin_len % 4 == 0
    assert 28 + json_len + bin_len == len(data)
    binary = data[28 + json_len : 28 + json_len + bin_len]
    assert gltf["asset"]["version"] == "2.0"
    assert gltf["buffers"][0]["byteLength"] <= bin_len
    prim = gltf["meshes"][0]["primitives"][0]
    acc = gltf["accessors"]
    views = gltf["bufferViews"]

    def read_accessor(i, dtype, width):
        a = acc[i]
        view = views[a["bufferView"]]
        start = view["byteOffset"] + a.get("byteOffset", 0)
        arr = np.frombuffer(binary, dtype=dtype, count=a["count"] * width, offset=start)
        return arr.reshape(a["count"], width) if width > 1 else arr

    pos = read_accessor(prim["attributes"]["POSITION"], "<f4", 3)
    nrm = read_accessor(prim["attributes"]["NORMAL"], "<f4", 3)
    idx = read_accessor(prim["indices"], "<u4", 1)
    np.testing.assert_array_equal(pos, V.astype(np.float32))
    np.testing.assert_array_equal(idx.reshape(-1, 3), F)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-6)
    assert acc[prim["attributes"]["POSITION"]]["min"] == [float(x) for x in pos.min(axis=0)]
    assert acc[prim["attributes"]["POSITION"]]["max"] == [float(x) for x in pos.max(axis=0)]
    assert acc[prim["indices"]]["componentType"] == 5125 and prim["mode"] == 4
    for view in views:
        assert view["byteOffset"] % 4 == 0 and view["byteOffset"] + view["byteLength"] <= bin_len


def test_write_glb_refuses_nan(tmp_path):
    V, F = cube()
    V[0, 0] = np.nan
    with pytest.raises(MeshWriteError, match="NaN or infinite coordinates"):
        write_mesh(tmp_path / "c.glb", V, F)
    write_mesh(tmp_path / "c.obj", V, F)  # text formats can store NaN for inspection
    assert np.isnan(read_mesh(tmp_path / "c.obj").V[0, 0])


def test_write_failure_midway_keeps_old_file(tmp_path, monkeypatch):
    V, F = cube()
    path = tmp_path / "keep.obj"
    write_mesh(path, V, F)
    old = path.read_bytes()

    def exploding_writer(fh, V, F):
        fh.write(b"v 1 2 3\n" * 1000)
        raise RuntimeError("disk on fire")

    monkeypatch.setitem(mio._WRITERS, ".obj", exploding_writer)
    with pytest.raises(MeshWriteError, match="disk on fire.*left unchanged"):
        write_mesh(path, *icosphere(1))
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.obj"]


def test_write_failure_in_fsync_keeps_old_file(tmp_path, monkeypatch):
    V, F = cube()
    path = tmp_path / "keep.ply"
    write_mesh(path, V, F)
    old = path.read_bytes()

    def bad_fsync(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mio.os, "fsync", bad_fsync)
    with pytest.raises(MeshWriteError, match="No space left"):
        write_mesh(path, *icosphere(2))
    assert path.read_bytes() == old
    assert [p.name for p in tmp_path.iterdir()] == ["keep.ply"]


def test_write_bad_arrays_keep_old_file(tmp_path):
    V, F = cube()
    path = tmp_path / "k.off"
    write_mesh(path, V, F)
    old = path.read_bytes()

    class Boom:
        def __float__(self):
            raise ValueError("cannot convert")

    bad_V = np.array(V.tolist(), dtype=object)
    bad_V[3, 1] = Boom()
    with pytest.raises(MeshWriteError, match="not numbers"):
        write_mesh(path, bad_V, F)
    with pytest.raises(MeshWriteError, match="refer to vertices that do not exist"):
        write_mesh(path, V, F + 5)
    with pytest.raises(MeshWriteError, match=r"\(m, 3\)"):
        write_mesh(path, V, F[:, :2])
    with pytest.raises(MeshWriteError, match="empty"):
        write_mesh(path, V, np.zeros((0, 3), int))
    assert path.read_bytes() == old


def test_write_user_mistakes(tmp_path):
    V, F = cube()
    with pytest.raises(MeshWriteError, match="not a format Stylize3D can write"):
        write_mesh(tmp_path / "c.fbx", V, F)
    with pytest.raises(MeshWriteError, match="does not exist"):
        write_mesh(tmp_path / "no" / "dir" / "c.obj", V, F)
    with pytest.raises(MeshWriteError, match="is a folder"):
        (tmp_path / "d.obj").mkdir()
        write_mesh(tmp_path / "d.obj", V, F)


def test_written_file_permissions_are_not_private(tmp_path):
    path = tmp_path / "perm.obj"
    write_mesh(path, *cube())
    assert path.stat().st_mode & 0o044  # readable by group/others (umask permitting), not 0600


@pytest.mark.parametrize("ext", SUPPORTED_WRITE)
def test_overwrite_replaces_content(tmp_path, ext):
    path = tmp_path / f"o{ext}"
    write_mesh(path, *cube())
    first = path.read_bytes()
    write_mesh(path, *icosphere(1))
    assert path.read_bytes() != first


def test_formats_and_filter():
    assert set(SUPPORTED_READ) == {".obj", ".off", ".ply", ".stl", ".glb"}
    assert set(SUPPORTED_WRITE) == set(SUPPORTED_READ)
    assert file_filter() == "Meshes (*.obj *.ply *.stl *.off *.glb)"
    assert file_filter("write") == "Meshes (*.obj *.ply *.stl *.off *.glb)"
    with pytest.raises(ValueError):
        file_filter("both")


# ------------------------------------------------------------------------------ GLB reading, colours
def test_glb_round_trip(tmp_path):
    V, F = torus()
    path = tmp_path / "t.glb"
    write_mesh(path, V, F)
    back = read_mesh(path)
    assert np.array_equal(back.F, F)
    assert np.allclose(back.V, V.astype(np.float32), atol=0, rtol=0)  # float32 in the file
    assert back.notes == []


def _glb(gltf: dict, binary: bytes) -> bytes:
    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\x00" * (-len(binary) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\x00") + binary)


def test_glb_from_another_program_with_nodes_strides_and_two_parts(tmp_path):
    """Interleaved positions (byteStride), uint16 indices, a translated and a scaled node."""
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    inter = np.zeros((3, 6), np.float32)
    inter[:, :3] = P
    inter[:, 3:] = 7.0  # another attribute interleaved
    idx = np.array([0, 1, 2, 0], np.uint16)  # padded to 4 bytes; count says 3
    binary = inter.tobytes() + idx.tobytes()
    gltf = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0, "translation": [0, 0, 5]},
                      {"mesh": 0, "scale": [2, 2, 2]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "buffers": [{"byteLength": len(binary)}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 72, "byteStride": 24},
                            {"buffer": 0, "byteOffset": 72, "byteLength": 8}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
                          {"bufferView": 1, "componentType": 5123, "count": 3,
                           "type": "SCALAR"}]}
    path = tmp_path / "other.glb"
    path.write_bytes(_glb(gltf, binary))
    m = read_mesh(path)
    assert m.V.shape == (6, 3) and m.F.tolist() == [[0, 1, 2], [3, 4, 5]]
    assert np.allclose(m.V[:3], P + [0, 0, 5]) and np.allclose(m.V[3:], 2 * P)
    assert "2 mesh parts" in m.notes[0]


@pytest.mark.parametrize("kind, says", [("signature", "signature"), ("cut", "truncated"),
                                        ("draco", "extensions")])
def test_bad_glb_is_a_plain_message(tmp_path, kind, says):
    path = tmp_path / "t.glb"
    write_mesh(path, *cube())
    data = path.read_bytes()
    if kind == "signature":
        data = b"glTX" + data[4:]
    elif kind == "cut":
        data = data[:40]
    else:  # a file that needs Draco decompression
        jlen = struct.unpack_from("<I", data, 12)[0]
        gltf = json.loads(data[20:20 + jlen])
        gltf["extensionsRequired"] = ["KHR_draco_mesh_compression"]
        data = _glb(gltf, data[20 + jlen + 8:])
    path.write_bytes(data)
    with pytest.raises(MeshReadError) as e:
        read_mesh(path)
    assert says in str(e.value)


@pytest.mark.parametrize("ext", [".ply", ".obj"])
def test_vertex_colours_written_and_geometry_reads_back(tmp_path, ext):
    V, F = icosphere(1)
    rgb = (np.arange(len(V) * 3).reshape(-1, 3) * 7 % 256).astype(np.uint8)
    path = tmp_path / f"c{ext}"
    write_mesh(path, V, F, vertex_colors=rgb)
    back = read_mesh(path)
    assert np.array_equal(back.F, F) and np.allclose(back.V, V)
    if ext == ".ply":
        raw = path.read_bytes()
        head, body = raw.split(b"end_header\n", 1)
        assert b"property uchar red" in head
        rec = np.frombuffer(body[:len(V) * 27],
                            dtype=np.dtype([("p", "<f8", (3,)), ("c", "u1", (3,))]))
        assert np.array_equal(rec["c"], rgb)
    else:
        rows = [line.split()[4:] for line in path.read_text().splitlines()
                if line.startswith("v ")]
        assert np.allclose(np.array(rows, float) * 255, rgb, atol=1e-3)


def test_vertex_colours_refused_plainly(tmp_path):
    V, F = cube()
    with pytest.raises(MeshWriteError, match="use a .ply or .obj"):
        write_mesh(tmp_path / "c.stl", V, F, vertex_colors=np.zeros((len(V), 3)))
    with pytest.raises(MeshWriteError, match="one RGB colour per vertex"):
        write_mesh(tmp_path / "c.ply", V, F, vertex_colors=np.zeros((2, 3)))
    with pytest.raises(MeshWriteError, match=r"\[0, 1\]"):
        write_mesh(tmp_path / "c.ply", V, F, vertex_colors=np.full((len(V), 3), 2.0))
    assert not (tmp_path / "c.ply").exists()


def test_ply_colours_are_read_from_binary_and_ascii_files(tmp_path):
    """The app writes coloured meshes as binary PLY; their colours were read from ASCII PLY
    only (the Adversarial panel saw a grey shape)."""
    from algorithms.mesh.io import ply_colors
    from algorithms.render.sh import read_mesh_colors

    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    C = np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.2], [0.2, 0.2, 0.2], [1.0, 1.0, 1.0]])
    p = tmp_path / "c.ply"
    write_mesh(p, V, F, vertex_colors=C)
    assert p.read_bytes().startswith(b"ply\nformat binary")
    kind, got = read_mesh_colors(p, 4, 2)
    assert kind == "vertex"
    np.testing.assert_allclose(got, C, atol=1 / 255)
    # ASCII, colours on the faces of a quad and a triangle: one row per triangle
    text = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
            "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
            "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 2 0\n4 0 1 2 3 255 0 0\n3 1 4 2 0 0 255\n")
    q = tmp_path / "f.ply"
    q.write_text(text)
    mesh = read_mesh(q)
    assert len(mesh.F) == 3
    kind, got = read_mesh_colors(q, 5, 3)
    assert kind == "face"
    np.testing.assert_allclose(got, [[1, 0, 0], [1, 0, 0], [0, 0, 1]])
    assert ply_colors(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                      b"end_header\n") is None  # no colours, truncated: None, no exception
    assert ply_colors(b"garbage") is None


def test_number_parsing_reads_to_the_end_and_leaves_the_warning_filters_alone(tmp_path,
                                                                             monkeypatch):
    # the fast parser stops silently at an unreadable token; a stop anywhere, the last token
    # included, is an error. It must not touch the warning filters: in Python 3.11 they are
    # shared by every thread (a read in a worker thread once turned another thread's
    # DeprecationWarning into an error, failing unrelated tests)
    import warnings

    p = tmp_path / "bad.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0x\nf 1 2 3\n")
    calls = [(mio._parse_floats, "1 2.5\n-3e2"), (mio._parse_ints, "1 2\t3")]
    calls += [(mio._parse_floats, t) for t in ("1 2 3x", "1 x 3", "1,2,3", "1 2", "1 2 3 4")]
    calls += [(mio._parse_ints, t) for t in ("1 2 3.5", "1 2.5 3", "1 2 a")]
    touched, got = [], []

    def spy(name):
        real = getattr(warnings, name)
        return lambda *a, **k: touched.append(name) or real(*a, **k)

    with monkeypatch.context() as mp:
        for name in ("catch_warnings", "simplefilter", "filterwarnings"):
            mp.setattr(warnings, name, spy(name))
        for f, text in calls:
            try:
                got.append(f(text, 3))
            except ValueError:
                got.append(None)
        try:
            read_mesh(p)
        except MeshReadError as e:
            got.append(str(e))
    assert touched == []
    np.testing.assert_array_equal(got[0], [1, 2.5, -300])
    np.testing.assert_array_equal(got[1], [1, 2, 3])
    assert got[2:-1] == [None] * (len(calls) - 2)
    assert "line 3" in got[-1]
