"""Surface multigrid vs direct (CHOLMOD) and algebraic multigrid (PyAMG), same run (thesis §8.6).

For a Loop-upsampled mesh at each size (the base mesh from tests/data or $STYLIZE3D_MESHES, subdivided 1, 2, 3
times: armadillo gives ~58k, 233k, 933k vertices), normalized to a unit bounding box:

  hierarchy     surface_multigrid(V, F) build time (geometry only, done once per mesh)
  smoothing     data smoothing (alpha Q + (1-alpha) M) u = (1-alpha) M f (Eq. 8.16) for a NEW alpha
                each solve, Q = Dirichlet (-L) and bilaplacian (L M^-1 L). Peers, once per alpha:
                  chol    CHOLMOD factor + solve (algorithms.linalg.SPDSolver backend="cholmod")
                  sa, rs  PyAMG smoothed aggregation / Ruge-Stuben setup + solve to the same rtol
                          (defaults, accel=None, maxiter 100; x0 = 0 like ours)
                then one line per multigrid variant (DataSmoother.smooth: Galerkin sums +
                smoother + coarse factor + iterations to rtol, all included):
                  dirichlet    plain V-cycles (thesis) / V-cycle-preconditioned CG
                  bilaplacian  factored PCG (two second-order V-cycles per step, the default) /
                               CG preconditioned by V-cycles on the Galerkin bilaplacian
                peer/mg = peer seconds / multigrid seconds (> 1: multigrid faster); err = relative
                difference to the CHOLMOD solution; "to err 1e-5": the same run stopped at the
                first iteration whose relative error to CHOLMOD is <= 1e-5 (the thesis's accuracy
                criterion, Fig. 8.21) and timed again alone.
  convergence   Poisson (-L + 1e-3 M) x = M r, residual reduction per V-cycle over 10 cycles,
                ours vs PyAMG RS and SA with their defaults (thesis Fig. 8.3).

Threads (issue 25): the last section times, on the base mesh after one Loop subdivision, in
child processes with NUMBA_NUM_THREADS=1 and =2 (alternating rounds, benchmarks/_threads.py):
2 + 2 multi-colour Gauss-Seidel sweeps (one and three right-hand sides; a colour's rows on the
threads), the same with the default block Gauss-Seidel (sequential: one thread whatever the
setting, for reference) and a Poisson solve to rtol 1e-8 with the multi-colour smoother;
ratio = 2 threads / 1 thread. ``--no-threads`` skips it, ``--rounds`` sets the rounds.

Usage: .venv/bin/python benchmarks/multigrid.py [--sizes 1,2,3] [--mesh armadillo.obj]
       [--prolongation intrinsic|closest_point] [--alphas 2] [--rtol 1e-5] [--no-amg]
       [--no-threads] [--rounds 3]
BLAS threads are set to 1 before NumPy loads (override with OMP_NUM_THREADS): on this shared
2-core machine a threaded BLAS dot product of 58k numbers took ~8 ms instead of ~0.01 ms, which
slowed every iterative solver (PyAMG's norms included). The multigrid itself is single-threaded.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _threads import child_report, threads_section  # noqa: E402
from _timing import median_seconds, mesh_path  # noqa: E402

from algorithms.linalg import SPDSolver, cholmod_available  # noqa: E402
from algorithms.mesh import read_mesh  # noqa: E402
from algorithms.mesh.operators import (cotangent_laplacian_psd, mass_matrix,  # noqa: E402
                                       normalize_unit_box)
from algorithms.mesh.subdivision import loop_subdivide  # noqa: E402
from algorithms.multigrid import surface_multigrid  # noqa: E402
from algorithms.multigrid.applications import DataSmoother  # noqa: E402

ERR = 1e-5  # relative error to the direct solution for the "mg@err" columns
VARIANTS = {
    "dirichlet": [("V-cycles (thesis)", dict(accel=None)),
                  ("V-cycle-PCG", dict(accel="cg"))],
    "bilaplacian": [("factored PCG (default)", dict(preconditioner="factored")),
                    ("Galerkin V-cycle-PCG", dict(preconditioner="galerkin", accel="cg"))],
}
ALPHAS = {"dirichlet": [1e-3, 1e-4, 1e-2], "bilaplacian": [1e-6, 1e-7, 1e-5]}


REPEAT = [1]  # median over this many runs (3 below 300k vertices: timings on shared cores are noisy)


def timed(fn):
    """(result of the last call, median wall time over REPEAT[0] calls)."""
    ts = []
    out = None
    for _ in range(REPEAT[0]):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return out, float(np.median(ts))


def rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def amg_solve(kind, A, b, rtol, accel, x0):
    import pyamg

    fn = pyamg.smoothed_aggregation_solver if kind == "sa" else pyamg.ruge_stuben_solver
    res = []

    def run():
        ml = fn(A.tocsr())
        return ml.solve(b, x0=x0, tol=rtol, maxiter=100, accel=accel, residuals=res)

    x, t = timed(run)
    return x, t, len(res) - 1, res[-1] / res[0] if res and res[0] > 0 else 0.0


def _maxrss_gb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def factor_per_cycle(res):
    return (res[-1] / res[0]) ** (1.0 / (len(res) - 1))


def threads_child(mesh: str, prolongation: str) -> None:
    """Child of the threads section: the smoothers and a V-cycle solve with this process's
    Numba threads."""
    from algorithms.multigrid.relaxation import BlockGaussSeidel, MultiColorGaussSeidel

    base = read_mesh(mesh_path(mesh))
    V, F = loop_subdivide(base.V, base.F, 1)
    V = normalize_unit_box(V)[0]
    n = len(V)
    A = (cotangent_laplacian_psd(V, F) + 1e-3 * mass_matrix(V, F)).tocsr()
    rng = np.random.default_rng(0)
    times = {}
    mc = MultiColorGaussSeidel(A)
    bgs = BlockGaussSeidel(A)
    for d in (1, 3):
        b = rng.standard_normal((n, d))
        x0 = rng.standard_normal((n, d))
        for name, sm in ((f"multicolor 2+2 sweeps, d={d}", mc),
                         (f"block GS 2+2 sweeps, d={d} (serial)", bgs)):
            def run(sm=sm, b=b, x0=x0):
                x = x0.copy()
                sm.relax(x, b, 2)
                sm.relax(x, b, 2, backward=True)
            run()
            times[name] = 1e3 * median_seconds(run, 15)
    mg = surface_multigrid(V, F, prolongation=prolongation)
    solver = mg.solver(A, smoother="multicolor")
    rhs = mass_matrix(V, F) @ rng.standard_normal(n)
    solver.solve(rhs, rtol=1e-8, maxiter=100)
    times[f"V-cycle solve rtol 1e-8, multicolor ({n} V)"] = 1e3 * median_seconds(
        lambda: solver.solve(rhs, rtol=1e-8, maxiter=100), 5)
    child_report(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="1,2,3",
                    help="Loop subdivision levels of the base mesh, comma separated (0 = as is)")
    ap.add_argument("--mesh", default="armadillo.obj")
    ap.add_argument("--prolongation", default="intrinsic", choices=["intrinsic", "closest_point"])
    ap.add_argument("--alphas", type=int, default=2, help="alphas per energy (1-3)")
    ap.add_argument("--rtol", type=float, default=1e-5)
    ap.add_argument("--no-amg", action="store_true", help="skip the PyAMG peers")
    ap.add_argument("--no-direct-above", type=int, default=10**9,
                    help="skip CHOLMOD on meshes with more vertices than this")
    ap.add_argument("--no-threads", action="store_true", help="skip the threads section")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the threads section")
    ap.add_argument("--threads-child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads_child:
        threads_child(args.mesh, args.prolongation)
        return
    sys.stdout.reconfigure(line_buffering=True)
    path = mesh_path(args.mesh)
    if not path.exists():
        print(f"{args.mesh}: not found (tests/data or $STYLIZE3D_MESHES)")
        return
    base = read_mesh(path)
    backend = "cholmod" if cholmod_available() else "superlu"
    print(f"base mesh {args.mesh}: {len(base.V):,} vertices; prolongation {args.prolongation}; "
          f"direct peer {backend}; rtol {args.rtol:g}")
    for lev in [int(s) for s in args.sizes.split(",") if s.strip()]:
        V, F = (base.V, base.F) if lev == 0 else loop_subdivide(base.V, base.F, lev)
        V = normalize_unit_box(V)[0]
        n = len(V)
        REPEAT[0] = 3 if n < 300_000 else 1
        print(f"\n=== Loop x{lev}: {n:,} vertices, {len(F):,} faces ===")
        REPEAT[0], rep = 1, REPEAT[0]
        mg, t_build = timed(lambda: surface_multigrid(V, F, prolongation=args.prolongation))
        REPEAT[0] = rep
        sizes = " -> ".join(f"{len(L[0]):,}" for L in mg.levels)
        print(f"hierarchy: {t_build:.1f} s ({sizes})")
        for e in mg.report["levels"][1:]:
            print(f"  level {e['level']}: {e['vertices']:,} V, {e['seconds']:.1f} s")
        rng = np.random.default_rng(0)
        f = V[:, 1] + 0.05 * rng.standard_normal(n)

        # ---- Poisson convergence factor
        L = cotangent_laplacian_psd(V, F)
        M = mass_matrix(V, F)
        A = (L + 1e-3 * M).tocsr()
        b = M @ rng.standard_normal(n)
        s = mg.solver(A)
        res = []
        _, t_mg = timed(lambda: s.solve(b, rtol=1e-30, maxiter=10, residuals=res))
        line = f"Poisson factor/cycle: ours {factor_per_cycle(res):.3f} ({t_mg / 10:.3f} s/cycle)"
        if not args.no_amg:
            import pyamg

            for name, fn in [("RS", pyamg.ruge_stuben_solver),
                             ("SA", pyamg.smoothed_aggregation_solver)]:
                r = []
                ml = fn(A)
                ml.solve(b, tol=1e-30, maxiter=10, residuals=r)
                line += f", {name} {factor_per_cycle(r):.3f}"
        print(line)

        # ---- data smoothing with changing alpha
        for energy in ("dirichlet", "bilaplacian"):
            t = time.perf_counter()
            ds = DataSmoother(V, F, energy=energy, mg=mg)
            t_pre = time.perf_counter() - t
            print(f"\n{energy}: Q, P^T Q P, P^T M P (and P^T L P) precomputed in {t_pre:.2f} s")
            for alpha in ALPHAS[energy][:max(1, min(3, args.alphas))]:
                Aa = ds.system(alpha)
                rhs = (1 - alpha) * (ds.M @ f)
                peers = {}
                line = f"  alpha {alpha:.0e}: peers (factor/setup + solve):"
                if n <= args.no_direct_above:
                    try:
                        ud, t = timed(lambda: SPDSolver(Aa, backend=backend).solve(rhs))
                        peers["chol"] = t
                        line += f" {backend} {t:.2f} s"
                    except MemoryError:
                        ud = None
                        line += f" {backend} out of memory"
                else:
                    ud = None
                if not args.no_amg:
                    for kind in ("sa", "rs"):
                        _, t, it, r = amg_solve(kind, Aa, rhs, args.rtol, None, None)
                        peers[kind] = t
                        line += (f", PyAMG {kind.upper()} {t:.2f} s ({it} cycles"
                                 f"{'' if r <= args.rtol else ', rtol NOT reached'})")
                print(line + f"  [max RSS {_maxrss_gb():.1f} GB]")
                for label, kw in VARIANTS[energy]:
                    (u, info), t_ours = timed(lambda: ds.smooth(f, alpha, rtol=args.rtol,
                                                                maxiter=300, **kw))
                    row = (f"    {label:24s} {t_ours:7.3f} s {info['cycles']:4d} it"
                           f"{'' if info['converged'] else ' (NOT converged)'}")
                    for k in ("chol", "sa", "rs"):
                        if k in peers:
                            row += f"  {k}/mg {peers[k] / t_ours:5.1f}"
                    if ud is not None:
                        row += f"  err {rel(u, ud):.1e}"
                        # iterations needed for a relative error <= ERR to the direct solution
                        # (the thesis's accuracy criterion), then timed alone
                        errs = []
                        ds.smooth(f, alpha, rtol=1e-30, maxiter=300, **kw,
                                  callback=lambda x: errs.append(rel(x, ud)))
                        k = next((i + 1 for i, e in enumerate(errs) if e <= ERR), None)
                        if k is not None:
                            _, t_k = timed(lambda: ds.smooth(f, alpha, rtol=1e-30, maxiter=k,
                                                             **kw))
                            row += (f"  | to err {ERR:.0e}: {t_k:.3f} s {k} it, "
                                    f"chol/mg {peers['chol'] / t_k:.1f}")
                    print(row)
    if not args.no_threads:
        print()
        threads_section(__file__, "multigrid", ["--mesh", args.mesh, "--prolongation",
                                                args.prolongation], rounds=args.rounds,
                        title=f"{args.mesh} after one Loop subdivision")


if __name__ == "__main__":
    main()
