"""``stylize3d augment`` and ``stylize3d augment-train``: rendered adversarial data augmentation
(thesis §3.5).

* ``augment MESH... --label LABEL -o DATASET`` renders each mesh ``--count`` times under the
  base lighting (``--lighting none``), a random light in the norm ball around it (``random``)
  or the lighting attack against the classifier from such a random light (``adversarial``),
  from random views, distances and backgrounds, into ``DATASET/LABEL/NNNN.png`` with
  ``DATASET/manifest.jsonl``. A thin wrapper around :func:`app.recipes.augment.dataset_steps`
  (the Adversarial lighting panel's *Make training images…* runs the same recipe on its mesh).
  Running it again skips the images already made (same settings, same seed: same images);
  images made with other settings are replaced only with ``--overwrite``.
* ``augment-train DATASET... -o W.pt`` fine-tunes the classifier's last layers on the images
  (the ImageNet classes named by the dataset folders, :mod:`algorithms.adversarial.finetune`);
  ``stylize3d adversary --classifier W.pt`` and the panel's *Load…* take the weights.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from algorithms.errors import ParameterError
from app.cli.common import (MESH_HELP, Terminated, add_params_arguments,
                            add_params_file_argument, check_output, method_params, print_json,
                            read_valid)
from app.cli.common import say as common_say

COMMANDS = ("augment", "augment-train")
PANEL = "Adversarial lighting"


def _say(args):
    if args.json or args.quiet:
        return lambda text: None
    return lambda text: print(text, file=sys.stderr, flush=True)


def _classifier_ref(args) -> str | None:
    if not args.classifier:
        return None
    from app.recipes import adversarial as rcp

    return rcp.load_classifier_file(args.classifier)[1]


def _meshes(args, say) -> list:
    """``(name, state, colour options)`` of every input (read and checked first: a missing or
    broken mesh stops the command before anything is written)."""
    from app.document import MeshState
    from app.project import is_project_path, read_project
    from app.recipes import adversarial as rcp

    out = []
    for path in args.meshes:
        data, _ = read_valid(path, clean=args.clean, quiet=args.json or args.quiet)
        own = {"color": [float(x) for x in (args.color or rcp.DEFAULT_COLOR)],
               "face_colors": None}
        if is_project_path(path):
            saved = read_project(path).options_of(PANEL) or {}
            own.update({k: saved[k] for k in ("color", "face_colors") if k in saved})
        else:
            C = rcp.read_face_colors((path, len(data.V), len(data.F)), data.F)
            if C is not None:
                own["face_colors"] = rcp.face_colors_ref(C)
            elif args.color is None:
                say(f"{path}: no colours in the file; using grey 0.7 (--color to choose)")
        out.append((path, MeshState.make(data.V, data.F), own))
    return out


def cmd_augment(args: argparse.Namespace) -> int:
    """Training images of meshes under random or adversarial lighting (thesis §3.5)."""
    from algorithms.adversarial.augment import AugmentParams
    from app.recipes import augment as aug

    t0 = time.perf_counter()
    say = _say(args)
    params = method_params(args, AugmentParams)
    if args.workers is not None and args.workers < 1:
        raise ParameterError(f"--workers must be at least 1 (got {args.workers}).")
    aug.check_dataset_folder(args.output, args.overwrite)
    meshes = _meshes(args, say)
    options = {"dataset": args.output, "label": args.label, "overwrite": args.overwrite,
               "classifier": _classifier_ref(args)}
    workers = args.workers or max(1, min(2, len(meshes), os.cpu_count() or 1))
    last = None
    try:
        for last in aug.dataset_steps(meshes, params, options, workers=workers):
            if last.record:
                rec = last.record
                extra = f" ({rec['note']})" if rec.get("note") else ""
                say(f"[{last.iteration}/{last.total}] {last.message}{extra}")
    except KeyboardInterrupt as e:  # Ctrl+C, or SIGTERM (common.Terminated)
        term = isinstance(e, Terminated)
        done = last.iteration if last is not None and last.record else 0
        common_say(f"stylize3d augment: {'stopped (SIGTERM)' if term else 'interrupted'}. "
                   f"The {done} image(s) made are kept and listed in "
                   f"{os.path.join(args.output, aug.MANIFEST)}; run the same command again to "
                   "make the rest.")
        return 143 if term else 130
    s = dict(last.summary)
    seconds = time.perf_counter() - t0
    notes = [r for r in aug.read_manifest(args.output).values()
             if r.get("note") and r.get("label") == s["label"]]
    report = {"dataset": str(args.output), "label": s["label"], "lighting": params.lighting,
              "meshes": len(meshes), "count": params.count, "made": s["made"],
              "skipped": s["skipped"], "fooled": s.get("fooled", 0),
              "mean_true_probability_before": s.get("mean_true_probability_before"),
              "mean_true_probability_after": s.get("mean_true_probability_after"),
              "images_with_notes": len(notes), "workers": workers, "seconds": seconds,
              "images_per_second": s["made"] / seconds if seconds > 0 else 0.0,
              "resolution": params.resolution, "iterations": params.iterations}
    if args.json:
        print_json(report)
        return 0
    print(f"{s['made']} image(s) made, {s['skipped']} already there, in "
          f"{os.path.join(args.output, s['label'])} ({seconds:.1f} s, "
          f"{report['images_per_second']:.2f} images/s, {workers} worker(s))")
    if s["made"]:
        print(f"the classifier's probability of '{s['label']}': "
              f"{100 * report['mean_true_probability_before']:.0f}% -> "
              f"{100 * report['mean_true_probability_after']:.0f}% on average; it missed it on "
              f"{s['fooled']} of {s['made']} image(s)")
    if notes and params.lighting == "adversarial":
        print(f"{len(notes)} image(s) of '{s['label']}' in the dataset have a note (the attack "
              "did not fool the classifier within its iterations, or the start already did); "
              f"see {os.path.join(args.output, aug.MANIFEST)}")
    return 0


def cmd_augment_train(args: argparse.Namespace) -> int:
    """Fine-tune the classifier's last layers on image datasets (thesis §3.5)."""
    from algorithms.adversarial.finetune import FinetuneParams, save_finetuned
    from algorithms.adversarial.labels import short_name
    from app.recipes import augment as aug

    t0 = time.perf_counter()
    say = _say(args)
    params = method_params(args, FinetuneParams)
    if not args.output.lower().endswith(".pt"):
        raise ParameterError(f"Name the weights file *.pt (got '{args.output}').")
    check_output(args.output, args.overwrite)
    first = last = None
    for last in aug.train_steps(args.datasets, params, {"classifier": _classifier_ref(args)}):
        if first is None:
            first = last
            say(f"{len(last.files)} images of {len(last.class_indices)} class(es): "
                + ", ".join(short_name(n) for n in last.classifier.class_names))
        say(last.message)
    save_finetuned(args.output, last, last.class_indices,
                   extra={"epochs": int(params.epochs), "images": len(last.files),
                          "datasets": [str(d) for d in args.datasets]})
    seconds = time.perf_counter() - t0
    report = {"weights": str(args.output),
              "classes": [short_name(n) for n in last.classifier.class_names],
              "images": len(last.files), "epochs": int(params.epochs),
              "accuracy_before": first.metrics["accuracy"],
              "accuracy_after": last.metrics["accuracy"], "loss_before": first.metrics["loss"],
              "loss_after": last.metrics["loss"], "seconds": seconds}
    if args.json:
        print_json(report)
        return 0
    print(f"wrote {args.output}: {len(report['classes'])} class(es), training accuracy "
          f"{100 * report['accuracy_before']:.1f}% (the base classifier restricted to them) -> "
          f"{100 * report['accuracy_after']:.1f}% after {params.epochs} epoch(s), "
          f"{seconds:.1f} s. Use it: stylize3d adversary MESH --classifier {args.output}")
    return 0


