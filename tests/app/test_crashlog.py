"""No silent crash (issue 35): a segfault in a command, a batch worker or the app leaves a crash
log with every thread's Python stack; a command says so and exits with 70; the app says so at
its next start, once (app/crashlog.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from app import crashlog
from tests.conftest import ROOT, SAMPLES, TEST_DATA

_SCRIPT = Path(sys.executable).parent / "stylize3d"
#: what a user types: the console script (``python -m app`` where it is not installed)
STYLIZE3D = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "app"]
BLOB = SAMPLES / "blob.obj"
#: a cubic run of several seconds (sixteen λ share one set-up, 0.2 s each): still running when
#: it is killed, even on a loaded machine
SLOW_CUBIC = ["cubic", str(BLOB), "--lambda", *[f"{0.05 * k:.2f}" for k in range(1, 17)]]


@pytest.fixture(autouse=True)
def _sigint_as_in_a_terminal():
    """The commands these tests start get SIGINT at its default, as from an interactive shell.

    A program started in the background by a script (``pytest ... &`` in a CI job without job
    control) inherits SIGINT *ignored*; Python then installs no KeyboardInterrupt handler and
    every command it starts ignores SIGINT too, as POSIX asks (the supervisor keeps that, see
    :func:`test_a_command_whose_caller_ignores_sigint_ignores_it_too`). A handler set here is
    reset to the default in a child by ``exec``; the old disposition comes back after the test.
    """
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


@pytest.fixture
def crash_dir(tmp_path, monkeypatch) -> Path:
    d = tmp_path / "crash-logs"
    monkeypatch.setenv("STYLIZE3D_CRASH_DIR", str(d))
    monkeypatch.delenv("STYLIZE3D_SUPERVISE", raising=False)
    return d


def _wait_for(what, timeout=60.0, proc=None, every=0.02):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = what()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the process ended early (status {proc.returncode})")
        time.sleep(every)
    raise AssertionError("timed out")


def _logs(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.log")) if folder.exists() else []


def _child_pid(folder: Path) -> int | None:
    """The pid of the supervised command, from the line it adds to its crash log."""
    for p in _logs(folder):
        for line in p.read_text(errors="replace").splitlines():
            if line.startswith("# the command runs in pid "):
                return int(line.split()[6])
    return None


def _gone(pid: int) -> bool:
    import psutil

    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def _start_cubic(tmp_path, *extra, env=None, command=SLOW_CUBIC):
    """The slow cubic command, its stderr going to a file (:func:`_stderr` reads it)."""
    err = tmp_path / "stderr.txt"
    with open(err, "w") as fh:
        proc = subprocess.Popen([*STYLIZE3D, *command, "-o", str(tmp_path / "out.obj"),
                                 *extra], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=fh,
                                env=env)
    return proc, err


def _stderr(err: Path) -> str:
    return err.read_text(errors="replace")


# ----------------------------------------------------------------------------- commands
def test_a_segfault_in_a_command_says_where_its_stacks_are_and_exits_70(tmp_path, crash_dir):
    proc, err = _start_cubic(tmp_path)
    try:
        child = _wait_for(lambda: _child_pid(crash_dir), proc=proc)
        _wait_for(lambda: "iteration" in _stderr(err), proc=proc)  # it is computing
        assert proc.poll() is None, "the command ended before it could be killed"
        os.kill(child, signal.SIGSEGV)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = _stderr(err)
    assert proc.returncode == 70, text
    (log,) = _logs(crash_dir)
    assert log.name.endswith(f"_cli-cubic_{proc.pid}.log")
    said = text.strip().splitlines()[-1]
    assert said.startswith("stylize3d cubic crashed (segmentation fault); the details are in ")
    assert f"the details are in {log}." in said and "Your input files are unchanged." in said
    assert "Traceback" not in text
    content = log.read_text()
    # the header: program, command line, pid, start time, versions
    assert "# Stylize3D crash log of the command 'stylize3d cubic' (cli-cubic)" in content
    assert f"# command: stylize3d cubic {BLOB}" in content
    assert f"pid {proc.pid}" in content and f"runs in pid {child}" in content
    assert "# started 2" in content and "Python 3." in content
    # the stacks faulthandler wrote, in the solver, and what the supervisor added
    assert "Fatal Python error: Segmentation fault" in content
    assert "Current thread 0x" in content and 'File "' in content
    # the command's frame; the solver's frames only when the signal came inside an iteration
    # (between two, the main thread is printing the progress line in app/cli/deform.py)
    assert "app/cli/deform.py" in content
    assert "died of signal SIGSEGV" in content and "Versions: " in content
    assert "numpy " in content.split("Versions: ")[1]
    assert crashlog.has_crash(log)
    assert not (tmp_path / "out.obj").exists()


def test_a_normal_command_passes_everything_through_and_leaves_no_crash_log(
        crash_dir, capsys):
    from app.__main__ import main

    mesh = str(TEST_DATA / "spot_lowres.obj")
    assert main(["info", mesh, "--json"]) == 0  # in this process: nothing installed
    here = json.loads(capsys.readouterr().out)
    assert crashlog.current_log() is None
    out = subprocess.run([*STYLIZE3D, "info", mesh, "--json"], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0 and out.stderr == ""
    assert json.loads(out.stdout) == here
    # exit statuses and messages pass through
    bad = subprocess.run([*STYLIZE3D, "info", "no-such-file.obj"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "does not exist" in bad.stderr
    typo = subprocess.run([*STYLIZE3D, "cubc", "x"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert typo.returncode == 2 and "Did you mean 'cubic'?" in typo.stderr
    # stdin reaches the command, a closed stdout is the command's own business
    piped = subprocess.run([*STYLIZE3D, "info", mesh, "--json"], cwd=ROOT, input="",
                           capture_output=True, text=True, timeout=120)
    assert json.loads(piped.stdout) == here
    assert _logs(crash_dir) == []  # every supervised run removed its crash log


def test_signals_reach_the_command_and_its_status_passes_through(tmp_path, crash_dir):
    # SIGINT sent to the process the shell started (kill, not the terminal): forwarded once
    proc, err = _start_cubic(tmp_path)
    try:
        child = _wait_for(lambda: _child_pid(crash_dir), proc=proc)
        _wait_for(lambda: "iteration" in _stderr(err), proc=proc)
        proc.send_signal(signal.SIGINT)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = _stderr(err)
    assert proc.returncode == 130, text
    assert "stylize3d: interrupted; nothing was written." in text and "Traceback" not in text
    assert _wait_for(lambda: _gone(child), timeout=10)
    assert _logs(crash_dir) == []
    # SIGTERM (forwarded to the command): it stops like Ctrl+C, says so, exits 143 (issue 39)
    proc, err = _start_cubic(tmp_path)
    try:
        child = _wait_for(lambda: _child_pid(crash_dir), proc=proc)
        _wait_for(lambda: "iteration" in _stderr(err), proc=proc)  # past start-up
        proc.terminate()
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = _stderr(err)
    assert proc.returncode == 143, text
    assert "stylize3d: stopped (SIGTERM); nothing was written." in text
    assert "Traceback" not in text
    assert _wait_for(lambda: _gone(child), timeout=10)
    assert _logs(crash_dir) == []
    # SIGKILL of the supervisor: the kernel ends the command too (no orphan keeps computing)
    proc, err = _start_cubic(tmp_path)
    try:
        child = _wait_for(lambda: _child_pid(crash_dir), proc=proc)
        proc.kill()
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert _wait_for(lambda: _gone(child), timeout=10)


def test_ctrl_c_in_a_terminal_interrupts_the_command_once(tmp_path, crash_dir):
    """The terminal sends SIGINT to the supervisor and the command (one process group): the
    supervisor must not forward it a second time (a second KeyboardInterrupt while the command
    says "interrupted" would be a traceback)."""
    import pty

    pid, fd = pty.fork()
    if pid == 0:  # the child: a session of its own with the pseudo-terminal as its terminal
        try:
            os.chdir(ROOT)
            signal.signal(signal.SIGINT, signal.SIG_DFL)  # as an interactive shell starts it
            os.execv(STYLIZE3D[0], [*STYLIZE3D, *SLOW_CUBIC, "-o", str(tmp_path / "out.obj")])
        finally:
            os._exit(127)
    out = b""
    sent = False
    deadline = time.time() + 120
    while time.time() < deadline:
        try:
            data = os.read(fd, 4096)
        except OSError:  # the terminal closed: the command ended
            break
        if not data:
            break
        out += data
        if not sent and b"iteration 2:" in out:
            os.write(fd, b"\x03")  # Ctrl+C
            sent = True
    _, status = os.waitpid(pid, 0)
    os.close(fd)
    text = out.decode(errors="replace")
    assert sent, text
    assert os.waitstatus_to_exitcode(status) == 130, text
    assert text.count("interrupted; nothing was written.") == 1 and "Traceback" not in text
    assert _logs(crash_dir) == []


def test_a_command_whose_caller_ignores_sigint_ignores_it_too(tmp_path, crash_dir):
    """``stylize3d cubic ... &`` in a script: SIGINT is ignored, so the command keeps running
    through a SIGINT sent to it, as it would without a supervisor, and writes its results."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the command (the fixture resets)
    proc, err = _start_cubic(tmp_path, command=["cubic", str(BLOB), "--lambda", "0.2", "0.4",
                                                "0.6", "0.8"])
    try:
        child = _wait_for(lambda: _child_pid(crash_dir), proc=proc)
        _wait_for(lambda: "iteration" in _stderr(err), proc=proc)
        proc.send_signal(signal.SIGINT)  # forwarded by the supervisor, ignored by the command
        proc.wait(120)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = _stderr(err)
    assert proc.returncode == 0, text
    assert "interrupted" not in text and "Traceback" not in text
    assert len(list(tmp_path.glob("out_lambda*.obj"))) == 4
    assert _wait_for(lambda: _gone(child), timeout=10)
    assert _logs(crash_dir) == []


