"""Surface distances (METRO style, Cignoni et al. 1998) and the Table 4.2 protocol.

:func:`surface_distances` samples both surfaces -- every vertex plus ``samples`` points spread
uniformly by area (a fixed seed) -- and measures each sample's exact point-to-triangle distance
to the other surface (libigl's AABB tree). Reported, both in % of the bounding-box diagonal of the
reference mesh ``B``:

* ``hausdorff``: the symmetric Hausdorff distance, max of the two one-sided maxima;
* ``mean_distance``: the larger of the two one-sided area-weighted mean distances (METRO prints
  both one-sided means; we report the larger, like its symmetric Hausdorff).

Units of Table 4.2: the thesis prints numbers such as H 2.75 / M 0.73 for Loop without a unit;
METRO's own output is in model units, and these magnitudes on TOSCA shapes (hundreds of units
across) only make sense relative to the size -- we read them as % of the bounding-box diagonal
(our choice, stated in every report). Our numbers are therefore comparable in kind, not
digit-for-digit (different shapes and decimations).

:func:`evaluate_protocol` is the Table 4.2 protocol: QSlim (the project's
:func:`algorithms.mesh.decimate.decimate`) each mesh to a random vertex count in 350-450,
subdivide 2 levels with each method, measure against the original.

**Roughness** (issue 22: "never rougher than Loop"), two measures of a subdivided mesh against
another method's subdivision of the same input:

* :func:`planar_normal_deviation` -- on the *planar regions* of the input (coarse triangles whose
  neighbourhood, two rings of vertices, is flat within 0.5 degrees): the area-weighted RMS angle
  between the subdivided triangles' normals and their coarse triangle's normal, in degrees.
  Loop and butterfly keep such regions exactly planar (their stencils reach no further than two
  rings, and an affine combination of coplanar points is in the plane), so they score ~0; a
  dimple of any depth scores above. It is blind to sharp features (they are not planar), which
  an interpolating scheme rightly keeps.
* :func:`bending_energy` -- the discrete-shells bending energy ``sum_e 3 theta_e^2 |e|^2 /
  (A_1 + A_2)`` (Grinspun et al. 2003; ``theta_e`` the angle between the two face normals):
  scale invariant, and under refinement it tends to the integral of squared curvature, so
  dimples (curvature at the scale of an edge) raise it. For smooth shapes (the blob): a rougher
  surface has more of it. It also rises with kept sharp features, so it compares methods fairly
  only on smooth inputs.

And one against the original: :func:`normal_error`, the mean angle between the subdivided
surface's normals and the original's at the closest points. A dimple or a fold raises it; a
sharp feature kept where the original has one does not (issue 36: the reading of "rougher"
that does not count a kept crease as roughness).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..errors import ParameterError

__all__ = ["sample_surface", "surface_distances", "point_surface_distances", "evaluate_protocol",
           "coarsen_to_vertices", "coarsening_problem", "bending_energy", "planar_faces",
           "planar_normal_deviation", "normal_error"]


def _face_normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    a = np.linalg.norm(n, axis=1)
    return n / np.maximum(a, 1e-300)[:, None], 0.5 * a


def _interior_edges(F, n):
    """(face a, face b, vertex i, vertex j) of every interior edge, once."""
    from .topology import half_flaps

    hf = half_flaps(np.asarray(F, dtype=np.int64), n)
    keep = (hf.twin_face >= 0) & (hf.ijkl[:, 0] < hf.ijkl[:, 1])
    return hf.face[keep], hf.twin_face[keep], hf.ijkl[keep, 0], hf.ijkl[keep, 1]


def bending_energy(V, F, edges=None) -> float:
    """Discrete-shells bending energy ``sum_e 3 theta_e^2 |e|^2 / (A_1 + A_2)`` over the
    interior edges (module docstring); dimensionless. ``edges``: ``_interior_edges(F,
    len(V))`` when already known (two meshes with the same faces share it)."""
    return float(_bending_terms(V, F, edges)[1].sum())


def _bending_terms(V, F, edges=None) -> tuple[np.ndarray, np.ndarray]:
    """(face a of each interior edge, its term of :func:`bending_energy`)."""
    V = np.asarray(V, dtype=np.float64)
    N, A = _face_normals(V, np.asarray(F, dtype=np.int64))
    fa, fb, i, j = _interior_edges(F, len(V)) if edges is None else edges
    theta = np.arccos(np.clip((N[fa] * N[fb]).sum(axis=1), -1.0, 1.0))
    e2 = ((V[i] - V[j]) ** 2).sum(axis=1)
    return fa, 3.0 * theta ** 2 * e2 / np.maximum(A[fa] + A[fb], 1e-300)


def planar_faces(V, F, tolerance_degrees: float = 0.5, rings: int = 2) -> np.ndarray:
    """(m,) bool: triangles whose neighbourhood is planar -- no edge within ``rings`` vertex
    rings of them bends by more than ``tolerance_degrees``."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    N, _ = _face_normals(V, F)
    fa, fb, _, _ = _interior_edges(F, len(V))
    bent = (N[fa] * N[fb]).sum(axis=1) < np.cos(np.radians(tolerance_degrees))
    bad = np.zeros(len(F), dtype=bool)
    bad[fa[bent]] = True
    bad[fb[bent]] = True
    from .topology import half_flaps

    boundary = half_flaps(F, len(V)).twin_face < 0  # a boundary is not a planar interior
    bad[np.repeat(np.arange(len(F)), 3)[boundary]] = True
    for _ in range(rings):
        near = np.zeros(len(V), dtype=bool)
        near[F[bad].reshape(-1)] = True
        bad = near[F].any(axis=1)
    return ~bad


