"""Recipes of the "Multigrid smoothing" panel (thesis ch. 8): data smoothing on the surface
multigrid hierarchy, the hierarchy itself, a solver comparison, and mean curvature flow.

Recipes (name / command, Params, what the run gives):

* ``"Multigrid smoothing"`` / ``smooth-data`` — :class:`DataSmoothingParams`. Smooths a signal
  (Eq. 8.6). The result is a new per-vertex field ``"smoothed"`` of the state (scalar signals)
  or the smoothed vertex positions (``signal = "positions"``).
* ``"Multigrid smoothing: hierarchy"`` / ``multigrid-hierarchy`` — :class:`MultigridParams`
  (its ratio, coarsest size, decimation and prolongation). Builds the hierarchy; the document
  does not change; the outcome holds the level sizes and a digest of every level and
  prolongation.
* ``"Multigrid smoothing: compare solvers"`` / ``multigrid-compare`` —
  :class:`DataSmoothingParams` (energy and α; ``solver`` is not used: both run). Solves once
  with multigrid and once with the direct solver; the document does not change; the outcome
  holds both solutions, their largest difference and the multigrid iterations. The measured
  seconds are only in the last step's ``info`` (for display): they vary from run to run.
* ``"Multigrid smoothing: mean curvature flow"`` / ``multigrid-flow`` — :class:`SmoothParams`
  (the panel uses ``flow="cmcf"``, its dt as ``step_size`` and its step count as
  ``iterations``). The flow's linear solves are V-cycles on the hierarchy; the result is the
  new vertex positions.

Options (JSON-able; every key optional):

``signal`` : str
    ``"noise"`` (default: the field ``"noisy input"`` of the state), ``"positions"`` (the vertex
    positions) or ``"loaded"`` (the field ``"loaded field"``). Smoothing and comparison only.
``noise`` : float, ``noise_seed`` : int
    the noisy test field's level (relative to the pattern's spread, default 0.4) and random
    seed (default 0). Used only when ``signal`` is ``"noise"`` and the state has no
    ``"noisy input"`` field: the recipe then makes it (:func:`noisy_field`) and the result
    state gets it too. The panel's "New noise" makes the field with the same function and a
    new seed, which it records here.
``field`` : str
    the ``"blob:..."`` reference (:func:`app.recipes.put_blob_file`) of a field file (.npy,
    .txt, .csv: one value per vertex), used when ``signal`` is ``"loaded"`` and the state has
    no ``"loaded field"`` (the result state then gets it too). The panel loads the file into
    the state instead.
``warm_start`` : list of float
    the α's of the solves this one continues from, oldest first (default ``[]``: a cold start
    from zero, as SciPy and PyAMG). With ``[a1, a2]`` the run first solves at ``a1`` from zero,
    then at ``a2`` from that solution, then at ``params.alpha`` from that one: exactly the
    sequence of a slider being dragged, so the run's bits are a function of its input alone
    (an iterative solve stopped at a tolerance depends on its first guess: the bits of a
    warm-started solve differ from a cold one's within the tolerance). The cache keeps the
    solutions, so in the panel only the last solve is computed; a replay with a fresh cache
    re-solves the list (at most :data:`WARM_START_MAX` α's). Only the multigrid solver uses
    it (the direct solver has no first guess). The panel passes the α's of its earlier solves
    of the same input, energy, solver and hierarchy (:func:`warm_start_chain`), restarting
    cold after :data:`WARM_START_MAX` of them.
``hierarchy_positions`` : str
    the ``"blob:..."`` reference of an ``.npy`` (n, 3) array: the vertex positions to build
    the hierarchy from, when they are not the input's (default: the input's). The panel builds
    one hierarchy per connectivity and keeps it while the shape changes (smoothed positions,
    flow steps), as the thesis reuses one hierarchy for every flow step; the positions it was
    built on are then an input of the run (:func:`hierarchy_option`). Not used by the
    hierarchy recipe (it always builds on the input's positions).

``rtol`` : float, ``max_iterations`` : int, ``fallback`` : bool
    the multigrid solve's stopping tolerance (relative residual, default :data:`RTOL`), its
    most iterations (default :data:`MAX_ITERATIONS`; it also stops early when the residual
    grows or stalls) and whether an unconverged solve falls back to the direct solver when it
    fits in memory (default True; False raises NotConvergedError). Smoothing only (the
    command line's ``--rtol``, ``--max-cycles`` and ``--no-fallback``); the panel uses the
    defaults.

The panel's options also hold ``flow_step_size`` and ``flow_steps`` (its flow's settings, kept
with a project), which these recipes do not read: a flow run takes them as its Params.

``cache`` holds the hierarchy (one mesh at a time), the Galerkin matrices of recent
(positions, energy, solver) and recent solutions; entries are checked against the input arrays
and options they were made from, so the cache changes the speed of a run, never its bits.

Also here, Qt-free, for the panel: :func:`noisy_field`, :func:`warm_start_chain`,
:func:`hierarchy_option`, :func:`hierarchy_of`, :func:`coarse_face_colors`,
:func:`coarse_triangle_colors`, :func:`signal_range`.
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import Recipe, blob_bytes, blob_path, put_blob, register, unchanged_result

NOISY_FIELD = "noisy input"
LOADED_FIELD = "loaded field"
RESULT_FIELD = "smoothed"
#: ``options["signal"]`` values, in the panel's order
SIGNALS = ("noise", "positions", "loaded")
DEFAULT_NOISE = 0.4
#: at most this many CG steps per multigrid solve (they also stop early on growth or a stall)
MAX_ITERATIONS = 100
#: relative residual at which a multigrid solve stops
RTOL = 1e-5
#: the longest ``warm_start`` list the panel passes (a replay re-solves that many α's)
WARM_START_MAX = 10

SMOOTH = "Multigrid smoothing"
HIERARCHY = "Multigrid smoothing: hierarchy"
COMPARE = "Multigrid smoothing: compare solvers"
FLOW = "Multigrid smoothing: mean curvature flow"

_KEEP_SMOOTHERS = 4
_KEEP_SOLUTIONS = 2 * WARM_START_MAX + 4


@dataclass
class MultigridStep(Step):
    """A Step of these recipes that carries what the run computed.

    values : the smoothed signal ((n,) or (n, 3)), smoothing only.
    made_fields : input fields the recipe made itself (a noisy field, a field file), which the
        result state gets too.
    info : the solver's report (solver, cycles, residuals, seconds, fallback, auto, ...):
        for display; its seconds vary from run to run and are never in the outcome.
    figures : the analysis's figures and arrays (the outcome of comparison and hierarchy).
    mg : the hierarchy used (for the panel's views and scripts).
    """

    values: Any = None
    made_fields: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)
    mg: Any = None


# ------------------------------------------------------------------------------ inputs
def noisy_field(V, F, noise: float = DEFAULT_NOISE, seed: int = 0) -> np.ndarray:
    """The noisy test field (n,): a smooth pattern plus Gaussian noise of ``noise`` times its
    spread, from ``seed`` (:func:`algorithms.smoothing.noisy_test_field`)."""
    from algorithms.smoothing import noisy_test_field

    return noisy_test_field(V, F, float(noise), int(seed))[1]


def _signal(options: dict) -> str:
    from algorithms.errors import ParameterError

    signal = options.get("signal", "noise")
    if signal not in SIGNALS:
        raise ParameterError(f"Unknown signal {signal!r}; choose one of {', '.join(SIGNALS)}.")
    return signal


def _source(state, signal: str):
    """The state's array of the signal (None when the state has no such field)."""
    if signal == "positions":
        return state.V
    return state.fields.get(NOISY_FIELD if signal == "noise" else LOADED_FIELD)


def signal_values(state, options: dict) -> tuple[np.ndarray, dict]:
    """(the signal's array, the input fields made from ``options``) of a run."""
    from algorithms.errors import Stylize3DError

    signal = _signal(options)
    src = _source(state, signal)
    if src is not None:
        return src, {}
    if signal == "noise":
        vals = noisy_field(state.V, state.F, options.get("noise", DEFAULT_NOISE),
                           options.get("noise_seed", 0))
        return vals, {NOISY_FIELD: vals}
    ref = options.get("field")
    if ref:
        from algorithms.mesh.fields import read_field

        vals = read_field(str(blob_path(ref)), len(state.V))
        return vals, {LOADED_FIELD: vals}
    raise Stylize3DError("There is no input signal: make a noisy field or load one.")


def resolve_solver(n: int, params) -> tuple[str, str | None]:
    """("multigrid" or "direct", the sentence of ``solver="auto"`` or None)."""
    if params.solver != "auto":
        return params.solver, None
    from algorithms.multigrid.applications import choose_solver

    return choose_solver(n, params.energy)


def _warm_list(options: dict) -> list[float]:
    from algorithms.errors import ParameterError

    raw = options.get("warm_start") or []
    try:
        alphas = [float(a) for a in raw]
    except (TypeError, ValueError):
        raise ParameterError("options['warm_start'] must be a list of numbers (the α's of the "
                             "earlier solves).") from None
    if not all(0.0 < a < 1.0 for a in alphas):
        raise ParameterError("Every α in options['warm_start'] must lie between 0 and 1.")
    return alphas


def solve_options(options: dict) -> tuple[float, int, bool]:
    """(rtol, max_iterations, fallback) of a smoothing run's options (module docstring)."""
    from algorithms.errors import ParameterError

    try:
        rtol = float(options.get("rtol", RTOL))
        maxiter = options.get("max_iterations", MAX_ITERATIONS)
        if isinstance(maxiter, float) and maxiter.is_integer():
            maxiter = int(maxiter)
        if isinstance(maxiter, bool) or not isinstance(maxiter, int):
            raise ValueError
    except (TypeError, ValueError):
        raise ParameterError("options['rtol'] must be a number and options['max_iterations'] "
                             "a whole number.") from None
    if not (rtol > 0 and maxiter >= 1):
        raise ParameterError(f"The multigrid tolerance must be positive and the iterations at "
                             f"least 1 (got {rtol:g} and {maxiter}).")
    return rtol, maxiter, bool(options.get("fallback", True))


# ------------------------------------------------------------------------------ hierarchy
def _build_key(params=None) -> tuple:
    if params is None:
        from algorithms.multigrid.params import MultigridParams

        params = MultigridParams()
    return (float(params.ratio), int(params.min_vertices), str(params.strategy),
            str(params.prolongation))


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a, dtype=np.float64), allow_pickle=False)
    return buf.getvalue()


