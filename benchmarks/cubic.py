"""Cubic stylization: ms per local-global iteration, local/global split, libigl's ARAP as the peer.

Meshes (default): spot_lowres, bob, rocker-arm, armadillo (tests/data) and a procedural
20,000-vertex mesh
("bumpy20k": organic_sample("bumpy") after one Loop subdivision, QSlim-decimated to exactly
20,000 vertices; _timing.bumpy20k). For each mesh, with the thesis defaults (lambda 0.2, stop at relative move 3e-3):

  V, its        vertices, and local-global iterations the stopping rule gives
  run s         a whole run of CubicStylizer.steps (construction excluded; precompute column)
  ms/it         run s / its
  local, global, other
                the same loop re-timed part by part, ms per iteration: local = per-vertex ADMM
                (compiled kernel or NumPy), global = right-hand side + prefactored solve,
                other = the pass after the solve (covariances at the new positions, L1 term,
                move, output) and the energy
  numpy ms/it   the same run with the compiled kernels switched off (the NumPy path; --no-numpy
                skips it)
  igl ms/it     libigl's ARAP (igl.arap_precomputation / igl.arap_solve, SPOKES_AND_RIMS, one
                pinned vertex, max_iter = its, started from our result), per iteration
  ratio         ours / igl per iteration (> 1: ours slower). libigl has no cubic stylization;
                its ARAP iteration is the same local-global loop without the L1 term (no ADMM).

The first line reports the one-off cost of the compiled kernels (Numba import + cache load, or
compilation when the cache is cold).

The last line times per-vertex local frames (``frames=``, §5.4) on bumpy20k: ms per iteration of
a fixed-length run (``--frames-iterations``, no stopping rule, so all runs do the same number of
outer iterations) without frames, with identity frames (the same ADMM work: the frames' own
overhead) and with two regions (frames turned 45 degrees about y where y > median; a different
problem, so a different ADMM iteration count, shown as inner its/vertex), and the ratios to the
run without frames. ``--no-frames`` skips it.

Threads (issue 25): the last section runs bumpy20k in child processes with
NUMBA_NUM_THREADS=1 and =2 (alternating rounds, benchmarks/_threads.py) and prints, per kernel,
the medians and the ratio 2/1: a whole run (ms per iteration, the thesis's stopping rule), the
local step (ADMM, the warm state of the run's 10th iteration), covariances K U, right-hand side
K^T R, the prefactored solve (CHOLMOD through cholespy: one thread whatever NUMBA_NUM_THREADS
says), the energy / L1 / displacement terms one by one (the general energy sum, and the one dot
product the run uses), and the run's fused pass after the solve (covariances, L1, move, output). ``--no-threads`` skips it; ``--rounds`` sets
the rounds.

Usage: .venv/bin/python benchmarks/cubic.py [--lam 0.2] [--repeat 3] [--no-numpy] [--no-frames]
       [--frames-iterations 30] [--no-threads] [--rounds 3] [mesh names...]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _threads import child_report, threads_section  # noqa: E402
from _timing import bumpy20k, median_seconds, mesh_path  # noqa: E402

import igl  # noqa: E402
from algorithms.deform.arap import (  # noqa: E402
    compiled_kernels,
    relative_displacement,
    set_compiled_kernels,
)
from algorithms.deform.cubic import (  # noqa: E402
    AdmmState,
    CubicParams,
    CubicStylizer,
    admm_local_step,
)
from algorithms.mesh import read_mesh  # noqa: E402

DEFAULT = ["spot_lowres.obj", "bob.obj", "rocker-arm.obj", "armadillo.obj", "bumpy20k"]


def load(name: str):
    if name == "bumpy20k":
        return bumpy20k()
    path = mesh_path(name)
    if not path.exists():
        return None
    m = read_mesh(path)
    return m.V, m.F


def split_run(st: CubicStylizer, params: CubicParams, iterations: int) -> dict[str, float]:
    """Re-run CubicStylizer.steps' loop with timers around its parts (seconds in total)."""
    system, known, Vn = st.system, st.known, st.V_normalized
    prox = st.style_prox(params)
    lam_a = params.lam * st.areas
    state = AdmmState.initial(st.n, params.rho0)
    U = Vn.copy()
    U[system.constrained] = known[system.constrained]
    t_local = t_global = t_other = 0.0
    S = system.covariances(U)
    for _ in range(iterations):
        t0 = time.perf_counter()
        R, iters = admm_local_step(S, st.normals, lam_a, prox, state, params)
        t1 = time.perf_counter()
        b = system.rhs(R)
        Un = system.solve(b, known)
        t2 = time.perf_counter()
        kern = compiled_kernels()
        if kern is not None:  # what CubicStylizer.steps does after the solve
            S, V_out, *_ = kern.cube_after_solve(*system._k_blocks(), Un, R, st.normals, None,
                                                 prox.diagonal, lam_a, U, Vn, st.scale,
                                                 st.center)
        else:
            relative_displacement(Un, U, Vn)
            S = system.covariances(Un)
            float((lam_a * prox.norm(np.einsum("kab,kb->ka", R, st.normals))).sum())
            V_out = None
        U = Un
        system.energy_after_solve(U, R, b, rotations=True, covariances=S)
        st._to_output(U, V_out)
        t3 = time.perf_counter()
        t_local += t1 - t0
        t_global += t2 - t1
        t_other += t3 - t2
    return {"local": t_local, "global": t_global, "other": t_other}


