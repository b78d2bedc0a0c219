"""The session log of a user study: JSON Lines, one action per line, synced as written (Qt-free).

Format 1. The first line is the session header::

    {"log_format": 1, "type": "session", "app": "stylize3d", "app_version": "0.1.0",
     "study": ID, "protocol_sha256": HEX, "protocol": PATH, "participant": CODE,
     "condition": NAME, "task_order": [TASK, ...], "t_wall": EPOCH_S, "t_mono": 0.0}

Every further line is an event::

    {"t_wall": EPOCH_S, "t_mono": S_SINCE_SESSION_START, "task": TASK or null,
     "action": NAME, ...action fields}

``t_mono`` is monotonic (immune to clock changes) and counts from the session start; after a
resume it continues from the last logged value. Actions written by the app:

``task_start`` / ``task_end`` (``status``: done, skipped, timeout; ``seconds``),
``open`` (``path``, ``mesh_hash``), ``run`` (``method``, ``params``, ``options``,
``input_hash``, ``input_file``: the saved input state for replay), ``result`` (``method``,
``status``: done, cancelled, failed; ``result_hash``, ``seconds``, ``message``),
``edit`` (an undoable change that is not a run, e.g. a brush stroke: ``text``, ``after_hash``,
``fields`` {name: {vertices, values}} of what changed, ``moved_vertices``, ``handles``; brush
strokes add ``tool``, ``field``, ``radius``, ``strength``, ``erase``),
``undo`` / ``redo`` (``text``, ``result_hash``), ``camera`` (throttled: ``position``,
``focal_point``, ``up``), ``panel`` (``title`` of the panel brought forward),
``questionnaire`` (``answers``: {item id: value}), ``resume``, ``session_end``.

Privacy: the log holds the participant code the experimenter typed, and nothing else about the
person (no user name, host name, or file paths outside the study's own folder are written by the
app; the protocol path is the experimenter's).

Each line is written whole, flushed and ``os.fsync``-ed before the call returns, so killing the
app loses at most the line being written; :func:`read_log` skips a cut-off last line and says so.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .protocol import StudyError

#: The log format this version writes and reads.
LOG_FORMAT = 1


def mesh_hash(V, F) -> str:
    """SHA-256 of the positions (little-endian float64) and triangles (little-endian int64)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(V, dtype="<f8").tobytes())
    h.update(b"|")
    h.update(np.ascontiguousarray(F, dtype="<i8").tobytes())
    return h.hexdigest()


def state_hash(V, F, fields: dict | None = None, handles=()) -> str:
    """SHA-256 of a whole document state: mesh, per-vertex fields (by name) and point handles."""
    h = hashlib.sha256(mesh_hash(V, F).encode())
    for name in sorted(fields or {}):
        h.update(name.encode())
        h.update(np.ascontiguousarray(fields[name], dtype="<f8").tobytes())
    for v, p in handles or ():
        h.update(f"h{int(v)}:{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}".encode())
    return h.hexdigest()


def _save_array(base: Path, a: np.ndarray) -> str:
    """Write an array once per content under ``base/arrays/``; returns its relative path."""
    import io

    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    data = buf.getvalue()
    rel = f"arrays/{hashlib.sha256(data).hexdigest()[:40]}.npy"
    dest = base / rel
    if not dest.is_file():
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_suffix(".part")
        tmp.write_bytes(data)
        os.replace(tmp, dest)
    return rel


def save_state(base, state, rel: str) -> None:
    """Save a document state for replay as ``base/rel`` (a small JSON file) whose arrays (V, F,
    each field, the selection) are stored once per content under ``base/arrays/``."""
    base = Path(base)
    doc = {"V": _save_array(base, np.asarray(state.V, np.float64)),
           "F": _save_array(base, np.asarray(state.F, np.int64)),
           "fields": {k: _save_array(base, np.asarray(v, np.float64))
                      for k, v in sorted(state.fields.items())},
           "selection": (None if state.selection is None
                         else _save_array(base, np.asarray(state.selection, bool))),
           "handles": [[int(v), [float(x) for x in p]] for v, p in state.handles]}
    dest = base / rel
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".part")
    tmp.write_text(json.dumps(doc))
    os.replace(tmp, dest)


def load_state(path):
    """A MeshState saved by :func:`save_state` (``.json``) or by older sessions (``.npz``)."""
    from dataclasses import replace

    from app.document import MeshState

    path = Path(path)
    if path.suffix == ".json":
        base = path.parent.parent
        doc = json.loads(path.read_text())

        def arr(rel):
            return np.load(base / rel, allow_pickle=False)

        state = MeshState.make(arr(doc["V"]), arr(doc["F"]),
                               {k: arr(r) for k, r in doc.get("fields", {}).items()},
                               None if doc.get("selection") is None else arr(doc["selection"]))
        return state.with_handles({int(v): tuple(p) for v, p in doc.get("handles", [])})
    with np.load(path, allow_pickle=False) as z:
        fields = {k[len("field_"):]: z[k] for k in z.files if k.startswith("field_")}
        state = MeshState.make(z["V"], z["F"], fields)
        if "handle_ids" in z.files:
            handles = tuple((int(v), tuple(float(x) for x in p))
                            for v, p in zip(z["handle_ids"], z["handle_pos"]))
            state = replace(state, handles=handles)
    return state


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())  # NaN / inf become strings (JSON has no NaN)
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


