"""Write the made-up raw scan that Paparazzi's results are checked on (docs/results/paparazzi.md,
"the sliver scan"): armadillo Loop-subdivided once and bob twice, side by side (two parts),
Gaussian noise along the normals (0.3 mean edge lengths), 40 holes (a 2-ring of faces removed
around random vertices, whose vertices stay as loose points) and about 12,000 slivers (faces
split 1-to-3 by a point a 1/500 of the face's height from one of its edges).

    python benchmarks/make_sliver_scan.py --meshes ../shared/meshes OUT.obj

Deterministic (seed 0). The scan of issue 23's sixth pass was made the same way by a script
that was not kept; this one rebuilds its kind, not its bytes. Needs ``--clean`` to run
(its loose points).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from algorithms.mesh import read_mesh, write_mesh  # noqa: E402
from algorithms.mesh.subdivision import loop_subdivide  # noqa: E402


def vertex_normals(V, F):
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    out = np.zeros_like(V)
    for k in range(3):
        np.add.at(out, F[:, k], N)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


def mean_edge(V, F):
    E = np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())


def sliver_scan(meshes: Path, seed: int = 0, holes: int = 40, slivers: int = 12000,
                noise: float = 0.3):
    rng = np.random.default_rng(seed)
    parts = []
    for name, levels in (("armadillo.obj", 1), ("bob.obj", 2)):
        m = read_mesh(meshes / name)
        V, F = loop_subdivide(np.asarray(m.V, float), np.asarray(m.F, np.int64), levels)
        V = V - V.mean(0)
        V = V / np.abs(V).max()
        parts.append((V, F))
    (Va, Fa), (Vb, Fb) = parts
    Vb = Vb + [2.5, 0.0, 0.0]
    V = np.vstack([Va, Vb])
    F = np.vstack([Fa, Fb + len(Va)])
    V = V + rng.normal(scale=noise * mean_edge(V, F), size=(len(V), 1)) * vertex_normals(V, F)
    # holes: the faces of a 2-ring around random vertices go; their vertices stay (loose)
    drop = np.zeros(len(F), bool)
    for c in rng.choice(len(V), holes, replace=False):
        ring = {int(c)}
        for _ in range(2):
            ring |= set(F[np.isin(F, list(ring)).any(1)].ravel().tolist())
        drop |= np.isin(F, list(ring)).all(1)
    F = F[~drop]
    # slivers: a face split 1-to-3 by a point near one of its edges
    pick = rng.choice(len(F), min(slivers, len(F)), replace=False)
    keep = np.ones(len(F), bool)
    keep[pick] = False
    new_V, new_F = [], []
    for n, k in enumerate(pick):
        a, b, c = F[k]
        p = 0.5 * (V[a] + V[b])
        p = p + (V[c] - p) / 500.0
        i = len(V) + n
        new_V.append(p)
        new_F += [[a, b, i], [b, c, i], [c, a, i]]
    V = np.vstack([V, np.array(new_V)])
    F = np.vstack([F[keep], np.array(new_F, np.int64)])
    return V, F


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--meshes", type=Path, default=Path("../shared/meshes"),
                    help="the folder with armadillo.obj and bob.obj")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    V, F = sliver_scan(args.meshes, args.seed)
    write_mesh(args.out, V, F)
    print(f"wrote {args.out}: {len(V)} vertices, {len(F)} triangles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
