"""The guard's repair of crossings (issues 36 and 38): the previous level's own surface is
blended back in where the network's level crosses itself, away from the input's own
crossings."""

from __future__ import annotations

import numpy as np

from algorithms.mesh.intersections import (intersecting_pairs, new_crossing_pairs,
                                           new_crossing_pairs_away)
from algorithms.mesh.primitives import grid
from algorithms.subdivision.inference import (_blend_back_where_crossed, _Guard,
                                              midpoints_in_refine_numbering)
from algorithms.subdivision.topology import refine


def _two_sheets(gap: float = 0.1):
    V, F = grid(6, 6)
    top = V + [0.0, 0.0, gap]
    return np.vstack([V, top]), np.vstack([F, F[:, ::-1] + len(V)])


def test_the_previous_levels_surface_keeps_each_child_in_its_parents_plane():
    rng = np.random.default_rng(0)
    V, F = _two_sheets()
    V = V + 0.02 * rng.standard_normal(V.shape)
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    np.testing.assert_array_equal(VM[:len(V)], V)
    for f, kids in enumerate(F1.reshape(-1, 4, 3)):
        a, b, c = V[F[f]]
        n = np.cross(b - a, c - a)
        d = (VM[kids.ravel()] - a) @ n / np.linalg.norm(n)
        assert np.abs(d).max() < 1e-12
    # so a surface that does not cross itself gives a level that does not either
    assert len(intersecting_pairs(VM, F1)) == 0


def test_where_the_network_crosses_the_previous_levels_surface_is_blended_back_in():
    V, F = _two_sheets(0.1)
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    # the "network" pushes the middle of the top sheet through the bottom one
    V_net = VM.copy()
    top = np.arange(len(V_net)) >= 0
    top &= V_net[:, 2] > 0.05
    middle = top & (np.abs(V_net[:, 0] - 0.5) < 0.15) & (np.abs(V_net[:, 1] - 0.5) < 0.15)
    V_net[middle, 2] = -0.05

    def new_pairs(X):
        return new_crossing_pairs(intersecting_pairs(X, F1), 1, np.zeros((0, 2)))

    pairs = new_pairs(V_net)
    assert len(pairs) > 0
    out, moved, left = _blend_back_where_crossed(V_net, F1, V, F, pairs, new_pairs)
    assert left == 0 and len(new_pairs(out)) == 0
    changed = (out != V_net).any(axis=1)
    assert changed.any() and changed.sum() == moved
    # only around the crossing: the far corners of both sheets keep the network's positions
    corner = (np.abs(V_net[:, 0] - 0.5) > 0.4) & (np.abs(V_net[:, 1] - 0.5) > 0.4)
    assert not changed[corner].any()
    # crossings beside the input's own are left alone (away() finds none)
    out2, moved2, left2 = _blend_back_where_crossed(V_net, F1, V, F, pairs, new_pairs,
                                                    away=lambda P: P[:0])
    assert moved2 == 0 and left2 == 0
    np.testing.assert_array_equal(out2, V_net)


def test_crossings_beside_the_inputs_own_are_not_new():
    V, F = grid(10, 10)
    # face 10 i + j is the square (i, j) of the grid's first half: opposite corners
    known = np.array([[0, 99]])                # the input's own crossing pair
    kid = lambda f: 4 * f                       # noqa: E731 - a child of face f at level 1
    pairs = np.array([[kid(0), kid(99)],        # children of the known pair
                      [kid(1), kid(98)],        # beside it on both sides
                      [kid(1), kid(55)],        # beside it on one side only
                      [kid(44), kid(55)]])      # far from it
    assert len(new_crossing_pairs(pairs, 1, known)) == 3
    away = new_crossing_pairs_away(pairs, 1, F, known)
    np.testing.assert_array_equal(away, pairs[2:])
    # with no crossings in the input every new pair counts
    np.testing.assert_array_equal(new_crossing_pairs_away(pairs, 1, F, np.zeros((0, 2))), pairs)


