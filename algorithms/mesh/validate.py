"""Check a mesh for problems (:func:`validate_mesh`) and fix what can be fixed (:func:`clean_mesh`).

Every problem is a :class:`MeshIssue` with a stable ``code``, a severity, a message written for a
novice, a count, whether :func:`clean_mesh` can fix it, and the indices involved.

Issue codes (severity; whether :func:`clean_mesh` fixes it; what ``indices`` holds)
-----------------------------------------------------------------------------------
``bad_shape`` (error; no)
    ``V`` is not ``(n, 3)`` numbers or ``F`` not ``(m, 3)`` whole numbers. Nothing else is
    checked.
``empty`` (error; no)
    No vertices or no faces. Nothing else is checked.
``nonfinite`` (error; only if unused; vertices)
    NaN/inf coordinates. Fixable only when no face uses those vertices (they are then deleted
    as unreferenced).
``index_out_of_range`` (error; no; faces)
    Faces using indices ``< 0`` or ``>= n``. **Not fixable by default**, because deleting faces
    silently opens holes and a bad index usually means a damaged file;
    ``clean_mesh(..., remove_invalid_faces=True)`` deletes them (and faces on NaN vertices).
``repeated_index_in_face`` (warning; yes; faces)
    A face uses a vertex twice. Removed.
``degenerate_faces`` (warning; yes; faces)
    Zero-area faces: area ``<= DEGENERATE_AREA_RTOL * diagonal**2`` (``1e-14``). Removed.
``duplicate_faces`` (warning; yes; the later copies)
    Same three vertices as an earlier face, in any order. Removed.
``unreferenced_vertices`` (warning; yes; vertices)
    Vertices no face uses. Removed.
``duplicate_vertices`` (warning; yes; the later copies) -- or (info; no)
    Used vertices at exactly the same position as another used vertex. Merged ("welded").
    Copies whose merging would make the surface non-manifold (two parts touching at a point,
    or the halves of a vertex that Clean split) are kept apart; if only such copies exist the
    issue is an ``info`` and not fixable.
``nonmanifold_edges`` (error; yes; ``(k, 2)`` vertex pairs)
    Edges shared by more than two faces. Clean keeps, per edge, the lowest-index face running
    each direction (or the two lowest-index faces if all run the same way) and removes the
    others.
``nonmanifold_vertices`` (error; yes; vertices)
    Vertices whose faces form more than one fan. Each extra fan gets its own copy of the vertex.
``inconsistent_orientation`` (warning; yes; ``(k, 2)`` edges)
    Neighbouring faces disagree about the outside. Faces are flipped by a breadth-first search
    over each patch (its lowest-index face keeps its orientation).
``one_sided`` (warning; yes; ``(k, 2)`` edges)
    The same on a surface that cannot be oriented as it is (a Moebius strip, a Klein bottle, a
    model whose orientation flips along a seam). Clean cuts it open along the edges where the
    search's orientation still flips (the seam gets a boundary on each side, as mesh repair
    tools do), then orients it. Methods that do not need an orientation (cubic stylization
    cubifies a Klein bottle, thesis Fig. 5.12) run on it as it is: the commands do not refuse
    a mesh for this alone (``MeshReport.blocking``).
``inward_orientation`` (warning; yes; faces of those parts)
    Closed, consistently oriented parts with negative signed volume (inside-out). Flipped.
``multiple_components`` (info), ``boundary`` (info), ``genus`` (info)
    Number of parts, of boundary loops, of handles (genus only for manifold, orientable
    meshes); the number is in ``count``.
``file_note`` (info)
    Remarks from reading the file (the ``notes`` argument).

Topology checks run on the faces that have valid indices and three distinct vertices.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np
from .components import connected_components as _cc

from ..errors import InvalidMeshError, ParameterError
from .topology import (
    _corner_fans,
    _inconsistent_edges,
    _EdgeData,
    _genus_from,
    _orientation_data,
    _relabel_by_first_appearance,
)

__all__ = ["MeshIssue", "MeshReport", "CleanResult", "validate_mesh", "clean_mesh"]

#: Faces whose area is at most this fraction of the squared bounding-box diagonal are degenerate.
DEGENERATE_AREA_RTOL = 1e-14

_SEVERITIES = ("error", "warning", "info")


@dataclass
class MeshIssue:
    """One problem (or remark) found by :func:`validate_mesh`.

    Attributes
    ----------
    code : str
        Stable identifier, see the module docstring.
    severity : {'error', 'warning', 'info'}
        ``error``: methods cannot run; ``warning``: results may be wrong; ``info``: remark.
    message : str
        Plain-language explanation with what to do.
    count : int
        How many things are affected (faces, vertices, edges, parts, loops...).
    fixable : bool
        Whether :func:`clean_mesh` fixes it.
    indices : numpy.ndarray or None
        The vertices / faces involved (``(k,)``), or vertex pairs for edge issues (``(k, 2)``).
    """

    code: str
    severity: str
    message: str
    count: int = 0
    fixable: bool = False
    indices: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.severity not in _SEVERITIES:
            raise ValueError(f"severity must be one of {_SEVERITIES}, not {self.severity!r}")

    def to_dict(self, max_indices: int = 20) -> dict[str, Any]:
        """JSON-safe dict; ``indices`` truncated to the first ``max_indices`` entries (rows)."""
        idx = None
        truncated = False
        if self.indices is not None:
            arr = np.asarray(self.indices)
            truncated = bool(arr.shape[0] > max_indices)
            idx = arr[:max_indices].tolist()
        return {
            "code": str(self.code),
            "severity": str(self.severity),
            "message": str(self.message),
            "count": int(self.count),
            "fixable": bool(self.fixable),
            "indices": idx,
            "indices_truncated": truncated,
        }


#: Short names of the problems, for one-line advice (status bar, CLI hints).
_SHORT_NAMES = {
    "bad_shape": "unreadable coordinates or triangles",
    "empty": "no triangles",
    "nonfinite": "NaN/infinite coordinates",
    "index_out_of_range": "triangles using missing vertices",
    "repeated_index_in_face": "triangles using a vertex twice",
    "degenerate_faces": "zero-area triangles",
    "duplicate_faces": "duplicate triangles",
    "unreferenced_vertices": "unused vertices",
    "duplicate_vertices": "duplicate vertices",
    "nonmanifold_edges": "edges shared by 3+ triangles",
    "nonmanifold_vertices": "non-manifold vertices",
    "inconsistent_orientation": "inconsistent orientation",
    "one_sided": "one-sided surface (cut open)",
    "inward_orientation": "inside-out parts",
}

#: What a user can do about a problem Clean cannot fix.
_REMEDIES = {
    "bad_shape": "the file is damaged: export the model again",
    "empty": "open a file that has triangles",
    "nonfinite": "the file's coordinates are damaged: export the model again",
    "index_out_of_range": ("the file is damaged: export the model again (or 'stylize3d clean' "
                           "with --remove-invalid-faces deletes those triangles)"),
}


@dataclass
class MeshReport:
    """Result of :func:`validate_mesh`: a list of issues and a dict of statistics.

    ``stats`` keys: ``vertices``, ``faces``, ``edges``, ``components``, ``boundary_loops``,
    ``boundary_edges``, ``genus`` (None unless manifold and orientable), ``euler``, ``manifold``,
    ``orientable``, ``closed``, ``bbox_min``, ``bbox_max``, ``diagonal``, ``total_area``.
    Values are plain Python types (or None when they cannot be computed).
    """

    issues: list[MeshIssue] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def errors(self) -> list[MeshIssue]:
        """Issues with severity ``'error'``."""
        return [i for i in self.issues if i.severity == "error"]

    @property
    def warnings(self) -> list[MeshIssue]:
        """Issues with severity ``'warning'``."""
        return [i for i in self.issues if i.severity == "warning"]

    @property
    def infos(self) -> list[MeshIssue]:
        """Issues with severity ``'info'``."""
        return [i for i in self.issues if i.severity == "info"]

    @property
    def ok(self) -> bool:
        """True when there are no errors (warnings and infos allowed)."""
        return not self.errors

    @property
    def needs_cleaning(self) -> bool:
        """True when some error or warning can be fixed by :func:`clean_mesh`."""
        return any(i.fixable and i.severity in ("error", "warning") for i in self.issues)

    @property
    def blocking(self) -> bool:
        """True when a method must not run on the mesh as it is: an error, or a fixable warning
        other than a one-sided surface (which the methods that need an orientation refuse
        themselves, pointing to Clean; cubic stylization runs on it)."""
        return bool(self.errors) or any(
            i.fixable and i.severity == "warning" and i.code != "one_sided"
            for i in self.issues)

    @property
    def advice(self) -> str:
        """One line saying what to do about the errors and warnings ("" when there are none).

        It names 'Clean' only for what :func:`clean_mesh` fixes; for the rest it says what the
        user can do instead, so the two never disagree.
        """
        problems = self.errors + self.warnings
        if not problems:
            return ""
        fixable = [i for i in problems if i.fixable]
        stuck = [i for i in problems if not i.fixable]
        parts = []
        if fixable:
            what = ", ".join(_SHORT_NAMES.get(i.code, i.code) for i in fixable)
            parts.append(f"Use 'Clean' to fix: {what}")
        if stuck:
            what = ", ".join(_SHORT_NAMES.get(i.code, i.code) for i in stuck)
            remedies = []
            for i in stuck:
                r = _REMEDIES.get(i.code, "re-export the model from the program that made it")
                if r not in remedies:
                    remedies.append(r)
            parts.append(f"'Clean' cannot fix: {what}; " + "; ".join(remedies))
        return ". ".join(parts) + "."

    @property
    def codes(self) -> list[str]:
        """Codes of all issues, in report order."""
        return [i.code for i in self.issues]

    def get(self, code: str) -> MeshIssue | None:
        """The first issue with this code, or None."""
        return next((i for i in self.issues if i.code == code), None)

    def __contains__(self, code: object) -> bool:
        return any(i.code == code for i in self.issues)

    def summary(self) -> str:
        """Multi-line plain-English summary."""
        s = self.stats
        lines = []
        if s.get("vertices") is not None and s.get("faces") is not None:
            head = f"Mesh: {s['vertices']:,} vertices, {s['faces']:,} triangles"
            if s.get("edges") is not None:
                head += f", {s['edges']:,} edges"
            lines.append(head + ".")
            parts = []
            if s.get("components") is not None:
                c = s["components"]
                parts.append(f"{c} part{'s' if c != 1 else ''}")
            if s.get("closed"):
                parts.append("closed")
            elif s.get("boundary_loops"):
                b = s["boundary_loops"]
                parts.append(
                    f"{b} boundary loop{'s' if b != 1 else ''} ({s['boundary_edges']:,} edges)"
                )
            if s.get("genus") is not None:
                parts.append(f"genus {s['genus']}")
            if parts:
                lines.append("Shape: " + ", ".join(parts) + ".")
        for title, group in (
            ("Errors", self.errors),
            ("Warnings", self.warnings),
            ("Notes", self.infos),
        ):
            if group:
                lines.append(f"{title}:")
                lines.extend(f"  - {i.message}" for i in group)
        if not self.errors and not self.warnings:
            lines.append("No problems found.")
        else:
            lines.append(self.advice)
            if self.errors and not self.needs_cleaning:
                lines.append("The errors above must be fixed before the mesh can be processed.")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation (no NumPy types; indices truncated to 20)."""
        return {
            "ok": bool(self.ok),
            "needs_cleaning": bool(self.needs_cleaning),
            "stats": {k: _jsonable(v) for k, v in self.stats.items()},
            "issues": [i.to_dict() for i in self.issues],
        }


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    return v


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def _n(count: int, singular: str, plural: str | None = None) -> str:
    return f"{count:,} {singular if count == 1 else (plural or singular + 's')}"


