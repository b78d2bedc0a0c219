"""Recipes "Subdivision" and "Subdivision training": neural subdivision (thesis ch. 4), the
classic schemes, and training a network on the open mesh.

"Subdivision" (CLI ``subdivide``; params :class:`~algorithms.subdivision.model.SubdivideParams`)
subdivides the mesh ``levels`` times with neural / Loop / modified butterfly / mid-point
subdivision, after QSlimming it to about ``coarsen_first`` vertices when that is set (and below
the vertex count). The last step carries the new faces (:class:`MeshStep`), so the result is the
new mesh (:func:`app.recipes.positions_result`). Options:

* ``weights`` (str): which network neural subdivision uses — ``"shipped"`` (the project's
  weights), ``"trained"`` (``trained_weights``) or ``"file"`` (``weights_file``); the panel's
  older combo texts ("Shipped", "Trained here", "File…") are read too. A choice whose weights
  are not given falls back to the shipped weights (what the panel always did);
* ``trained_weights`` (str or None): blob reference of the weights a "Subdivision training" run
  made (its outcome's ``weights``);
* ``weights_file`` (str or None): blob reference of a weights file (:func:`weights_blob_from_file`
  = :func:`app.recipes.put_blob_file` after checking the file);
* ``training`` (dict, optional): the panel's training settings, kept with its other settings in
  project files; not read by this recipe.

"Subdivision training" (CLI ``subdivide-train``; params :func:`training_params_cls`, the fields of
:class:`~algorithms.subdivision.data.DataParams` and
:class:`~algorithms.subdivision.train.TrainParams` together — ``seed`` seeds the random
collapses, ``training_seed`` the initial weights (``torch.manual_seed``) and the shuffling
(a NumPy generator); PyTorch trains on one thread) makes the coarse meshes of the open mesh
(streamed as progress steps), then trains, one :class:`TrainingStep` per epoch with the training
and validation losses; stopping early keeps the best weights so far (each step carries them).
The document does not change; the outcome (:func:`training_outcome`) holds the losses, the best
epoch and the trained weights as a weights file stored as a blob (``weights``) with its SHA-256
(``weights_sha256``). Options: ``workers`` (int, default 2: local processes making the coarse
meshes; 1 = in this process) and ``cache`` (bool, default True: read and write the on-disk data
cache, ``$STYLIZE3D_CACHE``); neither changes the result (the data module tests that a coarse
mesh does not depend on where it was made or whether it came from the cache).
"""

from __future__ import annotations

import dataclasses
import tempfile
import threading
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import Recipe, blob_path, put_blob, put_blob_file, register, unchanged_result

SUBDIVIDE_RECIPE = "Subdivision"
TRAIN_RECIPE = "Subdivision training"
#: the ``weights`` option's values
WEIGHTS_CHOICES = ("shipped", "trained", "file")
#: the panel's combo texts (read as the choices above)
_WEIGHTS_TEXTS = {"Shipped": "shipped", "Trained here": "trained", "File…": "file"}
#: the name a trained network's weights blob gets
TRAINED_WEIGHTS_NAME = "subdivision_weights.pt"


@dataclass
class MeshStep(Step):
    """The subdivided mesh: ``V`` (n, 3) float64 with its own faces ``F`` (m, 3) int64 (the
    Qt-free twin of :class:`app.jobs.MeshStep`)."""

    F: np.ndarray | None = None
    #: what neural subdivision did to stay in its network's range ('' when nothing), for the
    #: panel to show (see algorithms.subdivision.inference.scale_plan)
    note: str = ""
    #: the scheme that made the mesh: "neural", or "loop" when the network was not used
    #: (``fallback``), "neural+loop" when the network made the first levels and Loop the rest
    #: (``fallback`` too), or the classic scheme asked for
    method_used: str = ""
    fallback: bool = False
    #: what made each level ("neural" / "loop" / the classic scheme), in order
    levels_used: tuple = ()
    #: with ``fallback``: why the network was not used (one short clause)
    fallback_reason: str = ""


