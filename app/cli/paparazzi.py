"""``stylize3d paparazzi``: image filters applied to a shape through many rendered views
(thesis ch. 2). Filters registered by ``--plugin`` files add their own flags.

A thin wrapper around the recipe "Paparazzi" (:mod:`app.recipes.paparazzi`): Params from the
flags (defaults < a project's saved Paparazzi settings < ``--params`` < flags); the options are
the filter and its parameters (``--filter`` and the filter's flags over, for the same filter,
the project's saved ones; the filter's files, e.g. ``--image``, become blobs) and the plug-in
file the filter comes from. The output is the recipe's result: ``app.recipes.run("paparazzi",
...)`` with the same inputs gives the same mesh bit for bit. The command also checks the result
(a 2-manifold of the input's topology, no new self-intersections) before writing it.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from algorithms.errors import ParameterError, Stylize3DError
from algorithms.params import describe, params_from_dict
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_params, method_recipe,
                            params_to_dict, print_json, read_input, saved_panel)
from app.cli.deform import user_paths

COMMANDS = ("paparazzi",)


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
        # None = not given: the project's saved value (same filter) or the default is used
        if spec.type is bool:
            group.add_argument(flag, dest=dest, action=argparse.BooleanOptionalAction,
                               default=None, help=help_text)
        else:
            group.add_argument(flag, dest=dest, type=spec.type, default=None,
                               choices=spec.choices, metavar=spec.name.upper(), help=help_text)
    for action in s._actions:
        if action.dest == "filter":
            action.choices = filter_names()
            action.help = "the image filter (required unless the input is a project with " \
                "saved Paparazzi settings, whose filter and filter parameters are then " \
                "used): " + "; ".join(
                f"{n}: {get_filter(n).description or 'a user filter'}"
                for n in filter_names()).replace("%", "%%")


def add_parsers(sub) -> None:
    from algorithms.paparazzi.optimize import PaparazziParams

    s = sub.add_parser("paparazzi", help="Paparazzi: image filters applied to a shape through "
                                         "many rendered views (thesis ch. 2)")
    s.__class__ = _PaparazziParser     # same state, plus the --plugin pre-pass above
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("-o", "--output", required=True, help="where to write the filtered mesh")
    s.add_argument("--filter", help="the image filter")
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
    add_params_file_argument(s)
    add_params_arguments(s, PaparazziParams)
    _add_paparazzi_filter_flags(s)
    s.set_defaults(func=cmd_paparazzi)


class _MissingFilter(ParameterError):
    """No ``--filter`` and no saved one: a usage error, argparse's exit status."""

    exit_code = 2


def paparazzi_options(args: argparse.Namespace) -> tuple[dict, Any, dict]:
    """The Paparazzi recipe's options for this run: the filter (``--filter``, else the project's
    saved one, loading its plug-in from the project when needed) and its parameters (defaults <
    the project's saved ones, for the same filter < the flags given here); files become blobs.
    Returns ``(options, the filter's Params as given, {blob reference: path given})``."""
    from app.recipes import is_blob_ref
    from app.recipes.paparazzi import ensure_filter, filter_options

    saved = saved_panel(args, "Paparazzi")
    saved = (saved["options"] or {}) if saved is not None else {}
    name = args.filter or saved.get("filter")
    if not name:
        raise _MissingFilter("the following arguments are required: --filter (unless the "
                             "input is a project (.s3d) with saved Paparazzi settings)")
    same = saved.get("filter") == name
    # the saved plug-in, unless --filter and --plugin name the user's own
    plugin = saved.get("plugin") if same and not (args.filter and args.plugin) else None
    spec = ensure_filter(name, plugin)
    values = {ps.name: ps.default for ps in describe(spec.params)}
    if same:
        values.update({k: v for k, v in (saved.get("filter_params") or {}).items()
                       if k in values})
    for ps in describe(spec.params):
        given = getattr(args, f"pz_{spec.name}_{ps.name}".replace("-", "_"), None)
        if given is not None:
            values[ps.name] = given
    fparams = params_from_dict(spec.params, values)
    options = filter_options(spec.name, fparams)
    named = {v: values[k] for k, v in options["filter_params"].items()
             if is_blob_ref(v) and v != values[k]}
    return options, fparams, named


def paparazzi_job(args: argparse.Namespace) -> tuple:
    """``(params, options)`` of the Paparazzi recipe that ``paparazzi`` runs (for
    ``stylize3d batch``; the filter's files and plug-in become blobs)."""
    from algorithms.paparazzi.optimize import PaparazziParams

    params = method_params(args, PaparazziParams, panel="Paparazzi")
    return params, paparazzi_options(args)[0]


