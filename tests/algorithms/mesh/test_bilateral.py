"""Bilateral normal filtering (Zheng et al. 2011), the non-image peer of Paparazzi's guided
filter (issue 23): one pass against a hand-written sum, a crease kept where the range weight
is small, and a noisy cube brought back towards the clean one with its creases."""

from __future__ import annotations

import numpy as np

from algorithms.mesh.bilateral import (BilateralNormalParams, bilateral_normal_filter,
                                       bilateral_normal_filter_iter, filter_face_normals)
from algorithms.mesh.operators import face_areas, face_normals, vertex_normals
from algorithms.mesh.primitives import cube, grid


def _fold():
    """A 4 x 2 strip folded 90 degrees along x = 1: faces on z = 0 (x <= 1) and x = 1 (up)."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 1, 0], [1, 1, 0], [1, 1, 1],
                  [0, 2, 0], [1, 2, 0], [1, 2, 1]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4],
                  [3, 4, 7], [3, 7, 6], [4, 5, 8], [4, 8, 7]])
    return V, F


def test_one_pass_is_the_papers_weighted_sum_written_out():
    V, F = _fold()
    rng = np.random.default_rng(3)
    N = face_normals(V, F) + 0.1 * rng.standard_normal((len(F), 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    got = filter_face_normals(V, F, N, sigma_s=0.7, sigma_r=0.5)
    C = V[F].mean(1)
    A = face_areas(V, F)
    for i in range(len(F)):
        s = np.zeros(3)
        for j in range(len(F)):
            if set(F[i]) & set(F[j]):          # shares a vertex (itself included)
                s += (A[j] * np.exp(-np.sum((C[i] - C[j]) ** 2) / (2 * 0.7 ** 2))
                      * np.exp(-np.sum((N[i] - N[j]) ** 2) / (2 * 0.5 ** 2)) * N[j])
        np.testing.assert_allclose(got[i], s / np.linalg.norm(s), atol=1e-12)


def test_a_small_normal_range_keeps_the_crease_a_large_one_rounds_it():
    V, F = _fold()
    N = face_normals(V, F)
    kept = filter_face_normals(V, F, N, sigma_s=1.0, sigma_r=0.2)
    np.testing.assert_allclose(kept, N, atol=1e-6)       # |n_i - n_j| = 1.41 >> 0.2
    rounded = filter_face_normals(V, F, N, sigma_s=1.0, sigma_r=10.0)
    assert np.degrees(np.arccos(np.clip((rounded * N).sum(1), -1, 1))).min() > 10


def test_vertices_fit_a_noisy_plane_to_its_filtered_normals_and_the_border_stays():
    V, F = grid(12, 12)                                  # z = 0
    rng = np.random.default_rng(0)
    noisy = V.copy()
    noisy[:, 2] += 0.02 * rng.standard_normal(len(V))
    out = bilateral_normal_filter(noisy, F, BilateralNormalParams(normal_iterations=10,
                                                                  vertex_iterations=30))
    from algorithms.mesh.topology import boundary_edges

    b = np.unique(boundary_edges(F).ravel())
    np.testing.assert_array_equal(out[b], noisy[b])
    inner = np.setdiff1d(np.arange(len(V)), b)
    # the inner vertices' heights around the plane fitted to the border shrink a lot
    assert np.std(out[inner, 2]) < 0.5 * np.std(noisy[inner, 2])


def test_a_noisy_cube_comes_back_close_to_the_clean_one_with_sharp_creases():
    V, F = cube(6)
    h = 2.0 / 6
    rng = np.random.default_rng(1)
    noisy = V + (0.15 * h * rng.standard_normal(len(V)))[:, None] * vertex_normals(V, F)
    steps = list(bilateral_normal_filter_iter(noisy, F, BilateralNormalParams()))
    assert len(steps) == 30 and steps[-1].fraction == 1.0
    assert steps[0].metrics["normal_change"] > steps[19].metrics["normal_change"]
    out = steps[-1].V
    N0 = face_normals(V, F)

    def err(X):
        return np.degrees(np.arccos(np.clip((face_normals(X, F) * N0).sum(1), -1, 1))).mean()

    assert err(out) < 0.3 * err(noisy), (err(noisy), err(out))
    assert np.abs(out - V).mean() < 0.6 * np.abs(noisy - V).mean()
    # the faces along the cube's edges keep their side's normal (a rounded crease would tilt
    # them by tens of degrees)
    worst = np.degrees(np.arccos(np.clip((face_normals(out, F) * N0).sum(1), -1, 1)))
    assert np.percentile(worst, 95) < 5.0, np.percentile(worst, 95)
