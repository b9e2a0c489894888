"""Renders of a print under a real light (``saucerfab verify --light``, issue 45).

The scene is the emitted verify's (:mod:`.raytrace`: the exported mesh in
the render frame, the cup from ``scene.json``, the same cameras), with the
materials and lights of :mod:`.lighting`:

* every face of the part is the semi-glossy plastic
  (:func:`~.lighting.plastic_bsdf`), its texture's sRGB numbers converted
  to linear as albedo (untextured faces: the default wall grey, likewise);
* the cup is the chosen metal (:data:`~.lighting.CUP_METALS`) with its
  black lid;
* the room's constant environment and the lamp (:func:`emitters`).

Up to three scenes per print (:class:`LitTracer`): ``lit`` with the texture,
``white`` with every albedo 1: the shading alone, what the light and the
relief do to a white print, and ``black`` with every albedo 0: the plastic's
coat alone. The plastic is linear in its albedo (Mitsuba's ``roughplastic``
without its ``nonlinear`` option), so on a flat plate, where light passes
from one point of the part to another only through the cup (a second-order
share), ``black + a (white - black)`` is the plate printed with albedo ``a``
(:func:`~.litscore.flat_print`).

The integrator is Mitsuba's path tracer with :data:`MAX_DEPTH` 5. Depth
counts the segments of a light path: 2 is a lit point seen directly
(camera -> saucer -> light), 3 a lit point seen in the cup (camera -> cup ->
saucer -> light), 4 adds one bounce between facing slopes, or the cup
lighting the saucer, to a point seen in the cup, and 5 both (camera -> cup ->
saucer -> cup or saucer -> saucer -> light): the light bounced between the
slopes that carry the two pictures, which tints one with the other (issue
45). Longer paths carry little: on the heart/star default export under the
room's lamp (white albedo, the direct view) depths 3, 4 and 5 added 17, 15
and 3 % to the direct light's mean. Mitsuba's Russian roulette starts at
depth 5 and so never cuts a path short.

As the emitted colour pass, each render is two independent halves
(:func:`~.raytrace.colour_halves`, :data:`~.raytrace.SAMPLER`): the
picture is their mean, half their difference the noise estimate (:class:`LitImage`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.fabricate.scene_file import CupSpec, PrintScene, ViewSpec
from saucerfab.verify.lighting import (
    LightSpec,
    Metal,
    lamp_frame,
    place_lamp,
    plastic_bsdf,
    srgb_to_linear,
)
from saucerfab.verify.printfolder import PrintedSurface
from saucerfab.verify.raytrace import (
    SAMPLER,
    UNTEXTURED_RGB,
    _cup_meshes,
    _mesh,
    _sensor,
    colour_halves,
    mitsuba,
    render_origin,
)

#: longest light path, in segments (module docstring)
MAX_DEPTH = 5
#: Mitsuba's path tracer; its Russian roulette starts at ``rr_depth`` (5, Mitsuba's default), so no path
#: of :data:`MAX_DEPTH` is cut short
LIT_INTEGRATOR = {"type": "path", "max_depth": MAX_DEPTH, "rr_depth": 5}
#: segments of the flat plate's outline on a round saucer
PLATE_SEGMENTS = 256
#: the linear albedo of each 8-bit sRGB number
_SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0)


@dataclass(frozen=True)
class LitImage:
    """One lit render: (S, S, 3) float32 **linear** radiance in the paper's units (:mod:`.lighting`),
    and half its two halves' difference, (S, S, 3), whose square estimates its sampling variance."""

    rgb: np.ndarray
    half_diff: np.ndarray


def toward_viewer(scene: PrintScene) -> tuple[float, float]:
    """The horizontal direction from the cup's axis to the design eye, (x, y) unit, file frame."""
    dx, dy = scene.camera[0] - scene.cup.center[0], scene.camera[1] - scene.cup.center[1]
    n = math.hypot(dx, dy)
    return (dx / n, dy / n) if n > 0 else (0.0, -1.0)


