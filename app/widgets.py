"""Small reusable widgets: a live line plot for energies and residuals."""

from __future__ import annotations

import math

from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QFont, QPainter, QPainterPath, QPen
from PySide6.QtWidgets import QSizePolicy, QWidget


class LinePlot(QWidget):
    """A light-weight plot of one series per name against the iteration (optionally log y)."""

    COLORS = ["#2b6cb0", "#c05621", "#2f855a", "#9b2c2c", "#6b46c1"]

    def __init__(self, title: str = "", log_y: bool = False, parent: QWidget | None = None):
        super().__init__(parent)
        self.title = title
        self.log_y = log_y
        self.series: dict[str, list[float]] = {}
        self.setMinimumHeight(110)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred)
        self.setToolTip("Value per iteration of the running method (latest value on the right).")

    def clear(self) -> None:
        self.series.clear()
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
