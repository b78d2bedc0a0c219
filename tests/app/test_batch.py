"""``stylize3d batch`` (issue 21): a method on a library of meshes with a local process pool or a
Dask cluster; outputs equal to the one-mesh command's, plain failures, resuming after the driver
is killed, a worker killed mid-mesh retried once, memory and time limits, dry run, typos."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from algorithms.mesh import icosphere, torus, write_mesh
from app import batch
from app.cli import main
from tests.conftest import ROOT, TEST_DATA


def _rotation(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def _library(root: Path) -> tuple[list[Path], list[Path]]:
    """Good meshes (tests/data and primitives, rotated / scaled; two with the same file name
    in different folders) and broken ones (empty, NaN, non-manifold, garbage bytes)."""
    good = []
    for name in ("hand_lowres.obj", "spot_lowres.obj"):
        p = root / name
        p.write_bytes((TEST_DATA / name).read_bytes())
        good.append(p)
    for k, (sub, (V, F)) in enumerate([("a", icosphere(2)), ("b", icosphere(2)),
                                       ("a", torus(n_major=24, n_minor=12)), ("b", icosphere(1))]):
        (root / sub).mkdir(exist_ok=True)
        name = "ico.obj" if k < 2 else f"shape{k}.{'off' if k == 2 else 'ply'}"
        p = root / sub / name
        write_mesh(p, (V @ _rotation(k).T) * (0.5 + k), F)
        good.append(p)
    bad = {"empty.obj": "", "nan.obj": "v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\n"
           "f 1 3 4\nf 1 4 2\nf 2 4 3\n",
           "nonmanifold.obj": "v 0 0 0\nv 1 0 0\nv 0.5 1 0\nv 0.5 -1 0\nv 0.5 0 1\n"
           "f 1 2 3\nf 2 1 4\nf 1 2 5\n"}
    broken = []
    for name, text in bad.items():
        (root / name).write_text(text)
        broken.append(root / name)
    g = root / "garbage.obj"
    g.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    broken.append(g)
    return good, broken


def _records(report: Path) -> list[dict]:
    return [json.loads(line) for line in report.read_text().splitlines() if line.strip()]


def _reference(path: Path, tmp: Path, *flags) -> bytes:
    """What the one-mesh command writes for ``path``."""
    suffix = ".obj" if path.suffix == ".s3d" else path.suffix   # a project gives a mesh
    out = tmp / f"ref-{abs(hash(str(path)))}{suffix}"
    assert main(["cubic", str(path), "-o", str(out), "--quiet", *flags]) == 0
    return out.read_bytes()


def _no_tmp(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.endswith(".tmp")]


def _batch_cmd(*args) -> list[str]:
    return [sys.executable, "-m", "app", "batch", *map(str, args)]


@pytest.fixture(scope="module")
def cubic_batch(tmp_path_factory):
    """One batch of cubic over the library with 2 workers (the CLI, in this process)."""
    tmp = tmp_path_factory.mktemp("cubic")
    lib = tmp / "lib"
    lib.mkdir()
    good, broken = _library(lib)
    out = tmp / "out"
    code = main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "2", "--quiet",
                 "--json"])
    return {"tmp": tmp, "lib": lib, "good": good, "broken": broken, "out": out, "code": code}


def test_cubic_batch_equals_one_mesh_command_and_reports_broken_meshes(cubic_batch, tmp_path):
    good, broken, out = cubic_batch["good"], cubic_batch["broken"], cubic_batch["out"]
    assert cubic_batch["code"] == 1  # some failed
    recs = {Path(r["input"]).resolve(): r for r in _records(out / "batch-report.jsonl")}
    assert len(recs) == len(good) + len(broken)
    for p in good:
        r = recs[p.resolve()]
        assert r["status"] == "done", r
        # the same file name in two folders: each keeps its folder below the common one
        assert Path(r["output"]) == out / p.relative_to(cubic_batch["lib"])
        assert Path(r["output"]).read_bytes() == _reference(p, tmp_path)
        assert r["output_sha256"] and len(r["key"]) == 64 and r["seconds"] > 0
        f = r["figures"]
        assert f["iterations"] > 0 and f["faces"] == f["faces_in"] > 0
        assert f["l1_normals_after"] < f["l1_normals_before"]
    for p in broken:
        r = recs[p.resolve()]
        assert r["status"] == "failed" and len(r["message"]) > 20, r
        assert "Traceback" not in r["message"] and "bug" not in r["message"]
        assert not Path(r["output"]).exists()
    assert "NaN" in recs[(cubic_batch["lib"] / "nan.obj").resolve()]["message"] or \
        "not a number" in recs[(cubic_batch["lib"] / "nan.obj").resolve()]["message"].lower()
    assert not _no_tmp(out)


def test_a_box_in_a_batch_says_its_faces_already_face_the_axes(tmp_path):
    """The batch record carries the note the line gives (issue 38: the corpus's CAD tray; a
    flat drawing for analogies)."""
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import cube

    lib = tmp_path / "lib"
    lib.mkdir()
    write_mesh(lib / "box.obj", *cube(3))
    out = tmp_path / "out"
    assert main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet"]) == 0
    (rec,) = [r for r in _records(out / "batch-report.jsonl") if r.get("status") == "done"]
    assert any("already face the axes" in n for n in rec.get("notes", [])), rec
    from tests.conftest import unit_square_grid

    (lib / "box.obj").unlink()
    write_mesh(lib / "flat.obj", *unit_square_grid(8))   # every normal is a cube normal
    out = tmp_path / "out2"
    assert main(["batch", "analogy", str(lib), "-o", str(out), "--workers", "1", "--quiet",
                 "--style", "cube"]) == 0
    (rec,) = [r for r in _records(out / "batch-report.jsonl") if r.get("status") == "done"]
    assert any("already within" in n for n in rec.get("notes", [])), rec


def test_dry_run_lists_what_would_run_or_be_skipped_and_runs_nothing(cubic_batch, capsys,
                                                                      tmp_path):
    lib, out = cubic_batch["lib"], cubic_batch["out"]
    before = (out / "batch-report.jsonl").read_text()
    assert main(["batch", "cubic", str(lib), "-o", str(out), "--dry-run", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    actions = {Path(i["input"]).name: i["action"] for i in d["items"]}
    assert actions["hand_lowres.obj"] == "skip" and actions["garbage.obj"] == "run"
    assert d["skip"] == len(cubic_batch["good"]) and d["run"] == len(cubic_batch["broken"])
    assert (out / "batch-report.jsonl").read_text() == before  # nothing written
    fresh = tmp_path / "never"
    assert main(["batch", "cubic", str(lib), "-o", str(fresh), "--dry-run", "--lam", "0.3"]) \
        == 0
    text = capsys.readouterr().out
    assert text.count("run ") >= len(cubic_batch["good"]) and "not done yet" in text
    assert not fresh.exists()


def test_a_typo_or_a_method_without_batch_form_is_a_plain_usage_error(tmp_path, capsys):
    mesh = tmp_path / "m.obj"
    write_mesh(mesh, *icosphere(1))
    assert main(["batch", "cubc", str(mesh), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "Did you mean 'cubic'?" in err and "Traceback" not in err
    assert main(["batch", "coarsen", str(mesh), "-o", str(tmp_path / "o")]) == 2
    assert "no batch form" in capsys.readouterr().err
    assert main(["batch", "cubic", str(tmp_path / "nothing*.obj"), "-o",
                 str(tmp_path / "o")]) == 2
    assert main(["batch", "cubic", str(mesh), "-o", str(tmp_path / "o"), "--lam", "-3"]) == 5
    assert not (tmp_path / "o").exists()


def test_settings_from_a_project_or_a_settings_file_make_the_same_job(tmp_path):
    from app.document import MeshState
    from app.project import Project, save_project

    job = batch.build_job("cubic", ["--lambda", "0.4"])
    # options switch to progressive meshes above the automatic size, as for one mesh
    assert job.options_for(1000)["progressive"] is None
    big = job.options_for(400_000)["progressive"]
    assert big["target_faces"] == 20_000 and big["preview_every"] == 0
    params = {**job.params}
    options = {"plane_axis": 0, "progressive": None, "multigrid": False}
    proj = Project(MeshState.make(*icosphere(1)),
                   panels={"Cubic": {"params": params, "options": options},
                           "Smooth": {"params": {}, "options": {}}})
    path = save_project(tmp_path / "scene.s3d", proj)
    saved = batch.build_job(str(path))  # the only changed panel: Cubic
    assert (saved.recipe, saved.params, saved.options) == (job.recipe, job.params, job.options)
    # as for one mesh, saved settings keep the panel's own progressive choice on big meshes
    assert saved.large_options is None and saved.key != job.key
    settings = batch.write_panel_settings(tmp_path / "cubic.json", "Cubic", params, options)
    assert batch.build_job(str(settings)).key == saved.key
    assert batch.job_from_settings("Cubic", params, options).key == saved.key
    flags = batch.build_job(str(settings), ["--lambda", "0.2"])
    assert flags.params["lam"] == 0.2 and flags.key != saved.key   # flags win
    proj.panels["Smooth"]["params"] = {"iterations": 3}
    save_project(tmp_path / "two.s3d", proj)
    with pytest.raises(batch.BatchUsageError, match="--panel"):
        batch.build_job(str(tmp_path / "two.s3d"))
    smooth = batch.build_job(str(tmp_path / "two.s3d"), panel="smooth")
    assert smooth.recipe == "Smooth" and smooth.params["iterations"] == 3


def test_output_names_keep_folders_and_never_collide(tmp_path):
    ins = [tmp_path / "lib" / "a" / "x.obj", tmp_path / "lib" / "b" / "x.obj",
           tmp_path / "lib" / "a" / "x.s3d"]
    outs = batch.output_names(ins, tmp_path / "out")
    assert outs[0] == (tmp_path / "out" / "a" / "x.obj").resolve()
    assert outs[1] == (tmp_path / "out" / "b" / "x.obj").resolve()
    assert outs[2].suffix == ".obj" and outs[2] != outs[0] and len(set(outs)) == 3
    with pytest.raises(batch.BatchUsageError):
        batch.output_names([tmp_path / "x.obj"], tmp_path)


def _mixed_library(tmp_path, n: int, seed: int) -> tuple[Path, list[Path]]:
    """``tmp_path/lib`` with ``n`` spheres and tori of growing sizes, rotated."""
    lib = tmp_path / "lib"
    lib.mkdir()
    good = []
    for k in range(n):
        V, F = torus(n_major=30 + 2 * k, n_minor=14) if k % 2 else icosphere(3)
        p = lib / f"m{k}.obj"
        write_mesh(p, (V @ _rotation(seed + k).T) * (1 + k), F)
        good.append(p)
    return lib, good


def test_resume_after_the_driver_is_killed_does_nothing_twice(tmp_path):
    lib, good = _mixed_library(tmp_path, 6, 10)
    out = tmp_path / "out"
    report = out / "batch-report.jsonl"
    proc = subprocess.Popen(_batch_cmd("cubic", lib, "-o", out, "--workers", "1", "--quiet"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if report.exists() and sum('"done"' in x for x in report.read_text().splitlines()) >= 2:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the batch ended before it could be killed"
    workers = _worker_pids(out)
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    _wait_gone(workers)  # the workers see their driver gone and stop
    done_before = {r["input"] for r in _records(report) if r["status"] == "done"}
    assert 2 <= len(done_before) < len(good)
    code = main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet",
                 "--json"])
    assert code == 0
    recs = _records(report)
    for p in good:
        mine = [r for r in recs if r["input"] == str(p.resolve())]
        assert sum(r["status"] == "done" for r in mine) == 1, mine   # nothing done twice
        assert Path(mine[-1]["output"]).read_bytes() == _reference(p, tmp_path)
    skipped = [r for r in recs if r["status"] == "skipped"]
    assert len(skipped) >= len(done_before) and all(r["message"] for r in skipped)
    assert not _no_tmp(out)
    assert not list((out / ".batch").glob("run-*")) and not list((out / ".batch" /
                                                                  "pending").iterdir())


def test_sigterm_stops_a_batch_like_ctrl_c_and_it_resumes(tmp_path):
    """SIGTERM (SLURM, Kubernetes, ``kill``; issue 39 item 6): exit 143 with the resume advice,
    no run folder left, the workers gone; the same command then finishes, nothing done twice."""
    lib, good = _mixed_library(tmp_path, 5, 20)
    out = tmp_path / "out"
    report = out / "batch-report.jsonl"
    err = tmp_path / "stderr.txt"
    with open(err, "w") as fh:
        proc = subprocess.Popen(_batch_cmd("cubic", lib, "-o", out, "--workers", "1",
                                           "--quiet"), cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=fh)
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if report.exists() and sum('"done"' in x for x in report.read_text().splitlines()) >= 1:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the batch ended before it could be stopped"
    workers = _worker_pids(out)
    proc.send_signal(signal.SIGTERM)
    proc.wait(60)
    text = err.read_text()
    assert proc.returncode == 143, text
    assert "stopped (SIGTERM)" in text and "run the same command again" in text, text
    assert "Traceback" not in text and "leaked semaphore" not in text, text
    _wait_gone(workers)
    assert not list((out / ".batch").glob("run-*"))
    done_before = {r["input"] for r in _records(report) if r["status"] == "done"}
    assert 1 <= len(done_before) < len(good)
    assert main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet"]) == 0
    recs = _records(report)
    for p in good:
        mine = [r for r in recs if r["input"] == str(p.resolve())]
        assert sum(r["status"] == "done" for r in mine) == 1, mine


def _worker_pids(out: Path) -> set[int]:
    pids = set()
    for f in (out / ".batch").glob("run-*/pid-*.json"):
        pids.add(int(f.name[len("pid-"):-len(".json")]))
    return pids


def _wait_gone(pids, timeout=20.0) -> None:
    import psutil

    deadline = time.time() + timeout
    while time.time() < deadline and any(psutil.pid_exists(p) and
                                         psutil.Process(p).status() != "zombie" for p in pids):
        time.sleep(0.05)


def test_a_worker_killed_mid_mesh_costs_only_that_mesh_a_retry(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    slow = lib / "armadillo.obj"
    slow.write_bytes((TEST_DATA / "armadillo.obj").read_bytes())
    others = []
    for k in range(3):
        p = lib / f"s{k}.obj"
        write_mesh(p, icosphere(2)[0] * (1 + k), icosphere(2)[1])
        others.append(p)
    out = tmp_path / "out"
    proc = subprocess.Popen(_batch_cmd("cubic", lib, "-o", out, "--workers", "2", "--quiet"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    victim = None
    deadline = time.time() + 120
    while victim is None and time.time() < deadline and proc.poll() is None:
        for f in (out / ".batch").glob("run-*/pid-*.json"):
            try:
                d = json.loads(f.read_text())
            except (OSError, ValueError):
                continue
            if d["input"] == str(slow.resolve()):
                victim = d["pid"]
        time.sleep(0.01)
    assert victim is not None, "the slow mesh never started"
    os.kill(victim, signal.SIGKILL)
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 0, err
    recs = {r["input"]: r for r in _records(out / "batch-report.jsonl")}
    r = recs[str(slow.resolve())]
    assert r["status"] == "done" and r["retries"] == 1 and r["attempts"] == 2, r
    assert Path(r["output"]).read_bytes() == _reference(slow, tmp_path)
    for p in others:
        assert recs[str(p.resolve())]["status"] == "done"
        assert recs[str(p.resolve())]["retries"] == 0
    assert not _no_tmp(out)


def test_memory_and_time_limits_fail_the_mesh_plainly_without_retry(tmp_path, capsys):
    mesh = tmp_path / "armadillo.obj"
    mesh.write_bytes((TEST_DATA / "armadillo.obj").read_bytes())
    # refused before running: the estimate does not fit
    code = main(["batch", "cubic", str(mesh), "-o", str(tmp_path / "o1"), "--workers", "1",
                 "--memory-limit", "200MB", "--quiet"])
    assert code == 1
    (r,) = _records(tmp_path / "o1" / "batch-report.jsonl")
    assert r["status"] == "failed" and "would need about" in r["message"]
    assert "more than the memory limit per task (200 MB)" in r["message"]
    assert r["category"] == "limit" and r["limit"] == "memory"
    # the watchdog stops a task over the limit (no estimate): no retry
    job = batch.build_job("cubic")
    s = batch.run_batch(job, [mesh], tmp_path / "o2", workers=1, memory_limit=50_000_000,
                        precheck=False)
    (r,) = _records(tmp_path / "o2" / "batch-report.jsonl")
    assert s.failed == 1 and s.exit_code == 1
    assert r["message"].startswith("it needed more than 50 MB (the memory limit per task)")
    assert r["limit"] == "memory" and r["attempts"] == 1 and r["retries"] == 0
    assert r["category"] == "limit"
    # time limit
    code = main(["batch", "cubic", str(mesh), "-o", str(tmp_path / "o3"), "--workers", "1",
                 "--time-limit", "0.3", "--quiet"])
    assert code == 1
    (r,) = _records(tmp_path / "o3" / "batch-report.jsonl")
    assert r["message"].startswith("it took longer than 0.3 s (the time limit per task)")
    assert r["limit"] == "time" and r["attempts"] == 1 and r["category"] == "limit"
    assert r["finished"]
    assert not (tmp_path / "o3" / "armadillo.obj").exists() and not _no_tmp(tmp_path)


def test_a_dask_local_cluster_gives_the_same_outputs(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    lib = tmp_path / "lib"
    lib.mkdir()
    good = []
    for name in ("hand_lowres.obj", "spot_lowres.obj"):
        (lib / name).write_bytes((TEST_DATA / name).read_bytes())
        good.append(lib / name)
    (lib / "empty.obj").write_text("")
    out = tmp_path / "out"
    # Dask's nanny writes its worker settings (MALLOC_TRIM_THRESHOLD_, OMP_NUM_THREADS=1)
    # into this process's environment: put it back for the rest of the test session
    saved = dict(os.environ)
    try:
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      host="127.0.0.1", dashboard_address=None) as cluster:
            code = main(["batch", "cubic", str(lib), "-o", str(out), "--scheduler",
                         cluster.scheduler_address, "--json", "--quiet"])
    finally:
        os.environ.clear()
        os.environ.update(saved)
    summary = json.loads(capsys.readouterr().out)
    assert code == 1 and summary["executor"] == "dask"
    assert summary["done"] == 2 and summary["failed"] == 1
    for p in good:
        assert (out / p.name).read_bytes() == _reference(p, tmp_path)
    (bad,) = [r for r in _records(out / "batch-report.jsonl") if r["status"] == "failed"]
    assert "empty" in bad["message"].lower() and "Traceback" not in bad["message"]


def test_clean_and_a_project_input_as_the_one_mesh_command(tmp_path, bad_files):
    from app.document import MeshState
    from app.project import Project, save_project
    from app.recipes import LAMBDA_FIELD

    lib = tmp_path / "lib"
    lib.mkdir()
    dup = lib / "duplicates.obj"
    dup.write_bytes(bad_files["duplicates"].read_bytes())
    V, F = icosphere(2)
    state = MeshState.make(V, F).with_field(LAMBDA_FIELD, np.linspace(0.0, 2.0, len(V)))
    scene = save_project(lib / "scene.s3d", Project(state))  # painted λ, no saved settings
    out = tmp_path / "out"
    assert main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet"]) == 1
    recs = {Path(r["input"]).name: r for r in _records(out / "batch-report.jsonl")}
    assert recs["duplicates.obj"]["status"] == "failed"
    assert "--clean" in recs["duplicates.obj"]["message"]
    assert recs["scene.s3d"]["status"] == "done"
    assert Path(recs["scene.s3d"]["output"]) == (out / "scene.obj").resolve()
    assert (out / "scene.obj").read_bytes() == _reference(scene, tmp_path)
    assert main(["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet",
                 "--clean"]) == 0
    recs = _records(out / "batch-report.jsonl")[-2:]
    assert {r["status"] for r in recs} == {"done"}  # --clean changes the key: both run again
    assert (out / "duplicates.obj").read_bytes() == _reference(dup, tmp_path, "--clean")


def test_progress_bar_on_a_terminal_and_no_qt(tmp_path):
    import io

    from rich.console import Console

    from app.cli.batch import _Progress

    buf = io.StringIO()
    bar = _Progress("cubic", quiet=False, console=Console(file=buf, force_terminal=True,
                                                          width=160))
    bar(None, {"total": 3, "done": 0, "failed": 0, "skipped": 1, "remaining": 2})
    bar({"input": "a.obj", "output": "o/a.obj", "status": "failed", "message": "it is empty",
         "seconds": 0.1}, {"total": 3, "done": 0, "failed": 1, "skipped": 1, "remaining": 1})
    bar.close()
    text = buf.getvalue()
    assert "a.obj: it is empty" in text and "failed 1" in text and "skipped 1" in text
    assert "remaining 1" in text and "ETA" in text and "/min" in text
    mesh = tmp_path / "m.obj"
    write_mesh(mesh, *icosphere(1))
    code = (f"import sys\nfrom app.__main__ import main\n"
            f"assert main(['batch', 'cubic', {str(mesh)!r}, '-o', {str(tmp_path / 'o')!r}, "
            f"'--workers', '1', '--quiet']) == 0\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"('PySide6', 'vtkmodules', 'pyvista', 'pyvistaqt')))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.splitlines()[-1] == "[]", r.stdout + r.stderr


@pytest.mark.parametrize("method, flags", [
    ("smooth", ["--iterations", "2"]),
    ("subdivide", ["--method", "loop", "--levels", "1"]),
    ("analogy", ["--style", "octahedron", "--max-iterations", "5"]),
])
def test_other_methods_write_what_their_one_mesh_command_writes(tmp_path, method, flags):
    mesh = tmp_path / "m.obj"
    write_mesh(mesh, *torus(n_major=20, n_minor=10))
    out = tmp_path / "out"
    assert main(["batch", method, str(mesh), "-o", str(out), "--workers", "1", "--quiet",
                 *flags]) == 0
    ref = tmp_path / "ref.obj"
    quiet = [] if method == "subdivide" else ["--quiet"]  # subdivide prints no progress
    assert main([method, str(mesh), "-o", str(ref), *quiet, *flags]) == 0
    assert (out / "m.obj").read_bytes() == ref.read_bytes()


def test_existing_files_are_not_replaced_without_overwrite(tmp_path, capsys):
    """Like every command: a result never replaces a file the batch did not write, unless
    --overwrite (exit 3, nothing run); the batch's own results are written again freely."""
    lib = tmp_path / "lib"
    lib.mkdir()
    V, F = icosphere(2)
    write_mesh(lib / "a.obj", V, F)
    write_mesh(lib / "b.obj", V * 1.1, F)
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.obj").write_text("precious")
    args = ["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet",
            "--max-iterations", "3"]
    assert main(args) == 3
    assert (out / "a.obj").read_text() == "precious" and not (out / "b.obj").exists()
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    assert (out / "a.obj").read_text() != "precious"
    # the batch's own results: a run with other settings writes them again without asking
    assert main(args[:-1] + ["4"]) == 0


