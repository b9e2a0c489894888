"""Fitting the view frames to where the saucer actually appears.

With the paper's preset the direct frame reaches past the saucer's far edge
(its top third shows the cup's foot, not the saucer) and the saucer's
reflection fills only about half of the reflected frame's width, so parts of
the input images fall where no saucer can show them. ``fit_frames`` keeps the
camera and re-aims each frame at the region the saucer covers in it:

Each frame holds its picture at the picture's own aspect (a wide word gets a
wide frame): a rectangle of that aspect, centred in the square view, whose
``extent`` the scene records (:class:`saucerfab.model.scene.ViewFrame`); the rest of
the square is the picture's background.

* ``"contain"``: the largest such rectangle inside the region's bounding box,
  so the whole input image lands on the saucer (or its reflection);
* ``"cover"``: the smallest one containing the region, so the whole
  saucer is used and the image's margins fall off it;
* ``"inscribed"``: the largest one inside the region itself (not its
  bounding box): the saucer's reflection in a round cup is a curved
  trapezoid, so ``contain`` leaves the frame's corners off it (verify: 72 %
  of the reflected frame covered) while this frame lies wholly on it, at the
  price of a smaller picture. The mirror's image of the saucer is a wide,
  short band, so a wide picture is shown much wider than a square one.

``"inscribed"`` is the default of a design (``DesignRequest.frames``):
measured with ``saucerfab verify`` it shows each whole picture (100 % of
both frames on the saucer and its reflection), where ``contain`` loses the
reflected frame's corners (72 %) and the paper's preset (``frames="scene"``,
still available) shows 66 % of the direct and 31 % of the reflected frame
(benchmarks/results/HISTORY.md, "Verify (issue 13)" and "Default path (issue 14, in part)").
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.model.camera import Camera
from saucerfab.model.footprint import design_vertices, direct_vertices
from saucerfab.model.heightfield import make_grid
from saucerfab.model.scene import Scene, ViewFrame
from saucerfab.optimize.request import FRAMES

#: the frames this module fits (the request's choices but "scene", which keeps the scene's own)
FITTED_FRAMES = tuple(m for m in FRAMES if m != "scene")

#: cells across the region's bounding box when finding the largest square inside it ("inscribed")
INSCRIBED_CELLS = 160
#: a picture whose frame has less than this share of the area a square picture's frame gets is
#: said to fit small (a very wide or tall picture in the mirror's short band)
SMALL_FIT_SHARE = 0.5


def largest_inscribed_square(xy: np.ndarray, cells: int = INSCRIBED_CELLS,
                             centre_x: float | None = None) -> tuple[np.ndarray, float]:
    """Centre (2,) and half side of the largest axis-aligned square inside a region.

    The region is given by points dense in it (the projected saucer
    vertices): they are splatted onto a square grid over their bounding box,
    gaps closed, holes filled, and the result shrunk by one cell so the
    square stays strictly inside; the largest all-inside square of cells is
    found by the usual dynamic programme. With ``centre_x`` the square is
    centred on that x (:func:`_largest_centred_square`).
    """
    from scipy import ndimage

    # no finer than the points are dense: about one point per cell of the bounding box side
    cells = max(8, min(cells, int(0.8 * math.sqrt(len(xy)))))
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    cell = float((hi - lo).max()) / cells
    n = np.floor((hi - lo) / cell).astype(int) + 1
    ij = np.minimum(np.floor((xy - lo) / cell).astype(int), n - 1)
    occ = np.zeros((n[1], n[0]), bool)  # [row = y cell, column = x cell]
    occ[ij[:, 1], ij[:, 0]] = True
    occ = ndimage.binary_closing(np.pad(occ, 3), structure=np.ones((3, 3)), iterations=2)[3:-3, 3:-3]
    occ = ndimage.binary_erosion(ndimage.binary_fill_holes(occ))
    if centre_x is not None:
        return _largest_centred_square(occ, lo, cell, float(centre_x))
    # dp[i, j]: side of the largest all-inside square whose bottom-right cell is (i, j)
    dp = np.zeros((n[1] + 1, n[0] + 1), np.int64)
    for i in range(n[1]):
        for j in range(n[0]):
            if occ[i, j]:
                dp[i + 1, j + 1] = 1 + min(dp[i, j], dp[i, j + 1], dp[i + 1, j])
    best = int(dp.max())
    if best == 0:
        raise ConfigError("the saucer's region in a view is too small to fit a frame in; move the saucer or the camera")
    # of the squares that size, the one nearest the region's centroid (a symmetric region keeps its axis)
    ends = np.argwhere(dp[1:, 1:] == best)  # (row, column) of each square's last cell
    centres = ends[:, ::-1] + 1 - best / 2  # (x, y) in cells
    centroid = np.argwhere(occ)[:, ::-1].mean(axis=0) + 0.5
    k = int(np.argmin(((centres - centroid) ** 2).sum(axis=1)))
    return lo + cell * centres[k], best * cell / 2


def _largest_centred_square(occ: np.ndarray, lo: np.ndarray, cell: float, centre_x: float) -> tuple[np.ndarray, float]:
    """The largest square of all-inside cells of ``occ`` (rows y, columns x) centred on ``centre_x``.

    Its columns are the ``side`` cells nearest the centre line; the rows are
    scanned with a summed-area table, largest size first; of the
    positions that size the one nearest the region's centroid in y is kept.
    """
    rows, cols = occ.shape
    sat = np.zeros((rows + 1, cols + 1), np.int64)
    sat[1:, 1:] = np.cumsum(np.cumsum(occ, axis=0), axis=1)
    c = (centre_x - float(lo[0])) / cell  # the centre line, in cells from the box's left edge
    centroid_y = float(np.argwhere(occ)[:, 0].mean()) + 0.5 if occ.any() else 0.0
    for side in range(min(rows, cols), 0, -1):  # largest first
        j0 = int(round(c - side / 2))
        j1 = j0 + side
        if j0 < 0 or j1 > cols:
            continue
        i = np.arange(rows - side + 1)
        full = (sat[i + side, j1] - sat[i, j1] - sat[i + side, j0] + sat[i, j0]) == side * side
        if full.any():
            starts = i[full]
            k = int(np.argmin(np.abs(starts + side / 2 - centroid_y)))
            centre = np.array([j0 + side / 2, starts[k] + side / 2])
            return lo + cell * centre, side * cell / 2
    raise ConfigError("the saucer's region in a view is too small to fit a frame in on the cup's axis; "
                      "move the saucer or the camera")


def largest_inscribed_rectangle(xy: np.ndarray, aspect: float = 1.0, cells: int = INSCRIBED_CELLS,
                                centre_x: float | None = None) -> tuple[np.ndarray, float, float]:
    """Centre (2,), half width and half height of the largest axis-aligned rectangle of ``aspect``
    (width over height) inside the region of the points ``xy`` (P, 2), centred on ``centre_x`` if given.

    The square of :func:`largest_inscribed_square` in coordinates whose x is
    divided by ``aspect``: a square there is a rectangle of that aspect here.
    """
    scaled = np.asarray(xy, np.float64) / np.array([aspect, 1.0])
    centre, half = largest_inscribed_square(scaled, cells, None if centre_x is None else centre_x / aspect)
    return centre * np.array([aspect, 1.0]), half * aspect, half


def refit_frame(cam: Camera, points: np.ndarray, mode: str, aspect: float = 1.0,
                axis: np.ndarray | None = None) -> ViewFrame:
    """``cam``'s frame re-aimed from the same eye at ``points`` (P, 3): its picture, a rectangle of
    ``aspect`` (width over height), "inscribed" in the points' region, "contain"-ed in their
    bounding box or "cover"-ing it; the square view holds the rectangle, its ``extent`` says where.

    ``axis`` (3,), a point in model units: an inscribed rectangle is centred on it left to right (a
    round saucer's pictures stand on the cup's axis, in front of it and in its middle, not off
    to one side where the region between saucer and cup happens to be widest)."""
    eye = np.asarray(cam.eye, np.float64)
    frame_cam = cam
    hw = hh = 1.0
    for _ in range(3):  # the re-aimed axis changes the perspective slightly; iterate
        ndc = frame_cam.project(points)
        lo, hi = ndc[:, :2].min(axis=0), ndc[:, :2].max(axis=0)
        if mode == "inscribed":
            cx = None if axis is None else float(frame_cam.project(np.asarray(axis, np.float64)[None])[0, 0])
            centre, hw, hh = largest_inscribed_rectangle(ndc[:, :2], aspect, centre_x=cx)
        else:
            centre = (lo + hi) / 2
            half = (hi - lo) / 2
            # the rectangle of the aspect inside (contain) or around (cover) the bounding box
            hh = float(min(half[1], half[0] / aspect) if mode == "contain" else max(half[1], half[0] / aspect))
            hw = aspect * hh
        side = max(hw, hh)
        r = frame_cam.axes()
        w = frame_cam.tan_angle
        d = r[2] + centre[0] * w * r[0] + centre[1] * w * r[1]
        d /= np.linalg.norm(d)
        dist = float(np.linalg.norm(np.asarray(frame_cam.target) - eye))
        target = tuple(float(v) for v in eye + d * dist)
        angle = math.degrees(math.atan(w * side))
        frame_cam = Camera(cam.eye, target, angle, cam.image_size)
    side = max(hw, hh)
    extent = (min(1.0, hw / side), min(1.0, hh / side))
    return ViewFrame(frame_cam.target, frame_cam.viewing_angle_deg, cam.image_size, extent)


def fit_frames(
    scene: Scene, heights: np.ndarray, mode: str = "contain", groups: list[list[int]] | None = None,
    aspects: dict[str, float] | None = None,
) -> Scene:
    """A copy of ``scene`` whose frames are fitted to the saucer and its reflection.

    Args:
        heights: (N, N) base heights (the region barely depends on them).
        mode: "inscribed", "contain" or "cover" (see the module docstring).
        groups: prism facet groups of two reflected images: the reflected
            frame is fitted to the first group's region, ``reflected2`` to the second.
        aspects: view name -> its picture's width over height (default 1: a square).
    """
    aspects = aspects or {}
    from saucerfab.model.mirror import reflect

    if mode not in FITTED_FRAMES:
        raise ConfigError(f"frames mode must be one of {', '.join(FITTED_FRAMES)}, got {mode!r}")
    grid = make_grid(scene.saucer)
    h = np.asarray(heights, np.float64).reshape(-1)
    verts = grid.vertices(h)
    # the design's vertices only (a disc: on it, clear of the cup; directly: not behind the cup)
    seen = direct_vertices(scene, verts)
    axis = np.zeros(3) if scene.saucer.is_disc else None  # the cup's axis (its bottom's centre)
    direct = refit_frame(Camera.from_scene(scene, "direct"), verts[seen], mode, aspects.get("direct", 1.0), axis)
    on = design_vertices(scene, grid.xy())
    pieces = reflect(scene, grid.xy())

    def region(facets: list[int] | None) -> np.ndarray:
        pts = [
            p.reflected_vertices(h)[p.valid(h, scene.cup.height) & on]
            for p in pieces
            if facets is None or p.facet in facets
        ]
        allp = np.concatenate(pts) if pts else np.zeros((0, 3))
        if allp.shape[0] < 3:
            raise ConfigError("no part of the saucer is seen in the cup; move the saucer or the camera")
        return allp

    cam_r = Camera.from_scene(scene, "reflected")
    a_r = aspects.get("reflected", 1.0)
    if groups is None:
        return replace(scene, direct=direct, reflected=refit_frame(cam_r, region(None), mode, a_r, axis))
    return replace(
        scene,
        direct=direct,
        # two reflections, each in its own facets' region to one side of the axis: not centred on it
        reflected=refit_frame(cam_r, region(groups[0]), mode, a_r),
        reflected2=refit_frame(cam_r, region(groups[1]), mode, aspects.get("reflected2", 1.0)),
    )


def frame_area(frame: ViewFrame) -> float:
    """The picture's area in its view, in squared tangents of the view angle (solid angle, near the axis)."""
    t = math.tan(math.radians(frame.viewing_angle_deg))
    return 4.0 * t * t * frame.extent[0] * frame.extent[1]


def frame_notes(square: Scene, fitted: Scene, aspects: dict[str, float]) -> list[str]:
    """What to tell a designer whose picture's shape fits its view small: one line per such view.

    Args:
        square: the scene with square frames fitted. fitted: with the pictures' aspects.
        aspects: view name -> the picture's width over height.
    """
    out = []
    for name, aspect in aspects.items():
        a, b = getattr(square, name, None), getattr(fitted, name, None)
        if a is None or b is None or abs(aspect - 1.0) < 1e-6:
            continue
        share = frame_area(b) / frame_area(a)
        if share < SMALL_FIT_SHARE:
            shape = f"{aspect:.1f}:1" if aspect >= 1 else f"1:{1 / aspect:.1f}"
            out.append(
                f"the {name} picture is {shape}: the largest frame of that shape where the view sees the saucer "
                f"has {share:.0%} of the area a square picture's would; it is shown whole at that size "
                "(a less elongated picture, or --fit crop, shows larger)"
            )
    return out
