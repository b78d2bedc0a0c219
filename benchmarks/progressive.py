"""Affine progressive meshes (thesis Alg. 4) at ~1M triangles: where the time goes, the online
step per new λ, peak memory, cubeness against stylizing every triangle, and the size from
which the automatic choice switches (issue 25).

Meshes (made from tests/data, so anyone can rerun it):
  subdivided   rocker-arm.obj Loop-subdivided 3x: 1.29M triangles (643k vertices)
  defects      the same with real-scan defects: 40 holes cut out (every triangle within 0.6 %
               of the diagonal of a random vertex), 3 % of the interior edges split at 2 % of
               their length (two slivers each), then `clean` as the CLI's --clean does
Each case runs in a fresh child process (its own peak memory, ru_maxrss):
  progressive  pre-processing split into decimation (recorded collapses), affine-split weights,
               cluster labels, coarse CubicStylizer; then for every --lam the online step (coarse
               solve to the thesis's stopping rule + replay of every split); PLY write + read
  direct       the peer: CubicStylizer on every triangle (factorization) + the solve, first
               --lam only (the full-resolution result the cubeness is compared with)
Cubeness: change of the area-weighted mean L1 norm of the unit vertex normals (input - result);
"ratio" = progressive change / direct change (target: within 10 %: 0.9 .. 1.1).
--sweep: the break-even size (direct vs progressive, whole run for one λ) on smaller meshes
  from tests/data (bob, rocker-arm, armadillo Loop-subdivided), in child processes too.
Wall and CPU seconds are printed (the machine is shared: CPU seconds are the steadier figure);
ratios are against the peer measured in the same run; `uptime` load is printed.

Usage: .venv/bin/python benchmarks/progressive.py [--cases subdivided,defects]
       [--lam 0.2,0.4] [--coarse 20000] [--exponents 0.25,0] [--no-direct] [--sweep]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def load(case: str):
    from algorithms.mesh import clean_mesh, loop_subdivide, read_mesh

    name, levels = {"subdivided": ("rocker-arm.obj", 3), "defects": ("rocker-arm.obj", 3),
                    "bob1": ("bob.obj", 1), "rocker1": ("rocker-arm.obj", 1),
                    "armadillo1": ("armadillo.obj", 1), "bob2": ("bob.obj", 2),
                    "armadillo2": ("armadillo.obj", 2)}[case]
    md = read_mesh(ROOT / "tests" / "data" / name)
    V, F = loop_subdivide(md.V, md.F, levels)
    notes = [f"{name} Loop x{levels}"]
    if case == "defects":
        V, F, made = make_defects(V, F, np.random.default_rng(25))
        res = clean_mesh(V, F)
        V, F = res.V, res.F
        notes += made + [f"clean: {a}" for a in res.actions]
    return V, F, notes


def make_defects(V, F, rng):
    """Holes and slivers like a raw scan's (see the module docstring)."""
    from algorithms.mesh.operators import bounding_box_diagonal
    from algorithms.mesh.topology import unique_edges

    diag = bounding_box_diagonal(V)
    centers = V[rng.choice(len(V), 40, replace=False)]
    cent = V[F].mean(axis=1)
    cut = np.zeros(len(F), bool)
    for c in centers:
        cut |= ((cent - c) ** 2).sum(axis=1) < (0.006 * diag) ** 2
    F = F[~cut]
    E, EMAP, counts = unique_edges(F)
    m = len(F)
    interior = np.flatnonzero(counts == 2)
    pick = rng.permutation(interior)[: int(0.03 * len(interior))]
    # the two triangles of every picked edge; keep edges whose triangles are all distinct
    he_edge = EMAP  # half-edge h = c * m + f  ->  its edge
    order = np.argsort(he_edge, kind="stable")
    first = np.searchsorted(he_edge[order], pick)
    h1, h2 = order[first], order[first + 1]
    f1, f2 = h1 % m, h2 % m
    used = np.zeros(m, bool)
    keep = []
    for e, a, b in zip(pick, f1, f2):
        if not used[a] and not used[b]:
            used[a] = used[b] = True
            keep.append((e, a, b))
    newV = [V]
    newF = []
    drop = np.zeros(m, bool)
    n = len(V)
    for e, fa, fb in keep:
        a, b = E[e]
        p = V[a] + 0.02 * (V[b] - V[a])
        newV.append(p[None])
        for f in (fa, fb):
            t = F[f]
            k = int(np.flatnonzero(t == a)[0])
            # rotate so the triangle reads (a, x, y); the split edge is (a, b)
            t = np.roll(t, -k)
            if t[1] == b:  # (a, b, c) -> (a, p, c), (p, b, c)
                newF += [(a, n, t[2]), (n, b, t[2])]
            else:  # (a, c, b) -> (a, c, p), (p, c, b)
                newF += [(a, t[1], n), (n, t[1], b)]
            drop[f] = True
        n += 1
    V2 = np.vstack(newV)
    F2 = np.vstack([F[~drop], np.asarray(newF, dtype=np.int64).reshape(-1, 3)])
    return V2, F2, [f"{int(cut.sum()):,} triangles cut out (40 holes)",
                    f"{len(keep):,} edges split into slivers"]


def peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


class Clock:
    def __init__(self):
        self.w, self.c = time.perf_counter(), time.process_time()

    def lap(self):
        w, c = time.perf_counter(), time.process_time()
        out = (w - self.w, c - self.c)
        self.w, self.c = w, c
        return out


def run_progressive(case, lams, coarse, exponent, q):
    from algorithms.deform.cubic import CubicParams, CubicStylizer, mean_l1_of_normals
    from algorithms.deform.progressive import AffineSplits
    from algorithms.mesh import read_mesh, write_mesh
    from algorithms.mesh.decimate import decimate

    V, F, notes = load(case)
    base_gb = peak_gb()
    l1 = mean_l1_of_normals(V, F)
    out = {"case": case, "n": len(V), "m": len(F), "notes": notes, "l1_in": l1,
           "load_gb": base_gb}
    ck = Clock()
    dec = decimate(V, F, coarse)
    out["decimate"] = ck.lap()
    sp = AffineSplits(dec)
    out["splits"] = ck.lap()
    dec.clusters()
    out["clusters"] = ck.lap()
    st = CubicStylizer(dec.V, dec.F)
    out["stylizer"] = ck.lap()
    out["regularized"] = int(sp.regularized.sum())
    out["runs"] = []
    for lam, expo in [(lam, e) for e in exponent for lam in lams]:
        nc_lam = lam * (len(F) / len(dec.F)) ** expo
        last = None
        for last in st.steps(CubicParams(lam=lam), lam_per_vertex=np.full(len(dec.V), nc_lam)):
            pass
        solve = ck.lap()
        Vf = sp.apply(last.V)
        replay = ck.lap()
        out["runs"].append({"lam": lam, "exponent": expo, "coarse_lam": nc_lam,
                            "iterations": last.iteration,
                            "solve": solve, "replay": replay,
                            "l1": mean_l1_of_normals(Vf, F)})
    path = f"/tmp/stylize3d-bench-{os.getpid()}.ply"
    ck.lap()
    write_mesh(path, Vf, F)
    out["write"] = ck.lap()
    read_mesh(path)
    out["read"] = ck.lap()
    os.unlink(path)
    out["peak_gb"] = peak_gb()
    q.put(out)


def run_direct(case, lam, q):
    from algorithms.deform.cubic import CubicParams, CubicStylizer, mean_l1_of_normals

    V, F, _ = load(case)
    ck = Clock()
    st = CubicStylizer(V, F)
    pre = ck.lap()
    last = None
    for last in st.steps(CubicParams(lam=lam)):
        pass
    solve = ck.lap()
    q.put({"pre": pre, "solve": solve, "iterations": last.iteration,
           "l1": mean_l1_of_normals(last.V, F), "peak_gb": peak_gb()})


def child(fn, *args):
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=fn, args=(*args, q))
    p.start()
    out = q.get()
    p.join()
    return out


