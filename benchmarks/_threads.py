"""The "threads" section shared by the kernel benchmarks (issue 25): 1 vs 2 Numba threads.

:func:`threads_section` runs the calling benchmark again as a child process with
``--threads-child NAME`` in the environment ``NUMBA_NUM_THREADS=1`` and ``=2``, alternating
(1, 2, 1, 2, ...) for ``rounds`` rounds so that a change of the machine's load hits both alike.
The child times its kernels (median of its own repeats) and prints one JSON line
``{"kernel": ms, ...}``; the parent prints, per kernel, the median over the rounds of each
thread count and the ratio 2 threads / 1 thread (< 1: faster on two), with the load average
before and after. ``extra_env`` is added to the children's environment (e.g. ``OMP_WAIT_POLICY``
to compare wait policies).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def child_report(times_ms: dict[str, float]) -> None:
    """In the child: print the kernels' times (ms) as the line the parent reads."""
    print("THREADS-JSON " + json.dumps(times_ms), flush=True)


def run_child(script: str, name: str, threads: int, args: list[str],
              extra_env: dict[str, str] | None = None, timeout: float = 900) -> dict[str, float]:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    env.update(extra_env or {})
    out = subprocess.run([sys.executable, script, "--threads-child", name, *args], env=env,
                         capture_output=True, text=True, timeout=timeout)
    for line in out.stdout.splitlines():
        if line.startswith("THREADS-JSON "):
            return json.loads(line[len("THREADS-JSON "):])
    raise RuntimeError(f"{script} --threads-child {name} with {threads} thread(s) printed no "
                       f"times:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")


def threads_section(script: str, name: str, args: list[str] | None = None, rounds: int = 3,
                    extra_env: dict[str, str] | None = None, title: str = "") -> dict:
    """Run, compare and print; returns ``{kernel: (ms 1 thread, ms 2 threads, ratio)}``."""
    from algorithms.compiled import threading_layer

    args = list(args or [])
    before = load_average()
    runs: dict[int, list[dict[str, float]]] = {1: [], 2: []}
    for _ in range(max(1, rounds)):
        for t in (1, 2):
            runs[t].append(run_child(script, name, t, args, extra_env))
    after = load_average()
    kernels = list(runs[1][0])
    print(f"threads{(' — ' + title) if title else ''}: NUMBA_NUM_THREADS=1 vs 2 in child "
          f"processes, {rounds} alternating rounds (medians), layer {threading_layer()}, "
          f"{os.cpu_count()} CPUs, load average {before} -> {after}"
          + (f", env {extra_env}" if extra_env else ""))
    print(f"  {'kernel':<34}{'1 thread ms':>12}{'2 threads ms':>14}{'2/1':>7}")
    result = {}
    for k in kernels:
        a = statistics.median(r[k] for r in runs[1])
        b = statistics.median(r[k] for r in runs[2])
        result[k] = (a, b, b / a if a > 0 else float("nan"))
        print(f"  {k:<34}{a:>12.3f}{b:>14.3f}{b / a if a > 0 else float('nan'):>7.2f}")
    return result
