"""Undo commands. Every edit of the document is a :class:`StateCommand` on the QUndoStack."""

from __future__ import annotations

from PySide6.QtGui import QUndoCommand

from app.document import Document, MeshState


class StateCommand(QUndoCommand):
    """Switch the document between two immutable :class:`MeshState` snapshots.

    ``merge_id`` (> 0) makes consecutive commands with the same id collapse into one undo step
    (live re-runs of a method while a slider moves): the merged command goes from the first one's
    ``before`` to the last one's ``after``.
    """

    def __init__(self, doc: Document, before: MeshState, after: MeshState, text: str,
                 merge_id: int = -1):
        super().__init__(text)
        self.doc, self.before, self.after = doc, before, after
        self._merge_id = merge_id

    def id(self) -> int:  # noqa: A003 (Qt API)
        return self._merge_id

    def mergeWith(self, other: QUndoCommand) -> bool:  # noqa: N802 (Qt API)
        if not isinstance(other, StateCommand) or other.id() != self.id() or self.id() < 0:
            return False
        if other.before is not self.after:
            return False
        self.after = other.after
        return True

    def redo(self) -> None:
        self.doc.set_state(self.after)

    def undo(self) -> None:
        self.doc.set_state(self.before)
