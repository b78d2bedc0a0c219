"""Relaxation of the V-cycle: Gauss-Seidel (serial) and multi-colour Gauss-Seidel (App. 8.9.1).

``GaussSeidel``
    The thesis's relaxation: lexicographic Gauss-Seidel, compiled with Numba
    (:mod:`algorithms.multigrid.kernels`). Without Numba (missing, or ``STYLIZE3D_NUMBA=0``) the
    same sweep runs in PyAMG's compiled ``gauss_seidel`` (same arithmetic, same result to
    round-off), one right-hand-side column at a time.
``MultiColorGaussSeidel``
    Gauss-Seidel in the order of a colouring of the matrix graph (Alg. 10: greedy, descending
    degree, move-to-back palette). Rows of one colour do not touch each other, so each colour is
    one vectorized update ``x_c += (b_c - A_c x) / diag_c`` (SciPy sparse product); it is the
    Gauss-Seidel method for the colour-permuted ordering, so it has the same fixed point.

Sweep directions. Pre-relaxation sweeps forward, post-relaxation backward (reverse row or
colour order): the V-cycle is then a symmetric operator, which :meth:`MultigridSolver.
aspreconditioner` needs for CG. (The thesis only says "Gauss-Seidel"; the direction is our choice.)
"""

from __future__ import annotations


import numpy as np
import scipy.sparse as sp

from ..compiled import KernelModule

__all__ = ["compiled_kernels", "set_compiled_kernels", "greedy_coloring", "is_valid_coloring",
           "GaussSeidel", "MultiColorGaussSeidel", "make_smoother", "SMOOTHERS"]

SMOOTHERS = ("gauss_seidel", "multicolor")

_KERNELS = KernelModule("algorithms.multigrid.kernels")


def compiled_kernels():
    """The Numba kernels module, or None (Numba missing, ``STYLIZE3D_NUMBA=0``, or switched off)."""
    return _KERNELS.get()


def set_compiled_kernels(enabled: bool) -> bool:
    """Switch the compiled kernels on or off; returns the previous setting."""
    return _KERNELS.set(enabled)


def _csr(A) -> sp.csr_matrix:
    A = sp.csr_matrix(A, dtype=np.float64)
    A.sort_indices()
    return A


def greedy_coloring(A) -> np.ndarray:
    """Colour the graph of the off-diagonal non-zeros of ``A`` (thesis Alg. 10).

    Parameters
    ----------
    A : (n, n) sparse matrix with a symmetric sparsity pattern.

    Returns
    -------
    (n,) int64 colours ``0..k-1``; no two rows ``i != j`` with ``A[i, j] != 0`` share a colour.
    """
    A = _csr(A)
    n = A.shape[0]
    deg = np.diff(A.indptr)
    order = np.argsort(-deg, kind="stable").astype(np.int64)
    kern = compiled_kernels()
    if kern is not None:
        return kern.greedy_coloring(A.indptr, A.indices, order)
    # Plain Python fallback (same algorithm; slow on big meshes)
    color = np.full(n, -1, dtype=np.int64)
    palette: list[int] = []
    indptr, indices = A.indptr, A.indices
    for i in order.tolist():
        used = {int(color[j]) for j in indices[indptr[i]:indptr[i + 1]] if j != i and color[j] >= 0}
        for q, c in enumerate(palette):
            if c not in used:
                palette.append(palette.pop(q))
                break
        else:
            c = len(palette)
            palette.append(c)
        color[i] = c
    return color


def is_valid_coloring(A, color: np.ndarray) -> bool:
    """True when no off-diagonal non-zero of ``A`` joins two rows of the same colour."""
    C = sp.coo_matrix(A)
    off = C.row != C.col
    return not np.any(color[C.row[off]] == color[C.col[off]])


class GaussSeidel:
    """Serial Gauss-Seidel on a CSR matrix (Numba kernel; PyAMG's compiled sweep as fallback)."""

    name = "gauss_seidel"

    def __init__(self, A):
        self.A = _csr(A)
        self.diag = np.ascontiguousarray(self.A.diagonal())
        self._kern = compiled_kernels()
        # the kernels take SciPy's index arrays as they are (int32 or int64: one compiled
        # specialization each), no copies
        self._indptr = self.A.indptr
        self._indices = self.A.indices

    def relax(self, x: np.ndarray, b: np.ndarray, sweeps: int, backward: bool = False) -> None:
        """In place on ``x`` (n, d), C-contiguous, with right-hand side ``b`` (n, d)."""
        if sweeps <= 0:
            return
        if self._kern is not None:
            self._kern.gauss_seidel_sweeps(self._indptr, self._indices, self.A.data, self.diag,
                                           x, b, int(sweeps), bool(backward))
            return
        from pyamg.relaxation.relaxation import gauss_seidel

        for c in range(x.shape[1]):
            xc = np.ascontiguousarray(x[:, c])
            gauss_seidel(self.A, xc, np.ascontiguousarray(b[:, c]), iterations=int(sweeps),
                         sweep="backward" if backward else "forward")
            x[:, c] = xc


class MultiColorGaussSeidel:
    """Gauss-Seidel by colours (App. 8.9.1): one vectorized update per colour.

    Parameters
    ----------
    A : (n, n) sparse matrix.
    coloring : optional precomputed (n,) colours of A's graph (reused when only values change).
    """

    name = "multicolor"

    def __init__(self, A, coloring: np.ndarray | None = None):
        self.A = _csr(A)
        n = self.A.shape[0]
        self.coloring = greedy_coloring(self.A) if coloring is None else np.asarray(coloring)
        if self.coloring.shape != (n,):
            raise ValueError("coloring must have one colour per row")
        diag = self.A.diagonal()
        order = np.argsort(self.coloring, kind="stable")
        counts = np.bincount(self.coloring)
        bounds = np.concatenate([[0], np.cumsum(counts)])
        self.groups = []
        for c in range(len(counts)):
            rows = order[bounds[c]:bounds[c + 1]]
            if rows.size == 0:
                continue
            d = diag[rows]
            inv = np.zeros_like(d)
            inv[d != 0] = 1.0 / d[d != 0]
            self.groups.append((rows, self.A[rows], inv[:, None]))

    @property
    def n_colors(self) -> int:
        return len(self.groups)

    def relax(self, x: np.ndarray, b: np.ndarray, sweeps: int, backward: bool = False) -> None:
        groups = self.groups[::-1] if backward else self.groups
        for _ in range(int(sweeps)):
            for rows, Ac, inv in groups:
                x[rows] += (b[rows] - Ac @ x) * inv


def make_smoother(kind: str, A, coloring: np.ndarray | None = None):
    """A smoother object for ``A`` of the given kind (see :data:`SMOOTHERS`)."""
    if kind == "gauss_seidel":
        return GaussSeidel(A)
    if kind == "multicolor":
        return MultiColorGaussSeidel(A, coloring)
    from ..errors import ParameterError

    raise ParameterError(f"Unknown smoother {kind!r}; choose one of {', '.join(SMOOTHERS)}.")
