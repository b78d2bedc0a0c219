"""Recipe "Cubic": cubic stylization (thesis ch. 5) with what the user painted and placed.

Inputs from the document state: the λ scale field (``lambda_scale``, times ``params.lam``), the
fixed region (``fixed``), the plane region (``plane``, flattened along ``options["plane_axis"]``
at its mean coordinate), point handles and painted local cube frames (``frame_r*``, degrees).
Options: ``plane_axis`` (0-2), ``progressive`` (a ProgressiveParams dict, or None for every
triangle; a dict without ``finish``, saved before it existed, runs on the copy alone as it did
then), ``multigrid`` (bool: the multigrid global solve).
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import FIXED_FIELD, FRAME_FIELDS, LAMBDA_FIELD, PLANE_FIELD, Recipe, register


def frames_of(state, global_rotation: np.ndarray) -> np.ndarray | None:
    """(n, 3, 3) per-vertex cube frames from the painted angles, or None when none is painted;
    vertices without a painted frame use ``global_rotation``."""
    from algorithms.deform.cubic import rotation_from_degrees

    if FRAME_FIELDS[0] not in state.fields:
        return None
    ang = np.stack([np.asarray(state.fields.get(f, np.full(len(state.V), np.nan)))
                    for f in FRAME_FIELDS], axis=1)
    frames = np.broadcast_to(global_rotation, (len(ang), 3, 3)).copy()
    ok = np.isfinite(ang).all(axis=1)
    if ok.any():
        uniq, inv = np.unique(ang[ok], axis=0, return_inverse=True)
        mats = np.stack([rotation_from_degrees(*a) for a in uniq])
        frames[ok] = mats[inv.reshape(-1)]
    return frames


def constraints_of(state, plane_axis: int):
    """(fixed vertices, (handle indices, targets), (plane indices, axes, values)) of a state."""
    n = len(state.V)
    fixed = np.flatnonzero(state.fields.get(FIXED_FIELD, np.zeros(n)) > 0.5)
    h = state.handle_dict
    handles = None
    if h:
        idx = np.array(sorted(h), dtype=np.int64)
        handles = (idx, np.array([h[i] for i in idx], dtype=np.float64))
    plane = None
    pv = np.flatnonzero(state.fields.get(PLANE_FIELD, np.zeros(n)) > 0.5)
    if pv.size:
        value = float(state.V[pv, plane_axis].mean())
        plane = (pv, np.full(pv.size, plane_axis), np.full(pv.size, value))
    return fixed, handles, plane


def cubic_steps(state, params, options: dict | None = None, cache: dict | None = None
                ) -> Iterator[Step]:
    """The Cubic panel's run. ``options``: ``plane_axis`` (0-2), ``progressive`` (a
    ProgressiveParams dict or None), ``multigrid`` (bool)."""
    from algorithms.deform.collisions import hold_where_crossed
    from algorithms.deform.cubic import CubicStylizer, rotation_from_degrees
    from algorithms.deform.progressive import ProgressiveCubic, ProgressiveParams
    from algorithms.errors import ParameterError
    from algorithms.params import params_from_dict

    options = options or {}
    cache = {} if cache is None else cache
    plane_axis = int(options.get("plane_axis", 0))
    prog = options.get("progressive")
    # options saved before "finish" existed ran on the copy alone: replay them so
    prog = None if prog is None else params_from_dict(ProgressiveParams,
                                                      {"finish": False, **prog})
    multigrid = bool(options.get("multigrid", False)) and prog is None
    finish, why = (False, "") if prog is None else finish_of(prog, len(state.F))
    fixed, handles, plane = constraints_of(state, plane_axis)
    key = (id(state.V), id(state.F), fixed.tobytes(),
           None if handles is None else (handles[0].tobytes(), handles[1].tobytes()),
           None if plane is None else (plane[0].tobytes(), plane[1].tobytes(),
                                       plane[2].tobytes()),
           params.normalize, params.pin_one_vertex,
           None if prog is None else (prog.target_faces, prog.strategy, prog.tikhonov),
           multigrid)
    if cache.get("key") == key:
        solver = cache["solver"]
    elif prog is None:
        solver = CubicStylizer(state.V, state.F, fixed=fixed, handles=handles,
                               coord_constraints=plane, normalize=params.normalize,
                               pin_one_vertex=params.pin_one_vertex,
                               backend="multigrid" if multigrid else "auto")
    else:
        solver = ProgressiveCubic(state.V, state.F, target_faces=prog.target_faces,
                                  strategy=prog.strategy, tikhonov=prog.tikhonov,
                                  fixed=fixed, handles=handles, coord_constraints=plane,
                                  normalize=params.normalize,
                                  pin_one_vertex=params.pin_one_vertex, finish=finish)
    cache["key"], cache["solver"] = key, solver
    scale = state.fields.get(LAMBDA_FIELD)
    lam_v = None if scale is None else params.lam * np.asarray(scale)
    rotation = rotation_from_degrees(params.rot_x, params.rot_y, params.rot_z)
    frames = frames_of(state, rotation)
    extra = {} if frames is None else {"frames": frames}
    if prog is not None and frames is not None:
        raise ParameterError("Painted local cube frames do not work with progressive meshes "
                             "yet: switch progressive meshes off, or clear the frames.")

    def rerun(ids, targets, V_start):
        """The same run with the vertices ``ids`` held at ``targets`` too, from ``V_start``
        (algorithms.deform.collisions)."""
        # the parts' pinned vertices stay where they are (they are at their input positions),
        # so the mesh does not shift as a whole when held vertices take the pins' place
        pins = first.pinned[~np.isin(first.pinned, ids)]
        ids = np.concatenate([ids, pins])
        targets = np.concatenate([targets, V_start[pins]])
        h = (ids, targets) if handles is None else (np.concatenate([handles[0], ids]),
                                                    np.concatenate([handles[1], targets]))
        held = CubicStylizer(state.V, state.F, fixed=fixed, handles=h, coord_constraints=plane,
                             normalize=params.normalize, pin_one_vertex=params.pin_one_vertex,
                             backend="multigrid" if multigrid else "auto")
        return held.steps(params, lam_per_vertex=lam_v, rotation=rotation, initial=V_start,
                          **extra)

    first = solver if prog is None else solver.fine_stylizer() if finish else None
    if prog is None:
        steps = solver.steps(params, lam_per_vertex=lam_v, rotation=rotation, **extra)
    else:
        steps = solver.steps(params, lam_per_vertex=lam_v, rotation=rotation,
                             preview_every=prog.preview_every, lam_exponent=prog.lam_exponent,
                             finish=finish)
    if params.hold_crossings and (prog is None or finish):
        held = constrained_vertices(len(state.V), fixed, handles, plane)
        held[first.pinned] = True
        steps = hold_where_crossed(steps, state.V, state.F, rerun, constrained=held)
    return steps if prog is None else with_note(steps, why)


def constrained_vertices(n: int, fixed, handles, plane) -> np.ndarray:
    """(n,) bool: the vertices a constraint of the user's holds (fixed, handles, planes)."""
    out = np.zeros(n, bool)
    for ids in (fixed, None if handles is None else handles[0],
                None if plane is None else plane[0]):
        if ids is not None and len(ids):
            out[np.asarray(ids, np.int64)] = True
    return out


