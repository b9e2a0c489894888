"""Reading a print folder back from disk for verification.

A print folder is what ``saucerfab export`` writes: the mesh files, their
textures, ``scene.json`` (the viewing geometry in the files' millimetres,
schema ``saucerfab.scene/1``, written by :mod:`saucerfab.fabricate.scene_json`
and read by :mod:`saucerfab.fabricate.scene_file`)
and the reference pictures ``reference_<view>.png`` (each input picture as
the designer meant it: alpha composited over the design's background and
fitted into its square view frame by the design's rule, in the frame's
centred rectangle ``extent`` when it keeps its own aspect).

Everything here treats the folder as untrusted (a bureau verifies folders
it was sent): ``scene.json`` is size-bounded and every number is checked,
meshes go through the checker's bounded readers
(:func:`saucerfab.check.readers.read_mesh`) and pictures through the
bounded image loader. Any problem raises :class:`VerifyInputError` (exit 2)
with what is wrong and what to do (a bad ``scene.json``: the reader's
:class:`~saucerfab.errors.SceneFileError`, raised again as verify's).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.errors import InputFileError, SceneFileError
from saucerfab.fabricate.scene_file import MAX_SCENE_JSON_BYTES, PrintScene, read_scene_file
from saucerfab.files.formats import TABLE
from saucerfab.model.design_folder import reference_name
from saucerfab.model.footprint import in_grown_footprint
from saucerfab.model.scene import CUP_RING_MM, MAX_GRID

#: largest reference picture read, bytes and pixels
MAX_REFERENCE_BYTES = 64 << 20
MAX_REFERENCE_PIXELS = 4096 * 4096
#: mesh formats verify renders, in the order it prefers them (textured formats;
#: "zip" is an OBJ zipped with its MTL and PNG, as ``export --zip-obj`` writes it)
RENDERED_FORMATS = ("obj", "zip", "3mf", "glb")
#: suffix of each rendered format's mesh file (from the formats table)
_SUFFIX = {f: TABLE[f].mesh_suffix if f in TABLE else f".{f}" for f in RENDERED_FORMATS}


class VerifyInputError(InputFileError):
    """A print folder (or a file in it) that verify cannot use."""


def load_print_scene(folder: Path) -> PrintScene:
    """Read and validate ``folder/scene.json`` (:func:`saucerfab.fabricate.scene_file.read_scene_file`).

    The scene's footprint (``saucer_x``, ``saucer_y``) is always set: a
    print's scene.json must have it.

    Raises:
        VerifyInputError: missing, too large, not JSON, wrong schema, or a
            value out of range (the reader's message, as verify's error: exit 2).
    """
    path = folder / "scene.json"
    if not path.is_file():
        raise VerifyInputError(
            f"{folder} is not a print folder: it has no scene.json; give the folder 'saucerfab export --out' wrote"
        )
    try:
        return read_scene_file(path)
    except SceneFileError as exc:
        raise VerifyInputError(str(exc)) from None


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
    if scene.is_disc:
        # a round part's seat (the pocket's floor, its rim) lies inside the disc: it is not the relief's top;
        # it stands within the cup's ring (CUP_RING_MM around the cup's footprint), which holds no design
        c = tri.mean(axis=1)[:, :2] - np.asarray(scene.cup.center)
        inside &= ~in_grown_footprint(scene.cup.outline, c, CUP_RING_MM)
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


def export_record(folder: Path) -> dict[str, Any]:
    """A print folder's ``export.json``, read with the same bound as ``scene.json``, or {} when unreadable."""
    try:
        path = folder / "export.json"
        if path.stat().st_size > MAX_SCENE_JSON_BYTES:
            return {}
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return {}
    return doc if isinstance(doc, dict) else {}


def design_parameters(folder: Path) -> dict[str, Any]:
    """The parameters of the design a print folder was exported from (``export.json``), or {} when unreadable.

    What verify takes from it (the eyes the design was made for) falls back to its defaults.
    """
    design = export_record(folder).get("design")
    params = design.get("parameters") if isinstance(design, dict) else None
    return params if isinstance(params, dict) else {}


def shading_note(folder: Path) -> str | None:
    """The line ``verify`` prints in emitted light for a print whose texture ``export --shading-compensation``
    compensated for a light's shading (``export.json``'s options): its colours are only right under that
    light, so its emitted scores read low. None for any other print (or an unreadable record)."""
    from saucerfab.fabricate.options import SHADING_COMPENSATIONS

    options = export_record(folder).get("options")
    light = options.get("shading_compensation") if isinstance(options, dict) else None
    if light == "off" or light not in SHADING_COMPENSATIONS:
        return None
    return (f"this print's colours are compensated for the {light} light's shading (export --shading-compensation "
            f"{light}); verify it with --light room to score it as it will be seen")


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
    from saucerfab.imaging.images import load_image

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
