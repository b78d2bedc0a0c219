"""Batch sub-commands of ``stylize3d``. Imports no Qt and no VTK.

Every sub-command prints a plain message and exits non-zero on bad input (the exit status is the
error's ``exit_code``: 2 unreadable file, 3 unwritable file, 4 invalid mesh, 5 bad parameter,
6 an iterative solve that did not converge; 70 an unexpected failure, whose traceback goes to a
crash-log file, never to the screen).
Method flags are generated from the methods' Params dataclasses (one definition per parameter).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

from algorithms.errors import InvalidMeshError, MeshWriteError, ParameterError, Stylize3DError
from algorithms.params import describe, params_from_dict, params_to_dict

SUBCOMMANDS = ("info", "clean", "smooth", "multigrid-info", "cubic", "analogy", "coarsen",
               "study", "subdivide",
               "subdivide-train", "subdivide-eval", "adversary")


# ----------------------------------------------------------------------------- Params -> flags
def add_params_arguments(parser: argparse.ArgumentParser, params_cls: type) -> None:
    """Add one flag per field of ``params_cls`` (defaults, ranges and help from its metadata)."""
    group = parser.add_argument_group("method parameters")
    for spec in describe(params_cls):
        lo = "" if spec.minimum is None else f"{spec.minimum:g}"
        hi = "" if spec.maximum is None else f"{spec.maximum:g}"
        rng = f" Range {lo or '-inf'}..{hi or 'inf'}." if (lo or hi) else ""
        help_text = f"{spec.tooltip}{rng} Default: {spec.default}."
        help_text = help_text.replace("%", "%%")
        flags = (spec.flag, *spec.cli_aliases)
        if spec.type is bool:
            group.add_argument(*flags, dest=spec.name, action=argparse.BooleanOptionalAction,
                               default=spec.default, help=help_text)
        elif spec.type is str:
            group.add_argument(*flags, dest=spec.name, default=spec.default,
                               choices=spec.choices, help=help_text)
        else:
            group.add_argument(*flags, dest=spec.name, type=spec.type, default=spec.default,
                               metavar=spec.name.upper(), help=help_text)


def params_from_args(params_cls: type, args: argparse.Namespace) -> Any:
    values = {spec.name: getattr(args, spec.name) for spec in describe(params_cls)}
    return params_from_dict(params_cls, values)


# ----------------------------------------------------------------------------- helpers
def _read_valid(path: str, *, clean: bool = False, quiet: bool = False):
    """Read a mesh a method can process. Errors and fixable problems are refused with the report
    (and a hint to clean), unless ``clean`` is set: then the mesh is cleaned and what was done is
    printed to stderr."""
    from algorithms.mesh import MeshData, clean_mesh, read_mesh, validate_mesh

    data = read_mesh(path)
    report = validate_mesh(data.V, data.F, notes=data.notes)
    if clean and (report.errors or report.needs_cleaning):
        res = clean_mesh(data.V, data.F)
        if not quiet:
            for a in res.actions:
                print(f"clean: {a}", file=sys.stderr)
        data = MeshData(res.V, res.F, list(data.notes) + list(res.actions))
        report = validate_mesh(data.V, data.F, notes=data.notes)
    if report.errors or report.needs_cleaning:
        hint = ("" if clean or not report.needs_cleaning else
                f"\nAdd --clean to fix what can be fixed first, or run: "
                f"stylize3d clean {path} -o cleaned{Path(path).suffix}")
        raise InvalidMeshError(f"{path} cannot be processed as it is:\n{report.summary()}{hint}")
    return data, report


def _check_output(path: str, overwrite: bool, inp: str | None = None) -> None:
    out = Path(path)
    if inp is not None and out.exists() and os.path.samefile(out, inp) and not overwrite:
        raise MeshWriteError(f"{path} is the input file; pass --overwrite to replace it.")
    if out.exists() and not overwrite:
        raise MeshWriteError(f"{path} already exists; pass --overwrite to replace it.")
    if out.is_dir():
        raise MeshWriteError(f"{path} is a folder, not a file name.")


def _print_json(obj: dict) -> None:
    print(json.dumps(obj, indent=2, sort_keys=False, default=float))


# ----------------------------------------------------------------------------- sub-commands
def cmd_info(args: argparse.Namespace) -> int:
    from algorithms.mesh import read_mesh, validate_mesh

    data = read_mesh(args.mesh)
    report = validate_mesh(data.V, data.F, notes=data.notes)
    if args.json:
        out = {"file": str(args.mesh), "ok": report.ok, "notes": list(data.notes)}
        out.update(report.to_dict())
        _print_json(out)
    else:
        print(f"{args.mesh}")
        print(report.summary())
    # 0: every method accepts the mesh as it is; 4: it has errors or needs cleaning first
    return 0 if report.ok and not report.needs_cleaning else InvalidMeshError.exit_code


def cmd_clean(args: argparse.Namespace) -> int:
    from algorithms.mesh import clean_mesh, read_mesh, validate_mesh, write_mesh

    _check_output(args.output, args.overwrite, args.mesh)
    data = read_mesh(args.mesh)
    result = clean_mesh(data.V, data.F, remove_invalid_faces=args.remove_invalid_faces)
    after = validate_mesh(result.V, result.F)
    if after.errors:
        raise InvalidMeshError("Clean could not fix everything, so nothing was written:\n"
                               + "\n".join(result.actions) + "\n" + after.summary())
    write_mesh(args.output, result.V, result.F)
    if args.json:
        _print_json({"input": args.mesh, "output": args.output, "actions": list(result.actions),
                     "ok": after.ok, **after.to_dict()})
    else:
        for a in list(data.notes) + list(result.actions):
            print(a)
        print(f"Wrote {args.output} ({len(result.V)} vertices, {len(result.F)} triangles).")
        if not after.ok:
            print("Problems that Clean could not fix:\n" + after.summary())
    return 0 if after.ok else InvalidMeshError.exit_code


def _data_smoothing_requested(args: argparse.Namespace) -> bool:
    return any(getattr(args, k) is not None for k in ("signal", "energy", "alpha", "solver"))


def cmd_smooth(args: argparse.Namespace) -> int:
    if _data_smoothing_requested(args):
        return _cmd_data_smooth(args)
    from algorithms.mesh import write_mesh
    from algorithms.smoothing import SmoothParams, smooth_iter

    params = params_from_args(SmoothParams, args)
    _check_output(args.output, args.overwrite, args.mesh)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json or args.quiet)
    t0 = time.perf_counter()
    history = []
    last = None
    for last in smooth_iter(data.V, data.F, params):
        history.append(last.metrics)
        if not args.json and not args.quiet:
            print(f"  step {last.iteration}/{last.total}: bending energy {last.metrics['bending_energy']:.6g}",
                  file=sys.stderr)
    seconds = time.perf_counter() - t0
    write_mesh(args.output, last.V, data.F)
    if args.json:
        _print_json({"input": args.mesh, "output": args.output, "params": params_to_dict(params),
                     "iterations": last.iteration, "seconds": seconds,
                     "bending_energy": [h["bending_energy"] for h in history],
                     "displacement": [h["displacement"] for h in history]})
    else:
        print(f"Smoothed {args.mesh} in {seconds:.2f} s ({last.iteration} steps); wrote {args.output}.")
    return 0


def _cmd_data_smooth(args: argparse.Namespace) -> int:
    """Data smoothing (thesis Eq. 8.6) of positions, a noisy test field or a field file."""
    import numpy as np

    from algorithms.mesh import write_mesh
    from algorithms.mesh.fields import FIELD_EXTENSIONS, read_field, write_field
    from algorithms.multigrid import surface_multigrid
    from algorithms.multigrid.applications import DataSmoother
    from algorithms.multigrid.params import DataSmoothingParams
    from algorithms.smoothing import noisy_test_field, unit_area

    defaults = DataSmoothingParams()
    params = params_from_dict(DataSmoothingParams, {
        "energy": args.energy or defaults.energy,
        "alpha": defaults.alpha if args.alpha is None else args.alpha,
        "solver": args.solver or defaults.solver})
    signal = args.signal or "positions"
    out_ext = Path(args.output).suffix.lower()
    if signal == "positions":
        if out_ext in FIELD_EXTENSIONS:
            raise ParameterError(f"--signal positions writes a mesh; {args.output} is a field "
                                 "file name. Use .obj, .ply, .off or .stl.")
    elif out_ext not in FIELD_EXTENSIONS:
        raise ParameterError(f"--signal {signal} writes one value per vertex: give -o a "
                             f"{', '.join(FIELD_EXTENSIONS)} file name.")
    _check_output(args.output, args.overwrite, args.mesh)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json or args.quiet)
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
        _print_json(out)
    else:
        extra = (f"; RMS error to the clean signal {out['rms_error_before']:.4g} -> "
                 f"{out['rms_error_after']:.4g}" if clean is not None else "")
        how = (f"multigrid ({out['cycles']} CG steps, {len(out['levels'])} levels)"
               if out["solver"] == "multigrid" else "the direct solver")
        print(f"Smoothed {signal} of {args.mesh} ({params.energy}, α {params.alpha:g}) with "
              f"{how} in {info['seconds']:.3f} s{extra}; wrote {args.output}.")
    return 0


def cmd_multigrid_info(args: argparse.Namespace) -> int:
    """Build the multigrid hierarchy of a mesh and report levels, sizes, time and bijectivity."""
    import numpy as np

    from algorithms.multigrid import surface_multigrid

    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json)
    progress = None
    if not args.json:
        progress = lambda frac, msg: print(f"  {100 * frac:5.1f}%  {msg}", file=sys.stderr)  # noqa: E731
    mg = surface_multigrid(data.V, data.F, ratio=args.ratio, min_vertices=args.min_vertices,
                           strategy=args.strategy, prolongation=args.prolongation,
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
        _print_json(out)
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


def _progressive_choice(args: argparse.Namespace, n_faces: int, command: str, *,
                        auto_ok: bool = True):
    """ProgressiveParams when the command should run through affine progressive meshes, else None.

    ``--progressive-faces M`` asks for it; above ``AUTO_PROGRESSIVE_FACES`` triangles it is on by
    default (as in the app), said on stderr, unless ``--no-progressive``.
    """
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES, ProgressiveParams

    if args.progressive_faces is not None and args.no_progressive:
        raise ParameterError("--progressive-faces and --no-progressive contradict each other; "
                             "choose one.")
    faces = args.progressive_faces
    if faces is None:
        if args.no_progressive or not auto_ok or n_faces <= AUTO_PROGRESSIVE_FACES:
            return None
        faces = min(ProgressiveParams().target_faces, n_faces // 2)
        if not args.quiet:
            _say(f"stylize3d {command}: this mesh has {n_faces:,} triangles (more than "
                 f"{AUTO_PROGRESSIVE_FACES:,}), so it is stylized through affine progressive "
                 f"meshes: on a {faces:,}-triangle copy, then the details are put back. Pass "
                 f"--no-progressive to work on every triangle directly (slower), or "
                 f"--progressive-faces M to choose the copy's size.")
    return params_from_dict(ProgressiveParams, {"target_faces": faces, "preview_every": 0})


def cmd_cubic(args: argparse.Namespace) -> int:
    from algorithms.deform.cubic import CubicParams, cubic_stylization_iter, mean_l1_of_normals
    from algorithms.mesh import write_mesh

    params = params_from_args(CubicParams, args)
    if args.lambda_xyz is not None:
        x, y, z = args.lambda_xyz
        params = params_from_dict(CubicParams, {**params_to_dict(params), "per_axis": True,
                                                "axis_factor_x": x, "axis_factor_y": y,
                                                "axis_factor_z": z})
    _check_output(args.output, args.overwrite, args.mesh)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json or args.quiet)
    l1_before = mean_l1_of_normals(data.V, data.F)
    t0 = time.perf_counter()
    last = None
    if args.progressive_faces is not None and args.global_solver == "multigrid":
        raise ParameterError("--progressive-faces and --global-solver multigrid are two ways to "
                             "handle big meshes; choose one.")
    prog = _progressive_choice(args, len(data.F), "cubic",
                               auto_ok=args.global_solver != "multigrid")
    if prog is not None:
        from algorithms.deform.progressive import progressive_cubic_iter

        steps = progressive_cubic_iter(data.V, data.F, params, prog)
    else:
        steps = cubic_stylization_iter(data.V, data.F, params,
                                       backend="multigrid" if args.global_solver == "multigrid"
                                       else "auto")
    for last in steps:
        if "energy" in last.metrics and not args.json and not args.quiet:
            print(f"  iteration {last.iteration}: energy {last.metrics['energy']:.6g}, "
                  f"relative move {last.metrics.get('displacement', 0):.2e}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    write_mesh(args.output, last.V, data.F)
    l1_after = mean_l1_of_normals(last.V, data.F)
    if args.json:
        _print_json({"input": args.mesh, "output": args.output, "params": params_to_dict(params),
                     "iterations": last.iteration, "seconds": seconds,
                     "final_relative_displacement": last.metrics.get("displacement"),
                     "progressive_faces": None if prog is None else prog.target_faces,
                     "progressive_auto": prog is not None and args.progressive_faces is None,
                     "l1_normals_before": l1_before, "l1_normals_after": l1_after})
    else:
        print(f"Stylized {args.mesh} in {seconds:.2f} s ({last.iteration} iterations); mean L1 "
              f"norm of normals {l1_before:.4f} -> {l1_after:.4f}; wrote {args.output}.")
    return 0


def cmd_analogy(args: argparse.Namespace) -> int:
    from algorithms.deform.analogies import AnalogyParams, ShapeAnalogy, angles_to_targets
    from algorithms.deform.targets import load_style
    from algorithms.mesh import write_mesh
    from algorithms.mesh.operators import mass_matrix, vertex_normals

    params = params_from_args(AnalogyParams, args)
    _check_output(args.output, args.overwrite, args.mesh)
    target_map, what = load_style(args.style, args.style_map)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json or args.quiet)

    def angles(V):
        N = vertex_normals(V, data.F)
        return angles_to_targets(N, target_map(N), mass_matrix(V, data.F, "voronoi").diagonal())

    before = angles(data.V)
    t0 = time.perf_counter()
    last = None
    prog = _progressive_choice(args, len(data.F), "analogy")
    if prog is not None:
        from algorithms.deform.progressive import progressive_analogy_iter

        steps = progressive_analogy_iter(data.V, data.F, target_map, params, prog)
    else:
        steps = ShapeAnalogy(data.V, data.F, target_map).steps(params)
    for last in steps:
        if not args.json and not args.quiet and "mean_angle_to_targets" in last.metrics:
            print(f"  iteration {last.iteration}: mean angle to targets "
                  f"{last.metrics['mean_angle_to_targets']:.2f}°", file=sys.stderr)
    seconds = time.perf_counter() - t0
    write_mesh(args.output, last.V, data.F)
    after = angles(last.V)
    if args.json:
        _print_json({"input": args.mesh, "output": args.output, "style": args.style,
                     "style_map": what, "params": params_to_dict(params),
                     "iterations": last.iteration, "seconds": seconds,
                     "progressive_faces": None if prog is None else prog.target_faces,
                     "progressive_auto": prog is not None and args.progressive_faces is None,
                     "mean_angle_before": before[0], "max_angle_before": before[1],
                     "mean_angle_after": after[0], "max_angle_after": after[1]})
    else:
        print(f"Stylized {args.mesh} after {what} in {seconds:.2f} s ({last.iteration} "
              f"iterations); mean angle to the target normals {before[0]:.1f}° -> "
              f"{after[0]:.1f}°; wrote {args.output}.")
    return 0


OPERATOR_NAMES = {"cotan": "cotangent", "idt": "intrinsic_delaunay", "graph": "graph",
                  "pointcloud": "point_cloud", "aniso": "anisotropic"}


def _parse_operator(text: str) -> tuple[str, float]:
    """'cotan' | 'idt' | 'graph' | 'pointcloud' | 'aniso:ALPHA' -> (operator name, alpha)."""
    name, _, arg = text.partition(":")
    if name not in OPERATOR_NAMES:
        raise ParameterError(f"Unknown operator '{text}': use cotan, idt, aniso:ALPHA, graph or "
                             "pointcloud.")
    alpha = 10.0
    if arg:
        try:
            alpha = float(arg)
        except ValueError:
            raise ParameterError(f"The anisotropy in '{text}' must be a number, e.g. aniso:70.")
    return OPERATOR_NAMES[name], alpha


def _save_npz(path: str, arrays: dict) -> None:
    """Atomic .npz of sparse/dense arrays (sparse as name_data/_indices/_indptr/_shape)."""
    import os
    import tempfile

    import numpy as np
    import scipy.sparse as sp

    flat = {}
    for k, a in arrays.items():
        if sp.issparse(a):
            a = sp.csr_matrix(a)
            flat.update({f"{k}_data": a.data, f"{k}_indices": a.indices, f"{k}_indptr": a.indptr,
                         f"{k}_shape": np.array(a.shape)})
        else:
            flat[k] = np.asarray(a)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **flat)
        os.replace(tmp, path)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise MeshWriteError(f"Could not write {path}: {e.strerror or e}") from None


def cmd_coarsen(args: argparse.Namespace) -> int:
    from algorithms.spectral.coarsen import CoarsenParams
    from algorithms.spectral.compare import compare_coarsenings

    params = params_from_args(CoarsenParams, args)
    operator, alpha = _parse_operator(args.operator)
    methods = ["ours"] + [c for c in (args.compare.split(",") if args.compare else []) if c]
    bad = [c for c in methods if c not in ("ours", "qslim", "amg")]
    if bad:
        raise ParameterError(f"--compare takes qslim and/or amg (got {', '.join(bad)}).")
    if args.output:
        _check_output(args.output, args.overwrite)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=True)
    n = len(data.V)
    if not 2 * (params.k or round(params.m / 3)) < params.m < n:
        raise ParameterError(f"Need 2k < m < n (here n = {n}, m = {params.m}, k = "
                             f"{params.k or round(params.m / 3)}).")
    iterations = {"n": 0}

    def progress(step):
        iterations["n"] = step.iteration
        if not args.json and not args.quiet and step.iteration % 50 == 0:
            print(f"  iteration {step.iteration}: energy {step.energy:.6g}", file=sys.stderr)

    cmp_ = compare_coarsenings(data.V, data.F, operator, m=params.m, k=params.k or None,
                               params=params, methods=tuple(dict.fromkeys(methods)),
                               alpha=alpha, callback=progress)
    out = {"n": cmp_.n, "m": cmp_.m, "k": cmp_.k, "methods": {}}   # a fixed interface
    for name, r in cmp_.methods.items():
        d = {"c_diag_score": r.metrics["c_diag_score"],
             "eig_rel_err_mean": r.metrics["eig_rel_error_mean"],
             "eig_rel_err_max": r.metrics["eig_rel_error_max"], "seconds": r.seconds}
        if name == "ours":
            # the thesis optimizer's (NADAM) iterations, capped by --max-iterations; the
            # balancing stage's come on top (--balance-iterations)
            d["iterations"] = int(cmp_.timings.get("ours_iterations", iterations["n"]))
        out["methods"][name] = d
    if args.output:
        ours = cmp_.methods["ours"]
        _save_npz(args.output, {"L": ours.L, "M": ours.M, "P": ours.P,
                                "G": ours.extra["G"], "K": ours.extra["K"]})
    if args.json:
        _print_json(out)
        for note in cmp_.notes:   # a baseline left out: said on stderr, absent from "methods"
            print(f"Note: {note}", file=sys.stderr)
    else:
        print(cmp_.table())
        for note in cmp_.notes:
            print(f"Note: {note}")
        if args.output:
            print(f"Wrote {args.output}.")
    return 0


# ----------------------------------------------------------------------------- subdivision (ch. 4)
def _neural_or_baseline(method: str, weights: str | None):
    """``fn(V, F, levels) -> (V, F)`` for a subdivision method name."""
    from algorithms.subdivision.baselines import subdivide_baseline

    if method == "neural":
        from algorithms.subdivision.model import load_weights, neural_subdivide

        net, _ = load_weights(None if weights in (None, "shipped") else weights)
        return lambda V, F, levels: neural_subdivide(V, F, levels, net)
    return lambda V, F, levels: subdivide_baseline(V, F, levels, method)


def cmd_subdivide(args: argparse.Namespace) -> int:
    from algorithms.mesh import write_mesh

    if not 1 <= args.levels <= 3:
        raise ParameterError(f"--levels must be 1, 2 or 3 (got {args.levels}).")
    _check_output(args.output, args.overwrite, args.mesh)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json)
    fn = _neural_or_baseline(args.method, args.weights)
    t0 = time.perf_counter()
    V, F = fn(data.V, data.F, args.levels)
    dt = time.perf_counter() - t0
    write_mesh(args.output, V, F)
    out = {"input": args.mesh, "output": args.output, "method": args.method,
           "levels": args.levels, "vertices_in": int(len(data.V)), "faces_in": int(len(data.F)),
           "vertices": int(len(V)), "faces": int(len(F)), "seconds": dt}
    if args.json:
        _print_json(out)
    else:
        print(f"Wrote {args.output}: {args.method} subdivision, {args.levels} level(s), "
              f"{len(data.F):,} -> {len(F):,} triangles in {dt:.2f} s.")
    return 0


def cmd_subdivide_train(args: argparse.Namespace) -> int:
    import numpy as np

    from algorithms.subdivision.data import DataParams, generate_dataset
    from algorithms.subdivision.model import save_weights
    from algorithms.subdivision.train import Trainer, TrainParams

    dparams = params_from_args(DataParams, args)
    tparams = params_from_args(TrainParams, args)
    _check_output(args.output, args.overwrite)
    shapes = [_read_valid(p, clean=args.clean, quiet=args.json)[0] for p in args.meshes]
    quiet = args.json or args.quiet
    t0 = time.perf_counter()
    last = {"pct": -1}

    def progress(frac, msg):
        pct = int(frac * 100)
        if not quiet and pct >= last["pct"] + 10:
            last["pct"] = pct
            print(f"  data: {msg}", file=sys.stderr)

    samples = generate_dataset([(d.V, d.F) for d in shapes], dparams, workers=args.workers,
                               scheduler=args.scheduler, cache_dir=args.cache_dir,
                               use_cache=not args.no_cache, progress=progress)
    t_data = time.perf_counter() - t0
    trainer = Trainer(samples, tparams)
    t1 = time.perf_counter()
    try:
        for step in trainer.steps():
            if not quiet and (step.iteration % 10 == 0 or step.iteration == 1):
                print(f"  {step.message}", file=sys.stderr)
    except KeyboardInterrupt:
        _say("stylize3d subdivide-train: interrupted; saving the best weights so far.")
    t_train = time.perf_counter() - t1
    info = {"trained_on": ", ".join(Path(p).name for p in args.meshes),
            "coarse_meshes": dparams.coarse_meshes, "levels": dparams.levels,
            "epochs_run": len(trainer.history), "best_epoch": trainer.best_epoch,
            "best_validation_loss": float(trainer.best_loss), "targets": dparams.targets}
    save_weights(args.output, trainer.net, info)
    spe = trainer.seconds_per_epoch
    out = {"weights": args.output, "meshes": list(args.meshes),
           "coarse_meshes": len(samples), "epochs": len(trainer.history),
           "best_epoch": trainer.best_epoch, "best_validation_loss": float(trainer.best_loss),
           "final_loss": trainer.history[-1]["loss"] if trainer.history else None,
           "stopped_early": bool(trainer.stopped_early),
           "seconds_data": t_data, "seconds_training": t_train,
           "seconds_per_epoch": float(np.median(spe)) if spe else None}
    if args.json:
        _print_json(out)
    else:
        stopped = (f" (stopped early: no progress in {tparams.patience} epochs)"
                   if trainer.stopped_early else "")
        print(f"Wrote {args.output}: {len(samples)} coarse meshes ({t_data:.0f} s), "
              f"{len(trainer.history)} epochs{stopped} ({t_train:.0f} s); best validation loss "
              f"{trainer.best_loss:.4g} at epoch {trainer.best_epoch}.")
    return 0


def _parse_range(text: str) -> tuple[int, int]:
    try:
        parts = [int(p) for p in str(text).split("-")]
        lo, hi = (parts[0], parts[0]) if len(parts) == 1 else (parts[0], parts[1])
        if len(parts) > 2 or lo < 4 or hi < lo:
            raise ValueError
    except ValueError:
        raise ParameterError(f"--target-vertices takes a range like 350-450 (got {text!r}).") \
            from None
    return lo, hi


def cmd_subdivide_eval(args: argparse.Namespace) -> int:
    import numpy as np

    from algorithms.subdivision.metrics import evaluate_protocol

    lo, hi = _parse_range(args.target_vertices)
    methods = [m for m in args.methods.split(",") if m]
    bad = [m for m in methods if m not in ("neural", "loop", "butterfly", "midpoint")]
    if bad or not methods:
        raise ParameterError(f"--methods takes neural, loop, butterfly, midpoint (got "
                             f"{args.methods!r}).")
    fns = {m: _neural_or_baseline(m, args.weights) for m in methods}
    meshes = []
    for p in args.meshes:
        d, _ = _read_valid(p, clean=args.clean, quiet=args.json)
        meshes.append((Path(p).name, d.V, d.F))

    def progress(frac, msg):
        if not args.json and not args.quiet:
            print(f"  {msg}", file=sys.stderr)

    rows = evaluate_protocol(meshes, fns, target_vertices=(lo, hi), levels=args.levels,
                             samples=args.samples, seed=args.seed, progress=progress)
    keys = ("hausdorff", "mean_distance")
    summary = {m: {k: float(np.mean([r["methods"][m][k] for r in rows])) for k in keys}
               for m in methods}
    out = {"units": "% of the bounding-box diagonal of each original mesh",
           "weights": args.weights, "levels": args.levels, "target_vertices": [lo, hi],
           "methods": summary,
           "meshes": [{"mesh": r["mesh"], "vertices": r["vertices"],
                       "coarse_vertices": r["coarse_vertices"],
                       "methods": {m: {k: r["methods"][m][k] for k in keys} for m in methods}}
                      for r in rows]}
    if "neural" in methods:
        others = [m for m in methods if m in ("loop", "butterfly")]
        out["neural_best_on_both"] = sum(
            all(r["methods"]["neural"][k] < r["methods"][o][k] for k in keys for o in others)
            for r in rows)
    if args.json:
        _print_json(out)
    else:
        head = "mesh".ljust(22) + "".join(f"H_{m}".rjust(12) for m in methods) + \
            "".join(f"M_{m}".rjust(12) for m in methods)
        print(f"Table 4.2 protocol: QSlim to {lo}-{hi} vertices, {args.levels} levels; "
              f"H = Hausdorff, M = mean surface distance, in % of the bounding-box diagonal.")
        print(head)
        for r in rows:
            print(r["mesh"][:21].ljust(22)
                  + "".join(f"{r['methods'][m]['hausdorff']:12.3f}" for m in methods)
                  + "".join(f"{r['methods'][m]['mean_distance']:12.3f}" for m in methods))
        print("mean".ljust(22) + "".join(f"{summary[m]['hausdorff']:12.3f}" for m in methods)
              + "".join(f"{summary[m]['mean_distance']:12.3f}" for m in methods))
    return 0


# ----------------------------------------------------------------------------- parser
def cmd_study(args: argparse.Namespace) -> int:
    """``stylize3d study replay|summary``: user-study logs, headless (no Qt)."""
    if args.study_command == "summary":
        from app.study.summary import summary_csv

        if args.output:
            _check_output(args.output, args.overwrite)
        text, warnings = summary_csv(args.logs, args.output)
        for w in warnings:
            _say(f"stylize3d study summary: {w}")
        if not args.output:
            print(text, end="")
        else:
            n = text.count("\n") - 1
            print(f"Wrote {args.output} ({n} row{'s' if n != 1 else ''}).")
        return 0
    from app.study.replay import replay_or_raise

    report = replay_or_raise(args.log, args.output)
    for w in report.warnings:
        _say(f"stylize3d study replay: {w}")
    c = report.counts
    if args.json:
        _print_json(report.to_dict())
    else:
        for r in report.runs:
            extra = f" ({r.reason})" if r.reason else ""
            if r.max_difference is not None:
                extra += f"; largest vertex difference {r.max_difference:.2e} of the diagonal"
            print(f"run {r.index} [{r.task}] {r.method}: {r.status}{extra}")
        print(f"{c.get('match', 0)} of {len(report.runs)} finished runs reproduced their "
              f"logged result exactly; {c.get('mismatch', 0)} differ; "
              f"{c.get('not replayable', 0)} not replayable; {c.get('failed', 0)} failed.")
    return 0 if not c.get("mismatch") and not c.get("failed") else 1


def _lighting_arg(value: str):
    """``--lighting``: a published environment's name, or a lighting .json file."""
    from algorithms.adversarial.lighting_io import read_lighting
    from algorithms.render.sh import ENVIRONMENTS

    if value in ENVIRONMENTS:
        return value
    if value.lower().endswith(".json") or Path(value).exists():
        return read_lighting(value)
    raise ParameterError(f"Unknown lighting '{value}': use one of {', '.join(ENVIRONMENTS)} or "
                         "a lighting .json file.")


