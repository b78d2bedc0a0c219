"""Cubic stylization: iterations per second, local/global split, and libigl's ARAP as the peer.

For each mesh (default: armadillo.obj, 14.6k vertices / 29k faces):
  precompute    CubicStylizer construction (normalization, normals, areas, K, factorizations)
  run           a whole cubic_stylization run with the thesis defaults (lambda 0.2, stop at
                relative move 3e-3): iterations, seconds, iterations per second
  split         the same run re-timed step by step: local = covariances + per-vertex ADMM,
                global = right-hand side + prefactored solve (plus the mean ADMM inner iterations)
  peer          libigl's ARAP (spokes and rims) on the same mesh: igl.arap_precomputation, then
                igl.arap_solve with max_iter = N, timed per iteration (libigl has no cubic
                stylization; its ARAP iteration is the same local-global loop without the L1 term
                and with single-precision rotation fitting)
Ratio = our seconds per iteration / libigl's seconds per ARAP iteration (> 1: ours slower).

Usage: .venv/bin/python benchmarks/cubic.py [--lam 0.2] [--repeat 3] [mesh names...]
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

from _timing import median_seconds  # noqa: E402

import igl  # noqa: E402
from algorithms.deform.cubic import (  # noqa: E402
    AdmmState,
    CubicParams,
    CubicStylizer,
    admm_local_step,
)
from algorithms.deform.arap import relative_displacement  # noqa: E402
from algorithms.mesh import read_mesh  # noqa: E402

SHARED = ROOT.parent / "shared" / "meshes"
DEFAULT = ["armadillo.obj"]


def split_run(st: CubicStylizer, params: CubicParams, iterations: int) -> dict[str, float]:
    """Re-run the stylizer's loop with timers around the local and the global step."""
    system, known, Vn = st.system, st.known, st.V_normalized
    prox = st.style_prox(params)
    lam_a = params.lam * st.areas
    state = AdmmState.initial(st.n, params.rho0)
    U = Vn.copy()
    U[system.constrained] = known[system.constrained]
    t_local = t_global = 0.0
    inner = []
    for _ in range(iterations):
        t0 = time.perf_counter()
        S = system.covariances(U)
        R, iters = admm_local_step(S, st.normals, lam_a, prox, state, params)
        t1 = time.perf_counter()
        Un = system.solve(system.rhs(R), known)
        t2 = time.perf_counter()
        t_local += t1 - t0
        t_global += t2 - t1
        inner.append(iters[iters > 0].mean())
        relative_displacement(Un, U, Vn)
        U = Un
    return {"local": t_local, "global": t_global, "inner_first": float(inner[0]),
            "inner_rest": float(np.mean(inner[1:])) if len(inner) > 1 else float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--lam", type=float, default=0.2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--peer-iterations", type=int, default=20)
    args = ap.parse_args()
    params = CubicParams(lam=args.lam)
    for name in args.meshes:
        path = SHARED / name
        if not path.exists():
            print(f"{name}: not in {SHARED}, skipped")
            continue
        m = read_mesh(path)
        V, F = m.V, m.F
        print(f"== {name}: {len(V)} vertices, {len(F)} faces, lambda {params.lam}")

        t_pre = median_seconds(lambda: CubicStylizer(V, F), args.repeat)
        st = CubicStylizer(V, F)
        t0 = time.perf_counter()
        steps = list(st.steps(params))
        t_run = time.perf_counter() - t0
        n_it = len(steps)
        print(f"precompute           {t_pre:8.3f} s   (backend {st.system.backend})")
        print(f"run                  {t_run:8.3f} s   {n_it} iterations, "
              f"{n_it / t_run:6.2f} it/s, {1e3 * t_run / n_it:7.2f} ms/it")

        sp_ = split_run(st, params, n_it)
        tot = sp_["local"] + sp_["global"]
        print(f"split (re-run)       local {sp_['local']:7.3f} s ({100 * sp_['local'] / tot:4.1f}%)"
              f"   global {sp_['global']:7.3f} s ({100 * sp_['global'] / tot:4.1f}%)")
        print(f"ADMM inner its/vertex first iteration {sp_['inner_first']:.2f}, "
              f"later mean {sp_['inner_rest']:.2f}")

        # peer: libigl ARAP (spokes and rims), one pinned vertex, started from our result
        b = np.array([0], dtype=np.int32)
        U0 = np.ascontiguousarray(steps[-1].V)
        bc = U0[b.astype(np.int64)]

        def peer_pre():
            d = igl.ARAPData()
            d.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
            d.max_iter = args.peer_iterations
            igl.arap_precomputation(V, F, 3, b, d)
            return d

        t_peer_pre = median_seconds(peer_pre, args.repeat)
        data = peer_pre()
        t_peer = median_seconds(lambda: igl.arap_solve(bc, data, U0), args.repeat)
        per_peer = t_peer / args.peer_iterations
        per_ours = t_run / n_it
        print(f"peer libigl ARAP     precompute {t_peer_pre:7.3f} s   "
              f"{1e3 * per_peer:7.2f} ms/it ({args.peer_iterations} its, median of "
              f"{args.repeat})")
        print(f"ratio ours/peer      per iteration {per_ours / per_peer:6.2f}   "
              f"precompute {t_pre / t_peer_pre:6.2f}")


if __name__ == "__main__":
    main()
