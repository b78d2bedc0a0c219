"""`stylize3d batch cubic` on a library of 200 meshes (issue 21): a local pool of 2 workers vs one
process in a row vs a Dask LocalCluster of 2 workers; resuming after the driver is killed; the
driver's peak resident memory for 20 vs 200 meshes.

The library (made in a temporary folder, reproducible from ``--seed``): meshes of tests/data,
each randomly rotated and scaled (a global factor 10^U(-1.5, 1.5) times per-axis factors
U(0.6, 1.6)) and, by the seed, Loop-subdivided once (the small ones), decimated (libigl's
``decimate``, to U(1000, 0.8 x faces) triangles) or left at its size, written as .obj / .off /
.ply; every one of them passes ``validate_mesh`` without cleaning (a draw that does not is
drawn again, counted as "redrawn"). Plus one ~300k-face mesh (rocker-arm, two Loop levels,
321,408 triangles: above the automatic progressive threshold) and four meshes broken on
purpose (non-manifold edge, a NaN coordinate, an empty file, garbage bytes). File names are
``mNNN_<what>.<ext>``, NNN a seeded permutation, so the big and broken ones sit at seeded
places in the (sorted) input order.

Every run is the command itself, ``python -m app batch cubic LIB -o OUT --quiet --json`` with
the cubic defaults (as ``stylize3d cubic``), in a subprocess of this script, into a fresh
folder; the driver's peak resident memory is read from ``/proc/PID/status`` (VmHWM, the
driver only, not its workers) every 50 ms.

  (a) pool          ``--workers 2`` (each worker limited to 1 thread: cores / workers)
  (b) in a row      ``--workers 1`` (one worker process, 2 threads)
  (c) dask          ``--scheduler ADDRESS`` of a ``distributed.LocalCluster(n_workers=2,
                    threads_per_worker=1, processes=True, dashboard_address=None)`` on 127.0.0.1
                    started here (its start-up is printed apart, not in the batch's seconds)
  (d) dask, malloc  the same, without the ``MALLOC_TRIM_THRESHOLD_=65536`` that Dask's nannies
                    put into their workers' environment by default
                    (``distributed.nanny.pre-spawn-environ``): it turns off glibc's dynamic mmap
                    threshold, so every NumPy array over 128 KiB is a fresh mmap; measured here
                    +25-30 % per cubic run on bob. No target; ``--no-malloc-run`` leaves it out.

A Nanny also writes its pre-spawn-environ into the os.environ of the process that starts it
(``MALLOC_TRIM_THRESHOLD_``, ``OMP_NUM_THREADS=1``, ...); the script puts its environment back
after each cluster so that later runs are not affected.

The runs go in rounds, (b) (a) (c) (d) then (d) (c) (a) (b) (``--rounds``, default 2; 1 with
``--quick``): the speed of this virtual machine drifts by tens of per cent from one minute to
the next (other machines on the same host; invisible from inside, no steal time reported), and
the mirrored order cancels a steady drift. Before each run a probe measures what the machine
gives at that moment: a fixed cubic run on bob (median of 3, one thread) alone, then two at once
in two processes; "scaling" = 2 x alone / together (2.0: both cores are ours; 1.0: one core's
worth), the ceiling of (a)/(b) at that time.

For each run: the batch's own seconds (``run_batch``, from the JSON summary: pool start-up,
planning and every mesh; not the interpreter's start-up, printed as "process s"), throughput =
meshes done / seconds, worker-seconds per done mesh (the records' ``seconds``), how busy the
workers were (sum of the records' seconds / (workers x batch seconds)), the driver's peak
memory, and the CPU used by us (this script's process tree) and by other processes of this
machine (/proc/stat) meanwhile, in cores. Ratios of the throughputs summed over the rounds:
(a)/(b) [target >= 1.7] and (c)/(a) [target >= 0.90, i.e. within 10 %].

Checks: every broken mesh failed with a plain message (no traceback, no "bug"), nothing
written for it; every good mesh done, its output on disk with the recorded SHA-256; the outputs
of (a), (b), (c) and the resumed run byte-identical to each other; a sample (``--sample``, the
big mesh and random others) byte-identical to ``python -m app cubic IN -o OUT`` (run first,
which also warms the disk and Numba caches).

Resume: (a) again into a fresh folder; the driver alone is killed (SIGKILL) once the report has
30 % of the inputs' records; its workers must stop by themselves; the same command again must
finish with every input exactly once in its new records (done / failed, or skipped when done
before; records recovered from the workers' pending files aside), no input done twice in the
whole report, the summary's ``skipped`` = the inputs done before the restart, and no partial
file (``*.tmp``, ``*.part``), pending record or run folder left.

Memory: the driver's peak resident memory of (a) (all inputs, the larger of the rounds) vs a
run of every 10th input (same flags, fresh folder); target: within +-100 MB.

Usage: .venv/bin/python benchmarks/batch.py [--count 200] [--quick] [--rounds 2] [--seed 21]
       [--sample 10] [--no-big] [--no-malloc-run] [--keep]
  --quick   20 meshes, one round (a smoke run); --keep leaves the temporary folder (its path is
            printed). The full run takes about 20 minutes on 2 cores.
Exit status 1 when a check fails (a missed ratio target is printed, not an error).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import math
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _timing import mesh_path  # noqa: E402

from algorithms.mesh import loop_subdivide, read_mesh, validate_mesh, write_mesh  # noqa: E402

BASES = ["hand_lowres.obj", "spot_lowres.obj", "wingnut.obj", "fertility.off", "bob.obj",
         "fandisk.off", "rocker-arm.obj", "camelhead.off", "armadillo.obj"]
BIG_BASE = "rocker-arm.obj"          # two Loop levels: 321,408 triangles
SUBDIVIDE_BELOW = 7_000              # faces: one Loop level keeps it under ~30k
BROKEN = ("nonmanifold", "nan", "empty", "garbage")
#: what the message of each broken mesh must say
WHAT = {"nonmanifold": "non-manifold", "nan": "NaN", "empty": "empty", "garbage": "binary data"}
REPORT = "batch-report.jsonl"
PLAIN_BAD = ("Traceback", "bug in Stylize3D", "unexpected error")

_children: list[subprocess.Popen] = []


# ----------------------------------------------------------------------------- the library
def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _transform(V, rng) -> np.ndarray:
    scale = 10 ** rng.uniform(-1.5, 1.5) * rng.uniform(0.6, 1.6, size=3)
    return (V @ _rotation(rng).T) * scale


def _ok(V, F) -> bool:
    rep = validate_mesh(V, F)
    return not rep.errors and not rep.needs_cleaning


def _draw(bases, rng):
    """One good mesh: (V, F, description)."""
    import igl

    names = list(bases)
    name = names[rng.integers(len(names))]
    V, F = bases[name]
    ops = ["subdivide", "decimate", "none"] if len(F) < SUBDIVIDE_BELOW else ["decimate", "none"]
    op = ops[rng.integers(len(ops))]
    if op == "subdivide":
        V, F = loop_subdivide(V, F, 1)
    elif op == "decimate":
        target = int(rng.integers(1000, max(1001, int(0.8 * len(F)))))
        V, F = igl.decimate(np.asarray(V, float), np.asarray(F, np.int32), target)[:2]
        V, F = np.asarray(V, float), np.asarray(F, np.int64)
    return _transform(V, rng), F, f"{Path(name).stem}-{op}"


def _write_broken(path: Path, kind: str, bases, rng) -> None:
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "garbage":
        path.write_bytes(rng.integers(0, 256, 8192, dtype=np.uint8).tobytes())
    elif kind == "nan":
        V, F = bases["hand_lowres.obj"]
        write_mesh(path, _transform(V, rng), F)
        lines = path.read_text().splitlines()
        k = next(i for i, ln in enumerate(lines) if ln.startswith("v ")) + 7
        lines[k] = "v 0.1 nan 0.3"
        path.write_text("\n".join(lines) + "\n")
    elif kind == "nonmanifold":
        V, F = bases["spot_lowres.obj"]
        a, b = F[0, 0], F[0, 1]
        V = np.vstack([V, V[[a, b]].mean(0) + [0.0, 0.0, 0.3]])
        F = np.vstack([F, [[b, a, len(V) - 1]]])   # a third face on the edge (a, b)
        write_mesh(path, _transform(V, rng), F)
    else:
        raise ValueError(kind)


def make_library(lib: Path, count: int, seed: int, big: bool):
    """Write the library; returns (good paths, {broken path: kind}, big path or None, stats)."""
    rng = np.random.default_rng(seed)
    bases = {}
    for n in BASES:
        p = mesh_path(n)
        if p.exists():
            m = read_mesh(p)
            bases[n] = (np.asarray(m.V, float), np.asarray(m.F, np.int64))
    lib.mkdir(parents=True)
    n_regular = count - len(BROKEN) - (1 if big else 0)
    if n_regular < 1:
        raise SystemExit(f"--count must be at least {len(BROKEN) + 2}")
    slots = rng.permutation(count)
    good, broken, faces, redrawn, kinds, formats = [], {}, [], 0, Counter(), Counter()
    k = 0
    for _ in range(n_regular):
        while True:
            V, F, what = _draw(bases, rng)
            if _ok(V, F):
                break
            redrawn += 1
        ext = [".obj", ".obj", ".off", ".ply"][rng.integers(4)]
        p = lib / f"m{slots[k]:03d}_{what}{ext}"
        k += 1
        write_mesh(p, V, F)
        good.append(p)
        faces.append(len(F))
        kinds[what.rsplit("-", 1)[1]] += 1
        formats[ext] += 1
    big_path = None
    if big:
        V, F = bases[BIG_BASE]
        V, F = loop_subdivide(V, F, 2)
        big_path = lib / f"m{slots[k]:03d}_big-{Path(BIG_BASE).stem}-loop2.obj"
        k += 1
        write_mesh(big_path, _transform(V, rng), F)
        good.append(big_path)
    for kind in BROKEN:
        ext = ".obj"
        p = lib / f"m{slots[k]:03d}_broken-{kind}{ext}"
        k += 1
        _write_broken(p, kind, bases, rng)
        broken[p] = kind
    stats = {"faces": faces, "redrawn": redrawn, "kinds": kinds, "formats": formats,
             "big_faces": 4 ** 2 * len(bases[BIG_BASE][1]) if big else 0}
    return good, broken, big_path, stats


# ----------------------------------------------------------------------------- runs
def _sha(path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _vm_hwm_kb(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


class PeakMemory(threading.Thread):
    """Polls the peak resident memory (VmHWM) of one process (not its children)."""

    def __init__(self, pid: int):
        super().__init__(daemon=True)
        self.pid, self.peak_kb, self.stop = pid, 0, threading.Event()

    def run(self) -> None:
        import psutil

        while not self.stop.is_set():
            kb = _vm_hwm_kb(self.pid)
            if kb is None:
                try:
                    kb = psutil.Process(self.pid).memory_info().rss // 1024
                except psutil.Error:
                    kb = 0
            self.peak_kb = max(self.peak_kb, kb)
            self.stop.wait(0.05)

    @property
    def mb(self) -> float:
        return self.peak_kb * 1024 / 1e6


class CpuWindow:
    """CPU seconds over a stretch of time: ours (this process and its waited-for descendants:
    a batch driver and the pool workers it joined, the Dask workers once the cluster closed)
    and the whole machine's busy time (/proc/stat), to tell what other processes used."""

    def __enter__(self):
        self.t0, self.ours0, self.machine0 = time.perf_counter(), self._ours(), self._machine()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.t0
        self.ours = self._ours() - self.ours0
        self.machine = self._machine() - self.machine0
        return False

    @staticmethod
    def _ours() -> float:
        c, s = resource.getrusage(resource.RUSAGE_CHILDREN), resource.getrusage(
            resource.RUSAGE_SELF)
        return c.ru_utime + c.ru_stime + s.ru_utime + s.ru_stime

    @staticmethod
    def _machine() -> float:
        try:
            with open("/proc/stat") as fh:
                v = [int(x) for x in fh.readline().split()[1:8]]
        except OSError:
            return float("nan")
        user, nice, system, _idle, _iowait, irq, softirq = v
        return (user + nice + system + irq + softirq) / os.sysconf("SC_CLK_TCK")

    def text(self) -> str:
        return (f"cpu: ours {self.ours / self.wall:.2f} cores, other processes "
                f"{max(0.0, self.machine - self.ours) / self.wall:.2f} cores")


