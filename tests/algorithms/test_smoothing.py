from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import igl
from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.linalg import SPDSolver
from algorithms.mesh import icosphere, read_mesh
from algorithms.mesh.operators import cotangent_laplacian, face_areas, mass_matrix
from algorithms.smoothing import SmoothParams, smooth, smooth_iter
from tests.conftest import shared_mesh


def noisy_sphere(seed=0):
    V, F = icosphere(3)
    rng = np.random.default_rng(seed)
    return V + 0.03 * rng.standard_normal(V.shape), F


def test_one_laplacian_step_solves_the_backward_euler_system():
    V, F = noisy_sphere()
    p = SmoothParams(step_size=1e-3, iterations=1, keep_size=False)
    V1 = smooth(V, F, p)
    L = igl.cotmatrix(V, F)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_BARYCENTRIC)
    h = 1e-3 * face_areas(V, F).sum()
    expected = spla.spsolve((M - h * L).tocsc(), M @ V)
    np.testing.assert_allclose(V1, expected, atol=1e-10)


def bending_energy(V, F):
    """Independent discrete ∫H² dA: libigl's cotangent matrix with *Voronoi* areas."""
    L = igl.cotmatrix(V, F)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal()
    hn = (L @ V) / M[:, None]
    return float((M * (hn ** 2).sum(axis=1)).sum() / 4)


@pytest.mark.parametrize("flow", ["laplacian", "cmcf", "mcf"])
def test_bending_energy_falls_and_size_is_kept(flow):
    V, F = noisy_sphere(1)
    steps = list(smooth_iter(V, F, SmoothParams(flow=flow, step_size=1e-3, iterations=5)))
    E = [s.metrics["bending_energy"] for s in steps]
    assert all(b < a for a, b in zip(E, E[1:])), E
    assert E[-1] < 0.5 * bending_energy(V, F)
    from algorithms.mesh import signed_volume
    assert signed_volume(steps[-1].V, F) == pytest.approx(signed_volume(V, F), rel=1e-9)
    assert [s.iteration for s in steps] == [1, 2, 3, 4, 5] and steps[-1].total == 5


def test_bending_energy_metric_matches_libigl_on_a_sphere():
    V, F = icosphere(4)
    # one negligible step leaves the sphere as it is; its metric is the sphere's ∫H² = 4π
    step = next(smooth_iter(V, F, SmoothParams(step_size=1e-7, iterations=1)))
    assert step.metrics["bending_energy"] == pytest.approx(4 * np.pi, rel=0.01)
    assert bending_energy(V, F) == pytest.approx(4 * np.pi, rel=0.02)


def test_smoothing_removes_noise_on_a_real_mesh():
    data = read_mesh(shared_mesh("spot_lowres.obj"))
    V, F = data.V, data.F
    rng = np.random.default_rng(2)
    noisy = V + 0.01 * rng.standard_normal((len(V), 1)) * igl.per_vertex_normals(V, F)
    out = smooth(noisy, F, SmoothParams(step_size=2e-5, iterations=3))
    assert np.linalg.norm(out - V) < 0.95 * np.linalg.norm(noisy - V)
    assert bending_energy(out, F) < 0.9 * bending_energy(noisy, F)
    # the enclosed volume is kept (closed mesh)
    from algorithms.mesh import signed_volume
    assert signed_volume(out, F) == pytest.approx(signed_volume(noisy, F), rel=1e-9)


def test_noisy_sphere_becomes_round():
    V, F = noisy_sphere(5)
    out = smooth(V, F, SmoothParams(step_size=1e-3, iterations=5))
    r_in, r_out = np.linalg.norm(V, axis=1), np.linalg.norm(out, axis=1)
    assert r_out.std() < 0.2 * r_in.std()


def test_keep_size_off_shrinks_a_closed_mesh():
    V, F = icosphere(2)
    out = smooth(V, F, SmoothParams(flow="mcf", step_size=5e-3, iterations=3, keep_size=False))
    assert face_areas(out, F).sum() < 0.95 * face_areas(V, F).sum()


def test_fixed_boundary_stays_put():
    from algorithms.mesh import grid
    from algorithms.mesh.topology import boundary_loops

    V, F = grid(12, 12)
    rng = np.random.default_rng(3)
    V = V.copy()
    V[:, 2] += 0.05 * rng.standard_normal(len(V))
    b = np.concatenate(boundary_loops(F))
    out = smooth(V, F, SmoothParams(step_size=1e-2, iterations=4, fix_boundary=True))
    np.testing.assert_array_equal(out[b], V[b])
    inner = np.setdiff1d(np.arange(len(V)), b)
    assert np.abs(out[inner, 2]).std() < np.abs(V[inner, 2]).std()


