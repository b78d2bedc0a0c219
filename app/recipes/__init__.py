"""Recipes: the one place where each method's Run is computed, Qt-free.

A recipe turns ``(state, params, options, cache)`` into the method's Step generator:

* ``state`` — an immutable :class:`~app.document.MeshState` (mesh, painted per-vertex fields,
  point handles);
* ``params`` — the method's frozen Params dataclass (the panel's form, the CLI's flags);
* ``options`` — a JSON-able dict of every other input of the run (a panel's own switches, the
  chosen style, a capture sphere, a random seed, references to binary inputs such as a target
  image or a style mesh — see *Blobs* below). ``options`` plus ``state`` plus ``params`` are
  the whole input: a run is reproducible from them (the study log records them);
* ``cache`` — a dict the caller keeps between runs of the same recipe (the panel keeps one per
  panel, a CLI run or a replay passes a fresh one); recipes put their precomputation there
  (factorizations, hierarchies, decimations) and must check that it belongs to the same input.

``Recipe.result(before, last_step, options)`` turns the last Step into the document's new
state (moved vertices by default; a new mesh when the step carries faces; a new field for field
results). ``Recipe.outcome(last_step)`` gives the run's figures as a dict (JSON-able numbers and
NumPy arrays): the CLI's ``--json``, the batch report and the study replay of analysis runs
(whose document does not change) read it.

Who calls a recipe: the panel's Run (:class:`app.panels.base.MethodPanel` when a recipe of the
panel's title exists), the command line (``app/cli``), the study replay
(:mod:`app.study.replay`) and scripts (:func:`run`). One module per method in this package
registers its recipes on import; :func:`recipes` imports them all.

Blobs: binary inputs (images, meshes) are not put into ``options`` themselves but referenced as
``"blob:<sha256>/<file name>"`` strings made by :func:`put_blob`; :func:`blob_bytes` and
:func:`blob_path` give them back. The store is content addressed and process wide; the project
file (:mod:`app.project`) and the study log save every blob a run's options refer to, and load
them back before a run.
"""

from __future__ import annotations

import hashlib
import importlib
import pkgutil
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from algorithms.steps import Step

#: below this largest move (fraction of the bounding-box diagonal) a result looks unchanged, and
#: the methods that move vertices say why (smooth, cubic, analogies)
VISIBLE_MOVE = 0.005


def largest_move(V0, V) -> float:
    """The largest vertex move from ``V0`` to ``V``, as a fraction of ``V0``'s bounding-box
    diagonal (inf when they do not pair vertex for vertex)."""
    V0 = np.asarray(V0, np.float64)
    V = np.asarray(V, np.float64)
    if V.shape != V0.shape or not len(V):
        return float("inf")
    diag = float(np.linalg.norm(np.ptp(V0, axis=0))) or 1.0
    return float(np.linalg.norm(V - V0, axis=1).max()) / diag


def unchanged_words(moved: float) -> str:
    """The opening of a note on a result that looks unchanged (see :data:`VISIBLE_MOVE`)."""
    return ("The shape did not change: " if moved < 1e-9 else
            f"The shape changed little (at most {100 * moved:.2g} % of its size): ")


#: Per-vertex fields the Cubic panel paints (names shared with its tools).
LAMBDA_FIELD = "lambda_scale"
FIXED_FIELD = "fixed"
PLANE_FIELD = "plane"
FRAME_FIELDS = ("frame_rx", "frame_ry", "frame_rz")


# ------------------------------------------------------------------------------ results
def positions_result(before, last: Step, options: dict | None = None):
    """The default ``Recipe.result``: the last step's vertices (same faces, fields kept), or
    a new mesh when the step carries faces of its own (fields and handles are dropped unless
    the faces are the same)."""
    from app.document import MeshState

    V = np.asarray(last.V, dtype=np.float64)
    F = getattr(last, "F", None)
    if F is None:
        return before.with_positions(V)
    F = np.asarray(F, dtype=np.int64)
    if F.shape == before.F.shape and V.shape == before.V.shape and np.array_equal(F, before.F):
        return before.with_positions(V)
    return MeshState.make(V, F)


