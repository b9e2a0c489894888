"""Fabrication options: base, cup seat, atlas and colour settings.

All lengths are millimetres in the physical print (after the model frame has
been scaled by ``Scene.mm_per_unit``). The defaults make a part that the
J55-class printers build as it is: a 3 mm plate under the cup's standing
plane, at least 2 mm of material under the saucer's lowest point, and a
1.5 mm deep recess that holds the real cup exactly where the design assumes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Literal

from saucerfab.errors import ConfigError

SeatKind = Literal["recess", "ring", "none"]
SEAT_KINDS: tuple[str, ...] = ("recess", "ring", "none")
BleedCompensation = Literal["on", "off"]
BLEED_COMPENSATIONS: tuple[str, ...] = ("on", "off")
#: ``off``, or the light whose shading the texture is compensated for (:mod:`saucerfab.fabricate.shading`)
ShadingCompensation = Literal["off", "ambient", "room"]
SHADING_COMPENSATIONS: tuple[str, ...] = ("off", "ambient", "room")

#: texture atlas edges we accept (a power of two keeps mipmaps exact)
MIN_TEXTURE_PX, MAX_TEXTURE_PX = 64, 16384


def _pos(name: str, v: float, *, zero_ok: bool = False) -> None:
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
        raise ConfigError(f"{name} must be a finite number, got {v!r}")
    if v < 0 or (v == 0 and not zero_ok):
        raise ConfigError(f"{name} must be {'non-negative' if zero_ok else 'positive'}, got {v!r}")


#: the walls' colour for a design that records no picture to take a background from (a neutral grey)
NEUTRAL_WALL_RGB: tuple[int, int, int] = (200, 200, 200)


@dataclass(frozen=True)
class FabOptions:
    """How to turn a design into a printable, coloured solid.

    Attributes:
        base_thickness_mm: plate thickness below the cup's standing plane
            (model z = 0); the flat bottom of the whole part lies at least
            this far below it.
        min_thickness_mm: material left under the saucer's lowest point; the
            bottom is lowered further when the saucer dips below z = 0.
        seat: ``recess`` (default): a plate reaches under the cup and holds a
            shallow pocket of the cup's footprint whose floor is exactly the
            cup's standing plane; ``ring``: the plate's top is that plane and
            a low ring surrounds the cup; ``none``: no plate (the cup then
            stands on a support as high as the part's base, reported).
        seat_depth_mm: depth of the recess, or height of the ring.
        seat_clearance_mm: gap between the cup's footprint and the recess
            wall (or the ring's inside), so a real cup drops in.
        seat_rim_mm: width of plate material around the recess (ring width).
        saucer_rim_mm: a round saucer's raised rim: the width of a ring at the
            disc's outer edge standing from the part's base above the relief
            (:mod:`saucerfab.fabricate.round_solid`); 0 (the default): no rim.
            Refused on a rectangle saucer.
        saucer_rim_height_mm: how far the rim's top stands above the highest
            point of the relief under it (used only with a rim).
        texture_px: atlas edge in pixels; ``None`` = the printer profile's
            resolution for the part's size (``PrinterProfile.texture_px_for``).
        padding_px: gutter around each atlas region filled by edge dilation,
            so bilinear filtering and mipmaps never reach background.
        wall_rgb: sRGB 8-bit colour of walls, base and seat; None (the default): the background
            the design meant around its direct picture (its ``--background``, else the picture's
            border colour: :func:`saucerfab.imaging.images.intended_background`), so the walls and the cup
            seat a viewer sees beside the picture do not stand out from it;
            :data:`NEUTRAL_WALL_RGB` for a design without references.
        mirror_rgb: sRGB 8-bit colour of the points of those surfaces the cup shows the design
            eye (the strip of plate in front of the cup, seen in the mirror under the reflected
            picture: :mod:`saucerfab.fabricate.sides`); None (the default): the background meant
            around the reflected picture when ``wall_rgb`` is None too, else ``wall_rgb`` (a
            colour given for the walls is used for all of them).
        inpaint: ``harmonic`` fills faces no viewer sees (``FaceView.NEITHER``)
            with a smooth (harmonic) continuation of their neighbours'
            colours; ``none`` leaves them at ``wall_rgb``.
        bleed_compensation: ``on`` pre-sharpens the top's texture for the printer's colour bleed
            (its profile's ``colour_bleed_mm``; :func:`saucerfab.fabricate.bleed.compensate_top`),
            so that the print's blurred colours come closer to the design's; the per-vertex colours
            (PLY) stay the design's. ``off`` (the default): the texture as designed. Recorded in
            ``export.json`` with the width used (``bleed``) only when on.
        shading_compensation: ``ambient`` or ``room`` divides the top's albedo by the shading pattern
            its relief casts on itself under that light (:mod:`saucerfab.fabricate.shading`: ``ambient``
            the room's uniform environment alone, its ambient occlusion; ``room`` verify's ``--light
            room``, that environment and its lamp) raised to a power below 1, then darkens the whole
            top by one factor, at most :data:`saucerfab.fabricate.shading.MAX_DARKENING` in mean
            linear albedo, and clips what is left out of range (a 3.5x darker print scored 0.5 dB
            more under the light: a person sees the darkness, the score's gain does not); the
            per-vertex colours (PLY) stay the design's.
            Before the bleed compensation when both are on (sharpen what prints). ``off`` (the
            default): the texture as designed. Recorded in ``export.json`` (``shading``) only when on.
        obj_zip: write OBJ + MTL + PNG as one ``.zip`` (what bureaus ask for)
            instead of three loose files.
        name: file stem of the written files (``saucer.3mf`` ...).
        coord_decimals: decimals of millimetre coordinates in text formats
            (5: 10 nm, far below any printer's resolution).
    """

    base_thickness_mm: float = 3.0
    min_thickness_mm: float = 2.0
    seat: SeatKind = "recess"
    seat_depth_mm: float = 1.5
    seat_clearance_mm: float = 0.5
    seat_rim_mm: float = 4.0
    saucer_rim_mm: float = 0.0
    saucer_rim_height_mm: float = 2.0
    texture_px: int | None = None
    padding_px: int = 8
    wall_rgb: tuple[int, int, int] | None = None
    mirror_rgb: tuple[int, int, int] | None = None
    inpaint: Literal["harmonic", "none"] = "harmonic"
    bleed_compensation: BleedCompensation = "off"
    shading_compensation: ShadingCompensation = "off"
    obj_zip: bool = False
    name: str = "saucer"
    coord_decimals: int = 5

    def __post_init__(self) -> None:
        _pos("base_thickness_mm", self.base_thickness_mm)
        _pos("min_thickness_mm", self.min_thickness_mm)
        if self.seat not in SEAT_KINDS:
            raise ConfigError(f"seat must be one of {SEAT_KINDS}, got {self.seat!r}")
        _pos("seat_depth_mm", self.seat_depth_mm)
        _pos("seat_clearance_mm", self.seat_clearance_mm, zero_ok=True)
        _pos("seat_rim_mm", self.seat_rim_mm)
        _pos("saucer_rim_mm", self.saucer_rim_mm, zero_ok=True)
        _pos("saucer_rim_height_mm", self.saucer_rim_height_mm)
        if self.texture_px is not None:
            tp = self.texture_px
            if (
                not isinstance(tp, int)
                or isinstance(tp, bool)
                or not MIN_TEXTURE_PX <= tp <= MAX_TEXTURE_PX
                or tp & (tp - 1)
            ):
                raise ConfigError(
                    f"texture_px must be a power of two in [{MIN_TEXTURE_PX}, {MAX_TEXTURE_PX}], got {tp!r}"
                )
        if not isinstance(self.padding_px, int) or not 1 <= self.padding_px <= 64:
            raise ConfigError(f"padding_px must be an integer in [1, 64], got {self.padding_px!r}")
        for key in ("wall_rgb", "mirror_rgb"):
            value = getattr(self, key)
            if value is not None:
                rgb = tuple(value)
                if len(rgb) != 3 or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255
                                            for c in rgb):
                    raise ConfigError(f"{key} must be three integers in [0, 255], got {value!r}")
                object.__setattr__(self, key, rgb)
        if self.inpaint not in ("harmonic", "none"):
            raise ConfigError(f"inpaint must be 'harmonic' or 'none', got {self.inpaint!r}")
        if self.bleed_compensation not in BLEED_COMPENSATIONS:
            raise ConfigError(
                f"bleed_compensation must be {' or '.join(map(repr, BLEED_COMPENSATIONS))}, "
                f"got {self.bleed_compensation!r}"
            )
        if self.shading_compensation not in SHADING_COMPENSATIONS:
            raise ConfigError(
                f"shading_compensation must be one of {', '.join(map(repr, SHADING_COMPENSATIONS))}, "
                f"got {self.shading_compensation!r}"
            )
        if (
            not isinstance(self.name, str)
            or not self.name
            or not all(c.isalnum() or c in "-_" for c in self.name)
        ):
            raise ConfigError(
                f"name must be a plain file stem (letters, digits, '-', '_'), got {self.name!r}"
            )
        if not isinstance(self.coord_decimals, int) or not 3 <= self.coord_decimals <= 9:
            raise ConfigError(f"coord_decimals must be an integer in [3, 9], got {self.coord_decimals!r}")

    def walls_under(self, min_wall_mm: float) -> list[str]:
        """What of the solid's own walls (base, under the saucer, seat rim, saucer rim) is under ``min_wall_mm``.

        One rule for the export (``fabricate/solid.py``) and the design's
        preflight (``optimize/printable.py``); each string names the option.
        """
        walls = [
            ("base_thickness_mm", self.base_thickness_mm),
            ("min_thickness_mm (under the saucer's lowest point)", self.min_thickness_mm),
        ]
        if self.seat != "none":
            walls.append(("seat_rim_mm", self.seat_rim_mm))
        if self.saucer_rim_mm > 0:  # 0: no rim, no wall
            walls.append(("saucer_rim_mm (the round saucer's raised rim)", self.saucer_rim_mm))
        return [f"{what} = {v:g} mm is below the minimum wall {min_wall_mm:g} mm" for what, v in walls if v < min_wall_mm]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready).

        Without a rim (``saucer_rim_mm`` 0) the rim's two settings are left
        out: they shape nothing, and a part without a rim is recorded
        (``export.json``) exactly as before the rim existed. So is
        ``bleed_compensation`` when off, and ``shading_compensation``: an export
        without them is the one made before the options existed, byte for byte.
        """
        d = asdict(self)
        if not self.saucer_rim_mm:
            del d["saucer_rim_mm"], d["saucer_rim_height_mm"]
        if self.bleed_compensation == "off":
            del d["bleed_compensation"]
        if self.shading_compensation == "off":
            del d["shading_compensation"]
        for key in ("wall_rgb", "mirror_rgb"):
            d[key] = None if getattr(self, key) is None else list(getattr(self, key))
        return d
