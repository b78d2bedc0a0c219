"""Tests for algorithms.mesh.topology, compared with libigl where they overlap."""

from __future__ import annotations


import igl
import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.errors import InvalidMeshError
from algorithms.mesh import topology as T
from algorithms.mesh.io import read_mesh
from algorithms.mesh.primitives import cube, grid, icosphere, organic_sample, torus
from tests.conftest import mobius_strip, shared_mesh



def shared(name):
    m = read_mesh(shared_mesh(name))
    return m.V, m.F


def two_cones_tip_to_tip():
    """Two triangle fans sharing only their apex vertex 0 (non-manifold vertex)."""
    k = 5
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
    ring1 = np.column_stack([np.cos(ang), np.sin(ang), np.ones(k)])
    ring2 = np.column_stack([np.cos(ang), np.sin(ang), -np.ones(k)])
    V = np.vstack([[0, 0, 0], ring1, ring2, [0, 0, 1], [0, 0, -1]])
    F = []
    for i in range(k):
        j = (i + 1) % k
        F += [[0, 1 + j, 1 + i], [1 + i, 1 + j, 11]]  # upper cone + cap
        F += [[0, 6 + i, 6 + j], [6 + j, 6 + i, 12]]  # lower cone + cap
    return V, np.array(F)


# --------------------------------------------------------------------------------------------


def test_halfedges_layout():
    F = np.array([[0, 1, 2], [2, 1, 3]])
    H = T.halfedges(F)
    np.testing.assert_array_equal(H, [[1, 2], [1, 3], [2, 0], [3, 2], [0, 1], [2, 1]])


def test_unique_edges_small():
    F = np.array([[0, 1, 2], [2, 1, 3]])
    E, EMAP, counts = T.unique_edges(F)
    np.testing.assert_array_equal(E, [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]])
    np.testing.assert_array_equal(np.sort(T.halfedges(F), axis=1), E[EMAP])
    np.testing.assert_array_equal(counts, [1, 1, 2, 1, 1])


@pytest.mark.parametrize("mesh", ["torus", "grid", "bunny"])
def test_unique_edges_match_libigl(mesh):
    V, F = {"torus": torus, "grid": lambda: grid(5, 7), "bunny": lambda: shared("stanford-bunny.obj")}[mesh]()
    E, EMAP, counts = T.unique_edges(F)
    _, uE, EMAPi, *_ = igl.unique_edge_map(F)
    assert E.shape == uE.shape
    assert np.all(E[:, 0] < E[:, 1])
    assert np.all(np.diff(E[:, 0] * (E.max() + 1) + E[:, 1]) > 0)  # lexicographically sorted
    np.testing.assert_array_equal(E[EMAP], np.sort(uE[EMAPi], axis=1))
    np.testing.assert_array_equal(np.bincount(EMAP, minlength=E.shape[0]), counts)


def _compare_flaps(F):
    E, EMAP, EF, EI = T.edge_flaps(F)
    Ei, EMAPi, EFi, EIi = igl.edge_flaps(F)
    n = F.max() + 1
    key_i = np.minimum(Ei[:, 0], Ei[:, 1]) * n + np.maximum(Ei[:, 0], Ei[:, 1])
    idx = np.searchsorted(E[:, 0] * n + E[:, 1], key_i)
    swapped = (Ei[:, 0] > Ei[:, 1])[:, None]
    np.testing.assert_array_equal(np.where(swapped, EF[idx][:, ::-1], EF[idx]), EFi)
    np.testing.assert_array_equal(np.where(swapped, EI[idx][:, ::-1], EI[idx]), EIi)
    # definition check: EF[e,0] runs E[e,0] -> E[e,1] opposite corner EI[e,0]
    m = F.shape[0]
    for k in (0, 1):
        ok = EF[:, k] >= 0
        f, c = EF[ok, k], EI[ok, k]
        start = F[f, (c + 1) % 3]
        end = F[f, (c + 2) % 3]
        np.testing.assert_array_equal(start, E[ok, k])
        np.testing.assert_array_equal(end, E[ok, 1 - k])
        np.testing.assert_array_equal(EMAP[c * m + f], np.flatnonzero(ok))


