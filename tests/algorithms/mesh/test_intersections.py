"""Counting the self-intersections a deformation made (algorithms.mesh.intersections)."""

import numpy as np

from algorithms.mesh.intersections import crossings_away_from, intersecting_pairs_here
from tests.conftest import unit_square_grid


def _two_sheets(shift_x: float = 0.0, through: bool = False):
    """A horizontal 8 x 8 grid (z = 0) and a vertical one (x = 0.5 + shift_x) through it, plus
    a small upright square far from the vertical sheet, above the floor or (``through``)
    through it."""
    V, F = unit_square_grid(8)
    W = V[:, [2, 0, 1]].copy()  # the vertical sheet: x = 0, spans y and z in [0, 1]
    W[:, 0] = 0.5 + shift_x
    W[:, 2] -= 0.5
    z0 = -0.05 if through else 0.05
    S = np.array([[0.05, 0.1, z0], [0.15, 0.1, z0], [0.15, 0.1, z0 + 0.1], [0.05, 0.1, z0 + 0.1]])
    n, k = len(V), len(W)
    P = np.vstack([V, W, S])
    T = np.vstack([F, F + n, np.array([[0, 1, 2], [0, 2, 3]]) + n + k])
    return P, T


def test_a_crossing_that_moves_is_not_a_new_one_and_a_crossing_elsewhere_is():
    P0, T = _two_sheets()
    before = intersecting_pairs_here(P0, T)
    assert len(before) > 0  # the two sheets cross along a line
    P1, _ = _two_sheets(shift_x=0.3)  # the vertical sheet moved by two grid steps
    after = intersecting_pairs_here(P1, T)
    assert len(after) > 0
    # none of these triangle pairs crossed before, and they lie two rings away: not made
    assert crossings_away_from(after, T, before, rings=1) == len(after)
    assert crossings_away_from(after, T, before) == 0
    P2, _ = _two_sheets(shift_x=0.3, through=True)  # the small square pushed through
    after2 = intersecting_pairs_here(P2, T)
    made = crossings_away_from(after2, T, before)
    assert made > 0 and made == len(after2) - len(after)
    # with no crossing before, every pair counts
    assert crossings_away_from(after2, T, np.zeros((0, 2), np.int64)) == len(after2)
    assert crossings_away_from(np.zeros((0, 2), np.int64), T, before) == 0


def test_the_pairs_touching_some_triangles_are_the_whole_meshs_pairs_with_one_of_them():
    """intersecting_pairs_touching_here looks at the given triangles and those whose bounding
    boxes may overlap theirs only; its answer must be exactly the whole-mesh test's pairs with
    a given triangle: for random sets, clustered sets, the empty set, every triangle, and with
    a few triangles far larger than the others (the grid's cells are sized on the 90th
    percentile: a large one is always looked at, and a large given one covers all its cells)."""
    from algorithms.mesh.intersections import intersecting_pairs_touching_here

    from algorithms.mesh import icosphere

    rng = np.random.default_rng(3)
    V, F = icosphere(4)
    V = V.copy()
    jitter = rng.random(len(V)) < 0.3
    V[jitter] += rng.normal(scale=0.03, size=(jitter.sum(), 3))   # crossings here and there
    P, T = _two_sheets(through=True)
    # a long sliver through the sphere, and the two sheets far off to one side
    V = np.vstack([V, P + [3.0, 0.0, 0.0], [[-1.5, 0.0, 0.01], [1.5, 0.0, 0.0], [1.5, 0.02, 0.0]]])
    F = np.vstack([F, T + len(V) - len(P) - 3, [[len(V) - 3, len(V) - 2, len(V) - 1]]])
    whole = intersecting_pairs_here(V, F)
    assert len(whole) > 20 and (whole == len(F) - 1).any()     # the sliver crosses the sphere
    m = len(F)
    centre = V[F].mean(axis=1)
    sets = [np.zeros(m, bool), np.ones(m, bool), rng.random(m) < 0.01, rng.random(m) < 0.2,
            np.linalg.norm(centre - centre[7], axis=1) < 0.3,           # a clustered patch
            np.arange(m) == m - 1,                                       # the sliver alone
            np.isin(np.arange(m), whole[(whole == m - 1).any(axis=1)]) & (np.arange(m) < m - 1)]
    # (the last: the sphere's triangles the sliver crosses, without it)
    for mask in sets:
        want = whole[mask[whole].any(axis=1)]
        got = intersecting_pairs_touching_here(V, F, mask)
        assert sorted(map(tuple, np.sort(got, 1).tolist())) == \
            sorted(map(tuple, np.sort(want, 1).tolist()))
        # indices instead of a mask: the same
        got_i = intersecting_pairs_touching_here(V, F, np.flatnonzero(mask))
        assert len(got_i) == len(got)
    assert len(intersecting_pairs_touching_here(V, F, sets[1])) == len(whole)


