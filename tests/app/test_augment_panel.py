"""The Adversarial lighting panel's *Make training images…* (issue 40) with real widgets: the
job runs on the window's job runner with progress, Stop keeps what was made, the document is
unchanged, a second run adds only the missing images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

TITLE = "Adversarial lighting"
ORANGE = Path(__file__).resolve().parents[2] / "resources" / "samples" / "orange.obj"


def open_panel(window, qtbot):
    panel = window.panels[TITLE]
    panel.raise_()
    with qtbot.waitSignal(panel.classified, timeout=60000):
        assert window.open_path(ORANGE)
    return panel


def small(panel, count, lighting="adversarial"):
    f = panel.augment_form
    f.set_value("count", count)
    f.set_value("resolution", 32)
    f.set_value("supersample", 1)
    f.set_value("iterations", 2)
    f.set_value("lighting", lighting)


def manifest(folder):
    p = Path(folder) / "manifest.jsonl"
    return [json.loads(line) for line in p.read_text().splitlines()] if p.is_file() else []


def test_make_training_images_streams_stops_and_resumes(window, qtbot, tmp_path, dialogs):
    panel = open_panel(window, qtbot)
    assert panel.augment_button.isEnabled() and panel.augment_button.toolTip()
    V0 = np.array(window.document.V)
    panel.true_edit.setText("orange")
    small(panel, 3)
    seen = []
    window.runner.preview.connect(lambda s: seen.append(s.iteration))
    ds = tmp_path / "ds"
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        assert panel.make_training_images(str(ds))
        assert window.runner.busy and window.runner.name == TITLE   # on the worker thread
        assert not panel.augment_button.isEnabled()
    assert sorted(p.name for p in (ds / "orange").iterdir()) == ["0000.png", "0001.png",
                                                                 "0002.png"]
    recs = manifest(ds)
    assert [r["file"] for r in recs] == ["orange/0000.png", "orange/0001.png",
                                         "orange/0002.png"]
    assert all(r["mode"] == "adversarial" and r["label"] == "orange" for r in recs)
    assert seen and seen == sorted(seen) and set(seen) <= {1, 2, 3}   # streamed per image
    assert panel.augment_summary["made"] == 3
    assert "3 image(s) made" in panel.status_label.text()
    assert window.undo_stack.count() == 0                         # the document is unchanged
    np.testing.assert_array_equal(window.document.V, V0)
    # again with the same settings: nothing to make, nothing started
    assert not panel.make_training_images(str(ds))
    assert "already" in panel.status_label.text()

    # a long run, stopped after its first image: what was made stays, listed in the manifest
    small(panel, 40, "random")
    ds2 = tmp_path / "ds2"
    n = len(seen)
    assert panel.make_training_images(str(ds2))
    qtbot.waitUntil(lambda: len(seen) > n, timeout=60000)
    assert panel.stop_button.isEnabled()
    with qtbot.waitSignal(window.runner.cancelled, timeout=60000):
        panel.stop_button.click()
    pngs = sorted((ds2 / "orange").glob("*.png"))
    assert 1 <= len(pngs) < 40
    assert {r["file"] for r in manifest(ds2)} == {f"orange/{p.name}" for p in pngs}
    assert "kept" in panel.status_label.text()
    np.testing.assert_array_equal(window.document.V, V0)
    assert window.undo_stack.count() == 0
    # the next run makes only the missing images
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        assert panel.make_training_images(str(ds2))
    assert panel.augment_summary["skipped"] == len(pngs)
    assert panel.augment_summary["made"] == 40 - len(pngs)
    assert len(list((ds2 / "orange").glob("*.png"))) == 40

    # other settings into the same folder: the panel asks; "Cancel" changes nothing
    small(panel, 3, "none")
    dialogs.answers.append("Cancel")
    before = (ds / "manifest.jsonl").read_bytes()
    assert not panel.make_training_images(str(ds))
    assert dialogs.questions and "other settings" in dialogs.questions[-1][1]
    assert (ds / "manifest.jsonl").read_bytes() == before


def test_the_panel_loads_weights_trained_on_its_images(window, qtbot, tmp_path):
    """Images from the panel, fine-tuned by the recipe `augment-train` runs, loaded back with
    Load…: the panel classifies with the dataset's classes."""
    from algorithms.adversarial.finetune import FinetuneParams, save_finetuned
    from app.recipes.augment import train_steps

    panel = open_panel(window, qtbot)
    for label, lighting in (("orange", "none"), ("lemon", "random")):
        panel.true_edit.setText(label)
        small(panel, 4, lighting)
        with qtbot.waitSignal(window.runner.finished, timeout=120000):
            assert panel.make_training_images(str(tmp_path / "ds"))
    steps = list(train_steps([tmp_path / "ds"], FinetuneParams(epochs=3)))
    w = tmp_path / "w.pt"
    save_finetuned(w, steps[-1], steps[-1].class_indices)
    with qtbot.waitSignal(panel.classified, timeout=60000):
        assert panel.load_classifier(str(w))
    assert "2 classes" in panel.classifier_name
    assert {n.split(",")[0] for n in panel.class_names()} == {"orange", "lemon"}
    names = [n for n, _p in panel.top5_view.entries]
    assert set(names) == {"orange", "lemon"}
    assert sum(p for _n, p in panel.top5_view.entries) == pytest.approx(1.0, abs=1e-4)