def held_crossings_note(metrics: dict, title: str = "") -> str:
    """What a deformation's hold on self-intersections did, from its last Step's metrics, as one
    sentence for a panel's closing line ("" when there is nothing to say;
    :func:`algorithms.deform.collisions.crossings_sentence`); ``title``: the recipe's (a
    smoothing flow's, whose Params are SmoothParams, is worded as one)."""
    from algorithms.deform.collisions import crossings_sentence
    from algorithms.smoothing import SmoothParams

    recipe = recipes().get(title)
    flow = recipe is not None and recipe.params_cls() is SmoothParams
    return crossings_sentence(metrics, "smoothing" if flow else "style")


def unchanged_result(before, last: Step, options: dict | None = None):
    """``Recipe.result`` of an analysis: the document does not change."""
    return before


@dataclass(frozen=True)
class Recipe:
    """One method's Run as a Qt-free function (module docstring).

    name : the panel's title ("Cubic"); the study log's ``method``.
    command : the CLI sub-command ("cubic").
    params : () -> the Params dataclass (resolved lazily: importing a recipe stays light).
    steps : (state, params, options, cache) -> Iterator[Step].
    result : (before, last_step, options) -> MeshState, the document after the run.
    outcome : (last_step) -> dict of figures / arrays, or None.
    deterministic : same input, same bits on the same machine (a seed in ``options`` counts).
    changes_faces : the steps may carry new faces (``step.F``).
    """

    name: str
    command: str
    params: Callable[[], type]
    steps: Callable[..., Iterator[Step]]
    result: Callable[..., Any] = positions_result
    outcome: Callable[[Step], dict] | None = None
    deterministic: bool = True
    changes_faces: bool = False
    note: str = ""

    def params_cls(self) -> type:
        return self.params()

    def make_params(self, values: dict | None = None):
        """Params from a (partial) dict; unknown names or bad values raise ParameterError."""
        from algorithms.params import params_from_dict, params_to_dict

        cls = self.params()
        return params_from_dict(cls, {**params_to_dict(cls()), **(values or {})})


_RECIPES: dict[str, Recipe] = {}
_loaded = False
_load_lock = threading.Lock()


def register(recipe: Recipe) -> Recipe:
    """Add a recipe (called by the method modules of this package on import)."""
    _RECIPES[recipe.name] = recipe
    return recipe


def _load_all() -> None:
    global _loaded
    if _loaded:
        return
    with _load_lock:
        if _loaded:
            return
        for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
            if not info.name.startswith("_"):
                importlib.import_module(f"{__name__}.{info.name}")
        _loaded = True


def recipes() -> dict[str, Recipe]:
    """Every registered recipe by name (the panel titles)."""
    _load_all()
    return dict(_RECIPES)


class _Registry(dict):
    """``RECIPES``: a read-only view that loads every recipe module on first use."""

    def _fill(self):
        if not dict.__len__(self) or len(_RECIPES) != dict.__len__(self):
            _load_all()
            dict.clear(self)
            dict.update(self, _RECIPES)

    def __getitem__(self, k):
        self._fill()
        return dict.__getitem__(self, k)

    def __contains__(self, k):
        self._fill()
        return dict.__contains__(self, k)

    def __iter__(self):
        self._fill()
        return dict.__iter__(self)

    def __len__(self):
        self._fill()
        return dict.__len__(self)

    def get(self, k, default=None):
        self._fill()
        return dict.get(self, k, default)

    def keys(self):
        self._fill()
        return dict.keys(self)

    def values(self):
        self._fill()
        return dict.values(self)

    def items(self):
        self._fill()
        return dict.items(self)


RECIPES: dict[str, Recipe] = _Registry()


