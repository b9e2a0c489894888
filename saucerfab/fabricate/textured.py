"""What every exporter receives, and the small helpers they share.

A :class:`TexturedMesh` is the finished part in file coordinates: shared
positions (so it is watertight as written), texture coordinates indexed per
face corner, the atlas as PNG bytes, per-vertex colours for formats without
textures. Writers are pure functions ``(TexturedMesh, FabOptions | None) -> dict[name, bytes]``
(listed in :mod:`saucerfab.files.formats`);
only :mod:`saucerfab.fabricate.registry` writes files.
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass, field

import numpy as np

from saucerfab import __version__

#: fixed date of every zip entry (the zip epoch), so archives are reproducible
ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@dataclass(frozen=True)
class TexturedMesh:
    """A textured, closed triangle mesh ready to write.

    Attributes:
        name: file stem and object name, e.g. ``saucer``.
        vertices: (V, 3) float64 positions, mm, file frame (positive octant).
        faces: (F, 3) int64, counter-clockwise seen from outside.
        uvs: (T, 2) float64 texture coordinates (u right, v up) in [0, 1].
        face_uvs: (F, 3) int64 indices into ``uvs`` per face corner.
        texture_png: the atlas as PNG bytes (sRGB, 8-bit RGB).
        texture_px: the atlas edge, pixels.
        vertex_rgb: (V, 3) uint8 sRGB per-vertex colour (for PLY).
        decimals: decimals of mm coordinates in text formats.
        meta: extra facts writers may put in headers (JSON-able, no dates).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    face_uvs: np.ndarray
    texture_png: bytes
    texture_px: int
    vertex_rgb: np.ndarray
    decimals: int = 5
    meta: dict[str, object] = field(default_factory=dict)

    @property
    def texture_name(self) -> str:
        """File name of the atlas beside OBJ and VRML files."""
        return f"{self.name}.png"


def generator() -> str:
    """The generator string written into file headers (no date: files are reproducible)."""
    return f"saucerfab {__version__}"


def fmt_rows(values: np.ndarray, decimals: int, template: str | None = None) -> list[str]:
    """Each row of a (K, C) float array as fixed-point text.

    Args:
        values: (K, C) numbers.
        decimals: digits after the point.
        template: a ``str.format`` pattern with C ``{}`` fields, e.g.
            ``'v {} {} {}\n'``; default: the numbers joined by spaces.

    Fixed decimals are exact here (coordinates are already rounded to them)
    and make the text reproducible across platforms.
    """
    c = values.shape[1]
    f = f"{{:.{decimals}f}}"
    pattern = (template or " ".join(["{}"] * c)).replace("{}", f)
    # -0.0 would print as "-0.00000"; adding 0.0 turns it into 0.0
    return [pattern.format(*r) for r in (np.asarray(values, np.float64) + 0.0).tolist()]


def deterministic_zip(entries: list[tuple[str, bytes, bool]]) -> bytes:
    """A zip archive of ``(name, data, compress)`` entries in the given order.

    Every entry has the same fixed date and Unix permissions 0644, so the
    same content always gives the same bytes. PNGs go in stored (they are
    already deflated); XML and text deflated.
    """
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data, compress in entries:
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
            info.create_system = 3  # Unix, so external_attr means permissions
            info.external_attr = 0o100644 << 16
            info.compress_type = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
            zf.writestr(info, data, compresslevel=6 if compress else None)
    return buf.getvalue()
