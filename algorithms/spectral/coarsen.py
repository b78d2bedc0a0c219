"""Spectral coarsening of a sparse PSD operator (thesis ch. 7: combinatorial + operator optimization).

Input: a sparse symmetric positive semi-definite ``L`` (n x n; for meshes pass ``-cotmatrix``), a
diagonal mass ``M`` (sparse diagonal or a length-n vector) and a target size ``m``. Output: a
sparse ``L~ = G^T L G`` (m x m, PSD, containing the null space of L), a lumped ``M~ = K M K^T``,
the interpolation ``G`` (n x m, cluster-ring sparsity), the cluster assignment ``K`` and the root
selection ``P`` (both m x n, 0/1).

No mesh is needed here; :mod:`algorithms.spectral.operators` builds (L, M) from meshes.

Optimizer choices (thesis 7.3.2, DESIGN.md §5):

* NADAM with beta1 = beta2 = 0.9 (authors' code), a *fixed* step gamma = 0.02 and a stop after
  ``patience`` = 10 consecutive iterations that do not improve the best energy (the thesis). The
  authors' MATLAB code instead halves the step after a stall, at most twice, and then stops:
  ``lr_decays=2``. (An earlier version halved the step after *every* non-improving iteration
  with no limit; the step fell to 0.0025 within 20 iterations and to 1.6e-4 by the 1000-
  iteration cap: armadillo 14.6k -> 500, k 100 ended at E = 2.1e5, C diag 0.655, mean
  eigenvalue error 0.147, against E = 6.1e4, 0.79 and 0.041 with the fixed step from the same
  K^T start, which stops by itself after 142 iterations.)
* NADAM sees the gradient of E / E0 (E0 the energy of the initial G): the same steps whatever
  the units of L and M, so the 1e-8 in the denominator stays negligible on any mesh scale.
* The initial G (the thesis does not say) is the piecewise-constant K^T of the authors' code,
  projected on the null-space constraint; the best iterate is returned. ``initial_G="smoothed"``
  starts instead from K^T after one damped-Jacobi step, (I - 4/(3 rho) D^-1 L) K^T with rho the
  Gershgorin bound of D^-1 L (smoothed aggregation's prolongator, inside S_G). It starts 18x
  lower on armadillo and ends in a lower minimum of the same energy there (14.6k -> 500, k 100:
  E = 2.4e4, C diag 0.91, mean eigenvalue error 0.030, against 6.3e4, 0.79, 0.041), and it is
  better on most shared meshes at m = 500, k = 100; but at mild coarsening (spot 829 -> 250,
  k 60) it reaches the same energy (2.6e3) with C diag 0.16 instead of 0.79 over the 60
  eigenvectors: the energy only constrains L~ on span(P Phi), and the softer start leaves
  spurious low modes in the other m - k directions. So it is an option, not the default.
* ``k`` eigenvectors (including the constant ones) enter the energy; 0 means round(m / 3) as in
  the authors' code (their demo passes 100 for m = 500).
* The energy counts residuals of eigenvector i in absolute terms, i.e. proportionally to lambda_i;
  the lowest modes therefore weigh little, and the coarse operator tends to be slightly stiff on
  them (e.g. fertility 4.5k -> 500, k 100: +16 % on the first ten eigenvalues, -4 % on the last
  ten). This is the thesis's objective and is kept.
* ARPACK runs from a fixed start vector so that results are reproducible.
* Beyond the thesis (issue 10): after NADAM, ``balance_iterations`` (200) L-BFGS iterations on
  the *eigenvalue-balanced* energy, column i of A and B scaled by (lam_k / lam_i)^(balance/2)
  (balance = 1), see :func:`_balance_stage`; ``balance_iterations=0`` is the thesis alone. Why
  ours lost to QSlim on meshes with boundary was measured hypothesis by hypothesis (m 300,
  k 60; camelhead, hand_lowres, armadillo / fertility with the base cut off, bob sliced open):
  (1) boundary conditions: the fine and every coarse operator are Neumann, and the lowest
  coarse eigenvalues are as stiff on the closed meshes (armadillo: 1.30-1.34 x, wingnut
  1.16-1.37 x) as on the open ones (camelhead 1.21-1.34 x): not boundary-specific.
  (2) the null space: G P 1 = 1 holds to 1e-13; on one part it is not the cause. With several
  parts it was (roots by node count; PyAMG left parts unaggregated): see
  :func:`_seeds_per_component`. (3) clustering near boundaries: Bell's centre (the node
  farthest from the other clusters) puts roots on the mesh boundary 3-4x as often as its share
  of nodes (camelhead 2.0 % against 0.5 %); exact medoids fix that (0.7 %) but not the scores
  (C diag 0.79 -> 0.77, eigenvalue error 0.099 -> 0.111; fertility without its base
  0.887 -> 0.912, 0.047 -> 0.048), so Bell's centre stays. (4) the stopping rule: patience
  30 instead of 10 changes nothing on armadillo and camelhead (the fixed step oscillates),
  +0.03 in C on wingnut and on fertility without its base; the authors' step halving
  (lr_decays 2-4) lowers the eigenvalue error by 10-40 % at up to 10x the iterations, and
  moves C both ways (armadillo 0.75 -> 0.61).
  (5) the initial G: "smoothed" helps at strong coarsening (armadillo cut: C 0.79 -> 0.88) and
  ruins mild coarsening (hand 810 -> 300: 0.60 -> 0.26). The common cause is the energy's
  weighting (the lowest modes weigh like lam_i^2), which the balancing stage addresses.

:func:`coarsen_hierarchy` applies the method recursively (thesis Fig. 7.16). A coarse level has
the cluster three-ring pattern of the level above, so after two levels L~ is nearly dense
(~40 non-zeros per row at level 1, m_2 - 1 at level 2 for m_2 < 100): the thesis names the
sparser patterns a deeper hierarchy would need as future work. Spectral errors compound: each
level is fitted to the previous level's (slightly stiff) low spectrum (spot 829 -> 250 -> 80,
k 30 / 15, thesis optimizer alone: mean error of the first ten eigenvalues 0.074, then 0.213).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.sparse.linalg import eigsh

from ..errors import ParameterError
from ..params import param
from ..optim import nadam_step
from ..compiled import KernelModule

__all__ = ["CoarsenParams", "CoarsenStep", "Clustering", "edge_distances", "kmedoids_clustering",
           "cluster_sparsity", "null_space", "project_constraint", "energy_and_gradient",
           "generalized_eigs", "suggested_coarse_size", "lbfgs_iter", "coarsen_iter", "coarsen",
           "HierarchyLevel", "coarsen_hierarchy"]


@dataclass(frozen=True)
class CoarsenParams:
    """Parameters of spectral coarsening (defaults: thesis ch. 7 / the authors' demo)."""

    m: int = param(500, label="Coarse size", minimum=2, maximum=10_000_000, step=1,
                   tooltip="Number of rows of the coarsened operator (coarse vertices). "
                           "Should exceed twice the eigenvector count.")
    k: int = param(0, label="Eigenvectors", minimum=0, maximum=10_000, step=1,
                   tooltip="How many low-frequency eigenvectors to preserve; 0 means round(m/3) "
                           "as in the authors' demo.")
    p: float = param(0.0, label="Operator length power p", minimum=-4.0, maximum=4.0, step=0.5,
                     advanced=True,
                     tooltip="Units of the operator in powers of length (0 for the cotangent "
                             "Laplacian). Used by the operator-aware edge distance.")
    q: float = param(2.0, label="Mass length power q", minimum=0.5, maximum=4.0, step=0.5,
                     advanced=True,
                     tooltip="Units of the mass matrix in powers of length (2 for surface "
                             "vertex areas, 3 for volumes).")
    max_iterations: int = param(1000, label="Max iterations", minimum=0, maximum=100_000, step=10,
                                tooltip="Upper bound on optimizer iterations.")
    learning_rate: float = param(0.02, label="Learning rate", minimum=1e-6, maximum=1.0,
                                 step=0.005, decimals=4, log_scale=True,
                                 tooltip="NADAM step size (thesis: fixed 0.02).")
    lr_decays: int = param(0, label="Step halvings on stall", minimum=0, maximum=20, step=1,
                           advanced=True,
                           tooltip="When the energy stalls for 'patience' iterations, halve the "
                                   "step size and go on, this many times, before stopping. 0 is "
                                   "the thesis (fixed step, stop at the first stall); the "
                                   "authors' MATLAB code halves up to twice.")
    patience: int = param(10, label="Patience", minimum=1, maximum=1000, step=1,
                          tooltip="Stop after this many consecutive iterations without "
                                  "improving the energy.")
    clustering_iterations: int = param(20, label="Clustering iterations", minimum=1,
                                       maximum=1000, step=1, advanced=True,
                                       tooltip="Lloyd iterations of the graph k-medoids.")
    initial_G: str = param("constant", label="Initial interpolation", advanced=True,
                           choices=("constant", "smoothed"),
                           tooltip="Starting point of the optimizer. 'constant': the "
                                   "piecewise-constant K^T (authors' code). 'smoothed': K^T "
                                   "after one damped-Jacobi step (as in smoothed aggregation); "
                                   "often a lower final energy, but it can leave spurious "
                                   "low-frequency modes when m is not much larger than 2k.")
    seed: int = param(0, label="Random seed", minimum=0, maximum=2**31 - 1, step=1,
                      tooltip="Seed of the random initial cluster roots.")
    balance_iterations: int = param(200, label="Balancing iterations", minimum=0,
                                    maximum=100_000, step=10,
                                    tooltip="After the thesis's optimization, this many L-BFGS "
                                            "iterations on the eigenvalue-balanced energy (each "
                                            "eigenvector's residual divided by its eigenvalue "
                                            "to the power 'balance'/2). It corrects the lowest "
                                            "eigenvalues, which the thesis energy leaves 15-35% "
                                            "too high. 0 = the thesis alone.")
    balance: float = param(1.0, label="Balancing exponent", minimum=0.0, maximum=2.0, step=0.5,
                           advanced=True,
                           tooltip="Weight of eigenvector i in the balancing stage: "
                                   "(lambda_k / lambda_i)^balance. 0 = the thesis energy, 2 = "
                                   "every eigenvalue counted by its relative error.")


@dataclass
class Clustering:
    """Result of the combinatorial stage."""

    labels: np.ndarray   # (n,) cluster of every fine node
    roots: np.ndarray    # (m,) root (fine index) of every cluster
    K: sp.csr_matrix     # (m, n) assignment
    P: sp.csr_matrix     # (m, n) root selection
    seconds: float = 0.0


@dataclass
class CoarsenStep:
    """One optimizer iteration; the last step carries the result."""

    iteration: int
    total: int | None
    energy: float
    metrics: dict[str, float] = field(default_factory=dict)
    message: str = ""
    done: bool = False
    L: sp.csr_matrix | None = None   # L~ (m x m)
    M: sp.csr_matrix | None = None   # M~ (m x m, diagonal)
    G: sp.csr_matrix | None = None   # (n x m)
    K: sp.csr_matrix | None = None
    P: sp.csr_matrix | None = None
    timings: dict[str, float] = field(default_factory=dict)
    #: which stage the step belongs to: "eigenvectors", "clustering", "optimizing",
    #: "balancing" or "comparing" (the progress shown to the user names it)
    stage: str = "optimizing"


# --------------------------------------------------------------------------------------------
# helpers

def _as_mass_vector(M, n: int) -> np.ndarray:
    d = M.diagonal() if sp.issparse(M) else np.asarray(M, dtype=float).reshape(-1)
    if d.shape[0] != n:
        raise ParameterError(f"the mass matrix has {d.shape[0]} entries but the operator has {n} "
                             "rows; pass the mass of the same mesh.")
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise ParameterError("the mass matrix has zero, negative or non-finite entries; remove "
                             "unreferenced or degenerate vertices first.")
    return np.asarray(d, dtype=float)


def _check_L(L) -> sp.csr_matrix:
    if not sp.issparse(L) or L.shape[0] != L.shape[1]:
        raise ParameterError("the operator must be a square sparse matrix.")
    L = sp.csr_matrix(L, dtype=float)
    if L.nnz and not np.all(np.isfinite(L.data)):
        raise ParameterError("the operator has non-finite entries.")
    if L.diagonal().sum() < 0:
        raise ParameterError("the operator looks negative semi-definite (libigl's cotmatrix "
                             "sign); pass -L.")
    return L


#: an operator of at least this many loose parts (blocks) is solved part by part
#: (:func:`_eigs_by_part`)
EIGS_BY_PART = 50


def generalized_eigs(L, M, k: int, sigma: float | None = None, progress=None):
    """First ``k`` eigenpairs of ``L x = lam M x`` (ascending), eigenvectors M-orthonormal.

    Large problems use ARPACK in shift-invert mode around ``sigma``; the default shift is
    ``-1e-8`` times the operator's own scale ``mean(diag L / diag M)``, so that the shifted
    matrix ``L - sigma M`` is safely non-singular whatever the mesh units (a fixed ``-1e-8``
    vanished in round-off on a scan stored in metres with 1e-8 m^2 vertex areas: "Factor is
    exactly singular"). Failures of the factorization or of ARPACK become a
    :class:`~algorithms.errors.ParameterError` with a plain message.

    ``progress(fraction, message)``, when given, is called at every Lanczos step (one solve
    with the factor of ``L - sigma M``; ARPACK asks for ``ncv = max(2k + 1, 20)`` of them,
    then about ``(ncv - k) / 2`` more per implicit restart). A Lanczos step's cost grows with
    the basis it is orthogonalized against, so the reported fraction is
    ``0.9 (steps / expected steps)^2``: the work done, not the step count. An exception it
    raises (e.g. :class:`~algorithms.steps.Cancelled`) stops ARPACK and propagates.

    It runs with one BLAS thread (:func:`algorithms.spectral._blas.single_blas_thread`), as in
    the panel's child process: with a busy machine, OpenBLAS's threads made ARPACK 3x slower.
    """
    from ._blas import single_blas_thread

    with single_blas_thread():
        Ld = L if sp.issparse(L) else sp.csr_matrix(L)
        parts, label = csgraph.connected_components(Ld, directed=False)
        if parts >= EIGS_BY_PART:
            return _eigs_by_part(Ld, M, k, sigma, progress, parts, label)
        return _generalized_eigs(L, M, k, sigma, progress)


def _eigs_by_part(L, M, k, sigma, progress, parts: int, label: np.ndarray):
    """:func:`generalized_eigs` of a block-diagonal operator (a mesh of ``parts`` loose parts):
    the spectrum is the union of the parts' spectra, so each part gives its own first ``k``
    (or all it has) and the smallest ``k`` of them are kept. On a mesh of many parts asking
    for ``k`` pairs past the null space of dimension ``parts`` (the corpus's abominevole:
    1,750 of 6,508 after 1,740 parts) one ARPACK run over the whole took 96 s."""
    n = L.shape[0]
    k = int(min(k, n - 1))
    Ms = sp.csr_matrix(M if sp.issparse(M) else sp.diags(np.asarray(M, float)))
    Lc = sp.csr_matrix(L)
    lams, vecs = [], []
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], np.arange(parts + 1))
    big = np.argmax(np.diff(starts))
    for c in range(parts):
        idx = order[starts[c]:starts[c + 1]]
        # the same solver as a whole operator (its checks, dense or ARPACK, plain errors),
        # every pair a small part has
        lam, phi = _generalized_eigs(Lc[idx][:, idx], Ms[idx][:, idx], min(k, len(idx)), sigma,
                                     progress if c == big else None, every=True)
        lams.append(np.asarray(lam, float))
        vecs.append((idx, np.asarray(phi, float)))
    lam_all = np.concatenate(lams)
    owner = np.concatenate([np.full(len(x), c) for c, x in enumerate(lams)])
    column = np.concatenate([np.arange(len(x)) for x in lams])
    keep = np.argsort(lam_all, kind="stable")[:k]
    phi = np.zeros((n, len(keep)))
    for j, t in enumerate(keep):
        idx, P = vecs[owner[t]]
        phi[idx, j] = P[:, column[t]]
    return lam_all[keep], phi


