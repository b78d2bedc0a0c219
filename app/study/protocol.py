"""Study protocol files: what a user-study session asks of its participants (Qt-free).

A protocol is a JSON or TOML file::

    study = "cubic-vs-analogies"      # study id (letters, digits, - and _)
    format = 1                          # protocol format (this version reads 1)
    conditions = ["A", "B"]            # at least one
    counterbalance = true               # task order per participant: a balanced Latin square row

    [[tasks]]
    id = "bunny-cube"
    title = "Make the bunny cubic"
    instructions = "Make the bunny look like it is built from cubes. Press Done when happy."
    image = "images/cube.png"          # optional picture shown with the instructions
    mesh = "meshes/bunny.obj"          # relative to the protocol file, or "sample:blob"
    time_limit_s = 300                  # optional; the task ends itself when time is up
    questionnaire = "sus"               # optional: "sus" or a list of items (below)

    [tasks.conditions.A]                # optional, per condition
    panels = ["Cubic"]                  # panels the participant may use (default: all)
    locked_panels = ["Analogies"]       # shown but disabled (default: none)
    params = { Cubic = { lam = 0.4 } }  # parameter values set and locked for this task

Questionnaire items are ``{id, type: "likert", text, scale (3-11), labels: [low, high]}`` or
``{id, type: "text", text}``. ``"sus"`` is the System Usability Scale (Brooke 1996; its ten items,
5-point scale), scored 0-100 in the summary.

Paths are resolved against the protocol file's folder. Every problem is a :class:`StudyError`
with a message that says where (task number and field) and what is expected.
"""

from __future__ import annotations

import hashlib
import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from algorithms.errors import Stylize3DError

#: The protocol format this version reads.
PROTOCOL_FORMAT = 1

SUS_ITEMS = (
    "I think that I would like to use this system frequently.",
    "I found the system unnecessarily complex.",
    "I thought the system was easy to use.",
    "I think that I would need the support of a technical person to be able to use this system.",
    "I found the various functions in this system were well integrated.",
    "I thought there was too much inconsistency in this system.",
    "I would imagine that most people would learn to use this system very quickly.",
    "I found the system very cumbersome to use.",
    "I felt very confident using the system.",
    "I needed to learn a lot of things before I could get going with this system.",
)

_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


class StudyError(Stylize3DError):
    """A study protocol or session log that cannot be used as it is (plain message)."""

    exit_code = 2


@dataclass(frozen=True)
class QuestionItem:
    id: str
    type: str  # "likert" | "text"
    text: str
    scale: int = 5
    labels: tuple[str, str] = ("Strongly disagree", "Strongly agree")


@dataclass(frozen=True)
class TaskSetup:
    """What one task allows in one condition."""

    panels: tuple[str, ...] | None = None  # None: every panel
    locked_panels: tuple[str, ...] = ()
    params: dict = field(default_factory=dict)  # panel -> {param: value}


@dataclass(frozen=True)
class Task:
    id: str
    title: str
    instructions: str
    mesh: str  # a resolved file path, or "sample:NAME"
    image: str | None = None
    time_limit_s: float | None = None
    questionnaire: tuple[QuestionItem, ...] = ()
    questionnaire_name: str | None = None  # "sus" for the built-in one
    setups: dict = field(default_factory=dict)  # condition -> TaskSetup

    def setup(self, condition: str) -> TaskSetup:
        return self.setups.get(condition, TaskSetup())


@dataclass(frozen=True)
class Protocol:
    study: str
    conditions: tuple[str, ...]
    tasks: tuple[Task, ...]
    counterbalance: bool = False
    path: str | None = None
    sha256: str = ""

    def task(self, task_id: str) -> Task:
        for t in self.tasks:
            if t.id == task_id:
                return t
        raise StudyError(f"The study has no task '{task_id}'.")

    def task_order(self, participant: str) -> list[str]:
        """Task ids in the order this participant does them.

        Without counterbalancing: the file's order. With it: row ``r`` of a balanced Latin
        square (Williams design) of the tasks, ``r`` = the participant code's trailing number
        (P07 -> 7) or, when it has none, a stable hash of the code, modulo the number of rows.
        """
        ids = [t.id for t in self.tasks]
        if not self.counterbalance or len(ids) < 2:
            return ids
        rows = balanced_latin_square(len(ids))
        m = re.search(r"(\d+)$", participant)
        r = int(m.group(1)) if m else int(hashlib.sha256(participant.encode()).hexdigest(), 16)
        return [ids[i] for i in rows[r % len(rows)]]


def balanced_latin_square(n: int) -> list[list[int]]:
    """Rows of a balanced Latin square (each task first equally often, each ordered pair
    adjacent equally often); for odd n the mirrored rows are added (2n rows)."""
    first = []
    lo, hi = 0, n - 1
    for k in range(n):
        if k % 2 == 0:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(x + r) % n for x in first] for r in range(n)]
    if n % 2:
        rows += [row[::-1] for row in rows]
    return rows


