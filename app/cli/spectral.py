"""``stylize3d coarsen``: spectral coarsening of a mesh operator (thesis ch. 7), with the QSlim
and algebraic-multigrid baselines measured the same way."""

from __future__ import annotations

import argparse
import sys

from algorithms.errors import MeshWriteError, ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, method_params, print_json, read_input)

COMMANDS = ("coarsen",)

OPERATOR_NAMES = {"cotan": "cotangent", "idt": "intrinsic_delaunay", "graph": "graph",
                  "pointcloud": "point_cloud", "aniso": "anisotropic"}


def _parse_operator(text: str) -> tuple[str, float]:
    """'cotan' | 'idt' | 'graph' | 'pointcloud' | 'aniso:ALPHA' -> (operator name, alpha)."""
    name, _, arg = text.partition(":")
    if name not in OPERATOR_NAMES:
        raise ParameterError(f"Unknown operator '{text}': use cotan, idt, aniso:ALPHA, graph or "
                             "pointcloud.")
    alpha = 10.0
    if arg:
        try:
            alpha = float(arg)
        except ValueError:
            raise ParameterError(f"The anisotropy in '{text}' must be a number, e.g. aniso:70.")
    return OPERATOR_NAMES[name], alpha


def _save_npz(path: str, arrays: dict) -> None:
    """Atomic .npz of sparse/dense arrays (sparse as name_data/_indices/_indptr/_shape)."""
    import os
    import tempfile

    import numpy as np
    import scipy.sparse as sp

    flat = {}
    for k, a in arrays.items():
        if sp.issparse(a):
            a = sp.csr_matrix(a)
            flat.update({f"{k}_data": a.data, f"{k}_indices": a.indices, f"{k}_indptr": a.indptr,
                         f"{k}_shape": np.array(a.shape)})
        else:
            flat[k] = np.asarray(a)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **flat)
        os.replace(tmp, path)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise MeshWriteError(f"Could not write {path}: {e.strerror or e}") from None


def cmd_coarsen(args: argparse.Namespace) -> int:
    from algorithms.spectral.coarsen import CoarsenParams
    from algorithms.spectral.compare import compare_coarsenings

    params = method_params(args, CoarsenParams, panel="Spectral coarsening")
    operator, alpha = _parse_operator(args.operator)
    methods = ["ours"] + [c for c in (args.compare.split(",") if args.compare else []) if c]
    bad = [c for c in methods if c not in ("ours", "qslim", "amg")]
    if bad:
        raise ParameterError(f"--compare takes qslim and/or amg (got {', '.join(bad)}).")
    if args.output:
        check_output(args.output, args.overwrite)
    data, _ = read_input(args, quiet=True)
    n = len(data.V)
    if not 2 * (params.k or round(params.m / 3)) < params.m < n:
        raise ParameterError(f"Need 2k < m < n (here n = {n}, m = {params.m}, k = "
                             f"{params.k or round(params.m / 3)}).")
    iterations = {"n": 0}

    def progress(step):
        iterations["n"] = step.iteration
        if not args.json and not args.quiet and step.iteration % 50 == 0:
            print(f"  iteration {step.iteration}: energy {step.energy:.6g}", file=sys.stderr)

    cmp_ = compare_coarsenings(data.V, data.F, operator, m=params.m, k=params.k or None,
                               params=params, methods=tuple(dict.fromkeys(methods)),
                               alpha=alpha, callback=progress)
    out = {"n": cmp_.n, "m": cmp_.m, "k": cmp_.k, "methods": {}}   # a fixed interface
    for name, r in cmp_.methods.items():
        d = {"c_diag_score": r.metrics["c_diag_score"],
             "eig_rel_err_mean": r.metrics["eig_rel_error_mean"],
             "eig_rel_err_max": r.metrics["eig_rel_error_max"], "seconds": r.seconds}
        if name == "ours":
            # the thesis optimizer's (NADAM) iterations, capped by --max-iterations; the
            # balancing stage's come on top (--balance-iterations)
            d["iterations"] = int(cmp_.timings.get("ours_iterations", iterations["n"]))
        out["methods"][name] = d
    if args.output:
        ours = cmp_.methods["ours"]
        _save_npz(args.output, {"L": ours.L, "M": ours.M, "P": ours.P,
                                "G": ours.extra["G"], "K": ours.extra["K"]})
    if args.json:
        print_json(out)
        for note in cmp_.notes:   # a baseline left out: said on stderr, absent from "methods"
            print(f"Note: {note}", file=sys.stderr)
    else:
        print(cmp_.table())
        for note in cmp_.notes:
            print(f"Note: {note}")
        if args.output:
            print(f"Wrote {args.output}.")
    return 0


def add_parsers(sub) -> None:
    from algorithms.spectral.coarsen import CoarsenParams

    s = sub.add_parser("coarsen", help="spectral coarsening of a mesh operator (thesis ch. 7)")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("--operator", default="cotan",
                   help="cotan, idt (intrinsic Delaunay), aniso:ALPHA (anisotropic), graph or "
                        "pointcloud. Default: cotan.")
    s.add_argument("--compare", default="",
                   help="baselines to measure the same way: qslim,amg")
    s.add_argument("-o", "--output", help="write ours (L, M, P, G, K) as .npz")
    s.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    s.add_argument("--json", action="store_true",
                   help='print {"n", "m", "k", "methods": {name: {"c_diag_score", '
                        '"eig_rel_err_mean", "eig_rel_err_max", "seconds"}}}')
    s.add_argument("--quiet", action="store_true", help="no progress")
    s.add_argument("--clean", action="store_true", help="clean the mesh first")
    add_params_file_argument(s)
    add_params_arguments(s, CoarsenParams)
    s.set_defaults(func=cmd_coarsen)
