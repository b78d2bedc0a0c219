"""Per participant and task figures from session logs, as CSV for pandas / R (Qt-free).

One row per (log, task) in the order the participant did the tasks. Columns:

``study, participant, condition, order, task, status`` (done / skipped / timeout / unfinished),
``seconds`` (the task's time: task_start to task_end on the log's clock ``t_mono``, which
leaves out the time the app was not running after a crash; the session logs the same figure in
``task_end``'s ``seconds`` and its time limit counts the same clock), ``actions`` (what the participant
did during the task: runs, edits, undo / redo, panels brought forward, questionnaires — not the
app's own events: task_start / task_end, the task's mesh being opened, results, notes, resumes,
camera moves, which have their own column), ``runs`` (runs started), ``failed_runs``,
``undo``, ``redo``, ``camera_moves``, ``final_params`` (JSON: for each method, the params of
the run whose result is part of the document at task end: a run the participant undid, or one
whose result was replaced by undoing to an earlier state, does not count; a run that changed
nothing, an analysis, counts on the state it ran on), ``result_hash`` (the document at task end), then one ``q_<item>`` column per
questionnaire item seen in any log, and ``sus_score`` (0-100, Brooke 1996) where the task asked
the SUS.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from .log import LogData, read_log
from .protocol import SUS_ITEMS

BASE_COLUMNS = ["study", "participant", "condition", "order", "task", "status", "seconds",
                "actions", "runs", "failed_runs", "undo", "redo", "camera_moves",
                "final_params", "result_hash"]
_NOT_ACTIONS = {"task_start", "task_end", "camera", "resume", "session_end", "result", "open",
                "note"}


def sus_score(answers: dict) -> float | None:
    """SUS score 0-100 from answers ``sus1..sus10`` on 1..5; None if any is missing."""
    total = 0
    for i in range(1, len(SUS_ITEMS) + 1):
        v = answers.get(f"sus{i}")
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not 1 <= v <= 5:
            return None
        total += (v - 1) if i % 2 == 1 else (5 - v)
    return total * 2.5


def summarize(data: LogData) -> list[dict]:
    """Rows (dicts) for one log."""
    h = data.header
    rows: dict[str, dict] = {}
    order = list(h.get("task_order") or [])

    def row(task):
        if task not in rows:
            rows[task] = {"study": h.get("study", ""), "participant": h.get("participant", ""),
                          "condition": h.get("condition", ""),
                          "order": order.index(task) + 1 if task in order else "",
                          "task": task, "status": "unfinished", "seconds": "", "actions": 0,
                          "runs": 0, "failed_runs": 0, "undo": 0, "redo": 0,
                          "camera_moves": 0, "final_params": {}, "result_hash": "",
                          "_start": None, "_answers": {}, "_params_of": {}, "_now": None}
        return rows[task]

    def follow(r, h, params=None):
        """The document is now in state ``h``: the params that made it are those of the state
        it came from plus ``params`` (a run), or those it had when it was reached before (an
        undo / redo back to it)."""
        if not h:
            return
        if params is not None:
            r["_params_of"][h] = {**r["_params_of"].get(r["_now"], {}), **params}
        elif h not in r["_params_of"]:
            r["_params_of"][h] = dict(r["_params_of"].get(r["_now"], {}))  # an edit
        r["_now"] = h

    for ev in data.events:
        task = ev.get("task")
        if task is None:
            continue
        r = row(task)
        a = ev.get("action")
        if a == "task_start":
            r["_start"] = ev["t_mono"]
        elif a == "task_end":
            r["status"] = ev.get("status", "done")
            if r["_start"] is not None:
                r["seconds"] = round(ev["t_mono"] - r["_start"], 3)
            r["result_hash"] = ev.get("result_hash", "")
            r["final_params"] = r["_params_of"].get(r["result_hash"], {})
        elif a == "open":  # a freshly opened mesh: made by no run
            r["_params_of"][ev.get("mesh_hash", "")] = {}
            r["_now"] = ev.get("mesh_hash", "")
        elif a == "camera":
            r["camera_moves"] += 1
        elif a == "result":
            if ev.get("status") == "done":
                follow(r, ev.get("result_hash", ""), {ev.get("method", "?"): ev.get("params", {})})
            elif ev.get("status") == "failed":
                r["failed_runs"] += 1
        elif a in ("undo", "redo"):
            follow(r, ev.get("result_hash", ""))
        elif a == "edit":
            follow(r, ev.get("after_hash", ""))
        elif a == "questionnaire":
            r["_answers"].update(ev.get("answers") or {})
        if a == "run":
            r["runs"] += 1
        elif a == "undo":
            r["undo"] += 1
        elif a == "redo":
            r["redo"] += 1
        if a not in _NOT_ACTIONS:
            r["actions"] += 1
    out = []
    for task in sorted(rows, key=lambda t: (order.index(t) if t in order else len(order), t)):
        r = rows[task]
        answers = r.pop("_answers")
        for k in ("_start", "_params_of", "_now"):
            r.pop(k)
        r["final_params"] = json.dumps(r["final_params"], sort_keys=True)
        for k, v in answers.items():
            r[f"q_{k}"] = v
        s = sus_score(answers)
        r["sus_score"] = "" if s is None else s
        out.append(r)
    return out


def summary_csv(paths, out=None) -> tuple[str, list[str]]:
    """Summarize logs into CSV text (written to ``out`` when given); returns (text, warnings)."""
    rows, warnings = [], []
    for p in paths:
        data = read_log(p)
        warnings += [f"{Path(p).name}: {w}" for w in data.warnings]
        rows += summarize(data)
    qcols = sorted({k for r in rows for k in r if k.startswith("q_")},
                   key=lambda c: (not c.startswith("q_sus"), _natural(c)))
    cols = BASE_COLUMNS + qcols + ["sus_score"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, restval="", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    text = buf.getvalue()
    if out is not None:
        from algorithms.mesh.io import atomic_write

        atomic_write(out, lambda f: f.write(text.encode("utf-8")))
    return text, warnings


def _natural(s: str):
    import re

    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", s)]
