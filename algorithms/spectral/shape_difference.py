"""Difference-driven coarsening with the modified shape difference operator (thesis 7.4.3, App. 7.6.4).

Given a reference mesh R and deformed versions D (same connectivity, vertex i of R corresponds to
vertex i of D), we build

* the functional map C (k_D x k) from functions on R to functions on D in the Laplace bases:
  ``C = Phi_D^T M_D Phi_R`` (the identity point map written in M-orthonormal eigenbases);
* the area-based shape difference of Rustamov et al. 2013 (option 2): ``A = C^T C`` (k x k);
* the *modified* shape difference ``A~ = (I - A)^T (I - A)`` (expansion and shrinking alike);
* its pull-back to the vertices, ``A~orig = Phi_R A~ Phi_R^T``, evaluated only on the mesh edges
  (the dense n x n matrix is never formed);
* an operator for the combinatorial coarsening whose off-diagonal entries are
  ``-L_ij = 1 / A~orig_ij`` on every edge (App. 7.6.4: "the inverse of the off-diagonal
  components ... as the -L_ij"), with zero row sums (so it is a PSD graph Laplacian), and the
  reference mass ``M_R``.

Edge distances of :func:`~algorithms.spectral.coarsen.edge_distances` are then proportional to
``A~orig_ij``: where the shapes differ, nodes are far apart and k-medoids puts more roots.

Choices the thesis leaves open (documented and tested here):

* ``k_deformed`` (rows of C) defaults to 2 k: a rectangular, "wide" functional map as in App.
  7.6.5, so that truncating the deformed basis does not read as area loss everywhere.
* ``A~orig_ij`` may be zero or negative on some edges (the pulled-back kernel is not positive
  entrywise); such entries, and all entries, are floored at ``floor`` times the largest edge
  value before inverting, which bounds the density contrast between deformed and rigid parts
  (default 1e-2, i.e. at most 100 times longer edges where the shapes differ most).
* Identical shapes (``||A~|| < 1e-10``) give uniform edge weights (plain graph Laplacian).
* Several deformed shapes combine by the element-wise maximum of their ``A~orig`` edge values
  (thesis Fig. 7.24).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import ParameterError
from .coarsen import Clustering, generalized_eigs, kmedoids_clustering
from .operators import cotangent_operator

__all__ = ["ShapeDifference", "modified_shape_difference", "shape_difference_operator",
           "difference_driven_clustering"]


@dataclass
class ShapeDifference:
    """Result of :func:`shape_difference_operator`."""

    L: sp.csr_matrix            # (n, n) PSD graph Laplacian, -L_ij = 1 / A~orig_ij on edges
    M: sp.csr_matrix            # (n, n) reference mass
    edge_values: np.ndarray     # (#E,) A~orig on the edges (max over the deformed shapes)
    edges: np.ndarray           # (#E, 2) i < j
    A_modified: list            # one (k, k) modified shape difference per deformed shape


def modified_shape_difference(C: np.ndarray) -> np.ndarray:
    """``(I - C^T C)^T (I - C^T C)`` for a functional map C (k_D x k) from R to D."""
    C = np.asarray(C, float)
    A = C.T @ C
    D = np.eye(A.shape[0]) - A
    return D.T @ D


def _edges_of(L: sp.spmatrix) -> np.ndarray:
    U = sp.triu(sp.csr_matrix(L), k=1).tocoo()
    E = np.c_[U.row, U.col].astype(np.int64)
    return E[np.lexsort((E[:, 1], E[:, 0]))]


def shape_difference_operator(V_ref, F, V_deformed, k: int = 50, *, k_deformed: int | None = None,
                              floor: float = 1e-2) -> ShapeDifference:
    """Modified shape difference operator of a reference mesh and deformed copies of it.

    Parameters
    ----------
    V_ref : (n, 3) reference vertices; F : (f, 3) faces shared by every shape.
    V_deformed : (n, 3) array or a list of them (same connectivity, same vertex order).
    k : number of reference eigenvectors (size of A~).
    k_deformed : eigenvectors on each deformed shape (rows of C); default 2 k.
    floor : relative floor of A~orig before inversion, in (0, 1].

    Returns
    -------
    :class:`ShapeDifference` whose ``(L, M)`` feed :func:`kmedoids_clustering`.
    """
    V_ref = np.asarray(V_ref, float)
    F = np.asarray(F, np.int64)
    Vds = [np.asarray(V_deformed, float)] if np.ndim(V_deformed) == 2 else \
        [np.asarray(v, float) for v in V_deformed]
    n = len(V_ref)
    if not Vds:
        raise ParameterError("give at least one deformed shape.")
    for v in Vds:
        if v.shape != V_ref.shape:
            raise ParameterError(f"a deformed shape has {len(v)} vertices but the reference has "
                                 f"{n}; the shape difference needs the same connectivity and "
                                 "vertex order (a known point-to-point correspondence).")
    if not 0 < floor <= 1:
        raise ParameterError("the floor must be in (0, 1].")
    k = int(min(k, n - 2))
    kd = int(min(k_deformed or 2 * k, n - 2))
    Lr, Mr = cotangent_operator(V_ref, F)
    _, phi_r = generalized_eigs(Lr, Mr, k)
    E = _edges_of(Lr)
    vals = None
    mods = []
    for Vd in Vds:
        Ld, Md = cotangent_operator(Vd, F)
        _, phi_d = generalized_eigs(Ld, Md, kd)
        C = phi_d.T @ (Md @ phi_r)                   # (kd, k): R -> D, identity correspondence
        At = modified_shape_difference(C)
        mods.append(At)
        # A~orig_ij = Phi_R[i] A~ Phi_R[j]^T on the edges only
        PA = phi_r @ At
        v = np.einsum("ek,ek->e", PA[E[:, 0]], phi_r[E[:, 1]])
        vals = v if vals is None else np.maximum(vals, v)
    top = float(vals.max())
    # A~ is dimensionless (C^T C = I for an isometry): below 1e-10 the shapes do not differ
    # within the basis, and the inverse would only amplify round-off
    if max(np.linalg.norm(a, 2) for a in mods) < 1e-10 or not np.isfinite(top) or top <= 0:
        # identical shapes: no difference anywhere, fall back to uniform weights
        clipped = np.ones_like(vals)
    else:
        clipped = np.maximum(vals, floor * top)
    w = 1.0 / clipped
    W = sp.csr_matrix((np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                      shape=(n, n))
    L = (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()
    return ShapeDifference(L, sp.csr_matrix(Mr), vals, E, mods)


def difference_driven_clustering(V_ref, F, V_deformed, m: int, k: int = 50, *,
                                 k_deformed: int | None = None, floor: float = 1e-2,
                                 iterations: int = 20, seed: int = 0) -> Clustering:
    """Combinatorial coarsening (k-medoids roots and clusters) driven by the modified shape
    difference: roots concentrate where the deformed shapes differ from the reference.

    The shape-difference operator has the units of a graph Laplacian of a surface mass, so the
    edge distance uses p = 0, q = 2 (thesis 7.3.1)."""
    sd = shape_difference_operator(V_ref, F, V_deformed, k, k_deformed=k_deformed, floor=floor)
    return kmedoids_clustering(sd.L, sd.M, m, p=0.0, q=2.0, iterations=iterations, seed=seed)
