"""Crash logs: no silent crash (issue 35). Qt-free; the one implementation the CLI, the batch
workers and the app use.

A segmentation fault (SIGSEGV) or an abort (SIGABRT) in compiled code (NumPy, SciPy, VTK, Qt,
PyTorch, a Numba kernel, ...) kills a Python process before any ``except`` runs. Python's
:mod:`faulthandler` can still write the Python stack of every thread at that moment (SIGSEGV,
SIGFPE, SIGABRT, SIGBUS, SIGILL) to a file descriptor opened beforehand; it cannot print a
sentence nor choose the exit status. So:

**Where.** One folder per user, :func:`crash_dir`: ``$STYLIZE3D_CRASH_DIR`` if set (tests use a
temporary folder), else ``$XDG_STATE_HOME/stylize3d/crash-logs``, else
``~/.local/state/stylize3d/crash-logs``. A file is named ``<YYYYmmdd-HHMMSS>_<program>_<pid>.log``;
``program`` is ``cli-<command>`` (a sub-command), ``batch-worker`` or ``app``. A Python error of
ours that the CLI or a batch worker caught (exit status 70, "the details are in ...") is written
there too, as ``..._<pid>_error.log`` (:func:`write_error_log`).

**Every crash-logged process** opens its file when it starts and writes a header (lines
starting with ``#``: program, command line, versions, pid, start time); faulthandler then
writes below it. The header alone means "nothing happened": a process that ends normally
removes its file (atexit; a batch worker's watchdog, which ends its process with ``os._exit``,
calls :func:`discard`), and a header-only file whose process is gone (killed with SIGKILL /
SIGTERM, where atexit does not run) is removed by the next :func:`install` or supervised
command (:func:`prune`). A file with more than its header is a crash: it is kept.

**A sub-command** (``stylize3d cubic ...``, :func:`entry`) runs in a child process under a small
supervising parent (:func:`supervise`), the process the shell started. The parent creates the
crash log, hands its descriptor to the child (which points faulthandler at it) and waits:

- the child exits: the parent removes the crash log and exits with the child's status
  (stdin / stdout / stderr are the same file descriptors, so ``--json`` output, pipes and
  exit statuses pass through unchanged);
- the child dies of SIGSEGV, SIGFPE, SIGABRT, SIGBUS or SIGILL: the crash log holds every
  thread's stack; the parent adds the signal and the library versions, prints *"stylize3d cubic
  crashed (segmentation fault); the details are in PATH. Your input files are unchanged. ..."*
  to stderr and exits with **70**, as the README promises for an unexpected failure;
- the child is killed with SIGKILL (most often the kernel's out-of-memory killer): a plain
  sentence saying so, exit status 70 (as a MemoryError gives); no log (there is nothing in it);
- the child dies of another signal (SIGINT, SIGTERM, SIGHUP, ...): the parent dies of the same
  signal, so the caller sees the status it saw before the supervisor existed.

Signals sent to the parent are forwarded to the child: SIGTERM, SIGHUP, SIGQUIT, SIGUSR1,
SIGUSR2 and SIGINT, except a signal the terminal generated (Ctrl+C, Ctrl+\\, a hang-up), which
the kernel already delivered to the child too (same process group; forwarding it would give the
child a second KeyboardInterrupt while it prints "interrupted"). The parent tells them apart by
``si_code`` (``signal.sigtimedwait``: SI_KERNEL from the terminal, SI_USER from ``kill``). Job
control (Ctrl+Z, ``fg``) reaches both processes as before. The child asks the kernel to kill it
when its parent dies (``PR_SET_PDEATHSIG``), so ``kill -9`` of the command's pid still stops the
work. Cost: one more Python start-up (the parent imports nothing but this module), about 30 ms
(measured: ``stylize3d info spot_lowres.obj``, 30 runs each with cached bytecode, median 0.256 s
supervised against 0.224 s with ``STYLIZE3D_SUPERVISE=0`` and 0.224 s for ``app.cli.main`` run
directly, on this 2-core machine).

``STYLIZE3D_SUPERVISE=0``, a platform without ``sigtimedwait`` / ``posix_spawn`` (not Linux), or
a child that cannot be started: the command runs in the process itself with :func:`install`;
a crash then still leaves its crash log with every thread's stack, but prints nothing and the
exit status is the signal's (e.g. 139 in a shell for SIGSEGV).

**A command called in-process** (``app.cli.main([...])`` / ``app.__main__.main([...])`` with an
explicit argument list: tests, scripts) installs nothing: the caller owns its process (pytest
has its own faulthandler).

**The app** (:func:`app.gui.run_app`) is not supervised (nobody reads its terminal): it calls
:func:`install`, and at its next start :func:`announce_last_crash` says *"Stylize3D stopped
unexpectedly last time. The details are in PATH."* in the status bar and View > Messages (never
a dialog), once: the log is renamed to ``...seen.log`` before it is shown, so the path shown is
the file's. Only the app's own crash logs are announced (a command's crash was said on its
terminal, a batch worker's is in the batch report).

**A batch worker** (:func:`app.batch.worker.init_pool_worker`) calls :func:`install`; its crash
log's path goes into the run folder's ``pid-<pid>.json``, and the driver puts it in the failed
record's message and ``crash_log`` (and ``crash_logs`` of a record whose mesh was retried).
Dask workers are not crash-logged (Dask reports their deaths).

This module imports only the standard library's cheapest modules at import time (the
supervising parent must start fast); the rest is imported when needed.
"""