@dataclass
class TrainingStep(Step):
    """One training epoch (``iteration``, ``total``, the first validation mesh's prediction as
    ``V``, the trainer's ``metrics``), with what training has kept so far.

    best_state : the best validation weights so far (a state dict of tensors; replaced, never
        changed in place, by later epochs).
    best_epoch, best_loss : the epoch of those weights and its validation loss.
    losses, validation_losses : the training and validation loss of every epoch so far.
    stopped_early : training ends here by its patience rule.
    info : the data and training settings (for the weights file's ``info``).
    data_seconds : how long making the coarse meshes took (for display; varies run to run).
    """

    best_state: dict | None = None
    best_epoch: int = 0
    best_loss: float = float("inf")
    losses: tuple = ()
    validation_losses: tuple = ()
    stopped_early: bool = False
    info: dict = dataclasses.field(default_factory=dict)
    data_seconds: float = 0.0


# ------------------------------------------------------------------------------ weights
def weights_choice(options: dict | None) -> str:
    """The ``weights`` option as one of :data:`WEIGHTS_CHOICES` (default "shipped")."""
    from algorithms.errors import ParameterError

    value = (options or {}).get("weights") or "shipped"
    value = _WEIGHTS_TEXTS.get(value, value)
    if value not in WEIGHTS_CHOICES:
        raise ParameterError(f"Unknown weights {value!r} for neural subdivision: use one of "
                             f"{', '.join(WEIGHTS_CHOICES)}.")
    return value


def weights_ref(options: dict | None) -> str | None:
    """The blob reference of the weights the options choose, or None for the shipped ones."""
    options = options or {}
    choice = weights_choice(options)
    if choice == "trained":
        return options.get("trained_weights") or None
    if choice == "file":
        return options.get("weights_file") or None
    return None


def load_network(ref: str | None, cache: dict | None = None):
    """The network (:class:`~algorithms.subdivision.inference.Network`, NumPy; no PyTorch) of a
    weights blob (None: the shipped weights): ours or the thesis author's ``netparams.dat``. A
    blob's network is kept in ``cache`` (blobs are content addressed). Raises a plain error
    (WeightsError, ParameterError) for a missing or foreign file."""
    from algorithms.subdivision.inference import load_network as read_network

    if ref is None:
        return read_network(None)
    nets = None if cache is None else cache.setdefault("networks", {})
    if nets is not None and ref in nets:
        return nets[ref]
    net = read_network(blob_path(ref))
    if nets is not None:
        nets[ref] = net
    return net


def weights_blob_from_file(path) -> str:
    """Check a weights file (a plain error if it is neither ours nor the author's network) and
    store it as a blob; returns the reference for the ``weights_file`` option."""
    from algorithms.subdivision.inference import load_network as read_network

    read_network(path)
    return put_blob_file(path)