def _generalized_eigs(L, M, k, sigma, progress, every: bool = False):
    """``every``: up to all ``n`` pairs (a part of :func:`_eigs_by_part`; the dense solve),
    else at most ``n - 1``."""
    n = L.shape[0]
    k = int(min(k, n if every else n - 1))
    Ms = M if sp.issparse(M) else sp.diags(np.asarray(M, float))
    mass = np.asarray(Ms.diagonal(), float)
    if not np.all(np.isfinite(mass)) or np.any(mass <= 0):
        raise ParameterError("the mass matrix has zero, negative or non-finite entries (vertices "
                             "with no area: unreferenced vertices or zero-area triangles); run "
                             "Clean, or remove those vertices, and try again.")
    Ld = L if sp.issparse(L) else sp.csr_matrix(L)
    if Ld.nnz and not np.all(np.isfinite(Ld.data)):
        raise ParameterError("the operator has non-finite entries, usually from zero-area "
                             "(degenerate) triangles; run Clean and try again.")
    if n <= max(200, 3 * k):
        import scipy.linalg as sla
        try:
            kk = int(min(k, n))
            Mc = sp.csr_matrix(Ms)
            if (Mc - sp.diags(Mc.diagonal())).count_nonzero() == 0:
                # diagonal M: the standard problem of D^-1 L D^-1 (D = M^1/2), first k only
                dinv = 1.0 / np.sqrt(mass)
                Cd = Ld.toarray() * dinv[:, None] * dinv[None, :]
                lam, y = sla.eigh((Cd + Cd.T) * 0.5, subset_by_index=[0, kk - 1])
                phi = y * dinv[:, None]
            else:
                lam, phi = sla.eigh(Ld.toarray(), Ms.toarray(), subset_by_index=[0, kk - 1])
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ParameterError(f"the eigenvectors of the operator could not be computed "
                                 f"({exc}); the mesh probably has degenerate triangles: run "
                                 "Clean and try again.") from None
        lam, phi = lam[:k], phi[:, :k]
    else:
        if sigma is None:
            scale = float(np.mean(np.abs(Ld.diagonal()) / mass))
            sigma = -1e-8 * (scale if np.isfinite(scale) and scale > 0 else 1.0)
        # fixed start vector: ARPACK's random one makes results (and everything optimized
        # from them) differ from run to run
        v0 = np.random.default_rng(0).uniform(0.5, 1.5, n)
        OPinv = _counting_shift_invert(Ld, Ms, sigma, k, progress)
        try:
            lam, phi = eigsh(sp.csc_matrix(Ld), k=k, M=sp.csc_matrix(Ms), sigma=sigma,
                             which="LM", v0=v0, OPinv=OPinv)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
            # SuperLU "Factor is exactly singular", ARPACK no convergence (a RuntimeError)
            raise ParameterError(f"the eigenvectors of the operator could not be computed "
                                 f"({exc}). The operator or its mass matrix is singular or "
                                 "badly scaled, which usually means degenerate (zero-area) "
                                 "triangles or parts with almost no area; run Clean, remove "
                                 "tiny loose parts, and try again.") from None
        order = np.argsort(lam)
        lam, phi = lam[order], phi[:, order]
        # M-orthonormalize (eigsh is close but not exact within clusters of eigenvalues)
        Gm = phi.T @ (Ms @ phi)
        try:
            C = np.linalg.cholesky((Gm + Gm.T) / 2)
        except np.linalg.LinAlgError:
            raise ParameterError("the eigenvectors of the operator came out linearly "
                                 "dependent (a singular or indefinite mass matrix); run Clean "
                                 "and try again.") from None
        phi = np.linalg.solve(C, phi.T).T
    if not (np.all(np.isfinite(lam)) and np.all(np.isfinite(phi))):
        raise ParameterError("the eigenvectors of the operator came out non-finite; the mesh "
                             "probably has degenerate triangles: run Clean and try again.")
    return lam, phi