def _verb(count: int, singular: str, plural: str) -> str:
    return singular if count == 1 else plural


def _examples(idx: np.ndarray, what: str, k: int = 3) -> str:
    idx = np.asarray(idx)
    if idx.size == 0:
        return ""
    shown = ", ".join(str(int(i)) for i in idx[:k])
    more = ", ..." if idx.size > k else ""
    return f" ({what} {shown}{more})"


def _empty_stats(n: int | None, m: int | None) -> dict[str, Any]:
    return {
        "vertices": n,
        "faces": m,
        "edges": None,
        "components": None,
        "boundary_loops": None,
        "boundary_edges": None,
        "genus": None,
        "euler": None,
        "manifold": False,
        "orientable": None,
        "closed": False,
        "bbox_min": None,
        "bbox_max": None,
        "diagonal": None,
        "total_area": None,
    }


def _triangle_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    a = V[F[:, 0]]
    with np.errstate(invalid="ignore", over="ignore"):
        return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - a, V[F[:, 2]] - a), axis=1)


def _degenerate_mask(V: np.ndarray, F: np.ndarray, diag: float) -> np.ndarray:
    """Zero-area faces (finite coordinates only) among faces with valid, distinct indices."""
    A = _triangle_areas(V, F)
    return np.isfinite(A) & (A <= DEGENERATE_AREA_RTOL * diag * diag)


