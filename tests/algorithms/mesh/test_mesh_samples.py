"""Tests for the shipped samples, the samples module and the package surface."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import algorithms.mesh as mesh
from algorithms.errors import MeshReadError, ParameterError
from algorithms.mesh import samples
from algorithms.mesh.operators import signed_volume
from algorithms.mesh.primitives import ORGANIC_SAMPLES

REPO = Path(__file__).resolve().parents[3]


def test_samples_dir_is_in_repo():
    assert samples.SAMPLES_DIR == REPO / "resources" / "samples"
    assert samples.SAMPLES_DIR.is_dir()
    assert set(samples.SAMPLE_NAMES) <= set(samples.available_samples())
    assert samples.DEFAULT_SAMPLE == "blob"


@pytest.mark.parametrize("name,g", sorted(ORGANIC_SAMPLES.items()))
def test_shipped_samples_are_clean(name, g):
    path = samples.sample_path(name)
    assert path == samples.SAMPLES_DIR / f"{name}.obj"
    assert path.stat().st_size < 600_000
    m = mesh.read_mesh(path)
    assert 2000 <= m.V.shape[0] <= 6000 and m.notes == []
    r = mesh.validate_mesh(m.V, m.F)
    assert r.ok and not r.warnings, r.summary()
    assert r.stats["closed"] and r.stats["genus"] == g and r.stats["components"] == 1
    assert signed_volume(m.V, m.F) > 0
    assert (m.V.max(axis=0) - m.V.min(axis=0)).max() == pytest.approx(1.0, abs=2e-6)


def test_sample_path_default_and_errors(tmp_path, monkeypatch):
    assert samples.sample_path() == samples.SAMPLES_DIR / "blob.obj"
    assert samples.sample_path("Blob.obj") == samples.SAMPLES_DIR / "blob.obj"
    with pytest.raises(ParameterError, match="no sample called 'teapot'"):
        samples.sample_path("teapot")
    monkeypatch.setattr(samples, "SAMPLES_DIR", tmp_path)
    with pytest.raises(MeshReadError, match="missing"):
        samples.sample_path("blob")
    assert samples.available_samples() == []


def test_make_samples_script_check_mode():
    out = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "make_samples.py"), "--check"],
        capture_output=True, text=True, timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert "blob.obj" in out.stdout


def test_package_reexports():
    for name in mesh.__all__:
        assert hasattr(mesh, name), name
    V, F = mesh.icosphere(1)
    assert mesh.validate_mesh(V, F).ok
    assert callable(mesh.operators.cotangent_laplacian)
    assert mesh.MeshData and mesh.MeshReport and mesh.MeshIssue and mesh.normalize_unit_box


def test_no_gui_imports():
    code = (
        "import sys, algorithms.mesh, algorithms.mesh.validate, algorithms.mesh.primitives;"
        "import algorithms.mesh.subdivision, algorithms.mesh.samples;"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('PySide6', 'PyQt5', 'PyQt6', 'shiboken6', 'vtk', 'vtkmodules', 'pyvista', 'pyvistaqt', 'app'));"
        "print(bad); sys.exit(1 if bad else 0)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
