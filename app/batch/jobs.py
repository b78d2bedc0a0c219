"""What a batch runs on every mesh: a :class:`Job` (recipe, params, options, the blobs they
refer to), built once from a method sub-command's own flags, a project's panel settings or a
panel-settings ``.json`` file, exactly as the one-mesh command builds them.

The one-mesh commands' public helpers build the Params and options (``cubic_job``,
``analogy_job`` in :mod:`app.cli.analogy`, ``smooth_job`` in :mod:`app.cli.smooth`,
``subdivide_job`` in :mod:`app.cli.subdivision`, ``paparazzi_job`` in
:mod:`app.cli.paparazzi`); the settings of a project or a ``.json`` file reach them as the
"input project" of :mod:`app.cli.common` (precedence: defaults < the panel's settings <
``--params`` < flags, as for one mesh).

Options that depend on the mesh: ``cubic`` and ``analogy`` go through affine progressive
meshes above ``AUTO_PROGRESSIVE_FACES`` triangles unless told otherwise; the job keeps both
option sets (``options`` and ``large_options``) and the worker takes the one for the mesh's
size, so every output equals the one-mesh command's.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from algorithms.errors import ParameterError, Stylize3DError

#: the format name of a panel-settings file (:func:`write_panel_settings`)
SETTINGS_FORMAT = "stylize3d-panel-settings"


class BatchUsageError(Stylize3DError):
    """A mistyped method, a missing input or output: the CLI's usage errors (exit status 2)."""

    exit_code = 2


# ----------------------------------------------------------------------------- methods
def _cubic(args, panel, n_faces):
    from app.cli.deform import cubic_job

    return ("Cubic", *cubic_job(args, n_faces))


def _analogy(args, panel, n_faces):
    from app.cli.analogy import analogy_job

    return ("Analogies", *analogy_job(args, n_faces))


def _smooth(args, panel, n_faces):
    from app.cli.smooth import smooth_job

    return smooth_job(args, True if panel == "Multigrid smoothing" else None)


def _subdivide(args, panel, n_faces):
    from app.cli.subdivision import subdivide_job

    return ("Subdivision", *subdivide_job(args))


def _paparazzi(args, panel, n_faces):
    from app.cli.paparazzi import paparazzi_job

    return ("Paparazzi", *paparazzi_job(args))


@dataclass(frozen=True)
class MethodSpec:
    """A sub-command with a batch form (it writes one mesh per input).

    command : the sub-command ("cubic"); module : its :mod:`app.cli` module.
    panels : the app panels whose settings it takes (the first is its own).
    build : ``(args, panel title or None, n_faces) -> (recipe title, Params, options)``.
    sized : the options may change above ``AUTO_PROGRESSIVE_FACES`` triangles.
    bytes_per_face : peak memory a run needs per input triangle on top of the worker's own
        (about twice what was measured on armadillo and bob, see docs/batch.md; a function of
        the params dict where it depends on them); used to refuse a mesh that would not fit
        the memory limit before running it.
    option_defaults : option values of a fresh panel (to tell which panel of a project was
        changed).
    """

    command: str
    module: str
    panels: tuple[str, ...]
    build: Callable[[argparse.Namespace, str | None, int], tuple]
    sized: bool = False
    bytes_per_face: float | Callable[[dict], float] = 20_000.0
    option_defaults: dict = field(default_factory=dict)


METHODS: dict[str, MethodSpec] = {
    "cubic": MethodSpec("cubic", "deform", ("Cubic",), _cubic, sized=True,
                        bytes_per_face=10_000.0,
                        option_defaults={"plane_axis": 0, "progressive": None,
                                         "multigrid": False}),
    "analogy": MethodSpec("analogy", "analogy", ("Analogies",), _analogy, sized=True,
                          bytes_per_face=10_000.0,
                          option_defaults={"style": "cube", "style_map": "auto"}),
    "smooth": MethodSpec("smooth", "smooth", ("Smooth", "Multigrid smoothing"), _smooth,
                         bytes_per_face=3_000.0),
    "subdivide": MethodSpec("subdivide", "subdivision", ("Subdivision",), _subdivide,
                            bytes_per_face=lambda p: 1_600.0 * 4 ** int(p.get("levels", 2)),
                            option_defaults={"weights": "shipped"}),
    "paparazzi": MethodSpec("paparazzi", "paparazzi", ("Paparazzi",), _paparazzi,
                            bytes_per_face=5_000.0, option_defaults={"filter": "guided"}),
}

