"""A whole study session on the real meshes of tests/data, replayed: every panel and painting
tool (tests/app/study/test_replay_everything.py with STYLIZE3D_REPLAY_BIG=1: armadillo, bob,
fandisk, spot, camelhead), killed once mid-task and resumed. Prints the session's time (the
driven app, including the killed part), the replay's time and their ratio, and what the replay
checked (every run, edit, undo/redo and task end must "match").

    .venv/bin/python benchmarks/study_replay.py      # needs Xvfb (pytest-xvfb starts it)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    env = {**os.environ, "STYLIZE3D_REPLAY_BIG": "1", "QT_QPA_PLATFORM": "xcb",
           "PYVISTA_OFF_SCREEN": "false"}
    env.pop("DISPLAY", None)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider",
                        "tests/app/study/test_replay_everything.py"], cwd=ROOT, env=env,
                       capture_output=True, text=True)
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("BENCH ")), None)
    if r.returncode != 0 or line is None:
        print(r.stdout[-4000:], r.stderr[-4000:])
        print("the session or its replay failed")
        return 1
    fig = json.loads(line[len("BENCH "):])
    print("meshes:", ", ".join(Path(m).name for m in fig["tasks"]))
    print(f"session (driven app, incl. the killed start): {fig['session_s']:.1f} s")
    print(f"replay of {fig['checks']} runs/edits/undos/tasks: {fig['replay_s']:.1f} s "
          f"(replay / session = {fig['replay_s'] / fig['session_s']:.2f})")
    for kind, counts in sorted(fig["counts"].items()):
        print(f"  {kind:6s} {counts}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
