"""The compiled kernels (algorithms/deform/kernels.py) against the NumPy code they replace."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

from algorithms.deform import arap
from algorithms.deform.arap import (
    ArapSystem,
    procrustes_rotations,
    procrustes_rotations_numpy,
    relative_displacement,
    set_compiled_kernels,
)
from algorithms.deform.cubic import (
    AdmmState,
    CubicParams,
    CubicStylizer,
    admm_local_step,
    cubic_stylization_iter,
)
from algorithms.mesh import icosphere, read_mesh
from tests.conftest import shared_mesh

kernels = pytest.importorskip("algorithms.deform.kernels")


@pytest.fixture
def numpy_path():
    """A context switch: ``with numpy_path(): ...`` runs with the compiled kernels off."""
    from contextlib import contextmanager

    @contextmanager
    def off():
        previous = set_compiled_kernels(False)
        try:
            yield
        finally:
            set_compiled_kernels(previous)

    if arap.compiled_kernels() is None:
        pytest.skip("compiled kernels switched off (STYLIZE3D_NUMBA=0)")
    return off


def kernel_procrustes(S):
    S = np.ascontiguousarray(S, dtype=np.float64)
    R = np.empty_like(S)
    kernels.procrustes_batch(S, R)
    return R


def assert_rotations(R, atol=1e-12):
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape),
                               atol=atol)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=atol)


def objective(R, S):
    return np.einsum("nij,nji->n", R, S)  # tr(R S)


def unique_maximizer(S, margin=1e-3):
    """Where the det-fixed Procrustes maximizer is unique with some margin (well-conditioned)."""
    sig = np.linalg.svd(S, compute_uv=False)
    neg = np.linalg.det(S) < 0
    ok = sig[:, 1] > margin * sig[:, 0]
    ok &= ~neg | (sig[:, 1] - sig[:, 2] > margin * sig[:, 0])
    return ok


# ------------------------------------------------------------------------------ Procrustes
def test_procrustes_kernel_matches_numpy_svd_on_random_matrices():
    rng = np.random.default_rng(0)
    S = rng.standard_normal((5000, 3, 3))
    S[:1000] *= rng.uniform(1e-6, 1e6, (1000, 1, 1))  # scales
    S[1000:2000] = -S[1000:2000]  # det < 0 (reflections) and > 0 alike
    Q = Rotation.random(1000, random_state=1).as_matrix()  # near rotations, SPD parts
    S[2000:3000] = (Q @ np.diag([3.0, 2.0, 1.0])) @ Q.transpose(0, 2, 1) @ Rotation.random(
        1000, random_state=2).as_matrix()
    R = kernel_procrustes(S)
    R_np = procrustes_rotations_numpy(S)
    assert_rotations(R)
    ok = unique_maximizer(S)
    assert ok.sum() > 4500
    assert np.abs(R[ok] - R_np[ok]).max() < 1e-9
    # never worse than NumPy's maximizer, also where the conditioning is poor
    scale = np.abs(S).max(axis=(1, 2))
    assert np.all(objective(R, S) >= objective(R_np, S) - 1e-12 * scale)


def test_procrustes_kernel_on_degenerate_matrices():
    rng = np.random.default_rng(3)
    a, b, c = rng.standard_normal((3, 3))
    Q = Rotation.random(random_state=4).as_matrix()
    cases = {
        "zero": np.zeros((3, 3)),
        "rank1": np.outer(a, b),
        "rank1_sym": np.outer(a, a),
        "rank1_tiny": 1e-200 * np.outer(a, b),
        "rank2": np.outer(a, b) + np.outer(c, a),
        "rank2_diag": np.diag([2.0, 1.0, 0.0]),
        "rank2_plane": Q @ np.diag([1.0, 0.5, 0.0]) @ Q.T,  # flat ARAP cell
        "rank2_dependent_columns": np.column_stack([a, b, a - 2 * b]),
        "reflection": np.diag([1.0, 1.0, -1.0]),
        "reflection_rot": Q @ np.diag([3.0, 2.0, -1.0]),
        "minus_identity": -np.eye(3),
        "identity": np.eye(3),
        "huge": 1e250 * rng.standard_normal((3, 3)),
        "tiny": 1e-250 * rng.standard_normal((3, 3)),
        "subnormal_entries": np.diag([1.0, 1e-310, 5e-324]),
    }
    S = np.array(list(cases.values()))
    R = kernel_procrustes(S)
    R_np = procrustes_rotations_numpy(S)
    assert np.isfinite(R).all()
    assert_rotations(R)
    names = list(cases)
    np.testing.assert_array_equal(R[names.index("zero")], np.eye(3))  # like NumPy
    np.testing.assert_allclose(R[names.index("identity")], np.eye(3), atol=1e-15)
    scale = np.maximum(np.abs(S).max(axis=(1, 2)), 1e-300)
    # every result maximizes tr(R S): as high as NumPy's (rank <= 1 and -I have many maximizers)
    np.testing.assert_allclose(objective(R, S) / scale, objective(R_np, S) / scale, atol=1e-12)
    # where the maximizer is unique, it is NumPy's
    for name in ("rank2", "rank2_diag", "rank2_plane", "rank2_dependent_columns", "reflection",
                 "reflection_rot", "identity", "huge", "tiny"):
        i = names.index(name)
        np.testing.assert_allclose(R[i], R_np[i], atol=1e-9, err_msg=name)
    # the reflection's maximizer flips the smallest singular direction
    np.testing.assert_allclose(R[names.index("reflection")], np.eye(3), atol=1e-15)
    # no silent rotation out of a NaN or an infinity
    bad = np.stack([np.eye(3)] * 3)
    bad[0, 1, 2] = np.nan
    bad[1, 0, 0] = np.inf
    Rb = kernel_procrustes(bad)
    assert np.isnan(Rb[:2]).all()
    np.testing.assert_array_equal(Rb[2], np.eye(3))


@settings(max_examples=300, deadline=None)
@given(hnp.arrays(np.float64, (3, 3), elements=st.one_of(
    st.sampled_from([0.0, 1.0, -1.0, 0.5]),
    st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False))))
def test_procrustes_kernel_property(S):
    """Any finite S: a rotation that reaches NumPy's value of tr(R S) (ties, zeros, repeats)."""
    R = kernel_procrustes(S[None])
    assert_rotations(R)
    R_np = procrustes_rotations_numpy(S[None])
    scale = max(float(np.abs(S).max()), 1e-300)
    assert objective(R, S[None])[0] >= objective(R_np, S[None])[0] - 1e-12 * scale
    if unique_maximizer(S[None])[0]:
        np.testing.assert_allclose(R[0], R_np[0], atol=1e-9)


