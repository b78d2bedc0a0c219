"""NumPy inference of neural subdivision (no PyTorch), the thesis author's published network,
and the torch-free weights reader."""

from __future__ import annotations

import pickle
import shutil
import zipfile

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.subdivision.inference import (AUTHOR_REFERENCE_EDGE, SCALE_TOLERANCE,
                                              SubdividedStep, WeightsError, load_network,
                                              mean_edge_length, neural_subdivide_np,
                                              neural_subdivision_iter, scale_plan)
from algorithms.subdivision.topology import split_vertex_order
from algorithms.subdivision.weights_file import NotATorchFile, read_torch_file
from tests.conftest import ROOT

REF = ROOT.parent / "shared" / "reference" / "neural_subdivision"
AUTHOR = REF / "author_network" / "netparams.dat"
needs_reference = pytest.mark.skipif(
    not AUTHOR.is_file(), reason=f"the thesis author's network and outputs are not here ({REF}; "
                                 f"MPL-2.0 data kept outside the repository)")
DATA = ROOT / "tests" / "data"


@needs_reference
def test_reproduces_the_authors_outputs_on_its_validation_set():
    net = load_network(AUTHOR)
    assert net.formulation == "author" and net.info["Dout"] == 32
    worst = 0.0
    for k in range(1, 11):
        m = read_mesh(REF / "cartoon_elephant_10" / "subd0" / f"{k:03d}.obj")
        V, F, note = neural_subdivide_np(m.V, m.F, 2, net)
        assert note == ""  # the validation meshes are inside the training range
        a1 = read_mesh(REF / "author_outputs" / f"{k:03d}_level1.obj")
        a2 = read_mesh(REF / "author_outputs" / f"{k:03d}_level2.obj")
        order = split_vertex_order(m.F, len(m.V), [a1.F, a2.F])
        diag = np.linalg.norm(m.V.max(0) - m.V.min(0))
        err = np.abs(V - a2.V[order]).max() / diag
        worst = max(worst, err)
        # same triangles, as vertex sets
        ours = {tuple(sorted(f)) for f in order[F].tolist()}
        assert ours == {tuple(sorted(f)) for f in a2.F.tolist()}
        # and it is not the input: the network moved the coarse vertices
        assert np.abs(V[:len(m.V)] - m.V).max() > 1e-5 * diag
    assert worst <= 1e-5, worst


@needs_reference
def test_author_reference_edge_is_its_validation_meshes():
    ell = []
    for k in range(1, 11):
        m = read_mesh(REF / "cartoon_elephant_10" / "subd0" / f"{k:03d}.obj")
        lo = m.V.min(0)
        ell.append(mean_edge_length((m.V - lo) / (m.V - lo).max(), m.F))
    assert abs(np.mean(ell) - AUTHOR_REFERENCE_EDGE) < 0.005 * AUTHOR_REFERENCE_EDGE


@needs_reference
def test_reader_matches_torch_load_on_both_layouts():
    torch = pytest.importorskip("torch")
    ours = ROOT / "resources" / "subdivision" / "neural_subdivision.pt"
    a = read_torch_file(AUTHOR)
    b = torch.load(AUTHOR, weights_only=True, map_location="cpu")
    assert list(a) == list(b) and all(np.array_equal(a[k], b[k].numpy()) for k in b)
    a = read_torch_file(ours)
    b = torch.load(ours, weights_only=True)
    assert a["format"] == b["format"] and a["info"] == b["info"]
    assert all(np.array_equal(a["state"][k], b["state"][k].numpy()) for k in b["state"])


