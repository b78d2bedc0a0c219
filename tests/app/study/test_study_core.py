"""Study protocol, session log and summary: the Qt-free core of user-study mode (issue 15)."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from app.study.log import LOG_FORMAT, SessionLog, mesh_hash, read_log, state_hash
from app.study.protocol import (StudyError, balanced_latin_square, check_against_panels,
                                load_protocol, parse_protocol)
from app.study.summary import summary_csv, sus_score
from tests.conftest import SAMPLES

PROTO = {
    "study": "pilot",
    "conditions": ["A", "B"],
    "counterbalance": True,
    "tasks": [
        {"id": "t1", "title": "Cubic", "instructions": "Make it cubic.", "mesh": "sample:blob",
         "time_limit_s": 120, "questionnaire": "sus",
         "conditions": {"A": {"panels": ["Cubic"], "locked_panels": ["Smooth"],
                              "params": {"Cubic": {"lam": 0.4}}}}},
        {"id": "t2", "title": "Smooth", "instructions": "Smooth it.", "mesh": "sample:bumpy",
         "questionnaire": [{"id": "ease", "type": "likert", "text": "Easy?", "scale": 7},
                           {"id": "comment", "type": "text", "text": "Anything else?"}]},
        {"id": "t3", "instructions": "Free.", "mesh": "sample:pretzel"},
    ],
}


def write_proto(tmp_path, data, name="study.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def test_protocol_json_and_toml_load_the_same(tmp_path):
    pj = load_protocol(write_proto(tmp_path, PROTO))
    toml = tmp_path / "study.toml"
    mesh = tmp_path / "m.obj"
    mesh.write_bytes((SAMPLES / "blob.obj").read_bytes())
    toml.write_text('study = "pilot"\nconditions = ["A"]\n[[tasks]]\nid = "t1"\n'
                    'instructions = "Go."\nmesh = "m.obj"\nquestionnaire = "sus"\n'
                    '[tasks.conditions.A]\npanels = ["Cubic"]\n'
                    'params = { Cubic = { lam = 0.3 } }\n')
    pt = load_protocol(toml)
    assert pj.study == pt.study == "pilot"
    assert pt.tasks[0].mesh == str(mesh.resolve())
    assert pt.tasks[0].setup("A").panels == ("Cubic",)
    assert pt.tasks[0].setup("A").params == {"Cubic": {"lam": 0.3}}
    assert len(pt.tasks[0].questionnaire) == 10 and pt.tasks[0].questionnaire_name == "sus"
    assert pj.tasks[0].setup("B").panels is None  # no setup for B: everything allowed
    assert len(pj.sha256) == 64


@pytest.mark.parametrize("broken, says", [
    ("{not json", "not valid JSON"),
    (json.dumps({**PROTO, "study": "has space"}), "'study' must be an id"),
    (json.dumps({**PROTO, "tasks": []}), "non-empty list of tasks"),
    (json.dumps({**PROTO, "tasks": [{**PROTO["tasks"][0], "mesh": "missing.obj"}]}),
     "does not exist"),
    (json.dumps({**PROTO, "tasks": [{**PROTO["tasks"][0], "time_limit_s": -3}]}),
     "'time_limit_s'"),
    (json.dumps({**PROTO, "tasks": [{**PROTO["tasks"][0], "conditions": {"C": {}}}]}),
     "condition 'C' is not in the study's conditions"),
    (json.dumps({**PROTO, "tasks": [PROTO["tasks"][0], PROTO["tasks"][0]]}), "used twice"),
    (json.dumps({**PROTO, "format": 9}), "newer Stylize3D"),
    (json.dumps({**PROTO, "colour": 1}), "Unknown protocol field"),
    (json.dumps({**PROTO, "tasks": [{**PROTO["tasks"][1], "questionnaire": [
        {"id": "x", "type": "likert", "text": "?", "scale": 2}]}]}), "'scale'"),
])
def test_malformed_protocol_is_a_plain_message(tmp_path, broken, says):
    p = tmp_path / "bad.json"
    p.write_text(broken)
    with pytest.raises(StudyError) as e:
        load_protocol(p)
    assert says in str(e.value)


def test_protocol_checked_against_the_apps_panels(tmp_path):
    from algorithms.deform.cubic import CubicParams
    from algorithms.smoothing import SmoothParams

    proto = load_protocol(write_proto(tmp_path, PROTO))
    panels = {"Cubic": CubicParams, "Smooth": SmoothParams}
    check_against_panels(proto, panels)
    bad = json.loads(json.dumps(PROTO))
    bad["tasks"][0]["conditions"]["A"]["params"] = {"Cubic": {"lam": -5}}
    with pytest.raises(StudyError, match="Task 't1', condition 'A', panel 'Cubic'"):
        check_against_panels(load_protocol(write_proto(tmp_path, bad, "b.json")), panels)
    bad["tasks"][0]["conditions"]["A"]["params"] = {"Cubc": {"lam": 0.1}}
    with pytest.raises(StudyError, match="no panel 'Cubc'"):
        check_against_panels(load_protocol(write_proto(tmp_path, bad, "c.json")), panels)


def test_balanced_latin_square_properties():
    for n in (2, 3, 4, 5):
        rows = balanced_latin_square(n)
        assert all(sorted(r) == list(range(n)) for r in rows)
        # every task comes first equally often, every ordered adjacent pair equally often
        firsts = [r[0] for r in rows]
        assert len(set(firsts.count(k) for k in range(n))) == 1
        pairs = [(r[i], r[i + 1]) for r in rows for i in range(n - 1)]
        counts = {(a, b): pairs.count((a, b)) for a in range(n) for b in range(n) if a != b}
        assert len(set(counts.values())) == 1


def test_task_order_counterbalanced_by_participant_number(tmp_path):
    proto = load_protocol(write_proto(tmp_path, PROTO))
    orders = {tuple(proto.task_order(f"P{k:02d}")) for k in range(6)}
    assert len(orders) == 6  # 3 tasks, odd: 2n = 6 rows, all used
    assert proto.task_order("P01") == proto.task_order("P07")  # 7 % 6 == 1
    plain = parse_protocol({**PROTO, "counterbalance": False})
    assert plain.task_order("P03") == ["t1", "t2", "t3"]


def new_log(tmp_path, name="P01.jsonl"):
    return SessionLog.create(tmp_path / name, study="pilot", protocol_path=None,
                             protocol_sha256="0" * 64, participant="P01", condition="A",
                             task_order=["t1", "t2"], app_version="test")


def test_log_round_trip_and_monotonic_times(tmp_path):
    log = new_log(tmp_path)
    log.task = "t1"
    log.write("task_start")
    log.write("run", method="Cubic", params={"lam": 0.2}, input_hash="a" * 64)
    log.write("result", method="Cubic", status="done", params={"lam": 0.2},
              result_hash="b" * 64, seconds=np.float64(1.5))
    log.write("task_end", status="done", result_hash="b" * 64)
    log.close()
    data = read_log(tmp_path / "P01.jsonl")
    assert data.header["log_format"] == LOG_FORMAT and data.participant == "P01"
    assert [e["action"] for e in data.events] == ["task_start", "run", "result", "task_end"]
    t = [e["t_mono"] for e in data.events]
    assert t == sorted(t) and data.events[2]["seconds"] == 1.5
    assert not data.warnings and data.current_task is None and data.finished_tasks == ["t1"]
    with pytest.raises(StudyError, match="already exists"):
        new_log(tmp_path)


def test_truncated_last_line_is_skipped_and_the_session_resumes(tmp_path):
    log = new_log(tmp_path)
    log.task = "t1"
    log.write("task_start")
    log.write("undo", text="Cubic")
    log.close()
    p = tmp_path / "P01.jsonl"
    with open(p, "a") as f:
        f.write('{"t_wall": 1, "t_mono": 9.0, "task": "t1", "act')  # killed mid-line
    data = read_log(p)
    assert data.truncated and "cut off" in data.warnings[0]
    assert [e["action"] for e in data.events] == ["task_start", "undo"]
    assert data.current_task == "t1"
    log2, before = SessionLog.resume(p)
    assert log2.task == "t1"
    log2.write("task_end", status="done")
    log2.close()
    after = read_log(p)
    assert not after.warnings
    assert [e["action"] for e in after.events] == ["task_start", "undo", "resume", "task_end"]
    assert after.events[2]["t_mono"] >= after.events[1]["t_mono"]


@pytest.mark.parametrize("content, says", [
    ('{"log_format": 2, "type": "session"}\n', "newer Stylize3D"),
    ('{"hello": 1}\n', "not a Stylize3D session log"),
    ("", "empty"),
    ('{"log_format": 1, "type": "session"}\nnot json\n{"action": "x", "t_mono": 1}\n',
     "line 2"),
])
def test_bad_logs_are_plain_messages(tmp_path, content, says):
    p = tmp_path / "x.jsonl"
    p.write_text(content)
    with pytest.raises(StudyError, match=says):
        read_log(p)


def test_hashes_change_with_every_part_of_the_state():
    V = np.random.default_rng(0).random((5, 3))
    F = np.array([[0, 1, 2], [2, 3, 4]])
    h = mesh_hash(V, F)
    assert h == mesh_hash(V.copy(), F.astype(np.int32))  # dtype and copies do not matter
    V2 = V.copy()
    V2[0, 0] = np.nextafter(V2[0, 0], 2)  # one ulp
    assert mesh_hash(V2, F) != h
    s = state_hash(V, F)
    assert state_hash(V, F, {"lam": np.ones(5)}) != s
    assert state_hash(V, F, handles=((1, (0.0, 0.0, 1.0)),)) != s


def test_sus_score_known_values():
    assert sus_score({f"sus{i}": 3 for i in range(1, 11)}) == 50.0
    best = {f"sus{i}": (5 if i % 2 else 1) for i in range(1, 11)}
    assert sus_score(best) == 100.0
    assert sus_score({"sus1": 5}) is None


def test_summary_csv_rows(tmp_path):
    for code, cond in (("P01", "A"), ("P02", "B")):
        log = SessionLog.create(tmp_path / f"{code}.jsonl", study="pilot", protocol_path=None,
                                protocol_sha256="0" * 64, participant=code, condition=cond,
                                task_order=["t2", "t1"])
        for task in ("t2", "t1"):
            log.task = task
            log.write("task_start")
            log.write("open", mesh="sample:blob", mesh_hash="m0")
            log.write("camera", position=[0, 0, 1])
            log.write("run", method="Smooth", params={"iterations": 3})
            log.write("result", method="Smooth", status="done", params={"iterations": 3},
                      result_hash="r1")
            log.write("undo", text="Smooth", result_hash="m0")
            log.write("questionnaire", answers={f"sus{i}": 3 for i in range(1, 11)}
                      if task == "t1" else {"ease": 6, "comment": "ok, fine"})
            log.write("task_end", status="done" if task == "t1" else "skipped",
                      result_hash="m0")
        log.close()
    out = tmp_path / "summary.csv"
    text, warnings = summary_csv([tmp_path / "P01.jsonl", tmp_path / "P02.jsonl"], out)
    assert out.read_text() == text and not warnings
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [(r["participant"], r["task"], r["order"]) for r in rows] == [
        ("P01", "t2", "1"), ("P01", "t1", "2"), ("P02", "t2", "1"), ("P02", "t1", "2")]
    r = rows[1]
    assert r["condition"] == "A" and r["status"] == "done" and float(r["seconds"]) >= 0
    assert r["runs"] == "1" and r["undo"] == "1" and r["camera_moves"] == "1"
    assert r["actions"] == "3"  # run, undo, questionnaire (camera and results not counted)
    assert json.loads(r["final_params"]) == {}  # the run was undone: the task ended on the input
    assert r["sus_score"] == "50.0" and r["q_sus1"] == "3"
    assert rows[0]["status"] == "skipped" and rows[0]["q_ease"] == "6"
    assert rows[0]["q_comment"] == "ok, fine" and rows[0]["sus_score"] == ""


def test_summary_final_params_and_seconds_describe_the_tasks_end(tmp_path):
    """Issue 41: ``final_params`` named a live run the participant undid (λ 0.85) while
    ``result_hash`` was the kept λ 0.2 result; ``seconds`` differed from task_end's. Every
    column describes the task's final state; one definition of the task's time."""
    log = SessionLog.create(tmp_path / "P03.jsonl", study="pilot", protocol_path=None,
                            protocol_sha256="0" * 64, participant="P03", condition="A",
                            task_order=["t"])
    log.task = "t"
    start = log.write("task_start")["t_mono"]
    log.write("open", mesh="sample:blob", mesh_hash="m0")

    def run(method, params, h):
        log.write("run", method=method, params=params)
        log.write("result", method=method, status="done", params=params, result_hash=h)

    run("Cubic", {"lambda_": 0.2}, "c2")
    run("Smooth", {"iterations": 2}, "s2")          # on top of the cubic result
    run("Cubic", {"lambda_": 0.85}, "c85")          # a live run on top of both ...
    log.write("undo", text="Cubic", result_hash="s2")   # ... undone
    log.write("undo", text="Smooth", result_hash="c2")  # and the smoothing too
    log.write("redo", text="Smooth", result_hash="s2")  # redone
    log.write("edit", text="Paint λ", after_hash="p1")  # a stroke keeps the runs' params
    run("Spectral coarsening", {"target": 100}, "p1")   # an analysis: the state stays
    log.write("run", method="Cubic", params={"lambda_": 0.5})
    log.write("result", method="Cubic", status="failed", params={"lambda_": 0.5})
    t = log.now() + 1.25
    log.write("task_end", at=t, status="done", result_hash="p1", seconds=round(t - start, 3))
    log.close()
    text, _ = summary_csv([tmp_path / "P03.jsonl"])
    (r,) = list(csv.DictReader(io.StringIO(text)))
    assert json.loads(r["final_params"]) == {"Cubic": {"lambda_": 0.2},
                                             "Smooth": {"iterations": 2},
                                             "Spectral coarsening": {"target": 100}}
    assert r["result_hash"] == "p1" and r["failed_runs"] == "1" and r["runs"] == "5"
    end = read_log(tmp_path / "P03.jsonl").events[-1]
    assert r["seconds"] == str(end["seconds"]) and end["t_mono"] == t
