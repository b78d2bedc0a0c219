"""``stylize3d info`` and ``stylize3d clean``: check a mesh, fix what can be fixed."""

from __future__ import annotations

import argparse

from algorithms.errors import InvalidMeshError
from app.cli.common import MESH_HELP, check_output, print_json

COMMANDS = ("info", "clean")


def _read(path: str):
    """A mesh file's MeshData, or the mesh of a project (``.s3d``)."""
    from algorithms.mesh import MeshData, read_mesh
    from app.project import is_project_path, read_project

    if is_project_path(path):
        st = read_project(path).state
        return MeshData(st.V, st.F, [])
    return read_mesh(path)


def cmd_info(args: argparse.Namespace) -> int:
    from algorithms.mesh import validate_mesh

    data = _read(args.mesh)
    report = validate_mesh(data.V, data.F, notes=data.notes)
    # 0: every method accepts the mesh as it is; 4: it has errors or needs cleaning first
    accepted = report.ok and not report.needs_cleaning
    if args.json:
        out = {"file": str(args.mesh), "notes": list(data.notes)}
        out.update(report.to_dict())
        # "ok" says what the exit status says (issue 39); "valid": no errors (warnings may
        # still ask for Clean, "needs_cleaning")
        out.update(ok=accepted, valid=report.ok)
        print_json(out)
    else:
        print(f"{args.mesh}")
        print(report.summary())
    return 0 if accepted else InvalidMeshError.exit_code


def cmd_clean(args: argparse.Namespace) -> int:
    from algorithms.mesh import clean_mesh, validate_mesh, write_mesh

    check_output(args.output, args.overwrite, args.mesh)
    data = _read(args.mesh)
    result = clean_mesh(data.V, data.F, remove_invalid_faces=args.remove_invalid_faces)
    after = validate_mesh(result.V, result.F)
    if after.errors:
        raise InvalidMeshError("Clean could not fix everything, so nothing was written:\n"
                               + "\n".join(result.actions) + "\n" + after.summary())
    write_mesh(args.output, result.V, result.F)
    if args.json:
        print_json({"input": args.mesh, "output": args.output, "actions": list(result.actions),
                    "ok": after.ok, **after.to_dict()})
    else:
        for a in list(data.notes) + list(result.actions):
            print(a)
        print(f"Wrote {args.output} ({len(result.V)} vertices, {len(result.F)} triangles).")
        if not after.ok:
            print("Problems that Clean could not fix:\n" + after.summary())
    return 0 if after.ok else InvalidMeshError.exit_code


def add_parsers(sub) -> None:
    s = sub.add_parser("info", help="check a mesh and print its statistics",
                       description="Check a mesh and print its statistics. Exit status 0: every "
                                   "method accepts it as it is; 4: it has errors or needs "
                                   "cleaning first; 2: the file cannot be read.")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("--json", action="store_true", help="print the report as JSON")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("clean", help="fix what can be fixed in a mesh and say what was done")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("-o", "--output", required=True, help="where to write the cleaned mesh")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true")
    s.add_argument("--remove-invalid-faces", action="store_true",
                   help="also delete triangles that use missing vertices or NaN coordinates "
                        "(a damaged file; this opens holes, so it is not done by default)")
    s.set_defaults(func=cmd_clean)