def get_recipe(name: str) -> Recipe:
    """A recipe by panel title ("Cubic") or CLI command ("cubic"), case-insensitive."""
    from algorithms.errors import ParameterError

    every = recipes()
    if name in every:
        return every[name]
    low = name.lower()
    for r in every.values():
        if low in (r.name.lower(), r.command.lower()):
            return r
    import difflib

    names = sorted({r.command for r in every.values()})
    close = difflib.get_close_matches(low, names, n=1)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    raise ParameterError(f"There is no method called {name!r}.{hint} "
                         f"The methods are: {', '.join(names)}.")


# ------------------------------------------------------------------------------ blobs
_BLOBS: dict[str, bytes] = {}
_BLOB_FILES: dict[str, Path] = {}
_blob_dir: Path | None = None


def put_blob(data: bytes, name: str) -> str:
    """Store binary input (an image, a mesh file) and return its reference for ``options``:
    ``"blob:<sha256>/<name>"`` (``name``: the file name, kept for its extension)."""
    data = bytes(data)
    digest = hashlib.sha256(data).hexdigest()
    base = Path(str(name)).name or "data"
    ref = f"blob:{digest}/{base}"
    _BLOBS[ref] = data
    return ref


def put_blob_file(path) -> str:
    """:func:`put_blob` of a file's bytes under its own name."""
    p = Path(path)
    return put_blob(p.read_bytes(), p.name)


def is_blob_ref(value: Any) -> bool:
    return isinstance(value, str) and value.startswith("blob:") and "/" in value


def _check_ref(ref: str) -> None:
    from algorithms.errors import ParameterError

    if not is_blob_ref(ref):
        raise ParameterError(f"{ref!r} is not a reference to stored input data.")
    if ref not in _BLOBS:
        raise ParameterError(f"The input {ref.split('/', 1)[1]!r} of this run is missing (it "
                             "was not saved with the project or log); load it again.")


def blob_bytes(ref: str) -> bytes:
    """The bytes behind a reference made by :func:`put_blob`."""
    _check_ref(ref)
    return _BLOBS[ref]


def blob_path(ref: str) -> Path:
    """A file holding the blob's bytes under its own name (for readers that want a path)."""
    global _blob_dir
    _check_ref(ref)
    p = _BLOB_FILES.get(ref)
    if p is not None and p.is_file():
        return p
    if _blob_dir is None:
        _blob_dir = Path(tempfile.mkdtemp(prefix="stylize3d-blobs-"))
    digest, name = ref[len("blob:"):].split("/", 1)
    d = _blob_dir / digest[:32]
    d.mkdir(exist_ok=True)
    p = d / name
    p.write_bytes(_BLOBS[ref])
    _BLOB_FILES[ref] = p
    return p


def blob_refs(obj: Any) -> list[str]:
    """Every blob reference inside a JSON-able object (options, a project's panels)."""
    out: list[str] = []
    if is_blob_ref(obj):
        out.append(obj)
    elif isinstance(obj, dict):
        for v in obj.values():
            out.extend(blob_refs(v))
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            out.extend(blob_refs(v))
    return out


def add_blob(ref: str, data: bytes) -> None:
    """Register the bytes of a reference read back from a project or a log (checked)."""
    from algorithms.errors import ParameterError

    if not is_blob_ref(ref):
        raise ParameterError(f"{ref!r} is not a reference to stored input data.")
    digest = ref[len("blob:"):].split("/", 1)[0]
    if hashlib.sha256(data).hexdigest() != digest:
        raise ParameterError(f"The stored input {ref.split('/', 1)[1]!r} is damaged (its "
                             "content does not match its checksum).")
    _BLOBS[ref] = bytes(data)


# ------------------------------------------------------------------------------ running
@dataclass
class RunResult:
    """What :func:`run` returns: the document after the run, its last Step and its figures."""

    state: Any  # MeshState
    last: Step
    outcome: dict
    recipe: Recipe
    params: Any
    options: dict


