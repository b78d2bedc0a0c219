"""Paparazzi benchmark (issue 12): render + d(image)/d(vertices) per iteration against PyTorch
autograd through the same rasterization, and a whole guided-filter run with its time split.

    python benchmarks/paparazzi.py [--mesh fandisk.off] [--iterations 3000] [--skip-run]

Prints sizes, medians and ratios measured in this run. The mesh is Loop-subdivided once
(fandisk: 7,229 -> 28,910 vertices, the thesis's "26K" row).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._timing import median_seconds, mesh_path  # noqa: E402


def torch_peer(V, F, r, G, light_matrix):
    """dE/dV by PyTorch autograd: normals of all faces, per-pixel gather, backward."""
    import torch

    Vt = torch.tensor(V, requires_grad=True)
    Ft = torch.as_tensor(F)
    N = torch.linalg.cross(Vt[Ft[:, 1]] - Vt[Ft[:, 0]], Vt[Ft[:, 2]] - Vt[Ft[:, 0]])
    N = N / N.norm(dim=1, keepdim=True)
    col = 0.5 * N @ torch.as_tensor(light_matrix) + 0.5
    fid = torch.as_tensor(r.raster.face_id.ravel())
    m = fid >= 0
    img = torch.zeros(fid.shape[0], 3, dtype=torch.float64)
    img[m] = col[fid[m]]
    (img * torch.as_tensor(G.reshape(-1, 3))).sum().backward()
    return Vt.grad.numpy()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", default="fandisk.off")
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--skip-run", action="store_true")
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from algorithms.mesh import loop_subdivide, read_mesh
    from algorithms.paparazzi import Paparazzi, PaparazziParams, offset_surface, sample_camera
    from algorithms.render import LambertianShading, image_vjp, render

    p = mesh_path(a.mesh)
    if not p.exists():
        print(f"{a.mesh} not found; skipping")
        return 0
    d = read_mesh(p)
    V, F = loop_subdivide(d.V, d.F, 1)
    from algorithms.mesh.operators import normalize_unit_box

    V = normalize_unit_box(V)[0] * 2
    print(f"mesh {a.mesh} subdivided: {len(V)} vertices, {len(F)} faces")
    off = offset_surface(V, F, 0.1)
    sh = LambertianShading()
    for res in (128, 256):
        rng = np.random.default_rng(0)
        cams = [sample_camera(off, rng, resolution=res) for _ in range(a.repeat)]
        Gs = [np.random.default_rng(i).standard_normal((res, res, 3)) for i in range(a.repeat)]
        k = iter(range(10**9))

        def ours():
            i = next(k) % a.repeat
            r = render(V, F, cams[i], sh)
            image_vjp(V, F, r, Gs[i])

        def only_render():
            render(V, F, cams[next(k) % a.repeat], sh)

        rs = [render(V, F, c, sh) for c in cams]

        def peer():
            i = next(k) % a.repeat
            torch_peer(V, F, rs[i], Gs[i], sh.light_matrix(cams[i]))

        ours()
        peer()
        t_ours = median_seconds(ours, a.repeat)
        t_render = median_seconds(only_render, a.repeat)
        t_peer = median_seconds(peer, a.repeat)
        g1 = image_vjp(V, F, rs[0], Gs[0])
        g2 = torch_peer(V, F, rs[0], Gs[0], sh.light_matrix(cams[0]))
        err = np.abs(g1 - g2).max() / max(1e-300, np.abs(g2).max())
        print(f"{res}^2: ours render+VJP {t_ours * 1e3:.2f} ms (render {t_render * 1e3:.2f} ms, "
              f"VJP {(t_ours - t_render) * 1e3:.2f} ms); torch autograd VJP alone (same raster) "
              f"{t_peer * 1e3:.2f} ms; ratio peer-VJP / our render+VJP "
              f"{t_peer / t_ours:.1f}x, peer-VJP / our VJP "
              f"{t_peer / max(1e-9, t_ours - t_render):.1f}x; max rel. difference {err:.1e}")
    if a.skip_run:
        return 0
    t = time.perf_counter()
    run = Paparazzi(V, F, "guided", None, PaparazziParams(iterations=a.iterations,
                                                           resolution=128, monitor_every=100))
    setup = time.perf_counter() - t
    last = None
    for last in run.steps():
        pass
    total = time.perf_counter() - t
    n = last.iteration
    s = last.seconds
    print(f"guided filter run: {len(V)} vertices, 128^2, {n} iterations, remesh every 30: "
          f"total {total:.1f} s ({total / 60:.2f} min; setup {setup:.1f} s)")
    print("  per iteration: " + ", ".join(f"{k} {s[k] / n * 1e3:.1f} ms" for k in
                                          ("render", "filter", "derivative", "remesh", "monitor")))
    print(f"  monitor energy {last.metrics['initial_monitor_energy']:.4g} -> "
          f"{last.metrics['monitor_energy']:.4g}; rollbacks {int(last.metrics['rollbacks'])}; "
          f"output {len(last.V)} vertices")
    return 0


if __name__ == "__main__":
    sys.exit(main())