def cmd_adversary(args: argparse.Namespace) -> int:
    """Parametric adversary (thesis ch. 3): perturb the SH lighting or the vertices within an
    L-infinity ball until an image classifier misclassifies the views; random baseline of the
    same norm on the same views."""
    import numpy as np

    from algorithms.adversarial import (AdversaryParams, attack_iter, default_classifier,
                                        evaluate, find_recognized_views, load_classifier,
                                        orbit_cameras, prepare_scene, random_perturbation,
                                        resolve_label, short_name)
    from algorithms.adversarial.lighting_io import write_lighting
    from algorithms.mesh import write_mesh
    from algorithms.render.sh import read_mesh_colors

    t0 = time.perf_counter()
    params = params_from_args(AdversaryParams, args)
    if args.output:
        ext = Path(args.output).suffix.lower()
        if params.mode == "lighting" and ext != ".json":
            raise ParameterError("A lighting attack writes the adversarial lighting as .json; "
                                 f"name the output file *.json (got '{args.output}').")
        if params.mode == "geometry" and ext == ".json":
            raise ParameterError("A geometry attack writes the perturbed mesh; name the output "
                                 "file .obj, .ply, .off or .stl.")
        _check_output(args.output, args.overwrite, args.mesh)
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=args.json)
    colours = read_mesh_colors(args.mesh, len(data.V), len(data.F))
    albedo = args.color if colours is None else colours[1]
    scene = prepare_scene(data.V, data.F, albedo=albedo, lighting=_lighting_arg(args.lighting))
    clf = load_classifier(args.classifier) if args.classifier else default_classifier()
    say = (lambda text: None) if args.json or args.quiet else (
        lambda text: print(text, file=sys.stderr, flush=True))
    width, res, ss = params.view_width, params.resolution, params.supersample
    if args.label:
        k = resolve_label(args.label, clf.class_names)
        found = find_recognized_views(scene, clf, k, candidates=24, elevation=params.elevation,
                                      width=width, resolution=res, supersample=ss)
        if not found:
            raise ParameterError(
                f"The classifier does not see '{short_name(clf.class_names[k])}' in any of 24 "
                "views around the shape (30 degrees up), so there is nothing to attack. Try "
                "another --label, or leave it out to attack whatever it sees.")
        if len(found) < params.views:
            say(f"only {len(found)} of 24 views are recognized; attacking those")
        azimuths = [a for a, _ in found[:params.views]]
        decrease = [k] * len(azimuths)
    else:
        azimuths = list(np.arange(params.views) * 360.0 / params.views)
        decrease = None
    cams = orbit_cameras(azimuths, elevation=params.elevation, width=width, resolution=res * ss)
    out: dict = {}
    for step in attack_iter(scene, clf, cams, params, decrease=decrease, increase=args.target,
                            _out=out):
        say(f"{step.message}; " + "; ".join(f"view {b + 1}: {t[0][0]} {100 * t[0][1]:.0f}%"
                                            for b, t in enumerate(step.top5)))
    result = out["result"]
    # random baseline: same norm, same views
    radius = params.ball()
    x = random_perturbation(scene, params.mode, radius, seed=params.seed)
    top, _ = evaluate(scene, clf, cams, supersample=ss, resolution=res,
                      **({"lighting": x} if params.mode == "lighting" else {"V": x}))
    targets = [None] * len(cams) if args.target is None else (
        [resolve_label(args.target, clf.class_names)] * len(cams))
    before = [resolve_label(v.label_before, clf.class_names) for v in result.views]
    random_success = [bool(top[b] == targets[b]) if targets[b] is not None else
                      bool(top[b] != (decrease[b] if decrease else before[b]))
                      for b in range(len(cams))]
    if args.output:
        if params.mode == "geometry":
            write_mesh(args.output, result.V, data.F)
        else:
            write_lighting(args.output, result.lighting)
    report = {"views": [v.to_dict() for v in result.views],
              "success_rate": result.success_rate,
              "random_success_rate": float(np.mean(random_success)),
              "norm": result.norm, "seconds": time.perf_counter() - t0}
    if args.json:
        _print_json(report)
    else:
        for b, v in enumerate(result.views):
            print(f"view {b + 1} (azimuth {azimuths[b]:.0f}°): {v.label_before} "
                  f"{100 * v.confidence_before:.0f}% -> {v.label_after} "
                  f"{100 * v.confidence_after:.0f}% {'fooled' if v.success else 'not fooled'}")
        print(f"success rate {100 * report['success_rate']:.0f}%, random perturbation of the "
              f"same norm {100 * report['random_success_rate']:.0f}%; L-inf norm "
              f"{result.norm:.4g} after {result.iterations} iterations, "
              f"{report['seconds']:.1f} s")
    return 0


