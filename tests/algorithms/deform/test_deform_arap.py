from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import igl
from algorithms.deform.arap import (
    ArapParams,
    ArapSystem,
    arap,
    arap_iter,
    procrustes_rotations,
    relative_displacement,
    spokes_and_rims_cells,
)
from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import grid, icosphere, read_mesh
from algorithms.mesh.operators import cotangent_laplacian
from tests.conftest import shared_mesh


def bumpy_sphere(sub=2, seed=0):
    V, F = icosphere(sub)
    rng = np.random.default_rng(seed)
    return V * (1 + 0.1 * rng.standard_normal((len(V), 1))), F


def random_rotations(n, seed=0):
    return Rotation.random(n, random_state=seed).as_matrix()


def loop_energy(V, F, U, R):
    """Independent spokes-and-rims ARAP energy: Python loops over faces, edges and cells."""
    E = 0.0
    for f in F:
        for k in range(3):
            i, j, o = f[(k + 1) % 3], f[(k + 2) % 3], f[k]
            a, b = V[i] - V[o], V[j] - V[o]
            cot = a @ b / np.linalg.norm(np.cross(a, b))
            w = cot
            d, dt = V[j] - V[i], U[j] - U[i]
            for c in f:  # the edge lies in the cell of every corner of the face
                E += 0.5 * w * np.sum((R[c] @ d - dt) ** 2)
    return E


# ------------------------------------------------------------------------------ Procrustes
def test_procrustes_returns_proper_rotations_that_beat_brute_force():
    rng = np.random.default_rng(1)
    S = rng.standard_normal((300, 3, 3))
    S[:50] = -S[:50] @ np.diag([1, 1, 1])  # many with negative determinant
    S[50:60, :, 2] = 0  # rank deficient
    R = procrustes_rotations(S)
    assert R.shape == (300, 3, 3)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    best = np.einsum("nij,nji->n", R, S)  # tr(R S)
    candidates = random_rotations(20000, seed=2)
    for i in range(0, 300, 30):
        brute = np.einsum("kij,ji->k", candidates, S[i]).max()
        assert best[i] >= brute - 1e-12
    # local optimality: no small rotation improves tr(R S)
    for i in range(0, 300, 7):
        for Dk in random_rotations(50, seed=i):
            small = Rotation.from_rotvec(0.01 * Rotation.from_matrix(Dk).as_rotvec()).as_matrix()
            assert np.trace(small @ R[i] @ S[i]) <= best[i] + 1e-12


def test_procrustes_recovers_known_rotation():
    R0 = random_rotations(100, seed=3)
    C = np.random.default_rng(4).standard_normal((100, 3, 5))
    # S = sum w d d~^T with d~ = R0 d  ->  S = D D^T R0^T
    S = C @ C.transpose(0, 2, 1) @ R0.transpose(0, 2, 1)
    np.testing.assert_allclose(procrustes_rotations(S), R0, atol=1e-10)


# ------------------------------------------------------------------------------ system
def test_spokes_and_rims_cells_shape_and_weights():
    V, F = bumpy_sphere(1)
    cell, tail, head, w = spokes_and_rims_cells(V, F)
    assert cell.shape == tail.shape == head.shape == w.shape == (9 * len(F),)
    # summing each face-edge weight once (not per cell) gives the cotangent Laplacian
    L = np.zeros((len(V), len(V)))
    sel = np.arange(0, 9 * len(F), 3)
    np.add.at(L, (tail[sel], head[sel]), w[sel])
    np.add.at(L, (head[sel], tail[sel]), w[sel])
    np.testing.assert_allclose(L, 2 * cotangent_laplacian(V, F).toarray() * (1 - np.eye(len(V))),
                               atol=1e-12)


def test_global_matrix_is_six_times_the_cotangent_laplacian():
    V, F = bumpy_sphere(2)
    system = ArapSystem(V, F, fixed=[0])
    np.testing.assert_allclose(system.Q.toarray(), -6 * cotangent_laplacian(V, F).toarray(),
                               atol=1e-12)