def cmd_paparazzi(args: argparse.Namespace) -> int:
    from app.cli.attributes import write_result
    from algorithms.mesh.topology import euler_characteristic, is_manifold
    from algorithms.paparazzi import count_self_intersections
    from algorithms.paparazzi.optimize import PaparazziParams

    params = method_params(args, PaparazziParams, panel="Paparazzi")
    options, fparams, named = paparazzi_options(args)
    check_output(args.output, args.overwrite, args.mesh)
    quiet = args.json or args.quiet
    data, _ = read_input(args, quiet=quiet)
    state = input_state(args, data)
    recipe = method_recipe("paparazzi", "Paparazzi")
    t0 = time.perf_counter()
    last = None
    report_every = max(1, params.iterations // 10)
    held: dict = {}  # the recipe leaves its optimizer and set-up time here
    with user_paths(named):
        for last in recipe.steps(state, params, options, held):
            if not quiet and (last.iteration % report_every == 0 or last.message):
                print(f"  iteration {last.iteration}/{params.iterations}: monitor energy "
                      f"{last.metrics['monitor_energy']:.6g} {last.message}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    run = held["run"]
    V, F = last.V, last.F
    manifold = bool(is_manifold(F))
    same_topology = euler_characteristic(F) == euler_characteristic(data.F)
    crossings = count_self_intersections(V, F)
    new_crossings = run.new_self_intersections(V, F) if crossings else 0
    if not manifold or not same_topology or new_crossings:
        raise Stylize3DError("Paparazzi failed: the result is not a clean 2-manifold with the "
                             "input's topology; nothing was written. Try a smaller learning rate.")
    after = recipe.result(state, last, options)
    write_result(args, args.output, after.V, after.F, data,
                 how="Paparazzi remakes the triangles when it remeshes, so they have nowhere "
                     "to go")
    outcome = recipe.outcome(last)
    sec = last.seconds
    it = outcome["iterations"]
    if args.json:
        print_json({
            "input": args.mesh, "output": args.output, "filter": options["filter"],
            "filter_params": params_to_dict(fparams), "params": params_to_dict(params),
            "iterations": it, "seconds": seconds, "setup_seconds": held["setup_seconds"],
            "seconds_split": {k: sec.get(k, 0.0) for k in
                              ("render", "filter", "derivative", "remesh", "monitor")},
            "seconds_per_iteration": {k: sec.get(k, 0.0) / it for k in
                                      ("render", "filter", "derivative", "remesh")},
            "learning_rate_used": run.learning_rate,
            "rough_input": run.rough_input,
            "fine_step": run.fine_step,
            # FilterSpec.step_follows_edge (l0, neural-style): the share of vertices whose
            # step on auto was smaller for their thin triangles at the start (None: not such
            # a run)
            "thin_step_share": outcome.get("thin_step_share"),
            "rough_probe": run.rough, "rough_share": run.rough_share,
            "initial_monitor_energy": outcome["initial_monitor_energy"],
            "final_monitor_energy": outcome["monitor_energy"],
            "last_monitor_energy": outcome.get("last_monitor_energy", outcome["monitor_energy"]),
            "kept_iteration": int(outcome.get("kept_iteration", it)),
            "vertices": int(len(after.V)), "faces": int(len(after.F)),
            "manifold": manifold, "same_topology": bool(same_topology),
            "self_intersecting_pairs": crossings,
            "input_self_intersecting_pairs": run.input_intersections,
            "new_self_intersecting_pairs": new_crossings,
            "self_intersections": crossings > 0,
            "remeshes": int(outcome["remeshes"]),
            "rollbacks": int(outcome["rollbacks"]),
            **{k: int(outcome.get(k, 0))
               for k in ("rollbacks_whole", "remesh_rejected", "remesh_retries",
                         "held_vertices", "put_back_vertices", "step_halvings")}})
    else:
        k = int(outcome.get("kept_iteration", it))
        kept = (f" (the shape of iteration {k}, the lowest; the last one's "
                f"{outcome['last_monitor_energy']:.4g})" if k < it else "")
        print(f"Paparazzi '{options['filter']}' on {args.mesh}: {it} iterations in "
              f"{seconds:.1f} s; monitor energy {outcome['initial_monitor_energy']:.4g} -> "
              f"{outcome['monitor_energy']:.4g}{kept}; step {run.learning_rate:g}"
              f"{' (rough surface)' if run.rough_input else ''}"
              f"{' (fine mesh)' if run.fine_step else ''}; "
              f"{len(after.V)} vertices; wrote {args.output}.")
    return 0
