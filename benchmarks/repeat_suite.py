"""The whole test suite several times in a row, each in a clean clone, then every method's
command on the samples from the cache the suite left (issue 35).

Each round: ``git clone`` of this repository's committed ``HEAD`` into a new folder, the
README's test command there (``bash scripts/setup.sh test``: a new ``.venv``, the install, the
kernel warm-up, pytest), then each command of :data:`benchmarks.crash_stress.COMMANDS` on the
bundled samples with that clone's environment and Numba cache (written by the suite's many
processes: the state in which Paparazzi used to crash). Prints, per round, the suite's summary
line and time and the commands' outcomes; exits non-zero when anything failed.

    .venv/bin/python benchmarks/repeat_suite.py --rounds 5 [--rev COMMIT]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.crash_stress import COMMANDS, _classify  # noqa: E402


def _suite(clone: Path, log: Path) -> tuple[int, str, float]:
    t0 = time.time()
    with open(log, "w") as f:
        rc = subprocess.call(["bash", "scripts/setup.sh", "test"], cwd=clone, stdout=f,
                             stderr=subprocess.STDOUT)
    text = log.read_text(errors="replace")
    summary = [ln for ln in text.splitlines()
               if re.search(r"\d+ (passed|failed|error)", ln) and " in " in ln]
    return rc, summary[-1].strip("= ") if summary else "(no pytest summary)", time.time() - t0


def _commands(clone: Path, out: Path) -> list[tuple[str, str, int | None]]:
    python = clone / ".venv" / "bin" / "python"
    samples = clone / "resources" / "samples"
    results = []
    for i, (name, args) in enumerate(COMMANDS):
        mesh = samples / ("orange.obj" if name.startswith("adversary") else
                          "blob.obj")
        argv = [a.replace("{in}", str(mesh)).replace("{out}", str(out / f"{i:02d}-{name}"))
                for a in args]
        try:
            p = subprocess.run([str(python), "-m", "app", *argv], cwd=clone, timeout=600,
                               capture_output=True, text=True)
            rc, err = p.returncode, p.stderr
        except subprocess.TimeoutExpired:
            rc, err = None, "timed out"
        results.append((name, _classify(rc, err), rc))
        if results[-1][1] != "ok":
            print(f"   !! {name}: exit {rc}\n{err[-1500:]}", flush=True)
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--keep", action="store_true", help="keep the clones")
    ap.add_argument("--rev", default="HEAD",
                    help="the commit every round checks out (default: HEAD when started), so "
                         "that commits made while it runs do not change the tree under test")
    args = ap.parse_args(argv)
    head = subprocess.check_output(["git", "rev-parse", "--short", args.rev], cwd=ROOT,
                                   text=True).strip()
    print(f"{args.rounds} rounds of: git clone ({head}) + bash scripts/setup.sh test + every "
          f"command on the samples", flush=True)
    bad = 0
    base = Path(tempfile.mkdtemp(prefix="repeat-suite-"))
    for r in range(1, args.rounds + 1):
        clone = base / f"round{r}"
        subprocess.check_call(["git", "clone", "-q", str(ROOT), str(clone)])
        subprocess.check_call(["git", "checkout", "-q", "--detach", head], cwd=clone)
        rc, summary, seconds = _suite(clone, base / f"round{r}.log")
        out = base / f"round{r}-out"
        out.mkdir()
        cmds = _commands(clone, out)
        ok = sum(o == "ok" for _, o, _ in cmds)
        refused = [n for n, o, _ in cmds if o == "refused"]  # a documented refusal (exit 2-6)
        failed = len(cmds) - ok - len(refused)
        print(f"round {r}: suite exit {rc} in {seconds / 60:.1f} min: {summary}; commands "
              f"afterwards: {ok}/{len(cmds)} ok, refused {refused or 'none'}, {failed} failed",
              flush=True)
        bad += (rc != 0) + failed
        if not args.keep and rc == 0 and not failed:
            subprocess.call(["rm", "-rf", str(clone)])
    print(f"logs: {base}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
