"""``stylize3d adversary``: parametric adversaries (thesis ch. 3), SH lighting or vertex
perturbations that fool an image classifier, with a random baseline of the same norm.

A thin wrapper around the recipes of :mod:`app.recipes.adversarial`: ``--mode lighting`` runs
"Adversarial lighting", ``--mode geometry`` runs "Adversarial lighting: geometry", both with the
recipe's ``random_baseline`` option (the random comparison of the report). The recipe's options
are built here, lowest to highest precedence:

1. the defaults (Grace Cathedral, 0.7 grey, the installed classifier, evenly spaced views from
   azimuth 0, no labels);
2. on a project (``scene.s3d``), the Adversarial lighting panel's saved options (lighting,
   colours, labels, view, classifier blob), so that a project without flags gives
   what ``app.recipes.run`` gives on it; on a mesh file, the file's own colours (per face, or
   per vertex averaged over each face, as the panel reads them);
3. the flags given: ``--lighting`` (a name or a lighting .json file), ``--color`` (the colour
   where there are no per-face colours), ``--classifier FILE`` (stored as a blob), ``--target``,
   ``--label`` (the true class: the views become the recognized ones among 24 around the shape,
   passed to the recipe as ``azimuths``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_project, input_state, method_params,
                            method_recipe, print_json, read_input, saved_panel)

COMMANDS = ("adversary",)

#: the panel whose saved settings a project gives this command
PANEL = "Adversarial lighting"
DEFAULT_LIGHTING = "Grace Cathedral"
DEFAULT_COLOR = (0.7, 0.7, 0.7)


def _lighting_arg(value: str) -> dict:
    """``--lighting``: a published environment's name, or a lighting .json file; the recipe's
    ``environment`` / ``lighting`` options."""
    from algorithms.adversarial.lighting_io import read_lighting
    from algorithms.render.sh import ENVIRONMENTS

    if value in ENVIRONMENTS:
        return {"environment": value, "lighting": None}
    if value.lower().endswith(".json") or Path(value).exists():
        return {"environment": "Custom", "lighting": read_lighting(value).tolist()}
    raise ParameterError(f"Unknown lighting '{value}': use one of {', '.join(ENVIRONMENTS)} or "
                         "a lighting .json file.")


def adversary_options(args: argparse.Namespace, data) -> dict:
    """The recipe's options without the view search (module docstring): defaults < the
    project's saved options or the mesh file's colours < the flags given."""
    from app.recipes import adversarial as rcp

    options = {"environment": DEFAULT_LIGHTING, "lighting": None, "true_label": "",
               "target": "", "azimuth": 0.0, "azimuths": None, "classifier": None,
               "color": list(DEFAULT_COLOR), "face_colors": None}
    saved = saved_panel(args, PANEL)
    if saved is not None:
        options.update(saved["options"])
    if input_project(args) is None:
        C = rcp.read_face_colors((args.mesh, len(data.V), len(data.F)), data.F)
        options["face_colors"] = None if C is None else rcp.face_colors_ref(C)
    if args.lighting is not None:
        options.update(_lighting_arg(args.lighting))
    if args.classifier:
        options["classifier"] = rcp.load_classifier_file(args.classifier)[1]
    if args.color is not None:
        options["color"] = [float(x) for x in args.color]
    if args.target is not None:
        options["target"] = args.target
    options["random_baseline"] = True
    return options


def recognized_views(args, state, params, options: dict, say) -> list[float]:
    """``--label``: the azimuths (best first, at most ``params.views``) among 24 around the
    shape (at the camera elevation) whose view the classifier gets right, under the run's own
    lighting and colours; refused when there is none."""
    from algorithms.adversarial import find_recognized_views, short_name
    from app.recipes import adversarial as rcp

    clf = rcp.classifier_of(options.get("classifier"))
    k = rcp.resolve_label(args.label, clf.class_names)
    scene, _ = rcp.scene_and_cameras(state, params, options, 1)  # the scene the run attacks
    found = find_recognized_views(scene, clf, k, candidates=24, elevation=params.elevation,
                                  width=params.view_width, resolution=params.resolution,
                                  supersample=params.supersample)
    if not found:
        raise ParameterError(
            f"The classifier does not see '{short_name(clf.class_names[k])}' in any of 24 "
            "views around the shape (30 degrees up), so there is nothing to attack. Try "
            "another --label, or leave it out to attack whatever it sees.")
    if len(found) < params.views:
        say(f"only {len(found)} of 24 views are recognized; attacking those")
    return [a for a, _ in found[:params.views]]


def cmd_adversary(args: argparse.Namespace) -> int:
    """Parametric adversary (thesis ch. 3): perturb the SH lighting or the vertices within an
    L-infinity ball until an image classifier misclassifies the views; random baseline of the
    same norm on the same views."""
    from algorithms.adversarial import AdversaryParams, short_name
    from algorithms.adversarial.lighting_io import write_lighting
    from app.cli.attributes import write_result
    from app.recipes import adversarial as rcp

    t0 = time.perf_counter()
    params = method_params(args, AdversaryParams, panel=PANEL)
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
    state = input_state(args, data)
    say = (lambda text: None) if args.json or args.quiet else (
        lambda text: print(text, file=sys.stderr, flush=True))
    options = adversary_options(args, data)
    if args.label:
        options["true_label"] = args.label
        options["azimuths"] = recognized_views(args, state, params, options, say)
    recipe = method_recipe("adversarial", rcp.GEOMETRY if params.mode == "geometry"
                           else rcp.LIGHTING)
    last = None
    for last in recipe.steps(state, params, options, {}):
        say(f"{last.message}; " + "; ".join(f"view {b + 1}: {t[0][0]} {100 * t[0][1]:.0f}%"
                                            for b, t in enumerate(last.top5)))
    out = recipe.outcome(last)
    if args.output:
        if params.mode == "geometry":
            write_result(args, args.output, recipe.result(state, last, options).V, data.F,
                         data)
        else:
            write_lighting(args.output, out["lighting"])
    names = rcp.class_names_of(rcp.classifier_of(options.get("classifier")))
    views = [{"label_before": short_name(names[out["label_before"][b]]),
              "confidence_before": float(out["confidence_before"][b]),
              "label_after": short_name(names[out["label_after"][b]]),
              "confidence_after": float(out["confidence_after"][b]),
              "success": bool(out["fooled"][b])} for b in range(len(out["fooled"]))]
    report = {"views": views, "success_rate": out["success_rate"],
              "random_success_rate": out["random_success_rate"],
              "norm": out["norm"], "seconds": time.perf_counter() - t0}
    if args.json:
        print_json(report)
    else:
        azimuths = rcp.azimuths_of(options, params.views)
        for b, v in enumerate(views):
            print(f"view {b + 1} (azimuth {azimuths[b]:.0f}°): {v['label_before']} "
                  f"{100 * v['confidence_before']:.0f}% -> {v['label_after']} "
                  f"{100 * v['confidence_after']:.0f}% "
                  f"{'fooled' if v['success'] else 'not fooled'}")
        print(f"success rate {100 * report['success_rate']:.0f}%, random perturbation of the "
              f"same norm {100 * report['random_success_rate']:.0f}%; L-inf norm "
              f"{out['norm']:.4g} after {out['iterations']} iterations, "
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
                   help="make the classifier see this class (default: any wrong class, or the "
                        "target saved in a project)")
    s.add_argument("--label", metavar="LABEL",
                   help="the true class: views are chosen among those the classifier gets "
                        "right (default: whatever it sees in evenly spaced views, or the "
                        "project's saved true label and view)")
    s.add_argument("--classifier", metavar="FILE",
                   help="a TorchScript model or EfficientNet-lite0 weights (default: the "
                        "installed ImageNet EfficientNet-lite0, or the one saved in a project)")
    s.add_argument("--lighting", default=None, metavar="NAME|FILE.json",
                   help="the starting lighting: an environment of Ramamoorthi & Hanrahan 2001 ("
                        + ", ".join(ENVIRONMENTS) + ") or a lighting .json file (written by "
                        "-o of a lighting attack or saved by the app's panel). "
                        "Default: Grace Cathedral (a project: the panel's saved lighting).")
    s.add_argument("--color", type=float, nargs=3, default=None, metavar=("R", "G", "B"),
                   help="surface colour when the mesh file (or project) has no per-face "
                        "colours. Default: 0.7 0.7 0.7 (a project: the panel's saved colour).")
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
