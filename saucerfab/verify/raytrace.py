"""What a viewer sees of the printed files: Mitsuba 3 renders of a print folder.

The scene is built from the files as written, never from the optimizer's
meshes: the saucer is the exported mesh (:class:`PrintedSurface`), the cup
a perfect mirror built from ``scene.json`` (:class:`CupSpec`), and the
camera the ``scene.json`` camera or a moved eye. The saucer's colours are
*emitted* radiance read from its texture without any colour-space change
(``raw`` bitmaps), and every other surface is black, so a pixel of a render
is exactly the printed colour the viewer sees there (a mirror reflects it
unchanged), averaged over the pixel (box filter).

Two renders per view (:data:`INTEGRATOR`):

* the colour pass: top and walls emit their texture colours, the cup is a
  conductor with reflectance 1;
* the coverage pass: the saucer's top emits (1, 1, 0), the rest of the part
  emits nothing, the cup reflects only green. Its red channel is the
  fraction of each pixel where the top is seen directly, green minus red the
  fraction where it is seen in the mirror.

Circular and elliptic cups are tessellated finely with their exact normals
as shading normals (Mitsuba's conductor reflects about the shading normal),
so the reflection follows the smooth cup to well under a pixel; prism
facets are flat.

Scenes are built in the **render frame**, the file frame moved so the cup's
axis at mid-height is the origin (:func:`render_origin`), the camera moved
with it. Mitsuba traces in float32 and starts a ray leaving a surface at
``p`` off it by ``(1 + max|p|) * RayEpsilon`` (8.9e-5) along the normal,
which for the mirror is a wall that reflects as if it stood half that much
further out: 5-8 um where an export puts the cup (its axis 150 mm from the
origin), a reflected picture 0.02-0.07 px off at 256 px. Around the cup the
offset is 3-5 um, and :func:`cup_mesh` sets the mirror inside the true wall
by half of it, so the reflection is the true wall's (tested against an
analytic reflection to 0.01 px).

The colour pass is rendered as two independent halves (:data:`SAMPLER`,
different seeds): the picture is their mean, and half their difference
(:attr:`ViewRender.half_diff`) squared is an unbiased estimate of the
render's own noise, which :func:`~saucerfab.verify.metrics.psnr` takes out
of the error: a noisy render's squared error is its true error plus its
noise variance, which at 16 samples per pixel read a photo 1.3 dB low.
Two renders with the same seeds sample the same points of each pixel, so
their noises are correlated and do not add: the variance of their
difference is estimated by the square of the difference of their
``half_diff`` (:func:`sampling_variance`).

Mitsuba's CPU variant ``scalar_rgb`` is used: it runs everywhere (its
``llvm_ad_rgb`` variant needs an LLVM newer than some systems have).
``SAUCERFAB_MITSUBA_VARIANT`` picks another, e.g. ``cuda_ad_rgb`` on a GPU.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.errors import SaucerfabError
from saucerfab.fabricate.scene_file import CupSpec, ViewSpec
from saucerfab.verify.printfolder import PrintedSurface

#: pixels seen at least this fully are compared (a pixel's share where the top is seen)
FULL_COVERAGE = 0.999
#: Mitsuba variant used unless SAUCERFAB_MITSUBA_VARIANT says otherwise
DEFAULT_VARIANT = "scalar_rgb"
VARIANT_ENV = "SAUCERFAB_MITSUBA_VARIANT"
#: segments of a tessellated circular or elliptic cup (sagitta 47 nm at r = 40 mm)
CUP_SEGMENTS = 2048
#: colour of faces without a texture (the default wall colour, 200/255)
UNTEXTURED_RGB = (200 / 255,) * 3
#: pixel sampler of the colour halves: Kensler's correlated multi-jitter, a stratified
#: a x b grid (Mitsuba's ``stratified`` takes only squares, and 8, the default's half, is not one)
SAMPLER = "multijitter"
#: pixel sampler of the coverage and position passes
COVERAGE_SAMPLER = "stratified"
#: Mitsuba's direct-illumination integrator, sampling BSDFs only: a camera ray
#: returns the emission it hits plus the emission along its BSDF-sampled ray,
#: which for the mirror (a delta lobe) is the reflected saucer and for the
#: black surfaces is nothing. These are the only light paths of this scene
#: (a convex cup never sees itself), at half the cost of the ``path`` integrator,
#: which gives the same pictures (checked when this was written: mean |diff| 0.001).
INTEGRATOR = {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1}

_MI: Any = None


class RendererMissing(SaucerfabError):
    """Mitsuba 3 is not installed or its variant cannot run."""


def mitsuba() -> Any:
    """The ``mitsuba`` module with its variant set (imported once)."""
    global _MI
    if _MI is None:
        try:
            import mitsuba as mi
        except ImportError:
            raise RendererMissing(
                "saucerfab verify renders with Mitsuba 3, which is not installed; "
                "install it with 'pip install mitsuba' (it runs on the CPU)"
            ) from None
        variant = os.environ.get(VARIANT_ENV, DEFAULT_VARIANT)
        try:
            mi.set_variant(variant)
        except (ImportError, AttributeError, ValueError) as exc:
            raise RendererMissing(
                f"Mitsuba variant {variant!r} cannot run here ({exc}); unset {VARIANT_ENV} "
                f"or set it to one of {', '.join(mi.variants())}"
            ) from None
        _MI = mi
    return _MI


@dataclass(frozen=True)
class ViewRender:
    """One view of the print from one eye.

    Attributes:
        rgb: (S, S, 3) float32 sRGB in [0, 1], row 0 at the top: what the eye sees.
        direct: (S, S) float32 in [0, 1], share of each pixel where the
            saucer's top is seen directly.
        reflected: (S, S) float32 in [0, 1], share seen in the mirror.
        half_diff: (S, S, 3) float32, half the difference of the colour
            pass's two halves (:func:`colour_halves`): its square is an
            unbiased estimate of the variance of ``rgb`` from sampling; zero
            where the render has a single sample per pixel and no estimate.
    """

    rgb: np.ndarray
    direct: np.ndarray
    reflected: np.ndarray
    half_diff: np.ndarray

    def coverage(self, view: str) -> np.ndarray:
        """(S, S) share of each pixel where the top is seen the view's way: directly for ``direct``, else in the mirror."""
        return self.direct if view == "direct" else self.reflected


