"""Compile the Numba kernels once, at installation (``python -m algorithms.warmup``).

The kernels are ``@njit(cache=True)``: the first call in a fresh installation compiles them
(tens of seconds for the self-parameterization loop) and stores the machine code next to the
sources; later processes load it in milliseconds. ``scripts/setup.sh`` runs this module right
after installing, so a user's first multigrid hierarchy or cubic stylization does not stall.
Running it again is cheap. It exercises every compiled path on a small sphere.
"""

from __future__ import annotations

import sys
import time


def main() -> int:
    t0 = time.perf_counter()
    from .deform.arap import compiled_kernels
    from .deform.cubic import CubicParams, CubicStylizer
    from .mesh.primitives import grid, icosphere
    from .mesh.selfparam import self_parameterize
    from .multigrid import surface_multigrid
    from .multigrid.applications import DataSmoother
    from .steps import run_to_end

    if compiled_kernels() is None:
        print("warm-up: Numba is not available; the NumPy fallbacks will be used.")
        return 0
    V, F = icosphere(3)
    run_to_end(CubicStylizer(V, F).steps(CubicParams(max_iterations=2)))
    for strategy in ("midpoint", "qslim", "vertex_removal"):
        self_parameterize(V, F, len(F) // 2, strategy=strategy)
    Vg, Fg = grid(8, 8)  # boundary cases
    self_parameterize(Vg, Fg, len(Fg) // 2)
    V4, F4 = icosphere(4)
    mg = surface_multigrid(V4, F4, min_vertices=100)
    for smoother in ("block_gauss_seidel", "gauss_seidel", "multicolor"):
        DataSmoother(V4, F4, mg=mg, smoother=smoother).smooth(V4[:, 0], 1e-3)
    from .render import look_at, rasterize
    for projection in ("orthographic", "perspective"):
        rasterize(V4, F4, look_at((0, 0, 3), (0, 0, 0), projection=projection, resolution=16))
    try:  # neural subdivision's half-flap kernels, forward and backward (training)
        import torch

        from .subdivision.model import MeshLevels, SubdivisionNet

        net = SubdivisionNet()
        for Vs, Fs in ((V, F), (Vg, Fg)):
            V0 = torch.from_numpy(Vs).to(net.dtype).requires_grad_(True)
            net.forward(V0, MeshLevels(Fs, len(Vs), 1, net.dtype))[-1].sum().backward()
    except ImportError:  # PyTorch is optional for everything else
        pass
    print(f"warm-up: compiled kernels ready in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
