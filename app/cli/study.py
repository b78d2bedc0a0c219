"""``stylize3d study replay|summary``: user-study logs, headless (no Qt)."""

from __future__ import annotations

import argparse

from app.cli.common import check_output, print_json, say

COMMANDS = ("study",)


def cmd_study(args: argparse.Namespace) -> int:
    """``stylize3d study replay|summary``: user-study logs, headless (no Qt)."""
    if args.study_command == "summary":
        from app.study.summary import summary_csv

        if args.output:
            check_output(args.output, args.overwrite)
        text, warnings = summary_csv(args.logs, args.output)
        for w in warnings:
            say(f"stylize3d study summary: {w}")
        if not args.output:
            print(text, end="")
        else:
            n = text.count("\n") - 1
            print(f"Wrote {args.output} ({n} row{'s' if n != 1 else ''}).")
        return 0
    from app.study.replay import replay_or_raise

    report = replay_or_raise(args.log, args.output)
    for w in report.warnings:
        say(f"stylize3d study replay: {w}")
    c = report.counts
    if args.json:
        print_json(report.to_dict())
    else:
        for r in report.runs:
            extra = f" ({r.reason})" if r.reason else ""
            if r.max_difference is not None:
                extra += f"; largest vertex difference {r.max_difference:.2e} of the diagonal"
            print(f"{r.kind} {r.index} [{r.task}] {r.method}: {r.status}{extra}")
        print(replay_summary_line(report))
    return 0 if not c.get("mismatch") and not c.get("failed") else 1


#: how each kind of check is named in the summary line (singular, plural)
_KIND_NAMES = {"run": ("finished run", "finished runs"), "edit": ("edit", "edits"),
               "undo": ("undo", "undos"), "redo": ("redo", "redos"),
               "task": ("task end state", "task end states")}


def replay_summary_line(report) -> str:
    """One sentence per kind of check: "5 of 5 finished runs reproduced their logged result
    exactly; 2 of 2 undos ..." (runs, edits, undo/redo and task checks counted apart)."""
    parts = []
    for kind, counts in report.counts_by_kind().items():
        total = sum(counts.values())
        one, many = _KIND_NAMES.get(kind, (kind, kind + "s"))
        s = (f"{counts.get('match', 0)} of {total} {one if total == 1 else many} "
             f"reproduced exactly")
        rest = [f"{counts[k]} {k}" for k in ("mismatch", "not replayable", "failed")
                if counts.get(k)]
        parts.append(s + (f" ({', '.join(rest)})" if rest else ""))
    return ("; ".join(parts) + ".") if parts else "Nothing to replay."


def add_parsers(sub) -> None:
    s = sub.add_parser("study", help="user-study logs: replay a session, summarize sessions")
    ss = s.add_subparsers(dest="study_command", metavar="replay|summary", required=True)
    r = ss.add_parser("replay", help="re-run a session's logged runs headless and check every "
                                     "result hash")
    r.add_argument("log", help="a session log (.jsonl)")
    r.add_argument("-o", "--output", metavar="DIR", help="write each replayed result here (OBJ)")
    r.add_argument("--json", action="store_true", help="print the report as JSON")
    r = ss.add_parser("summary", help="one CSV row per participant and task")
    r.add_argument("logs", nargs="+", help="session logs (.jsonl)")
    r.add_argument("-o", "--output", metavar="CSV", help="write the CSV here (default: print it)")
    r.add_argument("--overwrite", action="store_true", help="replace CSV if it exists")
    s.set_defaults(func=cmd_study)
