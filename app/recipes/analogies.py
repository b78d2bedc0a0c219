"""Recipe "Analogies": normal-driven shape analogy (thesis ch. 6) towards a chosen style.

Options (the JSON-able dict the Analogies panel's ``job_options()`` returns):

``style`` : str
    what the normals are pulled to: a primitive name (one of
    :data:`algorithms.deform.targets.PRIMITIVES`, default ``"cube"``), ``"capture sphere"``
    (the painted sphere of ``capture``), or the ``"blob:..."`` reference of a style file made
    by :func:`app.recipes.put_blob_file`: a style mesh (closest normals of a convex mesh, a cMCF
    spherical map otherwise) or a capture ``.json``; read with
    :func:`algorithms.deform.targets.load_style` from :func:`app.recipes.blob_path`.
``style_map`` : str, optional
    how a style mesh is mapped (``"auto"``, ``"closest"``, ``"spherical"``; default ``"auto"``,
    what the panel uses).
``capture`` : dict, optional
    the painted capture sphere, ``CaptureSphere.to_dict()``; used when ``style`` is
    ``"capture sphere"`` (the panel always records it, so a saved project keeps the painting).
``progressive`` : dict or None, optional
    a ProgressiveParams dict to run through an affine progressive mesh (the command line's
    ``--progressive-faces``); None (default, the panel) runs on every triangle.

The ShapeAnalogy precomputation (normals, areas, ARAP factorizations) is kept in ``cache`` for
the same input arrays (V, F), and a style's target map for the same style (a cMCF spherical map
takes seconds): a live re-run that only changes a parameter reuses both.

Also here, Qt-free, for the panel:

* the colour views: :func:`angle_to_targets_view`, :func:`gaussian_curvature_view`,
  :func:`target_direction_view`, :func:`capture_view_values` (with :func:`direction_hue`);
* the capture sphere's strokes: :func:`apply_capture_stroke` (the effect of one brush stroke,
  used by the panel's brush), :func:`capture_hash` and :func:`replay_capture_edit` (the study
  replay's check of a logged stroke, see the panel's ``_CaptureCommand.log_details``).
"""

from __future__ import annotations

import hashlib
import json
from typing import Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import Recipe, blob_path, is_blob_ref, register

#: The ``style`` of the painted capture sphere (the gallery's last item).
CAPTURE = "capture sphere"
#: The value range of :func:`direction_hue` (for an "hsv" colour map).
HUE_RANGE = (-np.pi - 2.0, np.pi + 2.0)
#: The panel's capture sphere: ``icosphere(3)`` (642 directions).
CAPTURE_SUBDIVISIONS = 3


# ------------------------------------------------------------------------------ capture sphere
def new_capture(subdivisions: int = CAPTURE_SUBDIVISIONS):
    """An unpainted :class:`~algorithms.deform.targets.CaptureSphere`."""
    from algorithms.deform.targets import CaptureSphere

    return CaptureSphere(subdivisions)


def capture_from_dict(data: dict):
    """The :class:`~algorithms.deform.targets.CaptureSphere` of ``CaptureSphere.to_dict()``
    (raises ParameterError with a plain message on malformed data)."""
    from algorithms.deform.targets import CaptureSphere
    from algorithms.errors import ParameterError

    if not isinstance(data, dict):
        raise ParameterError("The painted capture sphere of this run is missing or damaged.")
    return CaptureSphere.from_dict(data)


def capture_hash(capture: dict) -> str:
    """SHA-256 (hex) of ``json.dumps(capture, sort_keys=True)``: a capture sphere's identity in
    the study log."""
    return hashlib.sha256(json.dumps(capture, sort_keys=True).encode("utf-8")).hexdigest()


def _dab(cap, position, radius: float, erase: bool, target, label):
    """One dab of the capture brush on ``cap`` (in place): the sphere vertices within
    ``radius * π`` radians of the picked point's direction are painted with ``target`` (into
    region ``label``, a new one when None) or erased. Returns the region's label."""
    p = np.asarray(position, dtype=np.float64).reshape(3)
    d = p / max(np.linalg.norm(p), 1e-12)
    theta_r = max(float(radius), 1e-6) * np.pi
    near = np.flatnonzero(cap.vertices @ d > np.cos(theta_r))
    if erase:
        cap.erase(near)
        return label
    return cap.paint(near, np.asarray(target, dtype=np.float64), label)