def _hierarchy_positions(state, ref: str) -> np.ndarray:
    from algorithms.errors import ParameterError

    try:
        V = np.load(io.BytesIO(blob_bytes(ref)), allow_pickle=False)
    except ValueError as e:
        raise ParameterError(f"The hierarchy's positions {ref!r} are not an .npy array: {e}")
    if V.shape != state.V.shape or V.dtype != np.float64 or not np.isfinite(V).all():
        raise ParameterError(f"The hierarchy's positions have shape {V.shape}; the mesh has "
                             f"{len(state.V):,} vertices (finite (n, 3) float64 expected).")
    return V


def _same(a, b) -> bool:
    return a is b or (a.shape == b.shape and np.array_equal(a, b))


def hierarchy_of(cache: dict, F):
    """The hierarchy the cache holds for these faces (the same array), or None."""
    h = cache.get("hierarchy")
    return h["mg"] if h is not None and h["F"] is F else None


def hierarchy_option(cache: dict, state) -> dict:
    """``{"hierarchy_positions": ref}`` when the cache's hierarchy of ``state.F`` was built on
    other positions than ``state.V`` (the panel keeps it while the shape changes), else ``{}``.
    The positions are stored once per hierarchy (:func:`app.recipes.put_blob`)."""
    h = cache.get("hierarchy")
    if h is None or h["F"] is not state.F or h["key"] != _build_key():
        return {}
    if _same(h["V"], state.V):
        return {}
    if h.get("ref") is None:
        h["ref"] = put_blob(_npy_bytes(h["V"]), "hierarchy_positions.npy")
    return {"hierarchy_positions": h["ref"]}


