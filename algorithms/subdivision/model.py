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

``SubdivisionNet(formulation="author")`` trains the thesis author's formulation instead (V and E
see the three flap vectors and the four vertices' 29 learned features, 125 inputs, no
differential coordinates; see :mod:`.inference`); :meth:`SubdivisionNet.author_state` gives
its weights in the author's layout, which the NumPy inference runs with ``formulation="author"``
(tested equal). Our weights files hold our formulation only.

Weights files: ``torch.save`` of a dict of plain tensors, numbers and strings, read back with
``torch.load(..., weights_only=True)``; a file without our ``format`` tag gives a plain error.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..compiled import KernelModule
from ..errors import InvalidMeshError, ParameterError, Stylize3DError
from ..params import param
from .data import LOOP_WORKS, check_manifold, normalization
from .inference import SHIPPED_REFERENCE_EDGE, WeightsError, shipped_weights_path
from .topology import half_flaps, refine

__all__ = ["SubdivideParams", "SubdivisionNet", "MeshLevels", "neural_subdivide",
           "neural_subdivide_torch", "save_weights",
           "load_weights", "shipped_weights_path", "WeightsError", "FORMAT", "FEATURES",
           "compiled_kernels", "set_compiled_kernels"]

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
    dense_input: str = param("guard", label="Mesh denser than trained",
                             choices=("guard", "loop", "scale", "off"), advanced=True,
                             tooltip="The network was trained on coarse meshes (a few hundred "
                                     "vertices) and can leave dimples on denser ones. guard: "
                                     "run it (scaled to its training edge length) and, level by "
                                     "level, keep its result unless it is more than 2.6x as "
                                     "bent as modified butterfly's (1.25x on a denser mesh) or "
                                     "bends flat sides (a few isolated bulges get Loop's "
                                     "positions there instead; where it crosses itself, the "
                                     "level before is blended back in there); "
                                     "from there Loop subdivision makes the levels (only for "
                                     "the parts that fail, on a mesh of several parts; a "
                                     "message says so); loop: Loop whenever the mesh "
                                     "is denser than trained; "
                                     "scale: always the network, scaled; off: as is.")


def _torch():
    import torch

    return torch


