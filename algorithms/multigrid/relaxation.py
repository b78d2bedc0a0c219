"""Relaxation of the V-cycle: Gauss-Seidel (serial) and multi-colour Gauss-Seidel (App. 8.9.1).

``GaussSeidel``
    The thesis's relaxation: lexicographic Gauss-Seidel, compiled with Numba
    (:mod:`algorithms.multigrid.kernels`). Without Numba (missing, or ``STYLIZE3D_NUMBA=0``) the
    same sweep runs in PyAMG's compiled ``gauss_seidel`` (same arithmetic, same result to
    round-off), one right-hand-side column at a time.
``MultiColorGaussSeidel``
    Gauss-Seidel in the order of a colouring of the matrix graph (Alg. 10: greedy, descending
    degree, move-to-back palette). Rows of one colour do not touch each other, so each colour is
    one vectorized update ``x_c += (b_c - A_c x) / diag_c``; it is the Gauss-Seidel method for
    the colour-permuted ordering, so it has the same fixed point. Compiled, a colour's rows run
    on Numba's threads (:func:`algorithms.multigrid.kernels.multicolor_sweeps`: the same bits
    for any thread count); without Numba, one SciPy sparse product per colour (the same result
    to round-off).

``BlockGaussSeidel`` (default of the solver; our addition, issue 10)
    Gauss-Seidel over small blocks of strongly coupled rows, each block solved exactly. Thin
    triangles make a few couplings huge: a needle (an edge split very near one end) joins its
    two close vertices with a cotangent weight 40x the usual one, a flat obtuse cap gives a
    large *positive* off-diagonal. Point Gauss-Seidel cannot smooth the error that is equal on
    such a pair and different from its neighbours (it shrinks by ``w / (w + s)`` per sweep), and
    no coarse level represents it either: the V-cycle rate went to 0.83 on a scan with a few
    hundred thin triangles. Rows ``i, j`` are strongly coupled when ``|a_ij| >= 0.5
    sqrt(a_ii a_jj)`` (1/6 between equilateral neighbours); pairs are merged strongest first into
    blocks of at most 8 rows (union-find); all other rows are blocks of one, so on a mesh without
    thin triangles this is plain Gauss-Seidel. Blocks go in index order of their first row.

Sweep directions. Pre-relaxation sweeps forward, post-relaxation backward (reverse row or
colour order): the V-cycle is then a symmetric operator, which :meth:`MultigridSolver.
aspreconditioner` needs for CG. (The thesis only says "Gauss-Seidel"; the direction is our choice.)
"""

from __future__ import annotations


import numpy as np
import scipy.sparse as sp

from ..compiled import KernelModule

__all__ = ["compiled_kernels", "set_compiled_kernels", "greedy_coloring", "is_valid_coloring",
           "GaussSeidel", "MultiColorGaussSeidel", "BlockGaussSeidel", "strong_blocks",
           "make_smoother", "SMOOTHERS"]

SMOOTHERS = ("block_gauss_seidel", "gauss_seidel", "multicolor")
STRONG_COUPLING = 0.5
MAX_BLOCK = 8

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
        self._kern = compiled_kernels()
        # the compiled sweep: rows by colour (empty colours dropped), 1 / diag per row
        self._cptr = np.concatenate([[0], np.cumsum([len(g[0]) for g in self.groups])]
                                    ).astype(np.int64)
        self._rows = (np.concatenate([g[0] for g in self.groups]).astype(np.int64)
                      if self.groups else np.zeros(0, dtype=np.int64))
        self._inv = np.zeros(n)
        self._inv[diag != 0] = 1.0 / diag[diag != 0]

    @property
    def n_colors(self) -> int:
        return len(self.groups)

    def relax(self, x: np.ndarray, b: np.ndarray, sweeps: int, backward: bool = False) -> None:
        """In place on ``x`` (n, d), C-contiguous, with right-hand side ``b`` (n, d)."""
        if sweeps <= 0:
            return
        if self._kern is not None and x.ndim == 2 and x.flags.c_contiguous:
            A = self.A
            self._kern.multicolor_sweeps(A.indptr, A.indices, A.data, self._inv, self._cptr,
                                         self._rows, x, np.ascontiguousarray(b, np.float64),
                                         int(sweeps), bool(backward))
            return
        groups = self.groups[::-1] if backward else self.groups
        for _ in range(int(sweeps)):
            for rows, Ac, inv in groups:
                x[rows] += (b[rows] - Ac @ x) * inv


def _merge_python(n, ri, rj, max_block):
    parent = np.arange(n)
    size = np.ones(n, dtype=np.int64)

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in zip(ri.tolist(), rj.tolist()):
        a, b = root(a), root(b)
        if a == b or size[a] + size[b] > max_block:
            continue
        if size[a] < size[b]:
            a, b = b, a
        parent[b] = a
        size[a] += size[b]
    return np.array([root(i) for i in range(n)], dtype=np.int64)


