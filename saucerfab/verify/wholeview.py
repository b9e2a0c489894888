"""The whole view (issue 43, item 1): everything of the piece one eye sees, against the ideal whole view.

Verify's frames show each picture where the design put it; a person sees
the whole piece. From an eye, one sensor takes in the whole saucer and the
cup (:func:`whole_view_spec`), and the print is rendered through it as the
frames are (:class:`~.raytrace.PrintTracer`: the texture emitted, the cup a
mirror), with a part pass (:func:`~.raytrace.render_part`) telling, per pixel
and per sub-sample, whether the printed part is seen - any surface of it: top,
walls, base, seat plate - directly or in the mirror, and whether it is the top,
and position passes of the printed top (:func:`~.raytrace.render_positions`)
telling the top's point seen.

**The ideal whole view**, per pixel that sees the printed part fully (all of it
directly, or all of it in the mirror), is the mean over the pixel's
sub-samples of:

* the top seen directly: the direct reference picture's colour where the point lies
  inside the direct frame's picture as it projects onto the saucer (the point
  mapped through the design eye's direct camera to frame pixels, inside the
  picture's rectangle, ``extent``), else the direct picture's background colour;
* the top seen in the mirror: the reflected reference's colour where the point lies
  in the region the reflected frame's picture shows of the saucer (the design
  eye's reflected frame, whose pixels' saucer points come from a position pass
  and are inverted locally, :class:`FrameMaps`; the pixels of its rectangle),
  else the reflected picture's background colour;
* any other surface of the part (walls, base, seat plate; only the top can lie
  in a frame): the background colour of the way it is seen - a person sees
  every surface of the piece, and outside the frames each should read as the
  background.

The background colour is the design's ``--background`` when ``export.json``
records one, else the one ground the design chose for pictures whose border
colours differ (``ground``: :func:`saucerfab.imaging.images.piece_ground`),
else the picture's own border colour
(:func:`saucerfab.imaging.images.estimate_background`: the median of its outer ring).
Pixels that see no part (the table, the cup's rim, the mirror showing
anything else) or see it partly, or partly directly and partly in the mirror,
are left out of every score, and so is the outline of what sees it (a pixel
counts when it and its four neighbours see the part fully: an outline pixel
can hold a sliver of the table that the coverage samples miss).

**Scores** (:class:`WholeView`):

* ``psnr_db``: the render against the ideal over the saucer pixels, less the
  render's own sampling noise, as the frames' PSNR;
* ``stray_direct``, ``stray_reflected``: the **stray share** of each
  surround (the saucer seen directly outside the direct frame; the mirror's
  image of the saucer outside the reflected frames): the share of its pixels
  whose colour lies farther than :data:`STRAY_DISTANCE` from that surround's
  background. The issue's target is :data:`TARGET_MAX_STRAY`; a view fails
  above :data:`DEFAULT_MAX_STRAY` (lenient: the plate the cup stands on
  shows both beside the cup and in it, and where a design folder has two
  grounds one surround keeps it, 10-30 % of it; a design whose pictures'
  border colours differ now takes one,
  :func:`saucerfab.imaging.images.piece_ground`);
* ``width_share``: the reflected picture's width over the cup's visible width,
  both along the image row where the reflected frame's region is widest
  (the cup's silhouette there, from its wall projected into the image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.fabricate.scene_file import CupSpec, PrintScene, ViewSpec
from saucerfab.verify.printfolder import PrintedSurface
from saucerfab.verify.raytrace import (
    FULL_COVERAGE,
    PositionScene,
    PrintTracer,
    part_scene,
    position_scene,
    render_part,
    render_positions,
    sampling_variance,
)

#: colour distance (Euclidean over the three sRGB channels in [0, 1]) beyond which a
#: surround pixel is stray: far from the background the design meant there
STRAY_DISTANCE = 0.25
#: default highest stray share of a surround for a whole view to pass (lenient: a design folder made
#: with two grounds keeps 10-30 % of one surround on the plate under the cup, seen beside the cup and
#: in it; the one ground a design now takes (piece_ground) keeps it under :data:`TARGET_MAX_STRAY`)
DEFAULT_MAX_STRAY = 0.5
#: the stray share issue 43 asks of every design, each surround
TARGET_MAX_STRAY = 0.05
#: the whole view's field of view reaches this share past the piece's outermost point
MARGIN = 0.04
#: samples per pixel of the frames' position passes (a fully seen pixel's mean point is all that is kept)
POSITION_SPP = 4
#: the whole view's position passes take SUPERSAMPLE x SUPERSAMPLE points a pixel, one sample each, so
#: that the ideal is box-filtered as the render is
SUPERSAMPLE = 3
#: how far (pixels) a frame pixel's point may project from the pixel to count as seen directly, not in the mirror
DIRECT_TOLERANCE_PX = 1.0
#: steps from the nearest frame pixel to the one a saucer point lies in (one or two suffice; more cost little)
NEWTON_STEPS = 4
#: colours of the stray map: a stray pixel around the direct frame, around the reflected frame
STRAY_DIRECT_RGB = (1.0, 0.1, 0.1)
STRAY_REFLECTED_RGB = (0.1, 0.9, 1.0)
#: grey of pixels that see no saucer (left out of the scores) in the ideal and the stray map
NOT_SAUCER_RGB = (0.35, 0.35, 0.35)


def camera_axes(eye: tuple[float, float, float], view: ViewSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The camera of :func:`~.raytrace._sensor`: forward, right, up (unit, file frame) and tan(half angle)."""
    fwd = np.subtract(view.target, eye).astype(np.float64)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return fwd, right, np.cross(right, fwd), math.tan(math.radians(view.viewing_angle_deg))


