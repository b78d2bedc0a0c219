"""``stylize3d cubic`` (the Cubic recipe, thesis ch. 5) and ``stylize3d analogy`` (the Analogies
recipe: normal-driven shape analogies, thesis ch. 6).

``cubic`` is a thin wrapper around the recipe :mod:`app.recipes.cubic`: on a project
(``scene.s3d``) it uses the painted λ scale, fixed region, plane, cube frames and point handles,
and the Cubic panel's saved settings and options (plane axis, progressive meshes, multigrid), so
it gives the same vertices as ``app.recipes.run("cubic", project)``. Flags given on the command
line win (``--progressive-faces`` / ``--no-progressive`` / ``--global-solver`` over the saved
options). On a plain mesh (or a project without saved Cubic settings) meshes above
``AUTO_PROGRESSIVE_FACES`` triangles go through affine progressive meshes, as in the app.

``analogy`` is a thin wrapper around the recipe :mod:`app.recipes.analogies`: its options are
the style (a primitive, a style file given here, stored as a blob, or on a project the saved
style: a primitive, a style file or the painted capture sphere), the style map and progressive
meshes; defaults < the Analogies panel's saved options < ``--style`` / ``--style-map`` /
``--progressive-faces`` / ``--no-progressive``. The panel has no progressive switch: unless the
saved options hold one, big meshes go through progressive meshes as on a plain mesh. Without
that (or below the size), the output is ``app.recipes.run("analogy", project)`` bit for bit.
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

COMMANDS = ("cubic", "analogy")


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
    faces = args.progressive_faces
    if faces is not None:
        reason = f"--progressive-faces {faces} asked for a {faces:,}-triangle copy"
    elif args.no_progressive:
        return None, "--no-progressive asked to work on every triangle"
    elif not auto_ok:
        return None, "the multigrid global solver works on every triangle"
    else:
        faces = min(ProgressiveParams().target_faces, n_faces // 2)
        use, reason = choose_progressive(n_faces, faces)
        if not use:
            return None, reason
        if not args.quiet:
            say(f"stylize3d {command}: {reason}. Pass --no-progressive to work on every "
                f"triangle directly, or --progressive-faces M to choose the copy's size.")
    return params_from_dict(ProgressiveParams, {"target_faces": faces, "preview_every": 0}), reason


def cubic_options(args: argparse.Namespace, n_faces: int) -> tuple[dict, bool, str]:
    """The Cubic recipe's options for this run, whether progressive meshes were chosen
    automatically, and why the run works on a coarse copy or on every triangle: the project's
    saved options (if any) < the flags given here; without saved options, the measured
    automatic choice for big meshes."""
    from algorithms.deform.progressive import ProgressiveParams

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
    if args.progressive_faces is not None:
        base = options.get("progressive") or params_to_dict(ProgressiveParams())
        options["progressive"] = {**base, "target_faces": args.progressive_faces}
        options["multigrid"] = False
        reason = (f"--progressive-faces {args.progressive_faces} asked for a "
                  f"{args.progressive_faces:,}-triangle copy")
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


def cmd_cubic(args: argparse.Namespace) -> int:
    from algorithms.deform.cubic import mean_l1_of_normals
    from algorithms.mesh import write_mesh

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
        write_mesh(output, V, data.F)
        results.append({"lam": params.lam, "output": output, "params": params,
                        "iterations": last.iteration, "seconds": seconds,
                        "online_seconds": online,
                        "final_relative_displacement": last.metrics.get("displacement"),
                        "l1_normals_after": mean_l1_of_normals(V, data.F)})
    common = {"input": args.mesh,
              "progressive_faces": None if prog is None else int(prog["target_faces"]),
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
                        "l1_normals_after": r["l1_normals_after"]})
        else:
            print_json({**common, "runs": [
                {"lambda": r["lam"], "output": r["output"], "params": params_to_dict(r["params"]),
                 "iterations": r["iterations"], "seconds": r["seconds"],
                 "online_seconds": r["online_seconds"],
                 "final_relative_displacement": r["final_relative_displacement"],
                 "l1_normals_after": r["l1_normals_after"]} for r in results]})
    else:
        how = ("on every triangle" if prog is None else
               f"through a {int(prog['target_faces']):,}-triangle copy")
        for r in results:
            print(f"Stylized {args.mesh} (λ {r['lam']:g}) in {r['seconds']:.2f} s "
                  f"({r['iterations']} iterations); mean L1 norm of normals {l1_before:.4f} -> "
                  f"{r['l1_normals_after']:.4f}; wrote {r['output']}.")
        pre = "" if preprocess is None else f" (pre-processing {preprocess:.1f} s, once)"
        print(f"Worked {how}{pre}: {reason}.")
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


def analogy_style_options(args: argparse.Namespace) -> tuple[dict, dict]:
    """The Analogies recipe's style options (``style``, ``style_map``, ``capture``): defaults <
    the project's saved options < ``--style`` / ``--style-map``; a style file given here becomes
    a blob. Returns ``(options, {blob reference: path given})``."""
    from algorithms.deform.targets import PRIMITIVES, load_style
    from app.recipes import put_blob_file
    from app.recipes.analogies import CAPTURE

    saved = saved_panel(args, "Analogies")
    saved = dict(saved["options"]) if saved is not None else {}
    options = {"style": "cube", "style_map": "auto", **saved}
    named: dict[str, str] = {}
    style = args.style
    if style is None or style in PRIMITIVES:
        pass
    elif style == CAPTURE and saved.get("capture") is not None:
        pass  # the project's painted capture sphere
    elif Path(style).is_file():
        named[put_blob_file(style)] = style
        style = next(iter(named))
    else:
        load_style(style, args.style_map or "auto")  # its plain message (no such file, ...)
        raise ParameterError(f"Unknown style '{style}': use one of {', '.join(PRIMITIVES)}, a "
                             "capture .json file or a mesh file.")
    if style is not None:
        options["style"] = style
    if args.style_map is not None:
        options["style_map"] = args.style_map
    return options, named


def analogy_progressive(args: argparse.Namespace, options: dict, n_faces: int) -> bool:
    """Set ``options["progressive"]``: ``--progressive-faces`` / ``--no-progressive``, else the
    project's saved choice, else the automatic one for big meshes (the panel has no such
    switch, so a project without it keeps the command's automatic choice). Returns whether
    progressive meshes were chosen automatically."""
    if args.progressive_faces is None and not args.no_progressive and "progressive" in options:
        if options["progressive"] is not None:  # no previews on the command line
            options["progressive"] = {**options["progressive"], "preview_every": 0}
        return False
    prog = _progressive_choice(args, n_faces, "analogy")[0]
    options["progressive"] = None if prog is None else params_to_dict(prog)
    return prog is not None and args.progressive_faces is None


def analogy_job(args: argparse.Namespace, n_faces: int) -> tuple:
    """``(params, options)`` of the Analogies recipe that ``analogy`` would run on a mesh of
    ``n_faces`` triangles (the style checked; a style file given becomes a blob)."""
    from algorithms.deform.analogies import AnalogyParams
    from app.recipes.analogies import style_target_map

    params = method_params(args, AnalogyParams, panel="Analogies")
    options, named = analogy_style_options(args)
    with user_paths(named):
        style_target_map(options, {})
    analogy_progressive(args, options, n_faces)
    return params, options


def _angles_to_targets(V, F, target_map) -> tuple[float, float]:
    """(mean, max) degrees between the vertex normals and their targets (area-weighted mean)."""
    from algorithms.deform.analogies import angles_to_targets
    from algorithms.mesh.operators import mass_matrix, vertex_normals

    N = vertex_normals(V, F)
    return angles_to_targets(N, target_map(N), mass_matrix(V, F, "voronoi").diagonal())


def cmd_analogy(args: argparse.Namespace) -> int:
    from algorithms.deform.analogies import AnalogyParams
    from algorithms.mesh import write_mesh
    from app.recipes.analogies import style_target_map

    params = method_params(args, AnalogyParams, panel="Analogies")
    check_output(args.output, args.overwrite, args.mesh)
    options, named = analogy_style_options(args)
    cache: dict = {}  # the style's target map is built once, for the run and the figures
    with user_paths(named):
        target_map, what = style_target_map(options, cache)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    state = input_state(args, data)
    auto = analogy_progressive(args, options, len(data.F))
    prog = options["progressive"]
    before = _angles_to_targets(data.V, data.F, target_map)
    recipe = method_recipe("analogies", "Analogies")
    t0 = time.perf_counter()
    last = None
    with user_paths(named):
        for last in recipe.steps(state, params, options, cache):
            if not args.json and not args.quiet and "mean_angle_to_targets" in last.metrics:
                print(f"  iteration {last.iteration}: mean angle to targets "
                      f"{last.metrics['mean_angle_to_targets']:.2f}°", file=sys.stderr)
    seconds = time.perf_counter() - t0
    V = recipe.result(state, last, options).V
    write_mesh(args.output, V, data.F)
    after = _angles_to_targets(V, data.F, target_map)
    if args.json:
        print_json({"input": args.mesh, "output": args.output,
                    "style": args.style if args.style is not None else options["style"],
                    "style_map": what, "params": params_to_dict(params),
                    "iterations": last.iteration, "seconds": seconds,
                    "progressive_faces": None if prog is None else int(prog["target_faces"]),
                    "progressive_auto": auto,
                    "mean_angle_before": before[0], "max_angle_before": before[1],
                    "mean_angle_after": after[0], "max_angle_after": after[1]})
    else:
        print(f"Stylized {args.mesh} after {what} in {seconds:.2f} s ({last.iteration} "
              f"iterations); mean angle to the target normals {before[0]:.1f}° -> "
              f"{after[0]:.1f}°; wrote {args.output}.")
    return 0


def _add_progressive_arguments(s: argparse.ArgumentParser) -> None:
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES

    s.add_argument("--progressive-faces", type=int, metavar="M",
                   help="affine progressive meshes (thesis Alg. 4): stylize a decimated copy "
                        "with M triangles, then put the details back; for big meshes. On by "
                        f"default (M = 20,000) above {AUTO_PROGRESSIVE_FACES:,} triangles, "
                        "where it was measured faster")
    s.add_argument("--no-progressive", action="store_true",
                   help="never use progressive meshes, even for big meshes (slower)")


def add_parsers(sub) -> None:
    from algorithms.deform.analogies import AnalogyParams
    from algorithms.deform.cubic import CubicParams
    from algorithms.deform.targets import PRIMITIVES, STYLE_MAP_MODES

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

    s = sub.add_parser("analogy", help="normal-driven shape analogy (thesis ch. 6)",
                       description="Normal-driven shape analogy (thesis ch. 6). On a project "
                                   "(.s3d) it uses the Analogies panel's saved settings and "
                                   "style (a style file or the painted capture sphere saved "
                                   "with it); flags given here win.")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("-o", "--output", required=True, help="where to write the stylized mesh")
    s.add_argument("--style",
                   help=f"a primitive ({', '.join(PRIMITIVES)}), a normal-capture .json file, or "
                        "a style mesh file; on a project, 'capture sphere' is its painted "
                        "capture sphere. Default: cube (or the project's saved style).")
    s.add_argument("--style-map", choices=STYLE_MAP_MODES,
                   help="for a style mesh: closest face normals (convex meshes) or a spherical "
                        "parameterization (any closed genus-0 mesh); auto picks. Default: auto "
                        "(or the project's saved choice).")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help="print iterations, time, and the mean/max angle to the targets before "
                        "and after, as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    s.add_argument("--clean", action="store_true",
                   help="clean the mesh first when it has fixable problems (says what it fixed)")
    _add_progressive_arguments(s)
    add_params_file_argument(s)
    add_params_arguments(s, AnalogyParams)
    s.set_defaults(func=cmd_analogy)