def _batch_cmd(inputs, out: Path, flags) -> list[str]:
    return [sys.executable, "-m", "app", "batch", "cubic", *map(str, inputs), "-o", str(out),
            "--quiet", "--json", *flags]


def _start(cmd, log: Path) -> subprocess.Popen:
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=open(log, "wb"),
                            text=True, start_new_session=True)
    _children.append(proc)
    return proc


def run_batch_cli(inputs, out: Path, flags, log: Path) -> dict:
    """One batch as a subprocess: its JSON summary, exit status, wall seconds, driver peak MB."""
    t0 = time.perf_counter()
    with CpuWindow() as cpu:
        proc = _start(_batch_cmd(inputs, out, flags), log)
        mem = PeakMemory(proc.pid)
        mem.start()
        stdout, _ = proc.communicate()
        mem.stop.set()
        mem.join()
    wall = time.perf_counter() - t0
    try:
        summary = json.loads(stdout)
    except ValueError:
        summary = None
    if summary is None:
        print(f"  the batch printed no summary (exit {proc.returncode}); its stderr:")
        print("  " + log.read_text(errors="replace")[-3000:].replace("\n", "\n  "))
    return {"summary": summary, "code": proc.returncode, "wall": wall, "peak_mb": mem.mb,
            "cpu": cpu}


