"""The light and the materials of ``saucerfab verify --light`` (issue 45), each described once.

Verify's default (``--light emitted``) shows each texel as emitted light seen
in a perfect mirror (:mod:`.raytrace`). A person sees a semi-glossy plastic
lit by a lamp and a room, in a metal cup. This module says what those are;
:mod:`.lit` renders them and :mod:`.litscore` scores the renders.

**The light frame.** A lamp's place is given in millimetres relative to the
cup's foot (its axis at its standing plane), along the viewer's own
directions: ``x`` to the viewer's right, ``y`` towards the viewer (the
horizontal direction from the cup to the design eye, the saucer's side) and
``z`` up. So ``lamp:0,300,900,600`` is a 600 mm square lamp 900 mm above the
cup's foot and 300 mm in front of it, whatever way the files face.

**Brightness.** Every light is measured by what it does to a sheet of white
paper (a Lambertian reflector of albedo 1) lying flat at the cup's foot: its
linear radiance there. The renders are in those units and shown as sRGB
with no other exposure: a lamp of power 0.6 and a room of 0.15 make that
paper read 0.75 (sRGB 0.88), which leaves headroom for slopes that face the lamp.

**Lights** (:data:`LIGHTS`):

* ``emitted``: verify as before (texture emitted, perfect mirror);
* ``room``: a dim uniform environment (:data:`ROOM_AMBIENT`, a constant
  emitter all round) and a soft square lamp above and in front of the piece
  (:data:`ROOM_LAMP`), the set-up of issue 45's measurement;
* ``lamp:x,y,z,size[,power]``: that lamp alone, facing the cup's foot
  (power default :data:`DEFAULT_LAMP_POWER`).

**The saucer's plastic** (:func:`plastic_bsdf`): PolyJet Vero prints are
semi-glossy. Mitsuba's ``roughplastic`` (a GGX specular coat over a diffuse
base), the texture's sRGB numbers converted to linear as its diffuse albedo.

**The cup's metal** (:data:`CUP_METALS`): a conductor with the measured
complex refractive index (n, k) at the dominant wavelengths of the sRGB
primaries (:data:`RGB_WAVELENGTHS_NM`), so Mitsuba's Fresnel equations give
the reflectance at every angle; head-on it reflects :meth:`Metal.reflectance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError

#: the lights ``--light`` takes
LIGHTS = ("emitted", "room", "lamp")
#: verify's light when none is asked for: the emitted texture, as before issue 45
DEFAULT_LIGHT = "emitted"
#: a white paper's reading at the cup's foot under a ``lamp:`` of no given power
DEFAULT_LAMP_POWER = 0.75
#: the room's uniform environment: a white paper lying flat reads this under it alone (a dim room)
ROOM_AMBIENT = 0.15
#: the room's lamp: issue 45's measurement, a soft ~600 mm lamp 900 mm above and in front of the piece
ROOM_LAMP_XYZ_MM = (0.0, 300.0, 900.0)
ROOM_LAMP_SIZE_MM = 600.0
ROOM_LAMP_POWER = 0.6
#: from which eyes a lit verify renders and scores the views: the design eye alone (the default:
#: each eye costs two path-traced renders per view, about as much as the whole emitted verify of
#: that eye), or every eye the emitted verify renders
LIT_EYES = ("design", "all")
DEFAULT_LIT_EYES = "design"
#: the accepted forms, for messages and --help
LIGHT_FORMS = "emitted, room, or lamp:X,Y,Z,SIZE[,POWER] (mm from the cup's foot: X right, Y towards the viewer, Z up)"


@dataclass(frozen=True)
class Lamp:
    """A square area lamp facing the cup's foot.

    Attributes:
        xyz_mm: its centre in the light frame (module docstring): mm right of,
            towards the viewer from, and above the cup's foot.
        size_mm: the square's side.
        power: what a white paper lying flat at the cup's foot reads under it alone (linear radiance).
    """

    xyz_mm: tuple[float, float, float]
    size_mm: float
    power: float

    def to_dict(self) -> dict[str, Any]:
        return {"xyz_mm": [float(c) for c in self.xyz_mm], "size_mm": float(self.size_mm), "power": float(self.power)}


ROOM_LAMP = Lamp(ROOM_LAMP_XYZ_MM, ROOM_LAMP_SIZE_MM, ROOM_LAMP_POWER)


@dataclass(frozen=True)
class LightSpec:
    """What lights the print (:data:`LIGHTS`).

    Attributes:
        kind: ``emitted``, ``room`` or ``lamp``.
        lamp: the area lamp (None for ``emitted``).
        ambient: the uniform environment's radiance (a flat white paper's reading under it alone); 0 for none.
    """

    kind: str
    lamp: Lamp | None = None
    ambient: float = 0.0

    @property
    def lit(self) -> bool:
        """True for a real light (the saucer a plastic, the cup a metal); False for the emitted texture."""
        return self.kind != "emitted"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, recorded in verify.json."""
        return {"kind": self.kind, "lamp": None if self.lamp is None else self.lamp.to_dict(),
                "ambient": float(self.ambient),
                "frame": "mm from the cup's foot: x to the viewer's right, y towards the viewer, z up; "
                         "brightness: a white paper lying flat at the cup's foot reads lamp power + ambient"}


