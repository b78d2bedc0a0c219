"""Target normals on the sphere (thesis §6.3.1): closest normals, spherical parameterization by
cMCF, normal captures."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from algorithms.deform.targets import (
    CAPTURE_FORMAT,
    PRIMITIVES,
    CaptureSphere,
    ClosestNormals,
    SphericalStyleMap,
    TargetMap,
    closest_normal_targets,
    mesh_style_normals,
    primitive_normals,
    unit_rows,
)
from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import cube, icosahedron, icosphere, read_mesh, torus
from tests.conftest import shared_mesh


def random_directions(k, seed=0):
    D = np.random.default_rng(seed).normal(size=(k, 3))
    return D / np.linalg.norm(D, axis=1, keepdims=True)


# ------------------------------------------------------------------------------ primitives
@pytest.mark.parametrize("name, count", [("cube", 6), ("tetrahedron", 4), ("octahedron", 8),
                                         ("dodecahedron", 12), ("icosahedron", 20),
                                         ("triangular_prism", 5), ("hexagonal_prism", 8),
                                         ("pyramid", 5)])
def test_primitive_normals_are_the_distinct_unit_face_normals(name, count):
    N = primitive_normals(name)
    assert N.shape == (count, 3)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
    G = N @ N.T - np.eye(count)
    assert G.max() < 1 - 1e-6  # all distinct
    # a closed convex polytope's area-weighted normals sum to zero; with equal face areas
    # (all of these but the prisms and the pyramid) the plain sum does too
    if name in ("cube", "tetrahedron", "octahedron", "dodecahedron", "icosahedron"):
        np.testing.assert_allclose(N.sum(axis=0), 0.0, atol=1e-12)


def test_cube_normals_are_the_axes_and_every_primitive_name_works():
    np.testing.assert_array_equal(primitive_normals("cube"),
                                  np.vstack([np.eye(3), -np.eye(3)]))
    for name in PRIMITIVES:
        assert len(primitive_normals(name)) >= 4


def test_ngon_prism_and_pyramid_geometry():
    N = primitive_normals("prism", n=16)
    assert N.shape == (18, 3)
    np.testing.assert_allclose(N[:16, 2], 0.0)
    np.testing.assert_allclose(N[0], [1, 0, 0], atol=1e-15)
    P = primitive_normals("pyramid")
    # sides of the equilateral square pyramid are inclined arctan(sqrt 2) to the base: the angle
    # between a side's normal and the upward axis (the base normal is -z)
    inclination = np.degrees(np.arccos(-P[:4] @ P[4]))
    np.testing.assert_allclose(inclination, np.degrees(np.arctan(np.sqrt(2))))


def test_primitive_rotation_and_errors():
    Q = Rotation.from_euler("z", 45, degrees=True).as_matrix()
    N = primitive_normals("cube", rotation=Q)
    np.testing.assert_allclose(N[0], [np.sqrt(0.5), np.sqrt(0.5), 0], atol=1e-12)
    with pytest.raises(ParameterError, match="Unknown style primitive"):
        primitive_normals("teapot")
    with pytest.raises(ParameterError, match="sides"):
        primitive_normals("prism", n=2)
    with pytest.raises(ParameterError, match="rotation"):
        primitive_normals("cube", rotation=np.diag([1.0, 1.0, -1.0]))


# ------------------------------------------------------------------------------ closest normals
def test_closest_normal_targets_snap_to_the_largest_dot_product():
    S = primitive_normals("cube")
    N = unit_rows(np.array([[0.9, 0.1, 0.0], [0.1, -0.2, -0.95], [0.0, 0.0, 0.0],
                            [1.0, 1.0, 0.0]]))
    T = closest_normal_targets(N, S)
    np.testing.assert_array_equal(T, [[1, 0, 0], [0, 0, -1], [0, 0, 0], [1, 0, 0]])  # tie: first


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from(PRIMITIVES))
def test_closest_normal_targets_property(seed, name):
    S = primitive_normals(name)
    N = random_directions(50, seed)
    T = closest_normal_targets(N, S)
    # every target is a style normal, and no style normal is closer
    assert np.isclose(np.abs(T @ S.T - 1).min(axis=1), 0).all()
    assert ((N * T).sum(axis=1)[:, None] >= N @ S.T - 1e-12).all()


def test_closest_normals_from_a_convex_user_mesh():
    V, F = cube(3)
    cm = ClosestNormals.from_mesh(V, F)
    assert len(cm.style_normals) == 6
    np.testing.assert_allclose(np.sort(cm.style_normals, axis=0),
                               np.sort(primitive_normals("cube"), axis=0), atol=1e-12)
    D = random_directions(200)
    np.testing.assert_allclose(cm(D), ClosestNormals.primitive("cube")(D), atol=1e-12)
    Vi, Fi = icosahedron()
    assert len(mesh_style_normals(Vi, Fi)[0]) == 20


def test_user_mesh_inward_oriented_is_flipped_and_said():
    V, F = cube(1)
    cm = ClosestNormals.from_mesh(V, F[:, [0, 2, 1]])
    assert cm.notes and "inwards" in cm.notes[0]
    np.testing.assert_allclose(cm(np.array([[0.0, 0.0, 2.0]])), [[0, 0, 1]], atol=1e-12)


def test_user_mesh_refusals():
    V, F = torus()
    with pytest.raises(InvalidMeshError, match="not convex"):
        mesh_style_normals(V, F)
    Vc, Fc = cube(1)
    with pytest.raises(InvalidMeshError, match="holes"):
        mesh_style_normals(Vc, Fc[2:])
    with pytest.raises(ParameterError):
        ClosestNormals(np.zeros((2, 3)))


def test_target_maps_follow_the_protocol():
    assert isinstance(ClosestNormals.primitive("cube"), TargetMap)
    assert isinstance(CaptureSphere(1), TargetMap)


# ------------------------------------------------------------------------------ spherical maps
@pytest.fixture(scope="module")
def cube_map():
    V, F = cube(5)
    return SphericalStyleMap(V, F)


def test_spherical_map_of_a_cube_sends_the_axes_to_the_faces(cube_map):
    assert cube_map.flipped_faces == 0
    assert 1 <= cube_map.steps_taken <= 300
    np.testing.assert_allclose(np.linalg.norm(cube_map.sphere, axis=1), 1.0, atol=1e-12)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    np.testing.assert_allclose(cube_map(axes), axes, atol=1e-12)
    # conformal map of a cube: the regions of the faces almost match the closest-normal regions
    D = random_directions(4000, 1)
    agree = np.isclose((cube_map(D) * ClosestNormals.primitive("cube")(D)).sum(axis=1), 1.0)
    assert agree.mean() > 0.98


def test_spherical_map_point_location_is_exact(cube_map):
    D = random_directions(500, 2)
    faces, b = cube_map.locate(D)
    np.testing.assert_allclose(b.sum(axis=1), 1.0)
    assert (b >= 0).all()
    P = np.einsum("qc,qcx->qx", b, cube_map.sphere[cube_map.F[faces]])
    # the located point lies on the ray through d (the flat triangle, seen from the centre)
    np.testing.assert_allclose(unit_rows(P), D, atol=1e-9)


def test_spherical_map_of_a_sphere_is_nearly_the_identity():
    V, F = icosphere(3)
    m = SphericalStyleMap(V, F, interpolate="vertex")
    assert m.steps_taken < 20  # already round: the flow stops at once
    D = random_directions(1000, 3)
    ang = np.degrees(np.arccos(np.clip((m(D) * D).sum(axis=1), -1, 1)))
    assert ang.max() < 1.0
    assert np.array_equal(m(np.zeros((2, 3))), np.zeros((2, 3)))


def test_spherical_map_of_a_concave_genus0_shape():
    m = read_mesh(shared_mesh("spot_lowres.obj"))
    sm = SphericalStyleMap(m.V, m.F)
    assert sm.flipped_faces == 0 and sm.steps_taken <= 300
    D = random_directions(2000, 4)
    T = sm(D)
    np.testing.assert_allclose(np.linalg.norm(T, axis=1), 1.0, atol=1e-12)
    # every style face normal that comes back is one of spot's
    assert np.isin(sm.locate(D)[0], np.arange(len(sm.F))).all()
    # the map is orientation-preserving: on average a direction gets a target on its side
    assert (T * D).sum(axis=1).mean() > 0.5


def test_spherical_map_refuses_what_is_not_a_sphere():
    with pytest.raises(InvalidMeshError, match="genus 1"):
        SphericalStyleMap(*torus())
    V, F = icosphere(1)
    with pytest.raises(InvalidMeshError, match="2 separate parts"):
        SphericalStyleMap(np.vstack([V, V + 3]), np.vstack([F, F + len(V)]))
    with pytest.raises(InvalidMeshError, match="holes"):
        SphericalStyleMap(V, F[1:])
    Vn, Fn = np.vstack([V, [[0, 0, 2]]]), np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
    with pytest.raises(InvalidMeshError, match="not manifold"):
        SphericalStyleMap(Vn, Fn)
    with pytest.raises(ParameterError):
        SphericalStyleMap(V, F, interpolate="cubic")


# ------------------------------------------------------------------------------ captures
def test_capture_sphere_assigns_targets_by_region():
    cap = CaptureSphere(3)
    assert len(cap.vertices) == 642 and (cap.labels == -1).all()
    up = cap.paint_cap([0, 0, 1], 30, [1, 0, 0])
    down = cap.paint_cap([0, 0, -1], 20, [0, 1, 1])
    assert (up, down) == (0, 1) and cap.n_regions == 2
    N = unit_rows(np.array([[0.1, 0.0, 1.0], [0.0, -0.1, -1.0], [1.0, 0.2, 0.1], [0, 0, 0]]))
    T = cap(N)
    np.testing.assert_allclose(T[0], [1, 0, 0])
    np.testing.assert_allclose(T[1], [0, np.sqrt(0.5), np.sqrt(0.5)])
    np.testing.assert_allclose(T[2], N[2])  # unpainted: unchanged
    np.testing.assert_array_equal(T[3], 0)
    # a direction takes the label of its nearest sphere vertex
    D = random_directions(300, 5)
    lab = cap.labels[cap.nearest_vertex(D)]
    d2 = ((D[:, None, :] - cap.vertices[None]) ** 2).sum(axis=2)
    np.testing.assert_array_equal(lab, cap.labels[np.argmin(d2, axis=1)])
    cap.erase(np.flatnonzero(cap.labels == 0))
    np.testing.assert_allclose(cap(N[:1]), N[:1])


def test_capture_json_round_trip(tmp_path):
    cap = CaptureSphere(2)
    cap.paint_cap([1, 0, 0], 40, [0, 0, 1])
    cap.paint(np.arange(5), [0, -1, 0])
    path = tmp_path / "capture.json"
    cap.save(path)
    data = json.loads(path.read_text())
    assert data["format"] == CAPTURE_FORMAT and data["subdivisions"] == 2
    back = CaptureSphere.load(path)
    np.testing.assert_array_equal(back.labels, cap.labels)
    np.testing.assert_allclose(back.targets, cap.targets)
    D = random_directions(500, 6)
    np.testing.assert_array_equal(back(D), cap(D))


def test_capture_bad_files(tmp_path):
    with pytest.raises(ParameterError, match="does not exist"):
        CaptureSphere.load(tmp_path / "missing.json")
    p = tmp_path / "garbage.json"
    p.write_text("{not json")
    with pytest.raises(ParameterError, match="could not be read"):
        CaptureSphere.load(p)
    p.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ParameterError, match="not a valid normal capture"):
        CaptureSphere.load(p)
    bad = CaptureSphere(1).to_dict()
    bad["regions"] = [{"target": [0, 0, 1], "vertices": [999]}]
    p.write_text(json.dumps(bad))
    with pytest.raises(ParameterError, match="not on the sphere"):
        CaptureSphere.load(p)
    bad["regions"] = [{"target": [0, 0, 0], "vertices": [1]}]
    p.write_text(json.dumps(bad))
    with pytest.raises(ParameterError, match="non-zero"):
        CaptureSphere.load(p)
    with pytest.raises(ParameterError):
        CaptureSphere(1, labels=[0, 1])
    with pytest.raises(ParameterError):
        CaptureSphere(9)
