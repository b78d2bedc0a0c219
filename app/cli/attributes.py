"""The input's UVs, materials, normals and vertex colours in a command's result (issue 39
item 5): kept where the method keeps or splits the triangles, else said to be dropped (stderr,
``--json``'s ``surface_attributes``, batch records). See :mod:`algorithms.mesh.attributes`."""

from __future__ import annotations

import argparse
from pathlib import Path

from app.crashlog import say

#: what :func:`write_result` did with the input's UVs, normals, materials and colours (this
#: command's last output): ``{"found", "kept", "note"}``; :func:`print_json` adds it
LAST: dict = {}


def carried_attributes(input_path, data, how: str, output, levels: int = 0, F_out=None):
    """``(attributes to write or None, status)`` for a result of ``data`` (the mesh as read)
    written to ``output``: ``how`` is "same" (the method keeps the triangles), "subdivided"
    (``F_out`` splits each triangle in four, ``levels`` times) or, when they cannot be kept,
    why (a clause for the note). ``status`` is ``{}`` when the input carries nothing besides
    positions and triangles, else ``{"found": what, "kept": bool, "note": what happened}``;
    nothing is dropped without a note (issue 39, item 5)."""
    from algorithms.mesh.attributes import read_attributes
    from algorithms.mesh.io import attributes_kept_by
    from app.project import is_project_path

    if input_path is None or is_project_path(input_path):
        return None, {}
    attrs = read_attributes(input_path, len(data.V), len(data.F))
    name = Path(input_path).name
    if attrs is None:
        if _has_surface_extras(input_path):
            return None, {"found": "texture coordinates, normals or materials", "kept": False,
                          "note": f"{name}'s texture coordinates, normals and materials were "
                                  "not kept: cleaning renumbered its triangles."}
        return None, {}
    found = attrs.describe()
    if how == "same":
        out, extra = attrs, ""
    elif how == "subdivided":
        out = attrs.transferred(data.F, len(data.V), F_out, levels)
        if out is None:
            return None, {"found": found, "kept": False,
                          "note": f"{name}'s {found} were dropped: the result does not split "
                                  "each of its triangles in four."}
        extra = (" (vertex colours were not subdivided: dropped)"
                 if attrs.vertex_colors is not None else "")
        if out.empty:
            return None, {"found": found, "kept": False,
                          "note": f"{name}'s {found} were dropped: subdivision does not carry "
                                  "vertex colours."}
    else:
        return None, {"found": found, "kept": False,
                      "note": f"{name}'s {found} were dropped: {how}."}
    if not attributes_kept_by(output, out):
        return None, {"found": found, "kept": False,
                      "note": f"{name}'s {found} were not written: {Path(output).suffix} files "
                              "cannot hold them (write .obj to keep them)."}
    normals = " (normals: the new shape's)" if attrs.normals else ""
    return out, {"found": found, "kept": True, "note": f"kept {name}'s {found}{normals}{extra}."}


def _has_surface_extras(path) -> bool:
    import re

    p = Path(path)
    if p.suffix.lower() != ".obj":
        return False
    try:
        head = p.read_bytes()
    except OSError:
        return False
    return re.search(rb"(?m)^[ \t]*(vt|vn|usemtl|mtllib)[ \t]", head) is not None


def write_result(args: argparse.Namespace, output, V, F, data, how: str = "same",
                 levels: int = 0) -> dict:
    """Write a method's result with what the input carries (UVs, materials, normals, vertex
    colours) where the method keeps or subdivides its triangles, and say what happened to them
    (stderr; ``--json`` gets ``surface_attributes``). Returns the status."""
    from algorithms.mesh import write_mesh

    attrs, status = carried_attributes(getattr(args, "mesh", None), data, how, output, levels,
                                       F_out=F)
    write_mesh(output, V, F, attributes=attrs)
    LAST.clear()
    LAST.update(status)
    if status and not getattr(args, "json", False) and not getattr(args, "quiet", False):
        say(f"stylize3d: {status['note']}")
    return status


def reset() -> None:
    """Forget the last command's status (each command starts without one)."""
    LAST.clear()
