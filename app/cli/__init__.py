"""Batch sub-commands of ``stylize3d``. Imports no Qt and no VTK.

Every sub-command prints a plain message and exits non-zero on bad input (the exit status is the
error's ``exit_code``: 2 unreadable file, 3 unwritable file, 4 invalid mesh, 5 bad parameter,
6 an iterative solve that did not converge; 70 an unexpected failure, whose traceback goes to a
crash-log file, never to the screen; a segfault or abort too, through the supervisor of
:mod:`app.crashlog`).
Method flags are generated from the methods' Params dataclasses (one definition per parameter);
every method sub-command takes a mesh file or a project (``.s3d``) and ``--params FILE.json``
(precedence: see :mod:`app.cli.common`).

One module per method family registers its sub-parsers (``COMMANDS``, ``add_parsers(sub)``):
:mod:`~app.cli.mesh_tools` (info, clean), :mod:`~app.cli.smooth` (smooth, multigrid-info),
:mod:`~app.cli.deform` (cubic), :mod:`~app.cli.analogy`, :mod:`~app.cli.study`, :mod:`~app.cli.spectral`
(coarsen), :mod:`~app.cli.paparazzi`, :mod:`~app.cli.adversary`, :mod:`~app.cli.augment`
(augment, augment-train), :mod:`~app.cli.subdivision`
(subdivide, subdivide-train, subdivide-eval).
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import os
import sys
from pathlib import Path

from algorithms.errors import Stylize3DError
from app.cli.common import INTERNAL_ERROR_EXIT, say, silence_stdout, write_crash_log

#: the modules that add sub-commands (``app/cli/<name>.py``), in the order of
#: ``stylize3d --help``, with the sub-commands each adds (its ``COMMANDS``; a test keeps the
#: two in step). A sub-command imports only its own module (start-up time: ``stylize3d info``
#: must not import what ``paparazzi`` needs).
COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "mesh_tools": ("info", "clean"),
    "smooth": ("smooth", "multigrid-info"),
    "deform": ("cubic",),
    "analogy": ("analogy",),
    "study": ("study",),
    "spectral": ("coarsen",),
    "paparazzi": ("paparazzi",),
    "adversary": ("adversary",),
    "augment": ("augment", "augment-train"),
    "subdivision": ("subdivide", "subdivide-train", "subdivide-eval"),
    "batch": ("batch",),
}
SUBCOMMANDS: tuple[str, ...] = tuple(c for cs in COMMAND_MODULES.values() for c in cs)
_MODULE_OF = {c: m for m, cs in COMMAND_MODULES.items() for c in cs}

#: names re-exported lazily (PEP 562): ``app.cli.cmd_cubic`` imports :mod:`app.cli.deform`
_LAZY = {
    "cmd_adversary": "adversary", "cmd_augment": "augment", "cmd_augment_train": "augment",
    "cmd_analogy": "analogy", "cmd_cubic": "deform",
    "cmd_clean": "mesh_tools", "cmd_info": "mesh_tools", "cmd_paparazzi": "paparazzi",
    "cmd_multigrid_info": "smooth", "cmd_smooth": "smooth", "cmd_coarsen": "spectral",
    "cmd_study": "study", "cmd_subdivide": "subdivision", "cmd_subdivide_eval": "subdivision",
    "cmd_subdivide_train": "subdivision",
    "add_params_arguments": "common", "method_params": "common", "params_from_args": "common",
    "read_valid": "common", "settings": "common",
}


def command_module(command: str):
    """The module ``app.cli.<name>`` that adds sub-command ``command`` (imported now)."""
    return importlib.import_module(f"app.cli.{_MODULE_OF[command]}")


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f"app.cli.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    if name == "MODULES":  # every sub-command module, imported (for --help and tests)
        return tuple(importlib.import_module(f"app.cli.{m}") for m in COMMAND_MODULES)
    if name in COMMAND_MODULES:  # app.cli.deform etc. as attributes, as plain imports gave
        return importlib.import_module(f"app.cli.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``stylize3d`` parser: every sub-command, or only those of ``command``'s module (the
    only module imported then; how :func:`main` parses a command line)."""
    p = argparse.ArgumentParser(
        prog="stylize3d",
        description="Stylize3D: stylize and process 3D surface meshes. With no sub-command, "
                    "opens the app (optionally on MESH).")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    names = COMMAND_MODULES if command is None else (_MODULE_OF[command],)
    for name in names:
        importlib.import_module(f"app.cli.{name}").add_parsers(sub)
    return p


def unknown_command(word: str) -> str | None:
    """The message for a first argument that is neither a sub-command nor something the app
    can open, or None. An option, an existing file or folder, a name with a mesh or project
    extension, or a path opens the app as before; a bare word is a mistyped command."""
    if not word or word.startswith("-") or word in SUBCOMMANDS:
        return None
    p = Path(word)
    if p.exists() or p.suffix or os.sep in word or "/" in word:
        return None
    close = difflib.get_close_matches(word, SUBCOMMANDS, n=1, cutoff=0.6)
    if close:
        return f"stylize3d: unknown command '{word}'. Did you mean '{close[0]}'?"
    return (f"stylize3d: unknown command '{word}' (and there is no file of that name). The "
            f"commands are: {', '.join(SUBCOMMANDS)}; 'stylize3d MESH' opens a mesh in the app.")


