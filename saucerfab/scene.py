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
Each input image covers its whole (square) view frame.

Everything here is a frozen dataclass validated on construction; build one
from TOML with :func:`load_scene` and write one with :func:`scene_to_toml`.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np

from saucerfab.errors import ConfigError, GeometryError

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]

#: resolutions we accept; outside them memory or quality make no sense
MIN_IMAGE_SIZE, MAX_IMAGE_SIZE = 8, 4096
MIN_GRID, MAX_GRID = 4, 1024
#: least sine of a view axis's angle to the vertical (see Scene.__post_init__)
MIN_VIEW_TILT = 1e-9
#: the views a scene can have, in order: each has a frame, an input picture and a rendered image
VIEW_NAMES = ("direct", "reflected", "reflected2")


def _finite(name: str, *values: float) -> None:
    for v in values:
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ConfigError(f"{name} must be a finite number, got {v!r}")


def _positive(name: str, v: float) -> None:
    _finite(name, v)
    if v <= 0:
        raise ConfigError(f"{name} must be positive, got {v!r}")


def _vec(name: str, v: Any, n: int) -> tuple[float, ...]:
    try:
        t = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a list of {n} numbers, got {v!r}") from None
    if len(t) != n:
        raise ConfigError(f"{name} must have {n} components, got {len(t)}: {v!r}")
    _finite(name, *t)
    return t


# --------------------------------------------------------------------------- views


@dataclass(frozen=True)
class ViewFrame:
    """One view: where the camera looks, how wide, at what resolution.

    Attributes:
        target: point the view axis passes through, model units.
        viewing_angle_deg: SoftRas's ``viewing_angle``, the half field of view
            in degrees: tan(angle) = half frame width / depth along the axis.
        image_size: rendered image width = height, pixels.
    """

    target: Vec3
    viewing_angle_deg: float
    image_size: int = 512

    def __post_init__(self) -> None:
        object.__setattr__(self, "target", _vec("view target", self.target, 3))
        _positive("viewing_angle_deg", self.viewing_angle_deg)
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


# --------------------------------------------------------------------------- cups


@dataclass(frozen=True)
class CircleCup:
    """A round cylindrical mirror cup standing on z = 0 at the origin.

    Attributes:
        radius: cup radius, model units (paper: 0.4).
        height: height of the mirror wall above z = 0, model units.
    """

    radius: float = 0.4
    height: float = 1.0
    kind: Literal["circle"] = field(default="circle", init=False)

    def __post_init__(self) -> None:
        _positive("cup radius", self.radius)
        _positive("cup height", self.height)

    @property
    def circumradius(self) -> float:
        """Radius of the smallest origin-centred circle containing the footprint."""
        return self.radius

    @property
    def inradius(self) -> float:
        """Radius of the largest origin-centred circle inside the footprint."""
        return self.radius

    def boundary(self, n: int = 256) -> np.ndarray:
        """Footprint outline, counter-clockwise, shape (n, 2)."""
        t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return np.stack([self.radius * np.cos(t), self.radius * np.sin(t)], axis=1)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """True where points (..., 2) lie strictly inside the footprint."""
        xy = np.asarray(xy, dtype=np.float64)
        return np.einsum("...i,...i->...", xy, xy) < self.radius**2


@dataclass(frozen=True)
class EllipseCup:
    """An elliptic cylinder mirror: semi-axes (a, b) before rotation about z.

    Attributes:
        semi_axes: (a, b), along the cup's local x and y, model units.
        rotation_deg: rotation of the local x axis from the model x axis.
        height: mirror wall height above z = 0, model units.
    """

    semi_axes: Vec2 = (0.45, 0.35)
    rotation_deg: float = 0.0
    height: float = 1.0
    kind: Literal["ellipse"] = field(default="ellipse", init=False)

    def __post_init__(self) -> None:
        a, b = _vec("cup semi_axes", self.semi_axes, 2)
        object.__setattr__(self, "semi_axes", (a, b))
        _positive("cup semi-axis a", a)
        _positive("cup semi-axis b", b)
        _finite("cup rotation_deg", self.rotation_deg)
        _positive("cup height", self.height)

    @property
    def circumradius(self) -> float:
        return max(self.semi_axes)

    @property
    def inradius(self) -> float:
        return min(self.semi_axes)

    def _rot(self) -> np.ndarray:
        t = math.radians(self.rotation_deg)
        return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])

    def boundary(self, n: int = 256) -> np.ndarray:
        t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        a, b = self.semi_axes
        local = np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
        return local @ self._rot().T

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        local = xy @ self._rot()  # rotate by -theta
        a, b = self.semi_axes
        return (local[..., 0] / a) ** 2 + (local[..., 1] / b) ** 2 < 1.0