def test_procrustes_kernel_is_scale_invariant_and_independent_of_the_batch():
    rng = np.random.default_rng(5)
    S = rng.standard_normal((700, 3, 3))
    R = kernel_procrustes(S)
    # powers of two are exact: the same bits
    np.testing.assert_array_equal(kernel_procrustes(S * 2.0 ** 40), R)
    np.testing.assert_array_equal(kernel_procrustes(S * 2.0 ** -60), R)
    # a matrix gets the same bits whatever else is in its block, and in any order
    perm = rng.permutation(700)
    np.testing.assert_array_equal(kernel_procrustes(S[perm]), R[perm])
    for i in (0, 127, 128, 699):
        np.testing.assert_array_equal(kernel_procrustes(S[i:i + 1])[0], R[i])


def test_procrustes_rotations_dispatches_to_the_kernel(numpy_path):
    rng = np.random.default_rng(6)
    S = rng.standard_normal((50, 3, 3))
    np.testing.assert_array_equal(procrustes_rotations(S), kernel_procrustes(S))
    with numpy_path():
        assert arap.compiled_kernels() is None
        np.testing.assert_array_equal(procrustes_rotations(S), procrustes_rotations_numpy(S))
    assert arap.compiled_kernels() is not None
    assert procrustes_rotations(np.zeros((0, 3, 3))).shape == (0, 3, 3)
    with pytest.raises(ValueError):
        procrustes_rotations(np.zeros((4, 3)))


