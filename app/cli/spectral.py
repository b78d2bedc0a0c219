"""``stylize3d coarsen``: spectral coarsening of a mesh operator (thesis ch. 7), with the QSlim
and algebraic-multigrid baselines measured the same way.

A thin wrapper around the recipe "Spectral coarsening" (:mod:`app.recipes.spectral`), run in
this process (option ``isolated`` false): Params from the flags (defaults < a project's saved
settings < ``--params`` < flags); options ``operator`` / ``alpha`` (``--operator``) and
``compare`` (``--compare``) over a project's saved ones (the command's own default compares
with nothing). The JSON, the table and ``-o OUT.npz`` (ours' L, M, P, G and K) come from the
recipe's outcome, so they equal ``app.recipes.run("coarsen", ...)``'s bit for bit; the seconds
each method took, which the outcome leaves out, are measured during the run.
"""

from __future__ import annotations

import argparse
import sys

from algorithms.errors import MeshWriteError, ParameterError
from app.cli.common import (MESH_HELP, add_params_arguments, add_params_file_argument,
                            check_output, input_state, method_params, method_recipe, print_json,
                            read_input, saved_panel)

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


#: the command's options before a project's saved ones and the flags: no baselines unless
#: asked for, in this process (the panel runs it in a child process)
CLI_OPTIONS = {"operator": "cotangent", "alpha": 10.0, "compare": [], "isolated": False}


def coarsen_options(args: argparse.Namespace) -> dict:
    """The recipe's options: :data:`CLI_OPTIONS` < the project's saved Spectral coarsening
    options < ``--operator`` / ``--compare``; always in this process."""
    saved = saved_panel(args, "Spectral coarsening")
    options = {**CLI_OPTIONS, **(saved["options"] if saved is not None else {})}
    if args.operator is not None:
        options["operator"], options["alpha"] = _parse_operator(args.operator)
    if args.compare is not None:
        given = [c for c in args.compare.split(",") if c]
        bad = [c for c in given if c not in ("ours", "qslim", "amg")]
        if bad:
            raise ParameterError(f"--compare takes qslim and/or amg (got {', '.join(bad)}).")
        options["compare"] = [c for c in dict.fromkeys(given) if c != "ours"]
    options["isolated"] = False
    return options


def _table(outcome: dict, seconds: dict) -> str:
    """The comparison as a text table (one row per method that ran)."""
    lines = [f"{'method':8s} {'m':>6s} {'C diag':>8s} {'eig mean':>9s} {'eig max':>9s} "
             f"{'s':>7s}"]
    for name in outcome["methods"]:
        lines.append(f"{name:8s} {int(outcome[f'{name}.L.shape'][0]):6d} "
                     f"{outcome[f'{name}.c_diag_score']:8.3f} "
                     f"{outcome[f'{name}.eig_rel_error_mean']:9.3g} "
                     f"{outcome[f'{name}.eig_rel_error_max']:9.3g} "
                     f"{seconds.get(name, float('nan')):7.2f}")
    return "\n".join(lines)


def _ours_matrices(outcome: dict) -> dict:
    """Ours' L, M, P, G (n × m prolongation) and K (m × n cluster indicator) from the outcome."""
    import numpy as np
    import scipy.sparse as sp

    from app.recipes.spectral import outcome_matrix

    arrays = {k: outcome_matrix(outcome, f"ours.{k}") for k in ("L", "M", "P", "G")}
    clusters = outcome["ours.clusters"]
    n = len(clusters)
    arrays["K"] = sp.csr_matrix((np.ones(n), (clusters, np.arange(n))),
                                shape=(arrays["P"].shape[0], n))
    return arrays


#: the eigenvectors (--k) that the advice for a mesh of many loose parts names
ADVICE_K = 10


