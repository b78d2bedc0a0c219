"""What every sub-command shares: flags generated from Params, the input (a mesh file or a
project), the precedence of settings, output checks, JSON printing, exit codes, the crash log.

Settings of a method, lowest to highest precedence (:func:`settings`, :func:`method_params`):

1. the defaults (the Params dataclass's, or the command's own flag defaults);
2. the settings saved for the method's panel in a project file given as the input mesh
   (``scene.s3d``: ``Project.panels[title]["params"]``);
3. a ``--params FILE.json`` file (a JSON object of the same names, e.g. a panel's saved
   settings); a name the method does not have is an error (exit status 5);
4. the flags given on the command line.

Params flags are added with ``default=argparse.SUPPRESS``: a flag that was not given is absent
from the parsed arguments, so it never hides a saved or ``--params`` value (the help still
shows the default). Flags a command defines by hand use ``None`` for "not given".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Any, Iterable

from algorithms.errors import InvalidMeshError, MeshWriteError, ParameterError
from algorithms.params import describe, params_from_dict, params_to_dict
from app.crashlog import say  # stderr, never a traceback (one implementation)

#: exit status of an unexpected failure (a defect, or the machine ran out of memory)
INTERNAL_ERROR_EXIT = 70

#: the help of a method's positional input
MESH_HELP = "mesh file (.obj .ply .stl .off .glb) or a Stylize3D project (.s3d)"


# ----------------------------------------------------------------------------- Params -> flags
def add_params_arguments(parser: argparse.ArgumentParser, params_cls: type) -> None:
    """Add one flag per field of ``params_cls`` (ranges and help from its metadata). A flag that
    is not given is absent from the parsed arguments (see the module docstring)."""
    group = parser.add_argument_group("method parameters")
    for spec in describe(params_cls):
        lo = "" if spec.minimum is None else f"{spec.minimum:g}"
        hi = "" if spec.maximum is None else f"{spec.maximum:g}"
        rng = f" Range {lo or '-inf'}..{hi or 'inf'}." if (lo or hi) else ""
        help_text = f"{spec.tooltip}{rng} Default: {spec.default}."
        help_text = help_text.replace("%", "%%")
        flags = (spec.flag, *spec.cli_aliases)
        if spec.type is bool:
            group.add_argument(*flags, dest=spec.name, action=argparse.BooleanOptionalAction,
                               default=argparse.SUPPRESS, help=help_text)
        elif spec.type is str:
            group.add_argument(*flags, dest=spec.name, default=argparse.SUPPRESS,
                               choices=spec.choices, help=help_text)
        else:
            group.add_argument(*flags, dest=spec.name, type=spec.type, default=argparse.SUPPRESS,
                               metavar=spec.name.upper(), help=help_text)


def add_params_file_argument(parser: argparse.ArgumentParser) -> None:
    """``--params FILE.json``: the method's settings from a file (module docstring)."""
    parser.add_argument(
        "--params", dest="params_file", metavar="FILE.json",
        help="the method's settings from a JSON object of its parameter names (e.g. a panel's "
             "saved settings). Precedence: defaults < the settings saved in a project given as "
             "input < this file < the flags given here.")


def params_from_args(params_cls: type, args: argparse.Namespace) -> Any:
    """Params from the flags alone (defaults where a flag was not given)."""
    return method_params(args, params_cls, use_file=False)


# ----------------------------------------------------------------------------- settings
def _project_path(args: argparse.Namespace) -> str | None:
    path = getattr(args, "mesh", None)
    from app.project import is_project_path

    return str(path) if path is not None and is_project_path(path) else None


def input_project(args: argparse.Namespace):
    """The :class:`app.project.Project` given as the input mesh (read once), or None."""
    path = _project_path(args)
    if path is None:
        return None
    cached = getattr(args, "_project", None)
    if cached is None or cached[0] != path:
        from app.project import read_project

        cached = (path, read_project(path))
        args._project = cached
    return cached[1]


def saved_panel(args: argparse.Namespace, title: str | None) -> dict | None:
    """``{"params": ..., "options": ...}`` saved for panel ``title`` in the input project, or
    None (no project, or nothing saved for that panel)."""
    project = input_project(args) if title else None
    if project is None or title not in (project.panels or {}):
        return None
    return {"params": project.params_of(title), "options": project.options_of(title)}


