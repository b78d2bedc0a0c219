"""Neural subdivision's guard measured on real meshes nobody trained on (issue 36, item 1).

For every mesh of the given folders (cleaned; the shipped network's training shapes and any
``--exclude`` left out), coarsened by QSlim to each ``--sizes`` vertex count, and for
each of ``--levels`` levels, four results are compared with the original mesh:

* ``forced``    the network on every level (``dense="scale"``: scaled to its training edge
                length when the coarse mesh is denser than its training meshes);
* ``guard``     the product's default (``dense="guard"``): the network's levels up to the last
                that is at most 2.6x (1.25x on a denser mesh) as bent as modified
                butterfly's (and keeps flat sides flat), Loop for the rest;
* ``loop``, ``butterfly`` the classic schemes.

Measured: Hausdorff H and mean surface distance M (% of the original's bounding-box diagonal,
``--samples`` points a surface; :func:`algorithms.subdivision.metrics.surface_distances`) and
the discrete-shells bending energy of the result, and its normal error against the original
(:func:`algorithms.subdivision.metrics.normal_error`: the mean angle between its normals and
the original's at the closest points). The summary gives the share of inputs on which the
guard keeps the network for every level / for at least one level, and the issue's two
targets: the guarded result no rougher than Loop's by more than 10 % -- read two ways, no
more bent (which also counts the sharp features a result keeps and Loop rounds off), and no
larger a normal error (which counts dimples and folds, not kept creases) -- and within 2 % of
the better of forced and Loop on H and on M.

Each (mesh, size) runs in a worker process (spawn, one thread); rows are appended to
``--out`` (JSON lines) as they finish, and a rerun skips the rows already there.

Usage::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/subdivision_guard.py \\
        --meshes DIR [DIR ...] --out guard.jsonl [--sizes 200 400 1000] [--levels 1 2 3] \\
        [--jobs 2] [--weights W.pt]
    .venv/bin/python benchmarks/subdivision_guard.py --out guard.jsonl --table
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MESH_SUFFIXES = {".obj", ".ply", ".off", ".stl"}
#: the shipped weights' training shapes (resources/subdivision/README.md): never evaluated
TRAINED_ON = {"armadillo.obj", "bob.obj", "spot_lowres.obj", "fandisk.off", "rocker-arm.obj"}
METHODS = ("forced", "guard", "loop", "butterfly")


def mesh_paths(folders, exclude=()) -> list[Path]:
    out = []
    skip = TRAINED_ON | set(exclude)
    for d in folders:
        for p in sorted(Path(d).iterdir()):
            if p.suffix.lower() in MESH_SUFFIXES and p.name not in skip:
                out.append(p)
    return out


def measure(path: str, size: int, levels: list[int], samples: int, weights: str | None) -> list:
    """Rows for one mesh at one coarse size: one per level count (or one row with ``skipped``)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from algorithms.errors import Stylize3DError
    from algorithms.mesh import read_mesh
    from algorithms.mesh.validate import clean_mesh
    from algorithms.subdivision.baselines import subdivide_baseline
    from algorithms.subdivision.inference import load_network, neural_subdivision_iter
    from algorithms.subdivision.metrics import (bending_energy, coarsen_to_vertices,
                                                normal_error, surface_distances)

    name = Path(path).name
    base = {"mesh": name, "size": int(size)}
    try:
        m = read_mesh(path)
        c = clean_mesh(m.V, m.F)
        V, F = np.asarray(c.V, dtype=np.float64), np.asarray(c.F, dtype=np.int64)
        if len(V) <= size:
            return [{**base, "skipped": f"{len(V)} vertices after cleaning, not more than {size}"}]
        Vc, Fc = coarsen_to_vertices(V, F, size)
        net = load_network(weights)
    except Stylize3DError as exc:
        return [{**base, "skipped": str(exc).splitlines()[0][:200]}]
    rows = []
    for lv in levels:
        row = {**base, "levels": int(lv), "vertices": int(len(V)),
               "coarse_vertices": int(len(Vc)), "methods": {}}
        t0 = time.perf_counter()
        try:
            results = {}
            for dense, key in (("scale", "forced"), ("guard", "guard")):
                last = list(neural_subdivision_iter(Vc, Fc, lv, net, dense=dense))[-1]
                results[key] = (last.V, last.F)
                if key == "guard":
                    row["levels_used"] = list(last.levels_used)
                    row["guard_ratio"] = float(last.metrics.get("bending_vs_butterfly",
                                                                float("nan")))
            for scheme in ("loop", "butterfly"):
                results[scheme] = subdivide_baseline(Vc, Fc, lv, scheme)
            for key, (Vs, Fs) in results.items():
                # the guard's result is the forced one only where it is the same mesh: with the
                # network on every level it may still differ (the level before blended in where
                # the network's result crossed itself), so it is compared, not assumed
                Vf, Ff = results["forced"]
                if key == "guard":
                    row["guard_is_forced"] = bool(np.array_equal(Fs, Ff)
                                                  and np.array_equal(Vs, Vf))
                    if row["guard_is_forced"]:
                        row["methods"][key] = dict(row["methods"]["forced"])  # the same mesh
                        continue
                d = surface_distances(Vs, Fs, V, F, samples=samples)
                row["methods"][key] = {"H": d["hausdorff"], "M": d["mean_distance"],
                                       "bending": bending_energy(Vs, Fs),
                                       "normal": normal_error(Vs, Fs, V, F, samples=samples)}
        except Stylize3DError as exc:
            row = {**base, "levels": int(lv), "skipped": str(exc).splitlines()[0][:200]}
        row["seconds"] = time.perf_counter() - t0
        rows.append(row)
    return rows