def _duplicate_face_mask(F: np.ndarray) -> np.ndarray:
    """True for faces whose vertex set equals that of an earlier face."""
    if F.shape[0] < 2:
        return np.zeros(F.shape[0], dtype=bool)
    S = np.sort(F, axis=1)
    order = np.lexsort((np.arange(F.shape[0]), S[:, 2], S[:, 1], S[:, 0]))
    Ss = S[order]
    same = np.all(Ss[1:] == Ss[:-1], axis=1)
    dup = np.zeros(F.shape[0], dtype=bool)
    dup[order[1:][same]] = True
    return dup


def _repeated_mask(F: np.ndarray) -> np.ndarray:
    return (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])


def _coincident_representatives(V: np.ndarray, candidates: np.ndarray, tol: float) -> np.ndarray:
    """rep[v] = smallest-index candidate vertex at the same position (within tol) as v."""
    n = V.shape[0]
    rep = np.arange(n)
    idx = np.flatnonzero(candidates)
    if idx.size < 2:
        return rep
    if tol <= 0:
        P = np.ascontiguousarray(V[idx], dtype=np.float64) + 0.0  # -0.0 == 0.0
        key = P.view(np.dtype((np.void, 24))).ravel()
        _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
        rep[idx] = idx[first[inverse.ravel()]]
        return rep
    from scipy.spatial import cKDTree

    pairs = cKDTree(V[idx]).query_pairs(float(tol), output_type="ndarray")
    if pairs.size == 0:
        return rep
    k = idx.size
    _, lab = _cc(k, pairs[:, 0], pairs[:, 1])
    first = np.full(lab.max() + 1, k, dtype=np.int64)
    first[lab[::-1]] = np.arange(k)[::-1]
    rep[idx] = idx[first[lab]]
    return rep


def _bad_vertices_after(F: np.ndarray, n: int) -> np.ndarray:
    """Boolean (n,) mask: vertices on a non-manifold edge or with several fans in F, and, on an
    edge-manifold F that is one-sided, the vertices of the seam where its orientation flips
    (merging the two sides of a seam Clean cut open would make the surface one-sided again)."""
    bad = np.zeros(n, dtype=bool)
    if F.shape[0] == 0:
        return bad
    d = _EdgeData(F)
    bad[d.E[d.counts > 2].ravel()] = True
    _, fans = _corner_fans(d, n)
    bad[:fans.size] |= fans > 1
    if not bad.any():
        flip, _, orientable = _orientation_data(d)
        if not orientable:
            bad[d.E[_inconsistent_edges(d, flip)].ravel()] = True
    return bad


def _safe_weld(F: np.ndarray, rep: np.ndarray) -> tuple[np.ndarray, int]:
    """Undo merges that would make the surface non-manifold.

    Returns (rep restricted to safe merges, number of vertices kept apart).
    """
    n = rep.size
    rep = rep.copy()
    original = rep != np.arange(n)
    # Each round undoes at least one merge, so this terminates; it usually takes 1-2 rounds.
    while True:
        merged = rep != np.arange(n)
        if not merged.any():
            break
        Fw = rep[F]
        Fw = Fw[~_repeated_mask(Fw)]
        Fw = Fw[~_duplicate_face_mask(Fw)]
        bad = _bad_vertices_after(Fw, n)
        targets = np.zeros(n, dtype=bool)
        targets[rep[merged]] = True
        unsafe_targets = targets & bad
        if not unsafe_targets.any():
            break
        rep[unsafe_targets[rep]] = np.flatnonzero(unsafe_targets[rep])
    kept_apart = int((original & (rep == np.arange(n))).sum())
    return rep, kept_apart


# --------------------------------------------------------------------------------------------
# validate_mesh
# --------------------------------------------------------------------------------------------


def _coerce(V, F) -> tuple[np.ndarray | None, np.ndarray | None, list[MeshIssue]]:
    issues: list[MeshIssue] = []
    try:
        Va = np.asarray(V, dtype=np.float64)
    except (TypeError, ValueError):
        Va = None
        issues.append(
            MeshIssue("bad_shape", "error", "The vertex positions are not numbers.", fixable=False)
        )
    if Va is not None and (Va.ndim != 2 or Va.shape[1] != 3):
        if not (Va.size == 0):
            issues.append(
                MeshIssue(
                    "bad_shape",
                    "error",
                    "Vertex positions must be a table with three coordinates (x, y, z) per row; "
                    f"got an array of shape {Va.shape}.",
                )
            )
            Va = None
        else:
            Va = Va.reshape(0, 3)
    try:
        Fa = np.asarray(F)
        if Fa.dtype.kind == "f":
            with np.errstate(invalid="ignore"):
                if not np.all(Fa == np.round(Fa)):
                    raise ValueError
        if Fa.dtype.kind not in "iuf":
            raise ValueError
        Fa = Fa.astype(np.int64)
    except (TypeError, ValueError, OverflowError):
        Fa = None
        issues.append(
            MeshIssue(
                "bad_shape",
                "error",
                "The faces must be whole-number vertex indices (three per triangle).",
            )
        )
    if Fa is not None and (Fa.ndim != 2 or Fa.shape[1] != 3):
        if Fa.size == 0:
            Fa = Fa.reshape(0, 3)
        else:
            extra = (
                " Only triangles are supported; split polygons into triangles first."
                if Fa.ndim == 2 and Fa.shape[1] > 3
                else ""
            )
            issues.append(
                MeshIssue(
                    "bad_shape",
                    "error",
                    "Faces must be a table with three vertex indices per row (triangles); got an "
                    f"array of shape {Fa.shape}.{extra}",
                )
            )
            Fa = None
    return Va, Fa, issues


