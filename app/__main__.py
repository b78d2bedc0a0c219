"""``stylize3d`` / ``python -m app``: the GUI with no sub-command, batch sub-commands otherwise.

Batch sub-commands never import Qt or VTK (tests enforce it); the GUI modules are imported only
when the window is opened. A first argument that is neither a sub-command nor something the app
can open (an existing file, a name with an extension, a path, an option) is a mistyped command:
``stylize3d cubc x`` says "unknown command 'cubc'. Did you mean 'cubic'?" and exits with 2.

``main()`` without arguments is the process's entry point (the ``stylize3d`` script, ``python -m
app``): a sub-command then runs under the crash supervisor of :mod:`app.crashlog` (a segfault is
a plain sentence, a crash log and exit status 70). ``main(ARGV)`` runs in the calling process and
installs nothing (tests, scripts).
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    entry = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    if entry:
        from app import crashlog

        code = crashlog.entry(argv)
        if code is not None:  # the supervisor: the command ran in its child process
            return code
    from app import cli

    if argv and argv[0] in cli.SUBCOMMANDS:
        if entry:  # the process is the command: SIGTERM stops it like Ctrl+C (exit 143)
            from app.cli.common import stop_on_sigterm

            stop_on_sigterm()
        return cli.main(argv)
    if argv:
        message = cli.unknown_command(argv[0])
        if message is not None:
            print(message, file=sys.stderr)
            return 2
    return cli.gui_main(argv)


if __name__ == "__main__":
    import multiprocessing

    # child processes (algorithms.steps.isolated_iter) of a frozen (PyInstaller) app
    multiprocessing.freeze_support()
    sys.exit(main())
