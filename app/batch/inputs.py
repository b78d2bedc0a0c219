"""The inputs of a batch (files, folders searched recursively, globs) and where their results go.

Naming: a result keeps its input's file name, in the same sub-folder of ``OUT_DIR`` as the
input is below its **own root**: the folder given as INPUT (``lib`` for ``lib/a/x.obj`` found in
``lib``), the folder of a file given by name, or the folder a glob starts from (``lib`` for
``lib/**/*.obj``). So ``lib/a/x.obj`` and ``lib/b/x.obj`` give ``OUT_DIR/a/x.obj`` and
``OUT_DIR/b/x.obj``, and adding an input from another folder moves no result (before, results
were placed below the deepest folder common to all inputs, so one more input could move every
result and make a resumed batch run everything again; issue 39). A project (``.s3d``) gives a
mesh, ``<name>.obj``. Should two inputs still get the same name (``x.s3d`` next to ``x.obj``,
two roots with the same file), the later one gets ``<name>-<8 hex digits of its path>.<ext>``.
:func:`output_names` without roots keeps the common-folder rule (scripts that call it so).

Searching a folder never enters hidden folders, the batch's own output folder, nor the output
folder of an earlier batch (a folder holding ``.batch/`` or ``batch-report.jsonl``): results are
never taken as inputs.
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


def _is_batch_output(folder: Path) -> bool:
    """A folder an earlier batch wrote its results to (its bookkeeping is there)."""
    return ((folder / ".batch").is_dir() or (folder / "batch-report.jsonl").is_file()
            or any(folder.glob(".batch-shard-*")) or any(folder.glob("batch-report.shard-*")))


def _search(folder: Path, out_dir: Path | None) -> list[Path]:
    found = []
    for root, dirs, files in os.walk(folder):
        here = Path(root)
        dirs[:] = sorted(d for d in dirs if not d.startswith(_SKIP_PREFIX)
                         and Path(os.path.abspath(here / d)) != out_dir
                         and not _is_batch_output(here / d))
        found += [here / f for f in sorted(files) if _is_input(here / f)]
    return found


def _in_results(path: Path, root: Path, out_dir: Path | None) -> bool:
    """Whether a glob's match lies in this batch's or an earlier batch's output folder (below
    the glob's root)."""
    path, root = Path(os.path.abspath(path)), Path(os.path.abspath(root))
    for folder in path.parents:
        if folder == root or root not in folder.parents:
            break
        if folder == out_dir or _is_batch_output(folder):
            return True
    return False


def _glob_root(pattern: str) -> Path:
    """The folder a glob starts from: its leading parts without wildcards."""
    parts = []
    for part in Path(pattern).parts:
        if glob.has_magic(part):
            break
        parts.append(part)
    return Path(*parts) if parts else Path(".")


def collect_inputs(items, out_dir=None) -> list[Path]:
    """The input files (absolute, symbolic links kept, each once, in the order given; a
    folder's sorted), from files, folders (recursively, mesh and project files only, never
    inside ``out_dir`` or an earlier batch's output folder) and globs. An item that is none of
    these raises :class:`BatchUsageError` (exit status 2)."""
    return [p for p, _root in collect_inputs_with_roots(items, out_dir)]


def collect_inputs_with_roots(items, out_dir=None) -> list[tuple[Path, Path]]:
    """:func:`collect_inputs` with each input's root (module docstring), both absolute: what
    :func:`output_names` places the results by."""
    out = Path(os.path.abspath(out_dir)) if out_dir is not None else None
    seen: dict[Path, Path] = {}
    for item in map(str, items):
        p = Path(item)
        if p.is_file():
            found, root = [p], p.parent
        elif p.is_dir():
            found, root = _search(p, out), p
        else:
            root = _glob_root(item)
            matches = sorted(glob.glob(item, recursive=True))
            found = []
            for m in map(Path, matches):
                if _in_results(m, root, out):
                    continue
                if m.is_dir():
                    found += _search(m, out)
                elif _is_input(m):
                    found.append(m)
            if not matches:
                raise BatchUsageError(f"{item}: there is no such file or folder, and no file "
                                      "matches it.")
        for f in found:
            seen.setdefault(Path(os.path.abspath(f)), Path(os.path.abspath(root)))
    return list(seen.items())