def validate_mesh(V, F, notes: Iterable[str] = ()) -> MeshReport:
    """Check a mesh and report every problem in plain language.

    Parameters
    ----------
    V : (n, 3) float array
        Vertex positions (NaN/inf allowed: they are reported).
    F : (m, 3) int array
        Triangle corner indices (out-of-range allowed: they are reported).
    notes : iterable of str
        Remarks from reading the file (:attr:`MeshData.notes`); added as ``file_note`` infos.

    Returns
    -------
    MeshReport
        ``issues`` (see the module docstring for the codes) and ``stats``. Never raises for bad
        mesh content.
    """
    Va, Fa, shape_issues = _coerce(V, F)
    note_issues = [MeshIssue("file_note", "info", str(t)) for t in notes]
    if shape_issues:
        n = None if Va is None else int(Va.shape[0])
        m = None if Fa is None else int(Fa.shape[0])
        return _report(shape_issues + note_issues, _empty_stats(n, m))
    assert Va is not None and Fa is not None
    V, F = Va, Fa
    n, m = V.shape[0], F.shape[0]
    stats = _empty_stats(n, m)
    issues: list[MeshIssue] = []
    if n == 0 or m == 0:
        what = "no vertices" if n == 0 else "no triangles"
        if n == 0 and m == 0:
            what = "no vertices and no triangles"
        issues.append(
            MeshIssue(
                "empty",
                "error",
                f"The mesh is empty: it has {what}. Open or create a surface mesh first.",
            )
        )
        return _report(issues + note_issues, stats)

    # ---- indices out of range
    in_range = np.all((F >= 0) & (F < n), axis=1)
    bad_faces = np.flatnonzero(~in_range)
    if bad_faces.size:
        badvals = F[bad_faces][(F[bad_faces] < 0) | (F[bad_faces] >= n)]
        example = int(badvals[0])
        issues.append(
            MeshIssue(
                "index_out_of_range",
                "error",
                f"{_n(bad_faces.size, 'triangle')} {_verb(bad_faces.size, 'refers', 'refer')} to "
                f"vertices that do not exist (the mesh has {n:,} vertices, numbered 0 to "
                f"{n - 1:,}; triangle {int(bad_faces[0])} uses {example}). The file is probably "
                "damaged: export it again. Clean can delete these triangles only if asked "
                "to ('remove invalid faces'), because that leaves holes.",
                count=int(bad_faces.size),
                fixable=False,
                indices=bad_faces,
            )
        )
    Fv = F[in_range]
    fv_idx = np.flatnonzero(in_range)

    referenced = np.zeros(n, dtype=bool)
    referenced[Fv.ravel()] = True

    # ---- non-finite coordinates
    finite = np.isfinite(V).all(axis=1)
    nonfinite = np.flatnonzero(~finite)
    if nonfinite.size:
        used = nonfinite[referenced[nonfinite]]
        k = nonfinite.size
        if used.size:
            msg = (
                f"{_n(k, 'vertex', 'vertices')} {_verb(k, 'has', 'have')} invalid coordinates "
                f"(NaN or infinity){_examples(nonfinite, 'vertex' if k == 1 else 'vertices')}, "
                f"and {_n(used.size, 'of them is', 'of them are') if k > 1 else 'it is'} used by "
                "triangles, so the mesh cannot be shown or processed. Fix the file or export it "
                "again (Clean can delete the triangles that use them only if asked to: 'remove "
                "invalid faces')."
            )
        else:
            msg = (
                f"{_n(k, 'vertex', 'vertices')} {_verb(k, 'has', 'have')} invalid coordinates "
                f"(NaN or infinity){_examples(nonfinite, 'vertex' if k == 1 else 'vertices')}. "
                f"No triangle uses {_verb(k, 'it', 'them')}, so 'Clean' can simply delete "
                f"{_verb(k, 'it', 'them')}."
            )
        issues.append(
            MeshIssue("nonfinite", "error", msg, count=k, fixable=not used.size, indices=nonfinite)
        )

    # ---- bounding box, area
    Vref = V[referenced & finite]
    if Vref.shape[0] == 0:
        Vref = V[finite]
    if Vref.shape[0]:
        lo, hi = Vref.min(axis=0), Vref.max(axis=0)
        diag = float(np.linalg.norm(hi - lo))
        stats["bbox_min"] = [float(x) for x in lo]
        stats["bbox_max"] = [float(x) for x in hi]
        stats["diagonal"] = diag
    else:
        diag = 0.0

    # ---- repeated index within a face
    rep_mask = _repeated_mask(Fv)
    if rep_mask.any():
        k = int(rep_mask.sum())
        issues.append(
            MeshIssue(
                "repeated_index_in_face",
                "warning",
                f"{_n(k, 'triangle')} {_verb(k, 'uses', 'use')} the same vertex twice, so "
                f"{_verb(k, 'it has', 'they have')} no area"
                f"{_examples(fv_idx[rep_mask], 'triangle' if k == 1 else 'triangles')}. "
                f"'Clean' can remove {_verb(k, 'it', 'them')}.",
                count=k,
                fixable=True,
                indices=fv_idx[rep_mask],
            )
        )
    Ft = Fv[~rep_mask]
    ft_idx = fv_idx[~rep_mask]
    areas = _triangle_areas(V, Ft)
    fin_area = np.isfinite(areas)
    stats["total_area"] = float(areas[fin_area].sum())

    # ---- degenerate faces
    deg = fin_area & (areas <= DEGENERATE_AREA_RTOL * diag * diag)
    if deg.any():
        k = int(deg.sum())
        issues.append(
            MeshIssue(
                "degenerate_faces",
                "warning",
                f"{_n(k, 'triangle')} {_verb(k, 'has', 'have')} zero area (the corners lie on "
                f"one line){_examples(ft_idx[deg], 'triangle' if k == 1 else 'triangles')}. "
                "They break normals and the Laplacian. 'Clean' can remove "
                f"{_verb(k, 'it', 'them')}.",
                count=k,
                fixable=True,
                indices=ft_idx[deg],
            )
        )

    # ---- duplicate faces
    dupf = _duplicate_face_mask(Ft)
    if dupf.any():
        k = int(dupf.sum())
        issues.append(
            MeshIssue(
                "duplicate_faces",
                "warning",
                f"{_n(k, 'triangle')} {_verb(k, 'is an exact copy', 'are exact copies')} of "
                "another triangle (the same three corners)"
                f"{_examples(ft_idx[dupf], 'triangle' if k == 1 else 'triangles')}. 'Clean' can "
                f"remove the {_verb(k, 'copy', 'copies')}.",
                count=k,
                fixable=True,
                indices=ft_idx[dupf],
            )
        )

    # ---- unreferenced vertices
    unref = np.flatnonzero(~referenced)
    if unref.size:
        k = unref.size
        issues.append(
            MeshIssue(
                "unreferenced_vertices",
                "warning",
                f"{_n(k, 'vertex', 'vertices')} {_verb(k, 'is', 'are')} not used by any triangle "
                "(loose points). They do not show, but some methods need every vertex on the "
                f"surface. 'Clean' can remove {_verb(k, 'it', 'them')}.",
                count=int(k),
                fixable=True,
                indices=unref,
            )
        )

    # ---- duplicate (coincident) vertices
    rep = _coincident_representatives(V, referenced & finite, 0.0)
    dup_v = rep != np.arange(n)
    if dup_v.any():
        safe_rep, kept_apart = _safe_weld(Ft, rep)
        n_safe = int((safe_rep != np.arange(n)).sum())
        dup_idx = np.flatnonzero(dup_v)
        if n_safe:
            extra = (
                f" ({_n(kept_apart, 'other copy', 'other copies')} will stay separate because "
                "merging them would make the surface non-manifold.)"
                if kept_apart
                else ""
            )
            issues.append(
                MeshIssue(
                    "duplicate_vertices",
                    "warning",
                    f"{_n(n_safe, 'vertex', 'vertices')} {_verb(n_safe, 'sits', 'sit')} at exactly "
                    "the same position as another vertex, so the surface is cut into separate "
                    "pieces there (common in STL files and at texture seams). 'Clean' can merge "
                    f"{_verb(n_safe, 'it', 'them')}.{extra}",
                    count=n_safe,
                    fixable=True,
                    indices=np.flatnonzero(safe_rep != np.arange(n)),
                )
            )
        else:
            issues.append(
                MeshIssue(
                    "duplicate_vertices",
                    "info",
                    f"{_n(kept_apart, 'vertex', 'vertices')} {_verb(kept_apart, 'sits', 'sit')} at "
                    "the same position as another vertex but "
                    f"{_verb(kept_apart, 'is', 'are')} kept separate, because merging would make "
                    "the surface non-manifold (for example two parts touching at one point) "
                    "or one-sided (the two sides of a seam Clean cut open).",
                    count=kept_apart,
                    fixable=False,
                    indices=dup_idx,
                )
            )

    # ---- topology on valid faces
    if Ft.shape[0] == 0:
        return _report(issues + note_issues, stats)
    d = _EdgeData(Ft)
    stats["edges"] = int(d.E.shape[0])
    nref = int(np.count_nonzero(np.bincount(Ft.ravel(), minlength=n)))
    stats["euler"] = int(nref - d.E.shape[0] + Ft.shape[0])

    nm_edges = d.counts > 2
    if nm_edges.any():
        k = int(nm_edges.sum())
        issues.append(
            MeshIssue(
                "nonmanifold_edges",
                "error",
                f"{_n(k, 'edge')} {_verb(k, 'is', 'are')} shared by more than two triangles "
                "(non-manifold). Methods need every edge to touch one or two triangles. 'Clean' "
                "can remove the extra triangles.",
                count=k,
                fixable=True,
                indices=d.E[nm_edges],
            )
        )
    _, fans = _corner_fans(d, n)
    nm_vertices = np.flatnonzero(fans > 1)
    if nm_vertices.size:
        k = nm_vertices.size
        issues.append(
            MeshIssue(
                "nonmanifold_vertices",
                "error",
                f"{_n(k, 'vertex', 'vertices')} {_verb(k, 'joins', 'join')} pieces of surface that "
                "touch only at that point (non-manifold, like two cones tip to tip)"
                f"{_examples(nm_vertices, 'vertex' if k == 1 else 'vertices')}. 'Clean' can give "
                "each piece its own copy of the vertex.",
                count=int(k),
                fixable=True,
                indices=nm_vertices,
            )
        )
    edge_manifold = not nm_edges.any()
    manifold = edge_manifold and not nm_vertices.size
    stats["manifold"] = bool(manifold)

    # orientation: interior edges whose two half-edges run the same way
    hs = d.order
    same_edge = d.EMAP[hs[1:]] == d.EMAP[hs[:-1]]
    pair_e = d.EMAP[hs[:-1]][same_edge]
    two = d.counts[pair_e] == 2
    same_dir = d.fwd[hs[:-1][same_edge]] == d.fwd[hs[1:][same_edge]]
    bad_orient_edges = pair_e[two & same_dir]
    if bad_orient_edges.size or not edge_manifold:
        _, patch, orientable = _orientation_data(d)
    else:
        patch, orientable = None, True  # consistently oriented, hence orientable
    if not edge_manifold:
        orientable_known = None
    else:
        orientable_known = orientable
    stats["orientable"] = orientable_known
    if bad_orient_edges.size:
        k = int(bad_orient_edges.size)
        if orientable_known is False:
            msg = (
                f"Neighbouring triangles disagree about which side is outside along "
                f"{_n(k, 'edge')}, and the surface is one-sided (like a Moebius strip). 'Clean' "
                "can cut it open along a seam where the orientation flips, so that it has two "
                "sides (the seam becomes a boundary)."
            )
            fixable = True
        else:
            msg = (
                f"Neighbouring triangles disagree about which side is outside along "
                f"{_n(k, 'edge')} (some normals point inwards, shading looks patchy). 'Clean' can "
                "re-orient the triangles consistently."
            )
            fixable = True
        issues.append(
            MeshIssue(
                "one_sided" if orientable_known is False else "inconsistent_orientation",
                "warning",
                msg,
                count=k,
                fixable=fixable,
                indices=d.E[bad_orient_edges],
            )
        )

    # components (faces sharing vertices)
    C, flab = _face_components(Ft, n)
    stats["components"] = int(C)
    if patch is None:
        patch = flab  # manifold and consistently oriented: edge patches == components

    # boundary
    bmask = d.counts == 1
    n_bedges = int(bmask.sum())
    stats["boundary_edges"] = n_bedges
    if n_bedges:
        BE = d.E[bmask]
        _, blab = _cc(n, BE[:, 0], BE[:, 1])
        n_loops = int(np.count_nonzero(np.bincount(blab[BE[:, 0]])))
    else:
        n_loops = 0
    stats["boundary_loops"] = n_loops
    stats["closed"] = bool(manifold and n_bedges == 0)

    # inward-facing closed parts (only meaningful once consistently oriented)
    if manifold and not bad_orient_edges.size:
        P = int(patch.max()) + 1 if patch.size else 0
        face_boundary = np.zeros(Ft.shape[0], dtype=bool)
        bh = np.flatnonzero(bmask[d.EMAP])
        face_boundary[bh % d.m] = True
        open_patch = np.bincount(patch, weights=face_boundary, minlength=P) > 0
        a, b, c = V[Ft[:, 0]], V[Ft[:, 1]], V[Ft[:, 2]]
        with np.errstate(invalid="ignore", over="ignore"):
            vol_f = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
        vol = np.bincount(patch, weights=np.where(np.isfinite(vol_f), vol_f, 0.0), minlength=P)
        has_nan = np.bincount(patch, weights=~np.isfinite(vol_f), minlength=P) > 0
        inward = (~open_patch) & (~has_nan) & (vol < -1e-12 * max(diag, 1e-300) ** 3)
        if inward.any():
            k = int(inward.sum())
            faces_in = ft_idx[inward[patch]]
            whole = k == P
            what = (
                "The mesh is inside-out: its triangles face inwards"
                if whole
                else f"{_n(k, 'closed part')} of the mesh {_verb(k, 'is', 'are')} inside-out "
                "(triangles facing inwards)"
            )
            issues.append(
                MeshIssue(
                    "inward_orientation",
                    "warning",
                    f"{what}, so lighting looks wrong and volumes are negative. 'Clean' can flip "
                    f"{_verb(k, 'it', 'them')}. (If a part is meant to be a hollow cavity inside "
                    "another part, ignore this.)",
                    count=k,
                    fixable=True,
                    indices=faces_in,
                )
            )

    if C > 1:
        issues.append(
            MeshIssue(
                "multiple_components",
                "info",
                f"The mesh consists of {C:,} separate parts (connected components). Methods "
                "process all parts together.",
                count=int(C),
            )
        )
    if n_loops:
        issues.append(
            MeshIssue(
                "boundary",
                "info",
                f"The surface is open: it has {_n(n_loops, 'hole or border', 'holes or borders')} "
                f"(boundary {_verb(n_loops, 'loop', 'loops')}) made of {_n(n_bedges, 'edge')}.",
                count=n_loops,
            )
        )
    if manifold and orientable:
        g = _genus_from(d, n, C, flab)
        stats["genus"] = int(g)
        if g == 0:
            desc = "no handles, like a sphere or a disc"
        elif g == 1:
            desc = "one handle, like a doughnut"
        else:
            desc = f"{g} handles, like a pretzel"
        issues.append(MeshIssue("genus", "info", f"The surface has genus {g} ({desc}).", count=g))
    return _report(issues + note_issues, stats)


