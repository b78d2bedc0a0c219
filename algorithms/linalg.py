"""Direct sparse solves shared by every method (prefactor once, solve many times).

``SPDSolver`` factors a sparse symmetric positive definite matrix once and solves for many
right-hand sides; ``fixed`` rows/columns are eliminated (Dirichlet conditions) by the reduced
system  A_ff x_f = b_f - A_fc x_c. Backends: CHOLMOD's supernodal Cholesky (through the
self-contained ``cholespy`` wheel; the default) and SciPy's SuperLU (COLAMD ordering); both are
exact direct solvers, so results agree to round-off.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["SPDSolver", "cholmod_available"]


def cholmod_available() -> bool:
    """True when CHOLMOD (the ``cholespy`` package) can be imported."""
    try:
        import cholespy  # noqa: F401
    except Exception:
        return False
    return True


class SPDSolver:
    """Prefactored solver for a sparse SPD matrix, optionally with fixed (Dirichlet) unknowns.

    Parameters
    ----------
    A : (n, n) sparse symmetric positive (semi-)definite matrix; positive definite once the
        ``fixed`` unknowns are removed.
    fixed : (k,) int indices of unknowns whose values are given at solve time (may be empty).
    backend : "auto" (CHOLMOD when cholespy is installed, else SuperLU), "cholmod" (CHOLMOD
        supernodal Cholesky; needs ``A_ff`` positive definite), "superlu", or "auto-once" for a
        matrix factored for a single solve: SuperLU (which releases Python's lock while it
        factors) in every process, so that the app, the command line and a study replay get
        the same bits.

    Notes
    -----
    ``solve(b, x_fixed)`` accepts ``b`` of shape (n,) or (n, d) and ``x_fixed`` of shape (k,) or
    (k, d); it returns the full solution with the fixed entries set to ``x_fixed``.
    """

    def __init__(self, A: sp.spmatrix, fixed: np.ndarray | None = None, backend: str = "auto"):
        A = sp.csc_matrix(A, dtype=np.float64)
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError(f"A must be square, got {A.shape}")
        self.n = n
        fixed = np.unique(np.asarray([] if fixed is None else fixed, dtype=np.int64))
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n):
            raise ValueError("fixed indices out of range")
        self.fixed = fixed
        free_mask = np.ones(n, dtype=bool)
        free_mask[fixed] = False
        self.free = np.flatnonzero(free_mask)
        # The fixed unknowns stay in place as decoupled identity rows: A_e = [A_ff 0; 0 I] in
        # the original order, so a solve needs no gather of the free rows and no scatter of the
        # solution (those two copies cost as much as the triangular solves on a 20k-vertex
        # mesh with one pinned vertex). The identity rows add no fill to the factor.
        if fixed.size:
            keep = sp.diags(free_mask.astype(np.float64))
            A_fc = (keep @ A[:, fixed]).tocsr()           # n x k, zero in the fixed rows
            # only the rows next to a fixed unknown are nonzero: b_f -= A_fc x_c touches those
            # (a 20k-vertex mesh with one pinned vertex: 7 rows instead of an n x 3 product)
            self._fc_rows = np.flatnonzero(np.diff(A_fc.indptr))
            self.A_fc = A_fc[self._fc_rows]
            A_e = (keep @ A @ keep + sp.diags((~free_mask).astype(np.float64))).tocsc()
            A_e.eliminate_zeros()  # our own matrix (the caller's is never modified)
        else:
            self.A_fc = None
            A_e = A
        self.A_e = A_e
        if backend == "auto-once":
            # a matrix factored for one solve (a new matrix every step): SuperLU, in every
            # process. CHOLMOD through cholespy keeps Python's lock while it factors (63 ms at
            # 14.6k vertices, 362 ms at 58k for mean curvature flow), which froze the desktop
            # app's window; SuperLU releases it. Same total time at <= 15k vertices (cMCF, 10
            # steps: armadillo 0.81 vs 0.86 s), 22 % slower at 58k. The choice once depended on
            # the process (SuperLU in the app, CHOLMOD elsewhere), so a study replay or the
            # command line got other last bits than the app's run and replay reported a
            # mismatch: a result must not depend on which process computes it.
            backend = "superlu"
        if backend == "auto":
            # CHOLMOD: 2.6x faster per ARAP iteration than SuperLU on igea (134k vertices)
            backend = "cholmod" if cholmod_available() else "superlu"
        self.backend = backend
        if backend == "cholmod":
            self._solve = _cholmod_factor(self.A_e)
        elif backend == "superlu":
            # The system is symmetric: a symmetric ordering (MMD on A^T+A) keeps the fill of a
            # Cholesky-like factorization; COLAMD is much faster to compute on big meshes.
            lu = spla.splu(self.A_e, permc_spec="COLAMD",
                           options=dict(SymmetricMode=True))
            self._solve = lu.solve
        else:
            raise ValueError(f"unknown backend {backend!r}")

    def solve(self, b: np.ndarray, x_fixed: np.ndarray | None = None) -> np.ndarray:
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise ValueError(f"b has {b.shape[0]} rows, expected {self.n}")
        rhs = np.array(b, dtype=np.float64, order="C")  # a fresh array, modified in place
        if self.fixed.size:
            if x_fixed is None:
                raise ValueError("x_fixed is required when the solver has fixed unknowns")
            x_fixed = np.asarray(x_fixed, dtype=np.float64).reshape((self.fixed.size,) + b.shape[1:])
            rhs[self._fc_rows] -= self.A_fc @ x_fixed
            rhs[self.fixed] = x_fixed
        x = np.asarray(self._solve(rhs)).reshape(b.shape)
        if self.fixed.size:
            x[self.fixed] = x_fixed  # exact (the identity rows give them to round-off)
        return x


def _cholmod_factor(A: sp.spmatrix):
    """CHOLMOD factor of an SPD matrix (cholespy); returns ``solve(b)`` for b of shape (n,) or (n, d)."""
    import cholespy

    A = sp.coo_matrix(A)
    n = A.shape[0]
    factor = cholespy.CholeskySolverD(n, A.row.astype(np.int32), A.col.astype(np.int32),
                                      np.ascontiguousarray(A.data, dtype=np.float64),
                                      cholespy.MatrixType.COO)

    def solve(b: np.ndarray) -> np.ndarray:
        b = np.ascontiguousarray(b, dtype=np.float64)
        x = np.empty_like(b)
        factor.solve(b, x)
        return x

    return solve