def test_the_note_says_where_the_surface_was_left_unsmoothed():
    V, F = _two_sheets()
    g = _Guard(V, F)
    g.unsmoothed, g.blended_levels, g.crossings_seen = 12, [2], 7
    assert g.blend_note() == (
        "The network's result crossed itself in 7 places where the input does not; there the "
        "surface of the level before was blended back in (12 vertices, level 2, left "
        "unsmoothed).")


def test_pairs_the_previous_levels_own_surface_shows_are_left_alone():
    # two sheets lying on each other: the previous level's own surface "crosses" at this
    # resolution (as the touching coplanar slivers of a CAD part do), so nothing can mend it
    # and nothing is held (ADIS16480 was held over 8 rounds for 16 such pairs); they are
    # counted as left, so the note says so
    from algorithms.mesh.intersections import pairs_not_in

    V, F = _two_sheets(0.0)
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    own = intersecting_pairs(VM, F1)
    assert len(own) > 0
    np.testing.assert_array_equal(pairs_not_in(own, own[:, ::-1]), own[:0])
    np.testing.assert_array_equal(pairs_not_in(own, own[:3]), own[3:])
    def new_pairs(X):
        return intersecting_pairs(X, F1)

    out, moved, left = _blend_back_where_crossed(VM.copy(), F1, V, F, own, new_pairs)
    assert moved == 0
    assert left == len(own)            # left, and said
    np.testing.assert_array_equal(out, VM)


def _pushed_through(depth: float):
    """Two sheets 0.1 apart, refined once, with the middle of the top one pushed down to
    ``depth`` (through the bottom sheet at z = 0 when ``depth`` < 0)."""
    V, F = _two_sheets(0.1)
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    V_net = VM.copy()
    middle = ((V_net[:, 2] > 0.05) & (np.abs(V_net[:, 0] - 0.5) < 0.15)
              & (np.abs(V_net[:, 1] - 0.5) < 0.15))
    V_net[middle, 2] = depth

    def new_pairs(X):
        return new_crossing_pairs(intersecting_pairs(X, F1), 1, np.zeros((0, 2)))

    return V, F, F1, VM, V_net, new_pairs


def test_a_crossing_is_moved_back_only_as_far_as_it_takes():
    # pushed 0.02 through: a fraction of the way back to the previous level's surface ends it,
    # so the blend keeps more of the network's shape than going all the way back would
    V, F, F1, VM, V_net, new_pairs = _pushed_through(-0.02)
    assert len(new_pairs(V_net)) > 0
    out, moved, left = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs)
    assert left == 0 and len(new_pairs(out)) == 0
    step = np.linalg.norm(out - V_net, axis=1)
    full = np.linalg.norm(VM - V_net, axis=1)
    changed = step > 0
    assert changed.sum() == moved > 0
    # every moved vertex went less than all the way (the full blend would put the crossing
    # triangles' corners on VM), and the middle is still below where the previous level was
    assert (step[changed] < full[changed] - 1e-12).all()
    mid = V_net[:, 2] == -0.02
    assert (out[mid, 2] < VM[mid, 2] - 0.01).all() and (out[mid, 2] > 0).all()


def test_a_deep_crossing_still_gets_the_whole_blend():
    # pushed 0.5 through: only the full blend (weight 1 at the corners) clears the bottom sheet
    from algorithms.subdivision import inference

    V, F, F1, VM, V_net, new_pairs = _pushed_through(-0.5)
    out, moved, left = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs)
    assert left == 0 and len(new_pairs(out)) == 0
    mid = V_net[:, 2] == -0.5
    # the deepest corners are the crossing triangles', weight 1: back on the previous level
    assert np.isclose(out[mid, 2], VM[mid, 2]).any()
    assert max(inference.BLEND_FRACTIONS) < 1


def test_the_least_blend_looks_only_near_the_blend_and_finds_the_same():
    from algorithms.mesh.intersections import intersecting_pairs_touching

    V, F, F1, VM, V_net, new_pairs = _pushed_through(-0.02)

    def near(X, faces):
        return new_crossing_pairs(intersecting_pairs_touching(X, F1, faces), 1,
                                  np.zeros((0, 2)))

    a = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs)
    b = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs,
                                  new_pairs_near=near)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1:] == b[1:]


