"""The driver of a batch: plan (what runs, what is skipped), executors, the report, retries.

Executors: a local ``ProcessPoolExecutor`` ("spawn" context; each process gets the Job once)
or a Dask distributed ``Client(ADDRESS).get_executor()`` (the Job is scattered once to every
worker) -- the same ``concurrent.futures`` interface ``subdivide-train`` uses. At most
``2 x workers`` meshes are in flight; the driver never holds a mesh, only small records.

Resuming: the report gets one JSON line per finished input (flushed and fsync'ed). When a
batch starts, an input whose last record is "done" (or "skipped") with the same key (input
bytes + job) and whose output still has the recorded SHA-256 is skipped, with a "skipped"
record; everything else runs. Records a killed driver never wrote are recovered from the
workers' ``pending/`` files; temporary files of outputs (``.NAME.*.tmp``, a write cut short)
are removed before their input runs again.

A local worker process that dies (kill -9, a crash) breaks the pool: the driver waits for it to
shut down, finds which process died by itself (exit status other than the pool's SIGTERM) and
which input it was working on (the run folder's ``pid-*.json``), counts a retry for that input
only, re-queues every input that was in flight and starts a new pool. A worker that crashed
(segfault, abort) left a crash log with its Python stacks (:mod:`app.crashlog`): its path goes
into the mesh's record (``crash_logs``, and the message and ``crash_log`` of a failed record).
A process the watchdog ended (memory / time limit, :mod:`app.batch.worker`) fails its input
with the reason, without retry. With Dask, the scheduler re-runs a task whose worker died by
itself; after its allowed failures the task's ``KilledWorker`` becomes a failed record.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import json
import os
import shutil
import signal
import time
from collections import deque
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from algorithms.errors import ConnectionFailed, ParameterError, Stylize3DError
from app.batch.jobs import BatchUsageError, Job
from app.batch.worker import file_sha256, init_pool_worker, input_id, limit_file, record_key, \
    run_task

REPORT_NAME = "batch-report.jsonl"
BATCH_DIR = ".batch"
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                     "NUMBA_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
_UNITS = {"": 1, "b": 1, "k": 1e3, "kb": 1e3, "m": 1e6, "mb": 1e6, "g": 1e9, "gb": 1e9,
          "t": 1e12, "tb": 1e12, "kib": 2 ** 10, "mib": 2 ** 20, "gib": 2 ** 30, "tib": 2 ** 40}


class BatchError(Stylize3DError):
    """The batch itself cannot go on (the Dask scheduler went away, ...); exit status 1."""

    exit_code = 1


def parse_size(text) -> int | None:
    """``"4GB"``, ``"512MB"``, ``"1.5GiB"`` -> bytes; ``"none"`` / ``"0"`` -> None (no limit)."""
    import re

    s = str(text).strip().lower().replace(" ", "")
    if s in ("none", "0", "off"):
        return None
    m = re.fullmatch(r"([0-9]*\.?[0-9]+)([a-z]*)", s)
    if not m or m.group(2) not in _UNITS or (m.group(2) in ("", "b") and float(m.group(1)) < 1e6):
        raise ParameterError(f"--memory-limit takes a size such as 4GB or 512MB (got {text!r}).")
    return int(float(m.group(1)) * _UNITS[m.group(2)])


def default_memory_limit(workers: int) -> int:
    """The machine's memory less 1 GB for the system, shared by ``workers`` tasks."""
    import psutil

    total = psutil.virtual_memory().total
    return int(max(total - 1e9, total / 2) / max(1, workers))


# ----------------------------------------------------------------------------- the report
def json_records(path) -> Iterator[dict]:
    """The JSON objects of a JSON-lines file written by :class:`ReportWriter`, in order (a
    damaged line -- a write cut short -- is skipped); nothing when the file is missing."""
    p = Path(path)
    if not p.is_file():
        return
    with open(p, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict):
                yield rec


def read_report(path) -> dict[str, dict]:
    """The last record of each input in a report (a damaged line -- a write cut short -- is
    ignored), plus ``"__task_ids__"``: the task ids recorded."""
    last: dict[str, dict] = {}
    ids: set[str] = set()
    for rec in json_records(path):
        if "input" in rec:
            last[rec["input"]] = rec
            if rec.get("task_id"):
                ids.add(rec["task_id"])
    last["__task_ids__"] = ids  # type: ignore[assignment]
    return last


