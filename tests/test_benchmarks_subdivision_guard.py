"""benchmarks/subdivision_guard.py (issue 36): one mesh measured end to end, and the summary's
counts on made-up rows, column by column."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.conftest import ROOT, load_benchmark


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("subdivision_guard")


def test_one_mesh_measured(bench):
    """spot (tests/data) coarsened to 200 vertices, 1 level: four results, each measured; the
    guard keeps the network there (its row is the forced one), which is closer to spot than
    Loop's (as on the Table 4.2 protocol)."""
    rows = bench.measure(str(ROOT / "tests" / "data" / "spot_lowres.obj"), 200, [1], 5000, None)
    (row,) = rows
    assert row["mesh"] == "spot_lowres.obj" and row["levels"] == 1
    assert 190 <= row["coarse_vertices"] <= 210
    assert set(row["methods"]) == set(bench.METHODS)
    for m in row["methods"].values():
        assert all(math.isfinite(m[k]) and m[k] > 0 for k in ("H", "M", "bending", "normal"))
    # the normal error ranks the schemes as the distances do on spot: the network's normals
    # are the closest to the original's, Loop's (which rounds the ears) farther
    assert row["methods"]["forced"]["normal"] < row["methods"]["loop"]["normal"]
    assert row["levels_used"] == ["neural"]
    assert row["guard_is_forced"] and row["methods"]["guard"] == row["methods"]["forced"]
    assert row["methods"]["forced"]["M"] < row["methods"]["loop"]["M"]
    json.dumps(rows)  # JSON lines


def test_a_mesh_too_small_is_skipped_with_the_reason(bench):
    (row,) = bench.measure(str(ROOT / "tests" / "data" / "spot_lowres.obj"), 10_000, [1], 100,
                           None)
    assert "skipped" in row and "not more than 10000" in row["skipped"]


def _row(size, lv, used, g, f, lo, b):
    def m(h, mm, be, nrm=5.0):
        return {"H": h, "M": mm, "bending": be, "normal": nrm}
    return {"mesh": "x", "size": size, "levels": lv, "levels_used": used,
            "methods": {"guard": m(*g), "forced": m(*f), "loop": m(*lo), "butterfly": m(*b)}}


def test_summary_counts(bench):
    rows = [
        # network kept: guard == forced; H/M better than Loop; 3x Loop's bending
        _row(400, 2, ["neural", "neural"], (1.0, 0.10, 30, 4.0), (1.0, 0.10, 30, 4.0),
             (2.0, 0.3, 10, 6.0), (1.5, 0.2, 20, 5.0)),
        # guard fell back to Loop at level 2: bending 1.05x Loop's (<= 1.1x); H within 2 % of
        # min(forced 3.0, Loop 2.0)? 2.03 <= 2.04: yes; M 0.31 vs min(0.2, 0.3) * 1.02: no
        # normal error 6.7 against Loop's 6.0: above 1.1x (6.6)
        _row(400, 2, ["neural", "loop"], (2.03, 0.31, 10.5, 6.7), (3.0, 0.2, 90, 9.0),
             (2.0, 0.3, 10, 6.0), (2.5, 0.25, 20, 7.0)),
        _row(200, 1, ["loop"], (2.0, 0.3, 10), (3.0, 0.4, 50), (2.0, 0.3, 10), (2.5, 0.3, 20)),
        {"mesh": "y", "size": 400, "skipped": "5 vertices after cleaning"},
    ]
    text = bench.summarize(rows)
    lines = text.splitlines()
    row400 = next(x for x in lines if x.startswith("| 400 | 2 |"))
    cells = [c.strip() for c in row400.strip("|").split("|")]
    assert cells[2] == "2"                      # inputs
    assert cells[3] == "1 (50 %)"               # network on every level
    assert cells[4] == "2"                      # network on at least one level
    assert cells[5] == "1 (50 %)"               # guard <= 1.1x Loop's bending
    assert cells[6] == "2 (100 %) / 1 (50 %)"   # within 2 % on H / on M
    assert cells[7] == "1.515 / 2.000 / 2.000 / 2.000"
    assert cells[9] == "1 (50 %)"               # guard's normal error <= 1.1x Loop's
    assert cells[10] == "5.350 / 6.500 / 6.000 / 6.000"
    row200 = next(x for x in lines if x.startswith("| 200 | 1 |"))
    cells = [c.strip() for c in row200.strip("|").split("|")]
    assert cells[3] == "0 (0 %)" and cells[4] == "0" and cells[5] == "1 (100 %)"
    total = next(x for x in lines if x.startswith("| all | all |"))
    assert [c.strip() for c in total.strip("|").split("|")][2] == "3"
    assert "Skipped (1): y @ 400: 5 vertices after cleaning" in text
    assert np.isclose(float(cells[7].split(" / ")[0]), 2.0)


def test_summary_of_rows_without_the_normal_error(bench):
    """Rows measured before the normal error existed: its two columns say "-"."""
    row = _row(400, 1, ["neural"], (1.0, 0.1, 3), (1.0, 0.1, 3), (2.0, 0.2, 1), (1.5, 0.2, 2))
    for m in row["methods"].values():
        del m["normal"]
    line = next(x for x in bench.summarize([row]).splitlines() if x.startswith("| 400 | 1 |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[9] == "-" and cells[10] == "-" and cells[5] == "0 (0 %)"
