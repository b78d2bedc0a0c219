"""Crossings a local-global deformation made, held back where they are (issue 38).

Cubic stylization and shape analogies (thesis ch. 5-6) minimize ARAP plus a normal term and know
nothing of collisions: where two parts of the surface are close (a camel's lips, a helmet's
inner and outer shell, a chair's overlapping parts), the style can push one through the other.
On the 52 meshes of the corpus (docs/results/corpus.md) cubic stylization at its defaults made
new self-intersections on 13.

:func:`hold_where_crossed` runs after the deformation has converged:

1. the self-intersections of the result (libigl, exact predicates) that the input did not have
   are found, leaving out those within two vertex rings of the input's own crossings (where
   sheets already passed through each other, any move shifts the crossing line;
   :func:`~algorithms.mesh.intersections.new_crossings_away_from`);
2. the vertices of the crossing triangles and one ring around them are *held*: put back where
   they were at the latest recorded iterate (every :data:`CHECKPOINT_EVERY` iterations, the
   input first) at which no new crossing touched them, found by bisection;
3. the deformation runs again from its result with those vertices as hard constraints (the
   same energy, one more factorization), so the rest of the surface settles around them;
4. while crossings are left, up to :data:`ROUNDS` times (a bound on the time): the held set
   grows by the new crossings' vertices, and all of it is put back at one iterate
   (constraints taken from different iterates can disagree and tear the surface); the rounds
   go on while the held set
   grows, also after a round that did not lower the count (the next, larger set often does:
   on beast, twirl and cycloidal the first round changed nothing and the later ones removed
   34 of 34, 4 of 4 and 104 of 105 crossings), and the result with the fewest crossings is
   kept;
5. where crossings are still left, the surface around them is blended back towards the input
   (:func:`put_back`, no new run; up to :data:`PUT_BACK_ROUNDS` widenings, the fewest
   crossings kept). What is left is said.

This is not El Topo's continuous collision handling: held regions stop where they were before
they first crossed (less styled there), the rest is the method's own optimum with those
constraints. Measured on the corpus (docs/results/corpus.md, every method at its defaults):
cubic stylization made new crossings on 14 of 52 meshes, analogies on 18; with the rounds
below both leave none (30 November 2026, fifth session; analogies' ogre: 2,586 -> 0 with
31,288 of its 62,194 vertices held, beast 199 -> 0 with 4,365); camelhead's lips 136 -> 0
(cubic) in one round, keeping 97 % of the change of the L1 norm of the normals; the runs took
up to 2.7x as long (nefertiti's analogy, 100k triangles: 4.4 -> 11.9 s; docs/results/cubic.md).
"""

from __future__ import annotations

from typing import Callable, Iterator

import numpy as np

from ..steps import Step

__all__ = ["CHECK_MAX_FACES", "CHECKPOINT_EVERY", "HOLD_CROSSINGS_TOOLTIP", "PUT_BACK_FALLOFF",
           "PUT_BACK_ROUNDS", "ROUNDS", "WORDING", "crossings_of", "crossings_sentence",
           "grow_held", "hold_where_crossed", "metrics_of", "put_back"]

#: The tooltip of the setting (``hold_crossings`` of the cubic and analogy parameters).
HOLD_CROSSINGS_TOOLTIP = (
    "Where the style pushes the surface through itself (thin walls, parts that nearly touch), "
    "hold those vertices where they were before they crossed and let the rest settle around "
    "them; where they would still cross, put the surface there back towards the input. Meshes "
    "of up to 200,000 triangles. Off: the thesis's method as it is.")

