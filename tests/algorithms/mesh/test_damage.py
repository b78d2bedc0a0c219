"""algorithms.mesh.damage: collapsed triangles (the fold test lives with the corpus script's,
tests/test_benchmarks_corpus.py, which measures with the same function)."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import icosphere
from algorithms.mesh.damage import collapsed_triangles, folded_triangles


def test_a_triangle_squashed_to_a_line_is_collapsed_and_one_already_flat_is_not():
    V, F = icosphere(2)
    assert not collapsed_triangles(V, V, F).any()
    a, b, c = F[0]
    W = V.copy()
    W[c] = 0.5 * (W[a] + W[b])  # onto the opposite edge: zero area
    hit = collapsed_triangles(V, W, F)
    assert hit[0] and hit.sum() >= 1
    assert not collapsed_triangles(W, W, F).any()  # the input's own are not "made"
    assert not folded_triangles(V, W, F)[0]  # no normal to judge: left to the collapse count