class MeshLevels:
    """Index tensors of one mesh, or of several meshes side by side, and of their refinements
    (built once, reused across epochs and calls).

    ``levels[l]`` holds the half-flap indices of level ``l`` (0 = the input) for ``l < L``;
    ``faces[l]`` the faces of every level 0..L (numpy). :meth:`batch` puts several meshes' levels
    side by side so that the network runs over all their half-flaps at once (one matrix product
    per layer); every mesh keeps its own vertex order inside its block, so the result is the same
    as running the meshes one by one.
    """

    def __init__(self, F: np.ndarray, n: int, levels: int, dtype=None):
        torch = _torch()
        dt = dtype if dtype is not None else getattr(torch, DTYPE_NAME)
        self.dtype = dt
        self.levels = []
        self.faces = []
        self.sizes = []  # vertices per level (for batching)
        self.meshes = 1
        F = np.asarray(F, dtype=np.int64)
        for _ in range(levels):
            hf = half_flaps(F, n)
            lv = {}
            ijkl = hf.ijkl
            has_l = ijkl[:, 3] >= 0
            lsafe = np.where(has_l, ijkl[:, 3], ijkl[:, 2])
            lv["ijkl"] = torch.from_numpy(np.stack([ijkl[:, 0], ijkl[:, 1], ijkl[:, 2], lsafe],
                                                   axis=1))
            lv["has_l"] = torch.from_numpy(has_l)
            lv["src"] = torch.from_numpy(np.ascontiguousarray(ijkl[:, 0]))  # flap -> its vertex
            lv["boundary"] = bool((~has_l).any())
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
            lv["perm"] = None  # order of cat([old, edge vertices]) in the next level (batches)
            self.levels.append(lv)
            self.faces.append(F)
            self.sizes.append(n)
            F = refine(F, n, hf.EF)
            n = n + len(hf.E)
        self.faces.append(F)
        self.sizes.append(n)
        self.n_final = n

    @classmethod
    def batch(cls, items: "list[MeshLevels]") -> "MeshLevels":
        """Several meshes' levels side by side (same number of levels, same dtype).

        Level ``l`` of the batch holds mesh 0's level-``l`` vertices, then mesh 1's, ...; the
        output of :meth:`SubdivisionNet.forward` at level ``l`` is the concatenation of the
        meshes' own outputs (see :attr:`offsets`)."""
        torch = _torch()
        items = list(items)
        if len(items) == 1:
            return items[0]
        L = len(items[0].levels)
        if any(len(it.levels) != L for it in items):
            raise ValueError("all meshes of a batch need the same number of levels")
        out = cls.__new__(cls)
        out.dtype = items[0].dtype
        out.meshes = sum(it.meshes for it in items)
        out.levels, out.faces = [], []
        out.sizes = [sum(it.sizes[lv] for it in items) for lv in range(L + 1)]
        out.n_final = out.sizes[-1]
        for lev in range(L + 1):
            offs = np.cumsum([0] + [it.sizes[lev] for it in items])[:-1]
            out.faces.append(np.concatenate([it.faces[lev] + o for it, o in zip(items, offs)]))
        for lev in range(L):
            lvs = [it.levels[lev] for it in items]
            voff = np.cumsum([0] + [x["n"] for x in lvs])[:-1]
            foff = np.cumsum([0] + [len(x["F"]) for x in lvs])[:-1]
            eoff = np.cumsum([0] + [x["e"] for x in lvs])[:-1]
            cat = lambda key, off=None: torch.cat(  # noqa: E731
                [x[key] + int(o) for x, o in zip(lvs, off)] if off is not None
                else [x[key] for x in lvs])
            lv = {"ijkl": cat("ijkl", voff), "src": cat("src", voff), "has_l": cat("has_l"),
                  "boundary": any(x["boundary"] for x in lvs),
                  "face": cat("face", foff), "twin": cat("twin", foff),
                  "has_twin": cat("has_twin"), "F": cat("F", voff),
                  "nb_src": cat("nb_src", voff), "nb_dst": cat("nb_dst", voff),
                  "deg": cat("deg"), "edge": cat("edge", eoff), "E": cat("E", voff),
                  "n": int(sum(x["n"] for x in lvs)), "e": int(sum(x["e"] for x in lvs)),
                  "src_count": cat("src_count"), "edge_count": cat("edge_count")}
            # next level: mesh b's block = [its old vertices, its edge vertices]
            n_all = lv["n"]
            parts = []
            for x, vo, eo in zip(lvs, voff, eoff):
                parts.append(np.arange(vo, vo + x["n"]))
                parts.append(n_all + np.arange(eo, eo + x["e"]))
            lv["perm"] = torch.from_numpy(np.concatenate(parts))
            out.levels.append(lv)
        return out


def _mlp(torch, fin):
    nn = torch.nn
    net = nn.Sequential(nn.Linear(fin, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, HIDDEN), nn.ReLU(),
                        nn.Linear(HIDDEN, FEATURES))
    for mod in net:
        if isinstance(mod, nn.Linear):
            nn.init.xavier_normal_(mod.weight)
            nn.init.zeros_(mod.bias)
    return net.to(DTYPE_NAME == 'float64' and torch.float64 or torch.float32)


_KERNELS = KernelModule("algorithms.subdivision.kernels")
_FUSED = {}


def compiled_kernels():
    """The compiled half-flap kernels (:mod:`algorithms.subdivision.kernels`), or None."""
    return _KERNELS.get()


def set_compiled_kernels(enabled: bool) -> bool:
    """Switch the compiled half-flap kernels on or off; returns the previous setting."""
    return _KERNELS.set(enabled)