@needs_reference
def test_broken_files_get_a_plain_message(tmp_path):
    garbage = tmp_path / "garbage.dat"
    garbage.write_bytes(np.random.default_rng(0).bytes(5000))
    cut = tmp_path / "netparams.dat"
    cut.write_bytes(AUTHOR.read_bytes()[:40_000])  # truncated inside the tensor data
    head = tmp_path / "head.dat"
    head.write_bytes(AUTHOR.read_bytes()[:300])  # truncated inside the pickle
    zcut = tmp_path / "ours.pt"
    zcut.write_bytes((ROOT / "resources" / "subdivision" / "neural_subdivision.pt")
                     .read_bytes()[:20_000])
    for p in (garbage, cut, head, zcut):
        with pytest.raises(WeightsError, match="not a Stylize3D neural-subdivision weights "
                                               "file, nor the thesis author's") as err:
            load_network(p)
        assert p.name in str(err.value) and "Traceback" not in str(err.value)
    # hyperparameters of another network beside it
    d = tmp_path / "other"
    d.mkdir()
    shutil.copy(AUTHOR, d / "netparams.dat")
    (d / "hyperparameters.json").write_text('{"Din": 9, "Dout": 32}')
    with pytest.raises(WeightsError, match="Din 9"):
        load_network(d / "netparams.dat")
    with pytest.raises(WeightsError, match="does not exist"):
        load_network(tmp_path / "missing.dat")


def test_reader_runs_no_code(tmp_path):
    """A pickle that would call a function is refused before anything runs."""
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (shutil.copy, (__file__, str(marker)))

    p = tmp_path / "evil.pt"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("archive/data.pkl", pickle.dumps({"format": Evil()}, protocol=2))
    with pytest.raises(NotATorchFile, match="shutil"):
        read_torch_file(p)
    legacy = tmp_path / "evil.dat"
    legacy.write_bytes(pickle.dumps(0x1950A86A20F9469CFC6C) + pickle.dumps(1001)
                       + pickle.dumps({"little_endian": True}) + pickle.dumps(Evil()))
    with pytest.raises(NotATorchFile):
        read_torch_file(legacy)
    with pytest.raises(WeightsError):
        load_network(p)
    assert not marker.exists()


@pytest.mark.parametrize("name", ["spot_lowres.obj", "hand_lowres.obj"])
def test_same_numbers_as_the_pytorch_path(name):
    pytest.importorskip("torch")
    from algorithms.subdivision.model import load_weights, neural_subdivide_torch

    m = read_mesh(DATA / name)
    net = load_network(None)
    V, F, _ = neural_subdivide_np(m.V, m.F, 2, net, adapt_scale=False)
    Vt, Ft = neural_subdivide_torch(m.V, m.F, 2, load_weights(None)[0])
    assert np.array_equal(F, Ft)
    diag = np.linalg.norm(m.V.max(0) - m.V.min(0))
    assert np.abs(V - Vt).max() <= 1e-5 * diag


def test_scale_guard_says_what_it_did():
    net = load_network(None)
    m = read_mesh(DATA / "hand_lowres.obj")
    ell = mean_edge_length(m.V, m.F)
    off = scale_plan(net, m.V, m.F, adapt=False)
    assert off.note == "" and not off.fallback
    ratio = ell * off.scale / net.reference_edge
    assert ratio < 1 / SCALE_TOLERANCE  # a dense mesh for this network
    # denser than trained: Loop instead (default), or scaled to the training edge length
    loop = scale_plan(net, m.V, m.F)
    assert loop.fallback and "Loop subdivision was used" in loop.note
    assert loop.ratio == pytest.approx(ratio)
    advice = int(loop.note.split("to about ")[1].split()[0])
    from algorithms.subdivision.metrics import coarsen_to_vertices

    Va, Fa = coarsen_to_vertices(m.V, m.F, advice)  # the advice brings it into range
    assert scale_plan(net, Va, Fa).note == ""
    scaled = scale_plan(net, m.V, m.F, dense="scale")
    assert not scaled.fallback and "scaled to match" in scaled.note
    assert np.isclose(ell * scaled.scale, net.reference_edge)
    # a coarser mesh than trained is scaled; one in range is left as its formulation scales it
    Vc, Fc = coarsen_to_vertices(m.V, m.F, 40)
    coarse = scale_plan(net, Vc, Fc)
    assert not coarse.fallback and "longer" in coarse.note
    assert np.isclose(mean_edge_length(Vc, Fc) * coarse.scale, net.reference_edge)
    Vi, Fi = Va, Fa
    inside = scale_plan(net, Vi * 7.0, Fi)
    assert inside.note == "" and inside.scale == pytest.approx(
        scale_plan(net, Vi, Fi, adapt=False).scale / 7.0)
    # Loop really is what the default returns there, with the note
    from algorithms.subdivision.baselines import subdivide_baseline

    V, F, note = neural_subdivide_np(m.V, m.F, 2, net)
    VL, FL = subdivide_baseline(m.V, m.F, 2, "loop")
    assert note == loop.note and np.array_equal(V, VL) and np.array_equal(F, FL)
    with pytest.raises(Exception, match="Unknown choice"):
        scale_plan(net, m.V, m.F, dense="maybe")


