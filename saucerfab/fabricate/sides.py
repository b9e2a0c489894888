"""The colour of every surface but the top: the background of the view each point is seen in.

The top carries the design's texture. The other surfaces of the part (the
saucer's walls, the base, the plate the cup stands on) carry no picture, but
a viewer sees them beside the pictures: directly (the walls, the plate around
the cup) and in the cup (the strip of plate in front of the cup shows in the
mirror just under the reflected picture). Each should read as the background
the design meant there (verify's whole view scores them so,
:mod:`saucerfab.verify.wholeview`): a point the cup shows the design eye takes
the reflected picture's background, every other point the direct picture's.

Most of the plate is seen both ways at once (beside the cup directly, and
near the cup's silhouette in the mirror), so a point is painted for the view
in which it looks larger (:func:`view_areas`: the image area of a small patch
around it, directly and in the cup): the cup's convex mirror shrinks what it
shows except for the strip in front of it, which the mirror spreads out under
the reflected picture while the eye sees it foreshortened. A reflection counts
where it is valid (:func:`saucerfab.model.mirror.reflect`: the mirror point T on the
part of the cup the eye sees, between its bottom and rim) and the surface
faces T; the saucer's top, which could hide a point from the cup, lies on
the far side of the points the cup shows, so no occlusion test is made.

The page's charts (:mod:`saucerfab.fabricate.atlas`) are painted texel by
texel, each texel classified at its own point (a plate of a few large
triangles is split where the mirror's view of it ends); formats with vertex
colours take the rule at each vertex.
"""

from __future__ import annotations

import numpy as np

from saucerfab.fabricate.atlas import UVMap
from saucerfab.fabricate.solid import Solid
from saucerfab.model.camera import Camera
from saucerfab.model.footprint import hidden_by_cup
from saucerfab.model.scene import Scene
from saucerfab.render.texels import raster_triangles_2d

#: the side of the small patch whose image areas decide a point's colour (model units: 0.1 mm at 100 mm a unit)
AREA_STEP = 1e-3
#: samples per side of the part's footprint when weighing the two surrounds (:func:`surround_sizes`)
BALANCE_SAMPLES = 96

#: texels of the gutter beside a painted chart texel painted too (bilinear filtering reaches one)
GUTTER_TEXELS = 2


def to_model(solid: Solid, points_mm: np.ndarray) -> np.ndarray:
    """(P, 3) file millimetres -> model units (the inverse of ``solid.model_to_file``)."""
    inv = np.linalg.inv(solid.model_to_file)
    p = np.asarray(points_mm, np.float64)
    return p @ inv[:3, :3].T + inv[:3, 3]


def _image_area(cam: Camera, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(P,) area in ``cam``'s NDC of the triangles (a, b, c), each (P, 3) model units."""
    pa, pb, pc = (cam.project(x)[:, :2] for x in (a, b, c))
    u, v = pb - pa, pc - pa
    return np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])


