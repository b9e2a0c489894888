"""Reading a print folder back from disk for verification.

A print folder is what ``saucerfab export`` writes: the mesh files, their
textures, ``scene.json`` (the viewing geometry in the files' millimetres,
schema ``saucerfab.scene/1``, see :mod:`saucerfab.fabricate.scene_json`)
and the reference pictures ``reference_<view>.png`` (each input picture as
the designer meant it: alpha composited over the design's background and
fitted into its square view frame by the design's rule, in the frame's
centred rectangle ``extent`` when it keeps its own aspect).

Everything here treats the folder as untrusted (a bureau verifies folders
it was sent): ``scene.json`` is size-bounded and every number is checked,
meshes go through the checker's bounded readers
(:func:`saucerfab.check.readers.read_mesh`) and pictures through the
bounded image loader. Any problem raises :class:`VerifyInputError` (exit 2)
with what is wrong and what to do.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.design import reference_name
from saucerfab.cups import CUP_CLASSES, Cup, cup_from_dict
from saucerfab.errors import ConfigError, InputFileError
from saucerfab.formats import TABLE
from saucerfab.scene import EXTENT_TOLERANCE, FULL_EXTENT, MAX_GRID

#: largest scene.json read (a real one is about 1.5 kB)
MAX_SCENE_JSON_BYTES = 1 << 20
#: largest reference picture read, bytes and pixels
MAX_REFERENCE_BYTES = 64 << 20
MAX_REFERENCE_PIXELS = 4096 * 4096
#: mesh formats verify renders, in the order it prefers them (textured formats;
#: "zip" is an OBJ zipped with its MTL and PNG, as ``export --zip-obj`` writes it)
RENDERED_FORMATS = ("obj", "zip", "3mf", "glb")
#: suffix of each rendered format's mesh file (from the formats table)
_SUFFIX = {f: TABLE[f].mesh_suffix if f in TABLE else f".{f}" for f in RENDERED_FORMATS}
#: view names a print may have, in report order
VIEW_NAMES = ("direct", "reflected", "reflected2")


class VerifyInputError(InputFileError):
    """A print folder (or a file in it) that verify cannot use."""


@dataclass(frozen=True)
class ViewSpec:
    """One view frame of ``scene.json`` (file frame, mm).

    Attributes:
        name: ``direct``, ``reflected`` or ``reflected2``.
        target: (3,) point the view axis passes through, mm.
        viewing_angle_deg: SoftRas's half field of view: tan(angle) = half
            the frame's width / depth along the axis.
        extent: (ex, ey) the picture's half width and half height in the
            frame's NDC (:mod:`saucerfab.render.camera`): the picture covers
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
        outline: the cup's own shape (:mod:`saucerfab.cups`) built from the
            file's fields, lengths in mm, about its axis: its wall
            (:meth:`~saucerfab.cups.Cup.wall`) is what verify ray-traces.
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
    """``scene.json`` as verify uses it.

    Attributes:
        camera: (3,) the design eye, mm, file frame.
        views: view name -> frame, in :data:`VIEW_NAMES` order.
        cup: the mirror cup.
        saucer_x, saucer_y: the saucer's footprint (min, max), mm.
        mm_per_unit: millimetres per model unit.
        glb_matrix: (4, 4) the GLB node's matrix (file frame in metres -> glTF's y-up).
    """

    camera: tuple[float, float, float]
    views: dict[str, ViewSpec]
    cup: CupSpec
    saucer_x: tuple[float, float]
    saucer_y: tuple[float, float]
    mm_per_unit: float
    glb_matrix: np.ndarray


def _bad(path: Path, what: str) -> VerifyInputError:
    return VerifyInputError(f"{path}: {what}; re-export the design with 'saucerfab export' to get a valid scene.json")


def _num(path: Path, v: Any, what: str, *, positive: bool = False, limit: float = 1e7) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > limit:
        raise _bad(path, f"{what} must be a finite number (|x| <= {limit:g}), got {str(v)[:40]!r}")
    if positive and v <= 0:
        raise _bad(path, f"{what} must be positive, got {v!r}")
    return float(v)


def _vec(path: Path, v: Any, n: int, what: str) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n:
        raise _bad(path, f"{what} must be a list of {n} numbers, got {str(v)[:60]!r}")
    return tuple(_num(path, x, what) for x in v)