def timed_run(st: CubicStylizer, params: CubicParams, repeat: int) -> tuple[int, float, np.ndarray]:
    times, n_it, V = [], 0, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        steps = list(st.steps(params))
        times.append(time.perf_counter() - t0)
        n_it, V = len(steps), steps[-1].V
    return n_it, float(np.median(times)), V


def frames_line(params: CubicParams, iterations: int, repeat: int) -> str:
    """ms/iteration on bumpy20k without frames, with identity frames and with two regions."""
    from algorithms.deform.cubic import rotation_from_degrees

    V, F = load("bumpy20k")
    st = CubicStylizer(V, F)
    p = replace(params, max_iterations=iterations, rel_displacement_tol=0.0)
    n = st.n
    upper = V[:, 1] > np.median(V[:, 1])
    cases = {
        "none": None,
        "identity": np.tile(np.eye(3), (n, 1, 1)),
        "two regions": np.where(upper[:, None, None], rotation_from_degrees(0, 45, 0), np.eye(3)),
    }
    ms, inner = {}, {}
    for name, frames in cases.items():
        steps = list(st.steps(p, frames=frames))
        inner[name] = float(np.mean([s.metrics["admm_iterations"] for s in steps]))
        ms[name] = 1e3 * median_seconds(lambda: list(st.steps(p, frames=frames)),
                                        repeat) / iterations
    base = ms["none"]
    parts = [f"{name} {ms[name]:.2f} ms/it (x{ms[name] / base:.2f}, {inner[name]:.2f} its/vertex)"
             for name in cases]
    return (f"frames on bumpy20k ({n} V, {iterations} iterations, "
            f"{'kernel' if compiled_kernels() is not None else 'NumPy'} path): " + "; ".join(parts))


