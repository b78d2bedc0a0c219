"""The work of one mesh, in a worker process (a local pool's or a Dask worker's): read it, run the
job's recipe to its end, check and write the result atomically, return a small record.

:func:`run_task` is the top-level (picklable) entry point for both executors; a local pool's
processes get the Job once, from :func:`init_pool_worker`, a Dask task gets it as an argument
(scattered once to every worker by the driver).

The watchdog: a thread of the worker process reads the process's resident memory (psutil)
five times a second and the running task's time; over ``memory_limit`` or ``time_limit`` it
writes the reason into the run folder (``limit-<input id>.json``) and ends the process at once
(``os._exit``, exit status :data:`EXIT_MEMORY` / :data:`EXIT_TIME`); the driver then records
the mesh as failed with that reason and does not run it again (a Dask worker that the
scheduler gives the task again finds the reason and returns it at once). In a local pool it
also ends the process when the driver has gone (killed): no orphan keeps computing.

Every task writes ``pid-<pid>.json`` in the run folder when it starts (which input this process
is working on): after a local pool breaks, the driver reads them to know which mesh's worker
died. A finished mesh's record also goes to ``pending/<task id>.json`` (atomically) before the
task returns, so a driver killed between the worker's write and its own report line still
counts the mesh as done when it starts again.

A local pool's worker process is crash-logged (:func:`app.crashlog.install`, in
:func:`init_pool_worker`): a segfault or abort writes every thread's Python stack to its crash
log, whose path ``pid-<pid>.json`` also holds (``crash_log``), so the driver can name it in the
mesh's record. A process this module ends itself (watchdog, driver gone) removes its crash log
first (:func:`app.crashlog.discard`): it did not crash.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import threading
import time
from pathlib import Path

#: exit status of a worker process the watchdog ended (memory, time)
EXIT_MEMORY = 86
EXIT_TIME = 87
#: seconds between two looks of the watchdog
WATCH_EVERY = 0.2

_state: dict = {"job": None, "pool": False, "parent": None}
_current: dict[str, dict] = {}          # task id -> what the watchdog needs
_lock = threading.Lock()
_watchdog: threading.Thread | None = None
_blobs_added: set[str] = set()


# ----------------------------------------------------------------------------- files
def file_sha256(path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def input_id(path) -> str:
    """A short name of an input (its absolute path's hash) for the run folder's files."""
    return hashlib.sha256(os.path.abspath(path).encode()).hexdigest()[:16]


def record_key(input_sha256: str, job_key: str) -> str:
    """The key of a result: the input's bytes and everything of the job (its key)."""
    return hashlib.sha256(f"{input_sha256}:{job_key}".encode()).hexdigest()


def _write_json(path: Path, obj: dict) -> None:
    from algorithms.mesh.io import atomic_write

    text = json.dumps(obj, default=str).encode()
    atomic_write(path, lambda fh: fh.write(text))


def limit_file(run_dir, iid: str) -> Path:
    return Path(run_dir) / f"limit-{iid}.json"


# ----------------------------------------------------------------------------- watchdog
def init_pool_worker(job) -> None:
    """ProcessPoolExecutor initializer: keep the job, leave Ctrl+C to the driver, watch, and
    keep a crash log (module docstring)."""
    from app import crashlog

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    crashlog.install("batch-worker")
    _state.update(job=job, pool=True, parent=os.getppid())
    _start_watchdog()


def _start_watchdog() -> None:
    global _watchdog
    with _lock:
        if _watchdog is None or not _watchdog.is_alive():
            _watchdog = threading.Thread(target=_watch, name="stylize3d-batch-watchdog",
                                         daemon=True)
            _watchdog.start()


def _gb(n: float) -> str:
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.0f} MB"


def _exit(code: int) -> None:
    """End this worker process now (not a crash: its crash log goes)."""
    from app import crashlog

    crashlog.discard()
    os._exit(code)


