"""benchmarks/scale.py (issue 25): the exponent fit and the tables on synthetic numbers, and one
quick end-to-end run (cubic at 10^4 vertices, about 10 s on the shared CI machine)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import load_benchmark

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scale():
    return load_benchmark("scale")


NS = [14_587, 58_330, 233_281, 932_989]


def test_fit_exponent_linear_and_quadratic(scale):
    assert scale.fit_exponent(NS, [3e-6 * n for n in NS]) == pytest.approx(1.0, abs=1e-12)
    assert scale.fit_exponent(NS, [2e-11 * n * n for n in NS]) == pytest.approx(2.0, abs=1e-12)
    assert scale.fit_exponent(NS, [5.0] * 4) == pytest.approx(0.0, abs=1e-12)
    # n log n lies between 1 and 1.2 over these sizes
    import math

    a = scale.fit_exponent(NS, [n * math.log(n) for n in NS])
    assert 1.0 < a < 1.2


def test_fit_exponent_is_least_squares(scale):
    # noisy points: the slope of the least-squares line through (log n, log t)
    import numpy as np

    rng = np.random.default_rng(0)
    ts = [1e-7 * n ** 1.3 * float(np.exp(0.2 * rng.standard_normal())) for n in NS]
    want = np.polyfit(np.log(NS), np.log(ts), 1)[0]
    assert scale.fit_exponent(NS, ts) == pytest.approx(want, rel=1e-12)


def test_fit_exponent_skips_what_did_not_run(scale):
    assert scale.fit_exponent([1e4], [1.0]) is None
    assert scale.fit_exponent([1e4, 1e5], [1.0, None]) is None
    assert scale.fit_exponent([1e4, 1e4], [1.0, 2.0]) is None
    assert scale.fit_exponent([1e4, 1e5, 1e6], [1e-2, None, 1e2]) == pytest.approx(2.0)


def test_sizes_go_to_the_nearest_loop_level(scale):
    assert [scale.level_for_size(t, 14_587) for t in (1e4, 1e5, 1e6)] == [0, 1, 3]
    assert scale.level_for_size(2.3e5, 14_587) == 2
    assert scale.level_for_size(1e9, 14_587) == 3
    assert scale.level_for_size(10, 14_587) == 0


def _case(name, level, n, t, status="ok", **measures):
    if status != "ok":
        return dict(case=name, level=level, status=status, error="boom")
    return dict(case=name, level=level, n=n, status=status, base_mb=100.0,
                peak_mb=100.0 + n * 1e-3, measures={scale_main(name): t, **measures}, info="x")


def scale_main(name):
    return {"cubic": "per iteration", "arap_igl": "per iteration", "multigrid": "solve",
            "cholmod": "factor + solve"}[name]


def test_tables_on_synthetic_numbers(scale):
    levels = [0, 1, 3]
    ns = [NS[0], NS[1], NS[3]]
    cases = []
    for lev, n in zip(levels, ns):
        cases.append(_case("cubic", lev, n, 1e-6 * n, **{"set-up": 1e-10 * n * n}))
        cases.append(_case("arap_igl", lev, n, 2e-6 * n))
        if lev < 3:
            cases.append(_case("multigrid", lev, n, 1e-5 * n))
    cases.append(_case("multigrid", 3, None, None, status="timeout"))
    cases.append(_case("cholmod", 0, ns[0], 1.0))
    cases.append(_case("cholmod", 1, None, None, status="error"))
    md = "\n".join(scale.build_tables(cases, levels, ["cubic", "multigrid"], timeout=600))

    rows = {tuple(c.strip() for c in line.strip("|").split("|")) for line in md.splitlines()
            if line.startswith("| ")}

    def row(*start):
        hits = [r for r in rows if r[:len(start)] == start]
        assert len(hits) == 1, (start, md)
        return hits[0]

    assert row("case", "measure")[2:] == ("14.6k", "58.3k", "933.0k", "a")
    cubic = row("cubic stylization (ours)", "per iteration **(compared)**")
    assert cubic[-1] == "1.00"
    assert row("cubic stylization (ours)", "set-up")[-1] == "2.00"
    # the timed-out and failed cases are shown, not dropped
    mg = row("surface multigrid (ours)", "solve **(compared)**")
    assert mg[4] == "timeout (600 s)" and mg[-1] == "1.00"
    chol = row("CHOLMOD direct", "factor + solve **(compared)**")
    assert chol[2:] == ("1.00", "error", "not run", "-")
    # ratios ours / peer
    assert row("cubic", "per iteration / libigl ARAP per iteration")[2:] == ("0.50",) * 3
    ratio_mg = row("multigrid", "solve / CHOLMOD factor + solve")[2:]
    assert ratio_mg[0] == f"{1e-5 * ns[0] / 1.0:.2f}"
    assert ratio_mg[1:] == ("peer failed", "ours timed out")
    # memory: peak (base) and the exponent of peak - base (linear here)
    mem = [r for r in rows if r[0] == "cubic stylization (ours)" and len(r) == 5]
    assert mem and mem[0][1] == f"{100 + ns[0] * 1e-3:.0f} (100)" and mem[0][-1] == "1.00"
    assert "failed: boom" in md and "timed out after 600 s" in md


def test_quick_cubic_end_to_end(tmp_path):
    out = tmp_path / "scale.md"
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "scale.py"), "--quick",
                        "--methods", "cubic", "--out", str(out)],
                       capture_output=True, text=True, timeout=240, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    md = out.read_text()
    assert "python benchmarks/scale.py --quick --methods cubic" in md
    assert "Incomplete" not in md
    for case in ("cubic stylization (ours)", "ARAP (libigl)"):
        cells = re.search(rf"^\| {re.escape(case)} \| per iteration \*\*\(compared\)\*\* \| "
                          r"([0-9.e-]+) \| - \|$", md, re.M)
        assert cells, md
        assert float(cells.group(1)) > 0
    ratio = re.search(r"^\| cubic \| per iteration / libigl ARAP per iteration \| ([0-9.]+) \|$",
                      md, re.M)
    assert ratio and float(ratio.group(1)) > 0
    peak = re.search(r"^\| cubic stylization \(ours\) \| (\d+) \((\d+)\) \| - \|$", md, re.M)
    assert peak and int(peak.group(1)) >= int(peak.group(2)) > 0
    progress = [line for line in r.stdout.splitlines()
                if re.match(r"^  \S.* 14\.6k: .* peak ", line)]
    assert len(progress) == 2, r.stdout
