"""Qt-free mesh core: reading/writing, validation and cleaning, topology, operators,
primitives and subdivision. Conventions: ``V`` is ``(n, 3) float64``, ``F`` is ``(m, 3) int64``.

The submodules are importable as ``algorithms.mesh.io``, ``.topology``, ``.operators``,
``.validate``, ``.primitives``, ``.subdivision`` and ``.samples``; the most used names are
re-exported here.
"""

from __future__ import annotations

from . import io, operators, primitives, samples, subdivision, topology, validate
from .io import SUPPORTED_READ, SUPPORTED_WRITE, MeshData, file_filter, read_mesh, write_mesh
from .operators import (
    barycentric_vertex_areas,
    bounding_box_diagonal,
    cotangent_laplacian,
    cotangent_laplacian_psd,
    denormalize,
    face_areas,
    face_normals,
    mass_matrix,
    normalize_unit_box,
    signed_volume,
    vertex_normals,
)
from .primitives import (
    cube,
    dodecahedron,
    grid,
    icosahedron,
    icosphere,
    octahedron,
    organic_sample,
    platonic_solid,
    tetrahedron,
    torus,
)
from .samples import SAMPLES_DIR, sample_path
from .subdivision import loop_subdivide, midpoint_subdivide
from .topology import (
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
from .validate import CleanResult, MeshIssue, MeshReport, clean_mesh, validate_mesh

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

# decimation with recorded collapses (progressive meshes); ``decimate`` is the submodule, its
# function is ``decimate.decimate``
from . import decimate  # noqa: E402
from .decimate import CollapseRecord, Decimation  # noqa: E402

__all__ += ["decimate", "Decimation", "CollapseRecord"]