class ReportWriter:
    """Appends one JSON line per record, flushed and fsync'ed (a crash loses no finished line;
    a line cut short by a crash is finished with a newline first)."""

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fh = open(self.path, "a+b")
        self.fh.seek(0, os.SEEK_END)
        if self.fh.tell():
            self.fh.seek(-1, os.SEEK_END)
            if self.fh.read(1) != b"\n":
                self.fh.write(b"\n")

    def write(self, rec: dict) -> None:
        self.fh.seek(0, os.SEEK_END)
        self.fh.write((json.dumps(rec, default=str) + "\n").encode())
        self.fh.flush()
        os.fsync(self.fh.fileno())

    def close(self) -> None:
        self.fh.close()


# ----------------------------------------------------------------------------- the plan
@dataclass
class Item:
    """One input of a batch and what happens to it."""

    input: str
    output: str
    action: str = "run"          # "run" or "skip"
    reason: str = ""
    key: str = ""
    input_id: str = ""
    deaths: int = 0              # times its worker process died (retries used)
    attempts: int = 0            # times it was started in this batch
    task_id: str = ""            # the id of its latest start
    previous: dict | None = None
    crash_logs: list = field(default_factory=list)  # of its worker processes that crashed


def plan(job: Job, inputs, outputs, report, redo: bool = False) -> list[Item]:
    """What a batch would do with each input (the dry run shows it): skip an input whose last
    record is done with the same key and whose output still has the recorded SHA-256."""
    recorded = read_report(report)
    items = []
    for inp, out in zip(inputs, outputs):
        it = Item(str(inp), str(out), input_id=input_id(inp))
        prev = recorded.get(it.input)
        if redo:
            it.reason = "--overwrite: run again"
        elif prev is None:
            it.reason = "not done yet"   # its key is the worker's to compute (one read)
        elif prev.get("status") not in ("done", "skipped"):
            it.reason = f"{prev.get('status')} last time"
        elif not _key(it, job):
            it.reason = "the input cannot be read"
        elif prev.get("key") != it.key:
            it.reason = "the input or the settings changed since it was done"
        elif prev.get("output") != it.output:
            it.reason = "its result now goes elsewhere"
        elif not Path(out).is_file():
            it.reason = "its result is missing"
        elif file_sha256(out) != prev.get("output_sha256"):
            it.reason = "its result was changed since"
        else:
            it.action, it.previous = "skip", prev
            it.reason = (f"done on {prev.get('finished', '?')} with the same input and "
                         f"settings; its result {Path(out).name} is unchanged")
        items.append(it)
    return items


def _key(it: Item, job: Job) -> str:
    """Set and return the item's key (SHA-256 of the input's bytes and the job); "" when the
    input cannot be read (its worker will say why)."""
    try:
        it.key = record_key(file_sha256(it.input), job.key)
    except OSError:
        it.key = ""
    return it.key


# ----------------------------------------------------------------------------- executors
@contextlib.contextmanager
def _threads_per_process(n: int) -> Iterator[None]:
    """Processes started meanwhile see ``n`` threads for OpenMP / BLAS / Numba (they read it
    before importing NumPy); restored afterwards."""
    old = {k: os.environ.get(k) for k in _THREAD_VARIABLES}
    for k in _THREAD_VARIABLES:
        os.environ[k] = str(n)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def make_executor(job: Job, workers: int, scheduler: str | None):
    """``(executor, close, job argument of run_task, slots)``: a local spawn pool whose
    processes get ``job`` once, or a Dask client's executor with ``job`` scattered once."""
    if scheduler:
        from algorithms.subdivision.data import dask_client

        client = dask_client(scheduler)
        slots = max(1, sum(client.nthreads().values()))
        job_ref = client.scatter(job, broadcast=True, hash=False)
        quiet = _quiet_dask_tracebacks()

        def close():
            try:
                client.close()
            finally:
                quiet()

        return client.get_executor(), close, job_ref, slots
    ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=_worker_context(),
                                initializer=init_pool_worker, initargs=(job,))
    return ex, lambda: ex.shutdown(wait=True, cancel_futures=True), None, workers


@contextlib.contextmanager
def process_pool(workers: int, initializer=None, initargs=()) -> Iterator[cf.Executor]:
    """A local pool of ``workers`` "spawn" processes like the batch's own (they never import
    the caller's main script, :func:`_worker_context`), each seeing one thread for OpenMP /
    BLAS / Numba (the cores are shared by the processes); shut down on leaving, queued work
    cancelled. For other commands that spread work over processes (``stylize3d augment``)."""
    with _threads_per_process(1):
        ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=_worker_context(),
                                    initializer=initializer, initargs=initargs)
        try:
            yield ex
        finally:
            ex.shutdown(wait=True, cancel_futures=True)


