"""Parameter sets of the surface multigrid (DESIGN.md §2: one definition for CLI, GUI and log).

Defaults are the thesis's (§8.5, App. 8.9.4): coarsen faces x0.25 per level down to >= 500
vertices, uniform mid-point collapse with intrinsic (self-parameterization) prolongation,
Gauss-Seidel with 2 pre- and 2 post-sweeps, tolerance 1e-5.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..params import param
from .applications import ENERGIES
from .hierarchy import PROLONGATIONS
from .relaxation import SMOOTHERS

__all__ = ["MultigridParams", "DataSmoothingParams"]


@dataclass(frozen=True)
class MultigridParams:
    """Hierarchy and V-cycle settings."""

    ratio: float = param(
        0.25, label="Coarsening ratio", minimum=0.05, maximum=0.9, step=0.05, decimals=2,
        advanced=True,
        tooltip="Fraction of the triangles kept from one level to the next. Smaller values give "
                "fewer, cheaper levels but slower convergence.")
    min_vertices: int = param(
        500, label="Coarsest size", minimum=10, maximum=100000, step=100, advanced=True,
        tooltip="Stop coarsening before a level would have fewer vertices than this; the "
                "coarsest level is solved exactly.")
    strategy: str = param(
        "midpoint", label="Decimation", choices=("midpoint", "qslim"), advanced=True,
        tooltip="midpoint: uniform edge collapses (best for the solver). qslim: keeps the shape's "
                "appearance.")
    prolongation: str = param(
        "intrinsic", label="Prolongation", choices=PROLONGATIONS, advanced=True,
        tooltip="intrinsic: map vertices between levels through a self-parameterization (the "
                "method of the thesis). closest_point: the naive projection, for comparison.")
    smoother: str = param(
        "block_gauss_seidel", label="Relaxation", choices=SMOOTHERS, advanced=True,
        tooltip="block_gauss_seidel: Gauss-Seidel that solves strongly coupled vertices (thin "
                "triangles) together; plain Gauss-Seidel elsewhere. gauss_seidel: serial "
                "Gauss-Seidel (the thesis). multicolor: Gauss-Seidel by independent colour "
                "groups (vectorized).")
    presmooth: int = param(
        2, label="Pre-sweeps", minimum=0, maximum=10, step=1, advanced=True,
        tooltip="Relaxation sweeps before each coarse-grid correction.")
    postsmooth: int = param(
        2, label="Post-sweeps", minimum=0, maximum=10, step=1, advanced=True,
        tooltip="Relaxation sweeps after each coarse-grid correction.")
    rtol: float = param(
        1e-5, label="Tolerance", minimum=1e-12, maximum=1e-1, step=1e-5, decimals=12,
        log_scale=True,
        tooltip="Stop when the residual has shrunk by this factor relative to the right-hand "
                "side. 1e-3 is visually exact for most uses; smaller is more accurate.")
    maxiter: int = param(
        100, label="Max cycles", minimum=1, maximum=10000, step=10,
        tooltip="Stop after this many V-cycles even if the tolerance is not reached.")


@dataclass(frozen=True)
class DataSmoothingParams:
    """Data smoothing (Eq. 8.6)."""

    energy: str = param(
        "dirichlet", label="Smoothness energy", choices=ENERGIES,
        tooltip="dirichlet: penalizes gradients. bilaplacian: penalizes curvature of the signal, "
                "smoother results. hessian: squared Hessian, smooth like bilaplacian but without "
                "flattening the signal at open borders.")
    alpha: float = param(
        1e-3, label="Smoothness", minimum=1e-12, maximum=0.999999, step=1e-3, decimals=12,
        log_scale=True,
        tooltip="Between 0 and 1: larger values smooth more. The app and the command line "
                "apply it to the mesh scaled to unit area, so it does not depend on units: "
                "about 1e-4 to 1e-2 for dirichlet, 1e-7 to 1e-4 for bilaplacian.")
    solver: str = param(
        "auto", label="Solver", choices=("auto", "multigrid", "direct"),
        tooltip="auto: direct for small and medium meshes, multigrid for big ones (says which). "
                "multigrid: reuses the hierarchy, fast when alpha changes; falls back to the "
                "direct solver, saying so, if it does not converge. direct: a new Cholesky "
                "factorization for every alpha.")
