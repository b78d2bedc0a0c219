"""Autosave and recovery: the open work is kept in a per-user recovery folder while it changes,
and offered back after a crash.

What is written
    the same ``.s3d`` project File > Save Project As… writes (:func:`app.project.project_bytes`:
    the mesh, the mesh as first opened, painted fields, selection, handles, every panel's
    settings and stored inputs), plus a small JSON sidecar saying what it is (title, the mesh
    or project file the work came from, sizes, the last change), when it was written, and
    which process wrote it (pid, the process's start time, host name).

Where
    ``$STYLIZE3D_RECOVERY_DIR`` when set (the test suite points it at a temporary folder),
    else ``$XDG_STATE_HOME/stylize3d/recovery`` (``~/.local/state/stylize3d/recovery``) on
    Linux, ``%LOCALAPPDATA%/Stylize3D/recovery`` on Windows, ``~/Library/Application
    Support/Stylize3D/recovery`` on macOS. The folder is made private (0700), the files 0600.

Slots
    Each window has its own slot, ``<host>_<pid>_<random>.s3d`` + ``.json``, so several windows
    or processes never overwrite each other. Both files are written atomically (a temporary
    file in the same folder, flushed, fsync-ed, renamed over the old one, the folder fsync-ed):
    a failed or interrupted write leaves the previous autosave as it was.

When (:class:`Autosaver`)
    Every change (a finished job, an edit, undo / redo, a newly opened file, a panel's
    settings) marks the work changed and restarts a single-shot timer (1.5 s): several quick
    edits give one write. While changes keep coming faster than that, a second timer writes at
    least every 60 s. Nothing is written when nothing changed since the last autosave. The
    slot exists only while the document has unsaved changes: once it is saved (or opened
    fresh, or undone back to its saved state) the slot's files are removed; a normal close of
    the window (also after "Discard changes") removes them too. The project of a
    100,000-triangle mesh takes about 0.25 s to compress, so the GUI thread only takes a
    snapshot (immutable :class:`~app.document.MeshState` objects and the panels' settings,
    well under a millisecond) and a worker thread compresses and writes it. A user-study
    session (``window.study_session``) keeps its own log-based resume: while one runs nothing
    is autosaved and the window's slot is removed.

Recovery (:func:`offer_recovery`, called by :func:`app.gui.run_app` at start-up)
    A slot whose process no longer runs (same host; the pid is gone, or now belongs to a
    process started at another time) is offered in a :class:`RecoveryDialog`: Recover, Discard
    (deletes it) or Decide Later (kept, offered at the next start). A slot of a running process
    (another open window) and one written on another host (its process cannot be checked from
    here) are left alone. Recover makes the autosaved project the document as Open Project
    would, but marked as unsaved work: the undo history starts there (nothing to undo, and
    undoing later edits never makes it "saved"), the window remembers the mesh or project file
    the work came from (Save writes that file only after asking to replace it; Save Project As
    asks for a name), and the recovered slot is deleted once this window has autosaved the
    work into its own slot. The first recovered slot ends the offer; other orphans stay for
    the next start.
"""

from __future__ import annotations

import json
import os
import re
import socket
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QDialog, QHBoxLayout, QLabel, QPushButton, QVBoxLayout

from algorithms.errors import Stylize3DError

ENV_DIR = "STYLIZE3D_RECOVERY_DIR"
SIDECAR_FORMAT = "stylize3d-recovery"
SIDECAR_VERSION = 1

RECOVER, DISCARD, LATER = "recover", "discard", "later"


# ------------------------------------------------------------------------------ files (Qt-free)
def recovery_dir() -> Path:
    """The per-user recovery folder (see the module docstring); not created here."""
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or str(Path.home() / "AppData" / "Local")
        return Path(base) / "Stylize3D" / "recovery"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Application Support" / "Stylize3D" / "recovery"
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "stylize3d" / "recovery"


def this_host() -> str:
    """This machine's name as slot file names carry it (letters, digits, '.', '-')."""
    name = re.sub(r"[^A-Za-z0-9.-]", "-", socket.gethostname() or "")[:64]
    return name or "localhost"


def process_started(pid: int) -> float | None:
    """When process ``pid`` started (seconds since the epoch), None when unknown / gone."""
    import psutil

    try:
        return float(psutil.Process(pid).create_time())
    except (psutil.Error, OSError, ValueError):
        return None


