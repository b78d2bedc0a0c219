"""``stylize3d analogy`` (the Analogies recipe: normal-driven shape analogies, thesis ch. 6).

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
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_params, method_recipe,
                            params_to_dict, print_json, read_input, saved_panel)
from app.cli.deform import (_add_progressive_arguments, _progressive_choice, crossings_sentence_of,
                             user_paths)

COMMANDS = ("analogy",)


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
    if (args.progressive_faces is None and not args.no_progressive and not args.coarse_only
            and "progressive" in options):
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
    from algorithms.deform.collisions import crossings_of
    from app.cli.attributes import write_result
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
    finished, not_finished = False, ""
    if prog is not None:
        from algorithms.deform.progressive import ProgressiveParams
        from algorithms.params import params_from_dict
        from app.recipes.cubic import finish_of

        finished, not_finished = finish_of(
            params_from_dict(ProgressiveParams, {"finish": False, **prog}), len(data.F))
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
    write_result(args, args.output, V, data.F, data)
    after = _angles_to_targets(V, data.F, target_map)
    from app.recipes.analogies import change_note

    note = change_note(data.V, V, after[0], params.lam, flags=True)
    if args.json:
        print_json({"input": args.mesh, "output": args.output,
                    "style": args.style if args.style is not None else options["style"],
                    "style_map": what, "params": params_to_dict(params),
                    "iterations": last.iteration, "seconds": seconds,
                    "progressive_faces": None if prog is None else int(prog["target_faces"]),
                    "progressive_auto": auto,
                    "progressive_finish": None if prog is None else finished,
                    "progressive_not_finished": not_finished or None,
                    "mean_angle_before": before[0], "max_angle_before": before[1],
                    "mean_angle_after": after[0], "max_angle_after": after[1],
                    "crossings": crossings_of(last.metrics),
                    **({"note": note} if note else {})})
    else:
        print(f"Stylized {args.mesh} after {what} in {seconds:.2f} s ({last.iteration} "
              f"iterations); mean angle to the target normals {before[0]:.1f}° -> "
              f"{after[0]:.1f}°; wrote {args.output}.")
        said = " ".join(x for x in (crossings_sentence_of(crossings_of(last.metrics)), note)
                        if x)
        if said:
            print(said)
        if prog is not None:
            faces = int(prog["target_faces"])
            print(f"Worked through a {faces:,}-triangle copy, then on every triangle from its "
                  f"result." if finished else
                  f"Worked through a {faces:,}-triangle copy alone (the details put back"
                  + (f"; {not_finished})." if not_finished else
                     ", not finished on every triangle)."))
    return 0


def add_parsers(sub) -> None:
    from algorithms.deform.analogies import AnalogyParams
    from algorithms.deform.targets import PRIMITIVES, STYLE_MAP_MODES

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
