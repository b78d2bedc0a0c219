"""Mesh core speed against libigl, measured in the same run.

Prints, for each shared mesh, median wall times of ours vs the libigl peer and the ratio
(ours / peer; < 1 means we are faster):
  read      algorithms.mesh.read_mesh        vs igl.read_triangle_mesh
  edges     topology.unique_edges            vs igl.unique_edge_map
  boundary  topology.boundary_loops          vs igl.boundary_loop (all loops)
  normals   operators.vertex_normals         vs igl.per_vertex_normals (area weighting)
  validate  validate.validate_mesh           (no peer: the whole report; absolute time)

Usage: .venv/bin/python benchmarks/mesh_core.py [--repeat 5] [mesh names...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import igl
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _timing import median_seconds, mesh_path  # noqa: E402

from algorithms.mesh import read_mesh, validate_mesh  # noqa: E402
from algorithms.mesh.operators import vertex_normals  # noqa: E402
from algorithms.mesh.topology import boundary_loops, unique_edges  # noqa: E402

DEFAULT = ["spot_lowres.obj", "camelhead.off", "stanford-bunny.obj", "koala.obj", "igea.ply"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"{'mesh':20s} {'V':>8s} {'F':>8s} {'task':9s} {'ours ms':>9s} {'libigl ms':>10s} {'ratio':>6s}")
    for name in args.meshes:
        path = mesh_path(name)
        if not path.exists():
            print(f"{name}: not found (tests/data or $STYLIZE3D_MESHES), skipped")
            continue
        mesh = read_mesh(path)
        V, F = mesh.V, mesh.F
        Fi = np.ascontiguousarray(F)
        rows = [
            ("read", lambda: read_mesh(path), lambda: igl.read_triangle_mesh(str(path))),
            ("edges", lambda: unique_edges(F), lambda: igl.unique_edge_map(Fi)),
            ("boundary", lambda: boundary_loops(F), lambda: igl.boundary_loop_all(Fi)
             if hasattr(igl, "boundary_loop_all") else igl.boundary_loop(Fi)),
            ("normals", lambda: vertex_normals(V, F),
             lambda: igl.per_vertex_normals(V, Fi, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)),
            ("validate", lambda: validate_mesh(V, F), None),
        ]
        for task, ours, peer in rows:
            t_ours = median_seconds(ours, args.repeat)
            if peer is None:
                print(f"{name:20s} {len(V):8d} {len(F):8d} {task:9s} {1e3 * t_ours:9.1f} {'—':>10s} {'—':>6s}")
                continue
            t_peer = median_seconds(peer, args.repeat)
            print(f"{name:20s} {len(V):8d} {len(F):8d} {task:9s} {1e3 * t_ours:9.1f} "
                  f"{1e3 * t_peer:10.1f} {t_ours / t_peer:6.2f}")


if __name__ == "__main__":
    main()
