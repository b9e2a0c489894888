"""``scene.json``: the viewing geometry in the coordinates of the written files.

Schema ``saucerfab.scene/1`` (all lengths millimetres, file frame: the
coordinates of the 3MF/OBJ/PLY/VRML/STL files; the GLB's POSITION data holds
the same numbers in metres)::

    {"schema": "saucerfab.scene/1", "units": "mm",
     "camera": {"position": [x, y, z], "up": [0, 0, 1]},
     "views": {"direct":    {"target": [x, y, z], "viewing_angle_deg": a, "width": w, "height": h,
                            "extent": [ex, ey]},
               "reflected": {...}},
     "cup": {"shape": "circle", "center": [x, y], "bottom_z": z, "height": h, "radius": r}
            | {"shape": "ellipse", ..., "semi_axes": [a, b], "rotation_deg": t}
            | {"shape": "prism", ..., "sides": n, "circumradius": r, "rotation_deg": t}
            (each shape's fields: its ``file_fields``, saucerfab/model/cups.py),
     "model_to_file": [[s, 0, 0, tx], [0, s, 0, ty], [0, 0, s, tz], [0, 0, 0, 1]]}

``viewing_angle_deg`` is SoftRas's: tan(angle) = half the frame's width /
depth along the view axis; ``width`` and ``height`` are the view image's
size in pixels; ``extent`` ``[ex, ey]`` is where the picture lies in the
square view: ``|x_ndc| <= ex``, ``|y_ndc| <= ey`` (the larger 1; a 2:1 picture
``[1, 0.5]``; missing in older files: ``[1, 1]``), the rest of the square
being its background. The
model-to-file map is a uniform scale (mm per model unit) and a translation
into the positive octant, so angles and the up vector are unchanged.

Beyond those fields: ``mm_per_unit``, the saucer's footprint and the cup
seat in file coordinates, and the GLB's node transform. A round saucer's
``saucer`` also holds its outline, so verify and any renderer rebuild it
(a rectangle's has no such keys: its file reads as it did before discs)::

     "saucer": {"x_range": [x0, x1], "y_range": [y0, y1],
                "outline": "disc", "diameter": d, "center": [cx, cy]}

``x_range`` and ``y_range`` are then the disc's bounding square (``center``
+- ``diameter`` / 2); the part's outline is a polygon whose vertices lie on
that circle (:mod:`saucerfab.fabricate.round_solid`).

The reader, beside this writer: :mod:`saucerfab.fabricate.scene_file`
(:func:`~saucerfab.fabricate.scene_file.read_scene_file`, one typed
:class:`~saucerfab.fabricate.scene_file.PrintScene`), which also holds the
schema's name.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from saucerfab.fabricate.export_glb import Z_UP_TO_Y_UP
from saucerfab.fabricate.scene_file import SCHEMA, UNITS
from saucerfab.fabricate.solid import Solid
from saucerfab.model.scene import Scene

__all__ = ["DECIMALS", "SCHEMA", "scene_dict", "scene_json_bytes", "viewing_dict"]

#: decimals of millimetre values in scene.json (10 nm)
DECIMALS = 6


def _r(x: float) -> float:
    return round(float(x), DECIMALS) + 0.0


def _pt(m: np.ndarray, p: tuple[float, ...]) -> list[float]:
    q = m @ np.array([*p, 1.0])
    return [_r(c) for c in q[:3]]


def viewing_dict(scene: Scene, model_to_file: np.ndarray) -> dict[str, Any]:
    """The viewing part of ``scene.json`` (schema, units, camera, views, cup, transform).

    ``model_to_file``: (4, 4) uniform scale (mm per model unit) and translation.
    This is what a renderer needs to show the saucer with its cup; the
    design report uses it for a design that has no solid yet.
    """
    m = np.asarray(model_to_file, np.float64)
    s = float(m[0, 0])
    cup = scene.cup
    centre = _pt(m, (0.0, 0.0, 0.0))
    cup_d: dict[str, Any] = {
        "shape": cup.kind,
        "center": centre[:2],
        "bottom_z": centre[2],
        "height": _r(cup.height * s),
        **cup.file_fields(lambda length: _r(length * s)),  # the shape's own fields, lengths in mm
    }

    def view(name: str) -> dict[str, Any]:
        v = getattr(scene, name)
        return {
            "target": _pt(m, v.target),
            "viewing_angle_deg": float(v.viewing_angle_deg),
            "width": int(v.image_size),
            "height": int(v.image_size),
            "extent": [float(e) for e in v.extent],
        }

    return {
        "schema": SCHEMA,
        "units": UNITS,
        "camera": {"position": _pt(m, scene.camera), "up": [0.0, 0.0, 1.0]},
        "views": {
            "direct": view("direct"),
            "reflected": view("reflected"),
            # a prism design with two reflected images has its own frame for the second
            **({"reflected2": view("reflected2")} if scene.reflected2 is not None else {}),
        },
        "cup": cup_d,
        "model_to_file": [[_r(c) for c in row] for row in m.tolist()],
        "mm_per_unit": _r(s),
    }


def scene_dict(scene: Scene, solid: Solid) -> dict[str, Any]:
    """The ``scene.json`` content for ``scene`` as written with ``solid``'s transform."""
    (x0, x1), (y0, y1) = solid.footprint
    seat = solid.seat
    saucer: dict[str, Any] = {"x_range": [_r(x0), _r(x1)], "y_range": [_r(y0), _r(y1)]}
    if solid.disc_radius_mm is not None:  # written for a disc only: a rectangle's scene.json stays as it was
        saucer.update(outline="disc", diameter=_r(2.0 * solid.disc_radius_mm),
                      center=[_r(c) for c in seat.center_xy])
    return {
        **viewing_dict(scene, solid.model_to_file),
        "saucer": saucer,
        "seat": {
            "kind": seat.kind,
            "floor_z": _r(seat.floor_z),
            "top_z": _r(seat.top_z),
            "base_z": _r(solid.bottom_z),
        },
        "glb": {"units": "m", "scale_from_mm": 0.001, "node_matrix_column_major": Z_UP_TO_Y_UP},
    }


def _dumps(obj: Any, indent: str = "") -> str:
    """JSON with one line per key and number lists kept on one line (readable matrices)."""
    inner = indent + "  "
    if isinstance(obj, dict):
        items = [f"{inner}{json.dumps(k)}: {_dumps(v, inner)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    if isinstance(obj, list) and any(isinstance(v, (dict, list)) for v in obj):
        return "[\n" + ",\n".join(inner + _dumps(v, inner) for v in obj) + "\n" + indent + "]"
    return json.dumps(obj)


def scene_json_bytes(scene: Scene, solid: Solid) -> bytes:
    """``scene.json`` as UTF-8 bytes (keys in the schema's order)."""
    return (_dumps(scene_dict(scene, solid)) + "\n").encode("utf-8")
