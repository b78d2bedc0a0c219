"""Crash stress: hundreds of fresh processes over every method's command and the recipes.

Issue 35: "never crash". Each case is a new process (``python -m app <command> ...`` or a
recipe called from ``python -c``) on a bundled sample, a small real mesh of ``tests/data/``,
a noisy copy of one, or (``--shared``) a mesh of ``$STYLIZE3D_MESHES``; with a random thread
count (``NUMBA_NUM_THREADS`` 1 or 2, ``OMP_NUM_THREADS`` following it or not); several at the
same time. The run goes through phases, each with its own Numba cache: the first processes of a
phase start together on an **empty** cache (the first compiles race, as on a fresh install or
when several batch workers start), the rest use the cache they left (warm).

Every outcome is classified:

* ``ok`` -- exit 0;
* ``refused`` -- exit 2-6 with a plain message (bad input / parameter / did not converge: the
  documented refusals, never a crash), or 1 from a batch in which a mesh failed so;
* ``crash`` -- killed by a signal, or exit 70 with "crashed (": a segmentation fault or abort;
* ``traceback`` -- exit 70 otherwise, or a Python traceback on stderr;
* ``hang`` -- still running after ``--timeout`` seconds.

Target: 0 crashes, 0 tracebacks, 0 hangs. The failures are printed with their command, thread
count, cache state and the end of stderr; ``--json FILE`` keeps every record.

    .venv/bin/python benchmarks/crash_stress.py                 # 300 processes, 3 phases
    .venv/bin/python benchmarks/crash_stress.py -n 60 --phases 2 --concurrency 3
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "resources" / "samples"
TEST_DATA = ROOT / "tests" / "data"

#: (name, arguments after ``python -m app``); {in} the input, {out} an output path stem
COMMANDS: list[tuple[str, list[str]]] = [
    ("info", ["info", "{in}", "--json"]),
    ("clean", ["clean", "{in}", "-o", "{out}.obj"]),
    ("smooth", ["smooth", "{in}", "-o", "{out}.obj", "--iterations", "3"]),
    ("smooth-multigrid", ["smooth", "{in}", "-o", "{out}.npy", "--signal", "noise",
                          "--solver", "multigrid"]),
    ("multigrid-info", ["multigrid-info", "{in}", "--json"]),
    ("cubic", ["cubic", "{in}", "-o", "{out}.obj", "--max-iters", "6"]),
    ("analogy", ["analogy", "{in}", "-o", "{out}.obj", "--style", "octahedron",
                 "--max-iters", "6"]),
    ("coarsen", ["coarsen", "{in}", "--m", "200", "--k", "20", "--max-iterations", "5",
                 "--balance-iterations", "5", "-o", "{out}.npz"]),
    ("subdivide-loop", ["subdivide", "{in}", "-o", "{out}.obj", "--levels", "1",
                        "--method", "loop"]),
    ("subdivide-neural", ["subdivide", "{in}", "-o", "{out}.obj", "--levels", "1",
                          "--coarsen-first", "400"]),
    ("paparazzi-guided", ["paparazzi", "{in}", "-o", "{out}.obj", "--filter", "guided",
                          "--iterations", "12"]),
    ("paparazzi-quantize", ["paparazzi", "{in}", "-o", "{out}.obj", "--filter", "quantize",
                            "--iterations", "12"]),
    ("adversary-lighting", ["adversary", "{in}", "--mode", "lighting", "--iterations", "2",
                            "--views", "1"]),
    ("batch-paparazzi", ["batch", "paparazzi", "{in}", "-o", "{out}-batch", "--workers", "2",
                         "--filter", "quantize", "--iterations", "12"]),
]

#: recipes called from Python, as scripts do (app.recipes.run), on the painted sample project
RECIPES = [
    ("recipe-cubic", "cubic", {"max_iterations": 6}),
    ("recipe-paparazzi", "paparazzi", {"iterations": 12}),
    ("recipe-subdivision", "subdivide", {"levels": 1}),
]
RECIPE_CODE = """
import sys, json
from app.recipes import load, run
r = run(sys.argv[1], load(sys.argv[2]), json.loads(sys.argv[3]))
print(type(r).__name__)
"""


def _inputs(tmp: Path, shared: bool) -> list[Path]:
    """Samples, the small real meshes of tests/data, noisy copies of three of them and (with
    ``shared``) the meshes of $STYLIZE3D_MESHES or ../shared/meshes up to 200k faces."""
    import numpy as np

    from algorithms.mesh.io import read_mesh, write_mesh

    paths = sorted(SAMPLES.glob("*.obj")) + sorted(
        p for p in TEST_DATA.iterdir() if p.suffix in (".obj", ".off"))
    rng = np.random.default_rng(7)
    for name in ("spot_lowres.obj", "fandisk.off", "bob.obj"):
        m = read_mesh(TEST_DATA / name)
        V = np.asarray(m.V, dtype=float)
        edge = np.linalg.norm(V[m.F[:, 0]] - V[m.F[:, 1]], axis=1).mean()
        noisy = tmp / f"noisy-{Path(name).stem}.obj"
        write_mesh(noisy, V + rng.normal(scale=0.3 * edge, size=V.shape), m.F)
        paths.append(noisy)
    if shared:
        folder = Path(os.environ.get("STYLIZE3D_MESHES", ROOT.parent / "shared" / "meshes"))
        for p in sorted(folder.glob("*")):
            if p.suffix.lower() in (".obj", ".off", ".ply", ".stl") and p.stat().st_size < 15e6:
                paths.append(p)
    return paths


def _case(rng: random.Random, inputs: list[Path], out_dir: Path, i: int):
    """One random case: (name, argv)."""
    if RECIPES and (not COMMANDS or rng.random() < 0.12):
        name, title, params = rng.choice(RECIPES)
        project = SAMPLES / "blob-painted.s3d"
        return name, "blob-painted.s3d", [sys.executable, "-c", RECIPE_CODE, title,
                                          str(project), json.dumps(params)]
    name, args = rng.choice(COMMANDS)
    mesh = rng.choice(inputs)
    if name == "adversary-lighting":  # the classifier's object, or another sample
        mesh = rng.choice([SAMPLES / "orange.obj", SAMPLES / "blob.obj"])
    argv = [a.replace("{in}", str(mesh)).replace("{out}", str(out_dir / f"case{i:04d}"))
            for a in args]
    return name, mesh.name, [sys.executable, "-m", "app", *argv]


def _classify(rc: int | None, err: str) -> str:
    if rc is None:
        return "hang"
    if rc < 0 or rc >= 128 or (rc == 70 and "crashed (" in err):
        return "crash"
    if rc == 70 or "Traceback (most recent call last)" in err:
        return "traceback"
    if rc == 0:
        return "ok"
    if 1 <= rc <= 6:  # 1: a batch in which some mesh failed with a plain reason
        return "refused"
    return "traceback"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", "--processes", type=int, default=300)
    ap.add_argument("--phases", type=int, default=3,
                    help="number of Numba caches, each starting empty (default 3)")
    ap.add_argument("--concurrency", type=int, default=3,
                    help="processes at once (the first of each phase all start together)")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shared", action="store_true", help="also the meshes of ../shared/meshes")
    ap.add_argument("--json", metavar="FILE", help="write every record here")
    ap.add_argument("--only", metavar="NAMES",
                    help="comma-separated case names (e.g. smooth-multigrid,recipe-cubic)")
    args = ap.parse_args(argv)
    if args.only:
        names = set(args.only.split(","))
        unknown = names - {c[0] for c in COMMANDS} - {r[0] for r in RECIPES}
        if unknown:
            ap.error(f"unknown case(s): {', '.join(sorted(unknown))}")
        COMMANDS[:] = [c for c in COMMANDS if c[0] in names]
        RECIPES[:] = [r for r in RECIPES if r[0] in names]
    rng = random.Random(args.seed)
    tmp = Path(tempfile.mkdtemp(prefix="crash-stress-"))
    crash_dir = tmp / "crash-logs"
    inputs = _inputs(tmp, args.shared)
    print(f"crash stress: {args.processes} processes, {args.phases} phase(s) with an empty "
          f"Numba cache each, {args.concurrency} at once; {len(inputs)} meshes, "
          f"{len(COMMANDS)} commands + {len(RECIPES)} recipes; {platform.node()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}")
    per_phase = [args.processes // args.phases + (p < args.processes % args.phases)
                 for p in range(args.phases)]
    records = []
    t_start = time.time()
    i = 0
    for phase, count in enumerate(per_phase):
        cache = tmp / f"numba-cache-{phase}"
        running: list[tuple[subprocess.Popen, dict, float]] = []
        started = 0
        while started < count or running:
            # the first `concurrency` of a phase start at once, on the empty cache
            while started < count and len(running) < args.concurrency:
                name, mesh, cmd = _case(rng, inputs, tmp, i)
                threads = rng.choice([1, 2])
                env = {k: v for k, v in os.environ.items()
                       if k not in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")}
                env.update(NUMBA_CACHE_DIR=str(cache), NUMBA_NUM_THREADS=str(threads),
                           STYLIZE3D_CRASH_DIR=str(crash_dir), PYTHONFAULTHANDLER="1")
                if rng.random() < 0.5:
                    env["OMP_NUM_THREADS"] = str(threads)
                rec = {"i": i, "phase": phase, "case": name, "mesh": mesh,
                       "threads": threads, "omp": env.get("OMP_NUM_THREADS"),
                       "cache": "empty" if started < args.concurrency else "warm",
                       "cmd": cmd}
                err_file = open(tmp / f"case{i:04d}.err", "w+")
                p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                     stderr=err_file, stdin=subprocess.DEVNULL)
                rec["_err"] = err_file
                running.append((p, rec, time.time()))
                started += 1
                i += 1
            time.sleep(0.2)
            still = []
            for p, rec, t0 in running:
                rc = p.poll()
                if rc is None and time.time() - t0 < args.timeout:
                    still.append((p, rec, t0))
                    continue
                if rc is None:
                    p.kill()
                    p.wait()
                f = rec.pop("_err")
                f.seek(0)
                err = f.read()
                f.close()
                rec.update(rc=rc, seconds=round(time.time() - t0, 2),
                           outcome=_classify(rc, err), stderr_tail=err[-1500:])
                records.append(rec)
                if rec["outcome"] in ("crash", "traceback", "hang"):
                    print(f"!! {rec['outcome']}: case {rec['i']} {rec['case']} on "
                          f"{rec['mesh']} ({rec['threads']} thread(s), {rec['cache']} cache, "
                          f"exit {rc}):\n{err[-1500:]}", flush=True)
            running = still
        done = [r for r in records if r["phase"] == phase]
        print(f"phase {phase + 1}/{args.phases}: {len(done)} processes, "
              f"{sum(r['outcome'] == 'ok' for r in done)} ok, "
              f"{sum(r['outcome'] == 'refused' for r in done)} refused, "
              f"{sum(r['outcome'] in ('crash', 'traceback', 'hang') for r in done)} failed "
              f"({time.time() - t_start:.0f} s so far)", flush=True)
    outcomes = {}
    for r in records:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    print("\nper case (ok / refused / failed):")
    for name in sorted({r["case"] for r in records}):
        rs = [r for r in records if r["case"] == name]
        print(f"  {name:20s} {sum(r['outcome'] == 'ok' for r in rs):4d} "
              f"{sum(r['outcome'] == 'refused' for r in rs):4d} "
              f"{sum(r['outcome'] not in ('ok', 'refused') for r in rs):4d}")
    cold = [r for r in records if r["cache"] == "empty"]
    print(f"\ntotal: {len(records)} processes in {time.time() - t_start:.0f} s; "
          f"{len(cold)} started together on an empty cache; threads 1: "
          f"{sum(r['threads'] == 1 for r in records)}, 2: "
          f"{sum(r['threads'] == 2 for r in records)}")
    print("outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    refusals = sorted({r["stderr_tail"].strip().splitlines()[-1][:160]
                       for r in records if r["outcome"] == "refused"
                       and r["stderr_tail"].strip()})
    if refusals:
        print("refusal messages seen:")
        for line in refusals:
            print("  " + line)
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))
    bad = sum(outcomes.get(k, 0) for k in ("crash", "traceback", "hang"))
    print("crash logs:", sorted(os.listdir(crash_dir)) if crash_dir.exists() else "none")
    if not bad:
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        print(f"kept for inspection: {tmp}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
