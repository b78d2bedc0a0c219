"""Smoke test of the one-folder build (run by packaging/build.sh; any Python with NumPy + Pillow).

    python packaging/smoke_test.py BUNDLE_DIR [--venv VENV] [--out DIR] [--repeats N]

Checks, with the built binary ``BUNDLE_DIR/stylize3d``:

1. where the frozen app finds resources/ (``STYLIZE3D_BUNDLE_CHECK=1``): samples and style
   thumbnails are there;
2. headless (no DISPLAY): ``stylize3d cubic resources/samples/blob.obj -o OUT.obj --json`` exits 0,
   its JSON names the output, ran iterations and made the mesh more cubic (L1 norm of the normals
   went down), and OUT.obj has the input's vertex / face counts, finite coordinates, moved vertices;
   then ``stylize3d subdivide ... --method neural --levels 1`` (torch and the shipped weights in
   resources/subdivision, when the tree has them) gives 4x the faces; a second cubic run loads
   the compiled kernels from a cache outside the source tree (NUMBA_DEBUG_CACHE);
3. under Xvfb (``xvfb-run -a -s "-screen 0 1600x1000x24"``):
   ``stylize3d resources/samples/blob.obj --screenshot PNG`` exits 0 and the PNG is a window-sized,
   non-blank picture (grey-level standard deviation, share of mesh-coloured pixels); with --venv
   the same screenshot from the venv is taken and the mesh must cover about as much of it.

Then it times ``--help``, ``info blob.obj --json`` and the screenshot run (median of --repeats),
for the bundle and, with --venv, for ``VENV/bin/stylize3d``, and prints a table. Exit 0 when every
check passed, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = "resources/samples/blob.obj"
XVFB = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24"]
MESH_RGB = np.array([0xE8, 0xD4, 0xB0], float)  # app/viewport.py MESH_COLOR (lit: darker shades)

failures: list[str] = []


def check(ok: bool, what: str) -> bool:
    print(("  ok    " if ok else "  FAIL  ") + what, flush=True)
    if not ok:
        failures.append(what)
    return ok


def headless_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env.pop("QT_QPA_PLATFORM", None)
    return env


def run(cmd: list[str], *, timeout: float = 600, env: dict | None = None,
        cwd: Path = ROOT) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=cwd, env=env or headless_env(), capture_output=True, text=True,
                       timeout=timeout)
    return p, time.perf_counter() - t0


def tail(p: subprocess.CompletedProcess) -> str:
    return ("\n" + (p.stdout + p.stderr)[-2000:]) if p.returncode else ""


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    V, F = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            V.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            F.append([int(t.split("/")[0]) - 1 for t in line.split()[1:4]])
    return np.array(V, float), np.array(F, np.int64)


def check_resources(binary: Path) -> None:
    env = headless_env()
    env["STYLIZE3D_BUNDLE_CHECK"] = "1"
    p, _ = run([str(binary)], env=env, cwd=Path(tempfile.gettempdir()), timeout=300)
    if not check(p.returncode == 0, f"bundle resource check exits 0 (got {p.returncode}){tail(p)}"):
        return
    info = json.loads(p.stdout)
    meipass = info["meipass"] or ""
    check(info["frozen"] and info["resources_dir"].startswith(meipass),
          f"frozen, resources inside the bundle: {info['resources_dir']}")
    check({"blob", "bumpy", "pretzel"} <= set(info["samples"]), f"samples found: {info['samples']}")
    check(len(info["style_thumbnails"]) >= 1,
          f"style thumbnails found: {len(info['style_thumbnails'])}")
    print(f"        resources/ holds: {', '.join(info['resources'])}")


def check_cubic(binary: Path, out: Path) -> None:
    target = out / "cubic.obj"
    target.unlink(missing_ok=True)
    p, secs = run([str(binary), "cubic", SAMPLE, "-o", str(target), "--json"])
    if not check(p.returncode == 0, f"headless cubic exits 0 (got {p.returncode}, {secs:.1f} s)"
                 f"{tail(p)}"):
        return
    try:
        report = json.loads(p.stdout)
    except json.JSONDecodeError as exc:
        check(False, f"cubic --json prints JSON ({exc}): {p.stdout[:300]!r}")
        return
    check(Path(report.get("output", "")).resolve() == target.resolve(),
          f"JSON names the output ({report.get('output')})")
    check(report.get("iterations", 0) > 0, f"JSON: {report.get('iterations')} iterations")
    before, after = report.get("l1_normals_before"), report.get("l1_normals_after")
    check(before is not None and after is not None and after < before,
          f"JSON: L1 norm of normals {before} -> {after} (more cubic)")
    if not check(target.is_file(), f"output mesh written ({target})"):
        return
    V0, F0 = read_obj(ROOT / SAMPLE)
    V1, F1 = read_obj(target)
    check(V1.shape == V0.shape and F1.shape == F0.shape,
          f"output has the input's size: {len(V1)} vertices, {len(F1)} faces")
    check(bool(np.isfinite(V1).all()), "output coordinates are finite")
    if V1.shape == V0.shape:
        # the CLI normalizes the result's scale: compare centred, unit-box shapes
        def unit(V):
            V = V - V.mean(0)
            return V / np.abs(V).max()
        moved = float(np.abs(unit(V1) - unit(V0)).max())
        check(moved > 1e-3, f"vertices moved (max change {moved:.3g} of the unit box)")
    print(f"        cubic: {secs:.1f} s wall for the whole command "
          f"({report.get('seconds', float('nan')):.1f} s in the method)")


def check_kernel_cache(binary: Path, out: Path) -> None:
    """The compiled (Numba) kernels are cached by absolute path, never into the current
    directory's tree (the smoke test runs in the checkout), and a second run loads them."""
    env = headless_env()
    env["NUMBA_DEBUG_CACHE"] = "1"
    p, secs = run([str(binary), "cubic", SAMPLE, "-o", str(out / "cubic2.obj"), "--overwrite",
                   "--json"], env=env)
    if not check(p.returncode == 0, f"second cubic run exits 0 ({secs:.1f} s){tail(p)}"):
        return
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("[cache]")]
    paths = [ln.split("'")[1] for ln in lines if ln.count("'") >= 2]
    bad = [q for q in paths if not os.path.isabs(q) or Path(q).resolve().is_relative_to(ROOT)
           and not Path(q).resolve().is_relative_to(binary.parent.resolve())]
    check(bool(paths) and not bad, f"kernel cache outside the source tree ({len(paths)} cache "
          f"operations{', e.g. ' + paths[0] if paths else ''}; bad: {bad[:2]})")
    loads = sum("data loaded from" in ln for ln in lines)
    check(loads > 0, f"second run loads compiled kernels from the cache ({loads} loaded)")


