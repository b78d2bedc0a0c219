"""``stylize3d smooth`` (the Smooth recipe: Laplacian / mean-curvature flow; or data smoothing,
thesis Eq. 8.6, with surface multigrid: the "Multigrid smoothing" recipe of
:mod:`app.recipes.multigrid`) and ``stylize3d multigrid-info`` (thesis ch. 8).

Data smoothing on a project (``scene.s3d``) uses the Multigrid smoothing panel's saved settings
and options (its noisy or loaded field, noise level and seed) unless flags say otherwise, so
``smooth scene.s3d -o out.npy --signal noise`` writes the values of
``app.recipes.run("Multigrid smoothing", project, params, options)``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, field_names, input_state, method_params,
                            method_recipe, params_file, params_to_dict, print_json, read_input,
                            saved_panel, settings)

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
    from algorithms.deform.collisions import crossings_of, crossings_sentence
    from algorithms.smoothing import SmoothParams

    names = _smooth_names()
    if _data_smoothing_requested(args):
        return _cmd_data_smooth(args, names)
    from app.cli.attributes import write_result

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
    write_result(args, args.output, last.V, data.F, data)
    crossings = crossings_of(last.metrics)
    from app.recipes.smooth import change_advice

    advice = change_advice(last, params, flags=True)
    if args.json:
        out = {"input": args.mesh, "output": args.output, "params": params_to_dict(params),
               "iterations": last.iteration, "seconds": seconds,
               "bending_energy": [h["bending_energy"] for h in history],
               "displacement": [h["displacement"] for h in history],
               # the largest move, in units of the bounding-box diagonal
               "moved": float(last.metrics.get("moved", 0.0)),
               "crossings": crossings}
        if advice:   # the shape barely changed: why, and what to raise
            out["note"] = advice
        print_json(out)
    else:
        said = " ".join(x for x in (crossings_sentence(last.metrics, "smoothing"), advice)
                        if x)
        print(f"Smoothed {args.mesh} in {seconds:.2f} s ({last.iteration} steps); wrote "
              f"{args.output}." + (f" {said}" if said else ""))
    return 0


def data_signal(args: argparse.Namespace) -> tuple[str, str]:
    """(the recipe's ``signal`` option, its name for messages) of ``smooth --signal ...``:
    ``--signal``; without it, the input project's saved signal (noise, or its loaded field)
    when ``-o`` is a field file, else positions. Refuses an output of the wrong kind."""
    from algorithms.mesh.fields import FIELD_EXTENSIONS
    from app.recipes.multigrid import SMOOTH

    out_ext = Path(args.output).suffix.lower()
    given = args.signal
    if given is None:
        saved = saved_panel(args, SMOOTH)
        kept = saved["options"].get("signal") if saved is not None else None
        signal = kept if kept in ("noise", "loaded") and out_ext in FIELD_EXTENSIONS \
            else "positions"
    else:
        signal = given if given in ("positions", "noise") else "loaded"
    name = given or signal
    if signal == "positions":
        if out_ext in FIELD_EXTENSIONS:
            raise ParameterError(f"--signal positions writes a mesh; {args.output} is a field "
                                 "file name. Use .obj, .ply, .off or .stl.")
    elif out_ext not in FIELD_EXTENSIONS:
        raise ParameterError(f"--signal {name} writes one value per vertex: give -o a "
                             f"{', '.join(FIELD_EXTENSIONS)} file name.")
    return signal, name


def data_smoothing_options(args: argparse.Namespace, state, signal: str):
    """(options of the "Multigrid smoothing" recipe, the state to run it on) for
    ``smooth --signal ...`` (``signal``: :func:`data_signal`'s).

    Options: the input project's saved "Multigrid smoothing" options (if any) < the flags. A
    field file given with ``--signal`` is checked here (its own name in messages) and becomes
    a blob; ``--noise`` / ``--seed`` make a new noisy field even when the project holds one."""
    from algorithms.mesh.fields import read_field
    from app.recipes import multigrid as rm
    from app.recipes import put_blob_file

    saved = saved_panel(args, rm.SMOOTH)
    options = dict(saved["options"]) if saved is not None else {}
    options["signal"] = signal
    options.setdefault("noise", rm.DEFAULT_NOISE)
    options.setdefault("noise_seed", 0)
    if args.noise is not None or args.seed is not None:
        if args.noise is not None:
            options["noise"] = args.noise
        if args.seed is not None:
            options["noise_seed"] = args.seed
        state = state.with_field(rm.NOISY_FIELD, None)
    if signal == "loaded" and args.signal is not None:
        read_field(args.signal, len(state.V))  # a plain error naming the user's file
        options["field"] = put_blob_file(args.signal)
        state = state.with_field(rm.LOADED_FIELD, None)
    options.update(rtol=args.rtol, max_iterations=args.max_cycles, fallback=args.fallback)
    return options, state


def smooth_job(args: argparse.Namespace, data_smoothing: bool | None = None) -> tuple:
    """``(recipe title, params, options)`` that ``smooth`` runs on any mesh, for ``stylize3d
    batch``: the flow ("Smooth"), or data smoothing of the positions ("Multigrid smoothing")
    when its flags ask for it (or ``data_smoothing``). A batch writes meshes, so it smooths
    the positions: ``--signal`` noise or a field file (values per vertex) is refused with a
    plain message, and a project's saved signal other than the positions is not used."""
    from algorithms.mesh import tetrahedron
    from algorithms.multigrid.params import DataSmoothingParams
    from algorithms.smoothing import SmoothParams
    from app.document import MeshState
    from app.recipes import multigrid as rm

    names = _smooth_names()
    if not (_data_smoothing_requested(args) if data_smoothing is None else data_smoothing):
        return "Smooth", method_params(args, SmoothParams, panel="Smooth", allowed=names), {}
    params = method_params(args, DataSmoothingParams, panel=rm.SMOOTH, allowed=names)
    if args.signal not in (None, "positions"):
        raise ParameterError("A batch writes meshes: only --signal positions (the default) "
                             "has a batch form; smoothing noise or a field file writes one "
                             "value per vertex, one mesh at a time with stylize3d smooth.")
    # the state only carries a noisy field to drop; none is used for the positions
    options, _ = data_smoothing_options(args, MeshState.make(*tetrahedron()), "positions")
    return rm.SMOOTH, params, options


def _cmd_data_smooth(args: argparse.Namespace, names: set[str]) -> int:
    """Data smoothing (thesis Eq. 8.6) of positions, a noisy test field or a field file: the
    recipe "Multigrid smoothing" (:mod:`app.recipes.multigrid`)."""
    import numpy as np

    from app.cli.attributes import write_result
    from algorithms.mesh.fields import write_field
    from algorithms.multigrid.params import DataSmoothingParams
    from app.recipes import multigrid as rm

    params = method_params(args, DataSmoothingParams, panel=rm.SMOOTH, allowed=names)
    kind, signal = data_signal(args)
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    options, state = data_smoothing_options(args, input_state(args, data), kind)
    solver, why = rm.resolve_solver(len(state.V), params)
    if why is not None and not (args.json or args.quiet):
        print(f"stylize3d smooth: {why}.", file=sys.stderr)
    recipe = method_recipe("multigrid", rm.SMOOTH)
    last = None
    for last in recipe.steps(state, params, options, {}):
        pass
    info, mg, u = last.info, last.mg, last.values
    if info.get("fallback") and not args.json:
        print(f"stylize3d smooth: {info['fallback']}", file=sys.stderr)
    if options["signal"] == "positions":
        write_result(args, args.output, u, state.F, data)
    else:
        write_field(args.output, u)
    out = {"input": args.mesh, "output": args.output, "signal": signal,
           "params": params_to_dict(params), "vertices": len(state.V),
           "solver": info.get("solver", solver), "solver_choice": why,
           "fallback": info.get("fallback"),
           "hierarchy_seconds": float(mg.build_seconds) if mg is not None else 0.0,
           "precompute_seconds": info["precompute_seconds"],
           "setup_seconds": info["setup_seconds"], "solve_seconds": info["solve_seconds"],
           "cycles": info.get("multigrid_cycles", info.get("cycles", 0)),
           "converged": bool(info.get("converged", True)),
           "levels": [len(Vh) for Vh, _ in mg.levels] if mg is not None else None,
           "hierarchy_notes": list(mg.report.get("notes", [])) if mg is not None else []}
    res = list(info.get("multigrid_residuals") or info.get("residuals") or [])
    if res:
        out["relative_residual"] = float(res[-1] / res[0]) if res[0] > 0 else 0.0
    if options["signal"] == "noise":  # how close the result gets to the clean pattern
        from algorithms.smoothing import noisy_test_field

        clean = noisy_test_field(state.V, state.F, 0.0)[0]
        f = last.made_fields.get(rm.NOISY_FIELD, state.fields.get(rm.NOISY_FIELD))
        rms = lambda x: float(np.sqrt(np.mean((x - clean) ** 2)))  # noqa: E731
        out["rms_error_before"], out["rms_error_after"] = rms(f), rms(u)
    if args.json:
        print_json(out)
    else:
        extra = (f"; RMS error to the clean signal {out['rms_error_before']:.4g} -> "
                 f"{out['rms_error_after']:.4g}" if "rms_error_after" in out else "")
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
        "and options (signal, noise, seed, loaded field) are the defaults.")
    d.add_argument("--signal", metavar="positions|noise|FIELD",
                   help="positions (writes the smoothed mesh), noise (a noisy test field made "
                        "here; writes the smoothed values) or a per-vertex field file "
                        "(.npy/.txt/.csv; writes the smoothed values). Default: positions; "
                        "on a project whose Multigrid smoothing panel smooths noise or a loaded "
                        "field, that signal when -o is a field file.")
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
    d.add_argument("--noise", type=float,
                   help="noise of --signal noise, relative to the pattern's spread. Default: "
                        "0.4 (or the project's saved noise).")
    d.add_argument("--seed", type=int,
                   help="random seed of --signal noise. Default: 0 (or the project's saved "
                        "seed; a project's noisy field is used unless --noise or --seed is "
                        "given).")
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
