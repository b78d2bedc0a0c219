"""Lighting files (.json): the format `stylize3d adversary -o x.json` writes, read back exactly;
short files padded; plain errors for files that are not lighting."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.adversarial.lighting_io import (LIGHTING_FORMAT, LightingFileError,
                                                read_lighting, write_lighting)
from algorithms.errors import Stylize3DError
from algorithms.render.sh import environment


def test_round_trip_is_exact(tmp_path):
    U = np.random.default_rng(0).normal(size=(49, 3))
    p = tmp_path / "light.json"
    write_lighting(p, U)
    doc = json.loads(p.read_text())
    assert doc["format"] == LIGHTING_FORMAT and doc["degree"] == 6
    assert np.array(doc["coefficients"]).shape == (49, 3)
    np.testing.assert_array_equal(read_lighting(p), U)


def test_nine_coefficients_and_a_bare_list(tmp_path):
    U9 = environment("Grace Cathedral")[:9]
    p = tmp_path / "nine.json"
    p.write_text(json.dumps(U9.tolist()))
    U = read_lighting(p)
    assert U.shape == (49, 3)
    np.testing.assert_array_equal(U, environment("Grace Cathedral"))
    write_lighting(p, U9)                      # written padded to 49 rows
    assert len(json.loads(p.read_text())["coefficients"]) == 49


@pytest.mark.parametrize("text, words", [
    ("not json", "not JSON"),
    ('{"coefficients": [[1, 2, 3], [4, 5, 6]]}', "1, 4, 9"),
    ('{"coefficients": [[1, 2]]}', "1, 4, 9"),
    ('{"coefficients": "x"}', "1, 4, 9"),
    ('{"coefficients": [[1, 2, NaN]]}', "not finite"),
])
def test_plain_errors(tmp_path, text, words):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(LightingFileError) as e:
        read_lighting(p)
    assert words in str(e.value) and isinstance(e.value, Stylize3DError)
    with pytest.raises(LightingFileError, match="does not exist"):
        read_lighting(tmp_path / "missing.json")
