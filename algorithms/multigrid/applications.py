"""Applications of the surface multigrid solver (thesis §8.6, App. 8.9.5).

Data smoothing (Eq. 8.6, 8.16-8.17)
    ``x* = argmin alpha E_s(x) + (1 - alpha) int |x - f|^2``, discretized as
    ``(alpha Q + (1 - alpha) M) x = (1 - alpha) M f`` with ``M`` the lumped (barycentric) mass matrix
    and ``Q`` the matrix of the smoothness energy:

    * ``"dirichlet"``: ``Q = -L`` (positive semi-definite cotangent Laplacian),
    * ``"bilaplacian"``: ``Q = L M^-1 L`` (squared Laplacian, natural boundary conditions),
    * ``"hessian"``: the squared Hessian energy of Stein et al. 2020 (curved Hessian), from
      ``gpytoolbox.biharmonic_energy(..., bc="curved_hessian")`` (a pinned dependency; should it
      be missing, a :class:`ParameterError` says so). Not re-implemented here.

    :class:`DataSmoother` precomputes the Galerkin parts ``P^T Q P`` and ``P^T M P`` on every level
    (App. 8.9.5) **on one shared sparsity pattern**, so a new alpha costs one vector operation
    ``alpha q + (1 - alpha) m`` per level plus the smoother set-up and the small coarsest
    factorization. ``alpha`` lies in (0, 1); its useful range depends on the mesh's scale (the
    Dirichlet energy scales like length^0, the mass like length^2, the bilaplacian like length^-2).

    Bilaplacian solver (our addition; the thesis runs V-cycles on ``P^T A P`` of the fourth-order
    matrix and notes in §8.8 that linear prolongation converges poorly there). Default
    ``preconditioner="factored"``: CG on ``A`` preconditioned by ``S^-1 M S^-1`` with the
    second-order ``S = sqrt(alpha) (-L) + sqrt(1 - alpha) M``, each ``S^-1`` one V-cycle on the same
    hierarchy (``P^T L P`` precomputed too). Since ``A <= S M^-1 S <= 2 A`` this needs fewer
    iterations than V-cycles on the fourth-order Galerkin matrices (benchmarks/multigrid.py,
    rtol 1e-5, alpha 1e-6: 32 vs 40 CG steps at 933k vertices, 18 vs 23 at 233k). ``preconditioner="galerkin"`` is the thesis's way
    (with ``accel="cg"`` advised).

Mean curvature flow (Fig. 8.23)
    Not here: the one implementation of the smoothing flows is :func:`algorithms.smoothing.
    smooth_iter`; pass it ``multigrid=`` (a hierarchy of the input, reused by every step while
    the system changes) to solve each step with V-cycles.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..errors import ParameterError
from ..linalg import SPDSolver
from ..mesh.operators import cotangent_laplacian, cotangent_laplacian_psd, mass_matrix
from .hierarchy import SurfaceMultigrid, surface_multigrid
from .relaxation import greedy_coloring
from .solver import MultigridSolver, NotConvergedError, failure_reason, pcg_iterate

__all__ = ["ENERGIES", "SOLVERS", "smoothness_matrix", "DataSmoother", "AlignedPair",
           "choose_solver", "direct_fits_in_memory"]

ENERGIES = ("dirichlet", "bilaplacian", "hessian")
SOLVERS = ("auto", "multigrid", "direct")
#: ``solver="auto"``: the direct solver up to this many vertices, surface multigrid above.
#: Estimates, not a measured crossover: on koala (50k vertices, bilaplacian) CHOLMOD took 5.7 s
#: and multigrid 7.1 s plus a 3.7 s hierarchy, so one solve is cheaper direct at that size; the
#: factor's memory grows faster than the hierarchy's (5.9 GB for the bilaplacian at 933k).
AUTO_DIRECT_MAX = {"dirichlet": 150_000, "bilaplacian": 60_000, "hessian": 60_000}


def _available_memory() -> int:
    """Bytes of memory available now (Linux /proc/meminfo; 4 GiB when unknown)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30