def check_subdivide(binary: Path, out: Path) -> None:
    """Neural subdivision with the shipped weights: torch and resources/subdivision in the bundle."""
    if not (ROOT / "resources" / "subdivision").is_dir():
        print("        (no resources/subdivision in this tree: skipped)")
        return
    p, _ = run([str(binary), "subdivide", "--help"])
    if p.returncode != 0:
        print("        (this build has no subdivide command: skipped)")
        return
    target = out / "subdivided.obj"
    target.unlink(missing_ok=True)
    p, secs = run([str(binary), "subdivide", SAMPLE, "-o", str(target), "--levels", "1",
                   "--method", "neural", "--json"])
    if not check(p.returncode == 0, f"neural subdivision (torch, shipped weights) exits 0 "
                 f"(got {p.returncode}, {secs:.1f} s){tail(p)}"):
        return
    report = json.loads(p.stdout)
    V0, F0 = read_obj(ROOT / SAMPLE)
    V1, F1 = read_obj(target)
    check(len(F1) == 4 * len(F0) and bool(np.isfinite(V1).all()),
          f"one level: {len(F0)} -> {len(F1)} faces, finite ({report.get('method')})")


def screenshot(binary: Path, png: Path) -> tuple[subprocess.CompletedProcess, float]:
    png.unlink(missing_ok=True)
    return run(XVFB + [str(binary), SAMPLE, "--screenshot", str(png)], timeout=300)


def image_stats(png: Path) -> dict:
    img = np.asarray(Image.open(png).convert("RGB"), float)
    grey = img.mean(axis=2)
    # pixels near the mesh colour or a darker (shaded) version of it
    norm = img / (np.linalg.norm(img, axis=2, keepdims=True) + 1e-9)
    cos = norm @ (MESH_RGB / np.linalg.norm(MESH_RGB))
    mesh_share = float(((cos > 0.995) & (grey > 60)).mean())
    return {"width": img.shape[1], "height": img.shape[0], "std": float(grey.std()),
            "mesh_share": mesh_share}


def small(png: Path) -> np.ndarray:
    return np.asarray(Image.open(png).convert("L").resize((160, 100), Image.BILINEAR), float)


