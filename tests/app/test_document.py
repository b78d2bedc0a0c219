"""The Qt-free document model."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere
from app.document import Document, MeshState


def test_states_are_immutable_snapshots():
    V, F = icosphere(1)
    s = MeshState.make(V, F, {"lam": np.ones(len(V))})
    V[0] = 99.0
    assert s.V[0, 0] != 99.0
    with pytest.raises(ValueError):
        s.V[0, 0] = 1.0
    with pytest.raises(ValueError):
        s.with_field("bad", np.ones(3))
    with pytest.raises(ValueError):
        s.with_positions(np.zeros((2, 3)))


def test_notifications_say_what_changed():
    V, F = icosphere(1)
    doc = Document()
    seen = []
    doc.subscribe(seen.append)
    doc.load(V, F, "x.obj")
    s0 = doc.state
    doc.set_state(s0.with_positions(V * 2))
    doc.set_state(doc.state.with_field("lam", np.zeros(len(V))))
    doc.set_state(doc.state.with_selection(np.zeros(len(V), bool)))
    V2, F2 = icosphere(2)
    doc.set_state(MeshState.make(V2, F2))
    assert seen == ["mesh", "positions", "fields", "selection", "topology"]
    assert doc.modified and doc.original is s0


def test_remap_follows_vertex_map():
    V, F = icosphere(0)
    doc = Document()
    doc.load(V, F, None)
    doc.set_state(doc.state.with_field("lam", np.arange(len(V), dtype=float))
                  .with_selection(np.arange(len(V)) % 2 == 0))
    vmap = np.arange(len(V))[::-1].copy()
    vmap[0] = -1  # deleted
    new = doc.remapped(V[::-1], F, vmap)
    assert new.fields["lam"][vmap[1]] == 1.0 and new.fields["lam"][vmap[5]] == 5.0
    assert new.selection[vmap[2]] and not new.selection[vmap[1]]


def test_with_positions_shares_frozen_positions_and_copies_others():
    import numpy as np

    from app.document import MeshState

    V = np.random.default_rng(0).random((4, 3))
    F = np.array([[0, 1, 2], [0, 2, 3]])
    a = MeshState.make(V, F)
    b = a.with_positions(V + 1)
    assert not b.V.flags.writeable and b.V is not a.V
    c = b.with_positions(a.V)  # another state's (read-only, owning) array: shared
    assert c.V is a.V
    W = V.copy()
    d = a.with_positions(W)  # a caller's writable array: copied, later edits do not leak in
    W[0] = 99
    assert d.V[0, 0] != 99 and not d.V.flags.writeable
