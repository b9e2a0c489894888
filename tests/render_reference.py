"""Slow, obvious soft rasterizer: SoftRas's CUDA kernel, line by line, in dense torch.

For the tests only (tiny scenes: every face against every pixel). It follows
``forward_soft_rasterize_cuda_kernel`` of SoftRas's
``soft_rasterize_cuda_kernel.cu`` with its ``soft_rasterize`` defaults
(euclidean distance, softmax colour, prod alpha, double-sided, per-face
colour): the same barycentric and ``face_sym``/``face_obt`` distance
computation, the same sequential loop over faces with the running softmax
maximum and sum, and SoftRas's own pixel-centre formula. It shares no code
with ``saucerfab.render`` except the camera projection; gradients come from
autograd through it.
"""

from __future__ import annotations

import math

import torch

from saucerfab.model.camera import Camera


def _p2f_distance(w: torch.Tensor, xp: torch.Tensor, yp: torch.Tensor, f: torch.Tensor):
    """SoftRas ``euclidean_p2f_distance`` for one face and all pixels.

    w: (3, P) barycentrics; xp, yp: (P,); f: (3, 3) projected corners.
    Returns sign (P,), dis_x (P,), dis_y (P,).
    """
    sym = f[:, :2] @ f[:, :2].T + 1  # face_sym = F F^T (homogeneous)
    obt = [0, 0, 0]
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        dot = (f[k1, 0] - f[k, 0]) * (f[k2, 0] - f[k, 0]) + (f[k1, 1] - f[k, 1]) * (f[k2, 1] - f[k, 1])
        if float(dot.detach()) < 0:
            obt[k] = 1
            break

    def closest(v0: int, t_v0: torch.Tensor, clamp: bool):
        v1, v2 = (v0 + 1) % 3, (v0 + 2) % 3
        t = [None, None, None]
        t[v0] = t_v0
        t[v1] = 1 - t_v0
        t[v2] = torch.zeros_like(t_v0)
        if clamp:
            t = [tk.clamp(0.0, 1.0) for tk in t]
        t = [t[k] - w[k] for k in range(3)]
        dx = t[0] * f[0, 0] + t[1] * f[1, 0] + t[2] * f[2, 0]
        dy = t[0] * f[0, 1] + t[1] * f[1, 1] + t[2] * f[2, 1]
        return dx, dy

    def t_on_edge(v0: int) -> torch.Tensor:
        v1 = (v0 + 1) % 3
        a0 = sym[v0] - sym[v1]
        return (w[0] * a0[0] + w[1] * a0[1] + w[2] * a0[2] - a0[v1]) / (a0[v0] - a0[v1])

    # inside: the nearest of the three edge lines
    best_x = best_y = best_d = None
    for k in range(3):
        dx, dy = closest(k, t_on_edge(k), clamp=False)
        d = dx * dx + dy * dy
        if best_d is None:
            best_x, best_y, best_d = dx, dy, d
        else:
            better = d < best_d
            best_x = torch.where(better, dx, best_x)
            best_y = torch.where(better, dy, best_y)
            best_d = torch.where(better, d, best_d)

    # outside: the edge picked from the barycentric region (with the obtuse fix)
    v0 = torch.full_like(xp, -1, dtype=torch.int64)
    r0 = (w[1] <= 0) & (w[2] <= 0)
    r1 = (w[2] <= 0) & (w[0] <= 0) & ~r0
    r2 = (w[0] <= 0) & (w[1] <= 0) & ~r0 & ~r1
    e0 = ~(r0 | r1 | r2)
    if obt[0]:
        alt0 = (xp - f[0, 0]) * (f[2, 0] - f[0, 0]) + (yp - f[0, 1]) * (f[2, 1] - f[0, 1]) > 0
    else:
        alt0 = torch.zeros_like(r0)
    if obt[1]:
        alt1 = (xp - f[1, 0]) * (f[0, 0] - f[1, 0]) + (yp - f[1, 1]) * (f[0, 1] - f[1, 1]) > 0
    else:
        alt1 = torch.zeros_like(r0)
    if obt[2]:
        alt2 = (xp - f[2, 0]) * (f[1, 0] - f[2, 0]) + (yp - f[2, 1]) * (f[1, 1] - f[2, 1]) > 0
    else:
        alt2 = torch.zeros_like(r0)
    v0 = torch.where(r0, torch.where(alt0, 2, 0), v0)
    v0 = torch.where(r1, torch.where(alt1, 0, 1), v0)
    v0 = torch.where(r2, torch.where(alt2, 1, 2), v0)
    v0 = torch.where(e0 & (w[0] <= 0), 1, v0)
    v0 = torch.where(e0 & (w[0] > 0) & (w[1] <= 0), 2, v0)
    v0 = torch.where(e0 & (w[0] > 0) & (w[1] > 0) & (w[2] <= 0), 0, v0)
    out_x = torch.zeros_like(xp)
    out_y = torch.zeros_like(xp)
    for k in range(3):
        dx, dy = closest(k, t_on_edge(k), clamp=True)
        out_x = torch.where(v0 == k, dx, out_x)
        out_y = torch.where(v0 == k, dy, out_y)

    inside = (w > 0).all(0) & (w < 1).all(0)
    sign = torch.where(inside, 1.0, -1.0).to(xp.dtype)
    return sign, torch.where(inside, best_x, out_x), torch.where(inside, best_y, out_y)


