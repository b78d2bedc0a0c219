"""Project files (.s3d, app/project.py): round trip, safety, plain messages (Qt-free)."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from app.document import MeshState
from app.project import (VERSION, Project, ProjectError, project_bytes, read_project,
                         save_project)
from app.recipes import blob_bytes, put_blob, run


def _state():
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    n = len(V)
    lam = np.linspace(0.5, 2.0, n)
    fixed = np.zeros(n)
    fixed[:5] = 1.0
    frames = np.full(n, np.nan)
    frames[7] = 30.0
    st = MeshState.make(V, F, {"lambda_scale": lam, "fixed": fixed, "frame_ry": frames},
                        selection=np.arange(n) % 3 == 0)
    return st.with_handles({11: (0.1, 0.2, 1.3)})


def _same_state(a, b):
    np.testing.assert_array_equal(a.V, b.V)
    np.testing.assert_array_equal(a.F, b.F)
    assert sorted(a.fields) == sorted(b.fields)
    for k in a.fields:
        np.testing.assert_array_equal(a.fields[k], b.fields[k])  # NaN == NaN here
    assert a.handles == b.handles
    if a.selection is None:
        assert b.selection is None
    else:
        np.testing.assert_array_equal(a.selection, b.selection)


def test_round_trip_keeps_everything(tmp_path):
    st = _state()
    orig = MeshState.make(st.V * 2.0, st.F)
    ref = put_blob(b"P6 not really an image", "target.png")
    panels = {"Cubic": {"params": {"lam": 0.4}, "options": {"plane_axis": 2}},
              "Paparazzi": {"params": {}, "options": {"target_image": ref, "seed": 3}}}
    p = save_project(tmp_path / "scene", Project(st, orig, panels, source="blob.obj"))
    assert p.name == "scene.s3d" and p.is_file()
    back = read_project(p)
    _same_state(st, back.state)
    _same_state(orig, back.original)
    assert back.panels == panels and back.source == "blob.obj"
    assert back.params_of("Cubic") == {"lam": 0.4} and back.options_of("Nothing") == {}
    assert blob_bytes(ref) == b"P6 not really an image"
    # nothing in it is a pickle
    with zipfile.ZipFile(p) as z:
        for name in z.namelist():
            if name.endswith(".npy"):
                a = np.load(io.BytesIO(z.read(name)), allow_pickle=False)
                assert a.dtype != object


def test_overwrite_is_refused_when_asked(tmp_path):
    p = save_project(tmp_path / "a.s3d", Project(_state()))
    before = p.read_bytes()
    with pytest.raises(ProjectError, match="exists"):
        save_project(p, Project(_state().with_handles({})), overwrite=False)
    assert p.read_bytes() == before


def _rewrite(src, dest, change):
    """Copy a project, letting change(name, data) -> data (None drops the entry)."""
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(dest, "w") as out:
        for name in z.namelist():
            data = change(name, z.read(name))
            if data is not None:
                out.writestr(name, data)
    return dest


def test_damaged_newer_and_foreign_files_get_plain_messages(tmp_path):
    good = save_project(tmp_path / "good.s3d", Project(_state()))
    data = good.read_bytes()
    cases = {}
    (tmp_path / "cut.s3d").write_bytes(data[: len(data) // 2])
    cases["cut.s3d"] = "not a Stylize3D project file"
    (tmp_path / "text.s3d").write_text("hello")
    cases["text.s3d"] = "not a Stylize3D project file"

    def newer(name, d):
        if name != "project.json":
            return d
        m = json.loads(d)
        m["version"] = VERSION + 1
        m["app_version"] = "9.0"
        return json.dumps(m)

    _rewrite(good, tmp_path / "newer.s3d", newer)
    cases["newer.s3d"] = "newer|Update Stylize3D"
    _rewrite(good, tmp_path / "noarr.s3d", lambda n, d: None if n == "arrays/F.npy" else d)
    cases["noarr.s3d"] = "damaged.*missing"

    def bad_index(name, d):
        if name != "arrays/F.npy":
            return d
        F = np.load(io.BytesIO(d))
        F[0, 0] = 10 ** 6
        b = io.BytesIO()
        np.save(b, F)
        return b.getvalue()

    _rewrite(good, tmp_path / "index.s3d", bad_index)
    cases["index.s3d"] = "vertex that does not exist"

    def pickled(name, d):
        if name != "arrays/V.npy":
            return d
        b = io.BytesIO()
        np.save(b, np.array([object()] * 3, dtype=object), allow_pickle=True)
        return b.getvalue()

    _rewrite(good, tmp_path / "pickle.s3d", pickled)
    cases["pickle.s3d"] = "damaged"

    def nan(name, d):
        if name != "arrays/V.npy":
            return d
        V = np.load(io.BytesIO(d))
        V[3, 1] = np.nan
        b = io.BytesIO()
        np.save(b, V)
        return b.getvalue()

    _rewrite(good, tmp_path / "nan.s3d", nan)
    cases["nan.s3d"] = "not numbers"

    def other(name, d):
        if name != "project.json":
            return d
        m = json.loads(d)
        m["format"] = "something-else"
        return json.dumps(m)

    _rewrite(good, tmp_path / "other.s3d", other)
    cases["other.s3d"] = "not a Stylize3D project file"
    for name, pattern in cases.items():
        with pytest.raises(ProjectError, match=pattern):
            read_project(tmp_path / name)
    with pytest.raises(ProjectError, match="no project file"):
        read_project(tmp_path / "missing.s3d")


def test_a_blob_that_does_not_match_its_checksum_is_refused(tmp_path):
    ref = put_blob(b"style mesh bytes", "style.obj")
    p = save_project(tmp_path / "b.s3d",
                     Project(_state(), panels={"Analogies": {"options": {"style": ref}}}))
    digest = ref[len("blob:"):].split("/")[0]
    _rewrite(p, tmp_path / "c.s3d",
             lambda n, d: b"tampered" if n == f"blobs/{digest}/style.obj" else d)
    with pytest.raises(ProjectError, match="damaged"):
        read_project(tmp_path / "c.s3d")


def test_run_takes_the_projects_painting_and_saved_settings(tmp_path):
    st = _state().with_handles({})
    project = Project(st, panels={"Cubic": {"params": {"lam": 0.5, "max_iterations": 5},
                                            "options": {"plane_axis": 0}}})
    p = save_project(tmp_path / "s.s3d", project)
    a = run("cubic", read_project(p))
    b = run("Cubic", st, {"lam": 0.5, "max_iterations": 5}, {"plane_axis": 0})
    np.testing.assert_array_equal(a.state.V, b.state.V)
    # the fixed vertices stayed (the painted field is an input)
    fixed = st.fields["fixed"] > 0.5
    np.testing.assert_allclose(a.state.V[fixed], st.V[fixed], atol=1e-9)
    assert a.outcome["iterations"] == 5
    c = run("cubic", st, {"lam": 0.5, "max_iterations": 5})
    assert np.abs(c.state.V - st.V).max() > 0  # it did something
    assert project_bytes(project)  # bytes without a file


def test_unknown_method_says_what_exists():
    from algorithms.errors import ParameterError
    from app.recipes import get_recipe

    with pytest.raises(ParameterError, match="Did you mean 'cubic'"):
        get_recipe("cubc")