def _extent(path: Path, v: Any, what: str) -> tuple[float, float]:
    """A view's ``extent``: two numbers in (0, 1], the larger 1 within :data:`EXTENT_TOLERANCE` (made exactly 1)."""
    ex, ey = _vec(path, v, 2, what)
    rule = (f"{what} is the picture's half width and half height in its square frame: two numbers in (0, 1], "
            f"the larger 1 (a 2:1 picture: [1.0, 0.5])")
    if not (0.0 < ex <= 1.0 and 0.0 < ey <= 1.0) or max(ex, ey) < 1.0 - EXTENT_TOLERANCE:
        raise _bad(path, f"{rule}; got {[ex, ey]}")
    # a side at 1 is the frame's own edge: exactly 1, so that a writer's rounding loses no edge pixel
    return (1.0 if ex >= 1.0 - EXTENT_TOLERANCE else ex, 1.0 if ey >= 1.0 - EXTENT_TOLERANCE else ey)


def _obj(path: Path, d: Any, key: str) -> dict[str, Any]:
    v = d.get(key) if isinstance(d, dict) else None
    if not isinstance(v, dict):
        raise _bad(path, f"'{key}' is missing or not an object")
    return v


def load_print_scene(folder: Path) -> PrintScene:
    """Read and validate ``folder/scene.json``.

    Raises:
        VerifyInputError: missing, too large, not JSON, wrong schema, or a
            value out of range.
    """
    path = folder / "scene.json"
    if not path.is_file():
        raise VerifyInputError(
            f"{folder} is not a print folder: it has no scene.json; give the folder 'saucerfab export --out' wrote"
        )
    if path.stat().st_size > MAX_SCENE_JSON_BYTES:
        raise _bad(path, f"the file is over {MAX_SCENE_JSON_BYTES:,} bytes, far more than any scene")
    try:
        d = json.loads(path.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise _bad(path, f"not valid JSON ({str(exc)[:80]})") from None
    if not isinstance(d, dict) or d.get("schema") != "saucerfab.scene/1":
        got = d.get("schema") if isinstance(d, dict) else None
        raise _bad(path, f"schema is {str(got)[:40]!r}, expected 'saucerfab.scene/1'")
    if d.get("units") != "mm":
        raise _bad(path, f"units are {str(d.get('units'))[:20]!r}; verify reads scenes in 'mm'")
    camera = _vec(path, _obj(path, d, "camera").get("position"), 3, "camera.position")
    views_d = _obj(path, d, "views")
    views: dict[str, ViewSpec] = {}
    for name in VIEW_NAMES:
        if name not in views_d:
            continue
        v = views_d[name]
        if not isinstance(v, dict):
            raise _bad(path, f"views.{name} is not an object")
        target = _vec(path, v.get("target"), 3, f"views.{name}.target")
        angle = _num(path, v.get("viewing_angle_deg"), f"views.{name}.viewing_angle_deg", positive=True)
        if angle >= 89:
            raise _bad(path, f"views.{name}.viewing_angle_deg {angle} is not below 89 degrees")
        if math.dist(target, camera) < 1e-6:
            raise _bad(path, f"views.{name}.target is the camera position")
        fwd = np.subtract(target, camera)
        if np.linalg.norm(np.cross(fwd / np.linalg.norm(fwd), (0.0, 0.0, 1.0))) < 1e-9:
            raise _bad(path, f"views.{name} looks straight up or down; its image orientation is undefined")
        extent = _extent(path, v["extent"], f"views.{name}.extent") if "extent" in v else FULL_EXTENT
        views[name] = ViewSpec(name, target, angle, extent)  # type: ignore[arg-type]
    for name in ("direct", "reflected"):
        if name not in views:
            raise _bad(path, f"views.{name} is missing")
    c = _obj(path, d, "cup")
    shape = c.get("shape")
    if shape not in CUP_CLASSES:
        raise _bad(path, f"cup.shape is {str(shape)[:20]!r}; known: {', '.join(CUP_CLASSES)}")
    center = _vec(path, c.get("center"), 2, "cup.center")
    bottom_z = _num(path, c.get("bottom_z"), "cup.bottom_z")
    height = _num(path, c.get("height"), "cup.height", positive=True)
    shape_fields = {k: v for k, v in c.items() if k not in ("center", "bottom_z")}
    for key, value in shape_fields.items():  # every length and angle a bounded number (sides too)
        if key != "shape":
            for x in value if isinstance(value, list) else [value]:
                _num(path, x, f"cup.{key}")
    try:
        outline = cup_from_dict(shape_fields, shape)  # the shape's own checks, as for a scene file
    except (ConfigError, TypeError, ValueError) as exc:
        raise _bad(path, f"cup: {str(exc)[:200]}") from None
    cup = CupSpec(center, bottom_z, height, outline)  # type: ignore[arg-type]
    saucer = _obj(path, d, "saucer")
    sx = _vec(path, saucer.get("x_range"), 2, "saucer.x_range")
    sy = _vec(path, saucer.get("y_range"), 2, "saucer.y_range")
    if not (sx[0] < sx[1] and sy[0] < sy[1]):
        raise _bad(path, "saucer.x_range and y_range must be (min, max) with min < max")
    mpu = _num(path, d.get("mm_per_unit"), "mm_per_unit", positive=True)
    glb = d.get("glb") if isinstance(d.get("glb"), dict) else {}
    mat = glb.get("node_matrix_column_major", [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0])
    m = np.array(_vec(path, mat, 16, "glb.node_matrix_column_major"), np.float64).reshape(4, 4).T
    if abs(np.linalg.det(m[:3, :3])) < 1e-9:
        raise _bad(path, "glb.node_matrix_column_major is singular")
    return PrintScene(camera, views, cup, sx, sy, mpu, m)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- meshes


@dataclass
class PrintedSurface:
    """One mesh file as printed: geometry in the file frame and its colours.

    Attributes:
        path: the mesh file.
        format: ``obj``, ``zip`` (a zipped OBJ), ``3mf`` or ``glb``.
        vertices: (V, 3) float64 positions, mm, file frame (z up).
        faces: (F, 3) int64 vertex indices.
        corner_uv: (F, 3, 2) texture coordinates per face corner (u right,
            v up), NaN where a face has none.
        face_texture: (F,) index into ``textures``, -1 for an untextured face.
        textures: (H, W, 3) uint8 sRGB images, row 0 at the top.
        top: (F,) bool, the faces of the saucer's coloured top (inside the
            footprint, facing up): what the viewer is meant to see.
    """

    path: Path
    format: str
    vertices: np.ndarray
    faces: np.ndarray
    corner_uv: np.ndarray
    face_texture: np.ndarray
    textures: list[np.ndarray]
    top: np.ndarray


def find_mesh_files(folder: Path) -> list[tuple[str, Path]]:
    """The rendered-format mesh files in ``folder``, preferred format first."""
    out: list[tuple[str, Path]] = []
    for fmt in RENDERED_FORMATS:
        for p in sorted(folder.glob(f"*{_SUFFIX[fmt]}")):
            if p.is_file() and not p.name.startswith("."):
                out.append((fmt, p))
    return out


def top_faces(vertices: np.ndarray, faces: np.ndarray, scene: PrintScene) -> np.ndarray:
    """(F,) bool: faces inside the saucer's footprint whose normal points up.

    The solid's walls are vertical (normal z = 0) and its base faces down;
    the seat plate lies outside the footprint. Heightfield faces as steep as
    a spike still have a positive normal z.
    """
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1)
    nz = np.divide(n[:, 2], length, out=np.zeros(len(faces)), where=length > 0)
    (x0, x1), (y0, y1) = scene.saucer_x, scene.saucer_y
    tol = 1e-6 * max(x1 - x0, y1 - y0)
    inside = (
        (tri[..., 0] >= x0 - tol).all(1)
        & (tri[..., 0] <= x1 + tol).all(1)
        & (tri[..., 1] >= y0 - tol).all(1)
        & (tri[..., 1] <= y1 + tol).all(1)
    )
    return inside & (nz > 1e-6)