def test_the_pairs_touching_some_triangles_on_degenerate_boxes_look_at_every_triangle():
    # all corners on one point (boxes of size 0), or one far-off triangle that would make the
    # grid's cell keys overflow: the whole mesh is looked at, and the answer is still the
    # whole-mesh test's
    from algorithms.mesh.intersections import (_aabb_neighbours,
                                               intersecting_pairs_touching_here)

    P, T = _two_sheets()
    flat = np.zeros_like(P)
    assert _aabb_neighbours(flat, T, np.arange(len(T)) == 0).all()
    far = np.vstack([P, [[1e18, 0, 0], [1e18 + 1024, 0, 0], [1e18, 1, 0]]])
    T2 = np.vstack([T, [[len(P), len(P) + 1, len(P) + 2]]])
    mask = np.arange(len(T2)) < 10
    assert _aabb_neighbours(far, T2, mask).all()
    # and a triangle far enough off that the grid has too many cells for a table (its cells
    # are then looked up in the sorted list of the marked ones): still only the neighbours
    mid = far.copy()
    mid[len(P):] -= [1e18 - 1e6, 0, 0]
    near = _aabb_neighbours(mid, T2, mask)
    assert not near.all() and near[mask].all()
    for X in (far, mid):
        whole = intersecting_pairs_here(X, T2)
        for m in (mask, ~mask):
            got = intersecting_pairs_touching_here(X, T2, m)
            assert sorted(map(tuple, np.sort(got, 1).tolist())) == \
                sorted(map(tuple, np.sort(whole[m[whole].any(axis=1)], 1).tolist()))


def test_the_compiled_box_test_marks_the_same_triangles_as_the_numpy_one():
    """Random sets of triangles (a few, many, a ball-shaped patch) of a real mesh, with and
    without a huge triangle, and the degenerate cases above: the compiled cells give the same
    mask as the NumPy code, bit for bit (it is a superset filter; the same one is what keeps
    Paparazzi's runs the same)."""
    import pytest

    from algorithms.mesh import intersections as I
    from algorithms.mesh import read_mesh
    from tests.conftest import ROOT

    if I._KERNELS.get() is None:
        pytest.skip("Numba is not available")
    m = read_mesh(str(ROOT / "tests" / "data" / "camelhead.off"))
    V, F = m.V, m.F
    rng = np.random.default_rng(7)
    C = V[F].mean(axis=1)
    masks = [np.isin(np.arange(len(F)), rng.choice(len(F), k, replace=False))
             for k in (1, 40, len(F) // 3)]
    masks.append(np.linalg.norm(C - C[len(F) // 2], axis=1) < 0.1 * np.ptp(V, axis=0).max())
    huge = V.copy()
    huge[F[5, 0]] += 0.7 * np.ptp(V, axis=0)        # one big triangle, among the queries or not
    P, T = _two_sheets()
    far = np.vstack([P, [[1e18, 0, 0], [1e18 + 1024, 0, 0], [1e18, 1, 0]]])
    T2 = np.vstack([T, [[len(P), len(P) + 1, len(P) + 2]]])
    mid = far.copy()
    mid[len(P):] -= [1e18 - 1e6, 0, 0]
    cases = [(X, F, mk) for X in (V, huge) for mk in masks + [~masks[0]]]
    cases += [(np.zeros_like(P), T, np.arange(len(T)) == 0),
              (far, T2, np.arange(len(T2)) < 10), (mid, T2, np.arange(len(T2)) < 10)]
    for X, G, mk in cases:
        before = I._KERNELS.set(False)
        try:
            want = I._aabb_neighbours(X, G, mk)
        finally:
            I._KERNELS.set(before)
        got = I._aabb_neighbours(X, G, mk)
        assert np.array_equal(got, want)
        assert got[mk].all()
