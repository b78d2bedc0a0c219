"""docs/scripting.md: every example runs as written (issue 20: one example per method)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

DOC = ROOT / "docs" / "scripting.md"


def _examples():
    text = DOC.read_text()
    blocks = re.findall(r"^### (.+?)\n.*?```python\n(.*?)```", text, flags=re.S | re.M)
    blocks.append(("Projects from a script",
                   re.search(r"## Projects from a script\n\n```python\n(.*?)```", text,
                             re.S).group(1)))
    return blocks


def test_there_is_one_example_per_method():
    titles = [t for t, _ in _examples()]
    assert len(titles) == 8, titles
    from app.recipes import recipes

    text = DOC.read_text()
    for r in recipes().values():  # every panel's main recipe appears in an example
        if ":" not in r.name and r.command not in ("smooth",):
            assert f'run("{r.command}"' in text, r.command


@pytest.mark.parametrize("title,code", _examples(), ids=lambda x: str(x)[:24])
def test_example_runs(title, code, tmp_path):
    if "adversary" in code:
        pytest.importorskip("torch")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=600, env={**__import__("os").environ,
                                         "STYLIZE3D_CACHE": str(tmp_path / "cache")})
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip(), "an example prints what it did"
    assert "PySide6" not in r.stderr
