"""Tests for algorithms.mesh.decimate: recorded edge collapses (progressive meshes)."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import read_mesh
from algorithms.mesh.decimate import (
    Decimation,
    _costs_vectorized,
    _Loop,
    decimate,
    vertex_quadrics,
)
from algorithms.mesh.operators import face_areas, face_normals, signed_volume
from algorithms.mesh.primitives import grid, icosphere, tetrahedron, torus
from algorithms.mesh.topology import (
    boundary_loops,
    connected_components,
    genus,
    is_manifold,
    unique_edges,
)
from tests.conftest import shared_mesh


def load(name):
    m = read_mesh(shared_mesh(name))
    return m.V, m.F


def check_valid(V, F):
    """Manifold, no repeated corners, no duplicate faces, no degenerate faces."""
    assert is_manifold(F)
    assert not ((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])).any()
    assert len(np.unique(np.sort(F, axis=1), axis=0)) == len(F)
    assert (face_areas(V, F) > 0).all()


# ------------------------------------------------------------------------------ topology
@pytest.mark.parametrize("name, target", [("spot_lowres.obj", 300), ("bob.obj", 1000),
                                          ("camelhead.off", 1500), ("fertility.off", 800)])
def test_keeps_manifoldness_genus_boundary_and_hits_the_target(name, target):
    V, F = load(name)
    d = decimate(V, F, target)
    assert d.reached_target and d.notes == []
    assert target - 1 <= len(d.F) <= target
    check_valid(d.V, d.F)
    assert genus(d.F) == genus(F)
    assert len(boundary_loops(d.F)) == len(boundary_loops(F))
    assert connected_components(d.F)[0] == connected_components(F)[0]
    # bookkeeping: every collapse removes one vertex and one or two faces
    assert len(d.V) == len(V) - len(d)
    assert len(d.F) == len(F) - len(d.removed_faces)


def test_genus_one_and_boundary_counts_of_the_shared_meshes():
    # the fixtures say what they are (bob genus 1, camelhead one boundary loop)
    assert genus(load("bob.obj")[1]) == 1
    assert len(boundary_loops(load("camelhead.off")[1])) == 1


@pytest.mark.parametrize("name, target", [("spot_lowres.obj", 100), ("camelhead.off", 400),
                                          ("bob.obj", 300)])
def test_replaying_every_split_reproduces_the_input_exactly(name, target):
    V, F = load(name)
    d = decimate(V, F, target)
    P, F2 = d.replay()
    assert np.array_equal(F2, F)  # same faces, same vertex ids, same order
    assert np.array_equal(P, V)  # bit for bit


def test_replay_with_a_position_function_sees_the_current_one_ring():
    V, F = load("spot_lowres.obj")
    d = decimate(V, F, 200)
    seen = []

    def fn(rec, P):
        # the kept vertex and its current neighbours exist, the removed one does not yet
        assert np.isfinite(P[rec.kept]).all() and np.isfinite(P[rec.ring]).all()
        assert np.isnan(P[rec.removed]).all()
        seen.append(rec.index)
        return rec.kept_position, rec.removed_position

    P, F2 = d.replay(position_fn=fn)
    assert seen == list(range(len(d) - 1, -1, -1))
    assert np.array_equal(P, V) and np.array_equal(F2, F)


def test_intermediate_levels_are_valid_meshes():
    V, F = load("camelhead.off")
    d = decimate(V, F, 600)
    for k in (0, len(d) // 3, 2 * len(d) // 3, len(d)):
        Vk, Fk = d.mesh_after(k)
        check_valid(Vk, Fk)
        assert len(boundary_loops(Fk)) == 1
        assert genus(Fk) == 0
    Vc, Fc = d.mesh_after(len(d))
    assert np.array_equal(Vc, d.V) and np.array_equal(Fc, d.F)


def test_records_are_consistent():
    V, F = load("bob.obj")
    d = decimate(V, F, 2000)
    assert isinstance(d, Decimation)
    for k in (0, 7, len(d) // 2, len(d) - 1):
        r = d.record(k)
        assert r.removed in r.ring_kept and r.kept in r.ring_removed
        assert r.kept not in r.ring and r.removed not in r.ring
        assert set(r.ring) == (set(r.ring_kept) | set(r.ring_removed)) - {r.kept, r.removed}
        assert len(r.removed_faces) == 2  # closed mesh: every edge is interior
        assert all({r.kept, r.removed} <= set(t) for t in r.removed_face_vertices)
        # just before collapse k, the changed faces had 'removed' at the recorded corner
        _, Fk = d.replay(until=k)
        alive = np.ones(len(F), bool)
        alive[d.removed_faces[:d.removed_faces_ptr[k]]] = False
        Fk_full = np.full((len(F), 3), -1)
        Fk_full[alive] = Fk
        assert (Fk_full[r.changed_faces, r.changed_corners] == r.removed).all()
        assert np.array_equal(Fk_full[r.removed_faces], r.removed_face_vertices)
    # all surviving vertices are ascending input ids; clusters cover every input vertex
    assert (np.diff(d.coarse_to_fine) > 0).all()
    lab = d.clusters()
    assert lab.min() == 0 and lab.max() == len(d.V) - 1
    assert (lab[d.coarse_to_fine] == np.arange(len(d.V))).all()
    assert (d.fine_to_coarse[d.removed] == -1).all()


def test_no_face_flips_and_closed_surface_stays_outward():
    V, F = icosphere(4)
    d = decimate(V, F, 100)
    check_valid(d.V, d.F)
    n = face_normals(d.V, d.F)
    c = d.V[d.F].mean(axis=1)
    assert (np.einsum("ij,ij->i", n, c) > 0).all()
    assert signed_volume(d.V, d.F) > 0


def test_qslim_keeps_a_sphere_round():
    V, F = icosphere(4)  # unit sphere
    d = decimate(V, F, 200)
    r = np.linalg.norm(d.V, axis=1)
    assert np.abs(r - 1).max() < 0.02
    m = decimate(V, F, 200, strategy="midpoint")
    assert np.abs(np.linalg.norm(m.V, axis=1) - 1).max() > np.abs(r - 1).max()


def test_boundary_vertices_stay_on_the_boundary():
    V, F = load("camelhead.off")
    d = decimate(V, F, 1000)
    fine_bnd = set(np.concatenate(boundary_loops(F)).tolist())
    coarse_bnd = d.coarse_to_fine[np.concatenate(boundary_loops(d.F))]
    assert set(coarse_bnd.tolist()) <= fine_bnd
    # a boundary vertex is never merged into an interior vertex
    for k in range(len(d)):
        if int(d.removed[k]) in fine_bnd:
            assert int(d.kept[k]) in fine_bnd


def test_grid_with_boundary_and_midpoint_strategy():
    V, F = grid(12, 12)
    d = decimate(V, F, 30, strategy="midpoint")
    check_valid(d.V, d.F)
    assert len(boundary_loops(d.F)) == 1
    # midpoint: the merged position is the midpoint unless one end is anchored to the boundary
    mid = 0.5 * (d.kept_position + d.removed_position)
    anchored = np.all(d.merged_position == d.kept_position, axis=1)
    assert np.allclose(d.merged_position[~anchored], mid[~anchored])
    P, F2 = d.replay()
    assert np.array_equal(P, V) and np.array_equal(F2, F)


def test_several_components_and_genus():
    V1, F1 = torus()
    V2, F2 = icosphere(2)
    V = np.vstack([V1, V2 + 5.0])
    F = np.vstack([F1, F2 + len(V1)])
    d = decimate(V, F, 150)
    check_valid(d.V, d.F)
    assert connected_components(d.F)[0] == 2
    assert genus(d.F) == 1


def test_kept_vertices_survive_unmoved():
    V, F = load("spot_lowres.obj")
    keep = np.array([0, 5, 100, 400])
    d = decimate(V, F, 150, keep=keep)
    f2c = d.fine_to_coarse
    assert (f2c[keep] >= 0).all()
    assert np.array_equal(d.V[f2c[keep]], V[keep])


def test_stops_and_says_so_when_the_target_cannot_be_reached():
    V, F = torus()
    d = decimate(V, F, 4)
    assert not d.reached_target
    assert "stopped" in d.notes[0]
    check_valid(d.V, d.F)
    assert genus(d.F) == 1
    V, F = tetrahedron()
    d = decimate(V, F, 1)
    assert len(d) == 0 and len(d.F) == 4 and not d.reached_target


def test_target_equal_to_input_collapses_nothing():
    V, F = icosphere(1)
    d = decimate(V, F, len(F))
    assert len(d) == 0 and np.array_equal(d.F, F) and np.array_equal(d.V, V)


def test_vectorized_initial_costs_match_the_loop():
    V, F = load("camelhead.off")
    E, _, counts = unique_edges(F)
    bnd = np.zeros(len(V), bool)
    bnd[E[counts == 1].ravel()] = True
    Q = vertex_quadrics(V, F)
    protect = np.zeros(len(V), bool)
    protect[::97] = True
    rng = np.random.default_rng(0)
    for strategy in ("qslim", "midpoint"):
        sel = rng.choice(len(E), 300, replace=False)
        sel = np.concatenate([sel, np.flatnonzero(counts == 1)[:50]])
        a, b = E[sel, 0], E[sel, 1]
        aa = protect[a] | (bnd[a] & ~bnd[b])
        ab = protect[b] | (bnd[b] & ~bnd[a])
        Qs = Q[a] + Q[b] if strategy == "qslim" else np.zeros((len(a), 10))
        cost, pos, keep_a = _costs_vectorized(Qs, V[a], V[b], aa, ab, strategy)
        loop = _Loop(V, F, Q, bnd, protect, strategy, 0.2)
        for t in range(len(sel)):
            ent = loop.entry(int(a[t]), int(b[t]))
            if ent is None:
                assert not np.isfinite(cost[t])
                continue
            assert ent[0] == pytest.approx(cost[t], rel=1e-6, abs=1e-12 * (1 + abs(cost).max()))
            assert np.allclose(ent[7:10], pos[t], rtol=1e-9, atol=1e-12)
            assert ent[6] == keep_a[t]


def test_quadric_of_a_vertex_vanishes_at_the_vertex():
    V, F = icosphere(2)
    Q = vertex_quadrics(V, F)
    x, y, z = V.T
    err = (Q[:, 0] * x * x + 2 * Q[:, 1] * x * y + 2 * Q[:, 2] * x * z + Q[:, 3] * y * y
           + 2 * Q[:, 4] * y * z + Q[:, 5] * z * z + 2 * (Q[:, 6] * x + Q[:, 7] * y + Q[:, 8] * z)
           + Q[:, 9])
    assert np.abs(err).max() < 1e-12


# ------------------------------------------------------------------------------ errors
def test_errors_are_plain():
    V, F = icosphere(1)
    with pytest.raises(ParameterError, match="larger than the mesh"):
        decimate(V, F, len(F) + 1)
    with pytest.raises(ParameterError, match="at least 1"):
        decimate(V, F, 0)
    with pytest.raises(ParameterError, match="whole number"):
        decimate(V, F, 10.5)
    with pytest.raises(ParameterError, match="strategy"):
        decimate(V, F, 10, strategy="fast")
    with pytest.raises(ParameterError, match="do not exist"):
        decimate(V, F, 10, keep=[len(V)])
    bad = V.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InvalidMeshError, match="NaN"):
        decimate(bad, F, 10)
    with pytest.raises(InvalidMeshError, match="do not exist"):
        decimate(V, F + 100, 10)
    # three triangles on one edge
    Vn = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], float)
    Fn = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(InvalidMeshError, match="more than two triangles"):
        decimate(Vn, Fn, 1)
    d = decimate(V, F, 40)
    with pytest.raises(ParameterError, match="shape"):
        d.replay(np.zeros((3, 3)))
    with pytest.raises(ParameterError, match="until"):
        d.replay(until=len(d) + 1)
