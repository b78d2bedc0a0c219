"""Paparazzi: stochastic multi-view optimization of a mesh through image filters (thesis ch. 2).

Per iteration (thesis Alg. at 204-220 for energy filters, 235-248 for iterative filters):
sample a camera on the offset surface (or use the fixed front view for single-view filters),
render ``R`` (flat shading, :mod:`algorithms.render`), get ``dE/dR`` from the filter (energy
filters) or ``-(f(R) - R)`` (iterative filters), pull it back to the vertices with the analytic
vector-Jacobian product and take a NAdam step.

Choices (written down here, tested in tests/algorithms/paparazzi/)
------------------------------------------------------------------
* Frame: the mesh is moved into ``[-1, 1]^3`` (longest side 2; the thesis's "unit-radius cube",
  OpenGL canonical units) while optimizing and moved back at the end, so σ = 0.1 and the 0.5-wide
  orthographic view mean what they mean in the thesis. ``sigma`` is in those units; the bounding
  box diagonal of a normalized shape is at most 3.46, so the thesis's 5 %-25 % of the diagonal is
  about 0.1-0.85.
* NAdam (Dozat 2016) in the form of Ruder's overview (thesis cites Ruder 2016; no momentum schedule): ``m, v`` with β1 = 0.9, β2 = 0.999,
  ε = 1e-8, step ``lr (β1 m̂ + (1-β1) g / (1-β1^t)) / (sqrt(v̂) + ε)``; the learning rate is
  divided by 5 at 90 % of the iterations (the authors' schedule).
* Mesh quality without El Topo: every ``remesh_every`` iterations (default 30, the thesis's) the
  mesh is remeshed isotropically (``gpytoolbox.remesh_botsch``'s C++ core, ``remesh_iterations``
  passes (default 1), target ``h`` = the input's mean edge length, boundary vertices fixed as
  features, reprojection on). By default (``remesh_scope`` "bad") only the vertices within one
  ring of a bad element -- an edge shorter than h/2 or longer than 2 h, a triangle with an angle
  below 20 degrees -- may move; the others stay fixed, as El Topo (the thesis's remesher)
  changes bad elements only. An element counts as bad only where the run has made it worse
  (by ``WORSE_FACTOR``) than it was when it was made, in the input or by a remeshing
  (:attr:`Paparazzi.baseline`): a CAD model's own slivers stay as they came. Only the
  triangles with such a vertex go to the remesher, and the
  part comes back stitched into the rest along its unchanged border; the checks below
  (topology, drift) look at that part. After the first few remeshings that part is a few % of
  a scan's triangles: remeshing alone on the corpus skull (49,999 vertices, 1000 iterations)
  took 16.5 s instead of 39.9 s with the whole mesh handed to the remesher. Re-placing every
  vertex ("all", the default before issue 23's fourth pass, 26 November 2026) cost what the
  steps had won: one such remeshing of the
  pretzel sample raised its 16-view guided energy by 8 % (1.783 -> 1.929) and the
  1000-iteration run ended above its start (1.856); moving bad elements only, it falls
  (1.700; docs/results/paparazzi.md). A remeshing may also move the surface by at most
  ``DRIFT_TOL`` = 0.25 target edge lengths (both ways between the surfaces before and after it):
  where it moved it more (a coarse mesh's thin part collapsed, a crease cut off) the surface is
  held for the remeshings, as where one crossed it (below); without it remeshing alone shrank a
  low-poly rabbit's ears to stubs (issue 38). The remeshed mesh is accepted only if it is still a 2-manifold
  with the input's Euler characteristic and boundary-loop count and no new self-intersections
  (``igl.predicates.find_self_intersections``, exact predicates); a triangle it made with a
  smallest angle below ``DEGENERATE_ANGLE`` = 1e-3 degrees (and below the mesh's own smallest)
  is held like a crossing (:meth:`Paparazzi._degenerate_points`; the value was not tuned: its
  cotangent is 6e4). At each check the steps' own crossings come first: the current mesh is
  checked for self-intersections; if the steps since the last check created any, the surface
  within ``HOLD_RADIUS`` edge lengths of them is put back where it was at the last check (the
  rest keeps its progress), and the whole mesh is rolled back to the last checked state only if
  that leaves crossings. Then the remeshing starts from a surface with no new crossings, so it
  is judged by the crossings it makes itself, and those can only involve the part it changed
  (:meth:`Paparazzi._remeshing_crossing_points`; the put-back is re-tested on the triangles it
  moved the same way). Until 30 November 2026 (fifth session) the remeshing came first and was
  tested with the steps' crossings in it: each such check tried 3 remeshings in vain and lost
  the cycle's remeshing (corpus skull, quantize: 26 of 33 remeshings rejected, 80 retries, 90 s;
  now 0 rejected, 15 retries, 38 s; docs/results/paparazzi.md). Rolling back the
  whole mesh at every crossing, as before, threw away most of neural-style's progress on the
  corpus's 45k-50k-vertex scans (skull: 12 of 33 checks rolled back; its energy ended above
  its start and the command wrote nothing). So
  a cycle costs one remeshing pass and one
  self-intersection check (about 0.4 s + 0.3 s on 29k vertices on an idle core); the core is
  called directly because ``remesh_botsch``'s Python wrapper spent another 0.85 s re-deriving
  boundary vertices and re-checking manifoldness, which the loop keeps as invariants.
  Crossings are handled where they happen (El Topo, which the thesis uses, also resolves
  collisions locally): a remeshing that made the surface cross itself is tried again (up to
  ``REMESH_ATTEMPTS`` = 3 times per check) with the vertices within ``HOLD_RADIUS`` = 4 target
  edge lengths of its crossings fixed, and the remesher keeps them fixed for the rest of the run;
  after a rollback the optimizer holds the surface within 4 edge lengths of the crossings still
  for the rest of the run, and halves the learning rate only when the crossings were next to a
  held part already (step shrinking; 11 halvings stop the run with a message). Halving at every
  rollback, as before, failed on camelhead (11,381 V, CLI defaults, guided): its lips are 3-4 %
  of an edge length apart, so every remeshing crossed them (all 33 rejected: nothing resampled
  the optimizer's noise), and the steps crossed the surface at two other spots (one the mirror
  image of the input's own crossings) again and again, each rollback halving the step of the
  whole shape, until the run stopped after 11 rollbacks. Now 1 of 33 remeshings is rejected (4
  retries), 1 rollback holds 131 vertices still, and the output has no crossings at all
  (benchmarks/paparazzi_effects.py). A run in which nothing crosses runs exactly as before.
  Since 1 December 2026 (``put_back_crossing_only``, on by default) the steps' crossings are
  first put back more narrowly: only the corners of the crossing triangles go back to their
  last checked positions, then the corners of any triangles that still cross (up to
  ``PUT_BACK_ROUNDS`` = 8 times; :meth:`Paparazzi._put_back_crossing`); they are not held, and
  the step is not halved: their first NAdam moment is cleared and they move again. Only if
  crossings remain does the check fall back to the 4-edge-length put-back and hold above. On a
  noisy, sliver-laden scan (docs/results/paparazzi.md, "the sliver scan") 1,299 folds after the
  first 30 steps made the 4-edge-length hold freeze 49,791 of 155,566 vertices, and 133k by the
  end: guided's energy rose (2.764 -> 2.783); with the narrow put-back (about 3,300 vertices at
  that check, none held) it fell to 1.366.
  ``remesh_threshold`` > 0 skips the remeshing (not the check) while no more than that share of
  the edges lies outside Botsch and Kobbelt's band ``[4/5 h, 4/3 h]`` (the edges a pass would
  split or collapse; a mesh with all its edges in the band has no angle below about 33 degrees).
  It is off by default: remeshing also resamples away the optimizer's high-frequency noise, and
  without it the guided filter roughens a regular mesh (spot Loop-subdivided twice, 13,234 V,
  1000 iterations: bending energy 369 -> 543 with the threshold 0.05, which never remeshed it;
  remeshing alone, every 30 iterations with an identity filter, gives 369 -> 339). With 0.05 a
  3000-iteration guided run on fandisk (28,910 V) remeshes 4 times instead of 99
  (benchmarks/paparazzi.py).
  A remeshing resets the optimizer moments (the authors' practice; vertices are new), and so does
  a rollback. The output is checked the same way; if the last steps created intersections, the
  last checked state is returned. "No self-intersections" means no new intersecting face pairs:
  none for a clean input; for an input that already intersects itself (camelhead: 5 pairs), none
  farther than 4 target edge lengths from the input's own (:meth:`Paparazzi._new_crossings`;
  comparing pair counts rejected every remeshing of camelhead, since resampling an existing
  intersection changes its pair count).
* Learning rate: the thesis gives none; each filter has its own default (``FilterSpec.
  learning_rate``: 2e-4, the guided filter 1e-5, slic 6e-5, neural-style 1e-3 (5e-4 with its
  network energy)). NAdam's steps
  are about ``lr`` per coordinate whatever the gradient's size, so where a filter asks for
  little a large step is mostly noise: with the guided filter's former defaults (epsilon 1e-8)
  the displacement a view asked for was 163 times smaller than a 5e-5 step on the blob sample,
  and the filter's own energy rose (issue 23; :func:`.filters._guided`, docs/results/paparazzi.md).
  *Rough scans* (issue 23, fifth pass): an edge-preserving filter takes noise stronger than its
  threshold for edges, so on a noisy scan its energy first *rises* as the surface is smoothed and
  falls only near the smooth surface (the guided filter along the straight path from the noisy
  fandisk to the clean one: 2.99 -> 3.85 at 70 % of the way -> 0.34; the filter's own full-batch
  direction raises it too). At 1e-5 a 1000-iteration run stays on the rising side (2.99 ->
  3.06). So with the step on auto and ``rough_step`` on, :meth:`Paparazzi.rough_probe` takes one
  small full-batch step at the start; if the energy rises the filter's
  ``FilterSpec.rough_learning_rate`` is used (guided 2e-4: the noisy fandisk 2.99 -> 0.96; the
  metric ``rough_input`` says so), provided at least ``ROUGH_SHARE`` = 0.7 of the shape's
  pixels are in the filter's noise regime (``FilterSpec.noise_pixels``; issue 38: the probe
  also rises on clean CAD models at the filter's fixed point, flat faces and sharp creases,
  where the rough step then raised the energy on 10 corpus meshes). The rough step was
  measured on meshes whose mean edge, in
  the cube of side 2, is 0.0226-0.04; on a finer mesh it shrinks in proportion below
  ``ROUGH_EDGE`` = 0.02 (a step is about ``lr`` per coordinate, so a fixed one is a larger share
  of a shorter edge and of its noise: a 155,813-vertex noisy scan at 2e-4 crossed itself, 7
  rollbacks, and its energy rose; issue 23, sixth pass). l0's own step does the same
  (``FilterSpec.step_follows_edge``; issue 38: its fixed step folded dense scans, hippo 2.67 %
  of the edges by more than 90 degrees, 0.81 % with the shrunk step; the first Step's message
  and the command line say "fine mesh"), and so does neural-style's since 1 December 2026
  (tenth session): with the crossings put back narrowly instead of held, its fixed 1e-3 (a
  fifth of an edge a step on the sliver scan, whose views are 0.1 wide) raised its energy on
  dense scans (lato000 1620 -> 1833, nefertiti 968 -> 1108; docs/results/paparazzi.md).
  *A smaller step when the energy climbs* (``plateau_step``, an option; issue 23, fifth
  pass): every ``PLATEAU_EVERY`` = 50 iterations the monitor energy is checked (the command
  line's monitor schedule, every 25, evaluates it then anyway; the panel's, every 50, too); once
  the run has brought it below its start, a value more than ``PLATEAU_RISE`` = 2 % above the
  lowest check halves the step (at most four times, to 1/16). A run whose energy keeps falling
  never halves and runs bit for bit as without the option. The filter's target moves with the
  surface (an iterative filter's f(R)), so past some point the steps can add more than they
  remove: l0 on the noisy fandisk fell from 23.55 to 19.6 in 150 iterations and climbed back to
  27.4 (ending at 24.5); with halving it ends at 19.87 (docs/results/paparazzi.md). Not for a
  filter whose energy is no measure of progress (``FilterSpec.halve_on_climb`` False:
  neural-style). Off by default: re-running the effects table with it on, slic's energy (its
  superpixels re-form from picture to picture, so a 2 % rise is often a jump, not a trend)
  ended higher on 7 of its 10 runs (spot 186.1 -> 216.5) and its effect weaker.
* A run must lower its monitor energy (below): a result whose energy is not below the start's
  did not converge. With ``lowest_fallback`` on (the default; issue 23, sixth pass) the monitor
  checks' shapes below the start are remembered (the lowest one, and the lowest one taken at a
  self-intersection check); if the last shape's energy is not below the start, the run returns
  the lowest of them instead (checked for new crossings first; the metric ``kept_iteration``
  says which, ``last_monitor_energy`` what the last one had). If none got below the start, the
  last shape is returned and the recipe (:func:`app.recipes.paparazzi.paparazzi_steps`) fails
  the run with :class:`EnergyNotLowered`, changing nothing. A run whose energy ends below its
  start runs bit for bit as without the option. Measured (docs/results/paparazzi.md): l0 on the
  noisy fandisk fell to 19.6 and climbed back above its start (23.55 -> 25.33 at iteration 1000).
* Nothing to filter (issue 38): an iterative filter that changes the input's monitor views by
  less than its ``FilterSpec.min_change`` (one 8-bit grey level: the rms of ``f(R) - R`` per
  channel over the views' foreground, :meth:`Paparazzi.change_per_pixel`) is refused before
  the first step with :class:`NothingToFilter`, changing nothing: the shape already looks the
  way the filter makes pictures look (CAD parts of flat faces under guided and l0), and every
  such corpus run raised its energy over a whole run instead (docs/results/paparazzi.md).
* Boundary vertices do not move (their gradient is zeroed), so a boundary loop stays where it is.
* Monitor energy (thesis 353-356, made multi-view): the thesis watches one fixed camera; one
  view sees a sixth of the shape at most and its energy can rise while the rest falls (issue
  23), so the run's ``monitor_energy`` is the *mean* energy of ``monitor_views`` (default 16)
  fixed views spread over the offset surface (:func:`.offset.monitor_cameras`, their own seeded
  stream ``[seed, 1]``; the front view alone for a single-view filter), evaluated at the start,
  every ``monitor_every`` iterations (default 25: sixteen filter calls every 25 iterations
  cost the slowest filters, slic and l0, about 60 % more time than the run's own, and the
  guided filter almost nothing) and at the end. Its energy is ``E`` for energy filters and
  ``1/2 |f(R) - R|^2`` over the foreground for iterative ones.
* Same seed, same result: all randomness comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from .. import offload
from ..errors import InvalidMeshError, ParameterError, Stylize3DError
from ..mesh.intersections import count_self_intersections
from ..mesh.intersections import intersecting_pairs as _intersecting_pairs
from ..mesh.intersections import intersecting_pairs_touching as _intersecting_pairs_touching
from ..params import param, validate_params
from ..render import image_vjp, render
from ..steps import Step
from ..optim import nadam_step
from .filters import FilterContext, FilterSpec, front_camera, get_filter
from .offset import OffsetSurface, monitor_cameras, offset_surface, sample_camera

__all__ = ["PaparazziParams", "PaparazziStep", "Paparazzi", "paparazzi_iter", "paparazzi",
           "EnergyNotLowered", "require_lowered",
           "FilterFailed", "count_self_intersections", "nadam_step"]


#: a rollback or a remeshing that made the surface cross itself holds the surface within this
#: many target edge lengths of the crossing still (see the module docstring)
HOLD_RADIUS = 4.0
#: ``PaparazziParams.put_back_crossing_only``: how many times the put-back grows by the
#: corners of the triangles that still cross before it gives up
#: (:meth:`Paparazzi._put_back_crossing`)
PUT_BACK_ROUNDS = 8
#: ``PaparazziParams.remesh_scope``: "bad" lets a remeshing move only the vertices within one
#: ring of a bad element -- an edge outside ``BAD_EDGE_BAND`` times the target length ``h`` or a
#: triangle with an angle below ``BAD_ANGLE`` degrees -- all others stay where they are (El Topo,
#: the thesis's remesher, also changes bad elements only); "all" re-places every vertex
REMESH_SCOPES = ("bad", "all")
BAD_EDGE_BAND = (0.5, 2.0)
BAD_ANGLE = 20.0
#: during a run an element counts as bad only where the run has made it worse than it was when
#: it was made (in the input, or by a remeshing): an edge outside ``BAD_EDGE_BAND`` and this
#: much shorter (or 1 / this much longer) than it was, a smallest angle below ``BAD_ANGLE`` and
#: this much smaller than it was (below ``DEGENERATE_ANGLE``: always). 4/5 is the remesher's
#: own tolerance (it collapses edges below 4/5 h, splits them above 4/3 h); not tuned. Without
#: it every remeshing re-placed a CAD model's long thin triangles whatever the filter did, and
#: the triangles a remeshing made beside them, bad too, were re-placed at the next one, and so
#: on across the part: guided's remeshing alone turned casting's curved faces jagged and
#: raised guided's energy by 6-21 % on three corpus CAD parts (tree, casting, chair_model),
#: more than the filter's steps lowered it (issue 38, 30 November 2026)
WORSE_FACTOR = 0.8
#: remeshing attempts per check (each one holding the surface where the last one crossed it)
REMESH_ATTEMPTS = 3
#: a remeshing may move the surface by at most this many target edge lengths h (checked both
#: ways between the surfaces before and after it); where it moved it more, the surface is held
#: for the remeshings, as where one made it cross itself. Resampling a curved surface at edge
#: length h moves it by about h^2 / (8 R); a mesh of edge length h represents curvature radii
#: down to about h / 2, where that is h / 4. Without the bound, on coarse meshes remeshing alone
#: (an identity filter, 1000 iterations) shrank the corpus rabbit's ears to stubs and crumpled a
#: box's faces (issue 38, 29 November 2026). Chosen on those two and the blob sample: 0.1 h also
#: held neural-style's relief there, and its network energy no longer fell (227.8 -> 228.0,
#: against 224.8 with 0.25 h or without the bound); 0.5 h let the box move 7 % of its diagonal.
DRIFT_TOL = 0.25
#: a remeshing that makes a triangle with a smallest angle below this many degrees (and below
#: the mesh's own smallest) is held there like one that crossed the surface
DEGENERATE_ANGLE = 1e-3
#: ``PaparazziParams.plateau_step``: every this many iterations the monitor energy is checked;
#: once the run has brought it below its start, a rise of more than ``PLATEAU_RISE`` above the
#: lowest value seen halves the step, at most down to ``PLATEAU_MIN`` of it (issue 23, fifth
#: pass; docs/results/paparazzi.md "A smaller step when the energy climbs")
PLATEAU_EVERY = 50
PLATEAU_RISE = 0.02
PLATEAU_MIN = 1.0 / 16.0
#: the rough step (``FilterSpec.rough_learning_rate``) is for a mesh whose mean edge, in the
#: cube of side 2, is at least this long (it was measured on meshes of 0.0226-0.04: armadillo
#: to bob); on a finer mesh it shrinks in proportion, so that a step stays the same share of an
#: edge and of the noise (issue 23, sixth pass)
ROUGH_EDGE = 0.02
#: a rising probe says "rough" only where at least this share of the shape's pixels (over the
#: monitor views) is in the filter's noise regime (``FilterSpec.noise_pixels``; issue 38). Set
#: on the effects-table meshes (fandisk, bob, spot, camelhead, armadillo and the four samples),
#: clean and with 0.1-0.3 mean edge lengths of noise: every noisy copy whose probe rises has a
#: share of 0.78-1.0, every clean mesh 0.01-0.66; 0.7 lies between. The corpus's clean CAD
#: models, whose probe rose (+0.2 % to +208 %) and whose energy the rough step then raised, have
#: 0.0-0.45 (docs/results/paparazzi.md, "Rough probe on clean CAD models")
ROUGH_SHARE = 0.7


def crease_edges(V, F, degrees: float) -> np.ndarray:
    """``(k, 2)`` the interior edges of ``(V, F)`` whose two faces' normals make an angle above
    ``degrees``."""
    from ..mesh.operators import face_normals
    from ..mesh.topology import edge_flaps

    E, _, EF, _ = edge_flaps(np.asarray(F, dtype=np.int64))
    inner = (EF >= 0).all(axis=1)
    N = face_normals(V, F)
    c = (N[EF[inner, 0]] * N[EF[inner, 1]]).sum(1)
    return E[inner][c < np.cos(np.radians(degrees))].astype(np.int64)


class FilterFailed(Stylize3DError):
    """The image filter raised; the run stops with its message."""

    exit_code = 6


class NothingToFilter(Stylize3DError):
    """An iterative filter changes the input's pictures by less than its ``min_change``: there
    is nothing for it to do, so the run is refused before its first step (nothing changed)."""

    exit_code = 6


class EnergyNotLowered(Stylize3DError):
    """The run ended without lowering its monitor energy: it did not converge, so nothing is
    changed (:func:`require_lowered`)."""

    exit_code = 6


def require_lowered(metrics: dict, spec: FilterSpec | None = None,
                    iterations: int | None = None) -> None:
    """Raise :class:`EnergyNotLowered` unless the last step's ``monitor_energy`` is below its
    ``initial_monitor_energy`` (a step without them, e.g. an empty run, passes); ``spec``, the
    run's filter, adds its advice (``FilterSpec.panel_iterations``); ``iterations``, the run's
    count, when known: a run of at least the command line's 1000 (and the filter's own count)
    is not told to try more iterations or another step, which lowered the energy on none of the
    corpus runs refused so (docs/results/paparazzi.md, 30 November 2026) and on one of three l0
    runs tried later (chair_model at 3,000 iterations or a tenth of the step; not capsule, not
    the sliver scan: docs/results/paparazzi.md, "l0's energy measured as the L0 objective"),
    so its message says they seldom help."""
    try:
        e0, e1 = float(metrics["initial_monitor_energy"]), float(metrics["monitor_energy"])
    except (KeyError, TypeError, ValueError):
        return
    if not e1 < e0:
        probe, share = metrics.get("rough_probe"), metrics.get("rough_share")
        if probe is not None and probe > 0 and share is not None and share < ROUGH_SHARE:
            # the probe rose on a shape whose pictures are flat: a clean model at the filter's
            # fixed point (docs/results/paparazzi.md "Rough probe on clean CAD models"), where
            # more iterations or another step raise the energy just the same
            name = getattr(spec, "name", "image")
            pct = 100 * float(share)
            noisy = "less than 1 %" if pct < 1 else f"only {pct:.0f} %"
            raise EnergyNotLowered(
                f"Paparazzi did not lower the {name} filter's energy ({e0:.4g} at the start, "
                f"{e1:.4g} at the end), so nothing was changed: this shape's pictures are "
                f"already close to what the filter makes (flat faces and sharp edges: "
                f"{noisy} of its pixels are in the filter's noise range, and a first small "
                f"step along the filter's pull raised its energy by {100 * float(probe):.0f} "
                f"%). More iterations will not change that; another filter can still change "
                f"the shape.")
        n = getattr(spec, "panel_iterations", 0)
        if iterations is not None and iterations >= max(n, PaparazziParams().iterations):
            raise EnergyNotLowered(
                f"Paparazzi did not lower the filter's energy (the mean over its fixed monitor "
                f"views: {e0:.4g} at the start, {e1:.4g} at the end, and no usable shape "
                f"measured on the way got below the start), so it did not converge and "
                f"nothing was changed. That was a full run ({iterations} iterations): on "
                f"shapes like this (some dense scans and CAD models) more iterations or a "
                f"smaller step seldom lower it, so another filter is the better next try: it "
                f"can still change the shape.")
        more = (f" (on a smooth shape the {spec.name} filter's energy rises before it falls: "
                f"give it {n} or more)" if n else "")
        raise EnergyNotLowered(
            f"Paparazzi did not lower the filter's energy (the mean over its fixed monitor "
            f"views: {e0:.4g} at the start, {e1:.4g} at the end, and no usable shape "
            f"measured on the way got below the start), so it did not converge and nothing "
            f"was changed. Try more iterations{more} or another learning rate.")


@dataclass(frozen=True)
class PaparazziParams:
    iterations: int = param(1000, label="Iterations", minimum=1, maximum=100000, step=100,
                            tooltip="How many views to render and filter. The thesis uses "
                                    "1000-3000; more gives a stronger effect.")
    learning_rate: float = param(0.0, label="Learning rate", minimum=0.0, maximum=0.1,
                                 log_scale=True, decimals=7,
                                 tooltip="NAdam step size (in units of the shape normalized to "
                                         "a cube of side 2). 0 = the filter's default (2e-4; "
                                         "guided 1e-5, slic 6e-5, neural-style 1e-3; l0's and "
                                         "neural-style's are smaller on a mesh whose edges "
                                         "are shorter than a 100th of its size, and at thin "
                                         "triangles). Larger moves faster but adds noise and "
                                         "may need more self-intersection rollbacks.")
    rough_step: bool = param(True, label="Larger step on rough scans", advanced=True,
                             tooltip="With the learning rate on auto: if the filter's own pull "
                                     "makes its energy rise at the start (a noisy scan whose "
                                     "noise an edge-preserving filter takes for edges), use the "
                                     "filter's larger step for rough surfaces (guided: 2e-4 "
                                     "instead of 1e-5, smaller in proportion on a mesh whose "
                                     "edges are shorter than a 100th of its size), which "
                                     "carries the surface past that rise to a smooth one.")
    thin_step: bool = param(True, label="Smaller step at thin triangles", advanced=True,
                            tooltip="With the learning rate on auto, for l0 and neural-style: a "
                                    "vertex of a thin triangle takes a step in proportion to "
                                    "the triangle's thinness, so that no facet tilts "
                                    "faster than an equilateral one (on CAD parts full of "
                                    "slivers l0's energy otherwise rises from the start). "
                                    "Off: every "
                                    "vertex takes the same step (before 1 December 2026).")
    plateau_step: bool = param(False, label="Smaller step when the energy climbs", advanced=True,
                               tooltip="Every 50 iterations the monitor energy is checked; once "
                                       "the run has lowered it, a rise of more than 2 % above "
                                       "its lowest value halves the step (down to 1/16 of it): "
                                       "the steps have started to add more than they remove. "
                                       "Off by default: it weakened slic on most shapes. "
                                       "Not for neural-style, whose energy is no measure of "
                                       "progress.")
    lowest_fallback: bool = param(True, label="Lowest shape if the energy ends higher",
                                  advanced=True,
                                  tooltip="A run must end with its monitor energy below its "
                                          "start. If the last shape's energy is not (an "
                                          "iterative filter's target moves with the surface, "
                                          "so its energy can climb back up), the result is the "
                                          "measured shape whose energy was lowest; if no shape "
                                          "got below the start, the run did not converge: it "
                                          "fails and changes nothing. Off: always the last "
                                          "shape, whatever its energy.")
    sigma: float = param(0.0, label="Camera offset σ", minimum=0.0, maximum=1.0, decimals=3,
                         tooltip="Distance of the camera cage from the shape (shape in a cube of "
                                 "side 2). 0 = the filter's default (0.1).")
    resolution: int = param(0, label="Resolution", minimum=0, maximum=1024, step=32,
                            tooltip="Rendered image size in pixels. 0 = the filter's default "
                                    "(128 or 256).")
    view_width: float = param(0.0, label="View width", minimum=0.0, maximum=4.0, decimals=3,
                              tooltip="Width of the orthographic view. 0 = the filter's default "
                                      "(0.5; SLIC 1.0).")
    remesh_every: int = param(30, label="Remesh every", minimum=0, maximum=10000, step=10,
                              tooltip="Remesh and check for self-intersections every this many "
                                      "iterations (0 = only check at the end).")
    remesh_threshold: float = param(0.0, label="Remesh threshold", minimum=0.0, maximum=1.0,
                                    decimals=3, advanced=True,
                                    tooltip="0 = remesh at every check, as the thesis does. "
                                            "Above 0: remesh only when more than this share of "
                                            "the edges is too long or too short (outside 4/5-4/3 "
                                            "of the target length); faster, but the result is "
                                            "rougher (e.g. 0.05).")
    remesh_scope: str = param("bad", label="Remesh triangles", choices=REMESH_SCOPES,
                              advanced=True,
                              tooltip="Which vertices a remeshing may move. 'bad' (default): "
                                      "only those next to a bad element (an edge shorter than "
                                      "half or longer than twice the target length, or a "
                                      "triangle with an angle below 20 degrees) that the run "
                                      "made worse than it was, as El Topo, the thesis's "
                                      "remesher, changes only bad elements; "
                                      "'all': every vertex (the whole surface re-placed).")
    remesh_spoiled_only: bool = param(True, label="Only what the run spoiled", advanced=True,
                                      tooltip="With 'bad': a triangle counts as bad only once "
                                              "the run has made it worse than it was when it "
                                              "was made (in your mesh or by a remeshing), so "
                                              "your own long thin triangles (a CAD model's) "
                                              "stay as they came. Off: every bad triangle is "
                                              "remade, your own too (before 30 November 2026).")
    put_back_crossing_only: bool = param(
        True, label="Put back only the crossing triangles", advanced=True,
        tooltip="Where the steps made the surface cross itself, put back only the corners of "
                "the triangles that cross (and of any that then still cross) where they were "
                "at the last check, and let them move again. Off: put back the surface within "
                "4 edge lengths of the crossings, hold it still for the rest of the run and "
                "halve the step when it crosses there again (before 1 December 2026; on a "
                "noisy scan that held most of the surface still).")
    remesh_iterations: int = param(1, label="Remesh passes", minimum=1, maximum=20, advanced=True,
                                   tooltip="Split/collapse/flip/relax passes per remeshing.")
    monitor_every: int = param(25, label="Monitor every", minimum=0, maximum=10000,
                               advanced=True,
                               tooltip="Evaluate the monitor energy (the mean over the fixed "
                                       "monitor views) every this many iterations (0 = only at "
                                       "the start and the end).")
    monitor_views: int = param(16, label="Monitor views", minimum=1, maximum=256, advanced=True,
                               tooltip="How many fixed views, spread all around the shape, the "
                                       "monitor energy is averaged over (one filter call each "
                                       "per evaluation).")
    upsample_vertices: int = param(0, label="Upsample to", minimum=0, maximum=2_000_000,
                                   step=10000, advanced=True,
                                   tooltip="Loop-subdivide the input until it has at least this "
                                           "many vertices (0 = no upsampling; the thesis uses "
                                           "10^5-10^6).")
    seed: int = param(0, label="Seed", minimum=0, maximum=2**31 - 1,
                      tooltip="Random seed of the camera sampling: the same seed gives the "
                              "same result.")


@dataclass
class PaparazziStep(Step):
    """A :class:`Step` that also carries the (possibly remeshed) faces and the last view."""

    F: np.ndarray | None = None
    image: np.ndarray | None = None
    filtered: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)


def _remesh_core(V, F, iterations: int, h: float, n_fixed: int, creases) -> tuple:
    """gpytoolbox's ``remesh_botsch`` C++ core (fixed vertices first)."""
    from gpytoolbox_bindings import _remesh_botsch_cpp_impl

    U, G = _remesh_botsch_cpp_impl(np.ascontiguousarray(V, np.float64),
                                   np.ascontiguousarray(F, np.int32), int(iterations), float(h),
                                   np.arange(n_fixed, dtype=np.int32),
                                   np.ascontiguousarray(creases, np.int32), True)
    return np.ascontiguousarray(U, np.float64), np.ascontiguousarray(G, np.int64)


