"""Small reusable widgets: a live line plot for energies and residuals."""

from __future__ import annotations

import math

from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QPainter, QPainterPath, QPen
from PySide6.QtWidgets import QSizePolicy, QToolButton, QVBoxLayout, QWidget


def dock_view_action(dock):
    """``dock.toggleViewAction()``, guarded against a PySide6 stale wrapper.

    Shiboken maps C++ addresses to Python wrappers; a wrapper of a non-QObject that Qt deleted
    behind its back can be handed back for a new QAction at the same address. The one such
    wrapper the app held (pyvistaqt's ``QSurface``, seen in CI) is gone since issue 35 (see
    ``app.viewport._TimedInteractor``); this stays as a second line of defence: such a wrapper is
    detached (``shiboken6.invalidate``; nothing is deleted) and the action asked for again."""
    from PySide6.QtGui import QAction

    action = dock.toggleViewAction()
    if not isinstance(action, QAction):
        import shiboken6

        shiboken6.invalidate(action)
        action = dock.toggleViewAction()
    return action


def plural(n: int, singular: str, plural_form: str | None = None) -> str:
    """ "1 iteration", "2 iterations", "1,024 vertices" (``plural_form`` when not singular + s)."""
    word = singular if n == 1 else (plural_form or singular + "s")
    return f"{n:,} {word}"


def number(x: float, digits: int = 3) -> str:
    """``x`` to ``digits`` significant digits as a person writes it: "471", "999.8" -> "1,000",
    "0.864", "12,345" (whole numbers of ``digits`` digits or more in full, with commas), never
    "1e+03"; scientific only below 0.001 or from a million on ("2.5e-05", "1.3e+06")."""
    x = float(x)
    if not math.isfinite(x) or x == 0.0:
        return f"{x:g}"
    if not 1e-3 <= abs(x) < 1e6:
        return f"{x:.{digits}g}"
    lead = math.floor(math.log10(abs(float(f"{x:.{digits}g}"))))     # after rounding: 999.8 -> 3
    decimals = max(0, digits - 1 - lead)
    return f"{x:,.{decimals}f}"


def article(word: str) -> str:
    """ "a cube", "an octahedron" (by the first letter; enough for the app's own words)."""
    return ("an " if word[:1].lower() in "aeiou" else "a ") + word


class CollapsibleSection(QWidget):
    """A titled group of widgets that folds away: a flat arrow button ("▸ Advanced") and, when
    open, its body. Folded it is one line of text, never an empty frame. ``setChecked`` /
    ``isChecked`` / ``toggled`` read like a checkable group box's."""

    toggled = Signal(bool)

    def __init__(self, title: str, parent: QWidget | None = None, expanded: bool = False):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        self.button = QToolButton()
        self.button.setText(title)
        self.button.setCheckable(True)
        self.button.setAutoRaise(True)
        self.button.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextBesideIcon)
        self.button.setStyleSheet("QToolButton { border: none; font-weight: bold; }")
        self.body = QWidget()
        self.body.setVisible(False)
        lay.addWidget(self.button)
        lay.addWidget(self.body)
        self.button.toggled.connect(self._on_toggled)
        self._set_arrow(False)
        self.setChecked(expanded)

    def _set_arrow(self, on: bool) -> None:
        self.button.setArrowType(Qt.ArrowType.DownArrow if on else Qt.ArrowType.RightArrow)

    def _on_toggled(self, on: bool) -> None:
        self._set_arrow(on)
        self.body.setVisible(on)
        self.toggled.emit(on)

    def setChecked(self, on: bool) -> None:  # noqa: N802 (reads like QGroupBox)
        self.button.setChecked(bool(on))

    def isChecked(self) -> bool:  # noqa: N802
        return self.button.isChecked()

    def setToolTip(self, tip: str) -> None:  # noqa: N802
        super().setToolTip(tip)
        self.button.setToolTip(tip)