def _watch() -> None:
    import psutil

    me = psutil.Process()
    while True:
        time.sleep(WATCH_EVERY)
        if _state["pool"] and os.getppid() != _state["parent"]:
            _exit(0)  # the driver is gone: nobody will read what this computes
        with _lock:
            running = list(_current.values())
        if not running:
            continue
        rss = None
        now = time.monotonic()
        for c in running:
            if c["memory_limit"]:
                rss = me.memory_info().rss if rss is None else rss
                if rss > c["memory_limit"]:
                    _stop(c, EXIT_MEMORY, "memory",
                          f"it needed more than {_gb(c['memory_limit'])} (the memory limit "
                          "per task); it was stopped and nothing was written. Decimate it "
                          "first, or raise --memory-limit.")
            if c["time_limit"] and now - c["t0"] > c["time_limit"]:
                _stop(c, EXIT_TIME, "time",
                      f"it took longer than {c['time_limit']:g} s (the time limit per task); "
                      "it was stopped and nothing was written.")


def _stop(c: dict, code: int, kind: str, message: str) -> None:
    try:
        _write_json(limit_file(c["run_dir"], c["input_id"]),
                    {"kind": kind, "message": message, "task_id": c["task_id"],
                     "pid": os.getpid()})
    finally:
        _exit(code)


# ----------------------------------------------------------------------------- the task
def _ensure_blobs(job) -> None:
    from app.recipes import add_blob

    for ref, data in job.blobs.items():
        if ref not in _blobs_added:
            add_blob(ref, data)
            _blobs_added.add(ref)


def _scalars(d: dict | None) -> dict:
    import math

    out = {}
    for k, v in (d or {}).items():
        if isinstance(v, bool) or (isinstance(v, int) and not isinstance(v, bool)):
            out[k] = v if isinstance(v, bool) else int(v)
        elif isinstance(v, float) or type(v).__name__.startswith(("float", "int")):
            try:
                f = float(v)
            except (TypeError, ValueError):
                continue
            out[k] = f if math.isfinite(f) else None
        elif isinstance(v, str) and len(v) < 200:
            out[k] = v
        elif (isinstance(v, (list, tuple)) and len(v) <= 16
              and all(isinstance(x, str) and len(x) < 40 for x in v)):
            out[k] = list(v)    # e.g. subdivision's levels_used
    return out


def _check_paparazzi(before, last, cache) -> None:
    """The one-mesh command's check of a Paparazzi result (a clean 2-manifold of the input's
    topology, no new self-intersections)."""
    from algorithms.errors import Stylize3DError
    from algorithms.mesh.topology import euler_characteristic, is_manifold
    from algorithms.paparazzi import count_self_intersections

    V, F = last.V, last.F
    run = cache["run"]
    crossings = count_self_intersections(V, F)
    new = run.new_self_intersections(V, F) if crossings else 0
    if not is_manifold(F) or euler_characteristic(F) != euler_characteristic(before.F) or new:
        raise Stylize3DError("Paparazzi failed: the result is not a clean 2-manifold with the "
                             "input's topology; nothing was written. Try a smaller learning "
                             "rate.")


def _figures(job, before, after, outcome) -> dict:
    out = {"vertices_in": int(len(before.V)), "faces_in": int(len(before.F)),
           "vertices": int(len(after.V)), "faces": int(len(after.F)), **_scalars(outcome)}
    if job.method == "cubic":
        from algorithms.deform.cubic import mean_l1_of_normals

        out["l1_normals_before"] = mean_l1_of_normals(before.V, before.F)
        out["l1_normals_after"] = mean_l1_of_normals(after.V, after.F)
    return out


def _read(job, path: str):
    """The MeshState a recipe runs on (a project's with its painting) and the file's notes."""
    from app.cli.common import read_valid
    from app.document import MeshState
    from app.project import is_project_path, read_project

    project = read_project(path) if is_project_path(path) else None
    data, _ = read_valid(path, clean=job.clean, quiet=True, project=project)
    if project is not None and project.state.V.shape == data.V.shape:
        return project.state, list(data.notes)
    return MeshState.make(data.V, data.F), list(data.notes)


