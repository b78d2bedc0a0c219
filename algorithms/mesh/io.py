"""Reading and writing triangle meshes (OBJ, OFF, PLY, STL, GLB).

Formats
-------
Read (:data:`SUPPORTED_READ`) and write (:data:`SUPPORTED_WRITE`): ``.obj``, ``.off``, ``.ply``,
``.stl``, ``.glb`` (binary glTF 2.0: every triangle primitive of the default scene, node
transforms applied; sparse accessors, external buffers and compression extensions are refused
with a plain message). ``write_mesh(..., vertex_colors=)`` stores per-vertex colours in PLY
(``uchar red green blue``) and OBJ (``v x y z r g b``, the common extension).
The extension decides the format; case does not matter (``.OBJ`` works).

* **OBJ** -- ``v`` and ``f`` lines; face tokens ``1``, ``1/2``, ``1/2/3``, ``1//3``; negative
  (relative) indices; ``\\`` line continuations; everything else (``vt``, ``vn``, ``g``, ``usemtl``,
  ...) is ignored. Extra values on ``v`` lines (``w`` or colours) are ignored.
* **OFF** -- ``OFF``, ``COFF``, ``NOFF``, ``CNOFF``, ``STOFF`` headers, ``#`` comments, counts on
  the header line or the next line, per-vertex and per-face colours (ignored). Indices are 0-based.
* **PLY** -- ``ascii``, ``binary_little_endian`` and ``binary_big_endian``; vertex ``x y z`` of any
  numeric type; faces from the list property ``vertex_indices`` or ``vertex_index`` (any count and
  index types), or, if there is no ``face`` element, from a ``tristrips`` element. Every other
  element and property is skipped correctly.
* **STL** -- ASCII and binary. STL stores the three corners of every triangle separately; corners
  with bit-identical coordinates are welded into shared vertices (in order of first appearance) and
  a note says so.

Polygons with more than three corners are split into triangles by a fan from their first corner,
and :attr:`MeshData.notes` says how many were split.

Policy on bad content (read on purpose, reported later)
--------------------------------------------------------
:func:`read_mesh` raises :class:`~algorithms.errors.MeshReadError` only when the file cannot be
turned into arrays at all: missing file, folder, unknown extension, empty file, no vertices, no
faces (a point cloud), text that is not the announced format (including binary garbage named
``.obj``), a truncated binary PLY/STL, an OBJ face index ``0`` (OBJ counts from 1, so ``0`` has no
meaning), or an index too large to store in a 64-bit integer.

It deliberately does **not** raise for content that *can* be represented but is wrong: NaN or
infinite coordinates and out-of-range (too large or negative) face indices are kept in ``V`` and
``F`` exactly as given (0-based; an out-of-range OBJ index ``k`` is stored as ``k - 1``; a negative
OBJ index that points before the first vertex is stored as the negative number it resolves to).
:func:`algorithms.mesh.validate.validate_mesh` then reports them in plain language, which is more
useful to a novice than a refusal to open the file. Faces with fewer than three corners cannot be
represented as triangles; they are skipped and a note says so.

Writing
-------
:func:`write_mesh` is atomic: the data goes to a temporary file in the target folder, which is
flushed, ``fsync``-ed and then moved over the target with :func:`os.replace`. On any failure the
temporary file is removed, an existing file at the target is left byte-for-byte untouched, and
:class:`~algorithms.errors.MeshWriteError` is raised. OBJ and OFF store coordinates with Python's
shortest round-trip representation (``repr``), so a write/read round trip is exact; PLY stores
``double`` coordinates (exact); STL stores ``float32`` (the format allows nothing else); GLB stores
``float32`` positions and normals and ``uint32`` indices (glTF's rules). Non-finite coordinates
can be written to OBJ/OFF/PLY/STL (so a broken mesh can be inspected elsewhere) but not to GLB,
whose JSON cannot hold NaN; out-of-range indices are always refused.
"""

from __future__ import annotations

import json
import os
import re
import stat
import struct
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Callable

import numpy as np

from ..errors import MeshReadError, MeshWriteError

__all__ = [
    "MeshData",
    "read_mesh",
    "write_mesh",
    "SUPPORTED_READ",
    "SUPPORTED_WRITE",
    "file_filter",
    "atomic_write",
]

#: Extensions :func:`read_mesh` understands (lower case, with the dot).
SUPPORTED_READ: tuple[str, ...] = (".obj", ".ply", ".stl", ".off", ".glb")
#: Extensions :func:`write_mesh` understands (lower case, with the dot).
SUPPORTED_WRITE: tuple[str, ...] = (".obj", ".ply", ".stl", ".off", ".glb")

_FORMAT_NAMES = {
    ".obj": "an OBJ",
    ".off": "an OFF",
    ".ply": "a PLY",
    ".stl": "an STL",
    ".glb": "a GLB (binary glTF)",
}

_INT64_MAX = np.iinfo(np.int64).max
_INT64_MIN = np.iinfo(np.int64).min


def file_filter(mode: str = "read") -> str:
    """Return a Qt file-dialog filter string for the supported formats.

    Parameters
    ----------
    mode : {'read', 'write'}
        Both give ``"Meshes (*.obj *.ply *.stl *.off *.glb)"`` today.

    Returns
    -------
    str
        A filter such as ``"Meshes (*.obj *.ply *.stl *.off *.glb)"``.
    """
    if mode == "read":
        exts = SUPPORTED_READ
    elif mode == "write":
        exts = SUPPORTED_WRITE
    else:
        raise ValueError(f"file_filter mode must be 'read' or 'write', not {mode!r}")
    return "Meshes (" + " ".join("*" + e for e in exts) + ")"


@dataclass(frozen=True)
class MeshData:
    """A mesh as read from a file.

    Attributes
    ----------
    V : numpy.ndarray
        ``(n, 3) float64`` vertex positions (may contain NaN/inf if the file did).
    F : numpy.ndarray
        ``(m, 3) int64`` 0-based triangle corner indices (may be out of range if the file was).
    notes : list of str
        Plain-language remarks about what reading did, e.g.
        ``"24 quads and 3 polygons were split into triangles (fan triangulation)."``
    """

    V: np.ndarray
    F: np.ndarray
    notes: list[str] = field(default_factory=list)

    @property
    def n_vertices(self) -> int:
        """Number of vertex rows, ``V.shape[0]``."""
        return int(self.V.shape[0])

    @property
    def n_faces(self) -> int:
        """Number of triangles, ``F.shape[0]``."""
        return int(self.F.shape[0])


class _ParseError(Exception):
    """Internal: the content does not follow the format. The message completes a sentence."""


# --------------------------------------------------------------------------------------------
# helpers shared by the parsers
# --------------------------------------------------------------------------------------------


def _plural(count: int, singular: str, plural: str | None = None) -> str:
    word = singular if count == 1 else (plural or singular + "s")
    return f"{count:,} {word}"


def _reject_binary(data: bytes) -> None:
    """Raise _ParseError when a file that should be text looks like binary data."""
    sample = data[:65536]
    if b"\x00" in sample:
        raise _ParseError("it contains binary data, not text. Is it really this kind of file?")
    arr = np.frombuffer(sample, dtype=np.uint8)
    control = (arr < 32) & ~np.isin(arr, (9, 10, 11, 12, 13)) | (arr == 127)
    if arr.size and control.mean() > 0.01:
        raise _ParseError("it contains binary data, not text. Is it really this kind of file?")