def params_file(args: argparse.Namespace) -> dict:
    """The JSON object of ``--params`` (read once), or {}."""
    path = getattr(args, "params_file", None)
    if not path:
        return {}
    cached = getattr(args, "_params_values", None)
    if cached is not None:
        return cached
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParameterError(f"--params: there is no file {path}.") from None
    except (OSError, UnicodeDecodeError) as e:
        why = getattr(e, "strerror", None) or e
        raise ParameterError(f"--params: {path} cannot be read ({why}).") from None
    try:
        values = json.loads(text)
    except ValueError as e:
        raise ParameterError(f"--params: {path} is not valid JSON ({e}).") from None
    if not isinstance(values, dict):
        raise ParameterError(f"--params: {path} must hold a JSON object of parameter names and "
                             'values, e.g. {"lam": 0.4}.')
    args._params_values = values
    return values


def check_params_file(args: argparse.Namespace, allowed: Iterable[str]) -> None:
    """Refuse names in the ``--params`` file that the command does not have (exit status 5)."""
    allowed = set(allowed)
    unknown = sorted(set(params_file(args)) - allowed)
    if unknown:
        import difflib

        hints = []
        for name in unknown:
            close = difflib.get_close_matches(name, sorted(allowed), n=1)
            hints.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        raise ParameterError(
            f"--params: {args.params_file} has setting(s) that {args.command} does not have: "
            f"{', '.join(hints)}. Its settings are: {', '.join(sorted(allowed))}.")


def settings(args: argparse.Namespace, defaults: dict, *, panel: str | None = None,
             allowed: Iterable[str] | None = None, use_file: bool = True) -> dict:
    """``defaults`` < the input project's saved ``panel`` params < ``--params`` < given flags.

    Only names of ``defaults`` are taken from each layer. ``allowed``: every name the
    ``--params`` file may hold for this command (default: those of ``defaults``); others are
    refused. A flag counts as given when its name is in ``args`` with a value other than None.
    """
    values = dict(defaults)
    saved = saved_panel(args, panel)
    if saved is not None:
        values.update({k: v for k, v in saved["params"].items() if k in defaults})
    if use_file:
        check_params_file(args, defaults if allowed is None else allowed)
        values.update({k: v for k, v in params_file(args).items() if k in defaults})
    given = vars(args)
    values.update({k: given[k] for k in defaults if given.get(k) is not None})
    return values


def method_params(args: argparse.Namespace, params_cls: type, *, panel: str | None = None,
                  allowed: Iterable[str] | None = None, use_file: bool = True) -> Any:
    """The method's Params by the precedence of :func:`settings` (validated)."""
    specs = {s.name: s for s in describe(params_cls)}
    values = settings(args, {s.name: s.default for s in specs.values()}, panel=panel,
                      allowed=allowed, use_file=use_file)
    for k, v in values.items():  # JSON's 3.0 for a whole-number field
        if specs[k].type is int and isinstance(v, float) and v.is_integer():
            values[k] = int(v)
    return params_from_dict(params_cls, values)


def field_names(*params_classes: type) -> set[str]:
    return {f.name for cls in params_classes for f in dataclasses.fields(cls)}


# ----------------------------------------------------------------------------- input / output
def read_valid(path: str, *, clean: bool = False, quiet: bool = False, project=None):
    """Read a mesh a method can process: a mesh file or the mesh of a project (``.s3d``).

    Errors and fixable problems are refused with the report (and a hint to clean), unless
    ``clean`` is set: then the mesh is cleaned and what was done is printed to stderr (a project
    whose painted fields or handles would be lost by cleaning is refused instead).
    Returns ``(MeshData, report)``.
    """
    from algorithms.mesh import MeshData, clean_mesh, read_mesh, validate_mesh
    from app.project import is_project_path, read_project

    if is_project_path(path):
        project = project if project is not None else read_project(path)
        data = MeshData(project.state.V, project.state.F, [])
    else:
        project = None
        data = read_mesh(path)
    report = validate_mesh(data.V, data.F, notes=data.notes)
    if clean and (report.errors or report.needs_cleaning):
        if project is not None and (project.state.fields or project.state.handles):
            raise InvalidMeshError(
                f"{path}: the project's mesh needs cleaning, which renumbers its vertices and "
                f"would lose what was painted and placed on it:\n{report.summary()}\nClean it "
                "in the app (Edit > Clean Mesh), save the project again, then run this command.")
        res = clean_mesh(data.V, data.F)
        if not quiet:
            for a in res.actions:
                print(f"clean: {a}", file=sys.stderr)
        data = MeshData(res.V, res.F, list(data.notes) + list(res.actions))
        report = validate_mesh(data.V, data.F, notes=data.notes)
    if report.blocking:
        hint = ("" if clean or not report.needs_cleaning else
                f"\nAdd --clean to fix what can be fixed first, or run: "
                f"stylize3d clean {path} -o cleaned"
                f"{'.obj' if project is not None else Path(path).suffix}")
        raise InvalidMeshError(f"{path} cannot be processed as it is:\n{report.summary()}{hint}")
    return data, report


