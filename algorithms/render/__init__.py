"""The project's one renderer (thesis ch. 2 and 3; DESIGN.md §3): a CPU z-buffer rasterizer
(face ids, depth, barycentrics) for orthographic and perspective cameras, pluggable flat shading
(:class:`LambertianShading`: coloured directional lights), and the analytic vector-Jacobian
product d(image)/d(vertices) in O(pixels + faces).

>>> from algorithms.mesh import icosphere
>>> V, F = icosphere(2)
>>> cam = look_at((0, 0, 3), (0, 0, 0), width=2.5, resolution=32)
>>> r = render(V, F, cam)
>>> r.image.shape
(32, 32, 3)
"""

from .camera import PROJECTIONS, Camera, look_at
from .raster import Raster, compiled_kernels, rasterize, set_compiled_kernels
from .render import Rendering, face_unit_normals, image_vjp, normal_vjp, render
from .shading import MAPPINGS, LambertianShading, Shading, light_frame
from .sh import (ENVIRONMENTS, SHGradients, SHShading, environment, sh_basis, sh_image_vjp,
                 sh_render)

__all__ = ["Camera", "look_at", "PROJECTIONS", "Raster", "rasterize", "compiled_kernels",
           "set_compiled_kernels", "Rendering", "render", "image_vjp", "normal_vjp",
           "face_unit_normals", "Shading", "LambertianShading", "light_frame", "MAPPINGS",
           "SHShading", "SHGradients", "sh_render", "sh_image_vjp", "sh_basis", "environment",
           "ENVIRONMENTS"]