def _add_progressive_arguments(s: argparse.ArgumentParser) -> None:
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES

    s.add_argument("--progressive-faces", type=int, metavar="M",
                   help="affine progressive meshes (thesis Alg. 4): stylize a decimated copy "
                        "with M triangles, then put the details back; for big meshes. On by "
                        f"default (M = 20,000) above {AUTO_PROGRESSIVE_FACES:,} triangles")
    s.add_argument("--no-progressive", action="store_true",
                   help="never use progressive meshes, even for big meshes (slower)")


def build_parser() -> argparse.ArgumentParser:
    from algorithms.smoothing import SmoothParams

    p = argparse.ArgumentParser(
        prog="stylize3d",
        description="Stylize3D: stylize and process 3D surface meshes. With no sub-command, "
                    "opens the app (optionally on MESH).")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("info", help="check a mesh and print its statistics",
                       description="Check a mesh and print its statistics. Exit status 0: every "
                                   "method accepts it as it is; 4: it has errors or needs "
                                   "cleaning first; 2: the file cannot be read.")
    s.add_argument("mesh", help="mesh file (.obj .ply .stl .off)")
    s.add_argument("--json", action="store_true", help="print the report as JSON")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("clean", help="fix what can be fixed in a mesh and say what was done")
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the cleaned mesh")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true")
    s.add_argument("--remove-invalid-faces", action="store_true",
                   help="also delete triangles that use missing vertices or NaN coordinates "
                        "(a damaged file; this opens holes, so it is not done by default)")
    s.set_defaults(func=cmd_clean)

    s = sub.add_parser("smooth", help="implicit Laplacian / mean-curvature smoothing of the shape")
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the smoothed mesh")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true", help="print figures as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-step progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    add_params_arguments(s, SmoothParams)
    d = s.add_argument_group(
        "data smoothing (thesis Eq. 8.6, surface multigrid)",
        "Any of these switches from the flow above to data smoothing: minimize "
        "α E(u) + (1-α) ∫|u - f|² for a signal f; the flow options are then not used.")
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
    s.add_argument("mesh")
    s.add_argument("--json", action="store_true", help="print the report as JSON")
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    s.add_argument("--ratio", type=float, default=0.25,
                   help="triangles kept per level. Default: 0.25.")
    s.add_argument("--min-vertices", type=int, default=500,
                   help="coarsest level keeps at least this many vertices. Default: 500.")
    s.add_argument("--strategy", choices=("midpoint", "qslim"), default="midpoint",
                   help="edge-collapse strategy. Default: midpoint.")
    s.add_argument("--prolongation", choices=("intrinsic", "closest_point"), default="intrinsic",
                   help="intrinsic (self-parameterization, default) or closest_point.")
    s.set_defaults(func=cmd_multigrid_info)

    from algorithms.deform.cubic import CubicParams

    s = sub.add_parser("cubic", help="cubic stylization (thesis ch. 5)")
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the stylized mesh")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help="print iterations, time, final relative displacement and the mean L1 "
                        "norm of the unit normals before and after, as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    s.add_argument("--lambda-xyz", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="per-axis λ factors (turns on per-axis λ): λ_x = λ·X, ...")
    _add_progressive_arguments(s)
    s.add_argument("--global-solver", choices=("direct", "multigrid"), default="direct",
                   help="solver of the global step: direct (prefactored sparse Cholesky/LU) or "
                        "multigrid (surface multigrid V-cycles, warm-started; for very large "
                        "meshes). Default: direct.")
    add_params_arguments(s, CubicParams)
    s.set_defaults(func=cmd_cubic)

    from algorithms.deform.analogies import AnalogyParams
    from algorithms.deform.targets import PRIMITIVES, STYLE_MAP_MODES

    s = sub.add_parser("analogy", help="normal-driven shape analogy (thesis ch. 6)")
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the stylized mesh")
    s.add_argument("--style", default="cube",
                   help=f"a primitive ({', '.join(PRIMITIVES)}), a normal-capture .json file, or "
                        "a style mesh file. Default: cube.")
    s.add_argument("--style-map", choices=STYLE_MAP_MODES, default="auto",
                   help="for a style mesh: closest face normals (convex meshes) or a spherical "
                        "parameterization (any closed genus-0 mesh); auto picks. Default: auto.")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help="print iterations, time, and the mean/max angle to the targets before "
                        "and after, as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    _add_progressive_arguments(s)
    add_params_arguments(s, AnalogyParams)
    s.set_defaults(func=cmd_analogy)

    s = sub.add_parser("study", help="user-study logs: replay a session, summarize sessions")
    ss = s.add_subparsers(dest="study_command", metavar="replay|summary", required=True)
    r = ss.add_parser("replay", help="re-run a session's logged runs headless and check every "
                                     "result hash")
    r.add_argument("log", help="a session log (.jsonl)")
    r.add_argument("-o", "--output", metavar="DIR", help="write each replayed result here (OBJ)")
    r.add_argument("--json", action="store_true", help="print the report as JSON")
    r = ss.add_parser("summary", help="one CSV row per participant and task")
    r.add_argument("logs", nargs="+", help="session logs (.jsonl)")
    r.add_argument("-o", "--output", metavar="CSV", help="write the CSV here (default: print it)")
    r.add_argument("--overwrite", action="store_true", help="replace CSV if it exists")
    s.set_defaults(func=cmd_study)

    from algorithms.spectral.coarsen import CoarsenParams

    s = sub.add_parser("coarsen", help="spectral coarsening of a mesh operator (thesis ch. 7)")
    s.add_argument("mesh")
    s.add_argument("--operator", default="cotan",
                   help="cotan, idt (intrinsic Delaunay), aniso:ALPHA (anisotropic), graph or "
                        "pointcloud. Default: cotan.")
    s.add_argument("--compare", default="",
                   help="baselines to measure the same way: qslim,amg")
    s.add_argument("-o", "--output", help="write ours (L, M, P, G, K) as .npz")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"n", "m", "k", "methods": {name: {"c_diag_score", '
                        '"eig_rel_err_mean", "eig_rel_err_max", "seconds"}}}')
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    add_params_arguments(s, CoarsenParams)
    s.set_defaults(func=cmd_coarsen)
    _add_paparazzi_parser(sub)

    from algorithms.adversarial import AdversaryParams
    from algorithms.render.sh import ENVIRONMENTS

    s = sub.add_parser("adversary",
                       help="adversarial lighting or geometry that fools an image classifier "
                            "(thesis ch. 3)")
    s.add_argument("mesh")
    s.add_argument("--target", metavar="LABEL",
                   help="make the classifier see this class (default: any wrong class)")
    s.add_argument("--label", metavar="LABEL",
                   help="the true class: views are chosen among those the classifier gets "
                        "right (default: whatever it sees in evenly spaced views)")
    s.add_argument("--classifier", metavar="FILE",
                   help="a TorchScript model or EfficientNet-lite0 weights (default: the "
                        "installed ImageNet EfficientNet-lite0)")
    s.add_argument("--lighting", default="Grace Cathedral", metavar="NAME|FILE.json",
                   help="the starting lighting: an environment of Ramamoorthi & Hanrahan 2001 ("
                        + ", ".join(ENVIRONMENTS) + ") or a lighting .json file (written by "
                        "-o of a lighting attack or saved by the app's panel). "
                        "Default: Grace Cathedral.")
    s.add_argument("--color", type=float, nargs=3, default=(0.7, 0.7, 0.7), metavar=("R", "G", "B"),
                   help="surface colour when the mesh file has none. Default: 0.7 0.7 0.7.")
    s.add_argument("-o", "--output",
                   help="write the perturbed mesh (geometry) or the lighting (.json)")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"views": [{"label_before", "confidence_before", "label_after", '
                        '"confidence_after", "success"}], "success_rate", '
                        '"random_success_rate", "norm", "seconds"}')
    s.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    add_params_arguments(s, AdversaryParams)
    s.set_defaults(func=cmd_adversary)

    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.train import TrainParams

    s = sub.add_parser("subdivide", help="subdivide a mesh: neural (thesis ch. 4), Loop, "
                                         "modified butterfly or mid-point")
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the subdivided mesh")
    s.add_argument("--levels", type=int, default=2, help="1 to 3 levels. Default: 2.")
    s.add_argument("--method", choices=("neural", "loop", "butterfly", "midpoint"),
                   default="neural", help="Default: neural (with the shipped weights).")
    s.add_argument("--weights", help="a weights file from subdivide-train (default: shipped)")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"method", "levels", "vertices", "faces", "seconds", ...}')
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    s.set_defaults(func=cmd_subdivide)

    s = sub.add_parser("subdivide-train", help="train neural subdivision on one or more meshes "
                                               "(thesis §4.4, App. 4.8.5-4.8.6)")
    s.add_argument("meshes", nargs="+", metavar="MESH")
    s.add_argument("-o", "--output", required=True, help="where to write the weights (.pt)")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="a Dask distributed scheduler (tcp://host:8786) to generate the data on "
                        "(its workers need Stylize3D installed); default: local processes")
    s.add_argument("--workers", type=int, default=2,
                   help="local processes for data generation (1: in this process). Default: 2.")
    s.add_argument("--cache-dir", help="where generated data is cached (default: "
                                       "$STYLIZE3D_CACHE/subdivision or ~/.cache/stylize3d)")
    s.add_argument("--no-cache", action="store_true", help="neither read nor write the cache")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"weights", "coarse_meshes", "epochs", "best_epoch", '
                        '"best_validation_loss", "seconds_data", "seconds_training", ...}')
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true", help="clean the meshes first")
    add_params_arguments(s, DataParams)
    add_params_arguments(s, TrainParams)
    s.set_defaults(func=cmd_subdivide_train)

    s = sub.add_parser("subdivide-eval", help="the Table 4.2 protocol: QSlim each mesh to "
                                              "350-450 vertices, subdivide, measure H and M")
    s.add_argument("weights", help="a weights file ('shipped' for the shipped weights)")
    s.add_argument("meshes", nargs="+", metavar="MESH")
    s.add_argument("--target-vertices", default="350-450",
                   help="coarse vertex range. Default: 350-450.")
    s.add_argument("--levels", type=int, default=2, help="Default: 2.")
    s.add_argument("--methods", default="neural,loop,butterfly",
                   help="comma-separated: neural, loop, butterfly, midpoint. "
                        "Default: neural,loop,butterfly.")
    s.add_argument("--samples", type=int, default=200_000,
                   help="area-uniform samples per surface (plus the vertices). Default: 200000.")
    s.add_argument("--seed", type=int, default=0, help="seed of the targets and samples")
    s.add_argument("--json", action="store_true",
                   help='print {"methods": {name: {"hausdorff", "mean_distance"}}, "meshes": '
                        '[...]} (%% of the bounding-box diagonal)')
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true", help="clean the meshes first")
    s.set_defaults(func=cmd_subdivide_eval)
    return p



