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
    real = inf._stage

    def spy(*a, **k):
        for n in real(*a, **k):
            seen.add(threading.get_ident())
            yield n

    monkeypatch.setattr(inf, "_stage", spy)
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    two = list(neural_subdivision_iter(m.V, m.F, 2, net, chunk=2000, dense="scale"))
    assert len(seen) == 2
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