def direct_fits_in_memory(n: int, energy: str) -> tuple[bool, int]:
    """Whether a Cholesky factor of the smoothing system of ``n`` vertices fits in half the
    available memory, and its estimated size in bytes (nested-dissection fill of a surface mesh,
    ~12 n log2 n non-zeros for a 1-ring matrix, 3 times that for the 2-ring bilaplacian and
    Hessian; 16 bytes per non-zero with the indices, an over-estimate on purpose)."""
    nnz = 12.0 * n * max(np.log2(max(n, 2)), 1.0) * (1.0 if energy == "dirichlet" else 3.0)
    need = int(16 * nnz)
    return need <= _available_memory() // 2, need


def choose_solver(n: int, energy: str) -> tuple[str, str]:
    """``solver="auto"``: ("direct" or "multigrid", a sentence saying why)."""
    limit = AUTO_DIRECT_MAX.get(energy, 60_000)
    if n <= limit:
        return "direct", (f"auto: direct solver ({n:,} vertices; up to {limit:,} a direct "
                          f"factorization is faster than building the multigrid hierarchy)")
    return "multigrid", (f"auto: surface multigrid ({n:,} vertices, more than {limit:,})")


def smoothness_matrix(V, F, energy: str = "dirichlet") -> sp.csr_matrix:
    """The positive semi-definite matrix ``Q`` of a smoothness energy (see the module docstring)."""
    if energy == "dirichlet":
        return cotangent_laplacian_psd(V, F)
    if energy == "bilaplacian":
        L = cotangent_laplacian(V, F)
        m = mass_matrix(V, F).diagonal()
        inv = np.where(m > 0, 1.0 / np.where(m > 0, m, 1.0), 0.0)
        Q = (L.T @ sp.diags(inv) @ L).tocsr()
        return ((Q + Q.T) * 0.5).tocsr()
    if energy == "hessian":
        try:
            import gpytoolbox
        except ImportError as exc:
            raise ParameterError(
                "The squared Hessian energy needs the optional package gpytoolbox (not "
                "installed). Use energy='bilaplacian' or 'dirichlet'.") from exc
        Q = gpytoolbox.biharmonic_energy(np.asarray(V, dtype=np.float64),
                                         np.asarray(F, dtype=np.int64), bc="curved_hessian")
        return sp.csr_matrix(Q)
    raise ParameterError(f"Unknown smoothness energy {energy!r}; choose one of "
                         f"{', '.join(ENERGIES)}.")


class AlignedPair:
    """Two sparse matrices stored on one (union) sparsity pattern: ``a X + b Y`` is a vector op."""

    def __init__(self, X, Y):
        X = sp.coo_matrix(X)
        Y = sp.coo_matrix(Y)
        n = X.shape
        rows = np.concatenate([X.row, Y.row])
        cols = np.concatenate([X.col, Y.col])
        zx = np.zeros(X.nnz)
        zy = np.zeros(Y.nnz)
        Xc = sp.csr_matrix((np.concatenate([X.data, zy]), (rows, cols)), shape=n)
        Yc = sp.csr_matrix((np.concatenate([zx, Y.data]), (rows, cols)), shape=n)
        Xc.sum_duplicates()
        Yc.sum_duplicates()
        if not (np.array_equal(Xc.indptr, Yc.indptr) and np.array_equal(Xc.indices, Yc.indices)):
            raise RuntimeError("sparsity patterns could not be aligned")  # pragma: no cover
        self.indptr, self.indices = Xc.indptr, Xc.indices
        self.x, self.y = Xc.data, Yc.data
        self.shape = n

    def combine(self, a: float, b: float) -> sp.csr_matrix:
        return sp.csr_matrix((a * self.x + b * self.y, self.indices, self.indptr), shape=self.shape)

    def pattern(self) -> sp.csr_matrix:
        return sp.csr_matrix((np.ones_like(self.x), self.indices, self.indptr), shape=self.shape)