def _fused(torch):
    """PyTorch autograd Functions over the compiled kernels, or None without them.

    ``Flap``: (V, level) -> (loc (H, 7, 3), R (H, 3, 3)), the differential coordinates, the
    local frames and the flap vectors in them (kernels module docstring); ``SlotGather``:
    (Z4 (n, 4, C), ijkl) -> sum_s Z4[ijkl[:, s], s]; ``Pool``: (out (H, C), R, dst, count) ->
    (N, C), each flap's [R^T out[:3], out[3:]] averaged into its vertex or edge ``dst``. Each
    forward is one compiled loop and so is each backward (no per-operation autograd graph)."""
    kern = _KERNELS.get()
    if kern is None:
        return None
    if "ns" in _FUSED:
        return _FUSED["ns"]

    def arr(t):
        return np.ascontiguousarray(t.detach().numpy())

    def consts(a):  # 1 and the norm clamp in the arrays' precision (kernels docstring)
        return a.dtype.type(1.0), a.dtype.type(kern.EPS)

    class Flap(torch.autograd.Function):
        @staticmethod
        def forward(ctx, V, lv):
            Vn = arr(V)
            ijkl, has_l = lv["ijkl"].numpy(), lv["has_l"].numpy()
            D = np.empty_like(Vn)
            kern.laplace(Vn, lv["nb_src"].numpy(), lv["nb_dst"].numpy(), lv["deg"].numpy(), D)
            H = len(ijkl)
            loc = np.empty((H, 7, 3), dtype=Vn.dtype)
            R = np.empty((H, 3, 3), dtype=Vn.dtype)
            kern.flap_forward(Vn, D, ijkl, has_l, loc, R, *consts(Vn))
            ctx.save_for_backward(V)
            ctx.D = D
            ctx.lv = lv
            return torch.from_numpy(loc), torch.from_numpy(R)

        @staticmethod
        def backward(ctx, gloc, gR):
            (V,) = ctx.saved_tensors
            lv = ctx.lv
            Vn = arr(V)
            H = len(lv["ijkl"])
            gl = arr(gloc) if gloc is not None else np.zeros((H, 7, 3), Vn.dtype)
            gr = arr(gR) if gR is not None else np.zeros((H, 3, 3), Vn.dtype)
            gV = np.zeros_like(Vn)
            gD = np.zeros_like(Vn)
            kern.flap_backward(Vn, ctx.D, lv["ijkl"].numpy(), lv["has_l"].numpy(), gl, gr, gV,
                               gD, *consts(Vn))
            kern.laplace_backward(gD, lv["nb_src"].numpy(), lv["nb_dst"].numpy(),
                                  lv["deg"].numpy(), gV)
            return torch.from_numpy(gV), None

    class Pool(torch.autograd.Function):
        @staticmethod
        def forward(ctx, out, R, dst, count):
            o, Rn = arr(out), arr(R)
            acc = np.empty((len(count), o.shape[1]), dtype=o.dtype)
            inv = 1.0 / count.numpy()
            kern.pool(o, Rn, dst.numpy(), inv, acc)
            ctx.save_for_backward(out, R)
            ctx.idx = (dst, inv)
            return torch.from_numpy(acc)

        @staticmethod
        def backward(ctx, g):
            out, R = ctx.saved_tensors
            dst, inv = ctx.idx
            o, Rn = arr(out), arr(R)
            gout = np.empty_like(o)
            gR = np.empty_like(Rn)
            kern.pool_backward(o, Rn, dst.numpy(), inv, arr(g), gout, gR)
            return torch.from_numpy(gout), torch.from_numpy(gR), None, None

    class SlotGather(torch.autograd.Function):
        @staticmethod
        def forward(ctx, Z4, ijkl):
            z = arr(Z4)
            out = np.empty((len(ijkl), z.shape[2]), dtype=z.dtype)
            kern.slot_gather_sum(z, ijkl.numpy(), out)
            ctx.shape = z.shape
            ctx.ijkl = ijkl
            return torch.from_numpy(out)

        @staticmethod
        def backward(ctx, g):
            gz = np.zeros(ctx.shape, dtype=g.numpy().dtype)
            kern.slot_scatter_add(arr(g), ctx.ijkl.numpy(), gz)
            return torch.from_numpy(gz), None

    class NS:
        pass

    ns = NS()
    ns.Flap, ns.Pool, ns.SlotGather = Flap, Pool, SlotGather
    _FUSED["ns"] = ns
    return ns


