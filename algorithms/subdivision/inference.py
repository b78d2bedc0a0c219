"""Neural subdivision with a trained network, in NumPy (no PyTorch): the project's networks and
the thesis author's published one.

PyTorch is needed to *train* (:mod:`.model`, :mod:`.train`); subdividing with trained weights
runs here, on float32 arrays, with the same mathematics as ``SubdivisionNet.forward`` (tested to
agree within 1e-5 of the bounding-box diagonal) and without importing torch.

**Two formulations** (the file says which, see :func:`load_network`):

* ``"stylize3d"`` (ours, :mod:`.model`'s docstring): per half-flap ``(i, j, k, l)`` in its local
  frame, ``I`` sees the edge vectors ``j-i, k-i, l-i`` and the four differential coordinates;
  ``V`` and ``E`` see the edge vectors and each vertex's ``[delta_v, z_v]`` (differential
  coordinates recomputed from the current positions + 29 learned features); 137 inputs. Inputs
  are scaled by :func:`algorithms.subdivision.data.normalization` (centroid, farthest vertex).
* ``"author"`` (the thesis author's published network, ``netparams.dat`` + its
  ``hyperparameters.json``; described in ../shared/reference/neural_subdivision/README.md): per
  half-flap the four vertices' vectors in the local frame with the first vertex's position (the
  origin, always 0) left out -- ``I``: ``[d_i, p_j, d_j, p_k, d_k, p_l, d_l]`` (21),
  ``V``/``E``: ``[z_i, p_j, z_j, p_k, z_k, p_l, z_l]`` (125; positions and 29 learned features,
  no differential coordinates). The mesh is scaled to the unit cube first,
  ``(V - min V) / max(V - min V)``, and back after.

Everything else is shared, and was checked against the author's outputs (the reproduction test):
the local frame (x along the half-edge, z the sum of its two face normals made orthogonal to x,
y = z x x), the uniform differential coordinates ``v - mean(neighbours)``, averaging the 32
outputs of the half-flaps into their first vertex (``I``, ``V``: the first 3, turned back to world
axes, move the vertex) or their edge (``E``: the new vertex is the edge mid-point of the updated
vertices plus the averaged displacement), and the order I, then per level V then E. On a
boundary edge the missing ``l`` is ``k`` turned by pi about the edge (ours; the author's code
refuses meshes with boundary).

**The mirror average** (ours, not the thesis's; :attr:`Network.mirror_average`): every stage of
our networks is averaged with the same network run on the mesh mirrored in x (its own learned
features carried level to level), its displacement mirrored back (:func:`_mirrored_stage`).
The half-flap network is equivariant to rotations but not to reflections; the average is, so a
region flat over the network's reach stays exactly flat, and the network's bias along the
normal on flaps flatter than it was trained on (dimples on dense meshes) cancels. It costs a
second pass of the network. Measured (docs/results/subdivision.md, "The mirror average"):
fandisk as it is 1.9 -> 0.01 degrees off its flat sides; bob as it is 2.28x -> 1.15x
butterfly's bending; the default on 32 coarse unseen meshes (Table 4.2 protocol) mean H
1.659 -> 1.420 % and M 0.139 -> 0.128 % (1.205 / 0.113 with the crossing repair of
:func:`_blend_back_where_crossed`). The author's network runs as published, without it.

**Staying inside what the network was trained on** (:func:`scale_plan`). The network is not
scale invariant (thesis §4.7): it was trained on coarse meshes of 150-300 vertices, so in its
normalized frame it has only seen edges of about one length (``reference_edge``: the mean edge
length of its training meshes, in the file's ``info`` or, for older files, the values measured
below) and flaps bent as much as a 150-300-vertex mesh's. A dense mesh (fandisk's 7,229
vertices) normalized by its overall size has edges ~5x shorter, and the network's displacements
-- learned at the training edge length -- come out as dimples of about one edge all over flat
and smooth parts (fandisk, 2 levels: 32 degrees RMS off its flat sides; Loop: 0.01). Scaling the
mesh so its mean edge length is the training one cuts that ~10x, but not to Loop's level (the
flaps are the right size but far flatter than any the network saw), so:

* a mesh within :data:`SCALE_TOLERANCE` of the training edge length is used as the formulation
  scales it (the author's outputs and the Table 4.2 protocol, 350-450 vertices, unchanged);
* a coarser one is scaled so its mean edge length is the training one;
* a denser one is scaled like a coarser one and its result compared with butterfly's
  (``dense="guard"``, the application's default; :class:`_Guard`), or gets Loop subdivision
  instead (``"loop"``, this function's default), with a message saying so and suggesting
  'Coarsen first' to a vertex count the network was trained for; or, on request, the network
  scaled without the comparison (``"scale"``) or as is (``"off"``).

A mesh of several parts (sharing no vertex) is judged part by part (:func:`_part_ratios`:
each part's density as if it were alone; a scene's gaps would otherwise make every part look
denser: fandisk 4 diagonals from a small sphere read "45x denser", alone 5.7x), and 'Coarsen
first' (:func:`coarsen_for_network`) simplifies each part to its share of the count, so that
the advised count brings every part into range. The network still sees the whole mesh in one
frame.

Every such decision is said in ``SubdividedStep.note`` (empty when nothing was done);
``adapt_scale=False`` turns the guard off.

**Progress and Stop**: :func:`neural_subdivision_iter` works in chunks of about
:data:`CHUNK_FLAPS` half-flaps and yields a progress step after each (``"Level 1 of 2: ..."``
with per-mille progress), so a consumer that stops listening stops the work within one chunk.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import InvalidMeshError, ParameterError, Stylize3DError
from ..steps import Step
from .topology import half_flaps, refine
from .weights_file import NotATorchFile, read_torch_file

__all__ = ["Network", "load_network", "WeightsError", "shipped_weights_path", "network_from_state", "neural_subdivision_iter",
           "neural_subdivide_np", "SubdividedStep", "scale_plan", "mean_edge_length",
           "coarsen_for_network",
           "FORMULATIONS", "SCALE_TOLERANCE", "CHUNK_FLAPS", "OUR_FORMAT",
           "SHIPPED_REFERENCE_EDGE", "AUTHOR_REFERENCE_EDGE", "ScalePlan",
           "DENSE_CHOICES"]

OUR_FORMAT = "stylize3d-neural-subdivision"
FORMULATIONS = ("stylize3d", "author")
FEATURES = 32
MAX_LEVELS = 3
#: inputs whose mean edge length is within this factor of the training meshes' are left as is
SCALE_TOLERANCE = 1.5
#: half-flaps per chunk of work between two progress steps (~10-30 ms of work here)
CHUNK_FLAPS = 40_000
#: mean edge length of the training coarse meshes in the normalized frame, for files that do
#: not record it (files trained since record theirs as ``info["mean_edge_length"]``): the
#: shipped weights' data (armadillo scaled by
#: :func:`~algorithms.subdivision.data.normalization`, coarse meshes of 150-300 vertices by
#: :func:`~algorithms.subdivision.data.generate_coarse_sample`): 0.268 on the first 12 of
#: them (0.226-0.306), measured 2026-11-26
SHIPPED_REFERENCE_EDGE = 0.268
#: the same for the author's network: its validation meshes (cartoon_elephant_10/subd0, ~300
#: vertices, of the shape its 200 training meshes came from) in the unit cube: 0.0961
#: (0.0895-0.1025); test-checked
AUTHOR_REFERENCE_EDGE = 0.0961


class WeightsError(Stylize3DError):
    """A weights file is missing, unreadable or not a neural-subdivision weights file."""

    exit_code = 2


class WeightsFileError(Exception):
    """Why a file is not a network (inside :func:`load_network`)."""


def shipped_weights_path() -> Path:
    """The weights trained by the project (resources/subdivision/neural_subdivision.pt)."""
    return Path(__file__).resolve().parents[2] / "resources" / "subdivision" / \
        "neural_subdivision.pt"


# ------------------------------------------------------------------------------ BLAS threads
_BLAS: dict = {}


def _openblas():
    """(get, set) of the thread count of NumPy's bundled OpenBLAS, or None (another BLAS)."""
    if "fns" in _BLAS:
        return _BLAS["fns"]
    fns = None
    try:
        import ctypes
        import glob

        libdir = Path(np.__file__).resolve().parent.parent / "numpy.libs"
        for lib in sorted(glob.glob(str(libdir / "libscipy_openblas*.so*"))):
            dll = ctypes.CDLL(lib)
            for suffix in ("64_", "_64_", ""):
                get = getattr(dll, f"scipy_openblas_get_num_threads{suffix}", None)
                put = getattr(dll, f"scipy_openblas_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    get.restype = ctypes.c_int
                    put.argtypes = [ctypes.c_int]
                    fns = (get, put)
                    break
            if fns:
                break
    except Exception:  # noqa: BLE001 - no such library: leave BLAS alone
        fns = None
    _BLAS["fns"] = fns
    return fns


class _OneBlasThread:
    """Run NumPy's matrix products on one thread inside the block (restored after).

    The network's products are narrow ((h, 21..137) x (.., 32)); OpenBLAS's threads do not pay
    there and, when the cores are busy with other work, they cost up to 10x (measured: a
    (77k, 21) x (21, 32) product 3 ms on one thread, 40-75 ms on two with the machine loaded)."""

    def __enter__(self):
        fns = _openblas()
        self.old = None
        if fns is not None:
            self.old = int(fns[0]())
            if self.old != 1:
                fns[1](1)
        return self

    def __exit__(self, *exc):
        fns = _openblas()
        if fns is not None and self.old is not None and self.old != 1:
            fns[1](self.old)
        return False


# ------------------------------------------------------------------------------ the network
@dataclass
class _Module:
    """One half-flap MLP, its first layer split into geometric and feature columns.

    ``slots``: which of the 7 canonical flap vectors (``p_j, p_k, p_l, d_i, d_j, d_k, d_l`` in
    the local frame) it reads; ``Wg`` (3 len(slots), H1); ``Wz`` (29, 4 H1) or None: the feature
    columns of the 4 flap vertices side by side; ``b0`` (H1,); ``rest``: [(W^T, b)] of the other
    layers (ReLU between layers, none after the last)."""

    slots: tuple
    Wg: np.ndarray
    Wz: np.ndarray | None
    b0: np.ndarray
    rest: list

    def hidden(self, geo: np.ndarray, Zw: np.ndarray | None, ijkl: np.ndarray) -> np.ndarray:
        """(h, 32) outputs for the flap vectors ``geo`` (h, 3 len(slots)) and the per-vertex
        feature products ``Zw`` (n, 4 H1)."""
        h = geo @ self.Wg
        h += self.b0
        if Zw is not None:
            H1 = self.b0.shape[0]
            flat = Zw.reshape(-1, H1)
            idx = ijkl * 4 + np.arange(4)
            h += flat[idx[:, 0]]
            h += flat[idx[:, 1]]
            h += flat[idx[:, 2]]
            h += flat[idx[:, 3]]
        for W, b in self.rest:
            np.maximum(h, 0, out=h)
            h = h @ W
            h += b
        return h


@dataclass
class Network:
    """A trained neural-subdivision network, ready for NumPy inference.

    formulation : "stylize3d" or "author" (module docstring).
    modules : {"I", "V", "E"} -> _Module.
    reference_edge : mean edge length of the training meshes in the normalized frame (None:
        unknown, no scale guard).
    info : what the file says about its training (plain values).
    name : a short description for messages.
    arrays : the layers as read, {name: array} (for comparisons and saving).
    """

    formulation: str
    modules: dict
    reference_edge: float | None
    info: dict = field(default_factory=dict)
    name: str = "network"
    arrays: dict = field(default_factory=dict)
    #: average with the mirror image (None: ours yes, the author's no; see mirror_average)
    mirror: bool | None = None

    def state(self) -> dict:
        """The layers as PyTorch tensors (imports torch: for training, saving and comparing with
        a ``SubdivisionNet.state()``; inference never calls it)."""
        import torch

        return {k: torch.from_numpy(np.array(v)) for k, v in self.arrays.items()}

    @property
    def uses_differential_coordinates(self) -> bool:
        return self.formulation == "stylize3d"

    @property
    def mirror_average(self) -> bool:
        """Whether inference averages the network with its mirror image
        (:func:`_mirrored_stage`): :attr:`mirror` when set; otherwise ours yes, the thesis
        author's network no (it runs as published)."""
        if self.mirror is not None:
            return bool(self.mirror)
        return self.formulation == "stylize3d"

    def normalization(self, V: np.ndarray) -> tuple[np.ndarray, float]:
        """(centre, scale) of the formulation: normalized = (V - centre) * scale."""
        if self.formulation == "author":
            lo = V.min(axis=0)
            ext = float((V - lo).max()) if len(V) else 0.0
            if not np.isfinite(ext) or ext <= 0:
                raise InvalidMeshError("The mesh has no extent (all vertices at one point), so "
                                       "it cannot be subdivided.")
            return lo, 1.0 / ext
        from .data import normalization

        return normalization(V)


def _relu_chain(layers: list, fin_expected: int, what: str) -> list:
    """Check a list of (W (out, in), b (out,)) layers; returns them as float32."""
    out = []
    fin = fin_expected
    for W, b in layers:
        W = np.asarray(W)
        b = np.asarray(b)
        if W.ndim != 2 or b.ndim != 1 or W.shape[1] != fin or b.shape[0] != W.shape[0]:
            raise WeightsFileError(f"the {what} network's layers do not fit together")
        out.append((W.astype(np.float32), b.astype(np.float32)))
        fin = W.shape[0]
    if fin != FEATURES:
        raise WeightsFileError(f"the {what} network has {fin} outputs, not {FEATURES}")
    return out


def _make_module(layers: list, geo_cols: dict, z_cols: list | None) -> _Module:
    """``geo_cols``: canonical slot -> its 3 input columns; ``z_cols``: per flap vertex its 29
    feature columns (or None)."""
    W0, b0 = layers[0]
    slots = tuple(sorted(geo_cols))
    Wg = np.concatenate([W0[:, geo_cols[s]] for s in slots], axis=1).T.copy()
    Wz = None
    if z_cols is not None:
        Wz = np.concatenate([W0[:, c] for c in z_cols], axis=0)  # (4 H1, 29)
        Wz = np.ascontiguousarray(Wz.T)  # (29, 4 H1)
    rest = [(np.ascontiguousarray(W.T), b.copy()) for W, b in layers[1:]]
    return _Module(slots, np.ascontiguousarray(Wg), Wz, b0.copy(), rest)


def _r(a, n=3):
    return list(range(a, a + n))


def _ours_modules(state: dict) -> dict:
    """Our layout (model.py: Sequential Linear-ReLU-Linear-ReLU-Linear, keys ``I.0.weight``)."""
    mods = {}
    for name, fin in (("I", 21), ("V", 137), ("E", 137)):
        idx = sorted({int(k.split(".")[1]) for k in state if k.startswith(name + ".")
                      and k.count(".") == 2 and k.split(".")[1].isdigit()})
        try:
            if not idx:
                raise KeyError(name)
            layers = [(state[f"{name}.{i}.weight"], state[f"{name}.{i}.bias"]) for i in idx]
        except KeyError:
            raise WeightsFileError(f"module {name} is missing or incomplete") from None
        layers = _relu_chain(layers, fin, name)
        if name == "I":  # [e_ij, e_ik, e_il, d_i, d_j, d_k, d_l]
            geo = {s: _r(3 * s) for s in range(7)}
            mods[name] = _make_module(layers, geo, None)
        else:  # [e_ij, e_ik, e_il, d_i, z_i, d_j, z_j, d_k, z_k, d_l, z_l]
            geo = {0: _r(0), 1: _r(3), 2: _r(6)}
            for v in range(4):
                geo[3 + v] = _r(9 + 32 * v)
            z = [_r(12 + 32 * v, 29) for v in range(4)]
            mods[name] = _make_module(layers, geo, z)
    return mods


def _author_modules(state: dict) -> dict:
    """The author's layout (``net_init`` / ``net_vertex`` / ``net_edge``, layers ``layerIn``,
    ``hidden.N``, ``layerOut``)."""
    mods = {}
    for name, key, fin in (("I", "net_init", 21), ("V", "net_vertex", 125),
                           ("E", "net_edge", 125)):
        try:
            hid = sorted({int(k.split(".")[2]) for k in state
                          if k.startswith(f"{key}.hidden.") and k.endswith(".weight")})
            names = ["layerIn"] + [f"hidden.{i}" for i in hid] + ["layerOut"]
            layers = [(state[f"{key}.{n}.weight"], state[f"{key}.{n}.bias"]) for n in names]
        except (KeyError, ValueError):
            raise WeightsFileError(f"{key} is missing or incomplete") from None
        layers = _relu_chain(layers, fin, key)
        if name == "I":  # [d_i, p_j, d_j, p_k, d_k, p_l, d_l]
            geo = {3: _r(0), 0: _r(3), 4: _r(6), 1: _r(9), 5: _r(12), 2: _r(15), 6: _r(18)}
            mods[name] = _make_module(layers, geo, None)
        else:  # [z_i, p_j, z_j, p_k, z_k, p_l, z_l]
            geo = {0: _r(29), 1: _r(61), 2: _r(93)}
            z = [_r(0, 29), _r(32, 29), _r(64, 29), _r(96, 29)]
            mods[name] = _make_module(layers, geo, z)
    return mods


def network_from_state(state: dict, formulation: str = "stylize3d", *,
                       reference_edge: float | None = None, info: dict | None = None,
                       name: str = "network") -> Network:
    """A :class:`Network` from layer arrays (NumPy arrays or anything ``np.asarray`` takes,
    e.g. a ``SubdivisionNet.state()`` of tensors)."""
    st = {str(k): np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v)
          for k, v in state.items()}
    if formulation == "stylize3d":
        mods = _ours_modules(st)
    elif formulation == "author":
        mods = _author_modules(st)
    else:
        raise ValueError(f"unknown formulation {formulation!r}")
    return Network(formulation, mods, reference_edge, dict(info or {}), name, st)