@dataclass(frozen=True)
class PrismCup:
    """A regular n-gon prism mirror (each facet a plane mirror).

    Attributes:
        sides: number of facets n >= 3.
        circumradius: distance from the axis to each vertex, model units.
        rotation_deg: angle of the first vertex from the model +x axis.
        height: mirror wall height above z = 0, model units.
    """

    sides: int = 6
    circumradius: float = 0.45
    rotation_deg: float = 0.0
    height: float = 1.0
    kind: Literal["prism"] = field(default="prism", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.sides, int) or isinstance(self.sides, bool) or not (
            3 <= self.sides <= 64
        ):
            raise ConfigError(f"prism sides must be an integer in [3, 64], got {self.sides!r}")
        _positive("cup circumradius", self.circumradius)
        _finite("cup rotation_deg", self.rotation_deg)
        _positive("cup height", self.height)

    @property
    def inradius(self) -> float:
        return self.circumradius * math.cos(math.pi / self.sides)

    def boundary(self, n: int | None = None) -> np.ndarray:
        """The polygon's vertices, counter-clockwise, shape (sides, 2)."""
        t = math.radians(self.rotation_deg) + 2 * np.pi * np.arange(self.sides) / self.sides
        return self.circumradius * np.stack([np.cos(t), np.sin(t)], axis=1)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        v = self.boundary()
        inside = np.ones(xy.shape[:-1], dtype=bool)
        for k in range(self.sides):
            a, b = v[k], v[(k + 1) % self.sides]
            e = b - a
            cross = e[0] * (xy[..., 1] - a[1]) - e[1] * (xy[..., 0] - a[0])
            inside &= cross > 0
        return inside


Cup = Union[CircleCup, EllipseCup, PrismCup]


def parse_cup_spec(spec: str) -> Cup:
    """Parse a CLI cup spec: ``circle[:R]``, ``ellipse:A,B[,ROT]``, ``prism:N[,R[,ROT]]``."""
    name, _, rest = spec.strip().partition(":")
    args = [a for a in rest.split(",") if a.strip()] if rest else []
    try:
        nums = [float(a) for a in args]
    except ValueError:
        raise ConfigError(
            f"cup spec {spec!r}: parameters must be numbers, e.g. 'prism:6,0.45,0'"
        ) from None
    if name == "circle" and len(nums) <= 1:
        return CircleCup(*(nums[:1]))
    if name == "ellipse" and len(nums) in (2, 3):
        return EllipseCup((nums[0], nums[1]), *(nums[2:3]))
    if name == "prism" and 1 <= len(nums) <= 3:
        # check finiteness first: int() of nan/inf raises ValueError/OverflowError
        if not math.isfinite(nums[0]) or nums[0] != int(nums[0]):
            raise ConfigError(f"cup spec {spec!r}: the number of prism sides must be whole")
        return PrismCup(int(nums[0]), *nums[1:])
    raise ConfigError(
        f"unknown cup spec {spec!r}; use 'circle[:R]', 'ellipse:A,B[,ROT_DEG]' "
        f"or 'prism:N[,CIRCUMRADIUS[,ROT_DEG]]'"
    )


# --------------------------------------------------------------------------- saucer


@dataclass(frozen=True)
class Saucer:
    """The saucer heightfield's footprint, resolution and height bound.

    Attributes:
        x_range: (x0, x1), model units.
        y_range: (y0, y1), model units.
        resolution: vertices per side of the square grid (paper: 150).
        delta: bound on height change, |z - h| < delta, model units (paper: 0.05).
    """

    x_range: Vec2 = (-0.5, 0.5)
    y_range: Vec2 = (-1.5, -0.5)
    resolution: int = 150
    delta: float = 0.05

    def __post_init__(self) -> None:
        xr = _vec("saucer x_range", self.x_range, 2)
        yr = _vec("saucer y_range", self.y_range, 2)
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
        _positive("delta", self.delta)

    @property
    def size(self) -> Vec2:
        """(width along x, depth along y), model units."""
        return (self.x_range[1] - self.x_range[0], self.y_range[1] - self.y_range[0])


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
            (for a circle, its diameter; ellipse: 2a; prism: 2 * circumradius),
            which fixes the model-to-millimetre scale.
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
        object.__setattr__(self, "camera", _vec("camera", self.camera, 3))
        _positive("cup_diameter_mm", self.cup_diameter_mm)
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

    @property
    def cup_width_units(self) -> float:
        """The cup's width in model units that ``cup_diameter_mm`` refers to."""
        if isinstance(self.cup, CircleCup):
            return 2 * self.cup.radius
        if isinstance(self.cup, EllipseCup):
            return 2 * self.cup.semi_axes[0]
        return 2 * self.cup.circumradius

    @property
    def mm_per_unit(self) -> float:
        """Millimetres per model unit."""
        return self.cup_diameter_mm / self.cup_width_units

    def with_changes(self, **changes: Any) -> "Scene":
        """A copy with top-level fields replaced (validated again)."""
        return replace(self, **changes)


