"""``stylize3d`` / ``python -m app``: the GUI with no sub-command, batch sub-commands otherwise.

Batch sub-commands never import Qt or VTK (tests enforce it); the GUI modules are imported only
when the window is opened. A first argument that is neither a sub-command nor something the app
can open (an existing file, a name with an extension, a path, an option) is a mistyped command:
``stylize3d cubc x`` says "unknown command 'cubc'. Did you mean 'cubic'?" and exits with 2.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    from app import cli

    if argv and argv[0] in cli.SUBCOMMANDS:
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
