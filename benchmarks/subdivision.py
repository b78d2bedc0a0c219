"""Neural subdivision benchmark (issue 14): sizes, medians and ratios against peers in one run.

* inference: a ~1k-face mesh (spot, QSlim-decimated) -> 2 levels, neural vs Loop (libigl) vs
  modified butterfly (ours);
* data generation: seconds per coarse mesh at the default sizes (150-300 vertices, 100 random
  edges per collapse) on armadillo (14.5k vertices), 1 local worker vs 2 (speed-up);
* training: seconds per coarse mesh and per epoch at the default sizes (an epoch = 180 training
  meshes of the default 200, 20 held out).

Usage: ``python benchmarks/subdivision.py [--quick]`` (``--quick``: fewer repeats and meshes).

``--learn-loop N EPOCHS`` instead runs App. 4.8.7 (learning Loop): trains on N coarse meshes of
bob whose targets are their own Loop subdivision, for EPOCHS epochs, then subdivides unseen
coarse meshes (spot, armadillo, fertility; QSlim to ~300 vertices) and prints the mean and max
per-vertex distance to libigl's Loop, in % of the bounding-box diagonal (thesis: 0.3 % mean).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_seconds, mesh_path  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--learn-loop", nargs=2, type=int, metavar=("N", "EPOCHS"))
    ap.add_argument("--coarse", type=int, default=0,
                    help="coarse meshes for the data-generation timing (default 2 quick, 8)")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    if args.learn_loop:
        return learn_loop(*args.learn_loop)
    from algorithms.mesh import read_mesh
    from algorithms.mesh.subdivision import loop_subdivide
    from algorithms.subdivision.baselines import butterfly_subdivide
    from algorithms.subdivision.data import DataParams, generate_dataset
    from algorithms.subdivision.metrics import coarsen_to_vertices
    from algorithms.subdivision.model import SubdivisionNet, load_weights, neural_subdivide
    from algorithms.subdivision.train import Trainer, TrainParams

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
    print(f"  butterfly {t_b * 1e3:8.1f} ms   {t_b / t_l:7.1f}x Loop")

    # ---- data generation
    arm = read_mesh(mesh_path("armadillo.obj"))
    k = args.coarse or (2 if args.quick else 8)
    p = DataParams(coarse_meshes=k, seed=12345)
    res = {}
    for w in (1, 2):
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            generate_dataset([(arm.V, arm.F)], p, workers=w, use_cache=False)
            res[w] = time.perf_counter() - t
            del d
    print(f"data generation: armadillo {len(arm.V)} vertices / {len(arm.F)} faces -> "
          f"{k} coarse meshes of 150-300 vertices, 2 levels")
    print(f"  1 worker  {res[1] / k:7.2f} s per coarse mesh")
    print(f"  2 workers {res[2] / k:7.2f} s per coarse mesh   speed-up {res[1] / res[2]:.2f}x "
          f"(process start-up included)")
    print(f"  default 200 coarse meshes: ~{200 * res[2] / k / 60:.1f} min with 2 workers")

    # ---- training
    samples = generate_dataset([(arm.V, arm.F)], DataParams(coarse_meshes=k, seed=12345),
                               workers=1, use_cache=False)
    tr = Trainer(samples, TrainParams(epochs=2, validation_fraction=0.0))
    ts = []
    for _ in range(2):
        for item in tr.train_set:
            t = time.perf_counter()
            tr.opt.zero_grad()
            tr._loss(item).backward()
            tr.opt.step()
            ts.append(time.perf_counter() - t)
    per_mesh = statistics.median(ts)
    sizes = [len(s.V) for s in samples]
    print(f"training: coarse meshes of {min(sizes)}-{max(sizes)} vertices, 2 levels, "
          f"1 thread")
    print(f"  {per_mesh:7.3f} s per coarse mesh (forward + backward + Adam step)")
    print(f"  {180 * per_mesh:7.1f} s per epoch at the default 200 coarse meshes (180 trained)")
    print(f"  default 700 epochs: ~{700 * 180 * per_mesh / 3600:.1f} h")
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