from __future__ import annotations

import os
import signal
import sys
import time

#: the variable that names the crash-log folder (tests point it at a temporary folder)
DIR_VARIABLE = "STYLIZE3D_CRASH_DIR"
#: ``STYLIZE3D_SUPERVISE=0`` runs a sub-command in the process itself (module docstring)
SUPERVISE_VARIABLE = "STYLIZE3D_SUPERVISE"
#: parent -> child: ``"<fd>:<parent pid>:<program>:<path>"`` (removed from the child's environment)
_CHILD_VARIABLE = "_STYLIZE3D_CRASH_LOG"
#: exit status of an unexpected failure (the same as app.cli.common.INTERNAL_ERROR_EXIT)
INTERNAL_ERROR_EXIT = 70

#: the signals faulthandler reports, with the words a user reads
FATAL_SIGNALS: dict[int, str] = {
    signal.SIGSEGV: "segmentation fault",
    signal.SIGFPE: "floating-point exception",
    signal.SIGABRT: "aborted",
    signal.SIGBUS: "bus error",
    signal.SIGILL: "illegal instruction",
}
#: signals the supervisor forwards to the command (SIGINT only when it was not the terminal's)
_FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1,
              signal.SIGUSR2)
_SI_KERNEL = 0x80  # Linux: a signal the kernel (here: the terminal) generated
#: the first line of what faulthandler writes
FAULT_MARK = "Fatal Python error"
_HEADER_END = "# ---- Python stacks of every thread at a crash follow this line ----\n"
_MAX_COMMAND = 4000

_state: dict = {"path": None, "fd": None, "program": None, "pid": None, "owner": False}


# ----------------------------------------------------------------------------- files
def crash_dir() -> str:
    """The per-user crash-log folder (module docstring); not created here."""
    env = os.environ.get(DIR_VARIABLE)
    if env:
        return os.path.abspath(os.path.expanduser(env))
    state = os.environ.get("XDG_STATE_HOME", "")
    if not os.path.isabs(state):  # the XDG spec: a relative path is invalid, ignore it
        state = os.path.join(os.path.expanduser("~"), ".local", "state")
    return os.path.join(state, "stylize3d", "crash-logs")


def _program_name(program: str) -> str:
    clean = "".join(c if c.isascii() and (c.isalnum() or c == "-") else "-"
                    for c in program.lower())
    return clean.strip("-")[:40] or "stylize3d"


def parse_name(name: str) -> dict | None:
    """``{"stamp", "program", "pid", "error", "seen"}`` of a crash-log file name, or None."""
    if not name.endswith(".log"):
        return None
    stem = name[:-4]
    seen = stem.endswith(".seen")
    stem = stem[:-5] if seen else stem
    error = stem.endswith("_error")
    stem = stem[:-6] if error else stem
    parts = stem.split("_")
    if len(parts) < 3 or not parts[-1].isdigit():
        return None
    return {"stamp": parts[0], "program": "_".join(parts[1:-1]), "pid": int(parts[-1]),
            "error": error, "seen": seen}


def _quote(arg: str) -> str:
    safe = arg and all(c.isalnum() or c in "-_./=:,+@%" for c in arg)
    return arg if safe else "'" + arg.replace("'", "'\\''") + "'"