def process_running(pid: int, started: float | None = None) -> bool:
    """Whether process ``pid`` runs on this machine. With ``started`` (its start time as
    :func:`process_started` gave it), a process that reuses the pid but started at another time
    is not it. A zombie (killed, not yet reaped) does not run; a process we may not inspect
    does."""
    import psutil

    try:
        p = psutil.Process(int(pid))
        if p.status() == psutil.STATUS_ZOMBIE:
            return False
        now_started = p.create_time()
    except psutil.NoSuchProcess:
        return False
    except (psutil.Error, OSError):
        return True
    return started is None or abs(float(now_started) - float(started)) < 1.0


def _fsync_dir(folder: Path) -> None:
    if sys.platform == "win32":
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically: a private temporary file in the same folder is
    written, flushed and fsync-ed, then renamed over ``path`` (and the folder fsync-ed). On any
    failure the temporary file is removed, ``path`` keeps its old content and the error
    propagates (OSError)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_dir(path.parent)


def _ensure_folder(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    try:
        os.chmod(folder, 0o700)
    except OSError:
        pass


class RecoverySlot:
    """One window's recovery files: ``<id>.s3d`` (the project) and ``<id>.json`` (what, when,
    who). Qt-free."""

    def __init__(self, folder: Path | None = None, *, pid: int | None = None,
                 host: str | None = None, token: str | None = None):
        self.folder = Path(folder) if folder is not None else recovery_dir()
        self.pid = os.getpid() if pid is None else int(pid)
        self.host = host or this_host()
        self.token = token or os.urandom(4).hex()
        self.id = f"{self.host}_{self.pid}_{self.token}"
        self._started: float | None = None

    @property
    def project_file(self) -> Path:
        return self.folder / f"{self.id}.s3d"

    @property
    def info_file(self) -> Path:
        return self.folder / f"{self.id}.json"

    def exists(self) -> bool:
        return self.project_file.exists() or self.info_file.exists()

    def write(self, data: bytes, info: dict) -> None:
        """The project's bytes, then the sidecar, each atomically (OSError on failure: the
        files of the previous write are unchanged)."""
        _ensure_folder(self.folder)
        atomic_write_bytes(self.project_file, data)
        if self._started is None:
            self._started = process_started(self.pid)
        side = {"format": SIDECAR_FORMAT, "version": SIDECAR_VERSION, "slot": self.id,
                "host": self.host, "pid": self.pid, "pid_started": self._started,
                "bytes": len(data), **info}
        atomic_write_bytes(self.info_file, json.dumps(side, indent=1).encode("utf-8"))

    def remove(self) -> None:
        remove_slot_files(self.folder, self.id)


def remove_slot_files(folder: Path, slot_id: str) -> None:
    """Delete a slot's files, with temporary files an interrupted write left behind."""
    folder = Path(folder)
    for p in (folder / f"{slot_id}.s3d", folder / f"{slot_id}.json"):
        try:
            p.unlink()
        except FileNotFoundError:
            pass
    try:
        leftovers = [p for p in folder.iterdir() if p.name.startswith(f".{slot_id}.")]
    except OSError:
        return
    for p in leftovers:
        try:
            p.unlink()
        except OSError:
            pass


@dataclass
class RecoveryInfo:
    """An autosaved slot as found in the recovery folder (see :func:`list_slots`)."""

    slot: str
    folder: Path
    host: str
    pid: int
    pid_started: float | None
    saved_at: float
    title: str
    mesh_path: str | None = None
    project_path: str | None = None
    vertices: int | None = None
    faces: int | None = None
    last_change: str | None = None
    changes: int | None = None

    @property
    def project_file(self) -> Path:
        return self.folder / f"{self.slot}.s3d"

    @property
    def info_file(self) -> Path:
        return self.folder / f"{self.slot}.json"

    def is_orphaned(self) -> bool:
        """Written on this host by a process that no longer runs."""
        return self.host == this_host() and not process_running(self.pid, self.pid_started)

    def when_text(self, now: float | None = None) -> str:
        now = time.time() if now is None else now
        stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.saved_at))
        ago = max(0.0, now - self.saved_at)
        if ago < 90:
            rel = f"{ago:.0f} seconds ago"
        elif ago < 90 * 60:
            rel = f"{ago / 60:.0f} minutes ago"
        elif ago < 48 * 3600:
            rel = f"{ago / 3600:.0f} hours ago"
        else:
            rel = f"{ago / 86400:.0f} days ago"
        return f"{stamp} ({rel})"

    def describe(self, now: float | None = None) -> str:
        """What and from when, in words (the recovery dialog's text)."""
        what = self.title
        if self.vertices is not None and self.faces is not None:
            what += f" — {self.vertices:,} vertices, {self.faces:,} triangles"
        lines = [what]
        if self.last_change:
            n = f" ({self.changes} undoable steps)" if self.changes else ""
            lines.append(f"Last change: {self.last_change}{n}")
        origin = self.project_path or self.mesh_path
        if origin:
            lines.append(f"Started from: {origin}")
        lines.append(f"Autosaved: {self.when_text(now)}")
        return "\n".join(lines)


