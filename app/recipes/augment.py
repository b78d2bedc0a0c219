"""Recipe of the Adversarial lighting panel's *Make training images…* and of ``stylize3d
augment`` / ``augment-train`` (thesis §3.5: rendered adversarial data augmentation;
:mod:`algorithms.adversarial.augment`, :mod:`algorithms.adversarial.finetune`).

A dataset is an ImageFolder: ``DATASET/LABEL/NNNN.png`` (``LABEL`` the short name of the true
class, e.g. ``orange``; ``NNNN = mesh index x count + image index``) and
``DATASET/manifest.jsonl``, one JSON object per image written (appended, flushed and
fsync'ed after its PNG, the batch report's writer): ``file``, ``mesh``, ``label``, ``class``,
``classifier``, ``key`` and the image's record (view, background, SH coefficients ``sh``, mode,
seed, the classifier's ``top1_before`` / ``top1_after``, ..., see
:func:`algorithms.adversarial.augment.augment_iter`).

Resuming: an image whose PNG exists and whose last manifest record has the same ``key`` (a hash
of the mesh, its colours, the label, the classifier, the params and the image's place) is
skipped; the same seed gives the same images, bit for bit, whatever the number of worker
processes (each image is computed with one PyTorch thread: the attack's gradients round
differently with other thread counts). A PNG that exists with another key, or a folder
that holds files but no manifest, is refused (:class:`~algorithms.errors.MeshWriteError`, exit
status 3) unless ``overwrite`` is set.

``options`` of the recipe (one mesh; the document's in the panel): ``dataset`` (folder),
``label`` (the true class, a name or number of the classifier's classes), ``mesh`` (its name in
the manifest), ``mesh_index`` (0), ``classifier`` (a blob reference, None = the installed one),
``color`` / ``face_colors`` (as the attack recipes'), ``overwrite`` (False), ``indices`` (the
images to make; None = those the plan finds missing) and ``skipped`` (with ``indices``: how many
the caller found made, for the summary).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Iterator

import numpy as np

from algorithms.steps import Step
from app.recipes import Recipe, add_blob, blob_bytes, register, unchanged_result

__all__ = ["AUGMENT", "MANIFEST", "DatasetStep", "image_steps", "augment_outcome",
           "read_manifest", "plan_images", "plan_request", "label_of", "dataset_steps",
           "read_dataset", "train_steps", "check_dataset_folder"]

AUGMENT = "Adversarial lighting: training images"
MANIFEST = "manifest.jsonl"


# ------------------------------------------------------------------------------ the dataset
def read_manifest(dataset) -> dict[str, dict]:
    """The last record of each image file (``"LABEL/NNNN.png"``) in ``DATASET/manifest.jsonl``
    (a line cut short by a crash is ignored)."""
    from app.batch.driver import json_records

    return {rec["file"]: rec for rec in json_records(Path(dataset) / MANIFEST)
            if isinstance(rec.get("file"), str)}


def label_of(options: dict, class_names) -> tuple[int, str]:
    """``(class index, folder name)`` of ``options["label"]`` among ``class_names``."""
    from algorithms.adversarial.labels import resolve_label, short_name
    from algorithms.errors import ParameterError

    text = str(options.get("label") or "").strip()
    if not text:
        raise ParameterError("Say what the object is (--label, or the panel's True label): the "
                             "images go into a folder of that name.")
    k = resolve_label(text, class_names)
    return k, short_name(class_names[k]).replace("/", "-")


def _mesh_digest(state, options: dict) -> str:
    h = hashlib.sha256()
    for a in (np.ascontiguousarray(state.V, dtype=np.float64),
              np.ascontiguousarray(state.F, dtype=np.int64)):
        h.update(a.tobytes())
    colours = options.get("face_colors")
    h.update(str(colours if colours else options.get("color")).encode())
    return h.hexdigest()


def _keys(state, params, options: dict, folder: str, indices) -> dict[int, str]:
    settings = {k: v for k, v in dataclasses.asdict(params).items() if k != "count"}
    common = json.dumps({"mesh": _mesh_digest(state, options), "label": folder,
                         "classifier": options.get("classifier") or "default",
                         "settings": settings, "count": int(params.count),
                         "mesh_index": int(options.get("mesh_index", 0))}, sort_keys=True)
    return {j: hashlib.sha256(f"{common}:{j}".encode()).hexdigest()[:32] for j in indices}


def _file_of(folder: str, params, mesh_index: int, j: int) -> str:
    return f"{folder}/{mesh_index * params.count + j:04d}.png"


def check_dataset_folder(dataset, overwrite: bool) -> None:
    """A folder that holds files but no manifest is not one of ours: refused without
    ``overwrite``."""
    from algorithms.errors import MeshWriteError

    d = Path(dataset)
    if d.exists() and not d.is_dir():
        raise MeshWriteError(f"{dataset} is a file, not a folder: name a folder for the "
                             "dataset.")
    if d.is_dir() and not (d / MANIFEST).is_file() and any(d.iterdir()) and not overwrite:
        raise MeshWriteError(f"{dataset} is not empty and holds no {MANIFEST}: it is not a "
                             "dataset this command made. Choose a new or empty folder, or pass "
                             "--overwrite to write into it anyway.")


def plan_images(state, params, options: dict, folder: str) -> tuple[list[int], list[int]]:
    """``(to make, already done)`` image indices of one mesh (module docstring); an existing
    PNG made with other settings raises MeshWriteError unless ``options["overwrite"]``."""
    from algorithms.errors import MeshWriteError

    dataset = Path(options["dataset"])
    check_dataset_folder(dataset, bool(options.get("overwrite")))
    k = int(options.get("mesh_index", 0))
    keys = _keys(state, params, options, folder, range(params.count))
    manifest = read_manifest(dataset)
    todo, done, clash = [], [], []
    for j in range(params.count):
        f = _file_of(folder, params, k, j)
        if (dataset / f).is_file():
            if manifest.get(f, {}).get("key") == keys[j]:
                done.append(j)
                continue
            clash.append(f)
        todo.append(j)
    if clash and not options.get("overwrite"):
        raise MeshWriteError(
            f"{len(clash)} image(s) of {dataset} were made with other settings, another mesh "
            f"or not by this command (first: {clash[0]}); pass --overwrite to replace them, or "
            "choose another dataset folder.")
    return todo, done


def plan_request(state, params, options: dict, class_names) -> tuple[list[int], list[int]]:
    """:func:`plan_images` of a run's options, the label resolved among ``class_names``
    (no classifier is loaded: quick enough for the GUI thread)."""
    from algorithms.adversarial.augment import check_params

    check_params(params)
    return plan_images(state, params, options, label_of(options, class_names)[1])


def _write_png(path: Path, image: np.ndarray) -> None:
    import io

    from PIL import Image

    from algorithms.mesh.io import atomic_write

    a = (np.clip(np.asarray(image, dtype=np.float64), 0, 1) * 255 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(a, "RGB").save(buf, format="PNG")
    data = buf.getvalue()
    atomic_write(path, lambda fh: fh.write(data))


class _Manifest:
    """Appends records to ``DATASET/manifest.jsonl`` (the batch report's writer)."""

    def __init__(self, dataset):
        from app.batch.driver import ReportWriter

        self._w = ReportWriter(Path(dataset) / MANIFEST)

    def write(self, rec: dict) -> None:
        self._w.write(rec)

    def close(self) -> None:
        self._w.close()


# ------------------------------------------------------------------------------ one mesh
def _one_thread(steps):
    """``steps`` computed with one PyTorch thread (restored between steps): the attack's
    gradients round differently with other thread counts, and an image must not depend on
    whether it was made here or in a worker process (one thread each), nor on ``--workers``
    (the same seed gives the same images, bit for bit)."""
    from algorithms.torch_threads import one_torch_thread

    it = iter(steps)
    while True:
        with one_torch_thread():
            try:
                step = next(it)
            except StopIteration:
                return
        yield step


@dataclasses.dataclass
class DatasetStep(Step):
    """An image written (``record``, ``image``) or, at the end of a dataset run, its summary
    (``summary``)."""

    image: np.ndarray | None = None
    record: dict = dataclasses.field(default_factory=dict)
    summary: dict = dataclasses.field(default_factory=dict)


def image_steps(state, params, options: dict | None = None, cache: dict | None = None
                ) -> Iterator[DatasetStep]:
    """Make and write one mesh's missing images (module docstring), one step per image; the
    last step's ``summary`` counts made, skipped and fooled images."""
    from algorithms.adversarial.attack import prepare_scene
    from algorithms.adversarial.augment import augment_iter, base_lighting, summarize
    from app.recipes import adversarial as adv

    options = dict(options or {})
    clf = adv.classifier_of(options.get("classifier"))
    label, folder = label_of(options, clf.class_names)
    dataset = Path(options["dataset"])
    k = int(options.get("mesh_index", 0))
    if options.get("indices") is None:
        todo, done = plan_images(state, params, options, folder)
    else:
        todo = [int(j) for j in options["indices"]]
        done = [None] * int(options.get("skipped", 0))
    keys = _keys(state, params, options, folder, todo)
    (dataset / folder).mkdir(parents=True, exist_ok=True)
    scene = prepare_scene(np.asarray(state.V), np.asarray(state.F),
                          albedo=adv.albedo_of(state, options),
                          lighting=base_lighting(params.base_lighting))  # (each image: its own)
    manifest = _Manifest(dataset) if options.get("manifest", True) else None
    records = []
    try:
        for step in _one_thread(augment_iter(scene, clf, label, params, todo, mesh_index=k)):
            rec = {"file": _file_of(folder, params, k, step.record["index"]),
                   "mesh": str(options.get("mesh") or "mesh"), "label": folder,
                   "class": label, "classifier": getattr(clf, "name", "classifier"),
                   "key": keys[step.record["index"]], **step.record}
            _write_png(dataset / rec["file"], step.image)
            if manifest is not None:
                manifest.write(rec)
            records.append(rec)
            yield DatasetStep(step.iteration, step.total, step.V, step.metrics,
                              f"{rec['file']}: {step.message.split(': ', 1)[1]}",
                              image=step.image, record=rec)
    finally:
        if manifest is not None:
            manifest.close()
    summary = {**summarize(records), "made": len(records), "skipped": len(done),
               "dataset": str(dataset), "label": folder}
    yield DatasetStep(len(todo), len(todo), np.asarray(state.V), {}, _summary_text(summary),
                      summary=summary)


def _summary_text(s: dict) -> str:
    text = f"{s['made']} image(s) made, {s['skipped']} already there"
    if s.get("made"):
        text += (f"; the classifier missed '{s['label']}' on {s['fooled']} of them (true "
                 f"class {100 * s['mean_true_probability_before']:.0f}% -> "
                 f"{100 * s['mean_true_probability_after']:.0f}% on average)")
    return text + f"; in {s['dataset']}"


def augment_outcome(last) -> dict:
    """The last step's summary (made, skipped, fooled, mean true-class probabilities)."""
    return dict(getattr(last, "summary", {}) or {})


# ------------------------------------------------------------------------------ many meshes
def _task(V, F, params, options: dict, blobs: dict) -> list[dict]:
    """A worker process's share: images ``options["indices"]`` of one mesh (no manifest: the
    caller appends the records it gets back)."""
    from app.document import MeshState

    for ref, data in blobs.items():
        add_blob(ref, data)
    state = MeshState.make(V, F)
    return [s.record for s in image_steps(state, params, {**options, "manifest": False})
            if s.record]


def dataset_steps(meshes, params, options: dict, *, workers: int = 1, chunk: int = 10
                  ) -> Iterator[DatasetStep]:
    """Images of several meshes: ``meshes`` a list of ``(name, state, options of the mesh)``
    (the mesh's colours); ``options`` the common ones (dataset, label, classifier, overwrite).
    Plans every mesh first (so a refusal writes nothing), then makes the images here
    (``workers`` 1) or in a pool of worker processes (the batch's, :func:`app.batch.driver.
    process_pool`), ``chunk`` images per task; the manifest is written here. One step per
    image, then one with the ``summary``."""
    from algorithms.adversarial.augment import check_params, summarize
    from app.recipes import adversarial as adv
    from app.recipes import blob_refs

    check_params(params)
    check_dataset_folder(options["dataset"], bool(options.get("overwrite")))
    clf = adv.classifier_of(options.get("classifier"))
    _, folder = label_of(options, clf.class_names)
    plans, skipped = [], 0
    for k, (name, state, own) in enumerate(meshes):
        opts = {**options, **own, "mesh": name, "mesh_index": k}
        todo, done = plan_images(state, params, opts, folder)
        skipped += len(done)
        plans += [(state, {**opts, "indices": todo[i:i + chunk]})
                  for i in range(0, len(todo), chunk)]
    total = sum(len(o["indices"]) for _, o in plans)
    records: list[dict] = []
    manifest = _Manifest(options["dataset"])

    def finished(recs):
        for rec in recs:
            manifest.write(rec)
            records.append(rec)
            yield DatasetStep(len(records), total, np.zeros((0, 3)),
                              {"true_probability": rec["true_probability_after"]},
                              f"{rec['file']}: {rec['top1_after']['name']} "
                              f"{100 * rec['top1_after']['probability']:.0f}%", record=rec)

    try:
        if workers <= 1 or len(plans) <= 1:
            for state, opts in plans:
                for s in image_steps(state, params, {**opts, "manifest": False}):
                    if s.record:
                        yield from finished([s.record])
        else:
            import concurrent.futures as cf

            from app.batch.driver import process_pool

            with process_pool(min(workers, len(plans))) as ex:
                futures = []
                for state, opts in plans:
                    blobs = {r: blob_bytes(r) for r in blob_refs(opts)}
                    futures.append(ex.submit(_task, np.asarray(state.V), np.asarray(state.F),
                                             params, opts, blobs))
                for fut in cf.as_completed(futures):
                    yield from finished(fut.result())
    finally:
        manifest.close()
    summary = {**summarize(records), "made": len(records), "skipped": skipped,
               "dataset": str(options["dataset"]), "label": folder, "workers": workers}
    yield DatasetStep(total, total, np.zeros((0, 3)), {}, _summary_text(summary),
                      summary=summary)


# ------------------------------------------------------------------------------ training
def read_dataset(folders, class_names) -> tuple[np.ndarray, np.ndarray, list[int], list[str]]:
    """The PNG images of ImageFolder datasets: ``(images (N, S, S, 3) float32, labels (N,) in
    0..K-1, class indices (K,) in ``class_names``, files)``; the classes are the folders'
    names resolved among ``class_names`` (an unknown name is refused with close names), in
    the order of their class index. All images must have one size."""
    from PIL import Image

    from algorithms.adversarial.labels import resolve_label
    from algorithms.errors import MeshReadError, ParameterError

    found: dict[int, list[Path]] = {}
    for d in folders:
        d = Path(d)
        if not d.is_dir():
            raise MeshReadError(f"The dataset folder {d} does not exist.")
        subs = sorted(p for p in d.iterdir() if p.is_dir() and any(p.glob("*.png")))
        if not subs:
            raise MeshReadError(f"{d} holds no LABEL/*.png images (make them with stylize3d "
                                "augment).")
        for s in subs:
            try:
                k = resolve_label(s.name, class_names)
            except ParameterError as e:
                raise ParameterError(f"The folder {s} is not named after a class of the "
                                     f"classifier: {e}") from None
            found.setdefault(k, []).extend(sorted(s.glob("*.png")))
    classes = sorted(found)
    images, labels, files = [], [], []
    for c, k in enumerate(classes):
        for f in found[k]:
            try:
                with Image.open(f) as im:
                    a = np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0
            except OSError as e:
                raise MeshReadError(f"{f} is not a readable image ({e}).") from None
            if images and a.shape != images[0].shape:
                raise ParameterError(f"{f} is {a.shape[1]} x {a.shape[0]} pixels, the first "
                                     f"image {images[0].shape[1]} x {images[0].shape[0]}: "
                                     "make all images with one --resolution.")
            images.append(a)
            labels.append(c)
            files.append(os.fspath(f))
    return np.stack(images), np.asarray(labels, dtype=np.int64), classes, files


def train_steps(folders, params, options: dict | None = None):
    """Fine-tune the classifier (``options["classifier"]``: a blob reference, None = the
    installed one) on the datasets ``folders``: the steps of
    :func:`algorithms.adversarial.finetune.finetune_iter` (one per epoch, iteration 0 = the
    restricted base); each carries ``class_indices`` and ``files``."""
    from algorithms.adversarial.finetune import finetune_iter
    from app.recipes import adversarial as adv

    options = options or {}
    clf = adv.classifier_of(options.get("classifier"))
    images, labels, classes, files = read_dataset(folders, clf.class_names)
    for step in finetune_iter(clf, images, labels, classes, params):
        step.class_indices = classes
        step.files = files
        yield step


# ------------------------------------------------------------------------------ registry
def _params():
    from algorithms.adversarial.augment import AugmentParams

    return AugmentParams


AUGMENT_RECIPE = register(Recipe(AUGMENT, "augment", _params, image_steps,
                                 result=unchanged_result, outcome=augment_outcome,
                                 note="training images of the mesh under random or adversarial "
                                      "lighting, written to a dataset folder; the document "
                                      "does not change"))
