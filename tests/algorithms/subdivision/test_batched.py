"""The fast network evaluation equals the plain formulas; batches equal meshes one by one."""

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.subdivision.data import normalization
from algorithms.subdivision.model import FEATURES, MeshLevels, SubdivisionNet

torch = pytest.importorskip("torch")
DATA = "tests/data/"


def _mesh(name):
    m = read_mesh(DATA + name)
    c, s = normalization(m.V)
    return (m.V - c) * s, m.F


def _net64(seed):
    net = SubdivisionNet(seed=seed)
    net.module.double()
    return net


def _reference_forward(net, V0, ml):
    """The module docstring written out plainly: per half-flap inputs in the local frame
    (one full input vector of 21 or 137 numbers per flap), MLP, averages."""
    def unit(x):
        return x / torch.linalg.vector_norm(x, dim=1, keepdim=True).clamp_min(1e-12)

    def apply(name, V, Z, lv):
        i, j, k, l = lv["ijkl"].T
        F = lv["F"]
        FN = unit(torch.linalg.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]))
        x = unit(V[j] - V[i])
        nz = FN[lv["face"]] + FN[lv["twin"]] * lv["has_twin"][:, None]
        z = unit(nz - (nz * x).sum(1, keepdim=True) * x)
        y = torch.linalg.cross(z, x)
        loc = lambda w: torch.stack([(w * x).sum(1), (w * y).sum(1), (w * z).sum(1)], 1)  # noqa
        acc = torch.zeros_like(V).index_add_(0, lv["nb_src"], V[lv["nb_dst"]])
        D = V - acc / lv["deg"][:, None]
        mir = torch.tensor([1.0, -1.0, -1.0], dtype=V.dtype)
        hl = lv["has_l"][:, None]
        eil = torch.where(hl, loc(V[l] - V[i]), loc(V[k] - V[i]) * mir)
        dl = torch.where(hl, loc(D[l]), loc(D[k]) * mir)
        g = [loc(V[j] - V[i]), loc(V[k] - V[i]), eil]
        if Z is None:
            inp = torch.cat(g + [loc(D[i]), loc(D[j]), loc(D[k]), dl], 1)
        else:
            inp = torch.cat(g + [loc(D[i]), Z[i], loc(D[j]), Z[j], loc(D[k]), Z[k], dl, Z[l]], 1)
        out = net.module[name](inp)
        disp = out[:, :1] * x + out[:, 1:2] * y + out[:, 2:3] * z
        return disp, out[:, 3:]

    def avg(index, rows, count, vals):
        return torch.zeros(rows, vals.shape[1], dtype=vals.dtype).index_add_(0, index, vals) \
            / count

    lv = ml.levels[0]
    d, f = apply("I", V0, None, lv)
    V = V0 + avg(lv["ijkl"][:, 0], len(V0), lv["src_count"], d)
    Z = avg(lv["ijkl"][:, 0], len(V0), lv["src_count"], f)
    outs = [V]
    for lv in ml.levels:
        d, f = apply("V", V, Z, lv)
        V = V + avg(lv["ijkl"][:, 0], len(V), lv["src_count"], d)
        Z = avg(lv["ijkl"][:, 0], len(V), lv["src_count"], f)
        d, f = apply("E", V, Z, lv)
        E = lv["E"]
        V = torch.cat([V, 0.5 * (V[E[:, 0]] + V[E[:, 1]])
                       + avg(lv["edge"], lv["e"], lv["edge_count"], d)])
        Z = torch.cat([Z, avg(lv["edge"], lv["e"], lv["edge_count"], f)])
        outs.append(V)
    assert Z.shape[1] == FEATURES - 3
    return outs


@pytest.mark.parametrize("name", ["spot_lowres.obj",    # closed
                                  "hand_lowres.obj"])   # boundary (mirrored flaps)
def test_fast_forward_equals_the_plain_formulas(name):
    V, F = _mesh(name)
    net = _net64(4)
    ml = MeshLevels(F, len(V), 2, torch.float64)
    V0 = torch.from_numpy(V)
    with torch.no_grad():
        got = net.forward(V0, ml)
        ref = _reference_forward(net, V0, ml)
    assert [len(x) for x in got] == [len(x) for x in ref]
    for a, b in zip(got, ref):
        assert float((a - b).abs().max()) < 1e-10
    # and it is not trivially the input: level 2 moved away from the mid-points
    assert float((got[2][:len(V)] - V0).abs().max()) > 1e-3


def test_batched_network_equals_mesh_by_mesh():
    from algorithms.subdivision.metrics import coarsen_to_vertices

    meshes = [_mesh("spot_lowres.obj"), _mesh("hand_lowres.obj")]
    meshes.append(coarsen_to_vertices(*meshes[0], 200))
    net = _net64(5)
    mls = [MeshLevels(F, len(V), 2, torch.float64) for V, F in meshes]
    batch = MeshLevels.batch(mls)
    assert batch.meshes == 3 and batch.sizes[0] == sum(len(V) for V, _ in meshes)
    V0s = [torch.from_numpy(np.ascontiguousarray(V)) for V, _ in meshes]
    with torch.no_grad():
        one = [net.forward(v, m) for v, m in zip(V0s, mls)]
        both = net.forward(torch.cat(V0s), batch)
    for lev in range(3):
        np.testing.assert_array_equal(
            batch.faces[lev], np.concatenate([m.faces[lev] + o for m, o in zip(
                mls, np.cumsum([0] + [m.sizes[lev] for m in mls])[:-1])]))
        want = torch.cat([o[lev] for o in one])
        assert float((both[lev] - want).abs().max()) < 1e-10

    # gradients of the summed loss agree too
    def grads(fn):
        net.module.zero_grad()
        fn().backward()
        return torch.cat([p.grad.reshape(-1) for p in net.module.parameters()])

    g1 = grads(lambda: sum((net.forward(v, m)[2] ** 2).sum() for v, m in zip(V0s, mls)))
    g2 = grads(lambda: (net.forward(torch.cat(V0s), batch)[2] ** 2).sum())
    assert float((g1 - g2).abs().max()) < 1e-9 * float(g1.abs().max())
