"""Issue 22: neural subdivision never makes a flat or smooth surface rougher than Loop does
(the shipped weights on the shared meshes as they are), and the measures themselves."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.subdivision.baselines import subdivide_baseline
from algorithms.subdivision.inference import load_network, neural_subdivide_np
from algorithms.subdivision.metrics import (bending_energy, planar_faces,
                                            planar_normal_deviation)
from app.document import MeshState
from app.recipes import run
from tests.conftest import ROOT

FANDISK = ROOT / "tests" / "data" / "fandisk.off"
BLOB = ROOT / "resources" / "samples" / "blob.obj"
#: a mesh as it is where the shipped network's level 2 is more than twice as bent as modified
#: butterfly's (the weights shipped since 2026-11-29: 2.3x; those before: 3.7x; the blob
#: sample, 3.0x with those before, is 1.75x with these and passes)
BOB = ROOT / "tests" / "data" / "bob.obj"


def test_measures_see_dimples():
    """A flat grid: Loop keeps the inside planar (0 deg); one pushed-in vertex is seen by both
    measures; the bending energy does not depend on the size."""
    from algorithms.mesh.primitives import grid

    V, F = grid(12, 12)
    planar = planar_faces(V, F)
    assert planar.any() and not planar.all()  # the rim is not an interior planar region
    VL, FL = subdivide_baseline(V, F, 2, "loop")
    assert planar_normal_deviation(V, F, VL, FL, 2) < 1e-6
    assert bending_energy(VL, FL) < 1e-12
    Vd = VL.copy()
    centre = np.argmin(((VL[:, :2] - VL[:, :2].mean(0)) ** 2).sum(1))
    Vd[centre, 2] -= 0.01
    assert planar_normal_deviation(V, F, Vd, FL, 2) > 0.1
    e = bending_energy(Vd, FL)
    assert e > 1e-4 and bending_energy(Vd * 3.0, FL) == pytest.approx(e)



def test_normal_error_against_the_original():
    """0 for the original itself; for a grid with one vertex pushed in, the area-weighted mean
    tilt of its triangles against the flat original's normal (computed here exactly, without
    sampling), within the sampling's error; the same for any size; a kept crease (the
    original's own fold) costs nothing."""
    from algorithms.mesh.primitives import grid
    from algorithms.subdivision.metrics import normal_error

    V, F = grid(12, 12)
    assert normal_error(V, F, V, F, samples=20_000) < 1e-6
    Vd = V.copy()
    centre = np.argmin(((V[:, :2] - V[:, :2].mean(0)) ** 2).sum(1))
    Vd[centre, 2] -= 0.05
    n = np.cross(Vd[F[:, 1]] - Vd[F[:, 0]], Vd[F[:, 2]] - Vd[F[:, 0]])
    area = np.linalg.norm(n, axis=1)
    tilt = np.degrees(np.arccos(np.abs(n[:, 2]) / area))
    exact = float((tilt * area).sum() / area.sum())
    got = normal_error(Vd, F, V, F, samples=200_000)
    assert exact > 0.1 and got == pytest.approx(exact, rel=0.03)
    assert normal_error(Vd * 3.0, F, V * 3.0, F, samples=200_000) == pytest.approx(got)
    # the original folded along x = middle: the same fold in the result is no error
    Vf = V.copy()
    Vf[:, 2] = 0.3 * np.abs(V[:, 0] - V[:, 0].mean())
    assert normal_error(Vf, F, Vf, F, samples=20_000) < 1e-6
    assert normal_error(V, F, Vf, F, samples=20_000) > 10.0       # rounding it off is

def _default_run(path, levels):
    m = read_mesh(path)
    r = run("subdivide", MeshState.make(m.V, m.F), {"method": "neural", "levels": levels}, {})
    return m, r