#: Meshes with more triangles are not checked (one self-intersection test takes about 0.2 s at
#: 100,000 triangles and 3.3 s at 1.6M): the result's Step says so.
CHECK_MAX_FACES = 200_000
#: An iterate is recorded every this many iterations (at most :data:`MAX_CHECKPOINTS`, the
#: stride doubling when full), with the input first.
CHECKPOINT_EVERY = 5
MAX_CHECKPOINTS = 48
#: Rounds of holding and running again: they go on while crossings are left and the held set
#: grows, so this only bounds the time. 5 until 30 November 2026 (fifth session), when
#: analogies on beast and ogre (corpus) ended with 7 and 36 crossings after 5 rounds and with
#: none after their 6th (counter: 468 -> 0); no corpus or shared mesh needed more than 6.
ROUNDS = 20
#: Rounds of putting the surface back towards the input where crossings are still left, and
#: over how many rings past the first the blend's weight falls off (1: 1, then 1/2). A wider
#: falloff (3: 1, 3/4, 1/2, 1/4) ended the crossings of beast and counter (analogies), but only
#: by blending between a part the style had moved far and its input position, which tore the
#: surface (edges 36 and 24 times their length): refused by the damage check, it gained nothing
#: on the corpus (30 November 2026), so it is not tried.
PUT_BACK_ROUNDS = 10
PUT_BACK_FALLOFF = 1


def grow_held(held: np.ndarray, bad: np.ndarray, F: np.ndarray, VF, fixed: np.ndarray
              ) -> np.ndarray:
    """(n,) bool: ``held`` and the corners of the crossing triangle pairs ``bad`` (k, 2) with
    one ring of vertices around them, less ``fixed`` (vertices held otherwise). ``VF``: the
    vertex-face adjacency (csr) of ``F``."""
    grown = held.copy()
    grown[F[np.unique(bad.ravel())].ravel()] = True
    grown[F[VF[np.flatnonzero(grown)].indices].ravel()] = True  # and one ring
    grown &= ~fixed
    return grown


def put_back(V, V0, F, known, bad, fixed, rounds: int = PUT_BACK_ROUNDS, more=None,
             falloff: int = PUT_BACK_FALLOFF, crossings=None, damage=None
             ) -> tuple[np.ndarray, int, int]:
    """The last resort where holding and running again left crossings: around the crossing
    triangles ``bad`` (k, 2) of ``V``, the surface is blended back towards the input ``V0``
    (weight 1 on their corners and one ring, falling off over the next ``falloff`` rings),
    widened up to ``rounds`` times while crossings are left; the input crosses itself nowhere
    new, so this ends them where the widening settles (not always: the blend's edge can cross
    elsewhere round after round). ``fixed`` vertices (held by the caller) never move. ``more(X)``, optional: further (k, 2)
    triangle pairs to mend and count (a flow's folded or collapsed triangles, each as a pair
    with itself; ``bad`` then holds them too). ``crossings(X)``, optional: the crossing pairs
    to end (default: the new ones away from ``known``, of the same triangles; a subdivision
    counts them through their parents). ``damage``: the caller's
    :class:`~algorithms.mesh.damage.Damage` of ``V0``, if it has one. A blend is only a
    candidate if it damages
    nothing (:func:`_blend_damage`: where the style moved a part far, a blend between the two
    stretches and folds the triangles between them: beast's foot, edges 36 times their length).
    Returns the positions with the fewest crossings (and ``more``) among the candidates (``V``
    itself if none had fewer), the vertices moved there, and that count."""
    from ..mesh.intersections import intersecting_pairs_here, new_crossings_away_from
    from ..mesh.topology import vertex_adjacency

    V = np.asarray(V, np.float64)
    V0 = np.asarray(V0, np.float64)
    n = len(V)
    A = vertex_adjacency(F, n)
    damaged = _blend_damage(V0, V, F, damage)
    if crossings is None:
        def crossings(X):
            return new_crossings_away_from(intersecting_pairs_here(X, F), F, known)
    best = (V, 0, len(bad))
    w = np.zeros(n)
    for _ in range(int(rounds)):
        if not len(bad):
            break
        ring = np.zeros(n, bool)
        ring[F[bad.ravel()].ravel()] = True
        ring |= A @ ring.astype(np.float64) > 0          # the corners and one ring: 1
        wk = ring.astype(np.float64)
        for i in range(1, int(falloff) + 1):             # then falling off
            grown = ring | (A @ ring.astype(np.float64) > 0)
            wk[grown & ~ring] = 1.0 - i / (int(falloff) + 1)
            ring = grown
        w = np.maximum(w, wk)
        w[fixed] = 0.0
        X = (1.0 - w)[:, None] * V + w[:, None] * V0
        bad = crossings(X)
        if more is not None:
            bad = np.concatenate([np.asarray(bad, np.int64).reshape(-1, 2), more(X)])
        if len(bad) < best[2] and not damaged(X):
            best = (X, int((w > 0).sum()), len(bad))
    return best


