"""Class labels typed by a person: exact names, any of a class's comma-separated synonyms, or an
index; unknown names are refused with the closest names (difflib)."""

from __future__ import annotations

import difflib
from typing import Sequence

from ..errors import ParameterError

__all__ = ["resolve_label", "short_name"]


def short_name(name: str) -> str:
    """The first synonym of an ImageNet name (``"tench, Tinca tinca"`` -> ``"tench"``)."""
    return name.split(",")[0].strip()


def resolve_label(text, class_names: Sequence[str]) -> int:
    """Index of the class ``text`` names (case-insensitive; a synonym or a number also works)."""
    t = str(text).strip()
    if t.isdigit():
        i = int(t)
        if 0 <= i < len(class_names):
            return i
        raise ParameterError(f"Class number {i} does not exist: the classifier knows classes 0 "
                             f"to {len(class_names) - 1}.")
    key = t.lower()
    lookup: dict[str, int] = {}
    for i, name in enumerate(class_names):
        lookup.setdefault(name.lower(), i)
        for syn in name.split(","):
            lookup.setdefault(syn.strip().lower(), i)
    if key in lookup:
        return lookup[key]
    close = difflib.get_close_matches(key, list(lookup), n=5, cutoff=0.6)
    if not close:
        close = [k for k in lookup if key and key in k][:5]
    hint = (" Did you mean: " + ", ".join(repr(short_name(class_names[lookup[c]]))
                                          if c == short_name(class_names[lookup[c]]).lower()
                                          else repr(c) for c in close) + "?") if close else \
        " Type a class name of the classifier (e.g. 'teapot', 'coffee mug') or its number."
    raise ParameterError(f"Unknown class label {t!r}.{hint}")