# ------------------------------------------------------------------------------ subdividing
def subdivision_steps(state, params, options: dict | None = None, cache: dict | None = None
                      ) -> Iterator[Step]:
    """The Subdivision panel's Run: progress steps (per-mille ``iteration`` of ``total`` 1000,
    ``V`` the input, a message: "QSlim to N vertices", "Level 1 of 2: moving the vertices", ...),
    then one :class:`MeshStep` with the subdivided mesh (its ``note`` says what neural
    subdivision did to stay within its network's training range, '' when nothing).

    The subdivision itself runs in this generator in small pieces (neural: chunks of
    half-flaps, :func:`~algorithms.subdivision.inference.neural_subdivision_iter`; the classic
    schemes: one level at a time), so a consumer that stops asking (Stop) stops it within one
    piece; nothing is imported from PyTorch."""
    from algorithms.steps import with_progress

    options = options or {}
    cache = {} if cache is None else cache
    net = load_network(weights_ref(options), cache) if params.method == "neural" else None
    V, F = np.asarray(state.V), np.asarray(state.F)
    if params.coarsen_first and params.coarsen_first < len(V):
        def work(progress):
            from algorithms.errors import ParameterError
            from algorithms.subdivision.inference import coarsen_for_network
            from algorithms.subdivision.metrics import coarsening_problem

            progress(0.1, f"QSlim to {params.coarsen_first} vertices")
            # a scene of parts: each part to its share (what the network wants of it)
            Vc, Fc = coarsen_for_network(net, V, F, params.coarsen_first)
            why = coarsening_problem(V, F, Vc, Fc, params.coarsen_first)
            if why:   # issue 36 item 4: never subdivide a collapsed copy
                raise ParameterError(
                    f"'Coarsen first' to {params.coarsen_first} vertices collapsed this mesh "
                    f"({why}). Use a larger count, or 0 to subdivide the mesh as it is.")
            return Vc, Fc

        box: dict = {}
        yield from with_progress(work, state.V, box)
        if "value" not in box:
            return
        V, F = box["value"]
    levels = int(params.levels)
    note = ""
    method_used, fallback, reason = params.method, False, ""
    levels_used = (params.method,) * levels
    metrics: dict = {}
    if params.method == "neural":
        from algorithms.subdivision.inference import SubdividedStep, neural_subdivision_iter

        last = None
        for step in neural_subdivision_iter(V, F, levels, net,
                                            dense=getattr(params, "dense_input", "loop")):
            if isinstance(step, SubdividedStep):
                last = step
            else:
                step.V = state.V
                yield step
        V, F, note = last.V, last.F, last.note
        metrics = dict(last.metrics)   # the guard's (bending_vs_butterfly, unsmoothed_vertices)
        fallback = bool(getattr(last, "fallback", False))
        levels_used = tuple(last.levels_used) or (("loop" if fallback else "neural"),) * levels
        # neural, loop or neural+loop (a level is "neural+loop" where the guard handed some of
        # the mesh's parts to Loop)
        method_used = "+".join(dict.fromkeys(x for lv in levels_used for x in lv.split("+")))
        reason = str(getattr(last, "fallback_reason", "")) if fallback else ""
    else:
        from algorithms.subdivision.baselines import subdivide_baseline

        name = {"loop": "Loop", "butterfly": "Butterfly", "midpoint": "Mid-point"}.get(
            params.method, params.method)
        for k in range(levels):
            yield Step(int(1000 * k / levels), 1000, state.V, {},
                       f"Level {k + 1} of {levels}: {name} subdivision")
            V, F = subdivide_baseline(V, F, 1, params.method)
    message = f"{len(F):,} triangles" + (f". {note}" if note else "")
    yield MeshStep(1, 1, np.asarray(V, dtype=np.float64), metrics, message,
                   F=np.asarray(F, dtype=np.int64), note=note, method_used=method_used,
                   fallback=fallback, levels_used=levels_used, fallback_reason=reason)


def method_words(method_used: str, fallback: bool, levels_used=(), blended: int = 0) -> str:
    """ "neural subdivision", "Loop subdivision instead of the network", "neural subdivision
    (level 1), then Loop instead of the network (level 2)", ... (what ran); with ``blended``
    (the guard's ``loop_blended_vertices``), where Loop's positions replaced the network's."""
    extra = (f" (Loop's positions blended in at {blended:,} vertices over its bulges)"
             if blended else "")
    return _scheme_words(method_used, fallback, levels_used) + extra


def _scheme_words(method_used: str, fallback: bool, levels_used=()) -> str:
    names = {"neural": "neural", "loop": "Loop", "butterfly": "modified butterfly",
             "midpoint": "mid-point"}
    if method_used == "neural+loop":
        used = list(levels_used)
        k = used.count("neural")
        n = len(used)

        def span(a, b):
            return f"level {a}" if a == b else f"levels {a}-{b}"
        if "neural+loop" in used:      # the guard handed some parts to Loop
            j = used.index("neural+loop") + 1
            last = used.index("loop") + 1 if "loop" in used else n + 1
            said = (f"neural subdivision, with Loop instead of the network on some parts "
                    f"({span(j, last - 1)})")
            return said + (f", then Loop on every part ({span(last, n)})" if last <= n else "")
        if k and n > k:
            return (f"neural subdivision ({span(1, k)}), then Loop instead of the network "
                    f"({span(k + 1, n)})")
        return "neural subdivision, then Loop instead of the network"
    name = names.get(method_used, method_used)
    return f"{name} subdivision" + (" instead of the network" if fallback else "")