def _run(job, task: dict, rec: dict) -> dict:
    import numpy as np
    import psutil

    from algorithms.errors import InvalidMeshError
    from algorithms.mesh import write_mesh

    rec["input_sha256"] = file_sha256(task["input"])
    rec["key"] = record_key(rec["input_sha256"], job.key)
    if job.method == "pipeline":
        return _run_pipeline(job, task, rec)
    state, notes = _read(job, task["input"])
    if getattr(job, "note", ""):
        notes = [job.note] + list(notes)
    if notes:
        rec["notes"] = notes
    limit = task.get("memory_limit")
    if limit and task.get("precheck", True):
        need = psutil.Process().memory_info().rss + len(state.F) * job.bytes_per_face
        if need > limit:
            return {**rec, "status": "failed", "category": "limit", "limit": "memory",
                    "message": f"it would need about {_gb(need)} for its {len(state.F):,} "
                               f"triangles, more than the memory limit per task "
                               f"({_gb(limit)}); it was not run. Decimate it first, or raise "
                               "--memory-limit."}
    _ensure_blobs(job)
    job = _with_project_settings(job, task["input"], rec)
    after, last, recipe = run_step(job, state)
    V, F = np.asarray(after.V), np.asarray(after.F)
    if not (len(V) and len(F) and np.isfinite(V).all() and F.min() >= 0 and F.max() < len(V)):
        raise InvalidMeshError("the result is not a valid mesh (empty, or coordinates that "
                               "are not numbers); nothing was written.")
    if _state["pool"] and os.getppid() != _state["parent"]:
        _exit(0)  # the driver is gone: do not write behind its back
    out = Path(task["output"])
    out.parent.mkdir(parents=True, exist_ok=True)
    # the input's UVs, materials, normals and colours: kept, subdivided or said to be dropped
    from app.cli.attributes import carried_attributes

    attrs, status = carried_attributes(task["input"], state, _attributes_how(job, state),
                                       out, int(job.params.get("levels", 0) or 0), F_out=F)
    write_mesh(out, V, F, attributes=attrs)
    if status:
        rec["surface_attributes"] = status
        rec["notes"] = list(rec.get("notes", [])) + [status["note"]]
    outcome = recipe.outcome(last) if recipe.outcome is not None else {}
    said = ""   # a shape the style barely changed: why (as the line says)
    if job.method == "cubic":
        from algorithms.deform.cubic import CubicParams
        from app.recipes.cubic import change_note

        lam = float(job.params.get("lam", CubicParams().lam))
        said = change_note(state.V, V, F, lam, flags=True)
    elif job.method == "analogy" and "mean_angle_to_targets" in (outcome or {}):
        from algorithms.deform.analogies import AnalogyParams
        from app.recipes.analogies import change_note as analogy_note

        lam = float(job.params.get("lam", AnalogyParams().lam))
        said = analogy_note(state.V, V, float(outcome["mean_angle_to_targets"]), lam,
                            flags=True)
    if said:
        rec["notes"] = list(rec.get("notes", [])) + [said]
    return {**rec, "status": "done", "message": "",
            "output_sha256": file_sha256(out), "figures": _figures(job, state, after, outcome)}


def _with_project_settings(job, path: str, rec: dict):
    """A project given as INPUT to ``batch METHOD`` (a plain command): its saved settings of
    the method's panel for every parameter the flags did not set, as ``stylize3d METHOD
    PROJECT.s3d`` does (issue 39 item 3); the record's notes say which."""
    import dataclasses

    from app.batch.jobs import METHODS
    from app.project import is_project_path, read_project

    if job.source != "flags" or not is_project_path(path):
        return job
    panel = METHODS[job.method].panels[0]
    saved = (read_project(path).panels or {}).get(panel) or {}
    use = {k: v for k, v in (saved.get("params") or {}).items()
           if k in job.params and k not in job.given and job.params[k] != v}
    if not use:
        return job
    rec["notes"] = list(rec.get("notes", [])) + [
        f"the project's saved {panel} settings were used for "
        + ", ".join(f"{k} = {v!r}" for k, v in sorted(use.items()))
        + " (flags given on the command line win)."]
    return dataclasses.replace(job, params={**job.params, **use})