@pytest.mark.parametrize("levels", [1, 2])
def test_fandisk_as_it_is_keeps_its_flat_sides_flat(levels):
    """The default on fandisk as it is (7,229 vertices, 5.7x denser than the training meshes):
    the network's level 1 is kept (averaged with its mirror image it bends no flat side), and
    its flat sides stay as flat as Loop's (measured 0.009 degrees RMS at 1 and 2 levels, Loop
    0.008: float32 rounding). Before the mirror average the network bent them by 1.1 degrees and
    Loop made every level (this test then asserted Loop's result)."""
    m, r = _default_run(FANDISK, levels)
    planar = planar_faces(m.V, m.F)
    assert planar.sum() > 0.1 * len(m.F)
    dev = planar_normal_deviation(m.V, m.F, r.state.V, r.state.F, levels, planar)
    assert dev < 0.05
    assert r.outcome["levels_used"][0] == "neural"
    assert "denser than the network was trained for" in r.outcome["note"]


def test_the_mirror_average_keeps_a_plane_a_plane_and_commutes_with_mirroring():
    """The network averaged with its mirror image (inference's default for our networks) is
    equivariant to reflections: a jittered flat grid subdivides into a flat surface (to float32
    rounding), and subdividing a mirrored mesh (positions mirrored, faces as they are) gives
    the mirrored result. The plain network
    (``mirror=False``, as the author's runs) does neither -- the test would fail without the
    average."""
    import dataclasses

    from algorithms.mesh.primitives import grid

    V, F = grid(14, 14)
    rng = np.random.default_rng(3)
    V = V + np.c_[rng.uniform(-0.2, 0.2, (len(V), 2)) / 14, np.zeros(len(V))]
    net = load_network(None)
    plain = dataclasses.replace(net, mirror=False)
    assert net.mirror_average and not plain.mirror_average
    out, Fo, _ = neural_subdivide_np(V, F, 2, net, dense="scale")
    raw, _, _ = neural_subdivide_np(V, F, 2, plain, dense="scale")
    size = np.ptp(V, axis=0).max()
    assert np.abs(out[:, 2] - V[0, 2]).max() < 1e-5 * size
    assert np.abs(raw[:, 2] - V[0, 2]).max() > 1e-3 * size
    M = np.diag([1.0, -1.0, 1.0])  # another mirror than the one averaged with
    m = read_mesh(BOB)
    a, _, _ = neural_subdivide_np(m.V, m.F, 1, net, dense="scale")
    b, _, _ = neural_subdivide_np(m.V @ M, m.F, 1, net, dense="scale")
    diag = np.linalg.norm(np.ptp(m.V, axis=0))
    assert np.abs(b @ M - a).max() < 1e-5 * diag
    c, _, _ = neural_subdivide_np(m.V, m.F, 1, plain, dense="scale")
    d, _, _ = neural_subdivide_np(m.V @ M, m.F, 1, plain, dense="scale")
    assert np.abs(d @ M - c).max() > 1e-4 * diag


def test_fandisk_scaled_network_keeps_its_dimples_small():
    """With dense_input="scale" the network runs (scaled to its training edge length): its
    dimples on the flat sides stay small. Measured with the weights shipped since 2026-11-29
    (issue 36 item 3): 1.9 degrees scaled, 1.2 unguarded; the weights shipped before: 3.1
    scaled but 32 unguarded (then this test asserted scaled < unguarded / 4, which the new
    network, far less pitted unguarded, no longer needs)."""
    m = read_mesh(FANDISK)
    net = load_network(None)
    planar = planar_faces(m.V, m.F)
    Vs, Fs, note = neural_subdivide_np(m.V, m.F, 2, net, dense="scale")
    Vo, Fo, none = neural_subdivide_np(m.V, m.F, 2, net, dense="off")
    assert "scaled to match" in note and none == ""
    scaled = planar_normal_deviation(m.V, m.F, Vs, Fs, 2, planar)
    raw = planar_normal_deviation(m.V, m.F, Vo, Fo, 2, planar)
    assert scaled < 3.0 and raw < 3.0  # measured 1.9 and 1.2 degrees (Loop: 0.01)


