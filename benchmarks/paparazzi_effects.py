"""Paparazzi per-filter effects (issues 12 and 23): each filter, with the CLI's defaults, lowers its
own energy averaged over 16 fixed monitor views, changes the shape measurably in its own way,
beats remeshing alone (the control) and leaves a clean 2-manifold with the input's topology.

    python benchmarks/paparazzi_effects.py [--meshes spot_lowres.obj bob.obj fandisk.off
        camelhead.off blob.obj bumpy.obj pretzel.obj] [--filters guided quantize slic l0
        neural-style] [--iterations 1000] [--no-sheets] [--remesh-scope bad|all]
    python benchmarks/paparazzi_effects.py --corpus DIR [--max-faces N] [--time-limit S]
        --json FILE --no-sheets; then --summary FILE (issue 38: every corpus mesh as the
        command line reads it, cleaned when it is not a 2-manifold, not subdivided)
    python benchmarks/paparazzi_effects.py --suspects [--meshes bob.obj fandisk.off]
    python benchmarks/paparazzi_effects.py --noisy [--save DIR] [--sheet-tag _noisy]
    python benchmarks/paparazzi_effects.py --pretzel [--iterations 1000]
    python benchmarks/paparazzi_effects.py --noise-variance
    python benchmarks/paparazzi_effects.py --barrier [--meshes ...] [--filters guided l0]

For each mesh (tests/data, ../shared/meshes or resources/samples; Loop-subdivided until it has at
least 5,000 vertices, e.g. spot 829 -> 13,234; the bundled samples are used as they are) and each
filter, runs ``Paparazzi`` with ``PaparazziParams(iterations=N)`` and the filter's default Params
-- exactly what ``stylize3d paparazzi MESH -o OUT --filter NAME`` builds from its flags' defaults
-- and the *control*: the same run with a filter that returns each picture unchanged (nothing
pulls on the surface; only the remeshing acts, with the filter's own remeshing settings). One row
per run:

  E16 before -> after   the run's monitor energy (mean over the 16 fixed monitor views, the
                        filter's own energy: 1/2 |f(R) - R|^2 over the foreground); must fall
  measure               the filter's shape measure before -> after, and the control's after;
                        "beats" says whether the filter moved it further than the control
  crease5               (guided) share of the length of the input's sharp edges (> 30 deg) whose
                        dihedral angle the output keeps within 5 deg (measures.crease_fraction)
  checks                2-manifold, same Euler characteristic and boundary loops, libigl
                        self-intersecting pairs in -> out

Measures (algorithms/paparazzi/measures.py): quantize palette15 (up); slic, l0 planar3 (up;
also flat1); guided bending sum |L V|^2 / M (down); neural-style Gram16: the Gram loss of each
monitor view (of the 16 the shape covers at least half of) against the style (its ``gram``
energy, the default since issue 23's seventh pass) or, with ``--energy network``, against the
network's stylization of the view, averaged (down; until 26 November 2026 monitor view 0
alone).

Unless --no-sheets, writes one contact sheet per filter, docs/images/paparazzi_<filter>.png:
one row per mesh, before / after / control, rendered off-screen with a grey light from a fixed
three-quarter view (algorithms.render).

``--noisy`` runs issue 23's noisy scans (``noisy:fandisk.off``, ``noisy:bob.obj``: Gaussian
noise of 0.3 mean edge lengths along the vertex normals, seed 0); crease5 and the distances are
then measured against the clean mesh. ``--pretzel`` measures why the guided energy of the pretzel
sample rises, ``--noise-variance`` why the guided filter cannot both remove that noise and keep
fandisk's creases (docs/results/paparazzi.md).

``--suspects`` measures, for the guided filter, each suspect of issue 23 separately (see
docs/results/paparazzi.md): the filter's change per view against the optimizer's step, the radius
against the triangles' size in pixels, what a remeshing does to the energy, resolution and the
defaults (old: radius 15, epsilon 1e-8; the thesis's Fig. 2.15: radius 4, epsilon 0.02).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._timing import mesh_path  # noqa: E402

MIN_VERTICES = 5000
SAMPLES = ROOT / "resources" / "samples"


#: issue 23's noisy scans: Gaussian noise of this many mean edge lengths along the vertex
#: normals, from this seed (``noisy:bob.obj``, ``noisy:fandisk.off``)
NOISE, NOISE_SEED = 0.3, 0


def load(name):
    """``(V, F)`` of a mesh name (``noisy:NAME``: that mesh with :data:`NOISE`), or None."""
    from algorithms.mesh import loop_subdivide, read_mesh

    if name.startswith("noisy:"):
        from algorithms.paparazzi.measures import noisy_scan

        got = load(name[len("noisy:"):])
        return None if got is None else (noisy_scan(*got, NOISE, NOISE_SEED), got[1])
    if Path(name).is_file():             # --corpus: a file, as the command line reads it
        return load_as_cli(Path(name))
    p = SAMPLES / name if (SAMPLES / name).exists() else mesh_path(name)
    if not p.exists():
        return None
    d = read_mesh(p)
    V, F = d.V, d.F
    if p.parent != SAMPLES:
        while len(V) < MIN_VERTICES:
            V, F = loop_subdivide(V, F, 1)
    return V, F


def load_as_cli(path):
    """``(V, F)`` of a mesh file as ``stylize3d paparazzi FILE --clean`` runs on it (the
    command's own reader: cleaned when validation asks for it), or the refusal's message (a
    str) when it stays unusable."""
    from app.cli.common import read_valid
    from app.recipes.paparazzi import manifold_report

    try:
        data, _ = read_valid(str(path), clean=True, quiet=True)
    except Exception as e:  # noqa: BLE001 - the command refuses it too
        return f"refused: {str(e).splitlines()[0][:160]}"
    if manifold_report(data.V, data.F) is not None:
        return "refused: not a 2-manifold after clean"
    return data.V, data.F


def clean_of(name):
    """The clean mesh a ``noisy:`` name was made from (the reference of crease5 and of the
    distance to the clean shape); the mesh itself otherwise."""
    return load(name[len("noisy:"):] if name.startswith("noisy:") else name)


def _gram_monitor(run, V, F, views=1):
    """Gram loss of a monitor view of world-frame V: against the style's Gram matrices (the
    ``gram`` energy's own: the filter's energy of that view), or, with the ``network`` energy,
    against the network's stylization of the view; view 0 (``views=1``), or the mean over the
    first ``views`` monitor views that the shape covers at least half of (``views=16``:
    *Gram16*; one view is a noisy judge, see docs/results/paparazzi.md)."""
    from algorithms.paparazzi.filters import FilterContext
    from algorithms.paparazzi.neural_style import gram_style_loss
    from algorithms.render import render

    X = (np.asarray(V) - run.center) / run.scale
    losses = []
    for cam in run.monitor_cameras()[:views]:
        r = render(X, F, cam, run.shading)
        if views > 1 and r.mask.mean() < 0.5:
            continue
        ctx = FilterContext(camera=cam, mask=r.mask, state=run.state)
        E, _, styled = run.spec.function(r.image, run.filter_params, ctx)
        losses.append(E if run.filter_params.energy == "gram"
                      else gram_style_loss(r.image, styled))
    return float(np.mean(losses))


def measure(name, run, V, F):
    from algorithms.paparazzi import bending_energy, palette_fraction, planar_area_fraction

    if name == "quantize":
        return "palette15", palette_fraction(V, F), +1
    if name in ("slic", "l0"):
        return "planar3", planar_area_fraction(V, F), +1
    if name == "guided":
        return "bending", bending_energy(V, F), -1
    if name == "neural-style":
        return "gram16", _gram_monitor(run, V, F, views=16), -1
    raise KeyError(name)


def control_spec(spec):
    """The filter's control: the image itself, with the filter's resolution and remeshing."""
    return dataclasses.replace(spec, name=f"{spec.name}-control", kind="iterative",
                               function=lambda image, params, ctx: image, min_change=0.0)


#: ``--remesh-scope``: PaparazziParams.remesh_scope of every run here
SCOPE = "bad"


def PP(**kw):
    """``PaparazziParams`` with this run's ``--remesh-scope``."""
    from algorithms.paparazzi import PaparazziParams

    return PaparazziParams(remesh_scope=SCOPE, **kw)


