"""``stylize3d subdivide``, ``subdivide-train`` and ``subdivide-eval``: neural subdivision
(thesis ch. 4) and the Loop / modified butterfly / mid-point baselines."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, field_names, method_params, params_to_dict,
                            print_json, read_input, read_valid, say, settings)

COMMANDS = ("subdivide", "subdivide-train", "subdivide-eval")


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
    from algorithms.params import params_from_dict
    from algorithms.subdivision.model import SubdivideParams

    values = settings(args, params_to_dict(SubdivideParams()), panel="Subdivision")
    if isinstance(values["levels"], float) and values["levels"].is_integer():
        values["levels"] = int(values["levels"])
    if not isinstance(values["levels"], int) or not 1 <= values["levels"] <= 3:
        raise ParameterError(f"--levels must be 1, 2 or 3 (got {values['levels']}).")
    params = params_from_dict(SubdivideParams, values)
    check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json)
    fn = _neural_or_baseline(params.method, args.weights)
    t0 = time.perf_counter()
    V, F = data.V, data.F
    if params.coarsen_first and params.coarsen_first < len(V):   # as the Subdivision panel
        from algorithms.subdivision.metrics import coarsen_to_vertices

        V, F = coarsen_to_vertices(V, F, params.coarsen_first)
    V, F = fn(V, F, params.levels)
    dt = time.perf_counter() - t0
    write_mesh(args.output, V, F)
    out = {"input": args.mesh, "output": args.output, "method": params.method,
           "levels": params.levels, "coarsen_first": params.coarsen_first,
           "vertices_in": int(len(data.V)), "faces_in": int(len(data.F)),
           "vertices": int(len(V)), "faces": int(len(F)), "seconds": dt}
    if args.json:
        print_json(out)
    else:
        print(f"Wrote {args.output}: {params.method} subdivision, {params.levels} level(s), "
              f"{len(data.F):,} -> {len(F):,} triangles in {dt:.2f} s.")
    return 0


def cmd_subdivide_train(args: argparse.Namespace) -> int:
    import numpy as np

    from algorithms.subdivision.data import DataParams, generate_dataset
    from algorithms.subdivision.model import save_weights
    from algorithms.subdivision.train import Trainer, TrainParams

    names = field_names(DataParams, TrainParams)
    dparams = method_params(args, DataParams, allowed=names)
    tparams = method_params(args, TrainParams, allowed=names)
    check_output(args.output, args.overwrite)
    shapes = [read_valid(p, clean=args.clean, quiet=args.json)[0] for p in args.meshes]
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
        say("stylize3d subdivide-train: interrupted; saving the best weights so far.")
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
        print_json(out)
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
    s.add_argument("--coarsen-first", type=int, metavar="N",
                   help="QSlim the mesh to about N vertices first, as the Subdivision panel "
                        "does (0: off). Default: 0.")
    s.add_argument("--weights", help="a weights file from subdivide-train (default: shipped)")
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
