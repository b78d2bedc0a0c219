"""Spectral-preservation metrics: functional map (Eq. 7.1) and eigenvalue errors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .coarsen import generalized_eigs

__all__ = ["SpectralMetrics", "functional_map", "c_diag_score", "eigenvalue_errors",
           "spectral_metrics"]


@dataclass
class SpectralMetrics:
    c_diag_score: float          # mean |C_ii| / ||C_i,:||, 1 = perfect
    eig_rel_error_mean: float    # over the first k non-zero eigenvalues
    eig_rel_error_max: float
    C: np.ndarray                # (k, k) functional map
    lam_fine: np.ndarray
    lam_coarse: np.ndarray

    def as_dict(self) -> dict[str, float]:
        return {"c_diag_score": self.c_diag_score, "eig_rel_error_mean": self.eig_rel_error_mean,
                "eig_rel_error_max": self.eig_rel_error_max}


def functional_map(phi_coarse, M_coarse, P, phi_fine) -> np.ndarray:
    """C = Phi~^T M~ P Phi (k x k)."""
    return phi_coarse.T @ (M_coarse @ (P @ phi_fine))


def c_diag_score(C: np.ndarray, lam=None, rtol: float = 1e-6) -> float:
    """Sign-invariant diagonality: mean over rows i of |C_ii| / ||C_i,:||_2.

    With the fine eigenvalues ``lam`` (first k), rows of a repeated eigenvalue are scored as a
    block (thesis Fig. 7.10: with multiplicity C should be *block* diagonal; any rotation of the
    eigenvectors of one eigenvalue is as good as another): row i scores
    ||C_i,J|| / ||C_i,:|| with J the eigenvalues equal to lam_i within ``rtol`` (relative to
    the largest), and all the zero eigenvalues of an operator with several connected parts form
    one block. Without ``lam``, or with distinct eigenvalues, this is the plain diagonal score.
    """
    k = min(C.shape)
    C = np.asarray(C)
    rn = np.linalg.norm(C[:k], axis=1)
    rn[rn == 0] = 1.0
    if lam is None:
        return float(np.mean(np.abs(np.diag(C[:k, :k])) / rn))
    lam = np.asarray(lam, float)[:k]
    tol = rtol * max(np.abs(lam).max(), 1e-300)
    # group sorted eigenvalues whose neighbours differ by at most tol
    brk = np.r_[0, np.flatnonzero(np.diff(lam) > tol) + 1, len(lam)]
    num = np.empty(k)
    for a, b in zip(brk[:-1], brk[1:]):
        num[a:b] = np.linalg.norm(C[a:b, a:b], axis=1)
    return float(np.mean(num / rn))


def eigenvalue_errors(lam_fine, lam_coarse, k: int, zero_tol: float = 1e-8):
    """Mean and max |lam~ - lam| / lam over the first k non-zero eigenvalues of each side
    (NaN, NaN where either side has none: a coarse operator of one node per part)."""
    lf = np.asarray(lam_fine)
    lc = np.asarray(lam_coarse)
    scale = max(np.abs(lf).max(), 1e-300)
    nf = lf[np.abs(lf) > zero_tol * scale][:k]
    nc = lc[np.abs(lc) > zero_tol * scale][:k]
    kk = min(len(nf), len(nc))
    if kk == 0:
        return float("nan"), float("nan")
    rel = np.abs(nc[:kk] - nf[:kk]) / np.abs(nf[:kk])
    return float(rel.mean()), float(rel.max())


def spectral_metrics(L, M, L_coarse, M_coarse, P, k: int, *, fine_eigs=None) -> SpectralMetrics:
    """Functional-map diagonality and eigenvalue errors of a coarsening (L~, M~, P) of (L, M).

    ``fine_eigs=(lam, phi)`` reuses a fine eigendecomposition with at least k + nullity pairs.
    """
    Mf = M if sp.issparse(M) else sp.diags(np.asarray(M, float))
    Mc = M_coarse if sp.issparse(M_coarse) else sp.diags(np.asarray(M_coarse, float))
    from scipy.sparse import csgraph
    nnull = csgraph.connected_components(sp.csr_matrix(L), directed=False)[0]
    ke = k + nnull
    if fine_eigs is None or fine_eigs[1].shape[1] < ke:
        fine_eigs = generalized_eigs(L, Mf, ke)
    lam_f, phi_f = fine_eigs
    lam_c, phi_c = generalized_eigs(sp.csr_matrix(L_coarse), Mc, min(ke, L_coarse.shape[0] - 1))
    kk = min(k, phi_c.shape[1])
    C = functional_map(phi_c[:, :kk], Mc, P, phi_f[:, :kk])
    mean, mx = eigenvalue_errors(lam_f, lam_c, k)
    return SpectralMetrics(c_diag_score(C, lam_f[:kk]), mean, mx, C, np.asarray(lam_f),
                           np.asarray(lam_c))