class LinePlot(QWidget):
    """A light-weight plot of one series per name against the iteration (optionally log y)."""

    COLORS = ["#2b6cb0", "#c05621", "#2f855a", "#9b2c2c", "#6b46c1"]

    def __init__(self, title: str = "", log_y: bool = False, parent: QWidget | None = None,
                 empty_text: str = ""):
        super().__init__(parent)
        self.title = title
        #: shown while there is no series and no placeholder (what would appear here, and when)
        self.empty_text = empty_text
        self.log_y = log_y
        self.series: dict[str, list[float]] = {}
        #: drawn in the middle while there is no series (why the plot is empty)
        self.placeholder = ""
        self.setMinimumHeight(110)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred)
        self.setToolTip("Value per iteration of the running method (latest value on the right).")

    def clear(self) -> None:
        self.series.clear()
        self.placeholder = ""
        self.update()

    def set_placeholder(self, text: str) -> None:
        """Say in the empty plot why it is empty (cleared by :meth:`clear`)."""
        self.placeholder = text
        self.update()

    def append(self, name: str, value: float) -> None:
        if value is None or not math.isfinite(value):
            return
        self.series.setdefault(name, []).append(float(value))
        self.update()

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt API)
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), QColor("#fbfbfb"))
        p.setPen(QColor("#888"))
        p.drawRect(self.rect().adjusted(0, 0, -1, -1))
        font = QFont(p.font())
        font.setPointSizeF(max(7.0, font.pointSizeF() - 1))
        p.setFont(font)
        m = 8
        top = m + 14 + 12 * max(len(self.series), 1)
        area = QRectF(m + 2, top, self.width() - 2 * m - 4, self.height() - top - m)
        p.setPen(QColor("#333"))
        p.drawText(QPointF(m, m + 8), self.title or ", ".join(self.series))
        if not self.series and (self.placeholder or self.empty_text):
            p.setPen(QColor("#555"))
            p.drawText(area.adjusted(4, 0, -4, 0), int(Qt.AlignmentFlag.AlignCenter
                                                       | Qt.TextFlag.TextWordWrap),
                       self.placeholder or self.empty_text)
        for i, (name, ys) in enumerate(self.series.items()):
            vals = [math.log10(y) if self.log_y else y for y in ys if (y > 0 or not self.log_y)]
            if not vals:
                continue
            lo, hi = min(vals), max(vals)
            if hi - lo < 1e-12:
                lo, hi = lo - 0.5, hi + 0.5
            n = max(len(vals) - 1, 1)
            path = QPainterPath()
            for k, v in enumerate(vals):
                pt = QPointF(area.left() + area.width() * k / n,
                             area.bottom() - area.height() * (v - lo) / (hi - lo))
                path.moveTo(pt) if k == 0 else path.lineTo(pt)
            p.setPen(QPen(QColor(self.COLORS[i % len(self.COLORS)]), 1.6))
            p.drawPath(path)
            last = ys[-1]
            p.drawText(QRectF(m, m + 12 + 12 * i, self.width() - 2 * m, 12),
                       Qt.AlignmentFlag.AlignLeft, (f"{name}: " if len(self.series) > 1 else "")
                       + f"last {last:.4g} · min {min(ys):.4g} · max {max(ys):.4g}")
        p.end()


class MessageLog(QWidget):
    """Every report the app gave (opened files and what cleaning changed, finished, cancelled
    and failed jobs, saves), newest last, with the time. The status bar shows one line of each
    for a few seconds; this keeps the whole text (View > Messages, or "Details…")."""

    def __init__(self, parent: QWidget | None = None):
        from PySide6.QtWidgets import QHBoxLayout, QPlainTextEdit, QPushButton, QVBoxLayout

        super().__init__(parent)
        self.entries: list[tuple[str, str, str]] = []  # (time, level, text)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        self.text = QPlainTextEdit()
        self.text.setReadOnly(True)
        self.text.setToolTip("Every message of this session; select and copy what you need.")
        lay.addWidget(self.text)
        row = QHBoxLayout()
        row.addStretch(1)
        self.clear_button = QPushButton("Clear")
        self.clear_button.setToolTip("Remove all messages from this list.")
        self.clear_button.clicked.connect(self.clear)
        row.addWidget(self.clear_button)
        lay.addLayout(row)

    def add(self, text: str, level: str = "info") -> None:
        import time

        stamp = time.strftime("%H:%M:%S")
        self.entries.append((stamp, level, text))
        mark = {"error": "⚠ ", "warning": "⚠ "}.get(level, "")
        self.text.appendPlainText(f"{stamp}  {mark}{text}")

    def clear(self) -> None:
        self.entries.clear()
        self.text.clear()

    def all_text(self) -> str:
        return "\n".join(t for _s, _l, t in self.entries)