def check_screenshot(binary: Path, png: Path, reference: Path | None) -> None:
    p, secs = screenshot(binary, png)
    if not check(p.returncode == 0 and png.is_file(),
                 f"GUI under Xvfb saves a screenshot (rc {p.returncode}, {secs:.1f} s){tail(p)}"):
        return
    s = image_stats(png)
    check(s["width"] >= 800 and s["height"] >= 500, f"screenshot size {s['width']}x{s['height']}")
    check(s["std"] > 10, f"screenshot not blank: grey-level std {s['std']:.1f}")
    check(s["mesh_share"] > 0.02, f"mesh visible: {100 * s['mesh_share']:.1f}% mesh-coloured pixels")
    if reference is not None and reference.is_file():
        # The venv runs the working tree as it is now, the bundle the tree as it was at build
        # time: panels and toolbars may differ, so the whole-window difference is only printed;
        # the check is that the mesh covers about as much of the window in both.
        r = image_stats(reference)
        diff = float(np.abs(small(png) - small(reference)).mean())
        ratio = s["mesh_share"] / max(r["mesh_share"], 1e-9)
        check(0.5 < ratio < 2.0, f"mesh area like the venv's screenshot ({100 * s['mesh_share']:.1f}%"
              f" vs {100 * r['mesh_share']:.1f}%; whole window downscaled to 160x100: mean "
              f"|diff| {diff:.1f} / 255)")


def time_commands(binary: Path, repeats: int, png: Path) -> dict[str, float]:
    cmds = {
        "--help": [str(binary), "--help"],
        "info --json": [str(binary), "info", SAMPLE, "--json"],
    }
    times: dict[str, float] = {}
    for name, cmd in cmds.items():
        ts = []
        for _ in range(repeats):
            p, secs = run(cmd)
            if p.returncode != 0:
                check(False, f"{' '.join(cmd)} exits 0 (got {p.returncode}){tail(p)}")
                break
            ts.append(secs)
        times[name] = statistics.median(ts) if ts else float("nan")
    ts = []
    for _ in range(repeats):
        p, secs = screenshot(binary, png)
        if p.returncode == 0:
            ts.append(secs)
    times["screenshot (xvfb-run)"] = statistics.median(ts) if ts else float("nan")
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bundle", type=Path, help="the one-folder build (holds the stylize3d binary)")
    ap.add_argument("--venv", type=Path, help="a venv with stylize3d installed, to compare with")
    ap.add_argument("--out", type=Path, default=None, help="where results go (default: temp)")
    ap.add_argument("--repeats", type=int, default=3, help="timing runs per command (median)")
    args = ap.parse_args(argv)
    binary = args.bundle.resolve() / "stylize3d"
    out = (args.out or Path(tempfile.mkdtemp(prefix="stylize3d-smoke-"))).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if shutil.which("xvfb-run") is None:
        print("xvfb-run is missing (apt-get install xvfb xauth)", file=sys.stderr)
        return 2
    if not binary.is_file():
        print(f"no binary at {binary}", file=sys.stderr)
        return 2
    venv_bin = args.venv.resolve() / "bin" / "stylize3d" if args.venv else None
    if venv_bin is not None and not venv_bin.is_file():
        print(f"  (no {venv_bin}: no comparison with a venv)")
        venv_bin = None

    print(f"Smoke test of {binary} (results in {out})")
    print("1. resources in the bundle")
    check_resources(binary)
    print("2. headless cubic stylization")
    check_cubic(binary, out)
    check_kernel_cache(binary, out)
    print("2b. headless neural subdivision (torch and the shipped weights)")
    check_subdivide(binary, out)
    print("3. GUI screenshot under Xvfb")
    reference = None
    if venv_bin is not None:
        reference = out / "venv.png"
        p, secs = screenshot(venv_bin, reference)
        if p.returncode != 0:
            print(f"  (venv screenshot failed, rc {p.returncode}: no comparison){tail(p)}")
            reference = None
    check_screenshot(binary, out / "bundle.png", reference)

    print(f"4. start-up times (median of {args.repeats}, seconds of wall time)")
    rows = {"bundle": time_commands(binary, args.repeats, out / "timing-bundle.png")}
    if venv_bin is not None:
        rows["venv"] = time_commands(venv_bin, args.repeats, out / "timing-venv.png")
    names = list(rows["bundle"])
    print("   " + f"{'':8s}" + "".join(f"{n:>24s}" for n in names))
    for who, t in rows.items():
        print("   " + f"{who:8s}" + "".join(f"{t[n]:24.2f}" for n in names))
    (out / "timings.json").write_text(json.dumps(rows, indent=2))

    if failures:
        print(f"SMOKE TEST FAILED: {len(failures)} check(s) failed")
        return 1
    print("SMOKE TEST PASSED")
    return 0


if __name__ == "__main__":
    sys.exit(main())
