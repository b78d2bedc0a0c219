"""Re-compute a session's logged runs and edits headless and check their hashes (Qt-free).

Everything that changed the document during a session is re-computed from its logged input:

* a **run** (a ``run`` event followed by its ``result`` with status ``done``): the input state
  saved by the session (``<log>_files/states/``) is loaded, the binary inputs its options refer
  to (``<log>_files/blobs/``) are loaded, the run's recipe (:mod:`app.recipes`, named by the
  log's ``recipe``, else its ``method``) is run with the logged Params and options, and the hash
  of the resulting document state is compared with the logged ``result_hash``; a run that does
  not change the document (an analysis: spectral coarsening, a lighting attack, a training) is
  checked by the hash of its outcome (``outcome_hash``);
* an **edit** (brush, Gauss-map and stamp strokes, handles, Clear painting, Clean, the capture
  sphere's strokes): :func:`app.edits.replay_edit` (or the Analogies recipe's
  ``replay_capture_edit``) re-computes it from its logged input state and the tool's logged
  inputs, and the result's hash is compared with ``after_hash``;
* an **undo / redo** must return to a state the task had already reached;
* each **task**: the state at its end (``task_end``'s ``result_hash``) must be the one the replay
  reached by following the task's events in order from the mesh it opened.

Determinism: recipes are deterministic (fixed-order iterations, seeds in their options): on the
same machine with the same library versions they reproduce the hash exactly. Other machines or
BLAS thread counts can change the last bits of floating-point sums; then the hash differs and the
report gives the largest vertex difference (relative to the bounding-box diagonal) so a reader can
tell round-off from a real difference. A recipe registered as not deterministic is named in the
report's ``nondeterministic`` list. Runs of logs written before recipes existed for their panel,
or whose input state was not saved, are "not replayable", with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .log import load_state, read_log, state_hash
from .protocol import StudyError


@dataclass
class ReplayedRun:
    index: int
    task: str | None
    method: str
    status: str  # "match" | "mismatch" | "not replayable" | "failed"
    reason: str = ""
    max_difference: float | None = None  # relative to the bbox diagonal, when it can be measured
    output: str | None = None
    kind: str = "run"  # "run" | "edit" | "undo" | "redo" | "task"


@dataclass
class ReplayReport:
    log: str
    runs: list[ReplayedRun] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    nondeterministic: list[str] = field(default_factory=list)

    @property
    def counts(self) -> dict:
        out = {}
        for r in self.runs:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def counts_by_kind(self) -> dict:
        out: dict = {}
        for r in self.runs:
            d = out.setdefault(r.kind, {})
            d[r.status] = d.get(r.status, 0) + 1
        return out

    def to_dict(self) -> dict:
        return {"log": self.log, "counts": self.counts, "counts_by_kind": self.counts_by_kind(),
                "warnings": self.warnings, "nondeterministic": self.nondeterministic,
                "runs": [r.__dict__ for r in self.runs]}


#: fields added to a recipe's Params after logs were written with it, with the value that
#: reproduces what a log without the field ran (logs hold every field of the Params they ran
#: with, so a missing field means the log predates it). Paparazzi's ``remesh_scope`` (issue 23,
#: fourth pass): before it every remeshing re-placed the whole surface ("all"); its
#: ``rough_step`` and ``plateau_step`` (fifth pass): before them the step on "auto" was the
#: filter's own on any surface and was never halved when the energy climbed (False, False);
#: its ``lowest_fallback`` (sixth pass): before it a run returned its last shape whatever its
#: energy (False). Its ``remesh_spoiled_only`` (issue 38, 30 November 2026): before it every
#: bad element was remeshed, the input's own too (False); its ``thin_step`` (issue 38, 1 December
#: 2026): before it every vertex of an l0 run took the same step (False); its
#: ``put_back_crossing_only`` (issue 38, 1 December 2026, tenth session): before it the steps'
#: crossings put back and held the surface within 4 edge lengths (False). Cubic's,
#: Analogies', Smooth's and the multigrid flow's ``hold_crossings`` (issue 38): before it a
#: run kept whatever crossings the style or the flow made (False).
ADDED_FIELDS: dict[str, dict] = {"Paparazzi": {"remesh_scope": "all", "rough_step": False,
                                               "plateau_step": False, "lowest_fallback": False,
                                               "remesh_spoiled_only": False,
                                               "thin_step": False,
                                               "put_back_crossing_only": False},
                                 "Cubic": {"hold_crossings": False},
                                 "Analogies": {"hold_crossings": False},
                                 "Smooth": {"hold_crossings": False},
                                 "Multigrid smoothing: mean curvature flow": {
                                     "hold_crossings": False}}


#: the same for a Paparazzi filter's Params (``options["filter_params"]``): neural-style's
#: ``energy`` (issue 23, seventh pass): before it the filter pulled each view towards the style
#: network's repainting of it ("network").
ADDED_FILTER_FIELDS: dict[str, dict] = {"neural-style": {"energy": "network"}}


def logged_options(recipe_name: str, options: dict | None) -> dict:
    """A run's logged ``options``, with the filter Params' fields its log predates set as they
    then ran (:data:`ADDED_FILTER_FIELDS`)."""
    options = dict(options or {})
    added = ADDED_FILTER_FIELDS.get(str(options.get("filter") or "")) if (
        recipe_name == "Paparazzi") else None
    if added:
        values = dict(options.get("filter_params") or {})
        for k, v in added.items():
            values.setdefault(k, v)
        options["filter_params"] = values
    return options


def logged_params(recipe_name: str, values: dict | None) -> dict:
    """A run's logged Params dict, with the fields its log predates set as they then ran."""
    values = dict(values or {})
    for k, v in ADDED_FIELDS.get(recipe_name, {}).items():
        values.setdefault(k, v)
    return values