def test_without_the_supervisor_a_segfault_still_leaves_its_stacks(tmp_path, crash_dir):
    env = {**os.environ, "STYLIZE3D_SUPERVISE": "0"}
    proc, err = _start_cubic(tmp_path, env=env)
    try:
        log = _wait_for(lambda: [p for p in _logs(crash_dir)
                                 if p.name.endswith(f"_cli-cubic_{proc.pid}.log")], proc=proc)[0]
        _wait_for(lambda: "iteration" in _stderr(err), proc=proc)
        os.kill(proc.pid, signal.SIGSEGV)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGSEGV  # the signal's status (module docstring)
    content = log.read_text()
    assert "Fatal Python error: Segmentation fault" in content and 'File "' in content
    assert "app/cli/deform.py" in content


def test_python_errors_and_pruning_use_the_one_folder(tmp_path, crash_dir, monkeypatch,
                                                      capsys):
    from app import cli

    def boom(args):
        raise RuntimeError("a defect")

    monkeypatch.setattr(cli, "cmd_info", boom)
    assert cli.main(["info", str(TEST_DATA / "spot_lowres.obj")]) == 70
    err = capsys.readouterr().err
    path = Path(err.split("the details are in ")[1].strip().rstrip("."))
    assert path.parent == crash_dir and path.name.endswith(f"_{os.getpid()}_error.log")
    text = path.read_text()
    assert text.startswith("# Stylize3D crash log") and "RuntimeError: a defect" in text
    # the folder does not fill up: a header-only log of a process that is gone is removed;
    # a live process's, a crash's and an error log stay
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    header = crashlog._header("app", ["x.obj"])
    gone = crash_dir / f"20250101-000000_app_{dead.pid}.log"
    alive = crash_dir / f"20250101-000000_app_{os.getppid()}.log"
    crashed = crash_dir / f"20250101-000001_app_{dead.pid}.log"
    for p in (gone, alive, crashed):
        p.write_text(header)
    with open(crashed, "a") as fh:
        fh.write("Fatal Python error: Aborted\n\nCurrent thread 0x1 (most recent call first):\n")
    assert not crashlog.has_crash(gone) and crashlog.has_crash(crashed)
    assert crashlog.prune() == 1
    assert not gone.exists() and alive.exists() and crashed.exists() and path.exists()
    # a file name with a newline cannot fake a crash in a header
    assert not crashlog.has_crash_text(crashlog._header("app", ["a\nb.obj"]))