def records(out: Path) -> list[dict]:
    p = out / REPORT
    if not p.exists():
        return []
    return [json.loads(ln) for ln in p.read_text().splitlines() if ln.strip()]


def last_records(out: Path) -> dict[str, dict]:
    return {r["input"]: r for r in records(out)}


def run_figures(run: dict, out: Path, workers: int) -> dict:
    s = run["summary"] or {}
    recs = [r for r in records(out) if r["status"] in ("done", "failed")]
    done = [r for r in recs if r["status"] == "done"]
    busy = sum(r.get("seconds", 0.0) for r in recs)
    secs = s.get("seconds") or float("nan")
    return {"seconds": secs, "throughput": s.get("throughput") or 0.0,
            "done": s.get("done"), "failed": s.get("failed"), "wall": run["wall"],
            "per_mesh": statistics.mean(r["seconds"] for r in done) if done else float("nan"),
            "busy": busy / (workers * secs) if secs == secs else float("nan"),
            "peak_mb": run["peak_mb"], "code": run["code"],
            "workers_seen": len({r.get("worker") for r in recs}), "cpu": run["cpu"]}


def _print_run(label: str, f: dict) -> None:
    print(f"  {label:19s} {f['seconds']:7.1f} s  {f['throughput']:6.3f} meshes/s  "
          f"done {f['done']} failed {f['failed']}  {f['per_mesh']:5.2f} s/mesh in a worker  "
          f"workers busy {100 * f['busy']:5.1f} %  driver peak {f['peak_mb']:5.0f} MB  "
          f"(process {f['wall']:.1f} s, exit {f['code']})")
    print(f"  {'':19s} {f['cpu'].text()}")