def logged_step(recipe_name: str, values: dict, raw: dict, options: dict) -> dict:
    """``values`` (:func:`logged_params`) with the learning rate a neural-style run logged
    before 1 December 2026 (tenth session; its log has no ``put_back_crossing_only``) took on
    auto: the filter's own, on every mesh and vertex. Since then neural-style's step on auto
    follows the mesh's edge and thin triangles (``FilterSpec.step_follows_edge``), which is
    no setting a log could hold; a fixed step set to the same value runs as it ran."""
    if (recipe_name != "Paparazzi" or options.get("filter") != "neural-style"
            or "put_back_crossing_only" in raw or values.get("learning_rate")):
        return values
    from algorithms.paparazzi import get_filter
    from app.recipes.paparazzi import resolve_filter_params

    spec = get_filter("neural-style")
    return {**values, "learning_rate": spec.step(resolve_filter_params(
        spec, options.get("filter_params")))}


def files_dir(log_path) -> Path:
    p = Path(log_path).with_suffix("")
    return p.parent / (p.name + "_files")


def _hash(state) -> str:
    return state_hash(state.V, state.F, state.fields, state.handles)


def _load_blobs(base: Path, options) -> None:
    from app.recipes import add_blob, blob_refs

    for ref in blob_refs(options):
        digest, name = ref[len("blob:"):].split("/", 1)
        p = base / "blobs" / digest / name
        if p.is_file():
            add_blob(ref, p.read_bytes())


def _difference(base: Path, res_file, after) -> float | None:
    if res_file and (base / res_file).is_file():
        logged = load_state(base / res_file)
        if logged.V.shape == after.V.shape:
            diag = float(np.linalg.norm(np.ptp(logged.V, axis=0))) or 1.0
            return float(np.abs(logged.V - after.V).max()) / diag
    return None


