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