def _parse_slot_id(stem: str) -> tuple[str, int] | None:
    parts = stem.rsplit("_", 2)
    if len(parts) != 3 or not parts[1].isdigit():
        return None
    return parts[0], int(parts[1])


def _read_info(folder: Path, slot_id: str) -> RecoveryInfo | None:
    side = folder / f"{slot_id}.json"
    proj = folder / f"{slot_id}.s3d"
    parsed = _parse_slot_id(slot_id)
    if parsed is None or not proj.is_file():
        return None
    host, pid = parsed
    d: dict = {}
    try:
        d = json.loads(side.read_text("utf-8"))
        if not isinstance(d, dict) or d.get("format") != SIDECAR_FORMAT:
            d = {}
    except (OSError, ValueError):
        d = {}  # an interrupted first write (project written, sidecar not yet)

    def get(key, kind, default=None):
        v = d.get(key, default)
        return v if isinstance(v, kind) and not isinstance(v, bool) else default

    try:
        mtime = proj.stat().st_mtime
    except OSError:
        return None
    return RecoveryInfo(
        slot=slot_id, folder=folder, host=host, pid=pid,
        pid_started=get("pid_started", (int, float)),
        saved_at=float(get("saved_at", (int, float), mtime)),
        title=get("title", str, "unnamed work"), mesh_path=get("mesh_path", str),
        project_path=get("project_path", str), vertices=get("vertices", int),
        faces=get("faces", int), last_change=get("last_change", str),
        changes=get("changes", int))


def list_slots(folder: Path | None = None) -> list[RecoveryInfo]:
    """Every slot in the recovery folder, newest first (running or not)."""
    folder = Path(folder) if folder is not None else recovery_dir()
    try:
        names = {p.stem for p in folder.glob("*.s3d") if not p.name.startswith(".")}
    except OSError:
        return []
    out = [i for i in (_read_info(folder, n) for n in sorted(names)) if i is not None]
    return sorted(out, key=lambda i: i.saved_at, reverse=True)


def orphaned_slots(folder: Path | None = None) -> list[RecoveryInfo]:
    """The slots to offer: written on this host by processes that no longer run, newest
    first. Temporary files of a first write that a crash interrupted (no project written
    yet, nothing to offer) are deleted on the way."""
    folder = Path(folder) if folder is not None else recovery_dir()
    _sweep_leftovers(folder)
    return [i for i in list_slots(folder) if i.is_orphaned()]


def _sweep_leftovers(folder: Path) -> None:
    try:
        temps = [p for p in folder.glob(".*.tmp") if p.is_file()]
    except OSError:
        return
    host = this_host()
    for p in temps:
        m = re.match(r"^\.(.+)\.(?:s3d|json)\.[^.]+\.tmp$", p.name)
        slot_id = m.group(1) if m else ""
        parsed = _parse_slot_id(slot_id)
        if (parsed is None or parsed[0] != host or (folder / f"{slot_id}.s3d").exists()
                or process_running(parsed[1])):
            continue
        try:
            p.unlink()
        except OSError:
            pass


def discard_slot(info: RecoveryInfo) -> None:
    remove_slot_files(info.folder, info.slot)


# ------------------------------------------------------------------------------ the window's side
def in_study_session(window) -> bool:
    session = getattr(window, "study_session", None)
    return session is not None and not getattr(session, "finished", False)


