"""CLI `stylize3d augment` / `augment-train` (issue 40): the ImageFolder layout and manifest,
resuming and reproducing, the worker pool, refusals, and weights the other commands load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from algorithms.adversarial.shapes import subject  # noqa: E402
from algorithms.mesh import write_mesh  # noqa: E402
from app.cli import main  # noqa: E402

ORANGE = Path(__file__).resolve().parents[2] / "resources" / "samples" / "orange.obj"
TINY = ["--resolution", "32", "--supersample", "1", "--iterations", "2"]


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    d = tmp_path_factory.mktemp("aug")
    out = {}
    for name in ("orange", "golf ball"):
        V, F, _ = subject(name)
        out[name] = d / f"{name.replace(' ', '_')}.obj"
        write_mesh(out[name], V, F)
    return out


def augment(capsys, *argv):
    code = main(["augment", *argv, "--json"])
    captured = capsys.readouterr()
    return code, json.loads(captured.out), captured.err


def manifest(ds):
    return [json.loads(line) for line in (Path(ds) / "manifest.jsonl").read_text().splitlines()]


def pngs(ds, label="orange"):
    return {p.name: p.read_bytes() for p in sorted((Path(ds) / label).glob("*.png"))}


def test_layout_manifest_resume_and_workers(meshes, tmp_path, capsys):
    ds = tmp_path / "ds"
    args = [str(ORANGE), str(meshes["orange"]), "--label", "orange", "-o", str(ds), "--count",
            "3", "--lighting", "random", "--color", "1", "0.48", "0.05", *TINY]
    code, rep, err = augment(capsys, *args, "--workers", "1")
    assert code == 0, err
    assert rep["made"] == 6 and rep["skipped"] == 0 and rep["label"] == "orange"
    assert rep["images_per_second"] > 0 and rep["lighting"] == "random"
    assert sorted(pngs(ds)) == [f"{i:04d}.png" for i in range(6)]
    recs = manifest(ds)
    assert [r["file"] for r in recs] == [f"orange/{i:04d}.png" for i in range(6)]
    assert [r["mesh"] for r in recs] == [str(ORANGE)] * 3 + [str(meshes["orange"])] * 3
    for r in recs:
        assert r["mode"] == "random" and r["seed"] == 0 and r["label"] == "orange"
        assert set(r["view"]) == {"azimuth", "elevation", "width"}
        assert np.array(r["sh"]).shape == (49, 3) and r["norm"] <= 0.5
        for k in ("top1_before", "top1_after"):
            assert set(r[k]) == {"class", "name", "probability"}
        assert r["background"] in (0.0, 0.25, 0.5, 0.75, 1.0)
    from PIL import Image

    with Image.open(ds / "orange" / "0000.png") as im:
        assert im.size == (32, 32) and im.mode == "RGB"
    before = pngs(ds)
    # again: nothing made, nothing appended
    code, rep, _ = augment(capsys, *args)
    assert code == 0 and rep["made"] == 0 and rep["skipped"] == 6
    assert len(manifest(ds)) == 6
    # a lost image is made again, bit for bit the same (same seed)
    (ds / "orange" / "0004.png").unlink()
    code, rep, _ = augment(capsys, *args)
    assert code == 0 and rep["made"] == 1 and rep["skipped"] == 5
    assert pngs(ds) == before
    # two worker processes make the same images
    ds2 = tmp_path / "ds2"
    code, rep, err = augment(capsys, *[str(ds2) if a == str(ds) else a for a in args],
                             "--workers", "2")
    assert code == 0, err
    assert rep["workers"] == 2 and pngs(ds2) == before
    assert sorted(r["file"] for r in manifest(ds2)) == sorted(f"orange/{n}" for n in before)
    # another seed would replace them: refused (exit 3) unless --overwrite
    code = main(["augment", *args, "--seed", "1"])
    err = capsys.readouterr().err
    assert code == 3 and "other settings" in err and "--overwrite" in err
    assert pngs(ds) == before
    code, rep, _ = augment(capsys, *args, "--seed", "1", "--overwrite")
    assert code == 0 and rep["made"] == 6 and pngs(ds) != before


def test_adversarial_mode_records_the_attack(meshes, tmp_path, capsys):
    import torch

    ds = tmp_path / "adv"
    threads = torch.get_num_threads()
    torch.set_num_threads(2)   # in this process; the images are made with one thread anyway
    try:
        code, rep, err = augment(capsys, str(ORANGE), "--label", "orange", "-o", str(ds),
                                 "--count", "6", "--radius", "0.1", "--resolution", "48",
                                 "--supersample", "1", "--iterations", "2")
    finally:
        torch.set_num_threads(threads)
    assert code == 0, err
    recs = manifest(ds)
    assert len(recs) == 6 and all(r["mode"] == "adversarial" for r in recs)
    assert all(np.array(r["sh_start"]).shape == (49, 3) for r in recs)
    attacked = [r for r in recs if r["iterations"] > 0]
    assert len(attacked) >= 2
    assert all(r["true_probability_after"] < r["true_probability_before"] for r in attacked)
    assert rep["mean_true_probability_after"] < rep["mean_true_probability_before"]
    for r in recs:
        assert r["iterations"] <= 2 and (r["fooled"] or r["note"])
        assert r["norm"] <= 0.1 + 1e-12
    assert torch.get_num_threads() == threads
    # the attack's images do not depend on where they are made (worker processes: one
    # PyTorch thread each)
    ds2 = tmp_path / "adv2"
    code, _, err = augment(capsys, str(ORANGE), str(ORANGE), "--label", "orange", "-o",
                           str(ds2), "--count", "6", "--radius", "0.1", "--resolution", "48",
                           "--supersample", "1", "--iterations", "2", "--workers", "2")
    assert code == 0, err
    assert {k: v for k, v in pngs(ds2).items() if int(k[:4]) < 6} == pngs(ds)
    # how: each image is computed with one thread, the caller's count restored in between
    from app.recipes.augment import _one_thread

    def probe():
        for _ in range(3):
            yield torch.get_num_threads()

    torch.set_num_threads(2)
    try:
        seen = []
        for n in _one_thread(probe()):
            seen.append((n, torch.get_num_threads()))
    finally:
        torch.set_num_threads(threads)
    assert seen == [(1, 2)] * 3


def test_bad_input_gets_plain_messages(meshes, tmp_path, capsys):
    ds = str(tmp_path / "ds")
    assert main(["augment", str(tmp_path / "missing.obj"), "--label", "orange", "-o", ds]) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert main(["augment", str(ORANGE), "--label", "oragne", "-o", ds, *TINY]) == 5
    err = capsys.readouterr().err
    assert "Did you mean" in err and "'orange'" in err and "Traceback" not in err
    other = tmp_path / "photos"
    other.mkdir()
    (other / "holiday.jpg").write_bytes(b"x")
    assert main(["augment", str(ORANGE), "--label", "orange", "-o", str(other), *TINY]) == 3
    assert "not a dataset" in capsys.readouterr().err
    assert main(["augment", str(ORANGE), "--label", "orange", "-o", ds, "--lighting",
                 "sideways"]) == 2                                 # argparse: a bad choice
    capsys.readouterr()
    code = main(["augment", str(ORANGE), "--label", "oragne", "-o", ds, "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert code == 5 and rep["ok"] is False and rep["exit_code"] == 5
    assert main(["augment-train", str(tmp_path / "nothing"), "-o", str(tmp_path / "w.pt")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["augment-train", ds, "-o", str(tmp_path / "w.txt")]) == 5
    capsys.readouterr()


def test_augment_train_weights_load_and_improve_on_the_images(meshes, tmp_path, capsys):
    from algorithms.adversarial import classify, default_classifier, load_classifier, \
        resolve_label

    ds = tmp_path / "ds"
    for name, mesh, colour in (("orange", meshes["orange"], ["1", "0.48", "0.05"]),
                               ("golf ball", meshes["golf ball"], ["0.95", "0.95", "0.95"])):
        code, _, err = augment(capsys, str(mesh), "--label", name, "-o", str(ds), "--count",
                               "8", "--lighting", "random", "--color", *colour, *TINY)
        assert code == 0, err
    w = tmp_path / "w.pt"
    code = main(["augment-train", str(ds), "-o", str(w), "--epochs", "8", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    rep = json.loads(captured.out)
    assert rep["classes"] == ["orange", "golf ball"] or rep["classes"] == ["golf ball", "orange"]
    assert rep["images"] == 16 and rep["epochs"] == 8
    assert rep["accuracy_after"] > rep["accuracy_before"] and rep["accuracy_after"] >= 0.9
    assert rep["loss_after"] < rep["loss_before"]
    # measured independently: the weights file against the base classifier on the same PNGs
    from PIL import Image

    clf = load_classifier(w)
    names = [n.split(",")[0] for n in clf.class_names]
    assert sorted(names) == ["golf ball", "orange"]
    imgs, labels = [], []
    for label in ("orange", "golf ball"):
        for p in sorted((ds / label).glob("*.png")):
            with Image.open(p) as im:
                imgs.append(np.asarray(im, dtype=np.float32) / 255)
            labels.append(names.index(label))
    imgs, labels = np.stack(imgs), np.array(labels)
    base = default_classifier()
    idx = [resolve_label(n, base.class_names) for n in names]
    acc_base = (classify(base, imgs)[:, idx].argmax(1) == labels).mean()
    acc_new = (classify(clf, imgs).argmax(1) == labels).mean()
    assert acc_new > acc_base and acc_new == pytest.approx(rep["accuracy_after"])
    # the existing weights are not replaced without --overwrite
    assert main(["augment-train", str(ds), "-o", str(w), "--epochs", "1"]) == 3
    capsys.readouterr()
    # `adversary --classifier W.pt` and `augment --classifier W.pt` use them (their classes)
    code = main(["adversary", str(meshes["golf ball"]), "--classifier", str(w), "--iterations",
                 "1", "--resolution", "32", "--supersample", "1", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert json.loads(captured.out)["views"][0]["label_before"] in ("golf ball", "orange")
    code, rep, err = augment(capsys, str(meshes["golf ball"]), "--label", "golf ball", "-o",
                             str(tmp_path / "round2"), "--count", "2", "--classifier", str(w),
                             *TINY)
    assert code == 0, err
    assert all(r["classifier"] == "w.pt" for r in manifest(tmp_path / "round2"))
    assert main(["augment", str(meshes["golf ball"]), "--label", "tench", "-o",
                 str(tmp_path / "round3"), "--classifier", str(w), *TINY]) == 5
    capsys.readouterr()