def cmd_coarsen(args: argparse.Namespace) -> int:
    from algorithms.spectral.coarsen import CoarsenParams

    params = method_params(args, CoarsenParams, panel="Spectral coarsening")
    options = coarsen_options(args)
    if args.output:
        check_output(args.output, args.overwrite)
    data, _ = read_input(args, quiet=True)
    n = len(data.V)
    k = params.k or round(params.m / 3)
    if not 2 * k < params.m < n:
        if params.m >= n:
            m_ok = max(n // 2, 2 * params.k + 1) if params.k else n // 2
            fix = (f"ask for fewer: --m {m_ok}" if 3 <= m_ok < n and 2 * (params.k or round(
                m_ok / 3)) < m_ok else "this mesh is too small to coarsen")
            raise ParameterError(f"This mesh has {n:,} vertices, and the coarse operator was "
                                 f"to have {params.m:,} (--m, which must be fewer): {fix}.")
        raise ParameterError(f"{k} eigenvectors (--k) need more than {2 * k} coarse vertices "
                             f"(--m {params.m}): ask for --k {max((params.m - 1) // 2, 1)} or "
                             f"fewer, or a larger --m below {n:,}.")
    from algorithms.mesh.topology import connected_components

    # the parts the Laplacian's null vectors count (loose vertices each one)
    parts = connected_components(data.F, len(data.V), over="vertices")[0]
    if parts >= params.m:
        # the recipe's refusal, said with the flags that fix it (issue 38: the corpus's
        # abominevole, 1,740 loose parts after --clean, was refused with no flag named). Each
        # part takes one coarse vertex for its constant vector, and the k eigenvectors kept k
        # more: m = parts + k, with --k as given, else 10 (k = m / 3, the default, would make
        # that 2,610 coarse vertices and 870 eigenvectors there; --m 1750 --k 10 took 107 s
        # with one eigensolve of the whole, 2-3 s part by part since 30 November 2026)
        k_ok = params.k or ADVICE_K
        m_ok = max(parts + k_ok, 2 * k_ok + 1)
        fix = (f"ask for --m {m_ok}{'' if params.k else f' --k {k_ok}'} or more (one coarse "
               f"vertex per part and one per eigenvector kept), or remove its small loose "
               f"parts first" if m_ok < n
               else "this mesh is mostly loose pieces and cannot be coarsened")
        raise ParameterError(f"This mesh has {parts:,} separate parts, but the coarse operator "
                             f"was to have {params.m:,} vertices (--m): {fix}.")
    recipe = method_recipe("spectral", "Spectral coarsening")
    import time

    last = None
    shown_stage, shown_at = None, 0.0
    for last in recipe.steps(input_state(args, data), params, options, {}):
        if args.json or args.quiet or not last.message or last.total != 100:
            continue
        # the recipe's one progress (stage, step of total, time left): a line when the stage
        # changes and at most one every 2 s within it
        stage = last.message.split(":")[0].split(" ·")[0]
        now = time.perf_counter()
        if stage != shown_stage or now - shown_at >= 2.0:
            energy = (f" (energy {last.metrics['energy']:.6g})" if "energy" in last.metrics
                      else "")
            print(f"  {last.iteration:3d} %  {last.message}{energy}", file=sys.stderr)
            shown_stage, shown_at = stage, now
    outcome = recipe.outcome(last)
    seconds = last.seconds  # each method's time (the outcome holds none)
    out = {"n": outcome["n"], "m": outcome["m"], "k": outcome["k"],
           "methods": {}}   # a fixed interface
    for name in outcome["methods"]:
        d = {"c_diag_score": outcome[f"{name}.c_diag_score"],
             "eig_rel_err_mean": outcome[f"{name}.eig_rel_error_mean"],
             "eig_rel_err_max": outcome[f"{name}.eig_rel_error_max"],
             "seconds": seconds.get(name, float("nan"))}
        if name == "ours":
            # the thesis optimizer's (NADAM) iterations, capped by --max-iterations; the
            # balancing stage's come on top (--balance-iterations)
            d["iterations"] = outcome["ours.iterations"]
        out["methods"][name] = d
    if args.output:
        _save_npz(args.output, _ours_matrices(outcome))
    if args.json:
        print_json(out)
        for note in outcome["notes"]:  # a baseline left out: said on stderr, not in "methods"
            print(f"Note: {note}", file=sys.stderr)
    else:
        print(_table(outcome, seconds))
        for note in outcome["notes"]:
            print(f"Note: {note}")
        if args.output:
            print(f"Wrote {args.output}.")
    return 0


def add_parsers(sub) -> None:
    from algorithms.spectral.coarsen import CoarsenParams

    s = sub.add_parser("coarsen", help="spectral coarsening of a mesh operator (thesis ch. 7)")
    s.add_argument("mesh", help=MESH_HELP)
    s.add_argument("--operator",
                   help="cotan, idt (intrinsic Delaunay), aniso:ALPHA (anisotropic), graph or "
                        "pointcloud. Default: cotan (or the project's saved operator).")
    s.add_argument("--compare",
                   help="baselines to measure the same way: qslim,amg (\"\" for none). "
                        "Default: none (or the project's saved choice).")
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