def test_parts_settling_at_different_fractions_report_exactly_their_crossings():
    """Two pushed-through spots of different depths, far apart on a finer grid: their blended
    parts settle at different fractions (the least blend re-tests only the parts that still
    move), and the crossing pairs returned with the result are exactly the result's, as a
    test of the whole mesh finds them."""
    from algorithms.subdivision.inference import BLEND_FRACTIONS, _least_blend
    from algorithms.mesh.topology import vertex_adjacency

    V0, F0 = grid(12, 12)
    top = V0 + [0.0, 0.0, 0.1]
    V = np.vstack([V0, top])
    F = np.vstack([F0, F0[:, ::-1] + len(V0)])
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    V_net = VM.copy()
    upper = V_net[:, 2] > 0.05
    for cx, depth in ((0.25, -0.02), (0.75, -0.3)):
        spot = upper & (np.abs(V_net[:, 0] - cx) < 0.08) & (np.abs(V_net[:, 1] - 0.5) < 0.08)
        V_net[spot, 2] = depth

    def new_pairs(X):
        return new_crossing_pairs(intersecting_pairs(X, F1), 1, np.zeros((0, 2)))

    pairs = new_pairs(V_net)
    assert len(pairs)
    # weight 1 on the crossing triangles' corners (both spots), as the blend rounds set it
    w = np.zeros(len(V_net))
    w[np.unique(F1[np.unique(pairs)])] = 1.0
    X, got = _least_blend(V_net, VM, w, vertex_adjacency(F1, len(V_net)), F1,
                          new_pairs(V_net + w[:, None] * (VM - V_net)), new_pairs)
    moved = np.abs(X - V_net).max(axis=1) > 0
    frac = np.abs(X - V_net)[moved, 2] / np.abs(VM - V_net)[moved, 2]
    fractions = set(np.round(frac, 6)) & set(BLEND_FRACTIONS + (1.0,))
    assert len(fractions) >= 2         # the two spots settled at different fractions
    want = {tuple(p) for p in np.sort(new_pairs(X), axis=1)}
    assert {tuple(p) for p in np.sort(got, axis=1)} == want


def test_the_widening_rounds_retest_only_what_moved_and_find_the_same(monkeypatch):
    """The blend's widening rounds re-test only the triangles whose corners' weights changed
    that round (the other pairs are the round before's): the same result as testing the whole
    mesh every round, on a wide deep push that takes three rounds."""
    from algorithms.mesh.intersections import intersecting_pairs_touching
    from algorithms.subdivision import inference

    V0, F0 = grid(12, 12)
    V = np.vstack([V0, V0 + [0.0, 0.0, 0.1]])
    F = np.vstack([F0, F0[:, ::-1] + len(V0)])
    F1 = refine(F, len(V))
    VM = midpoints_in_refine_numbering(V, F, F1)
    V_net = VM.copy()
    spot = ((V_net[:, 2] > 0.05) & (np.abs(V_net[:, 0] - 0.5) < 0.2)
            & (np.abs(V_net[:, 1] - 0.5) < 0.2))
    V_net[spot, 2] = -0.5

    def new_pairs(X):
        return new_crossing_pairs(intersecting_pairs(X, F1), 1, np.zeros((0, 2)))

    rounds, tested = [], []
    real = inference._rings
    monkeypatch.setattr(inference, "_rings", lambda *a, **k: rounds.append(1) or real(*a, **k))

    def near(X, faces):
        tested.append(len(faces))
        return new_crossing_pairs(intersecting_pairs_touching(X, F1, faces), 1,
                                  np.zeros((0, 2)))

    a = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs)
    assert len(rounds) == 3
    rounds.clear()
    b = _blend_back_where_crossed(V_net, F1, V, F, new_pairs(V_net), new_pairs,
                                  new_pairs_near=near)
    assert len(rounds) == 3 and a[2] == 0
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1:] == b[1:]
    # the later rounds test only part of the triangles that move
    moving = (np.abs(a[0] - V_net).max(axis=1) > 0)[F1].any(axis=1).sum()
    assert 0 < tested[1] < moving and 0 < tested[2] < moving
