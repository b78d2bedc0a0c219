"""Shared meshes and hierarchies of the multigrid tests (cached: built once per session)."""

from __future__ import annotations

import numpy as np
from algorithms.mesh.primitives import icosphere
from algorithms.multigrid import surface_multigrid


# both prolongations, always: the intrinsic one (self-parameterization) is the method of the
# thesis, the closest-point one its naive baseline
KINDS = ["closest_point", "intrinsic"]


def sphere_cap(subdivisions: int = 4, z_cut: float = 0.5):
    """The part of an icosphere below z = z_cut (a disk with one boundary loop)."""
    V, F = icosphere(subdivisions)
    keep = V[F].mean(axis=1)[:, 2] < z_cut
    F = F[keep]
    used = np.unique(F)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return V[used].copy(), remap[F]


def boundary_vertices(F) -> np.ndarray:
    from algorithms.mesh.topology import boundary_edges

    return np.unique(boundary_edges(F).ravel())


_CACHE: dict = {}


def hierarchy(name: str, kind: str):
    """Cached hierarchies: 'sphere' (icosphere(4), 3 levels) and 'cap' (sphere cap, 3 levels)."""
    key = (name, kind)
    if key not in _CACHE:
        if name == "sphere":
            V, F = icosphere(4)
        elif name == "cap":
            V, F = sphere_cap(4)
        elif name == "sphere5":
            V, F = icosphere(5)
        else:
            raise KeyError(name)
        mn = 500 if name == "sphere5" else 100
        _CACHE[key] = (V, F, surface_multigrid(V, F, min_vertices=mn, prolongation=kind))
    return _CACHE[key]