def output_names(inputs: list[Path], out_dir, roots: list[Path] | None = None, *,
                 fmt: str | None = None, name: str | None = None,
                 command: str = "") -> list[Path]:
    """The result file of each input (module docstring): below each input's own root when
    ``roots`` are given (:func:`collect_inputs_with_roots`), else below the inputs' deepest
    common folder; ``fmt`` (``"ply"``, ...) the results' format instead of the inputs', ``name``
    a file-name template (``"{stem}_{command}"``; fields ``stem``, ``command``, ``parent``).
    Refuses a result that would replace an input, and a template that is not a file name."""
    out_dir = Path(os.path.abspath(out_dir))
    if name is not None:
        try:
            probe = name.format(stem="x", command="c", parent="p")
        except (KeyError, IndexError, ValueError) as e:
            raise BatchUsageError(f"--name {name!r} is not a usable template ({e}); its fields "
                                  "are {stem}, {command} and {parent}.") from None
        if not probe or "/" in probe or os.sep in probe or probe in (".", ".."):
            raise BatchUsageError(f"--name {name!r} must make a file name (no folders).")
    if not inputs:
        return []
    common = None
    if roots is None:
        try:
            common = Path(os.path.commonpath([str(p.parent) for p in inputs]))
        except ValueError:  # different drives: names only
            common = None
    taken: set[Path] = set()
    outputs = []
    ins = set(inputs)
    for k, p in enumerate(inputs):
        root = roots[k] if roots is not None else common
        try:
            rel = Path(p.name) if root is None else p.relative_to(root)
        except ValueError:  # not below its root (a symbolic link's target): the name only
            rel = Path(p.name)
        if rel.suffix.lower() == ".s3d":
            rel = rel.with_suffix(".obj")
        if fmt:
            rel = rel.with_suffix("." + fmt.lower().lstrip("."))
        if name is not None:
            rel = rel.with_name(name.format(stem=rel.stem, command=command,
                                            parent=p.parent.name) + rel.suffix)
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


def read_input_list(path) -> list[str]:
    """The INPUTs of a ``--from-list`` file: one per line, ``#`` starts a comment, blank lines
    skipped, relative paths relative to the file's folder."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise BatchUsageError(f"--from-list {path}: the list cannot be read ({e}).") from None
    items = []
    for line in lines:
        line = line.split("#", 1)[0].strip()
        if line:
            p = Path(os.path.expanduser(line))
            items.append(str(p if p.is_absolute() else path.parent / p))
    return items


def excluded(path: Path, root: Path, patterns) -> bool:
    """Whether ``--exclude`` GLOBs leave ``path`` out: its path below ``root`` or its file
    name matches one."""
    import fnmatch

    try:
        rel = path.relative_to(root).as_posix()
    except ValueError:
        rel = path.name
    return any(fnmatch.fnmatch(rel, g) or fnmatch.fnmatch(path.name, g) for g in patterns)


__all__ = ["INPUT_SUFFIXES", "collect_inputs", "collect_inputs_with_roots", "excluded",
           "output_names", "read_input_list"]


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` (1 <= I <= N) of ``--shard``."""
    try:
        i, n = (int(x) for x in str(text).split("/"))
    except ValueError:
        raise BatchUsageError(f"--shard takes I/N (e.g. 2/8: the second of 8 shards), not "
                              f"{text!r}.") from None
    if not (n >= 1 and 1 <= i <= n):
        raise BatchUsageError(f"--shard {text}: I must be between 1 and N (N at least 1).")
    return i, n


def in_shard(path: Path, root: Path, shard: tuple[int, int]) -> bool:
    """Whether an input belongs to shard ``(I, N)``: by a hash of its path below its root, so
    every input is in exactly one shard, whatever the machine, and adding inputs moves no
    other input to another shard (array jobs: one shard per task)."""
    import hashlib

    i, n = shard
    try:
        rel = Path(path).relative_to(root).as_posix()
    except ValueError:
        rel = Path(path).name
    h = int.from_bytes(hashlib.sha1(rel.encode("utf-8")).digest()[:8], "big")
    return h % n == i - 1


def shard_names(shard: tuple[int, int] | None) -> tuple[str, str]:
    """(report file name, state folder name) of a shard: each shard has its own, so that N
    shards can write into one output folder at the same time."""
    if shard is None:
        return "batch-report.jsonl", ".batch"
    i, n = shard
    return f"batch-report.shard-{i}-of-{n}.jsonl", f".batch-shard-{i}-of-{n}"
