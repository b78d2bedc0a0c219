"""Recipe "Paparazzi": image filters applied to a shape through its renderings (thesis ch. 2).

``params``: :class:`~algorithms.paparazzi.PaparazziParams` (iterations, learning rate, σ,
resolution, view width, remeshing, monitor view, upsampling and the camera ``seed``: all the
randomness of a run comes from it, so the same input gives the same bits). The panel's form
(:class:`app.panels.paparazzi.PaparazziPanelParams`) has the same fields with a shorter default
run; any object with these fields is accepted.

``options`` (JSON-able):

* ``filter`` (str): the image filter's registry name (``guided``, ``quantize``, ``slic``,
  ``l0``, ``neural-style``, ``target-image``, ``target-mesh`` or a plug-in's); default
  ``"guided"``.
* ``filter_params`` (dict): that filter's Params as a (partial) dict. Its file fields (text
  fields without choices: the target image, the target mesh, the neural-style painting) hold
  ``"blob:..."`` references (:func:`app.recipes.put_blob_file`), read back here with
  :func:`app.recipes.blob_path`; ``""`` for an optional file left empty. (A plain path is
  accepted too, for scripts; the panel stores one only for a file it could not read, whose
  run then fails with the reader's plain message, as it did before.)
* ``plugin`` (str, optional): a ``"blob:..."`` reference to the Python file that registered
  the filter (a plug-in, :func:`algorithms.paparazzi.filters.load_filter_plugin`); when the
  filter registered under that name is not the one of this file (another process: the CLI, a
  study replay), the file is loaded from the blob first.

The steps carry their (remeshed) faces: ``Recipe.result`` commits a new mesh when they changed,
after checking that it is a valid 2-manifold of the input's topology. The Paparazzi optimizer
itself refuses an input that is not a 2-manifold with a plain message.

The panel's views are computed here too (Qt-free): :func:`rgb8` (the rendered / filtered
pictures of a step), :func:`monitor_points` (which monitor energies the plot shows),
:func:`describe_filter_file` (a chosen file read as the filter will read it) and
:func:`manifold_report` (the panel's check before a run, with its offer to clean).
"""

from __future__ import annotations

import dataclasses
import hashlib
import sys
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import (Recipe, blob_path, is_blob_ref, positions_result, put_blob,
                         put_blob_file, register)

DEFAULT_FILTER = "guided"


# ------------------------------------------------------------------------------ filters
def filter_names() -> list[str]:
    """The registered image filters (built-in ones first, then those registered later)."""
    from algorithms.paparazzi import filter_names as names

    return names()


def filter_spec(name: str):
    """The :class:`~algorithms.paparazzi.FilterSpec` registered as ``name`` (a
    ParameterError with a plain message when there is none)."""
    from algorithms.paparazzi import get_filter

    return get_filter(name)


def file_fields(spec) -> list[str]:
    """The names of a filter's file fields: text fields without choices (a target image, a
    target mesh, a painting)."""
    from algorithms.params import describe

    return [s.name for s in describe(spec.params) if s.type is str and not s.choices]


#: filter function -> the blob reference of the plug-in file it came from (taken once, the
#: first time a run uses it: a file edited later does not change what the filter runs)
_PLUGIN_REFS: dict[Any, str | None] = {}


def _plugin_file(spec) -> Path | None:
    """The Python file a filter was registered from, when it is not part of the app (a plug-in
    loaded with ``load_filter_plugin``, or a user's module); None for the built-in filters."""
    module = getattr(spec.function, "__module__", "") or ""
    if module.split(".")[0] in ("algorithms", "app"):
        return None
    path = getattr(sys.modules.get(module), "__file__", None)
    if not path or not str(path).endswith(".py") or not Path(path).is_file():
        return None
    return Path(path)


def plugin_ref(spec) -> str | None:
    """The blob reference of the plug-in file a filter comes from (see :func:`_plugin_file`),
    or None for a built-in filter."""
    fn = spec.function
    if fn not in _PLUGIN_REFS:
        path = _plugin_file(spec)
        ref = None
        if path is not None:
            try:
                ref = put_blob(path.read_bytes(), path.name)
            except OSError:
                ref = None
        _PLUGIN_REFS[fn] = ref
    return _PLUGIN_REFS[fn]


def ensure_filter(name: str, plugin: str | None = None):
    """The FilterSpec ``name``; with a ``plugin`` reference, the one that file registers (the
    file is loaded from its blob unless the filter registered now is that file's)."""
    from algorithms.errors import ParameterError
    from algorithms.paparazzi import get_filter
    from algorithms.paparazzi.filters import load_filter_plugin

    if not plugin:
        return get_filter(name)
    try:
        spec = get_filter(name)
    except ParameterError:
        spec = None
    if spec is not None:
        if _PLUGIN_REFS.get(spec.function) == plugin:
            return spec
        path = _plugin_file(spec)
        digest = plugin[len("blob:"):].split("/", 1)[0] if is_blob_ref(plugin) else None
        if path is not None and digest is not None:
            try:
                same = hashlib.sha256(path.read_bytes()).hexdigest() == digest
            except OSError:
                same = False
            if same:
                _PLUGIN_REFS.setdefault(spec.function, plugin)
                return spec
    names = load_filter_plugin(blob_path(plugin))
    spec = get_filter(name)
    for n in names:
        _PLUGIN_REFS[filter_spec(n).function] = plugin
    return spec