def test_edge_flaps_match_libigl():
    _compare_flaps(torus(n_major=9, n_minor=7)[1])
    _compare_flaps(grid(4, 3)[1])
    _compare_flaps(organic_sample("pretzel")[1])


@pytest.mark.parametrize("name", ["hand_lowres.obj", "camelhead.off", "fertility.off"])
def test_edge_flaps_match_libigl_shared(name):
    _compare_flaps(shared(name)[1])


def test_edge_flaps_rejects_nonmanifold_and_inconsistent():
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(InvalidMeshError, match="shared by more than two triangles"):
        T.edge_flaps(F)
    F = np.array([[0, 1, 2], [0, 1, 3]])  # same direction on edge 0-1
    with pytest.raises(InvalidMeshError, match="oriented inconsistently"):
        T.edge_flaps(F)
    with pytest.raises(InvalidMeshError, match="oriented inconsistently"):
        T.halfedge_twins(F)


def test_halfedge_twins():
    V, F = torus(n_major=8, n_minor=6)
    H = T.halfedges(F)
    twin = T.halfedge_twins(F)
    assert (twin >= 0).all()
    np.testing.assert_array_equal(H[twin], H[:, ::-1])
    np.testing.assert_array_equal(twin[twin], np.arange(H.shape[0]))
    V, F = grid(3, 2)
    twin = T.halfedge_twins(F)
    assert (twin < 0).sum() == 2 * (3 + 2)
    inner = twin >= 0
    H = T.halfedges(F)
    np.testing.assert_array_equal(H[twin[inner]], H[inner][:, ::-1])


def test_faces_input_checks():
    with pytest.raises(InvalidMeshError, match=r"\(m, 3\)"):
        T.unique_edges(np.array([[0, 1, 2, 3]]))
    with pytest.raises(InvalidMeshError, match="negative"):
        T.unique_edges(np.array([[0, -1, 2]]))
    with pytest.raises(InvalidMeshError, match="whole numbers"):
        T.unique_edges(np.array([[0, 1.5, 2]]))
    with pytest.raises(InvalidMeshError, match="only 2 vertices"):
        T.vertex_adjacency(np.array([[0, 1, 2]]), n=2)
    E, EMAP, counts = T.unique_edges(np.zeros((0, 3), int))
    assert E.shape == (0, 2) and EMAP.size == 0


def test_vertex_adjacency_matches_libigl():
    V, F = icosphere(2)
    A = T.vertex_adjacency(F)
    Ai = igl.adjacency_matrix(F)
    assert sp.isspmatrix_csr(A) and A.dtype == np.float64
    assert (A != Ai).nnz == 0
    A2 = T.vertex_adjacency(F, n=V.shape[0] + 3)
    assert A2.shape == (V.shape[0] + 3,) * 2 and A2[-3:].nnz == 0


def test_vertex_face_adjacency():
    V, F = cube()
    VF = T.vertex_face_adjacency(F)
    assert VF.shape == (8, 12)
    for v in range(8):
        faces = VF.indices[VF.indptr[v] : VF.indptr[v + 1]]
        np.testing.assert_array_equal(faces, np.flatnonzero((F == v).any(axis=1)))
    assert set(VF.data) == {1.0}
    VF = T.vertex_face_adjacency(np.array([[0, 0, 1]]), n=3)  # repeated corner counts once
    np.testing.assert_array_equal(VF.toarray(), [[1], [1], [0]])


def test_face_adjacency_matches_libigl():
    V, F = torus(n_major=10, n_minor=6)
    A = T.face_adjacency(F)
    TT, _ = igl.triangle_triangle_adjacency(F)
    m = F.shape[0]
    rows = np.repeat(np.arange(m), 3)
    B = sp.csr_matrix((np.ones(3 * m), (rows, TT.ravel())), shape=(m, m))
    assert (A != B).nnz == 0
    # non-manifold edge: all three faces mutually adjacent
    A = T.face_adjacency(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])).toarray()
    np.testing.assert_array_equal(A, 1 - np.eye(3))