def apply_capture_stroke(capture: dict, stroke: dict) -> dict:
    """The capture sphere after one brush stroke (the panel's capture brush computes its strokes
    with this function; the study replay recomputes logged ones).

    Parameters
    ----------
    capture : dict, ``CaptureSphere.to_dict()`` before the stroke.
    stroke : dict, every input of the stroke:
        ``"dabs"``: list of picked points ``[x, y, z]`` on the sphere view, in order (each dab
        takes the sphere vertices within ``radius * π`` radians of the point's direction);
        ``"radius"``: float, the brush radius (fraction of π);
        ``"erase"``: bool, erase instead of paint;
        ``"target"``: ``[x, y, z]``, the target direction (normalized) painted regions send
        their normals to; the stroke's dabs make ONE new region (its first dab creates it,
        even when it takes no vertex), as in the brush.

    Returns
    -------
    dict, ``CaptureSphere.to_dict()`` after the stroke.
    """
    from algorithms.errors import ParameterError

    cap = capture_from_dict(capture)
    try:
        dabs = [np.asarray(p, dtype=np.float64).reshape(3) for p in stroke["dabs"]]
        radius = float(stroke["radius"])
        erase = bool(stroke["erase"])
        target = np.asarray(stroke["target"], dtype=np.float64).reshape(3)
    except (KeyError, TypeError, ValueError) as e:
        raise ParameterError(f"This is not a valid capture-sphere stroke ({e}).") from None
    label = None
    for p in dabs:
        label = _dab(cap, p, radius, erase, target, label)
    return cap.to_dict()


def replay_capture_edit(details: dict) -> bool:
    """Whether a logged capture stroke (``_CaptureCommand.log_details``: ``capture_before``,
    ``stroke``, ``capture_after_hash``) gives the same capture sphere again. A malformed record
    gives False."""
    from algorithms.errors import Stylize3DError

    try:
        after = apply_capture_stroke(details["capture_before"], details["stroke"])
    except (Stylize3DError, KeyError, TypeError, ValueError):
        return False
    return capture_hash(after) == details.get("capture_after_hash")


# ------------------------------------------------------------------------------ styles
def style_target_map(options: dict | None, cache: dict | None = None):
    """``(target map, description)`` of the style ``options`` name (module docstring).

    Target maps of primitives and style files are kept in ``cache["styles"]``; a capture
    sphere is rebuilt from its dict (a snapshot: painting it later does not change a run)."""
    from algorithms.deform.targets import PRIMITIVES, load_style
    from algorithms.errors import ParameterError

    options = options or {}
    style = options.get("style", "cube")
    mode = options.get("style_map", "auto")
    if style == CAPTURE:
        cap = options.get("capture")
        if cap is None:
            raise ParameterError("The capture sphere style needs a painted capture sphere "
                                 "(options['capture']).")
        return capture_from_dict(cap), "your painted capture sphere"
    if not isinstance(style, str) or not (style in PRIMITIVES or is_blob_ref(style)):
        raise ParameterError(f"Unknown style {style!r}: use one of {', '.join(PRIMITIVES)}, "
                             f"{CAPTURE!r}, or a style file stored as input data "
                             "(app.recipes.put_blob_file).")
    styles = None if cache is None else cache.setdefault("styles", {})
    key = (style, mode)
    if styles is not None and key in styles:
        return styles[key]
    spec = style if style in PRIMITIVES else str(blob_path(style))
    got = load_style(spec, mode)
    if styles is not None:
        styles[key] = got
    return got


# ------------------------------------------------------------------------------ the run
def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a is b or (a.shape == b.shape and np.array_equal(a, b))


def shape_analogy_of(state, cache: dict | None = None):
    """The :class:`~algorithms.deform.analogies.ShapeAnalogy` of ``state``'s mesh, kept in
    ``cache["analogy"]`` for the same V and F (by identity, else by value)."""
    from algorithms.deform.analogies import ShapeAnalogy

    held = None if cache is None else cache.get("analogy")
    if held is not None and _same(held[0], state.V) and _same(held[1], state.F):
        return held[2]
    sa = ShapeAnalogy(state.V, state.F)
    if cache is not None:
        cache["analogy"] = (state.V, state.F, sa)
    return sa