def _one_line(text: str) -> str:
    """A header line stays one line (a file name may hold a newline)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def command_line(argv: list[str] | None = None) -> str:
    """``stylize3d`` and the arguments of this process's command line (cut to 4,000 chars)."""
    args = list(sys.argv[1:] if argv is None else argv)
    text = " ".join(_quote(a) for a in ["stylize3d", *args])
    return text if len(text) <= _MAX_COMMAND else text[:_MAX_COMMAND] + " …"


def versions(cheap: bool = True) -> str:
    """``stylize3d 0.1.0, numpy 2.4.6, ...``: the package and the compiled libraries. ``cheap``:
    only the libraries already imported (their ``__version__``; no file is read), and the
    package's own version only when it was looked up already; otherwise everything, from the
    installed packages' metadata (after a crash, when time does not matter)."""
    names = {"numpy": "numpy", "scipy": "scipy", "numba": "numba", "torch": "torch",
             "vtk": "vtk", "PySide6": "pyside6-essentials", "pyvista": "pyvista",
             "igl": "libigl", "onnxruntime": "onnxruntime"}
    out = []
    app = sys.modules.get("app")
    own = getattr(app, "__dict__", {}).get("__version__") if app is not None else None
    if own is None and not cheap:
        try:
            from importlib import metadata

            own = metadata.version("stylize3d")
        except Exception:  # noqa: BLE001 - a source tree that is not installed
            own = None
    out.append(f"stylize3d {own or '(version not looked up)'}")
    for module, dist in names.items():
        version = None
        mod = sys.modules.get(module)
        if mod is not None:
            version = getattr(mod, "__version__", None)
        if version is None and not cheap:
            try:
                from importlib import metadata

                version = metadata.version(dist)
            except Exception:  # noqa: BLE001 - not installed
                continue
        if version is not None:
            out.append(f"{module} {version}")
    u = os.uname() if hasattr(os, "uname") else None
    system = f"{u.sysname} {u.release} {u.machine}" if u else sys.platform
    return f"Python {sys.version.split()[0]} on {system}; " + ", ".join(out)


def _header(program: str, argv: list[str] | None, note: str = "", cheap: bool = True) -> str:
    what = {"app": "the Stylize3D app", "batch-worker": "a batch worker process"}.get(
        program, f"the command 'stylize3d {program[4:]}'" if program.startswith("cli-")
        else program)
    lines = [f"# Stylize3D crash log of {what} ({program})",
             f"# started {time.strftime('%Y-%m-%d %H:%M:%S %z')}, pid {os.getpid()}"
             + (f" {note}" if note else ""),
             f"# command: {command_line(argv)}",
             f"# {versions(cheap)}",
             "# The process removes this file when it ends normally; if it is still here with "
             "nothing below this header, the process was killed (SIGKILL, SIGTERM).",
             ]
    return "\n".join(_one_line(x) for x in lines) + "\n" + _HEADER_END


def _create(program: str, suffix: str = "") -> tuple[str, int]:
    """A new crash-log file (mode 0600) and its descriptor (append mode, not inheritable)."""
    folder = crash_dir()
    os.makedirs(folder, mode=0o700, exist_ok=True)
    base = f"{time.strftime('%Y%m%d-%H%M%S')}_{_program_name(program)}_{os.getpid()}"
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND | getattr(os, "O_CLOEXEC", 0)
    for k in range(100):
        name = base if k == 0 else f"{base}-{k}"  # a second file in the same second
        path = os.path.join(folder, f"{name}{suffix}.log")
        try:
            return path, os.open(path, flags, 0o600)
        except FileExistsError:
            continue
    raise FileExistsError(path)


def _write(fd: int, text: str) -> None:
    data = text.encode("utf-8", "replace")
    while data:
        data = data[os.write(fd, data):]


def has_crash_text(text: str | bytes) -> bool:
    """Whether a crash log's text holds more than header lines (which start with ``#``)."""
    data = text.encode("utf-8", "replace") if isinstance(text, str) else text
    return any(line.strip() and not line.startswith(b"#") for line in data.splitlines())


def has_crash(path) -> bool:
    """Whether a crash log holds more than its header (a crash's stacks or a Python error)."""
    try:
        with open(path, "rb") as fh:
            return has_crash_text(fh.read(1 << 20))
    except OSError:
        return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def prune() -> int:
    """Remove header-only crash logs of processes that are gone (killed; nothing happened to
    report). Returns how many were removed."""
    folder = crash_dir()
    try:
        names = os.listdir(folder)
    except OSError:
        return 0
    removed = 0
    for name in names:
        info = parse_name(name)
        if info is None or info["error"] or info["seen"] or info["pid"] == os.getpid():
            continue
        path = os.path.join(folder, name)
        if _alive(info["pid"]) or has_crash(path):
            continue
        try:
            os.unlink(path)
            removed += 1
        except OSError:
            pass
    return removed


