"""The compiled half-flap kernels (algorithms/subdivision/kernels.py) and their hand-written
backward passes: the same values and gradients as the plain PyTorch path, and finite differences.
"""

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.subdivision.data import normalization
from algorithms.subdivision.model import (MeshLevels, SubdivisionNet, _fused,
                                          compiled_kernels, set_compiled_kernels)

torch = pytest.importorskip("torch")
pytest.importorskip("numba")
DATA = "tests/data/"


def _mesh(name):
    m = read_mesh(DATA + name)
    c, s = normalization(m.V)
    return (m.V - c) * s, m.F


def _values_and_grads(net, V, F, fused):
    net.fused = fused
    net.module.zero_grad()
    ml = MeshLevels(F, len(V), 2, torch.float64)
    V0 = torch.from_numpy(np.ascontiguousarray(V)).requires_grad_(True)
    outs = net.forward(V0, ml)
    rng = np.random.default_rng(0)
    # a loss that weighs every coordinate of every level differently
    loss = sum((o * torch.from_numpy(rng.standard_normal(o.shape))).sum() + (o ** 2).sum()
               for o in outs)
    loss.backward()
    grads = {k: p.grad.clone() for k, p in net.module.named_parameters()}
    return [o.detach() for o in outs], V0.grad.clone(), grads


@pytest.mark.parametrize("name", ["spot_lowres.obj",    # closed
                                  "hand_lowres.obj"])   # boundary: mirrored flaps
def test_compiled_path_equals_pytorch_path_values_and_gradients(name):
    assert compiled_kernels() is not None
    V, F = _mesh(name)
    net = SubdivisionNet(seed=7)
    net.module.double()
    a = _values_and_grads(net, V, F, True)
    b = _values_and_grads(net, V, F, False)
    for x, y in zip(a[0], b[0]):
        assert float((x - y).abs().max()) < 1e-12
    scale = float(b[1].abs().max())
    assert scale > 0 and float((a[1] - b[1]).abs().max()) < 1e-10 * scale
    for k in b[2]:
        s = float(b[2][k].abs().max())
        assert s > 0, k   # every parameter gets a gradient
        assert float((a[2][k] - b[2][k]).abs().max()) < 1e-10 * s, k


def test_switching_the_kernels_off_uses_the_pytorch_path():
    V, F = _mesh("hand_lowres.obj")
    net = SubdivisionNet(seed=2)
    ml = MeshLevels(F, len(V), 1, net.dtype)
    V0 = torch.from_numpy(V).to(net.dtype)
    with torch.no_grad():
        on = net.forward(V0, ml)[-1]
        before = set_compiled_kernels(False)
        try:
            assert _fused(torch) is None
            off = net.forward(V0, ml)[-1]
        finally:
            set_compiled_kernels(before)
    assert float((on - off).abs().max()) < 1e-4


def _level(name):
    V, F = _mesh(name)
    return torch.from_numpy(V), MeshLevels(F, len(V), 1, torch.float64).levels[0]


@pytest.mark.parametrize("name", ["spot_lowres.obj", "hand_lowres.obj"])
def test_flap_gradient_matches_finite_differences(name):
    fused = _fused(torch)
    V, lv = _level(name)
    rng = np.random.default_rng(1)
    H = len(lv["ijkl"])
    wl = torch.from_numpy(rng.standard_normal((H, 7, 3)))
    wr = torch.from_numpy(rng.standard_normal((H, 3, 3)))

    def f(X):
        loc, R = fused.Flap.apply(X, lv)
        return (loc * wl).sum() + (R * wr).sum()

    X = V.clone().requires_grad_(True)
    f(X).backward()
    g = X.grad.numpy()
    # central differences along random directions and single coordinates
    h = 1e-6
    for t in range(6):
        d = rng.standard_normal(V.shape) if t < 3 else np.zeros(V.shape)
        if t >= 3:
            d[rng.integers(len(V)), rng.integers(3)] = 1.0
        D = torch.from_numpy(d)
        with torch.no_grad():
            fd = (float(f(V + h * D)) - float(f(V - h * D))) / (2 * h)
        an = float((g * d).sum())
        assert abs(fd - an) <= 1e-6 * max(1.0, abs(an)), (t, fd, an)


def test_pool_and_slot_gather_pass_gradcheck():
    fused = _fused(torch)
    V, lv = _level("hand_lowres.obj")
    ijkl = lv["ijkl"][:40].clone()
    ijkl = torch.remainder(ijkl, 12)   # a small problem with repeated vertices
    rng = np.random.default_rng(3)
    Z4 = torch.from_numpy(rng.standard_normal((12, 4, 5))).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda z: fused.SlotGather.apply(z, ijkl), (Z4,))
    out = torch.from_numpy(rng.standard_normal((40, 6))).requires_grad_(True)
    Q = torch.linalg.qr(torch.from_numpy(rng.standard_normal((40, 3, 3))))[0]
    R = Q.clone().requires_grad_(True)
    dst = ijkl[:, 0].clone()
    count = torch.bincount(dst, minlength=12).clamp_min(1).to(torch.float64)
    assert torch.autograd.gradcheck(lambda o, r: fused.Pool.apply(o, r, dst, count), (out, R))
    # and Pool is the plain average of [R^T out[:3], out[3:]]
    with torch.no_grad():
        got = fused.Pool.apply(out, R, dst, count)
        w = torch.cat([torch.bmm(out[:, None, :3], R)[:, 0], out[:, 3:]], 1)
        want = torch.zeros(12, 6, dtype=torch.float64).index_add_(0, dst, w) / count[:, None]
    assert float((got - want).abs().max()) < 1e-12
