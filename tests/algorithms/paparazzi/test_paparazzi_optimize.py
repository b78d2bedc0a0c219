"""The Paparazzi loop: offset cameras, NAdam, single-view L2, remeshing guarantees, boundaries,
bad input, reproducibility and each filter's own effect (short runs; long ones in
benchmarks/paparazzi.py)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from algorithms.errors import InvalidMeshError, Stylize3DError
from algorithms.mesh import icosphere, read_mesh, write_mesh
from algorithms.mesh.topology import boundary_loops, euler_characteristic, is_manifold
from algorithms.paparazzi import (FilterFailed, Paparazzi, PaparazziParams,
                                  count_self_intersections, get_filter, offset_surface,
                                  palette_fraction, paparazzi_iter, register_filter,
                                  sample_camera, unregister_filter)
from algorithms.paparazzi.optimize import nadam_step
from algorithms.steps import run_to_end
from tests.conftest import drift_filter, shared_mesh


def test_offset_surface_is_at_distance_sigma_and_cameras_look_inwards():
    import igl

    V, F = icosphere(3)
    off = offset_surface(V, F, 0.2)
    d = igl.signed_distance(off.V, V, F)[0]
    np.testing.assert_allclose(d, 0.2, atol=0.02)
    rng = np.random.default_rng(0)
    cams = [sample_camera(off, rng, resolution=8) for _ in range(400)]
    P = np.array([c.position for c in cams])
    D = np.array([c.direction for c in cams])
    np.testing.assert_allclose(np.linalg.norm(P, axis=1), 1.2, atol=0.03)
    assert (np.einsum("ij,ij->i", D, -P / np.linalg.norm(P, axis=1)[:, None]) > 0.99).all()
    # area-uniform on a sphere: each octant gets about 1/8 of the cameras
    octant = (P > 0) @ [1, 2, 4]
    assert np.bincount(octant, minlength=8).min() > 25
    ups = np.array([c.up for c in cams])
    assert np.abs(ups.mean(0)).max() < 0.15            # random roll: no preferred up


def test_nadam_first_step_is_1_9_learning_rates_times_the_sign():
    # Ruder's form: lr (b1 m_hat + (1 - b1) g / (1 - b1^t)) / sqrt(v_hat); at t = 1, m_hat = g,
    # sqrt(v_hat) = |g|, so the step is lr (0.9 + 1) sign(g).
    g = np.array([[3.0, -0.5, 1e-3]])
    m, v = np.zeros_like(g), np.zeros_like(g)
    np.testing.assert_allclose(nadam_step(g, m, v, 1, 0.01), 0.019 * np.sign(g), rtol=1e-5)
    np.testing.assert_allclose(m, 0.1 * g)
    np.testing.assert_allclose(v, 0.001 * g * g)


def _bumpy_target(tmp_path, level=3):
    V, F = icosphere(level)
    T = V.copy()
    z = T[:, 2] > 0.3
    T[z, 2] += 0.15 * np.sin(6 * T[z, 0]) * np.cos(5 * T[z, 1]) * (T[z, 2] - 0.3)
    path = tmp_path / "target.obj"
    write_mesh(path, T, F)
    return V, F, str(path)


def test_single_view_l2_to_another_shape_reproduces_it_in_that_view(tmp_path):
    # Fig. 2.5: the image error (over the pixels both renderings cover, see the target-mesh
    # filter) falls by >= 90 %. The derivative keeps visibility fixed, so a face's pixels do not
    # follow its vertices: with faces of several pixels (icosphere(3) at 64 px, ~4 px a face) the
    # face boundaries cannot be aligned and the error stops at 15-20 % of its start whatever the
    # step; with faces of about a pixel (icosphere(4), as the thesis's 10^5-10^6-vertex meshes at
    # 128-256 px) it falls below 10 % (measured: 5.2 % after 300 iterations).
    V, F, target = _bumpy_target(tmp_path, level=4)
    fp = get_filter("target-mesh").params(target=target, single_view=True)
    last = run_to_end(paparazzi_iter(V, F, "target-mesh", fp, PaparazziParams(
        iterations=300, learning_rate=5e-4, resolution=64, monitor_every=0)))
    e0, e1 = last.metrics["initial_monitor_energy"], last.metrics["monitor_energy"]
    assert e1 < 0.10 * e0, (e0, e1)
    assert is_manifold(last.F) and count_self_intersections(last.V, last.F) == 0


@pytest.mark.parametrize("name", ["spot_lowres.obj"])
def test_remeshing_keeps_a_manifold_with_the_input_topology_and_no_self_intersections(
        name, monkeypatch):
    from algorithms.paparazzi import optimize

    # every bad element remeshed, as if the steps had made each one worse than the input had
    # it (WORSE_FACTOR infinite: the plain rule), so that these 90 iterations remesh
    monkeypatch.setattr(optimize, "WORSE_FACTOR", np.inf)
    d = read_mesh(shared_mesh(name))
    before = palette_fraction(d.V, d.F)
    steps = list(paparazzi_iter(d.V, d.F, "quantize", None, PaparazziParams(
        iterations=90, learning_rate=5e-4, resolution=64, monitor_every=0, remesh_every=30)))
    last = steps[-1]
    assert last.metrics["remeshes"] == 2            # at every check but the last
    assert len(last.V) != len(d.V)                            # it was remeshed
    assert is_manifold(last.F)
    assert euler_characteristic(last.F) == euler_characteristic(d.F)
    assert count_self_intersections(last.V, last.F) == 0
    assert palette_fraction(last.V, last.F) > before + 0.05   # quantization's own effect


def test_same_seed_same_result_other_seed_other_result():
    V, F = icosphere(2)
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    run = lambda seed: run_to_end(paparazzi_iter(V, F, "quantize", None, PaparazziParams(  # noqa: E731
        iterations=12, resolution=32, remesh_every=6, monitor_every=0, seed=seed))).V
    a, b, c = run(3), run(3), run(4)
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def test_mesh_with_boundary_works_and_its_boundary_stays():
    d = read_mesh(shared_mesh("hand_lowres.obj"))
    loops = boundary_loops(d.F)
    assert len(loops) == 1
    P = Paparazzi(d.V, d.F, "guided", None, PaparazziParams(
        iterations=30, resolution=64, learning_rate=5e-4, remesh_every=15, monitor_every=0))
    last = run_to_end(P.steps())
    out_loops = boundary_loops(last.F)
    assert len(out_loops) == 1 and is_manifold(last.F)
    ring_in = np.sort(d.V[loops[0]], axis=0)
    ring_out = np.sort(last.V[out_loops[0]], axis=0)
    np.testing.assert_allclose(ring_out, ring_in, atol=1e-9)      # the same boundary vertices
    assert not np.allclose(last.V[len(out_loops[0]):].mean(0), 0)  # and the shape was processed


def test_non_manifold_mesh_is_refused_plainly():
    V, F = icosphere(1)
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
    V2 = np.vstack([V, [[2.0, 2.0, 2.0]]])
    with pytest.raises(InvalidMeshError, match="2-manifold.*Clean"):
        Paparazzi(V2, F2, "guided")


def test_a_filter_that_raises_stops_the_run_with_its_message():
    @register_filter("test-broken", kind="iterative")
    def broken(image, params, ctx):
        raise ValueError("my filter is broken")

    try:
        V, F = icosphere(2)
        with pytest.raises(FilterFailed, match="test-broken.*my filter is broken"):
            run_to_end(paparazzi_iter(V, F, "test-broken", None,
                                      PaparazziParams(iterations=3, resolution=16)))
    finally:
        unregister_filter("test-broken")


def test_an_energy_filter_may_say_what_to_show_and_a_wrong_return_is_a_plain_error():
    shown = []

    @register_filter("test-shows", kind="energy", learning_rate=lambda p: 3e-4)
    def shows(image, params, ctx):
        G = image - 0.25
        pic = np.full_like(image, 0.75)
        shown.append(pic)
        return 0.5 * float((G * G).sum()), G, pic

    @register_filter("test-four", kind="energy")
    def four(image, params, ctx):
        return 0.0, np.zeros_like(image), image, image

    try:
        V, F = icosphere(2)
        run = Paparazzi(V, F, "test-shows", None, PaparazziParams(iterations=2, resolution=16,
                                                                   monitor_every=0))
        assert run.learning_rate == 3e-4        # a filter's step may be a function of its Params
        last = run_to_end(run.steps())
        np.testing.assert_array_equal(last.filtered, shown[-1])   # not R - dE/dR
        with pytest.raises(FilterFailed, match="test-four.*picture to show"):
            run_to_end(paparazzi_iter(V, F, "test-four", None,
                                      PaparazziParams(iterations=2, resolution=16)))
    finally:
        unregister_filter("test-shows")
        unregister_filter("test-four")


def test_an_unreadable_target_image_is_refused_before_running(tmp_path):
    from algorithms.paparazzi import ImageReadError

    bad = tmp_path / "target.png"
    bad.write_text("no image here")
    V, F = icosphere(2)
    with pytest.raises(ImageReadError, match="cannot be read"):
        Paparazzi(V, F, "target-image", get_filter("target-image").params(image=str(bad)))


@pytest.mark.parametrize("narrow", [True, False])
def test_self_intersections_are_rolled_back_and_the_step_shrinks(narrow):
    # an energy that pushes two close sheets of a thin shape into each other
    V, F = icosphere(2)
    V = V * [1.0, 1.0, 0.04]

    @register_filter("test-crush", kind="energy")
    def crush(image, params, ctx):
        G = np.zeros_like(image)
        G[..., 2] = ctx.mask * -50.0       # wants every face to turn towards the camera's back
        return float(image[..., 2].sum()), G

    try:
        last = run_to_end(paparazzi_iter(V, F, "test-crush", None, PaparazziParams(
            iterations=40, learning_rate=0.02, resolution=32, remesh_every=5, sigma=0.1,
            monitor_every=0, put_back_crossing_only=narrow)))
    finally:
        unregister_filter("test-crush")
    assert last.metrics["rollbacks"] >= 1
    if narrow:   # PaparazziParams.put_back_crossing_only: the crossing corners only, none held
        assert last.metrics["put_back_vertices"] >= 1
        # not halved either: the last tenth of the iterations takes a fifth of the step
        assert last.metrics["held_vertices"] == 0
        assert last.metrics["learning_rate"] == pytest.approx(0.02 * 0.2)
    else:        # the surface around the crossings held still
        assert last.metrics["put_back_vertices"] == 0 and last.metrics["held_vertices"] >= 1
    assert count_self_intersections(last.V, last.F) == 0
    assert is_manifold(last.F)
    # the steps' crossings are put back before the remeshing, which is then judged by its own:
    # no remeshing is lost to them (when the remeshing came first: 2 of 7 rejected, 6 retries)
    assert last.metrics["remeshes"] >= 5 and last.metrics["remesh_rejected"] == 0


def test_crossings_that_come_back_beside_held_parts_stop_the_run_with_a_value_to_try():
    # every check finds a crossing at the same spot (next to the part held since the first):
    # the step halves each time, and after 11 halvings the run stops with the learning rate to
    # use instead, half of the run's (the corpus's counter ran with it: quantize 818 -> 617)
    V, F = icosphere(2)

    class Crossing(Paparazzi):
        def _new_pairs(self, V, F, IF):
            return np.array([[0, 1]], dtype=np.int64)        # faces 0 and 1 cross, always

    run = Crossing(V, F, "guided", None, PaparazziParams(
        iterations=40, learning_rate=4e-4, resolution=16, remesh_every=1, monitor_every=0,
        lowest_fallback=False, put_back_crossing_only=False))
    with pytest.raises(Stylize3DError, match=r"half the learning rate \(0\.0002; command line: "
                                             r"--learning-rate 0\.0002\)") as err:
        run_to_end(run.steps())
    assert "1000 times smaller step" in str(err.value)
    assert "smooth the mesh first" in str(err.value)


def test_a_crossing_puts_back_only_the_surface_around_it():
    # a thin slab; a dent in one end's top sheet is pushed through the bottom sheet, the other
    # end's top sheet lifted a little (harmless progress): only the dent goes back
    V, F = icosphere(3)
    run = Paparazzi(V * [3.0, 1.0, 0.05], F, "guided", None, PaparazziParams(iterations=1))
    before = run.V0
    X = before.copy()
    top = X[:, 2] > 0
    crush = top & ((X[:, 0] - 0.7) ** 2 + X[:, 1] ** 2 < 0.15 ** 2)
    lift = top & (X[:, 0] < -0.6)
    assert crush.sum() >= 3 and lift.sum() >= 10
    X[crush, 2] -= 0.06
    X[lift, 2] += 0.002
    spots = run._new_crossing_points(X, run.F0)
    assert len(spots) and spots[:, 0].min() > 0.3          # crossings at the crushed end only
    U = run._put_back(X, run.F0, before, spots)
    assert U is not None and len(run._new_crossing_points(U, run.F0)) == 0
    np.testing.assert_array_equal(U[crush], before[crush])
    np.testing.assert_array_equal(U[lift], X[lift])       # the rest keeps its progress
    # a put-back that cannot clear the crossings asks for the whole rollback
    assert run._put_back(X, run.F0, X, spots) is None
    # with X's pairs known only the triangles put back are tested again: the same answers,
    # also where crossings are left among the triangles it did not touch (the other end
    # crushed too, but only this end's spots given)
    from algorithms.mesh.intersections import intersecting_pairs_here

    pairs = intersecting_pairs_here(X, run.F0)
    np.testing.assert_array_equal(run._put_back(X, run.F0, before, spots, pairs), U)
    assert run._put_back(X, run.F0, X, spots, pairs) is None
    both = top & ((np.abs(X[:, 0]) - 0.7) ** 2 + X[:, 1] ** 2 < 0.15 ** 2)
    Y = before.copy()
    Y[both, 2] -= 0.06
    one_end = run._new_crossing_points(Y, run.F0)
    one_end = one_end[one_end[:, 0] > 0]
    assert run._put_back(Y, run.F0, before, one_end) is None
    assert run._put_back(Y, run.F0, before, one_end, intersecting_pairs_here(Y, run.F0)) is None


def test_a_crossing_puts_back_only_the_corners_of_the_crossing_triangles():
    # PaparazziParams.put_back_crossing_only: the slab of the test above, its dent pushed
    # through the bottom sheet; only the corners of the triangles that cross go back (then
    # those of any that still cross), far fewer than within 4 edge lengths, and the rest,
    # the dent's own uncrossed vertices too, keeps its progress
    from algorithms.mesh.intersections import intersecting_pairs_here

    V, F = icosphere(3)
    run = Paparazzi(V * [3.0, 1.0, 0.05], F, "guided", None, PaparazziParams(iterations=1))
    before, F = run.V0, run.F0
    X = before.copy()
    top = X[:, 2] > 0
    crush = top & ((X[:, 0] - 0.7) ** 2 + X[:, 1] ** 2 < 0.15 ** 2)
    lift = top & (X[:, 0] < -0.6)
    X[crush, 2] -= 0.06
    X[lift, 2] += 0.002
    pairs = intersecting_pairs_here(X, F)
    new = run._new_pairs(X, F, pairs)
    np.testing.assert_array_equal(new, pairs)                # a clean input: every pair is new
    U, back = run._put_back_crossing(X, F, before, new)
    assert U is not None and len(run._new_crossing_points(U, F)) == 0
    corners = np.unique(F[pairs].ravel())
    assert back[corners].all()                              # at least the crossing corners
    np.testing.assert_array_equal(U[back], before[back])
    np.testing.assert_array_equal(U[~back], X[~back])       # nothing else
    assert not back[lift].any()
    spots = run._new_crossing_points(X, F)
    wide = run._near(X, spots) | run._near(before, spots)      # what _put_back puts back
    assert 0 < back.sum() < wide.sum() / 3
    # put back where it already was (nothing to go back to): crossings stay, and the caller
    # falls back to the wide put-back (None)
    assert run._put_back_crossing(X, F, X, new)[0] is None
    # a surface with no new crossings is returned as it is
    U2, back2 = run._put_back_crossing(before, F, before, run._new_pairs(
        before, F, intersecting_pairs_here(before, F)))
    assert not back2.any()
    np.testing.assert_array_equal(U2, before)


def test_a_shape_whose_pictures_the_filter_leaves_as_they_are_is_refused_before_a_step():
    # FilterSpec.min_change: an iterative filter that changes the input's monitor views by less
    # than one grey level (rms per channel over the foreground) has nothing to do; the run is
    # refused before its first step, with the figure, and nothing is yielded
    from algorithms.mesh import cube
    from algorithms.paparazzi import NothingToFilter
    from algorithms.render import render

    V, F = cube(8)
    for name in ("guided", "l0"):
        run = Paparazzi(V, F, name, None, PaparazziParams(iterations=5))
        steps = run.steps()
        with pytest.raises(NothingToFilter, match=rf"the way the {name} filter.*of a grey "
                                                  r"level on average \(less than 1\)"):
            next(steps)
        # the figure: the rms of f(R) - R per channel over the views' foreground pixels
        d2 = n = 0.0
        for c in run.monitor_cameras():
            r = render(run.V0, run.F0, c, run.shading)
            f = run.spec.function(r.image, run.filter_params, run._context(r, c))
            d2 += float(((f - r.image)[r.mask] ** 2).sum())
            n += int(r.mask.sum()) * r.image.shape[-1]
        renders: list = []
        e = run.monitor_energy(run.V0, run.F0, renders=renders)
        assert len(renders) == 16
        assert run.change_per_pixel(e, renders) == pytest.approx(np.sqrt(d2 / n), rel=1e-9)
        assert run.change_per_pixel(e, renders) < 1.0 / 255.0
    # a smooth shape gives the filter something to do: it runs
    W, G = icosphere(3)
    run = Paparazzi(W * [1.0, 0.7, 0.5], G, "l0", None, PaparazziParams(iterations=2,
                                                                        monitor_every=0))
    assert run_to_end(run.steps()).iteration == 2
    # min_change 0 never refuses (remeshing alone, the benchmarks' control, is an identity)
    quiet = dataclasses.replace(get_filter("l0"), min_change=0.0)
    assert run_to_end(Paparazzi(V, F, quiet, None, PaparazziParams(
        iterations=2, monitor_every=0)).steps()).iteration == 2


def test_a_clean_box_at_the_guided_filters_fixed_point_is_refused_with_the_reason():
    # a box's pictures are flat faces and sharp edges, what the guided filter makes: its pull
    # raises the energy from the first step and the run finds no lower shape. The refusal says
    # so (measured here: probe +139 %, 4 % of the pixels noisy; energy 0.0313 -> 0.0318) rather
    # than advising more iterations, which raise it just the same
    from algorithms.mesh import cube
    from algorithms.paparazzi import EnergyNotLowered, require_lowered
    from algorithms.paparazzi.optimize import ROUGH_SHARE

    V, F = cube(8)
    pp = PaparazziParams(iterations=60, monitor_every=10)
    # at the defaults the box is refused before the first step, its pictures already being
    # the filter's (NothingToFilter, below); the refusal after a run is for the shapes just
    # above that line, so it is tested here with the early refusal switched off
    run = Paparazzi(V, F, dataclasses.replace(get_filter("guided"), min_change=0.0), None, pp)
    m = run_to_end(run.steps()).metrics
    assert m["rough_probe"] > 0 and m["rough_share"] < ROUGH_SHARE and not m["rough_input"]
    assert m["monitor_energy"] >= m["initial_monitor_energy"]
    with pytest.raises(EnergyNotLowered, match="already close to what the filter makes") as e:
        require_lowered(m, get_filter("guided"))
    assert "More iterations will not" in str(e.value) and "guided filter" in str(e.value)
    # a probe that fell, or a noisy shape's, keeps the general advice; after the command
    # line's 1000 iterations or more (and the filter's own count) it no longer tells to try
    # more iterations or another step: that lowered none of the corpus runs refused so
    # (nefertiti neural-style; guided chair_model, casting, counter)
    for extra in ({"rough_probe": -0.1}, {"rough_share": ROUGH_SHARE}):
        for n in (None, 60, 999):
            with pytest.raises(EnergyNotLowered, match="Try more iterations"):
                require_lowered(dict(m, **extra), get_filter("guided"), n)
        for n in (1000, 3000):
            with pytest.raises(EnergyNotLowered, match=rf"a full run \({n} iterations\): "
                               r"on shapes.*more iterations or a smaller step seldom lower "
                               r"it, so another filter is the better next try") as e:
                require_lowered(dict(m, **extra), get_filter("guided"), n)
            assert "Try more" not in str(e.value)


def test_remeshing_happens_only_when_the_edge_lengths_left_the_band():
    # a regular sphere: every edge within [4/5 h, 4/3 h], so the checks only look for crossings
    V, F = icosphere(3)
    # (the threshold is about whole-surface remeshing: remesh_scope "all")
    pp = PaparazziParams(iterations=12, resolution=32, remesh_every=6, monitor_every=0,
                         remesh_threshold=0.05, remesh_scope="all")
    run = Paparazzi(V, F, "guided", None, pp)
    assert run.band_fraction(run.V0, run.F0) < 0.05
    last = run_to_end(run.steps())
    assert last.metrics["remeshes"] == 0 and len(last.V) == len(V)
    # stretched 2.5x along x: most edges leave the band, so the first check remeshes, and the
    # remeshed mesh has far fewer edges outside it (creases free: the guided filter's remeshing
    # keeps edges sharper than 45 degrees, which the stretched ends of this coarse sphere have)
    import dataclasses

    free = dataclasses.replace(get_filter("guided"), crease_angle=0.0)
    run = Paparazzi(V * [2.5, 1.0, 1.0], F, free, None, pp)
    before = run.band_fraction(run.V0, run.F0)
    assert before > 0.3
    steps = list(run.steps())
    assert steps[5].metrics["remeshes"] == 1
    after = run.band_fraction((steps[5].V - run.center) / run.scale, steps[5].F)
    # 0.496 -> 0.297 with the guided filter's former defaults, 0.304 with today's
    assert after < 0.65 * before, (before, after)
    assert is_manifold(steps[-1].F) and count_self_intersections(steps[-1].V, steps[-1].F) == 0


def test_remeshing_moves_only_the_vertices_next_to_bad_elements_by_default():
    """PaparazziParams.remesh_scope "bad" (the default): a remeshing may move only the vertices
    within one ring of an edge outside [h/2, 2 h] or of a triangle with an angle below 20
    degrees; every other vertex keeps its place bit for bit, and the bad elements are mended.
    "all" re-places the whole surface."""
    from scipy.spatial import cKDTree

    from algorithms.paparazzi.optimize import BAD_ANGLE, BAD_EDGE_BAND

    import igl

    V, F = icosphere(3)
    E = igl.edges(F)
    a, b = E[0]
    V = V.copy()
    V[a] = V[b] + 0.2 * (V[a] - V[b])              # one edge at a fifth of its length
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    assert run.params.remesh_scope == "bad" and BAD_EDGE_BAND == (0.5, 2.0)
    near = run.near_bad(run.V0, run.F0)
    # the short edge's ends, the slivers beside it and their one-ring: a few dozen of 642
    assert near[a] and near[b] and 6 < near.sum() < 60, near.sum()
    bad_faces = (np.degrees(igl.internal_angles(run.V0, run.F0)).min(1) < BAD_ANGLE)
    assert near[run.F0[bad_faces]].all()
    everything = np.ones(len(run.V0), bool)
    U, H = run._remesh(run.V0, run.F0, everything)
    d, _ = cKDTree(U).query(run.V0[~near])
    assert (d == 0).all()                            # the others did not move at all
    lengths = np.linalg.norm(U[igl.edges(H)[:, 0]] - U[igl.edges(H)[:, 1]], axis=1)
    assert lengths.min() > 0.45 * run.edge_length    # the short edge is gone
    assert np.degrees(igl.internal_angles(U, H)).min() > 15.0
    assert is_manifold(H) and euler_characteristic(H) == 2
    # a mesh without bad elements is left as it is; "all" moves (nearly) every vertex
    run = Paparazzi(*icosphere(3), "guided", None, PaparazziParams(iterations=1))
    assert not run.near_bad(run.V0, run.F0).any()
    U, H = run._remesh(run.V0, run.F0, everything)
    np.testing.assert_array_equal(U, run.V0)
    whole = Paparazzi(*icosphere(3), "guided", None, PaparazziParams(iterations=1,
                                                                     remesh_scope="all"))
    U, H = whole._remesh(whole.V0, whole.F0, everything)
    d, _ = cKDTree(U).query(whole.V0)
    assert (d > 0).mean() > 0.9


def test_a_remeshing_hands_the_remesher_only_the_triangles_next_to_bad_elements(monkeypatch):
    """Issue 38 item 3 (El Topo changes only bad elements): with remesh_scope "bad" the core
    gets the triangles with a vertex next to a bad element, not the whole mesh; every other
    triangle comes out with the same three corner positions, bit for bit, the result is a
    closed manifold of the same genus, and the drift check measured on the part agrees with
    the one on the whole surfaces."""
    import igl

    from algorithms.paparazzi import optimize

    V, F = icosphere(4)                             # 2,562 vertices, 5,120 triangles
    V = V.copy()
    a, b = igl.edges(F)[0]
    V[a] = V[b] + 0.2 * (V[a] - V[b])
    sizes = []
    real = optimize._remesh_core

    def counting(V_, F_, *rest):
        sizes.append(len(F_))
        return real(V_, F_, *rest)

    monkeypatch.setattr(optimize, "_remesh_core", counting)
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    U, G = run._remesh(run.V0, run.F0, np.ones(len(run.V0), bool))
    assert len(sizes) == 1 and 6 < sizes[0] < 60          # the patch, of 5,120
    done = run.remeshed
    assert done.start == len(run.V0) - len(done.moved) and len(done.old_faces) == sizes[0]

    def corners(X, T):
        return {tuple(np.sort(X[t], axis=0).ravel()) for t in T}
    untouched = np.ones(len(run.F0), bool)
    untouched[np.isin(run.F0, done.moved).any(axis=1)] = False
    assert untouched.sum() >= len(run.F0) - 60
    assert corners(run.V0, run.F0[untouched]) <= corners(U, G)
    assert is_manifold(G) and euler_characteristic(G) == 2 and run._same_topology(run.V0, G)
    np.testing.assert_array_equal(U[:done.start], np.delete(run.V0, done.moved, axis=0))
    assert np.linalg.norm(U[G[:, 0]] - U[G[:, 1]], axis=1).min() > 0.45 * run.edge_length
    part = run._drift_points(run.V0, run.F0, U, G)
    # crossings are looked for in the part only: the same as on the whole mesh, here with a
    # vertex of the part pushed through the sphere to the other side
    pushed = U.copy()
    k = done.start + np.argmax(np.linalg.norm(U[done.start:], axis=1))
    pushed[k] *= -1.5
    found = run._remeshing_crossing_points(run.V0, pushed, G)
    assert len(found) and len(found) == len(run._new_crossing_points(pushed, G))
    np.testing.assert_array_equal(np.sort(found, axis=0),
                                  np.sort(run._new_crossing_points(pushed, G), axis=0))
    run.remeshed = None                                    # the whole surfaces instead
    whole = run._drift_points(run.V0, run.F0, U, G)
    np.testing.assert_array_equal(np.sort(part, axis=0), np.sort(whole, axis=0))


def test_a_part_remeshed_into_another_topology_is_rejected(monkeypatch):
    """The topology check of a part (Paparazzi._same_topology) rejects what the whole-mesh
    check would: a part that comes back with a hole (one of its triangles dropped), and one
    with a triangle doubled (an edge of three triangles), without raising."""
    import igl

    from algorithms.paparazzi import optimize
    from algorithms.paparazzi.optimize import _topology

    V, F = icosphere(3)
    V = V.copy()
    a, b = igl.edges(F)[0]
    V[a] = V[b] + 0.2 * (V[a] - V[b])
    real = optimize._remesh_core
    for damage in ("hole", "doubled"):
        def damaging(*args, damage=damage):
            U, G = real(*args)
            return U, (G[1:] if damage == "hole" else np.vstack([G, G[:1]]))

        monkeypatch.setattr(optimize, "_remesh_core", damaging)
        run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
        U, G = run._remesh(run.V0, run.F0, np.ones(len(run.V0), bool))
        assert run.remeshed.start > 0                      # a part was remeshed
        assert (_topology(G) != run.topology) if damage == "hole" else not is_manifold(G)
        assert not run._same_topology(run.V0, G)


@pytest.mark.parametrize("name, iterations, factor", [
    # (guided: test_guided_lowers_its_energy_smooths_more_than_remeshing_and_keeps_fandisks_creases
    # below; on spot its 300-iteration effect is within 1 % of remeshing alone since remeshing
    # moves only bad elements: 322.5 -> 321.3 against 323.6, spot subdivided once 349.8 against
    # 350.0 in 600 iterations; with the whole surface re-placed 339.0 against 347.9)
    # L0 -> the area of near-planar faces (dihedral angles < 3 deg) rises (0.047 -> 0.067; with
    # the whole surface re-placed at each remeshing 0.065)
    ("l0", 40, 1.3),
    # SLIC -> the same, at its defaults (the authors' 6e-5, views 1.0 wide) on spot subdivided
    # once (3,310 V), remeshing as the CLI does: 0.047 -> 0.153 (x3.2; re-placing the whole
    # surface 0.146, seed 1: x3.06; with the former 0.3-wide views 0.0626, x1.33); the
    # 1000-iteration runs of
    # benchmarks/paparazzi_effects.py: docs/results/paparazzi.md's effects table
    ("slic", 300, 2.0),
])
def test_each_filter_changes_the_shape_in_its_own_way(name, iterations, factor):
    # short runs at 64 px on spot subdivided once (quantization's own effect: see the remeshing
    # test above); benchmarks/paparazzi_effects.py runs the CLI's defaults for 1000 iterations
    # on 5k-20k V
    from algorithms.mesh import loop_subdivide
    from algorithms.paparazzi import planar_area_fraction as f

    d = read_mesh(shared_mesh("spot_lowres.obj"))
    V, F = loop_subdivide(d.V, d.F, 1)
    pp = PaparazziParams(iterations=iterations, resolution=64, monitor_every=0)
    last = run_to_end(paparazzi_iter(V, F, name, None, pp))
    before, after = f(V, F), f(last.V, last.F)
    assert after > factor * before, (before, after)
    assert is_manifold(last.F) and euler_characteristic(last.F) == euler_characteristic(F)
    assert count_self_intersections(last.V, last.F) == 0


def test_an_unreferenced_vertex_does_not_stop_the_run():
    V, F = icosphere(2)
    V2 = np.vstack([V * 0.5, [[0.6, 0.6, 0.6]]])           # last vertex in no face
    steps = list(paparazzi_iter(V2, F, "guided", None, PaparazziParams(
        iterations=35, resolution=32, monitor_every=0)))
    assert len(steps[0].V) == len(V2) and steps[-1].metrics["remeshes"] == 1
    assert is_manifold(steps[-1].F) and count_self_intersections(steps[-1].V, steps[-1].F) == 0


def test_an_input_that_intersects_itself_may_keep_but_not_add_intersections():
    # two interpenetrating spheres: remeshing resamples the intersection curve (its pair count
    # changes) but adds none elsewhere, so it is accepted; the output's crossings are all where
    # the input's were
    V, F = icosphere(3)
    c2 = np.array([1.2, 0.0, 0.0])
    V2 = np.vstack([V, V * 0.8 + c2])
    F2 = np.vstack([F, F + len(V)])
    run = Paparazzi(V2, F2, "guided", None, PaparazziParams(
        iterations=12, resolution=32, remesh_every=6, monitor_every=0))
    assert run.input_intersections > 0
    last = run_to_end(run.steps())
    assert last.metrics["remeshes"] == 1 and last.metrics["remesh_rejected"] == 0
    assert count_self_intersections(last.V, last.F) > 0
    assert run.new_self_intersections(last.V, last.F) == 0
    # the first sphere moved 1 down: the spheres still cross, but along another circle, 1 away
    first = (np.abs(np.linalg.norm(last.V, axis=1) - 1.0)
             < np.abs(np.linalg.norm(last.V - c2, axis=1) - 0.8))
    moved = last.V.copy()
    moved[first] -= [0.0, 1.0, 0.0]
    assert count_self_intersections(moved, last.F) > 0
    assert run.new_self_intersections(moved, last.F) > 0


def test_guided_run_on_camelhead_finishes_despite_its_near_touching_lips():
    """Regression (issue 12): camelhead's lips are a few % of an edge apart, so remeshing there
    crosses the surface; with the CLI's defaults (1000 iterations) every remeshing used to be
    rejected and the halved steps stopped the run. Crossings are now handled where they happen
    (retried remeshing with the crossing's neighbourhood held, local rollback)."""
    m = read_mesh(shared_mesh("camelhead.off"))
    run = Paparazzi(m.V, m.F, "guided", None, PaparazziParams(iterations=1000))
    last = run_to_end(run.steps())
    mt = last.metrics
    print(f"\ncamelhead guided: {mt['remeshes']} remeshes, {mt['remesh_rejected']} rejected, "
          f"{mt['remesh_retries']} retries, {mt['rollbacks']} rollbacks, "
          f"{mt['held_vertices']} vertices held")
    assert mt["remeshes"] >= 20 and mt["remesh_rejected"] <= 3
    assert is_manifold(last.F)
    assert euler_characteristic(last.F) == euler_characteristic(m.F)
    assert len(boundary_loops(last.F)) == len(boundary_loops(m.F))
    assert run.new_self_intersections(last.V, last.F) == 0


def test_piecewise_planar_filters_keep_creases_through_remeshing(monkeypatch):
    """FilterSpec.crease_angle: a filter that makes shapes piecewise planar (slic, l0: 45 deg)
    has the remeshing keep edges sharper than that as creases; without it, and without the
    bound on how far a remeshing may move the surface (DRIFT_TOL), remeshing alone rounds a
    box's edges (measured: near-planar area 1 -> 0.21 without, 0.66 with creases; the faces
    beside a crease are a large share of so coarse a box). With the bound (issue 38) the
    remeshing holds the box's edges even without creases: it does not remesh there."""
    from algorithms.mesh.primitives import cube
    from algorithms.paparazzi import optimize, planar_area_fraction
    from algorithms.paparazzi.optimize import crease_edges

    # and the guided filter, whose edge-preserving smoothing should keep them too (issue 23)
    assert {get_filter(n).crease_angle for n in ("slic", "l0", "guided")} == {45.0}
    assert get_filter("quantize").crease_angle == 0.0
    V, F = cube(subdivisions=5)
    assert len(crease_edges(V, F, 45.0)) == 12 * 6          # 12 edges of 6 segments
    V = V * [3.0, 1.0, 1.0]    # a box of stretched triangles: the remeshing splits and flips
    # ... all of them, as if the steps had made them so (WORSE_FACTOR infinite: the plain rule;
    # an identity filter spoils nothing, and the input's own bad triangles are left alone)
    monkeypatch.setattr(optimize, "WORSE_FACTOR", np.inf)

    def run(angle):
        name = f"test-identity-{int(angle)}"
        register_filter(name, kind="iterative", crease_angle=angle, min_change=0.0)(
            lambda image, params, ctx: image)
        try:
            last = run_to_end(paparazzi_iter(V, F, name, None, PaparazziParams(
                iterations=31, resolution=32, remesh_every=30, monitor_every=0)))
        finally:
            unregister_filter(name)
        assert last.metrics["remeshes"] == 1
        share = planar_area_fraction(last.V, last.F)
        print(f"\ncrease angle {angle}, DRIFT_TOL {optimize.DRIFT_TOL}: planar share 1.0 -> "
              f"{share:.3f}, {len(crease_edges(last.V, last.F, 45.0))} crease edges, "
              f"{len(last.V)} vertices, {int(last.metrics['remesh_drift_holds'])} drift holds")
        return last, share

    last, creased = run(45.0)
    assert len(last.V) != len(V) and creased > 0.5          # remeshed, and the edges kept
    last, held = run(0.0)
    assert last.metrics["remesh_drift_holds"] >= 1 and held > 0.5
    monkeypatch.setattr(optimize, "DRIFT_TOL", np.inf)       # the bound off: rounded
    last, rounded = run(0.0)
    assert len(last.V) != len(V) and rounded < 0.3 and creased > rounded + 0.3


def test_monitor_energy_is_the_mean_over_16_fixed_views_spread_around_the_shape(tmp_path):
    # issue 23: one monitor view sees a sixth of the shape at most; the run's monitor is the
    # mean energy of >= 16 fixed views spread over the offset surface, the same views all run
    from algorithms.paparazzi import monitor_cameras

    V, F = icosphere(3)
    pp = PaparazziParams(iterations=4, resolution=32, remesh_every=0, monitor_every=2)
    run = Paparazzi(V, F, "guided", None, pp)
    cams = run.monitor_cameras()
    assert len(cams) == 16
    again = run.monitor_cameras()
    assert all(np.array_equal(a.position, b.position) for a, b in zip(cams, again))
    P = np.array([c.position for c in cams])
    # spread: every octant of the sphere has a monitor camera, none two close together
    assert len(set(((P > 0) @ [1, 2, 4]).tolist())) == 8
    D = np.linalg.norm(P[:, None] - P[None], axis=2) + 10 * np.eye(16)
    assert D.min() > 0.4
    # farthest-point: the views cover the cage better than 16 random ones of the same stream
    rng = np.random.default_rng(0)
    rand = np.array([sample_camera(run.offset, rng).position for _ in range(16)])
    Dr = np.linalg.norm(rand[:, None] - rand[None], axis=2) + 10 * np.eye(16)
    assert D.min() > Dr.min()
    X = (V - run.center) / run.scale
    energies = [run.evaluate(X, F, c)[0] for c in cams]
    assert run.monitor_energy(X, F) == pytest.approx(np.mean(energies))
    assert np.std(energies) > 0          # the views see different things
    steps = list(run.steps())
    assert steps[0].metrics["initial_monitor_energy"] == pytest.approx(np.mean(energies))
    assert steps[-1].metrics["monitor_views"] == 16
    assert len(monitor_cameras(run.offset, 20, np.random.default_rng(1))) == 20
    # a single-view filter's monitor is its one fixed view
    write_mesh(tmp_path / "sphere.obj", *icosphere(2))
    single = Paparazzi(V, F, "target-mesh", get_filter("target-mesh").params(
        target=str(tmp_path / "sphere.obj"), single_view=True), pp)
    assert len(single.monitor_cameras()) == 1


def test_guided_lowers_its_energy_smooths_more_than_remeshing_and_keeps_fandisks_creases():
    # issue 23 (1000-iteration figures: docs/results/paparazzi.md): the guided filter at its
    # defaults lowers its own energy (mean over the 16 monitor views), ends smoother (bending
    # energy) than the same run with the picture returned unchanged (remeshing alone), and keeps the
    # input's sharp creases, on fandisk in 200 iterations
    import dataclasses

    from algorithms.paparazzi import bending_energy
    from algorithms.paparazzi.measures import crease_fraction

    d = read_mesh(shared_mesh("fandisk.off"))
    pp = PaparazziParams(iterations=200, monitor_every=0)
    spec = get_filter("guided")
    last = run_to_end(paparazzi_iter(d.V, d.F, spec, None, pp))
    control = run_to_end(paparazzi_iter(d.V, d.F, dataclasses.replace(
        spec, name="guided-control", function=lambda image, params, ctx: image,
        min_change=0.0), None, pp))
    m = last.metrics
    assert m["monitor_views"] == 16
    assert m["monitor_energy"] < 0.99 * m["initial_monitor_energy"], m
    assert bending_energy(last.V, last.F) < 0.99 * bending_energy(control.V, control.F)
    assert crease_fraction(d.V, d.F, last.V, last.F) > 0.85
    assert is_manifold(last.F) and count_self_intersections(last.V, last.F) == 0


def test_the_step_is_halved_once_the_energy_climbs_back_up():
    # PaparazziParams.plateau_step (issue 23, fifth pass): a filter whose target drifts away
    # (here: its pull weakens over 90 calls, then grows from call 400) makes the monitor
    # energy fall below its start and then climb; each climb of more than PLATEAU_RISE above
    # the lowest check halves the step; without the option the step stays; a falling energy is
    # never touched; off by default (docs/results/paparazzi.md)
    from algorithms.paparazzi.optimize import PLATEAU_EVERY, PLATEAU_MIN, PLATEAU_RISE

    assert (PLATEAU_EVERY, PLATEAU_RISE, PLATEAU_MIN) == (50, 0.02, 1 / 16)
    assert PaparazziParams().plateau_step is False
    with drift_filter("test-drift", growth=2000.0) as drift:
        V, F = icosphere(2)
        rates = {}
        for on in (True, False):
            drift["calls"] = 0
            pp = PaparazziParams(iterations=600, resolution=32, remesh_every=0, monitor_every=0,
                                 plateau_step=on)
            steps = list(Paparazzi(V, F, "test-drift", None, pp).steps())
            m = steps[-1].metrics
            rates[on] = [s.metrics["learning_rate"] for s in steps[:int(0.9 * 600)]]
            if on:
                assert m["step_halvings"] >= 2, m
                assert min(rates[on]) == pytest.approx(1e-4 * 0.5 ** m["step_halvings"])
                assert any("step halved" in s.message for s in steps)
            else:
                assert m["step_halvings"] == 0 and set(rates[on]) == {1e-4}
        assert rates[True][:PLATEAU_EVERY] == rates[False][:PLATEAU_EVERY]
    # quantize on a bumpy sphere: its energy falls, nothing is halved, and the run is the same
    # bit for bit as without the option (the checks only read the surface)
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    runs = [run_to_end(Paparazzi(V, F, "quantize", None, PaparazziParams(
        iterations=200, resolution=32, remesh_every=60, monitor_every=0,
        plateau_step=on)).steps()) for on in (True, False)]
    last = runs[0]
    assert last.metrics["monitor_energy"] < last.metrics["initial_monitor_energy"]
    assert last.metrics["step_halvings"] == 0
    np.testing.assert_array_equal(runs[0].V, runs[1].V)
    np.testing.assert_array_equal(runs[0].F, runs[1].F)


def test_a_run_whose_energy_ends_above_its_start_returns_its_lowest_shape():
    # PaparazziParams.lowest_fallback (issue 23, sixth pass): a filter whose target drifts away
    # (its pull weakens, then grows from call 400) makes the monitor energy fall below its start
    # and climb back above it; the run returns the shape of its lowest check, unless that shape
    # cannot be shown free of new self-crossings; with a milder drift the energy ends below its
    # start and the last shape is returned, bit for bit as with the option off
    from algorithms.paparazzi.optimize import Paparazzi as P

    assert PaparazziParams().lowest_fallback is True

    class Poisoned(P):
        # the end's check of the lowest (unchecked) shape finds a crossing (the loop's own
        # checks test the new pairs directly: this is the run's only call)
        n = 0

        def _new_crossing_points(self, V, F, IF=None):
            Poisoned.n += 1
            return (np.zeros((1, 3)) if Poisoned.n == 1
                    else super()._new_crossing_points(V, F, IF))

    def runs(cases):
        out = {}
        for key, cls, on in cases:
            drift["calls"] = 0
            pp = PaparazziParams(iterations=600, resolution=32, remesh_every=0,
                                 monitor_every=25, lowest_fallback=on)
            out[key] = list(cls(V, F, "test-drift-keep", None, pp).steps())
        return out

    with drift_filter("test-drift-keep", growth=1000.0) as drift:
        V, F = icosphere(2)
        got = runs((("on", P, True), ("poisoned", Poisoned, True), ("off", P, False)))
        steps = got["on"]
        m = steps[-1].metrics
        checks = [s.metrics["monitor_energy"] for s in steps[24:-1:25]]
        k = int(m["kept_iteration"])
        assert 25 <= k < 600 and k % 25 == 0
        assert m["monitor_energy"] == min(checks) < m["initial_monitor_energy"]
        assert m["last_monitor_energy"] >= m["initial_monitor_energy"]
        np.testing.assert_array_equal(steps[-1].V, steps[k - 1].V)
        np.testing.assert_array_equal(steps[-1].F, steps[k - 1].F)
        assert "kept the shape of iteration" in steps[-1].message
        assert Poisoned.n == 1
        for key in ("poisoned", "off"):
            last = got[key][-1]
            assert last.metrics["kept_iteration"] == 600
            assert last.metrics["monitor_energy"] == m["last_monitor_energy"]
            np.testing.assert_array_equal(last.V, got["poisoned"][-1].V)
        np.testing.assert_array_equal(got["off"][-2].V, steps[-2].V)   # same run until then
        # a milder drift: the energy climbs back but ends below its start: the last shape
        drift["growth"] = 4000.0
        got = runs((("on", P, True), ("off", P, False)))
        m = got["on"][-1].metrics
        assert m["monitor_energy"] < m["initial_monitor_energy"]
        assert m["monitor_energy"] > 1.05 * min(s.metrics["monitor_energy"]
                                                for s in got["on"][24:-1:25])
        assert m["kept_iteration"] == 600
        np.testing.assert_array_equal(got["on"][-1].V, got["off"][-1].V)


def test_a_remeshing_that_leaves_a_flat_triangle_is_held_there(monkeypatch):
    """The remesher can leave three collinear vertices (nefertiti of the corpus, remeshing
    alone: smallest angles of 2e-13 degrees, bending energy NaN). Here the first remeshing's
    output gets one triangle squashed onto its edge: the remeshing is tried again with the
    surface held there, and the result has no such triangle (issue 38). Two short edges on
    opposite sides of a sphere make two bad spots; the triangle squashed is next to the first,
    so the second attempt, with the surface there held, still remeshes the other."""
    import igl

    from algorithms.mesh import icosphere
    from algorithms.paparazzi import optimize

    V, F = icosphere(3)
    V = V.copy()
    E = igl.edges(F)
    first = E[np.argmax(V[E[:, 0], 2] + V[E[:, 1], 2])]          # at the top
    second = E[np.argmin(V[E[:, 0], 2] + V[E[:, 1], 2])]         # at the bottom
    for a, b in (first, second):
        V[a] = V[b] + 0.2 * (V[a] - V[b])
    top = V[first].mean(axis=0)
    # the short edges count as the run's (WORSE_FACTOR infinite: the plain rule), as if the
    # steps had made them; the identity filter below spoils nothing itself
    monkeypatch.setattr(optimize, "WORSE_FACTOR", np.inf)
    real = optimize._remesh_core
    calls = []

    def squashing(*args):
        U, G = real(*args)
        calls.append(len(G))
        if len(calls) == 1:
            a, b, c = G[np.argmin(np.linalg.norm(U[G].mean(axis=1) - top, axis=1))]
            U = U.copy()
            # next to the midpoint of the opposite edge, a millionth of an edge off it: a
            # sliver, not an exact zero (which the exact crossing test flags on its own)
            U[c] = 0.5 * (U[a] + U[b]) + 1e-6 * (U[c] - 0.5 * (U[a] + U[b]))
        return U, G

    def run(angle):
        monkeypatch.setattr(optimize, "DEGENERATE_ANGLE", angle)
        calls.clear()
        name = "test-identity-flat"
        register_filter(name, kind="iterative", min_change=0.0)(
            lambda image, params, ctx: image)
        try:
            return run_to_end(paparazzi_iter(V, F, name, None, PaparazziParams(
                iterations=31, resolution=32, remesh_every=30, monitor_every=0)))
        finally:
            unregister_filter(name)

    monkeypatch.setattr(optimize, "_remesh_core", squashing)
    last = run(1e-3)
    smallest = np.degrees(np.asarray(igl.internal_angles(last.V, last.F))).min()
    assert len(calls) == 2 and last.metrics["remesh_degenerate_holds"] == 1
    assert smallest > 1.0
    last = run(0.0)  # the check off: the squashed triangle is kept
    assert len(calls) == 1 and last.metrics["remesh_degenerate_holds"] == 0
    assert np.degrees(np.asarray(igl.internal_angles(last.V, last.F))).min() < 1e-3


def test_l0s_step_shrinks_with_the_edge_on_fine_meshes_and_a_set_step_is_kept(monkeypatch):
    # FilterSpec.step_follows_edge (l0): the step on auto is the filter's learning rate times
    # min(1, mean edge / ROUGH_EDGE), as the rough step; other filters and a step the run sets
    # are left as they are. (ROUGH_EDGE is raised here so that a small sphere counts as fine.)
    from algorithms.paparazzi import optimize

    V, F = icosphere(2)
    coarse = Paparazzi(V, F, "l0")
    assert coarse.edge_length > optimize.ROUGH_EDGE and coarse.learning_rate == 2e-4
    monkeypatch.setattr(optimize, "ROUGH_EDGE", 1.0)
    run = Paparazzi(V, F, "l0", None, PaparazziParams(iterations=20, monitor_every=0))
    assert run.learning_rate == pytest.approx(2e-4 * run.edge_length)
    first = next(run.steps())             # (the last tenth of a run takes a smaller step)
    assert first.metrics["learning_rate"] == pytest.approx(2e-4 * run.edge_length)
    assert run.fine_step and first.message.startswith("Fine mesh: its edges are shorter")
    assert f"step is {run.learning_rate:.2g} instead of 0.0002" in first.message
    assert not coarse.fine_step
    assert Paparazzi(V, F, "quantize").learning_rate == 2e-4
    assert Paparazzi(V, F, "l0", None, PaparazziParams(learning_rate=3e-4)).learning_rate == 3e-4