def project(points: np.ndarray, eye: tuple[float, float, float], view: ViewSpec, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates of ``points`` (..., 3) mm in ``view`` from ``eye``, ``size`` px a side.

    Returns:
        (..., 2) (column, row) in pixels from the frame's top-left corner (a pixel
        ``i`` spans ``[i, i + 1)``), NaN behind the eye; (...,) depth along the view, mm.
    """
    fwd, right, up, w = camera_axes(eye, view)
    rel = np.asarray(points, np.float64) - np.asarray(eye, np.float64)
    depth = rel @ fwd
    with np.errstate(divide="ignore", invalid="ignore"):
        nx = np.where(depth > 0, (rel @ right) / (depth * w), np.nan)
        ny = np.where(depth > 0, (rel @ up) / (depth * w), np.nan)
    return np.stack([(nx + 1.0) * 0.5 * size, (1.0 - ny) * 0.5 * size], -1), depth


def cup_points(cup: CupSpec, segments: int = 256, levels: int = 33) -> np.ndarray:
    """(N, 3) mm: points over the cup's mirror wall (its outline at ``levels`` heights)."""
    ring = cup.outline.wall(segments)[:, 0, :2] + np.asarray(cup.center)
    z = np.linspace(cup.bottom_z, cup.bottom_z + cup.height, levels)
    return np.concatenate([np.c_[ring, np.full(len(ring), zz)] for zz in z])