# ----------------------------------------------------------------------------- paparazzi
SUBCOMMANDS = SUBCOMMANDS + ("paparazzi",)


def _paparazzi_filter_flags() -> list[tuple[str, str, object]]:
    """(filter name, flag, ParamSpec) for every registered filter's parameters; a field name
    used by two filters (or by PaparazziParams) gets the filter's name as a prefix."""
    from algorithms.paparazzi import filter_names, get_filter
    from algorithms.paparazzi.optimize import PaparazziParams

    taken = {spec.flag for spec in describe(PaparazziParams)}
    counts: dict[str, int] = {}
    for name in filter_names():
        for spec in describe(get_filter(name).params):
            counts[spec.flag] = counts.get(spec.flag, 0) + 1
    out = []
    for name in filter_names():
        for spec in describe(get_filter(name).params):
            flag = spec.flag
            if flag in taken or counts[flag] > 1:
                flag = f"--{name}-{spec.name.replace('_', '-')}"
            out.append((name, flag, spec))
    return out


_PAPARAZZI_PLUGIN_HELP = (
    "a Python file that registers image filters with "
    "algorithms.paparazzi.register_filter (see the algorithms.paparazzi.filters documentation); "
    "it is imported before the other flags are read, so its filters become --filter choices and "
    "their Params fields become flags (shown by --help after --plugin). Repeatable. A file that "
    "is missing, fails to import or registers nothing stops the command with a message; nothing "
    "is written.")


