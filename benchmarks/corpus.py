"""Every method's command at its defaults on a corpus of real meshes (issue 38).

Runs ``stylize3d METHOD MESH -o OUT --json`` for every (mesh, method) pair in worker processes
with a time limit, and sorts each run into one class:

  result        exit 0, a visible, artefact-free result (for the methods that move vertices:
                the largest move is at least 0.2 % of the bounding-box diagonal)
  refused       exit 2-6 with a message (the message is kept)
  advice works  refused, and the advice in the message works: the message names Clean and the
                same command with --clean gives a result, or it names a setting with a value
                ("ask for fewer: --m 140") and the command with that setting gives one (then
                classified like any result); or a result with no visible effect whose --json
                ``note`` says which setting to raise, with a value ("--step-size 1e-04"), and
                the command with it (twice at most) gives a visible result
  no effect     exit 0, but a method that deforms moved no vertex by 0.2 % of the diagonal
                (also after its advice, if it gave one)
  artefact      exit 0, but the result has NaN coordinates, triangles it made degenerate
                (area below 1e-12 of the diagonal squared where the input's was not), more
                than 0.1 % of its triangles folded over (turned back against at least two
                neighbours: their normals more than 120 degrees apart, 60 more than in the
                input; same triangles),
                self-intersections the input did not have (of a result with the input's
                triangles: the intersecting pairs that did not intersect in the input, except
                pairs both within two vertex rings of the input's own crossings, where a move
                shifts the crossing line onto neighbouring triangles; of a subdivided result:
                the intersecting pairs whose parent triangles did not intersect in the input,
                as each input crossing comes back split many times; measured where input and
                result have at most 300,000 triangles), or spikes (a vertex
                moved more than the mean of its neighbours' moves by over twice the length of
                its edges and over 1 % of the diagonal)
  substitution  exit 0, and the command's --json says another method ran (``fallback``);
                it is said, so it is not silent, but it counts against the method
  over time     more than 60 s on a mesh of at most 100,000 triangles, or killed at --timeout
  crash         exit 70 (an unexpected error: a defect), death by a signal, or "Traceback"

The thresholds were set before the first run, from what a person sees (0.2 % of the diagonal is
about one pixel at the window's size), not tuned on this corpus.

Each run and its measurement happen in a child process (``--one``), so a crash in a method or
in the measurement (libigl's intersection test) costs one cell, not the run. Writes
docs/results/corpus.md (one row per mesh, one column per method, with the date, the machine
and the commit) and one contact sheet per method, docs/images/corpus_<method>.png (the
result, or the input with the class when there is no result).

The corpus is not in the repository: give its folder with --corpus or STYLIZE3D_CORPUS.
docs/results/corpus_records.json holds the records of the page's last run: rerun one method
after a change with ``--methods NAME --merge docs/results/corpus_records.json --json FILE``.

Usage: .venv/bin/python benchmarks/corpus.py --corpus DIR [--extra DIR] [--methods a,b]
       [--meshes name,name] [--jobs 2] [--timeout 300] [--no-pictures] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SUFFIXES = {".obj", ".ply", ".off", ".stl", ".glb"}
#: method -> (command line after ``stylize3d``, output suffix or None, moves vertices)
METHODS: dict[str, tuple[list[str], str | None, bool]] = {
    "cubic": (["cubic"], ".obj", True),
    "analogy": (["analogy"], ".obj", True),
    "smooth": (["smooth"], ".obj", True),
    "multigrid": (["multigrid-info"], None, False),
    "coarsen": (["coarsen"], ".npz", False),
    "subdivide": (["subdivide"], ".obj", False),
    "paparazzi-guided": (["paparazzi", "--filter", "guided"], ".obj", True),
    "paparazzi-quantize": (["paparazzi", "--filter", "quantize"], ".obj", True),
    "paparazzi-slic": (["paparazzi", "--filter", "slic"], ".obj", True),
    "paparazzi-l0": (["paparazzi", "--filter", "l0"], ".obj", True),
    "adversary": (["adversary"], ".json", False),
}
#: the page's note when Paparazzi's filters were not among the methods run
PAPARAZZI_ELSEWHERE = (
    "Paparazzi's filters are not in this table: at the command line's 1000 iterations one run "
    "takes 0.1-4 minutes even on a mesh of a few hundred vertices. They are measured filter by "
    "filter, each against remeshing alone, by `benchmarks/paparazzi_effects.py --corpus`: see "
    "[results/paparazzi.md](paparazzi.md#on-the-corpus-issue-38).")
SHORT = {"result": "ok", "advice works": "ok*", "refused": "R", "no effect": "-",
         "artefact": "X", "substitution": "S", "over time": "T", "crash": "C!"}
VISIBLE = 2e-3       # of the diagonal
SPIKE = 1e-2         # of the diagonal
FOLDS = 1e-3         # share of triangles
SLOW_S = 60.0        # seconds, meshes of at most SLOW_FACES triangles
SLOW_FACES = 100_000
#: self-intersections are measured on results and inputs of at most this many triangles (a
#: result with the input's triangles at 124k, ogre's, hid 89 crossings under the old 100k cap)
CROSSING_FACES = 300_000


# ---------------------------------------------------------------------------- one run (child)
def _command(method: str, mesh: Path, out: Path, clean: bool, extra=()) -> list[str]:
    argv, suffix, _ = METHODS[method]
    cmd = [sys.executable, "-m", "app", *argv, str(mesh), "--json"]
    if suffix is not None:
        cmd += ["-o", str(out), "--overwrite"]
    if clean:
        cmd.append("--clean")
    return cmd + list(extra)


#: a setting with its value named in a refusal ("ask for fewer: --m 140") or in a result's
#: advice ("--step-size 1e-04")
ADVICE_FLAG = re.compile(r"(--[a-z][a-z-]*)[ =](\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)")


def advised_setting(message: str) -> list[str]:
    """``[flag, value, ...]`` of the first setting a refusal's message names with a value, and
    of the settings named right after it ("--m 1750 --k 10"), or []."""
    hit = ADVICE_FLAG.search(message or "")
    out: list[str] = []
    while hit:
        out += [hit.group(1), hit.group(2)]
        rest = message[hit.end():]
        nxt = ADVICE_FLAG.match(rest.lstrip())
        if not nxt or not rest[:len(rest) - len(rest.lstrip())].isspace():
            break
        hit = ADVICE_FLAG.search(message, hit.end() + (len(rest) - len(rest.lstrip())))
    return out


def merge_settings(extra: list[str], advice: list[str]) -> list[str]:
    """``extra`` (``[flag, value, ...]``) with the settings of ``advice`` added, or their values
    replaced where ``extra`` already names the flag."""
    pairs = dict(zip(extra[::2], extra[1::2]))
    pairs.update(zip(advice[::2], advice[1::2]))
    return [x for kv in pairs.items() for x in kv]


def _last_json(text: str) -> dict:
    """The last JSON object printed (one line, or indented over several)."""
    lines = text.splitlines(keepends=True)
    for k in range(len(lines) - 1, -1, -1):
        if lines[k].startswith("{"):
            try:
                value = json.loads("".join(lines[k:]))
            except ValueError:
                try:
                    value = json.loads(lines[k])
                except ValueError:
                    continue
            if isinstance(value, dict):
                return value
    return {}


def _fallback(record) -> bool:
    """Whether a command's --json (or any object or list in it) says ``"fallback": true``."""
    if isinstance(record, list):
        return any(_fallback(item) for item in record)
    if not isinstance(record, dict):
        return False
    return bool(record.get("fallback")) or any(_fallback(v) for v in record.values())