def whole_view_spec(scene: PrintScene, surface: PrintedSurface, eye: tuple[float, float, float]) -> ViewSpec:
    """A square view from ``eye`` that takes in the whole saucer footprint (its top's height range) and the cup.

    The view looks at the middle of the piece's bounding points' span across the
    image; its half angle reaches the outermost of them, plus :data:`MARGIN`.
    """
    (x0, x1), (y0, y1) = scene.saucer_x, scene.saucer_y
    top = surface.vertices[np.unique(surface.faces[surface.top])] if surface.top.any() else surface.vertices
    z0, z1 = float(top[:, 2].min()), float(top[:, 2].max())
    saucer = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], np.float64)
    pts = np.concatenate([saucer, cup_points(scene.cup, 64, 3)])
    e = np.asarray(eye, np.float64)
    dirs = pts - e
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    mid = dirs.mean(axis=0)
    dist = float(np.linalg.norm(pts.mean(0) - e))
    target = e + mid / np.linalg.norm(mid) * dist
    for _ in range(3):  # aim at the middle of the points' span across the image, so the piece is centred
        probe = ViewSpec("whole", tuple(target), 45.0)  # type: ignore[arg-type]  # tan 45 = 1: coordinates are tangents
        uv, _ = project(pts, eye, probe, 2)
        tx, ty = 0.5 * (uv.min(0) + uv.max(0)) - 1.0  # (right, down) tangents of the span's middle
        fwd, right, up, _ = camera_axes(eye, probe)
        d = fwd + tx * right - ty * up
        target = e + d / np.linalg.norm(d) * dist
    probe = ViewSpec("whole", tuple(float(c) for c in target), 45.0)  # type: ignore[arg-type]
    uv, _ = project(pts, eye, probe, 2)
    reach = float(np.nanmax(np.abs(uv - 1.0)))  # the largest tangent off the axis, horizontally or vertically
    return ViewSpec("whole", probe.target, math.degrees(math.atan(reach * (1.0 + MARGIN))))


def background_colours(references: dict[str, np.ndarray], background: Any = None) -> dict[str, np.ndarray]:
    """Each view's intended background: the design's ``--background`` if given, else the picture's border colour.

    Args:
        references: view -> (H, W, 3) float reference picture in [0, 1].
        background: the design's ``background`` parameter (``#rrggbb``) or None.
    """
    from saucerfab.imaging.images import intended_background

    return {v: intended_background(img, background) for v, img in references.items()}


def _sample(img: np.ndarray, cr: np.ndarray) -> np.ndarray:
    """Bilinear sample of (H, W, 3) ``img`` at (N, 2) (column, row) pixel coordinates (pixel centres at +0.5)."""
    from scipy.ndimage import map_coordinates

    rows, cols = cr[:, 1] - 0.5, cr[:, 0] - 0.5
    return np.stack([map_coordinates(img[..., c], [rows, cols], order=1, mode="nearest") for c in range(3)], -1)


