"""Normal-driven shape analogies: iterations per second per regularizer, libigl's ARAP as the peer.

Meshes (default): armadillo (tests/data, 14,587 vertices) and a procedural 20,000-vertex mesh
("bumpy20k": organic_sample("bumpy") after one Loop subdivision, QSlim-decimated to exactly
20,000 vertices; _timing.bumpy20k). For
each mesh and regularizer (arap, farap, acap), cube style, λ = 1, fixed and dynamic targets, a fixed
number of iterations (the stopping rule off):

  V           vertices
  reg, T      regularizer; targets fixed / dynamic
  pre s       ShapeAnalogy construction + the regularizer's ARAP system (cotangent weights, K,
              the prefactored global matrix), one-off
  it/s        iterations per second of ShapeAnalogy.steps (median of --repeat runs; every
              iteration also computes the metrics: energy, angles to targets, displacement)
  ms/it       the same, milliseconds per iteration
  local, global, other
              ms per iteration of the same loop re-timed by parts: local = normal term + batched
              Procrustes (compiled), global = right-hand side + prefactored solve, other =
              centroid, covariances, normals, targets, energy and metrics
  numpy it/s  the same run with the compiled kernels switched off (--no-numpy skips it)
  igl ms/it   libigl's ARAP (igl.arap_precomputation / igl.arap_solve; SPOKES_AND_RIMS for
              arap and acap, ELEMENTS (one rotation per triangle) for farap; one pinned vertex,
              started from the input), per iteration, in the same process
  ratio       ours / igl per iteration (> 1: ours slower). libigl has no normal term, no scale
              and computes no metrics; its iteration is the same local-global loop.

Target (issue): >= 50 it/s at ~20k vertices for every regularizer.

Threads (issue 25): the last section runs bumpy20k in child processes with NUMBA_NUM_THREADS=1
and =2 (alternating rounds, benchmarks/_threads.py): ms per iteration of each regularizer (fixed
targets), and its kernels (Procrustes of all cells, scaled Procrustes for acap, covariances,
right-hand side); ratio = 2 threads / 1 thread. ``--no-threads`` skips it.

Usage: .venv/bin/python benchmarks/analogies.py [--iterations 60] [--repeat 3] [--no-numpy]
       [--no-threads] [--rounds 3] [mesh names...]
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
from algorithms.deform.analogies import (  # noqa: E402
    REGULARIZERS,
    AnalogyParams,
    ShapeAnalogy,
    _face_cross,
)
from algorithms.deform.arap import (  # noqa: E402
    compiled_kernels,
    procrustes_rotations,
    relative_displacement,
    set_compiled_kernels,
)
from algorithms.deform.targets import ClosestNormals  # noqa: E402
from algorithms.mesh import read_mesh  # noqa: E402

DEFAULT = ["armadillo.obj", "bumpy20k"]
CUBE = ClosestNormals.primitive("cube")


def load(name: str):
    if name == "bumpy20k":
        return bumpy20k()
    path = mesh_path(name)
    if not path.exists():
        return None
    m = read_mesh(path)
    return m.V, m.F


def split_run(sa: ShapeAnalogy, params: AnalogyParams, iterations: int) -> dict[str, float]:
    """Re-run the fixed-target loop of ShapeAnalogy.steps with timers around its parts."""
    on_faces = params.regularizer == "farap"
    cells = "faces" if on_faces else "spokes_and_rims"
    kind = "faces" if on_faces else "vertices"
    system = sa.system(cells)
    n_in = sa.face_normals if on_faces else sa.vertex_normals
    lam_a = params.lam * (sa.face_areas if on_faces else sa.vertex_areas)
    T = CUBE(n_in)
    wn = (2 * lam_a)[:, None] * n_in
    U = sa.V.copy()
    S = system.covariances(U)
    t_local = t_global = t_other = 0.0
    for _ in range(iterations):
        t0 = time.perf_counter()
        extra = np.einsum("ka,kb->kab", wn, T)
        if params.regularizer == "acap":
            R, s = system.scaled_rotations(U, extra, 2 * lam_a, covariances=S)
            M = R * s[:, None, None]
        else:
            M = procrustes_rotations(S + extra)
        t1 = time.perf_counter()
        Un = system.solve(system.rhs(M), sa.known)
        t2 = time.perf_counter()
        X = _face_cross(Un, sa.F)
        Un, factor = sa._place(Un, params.regularizer == "acap", X)
        relative_displacement(Un, U, sa.V)
        U = Un
        S = system.covariances(U)
        system.energy(U, M, exact=False, covariances=S)
        N, _ = sa.normals(U, kind, X, factor)
        if params.dynamic_targets:
            T = CUBE(N)
        U.copy()
        t3 = time.perf_counter()
        t_local += t1 - t0
        t_global += t2 - t1
        t_other += t3 - t2
    return {"local": t_local, "global": t_global, "other": t_other}


def igl_ms_per_iteration(V, F, regularizer: str, iterations: int, repeat: int) -> float:
    data = igl.ARAPData()
    data.energy = (igl.ARAP_ENERGY_TYPE_ELEMENTS if regularizer == "farap"
                   else igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS)
    data.max_iter = iterations
    b = np.array([0], dtype=np.int32)
    igl.arap_precomputation(V, F, 3, b, data)
    U0 = np.ascontiguousarray(V)
    bc = U0[[0]]
    return 1e3 * median_seconds(lambda: igl.arap_solve(bc, data, U0), repeat) / iterations


def threads_child(iterations: int, repeat: int) -> None:
    """Child of the threads section: bumpy20k's runs and kernels with this process's threads."""
    V, F = load("bumpy20k")
    times = {}
    for reg in REGULARIZERS:
        sa = ShapeAnalogy(V, F, CUBE)
        p = AnalogyParams(regularizer=reg, max_iterations=iterations, rel_displacement_tol=0.0)
        list(sa.steps(p))
        times[f"{reg} run, ms per iteration"] = 1e3 * median_seconds(
            lambda: list(sa.steps(p)), repeat) / iterations
    sa = ShapeAnalogy(V, F, CUBE)
    for cells in ("spokes_and_rims", "faces"):
        system = sa.system(cells)
        U = sa.V + 1e-3 * np.random.default_rng(0).standard_normal(sa.V.shape)
        S = system.covariances(U)
        R = procrustes_rotations(S)
        tag = "vertex" if cells == "spokes_and_rims" else "face"
        times[f"Procrustes, {tag} cells"] = 1e3 * median_seconds(
            lambda: procrustes_rotations(S), 20)
        if cells == "spokes_and_rims":
            times["scaled Procrustes (acap)"] = 1e3 * median_seconds(
                lambda: system.scaled_rotations(U, covariances=S), 20)
        times[f"covariances, {tag} cells"] = 1e3 * median_seconds(
            lambda: system.covariances(U), 20)
        times[f"right-hand side, {tag} cells"] = 1e3 * median_seconds(
            lambda: system.rhs(R), 20)
    child_report(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-numpy", action="store_true")
    ap.add_argument("--no-threads", action="store_true", help="skip the threads section")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the threads section")
    ap.add_argument("--threads-child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads_child:
        threads_child(args.iterations, args.repeat)
        return

    t0 = time.perf_counter()
    kern = compiled_kernels()
    if kern is not None:  # load (or compile) every kernel once
        from algorithms.mesh import icosphere

        Vs, Fs = icosphere(1)
        for reg in REGULARIZERS:
            list(ShapeAnalogy(Vs, Fs, CUBE).steps(AnalogyParams(regularizer=reg,
                                                                max_iterations=2)))
    print(f"compiled kernels: {'numba' if kern is not None else 'off (NumPy)'}, "
          f"first use {time.perf_counter() - t0:.2f} s")
    print(f"cube style, λ = 1, {args.iterations} iterations per run, median of {args.repeat}")
    head = (f"{'mesh':<12}{'V':>7}  {'reg':<6}{'T':<8}{'pre s':>7}{'it/s':>8}{'ms/it':>8}"
            f"{'local':>8}{'global':>8}{'other':>8}{'numpy it/s':>12}{'igl ms/it':>11}"
            f"{'ratio':>7}")
    print(head)
    print("-" * len(head))
    summary = []
    for name in args.meshes:
        mesh = load(name)
        if mesh is None:
            print(f"{name:<12} (not found, skipped)")
            continue
        V, F = mesh
        for reg in REGULARIZERS:
            cells = "faces" if reg == "farap" else "spokes_and_rims"

            def build():
                sa_ = ShapeAnalogy(V, F, CUBE)
                sa_.system(cells)
                return sa_

            t_pre = median_seconds(build, 1)
            sa = build()
            peer = igl_ms_per_iteration(V, F, reg, args.iterations, args.repeat)
            for dyn in (False, True):
                p = AnalogyParams(regularizer=reg, dynamic_targets=dyn,
                                  max_iterations=args.iterations, rel_displacement_tol=0.0)
                t_run = median_seconds(lambda: list(sa.steps(p)), args.repeat)
                ms = 1e3 * t_run / args.iterations
                sp_ = split_run(sa, p, args.iterations)
                numpy_its = float("nan")
                if not args.no_numpy and kern is not None:
                    previous = set_compiled_kernels(False)
                    try:
                        numpy_its = args.iterations / median_seconds(
                            lambda: list(sa.steps(replace(p))), 1)
                    finally:
                        set_compiled_kernels(previous)
                mesh_name = name.rsplit(".", 1)[0]
                print(f"{mesh_name:<12}{len(V):>7}  {reg:<6}{'dynamic' if dyn else 'fixed':<8}"
                      f"{t_pre:>7.2f}{1e3 / ms:>8.1f}{ms:>8.2f}"
                      f"{1e3 * sp_['local'] / args.iterations:>8.2f}"
                      f"{1e3 * sp_['global'] / args.iterations:>8.2f}"
                      f"{1e3 * sp_['other'] / args.iterations:>8.2f}"
                      f"{numpy_its:>12.1f}{peer:>11.2f}{ms / peer:>7.2f}")
                summary.append((mesh_name, reg, dyn, 1e3 / ms))
    if summary:
        worst = min(summary, key=lambda r: r[3])
        print(f"slowest: {worst[0]} {worst[1]} ({'dynamic' if worst[2] else 'fixed'}) "
              f"{worst[3]:.1f} it/s; target >= 50 it/s at ~20k vertices")
    if not args.no_threads:
        threads_section(__file__, "analogies", ["--iterations", str(args.iterations),
                                                "--repeat", str(args.repeat)],
                        rounds=args.rounds, title="shape analogies on bumpy20k, cube style")


if __name__ == "__main__":
    main()