def _folds_made(V0, V, F) -> np.ndarray:
    """(m,) bool: triangles the method folded over (same triangles ``F`` before and after):
    :func:`algorithms.mesh.damage.folded_triangles`, the definition the smoothing flows keep
    from making too."""
    from algorithms.mesh.damage import folded_triangles

    return folded_triangles(V0, V, F)


def _measure(mesh: Path, out: Path, clean: bool, moves: bool) -> dict:
    """Effect and artefact figures of a result (module docstring)."""
    from algorithms.mesh import read_mesh
    from algorithms.mesh.damage import COLLAPSED_AREA, collapsed_triangles
    from algorithms.mesh.operators import face_areas
    from algorithms.mesh.validate import clean_mesh

    src = read_mesh(mesh)
    V0, F0 = src.V, src.F
    if clean:
        c = clean_mesh(V0, F0)
        V0, F0 = c.V, c.F
    res = read_mesh(out)
    V, F = res.V, res.F
    diag = float(np.linalg.norm(np.ptp(V0, axis=0))) or 1.0
    m: dict = {"faces_in": int(len(F0)), "faces_out": int(len(F))}
    if not np.isfinite(V).all():
        m["nan"] = True
        return m
    a0 = face_areas(V0, F0)
    a = face_areas(V, F)
    tiny = COLLAPSED_AREA * diag * diag
    same = V.shape == V0.shape and np.array_equal(F, F0)
    if same:
        m["degenerate_made"] = int(collapsed_triangles(V0, V, F).sum())
        d = np.linalg.norm(V - V0, axis=1)
        m["moved"] = float(d.max() / diag)
        m["folds_made"] = int(_folds_made(V0, V, F).sum())
        # spikes: a vertex's move against the mean move of its neighbours
        import scipy.sparse as sp

        n = len(V)
        E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        A = sp.csr_matrix((np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                          shape=(n, n))
        deg = np.asarray(A.sum(axis=1)).ravel()
        D = V - V0
        mean_nb = (A @ D) / np.maximum(deg, 1)[:, None]
        # local size: the mean length of the vertex's edges in the input
        length = np.linalg.norm(V0[E[:, 0]] - V0[E[:, 1]], axis=1)
        ring = (np.bincount(E[:, 0], length, n) + np.bincount(E[:, 1], length, n)) / np.maximum(
            np.bincount(E[:, 0], minlength=n) + np.bincount(E[:, 1], minlength=n), 1)
        off = np.linalg.norm(D - mean_nb, axis=1)
        spiky = (deg > 0) & (off > 2.0 * ring)
        m["spike"] = float(off[spiky].max() / diag) if spiky.any() else 0.0
    else:
        from scipy.spatial import cKDTree

        m["degenerate_made"] = max(int((a <= tiny).sum()) - int((a0 <= tiny).sum()), 0)
        dist, _ = cKDTree(V0).query(V)
        m["moved"] = float(dist.max() / diag)  # to the nearest input vertex (an upper bound)
    if len(F) <= CROSSING_FACES and len(F0) <= CROSSING_FACES:
        from algorithms.mesh.intersections import (crossings_away_from,
                                                   intersecting_pairs_here,
                                                   new_crossing_pairs_away, pairs_not_in)

        try:
            P0, P = intersecting_pairs_here(V0, F0), intersecting_pairs_here(V, F)
            m["intersections_in"], m["intersections_out"] = len(P0), len(P)
            k = int(round(np.log(max(len(F), 1) / len(F0)) / np.log(4))) if len(F0) else 0
            if k >= 1 and len(F) == len(F0) * 4 ** k:
                # a subdivided result: its triangles split the input's, so the input's own
                # crossings come back many times; count those whose parents did not cross,
                # away from the input's own crossings (as for the methods that move vertices)
                # and not shown by the input's own surface split as many times (coplanar
                # slivers of a CAD part that the exact test reports as touching)
                from algorithms.subdivision.inference import midpoints_in_refine_numbering
                from algorithms.subdivision.topology import refine

                used, FL = np.unique(np.asarray(F0, np.int64), return_inverse=True)
                VL, FL = np.asarray(V0, np.float64)[used], FL.reshape(-1, 3)
                for _ in range(k):
                    F1 = refine(FL, len(VL))
                    VL, FL = midpoints_in_refine_numbering(VL, FL, F1), F1
                own = intersecting_pairs_here(VL, FL) if np.array_equal(FL, F) else P[:0]
                m["intersections_made"] = len(pairs_not_in(
                    new_crossing_pairs_away(P, k, F0, P0), own))
            elif same:
                # the same triangles moved: where the input already crossed itself, the
                # crossing line shifts onto neighbouring triangles; count the others
                m["intersections_made"] = crossings_away_from(P, F, P0)
        except Exception as e:  # noqa: BLE001 - a measurement that fails is reported, not fatal
            m["intersections_error"] = str(e)[:120]
    m["moves"] = moves
    return m


def _classify(rc: int | None, seconds: float, stderr: str, record: dict, m: dict | None,
              moves: bool, faces: int, timeout: float) -> tuple[str, str]:
    if rc is None:
        return "over time", f"killed after {timeout:.0f} s"
    if rc == 70 or rc < 0 or rc > 128 or "Traceback" in stderr:
        tail = stderr.strip().splitlines()[-1] if stderr.strip() else ""
        return "crash", f"exit {rc}: {tail[:160]}"
    if rc != 0:
        msg = str(record.get("error") or (stderr.strip().splitlines() or [""])[-1])
        return "refused", msg[:200]
    if faces <= SLOW_FACES and seconds > SLOW_S:
        return "over time", f"{seconds:.0f} s"
    if _fallback(record):
        return "substitution", str(record.get("method_used") or record.get("note") or "")[:120]
    if m is None:
        return "result", ""
    if m.get("nan"):
        return "artefact", "NaN coordinates"
    why = []
    if m.get("degenerate_made", 0) > 0:
        why.append(f"{m['degenerate_made']} degenerate triangles made")
    if m.get("folds_made", 0) > FOLDS * m.get("faces_out", 0):
        why.append(f"{m['folds_made']} triangles folded over")
    made = m.get("intersections_made",
                 m.get("intersections_out", 0) - m.get("intersections_in", 0))
    if made > 0:
        why.append(f"{made} self-intersections made")
    if m.get("spike", 0.0) > SPIKE:
        why.append(f"spike {100 * m['spike']:.1f} % of the diagonal")
    if why:
        return "artefact", "; ".join(why)
    if not moves:
        return "result", ""
    if m.get("moved", 1.0) < VISIBLE:
        return "no effect", f"largest move {100 * m.get('moved', 0):.3f} % of the diagonal"
    return "result", f"moved {100 * m.get('moved', 0):.2f} %" if "moved" in m else ""


def _thumbnail(mesh: Path, png: Path, label: str) -> None:
    """A 160-px flat-shaded picture of a mesh with a caption (our renderer, no GUI)."""
    from PIL import Image, ImageDraw

    from algorithms.mesh import read_mesh
    from algorithms.render import look_at, render

    md = read_mesh(mesh)
    V, F = md.V, md.F
    lo, hi = V.min(axis=0), V.max(axis=0)
    c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2 or 1.0
    d = np.array([1.0, 0.8, 1.4])
    cam = look_at(c + 3 * r * d / np.linalg.norm(d), c, width=2.1 * r, resolution=160)
    img = render(V, F, cam, background=1.0).image
    im = Image.fromarray((np.clip(img, 0, 1) * 255).astype(np.uint8))
    ImageDraw.Draw(im).text((4, 146), label[:28], fill=(0, 0, 0))
    im.save(png)


def run_one(method: str, mesh: Path, work: Path, timeout: float) -> dict:
    """Run and classify one (mesh, method) pair (in a child process of the benchmark)."""
    argv, suffix, moves = METHODS[method]
    from algorithms.mesh import read_mesh

    try:
        faces = len(read_mesh(mesh).F)
    except Exception:  # noqa: BLE001 - the command says what is wrong with the file
        faces = 0
    out = work / f"{mesh.stem}__{method}{suffix or ''}"
    rec: dict = {"mesh": mesh.name, "method": method, "faces": faces}
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    clean = False
    extra: list[str] = []

    def command():
        """(exit status or None when killed, stdout, stderr, seconds, its --json)."""
        t0 = time.perf_counter()
        try:
            p = subprocess.run(_command(method, mesh, out, clean, extra), cwd=ROOT, env=env,
                               capture_output=True, text=True, timeout=timeout)
            rc, stdout, stderr = p.returncode, p.stdout, p.stderr
        except subprocess.TimeoutExpired:
            rc, stdout, stderr = None, "", ""
        return rc, stdout, stderr, time.perf_counter() - t0, _last_json(stdout)

    for attempt in (0, 1, 2):
        rc, stdout, stderr, seconds, record = command()
        refused = rc is not None and 2 <= rc <= 6
        said = str(record.get("error") or "") + "\n" + stderr
        if attempt == 0 and refused and "clean" in (stderr + json.dumps(record)).lower():
            rec["refusal"] = str(record.get("error") or stderr.strip().splitlines()[-1:])[:200]
            clean = True
            continue
        if attempt < 2 and refused and not extra and advised_setting(said):
            # the advice names a setting and its value ("ask for fewer: --m 140"): follow it
            extra = advised_setting(said)
            rec.setdefault("refusal", said.strip().splitlines()[-1][:200] if said.strip()
                           else "")
            rec["advice"] = " ".join(extra)
            continue
        break

    def measured(rc):
        if rc == 0 and suffix == ".obj" and out.exists():
            try:
                return _measure(mesh, out, clean, moves)
            except Exception as e:  # noqa: BLE001 - reported in the cell
                return {"measure_error": f"{type(e).__name__}: {e}"[:160]}
        return None

    m = measured(rc)
    kind, why = _classify(rc, seconds, stderr, record, m, moves, faces, timeout)
    # a result that changed nothing visible and says which setting to raise (smooth: "Raise
    # --step-size (e.g. --step-size 1e-04)"): follow that advice, twice at most
    for _ in range(2):
        advice = advised_setting(str(record.get("note") or ""))
        if kind != "no effect" or not advice:
            break
        extra = merge_settings(extra, advice)
        rec["advice"] = " ".join(extra)
        rec.setdefault("first", why)
        rc, stdout, stderr, seconds, record = command()
        m = measured(rc)
        kind, why = _classify(rc, seconds, stderr, record, m, moves, faces, timeout)
    followed = " ".join((["--clean"] if clean else []) + extra)
    if followed and kind == "result":
        kind = "advice works"
    elif followed and kind == "refused":
        why = f"refused, and with {followed}: {why}"
    rec.update(kind=kind, why=why, seconds=round(seconds, 2), exit=rc, clean=clean,
               measure=m)
    png = work / f"{mesh.stem}__{method}.png"
    try:
        shown = out if (rc == 0 and suffix == ".obj" and out.exists()) else mesh
        _thumbnail(shown, png, f"{mesh.stem[:14]} {SHORT[kind]}")
        rec["picture"] = str(png)
    except Exception as e:  # noqa: BLE001
        rec["picture_error"] = str(e)[:120]
    return rec


# ---------------------------------------------------------------------------- the benchmark
def _child(method: str, mesh: Path, work: Path, timeout: float) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", method, str(mesh),
           "--work", str(work), "--timeout", str(timeout)]
    try:
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                           timeout=2 * timeout + 300)
    except subprocess.TimeoutExpired:
        return {"mesh": mesh.name, "method": method, "kind": "over time",
                "why": "the measurement did not finish"}
    rec = _last_json(p.stdout)
    if not rec:
        return {"mesh": mesh.name, "method": method, "kind": "crash",
                "why": f"the measuring process died (exit {p.returncode}): "
                       f"{(p.stderr.strip().splitlines() or [''])[-1][:160]}"}
    return rec