#: panel title -> the sub-command whose batch form applies its settings
PANEL_METHODS = {title: spec.command for spec in METHODS.values() for title in spec.panels}

#: sub-commands without a batch form, and why
NO_BATCH_FORM = {
    "coarsen": "it writes operators (.npz), not a mesh",
    "adversary": "it attacks an image classifier and writes a lighting or needs each mesh's "
                 "own views",
    "subdivide-train": "it trains one network on all its meshes together",
    "subdivide-eval": "it measures, it writes no mesh",
    "multigrid-info": "it reports, it writes no mesh",
    "info": "it reports, it writes no mesh",
    "clean": "use 'stylize3d clean' per file (or --clean with a method)",
    "study": "it replays or summarizes study logs",
}


# ----------------------------------------------------------------------------- the job
def _app_version() -> str:
    from app import __version__

    return __version__


@dataclass
class Job:
    """Everything a batch runs on each mesh (module docstring); picklable, sent once to each
    worker process.

    method : the sub-command ("cubic"); recipe : the recipe's name ("Cubic").
    params : the Params as a dict; options : the recipe's options (meshes up to
        ``large_faces`` triangles); large_options : the options for bigger meshes, or None
        when they are the same.
    blobs : ``{reference: bytes}`` of every blob the options refer to.
    clean : clean each mesh first (``--clean``); source : where the settings came from.
    note : what the batch does differently from the panel (said in every record).
    """

    method: str
    recipe: str
    params: dict
    options: dict
    large_options: dict | None = None
    large_faces: int = 300_000
    blobs: dict = field(default_factory=dict)
    clean: bool = False
    source: str = "flags"
    #: what the batch does differently from the panel whose settings it applies
    #: (:func:`settings_note`); every record's ``notes`` carries it
    note: str = ""
    #: the params set by flags or ``--params`` (METHOD a plain command): a project given as
    #: INPUT supplies its saved settings for the others, as the one-mesh command does
    given: dict = field(default_factory=dict)
    #: the version of the driver that made the job (a worker of another version refuses it)
    version: str = field(default_factory=lambda: _app_version())

    def options_for(self, n_faces: int) -> dict:
        """The options for a mesh of ``n_faces`` triangles."""
        if self.large_options is not None and n_faces > self.large_faces:
            return self.large_options
        return self.options

    @property
    def bytes_per_face(self) -> float:
        """The estimated peak memory per input triangle (:class:`MethodSpec`)."""
        b = METHODS[self.method].bytes_per_face
        return float(b(self.params) if callable(b) else b)

    @property
    def key(self) -> str:
        """SHA-256 of what the output depends on besides the input: recipe, params, options,
        blob digests, ``--clean`` and the app's version."""
        from app import __version__

        ident = {"recipe": self.recipe, "params": self.params, "options": self.options,
                 "large_options": self.large_options, "large_faces": self.large_faces,
                 "clean": self.clean, "app_version": __version__,
                 "blobs": sorted(hashlib.sha256(b).hexdigest() for b in self.blobs.values())}
        text = json.dumps(ident, sort_keys=True, default=repr, allow_nan=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def describe(self) -> dict:
        """A JSON-able summary (the dry run and the summary show it)."""
        return {"method": self.method, "recipe": self.recipe, "params": self.params,
                "options": self.options, "large_options": self.large_options,
                "large_faces": self.large_faces, "clean": self.clean, "source": self.source,
                "note": self.note, "blobs": {ref: len(b) for ref, b in self.blobs.items()}, "key": self.key}


# ----------------------------------------------------------------------------- the parser
def method_parser(command: str) -> argparse.ArgumentParser:
    """The sub-command's own parser, turned into ``stylize3d batch COMMAND``'s: INPUT... in
    place of its mesh, ``-o`` the output folder, and the batch's flags (:func:`add_batch_flags`)."""
    import importlib

    module = importlib.import_module(f"app.cli.{METHODS[command].module}")
    root = argparse.ArgumentParser(prog="stylize3d batch")
    sub = root.add_subparsers(dest="command")
    module.add_parsers(sub)
    p = sub.choices[command]
    p.prog = f"stylize3d batch {command}"
    p.description = (f"Run '{command}' on every INPUT (mesh files, folders searched "
                     "recursively, globs); each result goes to OUT_DIR under the input's name. "
                     f"The method's flags mean what they mean in 'stylize3d {command}'.")
    p.conflict_handler = "resolve"   # the batch's --json / --quiet / --overwrite / -o win
    for action in p._actions:
        if action.dest == "mesh":
            action.dest, action.nargs, action.metavar = "inputs", "*", "INPUT"
            action.help = "mesh files (.obj .ply .stl .off .glb), projects (.s3d), folders " \
                          "(searched recursively for meshes) or globs"
        elif action.dest == "lam" and action.nargs == "+":
            # the one-mesh command takes several λ (one output each); a batch takes one: its
            # help says what it accepts (issue 39 item 9: it offered what batch refuses)
            text = (action.help or "").split(" Several values:")[0].rstrip()
            action.help = text + " A batch takes one value (run one batch per λ)."
    add_batch_flags(p)
    return p


def add_batch_flags(p: argparse.ArgumentParser) -> None:
    """The flags of ``stylize3d batch`` on top of the method's own."""
    g = p.add_argument_group("batch")
    g.add_argument("-o", "--output", metavar="OUT_DIR",
                   help="the folder the results go to (made if missing); an input's result "
                        "keeps its file name (a project's is written as .obj), below the "
                        "inputs' deepest common folder")
    g.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: the number of cores)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask distributed scheduler (tcp://host:8786) instead of "
                        "local processes; its workers need Stylize3D installed and OUT_DIR "
                        "on a shared file system")
    g.add_argument("--report", metavar="FILE",
                   help="the report, one JSON line per input (default: "
                        "OUT_DIR/batch-report.jsonl)")
    g.add_argument("--memory-limit", metavar="SIZE",
                   help="memory per task, e.g. 4GB or 512MB (default: the machine's memory "
                        "less 1 GB, shared by the workers; none with --scheduler)")
    g.add_argument("--time-limit", type=float, metavar="SECONDS",
                   help="time per mesh (default: none)")
    g.add_argument("--retries", type=int, default=2, metavar="N",
                   help="runs again a mesh whose worker process died, at most N times "
                        "(default: 2)")
    g.add_argument("--panel", metavar="NAME",
                   help="with a project or settings file as METHOD: whose settings to apply "
                        "(default: the only panel whose settings were changed)")
    g.add_argument("--dry-run", action="store_true",
                   help="list what would run and what would be skipped, then exit")
    g.add_argument("--overwrite", action="store_true",
                   help="run every input again, even those the report says are done")
    g.add_argument("--json", action="store_true",
                   help="print one JSON summary at the end (counts, seconds, throughput, "
                        "report)")
    g.add_argument("--quiet", action="store_true", help="no progress bar, no per-mesh lines")
    g.add_argument("--format", choices=("obj", "ply", "stl", "off", "glb"),
                   help="write every result in this format (default: the input's; a "
                        "project's as obj)")
    g.add_argument("--name", metavar="TEMPLATE",
                   help="result file names without extension, e.g. \"{stem}_{command}\": "
                        "{stem} the input's name without extension, {command} the method, "
                        "{parent} the name of the input's folder")
    g.add_argument("--exclude", metavar="GLOB", action="append", default=[],
                   help="leave out inputs whose path below their INPUT, or whose file name, "
                        "matches GLOB (e.g. '*_lowres.obj', 'old/*'); may be given again")
    g.add_argument("--from-list", metavar="FILE",
                   help="more INPUTs from a file, one per line ('#' starts a comment; "
                        "relative paths are relative to the file's folder)")
    g.add_argument("--shard", metavar="I/N",
                   help="run only the I-th of N shares of the inputs (array jobs: N tasks with "
                        "I = 1..N, e.g. --shard $((SLURM_ARRAY_TASK_ID + 1))/N); each shard "
                        "has its own report (batch-report.shard-I-of-N.jsonl), all write "
                        "into one output folder at once")
    g.add_argument("--max-failures", type=int, metavar="N",
                   help="stop after N meshes failed (what is done is recorded; the same "
                        "command goes on later)")


