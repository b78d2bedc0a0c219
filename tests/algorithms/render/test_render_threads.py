"""Issue 25: the renderer's normal derivative on Numba's threads gives the same bits for one and
two threads (per-face terms on threads, added up in face order), from a worker thread too."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from algorithms import compiled
from algorithms.mesh import icosphere
from algorithms.render import (LambertianShading, compiled_kernels, image_vjp, look_at,
                               normal_vjp, render, set_compiled_kernels)

pytestmark = pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")


def outputs():
    V, F = icosphere(5)  # 20480 faces, ~10k seen: several chunks of faces
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    cam = look_at((1.5, 0.5, 2.0), (0, 0, 0), width=2.2, resolution=160)
    r = render(V, F, cam, LambertianShading())
    G = np.random.default_rng(1).standard_normal(r.image.shape)
    g = np.random.default_rng(2).standard_normal((len(F), 3))
    return (image_vjp(V, F, r, G), normal_vjp(V, F, np.arange(len(F)), g), len(r.faces))


def test_vjp_same_bits_for_one_and_two_threads_and_numpy_to_round_off():
    import numba

    kern = compiled_kernels()
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = outputs()
    finally:
        numba.set_num_threads(previous)
    assert one[2] > 2 * kern.VJP_CHUNK
    if numba.config.NUMBA_NUM_THREADS >= 2:
        numba.set_num_threads(2)
        try:
            assert compiled.use_threads()
            two = outputs()
        finally:
            numba.set_num_threads(previous)
        for a, b in zip(one[:2], two[:2]):
            assert a.tobytes() == b.tobytes()
        got = {}
        t = threading.Thread(target=lambda: got.setdefault("x", outputs()))
        t.start()
        t.join(300)
        for a, b in zip(one[:2], got["x"][:2]):
            assert a.tobytes() == b.tobytes()
    prev = set_compiled_kernels(False)
    try:
        ref = outputs()
    finally:
        set_compiled_kernels(prev)
    for a, b in zip(one[:2], ref[:2]):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * np.abs(b).max())
        assert np.abs(b).max() > 0
