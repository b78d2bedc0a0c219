"""Guards against a broken Qt binding build.

PySide6 6.12.0 on Python 3.11 decrements None's reference count on every call of a method that
returns void (setPen, moveTo, ...); after a few thousand paint calls the interpreter aborts with
"Fatal Python error: none_dealloc". pyproject.toml pins a release without the bug; this test fails
if a future pin brings it back.
"""

from __future__ import annotations

import sys


def test_void_methods_keep_none_alive(qtbot):
    from PySide6.QtCore import QPointF
    from PySide6.QtGui import QColor, QImage, QPainter, QPainterPath

    img = QImage(16, 16, QImage.Format.Format_RGB32)
    painter = QPainter(img)
    path = QPainterPath()
    before = sys.getrefcount(None)
    for _ in range(2000):
        painter.setPen(QColor("#123456"))
        path.moveTo(QPointF(1.0, 1.0))
    after = sys.getrefcount(None)
    painter.end()
    assert after - before > -100, f"None lost {before - after} references in 4000 void calls"