def analogy_steps(state, params, options: dict | None = None, cache: dict | None = None
                  ) -> Iterator[Step]:
    """The Analogies panel's run (options: module docstring)."""
    from algorithms.deform.analogies import ShapeAnalogy
    from algorithms.deform.collisions import hold_where_crossed
    from algorithms.deform.progressive import ProgressiveParams, progressive_analogy_iter
    from algorithms.params import params_from_dict

    options = options or {}
    cache = {} if cache is None else cache
    tmap, _what = style_target_map(options, cache)
    prog = options.get("progressive")

    def rerun(ids, targets, V_start):
        """The same run with the vertices ``ids`` held at ``targets``, from ``V_start``
        (algorithms.deform.collisions)."""
        held = ShapeAnalogy(state.V, state.F, tmap, handles=(ids, targets))
        return held.steps(params, target_map=tmap, initial=V_start)

    if prog is not None:
        # options saved before "finish" existed ran on the copy alone: replay them so
        prog = params_from_dict(ProgressiveParams, {"finish": False, **prog})
        from dataclasses import replace

        from app.recipes.cubic import finish_of, with_note

        finish, why = finish_of(prog, len(state.F))
        steps = progressive_analogy_iter(state.V, state.F, tmap, params,
                                         replace(prog, finish=finish))
        if params.hold_crossings and finish:
            steps = hold_where_crossed(steps, state.V, state.F, rerun)
        return with_note(steps, why)

    steps = shape_analogy_of(state, cache).steps(params, target_map=tmap)
    return hold_where_crossed(steps, state.V, state.F, rerun) if params.hold_crossings else steps


#: a result whose normals are on average within this many degrees of the style's targets
#: matches the style already: there is little left to turn
STYLE_MATCH_DEGREES = 5.0


def change_note(V0, V, mean_angle: float, lam: float, flags: bool = False) -> str:
    """What to tell a user whose analogy barely changed the shape (empty when it visibly did,
    :data:`~app.recipes.VISIBLE_MOVE`): its normals already match the style's (``mean_angle``,
    degrees, the result's mean angle to the targets), or how to pull harder -- the panel's
    setting name, or with ``flags`` the command line's."""
    from app.recipes import VISIBLE_MOVE, largest_move, unchanged_words

    moved = largest_move(V0, V)
    if moved >= VISIBLE_MOVE:
        return ""
    said = unchanged_words(moved)
    if mean_angle <= STYLE_MATCH_DEGREES:
        return said + (f"its normals are already within {mean_angle:.1f} degrees of the style's "
                       f"on average, so there is little left to turn.")
    more = max(2.0, 5.0 * float(lam))
    return said + (f"raise --lambda (e.g. --lambda {more:g}) to pull harder." if flags else
                   f"raise λ (e.g. to {more:g}) to pull harder.")


def _analogy_params():
    from algorithms.deform.analogies import AnalogyParams

    return AnalogyParams


def _analogy_outcome(last: Step) -> dict:
    return {"iterations": int(last.iteration), **{k: float(v) for k, v in last.metrics.items()}}


register(Recipe("Analogies", "analogy", _analogy_params, analogy_steps,
                outcome=_analogy_outcome))


# ------------------------------------------------------------------------------ colour views
def direction_hue(T: np.ndarray) -> np.ndarray:
    """A scalar per unit direction ``T (k, 3)`` for an "hsv" colour map over :data:`HUE_RANGE`:
    equal directions get equal colours (azimuth plus a lift by z); the capture sphere and the
    mesh use it alike."""
    T = np.asarray(T, dtype=np.float64)
    return np.arctan2(T[:, 1], T[:, 0]) + 2.0 * T[:, 2]


def capture_view_values(capture) -> np.ndarray:
    """``(p,)`` values of the capture sphere's view: the :func:`direction_hue` of each painted
    vertex's region target, NaN where unpainted."""
    lab = capture.labels
    vals = np.full(len(lab), np.nan)
    painted = lab >= 0
    if painted.any():
        vals[painted] = direction_hue(capture.targets[lab[painted]])
    return vals


def angle_to_targets_view(V, F, target_map) -> np.ndarray:
    """``(n,)`` degrees between each vertex normal and its target (thesis Fig. 6.15)."""
    from algorithms.mesh.operators import vertex_normals

    N = vertex_normals(V, F)
    T = target_map(N)
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", N, T), -1.0, 1.0)))


def target_direction_view(V, F, target_map) -> np.ndarray:
    """``(n,)`` :func:`direction_hue` of each vertex's target direction (the capture sphere's
    colours on the mesh)."""
    from algorithms.mesh.operators import vertex_normals

    return direction_hue(target_map(vertex_normals(V, F)))


def gaussian_curvature_view(V, F) -> tuple[np.ndarray, tuple[float, float]]:
    """``(K (n,), (-lim, lim))``: Gaussian curvature (angle defect per Voronoi area, Fig. 6.21)
    and a symmetric colour range at its 95th absolute percentile (1 when that is 0)."""
    from algorithms.mesh.operators import gaussian_curvature

    K = gaussian_curvature(V, F)
    lim = float(np.percentile(np.abs(K), 95)) or 1.0
    return K, (-lim, lim)
