"""``stylize3d smooth`` (the Smooth recipe: Laplacian / mean-curvature flow; or data smoothing,
thesis Eq. 8.6, with surface multigrid) and ``stylize3d multigrid-info`` (thesis ch. 8)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, field_names, input_state, method_params,
                            method_recipe, params_file, params_to_dict, print_json, read_input,
                            settings)

COMMANDS = ("smooth", "multigrid-info")

#: the flags that switch ``smooth`` to data smoothing (also as names in a --params file)
DATA_SMOOTHING_NAMES = ("energy", "alpha", "solver")


def _smooth_names() -> set[str]:
    from algorithms.multigrid.params import DataSmoothingParams
    from algorithms.smoothing import SmoothParams

    return field_names(SmoothParams, DataSmoothingParams)


def _data_smoothing_requested(args: argparse.Namespace) -> bool:
    if any(getattr(args, k) is not None for k in ("signal", *DATA_SMOOTHING_NAMES)):
        return True
    return any(k in params_file(args) for k in DATA_SMOOTHING_NAMES)


def cmd_smooth(args: argparse.Namespace) -> int:
    from algorithms.smoothing import SmoothParams

    names = _smooth_names()
    if _data_smoothing_requested(args):
        return _cmd_data_smooth(args, names)
    from algorithms.mesh import write_mesh

    params = method_params(args, SmoothParams, panel="Smooth", allowed=names)
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    recipe = method_recipe("smooth", "Smooth")
    t0 = time.perf_counter()
    history = []
    last = None
    for last in recipe.steps(input_state(args, data), params, {}, {}):
        history.append(last.metrics)
        if not args.json and not args.quiet:
            print(f"  step {last.iteration}/{last.total}: bending energy {last.metrics['bending_energy']:.6g}",
                  file=sys.stderr)
    seconds = time.perf_counter() - t0
    write_mesh(args.output, last.V, data.F)
    if args.json:
        print_json({"input": args.mesh, "output": args.output, "params": params_to_dict(params),
                    "iterations": last.iteration, "seconds": seconds,
                    "bending_energy": [h["bending_energy"] for h in history],
                    "displacement": [h["displacement"] for h in history]})
    else:
        print(f"Smoothed {args.mesh} in {seconds:.2f} s ({last.iteration} steps); wrote {args.output}.")
    return 0


def _cmd_data_smooth(args: argparse.Namespace, names: set[str]) -> int:
    """Data smoothing (thesis Eq. 8.6) of positions, a noisy test field or a field file."""
    import numpy as np

    from algorithms.mesh import write_mesh
    from algorithms.mesh.fields import FIELD_EXTENSIONS, read_field, write_field
    from algorithms.multigrid import surface_multigrid
    from algorithms.multigrid.applications import DataSmoother
    from algorithms.multigrid.params import DataSmoothingParams
    from algorithms.smoothing import noisy_test_field, unit_area

    params = method_params(args, DataSmoothingParams, panel="Multigrid smoothing",
                           allowed=names)
    signal = args.signal or "positions"
    out_ext = Path(args.output).suffix.lower()
    if signal == "positions":
        if out_ext in FIELD_EXTENSIONS:
            raise ParameterError(f"--signal positions writes a mesh; {args.output} is a field "
                                 "file name. Use .obj, .ply, .off or .stl.")
    elif out_ext not in FIELD_EXTENSIONS:
        raise ParameterError(f"--signal {signal} writes one value per vertex: give -o a "
                             f"{', '.join(FIELD_EXTENSIONS)} file name.")
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    V, F = data.V, data.F
    clean = None
    if signal == "positions":
        f = V
    elif signal == "noise":
        clean, f = noisy_test_field(V, F, args.noise, args.seed)
    else:
        f = read_field(signal, len(V))
    from algorithms.multigrid.applications import choose_solver

    t0 = time.perf_counter()
    solver, why = params.solver, None
    if solver == "auto":
        solver, why = choose_solver(len(V), params.energy)
        if not (args.json or args.quiet):
            print(f"stylize3d smooth: {why}.", file=sys.stderr)
    mg = None
    if solver == "multigrid":
        mg = surface_multigrid(V, F)
    t1 = time.perf_counter()
    # operators of the unit-area copy: one α does the same whatever the mesh's units
    smoother = DataSmoother(unit_area(V, F), F, energy=params.energy, solver=solver, mg=mg)
    t2 = time.perf_counter()
    # never a silent wrong answer: an unconverged multigrid solve falls back to the direct
    # solver when it fits in memory (saying so) or raises NotConvergedError (exit status 6,
    # nothing written); --no-fallback always refuses
    u, info = smoother.smooth_checked(f, params.alpha, rtol=args.rtol, maxiter=args.max_cycles,
                                      fallback=args.fallback)
    if info.get("fallback") and not args.json:
        print(f"stylize3d smooth: {info['fallback']}", file=sys.stderr)
    if signal == "positions":
        write_mesh(args.output, u, F)
    else:
        write_field(args.output, u)
    out = {"input": args.mesh, "output": args.output, "signal": signal,
           "params": params_to_dict(params), "vertices": len(V),
           "solver": info.get("solver", solver), "solver_choice": why,
           "fallback": info.get("fallback"),
           "hierarchy_seconds": t1 - t0, "precompute_seconds": t2 - t1,
           "setup_seconds": info["setup_seconds"], "solve_seconds": info["solve_seconds"],
           "cycles": info.get("multigrid_cycles", info.get("cycles", 0)),
           "converged": bool(info.get("converged", True)),
           "levels": [len(Vh) for Vh, _ in mg.levels] if mg is not None else None,
           "hierarchy_notes": list(mg.report.get("notes", [])) if mg is not None else []}
    res = list(info.get("multigrid_residuals") or info.get("residuals") or [])
    if res:
        out["relative_residual"] = float(res[-1] / res[0]) if res[0] > 0 else 0.0
    if clean is not None:
        rms = lambda x: float(np.sqrt(np.mean((x - clean) ** 2)))  # noqa: E731
        out["rms_error_before"], out["rms_error_after"] = rms(f), rms(u)
    if args.json:
        print_json(out)
    else:
        extra = (f"; RMS error to the clean signal {out['rms_error_before']:.4g} -> "
                 f"{out['rms_error_after']:.4g}" if clean is not None else "")
        how = (f"multigrid ({out['cycles']} CG steps, {len(out['levels'])} levels)"
               if out["solver"] == "multigrid" else "the direct solver")
        print(f"Smoothed {signal} of {args.mesh} ({params.energy}, α {params.alpha:g}) with "
              f"{how} in {info['seconds']:.3f} s{extra}; wrote {args.output}.")
    return 0


#: multigrid-info's settings (flags, or names in a --params file) and their defaults
HIERARCHY_DEFAULTS = {"ratio": 0.25, "min_vertices": 500, "strategy": "midpoint",
                      "prolongation": "intrinsic"}


def cmd_multigrid_info(args: argparse.Namespace) -> int:
    """Build the multigrid hierarchy of a mesh and report levels, sizes, time and bijectivity."""
    import numpy as np

    from algorithms.multigrid import surface_multigrid

    opts = settings(args, HIERARCHY_DEFAULTS)
    data, _ = read_input(args, quiet=args.json)
    progress = None
    if not args.json:
        def progress(frac, msg):
            print(f"  {100 * frac:5.1f}%  {msg}", file=sys.stderr)
    mg = surface_multigrid(data.V, data.F, ratio=opts["ratio"], min_vertices=opts["min_vertices"],
                           strategy=opts["strategy"], prolongation=opts["prolongation"],
                           progress=progress)
    levels = []
    all_ok = True
    for h, (Vh, Fh) in enumerate(mg.levels):
        entry = {"level": h, "vertices": int(len(Vh)), "faces": int(len(Fh))}
        if h > 0:
            P = mg.prolongations[h - 1].tocsr()
            nnz = np.diff(P.indptr)
            rows = np.asarray(P.sum(axis=1)).ravel()
            rep = mg.report["levels"][h]
            # bijectivity: every fine vertex in exactly one coarse triangle, with valid
            # barycentric coordinates (>= 0, sum 1): 3 non-negative weights per row summing to 1
            ok = bool((nnz == 3).all() and P.data.min() >= -1e-8
                      and np.abs(rows - 1).max() <= 1e-8)
            all_ok &= ok
            entry.update(seconds=float(rep.get("seconds", 0.0)), prolongation_nnz_per_row=3
                         if (nnz == 3).all() else int(nnz.max()),
                         min_barycentric=float(P.data.min()),
                         max_row_sum_error=float(np.abs(rows - 1).max()), bijective=ok)
            sprep = rep.get("selfparam") or {}
            for k in ("rejections", "reached_target", "collapses"):
                if k in sprep:
                    entry[k] = sprep[k]
        levels.append(entry)
    out = {"input": args.mesh, "vertices": int(len(data.V)), "faces": int(len(data.F)),
           "n_levels": mg.n_levels, "hierarchy_seconds": float(mg.build_seconds),
           "prolongation": mg.report.get("prolongation"), "strategy": mg.report.get("strategy"),
           "bijective": all_ok, "levels": levels, "notes": list(mg.report.get("notes", []))}
    if args.json:
        print_json(out)
    else:
        print(f"{args.mesh}: {mg.n_levels} levels, built in {mg.build_seconds:.2f} s "
              f"({out['prolongation']} prolongation, {out['strategy']} collapses)")
        for e in levels:
            extra = "" if e["level"] == 0 else (
                f"  {e['seconds']:.2f} s, barycentric min {e['min_barycentric']:.2e}, "
                f"{'bijective' if e['bijective'] else 'NOT bijective'}")
            print(f"  level {e['level']}: {e['vertices']:>9,} vertices {e['faces']:>9,} "
                  f"triangles{extra}")
        for n in out["notes"]:
            print(f"  note: {n}")
    return 0 if all_ok else 1


def add_parsers(sub) -> None:
    from algorithms.smoothing import SmoothParams

    s = sub.add_parser("smooth", help="implicit Laplacian / mean-curvature smoothing of the shape")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("-o", "--output", required=True, help="where to write the smoothed mesh")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true", help="print figures as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-step progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    add_params_file_argument(s)
    add_params_arguments(s, SmoothParams)
    d = s.add_argument_group(
        "data smoothing (thesis Eq. 8.6, surface multigrid)",
        "Any of these switches from the flow above to data smoothing (so does a --params file "
        "holding energy, alpha or solver): minimize α E(u) + (1-α) ∫|u - f|² for a signal f; "
        "the flow options are then not used. A project's saved 'Multigrid smoothing' settings "
        "are the defaults.")
    d.add_argument("--signal", metavar="positions|noise|FIELD",
                   help="positions (writes the smoothed mesh), noise (a noisy test field made "
                        "here; writes the smoothed values) or a per-vertex field file "
                        "(.npy/.txt/.csv; writes the smoothed values). Default: positions.")
    d.add_argument("--energy", choices=("dirichlet", "bilaplacian", "hessian"),
                   help="smoothness energy E. Default: dirichlet.")
    d.add_argument("--alpha", type=float, metavar="A",
                   help="smoothness α in (0, 1), for the mesh scaled to unit area (so it does "
                        "not depend on units); larger is smoother. Typical: 1e-3 (dirichlet), "
                        "1e-6 (bilaplacian). Default: 1e-3.")
    d.add_argument("--solver", choices=("auto", "multigrid", "direct"),
                   help="auto (default: direct for small and medium meshes, multigrid above; "
                        "says which), multigrid (CG with surface-multigrid V-cycles) or direct "
                        "(a Cholesky factorization).")
    d.add_argument("--rtol", type=float, default=1e-5,
                   help="relative residual at which the multigrid iterations stop. "
                        "Default: 1e-5.")
    d.add_argument("--max-cycles", type=int, default=100,
                   help="at most this many multigrid iterations; they also stop early when "
                        "the residual grows or stalls. Default: 100.")
    d.add_argument("--fallback", action=argparse.BooleanOptionalAction, default=True,
                   help="when multigrid does not converge, solve with the direct solver if it "
                        "fits in memory (and say so). With --no-fallback the command fails "
                        "(exit status 6) and writes nothing. Default: on.")
    d.add_argument("--noise", type=float, default=0.4,
                   help="noise of --signal noise, relative to the pattern's spread. Default: 0.4.")
    d.add_argument("--seed", type=int, default=0, help="random seed of --signal noise.")
    s.set_defaults(func=cmd_smooth)

    s = sub.add_parser("multigrid-info",
                       help="build the surface-multigrid hierarchy and report it (thesis ch. 8)",
                       description="Build the multigrid hierarchy of a mesh (successive "
                                   "self-parameterization) and report levels, sizes, time and "
                                   "whether every fine vertex has valid barycentric coordinates "
                                   "in one coarse triangle. Exit status 1 when not.")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("--json", action="store_true", help="print the report as JSON")
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    add_params_file_argument(s)
    s.add_argument("--ratio", type=float, help="triangles kept per level. Default: 0.25.")
    s.add_argument("--min-vertices", type=int,
                   help="coarsest level keeps at least this many vertices. Default: 500.")
    s.add_argument("--strategy", choices=("midpoint", "qslim"),
                   help="edge-collapse strategy. Default: midpoint.")
    s.add_argument("--prolongation", choices=("intrinsic", "closest_point"),
                   help="intrinsic (self-parameterization, default) or closest_point.")
    s.set_defaults(func=cmd_multigrid_info)