def view_areas(scene: Scene, points: np.ndarray, normals: np.ndarray,
               step: float = AREA_STEP) -> tuple[np.ndarray, np.ndarray]:
    """How large the design eye sees a small patch at each point, directly and in the cup.

    Args:
        points: (P, 3) model units. normals: (P, 3) the surface's outward normals there.
        step: the patch's side, model units.
    Returns:
        ``(direct, mirror)``, each (P,): the patch's image area in the design
        eye's direct camera's NDC (0 where the surface faces away from the eye
        or the cup hides it),
        and of its reflection, summed over the cup's pieces (0 where no piece
        reflects it validly or the surface faces away from the mirror point).
    """
    from saucerfab.model.mirror import reflect

    pts = np.asarray(points, np.float64)
    nrm = np.asarray(normals, np.float64)
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    # a tangent basis: any vector not along the normal, crossed twice
    helper = np.where(np.abs(nrm[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(nrm, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(nrm, e1)
    corners = (pts, pts + step * e1, pts + step * e2)
    cam = Camera.from_scene(scene, "direct")
    eye = np.asarray(scene.camera, np.float64)
    direct = _image_area(cam, *corners)
    direct[(np.einsum("ij,ij->i", eye - pts, nrm) <= 0) | hidden_by_cup(scene, pts)] = 0.0
    mirror = np.zeros(pts.shape[0])
    inside = np.asarray(scene.cup.contains(pts[:, :2]), bool)
    idx = np.flatnonzero(~inside)
    if idx.size == 0:
        return direct, mirror
    k = idx.size
    stacked = np.concatenate([c[idx] for c in corners])  # (3K, 3): each corner's reflection in one call
    for piece in reflect(scene, stacked[:, :2]):
        z = stacked[:, 2]
        ok = piece.valid(z, scene.cup.height)
        ok = ok[:k] & ok[k:2 * k] & ok[2 * k:]
        to_t = np.concatenate([piece.t_xy[:k] - pts[idx, :2], (piece.t_z(z)[:k] - pts[idx, 2])[:, None]], axis=1)
        ok &= np.einsum("ij,ij->i", to_t, nrm[idx]) > 0
        virtual = np.concatenate([piece.r_xy, z[:, None]], axis=1)
        area = _image_area(cam, virtual[:k], virtual[k:2 * k], virtual[2 * k:])
        mirror[idx[ok]] += area[ok]
    return direct, mirror


def surround_sizes(scene: Scene, footprint: np.ndarray, samples: int = BALANCE_SAMPLES) -> tuple[float, float]:
    """The image areas of the two surrounds a person judges: the part seen directly around the direct frame,
    and its image in the cup around the reflected frames (in the direct camera's NDC).

    Args:
        footprint: (2, 2) ``[[x0, x1], [y0, y1]]`` of the part, model units; sampled
            ``samples`` x ``samples`` as a flat floor facing up (the relief and the
            plate's few millimetres change the areas little).
    """
    (x0, x1), (y0, y1) = footprint
    gx, gy = np.meshgrid(np.linspace(x0, x1, samples), np.linspace(y0, y1, samples))
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    if scene.saucer.is_disc:  # a round part covers its disc, not the corners of its bounding square
        pts = pts[scene.saucer.on_saucer(pts[:, :2])]
    up = np.tile([0.0, 0.0, 1.0], (pts.shape[0], 1))
    direct, mirror = view_areas(scene, pts, up)
    cell = ((x1 - x0) / (samples - 1)) * ((y1 - y0) / (samples - 1)) / AREA_STEP**2
    cam = Camera.from_scene(scene, "direct")

    def picture(view: str) -> float:  # the picture's rectangle (its extent in its square view), in cam's NDC
        frame = getattr(scene, view)
        return 4.0 * frame.extent[0] * frame.extent[1] * (Camera.from_scene(scene, view).tan_angle / cam.tan_angle) ** 2

    frames_r = sum(picture(v) for v in ("reflected", "reflected2") if v == "reflected" or scene.reflected2 is not None)
    return max(float(direct.sum() * cell) - picture("direct"), 1e-12), max(float(mirror.sum() * cell) - frames_r, 1e-12)


def shown_by_cup(scene: Scene, points: np.ndarray, normals: np.ndarray, balance: float = 1.0) -> np.ndarray:
    """(P,) bool: these points (model units, surfaces facing ``normals``) take the cup's background.

    A point both views show is painted for the surround in which it weighs
    more: its image area in the cup over the mirror's surround against its
    area seen directly over the direct surround (``balance``: the mirror's
    surround over the direct one, :func:`surround_sizes`), as verify's stray
    shares weigh a pixel in each.
    """
    direct, mirror = view_areas(scene, points, normals)
    return mirror > direct * balance


def balance(solid: Solid, scene: Scene) -> float:
    """The mirror's surround over the direct one (:func:`surround_sizes`) over ``solid``'s footprint."""
    lo = to_model(solid, solid.vertices.min(axis=0, keepdims=True))[0]  # the whole part: saucer and plate
    hi = to_model(solid, solid.vertices.max(axis=0, keepdims=True))[0]
    d, m = surround_sizes(scene, np.array([[lo[0], hi[0]], [lo[1], hi[1]]]))
    return m / d


def face_normals(solid: Solid, faces: np.ndarray) -> np.ndarray:
    """(K, 3) unit outward normals of ``faces`` (K, 3) of ``solid`` (file frame = model directions)."""
    v = solid.vertices[faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def paint_sides(page: np.ndarray, solid: Solid, uvmap: UVMap, scene: Scene,
                mirror_rgb: tuple[int, int, int], weight: float) -> float:
    """Paint, in place, the texels of the page's charts (every face but the top) that the cup shows, ``mirror_rgb``.

    The rest of the charts keep the page's wall colour (the direct picture's
    background); the gutter beside a painted texel is painted too
    (:data:`GUTTER_TEXELS`), so filtering at a chart's edge does not mix the
    wall colour back in.

    Args:
        page: (S, S, 3) uint8 atlas page.
        weight: the two surrounds' balance, :func:`balance` of ``solid`` and ``scene``.
    Returns:
        The share (0..1) of the charts' texels painted.
    """
    side = np.flatnonzero(~solid.is_top)
    if side.size == 0:
        return 0.0
    s = page.shape[0]
    faces = solid.faces[side]
    uv = uvmap.uvs[uvmap.face_uvs[side]]  # (K, 3, 2)
    tri = np.stack([uv[..., 0] * s, (1.0 - uv[..., 1]) * s], axis=-1)
    pix, ti, bary = raster_triangles_2d(tri, s, s)
    if pix.size == 0:
        return 0.0
    corners = to_model(solid, solid.vertices[faces].reshape(-1, 3)).reshape(-1, 3, 3)
    points = np.einsum("kc,kcd->kd", bary, corners[ti])
    shown = shown_by_cup(scene, points, face_normals(solid, faces)[ti], weight)
    painted = np.zeros(s * s, bool)
    painted[pix[shown]] = True
    charts = np.zeros(s * s, bool)
    charts[pix] = True
    share = float(painted.sum() / max(charts.sum(), 1))
    if painted.any():
        from scipy import ndimage

        # into the gutter beside the painted texels (not into other charts): a texel filtered at a
        # chart's edge mixes in its neighbour outside, which should be the same colour
        grown = ndimage.binary_dilation(painted.reshape(s, s), iterations=GUTTER_TEXELS).reshape(-1)
        painted |= grown & ~charts
        page.reshape(-1, 3)[painted] = np.asarray(mirror_rgb, np.uint8)
    return share


def side_vertex_colours(vertex_rgb: np.ndarray, solid: Solid, scene: Scene, mirror_rgb: tuple[int, int, int],
                        weight: float) -> None:
    """Give, in place, the vertices of faces other than the top that the cup shows ``mirror_rgb`` (V, 3) uint8
    (``weight``: as :func:`paint_sides`'s).

    A vertex of the top keeps its colour. A vertex's normal is the mean of its
    side faces' normals (a corner of the plate faces up and out).
    """
    side = np.flatnonzero(~solid.is_top)
    if side.size == 0:
        return
    faces = solid.faces[side]
    nrm = np.zeros_like(solid.vertices, dtype=np.float64)
    fn = face_normals(solid, faces)
    for k in range(3):
        np.add.at(nrm, faces[:, k], fn)
    on_top = np.zeros(solid.vertices.shape[0], bool)
    on_top[solid.faces[solid.is_top].ravel()] = True
    vid = np.setdiff1d(np.unique(faces), np.flatnonzero(on_top))
    shown = shown_by_cup(scene, to_model(solid, solid.vertices[vid]), nrm[vid], weight)
    vertex_rgb[vid[shown]] = np.asarray(mirror_rgb, np.uint8)