def _as_state(obj):
    from app.document import MeshState

    if isinstance(obj, MeshState):
        return obj
    st = getattr(obj, "state", None)  # a Project
    if isinstance(st, MeshState):
        return st
    if isinstance(obj, (tuple, list)) and len(obj) == 2:
        return MeshState.make(obj[0], obj[1])
    from algorithms.errors import ParameterError

    raise ParameterError("run() needs a MeshState, a Project or a (V, F) pair.")


def run(method: str, state, params=None, options: dict | None = None, *,
        cache: dict | None = None, callback: Callable[[Step], None] | None = None
        ) -> RunResult:
    """Run a method to its end, headless: ``run("cubic", project_or_state, {"lam": 0.4})``.

    ``state``: a MeshState, a :class:`app.project.Project` (its mesh, painting and the
    method's saved panel settings) or ``(V, F)``.
    ``params``: a Params instance (used as it is) or a (partial) dict whose values replace the
    project's saved ones (the fields it does not name keep the project's values, as on the
    command line). ``callback`` sees every Step.
    """
    recipe = get_recipe(method)
    saved = {}
    panels = getattr(state, "panels", None)
    if isinstance(panels, dict):
        saved = panels.get(recipe.name) or {}
    st = _as_state(state)
    if params is None:
        params = saved.get("params", {})
    elif isinstance(params, dict):  # a partial dict: on top of the saved settings (issue 39)
        params = {**saved.get("params", {}), **params}
    if isinstance(params, dict):
        params = recipe.make_params(params)
    if options is None:
        options = dict(saved.get("options", {}))
    last = None
    for last in recipe.steps(st, params, options, {} if cache is None else cache):
        if callback is not None:
            callback(last)
    if last is None:
        raise RuntimeError(f"{recipe.name} produced no result")
    after = recipe.result(st, last, options)
    out = recipe.outcome(last) if recipe.outcome is not None else {}
    return RunResult(after, last, out or {}, recipe, params, options)


def load(path, *, clean: bool = False):
    """A :class:`app.project.Project` of a ``.s3d`` project or of a mesh file (checked as the
    app checks it; ``clean=True`` first fixes what Clean can fix). Raises a plain
    Stylize3DError for a file that cannot be used."""
    from app.project import Project, is_project_path, read_project

    if is_project_path(path):
        return read_project(path)
    from pathlib import Path as _P

    from algorithms.errors import InvalidMeshError
    from algorithms.mesh import clean_mesh, read_mesh, validate_mesh
    from app.document import MeshState

    data = read_mesh(path)
    V, F = data.V, data.F
    if clean:
        res = clean_mesh(V, F)
        V, F = res.V, res.F
    report = validate_mesh(V, F)
    if report.errors:
        raise InvalidMeshError(f"{_P(path).name} cannot be used as it is:\n{report.summary()}"
                               "\nTry load(path, clean=True) or `stylize3d clean`.")
    return Project(MeshState.make(V, F), source=_P(path).name)


def run_recipe(title: str, state, params_dict: dict, options: dict | None = None,
               cache: dict | None = None) -> Step | None:
    """Run a recipe to its end; returns the last Step (None if it yielded nothing)."""
    recipe = get_recipe(title)
    params = recipe.make_params(params_dict) if isinstance(params_dict, dict) else params_dict
    last = None
    for last in recipe.steps(state, params, options or {}, {} if cache is None else cache):
        pass
    return last


def outcome_hash(outcome: dict) -> str:
    """SHA-256 of a recipe's outcome (numbers and arrays, by name): the study log's check of
    runs that do not change the document."""
    h = hashlib.sha256()
    for k in sorted(outcome):
        v = outcome[k]
        h.update(str(k).encode())
        if isinstance(v, np.ndarray):
            a = np.ascontiguousarray(v)
            h.update(str(a.dtype.str).encode() + str(a.shape).encode())
            h.update(a.tobytes())
        else:
            h.update(repr(v).encode())
    return h.hexdigest()

