"""Paparazzi's remeshing changes what the run made worse, not what the input already had bad
(``WORSE_FACTOR``, ``Paparazzi.baseline``; issue 38): a CAD model's long thin triangles stay as
they came, an element the steps degrade is still mended, and the triangles a remeshing made are
judged against their own shape from then on."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import icosphere
from algorithms.mesh.topology import euler_characteristic, is_manifold
from algorithms.paparazzi import (Paparazzi, PaparazziParams, get_filter, paparazzi_iter,
                                  register_filter, unregister_filter)
from algorithms.paparazzi.optimize import BAD_ANGLE
from algorithms.steps import run_to_end


def cylinder(segments: int = 24, height: float = 2.0, rows: int = 1):
    """A closed CAD-like cylinder: ``rows`` rows of long thin side triangles, fan caps (with the
    defaults every triangle has an angle below 20 degrees and the rim's edges are short)."""
    t = 2 * np.pi * np.arange(segments) / segments
    ring = np.c_[np.cos(t), np.sin(t)]
    V = np.vstack([np.c_[ring, np.full(segments, height * r / rows)] for r in range(rows + 1)]
                  + [[[0, 0, 0], [0, 0, height]]])
    bottom, top = (rows + 1) * segments, (rows + 1) * segments + 1
    F = []
    for i in range(segments):
        j = (i + 1) % segments
        for r in range(rows):
            a, b = r * segments, (r + 1) * segments
            F += [[a + i, a + j, b + j], [a + i, b + j, b + i]]
        F += [[bottom, j, i], [top, rows * segments + i, rows * segments + j]]
    return V, np.array(F)


def test_the_inputs_own_bad_triangles_are_not_bad_until_the_run_makes_them_worse():
    V, F = cylinder()
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    V0, F0 = run.V0, run.F0
    base = run.face_shape(V0, F0)
    assert (base[:, 3] < BAD_ANGLE).all()
    assert run.near_bad(V0, F0).all()                       # the plain rule: every vertex
    assert not run.near_bad(V0, F0, base).any()             # against the input: none
    # a little change (within WORSE_FACTOR) leaves them alone, also a good triangle that
    # crosses the threshold by a hair (hysteresis); a bigger one does not
    rng = np.random.default_rng(0)
    jiggled = V0 + rng.normal(scale=1e-4, size=V0.shape)
    assert not run.near_bad(jiggled, F0, base).any()
    k = 2 * 24                                              # the bottom cap's centre
    pulled = V0.copy()
    pulled[k] = V0[0] + 0.5 * (V0[k] - V0[0])              # its spokes to vertex 0's side
    near = run.near_bad(pulled, F0, base)
    assert near[k] and near[0] and not near[k + 1]          # the top cap's centre is left alone
    # a triangle with no area is bad even if the input had it so
    flat = base.copy()
    flat[:, 3] = 0.0
    squashed = V0.copy()
    squashed[F0[0, 2]] = 0.5 * (V0[F0[0, 0]] + V0[F0[0, 1]])
    assert run.near_bad(squashed, F0, flat)[F0[0]].all()


def test_a_good_triangle_the_steps_spoil_is_mended_as_before():
    import igl

    V, F = icosphere(3)
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    base = run.face_shape(run.V0, run.F0)
    a, b = igl.edges(run.F0)[0]
    V1 = run.V0.copy()
    V1[a] = V1[b] + 0.2 * (V1[a] - V1[b])                  # one edge at a fifth of its length
    np.testing.assert_array_equal(run.near_bad(V1, run.F0, base), run.near_bad(V1, run.F0))
    assert run.near_bad(V1, run.F0, base)[[a, b]].all()


def test_the_triangles_a_remeshing_made_are_judged_against_their_own_shape():
    """After a remeshing of a part next to the input's slivers, the kept triangles keep their
    input shape as the baseline and the new ones get theirs: the next check finds nothing bad
    until something moves (without the carried baseline the remeshed part's border and the
    slivers beside it would be remeshed again and again, across the whole part)."""
    V, F = cylinder(32, 12.0, 6)
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=1))
    run.baseline = run.face_shape(run.V0, run.F0)
    k = 7 * 32                                             # the bottom cap's centre
    V1 = run.V0.copy()
    V1[k] = V1[0] + 0.3 * (V1[k] - V1[0])                 # the steps spoil the bottom cap
    U, G = run._remesh(V1, run.F0, np.ones(len(V1), bool))
    done = run.remeshed
    assert done.start > 0 and 0 < (~done.kept_faces).sum() < len(run.F0) // 2
    assert is_manifold(G) and euler_characteristic(G) == 2
    old = run.baseline
    run.carry_baseline(U, G)
    kept = int(done.kept_faces.sum())
    np.testing.assert_array_equal(run.baseline[:kept], old[done.kept_faces])
    np.testing.assert_array_equal(run.baseline[kept:], run.face_shape(U, G[kept:]))
    np.testing.assert_array_equal(run.face_shape(U, G[:kept]), old[done.kept_faces])
    assert not run.near_bad(U, G, run.baseline).any()
    assert run.near_bad(U, G).sum() > len(U) // 2          # the plain rule still would


def test_remeshing_alone_leaves_a_cad_models_thin_triangles_as_they_came():
    """The control of docs/results/paparazzi.md (a filter that returns each picture unchanged,
    so only the remeshing acts): on a mesh whose every triangle was bad to begin with, the run
    now writes the input back; the plain rule re-placed its triangles at every remeshing."""
    V, F = cylinder()
    spec = get_filter("guided")
    register_filter("test-identity-baseline", kind="iterative", resolution=32,
                    width=spec.width, crease_angle=spec.crease_angle, min_change=0.0)(
        lambda image, params, ctx: image)
    try:
        pp = PaparazziParams(iterations=60, remesh_every=10, monitor_every=0)
        run = Paparazzi(V, F, "test-identity-baseline", None, pp)
        last = run_to_end(run.steps())
        assert last.metrics["remeshes"] == 5
        np.testing.assert_array_equal(last.F, F)
        np.testing.assert_allclose(last.V, V, atol=1e-12)
        plain = run.near_bad(run.V0, run.F0)
        assert plain.all()                                 # so the plain rule would have moved
    finally:
        unregister_filter("test-identity-baseline")


def test_a_run_with_remeshing_on_input_slivers_ends_manifold_and_checked():
    """l0 (step 2e-4, larger than guided's) on the cylinder, 60 iterations at 64 pixels: a
    closed manifold of the same genus with no self-intersections comes out, whatever the
    remeshing left alone."""
    from algorithms.paparazzi import count_self_intersections

    V, F = cylinder()
    last = run_to_end(paparazzi_iter(V, F, "l0", None,
                                     PaparazziParams(iterations=60, remesh_every=10,
                                                     monitor_every=0, resolution=64)))
    assert is_manifold(last.F) and euler_characteristic(last.F) == 2
    assert count_self_intersections(last.V, last.F) == 0
    assert last.metrics["remeshes"] == 5
    moved = (np.abs(last.V - V).max() if len(last.V) == len(V) else np.inf)
    assert moved > 1e-3                                     # the steps did move it (0.005)