def test_energy_matches_an_independent_loop():
    V, F = bumpy_sphere(1, seed=5)
    rng = np.random.default_rng(6)
    U = V + 0.1 * rng.standard_normal(V.shape)
    R = random_rotations(len(V), seed=7)
    system = ArapSystem(V, F, fixed=[0])
    assert system.energy(U, R) == pytest.approx(loop_energy(V, F, U, R), rel=1e-12)
    assert system.energy(U, R, exact=False) == pytest.approx(loop_energy(V, F, U, R), rel=1e-9)
    # and the energy is the quadratic form the operators encode
    quad = (0.5 * np.einsum("nij,njk,nik->", R, system.rest_covariance, R)
            - np.einsum("nij,nji->", R, system.covariances(U))
            + 0.5 * np.sum(U * (system.Q @ U)))
    assert quad == pytest.approx(loop_energy(V, F, U, R), rel=1e-9)
    # rhs(R) is the gradient's linear part: dE/dU = Q U - rhs(R)
    eps = 1e-6
    i, d = 5, 1
    Up, Um = U.copy(), U.copy()
    Up[i, d] += eps
    Um[i, d] -= eps
    fd = (system.energy(Up, R) - system.energy(Um, R)) / (2 * eps)
    grad = (system.Q @ U - system.rhs(R))[i, d]
    assert fd == pytest.approx(grad, rel=1e-6, abs=1e-9)