# ----------------------------------------------------------------------------- settings
def _settings_of_json(path: Path) -> tuple[dict, dict]:
    """``(panels, blobs)`` of a panel-settings file (:func:`write_panel_settings`); its blobs
    go into the recipes' store."""
    from app.recipes import add_blob

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BatchUsageError(f"There is no settings file {path}.") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise BatchUsageError(f"{path} is not a panel-settings file ({e}).") from None
    if not isinstance(data, dict):
        raise BatchUsageError(f"{path} is not a panel-settings file (not a JSON object).")
    if "panels" in data and isinstance(data["panels"], dict):
        panels = data["panels"]
    elif "panel" in data:
        panels = {str(data["panel"]): {"params": data.get("params") or {},
                                       "options": data.get("options") or {}}}
    else:
        raise BatchUsageError(f"{path} is not a panel-settings file: it needs \"panel\", "
                              "\"params\" and \"options\" (or a project's \"panels\").")
    for ref, text in (data.get("blobs") or {}).items():
        try:
            add_blob(ref, base64.b64decode(text))
        except (ValueError, TypeError) as e:
            raise BatchUsageError(f"{path}: the stored input {ref!r} is damaged ({e}).") \
                from None
    bad = [t for t, v in panels.items() if not (isinstance(v, dict)
                                               and isinstance(v.get("params", {}), dict)
                                               and isinstance(v.get("options", {}), dict))]
    if bad:
        raise BatchUsageError(f"{path}: the settings of {', '.join(bad)} are not valid.")
    return panels, data.get("blobs") or {}