def run_filter(V, F, spec, fparams, params, limit=None):
    """Run to the end; with ``limit`` (seconds) stop there instead: then ``last`` is None and
    the fourth value the iterations done (``--time-limit``: an over-time run, not a result)."""
    from algorithms.paparazzi import Paparazzi

    t = time.perf_counter()
    run = Paparazzi(V, F, spec, fparams, params)
    last, done = None, 0
    for last in run.steps():
        done += 1
        if limit is not None and time.perf_counter() - t > limit and done < params.iterations:
            return run, None, time.perf_counter() - t, done
    return run, last, time.perf_counter() - t, done


def view_picture(V, F, size=256):
    """A grey flat-shaded picture of ``(V, F)`` from a fixed three-quarter view (uint8)."""
    from algorithms.render import LambertianShading, look_at, render

    c = (V.max(0) + V.min(0)) / 2
    s = float(np.linalg.norm(V.max(0) - V.min(0)))
    X = (V - c) / s * 2.0
    cam = look_at((1.6, 1.0, 2.4), (0, 0, 0), width=2.2, resolution=size)
    sh = LambertianShading(directions=[[0.35, 0.6, 1.0]], colors=[[1.0]], mapping="linear")
    r = render(X, F, cam, sh)
    img = np.clip(0.15 + 0.85 * r.image[..., 0], 0, 1)
    img[~r.mask] = 1.0
    return (img * 255 + 0.5).astype(np.uint8)