def test_bad_inputs_raise_plain_errors():
    V, F = icosphere(1)
    Vn = V.copy()
    Vn[0, 0] = np.nan
    with pytest.raises(InvalidMeshError, match="NaN"):
        next(smooth_iter(Vn, F))
    with pytest.raises(InvalidMeshError):
        next(smooth_iter(V, np.zeros((0, 3), np.int64)))
    with pytest.raises(ParameterError):
        next(smooth_iter(V, F, SmoothParams(iterations=0)))


def test_spd_solver_with_dirichlet_matches_dense():
    V, F = icosphere(2)
    A = (mass_matrix(V, F) - 0.1 * cotangent_laplacian(V, F)).tocsc()
    rng = np.random.default_rng(4)
    fixed = np.array([0, 5, 17])
    b = rng.standard_normal((len(V), 2))
    xc = rng.standard_normal((3, 2))
    x = SPDSolver(A, fixed).solve(b, xc)
    Ad = A.toarray()
    free = np.setdiff1d(np.arange(len(V)), fixed)
    ref = np.linalg.solve(Ad[np.ix_(free, free)], b[free] - Ad[np.ix_(free, fixed)] @ xc)
    np.testing.assert_allclose(x[free], ref, atol=1e-10)
    np.testing.assert_array_equal(x[fixed], xc)


def test_loose_points_stay_and_degenerate_faces_are_refused():
    V, F = icosphere(2)
    V2 = np.vstack([V, [[5.0, 5.0, 5.0]]])  # an unreferenced vertex
    out = smooth(V2, F, SmoothParams(iterations=2))
    np.testing.assert_array_equal(out[-1], V2[-1])
    np.testing.assert_allclose(out[:-1], smooth(V, F, SmoothParams(iterations=2)), atol=1e-12)
    Fd = np.vstack([F, [[0, 0, 1]]])  # a zero-area triangle
    with pytest.raises(InvalidMeshError, match="Clean"):
        next(smooth_iter(V, Fd))


@pytest.mark.parametrize("flow", ["laplacian", "cmcf", "mcf"])
def test_multigrid_steps_match_the_direct_steps(flow):
    """``multigrid=``: every flow's steps by V-cycles on one hierarchy (the matrix of cMCF / MCF
    changes every step) equal the factorized steps; area falls (thesis Fig. 8.23)."""
    from algorithms.multigrid import surface_multigrid

    V, F = icosphere(4)
    V = V * np.array([1.0, 0.7, 0.5]) + 0.01 * np.random.default_rng(5).standard_normal(V.shape)
    mg = surface_multigrid(V, F, min_vertices=100)
    assert mg.n_levels >= 3
    params = SmoothParams(flow=flow, step_size=1e-3, iterations=4, keep_size=False)
    direct = list(smooth_iter(V, F, params))
    multi = list(smooth_iter(V, F, params, multigrid=mg, multigrid_rtol=1e-10))
    areas = [face_areas(V, F).sum()] + [face_areas(s.V, F).sum() for s in multi]
    assert all(areas[i + 1] < areas[i] for i in range(4))
    for a, b in zip(multi, direct):
        assert np.abs(a.V - b.V).max() < 1e-8
        assert a.metrics["cycles"] >= 1 and "cycles" not in b.metrics


def test_multigrid_steps_keep_a_fixed_boundary():
    from algorithms.mesh import grid
    from algorithms.mesh.topology import boundary_loops
    from algorithms.multigrid import surface_multigrid

    V, F = grid(40, 40)
    V = V.copy()
    V[:, 2] += 0.05 * np.random.default_rng(3).standard_normal(len(V))
    mg = surface_multigrid(V, F, min_vertices=200)
    params = SmoothParams(flow="cmcf", step_size=1e-2, iterations=3, fix_boundary=True)
    out = smooth_iter(V, F, params, multigrid=mg, multigrid_rtol=1e-10)
    last = list(out)[-1].V
    b = np.concatenate(boundary_loops(F))
    np.testing.assert_array_equal(last[b], V[b])
    np.testing.assert_allclose(last, smooth(V, F, params), atol=1e-8)
    with pytest.raises(InvalidMeshError, match="another mesh"):
        next(smooth_iter(V[:-1], F[:10], params, multigrid=mg))