def filter_options(name: str, fparams) -> dict:
    """``options`` of a run with filter ``name`` and its Params ``fparams`` (file fields holding
    paths): the files become blob references (a file that cannot be read keeps its path, so the
    run fails with the filter's own plain message), a plug-in's file is referenced."""
    from algorithms.params import params_to_dict

    spec = filter_spec(name)
    values = params_to_dict(fparams)
    for f in file_fields(spec):
        v = values.get(f)
        if isinstance(v, str) and v and not is_blob_ref(v):
            try:
                if Path(v).is_file():
                    values[f] = put_blob_file(v)
            except OSError:
                pass
    out = {"filter": name, "filter_params": values}
    ref = plugin_ref(spec)
    if ref is not None:
        out["plugin"] = ref
    return out


def resolve_filter_params(spec, values: dict | None):
    """The filter's Params from ``options["filter_params"]``: blob references become the paths
    of files holding their bytes (:func:`app.recipes.blob_path`)."""
    from algorithms.params import params_from_dict

    values = dict(values or {})
    for f in file_fields(spec):
        v = values.get(f)
        if is_blob_ref(v):
            values[f] = str(blob_path(v))
    return params_from_dict(spec.params, values)


def run_params(params):
    """A :class:`PaparazziParams` with the fields of ``params`` (e.g. the panel's form)."""
    from algorithms.paparazzi import PaparazziParams

    if type(params) is PaparazziParams:
        return params
    return PaparazziParams(**{f.name: getattr(params, f.name)
                              for f in dataclasses.fields(PaparazziParams)})


# ------------------------------------------------------------------------------ the run
def paparazzi_steps(state, params, options: dict | None = None, cache: dict | None = None
                    ) -> Iterator[Step]:
    """The Paparazzi panel's run (module docstring). A generator: the filter is found, its
    files read and the optimizer built when the first step is asked for (the worker thread).
    The optimizer object and the seconds its set-up took are left in ``cache`` (``"run"``,
    ``"setup_seconds"``) for a caller that reports more (the command line's checks).

    A run that ends without lowering its monitor energy did not converge: with
    ``lowest_fallback`` on (the default) the generator raises, after its last step,
    :class:`algorithms.paparazzi.EnergyNotLowered`, so every caller (panel, command line,
    replay, batch) fails with its plain message and changes nothing."""
    import time

    from algorithms.paparazzi import Paparazzi, require_lowered

    options = options or {}
    spec = ensure_filter(str(options.get("filter") or DEFAULT_FILTER), options.get("plugin"))
    fparams = resolve_filter_params(spec, options.get("filter_params"))
    t0 = time.perf_counter()
    run = Paparazzi(np.asarray(state.V), np.asarray(state.F), spec, fparams, run_params(params))
    if cache is not None:
        cache["run"], cache["setup_seconds"] = run, time.perf_counter() - t0
    last = None
    for last in run.steps():
        yield last
    if last is not None and run.params.lowest_fallback:
        require_lowered(last.metrics, spec, run.params.iterations)


def paparazzi_result(before, last: Step, options: dict | None = None):
    """The document after a run: the last step's mesh (new faces after remeshing), refused
    with a plain message when it is not a valid 2-manifold of the input's topology."""
    from algorithms.errors import InvalidMeshError
    from algorithms.mesh.topology import boundary_loops, euler_characteristic, is_manifold

    V = np.asarray(last.V, dtype=np.float64)
    F = getattr(last, "F", None)
    F = before.F if F is None else np.asarray(F, dtype=np.int64)
    ok = (V.ndim == 2 and V.shape[1] == 3 and len(V) > 0 and np.isfinite(V).all()
          and F.ndim == 2 and F.shape[1] == 3 and len(F) > 0 and F.min() >= 0
          and F.max() < len(V))
    if not ok:
        raise InvalidMeshError("Paparazzi returned an invalid mesh; the document was not "
                               "changed.")
    if F is not before.F and not (F.shape == before.F.shape and np.array_equal(F, before.F)):
        if not is_manifold(F) or (
                euler_characteristic(F), len(boundary_loops(F))) != (
                euler_characteristic(before.F), len(boundary_loops(before.F))):
            raise InvalidMeshError("Paparazzi's remeshed result is not a 2-manifold of the "
                                   "input's shape (holes, handles); the document was not "
                                   "changed.")
    return positions_result(before, last, options)


def _paparazzi_params():
    from algorithms.paparazzi import PaparazziParams

    return PaparazziParams


