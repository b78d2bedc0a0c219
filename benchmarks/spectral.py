"""Benchmark: spectral coarsening of armadillo (n ~ 30k) to m = 500 with k = 100 eigenvectors,
against QSlim and AMG. Prints timings (eigendecomposition, clustering, optimization, baselines)
and the metrics. Target: <= 60 s total on 2 cores.

    .venv/bin/python benchmarks/spectral.py [mesh] [m] [k] [max_iterations]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from algorithms.mesh.io import read_mesh  # noqa: E402
from algorithms.spectral import CoarsenParams  # noqa: E402
from algorithms.spectral.compare import compare_coarsenings  # noqa: E402


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    mesh = argv[0] if argv else str(ROOT.parent / "shared" / "meshes" / "armadillo.obj")
    m = int(argv[1]) if len(argv) > 1 else 500
    k = int(argv[2]) if len(argv) > 2 else 100
    iters = int(argv[3]) if len(argv) > 3 else 1000
    md = read_mesh(mesh)
    t = time.perf_counter()
    res = compare_coarsenings(md.V, md.F, "cotangent", m, k, CoarsenParams(max_iterations=iters))
    total = time.perf_counter() - t
    print(f"{Path(mesh).name}: n={res.n} m={m} k={k}")
    print(res.table())
    for key, val in res.timings.items():
        print(f"  {key:28s} {val:8.2f}")
    print(f"  {'total':28s} {total:8.2f}  (target <= 60 s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
