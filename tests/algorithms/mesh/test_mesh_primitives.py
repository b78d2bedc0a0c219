"""Tests for algorithms.mesh.primitives: closed, manifold, outward, expected genus and counts."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import primitives as P
from algorithms.mesh.operators import face_areas, signed_volume
from algorithms.mesh.topology import boundary_loops, genus, halfedge_twins
from algorithms.mesh.validate import validate_mesh


def assert_closed_outward(V, F, g):
    assert V.dtype == np.float64 and F.dtype == np.int64
    assert V.ndim == 2 and V.shape[1] == 3 and F.shape[1] == 3
    report = validate_mesh(V, F)
    assert report.ok and not report.warnings, report.summary()
    assert report.stats["closed"] and report.stats["manifold"] and report.stats["components"] == 1
    assert report.stats["genus"] == g == genus(F)
    assert (halfedge_twins(F) >= 0).all()  # consistently oriented, no boundary
    assert signed_volume(V, F) > 0
    assert face_areas(V, F).min() > 0


@pytest.mark.parametrize(
    "name,nv,nf",
    [("tetrahedron", 4, 4), ("cube", 8, 12), ("hexahedron", 8, 12), ("octahedron", 6, 8),
     ("icosahedron", 12, 20), ("dodecahedron", 20, 36)],
)
def test_platonic_solids(name, nv, nf):
    V, F = P.platonic_solid(name)
    assert V.shape == (nv, 3) and F.shape == (nf, 3)
    np.testing.assert_allclose(np.linalg.norm(V, axis=1), 1.0, rtol=1e-12)
    assert_closed_outward(V, F, 0)
    # all edges of a regular solid have the same length (ignoring pentagon diagonals)
    E = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    lengths = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    assert lengths.min() == pytest.approx(np.sort(lengths)[0])
    if name not in ("dodecahedron", "cube", "hexahedron"):
        assert np.ptp(lengths) < 1e-12


def test_named_functions_match_platonic_solid():
    for name in ("tetrahedron", "octahedron", "icosahedron", "dodecahedron"):
        V1, F1 = getattr(P, name)()
        V2, F2 = P.platonic_solid(name)
        np.testing.assert_array_equal(V1, V2)
        np.testing.assert_array_equal(F1, F2)
    with pytest.raises(ParameterError, match="Choose one of"):
        P.platonic_solid("sphere")


@pytest.mark.parametrize("s", [0, 1, 3])
def test_cube(s):
    V, F = P.cube(s)
    k = s + 1
    assert V.shape == (6 * k * k + 2, 3) and F.shape == (12 * k * k, 3)
    np.testing.assert_allclose(np.abs(V).max(axis=1), 1.0)  # every vertex on the surface of [-1,1]^3
    assert_closed_outward(V, F, 0)
    assert signed_volume(V, F) == pytest.approx(8.0)
    assert face_areas(V, F).sum() == pytest.approx(24.0)
    V, F = P.cube(s, size=1.0)
    assert V.min() == -0.5 and V.max() == 0.5


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_icosphere(k):
    V, F = P.icosphere(k, radius=2.5)
    assert V.shape == (10 * 4**k + 2, 3) and F.shape == (20 * 4**k, 3)
    np.testing.assert_allclose(np.linalg.norm(V, axis=1), 2.5, rtol=1e-12)
    assert_closed_outward(V, F, 0)


def test_torus():
    V, F = P.torus(R=2.0, r=0.5, n_major=30, n_minor=12)
    assert V.shape == (360, 3) and F.shape == (720, 3)
    assert_closed_outward(V, F, 1)
    # distance from the tube centre circle is r
    rho = np.hypot(V[:, 0], V[:, 1])
    np.testing.assert_allclose(np.hypot(rho - 2.0, V[:, 2]), 0.5, rtol=1e-12)
    with pytest.raises(ParameterError, match="smaller than R"):
        P.torus(R=1, r=1)
    with pytest.raises(ParameterError, match="at least 3"):
        P.torus(n_major=2)


def test_grid():
    V, F = P.grid(4, 3)
    assert V.shape == (20, 3) and F.shape == (24, 3)
    assert V[:, 2].max() == 0 and V[:, :2].min() == 0 and V[:, :2].max() == 1
    np.testing.assert_array_equal(V[1 * 4 + 2], [0.25, 2 / 3, 0])
    assert face_areas(V, F).sum() == pytest.approx(1.0)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert (n[:, 2] > 0).all()
    loops = boundary_loops(F)
    assert len(loops) == 1 and len(loops[0]) == 14
    r = validate_mesh(V, F)
    assert r.ok and not r.warnings and r.stats["genus"] == 0
    with pytest.raises(ParameterError, match="whole number"):
        P.grid(2.5, 2)
    with pytest.raises(ParameterError, match="at least 1"):
        P.grid(0, 2)


@pytest.mark.parametrize("name,g", sorted(P.ORGANIC_SAMPLES.items()))
def test_organic_samples(name, g):
    V, F = P.organic_sample(name)
    assert 2000 <= V.shape[0] <= 6000
    assert_closed_outward(V, F, g)
    side = V.max(axis=0) - V.min(axis=0)
    assert side.max() == pytest.approx(1.0)
    np.testing.assert_allclose((V.max(axis=0) + V.min(axis=0)) / 2, 0, atol=1e-12)
    # reasonable triangles after relaxation (no slivers from marching cubes)
    a = np.linalg.norm(V[F[:, 1]] - V[F[:, 2]], axis=1)
    b = np.linalg.norm(V[F[:, 2]] - V[F[:, 0]], axis=1)
    c = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1)
    quality = 4 * np.sqrt(3) * face_areas(V, F) / (a * a + b * b + c * c)
    assert quality.min() > 0.2 and quality.mean() > 0.85


def test_organic_sample_unknown():
    with pytest.raises(ParameterError, match="blob"):
        P.organic_sample("teapot")


def test_parameter_validation():
    with pytest.raises(ParameterError):
        P.icosphere(-1)
    with pytest.raises(ParameterError):
        P.icosphere(2, radius=0)
    with pytest.raises(ParameterError):
        P.cube("two")
