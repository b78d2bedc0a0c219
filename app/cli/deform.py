"""``stylize3d cubic`` (the Cubic recipe, thesis ch. 5); the analogy command is in
:mod:`app.cli.analogy` and shares this module's progressive-meshes choice and flags.

``cubic`` is a thin wrapper around the recipe :mod:`app.recipes.cubic`: on a project
(``scene.s3d``) it uses the painted λ scale, fixed region, plane, cube frames and point handles,
and the Cubic panel's saved settings and options (plane axis, progressive meshes, multigrid), so
it gives the same vertices as ``app.recipes.run("cubic", project)``. Flags given on the command
line win (``--progressive-faces`` / ``--no-progressive`` / ``--global-solver`` over the saved
options). On a plain mesh (or a project without saved Cubic settings) meshes above
``AUTO_PROGRESSIVE_FACES`` triangles go through affine progressive meshes, as in the app.
"""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from algorithms.errors import ParameterError, Stylize3DError
from algorithms.params import params_from_dict
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_params, method_recipe,
                            params_to_dict, print_json, read_input, saved_panel, say)

COMMANDS = ("cubic",)


def _progressive_choice(args: argparse.Namespace, n_faces: int, command: str, *,
                        auto_ok: bool = True):
    """``(ProgressiveParams or None, reason)``: whether the command runs through affine
    progressive meshes, and why (a sentence for the output).

    ``--progressive-faces M`` asks for it, ``--no-progressive`` refuses it; otherwise the
    measured rule :func:`algorithms.deform.progressive.choose_progressive` decides (as in the
    app), and an automatic switch to progressive meshes is said on stderr.
    """
    from algorithms.deform.progressive import ProgressiveParams, choose_progressive

    if args.progressive_faces is not None and args.no_progressive:
        raise ParameterError("--progressive-faces and --no-progressive contradict each other; "
                             "choose one.")
    coarse_only = getattr(args, "coarse_only", False)
    if coarse_only and args.no_progressive:
        raise ParameterError("--coarse-only stylizes a coarse copy (progressive meshes) and "
                             "--no-progressive refuses one; choose one.")
    if coarse_only and not auto_ok:
        raise ParameterError("--coarse-only works on a coarse copy and the multigrid global "
                             "solver on every triangle; choose one.")
    faces = args.progressive_faces
    if faces is not None:
        reason = f"--progressive-faces {faces} asked for a {faces:,}-triangle copy"
    elif args.no_progressive:
        return None, "--no-progressive asked to work on every triangle"
    elif not auto_ok:
        return None, "the multigrid global solver works on every triangle"
    elif coarse_only:
        faces = min(ProgressiveParams().target_faces, n_faces // 2)
        reason = f"--coarse-only asked for a {faces:,}-triangle copy alone"
    else:
        faces = min(ProgressiveParams().target_faces, n_faces // 2)
        use, reason = choose_progressive(n_faces, faces)
        if not use:
            return None, reason
        if not args.quiet:
            say(f"stylize3d {command}: {reason}. Pass --no-progressive to work on every "
                f"triangle from the start, --coarse-only for the copy alone (faster, less "
                f"cubic), or --progressive-faces M to choose the copy's size.")
    return params_from_dict(ProgressiveParams, {"target_faces": faces, "preview_every": 0,
                                                "finish": not coarse_only}), reason


def cubic_options(args: argparse.Namespace, n_faces: int) -> tuple[dict, bool, str]:
    """The Cubic recipe's options for this run, whether progressive meshes were chosen
    automatically, and why the run works on a coarse copy or on every triangle: the project's
    saved options (if any) < the flags given here; without saved options, the measured
    automatic choice for big meshes."""
    from algorithms.deform.progressive import ProgressiveParams

    if args.coarse_only and args.global_solver == "multigrid":
        raise ParameterError("--coarse-only works on a coarse copy and the multigrid global "
                             "solver on every triangle; choose one.")
    if args.progressive_faces is not None and args.global_solver == "multigrid":
        raise ParameterError("--progressive-faces and --global-solver multigrid are two ways to "
                             "handle big meshes; choose one.")
    if args.progressive_faces is not None and args.no_progressive:
        raise ParameterError("--progressive-faces and --no-progressive contradict each other; "
                             "choose one.")
    saved = saved_panel(args, "Cubic")
    if saved is None:
        prog, reason = _progressive_choice(args, n_faces, "cubic",
                                           auto_ok=args.global_solver != "multigrid")
        options = {"plane_axis": 0, "progressive": None if prog is None else params_to_dict(prog),
                   "multigrid": args.global_solver == "multigrid" and prog is None}
        return options, prog is not None and args.progressive_faces is None, reason
    options = {"plane_axis": 0, "progressive": None, "multigrid": False, **saved["options"]}
    reason = "the project's saved Cubic options"
    if args.progressive_faces is not None or args.coarse_only:
        if args.coarse_only and args.no_progressive:
            raise ParameterError("--coarse-only stylizes a coarse copy (progressive meshes) "
                                 "and --no-progressive refuses one; choose one.")
        saved_prog = options.get("progressive")
        base = saved_prog or params_to_dict(ProgressiveParams())
        faces = (args.progressive_faces if args.progressive_faces is not None
                 else int(base["target_faces"]) if saved_prog
                 else min(int(base["target_faces"]), n_faces // 2))
        options["progressive"] = {**base, "target_faces": faces}
        if args.coarse_only:
            options["progressive"]["finish"] = False
        options["multigrid"] = False
        reason = (f"--progressive-faces {faces} asked for a {faces:,}-triangle copy"
                  if args.progressive_faces is not None
                  else f"--coarse-only asked for the {faces:,}-triangle copy alone")
    elif args.no_progressive:
        options["progressive"] = None
        reason = "--no-progressive asked to work on every triangle"
    if args.global_solver is not None:
        options["multigrid"] = args.global_solver == "multigrid"
        if options["multigrid"]:
            options["progressive"] = None
            reason = "the multigrid global solver works on every triangle"
    if options.get("progressive") is not None:  # no previews on the command line
        options["progressive"] = {**options["progressive"], "preview_every": 0}
    return options, False, reason


def lambda_values(args: argparse.Namespace) -> list[float] | None:
    """The λ values given with ``--lambda`` (one or several), or None when none was given."""
    lam = getattr(args, "lam", None)
    if lam is None:
        return None
    return [float(x) for x in (lam if isinstance(lam, (list, tuple)) else [lam])]


def cubic_params(args: argparse.Namespace, lam: float | None = None):
    """The CubicParams of ``cubic``'s flags: defaults < a project's saved Cubic settings <
    ``--params`` < the flags (``--lambda-xyz`` turns per-axis λ on). ``lam``: one of several
    ``--lambda`` values (default: the first given)."""
    from algorithms.deform.cubic import CubicParams

    lams = lambda_values(args)
    if lams is not None:
        args = argparse.Namespace(**{**vars(args), "lam": lams[0] if lam is None else lam})
    params = method_params(args, CubicParams, panel="Cubic")
    if args.lambda_xyz is not None:
        x, y, z = args.lambda_xyz
        params = params_from_dict(CubicParams, {**params_to_dict(params), "per_axis": True,
                                                "axis_factor_x": x, "axis_factor_y": y,
                                                "axis_factor_z": z})
    return params


def cubic_job(args: argparse.Namespace, n_faces: int) -> tuple:
    """``(params, options)`` of the Cubic recipe that ``cubic`` would run on a mesh of
    ``n_faces`` triangles (``stylize3d batch`` builds its job with it)."""
    lams = lambda_values(args)
    if lams is not None and len(lams) > 1:
        raise ParameterError("A batch job runs one λ; give --lambda a single value (run the "
                             "batch once per λ, or use stylize3d cubic with several values).")
    return cubic_params(args), cubic_options(args, n_faces)[0]


def output_for_lambda(output: str, lam: float, several: bool) -> str:
    """The output path of one λ: OUTPUT itself for a single λ; with several, ``{lam}`` in OUTPUT
    replaced by the value, else ``_lambdaVALUE`` inserted before the extension."""
    if not several:
        return output
    text = f"{lam:g}"
    if "{lam}" in output:
        return output.replace("{lam}", text)
    p = Path(output)
    return str(p.with_name(f"{p.stem}_lambda{text}{p.suffix}"))


def crossings_sentence_of(crossings: dict | None) -> str:
    """The sentence of :func:`algorithms.deform.collisions.crossings_sentence` for the report
    ``crossings`` (from :func:`~algorithms.deform.collisions.crossings_of`)."""
    from algorithms.deform.collisions import crossings_sentence, metrics_of

    return crossings_sentence(metrics_of(crossings)) if crossings is not None else ""


def cmd_cubic(args: argparse.Namespace) -> int:
    from algorithms.deform.collisions import crossings_of
    from algorithms.deform.cubic import mean_l1_of_normals
    from app.cli.attributes import write_result

    lams = lambda_values(args)
    several = lams is not None and len(lams) > 1
    if several and len(set(lams)) != len(lams):
        raise ParameterError("--lambda: the same value is given twice.")
    runs = [(None if lams is None else lam, cubic_params(args, lam))
            for lam in (lams if lams is not None else [None])]
    outputs = [output_for_lambda(args.output, p.lam, several) for _, p in runs]
    if len(set(outputs)) != len(outputs):
        raise ParameterError("--lambda: two values would write the same file "
                             f"({', '.join(outputs)}); give values that differ in 6 digits.")
    for out in outputs:
        check_output(out, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    state = input_state(args, data)
    l1_before = mean_l1_of_normals(data.V, data.F)
    options, auto, reason = cubic_options(args, len(data.F))
    prog = options.get("progressive")
    recipe = method_recipe("cubic", "Cubic")
    cache: dict = {}  # one solver (factorizations, progressive mesh) for every λ
    results = []
    preprocess = None
    for (_, params), output in zip(runs, outputs):
        t0 = time.perf_counter()
        last = None
        for last in recipe.steps(state, params, options, cache):
            if "energy" in last.metrics and not args.json and not args.quiet:
                print(f"  iteration {last.iteration}: energy {last.metrics['energy']:.6g}, "
                      f"relative move {last.metrics.get('displacement', 0):.2e}",
                      file=sys.stderr)
        seconds = time.perf_counter() - t0
        timings = getattr(cache.get("solver"), "timings", None)
        if preprocess is None and timings is not None:
            preprocess = float(timings.get("total", 0.0))
            online = max(seconds - preprocess, 0.0)
        else:
            online = seconds
        V = recipe.result(state, last, options).V
        write_result(args, output, V, data.F, data)
        from app.recipes.cubic import change_note

        results.append({"lam": params.lam, "output": output, "params": params,
                        "note": change_note(data.V, V, data.F, params.lam, flags=True),
                        "iterations": last.iteration, "seconds": seconds,
                        "online_seconds": online,
                        "final_relative_displacement": last.metrics.get("displacement"),
                        "l1_normals_after": mean_l1_of_normals(V, data.F),
                        "crossings": crossings_of(last.metrics)})
    finished, not_finished = False, ""
    if prog is not None:
        from algorithms.deform.progressive import ProgressiveParams
        from app.recipes.cubic import finish_of

        finished, not_finished = finish_of(
            params_from_dict(ProgressiveParams, {"finish": False, **prog}), len(data.F))
    common = {"input": args.mesh,
              "progressive_faces": None if prog is None else int(prog["target_faces"]),
              "progressive_finish": None if prog is None else finished,
              "progressive_not_finished": not_finished or None,
              "progressive_auto": auto, "progressive_reason": reason,
              "preprocess_seconds": preprocess, "l1_normals_before": l1_before}
    if args.json:
        if not several:
            r = results[0]
            print_json({"input": args.mesh, "output": r["output"],
                        "params": params_to_dict(r["params"]), "iterations": r["iterations"],
                        "seconds": r["seconds"], "online_seconds": r["online_seconds"],
                        "final_relative_displacement": r["final_relative_displacement"],
                        **{k: v for k, v in common.items() if k != "input"},
                        "l1_normals_after": r["l1_normals_after"], "crossings": r["crossings"],
                        **({"note": r["note"]} if r["note"] else {})})
        else:
            print_json({**common, "runs": [
                {"lambda": r["lam"], "output": r["output"], "params": params_to_dict(r["params"]),
                 "iterations": r["iterations"], "seconds": r["seconds"],
                 "online_seconds": r["online_seconds"],
                 "final_relative_displacement": r["final_relative_displacement"],
                 "l1_normals_after": r["l1_normals_after"], "crossings": r["crossings"],
                 **({"note": r["note"]} if r["note"] else {})}
                for r in results]})
    else:
        how = ("on every triangle" if prog is None else
               f"through a {int(prog['target_faces']):,}-triangle copy, then on every triangle "
               f"from its result" if finished else
               f"through a {int(prog['target_faces']):,}-triangle copy alone (the details put "
               f"back, not finished on every triangle: less cubic than working on every "
               f"triangle)")
        for r in results:
            print(f"Stylized {args.mesh} (λ {r['lam']:g}) in {r['seconds']:.2f} s "
                  f"({r['iterations']} iterations); mean L1 norm of normals {l1_before:.4f} -> "
                  f"{r['l1_normals_after']:.4f}; wrote {r['output']}.")
            said = " ".join(x for x in (crossings_sentence_of(r["crossings"]), r["note"]) if x)
            if said:
                print(said)
        pre = "" if preprocess is None else f" (pre-processing {preprocess:.1f} s, once)"
        print(f"Worked {how}{pre}: {reason}" + (f"; {not_finished}." if not_finished else "."))
    return 0


@contextmanager
def user_paths(named: dict[str, str]):
    """Errors raised inside name the user's files, not the copies of their blobs that the
    recipe reads (``named``: blob reference -> the path given on the command line)."""
    try:
        yield
    except Stylize3DError as e:
        from app.recipes import blob_path

        text = str(e)
        for ref, path in named.items():
            text = text.replace(str(blob_path(ref)), path)
        if text != str(e):
            e.args = (text,)
        raise


def _add_progressive_arguments(s: argparse.ArgumentParser) -> None:
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES

    s.add_argument("--progressive-faces", type=int, metavar="M",
                   help="affine progressive meshes (thesis Alg. 4): stylize a decimated copy "
                        "with M triangles, put the details back, then finish on every "
                        "triangle from there; for big meshes. On by default (M = 20,000) "
                        f"above {AUTO_PROGRESSIVE_FACES:,} triangles, where its energy was "
                        "within 1 %% of working on every triangle from the start or lower "
                        "(lower on 14 of 20 runs measured), in fewer iterations")
    s.add_argument("--no-progressive", action="store_true",
                   help="never use progressive meshes: work on every triangle from the start")
    s.add_argument("--coarse-only", action="store_true",
                   help="progressive meshes without the finish: stylize the copy and put the "
                        "details back only (about a second per λ on a million triangles, for "
                        "trying λ; on scans it came out 0.4-1.3x as cubic as working on "
                        "every triangle from the start, and less than finished)")


def add_parsers(sub) -> None:
    from algorithms.deform.cubic import CubicParams

    s = sub.add_parser("cubic", help="cubic stylization (thesis ch. 5)",
                       description="Cubic stylization (thesis ch. 5). On a project (.s3d) it "
                                   "uses what was painted and placed (λ scale, fixed region, "
                                   "plane, cube frames, point handles) and the Cubic panel's "
                                   "saved settings; flags given here win.")
    s.add_argument("mesh", help=MESH_HELP)
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
    s.add_argument("--global-solver", choices=("direct", "multigrid"),
                   help="solver of the global step: direct (prefactored sparse Cholesky/LU) or "
                        "multigrid (surface multigrid V-cycles, warm-started; for very large "
                        "meshes). Default: direct (or the project's saved choice).")
    add_params_file_argument(s)
    add_params_arguments(s, CubicParams)
    for action in s._actions:  # several λ in one run: the pre-processing is shared
        if action.dest == "lam":
            action.nargs = "+"
            action.help = (action.help + " Several values: one output per value (OUTPUT "
                           "gets _lambdaVALUE before its extension, or put {lam} in it); "
                           "factorizations and progressive meshes are built once.")
    s.set_defaults(func=cmd_cubic)

