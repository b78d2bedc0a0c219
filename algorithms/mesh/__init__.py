"""Qt-free mesh core: reading/writing, validation and cleaning, topology, operators,
primitives and subdivision. Conventions: ``V`` is ``(n, 3) float64``, ``F`` is ``(m, 3) int64``.

The submodules are importable as ``algorithms.mesh.io``, ``.topology``, ``.operators``,
``.validate``, ``.primitives``, ``.subdivision`` and ``.samples``; the most used names are
re-exported here. Only ``io``, ``topology`` and ``validate`` (NumPy only) load with the
package; the others (and SciPy with them) load when a name of theirs is first used, so reading
and checking a mesh (``stylize3d info``) starts in a fraction of a second.
"""

from __future__ import annotations

import importlib

from . import io, topology, validate
from .io import (  # noqa: F401
    SUPPORTED_READ,
    SUPPORTED_WRITE,
    MeshData,
    file_filter,
    read_mesh,
    write_mesh,
)
from .topology import (  # noqa: F401
    boundary_edges,
    boundary_loops,
    connected_components,
    edge_flaps,
    euler_characteristic,
    face_adjacency,
    genus,
    halfedge_twins,
    halfedges,
    is_edge_manifold,
    is_manifold,
    is_vertex_manifold,
    nonmanifold_edges,
    nonmanifold_vertices,
    orient_consistently,
    unique_edges,
    vertex_adjacency,
    vertex_face_adjacency,
)
from .validate import (  # noqa: F401
    CleanResult,
    MeshIssue,
    MeshReport,
    clean_mesh,
    validate_mesh,
)

#: names re-exported from the submodules loaded on first use
_LAZY = {
    'barycentric_vertex_areas': 'operators',
    'bounding_box_diagonal': 'operators',
    'cotangent_laplacian': 'operators',
    'cotangent_laplacian_psd': 'operators',
    'denormalize': 'operators',
    'face_areas': 'operators',
    'face_normals': 'operators',
    'mass_matrix': 'operators',
    'normalize_unit_box': 'operators',
    'signed_volume': 'operators',
    'vertex_normals': 'operators',
    'cube': 'primitives',
    'dodecahedron': 'primitives',
    'grid': 'primitives',
    'icosahedron': 'primitives',
    'icosphere': 'primitives',
    'octahedron': 'primitives',
    'organic_sample': 'primitives',
    'platonic_solid': 'primitives',
    'tetrahedron': 'primitives',
    'torus': 'primitives',
    'SAMPLES_DIR': 'samples',
    'sample_path': 'samples',
    'loop_subdivide': 'subdivision',
    'midpoint_subdivide': 'subdivision',
    'CollapseRecord': 'decimate',
    'Decimation': 'decimate',
}
_SUBMODULES = ("operators", "primitives", "samples", "subdivision", "decimate")


__all__ = [
    # modules
    "io", "operators", "primitives", "samples", "subdivision", "topology", "validate",
    # io
    "MeshData", "read_mesh", "write_mesh", "SUPPORTED_READ", "SUPPORTED_WRITE", "file_filter",
    # validation
    "MeshIssue", "MeshReport", "CleanResult", "validate_mesh", "clean_mesh",
    # operators
    "face_areas", "face_normals", "vertex_normals", "barycentric_vertex_areas",
    "cotangent_laplacian", "cotangent_laplacian_psd", "mass_matrix", "signed_volume",
    "bounding_box_diagonal", "normalize_unit_box", "denormalize",
    # topology
    "halfedges", "unique_edges", "edge_flaps", "halfedge_twins", "vertex_adjacency",
    "vertex_face_adjacency", "face_adjacency", "boundary_edges", "boundary_loops",
    "connected_components", "nonmanifold_edges", "nonmanifold_vertices", "is_edge_manifold",
    "is_vertex_manifold", "is_manifold", "euler_characteristic", "genus", "orient_consistently",
    # primitives
    "tetrahedron", "cube", "octahedron", "icosahedron", "dodecahedron", "platonic_solid",
    "icosphere", "torus", "grid", "organic_sample",
    # subdivision
    "loop_subdivide", "midpoint_subdivide",
    # samples
    "SAMPLES_DIR", "sample_path",
]  # fmt: skip
__all__ += ["decimate", "Decimation", "CollapseRecord"]


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))