class FrameMaps:
    """Where a saucer point lies in each view's frame, as the design eye sees the frames.

    Direct view: the point projected through the design eye's direct camera
    (exact). Reflected views: a position pass of the top in the frame from the
    design eye gives each fully seen pixel's saucer point (x, y); a point is
    placed in the frame by the pixel whose point is nearest and that pixel's
    local affine map (the grid's differences to its neighbours), and lies
    inside where the pixel it lands in is one the mirror shows the saucer in.
    "In the frame" means in its picture: the centred rectangle of the square
    frame the picture covers (``scene.json``'s ``extent``; the rest of the
    square is the picture's background, so a point there is surround).
    (A triangulation of the points in (x, y) fails here: the mirror squeezes
    the frame's grid several times more along one axis than the other.)

    Args:
        top_xy, top_z: position scenes of the print's top emitting (x, y) and z.
        design_eye: mm. views: the frames. size: pixels a side of the frame passes.
    """

    def __init__(self, top_xy: PositionScene, top_z: PositionScene, design_eye: tuple[float, float, float],
                 views: dict[str, ViewSpec], size: int) -> None:
        self.design_eye = design_eye
        self.views = views
        self.size = size
        self._grid: dict[str, tuple[_Nearest, np.ndarray, np.ndarray, np.ndarray]] = {}
        rows, cols = np.mgrid[0:size, 0:size]
        centre = np.stack([cols + 0.5, rows + 0.5], -1)
        for name, view in views.items():
            if name == "direct":
                continue
            pos = render_positions(top_xy, design_eye, view, size, POSITION_SPP)
            z = render_positions(top_z, design_eye, view, size, POSITION_SPP)["xyz"][..., 2]
            xyz = np.concatenate([pos["xyz"][..., :2], z[..., None]], -1)
            seen_at, _ = project(xyz, design_eye, view, size)
            # a point that projects onto its own pixel is seen directly, not in the mirror
            direct = np.linalg.norm(seen_at - centre, axis=-1) <= DIRECT_TOLERANCE_PX
            ok = pos["full"] & np.isfinite(xyz).all(-1) & ~direct
            if ok.sum() < 3:
                continue
            xy = np.where(ok[..., None], xyz[..., :2], np.nan)
            jac = np.stack([_slope(xy, axis=1), _slope(xy, axis=0)], -1)  # (S, S, 2 xy, 2 [col, row])
            good = ok & np.isfinite(jac).all((-1, -2)) & (np.abs(np.linalg.det(np.nan_to_num(jac))) > 0)
            inv = np.full((size * size, 2, 2), np.nan)
            inv[good.ravel()] = np.linalg.inv(jac.reshape(-1, 2, 2)[good.ravel()])
            # the map is built from every pixel the mirror shows (whole slopes up to the rectangle's edge);
            # a point is in the frame only where it lands in the picture's rectangle
            framed = ok & view.picture_mask(size)
            self._grid[name] = (_Nearest(xy.reshape(-1, 2), good.ravel()), xy.reshape(-1, 2), inv, framed)

    def locate(self, name: str, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) frame pixel coordinates (column, row; ``size`` px a side) of saucer points ``xyz`` (N, 3) in
        view ``name``, and (N,) bool, inside the frame's picture (its rectangle, :attr:`ViewSpec.extent`)."""
        n, s = xyz.shape[0], self.size
        if name == "direct":
            cr, depth = project(xyz, self.design_eye, self.views[name], s)
            inside = (depth > 0) & np.isfinite(cr).all(-1) & (cr >= 0).all(-1) & (cr <= s).all(-1)
            # the picture's rectangle, |x_ndc| <= ex and |y_ndc| <= ey, in pixels: |2 col - s| <= ex s; with
            # extent (1, 1) this is the square above exactly (rounding is monotone), so older prints score alike
            ex, ey = self.views[name].extent
            inside &= (np.abs(2.0 * cr[:, 0] - s) <= ex * s) & (np.abs(2.0 * cr[:, 1] - s) <= ey * s)
            return cr, inside
        if name not in self._grid or n == 0:
            return np.full((n, 2), np.nan), np.zeros(n, bool)
        tree, xy, inv, ok = self._grid[name]
        q = xyz[:, :2]
        _, k = tree.query(q)
        pix = tree.indices_of(k)
        # Newton steps on the pixel grid: the nearest point in (x, y) can lie pixels away along the
        # squeezed axis, so step to the pixel the local affine map points at and map again from there
        for _ in range(NEWTON_STEPS):
            offset = np.einsum("nij,nj->ni", inv[pix], q - xy[pix])  # (d col, d row) pixels
            cr = np.stack([pix % s + 0.5, pix // s + 0.5], -1) + offset
            cell = np.clip(np.floor(cr), 0, s - 1).astype(np.int64)
            nxt = cell[:, 1] * s + cell[:, 0]
            usable = np.isfinite(inv[nxt]).all((1, 2))
            pix = np.where(usable, nxt, pix)
        offset = np.einsum("nij,nj->ni", inv[pix], q - xy[pix])
        cr = np.stack([pix % s + 0.5, pix // s + 0.5], -1) + offset
        cell = np.floor(cr).astype(np.int64)
        inside = (np.abs(offset) <= 1.0).all(-1) & (cell >= 0).all(-1) & (cell < s).all(-1)
        inside[inside] = ok[cell[inside, 1], cell[inside, 0]]
        return np.where(inside[:, None], cr, np.nan), inside


class _Nearest:
    """The nearest of the pixels ``usable`` (flat indices into ``xy`` (N, 2)) to query points."""

    def __init__(self, xy: np.ndarray, usable: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        self._idx = np.flatnonzero(usable)
        self._tree = cKDTree(xy[self._idx])

    def query(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._tree.query(q)

    def indices_of(self, k: np.ndarray) -> np.ndarray:
        return self._idx[k]


def _slope(a: np.ndarray, axis: int) -> np.ndarray:
    """Per pixel, the change of ``a`` (S, S, k) over one pixel along ``axis``: the mean of the forward and backward
    differences that exist (NaN where neither does)."""
    fwd = np.full_like(a, np.nan)
    back = np.full_like(a, np.nan)
    if axis == 0:
        fwd[:-1] = a[1:] - a[:-1]
        back[1:] = a[1:] - a[:-1]
    else:
        fwd[:, :-1] = a[:, 1:] - a[:, :-1]
        back[:, 1:] = a[:, 1:] - a[:, :-1]
    with np.errstate(invalid="ignore"):
        return np.where(np.isnan(fwd), back, np.where(np.isnan(back), fwd, 0.5 * (fwd + back)))


@dataclass
class WholeView:
    """One eye's whole view, its ideal and its scores (see the module docstring).

    Attributes:
        rgb: (S, S, 3) the render. ideal: (S, S, 3) the ideal whole view (grey where no part is seen).
        direct, mirror: (S, S) bool, the printed part (any surface) seen fully directly / in the mirror.
        in_direct, in_mirror: (S, S) bool, of those, the points inside the direct / a reflected frame.
        stray: (S, S) bool, surround pixels farther than :data:`STRAY_DISTANCE` from their background.
        psnr_db, stray_direct, stray_reflected, width_share: the scores (NaN where nothing to score).
        other: (S, S) float in [0, 1], the share of each pixel that sees a surface of the part other than
            its top (walls, base, seat plate); None when not measured.
    """

    rgb: np.ndarray
    ideal: np.ndarray
    direct: np.ndarray
    mirror: np.ndarray
    in_direct: np.ndarray
    in_mirror: np.ndarray
    stray: np.ndarray
    psnr_db: float
    stray_direct: float
    stray_reflected: float
    width_share: float
    other: np.ndarray | None = None

    @property
    def pixels(self) -> int:
        """Pixels scored (the printed part seen fully)."""
        return int((self.direct | self.mirror).sum())

    def surround_pixels(self) -> tuple[int, int]:
        """Pixels of the direct surround and of the mirror's surround."""
        return int((self.direct & ~self.in_direct).sum()), int((self.mirror & ~self.in_mirror).sum())


def stray_mask(rgb: np.ndarray, surround: np.ndarray, background: np.ndarray) -> np.ndarray:
    """(S, S) bool: pixels of ``surround`` whose colour is farther than :data:`STRAY_DISTANCE` from ``background``."""
    far = np.linalg.norm(np.asarray(rgb, np.float64) - np.asarray(background, np.float64), axis=-1) > STRAY_DISTANCE
    return far & surround


def share(mask: np.ndarray, of: np.ndarray) -> float:
    """The share of ``of``'s pixels in ``mask``; NaN when ``of`` is empty."""
    n = int(of.sum())
    return float((mask & of).sum()) / n if n else float("nan")


def width_share(in_mirror: np.ndarray, cup: CupSpec, eye: tuple[float, float, float], view: ViewSpec) -> float:
    """The reflected picture's width over the cup's visible width along the row where the picture is widest.

    The picture's width is the span of the reflected frame's pixels in that row;
    the cup's, the span of its wall's silhouette there (its wall points projected
    into the image). NaN when the mirror shows none of the frame.
    """
    counts = in_mirror.sum(axis=1)
    if counts.max(initial=0) == 0:
        return float("nan")
    row = int(np.argmax(counts))
    cols = np.flatnonzero(in_mirror[row])
    picture = float(cols.max() - cols.min() + 1)
    cr, depth = project(cup_points(cup), eye, view, in_mirror.shape[0])
    near = (depth > 0) & (np.abs(cr[:, 1] - (row + 0.5)) <= 1.0)
    if not near.any():
        return float("nan")
    return picture / float(np.ptp(cr[near, 0]))


def score_whole_view(rgb: np.ndarray, ideal: np.ndarray, noise: np.ndarray | None, direct: np.ndarray,
                     mirror: np.ndarray, in_direct: np.ndarray, in_mirror: np.ndarray,
                     backgrounds: tuple[np.ndarray, np.ndarray], width: float,
                     other: np.ndarray | None = None) -> WholeView:
    """The scores of a rendered whole view against its ideal (pure arrays; see :class:`WholeView`).

    Args:
        backgrounds: the direct and the reflected picture's background colours.
        width: :func:`width_share`. other: :attr:`WholeView.other`.
    """
    from saucerfab.verify.metrics import psnr

    around_direct, around_mirror = direct & ~in_direct, mirror & ~in_mirror
    stray = stray_mask(rgb, around_direct, backgrounds[0]) | stray_mask(rgb, around_mirror, backgrounds[1])
    return WholeView(
        rgb=rgb, ideal=ideal, direct=direct, mirror=mirror, in_direct=in_direct, in_mirror=in_mirror, stray=stray,
        psnr_db=psnr(rgb, ideal, direct | mirror, noise),
        stray_direct=share(stray, around_direct), stray_reflected=share(stray, around_mirror), width_share=width,
        other=other,
    )


class WholeViews:
    """Whole views of one printed file from any eye, with the ideal built from the design eye's frames.

    Args:
        tracer: the file's :class:`~.raytrace.PrintTracer`. surface: the file as read.
        scene: the print's ``scene.json``. references: view -> (H, W, 3) float reference picture.
        backgrounds: view -> (3,) background colour (:func:`background_colours`).
        size: pixels a side of the whole view and the frame passes.
    """

    def __init__(self, tracer: PrintTracer, surface: PrintedSurface, scene: PrintScene,
                 references: dict[str, np.ndarray], backgrounds: dict[str, np.ndarray], size: int) -> None:
        self.tracer, self.surface, self.scene, self.size = tracer, surface, scene, size
        self.references, self.backgrounds = references, backgrounds
        top = surface.faces[surface.top]
        self._top_xy = position_scene(surface.vertices, top, scene.cup, axes=(0, 1))
        self._top_z = position_scene(surface.vertices, top, scene.cup, axes=(2, 2))
        self.maps = FrameMaps(self._top_xy, self._top_z, scene.camera, scene.views, size)
        self._part = part_scene(surface, scene.cup)

    def render(self, eye: tuple[float, float, float], spp: int) -> WholeView:
        """The whole view from ``eye`` (mm) at ``spp`` samples per pixel, with its ideal and scores."""
        from scipy.ndimage import binary_erosion

        s = self.size
        view = whole_view_spec(self.scene, self.surface, eye)
        r = self.tracer.render(eye, view, s, spp)
        # the ideal is box-filtered like the render: each pixel's mean over SUPERSAMPLE x SUPERSAMPLE points
        # (a picture sampled once at a pixel's mean point aliases where a frame pixel covers several of its pixels)
        n, m = s * SUPERSAMPLE, SUPERSAMPLE * SUPERSAMPLE
        pos = render_positions(self._top_xy, eye, view, n, 1)["xyz"][..., :2]
        z = render_positions(self._top_z, eye, view, n, 1)["xyz"][..., 2]
        sub = np.concatenate([pos, z[..., None]], -1).reshape(s, SUPERSAMPLE, s, SUPERSAMPLE, 3)
        sub = sub.transpose(0, 2, 1, 3, 4).reshape(s, s, m, 3)  # each pixel's points of the top
        # what of the part each pixel's area (spp samples) and each of its points (the position passes' rays)
        # sees: every surface a person sees counts, not only the top
        part = render_part(self._part, eye, view, s, spp)
        sub_part = render_part(self._part, eye, view, n, 1)

        def points(a: np.ndarray) -> np.ndarray:
            return a.reshape(s, SUPERSAMPLE, s, SUPERSAMPLE).transpose(0, 2, 1, 3).reshape(s, s, m) > 0.5

        # a point is on the top where the part pass says so: the top passes hold no other surface, so they
        # also 'see' the top behind a wall or the seat plate; a top point they miss leaves its pixel out
        on_top = points(sub_part.top) & np.isfinite(sub).all(-1)
        lost = points(sub_part.top) & ~np.isfinite(sub).all(-1)
        direct = (part.direct >= FULL_COVERAGE) & points(sub_part.direct).all(-1) & ~lost.any(-1)
        mirror = (part.reflected >= FULL_COVERAGE) & points(sub_part.reflected).all(-1) & ~lost.any(-1) & ~direct
        # a pixel on the part's outline can be seen fully by the coverage samples and still hold a sliver of
        # the table in the colour samples (read as stray): only pixels whose four neighbours see the part count
        core = binary_erosion(direct | mirror, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool))
        direct, mirror = direct & core, mirror & core
        ideal = np.broadcast_to(np.asarray(NOT_SAUCER_RGB, np.float32), r.rgb.shape).copy()
        in_frame = {"direct": np.zeros((s, s), bool), "mirror": np.zeros((s, s), bool)}
        for seen, kind, names in ((direct, "direct", ["direct"]),
                                  (mirror, "mirror", [v for v in self.scene.views if v != "direct"])):
            top = on_top[seen].reshape(-1)  # walls, base and seat plate lie in no frame: their ideal is the background
            pts = sub[seen].reshape(-1, 3)[top]
            colour = np.broadcast_to(self.backgrounds["direct" if kind == "direct" else "reflected"],
                                     (top.size, 3)).astype(np.float32)
            hit = np.zeros(top.size, bool)
            for name in names:
                cr, inside = self.maps.locate(name, pts)
                inside &= ~hit[top]  # the first frame that holds a point gives its colour
                if inside.any():
                    ref = self.references[name]
                    where = np.flatnonzero(top)[inside]
                    colour[where] = _sample(ref, cr[inside] * (ref.shape[0] / self.maps.size))
                    hit[where] = True
            ideal[seen] = colour.reshape(-1, m, 3).mean(axis=1)
            in_frame[kind][seen] = hit.reshape(-1, m).mean(axis=1) >= 0.5  # the pixel lies mostly in a frame
        width = width_share(in_frame["mirror"], self.scene.cup, eye, view)
        return score_whole_view(r.rgb, ideal, sampling_variance(r), direct, mirror, in_frame["direct"],
                                in_frame["mirror"], (self.backgrounds["direct"], self.backgrounds["reflected"]), width,
                                other=np.clip(part.direct + part.reflected - part.top, 0.0, 1.0))


def stray_map(wv: WholeView) -> np.ndarray:
    """(S, S, 3) float: the render in dim grey, stray pixels in colour, pixels that see no part flat grey."""
    grey = np.repeat(np.asarray(wv.rgb, np.float32).mean(axis=2, keepdims=True), 3, axis=2) * 0.5 + 0.25
    out = np.where((wv.direct | wv.mirror)[..., None], grey, np.asarray(NOT_SAUCER_RGB, np.float32))
    out[wv.stray & wv.direct] = STRAY_DIRECT_RGB
    out[wv.stray & wv.mirror] = STRAY_REFLECTED_RGB
    return out.astype(np.float32)