class DataSmoother:
    """Smooth signals on a mesh for any alpha, reusing one multigrid hierarchy (App. 8.9.5).

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64 the mesh.
    energy : "dirichlet", "bilaplacian" or "hessian" (optional, see the module docstring).
    solver : "multigrid" (V-cycles on the precomputed hierarchy), "direct" (a new Cholesky
        factorization per alpha: CHOLMOD when available, else SuperLU; the peer of the thesis)
        or "auto" (:func:`choose_solver`: by size and energy; ``auto_reason`` says which).
    mg : an existing :class:`SurfaceMultigrid` of this mesh (built with defaults when omitted and
        ``solver="multigrid"``).
    smoother, presmooth, postsmooth : relaxation of the V-cycle.
    """

    def __init__(self, V, F, energy: str = "dirichlet", solver: str = "multigrid",
                 mg: SurfaceMultigrid | None = None, smoother: str = "block_gauss_seidel",
                 presmooth: int = 2, postsmooth: int = 2):
        if solver not in SOLVERS:
            raise ParameterError(f"Unknown solver {solver!r}; choose 'auto', 'multigrid' or "
                                 f"'direct'.")
        self.auto_reason = None
        if solver == "auto":
            solver, self.auto_reason = choose_solver(len(V), energy)
        t = time.perf_counter()
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.F = np.ascontiguousarray(F, dtype=np.int64)
        self.energy = energy
        self.solver_kind = solver
        self.Q = smoothness_matrix(self.V, self.F, energy)
        self.M = mass_matrix(self.V, self.F).tocsr()
        self.smoother, self.presmooth, self.postsmooth = smoother, presmooth, postsmooth
        self.mg = None
        self.pairs: list[AlignedPair] = []
        self.lap_pairs: list[AlignedPair] = []
        self.colorings = self.lap_colorings = None
        if solver == "multigrid":
            self.mg = mg if mg is not None else surface_multigrid(self.V, self.F)
            if self.mg.n_vertices != len(self.V):
                raise ParameterError("The multigrid hierarchy was built on another mesh "
                                     f"({self.mg.n_vertices:,} vertices, this one has "
                                     f"{len(self.V):,}).")
            Qh, Mh = self.Q, self.M
            Lh = self.L = cotangent_laplacian_psd(self.V, self.F)
            self.pairs.append(AlignedPair(Qh, Mh))
            bilap = energy == "bilaplacian"
            if bilap:
                self.lap_pairs.append(AlignedPair(Lh, Mh))
            for P in self.mg.prolongations:
                PT = P.T.tocsr()
                Qh = (PT @ (Qh @ P)).tocsr()
                Mh = (PT @ (Mh @ P)).tocsr()
                self.pairs.append(AlignedPair(Qh, Mh))
                if bilap:
                    Lh = (PT @ (Lh @ P)).tocsr()
                    self.lap_pairs.append(AlignedPair(Lh, Mh))
            if smoother == "multicolor":
                self.colorings = [greedy_coloring(p.pattern()) for p in self.pairs[:-1]]
                if bilap:
                    self.lap_colorings = [greedy_coloring(p.pattern()) for p in self.lap_pairs[:-1]]
        self.precompute_seconds = time.perf_counter() - t

    def system(self, alpha: float) -> sp.csr_matrix:
        """The finest system matrix ``alpha Q + (1 - alpha) M``."""
        return (alpha * self.Q + (1.0 - alpha) * self.M).tocsr()

    def smooth(self, f, alpha: float, *, rtol: float = 1e-5, maxiter: int = 100,
               x0=None, accel: str | None = "cg", callback=None,
               preconditioner: str = "factored") -> tuple[np.ndarray, dict]:
        """Smooth ``f`` ((n,) or (n, d)) with parameter ``alpha`` in (0, 1).

        Returns
        -------
        u : the smoothed signal, shaped like ``f``.
        info : dict with ``seconds`` (total), ``setup_seconds`` (matrices + smoother + coarse
            factor, or the factorization for "direct"), ``solve_seconds``, ``cycles``,
            ``residuals`` (absolute norms, initial first; empty for "direct").
            The iterations start from ``x0`` (default: zero, as SciPy and PyAMG; starting from
            ``f`` looks natural but its residual ``(1-alpha) M f - A f`` is dominated by the
            noise that ``Q`` amplifies, 1e2-1e5 times ``||b||``, so it needs more iterations). ``accel="cg"``
            (default): CG preconditioned by the V-cycle (Dirichlet on camelhead 22 -> 10
            iterations, on a scan with thin triangles 96 -> 18; ``None``: plain V-cycles, the
            thesis; see :meth:`MultigridSolver.solve`). ``callback(u)`` is called after each cycle.
            ``preconditioner`` (bilaplacian only): "factored" (default; CG preconditioned by
            two V-cycles of the second-order ``sqrt(alpha)(-L) + sqrt(1-alpha) M``, see
            :meth:`_smooth_factored`; ``accel`` is ignored) or "galerkin" (V-cycles on the
            Galerkin hierarchy of the fourth-order matrix itself, as in the thesis).
        """
        alpha = float(alpha)
        if not 0.0 < alpha < 1.0:
            raise ParameterError(f"alpha must lie strictly between 0 and 1 (got {alpha}).")
        f = np.asarray(f, dtype=np.float64)
        if f.shape[0] != len(self.V):
            raise ParameterError(f"The signal has {f.shape[0]} values; the mesh has "
                                 f"{len(self.V):,} vertices.")
        t0 = time.perf_counter()
        rhs = (1.0 - alpha) * (self.M @ f)
        if self.solver_kind == "direct":
            return self._direct(rhs, alpha, t0)
        if self.energy == "bilaplacian" and preconditioner == "factored":
            return self._smooth_factored(f, alpha, rhs, rtol, maxiter, x0, callback, t0)
        if preconditioner not in ("galerkin", "factored"):
            raise ParameterError(f"Unknown preconditioner {preconditioner!r}; use 'galerkin' or "
                                 f"'factored'.")
        mats = [p.combine(alpha, 1.0 - alpha) for p in self.pairs]
        s = MultigridSolver(mats, self.mg.prolongations, smoother=self.smoother,
                            presmooth=self.presmooth, postsmooth=self.postsmooth,
                            colorings=self.colorings)
        t1 = time.perf_counter()
        u = s.solve(rhs, x0=x0, rtol=rtol, maxiter=maxiter, accel=accel,
                    callback=callback)
        t2 = time.perf_counter()
        info = dict(seconds=t2 - t0, setup_seconds=t1 - t0, solve_seconds=t2 - t1,
                    cycles=s.last_info["cycles"], residuals=s.last_info["residuals"],
                    converged=s.last_info["converged"], method="galerkin",
                    stop=s.last_info.get("stop"))
        self.last_solver = s
        return u, info

    def _direct(self, rhs, alpha, t0):
        s = SPDSolver(self.system(alpha))  # CHOLMOD when installed, else SuperLU
        t1 = time.perf_counter()
        u = s.solve(rhs)
        t2 = time.perf_counter()
        return u, dict(seconds=t2 - t0, setup_seconds=t1 - t0, solve_seconds=t2 - t1,
                       cycles=0, residuals=[], backend=s.backend, converged=True,
                       stop="converged", solver="direct")

    def smooth_checked(self, f, alpha: float, *, rtol: float = 1e-5, maxiter: int = 100,
                       x0=None, callback=None, fallback: bool = True,
                       preconditioner: str = "factored") -> tuple[np.ndarray, dict]:
        """:meth:`smooth` that never returns an unconverged result.

        When the multigrid iteration stops before ``rtol`` (too many cycles, a growing or
        stalled residual), the system is solved by the direct solver instead if ``fallback``
        and its factor fits in memory (:func:`direct_fits_in_memory`); ``info["fallback"]``
        then says so in a sentence. Otherwise :class:`NotConvergedError` is raised with a plain
        message. ``info["solver"]`` is the solver whose result is returned.
        """
        u, info = self.smooth(f, alpha, rtol=rtol, maxiter=maxiter, x0=x0, callback=callback,
                              preconditioner=preconditioner)
        info.setdefault("solver", self.solver_kind)
        if self.solver_kind == "direct" or info.get("converged"):
            return u, info
        res = info.get("residuals") or [1.0]
        relres = res[-1] / res[0] if res[0] > 0 else float("nan")
        what = {"maxiter": f"it did not reach the tolerance {rtol:g} in {info['cycles']} "
                           f"iterations",
                "diverged": "the residual grew (the iteration diverged)",
                "stalled": "the residual stopped decreasing",
                "breakdown": "the iteration broke down (the preconditioned system is not "
                             "positive definite)"}.get(info.get("stop"), "it did not converge")
        reason = (f"Multigrid stopped after {info['cycles']} iterations at relative residual "
                  f"{relres:.2g}: {what}")
        fits, need = direct_fits_in_memory(len(self.V), self.energy)
        if fallback and fits:
            t0 = time.perf_counter()
            rhs = (1.0 - float(alpha)) * (self.M @ np.asarray(f, dtype=np.float64))
            u, dinfo = self._direct(rhs, float(alpha), t0)
            dinfo.update(fallback=f"{reason}; solved with the direct solver instead.",
                         multigrid_cycles=info["cycles"], multigrid_residuals=res,
                         multigrid_stop=info.get("stop"),
                         seconds=info["seconds"] + dinfo["seconds"])
            return u, dinfo
        hint = ("The direct solver needs about "
                f"{need / 2**30:.1f} GiB here, more than half the free memory"
                if fallback and not fits else "Use the direct solver (--solver direct, or Solver: "
                "direct in the app)")
        raise NotConvergedError(f"{reason}. Nothing was changed. {hint}; a smaller alpha or a "
                                f"cleaned mesh also helps.")

    def _smooth_factored(self, f, alpha, rhs, rtol, maxiter, x0, callback, t0):
        """Bilaplacian by CG preconditioned with ``S^-1 M S^-1``, ``S = sqrt(a) (-L) + sqrt(1-a) M``.

        ``S M^-1 S = alpha L M^-1 L + (1 - alpha) M + 2 sqrt(alpha (1 - alpha)) (-L)`` lies between
        ``A`` and ``2 A`` (the cross term is at most the sum of the other two), so with exact
        inverses CG needs a mesh-independent number of steps; each ``S^-1`` is one V-cycle of a
        second-order (1-ring) system on the same hierarchy, Galerkin parts precomputed.
        """
        a, c = np.sqrt(alpha), np.sqrt(1.0 - alpha)
        # one more sweep each side than the V-cycle settings (3+3 by default): camelhead,
        # alpha 1e-3, 32 -> 25 CG steps for the same time
        S = MultigridSolver([p.combine(a, c) for p in self.lap_pairs], self.mg.prolongations,
                            smoother=self.smoother, presmooth=self.presmooth + 1,
                            postsmooth=self.postsmooth + 1, colorings=self.lap_colorings)
        A = self.pairs[0].combine(alpha, 1.0 - alpha)
        m = self.M.diagonal()[:, None]

        def precondition(r):
            z = S.precondition(r)
            z *= m
            return S.precondition(z)

        shape = rhs.shape
        B = np.ascontiguousarray(rhs.reshape(rhs.shape[0], -1))
        X = (np.zeros(B.shape) if x0 is None
             else np.array(x0, dtype=np.float64).reshape(B.shape))
        t1 = time.perf_counter()
        nb = float(np.sqrt(np.einsum("ij,ij->", B, B)))
        R = B - A @ X
        hist = [float(np.sqrt(np.einsum("ij,ij->", R, R)))]
        converged = hist[0] <= rtol * nb
        stop = "converged" if converged else "maxiter"
        k = 0
        if not converged:
            it = pcg_iterate(A, B, X, precondition)
            while k < int(maxiter):
                hist.append(next(it))
                k += 1
                if callback is not None:
                    callback(X.reshape(shape).copy())
                if hist[-1] <= rtol * nb:
                    converged = True
                    stop = "converged"
                    break
                why = failure_reason(hist, "cg")
                if why is not None:
                    stop = why
                    break
        t2 = time.perf_counter()
        info = dict(seconds=t2 - t0, setup_seconds=t1 - t0, solve_seconds=t2 - t1, cycles=k,
                    vcycles=2 * k + 1, residuals=hist, converged=converged, method="factored",
                    stop=stop)
        self.last_solver = S
        return X.reshape(shape), info