def planar_normal_deviation(V0, F0, V, F, levels: int, planar: np.ndarray | None = None
                            ) -> float:
    """Area-weighted RMS angle (degrees) between the triangles of a subdivision ``(V, F)`` of
    ``(V0, F0)`` (``levels`` 1-to-4 splits in the order of
    :func:`~algorithms.subdivision.topology.refine`: triangle ``t`` lies in coarse triangle
    ``t // 4**levels``) and their coarse triangle, over the planar coarse triangles
    (:func:`planar_faces`, or ``planar``). NaN when there are none."""
    V0 = np.asarray(V0, dtype=np.float64)
    F0 = np.asarray(F0, dtype=np.int64)
    planar = planar_faces(V0, F0) if planar is None else planar
    N0, _ = _face_normals(V0, F0)
    N, A = _face_normals(np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64))
    parent = np.arange(len(N)) // (4 ** int(levels))
    sel = planar[parent]
    if not sel.any():
        return float("nan")
    c = np.clip((N[sel] * N0[parent[sel]]).sum(axis=1), -1.0, 1.0)
    return float(np.degrees(np.sqrt(np.average(np.arccos(c) ** 2, weights=A[sel]))))


def sample_surface(V, F, count: int, seed: int = 0) -> np.ndarray:
    """``count`` points uniformly distributed by area on the triangles (plus nothing else)."""
    return _sample_faces(V, F, count, seed)[0]


def _sample_faces(V, F, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`sample_surface`'s points, the triangle each lies on)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    if count <= 0 or A.sum() <= 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    rng = np.random.default_rng(seed)
    f = rng.choice(len(F), size=count, p=A / A.sum())
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    b = np.stack([1 - r1, r1 * (1 - r2), r1 * r2], axis=1)
    return np.einsum("qi,qij->qj", b, V[F[f]]), f


def normal_error(VA, FA, VB, FB, samples: int = 200_000, seed: int = 0) -> float:
    """Mean angle, in degrees, between the surface ``A``'s normal and the normal of the
    reference ``B`` at the closest point, over ``samples`` points spread uniformly by area on
    ``A`` (a fixed seed; the triangle normals of both, libigl's closest triangle of ``B``).
    Dimples and folds of ``A`` turn its normals away from the reference's, so it rises with
    them; sharp features that ``A`` keeps where ``B`` has them do not raise it, as they raise
    the bending energy. Both meshes must be oriented alike (a subdivision of a coarse copy of
    ``B`` is)."""
    import igl

    VA = np.asarray(VA, dtype=np.float64)
    FA = np.asarray(FA, dtype=np.int64)
    VB = np.asarray(VB, dtype=np.float64)
    FB = np.asarray(FB, dtype=np.int64)
    P, f = _sample_faces(VA, FA, samples, seed)
    if not len(P):
        raise ParameterError("The mesh has no area to sample.")
    _, near, _ = igl.point_mesh_squared_distance(P, VB, FB)
    NA, _ = _face_normals(VA, FA)
    NB, _ = _face_normals(VB, FB)
    c = np.einsum("ij,ij->i", NA[f], NB[np.asarray(near, np.int64)])
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))).mean())


