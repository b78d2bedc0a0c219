import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import read_mesh
from algorithms.subdivision.model import (SubdivisionNet, WeightsError, load_weights,
                                          neural_subdivide, save_weights)

torch = pytest.importorskip("torch")
DATA = "tests/data/"


def _rotation(seed):
    Q = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))[0]
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1
    return Q


@pytest.mark.parametrize("name", ["spot_lowres.obj", "hand_lowres.obj"])
def test_rigid_motion_invariance(name):
    m = read_mesh(DATA + name)
    net = SubdivisionNet(seed=3)
    V, F = neural_subdivide(m.V, m.F, 2, net)
    assert len(F) == 16 * len(m.F)
    R, t = _rotation(1), np.array([3.0, -20.0, 7.5])
    Vr, Fr = neural_subdivide(m.V @ R.T + t, m.F, 2, net)
    np.testing.assert_array_equal(F, Fr)
    diag = np.linalg.norm(m.V.max(0) - m.V.min(0))
    err = np.abs(Vr - (V @ R.T + t)).max()
    assert err < 1e-5 * diag
    # the network does move vertices (it is not the identity / mid-point)
    from algorithms.mesh.subdivision import midpoint_subdivide

    assert not np.allclose(V[:len(m.V)], midpoint_subdivide(m.V, m.F, 2)[0][:len(m.V)])


def test_weights_round_trip_and_plain_errors(tmp_path):
    net = SubdivisionNet(seed=1)
    p = tmp_path / "w.pt"
    save_weights(p, net, {"trained_on": "x"})
    net2, info = load_weights(p)
    assert info["trained_on"] == "x"
    for k, v in net.state().items():
        assert torch.equal(v, net2.state()[k])
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a weights file at all")
    with pytest.raises(WeightsError, match="not a Stylize3D"):
        load_weights(bad)
    other = tmp_path / "other.pt"
    torch.save({"state_dict": {"a": torch.zeros(2)}}, other)
    with pytest.raises(WeightsError, match="not a Stylize3D"):
        load_weights(other)
    npz = tmp_path / "x.npz"
    np.savez(npz, a=np.zeros(3))
    with pytest.raises(WeightsError):
        load_weights(npz)
    with pytest.raises(WeightsError, match="does not exist"):
        load_weights(tmp_path / "missing.pt")


def test_levels_are_checked():
    m = read_mesh(DATA + "spot_lowres.obj")
    with pytest.raises(ParameterError):
        neural_subdivide(m.V, m.F, 4, SubdivisionNet())
    with pytest.raises(ParameterError):
        neural_subdivide(m.V, m.F, 0, SubdivisionNet())
    V1, F1 = neural_subdivide(m.V, m.F, 1, SubdivisionNet())
    assert len(F1) == 4 * len(m.F) and np.isfinite(V1).all()
