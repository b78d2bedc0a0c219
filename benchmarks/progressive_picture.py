"""Side-by-side picture of cubic stylization on a big scan (issue 37; docs/cubic.md).

Four views of one mesh, same camera: the input, every triangle from the start (the thesis's
stopping rule), the coarse copy alone (thesis Alg. 4: stylize a 20,000-triangle copy, put the
details back; ``--coarse-only``), and the default (the copy's result finished on every
triangle). Prints each one's change of the area-weighted mean L1 norm of the unit normals, its
full-resolution energy (ARAP + λ-weighted L1; lower = closer to the minimum), iterations and
seconds, and writes the picture.

Usage (needs a display or xvfb-run)::

    xvfb-run -a .venv/bin/python benchmarks/progressive_picture.py MESH --loop 1 --lam 0.2 \\
        --out docs/images/cubic_progressive.png [--view xz]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("--loop", type=int, default=0)
    ap.add_argument("--lam", type=float, default=0.2)
    ap.add_argument("--out", required=True)
    ap.add_argument("--view", default="xy", help="pyvista camera position: xy, xz, yz, ...")
    ap.add_argument("--size", type=int, default=420, help="pixels per view")
    a = ap.parse_args(argv)

    from algorithms.deform.cubic import CubicParams, CubicStylizer, mean_l1_of_normals
    from algorithms.deform.progressive import ProgressiveCubic
    from algorithms.mesh import loop_subdivide, read_mesh
    from algorithms.mesh.validate import clean_mesh

    md = read_mesh(a.mesh)
    c = clean_mesh(md.V, md.F)
    V, F = loop_subdivide(c.V, c.F, a.loop) if a.loop else (c.V, c.F)
    c0 = mean_l1_of_normals(V, F)
    params = CubicParams(lam=a.lam)
    shapes = [("input", V, {})]

    t = time.perf_counter()
    st = CubicStylizer(V, F)
    set_up = time.perf_counter() - t
    t = time.perf_counter()
    last, k = None, 0
    for last in st.steps(params):
        k += 1
    shapes.append(("every triangle from the start", last.V,
                   {"iterations": k, "energy": last.metrics["energy"],
                    "seconds": time.perf_counter() - t + set_up}))
    t = time.perf_counter()
    pc = ProgressiveCubic(V, F)
    pre = time.perf_counter() - t
    t = time.perf_counter()
    alone = pc.stylize(params)
    shapes.append(("copy alone (--coarse-only)", alone,
                   {"seconds": time.perf_counter() - t + pre}))
    t = time.perf_counter()
    last, k = None, 0
    for last in st.steps(params, initial=alone):  # what ProgressiveCubic(finish=True) runs
        k += 1
    shapes.append(("copy, then finished (default)", last.V,
                   {"iterations": k, "energy": last.metrics["energy"],
                    "seconds": time.perf_counter() - t + shapes[-1][2]["seconds"] + set_up}))
    for name, X, info in shapes:
        print(json.dumps({"mesh": Path(a.mesh).name, "loop": a.loop, "faces": int(len(F)),
                          "lam": a.lam, "shape": name, "change": c0 - mean_l1_of_normals(X, F),
                          **info}), flush=True)

    from _pictures import render_grid

    render_grid([[(name, X, F) for name, X, _ in shapes]], a.out, a.size, smooth=True,
                view=a.view, zoom=1.3)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