def _author_hyperparameters(path: Path) -> dict:
    hp = path.with_name("hyperparameters.json")
    if not hp.is_file():
        return {}
    try:
        d = json.loads(hp.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        raise WeightsFileError(f"its {hp.name} could not be read") from None
    if not isinstance(d, dict):
        raise WeightsFileError(f"its {hp.name} is not a settings file")
    if d.get("Din", 6) != 6 or d.get("Dout", FEATURES) != FEATURES:
        raise WeightsFileError(f"its {hp.name} describes another network (Din {d.get('Din')}, "
                               f"Dout {d.get('Dout')}; this reader knows Din 6, Dout 32)")
    return d


def load_network(path=None) -> Network:
    """Read a weights file without PyTorch (None: the shipped weights): the project's
    (``torch.save`` of our dict, with ``format`` = :data:`OUR_FORMAT`) or the thesis author's
    ``netparams.dat`` (a state dict of ``net_init`` / ``net_vertex`` / ``net_edge``; its
    ``hyperparameters.json`` beside it is read and checked when present). Raises
    :class:`WeightsError` with a plain message otherwise."""
    p = Path(os.fspath(path)) if path is not None else shipped_weights_path()
    if not p.is_file():
        if path is None:
            raise WeightsError(f"The shipped neural-subdivision weights are missing ({p}). "
                               f"Reinstall Stylize3D, or train weights with 'stylize3d "
                               f"subdivide-train'.")
        raise WeightsError(f"The weights file '{p}' does not exist.")
    try:
        return _load_network(p)
    except WeightsFileError as exc:
        raise WeightsError(f"'{p.name}' is not a Stylize3D neural-subdivision weights file, nor "
                           f"the thesis author's published network: {exc}. Use a file made by "
                           f"'stylize3d subdivide-train' or the Subdivision panel, or the "
                           f"author's netparams.dat with its hyperparameters.json.") from None


def _load_network(p: Path) -> Network:
    try:
        obj = read_torch_file(p)
    except NotATorchFile as exc:
        raise WeightsFileError(f"it could not be read as one ({exc})") from None
    except OSError as exc:
        raise WeightsFileError(f"it could not be opened ({exc.strerror or exc})") from None
    if isinstance(obj, dict) and obj.get("format") == OUR_FORMAT and isinstance(
            obj.get("state"), dict):
        info = {str(k): v for k, v in dict(obj.get("info") or {}).items()
                if isinstance(v, (int, float, str, bool))}
        ref = info.get("mean_edge_length")
        if not isinstance(ref, (int, float)) or not ref > 0:
            ref = SHIPPED_REFERENCE_EDGE
        if int(obj.get("version", 0)) > 1:
            raise WeightsFileError(f"it was written by a newer Stylize3D (format version "
                                   f"{obj.get('version')}); update Stylize3D to read it")
        return network_from_state(obj["state"], "stylize3d", reference_edge=float(ref),
                                  info={**info, "format_version": int(obj.get("version", 0))},
                                  name=p.name)
    if isinstance(obj, dict) and any(str(k).startswith("net_init.") for k in obj):
        hp = _author_hyperparameters(p)
        info = {"trained_by": "the thesis author (published weights)"}
        info.update({k: v for k, v in hp.items() if isinstance(v, (int, float, str, bool))})
        return network_from_state(obj, "author", reference_edge=AUTHOR_REFERENCE_EDGE,
                                  info=info, name=p.name)
    raise WeightsFileError("it holds something else than a neural-subdivision network")


# ------------------------------------------------------------------------------ geometry
def mean_edge_length(V: np.ndarray, F: np.ndarray, edges: np.ndarray | None = None) -> float:
    """Mean length of the mesh's undirected edges (``edges`` (e, 2): them, if known)."""
    E = _unique_edges(F, len(V)) if edges is None else edges
    return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())


