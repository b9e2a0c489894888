"""Where a finding points: rounded points, the first faces or vertices, coordinates for messages.

The ``where`` dictionary of a :class:`~saucerfab.check.report.Finding` and
the "near (x, y, z) mm" of its message, written the same way by every check.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: faces or vertices listed in a ``where`` (the count says how many there are in all)
WHERE_FIRST = 10


def pt(p: np.ndarray) -> list[float]:
    """A point (3,) in mm as a JSON list, rounded to 0.1 micron."""
    return [round(float(x), 4) for x in p]


def where(point: np.ndarray | None = None, faces: Any = None, vertices: Any = None,
          count: int | None = None) -> dict[str, Any]:
    """A finding's ``where``: a point (3,) in mm, the first faces and vertices (file indices), a count."""
    w: dict[str, Any] = {}
    if point is not None:
        w["point_mm"] = pt(point)
    if faces is not None:
        w["faces"] = [int(f) for f in list(faces)[:WHERE_FIRST]]
    if vertices is not None:
        w["vertices"] = [int(v) for v in list(vertices)[:WHERE_FIRST]]
    if count is not None:
        w["count"] = int(count)
    return w


def fmt_pt(p: np.ndarray) -> str:
    """A point (3,) in mm for a message: ``(x, y, z) mm`` to 0.01 mm."""
    return "(" + ", ".join(f"{x:.2f}" for x in p) + ") mm"