def soft_rasterize_reference(
    vertices: torch.Tensor,
    faces: torch.Tensor,
    face_colors: torch.Tensor,
    camera: Camera,
    *,
    sigma: float = 1e-5,
    gamma: float = 1e-4,
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    near: float = 1.0,
    far: float = 100.0,
    eps: float = 1e-3,
    dist_eps: float = 1e-4,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Dense SoftRas: image (S, S, 3) and alpha (S, S), same dtype as ``vertices``."""
    s = camera.image_size
    dtype = vertices.dtype
    proj = camera.project_torch(vertices)
    face_v = proj[faces]  # (F, 3, 3): SoftRas's face_vertices after perspective
    pn = torch.arange(s * s)
    yi = s - 1 - pn // s  # SoftRas: image row pn // is counts from the top
    xi = pn % s
    yp = ((2.0 * yi + 1.0 - s) / s).to(dtype)
    xp = ((2.0 * xi + 1.0 - s) / s).to(dtype)
    threshold = math.log(1.0 / dist_eps - 1.0) * sigma

    softmax_sum = torch.full((s * s,), math.exp(eps / gamma), dtype=dtype)
    softmax_max = torch.full((s * s,), eps, dtype=dtype)
    bg = torch.tensor(background, dtype=dtype)
    color = bg[:, None] * softmax_sum[None, :]  # (3, P)
    keep_alpha = torch.ones(s * s, dtype=dtype)

    for fn in range(faces.shape[0]):
        f = face_v[fn]
        p = f[:, :2]
        inv_star = torch.stack([
            torch.stack([p[1, 1] - p[2, 1], p[2, 0] - p[1, 0], p[1, 0] * p[2, 1] - p[2, 0] * p[1, 1]]),
            torch.stack([p[2, 1] - p[0, 1], p[0, 0] - p[2, 0], p[2, 0] * p[0, 1] - p[0, 0] * p[2, 1]]),
            torch.stack([p[0, 1] - p[1, 1], p[1, 0] - p[0, 0], p[0, 0] * p[1, 1] - p[1, 0] * p[0, 1]]),
        ])
        det = p[2, 0] * (p[0, 1] - p[1, 1]) + p[0, 0] * (p[1, 1] - p[2, 1]) + p[1, 0] * (p[2, 1] - p[0, 1])
        det = det.clamp_min(1e-10) if float(det.detach()) > 0 else det.clamp_max(-1e-10)
        inv = inv_star / det
        w = inv[:, 0:1] * xp + inv[:, 1:2] * yp + inv[:, 2:3]  # (3, P)

        sign, dis_x, dis_y = _p2f_distance(w, xp, yp, f)
        dis = dis_x * dis_x + dis_y * dis_y
        used = ~((sign < 0) & (dis >= threshold))
        soft = torch.sigmoid(sign * dis / sigma)
        keep_alpha = torch.where(used, keep_alpha * (1.0 - soft), keep_alpha)

        wc = w.clamp(0.0, 1.0)
        wc = wc / wc.sum(0).clamp_min(1e-5)
        zp = 1.0 / (wc[0] / f[0, 2] + wc[1] / f[1, 2] + wc[2] / f[2, 2])
        used = used & (zp >= near) & (zp <= far)
        zp_norm = (far - zp) / (far - near)
        new_max = used & (zp_norm > softmax_max)
        exp_delta = torch.exp(torch.where(new_max, (softmax_max - zp_norm) / gamma, 0.0))
        softmax_max = torch.where(new_max, zp_norm, softmax_max)
        exp_z = torch.exp(torch.where(used, (zp_norm - softmax_max) / gamma, 0.0))
        softmax_sum = torch.where(used, exp_delta * softmax_sum + exp_z * soft, softmax_sum)
        color = torch.where(
            used[None, :], exp_delta * color + (exp_z * soft)[None, :] * face_colors[fn][:, None], color
        )

    image = (color / softmax_sum).T.reshape(s, s, 3)
    alpha = (1.0 - keep_alpha).reshape(s, s)
    return image, alpha


def rasterize_hard_reference(vertices, faces, camera: Camera):  # type: ignore[no-untyped-def]
    """Brute-force hard rasterization: the ray through every pixel centre against
    every triangle (Moeller-Trumbore, both sides), nearest hit wins, ties to the
    lower face index.

    Returns ``face_id`` (S, S), ``bary`` (S, S, 3) (barycentrics of the hit point
    on the 3-D triangle), ``depth`` (S, S) (distance along the view axis) and
    ``margin`` (S, S): the smallest |barycentric| over all faces the ray meets or
    nearly meets, to leave out pixels that lie on an edge, where the answer
    depends on rounding.
    """
    import numpy as np

    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    eye, dirs = camera.rays()
    forward = camera.axes()[2]
    s = camera.image_size
    face_id = np.full((s, s), -1, np.int64)
    bary = np.zeros((s, s, 3))
    depth = np.full((s, s), np.inf)
    margin = np.full((s, s), np.inf)
    for k, (a, b, c) in enumerate(f):
        e1, e2 = v[b] - v[a], v[c] - v[a]
        pvec = np.cross(dirs, e2)
        det = pvec @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = eye - v[a]
            u = (pvec @ tvec) * inv
            qvec = np.cross(tvec, e1)
            w = (dirs * qvec).sum(-1) * inv
            t = (qvec @ e2) * inv
        ok = np.isfinite(inv) & (t > 0)
        near_edge = ok & (np.minimum(np.minimum(u, w), 1 - u - w) > -1e-6)
        margin = np.where(near_edge, np.minimum(margin, np.abs(np.minimum(np.minimum(u, w), 1 - u - w))), margin)
        hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1)
        z = t * (dirs @ forward)
        better = hit & (z < depth)
        face_id[better] = k
        depth[better] = z[better]
        bary[better] = np.stack([1 - u - w, u, w], -1)[better]
    return face_id, bary, depth, margin
