"""Progressive meshes against full resolution, per λ and copy size (issue 37).

For one mesh (cleaned, optionally Loop-subdivided): full resolution at the thesis's stopping rule
for each λ (the peer, in the same run), then progressive meshes with each copy size ``--m``:
the change of the area-weighted mean L1 norm of the unit vertex normals ("change"), its ratio
to full resolution's, and the share of area whose normal lies within 10° of an axis ("share")
with its difference in points. With ``--long N`` full resolution also runs on for N iterations
without the stopping rule (printed every 50), to see how far the rule is from convergence, and
so does the finished path from the copy's result (do both reach the same look?).

Each copy size is measured twice: the copy alone (thesis Alg. 4: stylize the copy, put the
details back) and *finished* (the product's default, ``ProgressiveParams.finish``: then the
full-resolution iterations from that result to the same stopping rule; run here with the full
resolution's own stylizer, exactly what ``ProgressiveCubic(finish=True)`` does, so its set-up
is not paid twice). For full resolution and the finished result the full-resolution energy
(ARAP + λ-weighted L1, the thesis's objective, at the last iteration) is printed: the lower,
the closer to the minimum the user asked for.

Usage::

    .venv/bin/python benchmarks/progressive_vs_full.py MESH [--loop 1] [--lam 0.1 0.2 0.5]
        [--m 20000 50000] [--long 600]

Rows are JSON lines (one per measurement), then a markdown table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def axis_share(V, F, degrees: float = 10.0) -> float:
    """Share of the area (barycentric vertex areas) whose unit normal is within ``degrees`` of
    a coordinate axis."""
    from algorithms.mesh.operators import barycentric_vertex_areas, vertex_normals

    N = vertex_normals(V, F)
    a = barycentric_vertex_areas(V, F)
    return float(a[np.abs(N).max(1) >= np.cos(np.radians(degrees))].sum() / a.sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("--loop", type=int, default=0, help="Loop subdivision levels first")
    ap.add_argument("--lam", nargs="*", type=float, default=[0.1, 0.2, 0.5])
    ap.add_argument("--m", nargs="*", type=int, default=[20000])
    ap.add_argument("--long", type=int, default=0, help="full resolution without the rule")
    ap.add_argument("--painted", action="store_true",
                    help="a painted λ: each λ times 2 above the median height (y), times 0.5 "
                         "below (the λ brush's scale field)")
    a = ap.parse_args(argv)

    from algorithms.deform.cubic import CubicParams, CubicStylizer, mean_l1_of_normals
    from algorithms.deform.progressive import ProgressiveCubic
    from algorithms.mesh import loop_subdivide, read_mesh
    from algorithms.mesh.validate import clean_mesh

    md = read_mesh(a.mesh)
    c = clean_mesh(md.V, md.F)
    V, F = (loop_subdivide(c.V, c.F, a.loop) if a.loop else (c.V, c.F))
    name = Path(a.mesh).name + (f" Loop x{a.loop}" if a.loop else "")
    c0 = mean_l1_of_normals(V, F)
    rows = []
    scale = np.where(V[:, 1] > np.median(V[:, 1]), 2.0, 0.5) if a.painted else None

    def lam_v(lam):
        return None if scale is None else lam * scale
    if a.painted:
        name += " painted λ"

    def emit(**row):
        row = {"mesh": name, "faces": int(len(F)), **row}
        print(json.dumps(row), flush=True)
        rows.append(row)

    t = time.perf_counter()
    st = CubicStylizer(V, F)
    set_up = time.perf_counter() - t
    full = {}
    for lam in a.lam:
        t = time.perf_counter()
        last, k = None, 0
        for last in st.steps(CubicParams(lam=lam), lam_per_vertex=lam_v(lam)):
            k += 1
        full[lam] = (c0 - mean_l1_of_normals(last.V, F), axis_share(last.V, F))
        emit(lam=lam, method="full", change=full[lam][0], share=full[lam][1], iterations=k,
             energy=last.metrics["energy"], seconds=time.perf_counter() - t,
             set_up_seconds=set_up)
        if a.long:
            t = time.perf_counter()
            for s in st.steps(CubicParams(lam=lam, rel_displacement_tol=0.0,
                                          max_iterations=a.long), lam_per_vertex=lam_v(lam)):
                if s.iteration % 50 == 0 or s.iteration == a.long:
                    emit(lam=lam, method="full, no rule", iteration=s.iteration,
                         change=c0 - mean_l1_of_normals(s.V, F), share=axis_share(s.V, F),
                         relative_move=s.metrics.get("displacement"),
                         energy=s.metrics["energy"], seconds=time.perf_counter() - t)
    for m in a.m:
        t = time.perf_counter()
        pc = ProgressiveCubic(V, F, target_faces=m)
        pre = time.perf_counter() - t
        for lam in a.lam:
            t = time.perf_counter()
            Vp = pc.stylize(CubicParams(lam=lam), lam_per_vertex=lam_v(lam))
            ch, sh = c0 - mean_l1_of_normals(Vp, F), axis_share(Vp, F)
            alone = time.perf_counter() - t
            emit(lam=lam, method=f"progressive m={m}", change=ch, share=sh,
                 ratio=ch / full[lam][0], share_points=100 * (sh - full[lam][1]),
                 seconds=alone, preprocessing_seconds=pre)
            t = time.perf_counter()
            last, k = None, 0
            for last in st.steps(CubicParams(lam=lam), lam_per_vertex=lam_v(lam), initial=Vp):
                k += 1
            ch, sh = c0 - mean_l1_of_normals(last.V, F), axis_share(last.V, F)
            emit(lam=lam, method=f"finished m={m}", change=ch, share=sh,
                 ratio=ch / full[lam][0], share_points=100 * (sh - full[lam][1]),
                 iterations=k, energy=last.metrics["energy"],
                 seconds=alone + time.perf_counter() - t, preprocessing_seconds=pre + set_up)
            if a.long:   # the same iterations without the rule from the copy's result
                t = time.perf_counter()
                for s in st.steps(CubicParams(lam=lam, rel_displacement_tol=0.0,
                                              max_iterations=a.long),
                                  lam_per_vertex=lam_v(lam), initial=Vp):
                    if s.iteration % 50 == 0 or s.iteration == a.long:
                        emit(lam=lam, method=f"finished m={m}, no rule", iteration=s.iteration,
                             change=c0 - mean_l1_of_normals(s.V, F), share=axis_share(s.V, F),
                             relative_move=s.metrics.get("displacement"),
                             energy=s.metrics["energy"], seconds=time.perf_counter() - t)
    print()
    print("| λ | full: change / share / iterations / energy / seconds | " +
          " | ".join(f"m {m} alone: ratio / Δshare | m {m} finished: ratio / Δshare / "
                     "iterations / energy / seconds" for m in a.m) + " |")
    print("|---|---|" + "---|---|" * len(a.m))
    for lam in a.lam:
        f = next(r for r in rows if r["lam"] == lam and r["method"] == "full")
        cells = []
        for m in a.m:
            p = next(r for r in rows if r["lam"] == lam and r["method"] == f"progressive m={m}")
            q = next(r for r in rows if r["lam"] == lam and r["method"] == f"finished m={m}")
            cells += [f"{p['ratio']:.2f} / {p['share_points']:+.1f}",
                      f"{q['ratio']:.2f} / {q['share_points']:+.1f} / {q['iterations']} / "
                      f"{q['energy']:.4f} / {q['seconds']:.1f}"]
        print(f"| {lam:g} | {f['change']:.3f} / {f['share']:.3f} / {f['iterations']} / "
              f"{f['energy']:.4f} / {f['seconds']:.1f} | " + " | ".join(cells) + " |")
    if a.long:
        print()
        print("At equal energy: full resolution run on without the rule, read (linearly "
              "between its 50-iteration rows) where its energy equals the finished result's:")
        for lam in a.lam:
            for m in a.m:
                q = next(r for r in rows if r["lam"] == lam and r["method"] == f"finished m={m}")
                eq = equal_energy([r for r in rows if r["lam"] == lam
                                   and r["method"] == "full, no rule"], q["energy"])
                if eq is None:
                    print(f"  λ {lam:g}, m {m}: full resolution did not reach the finished "
                          f"energy {q['energy']:.4f} within {a.long} iterations")
                    continue
                it, ch, sh = eq
                print(f"  λ {lam:g}, m {m}: energy {q['energy']:.4f} at full resolution's "
                      f"iteration ~{it:.0f}: change {ch:.4f}, share {sh:.3f}; finished "
                      f"{q['change']:.4f} / {q['share']:.3f}: ratio {q['change'] / ch:.2f}, "
                      f"{100 * (q['share'] - sh):+.1f} points")
    return 0


def equal_energy(run: list, energy: float):
    """(iteration, change, share) of a run's rows (energy falling with the iterations) where
    its energy equals ``energy``, linear between the two rows around it; None if never."""
    run = sorted(run, key=lambda r: r["iteration"])
    for r0, r1 in zip(run, run[1:]):
        if r0["energy"] >= energy >= r1["energy"] and r0["energy"] > r1["energy"]:
            t = (r0["energy"] - energy) / (r0["energy"] - r1["energy"])
            return tuple(r0[k] + t * (r1[k] - r0[k]) for k in ("iteration", "change", "share"))
    return None


if __name__ == "__main__":
    sys.exit(main())
