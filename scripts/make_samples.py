#!/usr/bin/env python3
"""Regenerate the sample meshes shipped in resources/samples/.

Usage::

    python scripts/make_samples.py            # writes blob.obj, bumpy.obj, pretzel.obj, orange.obj
    python scripts/make_samples.py --check    # only validate the shipped files (no writing)

The shapes come from :func:`algorithms.mesh.primitives.organic_sample` (marching cubes of
implicit fields made by the project, so there are no third-party licence questions).
``orange.obj`` is :func:`algorithms.adversarial.shapes.orange` (procedural too) with its colours
as OBJ vertex colours (each vertex the mean of its faces' colours), so the Adversarial panel
starts from an object the classifier recognizes. Coordinates are rounded to 6 decimals to keep the files small; every file is validated after
writing (closed, manifold, outward, expected genus).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from algorithms.mesh.io import read_mesh, write_mesh  # noqa: E402
from algorithms.mesh.operators import signed_volume  # noqa: E402
from algorithms.mesh.primitives import ORGANIC_SAMPLES, organic_sample  # noqa: E402
from algorithms.mesh.samples import SAMPLES_DIR  # noqa: E402
from algorithms.mesh.validate import validate_mesh  # noqa: E402

DECIMALS = 6
MAX_BYTES = 600_000


def build(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The sample ``name`` as it is stored: (V rounded to DECIMALS, F)."""
    V, F = organic_sample(name)
    return np.round(V, DECIMALS) + 0.0, F


def build_orange() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coloured orange: (V rounded, F, vertex colours in [0, 1])."""
    from algorithms.adversarial.shapes import orange

    V, F, A = orange()
    C = np.zeros((len(V), 3))
    count = np.zeros(len(V))
    for k in range(3):
        np.add.at(C, F[:, k], A)
        np.add.at(count, F[:, k], 1.0)
    return np.round(V, DECIMALS) + 0.0, F, np.round(C / count[:, None], 3)


def check(path: Path, genus: int) -> list[str]:
    """Problems with a written sample file (empty list if fine)."""
    problems = []
    mesh = read_mesh(path)
    report = validate_mesh(mesh.V, mesh.F)
    s = report.stats
    if report.errors or report.warnings:
        problems.append(f"{path.name}: {report.codes}")
    if not s["closed"] or s["genus"] != genus or s["components"] != 1:
        problems.append(
            f"{path.name}: closed={s['closed']} genus={s['genus']} parts={s['components']}"
        )
    if signed_volume(mesh.V, mesh.F) <= 0:
        problems.append(f"{path.name}: not outward oriented")
    if path.stat().st_size > MAX_BYTES:
        problems.append(f"{path.name}: {path.stat().st_size} bytes > {MAX_BYTES}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="verify instead of writing")
    parser.add_argument("--out", type=Path, default=SAMPLES_DIR, help="output folder")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    problems: list[str] = []
    for name, genus in ORGANIC_SAMPLES.items():
        path = args.out / f"{name}.obj"
        if not args.check:
            V, F = build(name)
            write_mesh(path, V, F)
        problems += check(path, genus)
        print(f"{path}: {path.stat().st_size / 1000:.0f} kB")
    orange = args.out / "orange.obj"
    if not args.check:
        V, F, C = build_orange()
        write_mesh(orange, V, F, vertex_colors=C)
    problems += check(orange, 0)
    print(f"{orange}: {orange.stat().st_size / 1000:.0f} kB")
    project = args.out / "blob-painted.s3d"
    if not args.check:
        write_sample_project(args.out / "blob.obj", project)
    print(f"{project}: {project.stat().st_size / 1000:.0f} kB")
    for p in problems:
        print("PROBLEM:", p, file=sys.stderr)
    return 1 if problems else 0


def write_sample_project(mesh: Path, out: Path) -> None:
    """A project made from the blob as a user would make it in the app: λ painted stronger on
    the upper half and weaker below, the lowest region fixed, one handle pulling the top out,
    and the Cubic and Subdivision panels' settings (the README's project examples use it)."""
    from app.document import MeshState
    from app.project import Project, save_project

    data = read_mesh(mesh)
    V, F = data.V, data.F
    z = V[:, 1]  # the samples are Y-up
    st = MeshState.make(V, F)
    st = st.with_field("lambda_scale", np.where(z > np.median(z), 2.0, 0.5))
    st = st.with_field("fixed", (z < z.min() + 0.1 * np.ptp(z)).astype(float))
    top = int(np.argmax(z))
    st = st.with_handles({top: tuple(float(x) for x in V[top] + [0.0, 0.15 * np.ptp(z), 0.0])})
    panels = {"Cubic": {"params": {"lam": 0.4}, "options": {"plane_axis": 1, "progressive": None,
                                                            "multigrid": False}},
              "Subdivision": {"params": {"method": "neural", "levels": 1, "coarsen_first": 0},
                              "options": {"weights": "shipped"}}}
    save_project(out, Project(st, panels=panels, source=mesh.name))


if __name__ == "__main__":
    raise SystemExit(main())