def _contact_sheets(records: list[dict], methods: list[str], folder: Path) -> list[Path]:
    from PIL import Image

    made = []
    for method in methods:
        if METHODS[method][1] != ".obj":
            continue  # no mesh comes out: its pictures would be the inputs again
        pics = [r.get("picture") for r in records if r["method"] == method and r.get("picture")]
        if not pics:
            continue
        path = folder / f"corpus_{method}.png"
        if not all(Path(p).exists() for p in pics):
            # a method merged from an earlier run whose pictures are gone: its sheet is kept
            print(f"{method}: pictures of an earlier run are gone; {path} kept as it was")
            if path.exists():
                made.append(path)
            continue
        cols = 8
        rows = (len(pics) + cols - 1) // cols
        sheet = Image.new("RGB", (cols * 160, rows * 160), "white")
        for k, p in enumerate(pics):
            sheet.paste(Image.open(p), ((k % cols) * 160, (k // cols) * 160))
        sheet.quantize(colors=255).save(path, optimize=True)
        made.append(path)
    return made


def _page(records: list[dict], methods: list[str], meshes: list[Path], args, seconds: float,
          sheets: list[Path]) -> str:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    by = {(r["mesh"], r["method"]): r for r in records}
    lines = [
        "# Every method at its defaults on the corpus",
        "",
        f"Generated by `benchmarks/corpus.py` on {datetime.now(timezone.utc):%Y-%m-%d %H:%M UTC},"
        f" commit {commit}, {platform.machine()} with {os.cpu_count()} cores "
        f"({args.jobs} runs at a time, one thread each); the commands took "
        f"{sum(r.get('seconds') or 0 for r in records) / 60:.0f} min in all (summed over the "
        f"runs; this invocation {seconds / 60:.1f} min). "
        f"{len(meshes)} meshes x {len(methods)} methods. The classes are defined in the "
        "script's docstring: ok = a visible, artefact-free result; ok* = after the advice of "
        "the refusal (Clean, or the setting and value it named) was followed, or the setting "
        "and value named by a result that changed nothing visible (smooth: --step-size); R = "
        "refused with a message (also after its advice); - = no visible effect (also after "
        "its advice); "
        "X = artefact; S = another method ran (said in the output); T = over time; "
        "C! = crash or traceback." + (
            " Part of the table comes from an earlier run of the same script (--merge): the "
            "pairs run this time replaced that run's."
            if args.merge else ""),
        "",
    ]
    if not any(m.startswith("paparazzi") for m in methods):
        lines += [PAPARAZZI_ELSEWHERE, ""]
    lines += [
        "| mesh | triangles | " + " | ".join(methods) + " |",
        "|---|---:|" + "---|" * len(methods),
    ]
    for mesh in meshes:
        cells = []
        faces = ""
        for method in methods:
            r = by.get((mesh.name, method))
            if r is None:
                cells.append("")
                continue
            faces = faces or f"{r.get('faces', 0):,}"
            cells.append(SHORT.get(r["kind"], r["kind"]))
        lines.append(f"| {mesh.name} | {faces} | " + " | ".join(cells) + " |")
    lines += ["", "## Per method", "",
              "| method | " + " | ".join(SHORT.values()) + " | visible and artefact-free, "
              "of the pairs not refused |",
              "|---|" + "---:|" * (len(SHORT) + 1)]
    for method in methods:
        rs = [r for r in records if r["method"] == method]
        counts = [sum(r["kind"] == k for r in rs) for k in SHORT]
        good = sum(r["kind"] in ("result", "advice works") for r in rs)
        considered = sum(r["kind"] != "refused" for r in rs)
        share = f"{100 * good / considered:.0f} % ({good}/{considered})" if considered else "-"
        lines.append(f"| {method} | " + " | ".join(map(str, counts)) + f" | {share} |")
    lines += ["", "## What went wrong", ""]
    import re

    for r in records:
        if r["kind"] not in ("result", "advice works"):
            # file names only: the page never points at folders outside the repository
            why = re.sub(r"(?<![\w/])(?:\.{1,2})?/(?:[\w.+-]+/)*([\w.+-]+)", r"\1",
                         " ".join(str(r.get("why", "")).split()))[:240]
            lines.append(f"- {r['mesh']}, {r['method']}: **{r['kind']}** — {why}")
    if sheets:
        lines += ["", "## Contact sheets", ""]
        lines += [f"![{p.stem}](../images/{p.name})" for p in sheets]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", default=os.environ.get("STYLIZE3D_CORPUS"))
    ap.add_argument("--extra", action="append", default=[],
                    help="another folder of meshes (e.g. the shared meshes)")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--meshes", default="", help="only these file names (comma-separated)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--work", default="")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "corpus.md"))
    ap.add_argument("--images", default=str(ROOT / "docs" / "images"))
    ap.add_argument("--no-pictures", action="store_true")
    ap.add_argument("--json", default="", help="also write every record to this file")
    ap.add_argument("--merge", default="",
                    help="records of an earlier run (--json): the pairs run now replace theirs, "
                         "the page shows all (rerun one method after a change)")
    ap.add_argument("--one", nargs=2, metavar=("METHOD", "MESH"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        work = Path(args.work)
        work.mkdir(parents=True, exist_ok=True)
        print(json.dumps(run_one(args.one[0], Path(args.one[1]), work, args.timeout)))
        return 0
    if not args.corpus:
        ap.error("give the corpus folder with --corpus DIR (or STYLIZE3D_CORPUS)")
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        ap.error(f"unknown methods {unknown}; choose from {', '.join(METHODS)}")
    meshes = []
    for folder in [args.corpus, *args.extra]:
        meshes += sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in SUFFIXES)
    if args.meshes:
        wanted = set(args.meshes.split(","))
        meshes = [m for m in meshes if m.name in wanted]
    import tempfile

    work = Path(args.work or tempfile.mkdtemp(prefix="corpus-"))
    work.mkdir(parents=True, exist_ok=True)
    pairs = [(method, mesh) for mesh in meshes for method in methods]
    print(f"{len(meshes)} meshes x {len(methods)} methods = {len(pairs)} runs, {args.jobs} at a "
          f"time, results in {work}", flush=True)
    t0 = time.perf_counter()
    records = []
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = [pool.submit(_child, method, mesh, work, args.timeout)
                   for method, mesh in pairs]
        for k, f in enumerate(futures, 1):
            r = f.result()
            records.append(r)
            print(f"[{k}/{len(pairs)}] {r['mesh']:<28} {r['method']:<20} {r['kind']:<13} "
                  f"{r.get('seconds', '')} s  {r.get('why', '')[:90]}", flush=True)
    seconds = time.perf_counter() - t0
    if args.merge:
        done = {(r["mesh"], r["method"]) for r in records}
        earlier = json.loads(Path(args.merge).read_text())
        records = [r for r in earlier if (r["mesh"], r["method"]) not in done] + records
        methods = list(dict.fromkeys([r["method"] for r in earlier] + methods))
        names = {r["mesh"] for r in records}
        meshes = sorted({m for m in meshes} | {m for folder in [args.corpus, *args.extra]
                                               for m in Path(folder).iterdir()
                                               if m.name in names}, key=lambda m: m.name)
        methods = [m for m in METHODS if m in methods]
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))
    sheets = [] if args.no_pictures else _contact_sheets(records, methods, Path(args.images))
    Path(args.out).write_text(_page(records, methods, meshes, args, seconds, sheets))
    print(f"wrote {args.out} ({seconds / 60:.1f} min)")
    for method in methods:
        rs = [r for r in records if r["method"] == method]
        print(f"{method:<20} " + "  ".join(f"{SHORT[k]}:{sum(r['kind'] == k for r in rs)}"
                                           for k in SHORT))
    return 0


if __name__ == "__main__":
    sys.exit(main())