class _PaparazziParser(argparse.ArgumentParser):
    """The ``paparazzi`` sub-parser: before parsing, it imports the ``--plugin`` files found among
    its arguments and adds their filters' flags (argparse classifies every flag before it runs
    any action, so a plugin's flags must exist before parsing starts)."""

    def parse_known_args(self, args=None, namespace=None):
        args = list(sys.argv[1:] if args is None else args)
        files = []
        for i, a in enumerate(args):
            if a == "--":
                break
            if a == "--plugin" and i + 1 < len(args):
                files.append(args[i + 1])
            elif a.startswith("--plugin="):
                files.append(a.split("=", 1)[1])
        if files:
            from algorithms.paparazzi.filters import load_filter_plugin

            try:
                for f in files:
                    load_filter_plugin(f)
            except Stylize3DError as e:
                self.exit(e.exit_code, f"stylize3d paparazzi: {e}\n")
            _add_paparazzi_filter_flags(self)
        return super().parse_known_args(args, namespace)


def _add_paparazzi_filter_flags(s: argparse.ArgumentParser) -> None:
    """Add the flags of every registered filter that ``s`` does not have yet (all of them when
    the parser is built, a plugin's when ``--plugin`` loaded one) and refresh ``--filter``."""
    from algorithms.paparazzi import filter_names, get_filter

    group = getattr(s, "_pz_group", None)
    if group is None:
        group = s._pz_group = s.add_argument_group(
            "filter parameters (only those of the chosen --filter are used)")
    have = {a.dest for a in s._actions}
    flags = set(s._option_string_actions)
    for name, flag, spec in _paparazzi_filter_flags():
        dest = f"pz_{name}_{spec.name}".replace("-", "_")
        if dest in have:
            continue
        if flag in flags:                  # a plugin's field clashing with a flag already there
            flag = f"--{name}-{spec.name.replace('_', '-')}"
        help_text = f"[{name}] {spec.tooltip} Default: {spec.default}.".replace("%", "%%")
        if spec.type is bool:
            group.add_argument(flag, dest=dest, action=argparse.BooleanOptionalAction,
                               default=spec.default, help=help_text)
        else:
            group.add_argument(flag, dest=dest, type=spec.type, default=spec.default,
                               choices=spec.choices, metavar=spec.name.upper(), help=help_text)
    for action in s._actions:
        if action.dest == "filter":
            action.choices = filter_names()
            action.help = "the image filter: " + "; ".join(
                f"{n}: {get_filter(n).description or 'a user filter'}"
                for n in filter_names()).replace("%", "%%")


