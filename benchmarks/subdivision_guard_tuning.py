"""The guard's bending factors, derived on meshes the evaluation never sees (issue 36, item 1).

The guard (``dense="guard"``, :class:`algorithms.subdivision.inference._Guard`) sends a level to
Loop subdivision when the network's result is more than a factor times as bent as modified
butterfly's. This script measures that ratio where the factors may be set: on the bundled
samples (``resources/samples``) and the shipped network's training shapes (``tests/data``:
armadillo, bob, spot_lowres, fandisk, rocker-arm), never on the evaluation meshes of
``subdivision_guard.py`` (the corpus and the other shared meshes). For every tuning mesh, as it
is and QSlimmed to each ``--sizes`` vertex count, and each level count, the network is forced
(``dense="scale"``) with the mirror average (as shipped) and without it (the plain network,
which leaves dimples on flat flaps: the looks that set the factors before the average). Prints
one JSON line per result with the bending ratio to butterfly's and whether the input counts as
denser than the training meshes, and with ``--picture`` renders the results sorted by ratio
(flat shading, so that dimples show) to judge where the look goes wrong.

Usage (the picture needs a display or xvfb-run)::

    OMP_NUM_THREADS=1 xvfb-run -a .venv/bin/python benchmarks/subdivision_guard_tuning.py \\
        --out /tmp/tuning.jsonl [--picture /tmp/tuning.png] [--top 24] \\
        [--closeups docs/images/subdivision_guard_factors.png --px 360]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from subdivision_guard import TRAINED_ON  # noqa: E402  (the evaluation leaves these out)

from algorithms.mesh.samples import SAMPLE_NAMES, sample_path  # noqa: E402

SAMPLES = [str(sample_path(n).relative_to(ROOT)) for n in SAMPLE_NAMES]
TRAINING = [f"tests/data/{n}" for n in sorted(TRAINED_ON)]


#: the results that set the factors (see GUARD_BENDING_FACTOR): (mesh, vertices or None for
#: as it is, levels); the highest clean ratio and the lowest marked one above it, each side
CLOSEUPS = [("tests/data/bob.obj", 400, 2), ("tests/data/bob.obj", 200, 3),
            ("tests/data/fandisk.off", None, 2), ("resources/samples/pretzel.obj", None, 2)]


def closeups(out: str, net, plain, px: int) -> None:
    """One row per :data:`CLOSEUPS` case: the network with the mirror average (shipped),
    without it, and modified butterfly, flat-shaded and zoomed in, each with its bending
    ratio to butterfly's."""
    from _pictures import render_grid

    from algorithms.mesh import read_mesh
    from algorithms.mesh.validate import clean_mesh
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.inference import neural_subdivision_iter
    from algorithms.subdivision.metrics import bending_energy, coarsen_to_vertices

    rows = []
    for path, size, lv in CLOSEUPS:
        m = read_mesh(ROOT / path)
        c = clean_mesh(m.V, m.F)
        V, F = np.asarray(c.V, np.float64), np.asarray(c.F, np.int64)
        if size:
            V, F = coarsen_to_vertices(V, F, size)
        Vb, Fb = subdivide_baseline(V, F, lv, "butterfly")
        ref = bending_energy(Vb, Fb)
        head = f"{Path(path).stem} {size or 'as is'}, {lv} levels"
        row = []
        for name, n in (("mirror average", net), ("plain", plain)):
            r = list(neural_subdivision_iter(V, F, lv, n, dense="scale"))[-1]
            row.append((f"{head}: {name} {bending_energy(r.V, r.F) / ref:.2f}x", r.V, r.F))
        row.append(("modified butterfly", Vb, Fb))
        rows.append(row)
    render_grid(rows, out, px, smooth=False, zoom=2.5)
    print(f"wrote {out}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="JSON lines (overwritten)")
    ap.add_argument("--sizes", nargs="*", type=int, default=[200, 400, 1000])
    ap.add_argument("--levels", type=int, default=3, help="levels on the coarse copies")
    ap.add_argument("--full-levels", type=int, default=2, help="levels on the meshes as they are")
    ap.add_argument("--picture", default=None)
    ap.add_argument("--top", type=int, default=24, help="results in the picture (highest ratio)")
    ap.add_argument("--px", type=int, default=420)
    ap.add_argument("--closeups", default=None,
                    help="close-up picture of the cases that set the factors: the network with "
                         "and without the mirror average beside butterfly")
    a = ap.parse_args(argv)

    from algorithms.mesh import read_mesh
    from algorithms.mesh.validate import clean_mesh
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.inference import (load_network, neural_subdivision_iter,
                                                  scale_plan)
    from algorithms.subdivision.metrics import bending_energy, coarsen_to_vertices

    net = load_network(None)
    plain = load_network(None)
    plain.mirror = False
    rows, shapes = [], []
    with open(a.out, "w") as fh:
        for path in SAMPLES + TRAINING:
            m = read_mesh(ROOT / path)
            c = clean_mesh(m.V, m.F)
            V, F = np.asarray(c.V, np.float64), np.asarray(c.F, np.int64)
            inputs = [("as is", V, F, a.full_levels)]
            inputs += [(str(s), *coarsen_to_vertices(V, F, s), a.levels)
                       for s in a.sizes if len(V) > s]
            for size, Vc, Fc, top in inputs:
                denser = scale_plan(net, Vc, Fc, dense="scale").denser
                Vb, Fb = Vc, Fc
                for lv in range(1, top + 1):
                    Vb, Fb = subdivide_baseline(Vb, Fb, 1, "butterfly")
                    ref = bending_energy(Vb, Fb)
                    row = {"mesh": Path(path).name, "size": size, "levels": lv,
                           "coarse_vertices": int(len(Vc)), "denser": bool(denser)}
                    for key, n in (("mirror", net), ("plain", plain)):
                        last = list(neural_subdivision_iter(Vc, Fc, lv, n, dense="scale"))[-1]
                        row[key] = float(bending_energy(last.V, last.F) / ref)
                        if key == "mirror":
                            shapes.append((row, last.V, last.F))
                    rows.append(row)
                    fh.write(json.dumps(row) + "\n")
                    print(json.dumps(row), flush=True)
    if a.closeups:
        closeups(a.closeups, net, plain, a.px)
    if a.picture:
        from _pictures import render_grid

        best = sorted(shapes, key=lambda s: -s[0]["mirror"])[:a.top]
        cells = [(f"{r['mesh']} {r['size']} L{r['levels']}"
                  f"{' dense' if r['denser'] else ''}: {r['mirror']:.2f}x", X, G)
                 for r, X, G in best]
        grid = [cells[i:i + 4] for i in range(0, len(cells), 4)]
        render_grid(grid, a.picture, a.px, smooth=False, zoom=1.05)
        print(f"wrote {a.picture}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
