"""House rules that must not erode: algorithms/ imports no Qt, VTK or app; batch CLI imports no Qt."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = ("PySide6", "PyQt5", "PyQt6", "qtpy", "pyvistaqt", "pyvista", "vtk", "vtkmodules", "app")


def test_algorithms_source_has_no_forbidden_imports():
    bad = []
    for path in (ROOT / "algorithms").rglob("*.py"):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            bad += [f"{path.relative_to(ROOT)}: {n}" for n in names if n.split(".")[0] in FORBIDDEN]
    assert not bad, bad


def _modules_loaded_by(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint('\\n'.join(sys.modules))"],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return {m.split(".")[0] for m in out.stdout.split()}


def test_importing_every_algorithm_module_loads_no_gui():
    mods = sorted(".".join(p.relative_to(ROOT).with_suffix("").parts)
                  for p in (ROOT / "algorithms").rglob("*.py") if p.name != "__init__.py")
    loaded = _modules_loaded_by("\n".join(f"import {m}" for m in mods))
    assert not loaded & {"PySide6", "vtkmodules", "vtk", "pyvista", "pyvistaqt", "app"}


def test_batch_cli_loads_no_qt(tmp_path):
    from algorithms.mesh import icosphere, write_mesh

    V, F = icosphere(1)
    write_mesh(tmp_path / "s.obj", V, F)
    code = (f"from app.__main__ import main\n"
            f"rc = main(['info', {str(tmp_path / 's.obj')!r}])\n"
            f"rc2 = main(['smooth', {str(tmp_path / 's.obj')!r}, '-o', {str(tmp_path / 'o.obj')!r}, '--iterations', '2', '--quiet'])\n"
            f"assert rc == 0 and rc2 == 0, (rc, rc2)")
    loaded = _modules_loaded_by(code)
    assert not loaded & {"PySide6", "vtkmodules", "vtk", "pyvista", "pyvistaqt"}
    assert (tmp_path / "o.obj").exists()