def hierarchy_steps(state, options: dict, cache: dict, params=None):
    """Steps while the hierarchy is built (none when the cache holds it); returns it.

    Built on ``options["hierarchy_positions"]`` when given, else on the input's positions,
    with ``params`` (a MultigridParams; default: its defaults, the thesis's)."""
    from algorithms.multigrid import surface_multigrid
    from algorithms.steps import with_progress

    key = _build_key(params)
    ref = options.get("hierarchy_positions") if params is None else None
    h = cache.get("hierarchy")
    if h is not None and h["key"] == key and _same(h["F"], state.F):
        if ref is not None and h.get("ref") == ref:
            return h["mg"]
        Vsrc = _hierarchy_positions(state, ref) if ref is not None else state.V
        if _same(h["V"], Vsrc):
            return h["mg"]
    else:
        Vsrc = _hierarchy_positions(state, ref) if ref is not None else state.V
    F = state.F
    kw = dict(zip(("ratio", "min_vertices", "strategy", "prolongation"), key))
    out: dict = {}
    yield from with_progress(lambda progress: surface_multigrid(Vsrc, F, progress=progress, **kw),
                             state.V, out)
    mg = out["value"]
    cache["hierarchy"] = {"F": F, "V": Vsrc, "key": key, "mg": mg, "ref": ref}  # one mesh
    cache["smoothers"] = {}
    cache["solutions"] = {}
    cache.pop("last", None)
    return mg


