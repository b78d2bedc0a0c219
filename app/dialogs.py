"""Every modal dialog the app shows goes through these functions, so tests can patch them.

Nothing else in the app calls QMessageBox / QFileDialog directly.
"""

from __future__ import annotations

from PySide6.QtWidgets import QFileDialog, QMessageBox, QWidget


def error(parent: QWidget | None, title: str, text: str, details: str | None = None) -> None:
    box = QMessageBox(QMessageBox.Icon.Warning, title, text, QMessageBox.StandardButton.Ok, parent)
    if details:
        box.setDetailedText(details)
    box.exec()


def info(parent: QWidget | None, title: str, text: str) -> None:
    QMessageBox.information(parent, title, text)


def choose(parent: QWidget | None, title: str, text: str, choices: list[str],
           default: str | None = None, details: str | None = None) -> str | None:
    """Ask the user to pick one of ``choices`` (button labels); None when the dialog is closed.
    The last choice is treated as "Cancel"."""
    box = QMessageBox(QMessageBox.Icon.Question, title, text, QMessageBox.StandardButton.NoButton,
                      parent)
    if details:
        box.setDetailedText(details)
    buttons = {}
    for i, label in enumerate(choices):
        role = (QMessageBox.ButtonRole.RejectRole if i == len(choices) - 1
                else QMessageBox.ButtonRole.AcceptRole)
        b = box.addButton(label, role)
        buttons[b] = label
        if label == default:
            box.setDefaultButton(b)
    box.exec()
    return buttons.get(box.clickedButton())


def confirm(parent: QWidget | None, title: str, text: str, yes: str = "Yes", no: str = "Cancel") -> bool:
    return choose(parent, title, text, [yes, no], default=no) == yes


def open_file(parent: QWidget | None, title: str, filter: str, directory: str = "") -> str | None:
    path, _ = QFileDialog.getOpenFileName(parent, title, directory, filter)
    return path or None


def open_folder(parent: QWidget | None, title: str, directory: str = "") -> str | None:
    path = QFileDialog.getExistingDirectory(parent, title, directory)
    return path or None


def save_file(parent: QWidget | None, title: str, filter: str, directory: str = "") -> str | None:
    """Ask for a path to write. Does not confirm overwriting: the caller asks (app-wide policy)."""
    path, _ = QFileDialog.getSaveFileName(parent, title, directory, filter,
                                          options=QFileDialog.Option.DontConfirmOverwrite)
    return path or None


def ask_text(parent: QWidget | None, title: str, label: str, text: str = "") -> str | None:
    """A line of text from the user (e.g. a preset name); None when cancelled or empty."""
    from PySide6.QtWidgets import QInputDialog

    value, ok = QInputDialog.getText(parent, title, label, text=text)
    value = value.strip()
    return value if ok and value else None


def help_window(parent: QWidget | None, title: str, path):
    """A non-modal window showing one docs/*.md page (with its pictures); ``.browser`` is the
    text view."""
    from PySide6.QtCore import QUrl
    from PySide6.QtGui import QTextDocument
    from PySide6.QtWidgets import QDialog, QTextBrowser, QVBoxLayout

    dlg = QDialog(parent)
    dlg.setWindowTitle(title)
    dlg.resize(760, 720)
    lay = QVBoxLayout(dlg)
    view = QTextBrowser()
    view.setOpenExternalLinks(True)
    view.setSearchPaths([str(path.parent)])
    view.setSource(QUrl.fromLocalFile(str(path)), QTextDocument.ResourceType.MarkdownResource)
    lay.addWidget(view)
    dlg.browser = view
    return dlg