def contact_sheet(rows, path, title,
                  captions=("before", "after", "control (remeshing alone)")):
    """rows: [(label, picture, ...)] of uint8 pictures (one per caption; None = blank) -> a
    PNG."""
    from PIL import Image, ImageDraw

    size = rows[0][1].shape[0]
    pad, head = 6, 22
    W = len(captions) * (size + pad) + pad + 110
    H = head + len(rows) * (size + pad) + pad + 16
    sheet = Image.new("L", (W, H), 255)
    d = ImageDraw.Draw(sheet)
    d.text((pad, 4), title, fill=0)
    for j, cap in enumerate(captions):
        d.text((110 + pad + j * (size + pad), head - 2), cap, fill=0)
    for i, (label, *pics) in enumerate(rows):
        y = head + 14 + i * (size + pad)
        d.text((pad, y + size // 2), label, fill=0)
        for j, pic in enumerate(pics):
            if pic is not None:
                sheet.paste(Image.fromarray(pic), (110 + pad + j * (size + pad), y))
    path.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(path)


def effects(a) -> int:
    from algorithms.mesh.topology import boundary_loops, euler_characteristic, is_manifold
    from algorithms.paparazzi import (NothingToFilter, PaparazziParams,
                                      count_self_intersections, filter_names, get_filter)
    from algorithms.mesh.operators import signed_volume
    from algorithms.paparazzi.measures import crease_fraction, surface_distance

    import os
    print(f"load average {os.getloadavg()[0]:.2f}; {a.iterations} iterations; 16 monitor views",
          flush=True)
    print(f"{'mesh':<16}{'filter':<13}{'V in':>7}{'V out':>7}{'sec':>7}{'ctl s':>7}  "
          f"{'E16 before -> after':<24}{'falls':<6}{'measure':<10}{'before':>9} -> "
          f"{'after':<9}{'control':>9} {'beats':<6}{'crease5':<16}checks", flush=True)
    sheets: dict[str, list] = {}
    controls: dict = {}
    for mesh in a.meshes:
        got = load(mesh)
        if got is None:
            print(f"{mesh} not found; skipping")
            continue
        if isinstance(got, str):
            print(f"{Path(mesh).name:<16}{'all':<13}{got}", flush=True)
            _record(a, mesh=Path(mesh).name, filter="all", kind="refused", why=got)
            continue
        V, F = got
        Vc, _ = (V, F) if Path(mesh).is_file() else clean_of(mesh)
        noisy = mesh.startswith("noisy:")
        topo = (euler_characteristic(F), len(boundary_loops(F)))
        for name in a.filters:
            if name not in filter_names():
                print(f"{mesh:<16}{name:<13}skipped: the filter is not registered here "
                      f"(its optional packages are missing)", flush=True)
                continue
            spec = get_filter(name)
            params = PaparazziParams(iterations=a.iterations, remesh_scope=SCOPE,
                                     learning_rate=a.learning_rate)
            fparams = spec.params()
            if name == "neural-style":
                fparams = dataclasses.replace(fparams, energy=a.energy)
            try:
                run, last, sec, done = run_filter(V, F, spec, fparams, params, a.time_limit)
            except Exception as e:  # noqa: BLE001 - a refusal or failure is a row, not the end
                why = f"{type(e).__name__}: {str(e).splitlines()[0][:160] if str(e) else ''}"
                # a refusal before the first step, for the reason its message states
                kind = "refused" if isinstance(e, NothingToFilter) else "failed"
                print(f"{Path(mesh).name:<16}{name:<13}{kind}: {why}", flush=True)
                _record(a, mesh=Path(mesh).name, filter=name, kind=kind, why=why,
                        vertices=len(V))
                continue
            if last is None:
                print(f"{Path(mesh).name:<16}{name:<13}over time: {done} of {a.iterations} "
                      f"iterations in {sec:.0f} s", flush=True)
                _record(a, mesh=Path(mesh).name, filter=name, kind="over time",
                        why=f"{done} of {a.iterations} iterations in {sec:.0f} s",
                        vertices=len(V), seconds=round(sec, 1))
                continue
            # the control's vertices move only by remeshing (its gradient is zero), so it depends
            # on the filter only through the remeshing's crease angle: one run per angle
            key = (mesh, float(spec.crease_angle or 0.0))
            if key not in controls:
                controls[key] = run_filter(V, F, control_spec(spec), fparams, params)
            crun, clast, csec, _ = controls[key]
            Vo, Fo = last.V, last.F
            m = last.metrics
            label, before, sign = measure(name, run, V, F)
            _, after, _ = measure(name, run, Vo, Fo)
            _, ctl, _ = measure(name, run, clast.V, clast.F)
            beats = (after - ctl) * sign > 0
            e0, e1 = m["initial_monitor_energy"], m["monitor_energy"]
            same = (euler_characteristic(Fo), len(boundary_loops(Fo))) == topo
            crossings = count_self_intersections(Vo, Fo)
            crease = ""
            if name == "guided":       # against the clean input's angles (a noisy scan's own
                crease = (f"{crease_fraction(Vc, F, Vo, Fo):.3f} "      # are noise)
                          f"(c {crease_fraction(Vc, F, clast.V, clast.F):.3f})")
            # the filter's own energy on remeshing alone's output: does the run end lower?
            e_ctl = run.monitor_energy((clast.V - run.center) / run.scale, clast.F)
            print(f"    {mesh} {name}: E16 of the control's output {e_ctl:.4g} "
                  f"(the run's {e1:.4g})", flush=True)
            _record(a, mesh=Path(mesh).name, filter=name, kind="result", vertices=len(V),
                    vertices_out=len(Vo), seconds=round(sec, 1), control_seconds=round(csec, 1),
                    e16_before=e0, e16_after=e1, e16_control=e_ctl, falls=bool(e1 < e0),
                    beats_control=bool(e1 < e_ctl), measure=label, measure_before=before,
                    measure_after=after, measure_control=ctl, measure_beats=bool(beats),
                    crossings_in=int(run.input_intersections), crossings_out=int(crossings),
                    manifold=bool(is_manifold(Fo)), same_topology=bool(same),
                    kept_iteration=int(m.get("kept_iteration", a.iterations)),
                    rollbacks=int(m["rollbacks"]))
            if noisy and name == "guided":
                diag = float(np.linalg.norm(Vc.max(0) - Vc.min(0)))
                print(f"    {mesh} guided: distance to the clean mesh (mean, / diagonal) "
                      f"{surface_distance(Vo, Fo, Vc, F) / diag:.5f} (control "
                      f"{surface_distance(clast.V, clast.F, Vc, F) / diag:.5f}, noisy input "
                      f"{surface_distance(V, F, Vc, F) / diag:.5f}); moved from the noisy "
                      f"input {surface_distance(Vo, Fo, V, F) / diag:.5f}; volume change "
                      f"{(signed_volume(Vo, Fo) - signed_volume(V, F)) / signed_volume(V, F):+.4f}",
                      flush=True)
            if a.save:
                from algorithms.mesh import write_mesh

                stem = Path(mesh).name.replace(":", "_").rsplit(".", 1)[0]
                Path(a.save).mkdir(parents=True, exist_ok=True)
                write_mesh(Path(a.save) / f"{stem}_{name}.obj", Vo, Fo)
                write_mesh(Path(a.save) / f"{stem}_{name}_control.obj", clast.V, clast.F)
            print(f"{mesh:<16}{name:<13}{len(V):>7}{len(Vo):>7}{sec:>7.1f}{csec:>7.1f}  "
                  f"{f'{e0:.4g} -> {e1:.4g}':<24}{'yes' if e1 < e0 else 'NO':<6}{label:<10}"
                  f"{before:>9.4g} -> {after:<9.4g}{ctl:>9.4g} {'yes' if beats else 'NO':<6}"
                  f"{crease:<16}{'manifold' if is_manifold(Fo) else 'NOT-MANIFOLD'} "
                  f"{'same-topology' if same else 'TOPOLOGY-CHANGED'} crossings "
                  f"{run.input_intersections}->{crossings} (rollbacks {int(m['rollbacks'])}, "
                  f"rejected remeshes {int(m['remesh_rejected'])}) step {run.learning_rate:g}"
                  f"{' rough' if m.get('rough_input') else ''} halvings "
                  f"{int(m.get('step_halvings', 0))} kept "
                  f"{int(m.get('kept_iteration', a.iterations))} (last "
                  f"{m.get('last_monitor_energy', e1):.4g})", flush=True)
            if not a.no_sheets:       # written after each row: a long run stopped early
                rows = sheets.setdefault(name, [])   # keeps the rows it has
                rows.append((f"{Path(mesh).stem}\n{len(V):,} V", view_picture(V, F),
                             view_picture(Vo, Fo), view_picture(clast.V, clast.F)))
                out = ROOT / "docs" / "images" / f"paparazzi_{name}{a.sheet_tag}.png"
                contact_sheet(rows, out, f"Paparazzi, filter {name}: {a.iterations} "
                                         "iterations, command-line defaults")
    return 0


def _record(a, **rec):
    """One JSON line per row to ``--json`` (appended at once: a long run stopped early keeps
    its rows)."""
    if a.json:
        import json

        with open(a.json, "a") as fh:
            fh.write(json.dumps(rec) + "\n")


def summary(paths, markdown: bool = False) -> int:
    """Per filter, from ``--json`` files: on how many meshes the run's own energy fell, and on
    how many it also ended below remeshing alone's output (the issue-38 target: >= 90 % of
    the meshes the filter accepts); with ``markdown`` also one table row per mesh."""
    import json

    recs = [json.loads(line) for path in paths for line in open(path) if line.strip()]
    if markdown:
        names = [f for f in ("guided", "quantize", "slic", "l0", "neural-style")
                 if any(r["filter"] == f for r in recs)]
        print("| mesh | vertices | " + " | ".join(names) + " |")
        print("|---|---:|" + "---|" * len(names))
        meshes = sorted({r["mesh"] for r in recs},
                        key=lambda m: min(r.get("vertices", 0) for r in recs if r["mesh"] == m))
        for mesh in meshes:
            rows = {r["filter"]: r for r in recs if r["mesh"] == mesh}
            if "all" in rows:
                print(f"| {mesh} | | {rows['all']['why']} |" + " |" * (len(names) - 1))
                continue
            cells = []
            for f in names:
                r = rows.get(f)
                if r is None:
                    cells.append("not run")
                elif r["kind"] != "result":
                    cells.append(f"{r['kind']} ({r.get('why', '')})")
                else:
                    ok = "yes" if r["falls"] and r["beats_control"] else (
                        "**rises**" if not r["falls"] else "**not below control**")
                    cells.append(f"{r['e16_before']:.3g} → {r['e16_after']:.3g} "
                                 f"(control {r['e16_control']:.3g}) {ok}, {r['seconds']:.0f} s")
            verts = max(r.get("vertices", 0) for r in rows.values())
            print(f"| {mesh} | {verts:,} | " + " | ".join(cells) + " |")
        print()
    refused = sorted({r["mesh"] for r in recs if r["filter"] == "all"})
    print(f"{len(refused)} meshes refused by every filter: {', '.join(refused) or '-'}")
    for name in sorted({r["filter"] for r in recs} - {"all"}):
        rows = [r for r in recs if r["filter"] == name]
        res = [r for r in rows if r["kind"] == "result"]
        falls = sum(r["falls"] for r in res)
        both = sum(r["falls"] and r["beats_control"] for r in res)
        refused = sum(r["kind"] == "refused" for r in rows)
        accepted = len(rows) - refused
        print(f"{name:<13} {len(rows)} meshes: {len(res)} results, "
              f"{sum(r['kind'] == 'over time' for r in rows)} over time, "
              f"{sum(r['kind'] == 'failed' for r in rows)} failed, {refused} refused before "
              f"the first step; energy falls on {falls}, falls and ends below remeshing alone "
              f"on {both} ({100 * both / max(len(rows), 1):.0f} % of the {len(rows)} it was "
              f"run on, {100 * both / max(accepted, 1):.0f} % of the {accepted} it accepted)")
        for r in rows:
            if r["kind"] != "result" or not (r["falls"] and r["beats_control"]):
                extra = (f"E16 {r['e16_before']:.4g} -> {r['e16_after']:.4g}, control "
                         f"{r['e16_control']:.4g}" if r["kind"] == "result" else r.get("why", ""))
                print(f"    {r['mesh']}: {r['kind']}: {extra}")
    return 0


# ----------------------------------------------------------------------------- suspects
def _step_against_change(run, V, F, views=32):
    """(rms colour change |f(R) - R| per foreground pixel, the displacement it asks for (2 |dR|
    times the mean edge length: colour = (n + 1) / 2, a face turns by about |dn| radians when a
    corner moves |dn| h), the NAdam step (about the learning rate per coordinate, whatever the
    gradient's size)) over ``views`` random views of the input."""
    from algorithms.render import render

    rng = np.random.default_rng(7)
    X = (np.asarray(V) - run.center) / run.scale
    dR = []
    for _ in range(views):
        cam = run.camera(rng)
        r = render(X, F, cam, run.shading)
        E, G, _, _ = run._filter(r, run._context(r, cam))
        if r.mask.any():
            dR.append(np.sqrt((G[r.mask] ** 2).sum(1).mean()))
    rms = float(np.mean(dR))
    return rms, 2.0 * rms * run.edge_length, run.learning_rate


def _remesh_effect(V, F, spec, fparams, params):
    """Mean monitor energy just before and just after each remeshing of a run, and its change
    over the whole run: does remeshing undo what the steps did?"""
    from algorithms.paparazzi import Paparazzi

    run = Paparazzi(V, F, spec, fparams, params)
    cams = run.monitor_cameras()
    jumps = []
    original = run._remesh

    def remesh(X, G, free):
        U, H = original(X, G, free)
        jumps.append((run.monitor_energy(X, G, cams), run.monitor_energy(U, H.astype(np.int64),
                                                                           cams)))
        return U, H

    run._remesh = remesh
    last = None
    for last in run.steps():
        pass
    m = last.metrics
    return m["initial_monitor_energy"], m["monitor_energy"], jumps, last


def suspects(a) -> int:
    import os

    from algorithms.paparazzi import PaparazziParams, bending_energy, get_filter
    from algorithms.paparazzi.measures import crease_fraction

    spec = get_filter("guided")
    P = spec.params
    print(f"load average {os.getloadavg()[0]:.2f}; guided filter suspects; "
          f"{a.iterations} iterations", flush=True)
    # (Params, learning rate, remeshing's crease angle) of each setting compared
    settings = {"old (r 15, eps 1e-8, s 4)": (P(radius=15, epsilon=1e-8, subsample=4), 5e-5, 0.0),
                "thesis (r 4, eps 0.02, s 4)": (P(radius=4, epsilon=0.02, subsample=4), 5e-5,
                                                0.0),
                "today's defaults": (P(), spec.learning_rate, spec.crease_angle)}
    for mesh in a.meshes:
        got = load(mesh)
        if got is None:
            continue
        V, F = got
        from algorithms.paparazzi import Paparazzi

        probe = Paparazzi(V, F, spec, P(), PP(iterations=1))
        px = probe.edge_length / probe.width * probe.resolution
        print(f"\n{mesh}: {len(V):,} vertices; mean edge {probe.edge_length:.4f} "
              f"(shape in a cube of side 2) = {px:.1f} px at {probe.resolution} px, view "
              f"{probe.width}")
        for label, (fp, lr, crease) in settings.items():
            variant = dataclasses.replace(spec, learning_rate=lr, crease_angle=crease)
            run = Paparazzi(V, F, variant, fp, PP(iterations=1))
            rms, want, step = _step_against_change(run, V, F)
            print(f"  {label:<28} radius {fp.radius} px = {fp.radius / px:.2f} edges; colour "
                  f"change per view {rms:.3g} (rms per pixel) -> asks for {want:.3g} per step; "
                  f"NAdam step ~{step:.3g} ({step / want:.3g} x what it asks)")
        rows = []
        for label, (fp, lr, crease) in settings.items():
            rows.append((label, fp, lr, crease, {}))
        old_t = settings["thesis (r 4, eps 0.02, s 4)"]
        rows += [(f"thesis, lr {lr:g}", old_t[0], lr, 0.0, {}) for lr in (2e-5, 1e-4, 2e-4)]
        rows += [(f"thesis, {res} px", old_t[0], 5e-5, 0.0, {"resolution": res})
                 for res in (64, 256)]
        rows += [(f"thesis, radius {r}", P(radius=r, epsilon=0.02, subsample=4), 5e-5, 0.0, {})
                 for r in (8, 15)]
        rows += [("thesis, no remeshing", old_t[0], 5e-5, 0.0, {"remesh_every": 0}),
                 ("thesis, creases kept", old_t[0], 5e-5, 45.0, {})]
        rows += [(f"s 1, eps {e:g}, creases kept", P(radius=4, epsilon=e, subsample=1),
                  spec.learning_rate, 45.0, {}) for e in (1e-3, 5e-3)]
        rows += [("today's, creases free", P(), spec.learning_rate, 0.0, {}),
                 ("today's, lr 2e-5", P(), 2e-5, spec.crease_angle, {})]
        for crease in sorted({r[3] for r in rows}):
            ctl = dataclasses.replace(control_spec(spec), crease_angle=crease)
            _, _, _, clast = _remesh_effect(V, F, ctl, P(),
                                            PP(iterations=a.iterations))
            print(f"  control (remeshing alone, creases {'kept' if crease else 'free'}): "
                  f"bending {bending_energy(V, F):.4g} -> {bending_energy(clast.V, clast.F):.4g},"
                  f" crease5 {crease_fraction(V, F, clast.V, clast.F):.3f}", flush=True)
        for label, fp, lr, crease, extra in rows:
            variant = dataclasses.replace(spec, learning_rate=lr, crease_angle=crease)
            e0, e1, jumps, last = _remesh_effect(
                V, F, variant, fp, PP(iterations=a.iterations, **extra))
            up = sum(j[1] - j[0] for j in jumps)
            print(f"  {label:<28} E16 {e0:.4g} -> {e1:.4g} ({100 * (e1 - e0) / e0:+.1f} %); "
                  f"remeshings changed it by {up:+.4g} in all ({len(jumps)} of them); bending "
                  f"{bending_energy(last.V, last.F):.4g}; crease5 "
                  f"{crease_fraction(V, F, last.V, last.F):.3f}", flush=True)
    return 0


# ----------------------------------------------------------------------------- pretzel, noise
def pretzel(a) -> int:
    """Why the guided energy of the pretzel sample rises (docs/results/paparazzi.md, "The pretzel"):
    each monitor view before and after one remeshing; remeshings alone; the same with the
    vertices projected onto the exact implicit surface the sample was made from; the jumps at
    remeshings against the steps between them for several learning rates and remeshing
    intervals."""
    import os

    from algorithms.mesh.primitives import _field_pretzel as field
    from algorithms.paparazzi import Paparazzi, PaparazziParams, bending_energy, get_filter

    V, F = load("pretzel.obj")
    spec = get_filter("guided")
    run = Paparazzi(V, F, spec, None, PP(iterations=1))
    X, G = run.V0, run.F0
    cams = run.monitor_cameras()
    print(f"load average {os.getloadavg()[0]:.2f}; pretzel {len(X):,} vertices; guided defaults")
    everything = np.ones(len(X), bool)
    U, H = run._remesh(X, G, everything)
    for i, c in enumerate(cams):
        print(f"  view {i:2d}: E {run.evaluate(X, G, c)[0]:.3f} -> {run.evaluate(U, H, c)[0]:.3f} "
              "after one remeshing")
    # the sample is marching cubes of _field_pretzel relaxed onto it, then scaled: find the scale
    ss = np.linspace(0.9, 1.2, 3001)
    s = ss[int(np.argmin([np.mean(field(X * t) ** 2) for t in ss]))]

    def onto_surface(P):
        P = P * s
        for _ in range(4):
            f = field(P)
            g = np.stack([(field(P + 1e-6 * e) - field(P - 1e-6 * e)) / 2e-6 for e in np.eye(3)],
                         axis=1)
            P = P - (f / np.maximum((g * g).sum(1), 1e-12))[:, None] * g
        return P / s

    U, H = X, G
    print(f"  input E16 {run.monitor_energy(X, G, cams):.4f}")
    for k in range(1, 4):
        U, H = run._remesh(U, H, np.ones(len(U), bool))
        P = onto_surface(U)
        print(f"  after {k} remeshing(s) alone: E16 {run.monitor_energy(U, H, cams):.4f}; "
              f"projected onto the exact surface {run.monitor_energy(P, H, cams):.4f}", flush=True)
        U = P
    for label, lr, extra in [("defaults", None, {}), ("lr 2e-5", 2e-5, {}),
                             ("lr 5e-5", 5e-5, {}), ("remesh every 100", None,
                                                     {"remesh_every": 100}),
                             ("no remeshing", None, {"remesh_every": 0})]:
        sp = spec if lr is None else dataclasses.replace(spec, learning_rate=lr)
        e0, e1, jumps, last = _remesh_effect(V, F, sp, None,
                                             PP(iterations=a.iterations, **extra))
        up = sum(j[1] - j[0] for j in jumps)
        print(f"  {label:<18} E16 {e0:.4f} -> {e1:.4f}; {len(jumps)} remeshings {up:+.4f}, steps "
              f"{e1 - e0 - up:+.4f}; bending {bending_energy(V, F):.1f} -> "
              f"{bending_energy(last.V, last.F):.1f}", flush=True)
    return 0


def noise_variance(a) -> int:
    """Colour variance of the guided filter's 9 x 9 windows on clean and noisy fandisk, in flat
    regions and at creases (20 random views), and the filter's change there: why no epsilon
    both removes the noise and keeps the creases (docs/results/paparazzi.md, "Noisy scans")."""
    import os

    from algorithms.paparazzi import Paparazzi, PaparazziParams
    from algorithms.paparazzi.filters import _box, guided_filter
    from algorithms.paparazzi.measures import _dihedral_angles
    from algorithms.render import render

    Vc, F = load("fandisk.off")
    Vn, _ = load("noisy:fandisk.off")
    run = Paparazzi(Vc, F, "guided", None, PP(iterations=1))
    eps, r = run.filter_params.epsilon, run.filter_params.radius
    Xc, Xn = (Vc - run.center) / run.scale, (Vn - run.center) / run.scale
    _, f0, f1, ang = _dihedral_angles(Vc, F)
    crease = np.zeros(len(F), bool)
    crease[f0[ang > 30]] = crease[f1[ang > 30]] = True
    rng = np.random.default_rng(5)
    var = {k: [] for k in ("clean flat", "clean crease", "noisy flat", "noisy crease")}
    change = {k: [] for k in var}
    for _ in range(20):
        cam = run.camera(rng)
        rc = render(Xc, F, cam, run.shading)
        fid = np.where(rc.slot >= 0, rc.faces[np.maximum(rc.slot, 0)], -1)
        cm = (fid >= 0) & crease[np.maximum(fid, 0)]
        near = _box(cm[..., None].astype(float), r)[..., 0] > 0
        for tag, X in (("clean", Xc), ("noisy", Xn)):
            I = render(X, F, cam, run.shading)
            v = (_box(I.image ** 2, r) - _box(I.image, r) ** 2).sum(2)
            q = guided_filter(I.image, I.image, r, eps)
            inside = _box(I.mask[..., None].astype(float), r)[..., 0] > 0.999
            for part, sel in (("flat", inside & ~near), ("crease", inside & near & cm)):
                var[f"{tag} {part}"].append(v[sel])
                change[f"{tag} {part}"].append(np.linalg.norm(q - I.image, axis=2)[sel])
    print(f"load average {os.getloadavg()[0]:.2f}; fandisk, guided radius {r}, epsilon {eps:g}")
    for k in var:
        v, c = np.concatenate(var[k]), np.concatenate(change[k])
        print(f"  {k:<13} window colour variance median {np.median(v):.4f}; the filter's change "
              f"|q - I| median {np.median(c):.4f}")
    return 0


def barrier(a) -> int:
    """Why a filter's energy rises on a noisy scan at a small step (docs/results/paparazzi.md,
    "Rough scans"): the 16-view energy along the straight path from each noisy scan (t = 0) to its
    clean mesh (t = 1), per filter, and ``Paparazzi.rough_probe`` (the relative change of the
    energy after one small full-batch step along the filter's own pull; > 0 = rough) on the
    clean meshes and on noisy copies at 0.1, 0.2 and 0.3 mean edge lengths of noise."""
    import os

    from algorithms.paparazzi import Paparazzi, get_filter
    from algorithms.paparazzi.measures import noisy_scan

    print(f"load average {os.getloadavg()[0]:.2f}; 16 monitor views", flush=True)
    ts = np.linspace(0.0, 1.0, 11)
    for name in a.meshes:
        got = load(name)
        if got is None:
            print(f"{name} not found; skipping")
            continue
        V, F = got
        for filt in a.filters:
            spec = get_filter(filt)
            row = []
            for amount in (0.0, 0.1, 0.2, 0.3):
                X = noisy_scan(V, F, amount, NOISE_SEED) if amount else V
                run = Paparazzi(X, F, spec, None, PP(iterations=1))
                row.append(f"{amount:g}: {100 * run.rough_probe(run.V0, run.F0):+.3f} %")
            print(f"  {name:<18} {filt:<13} rough probe at noise (edge lengths) "
                  + ", ".join(row), flush=True)
            W = noisy_scan(V, F, NOISE, NOISE_SEED)
            run = Paparazzi(W, F, spec, None, PP(iterations=1))
            cams = run.monitor_cameras()
            e = [run.monitor_energy(((1 - t) * W + t * V - run.center) / run.scale, F, cams)
                 for t in ts]
            k = int(np.argmax(e))
            print(f"  {name:<18} {filt:<13} energy from noisy ({NOISE:g}) to clean: "
                  + " ".join(f"{t:.1f}:{x:.4g}" for t, x in zip(ts, e))
                  + f"  (peak {e[k] / e[0]:.2f} x the noisy scan's at t = {ts[k]:.1f})",
                  flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", nargs="+", default=None)
    ap.add_argument("--filters", nargs="+",
                    default=["guided", "quantize", "slic", "l0", "neural-style"])
    ap.add_argument("--iterations", type=int, default=1000)
    ap.add_argument("--energy", choices=("gram", "network"), default="gram",
                    help="neural-style's energy (default: its default, gram)")
    ap.add_argument("--learning-rate", type=float, default=0.0,
                    help="every run's learning rate (0: each filter's own, the default)")
    ap.add_argument("--no-sheets", action="store_true")
    ap.add_argument("--sheet-tag", default="",
                    help="docs/images/paparazzi_<filter><TAG>.png (e.g. _noisy)")
    ap.add_argument("--save", default=None, help="write each output and control mesh here")
    ap.add_argument("--remesh-scope", choices=("bad", "all"), default="bad",
                    help="PaparazziParams.remesh_scope (default bad, the command line's; all: "
                         "the whole surface re-placed, the default before issue 23's fourth pass)")
    ap.add_argument("--noisy", action="store_true",
                    help="the noisy scans: noisy:fandisk.off noisy:bob.obj")
    ap.add_argument("--noise", type=float, default=None,
                    help="noise of the noisy: meshes, in mean edge lengths (default 0.3)")
    ap.add_argument("--corpus", default=None,
                    help="every mesh file of this folder, read (and cleaned when not a "
                         "2-manifold) as `stylize3d paparazzi FILE --clean` does, unsubdivided")
    ap.add_argument("--max-faces", type=int, default=0,
                    help="with --corpus: only meshes of at most this many triangles")
    ap.add_argument("--from-index", type=int, default=0,
                    help="with --corpus: start at this mesh of the list sorted by size")
    ap.add_argument("--worker", default="1/1", metavar="K/N",
                    help="with --corpus: run only the K-th of every N meshes (smallest first), "
                         "so N workers (K = 1..N, each its own --json) share the corpus evenly")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="seconds per run; a run stopped there is 'over time', not a result")
    ap.add_argument("--json", default="", help="append one JSON line per row to this file")
    ap.add_argument("--summary", nargs="+", default=None,
                    help="only print the per-filter summary of --json files")
    ap.add_argument("--markdown", action="store_true",
                    help="with --summary: also a table, one row per mesh")
    ap.add_argument("--suspects", action="store_true")
    ap.add_argument("--barrier", action="store_true",
                    help="each filter's energy from the noisy scans to the clean meshes, and "
                         "the rough probe at three noise levels")
    ap.add_argument("--pretzel", action="store_true",
                    help="why the pretzel's guided energy rises (each suspect)")
    ap.add_argument("--noise-variance", action="store_true",
                    help="window colour variance of noise and creases (fandisk)")
    a = ap.parse_args()
    if a.summary:
        return summary(a.summary, a.markdown)
    if a.corpus:
        from algorithms.mesh import read_mesh

        files = sorted(p for p in Path(a.corpus).iterdir()
                       if p.suffix.lower() in {".obj", ".ply", ".off", ".stl", ".glb"})
        def faces(p):
            try:
                return len(read_mesh(p).F)
            except Exception:  # noqa: BLE001 - listed, and refused in its row
                return 0
        size = {p: faces(p) for p in files}
        files = sorted((p for p in files if not a.max_faces or size[p] <= a.max_faces),
                       key=lambda p: (size[p], p.name))   # smallest first: a run cut short
        # still has every filter on the meshes it reached
        done = set()
        if a.json and Path(a.json).exists():   # the same --json again resumes: meshes with
            import json                        # rows there are not run again
            done = {json.loads(line)["mesh"] for line in open(a.json) if line.strip()}
        files = files[a.from_index:]           # a second worker can start mid-list
        k, n = (int(x) for x in a.worker.split("/"))
        files = files[k - 1::n]                # or take every n-th mesh (sizes spread evenly)
        a.meshes = [str(p) for p in files if p.name not in done]
    global SCOPE, NOISE
    SCOPE = a.remesh_scope
    if a.noise is not None:
        NOISE = a.noise
    if a.pretzel:
        return pretzel(a)
    if a.noise_variance:
        return noise_variance(a)
    if a.barrier:
        a.meshes = a.meshes or ["fandisk.off", "bob.obj", "spot_lowres.obj", "camelhead.off",
                                "armadillo.obj", "blob.obj", "bumpy.obj", "pretzel.obj"]
        return barrier(a)
    if a.suspects:
        a.meshes = a.meshes or ["bob.obj", "fandisk.off"]
        return suspects(a)
    if a.noisy:
        a.meshes = a.meshes or ["noisy:fandisk.off", "noisy:bob.obj"]
    a.meshes = a.meshes or ["spot_lowres.obj", "bob.obj", "fandisk.off", "camelhead.off",
                            "blob.obj", "bumpy.obj", "pretzel.obj"]
    return effects(a)


if __name__ == "__main__":
    sys.exit(main())