# ----------------------------------------------------------------------------- checks
class Checks:
    def __init__(self):
        self.failures: list[str] = []

    def check(self, ok: bool, what: str) -> bool:
        if not ok:
            self.failures.append(what)
            print(f"  CHECK FAILED: {what}")
        return ok


def check_outcome(c: Checks, label: str, out: Path, good, broken) -> dict[str, str]:
    """Every broken mesh failed plainly, every good one done and written; {input: sha}."""
    last = last_records(out)
    shas = {}
    for p in good:
        r = last.get(str(p))
        if not c.check(r is not None and r["status"] in ("done", "skipped"),
                       f"{label}: {p.name} not done: {r and r.get('message')}"):
            continue
        o = Path(r["output"])
        if c.check(o.is_file() and _sha(o) == r.get("output_sha256"),
                   f"{label}: the output of {p.name} is missing or not the recorded one"):
            shas[str(p)] = r["output_sha256"]
    for p in broken:
        r = last.get(str(p))
        msg = (r or {}).get("message", "")
        c.check(r is not None and r["status"] == "failed" and len(msg) > 20
                and not any(b in msg for b in PLAIN_BAD),
                f"{label}: broken {p.name} not failed plainly: {r}")
        c.check(r is None or not Path(r["output"]).exists(),
                f"{label}: something was written for broken {p.name}")
    return shas