# ----------------------------------------------------------------------------- batch workers
def test_a_batch_worker_crash_is_named_in_the_mesh_record(tmp_path, crash_dir):
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import icosphere
    from app.cli import main

    lib = tmp_path / "lib"
    lib.mkdir()
    slow = lib / "armadillo.obj"
    slow.write_bytes((TEST_DATA / "armadillo.obj").read_bytes())
    small = lib / "sphere.obj"
    write_mesh(small, *icosphere(2))
    out = tmp_path / "out"
    killed = {}

    def kill_the_slow_one():
        deadline = time.time() + 120
        while time.time() < deadline and not killed:
            for f in (out / ".batch").glob("run-*/pid-*.json"):
                try:
                    d = json.loads(f.read_text())
                except (OSError, ValueError):
                    continue
                if d["input"] == str(slow.resolve()):
                    killed.update(d)
                    os.kill(d["pid"], signal.SIGSEGV)
                    return
            time.sleep(0.01)

    t = threading.Thread(target=kill_the_slow_one)
    t.start()
    try:
        code = main(["batch", "cubic", str(slow), str(small), "-o", str(out), "--workers", "1",
                     "--retries", "0", "--quiet"])
    finally:
        t.join(130)
    assert killed, "the slow mesh never started"
    assert code == 1
    recs = {}
    for line in (out / "batch-report.jsonl").read_text().splitlines():
        r = json.loads(line)
        recs[r["input"]] = r
    r = recs[str(slow.resolve())]
    log = Path(killed["crash_log"])
    assert r["status"] == "failed" and r["crash_log"] == str(log) == r["crash_logs"][-1]
    assert "the worker process died while working on it" in r["message"]
    assert f"It crashed; the details are in {log}." in r["message"]
    assert log.parent == crash_dir and log.name.endswith(f"_batch-worker_{killed['pid']}.log")
    content = log.read_text()
    assert "# Stylize3D crash log of a batch worker process (batch-worker)" in content
    assert "Fatal Python error: Segmentation fault" in content and 'File "' in content
    assert "Thread 0x" in content  # the watchdog thread's stack too: every thread
    assert recs[str(small.resolve())]["status"] == "done"
    assert "crash_logs" not in recs[str(small.resolve())]
    # the worker that ended normally removed its crash log
    assert _logs(crash_dir) == [log]