def threads_child(repeat: int) -> None:
    """Child of the threads section: time bumpy20k's kernels with this process's threads."""
    params = CubicParams()
    V, F = load("bumpy20k")
    st = CubicStylizer(V, F)
    system, known, Vn = st.system, st.known, st.V_normalized
    kern = compiled_kernels()
    steps = list(st.steps(params))  # compiles / loads the kernels
    n_it = len(steps)
    times = {"whole run, ms per iteration":
             1e3 * median_seconds(lambda: list(st.steps(params)), repeat) / n_it}
    # a mid-run state: the local step's warm ADMM state after 10 iterations
    prox = st.style_prox(params)
    lam_a = params.lam * st.areas
    state = AdmmState.initial(st.n, params.rho0)
    U = Vn.copy()
    U[system.constrained] = known[system.constrained]
    for _ in range(10):
        R, _ = admm_local_step(system.covariances(U), st.normals, lam_a, prox, state, params)
        U = system.solve(system.rhs(R), known)
    S = system.covariances(U)
    z, u, rho = state.z.copy(), state.u.copy(), state.rho.copy()

    def local():
        state.z[:], state.u[:], state.rho[:] = z, u, rho
        admm_local_step(S, st.normals, lam_a, prox, state, params)

    b = system.rhs(R)
    reps = max(20, 10 * repeat)
    times["local step (ADMM)"] = 1e3 * median_seconds(local, reps)
    times["covariances K U"] = 1e3 * median_seconds(lambda: system.covariances(U), reps)
    times["right-hand side K^T R"] = 1e3 * median_seconds(lambda: system.rhs(R), reps)
    times["solve (cholespy)"] = 1e3 * median_seconds(lambda: system.solve(b, known), reps)
    times["ARAP energy terms (general)"] = 1e3 * median_seconds(
        lambda: system.energy(U, R, exact=False, covariances=S), reps)
    times["energy after solve (the run's)"] = 1e3 * median_seconds(
        lambda: system.energy_after_solve(U, R, b, rotations=True), reps)
    Uo = U + 1e-3
    if kern is not None:
        times["L1 term"] = 1e3 * median_seconds(
            lambda: kern.cube_l1_energy(R, st.normals, None, prox.diagonal, lam_a), reps)
        times["after solve: K U + L1 + move + out"] = 1e3 * median_seconds(
            lambda: kern.cube_after_solve(*system._k_blocks(), U, R, st.normals, None,
                                          prox.diagonal, lam_a, Uo, Vn, st.scale, st.center),
            reps)
    times["relative displacement"] = 1e3 * median_seconds(
        lambda: relative_displacement(U, Uo, Vn), reps)
    child_report(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--lam", type=float, default=0.2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-numpy", action="store_true", help="skip the NumPy-path run")
    ap.add_argument("--no-frames", action="store_true", help="skip the local-frames line")
    ap.add_argument("--frames-iterations", type=int, default=30,
                    help="outer iterations of the local-frames runs (default 30)")
    ap.add_argument("--no-threads", action="store_true", help="skip the threads section")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the threads section")
    ap.add_argument("--threads-child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads_child:
        threads_child(args.repeat)
        return
    params = CubicParams(lam=args.lam)

    t0 = time.perf_counter()
    kern = compiled_kernels()
    if kern is not None:  # first call: Numba import + cache load (or compilation)
        from algorithms.mesh import icosphere

        Vs, Fs = icosphere(1)
        list(CubicStylizer(Vs, Fs).steps(CubicParams(max_iterations=2)))
    print(f"compiled kernels: {'numba' if kern is not None else 'unavailable (NumPy path)'}, "
          f"first use {time.perf_counter() - t0:.2f} s")
    print(f"lambda {params.lam}, stop at relative move {params.rel_displacement_tol}; "
          f"times are medians of {args.repeat} runs")
    head = (f"{'mesh':<16}{'V':>7}{'its':>5}{'precomp s':>10}{'run s':>8}{'ms/it':>8}"
            f"{'local':>8}{'global':>8}{'other':>8}{'numpy ms/it':>12}{'igl ms/it':>10}"
            f"{'ratio':>7}")
    print(head)
    print("-" * len(head))
    for name in args.meshes:
        mesh = load(name)
        if mesh is None:
            print(f"{name}: not found (tests/data or $STYLIZE3D_MESHES), skipped")
            continue
        V, F = mesh
        t_pre = median_seconds(lambda: CubicStylizer(V, F), args.repeat)
        st = CubicStylizer(V, F)
        n_it, t_run, U_ours = timed_run(st, params, args.repeat)
        sp_ = split_run(st, params, n_it)

        numpy_ms = float("nan")
        if not args.no_numpy and kern is not None:
            previous = set_compiled_kernels(False)
            try:
                n_np, t_np, _ = timed_run(st, params, 1)
            finally:
                set_compiled_kernels(previous)
            numpy_ms = 1e3 * t_np / n_np

        # peer: libigl ARAP (spokes and rims), one pinned vertex, the same iteration count
        b = np.array([0], dtype=np.int32)
        U0 = np.ascontiguousarray(U_ours)
        bc = U0[b.astype(np.int64)]
        data = igl.ARAPData()
        data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
        data.max_iter = n_it
        igl.arap_precomputation(V, F, 3, b, data)
        t_peer = median_seconds(lambda: igl.arap_solve(bc, data, U0), args.repeat)
        per_peer = t_peer / n_it
        per_ours = t_run / n_it
        print(f"{name.rsplit('.', 1)[0]:<16}{len(V):>7}{n_it:>5}{t_pre:>10.3f}{t_run:>8.3f}"
              f"{1e3 * per_ours:>8.2f}{1e3 * sp_['local'] / n_it:>8.2f}"
              f"{1e3 * sp_['global'] / n_it:>8.2f}{1e3 * sp_['other'] / n_it:>8.2f}"
              f"{numpy_ms:>12.2f}{1e3 * per_peer:>10.2f}{per_ours / per_peer:>7.2f}")
    if not args.no_frames:
        print(frames_line(params, args.frames_iterations, args.repeat))
    if not args.no_threads:
        threads_section(__file__, "cubic", ["--repeat", str(args.repeat)], rounds=args.rounds,
                        title=f"cubic stylization on bumpy20k, lambda {params.lam}")


if __name__ == "__main__":
    main()