# ------------------------------------------------------------------------------ ARAP operators
def test_operators_match_the_sparse_products(numpy_path):
    V, F = icosphere(2)
    rng = np.random.default_rng(7)
    system = ArapSystem(V, F, fixed=[0])
    U = V + 0.05 * rng.standard_normal(V.shape)
    R = Rotation.random(len(V), random_state=8).as_matrix()
    S = system.covariances(U)
    b = system.rhs(R)
    e = system.energy(U, R, exact=False)
    d = relative_displacement(U, V + 0.01, V)
    with numpy_path():
        S_np = system.covariances(U)
        b_np = system.rhs(R)
        e_np = system.energy(U, R, exact=False)
        d_np = relative_displacement(U, V + 0.01, V)
    np.testing.assert_allclose(S, S_np, rtol=0, atol=1e-14 * np.abs(S_np).max())
    np.testing.assert_allclose(b, b_np, rtol=0, atol=1e-14 * np.abs(b_np).max())
    assert e == pytest.approx(e_np, rel=1e-12)
    assert e == pytest.approx(system.energy(U, R), rel=1e-9)
    assert system.energy(U, R, exact=False, covariances=S) == e
    assert d == pytest.approx(d_np, rel=1e-14)
    assert relative_displacement(V, V, V) == 0.0
    bad = U.copy()
    bad[3, 1] = np.nan  # a NaN is not lost (both paths answer inf: the run does not stop)
    assert relative_displacement(bad, V, V) == np.inf
    with numpy_path():
        assert relative_displacement(bad, V, V) == np.inf


@pytest.mark.parametrize("frames", [False, True])
def test_cube_after_solve_is_the_separate_kernels_bit_for_bit(frames):
    """The fused pass after a global step (covariances, L1 term, move maxima, output) gives the
    numbers of the separate kernels exactly, with and without local frames; a NaN reaches the
    move (the run then never stops on it) without changing the other outputs."""
    V, F = icosphere(4)  # 2,562 vertices: several chunks, so threads when there are two
    rng = np.random.default_rng(21)
    system = ArapSystem(V, F, fixed=[0])
    n = len(V)
    U = V + 0.02 * rng.standard_normal(V.shape)
    U_old = V + 0.01 * rng.standard_normal(V.shape)
    R = Rotation.random(n, random_state=22).as_matrix()
    normals = V / np.linalg.norm(V, axis=1, keepdims=True)
    lam_a = 0.2 * rng.random(n)
    diag = np.array([1.0, 0.5, 2.0])
    Q = Rotation.random(n, random_state=23).as_matrix() if frames else None
    center, scale = np.array([0.3, -1.0, 2.0]), 1.7
    S, V_out, e_l1, step, total, bbox = kernels.cube_after_solve(
        *system._k_blocks(), U, R, normals, Q, diag, lam_a, U_old, V, scale, center)
    np.testing.assert_array_equal(S, system.covariances(U))
    np.testing.assert_array_equal(V_out, U * scale + center)
    assert e_l1 == kernels.cube_l1_energy(R, normals, Q, diag, lam_a)
    assert (step, total, bbox) == kernels.displacement_maxima(U, U_old, V)
    assert arap.displacement_ratio(step, total, bbox) == relative_displacement(U, U_old, V)
    bad = U.copy()
    bad[5, 2] = np.nan
    out = kernels.cube_after_solve(*system._k_blocks(), bad, R, normals, Q, diag, lam_a, U_old,
                                   V, scale, center)
    assert np.isnan(out[3]) and arap.displacement_ratio(*out[3:]) == np.inf
    assert out[2] == e_l1


# ------------------------------------------------------------------------------ cubic local step
def spot_local_problem(lam=0.2):
    m = read_mesh(shared_mesh("spot_lowres.obj"))
    st = CubicStylizer(m.V, m.F)
    U = st.V_normalized + 0.002 * np.random.default_rng(9).standard_normal(m.V.shape)
    return st, st.system.covariances(U), lam * st.areas


@pytest.mark.parametrize("case", ["cube", "per_axis", "masked", "warm", "frames",
                                  "frames_warm"])
