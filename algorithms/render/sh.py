"""Spherical-harmonics (SH) environment lighting for the one renderer (thesis ch. 3, App. 3.7.3).

A new :class:`~algorithms.render.shading.Shading` implementation: the rasterizer, the per-face
image formation and the geometry derivative ``normal_vjp`` are the renderer's
(:mod:`algorithms.render.render`); this module adds the SH basis, the clamped-cosine convolution
and the lighting / albedo / normal derivatives.

Image formation (Eq. 3.24-3.25), per colour channel ``c`` and face normal ``n``::

    I_c = rho_c * sum_{l=0..L} sum_{m=-l..l} U_{lm,c} A_l Y_l^m(n),
    A_l = sqrt(4 pi / (2l + 1)) G~_l                                   (Eq. 3.21)

with the real SH basis ``Y_l^m`` of Eq. 3.16-3.17 (degree ``L = 6``: 49 coefficients per
channel; coefficient ``(l, m)`` sits at index ``l*l + l + m``), and ``G~_l`` the clamped-cosine
coefficients of Basri and Jacobs (2003, App. A; the thesis's case formula): ``A_0 = pi``,
``A_1 = 2 pi / 3``, ``A_2 = pi / 4``, ``A_odd>1 = 0``, ``A_4 = -pi / 24``, ``A_6 = pi / 64``.
As written in the thesis there is no ``1 / pi`` (radiance = albedo x irradiance / pi in some
texts): the image is ``rho`` times the irradiance.

Lighting frame: the coefficients are in world coordinates (``theta`` measured from +z, ``phi``
from +x in the x-y plane, Eq. 3.16); the environment is distant, so it does not turn with the
camera.

Evaluation (a choice, documented and tested): for unit ``n`` the real SH are polynomials,
``Y_l^{+-m}(n) = K_l^m sqrt(2) P_l^{(m)}(n_z) {Re, Im}((n_x + i n_y)^m)``, with ``P_l^{(m)}`` the
``m``-th derivative of the Legendre polynomial (the Condon-Shortley phase of ``P_l^m`` cancels
the ``(-1)^m`` of Eq. 3.16). This equals Eq. 3.16 exactly (``test_render_sh.py`` compares it with
the literal spherical-coordinate form :func:`sh_basis_polar`) but has no singularity at the poles.
Its gradient is projected onto the tangent plane of ``n``: that is the gradient of ``Y(n/|n|)``,
which is what Eq. 3.37-3.40 compute (``d theta/dn`` and ``d phi/dn`` of Eq. 3.39-3.40 are
orthogonal to ``n``), and the tests compare it with the literal :func:`sh_basis_gradient_polar`
away from the poles, where Eq. 3.38-3.40 divide by ``sin theta``. (The second line of Eq. 3.37
prints ``P_l^{-m}`` in the ``m > 0`` case; ``P_l^m`` is meant.)

Derivatives (vector-Jacobian products, visibility fixed as in the renderer)
---------------------------------------------------------------------------
For the per-face image gradient ``g_f = sum_{p sees f} dE/dI_p``:

* lighting (Eq. 3.28): ``dE/dU_{j,c} = A_j sum_f rho_{f,c} g_{f,c} Y_j(n_f)``;
* albedo (Eq. 3.29): ``dE/drho_{f,c} = g_{f,c} sum_j U_{j,c} A_j Y_j(n_f)``;
* vertices (Eq. 3.36, 3.41): ``dE/dn_f = sum_{j,c} rho_{f,c} g_{f,c} U_{j,c} A_j dY_j/dn (n_f)``,
  pulled back to the vertices by the renderer's :func:`~algorithms.render.render.normal_vjp`.

Compiled path (:mod:`algorithms.render.kernels`, the renderer's switch
:func:`~algorithms.render.raster.set_compiled_kernels`): :class:`SHShading` evaluates, per seen
face, ``Y_l^m = K_l^m sqrt(2) Q_l^|m|(n_z) {Re, Im}((n_x + i n_y)^|m|)`` with
``Q_l^m = d^m P_l / dz^m`` by the associated-Legendre recurrence
``(l - m) Q_l^m = (2l - 1) z Q_{l-1}^m - (l + m - 1) Q_{l-2}^m``, ``Q_m^m = (2m - 1)!!``
(the same polynomials as the tables above, a few flops per coefficient), and ``dQ_l^m/dz =
Q_l^{m+1}``, so ``dY/dn`` comes from the same table; ``dE/dn`` is accumulated without forming
the ``(k, 49, 3)`` gradient.
The compiled kernels work on blocks of 64 faces with the face index innermost (vectorizable
loops); the rendering keeps the basis (``(49, k)``, transposed) and the irradiance of the seen
faces (:class:`SHState`), so Eq. 3.28 is one matrix product and Eq. 3.29 one multiplication.
Same numbers as the NumPy path to rounding (tested to 1e-12).

Published environments
----------------------
:data:`ENVIRONMENTS` holds the nine lighting coefficients (degrees 0-2, RGB) of light probes
published by Ramamoorthi and Hanrahan, "An Efficient Representation for Irradiance Environment
Maps", SIGGRAPH 2001 (their table of ``L_lm``; computed from Debevec's light probes). The digits
are those reproduced in R. Rost, *OpenGL Shading Language* (2nd ed., 2006, section 12.3), which
round to the two-decimal values of the paper's table; only Grace Cathedral, Eucalyptus Grove and
St. Peter's Basilica are embedded (the sets we could verify). Higher degrees are zero. The probe
images have +y up, which is also the up direction of the project's cameras (``look_at``).
Preetham skylight (App. 3.7.4) is *not* provided: it needs the polynomial tables
``(p_lm)_ij`` fitted by Habel et al. 2008, which we could not find in a citable form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MeshReadError, ParameterError
from .camera import Camera
from .raster import compiled_kernels
from .render import Rendering, face_color_gradients, normal_vjp, render

__all__ = ["SH_DEGREE", "n_coefficients", "sh_index", "clamped_cosine_coefficients",
           "convolution_weights", "sh_basis", "sh_basis_gradient", "sh_basis_vjp", "sh_basis_polar",
           "sh_basis_gradient_polar", "ENVIRONMENTS", "ENVIRONMENT_SOURCE", "environment",
           "SHShading", "SHState", "SHGradients", "sh_render", "sh_image_vjp", "face_albedo",
           "read_mesh_colors", "sh_face_colors_torch", "rotate_lighting"]

SH_DEGREE = 6


def n_coefficients(degree: int = SH_DEGREE) -> int:
    """Coefficients per colour channel of SH up to ``degree``: ``(degree + 1)^2`` (49 for 6)."""
    return (int(degree) + 1) ** 2


def sh_index(l: int, m: int) -> int:
    """Index of coefficient ``(l, m)`` (``-l <= m <= l``) in a coefficient vector."""
    if not (0 <= l and -l <= m <= l):
        raise ValueError(f"no spherical harmonic with l={l}, m={m}")
    return l * l + l + m


def _check_degree(degree) -> int:
    d = int(degree)
    if d != degree or d < 0 or d > 12:
        raise ParameterError(f"The spherical-harmonics degree must be a whole number from 0 to 12 "
                             f"(got {degree!r}).")
    return d


def clamped_cosine_coefficients(degree: int = SH_DEGREE) -> np.ndarray:
    """``G~_l`` (``degree + 1``,): SH coefficients of ``max(cos theta, 0)`` (Basri & Jacobs
    2003, App. A; thesis formula after Eq. 3.20)."""
    d = _check_degree(degree)
    G = np.zeros(d + 1)
    for l in range(d + 1):
        if l == 0:
            G[l] = math.sqrt(math.pi) / 2.0
        elif l == 1:
            G[l] = math.sqrt(math.pi / 3.0)
        elif l % 2 == 0:
            G[l] = ((-1) ** (l // 2 + 1) * math.factorial(l - 2) * math.sqrt((2 * l + 1) * math.pi)
                    / (2 ** l * math.factorial(l // 2 - 1) * math.factorial(l // 2 + 1)))
    return G


def convolution_weights(degree: int = SH_DEGREE) -> np.ndarray:
    """``A_l = sqrt(4 pi/(2l+1)) G~_l`` repeated for each ``m``: ``(n_coefficients,)``."""
    G = clamped_cosine_coefficients(degree)
    A = np.array([math.sqrt(4 * math.pi / (2 * l + 1)) * G[l] for l in range(len(G))])
    return np.repeat(A, [2 * l + 1 for l in range(len(G))])


def _K(l: int, m: int) -> float:
    m = abs(m)
    return math.sqrt((2 * l + 1) * math.factorial(l - m) / (4 * math.pi * math.factorial(l + m)))


_TABLES: dict[int, tuple] = {}


def _tables(degree: int):
    """Per coefficient: polynomial in z (coefficients by power), the order m, cos/sin part,
    and the same for d/dz."""
    if degree not in _TABLES:
        nc = n_coefficients(degree)
        Pz = np.zeros((degree + 1, nc))    # Y_j = (sum_p Pz[p, j] z^p) * XY_j(x, y)
        order = np.zeros(nc, dtype=np.int64)
        is_sin = np.zeros(nc, dtype=bool)
        for l in range(degree + 1):
            leg = np.polynomial.legendre.Legendre.basis(l).convert(kind=np.polynomial.Polynomial)
            for m in range(-l, l + 1):
                j = sh_index(l, m)
                am = abs(m)
                p = leg.deriv(am) if am else leg
                scale = _K(l, m) * (math.sqrt(2.0) if m != 0 else 1.0)
                c = p.coef * scale
                Pz[:len(c), j] = c
                order[j] = am
                is_sin[j] = m < 0
        dPz = np.zeros_like(Pz)
        dPz[:-1] = Pz[1:] * np.arange(1, degree + 1)[:, None]
        _TABLES[degree] = (Pz, dPz, order, is_sin)
    return _TABLES[degree]


_KF: dict[int, np.ndarray] = {}


def _kf(degree: int) -> np.ndarray:
    """``K_l^m`` (times ``sqrt(2)`` for ``m != 0``) per coefficient, for the compiled kernels."""
    if degree not in _KF:
        kf = np.empty(n_coefficients(degree))
        for l in range(degree + 1):
            for m in range(-l, l + 1):
                kf[sh_index(l, m)] = _K(l, m) * (math.sqrt(2.0) if m != 0 else 1.0)
        kf.setflags(write=False)
        _KF[degree] = kf
    return _KF[degree]


def _as_normals(normals) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(normals, dtype=np.float64).reshape(-1, 3))


def _unit_normals(normals) -> np.ndarray:
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    nrm = np.linalg.norm(N, axis=1, keepdims=True)
    return N / np.where(nrm > 0, nrm, 1.0)


def _xy_powers(x, y, degree):
    """Re and Im of (x + i y)^m, m = 0..degree: two (k, degree+1) arrays."""
    k = len(x)
    C = np.empty((k, degree + 1))
    S = np.empty((k, degree + 1))
    C[:, 0], S[:, 0] = 1.0, 0.0
    for m in range(1, degree + 1):
        C[:, m] = C[:, m - 1] * x - S[:, m - 1] * y
        S[:, m] = C[:, m - 1] * y + S[:, m - 1] * x
    return C, S


def _parts(normals, degree, with_gradient: bool):
    """The factors of ``Y_j = P_j(z) XY_j(x, y)`` (and of their partial derivatives)."""
    d = _check_degree(degree)
    N = _unit_normals(normals)
    Pz, dPz, order, is_sin = _tables(d)
    x, y, z = N[:, 0], N[:, 1], N[:, 2]
    k = len(N)
    Z = np.empty((k, d + 1))
    Z[:, 0] = 1.0
    for p in range(1, d + 1):
        Z[:, p] = Z[:, p - 1] * z
    C, S = _xy_powers(x, y, d)
    CS = np.concatenate([C, S], axis=1)
    idx = order + (d + 1) * is_sin
    P = Z @ Pz
    XY = CS[:, idx]
    if not with_gradient:
        return N, P, XY
    mm = order.astype(np.float64)
    Cm1 = np.zeros_like(C)
    Sm1 = np.zeros_like(S)
    Cm1[:, 1:], Sm1[:, 1:] = C[:, :-1], S[:, :-1]
    # d/dx (x+iy)^m = m (x+iy)^(m-1); d/dy = i m (x+iy)^(m-1)
    dXYdx = mm * np.concatenate([Cm1, Sm1], axis=1)[:, idx]
    dXYdy = mm * np.concatenate([-Sm1, Cm1], axis=1)[:, idx]
    return N, P, XY, Z @ dPz, dXYdx, dXYdy


def sh_basis(normals, degree: int = SH_DEGREE) -> np.ndarray:
    """Real SH ``Y_l^m`` (Eq. 3.16-3.17) of the directions ``normals (k, 3)`` (normalized here):
    ``(k, (degree+1)^2)``."""
    _, P, XY = _parts(normals, degree, False)
    return P * XY


def sh_basis_gradient(normals, degree: int = SH_DEGREE) -> np.ndarray:
    """``dY_j/dn`` (k, (degree+1)^2, 3) at unit normals: the gradient of ``Y_j(n/|n|)``, i.e.
    tangent to the sphere (what Eq. 3.37-3.40 compute, without their pole singularity)."""
    N, P, XY, dP, dXYdx, dXYdy = _parts(normals, degree, True)
    g = np.stack([P * dXYdx, P * dXYdy, dP * XY], axis=-1)           # (k, nc, 3)
    radial = np.einsum("kjd,kd->kj", g, N)
    return g - radial[..., None] * N[:, None, :]


def sh_basis_vjp(normals, weights, degree: int = SH_DEGREE) -> np.ndarray:
    """``sum_j weights_kj dY_j/dn (n_k)`` (k, 3) without forming the (k, nc, 3) gradient."""
    N, P, XY, dP, dXYdx, dXYdy = _parts(normals, degree, True)
    wP = weights * P
    g = np.stack([(wP * dXYdx).sum(1), (wP * dXYdy).sum(1), (weights * dP * XY).sum(1)], axis=1)
    return g - np.einsum("kd,kd->k", g, N)[:, None] * N


def _assoc_legendre(l: int, m: int, x):
    """``P_l^m(x)`` with the Condon-Shortley phase, ``m >= 0`` (scipy's ``lpmv``)."""
    from scipy.special import lpmv

    return lpmv(m, l, x)


def sh_basis_polar(theta, phi, degree: int = SH_DEGREE) -> np.ndarray:
    """Eq. 3.16-3.17 literally, in polar angles (reference implementation for the tests):
    ``(k, (degree+1)^2)``."""
    d = _check_degree(degree)
    th = np.asarray(theta, dtype=np.float64).reshape(-1)
    ph = np.asarray(phi, dtype=np.float64).reshape(-1)
    out = np.empty((len(th), n_coefficients(d)))
    ct = np.cos(th)
    for l in range(d + 1):
        for m in range(-l, l + 1):
            K = _K(l, m)
            if m < 0:
                v = (-1) ** m * math.sqrt(2) * _assoc_legendre(l, -m, ct) * np.sin(-m * ph)
            elif m > 0:
                v = (-1) ** m * math.sqrt(2) * _assoc_legendre(l, m, ct) * np.cos(m * ph)
            else:
                v = _assoc_legendre(l, 0, ct)
            out[:, sh_index(l, m)] = K * v
    return out


def sh_basis_gradient_polar(normals, degree: int = SH_DEGREE) -> np.ndarray:
    """Eq. 3.37-3.40 literally (reference for the tests; singular where ``n_x = n_y = 0``):
    ``(k, (degree+1)^2, 3)``."""
    d = _check_degree(degree)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    nx, ny, nz = N[:, 0], N[:, 1], N[:, 2]
    r2 = nx * nx + ny * ny
    n2 = r2 + nz * nz
    rho = np.sqrt(r2)
    theta = np.arccos(nz / np.sqrt(n2))
    phi = np.arctan2(ny, nx)
    dtheta = np.stack([nx * nz, ny * nz, -r2], axis=1) / (n2 * rho)[:, None]      # Eq. 3.39
    dphi = np.stack([-ny / r2, nx / r2, np.zeros_like(nx)], axis=1)               # Eq. 3.40
    ct, st = np.cos(theta), np.sin(theta)
    out = np.empty((len(N), n_coefficients(d), 3))
    for l in range(d + 1):
        for m in range(-l, l + 1):
            am = abs(m)
            P = _assoc_legendre(l, am, ct)
            dP = (-ct * (l + 1) * P + (l - am + 1) * _assoc_legendre(l + 1, am, ct)) / st  # 3.38
            K = _K(l, m)
            if m < 0:
                g = (-1) ** m * math.sqrt(2) * (dP[:, None] * dtheta * np.sin(-m * phi)[:, None]
                                                - m * (P * np.cos(-m * phi))[:, None] * dphi)
            elif m > 0:
                g = (-1) ** m * math.sqrt(2) * (dP[:, None] * dtheta * np.cos(m * phi)[:, None]
                                                - m * (P * np.sin(m * phi))[:, None] * dphi)
            else:
                g = dP[:, None] * dtheta
            out[:, sh_index(l, m)] = K * g
    return out


# --------------------------------------------------------------------------------------------
# published environments
# --------------------------------------------------------------------------------------------

ENVIRONMENT_SOURCE = ("R. Ramamoorthi and P. Hanrahan, 'An Efficient Representation for Irradiance "
                      "Environment Maps', SIGGRAPH 2001 (9 lighting coefficients L_lm, RGB, of "
                      "Debevec's light probes); digits as reproduced in R. Rost, 'OpenGL Shading "
                      "Language', 2nd ed., 2006, sec. 12.3.")

# rows: L00, L1-1, L10, L11, L2-2, L2-1, L20, L21, L22 (index l*l + l + m); columns R, G, B
ENVIRONMENTS: dict[str, np.ndarray] = {
    "Grace Cathedral": np.array([
        [0.78908, 0.43710, 0.54161],
        [0.39499, 0.34989, 0.60488],
        [-0.33974, -0.18236, -0.26940],
        [-0.29213, -0.05562, 0.00944],
        [-0.11141, -0.05090, -0.12231],
        [-0.26240, -0.22401, -0.47479],
        [-0.15570, -0.09471, -0.14733],
        [0.56014, 0.21444, 0.13915],
        [0.21205, -0.05432, -0.30374]]),
    "Eucalyptus Grove": np.array([
        [0.3783264, 0.4260425, 0.4504587],
        [0.2887813, 0.3586803, 0.4147053],
        [0.0379030, 0.0295216, 0.0098567],
        [-0.1033028, -0.1031690, -0.0884924],
        [-0.0621750, -0.0554432, -0.0396779],
        [0.0077820, -0.0148312, -0.0471301],
        [-0.0935561, -0.1254260, -0.1525629],
        [-0.0572703, -0.0502192, -0.0363410],
        [0.0203348, -0.0044201, -0.0452180]]),
    "St. Peter's Basilica": np.array([
        [0.3623915, 0.2624130, 0.2326261],
        [0.1759130, 0.1436267, 0.1260569],
        [-0.0247311, -0.0101253, -0.0010745],
        [0.0346500, 0.0223184, 0.0101350],
        [0.0198140, 0.0144073, 0.0043987],
        [-0.0469596, -0.0254485, -0.0117786],
        [-0.0898667, -0.0760911, -0.0740964],
        [0.0050194, 0.0038841, 0.0001374],
        [-0.0818750, -0.0321501, 0.0033399]]),
}
for _v in ENVIRONMENTS.values():
    _v.setflags(write=False)


def environment(name: str = "Grace Cathedral", degree: int = SH_DEGREE) -> np.ndarray:
    """The published lighting ``name`` as ``(n_coefficients(degree), 3)`` (zeros above l = 2)."""
    d = _check_degree(degree)
    key = {k.lower(): k for k in ENVIRONMENTS}.get(str(name).strip().lower())
    if key is None:
        raise ParameterError(f"Unknown lighting environment {name!r}. Choose one of: "
                             f"{', '.join(ENVIRONMENTS)}.")
    U = np.zeros((n_coefficients(d), 3))
    k = min(9, len(U))
    U[:k] = ENVIRONMENTS[key][:k]
    return U


def rotate_lighting(U, R) -> np.ndarray:
    """The SH lighting ``U ((l+1)^2, C)`` turned by the rotation matrix ``R (3, 3)``: the light
    that arrived from direction ``w`` arrives from ``R w``, ``U'(w) = U(R^T w)``. A rotation
    keeps each degree's band, so the coefficients of every degree are refitted exactly (least
    squares on 4 x (l+1)^2 + 64 Fibonacci-sphere directions; error ~1e-15)."""
    U = np.asarray(U, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-8):
        raise ParameterError("rotate_lighting needs a 3 x 3 rotation matrix.")
    flat = U.ndim == 1
    U2 = U[:, None] if flat else U
    d = _check_degree(int(round(math.sqrt(U2.shape[0]))) - 1)
    if (d + 1) ** 2 != U2.shape[0]:
        raise ParameterError(f"SH lighting needs (l+1)^2 rows; got {U2.shape[0]}.")
    k = 4 * (d + 1) ** 2 + 64
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    phi = i * math.pi * (3 - math.sqrt(5))
    r = np.sqrt(1 - z * z)
    W = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    B = sh_basis(W, d)
    out = np.linalg.lstsq(B, sh_basis(W @ R, d) @ U2, rcond=None)[0]
    return out[:, 0] if flat else out


# --------------------------------------------------------------------------------------------
# shading
# --------------------------------------------------------------------------------------------


class SHShading:
    """Flat Lambertian shading under SH environment lighting (Eq. 3.24-3.25).

    Parameters
    ----------
    coefficients : (n_coefficients(degree), C) lighting ``U`` (``C`` colour channels; a 1-D
        array is one grey channel). The degree is deduced from the row count (1, 4, 9, ..., 49).
    """

    def __init__(self, coefficients):
        U = np.asarray(coefficients, dtype=np.float64)
        if U.ndim == 1:
            U = U[:, None]
        d = int(round(math.sqrt(U.shape[0]))) - 1 if U.ndim == 2 and U.shape[0] > 0 else -1
        if U.ndim != 2 or d < 0 or (d + 1) ** 2 != U.shape[0] or d > 12:
            raise ParameterError(f"SH lighting needs (l+1)^2 rows of coefficients (1, 4, 9, ..., "
                                 f"49) per colour channel; got an array of shape {U.shape}.")
        if not np.isfinite(U).all():
            raise ParameterError("The lighting coefficients must be finite numbers.")
        self.coefficients = U
        self.degree = d
        self.channels = int(U.shape[1])
        self._A = convolution_weights(d)

    @property
    def weighted(self) -> np.ndarray:
        """``A_j U_j`` (n_coefficients, C)."""
        return self._A[:, None] * self.coefficients

    def basis(self, normals) -> np.ndarray:
        """``Y_j(n) (k, n_coefficients)`` (compiled when available, else :func:`sh_basis`)."""
        return self._basis_and_irradiance(normals)[0]

    def _basis_and_irradiance(self, normals):
        kern = compiled_kernels()
        if kern is not None:
            N = _as_normals(normals)
            Yt = np.empty((len(self._A), len(N)))
            irr = np.empty((len(N), self.channels))
            kern.sh_values_t(N, _kf(self.degree), np.ascontiguousarray(self.weighted), Yt, irr)
            return Yt.T, irr
        Y = sh_basis(normals, self.degree)
        return Y, Y @ self.weighted

    def face_colors_with_state(self, normals, camera: Camera | None = None, albedo=None):
        """Colours and an :class:`SHState` (the basis and irradiance of these faces) that
        :func:`sh_image_vjp` reuses: the lighting derivative (Eq. 3.28) is then one product."""
        Y, irr = self._basis_and_irradiance(normals)
        col = irr if albedo is None else irr * albedo
        return col, SHState(self, Y, irr)

    def irradiance(self, normals) -> np.ndarray:
        """``F(n) = sum_j U_j A_j Y_j(n)`` (k, C), Eq. 3.25 without the albedo."""
        return self._basis_and_irradiance(normals)[1]

    def face_colors(self, normals, camera: Camera | None = None, albedo=None) -> np.ndarray:
        col = self.irradiance(normals)
        if albedo is not None:
            col = col * albedo
        return col

    def face_colors_vjp(self, normals, camera, grad_colors, albedo=None):
        g = np.asarray(grad_colors, dtype=np.float64)
        grad_albedo = None
        if albedo is not None:
            grad_albedo = g * self.irradiance(normals)                  # Eq. 3.29
            g = g * albedo
        kern = compiled_kernels()
        if kern is not None:
            N = _as_normals(normals)
            gN = np.empty((len(N), 3))
            kern.sh_normal_vjp(N, np.ascontiguousarray(g).reshape(len(N), -1),
                               np.ascontiguousarray(self.weighted), _kf(self.degree), gN)
            return gN, grad_albedo                                        # Eq. 3.36
        w = g @ self.weighted.T                                           # (k, nc)
        return sh_basis_vjp(normals, w, self.degree), grad_albedo        # Eq. 3.36

    def lighting_vjp(self, normals, grad_colors, albedo=None, *, basis=None) -> np.ndarray:
        """``dE/dU (n_coefficients, C)`` from per-face colour gradients (Eq. 3.28); ``basis``:
        ``Y (k, n_coefficients)`` of ``normals`` when already known."""
        g = np.asarray(grad_colors, dtype=np.float64)
        if albedo is not None:
            g = g * albedo
        if basis is None:
            basis = self.basis(normals)
        return self._A[:, None] * (basis.T @ g)


def sh_render(V, F, camera: Camera, lighting, *, albedo=None, background: float = 0.0,
              backend: str = "auto") -> Rendering:
    """Render ``(V, F)`` under SH ``lighting (n_coefficients, C)`` with per-face ``albedo``
    ((m, C), (C,) or a number; None = 1) through the renderer's :func:`render`."""
    shading = lighting if isinstance(lighting, SHShading) else SHShading(lighting)
    alb = None if albedo is None else face_albedo(np.asarray(F).reshape(-1, 3), albedo,
                                                   channels=shading.channels)
    return render(V, F, camera, shading, albedo=alb, background=background, backend=backend)


@dataclass
class SHState:
    """What :meth:`SHShading.face_colors_with_state` keeps in :attr:`Rendering.state`: the
    shading, the basis ``Y (k, n_coefficients)`` and the irradiance ``(k, C)`` of the seen faces."""

    shading: SHShading
    basis: np.ndarray
    irradiance: np.ndarray


@dataclass
class SHGradients:
    """Vector-Jacobian products of an SH rendering: ``vertices (n, 3)``, ``lighting
    (n_coefficients, C)``, ``albedo (m, C)`` (zero for unseen faces); None where not asked."""

    vertices: np.ndarray | None
    lighting: np.ndarray | None
    albedo: np.ndarray | None


def sh_image_vjp(V, F, rendering: Rendering, grad_image, *, vertices: bool = True,
                 lighting: bool = True, albedo: bool = False) -> SHGradients:
    """``dE/dV``, ``dE/dU`` and ``dE/drho`` from ``dE/dI (H, W, C)`` for an image of
    :func:`sh_render` (visibility fixed). One pass over the pixels; O(pixels + faces)."""
    shading = rendering.shading
    if not isinstance(shading, SHShading):
        raise TypeError("sh_image_vjp needs a rendering made with SHShading")
    gc = face_color_gradients(rendering, grad_image)
    C = gc.shape[1]
    N, alb = rendering.normals, rendering.albedo
    st = rendering.state
    if not (isinstance(st, SHState) and st.shading is shading and len(st.basis) == len(N)):
        st = None
    dV = dU = dA = None
    if vertices:
        gN, _ = shading.face_colors_vjp(N, rendering.camera, gc if alb is None else gc * alb)
        dV = normal_vjp(V, F, rendering.faces, gN)                      # Eq. 3.36, 3.41
    if albedo:
        dA = np.zeros((len(F), C))
        irr = st.irradiance if st is not None else shading.irradiance(N)
        dA[rendering.faces] = gc * irr                                   # Eq. 3.29
    if lighting:
        dU = shading.lighting_vjp(N, gc, alb, basis=None if st is None else st.basis)  # Eq. 3.28
    return SHGradients(dV, dU, dA)


# --------------------------------------------------------------------------------------------
# albedo
# --------------------------------------------------------------------------------------------


def face_albedo(F, albedo, *, channels: int = 3) -> np.ndarray:
    """Per-face albedo ``(m, channels)`` from a number, a colour ``(channels,)``, per-face colours
    ``(m, channels)`` or per-vertex colours ``(n, channels)`` (averaged over each face's corners;
    pass ``n != m`` or use :func:`read_mesh_colors`)."""
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    a = np.asarray(albedo, dtype=np.float64)
    if not np.isfinite(a).all():
        raise ParameterError("Albedo (surface colour) values must be finite numbers.")
    if a.ndim == 0:
        return np.full((len(F), channels), float(a))
    if a.ndim == 1 and a.shape[0] == channels:
        return np.broadcast_to(a, (len(F), channels)).copy()
    if a.ndim == 2 and a.shape == (len(F), channels):
        return a
    if a.ndim == 2 and a.shape[1] == channels and a.shape[0] > int(F.max(initial=-1)):
        return a[F].mean(axis=1)
    raise ParameterError(f"Give the surface colour as one number, one colour of {channels} "
                         f"values, or one colour per face ({len(F)} x {channels}); got an array "
                         f"of shape {a.shape}.")


def read_mesh_colors(path, n_vertices: int, n_faces: int):
    """Colours stored in a mesh file, in [0, 1]: ``("vertex", (n, 3))``, ``("face", (m, 3))`` or
    None when the file has none. Reads OBJ ``v x y z r g b`` lines and the ``red green blue``
    vertex / face properties of ASCII and binary PLY (0-255 integers or 0-1 floats; binary is
    what the app's Export Coloured Mesh writes); other files give None."""
    p = Path(path)
    ext = p.suffix.lower()
    try:
        text = p.read_bytes()
    except OSError as exc:
        raise MeshReadError(f"'{p}' cannot be opened: {exc.strerror or exc}.") from None
    if ext == ".obj":
        cols = []
        for line in text.decode("utf-8", "replace").splitlines():
            t = line.split()
            if t and t[0] == "v":
                if len(t) < 7:
                    return None
                cols.append([float(v) for v in t[4:7]])
        C = np.asarray(cols, dtype=np.float64)
        if len(C) != n_vertices:
            return None
        if C.max(initial=0) > 1.0:
            C = C / 255.0
        return ("vertex", np.clip(C, 0.0, 1.0))
    if ext == ".ply":
        from algorithms.mesh.io import ply_colors

        got = ply_colors(text)
        if got is None:
            return None
        kind, C = got
        return got if len(C) == (n_vertices if kind == "vertex" else n_faces) else None
    return None


def sh_face_colors_torch(Vt, Ut, F, albedo, degree: int = SH_DEGREE):
    """The same image formation in PyTorch (Eq. 3.24-3.25 on flat face normals), for autograd
    peers in tests and benchmarks: per-face colours ``(k, C)`` of faces ``F (k, 3)`` from vertex
    positions ``Vt (n, 3)`` and lighting ``Ut (n_coefficients, C)`` (torch tensors, float64),
    ``albedo (k, C)``. The basis is evaluated by the polynomial tables this module uses."""
    import torch

    X = Vt[torch.as_tensor(F)]
    n = torch.linalg.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    n = n / n.norm(dim=1, keepdim=True)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    Pz, _, order, is_sin = _tables(degree)
    Z = torch.stack([z ** p for p in range(degree + 1)], 1)
    Cs, Ss = [torch.ones_like(x)], [torch.zeros_like(x)]
    for _ in range(1, degree + 1):  # cos(m φ) sin^m θ, sin(m φ) sin^m θ as polynomials in x, y
        Cs.append(Cs[-1] * x - Ss[-1] * y)
        Ss.append(Cs[-2] * y + Ss[-1] * x)
    XY = torch.stack([(Ss if s else Cs)[o] for o, s in zip(order, is_sin)], 1)
    Y = (Z @ torch.as_tensor(Pz)) * XY
    A = torch.as_tensor(convolution_weights(degree))
    return (Y @ (A[:, None] * Ut)) * torch.as_tensor(albedo)
