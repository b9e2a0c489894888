"""Blur-matched target images and the compatibility score rho (paper, section 3.5).

SoftRas images are blurrier than the inputs, so comparing against the inputs
would add an error no heightfield can remove. As the paper does, each target
is the input image projected onto a shape as per-face colours and rendered
through the same soft rasterizer at the same sigma:

* direct target: the base shape S coloured from the direct image by
  projection in the direct view, rendered in the direct view;
* reflected target: the reflected shape of S coloured from the reflected
  image by projection in the reflected view, rendered in the reflected view.

The compatibility score (section 3.5) swaps the roles: the direct-image
colouring seen in the mirror, and the reflected-image colouring seen directly.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from saucerfab.optimize.views import Rig, ViewMesh, ViewMeshes, visible_faces

if TYPE_CHECKING:
    import torch


def sample_bilinear(image: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` (H, W, C) at continuous pixel positions.

    Args:
        px: (..., 2) ``(column, row)``; pixel (i, j)'s centre is (j + 0.5, i + 0.5).
            Positions outside the image clamp to the border.
    Returns:
        (..., C) float64.
    """
    from saucerfab.render.sampling import sample_bilinear as sample_texture

    h, w = image.shape[:2]
    # the same lookup as the renderer's, in its UV convention (v up)
    uv = np.stack([px[..., 0] / w, 1.0 - px[..., 1] / h], axis=-1)
    return sample_texture(np.asarray(image, np.float64), uv)


def project_colors(
    view: ViewMesh,
    heights: np.ndarray,
    image: np.ndarray,
    num_faces: int,
    fill: tuple[float, float, float] = (0.5, 0.5, 0.5),
) -> np.ndarray:
    """Per-face colours (F, 3) of the saucer from ``image`` projected in ``view``.

    A face visible in the view gets the mean of the image over the pixels it
    covers (the hard rasterizer's face buffer at the image's resolution); a
    face too small or hidden gets the bilinear sample at its projected
    centroid; faces not in the view at all get ``fill``.

    Args:
        heights: (N, N) or (V,) heights. image: (S, S, 3) in [0, 1], the view's frame.
    """
    from saucerfab.render import rasterize_hard

    cam = view.camera.with_size(image.shape[0])
    verts = view.vertices_np(np.asarray(heights).reshape(-1))
    faces = np.asarray(view.faces)
    out = np.tile(np.asarray(fill, np.float64), (num_faces, 1))
    if faces.shape[0] == 0:
        return out
    ndc = cam.project(verts)
    cen = ndc[faces].mean(axis=1)
    px = cam.ndc_to_pixel(cen[:, :2])
    colors = sample_bilinear(image, px)
    face_id, _, _ = rasterize_hard(verts, faces, cam)
    fid = np.asarray(face_id).reshape(-1)
    hit = fid >= 0
    if hit.any():
        img = image.reshape(-1, image.shape[-1]).astype(np.float64)
        counts = np.bincount(fid[hit], minlength=faces.shape[0]).astype(np.float64)
        sums = np.stack(
            [np.bincount(fid[hit], weights=img[hit, k], minlength=faces.shape[0]) for k in range(3)],
            axis=1,
        )
        covered = counts > 0
        colors[covered] = sums[covered] / counts[covered, None]
    out[np.asarray(view.face_src)] = colors
    return out


def blur_matched_targets(
    rig: Rig,
    heights: np.ndarray,
    images: dict[str, np.ndarray],
    sigma: float,
    *,
    dtype: torch.dtype | None = None,
) -> dict[str, torch.Tensor]:
    """Render each view's input image through the soft rasterizer on ``heights``.

    Args:
        images: view name -> (S, S, 3) image in [0, 1] (the fitted input or its enhancement).
        dtype: the targets' dtype (default float32).
    Returns:
        view name -> (S, S, 3) target tensor.
    """
    import torch

    dtype = dtype or torch.float32
    h = torch.as_tensor(np.asarray(heights).reshape(-1), dtype=dtype)
    out: dict[str, torch.Tensor] = {}
    for view in rig.views:
        cols = project_colors(view, heights, images[view.name], rig.num_faces)
        with torch.no_grad():
            (img,) = rig.render(h, torch.as_tensor(cols, dtype=dtype), sigma, views=[view.name])
        out[view.name] = img
    return out


def compatibility(
    rig: Rig,
    heights: np.ndarray,
    enhanced: dict[str, np.ndarray],
    targets: dict[str, torch.Tensor],
    sigma: float,
    *,
    background: tuple[float, float, float] = (0.0, 0.5, 1.0),
    dtype: torch.dtype | None = None,
) -> float:
    """The compatibility score rho of the inputs and the base shape (section 3.5).

    (1) Colour S with the enhanced direct image by projection in the direct
    view; render its reflection: ``I_r^c``. (2) Colour S with the enhanced
    reflected image by projection in the reflected view; render it directly:
    ``I_d^c``. (3) ``rho = ||I^e_d_hat - I_d^c||^2 + ||I^e_r_hat - I_r^c||^2``
    against the blur-matched enhanced targets. Faces the projection does not
    reach get the enhancement's background colour (light blue), i.e. they
    count as background.

    With two reflected images, each reflected view contributes its own term.
    """
    import torch

    dtype = dtype or torch.float32
    h = torch.as_tensor(np.asarray(heights).reshape(-1), dtype=dtype)
    direct = rig.view("direct")
    col_d = project_colors(direct, heights, enhanced["direct"], rig.num_faces, background)
    rho = 0.0
    with torch.no_grad():
        for view in rig.views[1:]:
            col_r = project_colors(view, heights, enhanced[view.name], rig.num_faces, background)
            (seen_in_mirror,) = rig.render(h, torch.as_tensor(col_d, dtype=dtype), sigma, views=[view.name])
            (seen_directly,) = rig.render(h, torch.as_tensor(col_r, dtype=dtype), sigma, views=["direct"])
            rho += float(((targets[view.name] - seen_in_mirror) ** 2).sum())
            rho += float(((targets["direct"] - seen_directly) ** 2).sum())
    return rho


def projected_colors(rig: ViewMeshes, heights: np.ndarray, images: dict[str, np.ndarray]) -> np.ndarray:
    """Per-face colours (F, 3) from the texturing step's rule (section 3.4.2).

    A face seen only directly takes the direct image's colour, one seen only
    in a reflection that reflection's, one seen in both the average, one
    seen in neither grey. Used to start the colours (paper, Figure 12 (c)).
    """
    vis = visible_faces(rig, heights, supersample=1)
    acc = np.zeros((rig.num_faces, 3))
    cnt = np.zeros(rig.num_faces)
    for view in rig.views:
        cols = project_colors(view, heights, images[view.name], rig.num_faces)
        seen = vis[view.name]
        acc[seen] += cols[seen]
        cnt[seen] += 1
    out = np.full((rig.num_faces, 3), 0.5)
    some = cnt > 0
    out[some] = acc[some] / cnt[some, None]
    return out