def hierarchy_figures(mg) -> dict:
    """The hierarchy as figures: level sizes, the prolongation kind and a SHA-256 digest of
    every level's V and F and every prolongation (the replay's check)."""
    h = hashlib.sha256()
    for Vh, Fh in mg.levels:
        h.update(np.ascontiguousarray(Vh, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(Fh, dtype=np.int64).tobytes())
    for P in mg.prolongations:
        P = P.tocsr()
        for a in (P.indptr, P.indices, P.data):
            h.update(np.ascontiguousarray(a).tobytes())
    return {"n_levels": int(mg.n_levels),
            "level_vertices": np.array([len(Vh) for Vh, _ in mg.levels], dtype=np.int64),
            "level_faces": np.array([len(Fh) for _, Fh in mg.levels], dtype=np.int64),
            "prolongation": str(mg.report.get("prolongation")),
            "digest": h.hexdigest()}


def hierarchy_recipe_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    """Build the hierarchy of the input (``params``: MultigridParams); the last step's
    ``figures`` are :func:`hierarchy_figures`."""
    cache = {} if cache is None else cache
    mg = yield from hierarchy_steps(state, {}, cache, params)
    yield MultigridStep(1, 1, state.V, {}, "hierarchy built", figures=hierarchy_figures(mg),
                        mg=mg)


# ------------------------------------------------------------------------------ smoothing
def _smoother(state, energy: str, solver: str, mg, cache: dict):
    """(the cached DataSmoother of the input or None, its key)."""
    key = (id(state.V), id(state.F), energy, solver, id(mg))
    hit = cache.setdefault("smoothers", {}).get(key)
    if hit is not None and hit[0] is state.V and hit[1] is state.F and hit[2] is mg:
        return hit[3], key
    return None, key


def _keep(d: dict, key, value, n: int) -> None:
    d.pop(key, None)
    d[key] = value
    while len(d) > n:
        d.pop(next(iter(d)))


def warm_start_chain(cache: dict, state, params, options: dict) -> list[float]:
    """The ``warm_start`` list of a panel run: the α's that led to the cache's last solution
    when that solve had the same input arrays, energy, solver and hierarchy as this run (the
    panel's live slider), else ``[]``; ``[]`` too past :data:`WARM_START_MAX` α's, with the
    direct solver, and for a signal the recipe would have to make."""
    last = cache.get("last")
    if last is None:
        return []
    solver, _why = resolve_solver(len(state.V), params)
    src = _source(state, _signal(options))
    if solver != "multigrid" or src is None:
        return []
    ok = (last["V"] is state.V and last["F"] is state.F and last["f"] is src
          and last["energy"] == params.energy and last["solver"] == solver
          and last["mg"] is hierarchy_of(cache, state.F) and last["mg"] is not None)
    if not ok or len(last["chain"]) > WARM_START_MAX:
        return []
    return list(last["chain"])


def smoothing_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    """Data smoothing (Eq. 8.6) of the signal ``options["signal"]`` (module docstring).

    Steps: the hierarchy's build (multigrid, when not cached), "preparing the Galerkin
    matrices" (when not cached), the re-solves of ``warm_start`` (when not cached), then one
    step per iteration with its relative residual, then the last step whose ``values`` is the
    smoothed signal, ``V`` the smoothed positions (``signal="positions"``) or the input's,
    ``info`` the solver's report plus ``auto`` (the sentence of ``solver="auto"``),
    ``warm_start`` (whether it started from an earlier solution) and ``precompute_seconds``
    (building the Galerkin matrices in this run; 0 when cached). An unconverged multigrid
    solve falls back to the direct solver when it fits in memory (``info["fallback"]``) or
    raises NotConvergedError (``options["fallback"]`` False: always raises)."""
    from algorithms.multigrid.applications import DataSmoother
    from algorithms.smoothing import unit_area

    options = options or {}
    cache = {} if cache is None else cache
    signal = _signal(options)
    V, F = state.V, state.F
    solver, why = resolve_solver(len(V), params)
    f_src, made = signal_values(state, options)
    f = np.array(f_src, dtype=np.float64)
    chain = _warm_list(options) if solver == "multigrid" else []
    rtol, maxiter, fallback = solve_options(options)
    mg = None
    if solver == "multigrid":
        mg = yield from hierarchy_steps(state, options, cache)
    sm, skey = _smoother(state, params.energy, solver, mg, cache)
    precompute_seconds = 0.0
    if sm is None:
        yield Step(0, None, V, {}, "preparing the Galerkin matrices")
        sm = DataSmoother(unit_area(V, F), F, energy=params.energy, solver=solver, mg=mg)
        precompute_seconds = float(sm.precompute_seconds)
        _keep(cache["smoothers"], skey, (V, F, mg, sm), _KEEP_SMOOTHERS)
    sols = cache.setdefault("solutions", {})
    fkey = skey + (id(f_src),)

    def cached(k):  # the solution after chain[:k], or None
        hit = sols.get(fkey + (tuple(chain[:k]),))
        return hit[1] if hit is not None and hit[0] is f_src else None

    x0 = None
    if chain:
        start = next((k for k in range(len(chain), 0, -1) if cached(k) is not None), 0)
        x0 = cached(start) if start else None
        if start < len(chain):
            yield Step(0, None, V, {}, f"warm start: solving {len(chain) - start} earlier α")
        for k in range(start, len(chain)):
            x0, _info = sm.smooth_checked(f, chain[k], rtol=rtol, maxiter=maxiter, x0=x0,
                                          fallback=fallback)
            _keep(sols, fkey + (tuple(chain[:k + 1]),), (f_src, x0), _KEEP_SOLUTIONS)
    u, info = sm.smooth_checked(f, params.alpha, rtol=rtol, maxiter=maxiter, x0=x0,
                                fallback=fallback)
    done = chain + [float(params.alpha)]
    _keep(sols, fkey + (tuple(done),), (f_src, u), _KEEP_SOLUTIONS)
    cache["last"] = {"V": V, "F": F, "f": f_src, "energy": params.energy, "solver": solver,
                     "mg": mg, "chain": done}
    info["warm_start"] = x0 is not None
    info["auto"] = why
    info["requested_solver"] = solver
    info["precompute_seconds"] = precompute_seconds
    res = np.asarray(info.get("residuals") or [], dtype=np.float64)
    if res.size:
        res = res / (res[0] if res[0] > 0 else 1.0)
        for k, r in enumerate(res[1:], 1):
            yield Step(k, None, V, {"relative residual": float(r)}, "")
    Vout = u if signal == "positions" else V
    yield MultigridStep(int(info.get("cycles", 0)), None, Vout, {}, f"{info['seconds']:.3f} s",
                        values=u, made_fields=made, info=info, mg=mg)


def smoothing_result(before, last: Step, options: dict | None = None):
    """The smoothed positions (``signal="positions"``), else ``before`` with the field
    ``"smoothed"`` (and the input fields the recipe made)."""
    options = options or {}
    after = before
    for name, vals in getattr(last, "made_fields", {}).items():
        after = after.with_field(name, vals)
    if _signal(options) == "positions":
        return after.with_positions(np.asarray(last.values, dtype=np.float64))
    return after.with_field(RESULT_FIELD, last.values)


def _relres(info: dict) -> float:
    res = info.get("multigrid_residuals") or info.get("residuals") or []
    return float(res[-1] / res[0]) if len(res) and res[0] > 0 else 0.0


def smoothing_outcome(last: Step) -> dict:
    """The solver whose result it is, its iterations, the last residual relative to the
    first (of the multigrid iterations, also after a fallback), whether multigrid fell back to
    the direct solver and whether the solve was warm-started. No seconds."""
    info = getattr(last, "info", {}) or {}
    return {"solver": str(info.get("solver", "")),
            "cycles": int(info.get("multigrid_cycles", info.get("cycles", 0))),
            "relative_residual": _relres(info),
            "fallback": bool(info.get("fallback")),
            "warm_start": bool(info.get("warm_start"))}


# ------------------------------------------------------------------------------ comparison
def compare_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    """Solve once with each solver at ``params.alpha`` (fresh matrices for each, so the times
    compare); the last step's ``info`` maps "multigrid" and "direct" to their reports (with
    seconds, for display) and ``figures`` holds the outcome (no seconds)."""
    from algorithms.multigrid.applications import DataSmoother
    from algorithms.smoothing import unit_area

    options = options or {}
    cache = {} if cache is None else cache
    V, F = state.V, state.F
    f_src, _made = signal_values(state, options)
    f = np.array(f_src, dtype=np.float64)
    mg = yield from hierarchy_steps(state, options, cache)
    infos, sols = {}, {}
    kinds = ("multigrid", "direct")
    for k, solver in enumerate(kinds):
        sm = DataSmoother(unit_area(V, F), F, energy=params.energy, solver=solver,
                          mg=mg if solver == "multigrid" else None)
        sols[solver], infos[solver] = sm.smooth_checked(f, params.alpha, rtol=RTOL,
                                                        maxiter=MAX_ITERATIONS)
        msg = f"{solver}: {infos[solver]['seconds']:.3f} s"
        if k < len(kinds) - 1:
            yield Step(k + 1, 2, V, {}, msg)
    im = infos["multigrid"]
    # the multigrid solve's V-cycles, for the panel's residual plot (relative to the first)
    res = np.asarray(im.get("multigrid_residuals") or im.get("residuals") or [],
                     dtype=np.float64)
    if res.size > 1:
        res = res / (res[0] if res[0] > 0 else 1.0)
        for k, r in enumerate(res[1:], 1):
            yield Step(k, None, V, {"relative residual": float(r)}, "")
    figures = {"multigrid_cycles": int(im.get("multigrid_cycles", im.get("cycles", 0))),
               "multigrid_relative_residual": _relres(im),
               "multigrid_fallback": bool(im.get("fallback")),
               "max_difference": float(np.abs(sols["multigrid"] - sols["direct"]).max()),
               "multigrid_solution": np.asarray(sols["multigrid"], dtype=np.float64),
               "direct_solution": np.asarray(sols["direct"], dtype=np.float64)}
    yield MultigridStep(2, 2, V, {}, msg, info=infos, figures=figures, mg=mg)


def _figures(last: Step) -> dict:
    return dict(getattr(last, "figures", {}) or {})


# ------------------------------------------------------------------------------ flow
def flow_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    """Mean curvature flow (``params``: SmoothParams) whose linear solves are V-cycles on the
    hierarchy (the same for every step, thesis Fig. 8.23)."""
    from algorithms.smoothing import smooth_iter

    options = options or {}
    cache = {} if cache is None else cache
    mg = yield from hierarchy_steps(state, options, cache)
    yield from smooth_iter(state.V, state.F, params, multigrid=mg)


def _flow_outcome(last: Step) -> dict:
    return {"iterations": int(last.iteration), **{k: float(v) for k, v in last.metrics.items()}}


# ------------------------------------------------------------------------------ views
def coarse_face_colors(mg, level: int) -> np.ndarray:
    """Colours 0..19 of the coarse triangles of ``level``, different for triangles sharing a
    vertex (greedy colouring of the face graph, Alg. 10; wraps around only past 20 colours)."""
    import scipy.sparse as sp

    from algorithms.multigrid import greedy_coloring

    Fc = mg.levels[level][1]
    nv = int(Fc.max()) + 1
    inc = sp.csr_matrix((np.ones(Fc.size), (np.repeat(np.arange(len(Fc)), 3), Fc.ravel())),
                        shape=(len(Fc), nv))
    return greedy_coloring(inc @ inc.T) % 20


def coarse_triangle_colors(mg, level: int) -> np.ndarray:
    """Per fine triangle (float), the colour (0..19) of the coarse triangle of ``level`` its
    centroid lies on (the view "Fine triangles by coarse triangle")."""
    labels, _bary = mg.locate(level)
    return coarse_face_colors(mg, level)[labels].astype(float)


def signal_range(values) -> tuple[float, float] | None:
    """(min, max) of a signal for its colour map, or None."""
    if values is None:
        return None
    return float(np.min(values)), float(np.max(values))


# ------------------------------------------------------------------------------ registry
def _data_params():
    from algorithms.multigrid.params import DataSmoothingParams

    return DataSmoothingParams


def _multigrid_params():
    from algorithms.multigrid.params import MultigridParams

    return MultigridParams


def _smooth_params():
    from algorithms.smoothing import SmoothParams

    return SmoothParams


register(Recipe(SMOOTH, "smooth-data", _data_params, smoothing_steps, result=smoothing_result,
                outcome=smoothing_outcome))
register(Recipe(HIERARCHY, "multigrid-hierarchy", _multigrid_params, hierarchy_recipe_steps,
                result=unchanged_result, outcome=_figures))
register(Recipe(COMPARE, "multigrid-compare", _data_params, compare_steps,
                result=unchanged_result, outcome=_figures))
register(Recipe(FLOW, "multigrid-flow", _smooth_params, flow_steps, outcome=_flow_outcome))