def _counting_shift_invert(L, M, sigma: float, k: int, progress):
    """``(L - sigma M)^-1`` as a LinearOperator that reports every application to
    ``progress`` when given (see :func:`generalized_eigs`).

    The factor is CHOLMOD's (:class:`algorithms.linalg.SPDSolver`, when ``cholespy`` is
    installed: ``L - sigma M`` is positive definite for a PSD L and sigma < 0), else SuperLU's
    as eigsh builds it itself. ARPACK on a 30k-vertex Laplacian, k 101, one BLAS thread: 3.9 s
    of CPU with CHOLMOD against 5.8 s with SuperLU (306 solves either way)."""
    from scipy.sparse.linalg import LinearOperator, splu

    from ..linalg import SPDSolver, cholmod_available

    n = L.shape[0]
    A = sp.csc_matrix(L - sigma * M)
    solve_fn = None
    if cholmod_available():
        try:
            solve_fn = SPDSolver(A, backend="cholmod").solve
        except Exception:   # not positive definite (an indefinite operator): SuperLU below
            solve_fn = None
    if solve_fn is None:
        try:
            solve_fn = splu(A).solve
        except RuntimeError as exc:   # "Factor is exactly singular": eigsh's message path
            raise ValueError(str(exc)) from None
    ncv = min(n, max(2 * k + 1, 20))
    expected = [ncv + (ncv - k) // 2]
    count = [0]

    shown = [0.0]

    def solve(x):
        count[0] += 1
        c = count[0]
        if c > expected[0]:   # one more implicit restart than expected: say so, never "200 of 150"
            expected[0] += max(1, (ncv - k) // 2)
        if progress is not None and (c == 1 or c % 5 == 0):
            shown[0] = max(shown[0], 0.9 * min(1.0, c / expected[0]) ** 2)   # never backwards
            progress(shown[0], f"Lanczos step {c} of about {expected[0]}")
        return solve_fn(np.asarray(x, dtype=np.float64).reshape(n))

    return LinearOperator((n, n), matvec=solve, dtype=np.float64)


def suggested_coarse_size(n: int, m: int = 500) -> int:
    """A coarse size for an ``n``-node operator: ``m`` (the thesis's 500), but at most n / 8.

    Spectral coarsening is made for strong reduction (the thesis coarsens 21k-30k rows to
    300-600). Asked for a mild one (spot, 829 vertices, to the default 500 rows with k = 167),
    it is beaten by AMG (C diag 0.48 against 0.76): with one or two fine nodes per cluster the
    lumped coarse mass and the cluster-ring pattern fit the top eigenvectors poorly. At n / 8
    (spot: 104 rows, k 35) ours scores C diag 0.95 against 0.46 (QSlim) and 0.72 (AMG).
    """
    return int(max(2, min(int(m), int(n) // 8)))


# --------------------------------------------------------------------------------------------
# 1. combinatorial coarsening

def edge_distances(L, mass: np.ndarray, p: float = 0.0, q: float = 2.0) -> sp.csr_matrix:
    """Operator-aware edge lengths D_ij = (M_ii + M_jj)^((p+1)/q) / (-L_ij) (thesis Eq. in 7.3.1).

    Edges with -L_ij <= 0 (where the formula's max(., 0) would give no usable length) keep the
    graph connected with a length of 10x the largest positive one.
    """
    C = sp.coo_matrix(L)
    off = C.row != C.col
    i, j, w = C.row[off], C.col[off], -C.data[off]
    d = np.empty_like(w)
    good = w > 0
    d[good] = (mass[i[good]] + mass[j[good]]) ** ((p + 1.0) / q) / w[good]
    big = 10.0 * d[good].max() if good.any() else 1.0
    d[~good] = big
    D = sp.csr_matrix((d, (i, j)), shape=L.shape)
    D = D.maximum(D.T)  # symmetric
    return D


def _seeds_per_component(D: sp.csr_matrix, m: int, rng: np.random.Generator,
                         demand: np.ndarray | None = None) -> np.ndarray:
    """Random initial roots, ``m`` in all, handed out to the connected parts of the graph.

    Without ``demand`` each part gets roots in proportion to its node count (at least one).
    With ``demand`` (per node, >= 0; :func:`coarsen_iter` passes the density
    ``M_jj sum_i Phi_ji^2`` of the k eigenvectors, whose sum over a part is the number of those
    eigenvectors living on it), a part's share is the larger of its node share and its share of
    the low spectrum (then renormalized). A small part of a multi-part model (a washer of a CAD
    model, a loose piece of a scan) can carry several of the first k eigenvectors (its constant
    and its own slow modes) with few nodes. Measured (mean eigenvalue error, node share ->
    this rule): 12 parts, m 150, k 40: 0.100 -> 0.085; m 120, k 50: 0.136 -> 0.058; 20 parts,
    m 200, k 60: 0.204 -> 0.189; 50 parts (4.5k nodes), m 600, k 150: 0.140 -> 0.070 with the
    spectral share alone. The C-diagonal score moves both ways on such models (eigenvalues of
    different parts interleave, and C permutes them).
    """
    n = D.shape[0]
    ncomp, comp = csgraph.connected_components(D, directed=False)
    if ncomp > m:
        raise ParameterError(f"the operator has {ncomp} disconnected parts but only {m} coarse "
                             "nodes were asked for; ask for at least one per part, or remove "
                             "small loose parts first.")
    sizes = np.bincount(comp, minlength=ncomp)
    share = sizes / n
    if demand is not None and ncomp > 1:
        d = np.bincount(comp, weights=np.maximum(np.asarray(demand, float), 0.0),
                        minlength=ncomp)
        if d.sum() > 0:
            share = np.maximum(share, d / d.sum())
            share = share / share.sum()
    alloc = np.maximum(1, np.floor(share * m).astype(int))
    alloc = np.minimum(alloc, sizes)
    while alloc.sum() < m:  # hand out the remainder to the parts with room, largest need first
        room = sizes - alloc
        c = int(np.argmax(np.where(room > 0, np.maximum(share, 1e-12) / alloc, -1)))
        alloc[c] += 1
    while alloc.sum() > m:
        c = int(np.argmax(np.where(alloc > 1, alloc, -1)))
        alloc[c] -= 1
    seeds = [rng.choice(np.flatnonzero(comp == c), size=a, replace=False)
             for c, a in enumerate(alloc)]
    return np.concatenate(seeds).astype(np.int64)


def kmedoids_clustering(L, M, m: int, *, p: float = 0.0, q: float = 2.0, iterations: int = 20,
                        seed: int = 0, demand: np.ndarray | None = None) -> Clustering:
    """Graph k-medoids (Lloyd aggregation, Bell 2008) on operator-aware shortest paths.

    Each iteration assigns every node to its nearest root (one multi-source Dijkstra) and moves
    every root to its cluster's centre: the node farthest (within the cluster) from the cluster
    boundary, Bell's approximation of the medoid. ``demand`` (per node) decides how many roots
    each connected part gets (see :func:`_seeds_per_component`).
    """
    t0 = time.perf_counter()
    L = _check_L(L)
    n = L.shape[0]
    if not 1 <= m <= n:
        raise ParameterError(f"the coarse size m={m} must be between 1 and n={n}.")
    mass = _as_mass_vector(M, n)
    D = edge_distances(L, mass, p, q)
    rng = np.random.default_rng(seed)
    roots = _seeds_per_component(D, m, rng, demand)
    Dc = D.tocoo()
    labels = None
    for _ in range(max(1, iterations)):
        dist, _, src = csgraph.dijkstra(D, directed=False, indices=roots, min_only=True,
                                        return_predecessors=True)
        pos = np.full(n, -1, dtype=np.int64)
        pos[roots] = np.arange(len(roots))
        new_labels = pos[src]
        # centre update: distance to the cluster boundary inside each cluster
        same = new_labels[Dc.row] == new_labels[Dc.col]
        inner = sp.csr_matrix((Dc.data[same], (Dc.row[same], Dc.col[same])), shape=(n, n))
        boundary = np.zeros(n, dtype=bool)
        boundary[Dc.row[~same]] = True
        if boundary.any():
            bd = csgraph.dijkstra(inner, directed=False, indices=np.flatnonzero(boundary),
                                  min_only=True)
            bd[~np.isfinite(bd)] = np.inf  # isolated cluster: any node, prefer the old root
        else:
            bd = np.zeros(n)
        bd = np.where(np.isfinite(bd), bd, dist.max() + 1.0)
        # tie-break towards the current root so converged roots stay put
        score = bd.copy()
        score[roots] += 1e-12 * (1.0 + np.abs(score[roots]))
        order = np.lexsort((-score, new_labels))
        first = np.r_[0, np.flatnonzero(np.diff(new_labels[order])) + 1]
        new_roots = order[first]
        new_roots = new_roots[np.argsort(new_labels[new_roots])]
        converged = labels is not None and np.array_equal(new_roots, roots)
        labels, roots = new_labels, new_roots
        if converged:
            break
    # final assignment to the final roots
    _, _, src = csgraph.dijkstra(D, directed=False, indices=roots, min_only=True,
                                 return_predecessors=True)
    pos = np.full(n, -1, dtype=np.int64)
    pos[roots] = np.arange(len(roots))
    labels = pos[src]
    mm = len(roots)
    K = sp.csr_matrix((np.ones(n), (labels, np.arange(n))), shape=(mm, n))
    P = sp.csr_matrix((np.ones(mm), (np.arange(mm), roots)), shape=(mm, n))
    return Clustering(labels=labels, roots=roots, K=K, P=P, seconds=time.perf_counter() - t0)


def cluster_sparsity(L, K) -> sp.csr_matrix:
    """S_G = K^T A~ with the cluster adjacency A~ = K S_L K^T (so S_L~ = A~^3), n x m 0/1."""
    SL = sp.csr_matrix(L, copy=True)
    SL.data[:] = 1.0
    SL = SL + sp.eye(L.shape[0], format="csr")
    A = (K @ SL @ K.T).tocsr()
    A.data[:] = 1.0
    S = (K.T @ A).tocsr()
    S.data[:] = 1.0
    S.sort_indices()
    return S


# --------------------------------------------------------------------------------------------
# 2. operator optimization

def null_space(L, M=None, lam=None, phi=None, rtol: float = 1e-8) -> np.ndarray:
    """Basis Phi0 (n x c) of the null space of L.

    Exact connected-component indicators when L annihilates them (Laplacians: G P 1 = 1 per
    part); otherwise the eigenvectors ``phi`` whose eigenvalues are below ``rtol * max|lam|``.
    """
    L = sp.csr_matrix(L)
    n = L.shape[0]
    ncomp, comp = csgraph.connected_components(L, directed=False)
    ind = np.zeros((n, ncomp))
    ind[np.arange(n), comp] = 1.0
    scale = max(abs(L).sum(axis=1).max(), 1e-300)
    if np.abs(L @ ind).max() <= 1e-9 * scale:
        return ind
    if lam is None or phi is None:
        raise ParameterError("the operator has no constant null space; pass its eigenpairs.")
    lam = np.asarray(lam)
    keep = np.abs(lam) <= rtol * max(np.abs(lam).max(), 1e-300)
    return phi[:, keep]


def project_constraint(G: sp.csr_matrix, B0: np.ndarray, Phi0: np.ndarray) -> sp.csr_matrix:
    """Closest G' (Frobenius, same sparsity) with G' B0 = Phi0 (App. 7.6.2), B0 = P Phi0.

    The constraint decouples per row of G: g_i B0[J_i] = Phi0[i]; the minimum-norm correction is
    r_i (B0_J^T B0_J)^-1 B0_J^T with r_i = g_i B0_J - Phi0_i. For one null vector this is the
    element-wise division of the thesis.
    """
    G = sp.csr_matrix(G, copy=True)
    n = G.shape[0]
    rows = np.repeat(np.arange(n), np.diff(G.indptr))
    cols = G.indices
    c = B0.shape[1]
    resid = G @ B0 - Phi0                       # (n, c)
    if c == 0:
        return G
    if c == 1:
        b = B0[:, 0]
        S = G.copy()
        S.data = b[cols] ** 2
        gram = np.asarray(S.sum(axis=1)).ravel()
        gram[gram == 0] = 1.0
        G.data -= (resid[rows, 0] / gram[rows]) * b[cols]
        return G
    outer = (B0[:, :, None] * B0[:, None, :]).reshape(-1, c * c)
    S = G.copy()
    S.data[:] = 1.0
    gram = (S @ outer).reshape(n, c, c) + 1e-300 * np.eye(c)
    try:
        y = np.linalg.solve(gram, resid[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        y = np.stack([np.linalg.lstsq(gram[i], resid[i], rcond=None)[0] for i in range(n)])
    G.data -= np.einsum("zc,zc->z", y[rows], B0[cols])
    return G


def energy_and_gradient(G: sp.csr_matrix, L: sp.csr_matrix, A: np.ndarray, B: np.ndarray,
                        mt: np.ndarray, *, gradient: bool = True, chunk: int = 200_000,
                        blocks=None):
    """E_k(G) = 1/2 ||A - M~^-1 G^T L G B||^2_M~ and its gradient on the pattern of G.

    Gradient (App. 7.6.1): dE/dG = Y Z with Y = L G and Z = W B^T + B W^T, W = M~^-1 L~ B - A;
    evaluated only on the non-zeros of G as (Y W)_i . B_j + (Y B)_i . W_j (never n x m dense).
    ``blocks`` (from :func:`_cluster_blocks`) evaluates it cluster by cluster as small dense
    products (rows of one cluster share their column pattern), which is faster than gathering.
    Returns (E, grad_data aligned with G.data or None, L~).
    """
    Y = (L @ G).tocsr()
    Lt = (G.T @ Y).tocsr()
    Lt = (Lt + Lt.T) * 0.5
    W = (Lt @ B) / mt[:, None] - A
    E = 0.5 * float(np.sum(mt[:, None] * W * W))
    if not gradient:
        return E, None, Lt
    YW = Y @ W
    YB = Y @ B
    n = G.shape[0]
    g = np.empty(G.nnz)
    if blocks is not None:
        for R, J, pos in blocks:
            g[pos] = YW[R] @ B[J].T + YB[R] @ W[J].T
        return E, g, Lt
    rows = np.repeat(np.arange(n), np.diff(G.indptr))
    cols = G.indices
    for s in range(0, G.nnz, chunk):
        r, c = rows[s:s + chunk], cols[s:s + chunk]
        g[s:s + chunk] = (np.einsum("zk,zk->z", YW[r], B[c])
                          + np.einsum("zk,zk->z", YB[r], W[c]))
    return E, g, Lt


_KERNELS = KernelModule("algorithms.spectral.kernels")


def _dot(x: np.ndarray, y: np.ndarray) -> float:
    """x . y without BLAS (see :mod:`algorithms.spectral.kernels`: OpenBLAS's threads on a busy
    machine made one dot product of 215k numbers cost up to 23 ms)."""
    return float(np.add.reduce(x * y))


class _Energy:
    """The energy E_k and its gradient for one fixed pattern of G, evaluated on G's stored
    values only (``gdata``, aligned with the pattern's CSR data); the same quantities as
    :func:`energy_and_gradient`, reorganized for speed (issue 25).

    The patterns of ``Y = L G`` (n x m) and ``L~ = G^T Y`` (m x m) are fixed by the pattern of
    G, so they are computed once; each evaluation then only fills in their values (sparse
    products on known patterns, :func:`algorithms.spectral.kernels.spgemm_fixed`: about
    ``nnz(L) r + n r^2`` multiply-adds with r ~ 7 clusters per row of G), and all the work
    on the k eigenvectors happens at the coarse size m: ``W = M~^-1 L~ B - A`` and
    ``Z = W2 B^T + B W2^T`` (m x m, :func:`~algorithms.spectral.kernels.sym_outer`), then the
    gradient on the pattern ``g_ij = (Y Z)_ij`` (App. 7.6.1: dE/dG = Y Z). ``W2 = W`` for the
    thesis energy, or ``W2 = W diag(w)`` for column weights ``w`` (the balanced energy of
    :func:`_balance_stage`, whose columns of A and B are scaled by ``sqrt(w)``: its gradient is
    this one with W2). Earlier, each evaluation formed ``L G`` and ``G^T L G`` with SciPy's
    general sparse products and the gradient from n x k products plus a small matrix product
    per cluster: 30k -> 500, k 100 took 64-67 ms of CPU per evaluation here against 29-32 ms
    now (one thread each; measured side by side, benchmarks/spectral.py --kernels). No BLAS
    is called per evaluation: OpenBLAS's threads stalled for tens of ms per call while the
    machine's cores were busy with other work.
    For m > 4000 (an m x m Z above 128 MB) the gradient is taken as
    ``(Y W2)_i . B_j + (Y B)_i . W2_j`` instead. Without Numba everything runs in SciPy.
    The constraint G P Phi0 = Phi0 with one null vector (every Laplacian on one or several
    parts, see :func:`coarsen_iter`) is projected on the stored values directly; with several,
    through :func:`project_constraint`.
    """

    Z_LIMIT = 4000

    def __init__(self, G: sp.csr_matrix, L: sp.csr_matrix, A: np.ndarray, B: np.ndarray,
                 mt: np.ndarray, B0: np.ndarray, Phi0: np.ndarray):
        G = sp.csr_matrix(G, copy=True)
        G.sort_indices()
        self.shape = G.shape
        n, m = G.shape
        i64 = np.int64
        self.indptr = G.indptr.astype(i64)
        self.indices = G.indices.astype(i64)
        self.rows = np.repeat(np.arange(n), np.diff(self.indptr))
        Lc = sp.csr_matrix(L, dtype=np.float64)
        Lc.sort_indices()
        self.L = Lc
        self.A = np.ascontiguousarray(A, dtype=np.float64)
        self.B = np.ascontiguousarray(B, dtype=np.float64)
        self.mt = np.asarray(mt, dtype=np.float64)
        self.B0 = B0
        self.Phi0 = Phi0
        self.kernels = _KERNELS.get()
        if self.kernels is not None:
            # G^T in CSR: a fixed permutation of G's stored values
            self.t_order = np.argsort(self.indices, kind="stable")
            self.t_indptr = np.r_[0, np.cumsum(np.bincount(self.indices, minlength=m))].astype(
                i64)
            self.t_indices = self.rows[self.t_order]
            self.L_indptr, self.L_indices = Lc.indptr.astype(i64), Lc.indices.astype(i64)
            self.L_data = np.ascontiguousarray(Lc.data)
            ones = lambda X: sp.csr_matrix((np.ones(X.nnz), X.indices, X.indptr),  # noqa: E731
                                           shape=X.shape)
            Go = ones(G)
            Yp = (ones(Lc) @ Go).tocsr()          # no cancellation: all ones
            Yp.sort_indices()
            Tp = (Go.T @ ones(Yp)).tocsr()
            Tp.sort_indices()
            self.Y_indptr, self.Y_indices = Yp.indptr.astype(i64), Yp.indices.astype(i64)
            self.T_indptr, self.T_indices = Tp.indptr.astype(i64), Tp.indices.astype(i64)
        if B0.shape[1] == 1:
            self._b = B0[:, 0][self.indices]
            gram = np.bincount(self.rows, weights=self._b ** 2, minlength=n)
            gram[gram == 0] = 1.0
            self._gram = gram
            self._phi0 = np.asarray(Phi0[:, 0], dtype=np.float64)
        self.evaluations = 0

    def _G(self, gdata) -> sp.csr_matrix:
        return sp.csr_matrix((gdata, self.indices, self.indptr), shape=self.shape)

    # -- energy ---------------------------------------------------------------------------
    def __call__(self, gdata, weights=None, gradient: bool = True):
        """``(E, E_w, grad)``: the thesis energy, the energy with column weights ``weights``
        (None: E_w = E) and the gradient of E_w on the pattern (None without ``gradient``)."""
        self.evaluations += 1
        kn = self.kernels
        n, m = self.shape
        gdata = np.ascontiguousarray(gdata, dtype=np.float64)
        if kn is not None:
            yd = kn.spgemm_fixed(self.L_indptr, self.L_indices, self.L_data, self.indptr,
                                 self.indices, gdata, self.Y_indptr, self.Y_indices, m)
            td = kn.spgemm_fixed(self.t_indptr, self.t_indices, gdata[self.t_order],
                                 self.Y_indptr, self.Y_indices, yd, self.T_indptr,
                                 self.T_indices, m)
            LtB = kn.csr_dense(self.T_indptr, self.T_indices, td, self.B)
        else:
            G = self._G(gdata)
            Y = (self.L @ G).tocsr()
            LtB = np.asarray((G.T @ Y) @ self.B)
        W = LtB / self.mt[:, None] - self.A
        mW2 = self.mt[:, None] * W * W
        E = 0.5 * float(np.add.reduce(mW2, axis=None))
        if weights is None:
            Ew, W2 = E, W
        else:
            Ew = 0.5 * float(np.add.reduce(mW2 * weights, axis=None))
            W2 = W * weights
        if not gradient:
            return E, Ew, None
        if kn is not None and m <= self.Z_LIMIT:
            g = kn.pattern_rowdot(self.indptr, self.indices, self.Y_indptr, self.Y_indices,
                                  yd, kn.sym_outer(W2, self.B))
        elif kn is not None:
            YW = kn.csr_dense(self.Y_indptr, self.Y_indices, yd, W2)
            YB = kn.csr_dense(self.Y_indptr, self.Y_indices, yd, self.B)
            g = kn.pattern_dots(self.indptr, self.indices, YW, self.B, YB, W2)
        else:
            YW, YB = np.asarray(Y @ W2), np.asarray(Y @ self.B)
            g = np.empty(len(self.rows))
            chunk = 200_000
            for s in range(0, len(g), chunk):
                r, c = self.rows[s:s + chunk], self.indices[s:s + chunk]
                g[s:s + chunk] = (np.einsum("zk,zk->z", YW[r], self.B[c])
                                  + np.einsum("zk,zk->z", YB[r], W2[c]))
        return E, Ew, g

    def coarse_operator(self, gdata) -> sp.csr_matrix:
        """L~ = G^T L G (symmetrized), m x m CSR."""
        G = self._G(gdata)
        Lt = (G.T @ (self.L @ G)).tocsr()
        return ((Lt + Lt.T) * 0.5).tocsr()

    # -- constraint -----------------------------------------------------------------------
    def project(self, gdata, tangent: bool = False) -> np.ndarray:
        """The closest values (same pattern) with G B0 = Phi0 (``tangent``: G B0 = 0), see
        :func:`project_constraint`."""
        if self.B0.shape[1] != 1:
            G = sp.csr_matrix((np.array(gdata, dtype=float), self.indices, self.indptr),
                              shape=self.shape)
            target = np.zeros_like(self.Phi0) if tangent else self.Phi0
            return project_constraint(G, self.B0, target).data
        resid = np.bincount(self.rows, weights=gdata * self._b, minlength=self.shape[0])
        if not tangent:
            resid -= self._phi0
        return gdata - (resid / self._gram)[self.rows] * self._b


def _cluster_blocks(G: sp.csr_matrix, labels: np.ndarray):
    """Per cluster: (member rows R, shared columns J, positions in G.data (|R| x |J|)), or None
    when the rows of a cluster do not share one column pattern."""
    order = np.argsort(labels, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(labels[order])) + 1, len(order)]
    out = []
    for a, b in zip(starts[:-1], starts[1:]):
        R = order[a:b]
        lo, hi = G.indptr[R[0]], G.indptr[R[0] + 1]
        J = G.indices[lo:hi]
        cnt = np.diff(G.indptr)[R]
        if np.any(cnt != len(J)):
            return None
        pos = G.indptr[R][:, None] + np.arange(len(J))[None, :]
        if not np.array_equal(G.indices[pos], np.broadcast_to(J, pos.shape)):
            return None
        out.append((R, J, pos))
    return out


def lbfgs_iter(fun, x0: np.ndarray, maxiter: int, *, memory: int = 10, ftol: float = 1e-7,
               patience: int = 10, project=None):
    """Minimize ``fun(x) -> (f, grad)`` with L-BFGS (two-loop recursion, Armijo backtracking);
    a generator yielding ``(iteration, f, x)`` after every accepted step, so that callers can
    stream and cancel.

    ``project(x)``, when given, maps x back onto an affine constraint set after each step (the
    caller's gradient must already lie in the constraint's tangent space, so every search
    direction does too; the projection only removes round-off drift). Stops after ``maxiter``
    iterations, when the line search fails, or after ``patience`` consecutive iterations that
    lower f by less than ``ftol`` relatively.
    """
    x = np.array(x0, dtype=float)
    f, g = fun(x)
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    slow = 0
    for it in range(1, maxiter + 1):
        # two-loop recursion: d = -H g
        q = g.copy()
        alphas = []
        for s_, y_ in zip(reversed(S), reversed(Y)):
            a = _dot(s_, q) / _dot(y_, s_)
            alphas.append(a)
            q -= a * y_
        if S:
            q *= _dot(S[-1], Y[-1]) / _dot(Y[-1], Y[-1])
        else:
            q /= max(np.sqrt(_dot(g, g)), 1e-300)     # first step: unit length
        for (s_, y_), a in zip(zip(S, Y), reversed(alphas)):
            b = _dot(y_, q) / _dot(y_, s_)
            q += (a - b) * s_
        d = -q
        slope = _dot(g, d)
        if not slope < 0:                           # not a descent direction: restart
            S.clear()
            Y.clear()
            d = -g / max(np.sqrt(_dot(g, g)), 1e-300)
            slope = _dot(g, d)
            if not slope < 0:
                return
        t = 1.0
        for _ in range(40):
            xn = x + t * d
            if project is not None:
                xn = project(xn)
            fn, gn = fun(xn)
            if np.isfinite(fn) and fn <= f + 1e-4 * t * slope:
                break
            t *= 0.5
        else:
            return                                  # no decrease found: at a minimum
        s_, y_ = xn - x, gn - g
        if _dot(s_, y_) > 1e-10 * np.sqrt(_dot(s_, s_) * _dot(y_, y_)):
            S.append(s_)
            Y.append(y_)
            if len(S) > memory:
                S.pop(0)
                Y.pop(0)
        slow = slow + 1 if f - fn <= ftol * abs(f) else 0
        x, f, g = xn, fn, gn
        yield it, f, x
        if slow >= patience:
            return


def coarsen_iter(L, M, m: int | None = None, k: int | None = None,
                 params: CoarsenParams | None = None, *, eigs=None,
                 clustering: Clustering | None = None) -> Iterator[CoarsenStep]:
    """Spectral coarsening as a generator: one :class:`CoarsenStep` per optimizer iteration.

    ``m``/``k`` override ``params.m``/``params.k``; ``eigs=(lam, phi)`` reuses a fine
    eigendecomposition (first k, M-orthonormal); ``clustering`` reuses a combinatorial stage.
    The last step has ``done=True`` and the result (best iterate) in L, M, G, K, P.
    """
    params = params or CoarsenParams()
    m = int(params.m if m is None else m)
    k = int(params.k if k is None else k)
    if k <= 0:
        k = max(1, round(m / 3))
    L = _check_L(L)
    n = L.shape[0]
    mass = _as_mass_vector(M, n)
    if not 2 <= m <= n:
        raise ParameterError(f"the coarse size m={m} must be between 2 and the operator size "
                             f"{n}.")
    if k >= m:
        raise ParameterError(f"the eigenvector count k={k} must be smaller than m={m} "
                             "(the thesis recommends m > 2k).")
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if eigs is None:
        lam, phi = generalized_eigs(L, sp.diags(mass), k)
    else:
        lam, phi = eigs
        lam, phi = np.asarray(lam)[:k], np.asarray(phi)[:, :k]
    timings["eigendecomposition"] = time.perf_counter() - t
    t = time.perf_counter()
    if clustering is None:
        # roots per connected part by its share of the k eigenvectors (M-orthonormal: the
        # density sums to k), not by its node count (see _seeds_per_component)
        demand = mass * np.sum(phi * phi, axis=1)
        clustering = kmedoids_clustering(L, mass, m, p=params.p, q=params.q,
                                         iterations=params.clustering_iterations,
                                         seed=params.seed, demand=demand)
    K, P = clustering.K, clustering.P
    SG = cluster_sparsity(L, K)
    timings["clustering"] = time.perf_counter() - t

    t = time.perf_counter()
    mt = np.asarray(K @ mass).ravel()                   # M~ = K M K^T (diagonal)
    A = P @ ((L @ phi) / mass[:, None])                 # P M^-1 L Phi
    B = P @ phi                                         # P Phi
    Phi0 = null_space(L, None, lam, phi)
    if Phi0.shape[1] > 1 and np.array_equal(Phi0, Phi0.astype(bool)) \
            and np.all(Phi0.sum(axis=1) == 1):
        # connected-component indicators: every row of G only has columns of its own part (S_G
        # follows L's graph), so the c constraints of a row reduce to one, with the all-ones
        # vector (c times cheaper than the c x c per-row systems; 50 parts: 0.65 -> s per step)
        Phi0 = np.ones((n, 1))
    B0 = P @ Phi0
    # initial G: piecewise-constant prolongation K^T on the pattern S_G
    G = SG.copy()
    rows = np.repeat(np.arange(n), np.diff(G.indptr))
    G.data = (clustering.labels[rows] == G.indices).astype(float)   # explicit zeros kept
    if params.initial_G == "smoothed":
        # one damped-Jacobi step on K^T, (I - omega D^-1 L) K^T, omega = 4 / (3 rho) with rho
        # the Gershgorin bound of the spectral radius of D^-1 L (2 for an M-matrix, giving the
        # classical 2/3). Its pattern (clusters touching a node's neighbours) lies in S_G, and
        # its rows still sum to one, so G P 1 = 1 holds before the projection.
        S = (sp.diags(1.0 / L.diagonal()) @ L).tocsr()
        rho = float(np.asarray(abs(S).sum(axis=1)).max())
        Ksm = (K.T - (4.0 / 3.0 / rho) * (S @ K.T)).tocsr()
        G.data = np.asarray(Ksm[rows, G.indices]).ravel()
    elif params.initial_G != "constant":
        raise ParameterError(f"unknown initial G '{params.initial_G}'; use 'constant' or "
                             "'smoothed'.")
    G = project_constraint(G, B0, Phi0)
    ev = _Energy(G, L, A, B, mt, B0, Phi0)
    gdata = G.data.copy()
    E, _, grad = ev(gdata)
    E0 = E
    gscale = 1.0 / E0 if E0 > 0 else 1.0
    best_E, best_g = E, gdata.copy()
    yield CoarsenStep(0, params.max_iterations, E, {"energy": E, "relative_energy": 1.0},
                      "initial (piecewise constant)")
    # already exact (e.g. every part small enough to keep all its nodes): nothing to optimize;
    # NADAM on E / E0 with E0 ~ 0 would take huge steps
    scaleA = 0.5 * float(np.sum(mt[:, None] * A * A))
    max_it = params.max_iterations if E0 > 1e-14 * scaleA else 0
    lr = float(params.learning_rate)
    b1, b2, eps = 0.9, 0.9, 1e-8
    mom = np.zeros(gdata.size)
    vel = np.zeros(gdata.size)
    stall = 0
    decays = 0
    it = 0
    for it in range(1, max_it + 1):
        # NADAM on the energy relative to its initial value: the step is then independent of
        # the units of L and M (E scales like length^-2 for a surface Laplacian), so eps stays
        # negligible on small or large meshes alike
        gs = grad * gscale
        step = nadam_step(gs, mom, vel, it, lr, b1, b2, eps)  # updates mom, vel in place
        gdata = ev.project(gdata - step)
        E, _, grad = ev(gdata)
        if E < best_E:
            best_E, best_g = E, gdata.copy()
            stall = 0
        else:
            stall += 1
        yield CoarsenStep(it, params.max_iterations, E,
                          {"energy": E, "relative_energy": E / E0 if E0 else 0.0,
                           "learning_rate": lr},
                          f"iteration {it}: energy {E:.4g}")
        if stall >= params.patience:
            if decays < params.lr_decays:      # authors' schedule: halve and carry on
                lr *= 0.5
                decays += 1
                stall = 0
            else:
                break
    timings["optimization"] = time.perf_counter() - t
    timings["iterations"] = float(it)
    nadam_its = it
    if params.balance_iterations > 0 and max_it > 0:
        t = time.perf_counter()
        evals0 = ev.evaluations
        best_g, best_E, polished = yield from _balance_stage(ev, best_g, lam, params,
                                                             nadam_its, best_E)
        timings["balancing"] = time.perf_counter() - t
        timings["balancing_iterations"] = float(polished)
        timings["balancing_evaluations"] = float(ev.evaluations - evals0)
        it = nadam_its + polished
    Mt = sp.diags(mt).tocsr()
    best_G = sp.csr_matrix((best_g, ev.indices.copy(), ev.indptr.copy()), shape=ev.shape)
    best_Lt = ev.coarse_operator(best_g)
    yield CoarsenStep(it, params.max_iterations, best_E,
                      {"energy": best_E, "relative_energy": best_E / E0 if E0 else 0.0},
                      f"done after {it} iterations: energy {best_E:.4g} "
                      f"({best_E / E0 if E0 else 0:.3g} of the initial)",
                      done=True, L=best_Lt, M=Mt, G=best_G, K=K, P=P, timings=timings)


def balance_weights(lam, balance: float) -> np.ndarray:
    """Column weights of the balanced energy: ``(lam_max / lam_i)^balance`` for the non-zero
    eigenvalues, 1 for the zero ones (see :func:`_balance_stage`)."""
    lam = np.asarray(lam, float)
    w = np.ones(len(lam))
    scale = max(np.abs(lam).max(), 1e-300) if len(lam) else 1.0
    nonzero = np.abs(lam) > 1e-8 * scale
    if balance > 0 and nonzero.any():
        w[nonzero] = (lam[nonzero].max() / lam[nonzero]) ** float(balance)
    return w


def _balance_stage(ev: "_Energy", gdata, lam, params, it0, E_thesis):
    """Stage 2 (beyond the thesis): L-BFGS on the eigenvalue-balanced energy from the NADAM
    result; yields a CoarsenStep per iteration (energy = the thesis energy, for the plot) and
    returns (G's values, thesis energy, iterations).

    The thesis energy counts the residual of eigenvector i, which is about
    |lam~_i - lam_i| ||P phi_i||, in absolute terms, so eigenvector i weighs like lam_i^2 and the
    lowest ones hardly at all: the optimum leaves them 15-35% too stiff on every shared mesh
    (e.g. armadillo 14.6k -> 300, k 60: the first five coarse eigenvalues 1.30-1.34 times the
    fine ones, mean eigenvalue error 0.166, where QSlim has 0.082). Scaling column i of A and B
    by (lam_k / lam_i)^(w/2) counts it like lam_i^(2-w); w = 1 halves the spread. NADAM with a
    fixed step does not make progress on that energy (hand_lowres: E / E0 stays at 0.36 after
    1000 iterations), L-BFGS does (0.14 in 300): the low-mode corrections are smooth, global
    changes of G, which a per-entry step size cannot coordinate. Measured at 300 iterations,
    w = 1 (C diag, mean eigenvalue error; thesis -> balanced): armadillo 0.75, 0.166 -> 0.99,
    0.007; camelhead 0.79, 0.099 -> 0.86, 0.026; fertility 0.87, 0.058 -> 0.91, 0.017; wingnut
    0.65, 0.086 -> 0.75, 0.037.

    Scaling the columns of A and B by sqrt(w) scales the columns of W = M~^-1 L~ B - A the same
    way, so one evaluation (:class:`_Energy` with column weights w) gives both the balanced
    energy with its gradient and the thesis energy.
    """
    wts = balance_weights(lam, float(params.balance))
    gdata = np.array(gdata, dtype=float)
    E0w = ev(gdata, wts, gradient=False)[1]
    if not E0w > 0:
        return gdata, E_thesis, 0
    last = {}

    def fun(x):
        E, Ew, g = ev(x, wts)
        last["E"] = E
        return Ew / E0w, ev.project(g, tangent=True) / E0w   # tangent to G P Phi0 = Phi0

    best = None
    n_it = 0
    for n_it, f, x in lbfgs_iter(fun, gdata, params.balance_iterations,
                                 project=ev.project):
        E_t = last["E"]
        best = (x.copy(), E_t)
        yield CoarsenStep(it0 + n_it, None, E_t,
                          {"energy": E_t, "balanced_energy": f,
                           "balancing_iteration": float(n_it)},
                          f"balancing {n_it}: thesis energy {E_t:.4g}, balanced "
                          f"{f:.3g} of its start", stage="balancing")
    if best is None:
        return gdata, E_thesis, 0
    return best[0], best[1], n_it


def coarsen(L, M, m: int | None = None, k: int | None = None,
            params: CoarsenParams | None = None, **kw) -> CoarsenStep:
    """Run :func:`coarsen_iter` to the end and return its final step (with the result)."""
    last = None
    for last in coarsen_iter(L, M, m, k, params, **kw):
        pass
    return last


# --------------------------------------------------------------------------------------------
# 3. recursive multilevel hierarchy (thesis Fig. 7.16)

@dataclass
class HierarchyLevel:
    """One level of :func:`coarsen_hierarchy`: the coarse operator of the level above.

    ``G`` (m_prev x m), ``K`` and ``P`` (m x m_prev) relate this level to the previous one
    (m_prev = n for the first level); ``P_total``
    (m x n) selects this level's roots among the finest nodes (``P_l ... P_1``), so that
    :func:`~algorithms.spectral.metrics.spectral_metrics` can compare it with the input.
    """

    m: int
    k: int
    L: sp.csr_matrix
    M: sp.csr_matrix
    G: sp.csr_matrix
    K: sp.csr_matrix
    P: sp.csr_matrix
    P_total: sp.csr_matrix
    step: CoarsenStep


def coarsen_hierarchy(L, M, sizes, params: CoarsenParams | None = None, k=None, *,
                      callback=None) -> list[HierarchyLevel]:
    """Apply spectral coarsening recursively: (L, M) -> (L1, M1) -> (L2, M2) -> ...

    Parameters
    ----------
    L : (n, n) sparse PSD operator; M : (n, n) diagonal mass (or length-n vector).
    sizes : strictly decreasing coarse sizes ``m1 > m2 > ...`` (all < n).
    params : :class:`CoarsenParams` (``params.m`` is ignored; ``params.k`` is used per level
        when ``k`` is None, 0 meaning round(m_l / 3)).
    k : None, an int for every level, or one int per level (eigenvectors preserved by level l,
        computed on level l-1).
    callback : called with ``(level_index, CoarsenStep)`` for every optimizer step.

    Returns
    -------
    list of :class:`HierarchyLevel`, coarsest last. Each level's L is symmetric PSD and keeps
    the null space (G P 1 = 1 on every level, so the constants stay in the kernel).
    """
    params = params or CoarsenParams()
    sizes = [int(s) for s in np.atleast_1d(sizes)]
    L = _check_L(L)
    n = L.shape[0]
    if not sizes:
        raise ParameterError("give at least one coarse size for the hierarchy.")
    prev = n
    for s in sizes:
        if not 2 <= s < prev:
            raise ParameterError(f"hierarchy sizes must decrease strictly from n={n} and stay "
                                 f">= 2; got {sizes}.")
        prev = s
    if k is None:
        ks = [params.k] * len(sizes)
    elif np.ndim(k) == 0:
        ks = [int(k)] * len(sizes)
    else:
        ks = [int(x) for x in k]
        if len(ks) != len(sizes):
            raise ParameterError(f"give one eigenvector count per level ({len(sizes)}), "
                                 f"not {len(ks)}.")
    levels: list[HierarchyLevel] = []
    Lc, Mc = L, sp.diags(_as_mass_vector(M, n)).tocsr()
    P_total = sp.identity(n, format="csr")
    for li, (m_l, k_l) in enumerate(zip(sizes, ks)):
        k_l = k_l if k_l > 0 else max(1, round(m_l / 3))
        last = None
        for last in coarsen_iter(Lc, Mc, m_l, k_l, params):
            if callback is not None:
                callback(li, last)
        P_total = (last.P @ P_total).tocsr()
        levels.append(HierarchyLevel(m_l, k_l, last.L, last.M, last.G, last.K, last.P,
                                     P_total, last))
        Lc, Mc = last.L, last.M
    return levels