def test_manifold_checks_match_libigl():
    V, F = two_cones_tip_to_tip()
    np.testing.assert_array_equal(T.nonmanifold_vertices(F), [0])
    np.testing.assert_array_equal(~igl.is_vertex_manifold(F), np.arange(V.shape[0]) == 0)
    assert T.is_edge_manifold(F) and not T.is_vertex_manifold(F) and not T.is_manifold(F)
    F2 = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    np.testing.assert_array_equal(T.nonmanifold_edges(F2), [[0, 1]])
    assert not T.is_edge_manifold(F2)
    assert not igl.is_edge_manifold(F2)[0]
    assert T.is_manifold(torus()[1])


def test_shared_meshes_are_vertex_manifold_like_libigl():
    V, F = shared("stanford-bunny.obj")
    ours = np.zeros(V.shape[0], bool)
    ours[T.nonmanifold_vertices(F, V.shape[0])] = True
    ref = igl.is_vertex_manifold(F)
    used = np.zeros(V.shape[0], bool)
    used[F.ravel()] = True
    np.testing.assert_array_equal(~ours[used], ref[used])


def _same_loop(a, b):
    if len(a) != len(b) or a[0] not in b:
        return False
    k = list(b).index(a[0])
    return np.array_equal(np.roll(np.asarray(b), -k), a)


@pytest.mark.parametrize("mesh", ["grid", "bunny", "camelhead", "hand"])
def test_boundary_loops_match_libigl(mesh):
    F = {
        "grid": lambda: grid(6, 4)[1],
        "bunny": lambda: shared("stanford-bunny.obj")[1],
        "camelhead": lambda: shared("camelhead.off")[1],
        "hand": lambda: shared("hand_lowres.obj")[1],
    }[mesh]()
    loops = T.boundary_loops(F)
    ref = igl.boundary_loop_all(F)
    assert len(loops) == len(ref)
    for loop in loops:
        assert loop.dtype == np.int64
        assert loop[0] == loop.min()
        assert any(_same_loop(loop, r) for r in ref), "loop differs from libigl (order/direction)"
    assert [len(x) for x in loops] == sorted((len(x) for x in loops), reverse=True)
    longest = igl.boundary_loop(F)
    assert _same_loop(loops[0], longest)
    # direction: consecutive loop vertices form half-edges of faces
    H = {tuple(h) for h in T.halfedges(F).tolist()}
    for loop in loops:
        assert all((int(a), int(b)) in H for a, b in zip(loop, np.roll(loop, -1)))


def test_bunny_boundary_counts():
    F = shared("stanford-bunny.obj")[1]
    loops = T.boundary_loops(F)
    assert len(loops) == 5 and sum(len(x) for x in loops) == 223
    assert T.boundary_edges(F).shape == (223, 2)


def test_boundary_loops_closed_and_touching():
    assert T.boundary_loops(icosphere(1)[1]) == []
    # two triangles touching at vertex 0: two loops, each a simple cycle
    F = np.array([[0, 1, 2], [0, 3, 4]])
    loops = T.boundary_loops(F)
    assert sorted(map(tuple, loops)) == [(0, 1, 2), (0, 3, 4)]
    with pytest.raises(InvalidMeshError):
        T.boundary_loops(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))


def test_connected_components():
    V1, F1 = icosphere(1)
    V2, F2 = torus(n_major=8, n_minor=5)
    F = np.vstack([F2 + V1.shape[0], F1])
    n = V1.shape[0] + V2.shape[0] + 2  # two unreferenced vertices at the end
    count, labels = T.connected_components(F, n)
    assert count == 2 and labels.shape == (F.shape[0],)
    np.testing.assert_array_equal(labels, np.r_[np.zeros(F2.shape[0]), np.ones(F1.shape[0])])
    count_v, vlabels = T.connected_components(F, n, over="vertices")
    assert count_v == 4 and vlabels.shape == (n,)
    assert len(set(vlabels[V1.shape[0]:n - 2])) == 1 and vlabels[-1] != vlabels[-2]
    ncc, fc = igl.facet_components(F)
    assert ncc == 2
    with pytest.raises(ValueError):
        T.connected_components(F, over="edges")


