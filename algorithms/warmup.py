"""Compile the Numba kernels once, at installation (``python -m algorithms.warmup``).

The kernels are ``@njit(cache=True)``: the first call in a fresh installation compiles them
(tens of seconds for the self-parameterization loop) and stores the machine code next to the
sources; later processes load it in milliseconds. ``scripts/setup.sh`` runs this module right
after installing, so a user's first cubic stylization, Paparazzi run, multigrid hierarchy,
coarsening or subdivision does not stall. Running it again is cheap.

:func:`exercise` runs every kernel family (deform and its progressive replay, decimation,
self-parameterization, multigrid relaxation, the renderer with its Lambertian and
spherical-harmonics derivatives, Paparazzi's guided filter, its SLIC superpixels, spectral
coarsening, neural subdivision's half-flap kernels) on meshes big enough that the parallel
kernels run where there are threads (the SLIC, which has none, on a small picture), and
returns a digest of each family's results. ``--digest`` prints them as JSON: the kernels give
the same bits for any thread count and cache state, so two processes must print the same
digests (results of BLAS products, whose last bits follow OpenBLAS's thread count, are left
out) (``tests/algorithms/test_numba_cache.py`` checks it across fresh processes, thread
counts and concurrent first compiles).
"""

from __future__ import annotations

import hashlib
import json
import sys
import time

