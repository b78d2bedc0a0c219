"""``import stylize3d``: the public names in one namespace (issue 39, item 13)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from tests.conftest import ROOT, SAMPLES


def test_the_namespace_is_the_implementation():
    import app
    import app.batch
    import app.recipes
    import stylize3d

    assert sorted(dir(stylize3d)) == sorted(stylize3d.__all__)
    assert stylize3d.load is app.recipes.load and stylize3d.run is app.recipes.run
    assert stylize3d.recipes is app.recipes.recipes and stylize3d.batch is app.batch
    assert stylize3d.__version__ == app.__version__
    r = stylize3d.run("cubic", stylize3d.load(SAMPLES / "blob-painted.s3d"),
                      {"max_iterations": 2})
    again = app.recipes.run("cubic", app.recipes.load(SAMPLES / "blob-painted.s3d"),
                            {"max_iterations": 2})
    assert np.array_equal(r.state.V, again.state.V)


def test_importing_it_costs_nothing():
    code = ("import sys, json, stylize3d; print(json.dumps([m for m in ('app.recipes', "
            "'app.batch', 'numba', 'PySide6', 'torch', 'scipy') if m in sys.modules]))")
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == []
