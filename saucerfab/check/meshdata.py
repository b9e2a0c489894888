"""What a reader hands to the checks: triangles, colour data and notes.

Every reader (3MF, OBJ, PLY, STL, glTF/GLB, VRML) produces one
:class:`MeshData` through a :class:`MeshBuilder`, which enforces the
vertex/triangle caps *before* arrays are allocated and range-checks every
index, so the checks can trust shapes and indices.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.report import Finding, finding
from saucerfab.errors import InputFileError


class ReadError(InputFileError):
    """A file the checker cannot read as a mesh; ``code`` is an unreadable code from ``CODES``."""

    def __init__(self, code: str, message: str, where: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.where = where


@dataclass
class TextureInfo:
    """One texture a file references.

    Attributes:
        name: path as the file gives it (archive entry, relative path, "image 0").
        status: ``ok``, ``missing``, ``unreadable``, ``too_large`` or ``unsafe_path``.
        width, height: pixels (from the header, also when too large), or None.
        image_format: Pillow's format name (``PNG``, ``JPEG``...), or None.
        message: why, when status is not ``ok``.
        pixels: (height, width, 3) uint8 sRGB, row 0 at the top, when the
            limits ask to keep them (``Limits.keep_texture_pixels``); else None.
    """

    name: str
    status: str = "ok"
    width: int | None = None
    height: int | None = None
    image_format: str | None = None
    message: str = ""
    pixels: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "status": self.status, "width": self.width, "height": self.height,
                "format": self.image_format}


@dataclass
class MeshData:
    """A mesh as read, in the file's units, with instance transforms applied.

    Attributes:
        format: ``3mf``, ``obj``, ``stl``, ``ply``, ``glb``, ``gltf`` or ``wrl``.
        vertices: (n, 3) float64 positions (may hold NaN/Inf: a check reports them).
        faces: (m, 3) int64 vertex indices, all in range.
        unit_mm: millimetres per file unit.
        units: the unit's name (``millimeter``, ``inch``...).
        units_stated: whether the file states its unit (3MF, glTF by spec) or it was assumed.
        corner_uv: (m, 3, 2) texture coordinates per face corner as the file stores them (glTF: v
            down from the image's top; the other formats: v up), NaN where a face has none; or None.
        face_texture: (m,) index into ``textures`` per face, -1 for none; or None.
        face_colour: (m,) bool, faces coloured by vertex/face/material colours; or None.
        colour_kinds: which colour carriers the file uses: ``texture``, ``vertex``, ``face``, ``material``.
        textures: every texture referenced.
        parts: mesh parts instanced (objects, primitives, shapes).
        notes: warnings/info the reader found (skipped content, extension mismatch...).
    """

    format: str
    vertices: np.ndarray
    faces: np.ndarray
    unit_mm: float = 1.0
    units: str = "millimeter"
    units_stated: bool = False
    corner_uv: np.ndarray | None = None
    face_texture: np.ndarray | None = None
    face_colour: np.ndarray | None = None
    colour_kinds: set[str] = field(default_factory=set)
    textures: list[TextureInfo] = field(default_factory=list)
    parts: int = 1
    notes: list[Finding] = field(default_factory=list)


class MeshBuilder:
    """Collects parts, checking caps before allocation and indices on arrival."""

    def __init__(self, fmt: str, limits: Limits) -> None:
        self.fmt = fmt
        self.limits = limits
        self.nv = 0
        self.nf = 0
        self._v: list[np.ndarray] = []
        self._f: list[np.ndarray] = []
        self._uv: list[np.ndarray | None] = []
        self._tex: list[np.ndarray | None] = []
        self._col: list[np.ndarray | None] = []
        self.textures: list[TextureInfo] = []
        self._tex_keys: dict[str, int] = {}
        self.colour_kinds: set[str] = set()
        self.notes: list[Finding] = []
        self._noted: set[str] = set()
        self.parts = 0

    def reserve(self, n_vertices: int, n_faces: int, what: str = "", *, parts: int = 1, at_least: bool = False) -> None:
        """Refuse (``over_check_limit``) before allocating ``parts`` more parts (of these sizes in all) over the caps.

        ``at_least``: the counts are lower bounds (a count that stopped once
        past a cap), so the refusal does not repeat them as the option's value.
        """
        nf, nv = self.nf + n_faces, self.nv + n_vertices
        some = "at least " if at_least else ""
        if nf > self.limits.max_triangles:
            raise ReadError(
                "over_check_limit",
                f"{what or 'the file'} would bring the triangle count to {some}{nf:,}, over the "
                f"checker's limit of {self.limits.max_triangles:,} (Limits.max_triangles); "
                f"{raise_hint(None if at_least else nf)}",
            )
        if nv > self.limits.max_vertices:
            raise ReadError(
                "over_check_limit",
                f"{what or 'the file'} would bring the vertex count to {some}{nv:,}, over the "
                f"checker's limit of {self.limits.max_vertices:,} (Limits.max_vertices, 3 per allowed triangle); "
                f"{raise_hint(None if at_least else -(-nv // 3))}",
            )
        if self.parts + parts > self.limits.max_parts:
            raise ReadError("over_check_limit", f"more than {self.limits.max_parts:,} mesh parts (Limits.max_parts); "
                                                f"{raise_hint()}")

    def add(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        *,
        corner_uv: np.ndarray | None = None,
        face_texture: np.ndarray | None = None,
        face_colour: np.ndarray | None = None,
        what: str = "",
        parts: int = 1,
    ) -> None:
        """Add one part (or ``parts`` instances at once); ``faces`` index into this call's ``vertices``."""
        vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(faces).reshape(-1, 3)
        self.reserve(len(vertices), len(faces), what, parts=parts)
        if faces.size:
            if not np.issubdtype(faces.dtype, np.integer):
                raise ReadError("malformed", f"{what or 'face'} indices are not integers")
            faces = faces.astype(np.int64, copy=False)
            lo, hi = int(faces.min()), int(faces.max())
            if lo < 0 or hi >= len(vertices):
                badmask = (faces < 0) | (faces >= len(vertices))
                bad = int(np.flatnonzero(badmask.any(axis=1))[0])
                idx = int(faces[bad][badmask[bad]][0])
                raise ReadError(
                    "index_out_of_range",
                    f"{what or 'a'} face {self.nf + bad} uses vertex index {idx} but there are "
                    f"{len(vertices):,} vertices (valid 0..{len(vertices) - 1})",
                    where={"faces": [self.nf + bad]},
                )
        m = len(faces)
        self._v.append(vertices)
        self._f.append(faces + self.nv)
        self._uv.append(None if corner_uv is None else np.asarray(corner_uv, dtype=np.float64).reshape(m, 3, 2))
        self._tex.append(None if face_texture is None else np.asarray(face_texture, dtype=np.int32).reshape(m))
        self._col.append(None if face_colour is None else np.asarray(face_colour, dtype=bool).reshape(m))
        self.nv += len(vertices)
        self.nf += m
        self.parts += parts

    def texture(self, key: str, load: Any) -> int:
        """Index of texture ``key``, calling ``load() -> TextureInfo`` the first time."""
        if key not in self._tex_keys:
            if len(self.textures) >= self.limits.max_textures:
                raise ReadError("over_check_limit", f"more than {self.limits.max_textures} textures (Limits.max_textures)")
            self._tex_keys[key] = len(self.textures)
            self.textures.append(load())
        return self._tex_keys[key]

    def note(self, code: str, message: str, **kw: Any) -> None:
        """A reader warning/info, each code once (the first message says enough)."""
        if code not in self._noted:
            self._noted.add(code)
            self.notes.append(finding(code, message, **kw))

    def build(self, *, unit_mm: float = 1.0, units: str = "millimeter", units_stated: bool = False) -> MeshData:
        if self.nf == 0:
            raise ReadError("no_triangles", "the file holds no triangles")
        m_parts = [len(f) for f in self._f]

        def cat(parts: list[np.ndarray | None], shape: tuple[int, ...], fill: Any, dtype: Any) -> np.ndarray | None:
            if all(p is None for p in parts):
                return None
            return np.concatenate(
                [p if p is not None else np.full((m, *shape), fill, dtype=dtype) for p, m in zip(parts, m_parts)]
            )

        return MeshData(
            format=self.fmt,
            vertices=np.concatenate(self._v) if self._v else np.zeros((0, 3)),
            faces=np.concatenate(self._f),
            unit_mm=unit_mm,
            units=units,
            units_stated=units_stated,
            corner_uv=cat(self._uv, (3, 2), np.nan, np.float64),
            face_texture=cat(self._tex, (), -1, np.int32),
            face_colour=cat(self._col, (), False, bool),
            colour_kinds=set(self.colour_kinds),
            textures=list(self.textures),
            parts=self.parts,
            notes=list(self.notes),
        )