def partial_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*")
            if p.name.endswith((".tmp", ".part")) or ".tmp" in p.name or ".part" in p.name]


# ----------------------------------------------------------------------------- resume
def resume(c: Checks, lib: Path, out: Path, good, broken, count: int, ref_shas, tmp: Path):
    import psutil

    report = out / REPORT
    threshold = math.ceil(0.3 * count)
    t0 = time.perf_counter()
    proc = _start(_batch_cmd([lib], out, ["--workers", "2"]), tmp / "resume1.log")
    workers: set[int] = set()
    while proc.poll() is None:
        with_lines = report.read_text().count("\n") if report.exists() else 0
        try:
            workers |= {ch.pid for ch in psutil.Process(proc.pid).children(recursive=True)}
        except psutil.Error:
            pass
        if with_lines >= threshold:
            break
        time.sleep(0.02)
    if not c.check(proc.poll() is None, "resume: the first run ended before it was killed"):
        return None
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    t_kill = time.perf_counter() - t0
    deadline = time.time() + 30
    alive = workers
    while alive and time.time() < deadline:
        alive = {p for p in alive if psutil.pid_exists(p)
                 and psutil.Process(p).status() != psutil.STATUS_ZOMBIE}
        time.sleep(0.05)
    c.check(not alive, f"resume: {len(alive)} worker process(es) still running 30 s after "
                       "their driver was killed")
    for pid in alive:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    first = records(out)
    n_first = len(first)
    done_first = {r["input"] for r in first if r["status"] == "done"}
    pending = list((out / ".batch" / "pending").glob("*.json"))
    tmp_after_kill = partial_files(out)
    run2 = run_batch_cli([lib], out, ["--workers", "2"], tmp / "resume2.log")
    s = run2["summary"] or {}
    allrecs = records(out)
    new = allrecs[n_first:]
    recovered = [r for r in new if r.get("recovered")]
    own = [r for r in new if not r.get("recovered")]
    per_input = Counter(r["input"] for r in own)
    inputs = {str(p) for p in good} | {str(p) for p in broken}
    c.check(set(per_input) == inputs and all(v == 1 for v in per_input.values()),
            "resume: the second run's records are not exactly one per input "
            f"({sum(v != 1 for v in per_input.values())} inputs with more, "
            f"{len(inputs - set(per_input))} without)")
    done_total = Counter(r["input"] for r in allrecs if r["status"] == "done")
    twice = [i for i, v in done_total.items() if v > 1]
    c.check(not twice, f"resume: done twice: {twice[:5]}")
    before = done_first | {r["input"] for r in recovered if r["status"] == "done"}
    skipped_recs = [r for r in own if r["status"] == "skipped"]
    c.check(s.get("skipped") == len(before) == len(skipped_recs)
            and {r["input"] for r in skipped_recs} == before,
            f"resume: skipped {s.get('skipped')} (records {len(skipped_recs)}) but "
            f"{len(before)} were done before the restart")
    c.check(s.get("remaining") == 0 and s.get("done", 0) + s.get("skipped", 0) == len(good)
            and s.get("failed") == len(broken),
            f"resume: the second run did not finish every input: {s}")
    left = partial_files(out) + partial_files(lib)
    c.check(not left, f"resume: partial files left: {left[:5]}")
    c.check(not list((out / ".batch" / "pending").glob("*"))
            and not list((out / ".batch").glob("run-*")),
            "resume: pending records or run folders left in .batch/")
    shas = check_outcome(c, "resume", out, good, broken)
    diff = [i for i in shas if ref_shas.get(i) != shas[i]]
    c.check(not diff, f"resume: {len(diff)} outputs differ from run (a)'s")
    return {"killed_at": t_kill, "records_first": n_first, "done_first": len(done_first),
            "pending_at_kill": len(pending), "tmp_at_kill": len(tmp_after_kill),
            "recovered": len(recovered), "skipped": s.get("skipped"),
            "skipped_records": len(skipped_recs), "done2": s.get("done"),
            "failed2": s.get("failed"), "seconds2": s.get("seconds"), "wall2": run2["wall"],
            "code2": run2["code"], "workers_first": len(workers)}


