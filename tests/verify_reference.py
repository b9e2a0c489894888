"""A second, independent estimate of what a print shows: a plain numpy ray cast.

For a *flat* saucer (every height equal) and a *circular* cup only: rays
through a regular grid of sub-pixel points, intersected analytically with
the saucer's top plane and the cup's cylinder, reflected about the
cylinder's exact normal, and coloured from the **design's** texture by the
design's planar texture mapping. It shares nothing with
:mod:`saucerfab.verify` but ``scene.json``'s numbers: not the exported
mesh, not the baked atlas, not Mitsuba. The seat plate behind the saucer
(its top ``seat.top_z`` above the saucer's top) blocks reflected rays that
pass under it, as the printed part does.

Its pieces, :func:`camera_rays` and :func:`cylinder_reflection`, also place
a saucer feature's reflection exactly (``tests/verify/test_verify_accuracy.py``).
"""

from __future__ import annotations

import numpy as np


def _bilinear(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Sample (H, W, 3) ``tex`` at texture coordinates (u right, v up), clamped."""
    h, w = tex.shape[:2]
    x = np.clip(u * w - 0.5, 0, w - 1)
    y = np.clip((1 - v) * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    t = tex.astype(np.float64)
    return (t[y0, x0] * (1 - fx) * (1 - fy) + t[y0, x1] * fx * (1 - fy)
            + t[y1, x0] * (1 - fx) * fy + t[y1, x1] * fx * fy)


def camera_frame(eye, target, angle_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The camera of :mod:`saucerfab.model.camera`: a look-at from ``eye`` to ``target`` with z up.

    Returns:
        forward, right, up (unit, (3,) each) and ``tan(angle_deg)``, the
        frame's half width at unit depth.
    """
    fwd = np.asarray(target, np.float64) - np.asarray(eye, np.float64)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return fwd, right, np.cross(right, fwd), float(np.tan(np.radians(angle_deg)))


def camera_rays(eye, target, angle_deg: float, nx: np.ndarray, ny: np.ndarray) -> np.ndarray:
    """Unit directions (..., 3) of the rays through frame points (``nx`` right, ``ny`` up, each in [-1, 1])."""
    fwd, right, up, w = camera_frame(eye, target, angle_deg)
    d = np.asarray(nx)[..., None] * w * right + np.asarray(ny)[..., None] * w * up + fwd
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def cylinder_reflection(eye, d: np.ndarray, centre, radius: float):
    """Rays from ``eye`` along ``d`` (..., 3) off the vertical cylinder of ``radius`` about ``centre`` (x, y).

    The first root of ``|o_xy + t d_xy - c|^2 = r^2`` in front of the eye,
    reflected about the cylinder's exact normal; all in float64.

    Returns:
        t (...,) along the ray, the hit point p (..., 3), the reflected
        direction (..., 3), and whether the ray meets the cylinder at all.
    """
    eye = np.asarray(eye, np.float64)
    c = np.asarray(centre, np.float64)
    oc = eye[:2] - c
    a = (d[..., :2] ** 2).sum(-1)
    b = 2 * (d[..., :2] * oc).sum(-1)
    cc = (oc**2).sum() - radius * radius
    disc = b * b - 4 * a * cc
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
    p = eye + t[..., None] * d
    n = np.zeros_like(d)
    n[..., :2] = (p[..., :2] - c) / radius
    dr = d - 2 * (d * n).sum(-1, keepdims=True) * n
    return t, p, dr, (disc > 0) & (t > 0)


def cast(scene: dict, texture: np.ndarray, z_top: float, eye, view: str, res: int, sub: int = 4):
    """Render ``view`` of a flat saucer seen from ``eye`` (mm, file frame).

    Args:
        scene: the ``scene.json`` dict.
        texture: (T, T, 3) float in [0, 1], the design's texture, mapped
            planar over the footprint (u along x, v along y).
        z_top: the saucer top's z in the file frame, mm.
        res: pixels per side; ``sub`` x ``sub`` sub-pixel rays each (box filter).

    Returns:
        rgb (res, res, 3), direct coverage (res, res), reflected coverage (res, res).
    """
    v = scene["views"][view]
    eye = np.asarray(eye, np.float64)
    k = (np.arange(res * sub) + 0.5) / (res * sub)
    xs, ys = 2 * k - 1, 1 - 2 * k  # NDC of sub-pixel centres: columns right, rows down
    gx, gy = np.meshgrid(xs, ys)
    d = camera_rays(eye, v["target"], v["viewing_angle_deg"], gx, gy)

    (x0, x1), (y0, y1) = scene["saucer"]["x_range"], scene["saucer"]["y_range"]
    cup = scene["cup"]
    c = np.asarray(cup["center"], np.float64)
    r, cz0, cz1 = cup["radius"], cup["bottom_z"], cup["bottom_z"] + cup["height"]
    plate_top = scene["seat"]["top_z"]

    def hit_plane(o: np.ndarray, dd: np.ndarray):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (z_top - o[..., 2]) / dd[..., 2]
        p = o + t[..., None] * dd
        ok = (t > 1e-9) & (p[..., 0] >= x0) & (p[..., 0] <= x1) & (p[..., 1] >= y0) & (p[..., 1] <= y1)
        return t, p, ok

    def colour(p: np.ndarray) -> np.ndarray:
        return _bilinear(texture, (p[..., 0] - x0) / (x1 - x0), (p[..., 1] - y0) / (y1 - y0))

    tc, pc, dr, hit = cylinder_reflection(eye, d, c, r)
    on_cup = hit & (pc[..., 2] >= cz0) & (pc[..., 2] <= cz1)

    tp, pp, on_saucer = hit_plane(np.broadcast_to(eye, d.shape), d)
    direct = on_saucer & ~(on_cup & (tc < tp))
    cup_first = on_cup & ~(on_saucer & (tp < tc))

    _tr, pr, refl_hit = hit_plane(pc, dr)
    # the seat plate (behind the saucer, y > y1) stands above the top: a ray crossing y = y1 below it is blocked
    with np.errstate(divide="ignore", invalid="ignore"):
        ty = (y1 - pc[..., 1]) / dr[..., 1]
    z_at_edge = pc[..., 2] + ty * dr[..., 2]
    blocked = (ty > 0) & (z_at_edge < plate_top)
    reflected = cup_first & refl_hit & ~blocked

    rgb = np.zeros(d.shape)
    rgb[direct] = colour(pp[direct])
    rgb[reflected] = colour(pr[reflected])

    def box(a_: np.ndarray) -> np.ndarray:
        return a_.reshape(res, sub, res, sub, *a_.shape[2:]).mean(axis=(1, 3))

    return box(rgb), box(direct.astype(np.float64)), box(reflected.astype(np.float64))