def test_dense_bob_default_no_bumpier_than_the_guard_allows():
    """bob at its own density (5,344 vertices, 4.5x denser than the training meshes), 2
    levels, defaults: the network makes both levels, and its result is within the guard's
    factor for dense meshes of butterfly's bending (measured 1.15x; the network without the
    mirror average: 2.3x, faint dimples, and Loop made level 2 -- see the next test)."""
    from algorithms.subdivision.inference import GUARD_BENDING_FACTOR_DENSE

    m, r = _default_run(BOB, 2)
    VB, FB = subdivide_baseline(m.V, m.F, 2, "butterfly")
    bent = bending_energy(r.state.V, r.state.F) / bending_energy(VB, FB)
    assert bent <= GUARD_BENDING_FACTOR_DENSE
    assert r.outcome["levels_used"] == ["neural", "neural"]
    assert r.outcome["method_used"] == "neural" and r.outcome["fallback"] is False


def test_the_guard_keeps_the_network_where_it_is_no_bumpier_than_butterfly():
    """Issue 36: the guard decides from what the network produced, not from the density. On a
    coarse input (the blob QSlimmed to 400 vertices) it keeps the network's result, bit for
    bit the scaled network's. Its fallbacks are exercised with the plain network (without the
    mirror average, as the author's network runs), which fails where the shipped default no
    longer does: on the blob and bob as they are its level 2 is 1.75x and 2.3x as bent as
    modified butterfly's (dimples), and it bends fandisk's flat sides; Loop's levels are used
    there, said in the note."""
    import dataclasses

    from algorithms.subdivision.inference import (GUARD_BENDING_FACTOR,
                                                  GUARD_BENDING_FACTOR_DENSE, SubdividedStep,
                                                  neural_subdivision_iter)
    from algorithms.subdivision.metrics import coarsen_to_vertices

    m = read_mesh(BLOB)
    shipped = load_network(None)
    net = dataclasses.replace(shipped, mirror=False)

    def last(V, F, dense, network=net):
        steps = list(neural_subdivision_iter(V, F, 2, network, dense=dense))
        assert isinstance(steps[-1], SubdividedStep)
        return steps[-1]

    Vc, Fc = coarsen_to_vertices(m.V, m.F, 400)
    kept = last(Vc, Fc, "guard", shipped)
    assert not kept.fallback and kept.metrics["bending_vs_butterfly"] <= GUARD_BENDING_FACTOR
    np.testing.assert_array_equal(kept.V, last(Vc, Fc, "scale", shipped).V)
    assert kept.levels_used == ("neural", "neural")
    # a mesh denser than the training meshes gets the stricter factor: the blob as it is, level
    # 2 at 1.75x butterfly's bending (faint dimples, seen) is Loop's, level 1 (1.10x) the
    # network's
    blob = last(m.V, m.F, "guard")
    assert blob.levels_used == ("neural", "loop")
    assert GUARD_BENDING_FACTOR_DENSE < blob.metrics["bending_vs_butterfly"] \
        <= GUARD_BENDING_FACTOR
    # per level: on bob as it is, level 1 passes, level 2 is 2.3x butterfly's bending: the
    # network's level 1 is kept and Loop subdivides it once
    m = read_mesh(BOB)
    dense = last(m.V, m.F, "guard")
    assert dense.fallback and dense.metrics["bending_vs_butterfly"] > GUARD_BENDING_FACTOR_DENSE
    assert dense.levels_used == ("neural", "loop")
    one = list(neural_subdivision_iter(m.V, m.F, 1, net, dense="guard"))[-1]
    assert one.levels_used == ("neural",) and not one.fallback
    assert one.metrics["bending_vs_butterfly"] <= GUARD_BENDING_FACTOR_DENSE
    VL, FL = subdivide_baseline(one.V, one.F, 1, "loop")
    np.testing.assert_array_equal(dense.V, VL)
    np.testing.assert_array_equal(dense.F, FL)
    assert "as bent as modified butterfly's" in dense.note
    assert "The network made level 1; at level 2" in dense.note
    assert "Loop subdivision made level 2" in dense.note
    # a 3-level run whose level 2 fails: levels 2-3 by Loop, said so
    three = list(neural_subdivision_iter(m.V, m.F, 3, net, dense="guard"))[-1]
    assert three.levels_used == ("neural", "loop", "loop")
    assert "Loop subdivision made levels 2-3" in three.note
    # a level-1 failure (the flat sides of fandisk as it is): Loop for every level, with the
    # 'Coarsen first' advice
    f = read_mesh(FANDISK)
    flat = last(f.V, f.F, "guard")
    assert flat.levels_used == ("loop", "loop") and "flat sides" in flat.note
    VL, _ = subdivide_baseline(f.V, f.F, 2, "loop")
    np.testing.assert_array_equal(flat.V, VL)
    assert "'Coarsen first' to about" in flat.note


