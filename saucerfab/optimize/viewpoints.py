"""The eyes a design is made for (``saucerfab design --eyes``): a view rig per eye, and what each eye should see.

The eyes are :mod:`saucerfab.model.eyes`'s, the ones ``saucerfab verify`` renders
from: the design eye (the scene's camera), and with ``both`` a viewer's two
eyes ``ipd_mm`` apart along the direct view's right axis, with ``box`` a grid.
Each eye is the design's scene with the camera moved there and the view
frames unchanged (same targets, same angles: verify's frames of a moved
eye), and has its own :class:`~saucerfab.optimize.views.Rig`: its direct
view, and its own reflected shape (the mirror's reflection point T depends
on the eye, so the reflected xy of every saucer vertex is computed per eye).

**What a moved eye should see** (its targets). A moved eye looking at the
same frame target sees the saucer shifted in its image (the saucer lies in
front of the direct frame's target, so it moves by parallax: about 16 px at
256 px for 32 mm). Asking a moved eye to see the picture at the same place
in its own frame (the design frame with the camera moved) would ask for that
shift, which no print can give both the design eye and a moved eye. What a
viewer sees of a good print is the picture lying flat on the saucer like a
decal: so a moved eye's target is the picture as the design eye puts it on
the saucer's mean plane (the decal), seen from the moved eye: what verify
compares a moved eye with too (its flat print, ray-traced from the files:
``saucerfab/verify/flatprint.py``), and what a print could give every eye at
once if the saucer were flat; the relief's parallax (points at different depths
along a ray move apart) is what is left for the optimizer to weigh.

:func:`design_frame_ndc` gives, for each vertex of an eye's view, where in the
design eye's frame of that view the decal point it sees lies (for a mirror
view: the ray from the eye to the vertex's virtual point meets the virtual
mean plane, is mirrored back across the cup's tangent at T to the real
plane, and that saucer point's virtual point from the design eye is
projected into the design frame). :func:`decal_images` renders each eye's
pictures from it; the optimizer blur-matches them like the design eye's
(:func:`saucerfab.optimize.targets.blur_matched_targets`), and the texturing
step samples the pictures with it (:class:`saucerfab.optimize.texturing.EyeViews`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from saucerfab.model.camera import Camera
from saucerfab.model.eyes import Eye, EyeSpec, eye_positions, eye_weights
from saucerfab.model.scene import Scene
from saucerfab.optimize.views import BACKGROUND, ViewMesh, ViewMeshes

#: a moved eye's views are rendered at this share of the design eye's image size: the optimizer's
#: cost per moved eye falls about fourfold (--eyes both: about 1.5x the design eye's time per
#: iteration rather than 3x), and what a moved eye must see (the picture's shapes, not its finest
#: detail: verify scores it at 256 px) survives; its E_visual is scaled back by the pixel-area ratio
EYE_IMAGE_SCALE = 0.5


@dataclass
class EyeRig:
    """One eye of a design: its scene (the camera moved there) and its views.

    Attributes:
        eye: name, position (model units) and offset (mm) from the design eye.
        weight: its share of E_visual and of the texture blend (:func:`saucerfab.model.eyes.eye_weights`).
        scene: the design's scene seen from this eye (the frames unchanged).
        rig: its views (a :class:`~saucerfab.optimize.views.Rig`, or the numpy
            :class:`~saucerfab.optimize.views.ViewMeshes`).
    """

    eye: Eye
    weight: float
    scene: Scene
    rig: Any

    @property
    def area_factor(self) -> float:
        """(design image size / this eye's)^2: E_visual of this eye's smaller renders in the design eye's pixels."""
        s_d = self.scene.direct.image_size
        s_e = self.rig.views[0].camera.image_size
        return float(s_d * s_d) / float(s_e * s_e)


def eye_scenes(scene: Scene, spec: EyeSpec) -> list[tuple[Eye, float, Scene]]:
    """(eye, weight, scene from that eye) for every eye of ``spec``, the design eye first.

    Offsets are millimetres at the scene's scale (``scene.mm_per_unit``); the
    design eye's scene is ``scene`` itself.
    """
    eyes = eye_positions(spec, scene.camera, scene.direct.target, scene.mm_per_unit)
    out = []
    for eye, w in zip(eyes, eye_weights(eyes), strict=True):
        out.append((eye, w, scene if eye.name == "design" else replace(scene, camera=eye.position)))
    return out


def eye_rigs(
    scene: Scene,
    base: np.ndarray,
    spec: EyeSpec,
    reflected_groups: list[list[int]] | None = None,
    *,
    rig_class: type = ViewMeshes,
    design_rig: Any = None,
    image_scale: float = EYE_IMAGE_SCALE,
) -> list[EyeRig]:
    """A rig per eye (the design eye first, ``design_rig`` when given), each built on ``base``.

    The moved eyes render at ``image_scale`` times the design eye's image size (:data:`EYE_IMAGE_SCALE`).
    """
    out = []
    size = max(16, int(round(scene.direct.image_size * image_scale)))
    for eye, w, sc in eye_scenes(scene, spec):
        if eye.name == "design":
            rig = design_rig if design_rig is not None else rig_class(sc, base, reflected_groups=reflected_groups)
        else:
            rig = rig_class(sc, base, image_size=size, reflected_groups=reflected_groups)
        out.append(EyeRig(eye, w, sc, rig))
    return out


def decal_height(base: np.ndarray) -> float:
    """The height of the plane a moved eye's pictures lie on: the base shape's mean, model units."""
    return float(np.mean(base))


def design_frame_ndc(design: Scene, eye_scene: Scene, view: ViewMesh, heights: np.ndarray, z0: float) -> np.ndarray:
    """(V', 2) where each vertex of an eye's ``view`` shows the picture: NDC in the design eye's frame.

    The ray from the eye through the vertex (through its virtual point, for a
    mirror view) meets the plane ``z = z0``; that point of the decal is
    projected into the design eye's frame of the view (for a mirror view:
    mirrored back across the cup's tangent at T to the real plane, then seen
    in the mirror from the design eye; where the design eye does not see it
    in the same mirror piece, the eye's own virtual point stands in). For
    the design eye itself this is the vertex's own projection.

    Args:
        design: the design's scene. eye_scene: the same scene from the eye.
        view: a view of the eye's rig (its ``mirror`` set for a mirror view).
        heights: (N, N) or (V,) saucer heights, model units. z0: the decal's plane.
    """
    from saucerfab.model.mirror import reflect

    verts = view.vertices_np(heights)
    cam = Camera.from_scene(design, view.name)
    if verts.shape[0] == 0:
        return np.zeros((0, 2))
    e = np.asarray(eye_scene.camera, np.float64)
    dz = verts[:, 2] - e[2]
    dz = np.where(np.abs(dz) < 1e-12, -1e-12, dz)
    t = (z0 - e[2]) / dz
    p = e + t[:, None] * (verts - e)
    if view.mirror is None:
        return cam.project(p)[:, :2]
    m = np.asarray(view.mirror, np.float64)
    tp, n, facet = m[:, :2], m[:, 2:4], m[:, 4]
    q = p[:, :2] - 2.0 * ((p[:, :2] - tp) * n).sum(axis=1, keepdims=True) * n
    r = p[:, :2].copy()
    for piece in reflect(design, q):
        ok = piece.valid_xy & (facet == piece.facet)
        r[ok] = piece.r_xy[ok]
    return cam.project(np.concatenate([r, np.full((r.shape[0], 1), z0)], axis=1))[:, :2]


def decal_images(
    design: Scene, eye: EyeRig, heights: np.ndarray, images: dict[str, np.ndarray], z0: float, size: int | None = None
) -> dict[str, np.ndarray]:
    """Each view's picture as the eye should see it (the decal on the plane ``z0``), ``size`` px a side.

    Rendered on ``heights`` (the rays through its faces, not its colours,
    matter); where no saucer is seen, the renderer's background.

    Args:
        images: view name -> (T, T, 3) picture in [0, 1] covering the design frame.
        size: the images' side (default: each view's render size).
    """
    from saucerfab.optimize.targets import sample_bilinear
    from saucerfab.render import rasterize_hard

    out = {}
    for view in eye.rig.views:
        img = np.asarray(images[view.name], np.float64)
        s = size or view.camera.image_size
        pic = np.empty((s, s, 3))
        pic[:] = BACKGROUND
        faces = np.asarray(view.faces)
        if faces.shape[0]:
            coords = design_frame_ndc(design, eye.scene, view, heights, z0)
            fid, bary, _ = rasterize_hard(view.vertices_np(heights), faces, view.camera.with_size(s))
            hit = fid >= 0
            ndc = np.einsum("kc,kcd->kd", bary[hit], coords[faces[fid[hit]]])
            t = img.shape[0]
            px = np.stack([(ndc[:, 0] + 1) * t / 2, (1 - ndc[:, 1]) * t / 2], axis=-1)
            pic[hit] = sample_bilinear(img, px)
        out[view.name] = pic
    return out