def _fromstring(text: str, dtype, expected: int) -> np.ndarray:
    """``np.fromstring(text, sep=" ")`` that raises ValueError unless it read exactly
    ``expected`` values to the end. ``np.fromstring`` stops silently (with a
    DeprecationWarning) at the first token it cannot read, so a sentinel value is appended: a
    stop anywhere before the end loses it. No warning filter is touched (``catch_warnings`` is
    process-wide, not thread-safe: a mesh read in a worker thread turned another thread's
    warnings into errors)."""
    try:
        arr = np.fromstring(text + " 0", dtype=dtype, sep=" ")
    except DeprecationWarning:      # where warnings are errors
        raise ValueError("unreadable value") from None
    if arr.size != expected + 1:
        raise ValueError("wrong number of values")
    return arr[:-1]


def _parse_floats(text: str, expected: int) -> np.ndarray:
    """Parse whitespace-separated floats (fast C path); raise ValueError if anything is off."""
    if expected == 0:
        return np.zeros(0)
    return _fromstring(text, np.float64, expected)


def _parse_ints(text: str, expected: int) -> np.ndarray:
    """Parse whitespace-separated integers; raise ValueError/OverflowError if anything is off."""
    if expected == 0:
        return np.zeros(0, dtype=np.int64)
    arr = _fromstring(text, np.int64, expected)
    if arr.size and (arr.max() == _INT64_MAX or arr.min() == _INT64_MIN):
        # np.fromstring saturates instead of failing; check the extreme tokens exactly.
        for tok in text.split():
            if not (_INT64_MIN < int(tok) < _INT64_MAX):
                raise OverflowError(tok)
    return arr


def _first_bad_token(tokens: list[str], kind: type) -> str | None:
    for tok in tokens:
        try:
            kind(tok)
        except (ValueError, OverflowError):
            return tok
    return None