def test_the_guard_does_not_run_the_network_on_a_big_dense_mesh(monkeypatch):
    """A dense mesh whose result would be over GUARD_MAX_TRIANGLES gets Loop without the
    network being run (comparing would cost minutes and GBs; igea: 43 s, 3.5 GB), said so."""
    from algorithms.subdivision import inference

    m = read_mesh(BLOB)
    net = load_network(None)
    monkeypatch.setattr(inference, "GUARD_MAX_TRIANGLES", 4 * len(m.F) - 1)

    def no_network(*args, **kwargs):
        raise AssertionError("the network ran")

    monkeypatch.setattr(inference, "_stage", no_network)
    last = list(inference.neural_subdivision_iter(m.V, m.F, 1, net, dense="guard"))[-1]
    assert last.fallback and "over the" in last.note and "about 450 vertices" in last.note
    VL, _ = subdivide_baseline(m.V, m.F, 1, "loop")
    np.testing.assert_array_equal(last.V, VL)
    # at the limit itself the network runs (and the guard compares)
    monkeypatch.undo()
    monkeypatch.setattr(inference, "GUARD_MAX_TRIANGLES", 4 * len(m.F))
    last = list(inference.neural_subdivision_iter(m.V, m.F, 1, net, dense="guard"))[-1]
    assert "over the" not in last.note


ENGINE_BRACKET = ROOT / "tests" / "data" / "engine_bracket.obj"


def _bracket():
    """The bracket as `--clean` gives it (the file's triangles face inwards: flipped)."""
    from algorithms.mesh.validate import clean_mesh

    m = read_mesh(ENGINE_BRACKET)
    c = clean_mesh(m.V, m.F)
    return c.V, c.F


def _children_stay_in_their_parents(F_parent: np.ndarray, F_child: np.ndarray, n: int) -> None:
    """Every child face 4 f .. 4 f + 3 uses, of the old vertices (ids < n), only f's corners."""
    kids = F_child.reshape(len(F_parent), 4, 3)
    for c in range(4):
        old = kids[:, c, :] < n
        inside = (kids[:, c, :, None] == F_parent[:, None, :]).any(-1)
        assert (inside | ~old).all()
    assert (kids < n).sum() == 3 * len(F_parent)      # each corner in exactly one child


def test_children_of_face_f_are_4f_to_4f_plus_3_for_loop_and_the_network():
    """The crossing check maps a triangle of a k-level result to its input triangle as
    f // 4**k: true of Loop's numbering and of the network's (refine)."""
    from algorithms.mesh.subdivision import loop_subdivide
    from algorithms.subdivision.topology import refine

    V, F = _bracket()
    V1, F1 = loop_subdivide(V, F, 1)
    _children_stay_in_their_parents(F, F1, len(V))
    _, F2 = loop_subdivide(V1, F1, 1)
    _children_stay_in_their_parents(F1, F2, len(V1))
    np.testing.assert_array_equal(loop_subdivide(V, F, 2)[1], F2)
    R1 = refine(F, len(V))
    _children_stay_in_their_parents(F, R1, len(V))


def test_crossings_not_in_parents_counts_only_new_ones():
    from algorithms.mesh.intersections import crossings_not_in_parents

    inherited = np.array([[3, 9]])
    # level 1: children 12-15 of 3 and 36-39 of 9 are inherited; 0 x 20 (faces 0 and 5) is new
    pairs = np.array([[12, 37], [39, 15], [0, 20], [1, 2]])
    assert crossings_not_in_parents(pairs, 1, inherited) == 2
    assert crossings_not_in_parents(pairs, 1, np.zeros((0, 2))) == 4
    assert crossings_not_in_parents(np.zeros((0, 2)), 1, inherited) == 0
    # level 2: 16 children per face
    assert crossings_not_in_parents(np.array([[48, 150], [0, 160]]), 2, inherited) == 1


