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
        [--radius 0.5] [--write-docs] [--json FILE] [--from-json FILE --write-docs]
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
        aug0 = AugmentParams(resolution=args.resolution, iterations=args.iterations,
                             radius=args.radius)
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


KEEP = "<!-- written by hand below this line; benchmarks/augmentation.py --write-docs keeps it -->"


def _pm(v):
    return f"{100 * v[0]:.1f} ± {100 * v[1]:.1f} %"


def verdict(summary) -> str:
    """adversarial > random > none on the light probes, each gap against the seeds' spread."""
    (n, sn), (r, sr), (a, sa) = (summary[f"probe:{k}"] for k in REGIMES)
    parts = []
    for hi, shi, lo, slo, what in ((a, sa, r, sr, "adversarial > random"),
                                   (r, sr, n, sn, "random > none")):
        spread = max(shi, slo)
        if hi > lo and hi - lo > spread:
            parts.append(f"{what}: yes, by {100 * (hi - lo):.1f} points, more than the seeds' "
                         f"spread ({100 * spread:.1f})")
        elif hi > lo:
            parts.append(f"{what}: only by {100 * (hi - lo):.1f} points, within the seeds' "
                         f"spread ({100 * spread:.1f}): not shown")
        else:
            parts.append(f"{what}: no ({100 * hi:.1f} % against {100 * lo:.1f} %)")
    return "; ".join(parts) + "."


