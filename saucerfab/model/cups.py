"""The mirror cups: one class per shape behind one protocol, and the table of shapes.

Every cup is a frozen dataclass standing on z = 0 with its axis through the
origin (model units, see :mod:`saucerfab.model.scene`). The rest of saucerfab asks
a cup only what :class:`Cup` lists (its width, outline, reflection, file
fields, whether it has facets) and finds a class by its ``kind`` in
:data:`CUP_CLASSES`, which feeds the CLI spec (:func:`parse_cup_spec`) and the
scene's TOML/JSON form (:func:`cup_to_dict`, :func:`cup_from_dict`).

Adding a shape: write its class here (the fields, validated in
``__post_init__``, and the :class:`Cup` members) and add it to
:data:`CUP_CLASSES`; if neither :func:`saucerfab.model.reflection.reflect_conic` nor
:func:`saucerfab.model.reflection.reflect_facets` reflects it, add its solver (and a
slow reference) to :mod:`saucerfab.model.reflection`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.model.reflection import (
    MirrorPiece,
    Reference,
    reference_conic,
    reference_facets,
    reflect_conic,
    reflect_facets,
    rotation_matrix,
)
from saucerfab.model.validate import as_vector, check_finite, check_keys, check_positive

Vec2 = tuple[float, float]

#: points on a smooth outline when the caller names no count (the scene's
#: overlap test); a faceted cup always gives its corners
OUTLINE_SEGMENTS = 256


class Cup(Protocol):
    """What saucerfab asks of a mirror cup (every shape is a frozen dataclass).

    Attributes:
        kind: the shape's name: its key in :data:`CUP_CLASSES` and the
            ``shape`` of its TOML/JSON table.
        height: mirror wall height above z = 0, model units.
        faceted: True when the wall is plane facets (each its own mirror
            piece, so two reflected images can split them), False when smooth.
        spec_usage: the CLI spec's form, e.g. ``circle[:R]``.
        spec_arity: (least, most) numbers the CLI spec takes.
    """

    kind: str
    height: float
    faceted: ClassVar[bool]
    spec_usage: ClassVar[str]
    spec_arity: ClassVar[tuple[int, int]]

    @classmethod
    def from_spec(cls, nums: list[float], spec: str) -> Cup:
        """The cup of a CLI spec's numbers (their count is within ``spec_arity``)."""
        ...

    @property
    def circumradius(self) -> float:
        """Radius of the smallest origin-centred circle containing the footprint, model units."""
        ...

    @property
    def inradius(self) -> float:
        """Radius of the largest origin-centred circle inside the footprint, model units."""
        ...

    @property
    def width_units(self) -> float:
        """The width, model units, that ``Scene.cup_diameter_mm`` gives in mm."""
        ...

    def boundary(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        """Footprint outline, counter-clockwise, (K, 2) model units.

        A smooth outline gives ``segments`` points; a faceted one its corners
        (facet k runs from corner k to k + 1) whatever ``segments`` says.
        """
        ...

    def wall(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        """The mirror wall as straight pieces with their outward normals, for renderers.

        Returns:
            (S, 2, 4): for each piece its two ends as ``[x, y, nx, ny]``,
            about the cup's axis in the cup's own length unit, (nx, ny) the
            unit outward normal there (a smooth cup's exact normal at each
            end, so shading is smooth; a facet's own normal at both ends).
            A smooth cup gives ``segments`` pieces, a faceted one a piece
            per facet.
        """
        ...

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """True where points (..., 2) lie strictly inside the footprint."""
        ...

    def reflect(self, camera: tuple[float, float, float], xy: np.ndarray) -> list[MirrorPiece]:
        """Saucer points Q (V, 2) reflected in the wall, seen from the camera P (3,), model units.

        One :class:`MirrorPiece` per mirror: a smooth wall has one (facet -1),
        a faceted one one per facet whose front the camera sees, in facet order.
        """
        ...

    def reflect_reference(self, camera: tuple[float, float, float], q_xy: tuple[float, float]) -> Reference:
        """One point, the slow and obvious way: what the tests hold :meth:`reflect` to."""
        ...

    def file_fields(self, to_mm: Callable[[float], float]) -> dict[str, Any]:
        """The shape's fields in ``scene.json`` (lengths through ``to_mm``), after shape, centre, height."""
        ...


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

    faceted: ClassVar[bool] = False
    spec_usage: ClassVar[str] = "circle[:R]"
    spec_arity: ClassVar[tuple[int, int]] = (0, 1)

    def __post_init__(self) -> None:
        check_positive("cup radius", self.radius)
        check_positive("cup height", self.height)

    @classmethod
    def from_spec(cls, nums: list[float], spec: str) -> CircleCup:
        return cls(*nums)

    @property
    def circumradius(self) -> float:
        return self.radius

    @property
    def inradius(self) -> float:
        return self.radius

    @property
    def width_units(self) -> float:
        """The diameter, model units."""
        return 2 * self.radius

    def boundary(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
        return np.stack([self.radius * np.cos(t), self.radius * np.sin(t)], axis=1)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        return np.einsum("...i,...i->...", xy, xy) < self.radius**2

    def reflect(self, camera: tuple[float, float, float], xy: np.ndarray) -> list[MirrorPiece]:
        # the paper's bisection on the angle POT: an ellipse with equal axes
        return [reflect_conic(self.radius, self.radius, 0.0, camera, xy)]

    def reflect_reference(self, camera: tuple[float, float, float], q_xy: tuple[float, float]) -> Reference:
        return reference_conic(self.radius, self.radius, 0.0, camera, q_xy)

    def wall(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        return _conic_wall(self.radius, self.radius, 0.0, segments)

    def file_fields(self, to_mm: Callable[[float], float]) -> dict[str, Any]:
        return {"radius": to_mm(self.radius)}


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

    faceted: ClassVar[bool] = False
    spec_usage: ClassVar[str] = "ellipse:A,B[,ROT_DEG]"
    spec_arity: ClassVar[tuple[int, int]] = (2, 3)

    def __post_init__(self) -> None:
        a, b = as_vector("cup semi_axes", self.semi_axes, 2)
        object.__setattr__(self, "semi_axes", (a, b))
        check_positive("cup semi-axis a", a)
        check_positive("cup semi-axis b", b)
        check_finite("cup rotation_deg", self.rotation_deg)
        check_positive("cup height", self.height)

    @classmethod
    def from_spec(cls, nums: list[float], spec: str) -> EllipseCup:
        return cls((nums[0], nums[1]), *(nums[2:3]))

    @property
    def circumradius(self) -> float:
        return max(self.semi_axes)

    @property
    def inradius(self) -> float:
        return min(self.semi_axes)

    @property
    def width_units(self) -> float:
        """2a, the local x axis, model units."""
        return 2 * self.semi_axes[0]

    def boundary(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
        a, b = self.semi_axes
        local = np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
        return local @ rotation_matrix(self.rotation_deg).T

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        local = xy @ rotation_matrix(self.rotation_deg)  # rotate by -theta
        a, b = self.semi_axes
        return (local[..., 0] / a) ** 2 + (local[..., 1] / b) ** 2 < 1.0

    def reflect(self, camera: tuple[float, float, float], xy: np.ndarray) -> list[MirrorPiece]:
        a, b = self.semi_axes
        return [reflect_conic(a, b, self.rotation_deg, camera, xy)]

    def reflect_reference(self, camera: tuple[float, float, float], q_xy: tuple[float, float]) -> Reference:
        a, b = self.semi_axes
        return reference_conic(a, b, self.rotation_deg, camera, q_xy)

    def wall(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        return _conic_wall(*self.semi_axes, self.rotation_deg, segments)

    def file_fields(self, to_mm: Callable[[float], float]) -> dict[str, Any]:
        return {
            "semi_axes": [to_mm(self.semi_axes[0]), to_mm(self.semi_axes[1])],
            "rotation_deg": float(self.rotation_deg),
        }


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

    faceted: ClassVar[bool] = True
    spec_usage: ClassVar[str] = "prism:N[,CIRCUMRADIUS[,ROT_DEG]]"
    spec_arity: ClassVar[tuple[int, int]] = (1, 3)

    def __post_init__(self) -> None:
        if not isinstance(self.sides, int) or isinstance(self.sides, bool) or not (
            3 <= self.sides <= 64
        ):
            raise ConfigError(f"prism sides must be an integer in [3, 64], got {self.sides!r}")
        check_positive("cup circumradius", self.circumradius)
        check_finite("cup rotation_deg", self.rotation_deg)
        check_positive("cup height", self.height)

    @classmethod
    def from_spec(cls, nums: list[float], spec: str) -> PrismCup:
        # check finiteness first: int() of nan/inf raises ValueError/OverflowError
        if not math.isfinite(nums[0]) or nums[0] != int(nums[0]):
            raise ConfigError(f"cup spec {spec!r}: the number of prism sides must be whole")
        return cls(int(nums[0]), *nums[1:])

    @property
    def inradius(self) -> float:
        return self.circumradius * math.cos(math.pi / self.sides)

    @property
    def width_units(self) -> float:
        """Twice the circumradius (corner to opposite corner for even n), model units."""
        return 2 * self.circumradius

    def boundary(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        """The polygon's corners, counter-clockwise, shape (sides, 2); ``segments`` is not used."""
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

    def reflect(self, camera: tuple[float, float, float], xy: np.ndarray) -> list[MirrorPiece]:
        return reflect_facets(self.boundary(), camera, xy)

    def reflect_reference(self, camera: tuple[float, float, float], q_xy: tuple[float, float]) -> Reference:
        return reference_facets(self.boundary(), camera, q_xy)

    def wall(self, segments: int = OUTLINE_SEGMENTS) -> np.ndarray:
        corners = self.boundary()
        mid = math.radians(self.rotation_deg) + 2 * np.pi * (np.arange(self.sides) + 0.5) / self.sides
        normal = np.stack([np.cos(mid), np.sin(mid)], axis=1)  # each facet's, at its middle angle
        ends = np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)
        return np.concatenate([ends, np.repeat(normal[:, None, :], 2, axis=1)], axis=2)

    def file_fields(self, to_mm: Callable[[float], float]) -> dict[str, Any]:
        return {
            "sides": int(self.sides),
            "circumradius": to_mm(self.circumradius),
            "rotation_deg": float(self.rotation_deg),
        }


def _conic_wall(a: float, b: float, rotation_deg: float, segments: int) -> np.ndarray:
    """:meth:`Cup.wall` of an elliptic cylinder with semi-axes (a, b) turned by ``rotation_deg``."""
    t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    r = rotation_matrix(rotation_deg)
    point = np.stack([a * np.cos(t), b * np.sin(t)], axis=1) @ r.T
    normal = np.stack([np.cos(t) / a, np.sin(t) / b], axis=1) @ r.T  # the gradient of x^2/a^2 + y^2/b^2
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    ends = np.concatenate([point, normal], axis=1)
    return np.stack([ends, np.roll(ends, -1, axis=0)], axis=1)


#: every cup shape by its ``kind``, in the order help texts list them
CUP_CLASSES: dict[str, type[Cup]] = {cls.kind: cls for cls in (CircleCup, EllipseCup, PrismCup)}

#: the CLI spec forms, for help texts
CUP_SPEC_USAGE = ", ".join(cls.spec_usage for cls in CUP_CLASSES.values())


def parse_cup_spec(spec: str) -> Cup:
    """Parse a CLI cup spec: ``circle[:R]``, ``ellipse:A,B[,ROT]``, ``prism:N[,R[,ROT]]`` (see :data:`CUP_SPEC_USAGE`)."""
    name, _, rest = spec.strip().partition(":")
    args = [a for a in rest.split(",") if a.strip()] if rest else []
    try:
        nums = [float(a) for a in args]
    except ValueError:
        raise ConfigError(
            f"cup spec {spec!r}: parameters must be numbers, e.g. 'prism:6,0.45,0'"
        ) from None
    cls = CUP_CLASSES.get(name)
    if cls is not None and cls.spec_arity[0] <= len(nums) <= cls.spec_arity[1]:
        return cls.from_spec(nums, spec)
    forms = [f"'{c.spec_usage}'" for c in CUP_CLASSES.values()]
    raise ConfigError(f"unknown cup spec {spec!r}; use {', '.join(forms[:-1])} or {forms[-1]}")


def cup_to_dict(cup: Cup) -> dict[str, Any]:
    """The cup's TOML/JSON table: ``shape`` (its kind), then its fields in order (tuples as lists)."""
    d = {f.name: getattr(cup, f.name) for f in fields(cup) if f.name != "kind"}  # type: ignore[arg-type]
    d = {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
    return {"shape": cup.kind, **d}


def cup_from_dict(table: Any, default_shape: str) -> Cup:
    """The cup of a ``[cup]`` table; without a ``shape`` key it is ``default_shape``.

    Raises:
        ConfigError: not a table, an unknown shape, an unknown key or a bad value.
        TypeError: a value of the wrong kind for its field (the scene reports it).
    """
    if not isinstance(table, dict):
        raise ConfigError(f"[cup] must be a table with a 'shape' key, got {table!r}")
    c = dict(table)
    shape = c.pop("shape", default_shape)
    if shape not in CUP_CLASSES:
        raise ConfigError(f"unknown cup shape {shape!r}; use one of {sorted(CUP_CLASSES)}")
    cls = CUP_CLASSES[shape]
    init = [f for f in fields(cls) if f.init]  # type: ignore[arg-type]
    check_keys(f"[cup] ({shape})", c, {f.name for f in init})
    # TOML gives lists; vector fields (tuple defaults) get tuples, as the classes hold them
    for f in init:
        if f.name in c and isinstance(f.default, tuple):
            c[f.name] = tuple(c[f.name])
    return cls(**c)
