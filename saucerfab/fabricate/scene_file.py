"""Reading ``scene.json`` back: the one parse from the file (or a viewing dict) to typed frames.

:mod:`saucerfab.fabricate.scene_json` writes ``scene.json`` (schema
``saucerfab.scene/1``, file frame, millimetres); this module reads it, for
``saucerfab verify`` (:func:`saucerfab.verify.printfolder.load_print_scene`)
and for the 3D view of the report pages (:func:`saucerfab.pages.viewer.viewer_html`).

The file is treated as untrusted (a bureau verifies folders it was sent):
it is size-bounded, and every number is checked to be finite and bounded
before it is used. Any problem raises :class:`~saucerfab.errors.SceneFileError`
(exit 2) naming the file, the field and the fix.

:func:`scene_from_dict` is the one parse from a ``saucerfab.scene/1`` dict
to a :class:`PrintScene`; :func:`read_scene_file` reads and bounds the file,
then calls it. A design's viewing dict
(:func:`~saucerfab.fabricate.scene_json.viewing_dict`, a design without a
solid yet) goes through the same parse with ``footprint=False``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, SceneFileError
from saucerfab.model.cups import CUP_CLASSES, Cup, cup_from_dict
from saucerfab.model.scene import (
    EXTENT_TOLERANCE,
    FULL_EXTENT,
    SAUCER_OUTLINES,
    VIEW_NAMES,
)

#: the schema ``scene.json`` is written in (and the only one read)
SCHEMA = "saucerfab.scene/1"
#: the length unit of ``scene.json`` (the file frame)
UNITS = "mm"
#: largest scene.json read (a real one is about 1.5 kB)
MAX_SCENE_JSON_BYTES = 1 << 20
#: largest magnitude of any number read (mm, degrees, counts): far beyond a printable part
MAX_ABS_VALUE = 1e7
#: how far a round saucer's bounding square (``center`` +- ``diameter`` / 2) may lie from the footprint, mm
#: (the writer rounds both to 1e-6 mm; the footprint's ends come from the grid, nanometres off)
DISC_FOOTPRINT_TOLERANCE_MM = 1e-3
#: the GLB node matrix (column major) when a file has none: the identity
_IDENTITY_16 = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]


@dataclass(frozen=True)
class ViewSpec:
    """One view frame of ``scene.json`` (file frame, mm).

    Attributes:
        name: ``direct``, ``reflected`` or ``reflected2``.
        target: (3,) point the view axis passes through, mm.
        viewing_angle_deg: SoftRas's half field of view: tan(angle) = half
            the frame's width / depth along the axis.
        extent: (ex, ey) the picture's half width and half height in the
            frame's NDC (:mod:`saucerfab.model.camera`): the picture covers
            the centred rectangle ``|x_ndc| <= ex``, ``|y_ndc| <= ey`` of the
            square frame, the rest is its background; (1, 1) the whole square.
    """

    name: str
    target: tuple[float, float, float]
    viewing_angle_deg: float
    extent: tuple[float, float] = FULL_EXTENT

    def picture_mask(self, size: int) -> np.ndarray:
        """(size, size) bool: the frame's pixels whose centres lie inside the picture's rectangle.

        Pixel (row i, column j) of a ``size`` px frame has its centre at
        ``x_ndc = (2j + 1) / size - 1``, ``y_ndc = 1 - (2i + 1) / size``; it is
        inside when ``|x_ndc| <= ex`` and ``|y_ndc| <= ey``. Compared as
        ``|2k + 1 - size| <= e * size`` (an odd integer against one product), so
        the rectangle is symmetric and (1, 1) is every pixel, with no rounding.
        """
        off = np.abs(2 * np.arange(size, dtype=np.float64) + 1 - size)  # |centre| in half pixels
        ex, ey = self.extent
        return (off <= ey * size)[:, None] & (off <= ex * size)[None, :]


@dataclass(frozen=True)
class CupSpec:
    """The mirror cup of ``scene.json`` (file frame, mm).

    Attributes:
        center: (x, y) of the cup's axis.
        bottom_z: z of the cup's bottom (its standing plane).
        height: mirror wall height.
        outline: the cup's own shape (:mod:`saucerfab.model.cups`) built from the
            file's fields, lengths in mm, about its axis: its wall
            (:meth:`~saucerfab.model.cups.Cup.wall`) is what verify ray-traces
            and the 3D view draws.
    """

    center: tuple[float, float]
    bottom_z: float
    height: float
    outline: Cup

    @property
    def shape(self) -> str:
        """The shape's name in ``scene.json`` (``circle``, ``ellipse``, ``prism``, ...)."""
        return self.outline.kind

    @property
    def width_mm(self) -> float:
        """The cup's width as export's ``--cup-diameter-mm`` names it."""
        return self.outline.width_units