class SessionLog:
    """Append-only writer of one participant's session (see the module docstring).

    Use :meth:`create` for a new session and :meth:`resume` to continue a crashed one.
    """

    def __init__(self, path: Path, header: dict, t_offset: float, fh):
        self.path = Path(path)
        self.header = header
        self._t0 = time.monotonic() - t_offset
        self._fh = fh
        self.task: str | None = None

    @property
    def results_dir(self) -> Path:
        """Folder next to the log for per-task results, questionnaire answers and replay inputs."""
        d = self.path.with_suffix("")
        d = d.parent / (d.name + "_files")
        d.mkdir(parents=True, exist_ok=True)
        return d

    @classmethod
    def create(cls, path, *, study: str, protocol_path: str | None, protocol_sha256: str,
               participant: str, condition: str, task_order: list[str],
               app_version: str = "") -> "SessionLog":
        path = Path(path)
        if path.exists():
            raise StudyError(f"{path} already exists: resume that session, or choose another "
                             "participant code.")
        path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(path, "x", encoding="utf-8")
        header = {"log_format": LOG_FORMAT, "type": "session", "app": "stylize3d",
                  "app_version": app_version, "study": study, "protocol_sha256": protocol_sha256,
                  "protocol": protocol_path, "participant": participant,
                  "condition": condition, "task_order": list(task_order),
                  "t_wall": time.time(), "t_mono": 0.0}
        log = cls(path, header, 0.0, fh)
        log._write_line(header)
        return log

    @classmethod
    def resume(cls, path) -> tuple["SessionLog", "LogData"]:
        """Reopen a log to append to it; returns the writer and what was logged so far."""
        data = read_log(path)
        last = data.events[-1]["t_mono"] if data.events else 0.0
        if data.truncated:
            # drop the cut-off fragment so the next line starts on a line of its own
            with open(path, "rb+") as f:
                f.truncate(data.intact_bytes)
        fh = open(path, "a", encoding="utf-8")
        log = cls(Path(path), data.header, float(last), fh)
        log.task = data.current_task
        log.write("resume", **({"note": "a cut-off last line was dropped"} if data.truncated
                               else {}))
        return log, data

    def now(self) -> float:
        """The log's clock (``t_mono``): seconds since the session started, the time the app
        was not running excluded."""
        return round(time.monotonic() - self._t0, 6)

    def write(self, action: str, *, at: float | None = None, **fields) -> dict:
        """Append one event (flushed and synced before returning); ``at``: its ``t_mono``
        when the caller read :meth:`now` to compute one of the fields from it."""
        if self._fh is None:
            raise StudyError("This session log is closed.")
        ev = {"t_wall": time.time(), "t_mono": self.now() if at is None else float(at),
              "task": self.task, "action": action}
        ev.update(_jsonable(fields))
        self._write_line(ev)
        return ev

    def _write_line(self, obj: dict) -> None:
        line = json.dumps(obj, ensure_ascii=False, separators=(",", ":"), allow_nan=False)
        self._fh.write(line + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


@dataclass
class LogData:
    """What :func:`read_log` found."""

    header: dict
    events: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    truncated: bool = False
    intact_bytes: int = 0

    @property
    def participant(self) -> str:
        return self.header.get("participant", "")

    @property
    def condition(self) -> str:
        return self.header.get("condition", "")

    @property
    def current_task(self) -> str | None:
        """The task that was started and not ended (where a crashed session resumes), or None."""
        cur = None
        for ev in self.events:
            if ev.get("action") == "task_start":
                cur = ev.get("task")
            elif ev.get("action") == "task_end" and ev.get("task") == cur:
                cur = None
        return cur

    @property
    def finished_tasks(self) -> list[str]:
        return [ev.get("task") for ev in self.events if ev.get("action") == "task_end"]


def read_log(path) -> LogData:
    """Read a session log. A cut-off last line (the app was killed while writing) is skipped with
    a warning; any other damage, or a log from a newer Stylize3D, is a plain :class:`StudyError`."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise StudyError(f"Cannot read the session log {p}: {e.strerror or e}.") from None
    lines = raw.split(b"\n")
    complete_end = raw.rfind(b"\n") + 1  # bytes up to the last newline
    tail = lines.pop()  # after the last newline: "" or a cut-off line
    data: LogData | None = None
    warnings = []
    truncated = False
    if tail.strip():
        truncated = True
        warnings.append(f"The last line of {p.name} was cut off (the app stopped while writing "
                        "it); it is ignored.")
    for k, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            if k == len(lines) and not tail.strip():
                truncated = True
                complete_end = sum(len(x) + 1 for x in lines[:k - 1])
                warnings.append(f"The last line of {p.name} is damaged (the app stopped while "
                                "writing it); it is ignored.")
                break
            raise StudyError(f"{p.name}, line {k}, is not a log entry (damaged file?).") from None
        if not isinstance(obj, dict):
            raise StudyError(f"{p.name}, line {k}, is not a log entry (damaged file?).")
        if data is None:
            if obj.get("type") != "session" or "log_format" not in obj:
                raise StudyError(f"{p.name} is not a Stylize3D session log (its first line is "
                                 "not a session header).")
            fmt = obj["log_format"]
            if not isinstance(fmt, int) or fmt > LOG_FORMAT:
                raise StudyError(f"{p.name} was written by a newer Stylize3D (log format {fmt}; "
                                 f"this version reads format {LOG_FORMAT}). Update Stylize3D to "
                                 "read it.")
            data = LogData(obj)
            continue
        if "action" not in obj or "t_mono" not in obj:
            raise StudyError(f"{p.name}, line {k}, has no action or time (damaged file?).")
        data.events.append(obj)
    if data is None:
        raise StudyError(f"{p.name} is empty: no session was recorded in it.")
    data.warnings = warnings
    data.truncated = truncated
    data.intact_bytes = complete_end
    return data
