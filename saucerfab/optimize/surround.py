"""The whole view in the optimizer: the saucer around the frames, seen directly and in the cup.

The paper's views are the two frames: its energy never looks at the saucer
outside the direct frame, nor at the mirror's image of the saucer outside the
reflected frame, so whatever the method leaves there is what a person sees
around the pictures: the direct picture stretched up the cup above the
reflected one (the "tower" of a heart above a star), the reflected picture's
colours in specks on the saucer. ``saucerfab verify`` measures it (the whole
view, :mod:`saucerfab.verify.wholeview`); this module lets the optimizer see it.

For each frame view (``direct``, ``reflected``, ``reflected2``) a **whole
view** (:class:`WholeView`) renders the same mesh through a camera from the
same eye that takes in all of it (the view's bounding square, a little
margin), at about half the frame's pixel density (:data:`WHOLE_PIXEL_SCALE`) and at most
:data:`MAX_WHOLE_SIZE` pixels a side (at the default 512 px frames, a whole-view pixel spans
about three frame pixels).
Its **target** is the ideal whole view, blur-matched as the frames' targets
are (:mod:`saucerfab.optimize.targets`): the base shape coloured with the
picture where a face's centre lies inside the frame and with the view's
**background** elsewhere, soft-rendered at the stage's sigma. Its energy,
``E_surround``, is the squared distance to that target over the pixels
*outside* the frame only (inside, the frame's own E_visual scores), each
pixel weighted by its area in frame pixels (the square's padding around a
non-square picture is surround too; its E_visual scores only the picture's
rectangle), so ``surround_weight = 1``
(the default) counts a square millimetre around a picture as much as one
inside it.

The background of a view is what :func:`saucerfab.imaging.images.intended_background`
says of the picture the stage aims at: the design's ``--background``, else
the one ground :func:`saucerfab.imaging.images.piece_ground` chose where the
pictures' border colours differ, else the picture's border colour (for the
black-white enhanced targets, their own background). With it in the energy the conflict reduction also hides each
picture from the other view's surround: the slopes that show the direct
picture turn away from the cup where the cup would show them outside the
reflected frame, as they do inside it.

The texture follows (:func:`surround_faces`): a face seen in a whole view
but in no frame takes its view's background, not the picture's edge
continued (the smeared bands beside a photograph).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.model.camera import Camera
from saucerfab.optimize.views import BACKGROUND, ViewMesh, ViewMeshes, frame_extent

if TYPE_CHECKING:
    import torch

#: a whole view's pixel spans this many of its frame's pixels across (the surround needs no
#: finer detail than its background; coarser keeps the extra renders cheap)
WHOLE_PIXEL_SCALE = 2.0
#: the whole view's square reaches this factor past the view's bounding square (the soft
#: rasterizer's blur at the saucer's outline stays inside the image)
WHOLE_MARGIN = 1.04
#: faces further than this many whole-view pixels inside the frame are left out of the whole view
#: (the soft rasterizer's blur at the large sigma reaches about 2 pixels)
INNER_MARGIN_PX = 3.0
#: whole views no larger than this many pixels a side (at the default 512 px frames every whole
#: view reaches it: 256 px costs 0.066 s an iteration's render and gradient against 0.108 s at 384,
#: with a whole-view pixel still under a millimetre of the 185 mm saucer)
MAX_WHOLE_SIZE = 256


def whole_camera(frame: Camera, points: np.ndarray) -> Camera:
    """A camera from ``frame``'s eye whose square takes in every point of ``points`` (P, 3).

    Its pixels are :data:`WHOLE_PIXEL_SCALE` of ``frame``'s across (at most
    :data:`MAX_WHOLE_SIZE` a side), so its size follows the view's extent.
    """
    from saucerfab.optimize.framing import refit_frame

    covering = refit_frame(frame, points, "cover")
    angle = math.degrees(math.atan(math.tan(math.radians(covering.viewing_angle_deg)) * WHOLE_MARGIN))
    ratio = math.tan(math.radians(angle)) / frame.tan_angle  # whole width over frame width
    size = int(min(MAX_WHOLE_SIZE, max(16, math.ceil(frame.image_size * ratio / WHOLE_PIXEL_SCALE))))
    return Camera(frame.eye, covering.target, angle, size)


def outside_weights(whole: Camera, frame: Camera, extent: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(S, S) float64: each whole-view pixel's area in ``frame`` pixels, 0 where its centre is inside the picture.

    Both cameras share the eye, so a pixel's ray lies inside the picture when it
    projects into the picture's rectangle ``|x| <= ex, |y| <= ey`` of the frame's NDC
    (``extent``; the square's padding around a non-square picture is surround).
    """
    eye, d = whole.rays()
    ndc = frame.project(np.asarray(eye) + d)
    inside = (np.abs(ndc[..., 0]) <= extent[0]) & (np.abs(ndc[..., 1]) <= extent[1]) & (ndc[..., 2] > 0)
    # pixel area ratio at the axis (the two fields of view are a few degrees apart: the
    # projection's own stretch across them differs by well under 1 %)
    area = ((2 * whole.tan_angle / whole.image_size) / (2 * frame.tan_angle / frame.image_size)) ** 2
    return np.where(inside, 0.0, area)


