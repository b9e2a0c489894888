"""``verify --bleed``: the print's colours as a full-colour printer blurs them (:mod:`saucerfab.fabricate.bleed`).

A PolyJet print's colour sits in translucent resin and spreads along the
surface (a printer profile's ``colour_bleed_mm``, the standard deviation of a
Gaussian). Verify reads the files as written; with ``--bleed`` each texture
is blurred as the printer would print it before the renders, chart by chart
of the files' own texture map (:func:`saucerfab.fabricate.bleed.bleed_mesh_texture`),
so the scores say what the print looks like, and whether an export's
``--bleed-compensation`` brought it back.

The width is the printer's (``--bleed`` alone: the profile ``export.json``
names) or one given in millimetres (``--bleed 0.2``). A print exported with
``--bleed-compensation on`` is verified blurred by its printer's bleed
without being asked (:func:`compensated_width`): its pre-sharpened texture is only
right as it prints, and read as written it would score its halos.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.verify.printfolder import PrintedSurface, export_record

#: ``--bleed`` without a width: the width of the printer the folder was exported for
BLEED_OF_PRINTER = "printer"


def export_printer(folder: Path) -> str | None:
    """The printer key ``export.json`` names, or None when it is missing or unreadable."""
    printer = export_record(folder).get("printer")
    key = printer.get("key") if isinstance(printer, dict) else None
    return key if isinstance(key, str) else None


def compensated_width(folder: Path) -> float | None:
    """The bleed, mm, the folder's texture was pre-sharpened for (``export --bleed-compensation on`` records
    it in ``export.json``), or None: not compensated, or nothing was (a printer with no width)."""
    from saucerfab.model.profiles import MAX_COLOUR_BLEED_MM

    record = export_record(folder)
    options, bleed = record.get("options"), record.get("bleed")
    if not (isinstance(options, dict) and options.get("bleed_compensation") == "on" and isinstance(bleed, dict)):
        return None
    width = bleed.get("sigma_mm")
    if isinstance(width, bool) or not isinstance(width, (int, float)):
        return None
    return float(width) if math.isfinite(width) and 0 < width <= MAX_COLOUR_BLEED_MM else None


def bleed_width_mm(folder: Path, value: str | None) -> float | None:
    """The bleed ``--bleed VALUE`` asks for, mm; None without ``--bleed``.

    Args:
        folder: the print folder (its ``export.json`` names the printer).
        value: None (no bleed), :data:`BLEED_OF_PRINTER` (the printer's
            ``colour_bleed_mm``) or a width in millimetres.

    Raises:
        ConfigError: a width that is not a positive number up to the profiles'
            largest, or a printer whose profile states none.
    """
    from saucerfab.model.profiles import MAX_COLOUR_BLEED_MM, load_profile

    if value is None:
        return None
    if value == BLEED_OF_PRINTER:
        key = export_printer(folder)
        if key is None:
            raise ConfigError(f"{folder}/export.json names no printer to take the colour bleed from; "
                              "give the width: --bleed 0.12 (mm)")
        width = float(load_profile(key).colour_bleed_mm)
        if width <= 0:
            raise ConfigError(f"the printer {key!r}'s profile states no colour_bleed_mm; give the width: "
                              "--bleed 0.12 (mm)")
        return width
    try:
        width = float(value)
    except ValueError:
        width = math.nan
    if not (math.isfinite(width) and 0 < width <= MAX_COLOUR_BLEED_MM):
        raise ConfigError(f"--bleed takes a width in mm over 0 and up to {MAX_COLOUR_BLEED_MM:g} (the point "
                          f"spread's standard deviation, e.g. 0.12), or nothing for the printer's; got {value!r}")
    return width


def bleed_surface(surface: PrintedSurface, sigma_mm: float) -> PrintedSurface:
    """``surface`` with each of its textures blurred as printed by a bleed of ``sigma_mm``.

    The files give each face corner its own texture coordinate; corners at the
    same coordinate are one texture vertex, so the faces of one chart of the
    map (the top's planar map, each chart of the walls) join up and each chart
    is blurred on its own, at its own texel density.
    """
    textures = list(surface.textures)
    for tex_id in range(len(textures)):
        sel = np.flatnonzero((surface.face_texture == tex_id) & np.isfinite(surface.corner_uv).all(axis=(1, 2)))
        if sel.size == 0:
            continue
        from saucerfab.fabricate.bleed import bleed_mesh_texture

        uvs, inverse = np.unique(surface.corner_uv[sel].reshape(-1, 2), axis=0, return_inverse=True)
        textures[tex_id] = bleed_mesh_texture(textures[tex_id], surface.vertices, surface.faces[sel], uvs,
                                              inverse.reshape(-1, 3), sigma_mm)
    return replace(surface, textures=textures)
