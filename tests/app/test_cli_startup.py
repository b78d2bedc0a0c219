"""Start-up of ``stylize3d info`` (issue 25): a sub-command imports only its own module, and
``info`` imports none of the heavy libraries (checked in a fresh interpreter; never timed)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "tests" / "data" / "spot_lowres.obj"

_PROBE = """
import json, sys
from app.__main__ import main
code = main(sys.argv[1:])
sys.stdout.flush()
print("\\n@@MODULES@@" + json.dumps(sorted(sys.modules)))
sys.exit(code)
"""


def _modules_after(*argv: str) -> tuple[int, set[str]]:
    out = subprocess.run([sys.executable, "-c", _PROBE, *argv], capture_output=True,
                         text=True, cwd=ROOT, timeout=120)
    assert "@@MODULES@@" in out.stdout, out.stderr
    return out.returncode, set(json.loads(out.stdout.split("@@MODULES@@")[1]))


def test_command_table_matches_the_modules():
    from app import cli

    for name, commands in cli.COMMAND_MODULES.items():
        module = cli.command_module(commands[0])
        assert module.__name__ == f"app.cli.{name}"
        assert tuple(module.COMMANDS) == commands
    # the full parser still knows every sub-command
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == set(cli.SUBCOMMANDS)


def test_info_imports_only_what_it_uses():
    code, mods = _modules_after("info", str(MESH))
    assert code == 0
    heavy = ("torch", "numba", "pyvista", "vtk", "PySide6", "pyamg", "skimage", "igl")
    assert not [m for m in mods if m.split(".")[0] in heavy]
    # no other sub-command's module nor the methods it would pull in
    others = [f"app.cli.{m}" for m in ("deform", "smooth", "spectral", "paparazzi",
                                        "adversary", "subdivision", "batch", "study")]
    assert not mods & set(others)
    assert not [m for m in mods if m.startswith(("algorithms.deform", "algorithms.paparazzi",
                                                 "algorithms.smoothing", "algorithms.spectral",
                                                 "algorithms.subdivision", "app.batch",
                                                 "app.recipes", "scipy.spatial",
                                                 "scipy.optimize"))]


def test_info_does_not_import_scipy_or_importlib_metadata():
    """Reading and checking a mesh needs NumPy only (connected components in NumPy,
    algorithms.mesh loads its SciPy-using submodules on first use, app.__version__ is looked up
    when asked)."""
    code, mods = _modules_after("info", str(MESH))
    assert code == 0
    assert not [m for m in mods if m == "scipy" or m.startswith("scipy.")]
    assert "importlib.metadata" not in mods


def test_cubic_help_builds_only_its_module():
    code, mods = _modules_after("cubic", "--help")
    assert code == 0
    assert "app.cli.deform" in mods
    assert "app.cli.paparazzi" not in mods and "app.cli.subdivision" not in mods
