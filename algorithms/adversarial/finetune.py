"""Fine-tuning the classifier on rendered training images (thesis §3.5; ``stylize3d
augment-train``).

The thesis trains a WideResNet on CIFAR-100 plus 100 rendered images for 150 epochs (App.
3.7.6: SGD, Nesterov momentum 0.9, weight decay 5e-4, cross entropy). CIFAR-100 and a GPU are
not at hand; what is here is the installed EfficientNet-lite0 trained on ImageNet. Choices:

* **Output classes: the ImageNet head restricted to the labels present.** The classes are the
  ImageNet classes the dataset folders name (``orange``, ``coffee mug``, ...); the new
  classification layer starts as the rows of the ImageNet layer for those classes, so before
  any training it *is* the ImageNet classifier restricted to them (epoch 0 is the fair
  baseline), and it knows nothing it would have to unlearn.
* **Only the last layers learn** (CPU time): ``layers="head"`` trains the classification layer;
  ``layers="last"`` (default) also the last 1 x 1 convolution (320 -> 1280 channels) and its
  batch norm's scale and shift (its running statistics stay ImageNet's). Everything before it
  is frozen, so its output is computed once per image and kept (``features``), and an epoch
  costs only the last layers.
* SGD with Nesterov momentum 0.9 and weight decay 5e-4 (the thesis's), learning rate 0.01,
  batches of 32, 10 epochs by default, in a fixed order given by the seed. No validation split:
  the last epoch's weights are kept (the thesis keeps the best on a validation set of
  CIFAR-100, which a few hundred renders cannot spare).

:func:`save_finetuned` writes ``{"format", "state_dict", "class_names", "imagenet_indices",
...}`` with ``torch.save``; :func:`~.classifiers.load_classifier` reads it with
``weights_only=True`` and takes the class names from it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Iterator, Sequence

import numpy as np

from ..errors import ParameterError
from ..params import param, validate_params
from ..steps import Step

__all__ = ["FinetuneParams", "FinetuneStep", "features", "head_logits", "finetune_iter",
           "save_finetuned", "FORMAT"]

FORMAT = "stylize3d-finetuned-classifier"


@dataclass(frozen=True)
class FinetuneParams:
    epochs: int = param(10, label="Epochs", minimum=1, maximum=1000, step=1,
                        tooltip="Passes over the training images.")
    learning_rate: float = param(0.01, label="Learning rate", minimum=1e-6, maximum=1.0,
                                 step=0.001, decimals=5,
                                 tooltip="SGD step size (Nesterov momentum 0.9, weight decay "
                                         "5e-4, as the thesis).")
    batch_size: int = param(32, label="Batch size", minimum=1, maximum=4096, step=1,
                            tooltip="Images per SGD step.")
    layers: str = param("last", label="Layers trained", choices=("head", "last"),
                        tooltip="head: the classification layer only; last: also the last "
                                "1x1 convolution (320 -> 1280 channels) and its batch norm.")
    seed: int = param(0, label="Random seed", minimum=0, maximum=2**31 - 1, step=1,
                      tooltip="Order of the images in each epoch.")


@dataclass
class FinetuneStep(Step):
    """One finished epoch: ``metrics`` loss and accuracy on the training images;
    ``classifier``: the fine-tuned classifier so far (a TorchClassifier of the kept classes)."""

    classifier: object = None
    state_dict: dict = field(default_factory=dict)


def _model_parts(model):
    for name in ("_conv_stem", "_bn0", "_blocks", "_conv_head", "_bn1", "_avg_pooling", "_fc"):
        if not hasattr(model, name):
            raise ParameterError("Only EfficientNet-lite0 classifiers (the installed one, or "
                                 "weights of it) can be fine-tuned here; this one is a "
                                 f"{type(model).__name__}.")


def _trunk(model, x):
    """Everything before the last 1 x 1 convolution (frozen)."""
    x = model._swish(model._bn0(model._conv_stem(x)))
    for block in model._blocks:
        x = block(x, drop_connect_rate=None)
    return x


def head_logits(model, f):
    """The trained last layers on trunk features ``f`` (:func:`features`): logits."""
    x = model._swish(model._bn1(model._conv_head(f)))
    return model._fc(model._avg_pooling(x).flatten(1))


def features(classifier, images: np.ndarray, batch: int = 32):
    """The frozen trunk's output ``(N, 320, 7, 7)`` (a torch tensor) of images ``(N, S, S, 3)``
    in [0, 1] (preprocessed as the classifier does)."""
    import torch

    _model_parts(classifier.model)
    out = []
    with torch.no_grad():
        for i in range(0, len(images), batch):
            x = torch.from_numpy(np.ascontiguousarray(
                np.asarray(images[i:i + batch], dtype=np.float32).transpose(0, 3, 1, 2)))
            out.append(_trunk(classifier.model, classifier.preprocess(x)))
    return torch.cat(out) if out else torch.zeros((0, 320, 7, 7))


def finetune_iter(classifier, images: np.ndarray, labels: Sequence[int],
                  class_indices: Sequence[int], params: FinetuneParams = FinetuneParams(),
                  class_names: Sequence[str] | None = None) -> Iterator[FinetuneStep]:
    """Fine-tune ``classifier`` (an EfficientNet-lite0 :class:`~.classifiers.TorchClassifier`)
    on ``images (N, S, S, 3)`` with ``labels`` (N,) in ``0..K-1``, the positions in
    ``class_indices`` (K classifier classes that become the outputs). Yields one
    :class:`FinetuneStep` per epoch (iteration 0: before training, the restricted base)."""
    import torch

    from .classifiers import TorchClassifier

    validate_params(params)
    labels = np.asarray(labels, dtype=np.int64)
    idx = [int(i) for i in class_indices]
    K = len(idx)
    if len(images) == 0 or len(labels) != len(images):
        raise ParameterError("Fine-tuning needs images, one label each.")
    if K < 1 or labels.min() < 0 or labels.max() >= K:
        raise ParameterError("Every label must be one of the classes kept.")
    names = list(class_names) if class_names is not None else \
        [classifier.class_names[i] for i in idx]
    base = classifier.model
    _model_parts(base)
    torch.manual_seed(int(params.seed))
    model = copy.deepcopy(base).eval()
    old = base._fc
    fc = torch.nn.Linear(old.in_features, K)
    with torch.no_grad():
        fc.weight.copy_(old.weight[idx])
        fc.bias.copy_(old.bias[idx])
    model._fc = fc
    trained = [model._fc] + ([model._conv_head, model._bn1] if params.layers == "last" else [])
    for p in model.parameters():
        p.requires_grad_(False)
    weights = [p for m in trained for p in m.parameters()]
    for p in weights:
        p.requires_grad_(True)
    feats = features(classifier, images)
    y = torch.from_numpy(labels)
    opt = torch.optim.SGD(weights, lr=params.learning_rate, momentum=0.9, nesterov=True,
                          weight_decay=5e-4)
    rng = np.random.default_rng(int(params.seed))

    def evaluate():
        with torch.no_grad():
            logits = torch.cat([head_logits(model, feats[i:i + 256])
                                for i in range(0, len(feats), 256)])
            loss = float(torch.nn.functional.cross_entropy(logits, y))
            acc = float((logits.argmax(1) == y).double().mean())
        return loss, acc

    def step_of(epoch, loss, acc):
        clf = TorchClassifier(copy.deepcopy(model), names, classifier.input_size,
                              name=f"fine-tuned ({K} classes)")
        return FinetuneStep(epoch, params.epochs, np.zeros((0, 3)),
                            {"loss": loss, "accuracy": acc},
                            f"epoch {epoch}/{params.epochs}: loss {loss:.3f}, training "
                            f"accuracy {100 * acc:.1f}%", classifier=clf,
                            state_dict={k: v.detach().clone() for k, v in
                                        model.state_dict().items()})

    yield step_of(0, *evaluate())
    for epoch in range(1, params.epochs + 1):
        order = rng.permutation(len(feats))
        for i in range(0, len(order), params.batch_size):
            b = torch.from_numpy(order[i:i + params.batch_size])
            opt.zero_grad()
            loss = torch.nn.functional.cross_entropy(head_logits(model, feats[b]), y[b])
            loss.backward()
            opt.step()
        yield step_of(epoch, *evaluate())


def save_finetuned(path, step: FinetuneStep, class_indices: Sequence[int], *,
                   extra: dict | None = None) -> None:
    """Write the weights of ``step`` with their class names (module docstring); ``extra``:
    JSON-like facts kept with them (epochs, datasets, ...)."""
    import io

    import torch

    from ..mesh.io import atomic_write

    obj = {"format": FORMAT, "state_dict": step.state_dict,
           "class_names": list(step.classifier.class_names),
           "imagenet_indices": [int(i) for i in class_indices],
           "architecture": "efficientnet-lite0", **(extra or {})}
    buf = io.BytesIO()
    torch.save(obj, buf)
    data = buf.getvalue()
    atomic_write(path, lambda fh: fh.write(data))
