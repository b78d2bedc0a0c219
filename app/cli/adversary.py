"""``stylize3d adversary``: parametric adversaries (thesis ch. 3), SH lighting or vertex
perturbations that fool an image classifier, with a random baseline of the same norm."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_project, method_params, print_json, read_input)

COMMANDS = ("adversary",)


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
    params = method_params(args, AdversaryParams, panel="Adversarial lighting")
    if args.output:
        ext = Path(args.output).suffix.lower()
        if params.mode == "lighting" and ext != ".json":
            raise ParameterError("A lighting attack writes the adversarial lighting as .json; "
                                 f"name the output file *.json (got '{args.output}').")
        if params.mode == "geometry" and ext == ".json":
            raise ParameterError("A geometry attack writes the perturbed mesh; name the output "
                                 "file .obj, .ply, .off or .stl.")
        check_output(args.output, args.overwrite, args.mesh)
    data, _ = read_input(args, quiet=args.json)
    colours = (None if input_project(args) is not None else
               read_mesh_colors(args.mesh, len(data.V), len(data.F)))
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
        print_json(report)
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


def add_parsers(sub) -> None:
    from algorithms.adversarial import AdversaryParams
    from algorithms.render.sh import ENVIRONMENTS

    s = sub.add_parser("adversary",
                       help="adversarial lighting or geometry that fools an image classifier "
                            "(thesis ch. 3)")
    s.add_argument("mesh", help=MESH_HELP)
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
    add_params_file_argument(s)
    add_params_arguments(s, AdversaryParams)
    s.set_defaults(func=cmd_adversary)