@dataclass(frozen=True)
class PrintScene:
    """``scene.json`` as read: the viewing geometry of a print (or of a design) in the file frame, mm.

    Attributes:
        camera: (3,) the design eye, mm, file frame.
        views: view name -> frame, in :data:`~saucerfab.model.scene.VIEW_NAMES` order.
        cup: the mirror cup.
        saucer_x, saucer_y: the saucer's footprint (min, max), mm; None only
            for a design's viewing dict (no solid yet, ``footprint=False``).
        mm_per_unit: millimetres per model unit.
        glb_matrix: (4, 4) the GLB node's matrix (file frame in metres -> glTF's y-up).
        source: the parsed JSON object itself, every key as read (the 3D
            view embeds it as it is); checked, never to be changed.
        saucer_outline: ``rectangle`` (the footprint is the saucer; also a file
            without ``saucer.outline``, or without ``saucer``) or ``disc``.
        saucer_center: a disc's centre (x, y), mm; None for a rectangle.
        saucer_diameter: a disc's diameter, mm; None for a rectangle.
    """

    camera: tuple[float, float, float]
    views: dict[str, ViewSpec]
    cup: CupSpec
    saucer_x: tuple[float, float] | None
    saucer_y: tuple[float, float] | None
    mm_per_unit: float
    glb_matrix: np.ndarray
    source: Mapping[str, Any] = field(repr=False, compare=False)
    saucer_outline: str = SAUCER_OUTLINES[0]
    saucer_center: tuple[float, float] | None = None
    saucer_diameter: float | None = None

    @property
    def is_disc(self) -> bool:
        """Whether the saucer is round (its outline the circle ``saucer_center``, ``saucer_diameter``)."""
        return self.saucer_outline == "disc"


def _bad(where: str, what: str) -> SceneFileError:
    return SceneFileError(f"{where}: {what}; re-export the design with 'saucerfab export' to get a valid scene.json")


def _num(where: str, v: Any, what: str, *, positive: bool = False, limit: float = MAX_ABS_VALUE) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > limit:
        raise _bad(where, f"{what} must be a finite number (|x| <= {limit:g}), got {str(v)[:40]!r}")
    if positive and v <= 0:
        raise _bad(where, f"{what} must be positive, got {v!r}")
    return float(v)


def _vec(where: str, v: Any, n: int, what: str) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n:
        raise _bad(where, f"{what} must be a list of {n} numbers, got {str(v)[:60]!r}")
    return tuple(_num(where, x, what) for x in v)


def _extent(where: str, v: Any, what: str) -> tuple[float, float]:
    """A view's ``extent``: two numbers in (0, 1], the larger 1 within :data:`EXTENT_TOLERANCE` (made exactly 1)."""
    ex, ey = _vec(where, v, 2, what)
    rule = (f"{what} is the picture's half width and half height in its square frame: two numbers in (0, 1], "
            f"the larger 1 (a 2:1 picture: [1.0, 0.5])")
    if not (0.0 < ex <= 1.0 and 0.0 < ey <= 1.0) or max(ex, ey) < 1.0 - EXTENT_TOLERANCE:
        raise _bad(where, f"{rule}; got {[ex, ey]}")
    # a side at 1 is the frame's own edge: exactly 1, so that a writer's rounding loses no edge pixel
    return (1.0 if ex >= 1.0 - EXTENT_TOLERANCE else ex, 1.0 if ey >= 1.0 - EXTENT_TOLERANCE else ey)


def _obj(where: str, d: Any, key: str) -> dict[str, Any]:
    v = d.get(key) if isinstance(d, dict) else None
    if not isinstance(v, dict):
        raise _bad(where, f"'{key}' is missing or not an object")
    return v