def _torch_index(a):
    return _torch().from_numpy(np.asarray(a, dtype=np.int64))


def _normalize(torch, x):
    return x / torch.linalg.vector_norm(x, dim=1, keepdim=True).clamp_min(1e-12)


# columns of the V / E modules' input: eij, eik, eil, di, Zi, dj, Zj, dk, Zk, dl, Zl
_GEO_COLS = np.r_[0:12, 41:44, 73:76, 105:108]
_Z_COLS = np.r_[12:41, 44:73, 76:105, 108:137]
_SLOT = np.arange(4)


class SubdivisionNet:
    """The three half-flap modules; :meth:`forward` runs I, then (V, E) per level.

    Built lazily on torch; ``self.module`` is a ``torch.nn.ModuleDict`` with keys I, V, E.

    Evaluation (mathematically the MLPs of the module docstring, arranged for speed): the seven
    vectors of a half-flap are turned into its local frame by one batched product; the first
    layer of V and E is split into its geometric columns (applied per half-flap) and its feature
    columns, which are applied once per *vertex* and then gathered to the flaps (a vertex is in
    ~24 half-flaps, so this saves most of the first layer's work). With Numba (the project's
    kernel switch, :mod:`algorithms.compiled`) the differential coordinates, frames, flap
    vectors, feature gathers and the averaging into vertices / edges run as compiled loops
    with hand-written backward passes (:func:`_fused`, :mod:`algorithms.subdivision.kernels`;
    tested against this PyTorch path and finite differences); ``fused = False`` on an instance
    or ``set_compiled_kernels(False)`` selects the plain PyTorch path.
    """

    def __init__(self, seed: int | None = 0, formulation: str = "stylize3d"):
        torch = _torch()
        if formulation not in ("stylize3d", "author"):
            raise ParameterError(f"Unknown network formulation {formulation!r} (use "
                                 f"'stylize3d' or 'author').")
        self.formulation = formulation
        self.fused = True  # use the compiled kernels where they are available
        if seed is not None:
            g = torch.random.fork_rng()
            g.__enter__()
            torch.manual_seed(int(seed))
        # the author's V / E see no differential coordinates: 3 flap vectors + 4 x 29 features
        fin = 3 * 3 + 4 * (FEATURES if formulation == "stylize3d" else FEATURES - 3)
        try:
            self.module = torch.nn.ModuleDict({
                "I": _mlp(torch, 3 * 3 + 4 * 3),
                "V": _mlp(torch, fin),
                "E": _mlp(torch, fin)})
        finally:
            if seed is not None:
                g.__exit__(None, None, None)

    # -- one step -----------------------------------------------------------------------------
    @staticmethod
    def _frames(torch, V, P, lv):
        """(H, 3, 3) local frames (rows x, y, z) and the flap vectors P - P_i."""
        F = lv["F"]
        VF = V[F]
        FN = _normalize(torch, torch.linalg.cross(VF[:, 1] - VF[:, 0], VF[:, 2] - VF[:, 0]))
        x = _normalize(torch, P[:, 1] - P[:, 0])
        nz = FN[lv["face"]] + FN[lv["twin"]] * lv["has_twin"][:, None]
        z = _normalize(torch, nz - (nz * x).sum(1, keepdim=True) * x)
        y = torch.linalg.cross(z, x)
        return torch.stack([x, y, z], dim=1)

    @staticmethod
    def _laplace(torch, V, lv):
        acc = torch.zeros_like(V).index_add_(0, lv["nb_src"], V[lv["nb_dst"]])
        return V - acc / lv["deg"][:, None]

    def _pooled(self, torch, name, V, Z, lv, dst, count):
        """Module ``name`` on every half-flap of level ``lv``, its outputs averaged into
        ``dst`` (vertices or edges; ``count`` flaps each): (N, 32) = [world displacement,
        feature]."""
        fused = _fused(torch) if self.fused else None
        if fused is None:
            disp, feat = self._apply_torch(torch, name, V, Z, lv)
            return torch.zeros(len(count), FEATURES, dtype=V.dtype).index_add_(
                0, dst, torch.cat([disp, feat], dim=1)) / count
        ijkl = lv["ijkl"]
        loc, R = fused.Flap.apply(V, lv)
        mlp = self.module[name]
        h = self._first_layer(torch, mlp[0], loc, Z, lambda ZW: fused.SlotGather.apply(
            ZW.reshape(-1, 4, HIDDEN), ijkl))
        return fused.Pool.apply(mlp[1:](h), R, dst, count.reshape(-1))

    def _first_layer(self, torch, lin, loc, Z, gather):
        """The first layer's pre-activations: its geometric columns applied to every flap's
        ``loc``, its feature columns applied once per vertex (``Z @ wz``: (n, 4 * 32), the four
        flap slots side by side) and summed over each flap's vertices by ``gather``.

        The author's formulation (V, E): the geometric columns are the 3 flap vectors only
        (columns 0:9), the features follow (9:125, vertex by vertex)."""
        if Z is None:
            return lin(loc.reshape(len(loc), 21))
        w = lin.weight
        if self.formulation == "author":
            h = torch.nn.functional.linear(loc[:, :3].reshape(len(loc), 9), w[:, :9], lin.bias)
            wz = w[:, 9:].reshape(HIDDEN, 4, FEATURES - 3).transpose(0, 1)
        else:
            h = torch.nn.functional.linear(loc.reshape(len(loc), 21), w[:, _GEO_COLS], lin.bias)
            wz = w[:, _Z_COLS].reshape(HIDDEN, 4, FEATURES - 3).transpose(0, 1)  # (4, 32, 29)
        return h + gather(Z @ wz.reshape(4 * HIDDEN, FEATURES - 3).T)

    def author_state(self) -> dict:
        """The weights in the thesis author's layout (``net_init`` / ``net_vertex`` /
        ``net_edge``, layers ``layerIn``, ``hidden.0``, ``layerOut``; columns in the author's
        order), for :func:`~algorithms.subdivision.inference.network_from_state` with
        ``formulation="author"``. Only for networks of the author's formulation."""
        if self.formulation != "author":
            raise ParameterError("Only a network of the author's formulation has the author's "
                                 "layout.")
        # ours I: [e_ij, e_ik, e_il, d_i, d_j, d_k, d_l] -> [d_i, p_j, d_j, p_k, d_k, p_l, d_l]
        perm_i = np.r_[9:12, 0:3, 12:15, 3:6, 15:18, 6:9, 18:21]
        # ours V/E: [e_ij, e_ik, e_il, z_i, z_j, z_k, z_l] -> [z_i, p_j, z_j, p_k, z_k, p_l, z_l]
        perm_ve = np.r_[9:38, 0:3, 38:67, 3:6, 67:96, 6:9, 96:125]
        out = {}
        for name, key, perm in (("I", "net_init", perm_i), ("V", "net_vertex", perm_ve),
                                ("E", "net_edge", perm_ve)):
            mlp = self.module[name]
            for idx, layer in ((0, "layerIn"), (2, "hidden.0"), (4, "layerOut")):
                W = mlp[idx].weight.detach().clone()
                if idx == 0:
                    W = W[:, _torch_index(perm)]
                out[f"{key}.{layer}.weight"] = W
                out[f"{key}.{layer}.bias"] = mlp[idx].bias.detach().clone()
        return out

    def _apply_torch(self, torch, name, V, Z, lv):
        """Outputs of module ``name`` on every half-flap: world displacement (H, 3), feature
        (plain PyTorch operations: Numba missing or switched off)."""
        ijkl = lv["ijkl"]
        PD = torch.cat([V, self._laplace(torch, V, lv)], dim=1)[ijkl]  # (H, 4, 6): one gather
        P, D = PD[..., :3], PD[..., 3:]
        R = self._frames(torch, V, P, lv)
        W = torch.cat([P[:, 1:] - P[:, :1], D], dim=1)  # eij eik eil di dj dk dl: (H, 7, 3)
        loc = torch.bmm(W, R.transpose(1, 2))        # in the local frame
        if lv["boundary"]:  # no l: the mirror of k (rotated by pi about the edge)
            flip = torch.tensor([1.0, -1.0, -1.0], dtype=V.dtype)
            has_l = lv["has_l"][:, None, None]
            loc = torch.cat([loc[:, :2], torch.where(has_l, loc[:, 2:3], loc[:, 1:2] * flip),
                             loc[:, 3:6], torch.where(has_l, loc[:, 6:7], loc[:, 5:6] * flip)],
                            dim=1)
        mlp = self.module[name]
        h = self._first_layer(torch, mlp[0], loc, Z, lambda ZW: ZW.reshape(-1, HIDDEN)[
            ijkl * 4 + torch.from_numpy(_SLOT)].sum(1))
        out = mlp[1:](h)
        disp = torch.bmm(out[:, None, :3], R)[:, 0]  # back to world axes
        return disp, out[:, 3:]

    @property
    def mirror_average(self) -> bool:
        """Whether inference averages the network with its mirror image (ours: yes; the
        author's formulation runs as published). See
        :func:`algorithms.subdivision.inference._mirrored_stage`."""
        return self.formulation == "stylize3d"

    def forward(self, V0, levels: MeshLevels, n_levels: int | None = None,
                mirror: bool = False):
        """Positions of every level: a list of tensors, level 0 (after I) .. L.

        ``mirror``: every stage is averaged with the network run on the mesh mirrored in x
        (its own features carried level to level), its displacement mirrored back -- what
        inference does (:attr:`mirror_average`); training's loss runs the plain network."""
        torch = _torch()
        L = len(levels.levels) if n_levels is None else n_levels
        sign = torch.tensor([-1.0, 1.0, 1.0], dtype=V0.dtype)

        def pooled(name, V, Zs, lv, dst, count):
            a = self._pooled(torch, name, V, Zs[0], lv, dst, count)
            if not mirror:
                return a[:, :3], [a[:, 3:]]
            b = self._pooled(torch, name, V * sign, Zs[1], lv, dst, count)
            return 0.5 * (a[:, :3] + b[:, :3] * sign), [a[:, 3:], b[:, 3:]]

        lv = levels.levels[0]
        disp, Zs = pooled("I", V0, [None, None], lv, lv["src"], lv["src_count"])
        V = V0 + disp
        outs = [V]
        for lev in range(L):
            lv = levels.levels[lev]
            disp, Zs = pooled("V", V, Zs, lv, lv["src"], lv["src_count"])
            V = V + disp
            dispE, ZE = pooled("E", V, Zs, lv, lv["edge"], lv["edge_count"])
            E = lv["E"]
            Vo = 0.5 * (V[E[:, 0]] + V[E[:, 1]]) + dispE
            V = torch.cat([V, Vo], dim=0)
            Zs = [torch.cat([Z, Ze], dim=0) for Z, Ze in zip(Zs, ZE)]
            if lv["perm"] is not None:
                V = V[lv["perm"]]
                Zs = [Z[lv["perm"]] for Z in Zs]
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