def _report(issues: list[MeshIssue], stats: dict[str, Any]) -> MeshReport:
    """Build the report with issues ordered errors, warnings, infos (stable within each)."""
    rank = {s: k for k, s in enumerate(_SEVERITIES)}
    return MeshReport(sorted(issues, key=lambda i: rank[i.severity]), stats)


def _face_components(F: np.ndarray, n: int) -> tuple[int, np.ndarray]:
    rows = np.concatenate([F[:, 0], F[:, 1]])
    cols = np.concatenate([F[:, 1], F[:, 2]])
    _, vlab = _cc(n, rows, cols)
    return _relabel_by_first_appearance(vlab[F[:, 0]].astype(np.int64))


# --------------------------------------------------------------------------------------------
# clean_mesh
# --------------------------------------------------------------------------------------------


@dataclass
class CleanResult:
    """Result of :func:`clean_mesh`.

    Attributes
    ----------
    V : (n', 3) float64 array
        Cleaned vertex positions.
    F : (m', 3) int64 array
        Cleaned triangles.
    actions : list of str
        What was done, one sentence per step (never empty).
    vertex_map : (n,) int64 array
        For each input vertex, its index in the output ``V`` (``-1`` if it was deleted). Merged
        vertices map to the same output vertex; a split vertex maps to the copy kept by its
        first fan.
    face_map : (m',) int64 array
        For each output face, the index of the input face it came from.
    """

    V: np.ndarray
    F: np.ndarray
    actions: list[str]
    vertex_map: np.ndarray
    face_map: np.ndarray