def parse_light(text: str | None) -> LightSpec:
    """``--light``'s value as a :class:`LightSpec` (None: :data:`DEFAULT_LIGHT`).

    Raises:
        ConfigError: not one of :data:`LIGHT_FORMS`, or a lamp with a bad number.
    """
    s = (DEFAULT_LIGHT if text is None else str(text)).strip().lower()
    if s == "emitted":
        return LightSpec("emitted")
    if s == "room":
        return LightSpec("room", ROOM_LAMP, ROOM_AMBIENT)
    if s.startswith("lamp:"):
        parts = [p.strip() for p in s[5:].split(",")]
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            nums = []
        if len(nums) not in (4, 5) or not all(math.isfinite(v) for v in nums):
            raise ConfigError(f"--light {text!r}: a lamp is lamp:X,Y,Z,SIZE[,POWER], four or five numbers "
                              f"(e.g. lamp:0,300,900,600); --light takes {LIGHT_FORMS}")
        x, y, z, size = nums[:4]
        power = nums[4] if len(nums) == 5 else DEFAULT_LAMP_POWER
        if size <= 0 or power <= 0:
            raise ConfigError(f"--light {text!r}: the lamp's SIZE (mm) and POWER must be positive")
        if z <= 0:
            raise ConfigError(f"--light {text!r}: the lamp must stand above the cup's foot (Z > 0 mm), got Z = {z:g}")
        return LightSpec("lamp", Lamp((x, y, z), size, power), 0.0)
    raise ConfigError(f"--light {text!r} is not a light; --light takes {LIGHT_FORMS}")


@dataclass(frozen=True)
class LampPlacement:
    """A lamp placed in the file frame (:func:`place_lamp`).

    Attributes:
        center: (3,) mm, file frame. target: (3,) mm, the cup's foot it faces.
        radiance: the lamp's emitted radiance, in the paper's units (module docstring).
    """

    center: np.ndarray
    target: np.ndarray
    size_mm: float
    radiance: float


#: quadrature points per side of the lamp when its radiance is set from its power
_LAMP_QUAD = 64


