import numpy as np
import pytest

from algorithms.errors import InvalidMeshError
from algorithms.mesh import icosphere, read_mesh
from algorithms.mesh.primitives import grid
from algorithms.subdivision.baselines import (butterfly_subdivide, butterfly_weights,
                                              subdivide_baseline)


def _regular_grid(k=8):
    # equilateral-ish regular triangulation: every interior vertex has valence 6
    xs, ys = np.meshgrid(np.arange(k), np.arange(k))
    V = np.stack([xs + 0.5 * ys, ys * np.sqrt(3) / 2, 0 * xs], -1).reshape(-1, 3).astype(float)
    F = []
    for y in range(k - 1):
        for x in range(k - 1):
            a, b, c, d = y * k + x, y * k + x + 1, (y + 1) * k + x, (y + 1) * k + x + 1
            F += [[a, b, c], [b, d, c]]
    return V, np.array(F)


@pytest.mark.parametrize("K", range(3, 12))
def test_extraordinary_stencils_sum_to_a_quarter(K):
    assert np.isclose(butterfly_weights(K).sum(), 0.25)


def test_butterfly_interpolates_and_keeps_planes():
    V, F = _regular_grid()
    V[:, 2] = 0.3 * V[:, 0] - 0.2 * V[:, 1] + 1.0
    Vs, Fs = butterfly_subdivide(V, F, 2)
    np.testing.assert_array_equal(Vs[:len(V)], V)
    np.testing.assert_allclose(Vs[:, 2], 0.3 * Vs[:, 0] - 0.2 * Vs[:, 1] + 1.0, atol=1e-12)
    assert len(Fs) == 16 * len(F)


def test_regular_eight_point_stencil_reproduces_a_quadratic():
    # f = x^2 on a regular grid: the 8-point butterfly is exact for cubics in the regular case
    V, F = _regular_grid()
    V[:, 2] = V[:, 0] ** 2
    Vs, _ = butterfly_subdivide(V, F, 1)
    from algorithms.subdivision.topology import half_flaps

    hf = half_flaps(F, len(V))
    deg = hf.degree
    inner = np.ones(len(V), bool)
    inner[hf.ijkl[hf.boundary][:, :2].ravel()] = False
    reg = inner[hf.E[:, 0]] & inner[hf.E[:, 1]] & (deg[hf.E[:, 0]] == 6) & (deg[hf.E[:, 1]] == 6)
    assert reg.sum() > 20
    odd = Vs[len(V):][reg]
    np.testing.assert_allclose(odd[:, 2], odd[:, 0] ** 2, atol=1e-12)


def test_butterfly_on_sphere_beats_midpoint_and_handles_boundary():
    V, F = icosphere(1)
    r = lambda X: np.abs(np.linalg.norm(X, axis=1) - 1).max()  # noqa: E731
    Vb, _ = butterfly_subdivide(V, F, 2)
    Vm, _ = subdivide_baseline(V, F, 2, "midpoint")
    assert r(Vb) < 0.5 * r(Vm)
    m = read_mesh("tests/data/hand_lowres.obj")
    Vh, Fh = butterfly_subdivide(m.V, m.F, 1)
    assert np.isfinite(Vh).all() and len(Fh) == 4 * len(m.F)


def test_butterfly_boundary_four_point_rule():
    V, F = grid(4, 4)
    V = np.asarray(V, float)
    V[:, 2] = V[:, 0] ** 3  # the 4-point rule reproduces cubics along a straight boundary
    Vs, _ = butterfly_subdivide(V, F, 1)
    from algorithms.subdivision.topology import half_flaps

    hf = half_flaps(F, len(V))
    be = np.unique(hf.edge[hf.boundary])
    # boundary edges along y = const whose both neighbours along the boundary exist
    ys = V[hf.E[be, 0], 1] == V[hf.E[be, 1], 1]
    P = Vs[len(V) + be[ys]]
    inner_x = (P[:, 0] > V[:, 0].min() + 1e-9 + (V[:, 0].max() - V[:, 0].min()) / 3 - 1e-6) & \
        (P[:, 0] < V[:, 0].max() - (V[:, 0].max() - V[:, 0].min()) / 3 + 1e-6)
    assert inner_x.any()
    np.testing.assert_allclose(P[inner_x, 2], P[inner_x, 0] ** 3, atol=1e-12)


def test_non_manifold_input_is_refused():
    V = np.random.default_rng(0).random((5, 3))
    F = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])
    with pytest.raises(InvalidMeshError):
        butterfly_subdivide(V, F, 1)


def _moebius(n=24, w=0.3):
    """A triangulated Moebius strip: one-sided, so no orientation makes every edge pair up."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = []
    for s in (-w, w):
        V.append(np.stack([(1 + s * np.cos(t / 2)) * np.cos(t),
                           (1 + s * np.cos(t / 2)) * np.sin(t), s * np.sin(t / 2)], axis=1))
    V = np.concatenate(V)
    F = []
    for i in range(n):
        j = (i + 1) % n
        a, b = i, n + i
        c, d = (j, n + j) if j else (n + j, j)  # the half twist joins the ends swapped
        F += [[a, c, b], [b, c, d]]
    return V, np.array(F)


def test_advice_to_clean_only_when_clean_fixes_it_else_loop(monkeypatch):
    """Issue 41 item 1: a mesh Clean cannot fix was told "'Clean' can fix both", and Clean then
    said "Nothing could be fixed automatically": circular advice. Now the message advises Clean
    only when Clean fixes it, and otherwise names Loop, which works on it. A one-sided strip is
    now fixed by Clean (it cuts the seam open, issue 38), so it is told to clean."""
    from algorithms.mesh.subdivision import loop_subdivide
    from algorithms.mesh.validate import clean_mesh
    from algorithms.subdivision import data

    V, F = _moebius()
    with pytest.raises(InvalidMeshError) as e:
        butterfly_subdivide(V, F, 1)
    assert "'Clean' fixes this." in str(e.value), str(e.value)
    c = clean_mesh(V, F)
    assert c.actions[0].startswith("Cut the one-sided surface open")
    Vb, Fb = butterfly_subdivide(c.V, c.F, 1)         # the advice works
    assert len(Fb) == 4 * len(F) and np.isfinite(Vb).all()
    # where Clean would not fix it, the message says so and names Loop, which works
    monkeypatch.setattr(data, "_clean_fixes_edges", lambda V, F: False)
    with pytest.raises(InvalidMeshError) as e:
        butterfly_subdivide(V, F, 1)
    msg = str(e.value)
    assert "'Clean' cannot fix it" in msg and "--method loop" in msg, msg
    Vl, Fl = loop_subdivide(V, F, 1)
    assert len(Fl) == 4 * len(F) and np.isfinite(Vl).all()
    monkeypatch.undo()
    # a closed mesh with one triangle flipped: Clean fixes it, and the message says so
    from algorithms.mesh.samples import sample_path
    from algorithms.mesh import read_mesh

    m = read_mesh(sample_path("blob"))
    F2 = m.F.copy()
    F2[0] = F2[0, ::-1]
    with pytest.raises(InvalidMeshError) as e:
        data.check_manifold(m.V, F2, "Neural subdivision")
    assert "'Clean' fixes this." in str(e.value)
    c = clean_mesh(m.V, F2)
    data.check_manifold(c.V, c.F, "Neural subdivision")  # no error after Clean