def paparazzi_outcome(last: Step) -> dict:
    """The run's figures: iterations, energies, mesh size, remeshes, rollbacks."""
    out = {"iterations": int(last.iteration)}
    for k, v in last.metrics.items():
        out[k] = float(v)
    F = getattr(last, "F", None)
    out["triangles"] = int(len(F)) if F is not None else 0
    return out


# ------------------------------------------------------------------------------ panel views
def rgb8(img) -> np.ndarray:
    """An ``(H, W[, C])`` float image in [0, 1] (C = 1 or 3, NaN as black) as a contiguous
    ``(H, W, 3)`` uint8 picture (the panel's rendered / filtered views)."""
    a = np.asarray(img, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    a = np.nan_to_num(a[..., :3], nan=0.0)
    return np.ascontiguousarray((np.clip(a, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))


def monitor_points(history: Iterable, every: int, iterations: int | None,
                   have_start: bool) -> tuple[list, bool]:
    """The monitor energies to plot from a batch of ``(iteration, metrics)``: the initial one
    (once: ``have_start`` says whether it is plotted already), then the value where it was
    evaluated (every ``every`` iterations and at the last, ``iterations``: the last shape's,
    ``last_monitor_energy``), not its repeated value in between. Returns
    ``(values, have_start)``."""
    out = []
    for it, metrics in history:
        if "monitor_energy" not in metrics:
            continue
        if not have_start:
            first = metrics.get("initial_monitor_energy")
            if first is not None:
                out.append(first)
                have_start = True
        if iterations is not None and it == iterations:
            # the last shape's energy, not the result's when an earlier, lower shape was kept
            # (PaparazziParams.lowest_fallback): the plot is the run's trajectory
            out.append(metrics.get("last_monitor_energy", metrics["monitor_energy"]))
        elif every and it % every == 0:
            out.append(metrics["monitor_energy"])
    return out, have_start


def manifold_report(V, F):
    """None when Paparazzi can run on the mesh (a 2-manifold), else the mesh's validation
    report (``needs_cleaning``, ``errors``, ``advice``, ``summary()``)."""
    from algorithms.mesh import validate_mesh
    from algorithms.mesh.topology import is_manifold

    if is_manifold(F):
        return None
    return validate_mesh(V, F)


def describe_filter_file(filter_name: str, field: str, kind: str, path: str) -> str:
    """Read ``path`` as the filter will for its file field ``field`` (``kind``: 'image',
    'mesh' or 'file'); a short description ("64 × 64 pixels, colour; ..."). A file it cannot
    use raises a :class:`~algorithms.errors.Stylize3DError` with a plain message."""
    reader = filter_spec(filter_name).file_readers.get(field) if filter_name else None
    if reader is not None:
        return _check_with_reader(reader, kind, path)
    return _check_file(kind, path)


def _check_with_reader(reader, kind: str, path: str) -> str:
    """Check a file with the filter's own reader (``FilterSpec.file_readers``: e.g. the
    neural-style painting, which may have any shape, since its reader crops the central
    square). A reader that fails without a Stylize3DError still gives a plain message."""
    from algorithms.errors import Stylize3DError
    from algorithms.paparazzi import ImageReadError

    try:
        data = reader(str(path))
    except Stylize3DError:
        raise
    except Exception as e:  # noqa: BLE001 - a reader's own defect: still a plain message
        raise ImageReadError(f"{path} cannot be used ({type(e).__name__}: {e}).") from None
    if kind != "image":
        return "file chosen"
    from PIL import Image

    try:
        with Image.open(path) as im:
            w, h = im.size
    except Exception:  # noqa: BLE001 - the filter's reader reads what PIL cannot: fine
        return "file chosen"
    note = f"{w} × {h} pixels"
    shape = getattr(data, "shape", None)
    if shape is not None and len(shape) in (2, 3) and tuple(shape[:2]) != (h, w):
        note += f", used as {shape[1]} × {shape[0]}"
        if len(shape) == 2 or shape[2] == 1:
            note += " grey"
    return note


def _check_file(kind: str, path: str) -> str:
    """Read the file as the filter will (raises a Stylize3DError); a short description."""
    from algorithms.paparazzi import ImageReadError, read_image

    if kind == "image":
        img = read_image(path)
        from PIL import Image

        with Image.open(path) as im:
            grey = im.mode in ("L", "LA", "I", "I;16", "F", "1")
        return (f"{img.shape[1]} × {img.shape[0]} pixels, {'grey' if grey else 'colour'}"
                f"{' (used as colour)' if grey else ''}; resized to the render resolution")
    if kind == "mesh":
        from algorithms.mesh import read_mesh

        data = read_mesh(path)
        return f"{len(data.V):,} vertices, {len(data.F):,} triangles"
    if not Path(path).is_file():
        raise ImageReadError(f"{path} is not a file.")
    return "file chosen"


register(Recipe("Paparazzi", "paparazzi", _paparazzi_params, paparazzi_steps,
                result=paparazzi_result, outcome=paparazzi_outcome, changes_faces=True,
                note="image filters (guided, quantize, slic, l0, neural-style, target image / "
                     "mesh, plug-ins) through renderings; remeshes as it goes; seed in params"))
