"""Neural subdivision benchmark (issue 14): sizes, medians and ratios against peers in one run.

* inference: a ~1k-face mesh (spot, QSlim-decimated) -> 2 levels, neural vs Loop (libigl) vs
  modified butterfly (ours);
* data generation: seconds per coarse mesh at the default sizes (150-300 vertices, 100 random
  edges per collapse) on armadillo (14.5k vertices), split into collapses (the
  self-parameterization), map queries and Loop topology + target points; 1 local worker vs 2
  (speed-up);
* training: seconds per coarse mesh (forward, backward + Adam, other) and per epoch at the
  default sizes (an epoch = 180 training meshes of the default 200, 20 validated in one batch),
  and the whole default training extrapolated (data + epochs).

Every timing is wall-clock on a possibly shared machine: the load average is printed with them.

``--inference`` (issue 22) runs only this: the whole ``stylize3d subdivide`` process (neural,
shipped weights, 2 levels; median of 5 runs of the whole command) on a ~1k-face and a ~10k-face
mesh against ``stylize3d subdivide --method loop`` on the same mesh in the same run (the
process's fixed cost is the same; targets <= 1.2 s and <= 2 s), the time of ``python -c
'import torch'`` (what the command no longer pays), and in this process the NumPy inference
against the PyTorch path (``neural_subdivide_torch``, one torch thread) on the same meshes.

``--roughness`` (issue 22) subdivides every shared mesh as it is (tests/data/*,
resources/samples/*.obj) 1-3 levels with Loop and with neural subdivision as the recipe runs it
(shipped weights, default settings), and at 2 levels also the network scaled
(``dense_input="scale"``) and unguarded (``"off"``), printing the planar-region normal
deviation (degrees) and the bending energy of each (:mod:`algorithms.subdivision.metrics`)
with the ratio to Loop's; ``--render DIR`` also writes a picture per mesh (pyvista off-screen).

``--validation-set W...`` (issue 22) subdivides the thesis author's validation set
(../shared/reference/neural_subdivision/cartoon_elephant_10: ten coarse elephants with ground
truth at level 2) 2 levels with each weights file (``author``: the author's network,
``shipped``: ours) and with Loop and butterfly, and prints each one's per-vertex RMS and max
error against the ground truth, in units of the bounding-box diagonal (the author's README:
~1.0-1.4e-3 for its network).

Usage: ``python benchmarks/subdivision.py [--quick] [--full [--save W.pt]]`` (``--quick``: fewer
repeats and meshes; ``--full``: also runs the whole default training once -- 200 coarse meshes
with 2 workers, then ``TrainParams()`` -- and prints its measured split).

``--learn-loop N EPOCHS`` instead runs App. 4.8.7 (learning Loop): trains on N coarse meshes of
bob whose targets are their own Loop subdivision, for EPOCHS epochs, then subdivides unseen
coarse meshes (spot, armadillo, fertility; QSlim to ~300 vertices) and prints the mean and max
per-vertex distance to libigl's Loop, in % of the bounding-box diagonal (thesis: 0.3 % mean).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_seconds, mesh_path  # noqa: E402


def _load() -> str:
    try:
        return "load average " + " / ".join(f"{x:.1f}" for x in os.getloadavg()) + \
            f" (1/5/15 min) on {os.cpu_count()} cores"
    except OSError:  # pragma: no cover - not on Linux
        return "load average unknown"


def _cpu_and_wall(fn):
    """(result, CPU seconds of this process, wall seconds)."""
    c, w = time.process_time(), time.perf_counter()
    r = fn()
    return r, time.process_time() - c, time.perf_counter() - w


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--learn-loop", nargs=2, type=int, metavar=("N", "EPOCHS"))
    ap.add_argument("--validation-set", nargs="+", metavar="W",
                    help="only: level-2 errors on the author's validation set for these weights "
                         "('author', 'shipped' or files), with Loop and butterfly")
    ap.add_argument("--roughness", action="store_true",
                    help="only the roughness figures (every shared mesh, 1-3 levels)")
    ap.add_argument("--render", default="", help="with --roughness: write pictures here")
    ap.add_argument("--max-levels", type=int, default=3,
                    help="with --roughness: up to this many levels (default 3)")
    ap.add_argument("--inference", action="store_true",
                    help="only the inference figures (whole CLI process, NumPy vs PyTorch)")
    ap.add_argument("--coarse", type=int, default=0,
                    help="coarse meshes for the data-generation timing (default 4 quick, 8)")
    ap.add_argument("--mesh", default="armadillo.obj",
                    help="training shape (default armadillo.obj, as the shipped weights)")
    ap.add_argument("--full", action="store_true",
                    help="also run the whole default training once (200 coarse meshes, "
                         "TrainParams() defaults incl. early stopping) and print its split")
    ap.add_argument("--patience", type=int, default=None,
                    help="with --full: early stopping patience (default: TrainParams' 0 = all "
                         "700 epochs)")
    ap.add_argument("--save", default="", help="with --full: write the trained weights here")
    ap.add_argument("--cache-dir", default="",
                    help="with --full: data cache folder (default: a fresh temporary one, so "
                         "the data generation is timed)")
    args = ap.parse_args()
    if args.inference:
        return inference(5 if not args.quick else 3)
    if args.roughness:
        return roughness(args.max_levels, args.render)
    if args.validation_set:
        return validation_set(args.validation_set)
    import torch

    torch.set_num_threads(1)
    if args.learn_loop:
        return learn_loop(*args.learn_loop)
    from algorithms.mesh import read_mesh
    from algorithms.mesh.subdivision import loop_subdivide
    from algorithms.subdivision.baselines import butterfly_subdivide
    from algorithms.subdivision.data import (DataParams, generate_coarse_sample,
                                             generate_dataset, normalization)
    from algorithms.subdivision.metrics import coarsen_to_vertices
    from algorithms.subdivision.model import SubdivisionNet, load_weights, neural_subdivide
    from algorithms.subdivision.train import Trainer, TrainParams
    from algorithms.params import params_to_dict

    print(f"start: {_load()}; torch {torch.__version__}, 1 torch thread", flush=True)
    rep = 3 if args.quick else 7
    # ---- inference
    spot = read_mesh(mesh_path("spot_lowres.obj"))
    V, F = coarsen_to_vertices(spot.V, spot.F, 502)
    try:
        net, _ = load_weights()
    except Exception:  # noqa: BLE001 - timing does not depend on the weights' values
        net = SubdivisionNet()
    neural_subdivide(V, F, 2, net)
    t_n = median_seconds(lambda: neural_subdivide(V, F, 2, net), rep)
    t_l = median_seconds(lambda: loop_subdivide(V, F, 2), rep)
    t_b = median_seconds(lambda: butterfly_subdivide(V, F, 2), rep)
    print(f"inference: {len(V)} vertices / {len(F)} faces -> 2 levels ({16 * len(F)} faces), "
          f"median of {rep}")
    print(f"  neural    {t_n * 1e3:8.1f} ms   (target <= 300 ms)  {t_n / t_l:7.1f}x Loop")
    print(f"  Loop      {t_l * 1e3:8.1f} ms   (libigl)")
    print(f"  butterfly {t_b * 1e3:8.1f} ms   {t_b / t_l:7.1f}x Loop", flush=True)

    # ---- data generation, one process: split per coarse mesh
    shape = read_mesh(mesh_path(args.mesh))
    k = args.coarse or (4 if args.quick else 8)
    p = DataParams(coarse_meshes=k, seed=12345)
    c, s = normalization(shape.V)
    Vn = (shape.V - c) * s
    generate_coarse_sample(Vn, shape.F, 10_000, p)  # compiled kernels loaded
    split = {"seconds_collapses": 0.0, "seconds_map": 0.0, "seconds_topology": 0.0}
    cpu = wall = 0.0
    for i in range(k):
        out, dc, dw = _cpu_and_wall(lambda i=i: generate_coarse_sample(Vn, shape.F, i, p))
        info = json.loads(str(out["info"]))
        for key in split:
            split[key] += info[key]
        cpu += dc
        wall += dw
    print(f"data generation: {args.mesh} {len(shape.V)} vertices / {len(shape.F)} faces -> "
          f"{k} coarse meshes of {p.min_vertices}-{p.max_vertices} vertices, {p.levels} levels, "
          f"{p.candidates} random edges per collapse")
    print(f"  1 process {wall / k:7.2f} s per coarse mesh (CPU {cpu / k:.2f} s): collapses + "
          f"self-parameterization {split['seconds_collapses'] / k:.2f} s, map queries "
          f"{split['seconds_map'] / k:.3f} s, Loop topology + target points "
          f"{split['seconds_topology'] / k:.3f} s", flush=True)
    # ---- 1 worker vs 2 workers (generate_dataset, no cache; the pool's start-up included)
    import resource

    res = {}
    for w in (1, 2):
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        generate_dataset([(shape.V, shape.F)], p, workers=w, use_cache=False)
        res[w] = time.perf_counter() - t
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        res[f"cores{w}"] = ((c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)) / res[w]
    # a warm pool (processes started, modules and compiled kernels loaded): the steady state
    # of a long run such as the default 200 coarse meshes
    import concurrent.futures as cf
    import multiprocessing

    from algorithms.subdivision import data as data_mod

    t = time.perf_counter()
    with data_mod._OneThreadChildren():
        pool = cf.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"))
        warm = [pool.submit(data_mod._task, Vn, shape.F, 10_000 + i, params_to_dict(p), None)
                for i in range(2)]
    cf.wait(warm)
    t_start = time.perf_counter() - t
    try:
        t = time.perf_counter()
        generate_dataset([(shape.V, shape.F)], p, executor=pool, use_cache=False)
        res["warm"] = time.perf_counter() - t
    finally:
        pool.shutdown()
    print(f"  generate_dataset, workers=1: {res[1] / k:7.2f} s per coarse mesh")
    print(f"  generate_dataset, workers=2: {res[2] / k:7.2f} s per coarse mesh   speed-up "
          f"{res[1] / res[2]:.2f}x (2 processes started and loaded in the run; the two "
          f"got {res['cores2']:.2f} cores on average)")
    print(f"  warm 2-process pool:         {res['warm'] / k:7.2f} s per coarse mesh   speed-up "
          f"{res[1] / res['warm']:.2f}x (start-up + first 2 meshes took {t_start:.1f} s)  "
          f"[{_load()}]")
    data_200 = 200 * min(res[2], res["warm"]) / k
    print(f"  default 200 coarse meshes: ~{data_200 / 60:.1f} min with 2 workers", flush=True)

    # ---- training: seconds per epoch at the default sizes, split
    samples = generate_dataset([(shape.V, shape.F)], p, workers=1, use_cache=False)
    t = time.perf_counter()
    tr = Trainer(samples, TrainParams(epochs=3, validation_fraction=0.0, patience=0))
    t_prep = time.perf_counter() - t  # one-time: network, optimizer, index tensors
    cpu_eps = []
    c0 = time.process_time()
    for _ in tr.steps():
        cpu_eps.append(time.process_time() - c0)
        c0 = time.process_time()
    h = tr.history[1:]  # the first epoch warms up
    cpu_ep = statistics.median(cpu_eps[1:])
    fwd = statistics.median(x["seconds_forward"] for x in h) / k
    bwd = statistics.median(x["seconds_backward"] for x in h) / k
    val = statistics.median(x["seconds_validation"] for x in h) / k  # all k in one batch
    oth = statistics.median(x["seconds_other"] for x in h) / k
    per_mesh = fwd + bwd + oth
    sizes = [len(x.V) for x in samples]
    d = TrainParams()
    ntrain, nval = 180, 20
    epoch = ntrain * per_mesh + nval * val
    print(f"training: coarse meshes of {min(sizes)}-{max(sizes)} vertices, 2 levels, 1 torch "
          f"thread, median of {len(h)} epochs over {k} meshes")
    print(f"  per coarse mesh: forward {fwd * 1e3:6.1f} ms, backward + Adam {bwd * 1e3:6.1f} ms,"
          f" other {oth * 1e3:5.1f} ms; validation (batched) {val * 1e3:5.1f} ms; set-up once "
          f"(network, optimizer, index tensors of {k} meshes) {t_prep:.2f} s")
    print(f"  CPU per epoch of these {k} meshes {cpu_ep:.2f} s vs wall "
          f"{statistics.median(x['seconds'] for x in h):.2f} s")
    print(f"  {epoch:7.1f} s per epoch at the default 200 coarse meshes ({ntrain} trained, "
          f"{nval} validated)")
    print(f"  whole default training, extrapolated: data {data_200 / 60:.1f} min (2 workers) + "
          f"{d.epochs} epochs {d.epochs * epoch / 60:.1f} min = "
          f"{(data_200 + d.epochs * epoch) / 60:.1f} min (patience {d.patience}); with early "
          f"stopping (e.g. --patience 60, which stopped at epoch 137 on armadillo): "
          f"{epoch * 100 / 60:.1f} min per 100 epochs")
    # the same from this process's CPU time (what a core of its own would take; the wall
    # times above include waiting for the CPU on a shared machine)
    cpu_epoch = epoch * cpu_ep / statistics.median(x["seconds"] for x in h)
    cpu_data = 200 * cpu / k / 2  # two processes, each its own core
    print(f"  CPU-time view: {cpu_epoch:.1f} s per epoch at 200 coarse meshes; data "
          f"{cpu_data / 60:.1f} min with 2 busy cores; 700 epochs {700 * cpu_epoch / 60:.0f} min; "
          f"{cpu_epoch * 100 / 60:.1f} min per 100 epochs")
    print(f"end: {_load()}", flush=True)
    if args.full:
        return full(shape, args)
    return 0


def _inference_meshes(tmp: Path) -> list:
    """(label, path, V, F): spot QSlim-ed to ~1k faces, armadillo to ~10k faces."""
    from algorithms.mesh import read_mesh, write_mesh
    from algorithms.subdivision.metrics import coarsen_to_vertices

    out = []
    for label, name, nv in (("1k faces", "spot_lowres.obj", 502),
                            ("10k faces", "armadillo.obj", 5002)):
        m = read_mesh(mesh_path(name))
        V, F = coarsen_to_vertices(m.V, m.F, nv)
        p = tmp / f"{Path(name).stem}_{len(F)}.obj"
        write_mesh(p, V, F)
        out.append((label, p, V, F))
    return out


def _process_seconds(args: list, repeat: int, env: dict | None = None) -> tuple[float, float]:
    """Median wall time and median CPU time (user + system) of a whole ``python ...`` process
    (OMP / BLAS threads as a user has). The CPU time is what the process itself needs: on a
    machine whose cores are busy with other work the wall time is mostly waiting."""
    import resource
    import subprocess

    root = Path(__file__).resolve().parents[1]
    walls, cpus = [], []

    def once():
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        r = subprocess.run([sys.executable, *args], cwd=root, capture_output=True, text=True,
                           env=None if env is None else {**os.environ, **env})
        walls.append(time.perf_counter() - t)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        if r.returncode != 0:
            raise RuntimeError(r.stderr)

    once()  # warm the file cache
    walls.clear()
    cpus.clear()
    for _ in range(max(1, repeat)):
        once()
    return statistics.median(walls), statistics.median(cpus)


def inference(repeat: int) -> int:
    """Issue 22's figures: whole-process ``stylize3d subdivide`` and NumPy vs PyTorch."""
    print(f"start: {_load()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="s3d-bench-") as d:
        tmp = Path(d)
        meshes = _inference_meshes(tmp)
        t_torch, c_torch = _process_seconds(["-c", "import torch"], repeat)
        print(f"whole process, median of {repeat} runs of the command (wall / CPU):")
        print(f"  python -c 'import torch'           {t_torch:6.2f} s / {c_torch:5.2f} s  "
              f"(no longer paid)")
        for label, p, V, F in meshes:
            out = tmp / "out.obj"
            base = ["-m", "app", "subdivide", str(p), "-o", str(out), "--overwrite",
                    "--levels", "2"]
            # --dense-input scale: the network runs even where the default would use Loop
            t_n = _process_seconds(base + ["--dense-input", "scale"], repeat)
            t_l = _process_seconds(base + ["--method", "loop"], repeat)
            # the network's two mirror chains on one thread (a user's thread limit of 1)
            t_1 = _process_seconds(base + ["--dense-input", "scale"], repeat,
                                   {"NUMBA_NUM_THREADS": "1"})
            target = 1.2 if len(F) < 5000 else 2.0
            print(f"  stylize3d subdivide {label:9s} ({len(V)} V / {len(F)} F -> {16 * len(F)} F):"
                  f" neural {t_n[0]:5.2f} s / {t_n[1]:5.2f} s (target <= {target} s), Loop "
                  f"{t_l[0]:5.2f} s / {t_l[1]:5.2f} s, ratio {t_n[0] / t_l[0]:4.2f} / "
                  f"{t_n[1] / t_l[1]:4.2f}; neural on one thread {t_1[0]:5.2f} s / "
                  f"{t_1[1]:5.2f} s, ratio {t_1[0] / t_l[0]:4.2f}", flush=True)
        print(f"  ({_load()})")
        import torch

        torch.set_num_threads(1)
        from algorithms.subdivision.inference import load_network, neural_subdivide_np
        from algorithms.subdivision.model import load_weights, neural_subdivide_torch

        net = load_network(None)
        tnet = load_weights(None)[0]
        print(f"in this process, median of {repeat}: NumPy inference vs the PyTorch path "
              f"(1 torch thread, Numba kernels as configured), shipped weights, 2 levels")
        for label, p, V, F in meshes:
            a = neural_subdivide_np(V, F, 2, net, adapt_scale=False)[0]
            b = neural_subdivide_torch(V, F, 2, tnet)[0]
            diag = float(np.linalg.norm(V.max(0) - V.min(0)))
            t_np = median_seconds(lambda: neural_subdivide_np(V, F, 2, net, adapt_scale=False),
                                  repeat)
            t_pt = median_seconds(lambda: neural_subdivide_torch(V, F, 2, tnet), repeat)
            print(f"  {label:9s} ({len(V)} V): NumPy {t_np * 1e3:7.1f} ms, PyTorch "
                  f"{t_pt * 1e3:7.1f} ms, ratio {t_np / t_pt:4.2f}; max difference "
                  f"{np.abs(a - b).max() / diag:.1e} of the diagonal", flush=True)
    print(f"end: {_load()}")
    return 0


def _shared_meshes() -> list:
    root = Path(__file__).resolve().parents[1]
    paths = sorted(p for p in (root / "tests" / "data").iterdir()
                   if p.suffix in (".obj", ".off", ".ply"))
    return paths + sorted((root / "resources" / "samples").glob("*.obj"))


def _render(path: Path, title: str, meshes: list) -> None:
    import pyvista as pv

    pl = pv.Plotter(off_screen=True, shape=(1, len(meshes)), window_size=(520 * len(meshes), 520))
    for k, (name, V, F) in enumerate(meshes):
        pl.subplot(0, k)
        pl.add_text(f"{title}: {name}", font_size=9)
        faces = np.hstack([np.full((len(F), 1), 3), F]).ravel()
        pl.add_mesh(pv.PolyData(V, faces), color="lightgray", specular=0.3)
        pl.view_isometric()
    pl.link_views()
    pl.screenshot(str(path))
    pl.close()


def roughness(max_levels: int, render: str) -> int:
    """Issue 22: never rougher than Loop, on every shared mesh as it is."""
    from algorithms.mesh import read_mesh
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.inference import load_network, neural_subdivide_np
    from algorithms.subdivision.metrics import (bending_energy, planar_faces,
                                                planar_normal_deviation)

    print(f"start: {_load()}", flush=True)
    net = load_network(None)
    print("planar = RMS degrees off the planar coarse triangles (nan: none); bend = bending "
          "energy; x = ratio to Loop's; neural = the recipe's default (shipped weights)")
    worst = 0.0
    for path in _shared_meshes():
        m = read_mesh(path)
        planar = planar_faces(m.V, m.F)
        for levels in range(1, max_levels + 1):
            if len(m.F) * 4 ** levels > 4_000_000:
                print(f"{path.name:18s} L{levels}: skipped ({len(m.F) * 4 ** levels:,} faces)")
                continue
            t = time.perf_counter()
            VL, FL = subdivide_baseline(m.V, m.F, levels, "loop")
            runs = [("Loop", VL, FL, "")]
            runs.append(("neural",) + tuple(neural_subdivide_np(m.V, m.F, levels, net)))
            if levels == 2:
                for mode in ("scale", "off"):
                    runs.append((f"net {mode}",) + tuple(
                        neural_subdivide_np(m.V, m.F, levels, net, dense=mode)))
            rows = []
            bl = bending_energy(VL, FL)
            for name, V, F, note in runs:
                pd = planar_normal_deviation(m.V, m.F, V, F, levels, planar)
                be = bending_energy(V, F)
                rows.append(f"{name} planar {pd:7.3f} bend {be:9.1f} ({be / bl:5.2f}x)")
                if name == "neural":
                    worst = max(worst, be / bl)
                    used = "Loop (denser than trained)" if "Loop subdivision was used" in note \
                        else ("scaled" if note else "network as is")
            print(f"{path.name:18s} {len(m.V):6d} V L{levels}: neural = {used}; "
                  + " | ".join(rows) + f"  [{time.perf_counter() - t:.1f} s]", flush=True)
            if render and levels == 2:
                Path(render).mkdir(parents=True, exist_ok=True)
                _render(Path(render) / f"{path.stem}.png", path.stem,
                        [(name, V, F) for name, V, F, _ in runs])
    print(f"worst bending ratio neural / Loop (default settings): {worst:.3f}")
    print(f"end: {_load()}")
    return 0


def refine_order_baseline(method: str):
    """Two levels of a library baseline (``loop``, ``butterfly``), its vertices put in our
    refine's order: ``fn(V, F) -> (V2, F2)``."""
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.topology import split_vertex_order

    def run(V, F):
        V1, F1 = subdivide_baseline(V, F, 1, method)
        V2, F2 = subdivide_baseline(V1, F1, 1, method)
        return V2[split_vertex_order(F, len(V), [F1, F2])], F2

    return run


def elephant_level2_distances(ref: Path, fn):
    """The author's validation set (``ref``/cartoon_elephant_10): for each of the ten coarse
    meshes, the level-2 vertex distances of ``fn(V, F) -> (V2, F2)`` (vertices in our refine's
    order) to the ground truth, in units of the diagonal; (n,) arrays, one per mesh."""
    from algorithms.mesh import read_mesh
    from algorithms.subdivision.topology import split_vertex_order

    out = []
    for k in range(1, 11):
        m = read_mesh(ref / "cartoon_elephant_10" / "subd0" / f"{k:03d}.obj")
        g1 = read_mesh(ref / "cartoon_elephant_10" / "subd1" / f"{k:03d}.obj")
        g2 = read_mesh(ref / "cartoon_elephant_10" / "subd2" / f"{k:03d}.obj")
        order = split_vertex_order(m.F, len(m.V), [g1.F, g2.F])
        diag = float(np.linalg.norm(m.V.max(0) - m.V.min(0)))
        V, _ = fn(m.V, m.F)
        if len(V) != len(g2.V):
            raise RuntimeError("level-2 vertex count differs from the ground truth")
        out.append(np.linalg.norm(V - g2.V[order], axis=1) / diag)
    return out


def validation_set(weights: list) -> int:
    """Level-2 vertex errors on the author's validation set (cartoon_elephant_10)."""
    from algorithms.subdivision.inference import load_network, neural_subdivide_np

    ref = Path(__file__).resolve().parents[2] / "shared" / "reference" / "neural_subdivision"
    if not (ref / "cartoon_elephant_10").is_dir():
        print(f"the validation set is not here ({ref}); nothing to do")
        return 0
    print(f"start: {_load()}", flush=True)
    methods = {}
    for w in weights:
        path = {"author": ref / "author_network" / "netparams.dat", "shipped": None}.get(w, w)
        net = load_network(path)
        methods[w] = (lambda V, F, net=net: neural_subdivide_np(V, F, 2, net,
                                                                 dense="scale")[:2])
    methods["Loop"] = refine_order_baseline("loop")
    methods["butterfly"] = refine_order_baseline("butterfly")
    errs = {name: [(float(np.sqrt((d ** 2).mean())), float(d.max()))
                   for d in elephant_level2_distances(ref, fn)]
            for name, fn in methods.items()}
    print("level-2 vertex error against the ground truth, in units of the diagonal "
          "(mean over the 10 meshes of the RMS, and of the max; range of the RMS)")
    for name, e in errs.items():
        r = np.array(e)
        print(f"  {str(name)[-28:]:28s} RMS {r[:, 0].mean():.2e} ({r[:, 0].min():.2e}-"
              f"{r[:, 0].max():.2e})  max {r[:, 1].mean():.2e}")
    print(f"end: {_load()}")
    return 0


def full(shape, args) -> int:
    """The whole default training (DataParams(), TrainParams()) on one shape, measured."""
    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.model import save_weights
    from algorithms.subdivision.train import Trainer, TrainParams, training_data

    print(f"--full: default training on {args.mesh} [{_load()}]", flush=True)
    tp = TrainParams() if args.patience is None else TrainParams(patience=args.patience)
    with tempfile.TemporaryDirectory() as tmp:
        cache = args.cache_dir or tmp
        t0 = time.perf_counter()
        # the product's data: the user's coarse meshes and the pretzel's to choose the epoch
        samples, validation = training_data([(shape.V, shape.F)], DataParams(), tp, workers=2,
                                            cache_dir=cache)
        t_data = time.perf_counter() - t0
    n_all = len(samples) + len(validation or [])
    print(f"  data: {n_all} coarse meshes ({len(validation or [])} to choose the epoch) in "
          f"{t_data:.0f} s ({t_data / n_all:.2f} s each, 2 workers) [{_load()}]", flush=True)
    t1 = time.perf_counter()
    tr = Trainer(samples, tp, validation_samples=validation)
    t_prep = time.perf_counter() - t1
    gen = tr.steps()
    try:
        for step in gen:
            if step.iteration % 10 == 0 or step.iteration == 1:
                print(f"  {step.message} ({step.metrics['seconds']:.1f} s) [{_load()}]",
                      flush=True)
    except KeyboardInterrupt:  # Ctrl-C: report (and save) what was trained so far
        gen.close()
        print("  interrupted: the best weights so far are kept", flush=True)
    t_train = time.perf_counter() - t1
    hs = tr.history
    tot = {k: sum(x[k] for x in hs) for k in ("seconds_forward", "seconds_backward",
                                               "seconds_validation", "seconds_other")}
    print(f"  training: {len(hs)} epochs (stopped early: {tr.stopped_early}), best validation "
          f"loss {tr.best_loss:.4g} at epoch {tr.best_epoch}; {t_train:.0f} s = preparation "
          f"{t_prep:.0f} s + forward {tot['seconds_forward']:.0f} s + backward/Adam "
          f"{tot['seconds_backward']:.0f} s + validation {tot['seconds_validation']:.0f} s + "
          f"other {tot['seconds_other']:.0f} s; median {statistics.median(tr.seconds_per_epoch):.1f}"
          f" s per epoch")
    print(f"  whole default training: {(t_data + t_train) / 60:.1f} min (data "
          f"{t_data / 60:.1f} + training {t_train / 60:.1f}) [{_load()}]", flush=True)
    if args.save:
        save_weights(args.save, tr.net, {"trained_on": args.mesh, "coarse_meshes": len(samples),
                                         "epochs_run": len(hs), "best_epoch": tr.best_epoch,
                                         "best_validation_loss": float(tr.best_loss)})
        print(f"  wrote {args.save}")
    return 0


def learn_loop(n: int, epochs: int) -> int:
    from algorithms.mesh import read_mesh
    from algorithms.subdivision.data import DataParams, _loop_targets, generate_dataset
    from algorithms.subdivision.metrics import coarsen_to_vertices
    from algorithms.subdivision.model import neural_subdivide
    from algorithms.subdivision.train import Trainer, TrainParams

    bob = read_mesh(mesh_path("bob.obj"))
    t0 = time.perf_counter()
    samples = generate_dataset([(bob.V, bob.F)], DataParams(coarse_meshes=n, targets="loop"),
                               workers=2)
    t1 = time.perf_counter()
    tr = Trainer(samples, TrainParams(epochs=epochs))
    for step in tr.steps():
        if step.iteration % 10 == 0:
            print(f"  {step.message}", flush=True)
    t2 = time.perf_counter()
    print(f"learning Loop: trained on bob ({len(bob.V)} vertices), {n} coarse meshes with Loop "
          f"targets, {epochs} epochs (data {t1 - t0:.0f} s, training {t2 - t1:.0f} s); best "
          f"validation loss {tr.best_loss:.3g} at epoch {tr.best_epoch}")
    for name in ("spot_lowres.obj", "armadillo.obj", "fertility.off"):
        m = read_mesh(mesh_path(name))
        Vc, Fc = coarsen_to_vertices(m.V, m.F, 300)
        Vn, _ = neural_subdivide(Vc, Fc, 2, tr.net)
        VL = _loop_targets(Vc, Fc, 2)[2]
        diag = np.linalg.norm(Vc.max(0) - Vc.min(0))
        d = np.linalg.norm(Vn - VL, axis=1) / diag * 100
        print(f"  unseen {name:18s} {len(Vc)} vertices -> {len(VL)}: mean {d.mean():.3f} %, "
              f"max {d.max():.3f} % of the bbox diagonal (thesis: mean 0.3 %)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
