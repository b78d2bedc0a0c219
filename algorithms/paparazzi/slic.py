"""SLIC superpixels of a masked RGB picture: scikit-image 0.26's ``slic``, label for label, faster.

:func:`slic_labels` returns exactly what ::

    skimage.segmentation.slic(image, n_segments=n, compactness=c, mask=mask, start_label=1,
                              channel_axis=-1)

returns for a 2-D RGB picture (float64 after ``img_as_float``) and a non-empty mask, all other
arguments at their defaults (10 iterations, no smoothing, connectivity enforced with size
factors 0.5 and 3, no SLIC-zero, colours compared in CIELAB), as Paparazzi's ``slic`` filter
calls it. The preparation is scikit-image's and NumPy's own: ``skimage.color.rgb2lab``, the
seeds' random draws from ``RandomState(123)``, the seeds' distances (``pdist``); the compiled
kernels of :mod:`algorithms.paparazzi.slic_kernels` (Numba) do the rest: the rescaling over the
mask, the seeds' k-means (SciPy's ``kmeans2``), the two k-means passes of ``_slic_cython`` and
``_enforce_label_connectivity_cython``, with the same floating-point operations wherever a
result is kept (see that module). Tested label for label against scikit-image on rendered views
and edge cases (``tests/algorithms/paparazzi/test_slic_kernel.py``); the same labels in all
1,280 cuts tried: the 640 monitor views of the 40 meshes of the shared corpus, each with the
filter's segment count and again with a random one (2 to 400) and compactness 1, 10 or 30.

Measured (``benchmarks/slic_filter.py``: the 16 monitor views each of capsule, hippo and the
blob sample, 256 x 256, one thread, a quiet machine): 36.4 ms a picture with scikit-image, 9.6 ms
here (3.8 times faster): 4.1 ms of preparation (``rgb2lab`` about 2.5 of it, the random draws
about 1) and 5.4 ms of kernels (k-means about 0.7, the two passes and the connectivity 4.7), where
scikit-image spends about 30 ms in its k-means, Cython passes and connectivity.

Where the kernels are unavailable (Numba missing, ``STYLIZE3D_NUMBA=0``) or the call is not the
case above (another dtype, no mask, an empty mask, non-finite values), scikit-image's ``slic`` is
called itself.
"""

from __future__ import annotations

import time

import numpy as np

from ..compiled import KernelModule

__all__ = ["slic_labels", "spatial_weight", "window_steps"]

_KERNELS = KernelModule("algorithms.paparazzi.slic_kernels")

MAX_NUM_ITER = 10
"""``slic``'s default ``max_num_iter``."""


def _skimage_slic(image, mask, n_segments, compactness):
    from skimage.segmentation import slic

    return slic(image, n_segments=n_segments, compactness=compactness, mask=mask, start_label=1,
                channel_axis=-1)


def spatial_weight(step: float) -> float:
    """``_slic_cython``'s spatial weight ``1.0 / (step * step)``: its ``step`` is a C ``float``,
    so the step is rounded to float32 and squared in float32, then divided into 1.0 in double
    (inf for a step of 0, as its C division gives)."""
    f = np.float32(step)
    with np.errstate(divide="ignore"):
        return float(np.float64(1.0) / np.float64(f * f))


def window_steps(shape: tuple[int, int], n_centroids: int) -> tuple[int, int]:
    """``_slic_cython``'s window steps (y, x) for a picture of ``shape`` and that many
    segments (a window reaches two steps either side of its centre): the steps of
    ``regular_grid((1, H, W), n_centroids)``."""
    from skimage.util import regular_grid

    slices = regular_grid((1,) + tuple(shape), n_centroids)
    return tuple(int(s.step if s.step is not None else 1) for s in slices[1:])


def slic_labels(image, mask, n_segments: int, compactness: float = 10.0, *,
                timings: dict | None = None) -> np.ndarray:
    """``skimage.segmentation.slic(image, n_segments, compactness, mask=mask, start_label=1,
    channel_axis=-1)`` (module docstring): labels ``(H, W)`` int (``intp``), 0 off the mask.
    ``timings``, when given, receives ``{"init": s, "kernels": s}`` (seconds) for the compiled
    path."""
    kernels = _KERNELS.get()
    if kernels is None:
        return _skimage_slic(image, mask, n_segments, compactness)
    from skimage.util import img_as_float

    img = img_as_float(image)
    if mask is None or img.dtype != np.float64 or img.ndim != 3 or img.shape[2] != 3:
        return _skimage_slic(image, mask, n_segments, compactness)
    mask = np.ascontiguousarray(mask, dtype=bool)
    if mask.shape != img.shape[:2] or not mask.any():
        return _skimage_slic(image, mask, n_segments, compactness)
    t0 = time.perf_counter()
    from scipy.spatial.distance import pdist, squareform
    from skimage.color import rgb2lab

    # slic(): the picture rescaled to [0, 1] over the mask (np.min / np.max and the two
    # in-place operations, compiled), then scikit-image's CIELAB
    img, ok = kernels.rescale_masked(np.ascontiguousarray(img), mask)
    if not ok:
        return _skimage_slic(image, mask, n_segments, compactness)   # it raises
    lab = rgb2lab(img[np.newaxis])

    # _get_mask_centroids(): the random seeds and the dense subset (the same draws) ...
    ys, xs = np.nonzero(mask)
    py = ys.astype(np.float64)
    px = xs.astype(np.float64)
    rng = np.random.RandomState(123)
    idx_full = np.arange(len(py), dtype=int)
    idx = np.sort(rng.choice(idx_full, min(n_segments, len(py)), replace=False))
    n_dense = int((10 ** 2) * n_segments)
    if len(py) > n_dense:
        dense = np.sort(rng.choice(idx_full, n_dense, replace=False))
        dy, dx = py[dense], px[dense]
    else:
        dy, dx = py, px
    cy = py[idx]
    cx = px[idx]
    t1 = time.perf_counter()
    kernels.kmeans2_yx(dy, dx, cy, cx, 5, *mask.shape)          # ... kmeans2(iter=5)
    t2 = time.perf_counter()
    centroids = np.stack([np.zeros_like(cy), cy, cx], axis=1)
    dist = squareform(pdist(centroids))
    np.fill_diagonal(dist, np.inf)
    closest = dist.argmin(-1)
    steps = abs(centroids - centroids[closest, :]).mean(0)
    step = max(steps)

    # slic() / _slic_cython(): windows from regular_grid, ratio, the spatial weight
    n_centroids = len(cy)
    step_y, step_x = window_steps(mask.shape, n_centroids)
    ratio = 1.0 / compactness
    w = spatial_weight(step)
    segment_size = mask.sum() / n_centroids
    min_size = int(0.5 * segment_size)
    max_size = int(3 * segment_size)
    t3 = time.perf_counter()
    labels = kernels.slic_2d(lab[0], mask, cy, cx, step_y, step_x, w, ratio, MAX_NUM_ITER,
                             min_size, max_size)
    t4 = time.perf_counter()
    if timings is not None:
        timings["init"] = (t1 - t0) + (t3 - t2)
        timings["kernels"] = (t2 - t1) + (t4 - t3)
    return labels