import numpy as np


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def exercise(families: tuple[str, ...] | None = None) -> dict[str, str]:
    """Run the compiled paths of the named kernel families (all by default); returns
    ``{family: digest of its results}``. Raises RuntimeError where Numba is not available."""
    from .deform.arap import compiled_kernels
    from .mesh.primitives import grid, icosphere

    if compiled_kernels() is None:
        raise RuntimeError("Numba is not available (or STYLIZE3D_NUMBA=0)")
    wanted = set(FAMILIES if families is None else families)
    unknown = wanted - set(FAMILIES)
    if unknown:
        raise ValueError(f"unknown kernel families: {sorted(unknown)}")
    out: dict[str, str] = {}
    V3, F3 = icosphere(3)
    V5, F5 = icosphere(5)   # 10,242 vertices, 20,480 faces: the parallel kernels' sizes
    Vg, Fg = grid(8, 8)     # boundary cases

    if "deform" in wanted:
        from .deform.cubic import CubicParams, CubicStylizer
        from .steps import run_to_end

        a = run_to_end(CubicStylizer(V3, F3).steps(CubicParams(max_iterations=2))).V
        b = run_to_end(CubicStylizer(V5, F5).steps(CubicParams(max_iterations=3))).V
        out["deform"] = _digest(a, b)
    if "progressive" in wanted:
        from .deform.cubic import CubicParams
        from .deform.progressive import ProgressiveParams, progressive_cubic

        out["progressive"] = _digest(progressive_cubic(
            V5, F5, CubicParams(max_iterations=2), ProgressiveParams(target_faces=2000)))
    if "decimate" in wanted:
        from .mesh.decimate import decimate

        res = [decimate(V5, F5, 2000, strategy=s) for s in ("qslim", "midpoint")]
        out["decimate"] = _digest(*[x for d in res for x in (d.V, d.F)])
    if "selfparam" in wanted:
        from .mesh.selfparam import self_parameterize

        res = [self_parameterize(V3, F3, len(F3) // 2, strategy=s)
               for s in ("midpoint", "qslim", "vertex_removal")]
        res.append(self_parameterize(Vg, Fg, len(Fg) // 2))
        out["selfparam"] = _digest(*[x for r in res for x in (r.V_coarse, r.F_coarse, r.bary)])
    if "multigrid" in wanted:
        from .multigrid import surface_multigrid
        from .multigrid.applications import DataSmoother

        mg = surface_multigrid(V5, F5, min_vertices=500)
        res = [DataSmoother(V5, F5, mg=mg, smoother=s).smooth(V5[:, 0], 1e-3)[0]
               for s in ("block_gauss_seidel", "gauss_seidel", "multicolor")]
        out["multigrid"] = _digest(*res)
    if "render" in wanted:
        from .render import LambertianShading, image_vjp, look_at, rasterize, render
        from .render.sh import environment, sh_image_vjp, sh_render

        res = []
        for projection in ("orthographic", "perspective"):
            r = rasterize(V5, F5, look_at((0, 0, 3), (0, 0, 0), projection=projection,
                                          resolution=64))
            res.append(r.face_id)
        cam = look_at((1.5, 0.5, 2.0), (0, 0, 0), width=2.2, resolution=160)
        r = render(V5, F5, cam, LambertianShading())
        G = np.cos(np.arange(r.image.size, dtype=np.float64)).reshape(r.image.shape)
        res += [r.image, image_vjp(V5, F5, r, G)]
        s = sh_render(V5, F5, cam, environment("Grace Cathedral"))
        g = sh_image_vjp(V5, F5, s, G)
        # (not g.lighting: a BLAS product, whose last bits follow OpenBLAS's thread count)
        res += [s.image, g.vertices]
        out["render"] = _digest(*res)
    if "paparazzi" in wanted:
        from .mesh.intersections import _aabb_neighbours
        from .paparazzi.filters import guided_filter

        rng = np.random.default_rng(0)
        img = rng.random((96, 96, 3))
        out["paparazzi"] = _digest(guided_filter(img, img, 15, 1e-4, 1),
                                   guided_filter(img, img, 15, 1e-8, 4),
                                   _aabb_neighbours(V5, F5, np.arange(len(F5)) % 7 == 0))
    if "slic" in wanted:   # Paparazzi's slic filter: seeds' k-means, both passes, connectivity
        from .paparazzi.slic import slic_labels

        rng = np.random.default_rng(0)
        y, x = np.mgrid[:72, :90]
        img = np.clip(np.stack([y / 72.0, x / 90.0, 0.5 + 0.1 * np.sin(x / 7.0)], -1)
                      + 0.05 * rng.random((72, 90, 3)), 0.0, 1.0)
        mask = ((y - 36) ** 2 + (x - 40) ** 2 < 30 ** 2) | ((y > 60) & (x > 70))
        out["slic"] = _digest(slic_labels(img, mask, 40), slic_labels(img, mask, 6))
    if "spectral" in wanted:
        from .mesh.operators import cotangent_laplacian, mass_matrix
        from .spectral.coarsen import CoarsenParams, coarsen

        L = -cotangent_laplacian(V5, F5)
        M = mass_matrix(V5, F5)
        step = coarsen(L, M, 300, 30, CoarsenParams(m=300, k=30, max_iterations=3,
                                                     balance_iterations=3))
        out["spectral"] = _digest(step.L.toarray(), step.G.toarray())
    if "subdivision" in wanted:
        try:  # neural subdivision's half-flap kernels, forward and backward (training)
            import torch

            from .subdivision.model import MeshLevels, SubdivisionNet
        except ImportError:  # PyTorch is optional for everything else
            out["subdivision"] = "no-torch"
        else:
            torch.manual_seed(0)
            net = SubdivisionNet()
            res = []
            for Vs, Fs in ((V3, F3), (Vg, Fg)):
                V0 = torch.from_numpy(Vs).to(net.dtype).requires_grad_(True)
                y = net.forward(V0, MeshLevels(Fs, len(Vs), 1, net.dtype))[-1]
                y.sum().backward()
                res += [y.detach().double().numpy(), V0.grad.double().numpy()]
            out["subdivision"] = _digest(*res)
    return out


FAMILIES = ("deform", "progressive", "decimate", "selfparam", "multigrid", "render",
            "paparazzi", "slic", "spectral", "subdivision")
"""The kernel families :func:`exercise` runs (one per compiled kernel module)."""


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    digest = "--digest" in argv
    families = tuple(a for a in argv if not a.startswith("--")) or None
    t0 = time.perf_counter()
    try:
        result = exercise(families)
    except RuntimeError:
        print("warm-up: Numba is not available; the NumPy fallbacks will be used.")
        return 0
    if digest:
        from .compiled import thread_count

        print(json.dumps({"digests": result, "threads": thread_count(),
                          "seconds": round(time.perf_counter() - t0, 2)}))
    else:
        print(f"warm-up: compiled kernels ready in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