def fmt(wc):
    return f"{wc[0]:7.2f} s ({wc[1]:6.2f} CPU)"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="subdivided,defects")
    ap.add_argument("--lam", default="0.2,0.4")
    ap.add_argument("--coarse", type=int, default=20000)
    ap.add_argument("--exponents", default=None,
                    help="coarse λ correction exponents, comma-separated (default: "
                         "ProgressiveParams'); the first is used for the ratios")
    ap.add_argument("--no-direct", action="store_true")
    ap.add_argument("--sweep", action="store_true")
    args = ap.parse_args()
    from algorithms.deform.progressive import ProgressiveParams

    exponent = ([ProgressiveParams().lam_exponent] if args.exponents is None
                else [float(x) for x in args.exponents.split(",")])
    lams = [float(x) for x in args.lam.split(",")]
    print(f"load: {os.getloadavg()}; coarse m = {args.coarse:,}; λ correction exponent "
          f"{exponent}")
    for case in [c for c in args.cases.split(",") if c]:
        r = child(run_progressive, case, lams, args.coarse, exponent)
        pre = [sum(r[k][i] for k in ("decimate", "splits", "clusters", "stylizer"))
               for i in (0, 1)]
        print(f"\n[{case}] {r['n']:,} vertices, {r['m']:,} triangles ({'; '.join(r['notes'])})")
        print(f"  pre-processing {fmt(pre)}: decimation {fmt(r['decimate'])}, split weights "
              f"{fmt(r['splits'])}, cluster labels {fmt(r['clusters'])}, coarse stylizer "
              f"{fmt(r['stylizer'])}; {r['regularized']:,} regularized splits")
        for run in r["runs"]:
            online = [run["solve"][i] + run["replay"][i] for i in (0, 1)]
            print(f"  λ {run['lam']} (exponent {run['exponent']}): online {fmt(online)} = "
                  f"coarse solve {fmt(run['solve'])} "
                  f"({run['iterations']} iterations, coarse λ {run['coarse_lam']:.3f}) + replay "
                  f"{fmt(run['replay'])}; L1 {r['l1_in']:.4f} -> {run['l1']:.4f}")
        print(f"  PLY write {fmt(r['write'])}, read {fmt(r['read'])}; peak memory "
              f"{r['peak_gb']:.2f} GB (mesh alone {r['load_gb']:.2f} GB)", flush=True)
        if not args.no_direct:
            d = child(run_direct, case, lams[0])
            run = r["runs"][0]
            prog_total = pre[0] + run["solve"][0] + run["replay"][0]
            direct_total = d["pre"][0] + d["solve"][0]
            dp, dd = r["l1_in"] - run["l1"], r["l1_in"] - d["l1"]
            print(f"  direct (peer), λ {lams[0]}: factorization {fmt(d['pre'])}, solve "
                  f"{fmt(d['solve'])} ({d['iterations']} iterations); L1 -> {d['l1']:.4f}; "
                  f"peak {d['peak_gb']:.2f} GB")
            print(f"  ratios: direct / progressive whole run {direct_total / prog_total:.2f}; "
                  f"direct / online {direct_total / (run['solve'][0] + run['replay'][0]):.1f}; "
                  f"cubeness change progressive / direct {dp:.4f} / {dd:.4f} = {dp / dd:.3f}",
                  flush=True)
    if args.sweep:
        print("\nbreak-even sweep (one λ, whole run, wall s; CPU s in brackets)")
        for case in ("bob1", "rocker1", "armadillo1", "bob2"):
            r = child(run_progressive, case, lams[:1], args.coarse, exponent)
            d = child(run_direct, case, lams[0])
            pre = [sum(r[k][i] for k in ("decimate", "splits", "clusters", "stylizer"))
                   for i in (0, 1)]
            run = r["runs"][0]
            pt = [pre[i] + run["solve"][i] + run["replay"][i] for i in (0, 1)]
            dt = [d["pre"][i] + d["solve"][i] for i in (0, 1)]
            dp, dd = r["l1_in"] - run["l1"], r["l1_in"] - d["l1"]
            print(f"  {case:>10} {r['m']:>9,} triangles: progressive {pt[0]:6.1f} "
                  f"({pt[1]:6.1f}), direct {dt[0]:6.1f} ({dt[1]:6.1f}); direct/progressive "
                  f"{dt[0] / pt[0]:.2f} (CPU {dt[1] / pt[1]:.2f}); cubeness ratio "
                  f"{dp / dd:.3f}", flush=True)
    print(f"\nload at the end: {os.getloadavg()}")
    print(json.dumps({"note": "targets (issue 25): pre-processing <= 60 s, online <= 4 s, "
                              "peak <= 2 GB at ~1M triangles, cubeness ratio 0.9..1.1"}))


if __name__ == "__main__":
    main()