def test_default_flow_smooths_armadillo_without_spikes():
    """Issue 10: the defaults must improve a real mesh, never wreck it (the former default
    raised armadillo's bending energy from 328 to 578 and grew spikes)."""
    from algorithms.mesh import read_mesh
    from algorithms.mesh.topology import unique_edges
    from tests.conftest import shared_mesh

    d = read_mesh(shared_mesh("armadillo.obj"))
    E, _, _ = unique_edges(d.F)
    edge = float(np.linalg.norm(d.V[E[:, 0]] - d.V[E[:, 1]], axis=1).mean())
    X = d.V
    energies = []
    for st in smooth_iter(d.V, d.F, SmoothParams()):
        assert np.linalg.norm(st.V - X, axis=1).max() < 2.0 * edge  # no vertex runs away
        X = st.V
        energies.append(st.metrics["bending_energy"])
    assert all(b < a for a, b in zip(energies, energies[1:]))
    assert energies[-1] < 0.6 * energies[0]
    # the old default on the same mesh: the check above catches it
    old = [st.metrics["bending_energy"] for st in
           smooth_iter(d.V, d.F, SmoothParams(flow="laplacian", step_size=1e-4))]
    assert old[-1] > old[0]


def test_each_part_is_smoothed_as_if_it_were_alone():
    """Issue 38: the time step was sized by the whole mesh's area, so a tiny part got a step
    thousands of times too large, collapsed to a point and made the system singular ("Factor is
    exactly singular" on four corpus meshes). Each part now has its own step."""
    Vb, Fb = noisy_sphere(2)
    Vs, Fs = noisy_sphere(3)
    Vs = 0.01 * Vs + np.array([3.0, 0.0, 0.0])  # a part 10,000 times smaller in area
    V = np.vstack([Vb, Vs])
    F = np.vstack([Fb, Fs + len(Vb)])
    p = SmoothParams(step_size=1e-3, iterations=5, keep_size=False)
    both = smooth(V, F, p)
    np.testing.assert_allclose(both[len(Vb):], smooth(Vs, Fs, p), rtol=0, atol=1e-12)
    np.testing.assert_allclose(both[:len(Vb)], smooth(Vb, Fb, p), rtol=0, atol=1e-10)
    small = face_areas(both[len(Vb):], Fs).sum()
    assert 0.5 * face_areas(Vs, Fs).sum() < small  # not collapsed


def test_open_borders_stay_by_default_and_their_triangles_do_not_collapse():
    """Issue 38: free borders were pulled in and the strips of triangles along them collapsed
    to zero area within three steps on scans (bending energy NaN). ``fix_boundary`` is now on
    by default; closed meshes are not affected."""
    from algorithms.mesh import grid
    from algorithms.mesh.topology import boundary_loops

    assert SmoothParams().fix_boundary
    V, F = grid(20, 20)
    rng = np.random.default_rng(5)
    V = V.copy()
    V[:, 2] += 0.02 * rng.standard_normal(len(V))
    b = np.concatenate(boundary_loops(F))
    steps = list(smooth_iter(V, F, SmoothParams()))
    out = steps[-1].V
    np.testing.assert_array_equal(out[b], V[b])
    assert all(np.isfinite(s.metrics["bending_energy"]) for s in steps)
    assert (face_areas(out, F) / face_areas(V, F)).min() > 0.1
    # a closed mesh: the same result with the setting on or off (it has no border)
    Vc, Fc = noisy_sphere(4)
    np.testing.assert_array_equal(smooth(Vc, Fc, SmoothParams()),
                                  smooth(Vc, Fc, SmoothParams(fix_boundary=False)))


# --- hold_crossings (issue 38) ----------------------------------------------------------------
def _new_crossings(V0, V, F) -> int:
    from algorithms.mesh.intersections import intersecting_pairs_here, new_crossings_away_from

    return len(new_crossings_away_from(intersecting_pairs_here(V, F), F,
                                       intersecting_pairs_here(V0, F)))