def test_admm_kernel_matches_the_numpy_loop(case, numpy_path):
    st, S, lam_a = spot_local_problem()
    p = CubicParams(lam=0.2)
    normals = st.normals.copy()
    frames = None
    if case.startswith("frames"):  # a random local frame per vertex
        frames = Rotation.random(st.n, random_state=12).as_matrix()
        if case == "frames_warm":
            p = CubicParams(lam=0.2, per_axis=True, axis_factor_x=0.5, axis_factor_z=3.0)
    if case == "per_axis":
        p = CubicParams(lam=0.2, per_axis=True, axis_factor_x=0.0, axis_factor_y=2.0)
    if case == "masked":  # lam = 0 and zero normals take the plain ARAP rotation
        lam_a = lam_a.copy()
        lam_a[::3] = 0.0
        normals[1::7] = 0.0
    prox = st.style_prox(p)
    assert prox.diagonal is not None
    state = AdmmState.initial(st.n, p.rho0)
    if case in ("warm", "frames_warm"):  # a warm state with varied rho
        rng = np.random.default_rng(10)
        state = AdmmState(0.3 * rng.standard_normal((st.n, 3)), 0.01 * rng.standard_normal(
            (st.n, 3)), p.rho0 * 2.0 ** rng.integers(-3, 8, st.n))
    s_np = AdmmState(state.z.copy(), state.u.copy(), state.rho.copy())
    R, it = admm_local_step(S, normals, lam_a, prox, state, p, frames)
    with numpy_path():
        R_np, it_np = admm_local_step(S, normals, lam_a, prox, s_np, p, frames)
    np.testing.assert_array_equal(it, it_np)
    assert it.max() > 1
    np.testing.assert_allclose(R, R_np, rtol=0, atol=1e-9)
    np.testing.assert_allclose(state.z, s_np.z, rtol=0, atol=1e-9)
    np.testing.assert_allclose(state.u, s_np.u, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(state.rho, s_np.rho)
    assert_rotations(R)
    if case == "masked":
        plain = (lam_a == 0) | ~np.abs(normals).any(axis=1)
        assert not it[plain].any() and it[~plain].all()
        np.testing.assert_array_equal(R[plain], kernel_procrustes(S[plain]))


def test_admm_kernel_with_frames_lowers_the_local_objective():
    """With frames the kernel minimizes tr(-R S) + lam a ||Q^T R n||_1, not the world-frame one."""
    st, S, lam_a = spot_local_problem(lam=0.5)
    p = CubicParams(lam=0.5)
    frames = Rotation.random(st.n, random_state=13).as_matrix()
    R, it = admm_local_step(S, st.normals, lam_a, st.style_prox(p), AdmmState.initial(st.n,
                                                                                     p.rho0),
                            p, frames)
    R0 = kernel_procrustes(S)
    Rw, _ = admm_local_step(S, st.normals, lam_a, st.style_prox(p),
                            AdmmState.initial(st.n, p.rho0), p)

    def local(Rs, Q):
        Rn = np.einsum("nij,nj->ni", Rs, st.normals)
        if Q is not None:
            Rn = np.einsum("nji,nj->ni", Q, Rn)
        return -np.einsum("nij,nji->n", Rs, S) + lam_a * np.abs(Rn).sum(axis=1)

    assert_rotations(R)
    assert local(R, frames).sum() < local(R0, frames).sum() - 1e-3
    assert local(R, frames).sum() < local(Rw, frames).sum() - 1e-3
    assert local(Rw, None).sum() < local(R, None).sum() - 1e-3
    # the energy helper: Q^T R n
    out = np.empty((st.n, 3))
    kernels.frame_normals(R, st.normals, frames, out)
    np.testing.assert_allclose(out, np.einsum("nji,nj->ni", frames,
                                              np.einsum("nij,nj->ni", R, st.normals)),
                               rtol=0, atol=1e-15)


def test_polyhedral_style_keeps_the_numpy_prox(numpy_path):
    st, S, lam_a = spot_local_problem()
    p = CubicParams(lam=0.2, style="octahedron")
    prox = st.style_prox(p)
    assert prox.diagonal is None
    a = AdmmState.initial(st.n, p.rho0)
    b = AdmmState.initial(st.n, p.rho0)
    R, it = admm_local_step(S, st.normals, lam_a, prox, a, p)
    with numpy_path():
        R_np, it_np = admm_local_step(S, st.normals, lam_a, prox, b, p)
    np.testing.assert_array_equal(it, it_np)
    np.testing.assert_allclose(R, R_np, rtol=0, atol=1e-9)


def test_full_run_on_spot_matches_the_numpy_path(numpy_path):
    """Kernel and NumPy paths: same iteration count, same vertices while their steps agree.

    The run itself is sensitive to round-off: the ADMM stops and the rho adaptation compare
    residuals that are at round-off level once a vertex has converged, so a difference of
    1e-15 decides some comparisons differently after ~15 iterations, and the results then
    differ by ~1e-5 (the NumPy path alone moves as much when the input is scaled by 1 + 1e-15).
    Vertices are therefore compared at 1e-8 over the first 20 steps, or up to the first step
    whose inner ADMM iteration counts differ if that comes sooner (past step 20 the round-off
    has grown to ~1e-8 even while the counts agree: how long they agree depends on the order
    of sums in the set-up), and the final shapes at a tolerance of the size of that round-off
    sensitivity.
    """
    m = read_mesh(shared_mesh("spot_lowres.obj"))
    ours = list(cubic_stylization_iter(m.V, m.F, CubicParams()))
    with numpy_path():
        ref = list(cubic_stylization_iter(m.V, m.F, CubicParams()))
    assert len(ours) == len(ref)
    same = 0
    for a, b in zip(ours[:20], ref[:20]):
        if (a.metrics["admm_iterations"] != b.metrics["admm_iterations"]
                or a.metrics["admm_iterations_max"] != b.metrics["admm_iterations_max"]):
            break
        np.testing.assert_allclose(a.V, b.V, rtol=0, atol=1e-8)
        same += 1
    assert same >= 15, same
    diag = float(np.linalg.norm(np.ptp(m.V, axis=0)))
    assert np.abs(ours[-1].V - ref[-1].V).max() < 1e-3 * diag
    for k in ("energy", "arap", "l1"):
        assert ours[-1].metrics[k] == pytest.approx(ref[-1].metrics[k], rel=1e-3)


def test_fixed_iteration_runs_agree_to_1e_8(numpy_path):
    """Before the round-off-level decisions diverge (see above), the runs agree tightly."""
    V, F = icosphere(3)
    V = V @ Rotation.random(random_state=11).as_matrix().T
    p = CubicParams(lam=0.5, max_iterations=12, rel_displacement_tol=0.0)
    ours = list(cubic_stylization_iter(V, F, p))
    with numpy_path():
        ref = list(cubic_stylization_iter(V, F, p))
    assert len(ours) == len(ref) == 12
    for a, b in zip(ours, ref):
        np.testing.assert_allclose(a.V, b.V, rtol=0, atol=1e-8)
        assert a.metrics["admm_iterations"] == b.metrics["admm_iterations"]
        assert a.metrics["energy"] == pytest.approx(b.metrics["energy"], rel=1e-9)


def test_procrustes_kernel_subnormal_and_huge_inputs():
    # found by hypothesis: a subnormal S used to overflow the power-of-two pre-scaling (NaN)
    from algorithms.deform.arap import procrustes_rotations, procrustes_rotations_numpy

    rng = np.random.default_rng(7)
    base = rng.standard_normal((4, 3, 3))
    for scale in (5e-324 * 2.0 ** 20, 1e-310, 1e300):
        S = base * scale  # subnormal S keeps only a few bits of base: compare with S itself,
        R = procrustes_rotations(S)  # brought to unit size by an exact power-of-two scaling
        assert np.isfinite(R).all()
        unit = np.ldexp(S, -np.frexp(np.abs(S).max())[1])
        np.testing.assert_allclose(R, procrustes_rotations_numpy(unit), atol=1e-9)
    R = procrustes_rotations(np.full((1, 3, 3), 5e-324))
    assert np.isfinite(R).all() and np.linalg.det(R[0]) == pytest.approx(1.0)
    np.testing.assert_allclose(R[0] @ R[0].T, np.eye(3), atol=1e-12)