class Autosaver(QObject):
    """Keeps one window's work in its recovery slot (see the module docstring).

    ``saved(path)`` after each write, ``failed(message)`` when one failed (the previous
    autosave stays; the window's message log says so once until a write works again).
    """

    saved = Signal(str)
    failed = Signal(str)
    #: (write number) from the writer thread
    _written = Signal(int)

    DEBOUNCE_MS = 1500
    MAX_WAIT_MS = 60_000

    def __init__(self, window, folder: Path | None = None, debounce_ms: int | None = None,
                 max_wait_ms: int | None = None):
        super().__init__(window)
        self.window = window
        self.slot = RecoverySlot(folder)
        self.debounce = QTimer(self)
        self.debounce.setSingleShot(True)
        self.debounce.setInterval(self.DEBOUNCE_MS if debounce_ms is None else debounce_ms)
        self.debounce.timeout.connect(self.save_now)
        #: the longest a change waits while changes keep restarting the debounce
        self.max_wait = QTimer(self)
        self.max_wait.setSingleShot(True)
        self.max_wait.setInterval(self.MAX_WAIT_MS if max_wait_ms is None else max_wait_ms)
        self.max_wait.timeout.connect(self.save_now)
        self.writes = 0  # successful writes (shown in tests and the measurements)
        self.last_write_seconds: float | None = None  # the worker's time for the last write
        self.last_snapshot_seconds: float | None = None  # the GUI thread's share
        self._dirty = False
        self._closed = False
        self._thread: threading.Thread | None = None
        self._jobs: dict[int, dict] = {}
        self._count = 0
        self._failing = False
        self._written.connect(self._on_written, Qt.ConnectionType.QueuedConnection)
        window.document.subscribe(self._on_document)
        window.undo_stack.indexChanged.connect(self.mark_changed)
        window.undo_stack.cleanChanged.connect(self.mark_changed)
        for panel in getattr(window, "panels", {}).values():
            form = getattr(panel, "form", None)
            if form is not None:
                form.changed.connect(self.mark_changed)

    # -- state -------------------------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        """Something changed since the last autosave."""
        return self._dirty

    @property
    def writing(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def idle(self) -> bool:
        """Nothing changed since the last autosave and no write is under way (or unreported)."""
        return not self._dirty and not self.writing and not self._jobs

    def _wanted(self) -> bool:
        doc = self.window.document
        return (not self._closed and not doc.is_empty and doc.modified
                and not in_study_session(self.window))

    def _on_document(self, _what: str) -> None:
        self.mark_changed()

    def mark_changed(self, *_args) -> None:
        """Something changed: write after a pause in the changes (and at least every
        ``max_wait`` while they keep coming)."""
        if self._closed:
            return
        self._dirty = True
        self.debounce.start()
        if not self.max_wait.isActive():
            self.max_wait.start()

    # -- writing -----------------------------------------------------------------------------
    def snapshot(self) -> tuple:
        """(Project, sidecar dict) of the work now; GUI thread (reads the panels' widgets).
        The document's states are immutable, so the worker may read them later."""
        win = self.window
        doc = win.document
        project = win.current_project()
        stack = win.undo_stack
        project_path = getattr(win, "project_path", None)
        title = (project_path.name if project_path else
                 (doc.path.name if doc.path else "untitled"))
        st = doc.state
        info = {"saved_at": time.time(), "title": title,
                "mesh_path": str(Path(doc.path).resolve()) if doc.path else None,
                "project_path": str(Path(project_path).resolve()) if project_path else None,
                "vertices": int(len(st.V)), "faces": int(len(st.F)),
                "fields": sorted(st.fields), "handles": len(st.handles),
                "changes": int(stack.index()),
                "last_change": stack.undoText() or None}
        from app import __version__

        info["app_version"] = __version__
        return project, info

    def save_now(self, wait: bool = False) -> bool:
        """Write the work now if it changed since the last autosave (remove the slot when
        there is nothing unsaved to keep). With ``wait`` the write is finished on return
        (also one already under way). Returns True when a write was started."""
        if self._closed:
            return False
        self.debounce.stop()
        self.max_wait.stop()
        if not self._wanted():
            self._dirty = False
            self.remove_files()
            return False
        if self.writing:  # one write at a time: this change follows when it ends
            if not wait:
                self._dirty = True
                return False
            self._finish(self._thread)
        if not self._dirty:
            return False
        t0 = time.perf_counter()
        try:
            project, info = self.snapshot()
        except Stylize3DError as e:  # a panel's settings cannot be read now
            self._report_failure(str(e))
            return False
        self.last_snapshot_seconds = time.perf_counter() - t0
        self._dirty = False
        self._count += 1
        n = self._count
        job = self._jobs[n] = {"error": None, "seconds": None}
        slot, signal = self.slot, self._written

        def work() -> None:
            from app.project import project_bytes

            t1 = time.perf_counter()
            try:
                slot.write(project_bytes(project), info)
            except (Stylize3DError, OSError) as e:
                job["error"] = str(e)
            except Exception as e:  # noqa: BLE001 - said in the message log, never raised
                job["error"] = f"{type(e).__name__}: {e}"
            job["seconds"] = time.perf_counter() - t1
            try:
                signal.emit(n)
            except RuntimeError:  # the window is gone
                pass

        self._thread = threading.Thread(target=work, name="autosave", daemon=True)
        self._thread.start()
        if wait:
            self._finish(self._thread)
        return True

    def _finish(self, thread: threading.Thread | None) -> None:
        if thread is not None:
            thread.join()
        for n in sorted(self._jobs):
            self._on_written(n)

    def wait(self) -> None:
        """Block until the write under way (if any) has ended and been taken into account."""
        self._finish(self._thread)

    def _on_written(self, n: int) -> None:
        job = self._jobs.pop(n, None)
        if job is None:  # taken into account already (save_now(wait=True))
            return
        self.last_write_seconds = job["seconds"]
        if job["error"]:
            self._dirty = True
            self._report_failure(job["error"])
        else:
            self.writes += 1
            if self._failing:
                self._failing = False
                self._say("Autosave works again.", "info")
            self.saved.emit(str(self.slot.project_file))
        if self._dirty and not self._closed:  # changed during the write, or to retry
            if job["error"]:
                if not self.max_wait.isActive():
                    self.max_wait.start()
            else:
                self.debounce.start()

    def _report_failure(self, message: str) -> None:
        self.failed.emit(message)
        if not self._failing:
            self._failing = True
            self._say(f"Autosave failed ({message}). The last autosave is kept; it is tried "
                      "again at the next change. Save your work (File > Save Project As…).",
                      "error")

    def _say(self, text: str, level: str) -> None:
        report = getattr(self.window, "report", None)
        if callable(report):
            try:
                report(text, level)
            except RuntimeError:
                pass

    def remove_files(self) -> None:
        """Delete this window's slot (after the write under way, if any)."""
        if self.writing:
            self._finish(self._thread)
        self.slot.remove()

    def close(self) -> None:
        """The window closes normally: stop, and remove this window's recovery files."""
        if self._closed:
            return
        self._closed = True
        self.debounce.stop()
        self.max_wait.stop()
        self.remove_files()


# ------------------------------------------------------------------------------ recovery
class RecoveryDialog(QDialog):
    """Asks what to do with one autosaved work: Recover, Discard, or Decide Later. ``choice``
    holds the answer (:data:`RECOVER`, :data:`DISCARD`, :data:`LATER`; Esc / closing: LATER).
    Tests click its buttons (``recover_button``, ``discard_button``, ``later_button``)."""

    def __init__(self, info: RecoveryInfo, parent=None, more: int = 0):
        super().__init__(parent)
        self.info = info
        self.choice = LATER
        self.setWindowTitle("Recover unsaved work?")
        self.setModal(True)
        lay = QVBoxLayout(self)
        head = QLabel("<b>Stylize3D did not close normally.</b> Work that was not saved had "
                      "been autosaved:")
        head.setWordWrap(True)
        lay.addWidget(head)
        self.text = QLabel(info.describe())
        self.text.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.text.setStyleSheet("margin: 8px 16px;")
        lay.addWidget(self.text)
        tail = ("Recover opens it as unsaved work (save it to keep it); Discard deletes the "
                "autosaved copy; Decide Later keeps it for the next start.")
        if more:
            tail += f" {more} more autosaved work{'s' if more > 1 else ''} follow."
        note = QLabel(tail)
        note.setWordWrap(True)
        lay.addWidget(note)
        row = QHBoxLayout()
        row.addStretch(1)
        self.recover_button = QPushButton("Recover")
        self.recover_button.setToolTip("Open the autosaved work in this window")
        self.discard_button = QPushButton("Discard")
        self.discard_button.setToolTip(f"Delete the autosaved copy ({info.project_file})")
        self.later_button = QPushButton("Decide Later")
        self.later_button.setToolTip("Keep the autosaved copy; it is offered at the next start")
        for b, choice in ((self.recover_button, RECOVER), (self.discard_button, DISCARD),
                          (self.later_button, LATER)):
            b.clicked.connect(lambda _=False, c=choice: self._choose(c))
            row.addWidget(b)
        lay.addLayout(row)
        self.recover_button.setDefault(True)
        self.recover_button.setFocus()

    def _choose(self, choice: str) -> None:
        self.choice = choice
        if choice == LATER:
            self.reject()
        else:
            self.accept()

    def ask(self) -> str:
        self.exec()
        return self.choice


def recover(window, info: RecoveryInfo) -> bool:
    """Make the autosaved work of ``info`` the window's document, as unsaved work whose undo
    history starts there (see the module docstring). A slot that cannot be read gets a plain
    message and is kept."""
    from app import dialogs
    from app.project import read_project

    try:
        project = read_project(info.project_file)
    except Stylize3DError as e:
        dialogs.error(window, "Cannot recover the autosaved work",
                      f"{e}\n\nThe autosaved file is kept in {info.folder}.")
        return False
    problems = window.load_project(project)
    doc = window.document
    # never "clean": undoing later edits back to here does not make it saved
    window.undo_stack.resetClean()
    doc.modified = True
    doc.path = Path(info.mesh_path) if info.mesh_path else None
    window.project_path = Path(info.project_path) if info.project_path else None
    window._update_title()
    autosaver = getattr(window, "autosave", None)
    if autosaver is not None:
        autosaver.mark_changed()
        autosaver.save_now(wait=True)  # this window's own copy first ...
        if autosaver.slot.exists():
            discard_slot(info)  # ... then the recovered one goes
    else:
        discard_slot(info)
    st = project.state
    msg = (f"Recovered {info.title} as autosaved {info.when_text()}: {len(st.V):,} vertices, "
           f"{len(st.F):,} triangles, {len(st.fields)} painted field(s), "
           f"{len(st.handles)} handle(s). It is not saved: use File > Save Project As… "
           "to keep it.")
    if problems:
        msg += " Some panel settings were not restored: " + "; ".join(problems)
    window.report(msg)
    return True


def offer_recovery(window, ask=None, folder: Path | None = None) -> bool:
    """At start-up: offer each orphaned slot (newest first) until one is recovered. ``ask``
    (``ask(dialog) -> choice``) replaces running the dialog (tests). Returns True when work
    was recovered into ``window``. Nothing is offered in a study session. A defect here never
    stops the start: it is printed and said in the message log, and the window opens empty."""
    if in_study_session(window):
        return False
    try:
        return _offer(window, ask, folder)
    except Exception as e:  # noqa: BLE001 - see the docstring
        import traceback

        traceback.print_exc()
        window.report(f"Could not offer the autosaved work ({type(e).__name__}: {e}); it is "
                      f"kept in {folder or recovery_dir()}.", "error")
        return False


def _offer(window, ask, folder) -> bool:
    slots = orphaned_slots(folder)
    for k, info in enumerate(slots):
        dlg = RecoveryDialog(info, window, more=len(slots) - k - 1)
        try:
            choice = ask(dlg) if ask is not None else dlg.ask()
        finally:
            dlg.deleteLater()
        if choice == RECOVER:
            if recover(window, info):
                left = len(slots) - k - 1
                if left:
                    window.report(f"{left} more autosaved work{'s are' if left > 1 else ' is'} "
                                  f"kept in {info.folder}; offered at the next start.")
                return True
        elif choice == DISCARD:
            discard_slot(info)
    return False


__all__ = ["Autosaver", "DISCARD", "ENV_DIR", "LATER", "RECOVER", "RecoveryDialog",
           "RecoveryInfo", "RecoverySlot", "atomic_write_bytes", "discard_slot",
           "in_study_session", "list_slots", "offer_recovery", "orphaned_slots",
           "process_running", "process_started", "recover", "recovery_dir",
           "remove_slot_files", "this_host"]