def main(argv: list[str]) -> int:
    argv = list(argv)
    if argv and not argv[0].startswith("-") and argv[0] not in SUBCOMMANDS:
        say(unknown_command(argv[0]) or f"stylize3d: unknown command '{argv[0]}'.")
        return 2
    parser = build_parser(argv[0] if argv and argv[0] in SUBCOMMANDS else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse already printed a usage message
        return int(e.code or 0)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    # through this package's namespace, so that a command replaced here (tests, scripts) runs
    func = globals().get(args.func.__name__, args.func)
    from app import crashlog
    from app.cli import common

    from app.cli import attributes

    common.json_printed(reset=True)
    crashlog.last_said(reset=True)
    attributes.reset()  # no UV status of an earlier command in this one's --json
    want_json = bool(getattr(args, "json", False)) or "--json" in argv

    def failed(message: str, code: int) -> int:
        """Say why the command stopped; with ``--json`` also as the one JSON object on stdout
        (unless the command printed its own)."""
        say(f"stylize3d {args.command}: {message}")
        if want_json and not common.json_printed():
            try:
                common.print_json_failure(args.command, message, code)
                sys.stdout.flush()
            except (BrokenPipeError, OSError, ValueError):
                pass
        return code

    try:
        code = int(func(args))
        if code and want_json and not common.json_printed():  # refused without raising
            said = crashlog.last_said() or f"the command stopped with exit status {code}."
            prefix = f"stylize3d {args.command}: "
            common.print_json_failure(args.command, said[len(prefix):] if
                                      said.startswith(prefix) else said, code)
        sys.stdout.flush()  # a closed pipe (`stylize3d info MESH | head`) shows up here
        return code
    except Stylize3DError as e:
        return failed(str(e), e.exit_code)
    except KeyboardInterrupt as e:
        term = isinstance(e, common.Terminated)
        text = ("stopped (SIGTERM)" if term else "interrupted") + "; nothing was written."
        code = 143 if term else 130
        say(f"stylize3d: {text}")
        if want_json and not common.json_printed():
            common.print_json_failure(args.command, text, code)
        return code
    except BrokenPipeError:
        # the reader of our output went away (e.g. `| head`): not an error of ours, and Python
        # must not print a second traceback when it flushes stdout at exit
        silence_stdout()
        return 0
    except MemoryError:
        return failed("this machine ran out of memory; nothing was written. Try a smaller mesh "
                      "(decimate it first) or the options for big meshes (e.g. "
                      "--progressive-faces for cubic, --solver multigrid for smooth).",
                      INTERNAL_ERROR_EXIT)
    except Exception as e:  # a defect of ours: say so plainly, never a bare traceback
        import traceback

        log = write_crash_log(traceback.format_exc())
        return failed(f"an unexpected error stopped the command ({type(e).__name__}: {e}); "
                      "nothing was written. This is a bug in Stylize3D"
                      + (f"; the details are in {log}." if log else "."), INTERNAL_ERROR_EXIT)


# ----------------------------------------------------------------------------- GUI
class _Version(argparse.Action):
    """``--version``: the installed package's version (looked up only when asked)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="print the version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        import app

        print(f"stylize3d {app.__version__}")
        parser.exit()


def gui_main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="stylize3d", description="Open the Stylize3D app.",
                                epilog="Batch sub-commands: " + ", ".join(SUBCOMMANDS)
                                + " (stylize3d COMMAND --help).")
    p.add_argument("mesh", nargs="?", help="mesh file or project (.s3d) to open")
    p.add_argument("--version", action=_Version)
    p.add_argument("--screenshot", metavar="PNG",
                   help="save a screenshot of the window once the mesh is shown, then quit")
    g = p.add_argument_group("user-study mode")
    g.add_argument("--study", metavar="PROTOCOL",
                   help="run a study session from a protocol file (.json or .toml)")
    g.add_argument("--participant", metavar="CODE",
                   help="participant code (otherwise the start dialog asks)")
    g.add_argument("--condition", metavar="NAME",
                   help="study condition (otherwise the start dialog asks)")
    g.add_argument("--log-dir", metavar="DIR",
                   help="where session logs and results go (default: logs/ next to the protocol)")
    args = p.parse_args(argv)
    study = None
    if args.study:
        from app.study.protocol import load_protocol

        try:  # a malformed protocol is a plain message before any window opens
            load_protocol(args.study)
        except Stylize3DError as e:
            say(f"stylize3d: {e}")
            return e.exit_code
        study = {"protocol": args.study, "participant": args.participant,
                 "condition": args.condition, "log_dir": args.log_dir}
    from app.gui import run_app  # Qt is imported only here

    if study is None:
        return run_app(args.mesh, screenshot=args.screenshot)
    return run_app(args.mesh, screenshot=args.screenshot, study=study)


__all__ = ["COMMAND_MODULES", "INTERNAL_ERROR_EXIT", "SUBCOMMANDS", "add_params_arguments",
           "build_parser", "cmd_adversary", "cmd_analogy", "cmd_clean", "cmd_coarsen",
           "command_module",
           "cmd_cubic", "cmd_info", "cmd_multigrid_info", "cmd_paparazzi", "cmd_smooth",
           "cmd_study", "cmd_subdivide", "cmd_subdivide_eval", "cmd_subdivide_train",
           "gui_main", "main", "method_params", "params_from_args", "read_valid", "settings",
           "unknown_command"]