def _unique_edges(F: np.ndarray, n: int) -> np.ndarray:
    """(e, 2) the undirected edges of ``F`` (``n`` vertices), each once, sorted."""
    F = np.asarray(F, dtype=np.int64)
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    key = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    return np.stack([key // n, key % n], axis=1)


@dataclass
class ScalePlan:
    """How the network sees a mesh: ``(V - centre) * scale``, or not at all (``fallback``:
    Loop subdivision instead); ``note`` says what was done ('' when nothing); ``ratio`` is the
    mesh's mean edge length over the training meshes' (in the normalized frame; nan unknown)."""

    centre: np.ndarray
    scale: float
    note: str = ""
    fallback: bool = False
    ratio: float = float("nan")
    advice: int = 0  # vertices for 'Coarsen first' on a denser mesh (0: none)
    reason: str = ""  # with ``fallback``: why, in one short clause (the batch record's)
    #: on a mesh of several parts, how dense it is in words (the parts judged one by one);
    #: '' for the whole mesh's ratio (:meth:`density_words`)
    density: str = ""

    def density_words(self) -> str:
        """How much denser than the training meshes, for the messages that follow the plan."""
        return self.density or (f"its edges are {1 / self.ratio:.1f}x shorter than its "
                                f"training meshes'")

    @property
    def denser(self) -> bool:
        """The mesh is denser than the training meshes (edges more than SCALE_TOLERANCE times
        shorter)."""
        return bool(np.isfinite(self.ratio) and 0 < self.ratio < 1 / SCALE_TOLERANCE)


#: what to do with a mesh denser than the network's training meshes (see scale_plan); "guard"
#: also compares the network's result with modified butterfly's on every mesh
DENSE_CHOICES = ("guard", "loop", "scale", "off")
#: "guard": the network's result is kept unless its bending energy is more than this many times
#: modified butterfly's on the same input and levels (then Loop subdivision is used). Both
#: factors are set on the tuning meshes only -- the four bundled samples and the five training
#: shapes, as they are and QSlimmed to 200 / 400 / 1,000 vertices, 1-3 levels
#: (benchmarks/subdivision_guard_tuning.py), never on the evaluation meshes -- as the geometric
#: mean of the highest ratio whose result looked clean and the lowest above it whose result was
#: marked (dimples, folds), judged in close-up pictures (docs/results/subdivision.md, "The
#: guard's factors from the tuning meshes"). Coarse copies: clean up to 2.36x (bob at 400
#: vertices, level 2), folds at 2.90x (bob at 200, level 3, the network without the mirror
#: average): 2.6
GUARD_BENDING_FACTOR = 2.6
#: ... and this many times on a mesh denser than the training meshes (scaled down to their edge
#: length: the network may then add detail the input does not call for). The same rule on the
#: tuning meshes as they are gave 1.4 (clean up to 1.38x: fandisk, level 2; fine dimples at
#: 1.43x: fandisk without the mirror average, 1.47x the pretzel), but on the corpus ogre as it is
#: came out at 1.27x at level 2 with a faint triangle-grid texture on its torso that Loop and
#: butterfly do not have: so the factor stays at the stricter 1.25 it had (set with the network
#: before the mirror average: the blob's faint dimples at 1.75x). Ogre, having decided this, is
#: no evidence for it.
GUARD_BENDING_FACTOR_DENSE = 1.25
#: "guard": ... and unless, on the input's flat regions, its triangles are more than this many
#: degrees (RMS) further from flat than butterfly's
GUARD_PLANAR_DEGREES = 0.5
#: "guard" on a mesh denser than the training meshes: the network is run (to be compared) only
#: while the result has at most this many triangles. Above, comparing costs minutes and GBs
#: (igea, 268,686 -> 4.3M triangles: 43 s and 3.5 GB against 3.5 s and 1.0 GB for Loop) on
#: meshes where detail finer than the training meshes' is already there: Loop, said.
GUARD_MAX_TRIANGLES = 2_000_000


def scale_plan(network: Network, V: np.ndarray, F: np.ndarray, adapt: bool = True, *,
               dense: str = "loop", edges: np.ndarray | None = None) -> ScalePlan:
    """How the network sees ``V`` (see the module docstring).

    The formulation's normalization; then, with ``adapt`` and a known reference edge length,
    when the mean edge length is more than :data:`SCALE_TOLERANCE` times off the reference:

    * edges longer (a coarser mesh than trained): scale so that it is the reference;
    * edges shorter (a denser mesh): ``dense="loop"`` (default): don't use the network, Loop
      subdivision instead; ``"scale"``: scale to the reference like a coarse mesh (the network
      then sees flaps of the right size but far flatter than any it was trained on: at 2
      levels ~10x smaller dimples than without on fandisk and the blob, measured, but not
      none, and still ~10x Loop's bending energy); ``"off"``: as is.
    """
    if dense not in DENSE_CHOICES:
        raise ParameterError(f"Unknown choice {dense!r} for meshes denser than the network's "
                             f"training meshes: use one of {', '.join(DENSE_CHOICES)}.")
    c, s = network.normalization(V)
    if not adapt or not network.reference_edge:
        return ScalePlan(c, s)
    ell = mean_edge_length(V, F, edges) * s
    ratio = ell / network.reference_edge
    parts = _part_ratios(network, V, F, edges)
    trained = "the coarse meshes (a few hundred vertices) the network was trained on"
    if not np.isfinite(ratio) or ratio <= 0 or 1 / SCALE_TOLERANCE <= ratio <= SCALE_TOLERANCE:
        if parts is None or dense == "off":
            return ScalePlan(c, s, ratio=ratio)
        # in range as a whole; a part denser than trained is said, with the advice
        denser = [r for _, r in parts if r < 1 / SCALE_TOLERANCE]
        advice = _advice(len(V), parts)
        if not denser:
            return ScalePlan(c, s, ratio=ratio)
        coarsen = (f" 'Coarsen first' to about {advice} vertices lets the network work as "
                   f"trained on them." if advice else "")
        return ScalePlan(c, s, f"{_of_parts(len(denser), len(parts), 'this mesh')} edges "
                               f"shorter than those of {trained} (up to {1 / min(denser):.1f}x); "
                               f"the network may leave slight dimples there.{coarsen}",
                         ratio=ratio, advice=advice)
    if ratio > 1:
        return ScalePlan(c, s / ratio, f"This mesh's edges are {ratio:.1f}x longer than those of "
                                       f"{trained}, so it was scaled to match before "
                                       f"subdividing and scaled back after.", ratio=ratio)
    how = f"its edges are {1 / ratio:.1f}x shorter than those of {trained}"
    density = ""
    if parts is None:
        advice = _advice(len(V), [(len(V), ratio)])
    else:
        # a scene of parts: the density each part has on its own (gaps between parts make the
        # whole look denser in the network's frame), and what each part needs
        advice = _advice(len(V), parts)
        denser = [r for _, r in parts if r < 1 / SCALE_TOLERANCE]
        if denser:
            how = (f"{_of_parts(len(denser), len(parts))} edges shorter than those of "
                   f"{trained}, up to {1 / min(denser):.1f}x")
            density = (f"{_of_parts(len(denser), len(parts))} edges shorter than its training "
                       f"meshes', up to {1 / min(denser):.1f}x")
        else:
            apart = (f"This mesh's {len(parts)} parts lie apart: over the whole its edges are "
                     f"{1 / ratio:.1f}x shorter than those of {trained} (each part's own are "
                     f"in range)")
            density = (f"its {len(parts)} parts lie apart: over the whole its edges are "
                       f"{1 / ratio:.1f}x shorter than its training meshes'")
            if dense in ("scale", "guard"):
                return ScalePlan(c, s / ratio, f"{apart}, so it was scaled to match.",
                                 ratio=ratio, density=density)
            if dense == "loop":
                return ScalePlan(c, s, f"{apart}, so Loop subdivision was used; "
                                       f"'Mesh denser than trained' = scale (--dense-input "
                                       f"scale) runs the network.", fallback=True,
                                 ratio=ratio, reason="the mesh's parts lie apart (denser as "
                                                     "a whole than the training meshes)",
                                 density=density)
    if dense == "off":
        return ScalePlan(c, s, ratio=ratio)
    coarsen = (f" 'Coarsen first' to about {advice} vertices lets the network work as trained."
               if advice else "")
    if dense in ("scale", "guard"):
        return ScalePlan(c, s / ratio, f"This mesh is denser than the network was trained for "
                                       f"({how}), so it was scaled to match; it may still show "
                                       f"slight dimples.{coarsen}", ratio=ratio, advice=advice,
                         density=density)
    see = (f" Set 'Coarsen first' to about {advice} vertices to see the network rebuild the "
           f"detail." if advice else "")
    return ScalePlan(c, s, f"This mesh is denser than the network was trained for ({how}); the "
                           f"network would leave dimples, so Loop subdivision was used.{see}",
                     fallback=True, ratio=ratio, advice=advice, density=density,
                     reason=f"the mesh is denser than the training meshes ({how})")


def _of_parts(k: int, n: int, whose: str = "its") -> str:
    """"1 of its 2 parts has" / "2 of this mesh's 3 parts have"."""
    owner = whose if whose == "its" else f"{whose}'s"
    return f"{k} of {owner} {n} parts {'has' if k == 1 else 'have'}"


def _advice(n: int, parts: list) -> int:
    """Vertices for 'Coarsen first' (0: coarsening would not help): over ``parts`` [(vertices,
    ratio of the mean edge length to the training one)], a denser part's vertices x ratio^2 (its
    edges at the training length: edge length ~ 1 / sqrt(vertices)) x 1.5 (QSlim keeps vertices
    where the detail is, so its mean edge is longer than a uniform mesh's), within 150-450 (the
    training meshes' range and the Table 4.2 protocol's), the other parts as they are. 0 when
    that is not clearly fewer than the mesh has (``n``): asking again after coarsening, or a
    mesh as coarse as coarsening can usefully make it."""
    advice = int(round(sum(_wanted(nv, ratio) for nv, ratio in parts), -1))
    return advice if advice <= ADVICE_SHARE * n else 0


def _wanted(nv: int, ratio: float) -> float:
    """The vertices a part of ``nv`` vertices needs to be as the network was trained (see
    :func:`_advice`)."""
    if ratio < 1 / SCALE_TOLERANCE:
        return float(np.clip(1.5 * nv * ratio * ratio, 150, 450))
    return float(nv)


#: 'Coarsen first' is advised only to a count at most this share of the mesh's vertices
ADVICE_SHARE = 0.8


def _parts(F: np.ndarray, n: int):
    """The mesh's parts (triangles sharing vertices): None for one part; else, per part, its
    vertex indices and its triangles' rows, from one sort each (a scan of thousands of
    fragments costs no more than one of a few)."""
    from ..mesh.topology import connected_components

    F = np.asarray(F, dtype=np.int64)
    if len(F) == 0:
        return None
    k, face_part = connected_components(F, n)
    if k < 2:
        return None
    vertex_part = np.full(n, -1, dtype=np.int64)
    vertex_part[F.reshape(-1)] = np.repeat(face_part, 3)
    used = np.flatnonzero(vertex_part >= 0)
    vs = used[np.argsort(vertex_part[used], kind="stable")]
    v_cut = np.searchsorted(vertex_part[vs], np.arange(k + 1))
    fs = np.argsort(face_part, kind="stable")
    f_cut = np.searchsorted(face_part[fs], np.arange(k + 1))
    return [(vs[v_cut[p]:v_cut[p + 1]], fs[f_cut[p]:f_cut[p + 1]]) for p in range(k)]


def _part_ratios(network: Network, V: np.ndarray, F: np.ndarray, edges=None, *,
                 indices: bool = False):
    """For a mesh of several parts (sharing no vertex): [(vertices, ratio)] per part, the ratio
    of its mean edge length to the training meshes' with the part normalized as if it were
    alone ([(vertex indices, triangle rows, ratio)] with ``indices``); None for one part, or
    where a part cannot be normalized alone. ``edges``: the mesh's undirected edges, if known.
    (The network itself sees the whole mesh in one frame: each part in its own frame made tiny
    parts -- octagonal_pocket's 4-vertex bits -- swell, Hausdorff 1.6 -> 2.8 % on the corpus,
    docs/results/subdivision.md.)"""
    F = np.asarray(F, dtype=np.int64)
    parts = _parts(F, len(V))
    if parts is None:
        return None
    E = _unique_edges(F, len(V)) if edges is None else np.asarray(edges, dtype=np.int64)
    vertex_part = np.empty(len(V), dtype=np.int64)
    for p, (idx, _) in enumerate(parts):
        vertex_part[idx] = p
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    total = np.bincount(vertex_part[E[:, 0]], weights=length, minlength=len(parts))
    count = np.bincount(vertex_part[E[:, 0]], minlength=len(parts))
    out = []
    for p, (idx, faces) in enumerate(parts):
        try:
            _, s = network.normalization(V[idx])
        except InvalidMeshError:
            return None
        ratio = total[p] / max(count[p], 1) * s / network.reference_edge
        if not np.isfinite(ratio) or ratio <= 0:
            return None
        out.append((idx, faces, float(ratio)) if indices else (len(idx), float(ratio)))
    return out


def coarsen_for_network(network: Network | None, V: np.ndarray, F: np.ndarray,
                        vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """'Coarsen first': QSlim to about ``vertices`` vertices
    (:func:`~.metrics.coarsen_to_vertices`). On a mesh of several parts with a network, each
    part is coarsened on its own to its share of ``vertices``, the shares in proportion to what
    :func:`scale_plan` wants of each (a denser part: the count that brings its edges to the
    training length; another: the vertices it has) after every part's 4 (or fewer, if it has
    fewer), none above what a part has. (QSlim on the whole scene spends its budget by absolute
    error: a small part loses its vertices first and a big dense one stays dense, so the advice
    of the note would never be reached.) Where the parts cannot keep 4 vertices each, a
    :class:`ParameterError` says the count that works."""
    from .metrics import coarsen_to_vertices

    F = np.asarray(F, dtype=np.int64)
    parts = None
    if network is not None and network.reference_edge and len(F):
        parts = _part_ratios(network, np.asarray(V, dtype=np.float64), F, indices=True)
    if parts is None:
        return coarsen_to_vertices(V, F, vertices)
    V = np.asarray(V, dtype=np.float64)
    want = np.array([_wanted(len(idx), r) for idx, _, r in parts])
    have = np.array([len(idx) for idx, _, _ in parts], dtype=np.float64)
    floor = np.minimum(have, 4.0)   # every part keeps at least a tetrahedron's worth
    budget = float(vertices) - floor.sum()
    if budget < 0:
        raise ParameterError(
            f"This mesh has {len(parts):,} separate parts, too many to share "
            f"{int(vertices):,} vertices (each part keeps at least 4: {int(floor.sum()):,} in "
            f"all). Set 'Coarsen first' to {int(floor.sum()):,} or more, or to 0 to subdivide "
            f"the mesh as it is.")
    share = floor + np.minimum(have - floor, np.round(budget * want / want.sum()))
    remap = np.full(len(V), -1, dtype=np.int64)
    Vs, Fs, base = [], [], 0
    for (idx, faces, _), k in zip(parts, share):
        remap[idx] = np.arange(len(idx))
        Vp, Fp = V[idx], remap[F[faces]]
        remap[idx] = -1
        if k < len(idx):
            Vp, Fp = coarsen_to_vertices(Vp, Fp, int(k))
        Vs.append(np.asarray(Vp, dtype=np.float64))
        Fs.append(np.asarray(Fp, dtype=np.int64) + base)
        base += len(Vs[-1])
    return np.vstack(Vs), np.vstack(Fs)


def _argsort_int(key: np.ndarray) -> np.ndarray:
    """``np.argsort`` of non-negative int64 keys (ties in any order), as one ``np.sort`` of
    ``key << b | index`` when that fits in 63 bits (about 2x faster here: NumPy's sort of
    int64 uses the CPU's vector sort, its argsort less so)."""
    H = len(key)
    if H == 0:
        return np.zeros(0, dtype=np.int64)
    bits = max(1, int(H - 1).bit_length())
    top = int(key.max())
    if top < 0 or top.bit_length() + bits > 63:
        return np.argsort(key)
    packed = np.sort((key << bits) | np.arange(H, dtype=np.int64))
    return packed & ((1 << bits) - 1)


class _Level:
    """Index arrays of one level: the half-flaps grouped by their vertex and by their edge.

    :meth:`build` makes them in three pieces (a generator), so that a consumer can stop
    between them on a big mesh."""

    def __init__(self, F: np.ndarray, n: int):
        self.F, self.n = F, int(n)

    def build(self) -> Iterator[None]:
        """The same half-flaps, edges (sorted, as :func:`~.topology.unique_edge_ids`) and edge
        of every corner as :func:`~.topology.half_flaps` (tested equal), from ONE sort of the
        undirected edge keys: equal keys are an edge's two half-edges (twins), the sorted keys'
        runs the edges in order, and that order groups the flaps by edge for the EDGE step.
        (half_flaps sorts three times; this is ~3x faster on a 400k-face level.)"""
        F = np.ascontiguousarray(self.F, dtype=np.int64)
        n = self.n
        src = F.reshape(-1)
        dst = F[:, [1, 2, 0]].reshape(-1)
        opp = F[:, [2, 0, 1]].reshape(-1)
        H = len(src)
        key = np.minimum(src, dst) * n + np.maximum(src, dst)
        order = _argsort_int(key)
        yield
        sk = key[order]
        new = np.r_[True, sk[1:] != sk[:-1]]
        starts = np.flatnonzero(new)
        counts = np.diff(np.r_[starts, H])
        if counts.max(initial=1) > 2:
            raise InvalidMeshError("Neural subdivision needs a manifold mesh: an edge is shared "
                                   "by more than two triangles. Run 'Clean' first.")
        ukey = sk[starts]
        self.E = np.stack([ukey // n, ukey % n], axis=1)
        edge = np.empty(H, dtype=np.int64)
        edge[order] = np.cumsum(new) - 1
        self.EF = edge.reshape(-1, 3)
        twin = np.full(H, -1, dtype=np.int64)
        pair = starts[counts == 2]
        twin[order[pair]] = order[pair + 1]
        twin[order[pair + 1]] = order[pair]
        has_l = twin >= 0
        l = np.where(has_l, opp[np.maximum(twin, 0)], opp)  # no l: k (mirrored later)
        ijkl = np.stack([src, dst, opp, l], axis=1)
        self.boundary = bool((~has_l).any())
        deg = np.bincount(self.E.reshape(-1), minlength=n)
        self.degree = np.maximum(deg, 1).astype(np.float32)
        self.H = H
        self.by_edge = _by_size(ijkl[order], has_l[order], starts, counts,
                                np.arange(len(starts)), len(starts))
        yield
        self.by_vertex = self._grouped(ijkl, has_l, src, n)
        yield

    @staticmethod
    def _grouped(ijkl, has_l, dst, N):
        order = _argsort_int(dst)  # the order inside a group does not matter (a sum)
        d = dst[order]
        starts = np.flatnonzero(np.r_[True, d[1:] != d[:-1]])
        counts = np.diff(np.r_[starts, len(d)])
        return _by_size(ijkl[order], has_l[order], starts, counts, d[starts], N)

    def laplace(self, V: np.ndarray) -> np.ndarray:
        i, j = self.E[:, 0], self.E[:, 1]
        acc = np.empty_like(V)
        for d in range(3):
            acc[:, d] = (np.bincount(i, weights=V[j, d], minlength=self.n)
                         + np.bincount(j, weights=V[i, d], minlength=self.n))
        return (V - acc / self.degree[:, None]).astype(V.dtype)


def _by_size(ijkl, has_l, starts, counts, dst, N) -> dict:
    """A stage's groups of half-flaps (the rows ``starts[g]`` .. of ``ijkl`` average into row
    ``dst[g]`` of the stage's output, ``N`` rows), reordered so that groups of equal size are
    adjacent (a stable sort by size): :func:`_group_sums` then sums a run of them as one
    reshaped array (5x faster than ``np.add.reduceat`` over rows)."""
    by = np.argsort(counts, kind="stable")
    sizes = counts[by]
    new_starts = np.r_[0, np.cumsum(sizes)[:-1]].astype(np.int64)
    rows = np.arange(len(ijkl)) + np.repeat(starts[by] - new_starts, sizes)
    return {"ijkl": np.ascontiguousarray(ijkl[rows]), "has_l": has_l[rows],
            "starts": new_starts, "counts": sizes, "dst": dst[by],
            "inv": (1.0 / sizes).astype(np.float32), "N": N}


def _group_sums(o: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The sums of ``o``'s rows over consecutive groups (group g: ``counts[g]`` rows from
    ``starts[g]``), a run of equal-size groups at a time (:func:`_by_size` makes the runs)."""
    cut = np.flatnonzero(np.r_[True, counts[1:] != counts[:-1]])
    if len(cut) > 64:  # not grouped by size
        return np.add.reduceat(o, starts, axis=0)
    out = np.empty((len(starts), o.shape[1]), o.dtype)
    for a, b in zip(cut, np.r_[cut[1:], len(starts)]):
        c, r0, n = int(counts[a]), int(starts[a]), int(b - a)
        block = o[r0:r0 + c * n].reshape(n, c, o.shape[1])
        if c == 1:
            out[a:b] = block[:, 0]
        elif c == 2:
            np.add(block[:, 0], block[:, 1], out=out[a:b])
        else:
            block.sum(axis=1, out=out[a:b])
    return out


def _flaps(Vc, Dc, ijkl, has_l, slots):
    """The first-layer input of a chunk of half-flaps: ``geo`` (h, 3 len(slots)), the canonical
    flap vectors ``slots`` (0-2: ``p_j, p_k, p_l``, 3-6: ``d_i, d_j, d_k, d_l``) in the local
    frame, and the frame rows ``(x, y, z)`` as (3, 3, h) (row, component, flap).

    ``Vc``, ``Dc``: (3, n) component-major positions / differential coordinates (every
    operation here is on contiguous (h,) arrays; NumPy's einsum over (h, 7, 3) was ~10x
    slower)."""
    i, j, k, l = ijkl[:, 0], ijkl[:, 1], ijkl[:, 2], ijkl[:, 3]
    pi = [Vc[d][i] for d in range(3)]
    a = [Vc[d][j] - pi[d] for d in range(3)]
    b = [Vc[d][k] - pi[d] for d in range(3)]
    c = [Vc[d][l] - pi[d] for d in range(3)]

    def cross(u, v):
        return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0]]

    def unit(u):
        r = 1.0 / np.maximum(np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]), 1e-12)
        r = r.astype(u[0].dtype, copy=False)
        return [u[0] * r, u[1] * r, u[2] * r]

    x = unit(a)
    nz = unit(cross(a, b))
    if has_l.any():
        f2 = unit(cross(c, a))
        if has_l.all():
            nz = [nz[d] + f2[d] for d in range(3)]
        else:
            nz = [nz[d] + np.where(has_l, f2[d], 0) for d in range(3)]
    p = nz[0] * x[0] + nz[1] * x[1] + nz[2] * x[2]
    z = unit([nz[d] - p * x[d] for d in range(3)])
    y = cross(z, x)
    rows = (x, y, z)
    vecs = {0: a, 1: b, 2: c}
    if any(s >= 3 for s in slots):
        for s, v in zip((3, 4, 5, 6), (i, j, k, l)):
            vecs[s] = [Dc[d][v] for d in range(3)]
    h = len(ijkl)
    geo = np.empty((h, 3 * len(slots)), dtype=Vc.dtype)
    boundary = not has_l.all()
    for col, s in enumerate(slots):
        u = vecs[s]
        for r in range(3):
            q = rows[r]
            geo[:, 3 * col + r] = u[0] * q[0] + u[1] * q[1] + u[2] * q[2]
    if boundary:  # no l: the mirror of k (turned by pi about the edge)
        nb = ~has_l
        pos = {s: col for col, s in enumerate(slots)}
        for sl, sk in ((2, 1), (6, 5)):
            if sl in pos and sk in pos:
                cl, ck = 3 * pos[sl], 3 * pos[sk]
                geo[nb, cl] = geo[nb, ck]
                geo[nb, cl + 1] = -geo[nb, ck + 1]
                geo[nb, cl + 2] = -geo[nb, ck + 2]
    return geo, rows


def _chain_sums(module: _Module, geo, frames, Zw, ijkl, starts, counts, flip: bool):
    """One chain's part of a chunk: the network on the flap vectors ``geo``, its displacement
    back to world axes through the flap ``frames`` (``flip``: the mirror chain, whose frame's
    normal is the plain frame's negated, and mirrored back; see :func:`_mirrored_stage`), summed
    over the groups; (groups, 32)."""
    x, y, z = frames
    with _OneBlasThread():
        o = module.hidden(geo, Zw, ijkl)
    o0, o1, o2 = o[:, 0].copy(), o[:, 1].copy(), o[:, 2].copy()
    if flip:
        np.negative(o2, out=o2)
    for d in range(3):  # the displacement back to world axes
        o[:, d] = o0 * x[d] + o1 * y[d] + o2 * z[d]
    return _group_sums(o, starts, counts)


def _mirrored_flaps(geo: np.ndarray) -> np.ndarray:
    """The flap vectors of the mirror image: the same with their normal components negated."""
    geo_m = geo.copy()
    np.negative(geo_m[:, 2::3], out=geo_m[:, 2::3])
    return geo_m


def _mirror_chain_sums(module: _Module, Vc, Dc, has_l, Zw, ijkl, starts, counts):
    """:func:`_chain_sums` of the mirror chain with the flaps computed here (a worker thread's
    part of a chunk)."""
    geo, frames = _flaps(Vc, Dc, ijkl, has_l, module.slots)
    return _chain_sums(module, _mirrored_flaps(geo), frames, Zw, ijkl, starts, counts, True)


def _stage(module: _Module, Vc, Dc, Zs: list, group: dict, outs: list, chunk: int,
           pool=None) -> Iterator[int]:
    """Run ``module`` over the flaps of ``group`` in chunks for each chain (``Zs``: the
    features of the plain chain and, when two, of the mirror chain), averaging into ``outs``
    (N, 32) each: [world displacement, feature]; yields the number of flaps done (over the
    chains) after each chunk. The mirror image's flap frames and vectors are the plain ones
    with the normal components negated (exactly, in floating point: every operation is odd or
    even in the mirrored coordinate), so one thread computes them once; with ``pool`` (a worker
    thread for the mirror chain) each thread computes its own copy, at the same time."""
    ijkl, has_l = group["ijkl"], group["has_l"]
    starts, counts, dst, inv = group["starts"], group["counts"], group["dst"], group["inv"]
    H = len(ijkl)
    Zws = []
    for Z in Zs:
        Zw = None
        if module.Wz is not None and Z is not None:
            with _OneBlasThread():
                Zw = Z @ module.Wz  # (n, 4 H1): the feature columns, once per vertex
        Zws.append(Zw)
    for out in outs:
        out[:] = 0
    G = len(starts)
    cuts = np.unique(np.r_[0, np.searchsorted(starts, np.arange(chunk, H, chunk)), G])
    for ga, gb in zip(cuts[:-1], cuts[1:]):
        s0 = starts[ga]
        s1 = starts[gb] if gb < G else H
        sl = slice(s0, s1)
        rest = (ijkl[sl], starts[ga:gb] - s0, counts[ga:gb])
        later = None
        if len(Zs) == 2 and pool is not None:   # the worker makes its own copy of the frames
            later = pool.submit(_mirror_chain_sums, module, Vc, Dc, has_l[sl], Zws[1], *rest)
        try:
            geo, frames = _flaps(Vc, Dc, ijkl[sl], has_l[sl], module.slots)
            sums = [_chain_sums(module, geo, frames, Zws[0], *rest, False)]
        finally:
            if later is not None:
                sums_m = later.result()
        if len(Zs) == 2:
            if later is None:
                sums_m = _chain_sums(module, _mirrored_flaps(geo), frames, Zws[1], *rest, True)
            sums.append(sums_m)
        for out, sm in zip(outs, sums):
            out[dst[ga:gb]] = sm * inv[ga:gb, None]
        yield (s1 - s0) * len(Zs)


def _mirrored_stage(module: _Module, X, D, Zs: list, group: dict, chunk: int, mirror: bool):
    """One stage (module ``I``, ``V`` or ``E`` over ``group``'s half-flaps), averaged with its
    mirror image when ``mirror``: the network also runs on the mesh mirrored in x (its own
    features ``Zs[1]``, carried level to level) and its displacement, mirrored back, is averaged
    with the plain one. A generator of flap counts (as :func:`_stage`); returns (displacement
    (N, 3), [features (N, 29) of each chain]).

    Why: the half-flap network is equivariant to rotations (it works in local frames) but not
    to reflections; a mirrored flap is the flap reflected across its own tangent plane (in the
    local frame only the normal components change sign). The average is equivariant to every
    reflection, so a surface that is flat over the network's reach stays exactly flat (a plane
    is its own mirror image across itself) -- the trained network alone bent dense CAD sides
    off flat by 1.1-2.2 degrees RMS -- and the bias of the network's displacement along the
    normal on flaps flatter than it was trained on (dimples on dense meshes) cancels to the
    part odd in the curvature. ``X``, ``D``: (n, 3) float32 positions and differential
    coordinates (``D`` None: not used).

    The two chains share the flap frames (:func:`_stage`); where two cores may be used
    (:func:`_two_threads`) and the stage is big enough, the mirror chain's network runs on a
    worker thread (NumPy releases Python's lock in its loops and products; BLAS held to one
    thread each). The result is the same, bit for bit, either way."""
    chains = Zs if mirror else Zs[:1]
    chunk = max(1, chunk // len(chains))   # about ``chunk`` flaps of work between two steps
    outs = [np.empty((group["N"], FEATURES), np.float32) for _ in chains]
    Vc = X.T.copy()
    Dc = None if D is None else D.T.copy()
    if len(chains) == 2 and len(group["ijkl"]) >= PARALLEL_FLAPS and _two_threads():
        from concurrent.futures import ThreadPoolExecutor

        with _OneBlasThread(), ThreadPoolExecutor(max_workers=1) as pool:
            yield from _stage(module, Vc, Dc, chains, group, outs, chunk, pool)
    else:
        yield from _stage(module, Vc, Dc, chains, group, outs, chunk)
    disp, feats = None, []
    for out in outs:   # the mirror chain's displacement is already mirrored back
        d = out[:, :3]
        disp = d if disp is None else 0.5 * (disp + d)
        feats.append(out[:, 3:].copy())
    return disp, feats


#: stages with at least this many half-flaps run the plain and the mirrored chain on two
#: threads (NumPy releases Python's lock in its loops and products); below, a thread's start
#: costs more than it saves
PARALLEL_FLAPS = 20_000


def _two_threads() -> bool:
    """Whether the mirror chains may take two threads: two usable cores, and the project's
    thread limit (``NUMBA_NUM_THREADS``, else ``OMP_NUM_THREADS``, as for the compiled
    kernels) not 1."""
    for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS"):
        value = os.environ.get(name, "").strip()
        if value:
            try:
                return int(value) > 1
            except ValueError:
                break
    try:
        return len(os.sched_getaffinity(0)) > 1
    except (AttributeError, OSError):
        return (os.cpu_count() or 1) > 1


@dataclass
class SubdividedStep(Step):
    """The last step of :func:`neural_subdivision_iter`: ``V`` the subdivided vertices
    (float64), ``F`` its faces, ``note`` what was done to stay in the network's range ('' when
    nothing)."""

    F: np.ndarray | None = None
    note: str = ""
    fallback: bool = False  # Loop subdivision was used instead of the network (for any level)
    #: what made each level: "neural" or "loop" (the guard can keep the network's first levels
    #: and let Loop make the rest); empty on the progress steps
    levels_used: tuple = ()
    #: with ``fallback``: why the network was not used, in one short clause (the note says it
    #: in full, with advice)
    fallback_reason: str = ""


def _check_levels(levels) -> int:
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
    return lv


def neural_subdivision_iter(V, F, levels: int, network: Network, *, adapt_scale: bool = True,
                            dense: str = "loop", chunk: int | None = None) -> Iterator[Step]:
    """Subdivide with ``network``, in steps: progress steps (``iteration`` per mille of the
    work, ``total`` 1000, ``V`` the input unchanged, ``message`` "Level 1 of 2: ...") after
    every chunk of half-flaps, then one :class:`SubdividedStep` with the result (input vertices
    first, moved; then one vertex per edge per level, in the order of
    :func:`~algorithms.subdivision.topology.refine`). Stopping the iteration stops the work."""
    lv = _check_levels(levels)
    chunk = int(CHUNK_FLAPS if chunk is None else chunk)
    from ..mesh.subdivision import midpoint_subdivide
    from .data import LOOP_WORKS, check_manifold

    V_in = V
    V, F = midpoint_subdivide(V, F, 0)  # the project's input checks
    check_manifold(V, F, "Neural subdivision", LOOP_WORKS)
    if len(F) * 4 ** lv > 20_000_000:
        raise ParameterError(f"{lv} levels would make {len(F) * 4 ** lv:,} triangles; use fewer "
                             f"levels.")
    m = len(F)
    work = 3 * m + sum(2 * 3 * m * 4 ** k for k in range(lv))  # flaps over all stages
    done = 0

    def progress(msg):
        return Step(int(min(999, 1000 * done / work)), 1000, V_in, {}, msg)

    yield progress(f"Level 1 of {lv}: reading the mesh")
    level = _Level(F, len(V))
    for _ in level.build():
        yield progress(f"Level 1 of {lv}: reading the mesh")
    plan = scale_plan(network, V, F, adapt_scale, dense=dense, edges=level.E)
    if dense == "guard" and plan.denser and len(F) * 4 ** lv > GUARD_MAX_TRIANGLES:
        coarsen = (f"'Coarsen first' to about {plan.advice} vertices lets the network rebuild "
                   f"the detail; " if plan.advice else "")
        plan = ScalePlan(plan.centre, plan.scale, (
            f"This mesh is denser than the network was trained for ({plan.density_words()}), "
            f"and the result has "
            f"{len(F) * 4 ** lv:,} triangles, over the {GUARD_MAX_TRIANGLES:,} up to which the "
            f"network's result is compared with butterfly's, so Loop subdivision was used. "
            f"{coarsen}'Mesh denser than trained' = scale (--dense-input scale) runs it "
            f"anyway."), fallback=True, ratio=plan.ratio, density=plan.density,
            advice=plan.advice, reason=f"the result would have {len(F) * 4 ** lv:,} triangles, "
                                       f"over the {GUARD_MAX_TRIANGLES:,} the guard compares")
    c, s, note = plan.centre, plan.scale, plan.note
    if plan.fallback:
        from .baselines import subdivide_baseline

        Vl, Fl = V, F
        for k in range(lv):
            yield Step(int(1000 * k / lv), 1000, V_in, {},
                       f"Level {k + 1} of {lv}: Loop subdivision (the mesh is denser than the "
                       f"network was trained for)")
            Vl, Fl = subdivide_baseline(Vl, Fl, 1, "loop")
        yield SubdividedStep(1000, 1000, np.asarray(Vl, dtype=np.float64), {},
                             f"{len(Fl):,} triangles", F=np.asarray(Fl, dtype=np.int64),
                             note=note, fallback=True, levels_used=("loop",) * lv,
                             fallback_reason=plan.reason)
        return
    X = ((V - c) * s).astype(np.float32)
    mirror = network.mirror_average
    Zs = [None, None]

    def stage(name, D, group, msg):
        nonlocal done
        it = _mirrored_stage(network.modules[name], X, D, Zs, group, chunk, mirror)
        while True:
            try:
                k = next(it)
            except StopIteration as stop:
                return stop.value
            done += k * (0.5 if mirror else 1.0)
            yield progress(msg)

    disp, Zs = yield from stage("I", level.laplace(X), level.by_vertex,
                                f"Level 1 of {lv}: initialization")
    X = X + disp
    with_d = network.uses_differential_coordinates
    guard = _Guard(V, F, GUARD_BENDING_FACTOR_DENSE if plan.denser else GUARD_BENDING_FACTOR) \
        if dense == "guard" else None
    kept = None   # the guard's last accepted level: (V, F) in the input's units
    for li in range(lv):
        head = f"Level {li + 1} of {lv}"
        disp, Zs = yield from stage("V", level.laplace(X) if with_d else None,
                                    level.by_vertex, f"{head}: moving the vertices")
        X = X + disp
        dispE, ZE = yield from stage("E", level.laplace(X) if with_d else None,
                                     level.by_edge, f"{head}: placing the new vertices")
        mid = 0.5 * (X[level.E[:, 0]] + X[level.E[:, 1]]) + dispE
        X = np.concatenate([X, mid])
        Zs = [np.concatenate([a, b]) for a, b in zip(Zs, ZE)]
        F_next = refine(level.F, level.n, level.EF)
        if guard is not None:
            out = X.astype(np.float64) / s + c
            if not np.isfinite(out).all():
                raise InvalidMeshError("Neural subdivision produced invalid positions "
                                       "(degenerate triangles in the input?). Run 'Clean' "
                                       "first.")
            yield progress(f"{head}: comparing with modified butterfly subdivision")
            prev = (V, F) if kept is None else kept
            why, blended = guard.check(li + 1, out, F_next, prev)
            if why:
                yield from _guard_fallback(V, F, lv, li, kept, why, guard, plan, note)
                return
            if blended is not None:   # the level before, where the network crossed itself
                out = blended
                X = ((out - c) * s).astype(np.float32)
            kept = (out, F_next)
        if li + 1 < lv:
            yield progress(f"{head}: splitting the triangles")
            level = _Level(F_next, len(X))
            for _ in level.build():
                yield progress(f"{head}: splitting the triangles")
    out = X.astype(np.float64) / s + c if kept is None else kept[0]
    if not np.isfinite(out).all():
        raise InvalidMeshError("Neural subdivision produced invalid positions (degenerate "
                               "triangles in the input?). Run 'Clean' first.")
    metrics: dict = {}
    if guard is not None:
        if np.isfinite(guard.ratio):
            metrics["bending_vs_butterfly"] = guard.ratio
        if guard.unsmoothed:
            metrics["unsmoothed_vertices"] = float(guard.unsmoothed)
        if guard.loop_part.any():
            metrics["loop_parts"] = float(guard.loop_part.sum())
        if guard.bumps:
            metrics["loop_blended_vertices"] = float(sum(m for *_, m in guard.bumps))
        note = " ".join(x for x in (note, guard.note, guard.parts_note(), guard.bump_note(),
                                    guard.blend_note()) if x)
        yield SubdividedStep(1000, 1000, out, metrics, f"{len(F_next):,} triangles", F=F_next,
                             note=note, levels_used=guard.levels_used(lv),
                             fallback=bool(guard.part_fallbacks),
                             fallback_reason=guard.parts_reason())
        return
    yield SubdividedStep(1000, 1000, out, metrics, f"{len(F_next):,} triangles", F=F_next,
                         note=note, levels_used=("neural",) * lv)


class _Guard:
    """The "guard" of ``dense="guard"``, level by level: the network's result after ``k``
    levels fails when it is more than ``factor`` (:data:`GUARD_BENDING_FACTOR`, or
    :data:`GUARD_BENDING_FACTOR_DENSE` on a mesh denser than the training meshes) times as bent
    as modified butterfly subdivision of the same input to ``k`` levels (discrete-shells
    bending energy,
    :func:`~.metrics.bending_energy`), or when, on the input's flat regions
    (:func:`~.metrics.planar_faces`), its triangles are more than :data:`GUARD_PLANAR_DEGREES`
    (RMS) further from flat than butterfly's. The network's levels up to the last that passed
    are kept and Loop subdivision makes the rest (:func:`_guard_fallback`).

    Bulges: where the excess bending sits in a few input triangles (at most
    :data:`BUMP_SHARE` of them, the fewest that bring the rest within the factor), Loop's
    positions are blended in around them and the level is judged again
    (:meth:`_bump_repair`; said in the note and ``loop_blended_vertices``). On the coarse
    copies of the corpus (docs/results/subdivision.md, "Bulges repaired where they are") this
    kept the network on face at 200 vertices (1 of 390 triangles; Hausdorff 1.14 -> 0.88 %,
    the forced network's) and no input there falls back to Loop on a whole level any more.

    Parts: a mesh of several parts (sharing no vertex) is judged whole first, as a one-part
    mesh (the factors were set on one-part meshes); where the whole fails, each part is judged
    on its own, and if some pass, only the parts that fail get Loop subdivision's positions
    from that level on (:meth:`_loop_parts`; each part keeps its own scheme's stencils), said
    as ``"neural+loop"`` levels, ``loop_parts`` and the note. On the coarse copies of the
    corpus this brought office_chair (56 parts; 1,000 vertices, 2 levels: Hausdorff 2.05 ->
    0.71 %, the network forced 0.71) back to the network's accuracy
    (docs/results/subdivision.md, "Parts judged one by one").

    Crossings: where the network's level crosses itself (intersecting triangle pairs whose
    parent triangles in the input did not intersect; a self-intersection is a defect a user
    sees and a 3-D printer refuses), the surface of the level before is blended back in around
    those triangles only (:func:`_blend_back_where_crossed`; said in the note and
    ``unsmoothed_vertices``), and what is left is said beside Loop subdivision's own count.
    Measured when the repair was added (with Loop's positions then; corpus and shared meshes
    as they are, level 1): the network crossed itself on dense smooth meshes in a few places
    (wingnut 8, koala 10, Loop 0); on CAD parts in many (octagonal_pocket 745, Loop 361;
    1002_tray_bottom 1,042, Loop 8). Refusing the whole level on crossings sent 24 more of the
    52 corpus and shared meshes to Loop, and on the coarse copies of
    docs/results/subdivision.md (issue 36) raised the guarded result's mean Hausdorff distance
    from 1.756 to 1.850 % (the network forced: 1.777): a level is never refused for crossings.

    Why butterfly, not Loop: Loop smooths the detail away, so a network that rebuilds detail is
    always more bent than Loop (0.8-22x on 25 meshes coarsened to 400 vertices, where it beat
    Loop's Hausdorff distance on 24); butterfly interpolates the input like the network, and
    the network's result was 0.29-1.89x as bent as butterfly's there, but 3.0x on the blob
    sample and 3.7-4.1x on bob at 3,000-5,344 vertices, where it leaves dimples. Coarse
    meshes have no flat regions; dense CAD meshes do, and there the network was 1.2-2.3
    degrees off flat (fandisk, casting, block as they are) where butterfly and Loop are 0
    (docs/results/subdivision.md)."""

    def __init__(self, V, F, factor: float = GUARD_BENDING_FACTOR):
        self.V0, self.F0 = V, F
        self.factor = float(factor)
        self.Vb, self.Fb = V, F     # butterfly, level by level (the same as all at once)
        self.level = 0
        self.ratio = float("nan")   # the last level's bending / butterfly's
        self.note = ""
        self.planar = None
        self.Vl, self.Fl, self.loop_level = V, F, 0   # Loop, level by level, when needed
        self.input_pairs = None     # the input's intersecting triangle pairs, when needed
        #: vertices of the result where the previous level's surface was blended back in (the
        #: network crossed itself there), and at which levels
        self.unsmoothed = 0
        self.blended_levels: list[int] = []
        self.crossings_seen = 0
        #: (crossings left, Loop's) after the last level's blend, when any is left
        self.crossings_left: tuple[int, int] | None = None
        from ..mesh.topology import connected_components

        #: the input's parts (triangles sharing vertices), judged one by one: each part that
        #: fails gets Loop from that level on, the others keep the network
        self.n_parts, self.face_part = connected_components(F, len(V))
        self.loop_part = np.zeros(self.n_parts, bool)
        #: (level, parts handed to Loop at it, their share of the input's triangles, why)
        self.part_fallbacks: list[tuple[int, int, float, str]] = []
        #: (level, input triangles, vertices) where Loop's positions were blended in over
        #: the network's bulges or dimples (:meth:`_bump_repair`)
        self.bumps: list[tuple[int, int, int]] = []
        #: and which input triangles, level by level
        self.bump_triangles: list[np.ndarray] = []

    def levels_used(self, made: int) -> tuple:
        """What made each of the first ``made`` levels: "neural", or "neural+loop" from the
        first level at which some parts were handed to Loop."""
        first = min((k for k, *_ in self.part_fallbacks), default=made + 1)
        return tuple("neural+loop" if k >= first else "neural" for k in range(1, made + 1))

    def parts_reason(self) -> str:
        """Why some parts got Loop, in one short clause ('' when none did)."""
        return "; ".join(
            f"at level {k} on {n:,} of {self.n_parts:,} parts ({100 * share:.0f} % of the "
            f"triangles) {why}" for k, n, share, why in self.part_fallbacks)

    def parts_note(self) -> str:
        if not self.part_fallbacks:
            return ""
        n = int(self.loop_part.sum())
        share = float(self.loop_part[self.face_part].mean())
        if len(self.part_fallbacks) == 1:   # the counts are said once
            k, _, _, why = self.part_fallbacks[0]
            said = f"at level {k} {why}"
        else:
            said = self.parts_reason()
        return (f"Loop subdivision was used instead of the network on {n:,} of the mesh's "
                f"{self.n_parts:,} parts ({100 * share:.0f} % of its triangles): "
                f"{said} (more than {self.factor:g}x); the network made the other parts.")

    def bump_note(self) -> str:
        """Where Loop's positions were blended in over the network's bulges or dimples."""
        if not self.bumps:
            return ""
        moved = sum(m for *_, m in self.bumps)
        if len(self.bumps) == 1:
            k, q, _ = self.bumps[0]
            where, levels = f"{q:,} of the input's triangles", f"level {k}"
        else:   # per level (a triangle may be repaired at more than one)
            where = "the input's triangles (" + ", ".join(
                f"{q:,} at level {k}" for k, q, _ in self.bumps) + ")"
            levels = "levels " + ", ".join(str(k) for k, *_ in self.bumps)
        return (f"The network's result bulged or dimpled over {where}; Loop subdivision's "
                f"positions were blended in there ({moved:,} vertices, {levels}), the network "
                f"made the rest.")

    def blend_note(self) -> str:
        if not self.unsmoothed:
            return ""
        at = ", ".join(str(k) for k in self.blended_levels)
        levels = f"level{'s' if len(self.blended_levels) > 1 else ''} {at}"
        return (f"The network's result crossed itself in {self.crossings_seen:,} place"
                f"{'s' if self.crossings_seen > 1 else ''} where the input does not; there "
                f"the surface of the level before was blended back in ({self.unsmoothed:,} "
                f"vertices, {levels}, left unsmoothed)"
                + (f"; {self.crossings_left[0]:,} crossings are left (Loop subdivision's: "
                   f"{self.crossings_left[1]:,})." if self.crossings_left else "."))

    def check(self, k: int, V_net, F_net, prev) -> tuple[str, np.ndarray | None]:
        """``(why, positions)``: ``why`` is '' when the network's result after ``k`` levels
        passes, else why it fails; ``positions`` is None (the network's result as it is), or
        the result with Loop's positions over its bulges and over the parts handed to Loop,
        and the previous level's surface blended back in where it crossed itself (``prev``:
        the ``(V, F)`` the network subdivided at this level, see
        :func:`_blend_back_where_crossed`)."""
        why, failing, repaired = self._check(k, V_net, F_net, prev)
        if why:
            return why, None
        mixed = None
        if repaired is not None:   # Loop's positions blended in where the network bulged
            V_net = mixed = repaired
        if failing is not None and failing.any():
            self.loop_part |= failing
        if self.loop_part.any():
            # those parts from their level on by Loop, from the level before (parts share no
            # vertex, so each keeps its own scheme's stencils), at every later level too
            V_net = mixed = self._loop_parts(V_net, F_net, prev)
        net_pairs = self._new_pairs(V_net, F_net, k)
        crossed = len(net_pairs)
        if not crossed:
            return "", mixed
        blended, moved, left = _blend_back_where_crossed(
            V_net, F_net, prev[0], prev[1], net_pairs, lambda X: self._new_pairs(X, F_net, k),
            lambda P: self._away(P, k), lambda X, faces: self._new_pairs(X, F_net, k, faces))
        # what is left after the last round is kept and said, with Loop's own count beside it
        # (two sheets closer than a subdivision's smoothing shrinks them): refusing the level
        # instead (Loop from there) lost more accuracy than the crossings cost (class docstring)
        self.crossings_left = (left, self._loop_crossings(k)) if left else None
        if not moved:
            # all beside the input's own crossings: left as they are
            return "", mixed
        self.unsmoothed += moved
        self.blended_levels.append(k)
        self.crossings_seen += crossed
        return "", blended

    def _loop_parts(self, V_net, F_net, prev) -> np.ndarray:
        """``V_net`` with the vertices of the parts handed to Loop (``loop_part``) at Loop
        subdivision's positions of the level before ``prev`` (in the numbering of ``F_net``)."""
        V_loop = _loop_positions(prev[0], prev[1], F_net, len(V_net))
        k = int(round(np.log(len(F_net) / len(self.F0)) / np.log(4)))
        face_part = np.repeat(self.face_part, 4 ** k)
        vert = np.zeros(len(V_net), bool)
        vert[np.asarray(F_net)[self.loop_part[face_part]].ravel()] = True
        out = np.array(V_net, np.float64)
        out[vert] = V_loop[vert]
        return out

    def _bump_repair(self, k, V_net, F_net, prev, edges, tn, tb, active) -> tuple | None:
        """Loop's positions blended in over the fewest input triangles whose children carry
        the network's excess bending (its terms ``tn`` minus butterfly's ``tb``, each interior
        edge's term split between its two triangles), enough of them that the rest would be
        within ``factor``; None when that takes more than :data:`BUMP_SHARE` of the ``active``
        input triangles (then the whole level fails, as before). Weight 1 on those children's
        corners and the ring around them, 1/2 on the next ring, as the crossing blend.
        Returns (positions, the input triangles repaired)."""
        from ..mesh.topology import vertex_adjacency

        fa, fb = edges[0], edges[1]
        parent = np.repeat(np.arange(len(self.F0)), 4 ** k)
        n0 = len(self.F0)

        def per_face(t):
            return (np.bincount(parent[fa], 0.5 * t, minlength=n0)
                    + np.bincount(parent[fb], 0.5 * t, minlength=n0))
        pn, pb = per_face(tn), per_face(tb)
        pn[~active] = 0.0
        pb[~active] = 0.0
        excess = pn - pb
        order = np.argsort(-excess)
        order = order[excess[order] > 0]
        need = pn.sum() - self.factor * pb.sum()
        if need <= 0 or not len(order):
            return None
        q = int(np.searchsorted(np.cumsum(excess[order]), need) + 1)
        if q > max(1, int(BUMP_SHARE * active.sum())) or q > len(order):
            return None
        bumpy = np.isin(parent, order[:q])
        n = len(V_net)
        ring1, ring2 = _rings(vertex_adjacency(F_net, n), F_net, np.flatnonzero(bumpy), n)
        w = np.where(ring1, 1.0, np.where(ring2, 0.5, 0.0))
        V_loop = _loop_positions(prev[0], prev[1], F_net, n)
        return ((1.0 - w)[:, None] * np.asarray(V_net, np.float64) + w[:, None] * V_loop,
                np.sort(order[:q]))

    def _loop_crossings(self, k: int) -> int:
        """How many new crossings Loop subdivision of the input to ``k`` levels makes."""
        from .baselines import subdivide_baseline

        self.Vl, self.Fl = subdivide_baseline(self.Vl, self.Fl, k - self.loop_level, "loop")
        self.loop_level = k
        return len(self._new_pairs(self.Vl, self.Fl, k))

    def _new_pairs(self, V, F, k: int, faces=None) -> np.ndarray:
        """The intersecting pairs of a ``k``-level result whose parents did not intersect in
        the input (the children of triangle f are 4 f .. 4 f + 3 at every level); with
        ``faces``, only the pairs with a triangle among them."""
        from ..mesh.intersections import (intersecting_pairs, intersecting_pairs_touching,
                                          new_crossing_pairs)

        pairs = (intersecting_pairs(V, F) if faces is None
                 else intersecting_pairs_touching(V, F, faces))
        if not len(pairs):
            return pairs
        if self.input_pairs is None:
            self.input_pairs = intersecting_pairs(self.V0, self.F0)
        return new_crossing_pairs(pairs, k, self.input_pairs)

    def _away(self, pairs, k: int) -> np.ndarray:
        """Of new pairs of a ``k``-level result, those away from the input's own crossings
        (:func:`~algorithms.mesh.intersections.new_crossing_pairs_away`)."""
        from ..mesh.intersections import new_crossing_pairs_away

        return new_crossing_pairs_away(pairs, k, self.F0, self.input_pairs
                                       if self.input_pairs is not None else np.zeros((0, 2)))

    def _check(self, k: int, V_net, F_net, prev) -> tuple:
        """``(why, failing parts or None, repaired positions or None)``."""
        from .baselines import subdivide_baseline
        from .metrics import (_bending_terms, _interior_edges, bending_energy, planar_faces,
                              planar_normal_deviation)

        if self.note:     # butterfly could not run: nothing to compare with
            return "", None, None
        try:
            self.Vb, self.Fb = subdivide_baseline(self.Vb, self.Fb, k - self.level, "butterfly")
            self.level = k
            same = self.Fb.shape == F_net.shape and np.array_equal(self.Fb, F_net)
            edges = _interior_edges(F_net, len(V_net)) if same else None
            # each interior edge's bending term, computed once a mesh and level: the whole
            # ratio, the parts' and the bulges' all sum them
            tb = _bending_terms(self.Vb, self.Fb, edges)[1] if same else None
            ref = float(tb.sum()) if same else bending_energy(self.Vb, self.Fb)
        except Stylize3DError:
            self.note = ("(Modified butterfly could not run on this mesh, so the network's "
                         "result was not compared with it.)")
            return "", None, None
        failing = repaired = None
        mine = ~self.loop_part
        # parts judged apart only where both results share the network's numbering
        by_part = same and self.n_parts > 1
        if by_part:
            edge_part = np.repeat(self.face_part, 4 ** k)[edges[0]]
            ref_p = np.bincount(edge_part, tb, minlength=self.n_parts)

        def terms(X):
            return _bending_terms(X, F_net, edges)[1]

        def ratio_of(t, sel=None):
            if not by_part:
                return float(t.sum()) / ref if ref > 0 else float("inf")
            return _ratio(np.bincount(edge_part, t, minlength=self.n_parts), ref_p,
                          mine if sel is None else sel)
        tn = terms(V_net) if same else None
        bent = ratio_of(tn) if same else (bending_energy(V_net, F_net) / ref if ref > 0
                                          else float("inf"))
        if bent > self.factor and same:
            # a few bulges or dimples (face at 200 vertices, level 1: 78 % of the excess
            # bending in one of 390 input triangles): Loop's positions blended in there only
            fixed = self._bump_repair(k, V_net, F_net, prev, edges, tn, tb,
                                      mine[self.face_part])
            if fixed is not None:
                bent_fixed = ratio_of(terms(fixed[0]))
                if bent_fixed <= self.factor:
                    repaired, bent = fixed[0], bent_fixed
                    moved = int((np.abs(repaired - V_net).max(axis=1) > 0).sum())
                    self.bumps.append((k, len(fixed[1]), moved))
                    self.bump_triangles.append(fixed[1])
        if bent > self.factor and by_part:
            # judged whole first (as a one-part mesh, with the factor tuned so); only where the
            # whole fails is each part judged, and only the parts that fail get Loop
            net_p = np.bincount(edge_part, tn, minlength=self.n_parts)
            # below 1e-10 a triangle a part's bending is rounding (the float32 network on
            # a flat part, which butterfly keeps exactly flat), not a bump
            tiny = 1e-10 * np.bincount(self.face_part, minlength=self.n_parts) * 4 ** k
            failing = mine & (net_p > self.factor * ref_p + tiny)
            ok = mine & ~failing
            if ok.any():
                worst = _ratio(net_p, ref_p, failing)
                self.part_fallbacks.append((
                    k, int(failing.sum()), float(failing[self.face_part].mean()),
                    f"the network's result was {worst:.2f}x as bent as modified "
                    f"butterfly's there" if np.isfinite(worst) and worst < 1e6 else
                    "the network's result was bent where modified butterfly's is flat"))
                bent = _ratio(net_p, ref_p, ok)
            else:
                failing = None
        self.ratio = float(bent)
        if bent > self.factor:
            return (f"the network's result was {bent:.2f}x as bent as modified butterfly's "
                    f"(bumps, dimples or creases that it has not; more than {self.factor:g}x)"
                    if np.isfinite(bent) and bent < 1e6 else
                    "the network's result was bent where modified butterfly's is flat"), None, None
        X = V_net if repaired is None else repaired
        if self.planar is None:
            self.planar = planar_faces(self.V0, self.F0)
        if self.planar.any():
            dev = planar_normal_deviation(self.V0, self.F0, X, F_net, k, self.planar)
            dev_b = planar_normal_deviation(self.V0, self.F0, self.Vb, self.Fb, k, self.planar)
            if dev > dev_b + GUARD_PLANAR_DEGREES:
                if repaired is not None:
                    self.bumps.pop()
                    self.bump_triangles.pop()
                return (f"the network's result bent its flat sides by {dev:.1f} degrees (RMS; "
                        f"modified butterfly: {dev_b:.1f})"), None, None
        return "", failing, repaired


def _ratio(net_p, ref_p, sel) -> float:
    """The bending of the parts ``sel`` over butterfly's there (inf where butterfly's is flat
    and the network's is not)."""
    r = ref_p[sel].sum()
    return net_p[sel].sum() / r if r > 0 else (0.0 if not net_p[sel].sum() else float("inf"))


#: the guard's local repair of bulges and dimples (:meth:`_Guard._bump_repair`): at most this
#: share of the input's triangles (chosen before it was measured: a repair for a few isolated
#: defects; more than that, and the network is not the scheme for this mesh)
BUMP_SHARE = 0.02


def _loop_positions(V_prev, F_prev, F_net, n: int) -> np.ndarray:
    """Loop subdivision's positions of one level of ``(V_prev, F_prev)``, in the numbering of
    ``F_net`` (:func:`refine`'s: each new vertex numbered as in the network's level; ``n``
    vertices)."""
    from ..mesh.subdivision import loop_matrix

    S, F_loop = loop_matrix(F_prev, len(V_prev))
    V_loop = np.asarray(S @ np.asarray(V_prev, np.float64))
    # igl's numbering (face a, b, c -> [a, ab, ca], [b, bc, ab], ...) to refine's (centre
    # child ab, bc, ca); old vertices keep their indices
    where = np.arange(n)
    kids_l = F_loop.reshape(-1, 4, 3)
    centre = np.asarray(F_net, np.int64).reshape(-1, 4, 3)[:, 3]
    where[centre[:, 0]] = kids_l[:, 0, 1]
    where[centre[:, 1]] = kids_l[:, 1, 1]
    where[centre[:, 2]] = kids_l[:, 0, 2]
    return V_loop[where]


#: the guard's local repair of crossings (:func:`_blend_back_where_crossed`): at most this many
#: rounds, each widening the blend of the previous level's surface
BLEND_ROUNDS = 3
#: then, where crossings are left, at most this many rounds of the tear-checked blend back
#: (ADIS16480, a CAD part with slivers: 19 crossings left after 3)
FLAT_ROUNDS = 8


def midpoints_in_refine_numbering(V_prev, F_prev, F_net) -> np.ndarray:
    """The previous level's surface in the numbering of ``F_net`` (:func:`~.topology.refine` of
    ``F_prev``): old vertices where they were, each edge's vertex at the edge's midpoint, so
    every child triangle lies in its parent's plane."""
    V_prev = np.asarray(V_prev, np.float64)
    F_prev = np.asarray(F_prev, np.int64)
    F_net = np.asarray(F_net, np.int64)
    n_out = int(F_net.max()) + 1
    VM = np.empty((n_out, 3))
    VM[:len(V_prev)] = V_prev
    mid = F_net.reshape(-1, 4, 3)[:, 3]           # (ab, bc, ca) of every parent triangle
    a, b, c = F_prev[:, 0], F_prev[:, 1], F_prev[:, 2]
    VM[mid[:, 0]] = 0.5 * (V_prev[a] + V_prev[b])
    VM[mid[:, 1]] = 0.5 * (V_prev[b] + V_prev[c])
    VM[mid[:, 2]] = 0.5 * (V_prev[c] + V_prev[a])
    return VM


def _rings(A, F, pairs, n) -> tuple[np.ndarray, np.ndarray]:
    """The corners of the triangles in ``pairs`` with one ring around them, and one more."""
    bad = np.zeros(n, dtype=bool)
    bad[F[pairs.ravel()].ravel()] = True
    ring1 = bad | (A @ bad.astype(np.float64) > 0)
    ring2 = ring1 | (A @ ring1.astype(np.float64) > 0)
    return ring1, ring2


#: the fractions of the blend weight tried, smallest first, on each connected part of the
#: blended region (:func:`_least_blend`)
BLEND_FRACTIONS = (0.125, 0.25, 0.5, 0.75)


def _least_blend(V_net, VM, w, A, F, pairs, new_pairs, away=None, new_pairs_near=None):
    """The blend ``V = V_net + s w (VM - V_net)`` with, on each connected part of the blended
    region (``w > 0``), the smallest fraction ``s`` of :data:`BLEND_FRACTIONS` (else 1) that
    leaves no crossing pair touching that part which the full blend (``s = 1``, crossing pairs
    ``pairs``) does not have: a crossing needs moving only as far as it takes to end it, and
    every further step towards the flat previous level loses the network's shape there (lilium
    at 200 vertices, 2 levels: Hausdorff 0.38 % with the full blend, 0.28 % without it).
    ``new_pairs_near(X, faces)``, optional: the new crossing pairs with a triangle among
    ``faces`` (the triangles with a blended corner, the only ones that move), found on that part
    of the mesh only; without it, ``new_pairs(X)`` on the whole mesh.
    Returns (positions, their new crossing pairs)."""
    from scipy.sparse.csgraph import connected_components

    blended = np.flatnonzero(w > 0)
    sub = A[blended][:, blended]
    n_parts, label = connected_components(sub, directed=False)
    part = np.full(len(V_net), -1)
    part[blended] = label
    D = VM - V_net
    full = V_net + w[:, None] * D
    moving = np.flatnonzero((w > 0)[F].any(axis=1))
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    touches = np.zeros(len(F), bool)
    touches[moving] = True
    still = pairs[~touches[pairs].any(axis=1)]   # the same at every fraction

    # the blended part of each moving triangle (its blended corners are adjacent: one part)
    face_part = part[F].max(axis=1)

    def near(X, faces):
        if not len(faces):
            return np.zeros((0, 2), np.int64)
        if new_pairs_near is not None:
            return np.asarray(new_pairs_near(X, faces), np.int64).reshape(-1, 2)
        P = np.asarray(new_pairs(X), np.int64).reshape(-1, 2)
        mask = np.zeros(len(F), bool)
        mask[faces] = True
        return P[mask[P].any(axis=1)]

    def key(P):
        P = np.sort(np.asarray(P, np.int64).reshape(-1, 2), axis=1)
        return set(map(tuple, P))

    def far(P):
        return away(P) if away is not None else P

    def parts_of(P):   # (k, 6) the blended parts of each pair's corners (-1: none)
        return part[F[P].reshape(len(P), -1)]

    allowed = key(far(pairs))               # what the full blend leaves is left anyway
    s = np.ones(n_parts)
    settled = np.zeros(n_parts, bool)
    final = []   # the pairs each round finds at their parts' final fractions
    for frac in BLEND_FRACTIONS:
        trial = np.where(settled, s, frac)
        X = V_net.copy()
        X[blended] += (trial[label] * w[blended])[:, None] * D[blended]
        # only the triangles of unsettled parts move from the round before: the pairs among
        # settled parts' triangles were tested at their final positions when they settled
        Q = near(X, moving[~settled[face_part[moving]]])
        P = far(Q)
        bad = np.zeros(n_parts, bool)
        extra = [p for p in np.asarray(P, np.int64).reshape(-1, 2)
                 if tuple(sorted(p)) not in allowed]
        for p in extra:
            lab = part[F[p].ravel()]         # the parts among the pair's triangles' corners
            bad[lab[lab >= 0]] = True
            if not (lab >= 0).any():      # (cannot be: unblended triangles never move)
                bad[:] = True
        newly = ~settled & ~bad
        s[newly] = frac
        settled |= newly
        if len(Q):
            lab = parts_of(Q)
            done = np.where(lab >= 0, settled[np.maximum(lab, 0)], True).all(axis=1)
            final.append(Q[done])
        if settled.all():
            break
    X = V_net.copy()
    X[blended] += (s[label] * w[blended])[:, None] * D[blended]
    # the parts that never settled are fully blended: their pairs there, against every
    # other part's final fraction, are new (tested exactly as before: the whole blend if
    # one is not the full blend's)
    P = near(X, moving[~settled[face_part[moving]]])
    if any(tuple(sorted(p)) not in allowed for p in np.asarray(far(P), np.int64).reshape(-1, 2)):
        return full, pairs              # the parts' choices crossed each other: the full blend
    found = np.concatenate(final + [P]) if final else P
    if len(found):   # each pair once (a pair is final in one round only; kept safe)
        _, first = np.unique(np.sort(found, axis=1), axis=0, return_index=True)
        found = found[np.sort(first)]
    return X, np.concatenate([still, found])


def _blend_back_where_crossed(V_net, F_net, V_prev, F_prev, pairs, new_pairs,
                              away=None, new_pairs_near=None) -> tuple[np.ndarray, int, int]:
    """The network's level with the previous level's surface blended back in around the
    triangles that cross each other where the input's did not.

    The previous level's surface (:func:`midpoints_in_refine_numbering`: the level the network
    subdivided, each new vertex at its edge's midpoint) has every child triangle in its
    parent's plane, so it crosses itself only where that level did. Only crossings away from
    the input's own count (``away(pairs)``, default all: near them, as on a model of
    interpenetrating parts, subdividing only moves the crossing line). Weight 1 on the crossing
    triangles' corners and the ring around them, 1/2 on the next ring, ``V = (1 - w) V_net + w
    V_prev``, widened up to :data:`BLEND_ROUNDS` times while any crossing is left; then the
    shared blend back of :func:`algorithms.deform.collisions.put_back`, taken only where it
    tears nothing, up to :data:`FLAT_ROUNDS` more rounds. ``pairs``: the new crossing pairs of
    ``V_net``; ``new_pairs(V)``: those of other positions on ``F_net``.

    Until 30 November 2026 the first blend used Loop subdivision's positions (and only down to
    Loop's own crossing count): Loop shrinks, so on CAD parts with thin walls the blend cost
    accuracy and rounded corners (coarse ADIS16480, 2 levels: H 5.76 % with Loop's positions,
    0.99 % with the previous level's, the network alone 1.37 %; 497 crossings left against 0;
    docs/results/subdivision.md, "The blend back").

    Returns (positions, vertices moved towards the previous level's surface, crossings left
    away from the input's own)."""
    from ..deform.collisions import put_back
    from ..mesh.intersections import intersecting_pairs, pairs_not_in
    from ..mesh.topology import vertex_adjacency

    n = len(V_net)
    V_net = np.asarray(V_net, np.float64)
    VM = midpoints_in_refine_numbering(V_prev, F_prev, F_net)
    A = vertex_adjacency(F_net, n)
    w = np.zeros(n)
    V = V_net
    far = away(pairs) if away is not None else pairs
    pairs0 = np.asarray(pairs, np.int64).reshape(-1, 2)

    def pairs_of(X, changed, before):
        # only triangles with a corner whose weight changed this round move: the other
        # pairs are the round before's (``before``), and the moving ones are tested on their
        # part of the mesh only (armadillo QSlimmed to 5,002 vertices, level 2: 160,000
        # triangles, a whole-mesh test 0.14 s a round)
        if new_pairs_near is None:
            return new_pairs(X)
        moving = changed[F_net].any(axis=1)
        keep = before[~moving[before].any(axis=1)]
        return np.concatenate([keep, np.asarray(new_pairs_near(X, np.flatnonzero(moving)),
                                                np.int64).reshape(-1, 2)])
    pairs = pairs0
    for _ in range(BLEND_ROUNDS):
        if not len(far):
            break
        ring1, ring2 = _rings(A, F_net, far, n)
        w_before = w
        w = np.maximum(w, np.where(ring1, 1.0, np.where(ring2, 0.5, 0.0)))
        V = (1.0 - w)[:, None] * V_net + w[:, None] * VM
        pairs = pairs_of(V, w != w_before, np.asarray(pairs, np.int64).reshape(-1, 2))
        far = away(pairs) if away is not None else pairs
    if (w > 0).any():
        V, pairs = _least_blend(V_net, VM, w, A, F_net, pairs, new_pairs, away, new_pairs_near)
        far = away(pairs) if away is not None else pairs
    if len(far):
        # pairs that the previous level's own surface shows at this resolution (triangles of a
        # sliver-laden CAD part touching in their common plane: ADIS16480, 275 at level 2 of
        # its unchanged surface) are not the subdivision's and cannot be mended here
        own = intersecting_pairs(VM, F_net)

        def crossings(X):
            found = new_pairs(X)
            return pairs_not_in(away(found) if away is not None else found, own)

        far = pairs_not_in(far, own)
        if len(far):
            V_back, _, n_far = put_back(V, VM, F_net, None, far, np.zeros(n, bool),
                                        rounds=FLAT_ROUNDS, crossings=crossings)
            if n_far < len(far):
                V = V_back
                pairs = new_pairs(V)
    left = away(pairs) if away is not None else pairs
    moved = int((np.abs(V - V_net).max(axis=1) > 0).sum()) if len(V) else 0
    return V, moved, int(len(left))


def _guard_fallback(V, F, lv: int, li: int, kept, why: str, guard: _Guard, plan: ScalePlan,
                    note: str) -> Iterator[Step]:
    """The network failed the guard at level ``li + 1`` of ``lv``: Loop subdivision makes the
    levels from there on, from the network's last accepted level ``kept`` (or from the input
    when level 1 failed)."""
    from .baselines import subdivide_baseline

    Vl, Fl = (V, F) if kept is None else kept
    for k in range(li, lv):
        yield Step(int(1000 * k / lv), 1000, V, {},
                   f"Level {k + 1} of {lv}: Loop subdivision")
        Vl, Fl = subdivide_baseline(Vl, Fl, 1, "loop")
    where = (f"This mesh is denser than the network was trained for "
             f"({plan.density_words()}); "
             if plan.denser else "On this mesh ")
    if li == 0:
        said = f"{where}{why}, so Loop subdivision was used."
    else:
        made = "level 1" if li == 1 else f"levels 1-{li}"
        rest = f"level {li + 1}" if li + 1 == lv else f"levels {li + 1}-{lv}"
        said = (f"The network made {made}; at level {li + 1} {why}, so Loop subdivision made "
                f"{rest}.")
    if plan.advice and li == 0:
        said += (f" 'Coarsen first' to about {plan.advice} vertices lets the network rebuild "
                 f"the detail.")
    metrics = {"bending_vs_butterfly": guard.ratio} if np.isfinite(guard.ratio) else {}
    if guard.part_fallbacks:   # parts the earlier levels had already handed to Loop
        metrics["loop_parts"] = float(guard.loop_part.sum())
        said = f"{guard.parts_note()} {said}"
    if guard.bumps:   # earlier levels the network kept, with Loop blended in over bulges
        metrics["loop_blended_vertices"] = float(sum(m for *_, m in guard.bumps))
        said = f"{said} {guard.bump_note()}"
    if guard.unsmoothed:   # earlier levels the network kept, repaired where they crossed
        metrics["unsmoothed_vertices"] = float(guard.unsmoothed)
        said = f"{said} {guard.blend_note()}"
    yield SubdividedStep(1000, 1000, np.asarray(Vl, dtype=np.float64), metrics,
                         f"{len(Fl):,} triangles", F=np.asarray(Fl, dtype=np.int64),
                         note=said if li == 0 else " ".join(x for x in (note, said) if x),
                         fallback=True, levels_used=guard.levels_used(li) + ("loop",) * (lv - li),
                         fallback_reason="; ".join(x for x in (guard.parts_reason(),
                                                               f"at level {li + 1} {why}") if x))


def neural_subdivide_np(V, F, levels: int, network: Network, *, adapt_scale: bool = True,
                        dense: str = "loop") -> tuple[np.ndarray, np.ndarray, str]:
    """:func:`neural_subdivision_iter` run to the end: (V_sub, F_sub, note)."""
    last = None
    for last in neural_subdivision_iter(V, F, levels, network, adapt_scale=adapt_scale,
                                        dense=dense):
        pass
    return last.V, last.F, last.note