def neural_subdivide(V, F, levels: int = 2, weights=None, *, adapt_scale: bool = True,
                     dense: str = "loop") -> tuple[np.ndarray, np.ndarray]:
    """Subdivide a triangle mesh with the neural subdivision network (NumPy inference,
    :mod:`.inference`; no PyTorch unless ``weights`` is a :class:`SubdivisionNet`).

    Parameters
    ----------
    V : (n, 3) float, F : (m, 3) int -- a manifold, consistently oriented triangle mesh (closed
        or with boundary, any genus).
    levels : 1..3 (the shipped network was trained for 2).
    weights : an :class:`~algorithms.subdivision.inference.Network`, a
        :class:`SubdivisionNet`, a path to a weights file (ours or the thesis author's), or None
        (the shipped weights).
    adapt_scale : keep the network within its training edge length
        (:func:`~algorithms.subdivision.inference.scale_plan`);
    dense : for a mesh denser than the training meshes: "loop" (Loop subdivision instead),
        "scale" (the network, scaled) or "off" (the network as is).

    Returns
    -------
    V_sub : (n_L, 3) float64 (input vertices first, moved; then one vertex per edge per level, in
        the order of :func:`algorithms.subdivision.topology.refine`), F_sub : (m 4^L, 3) int64.
    """
    from .inference import (Network, load_network, network_from_state, neural_subdivide_np)

    if isinstance(weights, Network):
        net = weights
    elif isinstance(weights, SubdivisionNet):
        net = network_from_state(weights.state(), "stylize3d",
                                 reference_edge=getattr(weights, "reference_edge", None)
                                 or SHIPPED_REFERENCE_EDGE)
    else:
        net = load_network(weights)
    V_sub, F_sub, _ = neural_subdivide_np(V, F, levels, net, adapt_scale=adapt_scale,
                                          dense=dense)
    return V_sub, F_sub


