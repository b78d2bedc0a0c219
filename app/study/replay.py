"""Re-run a session's logged runs headless and check their result hashes (Qt-free).

For every run that finished (a ``run`` event followed by its ``result`` with status ``done``),
the input state saved by the session (``<log>_files/states/*.npz``) is loaded, the panel's recipe
(:mod:`app.recipes`) is run with the logged Params and options, and the hash of the result is
compared with the logged one.

Determinism: the recipes of Smooth and Cubic are deterministic (sparse direct solves and
fixed-order iterations): on the same machine with the same library versions they reproduce the
hash exactly. Other machines or BLAS thread counts can change the last bits of floating-point
sums; then the hash differs and the report gives the largest vertex difference (relative to the
bounding-box diagonal) so a reader can tell round-off from a real difference. Panels without a
recipe (and runs whose input state was not saved) are listed as not replayable, with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .log import read_log, state_hash
from .protocol import StudyError


@dataclass
class ReplayedRun:
    index: int
    task: str | None
    method: str
    status: str  # "match" | "mismatch" | "not replayable" | "failed"
    reason: str = ""
    max_difference: float | None = None  # relative to the bbox diagonal, when it can be measured
    output: str | None = None


@dataclass
class ReplayReport:
    log: str
    runs: list[ReplayedRun] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def counts(self) -> dict:
        out = {}
        for r in self.runs:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def to_dict(self) -> dict:
        return {"log": self.log, "counts": self.counts, "warnings": self.warnings,
                "runs": [r.__dict__ for r in self.runs]}


def files_dir(log_path) -> Path:
    p = Path(log_path).with_suffix("")
    return p.parent / (p.name + "_files")


def load_state(path):
    """A MeshState saved by the session (V, F, ``field_*``, handles)."""
    from app.document import MeshState

    with np.load(path, allow_pickle=False) as z:
        fields = {k[len("field_"):]: z[k] for k in z.files if k.startswith("field_")}
        state = MeshState.make(z["V"], z["F"], fields)
        if "handle_ids" in z.files:
            handles = tuple((int(v), tuple(float(x) for x in p))
                            for v, p in zip(z["handle_ids"], z["handle_pos"]))
            from dataclasses import replace

            state = replace(state, handles=handles)
    return state


def replay(log_path, out_dir=None) -> ReplayReport:
    """Re-run every finished run of a log (module docstring). ``out_dir``: write each replayed
    result there as ``<n>_<task>_<method>.obj``."""
    from algorithms.errors import Stylize3DError
    from app.recipes import RECIPES, run_recipe

    data = read_log(log_path)
    report = ReplayReport(str(log_path), warnings=list(data.warnings))
    base = files_dir(log_path)
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
    pending: dict[str, dict] = {}
    n = 0
    for ev in data.events:
        a = ev.get("action")
        if a == "run":
            pending[ev.get("method", "?")] = ev
            continue
        if a != "result" or ev.get("status") != "done":
            continue
        method = ev.get("method", "?")
        run = pending.pop(method, None)
        n += 1
        rr = ReplayedRun(n, ev.get("task"), method, "not replayable")
        report.runs.append(rr)
        if method not in RECIPES:
            rr.reason = f"the {method} panel has no headless recipe yet"
            continue
        if run is None or not run.get("input_file"):
            rr.reason = "its input state was not saved in the log's folder"
            continue
        src = base / run["input_file"]
        if not src.is_file():
            rr.reason = f"its input state {src} is missing"
            continue
        try:
            before = load_state(src)
            last = run_recipe(method, before, run.get("params", {}), run.get("options", {}))
        except Stylize3DError as e:
            rr.status, rr.reason = "failed", str(e)
            continue
        if last is None:
            rr.status, rr.reason = "failed", "the method produced no result"
            continue
        after = before.with_positions(last.V)
        h = state_hash(after.V, after.F, after.fields, after.handles)
        rr.status = "match" if h == ev.get("result_hash") else "mismatch"
        res_file = ev.get("result_file")
        if rr.status == "mismatch":
            rr.reason = "the result differs from the logged one"
            if res_file and (base / res_file).is_file():
                logged = load_state(base / res_file)
                if logged.V.shape == after.V.shape:
                    diag = float(np.linalg.norm(np.ptp(logged.V, axis=0))) or 1.0
                    rr.max_difference = float(np.abs(logged.V - after.V).max()) / diag
        if out_dir is not None:
            from algorithms.mesh import write_mesh

            dest = out_dir / f"{n:03d}_{rr.task or 'none'}_{method.replace(' ', '_')}.obj"
            write_mesh(dest, after.V, after.F)
            rr.output = str(dest)
    if not report.runs:
        report.warnings.append("The log has no finished runs to replay.")
    return report


def replay_or_raise(log_path, out_dir=None) -> ReplayReport:
    """:func:`replay`, with a plain error for a log that cannot be read at all."""
    if not Path(log_path).exists():
        raise StudyError(f"There is no session log at {log_path}.")
    return replay(log_path, out_dir)