def run_step(job, state):
    """A Job's recipe on ``state`` as the one-mesh command runs it (a Paparazzi result is
    checked as it checks it): ``(result state, last step, recipe)``. The batch's one place
    that computes a method (a step of a step file too)."""
    from algorithms.errors import InvalidMeshError
    from app.recipes import get_recipe

    recipe = get_recipe(job.recipe)
    params = recipe.make_params(job.params)
    options = job.options_for(len(state.F))
    cache: dict = {}
    last = None
    for last in recipe.steps(state, params, options, cache):
        pass
    if last is None:
        raise InvalidMeshError(f"{job.recipe} produced no result.")
    if job.method == "paparazzi":
        _check_paparazzi(state, last, cache)
    return recipe.result(state, last, options), last, recipe


def _run_pipeline(job, task: dict, rec: dict) -> dict:
    """A step file's steps on one input (:mod:`app.batch.pipeline`)."""
    import numpy as np

    from algorithms.mesh import write_mesh
    from algorithms.mesh.io import attributes_kept_by
    from app.batch.pipeline import run_pipeline

    V, F, attrs, figures, notes = run_pipeline(job, task, rec)
    if _state["pool"] and os.getppid() != _state["parent"]:
        _exit(0)  # the driver is gone: do not write behind its back
    out = Path(task["output"])
    out.parent.mkdir(parents=True, exist_ok=True)
    if attrs is not None and not attributes_kept_by(out, attrs):
        notes = [n for n in notes if not n.startswith("kept ")] + [
            f"the input's {attrs.describe()} were not written: {out.suffix} files cannot "
            "hold them (write .obj to keep them)."]
        attrs = None
    write_mesh(out, np.asarray(V), np.asarray(F), attributes=attrs)
    if notes:
        rec["notes"] = list(rec.get("notes", [])) + notes
    return {**rec, "status": "done", "message": "", "output_sha256": file_sha256(out),
            "figures": {"vertices": int(len(V)), "faces": int(len(F)), "steps": figures}}


def _attributes_how(job, state) -> str:
    """What the method does to the input's triangles (:func:`app.cli.common.carried_attributes`):
    "same", "subdivided", or why they are new."""
    if job.method == "subdivide":
        c = int(job.params.get("coarsen_first", 0) or 0)
        if c and c < len(state.V):
            return "'Coarsen first' remade the triangles (QSlim) before subdividing"
        return "subdivided"
    if job.method == "paparazzi":
        return "Paparazzi remakes the triangles when it remeshes, so they have nowhere to go"
    return "same"


_malloc_tuned = False


def _tune_malloc() -> None:
    """Once per worker process: keep glibc from serving every NumPy array over 128 KiB as a
    fresh memory mapping. Dask's nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536``,
    which (glibc ties the mmap threshold to it) made a cubic stylization 30 % slower in a Dask
    worker than in the local pool (benchmarks/batch.py: 0.69x the pool's throughput; 0.92x
    without it). A fixed 32 MiB mmap threshold restores the pool's speed; results are the same
    bits (allocation only). No-op off glibc."""
    global _malloc_tuned
    if _malloc_tuned:
        return
    _malloc_tuned = True
    try:
        import ctypes
        import ctypes.util

        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        M_MMAP_THRESHOLD = -3
        libc.mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024)
    except (OSError, AttributeError):
        pass