def cup_foot(cup: CupSpec) -> np.ndarray:
    """(3,) mm, file frame: the cup's axis at its standing plane, the light frame's origin."""
    return np.array([cup.center[0], cup.center[1], cup.bottom_z], np.float64)


def emitters(mi: Any, light: LightSpec, foot: np.ndarray, toward_xy: tuple[float, float],
             origin: np.ndarray) -> dict[str, Any]:
    """Mitsuba scene entries of ``light`` in the render frame (``origin``, file frame, at 0): the room's
    constant environment and the lamp (a one-sided square facing the cup's foot, black behind)."""
    out: dict[str, Any] = {}
    if light.ambient > 0:
        out["room"] = {"type": "constant", "radiance": {"type": "rgb", "value": [float(light.ambient)] * 3}}
    if light.lamp is not None:
        p = place_lamp(light.lamp, foot, toward_xy)
        c, t = p.center - origin, p.target - origin
        n = (t - c) / np.linalg.norm(t - c)
        up = [0.0, 0.0, 1.0] if abs(float(n[2])) < 0.99 else [float(v) for v in lamp_frame(toward_xy)[1]]
        half = p.size_mm / 2.0
        # Mitsuba's rectangle spans [-1, 1]^2 facing +z; look_at turns +z towards the cup's foot
        to_world = mi.ScalarTransform4f().look_at(origin=[float(v) for v in c], target=[float(v) for v in t], up=up)
        out["lamp"] = {
            "type": "rectangle",
            "to_world": to_world @ mi.ScalarTransform4f().scale([half, half, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [float(p.radiance)] * 3}},
        }
    return out


class LitTracer:
    """The lit and white scenes of one printed surface, its cup, light and metal; renders any eye and view.

    Args:
        surface: the file as read (:func:`~.printfolder.read_surface`), or a flat plate (:func:`flat_plate`).
        scene: the print's scene.json (the cup, and the design eye that orients the light frame).
        light: a real light (``light.lit``). metal: the cup's metal.
        bsdf: the part's material given its albedo texture (default the plastic; the tests
            hold it to :func:`~.lighting.diffuse_bsdf`'s analytic values).
    """

    def __init__(self, surface: PrintedSurface, scene: PrintScene, light: LightSpec, metal: Metal,
                 bsdf: Callable[[dict[str, Any]], dict[str, Any]] = plastic_bsdf) -> None:
        self._mi = mitsuba()
        self._surface = surface
        self._cup = scene.cup
        self._origin = render_origin(scene.cup)
        self._lights = emitters(self._mi, light, cup_foot(scene.cup), toward_viewer(scene), self._origin)
        self._metal = metal
        self._bsdf = bsdf
        self._scenes: dict[str, Any] = {}
        self.extent_mm = float(np.ptp(surface.vertices, axis=0).max())

    def _scene(self, kind: str) -> Any:
        """The ``lit``, ``white`` or ``black`` Mitsuba scene, built on first use (a plate needs no textured one)."""
        if kind in self._scenes:
            return self._scenes[kind]
        mi, surface = self._mi, self._surface
        faces = surface.faces
        corners = surface.vertices[faces].reshape(-1, 3) - self._origin
        # Mitsuba's bitmap has v = 0 at the image's top row; the files' v runs bottom -> top
        uv = surface.corner_uv.reshape(-1, 2) * (1.0, -1.0) + (0.0, 1.0)
        entries: dict[str, Any] = {"type": "scene", "integrator": LIT_INTEGRATOR, **self._lights}
        plain = {"white": {"type": "rgb", "value": [1.0, 1.0, 1.0]}, "black": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        for tex_id in np.unique(surface.face_texture):
            sel = np.flatnonzero(surface.face_texture == tex_id)
            idx = (sel[:, None] * 3 + np.arange(3)).reshape(-1)
            if kind in plain:
                albedo: dict[str, Any] = plain[kind]
            elif tex_id >= 0:
                lin = _SRGB8_TO_LINEAR[surface.textures[int(tex_id)]]  # a table look-up: 4096^2 texels in 0.1 s
                albedo = {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(lin)), "raw": True,
                          "filter_type": "bilinear", "wrap_mode": "clamp"}  # linear already: no conversion
            else:
                albedo = {"type": "rgb", "value": [float(v) for v in srgb_to_linear(np.array(UNTEXTURED_RGB))]}
            key = f"part_{int(tex_id) + 1}"
            entries[key] = _mesh(mi, key, corners[idx], np.arange(idx.size).reshape(-1, 3),
                                 bsdf=self._bsdf(albedo), uv=uv[idx] if kind == "lit" else None)
        entries.update(_cup_meshes(mi, self._cup, self._origin, self._metal.bsdf()))
        self._scenes[kind] = mi.load_dict(entries)
        return self._scenes[kind]

    def render(self, kind: str, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int, *,
               seed: int = 0) -> LitImage:
        """The ``lit``, ``white`` or ``black`` scene from ``eye`` (mm) in ``view``'s frame, ``size`` px, ``spp`` samples a pixel.

        The camera is the emitted verify's (:func:`~.raytrace._sensor`); the two halves are rendered
        with seeds ``2 seed`` and ``2 seed + 1``, as :meth:`~.raytrace.PrintTracer.render`'s colour pass.
        """
        mi, scene = self._mi, self._scene(kind)
        half = colour_halves(spp)

        def one(n: int, s: int) -> np.ndarray:
            sensor = _sensor(mi, eye, view, size, n, self.extent_mm, self._origin, SAMPLER)
            return np.array(mi.render(scene, sensor=sensor, spp=n, seed=s), dtype=np.float32)

        if half:
            a, b = one(half, 2 * seed), one(half, 2 * seed + 1)
            return LitImage(0.5 * (a + b), 0.5 * (a - b))
        rgb = one(int(spp), 2 * seed)
        return LitImage(rgb, np.zeros_like(rgb))