#: the most triangles saucerfab's own export holds (a design at ``scene.MAX_GRID``: two triangles a grid cell on
#: top, as many again at most for the base, walls and seat); see :func:`folder_limits`
MAX_OWN_TRIANGLES = 4 * MAX_GRID**2
#: the most bytes :func:`folder_limits` trusts a folder's files to need (file, texture, inflated archive)
MAX_OWN_BYTES = 4 << 30


def folder_limits(folder: Path) -> Any:
    """The checker's limits for reading ``folder``'s meshes: the defaults, raised to the folder's own export.

    The defaults bound a stranger's file to 500,000 triangles and one
    8192 x 8192 texture; an export of a design at the largest grid holds
    millions of triangles and up to a 16384 px atlas, and verify must read
    it. So the limits are raised to the triangle count and atlas size its
    ``export.json`` states, and to its files' sizes on disk - but never past
    what saucerfab's own export can hold (:data:`MAX_OWN_TRIANGLES`,
    ``fabricate.options.MAX_TEXTURE_PX``, :data:`MAX_OWN_BYTES`), since the
    folder may come from elsewhere. A folder without a readable summary
    gets the defaults.
    """
    from saucerfab.check.limits import DEFAULT_LIMITS, inflated_bytes
    from saucerfab.fabricate.options import MAX_TEXTURE_PX

    lim = DEFAULT_LIMITS.with_(keep_texture_pixels=True)
    try:
        path = folder / "export.json"
        if path.stat().st_size > MAX_SCENE_JSON_BYTES:
            return lim
        d = json.loads(path.read_bytes().decode("utf-8"))
        tri, px = d["triangles"], d["texture_px"]
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, KeyError, TypeError):
        return lim
    if not (isinstance(tri, int) and isinstance(px, int)):
        return lim
    files = [p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")]
    return lim.raised_to(
        triangles=min(max(tri, 0), MAX_OWN_TRIANGLES),
        texture_px=min(max(px, 0), MAX_TEXTURE_PX),
        file_bytes=min(max((p.stat().st_size for p in files), default=0), MAX_OWN_BYTES),
        inflated_bytes=min(inflated_bytes([p for p in files if p.suffix.lower() in (".3mf", ".zip")]), MAX_OWN_BYTES),
    )


def design_parameters(folder: Path) -> dict[str, Any]:
    """The parameters of the design a print folder was exported from (``export.json``), or {} when unreadable.

    Read with the same bound as ``scene.json``; what verify takes from it
    (the eyes the design was made for) falls back to its defaults.
    """
    try:
        path = folder / "export.json"
        if path.stat().st_size > MAX_SCENE_JSON_BYTES:
            return {}
        params = json.loads(path.read_bytes().decode("utf-8"))["design"]["parameters"]
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, KeyError, TypeError):
        return {}
    return params if isinstance(params, dict) else {}