@pytest.mark.parametrize("case", ["pinned", "fixed_and_planes", "translated_parts", "superlu"])
def test_energy_after_solve_is_the_energy(case):
    """energy_after_solve (one dot product after a global step) is the energy: against the
    exact per-edge sum, with fixed vertices, per-coordinate constraints, an unreferenced vertex,
    a mesh in two parts each moved by a translation after the solve, and both direct solvers."""
    V, F = bumpy_sphere(2, seed=11)
    rng = np.random.default_rng(12)
    kw = {}
    if case == "fixed_and_planes":
        V = np.vstack([V, [[5.0, 5.0, 5.0]]])  # used by no triangle: constrained
        kw = dict(fixed=[0, 7, 9], coord_constraints=([3, 4, 4], [0, 1, 2]))
    elif case == "translated_parts":
        V = np.vstack([V, V + [3.0, 0.0, 0.0]])
        F = np.vstack([F, F + len(V) // 2])
        kw = dict(fixed=[0, len(V) // 2])
    else:
        kw = dict(fixed=[0])
    if case == "superlu":
        kw["backend"] = "superlu"
    system = ArapSystem(V, F, **kw)
    known = V + 0.05 * rng.standard_normal(V.shape)
    R = random_rotations(len(V), seed=13)
    b = system.rhs(R)
    U = system.solve(b, known)
    if case == "translated_parts":  # the part-by-part recentring of cubic stylization
        half = len(V) // 2
        U[:half] += [0.1, -0.2, 0.3]
        U[half:] += [-0.4, 0.0, 0.2]
    exact = system.energy(U, R)
    assert exact > 1e-3
    fast = system.energy_after_solve(U, R, b, rotations=True)
    assert fast == pytest.approx(exact, rel=1e-10)
    assert fast == pytest.approx(system.energy(U, R, exact=False), rel=1e-10)
    # the identity needs U to solve the system for b: a U that does not gives another number
    scaled = 1.05 * U
    wrong = system.energy_after_solve(scaled, R, b, rotations=True)
    assert abs(wrong - system.energy(scaled, R)) > 1e-4 * system.energy(scaled, R)


def test_energy_after_solve_takes_the_general_path_where_the_identity_fails():
    """Linear maps that are not rotations, soft handles and the multigrid backend: the value
    is energy(exact=False) itself."""
    V, F = bumpy_sphere(2, seed=14)
    rng = np.random.default_rng(15)
    R = 1.3 * random_rotations(len(V), seed=16)  # scaled rotations (ACAP-like)
    system = ArapSystem(V, F, fixed=[0])
    b = system.rhs(R)
    U = system.solve(b, V)
    assert system.energy_after_solve(U, R, b) == system.energy(U, R, exact=False)
    soft = ArapSystem(V, F, fixed=[0], soft_handles=([5, 9], 10.0))
    b = soft.rhs(R / 1.3)
    U = soft.solve(b, V, soft_targets=V[[5, 9]] + 0.1)
    assert soft.energy_after_solve(U, R / 1.3, b, rotations=True) == soft.energy(
        U, R / 1.3, exact=False)
    mg = ArapSystem(V, F, fixed=[0], backend="multigrid")
    b = mg.rhs(R / 1.3)
    U = mg.solve(b, V + 0.01 * rng.standard_normal(V.shape))
    assert mg.energy_after_solve(U, R / 1.3, b, rotations=True) == mg.energy(
        U, R / 1.3, exact=False)


def test_rest_state_is_a_fixed_point():
    V, F = bumpy_sphere(2, seed=8)
    system = ArapSystem(V, F, fixed=[3])
    R = system.rotations(V)
    np.testing.assert_allclose(R, np.broadcast_to(np.eye(3), R.shape), atol=1e-10)
    U = system.solve(system.rhs(R), V)
    np.testing.assert_allclose(U, V, atol=1e-10)
    assert system.energy(V, R) < 1e-20


def test_rotated_mesh_is_a_fixed_point_with_the_rotation():
    V, F = bumpy_sphere(2, seed=9)
    R0 = random_rotations(1, seed=10)[0]
    U = V @ R0.T
    system = ArapSystem(V, F, fixed=[0, 1])
    R = system.rotations(U)
    np.testing.assert_allclose(R, np.broadcast_to(R0, R.shape), atol=1e-10)
    np.testing.assert_allclose(system.solve(system.rhs(R), U), U, atol=1e-10)


def test_extra_procrustes_term_enters_the_covariance():
    V, F = bumpy_sphere(1)
    system = ArapSystem(V, F, fixed=[0])
    extra = np.random.default_rng(11).standard_normal((len(V), 3, 3))
    np.testing.assert_allclose(system.rotations(V, extra),
                               procrustes_rotations(system.covariances(V) + extra))


def test_hard_constraints_hold_and_solution_is_the_constrained_minimizer():
    V, F = bumpy_sphere(2, seed=12)
    n = len(V)
    fixed = np.array([0, 5, 9])
    ci, ca = np.array([20, 21, 22, 5]), np.array([0, 0, 2, 1])
    system = ArapSystem(V, F, fixed=fixed, coord_constraints=(ci, ca))
    assert system.constrained[fixed].all() and system.constrained[ci, ca].all()
    assert system.constrained.sum() == 3 * 3 + 3  # (5, y) already fixed
    known = V + np.random.default_rng(13).standard_normal(V.shape) * 0.2
    R = random_rotations(n, seed=14)
    U = system.solve(system.rhs(R), known)
    assert np.abs(U[system.constrained] - known[system.constrained]).max() <= 1e-10
    # gradient vanishes on the free entries
    grad = system.Q @ U - system.rhs(R)
    assert np.abs(grad[~system.constrained]).max() < 1e-9
    # different coordinates got different factorizations
    assert len(system._groups) == 3


def test_soft_handles_pull_towards_targets():
    V, F = bumpy_sphere(2, seed=15)
    idx = np.array([0, 7])
    tgt = V[idx] + [0.3, 0.0, 0.0]
    diag = ArapSystem(V, F, fixed=[1]).Q.diagonal().mean()
    dist = []
    for k in (1e-2, 1.0, 1e4):
        system = ArapSystem(V, F, fixed=[1], soft_handles=(idx, k * diag))
        U = V.copy()
        for _ in range(5):
            U = system.solve(system.rhs(system.rotations(U)), V, tgt)
        dist.append(np.linalg.norm(U[idx] - tgt, axis=1).max())
        grad = system.Q @ U - system.rhs(system.rotations(U))  # not zero: R changed
        assert np.isfinite(grad).all()
    assert dist[0] > dist[1] > dist[2] and dist[2] < 1e-3


def test_unconstrained_part_is_refused_with_a_message():
    V, F = bumpy_sphere(1)
    with pytest.raises(ParameterError, match="slide freely"):
        ArapSystem(V, F)
    with pytest.raises(ParameterError, match=" in z"):
        ArapSystem(V, F, coord_constraints=([0, 0], [0, 1]))
    # two components, only one held
    V2 = np.vstack([V, V + 3])
    F2 = np.vstack([F, F + len(V)])
    with pytest.raises(ParameterError, match="Part 2"):
        ArapSystem(V2, F2, fixed=[0])


def test_degenerate_and_bad_input_are_refused():
    V, F = grid(3, 3)
    Vd = V.copy()
    Vd[F[0, 1]] = Vd[F[0, 0]]  # collapse a triangle
    with pytest.raises(InvalidMeshError, match="degenerate"):
        ArapSystem(Vd, F, fixed=[0])
    with pytest.raises(InvalidMeshError):
        ArapSystem(V, F[:0], fixed=[0])
    with pytest.raises(ParameterError, match="do not exist"):
        ArapSystem(V, F, fixed=[len(V)])


def test_unreferenced_vertices_stay_where_given():
    V, F = bumpy_sphere(1)
    V = np.vstack([V, [[5.0, 5.0, 5.0]]])
    system = ArapSystem(V, F, fixed=[0])
    assert system.constrained[-1].all()
    U = system.solve(system.rhs(system.rotations(V)), V)
    np.testing.assert_array_equal(U[-1], V[-1])


# ------------------------------------------------------------------------------ arap_iter
def _libigl_arap(V, F, b, bc, iters):
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = iters
    igl.arap_precomputation(V, F, 3, b.astype(np.int32), data)
    U0 = V.copy()
    U0[b] = bc
    return igl.arap_solve(bc, data, U0)


@pytest.mark.parametrize("iters", [1, 10])
def test_matches_libigl_spokes_and_rims(iters):
    # libigl fits rotations in single precision (SSE 3x3 SVD), so agreement is ~1e-5 of the
    # bounding box, not round-off.
    V, F = bumpy_sphere(3, seed=16)
    b = np.array([0, 40, 80, 120, 160, 200])
    bc = V[b].copy()
    bc[0] += [0.4, 0.1, 0.0]
    bc[1] += [-0.2, 0.3, 0.2]
    U = arap(V, F, (b, bc), ArapParams(max_iterations=iters, rel_displacement_tol=0.0))
    Ui = _libigl_arap(V, F, b, bc, iters)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert np.abs(U - Ui).max() < 1e-4 * diag
    assert np.linalg.norm(U - V, axis=1).max() > 0.1 * diag  # it did deform


def test_matches_libigl_on_a_real_mesh():
    m = read_mesh(shared_mesh("spot_lowres.obj"))
    V, F = m.V, m.F
    b = np.array([0, 100, 200, 300, 400])
    bc = V[b].copy()
    bc[0] += [0.3, 0.1, 0.0]
    bc[1] += [-0.2, 0.0, 0.2]
    U = arap(V, F, (b, bc), ArapParams(max_iterations=10, rel_displacement_tol=0.0))
    Ui = _libigl_arap(V, F, b, bc, 10)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert np.abs(U - Ui).max() < 1e-4 * diag


def test_arap_iter_energy_decreases_and_handles_hold():
    V, F = bumpy_sphere(3, seed=17)
    b = np.array([0, 50])
    bc = V[b] + [[0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]]
    steps = list(arap_iter(V, F, (b, bc), ArapParams(max_iterations=30,
                                                     rel_displacement_tol=1e-4),
                           fixed=[100]))
    E = [s.metrics["energy"] for s in steps]
    assert all(e1 <= e0 * (1 + 1e-12) for e0, e1 in zip(E, E[1:]))
    U = steps[-1].V
    assert np.abs(U[b] - bc).max() <= 1e-10
    assert np.abs(U[100] - V[100]).max() <= 1e-10
    assert steps[-1].metrics["displacement"] < 1e-4 or len(steps) == 30
    assert [s.iteration for s in steps] == list(range(1, len(steps) + 1))


def test_arap_iter_soft_mode():
    V, F = bumpy_sphere(2, seed=18)
    b = np.array([0, 30])
    bc = V[b] + [[0.3, 0.0, 0.0], [-0.3, 0.0, 0.0]]
    hard = arap(V, F, (b, bc), ArapParams(max_iterations=20, rel_displacement_tol=0.0))
    soft = arap(V, F, (b, bc), ArapParams(max_iterations=20, rel_displacement_tol=0.0,
                                          handle_mode="soft", soft_weight=1e6))
    assert np.abs(soft - hard).max() < 1e-3
    loose = arap(V, F, (b, bc), ArapParams(max_iterations=20, handle_mode="soft",
                                           soft_weight=1e-2))
    assert np.linalg.norm(loose[b] - bc, axis=1).max() > 0.05


def test_relative_displacement():
    V = np.zeros((3, 3))
    V[1, 0] = 1.0
    U1 = V + [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]]
    U2 = V + [[0.0, 0.0, 0.0], [0.6, 0.0, 0.0], [0.0, 0.0, 0.0]]
    assert relative_displacement(U2, U1, V) == pytest.approx(0.1 / 0.6)
    assert relative_displacement(V, V, V) == 0.0
    assert relative_displacement(V + 1e-17, V, V) < 1e-6  # round-off of a shape that stays


def test_multigrid_global_step_matches_the_direct_solve():
    """backend="multigrid": same constrained minimizer as the factorization (to its tolerance),
    per-coordinate constraints included, and warm starts make later solves cheaper."""
    V, F = bumpy_sphere(4, seed=3)  # 2562 vertices: two multigrid levels
    fixed = np.array([0, 5, 9])
    ci, ca = np.array([20, 21, 22]), np.array([0, 0, 2])
    direct = ArapSystem(V, F, fixed=fixed, coord_constraints=(ci, ca))
    mg = ArapSystem(V, F, fixed=fixed, coord_constraints=(ci, ca), backend="multigrid",
                    multigrid_rtol=1e-10)
    assert mg.backend == "multigrid" and mg.multigrid.n_levels >= 2
    known = V + 0.05 * np.random.default_rng(4).standard_normal(V.shape)
    R = random_rotations(len(V), seed=5)
    Ud = direct.solve(direct.rhs(R), known)
    Um = mg.solve(mg.rhs(R), known)
    assert np.abs(Um[mg.constrained] - known[mg.constrained]).max() <= 1e-12
    assert np.abs(Um - Ud).max() < 1e-7 * np.abs(Ud).max()
    # a nearby right-hand side: the warm-started solve needs fewer cycles
    R2 = random_rotations(len(V), seed=5) @ Rotation.from_rotvec([0, 0, 0.01]).as_matrix()
    first = [g[2].cycles[-1] for g in mg._groups]
    mg.solve(mg.rhs(R2), known)
    again = [g[2].cycles[-1] for g in mg._groups]
    assert sum(again) < sum(first)


@pytest.mark.parametrize("cells", ["spokes_and_rims", "faces"])
def test_covariance_operator_from_summed_blocks_equals_the_term_by_term_assembly(cells):
    """K is assembled from its 3x1 blocks summed per (cell, vertex), Q from the weights summed
    per edge, and the per-term arrays are not kept (issue 37: 6.0 -> 2.4 GB at 1.3M
    triangles); the matrices must equal the plain assembly from the terms, and the covariances
    of the compiled blocks K @ U."""
    import scipy.sparse as sp

    from algorithms.deform.arap import face_cells

    m = read_mesh(shared_mesh("bob.obj"))
    V, F = m.V, m.F
    A = ArapSystem(V, F, cells=cells, fixed=[0])
    cell, tail, head, w = (spokes_and_rims_cells(V, F) if cells == "spokes_and_rims"
                           else face_cells(V, F))
    d = V[head] - V[tail]
    wd = w[:, None] * d
    rows = 3 * cell[:, None] + np.arange(3)[None, :]
    K = sp.csr_matrix((np.concatenate([wd.ravel(), -wd.ravel()]),
                       (np.concatenate([rows.ravel(), rows.ravel()]),
                        np.concatenate([np.repeat(head, 3), np.repeat(tail, 3)]))),
                      shape=(3 * A.n_cells, len(V)))
    Q = sp.csc_matrix((np.concatenate([w, w, -w, -w]),
                       (np.concatenate([tail, head, tail, head]),
                        np.concatenate([tail, head, head, tail]))), shape=(len(V), len(V)))
    assert abs(A.K - K).max() < 1e-13 and abs(A.Q - Q).max() < 1e-12
    assert A.K.nnz == K.nnz
    U = V + 0.01 * np.random.default_rng(0).standard_normal(V.shape)
    np.testing.assert_allclose(A.covariances(U), (K @ U).reshape(-1, 3, 3), atol=1e-12)
    R = procrustes_rotations(A.covariances(U))
    assert np.isclose(A.energy(U, R), A.energy(U, R, exact=False), rtol=1e-9)
    assert not hasattr(A, "_cell") and not hasattr(A, "_rest_edges")


def test_setting_up_holds_no_per_term_arrays():
    """The spokes-and-rims set-up sums per triangle into the adjacency pattern instead of
    building the 9 m per-term arrays and sorting 18 m keys (issue 37: the finished progressive
    path's peak at 1.29M triangles 2.75 -> 1.83 GB). Measured with tracemalloc (NumPy's
    allocations; CHOLMOD's are not traced) on bob Loop x1 (42,752 triangles): 492 bytes per
    triangle at the peak, against 1,426 with the term arrays."""
    import tracemalloc

    from algorithms.mesh import loop_subdivide

    m = read_mesh(shared_mesh("bob.obj"))
    V, F = loop_subdivide(m.V, m.F, 1)
    tracemalloc.start()
    try:
        A = ArapSystem(V, F, fixed=[0])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak / len(F) < 700, peak / len(F)
    assert A.Q.has_sorted_indices and abs(A.Q - A.Q.T).max() == 0.0
