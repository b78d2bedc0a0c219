"""Draw the app icon (packaging/stylize3d.png, 256x256 RGBA) from the bundled blob sample.

NumPy + Pillow only (no Qt, VTK or display): the sample mesh is cubic-stylized a little (the app's
own method, so the icon shows what the app does), rotated, flat-shaded with one directional light
in the viewport's mesh colour, and drawn face by face back to front at 4x size, then downscaled
for smooth edges. Deterministic; re-run after changing the sample:

    .venv/bin/python packaging/make_icon.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SIZE = 256
SUPER = 4
BASE = np.array([0xE8, 0xD4, 0xB0], float)  # app/viewport.py MESH_COLOR


def rotation(ax: float, ay: float) -> np.ndarray:
    cx, sx, cy, sy = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return rx @ ry


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path(__file__).with_name("stylize3d.png")
    from algorithms.deform.cubic import CubicParams, CubicStylizer
    from algorithms.mesh.io import read_mesh
    from algorithms.steps import run_to_end

    mesh = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    V, F = np.asarray(mesh.V, float), np.asarray(mesh.F, np.int64)
    last = run_to_end(CubicStylizer(V, F).steps(CubicParams(lam=0.4, max_iterations=60)))
    V = np.asarray(last.V, float)
    V = (V - V.mean(0)) @ rotation(np.radians(-25), np.radians(35)).T
    V /= np.abs(V[:, :2]).max()
    T = V[F]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    front = n[:, 2] > 0  # viewer looks along -z
    light = np.array([-0.4, 0.6, 0.7])
    light /= np.linalg.norm(light)
    shade = 0.35 + 0.65 * np.clip(n @ light, 0, 1)
    big = SIZE * SUPER
    scale = big * 0.44
    xy = np.stack([big / 2 + scale * T[..., 0], big / 2 - scale * T[..., 1]], axis=-1)
    img = Image.new("RGBA", (big, big), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    order = np.argsort(T[:, :, 2].mean(1))  # far to near
    for f in order[front[order]]:
        rgb = tuple(int(c) for c in np.clip(BASE * shade[f], 0, 255))
        draw.polygon([tuple(p) for p in xy[f]], fill=rgb + (255,), outline=rgb + (255,))
    img = img.resize((SIZE, SIZE), Image.LANCZOS)
    out.parent.mkdir(parents=True, exist_ok=True)
    img.save(out, optimize=True)
    print(f"wrote {out} ({SIZE}x{SIZE})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
