"""packaging/ stays well-formed (fast; the build itself is packaging/build.sh, minutes, not a test).

The spec is Python that PyInstaller executes: it must parse, ship resources/ whole, name the
entry script, hooks folder and the VTK back-ends pyvista loads by side effect. The .desktop entry
follows the Desktop Entry Specification's basic rules; the icon is a square PNG; the pins of the
packaging extra are exact and not part of the default install.
"""

from __future__ import annotations

import ast
import configparser
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "packaging"


def test_spec_parses_and_names_what_the_bundle_needs():
    src = (PKG / "stylize3d.spec").read_text()
    tree = ast.parse(src, filename="stylize3d.spec")
    calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call)
             and isinstance(n.func, ast.Name)}
    assert {"Analysis", "PYZ", "EXE", "COLLECT"} <= calls
    assert '"resources"), "resources")' in src  # resources/ shipped whole, same relative place
    for hidden in ("vtkmodules.vtkRenderingOpenGL2", "vtkmodules.vtkInteractionStyle",
                   "vtkmodules.vtkRenderingFreeType"):
        assert f'"{hidden}"' in src
    assert (PKG / "entry.py").is_file() and '"entry.py"' in src
    assert (PKG / "hooks").is_dir() and '"hooks"' in src
    for hook in (PKG / "hooks").glob("hook-*.py"):
        ast.parse(hook.read_text(), filename=str(hook))
    ast.parse((PKG / "entry.py").read_text())


def test_desktop_entry_is_well_formed():
    text = (PKG / "stylize3d.desktop").read_text()
    assert text.startswith("[Desktop Entry]\n")
    cp = configparser.ConfigParser(interpolation=None, strict=True)
    cp.optionxform = str  # keys are case-sensitive
    cp.read_string(text)
    entry = cp["Desktop Entry"]
    for key in ("Type", "Name", "Exec", "Icon"):
        assert entry.get(key), key
    assert entry["Type"] == "Application"
    assert entry["Exec"].split()[0] == "stylize3d"
    assert re.fullmatch(r"%[fFuU]", entry["Exec"].split()[1])
    assert entry["Icon"] == "stylize3d" and (PKG / "stylize3d.png").is_file()
    for key in ("Categories", "MimeType", "Keywords"):  # lists end with ';'
        assert entry[key].endswith(";"), key
    assert entry["Terminal"] in ("true", "false")
    assert all(re.fullmatch(r"[A-Za-z0-9-]+(\[[^\]]+\])?", k) for k in entry)


def test_desktop_entry_passes_desktop_file_validate():
    if shutil.which("desktop-file-validate") is None:
        pytest.skip("desktop-file-validate is not installed (Debian: desktop-file-utils)")
    out = subprocess.run(["desktop-file-validate", str(PKG / "stylize3d.desktop")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "error" not in out.stdout, out.stdout + out.stderr


def test_icon_is_a_square_png():
    with Image.open(PKG / "stylize3d.png") as im:
        assert im.format == "PNG" and im.size == (256, 256) and im.mode == "RGBA"
        alpha = im.getchannel("A")
        assert alpha.getextrema() == (0, 255)  # transparent background, opaque shape


def test_packaging_extra_is_pinned_and_optional():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extra = meta["optional-dependencies"]["packaging"]
    assert all(re.fullmatch(r"[A-Za-z0-9_.-]+==[0-9][0-9A-Za-z.]*", r) for r in extra), extra
    assert {r.split("==")[0] for r in extra} == {"pyinstaller", "pyinstaller-hooks-contrib"}
    assert not any(d.lower().startswith("pyinstaller") for d in meta["dependencies"])


def test_build_script_is_valid_bash():
    out = subprocess.run(["bash", "-n", str(PKG / "build.sh")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_smoke_test_imports_without_a_build():
    out = subprocess.run([sys.executable, str(PKG / "smoke_test.py"), "--help"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "bundle" in out.stdout, out.stderr
