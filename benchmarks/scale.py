"""The scale table (issue 25): five methods at about 10^4, 10^5 and 10^6 vertices, each against
the peer its own benchmark uses, with seconds, peak memory and the fitted growth exponent.

Meshes: tests/data/armadillo.obj (14,587 vertices) and its Loop subdivisions
(``algorithms.mesh.loop_subdivide``: libigl's rules, the same bits as ``igl.loop``): 58k, 233k
and 933k vertices. A
requested size goes to the level whose vertex count is nearest on a log scale (1e4 -> 14.6k,
1e5 -> 58k, 1e6 -> 933k). The meshes are built once, by a child process, into a cache folder.

Every (method, size, side) case -- side = ours or the peer -- runs in a fresh child process
(``--case``), so its peak memory is that process's ``ru_maxrss`` (``resource.getrusage`` in the
child; the parent imports only the standard library, so the children's figures are not raised
by the parent's own pages, which Linux counts into a child's ru_maxrss across exec). "base" is the
child's ru_maxrss after its imports and warm-up, before the mesh is loaded; peak - base is what
the case itself needed (mesh included). Each case has a timeout (``--timeout``, default 600 s);
a case that times out or fails is printed as such in the table, never dropped.

What is timed (wall clock; median of 3 repeats below 10^5 vertices, one run above, 1 in --quick):

  cubic        ours: CubicStylizer(V, F) (normalization, normals, areas, ARAP system and its
               CHOLMOD factorization) = "set-up"; then ``steps`` with a fixed number of
               iterations (``--iterations``, default 20; stopping rule off, thesis λ 0.2)
               = "per iteration" (the whole loop / iterations: ADMM local step, right-hand side,
               prefactored solve, energy and metrics). Numba kernels loaded before (warm-up on an
               icosphere).
  analogies    ours: ShapeAnalogy(V, F, cube) + its spokes-and-rims ARAP system = "set-up";
               ``steps`` (ARAP regularizer, cube style, λ 1, fixed targets, the same number of
               iterations, stopping rule off) = "per iteration".
  arap (igl)   the peer of both (benchmarks/cubic.py and analogies.py): libigl's ARAP,
               SPOKES_AND_RIMS, one pinned vertex; ``igl.arap_precomputation`` = "set-up",
               ``igl.arap_solve`` with max_iter = the same iterations, from the input = "per
               iteration". Run once per size and used as the peer of both rows.
  multigrid    data smoothing (Eq. 8.16), Dirichlet energy, alpha 1e-3, rtol 1e-5, on the mesh
               normalized to a unit box (benchmarks/multigrid.py). ours: surface_multigrid
               (V, F) = "hierarchy"; DataSmoother precomputation (Q, M, Galerkin products) =
               "Galerkin set-up"; ``DataSmoother.smooth`` for the new alpha (system matrices,
               smoother, coarse factor, V-cycle-preconditioned CG to rtol) = "solve"; a run that
               does not converge is an error. peer: CHOLMOD (``SPDSolver(backend="cholmod")``)
               factor = "factor", solve = "solve", and "factor + solve" (the cost of a new alpha).
               BLAS threads 1, as in benchmarks/multigrid.py.
  subdivision  one level; the input is chosen so that the OUTPUT has the table's vertex count:
               armadillo QSlim-ed to ~3.65k vertices for the 14.6k output, else the previous Loop
               level (14.6k -> 58k, 58k -> 233k, 233k -> 933k). ours: neural subdivision with the
               shipped weights, NumPy inference (``neural_subdivide_np``), ``adapt_scale=False``
               (the network always runs; by default a mesh denser than the training meshes gets
               Loop instead) = "one level"; loading the network = "load". peer: Loop,
               ``algorithms.mesh.loop_subdivide`` (libigl's rules) = "one level".
  paparazzi    the mesh normalized to a unit box x 2, offset surface at 0.1, 128^2 views
               (benchmarks/paparazzi.py). ours: offset surface + camera sampling = "set-up"
               (not part of an iteration); per iteration = ``render`` (rasterize + Lambertian
               shading) + ``image_vjp`` (d image / d vertices) for a random image gradient, median
               over ``--views`` views (default 5). peer: our rasterizer's face ids + PyTorch
               autograd through the shading (float64, one thread, normals of all faces;
               ``benchmarks.paparazzi.torch_peer``) = "per iteration". Not included: the image
               filter, NAdam and remeshing (they do not depend on the mesh size, or run every
               30 iterations).

The exponent a of time ~ n^a is the least-squares slope of log(seconds) on log(n) over the sizes
that finished (n = vertices; the output's for subdivision). The table is printed and, with
``--out``, written as Markdown (machine, load average before/after, date, the exact command);
the file is rewritten after every case, so a run that is stopped leaves what finished.

Usage: .venv/bin/python benchmarks/scale.py [--sizes 1e4,1e5,1e6] [--methods cubic,...]
       [--quick] [--iterations 20] [--views 5] [--timeout 600] [--out docs/scale.md]
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE_MESH = "armadillo.obj"
METHODS = ("cubic", "analogies", "multigrid", "subdivision", "paparazzi")
# (method, side) -> the child case that measures it; cubic and analogies share one ARAP peer
CASES = {
    ("cubic", "ours"): "cubic",
    ("cubic", "peer"): "arap_igl",
    ("analogies", "ours"): "analogies",
    ("analogies", "peer"): "arap_igl",
    ("multigrid", "ours"): "multigrid",
    ("multigrid", "peer"): "cholmod",
    ("subdivision", "ours"): "neural",
    ("subdivision", "peer"): "loop_igl",
    ("paparazzi", "ours"): "render",
    ("paparazzi", "peer"): "torch",
}
# the measure each case is compared and fitted on, then the others it reports
MAIN = {
    "cubic": "per iteration", "analogies": "per iteration", "arap_igl": "per iteration",
    "multigrid": "solve", "cholmod": "factor + solve",
    "neural": "one level", "loop_igl": "one level",
    "render": "per iteration", "torch": "per iteration",
}
LABEL = {
    "cubic": "cubic stylization (ours)", "analogies": "shape analogies, ARAP (ours)",
    "arap_igl": "ARAP (libigl)", "multigrid": "surface multigrid (ours)",
    "cholmod": "CHOLMOD direct", "neural": "neural subdivision (ours)",
    "loop_igl": "Loop (libigl)", "render": "render + VJP (ours)",
    "torch": "raster + PyTorch autograd",
}
PEER_NAME = {"cubic": "libigl ARAP", "analogies": "libigl ARAP", "multigrid": "CHOLMOD",
             "subdivision": "libigl Loop", "paparazzi": "PyTorch"}
SUBDIV_COARSE = 3650  # QSlim target for the input whose one-level output is ~14.6k vertices


# ---------------------------------------------------------------------------------------------
# table and fit (standard library only: the parent must stay small, see the module docstring)
# ---------------------------------------------------------------------------------------------

def fit_exponent(ns, ts) -> float | None:
    """Least-squares slope ``a`` of ``log t = a log n + c``; None with fewer than two usable
    points (positive, finite) or a single distinct n."""
    pts = [(math.log(n), math.log(t)) for n, t in zip(ns, ts)
           if n and t is not None and n > 0 and t > 0 and math.isfinite(t)]
    if len(pts) < 2:
        return None
    mx = sum(x for x, _ in pts) / len(pts)
    my = sum(y for _, y in pts) / len(pts)
    sxx = sum((x - mx) ** 2 for x, _ in pts)
    if sxx <= 0:
        return None
    return sum((x - mx) * (y - my) for x, y in pts) / sxx


def level_for_size(target: float, n0: int, levels: int = 3) -> int:
    """The Loop level (0..levels) of an n0-vertex mesh whose vertex count (~n0 4^k) is nearest
    to ``target`` on a log scale."""
    k = round(math.log(max(target, 1.0) / n0, 4))
    return int(min(max(k, 0), levels))


def fmt_seconds(t: float) -> str:
    if t >= 100:
        return f"{t:.0f}"
    if t >= 10:
        return f"{t:.1f}"
    if t >= 1:
        return f"{t:.2f}"
    if t >= 0.01:
        return f"{t:.3f}"
    return f"{t:.2g}"


def fmt_n(n: int) -> str:
    return f"{n / 1e6:.2f}M" if n >= 10**6 else f"{n / 1e3:.1f}k"


def _cell(case: dict | None, measure: str, timeout: float) -> str:
    if case is None:
        return "not run"
    if case["status"] == "timeout":
        return f"timeout ({timeout:.0f} s)"
    if case["status"] != "ok":
        return "error"
    v = case["measures"].get(measure)
    return "-" if v is None else fmt_seconds(v)


def _fmt_a(a: float | None) -> str:
    return "-" if a is None else f"{a:.2f}"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def _measures(cases: list[dict], name: str) -> list[str]:
    seen: list[str] = []
    for c in cases:
        if c["case"] == name and c["status"] == "ok":
            seen += [m for m in c["measures"] if m not in seen]
    main = MAIN.get(name)
    if main in seen or not seen:
        seen = [main] + [m for m in seen if m != main]
    return seen


def build_tables(cases: list[dict], levels: list[int], methods: list[str],
                 timeout: float = 600.0) -> list[str]:
    """Markdown lines: seconds per (case, measure) and size with the fitted exponent; ours / peer
    per method and size; peak memory per case and size. ``cases``: the children's reports
    (``case``, ``level``, ``n``, ``status``, ``measures`` {name: seconds}, ``peak_mb``,
    ``base_mb``), one per case and level (several methods may share one case)."""
    by = {(c["case"], c["level"]): c for c in cases}
    names: list[str] = []
    for m in methods:
        for side in ("ours", "peer"):
            if CASES[(m, side)] not in names:
                names.append(CASES[(m, side)])

    def n_of(name, lev):
        c = by.get((name, lev))
        return c.get("n") if c else None

    def size_label(lev):
        at = [c for c in cases if c["level"] == lev and c.get("n")]
        # the mesh's own count; subdivision's outputs only when nothing else ran at this level
        ns = sorted({c["n"] for c in at if c["case"] not in ("neural", "loop_igl")}) or \
            sorted({c["n"] for c in at})
        return fmt_n(ns[0]) if ns else f"level {lev}"

    sizes = [size_label(lev) for lev in levels]
    lines = ["Seconds (wall clock) per measure and mesh size (vertices); a = fitted exponent of "
             "time ~ n^a over the sizes that finished.", ""]
    rows = []
    for name in names:
        for meas in _measures(cases, name):
            cells, ns, ts = [], [], []
            for lev in levels:
                c = by.get((name, lev))
                cells.append(_cell(c, meas, timeout))
                if c and c["status"] == "ok" and c["measures"].get(meas) is not None:
                    ns.append(c["n"])
                    ts.append(c["measures"][meas])
            main = " **(compared)**" if meas == MAIN.get(name) else ""
            rows.append([LABEL.get(name, name), meas + main, *cells,
                         _fmt_a(fit_exponent(ns, ts))])
    lines += _table(["case", "measure", *sizes, "a"], rows)

    lines += ["", "Ours / peer on the compared measures (> 1: ours slower), same run.", ""]
    rows = []
    for m in methods:
        o, p = CASES[(m, "ours")], CASES[(m, "peer")]
        cells = []
        for lev in levels:
            co, cp = by.get((o, lev)), by.get((p, lev))
            bad = [(who, c) for who, c in (("ours", co), ("peer", cp))
                   if c is not None and c["status"] != "ok"]
            if bad:
                cells.append(", ".join(
                    f"{who} {'timed out' if c['status'] == 'timeout' else 'failed'}"
                    for who, c in bad))
            elif co is None or cp is None:
                cells.append("not run")
            else:
                a, b = co["measures"].get(MAIN[o]), cp["measures"].get(MAIN[p])
                cells.append("-" if not a or not b else f"{a / b:.2f}")
        rows.append([m, f"{MAIN[o]} / {PEER_NAME[m]} {MAIN[p]}", *cells])
    lines += _table(["method", "ratio of", *sizes], rows)

    lines += ["", "Peak memory of the case's process (ru_maxrss, MB) and, in brackets, the "
              "same process after imports and warm-up, before the mesh was loaded; a = fitted "
              "exponent of (peak - base) ~ n^a.", ""]
    rows = []
    for name in names:
        cells, ns, ms = [], [], []
        for lev in levels:
            c = by.get((name, lev))
            if c is None or c["status"] != "ok":
                cells.append(_cell(c, "", timeout))
                continue
            cells.append(f"{c['peak_mb']:.0f} ({c['base_mb']:.0f})")
            ns.append(c["n"])
            ms.append(c["peak_mb"] - c["base_mb"])
        rows.append([LABEL.get(name, name), *cells, _fmt_a(fit_exponent(ns, ms))])
    lines += _table(["case", *sizes, "a"], rows)

    notes = []
    for c in cases:
        if c["status"] == "timeout":
            notes.append(f"- {LABEL.get(c['case'], c['case'])}, level {c['level']}: timed out "
                         f"after {timeout:.0f} s (killed).")
        elif c["status"] != "ok":
            notes.append(f"- {LABEL.get(c['case'], c['case'])}, level {c['level']}: failed: "
                         f"{c.get('error', '?')}")
    details = [f"- {LABEL.get(c['case'], c['case'])} at {fmt_n(c['n'])}: {c['info']}"
               + (f" [whole process {c['wall']:.1f} s; load average after it {c['load']}]"
                  if "wall" in c and "load" in c else "")
               for c in cases if c["status"] == "ok" and c.get("info")]
    if notes:
        lines += ["", "Cases that did not finish:", "", *notes]
    if details:
        lines += ["", "Per case:", "", *details]
    return lines


# ---------------------------------------------------------------------------------------------
# the children (NumPy and the methods are imported here only)
# ---------------------------------------------------------------------------------------------

def _maxrss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _median_time(fn, repeat: int):
    """(result of the last call, median seconds over ``repeat`` calls)."""
    import statistics

    ts, out = [], None
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return out, statistics.median(ts)


def prepare(cache: Path, levels: list[int], subdivision: bool) -> None:
    """Child: write the meshes the cases need into ``cache`` (npz files)."""
    import numpy as np

    sys.path.insert(0, str(ROOT))
    from algorithms.mesh import loop_subdivide, read_mesh
    from benchmarks._timing import mesh_path

    base = read_mesh(mesh_path(BASE_MESH))
    need = set(levels)
    if subdivision:
        need |= {lev - 1 for lev in levels if lev > 0}
    for lev in sorted(need):
        p = cache / f"L{lev}.npz"
        if not p.exists():
            V, F = (base.V, base.F) if lev == 0 else loop_subdivide(base.V, base.F, lev)
            np.savez(p, V=V, F=F)
    if subdivision and 0 in levels and not (cache / "coarse.npz").exists():
        from algorithms.subdivision.metrics import coarsen_to_vertices

        V, F = coarsen_to_vertices(base.V, base.F, SUBDIV_COARSE)
        np.savez(cache / "coarse.npz", V=V, F=F)


def _load(cache: Path, name: str):
    import numpy as np

    d = np.load(cache / f"{name}.npz")
    return np.ascontiguousarray(d["V"], dtype=np.float64), np.ascontiguousarray(d["F"],
                                                                                dtype=np.int64)


def _icosphere():
    from algorithms.mesh import icosphere

    return icosphere(2)


def case_cubic(load, a) -> dict:
    from algorithms.deform.cubic import CubicParams, CubicStylizer

    Vs, Fs = _icosphere()
    for _ in CubicStylizer(Vs, Fs).steps(CubicParams(max_iterations=2)):
        pass
    base = _maxrss_mb()
    V, F = load()
    st, t_setup = _median_time(lambda: CubicStylizer(V, F), a.repeat)
    p = CubicParams(max_iterations=a.iterations, rel_displacement_tol=0.0)

    def run():
        k = 0
        for _ in st.steps(p):  # not kept: a list of Steps would hold every iterate
            k += 1
        if k != a.iterations:
            raise RuntimeError(f"ran {k} iterations, asked for {a.iterations}")
        return k

    _, t_run = _median_time(run, a.repeat)
    return dict(base_mb=base, n=len(V),
                measures={"set-up": t_setup, "per iteration": t_run / a.iterations},
                info=f"λ 0.2, {a.iterations} iterations (stopping rule off); median of "
                     f"{a.repeat}")


def case_analogies(load, a) -> dict:
    from algorithms.deform.analogies import AnalogyParams, ShapeAnalogy
    from algorithms.deform.targets import ClosestNormals

    cube = ClosestNormals.primitive("cube")
    Vs, Fs = _icosphere()
    for _ in ShapeAnalogy(Vs, Fs, cube).steps(AnalogyParams(max_iterations=2)):
        pass
    base = _maxrss_mb()
    V, F = load()

    def build():
        sa_ = ShapeAnalogy(V, F, cube)
        sa_.system("spokes_and_rims")
        return sa_

    sa, t_setup = _median_time(build, a.repeat)
    p = AnalogyParams(regularizer="arap", max_iterations=a.iterations, rel_displacement_tol=0.0)

    def run():
        k = 0
        for _ in sa.steps(p):
            k += 1
        if k != a.iterations:
            raise RuntimeError(f"ran {k} iterations, asked for {a.iterations}")

    _, t_run = _median_time(run, a.repeat)
    return dict(base_mb=base, n=len(V),
                measures={"set-up": t_setup, "per iteration": t_run / a.iterations},
                info=f"ARAP regularizer, cube, λ 1, fixed targets, {a.iterations} iterations "
                     f"(stopping rule off); median of {a.repeat}")


def case_arap_igl(load, a) -> dict:
    import igl
    import numpy as np

    base = _maxrss_mb()
    V, F = load()
    b = np.array([0], dtype=np.int32)

    def pre():
        d = igl.ARAPData()
        d.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
        d.max_iter = a.iterations
        igl.arap_precomputation(V, F, 3, b, d)
        return d

    data, t_setup = _median_time(pre, a.repeat)
    U0 = np.ascontiguousarray(V)
    bc = U0[[0]]
    _, t_run = _median_time(lambda: igl.arap_solve(bc, data, U0), a.repeat)
    return dict(base_mb=base, n=len(V),
                measures={"set-up": t_setup, "per iteration": t_run / a.iterations},
                info=f"SPOKES_AND_RIMS, 1 pinned vertex, max_iter {a.iterations}; median of "
                     f"{a.repeat}")


ALPHA, RTOL = 1e-3, 1e-5


def _smoothing_problem(V, F):
    import numpy as np

    from algorithms.mesh.operators import normalize_unit_box

    V = normalize_unit_box(V)[0]
    f = V[:, 1] + 0.05 * np.random.default_rng(0).standard_normal(len(V))
    return V, f


def case_multigrid(load, a) -> dict:
    from algorithms.multigrid import surface_multigrid
    from algorithms.multigrid.applications import DataSmoother

    Vs, Fs = _icosphere()
    ds = DataSmoother(Vs, Fs, "dirichlet", mg=surface_multigrid(Vs, Fs, min_vertices=40))
    ds.smooth(Vs[:, 0], ALPHA, rtol=RTOL, maxiter=300)
    base = _maxrss_mb()
    V, F = load()
    V, f = _smoothing_problem(V, F)
    mg, t_h = _median_time(lambda: surface_multigrid(V, F), 1)
    ds, t_g = _median_time(lambda: DataSmoother(V, F, "dirichlet", mg=mg), 1)
    (u, info), t_s = _median_time(lambda: ds.smooth(f, ALPHA, rtol=RTOL, maxiter=300), a.repeat)
    if not info.get("converged"):
        raise RuntimeError(f"multigrid smoothing did not converge to rtol {RTOL:g} in "
                           f"{info['cycles']} iterations (stop: {info.get('stop')})")
    levels = " -> ".join(f"{len(L[0]):,}" for L in mg.levels)
    return dict(base_mb=base, n=len(V),
                measures={"hierarchy": t_h, "Galerkin set-up": t_g, "solve": t_s},
                info=f"Dirichlet, alpha {ALPHA:g}, rtol {RTOL:g}: {info['cycles']} "
                     f"V-cycle-PCG iterations; levels {levels}; solve median of {a.repeat}, "
                     f"hierarchy and set-up one run each")


def case_cholmod(load, a) -> dict:
    from algorithms.linalg import SPDSolver
    from algorithms.mesh.operators import mass_matrix
    from algorithms.multigrid.applications import smoothness_matrix

    base = _maxrss_mb()
    V, F = load()
    V, f = _smoothing_problem(V, F)
    A = (ALPHA * smoothness_matrix(V, F, "dirichlet")
         + (1 - ALPHA) * mass_matrix(V, F)).tocsr()
    rhs = (1 - ALPHA) * (mass_matrix(V, F) @ f)
    fac, solve = [], []
    for _ in range(max(1, a.repeat)):
        t0 = time.perf_counter()
        s = SPDSolver(A, backend="cholmod")
        t1 = time.perf_counter()
        s.solve(rhs)
        t2 = time.perf_counter()
        fac.append(t1 - t0)
        solve.append(t2 - t1)
        del s
    import statistics

    both = statistics.median(x + y for x, y in zip(fac, solve))
    return dict(base_mb=base, n=len(V),
                measures={"factor + solve": both, "factor": statistics.median(fac),
                          "solve": statistics.median(solve)},
                info=f"Dirichlet, alpha {ALPHA:g}; median of {a.repeat}")


def case_neural(load, a) -> dict:
    from algorithms.subdivision.inference import load_network, neural_subdivide_np

    net, t_load = _median_time(lambda: load_network(None), 1)
    Vs, Fs = _icosphere()
    neural_subdivide_np(Vs, Fs, 1, net, adapt_scale=False)
    base = _maxrss_mb()
    V, F = load()
    out, t = _median_time(lambda: neural_subdivide_np(V, F, 1, net, adapt_scale=False),
                          a.repeat)
    return dict(base_mb=base, n=len(out[0]),
                measures={"one level": t, "load": t_load},
                info=f"input {len(V):,} vertices / {len(F):,} faces -> {len(out[0]):,} / "
                     f"{len(out[1]):,}; shipped weights, adapt_scale off; median of {a.repeat}")


def case_loop_igl(load, a) -> dict:
    from algorithms.mesh import loop_subdivide

    base = _maxrss_mb()
    V, F = load()
    out, t = _median_time(lambda: loop_subdivide(V, F, 1), a.repeat)
    return dict(base_mb=base, n=len(out[0]), measures={"one level": t},
                info=f"input {len(V):,} vertices -> {len(out[0]):,}; median of {a.repeat}")


def _views(V, F, a, cache: Path | None = None):
    """(V scaled, set-up seconds, cameras, image gradients, shading). The cameras are written to
    ``cache`` (ours) or read from it (the peer, when ours ran first: then it does not build the
    offset surface again, and its set-up is None)."""
    import numpy as np

    from algorithms.mesh.operators import normalize_unit_box
    from algorithms.paparazzi import offset_surface, sample_camera
    from algorithms.render import Camera, LambertianShading

    V = normalize_unit_box(V)[0] * 2
    Gs = [np.random.default_rng(i).standard_normal((128, 128, 3)) for i in range(a.views)]
    saved = None if cache is None else cache / f"cameras_{len(V)}_{a.views}.npz"
    if saved is not None and saved.exists() and not a.paparazzi_write:
        d = np.load(saved)
        near = [None if np.isnan(x) else float(x) for x in d["near"]]
        cams = [Camera(position=d["position"][i], direction=d["direction"][i], up=d["up"][i],
                       projection=str(d["projection"]), width=float(d["width"]),
                       fov=float(d["fov"]), resolution=128, near=near[i])
                for i in range(a.views)]
        return V, None, cams, Gs, LambertianShading()
    t0 = time.perf_counter()
    off = offset_surface(V, F, 0.1)
    rng = np.random.default_rng(0)
    cams = [sample_camera(off, rng, resolution=128) for _ in range(a.views)]
    t_setup = time.perf_counter() - t0
    if saved is not None and a.paparazzi_write:
        np.savez(saved, position=np.array([c.position for c in cams]),
                 direction=np.array([c.direction for c in cams]),
                 up=np.array([c.up for c in cams]), projection=cams[0].projection,
                 width=cams[0].width, fov=cams[0].fov,
                 near=np.array([np.nan if c.near is None else c.near for c in cams]))
    return V, t_setup, cams, Gs, LambertianShading()


def _warm_render(peer: bool):
    import numpy as np

    from algorithms.paparazzi import offset_surface, sample_camera
    from algorithms.render import LambertianShading, image_vjp, rasterize, render

    Vs, Fs = _icosphere()
    cam = sample_camera(offset_surface(Vs, Fs, 0.1), np.random.default_rng(0), resolution=128)
    G = np.ones((128, 128, 3))
    sh = LambertianShading()
    if peer:
        from benchmarks.paparazzi import torch_peer

        torch_peer(Vs, Fs, rasterize(Vs, Fs, cam).face_id, G, sh.light_matrix(cam))
    else:
        image_vjp(Vs, Fs, render(Vs, Fs, cam, sh), G)


def case_render(load, a) -> dict:
    import statistics

    from algorithms.render import image_vjp, render

    _warm_render(False)
    base = _maxrss_mb()
    V, F = load()
    a.paparazzi_write = True
    V, t_setup, cams, Gs, sh = _views(V, F, a, a.cache_dir)
    ts, seen = [], []
    for cam, G in zip(cams, Gs):
        t = time.perf_counter()
        r = render(V, F, cam, sh)
        image_vjp(V, F, r, G)
        ts.append(time.perf_counter() - t)
        seen.append(len(r.faces))
    if min(seen) == 0:
        raise RuntimeError("a view saw no face: the timing would not be a rendering's")
    return dict(base_mb=base, n=len(V),
                measures={"per iteration": statistics.median(ts), "set-up": t_setup},
                info=f"128^2, median over {a.views} views ({int(statistics.median(seen)):,} of "
                     f"{len(F):,} faces seen, median); set-up = offset surface + cameras")


def case_torch(load, a) -> dict:
    import statistics

    import torch

    torch.set_num_threads(1)
    from algorithms.render import rasterize
    from benchmarks.paparazzi import torch_peer

    _warm_render(True)
    base = _maxrss_mb()
    V, F = load()
    a.paparazzi_write = False
    V, t_off, cams, Gs, sh = _views(V, F, a, a.cache_dir)
    ts = []
    for cam, G in zip(cams, Gs):
        t = time.perf_counter()
        torch_peer(V, F, rasterize(V, F, cam).face_id, G, sh.light_matrix(cam))
        ts.append(time.perf_counter() - t)
    return dict(base_mb=base, n=len(V), measures={"per iteration": statistics.median(ts)},
                info=f"128^2, median over {a.views} views; torch {torch.__version__}, 1 thread, "
                     f"float64; cameras " + ("from the render case" if t_off is None else
                                             "sampled again (no render case ran)"))


CASE_FUNCTIONS = {
    "cubic": case_cubic, "analogies": case_analogies, "arap_igl": case_arap_igl,
    "multigrid": case_multigrid, "cholmod": case_cholmod, "neural": case_neural,
    "loop_igl": case_loop_igl, "render": case_render, "torch": case_torch,
}
ONE_BLAS_THREAD = {"multigrid", "cholmod"}  # as benchmarks/multigrid.py


def run_case_child(name: str, level: int, cache: Path, a) -> None:
    """Child: run one case and print its report as one JSON line. The case loads its mesh
    (``load()``) after its imports and warm-up, so "base" excludes the mesh."""
    sys.path.insert(0, str(ROOT))
    mesh = ("coarse" if level == 0 else f"L{level - 1}") if name in ("neural", "loop_igl") \
        else f"L{level}"
    t0 = time.perf_counter()
    a.cache_dir = cache
    out = CASE_FUNCTIONS[name](lambda: _load(cache, mesh), a)
    out.update(case=name, level=level, status="ok", peak_mb=_maxrss_mb(),
               seconds_child=time.perf_counter() - t0)
    print("SCALE-JSON " + json.dumps(out), flush=True)


# ---------------------------------------------------------------------------------------------
# the parent
# ---------------------------------------------------------------------------------------------

def _count_vertices(path: Path) -> int:
    with open(path, encoding="utf-8", errors="replace") as fh:
        return sum(1 for line in fh if line.startswith("v "))


def _load_text() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def machine() -> str:
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = "?"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} logical CPUs, {mem} RAM; {platform.system()} "
            f"{platform.release()}; Python {platform.python_version()}")


def _child_env(name: str) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    if name in ONE_BLAS_THREAD:
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env.setdefault(var, "1")
    return env


def run_case(name: str, level: int, cache: Path, a) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--case", name, str(level),
           "--cache", str(cache), "--iterations", str(a.iterations), "--views", str(a.views),
           "--repeat", str(a.repeat if a.n0 * 4 ** level < 10**5 else 1)]
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=a.timeout,
                           env=_child_env(name), cwd=ROOT)
    except subprocess.TimeoutExpired:
        return dict(case=name, level=level, status="timeout", wall=time.perf_counter() - t0)
    for line in r.stdout.splitlines():
        if line.startswith("SCALE-JSON "):
            out = json.loads(line[len("SCALE-JSON "):])
            out["wall"] = time.perf_counter() - t0
            return out
    tail = (r.stderr.strip().splitlines() or r.stdout.strip().splitlines() or ["no output"])[-1]
    return dict(case=name, level=level, status="error", error=f"exit {r.returncode}: {tail}",
                wall=time.perf_counter() - t0)


def document(cases, levels, methods, a, meta: dict, finished: bool) -> list[str]:
    lines = ["# Scale table", "",
             "Written by `benchmarks/scale.py` from one run (nothing typed by hand); "
             "see the script's docstring for exactly what each measure includes.", "",
             f"- command: `{meta['command']}`",
             f"- date (UTC): {meta['start']} -> {meta.get('end', 'still running')}",
             f"- machine: {meta['machine']}",
             f"- load average (1/5/15 min) before: {meta['load_before']}; after: "
             f"{meta.get('load_after', 'still running')} (the machine is shared: absolute "
             f"seconds are inflated by other processes; ours / peer of one size ran one after "
             f"the other)",
             f"- meshes: {BASE_MESH} (tests/data) and its Loop subdivisions; iterations "
             f"{a.iterations} (cubic, analogies, ARAP), views {a.views} (Paparazzi); median of "
             f"{a.repeat} runs below 10^5 vertices, one run above; per-case timeout "
             f"{a.timeout:.0f} s; every case in its own process; Numba and BLAS threads as the "
             f"environment sets them (BLAS 1 thread for multigrid and CHOLMOD, torch 1 thread)",
             ""]
    if not finished:
        lines += ["**Incomplete: the run had not finished when this file was written; only the "
                  "cases shown ran.**", ""]
    return lines + build_tables(cases, levels, methods, a.timeout) + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1e4,1e5,1e6",
                    help="target vertex counts, comma separated (nearest Loop level of "
                         "armadillo: 14.6k, 58k, 233k, 933k)")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma separated, of {', '.join(METHODS)}")
    ap.add_argument("--quick", action="store_true",
                    help="10^4 only, 5 iterations, 3 views, 1 repeat (for development)")
    ap.add_argument("--iterations", type=int, default=None,
                    help="local-global iterations of cubic / analogies / ARAP (default 20)")
    ap.add_argument("--views", type=int, default=None, help="Paparazzi views (default 5)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="repeats below 10^5 vertices (default 3; one above)")
    ap.add_argument("--timeout", type=float, default=600.0, help="per case, seconds")
    ap.add_argument("--out", default="", help="also write the table as Markdown here")
    ap.add_argument("--cache", default="", help="mesh cache folder (default: a temporary one)")
    ap.add_argument("--case", nargs=2, metavar=("NAME", "LEVEL"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    a.iterations = a.iterations or (5 if a.quick else 20)
    a.views = a.views or (3 if a.quick else 5)
    if a.case:
        name, level = a.case[0], int(a.case[1])
        a.repeat = a.repeat or 1
        run_case_child(name, level, Path(a.cache), a)
        return 0

    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in METHODS]
    if bad:
        ap.error(f"unknown method(s) {', '.join(bad)}; choose from {', '.join(METHODS)}")
    if a.repeat is None:
        a.repeat = 1 if a.quick else 3
    n0 = a.n0 = _count_vertices(ROOT / "tests" / "data" / BASE_MESH)
    targets = [1e4] if a.quick else [float(s) for s in a.sizes.split(",") if s.strip()]
    levels = sorted({level_for_size(t, n0) for t in targets})
    exe = Path(sys.executable)
    try:
        exe_text = str(exe.relative_to(ROOT))
    except ValueError:
        exe_text = str(exe)
    args_text = shlex.join(sys.argv[1:] if argv is None else argv)
    meta = dict(command=f"{exe_text} benchmarks/scale.py"
                + (f" {args_text}" if args_text else ""),
                start=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
                machine=machine(), load_before=_load_text())
    print(f"scale table: {', '.join(methods)} at levels {levels} of {BASE_MESH} ({n0:,} "
          f"vertices x ~4^level); {meta['machine']}; load average {meta['load_before']}",
          flush=True)

    tmp = None
    if a.cache:
        cache = Path(a.cache)
        cache.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="s3d-scale-")
        cache = Path(tmp.name)
    cases: list[dict] = []
    try:
        t = time.perf_counter()
        sub = "subdivision" in methods
        r = subprocess.run([sys.executable, "-c",
                            "import sys; sys.path.insert(0, sys.argv[1]); "
                            "from benchmarks.scale import prepare; from pathlib import Path; "
                            "prepare(Path(sys.argv[2]), [int(x) for x in sys.argv[3].split(',')],"
                            " sys.argv[4] == '1')",
                            str(ROOT), str(cache), ",".join(map(str, levels)),
                            "1" if sub else "0"],
                           capture_output=True, text=True, cwd=ROOT, env=_child_env(""))
        if r.returncode != 0:
            print(f"preparing the meshes failed:\n{r.stderr[-3000:]}", file=sys.stderr)
            return 1
        print(f"meshes prepared in {time.perf_counter() - t:.1f} s", flush=True)
        for lev in levels:
            done: set[str] = set()
            for m in methods:
                for side in ("ours", "peer"):
                    name = CASES[(m, side)]
                    if name in done:
                        continue
                    done.add(name)
                    c = run_case(name, lev, cache, a)
                    c["load"] = _load_text()
                    cases.append(c)
                    if c["status"] == "ok":
                        what = ", ".join(f"{k} {fmt_seconds(v)} s"
                                         for k, v in c["measures"].items())
                        print(f"  {LABEL[name]:<30} {fmt_n(c['n']):>7}: {what}; peak "
                              f"{c['peak_mb']:.0f} MB (base {c['base_mb']:.0f}); process "
                              f"{c['wall']:.1f} s  [load {_load_text()}]", flush=True)
                    else:
                        print(f"  {LABEL[name]:<30} level {lev}: {c['status']} "
                              f"{c.get('error', '')} after {c['wall']:.0f} s  "
                              f"[load {_load_text()}]", flush=True)
                    if a.out:
                        _write(a.out, document(cases, levels, methods, a, meta, False))
    finally:
        if tmp is not None:
            tmp.cleanup()
    meta["end"] = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    meta["load_after"] = _load_text()
    doc = document(cases, levels, methods, a, meta, True)
    print()
    print("\n".join(doc))
    if a.out:
        _write(a.out, doc)
        print(f"wrote {a.out}")
    return 0


def _write(path: str, lines: list[str]) -> None:
    p = Path(path)
    if not p.is_absolute():
        p = ROOT / p
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("\n".join(lines), encoding="utf-8")


if __name__ == "__main__":
    sys.exit(main())