def _subdivide_params():
    from algorithms.subdivision.model import SubdivideParams

    return SubdivideParams


def _subdivision_outcome(last: Step) -> dict:
    F = getattr(last, "F", None)
    out = {"vertices": int(len(last.V))}
    if F is not None:
        out["faces"] = int(len(F))
    if getattr(last, "note", ""):
        out["note"] = str(last.note)
    if getattr(last, "method_used", ""):   # what ran, said everywhere (issues 36, 39)
        out["method_used"] = str(last.method_used)
        out["fallback"] = bool(last.fallback)
        if getattr(last, "levels_used", ()):
            out["levels_used"] = list(last.levels_used)
        if getattr(last, "fallback_reason", ""):
            out["fallback_reason"] = str(last.fallback_reason)
    # the guard's local repair of crossings (said in the note too): the level before blended
    # back in where the network crossed itself
    # and the other places where Loop was used instead of the network: parts of the mesh, and
    # the vertices blended in over the network's bulges (both said in the note too)
    for key in ("unsmoothed_vertices", "loop_parts", "loop_blended_vertices"):
        count = int((last.metrics or {}).get(key, 0))
        if count:
            out[key] = count
    return out


# ------------------------------------------------------------------------------ training
_params_lock = threading.Lock()


def training_params_cls() -> type:
    """``SubdivisionTrainingParams``: the fields of DataParams then TrainParams (their labels,
    ranges and defaults), one frozen dataclass (made on first use; also this module's
    attribute of that name)."""
    cls = globals().get("SubdivisionTrainingParams")
    if cls is not None:
        return cls
    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.train import TrainParams

    with _params_lock:
        cls = globals().get("SubdivisionTrainingParams")
        if cls is not None:
            return cls
        fields = []
        for part in (DataParams, TrainParams):
            hints = typing.get_type_hints(part)
            for f in dataclasses.fields(part):
                fields.append((f.name, hints[f.name],
                               dataclasses.field(default=f.default, metadata=f.metadata)))
        cls = dataclasses.make_dataclass("SubdivisionTrainingParams", fields, frozen=True)
        cls.__module__ = __name__
        cls.__doc__ = ("Training neural subdivision on a mesh: data generation (DataParams) "
                       "and training (TrainParams) in one form.")
        globals()["SubdivisionTrainingParams"] = cls
        return cls


def __getattr__(name: str):  # the lazily made Params class (PEP 562)
    if name == "SubdivisionTrainingParams":
        return training_params_cls()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def split_training_params(params):
    """(DataParams, TrainParams) of a training Params instance (validated)."""
    from algorithms.params import params_from_dict
    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.train import TrainParams

    out = []
    for part in (DataParams, TrainParams):
        names = [f.name for f in dataclasses.fields(part)]
        out.append(params_from_dict(part, {k: getattr(params, k) for k in names}))
    return tuple(out)