def strong_blocks(A, theta: float = STRONG_COUPLING, max_block: int = MAX_BLOCK):
    """Blocks of strongly coupled rows of ``A`` (see the module docstring).

    Returns
    -------
    bptr, bverts : block ``c`` holds rows ``bverts[bptr[c]:bptr[c+1]]``; blocks are ordered by
        their smallest row.
    """
    A = _csr(A)
    n = A.shape[0]
    d = np.sqrt(np.abs(A.diagonal()))
    C = A.tocoo()
    off = (C.row < C.col) & (C.data != 0)
    ri, rj, v = C.row[off].astype(np.int64), C.col[off].astype(np.int64), np.abs(C.data[off])
    den = d[ri] * d[rj]
    strong = v >= theta * den
    ri, rj = ri[strong], rj[strong]
    order = np.argsort(-(v[strong] / den[strong]), kind="stable")
    ri, rj = ri[order], rj[order]
    kern = compiled_kernels()
    root = (kern.merge_strong_pairs(n, ri, rj, int(max_block)) if kern is not None
            else _merge_python(n, ri, rj, int(max_block)))
    # blocks ordered by their smallest row, rows ascending inside a block
    first = np.full(n, n, dtype=np.int64)
    np.minimum.at(first, root, np.arange(n))
    order = np.lexsort((np.arange(n), first[root]))
    key = first[root][order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    bptr = np.r_[starts, n].astype(np.int64)
    return bptr, order.astype(np.int64)


class BlockGaussSeidel:
    """Gauss-Seidel over blocks of strongly coupled rows (see the module docstring).

    Parameters
    ----------
    A : (n, n) sparse symmetric positive (semi-)definite matrix.
    theta, max_block : strength threshold and largest block.

    Attributes
    ----------
    n_blocks : number of blocks; ``block_sizes`` their sizes.
    """

    name = "block_gauss_seidel"

    def __init__(self, A, theta: float = STRONG_COUPLING, max_block: int = MAX_BLOCK):
        self.A = _csr(A)
        self.bptr, self.bverts = strong_blocks(self.A, theta, max_block)
        sizes = np.diff(self.bptr)
        self.iptr = np.r_[0, np.cumsum(sizes ** 2)].astype(np.int64)
        inv = np.empty(int(self.iptr[-1]))
        diag = self.A.diagonal()
        one = sizes == 1
        r1 = self.bverts[self.bptr[:-1][one]]
        d1 = diag[r1]
        inv[self.iptr[:-1][one]] = np.where(d1 != 0, 1.0 / np.where(d1 != 0, d1, 1.0), 0.0)
        for c in np.flatnonzero(~one):
            rows = self.bverts[self.bptr[c]:self.bptr[c + 1]]
            B = self.A[rows][:, rows].toarray()
            # a singular block (a pure Neumann piece) gets its pseudo-inverse: still symmetric
            inv[self.iptr[c]:self.iptr[c + 1]] = np.linalg.pinv(B, hermitian=True).ravel()
        self.inv = inv
        self.block_sizes = sizes
        self._kern = compiled_kernels()

    @property
    def n_blocks(self) -> int:
        return len(self.block_sizes)

    def relax(self, x: np.ndarray, b: np.ndarray, sweeps: int, backward: bool = False) -> None:
        """In place on ``x`` (n, d), C-contiguous, with right-hand side ``b`` (n, d)."""
        if sweeps <= 0:
            return
        A = self.A
        if self._kern is not None:
            self._kern.block_gauss_seidel_sweeps(A.indptr, A.indices, A.data, self.bptr,
                                                 self.bverts, self.iptr, self.inv, x, b,
                                                 int(sweeps), bool(backward))
            return
        nb = self.n_blocks
        for _ in range(int(sweeps)):
            for t in range(nb):
                c = nb - 1 - t if backward else t
                rows = self.bverts[self.bptr[c]:self.bptr[c + 1]]
                r = b[rows] - A[rows] @ x
                m = len(rows)
                x[rows] += self.inv[self.iptr[c]:self.iptr[c + 1]].reshape(m, m) @ r


def make_smoother(kind: str, A, coloring: np.ndarray | None = None):
    """A smoother object for ``A`` of the given kind (see :data:`SMOOTHERS`)."""
    if kind == "block_gauss_seidel":
        return BlockGaussSeidel(A)
    if kind == "gauss_seidel":
        return GaussSeidel(A)
    if kind == "multicolor":
        return MultiColorGaussSeidel(A, coloring)
    from ..errors import ParameterError

    raise ParameterError(f"Unknown smoother {kind!r}; choose one of {', '.join(SMOOTHERS)}.")