def mean_top_height(surface: PrintedSurface) -> float:
    """The area-weighted mean height (mm, file frame) of the printed top's faces."""
    tri = surface.vertices[surface.faces[surface.top]]  # (F, 3, 3)
    if tri.shape[0] == 0:
        return float(surface.vertices[:, 2].max())
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    z = tri[:, :, 2].mean(axis=1)
    return float(np.sum(area * z) / max(float(np.sum(area)), 1e-12))


def flat_plate(surface: PrintedSurface, scene: PrintScene) -> PrintedSurface:
    """A flat plate over the saucer's footprint at the printed top's mean height: the relief's shading
    reference (a flat print has no slopes to shade). Top faces only, untextured, facing up.

    The footprint is scene.json's: the rectangle ``saucer_x`` x ``saucer_y``, or the disc of a round saucer.
    """
    z0 = mean_top_height(surface)
    if scene.is_disc and scene.saucer_center is not None and scene.saucer_diameter is not None:
        r = scene.saucer_diameter / 2.0
        a = 2.0 * np.pi * np.arange(PLATE_SEGMENTS) / PLATE_SEGMENTS
        ring = np.c_[scene.saucer_center[0] + r * np.cos(a), scene.saucer_center[1] + r * np.sin(a)]
        xy = np.concatenate([[scene.saucer_center], ring])
        k = np.arange(1, PLATE_SEGMENTS + 1)
        faces = np.stack([np.zeros_like(k), k, np.where(k < PLATE_SEGMENTS, k + 1, 1)], 1)  # counter-clockwise: up
    else:
        (x0, x1), (y0, y1) = scene.saucer_x or (0.0, 0.0), scene.saucer_y or (0.0, 0.0)
        xy = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
        faces = np.array([[0, 1, 2], [0, 2, 3]])
    vertices = np.c_[xy, np.full(len(xy), z0)]
    f = faces.shape[0]
    return PrintedSurface(path=Path("flat_plate"), format="flat", vertices=vertices, faces=faces,
                          corner_uv=np.zeros((f, 3, 2)), face_texture=np.full(f, -1, np.int64),
                          textures=[], top=np.ones(f, bool))
