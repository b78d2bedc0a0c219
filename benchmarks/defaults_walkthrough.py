"""Every panel's defaults as a first-time user meets them (issues 24 items 1, 4, 11).

For each mesh (the bundled samples and armadillo) and each panel: open the mesh in the real
window, bring the panel to the front, click its Run button with the defaults, wait until the job
ends. Printed per case: seconds from the click to the end, what changed (vertices moved, in % of
the bounding-box diagonal, or the new vertex count), the longest stall of the window's event loop
after the run's first second (a 10 ms timer's largest gap: what a user feels as a frozen
window), the number of redraws, and the panel's closing status line. A screenshot of the window
after each run goes to --out (look at them). Needs an X display (xvfb-run on a server)::

    xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python benchmarks/defaults_walkthrough.py \\
        [--meshes blob bumpy pretzel orange armadillo] [--panels Cubic Smooth ...] \\
        [--size 1280x800] [--out /tmp/walkthrough] [--profile] [--stacks]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MESHES = {"blob": ROOT / "resources/samples/blob.obj",
          "bumpy": ROOT / "resources/samples/bumpy.obj",
          "pretzel": ROOT / "resources/samples/pretzel.obj",
          "orange": ROOT / "resources/samples/orange.obj",
          "armadillo": ROOT / "tests/data/armadillo.obj"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=list(MESHES))
    ap.add_argument("--panels", nargs="+", default=None, help="panel titles (default: all)")
    ap.add_argument("--size", default="1280x800")
    ap.add_argument("--out", type=Path, default=Path("/tmp/walkthrough"))
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--profile", action="store_true",
                    help="profile the GUI thread during each run (top functions by own time)")
    ap.add_argument("--stacks", action="store_true",
                    help="for each stall over 100 ms after the first second, print where the "
                         "other threads were when it ended (a call that kept Python's lock)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    from PySide6.QtCore import QEventLoop, QTimer
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    def wait(ms: int) -> None:
        """Run the event loop for ``ms`` as the app's own loop does. Not QTest.qWait: it keeps
        Python's lock while it waits, so the job's worker thread only runs between two waits
        (a Paparazzi run took 4.6x as long under qWait as under an event loop)."""
        loop = QEventLoop()
        QTimer.singleShot(ms, loop.quit)
        loop.exec()

    app = QApplication.instance() or QApplication(sys.argv)
    from app import dialogs
    from app.gui import warm_up_in_background
    from app.main_window import MainWindow

    dialogs.confirm = lambda *a, **k: True            # "discard changes?" between cases
    dialogs.choose = lambda parent, title, text, choices, *a, **k: choices[0]
    errors = []
    dialogs.error = lambda parent, title, text, *a, **k: errors.append(f"{title}: {text}")
    warm_up_in_background().join()
    w, h = (int(x) for x in args.size.split("x"))
    win = MainWindow()
    win.resize(w, h)
    win.show()
    QTest.qWaitForWindowExposed(win)
    panels = args.panels or list(win.panels)
    print(f"window {w}x{h}; load average {os.getloadavg()[0]:.1f}")
    print(f"{'mesh':10s} {'panel':22s} {'s':>6s} {'change':>16s} {'stall ms':>8s} "
          f"{'redraws':>7s}  status")
    for mesh_name in args.meshes:
        for title in panels:
            win.document.modified = False
            win.undo_stack.setClean()
            if not win.open_path(MESHES[mesh_name]):
                print(f"{mesh_name:10s} {title:22s} could not open")
                continue
            panel = win.panels[title]
            panel.live_box.setChecked(False)
            panel.raise_()
            t_wait = time.monotonic()
            while not panel.run_button.isEnabled() and time.monotonic() - t_wait < 120:
                wait(100)  # e.g. the classifier loading
            wait(300)
            V0 = np.array(win.document.V)
            gaps, last = [], [0.0]
            timer = QTimer()
            timer.setInterval(10)

            def tick():
                now = time.perf_counter()
                gaps.append((now, now - last[0]))
                last[0] = now

            timer.timeout.connect(tick)
            stall_stacks = []
            if args.stacks:
                import threading
                import traceback

                gui_id = threading.get_ident()

                def watch(stop):
                    # a pure-Python thread: it only runs with Python's lock, so an overslept
                    # 5 ms sleep is a stretch in which some thread kept the lock
                    last = time.perf_counter()
                    while not stop.is_set():
                        time.sleep(0.005)
                        now = time.perf_counter()
                        if now - last > 0.1 and now - t0 > 1.0:
                            here = []
                            for tid, fr in sys._current_frames().items():
                                if tid in (gui_id, threading.get_ident()):
                                    continue
                                st = traceback.extract_stack(fr)[-3:]
                                here.append(" <- ".join(f"{x.filename.split('/')[-1]}:{x.lineno} "
                                                        f"{x.name}" for x in reversed(st)))
                            stall_stacks.append((now - last, here))
                        last = now

                stop_watch = threading.Event()
                watcher = threading.Thread(target=watch, args=(stop_watch,), daemon=True)
            redraws0 = win.viewport.redraws
            errors.clear()
            t0 = last[0] = time.perf_counter()
            prof = None
            if args.profile:
                import cProfile

                prof = cProfile.Profile()
                prof.enable()
            if args.stacks:
                watcher.start()
            timer.start()
            panel.run_button.click()
            wait(50)
            while win.runner.busy and time.perf_counter() - t0 < args.timeout:
                wait(20)
            seconds = time.perf_counter() - t0
            timer.stop()
            if args.stacks:
                stop_watch.set()
                watcher.join()
                for gap, here in sorted(stall_stacks, key=lambda x: -x[0])[:5]:
                    print(f"  lock held {gap * 1000:.0f} ms; threads then at: " + " | ".join(here))
            if prof is not None:
                import pstats

                prof.disable()
                pstats.Stats(prof).sort_stats("tottime").print_stats(12)
            wait(300)
            late = [(g, t - t0) for t, g in gaps if t - t0 > 1.0]
            stall = max([g for g, _ in late] or [0.0]) * 1000
            if args.stacks and late:
                print("  longest stalls (ms at s): " + ", ".join(
                    f"{g * 1000:.0f} at {t:.1f}" for g, t in sorted(late, reverse=True)[:4]))
            V1 = np.asarray(win.document.V)
            diag = float(np.linalg.norm(np.ptp(V0, axis=0)))
            if V1.shape == V0.shape:
                change = f"moved {100 * np.linalg.norm(V1 - V0, axis=1).max() / diag:.2f} %"
            else:
                change = f"{len(V0):,} -> {len(V1):,} v"
            status = panel.status_label.text().replace("\n", " ")
            if errors:
                status = "ERROR " + " | ".join(errors)
            print(f"{mesh_name:10s} {title:22s} {seconds:6.1f} {change:>16s} {stall:8.0f} "
                  f"{win.viewport.redraws - redraws0:7d}  {status[:150]}", flush=True)
            win.viewport.render_now()
            win.grab().save(str(args.out / f"{mesh_name}_{title.split()[0].lower()}.png"))
    print(f"load average {os.getloadavg()[0]:.1f}; screenshots in {args.out}")
    win.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
