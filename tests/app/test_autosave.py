"""Autosave and recovery (app/autosave.py, issue 35 "never lose work").

The end-to-end case runs the app in fresh processes: three jobs, the autosave, ``kill -9``,
then a new start whose recovery dialog is answered with Recover gives the last state back bit
for bit, with nothing to undo. The other tests drive the parts in this process: debounce, the
periodic save, atomic writes, one slot per window, clean-up on a normal close, which slots are
offered, Discard / Decide Later, recovery of a mesh file's work and study sessions.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from app import autosave
from app.autosave import RecoverySlot, list_slots, orphaned_slots
from tests.conftest import ROOT, SAMPLES

DRIVER = Path(__file__).with_name("autosave_driver.py")


def _dead_pid() -> int:
    """The pid of a process that has ended (and was reaped)."""
    p = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                       capture_output=True, text=True, check=True)
    return int(p.stdout)


def _edit(window, k: int) -> None:
    """One undoable edit, as a brush stroke makes it: a painted field changes."""
    from app.commands import StateCommand

    before = window.document.state
    values = np.full(len(before.V), 0.1 * (k + 1))
    window.undo_stack.push(StateCommand(window.document, before,
                                        before.with_field("lambda_scale", values),
                                        f"Paint {k}"))


def _slot_state(path):
    from app.project import read_project

    return read_project(path).state


def _same_state(a, b) -> None:
    for x, y in ((a.V, b.V), (a.F, b.F)):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert sorted(a.fields) == sorted(b.fields)
    for k in a.fields:
        assert a.fields[k].dtype == b.fields[k].dtype
        assert np.array_equal(a.fields[k], b.fields[k]), k
    assert a.handles == b.handles


def _open_blob(window):
    assert window.open_path(SAMPLES / "blob.obj")
    for panel in window.panels.values():
        panel.live_box.setChecked(False)


# ------------------------------------------------------------------------------ end to end
def _read_marker(proc, marker: str, timeout: float) -> dict:
    lines: list[str] = []

    def read():
        for line in proc.stdout:
            lines.append(line)
            if line.startswith(marker):
                return

    t = threading.Thread(target=read, daemon=True)
    t.start()
    t.join(timeout)
    for line in lines:
        if line.startswith(marker):
            return json.loads(line[len(marker):])
    proc.kill()
    err = proc.stderr.read() if proc.stderr else ""
    raise AssertionError(f"no {marker.strip()} line within {timeout} s:\n{''.join(lines)}\n"
                         f"{err[-3000:]}")


def test_kill_9_then_recover_gives_the_last_state_bit_for_bit(tmp_path, needs_display):
    out, rec, home = tmp_path / "out", tmp_path / "recovery", tmp_path / "home"
    for d in (out, home):
        d.mkdir()
    env = {**os.environ, "STYLIZE3D_RECOVERY_DIR": str(rec), "HOME": str(home),
           "XDG_CONFIG_HOME": str(home / ".config"), "QT_QPA_PLATFORM": "xcb",
           "PYVISTA_OFF_SCREEN": "false"}
    a = subprocess.Popen([sys.executable, str(DRIVER), "work", str(out)], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        saved = _read_marker(a, "AUTOSAVED ", 150)
        slots = list_slots(rec)
        assert [s.pid for s in slots] == [a.pid]
        assert orphaned_slots(rec) == []  # its process runs: not offered to anyone
    finally:
        a.kill()  # SIGKILL: no clean-up of any kind
        a.wait(30)
        a.stdout.close()
        a.stderr.close()
    assert a.returncode == -9
    assert [s.slot for s in orphaned_slots(rec)] == [saved["own_slot"]]
    assert saved["undo_count"] == 3 and saved["modified"]

    b = subprocess.run([sys.executable, str(DRIVER), "recover", str(out)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=150)
    assert b.returncode == 0, b.stderr[-3000:]
    line = [x for x in b.stdout.splitlines() if x.startswith("RECOVERED ")]
    assert line, b.stdout + b.stderr[-3000:]
    got = json.loads(line[0][len("RECOVERED "):])
    # the dialog said what and from when, and Recover was clicked on it
    assert got["offered"] is True and len(got["dialogs"]) == 1
    text = got["dialogs"][0]
    assert "scene.s3d" in text and "3,232 vertices" in text and "Smooth" in text
    assert "Autosaved:" in text and "seconds ago" in text
    # bit for bit: positions, triangles, painted fields, the mesh as first opened, handles
    want, have = np.load(out / "expected.npz"), np.load(out / "recovered.npz")
    assert sorted(want.files) == sorted(have.files)
    assert {"V", "F", "orig_V", "field:lambda_scale", "field:fixed"} <= set(want.files)
    for k in want.files:
        assert want[k].dtype == have[k].dtype and np.array_equal(want[k], have[k]), k
    assert np.abs(want["V"] - want["orig_V"]).max() > 1e-3  # the jobs changed the mesh
    expected = json.loads((out / "expected.json").read_text())
    assert got["handles"] == expected["handles"] and got["fields"] == expected["fields"]
    # every panel's settings, as the jobs left them
    assert got["panels"] == expected["panels"]
    assert got["panels"]["Cubic"]["params"]["lam"] == 0.6
    assert got["panels"]["Smooth"]["params"]["iterations"] == 2
    # unsaved work whose undo history starts here; the project it came from is remembered
    assert got["modified"] and not got["can_undo"] and got["undo_count"] == 0
    assert got["project_path"] == str(out / "scene.s3d") and "[*]" in got["title"]
    # the killed process's slot went once the new window had its own copy ...
    assert got["recovery_files"] == [f"{got['own_slot']}.json", f"{got['own_slot']}.s3d"]
    # ... and a normal close ("Discard changes") removed that one
    assert any(s[0] == "confirm" and s[3] == "Discard changes" for s in got["said"])
    assert got["closed"] and got["after_close"] == [] and not list(rec.iterdir())


# ------------------------------------------------------------------------------ timers
def test_several_quick_edits_give_one_write(window, qtbot):
    auto = window.autosave
    assert auto.debounce.interval() == 1500 and auto.debounce.isSingleShot()
    _open_blob(window)
    assert not auto.slot.exists()  # a freshly opened file is not unsaved work
    auto.debounce.setInterval(600)
    saved = []
    auto.saved.connect(saved.append)
    for k in range(5):
        _edit(window, k)
        qtbot.wait(40)
    assert auto.writes == 0 and auto.dirty  # each edit restarted the pause
    qtbot.waitUntil(lambda: auto.writes == 1, timeout=5000)
    qtbot.wait(900)
    assert auto.writes == 1 and saved == [str(auto.slot.project_file)]
    _same_state(_slot_state(auto.slot.project_file), window.document.state)
    info = list_slots(auto.slot.folder)[0]
    assert info.pid == os.getpid() and info.last_change == "Paint 4" and info.changes == 5
    assert info.title == "blob.obj" and info.mesh_path == str((SAMPLES / "blob.obj").resolve())
    # nothing changed since: the timers write nothing
    auto.max_wait.timeout.emit()
    auto.debounce.timeout.emit()
    qtbot.wait(100)
    assert auto.writes == 1


def test_changes_that_keep_coming_are_saved_at_least_every_max_wait(window, qtbot):
    auto = window.autosave
    assert auto.max_wait.interval() == 60_000 and auto.max_wait.isSingleShot()
    _open_blob(window)
    auto.debounce.setInterval(5000)  # never reached: an edit comes every 50 ms
    auto.max_wait.setInterval(400)  # stands for the 60 s
    t0 = time.monotonic()
    _edit(window, 0)
    k = 1
    while time.monotonic() - t0 < 2.0:
        qtbot.wait(50)
        # the loop ends on an edit: a periodic write inside the last wait must not make the
        # pause look over (that raced, about one run in ten)
        _edit(window, k % 7)
        k += 1
    assert auto.debounce.isActive()
    assert 2 <= auto.writes <= 6, auto.writes
    n = auto.writes
    qtbot.waitUntil(lambda: auto.idle, timeout=3000)  # the last change: at most 0.4 s later
    assert auto.writes > n and auto.debounce.isActive() is False
    _same_state(_slot_state(auto.slot.project_file), window.document.state)


# ------------------------------------------------------------------------------ atomic writes
def test_a_failing_write_leaves_the_previous_autosave_intact(tmp_path, monkeypatch):
    slot = RecoverySlot(tmp_path)
    slot.write(b"first version", {"title": "a", "saved_at": 1.0})
    old_info = slot.info_file.read_bytes()

    def no_space(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(autosave.os, "fsync", no_space)
    with pytest.raises(OSError):
        slot.write(b"second version, longer", {"title": "b", "saved_at": 2.0})
    monkeypatch.undo()
    assert slot.project_file.read_bytes() == b"first version"
    assert slot.info_file.read_bytes() == old_info
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{slot.id}.json", f"{slot.id}.s3d"]
    assert (slot.project_file.stat().st_mode & 0o777) == 0o600
    slot.write(b"second version", {"title": "b", "saved_at": 2.0})
    assert slot.project_file.read_bytes() == b"second version"


def test_a_failing_autosave_is_said_once_and_retried(window, qtbot, monkeypatch):
    import app.project

    auto = window.autosave
    _open_blob(window)
    _edit(window, 0)
    auto.save_now(wait=True)
    good = auto.slot.project_file.read_bytes()
    failures = []
    auto.failed.connect(failures.append)

    def broken(project):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(app.project, "project_bytes", broken)
    _edit(window, 1)
    auto.save_now(wait=True)
    _edit(window, 2)
    auto.save_now(wait=True)
    assert len(failures) == 2 and auto.dirty
    assert auto.slot.project_file.read_bytes() == good  # the last good autosave is kept
    said = [m for m in [t for _s, _l, t in window.message_log.entries] if "Autosave failed" in m]
    assert len(said) == 1 and "No space left" in said[0]
    monkeypatch.undo()
    auto.max_wait.timeout.emit()  # the retry
    auto.wait()
    _same_state(_slot_state(auto.slot.project_file), window.document.state)
    assert any("Autosave works again" in m for m in [t for _s, _l, t in window.message_log.entries])


# ------------------------------------------------------------------------------ slots
def test_two_windows_keep_their_own_slots_and_a_normal_close_removes_them(window, dialogs,
                                                                           qtbot, tmp_path):
    from PySide6.QtCore import QSettings

    from app.main_window import MainWindow

    other = MainWindow(settings=QSettings(str(tmp_path / "other.ini"),
                                          QSettings.Format.IniFormat))
    other.show()
    try:
        _open_blob(window)
        _open_blob(other)
        _edit(window, 1)
        _edit(other, 2)
        _edit(other, 3)
        window.autosave.save_now(wait=True)
        other.autosave.save_now(wait=True)
        a, b = window.autosave.slot, other.autosave.slot
        assert a.id != b.id and a.folder == b.folder
        assert a.project_file.exists() and b.project_file.exists()
        _same_state(_slot_state(a.project_file), window.document.state)
        _same_state(_slot_state(b.project_file), other.document.state)
        assert _slot_state(a.project_file).fields["lambda_scale"][0] == 0.2
        assert _slot_state(b.project_file).fields["lambda_scale"][0] == 0.4
        # a window of a running process is never offered (both are this process's)
        assert orphaned_slots(a.folder) == []
        # a normal close after "Discard changes" removes that window's files only
        dialogs.answers.append("Discard changes")
        assert other.close()
        assert not b.exists() and a.project_file.exists()
        assert dialogs.questions[-1][0] == "Unsaved changes"
    finally:
        if other.isVisible():
            other.document.modified = False
            other.close()
        other.deleteLater()


def test_saving_the_work_removes_the_slot(window, dialogs, qtbot, tmp_path):
    auto = window.autosave
    auto.debounce.setInterval(200)
    _open_blob(window)
    _edit(window, 0)
    auto.save_now(wait=True)
    assert auto.slot.exists()
    dialogs.save_paths.append(str(tmp_path / "kept.s3d"))
    assert window.save_project_dialog()
    qtbot.waitUntil(lambda: not auto.slot.exists(), timeout=5000)  # the work is on disk
    _edit(window, 1)
    auto.save_now(wait=True)
    assert auto.slot.exists()
    window.undo_stack.undo()  # back to the saved state: nothing unsaved to keep
    qtbot.waitUntil(lambda: not auto.slot.exists(), timeout=5000)


def _orphan(folder, window, *, pid=None, host=None, info=None) -> RecoverySlot:
    from app.project import project_bytes

    slot = RecoverySlot(folder, pid=_dead_pid() if pid is None else pid, host=host)
    st = window.document.state
    slot.write(project_bytes(window.current_project()),
               {"title": "blob.obj", "saved_at": time.time() - 300, "vertices": len(st.V),
                "faces": len(st.F), **(info or {})})
    return slot


def test_only_slots_of_processes_that_ended_on_this_host_are_offered(window, tmp_path,
                                                                     monkeypatch):
    _open_blob(window)
    folder = tmp_path / "slots"
    live = _orphan(folder, window, pid=os.getpid())
    dead = _orphan(folder, window)
    elsewhere = _orphan(folder, window, host="another-machine")
    assert {s.slot for s in list_slots(folder)} == {live.id, dead.id, elsewhere.id}
    assert [s.slot for s in orphaned_slots(folder)] == [dead.id]
    # the pid runs again, but it is another process (started at another time): offered
    side = json.loads(live.info_file.read_text())
    side["pid_started"] -= 3600
    live.info_file.write_text(json.dumps(side))
    assert {s.slot for s in orphaned_slots(folder)} == {live.id, dead.id}
    # a slot whose sidecar was never written (killed between the two files) is still offered
    dead.info_file.unlink()
    info = [s for s in orphaned_slots(folder) if s.slot == dead.id][0]
    assert info.title == "unnamed work" and abs(info.saved_at - time.time()) < 60
    # the temporary file of a first write a crash interrupted goes; a running one's stays
    host = autosave.this_host()
    gone = folder / f".{host}_{_dead_pid()}_0badc0de.s3d.x1y2z3.tmp"
    kept = folder / f".{host}_{os.getpid()}_0badc0de.s3d.x1y2z3.tmp"
    for p in (gone, kept):
        p.write_bytes(b"half a project")
    orphaned_slots(folder)
    assert not gone.exists() and kept.exists()


def test_discard_deletes_and_decide_later_keeps(window, dialogs, qtbot, tmp_path):
    _open_blob(window)
    _edit(window, 0)
    folder = tmp_path / "slots"
    slot = _orphan(folder, window)
    window.undo_stack.clear()
    asked = []

    def later(dlg):
        asked.append(dlg.text.text())
        qtbot.mouseClick(dlg.later_button, _left())
        return dlg.choice

    assert autosave.offer_recovery(window, ask=later, folder=folder) is False
    assert slot.exists() and "blob.obj" in asked[0] and "5 minutes ago" in asked[0]

    def discard(dlg):
        qtbot.mouseClick(dlg.discard_button, _left())
        return dlg.choice

    assert autosave.offer_recovery(window, ask=discard, folder=folder) is False
    assert not slot.exists() and not list(folder.iterdir())
    assert autosave.offer_recovery(window, ask=discard, folder=folder) is False  # nothing left
    assert len(asked) == 1


def _left():
    from PySide6.QtCore import Qt

    return Qt.MouseButton.LeftButton


def test_recovered_mesh_work_is_unsaved_and_save_asks_before_replacing(window, dialogs, qtbot,
                                                                       tmp_path):
    import shutil

    src = tmp_path / "mine.obj"
    shutil.copy(SAMPLES / "blob.obj", src)
    assert window.open_path(src)
    _edit(window, 0)
    _edit(window, 1)
    cubic = window.panels["Cubic"]
    cubic.form.set_value("lam", 0.45)
    cubic.plane_axis.setCurrentIndex(2)
    settings = window.panel_settings()
    want = window.document.state
    folder = tmp_path / "slots"
    _orphan(folder, window, info={"mesh_path": str(src)})
    # a fresh window state: other settings, another mesh
    window.undo_stack.setClean()
    window.document.modified = False
    cubic.form.set_value("lam", 0.2)
    cubic.plane_axis.setCurrentIndex(0)
    _open_blob(window)

    def recover(dlg):
        qtbot.mouseClick(dlg.recover_button, _left())
        return dlg.choice

    assert autosave.offer_recovery(window, ask=recover, folder=folder) is True
    _same_state(window.document.state, want)
    assert window.panel_settings() == settings
    assert cubic.form.params().lam == 0.45 and cubic.plane_axis.currentIndex() == 2
    assert window.document.modified and not window.undo_stack.canUndo()
    assert window.document.path == src and "mine.obj" in window.windowTitle()
    # the dead process's slot was replaced by this window's own
    assert [s.slot for s in list_slots(folder)] == []
    assert window.autosave.slot.exists()
    _same_state(_slot_state(window.autosave.slot.project_file), want)
    # an edit and its undo: still unsaved work (the recovered state is saved nowhere)
    _edit(window, 5)
    window.undo_stack.undo()
    assert window.document.modified and "[*]" in window.windowTitle()
    # Save writes the original mesh file only after asking
    before = src.read_bytes()
    dialogs.answers.append("Cancel")
    assert window.save() is False
    assert dialogs.questions[-1][0] == "Replace file?" and src.read_bytes() == before
    dialogs.answers.append("Replace")
    assert window.save() is True and not window.document.modified


def test_a_damaged_slot_is_said_and_kept(window, dialogs, tmp_path):
    folder = tmp_path / "slots"
    slot = RecoverySlot(folder, pid=_dead_pid())
    slot.write(b"not a project", {"title": "x.obj", "saved_at": time.time()})
    assert autosave.offer_recovery(window, ask=lambda dlg: autosave.RECOVER,
                                   folder=folder) is False
    assert dialogs.errors and dialogs.errors[-1][0] == "Cannot recover the autosaved work"
    assert slot.exists() and window.document.is_empty


def test_no_autosave_and_no_offer_in_a_study_session(window, dialogs, qtbot, tmp_path):
    from app.study.session import start_study

    protocol = tmp_path / "study.json"
    protocol.write_text(json.dumps({
        "study": "autosave", "conditions": ["A"],
        "tasks": [{"id": "smooth-it", "title": "Smooth", "instructions": "Smooth it.",
                   "mesh": "sample:blob",
                   "conditions": {"A": {"panels": ["Smooth"],
                                        "params": {"Smooth": {"iterations": 2}}}}}]}))
    folder = tmp_path / "slots"
    _open_blob(window)
    orphan = _orphan(folder, window)
    start_study(window, protocol, log_dir=tmp_path / "logs", participant="P1", condition="A")
    assert autosave.in_study_session(window)
    smooth = window.panels["Smooth"]
    smooth.live_box.setChecked(False)
    with qtbot.waitSignal(window.job_committed, timeout=60000):
        smooth.run_button.click()
    assert window.document.modified
    window.autosave.save_now(wait=True)
    qtbot.wait(200)
    assert window.autosave.writes == 0 and not window.autosave.slot.exists()
    assert autosave.offer_recovery(window, ask=lambda dlg: pytest.fail("asked"),
                                   folder=folder) is False
    assert orphan.exists()
