"""The neural subdivision network (thesis §4.5, Fig. 4.18-4.20, Table 4.1) and its weights files.

Three half-flap operators, each an MLP with two hidden layers of 32 ReLU units and 32 outputs
(3 + 29), Xavier-normal weights, zero biases:

* ``I`` (INITIALIZATION) on the coarse mesh: input per half-flap ``(i, j, k, l)`` the three edge
  vectors ``j - i, k - i, l - i`` and the four vertices' differential coordinates
  ``delta_v = v - mean(neighbours)`` (Sorkine 2005), 3·3 + 4·3 = 21 numbers;
* ``V`` (VERTEX) and ``E`` (EDGE) at every level: the three edge vectors and the four vertices'
  32-vectors ``[delta_v, z_v]`` (differential coordinates + 29 learned features), 3·3 + 4·32.

Every vector enters and leaves in the **half-flap's local frame** -- x along the half-edge, z the
average of its two face normals made orthogonal to x, y = z × x -- so the network only sees and
predicts rigid-motion-invariant quantities. The first 3 outputs are a displacement (local frame,
turned back to world axes), the other 29 the new learned feature. ``I`` and ``V`` average their
half-flaps over each vertex's outgoing half-edges (the displacement moves the vertex); ``E``
averages the two half-flaps of an edge (the displacement is from the edge's mid-point, where the
new vertex goes). One subdivision level = VERTEX step on the old vertices, then EDGE step using
the updated vertices and features (in sequence, §4.5), then the Loop 1-to-4 topology.

Choices where the text is silent (written down, tested): the 3 non-learned numbers of a vertex's
32-vector are its differential coordinates recomputed from the current positions before each step
("convert global coordinates to local differential per-vertex quantities before each step"); on
a boundary edge the missing fourth flap vertex is ``k`` turned by pi about the edge, with ``k``'s
features (the authors' code handles closed meshes only). The network is not scale invariant
(thesis §4.7): meshes are scaled by :func:`algorithms.subdivision.data.normalization` (rigid-
motion invariant: centroid and farthest-vertex distance) before the network and back after.

Weights files: ``torch.save`` of a dict of plain tensors, numbers and strings, read back with
``torch.load(..., weights_only=True)``; a file without our ``format`` tag gives a plain error.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InvalidMeshError, ParameterError, Stylize3DError
from ..params import param
from .data import check_manifold, normalization
from .topology import half_flaps, refine

__all__ = ["SubdivideParams", "SubdivisionNet", "MeshLevels", "neural_subdivide", "save_weights", "load_weights",
           "shipped_weights_path", "WeightsError", "FORMAT", "FEATURES"]

FORMAT = "stylize3d-neural-subdivision"
FORMAT_VERSION = 1
FEATURES = 32  # 3 + 29
DTYPE_NAME = "float32"  # network and inference precision (float64 is ~2x slower)
HIDDEN = 32
MAX_LEVELS = 3


@dataclass(frozen=True)
class SubdivideParams:
    """Subdividing a mesh (the Subdivision panel's form)."""

    method: str = param("neural", label="Method", choices=("neural", "loop", "butterfly",
                                                            "midpoint"),
                        tooltip="neural: the learned subdivision (thesis ch. 4); loop: smooth, "
                                "shrinks; butterfly: interpolating; midpoint: splits only.")
    levels: int = param(2, label="Levels", minimum=1, maximum=MAX_LEVELS, step=1,
                        tooltip="Each level splits every triangle into four (the network was "
                                "trained for 2).")
    coarsen_first: int = param(0, label="Coarsen first to (vertices)", minimum=0,
                               maximum=1_000_000, step=50,
                               tooltip="0: off. Otherwise QSlim the mesh to about this many "
                                       "vertices first (e.g. 400), so you can watch the method "
                                       "rebuild the detail.")


class WeightsError(Stylize3DError):
    """A weights file is missing, unreadable or not a neural-subdivision weights file."""

    exit_code = 2


def shipped_weights_path() -> Path:
    """The weights trained by the project (resources/subdivision/neural_subdivision.pt)."""
    return Path(__file__).resolve().parents[2] / "resources" / "subdivision" / \
        "neural_subdivision.pt"


def _torch():
    import torch

    return torch


class MeshLevels:
    """Index tensors of one mesh and of its refinements (reused across epochs and calls).

    ``levels[l]`` holds the half-flap indices of level ``l`` (0 = the input) for ``l < L``;
    ``faces[l]`` the faces of every level 0..L.
    """

    def __init__(self, F: np.ndarray, n: int, levels: int, dtype=None):
        torch = _torch()
        dt = dtype if dtype is not None else getattr(torch, DTYPE_NAME)
        self.levels = []
        self.faces = []
        F = np.asarray(F, dtype=np.int64)
        for _ in range(levels):
            hf = half_flaps(F, n)
            lv = {}
            ijkl = hf.ijkl
            has_l = ijkl[:, 3] >= 0
            lsafe = np.where(has_l, ijkl[:, 3], ijkl[:, 2])
            lv["i"] = torch.from_numpy(ijkl[:, 0].copy())
            lv["j"] = torch.from_numpy(ijkl[:, 1].copy())
            lv["k"] = torch.from_numpy(ijkl[:, 2].copy())
            lv["l"] = torch.from_numpy(lsafe)
            lv["has_l"] = torch.from_numpy(has_l)
            lv["face"] = torch.from_numpy(hf.face)
            lv["twin"] = torch.from_numpy(np.maximum(hf.twin_face, 0))
            lv["has_twin"] = torch.from_numpy((hf.twin_face >= 0).astype(np.float64)).to(dt)
            lv["F"] = torch.from_numpy(F)
            lv["nb_src"] = torch.from_numpy(hf.neighbours[:, 0].copy())
            lv["nb_dst"] = torch.from_numpy(hf.neighbours[:, 1].copy())
            lv["deg"] = torch.from_numpy(np.maximum(hf.degree, 1.0)).to(dt)
            lv["edge"] = torch.from_numpy(hf.edge.copy())
            lv["E"] = torch.from_numpy(hf.E)
            lv["n"] = n
            lv["e"] = len(hf.E)
            lv["src_count"] = torch.from_numpy(
                np.bincount(ijkl[:, 0], minlength=n).astype(np.float64).clip(1))[:, None].to(dt)
            lv["edge_count"] = torch.from_numpy(
                np.bincount(hf.edge, minlength=len(hf.E)).astype(np.float64))[:, None].to(dt)
            self.levels.append(lv)
            self.faces.append(F)
            F = refine(F, n, hf.EF)
            n = n + len(hf.E)
        self.faces.append(F)
        self.n_final = n


def _mlp(torch, fin):
    nn = torch.nn
    net = nn.Sequential(nn.Linear(fin, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, HIDDEN), nn.ReLU(),
                        nn.Linear(HIDDEN, FEATURES))
    for mod in net:
        if isinstance(mod, nn.Linear):
            nn.init.xavier_normal_(mod.weight)
            nn.init.zeros_(mod.bias)
    return net.to(DTYPE_NAME == 'float64' and torch.float64 or torch.float32)


def _normalize(torch, x):
    return x / torch.linalg.vector_norm(x, dim=1, keepdim=True).clamp_min(1e-12)


class SubdivisionNet:
    """The three half-flap modules; :meth:`forward` runs I, then (V, E) per level.

    Built lazily on torch; ``self.module`` is a ``torch.nn.ModuleDict`` with keys I, V, E.
    """

    def __init__(self, seed: int | None = 0):
        torch = _torch()
        if seed is not None:
            g = torch.random.fork_rng()
            g.__enter__()
            torch.manual_seed(int(seed))
        try:
            self.module = torch.nn.ModuleDict({
                "I": _mlp(torch, 3 * 3 + 4 * 3),
                "V": _mlp(torch, 3 * 3 + 4 * FEATURES),
                "E": _mlp(torch, 3 * 3 + 4 * FEATURES)})
        finally:
            if seed is not None:
                g.__exit__(None, None, None)

    # -- one step -----------------------------------------------------------------------------
    @staticmethod
    def _frames(torch, V, lv):
        F = lv["F"]
        FN = torch.linalg.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        FN = _normalize(torch, FN)
        x = _normalize(torch, V[lv["j"]] - V[lv["i"]])
        nz = FN[lv["face"]] + FN[lv["twin"]] * lv["has_twin"][:, None]
        z = _normalize(torch, nz - (nz * x).sum(1, keepdim=True) * x)
        y = torch.linalg.cross(z, x)
        return torch.stack([x, y, z], dim=1)  # rows: local axes

    @staticmethod
    def _laplace(torch, V, lv):
        acc = torch.zeros_like(V).index_add_(0, lv["nb_src"], V[lv["nb_dst"]])
        return V - acc / lv["deg"][:, None]

    def _flap_inputs(self, torch, V, Z, lv):
        R = self._frames(torch, V, lv)
        loc = lambda w: (R * w[:, None, :]).sum(-1)  # noqa: E731
        i, j, k, l = lv["i"], lv["j"], lv["k"], lv["l"]
        Vi = V[i]
        eij, eik = loc(V[j] - Vi), loc(V[k] - Vi)
        mirror = eik * torch.tensor([1.0, -1.0, -1.0], dtype=V.dtype)
        has_l = lv["has_l"][:, None]
        eil = torch.where(has_l, loc(V[l] - Vi), mirror)
        D = self._laplace(torch, V, lv)
        di, dj, dk = loc(D[i]), loc(D[j]), loc(D[k])
        dl = torch.where(has_l, loc(D[l]), dk * torch.tensor([1.0, -1.0, -1.0], dtype=V.dtype))
        if Z is None:
            x = torch.cat([eij, eik, eil, di, dj, dk, dl], dim=1)
        else:
            x = torch.cat([eij, eik, eil, di, Z[i], dj, Z[j], dk, Z[k], dl, Z[l]], dim=1)
        return x, R

    def _apply(self, torch, name, V, Z, lv):
        x, R = self._flap_inputs(torch, V, Z, lv)
        out = self.module[name](x)
        disp = (R * out[:, :3, None]).sum(1)  # back to world axes
        return disp, out[:, 3:]

    def forward(self, V0, levels: MeshLevels, n_levels: int | None = None):
        """Positions of every level: a list of tensors, level 0 (after I) .. L."""
        torch = _torch()
        L = len(levels.levels) if n_levels is None else n_levels
        lv = levels.levels[0]
        disp, feat = self._apply(torch, "I", V0, None, lv)
        V = V0 + torch.zeros_like(V0).index_add_(0, lv["i"], disp) / lv["src_count"]
        Z = torch.zeros(len(V0), FEATURES - 3, dtype=V0.dtype).index_add_(0, lv["i"], feat) \
            / lv["src_count"]
        outs = [V]
        for lev in range(L):
            lv = levels.levels[lev]
            disp, feat = self._apply(torch, "V", V, Z, lv)
            V = V + torch.zeros_like(V).index_add_(0, lv["i"], disp) / lv["src_count"]
            Z = torch.zeros_like(Z).index_add_(0, lv["i"], feat) / lv["src_count"]
            disp, feat = self._apply(torch, "E", V, Z, lv)
            e = lv["e"]
            de = torch.zeros(e, 3, dtype=V.dtype).index_add_(0, lv["edge"], disp) \
                / lv["edge_count"]
            ze = torch.zeros(e, FEATURES - 3, dtype=V.dtype).index_add_(0, lv["edge"], feat) \
                / lv["edge_count"]
            E = lv["E"]
            Vo = 0.5 * (V[E[:, 0]] + V[E[:, 1]]) + de
            V = torch.cat([V, Vo], dim=0)
            Z = torch.cat([Z, ze], dim=0)
            outs.append(V)
        return outs

    @property
    def dtype(self):
        return next(self.module.parameters()).dtype

    # -- state --------------------------------------------------------------------------------
    def state(self) -> dict:
        return {k: v.detach().clone() for k, v in self.module.state_dict().items()}

    def load_state(self, state: dict) -> None:
        self.module.load_state_dict(state)


def neural_subdivide(V, F, levels: int = 2, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """Subdivide a triangle mesh with the neural subdivision network.

    Parameters
    ----------
    V : (n, 3) float, F : (m, 3) int -- a manifold, consistently oriented triangle mesh (closed
        or with boundary, any genus).
    levels : 1..3 (the shipped network was trained for 2).
    weights : a :class:`SubdivisionNet`, a path to a weights file, or None (the shipped weights).

    Returns
    -------
    V_sub : (n_L, 3) float64 (input vertices first, moved; then one vertex per edge per level, in
        the order of :func:`algorithms.subdivision.topology.refine`), F_sub : (m 4^L, 3) int64.
    """
    try:
        lv = int(levels)
        if lv != levels:
            raise ValueError
    except (TypeError, ValueError):
        raise ParameterError(f"The number of levels must be a whole number, not {levels!r}.") \
            from None
    if not 1 <= lv <= MAX_LEVELS:
        raise ParameterError(f"Neural subdivision makes 1 to {MAX_LEVELS} levels (asked for "
                             f"{lv}); for more, continue with Loop subdivision.")
    from ..mesh.subdivision import midpoint_subdivide

    V, F = midpoint_subdivide(V, F, 0)  # the project's input checks
    check_manifold(V, F, "Neural subdivision")
    if len(F) * 4 ** lv > 20_000_000:
        raise ParameterError(f"{lv} levels would make {len(F) * 4 ** lv:,} triangles; use fewer "
                             f"levels.")
    net = weights if isinstance(weights, SubdivisionNet) else load_weights(weights)[0]
    torch = _torch()
    c, s = normalization(V)
    try:
        ml = MeshLevels(F, len(V), lv, net.dtype)
    except Exception as exc:  # noqa: BLE001
        raise InvalidMeshError(f"Neural subdivision could not read the mesh's connectivity "
                               f"({exc}). Run 'Clean' first.") from None
    with torch.no_grad():
        out = net.forward(torch.from_numpy((V - c) * s).to(net.dtype), ml)[-1].double().numpy()
    if not np.isfinite(out).all():
        raise InvalidMeshError("Neural subdivision produced invalid positions (degenerate "
                               "triangles in the input?). Run 'Clean' first.")
    return out / s + c, ml.faces[-1]


# ------------------------------------------------------------------------------ weights files
def save_weights(path, net: SubdivisionNet, info: dict | None = None) -> None:
    """Write ``net`` to ``path`` atomically (a dict of plain tensors, numbers and strings)."""
    torch = _torch()
    from ..mesh.io import atomic_write

    obj = {"format": FORMAT, "version": FORMAT_VERSION, "state": net.state(),
           "info": {str(k): v for k, v in (info or {}).items()
                    if isinstance(v, (int, float, str, bool))}}
    atomic_write(path, lambda fh: torch.save(obj, fh))


def load_weights(path=None) -> tuple[SubdivisionNet, dict]:
    """Read a weights file (None: the shipped one). Returns (net, info).

    Raises WeightsError (a plain message) for a missing file or one that is not ours."""
    torch = _torch()
    p = Path(os.fspath(path)) if path is not None else shipped_weights_path()
    if not p.is_file():
        if path is None:
            raise WeightsError(f"The shipped neural-subdivision weights are missing ({p}). "
                               f"Reinstall Stylize3D, or train weights with 'stylize3d "
                               f"subdivide-train'.")
        raise WeightsError(f"The weights file '{p}' does not exist.")
    try:
        obj = torch.load(p, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - any failure means "not our file"
        raise WeightsError(f"'{p.name}' is not a Stylize3D neural-subdivision weights file (it "
                           f"could not be read as one). Use a file made by 'stylize3d "
                           f"subdivide-train' or the Subdivision panel.") from None
    if not isinstance(obj, dict) or obj.get("format") != FORMAT or "state" not in obj:
        raise WeightsError(f"'{p.name}' is not a Stylize3D neural-subdivision weights file. Use "
                           f"a file made by 'stylize3d subdivide-train' or the Subdivision "
                           f"panel.")
    if int(obj.get("version", 0)) > FORMAT_VERSION:
        raise WeightsError(f"'{p.name}' was written by a newer Stylize3D (format version "
                           f"{obj.get('version')}); update Stylize3D to read it.")
    net = SubdivisionNet(seed=None)
    try:
        net.load_state(obj["state"])
    except Exception:  # noqa: BLE001
        raise WeightsError(f"'{p.name}' holds weights of a different network shape; it is not a "
                           f"neural-subdivision weights file of this version.") from None
    return net, dict(obj.get("info", {}))
