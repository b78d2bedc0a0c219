"""Rendered adversarial data augmentation, the thesis's experiment rebuilt (§3.5, App. 3.7.6;
issue 40).

The thesis fine-tunes nothing: it trains five WideResNets on CIFAR-100 plus 100 rendered orange
images -- none, under random lighting, or under adversarial lighting renewed every epoch --
and tests them on 500 photos of oranges under projected light: 4.6 %, 40.4 % and 65.8 %.
Neither CIFAR-100 nor those photos are here; the renderer, the SH lighting, the attack, the
classifier and real-world lighting (light probes) are. So, per seed:

* subjects: the 8 procedural objects of Table 3.4's set (:mod:`algorithms.adversarial.shapes`)
  plus the orange sample (``resources/samples/orange.obj``, its colours): 9 meshes, 8 classes;
* three training regimes with the same image count, ``--count`` images per mesh per round
  (:func:`algorithms.adversarial.augment.augment_iter`: random view, distance, background; the
  three regimes see the same views in a round): ``none`` (the neutral base light), ``random``
  (a random light in the ball of radius 0.5 around it, App. 3.7.6) and ``adversarial`` (the
  lighting attack against the *current* model from such a random light, step 0.05, at most
  ``--iterations`` steps, stop once fooled). With ``--rounds R`` the images are made anew R
  times (new views, new lights; the adversarial ones against the model of the previous round:
  the thesis renews its adversaries every epoch) and the model is fine-tuned on each round for
  ``--epochs / R`` epochs (:func:`algorithms.adversarial.finetune.finetune_iter`: the ImageNet
  EfficientNet-lite0 with its head restricted to the 8 classes, last layers trained);
* test 1, real-world light: every mesh from ``--test-views`` unseen random views, each lit by
  one of the published light probes (Ramamoorthi & Hanrahan 2001, the 9 coefficients embedded
  in :mod:`algorithms.render.sh`) turned by a uniformly random rotation, on a random grey
  background; top-1 accuracy among the 8 classes;
* test 2, a fresh lighting attack: ``--attack-views`` of those test images per mesh attacked
  against each model (the thesis's attack: L-inf ball 0.1 around the probe's light, step 0.05,
  at most ``--test-iterations`` steps, stop once fooled); accuracy after the attack;
* the base classifier restricted to the 8 classes (no fine-tuning) on the same tests;
* ``--seeds`` seeds (new training views and lights, new test views; the models differ only by
  their data); mean +- sd over seeds.

Images are quantized to 8 bits as the PNG files of ``stylize3d augment`` are. One thread
(``torch.set_num_threads(1)``). ``--write-docs`` writes docs/results/augmentation.md and
docs/images/augmentation.png (matplotlib) from the run.

    OMP_NUM_THREADS=1 taskset -c 1 .venv/bin/python benchmarks/augmentation.py [--quick]
        [--seeds 5] [--count 12] [--rounds 2] [--epochs 10] [--resolution 128]
        [--iterations 30] [--test-views 12] [--attack-views 3] [--test-iterations 30]
        [--write-docs]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

REGIMES = ("none", "random", "adversarial")


def subjects():
    """``[(name, label, scene)]``: the 8 procedural subjects and the orange sample."""
    from algorithms.adversarial.attack import prepare_scene
    from algorithms.adversarial.shapes import SUBJECTS, subject
    from algorithms.mesh import read_mesh
    from app.recipes.adversarial import read_face_colors

    out = []
    for name in SUBJECTS:
        V, F, A = subject(name)
        out.append((name, name, prepare_scene(V, F, albedo=A)))
    path = ROOT / "resources" / "samples" / "orange.obj"
    data = read_mesh(str(path))
    C = read_face_colors((str(path), len(data.V), len(data.F)), data.F)
    out.append(("orange sample", "orange", prepare_scene(data.V, data.F,
                                                         albedo=0.7 if C is None else C)))
    return out


class Restricted:
    """A classifier's logits restricted to some of its classes (the base classifier as a
    K-class one, for the attack test)."""

    def __init__(self, inner, indices, names):
        import torch

        self._inner = inner
        self._idx = torch.as_tensor(list(indices))
        self.class_names = tuple(names)
        self.input_size = inner.input_size
        self.dtype = inner.dtype
        self.name = "base (restricted)"

    def logits(self, images):
        return self._inner.logits(images)[:, self._idx]


def quantize(img):
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8).astype(np.float32) / 255.0


def training_set(scenes, clf, label_of, params):
    """Images (quantized), labels 0..K-1 and records of one round."""
    from algorithms.adversarial.augment import augment_iter

    images, labels, records = [], [], []
    for k, (_name, c, scene) in enumerate(scenes):
        for step in augment_iter(scene, clf, label_of(c), params, range(params.count),
                                 mesh_index=k):
            images.append(quantize(step.image))
            labels.append(c)
            records.append(step.record)
    return np.stack(images), np.asarray(labels), records


def probe_test(scenes, seed, n_views, base_params):
    """Per image: (mesh k, class c, view draw, probe name, rotated lighting, image)."""
    from scipy.spatial.transform import Rotation

    from algorithms.adversarial.attack import render_views
    from algorithms.adversarial.augment import draw_image
    from algorithms.adversarial.transfer import view_camera
    from algorithms.render.sh import ENVIRONMENTS, environment, rotate_lighting

    probes = sorted(ENVIRONMENTS)
    p = dataclasses.replace(base_params, seed=10 ** 6 + seed)
    items = []
    for k, (_name, c, scene) in enumerate(scenes):
        for j in range(n_views):
            d = draw_image(p, k, j)
            rng = np.random.default_rng([seed, k, j, 99])
            probe = probes[int(rng.integers(len(probes)))]
            U = rotate_lighting(environment(probe), Rotation.random(random_state=rng)
                                .as_matrix())
            sc = dataclasses.replace(scene, lighting=U, background=d.background)
            cam = view_camera(d.view, p.resolution * p.supersample)
            img, _, _ = render_views(sc, [cam], supersample=p.supersample)
            items.append({"k": k, "c": c, "draw": d, "probe": probe, "U": U,
                          "image": quantize(img[0]), "scene": sc, "camera": cam})
    return items


def probe_accuracy(models, feats, labels):
    import torch

    from algorithms.adversarial.finetune import head_logits

    out = {}
    with torch.no_grad():
        for name, (model, idx) in models.items():
            logits = head_logits(model, feats)
            if idx is not None:
                logits = logits[:, idx]
            out[name] = float((logits.argmax(1).numpy() == labels).mean())
    return out


def attack_accuracy(clf, items, iterations, resolution):
    from algorithms.adversarial.attack import AdversaryParams, attack

    params = AdversaryParams(mode="lighting", iterations=iterations, resolution=resolution)
    right = []
    for it in items:
        res = attack(it["scene"], clf, [it["camera"]], params, decrease=it["c"])
        v = res.views[0]
        right.append(v.label_after == clf.class_names[it["c"]].split(",")[0].strip())
    return float(np.mean(right)) if right else float("nan")


def run(args):
    import torch

    from algorithms.adversarial.augment import AugmentParams, summarize
    from algorithms.adversarial.classifiers import default_classifier
    from algorithms.adversarial.finetune import FinetuneParams, features, finetune_iter
    from algorithms.adversarial.labels import resolve_label

    torch.set_num_threads(1)
    t_all = time.perf_counter()
    base = default_classifier()
    scenes = subjects()
    classes = sorted({resolve_label(c, base.class_names) for _, c, _ in scenes})
    names = [base.class_names[i] for i in classes]
    scenes = [(n, classes.index(resolve_label(c, base.class_names)), s) for n, c, s in scenes]
    K = len(classes)
    print(f"{len(scenes)} meshes, {K} classes; {args.count} images per mesh per round x "
          f"{args.rounds} round(s) = {len(scenes) * args.count * args.rounds} images per regime; "
          f"{args.resolution} px; attack <= {args.iterations} iterations; {args.epochs} "
          f"epochs; test {args.test_views} probe views per mesh, {args.attack_views} attacked "
          f"(<= {args.test_iterations} iterations); seeds {args.seeds}", flush=True)
    restricted = Restricted(base, classes, names)
    per_seed = []
    for seed in range(args.seeds):
        t_seed = time.perf_counter()
        times = {}
        t = time.perf_counter()
        aug0 = AugmentParams(resolution=args.resolution, iterations=args.iterations)
        test = probe_test(scenes, seed, args.test_views, aug0)
        test_feats = features(base, np.stack([it["image"] for it in test]))
        test_labels = np.array([it["c"] for it in test])
        times["test renders"] = time.perf_counter() - t
        models = {"base": (base.model, classes)}
        clfs = {"base": restricted}
        gen = {}
        for regime in REGIMES:
            current, t_gen, t_train, recs = None, 0.0, 0.0, []
            per_round = max(1, args.epochs // args.rounds)
            for r in range(args.rounds):
                p = dataclasses.replace(aug0, lighting=regime, count=args.count,
                                        seed=1000 * seed + r)
                t = time.perf_counter()
                against = base if current is None else current
                imgs, labels, records = training_set(
                    scenes, against, (lambda c: classes[c]) if current is None else
                    (lambda c: c), p)
                t_gen += time.perf_counter() - t
                recs += records
                t = time.perf_counter()
                fp = FinetuneParams(epochs=per_round, seed=seed)
                if current is None:
                    steps = list(finetune_iter(base, imgs, labels, classes, fp, names))
                else:
                    steps = list(finetune_iter(current, imgs, labels, range(K), fp, names))
                current = steps[-1].classifier
                t_train += time.perf_counter() - t
            models[regime] = (current.model, None)
            clfs[regime] = current
            gen[regime] = summarize(recs)
            times[f"{regime}: images"] = t_gen
            times[f"{regime}: training"] = t_train
        acc = probe_accuracy(models, test_feats, test_labels)
        t = time.perf_counter()
        attacked = [it for i, it in enumerate(test) if i % args.test_views < args.attack_views]
        adv_acc = {name: attack_accuracy(clf, attacked, args.test_iterations, args.resolution)
                   for name, clf in clfs.items()}
        times["attack test"] = time.perf_counter() - t
        row = {"seed": seed, "probe": acc, "attacked": adv_acc, "generation": gen,
               "times": times, "seconds": time.perf_counter() - t_seed,
               "test_images": len(test), "attacked_images": len(attacked)}
        per_seed.append(row)
        print(f"seed {seed}: probe accuracy " + ", ".join(f"{k} {100 * v:.1f}%"
                                                           for k, v in acc.items())
              + "; after a fresh attack " + ", ".join(f"{k} {100 * v:.1f}%"
                                                       for k, v in adv_acc.items())
              + f"; {row['seconds']:.0f} s (" + ", ".join(f"{k} {v:.0f} s"
                                                          for k, v in times.items()) + ")",
              flush=True)
        for regime in REGIMES:
            g = gen[regime]
            print(f"    {regime}: {g['images']} training images, the model attacked missed "
                  f"{g['fooled']}; true class {100 * g['mean_true_probability_before']:.0f}% -> "
                  f"{100 * g['mean_true_probability_after']:.0f}%", flush=True)
    total = time.perf_counter() - t_all
    summary = summarize_seeds(per_seed)
    print_table(summary)
    print(f"total {total:.0f} s ({total / 60:.1f} min)")
    return {"args": vars(args), "seeds": per_seed, "summary": summary, "seconds": total,
            "classes": names, "meshes": [n for n, _, _ in scenes]}


def summarize_seeds(per_seed):
    out = {}
    for test in ("probe", "attacked"):
        for name in ("base",) + REGIMES:
            v = np.array([s[test][name] for s in per_seed])
            out[f"{test}:{name}"] = (float(v.mean()), float(v.std(ddof=1)) if len(v) > 1
                                     else 0.0)
    return out


def print_table(summary):
    print(f"{'model':<14}{'light probes':>20}{'fresh attack':>20}")
    for name in ("base",) + REGIMES:
        p, a = summary[f"probe:{name}"], summary[f"attacked:{name}"]
        print(f"{name:<14}{100 * p[0]:>12.1f} ± {100 * p[1]:4.1f}%{100 * a[0]:>12.1f} ± "
              f"{100 * a[1]:4.1f}%")
    pn, pr, pa = (summary[f"probe:{r}"] for r in REGIMES)
    print(f"ratios (light probes): random / none {pr[0] / max(pn[0], 1e-9):.2f}, "
          f"adversarial / random {pa[0] / max(pr[0], 1e-9):.2f}")


def write_docs(res):
    raise NotImplementedError


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--count", type=int, default=12, help="images per mesh per round")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--iterations", type=int, default=30, help="training attack (thesis 30)")
    ap.add_argument("--test-views", type=int, default=12)
    ap.add_argument("--attack-views", type=int, default=3)
    ap.add_argument("--test-iterations", type=int, default=30)
    ap.add_argument("--quick", action="store_true", help="2 seeds, 4 images, 1 round, tiny")
    ap.add_argument("--json", metavar="FILE", help="write the results as JSON")
    ap.add_argument("--write-docs", action="store_true",
                    help="write docs/results/augmentation.md and docs/images/augmentation.png")
    args = ap.parse_args(argv)
    if args.quick:
        args.seeds, args.count, args.rounds, args.epochs = 2, 4, 1, 4
        args.test_views, args.attack_views, args.iterations, args.test_iterations = 4, 1, 5, 5
        args.resolution = 64
    res = run(args)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1, default=str))
    if args.write_docs:
        write_docs(res)
    return res


if __name__ == "__main__":
    main()