def paper_scene() -> Scene:
    """The paper's section 4 setup: the default preset."""
    return Scene()


PRESETS = {"paper": paper_scene}


# --------------------------------------------------------------------------- dict / TOML


def _cup_to_dict(cup: Cup) -> dict[str, Any]:
    d = {f.name: getattr(cup, f.name) for f in fields(cup) if f.name != "kind"}
    d = {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
    return {"shape": cup.kind, **d}


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """A plain-data (JSON/TOML-ready) description of ``scene``."""

    def view(v: ViewFrame) -> dict[str, Any]:
        return {
            "target": list(v.target),
            "viewing_angle_deg": v.viewing_angle_deg,
            "image_size": v.image_size,
        }

    s = scene.saucer
    extra = {"reflected2": view(scene.reflected2)} if scene.reflected2 is not None else {}
    return {
        "camera": list(scene.camera),
        "cup_diameter_mm": scene.cup_diameter_mm,
        "direct": view(scene.direct),
        "reflected": view(scene.reflected),
        **extra,
        "cup": _cup_to_dict(scene.cup),
        "saucer": {
            "x_range": list(s.x_range),
            "y_range": list(s.y_range),
            "resolution": s.resolution,
            "delta": s.delta,
        },
    }


_TOP_KEYS = {"camera", "cup_diameter_mm", "direct", "reflected", "reflected2", "cup", "saucer", "preset"}


def _check_keys(where: str, d: dict[str, Any], allowed: set[str]) -> None:
    unknown = set(d) - allowed
    if unknown:
        raise ConfigError(
            f"unknown key(s) {sorted(unknown)} in {where}; allowed: {sorted(allowed)}"
        )


def scene_from_dict(d: dict[str, Any], base: Scene | None = None) -> Scene:
    """Build a scene from plain data; missing keys keep ``base``'s (default: paper) values.

    A ``preset = "paper"`` key selects the base.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"a scene must be a table, got {type(d).__name__}")
    _check_keys("the scene", d, _TOP_KEYS)
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
                _check_keys(f"[{name}]", v, {"target", "viewing_angle_deg", "image_size"})
                start = getattr(base, name) or base.reflected
                kw[name] = replace(start, **v)
        if "saucer" in d:
            _check_keys("[saucer]", d["saucer"], {"x_range", "y_range", "resolution", "delta"})
            kw["saucer"] = replace(base.saucer, **d["saucer"])
        if "cup" in d:
            if not isinstance(d["cup"], dict):
                raise ConfigError(f"[cup] must be a table with a 'shape' key, got {d['cup']!r}")
            c = dict(d["cup"])
            shape = c.pop("shape", base.cup.kind)
            classes = {"circle": CircleCup, "ellipse": EllipseCup, "prism": PrismCup}
            if shape not in classes:
                raise ConfigError(f"unknown cup shape {shape!r}; use one of {sorted(classes)}")
            cls = classes[shape]
            allowed = {f.name for f in fields(cls) if f.init}
            _check_keys(f"[cup] ({shape})", c, allowed)
            if "semi_axes" in c:
                c["semi_axes"] = tuple(c["semi_axes"])
            kw["cup"] = cls(**c)
        return replace(base, **kw)
    except TypeError as exc:  # wrong arity from a malformed table
        raise ConfigError(f"invalid scene description: {exc}") from None


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
    lines = ["# saucerfab scene (model units; see saucerfab/scene.py)"]
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
    if path.stat().st_size > 1_000_000:
        raise ConfigError(f"scene file {str(path)!r} is over 1 MB; a scene is a few lines of TOML")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"scene file {str(path)!r} is not valid TOML: {exc}") from None
    except RecursionError:  # tomllib parses nested arrays recursively: a hostile file exhausts the stack
        raise ConfigError(
            f"scene file {str(path)!r} nests arrays or tables too deeply to be read; a scene is a few "
            "tables of numbers and short lists"
        ) from None
    return scene_from_dict(data)

