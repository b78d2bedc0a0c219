"""Per-vertex field files: round trips, and every bad file refused with a message."""

import numpy as np
import pytest

from algorithms.errors import MeshReadError, MeshWriteError
from algorithms.mesh.fields import read_field, write_field


@pytest.mark.parametrize("ext", [".npy", ".txt", ".csv"])
def test_round_trip(tmp_path, ext):
    v = np.random.default_rng(0).normal(size=37)
    p = tmp_path / f"f{ext}"
    write_field(p, v)
    np.testing.assert_array_equal(read_field(p, 37), v)
    assert [q.name for q in tmp_path.iterdir()] == [p.name]  # no temporary file left


def test_text_header_comments_and_columns(tmp_path):
    p = tmp_path / "f.csv"
    p.write_text("# made by hand\nid,value\n0,1.5\n\n1,2.5\n2,-3\n")
    np.testing.assert_array_equal(read_field(p, 3, column=1), [1.5, 2.5, -3.0])
    np.testing.assert_array_equal(read_field(p, 3), [0.0, 1.0, 2.0])


@pytest.mark.parametrize("content,match", [
    ("1\n2\n", "has 2 values, but the mesh has 3"),
    ("1\nnan\n3\n", "NaN or infinite"),
    ("1\n2\nthree\n", "line 3 is not a number"),
])
def test_bad_text_files(tmp_path, content, match):
    p = tmp_path / "f.txt"
    p.write_text(content)
    with pytest.raises(MeshReadError, match=match):
        read_field(p, 3)


def test_bad_npy_and_binary_and_missing(tmp_path):
    p = tmp_path / "f.npy"
    np.save(p, np.zeros((3, 2)))
    with pytest.raises(MeshReadError, match=r"shape \(3, 2\)"):
        read_field(p, 3)
    p.write_bytes(b"garbage")
    with pytest.raises(MeshReadError, match="not a valid .npy"):
        read_field(p, 3)
    q = tmp_path / "f.txt"
    q.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(MeshReadError, match="binary"):
        read_field(q, 3)
    with pytest.raises(MeshReadError, match="Cannot read"):
        read_field(tmp_path / "missing.txt", 3)
    with pytest.raises(MeshReadError, match="use one of"):
        read_field(tmp_path / "f.obj", 3)


def test_failed_write_keeps_existing_file(tmp_path):
    p = tmp_path / "f.txt"
    p.write_text("keep me\n")
    with pytest.raises(MeshWriteError, match="use one of"):
        write_field(tmp_path / "f.xyz", [1.0])
    with pytest.raises(MeshWriteError, match="does not exist"):
        write_field(tmp_path / "nope" / "f.txt", [1.0])

    # a value that cannot be converted fails before anything is written
    with pytest.raises((MeshWriteError, ValueError, TypeError)):
        write_field(p, ["x"])
    assert p.read_text() == "keep me\n"