@dataclass
class _Remeshed:
    """What a remeshing of ``V`` changed: only the vertices ``moved`` of ``V`` may have moved
    or gone, and its triangles ``old_faces`` (indices of ``V``) became ``new_faces`` (indices of
    the result); the result's vertices before ``start`` are ``V``'s others, in order
    (``to_new``: each vertex of ``V``'s index in the result, -1 for ``moved``), and those from
    ``start`` on are new. A whole-mesh remeshing: all of them (``start`` 0, no ``to_new``).
    ``smallest_angle``: the smallest angle (degrees) of ``V``'s triangles, where the search for
    bad elements measured it (None: not measured)."""

    V: np.ndarray
    moved: np.ndarray
    start: int
    old_faces: np.ndarray
    new_faces: np.ndarray
    to_new: np.ndarray | None = None
    smallest_angle: float | None = None
    #: which of ``V``'s triangles (the rows of the mesh handed in) the result keeps, in order,
    #: as its first rows (None: none, a whole-mesh remeshing)
    kept_faces: np.ndarray | None = None


def _topology(F) -> tuple[int, int, bool]:
    from ..mesh.topology import boundary_loops, euler_characteristic, is_manifold

    return euler_characteristic(F), len(boundary_loops(F)), is_manifold(F)


class Paparazzi:
    """One Paparazzi run: precomputes the normalization, offset surface and filter state.

    Parameters
    ----------
    V, F : the input mesh (a 2-manifold; boundaries allowed).
    filter : a registered filter name or :class:`FilterSpec`.
    filter_params : that filter's Params (default: its defaults).
    params : :class:`PaparazziParams`.
    """

    def __init__(self, V, F, filter: str | FilterSpec = "guided", filter_params: Any = None,
                 params: PaparazziParams | None = None):
        self.params = validate_params(params or PaparazziParams())
        self.spec = get_filter(filter) if isinstance(filter, str) else filter
        self.filter_params = validate_params(filter_params if filter_params is not None
                                             else self.spec.params())
        if not isinstance(self.filter_params, self.spec.params):
            raise ParameterError(f"The {self.spec.name} filter expects {self.spec.params.__name__} "
                                 f"parameters.")
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        self._check_input(V, F)
        from ..mesh.operators import normalize_unit_box

        Vu, self.center, scale = normalize_unit_box(V)
        self.scale = scale / 2.0            # world = V_opt * self.scale + center
        V0 = Vu * 2.0
        F0 = F.copy()
        p = self.params
        if p.upsample_vertices and len(V0) < p.upsample_vertices:
            from ..mesh.subdivision import loop_subdivide

            while len(V0) < p.upsample_vertices:
                V0, F0 = loop_subdivide(V0, F0, 1)
        self.V0, self.F0 = V0, F0
        self.topology = _topology(F0)
        import igl

        self.edge_length = float(igl.edge_lengths(V0, F0).mean())
        self.input_intersections = count_self_intersections(V0, F0)
        self._crossings_tree = None
        #: what the last remeshing changed (see :meth:`_remesh`)
        self.remeshed: _Remeshed | None = None
        #: during :meth:`steps`, :meth:`face_shape` of each triangle when it was made (in the
        #: input or by a remeshing): a remeshing changes only what the run has made worse
        #: (``WORSE_FACTOR``)
        self.baseline: np.ndarray | None = None
        if self.input_intersections:
            from scipy.spatial import cKDTree

            self._crossings_tree = cKDTree(V0[F0[_intersecting_pairs(V0, F0).ravel()]].mean(1))
        self.resolution = p.resolution or self.spec.resolution
        self.width = p.view_width or self.spec.width
        self.sigma = p.sigma or self.spec.sigma
        self.learning_rate = p.learning_rate or self.default_step()
        self.rough: float | None = None     # rough_probe's value at the start of steps()
        self.rough_share: float | None = None   # noise_share's value, where the probe rose
        self.single_view = self.spec.is_single_view(self.filter_params)
        self.shading = self.spec.make_shading(self.filter_params)
        info = {"normalize": lambda X: (np.asarray(X, float) - self.center) / self.scale,
                "resolution": self.resolution}
        self.state = (self.spec.prepare(self.filter_params, info)
                      if self.spec.prepare is not None else None)
        self.offset: OffsetSurface | None = None
        if not self.single_view:
            self.offset = offset_surface(V0, F0, self.sigma)

    @staticmethod
    def _check_input(V, F) -> None:
        from ..mesh.topology import is_manifold

        if V.ndim != 2 or V.shape[1] != 3 or len(V) < 4 or F.ndim != 2 or F.shape[1] != 3 \
                or len(F) < 4:
            raise InvalidMeshError("Paparazzi needs a triangle mesh with at least 4 triangles.")
        if not np.isfinite(V).all() or F.min() < 0 or F.max() >= len(V):
            raise InvalidMeshError("The mesh has invalid coordinates or face indices; clean it "
                                   "first (stylize3d clean, or Clean in the app).")
        if not is_manifold(F):
            raise InvalidMeshError(
                "Paparazzi needs a 2-manifold mesh (every edge shared by at most two triangles, "
                "every vertex with a single fan of triangles), because it remeshes the surface "
                "as it goes. This mesh is not; run Clean (stylize3d clean) first.")

    # -------------------------------------------------------------------- pieces
    def to_world(self, X) -> np.ndarray:
        return np.asarray(X) * self.scale + self.center

    def camera(self, rng: np.random.Generator):
        if self.single_view:
            return front_camera(self.resolution)
        return sample_camera(self.offset, rng, width=self.width, resolution=self.resolution)

    def _context(self, r, camera):
        ctx = FilterContext(camera=camera, mask=r.mask, state=self.state)

        def render_other(VT, FT):
            o = render(VT, FT, camera, self.shading)
            ctx.other_mask = o.mask
            return o.image
        ctx.render_other = render_other
        return ctx

    def monitor_cameras(self) -> list:
        """The fixed monitor views (module docstring): the front view for a single-view filter,
        else ``params.monitor_views`` views spread over the offset surface, drawn from their own
        seeded stream (``[seed, 1]``), so they do not depend on the run's cameras."""
        if self.single_view:
            return [front_camera(self.resolution)]
        return monitor_cameras(self.offset, self.params.monitor_views,
                               np.random.default_rng([self.params.seed, 1]),
                               width=self.width, resolution=self.resolution)

    def monitor_energy(self, V, F, cameras=None, renders: list | None = None) -> float:
        """Mean energy of the monitor views for ``(V, F)`` in the optimizer's frame (``E`` of an
        energy filter, ``1/2 |f(R) - R|^2`` over the foreground of an iterative one); the
        views' renderings are appended to ``renders`` when given."""
        return self._monitor_pass(V, F, cameras, renders, pull=False)[0]

    def _monitor_pass(self, V, F, cameras, renders: list | None, pull: bool):
        """(mean energy over the monitor views, with ``pull`` the summed image derivative with
        respect to ``V`` else None); the renderings are appended to ``renders`` when given."""
        cams = self.monitor_cameras() if cameras is None else cameras
        g = np.zeros_like(V) if pull else None
        energies = []
        workers = self.view_threads(len(cams))
        with ThreadPoolExecutor(workers) if workers > 1 else nullcontext() as pool:
            # the views side by side (FilterSpec.parallel_views), their results taken in the
            # views' order: the same numbers, added in the same order, as one view at a time
            results = (pool.map(lambda c: self.evaluate(V, F, c), cams) if pool is not None
                       else (self.evaluate(V, F, c) for c in cams))
            for E, G, r, _ in results:
                if renders is not None:
                    renders.append(r)
                energies.append(E)
                if pull:
                    g += image_vjp(V, F, r, G)
        return float(np.mean(energies)), g

    def view_threads(self, views: int) -> int:
        """How many of ``views`` monitor views are rendered and filtered at once: Numba's
        thread count for the calling thread (``OMP_NUM_THREADS``; 1 in a batch worker or a
        benchmark worker given one thread) for a filter that allows it
        (``FilterSpec.parallel_views``), else 1. Rendering and the built-in filters release
        Python's lock (compiled kernels, FFTs, scikit-image), so two views take about 0.55 of
        the time of one after the other (16 views of the corpus skull, 2 threads: l0 0.38 ->
        0.21 s, slic 0.78 -> 0.44 s; docs/results/paparazzi.md)."""
        if not self.spec.parallel_views or views < 2:
            return 1
        from ..compiled import thread_count

        return max(1, min(int(thread_count()), int(views)))

    @staticmethod
    def change_per_pixel(energy: float, renders: list) -> float:
        """An iterative filter's change of the views ``renders`` whose mean energy is
        ``energy``: the root mean square of ``f(R) - R`` per colour channel over their
        foreground pixels (``energy`` is ``1/2`` its sum of squares per view)."""
        count = sum(int(r.mask.sum()) * r.image.shape[-1] for r in renders)
        return float(np.sqrt(2.0 * energy * len(renders) / count)) if count else 0.0

    def default_step(self) -> float:
        """The filter's step for this mesh (the run's learning rate on auto): its
        ``learning_rate``, shrunk in proportion to the mean edge below ``ROUGH_EDGE`` for a
        filter with ``step_follows_edge`` (l0, neural-style)."""
        lr = self.spec.step(self.filter_params)
        return lr * self.edge_factor() if self.spec.step_follows_edge else lr

    def thin_factors(self, V, F) -> np.ndarray:
        """Per vertex, what a step on auto of a filter with ``step_follows_edge`` (l0,
        neural-style) is scaled by beyond :meth:`edge_factor`: ``min(1, a / (sqrt(3)/2
        min(ROUGH_EDGE, mean edge)))``, ``a`` the smallest altitude of the vertex's triangles
        (0 for a degenerate one: its vertex stays). A triangle's normal turns by about a step
        over its altitude, so a step that suits an equilateral triangle of the mesh's mean edge
        (or of ``ROUGH_EDGE``, where :meth:`edge_factor` shrank the step) turns a sliver's
        normal by far more: NAdam moves every vertex by about the learning rate whatever its
        pull, and on sliver-laden CAD parts l0's energy rose from the first steps (conrod +24 %
        in 25 steps at a tenth of the step) and the run failed. With this factor no vertex's
        triangles turn faster than an equilateral one's (issue 38; docs/results/paparazzi.md,
        "l0's step on thin triangles"). A vertex of no triangle keeps the full step."""
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        longest = np.maximum(np.maximum(np.linalg.norm(b - c, axis=1),
                                        np.linalg.norm(c - a, axis=1)),
                             np.linalg.norm(a - b, axis=1))
        twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        altitude = np.divide(twice_area, longest, out=np.zeros_like(twice_area),
                             where=longest > 0)
        smallest = np.full(len(V), np.inf)
        for k in range(3):
            np.minimum.at(smallest, F[:, k], altitude)
        scale = 0.5 * np.sqrt(3.0) * min(ROUGH_EDGE, self.edge_length)
        return np.minimum(1.0, smallest / scale)

    def edge_factor(self) -> float:
        """``min(1, mean edge / ROUGH_EDGE)``: what a step on auto is scaled by on a fine mesh
        (l0's and neural-style's own step, and every filter's rough step)."""
        return min(1.0, self.edge_length / ROUGH_EDGE)

    @property
    def fine_step(self) -> bool:
        """Whether this run's step on auto was shrunk for a fine mesh (:meth:`default_step`)."""
        return (not self.params.learning_rate and not self.rough_input
                and self.learning_rate < self.spec.step(self.filter_params))

    def require_something_to_filter(self, energy: float, renders: list) -> None:
        """Raise :class:`NothingToFilter` when an iterative filter changes the monitor views
        ``renders`` (mean energy ``energy``) by less than its ``min_change``
        (:class:`~algorithms.paparazzi.filters.FilterSpec`)."""
        spec = self.spec
        if spec.kind != "iterative" or not spec.min_change > 0:
            return
        change = self.change_per_pixel(energy, renders)
        if change < spec.min_change:
            grey = 255.0 * change
            raise NothingToFilter(
                f"Nothing was changed: this shape already looks the way the {spec.name} filter "
                f"makes pictures look. Filtering its {len(renders)} monitor views changes them "
                f"by {grey:.2g} of a grey level on average (less than "
                f"{255.0 * spec.min_change:.2g}), so there is nothing visible for it to do, "
                f"and its steps would only add noise. Another filter can still change the "
                f"shape (quantize, which turns faces to 20 directions, does on such shapes).")

    def monitor_pull(self, V, F, cameras=None, renders: list | None = None
                     ) -> tuple[float, np.ndarray]:
        """(:meth:`monitor_energy`, the filter's pull summed over the same views): the mean
        energy and its full-batch gradient with respect to ``V``, from one pass over the views
        (whose renderings are appended to ``renders`` when given)."""
        return self._monitor_pass(V, F, cameras, renders, pull=True)

    def rough_probe(self, V, F, cameras=None, free=None, start=None) -> float:
        """Relative change of the monitor energy after one small step along the filter's own
        pull summed over the monitor views (the full-batch update direction; the vertex that
        moves most moves ``edge_length / 32``; ``free``: the vertices that may move; ``start``:
        :meth:`monitor_pull` of ``V`` when the caller has it already). Above 0 the input is
        *rough* for this filter: its pull raises its own energy there. Measured (guided, issue
        23's fifth pass, 16 views; benchmarks/paparazzi_effects.py --barrier): fandisk, bob,
        bumpy, pretzel -1.9 % to -20 % clean, -1.8 % to -2.5 % with 0.1 mean edge lengths of
        noise (there the energy falls at the filter's own step), +0.03 % to +1.2 % with 0.2
        and 0.3 (docs/results/paparazzi.md, "Rough scans")."""
        cams = self.monitor_cameras() if cameras is None else cameras
        e0, g = start if start is not None else self.monitor_pull(V, F, cams)
        g = g.copy()
        if free is not None:
            g[~free] = 0.0
        top = float(np.linalg.norm(g, axis=1).max())
        if not (top > 0.0 and e0 > 0.0):
            return 0.0
        step = g * (self.edge_length / 32.0 / top)
        return (self.monitor_energy(V - step, F, cams) - e0) / e0

    def noise_share(self, V, F, cameras=None, renders: list | None = None) -> float | None:
        """The share of the shape's pixels over the monitor views that the filter takes for
        noise or edges (``FilterSpec.noise_pixels``), or None for a filter without that test;
        ``renders``: those views' renderings of ``V`` when the caller has them
        (:meth:`monitor_pull`)."""
        test = self.spec.noise_pixels
        if test is None:
            return None
        if renders is None:
            cams = self.monitor_cameras() if cameras is None else cameras
            renders = [render(V, F, c, self.shading) for c in cams]
        hits = total = 0
        for r in renders:
            h, n = test(r.image, r.mask, self.filter_params)
            hits, total = hits + h, total + n
        return hits / total if total else 0.0

    @property
    def rough_input(self) -> bool:
        """Whether this run took its filter's rough step: :meth:`rough_probe` above 0 and, for a
        filter with a noise test, :meth:`noise_share` at least :data:`ROUGH_SHARE`."""
        return (self.rough is not None and self.rough > 0
                and (self.rough_share is None or self.rough_share >= ROUGH_SHARE))

    def evaluate(self, V, F, camera):
        """(energy, dE/dR, rendering, filtered image or None) for one view."""
        r = render(V, F, camera, self.shading)
        return self._filter(r, self._context(r, camera))

    def _remesh(self, V, F, free):
        """One ``remesh_botsch`` pass through its C++ core (the Python wrapper spends more time
        than the pass itself re-deriving boundary vertices and re-checking manifoldness, which
        the loop keeps as invariants): fixed vertices first, as the core expects.

        With ``remesh_scope`` "bad" only the triangles with a vertex that may move (within one
        ring of a bad element, :meth:`near_bad`) go to the core, with their other vertices
        fixed: the rest of the surface is left as it is, bit for bit, and the pass costs in
        proportion to the part it changes (a few % of a 50k-vertex scan after the first
        remeshings). The core left triangles between fixed vertices as they were anyway
        (checked on the corpus skull: all 826 of them kept when the whole mesh went in), so the
        result is the same surface. Where the core changed the patch's border (an edge
        between two fixed vertices split), the whole mesh is remeshed instead, as before.
        ``self.remeshed`` says what changed (:class:`_Remeshed`), for the checks that follow to
        look there only."""
        n = len(V)
        low = None
        if self.params.remesh_scope == "bad":
            near, low = self._bad_elements(V, F, self.baseline if (
                self.params.remesh_spoiled_only and self.baseline is not None
                and len(self.baseline) == len(F)) else None)
            free = free & near
            if not free.any():
                self.remeshed = _Remeshed(V, np.zeros(0, np.int64), n, F[:0], F[:0],
                                          smallest_angle=low,
                                          kept_faces=np.ones(len(F), dtype=bool))
                return V, F
            patch = self._remesh_patch(V, F, free)
            if patch is not None:
                self.remeshed.smallest_angle = low
                return patch
        U, G = self._remesh_core_call(V, F, free)
        self.remeshed = _Remeshed(V, np.flatnonzero(free[:n]), 0, F, G, smallest_angle=low)
        return U, G

    def _creases(self, V, F) -> np.ndarray:
        # a piecewise-planar filter's creases (FilterSpec.crease_angle) survive the remeshing:
        # without it the remeshing alone rounded fandisk's edges (near-planar area 0.75 -> 0.63
        # in 1000 iterations; with it 0.75 -> 0.75, and l0 0.75 -> 0.77 instead of -> 0.67).
        # Not on an input that already crosses itself: on camelhead (lips 3-4 % of an edge
        # apart) creases that may be neither flipped nor collapsed made the remeshings cross the
        # surface again and again (l0: 13 of 33 rejected, 80 crossing pairs left by the lips)
        angle = float(getattr(self.spec, "crease_angle", 0.0) or 0.0)
        return (crease_edges(V, F, angle) if angle > 0 and self._crossings_tree is None
                else np.zeros((0, 2), np.int64))

    def _remesh_core_call(self, V, F, free, creases=None):
        """The core on the whole of (V, F), the vertices not ``free`` fixed."""
        n = len(V)
        creases = self._creases(V, F) if creases is None else creases
        fixed = np.flatnonzero(~free[:n]).astype(np.int32)
        if len(fixed):
            order = np.concatenate([fixed, np.flatnonzero(free[:n])]).astype(np.int32)
            inverse = np.empty(n, np.int32)
            inverse[order] = np.arange(n, dtype=np.int32)
            V = V[order]
            F = inverse[F]
            creases = inverse[creases]
        # the core keeps Python's lock for the whole pass (~90 ms on 14.6k vertices): in the
        # desktop app it runs in the helper process (algorithms.offload), same result
        return offload.call(_remesh_core, np.ascontiguousarray(V, np.float64),
                            np.ascontiguousarray(F, np.int32), int(self.params.remesh_iterations),
                            float(self.edge_length), len(fixed),
                            np.ascontiguousarray(creases, np.int32))

    def _remesh_patch(self, V, F, free):
        """:meth:`_remesh` on the triangles with a ``free`` vertex only, stitched back; None
        where the core changed the patch's border."""
        n = len(V)
        inside = free[F].any(axis=1)
        PF, rest = F[inside], F[~inside]
        verts = np.unique(PF)
        # every triangle of a free vertex is in the patch, so its border has fixed ones only
        fixed, moving = verts[~free[verts]], verts[free[verts]]
        local = np.full(n, -1, np.int64)
        local[fixed] = np.arange(len(fixed))
        local[moving] = len(fixed) + np.arange(len(moving))
        # the creases among the patch's vertices, found on the triangles that touch them (an
        # edge between two of them has both its triangles there): the same edges, in the same
        # order, as on the whole mesh, at the cost of the part
        touch = np.zeros(n, dtype=bool)
        touch[verts] = True
        creases = self._creases(V, F[touch[F].any(axis=1)])
        if len(creases):
            creases = local[creases]
            creases = creases[(creases >= 0).all(axis=1)]
        PV = np.concatenate([V[fixed], V[moving]])
        U, G = self._remesh_core_call(PV, local[PF], np.arange(len(PV)) >= len(fixed), creases)
        if not np.array_equal(U[:len(fixed)], PV[:len(fixed)]):
            return None
        keep = np.ones(n, dtype=bool)
        keep[moving] = False
        start = int(keep.sum())
        to_new = np.full(n, -1, np.int64)
        to_new[keep] = np.arange(start)
        of_local = np.concatenate([to_new[fixed], start + np.arange(len(U) - len(fixed))])
        G = of_local[G]
        # the patch's border (edges of one patch triangle: the seam with the rest, and the
        # mesh's own border there) must come out as it went in
        from ..mesh.topology import boundary_edges

        def keys(E):
            E = np.sort(E, axis=1)
            return E[:, 0] * (start + len(U)) + E[:, 1]

        border = to_new[boundary_edges(PF)]
        if len(border) and not np.isin(keys(border), keys(np.concatenate(
                [G[:, [0, 1]], G[:, [1, 2]], G[:, [2, 0]]]))).all():
            return None
        G = G.astype(np.int64)
        self.remeshed = _Remeshed(V, moving, start, PF, G, to_new, kept_faces=~inside)
        return np.concatenate([V[keep], U[len(fixed):]]), np.concatenate([to_new[rest], G])

    def near_bad(self, V, F, baseline=None) -> np.ndarray:
        """Vertices within one ring of a bad element: an edge outside ``BAD_EDGE_BAND`` times the
        target edge length, or a triangle with an angle below ``BAD_ANGLE`` degrees; with a
        ``baseline`` (:meth:`face_shape` of each triangle when it was made), only those the
        run has made worse since (``WORSE_FACTOR``)."""
        return self._bad_elements(V, F, baseline)[0]

    @staticmethod
    def face_shape(V, F) -> np.ndarray:
        """Per triangle: the lengths of its edges (0, 1), (1, 2), (2, 0) and its smallest angle
        in degrees (NaN where it has no area)."""
        import igl

        V = np.asarray(V, np.float64)
        F = np.asarray(F, np.int64)
        out = np.empty((len(F), 4))
        for k in range(3):
            out[:, k] = np.linalg.norm(V[F[:, k]] - V[F[:, (k + 1) % 3]], axis=1)
        if len(F):
            out[:, 3] = np.degrees(np.asarray(igl.internal_angles(V, F))).min(axis=1)
        return out

    def carry_baseline(self, V, F) -> None:
        """After an accepted remeshing into (V, F): the triangles it kept keep their
        :attr:`baseline`, the ones it made get their shape now."""
        done, old = self.remeshed, self.baseline
        if old is None:
            return
        kept = (old[done.kept_faces] if done is not None and done.kept_faces is not None
                and len(done.kept_faces) == len(old) else old[:0])
        self.baseline = np.concatenate([kept, self.face_shape(V, F[len(kept):])])

    def _bad_elements(self, V, F, baseline=None) -> tuple[np.ndarray, float]:
        """(:meth:`near_bad`, the smallest angle of the triangles in degrees, NaN counted as 0:
        the floor of the remeshing's check for nearly flat triangles, from the same angles)."""
        now = self.face_shape(V, F)
        F = np.asarray(F, np.int64)
        lo, hi = BAD_EDGE_BAND
        h = self.edge_length
        L, smallest = now[:, :3], now[:, 3]
        short, long_ = L < lo * h, L > hi * h
        small = ~(smallest >= BAD_ANGLE)                  # NaN: bad
        if baseline is not None:
            short &= L < WORSE_FACTOR * baseline[:, :3]
            long_ &= L * WORSE_FACTOR > baseline[:, :3]
            small &= ~(smallest >= WORSE_FACTOR * baseline[:, 3]) | (smallest < DEGENERATE_ANGLE)
        bad = np.zeros(len(V), dtype=bool)
        edge = short | long_
        for k in range(3):
            bad[F[edge[:, k], k]] = True
            bad[F[edge[:, k], (k + 1) % 3]] = True
        bad[F[small].ravel()] = True
        ring = bad.copy()
        ring[F[bad[F].any(axis=1)].ravel()] = True
        low = float(np.where(np.isfinite(smallest), smallest, 0.0).min()) if len(F) else 0.0
        return ring, low

    def band_fraction(self, V, F) -> float:
        """Share of the edges outside ``[4/5 h, 4/3 h]`` (the ones remeshing would change)."""
        E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)   # interior edges twice: same share
        h = self.edge_length
        return float(np.count_nonzero((L < 0.8 * h) | (L > 4.0 / 3.0 * h)) / max(1, len(L)))

    def _new_crossings(self, V, F) -> int:
        """Intersecting face pairs (libigl, exact) that are new: for a clean input all of them;
        for an input that intersects itself, those with a face farther than 4 target edge
        lengths from every face the input's intersections involve (remeshing or moving an
        existing intersection changes how many pairs it has, not where it is)."""
        return len(self._new_crossing_points(V, F)) // 2

    def _new_crossing_points(self, V, F, IF=None) -> np.ndarray:
        """``(2 k, 3)``: the centroids of both faces of each of the ``k`` new intersecting
        pairs (see :meth:`_new_crossings`); ``IF``: the intersecting pairs of (V, F), when
        known."""
        return self._pair_points(V, F, self._new_pairs(
            V, F, _intersecting_pairs(V, F) if IF is None else IF))

    @staticmethod
    def _pair_points(V, F, pairs) -> np.ndarray:
        """``(2 k, 3)``: the centroids of both faces of each of the ``k`` face ``pairs``."""
        return V[F[pairs.ravel()]].mean(1) if len(pairs) else np.zeros((0, 3))

    def _remeshing_crossing_points(self, V, U, G) -> np.ndarray:
        """:meth:`_new_crossing_points` of a remeshing (U, G) of ``V``, a surface with no new
        crossings. After a remeshing of a part (:meth:`_remesh_patch`) the rest's triangles are
        ``V``'s, bit for bit, so their pairs with each other are not new either: only pairs
        with a triangle of the part are looked for (the same answer as the whole mesh's, in a
        fraction of the time)."""
        done = self.remeshed
        if done is None or done.V is not V or done.start == 0:
            return self._new_crossing_points(U, G)
        part = np.arange(len(G) - len(done.new_faces), len(G))
        return self._new_crossing_points(U, G, _intersecting_pairs_touching(U, G, part))

    def _drift_points(self, V, F, U, G) -> np.ndarray:
        """Where a remeshing moved the surface rather than resampling it: the vertices of the
        mesh before it (V, F) farther than ``DRIFT_TOL`` target edge lengths from the remeshed
        surface (U, G) -- a thin part collapsed, a crease cut off -- and the remeshed vertices
        as far from the surface before. Both distances are exact point-to-triangle distances
        (libigl's AABB tree)."""
        import igl

        tol2 = (DRIFT_TOL * self.edge_length) ** 2
        # after a remeshing of part of the surface (self.remeshed), that part before and after
        # it: the vertices it kept in place lie on both, the rest of the surface is the same
        done = self.remeshed
        P, Q, old, new = V, U, F, G
        if done is not None and done.V is V:
            P, Q, old, new = V[done.moved], U[done.start:], done.old_faces, done.new_faces
        d_old = (igl.point_mesh_squared_distance(P, U, new)[0] if len(P) and len(new)
                 else np.zeros(len(P)))
        d_new = (igl.point_mesh_squared_distance(Q, V, old)[0] if len(Q) and len(old)
                 else np.zeros(len(Q)))
        return np.vstack([P[d_old > tol2], Q[d_new > tol2]])

    def _same_topology(self, V, G) -> bool:
        """Whether the remeshing of ``V`` to faces ``G`` kept a 2-manifold with the input's
        Euler characteristic and boundary loops. After a remeshing of part of the surface whose
        border came out as it went in (:meth:`_remesh_patch`), the part decides: the whole
        changes its Euler characteristic by as much as the part does and keeps its boundary
        when the part keeps its border edges; and it stays a manifold when every edge of the
        part has at most two triangles and the triangles around each of the part's vertices
        (the part's and the rest's that touch it) still form one fan."""
        from ..mesh.topology import (boundary_edges, euler_characteristic, is_edge_manifold,
                                     nonmanifold_vertices)

        done = self.remeshed
        if done is None or done.V is not V or done.start == 0:
            try:
                return _topology(G) == self.topology
            except InvalidMeshError:      # an edge of three triangles: not a manifold
                return False
        old, new = done.old_faces, done.new_faces
        if not len(old):
            return True

        def border(E):
            E = np.sort(np.asarray(E, np.int64).reshape(-1, 2), axis=1)
            return np.unique(E[:, 0] * (int(G.max()) + 1) + E[:, 1])
        touched = np.zeros(int(G.max()) + 1, dtype=bool)
        touched[new.ravel()] = True
        ring = G[touched[G].any(axis=1)]       # the part and the rest's triangles touching it
        if not is_edge_manifold(ring) or touched[nonmanifold_vertices(ring)].any():
            return False
        return (euler_characteristic(new) == euler_characteristic(old)
                and np.array_equal(border(boundary_edges(new)),
                                   border(done.to_new[boundary_edges(old)])))

    def _degenerate_points(self, V, F, U, G) -> np.ndarray:
        """The centroids of the triangles of the remeshed (U, G) whose smallest angle is below
        :data:`DEGENERATE_ANGLE` degrees and below the smallest of the mesh before it (V, F): the
        remesher can leave three nearly collinear vertices (nefertiti of the corpus, remeshing
        alone: 2 triangles with a smallest angle of 2e-13 degrees after the second remeshing,
        10 by the end of 1000 iterations; held for zero area only, a 3e-7-degree sliver was
        left), whose cotangent weights are infinite or huge for every later method."""
        import igl

        def smallest(X, T):
            a = np.degrees(np.asarray(igl.internal_angles(X, T))).min(axis=1)
            return np.where(np.isfinite(a), a, 0.0)

        done = self.remeshed
        mine = done is not None and done.V is V      # the record of this remeshing of (V, F)
        low = (done.smallest_angle if mine and done.smallest_angle is not None
               else float(smallest(V, F).min()) if len(F) else 0.0)
        floor = min(DEGENERATE_ANGLE, low)
        # after a remeshing of a part (self.remeshed) the other triangles are V's own, whose
        # angles are all at least the floor: only the part's new ones (G's last rows) can fail
        T = G
        if mine and done.start > 0:
            T = G[len(G) - len(done.new_faces):]
        bad = smallest(U, T) < floor
        return U[T[bad]].mean(axis=1) if bad.any() else np.zeros((0, 3))

    def _put_back(self, V, F, before, spots, pairs=None) -> np.ndarray | None:
        """``V`` with the vertices within :data:`HOLD_RADIUS` target edge lengths of ``spots``
        (new crossings; in ``V`` or in ``before``) put back at ``before`` (the last checked
        positions, same triangles ``F``), or None when that still leaves new crossings (the
        caller then rolls the whole mesh back). ``pairs``: ``V``'s intersecting pairs, when
        known: then only the triangles with a vertex put back are tested again."""
        back = self._near(V, spots) | self._near(before, spots)
        U = V.copy()
        U[back] = before[back]
        if pairs is None:
            return None if len(self._new_crossing_points(U, F)) else U
        moved = back[F].any(axis=1)
        kept = pairs[~moved[pairs].any(axis=1)] if len(pairs) else pairs
        IF = np.concatenate([kept, _intersecting_pairs_touching(U, F, moved)])
        return None if len(self._new_crossing_points(U, F, IF)) else U

    def _new_pairs(self, V, F, IF) -> np.ndarray:
        """The rows of ``IF`` (intersecting pairs of ``(V, F)``) that are new crossings (see
        :meth:`_new_crossings`)."""
        if not len(IF) or self._crossings_tree is None:
            return IF
        # farther than 4 edge lengths: no neighbour within them (a bounded search, 2x faster)
        d, _ = self._crossings_tree.query(V[F[IF.ravel()]].mean(1),
                                          distance_upper_bound=4.0 * self.edge_length)
        return IF[np.isinf(d).reshape(-1, 2).any(axis=1)]

    def _put_back_crossing(self, V, F, before, new) -> tuple[np.ndarray | None, np.ndarray]:
        """``PaparazziParams.put_back_crossing_only``: ``(U, back)``, ``V`` with the corners of
        its new crossing triangles put back at ``before`` (the last checked positions, same
        triangles ``F``, free of new crossings), then the corners of any triangles that still
        cross, up to :data:`PUT_BACK_ROUNDS` times; ``U`` is None if crossings remain (the
        caller then falls back to putting back everything within :data:`HOLD_RADIUS`).
        ``new``: ``V``'s new intersecting pairs (:meth:`_new_pairs`). Growing by the crossing
        triangles only, not by rings, matters: on a noisy scan the border between put-back and
        moved vertices folds anew wherever it runs (the sliver scan: a ring a round grew to 88k
        of 156k vertices in 8 rounds, still crossing; the crossing corners alone, 3,190
        vertices, then 3,228, were clean after one round)."""
        back = np.zeros(len(V), dtype=bool)
        back[F[new].ravel()] = True
        U = V.copy()
        added = back.copy()
        # the intersecting pairs of U with a triangle whose corners went back: only those can be
        # new (V's new pairs all have one; a pair of triangles that kept their corners is as in
        # V), and each round re-tests only the triangles whose corners it moved
        touching = np.zeros((0, 2), dtype=np.int64)
        for _ in range(PUT_BACK_ROUNDS):
            U[added] = before[added]
            moved = added[F].any(axis=1)
            touching = np.concatenate([touching[~moved[touching].any(axis=1)],
                                       _intersecting_pairs_touching(U, F, moved)])
            new = self._new_pairs(U, F, touching)
            if not len(new):
                return U, back
            added = np.zeros(len(V), dtype=bool)
            added[F[new].ravel()] = True
            added &= ~back
            if not added.any():          # every corner is back already: nothing left to try
                break
            back |= added
        return None, back

    def _near(self, V, spots) -> np.ndarray:
        """Vertices within :data:`HOLD_RADIUS` target edge lengths of any of ``spots``."""
        if not len(spots):
            return np.zeros(len(V), dtype=bool)
        from scipy.spatial import cKDTree

        r = HOLD_RADIUS * self.edge_length
        # only the vertices in the spots' bounding box grown by the radius can be that close
        box = np.all((V >= spots.min(axis=0) - r) & (V <= spots.max(axis=0) + r), axis=1)
        near = np.zeros(len(V), dtype=bool)
        if box.any():
            from ..compiled import thread_count

            # the queries split over the run's threads (the same answers)
            d, _ = cKDTree(spots).query(V[box], distance_upper_bound=r,
                                        workers=max(1, int(thread_count())))
            near[box] = np.isfinite(d)
        return near

    def new_self_intersections(self, V, F) -> int:
        """:meth:`_new_crossings` of a result in the input's coordinates (``PaparazziStep.V``)."""
        X = (np.asarray(V, dtype=np.float64) - self.center) / self.scale
        return self._new_crossings(X, np.asarray(F, dtype=np.int64))

    # -------------------------------------------------------------------- the loop
    def steps(self) -> Iterator[PaparazziStep]:
        p = self.params
        rng = np.random.default_rng(p.seed)
        monitor_cams = self.monitor_cameras()
        V, F = self.V0.copy(), self.F0.copy()
        good = (V.copy(), F.copy())
        self.baseline = (self.face_shape(V, F) if p.remesh_spoiled_only
                         and p.remesh_scope == "bad" else None)
        m = np.zeros_like(V)
        v = np.zeros_like(V)
        t_adam = 0
        lr_scale = 1.0
        secs = {"render": 0.0, "filter": 0.0, "derivative": 0.0, "remesh": 0.0, "monitor": 0.0}
        counts = {"remeshes": 0, "rollbacks": 0, "rollbacks_whole": 0, "remesh_rejected": 0,
                  "remesh_retries": 0,
                  "remesh_drift_holds": 0, "remesh_degenerate_holds": 0,
                  "put_back_vertices": 0}
        # the step: the run's, else the filter's; on a rough input the filter's rough step
        # (FilterSpec.rough_learning_rate; docs/results/paparazzi.md "Rough scans"), probed below
        # from the same pass over the monitor views as the starting energy
        probing = bool(not p.learning_rate and p.rough_step and self.spec.rough_learning_rate
                       and not self.single_view)
        tm = time.perf_counter()
        renders: list = []
        start = self.monitor_pull(V, F, monitor_cams, renders) if probing else None
        monitor0 = monitor = (start[0] if probing
                              else self.monitor_energy(V, F, monitor_cams, renders))
        secs["monitor"] += time.perf_counter() - tm
        self.require_something_to_filter(monitor0, renders)
        hold = np.zeros((0, 3))          # where steps made the surface cross itself
        remesh_hold = np.zeros((0, 3))   # where a remeshing did

        def movable(V, F):
            held = self._near(V, hold)
            counts["held_vertices"] = int(held.sum())
            return self._free_mask(F, len(V)) & ~held

        counts["held_vertices"] = 0
        free = movable(V, F)
        self.learning_rate = p.learning_rate or self.default_step()
        # FilterSpec.step_follows_edge and PaparazziParams.thin_step: the step on auto is also
        # smaller at the vertices of thin triangles (thin_factors), updated at each crossing
        # check (remeshing, rollback)
        thin = bool(p.thin_step and self.spec.step_follows_edge and not p.learning_rate)
        scale = self.thin_factors(V, F)[:, None] if thin else None
        if thin:
            counts["thin_step_share"] = float(np.mean(scale < 1.0))
        self.rough = self.rough_share = None
        first_message = ""
        if self.fine_step:
            first_message = (f"Fine mesh: its edges are shorter than a 100th of its size, so "
                             f"the {self.spec.name} filter's step is {self.learning_rate:.2g} "
                             f"instead of {self.spec.step(self.filter_params):g}.")
        if probing:
            tm = time.perf_counter()
            self.rough = self.rough_probe(V, F, monitor_cams, free, start)
            if self.rough > 0:
                self.rough_share = self.noise_share(V, F, monitor_cams, renders)
            secs["monitor"] += time.perf_counter() - tm
            if self.rough_input:
                self.learning_rate = self.spec.rough_learning_rate * self.edge_factor()
                first_message = (f"Rough surface: the {self.spec.name} filter's pull first "
                                 f"raises its energy here, so the step is "
                                 f"{self.learning_rate:g} instead of "
                                 f"{self.spec.step(self.filter_params):g}.")
        N = p.iterations
        plateau, lowest = 1.0, monitor0      # PaparazziParams.plateau_step
        # PaparazziParams.lowest_fallback: the lowest monitored shape below the start (energy,
        # iteration, V, F), and the lowest one known free of new crossings (checked in the
        # iteration it was taken); used only if the last shape's energy is not below the start
        best = best_ok = None
        best_checked = False
        end: dict = {}                       # the last step's extra metrics
        counts["step_halvings"] = 0
        for it in range(1, N + 1):
            cam = self.camera(rng)
            t0 = time.perf_counter()
            r = render(V, F, cam, self.shading)
            t1 = time.perf_counter()
            ctx = self._context(r, cam)
            E, G, _, filtered = self._filter(r, ctx)
            t2 = time.perf_counter()
            g = image_vjp(V, F, r, G)
            g[~free] = 0.0
            t3 = time.perf_counter()
            secs["render"] += t1 - t0
            secs["filter"] += t2 - t1
            secs["derivative"] += t3 - t2
            t_adam += 1
            lr = self.learning_rate * lr_scale * plateau * (0.2 if it > 0.9 * N else 1.0)
            d = nadam_step(g, m, v, t_adam, lr)
            V = V - (d if scale is None else d * scale)
            t4 = time.perf_counter()
            secs["derivative"] += t4 - t3
            message = first_message if it == 1 else ""
            crossing_checked = bool((p.remesh_every and it % p.remesh_every == 0) or it == N)
            if crossing_checked:
                tr = time.perf_counter()
                # first the steps' own crossings since the last check (put back or rolled
                # back), then the remeshing of a surface known free of new crossings, so that
                # a remeshing is judged by the crossings it makes (in the part it changed)
                pairs = _intersecting_pairs(V, F)
                new = self._new_pairs(V, F, pairs)
                spots = self._pair_points(V, F, new)
                if len(spots) and p.put_back_crossing_only:
                    U, back = self._put_back_crossing(V, F, good[0], new)
                    if U is not None:
                        # only the crossing triangles' corners go back; they move again from
                        # the next step (first moment cleared, second kept: a small restart)
                        counts["rollbacks"] += 1
                        counts["put_back_vertices"] += int(back.sum())
                        V = U
                        m[back] = 0.0
                        spots = spots[:0]
                        message = (f"self-intersection: put back the {int(back.sum())} "
                                   f"corners of the crossing triangles")
                if len(spots):
                    # crossings where the surface is held already: holding it was not enough
                    shrink = bool(len(hold)) and bool(self._near(spots, hold).any())
                    counts["rollbacks"] += 1
                    U = self._put_back(V, F, good[0], spots, pairs)
                    if U is None:
                        V, F = good[0].copy(), good[1].copy()
                        counts["rollbacks_whole"] += 1
                        message = ("self-intersection: rolled back and held the surface there "
                                   "still")
                    else:
                        V = U
                        message = ("self-intersection: put back the surface there and held "
                                   "it still")
                    hold = np.vstack([hold, spots])
                    if shrink:
                        lr_scale *= 0.5
                        message += "; halved the step"
                    if lr_scale < 1.0 / 1024:
                        # the advice names a value: half the run's step let the corpus's
                        # counter run (quantize, 818 -> 617) where 15 or 60 iterations between
                        # remeshings instead of 30 did not (30 November 2026). On a noisy scan
                        # whose sheets lie closer than an edge it does not (the sliver scan,
                        # neural-style: 1e-3, 5e-4, 2.5e-4 all stop here), but smoothing it
                        # first does (1188 -> 868; 1 December 2026)
                        raise Stylize3DError(
                            f"Paparazzi could not keep the mesh free of self-intersections even "
                            f"with a 1000 times smaller step. Run it again with half the "
                            f"learning rate ({self.learning_rate / 2:g}; command line: "
                            f"--learning-rate {self.learning_rate / 2:g}). If it stops here "
                            f"again, smooth the mesh first (the Smooth panel; command line: "
                            f"stylize3d smooth): on a noisy scan the surface's sheets lie too "
                            f"close for any step.")
                    free = movable(V, F)
                    m = np.zeros_like(V)
                    v = np.zeros_like(V)
                    t_adam = 0
                if p.remesh_every and it < N and (
                        p.remesh_threshold <= 0 or self.band_fraction(V, F) > p.remesh_threshold):
                    counts["remeshes"] += 1
                    accepted = False
                    for _attempt in range(REMESH_ATTEMPTS):
                        U, Gf = self._remesh(V, F, free & ~self._near(V, remesh_hold))
                        if not self._same_topology(V, Gf):
                            break
                        spots = self._remeshing_crossing_points(V, U, Gf)
                        drift = self._drift_points(V, F, U, Gf)
                        if len(drift):
                            counts["remesh_drift_holds"] += 1
                        flat = self._degenerate_points(V, F, U, Gf)
                        if len(flat):
                            counts["remesh_degenerate_holds"] += 1
                        spots = np.vstack([spots, drift, flat])
                        if not len(spots):
                            V, F = U, Gf
                            self.carry_baseline(V, F)
                            accepted = True
                            free = movable(V, F)
                            m = np.zeros_like(V)
                            v = np.zeros_like(V)
                            t_adam = 0
                            break
                        # the remesher made the surface cross itself there (sheets closer than
                        # an edge, e.g. camelhead's lips), or moved it (a thin part or a crease
                        # of a coarse mesh): it keeps those vertices from now on
                        remesh_hold = np.vstack([remesh_hold, spots])
                        counts["remesh_retries"] += 1
                    if not accepted:
                        counts["remesh_rejected"] += 1
                good = (V.copy(), F.copy())
                if thin:
                    scale = self.thin_factors(V, F)[:, None]
                secs["remesh"] += time.perf_counter() - tr
            check = (p.plateau_step and self.spec.halve_on_climb and it % PLATEAU_EVERY == 0
                     and it < N)
            measured = bool((p.monitor_every and it % p.monitor_every == 0) or it == N or check)
            if measured:
                tm = time.perf_counter()
                monitor = self.monitor_energy(V, F, monitor_cams)
                secs["monitor"] += time.perf_counter() - tm
            kept = N
            if p.lowest_fallback and measured and it < N and monitor < (
                    best[0] if best is not None else monitor0):
                if best is not None and best_checked:
                    best_ok = best
                best, best_checked = (monitor, it, V.copy(), F.copy()), crossing_checked
                if best_checked:
                    best_ok = best
            elif p.lowest_fallback and it == N and best is not None and monitor >= monitor0:
                tm = time.perf_counter()
                choice = best
                if not best_checked and len(self._new_crossing_points(best[2], best[3])):
                    choice = best_ok         # that shape crosses itself: the lowest checked one
                if choice is not None and choice[0] < monitor:
                    message = (message + "; " if message else "") + (
                        f"the energy ended above its start ({monitor:.4g} against "
                        f"{monitor0:.4g}): kept the shape of iteration {choice[1]}, whose "
                        f"energy ({choice[0]:.4g}) was the lowest")
                    end["last_monitor_energy"] = monitor
                    monitor, kept, V, F = choice[0], choice[1], choice[2], choice[3]
                secs["monitor"] += time.perf_counter() - tm
            if it == N:
                end.setdefault("last_monitor_energy", monitor)
                end["kept_iteration"] = kept
            if check:
                if monitor < lowest:
                    lowest = monitor
                elif (lowest < monitor0 and monitor > (1.0 + PLATEAU_RISE) * lowest
                      and plateau > PLATEAU_MIN):
                    plateau *= 0.5
                    lowest = monitor
                    counts["step_halvings"] += 1
                    message = (message + "; " if message else "") + (
                        f"the energy climbs again: step halved to {plateau:g} of the start's")
            metrics = {"energy": float(E), "monitor_energy": monitor,
                       "initial_monitor_energy": monitor0, "learning_rate": lr,
                       "monitor_views": float(len(monitor_cams)),
                       "base_learning_rate": self.learning_rate,
                       "rough_input": float(self.rough_input),
                       **({} if self.rough is None else {"rough_probe": self.rough}),
                       **({} if self.rough_share is None else {"rough_share": self.rough_share}),
                       "vertices": float(len(V)), **{k: float(c) for k, c in counts.items()},
                       **{k: float(c) for k, c in end.items()}}
            yield PaparazziStep(it, N, self.to_world(V), metrics, message, F=F.copy(),
                                image=r.image, filtered=filtered if filtered is not None
                                else r.image - G, seconds=dict(secs))

    def _filter(self, r, ctx):
        try:
            out = self.spec.function(r.image, self.filter_params, ctx)
        except Stylize3DError:
            raise
        except Exception as e:  # noqa: BLE001
            raise FilterFailed(f"The image filter '{self.spec.name}' failed: "
                               f"{type(e).__name__}: {e}") from e
        if self.spec.kind == "energy":
            try:
                E, G, *shown = out
                E = float(E)
                G = np.asarray(G, dtype=np.float64).reshape(r.image.shape)
                filtered = (np.asarray(shown[0], dtype=np.float64).reshape(r.image.shape)
                            if len(shown) == 1 else None)
                if len(shown) > 1:
                    raise ValueError("too many values")
            except Exception as e:  # noqa: BLE001
                raise FilterFailed(f"The energy filter '{self.spec.name}' must return (energy, "
                                   f"gradient image of shape {r.image.shape}[, the picture to "
                                   "show as its filtered view]).") from e
        else:
            try:
                filtered = np.asarray(out, dtype=np.float64).reshape(r.image.shape)
            except Exception as e:  # noqa: BLE001
                raise FilterFailed(f"The image filter '{self.spec.name}' must return an image "
                                   f"of shape {r.image.shape}.") from e
            D = filtered - r.image
            D[~r.mask] = 0.0
            E = 0.5 * float((D * D).sum())
            G = -D
        if not (np.isfinite(E) and np.isfinite(G).all()):
            raise FilterFailed(f"The image filter '{self.spec.name}' returned NaN or infinite "
                               "values.")
        return E, G, r, filtered

    def _free_mask(self, F, n: int | None = None) -> np.ndarray:
        from ..mesh.topology import boundary_edges

        n = max(int(F.max()) + 1, n or 0)
        free = np.ones(n, dtype=bool)
        if self.topology[1]:
            free[np.unique(boundary_edges(F).ravel())] = False
        return free


def paparazzi_iter(V, F, filter: str | FilterSpec = "guided", filter_params: Any = None,
                   params: PaparazziParams | None = None) -> Iterator[PaparazziStep]:
    """The house generator form: ``Paparazzi(...).steps()``."""
    return Paparazzi(V, F, filter, filter_params, params).steps()


def paparazzi(V, F, filter: str | FilterSpec = "guided", filter_params: Any = None,
              params: PaparazziParams | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run to the end; returns the output ``(V, F)`` in the input's coordinates."""
    last = None
    for last in paparazzi_iter(V, F, filter, filter_params, params):
        pass
    return last.V, last.F