def finish_of(prog, n_faces: int) -> tuple[bool, str]:
    """Whether a progressive run (ProgressiveParams ``prog``) finishes on every triangle of a
    mesh of ``n_faces`` triangles, and, when it was asked to but may not (above
    :data:`~algorithms.deform.progressive.FINISH_MAX_FACES`), why."""
    from algorithms.deform.progressive import finish_allowed

    if not prog.finish:
        return False, ""
    return finish_allowed(n_faces)


def big_mesh_note(n_faces: int) -> str:
    """What the Cubic panel says on opening a mesh that goes through progressive meshes: how
    it runs, and above :data:`~algorithms.deform.progressive.FINISH_MAX_FACES` that only the
    copy will be stylized, and why."""
    from algorithms.deform import progressive

    if progressive.finish_allowed(n_faces)[0]:
        return (f"This mesh has {n_faces:,} triangles: progressive meshes are on (a coarse "
                "copy is stylized first, then every triangle is finished from it). To try λ "
                "values quickly, untick 'Finish on every triangle': about a second per λ, "
                "less cubic.")
    need = progressive.FINISH_BYTES_PER_FACE * n_faces / 1e9
    limit = progressive.FINISH_MAX_FACES
    return (f"This mesh has {n_faces:,} triangles: progressive meshes are on, and only the "
            f"coarse copy will be stylized: finishing on every triangle would need about "
            f"{need:.0f} GB of memory (above {limit:,} triangles). Raise λ for a stronger "
            f"effect, or simplify the mesh below {limit:,} triangles.")


