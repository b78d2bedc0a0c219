"""Runs an algorithm generator (DESIGN.md §2) on a QThread: progress, live preview, cancel.

``JobRunner.start(name, factory)`` calls ``factory()`` *on the worker thread* (so precomputation
such as factorizations does not freeze the window) and iterates the :class:`~algorithms.steps.Step`
generator it returns. The worker only stores the newest step; a GUI-thread timer publishes it at
most ~30 times a second through :attr:`JobRunner.preview`, and less often when handling a
publication costs the GUI thread much (see :data:`PREVIEW_SHARE`), so a fast method never floods
the event queue, the window keeps answering, and only the GUI thread ever touches VTK. Cancelling sets a flag the worker checks before
asking the generator for its next step; the job then ends with :attr:`cancelled`. Exceptions end
it with :attr:`failed` and a plain message. A new ``start`` while a job runs cancels the old job and
starts the new one as soon as the old thread has stopped (used by live sliders).

A step may carry new faces (remeshing, subdivision): a ``Step`` with an ``F`` attribute that is
not None, such as :class:`MeshStep` or Paparazzi's ``PaparazziStep``; :func:`step_faces` reads it.
The panels stream such steps as whole meshes and commit the last one as the new mesh
(:class:`app.panels.base.MethodPanel`, ``changes_faces``).
"""

from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from PySide6.QtCore import QObject, QThread, QTimer, Signal

from algorithms.errors import Stylize3DError
from algorithms.steps import Step

PREVIEW_INTERVAL_MS = 33  # ~30 Hz at most
#: at most this share of the GUI thread's time goes to handling previews (labels, plots, progress
#: and the repaint of the window they cause): after a publication that kept the GUI thread busy
#: for t seconds, the next waits at least t · (1 − s) / s. The 3D view's own redraws are spaced
#: the same way by the viewport (app/viewport.py).
PREVIEW_SHARE = 0.4


@dataclass
class MeshStep(Step):
    """A :class:`Step` whose mesh has other faces than the input: ``F`` (m, 3) int64 goes with
    ``V`` (n, 3), whose size may differ from the input's too."""

    F: np.ndarray | None = None


def step_faces(step: Step) -> np.ndarray | None:
    """The faces a step carries (``step.F``), or None for a step that only moves vertices."""
    F = getattr(step, "F", None)
    return None if F is None else np.asarray(F)


class _JobThread(QThread):
    """Iterates the generator; communicates only through a lock-protected slot and signals."""

    ended = Signal(object, str, str)  # (last Step or None, status "done"|"cancelled"|"failed", message)

    def __init__(self, name: str, factory: Callable[[], Iterator[Step]]):
        super().__init__()
        self.name = name
        self.factory = factory
        self.cancel_requested = threading.Event()
        self._lock = threading.Lock()
        self._latest: Step | None = None
        self._seq = 0
        self._history: list[tuple[int, dict]] = []  # (iteration, metrics) of every step
        self.details = ""

    def take_latest(self) -> tuple[int, Step | None, list[tuple[int, dict]]]:
        """The newest step and the metrics of every step since the previous call."""
        with self._lock:
            hist, self._history = self._history, []
            return self._seq, self._latest, hist

    def run(self) -> None:  # worker thread
        last = None
        try:
            steps = self.factory()
            for step in steps:
                last = step
                with self._lock:
                    self._latest = step
                    self._seq += 1
                    self._history.append((step.iteration, dict(step.metrics)))
                if self.cancel_requested.is_set():
                    break
            if self.cancel_requested.is_set():
                if hasattr(steps, "close"):
                    steps.close()
                self.ended.emit(last, "cancelled", f"{self.name} was cancelled.")
            elif last is None:
                self.ended.emit(None, "failed", f"{self.name} produced no result.")
            else:
                self.ended.emit(last, "done", "")
        except Stylize3DError as e:
            self.details = traceback.format_exc()
            self.ended.emit(last, "failed", str(e))
        except MemoryError:
            self.details = traceback.format_exc()
            self.ended.emit(last, "failed",
                            f"{self.name} ran out of memory. Try a smaller mesh or fewer iterations.")
        except Exception as e:  # a bug: say so plainly, keep the traceback for the details box
            self.details = traceback.format_exc()
            self.ended.emit(last, "failed",
                            f"{self.name} stopped because of an unexpected error "
                            f"({type(e).__name__}: {e}). Your mesh was not changed.")


