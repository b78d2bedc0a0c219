"""The compiled SLIC of Paparazzi's ``slic`` filter (algorithms/paparazzi/slic.py) gives
scikit-image's ``slic`` labels exactly, pixel for pixel: on rendered views of the bundled
samples, the way the filter calls it, and on edge cases; with the kernels off it is
scikit-image's ``slic`` itself."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from algorithms.paparazzi import slic as S
from tests.conftest import SAMPLES


def _skimage(img, mask, n, compactness=10.0):
    from skimage.segmentation import slic

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # kmeans2's "One of the clusters is empty"
        return slic(img, n_segments=n, compactness=compactness, mask=mask, start_label=1,
                    channel_axis=-1)


def _ours(img, mask, n, compactness=10.0):
    return S.slic_labels(img, mask, n, compactness)


def _same(img, mask, n, compactness=10.0):
    ref = _skimage(img, mask, n, compactness)
    out = _ours(img, mask, n, compactness)
    assert out.shape == ref.shape
    assert np.array_equal(out, ref), \
        f"{int((out != ref).sum())} of {out.size} labels differ (n={n})"
    return ref


@pytest.fixture(scope="module")
def compiled():
    if S._KERNELS.get() is None:
        pytest.skip("compiled kernels unavailable or switched off (STYLIZE3D_NUMBA=0)")
    return S._KERNELS.get()


@pytest.fixture(scope="module")
def views():
    """Every monitor view of the two bundled samples, rendered as Paparazzi's slic filter
    sees them: ``(image clipped to [0, 1], mask)``."""
    from algorithms.mesh.io import read_mesh
    from algorithms.paparazzi import Paparazzi
    from algorithms.paparazzi.optimize import PaparazziParams
    from algorithms.render import render

    out = []
    for name in ("blob.obj", "bumpy.obj"):
        m = read_mesh(SAMPLES / name)
        run = Paparazzi(m.V, m.F, "slic", None, PaparazziParams())
        for cam in run.monitor_cameras():
            r = render(run.V0, run.F0, cam, run.shading)
            out.append((np.clip(r.image, 0.0, 1.0), np.asarray(r.mask, bool)))
    return out


def _segments(mask, per_picture=100):
    return max(1, int(round(per_picture * float(mask.mean()))))


def test_rendered_views_give_scikit_images_labels(views, compiled):
    assert len(views) == 32
    for img, mask in views:
        ref = _same(img, mask, _segments(mask))
        assert ref.max() > 1 and (ref[~mask] == 0).all()


def test_other_compactness_and_segment_counts(views, compiled):
    img, mask = views[3]
    for n, compactness in ((10, 10.0), (250, 10.0), (60, 1.0), (60, 40.0)):
        _same(img, mask, n, compactness)


def test_a_crop_whose_sides_are_not_a_multiple_of_the_tile(views, compiled):
    img, mask = views[5]
    ys, xs = np.nonzero(mask)
    y0, x0 = int(ys.min()) + 7, int(xs.min()) + 3
    crop = (slice(y0, y0 + 101), slice(x0, x0 + 77))
    _same(np.ascontiguousarray(img[crop]), np.ascontiguousarray(mask[crop]), 30)


def test_a_full_mask(views, compiled):
    img, _ = views[0]
    _same(img, np.ones(img.shape[:2], bool), 100)


def _disc(shape, cy, cx, r):
    y, x = np.mgrid[:shape[0], :shape[1]]
    return (y - cy) ** 2 + (x - cx) ** 2 <= r * r


def test_a_tiny_mask(compiled):
    rng = np.random.default_rng(1)
    img = rng.random((64, 64, 3))
    for pixels, n in (([(10, 10), (10, 11), (11, 10)], 1), ([(10, 10), (10, 11), (11, 10)], 2),
                      ([(5, 5), (5, 6), (6, 5), (6, 6), (30, 40), (31, 40)], 3)):
        mask = np.zeros((64, 64), bool)
        for p in pixels:
            mask[p] = True
        _same(img, mask, n)


def test_more_segments_than_foreground_pixels(compiled):
    rng = np.random.default_rng(2)
    img = rng.random((48, 48, 3))
    mask = _disc((48, 48), 20, 25, 3.5)
    assert mask.sum() < 100
    _same(img, mask, 100)


def test_two_separate_blobs(views, compiled):
    img, _ = views[7]
    mask = _disc(img.shape[:2], 70, 60, 40) | _disc(img.shape[:2], 180, 190, 55)
    _same(img, mask, 30)


def test_a_constant_colour(compiled):
    img = np.full((96, 80, 3), 0.4)
    mask = _disc((96, 80), 50, 40, 35)
    _same(img, mask, 25)


def test_noise_and_few_colours(compiled):
    """Random colours (the colour term decides) and two colours (many equal distances)."""
    rng = np.random.default_rng(3)
    for seed in range(3):
        img = rng.random((70, 90, 3))
        mask = _disc((70, 90), 35, 40, 30 + 5 * seed) | (rng.random((70, 90)) < 0.05)
        _same(img, mask, 20 + 7 * seed)
    y, x = np.mgrid[:64, :64]
    two = np.where((((y // 8) + (x // 8)) % 2 == 0)[..., None], [0.2, 0.5, 0.9], [0.8, 0.1, 0.3])
    _same(two, _disc((64, 64), 32, 32, 28), 16)


def test_the_kmeans_of_the_seeds_is_scipys(compiled):
    """``kmeans2_yx`` against ``scipy.cluster.vq.kmeans2`` with a cluster that empties."""
    from scipy.cluster.vq import kmeans2

    rng = np.random.default_rng(4)
    py = np.sort(rng.integers(0, 50, 400)).astype(float)
    px = rng.integers(0, 60, 400).astype(float)
    cy = np.concatenate([py[::40], [200.0]])
    cx = np.concatenate([px[::40], [200.0]])
    data = np.stack([np.zeros_like(py), py, px], 1)
    codes = np.stack([np.zeros_like(cy), cy, cx], 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, _ = kmeans2(data, codes, iter=5)
    compiled.kmeans2_yx(py, px, cy, cx, 5, 50, 60)
    assert np.array_equal(ref[:, 1], cy) and np.array_equal(ref[:, 2], cx)


def test_connectivity_is_scikit_images(compiled):
    """``enforce_connectivity`` against the Cython on blocky label fields with holes."""
    from skimage.segmentation._slic import _enforce_label_connectivity_cython

    rng = np.random.default_rng(5)
    for min_size, max_size in ((1, 10), (6, 40), (20, 9)):
        seg = np.kron(rng.integers(0, 6, (12, 15)), np.ones((3, 3), np.int64)).astype(np.intp)
        seg[rng.random(seg.shape) < 0.1] = 0
        ref = _enforce_label_connectivity_cython(seg[None], min_size, max_size, start_label=1)[0]
        assert np.array_equal(compiled.enforce_connectivity(seg.astype(np.int64), min_size,
                                                            max_size), ref)


def test_without_the_kernels_it_is_scikit_images_slic(views, monkeypatch):
    img, mask = views[1]
    n = _segments(mask)
    calls = []
    import skimage.segmentation

    real = skimage.segmentation.slic
    monkeypatch.setattr(skimage.segmentation, "slic",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    previous = S._KERNELS.set(False)
    try:
        out = _ours(img, mask, n)
    finally:
        S._KERNELS.set(previous)
    assert calls == [1]
    assert np.array_equal(out, _skimage(img, mask, n))


def _cython_pass(planes, mask, cy, cx, cc, step, max_iter, ignore_color):
    """scikit-image's ``_slic_cython`` on the same segments; returns (labels, segments)."""
    from skimage.segmentation._slic import _slic_cython

    image = np.ascontiguousarray(np.moveaxis(planes, 0, -1)[None])
    seg = np.ascontiguousarray(np.column_stack([np.zeros_like(cy), cy, cx, cc]))
    labels = _slic_cython(image, np.ascontiguousarray(mask.view(np.uint8)[None]), seg, step,
                          max_iter, np.ones(3), False, start_label=1, ignore_color=ignore_color)
    return labels[0], seg


