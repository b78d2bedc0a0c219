"""Inputs that make the subdivision guard hand levels or parts to Loop (the shipped network
passes on every test mesh), shared by the command-line and panel tests."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import read_mesh
from tests.conftest import ROOT

HAND = ROOT / "tests" / "data" / "hand_lowres.obj"


def untrained_weights(tmp_path) -> str:
    """A network that was never trained (seed 0) with the shipped one's reference edge
    length: its result is bumpy everywhere, as a badly trained network's is, so the guard
    hands levels to Loop (the shipped network passes on every test mesh since the guard blends
    Loop in over isolated bulges)."""
    from algorithms.subdivision.model import SubdivisionNet, load_weights, save_weights

    info = load_weights(None)[1]
    path = tmp_path / "untrained.pt"
    save_weights(path, SubdivisionNet(seed=0), {"mean_edge_length": info["mean_edge_length"]})
    return str(path)


def two_parts(tmp_path):
    """hand_lowres beside a noisy sphere (raw-scan-like, at the hand's edge length): with the
    untrained network of :func:`untrained_weights`, level 1 passes as a whole, and at level 2
    the hand's part is 7.7x as bent as butterfly's there while the sphere's passes."""
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import icosphere
    from algorithms.subdivision.inference import mean_edge_length

    f = read_mesh(HAND)
    S, FS = icosphere(2)
    S = S + 0.3 * mean_edge_length(S, FS) * np.random.default_rng(0).standard_normal(S.shape)
    S = S * (mean_edge_length(f.V, f.F) / mean_edge_length(S, FS))
    S = S + [f.V[:, 0].max() - S[:, 0].min() + 0.1 * np.ptp(f.V[:, 0]), 0.0, 0.0]
    path = tmp_path / "two.obj"
    write_mesh(path, np.vstack([f.V, S]), np.vstack([f.F, FS + len(f.V)]))
    return path
