import numpy as np

from algorithms.mesh import icosphere, read_mesh
from algorithms.subdivision.metrics import (coarsen_to_vertices, evaluate_protocol,
                                            sample_surface, surface_distances)


def test_identical_meshes_are_at_distance_zero():
    V, F = icosphere(2)
    d = surface_distances(V, F, V, F, samples=5000)
    assert d["hausdorff"] < 1e-9 and d["mean_distance"] < 1e-9


def test_scaled_sphere_distances_in_percent_of_the_diagonal():
    V, F = icosphere(4)
    d = surface_distances(1.1 * V, F, V, F, samples=20000)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    # every point of the scaled sphere is ~0.1 away (up to the tessellation's sagitta)
    assert abs(d["hausdorff_abs"] - 0.1) < 0.01
    assert abs(d["mean_abs"] - 0.1) < 0.01
    assert np.isclose(d["hausdorff"], 100 * d["hausdorff_abs"] / diag)


def test_samples_are_area_uniform():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0.0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])  # areas 0.5 and 4.5
    P = sample_surface(V, F, 20000, seed=1)
    in_small = (P[:, 0] + P[:, 1] <= 1 + 1e-12).mean()
    assert abs(in_small - 0.1) < 0.01


def test_protocol_runs_on_a_real_mesh():
    m = read_mesh("tests/data/spot_lowres.obj")
    Vc, Fc = coarsen_to_vertices(m.V, m.F, 400)
    assert 390 <= len(Vc) <= 410
    from algorithms.subdivision.baselines import subdivide_baseline

    rows = evaluate_protocol([("spot", m.V, m.F)],
                             {k: (lambda V, F, L, k=k: subdivide_baseline(V, F, L, k))
                              for k in ("loop", "butterfly", "midpoint")}, samples=20000)
    r = rows[0]["methods"]
    assert 350 <= rows[0]["coarse_vertices"] <= 450
    # Loop shrinks the shape: farther on average than the interpolating schemes
    assert r["loop"]["mean_distance"] > r["butterfly"]["mean_distance"]
    assert all(v["hausdorff"] >= v["mean_distance"] > 0 for v in r.values())
