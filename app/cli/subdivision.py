"""``stylize3d subdivide``, ``subdivide-train`` and ``subdivide-eval``: neural subdivision
(thesis ch. 4) and the Loop / modified butterfly / mid-point baselines.

``subdivide`` and ``subdivide-train`` are thin wrappers around the recipes "Subdivision" and
"Subdivision training" (:mod:`app.recipes.subdivision`). On a project (``scene.s3d``),
``subdivide`` uses the Subdivision panel's saved settings and options (the weights chosen
there: shipped, trained in the app, or a weights file, all kept in the project), so it gives
the same mesh as ``app.recipes.run("subdivide", project)``; ``--weights FILE`` (or
``shipped``) wins over the saved choice. ``subdivide-train`` makes the coarse meshes of every
mesh given (spread evenly over them; locally or on a Dask scheduler) and trains, with the
training settings saved in a project given as the first mesh (the panel's coarse meshes and
epochs) as its defaults; its weights file holds the recipe's best weights (on one mesh, those
of ``app.recipes.run("subdivide-train", mesh, params, {"workers": W, "cache": C})``) and
``trained_on`` (the meshes' file names).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_recipe, params_to_dict,
                            print_json, read_input, read_valid, saved_panel, say, settings)

COMMANDS = ("subdivide", "subdivide-train", "subdivide-eval")


def _neural_or_baseline(method: str, weights: str | None):
    """``fn(V, F, levels) -> (V, F)`` for a subdivision method name (subdivide-eval)."""
    from algorithms.subdivision.baselines import subdivide_baseline

    if method == "neural":
        from algorithms.subdivision.model import neural_subdivide

        from algorithms.subdivision.inference import load_network

        net = load_network(None if weights in (None, "shipped") else weights)
        # the protocol measures the network itself: never Loop in its place
        return lambda V, F, levels: neural_subdivide(V, F, levels, net, dense="scale")
    return lambda V, F, levels: subdivide_baseline(V, F, levels, method)


def subdivide_options(args: argparse.Namespace, method: str) -> dict:
    """The Subdivision recipe's options: the project's saved ones (if any) < ``--weights``
    (``shipped``, or a weights file, checked and stored as a blob; read only for neural
    subdivision, as before)."""
    saved = saved_panel(args, "Subdivision")
    options = dict(saved["options"]) if saved is not None else {}
    if args.weights is not None and method == "neural":
        if args.weights == "shipped":
            options["weights"] = "shipped"
        else:
            from app.recipes.subdivision import weights_blob_from_file

            options.update(weights="file", weights_file=weights_blob_from_file(args.weights))
    return options


def subdivide_params(args: argparse.Namespace):
    """The SubdivideParams of ``subdivide``'s flags (defaults < a project's saved Subdivision
    settings < ``--params`` < flags; 1 to 3 levels)."""
    from algorithms.params import params_from_dict
    from algorithms.subdivision.model import SubdivideParams

    values = settings(args, params_to_dict(SubdivideParams()), panel="Subdivision")
    if isinstance(values["levels"], float) and values["levels"].is_integer():
        values["levels"] = int(values["levels"])
    if not isinstance(values["levels"], int) or not 1 <= values["levels"] <= 3:
        raise ParameterError(f"--levels must be 1, 2 or 3 (got {values['levels']}).")
    return params_from_dict(SubdivideParams, values)


def subdivide_job(args: argparse.Namespace) -> tuple:
    """``(params, options)`` of the Subdivision recipe that ``subdivide`` runs (for
    ``stylize3d batch``)."""
    params = subdivide_params(args)
    return params, subdivide_options(args, params.method)


def cmd_subdivide(args: argparse.Namespace) -> int:
    from app.cli.attributes import write_result

    params = subdivide_params(args)
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json)
    options = subdivide_options(args, params.method)
    state = input_state(args, data)
    recipe = method_recipe("subdivision", "Subdivision")
    t0 = time.perf_counter()
    last = None
    for last in recipe.steps(state, params, options, {}):
        pass
    after = recipe.result(state, last, options)
    dt = time.perf_counter() - t0
    V, F = after.V, after.F
    how = ("'Coarsen first' remade the triangles (QSlim) before subdividing"
           if params.coarsen_first and params.coarsen_first < len(data.V) else "subdivided")
    write_result(args, args.output, V, F, data, how=how, levels=params.levels)
    note = str(getattr(last, "note", "") or "")
    method_used = str(getattr(last, "method_used", "") or params.method)
    fallback = bool(getattr(last, "fallback", False))
    levels_used = list(getattr(last, "levels_used", ()) or [method_used] * int(params.levels))
    out = {"input": args.mesh, "output": args.output, "method": params.method,
           "method_used": method_used, "fallback": fallback, "levels_used": levels_used,
           "fallback_reason": str(getattr(last, "fallback_reason", "") or ""),
           "levels": params.levels, "coarsen_first": params.coarsen_first,
           "vertices_in": int(len(data.V)), "faces_in": int(len(data.F)),
           "vertices": int(len(V)), "faces": int(len(F)), "seconds": dt, "note": note,
           # vertices where the guard blended the level before back in (the network's result
           # crossed itself there)
           "unsmoothed_vertices": int((last.metrics or {}).get("unsmoothed_vertices", 0)),
           # parts of the mesh the guard handed to Loop (the network made the others)
           "loop_parts": int((last.metrics or {}).get("loop_parts", 0)),
           # vertices where the guard blended Loop's positions in over the network's bulges
           "loop_blended_vertices": int((last.metrics or {}).get("loop_blended_vertices", 0))}
    if args.json:
        print_json(out)
    else:
        from app.recipes.subdivision import method_words

        if note:
            say(f"stylize3d subdivide: {note}")
        said = method_words(method_used, fallback, levels_used, out["loop_blended_vertices"])
        print(f"Wrote {args.output}: {said}, {params.levels} "
              f"level(s), {len(data.F):,} -> {len(F):,} triangles in {dt:.2f} s.")
    return 0


def training_params(args: argparse.Namespace, project=None):
    """The "Subdivision training" Params: defaults < the training settings saved in a project
    given as the first mesh (the Subdivision panel's coarse meshes and epochs) < ``--params``
    < the flags."""
    from algorithms.params import describe, params_from_dict
    from app.recipes import subdivision as rs

    cls = rs.training_params_cls()
    specs = {spec.name: spec for spec in describe(cls)}
    defaults = {name: spec.default for name, spec in specs.items()}
    if project is not None:
        saved = {**(project.options_of(rs.SUBDIVIDE_RECIPE).get("training") or {}),
                 **project.params_of(rs.TRAIN_RECIPE)}
        defaults.update({k: v for k, v in saved.items() if k in defaults})
    values = settings(args, defaults)
    for k, v in values.items():  # JSON's 3.0 for a whole-number field
        if specs[k].type is int and isinstance(v, float) and v.is_integer():
            values[k] = int(v)
    return params_from_dict(cls, values)


def cmd_subdivide_train(args: argparse.Namespace) -> int:
    import numpy as np

    from algorithms.mesh.io import atomic_write
    from app.document import MeshState
    from app.project import is_project_path, read_project
    from app.recipes import subdivision as rs

    first = args.meshes[0]
    project = read_project(first) if is_project_path(first) else None
    params = training_params(args, project)
    dparams, tparams = rs.split_training_params(params)
    check_output(args.output, args.overwrite)
    shapes = [read_valid(p, clean=args.clean, quiet=args.json,
                         project=project if k == 0 else None)[0]
              for k, p in enumerate(args.meshes)]
    quiet = args.json or args.quiet
    options = {"workers": args.workers, "cache": not args.no_cache}
    recipe = method_recipe("subdivision", rs.TRAIN_RECIPE)
    state = MeshState.make(shapes[0].V, shapes[0].F)
    shown = -1
    last = None
    epoch_seconds = []
    steps = rs.training_steps(state, params, options, {},
                              meshes=[(d.V, d.F) for d in shapes], scheduler=args.scheduler,
                              cache_dir=args.cache_dir)
    try:
        for step in steps:
            if isinstance(step, rs.TrainingStep):
                last = step
                epoch_seconds.append(float(step.metrics["seconds"]))
                if not quiet and (step.iteration % 10 == 0 or step.iteration == 1):
                    print(f"  {step.message}", file=sys.stderr)
            elif not quiet and step.total:  # making the coarse meshes: every 10 %
                pct = int(100 * step.iteration / step.total)
                if pct >= shown + 10:
                    shown = pct
                    print(f"  data: {step.message}", file=sys.stderr)
    except KeyboardInterrupt:
        if last is None:  # no epoch finished: no weights worth keeping
            raise
        say("stylize3d subdivide-train: interrupted; saving the best weights so far.")
    finally:
        steps.close()
    trained_on = ", ".join(Path(p).name for p in args.meshes)
    data = rs.trained_weights_bytes(last, {"trained_on": trained_on})
    atomic_write(args.output, lambda fh: fh.write(data))
    outcome = recipe.outcome(last)
    t_data = float(last.data_seconds)
    out = {"weights": args.output, "meshes": list(args.meshes),
           "coarse_meshes": int(dparams.coarse_meshes), "epochs": int(outcome["epochs"]),
           "best_epoch": int(outcome["best_epoch"]),
           "best_validation_loss": float(outcome["best_validation_loss"]),
           "final_loss": float(outcome["losses"][-1]),
           "stopped_early": bool(outcome["stopped_early"]),
           "seconds_data": t_data, "seconds_training": float(sum(epoch_seconds)),
           "seconds_per_epoch": float(np.median(epoch_seconds))}
    if args.json:
        print_json(out)
    else:
        stopped = (f" (stopped early: no progress in {tparams.patience} epochs)"
                   if out["stopped_early"] else "")
        print(f"Wrote {args.output}: {out['coarse_meshes']} coarse meshes ({t_data:.0f} s), "
              f"{out['epochs']} epochs{stopped} ({out['seconds_training']:.0f} s); best "
              f"validation loss {out['best_validation_loss']:.4g} at epoch "
              f"{out['best_epoch']}.")
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


#: subdivide-eval's settings (flags, or names in a --params file) and their defaults
EVAL_DEFAULTS = {"target_vertices": "350-450", "levels": 2, "methods": "neural,loop,butterfly",
                 "samples": 200_000, "seed": 0}


def cmd_subdivide_eval(args: argparse.Namespace) -> int:
    import numpy as np

    from algorithms.subdivision.metrics import evaluate_protocol

    opts = settings(args, EVAL_DEFAULTS)
    lo, hi = _parse_range(opts["target_vertices"])
    methods = [m for m in str(opts["methods"]).split(",") if m]
    bad = [m for m in methods if m not in ("neural", "loop", "butterfly", "midpoint")]
    if bad or not methods:
        raise ParameterError(f"--methods takes neural, loop, butterfly, midpoint (got "
                             f"{opts['methods']!r}).")
    levels = opts["levels"]
    fns = {m: _neural_or_baseline(m, args.weights) for m in methods}
    meshes = []
    for p in args.meshes:
        d, _ = read_valid(p, clean=args.clean, quiet=args.json)
        meshes.append((Path(p).name, d.V, d.F))

    def progress(frac, msg):
        if not args.json and not args.quiet:
            print(f"  {msg}", file=sys.stderr)

    rows = evaluate_protocol(meshes, fns, target_vertices=(lo, hi), levels=levels,
                             samples=opts["samples"], seed=opts["seed"], progress=progress)
    keys = ("hausdorff", "mean_distance")
    summary = {m: {k: float(np.mean([r["methods"][m][k] for r in rows])) for k in keys}
               for m in methods}
    out = {"units": "% of the bounding-box diagonal of each original mesh",
           "weights": args.weights, "levels": levels, "target_vertices": [lo, hi],
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
        print_json(out)
    else:
        head = "mesh".ljust(22) + "".join(f"H_{m}".rjust(12) for m in methods) + \
            "".join(f"M_{m}".rjust(12) for m in methods)
        print(f"Table 4.2 protocol: QSlim to {lo}-{hi} vertices, {levels} levels; "
              f"H = Hausdorff, M = mean surface distance, in % of the bounding-box diagonal.")
        print(head)
        for r in rows:
            print(r["mesh"][:21].ljust(22)
                  + "".join(f"{r['methods'][m]['hausdorff']:12.3f}" for m in methods)
                  + "".join(f"{r['methods'][m]['mean_distance']:12.3f}" for m in methods))
        print("mean".ljust(22) + "".join(f"{summary[m]['hausdorff']:12.3f}" for m in methods)
              + "".join(f"{summary[m]['mean_distance']:12.3f}" for m in methods))
    return 0


def add_parsers(sub) -> None:
    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.train import TrainParams

    s = sub.add_parser("subdivide", help="subdivide a mesh: neural (thesis ch. 4), Loop, "
                                         "modified butterfly or mid-point")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("-o", "--output", required=True, help="where to write the subdivided mesh")
    s.add_argument("--levels", type=int, help="1 to 3 levels. Default: 2.")
    s.add_argument("--method", choices=("neural", "loop", "butterfly", "midpoint"),
                   help="Default: neural (with the shipped weights).")
    s.add_argument("--dense-input", choices=("guard", "loop", "scale", "off"),
                   help="neural: guard (the network, scaled to its training edge length on a "
                        "denser mesh; level by level its result is kept unless it is more than "
                        "2.6x as bent as modified butterfly's, 1.25x on a denser mesh, or bends "
                        "flat sides (a few isolated bulges get Loop's positions there "
                        "instead); from there Loop subdivision makes the levels (only for the "
                        "parts that fail, on a mesh of several parts); where it crosses itself, "
                        "the level before is blended back in there; all said on stderr and in "
                        "--json levels_used, loop_parts, loop_blended_vertices), loop "
                        "(Loop on any mesh denser than the training meshes), scale (always the "
                        "network, scaled), off (as is). Default: guard.")
    s.add_argument("--coarsen-first", type=int, metavar="N",
                   help="QSlim the mesh to about N vertices first, as the Subdivision panel "
                        "does (0: off). Default: 0.")
    s.add_argument("--weights", help="a weights file from subdivide-train, or the thesis "
                                     "author's netparams.dat (its hyperparameters.json beside "
                                     "it is checked); default: shipped")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"method", "levels", "vertices", "faces", "seconds", ...}')
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    add_params_file_argument(s)
    s.set_defaults(func=cmd_subdivide)

    s = sub.add_parser("subdivide-train", help="train neural subdivision on one or more meshes "
                                               "(thesis §4.4, App. 4.8.5-4.8.6)")
    s.add_argument("meshes", nargs="+", metavar="MESH", help=MESH_HELP)
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
    add_params_file_argument(s)
    add_params_arguments(s, DataParams)
    add_params_arguments(s, TrainParams)
    s.set_defaults(func=cmd_subdivide_train)

    s = sub.add_parser("subdivide-eval", help="the Table 4.2 protocol: QSlim each mesh to "
                                              "350-450 vertices, subdivide, measure H and M")
    s.add_argument("weights", help="a weights file ('shipped' for the shipped weights)")
    s.add_argument("meshes", nargs="+", metavar="MESH", help=MESH_HELP)
    s.add_argument("--target-vertices", help="coarse vertex range. Default: 350-450.")
    s.add_argument("--levels", type=int, help="Default: 2.")
    s.add_argument("--methods",
                   help="comma-separated: neural, loop, butterfly, midpoint. "
                        "Default: neural,loop,butterfly.")
    s.add_argument("--samples", type=int,
                   help="area-uniform samples per surface (plus the vertices). Default: 200000.")
    s.add_argument("--seed", type=int, help="seed of the targets and samples. Default: 0.")
    s.add_argument("--json", action="store_true",
                   help='print {"methods": {name: {"hausdorff", "mean_distance"}}, "meshes": '
                        '[...]} (%% of the bounding-box diagonal)')
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true", help="clean the meshes first")
    add_params_file_argument(s)
    s.set_defaults(func=cmd_subdivide_eval)
