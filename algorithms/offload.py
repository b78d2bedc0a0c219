"""Run compiled calls that keep Python's lock in a helper process (desktop app only).

Some compiled cores never release Python's lock while they work: gpytoolbox's isotropic
remesher (~90 ms per pass on a 14.6k-vertex mesh) and libigl's exact self-intersection test
(~36 ms). Called from a job's worker thread in the desktop app, the window cannot redraw or
react for that long (issue 24: stalls of 105-140 ms during a Paparazzi run on armadillo). A
thread waiting on a pipe does release the lock, so in the app such calls go to one persistent
helper process; everywhere else (command line, tests of the algorithms, batch) they run here,
as before. The results are the same bits either way (the same compiled code on the same input).

``keep_lock_free(True)`` (the desktop app calls it) turns the helper on; :func:`call` runs a
module-level function there, or here when the helper is off. The helper starts on first use
(a process start with "spawn", on the calling thread, which waits on a pipe meanwhile), serves
one call at a time, and exits when this process closes its end of the pipe or exits. Unlike
:func:`algorithms.steps.isolated_iter` (a new process for a whole stage, e.g. ARPACK), the helper
stays, for short calls repeated inside a loop (a remeshing every 30 Paparazzi iterations).
An exception raised by the function is raised again here; a helper that stops mid-call (a crash
in the compiled code) raises :class:`~algorithms.errors.Stylize3DError` instead of taking the app
down with it, and the next call starts a new helper. If no helper can be started the call runs
here.
"""

from __future__ import annotations

import atexit
import threading
from typing import Any, Callable

from .errors import Stylize3DError

__all__ = ["keep_lock_free", "lock_free", "call", "helper_pid", "stop_helper"]

_enabled = False
_lock = threading.Lock()
_proc = None          # the helper (multiprocessing.Process) while it runs
_conn = None          # our end of its pipe
_failed_to_start = False


def keep_lock_free(on: bool = True) -> None:
    """Send lock-holding compiled calls to the helper process (``on``) or run them here."""
    global _enabled
    _enabled = bool(on)


def lock_free() -> bool:
    """True when this process asked for calls that keep Python's lock to run elsewhere (the
    desktop app); solvers then prefer backends that release it (:mod:`algorithms.linalg`)."""
    return _enabled


def _start():
    """The running helper, started if needed; None if none can be started."""
    global _proc, _conn, _failed_to_start
    if _proc is not None and _proc.is_alive():
        return _proc
    if _failed_to_start:
        return None
    import multiprocessing as mp

    from .steps import _child_threads

    # "spawn", never "fork" (a multi-threaded Qt process), as algorithms.steps.isolated_iter;
    # a frozen app's children go through multiprocessing.freeze_support (app/__main__.py)
    ctx = mp.get_context("spawn")
    ours, theirs = ctx.Pipe(duplex=True)
    try:
        proc = ctx.Process(target=_serve, args=(theirs, _child_threads), daemon=True,
                           name="stylize3d-helper")
        proc.start()
    except Exception:  # noqa: BLE001 - no helper: the calls run here
        _failed_to_start = True
        ours.close()
        return None
    finally:
        theirs.close()
    _proc, _conn = proc, ours
    return proc


def call(fn: Callable, *args: Any) -> Any:
    """``fn(*args)``, in the helper process when :func:`keep_lock_free` is on.

    ``fn`` must be a module-level function (pickled by name) and its arguments and result
    picklable (NumPy arrays, numbers, strings).
    """
    if not _enabled:
        return fn(*args)
    with _lock:
        proc = _start()
        if proc is None:
            return fn(*args)
        try:
            _conn.send((fn, args))
            ok, value = _conn.recv()     # waits on the pipe: Python's lock is free meanwhile
        except (EOFError, OSError):
            _stop()
            raise Stylize3DError(
                f"The helper process stopped while running {fn.__name__} (a crash in compiled "
                "code); nothing was changed. Try again, or save your work and restart the "
                "app.") from None
    if not ok:
        raise value
    return value


def helper_pid() -> int | None:
    """The helper process's id while it runs, else None."""
    with _lock:
        return _proc.pid if _proc is not None and _proc.is_alive() else None


def _stop() -> None:
    global _proc, _conn
    if _conn is not None:
        _conn.close()                    # the helper reads end-of-file and exits
    if _proc is not None:
        _proc.join(5)
        if _proc.is_alive():
            _proc.kill()
            _proc.join()
    _proc = _conn = None


def stop_helper() -> None:
    """End the helper process (it is started again by the next :func:`call`). At exit a call
    still waiting for its reply does not hold this up for more than 2 s: the helper is killed."""
    if _lock.acquire(timeout=2.0):
        try:
            _stop()
        finally:
            _lock.release()
    elif _proc is not None and _proc.is_alive():
        _proc.kill()


atexit.register(stop_helper)


def _serve(conn, setup: Callable[[], None]) -> None:  # pragma: no cover - runs in the helper
    """The helper's loop: receive ``(fn, args)``, send ``(ok, result or exception)``."""
    import pickle

    setup()
    while True:
        try:
            fn, args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            reply = (True, fn(*args))
        except Exception as exc:  # noqa: BLE001 - raised again in the caller
            reply = (False, exc)
        try:
            pickle.dumps(reply)
        except Exception as exc:  # noqa: BLE001 - e.g. an exception that does not pickle
            reply = (False, RuntimeError(f"{type(exc).__name__}: {exc}"))
        conn.send(reply)
