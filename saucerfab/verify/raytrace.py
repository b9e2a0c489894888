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
from saucerfab.verify.printfolder import CupSpec, PrintedSurface, ViewSpec

#: pixels seen at least this fully are compared (a pixel's share where the top is seen)
FULL_COVERAGE = 0.999
#: Mitsuba variant used unless SAUCERFAB_MITSUBA_VARIANT says otherwise
DEFAULT_VARIANT = "scalar_rgb"
VARIANT_ENV = "SAUCERFAB_MITSUBA_VARIANT"
#: segments of a tessellated circular or elliptic cup (sagitta 47 nm at r = 40 mm)
CUP_SEGMENTS = 2048
#: colour of faces without a texture (the default wall colour, 200/255)
UNTEXTURED_RGB = (200 / 255,) * 3
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
    """

    rgb: np.ndarray
    direct: np.ndarray
    reflected: np.ndarray


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


def cup_mesh(cup: CupSpec, segments: int = CUP_SEGMENTS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cup's mirror wall as triangles with outward shading normals.

    Each straight piece of the wall (:meth:`saucerfab.cups.Cup.wall`) is a
    quad with four corners of its own, so a facet keeps its flat normal and
    a smooth cup's normals, equal at the shared edges, shade smoothly.

    Returns:
        positions (V, 3) mm, faces (F, 3), normals (V, 3) unit, outward.
    """
    wall = cup.outline.wall(segments)  # (S, 2, 4): [x, y, nx, ny] at each piece's two ends
    z0, z1 = cup.bottom_z, cup.bottom_z + cup.height
    xy = wall[:, :, :2] + np.asarray(cup.center)
    n = np.concatenate([wall[:, :, 2:], np.zeros((len(wall), 2, 1))], axis=2)
    a, b = xy[:, 0], xy[:, 1]
    pos = np.stack([np.c_[a, np.full(len(a), z0)], np.c_[b, np.full(len(a), z0)],
                    np.c_[b, np.full(len(a), z1)], np.c_[a, np.full(len(a), z1)]], axis=1).reshape(-1, 3)
    normals = np.stack([n[:, 0], n[:, 1], n[:, 1], n[:, 0]], axis=1).reshape(-1, 3)
    base = 4 * np.arange(len(wall))[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return pos, faces, normals


def _cap(cup: CupSpec) -> tuple[np.ndarray, np.ndarray]:
    """A disc closing the cup's top (what is inside the cup is not the mirror)."""
    pos, _, _ = cup_mesh(cup, segments=256)
    ring = pos.reshape(-1, 4, 3)[:, 3]  # each piece's first end, at the top
    centre = np.array([[*cup.center, cup.bottom_z + cup.height]])
    p = np.concatenate([centre, ring])
    k = np.arange(1, len(p))
    f = np.stack([np.zeros_like(k), k, np.where(k + 1 < len(p), k + 1, 1)], 1)
    return p, f


class PrintTracer:
    """Mitsuba scenes of one printed file and its cup; renders any eye and view.

    Args:
        surface: the file as read (:func:`~saucerfab.verify.printfolder.read_surface`).
        cup: the mirror cup from ``scene.json``.
    """

    def __init__(self, surface: PrintedSurface, cup: CupSpec) -> None:
        mi = mitsuba()
        self._mi = mi
        black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        # one vertex per face corner: a corner's texture coordinate belongs to its face
        faces = surface.faces
        corners = surface.vertices[faces].reshape(-1, 3)
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
                colour[key] = _mesh(mi, key, pos, tri, bsdf=black, uv=uv[idx],
                                    emitter={"type": "area", "radiance": radiance})
                cover[key] = _mesh(
                    mi, key, pos, tri, bsdf=black,
                    emitter={"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 0.0]}} if is_top else None,
                )
        cpos, cfaces, cnorm = cup_mesh(cup)
        cap_p, cap_f = _cap(cup)
        mirror = {"type": "conductor", "material": "none"}
        green = {"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": [0.0, 1.0, 0.0]}}
        colour["cup"] = _mesh(mi, "cup", cpos, cfaces, bsdf=mirror, normals=cnorm)
        cover["cup"] = _mesh(mi, "cup", cpos, cfaces, bsdf=green, normals=cnorm)
        colour["cup_top"] = _mesh(mi, "cup_top", cap_p, cap_f, bsdf=black)
        cover["cup_top"] = _mesh(mi, "cup_top", cap_p, cap_f, bsdf=black)
        for d in (colour, cover):
            d["integrator"] = INTEGRATOR
        self._colour = mi.load_dict(colour)
        self._cover = mi.load_dict(cover)
        self.extent_mm = float(np.ptp(surface.vertices, axis=0).max())

    def render(self, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int, *, seed: int = 0) -> ViewRender:
        """Both passes of ``view`` seen from ``eye`` (mm), ``size`` x ``size`` pixels.

        The camera follows :mod:`saucerfab.render.camera`: a look-at from the
        eye to the view's target with z up, square frame, half angle
        ``view.viewing_angle_deg``; row 0 at the top, +x of the view to the right.
        """
        mi = self._mi
        sensor = _sensor(mi, eye, view, size, spp, self.extent_mm)
        rgb = np.array(mi.render(self._colour, sensor=sensor, spp=int(spp), seed=seed), dtype=np.float32)
        cov = np.array(mi.render(self._cover, sensor=sensor, spp=int(spp), seed=seed), dtype=np.float32)
        direct = np.clip(cov[..., 0], 0.0, 1.0)
        reflected = np.clip(cov[..., 1] - cov[..., 0], 0.0, 1.0)
        return ViewRender(np.clip(rgb, 0.0, 1.0), direct, reflected)


def _sensor(mi: Any, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int, extent_mm: float) -> Any:
    """The camera of :mod:`saucerfab.render.camera`: a look-at from ``eye`` to the view's target, z up, square."""
    dist = math.dist(eye, view.target)
    return mi.load_dict(
        {
            "type": "perspective",
            "fov": 2.0 * view.viewing_angle_deg,
            "fov_axis": "x",
            "near_clip": max(1e-3, dist * 1e-4),
            "far_clip": dist * 10 + extent_mm * 10,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(eye), target=list(view.target), up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": int(size), "height": int(size), "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": int(spp)},
        }
    )


#: where a position pass puts a coordinate: ``(c - low) / span + POSITION_OFFSET``, in
#: (0, 1.5): Mitsuba refuses negative radiance, and an offset keeps a pixel's
#: coverage (the third channel) apart from its coordinates
POSITION_OFFSET = 0.25


@dataclass(frozen=True)
class PositionScene:
    """A mesh that emits its own coordinates, with the mirror cup: see :func:`position_scene`."""

    scene: Any
    axes: tuple[int, int]
    low: np.ndarray
    span: float
    extent_mm: float


def position_scene(vertices: np.ndarray, faces: np.ndarray, cup: CupSpec, axes: tuple[int, int] = (0, 1)) -> PositionScene:
    """A scene where ``faces`` emit two of their coordinates and 1, and the cup mirrors them.

    Args:
        vertices: (V, 3) mm. faces: (F, 3). axes: the two coordinates emitted (0 x, 1 y, 2 z).
    """
    mi = mitsuba()
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    used = np.unique(faces)
    low = vertices[used].min(axis=0)
    span = float(max(np.ptp(vertices[used], axis=0).max(), 1e-9))
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(black)
    props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "mesh_attribute", "name": "vertex_color"}})
    m = mi.Mesh("positions", vertex_count=int(vertices.shape[0]), face_count=int(faces.shape[0]), props=props)
    p = mi.traverse(m)
    p["vertex_positions"] = type(p["vertex_positions"])(np.ascontiguousarray(vertices, np.float32).ravel())
    p["faces"] = type(p["faces"])(np.ascontiguousarray(faces, np.uint32).ravel())
    p.update()
    code = np.ones((vertices.shape[0], 3), np.float64)
    for k, a in enumerate(axes):
        code[:, k] = (vertices[:, a] - low[a]) / span + POSITION_OFFSET
    m.add_attribute("vertex_color", 3, [float(v) for v in code.astype(np.float32).ravel()])
    cpos, cfaces, cnorm = cup_mesh(cup)
    cap_p, cap_f = _cap(cup)
    scene = mi.load_dict({
        "type": "scene",
        "integrator": INTEGRATOR,
        "positions": m,
        "cup": _mesh(mi, "cup", cpos, cfaces, bsdf={"type": "conductor", "material": "none"}, normals=cnorm),
        "cup_top": _mesh(mi, "cup_top", cap_p, cap_f, bsdf=black),
    })
    return PositionScene(scene, axes, low, span, float(np.ptp(vertices[used], axis=0).max()))


def render_positions(ps: PositionScene, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> dict[str, np.ndarray]:
    """What point of a :func:`position_scene` each pixel sees (directly or in the mirror), on average.

    Returns:
        ``xyz``: (S, S, 3) mm, the pixel's mean point (NaN in the axis not emitted
        and where nothing is seen); ``full``: (S, S) bool, seen over the pixel's whole area.
    """
    mi = mitsuba()
    img = np.array(mi.render(ps.scene, sensor=_sensor(mi, eye, view, size, spp, ps.extent_mm), spp=int(spp)), np.float64)
    cov = img[..., 2]
    full = cov >= FULL_COVERAGE
    xyz = np.full(img.shape[:2] + (3,), np.nan)
    seen = cov > 0
    for k, a in enumerate(ps.axes):
        xyz[seen, a] = (img[seen, k] / cov[seen] - POSITION_OFFSET) * ps.span + ps.low[a]
    return {"xyz": xyz, "full": full}