def sampling_variance(*renders: ViewRender) -> np.ndarray:
    """(S, S, 3) unbiased estimate of the sampling variance of one render's ``rgb``, or of two renders' difference.

    Two renders of one view with the same seed share their samples'
    positions in each pixel: the differences of their halves are two
    independent estimates of their difference, and half the difference of
    those, squared, estimates its variance. (Adding the two renders' own variances would count the
    noise they share, and read two alike renders as identical.)
    """
    if len(renders) == 1:
        return np.square(renders[0].half_diff)
    a, b = renders
    return np.square(a.half_diff - b.half_diff)


def render_origin(cup: CupSpec) -> np.ndarray:
    """(3,) mm, file frame: the point the render frame puts at the origin, the cup's axis at mid-height.

    Mitsuba's offset of a ray leaving the mirror grows with the hit point's
    largest coordinate (module docstring): centred on the cup it is 3-5 um
    wherever the file placed the print.
    """
    return np.array([cup.center[0], cup.center[1], cup.bottom_z + cup.height / 2.0])


def colour_halves(spp: int) -> int:
    """Samples per pixel of each of the colour pass's two halves; 0 for one pass of ``spp`` (``spp`` < 2).

    Half of ``spp`` rounded down to a count :data:`SAMPLER` takes as it is
    (its grid is ``a x b``, ``a = isqrt(n)``; Mitsuba would round any other
    count up, with a warning): ``spp / 2`` for every even ``spp`` up to 16
    (the defaults 16 and 4), 30 for 64.
    """
    half = int(spp) // 2
    if half < 1:
        return 0
    a = math.isqrt(half)
    return a * (half // a)


def _mesh(
    mi: Any,
    name: str,
    positions: np.ndarray,
    faces: np.ndarray,
    *,
    bsdf: dict[str, Any],
    emitter: dict[str, Any] | None = None,
    uv: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> Any:
    """A Mitsuba mesh from arrays: positions (V, 3) mm, faces (F, 3), uv (V, 2), normals (V, 3)."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    m = mi.Mesh(
        name,
        vertex_count=int(positions.shape[0]),
        face_count=int(faces.shape[0]),
        props=props,
        has_vertex_normals=normals is not None,
        has_vertex_texcoords=uv is not None,
    )
    p = mi.traverse(m)

    def put(key: str, a: np.ndarray, dtype: Any) -> None:
        p[key] = type(p[key])(np.ascontiguousarray(a, dtype).ravel())  # the variant's own array type

    put("vertex_positions", positions, np.float32)
    put("faces", faces, np.uint32)
    if uv is not None:
        put("vertex_texcoords", uv, np.float32)
    if normals is not None:
        put("vertex_normals", normals, np.float32)
    p.update()
    return m


def cup_mesh(
    cup: CupSpec, segments: int = CUP_SEGMENTS, *, origin: np.ndarray | None = None, ray_epsilon: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cup's mirror wall as triangles with outward shading normals.

    Each straight piece of the wall (:meth:`saucerfab.model.cups.Cup.wall`) is cut
    into three quads of its own at ``|z| = max(|x|, |y|)`` (render frame), so
    a facet keeps its flat normal, a smooth cup's normals, equal at the
    shared edges, shade smoothly, and the inset below is linear over every
    triangle.

    Args:
        origin: (3,) mm, file frame: the point put at the origin (default: none, the file frame).
        ray_epsilon: the renderer's ``RayEpsilon``. Mitsuba starts the ray
            leaving the mirror at ``p`` from ``p + m n``, ``m = (1 + max|p|) *
            ray_epsilon``. A wall set in by ``s`` meets a ray ``s / cos(i)``
            further on, and the reflected ray started from there ``m`` out is
            the true wall's, moved by ``(m - 2 s) n`` across it: each vertex is
            set in by ``m / 2`` along its piece's normal, and the mirror
            reflects as the true wall (0 leaves the wall where it is).

    Returns:
        positions (V, 3) mm, faces (F, 3), normals (V, 3) unit, outward.
    """
    o = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    wall = cup.outline.wall(segments)  # (S, 2, 4): [x, y, nx, ny] at each piece's two ends
    xy = wall[:, :, :2] + np.asarray(cup.center) - o[:2]  # (S, 2, 2)
    z0, z1 = cup.bottom_z - o[2], cup.bottom_z + cup.height - o[2]
    kink = np.abs(xy).max(axis=2)  # (S, 2): where |z| takes over max|p|
    levels = np.stack([np.full_like(kink, z0), np.clip(-kink, z0, z1), np.clip(kink, z0, z1),
                       np.full_like(kink, z1)], axis=2)  # (S, 2 ends, 4)
    # quad k of a piece: end 0 and end 1 at levels k and k + 1, corners (a_k, b_k, b_k+1, a_k+1)
    ends, steps = np.array([0, 1, 1, 0]), np.array([0, 0, 1, 1])
    k = np.arange(3)[:, None] + steps  # (3, 4)
    z = levels[:, ends[None, :], k]  # (S, 3, 4)
    pos = np.concatenate([np.broadcast_to(xy[:, None, ends], z.shape + (2,)), z[..., None]], axis=3)
    normals = np.broadcast_to(np.concatenate([wall[:, :, 2:], np.zeros((len(wall), 2, 1))], 2)[:, None, ends], pos.shape)
    if ray_epsilon > 0.0:
        edge = xy[:, 1] - xy[:, 0]
        flat = np.stack([edge[:, 1], -edge[:, 0]], 1) / np.linalg.norm(edge, axis=1, keepdims=True)
        flat *= np.sign(np.sum(flat * wall[:, :, 2:].sum(1), axis=1, keepdims=True))  # outward
        inset = 0.5 * (1.0 + np.abs(pos).max(axis=3)) * ray_epsilon  # (S, 3, 4), mm
        pos = pos.copy()
        pos[..., :2] -= inset[..., None] * flat[:, None, None, :]
    pos, normals = pos.reshape(-1, 3), np.ascontiguousarray(normals).reshape(-1, 3)
    base = 4 * np.arange(len(wall) * 3)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    # a quad cut off at the wall's top or bottom has no height at one end or both
    zq = z.reshape(-1, 4)
    keep = np.concatenate([zq[:, 2] > zq[:, 1], zq[:, 3] > zq[:, 0]])
    return pos, faces[keep], normals


def _cap(cup: CupSpec, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A disc closing the cup's top (what is inside the cup is not the mirror), render frame."""
    ring = cup.outline.wall(256)[:, 0, :2] + np.asarray(cup.center)  # each piece's first end
    top = cup.bottom_z + cup.height
    p = np.concatenate([[[*cup.center, top]], np.c_[ring, np.full(len(ring), top)]]) - origin
    k = np.arange(1, len(p))
    f = np.stack([np.zeros_like(k), k, np.where(k + 1 < len(p), k + 1, 1)], 1)
    return p, f


#: the BSDF of every surface but the mirror: black, so a pixel shows only what is emitted
BLACK = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
#: the cup: a perfect mirror (reflectance 1)
MIRROR = {"type": "conductor", "material": "none"}


def _cup_meshes(mi: Any, cup: CupSpec, origin: np.ndarray, mirror: dict[str, Any]) -> dict[str, Any]:
    """The mirror wall (its BSDF ``mirror``) and its black lid, as scene entries in the render frame."""
    cpos, cfaces, cnorm = cup_mesh(cup, origin=origin, ray_epsilon=float(mi.math.RayEpsilon))
    cap_p, cap_f = _cap(cup, origin)
    return {"cup": _mesh(mi, "cup", cpos, cfaces, bsdf=mirror, normals=cnorm),
            "cup_top": _mesh(mi, "cup_top", cap_p, cap_f, bsdf=BLACK)}


class PrintTracer:
    """Mitsuba scenes of one printed file and its cup; renders any eye and view.

    Args:
        surface: the file as read (:func:`~saucerfab.verify.printfolder.read_surface`).
        cup: the mirror cup from ``scene.json``.
    """

    def __init__(self, surface: PrintedSurface, cup: CupSpec) -> None:
        mi = mitsuba()
        self._mi = mi
        self._origin = render_origin(cup)
        # one vertex per face corner: a corner's texture coordinate belongs to its face
        faces = surface.faces
        corners = surface.vertices[faces].reshape(-1, 3) - self._origin
        # Mitsuba's bitmap has v = 0 at the image's top row; the files' v runs bottom -> top
        uv = surface.corner_uv.reshape(-1, 2) * (1.0, -1.0) + (0.0, 1.0)
        colour: dict[str, Any] = {"type": "scene"}
        cover: dict[str, Any] = {"type": "scene"}
        for tex_id in np.unique(surface.face_texture):
            for is_top in (True, False):
                sel = np.flatnonzero((surface.face_texture == tex_id) & (surface.top == is_top))
                if sel.size == 0:
                    continue
                idx = (sel[:, None] * 3 + np.arange(3)).reshape(-1)
                pos, tri = corners[idx], np.arange(idx.size).reshape(-1, 3)
                if tex_id >= 0:
                    img = surface.textures[int(tex_id)].astype(np.float32) / 255.0
                    radiance: dict[str, Any] = {
                        "type": "bitmap",
                        "bitmap": mi.Bitmap(np.ascontiguousarray(img)),
                        "raw": True,  # the texture's sRGB numbers are what the pixel shows
                        "filter_type": "bilinear",
                        "wrap_mode": "clamp",
                    }
                else:
                    radiance = {"type": "rgb", "value": list(UNTEXTURED_RGB)}
                key = f"part_{'top' if is_top else 'rest'}_{int(tex_id) + 1}"
                colour[key] = _mesh(mi, key, pos, tri, bsdf=BLACK, uv=uv[idx],
                                    emitter={"type": "area", "radiance": radiance})
                cover[key] = _mesh(
                    mi, key, pos, tri, bsdf=BLACK,
                    emitter={"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 0.0]}} if is_top else None,
                )
        green = {**MIRROR, "specular_reflectance": {"type": "rgb", "value": [0.0, 1.0, 0.0]}}
        colour.update(_cup_meshes(mi, cup, self._origin, MIRROR))
        cover.update(_cup_meshes(mi, cup, self._origin, green))
        for d in (colour, cover):
            d["integrator"] = INTEGRATOR
        self._colour = mi.load_dict(colour)
        self._cover = mi.load_dict(cover)
        self.extent_mm = float(np.ptp(surface.vertices, axis=0).max())

    def render(self, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int, *, seed: int = 0) -> ViewRender:
        """Both passes of ``view`` seen from ``eye`` (mm), ``size`` x ``size`` pixels.

        The camera follows :mod:`saucerfab.model.camera`: a look-at from the
        eye to the view's target with z up, square frame, half angle
        ``view.viewing_angle_deg``; row 0 at the top, +x of the view to the right.
        The colour pass is two renders of :func:`colour_halves` samples per
        pixel (seeds ``2 seed`` and ``2 seed + 1``): ``rgb`` is their mean and
        ``half_diff`` half their difference, whose square's expectation is
        the variance of that mean.
        """
        mi = self._mi
        half = colour_halves(spp)

        def colour(n: int, s: int) -> np.ndarray:
            sensor = _sensor(mi, eye, view, size, n, self.extent_mm, self._origin, SAMPLER)
            return np.array(mi.render(self._colour, sensor=sensor, spp=n, seed=s), dtype=np.float32)

        if half:
            a, b = colour(half, 2 * seed), colour(half, 2 * seed + 1)
            rgb, half_diff = 0.5 * (a + b), 0.5 * (a - b)
        else:
            rgb = colour(int(spp), 2 * seed)
            half_diff = np.zeros_like(rgb)
        sensor = _sensor(mi, eye, view, size, int(spp), self.extent_mm, self._origin)
        cov = np.array(mi.render(self._cover, sensor=sensor, spp=int(spp), seed=seed), dtype=np.float32)
        direct = np.clip(cov[..., 0], 0.0, 1.0)
        reflected = np.clip(cov[..., 1] - cov[..., 0], 0.0, 1.0)
        return ViewRender(np.clip(rgb, 0.0, 1.0), direct, reflected, half_diff)


def _sensor(mi: Any, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int, extent_mm: float,
            origin: np.ndarray, sampler: str = COVERAGE_SAMPLER) -> Any:
    """The camera of :mod:`saucerfab.model.camera` in the render frame (``origin`` at 0): a look-at
    from ``eye`` to the view's target, z up, square."""
    dist = math.dist(eye, view.target)
    return mi.load_dict(
        {
            "type": "perspective",
            "fov": 2.0 * view.viewing_angle_deg,
            "fov_axis": "x",
            "near_clip": max(1e-3, dist * 1e-4),
            "far_clip": dist * 10 + extent_mm * 10,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(np.subtract(eye, origin)),
                                                        target=list(np.subtract(view.target, origin)), up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": int(size), "height": int(size), "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": sampler, "sample_count": int(spp)},
        }
    )


#: where a position pass puts a coordinate: ``(c - low) / span + POSITION_OFFSET``, in
#: (0, 1.5): Mitsuba refuses negative radiance, and an offset keeps a pixel's
#: coverage (the third channel) apart from its coordinates
POSITION_OFFSET = 0.25


@dataclass(frozen=True)
class PositionScene:
    """A mesh that emits its own coordinates, with the mirror cup: see :func:`position_scene`.

    ``origin``: (3,) mm, the file-frame point at the render frame's origin (:func:`render_origin`).
    """

    scene: Any
    axes: tuple[int, int]
    low: np.ndarray
    span: float
    extent_mm: float
    origin: np.ndarray


def position_scene(vertices: np.ndarray, faces: np.ndarray, cup: CupSpec, axes: tuple[int, int] = (0, 1)) -> PositionScene:
    """A scene where ``faces`` emit two of their coordinates and 1, and the cup mirrors them.

    Args:
        vertices: (V, 3) mm. faces: (F, 3). axes: the two coordinates emitted (0 x, 1 y, 2 z).
    """
    mi = mitsuba()
    origin = render_origin(cup)
    used = np.unique(faces)
    low = vertices[used].min(axis=0)
    span = float(max(np.ptp(vertices[used], axis=0).max(), 1e-9))
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(BLACK)
    props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "mesh_attribute", "name": "vertex_color"}})
    m = mi.Mesh("positions", vertex_count=int(vertices.shape[0]), face_count=int(faces.shape[0]), props=props)
    p = mi.traverse(m)
    p["vertex_positions"] = type(p["vertex_positions"])(np.ascontiguousarray(vertices - origin, np.float32).ravel())
    p["faces"] = type(p["faces"])(np.ascontiguousarray(faces, np.uint32).ravel())
    p.update()
    code = np.ones((vertices.shape[0], 3), np.float64)
    for k, a in enumerate(axes):
        code[:, k] = (vertices[:, a] - low[a]) / span + POSITION_OFFSET
    m.add_attribute("vertex_color", 3, [float(v) for v in code.astype(np.float32).ravel()])
    scene = mi.load_dict({"type": "scene", "integrator": INTEGRATOR, "positions": m,
                          **_cup_meshes(mi, cup, origin, MIRROR)})
    return PositionScene(scene, axes, low, span, float(np.ptp(vertices[used], axis=0).max()), origin)


def render_positions(ps: PositionScene, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> dict[str, np.ndarray]:
    """What point of a :func:`position_scene` each pixel sees (directly or in the mirror), on average.

    Returns:
        ``xyz``: (S, S, 3) mm, the pixel's mean point (NaN in the axis not emitted
        and where nothing is seen); ``full``: (S, S) bool, seen over the pixel's whole area.
    """
    mi = mitsuba()
    sensor = _sensor(mi, eye, view, size, spp, ps.extent_mm, ps.origin)
    img = np.array(mi.render(ps.scene, sensor=sensor, spp=int(spp)), np.float64)
    cov = img[..., 2]
    full = cov >= FULL_COVERAGE
    xyz = np.full(img.shape[:2] + (3,), np.nan)
    seen = cov > 0
    for k, a in enumerate(ps.axes):
        xyz[seen, a] = (img[seen, k] / cov[seen] - POSITION_OFFSET) * ps.span + ps.low[a]
    return {"xyz": xyz, "full": full}


#: the part pass (:func:`part_scene`): the top emits white, every other surface of the part (walls, base,
#: seat plate) yellow, and the cup reflects green and blue only, so that a pixel's red is the share of it
#: seeing the part directly, its green the share seeing the part either way, and its blue the share seeing
#: the top either way
PART_TOP_RGB = (1.0, 1.0, 1.0)
PART_REST_RGB = (1.0, 1.0, 0.0)
PART_MIRROR_RGB = (0.0, 1.0, 1.0)


@dataclass(frozen=True)
class PartScene:
    """The printed part, every surface of it, with the mirror cup: see :func:`part_scene`.

    ``origin``: (3,) mm, the file-frame point at the render frame's origin (:func:`render_origin`).
    """

    scene: Any
    extent_mm: float
    origin: np.ndarray


@dataclass(frozen=True)
class PartCoverage:
    """What of the part each pixel sees (:func:`render_part`), shares of the pixel's area in [0, 1].

    Attributes:
        direct: (S, S) any surface of the part seen directly.
        reflected: (S, S) any surface of the part seen in the mirror.
        top: (S, S) the part's coloured top seen, directly or in the mirror.
    """

    direct: np.ndarray
    reflected: np.ndarray
    top: np.ndarray


def part_scene(surface: PrintedSurface, cup: CupSpec) -> PartScene:
    """A scene of the whole printed part (top, walls, base, seat plate) and the mirror cup that tells, per
    pixel, whether the part is seen, directly or in the mirror, and whether its top is (:data:`PART_TOP_RGB`)."""
    mi = mitsuba()
    origin = render_origin(cup)
    entries: dict[str, Any] = {"type": "scene", "integrator": INTEGRATOR}
    for is_top, rgb in ((True, PART_TOP_RGB), (False, PART_REST_RGB)):
        faces = surface.faces[surface.top == is_top]
        if faces.size == 0:
            continue
        key = f"part_{'top' if is_top else 'rest'}"
        entries[key] = _mesh(mi, key, surface.vertices - origin, faces, bsdf=BLACK,
                             emitter={"type": "area", "radiance": {"type": "rgb", "value": list(rgb)}})
    mirror = {**MIRROR, "specular_reflectance": {"type": "rgb", "value": list(PART_MIRROR_RGB)}}
    entries.update(_cup_meshes(mi, cup, origin, mirror))
    return PartScene(mi.load_dict(entries), float(np.ptp(surface.vertices, axis=0).max()), origin)


def render_part(ps: PartScene, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> PartCoverage:
    """The part pass of ``view`` from ``eye`` (mm), ``size`` x ``size`` pixels at ``spp`` samples per pixel.

    Its samples are :func:`render_positions`' at the same size and ``spp`` (the same sensor and sampler), so
    at one sample a pixel the two passes describe the same ray.
    """
    mi = mitsuba()
    sensor = _sensor(mi, eye, view, size, spp, ps.extent_mm, ps.origin)
    img = np.clip(np.array(mi.render(ps.scene, sensor=sensor, spp=int(spp)), np.float64), 0.0, 1.0)
    return PartCoverage(direct=img[..., 0], reflected=np.clip(img[..., 1] - img[..., 0], 0.0, 1.0), top=img[..., 2])