def _add_paparazzi_parser(sub) -> None:
    from algorithms.paparazzi.optimize import PaparazziParams

    s = sub.add_parser("paparazzi", help="Paparazzi: image filters applied to a shape through "
                                         "many rendered views (thesis ch. 2)")
    s.__class__ = _PaparazziParser     # same state, plus the --plugin pre-pass above
    s.add_argument("mesh")
    s.add_argument("-o", "--output", required=True, help="where to write the filtered mesh")
    s.add_argument("--filter", required=True, help="the image filter")
    s.add_argument("--plugin", action="append", default=[], metavar="FILE.py",
                   help=_PAPARAZZI_PLUGIN_HELP)
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help="print iterations, seconds (render / filter / derivative / remesh), the "
                        "monitor-view energy before and after, and the manifold / "
                        "self-intersection checks of the output, as JSON")
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    add_params_arguments(s, PaparazziParams)
    _add_paparazzi_filter_flags(s)
    s.set_defaults(func=cmd_paparazzi)


def cmd_paparazzi(args: argparse.Namespace) -> int:
    from algorithms.mesh import write_mesh
    from algorithms.mesh.topology import euler_characteristic, is_manifold
    from algorithms.paparazzi import Paparazzi, count_self_intersections, get_filter
    from algorithms.paparazzi.optimize import PaparazziParams

    params = params_from_args(PaparazziParams, args)
    spec = get_filter(args.filter)
    values = {ps.name: getattr(args, f"pz_{spec.name}_{ps.name}".replace("-", "_"))
              for ps in describe(spec.params)}
    fparams = params_from_dict(spec.params, values)
    _check_output(args.output, args.overwrite, args.mesh)
    quiet = args.json or args.quiet
    data, _ = _read_valid(args.mesh, clean=args.clean, quiet=quiet)
    t0 = time.perf_counter()
    run = Paparazzi(data.V, data.F, spec, fparams, params)
    setup = time.perf_counter() - t0
    last = None
    report_every = max(1, params.iterations // 10)
    for last in run.steps():
        if not quiet and (last.iteration % report_every == 0 or last.message):
            print(f"  iteration {last.iteration}/{params.iterations}: monitor energy "
                  f"{last.metrics['monitor_energy']:.6g} {last.message}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    V, F = last.V, last.F
    manifold = bool(is_manifold(F))
    same_topology = euler_characteristic(F) == euler_characteristic(data.F)
    crossings = count_self_intersections(V, F)
    new_crossings = run.new_self_intersections(V, F) if crossings else 0
    if not manifold or not same_topology or new_crossings:
        raise Stylize3DError("Paparazzi failed: the result is not a clean 2-manifold with the "
                             "input's topology; nothing was written. Try a smaller learning rate.")
    write_mesh(args.output, V, F)
    sec = last.seconds
    it = last.iteration
    if args.json:
        _print_json({
            "input": args.mesh, "output": args.output, "filter": spec.name,
            "filter_params": params_to_dict(fparams), "params": params_to_dict(params),
            "iterations": it, "seconds": seconds, "setup_seconds": setup,
            "seconds_split": {k: sec.get(k, 0.0) for k in
                              ("render", "filter", "derivative", "remesh", "monitor")},
            "seconds_per_iteration": {k: sec.get(k, 0.0) / it for k in
                                      ("render", "filter", "derivative", "remesh")},
            "initial_monitor_energy": last.metrics["initial_monitor_energy"],
            "final_monitor_energy": last.metrics["monitor_energy"],
            "vertices": int(len(V)), "faces": int(len(F)),
            "manifold": manifold, "same_topology": bool(same_topology),
            "self_intersecting_pairs": crossings,
            "input_self_intersecting_pairs": run.input_intersections,
            "new_self_intersecting_pairs": new_crossings,
            "self_intersections": crossings > 0,
            "remeshes": int(last.metrics["remeshes"]),
            "rollbacks": int(last.metrics["rollbacks"]),
            **{k: int(last.metrics.get(k, 0))
               for k in ("remesh_rejected", "remesh_retries", "held_vertices")}})
    else:
        print(f"Paparazzi '{spec.name}' on {args.mesh}: {it} iterations in {seconds:.1f} s; "
              f"monitor energy {last.metrics['initial_monitor_energy']:.4g} -> "
              f"{last.metrics['monitor_energy']:.4g}; {len(V)} vertices; wrote {args.output}.")
    return 0


def main(argv: list[str]) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse already printed a usage message
        return int(e.code or 0)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    try:
        code = int(args.func(args))
        sys.stdout.flush()  # a closed pipe (`stylize3d info MESH | head`) shows up here
        return code
    except Stylize3DError as e:
        _say(f"stylize3d {args.command}: {e}")
        return e.exit_code
    except KeyboardInterrupt:
        _say("stylize3d: interrupted; nothing was written.")
        return 130
    except BrokenPipeError:
        # the reader of our output went away (e.g. `| head`): not an error of ours, and Python
        # must not print a second traceback when it flushes stdout at exit
        _silence_stdout()
        return 0
    except MemoryError:
        _say(f"stylize3d {args.command}: this machine ran out of memory; nothing was written. "
             "Try a smaller mesh (decimate it first) or the options for big meshes "
             "(e.g. --progressive-faces for cubic, --solver multigrid for smooth).")
        return INTERNAL_ERROR_EXIT
    except Exception as e:  # a defect of ours: say so plainly, never a bare traceback
        import traceback

        log = _write_crash_log(traceback.format_exc())
        _say(f"stylize3d {args.command}: an unexpected error stopped the command "
             f"({type(e).__name__}: {e}); nothing was written. This is a bug in Stylize3D"
             + (f"; the details are in {log}." if log else "."))
        return INTERNAL_ERROR_EXIT


#: exit status of an unexpected failure (a defect, or the machine ran out of memory)
INTERNAL_ERROR_EXIT = 70


def _say(text: str) -> None:
    """Print a message to stderr; a closed stderr is not worth a traceback."""
    try:
        print(text, file=sys.stderr)
        sys.stderr.flush()
    except (BrokenPipeError, OSError, ValueError):
        pass


def _silence_stdout() -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _write_crash_log(text: str) -> str | None:
    """Keep a traceback for the bug report in a temporary file (never on the user's screen)."""
    import tempfile

    try:
        fd, path = tempfile.mkstemp(prefix="stylize3d-crash-", suffix=".txt")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        return path
    except OSError:
        return None


# ----------------------------------------------------------------------------- GUI
def gui_main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="stylize3d", description="Open the Stylize3D app.",
                                epilog="Batch sub-commands: " + ", ".join(SUBCOMMANDS)
                                + " (stylize3d COMMAND --help).")
    p.add_argument("mesh", nargs="?", help="mesh file to open")
    p.add_argument("--screenshot", metavar="PNG",
                   help="save a screenshot of the window once the mesh is shown, then quit")
    g = p.add_argument_group("user-study mode")
    g.add_argument("--study", metavar="PROTOCOL",
                   help="run a study session from a protocol file (.json or .toml)")
    g.add_argument("--participant", metavar="CODE",
                   help="participant code (otherwise the start dialog asks)")
    g.add_argument("--condition", metavar="NAME",
                   help="study condition (otherwise the start dialog asks)")
    g.add_argument("--log-dir", metavar="DIR",
                   help="where session logs and results go (default: logs/ next to the protocol)")
    args = p.parse_args(argv)
    study = None
    if args.study:
        from app.study.protocol import load_protocol

        try:  # a malformed protocol is a plain message before any window opens
            load_protocol(args.study)
        except Stylize3DError as e:
            _say(f"stylize3d: {e}")
            return e.exit_code
        study = {"protocol": args.study, "participant": args.participant,
                 "condition": args.condition, "log_dir": args.log_dir}
    from app.gui import run_app  # Qt is imported only here

    if study is None:
        return run_app(args.mesh, screenshot=args.screenshot)
    return run_app(args.mesh, screenshot=args.screenshot, study=study)