def inside_frame(view: ViewMesh, heights: np.ndarray, extent: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(F',) bool: the view's faces whose centre lies inside its picture (the rectangle ``extent`` of its square)."""
    faces = np.asarray(view.faces)
    if faces.shape[0] == 0:
        return np.zeros(0, bool)
    ndc = view.camera.project(view.vertices_np(heights))
    cen = ndc[faces].mean(axis=1)
    return (np.abs(cen[:, 0]) <= extent[0]) & (np.abs(cen[:, 1]) <= extent[1]) & (cen[:, 2] > 0)


@dataclass
class WholeView:
    """One frame view's whole view.

    Attributes:
        frame: the frame view (a :class:`~saucerfab.optimize.views.ViewMesh` or ``View``).
        camera: the whole view's camera (:func:`whole_camera`).
        weights: (S, S) float64 pixel weights, :func:`outside_weights`.
        extent: the frame's picture rectangle in its square (:attr:`saucerfab.model.scene.ViewFrame.extent`).
    """

    frame: Any
    camera: Camera
    weights: np.ndarray
    extent: tuple[float, float] = (1.0, 1.0)
    _weights_t: Any = field(default=None, repr=False)

    @property
    def name(self) -> str:
        return str(self.frame.name)

    def render(self, h: torch.Tensor, c: torch.Tensor, sigma: float) -> torch.Tensor:
        """(S, S, 3) soft render of the view's mesh through the whole camera, differentiable in h and c."""
        from saucerfab.render import soft_rasterize

        img, _ = soft_rasterize(self.frame.vertices(h), self.frame.faces, self.frame.colors(c), self.camera,
                                sigma=sigma, background=BACKGROUND)
        return img

    def energy(self, rendered: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The weighted squared distance outside the frame (0-d, float64)."""
        import torch

        if self._weights_t is None:
            self._weights_t = torch.as_tensor(self.weights, dtype=rendered.dtype).unsqueeze(-1)
        return (((rendered - target) ** 2) * self._weights_t).sum(dtype=torch.float64)


def whole_views(rig: ViewMeshes, heights: np.ndarray) -> list[WholeView]:
    """A :class:`WholeView` per frame view of ``rig`` (views with no faces left out), at ``heights`` (N, N).

    Each keeps the frame view's faces but those lying wholly inside the frame,
    more than :data:`INNER_MARGIN_PX` whole-view pixels from its edge: they
    cover only pixels of weight 0 (the frame's own), and leaving them out
    saves their share of every render.
    """
    h = np.asarray(heights, np.float64).reshape(-1)
    out = []
    for view in rig.views:
        faces = np.asarray(view.faces)
        if faces.shape[0] == 0:
            continue
        verts = view.vertices_np(h)
        cam = whole_camera(view.camera, verts[np.unique(faces)])
        margin = INNER_MARGIN_PX * (2 * cam.tan_angle / cam.image_size) / view.camera.tan_angle  # frame NDC
        extent = frame_extent(rig.scene, view.name)
        ndc = view.camera.project(verts)
        inner = (np.abs(ndc[:, :2]) < np.asarray(extent) - margin).all(axis=1) & (ndc[:, 2] > 0)
        keep = ~inner[faces].all(axis=1)
        mesh = ViewMesh(view.name, view.camera, np.asarray(view.xy), np.asarray(view.vert_src), faces[keep],
                        np.asarray(view.face_src)[keep], mirror=view.mirror)
        out.append(WholeView(rig.as_view(mesh), cam, outside_weights(cam, view.camera, extent), extent))
    return out


def ideal_colors(view: ViewMesh, heights: np.ndarray, picture: np.ndarray, background: np.ndarray,
                 num_faces: int, extent: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(F, 3) saucer face colours of the ideal whole view: ``picture`` projected inside the frame, ``background`` outside.

    Indexed by saucer face as :func:`~saucerfab.optimize.targets.project_colors`;
    a face the view does not take gets the background too.
    """
    from saucerfab.optimize.targets import project_colors

    bg = np.asarray(background, np.float64)
    cols = project_colors(view, heights, picture, num_faces, fill=tuple(bg))
    src = np.asarray(view.face_src)
    outside = src[~inside_frame(view, heights, extent)]
    cols[outside] = bg
    return cols


def whole_targets(wholes: list[WholeView], heights: np.ndarray, pictures: dict[str, np.ndarray],
                  backgrounds: dict[str, np.ndarray], sigma: float, num_faces: int, *,
                  dtype: torch.dtype | None = None) -> list[torch.Tensor]:
    """The blur-matched ideal whole view of each of ``wholes`` (a list of (S, S, 3) tensors, in order).

    Args:
        heights: (N, N) base heights.
        pictures: view name -> (S, S, 3) picture the stage aims at, in [0, 1].
        backgrounds: view name -> (3,) background colour in [0, 1].
    """
    import torch

    dtype = dtype or torch.float32
    h = torch.as_tensor(np.asarray(heights).reshape(-1), dtype=dtype)
    out = []
    for whole in wholes:
        cols = ideal_colors(whole.frame, heights, pictures[whole.name], backgrounds[whole.name], num_faces,
                            whole.extent)
        with torch.no_grad():
            out.append(whole.render(h, torch.as_tensor(cols, dtype=dtype), sigma))
    return out


def backgrounds_of(pictures: dict[str, np.ndarray], background: Any = None) -> dict[str, np.ndarray]:
    """View name -> (3,) the background meant around each picture (:func:`saucerfab.imaging.images.intended_background`)."""
    from saucerfab.imaging.images import intended_background

    return {name: np.asarray(intended_background(np.asarray(img, np.float64), background), np.float64)
            for name, img in pictures.items()}


def surround_faces(rig: ViewMeshes, wholes: list[WholeView], heights: np.ndarray,
                   framed: np.ndarray, supersample: int = 2) -> dict[str, np.ndarray]:
    """Per frame view, (F,) bool: saucer faces its whole view shows outside every frame.

    A face counts for the first view (in the rig's order: direct, then the
    reflections) that sees it; ``framed`` (F,) marks the faces some frame sees,
    which keep the frames' texturing.
    """
    from saucerfab.render import rasterize_hard

    h = np.asarray(heights, np.float64).reshape(-1)
    taken = np.asarray(framed, bool).copy()
    out: dict[str, np.ndarray] = {}
    for whole in wholes:
        cam = whole.camera.with_size(whole.camera.image_size * supersample)
        fid, _, _ = rasterize_hard(whole.frame.vertices_np(h), np.asarray(whole.frame.faces), cam)
        hit = np.zeros(np.asarray(whole.frame.faces).shape[0], bool)
        hit[fid[fid >= 0]] = True
        seen = np.zeros(rig.num_faces, bool)
        seen[np.asarray(whole.frame.face_src)[hit]] = True
        mine = seen & ~taken
        taken |= mine
        out[whole.name] = mine
    return out


class Surround:
    """The whole view of one design: its whole views, their targets per stage, its energy and its texture colours.

    Args:
        rig: the design eye's views.
        prep: the prepared run (its base heights, pictures and enhanced targets).
        background: the design's ground (``Prepared.ground``: its ``--background`` or the one ground
            chosen for it; None: each picture's border colour).
    """

    def __init__(self, rig: Any, prep: Any, background: str | None) -> None:
        self.rig, self.prep, self.background = rig, prep, background
        self.wholes = whole_views(rig, prep.base)
        self._targets: dict[tuple[str, float], list[Any]] = {}

    def targets_for(self, kind: str, sigma: float) -> list[Any]:
        """The ideal whole view of each whole view, blur-matched (:func:`whole_targets`), made once per (kind, sigma).

        Outside the frames each aims at its picture's background: the design's ``--background`` for
        the pictures as they are (``kind`` "render"), the enhanced picture's own for the enhanced targets.
        """
        key = (kind, sigma)
        if key not in self._targets:
            pictures = self.prep.enhanced if kind == "enhanced" else self.prep.render
            backgrounds = backgrounds_of(pictures, None if kind == "enhanced" else self.background)
            self._targets[key] = whole_targets(self.wholes, self.prep.base, pictures, backgrounds, sigma,
                                               self.rig.num_faces)
        return self._targets[key]

    def energy(self, h: torch.Tensor, c: torch.Tensor, kind: str, sigma: float) -> torch.Tensor:
        """E_surround (0-d float64): the whole views' weighted squared distance to their targets outside the frames."""
        total = None
        for whole, target in zip(self.wholes, self.targets_for(kind, sigma), strict=True):
            e = whole.energy(whole.render(h, c, sigma), target)
            total = e if total is None else total + e
        if total is None:
            import torch

            return h.new_zeros((), dtype=torch.float64)
        return total

    def texture_colours(self, heights: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """The faces the design eye sees outside every frame at ``heights`` (N, N), with their view's
        background (the texture's ``surround``: :func:`saucerfab.optimize.texturing.texture_saucer`)."""
        visible = self.rig.visible_faces(heights)
        framed = np.logical_or.reduce([visible[v.name] for v in self.rig.views])
        faces = surround_faces(self.rig, self.wholes, heights, framed)
        backgrounds = backgrounds_of(self.prep.texture, self.background)
        if self.rig.scene.saucer.is_disc and "direct" in faces:
            # the rest of a disc (behind the cup, under its seat, the grid's corners the export cuts away)
            # stays plain: the direct picture's background, never a smear of the pictures
            faces["direct"] = faces["direct"] | ~np.logical_or.reduce([framed, *faces.values()])
        return [(faces[w.name], backgrounds[w.name]) for w in self.wholes]
