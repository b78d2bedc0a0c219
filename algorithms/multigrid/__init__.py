"""Surface multigrid via intrinsic prolongation (thesis ch. 8).

``mg = surface_multigrid(V, F)`` builds the geometry-only hierarchy once; ``mg.solver(A)`` builds
the Galerkin matrices of any matrix on that mesh and returns a :class:`MultigridSolver` with
``solve``, ``cycle_iter`` and ``aspreconditioner``. Applications (data smoothing with a cheap
change of alpha, mean curvature flow) are in :mod:`algorithms.multigrid.applications`.
"""

from ..mesh.selfparam import barycentric_prolongation
from .hierarchy import (PROLONGATIONS, SurfaceMultigrid,
                        closest_point_prolongation, surface_multigrid)
from .relaxation import SMOOTHERS, greedy_coloring, is_valid_coloring
from .solver import Cycle, MultigridSolver, galerkin_matrices, reduce_dirichlet

__all__ = [
    "PROLONGATIONS", "SMOOTHERS", "SurfaceMultigrid", "MultigridSolver", "Cycle",
    "surface_multigrid", "barycentric_prolongation", "closest_point_prolongation",
    "greedy_coloring", "is_valid_coloring", "galerkin_matrices", "reduce_dirichlet",
]