def lamp_frame(toward_xy: tuple[float, float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(right, toward) unit (3,) vectors of the light frame in the file frame, from the horizontal direction
    ``toward_xy`` from the cup to the design eye (:func:`~.core.where_to_stand`'s ``direction_xy``)."""
    t = np.array([toward_xy[0], toward_xy[1], 0.0], np.float64)
    n = float(np.linalg.norm(t))
    t = t / n if n > 0 else np.array([0.0, -1.0, 0.0])
    return np.array([-t[1], t[0], 0.0]), t


def place_lamp(lamp: Lamp, foot: np.ndarray, toward_xy: tuple[float, float] | np.ndarray) -> LampPlacement:
    """The lamp in the file frame, facing the cup's foot, with the radiance that gives its power.

    A white Lambertian paper at ``foot`` facing up reads ``L / pi * integral(cos a cos b / r^2 dA)``
    under a lamp of radiance ``L`` (a paper's irradiance over pi), so
    ``L = power * pi / integral``; the integral is taken over a 64 x 64 grid of the square.

    Args:
        foot: (3,) mm, the cup's foot (its axis at its standing plane), file frame.
        toward_xy: the horizontal direction from the cup to the design eye.
    """
    right, toward = lamp_frame(toward_xy)
    up = np.array([0.0, 0.0, 1.0])
    x, y, z = lamp.xyz_mm
    center = np.asarray(foot, np.float64) + x * right + y * toward + z * up
    normal = np.asarray(foot, np.float64) - center
    dist = float(np.linalg.norm(normal))
    normal /= dist
    # two edge directions of the square, perpendicular to its normal
    ref = up if abs(float(normal @ up)) < 0.99 else toward
    e1 = np.cross(normal, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    k = ((np.arange(_LAMP_QUAD) + 0.5) / _LAMP_QUAD - 0.5) * lamp.size_mm
    u, v = np.meshgrid(k, k)
    pts = center + u[..., None] * e1 + v[..., None] * e2  # (Q, Q, 3)
    d = pts - np.asarray(foot, np.float64)
    r2 = np.sum(d * d, axis=-1)
    cos_paper = np.clip(d[..., 2] / np.sqrt(r2), 0.0, None)
    cos_lamp = np.clip(-(d @ normal) / np.sqrt(r2), 0.0, None)
    form = float(np.sum(cos_paper * cos_lamp / r2) * (lamp.size_mm / _LAMP_QUAD) ** 2)
    if form <= 0.0:
        raise ConfigError(f"the lamp at {list(lamp.xyz_mm)} mm does not light the cup's foot; put it above the saucer")
    return LampPlacement(center, np.asarray(foot, np.float64), float(lamp.size_mm), lamp.power * math.pi / form)


# --------------------------------------------------------------------------- the saucer's plastic

#: the plastic's index of refraction: acrylate photopolymers measure 1.505-1.533 over the visible
#: (Optical Materials Express 11, 3392 (2021), "Refractive index and dispersion of transparent 3D printing
#: photoresins"); Vero is an acrylate photopolymer
PLASTIC_IOR = 1.5
#: the specular coat's GGX roughness (alpha): an estimate, no published BRDF of printed Vero found.
#: "Semi-glossy": a lamp's highlight on it is a soft blur, not a sharp image (alpha 0.1 is
#: a glossy lacquer, 0.3 a satin); the top of a PolyJet print in glossy mode
PLASTIC_ALPHA = 0.15
#: under a uniform room of radiance L, a flat plate of the plastic of albedo rho reads
#: (PLASTIC_ROOM_DIFFUSE * rho + PLASTIC_ROOM_COAT) * L where a Lambertian one reads rho * L (seen at
#: the design eye's 45-50 degrees from the vertical; measured with Mitsuba 3.9, tested to 0.01 L): the
#: diffuse base loses a fifth to the coat's Fresnel transmission in and out, the coat reflects ~5 % of
#: the room. The lit score's gain per channel takes up the scale; the coat lifts dark colours
PLASTIC_ROOM_DIFFUSE = 0.80
PLASTIC_ROOM_COAT = 0.047


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB numbers in [0, 1] to linear (IEC 61966-2-1), same shape, float32."""
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear to sRGB numbers (IEC 61966-2-1), same shape, float32; negative values map to 0."""
    c = np.maximum(np.asarray(c, np.float32), 0.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(c, 1.0 / 2.4) - 0.055).astype(np.float32)


def plastic_bsdf(albedo: dict[str, Any]) -> dict[str, Any]:
    """The saucer's semi-glossy plastic, ``albedo`` (a Mitsuba texture of linear reflectance) its diffuse colour."""
    return {"type": "roughplastic", "distribution": "ggx", "alpha": PLASTIC_ALPHA, "int_ior": PLASTIC_IOR,
            "ext_ior": 1.0, "diffuse_reflectance": albedo}


def diffuse_bsdf(albedo: dict[str, Any]) -> dict[str, Any]:
    """A Lambertian surface of ``albedo``: the analytic reference the plastic is held to in the tests."""
    return {"type": "diffuse", "reflectance": albedo}


def plastic_dict() -> dict[str, Any]:
    """The plastic's parameters for verify.json."""
    return {"bsdf": "roughplastic", "distribution": "ggx", "alpha": PLASTIC_ALPHA, "ior": PLASTIC_IOR,
            "albedo": "the texture's sRGB numbers converted to linear"}


# --------------------------------------------------------------------------- the cup's metal

#: the wavelengths (nm) at which each metal's (n, k) is taken for R, G, B: the dominant
#: wavelengths of the sRGB primaries (611, 549, 464 nm), rounded
RGB_WAVELENGTHS_NM = (610.0, 550.0, 465.0)


@dataclass(frozen=True)
class Metal:
    """A polished metal: its complex refractive index n + ik at :data:`RGB_WAVELENGTHS_NM`.

    ``n`` and ``k`` are None for the perfect mirror (reflectance 1 at every angle).
    """

    name: str
    n: tuple[float, float, float] | None
    k: tuple[float, float, float] | None
    source: str

    def reflectance(self) -> tuple[float, float, float]:
        """Head-on reflectance per channel: ``((n - 1)^2 + k^2) / ((n + 1)^2 + k^2)``; 1 for the mirror."""
        if self.n is None or self.k is None:
            return (1.0, 1.0, 1.0)
        n, k = np.asarray(self.n), np.asarray(self.k)
        r = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
        return (float(r[0]), float(r[1]), float(r[2]))

    def bsdf(self) -> dict[str, Any]:
        """Mitsuba's smooth conductor of this metal (Fresnel at every angle)."""
        if self.n is None or self.k is None:
            return {"type": "conductor", "material": "none"}
        return {"type": "conductor", "eta": {"type": "rgb", "value": list(self.n)},
                "k": {"type": "rgb", "value": list(self.k)}}

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "n_rgb": None if self.n is None else list(self.n),
                "k_rgb": None if self.k is None else list(self.k),
                "reflectance_rgb": [round(r, 4) for r in self.reflectance()], "source": self.source}


#: n, k interpolated linearly in each refractiveindex.info table at 610, 550, 465 nm
CUP_METALS: dict[str, Metal] = {
    "mirror": Metal("mirror", None, None, "a perfect mirror (reflectance 1), verify's emitted light"),
    # head-on reflectance 0.552, 0.555, 0.558
    "chromium": Metal("chromium", (3.180, 3.181, 2.456), (3.300, 3.329, 3.210),
                      "Johnson & Christy, Phys. Rev. B 9, 5056 (1974), via refractiveindex.info (main/Cr/Johnson)"),
    # head-on reflectance 0.599, 0.588, 0.573
    "stainless-steel": Metal("stainless-steel", (2.085, 1.904, 1.561), (3.356, 3.170, 2.839),
                             "Karlsson & Ribbing, J. Appl. Phys. 53, 6340 (1982), ferritic stainless steel, via "
                             "refractiveindex.info (other/alloys/stainless steel/Karlsson-ferritic)"),
    # head-on reflectance 0.721, 0.698, 0.664: the tables put palladium above platinum
    "palladium": Metal("palladium", (1.736, 1.641, 1.445), (4.172, 3.845, 3.351),
                       "Johnson & Christy, Phys. Rev. B 9, 5056 (1974), via refractiveindex.info (main/Pd/Johnson)"),
    # head-on reflectance 0.666, 0.642, 0.598
    "platinum": Metal("platinum", (2.253, 2.085, 1.879), (4.052, 3.715, 3.223),
                      "Rakic et al., Appl. Opt. 37, 5271 (1998), Brendel-Bormann fit, via refractiveindex.info "
                      "(main/Pt/Rakic-BB)"),
}
#: the cup's metal of a lit verify when none is asked for
DEFAULT_LIT_METAL = "stainless-steel"


def lit_eyes(choice: str | None, light: LightSpec) -> str:
    """``--lit-eyes``: :data:`LIT_EYES` (None: :data:`DEFAULT_LIT_EYES`).

    Raises:
        ConfigError: another value, or one given with the emitted light (which renders nothing lit).
    """
    if choice is None:
        return DEFAULT_LIT_EYES
    key = str(choice).strip().lower()
    if key not in LIT_EYES:
        raise ConfigError(f"--lit-eyes {choice!r}: give design (the design eye alone) or all (every eye verified)")
    if not light.lit:
        raise ConfigError(f"--lit-eyes {key} needs a real light to render; add --light room (or lamp:...), or drop it")
    return key


def cup_metal(name: str | None, light: LightSpec) -> Metal:
    """The cup's :class:`Metal` for ``--cup-metal name`` under ``light``.

    Not given: the mirror in emitted light, :data:`DEFAULT_LIT_METAL` under a real light.

    Raises:
        ConfigError: an unknown name, or a metal other than the mirror in emitted light (the emitted
            verify's mirror is what it measures: a real metal belongs to a real light).
    """
    if name is None:
        return CUP_METALS["mirror" if not light.lit else DEFAULT_LIT_METAL]
    key = str(name).strip().lower()
    if key not in CUP_METALS:
        raise ConfigError(f"--cup-metal {name!r} is not a metal verify knows; give one of {', '.join(CUP_METALS)}")
    if not light.lit and key != "mirror":
        raise ConfigError(f"--cup-metal {key} needs a real light: the emitted verify (--light emitted) measures the "
                          "pictures in a perfect mirror; add --light room (or lamp:...), or drop --cup-metal")
    return CUP_METALS[key]
