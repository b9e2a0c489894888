"""The scene: camera, the two view frames, the mirror cup, the saucer, units.

Model frame (paper, section 4): origin at the centre of the cup's bottom, z
up, lengths in model units (the paper's cup radius is 0.4). The saucer is a
heightfield over a rectangle on the negative-y side of the cup; the camera
looks at it from above and behind. Physical size enters only through
``Scene.cup_diameter_mm``: one model unit is ``mm_per_unit`` millimetres.

A *view frame* is what one image covers: a look-at camera from
``Scene.camera`` towards ``ViewFrame.target`` with z up, and SoftRas's
perspective, where ``viewing_angle_deg`` is the half field of view:
``tan(viewing_angle) = half the frame's width / depth along the view axis``.
Each input picture keeps its aspect: it covers a centred rectangle of its
square view frame (``ViewFrame.extent``), the rest is its background.

The cup shapes are in :mod:`saucerfab.model.cups`.

Everything here is a frozen dataclass validated on construction; build one
from TOML with :func:`load_scene` and write one with :func:`scene_to_toml`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, GeometryError
from saucerfab.files.tomlfile import read_toml
from saucerfab.model.cups import CircleCup, Cup, cup_from_dict, cup_to_dict
from saucerfab.model.validate import as_vector, check_keys, check_positive

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]

#: resolutions we accept; outside them memory or quality make no sense
MIN_IMAGE_SIZE, MAX_IMAGE_SIZE = 8, 4096
MIN_GRID, MAX_GRID = 4, 1024
#: least sine of a view axis's angle to the vertical (see Scene.__post_init__)
MIN_VIEW_TILT = 1e-9
#: the views a scene can have, in order: each has a frame, an input picture and a rendered image
VIEW_NAMES = ("direct", "reflected", "reflected2")
#: a view's extent when its picture fills the whole square (a square picture; files without extents)
FULL_EXTENT = (1.0, 1.0)
#: how close to 1 the larger side of an extent must be (written values are rounded)
EXTENT_TOLERANCE = 1e-6
#: the saucer's outlines: a rectangle of relief beside the cup (the paper's), or a disc with the cup at its centre
SAUCER_OUTLINES = ("rectangle", "disc")
#: on a disc, the ring around the cup's footprint that holds no design, mm: the export's cup seat (its
#: clearance and rim: 0.5 + 4.0 mm by default, saucerfab/fabricate/options.py) stands there
CUP_RING_MM = 5.0
#: a disc's design region must be at least this wide around the cup's ring, mm (the smallest saucer named
#: in the error is the cup's width plus twice this and the ring)
MIN_DISC_BAND_MM = 10.0


# --------------------------------------------------------------------------- views


@dataclass(frozen=True)
class ViewFrame:
    """One view: where the camera looks, how wide, at what resolution.

    Attributes:
        target: point the view axis passes through, model units.
        viewing_angle_deg: SoftRas's ``viewing_angle``, the half field of view
            in degrees: tan(angle) = half frame width / depth along the axis.
        image_size: rendered image width = height, pixels.
        extent: (ex, ey) the picture's half width and half height in the view's NDC: the
            picture covers ``|x_ndc| <= ex``, ``|y_ndc| <= ey`` of the square view, centred
            (each in (0, 1], the larger 1: a 2:1 picture has (1, 0.5)); the rest of the
            square is the picture's background (:func:`saucerfab.imaging.fitting.fit_square` pads it so).
    """

    target: Vec3
    viewing_angle_deg: float
    image_size: int = 512
    extent: Vec2 = FULL_EXTENT

    def __post_init__(self) -> None:
        object.__setattr__(self, "target", as_vector("view target", self.target, 3))
        ext = as_vector("view extent", self.extent, 2)
        if not all(0.0 < e <= 1.0 for e in ext) or abs(max(ext) - 1.0) > EXTENT_TOLERANCE:
            raise ConfigError(
                f"a view's extent is the picture's half width and half height in the square view, each in "
                f"(0, 1] and the larger 1 (a 2:1 picture: [1.0, 0.5]); got {list(ext)}"
            )
        object.__setattr__(self, "extent", tuple(1.0 if e >= 1.0 - EXTENT_TOLERANCE else e for e in ext))
        check_positive("viewing_angle_deg", self.viewing_angle_deg)
        if self.viewing_angle_deg >= 89.0:
            raise ConfigError(
                f"viewing_angle_deg is the half field of view and must be below 89 degrees, "
                f"got {self.viewing_angle_deg}"
            )
        if not isinstance(self.image_size, int) or not (
            MIN_IMAGE_SIZE <= self.image_size <= MAX_IMAGE_SIZE
        ):
            raise ConfigError(
                f"image_size must be an integer in [{MIN_IMAGE_SIZE}, {MAX_IMAGE_SIZE}], "
                f"got {self.image_size!r}"
            )


# --------------------------------------------------------------------------- saucer


@dataclass(frozen=True)
class Saucer:
    """The saucer heightfield's footprint, resolution and height bound.

    The heightfield is always a square grid over ``x_range`` x ``y_range``. A
    ``"rectangle"`` saucer is all of it (the paper's, beside the cup). A
    ``"disc"`` is the circle inscribed in it, centred on the cup's axis (the
    ranges are ``(-R, R)`` both): the cup stands at its centre, and only the
    grid's vertices on the disc and outside the cup's ring (:data:`CUP_RING_MM`)
    carry the design (:mod:`saucerfab.model.footprint`).

    Attributes:
        x_range: (x0, x1), model units.
        y_range: (y0, y1), model units.
        resolution: vertices per side of the square grid (paper: 150).
        delta: bound on height change, |z - h| < delta, model units (paper: 0.05).
        outline: one of :data:`SAUCER_OUTLINES`.
    """

    x_range: Vec2 = (-0.5, 0.5)
    y_range: Vec2 = (-1.5, -0.5)
    resolution: int = 150
    delta: float = 0.05
    outline: str = "rectangle"

    def __post_init__(self) -> None:
        xr = as_vector("saucer x_range", self.x_range, 2)
        yr = as_vector("saucer y_range", self.y_range, 2)
        object.__setattr__(self, "x_range", xr)
        object.__setattr__(self, "y_range", yr)
        if not xr[0] < xr[1] or not yr[0] < yr[1]:
            raise ConfigError(
                f"saucer ranges must be increasing (min, max), got x {xr} and y {yr}"
            )
        if not isinstance(self.resolution, int) or not (MIN_GRID <= self.resolution <= MAX_GRID):
            raise ConfigError(
                f"saucer resolution must be an integer in [{MIN_GRID}, {MAX_GRID}], "
                f"got {self.resolution!r}"
            )
        check_positive("delta", self.delta)
        if self.outline not in SAUCER_OUTLINES:
            raise ConfigError(f"the saucer's outline must be one of {', '.join(SAUCER_OUTLINES)}, got {self.outline!r}")
        if self.outline == "disc" and not (
            abs(xr[0] + xr[1]) < 1e-9 and abs(yr[0] + yr[1]) < 1e-9 and abs(xr[1] - yr[1]) < 1e-9
        ):
            raise ConfigError(
                f"a disc saucer is centred on the cup: its x_range and y_range are both (-R, R) for its radius R "
                f"(give [saucer] diameter instead); got x {xr} and y {yr}"
            )

    @property
    def size(self) -> Vec2:
        """(width along x, depth along y), model units."""
        return (self.x_range[1] - self.x_range[0], self.y_range[1] - self.y_range[0])

    @property
    def is_disc(self) -> bool:
        return self.outline == "disc"

    @property
    def radius(self) -> float:
        """A disc's radius, model units (a rectangle: half its width)."""
        return 0.5 * self.size[0]

    def on_saucer(self, xy: np.ndarray) -> np.ndarray:
        """(P,) bool: the points (P, 2) lie on the saucer's outline (a rectangle: its whole square)."""
        p = np.asarray(xy, np.float64)
        if not self.is_disc:
            (x0, x1), (y0, y1) = self.x_range, self.y_range
            return (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        # a hair inside the radius so the grid's four extreme vertices (exactly on it) count
        return np.hypot(p[:, 0], p[:, 1]) <= self.radius * (1.0 + 1e-9)


def disc_saucer(diameter: float, resolution: int, delta: float = 0.05) -> Saucer:
    """A round saucer of ``diameter`` model units centred on the cup's axis."""
    check_positive("saucer diameter", diameter)
    r = 0.5 * float(diameter)
    return Saucer(x_range=(-r, r), y_range=(-r, r), resolution=resolution, delta=delta, outline="disc")


# --------------------------------------------------------------------------- scene


@dataclass(frozen=True)
class Scene:
    """Everything geometric about one design.

    Attributes:
        camera: eye position P, model units.
        direct: the frame of the image seen directly on the saucer.
        reflected: the frame of the image seen in the mirror cup.
        cup: the mirror cup (its bottom centre is the origin).
        saucer: the saucer footprint and resolution.
        cup_diameter_mm: physical width of the real cup across its footprint
            (the cup's ``width_units`` in mm: a circle's diameter, an ellipse's
            2a, a prism's 2 * circumradius), which fixes the model-to-millimetre scale.
        reflected2: the frame of a second reflected image (prism cups, two
            reflections, each in its own facet region); None: the
            ``reflected`` frame is used for both.
    """

    camera: Vec3 = (0.0, -5.5, 5.0)
    direct: ViewFrame = ViewFrame((0.0, 0.0, -0.8), 4.5, 512)
    reflected: ViewFrame = ViewFrame((0.0, 0.0, 0.1), 3.0, 512)
    cup: Cup = field(default_factory=CircleCup)
    saucer: Saucer = field(default_factory=Saucer)
    cup_diameter_mm: float = 80.0
    reflected2: ViewFrame | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera", as_vector("camera", self.camera, 3))
        check_positive("cup_diameter_mm", self.cup_diameter_mm)
        cam = np.array(self.camera)
        views = [("direct", self.direct), ("reflected", self.reflected)]
        if self.reflected2 is not None:
            views.append(("reflected2", self.reflected2))
        for name, view in views:
            if np.linalg.norm(np.array(view.target) - cam) < 1e-9:
                raise ConfigError(f"the {name} view target coincides with the camera {self.camera}")
        if bool(self.cup.contains(cam[:2])):
            raise GeometryError(
                f"the camera {self.camera} stands inside the cup's footprint; "
                "move it outside (the paper uses (0, -5.5, 5))"
            )
        for name, view in views:
            # A look-at camera takes its "up" from the world's z: on a vertical
            # view axis that is undefined (the renderer would fail much later,
            # deep in a design or a verify). The bound is above the renderer's
            # own (1e-12), so whatever it would refuse is refused here. (After
            # the camera-in-cup check: a camera over the cup is the real mistake.)
            axis = np.array(view.target) - cam
            if float(np.hypot(axis[0], axis[1])) / float(np.linalg.norm(axis)) < MIN_VIEW_TILT:
                raise ConfigError(
                    f"the {name} view axis, from the camera {self.camera} to its target {view.target}, "
                    "is vertical; a view's up direction is then undefined. Move the target (or the "
                    "camera) sideways so the two are not on one vertical line (the paper looks down "
                    "at about 45 degrees)"
                )
        if self.saucer.is_disc:
            self._check_disc()
            return
        # The saucer may not overlap the cup: test the footprint rectangle
        # densely against the cup (exact for circles, conservative enough for
        # the others at this sampling), then the cup outline against the box.
        (x0, x1), (y0, y1) = self.saucer.x_range, self.saucer.y_range
        gx, gy = np.meshgrid(np.linspace(x0, x1, 65), np.linspace(y0, y1, 65))
        pts = np.stack([gx, gy], axis=-1)
        outline = self.cup.boundary()
        in_box = (
            (outline[:, 0] > x0) & (outline[:, 0] < x1) & (outline[:, 1] > y0) & (outline[:, 1] < y1)
        )
        if self.cup.contains(pts).any() or in_box.any():
            raise GeometryError(
                f"the saucer x {self.saucer.x_range}, y {self.saucer.y_range} overlaps the "
                f"{self.cup.kind} cup; move the saucer away from the cup or shrink the cup"
            )

    def _check_disc(self) -> None:
        """A disc holds the cup at its centre: the cup, its ring and a band of design must fit inside it."""
        outline = self.cup.boundary()
        reach = float(np.hypot(outline[:, 0], outline[:, 1]).max())  # the cup's farthest point from the axis
        s = self.mm_per_unit
        smallest_mm = 2.0 * (reach * s + CUP_RING_MM + MIN_DISC_BAND_MM)
        if 2.0 * self.saucer.radius * s < smallest_mm - 1e-9:
            raise GeometryError(
                f"the round saucer ({2.0 * self.saucer.radius * s:.1f} mm across) is too small for the "
                f"{self.cup_diameter_mm:g} mm {self.cup.kind} cup at its centre, its {CUP_RING_MM:g} mm seat ring "
                f"and a {MIN_DISC_BAND_MM:g} mm band of design; give a saucer of at least "
                f"{math.ceil(smallest_mm - 1e-6):g} mm "
                "(--saucer-diameter-mm) or a smaller cup"
            )

    @property
    def cup_ring_units(self) -> float:
        """The ring around the cup's footprint that holds no design on a disc (:data:`CUP_RING_MM`), model units."""
        return CUP_RING_MM / self.mm_per_unit

    @property
    def cup_width_units(self) -> float:
        """The cup's width in model units that ``cup_diameter_mm`` refers to."""
        return self.cup.width_units

    @property
    def mm_per_unit(self) -> float:
        """Millimetres per model unit."""
        return self.cup_diameter_mm / self.cup_width_units

    def with_changes(self, **changes: Any) -> "Scene":
        """A copy with top-level fields replaced (validated again)."""
        return replace(self, **changes)


def paper_scene() -> Scene:
    """The paper's section 4 setup: a 100 mm-wide rectangle of saucer in front of an 80 mm cup."""
    return Scene()


#: the ``wide`` scene's saucer, model units along x: 185 mm for the 80 mm cup, the widest rectangle every
#: bundled printer takes with room to spare (the HP's build area is 190 mm on its short side; the part is
#: 195 mm deep). The mirror shows a saucer across more of its width the wider the saucer is (issue 43,
#: benchmarks/bench_scene_choice.py and bench_whole.py; benchmarks/RESULTS.md, "The default scene:
#: rectangle, wide or round"): the reflected picture spans about half the cup's width (square) and 56 % of
#: it at 2:1 where the paper's 100 mm gives 36 % and 44 %, and a 2:1 direct picture about 80 % of the
#: saucer's width. It is the default scene.
WIDE_X_RANGE = (-0.925, 0.925)


def wide_scene() -> Scene:
    """The paper's eye, cup and frames' rule over a wider saucer (:data:`WIDE_X_RANGE`): larger pictures."""
    base = Scene()
    return replace(base, saucer=replace(base.saucer, x_range=WIDE_X_RANGE))


#: a round saucer's diameter over the cup's width: 200 mm for the 80 mm cup. Measured (bench_scene_choice.py
#: --round; benchmarks/RESULTS.md, "The default scene: rectangle, wide or round"): the mirror shows the
#: saucer in a band around the cup's foot, as tall as the saucer reaches in front of the cup; at twice the
#: cup (160 mm) a 2:1 reflected picture spans 54 % of the cup's width (the paper's rectangle: 44 %), at 2.5
#: times 68 %, at 3 times 83 % (a square one 31 / 42 / 54 %; the paper's 38 %), while the direct picture,
#: in front of the cup, is smaller than on the paper's rectangle at any of them. 200 mm fits every bundled
#: printer but the HP (190 mm deep), which is refused naming the largest that fits.
ROUND_DIAMETER_PER_CUP = 2.5
#: grid vertices per model unit on a round saucer: the paper's step (150 across its 1-unit rectangle: 0.67 mm)
ROUND_GRID_PER_UNIT = 149.0


def round_grid(diameter: float) -> int:
    """The grid resolution of a round saucer ``diameter`` model units across, at the paper's step."""
    return int(min(MAX_GRID, max(MIN_GRID, round(diameter * ROUND_GRID_PER_UNIT) + 1)))


def round_scene() -> Scene:
    """The paper's eye and cup with a round saucer around it (:data:`ROUND_DIAMETER_PER_CUP`), the cup at its centre."""
    base = Scene()
    d = ROUND_DIAMETER_PER_CUP * base.cup.width_units
    return replace(base, saucer=disc_saucer(d, round_grid(d), base.saucer.delta))


#: the named scenes (``--scene NAME``, ``preset = "NAME"`` in a scene TOML)
PRESETS = {"paper": paper_scene, "wide": wide_scene, "round": round_scene}
#: the scene a design gets when none is given (RESULTS.md, "The default scene: rectangle, wide or round", says why)
DEFAULT_PRESET = "wide"


def default_scene() -> Scene:
    """The scene a design gets when none is given (:data:`DEFAULT_PRESET`)."""
    return PRESETS[DEFAULT_PRESET]()


# --------------------------------------------------------------------------- dict / TOML


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """A plain-data (JSON/TOML-ready) description of ``scene``."""

    def view(v: ViewFrame) -> dict[str, Any]:
        return {
            "target": list(v.target),
            "viewing_angle_deg": v.viewing_angle_deg,
            "image_size": v.image_size,
            "extent": list(v.extent),
        }

    s = scene.saucer
    extra = {"reflected2": view(scene.reflected2)} if scene.reflected2 is not None else {}
    return {
        "camera": list(scene.camera),
        "cup_diameter_mm": scene.cup_diameter_mm,
        "direct": view(scene.direct),
        "reflected": view(scene.reflected),
        **extra,
        "cup": cup_to_dict(scene.cup),
        "saucer": {
            "x_range": list(s.x_range),
            "y_range": list(s.y_range),
            "resolution": s.resolution,
            "delta": s.delta,
            # written for a disc only: a rectangle's description stays what it was before discs
            **({"outline": s.outline} if s.is_disc else {}),
        },
    }


_TOP_KEYS = {"camera", "cup_diameter_mm", "direct", "reflected", "reflected2", "cup", "saucer", "preset"}


def scene_from_dict(d: dict[str, Any], base: Scene | None = None) -> Scene:
    """Build a scene from plain data; missing keys keep ``base``'s (default: paper) values.

    A ``preset = "paper"`` key selects the base.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"a scene must be a table, got {type(d).__name__}")
    check_keys("the scene", d, _TOP_KEYS)
    if "preset" in d:
        if not isinstance(d["preset"], str) or d["preset"] not in PRESETS:
            raise ConfigError(f"unknown scene preset {d['preset']!r}; known: {sorted(PRESETS)}")
        base = PRESETS[d["preset"]]()
    base = base or paper_scene()
    kw: dict[str, Any] = {}
    try:
        if "camera" in d:
            kw["camera"] = d["camera"]
        if "cup_diameter_mm" in d:
            kw["cup_diameter_mm"] = d["cup_diameter_mm"]
        for name in ("direct", "reflected", "reflected2"):
            if name in d:
                v = d[name]
                if not isinstance(v, dict):
                    raise ConfigError(f"[{name}] must be a table, got {v!r}")
                check_keys(f"[{name}]", v, {"target", "viewing_angle_deg", "image_size", "extent"})
                start = getattr(base, name) or base.reflected
                kw[name] = replace(start, **v)
        if "saucer" in d:
            kw["saucer"] = _saucer_from_dict(d["saucer"], base.saucer)
        if "cup" in d:
            kw["cup"] = cup_from_dict(d["cup"], base.cup.kind)
        return replace(base, **kw)
    except TypeError as exc:  # wrong arity from a malformed table
        raise ConfigError(f"invalid scene description: {exc}") from None


def _saucer_from_dict(t: Any, base: Saucer) -> Saucer:
    """The ``[saucer]`` table over ``base``: a disc may be given by its ``diameter`` (model units) instead of ranges."""
    if not isinstance(t, dict):
        raise ConfigError(f"invalid scene description: [saucer] must be a table, got {t!r}")
    check_keys("[saucer]", t, {"x_range", "y_range", "resolution", "delta", "outline", "diameter"})
    t = dict(t)
    outline = t.get("outline", base.outline)
    if "diameter" in t:
        if outline != "disc":
            raise ConfigError(
                '[saucer] diameter is for a round saucer (outline = "disc"); a rectangle takes x_range and y_range'
            )
        if "x_range" in t or "y_range" in t:
            raise ConfigError("[saucer] takes a disc's diameter or its ranges, not both")
        d = t.pop("diameter")
        if not isinstance(d, (int, float)) or isinstance(d, bool) or not math.isfinite(d) or d <= 0:
            raise ConfigError(f"[saucer] diameter must be a positive number of model units, got {d!r}")
        t["x_range"] = t["y_range"] = (-0.5 * d, 0.5 * d)
        t.setdefault("resolution", round_grid(float(d)))
    elif outline == "disc" and base.outline != "disc" and "x_range" not in t:
        raise ConfigError('a round saucer (outline = "disc") needs its diameter: [saucer] diameter = 1.6 (model units)')
    return replace(base, **t)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def scene_to_toml(scene: Scene) -> str:
    """TOML text for ``scene`` that :func:`load_scene` reads back to an equal scene."""
    d = scene_to_dict(scene)
    lines = ["# saucerfab scene (model units; see saucerfab/model/scene.py)"]
    for k in ("camera", "cup_diameter_mm"):
        lines.append(f"{k} = {_toml_value(d[k])}")
    for table in ("direct", "reflected", "reflected2", "cup", "saucer"):
        if table not in d:
            continue
        lines.append(f"\n[{table}]")
        for k, v in d[table].items():
            lines.append(f"{k} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


def load_scene(source: str | os.PathLike[str]) -> Scene:
    """Load a scene from a TOML file path or a preset name ("paper")."""
    if isinstance(source, str) and source in PRESETS:
        return PRESETS[source]()
    path = Path(source)
    if not path.is_file():
        raise ConfigError(
            f"scene file {str(path)!r} not found; give a TOML file or a preset ({sorted(PRESETS)})"
        )
    data = read_toml(
        path,
        "scene file",
        max_bytes=1_000_000,
        size_hint="a scene is a few lines of TOML",
        nesting_hint="a scene is a few tables of numbers and short lists",
    )
    return scene_from_dict(data)

