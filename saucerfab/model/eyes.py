"""Where the viewer's eyes are: the design eye, the two eyes of a viewer, an eye box.

One definition of the eyes for the optimizer (``saucerfab design --eyes``,
:mod:`saucerfab.optimize.viewpoints`) and the checker (``saucerfab verify
--eyes``, :mod:`saucerfab.verify`). Offsets are millimetres; positions are in
the frame of the design eye given to :func:`eye_positions`: the file frame of
``scene.json`` (mm), or the model frame with ``mm_per_unit``. "Left" and
"right" are along the direct view's horizontal right axis (the camera looks
at the saucer; world z is up), "up" along its image up axis, so an eye box is
a rectangle facing the saucer, centred on the design eye.

One word for each mode in every command: ``design`` (the design eye alone),
``both``, ``box:W,H[,N]``. ``point``, the name ``saucerfab design`` used for
``design`` before, is still read (design folders and scripts of that time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from saucerfab.errors import ConfigError

#: eye modes of ``--eyes`` (``point``, an older name of ``design``, is still read)
EYE_MODES = ("design", "both", "box")
#: the forms ``--eyes`` takes, in ``saucerfab design`` and ``saucerfab verify`` alike
EYES_USAGE = "|".join("box:W,H[,N]" if m == "box" else m for m in EYE_MODES)
#: the older name of ``design`` (``saucerfab design --eyes point``), still read
OLD_DESIGN_EYE_NAME = "point"
#: a viewer's interpupillary distance, mm (adult mean, about 63-64 mm)
DEFAULT_IPD_MM = 64.0
#: positions per side of an eye box
DEFAULT_BOX_STEPS = 3


@dataclass(frozen=True)
class EyeSpec:
    """Which eyes to render.

    Attributes:
        mode: ``design`` (the design point only), ``both`` (it and the two
            eyes of a viewer standing there) or ``box`` (it and a grid).
        ipd_mm: distance between the two eyes (``both``).
        box_mm: (width, height) of the eye box (``box``).
        box_steps: positions along each side of the box (``box``).
    """

    mode: str = "both"
    ipd_mm: float = DEFAULT_IPD_MM
    box_mm: tuple[float, float] = (0.0, 0.0)
    box_steps: int = DEFAULT_BOX_STEPS


@dataclass(frozen=True)
class Eye:
    """One eye position.

    Attributes:
        name: ``design``, ``left``, ``right`` or ``box(+16,-8)``.
        position: (3,) mm, file frame.
        offset_mm: (right, up) from the design eye, mm.
    """

    name: str
    position: tuple[float, float, float]
    offset_mm: tuple[float, float]


def parse_eyes(text: str, ipd_mm: float = DEFAULT_IPD_MM) -> EyeSpec:
    """``design`` (or its older name ``point``), ``both`` or ``box:W,H[,N]`` (millimetres; N positions per side)."""
    if not (isinstance(ipd_mm, (int, float)) and math.isfinite(ipd_mm) and 0 < ipd_mm <= 200):
        raise ConfigError(f"--ipd-mm must be a distance in (0, 200] mm, got {ipd_mm!r}")
    t = str(text).strip().lower()
    if t == OLD_DESIGN_EYE_NAME:
        t = "design"
    if t in ("design", "both"):
        return EyeSpec(t, float(ipd_mm))
    if t.startswith("box:"):
        parts = t[4:].split(",")
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            nums = []
        if len(nums) not in (2, 3) or not all(math.isfinite(v) and v >= 0 for v in nums):
            raise ConfigError(f"--eyes {text!r}: an eye box is box:W,H or box:W,H,N (mm, N positions per side)")
        steps = int(nums[2]) if len(nums) == 3 else DEFAULT_BOX_STEPS
        if not 2 <= steps <= 9 or (len(nums) == 3 and nums[2] != steps):
            raise ConfigError(f"--eyes {text!r}: N must be an integer in [2, 9]")
        if nums[0] > 1000 or nums[1] > 1000:
            raise ConfigError(f"--eyes {text!r}: an eye box wider than 1000 mm is not a viewing region")
        return EyeSpec("box", float(ipd_mm), (nums[0], nums[1]), steps)
    raise ConfigError(f"--eyes must be one of {EYES_USAGE.replace('|', ', ')}; got {text!r}")


def view_axes(eye: tuple[float, float, float], target: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) unit vectors of a look-at from ``eye`` to ``target`` with z up."""
    fwd = np.subtract(target, eye).astype(np.float64)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    return right, np.cross(right, fwd)


def eye_positions(
    spec: EyeSpec,
    design_eye: tuple[float, float, float],
    target: tuple[float, float, float],
    mm_per_unit: float = 1.0,
) -> list[Eye]:
    """The eyes of ``spec`` around ``design_eye`` (which comes first).

    Args:
        design_eye, target: the design eye and the direct view's target, in a frame of
            ``mm_per_unit`` millimetres per unit (1: the file frame of ``scene.json``).
    """
    e = np.asarray(design_eye, np.float64)
    right, up = view_axes(design_eye, target)

    def at(name: str, dr: float, du: float) -> Eye:
        p = e + (dr * right + du * up) / mm_per_unit
        return Eye(name, (float(p[0]), float(p[1]), float(p[2])), (float(dr), float(du)))

    eyes = [at("design", 0.0, 0.0)]
    if spec.mode == "both":
        eyes += [at("left", -spec.ipd_mm / 2, 0.0), at("right", spec.ipd_mm / 2, 0.0)]
    elif spec.mode == "box":
        w, h = spec.box_mm
        for du in np.linspace(h / 2, -h / 2, spec.box_steps):
            for dr in np.linspace(-w / 2, w / 2, spec.box_steps):
                if abs(dr) < 1e-9 and abs(du) < 1e-9:
                    continue  # the design eye is already there
                # whole millimetres as before ("box(+20,-10)"), a fraction where a small box has one:
                # no two eyes share a name (verify names its renders and pictures by it)
                eyes.append(at(f"box({dr:+.4g},{du:+.4g})", float(dr), float(du)))
    return eyes


def eye_weights(eyes: list[Eye]) -> list[float]:
    """The weight of each eye in the optimizer's E_visual and in the texture blend (they sum to 1).

    The design eye alone: 1. With others, the design eye keeps half (it is
    where the viewer is told to stand, and where ``verify`` scores without a
    shift) and the other eyes share the other half equally: ``both`` gives
    0.5, 0.25, 0.25; a 3 x 3 box 0.5 and 0.0625 each.
    """
    if len(eyes) == 1:
        return [1.0]
    return [0.5] + [0.5 / (len(eyes) - 1)] * (len(eyes) - 1)
