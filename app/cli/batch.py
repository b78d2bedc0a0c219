"""``stylize3d batch METHOD INPUT... -o OUT_DIR [batch flags] [the method's flags]``: one method
on a whole library of meshes, with local processes or a Dask cluster (:mod:`app.batch`;
docs/batch.md).

METHOD is a sub-command with a batch form (cubic, analogy, smooth, subdivide, paparazzi), a
project (``.s3d``: the settings of its panel, ``--panel NAME``) or a panel-settings ``.json``.
Exit status: 0 when every input is done or skipped, 1 when some failed (or the batch was
stopped), 2 for a mistyped METHOD, a missing INPUT or an unreadable settings file, 3 when
results would replace files the batch did not write (without --overwrite), 5 for a bad
parameter; 130 when interrupted (what is done is recorded: run the same command again).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from algorithms.errors import ParameterError
from app.cli.common import Terminated, print_json, say

COMMANDS = ("batch",)


def _check(args: argparse.Namespace) -> None:
    from app.batch import BatchUsageError

    if not args.inputs and not args.from_list:
        raise BatchUsageError("give at least one INPUT (mesh files, folders or globs).")
    if args.max_failures is not None and args.max_failures < 1:
        raise ParameterError(f"--max-failures must be at least 1 (got {args.max_failures}).")
    if not args.output:
        raise BatchUsageError("-o OUT_DIR is required (the folder the results go to).")
    if args.workers is not None and args.workers < 1:
        raise ParameterError(f"--workers must be at least 1 (got {args.workers}).")
    if args.time_limit is not None and not args.time_limit > 0:
        raise ParameterError(f"--time-limit must be a positive number of seconds (got "
                             f"{args.time_limit}).")
    if args.retries < 0:
        raise ParameterError(f"--retries must be 0 or more (got {args.retries}).")
    if Path(args.output).exists() and not Path(args.output).is_dir():
        raise BatchUsageError(f"-o {args.output} is a file; give a folder for the results.")


def _dry_run(job, args, inputs, outputs, report) -> int:
    from app.batch import plan

    items = plan(job, inputs, outputs, report, args.overwrite)
    runs = sum(it.action == "run" for it in items)
    if args.json:
        print_json({"dry_run": True, "job": job.describe(), "report": str(report),
                    "run": runs, "skip": len(items) - runs,
                    "items": [{"input": it.input, "output": it.output, "action": it.action,
                               "reason": it.reason} for it in items]})
        return 0
    for it in items:
        print(f"{it.action:4s}  {it.input} -> {it.output}  ({it.reason})")
    print(f"{runs} to run, {len(items) - runs} to skip; {job.method} with {job.source}; "
          f"report {report}. Nothing was run (--dry-run).")
    return 0


def _substitution(rec: dict) -> str:
    """``"; Loop subdivision instead of the network"`` for a record whose method fell back to
    another scheme (its figures' ``fallback``), and where the guard blended Loop's positions
    in over the network's bulges, how many vertices; else ''."""
    fig = rec.get("figures") or {}
    blended = int(fig.get("loop_blended_vertices") or 0)   # the guard's Loop over bulges
    if not fig.get("fallback") and not blended:
        return ""
    from app.recipes.subdivision import method_words

    return "; " + method_words(str(fig.get("method_used", "")), bool(fig.get("fallback")),
                               fig.get("levels_used") or (), blended)


def _one_line(message: str, limit: int = 240) -> str:
    """A failure's message on one line (a mesh report is several): the lines joined, cut at
    ``limit`` characters; the report keeps the whole message (issue 39 item 9)."""
    text = " ".join(part.strip(" -") for part in str(message).splitlines() if part.strip())
    return text if len(text) <= limit else text[:limit - 1].rstrip() + "… (the report has " \
                                                                       "the rest)"


class _Progress:
    """A rich progress bar on a terminal (done / failed / skipped / remaining, rate, ETA), or one
    plain line per mesh on stderr otherwise; nothing with --quiet."""

    def __init__(self, method: str, quiet: bool, console=None):
        self.quiet, self.bar, self.task = quiet, None, None
        self.substituted = 0  # meshes a method did with another scheme (said at the end)
        self.failed = 0       # failed meshes of this run (--max-failures)
        self.t0 = time.perf_counter()
        if not quiet and (console is not None or sys.stderr.isatty()):
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            console = console or Console(stderr=True)
            if console.width >= 120:
                counts = ("done {task.fields[done]} · failed {task.fields[failed]} · skipped "
                          "{task.fields[skipped]} · remaining {task.fields[remaining]} · "
                          "{task.fields[rate]}")
                bar = BarColumn()
            else:  # 80 columns: shorter words and bar, so the times are not cut
                counts = ("{task.fields[done]} ok {task.fields[failed]} failed "
                          "{task.fields[remaining]} left {task.fields[rate]}")
                bar = BarColumn(bar_width=10)
            self.bar = Progress(
                TextColumn(f"[bold]{method}"), bar, MofNCompleteColumn(), TextColumn(counts),
                TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                console=console)

    def __call__(self, rec: dict | None, counts: dict) -> None:
        ran = counts["done"] + counts["failed"]
        dt = time.perf_counter() - self.t0
        rate = f"{60 * ran / dt:.1f}/min" if ran and dt > 0 else "-/min"
        if self.bar is not None:
            fields = {k: v for k, v in counts.items() if k != "total"}
            if self.task is None:
                self.bar.start()
                self.task = self.bar.add_task("batch", total=counts["total"] - counts["skipped"],
                                              rate=rate, **fields)
            self.bar.update(self.task, completed=ran, rate=rate, **fields)
            if rec is not None and rec["status"] == "failed":
                from rich.text import Text

                self.bar.console.print(Text.assemble(("failed", "red"), f" {rec['input']}: "
                                                     f"{_one_line(rec['message'])}"),
                                       highlight=False, soft_wrap=True)
            elif rec is not None and rec["status"] == "done" and _substitution(rec):
                self.bar.console.print(f"done {rec['input']}{_substitution(rec)}",
                                       markup=False, highlight=False)
        elif not self.quiet and rec is not None:
            tail = f": {_one_line(rec['message'])}" if rec["status"] == "failed" else \
                f" -> {rec['output']} ({rec['seconds']:.1f} s{_substitution(rec)})"
            say(f"{rec['status']:6s} {rec['input']}{tail}")
        if rec is not None and rec["status"] == "done" and \
                (rec.get("figures") or {}).get("fallback"):
            self.substituted += 1
        if rec is not None and rec["status"] == "failed":
            self.failed += 1

    def close(self) -> None:
        if self.bar is not None and self.task is not None:
            self.bar.stop()


def _refuse_replacing(inputs, outputs, report, out, state_dir: str = ".batch") -> None:
    """Like every other command, never replace a file without --overwrite: only outputs this
    batch's report says it wrote itself are written again (a resumed or re-run batch)."""
    import os

    from algorithms.errors import MeshWriteError
    from app.batch import read_report

    recorded = read_report(report)
    # records the workers of a stopped driver left for the report (what run_batch recovers
    # first): their outputs were written by this batch too (issue 39, item 1)
    for f in sorted((Path(out) / state_dir / "pending").glob("*.json")):
        try:
            rec = json.loads(f.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(rec, dict) and rec.get("input") and rec.get("output"):
            recorded.setdefault(rec["input"], rec)
    clash = [str(o) for i, o in zip(inputs, outputs) if Path(o).exists()
             and (recorded.get(os.path.abspath(i)) or recorded.get(str(i)) or {}).get("output")
             not in (str(o), os.path.abspath(o))]
    if clash:
        raise MeshWriteError(
            f"{len(clash)} result(s) would replace files that are already in the output folder "
            f"and were not written by this batch (e.g. {clash[0]}); nothing was run. Give "
            "another -o folder, or --overwrite to replace them.")


def cmd_batch(args: argparse.Namespace) -> int:
    from app import batch

    try:
        job, bargs = batch.parse_batch_args(args.method, list(args.rest))
    except SystemExit as e:  # argparse printed its usage message
        return int(e.code or 0)
    _check(bargs)
    out = Path(bargs.output)
    from app.batch.inputs import excluded, in_shard, parse_shard, read_input_list, shard_names

    shard = parse_shard(bargs.shard) if bargs.shard else None
    items = list(bargs.inputs) + (read_input_list(bargs.from_list) if bargs.from_list else [])
    found = [(p, r) for p, r in batch.collect_inputs_with_roots(items, out_dir=out)
             if not excluded(p, r, bargs.exclude)]
    if not found:
        raise batch.BatchUsageError(f"No mesh files ({', '.join(batch.inputs.INPUT_SUFFIXES)}) "
                                    f"in {', '.join(map(str, items))}"
                                    + (" (after --exclude)." if bargs.exclude else "."))
    if shard is not None:
        every = len(found)
        found = [(p, r) for p, r in found if in_shard(p, r, shard)]
        say(f"stylize3d batch: shard {shard[0]}/{shard[1]}: {len(found)} of {every} input(s).")
        if not found:
            if bargs.json:
                print_json({"ok": True, "shard": list(shard), "total": 0, "done": 0,
                            "failed": 0, "skipped": 0})
            return 0
    report_name, state_dir = shard_names(shard)
    inputs = [p for p, _ in found]
    outputs = batch.output_names(inputs, out, roots=[r for _, r in found], fmt=bargs.format,
                                 name=bargs.name, command=job.method)
    report = Path(bargs.report).resolve() if bargs.report else out.resolve() / report_name
    if bargs.dry_run:
        return _dry_run(job, bargs, inputs, outputs, report)
    if not bargs.overwrite:
        _refuse_replacing(inputs, outputs, report, out, state_dir)
    memory = batch.parse_size(bargs.memory_limit) if bargs.memory_limit else "auto"
    progress = _Progress(job.method, bargs.quiet)
    try:
        summary = batch.run_batch(job, inputs, out, workers=bargs.workers,
                                  scheduler=bargs.scheduler, report=report, memory_limit=memory,
                                  time_limit=bargs.time_limit, retries=bargs.retries,
                                  redo=bargs.overwrite, outputs=outputs, on_record=progress,
                                  should_stop=lambda: bargs.max_failures is not None
                                  and progress.failed >= bargs.max_failures,
                                  state_dir=state_dir)
    except KeyboardInterrupt as e:  # Ctrl+C, or SIGTERM (common.Terminated)
        progress.close()
        term = isinstance(e, Terminated)
        say(f"stylize3d batch: {'stopped (SIGTERM)' if term else 'interrupted'}. What was done "
            f"is recorded in {report}; run the same command again to finish (done meshes are "
            "skipped).")
        return 143 if term else 130
    progress.close()
    if summary.stopped and bargs.max_failures is not None \
            and progress.failed >= bargs.max_failures:
        say(f"stylize3d batch: stopped after {progress.failed} failed mesh(es) "
            f"(--max-failures {bargs.max_failures}). What was done is recorded in {report}; "
            "the same command goes on (done meshes are skipped).")
    if bargs.json:
        print_json({"method": job.method, "recipe": job.recipe, "source": job.source,
                    **summary.to_dict(), "substituted": progress.substituted})
    else:
        sub = (f" {progress.substituted} of them with another scheme than asked (their "
               "records say \"fallback\": true and which ran)." if progress.substituted else "")
        print(f"Batch {job.method}: {summary.done} done, {summary.failed} failed, "
              f"{summary.skipped} skipped of {summary.total} in {summary.seconds:.1f} s "
              f"({60 * summary.throughput:.1f} meshes/min); results in {out}, report "
              f"{report}.{sub}")
    return summary.exit_code


def add_parsers(sub) -> None:
    from app.batch.jobs import METHODS

    s = sub.add_parser(
        "batch", help="run a method on many meshes (local processes or a Dask cluster)",
        usage="stylize3d batch METHOD INPUT... -o OUT_DIR [--workers N] [--scheduler ADDRESS] "
              "[--report FILE] [--memory-limit SIZE] [--time-limit S] [--dry-run] [--json] "
              "[--quiet] [--clean] [--format FMT] [--name TEMPLATE] [--exclude GLOB] "
              "[--from-list FILE] [--shard I/N] [--max-failures N] [the method's flags]",
        description="Run one method on every INPUT; results go to OUT_DIR under the inputs' "
                    "file names, one JSON line per input goes to the report. A batch that is "
                    "stopped and started again skips what is done. 'stylize3d batch METHOD "
                    "--help' lists the method's flags and the batch's. Exit status: 0 all "
                    "done or skipped, 1 some failed, 2 usage, 3 would replace files it did "
                    "not write (--overwrite), 5 bad parameter.")
    s.add_argument("method", metavar="METHOD",
                   help=f"{', '.join(METHODS)}; or a project (.s3d) or panel-settings .json "
                        "whose settings to apply")
    s.add_argument("rest", nargs=argparse.REMAINDER, metavar="...",
                   help="INPUT... -o OUT_DIR and the flags")
    s.set_defaults(func=cmd_batch)
