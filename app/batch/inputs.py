"""The inputs of a batch (files, folders searched recursively, globs) and where their results go.

Naming: a result keeps its input's file name, in the same sub-folder of ``OUT_DIR`` as the
input is below the inputs' deepest common folder; so ``lib/a/x.obj`` and ``lib/b/x.obj`` give
``OUT_DIR/a/x.obj`` and ``OUT_DIR/b/x.obj``, and files of one folder land straight in
``OUT_DIR``. A project (``.s3d``) gives a mesh, ``<name>.obj``. Should two inputs still get the
same name (``x.s3d`` next to ``x.obj``), the later one gets ``<name>-<8 hex digits of its
path>.<ext>``.
"""

from __future__ import annotations

import glob
import hashlib
import os
from pathlib import Path

from algorithms.mesh.io import SUPPORTED_READ
from app.batch.jobs import BatchUsageError

#: what a folder or a glob contributes: mesh files and projects
INPUT_SUFFIXES = tuple(SUPPORTED_READ) + (".s3d",)
#: folders a search never enters (the batch's own bookkeeping, hidden folders)
_SKIP_PREFIX = "."


def _is_input(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() in INPUT_SUFFIXES and not p.name.startswith(".")


def _search(folder: Path, out_dir: Path | None) -> list[Path]:
    found = []
    for root, dirs, files in os.walk(folder):
        here = Path(root)
        dirs[:] = sorted(d for d in dirs if not d.startswith(_SKIP_PREFIX)
                         and Path(os.path.abspath(here / d)) != out_dir)
        found += [here / f for f in sorted(files) if _is_input(here / f)]
    return found


def collect_inputs(items, out_dir=None) -> list[Path]:
    """The input files (absolute, symbolic links kept, each once, in the order given; a
    folder's sorted), from files, folders (recursively, mesh and project files only, never
    inside ``out_dir``) and globs. An item that is none of these raises
    :class:`BatchUsageError` (exit status 2)."""
    out = Path(os.path.abspath(out_dir)) if out_dir is not None else None
    seen: dict[Path, None] = {}
    for item in map(str, items):
        p = Path(item)
        if p.is_file():
            found = [p]
        elif p.is_dir():
            found = _search(p, out)
        else:
            matches = sorted(glob.glob(item, recursive=True))
            found = []
            for m in map(Path, matches):
                if m.is_dir():
                    found += _search(m, out)
                elif _is_input(m):
                    found.append(m)
            if not matches:
                raise BatchUsageError(f"{item}: there is no such file or folder, and no file "
                                      "matches it.")
        for f in found:
            seen.setdefault(Path(os.path.abspath(f)), None)
    return list(seen)


def output_names(inputs: list[Path], out_dir) -> list[Path]:
    """The result file of each input (module docstring); refuses a result that would replace
    an input."""
    out_dir = Path(os.path.abspath(out_dir))
    if not inputs:
        return []
    parents = [str(p.parent) for p in inputs]
    try:
        root = Path(os.path.commonpath(parents))
    except ValueError:  # different drives: names only
        root = None
    taken: set[Path] = set()
    outputs = []
    ins = set(inputs)
    for p in inputs:
        rel = Path(p.name) if root is None else p.relative_to(root)
        if rel.suffix.lower() == ".s3d":
            rel = rel.with_suffix(".obj")
        target = out_dir / rel
        if target in taken:
            tag = hashlib.sha256(str(p).encode()).hexdigest()[:8]
            target = target.with_name(f"{target.stem}-{tag}{target.suffix}")
        if target in ins:
            raise BatchUsageError(f"The result of {p} would replace the input itself: choose "
                                  "an output folder that is not the inputs' folder.")
        taken.add(target)
        outputs.append(target)
    return outputs


__all__ = ["INPUT_SUFFIXES", "collect_inputs", "output_names"]