# ----------------------------------------------------------------------------- one process
def current_log() -> str | None:
    """This process's crash-log file (None when none is installed)."""
    return _state["path"] if _state["pid"] == os.getpid() else None


def program() -> str | None:
    return _state["program"] if _state["pid"] == os.getpid() else None


def install(name: str, argv: list[str] | None = None, *,
            versions_now: bool = True) -> str | None:
    """Crash-log this process as program ``name`` (``app``, ``batch-worker``, ``cli-cubic``;
    module docstring): create its file with the header, point faulthandler at it (every
    thread), remove the file at a normal exit, prune. Returns the file's path (None if the
    folder cannot be written: nothing is installed then). Calling it again returns the same
    path."""
    if current_log() is not None:
        return _state["path"]
    import faulthandler

    if versions_now and "app" in sys.modules:
        try:  # the package's version for the header (importlib.metadata, ~40 ms; not for
            # a command: its supervisor adds the versions after a crash)
            sys.modules["app"].__version__
        except Exception:  # noqa: BLE001
            pass
    try:
        path, fd = _create(name)
        _write(fd, _header(name, argv))
    except OSError:
        return None
    faulthandler.enable(file=fd, all_threads=True)
    _state.update(path=path, fd=fd, program=_program_name(name), pid=os.getpid(), owner=True)
    import atexit

    atexit.register(_at_exit)
    prune()
    return path


def discard() -> None:
    """This process ends normally (without atexit, e.g. before ``os._exit``): stop writing
    to its crash log and remove it (its supervisor removes a supervised command's)."""
    if current_log() is None:
        return
    import faulthandler

    try:
        faulthandler.disable()
    except Exception:  # noqa: BLE001
        pass
    if _state["owner"]:
        try:
            os.unlink(_state["path"])
        except OSError:
            pass
        try:
            os.close(_state["fd"])
        except OSError:
            pass
    _state.update(path=None, fd=None, pid=None, owner=False)


def _at_exit() -> None:
    if current_log() is not None:  # not in a forked child that inherited the handler
        discard()


def write_error_log(text: str, program_name: str | None = None) -> str | None:
    """Keep a Python traceback that was caught (a defect of ours, exit status 70) in the crash
    folder as ``..._<pid>_error.log`` with the header; its path, or None when nothing could be
    written anywhere (a temporary file is the fallback)."""
    name = program_name or program() or "stylize3d"
    try:
        path, fd = _create(name, "_error")
    except OSError:
        import tempfile

        try:
            fd, path = tempfile.mkstemp(prefix="stylize3d-crash-", suffix=".txt")
        except OSError:
            return None
    try:
        _write(fd, _header(name, None) + text)
    except OSError:
        pass
    finally:
        os.close(fd)
    return path


# ----------------------------------------------------------------------------- the app
def unseen_crashes(program_name: str = "app") -> list[str]:
    """Crash logs of ``program_name`` with a crash in them, not yet shown, newest first."""
    folder = crash_dir()
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    found = []
    for name in names:
        info = parse_name(name)
        if (info is None or info["seen"] or info["error"] or info["program"] != program_name
                or info["pid"] == os.getpid()):
            continue
        path = os.path.join(folder, name)
        if has_crash(path):
            try:
                found.append((os.path.getmtime(path), path))
            except OSError:
                continue
    return [p for _t, p in sorted(found, reverse=True)]


def mark_seen(path: str) -> str | None:
    """Rename ``X.log`` to ``X.seen.log`` (shown once); the new path, or None if another
    process took it first."""
    new = path[:-4] + ".seen.log"
    try:
        os.rename(path, new)
    except OSError:
        return None
    return new


def announce_last_crash(report, show=None) -> str | None:
    """At the app's start: if the app died (crashed) last time, call ``report(text)`` (and
    ``show()``, e.g. open the Messages panel) once with "Stylize3D stopped unexpectedly last
    time. The details are in PATH." and mark every such log as shown. Returns the path shown,
    or None."""
    shown = [p for p in (mark_seen(p) for p in unseen_crashes("app")) if p]
    if not shown:
        return None
    more = (f" ({len(shown) - 1} earlier crash log(s) are in the same folder.)"
            if len(shown) > 1 else "")
    report(f"Stylize3D stopped unexpectedly last time. The details are in {shown[0]}. "
           f"Please include that file in a bug report.{more}")
    if show is not None:
        show()
    return shown[0]