def write_panel_settings(path, panel: str, params, options: dict) -> Path:
    """Write a panel's settings as a ``.json`` file that ``stylize3d batch FILE.json`` applies
    (the blobs its options refer to are embedded, base64). ``params``: Params or dict."""
    from algorithms.mesh.io import atomic_write
    from algorithms.params import params_to_dict
    from app.recipes import blob_bytes, blob_refs

    values = params if isinstance(params, dict) else params_to_dict(params)
    data = {"format": SETTINGS_FORMAT, "version": 1, "panel": panel, "params": values,
            "options": options,
            "blobs": {ref: base64.b64encode(blob_bytes(ref)).decode("ascii")
                      for ref in sorted(set(blob_refs(options)))}}
    text = json.dumps(data, indent=1)
    atomic_write(path, lambda fh: fh.write(text.encode("utf-8")))
    return Path(path)


def _changed(title: str, saved: dict) -> bool:
    """Whether a panel's saved settings differ from a fresh panel's (params, and the options
    :attr:`MethodSpec.option_defaults` knows; any loaded file counts as a change)."""
    from algorithms.params import params_to_dict
    from app.recipes import blob_refs, get_recipe

    spec = METHODS[PANEL_METHODS[title]]
    try:
        defaults = params_to_dict(get_recipe(title).params_cls()())
    except Stylize3DError:
        defaults = {}
    params = saved.get("params") or {}
    options = saved.get("options") or {}
    if any(k in defaults and defaults[k] != v for k, v in params.items()):
        return True
    if blob_refs(options):
        return True
    return any(k in options and options[k] != v for k, v in spec.option_defaults.items())


