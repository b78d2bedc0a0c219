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


# -------------------------------------------------------------------- recipes and panels (issue 20)
#: what a panel may import from algorithms/: parameters, errors, the Step type and file IO.
#: Everything a Run computes is a recipe's (app/recipes/); a view's computation is a Qt-free
#: function in the panel's recipe module.
PANEL_ALLOWED_MODULES = ("algorithms.errors", "algorithms.params", "algorithms.mesh.io",
                         "algorithms.mesh.fields")
PANEL_ALLOWED_NAMES = {"Step", "read_mesh", "write_mesh", "file_filter", "SUPPORTED_READ",
                       "SUPPORTED_WRITE", "read_field", "write_field", "field_file_filter",
                       "FIELD_EXTENSIONS", "read_image", "ImageReadError", "read_mesh_colors",
                       "read_lighting", "write_lighting", "filter_names", "describe", "param",
                       "save_weights", "load_weights"}


def _panel_algorithm_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            bad += [a.name for a in node.names if a.name.split(".")[0] == "algorithms"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "algorithms":
            if node.module in PANEL_ALLOWED_MODULES:
                continue
            for a in node.names:
                ok = (a.name.endswith("Params") or a.name.isupper() or a.name.endswith("Error")
                      or a.name in PANEL_ALLOWED_NAMES)
                if not ok:
                    bad.append(f"{node.module}.{a.name}")
    return bad


def test_panels_hold_no_numerical_code():
    bad = {}
    for path in sorted((ROOT / "app" / "panels").glob("*.py")):
        found = _panel_algorithm_imports(path)
        if found:
            bad[path.name] = found
    assert not bad, ("panels import numerical code; move it into their recipe module "
                     f"(app/recipes/): {bad}")


def test_every_panel_has_a_recipe_and_the_registry_lists_them_all():
    loaded = _modules_loaded_by("from app.recipes import recipes\n"
                                "print('\\n'.join(sorted(recipes())))")
    assert not loaded & {"PySide6", "vtkmodules", "pyvista"}  # recipes are Qt-free
    from app.panels import PANELS
    from app.recipes import recipes

    modules = {p.stem for p in (ROOT / "app" / "panels").glob("*.py")} - {"__init__", "base"}
    assert modules == {e.split(":")[0] for e in PANELS}
    src = (ROOT / "app" / "main_window.py").read_text()
    for m in modules:
        assert f"app.panels.{m}" not in src  # the window does not list panels by hand
    titles = set()
    for entry in PANELS:
        module, cls = entry.split(":")
        tree = ast.parse((ROOT / "app" / "panels" / f"{module}.py").read_text())
        node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls)
        for stmt in node.body:
            if isinstance(stmt, ast.Assign) and any(getattr(t, "id", "") == "title"
                                                    for t in stmt.targets):
                titles.add(stmt.value.value)
    assert len(titles) == len(PANELS)
    assert titles <= set(recipes()), sorted(titles - set(recipes()))


def test_cli_is_a_package_of_small_modules():
    assert not (ROOT / "app" / "cli.py").exists()
    sizes = {p.name: len(p.read_text().splitlines()) for p in (ROOT / "app" / "cli").glob("*.py")}
    assert sizes and max(sizes.values()) <= 400, sizes