def _view(where: str, name: str, v: Any, camera: tuple[float, ...]) -> ViewSpec:
    """``views.<name>``: its target, angle (below 89 degrees) and extent, looking neither straight up nor down."""
    if not isinstance(v, dict):
        raise _bad(where, f"views.{name} is not an object")
    target = _vec(where, v.get("target"), 3, f"views.{name}.target")
    angle = _num(where, v.get("viewing_angle_deg"), f"views.{name}.viewing_angle_deg", positive=True)
    if angle >= 89:
        raise _bad(where, f"views.{name}.viewing_angle_deg {angle} is not below 89 degrees")
    if math.dist(target, camera) < 1e-6:
        raise _bad(where, f"views.{name}.target is the camera position")
    fwd = np.subtract(target, camera)
    # the image's up is the file's z seen from the camera: undefined along z
    if np.linalg.norm(np.cross(fwd / np.linalg.norm(fwd), (0.0, 0.0, 1.0))) < 1e-9:
        raise _bad(where, f"views.{name} looks straight up or down; its image orientation is undefined")
    extent = _extent(where, v["extent"], f"views.{name}.extent") if "extent" in v else FULL_EXTENT
    return ViewSpec(name, target, angle, extent)  # type: ignore[arg-type]


def _cup(where: str, c: dict[str, Any]) -> CupSpec:
    """``cup``: a known shape, its axis and height, and the shape's own fields (checked by the shape's class)."""
    shape = c.get("shape")
    if shape not in CUP_CLASSES:
        raise _bad(where, f"cup.shape is {str(shape)[:20]!r}; known: {', '.join(CUP_CLASSES)}")
    center = _vec(where, c.get("center"), 2, "cup.center")
    bottom_z = _num(where, c.get("bottom_z"), "cup.bottom_z")
    height = _num(where, c.get("height"), "cup.height", positive=True)
    shape_fields = {k: v for k, v in c.items() if k not in ("center", "bottom_z")}
    for key, value in shape_fields.items():  # every length and angle a bounded number (sides too)
        if key != "shape":
            for x in value if isinstance(value, list) else [value]:
                _num(where, x, f"cup.{key}")
    try:
        outline = cup_from_dict(shape_fields, shape)  # the shape's own checks, as for a scene file
    except (ConfigError, TypeError, ValueError) as exc:
        raise _bad(where, f"cup: {str(exc)[:200]}") from None
    return CupSpec(center, bottom_z, height, outline)  # type: ignore[arg-type]


def _outline(
    where: str, saucer: dict[str, Any], sx: tuple[float, ...], sy: tuple[float, ...]
) -> tuple[str, tuple[float, ...] | None, float | None]:
    """``saucer.outline`` and a disc's ``diameter`` and ``center``: a known outline, and a disc whose
    bounding square is the footprint (``x_range``, ``y_range``)."""
    outline = saucer.get("outline", SAUCER_OUTLINES[0])
    if not isinstance(outline, str) or outline not in SAUCER_OUTLINES:
        raise _bad(where, f"saucer.outline is {str(outline)[:20]!r}; known: {', '.join(SAUCER_OUTLINES)}")
    if outline != "disc":
        extra = [k for k in ("diameter", "center") if k in saucer]
        if extra:
            raise _bad(where, f"saucer.{extra[0]} is a round saucer's (saucer.outline \"disc\"), "
                              f"but the outline is a {outline}")
        return outline, None, None
    diameter = _num(where, saucer.get("diameter"), "saucer.diameter", positive=True)
    center = _vec(where, saucer.get("center"), 2, "saucer.center")
    r = 0.5 * diameter
    square = ((center[0] - r, center[0] + r), (center[1] - r, center[1] + r))
    if max(abs(a - b) for got, want in zip(square, (sx, sy)) for a, b in zip(got, want)) > DISC_FOOTPRINT_TOLERANCE_MM:
        raise _bad(where, f"the round saucer (saucer.center {list(center)}, saucer.diameter {diameter:g} mm) must "
                          f"fill its footprint: its bounding square x {list(square[0])}, y {list(square[1])} is not "
                          f"saucer.x_range {list(sx)}, y_range {list(sy)}")
    return outline, center, diameter


