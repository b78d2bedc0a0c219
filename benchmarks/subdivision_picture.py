"""Pictures of neural subdivision's default (the guard) beside Loop and butterfly (issue 36).

For each mesh given: cleaned, coarsened by QSlim to ``--size`` vertices (the Table 4.2
protocol of docs/subdivision.md), then subdivided ``--levels`` times by the default (the
network, with the per-level guard), Loop and modified butterfly. One row per mesh: the original,
the coarse input, and the three results, flat-shaded so that bumps and facets show, each with
its Hausdorff distance H and mean distance M to the original (% of the diagonal). Prints the
figures as JSON lines and writes the picture.

Usage (needs a display or xvfb-run)::

    xvfb-run -a .venv/bin/python benchmarks/subdivision_picture.py MESH [MESH ...] \\
        --out docs/images/subdivision_guard.png [--size 400] [--levels 2]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--size", type=int, default=400)
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--px", type=int, default=300, help="pixels per view")
    a = ap.parse_args(argv)

    from algorithms.mesh import read_mesh
    from algorithms.mesh.validate import clean_mesh
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.inference import load_network, neural_subdivision_iter
    from algorithms.subdivision.metrics import coarsen_to_vertices, surface_distances

    net = load_network(None)
    rows = []
    for path in a.meshes:
        m = read_mesh(path)
        c = clean_mesh(m.V, m.F)
        V, F = np.asarray(c.V, np.float64), np.asarray(c.F, np.int64)
        Vc, Fc = coarsen_to_vertices(V, F, a.size)
        last = list(neural_subdivision_iter(Vc, Fc, a.levels, net))[-1]
        shapes = [("original", V, F, ""), (f"coarse input ({len(Vc)} vertices)", Vc, Fc, "")]
        results = [("default (" + "+".join(last.levels_used) + ")", last.V, last.F),
                   ("Loop", *subdivide_baseline(Vc, Fc, a.levels, "loop")),
                   ("butterfly", *subdivide_baseline(Vc, Fc, a.levels, "butterfly"))]
        for name, Vs, Fs in results:
            d = surface_distances(Vs, Fs, V, F)
            print(json.dumps({"mesh": Path(path).name, "result": name, "H": d["hausdorff"],
                              "M": d["mean_distance"], "triangles": int(len(Fs))}), flush=True)
            shapes.append((name, Vs, Fs, f"H {d['hausdorff']:.2f}  M {d['mean_distance']:.3f}"))
        rows.append((Path(path).name, shapes))

    from _pictures import render_grid

    render_grid([[((f"{mesh}: {name}" if j == 0 else name) + (f"\n{figures}" if figures else ""),
                   X, G) for j, (name, X, G, figures) in enumerate(shapes)]
                 for mesh, shapes in rows], a.out, a.px, smooth=False, zoom=1.05)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
