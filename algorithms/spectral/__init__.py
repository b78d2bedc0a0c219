"""Spectral coarsening (thesis ch. 7) and its metrics and baselines (DESIGN.md §5)."""

from .coarsen import (Clustering, CoarsenParams, CoarsenStep, HierarchyLevel, cluster_sparsity,
                      coarsen, coarsen_hierarchy, coarsen_iter, edge_distances,
                      energy_and_gradient, generalized_eigs, kmedoids_clustering, null_space,
                      project_constraint)
from .metrics import SpectralMetrics, c_diag_score, eigenvalue_errors, functional_map, spectral_metrics
from .shape_difference import (ShapeDifference, difference_driven_clustering,
                               modified_shape_difference, shape_difference_operator)

__all__ = ["Clustering", "CoarsenParams", "CoarsenStep", "HierarchyLevel", "cluster_sparsity",
           "coarsen", "coarsen_hierarchy", "coarsen_iter", "edge_distances",
           "energy_and_gradient", "generalized_eigs", "kmedoids_clustering", "null_space",
           "project_constraint", "SpectralMetrics", "c_diag_score", "eigenvalue_errors",
           "functional_map", "spectral_metrics", "ShapeDifference",
           "difference_driven_clustering", "modified_shape_difference",
           "shape_difference_operator"]
