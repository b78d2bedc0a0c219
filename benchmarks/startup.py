"""Start-up of ``stylize3d info`` on a small mesh, whole process (issue 25: <= 0.5 s).

Runs each command --repeat times in fresh processes, alternating them (round-robin) so that a
change of machine load hits every one alike, and prints the medians, the `uptime` load, and
ratios against the peers measured in the same run:
  python        ``python -c pass``: the interpreter alone
  numpy         ``python -c "import numpy"``
  numpy+sparse  ``python -c "import numpy, scipy.sparse"`` (what algorithms.mesh needs today)
  info          ``python -m app info tests/data/spot_lowres.obj`` (829 vertices)
  info (all)    the same, but with every CLI module imported first, as before issue 25

Usage: .venv/bin/python benchmarks/startup.py [--repeat 15] [--mesh spot_lowres.obj]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--mesh", default="spot_lowres.obj")
    args = ap.parse_args()
    mesh = str(ROOT / "tests" / "data" / args.mesh)
    py = sys.executable
    all_first = ("import sys; from app import cli; cli.MODULES; "
                 "sys.exit(cli.main(sys.argv[1:]))")
    cmds = {
        "python": [py, "-c", "pass"],
        "numpy": [py, "-c", "import numpy"],
        "numpy+sparse": [py, "-c", "import numpy, scipy.sparse"],
        "info": [py, "-m", "app", "info", mesh],
        "info (all)": [py, "-c", all_first, "info", mesh],
    }
    times: dict[str, list[float]] = {k: [] for k in cmds}
    load0 = os.getloadavg()
    for _ in range(args.repeat):
        for name, cmd in cmds.items():
            t = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           check=name.startswith("info") is False)
            times[name].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"stylize3d info {args.mesh}, whole process, median of {args.repeat} "
          f"(load before {load0[0]:.2f}, after {os.getloadavg()[0]:.2f})")
    for name, s in med.items():
        print(f"  {name:>13}: {s:6.3f} s  ({s / med['numpy+sparse']:.2f} x numpy+sparse, "
              f"{s / med['python']:.1f} x python)")
    print(f"  info / info (all): {med['info'] / med['info (all)']:.2f}; "
          f"info - numpy+sparse: {med['info'] - med['numpy+sparse']:.3f} s; target info <= 0.5 s")


if __name__ == "__main__":
    main()
