"""Runs the app in a fresh process for tests/app/test_autosave.py (not a test module).

``python tests/app/autosave_driver.py work OUT``
    a real MainWindow opens a copy of ``blob-painted.s3d`` (painted λ, a fixed region, a handle,
    panel settings), runs three jobs through the panels (Cubic λ 0.3, Cubic λ 0.6, Smooth),
    waits until the autosave of the last state is written, dumps that state to
    ``OUT/expected.npz`` / ``.json``, prints ``AUTOSAVED {...}`` and keeps running until it is
    killed (it exits by itself after two minutes).
``python tests/app/autosave_driver.py recover OUT``
    starts the app as ``stylize3d`` does (:func:`app.gui.run_app`), clicks Recover in the
    recovery dialog when it appears, dumps the recovered state to ``OUT/recovered.npz`` /
    ``.json`` with the undo history and the recovery folder's files, then closes the window
    normally (answering "Discard changes") and prints ``RECOVERED {...}``.

Both read ``STYLIZE3D_RECOVERY_DIR`` (the test sets it) and keep Qt's settings under ``OUT``.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _jsonable(x):
    from app.project import _jsonable as j

    return json.loads(json.dumps(j(x), allow_nan=False))


def dump(win, out: Path, name: str) -> dict:
    import numpy as np

    doc = win.document
    st = doc.state
    arrays = {"V": st.V, "F": st.F, "orig_V": doc.original.V, "orig_F": doc.original.F}
    for k, v in st.fields.items():
        arrays[f"field:{k}"] = v
    if st.selection is not None:
        arrays["selection"] = st.selection
    np.savez(out / f"{name}.npz", **arrays)
    meta = {"fields": sorted(st.fields), "handles": [[v, list(t)] for v, t in st.handles],
            "panels": _jsonable(win.panel_settings()), "modified": bool(doc.modified),
            "can_undo": win.undo_stack.canUndo(), "undo_count": win.undo_stack.count(),
            "title": win.windowTitle(),
            "mesh_path": str(doc.path) if doc.path else None,
            "project_path": str(win.project_path) if win.project_path else None,
            "recovery_files": sorted(p.name for p in win.autosave.slot.folder.iterdir()),
            "own_slot": win.autosave.slot.id, "pid": os.getpid()}
    (out / f"{name}.json").write_text(json.dumps(meta, indent=1))
    return meta


def _wait(app, done, seconds: float, what: str) -> None:
    import time

    t0 = time.monotonic()
    while not done():
        if time.monotonic() - t0 > seconds:
            raise SystemExit(f"driver: timed out waiting for {what}")
        app.processEvents()
        time.sleep(0.01)


def work(out: Path) -> None:
    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    app = QApplication(sys.argv[:1])
    QTimer.singleShot(120_000, lambda: os._exit(3))  # never outlive a failed test
    win = MainWindow(settings=QSettings(str(out / "settings.ini"), QSettings.Format.IniFormat))
    win.show()
    scene = out / "scene.s3d"
    shutil.copy(ROOT / "resources" / "samples" / "blob-painted.s3d", scene)
    assert win.open_path(scene), "could not open the project"
    for panel in win.panels.values():
        panel.live_box.setChecked(False)
    committed: list[str] = []
    failed: list[str] = []
    win.job_committed.connect(lambda name, _after: committed.append(name))
    win.runner.failed.connect(lambda msg, _d: failed.append(msg))

    def run(panel, **values) -> None:
        for k, v in values.items():
            panel.form.set_value(k, v)
        n = len(committed)
        panel.raise_()
        panel.run_button.click()
        _wait(app, lambda: len(committed) > n or failed, 90, f"{panel.title}'s job")
        assert not failed, failed

    cubic, smooth = win.panels["Cubic"], win.panels["Smooth"]
    run(cubic, lam=0.3, max_iterations=15)
    run(cubic, lam=0.6)
    run(smooth, iterations=2)
    assert committed == ["Cubic", "Cubic", "Smooth"], committed
    auto = win.autosave
    writes = auto.writes
    # the debounced autosave of the last change (and nothing pending after it)
    _wait(app, lambda: auto.writes > writes and auto.idle, 30, "the autosave")
    meta = dump(win, out, "expected")
    meta["write_seconds"] = auto.last_write_seconds
    meta["snapshot_seconds"] = auto.last_snapshot_seconds
    print("AUTOSAVED " + json.dumps(meta), flush=True)
    app.exec()  # until killed


def recover(out: Path) -> None:
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    import app.autosave as autosave
    from app import dialogs

    app = QApplication(sys.argv[:1])
    QTimer.singleShot(120_000, lambda: os._exit(3))
    said: list = []
    dialogs.error = lambda parent, title, text, details=None: said.append(["error", title, text])
    dialogs.info = lambda parent, title, text: said.append(["info", title, text])
    dialogs.confirm = lambda parent, title, text, yes="Yes", no="Cancel": (
        said.append(["confirm", title, text, yes]) or True)
    result: dict = {"dialogs": [], "said": said}

    def click_recover() -> None:  # as a user would: the dialog on screen, its Recover button
        w = app.activeModalWidget()
        if isinstance(w, autosave.RecoveryDialog) and not result["dialogs"]:
            result["dialogs"].append(w.text.text())
            w.recover_button.click()

    poll = QTimer()
    poll.setInterval(50)
    poll.timeout.connect(click_recover)
    poll.start()
    real_offer = autosave.offer_recovery

    def offer(win, *args, **kwargs):  # run_app's own call, watched: dump once it returned
        result["offered"] = real_offer(win, *args, **kwargs)

        def finish():
            result.update(dump(win, out, "recovered"))
            win.close()  # a normal close: asks to discard the unsaved work (yes)
            result["closed"] = not win.isVisible()
            result["after_close"] = sorted(p.name for p in win.autosave.slot.folder.iterdir())
            QTimer.singleShot(0, app.quit)
        QTimer.singleShot(0, finish)
        return result["offered"]

    autosave.offer_recovery = offer
    from app.gui import run_app

    rc = run_app(None)
    result["rc"] = rc
    print("RECOVERED " + json.dumps(result), flush=True)
    sys.stdout.flush()
    os._exit(0)  # without waiting for the start-up warm-up thread


if __name__ == "__main__":
    mode, folder = sys.argv[1], Path(sys.argv[2])
    {"work": work, "recover": recover}[mode](folder)