def summarize(rows: list[dict]) -> str:
    """The markdown summary: one block per (size, levels) and all together."""
    done = [r for r in rows if "methods" in r]
    lines = ["| coarse size | levels | inputs | network on every level | on ≥ 1 level | "
             "guard ≤ 1.1x Loop's bending | guard within 2 % of min(forced, Loop) on H / on M | "
             "mean H: guard / forced / Loop / butterfly | mean M: guard / forced / Loop / "
             "butterfly | guard's normal error ≤ 1.1x Loop's | mean normal error (degrees): "
             "guard / forced / Loop / butterfly |", "|---|---|---|---|---|---|---|---|---|---|---|"]

    def block(sel, size, lv):
        n = len(sel)
        if not n:
            return
        allnet = sum(r["levels_used"] == ["neural"] * r["levels"] for r in sel)
        anynet = sum("neural" in r["levels_used"] for r in sel)
        g = [r["methods"]["guard"] for r in sel]
        f = [r["methods"]["forced"] for r in sel]
        lo = [r["methods"]["loop"] for r in sel]
        b = [r["methods"]["butterfly"] for r in sel]
        bend = sum(gi["bending"] <= 1.1 * li["bending"] for gi, li in zip(g, lo))
        okH = sum(gi["H"] <= 1.02 * min(fi["H"], li["H"]) for gi, fi, li in zip(g, f, lo))
        okM = sum(gi["M"] <= 1.02 * min(fi["M"], li["M"]) for gi, fi, li in zip(g, f, lo))

        def mean(xs, k):
            return f"{np.mean([x[k] for x in xs]):.3f}"

        # rows measured before the normal error was added have none: "-"
        has_n = all("normal" in x for x in g + lo + f + b)
        nerr = (f"{sum(gi['normal'] <= 1.1 * li['normal'] for gi, li in zip(g, lo))} "
                f"({100 * sum(gi['normal'] <= 1.1 * li['normal'] for gi, li in zip(g, lo)) / n:.0f} %)"
                if has_n else "-")
        nmean = (f"{mean(g, 'normal')} / {mean(f, 'normal')} / {mean(lo, 'normal')} / "
                 f"{mean(b, 'normal')}" if has_n else "-")
        lines.append(f"| {size} | {lv} | {n} | {allnet} ({100 * allnet / n:.0f} %) | {anynet} | "
                     f"{bend} ({100 * bend / n:.0f} %) | {okH} ({100 * okH / n:.0f} %) / {okM} "
                     f"({100 * okM / n:.0f} %) | {mean(g, 'H')} / {mean(f, 'H')} / "
                     f"{mean(lo, 'H')} / {mean(b, 'H')} | {mean(g, 'M')} / {mean(f, 'M')} / "
                     f"{mean(lo, 'M')} / {mean(b, 'M')} | {nerr} | {nmean} |")
    sizes = sorted({r["size"] for r in done})
    levels = sorted({r["levels"] for r in done})
    for s in sizes:
        for lv in levels:
            block([r for r in done if r["size"] == s and r["levels"] == lv], s, lv)
    block(done, "all", "all")
    skipped = [r for r in rows if "skipped" in r]
    if skipped:
        lines.append("")
        lines.append(f"Skipped ({len(skipped)}): " + "; ".join(
            f"{r['mesh']} @ {r['size']}: {r['skipped']}" for r in skipped))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="*", default=[], help="folders of meshes")
    ap.add_argument("--exclude", nargs="*", default=[], help="file names to leave out")
    ap.add_argument("--sizes", nargs="*", type=int, default=[200, 400, 1000])
    ap.add_argument("--levels", nargs="*", type=int, default=[1, 2, 3])
    ap.add_argument("--samples", type=int, default=30_000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--weights", default=None, help="weights file (default: the shipped ones)")
    ap.add_argument("--out", required=True, help="JSON lines, appended (a rerun resumes)")
    ap.add_argument("--table", action="store_true", help="print the summary of --out and stop")
    a = ap.parse_args(argv)
    out = Path(a.out)
    rows = [json.loads(x) for x in out.read_text().splitlines()] if out.exists() else []
    if a.table:
        print(summarize(rows))
        return 0
    have = {(r["mesh"], r["size"]) for r in rows}
    tasks = [(str(p), s) for p in mesh_paths(a.meshes, a.exclude) for s in a.sizes
             if (p.name, s) not in have]
    print(f"{len(tasks)} (mesh, size) tasks, levels {a.levels}, {a.jobs} workers", flush=True)
    import multiprocessing as mp

    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs, mp_context=mp.get_context("spawn")) as pool:
        futs = {pool.submit(measure, p, s, a.levels, a.samples, a.weights): (p, s)
                for p, s in tasks}
        for k, fut in enumerate(as_completed(futs), 1):
            p, s = futs[fut]
            try:
                new = fut.result()
            except Exception as exc:  # a crash in one task is a row, not the end of the run
                new = [{"mesh": Path(p).name, "size": s, "skipped": f"crash: {exc!r}"[:200]}]
            with out.open("a") as fh:
                for r in new:
                    fh.write(json.dumps(r) + "\n")
            used = [r.get("levels_used", r.get("skipped", "")) for r in new]
            print(f"[{k}/{len(tasks)} {time.perf_counter() - t0:.0f} s] {Path(p).name} @ {s}: "
                  f"{used}", flush=True)
            rows.extend(new)
    print(summarize(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