#: a blended edge longer than this times its length in both the input and the result it came
#: from is a tear (:func:`put_back`)
BLEND_STRETCH = 2.0


def _blend_damage(V0, V, F, dmg=None):
    """``damaged(X)``: whether positions ``X`` blended between ``V0`` and ``V`` tear or fold
    the surface: an edge longer than :data:`BLEND_STRETCH` times its length in both, or a
    triangle folded over or collapsed (:mod:`algorithms.mesh.damage`) that ``V`` did not have
    (``dmg``: a :class:`~algorithms.mesh.damage.Damage` of ``V0`` already built)."""
    from ..mesh.damage import Damage

    F = np.asarray(F, np.int64)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    longest = np.maximum(np.linalg.norm(V0[E[:, 0]] - V0[E[:, 1]], axis=1),
                         np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1))
    dmg = Damage(V0, F) if dmg is None else dmg
    had = dmg.folded(V) | dmg.collapsed(V)

    def damaged(X) -> bool:
        if (np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) > BLEND_STRETCH * longest).any():
            return True
        return bool(((dmg.folded(X) | dmg.collapsed(X)) & ~had).any())

    return damaged


def _latest_clear(checkpoints: list[np.ndarray], F, known, faces: np.ndarray) -> int:
    """Index of a recorded iterate (the latest found by bisection) at which no new crossing
    touches ``faces`` (bool per face); 0, the input, always qualifies."""
    from ..mesh.intersections import intersecting_pairs_here, new_crossings_away_from

    def clear(k: int) -> bool:
        bad = new_crossings_away_from(intersecting_pairs_here(checkpoints[k], F), F, known)
        return not (faces[bad[:, 0]] | faces[bad[:, 1]]).any()

    lo, hi = 0, len(checkpoints) - 1  # clear(lo) holds; the last one (the result) does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if clear(mid):
            lo = mid
        else:
            hi = mid
    return lo