def _fan_triangulate(flat: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, int, int, int]:
    """Fan-triangulate polygons stored as a flat index list with per-polygon corner counts.

    Returns ``(F, n_quads, n_polygons, n_skipped)`` where n_skipped counts polygons with < 3
    corners (dropped).
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.cumsum(counts) - counts
    keep = counts >= 3
    n_skipped = int((~keep).sum())
    n_quads = int((counts == 4).sum())
    n_polys = int((counts > 4).sum())
    if n_quads == 0 and n_polys == 0 and n_skipped == 0:
        return flat.reshape(-1, 3), 0, 0, 0
    counts_k = counts[keep]
    starts_k = starts[keep]
    ntri = counts_k - 2
    total = int(ntri.sum())
    owner = np.repeat(np.arange(counts_k.size), ntri)
    j = np.arange(total) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    s = starts_k[owner]
    F = np.stack([flat[s], flat[s + j + 1], flat[s + j + 2]], axis=1)
    return F, n_quads, n_polys, n_skipped


def _polygon_notes(n_quads: int, n_polys: int, n_skipped: int) -> list[str]:
    notes = []
    if n_quads or n_polys:
        parts = []
        if n_quads:
            parts.append(_plural(n_quads, "quad"))
        if n_polys:
            parts.append(_plural(n_polys, "polygon"))
        verb = "was" if n_quads + n_polys == 1 else "were"
        notes.append(f"{' and '.join(parts)} {verb} split into triangles (fan triangulation).")
    if n_skipped:
        notes.append(
            f"{_plural(n_skipped, 'face')} with fewer than three corners "
            f"{'was' if n_skipped == 1 else 'were'} skipped (a face needs at least three)."
        )
    return notes


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------

_OBJ_V = ("v ", "v\t")
_OBJ_F = ("f ", "f\t")


def _parse_obj(data: bytes) -> tuple[np.ndarray, np.ndarray, list[str]]:
    _reject_binary(data)
    text = data.decode("utf-8", errors="replace")
    if "\\" in text:
        text = re.sub(r"\\[ \t]*\r?\n", " ", text)
    if re.search(r"(?m)^[ \t]", text):
        text = re.sub(r"(?m)^[ \t]+", "", text)
    lines = text.splitlines()
    vlines = [ln[2:] for ln in lines if ln.startswith(_OBJ_V)]
    flines = [ln[2:] for ln in lines if ln.startswith(_OBJ_F)]
    if not vlines and not flines:
        raise _ParseError("no vertex ('v') or face ('f') lines were found")

    def line_numbers(prefix: tuple[str, ...]) -> np.ndarray:
        return np.array([i + 1 for i, ln in enumerate(lines) if ln.startswith(prefix)], np.int64)

    # ---- vertices
    if any("#" in ln for ln in vlines):
        vlines = [ln.split("#", 1)[0] for ln in vlines]
    nv = len(vlines)
    vsplit = list(map(str.split, vlines))
    vcount = np.fromiter(map(len, vsplit), dtype=np.int64, count=nv)
    if nv and vcount.min() < 3:
        k = int(np.argmax(vcount < 3))
        raise _ParseError(
            f"line {line_numbers(_OBJ_V)[k]}: a vertex ('v') line needs three coordinates, "
            f"found {vcount[k]}"
        )
    try:
        if nv and vcount.max() == 3:
            V = _parse_floats("\n".join(vlines), 3 * nv).reshape(nv, 3)
        else:
            V = np.array([s[:3] for s in vsplit], dtype=np.float64).reshape(nv, 3)
    except ValueError:
        rows = np.array([_first_bad_token(s[:3], float) is not None for s in vsplit])
        k = int(np.argmax(rows))
        bad = _first_bad_token(vsplit[k][:3], float)
        raise _ParseError(
            f"line {line_numbers(_OBJ_V)[k]}: '{bad}' is not a number (vertex coordinates must be "
            "numbers)"
        ) from None

    # ---- faces
    nf = len(flines)
    if nf == 0:
        return V, np.zeros((0, 3), np.int64), []
    joined = "\n".join(flines)
    if "#" in joined:
        joined = re.sub(r"#[^\n]*", "", joined)
    if "/" in joined:
        joined = re.sub(r"/[^\s]*", "", joined)
    fl = joined.split("\n")
    fsplit = list(map(str.split, fl))
    fcount = np.fromiter(map(len, fsplit), dtype=np.int64, count=nf)
    total = int(fcount.sum())
    try:
        flat = _parse_ints(joined, total)
    except (ValueError, OverflowError):
        for k, toks in enumerate(fsplit):
            bad = _first_bad_token(toks, int)
            if bad is None:
                bad = next((t for t in toks if not (_INT64_MIN < int(t) < _INT64_MAX)), None)
            if bad is not None:
                raise _ParseError(
                    f"line {line_numbers(_OBJ_F)[k]}: '{bad}' is not a valid vertex index "
                    "(face corners must be whole numbers that fit in 64 bits)"
                ) from None
        raise _ParseError("the face ('f') lines could not be parsed") from None

    if total and (flat == 0).any():
        pos = int(np.argmax(flat == 0))
        k = int(np.searchsorted(np.cumsum(fcount), pos, side="right"))
        raise _ParseError(
            f"line {line_numbers(_OBJ_F)[k]}: face index 0 is not allowed (OBJ counts vertices "
            "from 1, or from -1 backwards)"
        )
    neg = flat < 0
    if neg.any():
        # relative index -1 = the most recent vertex defined before this face line
        vpos = line_numbers(_OBJ_V)
        fpos = line_numbers(_OBJ_F)
        before = np.searchsorted(vpos, fpos)  # vertices defined before each face line
        per_tok = np.repeat(before, fcount)
        flat = np.where(neg, per_tok + flat, flat - 1)
    else:
        flat = flat - 1
    F, nq, npoly, nskip = _fan_triangulate(flat, fcount)
    return V, F, _polygon_notes(nq, npoly, nskip)


# --------------------------------------------------------------------------------------------
# OFF
# --------------------------------------------------------------------------------------------


def _parse_off(data: bytes) -> tuple[np.ndarray, np.ndarray, list[str]]:
    head = data[:4096].lstrip()
    if re.match(rb"^[A-Za-z]*OFF[ \t]+BINARY", head):
        raise _ParseError(
            "binary OFF files are not supported. Save the mesh as ASCII OFF, PLY or OBJ instead"
        )
    _reject_binary(data)
    text = data.decode("utf-8", errors="replace")
    if "#" in text:
        text = re.sub(r"#[^\n\r]*", "", text)
    lines = [ln for ln in (s.strip() for s in text.splitlines()) if ln]
    if not lines:
        raise _ParseError("it contains only comments")
    header = lines[0].split()
    magic = header[0]
    m = re.fullmatch(r"(ST)?(C)?(N)?(4)?(n)?OFF", magic)
    if m is None:
        raise _ParseError(f"the first line should be 'OFF' but it is '{lines[0][:40]}'")
    if m.group(4) or m.group(5):
        raise _ParseError(f"'{magic}' files (not 3-D) are not supported")
    rest = header[1:]
    body_start = 1
    if len(rest) < 2:
        if len(lines) < 2:
            raise _ParseError("the line with the vertex and face counts is missing")
        rest = lines[1].split()
        body_start = 2
    try:
        nv, nf = int(rest[0]), int(rest[1])
        if nv < 0 or nf < 0:
            raise ValueError
    except (ValueError, IndexError):
        raise _ParseError(
            f"the counts line should hold 'vertices faces edges', found '{' '.join(rest)[:40]}'"
        ) from None
    body = lines[body_start:]
    if len(body) < nv:
        raise _ParseError(
            f"the header announces {nv:,} vertices but the file holds only {len(body):,} vertex "
            "lines (is it truncated?)"
        )
    vlines = body[:nv]
    flines = body[nv : nv + nf]
    if len(flines) < nf:
        raise _ParseError(
            f"the header announces {nf:,} faces but the file holds only {len(flines):,} face "
            "lines (is it truncated?)"
        )
    vsplit = list(map(str.split, vlines))
    vcount = np.fromiter(map(len, vsplit), dtype=np.int64, count=nv)
    if nv and vcount.min() < 3:
        k = int(np.argmax(vcount < 3))
        raise _ParseError(f"vertex {k} has fewer than three coordinates")
    try:
        if nv and vcount.min() == vcount.max():
            c = int(vcount[0])
            V = _parse_floats(" ".join(vlines), nv * c).reshape(nv, c)[:, :3].copy()
        else:
            V = np.array([s[:3] for s in vsplit], dtype=np.float64).reshape(nv, 3)
    except ValueError:
        for k, toks in enumerate(vsplit):
            bad = _first_bad_token(toks[:3], float)
            if bad is not None:
                raise _ParseError(f"vertex {k}: '{bad}' is not a number") from None
        raise _ParseError("the vertex lines could not be parsed") from None

    if nf == 0:
        return V, np.zeros((0, 3), np.int64), []
    fsplit = list(map(str.split, flines))
    fcount = np.fromiter(map(len, fsplit), dtype=np.int64, count=nf)
    if fcount.min() == fcount.max() and fcount[0] >= 4:
        # fast paths: every face line has the same number of tokens
        c = int(fcount[0])
        if c == 4:
            try:
                arr = _parse_ints(" ".join(flines), nf * 4).reshape(nf, 4)
            except (ValueError, OverflowError):
                arr = None
            if arr is not None and (arr[:, 0] == 3).all():
                return V, arr[:, 1:].copy(), []
        else:
            sarr = np.array(fsplit)
            if (sarr[:, 0] == "3").all():
                try:
                    return V, sarr[:, 1:4].astype(np.int64), []
                except (ValueError, OverflowError):
                    pass  # the general path below finds and reports the bad token
    # general path: polygons and/or colours after the indices
    heads = [s[0] if s else "" for s in fsplit]
    try:
        k = np.array(heads).astype(np.int64)
    except (ValueError, OverflowError):
        j = next(j for j, h in enumerate(heads) if _first_bad_token([h], int) is not None)
        raise _ParseError(
            f"face {j}: '{heads[j]}' should be the number of corners (a whole number)"
        ) from None
    short = fcount < k + 1
    if short.any() or (k < 0).any():
        j = int(np.argmax(short | (k < 0)))
        raise _ParseError(
            f"face {j} announces {k[j]} corners but its line holds {fcount[j] - 1} indices"
        )
    tokens = [t for s, kk in zip(fsplit, k.tolist(), strict=True) for t in s[1 : 1 + kk]]
    try:
        flat = np.array(tokens).astype(np.int64) if tokens else np.zeros(0, np.int64)
    except (ValueError, OverflowError):
        bad = _first_bad_token(tokens, int)
        raise _ParseError(f"'{bad}' is not a valid vertex index (a whole number)") from None
    F, nq, npoly, nskip = _fan_triangulate(flat, k)
    return V, F, _polygon_notes(nq, npoly, nskip)


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


@dataclass
class _PlyProperty:
    name: str
    dtype: str  # item type ('i4', ...)
    count_dtype: str | None = None  # list count type, None for scalar properties


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list[_PlyProperty] = field(default_factory=list)


def _ply_header(data: bytes) -> tuple[str, list[_PlyElement], int]:
    if not data.startswith(b"ply"):
        raise _ParseError("it does not start with 'ply'")
    m = re.search(rb"end_header[ \t]*\r?\n", data[:1 << 20])
    if m is None:
        raise _ParseError("its header has no 'end_header' line")
    header = data[: m.start()].decode("ascii", errors="replace")
    fmt = None
    elements: list[_PlyElement] = []
    for raw in header.splitlines()[1:]:
        toks = raw.split()
        if not toks or toks[0] in ("comment", "obj_info"):
            continue
        if toks[0] == "format":
            if len(toks) < 2 or toks[1] not in (
                "ascii",
                "binary_little_endian",
                "binary_big_endian",
            ):
                raise _ParseError(f"unknown PLY format line '{raw.strip()}'")
            fmt = toks[1]
        elif toks[0] == "element":
            try:
                elements.append(_PlyElement(toks[1], int(toks[2])))
            except (IndexError, ValueError):
                raise _ParseError(f"bad header line '{raw.strip()}'") from None
            if elements[-1].count < 0:
                raise _ParseError(f"bad element count in '{raw.strip()}'")
        elif toks[0] == "property":
            if not elements:
                raise _ParseError(f"header line '{raw.strip()}' comes before any element")
            try:
                if toks[1] == "list":
                    prop = _PlyProperty(toks[4], _PLY_TYPES[toks[3]], _PLY_TYPES[toks[2]])
                else:
                    prop = _PlyProperty(toks[2], _PLY_TYPES[toks[1]])
            except (IndexError, KeyError):
                raise _ParseError(f"unknown property type in '{raw.strip()}'") from None
            elements[-1].props.append(prop)
        else:
            raise _ParseError(f"unknown header line '{raw.strip()}'")
    if fmt is None:
        raise _ParseError("its header has no 'format' line")
    return fmt, elements, m.end()


def _ply_binary_element(
    data: bytes, pos: int, el: _PlyElement, endian: str
) -> tuple[dict[str, np.ndarray | tuple[np.ndarray, np.ndarray]], int]:
    """Read one binary element. Returns ({prop: array or (flat, counts)}, new position)."""
    n = el.count
    total = len(data)

    def truncated() -> _ParseError:
        return _ParseError(
            f"the file ends early (it looks truncated) while reading the {n:,} '{el.name}' records"
        )

    if all(p.count_dtype is None for p in el.props):
        dt = np.dtype([(f"p{i}", endian + p.dtype) for i, p in enumerate(el.props)])
        if pos + n * dt.itemsize > total:
            raise truncated()
        arr = np.frombuffer(data, dtype=dt, count=n, offset=pos)
        out = {p.name: arr[f"p{i}"] for i, p in enumerate(el.props)}
        return out, pos + n * dt.itemsize
    if n == 0:
        return {p.name: (np.zeros(0), np.zeros(0, np.int64)) if p.count_dtype else np.zeros(0)
                for p in el.props}, pos
    # Fast path: assume every list in this element has the length it has in the first record.
    fields = []
    p0 = pos
    for i, p in enumerate(el.props):
        if p.count_dtype is None:
            fields.append((f"p{i}", endian + p.dtype))
            p0 += np.dtype(p.dtype).itemsize
        else:
            cdt = np.dtype(endian + p.count_dtype)
            if p0 + cdt.itemsize > total:
                raise truncated()
            c = int(np.frombuffer(data, dtype=cdt, count=1, offset=p0)[0])
            if c < 0:
                raise _ParseError(f"a '{el.name}' record has a negative list length")
            fields.append((f"c{i}", cdt))
            fields.append((f"p{i}", endian + p.dtype, (c,)))
            p0 += cdt.itemsize + c * np.dtype(p.dtype).itemsize
    dt = np.dtype(fields)
    if pos + n * dt.itemsize <= total:
        arr = np.frombuffer(data, dtype=dt, count=n, offset=pos)
        ok = True
        for i, p in enumerate(el.props):
            if p.count_dtype is not None:
                c = arr.dtype[f"p{i}"].shape[0] if arr.dtype[f"p{i}"].shape else 0
                if not (arr[f"c{i}"] == c).all():
                    ok = False
                    break
        if ok:
            out: dict = {}
            for i, p in enumerate(el.props):
                if p.count_dtype is None:
                    out[p.name] = arr[f"p{i}"]
                else:
                    vals = arr[f"p{i}"].reshape(n, -1)
                    out[p.name] = (vals.ravel(), np.full(n, vals.shape[1], np.int64))
            return out, pos + n * dt.itemsize
    # Slow path (lists of different lengths, e.g. mixed triangles and quads): walk the records.
    # Sequential by nature, so a Python loop over records is unavoidable here.
    sizes = []
    for p in el.props:
        sizes.append(
            (np.dtype(p.dtype).itemsize, None if p.count_dtype is None else np.dtype(p.count_dtype))
        )
    starts = {i: [] for i, p in enumerate(el.props)}
    counts = {i: [] for i, p in enumerate(el.props) if p.count_dtype is not None}
    struct_codes = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I",
                    "f4": "f", "f8": "d"}
    count_fmt = {
        i: endian + struct_codes[p.count_dtype]
        for i, p in enumerate(el.props)
        if p.count_dtype is not None
    }
    cur = pos
    unpack = struct.unpack_from
    try:
        for _ in range(n):
            for i, (isz, cdt) in enumerate(sizes):
                if cdt is None:
                    starts[i].append(cur)
                    cur += isz
                else:
                    c = int(unpack(count_fmt[i], data, cur)[0])
                    if c < 0:
                        raise _ParseError(f"a '{el.name}' record has a negative list length")
                    cur += cdt.itemsize
                    starts[i].append(cur)
                    counts[i].append(c)
                    cur += c * isz
    except struct.error:
        raise truncated() from None
    if cur > total:
        raise truncated()
    buf = np.frombuffer(data, dtype=np.uint8)
    out = {}
    for i, p in enumerate(el.props):
        isz = sizes[i][0]
        st = np.asarray(starts[i], dtype=np.int64)
        if p.count_dtype is None:
            byte_idx = st[:, None] + np.arange(isz)
            out[p.name] = buf[byte_idx].copy().view(endian + p.dtype).ravel()
        else:
            cn = np.asarray(counts[i], dtype=np.int64)
            tot = int(cn.sum())
            item_start = np.repeat(st, cn) + isz * (
                np.arange(tot) - np.repeat(np.cumsum(cn) - cn, cn)
            )
            byte_idx = item_start[:, None] + np.arange(isz)
            vals = buf[byte_idx].copy().view(endian + p.dtype).ravel()
            out[p.name] = (vals, cn)
    return out, cur


def _ply_ascii_element(
    tokens: np.ndarray, pos: int, el: _PlyElement
) -> tuple[dict[str, np.ndarray | tuple[np.ndarray, np.ndarray]], int]:
    n = el.count
    total = tokens.size

    def truncated() -> _ParseError:
        return _ParseError(
            f"the file ends early (it looks truncated) while reading the {n:,} '{el.name}' records"
        )

    def conv(tok: np.ndarray, dtype: str) -> np.ndarray:
        try:
            if dtype[0] == "f":
                return tok.astype(np.float64)
            return tok.astype(np.float64).astype(np.int64) if tok.size else tok.astype(np.int64)
        except ValueError:
            bad = _first_bad_token(tok.tolist(), float)
            raise _ParseError(f"'{bad}' in the '{el.name}' records is not a number") from None

    if n == 0:
        return {p.name: (np.zeros(0), np.zeros(0, np.int64)) if p.count_dtype else np.zeros(0)
                for p in el.props}, pos
    # Fast path: fixed record length taken from the first record.
    offs = []
    rec = 0
    lens = []
    for p in el.props:
        if p.count_dtype is None:
            offs.append(rec)
            lens.append(None)
            rec += 1
        else:
            if pos + rec >= total:
                raise truncated()
            try:
                c = int(tokens[pos + rec])
            except ValueError:
                raise _ParseError(
                    f"'{tokens[pos + rec]}' should be a list length in the '{el.name}' records"
                ) from None
            offs.append(rec)
            lens.append(c)
            rec += 1 + c
    if pos + n * rec <= total:
        block = tokens[pos : pos + n * rec].reshape(n, rec)
        ok = all(
            c is None or (block[:, o] == str(c)).all() for o, c in zip(offs, lens, strict=True)
        )
        if ok:
            out: dict = {}
            for p, o, c in zip(el.props, offs, lens, strict=True):
                if c is None:
                    out[p.name] = conv(block[:, o], p.dtype)
                else:
                    vals = conv(block[:, o + 1 : o + 1 + c].ravel(), p.dtype)
                    out[p.name] = (vals, np.full(n, c, np.int64))
            return out, pos + n * rec
    # Slow path: variable-length lists; walk record by record (sequential by nature).
    starts: dict[int, list[int]] = {i: [] for i in range(len(el.props))}
    counts: dict[int, list[int]] = {i: [] for i in range(len(el.props))}
    cur = pos
    try:
        for _ in range(n):
            for i, p in enumerate(el.props):
                if p.count_dtype is None:
                    starts[i].append(cur)
                    cur += 1
                else:
                    c = int(tokens[cur])
                    if c < 0:
                        raise _ParseError(f"a '{el.name}' record has a negative list length")
                    starts[i].append(cur + 1)
                    counts[i].append(c)
                    cur += 1 + c
    except IndexError:
        raise truncated() from None
    except ValueError:
        raise _ParseError(
            f"a list length in the '{el.name}' records is not a whole number"
        ) from None
    if cur > total:
        raise truncated()
    out = {}
    for i, p in enumerate(el.props):
        st = np.asarray(starts[i], dtype=np.int64)
        if p.count_dtype is None:
            out[p.name] = conv(tokens[st], p.dtype)
        else:
            cn = np.asarray(counts[i], dtype=np.int64)
            tot = int(cn.sum())
            idx = np.repeat(st, cn) + (np.arange(tot) - np.repeat(np.cumsum(cn) - cn, cn))
            out[p.name] = (conv(tokens[idx], p.dtype), cn)
    return out, cur


def _tristrips_to_triangles(flat: np.ndarray) -> tuple[np.ndarray, int]:
    """Convert -1 separated triangle strips to triangles (alternating winding).

    Returns (F, number of zero-area strip triangles dropped, i.e. with a repeated corner).
    """
    flat = np.asarray(flat, dtype=np.int64)
    sep = flat < 0
    if flat.size < 3:
        return np.zeros((0, 3), np.int64), 0
    # position within its strip
    strip_id = np.cumsum(sep)
    idx = np.arange(flat.size)
    last_sep = np.maximum.accumulate(np.where(sep, idx, -1))
    pos_in_strip = idx - last_sep - 1  # first vertex of a strip has 0
    i = idx[:-2]
    valid = (~sep[:-2]) & (~sep[1:-1]) & (~sep[2:]) & (strip_id[:-2] == strip_id[2:])
    i = i[valid]
    a, b, c = flat[i], flat[i + 1], flat[i + 2]
    odd = (pos_in_strip[i] % 2) == 1
    F = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    degenerate = (a == b) | (b == c) | (a == c)
    return F[~degenerate], int(degenerate.sum())


def ply_colors(data: bytes) -> tuple[str, np.ndarray] | None:
    """The colours of a PLY file's bytes (ASCII or binary): ``("vertex", (n, 3))`` from the
    vertex element's red / green / blue, else ``("face", (m, 3))`` from the face element's,
    one row per triangle as :func:`read_mesh` triangulates (a polygon's colour repeated for
    each of its triangles); values in [0, 1] (0-255 integers scaled). None when it has none
    or cannot be parsed."""
    try:
        elements, results = _ply_elements(data)
    except (_ParseError, ValueError):
        return None
    types = {(e.name, p.name): p.dtype for e in elements for p in e.props}
    for name in ("vertex", "face"):
        el = results.get(name)
        if el is None or not all(c in el and not isinstance(el[c], tuple)
                                 for c in ("red", "green", "blue")):
            continue
        C = np.column_stack([np.asarray(el[c], dtype=np.float64) for c in ("red", "green", "blue")])
        if types.get((name, "red"), "f")[0] in "iu" or C.max(initial=0.0) > 1.0:
            C = C / 255.0
        if name == "face":
            key = next((k for k in ("vertex_indices", "vertex_index") if k in el), None)
            if key is None or not isinstance(el[key], tuple):
                return None
            counts = np.asarray(el[key][1], dtype=np.int64)
            C = np.repeat(C, np.maximum(counts - 2, 0), axis=0)
        return name, np.clip(C, 0.0, 1.0)
    return None


def _ply_elements(data: bytes) -> tuple[list[_PlyElement], dict[str, dict]]:
    """The header's elements and each element's properties read (ASCII or binary): the one
    reader behind :func:`read_mesh`'s PLY and :func:`ply_colors`."""
    fmt, elements, start = _ply_header(data)
    results: dict[str, dict] = {}
    if fmt == "ascii":
        tokens = np.array(data[start:].decode("ascii", errors="replace").split())
        pos = 0
        for el in elements:
            res, pos = _ply_ascii_element(tokens, pos, el)
            results.setdefault(el.name, res)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        pos = start
        for el in elements:
            res, pos = _ply_binary_element(data, pos, el, endian)
            results.setdefault(el.name, res)
    return elements, results


