"""Timing helper shared by the benchmarks."""

from __future__ import annotations

import statistics
import time


def bumpy20k():
    """The procedural 20,000-vertex benchmark mesh: organic_sample("bumpy") after one Loop
    subdivision (23,714 vertices), QSlim-decimated to exactly 20,000 vertices (39,996
    triangles, closed, genus 0; about 0.5 s). Issue 25's "per iteration at 20k vertices"."""
    from algorithms.mesh import loop_subdivide, organic_sample
    from algorithms.mesh.decimate import decimate

    V, F = loop_subdivide(*organic_sample("bumpy"), 1)
    d = decimate(V, F, 2 * 20000 - 4)
    return d.V, d.F


def median_seconds(fn, repeat: int) -> float:
    """Median wall time of ``repeat`` calls of ``fn()``."""
    ts = []
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def mesh_path(name: str):
    """Where a benchmark finds a real mesh: tests/data/ (the small ones, in the repository), then
    ``$STYLIZE3D_MESHES`` (the big ones: stanford-bunny, koala, igea), then ``../shared/meshes``
    beside the checkout. Returns a Path (which may not exist: callers say so and skip)."""
    import os
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    folders = [root / "tests" / "data"]
    if os.environ.get("STYLIZE3D_MESHES"):
        folders.append(Path(os.environ["STYLIZE3D_MESHES"]))
    folders.append(root.parent / "shared" / "meshes")
    for folder in folders:
        if (folder / name).exists():
            return folder / name
    return folders[-1] / name
