"""Printer profiles: what a full-colour printer or bureau can make and accepts.

Profiles are TOML files: the ones that ship live in ``printers/`` at the top
of the project (and are packaged under ``saucerfab/data/printers``); a user's
own are read from ``$SAUCERFAB_PRINTERS`` (a folder) or given as a path.
Lengths are millimetres.

Both the fabrication stage (what to build, how fine a texture) and the
checker (will this file print there) read them, so this module sits at the
package's top and imports nothing heavy.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from saucerfab.errors import ConfigError
from saucerfab.files.formats import FORMATS
from saucerfab.files.tomlfile import read_toml

#: the profile used when none is named
DEFAULT_PRINTER = "j55"
#: what a profile's exports may do about walls and features under its minimums
THIN_POLICIES = ("warn", "refuse")
#: largest profile file read (a real one is a few hundred bytes)
MAX_PROFILE_BYTES = 100_000
#: the widest colour bleed a profile may state, mm: a printer blurring its colours over millimetres would
#: print no picture, and a width in micrometres typed as millimetres (120 for 0.12) is caught
MAX_COLOUR_BLEED_MM = 2.0


@dataclass(frozen=True)
class PrinterProfile:
    """One printer or bureau.

    Attributes:
        key: short name used on the command line (file stem), e.g. ``j55``.
        name: human name, e.g. ``Stratasys J55 Prime``.
        build_volume_mm: (x, y, z) largest part, millimetres.
        min_wall_mm: thinnest wall the printer makes reliably.
        min_feature_mm: smallest detail (spike, ridge) it resolves.
        dpi: colour resolution, dots per inch; sets the texture atlas size.
        max_texture_px: largest texture edge its software accepts.
        accepted_formats: export formats its software or the bureau accepts.
        preferred_format: the one to send when there is a choice.
        max_triangles: polygon limit (0 = none).
        max_file_mb: file size limit (0 = none).
        thin_policy: what an export does about walls and features under the
            minimums that it cannot fix: ``warn`` (writes the files and says
            so) or ``refuse``. The checker's verdict does not depend on it
            (walls under min_wall_mm over more than
            ``Limits.thin_wall_error_fraction`` of the surface are not
            printable on any profile).
        colour_bleed_mm: the lateral colour bleed: the standard deviation, mm, of the
            Gaussian point spread that blurs the printed colour along the surface (light
            scattering in translucent resin; :mod:`saucerfab.fabricate.bleed`); 0 (the
            default for a profile that states none): no bleed known, nothing compensated.
        notes: free text.
    """

    key: str
    name: str
    build_volume_mm: tuple[float, float, float]
    min_wall_mm: float
    min_feature_mm: float
    dpi: float
    max_texture_px: int
    accepted_formats: tuple[str, ...]
    preferred_format: str
    max_triangles: int = 0
    max_file_mb: float = 0.0
    thin_policy: str = "warn"
    colour_bleed_mm: float = 0.0
    notes: str = ""

    def fits(self, bbox_mm: tuple[float, float, float]) -> bool:
        """Whether a part of bounding box ``bbox_mm`` (x, y, z) fits the build volume, turned about z as needed (z stays up)."""
        (a, b), (p, q) = sorted(bbox_mm[:2]), sorted(self.build_volume_mm[:2])
        return a <= p and b <= q and bbox_mm[2] <= self.build_volume_mm[2]

    def texture_px_for(self, size_mm: float) -> int:
        """Atlas edge in pixels for a part ``size_mm`` across, at this dpi (power of two, capped)."""
        want = size_mm / 25.4 * self.dpi
        px = 256
        while px < want and px < self.max_texture_px:
            px *= 2
        return min(px, self.max_texture_px)


def _default_dirs() -> list[Path]:
    dirs = []
    env = os.environ.get("SAUCERFAB_PRINTERS")
    if env:
        dirs.append(Path(env))
    here = Path(__file__).resolve()
    dirs.append(here.parents[2] / "printers")  # source checkout
    dirs.append(here.parents[1] / "data" / "printers")  # installed package data
    return dirs


#: keys a profile may leave out (PrinterProfile's defaults apply), and how each is read
_OPTIONAL: dict[str, Callable[[Any], Any]] = {
    "max_triangles": int, "max_file_mb": float, "thin_policy": str, "colour_bleed_mm": float, "notes": str,
}


def _size(v: float) -> bool:
    """Whether ``v`` is a size: finite and positive."""
    return math.isfinite(v) and v > 0


def _parse(path: Path) -> PrinterProfile:
    d = read_toml(path, "printer profile", max_bytes=MAX_PROFILE_BYTES, size_hint="a profile is a few lines",
                  nesting_hint="a profile is a few flat keys")
    required = {
        "name", "build_volume_mm", "min_wall_mm", "min_feature_mm", "dpi",
        "max_texture_px", "accepted_formats", "preferred_format",
    }
    missing = required - set(d)
    if missing:
        raise ConfigError(f"printer profile {str(path)!r} lacks {sorted(missing)}")
    unknown = set(d) - required - set(_OPTIONAL)
    if unknown:
        raise ConfigError(f"printer profile {str(path)!r} has unknown key(s) {sorted(unknown)}")
    try:
        prof = PrinterProfile(
            key=path.stem,
            name=str(d["name"]),
            build_volume_mm=tuple(float(x) for x in d["build_volume_mm"]),  # type: ignore[arg-type]
            min_wall_mm=float(d["min_wall_mm"]),
            min_feature_mm=float(d["min_feature_mm"]),
            dpi=float(d["dpi"]),
            max_texture_px=int(d["max_texture_px"]),
            accepted_formats=tuple(str(f).lower() for f in d["accepted_formats"]),
            preferred_format=str(d["preferred_format"]).lower(),
            **{k: convert(d[k]) for k, convert in _OPTIONAL.items() if k in d},  # others: the defaults
        )
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"printer profile {str(path)!r} has a bad value: {exc}") from None
    bad = [f for f in prof.accepted_formats if f not in FORMATS]
    broken = [
        rule for rule, ok in (
            ("build_volume_mm must be 3 finite positive sizes",
             len(prof.build_volume_mm) == 3 and all(math.isfinite(v) and v > 0 for v in prof.build_volume_mm)),
            (f"min_wall_mm must be finite and positive, got {prof.min_wall_mm!r}", _size(prof.min_wall_mm)),
            (f"min_feature_mm must be finite and positive, got {prof.min_feature_mm!r}", _size(prof.min_feature_mm)),
            (f"dpi must be finite and positive, got {prof.dpi!r}", _size(prof.dpi)),
            (f"max_texture_px must be a whole number >= 256, got {d['max_texture_px']!r}",
             prof.max_texture_px >= 256 and d["max_texture_px"] == prof.max_texture_px),
            (f"accepted_formats must come from {', '.join(FORMATS)} (unknown: {', '.join(bad)})", not bad),
            (f"preferred_format {prof.preferred_format!r} must be one of accepted_formats "
             f"({', '.join(prof.accepted_formats)})", prof.preferred_format in prof.accepted_formats),
            (f"thin_policy must be {'|'.join(THIN_POLICIES)}, got {prof.thin_policy!r}",
             prof.thin_policy in THIN_POLICIES),
            (f"max_triangles must be 0 (no limit) or positive, got {prof.max_triangles!r}", prof.max_triangles >= 0),
            (f"max_file_mb must be 0 (no limit) or finite and positive, got {prof.max_file_mb!r}",
             prof.max_file_mb == 0 or _size(prof.max_file_mb)),
            (f"colour_bleed_mm must be 0 (none known) or a finite size up to {MAX_COLOUR_BLEED_MM:g} mm "
             f"(the point spread's standard deviation, e.g. 0.12), got {prof.colour_bleed_mm!r}",
             prof.colour_bleed_mm == 0
             or (_size(prof.colour_bleed_mm) and prof.colour_bleed_mm <= MAX_COLOUR_BLEED_MM)),
        ) if not ok
    ]
    if broken:
        raise ConfigError(f"printer profile {str(path)!r} is inconsistent: {'; '.join(broken)}")
    return prof


def list_profiles() -> dict[str, PrinterProfile]:
    """All profiles found, by key (earlier folders win)."""
    out: dict[str, PrinterProfile] = {}
    for d in _default_dirs():
        if d.is_dir():
            for p in sorted(d.glob("*.toml")):
                out.setdefault(p.stem, _parse(p))
    return out


def load_profile(name_or_path: str | os.PathLike[str]) -> PrinterProfile:
    """A profile by key (``j55``) or by path to a TOML file."""
    text = os.fspath(name_or_path)
    if text.endswith(".toml") or os.sep in text:
        p = Path(text)
        if not p.is_file():
            raise ConfigError(f"printer profile file {text!r} not found")
        return _parse(p)
    profiles = list_profiles()
    if text not in profiles:
        raise ConfigError(
            f"unknown printer {text!r}; known: {sorted(profiles)} (see 'saucerfab printers'), "
            "or give a path to your own .toml"
        )
    return profiles[text]