def choose_panel(panels: dict, wanted: str | None, where: str) -> str:
    """The panel whose settings a batch applies: ``wanted`` (a title or a sub-command, any
    case), else the only supported panel whose settings were changed."""
    usable = [t for t in panels if t in PANEL_METHODS]
    if wanted:
        low = wanted.lower()
        for t in usable:
            if low in (t.lower(), PANEL_METHODS[t]):
                return t
        if any(low == t.lower() for t in panels):
            raise BatchUsageError(f"The {wanted} panel has no batch form. Panels a batch can "
                                  f"apply: {', '.join(sorted(PANEL_METHODS))}.")
        raise BatchUsageError(f"{where} has no settings of a panel called {wanted!r}; it has: "
                              f"{', '.join(usable) or 'none a batch can apply'}.")
    if not usable:
        raise BatchUsageError(f"{where} holds no settings a batch can apply (panels: "
                              f"{', '.join(sorted(PANEL_METHODS))}).")
    if len(usable) == 1:
        return usable[0]
    changed = [t for t in usable if _changed(t, panels[t])]
    if len(changed) == 1:
        return changed[0]
    which = changed or usable
    raise BatchUsageError(f"{where} holds the settings of several panels "
                          f"({', '.join(which)}); say which with --panel NAME.")


# ----------------------------------------------------------------------------- building
def resolve_method(method: str, panel: str | None = None):
    """``(command, project or None, label)`` of METHOD: a sub-command, a project (``.s3d``) or
    a panel-settings ``.json``; a project's or file's settings are returned as a Project."""
    import difflib

    from app.project import Project, is_project_path, read_project

    text = str(method)
    path = Path(text)
    if is_project_path(text):
        project = read_project(path)
        title = choose_panel(project.panels or {}, panel, path.name)
        return PANEL_METHODS[title], Project(None, panels={title: project.panels[title]}), \
            f"{path} ({title} panel)"
    if path.suffix.lower() == ".json":
        panels, _ = _settings_of_json(path)
        title = choose_panel(panels, panel, path.name)
        return PANEL_METHODS[title], Project(None, panels={title: panels[title]}), \
            f"{path} ({title} panel)"
    if text in METHODS:
        return text, None, "flags"
    if text in NO_BATCH_FORM:
        raise BatchUsageError(f"'{text}' has no batch form: {NO_BATCH_FORM[text]}. Methods a "
                              f"batch runs: {', '.join(METHODS)}.")
    close = difflib.get_close_matches(text, list(METHODS), n=1, cutoff=0.6)
    hint = f" Did you mean '{close[0]}'?" if close else ""
    raise BatchUsageError(f"unknown method '{text}'.{hint} METHOD is one of "
                          f"{', '.join(METHODS)}, a project (.s3d) or a panel-settings "
                          ".json file.")


def _use_settings(args: argparse.Namespace, project, label: str) -> None:
    """Make ``project``'s panel settings the "input project" of :mod:`app.cli.common` (its
    ``args._project`` cache), as if ``label`` had been given as the one-mesh command's mesh."""
    name = label if label.lower().endswith(".s3d") else label + ".s3d"
    args.mesh = name
    args._project = (name, project)


def _blobs_of(*option_sets) -> dict:
    from app.recipes import blob_bytes, blob_refs

    refs = sorted({r for o in option_sets if o for r in blob_refs(o)})
    return {ref: blob_bytes(ref) for ref in refs}


def job_from_args(command: str, args: argparse.Namespace, project=None,
                  source: str = "flags") -> Job:
    """The Job of parsed ``stylize3d batch`` arguments (``project``: the settings to apply)."""
    from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES
    from algorithms.params import params_to_dict

    spec = METHODS[command]
    args.command = command
    args.mesh = None
    panel = None
    if project is not None:
        panel = next(iter(project.panels))
        _use_settings(args, project, source.split(" (")[0])
    recipe, params, options = spec.build(args, panel, 0)
    given = {}
    if project is None:  # flags and --params: what a project given as INPUT cannot override
        from app.cli.common import params_file

        names = set(params_to_dict(params))
        given = {k: v for k, v in params_file(args).items() if k in names}
        given.update({k: v for k, v in vars(args).items() if k in names and v is not None})
    large = None
    if spec.sized:
        quiet = argparse.Namespace(**{**vars(args), "quiet": True})
        big = spec.build(quiet, panel, AUTO_PROGRESSIVE_FACES + 1)[2]
        large = None if big == options else big
    return Job(method=command, recipe=recipe, params=params_to_dict(params), options=options,
               large_options=large, large_faces=AUTO_PROGRESSIVE_FACES,
               blobs=_blobs_of(options, large), clean=bool(getattr(args, "clean", False)),
               source=source, given=given)