# ----------------------------------------------------------------------------- commands
_LAST_SAID: list = [None]


def say(text: str) -> None:
    """Print a message to stderr; a closed stderr is not worth a traceback (the CLI's
    ``app.cli.common.say`` is this function). The last message is kept (:func:`last_said`)."""
    _LAST_SAID[0] = text
    try:
        print(text, file=sys.stderr)
        sys.stderr.flush()
    except (OSError, ValueError, AttributeError):
        pass


def last_said(reset: bool = False) -> str | None:
    """The last message :func:`say` printed in this process (None after ``reset``)."""
    text = _LAST_SAID[0]
    if reset:
        _LAST_SAID[0] = None
    return text


def _suffix(word: str) -> str:
    """``pathlib.PurePath(word).suffix`` without importing pathlib."""
    name = os.path.basename(word)
    i = name.rfind(".")
    return name[i:] if 0 < i < len(name) - 1 else ""


def runs_a_command(argv: list[str]) -> bool:
    """Whether ``stylize3d ARGV`` runs a sub-command (or says a mistyped one), not the app:
    the first argument is a bare word (the rule of :func:`app.cli.unknown_command`)."""
    word = argv[0] if argv else ""
    if not word or word.startswith("-") or "/" in word or os.sep in word or _suffix(word):
        return False
    if not os.path.exists(word):
        return True
    from app.cli import SUBCOMMANDS  # a file named like a command: the command wins

    return word in SUBCOMMANDS


def can_supervise() -> bool:
    return (sys.platform.startswith("linux") and hasattr(signal, "sigtimedwait")
            and hasattr(os, "posix_spawn")
            and os.environ.get(SUPERVISE_VARIABLE, "1").strip().lower() not in
            ("0", "no", "off", "false"))


def entry(argv: list[str]) -> int | None:
    """At ``stylize3d``'s process entry (``app.__main__.main()`` without arguments): adopt the
    supervisor's crash log (the child), or run a sub-command under a supervisor (its exit
    status), or crash-log it here; None: go on with ``argv`` in this process."""
    if adopt():
        return None
    if not runs_a_command(argv):
        return None  # the app: app.gui.run_app installs
    program_name = f"cli-{argv[0]}"
    if can_supervise():
        code = supervise(argv, program_name)
        if code is not None:
            return code
    install(program_name, argv, versions_now=False)
    return None


def _die_with_parent() -> None:
    """Ask the kernel to kill this process when its parent (the supervisor) dies."""
    try:
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    except Exception:  # noqa: BLE001 - no prctl: the command outlives a killed supervisor
        pass


def adopt() -> bool:
    """In a supervised command (the child): take the crash-log descriptor the supervisor
    handed down, point faulthandler at it, add this pid to its header. False if this process
    is not a supervised command."""
    value = os.environ.pop(_CHILD_VARIABLE, None)  # not for the processes this one starts
    if not value:
        return False
    try:
        fd_text, parent_text, program_name, path = value.split(":", 3)
        fd, parent = int(fd_text), int(parent_text)
    except ValueError:
        return False
    _die_with_parent()
    if os.getppid() != parent:  # the supervisor died before PR_SET_PDEATHSIG took effect
        os._exit(1)
    import faulthandler

    try:
        os.set_inheritable(fd, False)
        faulthandler.enable(file=fd, all_threads=True)
        _write(fd, f"# the command runs in pid {os.getpid()} (its supervisor is pid {parent})\n")
    except (OSError, ValueError):
        return True  # no crash log, but the command runs (its supervisor still says a crash)
    _state.update(path=path, fd=fd, program=program_name, pid=os.getpid(), owner=False)
    prune()
    return True


def _child_command(argv: list[str]) -> list[str]:
    if getattr(sys, "frozen", False):  # the PyInstaller bundle: the binary is the entry point
        return [sys.executable, *argv]
    flags: list[str] = []
    f = sys.flags
    if (sys.warnoptions or getattr(sys, "_xoptions", None) or f.optimize or f.isolated
            or f.dont_write_bytecode or f.no_user_site or f.ignore_environment
            or getattr(f, "safe_path", False) or f.bytes_warning or f.verbose):
        from subprocess import _args_from_interpreter_flags

        flags = _args_from_interpreter_flags()
    # the child finds `app` where this process did: `-c` would put the current folder first
    # (a user's own `app` package there must not shadow ours)
    first = "" if getattr(f, "safe_path", False) else f"sys.path[0] = {sys.path[0]!r}; "
    code = f"import sys; {first}from app.__main__ import main; sys.exit(main())"
    return [sys.executable, *flags, "-c", code, *argv]