def point_surface_distances(P, V, F) -> np.ndarray:
    """(k,) distance of each point ``P`` (k, 3) to the surface ``(V, F)`` (libigl)."""
    import igl

    d2, _, _ = igl.point_mesh_squared_distance(np.ascontiguousarray(P), np.ascontiguousarray(V),
                                               np.ascontiguousarray(F, dtype=np.int64))
    return np.sqrt(np.maximum(d2, 0.0))


def surface_distances(VA, FA, VB, FB, samples: int = 200_000, seed: int = 0) -> dict:
    """Symmetric Hausdorff and mean surface distance between mesh A and reference mesh B.

    Returns a dict: ``hausdorff``, ``mean_distance`` (% of B's bounding-box diagonal),
    ``hausdorff_abs``, ``mean_abs`` (model units), ``a_to_b_mean``, ``b_to_a_mean`` (%),
    ``samples`` per surface, ``diagonal``.
    """
    VA = np.asarray(VA, dtype=np.float64)
    VB = np.asarray(VB, dtype=np.float64)
    diag = float(np.linalg.norm(VB.max(0) - VB.min(0)))
    if diag <= 0:
        raise ParameterError("The reference mesh has no extent.")
    PA = np.concatenate([VA, sample_surface(VA, FA, samples, seed)])
    PB = np.concatenate([VB, sample_surface(VB, FB, samples, seed + 1)])
    dab = point_surface_distances(PA, VB, FB)
    dba = point_surface_distances(PB, VA, FA)
    # area-uniform means over the random samples only (vertices are not area-uniform)
    mab = float(dab[len(VA):].mean()) if samples > 0 else float(dab.mean())
    mba = float(dba[len(VB):].mean()) if samples > 0 else float(dba.mean())
    h = float(max(dab.max(), dba.max()))
    m = max(mab, mba)
    pct = 100.0 / diag
    return {"hausdorff": h * pct, "mean_distance": m * pct, "hausdorff_abs": h, "mean_abs": m,
            "a_to_b_mean": mab * pct, "b_to_a_mean": mba * pct, "samples": int(samples),
            "diagonal": diag}


def coarsen_to_vertices(V, F, vertices: int):
    """QSlim (the project's decimation) to about ``vertices`` vertices.

    The decimation stops at a triangle count: by Euler's formula a mesh with ``n`` vertices,
    ``B`` border edges and Euler characteristic ``chi`` has ``2 n - B - 2 chi`` triangles, and
    the border of the coarse copy is taken to shrink like a length (``B sqrt(v / n)``). (The
    closed-mesh count ``F - 2 (n - v)`` alone left a terrain with a long border 5 vertices of
    150 asked for, and 10 open scan sheets 64.)"""
    from ..mesh.decimate import decimate
    from ..mesh.topology import boundary_edges

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    n = len(np.unique(F))
    B = len(boundary_edges(F))
    two_chi = 2 * n - B - len(F)
    v = int(vertices)
    target = int(round(2 * v - B * np.sqrt(min(1.0, v / max(n, 1))) - two_chi))
    target = int(min(len(F), max(4, target)))
    d = decimate(V, F, target, strategy="qslim")
    return d.V, d.F


