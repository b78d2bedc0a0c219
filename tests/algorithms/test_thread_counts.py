"""The compiled kernels (Numba, OpenMP layer) and PyTorch share a thread's OpenMP thread count:
Numba sets it to its own at every parallel launch, and PyTorch's CPU kernels then use it. With
different counts, torch's results on a thread depended on whether a kernel had run there (the
image classifier's logits changed in their last bits after one ``image_vjp``, and a study replay
of an adversarial run, logged on another thread, reported a mismatch). ``algorithms.compiled``
makes Numba's count OpenMP's (issue 23, sixth pass)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.conftest import ROOT

CODE = """
import json, threading
import algorithms.compiled  # what importing any algorithm does first
import numba, numpy as np, torch
from algorithms.mesh import icosphere
from algorithms.render import LambertianShading, image_vjp, look_at, render

before = torch.get_num_threads()
V, F = icosphere(5)
cam = look_at((1.5, 0.5, 2.0), (0, 0, 0), width=2.2, resolution=160)
r = render(V, F, cam, LambertianShading())
image_vjp(V, F, r, np.ones_like(r.image))     # a parallel Numba kernel where it has 2+ threads
after = torch.get_num_threads()
other = []
t = threading.Thread(target=lambda: other.append(torch.get_num_threads()))
t.start(); t.join()
print(json.dumps({"numba": numba.get_num_threads(), "before": before, "after": after,
                  "other_thread": other[0]}))
"""


def _counts(env_over: dict) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")}
    env.update(env_over)
    out = subprocess.run([sys.executable, "-c", CODE], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("env, numba_threads", [
    ({"OMP_NUM_THREADS": "1"}, 1), ({"NUMBA_NUM_THREADS": "1"}, 1), ({}, None)])
def test_a_kernel_launch_leaves_pytorchs_thread_count_as_it_was(env, numba_threads):
    pytest.importorskip("numba")
    pytest.importorskip("torch")
    c = _counts(env)
    if numba_threads is not None:
        assert c["numba"] == numba_threads, c
    assert c["before"] == c["after"] == c["other_thread"], c