def test_one_pass_is_the_cythons_with_many_equal_distances(compiled):
    """Seeds on whole pixels, a picture of two colours: many pixels are exactly as far from two
    segments (the lowest segment must win), and a seed alone in its corner empties (NaN)."""
    H, W = 40, 52
    y, x = np.mgrid[:H, :W]
    planes = np.where(((x // 13) % 2 == 0)[None], 0.3, 1.1) * np.array([1.0, 0.5, -0.2])[:, None,
                                                                                       None]
    planes = np.ascontiguousarray(planes)
    mask = ~(((y - 20) ** 2 + (x - 26) ** 2 < 30) | (x == 40))
    mask[:3, :3] = False
    gy, gx = np.mgrid[4:H:9, 3:W:12]
    cy0 = np.append(gy.ravel().astype(float), 0.0)
    cx0 = np.append(gx.ravel().astype(float), 0.0)
    step = 9.0
    sy, sx = S.window_steps((H, W), len(cy0))
    w = S.spatial_weight(step)
    for ignore_color in (True, False):
        for max_iter in (1, 3, 10):
            cy, cx = cy0.copy(), cx0.copy()
            cc = np.zeros((len(cy), 3)) if ignore_color else \
                np.tile(planes[:, 0, 0], (len(cy), 1)) + 0.01 * np.arange(len(cy))[:, None]
            ref, seg = _cython_pass(planes, mask, cy, cx, cc, step, max_iter, ignore_color)
            out = compiled.slic_pass(planes, mask, cy, cx, cc, sy, sx, w, max_iter,
                                     ignore_color)
            assert np.array_equal(out, ref), (ignore_color, max_iter)
            assert np.array_equal(np.column_stack([cy, cx, cc]), seg[:, 1:], equal_nan=True)


def test_a_bound_equal_to_the_worst_distance_still_takes_its_tie(compiled):
    """A pixel as far from segment 0 (outside the tile, its bound over the tile reached at that
    pixel) as from segment 1 (inside, looked at first): segment 0 takes it, as in the Cython."""
    planes = np.zeros((3, 16, 16))
    mask = np.zeros((16, 16), bool)
    mask[0, 8] = True
    for step in (7.0, 9.5):
        cy, cx = np.array([-10.0, 10.0]), np.array([8.0, 8.0])
        cc = np.zeros((2, 3))
        ref, _ = _cython_pass(planes, mask, cy.copy(), cx.copy(), cc.copy(), step, 1, True)
        assert ref[0, 8] == 1
        sy, sx = S.window_steps((16, 16), 2)
        out = compiled.slic_pass(planes, mask, cy, cx, cc, sy, sx, S.spatial_weight(step), 1,
                                 True)
        assert np.array_equal(out, ref)


def test_the_spatial_weight_is_the_cythons(compiled):
    """The Cython takes ``step`` as a C float: colour distances D around ``w`` on either side
    of 1 / step^2 in float64 flip its choice exactly where :func:`spatial_weight` says."""
    for step in (7.3, 12.345, 26.1):
        w = S.spatial_weight(step)
        assert w != 1.0 / (step * step)
        c = np.sqrt(w)
        while c * c > w:
            c = np.nextafter(c, 0.0)
        hi = c
        while hi * hi <= w:
            hi = np.nextafter(hi, 1.0)
        for t, expected in ((c, 1), (hi, 2)):
            # pixel x = 1: segment 1 on it at colour distance t^2, segment 2 one pixel away
            planes = np.zeros((3, 1, 3))
            mask = np.ones((1, 3), bool)
            cy, cx = np.zeros(2), np.array([1.0, 0.0])
            cc = np.array([[t, 0.0, 0.0], [0.0, 0.0, 0.0]])
            ref, _ = _cython_pass(planes, mask, cy.copy(), cx.copy(), cc.copy(), step, 1, False)
            assert ref[0, 1] == expected
            sy, sx = S.window_steps((1, 3), 2)
            out = compiled.slic_pass(planes, mask, cy, cx, cc, sy, sx, w, 1, False)
            assert np.array_equal(out, ref)
