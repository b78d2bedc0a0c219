"""Starts the Qt application (imported only when the GUI is opened)."""

from __future__ import annotations

import sys

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from app.main_window import APP_NAME, MainWindow


def run_app(mesh: str | None = None, screenshot: str | None = None,
            study: dict | None = None) -> int:
    from app import crashlog

    # a segfault or abort leaves every thread's stack in a crash log, said at the next start
    crashlog.install("app")
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName(APP_NAME)
    app.setOrganizationName(APP_NAME)
    win = MainWindow()
    sys.excepthook = make_excepthook(win)
    win.show()
    if not screenshot:  # nobody would read it in a screenshot run; it waits for a real start
        crashlog.announce_last_crash(lambda text: win.report(text, "warning", 60_000),
                                     win.show_messages)
    if not screenshot:
        QTimer.singleShot(300, warm_up_in_background)
    status = {"code": 0}
    said: list[tuple[str, str]] = []
    if screenshot:  # nobody is there to answer: questions are declined, messages kept
        _unattended_dialogs(said)
    recovered = False
    if not screenshot and not study:  # work autosaved before a crash (app/autosave.py)
        from app.autosave import offer_recovery

        recovered = offer_recovery(win)
        if recovered and mesh:
            win.report(f"{mesh} was not opened: the recovered work is open instead "
                       "(File > Open opens it).")
            mesh = None
    if mesh:
        QTimer.singleShot(0, lambda: win.open_path(mesh))
    elif not screenshot and not study and not recovered:  # first start (or "Show at start")
        from app.welcome import WelcomeDialog

        if WelcomeDialog.show_at_start(win):
            QTimer.singleShot(0, win.show_welcome)
    if study:
        QTimer.singleShot(0, lambda: _start_study(win, study, status))
    if screenshot:
        def shoot():
            if mesh and win.document.is_empty:
                why = "".join(f"\n{text}" for _title, text in said[-1:])
                if said and said[-1][0] == "Mesh problems":
                    why += (f"\n\nRun `stylize3d clean {mesh} -o CLEANED.obj` first, or open it "
                            "in the app and choose 'Clean and open'.")
                print(f"stylize3d: could not open {mesh}{':' if why else ''}{why}",
                      file=sys.stderr)
                status["code"] = 2
            elif not win.save_window_image(screenshot):
                status["code"] = 3
            else:
                print(f"Saved screenshot to {screenshot}")
            win.document.modified = False
            win.close()
        QTimer.singleShot(1500, shoot)
    rc = app.exec()
    return status["code"] or rc


def warm_up_in_background() -> "threading.Thread":
    """Load the compiled kernels (Numba) and the solvers' modules on a background thread while
    the user looks at the window, so the first Run does not pay for it. Loading holds Python's
    interpreter lock in slices of up to a few hundred milliseconds: better at start-up than in
    the middle of the first slider drag."""
    import threading

    def work():
        try:
            from algorithms.deform.arap import compiled_kernels
            from algorithms.deform.cubic import CubicParams, CubicStylizer
            from algorithms.mesh.primitives import icosphere
            from algorithms.multigrid import surface_multigrid
            from algorithms.steps import run_to_end

            if compiled_kernels() is None:
                return
            V, F = icosphere(2)
            run_to_end(CubicStylizer(V, F).steps(CubicParams(max_iterations=1)))
            from algorithms.multigrid.applications import DataSmoother

            V, F = icosphere(3)
            mg = surface_multigrid(V, F, min_vertices=100)
            for energy in ("dirichlet", "bilaplacian"):
                DataSmoother(V, F, mg=mg, energy=energy).smooth(V[:, 0], 1e-3)
        except Exception:  # a warm-up never stops the app; the first run will say what is wrong
            pass
        try:  # neural subdivision's kernels (the Subdivision panel)
            import torch

            from algorithms.mesh.primitives import icosphere
            from algorithms.subdivision.model import MeshLevels, SubdivisionNet

            V, F = icosphere(1)
            net = SubdivisionNet()
            V0 = torch.from_numpy(V).to(net.dtype).requires_grad_(True)
            net.forward(V0, MeshLevels(F, len(V), 1, net.dtype))[-1].sum().backward()
        except Exception:  # noqa: BLE001 - as above
            pass
        try:  # the renderer's kernels (Paparazzi, adversarial lighting: ~10 s to compile)
            import numpy as np

            from algorithms.mesh.primitives import icosphere
            from algorithms.paparazzi.filters import guided_filter
            from algorithms.render import (environment, image_vjp, look_at, render,
                                           sh_image_vjp, sh_render)

            V, F = icosphere(2)
            cam = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=2.5, resolution=32)
            r = render(V, F, cam)
            image_vjp(V, F, r, np.ones_like(r.image))
            guided_filter(r.image, r.image, 2, 1e-8, 2)
            s = sh_render(V, F, cam, environment())
            sh_image_vjp(V, F, s, np.ones_like(s.image))
            import torch  # noqa: F401 - the classifier's first use would import it (~1 s)
        except Exception:
            pass

    t = threading.Thread(target=work, name="warm-up", daemon=True)
    t.start()
    return t


def _unattended_dialogs(said: list) -> None:
    """For `--screenshot` runs: every dialog becomes a recorded message; questions are answered
    with their last choice (Cancel), so a mesh that needs cleaning is not opened silently."""
    from app import dialogs

    def error(parent, title, text, details=None):
        said.append((title, text))

    def choose(parent, title, text, choices, default=None, details=None):
        said.append((title, text))
        return None

    dialogs.error = error
    dialogs.info = error
    dialogs.choose = choose
    dialogs.confirm = lambda parent, title, text, yes="Yes", no="Cancel": bool(
        choose(parent, title, text, [yes, no]))


def _start_study(win, study: dict, status: dict) -> None:
    """User-study mode (app/study/session.py); a protocol that cannot be run says why and quits."""
    from algorithms.errors import Stylize3DError
    from app import dialogs
    from app.study.session import start_study

    try:
        session = start_study(win, study["protocol"], log_dir=study.get("log_dir"),
                              participant=study.get("participant"),
                              condition=study.get("condition"))
    except Stylize3DError as e:
        dialogs.error(win, "Cannot start the study session", str(e))
        status["code"] = e.exit_code
        win.close()
        return
    if session is None:  # the experimenter cancelled the start dialog
        win.close()


def make_excepthook(win):
    """An exception that escapes a slot (a defect of ours) becomes a plain dialog with the
    traceback under "Show Details", instead of text on a terminal the user never sees; the app
    keeps running and the document is as the last finished command left it."""
    import traceback

    from algorithms.errors import Stylize3DError
    from app import dialogs

    def hook(etype, value, tb):
        if issubclass(etype, KeyboardInterrupt):
            sys.__excepthook__(etype, value, tb)
            return
        details = "".join(traceback.format_exception(etype, value, tb))
        print(details, file=sys.stderr)
        if isinstance(value, Stylize3DError):
            dialogs.error(win, "Stylize3D", str(value))
            return
        what = ("The computer ran out of memory" if issubclass(etype, MemoryError)
                else f"An unexpected error stopped the action ({etype.__name__}: {value})")
        try:
            dialogs.error(win, "Something went wrong",
                          f"{what}. Your mesh is as the last finished step left it; Undo "
                          "(Ctrl+Z) works as before. Please report this with the details below.",
                          details)
        except Exception:  # never raise from the hook itself
            pass

    return hook