class JobRunner(QObject):
    """Runs one job at a time; see the module docstring.

    Signals
    -------
    started(str) : job name.
    progress(int, object, str) : iteration, total (int or None), message.
    preview(object) : the newest Step, throttled to ~30 Hz (GUI thread).
    metrics(object) : list of (iteration, metrics dict) of *every* step since the last emission
        (emitted just before ``preview`` and once more before ``finished``), for plots.
    finished(object) : the last Step of a job that ran to its end.
    cancelled(str) : a cancelled job; the document must be shown as it was.
    failed(str, str) : message for the user, technical details.
    busy_changed(bool)
    """

    started = Signal(str)
    progress = Signal(int, object, str)
    preview = Signal(object)
    metrics = Signal(object)
    finished = Signal(object)
    cancelled = Signal(str)
    failed = Signal(str, str)
    busy_changed = Signal(bool)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self._thread: _JobThread | None = None
        self._pending: tuple[str, Callable] | None = None
        self._published_seq = 0
        self._timer = QTimer(self)
        self._timer.setInterval(PREVIEW_INTERVAL_MS)
        self._timer.timeout.connect(self._publish)
        self.started_at = 0.0
        self.last_duration = 0.0
        self.publish_seconds = 0.0   # GUI time one publication costs (moving average)
        self._last_publish = 0.0
        self._closed = False

    @property
    def busy(self) -> bool:
        return self._thread is not None

    @property
    def name(self) -> str | None:
        return self._thread.name if self._thread else None

    def start(self, name: str, factory: Callable[[], Iterator[Step]]) -> None:
        """Run ``factory()``'s steps; if a job is running, cancel it and queue this one."""
        if self._closed:
            return
        if self._thread is not None:
            self._pending = (name, factory)
            self._thread.cancel_requested.set()
            return
        self._launch(name, factory)

    def cancel(self) -> None:
        """Ask the running job to stop after its current iteration (no-op when idle)."""
        self._pending = None
        if self._thread is not None:
            self._thread.cancel_requested.set()

    def shutdown(self, timeout_ms: int = 30000) -> None:
        """Cancel the running job, wait for its thread to end, and refuse new jobs (app exit)."""
        self._closed = True
        self.cancel()
        t = self._thread
        if t is not None:
            t.wait(timeout_ms)
            self._timer.stop()
            self._thread = None
            t.deleteLater()

    def wait(self, timeout_ms: int = 60000) -> bool:
        """Block until the worker thread ends (tests, shutdown). Signals still need the event loop."""
        t = self._thread
        return True if t is None else t.wait(timeout_ms)

    # -- internals ---------------------------------------------------------------------------
    def _launch(self, name: str, factory: Callable) -> None:
        t = _JobThread(name, factory)
        t.ended.connect(self._on_ended)
        self._thread = t
        self._published_seq = 0
        self.started_at = time.perf_counter()
        self._timer.start()
        self.busy_changed.emit(True)
        self.started.emit(name)
        t.start()

    def _publish(self, t: _JobThread | None = None) -> None:
        final = t is not None
        t = t or self._thread
        if t is None:
            return
        now = time.perf_counter()
        idle = self.publish_seconds * (1.0 - PREVIEW_SHARE) / PREVIEW_SHARE
        if not final and now - self._last_publish < idle:
            return  # the window is still catching up: the newest step waits (none is lost)
        self._last_publish = now
        # two hops through the event loop: the handlers' repaints are done by the second
        QTimer.singleShot(0, lambda: QTimer.singleShot(0, lambda: self._measured(now)))
        seq, step, hist = t.take_latest()
        if t.cancel_requested.is_set():
            return
        if hist:
            self.metrics.emit(hist)
        if step is not None and seq != self._published_seq:
            self._published_seq = seq
            self.progress.emit(step.iteration, step.total, step.message)
            self.preview.emit(step)

    def _measured(self, t0: float) -> None:
        """Zero-time timers fire once the events a publication caused (the handlers, the
        repaints) are done: that is what it cost the GUI thread."""
        cost = time.perf_counter() - t0
        self.publish_seconds = cost if self.publish_seconds == 0.0 else (
            0.7 * self.publish_seconds + 0.3 * cost)

    def _on_ended(self, last: Step | None, status: str, message: str) -> None:
        t = self._thread
        if t is None or self.sender() is not t:
            return
        t.wait()
        self._timer.stop()
        if status == "done":
            self._publish(t)  # the last steps' metrics and the final shape
        self._thread = None
        self.last_duration = time.perf_counter() - self.started_at
        details = t.details
        t.deleteLater()
        pending, self._pending = self._pending, None
        if status == "failed" and pending is None:
            # not busy any more before the error dialog opens: the window must not say
            # "working" with a Cancel button behind a modal message (issue 41)
            self.busy_changed.emit(False)
        if status == "done":
            self.finished.emit(last)
        elif status == "cancelled":
            self.cancelled.emit(message)
        else:
            self.failed.emit(message, details)
        if pending is not None:
            self._launch(*pending)
        elif status != "failed":
            self.busy_changed.emit(False)