# ------------------------------------------------------------------------------ loading
def load_protocol(path) -> Protocol:
    """Read and validate a protocol file (.json or .toml)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise StudyError(f"Cannot read the study protocol {p}: {e.strerror or e}.") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise StudyError(f"{p.name} is not a text file; a study protocol is JSON or TOML.") from None
    if p.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise StudyError(f"{p.name} is not valid TOML: {e}.") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise StudyError(f"{p.name} is not valid JSON: {e.msg} at line {e.lineno}, "
                             f"column {e.colno}.") from None
    proto = parse_protocol(data, base=p.parent)
    return Protocol(proto.study, proto.conditions, proto.tasks, proto.counterbalance,
                    str(p.resolve()), hashlib.sha256(raw).hexdigest())


def parse_protocol(data: Any, base=None) -> Protocol:
    """Validate a protocol already parsed into Python objects (paths resolved against ``base``)."""
    base = Path(base) if base is not None else Path.cwd()
    if not isinstance(data, dict):
        raise StudyError("A study protocol is a table (JSON object) with 'study', 'conditions' "
                         "and 'tasks'.")
    known = {"study", "format", "conditions", "counterbalance", "tasks", "description"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise StudyError(f"Unknown protocol field(s): {', '.join(unknown)} (known: "
                         f"{', '.join(sorted(known))}).")
    fmt = data.get("format", PROTOCOL_FORMAT)
    if not isinstance(fmt, int) or fmt < 1:
        raise StudyError("'format' must be a whole number (1).")
    if fmt > PROTOCOL_FORMAT:
        raise StudyError(f"This protocol uses format {fmt}, written for a newer Stylize3D; this "
                         f"version reads format {PROTOCOL_FORMAT}. Update Stylize3D.")
    study = data.get("study")
    if not isinstance(study, str) or not _ID.match(study):
        raise StudyError("'study' must be an id of letters, digits, '-' or '_' (e.g. "
                         "\"cubic-pilot\").")
    conditions = data.get("conditions", ["default"])
    if (not isinstance(conditions, list) or not conditions
            or not all(isinstance(c, str) and _ID.match(c) for c in conditions)):
        raise StudyError("'conditions' must be a non-empty list of ids (e.g. [\"A\", \"B\"]).")
    if len(set(conditions)) != len(conditions):
        raise StudyError("'conditions' lists the same condition twice.")
    cb = data.get("counterbalance", False)
    if not isinstance(cb, bool):
        raise StudyError("'counterbalance' must be true or false.")
    tasks = data.get("tasks")
    if not isinstance(tasks, list) or not tasks:
        raise StudyError("'tasks' must be a non-empty list of tasks.")
    parsed = tuple(_parse_task(t, k + 1, conditions, base) for k, t in enumerate(tasks))
    ids = [t.id for t in parsed]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise StudyError(f"Task id(s) used twice: {', '.join(dup)}.")
    return Protocol(study, tuple(conditions), parsed, cb)


def _parse_task(t: Any, k: int, conditions: list[str], base: Path) -> Task:
    where = f"Task {k}"
    if not isinstance(t, dict):
        raise StudyError(f"{where} must be a table with id, title, instructions and mesh.")
    known = {"id", "title", "instructions", "image", "mesh", "time_limit_s", "questionnaire",
             "conditions"}
    unknown = sorted(set(t) - known)
    if unknown:
        raise StudyError(f"{where}: unknown field(s) {', '.join(unknown)} (known: "
                         f"{', '.join(sorted(known))}).")
    tid = t.get("id")
    if not isinstance(tid, str) or not _ID.match(tid):
        raise StudyError(f"{where}: 'id' must be letters, digits, '-' or '_'.")
    where = f"Task {k} ('{tid}')"
    title = t.get("title", tid)
    instructions = t.get("instructions")
    if not isinstance(title, str) or not isinstance(instructions, str) or not instructions.strip():
        raise StudyError(f"{where}: 'instructions' must be a non-empty text ('title' a text).")
    mesh = t.get("mesh")
    if not isinstance(mesh, str) or not mesh:
        raise StudyError(f"{where}: 'mesh' must name a mesh file (relative to the protocol) or "
                         "a bundled sample as \"sample:blob\".")
    if mesh.startswith("sample:"):
        from algorithms.mesh.samples import sample_path

        try:
            sample_path(mesh.split(":", 1)[1])
        except Stylize3DError as e:
            raise StudyError(f"{where}: {e}") from None
    else:
        mp = (base / mesh).resolve()
        if not mp.is_file():
            raise StudyError(f"{where}: the mesh file {mp} does not exist.")
        mesh = str(mp)
    image = t.get("image")
    if image is not None:
        ip = (base / str(image)).resolve()
        if not ip.is_file():
            raise StudyError(f"{where}: the instruction image {ip} does not exist.")
        image = str(ip)
    limit = t.get("time_limit_s")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, float))
                              or not 0 < limit <= 24 * 3600):
        raise StudyError(f"{where}: 'time_limit_s' must be a number of seconds above 0.")
    q = t.get("questionnaire")
    items: tuple[QuestionItem, ...] = ()
    qname = None
    if q == "sus":
        qname = "sus"
        items = tuple(QuestionItem(f"sus{i + 1}", "likert", s, 5) for i, s in enumerate(SUS_ITEMS))
    elif q is not None:
        if not isinstance(q, list) or not q:
            raise StudyError(f"{where}: 'questionnaire' must be \"sus\" or a list of items.")
        items = tuple(_parse_item(it, where, j + 1) for j, it in enumerate(q))
        qids = [i.id for i in items]
        if len(set(qids)) != len(qids):
            raise StudyError(f"{where}: two questionnaire items have the same id.")
    setups = {}
    conds = t.get("conditions", {})
    if not isinstance(conds, dict):
        raise StudyError(f"{where}: 'conditions' must map condition names to settings.")
    for c, s in conds.items():
        if c not in conditions:
            raise StudyError(f"{where}: condition '{c}' is not in the study's conditions "
                             f"({', '.join(conditions)}).")
        setups[c] = _parse_setup(s, f"{where}, condition '{c}'")
    return Task(tid, title, instructions, mesh, image,
                None if limit is None else float(limit), items, qname, setups)


def _parse_item(it: Any, where: str, j: int) -> QuestionItem:
    w = f"{where}, question {j}"
    if not isinstance(it, dict):
        raise StudyError(f"{w} must be a table with id, type and text.")
    qid, typ, text = it.get("id"), it.get("type", "likert"), it.get("text")
    if not isinstance(qid, str) or not _ID.match(qid):
        raise StudyError(f"{w}: 'id' must be letters, digits, '-' or '_'.")
    if typ not in ("likert", "text"):
        raise StudyError(f"{w}: 'type' must be \"likert\" or \"text\".")
    if not isinstance(text, str) or not text.strip():
        raise StudyError(f"{w}: 'text' must be the question.")
    scale = it.get("scale", 5)
    if typ == "likert" and (isinstance(scale, bool) or not isinstance(scale, int)
                            or not 3 <= scale <= 11):
        raise StudyError(f"{w}: 'scale' must be a whole number from 3 to 11.")
    labels = it.get("labels", ["Strongly disagree", "Strongly agree"])
    if not (isinstance(labels, list) and len(labels) == 2 and all(isinstance(x, str) for x in labels)):
        raise StudyError(f"{w}: 'labels' must be two texts (low end, high end).")
    return QuestionItem(qid, typ, text, int(scale), (labels[0], labels[1]))


def _parse_setup(s: Any, where: str) -> TaskSetup:
    if not isinstance(s, dict):
        raise StudyError(f"{where} must be a table (panels, locked_panels, params).")
    unknown = sorted(set(s) - {"panels", "locked_panels", "params"})
    if unknown:
        raise StudyError(f"{where}: unknown field(s) {', '.join(unknown)}.")

    def names(key):
        v = s.get(key)
        if v is None:
            return None
        if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
            raise StudyError(f"{where}: '{key}' must be a list of panel names.")
        return tuple(v)

    params = s.get("params", {})
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        raise StudyError(f"{where}: 'params' must map panel names to {{parameter: value}}.")
    return TaskSetup(names("panels"), names("locked_panels") or (), params)


def check_against_panels(protocol: Protocol, panels: dict[str, type]) -> None:
    """Check panel names and locked parameters against the app's panels.

    ``panels``: panel title -> its Params dataclass. Unknown panels or parameters, and values
    outside a parameter's range, are reported with the task and condition.
    """
    from algorithms.params import params_from_dict

    for t in protocol.tasks:
        for c, s in t.setups.items():
            where = f"Task '{t.id}', condition '{c}'"
            for name in (s.panels or ()) + s.locked_panels + tuple(s.params):
                if name not in panels:
                    raise StudyError(f"{where}: there is no panel '{name}' (panels: "
                                     f"{', '.join(sorted(panels))}).")
            for name, values in s.params.items():
                try:
                    params_from_dict(panels[name], values)
                except Stylize3DError as e:
                    raise StudyError(f"{where}, panel '{name}': {e}") from None
                except (TypeError, ValueError) as e:
                    raise StudyError(f"{where}, panel '{name}': {e}") from None