def plot(res, path):
    try:
        import matplotlib
    except ImportError:
        print("matplotlib is not installed: no plot")
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ("base",) + REGIMES
    labels = ["ImageNet\n(no fine-tuning)", "no\naugmentation", "random\nlighting",
              "adversarial\nlighting"]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
    for ax, test, title in zip(axes, ("probe", "attacked"),
                               ("Light probes, rotated, unseen views",
                                "After a fresh lighting attack")):
        means = [100 * res["summary"][f"{test}:{n}"][0] for n in names]
        sds = [100 * res["summary"][f"{test}:{n}"][1] for n in names]
        x = np.arange(len(names))
        ax.bar(x, means, yerr=sds, capsize=4, color=["#999999", "#4c78a8", "#f58518",
                                                     "#54a24b"])
        for s in res["seeds"]:
            ax.plot(x + 0.25, [100 * s[test][n] for n in names], "k.", ms=3)
        ax.set_xticks(x, labels, fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.set_ylim(0, 100)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("top-1 accuracy (%), 8 classes")
    fig.suptitle(f"Rendered data augmentation (thesis §3.5): mean ± sd over "
                 f"{len(res['seeds'])} seeds (dots: seeds)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _wrap(text: str) -> str:
    import textwrap

    return textwrap.fill(text, 100, break_on_hyphens=False, break_long_words=False)


def write_docs(res):
    a = res["args"]
    md = ROOT / "docs" / "results" / "augmentation.md"
    png = ROOT / "docs" / "images" / "augmentation.png"
    has_plot = plot(res, png)
    kept = ""
    if md.is_file() and KEEP in md.read_text():
        kept = md.read_text().split(KEEP, 1)[1]
    sm = res["summary"]
    n_img = len(res["meshes"]) * a["count"] * a["rounds"]
    lines = [
        "# Rendered adversarial data augmentation: measurements",
        "",
        _wrap("The thesis's experiment (§3.5, App. 3.7.6) rebuilt with what is here; the user "
              "page is [Adversarial lighting](../adversarial_lighting.md#training-images-thesis-"
              "35). Regenerate with the command at the end."),
        "",
        _wrap("**The thesis**: five WideResNets trained on CIFAR-100 plus 100 rendered oranges, "
              "tested on 500 photos of oranges under projected light: 4.6 % (no augmentation), "
              "40.4 % (random lighting), **65.8 %** (adversarial lighting)."),
        "",
        _wrap(f"**Here** (`benchmarks/augmentation.py`): {len(res['meshes'])} meshes "
        f"({', '.join(res['meshes'])}), {len(res['classes'])} classes; the installed "
        "EfficientNet-lite0 with its ImageNet head restricted to those classes, its last layers "
        f"fine-tuned ({a['epochs']} epochs) on {n_img} rendered images per regime "
        f"({a['count']} per mesh per round, {a['rounds']} round(s); {a['resolution']} px; "
        f"random views, distances and grey backgrounds; lights in the L∞ ball of radius "
        f"{a.get('radius', 0.5):g} around a neutral white light; adversarial lights: at most "
        f"{a['iterations']} attack steps against the model of the previous round). Tests: "
        f"{a['test_views']} unseen views per mesh lit by the published light probes "
        "(Grace Cathedral, Eucalyptus Grove, St. Peter's Basilica; 9 coefficients each, "
        "Ramamoorthi & Hanrahan 2001) turned by a random rotation, and "
        f"{a['attack_views']} of them per mesh under a fresh lighting attack (L∞ 0.1 around "
        f"the probe's light, step 0.05, at most {a['test_iterations']} steps) against each "
        f"model. {len(res['seeds'])} seeds; mean ± sd (sample sd over seeds)."),
        "",
        "| model | light probes (top-1) | after a fresh lighting attack |",
        "|---|---|---|",
    ]
    titles = {"base": "ImageNet classifier, no fine-tuning", "none": "no augmentation",
              "random": "random lighting", "adversarial": "adversarial lighting"}
    for name in ("base",) + REGIMES:
        lines.append(f"| {titles[name]} | {_pm(sm['probe:' + name])} | "
                     f"{_pm(sm['attacked:' + name])} |")
    lines += ["", _wrap(f"Light-probe test: {verdict(sm)}"), ""]
    pairs = []
    for test, what in (("probe", "light probes"), ("attacked", "after the attack")):
        for hi, lo in (("adversarial", "random"), ("random", "none")):
            d = np.array([s[test][hi] - s[test][lo] for s in res["seeds"]])
            sd = d.std(ddof=1) if len(d) > 1 else 0.0
            pairs.append(f"{what}, {hi} − {lo}: {100 * d.mean():+.1f} ± {100 * sd:.1f} points "
                         f"({int((d > 0).sum())} of {len(d)} seeds above 0)")
    lines += [_wrap("Paired by seed (each seed's models share their test images; mean ± sd "
                    "of the per-seed differences): " + "; ".join(pairs) + "."), ""]
    if has_plot:
        lines += ["![Accuracy per training regime](../images/augmentation.png)", ""]
    lines += ["Per seed (light probes / after the attack, %):", "",
              "| seed | " + " | ".join(titles[n] for n in ("base",) + REGIMES) + " |",
              "|---|---|---|---|---|"]
    for s in res["seeds"]:
        lines.append(f"| {s['seed']} | " + " | ".join(
            f"{100 * s['probe'][n]:.1f} / {100 * s['attacked'][n]:.1f}"
            for n in ("base",) + REGIMES) + " |")
    lines += ["", _wrap("The training images (all seeds; *missed*: the model they were made "
                        "against did not give the true class as its top-1):"), "",
              "| regime | images | missed | true class, start -> image |", "|---|---|---|---|"]
    for r in REGIMES:
        g = [s["generation"][r] for s in res["seeds"]]
        n = sum(x["images"] for x in g)
        f = sum(x["fooled"] for x in g)
        b = np.mean([x["mean_true_probability_before"] for x in g])
        e = np.mean([x["mean_true_probability_after"] for x in g])
        lines.append(f"| {r} | {n} | {f} ({100 * f / n:.0f} %) | {100 * b:.0f} % -> "
                     f"{100 * e:.0f} % |")
    keys = list(res["seeds"][0]["times"])
    lines += ["", _wrap("Time per seed (one thread, seconds, mean over seeds): " + ", ".join(
        f"{k} {np.mean([s['times'][k] for s in res['seeds']]):.0f}" for k in keys)
        + f"; the whole run {res['seconds'] / 60:.1f} min."), "",
        "Run:", "",
        "    OMP_NUM_THREADS=1 taskset -c 1 .venv/bin/python benchmarks/augmentation.py "
        f"--seeds {a['seeds']} --count {a['count']} --rounds {a['rounds']} --epochs "
        f"{a['epochs']} --resolution {a['resolution']} --iterations {a['iterations']} "
        f"--test-views {a['test_views']} --attack-views {a['attack_views']} "
        f"--test-iterations {a['test_iterations']}"
        + (f" --radius {a['radius']:g}" if a.get("radius", 0.5) != 0.5 else "")
        + " --write-docs", "", KEEP]
    md.write_text("\n".join(lines) + (kept if kept else "\n"))
    print(f"wrote {md}" + (f" and {png}" if has_plot else ""))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--count", type=int, default=12, help="images per mesh per round")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--iterations", type=int, default=30, help="training attack (thesis 30)")
    ap.add_argument("--radius", type=float, default=0.5,
                    help="the training lights' ball around the neutral light (thesis: 0.5)")
    ap.add_argument("--test-views", type=int, default=12)
    ap.add_argument("--attack-views", type=int, default=3)
    ap.add_argument("--test-iterations", type=int, default=30)
    ap.add_argument("--quick", action="store_true", help="2 seeds, 4 images, 1 round, tiny")
    ap.add_argument("--json", metavar="FILE", help="write the results as JSON")
    ap.add_argument("--write-docs", action="store_true",
                    help="write docs/results/augmentation.md and docs/images/augmentation.png")
    ap.add_argument("--from-json", metavar="FILE",
                    help="no run: the results of an earlier --json (with --write-docs)")
    args = ap.parse_args(argv)
    if args.from_json:
        res = json.loads(Path(args.from_json).read_text())
        print_table(res["summary"])
        if args.write_docs:
            write_docs(res)
        return res
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