class _State:
    def __init__(self, V: np.ndarray, F: np.ndarray):
        self.V = V
        self.F = F
        self.vmap = np.arange(V.shape[0])
        self.fmap = np.arange(F.shape[0])
        self.actions: list[str] = []

    def keep_faces(self, keep: np.ndarray) -> None:
        self.F = self.F[keep]
        self.fmap = self.fmap[keep]

    def remap_vertices(self, new_index: np.ndarray, V_new: np.ndarray) -> None:
        """new_index[v_old_current] -> index in V_new (or -1)."""
        valid = self.vmap >= 0
        out = np.full_like(self.vmap, -1)
        out[valid] = new_index[self.vmap[valid]]
        self.vmap = out
        self.F = new_index[self.F]
        self.V = V_new


def clean_mesh(
    V,
    F,
    *,
    weld_tolerance: float = 0.0,
    remove_invalid_faces: bool = False,
    orient_outward: bool = True,
) -> CleanResult:
    """Fix every problem :func:`validate_mesh` marks as fixable, and say what was done.

    Steps, in order (each adds a sentence to ``actions`` when it changes something):

    1. (only with ``remove_invalid_faces``) delete faces with out-of-range indices or corners
       with NaN/inf coordinates;
    2. merge coincident vertices (exactly equal, or within ``weld_tolerance``), except copies
       whose merging would make the surface non-manifold;
    3. delete faces that use a vertex twice;
    4. delete zero-area faces;
    5. delete duplicate faces (same three vertices);
    6. delete extra faces on edges shared by more than two faces;
    7. split non-manifold vertices (one copy per fan);
    8. orient faces consistently (breadth-first over each patch); with ``orient_outward``,
       flip closed parts whose signed volume is negative;
    9. delete unreferenced vertices (including unused NaN/inf ones).

    The mesh is validated first (a clean mesh is returned unchanged at the cost of one
    :func:`validate_mesh`) and again after each pass; if a later step created a fixable problem
    (rare), the steps run again (at most three passes).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    weld_tolerance : float
        Merge vertices closer than this distance (0 = only identical positions).
    remove_invalid_faces : bool
        Also delete faces with out-of-range indices or non-finite corners (leaves holes).
    orient_outward : bool
        Flip inside-out closed parts.

    Returns
    -------
    CleanResult
        ``V``, ``F``, ``actions`` (``["Nothing to fix: the mesh is clean."]`` when there was
        nothing to do; problems that cannot be fixed are listed as ``"Not fixed: ..."``, after
        ``"Nothing could be fixed automatically."`` if nothing else was done),
        ``vertex_map`` and ``face_map``.

    Raises
    ------
    InvalidMeshError
        If the arrays have the wrong shape, the mesh is empty, or faces use out-of-range indices
        and ``remove_invalid_faces`` is False.
    """
    Va, Fa, shape_issues = _coerce(V, F)
    if shape_issues:
        raise InvalidMeshError("The mesh cannot be cleaned: " + shape_issues[0].message)
    assert Va is not None and Fa is not None
    if Va.shape[0] == 0 or Fa.shape[0] == 0:
        raise InvalidMeshError("The mesh is empty: there is nothing to clean.")
    try:
        weld_tolerance = float(weld_tolerance)
    except (TypeError, ValueError):
        weld_tolerance = float("nan")
    if not (weld_tolerance >= 0 and np.isfinite(weld_tolerance)):
        raise ParameterError(
            f"The weld tolerance must be zero or a positive distance, not {weld_tolerance}."
        )
    n = Va.shape[0]
    in_range = np.all((Fa >= 0) & (Fa < n), axis=1)
    if not in_range.all() and not remove_invalid_faces:
        k = int((~in_range).sum())
        raise InvalidMeshError(
            f"{_n(k, 'triangle')} {_verb(k, 'refers', 'refer')} to vertices that do not exist, "
            "so the mesh cannot be cleaned safely. Export the file again, or clean with "
            "'remove invalid faces' switched on to delete those triangles (this leaves holes)."
        )
    st = _State(Va.copy(), Fa.copy())
    if remove_invalid_faces:
        finite = np.isfinite(st.V).all(axis=1)
        ok = in_range.copy()
        ok[in_range] = finite[st.F[in_range]].all(axis=1)
        k_range = int((~in_range).sum())
        k_nan = int((~ok).sum()) - k_range
        if k_range:
            st.actions.append(
                f"Removed {_n(k_range, 'triangle')} that referred to vertices that do not exist."
            )
        if k_nan:
            st.actions.append(
                f"Removed {_n(k_nan, 'triangle')} with corners at invalid (NaN or infinite) "
                "coordinates."
            )
        st.keep_faces(ok)

    def needs_work(report: MeshReport) -> bool:
        return any(
            i.fixable
            and i.severity in ("error", "warning")
            and (orient_outward or i.code != "inward_orientation")
            for i in report.issues
        )

    report = validate_mesh(st.V, st.F)
    passes = 0
    while passes < 3 and (needs_work(report) or (weld_tolerance > 0 and passes == 0)):
        _clean_pass(st, weld_tolerance, orient_outward)
        passes += 1
        report = validate_mesh(st.V, st.F)
    leftover = needs_work(report)  # should not happen; never stay silent if it does
    not_fixed = []
    for issue in report.issues:
        if issue.severity == "info":
            continue
        by_choice = issue.code == "inward_orientation" and not orient_outward
        if not issue.fixable or (leftover and not by_choice):
            not_fixed.append("Not fixed: " + issue.message)
    if st.actions:
        actions = st.actions + not_fixed
    elif not_fixed:
        actions = ["Nothing could be fixed automatically."] + not_fixed
    else:
        actions = ["Nothing to fix: the mesh is clean."]
    return CleanResult(
        V=st.V, F=st.F.astype(np.int64), actions=actions, vertex_map=st.vmap, face_map=st.fmap
    )