#: :func:`coarsening_problem`'s limits: a coarse copy with fewer than this share of the vertices
#: asked for, a bounding box whose diagonal shrank below this share, or a surface area below
#: this share of the input's has collapsed. Set from what QSlim did on the validation corpus
#: when the face count was aimed at with the closed-mesh formula (before the border-aware
#: count of :func:`coarsen_to_vertices`): mountain (a terrain) and lato000 (10 open scan
#: sheets) kept 5 and 64 vertices whatever was asked; plane_holes at 150 vertices kept 41 % of
#: its area and 54 % of its diagonal; a brain cortex at 150 vertices keeps 72 % of its area
#: (its folds), a coarse copy that is still the shape, and passes.
COLLAPSE_VERTICES = 0.5
COLLAPSE_DIAGONAL = 0.9
COLLAPSE_AREA = 0.5


def coarsening_problem(V, F, Vc, Fc, asked: int) -> str:
    """'' when the coarse copy ``(Vc, Fc)`` of ``(V, F)`` (QSlim to ``asked`` vertices) is still
    the shape; otherwise what collapsed, in words: parts that vanished, far fewer vertices than
    asked (QSlim could not stop on a surface with borders), a shrunken bounding box, or lost
    surface area (see the ``COLLAPSE_*`` limits)."""
    from ..mesh.topology import connected_components

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    Vc = np.asarray(Vc, dtype=np.float64)
    Fc = np.asarray(Fc, dtype=np.int64)
    if len(Fc) == 0:
        return "no triangle was left"
    used, used_c = np.unique(F), np.unique(Fc)
    parts, _ = connected_components(F, len(V))
    parts_c, _ = connected_components(Fc, len(Vc))
    why = []
    if parts_c < parts:
        why.append(f"{parts - parts_c} of its {parts} parts vanished")
    if len(used_c) < COLLAPSE_VERTICES * min(int(asked), len(used)):
        why.append(f"only {len(used_c)} vertices and {len(Fc)} triangles were left")
    d0 = np.linalg.norm(V[used].max(0) - V[used].min(0))
    d1 = np.linalg.norm(Vc[used_c].max(0) - Vc[used_c].min(0))
    if d0 > 0 and d1 < COLLAPSE_DIAGONAL * d0:
        why.append(f"its size shrank to {100 * d1 / d0:.0f} %")
    _, a0 = _face_normals(V, F)
    _, a1 = _face_normals(Vc, Fc)
    if a0.sum() > 0 and a1.sum() < COLLAPSE_AREA * a0.sum():
        why.append(f"it lost {100 * (1 - a1.sum() / a0.sum()):.0f} % of its surface")
    return "; ".join(why)


def evaluate_protocol(meshes: Sequence[tuple[str, np.ndarray, np.ndarray]], subdividers: dict,
                      *, target_vertices=(350, 450), levels: int = 2, samples: int = 200_000,
                      seed: int = 0, progress: Callable[[float, str], None] | None = None
                      ) -> list[dict]:
    """Table 4.2: per mesh, QSlim to a random count in ``target_vertices``, subdivide ``levels``
    with every ``subdividers[name](V, F, levels) -> (V, F)``, measure against the original.

    Returns one dict per mesh: ``mesh``, ``vertices``, ``faces``, ``coarse_vertices``,
    ``methods`` {name: surface_distances(...)}.
    """
    lo, hi = int(target_vertices[0]), int(target_vertices[1])
    if not 4 <= lo <= hi:
        raise ParameterError(f"The target vertex range must be like 350-450 (got {lo}-{hi}).")
    rng = np.random.default_rng(seed)
    rows = []
    for t, (name, V, F) in enumerate(meshes):
        nv = int(rng.integers(lo, hi + 1))
        if len(V) <= nv:
            raise ParameterError(f"'{name}' has only {len(V)} vertices; it must be denser than "
                                 f"the coarse target ({lo}-{hi}).")
        Vc, Fc = coarsen_to_vertices(V, F, nv)
        row = {"mesh": name, "vertices": int(len(V)), "faces": int(len(F)),
               "coarse_vertices": int(len(Vc)), "methods": {}}
        for k, (mname, fn) in enumerate(subdividers.items()):
            if progress is not None:
                progress((t + k / len(subdividers)) / len(meshes), f"{name}: {mname}")
            Vs, Fs = fn(Vc, Fc, levels)
            row["methods"][mname] = surface_distances(Vs, Fs, V, F, samples, seed)
        rows.append(row)
    if progress is not None:
        progress(1.0, "done")
    return rows