def _parse_ply(data: bytes) -> tuple[np.ndarray, np.ndarray, list[str]]:
    elements, results = _ply_elements(data)
    if "vertex" not in results:
        raise _ParseError("it has no 'vertex' element")
    vert = results["vertex"]
    missing = [k for k in ("x", "y", "z") if k not in vert]
    if missing:
        raise _ParseError(f"the 'vertex' element has no {', '.join(missing)} property")
    if any(isinstance(vert[k], tuple) for k in "xyz"):
        raise _ParseError("the vertex coordinates x, y, z must be numbers, not lists")
    V = np.column_stack([np.asarray(vert[k], dtype=np.float64) for k in "xyz"])
    notes: list[str] = []
    if "face" in results:
        face = results["face"]
        key = next((k for k in ("vertex_indices", "vertex_index") if k in face), None)
        if key is None or not isinstance(face[key], tuple):
            raise _ParseError(
                "the 'face' element has no 'vertex_indices' (or 'vertex_index') list property"
            )
        flat, counts = face[key]
        flat = _as_index_array(flat)
        F, nq, npoly, nskip = _fan_triangulate(flat, counts)
        notes += _polygon_notes(nq, npoly, nskip)
    elif "tristrips" in results and isinstance(results["tristrips"].get("vertex_indices"), tuple):
        flat, _counts = results["tristrips"]["vertex_indices"]
        F, ndeg = _tristrips_to_triangles(_as_index_array(flat))
        notes.append(f"Triangle strips were converted to {F.shape[0]:,} triangles.")
        if ndeg:
            notes.append(
                f"{_plural(ndeg, 'zero-area triangle')} used only to join strips "
                f"{'was' if ndeg == 1 else 'were'} dropped."
            )
    else:
        F = np.zeros((0, 3), np.int64)
    return V, F, notes