def training_steps(state, params, options: dict | None = None, cache: dict | None = None,
                   *, meshes=None, scheduler: str | None = None, cache_dir=None
                   ) -> Iterator[Step]:
    """"Train on this mesh": the coarse meshes of the mesh (progress steps, cancellable), then
    one :class:`TrainingStep` per epoch (stopping keeps the best weights: every step carries
    them).

    For the command line (``subdivide-train``), beyond the recipe's input: ``meshes``, a list
    of (V, F) to make the coarse meshes from instead of the state's mesh (spread evenly over
    them; ``[(state.V, state.F)]`` is the recipe's run), ``scheduler``, the address of a Dask
    scheduler to make them on, and ``cache_dir``, the data cache's folder (default
    ``$STYLIZE3D_CACHE``); where the data is made or cached does not change it."""
    import time

    from algorithms.params import params_to_dict
    from algorithms.steps import with_progress
    from algorithms.subdivision.train import Trainer, training_data

    options = options or {}
    dparams, tparams = split_training_params(params)
    workers = int(options.get("workers", 2))
    use_cache = bool(options.get("cache", True))
    if meshes is None:
        meshes = [(state.V, state.F)]
    shapes = [(np.asarray(V), np.asarray(F)) for V, F in meshes]

    def make_data(progress):
        return training_data(shapes, dparams, tparams, progress=progress, workers=workers,
                             scheduler=scheduler, cache_dir=cache_dir, use_cache=use_cache)

    box: dict = {}
    t0 = time.perf_counter()
    yield from with_progress(make_data, state.V, box)
    if "value" not in box:
        return
    data_seconds = time.perf_counter() - t0
    samples, validation = box["value"]
    trainer = Trainer(samples, tparams, validation_samples=validation)
    from algorithms.subdivision.inference import mean_edge_length

    # the edge length the network is trained at (its scale guard's reference, see
    # algorithms.subdivision.inference.scale_plan)
    ref_edge = float(np.mean([mean_edge_length(s.V, s.F) for s in samples]))
    info = {**params_to_dict(dparams), **params_to_dict(tparams), "mean_edge_length": ref_edge}
    losses: list[float] = []
    vlosses: list[float] = []
    steps = trainer.steps()
    try:
        for s in steps:
            losses.append(float(s.metrics["loss"]))
            vlosses.append(float(s.metrics["validation_loss"]))
            yield TrainingStep(s.iteration, s.total, s.V, s.metrics, s.message,
                               best_state=trainer.best_state, best_epoch=int(trainer.best_epoch),
                               best_loss=float(trainer.best_loss), losses=tuple(losses),
                               validation_losses=tuple(vlosses),
                               stopped_early=bool(trainer.stopped_early), info=info,
                               data_seconds=data_seconds)
    finally:
        steps.close()


def trained_weights_bytes(step: TrainingStep, extra_info: dict | None = None) -> bytes:
    """The weights file (the project's format, :func:`~algorithms.subdivision.model.save_weights`)
    of a training step's best weights, as bytes (the same bytes for the same weights);
    ``extra_info`` is added to the file's ``info`` (e.g. the command line's ``trained_on``)."""
    from algorithms.subdivision.model import SubdivisionNet, save_weights

    net = SubdivisionNet(seed=0)  # seeded: leaves the global torch generator alone
    net.load_state(step.best_state)
    info = {"trained_by": TRAIN_RECIPE, "epochs_run": int(step.iteration),
            "best_epoch": int(step.best_epoch),
            "best_validation_loss": float(step.best_loss), **step.info, **(extra_info or {})}
    with tempfile.TemporaryDirectory(prefix="stylize3d-weights-") as d:
        p = Path(d) / TRAINED_WEIGHTS_NAME
        save_weights(p, net, info)
        return p.read_bytes()


def training_outcome(last: Step) -> dict:
    """What a training run made: ``epochs`` (run), ``best_epoch``, ``best_validation_loss``,
    ``losses`` / ``validation_losses`` (per epoch, float64 arrays), ``stopped_early``,
    ``weights`` (blob reference of the weights file, for the ``trained_weights`` option) and
    ``weights_sha256`` (of its bytes). Empty when no epoch finished."""
    if getattr(last, "best_state", None) is None:
        return {}
    ref = put_blob(trained_weights_bytes(last), TRAINED_WEIGHTS_NAME)
    return {"epochs": int(last.iteration), "best_epoch": int(last.best_epoch),
            "best_validation_loss": float(last.best_loss),
            "losses": np.asarray(last.losses, dtype=np.float64),
            "validation_losses": np.asarray(last.validation_losses, dtype=np.float64),
            "stopped_early": bool(last.stopped_early),
            "weights": ref, "weights_sha256": ref[len("blob:"):].split("/", 1)[0]}


register(Recipe(SUBDIVIDE_RECIPE, "subdivide", _subdivide_params, subdivision_steps,
                outcome=_subdivision_outcome, changes_faces=True))
register(Recipe(TRAIN_RECIPE, "subdivide-train", training_params_cls, training_steps,
                result=unchanged_result, outcome=training_outcome,
                note="the document does not change; the outcome holds the trained weights"))
