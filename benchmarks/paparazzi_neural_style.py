"""Neural-style Paparazzi benchmark (issue 12): time per filter call, and whether a run with the
CLI's defaults makes the monitor view's Gram (style) loss fall.

    python benchmarks/paparazzi_neural_style.py [--mesh bob.obj] [--iterations 1000]
                                                [--style 0] [--energy gram|network]
                                                [--upsample-vertices 0]
                                                [--skip-run]

1. Per call, medians in this process: the gram energy with its gradient at 128 px, the
   built-in style network at 128 and 256 px, the
   style-image network (384 px inside) at 128 px, and the guided filter at 128 px as the peer
   (ratios printed).
2. A run with ``stylize3d paparazzi IN -o OUT --filter neural-style`` defaults (1000 iterations,
   128 px, view width 0.1, sigma 0.02, the filter's learning rate, remesh every 30). Every 100
   iterations, with ``--energy network``: the Gram loss (:func:`gram_style_loss`) of the fixed
   monitor view against its own stylization ``f(R)``, against the stylization of the *first*
   monitor image ``f(R0)``, and, as a control, against another built-in style's stylization;
   with the default ``gram`` energy: against the style's texture and, as the control, against
   another style's; the optimizer's monitor energy; then the time split and the output
   checks.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._timing import median_seconds, mesh_path  # noqa: E402


def per_call(repeat: int) -> None:
    from algorithms.paparazzi.filters import guided_filter
    from algorithms.paparazzi.neural_style import (NeuralStyleParams, StyleNetwork,
                                                   gram_style_loss, style_exemplar, style_grams,
                                                   stylize)

    rng = np.random.default_rng(0)
    p = NeuralStyleParams()
    g128 = rng.random((128, 128))
    g256 = rng.random((256, 256))
    vec = StyleNetwork.style_vector(rng.random((256, 256, 3)))
    stylize(g128, p)
    stylize(g128, p, vec)
    rgb = np.repeat(g128[..., None], 3, axis=2)
    guided_filter(rgb, rgb, 15, 1e-8, 4)
    t128 = median_seconds(lambda: stylize(g128, p), repeat)
    t256 = median_seconds(lambda: stylize(g256, p), repeat)
    tarb = median_seconds(lambda: stylize(g128, p, vec), max(3, repeat // 3))
    tgf = median_seconds(lambda: guided_filter(rgb, rgb, 15, 1e-8, 4), repeat)
    grams = style_grams(style_exemplar(p))
    gram_style_loss(g128, None, gradient=True, target_grams=grams)
    tgram = median_seconds(lambda: gram_style_loss(g128, None, gradient=True,
                                                   target_grams=grams), repeat)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"per call (median of {repeat}): gram energy and its gradient 128 px "
          f"{1e3 * tgram:.1f} ms; built-in style network 128 px {1e3 * t128:.1f} ms, "
          f"256 px {1e3 * t256:.1f} ms (x{t256 / t128:.2f}); style image 128 px (384 inside) "
          f"{1e3 * tarb:.1f} ms; guided filter 128 px (peer) {1e3 * tgf:.1f} ms "
          f"(gram / guided = {tgram / tgf:.2f}, built-in / guided = {t128 / tgf:.2f})")


def run(mesh: str, iterations: int, style: int, control: int, upsample: int = 0,
        energy: str = "gram", **overrides) -> None:
    from algorithms.mesh import read_mesh
    from algorithms.mesh.topology import euler_characteristic, is_manifold
    from algorithms.paparazzi import Paparazzi, PaparazziParams, count_self_intersections
    from algorithms.paparazzi.neural_style import (NeuralStyleParams, gram_style_loss,
                                                   style_exemplar, stylize)
    from algorithms.render import render

    path = mesh_path(mesh)
    if not path.exists():
        print(f"{mesh} not found; skipping the run")
        return
    data = read_mesh(path)
    params = PaparazziParams(iterations=iterations, upsample_vertices=upsample,
                             **{k: v for k, v in overrides.items() if v is not None})
    fp = NeuralStyleParams(style=style, energy=energy)
    other = NeuralStyleParams(style=control, energy=energy)
    t0 = time.perf_counter()
    pz = Paparazzi(data.V, data.F, "neural-style", fp, params)
    cam = pz.monitor_cameras()[0]    # the first of the optimizer's 16 monitor views

    def view(Vw, F):
        return render((Vw - pz.center) / pz.scale, F, cam, pz.shading).image[..., 0]

    R0 = view(pz.to_world(pz.V0), pz.F0)
    S0 = stylize(R0, fp)

    def losses(R):
        if energy == "gram":     # against the style, and against the control style's texture
            return (gram_style_loss(R, style_exemplar(fp)), float("nan"),
                    gram_style_loss(R, style_exemplar(other)))
        return (gram_style_loss(R, stylize(R, fp)), gram_style_loss(R, S0),
                gram_style_loss(R, stylize(R, other)))

    first = losses(R0)
    print(f"{path.name}: {len(data.V)} vertices ({len(pz.V0)} optimized), {len(data.F)} faces; "
          f"{iterations} iterations, "
          f"{pz.resolution} px, view width {pz.width}, sigma {pz.sigma}, learning rate "
          f"{getattr(pz, 'learning_rate', params.learning_rate):g}, energy {energy}, style {style} "
          f"(control style {control}); setup {time.perf_counter() - t0:.1f} s")
    print(f"  (gram energy: Gram(R, f(R)) is against the style's texture, Gram(R, style "
          f"{control}) against the control style's)")
    print(f"  it     0: Gram(R, f(R)) {first[0]:9.2f}  Gram(R, f(R0)) {first[1]:9.2f}  "
          f"Gram(R, style {control}) {first[2]:9.2f}")
    t1 = time.perf_counter()
    last = None
    for last in pz.steps():
        if last.iteration % 100 == 0 or last.iteration == iterations:
            g = losses(view(last.V, last.F))
            print(f"  it {last.iteration:5d}: Gram(R, f(R)) {g[0]:9.2f} ({g[0] / first[0]:.3f})  "
                  f"Gram(R, f(R0)) {g[1]:9.2f} ({g[1] / first[1]:.3f})  "
                  f"Gram(R, style {control}) {g[2]:9.2f} ({g[2] / first[2]:.3f})  "
                  f"monitor energy (16 views) "
                  f"{last.metrics['monitor_energy']:.2f}", flush=True)
    secs = time.perf_counter() - t1
    V = (last.V - pz.center) / pz.scale
    split = ", ".join(f"{k} {v / iterations * 1e3:.1f}" for k, v in last.seconds.items())
    print(f"  {secs:.0f} s for {iterations} iterations ({secs / iterations * 1e3:.0f} ms each; "
          f"per iteration ms: {split})")
    print(f"  output: {len(V)} vertices, manifold {is_manifold(last.F)}, Euler characteristic "
          f"{euler_characteristic(pz.F0)} -> {euler_characteristic(last.F)}, self-intersecting "
          f"face pairs {count_self_intersections(V, last.F)}, remeshes "
          f"{int(last.metrics['remeshes'])}, rollbacks {int(last.metrics['rollbacks'])}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="bob.obj")
    ap.add_argument("--iterations", type=int, default=1000)
    ap.add_argument("--style", type=int, default=0)
    ap.add_argument("--energy", choices=("gram", "network"), default="gram")
    ap.add_argument("--control-style", type=int, default=7)
    ap.add_argument("--upsample-vertices", type=int, default=0,
                    help="Loop-subdivide to at least this many vertices (the CLI's default: 0)")
    ap.add_argument("--view-width", type=float, default=None, help="default: the filter's (0.1)")
    ap.add_argument("--sigma", type=float, default=None, help="default: the filter's (0.02)")
    ap.add_argument("--learning-rate", type=float, default=None,
                    help="default: the filter's (gram 1e-3, network 5e-4)")
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--skip-run", action="store_true")
    a = ap.parse_args()
    if a.repeat > 0:
        per_call(a.repeat)
    if not a.skip_run:
        run(a.mesh, a.iterations, a.style, a.control_style, a.upsample_vertices, a.energy,
            view_width=a.view_width, sigma=a.sigma, learning_rate=a.learning_rate)


if __name__ == "__main__":
    main()
