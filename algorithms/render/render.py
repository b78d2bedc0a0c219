"""Rendering (rasterize + shade) and the analytic vector-Jacobian product d(image)/d(vertices).

Derivative (thesis 303-323)
---------------------------
With flat shading and visibility held fixed, pixel ``p`` seeing face ``j`` has colour
``c(n_j)``; only the three corners of face ``j`` move it. The face normal's derivative w.r.t.
corner ``v_k`` is ``d n_j / d v_k = -h_jk n_j^T / |h_jk|^2``, where ``h_jk`` is the height vector
from the line of the opposite edge to ``v_k`` (the thesis prints ``h n^T / |h|^2`` without
fixing the orientation of ``h``; with ``h`` pointing to the corner, lifting the corner along
``n`` tilts ``n`` *away* from it, hence the minus sign -- checked against finite differences in
the tests). So for an image gradient ``G = dE/dR (H, W, C)``:

1. ``g_j = sum_{p sees j} G_p`` per face (one ``np.bincount`` per channel, O(pixels));
2. ``dE/dn_j`` = the shading's vector-Jacobian product of ``g_j`` (O(faces));
3. ``dE/dv_k += -n_j (h_jk . dE/dn_j) / |h_jk|^2`` for the corners of each seen face,
   accumulated with ``np.bincount`` (O(faces)).

No matrix is ever formed; cost O(pixels + seen faces).

Compiled path (:mod:`algorithms.render.kernels`, switched with
:func:`~algorithms.render.raster.set_compiled_kernels`): the seen faces (among the faces the
rasterizer z-tested), their normals, the slots and the painting of the image (one pass over the
pixels), step 1 and step 3 are single loops (no per-corner temporary arrays); the shading (step 2)
stays pluggable. :class:`LambertianShading` without albedo, being linear in the normal, is applied
inside the kernels (colours in the normals' loop; ``dE/dn_j = scale M g_j`` in step 3's loop),
and each of the shading and its derivative is one kernel call.
Both paths give the same numbers (to rounding; tested to 1e-12).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .raster import Raster, compiled_kernels, rasterize
from .shading import LambertianShading, Shading

__all__ = ["Rendering", "render", "image_vjp", "normal_vjp", "face_unit_normals"]


def face_unit_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(k, 3) unit normals of the faces ``F (k, 3)`` (zero for degenerate faces)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    N = np.cross(b - a, c - a)
    nrm = np.linalg.norm(N, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(nrm > 0, N / np.where(nrm > 0, nrm, 1.0), 0.0)


@dataclass
class Rendering:
    """A shaded image and what is needed to differentiate it.

    Attributes
    ----------
    raster : the :class:`Raster` (face ids, depth, barycentrics).
    image : (H, W, C) float64 colours (``background`` where no face is seen).
    faces : (k,) sorted ids of the faces seen.
    slot : (H, W) int64 index into ``faces`` per pixel (-1 for background).
    normals : (k, 3) unit normals of ``faces``.
    colors : (k, C) their colours.
    albedo : (k, C) their albedo, or None.
    shading : the shading used.
    state : what the shading kept for its derivatives (see :class:`~algorithms.render.shading.
        Shading`; e.g. the SH basis of the seen faces), or None.
    """

    raster: Raster
    image: np.ndarray
    faces: np.ndarray
    slot: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    albedo: np.ndarray | None
    shading: Shading
    state: object = None

    @property
    def camera(self) -> Camera:
        return self.raster.camera

    @property
    def mask(self) -> np.ndarray:
        return self.raster.face_id >= 0


def render(V, F, camera: Camera, shading: Shading | None = None, *, albedo=None,
           background: float = 0.0, backend: str = "auto") -> Rendering:
    """Rasterize and flat-shade ``(V (n, 3), F (m, 3))`` through ``camera``.

    ``shading`` defaults to :class:`LambertianShading` (R, G, B lights along the camera axes, the
    authors' ``(n.l + 1)/2``). ``albedo`` is an optional ``(m, C)`` per-face colour.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    shading = LambertianShading() if shading is None else shading
    r = rasterize(V, F, camera, backend=backend)
    fid = r.face_id
    kern = compiled_kernels() if backend != "numpy" else None
    if kern is not None:
        cand = r._candidates
        if cand is None:
            cand = np.arange(len(F))
        V = np.ascontiguousarray(V)
        F = np.ascontiguousarray(F)
        if albedo is None and type(shading) is LambertianShading:     # one call: normals and
            faces, N, colors, slot, image = kern.lambert_render(      # colours in one loop
                V, F, fid, cand, len(F), shading.light_matrix(camera), shading.scale,
                shading.offset, float(background))
            return Rendering(r, image, faces, slot, N, colors, None, shading, None)
        faces, lookup = kern.seen_lookup(fid, cand, len(F))
        N = np.empty((len(faces), 3))
        kern.face_normals(V, F, faces, N)
        alb = None if albedo is None else np.asarray(albedo, dtype=np.float64)[faces]
        colors, state = _shade(shading, N, camera, alb)
        colors = np.ascontiguousarray(colors, dtype=np.float64)
        slot = np.empty_like(fid)
        image = np.empty(fid.shape + (colors.shape[1],))
        kern.slot_paint(fid, lookup, colors, float(background), slot, image)
        return Rendering(r, image, faces, slot, N, colors, alb, shading, state)
    mask = fid >= 0
    seen = fid[mask]
    faces = np.flatnonzero(np.bincount(seen, minlength=len(F)))   # O(pixels + faces), no sort
    lookup = np.full(len(F) + 1, -1, dtype=np.int64)
    lookup[faces] = np.arange(len(faces))
    slot = lookup[fid]                                              # fid = -1 -> lookup[-1] = -1
    inv = slot[mask]
    N = face_unit_normals(V, F[faces])
    alb = None if albedo is None else np.asarray(albedo, dtype=np.float64)[faces]
    colors, state = _shade(shading, N, camera, alb)
    C = colors.shape[1]
    image = np.full(fid.shape + (C,), float(background))
    image[mask] = colors[inv]
    return Rendering(r, image, faces, slot, N, colors, alb, shading, state)


def _shade(shading, N, camera, alb):
    """Colours of the seen faces, and the shading's state for its derivatives when it keeps one
    (the optional ``face_colors_with_state`` of the :class:`Shading` protocol)."""
    with_state = getattr(shading, "face_colors_with_state", None)
    if with_state is not None:
        return with_state(N, camera, alb)
    return shading.face_colors(N, camera, alb), None


def normal_vjp(V, F, faces, grad_normals) -> np.ndarray:
    """Pull ``dE/dn_j (k, 3)`` for the faces ``faces (k,)`` back to ``dE/dV (n, 3)``.

    Uses ``d n_j / d v_k = -h_jk n_j^T / |h_jk|^2`` (module docstring); O(k).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    kern = compiled_kernels()
    if kern is not None:
        out = np.zeros((len(V), 3))
        kern.normal_vjp(np.ascontiguousarray(V), np.ascontiguousarray(F),
                        np.ascontiguousarray(faces, dtype=np.int64),
                        np.ascontiguousarray(grad_normals, dtype=np.float64), out)
        return out
    T = F[faces]
    X = V[T]  # (k, 3 corners, 3)
    g = np.asarray(grad_normals, dtype=np.float64)
    N = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    nrm = np.linalg.norm(N, axis=1)
    good = nrm > 0
    N = N / np.where(good, nrm, 1.0)[:, None]
    out = np.zeros((len(V), 3))
    for k in range(3):
        vk, va, vb = X[:, k], X[:, (k + 1) % 3], X[:, (k + 2) % 3]
        e = vb - va
        ee = np.einsum("ij,ij->i", e, e)
        t = np.einsum("ij,ij->i", vk - va, e) / np.where(ee > 0, ee, 1.0)
        h = vk - va - t[:, None] * e
        hh = np.einsum("ij,ij->i", h, h)
        s = -np.einsum("ij,ij->i", h, g) / np.where(hh > 0, hh, 1.0)
        s = np.where(good & (hh > 0), s, 0.0)
        contrib = N * s[:, None]
        idx = T[:, k]
        for d in range(3):
            out[:, d] += np.bincount(idx, weights=contrib[:, d], minlength=len(V))
    return out


def _checked_gradient(rendering: Rendering, grad_image) -> np.ndarray:
    """``dE/dR`` as a C-contiguous float64 ``(H, W, C)`` array of the rendering's shape."""
    G = np.ascontiguousarray(grad_image, dtype=np.float64)
    if G.ndim == 2:
        G = G[..., None]
    C = rendering.colors.shape[1]
    if G.shape != rendering.image.shape[:2] + (C,):
        raise ValueError(f"image gradient has shape {G.shape}, the image {rendering.image.shape}")
    return G


def face_color_gradients(rendering: Rendering, grad_image) -> np.ndarray:
    """``dE/d(face colour) (k, C)`` of the seen faces (``rendering.faces``) from ``dE/dR
    (H, W, C)``: flat shading gives each pixel its face's colour, so this is the per-face sum of
    the pixel gradients (one bincount per channel, O(pixels + faces)). Shared by every shading's
    vector-Jacobian product."""
    G = _checked_gradient(rendering, grad_image)
    C = G.shape[2]
    k = len(rendering.faces)
    kern = compiled_kernels()
    if kern is not None:
        gc = np.zeros((k, C))
        kern.face_sums(np.ascontiguousarray(rendering.slot), np.ascontiguousarray(G), gc)
        return gc
    mask = rendering.slot >= 0
    s = rendering.slot[mask]
    Gm = G[mask]
    gc = np.empty((k, C))
    for c in range(C):
        gc[:, c] = np.bincount(s, weights=Gm[:, c], minlength=k)
    return gc


def image_vjp(V, F, rendering: Rendering, grad_image, *, return_albedo: bool = False):
    """``dE/dV (n, 3)`` from ``dE/dR (H, W, C)`` for the image of :func:`render` (visibility
    fixed). With ``return_albedo=True`` also ``dE/d(albedo) (m, C)`` (zero for unseen faces;
    needs a rendering made with an albedo)."""
    shading = rendering.shading
    kern = compiled_kernels()
    if (kern is not None and not return_albedo and rendering.albedo is None
            and type(shading) is LambertianShading):
        # linear shading: dE/dn_j = scale M gc_j, applied in the normal derivative's loop; the
        # per-face sums too, in the same call
        G = _checked_gradient(rendering, grad_image)
        return kern.lambert_image_vjp(
            np.ascontiguousarray(V, dtype=np.float64), np.ascontiguousarray(F, dtype=np.int64),
            np.ascontiguousarray(rendering.slot), rendering.faces, G,
            shading.scale * shading.light_matrix(rendering.camera))
    gc = face_color_gradients(rendering, grad_image)
    C = gc.shape[1]
    gN, gA = shading.face_colors_vjp(rendering.normals, rendering.camera, gc, rendering.albedo)
    dV = normal_vjp(V, F, rendering.faces, gN)
    if not return_albedo:
        return dV
    F = np.asarray(F)
    full = np.zeros((len(F), C))
    if gA is not None:
        full[rendering.faces] = gA
    return dV, full
