"""Pipelines of steps: ``stylize3d batch steps.toml INPUT... -o OUT_DIR`` (issue 39, item 11).

A step file lists the steps every input goes through, in order::

    [[steps]]
    command = "clean"

    [[steps]]
    command = "subdivide"
    params = { method = "loop", levels = 1 }

    [[steps]]
    command = "cubic"
    params = { lam = 0.3 }

``command`` is ``clean`` or a method with a batch form (:data:`app.batch.jobs.METHODS`);
``params`` holds the method's parameter names, as ``--params FILE.json`` does (a name the method
does not have is refused); ``options`` (optional) the recipe's other options, as a panel saves
them. Each step runs exactly as the one-mesh command would on the previous step's result written
and read back as OBJ (an exact round trip), so the output equals running the commands one after
another by hand. Each step's result is kept under ``OUT_DIR/.steps/`` with the key of the input
and the steps so far: a later run (a failure fixed, a later step's settings changed) starts
from the last step whose key still matches (the record's ``steps_reused``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from algorithms.errors import ParameterError

__all__ = ["Pipeline", "read_pipeline", "is_pipeline_path", "run_pipeline"]

#: the steps' results below OUT_DIR (one folder per step)
STEPS_DIR = ".steps"


def is_pipeline_path(text) -> bool:
    return str(text).lower().endswith(".toml")


@dataclass
class Pipeline:
    """The batch job of a step file: what :class:`app.batch.jobs.Job` is for one method.

    steps : the steps' Jobs, None for ``clean``; commands : their commands; source : the file.
    """

    steps: list
    commands: list[str]
    source: str = ""
    clean: bool = False
    note: str = ""
    large_faces: int = 300_000
    blobs: dict = field(default_factory=dict)
    version: str = field(default_factory=lambda: __import__("app").__version__)

    method = "pipeline"

    @property
    def recipe(self) -> str:
        return " > ".join(self.commands)

    @property
    def params(self) -> dict:
        return {}

    @property
    def options(self) -> dict:
        return {}

    @property
    def large_options(self):
        return None

    def options_for(self, n_faces: int) -> dict:
        return {}

    def step_key(self, k: int) -> str:
        """SHA-256 of the steps ``0..k`` (their jobs' keys; ``clean`` has a fixed one)."""
        from app import __version__

        parts = [("clean", __version__) if s is None else (s.method, s.key)
                 for s in self.steps[:k + 1]]
        return hashlib.sha256(json.dumps(parts).encode()).hexdigest()

    @property
    def key(self) -> str:
        return self.step_key(len(self.steps) - 1)

    @property
    def bytes_per_face(self) -> float:
        """The largest need of a step, with the growth of the subdivisions before it."""
        need, growth = 0.0, 1.0
        for s in self.steps:
            if s is None:
                continue
            need = max(need, growth * s.bytes_per_face)
            if s.method == "subdivide":
                growth *= 4.0 ** int(s.params.get("levels", 2))
        return need or 3_000.0

    def describe(self) -> dict:
        return {"method": self.method, "recipe": self.recipe, "source": self.source,
                "steps": [{"command": c} if s is None else
                          {"command": c, "recipe": s.recipe, "params": s.params,
                           "options": s.options} for c, s in zip(self.commands, self.steps,
                                                                 strict=True)],
                "key": self.key}


def read_pipeline(path) -> Pipeline:
    """The :class:`Pipeline` of a step file (module docstring); a plain error for a bad one."""
    import tomllib

    from app.batch.jobs import METHODS, job_from_args, method_parser
    from app.project import Project
    from app.recipes import get_recipe

    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ParameterError(f"The step file {p} does not exist.") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ParameterError(f"The step file {p} cannot be read as TOML ({e}).") from None
    raw = data.get("steps")
    if not isinstance(raw, list) or not raw:
        raise ParameterError(f"{p.name} lists no steps: it needs [[steps]] tables with "
                             "command = \"clean\" | \"cubic\" | ...")
    steps, commands = [], []
    for k, st in enumerate(raw, 1):
        if not isinstance(st, dict) or not isinstance(st.get("command"), str):
            raise ParameterError(f"{p.name}, step {k}: it needs command = \"...\".")
        cmd = st["command"].strip()
        unknown = sorted(set(st) - {"command", "params", "options"})
        if unknown:
            raise ParameterError(f"{p.name}, step {k} ({cmd}): unknown key(s) "
                                 f"{', '.join(unknown)} (a step has command, params, options).")
        if cmd == "clean":
            if st.get("params") or st.get("options"):
                raise ParameterError(f"{p.name}, step {k}: clean takes no params.")
            steps.append(None)
            commands.append(cmd)
            continue
        if cmd not in METHODS:
            raise ParameterError(f"{p.name}, step {k}: unknown command {cmd!r}; a step is "
                                 f"clean or one of {', '.join(METHODS)}.")
        params = st.get("params", {}) or {}
        options = st.get("options", {}) or {}
        if not isinstance(params, dict) or not isinstance(options, dict):
            raise ParameterError(f"{p.name}, step {k} ({cmd}): params and options are tables.")
        spec = METHODS[cmd]
        panel = spec.panels[0]
        args = method_parser(cmd).parse_intermixed_args([])
        job = job_from_args(cmd, args, Project(None, panels={panel: {"params": params,
                                                                     "options": options}}),
                            f"{p.name} step {k}")
        cls = get_recipe(job.recipe).params()
        from dataclasses import fields

        names = {f.name for f in fields(cls)}
        bad = sorted(set(params) - names)
        if bad:
            raise ParameterError(f"{p.name}, step {k} ({cmd}): {', '.join(bad)} "
                                 f"{'is not a setting' if len(bad) == 1 else 'are not settings'}"
                                 f" of {job.recipe} (its settings: {', '.join(sorted(names))}).")
        steps.append(job)
        commands.append(cmd)
    blobs = {}
    for s in steps:
        if s is not None:
            blobs.update(s.blobs)
    return Pipeline(steps, commands, source=str(p), blobs=blobs)


def _how(command: str, job, same: bool, n_vertices: int = 0) -> str:
    """What a step did to the triangles (``same``: its result has the same triangles): "same",
    "subdivided", or why the UVs cannot follow (:func:`app.cli.common.carried_attributes`)."""
    if command == "clean":
        return "same" if same else "cleaning renumbered the triangles"
    if command == "subdivide":
        c = int(job.params.get("coarsen_first", 0) or 0)
        return ("'Coarsen first' remade the triangles (QSlim) before subdividing"
                if c and c < n_vertices else "subdivided")
    if command == "paparazzi":
        return "Paparazzi remakes the triangles when it remeshes, so they have nowhere to go"
    return "same" if same else f"{command} changed the triangles"


def run_pipeline(job: Pipeline, task: dict, rec: dict) -> tuple:
    """Run the steps on ``task["input"]``; returns ``(V, F, attributes or None, figures,
    notes)``. Each step's result is kept (OBJ + its key) for a later run to start from."""
    import numpy as np

    from algorithms.errors import InvalidMeshError
    from algorithms.mesh import clean_mesh, read_mesh, validate_mesh, write_mesh
    from algorithms.mesh.attributes import read_attributes
    from app.batch.worker import _ensure_blobs, file_sha256, run_step
    from app.document import MeshState
    from app.project import is_project_path, read_project

    _ensure_blobs(job)
    # read as it is: a clean step may come first, and each method step checks its own input
    path = task["input"]
    if is_project_path(path):
        state, notes = read_project(path).state, []
    else:
        data = read_mesh(path)
        state, notes = MeshState.make(data.V, data.F), list(data.notes)
    input_sha = rec.get("input_sha256") or file_sha256(task["input"])
    attrs = read_attributes(task["input"], len(state.V), len(state.F)) \
        if not str(task["input"]).lower().endswith(".s3d") else None
    found = attrs.describe() if attrs is not None else ""
    F0, n0 = state.F, len(state.V)
    uv_levels = 0  # the subdivision levels the UVs went through so far
    steps_root = Path(task["run_dir"]).parent.parent / STEPS_DIR
    name = task["input_id"]
    figures, reused = [], []
    start = 0
    # the last step whose kept result still has the key of this input and these steps
    for k in range(len(job.steps) - 1, -1, -1):
        kept = steps_root / f"{k + 1}-{job.commands[k]}" / f"{name}.obj"
        meta = kept.with_suffix(".json")
        try:
            info = json.loads(meta.read_text())
        except (OSError, ValueError):
            continue
        if info.get("key") == hashlib.sha256((input_sha + job.step_key(k)).encode()).hexdigest():
            m = read_mesh(kept)
            state = MeshState.make(m.V, m.F)
            uv_levels = info.get("uv_levels")
            if attrs is not None and uv_levels is None:
                attrs = None
            elif attrs is not None and uv_levels:
                attrs = attrs.transferred(F0, n0, state.F, int(uv_levels))
            start = k + 1
            reused = list(range(1, k + 2))
            figures = info.get("figures", [])
            break
    dropped = ""
    for k in range(start, len(job.steps)):
        cmd, step = job.commands[k], job.steps[k]
        F_before, n_before = state.F, len(state.V)
        if step is None:
            res = clean_mesh(state.V, state.F)
            notes += [f"step {k + 1} (clean): {a}" for a in res.actions]
            state = MeshState.make(res.V, res.F)
            figures.append({"step": cmd, "faces": int(len(state.F))})
        else:
            report = validate_mesh(state.V, state.F)
            if report.blocking:
                raise InvalidMeshError(f"step {k + 1} ({cmd}) cannot take the mesh as it is:\n"
                                       f"{report.summary()}\nAdd a clean step before it.")
            after, last, recipe = run_step(step, state)
            V, F = np.asarray(after.V), np.asarray(after.F)
            if not (len(V) and len(F) and np.isfinite(V).all()):
                raise InvalidMeshError(f"step {k + 1} ({cmd}): the result is not a valid mesh.")
            state = MeshState.make(V, F)
            out_fig = recipe.outcome(last) if recipe.outcome is not None else {}
            figures.append({"step": cmd, "faces": int(len(F)),
                            **{a: b for a, b in out_fig.items()
                               if isinstance(b, (int, float, str, bool))}})
        if attrs is not None:
            same = (len(state.F) == len(F_before) and len(state.V) == n_before
                    and np.array_equal(state.F, F_before))
            how = _how(cmd, step, same, n_before)
            if how == "subdivided":
                levels = int(step.params.get("levels", 2))
                attrs = attrs.transferred(F_before, n_before, state.F, levels)
                uv_levels += levels
                if attrs is None:
                    dropped = f"step {k + 1} ({cmd}) does not split each triangle in four"
            elif how != "same":
                attrs, dropped = None, f"step {k + 1} ({cmd}): {how}"
        if k < len(job.steps) - 1:  # kept for a later run (the final result is the output)
            kept = steps_root / f"{k + 1}-{cmd}" / f"{name}.obj"
            kept.parent.mkdir(parents=True, exist_ok=True)
            write_mesh(kept, state.V, state.F)
            key = hashlib.sha256((input_sha + job.step_key(k)).encode()).hexdigest()
            kept.with_suffix(".json").write_text(json.dumps(
                {"key": key, "input": task["input"], "figures": figures,
                 "uv_levels": None if attrs is None else uv_levels}))
    if found and attrs is None and not dropped:
        dropped = "an earlier run's step dropped them"
    if found:
        notes.append(f"{Path(task['input']).name}'s {found} were dropped: {dropped}."
                     if attrs is None else f"kept {Path(task['input']).name}'s {found}.")
    rec["steps_reused"] = reused
    return state.V, state.F, attrs, figures, notes


def _toml_value(v) -> str:
    import math

    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ParameterError(f"{v} cannot be written to a step file.")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()
                                if x is not None) + " }"
    raise ParameterError(f"{v!r} cannot be written to a step file.")


def step_file_text(command: str, params: dict, options: dict | None = None) -> str:
    """A step file of one step (File > Batch… "Save as step file…"): ``command`` with
    ``params`` and ``options`` (None values left out: TOML has no null). Options that refer to
    loaded files (images, meshes, weights) cannot go into a step file."""
    from app.recipes import blob_refs

    options = {k: v for k, v in (options or {}).items() if v is not None}
    if blob_refs(options):
        raise ParameterError("These settings refer to files loaded in the app (a style mesh, "
                             "an image, weights); a step file cannot hold them. Save the "
                             "panel's settings (.json) and use that as METHOD instead.")
    lines = ["# Stylize3D step file: stylize3d batch THIS_FILE INPUT... -o OUT_DIR",
             "", "[[steps]]", f"command = {_toml_value(command)}"]
    p = {k: v for k, v in params.items() if v is not None}
    if p:
        lines.append(f"params = {_toml_value(p)}")
    if options:
        lines.append(f"options = {_toml_value(options)}")
    return "\n".join(lines) + "\n"