class _NoTraceback:
    """A logging filter: Dask's own log lines without their tracebacks, empty ones dropped.
    When the scheduler stops, Dask's client logs "ERROR -" with two tracebacks (a closed
    connection, a CancelledError) before the batch says plainly what happened and how to go on
    (issue 39 item 1); a user needs the plain message, not the traceback."""

    def filter(self, record) -> bool:
        record.exc_info, record.exc_text, record.stack_info = None, None, None
        return bool(str(record.getMessage()).strip())


def _quiet_dask_tracebacks():
    """Put :class:`_NoTraceback` on Dask's loggers and their handlers; returns the undo."""
    import logging

    f = _NoTraceback()
    targets = [logging.getLogger(n) for n in ("distributed", "distributed.client",
                                               "distributed.core", "distributed.comm")]
    targets += [h for lg in targets for h in lg.handlers]
    for t in targets:
        t.addFilter(f)

    def undo():
        for t in targets:
            t.removeFilter(f)

    return undo


@contextlib.contextmanager
def _main_hidden():
    """While a worker process is launched: the caller's ``__main__`` names no file and no
    module, so that the "spawn" child does not import it (module docstring of
    :func:`_worker_context`)."""
    import sys

    main = sys.modules.get("__main__")
    if main is None:
        yield
        return
    missing = object()
    saved = {a: main.__dict__.get(a, missing) for a in ("__file__", "__spec__")}
    main.__dict__.pop("__file__", None)
    main.__dict__["__spec__"] = None
    try:
        yield
    finally:
        for a, v in saved.items():
            if v is missing:
                main.__dict__.pop(a, None)
            else:
                main.__dict__[a] = v


def _worker_context():
    """The "spawn" context of the local workers, whose children never import the caller's
    main script. A "spawn" child normally re-runs the main script's top level (to find what
    it defines), so a script that calls :func:`run_batch` without an ``if __name__ ==
    "__main__":`` guard -- the "From Python" example of docs/batch.md saved as a file -- made
    every worker start the batch again, and the workers kept dying (issue 39). The workers run
    only :mod:`app.batch.worker` (the job and the tasks are its objects), so nothing of the
    main script is needed there. POSIX only; elsewhere the plain "spawn" context."""
    import multiprocessing
    import sys

    if sys.platform == "win32":
        return multiprocessing.get_context("spawn")
    return _NoMainSpawnContext()


from multiprocessing import context as _mp_context  # noqa: E402 - next to its only use

if os.name == "posix":
    from multiprocessing import popen_spawn_posix as _popen_spawn

    class _NoMainPopen(_popen_spawn.Popen):
        def _launch(self, process_obj):
            with _main_hidden():
                super()._launch(process_obj)

    class _NoMainProcess(_mp_context.SpawnProcess):
        @staticmethod
        def _Popen(process_obj):
            return _NoMainPopen(process_obj)

    class _NoMainSpawnContext(_mp_context.SpawnContext):
        Process = _NoMainProcess


def _processes(ex) -> dict:
    """The pool's worker processes by pid (kept to read their exit status after a break)."""
    return dict(getattr(ex, "_processes", None) or {})


def _crash_log(path) -> str | None:
    """The crash log a dead worker left, if it crashed (stacks in it), else None."""
    from app.crashlog import has_crash

    return str(path) if path and has_crash(path) else None


def _remove_temp(output: str) -> None:
    """Temporary files of an atomic write of ``output`` cut short (a killed worker)."""
    p = Path(output)
    if p.parent.is_dir():
        for t in p.parent.glob(f".{p.name}.*.tmp"):
            with contextlib.suppress(OSError):
                t.unlink()


# ----------------------------------------------------------------------------- the run
@dataclass
class BatchSummary:
    """What a batch did: counts, seconds, throughput (meshes done per second), the report."""

    total: int = 0
    done: int = 0
    failed: int = 0
    skipped: int = 0
    stopped: bool = False
    seconds: float = 0.0
    throughput: float = 0.0
    report: str = ""
    out_dir: str = ""
    executor: str = "local"
    workers: int = 0
    failed_inputs: list = field(default_factory=list)

    @property
    def remaining(self) -> int:
        return self.total - self.done - self.failed - self.skipped

    @property
    def exit_code(self) -> int:
        """0 when every input is done or skipped, 1 otherwise."""
        return 0 if self.remaining == 0 and not self.failed else 1

    def counts(self) -> dict:
        return {"total": self.total, "done": self.done, "failed": self.failed,
                "skipped": self.skipped, "remaining": self.remaining}

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(remaining=self.remaining, exit_code=self.exit_code)
        return d