def neural_subdivide_torch(V, F, levels: int = 2, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """The PyTorch path of :func:`neural_subdivide` (``SubdivisionNet.forward``, the code
    training differentiates), without the scale guard: the peer the NumPy inference is tested
    and timed against.

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
    check_manifold(V, F, "Neural subdivision", LOOP_WORKS)
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
        out = net.forward(torch.from_numpy((V - c) * s).to(net.dtype), ml,
                          mirror=net.mirror_average)[-1].double().numpy()
    if not np.isfinite(out).all():
        raise InvalidMeshError("Neural subdivision produced invalid positions (degenerate "
                               "triangles in the input?). Run 'Clean' first.")
    return out / s + c, ml.faces[-1]


# ------------------------------------------------------------------------------ weights files
def save_weights(path, net, info: dict | None = None) -> None:
    """Write ``net`` (a :class:`SubdivisionNet`, or a NumPy
    :class:`~algorithms.subdivision.inference.Network` of our formulation) to ``path``
    atomically (a dict of plain tensors, numbers and strings)."""
    torch = _torch()
    from ..mesh.io import atomic_write
    from .inference import Network

    if isinstance(net, Network):
        if net.formulation != "stylize3d":
            raise WeightsError("Only networks of Stylize3D's formulation can be saved as "
                               "Stylize3D weights (this one is the thesis author's).")
        state = net.state()
        if net.reference_edge:  # the scale guard's reference goes with the weights
            info = {"mean_edge_length": float(net.reference_edge), **(info or {})}
    else:
        if getattr(net, "formulation", "stylize3d") != "stylize3d":
            raise WeightsError("Only networks of Stylize3D's formulation can be saved as "
                               "Stylize3D weights (this one is of the thesis author's "
                               "formulation: save author_state() with torch.save instead).")
        state = net.state()
    obj = {"format": FORMAT, "version": FORMAT_VERSION, "state": state,
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
