"""Paparazzi per-filter effects (issue 12): each filter, with the CLI's defaults, changes the shape
measurably in its own way and leaves a clean 2-manifold with the input's topology.

    python benchmarks/paparazzi_effects.py [--meshes spot_lowres.obj bob.obj fandisk.off
        camelhead.off] [--filters guided quantize slic l0 neural-style] [--iterations 1000]

For each mesh (tests/data; Loop-subdivided until it has at least 5,000 vertices, e.g. spot 829 ->
13,234) and each filter, runs ``Paparazzi`` with ``PaparazziParams(iterations=N)`` and the
filter's default Params -- exactly what ``stylize3d paparazzi MESH -o OUT --filter NAME`` builds
from its flags' defaults -- and prints one row: vertices in/out, seconds, the filter's measure
before -> after and whether it moved the expected way, the output checks (2-manifold, same
Euler characteristic and boundary-loop count, libigl self-intersecting pairs of the input and of
the output, and how many of the output's are new: farther than 4 edge lengths from the input's
own), and how often the surface crossed itself on the way (remeshings, those rejected, retries of
remeshings that crossed it; rollbacks, the vertices held still after them and the learning rate's
factor at the end (1 = never halved); see algorithms/paparazzi/optimize.py).

Measures (algorithms/paparazzi/measures.py):
  quantize      area fraction of faces whose normal is within 15 deg of the 20 palette normals (up)
  slic, l0      area fraction of faces whose dihedral angles to all neighbours are < 3 deg (up);
                also printed: flat1, the share of the interior edge length along which the
                two faces meet at < 1 deg (up; patches a few triangles wide count there too)
  guided        bending energy sum |L V|^2 / M (discrete Willmore energy; down)
  neural-style  Gram (style) loss between the monitor view and its stylization (down)
  identity      (--filters identity) the control run of the guided row: f(R) = R, so the
                gradient is 0 and only the remeshing every 30 iterations acts; its bending
                energy says how much of the guided row's change is the remeshing's;
                identity-planar: the same run measured like the L0 / SLIC rows
A filter that is not registered (neural-style needs its optional packages) is skipped with a
message.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._timing import mesh_path  # noqa: E402

MIN_VERTICES = 5000


def _gram_monitor(run, V, F):
    """Gram loss between the monitor view (world-frame V) and the filter's stylization of it."""
    from algorithms.paparazzi.filters import FilterContext
    from algorithms.paparazzi.neural_style import gram_style_loss
    from algorithms.render import render

    cam = run.camera(np.random.default_rng([run.params.seed, 1]))
    X = (np.asarray(V) - run.center) / run.scale
    r = render(X, F, cam, run.shading)
    ctx = FilterContext(camera=cam, mask=r.mask, state=run.state)
    styled = run.spec.function(r.image, run.filter_params, ctx)
    return gram_style_loss(r.image, styled)


def measure(name, run, V, F):
    from algorithms.paparazzi import bending_energy, palette_fraction, planar_area_fraction

    if name == "quantize":
        return "palette15", palette_fraction(V, F), +1
    if name in ("slic", "l0", "identity-planar"):
        return "planar3", planar_area_fraction(V, F), +1
    if name in ("guided", "identity"):
        return "bending", bending_energy(V, F), -1
    if name == "neural-style":
        return "gram", _gram_monitor(run, V, F), -1
    raise KeyError(name)


def second_measure(name, V, F):
    """The planar rows' second look (flat_edge_fraction), or None for the other filters."""
    from algorithms.paparazzi.measures import flat_edge_fraction

    if name in ("slic", "l0", "identity-planar"):
        return "flat1", flat_edge_fraction(V, F)
    return None


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", nargs="+",
                    default=["spot_lowres.obj", "bob.obj", "fandisk.off", "camelhead.off"])
    ap.add_argument("--filters", nargs="+",
                    default=["guided", "quantize", "slic", "l0", "neural-style"])
    ap.add_argument("--iterations", type=int, default=1000)
    a = ap.parse_args()
    from algorithms.mesh import loop_subdivide, read_mesh
    from algorithms.mesh.topology import boundary_loops, euler_characteristic, is_manifold
    from algorithms.paparazzi import (Paparazzi, PaparazziParams, count_self_intersections,
                                      filter_names, get_filter, register_filter)

    for control in ("identity", "identity-planar"):
        if control in a.filters and control not in filter_names():
            planar = "planar" in control  # the L0 / SLIC rows' control: their remeshing too
            register_filter(control, kind="iterative", resolution=256 if planar else 128,
                            crease_angle=45.0 if planar else 0.0,
                            description="control: the image itself")(
                lambda image, params, ctx: image)

    print(f"{'mesh':<16}{'filter':<13}{'V in':>7}{'V out':>7}{'sec':>8}  {'measure':<10}"
          f"{'before':>10} -> {'after':<10}{'ok':<4}{'manifold':<9}{'topology':<9}"
          f"{'crossings in->out':>18}", flush=True)
    for mesh in a.meshes:
        p = mesh_path(mesh)
        if not p.exists():
            print(f"{mesh} not found; skipping")
            continue
        d = read_mesh(p)
        V, F = d.V, d.F
        while len(V) < MIN_VERTICES:
            V, F = loop_subdivide(V, F, 1)
        topo = (euler_characteristic(F), len(boundary_loops(F)))
        for name in a.filters:
            if name not in filter_names():
                print(f"{mesh:<16}{name:<13}skipped: the filter is not registered here "
                      f"(its optional packages are missing)", flush=True)
                continue
            spec = get_filter(name)
            t = time.perf_counter()
            run = Paparazzi(V, F, spec, spec.params(), PaparazziParams(iterations=a.iterations))
            last = None
            for last in run.steps():
                pass
            sec = time.perf_counter() - t
            Vo, Fo = last.V, last.F
            m = last.metrics
            label, before, sign = measure(name, run, V, F)
            _, after, _ = measure(name, run, Vo, Fo)
            ok = (after - before) * sign > 0
            same = (euler_characteristic(Fo), len(boundary_loops(Fo))) == topo
            crossings = count_self_intersections(Vo, Fo)
            crossings_in = run.input_intersections
            new = run.new_self_intersections(Vo, Fo) if crossings else 0
            second = second_measure(name, V, F)
            also = (f"  [{second[0]} {second[1]:.4g} -> {second_measure(name, Vo, Fo)[1]:.4g}]"
                    if second else "")
            print(f"{mesh:<16}{name:<13}{len(V):>7}{len(Vo):>7}{sec:>8.1f}  {label:<10}"
                  f"{before:>10.4g} -> {after:<10.4g}{'yes' if ok else 'NO':<4}"
                  f"{'yes' if is_manifold(Fo) else 'NO':<9}{'same' if same else 'CHANGED':<9}"
                  f"{crossings_in:>12} -> {crossings:<3} ({new} new)  "
                  f"(remeshes {int(m['remeshes'])}, "
                  f"rejected {int(m['remesh_rejected'])}, retries {int(m['remesh_retries'])}; "
                  f"rollbacks {int(m['rollbacks'])}, held {int(m['held_vertices'])} V; "
                  f"step x{m['learning_rate'] / (0.2 * run.learning_rate):.3g}){also}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
