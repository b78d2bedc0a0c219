"""Training data of neural subdivision: random coarse meshes with a bijective map (App. 4.8.5).

For every training shape (scaled first, see :func:`normalization`) :func:`generate_dataset`
makes ``coarse_meshes`` coarse versions by **semi-random collapses** -- each collapse takes the
cheapest, by the quadric error, of 100 random edges, the merged vertex placed as QSlim does --
down to a random number of vertices in [150, 300], keeping the bijective map through the
project's successive self-parameterization
(:func:`algorithms.mesh.selfparam.self_parameterize` with ``strategy="qslim",
random_candidates=100``). Each coarse mesh is then split ``levels`` times with the Loop topology
(:func:`algorithms.subdivision.topology.refine`); every vertex of every level has a place
``g(v)`` on the coarse mesh (a face and barycentric coordinates), and its target is the point
``f(g(v))`` of the dense surface (:meth:`SelfParameterization.query_inverse`), §4.3.

``targets="loop"`` (App. 4.8.7, learning Loop) replaces the targets by the coarse mesh's own
Loop subdivision (libigl, in our vertex order).

Generation is embarrassingly parallel: one task per coarse mesh, submitted to any
``concurrent.futures.Executor`` -- a local process pool by default, or a Dask distributed
``Client``'s executor when a scheduler address is given (the workers need this package
installed). The local pool's processes get the (normalized) training shapes once, when they
start, so a task sends only its index and parameters, and they are started with one thread for
OpenMP / BLAS / Numba (two processes on two cores must not each start a thread per core). The
result of a coarse mesh does not depend on where it was made (bit-for-bit equal, tested). Every coarse mesh is cached as a plain ``.npz`` (no pickle) named by the hash of the
shape, the data parameters and its index, so a second run (or a run with more coarse meshes)
only computes what is missing. Meshes with boundary and of any genus work (the map is the
project's, which handles both).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import hashlib
import json
import multiprocessing
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import ConnectionFailed, InvalidMeshError, ParameterError
from ..params import param, params_to_dict, validate_params
from .topology import half_flaps, igl_odd_order, locate_vertices, refine, refine_barycentric

__all__ = ["DataParams", "CoarseSample", "normalization", "generate_coarse_sample",
           "selection_shape",
           "generate_dataset", "default_cache_dir", "check_manifold", "LOOP_WORKS", "mesh_hash",
           "subdivision_positions"]

DATA_VERSION = 1
SCHEDULER_TIMEOUT = 20  # seconds to reach a Dask scheduler


@dataclass(frozen=True)
class DataParams:
    """Data generation (thesis App. 4.8.5-4.8.6; defaults are the thesis')."""

    coarse_meshes: int = param(200, label="Coarse meshes", minimum=1, maximum=100000, step=10,
                               tooltip="How many random coarse versions of the training shapes "
                                       "to make (the thesis uses 200 in total).")
    min_vertices: int = param(150, label="Fewest coarse vertices", minimum=4, maximum=100000,
                              step=10, advanced=True,
                              tooltip="Each coarse mesh gets a random vertex count between this "
                                      "and the largest count (thesis: 150-300).")
    max_vertices: int = param(300, label="Most coarse vertices", minimum=4, maximum=100000,
                              step=10, advanced=True,
                              tooltip="Upper end of the random coarse vertex count.")
    candidates: int = param(100, label="Random edges per collapse", minimum=1, maximum=100000,
                            step=10, advanced=True,
                            tooltip="Each collapse takes the edge of least quadric error among "
                                    "this many random edges (thesis: 100). Fewer = more random.")
    levels: int = param(2, label="Levels", minimum=1, maximum=4, step=1,
                        tooltip="How many subdivision levels the targets cover (thesis: 2).")
    seed: int = param(0, label="Seed", minimum=0, maximum=2**31 - 1, step=1, advanced=True,
                      tooltip="Seed of the random collapses (the same seed gives the same data).")
    targets: str = param("map", label="Targets", choices=("map", "loop"), advanced=True,
                         tooltip="'map': points of the training shape through the bijective map "
                                 "(neural subdivision); 'loop': the coarse mesh's own Loop "
                                 "subdivision (learning Loop, App. 4.8.7).")


@dataclass
class CoarseSample:
    """One coarse mesh and its targets (all in the normalized frame of its training shape).

    Attributes
    ----------
    V : (n0, 3) float64, F : (m0, 3) int64 -- the coarse mesh.
    targets : list of (n_l, 3) float64 arrays, levels 0..L (level 0: the coarse vertices mapped
        onto the dense surface); level ``l`` has the vertices of :func:`refine` applied l times.
    """

    V: np.ndarray
    F: np.ndarray
    targets: list

    @property
    def levels(self) -> int:
        return len(self.targets) - 1


def normalization(V: np.ndarray) -> tuple[np.ndarray, float]:
    """Rigid-motion-invariant scaling: centre = vertex mean, scale so that the farthest vertex is
    at distance sqrt(3) (the half-diagonal of the box of side 2 the authors scale to).
    Returns ``(centre (3,), scale)``; normalized = (V - centre) * scale."""
    V = np.asarray(V, dtype=np.float64)
    c = V.mean(axis=0)
    r = float(np.sqrt(((V - c) ** 2).sum(axis=1).max())) if len(V) else 0.0
    if not np.isfinite(r) or r <= 0:
        raise InvalidMeshError("The mesh has no extent (all vertices at one point), so it cannot "
                               "be subdivided or used for training.")
    return c, np.sqrt(3.0) / r


#: what works where neural or butterfly subdivision cannot take a mesh and Clean cannot fix it
LOOP_WORKS = ("Loop subdivision works on this mesh as it is: set Method to 'loop' "
              "(command line: --method loop).")


def _directed_edge_repeats(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(sorted directed-edge keys ``src * n + dst``, positions where a key repeats)."""
    key = np.sort(F.reshape(-1) * n + F[:, [1, 2, 0]].reshape(-1))
    return key, np.flatnonzero(key[1:] == key[:-1])


def _clean_fixes_edges(V: np.ndarray, F: np.ndarray) -> bool:
    """True when 'Clean' (its defaults, as the app and ``stylize3d clean`` run it) leaves no
    directed edge used twice: advice to clean must work (a Moebius strip or a part glued to
    itself cannot be re-oriented, and 'Clean' then says "Nothing could be fixed")."""
    from algorithms.mesh.validate import clean_mesh

    try:
        res = clean_mesh(V, F)
    except Exception:  # noqa: BLE001 - a mesh Clean refuses: it cannot fix it either
        return False
    return not _directed_edge_repeats(np.asarray(res.F, np.int64), len(res.V))[1].size


def check_manifold(V: np.ndarray, F: np.ndarray, what: str, alternative: str = "") -> None:
    """Raise InvalidMeshError unless F is a consistently oriented, edge-manifold triangle mesh.

    The message advises 'Clean' only when Clean fixes it; otherwise it says so and gives
    ``alternative`` (what works on this mesh as it is, e.g. Loop subdivision), if any."""
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    src = F.reshape(-1)
    key, dup = _directed_edge_repeats(F, n)
    if dup.size:
        a, b = divmod(int(key[dup[0]]), n)
        if _clean_fixes_edges(V, F):
            advice = "'Clean' fixes this."
        else:
            advice = ("'Clean' cannot fix it on this mesh (a one-sided part, like a Moebius "
                      "strip, or triangles glued to each other's backs).")
            if alternative:
                advice += " " + alternative
        raise InvalidMeshError(
            f"{what} needs a manifold, consistently oriented triangle mesh, but the edge between "
            f"vertices {a} and {b} is used twice in the same direction ({dup.size} such edges: "
            f"more than two triangles on an edge, or neighbours facing opposite ways). {advice}")
    used = np.zeros(n, dtype=bool)
    used[src] = True
    if not used.all():
        raise InvalidMeshError(f"{what}: {int((~used).sum())} vertices belong to no triangle. "
                               f"Run 'Clean' to remove them first.")


def mesh_hash(V: np.ndarray, F: np.ndarray) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(V, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(F, dtype=np.int64).tobytes())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """``$STYLIZE3D_CACHE/subdivision`` or ``~/.cache/stylize3d/subdivision``."""
    base = os.environ.get("STYLIZE3D_CACHE")
    root = Path(base) if base else Path(os.environ.get("XDG_CACHE_HOME",
                                                       Path.home() / ".cache")) / "stylize3d"
    return root / "subdivision"


def subdivision_positions(F0: np.ndarray, n0: int, levels: int):
    """Faces and coarse locations of every level.

    Returns a list, per level 0..levels, of ``(F_l, face_l (n_l,), bary_l (n_l, 3))``: the faces
    of the level (:func:`refine` applied l times) and each vertex's coarse face and barycentric
    coordinates there."""
    F = np.asarray(F0, dtype=np.int64)
    n = int(n0)
    parent = np.arange(len(F), dtype=np.int64)
    corners = np.broadcast_to(np.eye(3), (len(F), 3, 3)).copy()
    out = []
    for lv in range(levels + 1):
        face, bary = locate_vertices(F, n, parent, corners)
        out.append((F, face, bary))
        if lv == levels:
            break
        hf = half_flaps(F, n)
        F = refine(F, n, hf.EF)
        n = n + len(hf.E)
        parent, corners = refine_barycentric(parent, corners)
    return out


def _loop_targets(V0: np.ndarray, F0: np.ndarray, levels: int) -> list:
    from ..mesh.subdivision import loop_matrix

    V = np.asarray(V0, dtype=np.float64)
    F = np.asarray(F0, dtype=np.int64)
    out = [V.copy()]
    for _ in range(levels):
        n = len(V)
        hf = half_flaps(F, n)
        perm = igl_odd_order(F, n, hf.E)
        NV = loop_matrix(F, n)[0] @ V
        V = np.concatenate([NV[:n], NV[n:][perm]])
        F = refine(F, n, hf.EF)
        out.append(V)
    return out


def generate_coarse_sample(V: np.ndarray, F: np.ndarray, index: int,
                           params: DataParams) -> dict:
    """Coarse mesh ``index`` of a (normalized) training shape (see the module docstring).

    Returns a dict of arrays ``V``, ``F``, ``T0..TL`` and ``info`` (a JSON string)."""
    import time

    from ..mesh.selfparam import self_parameterize

    t0 = time.perf_counter()
    rng = np.random.default_rng([int(params.seed), int(index), 7919])
    nv = int(rng.integers(params.min_vertices, params.max_vertices + 1))
    n, m = len(V), len(F)
    target_faces = int(min(m, max(4, m - 2 * (n - nv))))
    sp = self_parameterize(V, F, target_faces, strategy="qslim",
                           random_candidates=params.candidates,
                           seed=int(rng.integers(0, 2**31 - 1)))
    V0, F0 = sp.V_coarse, sp.F_coarse
    t1 = time.perf_counter()
    t_map = 0.0
    out = {"V": V0, "F": F0}
    if params.targets == "loop":
        for lv, T in enumerate(_loop_targets(V0, F0, params.levels)):
            out[f"T{lv}"] = T
    else:
        for lv, (_Fl, face, bary) in enumerate(subdivision_positions(F0, len(V0),
                                                                      params.levels)):
            ta = time.perf_counter()
            ff, fb = sp.query_inverse(face, bary)
            t_map += time.perf_counter() - ta
            out[f"T{lv}"] = np.einsum("qi,qij->qj", fb, V[F[ff]])
    t2 = time.perf_counter()
    # seconds: the self-parameterization's own count; seconds_*: this function's split
    # (collapses = the whole self-parameterization, map = query_inverse, topology = the Loop
    # topology, coarse locations and target points)
    out["info"] = np.array(json.dumps({"vertices": int(len(V0)), "target_vertices": nv,
                                       "reached_target": bool(sp.report["reached_target"]),
                                       "seconds": float(sp.report["seconds"]),
                                       "seconds_collapses": t1 - t0, "seconds_map": t_map,
                                       "seconds_topology": t2 - t1 - t_map}))
    return out


def _cache_path(cache_dir: Path, shape_key: str, params: DataParams, index: int) -> Path:
    d = params_to_dict(params)
    d.pop("coarse_meshes")
    d["version"] = DATA_VERSION
    pk = hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]
    return cache_dir / f"{shape_key[:16]}-{pk}-{index:05d}.npz"


# shapes handed to a local pool's process once, when it starts (see _init_worker)
_WORKER_SHAPES: list = []
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                     "NUMBA_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def _init_worker(shapes) -> None:
    """Local pool process start: keep the training shapes (sent once, not per task)."""
    _WORKER_SHAPES[:] = list(shapes)


def _shape_task(shape, index, params_dict, path):
    """Local pool task: coarse mesh ``index`` of the worker's training shape ``shape``."""
    V, F = _WORKER_SHAPES[shape]
    return _task(V, F, index, params_dict, path)


class _OneThreadChildren:
    """While active, processes started from here see 1 thread in the usual variables
    (a spawned process reads them before it imports NumPy / Numba); restored afterwards."""

    def __enter__(self):
        self._old = {k: os.environ.get(k) for k in _THREAD_VARIABLES}
        for k in _THREAD_VARIABLES:
            os.environ[k] = "1"
        return self

    def __exit__(self, *exc):
        for k, v in self._old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        return False


def _task(V, F, index, params_dict, path) -> str:
    """Worker entry point (top level, picklable): generate one coarse mesh and cache it."""
    from ..mesh.io import atomic_write

    params = DataParams(**params_dict)
    arrays = generate_coarse_sample(V, F, index, params)
    if path is None:
        return arrays
    atomic_write(path, lambda fh: np.savez(fh, **arrays))
    return str(path)


def _load(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _to_sample(arrays: dict, levels: int) -> CoarseSample:
    return CoarseSample(V=np.asarray(arrays["V"], dtype=np.float64),
                        F=np.asarray(arrays["F"], dtype=np.int64),
                        targets=[np.asarray(arrays[f"T{lv}"], dtype=np.float64)
                                 for lv in range(levels + 1)])


def dask_client(scheduler: str):
    """A Dask distributed ``Client`` of the scheduler at ``scheduler`` (e.g. tcp://host:8786);
    a missing Dask or an unreachable scheduler raise ParameterError with a plain message.
    Shared by training-data generation and ``stylize3d batch``."""
    try:
        from distributed import Client
    except ImportError:
        raise ParameterError("A scheduler address needs Dask distributed, which is not "
                             "installed in this environment. The README's set-up commands "
                             "install it; in another environment, from the checkout: "
                             "pip install -e '.[cluster]'.") from None
    try:
        return Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except Exception as exc:  # noqa: BLE001 - a plain message
        raise ConnectionFailed(f"Could not reach the Dask scheduler at {scheduler!r} "
                               f"({exc}). Check the address (e.g. tcp://host:8786) and that "
                               f"the scheduler is running.") from None


def _make_executor(workers: int | None, scheduler: str | None, shapes=()):
    if scheduler:
        client = dask_client(scheduler)
        return client.get_executor(), client.close
    w = max(1, int(workers if workers else min(2, os.cpu_count() or 1)))
    ex = cf.ProcessPoolExecutor(max_workers=w, mp_context=multiprocessing.get_context("spawn"),
                                initializer=_init_worker, initargs=(list(shapes),))
    return ex, lambda: ex.shutdown(wait=True, cancel_futures=True)


def generate_dataset(shapes: Sequence[tuple[np.ndarray, np.ndarray]], params: DataParams, *,
                     executor: cf.Executor | None = None, workers: int | None = None,
                     scheduler: str | None = None, cache_dir: str | os.PathLike | None = None,
                     use_cache: bool = True,
                     progress: Callable[[float, str], None] | None = None) -> list[CoarseSample]:
    """Coarse meshes and targets for training (see the module docstring).

    Parameters
    ----------
    shapes : list of (V (n, 3), F (m, 3)) dense training meshes (manifold, consistently
        oriented; boundary and genus allowed). The coarse meshes are spread evenly over them
        (App. 4.8.6). Each shape is normalized by :func:`normalization` first.
    params : DataParams.
    executor : any ``concurrent.futures.Executor`` to use (kept open); otherwise one is made:
        a Dask ``Client(scheduler).get_executor()`` when ``scheduler`` is given, else a local
        process pool of ``workers`` processes (default 2; 1 runs in this process, no pool).
    cache_dir : where the .npz files go (default :func:`default_cache_dir`).
    use_cache : False computes everything again (and does not write files).
    progress : optional ``callable(fraction, message)``; it may raise to cancel.

    Returns
    -------
    list of CoarseSample, in index order.
    """
    validate_params(params)
    if params.min_vertices > params.max_vertices:
        raise ParameterError(f"The fewest coarse vertices ({params.min_vertices}) must not "
                             f"exceed the most ({params.max_vertices}).")
    if not shapes:
        raise ParameterError("Training needs at least one mesh.")
    prepared = []
    for V, F in shapes:
        V = np.ascontiguousarray(V, dtype=np.float64)
        F = np.ascontiguousarray(F, dtype=np.int64)
        check_manifold(V, F, "Training")
        if len(V) <= params.max_vertices:
            raise InvalidMeshError(f"A training mesh has only {len(V)} vertices; it must be "
                                   f"denser than the coarse meshes (more than "
                                   f"{params.max_vertices} vertices).")
        c, s = normalization(V)
        Vn = (V - c) * s
        prepared.append((Vn, F, mesh_hash(Vn, F)))
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if use_cache:
        try:
            cache.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ParameterError(f"Cannot create the data cache folder '{cache}' "
                                 f"({exc.strerror or exc}).") from None
    N = int(params.coarse_meshes)
    jobs = []  # (slot, shape, index within shape, path)
    for t in range(N):
        s = t % len(prepared)
        jobs.append((t, s, t // len(prepared)))
    results: list = [None] * N
    todo = []
    for t, s, idx in jobs:
        Vn, F, key = prepared[s]
        path = _cache_path(cache, key, params, idx) if use_cache else None
        if path is not None and path.exists():
            try:
                results[t] = _to_sample(_load(path), params.levels)
                continue
            except Exception:  # noqa: BLE001 - a broken cache file is made again
                pass
        todo.append((t, s, idx, path))
    done = N - len(todo)
    if progress is not None:
        progress(done / N, f"{done} of {N} coarse meshes ready (cached)")
    if todo:
        pd = params_to_dict(params)
        own = None
        if executor is None and not scheduler and (workers or 2) <= 1:
            for t, s, idx, path in todo:
                Vn, F, _ = prepared[s]
                r = _task(Vn, F, idx, pd, path)
                results[t] = _to_sample(_load(r) if path is not None else r, params.levels)
                done += 1
                if progress is not None:
                    progress(done / N, f"{done} of {N} coarse meshes")
        else:
            ex = executor
            local = ex is None and not scheduler
            if ex is None:
                ex, own = _make_executor(workers, scheduler,
                                         [(Vn, F) for Vn, F, _ in prepared])
            try:
                futs = {}
                with _OneThreadChildren() if local else _nothing():
                    for t, s, idx, path in todo:
                        Vn, F, _ = prepared[s]
                        sp = str(path) if path is not None else None
                        fut = (ex.submit(_shape_task, s, idx, pd, sp) if local
                               else ex.submit(_task, Vn, F, idx, pd, sp))
                        futs[fut] = (t, path)
                for fut in cf.as_completed(list(futs)):
                    t, path = futs[fut]
                    r = fut.result()
                    results[t] = _to_sample(_load(r) if path is not None else r, params.levels)
                    done += 1
                    if progress is not None:
                        progress(done / N, f"{done} of {N} coarse meshes")
            finally:
                if own is not None:
                    own()
    return results


def selection_shape() -> tuple[np.ndarray, np.ndarray]:
    """(V, F) of the bundled shape a training run chooses its epoch on by default
    (``TrainParams.validation_shape`` "pretzel"): the pretzel sample
    (resources/samples/pretzel.obj, 4,216 vertices, genus 2, made by scripts/make_samples.py).
    A smooth shape unlike the mesh a user trains on says when the network stops generalizing
    and starts fitting its own shape. Issue 22's ablation (100 coarse armadillos x 80 epochs):
    chosen on 20 coarse pretzels (or on the thesis author's elephant: the same epoch, 12) the
    network beat Loop and butterfly on H and M on 11 of the 11 test meshes; chosen on its own
    coarse meshes (epoch 63), on 8; on the blob sample (epoch 56), on 8 (too smooth to tell)."""
    from pathlib import Path

    from ..mesh import read_mesh

    path = Path(__file__).resolve().parents[2] / "resources" / "samples" / "pretzel.obj"
    m = read_mesh(path)
    return np.asarray(m.V, dtype=np.float64), np.asarray(m.F, dtype=np.int64)


@contextlib.contextmanager
def _nothing():
    yield


def with_levels(params: DataParams, levels: int) -> DataParams:
    return replace(params, levels=int(levels))
