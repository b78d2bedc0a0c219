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


@pytest.mark.parametrize("name", ["blob", "bumpy", "hand", "open"])
def test_loop_is_libigls_loop_bit_for_bit(name):
    """Our Loop (built from undirected edges, safe on any orientation) gives the same bits as
    libigl's ``igl.loop`` on the oriented meshes it handles: 1 and 2 levels, closed and open."""
    import igl

    from algorithms.mesh import read_mesh
    from algorithms.mesh.samples import sample_path
    from tests.conftest import ROOT

    if name == "hand":
        m = read_mesh(ROOT / "tests" / "data" / "hand_lowres.obj")
        V, F = m.V, m.F
    elif name == "open":
        V, F = grid(9, 7)
        V = V + 0.05 * np.sin(7 * V[:, [1, 2, 0]])
    else:
        m = read_mesh(sample_path(name))
        V, F = m.V, m.F
    for levels in (1, 2):
        ours = loop_subdivide(V, F, levels)
        theirs = igl.loop(V, F, levels)
        np.testing.assert_array_equal(ours[1], theirs[1])
        np.testing.assert_array_equal(ours[0], theirs[0])


def test_loop_on_a_one_sided_strip_is_safe_and_smooth():
    """``igl.loop`` aborted the process ("double free or corruption") on a Moebius strip; ours
    subdivides it: each face in four, boundary vertices on the boundary rule, nothing moves
    farther than an edge."""
    from tests.algorithms.subdivision.test_baselines import _moebius

    V, F = _moebius(40)
    for levels in (1, 2, 3):
        V2, F2 = loop_subdivide(V, F, levels)
        assert len(F2) == len(F) * 4 ** levels and np.isfinite(V2).all()
        assert np.abs(V2[:len(V)] - V).max() < 0.1
    # the one-level matrix: rows sum to one (an affine combination), on a strip and a grid
    from algorithms.mesh.subdivision import loop_matrix

    for VV, FF in (_moebius(40), grid(5, 4)):
        S, _ = loop_matrix(FF, len(VV))
        np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0, atol=1e-14)
