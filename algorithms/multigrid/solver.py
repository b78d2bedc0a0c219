"""Galerkin multigrid V-cycle (thesis Alg. 8-9, App. 8.9.2) in the SciPy / PyAMG style.

``mg.solver(A)`` (see :meth:`SurfaceMultigrid.solver`) builds ``A_{h+1} = P_h^T A_h P_h`` on every
level, a smoother per level and a direct factorization of the coarsest matrix, and returns a
:class:`MultigridSolver`:

* ``solve(b, x0=None, rtol=1e-5, maxiter=100, callback=None, residuals=None, fixed_values=None)``
  runs V-cycles until ``||b - A x|| <= rtol ||b||`` (2-norm of the (reduced) system; Frobenius norm
  for several right-hand sides). The reference implementation stops on an absolute residual; the
  relative test is SciPy's and PyAMG's convention.
* ``cycle_iter(b, ...)`` is the same loop as a generator, one :class:`Cycle` per V-cycle (the GUI
  streams it and cancels by not asking for the next one).
* ``solve(..., accel="cg")`` wraps the V-cycle in preconditioned CG (PyAMG's ``accel``): plain
  V-cycles with linear prolongation converge slowly on fourth-order systems (bilaplacian; thesis
  §8.8 says so), CG recovers a steady rate there.
* ``aspreconditioner()`` is one V-cycle from zero as a ``LinearOperator`` (pre-sweeps forward,
  post-sweeps backward: a symmetric operator, usable by ``scipy.sparse.linalg.cg``).

Dirichlet conditions (App. 8.9.2). With ``fixed`` indices ``k`` and free indices ``u`` the finest
system is the reduced ``A_uu x_u = b_u - A_uk x_k``; the first prolongation keeps only the free rows,
``P_u = P[u, :]``. When many unknowns are fixed, some coarse columns of ``P_u`` are empty (every fine
vertex they interpolate is fixed) and ``P_u^T A_uu P_u`` would have zero rows and columns: those
columns are removed, together with the matching rows of the next prolongation. We repeat the test
on every level (the thesis does it once; removing rows of the next prolongation can empty some of
its columns in turn).

Neumann / natural boundaries need nothing: the cotangent Laplacian already has them. A singular
system (pure Neumann Laplacian) stays singular on every level; the coarsest factorization adds
``1e-12 * mean(diag)`` to the diagonal (the reference code adds 1e-12; we scale it so the shift
does not depend on the units) and right-hand sides must be compatible (sum to 0).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ParameterError, Stylize3DError
from ..linalg import SPDSolver
from .relaxation import SMOOTHERS, make_smoother

__all__ = ["MultigridSolver", "Cycle", "galerkin_matrices", "reduce_dirichlet", "pcg_iterate",
           "NotConvergedError", "failure_reason", "STOP_REASONS"]

COARSE_SHIFT = 1e-12
#: plain V-cycles: this many consecutive growing residuals mean divergence
GROWTH_CYCLES = 3
#: CG: no new smallest residual in this many steps means a stall
STALL_STEPS = 12
#: why an iteration stopped (``last_info["stop"]``)
STOP_REASONS = ("converged", "maxiter", "diverged", "stalled", "breakdown")


class NotConvergedError(Stylize3DError):
    """An iterative solve stopped before its tolerance: its result must not be used."""

    exit_code = 6


def failure_reason(hist: list, accel: str | None) -> str | None:
    """None while an iteration may go on, else why it must stop ("diverged", "stalled",
    "breakdown"), from the residual norms so far (initial first).

    Plain V-cycles contract the error every cycle when they work: ``GROWTH_CYCLES`` growing
    residuals in a row (or one above 1e3 times the initial) is divergence. CG's residual norm
    may rise now and then (it minimizes the energy norm of the error; on the bilaplacian the
    first step can raise it 1e4-fold), so, counting from the first step, a stall there is
    ``STALL_STEPS`` steps without a new smallest residual and a growth by 1e6 over the smallest
    is divergence. A non-finite value is a breakdown (the preconditioned system is not positive
    definite, see :func:`pcg_iterate`)."""
    r = hist[-1]
    if not np.isfinite(r):
        return "breakdown"
    if accel is None:
        if hist[0] > 0 and r > 1e3 * hist[0]:
            return "diverged"
        if len(hist) > GROWTH_CYCLES and all(hist[-k] > hist[-k - 1]
                                             for k in range(1, GROWTH_CYCLES + 1)):
            return "diverged"
        return None
    h = hist[1:]  # the first CG steps may raise the residual norm by 1e4 and more (bilaplacian)
    best = min(h)
    if best > 0 and r > 1e6 * best:
        return "diverged"
    if len(h) > STALL_STEPS and min(h[-STALL_STEPS:]) > min(h[:-STALL_STEPS]):
        return "stalled"
    return None


@dataclass
class Cycle:
    """State after one V-cycle (``iteration`` 1-based; ``residual`` relative to ``||b||``)."""

    iteration: int
    residual: float
    solver: "MultigridSolver"
    _x: np.ndarray
    _ctx: dict

    def solution(self) -> np.ndarray:
        """The current iterate as a full-size array (fixed values included); a fresh copy."""
        return self.solver._expand(self._x, self._ctx)


def reduce_dirichlet(prolongations: list, free: np.ndarray) -> tuple[list, list]:
    """Restrict the first prolongation to ``free`` rows and remove empty coarse columns.

    Returns (new prolongations, kept coarse indices per coarse level). The empty-column removal
    is repeated level by level (see the module docstring).
    """
    out = []
    kept_all = []
    rows = np.asarray(free, dtype=np.int64)
    for P in prolongations:
        Pu = sp.csr_matrix(P)[rows]
        Pu.eliminate_zeros()
        colmax = np.zeros(Pu.shape[1])
        np.maximum.at(colmax, Pu.indices, np.abs(Pu.data))
        keep = np.flatnonzero(colmax > 0)
        Pu = Pu[:, keep].tocsr() if keep.size < Pu.shape[1] else Pu
        out.append(Pu)
        kept_all.append(keep)
        rows = keep
    return out, kept_all


def galerkin_matrices(A, prolongations: list) -> list:
    """``[A, P_0^T A P_0, P_1^T (P_0^T A P_0) P_1, ...]`` as CSR matrices (sorted indices)."""
    mats = [sp.csr_matrix(A, dtype=np.float64)]
    for P in prolongations:
        P = sp.csr_matrix(P)
        Ac = (P.T.tocsr() @ (mats[-1] @ P)).tocsr()
        Ac.sort_indices()
        mats.append(Ac)
    return mats


def _norm(x: np.ndarray) -> float:
    """Frobenius norm without BLAS (a threaded BLAS dot was ~400x slower here on shared cores)."""
    v = x.reshape(-1)
    return float(np.sqrt(np.einsum("i,i->", v, v)))


def _as2d(b: np.ndarray) -> np.ndarray:
    b = np.asarray(b, dtype=np.float64)
    return np.ascontiguousarray(b.reshape(b.shape[0], -1))


def pcg_iterate(A, b: np.ndarray, x: np.ndarray,
                precondition: Callable[[np.ndarray], np.ndarray]) -> Iterator[float]:
    """Preconditioned conjugate gradients on ``A x = b``, in place on ``x`` ((n, d) arrays, one
    scalar recurrence per column); yields the (recursively updated) residual norm after each
    step. ``precondition(r)`` must be a symmetric positive definite operator. When it is not
    (or ``A`` is not), CG breaks down: a step with ``p^T A p <= 0`` or ``r^T z < 0`` yields NaN and
    leaves ``x`` as it was (callers stop on a non-finite residual)."""
    r = b - A @ x
    z = precondition(r)
    p = z.copy()
    rz = np.einsum("ij,ij->j", r, z)
    while True:
        Ap = A @ p
        pAp = np.einsum("ij,ij->j", p, Ap)
        if np.any(pAp < 0) or np.any(rz < 0) or not np.all(np.isfinite(pAp)):
            while True:
                yield float("nan")
        a = np.divide(rz, pAp, out=np.zeros_like(rz), where=pAp != 0)
        x += p * a
        r -= Ap * a
        yield _norm(r)
        z = precondition(r)
        rz_new = np.einsum("ij,ij->j", r, z)
        beta = np.divide(rz_new, rz, out=np.zeros_like(rz), where=rz != 0)
        p *= beta
        p += z
        rz = rz_new


class MultigridSolver:
    """Galerkin V-cycle solver on a fixed hierarchy (build with :meth:`SurfaceMultigrid.solver`).

    Attributes
    ----------
    matrices : list of CSR matrices, finest (the reduced system with Dirichlet conditions) first.
    prolongations : list of CSR matrices used between consecutive levels.
    n : size of the full system; ``free`` / ``fixed`` : index arrays into it.
    setup_seconds : time spent building Galerkin matrices, smoothers and the coarse factor.
    """

    def __init__(self, matrices: list, prolongations: list, *, n: int | None = None,
                 fixed=None, A_uk=None, smoother: str = "block_gauss_seidel", presmooth: int = 2,
                 postsmooth: int = 2, colorings: list | None = None,
                 coarse_backend: str = "superlu"):
        t = time.perf_counter()
        if smoother not in SMOOTHERS:
            raise ParameterError(f"Unknown smoother {smoother!r}; choose one of "
                                 f"{', '.join(SMOOTHERS)}.")
        if int(presmooth) < 0 or int(postsmooth) < 0:
            raise ParameterError("The number of relaxation sweeps cannot be negative.")
        self.matrices = [sp.csr_matrix(M) for M in matrices]
        self.prolongations = [sp.csr_matrix(P) for P in prolongations]
        self._restrictions = [P.T.tocsr() for P in self.prolongations]
        if len(self.prolongations) != len(self.matrices) - 1:
            raise ValueError("need one prolongation between consecutive matrices")
        n_u = self.matrices[0].shape[0]
        self.n = n_u if n is None else int(n)
        fixed = np.unique(np.asarray([] if fixed is None else fixed, dtype=np.int64))
        self.fixed = fixed
        mask = np.ones(self.n, dtype=bool)
        mask[fixed] = False
        self.free = np.flatnonzero(mask)
        if len(self.free) != n_u:
            raise ValueError("the finest matrix must be the free-free block")
        self.A_uk = A_uk
        self.smoother_kind = smoother
        self.presmooth, self.postsmooth = int(presmooth), int(postsmooth)
        self.smoothers = []
        for h, M in enumerate(self.matrices[:-1]):
            col = None if colorings is None else colorings[h]
            self.smoothers.append(make_smoother(smoother, M, col))
        Ac = self.matrices[-1]
        diag = Ac.diagonal()
        shift = COARSE_SHIFT * (float(np.mean(np.abs(diag))) if diag.size else 1.0)
        self._coarse = SPDSolver(Ac + shift * sp.identity(Ac.shape[0], format="csr"),
                                 backend=coarse_backend)
        self.setup_seconds = time.perf_counter() - t
        self.last_info: dict = {}

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_hierarchy(cls, mg, A, *, fixed=None, smoother="block_gauss_seidel", presmooth=2,
                       postsmooth=2, block=None):
        t = time.perf_counter()
        A = sp.csr_matrix(A, dtype=np.float64)
        b = 1 if block is None else int(block)
        if b < 1:
            raise ParameterError("block must be a positive number of unknowns per vertex.")
        n = A.shape[0]
        if A.shape != (n, n) or n != b * mg.n_vertices:
            raise ParameterError(
                f"The matrix is {A.shape[0]}x{A.shape[1]} but the mesh has {mg.n_vertices:,} "
                f"vertices" + (f" ({b} unknowns each)" if b > 1 else "") +
                "; build the hierarchy on the mesh the matrix comes from"
                + ("" if b > 1 or n % mg.n_vertices else
                   f", or pass block={n // mg.n_vertices} for a vector-valued system") + ".")
        Ps = mg.block_prolongations(block)
        fixed_arr = np.unique(np.asarray([] if fixed is None else fixed, dtype=np.int64))
        if fixed_arr.size and (fixed_arr.min() < 0 or fixed_arr.max() >= n):
            raise ParameterError(f"Some fixed indices lie outside 0..{n - 1}.")
        A_uk = None
        if fixed_arr.size:
            mask = np.ones(n, dtype=bool)
            mask[fixed_arr] = False
            free = np.flatnonzero(mask)
            if free.size == 0:
                raise ParameterError("Every unknown is fixed: there is nothing to solve.")
            A_u = A[free]
            A_uk = A_u[:, fixed_arr].tocsr()
            A0 = A_u[:, free].tocsr()
            Ps, _ = reduce_dirichlet(Ps, free)
        else:
            A0 = A
        mats = galerkin_matrices(A0, Ps)
        self = cls(mats, Ps, n=n, fixed=fixed_arr, A_uk=A_uk, smoother=smoother,
                   presmooth=presmooth, postsmooth=postsmooth)
        self.setup_seconds = time.perf_counter() - t
        return self

    # ------------------------------------------------------------------ V-cycle
    @property
    def n_levels(self) -> int:
        return len(self.matrices)

    def operator_complexity(self) -> float:
        return sum(M.nnz for M in self.matrices) / self.matrices[0].nnz

    def _vcycle(self, h: int, x: np.ndarray, b: np.ndarray) -> None:
        """One V-cycle on level ``h``, in place on ``x`` (n_h, d)."""
        if h == len(self.matrices) - 1:
            x[...] = self._coarse.solve(b).reshape(x.shape)
            return
        A = self.matrices[h]
        sm = self.smoothers[h]
        sm.relax(x, b, self.presmooth, backward=False)
        r = b - A @ x
        bc = np.ascontiguousarray(self._restrictions[h] @ r)
        xc = np.zeros_like(bc)
        self._vcycle(h + 1, xc, bc)
        x += self.prolongations[h] @ xc
        sm.relax(x, b, self.postsmooth, backward=True)

    def vcycle(self, x: np.ndarray, b: np.ndarray) -> np.ndarray:
        """One V-cycle on the (reduced) finest system; returns the new iterate."""
        x = _as2d(x).copy()
        self._vcycle(0, x, _as2d(b))
        return x

    # ------------------------------------------------------------------ solve
    def _prepare(self, b, x0, fixed_values):
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise ParameterError(f"The right-hand side has {b.shape[0]} rows; the system has "
                                 f"{self.n}.")
        shape = b.shape
        B = _as2d(b)
        d = B.shape[1]
        ctx = dict(shape=shape, d=d)
        if self.fixed.size:
            if fixed_values is None:
                xk = np.zeros((self.fixed.size, d))
            else:
                xk = np.asarray(fixed_values, dtype=np.float64).reshape(self.fixed.size, -1)
                if xk.shape[1] == 1 and d > 1:
                    xk = np.repeat(xk, d, axis=1)
                if xk.shape != (self.fixed.size, d):
                    raise ParameterError(f"fixed_values must have {self.fixed.size} rows "
                                         f"(one per fixed unknown), matching b's columns.")
            bu = np.ascontiguousarray(B[self.free] - self.A_uk @ xk)
            ctx["xk"] = xk
        else:
            bu = B
        if x0 is None:
            xu = np.zeros_like(bu)
        else:
            X0 = _as2d(x0)
            if X0.shape[0] == self.n:
                X0 = X0[self.free]
            if X0.shape[1] == 1 and d > 1:
                X0 = np.repeat(X0, d, axis=1)
            if X0.shape != bu.shape:
                raise ParameterError("x0 must have the shape of b.")
            xu = np.ascontiguousarray(X0, dtype=np.float64).copy()
        return bu, xu, ctx

    def _expand(self, xu: np.ndarray, ctx: dict) -> np.ndarray:
        if self.fixed.size:
            X = np.empty((self.n, ctx["d"]))
            X[self.free] = xu
            X[self.fixed] = ctx["xk"]
        else:
            X = xu.copy()
        return X.reshape(ctx["shape"])

    def _iterate(self, bu: np.ndarray, xu: np.ndarray, accel: str | None) -> Iterator[float]:
        """Update ``xu`` in place, one V-cycle (or one V-cycle-preconditioned CG step) per
        iteration; yields the absolute residual norm after each."""
        A = self.matrices[0]
        if accel is None:
            while True:
                self._vcycle(0, xu, bu)
                yield float(_norm(bu - A @ xu))
        if accel != "cg":
            raise ParameterError(f"Unknown acceleration {accel!r}; use None or 'cg'.")
        yield from pcg_iterate(A, bu, xu, self.precondition)

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """One V-cycle from zero on ``A z = r`` ((n_u, d) arrays); a fresh array."""
        z = np.zeros_like(r)
        self._vcycle(0, z, np.ascontiguousarray(r))
        return z

    def cycle_iter(self, b, x0=None, *, maxiter: int = 100, fixed_values=None,
                   accel: str | None = None) -> Iterator[Cycle]:
        """Iterate on ``A x = b``: one :class:`Cycle` (relative residual) per V-cycle (or per
        preconditioned CG step with ``accel="cg"``), up to ``maxiter``; stopping on a tolerance is
        the caller's choice (:meth:`solve` does it). Cancel by not asking for the next one."""
        bu, xu, ctx = self._prepare(b, x0, fixed_values)
        nb = float(_norm(bu))
        scale = nb if nb > 0 else 1.0
        it = self._iterate(bu, xu, accel)
        for k in range(1, int(maxiter) + 1):
            res = next(it) / scale
            yield Cycle(k, res, self, xu, ctx)

    def solve(self, b, x0=None, rtol: float = 1e-5, maxiter: int = 100,
              callback: Callable[[np.ndarray], None] | None = None, residuals: list | None = None,
              fixed_values=None, accel: str | None = None) -> np.ndarray:
        """Solve ``A x = b`` by V-cycles until ``||b - A x|| <= rtol ||b||`` or ``maxiter`` cycles.

        Parameters
        ----------
        b : (n,) or (n, d) right-hand side(s) of the full system.
        x0 : optional initial guess, full size (or free size).
        rtol : relative residual tolerance (on the reduced system with Dirichlet conditions).
        maxiter : maximum number of V-cycles (CG steps with ``accel="cg"``).
        callback : called with the current full iterate after each cycle.
        residuals : a list that receives the absolute residual norms, the initial one first
            (PyAMG's convention).
        fixed_values : (k,) or (k, d) values of the fixed unknowns (zero when omitted).
        accel : None (plain V-cycles, the thesis) or "cg" (CG preconditioned by one V-cycle per
            step, PyAMG's ``accel="cg"``; recommended for fourth-order systems such as the
            bilaplacian, where plain V-cycles with linear prolongation converge slowly).

        Returns
        -------
        x : the solution, shaped like ``b``. ``last_info`` holds cycles, residuals, converged
        and ``stop`` (one of :data:`STOP_REASONS`): the iteration stops early, unconverged, when
        the residual grows or stalls (:func:`failure_reason`). An unconverged result is not a
        solution; callers must check ``converged`` (the applications raise
        :class:`NotConvergedError` or fall back to a direct solve, saying so).
        """
        if rtol <= 0:
            raise ParameterError("rtol must be positive.")
        t = time.perf_counter()
        bu, xu, ctx = self._prepare(b, x0, fixed_values)
        A = self.matrices[0]
        nb = float(_norm(bu))
        hist = [float(_norm(bu - A @ xu))]
        converged = nb == 0 or hist[0] <= rtol * nb
        if nb == 0:
            xu[...] = 0.0
            hist[0] = 0.0
        k = 0
        stop = "converged" if converged else "maxiter"
        if not converged and int(maxiter) > 0:
            it = self._iterate(bu, xu, accel)
            while k < int(maxiter):
                hist.append(next(it))
                k += 1
                if callback is not None:
                    callback(self._expand(xu, ctx))
                converged = hist[-1] <= rtol * nb
                if converged:
                    stop = "converged"
                    break
                why = failure_reason(hist, accel)
                if why is not None:
                    stop = why
                    break
        if residuals is not None:
            residuals[:] = hist
        self.last_info = dict(cycles=k, residuals=hist, converged=bool(converged),
                              relative_residual=hist[-1] / nb if nb > 0 else 0.0,
                              seconds=time.perf_counter() - t, accel=accel, stop=stop)
        return self._expand(xu, ctx)

    def convergence_factor(self) -> float:
        """Geometric mean residual reduction per cycle of the last :meth:`solve`."""
        r = self.last_info.get("residuals", [])
        if len(r) < 2 or r[0] == 0:
            return 0.0
        return float((r[-1] / r[0]) ** (1.0 / (len(r) - 1)))

    def aspreconditioner(self) -> spla.LinearOperator:
        """One V-cycle from zero on the (reduced) finest system, as a LinearOperator."""
        n_u = self.matrices[0].shape[0]

        def matvec(r):
            r = np.asarray(r, dtype=np.float64)
            x = np.zeros((n_u, 1) if r.ndim == 1 else (n_u, r.shape[1]))
            self._vcycle(0, x, _as2d(r))
            return x.reshape(r.shape)

        return spla.LinearOperator((n_u, n_u), matvec=matvec, matmat=matvec, dtype=np.float64)

    def __repr__(self) -> str:
        sizes = " -> ".join(f"{M.shape[0]:,}" for M in self.matrices)
        return (f"MultigridSolver({self.n_levels} levels: {sizes}; {self.smoother_kind} "
                f"{self.presmooth}+{self.postsmooth}; operator complexity "
                f"{self.operator_complexity():.2f})")