def _clean_pass(st: _State, weld_tolerance: float, orient_outward: bool) -> None:
    n = st.V.shape[0]
    finite = np.isfinite(st.V).all(axis=1)

    # 2. weld
    referenced = np.zeros(n, dtype=bool)
    referenced[st.F.ravel()] = True
    rep = _coincident_representatives(st.V, referenced & finite, weld_tolerance)
    if (rep != np.arange(n)).any():
        Fc = st.F[~_repeated_mask(st.F)]
        rep, kept_apart = _safe_weld(Fc, rep)
        k = int((rep != np.arange(n)).sum())
        if k:
            st.F = rep[st.F]
            # vertices merged away become unreferenced; removed in step 9
            moved = st.vmap >= 0
            st.vmap[moved] = rep[st.vmap[moved]]
            how = "duplicate" if weld_tolerance <= 0 else f"nearby (closer than {weld_tolerance:g})"
            st.actions.append(f"Merged {_n(k, how + ' vertex', how + ' vertices')}.")

    # 3. repeated indices
    rm = _repeated_mask(st.F)
    if rm.any():
        k = int(rm.sum())
        st.keep_faces(~rm)
        st.actions.append(f"Removed {_n(k, 'triangle')} that used the same vertex twice.")

    # 4. degenerate
    if st.F.shape[0]:
        used = np.unique(st.F)
        Vu = st.V[used]
        Vu = Vu[np.isfinite(Vu).all(axis=1)]
        diag = float(np.linalg.norm(Vu.max(axis=0) - Vu.min(axis=0))) if Vu.size else 0.0
        deg = _degenerate_mask(st.V, st.F, diag)
        if deg.any():
            k = int(deg.sum())
            st.keep_faces(~deg)
            st.actions.append(f"Removed {_n(k, 'degenerate triangle')} (zero area).")

    # 5. duplicate faces
    dup = _duplicate_face_mask(st.F)
    if dup.any():
        k = int(dup.sum())
        st.keep_faces(~dup)
        st.actions.append(f"Removed {_n(k, 'duplicate triangle')}.")

    # 6. non-manifold edges
    removed = 0
    fixed_edges = 0
    for _ in range(10):
        if st.F.shape[0] == 0:
            break
        d = _EdgeData(st.F)
        bad = d.counts > 2
        if not bad.any():
            break
        fixed_edges = max(fixed_edges, int(bad.sum()))
        remove = _extra_faces_on_edges(d, bad)
        removed += int(remove.sum())
        st.keep_faces(~remove)
    if removed:
        st.actions.append(
            f"Removed {_n(removed, 'triangle')} so that every edge touches at most two triangles "
            f"({_n(fixed_edges, 'non-manifold edge')} fixed)."
        )

    # 7. split non-manifold vertices
    if st.F.shape[0]:
        d = _EdgeData(st.F)
        labels, fans = _corner_fans(d, st.V.shape[0])
        if (fans > 1).any():
            k = int((fans > 1).sum())
            extra = int((fans[fans > 1] - 1).sum())
            _split_fans(st, labels, d.m)
            st.actions.append(
                f"Split {_n(k, 'non-manifold vertex', 'non-manifold vertices')} into "
                f"{k + extra:,} (one copy for each piece of surface meeting there)."
            )

    # 8. orientation
    if st.F.shape[0]:
        d = _EdgeData(st.F)
        if not (d.counts > 2).any():
            flip, patch, orientable = _orientation_data(d)
            if not orientable:  # one-sided: cut it open where the orientation still flips
                seam = _inconsistent_edges(d, flip)
                labels, _ = _corner_fans(d, st.V.shape[0], cut=seam)
                n_before = st.V.shape[0]
                _split_fans(st, labels, d.m)
                k = int(seam.sum())
                st.actions.append(
                    f"Cut the one-sided surface open along {_n(k, 'edge')} where its "
                    f"orientation flips ({_n(st.V.shape[0] - n_before, 'vertex', 'vertices')} "
                    "doubled), so that it has two sides; the seam is now a boundary."
                )
            if flip.any():
                k = int(flip.sum())
                st.F[flip] = st.F[flip][:, [0, 2, 1]]
                st.actions.append(
                    f"Flipped {_n(k, 'triangle')} so that neighbouring triangles agree on which "
                    "side is outside."
                )
            if orient_outward and orientable:
                P = int(patch.max()) + 1
                bmask = d.counts == 1
                face_boundary = np.zeros(d.m, dtype=bool)
                face_boundary[np.flatnonzero(bmask[d.EMAP]) % d.m] = True
                open_patch = np.bincount(patch, weights=face_boundary, minlength=P) > 0
                a, b, c = st.V[st.F[:, 0]], st.V[st.F[:, 1]], st.V[st.F[:, 2]]
                with np.errstate(invalid="ignore", over="ignore"):
                    vol_f = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
                vol = np.bincount(
                    patch, weights=np.where(np.isfinite(vol_f), vol_f, 0.0), minlength=P
                )
                has_nan = np.bincount(patch, weights=~np.isfinite(vol_f), minlength=P) > 0
                Vu = st.V[np.unique(st.F)]
                Vu = Vu[np.isfinite(Vu).all(axis=1)]
                diag = float(np.linalg.norm(Vu.max(axis=0) - Vu.min(axis=0))) if Vu.size else 0.0
                inward = (~open_patch) & (~has_nan) & (vol < -1e-12 * max(diag, 1e-300) ** 3)
                if inward.any():
                    fl = inward[patch]
                    st.F[fl] = st.F[fl][:, [0, 2, 1]]
                    k = int(inward.sum())
                    st.actions.append(
                        f"Flipped {_n(k, 'closed part')} that {_verb(k, 'was', 'were')} "
                        f"inside-out ({_n(int(fl.sum()), 'triangle')}), so normals point outwards."
                    )

    # 9. unreferenced vertices
    n = st.V.shape[0]
    referenced = np.zeros(n, dtype=bool)
    referenced[st.F.ravel()] = True
    if not referenced.all():
        k = int((~referenced).sum())
        k_nan = int((~referenced & ~np.isfinite(st.V).all(axis=1)).sum())
        new_index = np.full(n, -1, dtype=np.int64)
        new_index[referenced] = np.arange(int(referenced.sum()))
        # merged vertices already point at their representative; only true deletions go to -1
        st.remap_vertices(new_index, st.V[referenced])
        nan_note = f" ({k_nan:,} of them had invalid coordinates)" if k_nan else ""
        st.actions.append(f"Removed {_n(k, 'unused vertex', 'unused vertices')}{nan_note}.")


