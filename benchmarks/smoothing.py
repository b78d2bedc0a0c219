"""Implicit smoothing: our prefactored direct solver vs SciPy's one-shot spsolve, same run.

For each mesh: one backward-Euler system (M - hL) X = M V (3 right-hand sides) is
  ours-factor   SPDSolver(A) construction (ordering + factorization, once per run of the
                "laplacian" flow)
  ours-solve    SPDSolver.solve (every later step of that flow)
  peer          scipy.sparse.linalg.spsolve(A, B) (what a naive loop would pay every step)
and a whole 10-step "laplacian" run. Ratios are ours / peer (< 1: ours faster).

Usage: .venv/bin/python benchmarks/smoothing.py [--repeat 3] [mesh names...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _timing import median_seconds, mesh_path  # noqa: E402

from algorithms.linalg import SPDSolver  # noqa: E402
from algorithms.mesh import read_mesh  # noqa: E402
from algorithms.mesh.operators import cotangent_laplacian, face_areas, mass_matrix  # noqa: E402
from algorithms.smoothing import SmoothParams, smooth  # noqa: E402

DEFAULT = ["spot_lowres.obj", "armadillo.obj", "koala.obj", "igea.ply"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"{'mesh':18s} {'V':>7s} {'factor s':>9s} {'solve s':>8s} {'spsolve s':>9s} "
          f"{'solve/peer':>10s} {'10 steps s':>10s} {'10 steps/10 peer':>16s}")
    for name in args.meshes:
        path = mesh_path(name)
        if not path.exists():
            print(f"{name}: not found (tests/data or $STYLIZE3D_MESHES), skipped")
            continue
        m = read_mesh(path)
        V, F = m.V, m.F
        h = 1e-4 * face_areas(V, F).sum()
        A = (mass_matrix(V, F) - h * cotangent_laplacian(V, F)).tocsc()
        B = mass_matrix(V, F) @ V
        solver = SPDSolver(A)
        t_factor = median_seconds(lambda: SPDSolver(A), args.repeat)
        t_solve = median_seconds(lambda: solver.solve(B), args.repeat)
        t_peer = median_seconds(lambda: spla.spsolve(A, B), args.repeat)
        x = solver.solve(B)
        assert np.allclose(x, spla.spsolve(A, B), atol=1e-9)
        t_run = median_seconds(lambda: smooth(V, F, SmoothParams(iterations=10)), 1)
        print(f"{name:18s} {len(V):7d} {t_factor:9.3f} {t_solve:8.3f} {t_peer:9.3f} "
              f"{t_solve / t_peer:10.3f} {t_run:10.3f} {t_run / (10 * t_peer):16.3f}")
    print(f"backend: {solver.backend}")


if __name__ == "__main__":
    main()