def scene_from_dict(d: Any, where: str, *, footprint: bool = True) -> PrintScene:
    """The one parse of a ``saucerfab.scene/1`` object (``json.loads`` of scene.json, or a viewing dict).

    Args:
        d: the parsed JSON object; kept as :attr:`PrintScene.source`.
        where: what to name in a message (the file's path, or what the dict is).
        footprint: require ``saucer`` (the footprint every exported scene.json
            has); False for a design's viewing dict, which has none: then
            ``saucer``, when present, is still checked.

    Raises:
        SceneFileError: wrong schema or units, a missing object, or a value
            that is not a bounded finite number or is out of its range.
    """
    if not isinstance(d, dict) or d.get("schema") != SCHEMA:
        got = d.get("schema") if isinstance(d, dict) else None
        raise _bad(where, f"schema is {str(got)[:40]!r}, expected {SCHEMA!r}")
    if d.get("units") != UNITS:
        raise _bad(where, f"units are {str(d.get('units'))[:20]!r}; verify reads scenes in {UNITS!r}")
    camera = _vec(where, _obj(where, d, "camera").get("position"), 3, "camera.position")
    views_d = _obj(where, d, "views")
    views = {name: _view(where, name, views_d[name], camera) for name in VIEW_NAMES if name in views_d}
    for name in ("direct", "reflected"):
        if name not in views:
            raise _bad(where, f"views.{name} is missing")
    cup = _cup(where, _obj(where, d, "cup"))
    sx: tuple[float, ...] | None = None
    sy: tuple[float, ...] | None = None
    outline: tuple[str, tuple[float, ...] | None, float | None] = (SAUCER_OUTLINES[0], None, None)
    if footprint or "saucer" in d:
        saucer = _obj(where, d, "saucer")
        sx = _vec(where, saucer.get("x_range"), 2, "saucer.x_range")
        sy = _vec(where, saucer.get("y_range"), 2, "saucer.y_range")
        if not (sx[0] < sx[1] and sy[0] < sy[1]):
            raise _bad(where, "saucer.x_range and y_range must be (min, max) with min < max")
        outline = _outline(where, saucer, sx, sy)
    mpu = _num(where, d.get("mm_per_unit"), "mm_per_unit", positive=True)
    glb = d.get("glb") if isinstance(d.get("glb"), dict) else {}
    mat = glb.get("node_matrix_column_major", _IDENTITY_16)
    m = np.array(_vec(where, mat, 16, "glb.node_matrix_column_major"), np.float64).reshape(4, 4).T
    if abs(np.linalg.det(m[:3, :3])) < 1e-9:
        raise _bad(where, "glb.node_matrix_column_major is singular")
    shape, centre, diameter = outline
    return PrintScene(camera, views, cup, sx, sy, mpu, m, MappingProxyType(d),  # type: ignore[arg-type]
                      saucer_outline=shape, saucer_center=centre, saucer_diameter=diameter)


def read_scene_file(path: Path) -> PrintScene:
    """Read ``path`` (a ``scene.json``, at most :data:`MAX_SCENE_JSON_BYTES`) and parse it (:func:`scene_from_dict`).

    Raises:
        SceneFileError: unreadable, too large, not UTF-8 JSON, or a bad value
            (the message names ``path`` and the field).
    """
    try:
        if path.stat().st_size > MAX_SCENE_JSON_BYTES:
            raise _bad(str(path), f"the file is over {MAX_SCENE_JSON_BYTES:,} bytes, far more than any scene")
        with path.open("rb") as f:
            data = f.read(MAX_SCENE_JSON_BYTES + 1)  # bounded even if the file grew since stat
    except OSError as exc:
        raise _bad(str(path), f"cannot be read ({exc.strerror or exc})") from None
    if len(data) > MAX_SCENE_JSON_BYTES:
        raise _bad(str(path), f"the file is over {MAX_SCENE_JSON_BYTES:,} bytes, far more than any scene")
    try:
        d = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise _bad(str(path), f"not valid JSON ({str(exc)[:80]})") from None
    return scene_from_dict(d, str(path))