def _lock(batch_dir: Path):
    """An exclusive lock on OUT_DIR/.batch/lock for the run (released by the OS if the driver
    dies); another batch into the same folder is refused."""
    fh = open(batch_dir / "lock", "a+")
    try:
        import fcntl
    except ImportError:  # not on POSIX: no lock
        return fh
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        raise BatchUsageError(f"Another batch is writing into {batch_dir.parent}; wait for it "
                              "to finish or choose another output folder.") from None
    return fh


def _recover(pending: Path, writer: ReportWriter, recorded_ids: set) -> int:
    """Records of meshes finished by workers of a driver that was killed before writing them."""
    n = 0
    for f in sorted(pending.glob("*.json")):
        try:
            rec = json.loads(f.read_text())
        except (OSError, ValueError):
            rec = None
        if isinstance(rec, dict) and rec.get("task_id") not in recorded_ids:
            writer.write({**rec, "recovered": True})
            n += 1
        with contextlib.suppress(OSError):
            f.unlink()
    for t in pending.glob(".*.tmp"):
        with contextlib.suppress(OSError):
            t.unlink()
    return n


def run_batch(job: Job, inputs, out_dir, *, workers: int | None = None,
              scheduler: str | None = None, report=None, memory_limit: int | None | str = "auto",
              time_limit: float | None = None, retries: int = 2, redo: bool = False,
              precheck: bool = True, outputs=None,
              on_record: Callable[[dict | None, dict], None] | None = None,
              should_stop: Callable[[], bool] | None = None,
              state_dir: str = BATCH_DIR) -> BatchSummary:
    """Run ``job`` on every input file (module docstring); returns a :class:`BatchSummary`.

    inputs : input files (see :func:`app.batch.collect_inputs`); outputs : their result files
        (default :func:`app.batch.output_names` under ``out_dir``).
    workers : local processes (default: the core count); scheduler : a Dask address instead.
    report : the JSONL report (default ``out_dir/batch-report.jsonl``).
    memory_limit : bytes per task, None for none, "auto" (local: the machine's memory less
        1 GB over the workers; Dask: none). time_limit : seconds per mesh, or None.
    retries : runs again a mesh whose worker died at most this many times.
    redo : run inputs the report says are done, too. precheck : refuse a mesh whose estimated
        memory need exceeds the limit before running it.
    on_record : ``(record, counts)`` after each record (``(None, counts)`` once at the start).
    should_stop : polled a few times a second; True stops the batch (in-flight meshes are
        abandoned without a record, to run again next time).
    state_dir : the folder under ``out_dir`` for the run's lock, pending records and worker
        files (one per shard: :func:`app.batch.inputs.shard_names`).
    """
    from app.batch.inputs import output_names

    t_start = time.perf_counter()
    inputs = [Path(os.path.abspath(p)) for p in inputs]
    out = Path(os.path.abspath(out_dir))
    outputs = [Path(p) for p in outputs] if outputs is not None else output_names(inputs, out)
    report = Path(os.path.abspath(report)) if report else out / REPORT_NAME
    workers = max(1, int(workers or os.cpu_count() or 1))
    if memory_limit == "auto":
        memory_limit = None if scheduler else default_memory_limit(workers)
    out.mkdir(parents=True, exist_ok=True)
    batch_dir = out / state_dir
    (batch_dir / "pending").mkdir(parents=True, exist_ok=True)
    lock = _lock(batch_dir)
    run_dir = batch_dir / f"run-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    summary = BatchSummary(total=len(inputs), report=str(report), out_dir=str(out),
                           executor="dask" if scheduler else "local", workers=workers)
    writer = None
    try:
        for old in batch_dir.glob("run-*"):
            shutil.rmtree(old, ignore_errors=True)
        run_dir.mkdir()
        writer = ReportWriter(report)
        _recover(batch_dir / "pending", writer, read_report(report)["__task_ids__"])
        items = plan(job, inputs, outputs, report, redo)
        todo = deque()
        for it in items:
            if it.action == "skip":
                prev = it.previous or {}
                writer.write({"input": it.input, "output": it.output, "status": "skipped",
                              "message": it.reason, "seconds": 0.0, "key": it.key,
                              "output_sha256": prev.get("output_sha256"),
                              "figures": prev.get("figures", {}), "method": job.method,
                              "recipe": job.recipe,
                              "finished": prev.get("finished")})
                summary.skipped += 1
            else:
                _remove_temp(it.output)
                todo.append(it)
        if on_record is not None:
            on_record(None, summary.counts())
        _Loop(job, todo, summary, writer, run_dir, batch_dir / "pending", workers, scheduler,
              memory_limit, time_limit, retries, precheck, on_record, should_stop).run()
    finally:
        if writer is not None:
            writer.close()
        shutil.rmtree(run_dir, ignore_errors=True)
        lock.close()
    summary.seconds = time.perf_counter() - t_start
    summary.throughput = summary.done / summary.seconds if summary.seconds > 0 else 0.0
    return summary