def _as_index_array(flat: np.ndarray) -> np.ndarray:
    flat = np.asarray(flat)
    if flat.dtype.kind == "f":
        if not np.all(np.isfinite(flat)) or not np.all(flat == np.round(flat)):
            raise _ParseError("some face indices are not whole numbers")
        if flat.size and np.abs(flat).max() >= 2.0**63:
            raise _ParseError("some face indices are too large to be stored")
    return flat.astype(np.int64)


# --------------------------------------------------------------------------------------------
# STL
# --------------------------------------------------------------------------------------------

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def _weld_corners(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weld bit-identical corner positions. P is (3m, 3). Returns V (first-appearance order), F."""
    P = np.ascontiguousarray(P, dtype=np.float64) + 0.0  # -0.0 -> 0.0
    if P.shape[0] == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    key = P.view(np.dtype((np.void, 24))).ravel()
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    V = P[first[order]]
    F = rank[inverse.ravel()].reshape(-1, 3).astype(np.int64)
    return V, F


def _parse_stl(data: bytes) -> tuple[np.ndarray, np.ndarray, list[str]]:
    n_bin = struct.unpack_from("<I", data, 80)[0] if len(data) >= 84 else None
    looks_ascii = data.lstrip()[:5].lower() == b"solid"
    if n_bin is not None and len(data) == 84 + 50 * n_bin:
        arr = np.frombuffer(data, dtype=_STL_RECORD, count=n_bin, offset=84)
        P = arr["v"].reshape(-1, 3).astype(np.float64)
        kind = "binary"
    elif looks_ascii and b"\x00" not in data[:65536]:
        text = data.decode("ascii", errors="replace")
        nums = re.findall(r"(?i)\bvertex\s+(\S+)\s+(\S+)\s+(\S+)", text)
        if not nums:
            if re.search(r"(?i)\bfacet\b", text):
                raise _ParseError("its 'facet' blocks contain no 'vertex' lines")
            raise _ParseError("it contains no triangles ('facet ... vertex' lines)")
        if len(nums) % 3:
            raise _ParseError(
                f"it holds {len(nums):,} 'vertex' lines, which is not a multiple of three "
                "(every facet needs exactly three)"
            )
        try:
            P = np.array(nums, dtype=np.float64)
        except ValueError:
            bad = _first_bad_token([t for row in nums for t in row], float)
            raise _ParseError(f"'{bad}' is not a number") from None
        kind = "ASCII"
    elif n_bin is not None:
        expected = 84 + 50 * n_bin
        if len(data) < expected:
            raise _ParseError(
                f"the file ends early (it looks truncated): a binary STL with {n_bin:,} triangles "
                f"needs {expected:,} bytes, the file has {len(data):,}"
            )
        arr = np.frombuffer(data, dtype=_STL_RECORD, count=n_bin, offset=84)
        P = arr["v"].reshape(-1, 3).astype(np.float64)
        kind = "binary"
        extra = len(data) - expected
        notes_extra = [f"{extra:,} bytes after the last triangle were ignored."]
        V, F = _weld_corners(P)
        return V, F, notes_extra + _stl_note(P.shape[0], V.shape[0], kind)
    else:
        raise _ParseError("it is too short to be a binary STL and is not an ASCII STL")
    V, F = _weld_corners(P)
    return V, F, _stl_note(P.shape[0], V.shape[0], kind)


def _stl_note(n_corners: int, n_vertices: int, kind: str) -> list[str]:
    if n_corners == 0:
        return []
    return [
        f"The {kind} STL file stores every triangle's corners separately: "
        f"{n_corners:,} corners at identical positions were merged into {n_vertices:,} shared "
        "vertices."
    ]


# --------------------------------------------------------------------------------------------
# read_mesh
# --------------------------------------------------------------------------------------------

_GLB_COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_GLB_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _glb_accessor(gltf: dict, binary: bytes, index: int) -> np.ndarray:
    """One accessor of a binary glTF as an array (count, width)."""
    try:
        acc = gltf["accessors"][index]
    except (KeyError, IndexError, TypeError):
        raise _ParseError(f"it refers to data (accessor {index}) that is not in the file")
    if "sparse" in acc:
        raise _ParseError("it uses sparse accessors, which Stylize3D does not read")
    dtype = _GLB_COMPONENTS.get(acc.get("componentType"))
    width = _GLB_WIDTH.get(acc.get("type"))
    if dtype is None or width is None:
        raise _ParseError(f"accessor {index} has an unsupported data type")
    count = int(acc.get("count", 0))
    if "bufferView" not in acc:
        return np.zeros((count, width), dtype=dtype)
    view = gltf["bufferViews"][acc["bufferView"]]
    if view.get("buffer", 0) != 0:
        raise _ParseError("its data lies in an external file (only .glb with embedded data "
                          "can be read)")
    start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
    item = np.dtype(dtype).itemsize * width
    stride = int(view.get("byteStride", 0)) or item
    end = start + stride * (count - 1) + item if count else start
    if end > len(binary) or end > int(view.get("byteOffset", 0)) + int(view["byteLength"]):
        raise _ParseError("it is truncated (its data ends early)")
    raw = np.frombuffer(binary, dtype=np.uint8, count=end - start, offset=start)
    if stride == item:
        return raw.view(dtype).reshape(count, width).copy()
    rows = np.lib.stride_tricks.as_strided(raw, shape=(count, item), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).reshape(count, width)


def _node_matrices(gltf: dict) -> list[tuple[int, np.ndarray]]:
    """(mesh index, 4x4 world matrix) of every node that draws a mesh (scene 0, or all roots)."""
    nodes = gltf.get("nodes", [])

    def local(n: dict) -> np.ndarray:
        if "matrix" in n:
            return np.array(n["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
        M = np.eye(4)
        if "scale" in n:
            M = np.diag(list(map(float, n["scale"])) + [1.0]) @ M
        if "rotation" in n:
            x, y, z, w = map(float, n["rotation"])
            R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                          [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                          [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            T = np.eye(4)
            T[:3, :3] = R
            M = T @ M
        if "translation" in n:
            T = np.eye(4)
            T[:3, 3] = list(map(float, n["translation"]))
            M = T @ M
        return M

    scenes = gltf.get("scenes")
    roots = (scenes[gltf.get("scene", 0)].get("nodes", []) if scenes
             else [i for i in range(len(nodes))
                   if not any(i in n.get("children", []) for n in nodes)])
    out, stack, seen = [], [(int(r), np.eye(4)) for r in reversed(roots)], set()
    while stack:  # depth first, in the file's order
        i, parent = stack.pop()
        if i in seen or not 0 <= i < len(nodes):
            continue
        seen.add(i)
        M = parent @ local(nodes[i])
        if "mesh" in nodes[i]:
            out.append((int(nodes[i]["mesh"]), M))
        stack.extend((int(c), M) for c in reversed(nodes[i].get("children", [])))
    return out


def _parse_glb(data: bytes) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Binary glTF 2.0: the triangles of every mesh the default scene draws, node transforms
    applied, all parts in one mesh (vertices of different primitives are not welded)."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise _ParseError("it does not start with the binary glTF signature (a .gltf text "
                          "file or another format renamed?)")
    version, total = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise _ParseError(f"it is glTF version {version}; only version 2 can be read")
    if total > len(data):
        raise _ParseError("it is truncated (shorter than its header says)")
    pos, js, binary = 12, None, b""
    while pos + 8 <= total:
        length, kind = struct.unpack_from("<I4s", data, pos)
        chunk = data[pos + 8:pos + 8 + length]
        if len(chunk) < length:
            raise _ParseError("it is truncated (a chunk ends early)")
        if kind == b"JSON":
            js = chunk
        elif kind == b"BIN\x00" and not binary:
            binary = chunk
        pos += 8 + length + (-length % 4)
    if js is None:
        raise _ParseError("it has no JSON chunk")
    try:
        gltf = json.loads(js.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise _ParseError("its JSON chunk is damaged")
    used = set(gltf.get("extensionsRequired", []))
    if used:
        raise _ParseError(f"it needs glTF extensions Stylize3D does not read "
                          f"({', '.join(sorted(used))}; e.g. Draco compression)")
    Vs, Fs, n, skipped = [], [], 0, 0
    for mesh_index, M in _node_matrices(gltf):
        for prim in gltf["meshes"][mesh_index].get("primitives", []):
            if prim.get("mode", 4) != 4:
                skipped += 1
                continue
            P = _glb_accessor(gltf, binary, prim["attributes"]["POSITION"]).astype(np.float64)
            if "indices" in prim:
                I = _glb_accessor(gltf, binary, prim["indices"]).astype(np.int64).reshape(-1)
            else:
                I = np.arange(len(P), dtype=np.int64)
            if I.size % 3:
                raise _ParseError("a triangle list has a number of corners that is not a "
                                  "multiple of 3")
            P = P @ M[:3, :3].T + M[:3, 3]
            Vs.append(P)
            Fs.append(I.reshape(-1, 3) + n)
            n += len(P)
    if not Vs:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), []
    notes = []
    if len(Vs) > 1:
        notes.append(f"The file holds {len(Vs)} mesh parts; they were read as one mesh.")
    if skipped:
        notes.append(f"{_plural(skipped, 'part')} drawn as points or lines (not triangles) "
                     "were skipped.")
    return np.vstack(Vs), np.vstack(Fs), notes


_READERS: dict[str, Callable[[bytes], tuple[np.ndarray, np.ndarray, list[str]]]] = {
    ".obj": _parse_obj,
    ".off": _parse_off,
    ".ply": _parse_ply,
    ".stl": _parse_stl,
    ".glb": _parse_glb,
}


def read_mesh(path: str | os.PathLike) -> MeshData:
    """Read a triangle mesh from an OBJ, OFF, PLY, STL or GLB (binary glTF 2.0) file.

    Parameters
    ----------
    path : str or os.PathLike
        The file. Its extension (case-insensitive) picks the format.

    Returns
    -------
    MeshData
        ``V (n, 3) float64``, ``F (m, 3) int64`` (0-based) and ``notes`` (list of plain-language
        remarks about what reading did, such as polygons split into triangles).

    Raises
    ------
    MeshReadError
        With a message for a novice when the file is missing, a folder, of an unsupported type,
        empty, without faces, not parsable as its format, or truncated. NaN coordinates and
        out-of-range indices do *not* raise (see the module docstring); validate the result with
        :func:`algorithms.mesh.validate.validate_mesh`.
    """
    try:
        p = Path(os.fspath(path))
    except TypeError:
        raise MeshReadError(f"{path!r} is not a file name.") from None
    if not p.exists():
        raise MeshReadError(f"The file '{p}' does not exist. Check the name and the folder.")
    if p.is_dir():
        raise MeshReadError(f"'{p}' is a folder, not a mesh file. Choose a file inside it.")
    ext = p.suffix.lower()
    supported = ", ".join(SUPPORTED_READ)
    if not ext:
        raise MeshReadError(
            f"'{p.name}' has no extension, so its format is unknown. Rename it to end in one of "
            f"{supported}."
        )
    if ext not in _READERS:
        hint = ""
        raise MeshReadError(
            f"'{p.name}' is a '{ext}' file, which Stylize3D cannot read. Supported formats: "
            f"{supported}.{hint}"
        )
    fmt = _FORMAT_NAMES[ext]
    try:
        data = p.read_bytes()
    except PermissionError:
        raise MeshReadError(f"'{p}' cannot be opened: permission denied.") from None
    except OSError as exc:
        raise MeshReadError(f"'{p}' cannot be opened: {exc.strerror or exc}.") from None
    if not data.strip():
        raise MeshReadError(f"'{p.name}' is empty: it contains no data.")
    try:
        V, F, notes = _READERS[ext](data)
    except _ParseError as exc:
        msg = str(exc)
        raise MeshReadError(f"'{p.name}' could not be read as {fmt} file: {msg}"
                            + ("" if msg.endswith(("?", ".", "!")) else ".")) from None
    except MemoryError:
        raise MeshReadError(f"'{p.name}' is too large to read into memory.") from None
    except Exception as exc:  # noqa: BLE001 -- never a bare traceback for a bad file
        raise MeshReadError(
            f"'{p.name}' could not be read as {fmt} file: unexpected content "
            f"({type(exc).__name__}: {exc})."
        ) from exc
    V = np.ascontiguousarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    if V.shape[0] == 0:
        raise MeshReadError(
            f"'{p.name}' could not be read as {fmt} file: it contains no vertices."
        )
    if F.shape[0] == 0:
        raise MeshReadError(
            f"'{p.name}' contains {V.shape[0]:,} vertices but no faces (triangles). Stylize3D "
            "works on surface meshes, not point clouds; export the surface with its faces."
        )
    return MeshData(V=V, F=F, notes=list(notes))


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def _face_normals32(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), 0.0)
    return n


def _write_obj(fh: BinaryIO, V: np.ndarray, F: np.ndarray, colors=None) -> None:
    fh.write(b"# Written by Stylize3D\n")
    fh.write(f"# {V.shape[0]} vertices, {F.shape[0]} triangles\n".encode())
    if V.shape[0] and colors is not None:
        rows = np.column_stack([V, colors / 255.0]).ravel().tolist()
        fh.write((("v %r %r %r %.6g %.6g %.6g\n" * V.shape[0]) % tuple(rows)).encode("ascii"))
    elif V.shape[0]:
        fh.write((("v %r %r %r\n" * V.shape[0]) % tuple(V.ravel().tolist())).encode("ascii"))
    if F.shape[0]:
        fh.write((("f %d %d %d\n" * F.shape[0]) % tuple((F + 1).ravel().tolist())).encode("ascii"))


def _write_off(fh: BinaryIO, V: np.ndarray, F: np.ndarray) -> None:
    fh.write(f"OFF\n# Written by Stylize3D\n{V.shape[0]} {F.shape[0]} 0\n".encode())
    if V.shape[0]:
        fh.write((("%r %r %r\n" * V.shape[0]) % tuple(V.ravel().tolist())).encode("ascii"))
    if F.shape[0]:
        fh.write((("3 %d %d %d\n" * F.shape[0]) % tuple(F.ravel().tolist())).encode("ascii"))


def _write_ply(fh: BinaryIO, V: np.ndarray, F: np.ndarray, colors=None) -> None:
    index_type, index_dtype = ("int", "<i4") if V.shape[0] < 2**31 else ("uint", "<u4")
    color_props = ("property uchar red\nproperty uchar green\nproperty uchar blue\n"
                   if colors is not None else "")
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment Written by Stylize3D\n"
        f"element vertex {V.shape[0]}\nproperty double x\nproperty double y\nproperty double z\n"
        f"{color_props}"
        f"element face {F.shape[0]}\nproperty list uchar {index_type} vertex_indices\nend_header\n"
    )
    fh.write(header.encode("ascii"))
    if colors is None:
        fh.write(np.ascontiguousarray(V, dtype="<f8").tobytes())
    else:
        rec = np.empty(V.shape[0], dtype=np.dtype([("p", "<f8", (3,)), ("c", "u1", (3,))]))
        rec["p"] = V
        rec["c"] = colors
        fh.write(rec.tobytes())
    rec = np.empty(F.shape[0], dtype=np.dtype([("c", "u1"), ("i", index_dtype, (3,))]))
    rec["c"] = 3
    rec["i"] = F
    fh.write(rec.tobytes())


def _write_stl(fh: BinaryIO, V: np.ndarray, F: np.ndarray) -> None:
    header = b"Binary STL written by Stylize3D".ljust(80, b" ")
    fh.write(header)
    fh.write(struct.pack("<I", F.shape[0]))
    rec = np.zeros(F.shape[0], dtype=_STL_RECORD)
    with np.errstate(invalid="ignore"):
        rec["normal"] = _face_normals32(V, F)
    rec["v"] = V[F]
    fh.write(rec.tobytes())


def _write_glb(fh: BinaryIO, V: np.ndarray, F: np.ndarray) -> None:
    P = np.ascontiguousarray(V, dtype="<f4")
    # area-weighted vertex normals, unit length (glTF requires unit normals)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.column_stack(
        [np.bincount(F.ravel(), weights=np.repeat(fn[:, k], 3), minlength=V.shape[0])
         for k in range(3)]
    )  # fmt: skip
    ln = np.linalg.norm(N, axis=1)
    bad = ~(ln > 0)
    N[~bad] /= ln[~bad, None]
    N[bad] = (0.0, 0.0, 1.0)
    N = np.ascontiguousarray(N, dtype="<f4")
    I = np.ascontiguousarray(F, dtype="<u4").ravel()
    bin_chunk = P.tobytes() + N.tobytes() + I.tobytes()
    npos = P.nbytes
    gltf = {
        "asset": {"version": "2.0", "generator": "Stylize3D"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "mode": 4}]}
        ],
        "buffers": [{"byteLength": len(bin_chunk)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": npos, "target": 34962},
            {"buffer": 0, "byteOffset": npos, "byteLength": N.nbytes, "target": 34962},
            {"buffer": 0, "byteOffset": 2 * npos, "byteLength": I.nbytes, "target": 34963},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": int(P.shape[0]),
                "type": "VEC3",
                "min": [float(x) for x in P.min(axis=0)],
                "max": [float(x) for x in P.max(axis=0)],
            },
            {"bufferView": 1, "componentType": 5126, "count": int(N.shape[0]), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5125, "count": int(I.size), "type": "SCALAR"},
        ],
    }
    js = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    bin_chunk += b"\x00" * (-len(bin_chunk) % 4)
    total = 12 + 8 + len(js) + 8 + len(bin_chunk)
    fh.write(struct.pack("<4sII", b"glTF", 2, total))
    fh.write(struct.pack("<I4s", len(js), b"JSON"))
    fh.write(js)
    fh.write(struct.pack("<I4s", len(bin_chunk), b"BIN\x00"))
    fh.write(bin_chunk)


_WRITERS: dict[str, Callable[[BinaryIO, np.ndarray, np.ndarray], None]] = {
    ".obj": _write_obj,
    ".off": _write_off,
    ".ply": _write_ply,
    ".stl": _write_stl,
    ".glb": _write_glb,
}


def _check_for_writing(V, F, name: str, ext: str) -> tuple[np.ndarray, np.ndarray]:
    prefix = f"Cannot save '{name}': "
    try:
        V = np.asarray(V, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshWriteError(prefix + f"the vertex positions are not numbers ({exc}).") from None
    try:
        F_arr = np.asarray(F)
        if F_arr.dtype.kind == "f":
            if not np.all(F_arr == np.round(F_arr)):
                raise ValueError("face indices are not whole numbers")
        F = F_arr.astype(np.int64)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MeshWriteError(prefix + f"the face indices are not whole numbers ({exc}).") from None
    if V.ndim != 2 or V.shape[1] != 3:
        raise MeshWriteError(prefix + f"vertex positions must be an (n, 3) array, got {V.shape}.")
    if F.ndim != 2 or F.shape[1] != 3:
        raise MeshWriteError(prefix + f"faces must be an (m, 3) array of triangles, got {F.shape}.")
    if V.shape[0] == 0 or F.shape[0] == 0:
        raise MeshWriteError(prefix + "the mesh is empty (no vertices or no faces).")
    bad = (F < 0) | (F >= V.shape[0])
    if bad.any():
        nbad = int(bad.any(axis=1).sum())
        raise MeshWriteError(
            prefix + f"{_plural(nbad, 'triangle')} refer to vertices that do not exist. "
            "Run 'Clean' or fix the mesh first."
        )
    if ext == ".glb" and not np.isfinite(V).all():
        nbad = int((~np.isfinite(V)).any(axis=1).sum())
        raise MeshWriteError(
            prefix + f"{_plural(nbad, 'vertex', 'vertices')} have NaN or infinite coordinates, "
            "which glTF cannot store. Fix the mesh first."
        )
    return np.ascontiguousarray(V), np.ascontiguousarray(F)


def _new_file_mode() -> int:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except OSError:
        pass
    return 0o644


def _check_colors(colors, n: int, name: str, ext: str) -> np.ndarray:
    prefix = f"Cannot save '{name}' with vertex colours: "
    if ext not in (".ply", ".obj"):
        raise MeshWriteError(prefix + "use a .ply or .obj file (other formats store no "
                             "per-vertex colours).")
    c = np.asarray(colors)
    if c.ndim != 2 or c.shape[0] != n or c.shape[1] not in (3, 4):
        raise MeshWriteError(prefix + f"they must be one RGB colour per vertex ({n}, 3), "
                             f"got {c.shape}.")
    c = c[:, :3]
    if c.dtype.kind == "f":
        if not np.isfinite(c).all() or c.min() < 0 or c.max() > 1:
            raise MeshWriteError(prefix + "float colours must lie in [0, 1].")
        c = np.rint(c * 255.0)
    elif c.min() < 0 or c.max() > 255:
        raise MeshWriteError(prefix + "integer colours must lie in 0..255.")
    return np.ascontiguousarray(c, dtype=np.uint8)


def write_mesh(path: str | os.PathLike, V: np.ndarray, F: np.ndarray, *,
               vertex_colors=None, attributes=None) -> None:
    """Write a triangle mesh atomically (OBJ, OFF, PLY, STL or GLB).

    Parameters
    ----------
    path : str or os.PathLike
        Target file; its extension (case-insensitive) picks the format, see
        :data:`SUPPORTED_WRITE`.
    V : array_like
        ``(n, 3)`` vertex positions (stored as float64; STL/GLB store float32).
    F : array_like
        ``(m, 3)`` 0-based triangle corner indices, all in ``[0, n)``.
    vertex_colors : array_like, optional
        ``(n, 3)`` (or ``(n, 4)``, alpha dropped) colours, ``uint8`` 0..255 or floats in
        [0, 1]; PLY and OBJ only.
    attributes : :class:`~algorithms.mesh.attributes.SurfaceAttributes`, optional
        UVs, materials, normals and vertex colours aligned with ``F``; OBJ only (other formats
        ignore them: :func:`attributes_kept_by` says whether a format keeps them).

    Raises
    ------
    MeshWriteError
        For an unsupported extension, a missing folder, bad arrays, or any failure while
        writing. A file that already existed at ``path`` is then left untouched.

    Notes
    -----
    The data is written to a temporary file next to the target, flushed and ``fsync``-ed, and
    then renamed over the target with :func:`os.replace`, so readers never see a half-written
    file.
    """
    try:
        p = Path(os.fspath(path))
    except TypeError:
        raise MeshWriteError(f"{path!r} is not a file name.") from None
    ext = p.suffix.lower()
    if ext not in _WRITERS:
        raise MeshWriteError(
            f"Cannot save '{p.name}': '{ext or '(no extension)'}' is not a format Stylize3D can "
            f"write. Use one of {', '.join(SUPPORTED_WRITE)}."
        )
    V, F = _check_for_writing(V, F, p.name, ext)
    if (attributes is not None and ext == ".ply" and vertex_colors is None
            and attributes.vertex_colors is not None
            and len(attributes.vertex_colors) == len(V)):
        vertex_colors = attributes.vertex_colors
    if attributes is not None and ext == ".obj" and not attributes.empty:
        from .attributes import obj_text

        if attributes.uv is not None and len(attributes.uv) != len(F):
            raise MeshWriteError(f"Cannot save '{p.name}': its texture coordinates are for "
                                 f"{len(attributes.uv):,} triangles, the mesh has {len(F):,}.")
        data = obj_text(V, F, attributes)
        atomic_write(p, lambda fh: fh.write(data))
        return
    if vertex_colors is None:
        atomic_write(p, lambda fh: _WRITERS[ext](fh, V, F))
    else:
        colors = _check_colors(vertex_colors, V.shape[0], p.name, ext)
        atomic_write(p, lambda fh: _WRITERS[ext](fh, V, F, colors))


def attributes_kept_by(path: str | os.PathLike, attributes=None) -> bool:
    """True when :func:`write_mesh` writes ``attributes`` (UVs, materials, normals, vertex
    colours) to this file's format: OBJ all of them, PLY vertex colours only."""
    ext = Path(os.fspath(path)).suffix.lower()
    if ext == ".obj":
        return True
    if ext == ".ply" and attributes is not None:
        return (attributes.uv is None and attributes.material is None and not attributes.mtllib
                and not attributes.normals and attributes.vertex_colors is not None)
    return False


def atomic_write(path: str | os.PathLike, write: Callable[[BinaryIO], None]) -> None:
    """Write a file atomically: ``write(fh)`` fills a temporary file next to ``path``, which is
    flushed, ``fsync``-ed and renamed over ``path``; on any failure the temporary file is removed,
    an existing file at ``path`` is left unchanged, and :class:`MeshWriteError` says why."""
    p = Path(os.fspath(path))
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise MeshWriteError(f"Cannot save '{p.name}': the folder '{folder}' does not exist.")
    if p.is_dir():
        raise MeshWriteError(f"Cannot save to '{p}': it is a folder.")
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix="." + p.name + ".", suffix=".tmp")
    except OSError as exc:
        raise MeshWriteError(
            f"Cannot save '{p.name}': cannot create files in '{folder}' "
            f"({exc.strerror or exc})."
        ) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        try:
            mode = stat.S_IMODE(os.stat(p).st_mode) if p.exists() else _new_file_mode()
            os.chmod(tmp, mode)
        except OSError:
            pass
        os.replace(tmp, p)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if not isinstance(exc, Exception):
            raise
        detail = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise MeshWriteError(
            f"Saving '{p.name}' failed ({detail or type(exc).__name__}); "
            "any existing file with that name was left unchanged."
        ) from exc
    if sys.platform != "win32":
        try:  # make the rename itself durable; best effort
            dfd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass
