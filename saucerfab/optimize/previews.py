"""Pictures of a finished design, and the final quality metric.

* ``direct_view.png`` / ``reflected_view.png`` (and ``reflected2_view.png``):
  the textured saucer rendered hard (sigma -> 0) in each view frame;
* ``composite.png``: what a viewer at the camera sees, the saucer and the
  mirror cup showing its reflection, in one wider frame;
* ``height_change.png``: |h - z| colour-coded;
* ``side_by_side.png``: inputs against results;
* ``inputs_targets.png``: each input as meant, its foreground mask and its
  enhanced target (what the first stages aim at);
* ``optimized_colors.png``: the per-face-coloured result against the
  enhanced targets (what the stages optimised, before texturing);
* ``energies.png``: the energies over time per stage (as the paper's Figure 10).

The metric ``E_visual_final`` is the paper's eq. 2 on hard renders: the
textured result against the input images projected onto the base shape and
rendered the same way (so pixels no saucer covers count for nothing).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.model.camera import Camera
from saucerfab.model.design import Design

if TYPE_CHECKING:
    from saucerfab.model.scene import Scene
    from saucerfab.optimize.prepare import Prepared
    from saucerfab.optimize.views import Rig, View, ViewMeshes

CUP_GREY = np.array([0.80, 0.82, 0.85])
BACKDROP = np.array([0.97, 0.97, 0.97])


def cup_mesh(cup, segments: int = 96) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """The cup's mirror wall as a triangle mesh: vertices (2K, 3), faces (2K, 3)."""
    outline = cup.boundary(segments)  # a faceted cup gives its corners
    k = outline.shape[0]
    bottom = np.concatenate([outline, np.zeros((k, 1))], axis=1)
    top = np.concatenate([outline, np.full((k, 1), cup.height)], axis=1)
    verts = np.concatenate([bottom, top])
    i = np.arange(k)
    j = (i + 1) % k
    faces = np.concatenate([np.stack([i, j, j + k], 1), np.stack([i, j + k, i + k], 1)])
    return verts, faces


def composite_camera(design: Design, size: int) -> Camera:
    """A camera at the viewer's eye framing both the saucer and the cup."""
    return scene_composite_camera(design.scene, design.heights, size)


def scene_composite_camera(scene: "Scene", heights: np.ndarray, size: int) -> Camera:
    """A camera at the viewer's eye framing the saucer (heights (N, N), model units) and the cup; size x size px."""
    (x0, x1), (y0, y1) = scene.saucer.x_range, scene.saucer.y_range
    zmax = float(heights.max())
    pts = [[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (0.0, zmax)]
    outline = scene.cup.boundary(32)
    pts += [[p[0], p[1], z] for p in outline for z in (0.0, scene.cup.height)]
    pts = np.asarray(pts)
    target = tuple(pts.mean(axis=0))
    cam = Camera(tuple(scene.camera), target, 10.0, size)
    ndc = cam.project(pts)
    half = float(np.abs(ndc[:, :2]).max()) * 1.06
    angle = math.degrees(math.atan(cam.tan_angle * half))
    return Camera(tuple(scene.camera), target, angle, size)


def _textured(verts: np.ndarray, faces: np.ndarray, uvs: np.ndarray, texture: np.ndarray, cam: Camera) -> np.ndarray:
    import torch

    from saucerfab.render import render_textured

    img = render_textured(
        torch.as_tensor(verts), torch.as_tensor(faces), torch.as_tensor(uvs), torch.as_tensor(texture), cam,
        background=(1.0, 1.0, 1.0),
    )
    return np.asarray(img, dtype=np.float64)


def _hard(verts: np.ndarray, faces: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    from saucerfab.render import rasterize_hard

    fid, _, depth = rasterize_hard(verts, faces, cam)
    return np.asarray(fid), np.asarray(depth)


def view_images(
    design: Design, rig: "Rig", size: int | None = None, names: Collection[str] | None = None
) -> dict[str, np.ndarray]:
    """Hard textured renders of each view (or of those in ``names``): name -> (S, S, 3) float in [0, 1]."""
    h = design.heights.reshape(-1)
    out = {}
    for view in rig.views:
        if names is not None and view.name not in names:
            continue
        cam = view.camera if size is None else view.camera.with_size(size)
        if view.faces.shape[0] == 0:
            out[view.name] = np.ones((cam.image_size, cam.image_size, 3))
            continue
        src = view.face_src.numpy()
        out[view.name] = _textured(view.vertices_np(h), view.faces.numpy(), design.face_uvs[src], design.texture, cam)
    return out


def composite_image(design: Design, rig: "Rig", size: int = 768) -> np.ndarray:
    """What the viewer sees: saucer, cup wall, and the reflection in it. (S, S, 3) float."""

    def paint(view: "View", verts: np.ndarray, faces: np.ndarray, cam: Camera) -> tuple[np.ndarray, ...]:
        uvs = design.face_uvs if view.identity else design.face_uvs[view.face_src.numpy()]
        return (_textured(verts, faces, uvs, design.texture, cam), *_hard(verts, faces, cam))

    return compose(design.scene, rig, design.heights, composite_camera(design, size), paint)


#: paint(view, vertices (V', 3), faces (F', 3), camera) -> (image (S, S, 3), face id (S, S), depth (S, S))
Paint = Callable[["ViewMesh", np.ndarray, np.ndarray, Camera], tuple[np.ndarray, ...]]


def compose(scene: "Scene", rig: "ViewMeshes", heights: np.ndarray, cam: Camera, paint: Paint) -> np.ndarray:
    """The composite of a saucer with heights (N, N) (model units) as ``paint`` colours each view's mesh.

    The backdrop, the cup wall in grey, the reflected views where the cup
    is (a mirror reflects ~92%), and the saucer in front. (S, S, 3) float in [0, 1].
    """
    size = cam.image_size
    h = heights.reshape(-1)
    direct = rig.view("direct")
    sv, sf = direct.vertices_np(h), np.asarray(direct.faces)
    saucer, s_id, s_depth = paint(direct, sv, sf, cam)
    cv, cf = cup_mesh(scene.cup)
    c_id, c_depth = _hard(cv, cf, cam)
    img = np.tile(BACKDROP, (size, size, 1))
    cup_px = c_id >= 0
    img[cup_px] = CUP_GREY
    for view in rig.views[1:]:
        if view.faces.shape[0] == 0:
            continue
        rv, rf = view.vertices_np(h), np.asarray(view.faces)
        refl, r_id, _ = paint(view, rv, rf, cam)
        m = cup_px & (r_id >= 0)
        img[m] = 0.92 * refl[m] + 0.08 * CUP_GREY  # a mirror reflects ~92%
    sauc_px = (s_id >= 0) & (~cup_px | (s_depth < c_depth))
    img[sauc_px] = saucer[sauc_px]
    return img


def final_visual_error(
    design: Design, rig: "Rig", prep: "Prepared", views: dict[str, np.ndarray] | None = None
) -> dict[str, float]:
    """E_visual (eq. 2) of hard renders, result vs inputs projected on the base shape.

    Args:
        views: :func:`view_images` of ``design`` at each view's own size, when the caller has them
            (the previews): a view already rendered at the size compared here is not rendered again.
    """
    from saucerfab.optimize.texturing import texture_saucer

    base_design = Design(
        scene=design.scene,
        heights=design.base_heights,
        base_heights=design.base_heights,
        texture=design.texture,
        face_uvs=design.face_uvs,
        face_view=design.face_view,
    )
    ref_tex = texture_saucer(rig, design.base_heights, prep.render, supersample=1)
    base_design.texture, base_design.face_uvs = ref_tex.texture, ref_tex.face_uvs
    size = prep.render["direct"].shape[0]
    want = view_images(base_design, rig, size)
    have = {name: img for name, img in (views or {}).items() if img.shape[0] == size}  # same camera, same render
    fresh = view_images(design, rig, size, names=[v.name for v in rig.views if v.name not in have])
    got = {v.name: have[v.name] if v.name in have else fresh[v.name] for v in rig.views}
    per = {f"E_visual_final_{k}": float(((want[k] - got[k]) ** 2).sum()) for k in got}
    per["E_visual_final"] = float(sum(per.values()))
    return per


def make_previews(
    design: Design, rig: "Rig", prep: "Prepared", colors: np.ndarray, log: list[dict[str, Any]]
) -> tuple[dict[str, bytes], dict[str, float]]:
    """PNG previews (name -> bytes) and the final metrics."""
    import torch

    from saucerfab.files.imageio import png_bytes_many
    from saucerfab.imaging import panels as report
    from saucerfab.optimize.stages import SIGMA_SMALL

    views = view_images(design, rig)
    # the pictures first, then all encoded side by side (png_bytes_many)
    # (each made 8-bit at once: a float64 panel of three pictures is tens of MB)
    u8 = report.as_uint8_rgb
    pictures: dict[str, np.ndarray] = {f"{name}_view.png": u8(img) for name, img in views.items()}
    pictures["composite.png"] = u8(composite_image(design, rig))
    pictures["height_change.png"] = u8(report.height_change_map(
        design.base_heights, design.heights, design.scene.saucer.delta
    ))
    panels = []
    for name in views:
        panels.append((f"input: {name}", prep.render[name]))
        panels.append((f"result: {name}", views[name]))
    pictures["side_by_side.png"] = u8(report.side_by_side(panels))
    # what the optimizer was given: each input as meant, its foreground mask, its enhanced target
    given = []
    for name in views:
        given.append((f"input: {name}", prep.render[name]))
        given.append((f"mask: {name}", report.mask_overlay(prep.render[name], prep.masks[name])))
        given.append((f"target: {name}", prep.enhanced[name]))
    pictures["inputs_targets.png"] = u8(report.side_by_side(given))
    with torch.no_grad():
        h = torch.as_tensor(design.heights.reshape(-1), dtype=torch.float32)
        soft = rig.render(h, torch.as_tensor(colors, dtype=torch.float32), SIGMA_SMALL)
    opt_panels = []
    for view, img in zip(rig.views, soft):
        opt_panels.append((f"enhanced target: {view.name}", prep.enhanced[view.name]))
        opt_panels.append((f"optimized colours: {view.name}", img.numpy()))
    pictures["optimized_colors.png"] = u8(report.side_by_side(opt_panels))
    pngs = png_bytes_many(pictures)
    if log:
        pngs["energies.png"] = report.energy_plot(log)
    return pngs, final_visual_error(design, rig, prep, views)