class _Replayer:
    def __init__(self, log_path, out_dir):
        self.data = read_log(log_path)
        self.report = ReplayReport(str(log_path), warnings=list(self.data.warnings))
        self.base = files_dir(log_path)
        self.out_dir = None if out_dir is None else Path(out_dir)
        if self.out_dir is not None:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        self.n = 0
        self.current = None  # the replayed document state of the task
        self.reached: dict[str, object] = {}  # hash -> state, every state the task reached
        self.pending: dict[str, dict] = {}

    def add(self, ev, kind, method, status="not replayable", reason="") -> ReplayedRun:
        self.n += 1
        rr = ReplayedRun(self.n, ev.get("task"), method, status, reason, kind=kind)
        self.report.runs.append(rr)
        return rr

    def reach(self, state) -> None:
        self.current = state
        self.reached[_hash(state)] = state

    def load(self, rel):
        if not rel:
            return None
        p = self.base / rel
        return load_state(p) if p.is_file() else None

    # -- events --------------------------------------------------------------------------------
    def on_open(self, ev) -> None:
        self.reached = {}
        st = self.load(ev.get("state_file"))
        if st is None:
            self.current = None
            return
        if _hash(st) != ev.get("mesh_hash"):
            self.report.warnings.append(f"task {ev.get('task')}: the saved opened mesh does not "
                                        "match its logged hash")
        self.reach(st)

    def on_result(self, ev) -> None:
        from algorithms.errors import Stylize3DError
        from app.recipes import outcome_hash, recipes, unchanged_result

        method = ev.get("method", "?")
        run = self.pending.pop(method, None)
        if ev.get("status") != "done":
            return
        name = ev.get("recipe") or (run or {}).get("recipe") or method
        rr = self.add(ev, "run", name)
        recipe = recipes().get(name)
        if recipe is None:
            rr.reason = f"the {name} panel has no headless recipe"
            return
        if not recipe.deterministic and name not in self.report.nondeterministic:
            self.report.nondeterministic.append(name)
        if run is None or not run.get("input_file"):
            rr.reason = "its input state was not saved in the log's folder"
            return
        src = self.base / run["input_file"]
        if not src.is_file():
            rr.reason = f"its input state {src} is missing"
            return
        try:
            before = load_state(src)
            options = logged_options(name, run.get("options", {}) or {})
            _load_blobs(self.base, options)
            params = recipe.make_params(logged_step(name, logged_params(
                name, run.get("params", {})), run.get("params", {}) or {}, options))
            last = None
            for last in recipe.steps(before, params, options, {}):
                pass
            if last is None:
                rr.status, rr.reason = "failed", "the method produced no result"
                return
            after = recipe.result(before, last, options)
        except Stylize3DError as e:
            rr.status, rr.reason = "failed", str(e)
            return
        h = _hash(after)
        ok = h == ev.get("result_hash")
        if ok and recipe.result is unchanged_result and ev.get("outcome_hash"):
            out = recipe.outcome(last) if recipe.outcome is not None else {}
            ok = outcome_hash(out or {}) == ev["outcome_hash"]
            if not ok:
                rr.reason = "the method's outcome differs from the logged one"
        rr.status = "match" if ok else "mismatch"
        if not ok and not rr.reason:
            rr.reason = "the result differs from the logged one"
            rr.max_difference = _difference(self.base, ev.get("result_file"), after)
        self.reach(after if ok or self.load(ev.get("result_file")) is None
                   else self.load(ev.get("result_file")))
        if self.out_dir is not None:
            from algorithms.mesh import write_mesh

            dest = self.out_dir / (f"{rr.index:03d}_{rr.task or 'none'}_"
                                   f"{name.replace(' ', '_').replace(':', '')}.obj")
            write_mesh(dest, after.V, after.F)
            rr.output = str(dest)

    def on_edit(self, ev) -> None:
        from algorithms.errors import Stylize3DError
        from app.edits import replay_edit

        tool = str(ev.get("tool") or "")
        rr = self.add(ev, "edit", ev.get("text") or tool or "edit")
        if tool == "capture":  # the Analogies panel's capture sphere (not document state)
            try:
                from app.recipes.analogies import replay_capture_edit
            except ImportError:
                rr.reason = "capture-sphere strokes cannot be re-computed by this version"
                return
            rr.status = "match" if replay_capture_edit(ev) else "mismatch"
            if rr.status == "mismatch":
                rr.reason = "the re-computed capture sphere differs from the logged one"
            return
        before = self.load(ev.get("before_file"))
        if before is None:
            before = self.current
            if before is None:
                rr.reason = "its input state was not saved in the log's folder"
                return
        elif self.current is not None and _hash(self.current) != ev.get("before_hash"):
            self.report.warnings.append(
                f"event {rr.index} ({rr.method}): the document changed before this edit in a "
                "way the log does not show")
        try:
            _load_blobs(self.base, ev)
            after = replay_edit(before, ev)
        except KeyError as e:
            rr.reason = f"the edit's logged inputs are incomplete (no {e})"
            st = self.load(ev.get("after_file"))
            if st is not None:
                self.reach(st)
            return
        except (Stylize3DError, ValueError, TypeError) as e:
            rr.status, rr.reason = "failed", f"{type(e).__name__}: {e}"
            return
        if after is None:
            rr.reason = (f"the tool {tool!r} of this edit is not known" if tool else
                         "this edit did not log its tool's inputs (an older log)")
            st = self.load(ev.get("after_file"))
            if st is not None:
                self.reach(st)
            return
        ok = _hash(after) == ev.get("after_hash")
        rr.status = "match" if ok else "mismatch"
        if not ok:
            rr.reason = "the re-computed edit differs from the logged one"
            rr.max_difference = _difference(self.base, ev.get("after_file"), after)
        self.reach(after)

    def on_undo_redo(self, ev, kind) -> None:
        h = ev.get("result_hash")
        rr = self.add(ev, kind, ev.get("text") or kind)
        st = self.reached.get(h)
        if st is None:
            rr.status = "mismatch"
            rr.reason = f"the {kind} went to a state this task had not reached in the replay"
            st = self.load(ev.get("result_file"))
            if st is not None:
                self.reach(st)
            return
        rr.status = "match"
        self.current = st

    def on_task_end(self, ev) -> None:
        if self.current is None or not ev.get("result_hash") or ev.get("status") == "failed":
            return
        rr = self.add(ev, "task", f"task {ev.get('task')}")
        ok = _hash(self.current) == ev["result_hash"]
        rr.status = "match" if ok else "mismatch"
        if not ok:
            rr.reason = "the replayed final state of the task differs from the logged one"

    def replay(self) -> ReplayReport:
        for ev in self.data.events:
            a = ev.get("action")
            if a == "run":
                self.pending[ev.get("method", "?")] = ev
            elif a == "open":
                self.on_open(ev)
            elif a == "result":
                self.on_result(ev)
            elif a == "edit":
                self.on_edit(ev)
            elif a in ("undo", "redo"):
                self.on_undo_redo(ev, a)
            elif a == "task_end":
                self.on_task_end(ev)
        if not self.report.runs:
            self.report.warnings.append("The log has no finished runs to replay.")
        return self.report


def replay(log_path, out_dir=None) -> ReplayReport:
    """Re-run every finished run and edit of a log (module docstring). ``out_dir``: write each
    replayed run's result there as ``<n>_<task>_<method>.obj``."""
    return _Replayer(log_path, out_dir).replay()


def replay_or_raise(log_path, out_dir=None) -> ReplayReport:
    """:func:`replay`, with a plain error for a log that cannot be read at all."""
    if not Path(log_path).exists():
        raise StudyError(f"There is no session log at {log_path}.")
    return replay(log_path, out_dir)
