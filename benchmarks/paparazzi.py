"""Paparazzi benchmark (issue 12): render + d(image)/d(vertices) per iteration against PyTorch
autograd through the same rasterization, and a whole guided-filter run with its time split.

    python benchmarks/paparazzi.py [--mesh fandisk.off] [--iterations 3000] [--skip-run]
                                   [--learning-rate 0] [--remesh-threshold 0]

Prints sizes, medians and ratios measured in this run. The mesh is Loop-subdivided once
(fandisk: 7,229 -> 28,910 vertices, the thesis's "26K" row).

Threads (issue 25): the last section runs rasterize, render and the image VJP at 128^2 and 256^2
in child processes with NUMBA_NUM_THREADS=1 and =2 (alternating rounds,
benchmarks/_threads.py); ratio = 2 threads / 1 thread. The VJP's per-face terms run on the
threads; the rasterizer stays on one thread. ``--no-threads`` skips it, ``--rounds`` sets the
rounds; ``--skip-run`` does not skip it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._threads import child_report, threads_section  # noqa: E402
from benchmarks._timing import mesh_path  # noqa: E402


def timed(fn, repeat):
    """Medians of the wall time and of this process's CPU time of ``repeat`` calls (one thread:
    the CPU time is what the call costs, not inflated by other processes on a loaded machine)."""
    wall, cpu = [], []
    for _ in range(max(1, repeat)):
        t, c = time.perf_counter(), time.process_time()
        fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - t)
    return float(np.median(wall)), float(np.median(cpu))


def torch_peer(V, F, face_id, G, light_matrix, *, seen_only=False):
    """dE/dV by PyTorch autograd (float64, one thread) through the same image formation: given
    our rasterizer's face ids, the face normals in torch (of all faces, as a PyTorch renderer
    does; ``seen_only``: only of the faces seen, found with ``torch.unique``), the shaded image
    ``(n.l + 1)/2`` gathered per pixel, ``E = <G, image>``, backward."""
    import torch

    Vt = torch.tensor(V, requires_grad=True)
    fid = torch.as_tensor(face_id.ravel())
    m = fid >= 0
    Ft = torch.as_tensor(F)
    fm = fid[m]
    if seen_only:
        faces, inv = torch.unique(fm, return_inverse=True)
        Ft, fm = Ft[faces], inv
    N = torch.linalg.cross(Vt[Ft[:, 1]] - Vt[Ft[:, 0]], Vt[Ft[:, 2]] - Vt[Ft[:, 0]])
    N = N / N.norm(dim=1, keepdim=True)
    col = 0.5 * N @ torch.as_tensor(light_matrix) + 0.5
    img = torch.zeros(fid.shape[0], 3, dtype=torch.float64)
    img[m] = col[fm]
    (img * torch.as_tensor(G.reshape(-1, 3))).sum().backward()
    return Vt.grad.numpy()


def threads_child(mesh: str, repeat: int) -> None:
    """Child of the threads section: render and VJP with this process's Numba threads."""
    from algorithms.mesh import loop_subdivide, read_mesh
    from algorithms.mesh.operators import normalize_unit_box
    from algorithms.paparazzi import offset_surface, sample_camera
    from algorithms.render import LambertianShading, image_vjp, rasterize, render

    d = read_mesh(mesh_path(mesh))
    V, F = loop_subdivide(d.V, d.F, 1)
    V = normalize_unit_box(V)[0] * 2
    off = offset_surface(V, F, 0.1)
    sh = LambertianShading()
    times = {}
    for res in (128, 256):
        rng = np.random.default_rng(0)
        cams = [sample_camera(off, rng, resolution=res) for _ in range(repeat)]
        Gs = [np.random.default_rng(i).standard_normal((res, res, 3)) for i in range(repeat)]
        rs = [render(V, F, c, sh) for c in cams]
        for i in range(repeat):
            image_vjp(V, F, rs[i], Gs[i])
        k = iter(range(10**9))
        n = 2 * repeat
        times[f"rasterize {res}^2"] = 1e3 * timed(
            lambda: rasterize(V, F, cams[next(k) % repeat]), n)[0]
        times[f"render {res}^2"] = 1e3 * timed(
            lambda: render(V, F, cams[next(k) % repeat], sh), n)[0]

        def vjp():
            i = next(k) % repeat
            image_vjp(V, F, rs[i], Gs[i])
        times[f"image VJP {res}^2 ({int(np.median([len(r.faces) for r in rs]))} faces)"] = \
            1e3 * timed(vjp, n)[0]
    child_report(times)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", default="fandisk.off")
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--skip-run", action="store_true")
    ap.add_argument("--learning-rate", type=float, default=0.0,
                    help="whole run's NAdam step (0 = the guided filter's default, as the CLI)")
    ap.add_argument("--remesh-threshold", type=float, default=0.0,
                    help="whole run's remesh_threshold (0 = remesh at every check, the thesis)")
    ap.add_argument("--no-threads", action="store_true", help="skip the threads section")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the threads section")
    ap.add_argument("--threads-child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.threads_child:
        threads_child(a.mesh, a.repeat)
        return 0
    if not a.no_threads and mesh_path(a.mesh).exists():
        threads_section(__file__, "paparazzi", ["--mesh", a.mesh, "--repeat", str(a.repeat)],
                        rounds=a.rounds, title=f"renderer on {a.mesh} subdivided once")
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
    print(f"one thread; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; times are "
          "medians over the views of the wall time and [in brackets] of this process's CPU time; "
          "ratios are of medians measured in this run")
    print("peer: the same raster (face ids from our rasterizer), then PyTorch autograd (float64, "
          "one thread): face normals, (n.l + 1)/2 per pixel, backward of <G, image>")
    from algorithms.render import rasterize

    for res in (128, 256):
        rng = np.random.default_rng(0)
        cams = [sample_camera(off, rng, resolution=res) for _ in range(a.repeat)]
        Gs = [np.random.default_rng(i).standard_normal((res, res, 3)) for i in range(a.repeat)]
        rs = [render(V, F, c, sh) for c in cams]
        Ms = [sh.light_matrix(c) for c in cams]
        k = iter(range(10**9))

        def ours():
            i = next(k) % a.repeat
            r = render(V, F, cams[i], sh)
            image_vjp(V, F, r, Gs[i])

        def only_render():
            render(V, F, cams[next(k) % a.repeat], sh)

        def only_vjp():
            i = next(k) % a.repeat
            image_vjp(V, F, rs[i], Gs[i])

        def only_raster():
            rasterize(V, F, cams[next(k) % a.repeat])

        def peer(seen_only=False):
            i = next(k) % a.repeat
            torch_peer(V, F, rs[i].raster.face_id, Gs[i], Ms[i], seen_only=seen_only)

        def peer_full(seen_only=False):
            i = next(k) % a.repeat
            fid = rasterize(V, F, cams[i]).face_id
            torch_peer(V, F, fid, Gs[i], Ms[i], seen_only=seen_only)

        for f in (ours, peer, lambda: peer(True)):
            f()
        n = 2 * a.repeat
        t_ours = timed(ours, n)
        t_render = timed(only_render, n)
        t_vjp = timed(only_vjp, n)
        t_raster = timed(only_raster, n)
        t_peer = timed(peer, n)
        t_full = timed(peer_full, n)
        t_peer_s = timed(lambda: peer(True), n)
        t_full_s = timed(lambda: peer_full(True), n)
        g1 = image_vjp(V, F, rs[0], Gs[0])
        g2 = torch_peer(V, F, rs[0].raster.face_id, Gs[0], Ms[0])
        err = np.abs(g1 - g2).max() / max(1e-300, np.abs(g2).max())
        n_seen = int(np.median([len(r.faces) for r in rs]))

        def ms(t):
            return f"{t[0] * 1e3:.2f} ms [{t[1] * 1e3:.2f}]"

        def ratio(x, y):
            return f"{x[0] / y[0]:.1f}x [CPU {x[1] / y[1]:.1f}x]"

        print(f"{res}^2 ({n_seen} faces seen, median): ours render+VJP {ms(t_ours)} (render "
              f"{ms(t_render)} of which rasterize {ms(t_raster)}; VJP {ms(t_vjp)}) "
              f"[target <= 10 ms]; max rel. difference to the peer {err:.1e}")
        print(f"  peer, normals of all faces: VJP (torch forward + backward) {ms(t_peer)}, with "
              f"the rasterization {ms(t_full)}; peer VJP / our VJP {ratio(t_peer, t_vjp)}; peer "
              f"(raster + torch shading + backward) / our render+VJP {ratio(t_full, t_ours)} "
              f"[target >= 10x]")
        print(f"  peer, normals of the seen faces only: VJP {ms(t_peer_s)}, with the rasterization "
              f"{ms(t_full_s)}; peer VJP / our VJP {ratio(t_peer_s, t_vjp)}; peer (raster + torch "
              f"shading + backward) / our render+VJP {ratio(t_full_s, t_ours)}")
    if a.skip_run:
        return 0

    t = time.perf_counter()
    run = Paparazzi(V, F, "guided", None, PaparazziParams(
        iterations=a.iterations, resolution=128, monitor_every=100,
        learning_rate=a.learning_rate, remesh_threshold=a.remesh_threshold))
    setup = time.perf_counter() - t
    last = None
    for last in run.steps():
        pass
    total = time.perf_counter() - t
    n = last.iteration
    s = last.seconds
    load = os.getloadavg()
    print(f"guided filter run: {len(V)} vertices, 128^2, {n} iterations, learning rate "
          f"{run.learning_rate:g}, checked every 30 ("
          + ("remeshed each time" if run.params.remesh_threshold <= 0 else
             f"remeshed when > {run.params.remesh_threshold:.0%} of the edges left the band")
          + f"): total {total:.1f} s "
          f"({total / 60:.2f} min; setup {setup:.1f} s); load average at the end "
          f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on {os.cpu_count()} cores")
    print("  per iteration (Table 2.1): " + ", ".join(
        f"{k} {s[k] / n * 1e3:.1f} ms" for k in ("render", "filter", "derivative", "remesh",
                                                  "monitor")))
    print(f"  remeshes {int(last.metrics['remeshes'])} (rejected "
          f"{int(last.metrics['remesh_rejected'])}) of {n // 30} checks; rollbacks "
          f"{int(last.metrics['rollbacks'])}; monitor energy "
          f"{last.metrics['initial_monitor_energy']:.4g} -> {last.metrics['monitor_energy']:.4g}; "
          f"output {len(last.V)} vertices")
    return 0


if __name__ == "__main__":
    sys.exit(main())