@pytest.mark.parametrize("flow,step", [("cmcf", 1e-4), ("laplacian", 3e-4), ("mcf", 1e-4)])
def test_steps_that_would_cross_the_surface_are_held_and_the_rest_still_smooths(flow, step):
    """fertility's arms pull through each other at a strong step (measured: cMCF 57 new
    crossing pairs, the fixed-operator flow 21, MCF 3,366, and triangles fold over or collapse
    on the way); held, none is left, the rest still
    moves and the result is no rougher than the flow's own (at this step the arms pinch: the
    bending energy rises with or without the hold)."""
    m = read_mesh(shared_mesh("fertility.off"))
    V, F = m.V, m.F
    *_, free = smooth_iter(V, F, SmoothParams(flow=flow, step_size=step, hold_crossings=False))
    assert _new_crossings(V, free.V, F) >= 20  # the case this test is about
    assert "crossings_checked" not in free.metrics
    steps = list(smooth_iter(V, F, SmoothParams(flow=flow, step_size=step)))
    last = steps[-1]
    assert _new_crossings(V, last.V, F) == 0  # counted independently of the metrics
    met = last.metrics
    assert met["crossings_checked"] == 1.0 and met["crossings_left"] == 0.0
    assert met["crossings_made"] >= 1 and 0 < met["held_vertices"] < 0.2 * len(V)
    assert [s.metrics["held_vertices"] for s in steps] == sorted(
        s.metrics["held_vertices"] for s in steps)  # once held, held to the end
    assert met["folded_left"] == 0.0
    assert last.message.startswith("Its steps would have pushed the surface through itself in "
                                   f"{int(met['crossings_made'])} place(s)")
    if met["folded_made"]:  # holding the first folds also kept many crossings from happening
        assert f"and folded over or collapsed {int(met['folded_made'])} triangle(s)" in \
            last.message
    assert last.message.endswith("none is left.")
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert face_areas(last.V, F).min() > 1e-12 * diag ** 2  # nothing collapsed
    e_free, e_held = bending_energy(free.V, F), bending_energy(last.V, F)
    assert np.isfinite(e_held)  # MCF's own result has collapsed triangles there (NaN)
    assert not np.isfinite(e_free) or e_held <= e_free
    assert last.metrics["moved"] > 0.5 * free.metrics["moved"]


def test_a_flow_that_crosses_nothing_is_unchanged_by_the_hold():
    V, F = noisy_sphere()
    p = SmoothParams(step_size=1e-4, iterations=5)
    held = list(smooth_iter(V, F, p))
    free = list(smooth_iter(V, F, SmoothParams(step_size=1e-4, iterations=5,
                                                hold_crossings=False)))
    np.testing.assert_array_equal(held[-1].V, free[-1].V)
    assert held[-1].metrics["crossings_made"] == 0 and held[-1].metrics["held_vertices"] == 0
    assert held[-1].message == "step 5/5"


def test_above_the_size_limit_crossings_are_not_checked_and_that_is_said(monkeypatch):
    import algorithms.deform.collisions as collisions

    V, F = noisy_sphere()
    monkeypatch.setattr(collisions, "CHECK_MAX_FACES", len(F) - 1)
    last = list(smooth_iter(V, F, SmoothParams(iterations=2)))[-1]
    assert last.metrics["crossings_checked"] == 0.0
    assert "not checked" in last.message


def test_a_flow_whose_system_turns_singular_stops_with_advice_and_the_hold_avoids_it():
    """Mean curvature flow at a large step collapses fertility's triangles and SuperLU found
    the matrix singular: it stopped as "an unexpected error ... a bug" (exit 70). Now a plain
    message; with the hold (the default) the collapsing triangles are held and it finishes."""
    m = read_mesh(shared_mesh("fertility.off"))
    p = dict(flow="mcf", step_size=3e-4)
    with pytest.raises(InvalidMeshError, match="use a smaller Step size"):
        list(smooth_iter(m.V, m.F, SmoothParams(**p, hold_crossings=False)))
    last = list(smooth_iter(m.V, m.F, SmoothParams(**p)))[-1]
    assert np.isfinite(last.V).all() and np.isfinite(last.metrics["bending_energy"])
    assert last.metrics["folded_left"] == 0 and last.metrics["crossings_left"] == 0


def test_the_holds_last_resort_puts_the_surface_back_towards_the_input_where_it_crosses():
    # issue 38: the pizza's smoothing left 3 crossings and 2 folded triangles with almost all
    # of it held; the surface around them blended back towards the input ends them
    from algorithms.mesh.intersections import crossings_away_from, intersecting_pairs_here
    from algorithms.smoothing import _Hold
    from tests.algorithms.deform.test_collisions import fine_dented_sheets

    V0, F, top, X = fine_dented_sheets()
    fixed = np.zeros(len(V0), bool)
    fixed[top[0]] = True
    hold = _Hold(V0, F, fixed)
    assert not hold.grow(X, may_grow=False) and hold.left > 0
    Y = hold.put_back(X, V0)
    known = intersecting_pairs_here(V0, F)
    assert crossings_away_from(intersecting_pairs_here(Y, F), F, known) == 0
    m = hold.figures()
    assert m["crossings_left"] == 0 and m["folded_left"] == 0 and m["put_back_vertices"] > 0
    moved = (Y != X).any(axis=1)
    assert 0 < moved.sum() <= m["put_back_vertices"] and not moved[fixed].any()
    # nothing to mend (the last check found nothing): the positions come back as they are
    assert not hold.grow(V0, may_grow=False)
    assert hold.put_back(V0, V0) is V0