# ----------------------------------------------------------------------------- probe
PROBE_MESH = "bob.obj"
PROBE_RUNS = 3


def probe_work() -> float:
    """The probe's own work (``--probe``): median seconds of a cubic run on bob, one thread."""
    from app.document import MeshState
    from app.recipes import get_recipe

    m = read_mesh(mesh_path(PROBE_MESH))
    state = MeshState.make(m.V, m.F)
    recipe = get_recipe("Cubic")
    params = recipe.make_params({})
    options = {"plane_axis": 0, "progressive": None, "multigrid": False}
    ts = []
    for _ in range(PROBE_RUNS + 1):   # the first one loads the compiled kernels
        t = time.perf_counter()
        for _ in recipe.steps(state, params, options, {}):
            pass
        ts.append(time.perf_counter() - t)
    return statistics.median(ts[1:])


def probe() -> dict:
    """What the machine gives now: the probe alone, then two probes at once (two processes,
    one thread each). scaling = 2 x alone / together: 2.0 when both cores are ours, 1.0 when
    only one core's worth is left to us (other machines' load on the same host is invisible
    from inside this virtual machine)."""
    env = {**os.environ, **{k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                              "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--probe"]

    def start():
        return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)

    alone = float(start().communicate()[0])
    both = [start(), start()]
    together = statistics.mean(float(q.communicate()[0]) for q in both)
    return {"alone": alone, "together": together, "scaling": 2 * alone / together}


# ----------------------------------------------------------------------------- main
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="20 meshes, one round (a smoke run)")
    ap.add_argument("--rounds", type=int, default=None,
                    help="rounds of (b), (a), (c); the second in reverse order (default 2, "
                         "--quick 1)")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--sample", type=int, default=10,
                    help="outputs compared with the one-mesh command (the big mesh and others)")
    ap.add_argument("--no-big", action="store_true", help="leave out the ~300k-face mesh")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    ap.add_argument("--no-malloc-run", action="store_true",
                    help="leave out run (d) (Dask without its MALLOC_TRIM_THRESHOLD_)")
    ap.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.probe:
        print(f"{probe_work():.4f}")
        return 0
    count = 20 if args.quick else args.count
    rounds = args.rounds or (1 if args.quick else 2)
    modes = ("b", "a", "c") if args.no_malloc_run else ("b", "a", "c", "d")
    c = Checks()
    tmp = Path(tempfile.mkdtemp(prefix="stylize3d-batch-bench-"))
    try:
        return _main(args, count, rounds, modes, c, tmp)
    finally:
        for p in _children:
            if p.poll() is None:
                p.kill()
        if args.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


LABELS = {"a": "(a) pool of 2", "b": "(b) in a row", "c": "(c) dask 2", "d": "(d) dask, malloc"}


def one_run(mode: str, lib: Path, out: Path, tmp: Path) -> dict:
    if mode in ("c", "d"):
        import dask
        import distributed

        env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
        if mode == "d":
            env.pop("MALLOC_TRIM_THRESHOLD_", None)
        saved = dict(os.environ)   # a Nanny puts its pre-spawn-environ into os.environ
        t0 = time.perf_counter()
        try:
            with CpuWindow() as cpu, \
                    dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
                with distributed.LocalCluster(n_workers=2, threads_per_worker=1,
                                              processes=True, host="127.0.0.1",
                                              dashboard_address=None) as cluster:
                    t_cluster = time.perf_counter() - t0
                    run = run_batch_cli([lib], out, ["--scheduler", cluster.scheduler_address],
                                        tmp / f"{out.name}.log")
        finally:
            os.environ.clear()
            os.environ.update(saved)
        run["cpu"] = cpu   # the cluster's worker processes are ours (waited for) once closed
        run["cluster_s"] = t_cluster
        return run
    return run_batch_cli([lib], out, ["--workers", "2" if mode == "a" else "1"],
                         tmp / f"{out.name}.log")