#: a failed record's ``category`` by the error's exit status (the README's table); others:
#: "limit" (with ``limit``: "memory" / "time"), "worker died", "crash", "file", "out of
#: memory", "bug", "error"
CATEGORIES = {2: "unreadable input", 3: "cannot write", 4: "invalid mesh", 5: "bad parameter",
              6: "did not converge"}


def run_task(job, task: dict) -> dict:
    """Process one input (module docstring) and return its record: ``input``, ``output``,
    ``status`` ("done" / "failed"), ``message``, ``seconds``, ``key``, ``input_sha256``,
    ``output_sha256``, ``figures``, ``attempt``, ``worker``, ``task_id``, ``finished``.
    Never raises for a problem of the mesh (the record says it)."""
    from algorithms.errors import Stylize3DError

    job = job if job is not None else _state["job"]
    t0 = time.perf_counter()
    _tune_malloc()
    _start_watchdog()
    iid, run_dir = task["input_id"], Path(task["run_dir"])
    rec = {"input": task["input"], "output": task["output"], "status": "failed",
           "message": "", "seconds": 0.0, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
           "attempt": task.get("attempt", 1),
           "task_id": task["task_id"], "method": job.method, "recipe": job.recipe,
           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    from app import __version__

    if getattr(job, "version", __version__) != __version__:
        return {**rec, "category": "version mismatch",
                "message": f"this worker runs Stylize3D {__version__}, the batch was started "
                           f"with {job.version}: install the same version on every worker "
                           "(pip install -e . in the same checkout); nothing was written."}
    stopped = limit_file(run_dir, iid)
    if stopped.exists():  # an earlier try of this task hit a limit (Dask gave it again)
        try:
            reason = json.loads(stopped.read_text())
            return {**rec, "message": reason["message"], "limit": reason.get("kind"),
                    "category": "limit"}
        except (OSError, ValueError, KeyError):
            pass
    from app.crashlog import current_log

    _write_json(run_dir / f"pid-{os.getpid()}.json",
                {"pid": os.getpid(), "task_id": task["task_id"], "input": task["input"],
                 "input_id": iid, "crash_log": current_log()})
    with _lock:
        _current[task["task_id"]] = {
            "task_id": task["task_id"], "input_id": iid, "run_dir": str(run_dir),
            "t0": time.monotonic(), "memory_limit": task.get("memory_limit"),
            "time_limit": task.get("time_limit")}
    try:
        rec = _run(job, task, rec)
    except Stylize3DError as e:
        rec = {**rec, "status": "failed", "message": str(e),
               "category": CATEGORIES.get(getattr(e, "exit_code", 0), "error")}
    except OSError as e:  # the input vanished or cannot be read, a folder cannot be made
        rec = {**rec, "status": "failed", "category": "file",
               "message": f"{e.filename or 'a file'} cannot be read or written "
                          f"({e.strerror or e}); nothing was written."}
    except MemoryError:
        rec = {**rec, "status": "failed", "category": "out of memory",
               "message": "it ran out of memory; nothing was written. Decimate it first, or "
                          "run fewer workers."}
    except Exception as e:  # noqa: BLE001 - a defect of ours: recorded plainly, batch goes on
        import traceback

        from app.cli.common import write_crash_log

        log = write_crash_log(traceback.format_exc())
        rec = {**rec, "status": "failed", "category": "bug",
               "message": f"an unexpected error stopped it ({type(e).__name__}: {e}); nothing "
                          "was written. This is a bug in Stylize3D"
                          + (f"; the details are in {log}." if log else ".")}
    finally:
        with _lock:
            _current.pop(task["task_id"], None)
    rec["seconds"] = time.perf_counter() - t0
    rec["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    if rec["status"] == "done" and task.get("pending_dir"):
        _write_json(Path(task["pending_dir"]) / f"{task['task_id']}.json", rec)
    return rec


__all__ = ["CATEGORIES", "EXIT_MEMORY", "EXIT_TIME", "file_sha256", "init_pool_worker", "input_id",
           "limit_file", "record_key", "run_task"]