def read_surface(path: Path, fmt: str, scene: PrintScene, limits: Any = None) -> PrintedSurface:
    """Read one exported mesh file with its textures (bounded, as the checker reads).

    ``limits``: the checker's limits to read it with (:func:`folder_limits`;
    default: the checker's defaults).

    Raises:
        VerifyInputError: unreadable, no texture, or a texture that cannot be decoded.
    """
    from saucerfab.check.limits import DEFAULT_LIMITS
    from saucerfab.check.meshdata import ReadError
    from saucerfab.check.readers import read_mesh

    if limits is None:
        limits = DEFAULT_LIMITS
    try:
        md = read_mesh(path, limits.with_(keep_texture_pixels=True))
    except ReadError as exc:
        raise VerifyInputError(f"{path.name}: cannot be read ({exc.code}): {exc.message}") from None
    if md.corner_uv is None or md.face_texture is None or not md.textures:
        raise VerifyInputError(
            f"{path.name} has no texture; verify renders textured files (OBJ, 3MF, GLB) as exported by "
            "'saucerfab export'"
        )
    textures: list[np.ndarray] = []
    for t in md.textures:
        if t.status != "ok" or t.pixels is None:
            raise VerifyInputError(f"{path.name}: texture {t.name!r} cannot be used ({t.status}): {t.message}")
        textures.append(t.pixels)
    v = md.vertices * md.unit_mm
    if fmt == "glb" or md.format in ("glb", "gltf"):
        # back from glTF's y-up frame to the file frame of scene.json (metres -> mm done above)
        inv = np.linalg.inv(scene.glb_matrix[:3, :3])
        v = v @ inv.T
    if not np.isfinite(v).all():
        raise VerifyInputError(f"{path.name} has NaN or infinite vertex positions")
    face_tex = md.face_texture.astype(np.int64)
    uv = md.corner_uv
    if md.format in ("glb", "gltf"):
        uv = uv * (1.0, -1.0) + (0.0, 1.0)  # glTF's v runs down from the image's top; here v runs up
    bad_uv = ~np.isfinite(uv).all(axis=(1, 2))
    face_tex = np.where(bad_uv, -1, face_tex)
    return PrintedSurface(
        path=path,
        format=fmt,
        vertices=v,
        faces=md.faces,
        corner_uv=np.nan_to_num(uv, nan=0.0),
        face_texture=face_tex,
        textures=textures,
        top=top_faces(v, md.faces, scene),
    )


# --------------------------------------------------------------------------- references


def load_references(folder: Path, views: list[str]) -> dict[str, np.ndarray]:
    """The reference pictures of ``views``: (S, S, 3) float32 sRGB in [0, 1].

    Raises:
        VerifyInputError: a reference is missing (a folder exported before
            verify existed), unreadable or not square.
    """
    from saucerfab.errors import ImageError
    from saucerfab.images import load_image

    out: dict[str, np.ndarray] = {}
    for view in views:
        p = folder / reference_name(view)
        if not p.is_file():
            raise VerifyInputError(
                f"{folder} has no {p.name} (the {view} picture as the design meant it); "
                "re-export the design with this saucerfab: 'saucerfab export DESIGN --out ...'"
            )
        try:
            img = load_image(p, max_pixels=MAX_REFERENCE_PIXELS, max_bytes=MAX_REFERENCE_BYTES)
        except ImageError as exc:
            raise VerifyInputError(f"{p.name}: {exc}") from None
        if img.rgb.shape[0] != img.rgb.shape[1]:
            raise VerifyInputError(f"{p.name} is {img.size[0]} x {img.size[1]}; a reference picture is square")
        out[view] = img.rgb
    return out