def _extra_faces_on_edges(d: _EdgeData, bad: np.ndarray) -> np.ndarray:
    """Faces to delete so that every bad edge keeps at most two faces.

    Per edge: keep the lowest-index face running each direction; if all faces run the same
    direction, keep the two lowest-index faces.
    """
    m = d.m
    h = np.flatnonzero(bad[d.EMAP])
    e = d.EMAP[h]
    f = h % m
    direction = (~d.fwd[h]).astype(np.int64)
    order = np.lexsort((f, direction, e))
    h, e, f, direction = h[order], e[order], f[order], direction[order]
    new_e = np.r_[True, e[1:] != e[:-1]]
    new_ed = new_e | np.r_[True, direction[1:] != direction[:-1]]
    # rank within edge and within (edge, direction)
    idx = np.arange(h.size)
    start_e = np.maximum.accumulate(np.where(new_e, idx, 0))
    start_ed = np.maximum.accumulate(np.where(new_ed, idx, 0))
    rank_e = idx - start_e
    rank_ed = idx - start_ed
    ndir = np.bincount(np.cumsum(new_e) - 1, weights=new_ed)[np.cumsum(new_e) - 1]
    keep = np.where(ndir >= 2, rank_ed == 0, rank_e < 2)
    remove = np.zeros(m, dtype=bool)
    remove[f[~keep]] = True
    return remove


def _split_fans(st: _State, labels: np.ndarray, m: int) -> None:
    """Give every fan beyond the first at a vertex its own vertex copy."""
    Fc = st.F.T.ravel()
    ncomp = int(labels.max()) + 1
    vertex_of_fan = np.empty(ncomp, dtype=np.int64)
    vertex_of_fan[labels] = Fc
    # first fan of each vertex = the one containing its lowest corner index
    first_corner = np.full(ncomp, Fc.size, dtype=np.int64)
    first_corner[labels[::-1]] = np.arange(Fc.size)[::-1]
    order = np.lexsort((first_corner, vertex_of_fan))
    is_first = np.r_[True, vertex_of_fan[order][1:] != vertex_of_fan[order][:-1]]
    n = st.V.shape[0]
    new_of_fan = np.empty(ncomp, dtype=np.int64)
    extra = order[~is_first]
    new_of_fan[order[is_first]] = vertex_of_fan[order[is_first]]
    new_of_fan[extra] = n + np.arange(extra.size)
    st.V = np.vstack([st.V, st.V[vertex_of_fan[extra]]])
    st.F = new_of_fan[labels].reshape(3, m).T.copy()
