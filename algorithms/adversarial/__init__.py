"""Parametric adversaries (thesis ch. 3): spherical-harmonics lighting and geometry perturbations
that fool an image classifier, the random baseline of the same norm, multi-view attacks and the
optical illusion, evaluation on unseen views. See :mod:`.attack` for the choices made."""

from .attack import (DEFAULT_RADIUS, AdversaryParams, AttackResult, AttackStep, Scene,
                     ViewResult, attack, attack_iter, classify, cost_image_gradients, evaluate,
                     find_recognized_views, orbit_cameras, prepare_scene, random_perturbation,
                     render_views)
from .classifiers import (Classifier, ClassifierLoadError, TorchClassifier, default_classifier,
                          imagenet_class_names, load_classifier)
from .labels import resolve_label, short_name

__all__ = ["AdversaryParams", "Scene", "prepare_scene", "orbit_cameras", "render_views",
           "classify", "cost_image_gradients", "find_recognized_views", "attack_iter", "attack",
           "AttackStep", "AttackResult", "ViewResult", "random_perturbation", "evaluate",
           "DEFAULT_RADIUS", "Classifier", "TorchClassifier", "ClassifierLoadError",
           "default_classifier", "load_classifier", "imagenet_class_names", "resolve_label",
           "short_name"]
