"""The flat print: what a moved eye should see, the reference a moved eye is scored against.

From an eye other than the design eye no print can show the designer's
picture as drawn: a picture lying on the saucer is seen in that eye's
perspective (the saucer's near edge, closer to the eye, moves more than its
far edge: a shear of about 20 px across a 256 px frame for an eye 32 mm to
the side, ``benchmarks/results/HISTORY.md``, "Eyes (issue 19)"), and in the mirror with that
eye's anamorphic distortion. A viewer takes both for the same picture. What
a print can get wrong from there is what it adds to that: the relief's
parallax (strokes breaking into slices at the wave ridges), colours placed
for one eye only, the conflicts between the two pictures.

So a moved eye's reference is the **flat print**: each view's reference
picture painted on a flat plate at the print's mean height, placed so that
the design eye sees it exactly as drawn, and ray-traced from the moved eye
with the same cup by the same renderer as the print. It is built from the
files and ``scene.json`` alone, like the rest of verify:

1. :func:`mean_height`: the plate's height is the mean height of the
   printed top where the design eye sees it in the view (a position pass:
   the top emits its own coordinates);
2. :func:`plate_points`: a large plane at that height, seen from the design
   eye in the view's frame (directly or in the mirror), gives the point of
   the plate under each pixel's centre;
3. :func:`flat_print`: a mesh through those points with each pixel's frame
   position as its texture coordinate, textured with the reference picture,
   is the flat print (:class:`~.printfolder.PrintedSurface`), which
   :class:`~.raytrace.PrintTracer` renders from any eye.

From the design eye the flat print shows the reference picture itself
(tested to above 35 dB), so the score from a moved eye measures only what
the print adds beyond any flat picture's change of perspective.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from saucerfab.fabricate.scene_file import CupSpec, ViewSpec
from saucerfab.verify.printfolder import PrintedSurface
from saucerfab.verify.raytrace import (
    FULL_COVERAGE,
    PositionScene,
    PrintTracer,
    ViewRender,
    position_scene,
    render_positions,
)

#: samples per pixel of the height pass: only the mean height over the view is kept
HEIGHT_SPP = 4
#: a plate quad whose side on the plate exceeds this many times the median is
#: a jump (a prism cup's edge between two facets), not a piece of the plate
MAX_STRETCH = 8.0


def mean_height(top: PositionScene, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int,
                region: np.ndarray) -> float:
    """Mean height (mm) of the printed top the design eye sees over ``region`` of ``view``.

    Args:
        top: :func:`~.raytrace.position_scene` of the print's top faces, emitting z.
        region: (S, S) bool, the pixels where the design eye sees the top fully in this view.
    """
    pos = render_positions(top, eye, view, size, spp)
    ok = region & pos["full"]
    return float(np.mean(pos["xyz"][ok, 2])) if ok.any() else float(np.nanmean(pos["xyz"][..., 2]))


def plate_points(cup: CupSpec, extent: tuple[float, float, float, float], z0: float,
                 eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> dict[str, np.ndarray]:
    """Where each pixel of ``view`` from ``eye`` meets the plane ``z = z0``, directly or in the mirror.

    Args:
        cup: the mirror cup. extent: (xmin, xmax, ymin, ymax) mm the plane covers.
    Returns:
        ``xyz``: (S, S, 3) mm, the pixel's mean point on the plane; ``full``:
        (S, S) bool, the pixel sees the plane over its whole area.
    """
    x0, x1, y0, y1 = extent
    verts = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]], np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
    pts = render_positions(position_scene(verts, faces, cup, axes=(0, 1)), eye, view, size, spp)
    xyz = pts["xyz"]
    xyz[..., 2] = np.where(np.isfinite(xyz[..., 0]), z0, np.nan)  # the plane's own height, not emitted
    return pts


def flat_print(points: dict[str, np.ndarray], region: np.ndarray, picture: np.ndarray, *, path: Path) -> PrintedSurface:
    """The flat print of one view: the plate's points under the frame's pixels, textured with ``picture``.

    Args:
        points: :func:`plate_points` from the design eye (S x S).
        region: (S, S) bool, where the design eye sees the print's top in this
            view; the plate is built under it with its holes filled (a pixel
            the printed top does not fill, at a crack or a speck, is still
            a pixel of the picture).
        picture: (H, W, 3) uint8 reference picture covering the view's frame.
        path: a name for the surface (reports only).
    Returns:
        A surface of top faces only, one texture; its texture coordinate at a
        pixel's centre is that pixel's place in the frame.
    """
    from scipy.ndimage import binary_fill_holes

    s = region.shape[0]
    ok = binary_fill_holes(region) & points["full"]
    idx = np.full((s, s), -1, np.int64)
    idx[ok] = np.arange(int(ok.sum()))
    vertices = points["xyz"][ok].astype(np.float64)
    rows, cols = np.nonzero(ok)
    uv = np.stack([(cols + 0.5) / s, 1.0 - (rows + 0.5) / s], axis=1)  # v up, as in the files
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    quad = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    tris = np.concatenate([np.stack([a[quad], c[quad], b[quad]], 1), np.stack([b[quad], c[quad], d[quad]], 1)])
    if tris.shape[0]:
        side = np.linalg.norm(vertices[tris] - vertices[np.roll(tris, 1, axis=1)], axis=2).max(axis=1)
        tris = tris[side <= MAX_STRETCH * float(np.median(side))]
        # face up: Mitsuba's area lights emit on the front side only, and a
        # mirror view's frame is mirrored, which turns the grid's winding over
        e1, e2 = vertices[tris[:, 1]] - vertices[tris[:, 0]], vertices[tris[:, 2]] - vertices[tris[:, 0]]
        down = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
        tris[down] = tris[down][:, [0, 2, 1]]
    f = tris.shape[0]
    return PrintedSurface(
        path=path,
        format="flat",
        vertices=vertices,
        faces=tris,
        corner_uv=uv[tris],
        face_texture=np.zeros(f, np.int64),
        textures=[np.ascontiguousarray(picture, np.uint8)],
        top=np.ones(f, bool),
    )


class FlatPrints:
    """The flat print of each view of one print, built once and rendered from any eye.

    Args:
        surface: the printed file (its top gives the plate's height).
        cup: the mirror cup. design_eye: the design eye, mm.
        views: view name -> its frame. pictures: view name -> (H, W, 3) uint8 reference picture.
        regions: view name -> (S, S) bool, where the design eye sees the top fully in that view
            (verify's compared pixels from the design eye: inside the picture's rectangle, so the plate
            carries the picture, not its frame's padding).
        size, spp: the render size and samples per pixel of the design eye's renders.
    """

    def __init__(self, surface: PrintedSurface, cup: CupSpec, design_eye: tuple[float, float, float],
                 views: dict[str, ViewSpec], pictures: dict[str, np.ndarray], regions: dict[str, np.ndarray],
                 size: int, spp: int) -> None:
        self.heights: dict[str, float] = {}
        self._tracers: dict[str, PrintTracer] = {}
        if not surface.top.any() or not any(r.any() for r in regions.values()):
            return  # the design eye sees no printed top: no flat print, nothing to compare
        top_scene = position_scene(surface.vertices, surface.faces[surface.top], cup, axes=(2, 2))
        lo, hi = surface.vertices.min(axis=0), surface.vertices.max(axis=0)
        pad = float(np.max(hi - lo))  # the plane reaches well past the saucer: a moved eye's rays land anywhere
        extent = (float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad))
        for name, view in views.items():
            if not regions[name].any():
                continue  # the design eye sees nothing of this view: no flat print, nothing to compare
            z0 = mean_height(top_scene, design_eye, view, size, min(spp, HEIGHT_SPP), regions[name])
            pts = plate_points(cup, extent, z0, design_eye, view, size, spp)
            flat = flat_print(pts, regions[name], pictures[name], path=Path(f"flat_{name}"))
            if flat.faces.shape[0] == 0:
                continue
            self.heights[name] = z0
            self._tracers[name] = PrintTracer(flat, cup)

    def render(self, name: str, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> tuple[np.ndarray, np.ndarray]:
        """The flat print of view ``name`` seen from ``eye``: (S, S, 3) rgb and (S, S) bool, where it is seen fully.

        Seen fully means in the view's own way: directly for the direct view, in
        the mirror for the others. A view the design eye did not see has no flat
        print: black, seen nowhere.
        """
        r = self.render_view(name, eye, view, size, spp)
        return r.rgb, r.coverage(name) >= FULL_COVERAGE

    def render_view(self, name: str, eye: tuple[float, float, float], view: ViewSpec, size: int, spp: int) -> ViewRender:
        """:meth:`render`'s whole render, with its sampling noise (:class:`~.raytrace.ViewRender`)."""
        if name not in self._tracers:
            black, nowhere = np.zeros((size, size, 3), np.float32), np.zeros((size, size), np.float32)
            return ViewRender(black, nowhere, nowhere, black)
        return self._tracers[name].render(eye, view, size, spp)