def parse_batch_args(method: str, argv: list[str]) -> tuple[Job, argparse.Namespace]:
    """``stylize3d batch METHOD argv...``: the Job and the parsed arguments. argparse's own
    usage errors raise SystemExit (status 2), bad values a plain Stylize3DError."""
    from app.batch.pipeline import is_pipeline_path, read_pipeline

    if is_pipeline_path(method):  # a step file: its steps, then INPUT... and the batch's flags
        job = read_pipeline(method)
        p = argparse.ArgumentParser(prog=f"stylize3d batch {Path(method).name}",
                                    description="Run every step of the step file on each "
                                                "INPUT, in order (docs/batch.md).")
        p.add_argument("inputs", nargs="*", metavar="INPUT")
        add_batch_flags(p)
        args = p.parse_intermixed_args(argv)
        args.clean = False
        return job, args
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--panel")
    known, _ = pre.parse_known_args(argv)
    command, project, source = resolve_method(method, known.panel)
    args = method_parser(command).parse_intermixed_args(argv)
    return job_from_args(command, args, project, source), args


def build_job(method: str, flags: list[str] | tuple = (), *, panel: str | None = None) -> Job:
    """The Job of ``stylize3d batch METHOD ... [flags]`` (scripts, the app)."""
    argv = list(flags) + (["--panel", panel] if panel else [])
    try:
        return parse_batch_args(method, argv)[0]
    except SystemExit as e:
        raise ParameterError(f"The flags {' '.join(map(str, flags))!r} are not valid for "
                             f"{method} (exit status {e.code}).") from None


def settings_note(panel: str, options: dict) -> str:
    """What a batch does differently from the panel with these settings, in plain words (""
    when nothing): the batch dialog shows it before Start, and the job's ``source`` (the
    summary and the report's header) keeps it."""
    signal = (options or {}).get("signal", "positions")
    if panel == "Multigrid smoothing" and signal != "positions":
        what = {"noise": "its noisy test field", "loaded": "the field loaded from a file"}.get(
            signal, f"its {signal!r} signal")
        return (f"The Multigrid smoothing panel is set to smooth {what}, which belongs to the "
                "open mesh. A batch writes meshes, so it smooths each mesh's shape (its vertex "
                "positions) with the panel's Smoothness and solver.")
    return ""


def job_from_settings(panel: str, params, options: dict, *, flags: list[str] | tuple = ()
                      ) -> Job:
    """The Job that applies a panel's settings (its Params or dict and its ``job_options()``)
    as ``stylize3d batch SETTINGS.json`` would: File > Batch… of the app. The blobs the
    options refer to must be in this process's store (they are, in the app)."""
    from algorithms.params import params_to_dict
    from app.project import Project

    if panel not in PANEL_METHODS:
        raise ParameterError(f"The {panel} panel has no batch form. Panels a batch can apply: "
                             f"{', '.join(sorted(PANEL_METHODS))}.")
    values = params if isinstance(params, dict) else params_to_dict(params)
    project = Project(None, panels={panel: {"params": values, "options": dict(options)}})
    command = PANEL_METHODS[panel]
    try:
        args = method_parser(command).parse_intermixed_args(list(flags))
    except SystemExit as e:
        raise ParameterError(f"The flags {' '.join(map(str, flags))!r} are not valid for "
                             f"{command} (exit status {e.code}).") from None
    note = settings_note(panel, options)
    source = f"{panel} panel settings" + (" (signal: the vertex positions, not the panel's "
                                          f"{options.get('signal')} field)" if note else "")
    job = job_from_args(command, args, project, source)
    job.note = note
    return job


__all__ = ["BatchUsageError", "Job", "METHODS", "MethodSpec", "NO_BATCH_FORM",
           "PANEL_METHODS", "SETTINGS_FORMAT", "build_job", "choose_panel", "job_from_args",
           "job_from_settings", "method_parser", "parse_batch_args", "resolve_method",
           "settings_note", "write_panel_settings"]
