"""``stylize3d cubic`` (the Cubic recipe, thesis ch. 5) and ``stylize3d analogy`` (normal-driven
shape analogies, thesis ch. 6).

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

from algorithms.errors import ParameterError
from algorithms.params import params_from_dict
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_params, method_recipe,
                            params_to_dict, print_json, read_input, saved_panel, say)

COMMANDS = ("cubic", "analogy")


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
            say(f"stylize3d {command}: this mesh has {n_faces:,} triangles (more than "
                f"{AUTO_PROGRESSIVE_FACES:,}), so it is stylized through affine progressive "
                f"meshes: on a {faces:,}-triangle copy, then the details are put back. Pass "
                f"--no-progressive to work on every triangle directly (slower), or "
                f"--progressive-faces M to choose the copy's size.")
    return params_from_dict(ProgressiveParams, {"target_faces": faces, "preview_every": 0})


def cubic_options(args: argparse.Namespace, n_faces: int) -> tuple[dict, bool]:
    """The Cubic recipe's options for this run and whether progressive meshes were chosen
    automatically: the project's saved options (if any) < the flags given here; without saved
    options, the automatic choice for big meshes."""
    from algorithms.deform.progressive import ProgressiveParams

    if args.progressive_faces is not None and args.global_solver == "multigrid":
        raise ParameterError("--progressive-faces and --global-solver multigrid are two ways to "
                             "handle big meshes; choose one.")
    if args.progressive_faces is not None and args.no_progressive:
        raise ParameterError("--progressive-faces and --no-progressive contradict each other; "
                             "choose one.")
    saved = saved_panel(args, "Cubic")
    if saved is None:
        prog = _progressive_choice(args, n_faces, "cubic",
                                   auto_ok=args.global_solver != "multigrid")
        options = {"plane_axis": 0, "progressive": None if prog is None else params_to_dict(prog),
                   "multigrid": args.global_solver == "multigrid" and prog is None}
        return options, prog is not None and args.progressive_faces is None
    options = {"plane_axis": 0, "progressive": None, "multigrid": False, **saved["options"]}
    if args.progressive_faces is not None:
        base = options.get("progressive") or params_to_dict(ProgressiveParams())
        options["progressive"] = {**base, "target_faces": args.progressive_faces}
        options["multigrid"] = False
    elif args.no_progressive:
        options["progressive"] = None
    if args.global_solver is not None:
        options["multigrid"] = args.global_solver == "multigrid"
        if options["multigrid"]:
            options["progressive"] = None
    if options.get("progressive") is not None:  # no previews on the command line
        options["progressive"] = {**options["progressive"], "preview_every": 0}
    return options, False


def cmd_cubic(args: argparse.Namespace) -> int:
    from algorithms.deform.cubic import CubicParams, mean_l1_of_normals
    from algorithms.mesh import write_mesh

    params = method_params(args, CubicParams, panel="Cubic")
    if args.lambda_xyz is not None:
        x, y, z = args.lambda_xyz
        params = params_from_dict(CubicParams, {**params_to_dict(params), "per_axis": True,
                                                "axis_factor_x": x, "axis_factor_y": y,
                                                "axis_factor_z": z})
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json or args.quiet)
    state = input_state(args, data)
    l1_before = mean_l1_of_normals(data.V, data.F)
    options, auto = cubic_options(args, len(data.F))
    prog = options.get("progressive")
    recipe = method_recipe("cubic", "Cubic")
    t0 = time.perf_counter()
    last = None
    for last in recipe.steps(state, params, options, {}):
        if "energy" in last.metrics and not args.json and not args.quiet:
            print(f"  iteration {last.iteration}: energy {last.metrics['energy']:.6g}, "
                  f"relative move {last.metrics.get('displacement', 0):.2e}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    V = recipe.result(state, last, options).V
    write_mesh(args.output, V, data.F)
    l1_after = mean_l1_of_normals(V, data.F)
    if args.json:
        print_json({"input": args.mesh, "output": args.output, "params": params_to_dict(params),
                    "iterations": last.iteration, "seconds": seconds,
                    "final_relative_displacement": last.metrics.get("displacement"),
                    "progressive_faces": None if prog is None else int(prog["target_faces"]),
                    "progressive_auto": auto,
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

    params = method_params(args, AnalogyParams, panel="Analogies")
    check_output(args.output, args.overwrite, args.mesh)
    target_map, what = load_style(args.style, args.style_map)
    data, _ = read_input(args, quiet=args.json or args.quiet)

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
        print_json({"input": args.mesh, "output": args.output, "style": args.style,
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


def _add_progressive_arguments(s: argparse.ArgumentParser) -> None:
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES

    s.add_argument("--progressive-faces", type=int, metavar="M",
                   help="affine progressive meshes (thesis Alg. 4): stylize a decimated copy "
                        "with M triangles, then put the details back; for big meshes. On by "
                        f"default (M = 20,000) above {AUTO_PROGRESSIVE_FACES:,} triangles")
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
    s.set_defaults(func=cmd_cubic)

    s = sub.add_parser("analogy", help="normal-driven shape analogy (thesis ch. 6)")
    s.add_argument("mesh", help=MESH_HELP)
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
    add_params_file_argument(s)
    add_params_arguments(s, AnalogyParams)
    s.set_defaults(func=cmd_analogy)
