"""UVs, materials, normals and vertex colours of OBJ files: read per triangle corner in
read_mesh's order, written back, and split with Loop-topology subdivision (issue 39 item 5)."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import read_mesh, write_mesh
from algorithms.mesh.attributes import read_attributes
from algorithms.mesh.primitives import grid
from algorithms.mesh.subdivision import loop_subdivide, midpoint_subdivide

TEXTURED = """mtllib box.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0.5 0.5 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
vt 0.25 0.25
vn 0 0 -1
vn 0 0 1
usemtl bottom
f 1/1/1 4/4/1 3/3/1 2/2/1
usemtl side
f 1/6/2 2/2/2 5/5/2
f 2/2/2 3/3/2 5/5/2
f 3/3 4/4 5/5
f 4/4/2 1/1/2 5/5/2
"""


def _textured(tmp_path):
    p = tmp_path / "box.obj"
    p.write_text(TEXTURED)
    return p


def test_read_aligns_corners_with_read_mesh_including_the_split_quad(tmp_path):
    p = _textured(tmp_path)
    m = read_mesh(p)
    a = read_attributes(p, len(m.V), len(m.F))
    assert len(m.F) == 6 and a.uv.shape == (6, 3, 2)
    # the quad 1 4 3 2 is split by the fan (1 4 3), (1 3 2)
    np.testing.assert_array_equal(m.F[:2], [[0, 3, 2], [0, 2, 1]])
    np.testing.assert_array_equal(a.uv[1], [[0, 0], [1, 1], [1, 0]])
    np.testing.assert_array_equal(a.uv[2], [[0.25, 0.25], [1, 0], [0.5, 0.5]])  # a seam corner
    assert a.material_names == ["bottom", "side"] and a.material.tolist() == [0, 0, 1, 1, 1, 1]
    assert a.normals and a.mtllib == ["box.mtl"]
    assert a.describe() == "texture coordinates (UVs), normals, 2 materials"


def test_round_trip_keeps_uvs_materials_and_gives_the_new_shapes_normals(tmp_path):
    p = _textured(tmp_path)
    m = read_mesh(p)
    a = read_attributes(p, len(m.V), len(m.F))
    V2 = m.V * [2.0, 1.0, 1.0]
    out = tmp_path / "out.obj"
    write_mesh(out, V2, m.F, attributes=a)
    m2 = read_mesh(out)
    b = read_attributes(out, len(m2.V), len(m2.F))
    np.testing.assert_array_equal(m2.V, V2)
    np.testing.assert_array_equal(m2.F, m.F)
    np.testing.assert_array_equal(b.uv, a.uv)
    assert b.material_names == a.material_names and b.material.tolist() == a.material.tolist()
    assert b.normals and b.mtllib == ["box.mtl"]
    text = out.read_text()
    assert text.count("usemtl") == 2 and "vn " in text


def test_subdivision_splits_uvs_linearly_and_keeps_seams(tmp_path):
    # a flat grid whose UVs are its x, y: after subdividing, every corner's UV is again its
    # vertex's x, y (midpoint positions are linear like the UVs)
    V, F = grid(4, 3)
    from algorithms.mesh.attributes import SurfaceAttributes

    a = SurfaceAttributes(uv=V[F][:, :, :2].copy(), material=np.arange(len(F)) % 2,
                          material_names=["a", "b"])
    for levels in (1, 2):
        Vs, Fs = midpoint_subdivide(V, F, levels)
        np.testing.assert_array_equal(Fs, loop_subdivide(V, F, levels)[1])  # one topology
        s = a.transferred(F, len(V), Fs, levels)
        assert s.uv.shape == (len(Fs), 3, 2)
        np.testing.assert_allclose(s.uv, Vs[Fs][:, :, :2], atol=1e-15)
        np.testing.assert_array_equal(s.material, np.repeat(a.material, 4 ** levels))
    # a seam: the two faces along an edge with different UVs keep different UVs at its midpoint
    uv = a.uv.copy()
    uv[0] += 10.0
    Fs = midpoint_subdivide(V, F, 1)[1]
    s = SurfaceAttributes(uv=uv).transferred(F, len(V), Fs, 1)
    assert np.abs(s.uv[:4] - 10.0 - a.transferred(F, len(V), Fs, 1).uv[:4]).max() < 1e-12


def test_not_an_obj_or_nothing_extra_gives_none(tmp_path):
    V, F = grid(2, 2)
    for name in ("plain.obj", "plain.ply"):
        write_mesh(tmp_path / name, V, F)
        assert read_attributes(tmp_path / name, len(V), len(F)) is None


def test_any_midpoint_topology_subdivision_gets_the_same_uvs_whatever_its_triangle_order():
    """Butterfly and the network order their new triangles unlike Loop; the UVs follow each
    triangle's parent read from the result itself: the same UV per (face, corner vertex) as
    Loop's linear split, for 1-3 levels, on a shuffled triangle order too."""
    from algorithms.mesh.attributes import SurfaceAttributes
    from algorithms.subdivision.baselines import butterfly_subdivide

    V, F = grid(4, 3)
    a = SurfaceAttributes(uv=V[F][:, :, :2].copy(), material=np.arange(len(F)) % 3,
                          material_names=["a", "b", "c"])
    rng = np.random.default_rng(1)
    for levels in (1, 2, 3):
        Vs, Fs = midpoint_subdivide(V, F, levels)
        Fb = butterfly_subdivide(V, F, levels)[1]
        # butterfly numbers its new vertices and triangles its own way: each child's UV
        # triangle is a quarter (per level) of its parent's, and together they tile the UVs
        tb = a.transferred(F, len(V), Fb, levels)
        area = np.abs(_uv_areas(tb.uv))
        np.testing.assert_allclose(area, np.abs(_uv_areas(a.uv)).mean() / 4 ** levels,
                                   rtol=1e-9)
        assert np.isfinite(tb.uv).all() and len(tb.material) == len(Fb)
        for V_out, F_out in ((Vs, Fs[rng.permutation(len(Fs))]), (Vs, np.roll(Fs, 1, axis=1))):
            t = a.transferred(F, len(V), F_out, levels)
            assert t is not None
            np.testing.assert_allclose(t.uv, V_out[F_out][:, :, :2], atol=1e-12)
            # the material of each child is its parent's: the parent found by position
            centre = V_out[F_out].mean(axis=1)[:, :2]
            parent = np.array([np.argmin(np.linalg.norm(V[F].mean(axis=1)[:, :2] - c, axis=1)
                                         + 1e3 * ~_inside(V[F][:, :, :2], c)) for c in centre])
            np.testing.assert_array_equal(t.material, a.material[parent])
    assert a.transferred(F, len(V), F[:2], 1) is None  # not a subdivision of F


def _inside(tri, p):
    """Which triangles (k, 3, 2) contain the point p (2,)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def cross(u, v, w):
        return (v[:, 0] - u[:, 0]) * (w[1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (w[0] - u[:, 0])

    d1, d2, d3 = cross(a, b, p), cross(b, c, p), cross(c, a, p)
    return ((d1 >= -1e-12) & (d2 >= -1e-12) & (d3 >= -1e-12)) | \
        ((d1 <= 1e-12) & (d2 <= 1e-12) & (d3 <= 1e-12))


def _uv_areas(uv):
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