def test_steps_are_small_and_stoppable():
    """Progress steps come every chunk of half-flaps with "Level i of L" words; stopping after
    the first step leaves the rest of the work undone."""
    m = read_mesh(DATA / "hand_lowres.obj")
    net = load_network(None)
    steps = list(neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale"))
    last = steps[-1]
    assert isinstance(last, SubdividedStep) and len(last.F) == 16 * len(m.F)
    progress = steps[:-1]
    # 3 m flaps for I, then 2 x 3 m 4^k per level: at least one step per 2000 flaps
    assert len(progress) >= (3 * len(m.F) * (1 + 2 + 8)) // 2000
    assert all(s.total == 1000 and s.V is m.V for s in progress)
    assert [s.iteration for s in progress] == sorted(s.iteration for s in progress)
    assert all(s.message.startswith(("Level 1 of 2", "Level 2 of 2")) for s in progress)
    assert not any("Iteration" in s.message for s in steps)
    gen = neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale")
    first = next(gen)
    gen.close()
    assert first.iteration < 100 and first.message.startswith("Level 1 of 2")


def test_group_sums_equal_reduceat_on_unsorted_and_sorted_groups():
    """The stage's sums over groups of half-flaps (runs of equal-size groups summed as one
    reshaped array) equal np.add.reduceat's, whatever the order of the sizes."""
    from algorithms.subdivision.inference import _group_sums

    rng = np.random.default_rng(3)
    for sizes in (np.sort(rng.integers(1, 9, 300)), rng.integers(1, 9, 300),
                  np.r_[np.full(40, 2), np.full(3, 1)]):
        starts = np.r_[0, np.cumsum(sizes)[:-1]]
        o = rng.standard_normal((int(sizes.sum()), 32)).astype(np.float32)
        ref = np.add.reduceat(o.astype(np.float64), starts, axis=0)
        got = _group_sums(o, starts, sizes)
        assert got.shape == ref.shape and got.dtype == np.float32
        assert np.abs(got - ref).max() <= 1e-5 * np.abs(ref).max()


def test_two_threads_give_the_same_bits_as_one(monkeypatch):
    """The plain and the mirrored chain on two threads (the default on two cores) give
    exactly what one thread gives, with progress steps and stopping as before; with the user's
    thread limit at 1 (NUMBA_NUM_THREADS / OMP_NUM_THREADS) no second thread is used."""
    import threading

    from algorithms.subdivision import inference as inf

    m = read_mesh(DATA / "hand_lowres.obj")
    net = load_network(None)
    assert net.mirror_average
    monkeypatch.setattr(inf, "PARALLEL_FLAPS", 1000)
    seen = set()
    real = inf._chain_sums

    def spy(*a, **k):
        seen.add(threading.get_ident())
        return real(*a, **k)

    monkeypatch.setattr(inf, "_chain_sums", spy)
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    two = list(neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale"))
    # this thread and a worker (each stage starts its own worker: its id may differ)
    assert threading.get_ident() in seen and len(seen) >= 2
    seen.clear()
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    one = list(neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale"))
    assert seen == {threading.get_ident()}
    assert np.array_equal(two[-1].V, one[-1].V) and np.array_equal(two[-1].F, one[-1].F)
    assert [s.iteration for s in two[:-1]] == sorted(s.iteration for s in two[:-1])
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    before = threading.active_count()
    gen = neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale")
    for _ in range(5):
        next(gen)
    gen.close()
    assert threading.active_count() == before


def _scene(gap_diagonals: float = 4.0):
    """hand_lowres (denser than the network's training meshes) beside a small coarse
    icosphere, ``gap_diagonals`` hand diagonals away: the scene's extent, not the hand's, set
    the network's frame before (the hand read "much denser", and 'Coarsen first' was advised
    to the 150 floor again after following it)."""
    from algorithms.mesh.primitives import icosphere

    m = read_mesh(DATA / "hand_lowres.obj")
    d = float(np.linalg.norm(np.ptp(m.V, axis=0)))
    S, FS = icosphere(1, radius=0.1 * d)
    S = S + m.V.max(axis=0) + [gap_diagonals * d, 0.0, 0.0]
    return m, np.vstack([m.V, S]), np.vstack([m.F, FS + len(m.V)]), len(m.V)


def test_a_scene_is_judged_part_by_part():
    """Issue 36 item 4: on a mesh of several parts, the density the note states and the
    'Coarsen first' count come from each part as if it were alone, whatever the gap between
    the parts (before: the scene's extent made the hand read far denser the further the sphere
    was, and the advice sat at the 150 floor). The network still sees the whole mesh in one
    frame (each part in its own frame was tried: tiny parts swelled)."""
    net = load_network(None)
    m, V, F, nh = _scene()
    alone = scale_plan(net, m.V, m.F, dense="guard")
    near = scale_plan(net, V, F, dense="guard")
    far = scale_plan(net, *_scene(40.0)[1:3], dense="guard")
    assert np.ndim(near.scale) == 0 and near.scale == pytest.approx(
        scale_plan(net, V, F, adapt=False).scale / near.ratio)
    for plan in (near, far):
        assert "1 of its 2 parts has edges shorter" in plan.note
        assert f"up to {1 / alone.ratio:.1f}x" in plan.note
    assert far.ratio < near.ratio < alone.ratio     # the whole scene, in the network's frame
    # the messages that follow the plan (a result over the guard's size, a level refused)
    # say the parts' density too, not the whole scene's
    assert near.density_words().startswith("1 of its 2 parts has edges shorter")
    assert alone.density_words() == (f"its edges are {1 / alone.ratio:.1f}x shorter than its "
                                     f"training meshes'")
    # the hand's count (as alone) + the sphere's 42 vertices (in range: kept), to 10
    assert near.advice == far.advice and abs(near.advice - (alone.advice + 42)) <= 10
    # in range as a whole, with a denser part (the hand inside six coarse spheres): said,
    # with the advice, and nothing done to the frame
    from algorithms.mesh.primitives import icosphere

    S, FS = icosphere(2, radius=0.5 * np.ptp(m.V, axis=0).max())
    S = S + m.V.mean(axis=0)
    Vi = np.vstack([m.V] + [S] * 6)
    Fi = np.vstack([m.F] + [FS + len(m.V) + i * len(S) for i in range(6)])
    inside = scale_plan(net, Vi, Fi, dense="guard")
    assert 1 / SCALE_TOLERANCE <= inside.ratio <= SCALE_TOLERANCE and not inside.fallback
    assert inside.note.startswith("1 of this mesh's 7 parts has edges shorter")
    assert abs(inside.advice - (alone.advice + 6 * len(S))) <= 10   # the hand's + the spheres'
    assert f"'Coarsen first' to about {inside.advice} vertices" in inside.note
    assert inside.scale == scale_plan(net, Vi, Fi, adapt=False).scale


def test_coarsen_first_on_a_scene_reaches_what_it_advised():
    """The advice on a scene sums what each part needs, and 'Coarsen first' to it coarsens
    each part to its share: after it no part is denser than trained and nothing is advised
    again (before: QSlim on the whole scene took the small part's vertices first, and the
    advice came back). On one part nothing changes: the same QSlim as before."""
    from algorithms.subdivision.inference import coarsen_for_network
    from algorithms.subdivision.metrics import coarsen_to_vertices, coarsening_problem

    net = load_network(None)
    m, V, F, nh = _scene()
    plan = scale_plan(net, V, F, dense="guard")
    assert plan.advice and f"'Coarsen first' to about {plan.advice} vertices" in plan.note
    Vc, Fc = coarsen_for_network(net, V, F, plan.advice)
    assert abs(len(Vc) - plan.advice) <= 0.1 * plan.advice
    assert coarsening_problem(V, F, Vc, Fc, plan.advice) == ""
    after = scale_plan(net, Vc, Fc, dense="guard")
    assert after.advice == 0 and "Coarsen first" not in after.note
    assert "parts lie apart" in after.note and "each part's own are in range" in after.note
    a = coarsen_for_network(net, m.V, m.F, 300)
    b = coarsen_to_vertices(m.V, m.F, 300)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_no_advice_to_coarsen_what_coarsening_would_not_help():
    """'Coarsen first' is advised only to clearly fewer vertices than the mesh has: a mesh
    already near the advised count (the 150 floor) is scaled, and the note says no more."""
    from algorithms.subdivision.inference import ADVICE_SHARE, _advice

    assert _advice(2000, [(2000, 0.3)]) == 270
    assert _advice(160, [(160, 0.3)]) == 0            # 150 of 160: not clearly fewer
    assert _advice(1000, [(1000, 0.9)]) == 0          # not denser
    assert _advice(int(150 / ADVICE_SHARE) + 10, [(int(150 / ADVICE_SHARE) + 10, 0.1)]) == 150


@pytest.mark.parametrize("threads", ["1", "2"])
def test_the_mirror_average_commutes_with_a_mirror(monkeypatch, threads):
    """The mirror chain reuses the plain chain's flap frames with their normal components
    negated; if that were wrong, subdividing the mirror image would not give the mirror image
    of the result. It does, to float32 rounding, on one thread and on two."""
    from algorithms.subdivision import inference as inf

    monkeypatch.setattr(inf, "PARALLEL_FLAPS", 1000)
    monkeypatch.setenv("NUMBA_NUM_THREADS", threads)
    m = read_mesh(DATA / "hand_lowres.obj")
    net = load_network(None)
    M = np.array([-1.0, 1.0, 1.0])
    V, F, _ = neural_subdivide_np(m.V, m.F, 2, net, dense="scale")
    Vm, Fm, _ = neural_subdivide_np(m.V * M, m.F, 2, net, dense="scale")
    assert np.array_equal(F, Fm)
    diag = float(np.linalg.norm(np.ptp(m.V, axis=0)))
    assert np.abs(Vm * M - V).max() <= 1e-6 * diag
    # without the average (the network alone) the mirror image differs: the test can fail
    net.mirror = False
    V1 = neural_subdivide_np(m.V, m.F, 2, net, dense="scale")[0]
    V1m = neural_subdivide_np(m.V * M, m.F, 2, net, dense="scale")[0]
    assert np.abs(V1m * M - V1).max() > 1e-4 * diag


def test_coarsen_first_keeps_every_part_or_says_the_count_that_does():
    """Each part keeps at least 4 vertices (what it has, if fewer), the rest of the count is
    shared as the parts need it; a count too small for that is refused with the count that
    works (whole-mesh QSlim made parts vanish there)."""
    from algorithms.errors import ParameterError
    from algorithms.mesh.primitives import icosphere
    from algorithms.mesh.topology import connected_components
    from algorithms.subdivision.inference import coarsen_for_network

    net = load_network(None)
    m = read_mesh(DATA / "hand_lowres.obj")
    S, FS = icosphere(1, radius=0.02 * np.ptp(m.V, axis=0).max())
    Vs, Fs, n = [m.V], [m.F], len(m.V)
    for i in range(30):   # 30 small 42-vertex spheres in a row beside the hand
        Vs.append(S + m.V.max(axis=0) + [0.05 * (i + 1) * np.ptp(m.V, axis=0).max(), 0, 0])
        Fs.append(FS + n)
        n += len(S)
    V, F = np.vstack(Vs), np.vstack(Fs)
    with pytest.raises(ParameterError, match=r"31 separate parts.*'Coarsen first' to 124 or more"):
        coarsen_for_network(net, V, F, 100)
    Vc, Fc = coarsen_for_network(net, V, F, 400)
    assert connected_components(Fc, len(Vc))[0] == 31
    assert 0.9 * 400 <= len(Vc) <= 1.1 * 400