class _Loop:
    """The submit / collect / retry loop of :func:`run_batch`."""

    def __init__(self, job, todo, summary, writer, run_dir, pending, workers, scheduler,
                 memory_limit, time_limit, retries, precheck, on_record, should_stop):
        self.job, self.todo, self.summary, self.writer = job, todo, summary, writer
        self.run_dir, self.pending = run_dir, pending
        self.workers, self.scheduler = workers, scheduler
        self.limits = {"memory_limit": memory_limit, "time_limit": time_limit,
                       "precheck": precheck}
        self.retries, self.on_record, self.should_stop = retries, on_record, should_stop
        self.count = 0
        self.unexplained = 0  # pool breaks in a row that no mesh could be blamed for
        self.stamp = run_dir.name[len("run-"):]

    # -- records
    def finish(self, it: Item, rec: dict) -> None:
        rec = {**rec, "input": it.input, "output": it.output, "attempts": it.attempts,
               "retries": it.deaths}
        rec.pop("attempt", None)
        rec.setdefault("key", it.key)
        if it.crash_logs:
            rec["crash_logs"] = list(it.crash_logs)
        if rec["status"] != "done":
            rec.pop("output_sha256", None)
            rec.pop("figures", None)
            rec.setdefault("category", "limit" if rec.get("limit") else "error")
        rec.setdefault("finished", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        self.writer.write(rec)
        with contextlib.suppress(OSError):
            (self.pending / f"{rec.get('task_id')}.json").unlink()
        if rec["status"] == "done":
            self.summary.done += 1
        else:
            self.summary.failed += 1
            self.summary.failed_inputs.append(it.input)
        if self.on_record is not None:
            self.on_record(rec, self.summary.counts())

    def failed(self, it: Item, message: str, **extra) -> None:
        self.finish(it, {"status": "failed", "message": message, "seconds": 0.0,
                         "task_id": it.task_id, "method": self.job.method,
                         "recipe": self.job.recipe, **extra})

    def task(self, it: Item) -> dict:
        self.count += 1
        it.attempts += 1
        it.task_id = f"{self.stamp}-{it.input_id}-{self.count}"
        return {"input": it.input, "output": it.output, "input_id": it.input_id,
                "task_id": it.task_id, "run_dir": str(self.run_dir),
                "pending_dir": str(self.pending), "attempt": it.attempts, **self.limits}

    # -- the loop
    def run(self) -> None:
        threads = max(1, (os.cpu_count() or 1) // self.workers)
        with _threads_per_process(threads) if not self.scheduler else contextlib.nullcontext():
            while self.todo:
                if not self.run_executor():
                    return

    def run_executor(self) -> bool:
        """Run the queue on one executor until it is empty (True) or the pool broke (True,
        with the queue refilled) or the batch was stopped (False)."""
        ex, close, job_arg, slots = make_executor(self.job, self.workers, self.scheduler)
        window = 2 * slots
        in_flight: dict = {}
        procs: dict = {}
        broken: list[Item] = []
        refused = False  # the pool broke while a mesh was being handed to it
        try:
            while (self.todo or in_flight) and not broken and not refused:
                if self.should_stop is not None and self.should_stop():
                    self.summary.stopped = True
                    self.abandon(ex, close, in_flight, procs)
                    return False
                while self.todo and len(in_flight) < window and not refused:
                    it = self.todo.popleft()
                    try:
                        in_flight[ex.submit(run_task, job_arg, self.task(it))] = it
                    except BrokenProcessPool:
                        it.attempts -= 1
                        self.todo.appendleft(it)
                        refused = True
                    procs.update(_processes(ex))
                done, _ = cf.wait(list(in_flight), timeout=0.25,
                                  return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    it = in_flight.pop(fut)
                    self.collect(fut, it, broken)
        except KeyboardInterrupt:
            self.summary.stopped = True
            self.abandon(ex, close, in_flight, procs)
            raise
        except BaseException:
            self.abandon(ex, close, in_flight, procs)
            raise
        if not broken and not refused:
            close()
            return True
        procs.update(_processes(ex))
        close()  # the broken pool's manager ends every process and joins them
        for fut, it in in_flight.items():
            self.collect(fut, it, broken)
        self.after_break(broken, procs)
        return True

    def collect(self, fut, it: Item, broken: list) -> None:
        try:
            rec = fut.result()
        except BrokenProcessPool:
            broken.append(it)
            return
        except cf.CancelledError:
            if self.scheduler:
                raise ConnectionFailed("The Dask scheduler cancelled the work (did it "
                                       "stop?). Run the same command again to finish the "
                                       "batch.") from None
            broken.append(it)
            return
        except Exception as e:  # noqa: BLE001
            if type(e).__name__ == "KilledWorker":
                self.failed(it, "the worker process died while working on it (each time the "
                                "scheduler gave it to a worker); the mesh may need more memory "
                                "than a worker has.", category="worker died")
                return
            if self.scheduler and isinstance(e, (OSError, TimeoutError)):
                raise ConnectionFailed(f"Lost the Dask scheduler ({e}). Run the same command "
                                       "again to finish the batch.") from None
            self.failed(it, f"an unexpected error ({type(e).__name__}: {e}).", category="bug")
            return
        self.finish(it, rec)

    def after_break(self, broken: list[Item], procs: dict) -> None:
        """A local pool broke (a worker process died): fail the inputs whose process a limit
        ended, count a retry for the one whose process died by itself, re-queue the rest."""
        died = {pid for pid, p in procs.items()
                if p.exitcode is not None and p.exitcode not in (0, -signal.SIGTERM)}
        working, logs = {}, {}
        for f in self.run_dir.glob("pid-*.json"):
            with contextlib.suppress(OSError, ValueError, KeyError):
                d = json.loads(f.read_text())
                working[d["task_id"]] = int(d["pid"])
                logs[d["task_id"]] = d.get("crash_log")
        culprits = {t for t, pid in working.items() if pid in died}
        if not culprits and not procs:  # no exit statuses to read: suspect every one
            culprits = set(working)
        requeue = []
        blamed = False
        for it in broken:
            _remove_temp(it.output)
            lim = limit_file(self.run_dir, it.input_id)
            reason = None
            if lim.exists():
                with contextlib.suppress(OSError, ValueError):
                    reason = json.loads(lim.read_text())
            if reason and reason.get("task_id") == it.task_id:
                self.failed(it, reason["message"], limit=reason.get("kind"), category="limit")
                blamed = True
                continue
            if it.task_id in culprits:
                blamed = True
                it.deaths += 1
                log = _crash_log(logs.get(it.task_id))
                if log:
                    it.crash_logs.append(log)
                if it.deaths > self.retries:
                    extra = {"crash_log": it.crash_logs[-1]} if it.crash_logs else {}
                    self.failed(it, f"the worker process died while working on it "
                                    f"({it.deaths} times); nothing was written."
                                    + (f" It crashed; the details are in {extra['crash_log']}."
                                       if extra else ""),
                                    category="crash" if extra else "worker died", **extra)
                    continue
            requeue.append(it)
        self.todo.extendleft(reversed(requeue))
        self.unexplained = 0 if blamed or not broken else self.unexplained + 1
        if self.unexplained >= 3:
            raise BatchError("The local worker processes keep stopping before they finish a "
                             "mesh, and no mesh is the cause (3 times in a row); the batch "
                             "stops. What is done is recorded: run the same command again to "
                             "go on.")

    def abandon(self, ex, close, in_flight: dict, procs: dict) -> None:
        """Stop now: queued work is cancelled, the pool's processes are ended (their meshes
        run again next time)."""
        procs.update(_processes(ex))
        for fut in in_flight:
            fut.cancel()
        for p in procs.values():
            with contextlib.suppress(Exception):
                p.terminate()
        with contextlib.suppress(Exception):
            ex.shutdown(wait=False, cancel_futures=True)
        with contextlib.suppress(Exception):
            close()


__all__ = ["BatchError", "BatchSummary", "Item", "REPORT_NAME", "ReportWriter",
           "default_memory_limit", "make_executor", "parse_size", "plan", "read_report",
           "run_batch"]
