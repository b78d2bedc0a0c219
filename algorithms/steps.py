"""The one shape of an iteration's state (DESIGN.md §2: iterative methods are generators).

Every iterative method is ``method_iter(V, F, params) -> Iterator[Step]``. The GUI's job runner
streams ``Step.V`` into the viewport, plots ``Step.metrics`` and cancels by not asking for the next
step; a plain ``method(V, F, params)`` calls :func:`run_to_end`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import threading
from typing import Any, Callable, Iterable, Iterator

import numpy as np

__all__ = ["Step", "run_to_end", "Cancelled", "with_progress", "isolated_iter",
           "IsolatedProcessError"]


@dataclass
class Step:
    """State after one iteration.

    Attributes
    ----------
    iteration : 1-based index of the finished iteration (0 = the initial state, if yielded).
    total : the planned number of iterations, or None when the method stops on a tolerance.
    V : (n, 3) float64 current vertex positions (a fresh array the consumer may keep).
    metrics : figures worth plotting (energy, residual, displacement, ...), all plain floats.
    message : a short status line for the user.
    """

    iteration: int
    total: int | None
    V: np.ndarray
    metrics: dict[str, float] = field(default_factory=dict)
    message: str = ""

    @property
    def fraction(self) -> float | None:
        """Progress in [0, 1] when ``total`` is known."""
        if not self.total:
            return None
        return min(1.0, max(0.0, self.iteration / self.total))


def run_to_end(steps: Iterable[Step], callback: Callable[[Step], None] | None = None) -> Step:
    """Consume a step generator and return its last step (raises if it yielded none)."""
    last = None
    for last in steps:
        if callback is not None:
            callback(last)
    if last is None:
        raise RuntimeError("the method produced no iteration")
    return last




class Cancelled(Exception):
    """Raised inside a blocking computation (from its progress callback) once its consumer has
    stopped listening; :func:`with_progress` swallows it."""


def with_progress(work: Callable[[Callable[[float, str], None]], Any], V: np.ndarray,
                  result: dict, *, poll_seconds: float = 0.05) -> Iterator[Step]:
    """Stream a blocking computation that reports progress as Steps, and let it be cancelled.

    ``work(progress)`` runs on a helper thread and calls ``progress(fraction, message)`` now and
    then. Meanwhile this generator yields a Step (iteration = per-mille done, total 1000, ``V``
    unchanged, message) whenever the progress moved. Its return value is stored in
    ``result["value"]``; an exception it raises is re-raised here. When the consumer stops
    iterating (``close()``: a cancelled job), the next ``progress`` call raises
    :class:`Cancelled`, which ends the computation early.
    """
    state = {"fraction": 0.0, "message": "", "error": None}
    stop = threading.Event()
    lock = threading.Lock()

    def progress(fraction: float, message: str = "") -> None:
        if stop.is_set():
            raise Cancelled()
        with lock:
            state["fraction"] = float(fraction)
            state["message"] = message

    def target() -> None:
        try:
            result["value"] = work(progress)
        except Cancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 - handed over to the consumer
            state["error"] = exc

    t = threading.Thread(target=target, name="stylize3d-work", daemon=True)
    t.start()
    last = -1
    try:
        while t.is_alive():
            t.join(poll_seconds)
            with lock:
                frac, msg = state["fraction"], state["message"]
            it = int(round(1000 * min(1.0, max(0.0, frac))))
            if it != last and t.is_alive():
                last = it
                yield Step(it, 1000, V, {}, msg)
    finally:
        stop.set()
    if state["error"] is not None:
        raise state["error"]


class IsolatedProcessError(RuntimeError):
    """The child process of :func:`isolated_iter` died without a result (killed, crashed)."""


def _child_threads() -> None:  # pragma: no cover - runs in the child
    """A child process computes on one BLAS/OpenMP thread (the parent's threads are busy)."""
    import os

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def _isolated_main(conn, gen_fn, args, kwargs) -> None:  # pragma: no cover - runs in the child
    _child_threads()
    try:
        gen = gen_fn(*args, **kwargs)
        while True:
            try:
                item = next(gen)
            except StopIteration as stop:
                conn.send(("return", stop.value))
                return
            conn.send(("item", item))
    except BaseException as exc:  # noqa: BLE001 - handed to the parent
        import pickle

        try:
            pickle.dumps(exc)
            conn.send(("error", exc))
        except Exception:  # noqa: BLE001 - an exception that does not pickle
            conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))
    finally:
        conn.close()


def isolated_iter(gen_fn: Callable[..., Iterator], *args, poll_seconds: float = 0.05,
                  **kwargs) -> Iterator:
    """Run the generator ``gen_fn(*args, **kwargs)`` in a child process and yield its items;
    return its return value (``result = yield from isolated_iter(...)``).

    Why: compiled library calls that hold Python's GIL for seconds (ARPACK's restarts and
    Ritz vectors, SciPy's sparse products, PyAMG) freeze a GUI thread even when they run on a
    worker thread; in a child process they cannot. ``gen_fn`` must be importable (a module-level
    function) and its arguments, items and result picklable. The child is started with
    "spawn" (never "fork": the parent may be a multi-threaded Qt process) and one BLAS thread.
    An exception in the child is re-raised here; closing this generator (a cancelled job)
    terminates the child. Costs a process start (about a second: imports) per call.
    """
    import multiprocessing as mp

    def died() -> IsolatedProcessError:
        proc.join(5)
        return IsolatedProcessError(f"the computation's process ended without a result (exit "
                                    f"code {proc.exitcode}); it may have run out of memory")

    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_isolated_main, args=(send, gen_fn, args, kwargs),
                       name="stylize3d-isolated", daemon=True)
    proc.start()
    send.close()
    try:
        while True:
            if not recv.poll(poll_seconds):
                if proc.is_alive():
                    continue
                if not recv.poll(0):
                    raise died()
            try:
                kind, payload = recv.recv()
            except EOFError:
                raise died() from None
            if kind == "item":
                yield payload
            elif kind == "return":
                return payload
            else:
                raise payload
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join(5)
        recv.close()