def test_the_docs_from_python_example_runs_as_a_script(tmp_path):
    """docs/batch.md's "From Python" example, saved as a file and run with ``python FILE``
    (no ``if __name__ == "__main__":`` guard): the spawned workers must not start the batch
    again (they did, and the run ended with "worker processes keep stopping"; issue 39)."""
    import re

    text = (ROOT / "docs" / "batch.md").read_text()
    section = text[text.index("## From Python"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert "run_batch" in code and "__main__" not in code
    lib = tmp_path / "library"
    lib.mkdir()
    for name in ("spot_lowres.obj", "hand_lowres.obj"):
        (lib / name).write_bytes((TEST_DATA / name).read_bytes())
    (tmp_path / "example.py").write_text(code)
    p = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr[-3000:]
    assert "'done': 2" in p.stdout and "'failed': 0" in p.stdout, p.stdout
    for name in ("spot_lowres.obj", "hand_lowres.obj"):
        assert (tmp_path / "out" / name).stat().st_size > 0


def test_resume_counts_the_records_a_stopped_driver_left_pending(tmp_path):
    """A driver stopped after its workers finished meshes but before it wrote their report
    lines (the Dask scheduler stopped, kill -9): the workers' ``pending/`` records say those
    outputs are this batch's own, so the same command resumes instead of refusing to replace
    them (it exited 3; issue 39, item 1), and nothing runs twice."""
    lib = tmp_path / "lib"
    lib.mkdir()
    for k in range(3):
        V, F = icosphere(2)
        write_mesh(lib / f"m{k}.obj", (V @ _rotation(40 + k).T) * (1 + k), F)
    out = tmp_path / "out"
    argv = ["batch", "cubic", str(lib), "-o", str(out), "--workers", "1", "--quiet"]
    assert main(argv) == 0
    report = out / "batch-report.jsonl"
    lines = report.read_text().splitlines()
    last = json.loads(lines[-1])
    assert last["status"] == "done"
    pending = out / ".batch" / "pending"
    (pending / f"{last['task_id']}.json").write_text(json.dumps(last))
    report.write_text("\n".join(lines[:-1]) + "\n")   # its line never reached the report
    assert main(argv) == 0
    recs = _records(report)
    mine = [r for r in recs if r["input"] == last["input"]]
    assert sum(r["status"] == "done" for r in mine) == 1, mine  # recovered, not run again
    assert any(r.get("recovered") for r in mine)
    assert not list(pending.iterdir())


def test_results_stay_put_when_an_input_from_another_folder_is_added(tmp_path):
    """Each result is placed below its own input's root (issue 39, item 8): adding a mesh from
    another folder moves no result, so a resumed batch skips what it did; an earlier batch's
    output folder inside the library is never taken as input."""
    lib = tmp_path / "lib"
    (lib / "a").mkdir(parents=True)
    (lib / "b").mkdir()
    V, F = icosphere(2)
    write_mesh(lib / "a" / "x.obj", V, F)
    write_mesh(lib / "b" / "y.obj", V * 2, F)
    other = tmp_path / "other"
    other.mkdir()
    write_mesh(other / "z.obj", V * 3, F)
    out = tmp_path / "out"
    base = ["batch", "smooth", "-o", str(out), "--workers", "1", "--quiet", "--iterations", "1"]
    assert main([base[0], base[1], str(lib), *base[2:]]) == 0
    first = {p.relative_to(out).as_posix() for p in out.rglob("*.obj")}
    assert first == {"a/x.obj", "b/y.obj"}
    # an earlier batch's results inside the library: not inputs
    assert main([base[0], base[1], str(lib / "a"), "-o", str(lib / "old-results"),
                 *base[4:]]) == 0
    assert (lib / "old-results" / "x.obj").exists()
    assert main([base[0], base[1], str(lib), str(other / "z.obj"), "--json", *base[2:]]) == 0
    recs = _records(out / "batch-report.jsonl")
    last = recs[-3:]
    assert sorted(Path(r["input"]).name for r in last) == ["x.obj", "y.obj", "z.obj"]
    assert {Path(r["input"]).name: r["status"] for r in last} == {
        "x.obj": "skipped", "y.obj": "skipped", "z.obj": "done"}
    assert {p.relative_to(out).as_posix() for p in out.rglob("*.obj")} == first | {"z.obj"}
    from app.batch import collect_inputs, collect_inputs_with_roots

    assert all("old-results" not in str(p) for p in collect_inputs([lib]))
    found = dict(collect_inputs_with_roots([str(lib / "*" / "*.obj")], out_dir=out))
    assert found == {lib / "a" / "x.obj": lib, lib / "b" / "y.obj": lib}


def test_format_name_exclude_and_a_list_of_inputs(tmp_path):
    """--format, --name, --exclude, --from-list (issue 39, item 12): what a pipeline engineer
    expects of pymeshlab / Blender scripts; a second run skips everything."""
    from algorithms.mesh import read_mesh

    lib = tmp_path / "lib"
    (lib / "keep").mkdir(parents=True)
    (lib / "old").mkdir()
    V, F = icosphere(2)
    write_mesh(lib / "keep" / "x.obj", V, F)
    write_mesh(lib / "old" / "y.obj", V, F)
    write_mesh(lib / "keep" / "x_lowres.obj", V, F)
    extra = tmp_path / "extra"
    extra.mkdir()
    write_mesh(extra / "z.off", V * 2, F)
    listing = tmp_path / "list.txt"
    listing.write_text("# more meshes\nextra/z.off   # relative to this file\n\n")
    out = tmp_path / "out"
    argv = ["batch", "smooth", str(lib), "-o", str(out), "--iterations", "1", "--workers", "1",
            "--quiet", "--format", "ply", "--name", "{stem}_{command}", "--exclude", "old/*",
            "--exclude", "*_lowres.obj", "--from-list", str(listing)]
    assert main(argv) == 0
    made = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.ply"))
    assert made == ["keep/x_smooth.ply", "z_smooth.ply"]
    assert read_mesh(out / "keep" / "x_smooth.ply").F.shape == F.shape
    assert main(argv) == 0
    recs = _records(out / "batch-report.jsonl")
    assert [r["status"] for r in recs[-2:]] == ["skipped", "skipped"]
    with pytest.raises(batch.BatchUsageError, match="fields"):
        batch.output_names([lib / "keep" / "x.obj"], out, name="{nope}")
    with pytest.raises(batch.BatchUsageError, match="file name"):
        batch.output_names([lib / "keep" / "x.obj"], out, name="a/{stem}")


def test_max_failures_stops_the_batch_and_it_goes_on_later(tmp_path, capsys):
    lib = tmp_path / "lib"
    lib.mkdir()
    for k in range(3):
        (lib / f"{k}-broken.obj").write_text("garbage\n")
    V, F = icosphere(2)
    for k in range(2):
        write_mesh(lib / f"good{k}.obj", V, F)
    out = tmp_path / "out"
    argv = ["batch", "smooth", str(lib), "-o", str(out), "--iterations", "1", "--workers", "1",
            "--max-failures", "1"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "stopped after" in err and "--max-failures 1" in err
    recs = _records(out / "batch-report.jsonl")
    assert 1 <= sum(r["status"] == "failed" for r in recs) < 3
    assert sum(r["status"] == "done" for r in recs) < 2     # it stopped before the end
    assert main(argv[:-2]) == 1                              # without the limit: the rest runs
    recs = _records(out / "batch-report.jsonl")
    assert {Path(r["input"]).name for r in recs if r["status"] == "done"} == {"good0.obj",
                                                                              "good1.obj"}


def test_shards_cover_every_input_once_and_run_side_by_side(tmp_path):
    """Issue 39 item 12: ``--shard I/N`` (array jobs). Every input falls in exactly one shard
    (by a hash of its path, so adding inputs moves no other); N shards write into one output
    folder at the same time, each with its own report and state folder."""
    import subprocess
    import sys

    from app.batch import read_report
    from app.batch.inputs import in_shard
    from tests.conftest import ROOT

    lib = tmp_path / "lib"
    (lib / "sub").mkdir(parents=True)
    V, F = icosphere(1)
    names = [f"m{i}.obj" for i in range(6)] + [f"sub/s{i}.obj" for i in range(3)]
    for n in names:
        write_mesh(lib / n, V, F)
    owners = [[i for i in (1, 2, 3) if in_shard(lib / n, lib, (i, 3))] for n in names]
    assert all(len(o) == 1 for o in owners) and len({o[0] for o in owners}) > 1
    out = tmp_path / "out"
    procs = [subprocess.Popen([sys.executable, "-m", "app", "batch", "smooth", str(lib), "-o",
                               str(out), "--shard", f"{i}/3", "--workers", "1", "--quiet"],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for i in (1, 2, 3)]
    results = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], results
    done = {}
    for i in (1, 2, 3):
        recs = {k: r for k, r in read_report(out / f"batch-report.shard-{i}-of-3.jsonl").items()
                if k != "__task_ids__"}
        assert all(r["status"] == "done" for r in recs.values())
        for k in recs:
            assert k not in done  # in one shard only
            done[k] = i
        assert f"shard {i}/3" in results[i - 1][1]
    assert len(done) == len(names)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.obj")) == sorted(names)
    # the library's output folder is not taken as input by a later batch
    from app.batch import collect_inputs_with_roots

    assert all(out not in p.parents for p, _ in collect_inputs_with_roots([tmp_path]))
    from algorithms.errors import Stylize3DError
    from app.batch.inputs import parse_shard

    for bad in ("0/3", "4/3", "x", "1/0"):
        with pytest.raises(Stylize3DError):
            parse_shard(bad)


def test_failed_records_say_their_category_and_every_record_its_times(tmp_path):
    """Issue 39 item 9: report records lacked a failure category, the limit name and times."""
    from app import batch

    lib = tmp_path / "lib"
    lib.mkdir()
    V, F = icosphere(1)
    write_mesh(lib / "good.obj", V, F)
    (lib / "garbage.obj").write_text("this is not a mesh\n")
    write_mesh(lib / "nan.obj", np.where(np.arange(len(V))[:, None] == 0, np.nan, V), F)
    job = batch.build_job("smooth")
    inputs = sorted(lib.glob("*.obj"))
    s = batch.run_batch(job, inputs, tmp_path / "out", workers=1)
    assert s.done == 1 and s.failed == 2
    recs = {Path(r["input"]).name: r for r in _records(tmp_path / "out" / "batch-report.jsonl")}
    assert recs["garbage.obj"]["category"] == "unreadable input"
    assert recs["nan.obj"]["category"] == "invalid mesh"
    assert "category" not in recs["good.obj"]
    for r in recs.values():
        assert r["started"] <= r["finished"] and r["seconds"] >= 0


def test_an_unreachable_scheduler_exits_7_not_5(tmp_path, monkeypatch, capsys):
    """Issue 39 item 9: a network failure had the bad-parameter code (5)."""
    import algorithms.subdivision.data as data_mod

    monkeypatch.setattr(data_mod, "SCHEDULER_TIMEOUT", 2)
    V, F = icosphere(1)
    write_mesh(tmp_path / "m.obj", V, F)
    code = main(["batch", "smooth", str(tmp_path / "m.obj"), "-o", str(tmp_path / "out"),
                 "--scheduler", "tcp://127.0.0.1:1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 7 and "Could not reach the Dask scheduler" in err, err


def test_batch_help_offers_one_lambda_as_batch_accepts(capsys):
    """Issue 39 item 9: the help offered several λ, which batch refuses."""
    from app.batch import method_parser

    lam = next(a for a in method_parser("cubic")._actions if a.dest == "lam")
    assert "A batch takes one value" in lam.help and "Several values" not in lam.help
    import argparse

    from app.cli.deform import add_parsers  # the one-mesh command keeps its text

    root = argparse.ArgumentParser()
    sub = root.add_subparsers()
    add_parsers(sub)
    one = next(a for a in sub.choices["cubic"]._actions if a.dest == "lam")
    assert "Several values" in one.help


def test_a_project_given_as_input_supplies_its_saved_settings(tmp_path):
    """Issue 39 item 3: ``batch cubic blob-painted.s3d`` ignored the project's saved λ 0.4 (the
    one-mesh command uses it); flags given on the command line still win."""
    import shutil

    from algorithms.mesh import read_mesh
    from app.project import read_project
    from tests.conftest import SAMPLES

    proj = tmp_path / "blob-painted.s3d"
    shutil.copy(SAMPLES / "blob-painted.s3d", proj)
    saved = read_project(proj).panels["Cubic"]["params"]
    assert saved["lam"] == 0.4
    for flags, lam in (([], 0.4), (["--lambda", "0.25"], 0.25)):
        out = tmp_path / f"out{lam}"
        assert main(["batch", "cubic", str(proj), "-o", str(out), "--workers", "1", "--quiet",
                     "--max-iterations", "5", *flags]) == 0
        (r,) = _records(out / "batch-report.jsonl")
        one = tmp_path / f"one{lam}.obj"
        assert main(["cubic", str(proj), "-o", str(one), "--max-iterations", "5", *flags]) == 0
        np.testing.assert_array_equal(read_mesh(out / "blob-painted.obj").V, read_mesh(one).V)
        assert ("lam = 0.4" in " ".join(r.get("notes", []))) == (lam == 0.4)


def test_a_worker_of_another_version_refuses_the_job(tmp_path):
    """Issue 39 item 10: workers check the driver's version (a Dask worker with another
    installation would compute other results under the same report key)."""
    import dataclasses

    from app import __version__, batch

    V, F = icosphere(1)
    write_mesh(tmp_path / "m.obj", V, F)
    job = batch.build_job("smooth")
    assert job.version == __version__
    old = dataclasses.replace(job, version="0.0.1-elsewhere")
    s = batch.run_batch(old, [tmp_path / "m.obj"], tmp_path / "out", workers=1)
    (r,) = _records(tmp_path / "out" / "batch-report.jsonl")
    assert s.failed == 1 and r["category"] == "version mismatch"
    assert "0.0.1-elsewhere" in r["message"] and not (tmp_path / "out" / "m.obj").exists()


def test_progress_keeps_its_times_at_80_columns_and_one_line_per_mesh(capsys):
    """Issue 39 item 9: at 80 columns the bar cut its times; a failure's several-line report
    made several stderr lines for one mesh."""
    import io

    from rich.console import Console

    from app.cli.batch import _Progress, _one_line

    buf = io.StringIO()
    bar = _Progress("cubic", quiet=False, console=Console(file=buf, force_terminal=True,
                                                          width=80))
    counts = {"total": 3, "done": 1, "failed": 0, "skipped": 0, "remaining": 2}
    bar(None, counts)
    bar({"input": "a.obj", "output": "o/a.obj", "status": "done", "message": "",
         "seconds": 0.1}, counts)
    bar.close()
    last = [ln for ln in buf.getvalue().splitlines() if "cubic" in ln][-1]
    assert "ETA" in last and "0:00:0" in last and "left" in last, last
    msg = "a.obj cannot be processed as it is:\nMesh: 3 vertices\nErrors:\n  - NaN coordinates"
    assert _one_line(msg) == "a.obj cannot be processed as it is: Mesh: 3 vertices Errors: " \
                             "NaN coordinates"
    plain = _Progress("cubic", quiet=False)  # stderr is not a terminal here: plain lines
    plain({"input": "a.obj", "output": "o/a.obj", "status": "failed", "message": msg,
           "seconds": 0.1}, {**counts, "failed": 1})
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "NaN coordinates" in err


def test_dask_log_lines_lose_their_tracebacks_while_a_batch_runs():
    """Issue 39 item 1: when the scheduler stopped, Dask's client logged "ERROR -" with two
    tracebacks before the batch's plain message (reproduced by hand with `dask scheduler`
    killed mid-batch; with this filter stderr holds the one message, and the same command
    finished the batch on a new scheduler)."""
    import io
    import logging

    from app.batch.driver import _quiet_dask_tracebacks

    buf = io.StringIO()
    h = logging.StreamHandler(buf)
    lg = logging.getLogger("distributed.client")
    lg.addHandler(h)
    try:
        undo = _quiet_dask_tracebacks()
        try:
            raise ConnectionResetError("Connection reset by peer")
        except ConnectionResetError:
            lg.error("", exc_info=True)                       # Dask's empty "ERROR -" line
            lg.error("Lost connection to the scheduler", exc_info=True)
        undo()
        assert buf.getvalue() == "Lost connection to the scheduler\n"
        try:
            raise ConnectionResetError("again")
        except ConnectionResetError:
            lg.error("after the batch", exc_info=True)
        assert "Traceback" in buf.getvalue()  # only while the batch runs
    finally:
        lg.removeHandler(h)
