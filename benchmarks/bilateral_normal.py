"""A non-image peer for Paparazzi's guided filter on issue 23's noisy scans: bilateral normal
filtering (Zheng et al. 2011, algorithms/mesh/bilateral.py) against the guided filter.

    python benchmarks/bilateral_normal.py [--meshes fandisk.off bob.obj] [--guided DIR]
        [--iterations 1000]

For each mesh: the clean mesh, its noisy scan (benchmarks/paparazzi_effects.py: Gaussian noise of
0.3 mean edge lengths along the vertex normals, seed 0), the guided filter's output (Paparazzi at
the command line's defaults, ``--iterations``; read from ``--guided DIR`` when that folder holds
``noisy_<mesh>_guided.obj`` and ``..._control.obj``, written by ``paparazzi_effects.py --noisy
--save DIR``), its control (remeshing alone), and bilateral normal filtering at its defaults
(sigma_r 0.35, 20 normal passes, 10 vertex updates) and at a number of normal passes chosen so
that its mean move from the noisy scan equals the guided output's (*equal move*: mean distance of
the output's vertices to the noisy surface, a measure that works across Paparazzi's remeshing).
Rows (lengths / bounding-box diagonal of the clean mesh):

  to clean     mean distance of the output's vertices to the clean surface (lower = closer)
  moved        mean distance of the output's vertices to the noisy surface
  vol          relative volume change from the noisy scan
  flat err     mean angle (degrees) between the output's normal and the clean normal at the
               centroids of the clean faces away from creases (every dihedral angle < 10 deg):
               how smooth the flat / smooth regions came out
  crease5      share of the clean mesh's sharp-edge length (> 30 deg) whose angle the output has
               within 5 deg (measures.crease_fraction against the CLEAN input)
  bending      bending energy sum |L V|^2 / M (lower = smoother)
  seconds      wall time of the method (the guided one only when run here)

Prints the load average; every figure is measured in this run. Unless --no-sheet, writes
docs/images/paparazzi_bilateral_noisy.png: per mesh, noisy scan / guided / bilateral / clean.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def flat_normal_error(Vc, F, Vo, Fo, below: float = 10.0) -> float:
    """Mean angle (deg) between the output's face normal and the clean one at the centroids of
    the clean faces whose dihedral angles are all below ``below`` degrees."""
    import igl

    from algorithms.mesh.operators import face_normals
    from algorithms.paparazzi.measures import _dihedral_angles

    _, f0, f1, ang = _dihedral_angles(Vc, F)
    worst = np.zeros(len(F))
    np.maximum.at(worst, f0, ang)
    np.maximum.at(worst, f1, ang)
    keep = worst < below
    C = Vc[F[keep]].mean(1)
    _, I, _ = igl.point_mesh_squared_distance(C, np.ascontiguousarray(Vo, float),
                                              np.ascontiguousarray(Fo, np.int64))
    No = face_normals(Vo, Fo)[np.asarray(I, np.int64)]
    Nc = face_normals(Vc, F)[keep]
    return float(np.degrees(np.arccos(np.clip((No * Nc).sum(1), -1, 1))).mean())


def row(label, Vc, Vn, F, Vo, Fo, seconds=None):
    from algorithms.mesh.operators import signed_volume
    from algorithms.paparazzi import bending_energy
    from algorithms.paparazzi.measures import crease_fraction, surface_distance

    diag = float(np.linalg.norm(Vc.max(0) - Vc.min(0)))
    figures = {"to clean": surface_distance(Vo, Fo, Vc, F) / diag,
               "moved": surface_distance(Vo, Fo, Vn, F) / diag,
               "vol": (signed_volume(Vo, Fo) - signed_volume(Vn, F)) / signed_volume(Vn, F),
               "flat err": flat_normal_error(Vc, F, Vo, Fo),
               "crease5": crease_fraction(Vc, F, Vo, Fo),
               "bending": bending_energy(Vo, Fo)}
    print(f"  {label:<34}{figures['to clean']:>10.5f}{figures['moved']:>10.5f}"
          f"{figures['vol']:>+9.4f}{figures['flat err']:>10.2f}{figures['crease5']:>9.3f}"
          f"{figures['bending']:>10.1f}" + (f"{seconds:>9.1f}" if seconds is not None else ""),
          flush=True)
    return figures


def main() -> int:
    from algorithms.mesh import read_mesh
    from algorithms.mesh.bilateral import BilateralNormalParams, bilateral_normal_filter
    from algorithms.paparazzi import Paparazzi, PaparazziParams, get_filter
    from algorithms.paparazzi.measures import surface_distance
    from benchmarks.paparazzi_effects import (NOISE, NOISE_SEED, contact_sheet, control_spec,
                                              load, view_picture)

    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", nargs="+", default=["fandisk.off", "bob.obj"])
    ap.add_argument("--guided", default=None, help="folder of saved guided outputs")
    ap.add_argument("--iterations", type=int, default=1000)
    ap.add_argument("--saved-filters", nargs="*", default=[],
                    help="also measure these filters' outputs saved in the --guided folder")
    ap.add_argument("--moves", nargs="*", type=float, default=[],
                    help="more equal-move rows: mean moves (/ diagonal) to match")
    ap.add_argument("--no-sheet", action="store_true",
                    help="do not write docs/images/paparazzi_bilateral_noisy.png")
    a = ap.parse_args()
    pictures = []
    print(f"load average {os.getloadavg()[0]:.2f}; noise {NOISE} mean edge lengths, seed "
          f"{NOISE_SEED}; guided: Paparazzi CLI defaults, {a.iterations} iterations")
    for mesh in a.meshes:
        Vc, F = load(mesh)
        Vn, _ = load(f"noisy:{mesh}")
        diag = float(np.linalg.norm(Vc.max(0) - Vc.min(0)))
        print(f"\n{mesh}: {len(Vc):,} vertices\n  {'':<34}{'to clean':>10}{'moved':>10}"
              f"{'vol':>9}{'flat err':>10}{'crease5':>9}{'bending':>10}{'seconds':>9}")
        row("noisy scan", Vc, Vn, F, Vn, F)
        stem = Path(mesh).stem
        saved = Path(a.guided) / f"noisy_{stem}_guided.obj" if a.guided else None
        if saved is not None and saved.exists():
            g = read_mesh(saved)
            c = read_mesh(Path(a.guided) / f"noisy_{stem}_guided_control.obj")
            (Vg, Fg), (Vk, Fk), tg = (g.V, g.F), (c.V, c.F), None
        else:
            spec = get_filter("guided")
            pp = PaparazziParams(iterations=a.iterations)
            t = time.perf_counter()
            last = None
            for last in Paparazzi(Vn, F, spec, None, pp).steps():
                pass
            tg = time.perf_counter() - t
            Vg, Fg = last.V, last.F
            for cl in Paparazzi(Vn, F, control_spec(spec), None, pp).steps():
                pass
            Vk, Fk = cl.V, cl.F
        row("guided (Paparazzi defaults)", Vc, Vn, F, Vg, Fg, tg)
        row("control (remeshing alone)", Vc, Vn, F, Vk, Fk)
        for other in a.saved_filters:        # other Paparazzi filters' saved outputs
            p = Path(a.guided or ".") / f"noisy_{stem}_{other}.obj"
            if p.exists():
                o = read_mesh(p)
                row(f"{other} (Paparazzi defaults)", Vc, Vn, F, o.V, o.F)
        t = time.perf_counter()
        Vb = bilateral_normal_filter(Vn, F)
        row("bilateral, defaults (20 + 10)", Vc, Vn, F, Vb, F, time.perf_counter() - t)
        # equal move: the fewest normal passes (10 vertex updates each) whose output moved at
        # least as far from the noisy scan as the guided output did (and --moves: other moves)
        for want in [surface_distance(Vg, Fg, Vn, F) / diag] + list(a.moves):
            Vk2 = equal_move(Vn, F, diag, want, row, Vc)
        pictures.append((f"{stem}\n{len(Vc):,} V", view_picture(Vn, F), view_picture(Vg, Fg),
                         view_picture(Vb, F), view_picture(Vc, F)))
    if not a.no_sheet:
        out = ROOT / "docs" / "images" / "paparazzi_bilateral_noisy.png"
        contact_sheet(pictures, out, "Noisy scans (0.3 mean edge lengths along the normals): the "
                      "guided filter (Paparazzi defaults) and bilateral normal filtering",
                      captions=("noisy scan", "guided", "bilateral normal", "clean"))
        print(f"\nwrote {out}")
    return 0


def equal_move(Vn, F, diag, want, row, Vc):
    """Bilateral normal filtering with the fewest normal passes whose output moved at least
    ``want`` (mean distance to the noisy surface / diagonal); prints its row."""
    from algorithms.mesh.bilateral import BilateralNormalParams, bilateral_normal_filter
    from algorithms.paparazzi.measures import surface_distance

    if True:
        got = None
        for k in range(0, 41):
            t = time.perf_counter()
            Vk2 = bilateral_normal_filter(Vn, F, BilateralNormalParams(
                normal_iterations=k, vertex_iterations=10 if k else 1))
            moved = surface_distance(Vk2, F, Vn, F) / diag
            if moved >= want or k == 40:
                got = (k, Vk2, time.perf_counter() - t)
                break
        k, Vk2, tk = got
        if k == 0:      # one vertex update with the unfiltered normals already moves further:
            for s in np.linspace(0.05, 1.0, 20):     # scale the update down to the same move
                Vs = Vn + s * (Vk2 - Vn)
                if surface_distance(Vs, F, Vn, F) / diag >= want:
                    Vk2 = Vs
                    break
        row(f"bilateral, move {want:.5f} ({k} passes)", Vc, Vn, F, Vk2, F, tk)
        return Vk2


if __name__ == "__main__":
    sys.exit(main())