def test_the_guard_blends_the_level_before_back_in_where_the_network_crosses_itself():
    """A CAD bracket with thin ribs close to each other (closed, genus 6): the network's level
    1 crosses itself where the input does not (its ribs pushed through each other); Loop's
    does not. The guard keeps the network's result and blends the level before (here the
    input, split at its edges' midpoints) back in around the crossing triangles only, said in
    the note; the result crosses itself nowhere new, and away from there it is the network's,
    bit for bit."""
    from algorithms.mesh.intersections import (count_self_intersections,
                                               crossings_not_in_parents,
                                               intersecting_pairs_here)
    from algorithms.subdivision.inference import (midpoints_in_refine_numbering,
                                                  neural_subdivision_iter)
    from algorithms.subdivision.topology import refine

    V, F = _bracket()
    assert count_self_intersections(V, F) == 0
    net = load_network(None)
    forced = list(neural_subdivision_iter(V, F, 1, net, dense="scale"))[-1]
    made = crossings_not_in_parents(intersecting_pairs_here(forced.V, forced.F), 1,
                                    np.zeros((0, 2)))
    assert made > 0
    VL, FL = subdivide_baseline(V, F, 1, "loop")
    assert count_self_intersections(VL, FL) == 0
    guarded = list(neural_subdivision_iter(V, F, 1, net, dense="guard"))[-1]
    assert not guarded.fallback and guarded.levels_used == ("neural",)
    np.testing.assert_array_equal(guarded.F, forced.F)
    assert count_self_intersections(guarded.V, guarded.F) == 0
    changed = np.flatnonzero((guarded.V != forced.V).any(axis=1))
    n = int(guarded.metrics["unsmoothed_vertices"])
    assert 0 < len(changed) == n < 0.05 * len(guarded.V)
    assert f"crossed itself in {made} places where the input does not" in guarded.note
    assert (f"the surface of the level before was blended back in ({n} vertices, level 1, "
            f"left unsmoothed)") in guarded.note
    # every changed vertex moved straight towards the level before (the input split at
    # midpoints), never past it, and only as far as it took (the least blend)
    W = midpoints_in_refine_numbering(V, F, refine(F, len(V)))
    d = guarded.V[changed] - forced.V[changed]
    D = W[changed] - forced.V[changed]
    t = (d * D).sum(axis=1) / (D * D).sum(axis=1)
    assert (t > 0).all() and (t <= 1 + 1e-9).all()
    np.testing.assert_allclose(d, t[:, None] * D, atol=1e-9)
    # two levels: level 2 goes on from the repaired level 1, and crosses nowhere new either
    two = list(neural_subdivision_iter(V, F, 2, net, dense="guard"))[-1]
    assert two.levels_used == ("neural", "neural") and not two.fallback
    assert count_self_intersections(two.V, two.F) == 0


def test_the_blend_note_says_what_was_changed_and_what_is_left():
    from algorithms.subdivision.inference import _Guard

    V, F = _bracket()
    g = _Guard(V, F)
    assert g.blend_note() == ""
    g.unsmoothed, g.blended_levels, g.crossings_seen = 38, [1], 5
    assert g.blend_note().endswith("blended back in (38 vertices, level 1, left unsmoothed).")
    g.unsmoothed, g.blended_levels, g.crossings_seen = 1200, [1, 2], 900
    g.crossings_left = (40, 12)
    assert g.blend_note() == (
        "The network's result crossed itself in 900 places where the input does not; there "
        "the surface of the level before was blended back in (1,200 vertices, levels 1, 2, "
        "left unsmoothed); 40 crossings are left (Loop subdivision's: 12).")


def _two_spheres():
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    return np.vstack([V, V + [3.0, 0.0, 0.0]]), np.vstack([F, F + len(V)])