def with_note(steps: Iterator[Step], note: str) -> Iterator[Step]:
    """``steps``, with ``note`` (if any) as the last Step's message and ``finish_skipped = 1``
    in its metrics (the panel's closing line and the batch record say it; the command line
    says it from :func:`finish_of`)."""
    if not note:
        yield from steps
        return
    last = None
    for st in steps:
        if last is not None:
            yield last
        last = st
    if last is not None:
        last.message = note
        last.metrics = {**last.metrics, "finish_skipped": 1.0}
        yield last


def touching_parts_of(state) -> tuple[int, int]:
    """``(parts, touching)`` of the mesh (:func:`algorithms.mesh.topology.touching_parts`):
    the Cubic panel warns when separate parts touch."""
    from algorithms.mesh.topology import touching_parts

    return touching_parts(state.V, state.F)


#: a result with at least this share of its area facing within :data:`AXIS_DEGREES` of an axis
#: is box-like already: the style has little left to square off
BOX_LIKE_SHARE = 0.9
AXIS_DEGREES = 10.0


def axis_facing_share(V, F) -> float:
    """Share of the surface's area whose triangle normal is within :data:`AXIS_DEGREES` of a
    coordinate axis."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area = np.linalg.norm(n, axis=1)
    ok = area > 0
    if not ok.any():
        return 0.0
    cos = np.abs(n[ok]).max(axis=1) / area[ok]
    return float(area[ok][cos >= np.cos(np.radians(AXIS_DEGREES))].sum() / area[ok].sum())


def change_note(V0, V, F, lam: float, flags: bool = False) -> str:
    """What to tell a user whose stylization barely changed the shape (empty when it visibly
    did, :data:`~app.recipes.VISIBLE_MOVE`): its faces already face the axes, or how to
    stylize more -- the panel's setting name, or with ``flags`` the command line's."""
    from app.recipes import VISIBLE_MOVE, largest_move, unchanged_words

    moved = largest_move(V0, V)
    if moved >= VISIBLE_MOVE:
        return ""
    said = unchanged_words(moved)
    share = axis_facing_share(V, F)
    if share >= BOX_LIKE_SHARE:
        return said + (f"its faces already face the axes ({100 * share:.0f} % of its area "
                       f"within {AXIS_DEGREES:g} degrees of one), so the style has little left "
                       f"to square off.")
    more = min(1.0, 2.5 * float(lam))
    return said + (f"raise --lambda (e.g. --lambda {more:g}) to stylize more." if flags else
                   f"raise λ (e.g. to {more:g}) to stylize more.")


def _cubic_params():
    from algorithms.deform.cubic import CubicParams

    return CubicParams


def _cubic_outcome(last: Step) -> dict:
    return {"iterations": int(last.iteration), **{k: float(v) for k, v in last.metrics.items()}}


register(Recipe("Cubic", "cubic", _cubic_params, cubic_steps, outcome=_cubic_outcome))
