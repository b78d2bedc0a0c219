import igl
import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.mesh.subdivision import midpoint_subdivide
from algorithms.subdivision.data import subdivision_positions
from algorithms.subdivision.topology import half_flaps, igl_odd_order, refine

DATA = "tests/data/"


@pytest.mark.parametrize("name", ["hand_lowres.obj", "spot_lowres.obj"])
def test_refine_is_libigl_midpoint_subdivision_in_our_order(name):
    m = read_mesh(DATA + name)
    n = len(m.V)
    hf = half_flaps(m.F, n)
    ours_F = refine(m.F, n, hf.EF)
    ours_V = np.concatenate([m.V, 0.5 * (m.V[hf.E[:, 0]] + m.V[hf.E[:, 1]])])
    NV, NF = midpoint_subdivide(m.V, m.F, 1)
    perm = igl_odd_order(m.F, n, hf.E)
    np.testing.assert_allclose(NV[n:][perm], ours_V[n:], atol=1e-12)
    # same faces once libigl's vertices are renamed to ours
    rename = np.arange(len(NV))
    rename[n + perm] = n + np.arange(len(perm))
    key = lambda F: set(map(tuple, np.sort(F, axis=1)))  # noqa: E731
    assert key(rename[NF]) == key(ours_F)
    # and orientation is kept: every directed edge of ours appears in libigl's faces
    d = lambda F: set(map(tuple, np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])))  # noqa: E731
    assert d(rename[NF]) == d(ours_F)


def test_igl_loop_uses_the_same_vertex_order_as_upsample():
    m = read_mesh(DATA + "spot_lowres.obj")
    _, NFu = igl.upsample(m.V, m.F, 1)
    _, NFl = igl.loop(m.V, m.F, 1)
    assert np.array_equal(NFu, NFl)


def test_half_flaps_boundary_and_twins():
    m = read_mesh(DATA + "hand_lowres.obj")
    hf = half_flaps(m.F, len(m.V))
    i, j, k, l = hf.ijkl.T
    assert (hf.boundary.sum()) > 0
    inner = ~hf.boundary
    # the fourth vertex is the third corner of the twin face
    tf = m.F[hf.twin_face[inner]]
    assert ((tf == l[inner, None]).any(1) & (tf == i[inner, None]).any(1)
            & (tf == j[inner, None]).any(1)).all()
    assert (l[hf.boundary] == -1).all()
    # every vertex is the source of exactly its number of faces
    assert np.array_equal(np.bincount(i, minlength=len(m.V)),
                          np.bincount(m.F.ravel(), minlength=len(m.V)))


def test_subdivision_positions_reproduce_midpoint_subdivision():
    m = read_mesh(DATA + "spot_lowres.obj")
    levels = subdivision_positions(m.F, len(m.V), 2)
    NV, _ = midpoint_subdivide(m.V, m.F, 2)
    F2, face, bary = levels[2]
    P = np.einsum("qi,qij->qj", bary, m.V[m.F[face]])
    assert len(P) == len(NV)
    # the same point set as libigl's two mid-point levels
    from scipy.spatial import cKDTree

    assert cKDTree(NV).query(P)[0].max() < 1e-12
    assert cKDTree(P).query(NV)[0].max() < 1e-12
    assert (bary >= 0).all() and np.allclose(bary.sum(1), 1)


def test_split_vertex_order_recovers_another_numbering():
    """Two levels of refine, with the new vertices of each level renumbered at random (as
    another program may number them): split_vertex_order finds the renumbering."""
    import numpy as np

    from algorithms.mesh import read_mesh
    from algorithms.subdivision.topology import refine, split_vertex_order

    m = read_mesh("tests/data/hand_lowres.obj")  # open: boundary edges too
    rng = np.random.default_rng(0)
    F, n = m.F, len(m.V)
    theirs_faces, maps = [], []
    for _ in range(2):
        Fn = refine(F, n)
        nn = int(Fn.max()) + 1
        p = np.r_[np.arange(n), n + rng.permutation(nn - n)]  # ours -> theirs (this level)
        maps.append(p)
        F, n = Fn, nn
    # theirs at level 2 numbers its level-1 vertices as their level 1 does
    F1 = refine(m.F, len(m.V))
    theirs1 = maps[0][F1]
    n1 = int(F1.max()) + 1
    F2 = refine(F1, n1)
    full = np.r_[maps[0], maps[1][n1:]]  # ours(level 2) -> theirs(level 2)
    theirs2 = full[F2]
    order = split_vertex_order(m.F, len(m.V), [theirs1, theirs2])
    assert np.array_equal(order, full)