def _main(args, count: int, rounds: int, modes, c: Checks, tmp: Path) -> int:
    print(f"stylize3d batch cubic (defaults) on {count} meshes; {os.cpu_count()} cores; "
          f"seed {args.seed}; {rounds} round(s)")
    t0 = time.perf_counter()
    lib = tmp / "lib"
    good, broken, big, st = make_library(lib, count, args.seed, not args.no_big)
    order = sorted(str(p) for p in list(good) + list(broken))
    f = st["faces"]
    print(f"library: {len(good)} good + {len(broken)} broken in {time.perf_counter() - t0:.1f} s"
          f"; regular meshes {min(f):,}-{max(f):,} faces (median {int(np.median(f)):,}, "
          f"total {sum(f):,}); {dict(st['kinds'])}; {dict(st['formats'])}; "
          f"redrawn (invalid draws) {st['redrawn']}")
    if big is not None:
        print(f"  big: {big.name} ({st['big_faces']:,} faces, "
              f"{big.stat().st_size / 1e6:.0f} MB), input {order.index(str(big)) + 1} of "
              f"{count}")
    print("  broken: " + ", ".join(f"{p.name} (input {order.index(str(p)) + 1})"
                                   for p in broken))

    # one-mesh command on a sample (first: it also warms the caches)
    rng = np.random.default_rng(args.seed + 1)
    regular = [p for p in good if p != big]
    sample = ([big] if big is not None else []) + \
        [regular[i] for i in rng.choice(len(regular), min(len(regular), args.sample), False)]
    sample = sample[:max(1, args.sample)]
    refs = tmp / "refs"
    refs.mkdir()
    t0 = time.perf_counter()
    ref_sha = {}
    for p in sample:
        o = refs / p.name
        r = subprocess.run([sys.executable, "-m", "app", "cubic", str(p), "-o", str(o),
                            "--quiet"], cwd=ROOT, capture_output=True, text=True)
        if c.check(r.returncode == 0, f"one-mesh cubic failed on {p.name}: {r.stderr[-500:]}"):
            ref_sha[str(p)] = _sha(o)
    print(f"one-mesh command on {len(sample)} sample inputs: {time.perf_counter() - t0:.1f} s")

    print("runs (batch seconds = run_batch's own; throughput = meshes done / batch seconds; "
          "probe = 2-process scaling of a fixed cubic run just before, see --help):")
    figs: dict[str, list[dict]] = {m: [] for m in modes}
    shas: dict[str, dict] = {}
    for r in range(rounds):
        for mode in modes if r % 2 == 0 else modes[::-1]:
            pr = probe()
            out = tmp / f"out_{mode}{r}"
            run = one_run(mode, lib, out, tmp)
            fig = run_figures(run, out, 1 if mode == "b" else 2)
            fig["probe"] = pr
            figs[mode].append(fig)
            _print_run(f"{LABELS[mode]} #{r + 1}", fig)
            print(f"  {'':19s} probe {pr['alone']:.2f} s alone, {pr['together']:.2f} s two at "
                  f"once: scaling {pr['scaling']:.2f}" +
                  (f"; LocalCluster start-up {run['cluster_s']:.1f} s (not in its seconds)"
                   if "cluster_s" in run else ""))
            got = check_outcome(c, f"{LABELS[mode]} #{r + 1}", out, good, broken)
            c.check(fig["done"] == len(good) and fig["failed"] == len(broken)
                    and fig["code"] == 1,
                    f"{LABELS[mode]} #{r + 1}: done {fig['done']} failed {fig['failed']} exit "
                    f"{fig['code']}, expected {len(good)} / {len(broken)} / 1")
            if "a" not in shas and mode == "a":
                shas["a"] = got
                msgs = last_records(out)
            else:
                shas[f"{mode}{r}"] = got
                shutil.rmtree(out, ignore_errors=True)

    def total(mode):
        done = sum(f_["done"] or 0 for f_ in figs[mode])
        secs = sum(f_["seconds"] for f_ in figs[mode])
        return done / secs if secs > 0 else 0.0

    tp = {m: total(m) for m in figs}
    r_ab = tp["a"] / tp["b"] if tp["b"] else 0.0
    r_ca = tp["c"] / tp["a"] if tp["a"] else 0.0
    scal = statistics.mean(f_["probe"]["scaling"] for fs in figs.values() for f_ in fs)
    print("throughput over the rounds (meshes done / batch seconds, summed): " +
          ", ".join(f"{LABELS[m]} {tp[m]:.3f}/s" for m in modes))
    print(f"ratios: (a)/(b) = {r_ab:.2f}x  [target >= 1.7: "
          f"{'met' if r_ab >= 1.7 else 'MISSED'}; the probe's mean 2-process scaling "
          f"{scal:.2f}]   (c)/(a) = {r_ca:.2f}  [target >= 0.90: "
          f"{'met' if r_ca >= 0.9 else 'MISSED'}]" +
          (f"   (d)/(a) = {tp['d'] / tp['a']:.2f}" if "d" in tp and tp["a"] else ""))

    same = all(shas["a"].get(i) == other.get(i) for other in shas.values() for i in shas["a"])
    c.check(same and len(shas["a"]) == len(good),
            "outputs of (a), (b), (c) are not byte-identical to each other")
    sample_ok = [i for i in ref_sha if shas["a"].get(i) == ref_sha[i]]
    c.check(len(sample_ok) == len(sample),
            f"{len(sample) - len(sample_ok)} sample outputs differ from the one-mesh command's")
    print(f"checks: {len(shas['a'])}/{len(good)} good written by every run and "
          f"{'identical' if same else 'NOT identical'} across the {len(shas)} runs; sample "
          f"{len(sample_ok)}/{len(sample)} byte-identical to `stylize3d cubic`; broken:")
    for p, kind in broken.items():
        r = msgs.get(str(p), {})
        lines = [ln.strip() for ln in r.get("message", "").splitlines() if ln.strip()]
        text = " ".join(lines[:1] + [ln for ln in lines if ln.startswith("- ")][:1])
        c.check(WHAT[kind] in r.get("message", ""),
                f"the message for the {kind} mesh does not say {WHAT[kind]!r}")
        print(f"  {kind:12s} {r.get('status')}: {text.replace(str(p), p.name)[:170]}")

    # resume
    res = resume(c, lib, tmp / "out_resume", good, broken, count, shas["a"], tmp)
    if res is not None:
        print(f"resume: driver SIGKILLed at {res['killed_at']:.1f} s after "
              f"{res['records_first']} records ({res['done_first']} done; "
              f"{res['pending_at_kill']} pending record(s), {res['tmp_at_kill']} temporary "
              f"file(s) at the kill; its {res['workers_first']} worker processes stopped by "
              f"themselves); restart: {res['recovered']} recovered, {res['skipped']} skipped "
              f"(report: {res['skipped_records']} skipped records), {res['done2']} done, "
              f"{res['failed2']} failed in {res['seconds2']:.1f} s (exit {res['code2']}); "
              f"each input once, none done twice, no partial file: "
              f"{'yes' if not any(f_.startswith('resume') for f_ in c.failures) else 'NO'}")

    # memory: every 10th input vs all
    small = order[::10]
    out_m = tmp / "out_mem"
    run = run_batch_cli(small, out_m, ["--workers", "2"], tmp / "mem.log")
    peak_small = run["peak_mb"]
    peak_all = max(f_["peak_mb"] for f_ in figs["a"])
    delta = peak_all - peak_small
    print(f"driver peak memory (pool of 2): {len(small)} meshes {peak_small:.0f} MB, {count} "
          f"meshes {peak_all:.0f} MB: {delta:+.0f} MB [target within +-100 MB: "
          f"{'met' if abs(delta) <= 100 else 'MISSED'}]")

    if c.failures:
        print(f"{len(c.failures)} check(s) FAILED")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