def add_parsers(sub) -> None:
    from algorithms.adversarial.augment import AugmentParams
    from algorithms.adversarial.finetune import FinetuneParams

    s = sub.add_parser("augment", help="training images under random or adversarial lighting "
                                       "(thesis §3.5)")
    s.add_argument("meshes", nargs="+", metavar="MESH", help=MESH_HELP)
    s.add_argument("--label", required=True,
                   help="what the meshes are: a class of the classifier (e.g. orange); the "
                        "images go to DATASET/LABEL/")
    s.add_argument("-o", "--output", required=True, metavar="DATASET",
                   help="the dataset folder (made if missing; running again adds what is "
                        "missing)")
    s.add_argument("--classifier", metavar="FILE",
                   help="attack this classifier (TorchScript, EfficientNet-lite0 weights or "
                        "augment-train's .pt; default: the installed ImageNet EfficientNet-lite0)")
    s.add_argument("--color", type=float, nargs=3, default=None, metavar=("R", "G", "B"),
                   help="surface colour of a mesh file without colours (default 0.7 grey)")
    s.add_argument("--workers", type=int, default=None,
                   help="worker processes (default: 2 for several meshes, else 1)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace images made with other settings, or write into a folder "
                        "that is not a dataset")
    s.add_argument("--json", action="store_true",
                   help='print {"dataset", "label", "made", "skipped", "fooled", '
                        '"mean_true_probability_before", "mean_true_probability_after", '
                        '"images_per_second", "seconds", ...}')
    s.add_argument("--quiet", action="store_true", help="no per-image progress")
    s.add_argument("--clean", action="store_true", help="clean the meshes first")
    add_params_file_argument(s)
    add_params_arguments(s, AugmentParams)
    s.set_defaults(func=cmd_augment)

    t = sub.add_parser("augment-train", help="fine-tune the classifier on augment's images "
                                             "(thesis §3.5)")
    t.add_argument("datasets", nargs="+", metavar="DATASET",
                   help="dataset folders (DATASET/LABEL/*.png; LABEL a class of the classifier)")
    t.add_argument("-o", "--output", required=True, metavar="W.pt",
                   help="the fine-tuned weights (with their class names)")
    t.add_argument("--classifier", metavar="FILE",
                   help="start from this EfficientNet-lite0 classifier (default: the installed "
                        "ImageNet one)")
    t.add_argument("--overwrite", action="store_true", help="replace W.pt if it exists")
    t.add_argument("--json", action="store_true",
                   help='print {"weights", "classes", "images", "epochs", "accuracy_before", '
                        '"accuracy_after", "loss_before", "loss_after", "seconds"}')
    t.add_argument("--quiet", action="store_true", help="no per-epoch progress")
    add_params_file_argument(t)
    add_params_arguments(t, FinetuneParams)
    t.set_defaults(func=cmd_augment_train)