# ----------------------------------------------------------------------------- the app
def _app_env(tmp_path, crash_dir) -> dict:
    return {**os.environ, "HOME": str(tmp_path / "home"),
            "XDG_CONFIG_HOME": str(tmp_path / "home" / ".config"),
            "STYLIZE3D_CRASH_DIR": str(crash_dir)}


def _start_app(tmp_path, env) -> subprocess.Popen:
    with open(tmp_path / "app-stderr.txt", "a") as err:
        return subprocess.Popen([*STYLIZE3D, str(BLOB)], cwd=ROOT, env=env,
                                stdout=subprocess.DEVNULL, stderr=err)


def _window_shown() -> bool:
    """Whether a Stylize3D window is on the (virtual) screen; where ``xwininfo`` is missing,
    after two seconds."""
    import shutil

    if shutil.which("xwininfo") is None:
        time.sleep(2.0)
        return True
    tree = subprocess.run(["xwininfo", "-root", "-tree"], capture_output=True, text=True,
                          timeout=30).stdout
    return "Stylize3D" in tree


def test_an_app_crash_is_logged_and_said_once_at_the_next_start(tmp_path, crash_dir,
                                                                 needs_display, qtbot,
                                                                 dialogs):
    env = _app_env(tmp_path, crash_dir)
    proc = _start_app(tmp_path, env)
    try:
        name = f"_app_{proc.pid}.log"
        log = _wait_for(lambda: [p for p in _logs(crash_dir) if p.name.endswith(name)
                                 and "---- Python stacks" in p.read_text()],
                        proc=proc, timeout=120)[0]
        _wait_for(_window_shown, proc=proc, timeout=120, every=0.1)
        assert proc.poll() is None
        os.kill(proc.pid, signal.SIGSEGV)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGSEGV  # the app is not supervised (module docstring)
    content = log.read_text()
    assert "# Stylize3D crash log of the Stylize3D app (app)" in content
    assert f"# command: stylize3d {BLOB}" in content
    assert "Fatal Python error: Segmentation fault" in content and 'File "' in content
    assert "app/gui.py" in content  # the main thread's stack: the event loop of run_app
    saved = content

    # the next start says it (run_app): the log is marked as shown
    proc = _start_app(tmp_path, env)
    seen = log.with_name(log.name[:-4] + ".seen.log")
    try:
        _wait_for(seen.exists, proc=proc, timeout=120)
        proc.terminate()
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not log.exists() and seen.read_text() == saved

    # in this process, a window given a crash log shows the message once, without a dialog
    from PySide6.QtCore import QSettings

    from app.main_window import MainWindow

    log.write_text(saved)  # unseen again
    win = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat))
    try:
        win.show()
        qtbot.waitExposed(win)
        said = [crashlog.announce_last_crash(lambda t: win.report(t, "warning", 60_000),
                                             win.show_messages)
                for _ in range(2)]  # as run_app calls it; a second start says nothing
        shown = said[0]
        assert shown is not None and said[1] is None
        text = (f"Stylize3D stopped unexpectedly last time. The details are in {shown}.")
        assert win.message_log.all_text().count(text) == 1
        assert win.statusBar().currentMessage().startswith("Stylize3D stopped unexpectedly")
        assert win.messages_dock.isVisible()
        assert Path(shown).read_text() == saved and not log.exists()
        assert not dialogs.errors and not dialogs.infos
    finally:
        win.document.modified = False
        win.close()
        win.deleteLater()
        from algorithms import offload

        offload.keep_lock_free(False)