def read_input(args: argparse.Namespace, *, quiet: bool = False):
    """``read_valid`` of ``args.mesh`` (a project is read once): ``(MeshData, report)``."""
    return read_valid(args.mesh, clean=getattr(args, "clean", False), quiet=quiet,
                      project=input_project(args))


def input_state(args: argparse.Namespace, data):
    """The MeshState a recipe runs on: the project's (painting, handles) or the mesh's."""
    from app.document import MeshState

    project = input_project(args)
    if project is not None and project.state.V.shape == data.V.shape:
        return project.state
    return MeshState.make(data.V, data.F)


def check_output(path: str, overwrite: bool, inp: str | None = None) -> None:
    out = Path(path)
    if inp is not None and out.exists() and os.path.samefile(out, inp) and not overwrite:
        raise MeshWriteError(f"{path} is the input file; pass --overwrite to replace it.")
    if out.exists() and not overwrite:
        raise MeshWriteError(f"{path} already exists; pass --overwrite to replace it.")
    if out.is_dir():
        raise MeshWriteError(f"{path} is a folder, not a file name.")


class Terminated(KeyboardInterrupt):
    """SIGTERM (what SLURM, Kubernetes and ``kill`` send) arrived: stop like Ctrl+C (clean up,
    say so, exit 143; a batch is resumable) instead of dying without a word."""


def stop_on_sigterm() -> None:
    """In the main thread: SIGTERM raises :class:`Terminated` (issue 39, item 6)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def _raise(signum, frame):
        raise Terminated()

    try:
        signal.signal(signal.SIGTERM, _raise)
    except (ValueError, OSError):  # not the main interpreter's main thread
        pass


_JSON_PRINTED = [False]  # whether this command printed its JSON object (app.cli.main)


def print_json(obj: dict) -> None:
    _JSON_PRINTED[0] = True
    from app.cli.attributes import LAST

    if LAST and "surface_attributes" not in obj and obj.get("ok", True) is not False:
        obj = {**obj, "surface_attributes": dict(LAST)}
    print(json.dumps(obj, indent=2, sort_keys=False, default=float))


def json_printed(reset: bool = False) -> bool:
    """Whether :func:`print_json` ran (since the last ``reset``)."""
    was = _JSON_PRINTED[0]
    if reset:
        _JSON_PRINTED[0] = False
    return was


def print_json_failure(command: str, message: str, exit_code: int) -> None:
    """The one JSON object of a command given ``--json`` that failed before printing its own:
    ``{"ok": false, "command", "error", "exit_code"}`` (issue 39: a script reading stdout always
    gets one object)."""
    print_json({"ok": False, "command": command, "error": message, "exit_code": exit_code})




def silence_stdout() -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def write_crash_log(text: str) -> str | None:
    """Keep a traceback for the bug report (never on the user's screen) in the crash-log folder
    (:func:`app.crashlog.crash_dir`, ``..._<pid>_error.log``); its path, or None."""
    from app.crashlog import write_error_log

    return write_error_log(text)


def method_recipe(module: str, title: str):
    """The registered :class:`app.recipes.Recipe` ``title`` of ``app/recipes/<module>.py``
    (only that module is imported)."""
    import importlib

    from app import recipes

    importlib.import_module(f"app.recipes.{module}")
    return recipes._RECIPES.get(title) or recipes.get_recipe(title)


__all__ = ["INTERNAL_ERROR_EXIT", "MESH_HELP", "add_params_arguments",
           "add_params_file_argument", "check_output", "check_params_file", "field_names",
           "input_project", "input_state", "json_printed", "method_params", "method_recipe",
           "params_file", "print_json_failure",
           "params_from_args", "params_to_dict", "print_json", "read_input", "read_valid",
           "saved_panel", "say", "settings", "silence_stdout", "stop_on_sigterm",
           "Terminated", "write_crash_log"]
