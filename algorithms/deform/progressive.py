"""Affine progressive meshes: cubic stylization of big meshes (thesis §5.3.2, Alg. 4).

Pre-processing (once per mesh and constraint set, :class:`ProgressiveCubic`):

1. ``V_c, F_c <- edge collapses(V, F, m)``: QSlim decimation to ``m`` triangles with every
   collapse recorded (:func:`algorithms.mesh.decimate.decimate`).
2. Per vertex split, the affine-fit weights (below) and a schedule of the splits in independent
   batches (:class:`AffineSplits`).
3. A :class:`~algorithms.deform.cubic.CubicStylizer` of the coarse mesh (its factorizations).

Online (every λ, style, orientation, painted λ): run cubic stylization on the coarse mesh
(Alg. 4 lines 3-6), then replay the vertex splits with affine maps (line 7).

Affine vertex splits
--------------------
Collapse ``k`` merged ``p_j`` (removed) into ``p_i`` (kept) at ``p_c`` (the merged position);
``N`` are the neighbours of the merged vertex just after the collapse and ``Q`` the ``3 x |N|``
matrix of rest vectors ``p_n - p_c`` (rest positions of that level). At the split, with the
current deformed positions ``~p_c``, ``~p_n`` (``~Q`` the deformed vectors), the linear part ``A``
of the affine map is the regularized least-squares fit ::

    A = argmin_A ||A Q - ~Q||_F^2 + ||A Gamma||_F^2 = ~Q Q^T (Q Q^T + Gamma Gamma^T)^-1

(``Gamma``: the Tikhonov term, below) and the translation makes the merged vertex map exactly
onto its deformed position (``t = ~p_c - A p_c``): this is the thesis's
``~p_j - ~p_c = ~Q A^T (p_j - p_c)`` with ``A^T = Q^T (Q Q^T + Gamma Gamma^T)^-1``. Both
endpoints are placed by the same map::

    ~p_i = ~p_c + A (p_i - p_c),      ~p_j = ~p_c + A (p_j - p_c).

Since ``A (p - p_c) = sum_n w_n (~p_n - ~p_c)`` with
``w = Q^T (Q Q^T + Gamma Gamma^T)^-1 (p - p_c)``,
the weights depend only on the rest mesh: they are computed once, for all splits at once
(vectorized), and a split costs one weighted sum over its 1-ring online.

Tikhonov regularization (the thesis: "if Q Q^T is singular, e.g. in planar regions"). With
``Q Q^T = U diag(s) U^T`` (``s_max`` its largest eigenvalue), the penalty
``(A - A_0) E (A - A_0)^T`` with ``E = Gamma Gamma^T = U diag(e) U^T``,
``e_a = max(0, tikhonov * s_max - s_a)``, is added: eigenvalues below ``tikhonov * s_max`` are
lifted to it, the others are left alone, so ::

    A = (~Q Q^T + A_0 E) (Q Q^T + E)^-1,
    A (p - p_c) = sum_n w_n (~p_n - ~p_c) + A_0 g,   g = E (Q Q^T + E)^-1 (p - p_c).

``tikhonov`` is dimensionless (default 1e-6) and ``s_max`` is a squared ring size, so the
regularization is scale-aware: it does not depend on the model's size or position, and it acts
only where the ring is flat to within ``sqrt(tikhonov) = 1e-3`` of its extent (``Q Q^T``
singular or nearly so: the fit's response along the ring's normal is undetermined or noise).
Where it acts, the undetermined part is taken from ``A_0``, the least-squares *similarity*
``s R`` of the ring (``R`` the Procrustes rotation of ``Q`` onto ``~Q`` via
:func:`~algorithms.deform.arap.procrustes_rotations`, ``s = tr(R Q ~Q^T) / ||Q||^2``), computed
online for the (few) regularized splits only. The thesis's plain Tikhonov pulls towards
``A_0 = 0`` instead, which shrinks every re-inserted vertex's offset along its ring's normal --
its detail -- at every level; measured on fandisk (CAD, flat faces, λ = 1, m = 2,000) the
largest edge stretch of the result was 1.71 with ``A_0 = 0`` and tikhonov 1e-2, and 1.23 / 1.18
/ 1.18 with the similarity prior and 1e-8 / 1e-6 / 1e-2 (direct full-resolution result 1.15,
no regularization 1.36: noise amplified by the near-singular fits). Properties (tested):

* identity, rotations, uniform scaling and translations of the coarse mesh are reproduced
  exactly on every mesh (the prior is then the map itself);
* general affine maps are reproduced exactly wherever no ring is flat to 1e-3 (no split
  regularized: bob, armadillo, spot, camelhead at the tested sizes, whose rings have
  ``s_min / s_max`` >= 1e-6); on meshes with flat regions (fandisk: 2,456 of 6,700 splits) a
  shear costs about 1.6e-5 of the diagonal there (0 with ``tikhonov = 0``).

Schedule: split ``k`` reads the current positions of ``c`` and ``N`` and writes ``i`` (= ``c``)
and ``j``. The splits are grouped into *waves* (a longest-path layering of the read/write
dependencies, in replay order: a split comes after every split that last wrote one of its
inputs, and not before a replay-earlier split that reads the value it overwrites); all splits of
a wave read first and then write, so each wave is a few NumPy operations. The result is
identical (to round-off) to replaying the splits one by one (tested). With Numba the replay
runs the splits one by one in compiled code (:mod:`.progressive_kernel`, ~5x faster and no
schedule to build); the waves are the fallback without it.

Steps (:meth:`ProgressiveCubic.steps`, :func:`progressive_cubic_iter`): mapping coarse positions
to the full mesh costs one replay (0.12-0.15 s CPU at 1.29M triangles, measured), more than a
coarse iteration, so the coarse iterations are streamed as full-resolution previews only every
``preview_every`` iterations (default 10; 0 = none): those Steps carry ``V`` = the replayed fine
positions of that coarse iterate and the coarse metrics. The last Step is always the
full-resolution result of the converged coarse run (its iteration number is the coarse run's
last; no earlier Step repeats it). :func:`progressive_cubic_iter` first yields an
``iteration = 0`` Step with the input positions once pre-processing is done (its message says
what the decimation did).

Finishing on every triangle (``ProgressiveParams.finish``, the product's default; issue 37):
after the replay, cubic stylization runs on the full mesh starting from the replayed result
(:meth:`CubicStylizer.steps` with ``initial``), with the plain λ (or painted λ) and the same
stopping rule, so the result minimizes the thesis's energy of the mesh the user gave. This is
the coarse-to-fine (cascadic) way of solving a local-global problem: the coarse solve carries
the large-scale deformation, which the full-resolution iterations propagate only slowly (their
relative move falls below the thesis's 3e-3 long before convergence on big meshes), and the
full-resolution iterations then flatten the details the copy cannot see, which converge fast.
Measured (``benchmarks/progressive_vs_full.py``; energies of the full mesh, lower is closer to
the minimum): igea (269k triangles) λ 0.1 / 0.2 / 0.5: 0.3149 / 0.6006 / 1.3787 in 27 / 21 / 11
full-resolution iterations, against 0.3149 / 0.6122 / 1.4608 in 217 / 177 / 135 iterations
from the input; the cold run needs about 250 and 400 iterations to reach the finished energies
at λ 0.2 and 0.5. The copy alone keeps its own cubeness (0.69-1.11 of the cold run's change
there), the finished result 0.94-1.30. It needs the full mesh's factorization (built once,
with the decimation, and kept for every λ), so it costs more memory than the copy alone.

Other choices:

* Constraints (``fixed``, ``handles``, ``coord_constraints``) are kept through the decimation
  (those vertices are never removed nor moved), so they act on the coarse mesh exactly and the
  replay leaves them where the coarse solve put them.
* Painted λ (``lam_per_vertex``, one value per input vertex) goes to the coarse mesh as the
  area-weighted mean over the input vertices merged into each coarse vertex.
* ``normalize`` / ``pin_one_vertex`` are the coarse stylizer's (see :mod:`.cubic`); the coarse
  mesh has nearly the same bounding box, so λ keeps its meaning.
* The faces are never changed: the output uses the input ``F``.

Speed (``benchmarks/progressive.py``, issue 25; rocker-arm Loop-subdivided 3x: 1.29M
triangles, m = 20,000, λ = 0.2; the shared 2-core machine was loaded 4-12, so CPU seconds are
the figures that carry, wall seconds were 2-4x more): pre-processing 28.7 s CPU (decimation
with recorded collapses 23.0 s in the compiled loop, split weights 5.5 s, cluster labels
0.01 s, coarse stylizer 0.13 s); online per λ 0.6-1.2 s CPU (coarse solve 0.5-1.1 s, 42-125
iterations; replay of the ~630k splits 0.12-0.15 s in the compiled sequential replay); PLY
write/read 0.02 s each; peak memory 1.45 GB (the mesh alone 0.28 GB). Peer in the same run,
stylizing every triangle: factorization 23.3 s CPU + 114 iterations 62.5 s CPU, peak 6.0 GB.
The online step is therefore ~86x faster than the direct run, and the whole progressive run
(pre-processing + one λ) 1.9x faster. Before issue 25 the Python collapse loop alone took
170 s wall at this size (loaded) and ~3 GB; the wave replay 0.3-0.5 s.

Resolution (measured, λ = 0.2): the replay keeps the coarse result's cubeness (the change of
the area-weighted mean L1 norm of the unit vertex normals on the full mesh equals the coarse
mesh's to ~0.001), so how cubic the result is depends on how the coarse solve compares with
the full-resolution one. Two cases were measured:

* meshes whose surface is smooth below the coarse resolution (subdivided, over-sampled): the
  plain λ matches. rocker-arm Loop x3 (1.29M -> 20k): change 0.114 against 0.112 stylizing
  every triangle (ratio 1.02); bob Loop x2 (171k -> 20k): 1.07.
* meshes detailed down to their own resolution (scans): stylizing every triangle also
  flattens the details that the coarse copy does not have, which the replay puts back as they
  were (the thesis's Fig. 5.17: m sets the level of detail kept), so the plain λ gives less
  change: rocker-arm 20k -> 5k 0.73 of the direct change, camelhead 0.67, armadillo 29k -> 7k
  0.37, armadillo Loop x1 (117k -> 20k) 0.62; the Stanford dragon scan (871k -> 20k) 0.48 in
  the issue's own figures.

``ProgressiveParams.lam_exponent`` (default 0: the thesis's λ) multiplies the coarse λ by
``(triangles / coarse triangles) ** exponent`` for the second case: 0.5 gave 1.06 (rocker-arm
20k), 1.00 (camelhead), 0.80 (armadillo 29k); about 0.22 matched armadillo Loop x1. It must
stay 0 for the first case (0.25 gave 1.47 on the 1.29M subdivided mesh), and no single value
fits both, so it is a setting, not automatic. Raising m keeps more of the change too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from ..mesh.decimate import STRATEGIES, Decimation, decimate
from ..mesh.operators import barycentric_vertex_areas
from ..params import param, validate_params
from ..steps import Step, run_to_end
from .arap import procrustes_rotations
from .cubic import CubicParams, CubicStylizer

__all__ = [
    "AUTO_PROGRESSIVE_FACES",
    "LAM_EXPONENT",
    "PROGRESSIVE_FASTER_FROM",
    "choose_progressive",
    "coarse_lambda_factor",
    "FINISH_MAX_FACES",
    "finish_allowed",
    "ProgressiveParams",
    "AffineSplits",
    "AffineProgressiveMesh",
    "ProgressiveCubic",
    "progressive_analogy_iter",
    "progressive_cubic_iter",
    "progressive_cubic",
]


#: Default exponent of the coarse λ correction (module docstring, "Resolution"): the coarse λ is
#: ``λ (m_fine / m_coarse) ** LAM_EXPONENT``; 0 (the thesis's plain λ) matched the full
#: result's cubeness within 2 % on a 1.29M-triangle subdivided mesh, 0.5 is closer on meshes
#: detailed down to their own resolution (measured there).
LAM_EXPONENT = 0.0


def coarse_lambda_factor(n_faces: int, n_coarse_faces: int, exponent: float) -> float:
    """The factor of λ on the coarse mesh: ``(n_faces / n_coarse_faces) ** exponent``."""
    if exponent == 0 or n_coarse_faces <= 0 or n_faces <= n_coarse_faces:
        return 1.0
    return float((n_faces / n_coarse_faces) ** exponent)


@dataclass(frozen=True)
class ProgressiveParams:
    """Parameters of affine progressive meshes (pre-processing; the cubic ones are separate)."""

    target_faces: int = param(
        20000, label="Coarse triangles (m)", minimum=4, maximum=100_000_000, step=1000,
        cli_aliases=("--coarse-faces",),
        tooltip="Triangles of the coarse mesh that is stylized; the details are then put back. "
                "Fewer run faster and keep details of a wider size range (the paper uses "
                "20,000). Must be below the mesh's own triangle count.")
    strategy: str = param(
        "qslim", label="Decimation", choices=STRATEGIES, advanced=True,
        tooltip="How the coarse mesh is made: qslim (quadric error, keeps the shape best) or "
                "midpoint (shortest edges first).")
    tikhonov: float = param(
        1e-6, label="Tikhonov weight", minimum=0.0, maximum=1.0, step=1e-8, decimals=12,
        log_scale=True, advanced=True,
        tooltip="Regularization of the affine fit at each vertex split, relative to the size of "
                "the vertex's neighbourhood. Only matters where the neighbourhood is flat; "
                "there the fit follows the neighbourhood's rotation and scale.")
    lam_exponent: float = param(
        LAM_EXPONENT, label="λ resolution correction", minimum=0.0, maximum=1.0, step=0.05,
        decimals=3, advanced=True,
        tooltip="The coarse copy is stiffer than the full mesh: at the same λ it comes out less "
                "cubic. Its λ is multiplied by (triangles / coarse triangles) to this power so "
                "that the result is about as cubic as stylizing every triangle. 0: the paper's "
                "plain λ (less cubic, keeps more detail).")
    finish: bool = param(
        True, label="Finish on every triangle",
        tooltip="After the copy is stylized and the details are put back, go on stylizing "
                "every triangle from there until it settles (the paper's stopping rule). "
                "Its energy was lower than working on every triangle from the start on 14 of "
                "20 runs measured on big meshes (at most 1 % higher on the others), in a "
                "fraction of the iterations. Off: only the copy is stylized, about a second "
                "per λ: a quick preview, which came out 0.4-1.3x as cubic as working on every "
                "triangle from the start on scans, and less than finished.")
    preview_every: int = param(
        10, label="Preview every", minimum=0, maximum=100000, step=1,
        tooltip="Show the full-resolution shape every this many coarse iterations while "
                "running (0: only the final result). Each preview costs one replay of the "
                "details.")


# ------------------------------------------------------------------------------ affine splits
def _next_involvement(dec: Decimation, verts: np.ndarray, after: np.ndarray):
    """For queries (vertex, collapse k): the first collapse k'' > k that involves the vertex.

    Returns
    -------
    nxt : (q,) int64, k'' or -1 (the vertex is a coarse vertex from level k+1 on).
    role : (q,) int64, 0 if the vertex is ``kept`` at k'', 1 if ``removed`` (undefined if -1).
    """
    K = len(dec)
    ev_v = np.concatenate([dec.kept, dec.removed])
    ev_k = np.concatenate([np.arange(K), np.arange(K)])
    ev_r = np.concatenate([np.zeros(K, np.int64), np.ones(K, np.int64)])
    key = ev_v * (K + 1) + ev_k
    o = np.argsort(key, kind="stable")
    key, ev_v, ev_k, ev_r = key[o], ev_v[o], ev_k[o], ev_r[o]
    q = verts * (K + 1) + after + 1
    pos = np.searchsorted(key, q, side="left")
    ok = pos < len(key)
    pos_c = np.minimum(pos, max(len(key) - 1, 0))
    ok &= ev_v[pos_c] == verts if len(key) else ok
    nxt = np.where(ok, ev_k[pos_c] if len(key) else -1, -1)
    role = np.where(ok, ev_r[pos_c] if len(key) else 0, 0)
    return nxt, role


class AffineSplits:
    """The affine vertex splits of a :class:`~algorithms.mesh.decimate.Decimation` (precomputed).

    Parameters
    ----------
    decimation : the recorded collapses.
    tikhonov : dimensionless Tikhonov weight (eigenvalues of ``Q Q^T`` below ``tikhonov * s_max``
        are lifted to it; module docstring).
    engine : "auto" (the compiled sequential replay when Numba is available) or "numpy" (the
        batched replay in waves of independent splits); both give the same positions to
        round-off (tested).

    Attributes
    ----------
    weights : (S, 2) float64, per ring entry (CSR of ``decimation.ring``) the weights of
        ``~p_n - ~p_c`` for the kept and the removed endpoint.
    regularized : (K,) bool, splits whose ring was flat enough for the Tikhonov term to act (their
        similarity prior is computed online).
    wave : (K,) int64, the batch (1-based) in which each split runs in the NumPy replay
        (computed on first use).
    n_waves : int.
    """

    def __init__(self, decimation: Decimation, tikhonov: float = 1e-6, *,
                 engine: str = "auto"):
        if not (tikhonov >= 0 and np.isfinite(tikhonov)):
            raise ParameterError("The Tikhonov weight must be a finite number >= 0.")
        if engine not in ("auto", "numpy"):
            raise ParameterError(f"Unknown replay engine {engine!r}; choose auto or numpy.")
        self.engine = engine
        dec = decimation
        self.decimation = dec
        self.tikhonov = float(tikhonov)
        K = len(dec)
        self.K = K
        ptr = dec.ring_ptr
        cnt = np.diff(ptr)
        if K and cnt.min() < 1:
            raise InvalidMeshError("A recorded collapse has an empty 1-ring; the decimation "
                                   "record is inconsistent.")
        split_of = np.repeat(np.arange(K), cnt)  # split of every ring entry
        ring = dec.ring
        # producers (next involvement after k, i.e. the split that last wrote the value) and
        # rest positions at level k + 1
        prod, role = _next_involvement(dec, ring, split_of)
        cprod, crole = _next_involvement(dec, dec.kept, np.arange(K))
        f2c = dec.fine_to_coarse
        rest = np.empty((len(ring), 3))
        coarse = prod < 0
        rest[coarse] = dec.V[f2c[ring[coarse]]]
        kp = ~coarse & (role == 0)
        rm = ~coarse & (role == 1)
        rest[kp] = dec.kept_position[prod[kp]]
        rest[rm] = dec.removed_position[prod[rm]]
        # weights
        q = rest - dec.merged_position[split_of]
        M = np.zeros((K, 9))
        if K:
            M = np.add.reduceat((q[:, :, None] * q[:, None, :]).reshape(-1, 9), ptr[:-1], axis=0)
        M = M.reshape(K, 3, 3)
        D = np.stack([dec.kept_position - dec.merged_position,
                      dec.removed_position - dec.merged_position], axis=2)  # (K, 3, 2)
        Y, G, self.regularized = _regularized_solve(M, D, self.tikhonov)
        self.weights = np.einsum("ea,eab->eb", q, Y[split_of]) if K else np.zeros((0, 2))
        # the similarity prior of the regularized splits: their rest ring vectors and the
        # offsets G D = E (Q Q^T + E)^-1 D that the prior's map multiplies
        reg_ids = np.flatnonzero(self.regularized)
        self._reg_index = np.full(K, -1, dtype=np.int64)
        self._reg_index[reg_ids] = np.arange(len(reg_ids))
        self._reg_g = G[reg_ids]  # (nr, 3, 2)
        self._reg_q = [q[ptr[k]:ptr[k + 1]] for k in reg_ids]
        self._reg_q_flat = (np.concatenate(self._reg_q) if len(reg_ids)
                            else np.zeros((0, 3)))
        self._reg_q_ptr = np.concatenate(
            [[0], np.cumsum([len(x) for x in self._reg_q])]).astype(np.int64)
        self._prod, self._cprod = prod, cprod
        self._wave = None  # the wave schedule, built on first use (NumPy replay only)

    @property
    def wave(self) -> np.ndarray:
        """(K,) int64, the batch (1-based) in which each split runs in the NumPy replay."""
        self._schedule()
        return self._wave

    @property
    def n_waves(self) -> int:
        """Number of batches of the NumPy replay."""
        self._schedule()
        return self._n_waves

    def _schedule(self) -> None:
        """The waves of independent splits and the per-wave arrays of the NumPy replay (the
        compiled replay does not need them)."""
        if self._wave is not None:
            return
        dec, K = self.decimation, self.K
        ptr, ring = dec.ring_ptr, dec.ring
        cnt = np.diff(ptr)
        self._wave = _waves(dec, ring, ptr, self._prod, self._cprod)
        self._n_waves = int(self._wave.max()) if K else 0
        order = np.argsort(self._wave, kind="stable")
        self._order = order
        bounds = np.searchsorted(self._wave[order], np.arange(1, self._n_waves + 2))
        self._wave_bounds = bounds
        # ring entries regrouped by wave
        seg_len = cnt[order]
        ent = np.zeros(0, np.int64)
        if K:
            starts = np.repeat(ptr[order], seg_len)
            local = np.arange(len(ring)) - np.repeat(np.cumsum(seg_len) - seg_len, seg_len)
            ent = starts + local
        self._ent_vertex = ring[ent]
        self._ent_w = self.weights[ent]
        self._ent_ptr = np.concatenate([[0], np.cumsum(seg_len)])
        self._kept = dec.kept[order]
        self._removed = dec.removed[order]
        # per wave: the regularized splits (position in the wave), their entries and prior data
        rs_local, re_rel, rq, rg, rs_ptr, re_ptr = [], [], [], [], [0], [0]
        for w in range(self._n_waves):
            s0, s1 = bounds[w], bounds[w + 1]
            loc = np.flatnonzero(self.regularized[order[s0:s1]])
            for t in loc:
                k = order[s0 + t]
                r = self._reg_index[k]
                a, b = self._ent_ptr[s0 + t], self._ent_ptr[s0 + t + 1]
                re_rel.append(np.arange(a, b) - self._ent_ptr[s0])
                rq.append(self._reg_q[r])
                rg.append(self._reg_g[r])
            rs_local.append(loc)
            rs_ptr.append(rs_ptr[-1] + len(loc))
            re_ptr.append(re_ptr[-1] + int(sum(len(x) for x in re_rel[len(re_rel) - len(loc):])
                                           if len(loc) else 0))
        self._rs_local = np.concatenate(rs_local) if rs_local else np.zeros(0, np.int64)
        self._re_rel = np.concatenate(re_rel) if re_rel else np.zeros(0, np.int64)
        self._re_len = np.array([len(x) for x in re_rel], dtype=np.int64)
        self._rq = np.concatenate(rq) if rq else np.zeros((0, 3))
        self._rg = np.stack(rg) if rg else np.zeros((0, 3, 2))
        self._rs_ptr = np.array(rs_ptr, dtype=np.int64)
        self._re_ptr = np.array(re_ptr, dtype=np.int64)

    def apply(self, coarse_positions) -> np.ndarray:
        """Replay every split with its affine map, starting from deformed coarse positions.

        Parameters
        ----------
        coarse_positions : (nc, 3) float, positions of the coarse vertices
            (``decimation.V`` order).

        Returns
        -------
        (n_fine, 3) float64 positions of the input mesh's vertices.
        """
        dec = self.decimation
        Pc = np.asarray(coarse_positions, dtype=np.float64)
        if Pc.shape != dec.V.shape:
            raise ParameterError(f"The coarse positions must have shape {dec.V.shape}, got "
                                 f"{Pc.shape}.")
        P = np.empty((dec.n_fine, 3))
        P[dec.coarse_to_fine] = Pc
        kernel = _compiled_replay() if self.engine != "numpy" else None
        if kernel is not None:
            return kernel(P, dec.kept, dec.removed, dec.ring_ptr, dec.ring, self.weights,
                          self._reg_index, self._reg_q_flat, self._reg_q_ptr,
                          np.ascontiguousarray(self._reg_g))
        self._schedule()
        b, ep = self._wave_bounds, self._ent_ptr
        kept, removed, ev, ew = self._kept, self._removed, self._ent_vertex, self._ent_w
        for w in range(self._n_waves):
            s0, s1 = b[w], b[w + 1]
            e0, e1 = ep[s0], ep[s1]
            c = kept[s0:s1]
            pc = P[c]
            cnt = np.diff(ep[s0:s1 + 1])
            diff = P[ev[e0:e1]] - np.repeat(pc, cnt, axis=0)
            ww = ew[e0:e1]
            starts = ep[s0:s1] - e0
            sk = np.add.reduceat(diff * ww[:, 0:1], starts, axis=0)
            sr = np.add.reduceat(diff * ww[:, 1:2], starts, axis=0)
            r0, r1 = self._rs_ptr[w], self._rs_ptr[w + 1]
            if r1 > r0:
                q0, q1 = self._re_ptr[w], self._re_ptr[w + 1]
                lens = self._re_len[r0:r1]
                seg = np.concatenate([[0], np.cumsum(lens)[:-1]])
                add = _similarity_offsets(self._rq[q0:q1], diff[self._re_rel[q0:q1]], seg,
                                          self._rg[r0:r1])
                loc = self._rs_local[r0:r1]
                sk[loc] += add[:, :, 0]
                sr[loc] += add[:, :, 1]
            P[removed[s0:s1]] = pc + sr
            P[c] = pc + sk
        return P

    def apply_sequential(self, coarse_positions) -> np.ndarray:
        """The same replay, one split at a time through
        :meth:`~algorithms.mesh.decimate.Decimation.replay` (slow; the reference)."""
        dec = self.decimation
        W, ptr = self.weights, dec.ring_ptr

        def fn(rec, P):
            k = rec.index
            pc = P[rec.kept]
            diff = P[rec.ring] - pc
            w = W[ptr[k]:ptr[k + 1]]
            pk, pr = pc + w[:, 0] @ diff, pc + w[:, 1] @ diff
            r = self._reg_index[k]
            if r >= 0:
                add = _similarity_offsets(self._reg_q[r], diff, np.zeros(1, np.int64),
                                          self._reg_g[r:r + 1])[0]
                pk, pr = pk + add[:, 0], pr + add[:, 1]
            return pk, pr

        return dec.replay(coarse_positions, fn)[0]


_KERNEL = None  # the algorithms.compiled.KernelModule of progressive_kernel, made on first use


def _compiled_replay():
    """The compiled replay (:mod:`algorithms.deform.progressive_kernel`), or None when Numba is
    missing or switched off (``STYLIZE3D_NUMBA=0``; :mod:`algorithms.compiled`)."""
    global _KERNEL
    if _KERNEL is None:
        from ..compiled import KernelModule

        _KERNEL = KernelModule("algorithms.deform.progressive_kernel")
    module = _KERNEL.get()
    return None if module is None else module.replay_splits


def _regularized_solve(M: np.ndarray, D: np.ndarray, tikhonov: float):
    """Solve the Tikhonov-regularized normal equations of the affine fits (module docstring).

    Parameters
    ----------
    M : (K, 3, 3) symmetric PSD ``Q Q^T``.
    D : (K, 3, r) right-hand sides (rest offsets of the endpoints).
    tikhonov : dimensionless weight.

    Returns
    -------
    Y : (K, 3, r) ``(M + E)^-1 D`` with ``E = U diag(max(s, tikhonov s_max) - s) U^T``.
    G : (K, 3, r) ``E (M + E)^-1 D`` (zero where ``E = 0``).
    regularized : (K,) bool, where ``E != 0``.
    """
    K = len(M)
    if K == 0:
        return np.zeros(D.shape), np.zeros(D.shape), np.zeros(0, dtype=bool)
    s, U = np.linalg.eigh(M)
    s = np.maximum(s, 0.0)
    floor = tikhonov * s[:, 2:3]
    s_reg = np.maximum(s, floor)
    reg = (s < floor).any(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(s_reg > 0, 1.0 / s_reg, 0.0)  # all-zero rings (never on a valid mesh)
        frac = np.where(s_reg > 0, (s_reg - s) / s_reg, 0.0)
    UtD = np.matmul(U.transpose(0, 2, 1), D)
    Y = np.matmul(U, inv[:, :, None] * UtD)
    G = np.matmul(U, frac[:, :, None] * UtD)
    G[~reg] = 0.0
    return Y, G, reg


def _similarity_offsets(q_rest: np.ndarray, q_def: np.ndarray, starts: np.ndarray,
                        g: np.ndarray) -> np.ndarray:
    """``s R g`` per regularized split: ``s R`` the least-squares similarity ring -> deformed ring.

    Parameters
    ----------
    q_rest, q_def : (E, 3) rest and deformed ring vectors of the splits, concatenated.
    starts : (r,) first entry of each split.
    g : (r, 3, 2) the offsets ``E (Q Q^T + E)^-1 D``.

    Returns
    -------
    (r, 3, 2) float64.
    """
    S = np.add.reduceat((q_rest[:, :, None] * q_def[:, None, :]).reshape(-1, 9), starts,
                        axis=0).reshape(-1, 3, 3)  # sum q q~^T
    R = procrustes_rotations(S)  # maximizes tr(R S) = sum q~ . R q
    nrm = np.add.reduceat((q_rest ** 2).sum(axis=1), starts)
    scale = np.einsum("kab,kba->k", R, S) / np.where(nrm > 0, nrm, 1.0)
    return scale[:, None, None] * np.matmul(R, g)


def _waves(dec: Decimation, ring, ptr, prod, cprod) -> np.ndarray:
    """Longest-path layering of the split dependencies in replay order (module docstring)."""
    K = len(dec)
    wave = [0] * K
    readmax = {}
    kept = dec.kept.tolist()
    removed = dec.removed.tolist()
    ring_l = ring.tolist()
    prod_l = prod.tolist()
    cprod_l = cprod.tolist()
    ptr_l = ptr.tolist()
    for k in range(K - 1, -1, -1):
        c = kept[k]
        p = cprod_l[k]
        w = wave[p] if p >= 0 else 0
        a, b = ptr_l[k], ptr_l[k + 1]
        for e in range(a, b):
            p = prod_l[e]
            if p >= 0:
                pw = wave[p]
                if pw > w:
                    w = pw
        w += 1
        r = readmax.get(c, 0)
        if r > w:
            w = r
        for e in range(a, b):
            x = ring_l[e]
            if readmax.get(x, 0) < w:
                readmax[x] = w
        readmax[c] = 0
        readmax[removed[k]] = 0
        wave[k] = w
    return np.array(wave, dtype=np.int64)


# ------------------------------------------------------------------------------ driver
def _constraint_vertices(n: int, fixed, handles, coord_constraints):
    """Validate the constraints (the stylizer re-checks them) and return the vertices they use."""
    used = []
    if fixed is not None:
        used.append(np.asarray(fixed, dtype=np.int64).reshape(-1))
    if handles is not None:
        idx, _ = handles
        used.append(np.asarray(idx, dtype=np.int64).reshape(-1))
    if coord_constraints is not None:
        used.append(np.asarray(coord_constraints[0], dtype=np.int64).reshape(-1))
    ids = np.unique(np.concatenate(used)) if used else np.zeros(0, np.int64)
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ParameterError(f"Some constrained vertices do not exist (the mesh has {n} "
                             f"vertices).")
    return ids


#: Above this many triangles the app and the CLI stylize through affine progressive meshes,
#: finished on every triangle (``ProgressiveParams.finish``), unless told not to. The copy alone
#: (``benchmarks/progressive.py --sweep``, one λ, the whole run) was faster than working on
#: every triangle from 42,752 triangles on (bob Loop x1: 1.6x wall) through 117k (5.0x) to
#: 1.29M (2.9x CPU), but less cubic on scans (0.42-1.27 of the cubeness change). Finished
#: (``benchmarks/progressive_vs_full.py``, issue 37): at 117k-124k triangles the first λ took
#: 0.59-0.82x the time of working on every triangle from the start (bob Loop x2 at 171k:
#: 0.75-0.95x), at energies 5.0 % lower to 0.31 % higher; at 269k-1.29M triangles 0.52-1.12x,
#: at energies 7.7 % lower to 0.9 % higher (lower on 14 of all 20 runs); every further λ
#: 0.07-0.4x. The threshold keeps the coarse copy at most a fifth of the mesh.
PROGRESSIVE_FASTER_FROM = 42_752
AUTO_PROGRESSIVE_FACES = 100_000


#: Above this many triangles progressive meshes are not finished on every triangle, whatever
#: ``ProgressiveParams.finish`` says (the copy alone, said in the output): the finish needs the
#: full mesh's factorization, measured at 1.87 GB peak for 1,285,632 triangles (rocker-arm Loop
#: x3, the whole process; 2.74 GB before the ARAP set-up summed per triangle), about 1.5 kB
#: per triangle, so 3M triangles need about 4.4 GB, and a bigger mesh could exhaust a
#: desktop's memory (the system then kills the app: lost work).
FINISH_MAX_FACES = 3_000_000
#: Measured peak bytes per triangle of the finished path (see :data:`FINISH_MAX_FACES`).
FINISH_BYTES_PER_FACE = 1_460


def finish_allowed(n_faces: int) -> tuple[bool, str]:
    """Whether a mesh of ``n_faces`` triangles may be finished on every triangle
    (:data:`FINISH_MAX_FACES`), and, when not, why (a sentence for the user)."""
    if n_faces <= FINISH_MAX_FACES:
        return True, ""
    need = FINISH_BYTES_PER_FACE * n_faces / 1e9
    return False, (f"not finished on every triangle: this mesh has {n_faces:,} triangles, more "
                   f"than {FINISH_MAX_FACES:,}, and finishing would need about {need:.0f} GB "
                   f"of memory; the copy alone was stylized (less cubic: raise λ, or simplify "
                   f"the mesh below {FINISH_MAX_FACES:,} triangles to finish it)")


def choose_progressive(n_faces: int, target_faces: int | None = None) -> tuple[bool, str]:
    """Whether a mesh of ``n_faces`` triangles is stylized through progressive meshes by
    default, and why (a sentence for the user).

    The rule (measured, see :data:`AUTO_PROGRESSIVE_FACES`): progressive meshes, finished on
    every triangle (``ProgressiveParams.finish``), above ``AUTO_PROGRESSIVE_FACES`` triangles,
    where they reached a lower energy than working on every triangle from the start on 14 of
    20 runs measured (at most 0.9 % higher on the others), in a fraction of its iterations;
    below, every triangle from the start.
    """
    m = ProgressiveParams().target_faces if target_faces is None else int(target_faces)
    if n_faces > AUTO_PROGRESSIVE_FACES:
        return True, (f"this mesh has {n_faces:,} triangles, more than "
                      f"{AUTO_PROGRESSIVE_FACES:,}: from there on, stylizing a {m:,}-triangle "
                      f"copy, putting the details back (affine progressive meshes) and then "
                      f"finishing on every triangle from there reached a lower energy than "
                      f"working on every triangle from the start on 14 of 20 runs measured "
                      f"on big meshes (at most 1 % higher on the others), in fewer iterations")
    return False, (f"this mesh has {n_faces:,} triangles, not more than "
                   f"{AUTO_PROGRESSIVE_FACES:,}: working on every triangle from the start "
                   f"converges well at this size")


class AffineProgressiveMesh:
    """An affine progressive mesh (thesis §5.3.2): a recorded decimation and its affine splits.

    The deformation-independent half of Alg. 4, shared by every method that deforms a coarse
    mesh and puts the details back (cubic stylization, shape analogies): construct once, deform
    :attr:`V_coarse`, then :meth:`prolong` the coarse positions to the input mesh.

    Parameters
    ----------
    V : (n, 3) float64 input positions.
    F : (m, 3) int64 triangles (manifold; never changed).
    target_faces : int, triangles of the coarse mesh (``m`` of Alg. 4), below ``len(F)``.
    strategy : decimation strategy ("qslim" or "midpoint").
    tikhonov : dimensionless Tikhonov weight of the affine fits (module docstring).
    keep : (k,) int, optional, input vertices never removed nor moved by the decimation.
    what : str, the method's name for error messages.

    Attributes
    ----------
    decimation : :class:`~algorithms.mesh.decimate.Decimation`; ``V_coarse``, ``F_coarse``.
    splits : :class:`AffineSplits`.
    clusters : (n,) int64, the coarse vertex each input vertex was merged into.
    timings : dict of pre-processing seconds: ``decimate``, ``splits``, ``total`` (subclasses
        add their own).
    notes : plain-language remarks (e.g. the decimation stopped early).
    """

    def __init__(self, V, F, *, target_faces: int = 20000, strategy: str = "qslim",
                 tikhonov: float = 1e-6, keep=None, what: str = "Cubic stylization"):
        t0 = time.perf_counter()
        V = np.array(V, dtype=np.float64, copy=True)
        F = np.asarray(F)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise InvalidMeshError(f"{what} needs a triangle mesh with at least one triangle.")
        F = np.ascontiguousarray(F, dtype=np.int64)
        if not (tikhonov >= 0 and np.isfinite(tikhonov)):
            raise ParameterError("The Tikhonov weight must be a finite number >= 0.")
        self.V, self.F, self.n = V, F, len(V)
        self.decimation = dec = decimate(V, F, target_faces, strategy=strategy, keep=keep)
        t1 = time.perf_counter()
        self.splits = AffineSplits(dec, tikhonov)
        t2 = time.perf_counter()
        self.clusters = dec.clusters()
        dec.drop_records()   # the splits replay from the rings alone (0.18 GB at 1.3M)
        area = barycentric_vertex_areas(V, F)
        self._cluster_area = np.bincount(self.clusters, weights=area, minlength=len(dec.V))
        self._area = area
        self.timings = {"decimate": t1 - t0, "splits": t2 - t1,
                        "total": time.perf_counter() - t0}
        self.notes = list(dec.notes)

    @property
    def V_coarse(self) -> np.ndarray:
        """(nc, 3) positions of the coarse mesh."""
        return self.decimation.V

    @property
    def F_coarse(self) -> np.ndarray:
        """(mc, 3) triangles of the coarse mesh."""
        return self.decimation.F

    @property
    def n_coarse_faces(self) -> int:
        """Triangles of the coarse mesh."""
        return len(self.decimation.F)

    def coarse_lambda(self, lam_per_vertex) -> np.ndarray:
        """Per-vertex λ (n,) of the input mapped to the coarse mesh (nc,) (area-weighted means)."""
        lam = np.asarray(lam_per_vertex, dtype=np.float64).reshape(-1)
        if lam.shape != (self.n,):
            raise ParameterError(f"Per-vertex λ needs one value per vertex ({self.n}), got "
                                 f"{lam.size}.")
        if (lam < 0).any() or not np.isfinite(lam).all():
            raise ParameterError("Per-vertex λ must be finite and non-negative.")
        nc = len(self.decimation.V)
        num = np.bincount(self.clusters, weights=lam * self._area, minlength=nc)
        cnt = np.bincount(self.clusters, weights=lam, minlength=nc)
        size = np.bincount(self.clusters, minlength=nc)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(self._cluster_area > 0, num / self._cluster_area,
                           cnt / np.maximum(size, 1))
        return out

    def coarse_ids(self, ids) -> np.ndarray | None:
        """Input vertex ids (kept by the decimation, e.g. constraints) as coarse vertex ids."""
        if ids is None:
            return None
        return self.decimation.fine_to_coarse[np.asarray(ids, dtype=np.int64).reshape(-1)]

    def prolong(self, coarse_positions) -> np.ndarray:
        """Affine vertex splits (Alg. 4 line 7): coarse positions (nc, 3) -> input ones (n, 3)."""
        return self.splits.apply(coarse_positions)

    def prolonged_steps(self, coarse_steps: Iterator[Step], preview_every: int = 10
                        ) -> Iterator[Step]:
        """Full-resolution Steps of a run on the coarse mesh (module docstring, "Steps").

        ``coarse_steps`` yields Steps with coarse positions ``V`` (nc, 3); this yields a
        full-resolution preview every ``preview_every`` coarse iterations (0: none), then the
        final prolonged result with ``replay_seconds`` added to its metrics.
        """
        prev = None
        for st in coarse_steps:
            if prev is not None and preview_every and prev.iteration % preview_every == 0:
                yield Step(iteration=prev.iteration, total=prev.total,
                           V=self.prolong(prev.V), metrics=dict(prev.metrics),
                           message=f"coarse {prev.message} (full-resolution preview)")
            prev = st
        if prev is None:
            return
        t = time.perf_counter()
        Vf = self.prolong(prev.V)
        metrics = dict(prev.metrics)
        metrics["replay_seconds"] = time.perf_counter() - t
        yield Step(iteration=prev.iteration, total=prev.total, V=Vf, metrics=metrics,
                   message=f"converged after {prev.iteration} coarse iterations on "
                           f"{self.n_coarse_faces:,} triangles; details restored on "
                           f"{len(self.F):,} triangles")

    def finished_steps(self, coarse_steps: Iterator[Step], preview_every: int,
                       finish: Callable[[np.ndarray], Iterator[Step]] | None) -> Iterator[Step]:
        """:meth:`prolonged_steps`, then, with ``finish``, the run on every triangle started
        from the prolonged result (module docstring, "Finishing on every triangle").

        ``finish(V_start)`` yields the full-resolution Steps (iterations counted from 1); they
        are yielded numbered after the coarse iterations, with ``coarse_iterations``,
        ``fine_iterations`` and ``replay_seconds`` added to their metrics. Without ``finish``
        this is :meth:`prolonged_steps`.
        """
        if finish is None:
            yield from self.prolonged_steps(coarse_steps, preview_every)
            return
        last = None
        for st in self.prolonged_steps(coarse_steps, preview_every):
            if last is not None:
                yield last
            last = st
        if last is None:
            return
        coarse_its = last.iteration
        replay = last.metrics.get("replay_seconds")
        yield Step(iteration=coarse_its, total=None, V=last.V, metrics=dict(last.metrics),
                   message=f"{last.message}; finishing on every triangle")
        for st in finish(last.V):
            metrics = dict(st.metrics)
            metrics.update(coarse_iterations=float(coarse_its),
                           fine_iterations=float(st.iteration))
            if replay is not None:
                metrics["replay_seconds"] = replay
            yield Step(iteration=coarse_its + st.iteration, total=None, V=st.V,
                       metrics=metrics, message=f"on every triangle, {st.message}")


class ProgressiveCubic(AffineProgressiveMesh):
    """Cubic stylization through an affine progressive mesh (thesis Alg. 4), precomputed once.

    Construction does the pre-processing (decimation, split weights and schedule, the coarse
    stylizer's factorizations); :meth:`stylize` / :meth:`steps` then run for any λ, style,
    orientation or painted λ without redoing it.

    Parameters
    ----------
    V : (n, 3) float64 input positions.
    F : (m, 3) int64 triangles (manifold; never changed).
    target_faces : int, triangles of the coarse mesh (``m`` of Alg. 4), below ``len(F)``.
    strategy : decimation strategy ("qslim" or "midpoint").
    tikhonov : dimensionless Tikhonov weight of the affine fits (module docstring).
    fixed, handles, coord_constraints : as :class:`~algorithms.deform.cubic.CubicStylizer`, in
        input vertex ids; these vertices are kept in the coarse mesh.
    normalize, pin_one_vertex, backend : passed to the coarse CubicStylizer.

    Attributes
    ----------
    decimation, splits, clusters, notes : see :class:`AffineProgressiveMesh`.
    stylizer : the coarse :class:`~algorithms.deform.cubic.CubicStylizer`.
    timings : dict of pre-processing seconds: ``decimate``, ``splits``, ``stylizer``, ``total``.
    """

    def __init__(self, V, F, *, target_faces: int = 20000, strategy: str = "qslim",
                 tikhonov: float = 1e-6, fixed=None, handles=None, coord_constraints=None,
                 normalize: bool = True, pin_one_vertex: bool = True, backend: str = "auto",
                 finish: bool = False):
        n = len(V) if np.ndim(V) == 2 else 0
        keep = _constraint_vertices(n, fixed, handles, coord_constraints)
        super().__init__(V, F, target_faces=target_faces, strategy=strategy, tikhonov=tikhonov,
                         keep=keep, what="Cubic stylization")
        dec = self.decimation
        t2 = time.perf_counter()
        c_handles = None if handles is None else (self.coarse_ids(handles[0]), handles[1])
        c_coord = None
        if coord_constraints is not None:
            ci, ca, cv = coord_constraints
            c_coord = (self.coarse_ids(ci), ca, cv)
        self.stylizer = CubicStylizer(dec.V, dec.F, fixed=self.coarse_ids(fixed),
                                      handles=c_handles, coord_constraints=c_coord,
                                      normalize=normalize,
                                      pin_one_vertex=pin_one_vertex, backend=backend)
        self.timings["stylizer"] = time.perf_counter() - t2
        self.timings["total"] += self.timings["stylizer"]
        self._fine_args = dict(fixed=fixed, handles=handles, coord_constraints=coord_constraints,
                               normalize=normalize, pin_one_vertex=pin_one_vertex,
                               backend=backend)
        self._fine: CubicStylizer | None = None
        if finish:
            self.fine_stylizer()

    def fine_stylizer(self) -> CubicStylizer:
        """The :class:`~algorithms.deform.cubic.CubicStylizer` of the input mesh that finishes
        on every triangle (built on first use, with the same constraints; its seconds are added
        to ``timings`` as ``fine_stylizer``)."""
        if self._fine is None:
            t = time.perf_counter()
            self._fine = CubicStylizer(self.V, self.F, **self._fine_args)
            self.timings["fine_stylizer"] = time.perf_counter() - t
            self.timings["total"] += self.timings["fine_stylizer"]
        return self._fine

    def lam_factor(self, lam_exponent: float = LAM_EXPONENT) -> float:
        """The factor of λ on the coarse mesh (:func:`coarse_lambda_factor`)."""
        return coarse_lambda_factor(len(self.F), self.n_coarse_faces, lam_exponent)

    def _coarse_lam(self, params: CubicParams, lam_per_vertex, lam_exponent: float):
        """Per-coarse-vertex λ (or None: ``params.lam`` as it is)."""
        if not (lam_exponent >= 0 and np.isfinite(lam_exponent)):
            raise ParameterError("The λ resolution correction must be a number >= 0.")
        factor = self.lam_factor(lam_exponent)
        if lam_per_vertex is None:
            if factor == 1.0:
                return None
            return np.full(len(self.decimation.V), float(params.lam) * factor)
        return self.coarse_lambda(lam_per_vertex) * factor

    def steps(self, params: CubicParams = CubicParams(), *, lam_per_vertex=None, lam_axes=None,
              rotation=None, style_matrix=None, preview_every: int = 10,
              lam_exponent: float = LAM_EXPONENT, finish: bool = False) -> Iterator[Step]:
        """Stylize the coarse mesh and replay the splits, as Steps (module docstring).

        Parameters
        ----------
        params : CubicParams.
        lam_per_vertex : (n,) float, optional, painted λ on the input mesh.
        lam_axes, rotation, style_matrix : as :meth:`CubicStylizer.steps`.
        preview_every : int, yield a full-resolution preview every this many coarse iterations
            (0: only the final Step).
        lam_exponent : float, λ (and painted λ) on the coarse mesh is multiplied by
            ``(triangles / coarse triangles) ** lam_exponent`` (module docstring,
            "Resolution"; 0: the thesis's plain λ).
        finish : bool, then run cubic stylization on every triangle from the result (with
            ``params`` and the plain λ / painted λ, to ``params``' stopping rule; module
            docstring, "Finishing on every triangle").

        Yields
        ------
        Step with ``V`` (n, 3): previews, then the final full-resolution result. ``metrics``
        are the coarse run's (``energy``, ``arap``, ``l1``, ``displacement``, ...) plus
        ``replay_seconds`` on the final Step; with ``finish``, the prolonged result and then
        one Step per full-resolution iteration (their metrics are the full mesh's, plus
        ``coarse_iterations``, ``fine_iterations`` and ``replay_seconds``).
        """
        validate_params(params)
        preview_every = int(preview_every)
        if preview_every < 0:
            raise ParameterError("'Preview every' must be 0 or a positive number of iterations.")
        lam_c = self._coarse_lam(params, lam_per_vertex, lam_exponent)
        fine = None
        if finish:
            stylizer = self.fine_stylizer()

            def fine(V_start):
                return stylizer.steps(params, lam_per_vertex=lam_per_vertex, lam_axes=lam_axes,
                                      rotation=rotation, style_matrix=style_matrix,
                                      initial=V_start)
        yield from self.finished_steps(
            self.stylizer.steps(params, lam_per_vertex=lam_c, lam_axes=lam_axes,
                                rotation=rotation, style_matrix=style_matrix), preview_every,
            fine)

    def stylize(self, params: CubicParams = CubicParams(), *, lam_per_vertex=None,
                lam_axes=None, rotation=None, style_matrix=None,
                callback: Callable[[Step], None] | None = None,
                lam_exponent: float = LAM_EXPONENT, finish: bool = False) -> np.ndarray:
        """Run :meth:`steps` to the end (no previews) and return the (n, 3) stylized positions.

        ``callback(step)`` receives every coarse iteration's Step (coarse positions,
        ``V`` (nc, 3)), then the full-resolution Step with the details restored, then (with
        ``finish``) every full-resolution iteration's Step.
        """
        validate_params(params)
        lam_c = self._coarse_lam(params, lam_per_vertex, lam_exponent)
        last = run_to_end(self.stylizer.steps(params, lam_per_vertex=lam_c, lam_axes=lam_axes,
                                              rotation=rotation, style_matrix=style_matrix),
                          callback)
        Vf = self.prolong(last.V)
        if callback is not None:
            callback(Step(iteration=last.iteration, total=last.total, V=Vf,
                          metrics=dict(last.metrics), message="details restored"))
        if finish:
            Vf = run_to_end(self.fine_stylizer().steps(
                params, lam_per_vertex=lam_per_vertex, lam_axes=lam_axes, rotation=rotation,
                style_matrix=style_matrix, initial=Vf), callback).V
        return Vf


def progressive_cubic_iter(V, F, params: CubicParams = CubicParams(),
                           progressive: ProgressiveParams = ProgressiveParams(), *,
                           lam_per_vertex=None, lam_axes=None, fixed=None, handles=None,
                           coord_constraints=None, rotation=None,
                           style_matrix=None) -> Iterator[Step]:
    """Fast cubic stylization (thesis Alg. 4) as Steps.

    Parameters
    ----------
    V : (n, 3) float64 input positions (not modified).
    F : (m, 3) int64 triangles (the output uses the same F).
    params : CubicParams (λ, style, ADMM settings, stopping).
    progressive : ProgressiveParams (coarse triangle count, decimation, Tikhonov, previews).
    lam_per_vertex, lam_axes, fixed, handles, coord_constraints, rotation, style_matrix : as
        :func:`~algorithms.deform.cubic.cubic_stylization_iter` (input vertex ids).

    Yields
    ------
    Step: ``iteration = 0`` with the input positions once pre-processing is done, then
    full-resolution previews every ``progressive.preview_every`` coarse iterations, then the
    copy's result put back, then (``progressive.finish``, the default) one Step per iteration
    on every triangle (see :meth:`ProgressiveCubic.steps`).
    """
    validate_params(params)
    validate_params(progressive)
    pc = ProgressiveCubic(V, F, target_faces=progressive.target_faces,
                          strategy=progressive.strategy, tikhonov=progressive.tikhonov,
                          fixed=fixed, handles=handles, coord_constraints=coord_constraints,
                          normalize=params.normalize, pin_one_vertex=params.pin_one_vertex,
                          finish=progressive.finish)
    msg = (f"pre-processing done in {pc.timings['total']:.1f} s: {len(pc.F):,} -> "
           f"{pc.n_coarse_faces:,} triangles")
    if pc.notes:
        msg += ". " + " ".join(pc.notes)
    yield Step(iteration=0, total=None, V=pc.V.copy(),
               metrics={"preprocess_seconds": pc.timings["total"]}, message=msg)
    yield from pc.steps(params, lam_per_vertex=lam_per_vertex, lam_axes=lam_axes,
                        rotation=rotation, style_matrix=style_matrix,
                        preview_every=progressive.preview_every,
                        lam_exponent=progressive.lam_exponent, finish=progressive.finish)


def progressive_cubic(V, F, params: CubicParams = CubicParams(),
                      progressive: ProgressiveParams = ProgressiveParams(), **kwargs) -> np.ndarray:
    """Run :func:`progressive_cubic_iter` to the end and return the (n, 3) stylized positions."""
    return run_to_end(progressive_cubic_iter(V, F, params, progressive, **kwargs)).V


def progressive_analogy_iter(V, F, target_map, params=None,
                             progressive: ProgressiveParams = ProgressiveParams(), *,
                             fixed=None, handles=None, lam_per_vertex=None) -> Iterator[Step]:
    """Normal-driven shape analogy (thesis ch. 6) of a big mesh through an affine progressive mesh.

    The thesis introduces affine progressive meshes for cubic stylization (§5.3.2, Alg. 4); shape
    analogies run on the same local-global ARAP core, so the same pre-processing applies: the
    analogy runs on the decimated mesh (fixed and handle vertices are kept by the decimation),
    then the affine vertex splits put the details back. Painted λ goes to the coarse mesh as
    area-weighted cluster means, as for cubic stylization.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64, the input mesh (the output uses the same F).
    target_map : the style (see :class:`~algorithms.deform.analogies.ShapeAnalogy`).
    params : AnalogyParams (default: the thesis's).
    progressive : ProgressiveParams.
    fixed, handles, lam_per_vertex : as :class:`~algorithms.deform.analogies.ShapeAnalogy` /
        its ``steps`` (input vertex ids).

    Yields
    ------
    Step: ``iteration = 0`` with the input positions once pre-processing is done, then
    full-resolution previews every ``progressive.preview_every`` coarse iterations, then the
    coarse result put back, then (``progressive.finish``, the default) one Step per iteration
    of the analogy on every triangle, started from it (its set-up is part of pre-processing).
    """
    from .analogies import AnalogyParams, ShapeAnalogy

    params = AnalogyParams() if params is None else params
    validate_params(params)
    validate_params(progressive)
    n = len(V) if np.ndim(V) == 2 else 0
    keep = _constraint_vertices(n, fixed, handles, None)
    t0 = time.perf_counter()
    apm = AffineProgressiveMesh(V, F, target_faces=progressive.target_faces,
                                strategy=progressive.strategy, tikhonov=progressive.tikhonov,
                                keep=keep, what="Shape analogies")
    c_handles = None if handles is None else (apm.coarse_ids(handles[0]), handles[1])
    analogy = ShapeAnalogy(apm.V_coarse, apm.F_coarse, target_map, fixed=apm.coarse_ids(fixed),
                           handles=c_handles)
    fine = None
    if progressive.finish:
        fine_analogy = ShapeAnalogy(V, F, target_map, fixed=fixed, handles=handles)

        def fine(V_start):
            return fine_analogy.steps(params, lam_per_vertex=lam_per_vertex, initial=V_start)
    seconds = time.perf_counter() - t0
    msg = (f"pre-processing done in {seconds:.1f} s: {len(apm.F):,} -> "
           f"{apm.n_coarse_faces:,} triangles")
    if apm.notes:
        msg += ". " + " ".join(apm.notes)
    yield Step(iteration=0, total=None, V=apm.V.copy(),
               metrics={"preprocess_seconds": seconds}, message=msg)
    lam_c = None if lam_per_vertex is None else apm.coarse_lambda(lam_per_vertex)
    yield from apm.finished_steps(analogy.steps(params, lam_per_vertex=lam_c),
                                  progressive.preview_every, fine)