def test_the_guard_hands_only_the_bumpy_part_to_loop():
    """Issue 36: a mesh of several parts is judged part by part (parts share no vertex, so each
    keeps its own scheme's stencils): the part whose result is bumpy gets Loop subdivision's
    positions, the other keeps the network's."""
    from algorithms.mesh.subdivision import loop_subdivide
    from algorithms.subdivision.inference import _Guard

    V, F = _two_spheres()
    n = len(V) // 2
    Vb, Fb = subdivide_baseline(V, F, 1, "butterfly")   # the network's numbering
    rng = np.random.default_rng(1)
    part = np.zeros(len(Vb), int)
    part[np.unique(Fb[len(F) // 2 * 4:])] = 1
    V_net = Vb + 1e-3 * rng.standard_normal(Vb.shape) * (part == 0)[:, None]   # faint
    V_net[part == 1] *= 1.0 + 0.05 * rng.standard_normal((int((part == 1).sum()), 1))
    g = _Guard(V, F, 2.6)
    why, out = g.check(1, V_net, Fb, (V, F))
    assert why == "" and out is not None
    np.testing.assert_array_equal(out[part == 0], V_net[part == 0])
    # the bumpy part is Loop's: its old vertices where Loop puts them, its new ones the same
    # points (Loop numbers them in another order)
    VL, FL = loop_subdivide(V, F, 1)
    old = np.arange(len(V)) >= n
    np.testing.assert_allclose(out[:len(V)][old], VL[:len(V)][old], atol=1e-12)
    new_ours = out[len(V):][part[len(V):] == 1]
    part_l = np.zeros(len(VL), int)
    part_l[np.unique(FL[len(F) // 2 * 4:])] = 1
    new_loop = VL[len(V):][part_l[len(V):] == 1]
    np.testing.assert_allclose(np.sort(new_ours.round(9), axis=0),
                               np.sort(new_loop.round(9), axis=0), atol=1e-9)
    assert g.levels_used(2) == ("neural+loop", "neural+loop")
    assert "on 1 of the mesh's 2 parts (50 % of its triangles): at level 1 the network's" \
        in g.parts_note()      # the counts said once
    assert g.parts_reason().startswith("at level 1 on 1 of 2 parts (50 % of the triangles)")
    # a part already given to Loop is not judged again; when every part fails, the level fails
    g2 = _Guard(V, F, 2.6)
    bumpy = Vb * (1.0 + 0.05 * rng.standard_normal((len(Vb), 1)))
    why, out = g2.check(1, bumpy, Fb, (V, F))
    assert "as bent as modified butterfly's" in why and out is None
    assert not g2.part_fallbacks


def test_a_one_part_mesh_is_judged_whole():
    from algorithms.mesh.primitives import icosphere
    from algorithms.subdivision.inference import _Guard

    V, F = icosphere(2)
    Vb, Fb = subdivide_baseline(V, F, 1, "butterfly")
    g = _Guard(V, F, 2.6)
    assert g.n_parts == 1
    why, out = g.check(1, Vb, Fb, (V, F))
    assert why == "" and out is None and g.levels_used(1) == ("neural",)
    assert abs(g.ratio - 1.0) < 1e-12


def test_an_isolated_bulge_gets_loop_there_and_the_network_elsewhere():
    """Issue 36: a level whose excess bending sits in a few input triangles (face at 200
    vertices: 78 % of it in one of 390) keeps the network, with Loop's positions blended in
    around those triangles only; the note and ``bumps`` say where."""
    from algorithms.mesh.primitives import icosphere
    from algorithms.mesh.topology import vertex_adjacency
    from algorithms.subdivision.inference import _Guard, _loop_positions

    V, F = icosphere(2)
    Vb, Fb = subdivide_baseline(V, F, 1, "butterfly")      # the network's numbering
    V_net = Vb.copy()
    kids = Fb[4 * 7:4 * 7 + 4]                              # the children of input triangle 7
    centre = np.unique(kids[3])                             # its three new (edge) vertices
    V_net[centre] *= 1.5                                    # a bulge over that one triangle
    g = _Guard(V, F, 2.6)
    why, out = g.check(1, V_net, Fb, (V, F))
    assert why == "" and out is not None
    assert g.bumps and g.bumps[0][:2] == (1, 1)             # level 1, one input triangle
    (chosen,) = g.bump_triangles[0]
    # the bulging vertices lie on triangle 7's edges: the triangle repaired is 7 or one of its
    # three neighbours across those edges
    shares_edge = [f for f in range(len(F)) if len(set(F[f]) & set(F[7])) >= 2]
    assert chosen in shares_edge
    moved = np.abs(out - V_net).max(axis=1) > 0
    assert g.bumps[0][2] == moved.sum() > 0
    # Loop's positions (weight 1) on the chosen triangle's children's corners and one ring,
    # blended on the next ring, and the network's, untouched, beyond
    VL = _loop_positions(V, F, Fb, len(Vb))
    A = vertex_adjacency(Fb, len(Vb))
    ring1 = np.zeros(len(Vb), bool)
    ring1[np.unique(Fb[4 * chosen:4 * chosen + 4])] = True
    ring1 |= A @ ring1.astype(float) > 0
    ring2 = ring1 | (A @ ring1.astype(float) > 0)
    np.testing.assert_allclose(out[ring1], VL[ring1], atol=1e-12)
    np.testing.assert_allclose(out[ring2 & ~ring1], 0.5 * (V_net + VL)[ring2 & ~ring1],
                               atol=1e-12)
    np.testing.assert_array_equal(out[~ring2], V_net[~ring2])
    assert moved.sum() < 0.06 * len(Vb) and g.ratio <= 2.6
    assert g.bump_note() == (
        f"The network's result bulged or dimpled over 1 of the input's triangles; Loop "
        f"subdivision's positions were blended in there ({moved.sum():,} vertices, level 1), "
        f"the network made the rest.")
    g.bumps = [(1, 3, 40), (2, 5, 120)]      # at two levels: counted per level
    assert g.bump_note().startswith("The network's result bulged or dimpled over the input's "
                                    "triangles (3 at level 1, 5 at level 2); Loop subdivision's "
                                    "positions were blended in there (160 vertices, levels 1, 2)")


def test_bulges_over_many_triangles_fail_the_level():
    """More than BUMP_SHARE (2 %) of the input's triangles to repair: the network is not the
    scheme for this mesh, the level fails as before and nothing is blended."""
    from algorithms.mesh.primitives import icosphere
    from algorithms.subdivision.inference import BUMP_SHARE, _Guard

    V, F = icosphere(2)                                     # 320 triangles: at most 6
    Vb, Fb = subdivide_baseline(V, F, 1, "butterfly")
    V_net = Vb.copy()
    for f in range(0, 320, 16):                             # 20 triangles far apart
        V_net[np.unique(Fb[4 * f + 3])] *= 1.15
    assert 20 > BUMP_SHARE * len(F)
    g = _Guard(V, F, 2.6)
    why, out = g.check(1, V_net, Fb, (V, F))
    assert "as bent as modified butterfly's" in why and out is None and not g.bumps
    assert not g.bump_triangles


def test_a_part_handed_to_loop_stays_loop_at_the_next_level():
    """A part that failed at level 1 gets Loop's positions at level 2 too, even when the
    rest of the mesh passes there (it is judged no more)."""
    from algorithms.subdivision.inference import _Guard, _loop_positions

    V, F = _two_spheres()
    Vb, Fb = subdivide_baseline(V, F, 1, "butterfly")
    part = np.zeros(len(Vb), int)
    part[np.unique(Fb[len(F) // 2 * 4:])] = 1
    rng = np.random.default_rng(1)
    V_net = Vb.copy()
    V_net[part == 1] *= 1.0 + 0.05 * rng.standard_normal((int((part == 1).sum()), 1))
    g = _Guard(V, F, 2.6)
    why, out1 = g.check(1, V_net, Fb, (V, F))
    assert why == "" and g.loop_part.tolist() == [False, True]
    V2, F2 = subdivide_baseline(V, F, 2, "butterfly")      # level 2's numbering
    part2 = np.zeros(len(V2), int)
    part2[np.unique(F2[len(F) // 2 * 16:])] = 1
    V2_net = V2 + 1e-4 * rng.standard_normal(V2.shape)   # the network, fine everywhere
    why, out2 = g.check(2, V2_net, F2, (out1, Fb))
    assert why == "" and out2 is not None
    np.testing.assert_array_equal(out2[part2 == 0], V2_net[part2 == 0])
    VL = _loop_positions(out1, Fb, F2, len(V2))
    np.testing.assert_allclose(out2[part2 == 1], VL[part2 == 1], atol=1e-12)
    assert g.levels_used(2) == ("neural+loop", "neural+loop")
