"""Undo commands. Every edit of the document is a :class:`StateCommand` on the QUndoStack."""

from __future__ import annotations

from PySide6.QtGui import QUndoCommand

from app.document import Document, MeshState


class StateCommand(QUndoCommand):
    """Switch the document between two immutable :class:`MeshState` snapshots."""

    def __init__(self, doc: Document, before: MeshState, after: MeshState, text: str):
        super().__init__(text)
        self.doc, self.before, self.after = doc, before, after

    def redo(self) -> None:
        self.doc.set_state(self.after)

    def undo(self) -> None:
        self.doc.set_state(self.before)