def test_euler_characteristic_matches_libigl():
    for V, F in (icosphere(2), torus(), grid(3, 3), organic_sample("pretzel")):
        assert T.euler_characteristic(F) == igl.euler_characteristic(F)
    assert T.euler_characteristic(icosphere(1)[1]) == 2
    assert T.euler_characteristic(torus()[1]) == 0
    # unreferenced vertices do not count
    F = icosphere(1)[1] + 5
    assert T.euler_characteristic(F) == 2


def test_genus():
    assert T.genus(icosphere(2)[1]) == 0
    assert T.genus(torus()[1]) == 1
    assert T.genus(grid(3, 3)[1]) == 0
    assert T.genus(organic_sample("pretzel")[1]) == 2
    # sphere + torus: sum of per-component genera
    V1, F1 = icosphere(1)
    F = np.vstack([F1, torus()[1] + V1.shape[0]])
    assert T.genus(F) == 1
    np.testing.assert_array_equal(T.genus(F, per_component=True), [0, 1])
    # a torus with a hole cut in it: still genus 1
    Ft = torus(n_major=48, n_minor=24)[1]
    holed = np.delete(Ft, [0, 48 * 24], axis=0)  # both triangles of one quad
    assert T.genus(holed) == 1 and len(T.boundary_loops(holed)) == 1


@pytest.mark.parametrize("name,g", [("fertility.off", 4), ("bob.obj", 1), ("rocker-arm.obj", 1), ("camelhead.off", 0), ("stanford-bunny.obj", 0)])
def test_genus_shared(name, g):
    V, F = shared(name)
    assert T.genus(F, V.shape[0]) == g


def test_genus_rejects_bad_meshes():
    with pytest.raises(InvalidMeshError, match="more than two triangles"):
        T.genus(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))
    with pytest.raises(InvalidMeshError, match="join separate pieces"):
        T.genus(two_cones_tip_to_tip()[1])
    with pytest.raises(InvalidMeshError, match="not orientable"):
        T.genus(mobius_strip()[1])
    with pytest.raises(InvalidMeshError, match="empty"):
        T.genus(np.zeros((0, 3), int))


def test_orient_consistently_restores_orientation():
    V, F = icosphere(2)
    rng = np.random.default_rng(3)
    flip = rng.random(F.shape[0]) < 0.4
    flip[0] = False  # the first face keeps its orientation
    Fb = F.copy()
    Fb[flip] = Fb[flip][:, [0, 2, 1]]
    G, flipped, orientable = T.orient_consistently(Fb)
    assert orientable
    np.testing.assert_array_equal(flipped, flip)
    np.testing.assert_array_equal(G, F)
    # igl agrees that the result is consistent
    T.edge_flaps(G)


def test_orient_consistently_mobius_and_nonmanifold():
    V, F = mobius_strip()
    _, _, orientable = T.orient_consistently(F)
    assert not orientable
    with pytest.raises(InvalidMeshError):
        T.orient_consistently(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))


def test_referenced_vertices():
    mask = T.referenced_vertices(np.array([[0, 2, 3]]), n=5)
    np.testing.assert_array_equal(mask, [True, False, True, True, False])


def test_topology_on_igea():
    # speed is measured in benchmarks/mesh_core.py; here: the large closed mesh is consistent
    V, F = shared("igea.ply")
    E, _, counts = T.unique_edges(F)
    assert len(E) == 3 * len(F) // 2 and (counts == 2).all()
    assert T.boundary_loops(F) == []
    assert T.connected_components(F, V.shape[0])[0] == 1
    assert T.genus(F, V.shape[0]) == 0


def test_touching_parts_counts_parts_near_another_part():
    import numpy as np

    from algorithms.mesh.primitives import icosphere
    from algorithms.mesh.topology import touching_parts

    V, F = icosphere(2)
    assert touching_parts(V, F) == (1, 0)
    for gap, touching in ((0.0, 2), (0.5, 0)):
        V2 = np.concatenate([V, V + [2.0 + gap, 0, 0], V + [9.0, 0, 0], [[50.0, 0, 0]]])
        F2 = np.concatenate([F, F + len(V), F + 2 * len(V)])  # + one loose vertex: ignored
        assert touching_parts(V2, F2) == (3, touching)
