"""What a mesh file carries besides positions and triangles: texture coordinates (UVs), normals,
materials and vertex colours -- read from OBJ files (PLY: vertex colours), carried through a
method, written back.

:func:`read_mesh` returns positions and triangles only. :func:`read_attributes` reads the rest
of an OBJ file (``vt``, ``vn``, ``mtllib``, ``usemtl``, ``v x y z r g b`` colours) as
:class:`SurfaceAttributes`, one entry per triangle corner, in the order of :func:`read_mesh`'s
triangles (polygons are split by the same fan). A method that keeps the triangles (cubic,
analogies, smoothing, adversarial geometry) keeps them as they are; a subdivision that splits
every triangle in four (Loop, modified butterfly, the network) splits each corner's UV linearly,
so seams stay seams (:meth:`SurfaceAttributes.transferred`); a method that remakes the triangles
(Paparazzi's remeshing, 'Coarsen first') cannot keep them, and the command says so.

Normals are not copied: a moved surface has other normals. When the input had normals the
output gets the new shape's (area-weighted per vertex), so a renderer that needs them has them.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

__all__ = ["SurfaceAttributes", "read_attributes"]


@dataclass
class SurfaceAttributes:
    """Per-corner texture coordinates, materials, vertex colours and whether the file had
    normals, aligned with a triangle array ``F`` of ``m`` faces.

    uv : (m, 3, 2) float64 texture coordinates of each corner, NaN where a corner had none;
        None when the file had no ``vt``.
    material : (m,) int index into ``material_names`` per triangle (-1: none); None if no
        ``usemtl``.
    material_names, mtllib : the ``usemtl`` names and the ``mtllib`` file names, as written.
    normals : the file had ``vn`` lines (the output gets the new shape's normals).
    vertex_colors : (n, 3) float colours in [0, 1] of ``v x y z r g b`` lines, or None.
    """

    uv: np.ndarray | None = None
    material: np.ndarray | None = None
    material_names: list[str] = field(default_factory=list)
    mtllib: list[str] = field(default_factory=list)
    normals: bool = False
    vertex_colors: np.ndarray | None = None

    @property
    def empty(self) -> bool:
        return (self.uv is None and self.material is None and not self.mtllib
                and not self.normals and self.vertex_colors is None)

    def describe(self) -> str:
        """"texture coordinates (UVs), normals, 2 materials, vertex colours" (what there is)."""
        parts = []
        if self.uv is not None:
            parts.append("texture coordinates (UVs)")
        if self.normals:
            parts.append("normals")
        if self.material is not None or self.mtllib:
            k = len(self.material_names)
            parts.append(f"{k} material{'s' if k != 1 else ''}" if k else "a material library")
        if self.vertex_colors is not None:
            parts.append("vertex colours")
        return ", ".join(parts)

    def transferred(self, F0: np.ndarray, n0: int, F_out: np.ndarray, levels: int
                    ) -> "SurfaceAttributes | None":
        """The attributes of ``F_out``, a subdivision of ``(n0, F0)`` by ``levels`` levels of
        any scheme that splits every triangle in four at its edges' new vertices, keeps the old
        vertices' numbers and numbers the new ones after them (Loop, modified butterfly, the
        network) -- whatever order it gives its triangles. Each new vertex's two parents are
        read from ``F_out`` itself (its neighbours among the older vertices), each triangle's
        parent triangle from its corners' parents; a new corner's UV is the mean of its edge's
        two corner UVs in the parent triangle (seams stay seams), and materials follow the
        parent. None when ``F_out`` is not such a subdivision."""
        from .topology import unique_edges

        F0 = np.asarray(F0, dtype=np.int64)
        ns, m, e = [int(n0)], len(F0), len(unique_edges(F0)[0])
        for _ in range(int(levels)):
            ns.append(ns[-1] + e)
            e, m = 2 * e + 3 * m, 4 * m
        T = np.asarray(F_out, dtype=np.int64)
        if len(T) != m or (len(T) and T.max() >= ns[-1]):
            return None
        chain = []  # (parent index, corner derivations) per level, finest first
        for lev in range(int(levels), 0, -1):
            n_prev = ns[lev - 1]
            E = unique_edges(T)[0]
            cross = (E[:, 0] < n_prev) != (E[:, 1] < n_prev)
            new = np.where(E[cross, 0] >= n_prev, E[cross, 0], E[cross, 1])
            old = np.where(E[cross, 0] >= n_prev, E[cross, 1], E[cross, 0])
            order = np.argsort(new, kind="stable")
            new, old = new[order], old[order]
            if len(new) != 2 * (ns[lev] - n_prev) or not (
                    np.array_equal(new[0::2], new[1::2])
                    and np.array_equal(new[0::2], np.arange(n_prev, ns[lev]))):
                return None
            ends = old.reshape(-1, 2)
            der = np.stack([T, T], axis=-1)                   # (m, 3, 2): each corner's parents
            isnew = T >= n_prev
            der[isnew] = ends[T[isnew] - n_prev]
            six = np.sort(der.reshape(len(T), 6), axis=1)
            keep = np.ones_like(six, dtype=bool)
            keep[:, 1:] = six[:, 1:] != six[:, :-1]
            if not (keep.sum(axis=1) == 3).all():
                return None
            key = six[keep].reshape(-1, 3)
            if lev > 1:
                parents, p = np.unique(key, axis=0, return_inverse=True)
                if len(parents) != len(T) // 4:
                    return None
            else:
                ref = np.sort(F0, axis=1)
                rk = (ref[:, 0] * n_prev + ref[:, 1]) * n_prev + ref[:, 2]
                ck = (key[:, 0] * n_prev + key[:, 1]) * n_prev + key[:, 2]
                srt = np.argsort(rk, kind="stable")
                pos = np.searchsorted(rk[srt], ck)
                pos = np.minimum(pos, len(rk) - 1)
                if not (rk[srt][pos] == ck).all():
                    return None
                p = srt[pos]
                parents = F0
            chain.append((np.asarray(p).ravel(), der, T))
            T = parents
        uv, mat, P = self.uv, self.material, F0
        for p, der, T_level in reversed(chain):
            if uv is not None:
                PV, PU = P[p], uv[p]                          # parent corners and their UVs

                def at(v):
                    k = np.argmax(PV == v[:, None], axis=1)
                    return PU[np.arange(len(v)), k]

                uv = np.stack([(at(der[:, c, 0]) + at(der[:, c, 1])) / 2 for c in range(3)],
                              axis=1)
            if mat is not None:
                mat = mat[p]
            P = T_level  # this level's triangles, in the order of uv's rows: the next parents
        return replace(self, uv=uv, material=mat, vertex_colors=None)


#: an OBJ line that carries more than positions and triangles (UVs, normals, materials, or a
#: vertex with colours: six numbers)
_EXTRAS = re.compile(rb"(?m)^[ \t]*(?:(?:vt|vn|usemtl|mtllib)[ \t]|v(?:[ \t]+\S+){6})")

_FACE_TOKEN = re.compile(r"^(-?\d+)(?:/(-?\d*)(?:/(-?\d*))?)?$")


def read_attributes(path: str | os.PathLike, n_vertices: int, n_faces: int
                    ) -> SurfaceAttributes | None:
    """The UVs, materials, normals and vertex colours of an OBJ file, aligned with the
    ``n_faces`` triangles :func:`~algorithms.mesh.io.read_mesh` read from it (None: not an OBJ,
    nothing besides positions and triangles, or triangles that do not line up -- then the
    caller cannot keep them and says so)."""
    p = Path(os.fspath(path))
    if p.suffix.lower() == ".ply":  # PLY: its vertex colours
        from .io import ply_colors

        try:
            got = ply_colors(p.read_bytes())
        except OSError:
            return None
        if got is None or got[0] != "vertex" or len(got[1]) != n_vertices:
            return None
        return SurfaceAttributes(vertex_colors=np.asarray(got[1], dtype=np.float64))
    if p.suffix.lower() != ".obj":
        return None
    try:
        raw = p.read_bytes()
    except OSError:
        return None
    # most meshes carry nothing more: a search in C, not the line-by-line parse below, on every
    # opened file and every batch input
    if _EXTRAS.search(raw) is None:
        return None
    text = raw.decode("utf-8", errors="replace")
    if "\\" in text:
        text = re.sub(r"\\[ \t]*\r?\n", " ", text)
    vt: list[tuple[float, float]] = []
    colors: list[tuple[float, float, float] | None] = []
    corners_vt: list[list[int]] = []
    mats: list[int] = []
    names: list[str] = []
    mtllib: list[str] = []
    current = -1
    has_vn = False
    nv = 0
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line[0] == "#":
            continue
        if "#" in line:
            line = line.split("#", 1)[0].rstrip()
        head, _, rest = line.partition(" ")
        if head == "v":
            nv += 1
            t = rest.split()
            if len(t) >= 6:
                try:
                    colors.append((float(t[3]), float(t[4]), float(t[5])))
                except ValueError:
                    colors.append(None)
            else:
                colors.append(None)
        elif head == "vt":
            t = rest.split()
            try:
                vt.append((float(t[0]), float(t[1]) if len(t) > 1 else 0.0))
            except (ValueError, IndexError):
                vt.append((np.nan, np.nan))
        elif head == "vn":
            has_vn = True
        elif head == "mtllib":
            mtllib.append(rest.strip())
        elif head == "usemtl":
            name = rest.strip()
            if name not in names:
                names.append(name)
            current = names.index(name)
        elif head == "f":
            toks = rest.split()
            ti = []
            for tok in toks:
                m = _FACE_TOKEN.match(tok)
                if m is None:
                    return None
                s = m.group(2)
                if s:
                    k = int(s)
                    ti.append(k - 1 if k > 0 else len(vt) + k)
                else:
                    ti.append(-1)
            if len(ti) < 3:
                continue  # read_mesh skips it too
            for i in range(1, len(ti) - 1):  # the fan read_mesh uses
                corners_vt.append([ti[0], ti[i], ti[i + 1]])
                mats.append(current)
    if len(corners_vt) != n_faces or nv != n_vertices:
        return None
    attrs = SurfaceAttributes(mtllib=mtllib, normals=has_vn, material_names=names)
    if vt and corners_vt:
        idx = np.asarray(corners_vt, dtype=np.int64)
        table = np.asarray(vt, dtype=np.float64).reshape(-1, 2)
        ok = (idx >= 0) & (idx < len(table))
        uv = np.full(idx.shape + (2,), np.nan)
        uv[ok] = table[idx[ok]]
        attrs.uv = uv
    if names:
        attrs.material = np.asarray(mats, dtype=np.int64)
    if colors and all(c is not None for c in colors):
        attrs.vertex_colors = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
    return None if attrs.empty else attrs


def obj_text(V: np.ndarray, F: np.ndarray, attrs: SurfaceAttributes) -> bytes:
    """An OBJ file of ``(V, F)`` with ``attrs`` (their triangle counts must agree): mtllib,
    positions (with colours), UVs (one per distinct corner value), the new shape's vertex
    normals when the input had normals, and faces grouped by ``usemtl`` in their order."""
    from .operators import vertex_normals

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    out = ["# Written by Stylize3D", f"# {len(V)} vertices, {len(F)} triangles"]
    out += [f"mtllib {m}" for m in attrs.mtllib]
    if attrs.vertex_colors is not None and len(attrs.vertex_colors) == len(V):
        rows = np.column_stack([V, attrs.vertex_colors])
        out.append(_lines("v %r %r %r %.6g %.6g %.6g", rows))
    else:
        out.append(_lines("v %r %r %r", V))
    vt_idx = None
    if attrs.uv is not None and len(attrs.uv) == len(F):
        flat = attrs.uv.reshape(-1, 2)
        has = np.isfinite(flat).all(axis=1)
        table, inv = np.unique(flat[has], axis=0, return_inverse=True)
        vt_idx = np.full(len(flat), -1, dtype=np.int64)
        vt_idx[has] = inv.ravel()
        vt_idx = vt_idx.reshape(-1, 3)
        out.append(_lines("vt %r %r", table))
    if attrs.normals:
        N = vertex_normals(V, F)
        out.append(_lines("vn %.9g %.9g %.9g", N))
    mat = attrs.material if attrs.material is not None and len(attrs.material) == len(F) \
        else None
    # the faces, run by run of one material, formatted by the whole run at once
    t_ok = vt_idx is not None and (vt_idx >= 0).all()
    if vt_idx is not None and not t_ok:
        t_ok = False  # some corners without UV: those faces are written one by one below
    runs = [(0, len(F), -1)] if mat is None else [
        (int(a), int(b), int(mat[a])) for a, b in zip(
            np.r_[0, np.flatnonzero(np.diff(mat)) + 1],
            np.r_[np.flatnonzero(np.diff(mat)) + 1, len(F)], strict=True)]
    for a, b, mid in runs:
        if mat is not None and mid >= 0:
            out.append(f"usemtl {attrs.material_names[mid]}")
        if a == b:
            continue
        Fv = F[a:b] + 1
        if vt_idx is None or t_ok:
            cols = [Fv]
            if vt_idx is not None:
                cols.append(vt_idx[a:b] + 1)
            if attrs.normals:
                cols.append(Fv)
            corner = "/".join(["%d"] * len(cols)) if vt_idx is not None or not attrs.normals \
                else "%d//%d"
            rows = np.stack(cols, axis=-1).reshape(b - a, -1)
            fmt = f"f {corner} {corner} {corner}"
            out.append(_lines(fmt, rows))
            continue
        for f in range(a, b):
            corners = []
            for k in range(3):
                v = F[f, k] + 1
                t = "" if vt_idx[f, k] < 0 else str(vt_idx[f, k] + 1)
                n = str(v) if attrs.normals else ""
                corners.append(f"{v}/{t}/{n}" if n else (f"{v}/{t}" if t else str(v)))
            out.append("f " + " ".join(corners))
    return ("\n".join(x for x in out if x) + "\n").encode("utf-8")


def _lines(fmt: str, rows: np.ndarray) -> str:
    """``fmt % row`` for every row, joined by newlines, in one formatting call."""
    rows = np.asarray(rows)
    if not len(rows):
        return ""
    return ("\n".join([fmt] * len(rows))) % tuple(rows.ravel().tolist())
