"""Shared fixtures: paths to the test meshes, bad input files, and the GUI harness.

Real meshes: the small ones live in ``tests/data/`` (with their licence lines in
``tests/data/SOURCES.md``), so a fresh clone runs the whole suite. The big ones (koala, igea,
stanford-bunny) stay outside the repository; the few tests that use them look in
``$STYLIZE3D_MESHES`` or ``../shared/meshes`` and skip, saying so, where they are absent.

GUI tests need an X display for the VTK viewport. ``scripts/setup.sh test`` runs pytest with the
pytest-xvfb plugin, which starts a virtual X server; where none can be started the viewport tests
skip and say why, and Qt falls back to the offscreen platform for the widget-only tests.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# CI runs are reproducible: hypothesis draws the same examples every time there (locally it keeps
# exploring new ones and remembers failures in .hypothesis/).
settings.register_profile("ci", derandomize=True, database=None, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]
TEST_DATA = ROOT / "tests" / "data"
SHARED_MESHES = Path(os.environ.get("STYLIZE3D_MESHES", ROOT.parent / "shared" / "meshes"))
SAMPLES = ROOT / "resources" / "samples"


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    # pytest-xvfb has set DISPLAY by now when it could start Xvfb.
    if not os.environ.get("DISPLAY"):
        os.environ["QT_QPA_PLATFORM"] = "offscreen"


@pytest.fixture(autouse=True)
def _private_recovery_dir(monkeypatch, tmp_path_factory):
    """Autosave (app/autosave.py) writes to an empty folder of each test's own, never to the
    user's recovery folder; with nothing in it, no window offers a recovery."""
    monkeypatch.setenv("STYLIZE3D_RECOVERY_DIR", str(tmp_path_factory.mktemp("recovery")))


@pytest.fixture(autouse=True, scope="session")
def _crash_logs_in_a_temporary_folder(tmp_path_factory):
    """Crash logs of the commands and apps the tests run (app/crashlog.py) go to a temporary
    folder, never the user's; a test that looks at them sets its own."""
    mp = pytest.MonkeyPatch()
    mp.setenv("STYLIZE3D_CRASH_DIR", str(tmp_path_factory.mktemp("crash-logs")))
    yield
    mp.undo()


def find_mesh(name: str) -> Path | None:
    """Path of a real test mesh: ``tests/data/`` first, then the big-mesh folder; None if absent."""
    for folder in (TEST_DATA, SHARED_MESHES):
        p = folder / name
        if p.exists():
            return p
    return None


def shared_mesh(name: str) -> Path:
    """Path of a real test mesh, skipping the calling test when it is not there (big meshes only)."""
    p = find_mesh(name)
    if p is None:
        pytest.skip(f"big mesh {name} is not in the repository and not found in {SHARED_MESHES}")
    return p


def unit_square_grid(n: int):
    """An n x n grid of the unit square in the plane z = 0: (V (k, 3), F (m, 3))."""
    from algorithms.mesh import grid

    V, F = grid(n, n)
    V = np.asarray(V, float)
    if V.shape[1] == 2:
        V = np.c_[V, np.zeros(len(V))]
    lo, hi = V.min(0), V.max(0)
    V = (V - lo) / np.where(hi - lo > 0, hi - lo, 1.0)
    V[:, 2] = 0.0
    return V, np.asarray(F, np.int64)


def mobius_strip(n: int = 16):
    """An open Moebius strip (one-sided, non-orientable) of n quads: (V (2n, 3), F (2n, 3))."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.vstack([np.column_stack([(1 + w * np.cos(t / 2)) * np.cos(t),
                                    (1 + w * np.cos(t / 2)) * np.sin(t), w * np.sin(t / 2)])
                   for w in (-0.3, 0.3)])
    F = []
    for i in range(n):
        a, b = i, n + i
        c, d = (i + 1, n + i + 1) if i < n - 1 else (n, 0)  # the last quad closes with a twist
        F += [[a, c, b], [b, c, d]]
    return V, np.array(F, dtype=np.int64)


@contextmanager
def drift_filter(name: str, growth: float = 1000.0, **options):
    """A Paparazzi test filter (iterative) whose target drifts: its pull weakens over its first
    90 calls, so the monitor energy falls below its start, and grows again from call 400 by
    ``1 / growth`` per call, so the energy climbs back (above its start within 600 calls on
    ``icosphere(2)`` for growth 1000, not for 4000). Registered while inside; yields its state,
    ``{"calls", "growth"}`` (set ``calls`` to 0 before each run; ``growth`` may change)."""
    from algorithms.paparazzi import register_filter, unregister_filter

    state = {"calls": 0, "growth": float(growth)}

    @register_filter(name, kind="iterative", **{"learning_rate": 1e-4, **options})
    def drift(image, params, ctx):
        state["calls"] += 1
        k = state["calls"]
        c = max(0.02, 0.2 - k / 500) + max(0.0, (k - 400) / state["growth"])
        return image + c * (image - 0.5)

    try:
        yield state
    finally:
        unregister_filter(name)


@contextmanager
def runaway_filter(name: str, **options):
    """A Paparazzi test filter (iterative) that asks for ever more contrast around the picture's
    mean, at a large step: on the tests' bumpy spheres its monitor energy rises at every check,
    so a run never lowers it. Registered while inside."""
    from algorithms.paparazzi import register_filter, unregister_filter

    @register_filter(name, kind="iterative", **{"learning_rate": 1e-2, **options})
    def runaway(image, params, ctx):
        return image + 0.5 * (image - image.mean())

    try:
        yield name
    finally:
        unregister_filter(name)


@pytest.fixture
def bad_files(tmp_path) -> dict[str, Path]:
    """The bad inputs every entry point must survive, as files."""
    files = {}
    p = tmp_path / "empty.obj"
    p.write_text("")
    files["empty"] = p
    p = tmp_path / "garbage.obj"
    p.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    files["garbage"] = p
    p = tmp_path / "nan.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    files["nan"] = p
    p = tmp_path / "out_of_range.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 9\nf 2 4 3\n")
    files["out_of_range"] = p
    p = tmp_path / "nonmanifold.obj"
    # three triangles sharing the edge (1, 2)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0.5 1 0\nv 0.5 -1 0\nv 0.5 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n")
    files["nonmanifold"] = p
    p = tmp_path / "duplicates.obj"
    # a tetrahedron whose faces each have their own copies of the corners
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    tris = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    lines = []
    for t in tris:
        lines += [f"v {P[i][0]} {P[i][1]} {P[i][2]}" for i in t]
    lines += [f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}" for k in range(4)]
    p.write_text("\n".join(lines) + "\n")
    files["duplicates"] = p
    return files


def load_benchmark(name: str):
    """The module ``benchmarks/NAME.py`` (benchmarks are scripts, not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"{name}_bench",
                                                  ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
