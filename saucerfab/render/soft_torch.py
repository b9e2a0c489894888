"""The straightforward soft rasterizer in vectorized torch (any device, autograd).

Every face is paired with every pixel centre in its bounding box widened by
the influence radius ``sqrt(log(1/dist_eps - 1) * sigma)``; the SoftRas
formulas of :mod:`saucerfab.render.soft` are evaluated on those pairs as flat
tensors and aggregated per pixel with ``index_add``/``scatter_reduce``.
Autograd gives the gradients. Its cost and memory grow with the number of
pairs (5.4 M for the paper's two views at ``sigma = 1e-5``); it is the
comparison for the compiled CPU kernels and the path for CUDA tensors.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from saucerfab.render.soft_common import DEFAULTS, DET_EPS, WSUM_EPS, SoftParams, distance_threshold

if TYPE_CHECKING:
    import torch

    from saucerfab.model.camera import Camera


def face_pixel_boxes(
    face_xy: "torch.Tensor", image_size: int, radius: float
) -> "tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]":
    """Inclusive pixel ranges of the faces' widened bounding boxes.

    Args:
        face_xy: Projected corners, shape [F, 3, 2], NDC.
        image_size: S.
        radius: Widening of each box on every side, NDC units.

    Returns:
        ``(row0, row1, col0, col1)``, each shape [F], int64: the pixels whose
        centres lie in the widened box, clipped to the image (``row1 < row0``
        or ``col1 < col0`` when none; faces with non-finite corners get none).
    """
    import torch

    s = image_size
    xy = face_xy.detach().to(torch.float64)
    lo = xy.amin(dim=1)
    hi = xy.amax(dim=1)
    finite = torch.isfinite(xy).all(dim=(1, 2))
    # centre of column j: x = (2j + 1)/S - 1; of row i: y = 1 - (2i + 1)/S
    col0 = torch.ceil(((lo[:, 0] - radius + 1) * s - 1) / 2)
    col1 = torch.floor(((hi[:, 0] + radius + 1) * s - 1) / 2)
    row0 = torch.ceil(((1 - hi[:, 1] - radius) * s - 1) / 2)
    row1 = torch.floor(((1 - lo[:, 1] + radius) * s - 1) / 2)
    out = []
    for v, is_lo in ((row0, True), (row1, False), (col0, True), (col1, False)):
        v = torch.nan_to_num(v, nan=0.0).clamp(-1, s)
        v = v.clamp_min(0) if is_lo else v.clamp_max(s - 1)
        out.append(v.to(torch.int64))
    row0, row1, col0, col1 = out
    # an empty box for faces we cannot place
    row1 = torch.where(finite, row1, row0 - 1)
    return row0, row1, col0, col1


def candidate_pairs(
    face_xy: "torch.Tensor", image_size: int, radius: float
) -> "tuple[torch.Tensor, torch.Tensor, torch.Tensor]":
    """All (face, pixel) pairs of the widened bounding boxes.

    Args: as :func:`face_pixel_boxes`.

    Returns:
        ``(face, row, col)``, each shape [P], int64, grouped by face.
    """
    import torch

    row0, row1, col0, col1 = face_pixel_boxes(face_xy, image_size, radius)
    h = (row1 - row0 + 1).clamp_min(0)
    w = (col1 - col0 + 1).clamp_min(0)
    counts = h * w
    total = int(counts.sum())
    dev = face_xy.device
    face = torch.repeat_interleave(torch.arange(face_xy.shape[0], device=dev), counts, output_size=total)
    start = torch.cumsum(counts, 0) - counts
    k = torch.arange(total, device=dev) - start[face]
    wf = w[face]
    return face, row0[face] + k // wf, col0[face] + k % wf


def count_candidate_pairs(vertices: "torch.Tensor", faces: "torch.Tensor", camera: "Camera",
                          sigma: float = DEFAULTS.sigma, dist_eps: float = DEFAULTS.dist_eps) -> int:
    """Number of bounding-box pixel-face pairs the torch backend evaluates (a work measure)."""
    import torch

    with torch.no_grad():
        proj = camera.project_torch(vertices.detach().to(torch.float64))
        fxy = proj[faces][..., :2]
        radius = math.sqrt(distance_threshold(sigma, dist_eps))
        row0, row1, col0, col1 = face_pixel_boxes(fxy, camera.image_size, radius)
        return int(((row1 - row0 + 1).clamp_min(0) * (col1 - col0 + 1).clamp_min(0)).sum())


def soft_rasterize_torch(
    vertices: "torch.Tensor", faces: "torch.Tensor", face_colors: "torch.Tensor", camera: "Camera", params: SoftParams
) -> "tuple[torch.Tensor, torch.Tensor]":
    """The torch backend of :func:`saucerfab.render.soft_rasterize` (arguments checked there).

    Takes and returns what :func:`saucerfab.render.soft_numba.soft_rasterize_numba`
    does (any device here): ``vertices`` [V, 3], ``faces`` [F, 3] int64,
    ``face_colors`` [F, 3] in ``vertices.dtype``, the view, the checked
    ``params``; gives ``(image [S, S, 3], alpha [S, S])``.
    """
    import torch
    import torch.nn.functional as F

    sigma, gamma, background = params.sigma, params.gamma, params.background
    near, far, eps = params.near, params.far, params.eps
    s = camera.image_size
    dtype, dev = vertices.dtype, vertices.device
    thr = params.threshold
    proj = camera.project_torch(vertices)  # (V, 3): x_ndc, y_ndc, depth
    fv = proj[faces]  # (F, 3 corners, 3)
    x0, x1, x2 = fv[:, 0, 0], fv[:, 1, 0], fv[:, 2, 0]
    y0, y1, y2 = fv[:, 0, 1], fv[:, 1, 1], fv[:, 2, 1]

    # Barycentric coordinates as SoftRas's face_inv: adjugate / clamped determinant.
    det = x2 * (y0 - y1) + x0 * (y1 - y2) + x1 * (y2 - y0)
    det = torch.where(det > 0, det.clamp_min(DET_EPS), det.clamp_max(-DET_EPS))
    inv = torch.stack(
        [
            y1 - y2, x2 - x1, x1 * y2 - x2 * y1,
            y2 - y0, x0 - x2, x2 * y0 - x0 * y2,
            y0 - y1, x1 - x0, x0 * y1 - x1 * y0,
        ],
        dim=1,
    ) / det[:, None]  # (F, 9)

    face, row, col = candidate_pairs(fv[..., :2], s, math.sqrt(thr))
    px = ((2 * col + 1).to(dtype) / s - 1)
    py = (1 - (2 * row + 1).to(dtype) / s)
    pix = row * s + col

    # Squared distance to the closed triangle: the nearest of its three edges.
    c = fv[face][..., :2]  # (P, 3, 2)
    p = torch.stack([px, py], dim=1)[:, None, :]  # (P, 1, 2)
    a = c
    e = torch.roll(c, shifts=-1, dims=1) - c  # edge k: corner k -> corner k+1
    ee = (e * e).sum(-1).clamp_min(1e-30)  # degenerate edges project onto their start
    t = (((p - a) * e).sum(-1) / ee).clamp(0.0, 1.0)
    diff = a + t[..., None] * e - p
    d2 = (diff * diff).sum(-1).amin(dim=1)  # (P,)

    fi = inv[face]  # (P, 9)
    w = torch.stack(
        [fi[:, 3 * k] * px + fi[:, 3 * k + 1] * py + fi[:, 3 * k + 2] for k in range(3)], dim=1
    )
    inside = ((w > 0) & (w < 1)).all(dim=1)
    keep = inside | (d2 < thr)
    face, pix, w, inside, d2 = face[keep], pix[keep], w[keep], inside[keep], d2[keep]

    x = torch.where(inside, d2, -d2) / sigma  # sign * d^2 / sigma
    n_pix = s * s
    # alpha = 1 - prod(1 - D); log(1 - D) = logsigmoid(-x) stays finite where D -> 1
    log_t = torch.zeros(n_pix, dtype=dtype, device=dev).index_add(0, pix, F.logsigmoid(-x))
    alpha = 1 - torch.exp(log_t)

    # Perspective-correct depth from the clipped barycentrics.
    wc = w.clamp(0.0, 1.0)
    wc = wc / wc.sum(dim=1, keepdim=True).clamp_min(WSUM_EPS)
    z = 1.0 / (wc / fv[face][..., 2]).sum(dim=1)
    rgb = (z >= near) & (z <= far)
    face, pix, x, z = face[rgb], pix[rgb], x[rgb], z[rgb]
    zn = (far - z) / (far - near)

    # Softmax over normalized inverse depth, shifted by the pixel's maximum
    # (a constant per pixel: it cancels in the ratio, so it carries no gradient).
    m = torch.full((n_pix,), eps, dtype=dtype, device=dev)
    m = m.scatter_reduce(0, pix, zn.detach(), reduce="amax", include_self=True)
    wt = torch.sigmoid(x) * torch.exp((zn - m[pix]) / gamma)
    w_bg = torch.exp((2 * eps - m) / gamma)
    den = w_bg + torch.zeros(n_pix, dtype=dtype, device=dev).index_add(0, pix, wt)
    bg = torch.tensor(background, dtype=dtype, device=dev)
    num = w_bg[:, None] * bg + torch.zeros(n_pix, 3, dtype=dtype, device=dev).index_add(
        0, pix, wt[:, None] * face_colors[face]
    )
    image = (num / den[:, None]).reshape(s, s, 3)
    return image, alpha.reshape(s, s)
