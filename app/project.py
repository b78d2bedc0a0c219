"""Project files (``.s3d``): the mesh with everything the user painted, placed and chose. Qt-free.

A project is one ZIP archive (read with :mod:`zipfile` and ``numpy.load(allow_pickle=False)``:
nothing in it is ever executed or unpickled) holding:

``project.json``
    ``{"format": "stylize3d-project", "version": 1, "app_version": "...",
    "source": "<the mesh file's name or null>",
    "mesh": {"V": "arrays/V.npy", "F": "arrays/F.npy"},
    "fields": {"<name>": "arrays/field_<k>.npy", ...},
    "selection": "arrays/selection.npy" | null,
    "handles": [[vertex, [x, y, z]], ...],
    "original": {"V": ..., "F": ...} | null,
    "panels": {"<panel title>": {"params": {...}, "options": {...}}, ...},
    "blobs": {"blob:<sha256>/<name>": "blobs/<sha256>/<name>", ...}}``
``arrays/*.npy``
    V (n, 3) float64, F (m, 3) int64, one (n,) float64 array per per-vertex field (λ scale,
    fixed, plane, frames, Gauss-map painting, fields of results, ...), the selection (n,) bool;
``blobs/<sha256>/<name>``
    the binary inputs the panels' options refer to (target images, style meshes), checked
    against their SHA-256 on reading.

``panels`` holds each panel's Params (``params``, the fields that the form shows) and its other
settings (``options``: the JSON-able dict the panel's recipe takes — chosen style, painted
capture sphere, plane axis, seed, ...), exactly what a Run of that panel would use; the command
line (``stylize3d cubic scene.s3d -o out.obj``) and :func:`app.recipes.run` take them from here.

Versions: ``version`` grows when the format changes incompatibly; a reader refuses a newer one
with a plain message (and reads every older one). Writing is atomic (a temporary file renamed
over the target), so a failed save never damages an existing project.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from algorithms.errors import Stylize3DError

FORMAT = "stylize3d-project"
VERSION = 1
SUFFIX = ".s3d"
#: the biggest project.json this reader accepts (bytes); arrays have their own limits
_MAX_JSON = 64 * 1024 * 1024


class ProjectError(Stylize3DError):
    """A project file cannot be read or written (damaged, from a newer version, ...)."""

    exit_code = 2


@dataclass
class Project:
    """A document with every panel's settings (see the module docstring).

    state : MeshState — the mesh now, with its fields, selection and handles.
    original : MeshState or None — the mesh as first opened (the app's ghost / Before view).
    panels : panel title -> {"params": dict, "options": dict}.
    source : the name of the mesh file the work started from, if any.
    """

    state: Any
    original: Any = None
    panels: dict = field(default_factory=dict)
    source: str | None = None

    def params_of(self, name: str) -> dict:
        return dict((self.panels.get(name) or {}).get("params") or {})

    def options_of(self, name: str) -> dict:
        return dict((self.panels.get(name) or {}).get("options") or {})


def is_project_path(path) -> bool:
    return Path(str(path)).suffix.lower() == SUFFIX


def _npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def project_bytes(project: Project) -> bytes:
    """The ``.s3d`` file's bytes for ``project`` (see :func:`save_project`)."""
    from app import __version__
    from app.recipes import blob_bytes, blob_refs

    st = project.state
    if st is None:
        raise ProjectError("There is no mesh to save in a project.")
    files: dict[str, bytes] = {"arrays/V.npy": _npy(np.asarray(st.V, np.float64)),
                               "arrays/F.npy": _npy(np.asarray(st.F, np.int64))}
    fields = {}
    for k, (name, values) in enumerate(sorted(st.fields.items())):
        rel = f"arrays/field_{k}.npy"
        files[rel] = _npy(np.asarray(values, np.float64))
        fields[name] = rel
    selection = None
    if st.selection is not None:
        selection = "arrays/selection.npy"
        files[selection] = _npy(np.asarray(st.selection, bool))
    original = None
    if project.original is not None and project.original is not st:
        original = {"V": "arrays/original_V.npy", "F": "arrays/original_F.npy"}
        files[original["V"]] = _npy(np.asarray(project.original.V, np.float64))
        files[original["F"]] = _npy(np.asarray(project.original.F, np.int64))
    panels = _jsonable(project.panels or {})
    blobs = {}
    for ref in sorted(set(blob_refs(panels))):
        digest, name = ref[len("blob:"):].split("/", 1)
        rel = f"blobs/{digest}/{name}"
        files[rel] = blob_bytes(ref)
        blobs[ref] = rel
    manifest = {"format": FORMAT, "version": VERSION, "app_version": __version__,
                "source": project.source,
                "mesh": {"V": "arrays/V.npy", "F": "arrays/F.npy"}, "fields": fields,
                "selection": selection,
                "handles": [[int(v), [float(x) for x in p]] for v, p in st.handles],
                "original": original, "panels": panels, "blobs": blobs}
    try:
        text = json.dumps(manifest, indent=1, allow_nan=False)
    except ValueError as e:
        raise ProjectError(f"A panel's settings cannot be saved in a project ({e}).") from None
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("project.json", text)
        for rel, data in files.items():
            z.writestr(rel, data)
    return buf.getvalue()


def save_project(path, project: Project, *, overwrite: bool = True) -> Path:
    """Write ``project`` to ``path`` (``.s3d`` added when missing) atomically. With
    ``overwrite=False`` an existing file is an error (nothing is written)."""
    from algorithms.mesh.io import atomic_write

    p = Path(path)
    if p.suffix.lower() != SUFFIX:
        p = p.with_name(p.name + SUFFIX)
    if p.exists() and not overwrite:
        raise ProjectError(f"'{p}' exists already; choose another name or allow replacing it.")
    data = project_bytes(project)
    try:
        atomic_write(p, lambda fh: fh.write(data))
    except Stylize3DError as e:
        raise ProjectError(str(e)) from None
    return p


def _damaged(name: str, what: str) -> ProjectError:
    return ProjectError(f"'{name}' is damaged: {what}. Open an earlier copy, or the mesh file "
                        "it was made from.")


def _load_array(z: zipfile.ZipFile, rel: Any, name: str) -> np.ndarray:
    if not isinstance(rel, str) or rel not in z.namelist():
        raise _damaged(name, f"the entry {rel!r} is missing")
    try:
        with z.open(rel) as fh:
            return np.load(io.BytesIO(fh.read()), allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise _damaged(name, f"the entry {rel!r} cannot be read ({e})") from None


def _mesh_state(z, V_rel, F_rel, name):
    from app.document import MeshState

    V = _load_array(z, V_rel, name)
    F = _load_array(z, F_rel, name)
    if V.ndim != 2 or V.shape[1:] != (3,) or not np.issubdtype(V.dtype, np.floating):
        raise _damaged(name, f"its vertices have shape {V.shape} ({V.dtype})")
    if F.ndim != 2 or F.shape[1:] != (3,) or not np.issubdtype(F.dtype, np.integer):
        raise _damaged(name, f"its triangles have shape {F.shape} ({F.dtype})")
    if len(V) == 0 or len(F) == 0:
        raise _damaged(name, "its mesh is empty")
    if F.min() < 0 or F.max() >= len(V):
        raise _damaged(name, "a triangle refers to a vertex that does not exist")
    if not np.isfinite(V).all():
        raise _damaged(name, "some vertex coordinates are not numbers (NaN or infinite)")
    return MeshState.make(V, F)


def read_project(path) -> Project:
    """Read a ``.s3d`` file; its blobs are added to the recipes' store. A damaged file, one
    that is not a project, or one from a newer version raises :class:`ProjectError`."""
    from app.recipes import add_blob

    p = Path(path)
    name = p.name
    if not p.is_file():
        raise ProjectError(f"There is no project file at '{p}'.")
    try:
        z = zipfile.ZipFile(p)
    except (zipfile.BadZipFile, OSError) as e:
        raise ProjectError(f"'{name}' is not a Stylize3D project file (or it is damaged: "
                           f"{e}).") from None
    with z:
        try:
            info = z.getinfo("project.json")
        except KeyError:
            raise ProjectError(f"'{name}' is not a Stylize3D project file (it has no "
                               "project.json).") from None
        if info.file_size > _MAX_JSON:
            raise _damaged(name, "its project.json is too big")
        try:
            manifest = json.loads(z.read(info).decode("utf-8"))
        except (ValueError, UnicodeDecodeError, zipfile.BadZipFile, OSError) as e:
            raise _damaged(name, f"its project.json cannot be read ({e})") from None
        if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
            raise ProjectError(f"'{name}' is not a Stylize3D project file.")
        version = manifest.get("version")
        if not isinstance(version, int) or version < 1:
            raise _damaged(name, f"its format version {version!r} is not valid")
        if version > VERSION:
            saved = manifest.get("app_version", "a newer version")
            raise ProjectError(
                f"'{name}' was saved by Stylize3D {saved} in project format {version}; this "
                f"version reads formats up to {VERSION}. Update Stylize3D to open it.")
        mesh = manifest.get("mesh") or {}
        state = _mesh_state(z, mesh.get("V"), mesh.get("F"), name)
        n = len(state.V)
        fields = manifest.get("fields") or {}
        if not isinstance(fields, dict):
            raise _damaged(name, "its list of painted fields is not valid")
        for fname, rel in fields.items():
            a = _load_array(z, rel, name)
            if a.shape != (n,) or not np.issubdtype(a.dtype, np.number):
                raise _damaged(name, f"the field {fname!r} has {a.shape} values for {n} "
                                     "vertices")
            state = state.with_field(str(fname), a.astype(np.float64))
        if manifest.get("selection"):
            sel = _load_array(z, manifest["selection"], name)
            if sel.shape != (n,):
                raise _damaged(name, "its selection does not fit the mesh")
            state = state.with_selection(sel.astype(bool))
        handles = manifest.get("handles") or []
        try:
            hd = {int(v): tuple(float(x) for x in pos) for v, pos in handles}
            if any(len(t) != 3 for t in hd.values()):
                raise ValueError("a handle needs three coordinates")
            state = state.with_handles(hd)
        except (TypeError, ValueError) as e:
            raise _damaged(name, f"its point handles are not valid ({e})") from None
        original = None
        if manifest.get("original"):
            o = manifest["original"]
            if not isinstance(o, dict):
                raise _damaged(name, "its original mesh entry is not valid")
            original = _mesh_state(z, o.get("V"), o.get("F"), name)
        panels = manifest.get("panels") or {}
        if not isinstance(panels, dict) or not all(
                isinstance(v, dict) and isinstance(v.get("params", {}), dict)
                and isinstance(v.get("options", {}), dict) for v in panels.values()):
            raise _damaged(name, "its panel settings are not valid")
        blobs = manifest.get("blobs") or {}
        if not isinstance(blobs, dict):
            raise _damaged(name, "its list of stored inputs is not valid")
        for ref, rel in blobs.items():
            if not isinstance(rel, str) or rel not in z.namelist():
                raise _damaged(name, f"the stored input {rel!r} is missing")
            try:
                add_blob(ref, z.read(rel))
            except Stylize3DError as e:
                raise _damaged(name, str(e)) from None
    source = manifest.get("source")
    return Project(state=state, original=original, panels=panels,
                   source=source if isinstance(source, str) else None)


def project_of_document(document, panels: dict | None = None) -> Project:
    """A Project of an open :class:`app.document.Document` and the panels' settings."""
    src = document.path.name if getattr(document, "path", None) else None
    return Project(state=document.state, original=document.original, panels=dict(panels or {}),
                   source=src)
