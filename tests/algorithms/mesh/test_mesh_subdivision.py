"""Tests for algorithms.mesh.subdivision."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh.primitives import cube, grid, icosphere, torus
from algorithms.mesh.subdivision import loop_subdivide, midpoint_subdivide
from algorithms.mesh.topology import unique_edges
from algorithms.mesh.validate import validate_mesh


@pytest.mark.parametrize("subdivide", [loop_subdivide, midpoint_subdivide])
@pytest.mark.parametrize("maker", [lambda: icosphere(1), lambda: torus(n_major=8, n_minor=6), lambda: grid(3, 2)])
def test_counts_and_topology(subdivide, maker):
    V, F = maker()
    closed = validate_mesh(V, F).stats["closed"]
    Vk, Fk = V, F
    for level in (1, 2):
        nE = unique_edges(Fk)[0].shape[0]
        Vn, Fn = subdivide(V, F, level)
        assert Fn.shape == (F.shape[0] * 4**level, 3) and Fn.dtype == np.int64
        assert Vn.shape == (Vk.shape[0] + nE, 3) and Vn.dtype == np.float64
        r = validate_mesh(Vn, Fn)
        assert r.ok and not r.warnings
        assert r.stats["closed"] == closed
        assert r.stats["genus"] == validate_mesh(V, F).stats["genus"]
        Vk, Fk = Vn, Fn


def test_midpoint_keeps_shape():
    V, F = cube()
    Vn, Fn = midpoint_subdivide(V, F, 2)
    np.testing.assert_array_equal(Vn[: V.shape[0]], V)
    np.testing.assert_allclose(np.abs(Vn).max(axis=1), 1.0)  # still on the cube surface


def test_loop_of_icosphere_stays_near_sphere():
    V, F = icosphere(2)
    Vn, Fn = loop_subdivide(V, F, 2)
    r = np.linalg.norm(Vn, axis=1)
    assert r.max() <= 1.0 + 1e-9  # Loop shrinks convex shapes slightly
    assert r.min() > 0.97
    assert np.std(r) < 0.005
    # vertices move (unlike mid-point subdivision)
    assert not np.allclose(loop_subdivide(*cube(), 1)[0][:8], cube()[0])


def test_level_zero_returns_copies():
    V, F = icosphere(0)
    Vn, Fn = loop_subdivide(V, F, 0)
    np.testing.assert_array_equal(Vn, V)
    assert Vn is not V and not np.shares_memory(Vn, V)
    Vn, Fn = midpoint_subdivide(V, F, 0)
    np.testing.assert_array_equal(Fn, F)


def test_bad_input():
    V, F = icosphere(0)
    with pytest.raises(ParameterError, match="0 or more"):
        loop_subdivide(V, F, -1)
    with pytest.raises(ParameterError, match="whole number"):
        loop_subdivide(V, F, 1.5)
    with pytest.raises(ParameterError, match="limit"):
        midpoint_subdivide(V, F, 12)
    Vb = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], float)
    Fb = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(InvalidMeshError, match="non-manifold"):
        loop_subdivide(Vb, Fb)
    with pytest.raises(InvalidMeshError, match="do not exist"):
        midpoint_subdivide(V, F + 100)
    Vn = V.copy()
    Vn[0] = np.nan
    with pytest.raises(InvalidMeshError, match="NaN"):
        loop_subdivide(Vn, F)
    with pytest.raises(InvalidMeshError, match="same vertex twice"):
        loop_subdivide(V, np.vstack([F, [[0, 0, 1]]]))
    with pytest.raises(InvalidMeshError, match="no faces"):
        loop_subdivide(V, np.zeros((0, 3), int))
