"""Affine progressive meshes (thesis Alg. 4): pre-processing vs online time at ~1M triangles.

Default mesh: igea.ply (269k triangles) Loop-subdivided once -> 1.07M triangles (537k vertices).
For each coarse size m (default 2,000 and 20,000 triangles):
  pre       ProgressiveCubic construction: QSlim decimation with recorded collapses, affine-split
            weights and wave schedule, the coarse CubicStylizer (normalization, factorizations)
  online    ProgressiveCubic.stylize(lambda): cubic stylization of the coarse mesh to convergence
            (thesis defaults: stop at relative move 3e-3) + replay of every vertex split
  replay    the replay alone (median of --repeat runs), and its number of waves
  ratio     online / pre
  checks    lossless replay of the rest pose (max error / bbox diagonal); mean L1 norm of the
            unit vertex normals (area-weighted) of the input and of the result
Peer (same run): direct CubicStylizer on the full mesh: construction time, then the first
--peer-iterations iterations timed; "direct (extrapolated)" = construction + first iteration +
(N - 1) x the mean of the later ones, N = the coarse run's iteration count -- an EXTRAPOLATION
(the full-resolution run was not run to convergence; it usually needs a different number of
iterations; the first iteration is dearer: ADMM starts cold).
Target (issue): online <= 2 s after pre-processing at 1M triangles.

Usage: .venv/bin/python benchmarks/progressive.py [--mesh igea.ply] [--upsample 1]
       [--coarse 2000,20000] [--lam 0.2] [--peer-iterations 4] [--no-peer] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _timing import median_seconds, mesh_path  # noqa: E402

from algorithms.deform.cubic import CubicParams, CubicStylizer  # noqa: E402
from algorithms.deform.progressive import ProgressiveCubic  # noqa: E402
from algorithms.mesh import loop_subdivide, read_mesh  # noqa: E402
from algorithms.mesh.operators import (  # noqa: E402
    barycentric_vertex_areas,
    bounding_box_diagonal,
    vertex_normals,
)



def mean_l1(V, F) -> float:
    N = vertex_normals(V, F)
    a = barycentric_vertex_areas(V, F)
    return float((a * np.abs(N).sum(axis=1)).sum() / a.sum())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", default="igea.ply")
    ap.add_argument("--upsample", type=int, default=1, help="Loop subdivision levels")
    ap.add_argument("--coarse", default="2000,20000", help="coarse triangle counts m")
    ap.add_argument("--lam", type=float, default=0.2)
    ap.add_argument("--peer-iterations", type=int, default=4)
    ap.add_argument("--no-peer", action="store_true")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    params = CubicParams(lam=args.lam)

    t = time.perf_counter()
    md = read_mesh(mesh_path(args.mesh))
    V, F = md.V, md.F
    if args.upsample:
        V, F = loop_subdivide(V, F, args.upsample)
    print(f"mesh {args.mesh}, Loop x{args.upsample}: {len(V):,} vertices, {len(F):,} triangles "
          f"(load + subdivide {time.perf_counter() - t:.1f} s); lambda {args.lam}")
    diag = bounding_box_diagonal(V)
    l1_in = mean_l1(V, F)

    rows = []
    for m in [int(x) for x in args.coarse.split(",")]:
        pc = ProgressiveCubic(V, F, target_faces=m)
        tm = pc.timings
        iters = []
        t = time.perf_counter()
        out = pc.stylize(params, callback=lambda s: iters.append(s.iteration))
        online = time.perf_counter() - t
        replay = median_seconds(lambda: pc.prolong(pc.decimation.V), args.repeat)
        lossless = float(np.abs(pc.prolong(pc.decimation.V) - V).max() / diag)
        n_it = iters[-1]
        rows.append(dict(m=pc.n_coarse_faces, pre=tm["total"], dec=tm["decimate"],
                         spl=tm["splits"], sty=tm["stylizer"], online=online, iters=n_it,
                         replay=replay, waves=pc.splits.n_waves, lossless=lossless,
                         l1=mean_l1(out, F), notes=pc.notes))
        r = rows[-1]
        print(f"  m={r['m']:>6,}: pre {r['pre']:6.1f} s (decimate {r['dec']:.1f}, splits "
              f"{r['spl']:.1f}, coarse stylizer {r['sty']:.2f}); online {r['online']:.2f} s "
              f"({r['iters']} coarse iterations, replay {r['replay']:.3f} s in {r['waves']} "
              f"waves); online/pre {r['online'] / r['pre']:.3f}; rest-pose replay error "
              f"{r['lossless']:.1e} diag; L1 {l1_in:.4f} -> {r['l1']:.4f}"
              + (f"; {' '.join(r['notes'])}" if r["notes"] else ""), flush=True)
        del pc

    peer = None
    if not args.no_peer:
        t = time.perf_counter()
        st = CubicStylizer(V, F)
        peer_pre = time.perf_counter() - t
        g = st.steps(params)
        ts = []
        for _ in range(args.peer_iterations):
            t = time.perf_counter()
            next(g)
            ts.append(time.perf_counter() - t)
        per_it = float(np.mean(ts[1:])) if len(ts) > 1 else ts[0]
        peer = dict(pre=peer_pre, per_it=per_it, first=ts[0])
        print(f"  peer: direct CubicStylizer on {len(F):,} triangles: construction "
              f"{peer_pre:.1f} s, "
              f"{args.peer_iterations} iterations {', '.join(f'{x:.2f}' for x in ts)} s "
              f"(later ones: mean {per_it:.2f} s/iteration)", flush=True)

    print()
    print(f"{'m':>8} {'pre s':>8} {'online s':>9} {'iters':>6} {'replay s':>9} {'online/pre':>10}"
          + ("" if peer is None else f" {'direct s (extrap.)':>19} {'direct/online':>13}"))
    for r in rows:
        line = (f"{r['m']:>8,} {r['pre']:>8.1f} {r['online']:>9.2f} {r['iters']:>6} "
                f"{r['replay']:>9.3f} {r['online'] / r['pre']:>10.3f}")
        if peer is not None:
            direct = peer["pre"] + peer["first"] + peer["per_it"] * (r["iters"] - 1)
            line += f" {direct:>19.1f} {direct / r['online']:>13.1f}"
        print(line)
    if peer is not None:
        print("direct s (extrap.) = direct construction + its first iteration + (N - 1) x the "
              f"mean of its iterations 2..{args.peer_iterations}, N = the coarse run's iteration "
              "count (an extrapolation, not a converged full-resolution run).")
    print("target: online <= 2 s after pre-processing at 1M triangles")


if __name__ == "__main__":
    main()