def supervise(argv: list[str], program_name: str) -> int | None:
    """Run ``stylize3d ARGV`` in a child process and wait (module docstring); its exit status,
    or None when no child could be started (run it here then)."""
    try:
        path, fd = _create(program_name)
        _write(fd, _header(program_name, argv, "(the supervisor; the command runs in a child "
                                               "process)", cheap=True))
    except OSError:
        return None
    waited = set(_FORWARDED) | {signal.SIGCHLD}
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, waited)
    try:
        os.set_inheritable(fd, True)
        env = dict(os.environ)
        env[_CHILD_VARIABLE] = f"{fd}:{os.getpid()}:{program_name}:{path}"
        cmd = _child_command(argv)
        pid = os.posix_spawn(cmd[0], cmd, env, setsigmask=old_mask)
    except OSError:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        os.close(fd)
        _unlink(path)
        return None
    os.close(fd)  # the child holds it
    status = _wait(pid)
    code = os.waitstatus_to_exitcode(status)
    if code >= 0:
        _unlink(path)
        return code
    sig = -code
    command = program_name[4:] if program_name.startswith("cli-") else program_name
    # the command may have died in the middle of a progress line: the message starts a line
    if sig in FATAL_SIGNALS:
        _after_crash(path, sig)
        say(f"\nstylize3d {command} crashed ({FATAL_SIGNALS[sig]}); the details are in {path}. "
             "Your input files are unchanged. This is a bug in Stylize3D or a library it "
             "uses: please report it with that file.")
        return INTERNAL_ERROR_EXIT
    _unlink(path)
    if sig == signal.SIGKILL:
        say(f"\nstylize3d {command} was killed (SIGKILL) before it finished; nothing more was "
             "written. If nobody stopped it, the system ran out of memory: try a smaller mesh "
             "(decimate it first) or the options for big meshes.")
        return INTERNAL_ERROR_EXIT
    # SIGINT, SIGTERM, SIGHUP, ...: end the same way, as if there were no supervisor
    signal.signal(sig, signal.SIG_DFL)
    os.kill(os.getpid(), sig)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {sig})
    return 128 + sig  # the signal is ignored here (e.g. SIGHUP under nohup)


def _wait(pid: int) -> int:
    """Wait for the child, forwarding the signals sent to this process (module docstring).
    The signals are blocked: they wait in ``sigtimedwait``, none is lost between two looks."""
    waited = set(_FORWARDED) | {signal.SIGCHLD}
    while True:
        info = signal.sigtimedwait(waited, 5.0)
        if info is not None and info.si_signo != signal.SIGCHLD and info.si_code != _SI_KERNEL:
            try:
                os.kill(pid, info.si_signo)
            except ProcessLookupError:
                pass
        try:
            done, status = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:  # someone else reaped it (cannot happen here)
            return 0
        if done:
            return status


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _after_crash(path: str, sig: int) -> None:
    """The supervisor's lines under a crashed command's stacks."""
    stacks = False
    try:
        with open(path, "rb") as fh:
            stacks = FAULT_MARK.encode() in fh.read()
    except OSError:
        pass
    lines = [""]
    if not stacks:
        lines.append("(The command died before it could write its Python stacks.)")
    lines.append(f"The command died of signal {signal.Signals(sig).name} ({FATAL_SIGNALS[sig]}) "
                 f"at {time.strftime('%Y-%m-%d %H:%M:%S %z')}; its supervisor (pid "
                 f"{os.getpid()}) exited with status {INTERNAL_ERROR_EXIT}.")
    lines.append(f"Versions: {versions(cheap=False)}")
    try:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")
    except OSError:
        pass


__all__ = ["DIR_VARIABLE", "FATAL_SIGNALS", "SUPERVISE_VARIABLE", "adopt", "announce_last_crash",
           "can_supervise", "crash_dir", "current_log", "discard", "entry", "has_crash",
           "has_crash_text",
           "install", "mark_seen", "parse_name", "program", "prune", "runs_a_command",
           "supervise", "unseen_crashes", "versions", "write_error_log"]