def hold_where_crossed(steps: Iterator[Step], V0, F,
                       rerun: Callable[[np.ndarray, np.ndarray, np.ndarray], Iterator[Step]], *,
                       constrained=None, rounds: int = ROUNDS,
                       put_back_rounds: int = PUT_BACK_ROUNDS,
                       wording: str = "style") -> Iterator[Step]:
    """``steps`` (a deformation of the mesh ``V0``, ``F`` from its input positions, one Step
    per iteration), then the rounds of the module docstring.

    Parameters
    ----------
    steps : the deformation's Steps (``V`` (n, 3) in ``V0``'s units).
    V0 : (n, 3) the input positions; F : (m, 3) its triangles (never changed).
    rerun : ``rerun(ids, targets, V_start)`` -> Steps of the same deformation with the vertices
        ``ids`` held at ``targets`` (on top of the caller's own constraints), started from
        ``V_start``.
    constrained : (n,) bool, optional, vertices the caller already constrains (never held).
    rounds : int, at most this many rounds.
    put_back_rounds : int, then at most this many widenings of :func:`put_back` (0: none).
    wording : a key of :data:`WORDING`, for the last Step's sentence.

    Yields
    ------
    The Steps of ``steps``, then those of each round (numbered on from the last), all passed
    through as they come. The last Step carries the metrics ``crossings_made`` (new crossings
    of the deformation before any holding), ``crossings_left``, ``held_vertices`` (and
    ``put_back_vertices`` where :func:`put_back` lowered the count), and its
    message says what was held; above :data:`CHECK_MAX_FACES` triangles nothing is checked
    and ``crossings_checked`` is 0.
    """
    from ..mesh.intersections import intersecting_pairs_here, new_crossings_away_from
    from ..mesh.topology import vertex_face_adjacency

    V0 = np.asarray(V0, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    check = len(F) <= CHECK_MAX_FACES
    checkpoints = [V0]
    stride, since = CHECKPOINT_EVERY, 0
    last = None
    for st in steps:
        if last is not None:
            yield last
        last = st
        if check and st.V is not None and len(st.V) == len(V0):
            since += 1
            if since >= stride:
                since = 0
                checkpoints.append(np.array(st.V, dtype=np.float64, copy=True))
                if len(checkpoints) > MAX_CHECKPOINTS:
                    checkpoints = checkpoints[:1] + checkpoints[2::2]
                    stride *= 2
    if last is None:
        return
    if not check:
        last.metrics = {**last.metrics, "crossings_checked": 0.0}
        yield last
        return
    known = intersecting_pairs_here(V0, F)
    bad = new_crossings_away_from(intersecting_pairs_here(last.V, F), F, known)
    made = len(bad)
    n = len(V0)
    fixed = np.zeros(n, bool) if constrained is None else np.asarray(constrained, bool).copy()
    held = np.zeros(n, bool)
    targets = np.zeros((n, 3))
    VF = vertex_face_adjacency(F, n).tocsr() if made else None
    # the bisection runs over the deformation's own iterates, its result last
    checkpoints.append(np.array(last.V, dtype=np.float64, copy=True))
    first = last
    best = (len(bad), last, 0, bad)  # (crossings, Step, vertices held, their pairs): kept
    k_round = 0
    while len(bad) and k_round < rounds:
        k_round += 1
        grown = grow_held(held, bad, F, VF, fixed)
        if np.array_equal(grown, held):
            break
        held = grown
        faces = np.zeros(len(F), bool)
        faces[VF[np.flatnonzero(held)].indices] = True
        # every held vertex from one iterate, so that the constraints agree with each other
        k = _latest_clear(checkpoints, F, known, faces)
        targets[held] = checkpoints[k][held]
        ids = np.flatnonzero(held)
        start = last
        yield Step(iteration=start.iteration, total=None, V=start.V, metrics=dict(start.metrics),
                   message=f"{len(bad)} new self-intersection(s): holding {len(ids):,} "
                           f"vertices where they were before they crossed, then running on")
        base = start.iteration
        for st in rerun(ids, targets[ids], start.V):
            if last is not start:
                yield last
            last = Step(iteration=base + st.iteration, total=None, V=st.V,
                        metrics=dict(st.metrics), message=f"held where crossed, {st.message}")
        bad = new_crossings_away_from(intersecting_pairs_here(last.V, F), F, known)
        if len(bad) < best[0]:
            best = (len(bad), last, len(ids), bad)
    left, kept, n_held, bad = best
    V_kept, n_back = kept.V, 0
    if left and put_back_rounds > 0:
        V_back, n_back, left_back = put_back(kept.V, V0, F, known, bad, fixed, put_back_rounds)
        if left_back < left:
            V_kept, left = V_back, left_back
        else:
            n_back = 0
    # the deformation's own figures (e.g. a progressive run's coarse and fine iteration counts,
    # the held rounds' iterations counted as fine ones), then the kept result's
    metrics = {**first.metrics, **kept.metrics}
    if "fine_iterations" in first.metrics:
        metrics["fine_iterations"] = float(first.metrics["fine_iterations"]
                                           + last.iteration - first.iteration)
    metrics.update(crossings_checked=1.0, crossings_made=float(made),
                   crossings_left=float(left), held_vertices=float(n_held))
    if n_back:
        metrics["put_back_vertices"] = float(n_back)
    # numbered after every iteration that ran; the positions are the kept result's
    yield Step(iteration=last.iteration, total=last.total, V=V_kept, metrics=metrics,
               message=crossings_sentence(metrics, wording) or kept.message)


def crossings_of(metrics: dict) -> dict | None:
    """What :func:`hold_where_crossed` (or a smoothing flow's hold) did, from a last Step's
    metrics, for a report: ``{"checked", "made", "held_vertices", "left"}``, and with a flow's
    ``"folded"`` and ``"folded_left"`` (triangles folded over or collapsed; None: it did not
    run)."""
    if "crossings_checked" not in metrics:
        return None
    if not metrics["crossings_checked"]:
        return {"checked": False, "made": None, "held_vertices": 0, "left": None}
    out = {"checked": True, "made": int(metrics["crossings_made"]),
           "held_vertices": int(metrics["held_vertices"]), "left": int(metrics["crossings_left"])}
    if metrics.get("put_back_vertices"):
        out["put_back_vertices"] = int(metrics["put_back_vertices"])
    if "folded_made" in metrics:
        out.update(folded=int(metrics["folded_made"]), folded_left=int(metrics["folded_left"]))
    return out


def metrics_of(crossings: dict | None) -> dict:
    """The metrics that :func:`crossings_of` read ``crossings`` from (empty for None)."""
    if crossings is None:
        return {}
    if not crossings["checked"]:
        return {"crossings_checked": 0.0}
    m = {"crossings_checked": 1.0, "crossings_made": crossings["made"],
         "held_vertices": crossings["held_vertices"], "crossings_left": crossings["left"]}
    if crossings.get("put_back_vertices"):
        m["put_back_vertices"] = crossings["put_back_vertices"]
    if "folded" in crossings:
        m.update(folded_made=crossings["folded"], folded_left=crossings["folded_left"])
    return m


#: Who moved the surface, the tense, and what to do about damage that is left, per kind of
#: method.
WORDING = {"style": ("The style", "", "lower λ, or move the parts apart"),
           "smoothing": ("Its steps", "would have ",
                         "lower Step size or Iterations, or move the parts apart")}


def crossings_sentence(metrics: dict, wording: str = "style") -> str:
    """One sentence on what :func:`hold_where_crossed` (or a flow's hold) did ("" when there is
    nothing to say: it did not run, or the deformation made no crossing, fold or collapse);
    ``wording``: a key of :data:`WORDING`."""
    who, tense, advice = WORDING[wording]
    c = crossings_of(metrics)
    if c is None:
        return ""
    if not c["checked"]:
        return (f"Self-intersections were not checked (more than {CHECK_MAX_FACES:,} "
                f"triangles).")
    folded, folded_left = c.get("folded", 0), c.get("folded_left", 0)
    if not c["made"] and not folded:
        return ""
    did = []
    if c["made"]:
        did.append(f"pushed the surface through itself in {c['made']} place(s)")
    if folded:
        did.append(f"folded over or collapsed {folded} triangle(s)")
    did = f"{who} {tense}{' and '.join(did)}"
    rest = []
    if c["left"]:
        rest.append(f"{c['left']} crossing(s)")
    if folded_left:
        rest.append(f"{folded_left} folded or collapsed triangle(s)")
    left = "none is left" if not rest else f"{' and '.join(rest)} are left: {advice}"
    back = c.get("put_back_vertices", 0)
    back = (f"; where they still crossed, {back:,} vertices were put back towards the input"
            if back else "")
    if not c["held_vertices"]:
        return (f"{did}; holding those points back did not reduce them{back}, so {left}."
                if not back else f"{did}{back}; {left}.")
    when = "before they crossed" if not folded else "before the step that did it"
    return (f"{did}: {c['held_vertices']:,} vertices were held where they were {when}{back}; "
            f"{left}.")
