"""Which of the saucer's grid vertices carry the design, and which the cup hides from the eye.

The heightfield is a square grid (:mod:`saucerfab.model.heightfield`). A
rectangle saucer is all of it. A disc (:class:`saucerfab.model.scene.Saucer`,
``outline = "disc"``) is the circle inscribed in the grid with the cup standing
at its centre, so three kinds of vertex are not design:

* off the disc (the grid's corners);
* under the cup or in the ring around it where the export's seat stands
  (the cup's footprint grown by ``Scene.cup_ring_units``);
* for the direct view only: behind the cup, hidden from the eye by it (the
  cup is a closed body to the eye; the mirror shows those parts of the saucer
  it can, and the rest stays plain).

The optimizer renders, frames and textures only the design's faces
(:class:`saucerfab.optimize.views.ViewMeshes`); everything else of the grid is
painted the background and the export cuts it away (off the disc) or covers
it (the seat).
"""

from __future__ import annotations

import numpy as np

from saucerfab.model.cups import Cup
from saucerfab.model.heightfield import make_grid
from saucerfab.model.relief import edge_lines
from saucerfab.model.scene import Saucer, Scene

#: directions in which a vertex is tested against the cup's footprint when growing it by the ring
RING_DIRECTIONS = 16
#: samples along the part of a line of sight that passes the cup's bounding cylinder (:func:`hidden_by_cup`)
SIGHT_SAMPLES = 64


def in_grown_footprint(cup: Cup, xy: np.ndarray, ring: float) -> np.ndarray:
    """(P,) bool: the points (P, 2), about the cup's axis, lie in its footprint grown by ``ring`` (same units).

    The growth is tested as the footprint containing the point moved by the
    ring's width in :data:`RING_DIRECTIONS` directions (exact for a circle up to
    the directions' spacing, within ``ring * (1 - cos(pi / 16))`` = 2 % of the ring for the others).
    """
    p = np.asarray(xy, np.float64)
    out = np.asarray(cup.contains(p), bool).copy()
    close = np.flatnonzero(~out & (np.hypot(p[:, 0], p[:, 1]) <= cup.circumradius + ring))
    for a in 2 * np.pi * np.arange(RING_DIRECTIONS) / RING_DIRECTIONS:
        if close.size == 0:
            break
        hit = np.asarray(cup.contains(p[close] + ring * np.array([np.cos(a), np.sin(a)])), bool)
        out[close[hit]] = True
        close = close[~hit]
    return out


def near_cup(scene: Scene, xy: np.ndarray) -> np.ndarray:
    """(P,) bool: the points (P, 2) lie in the cup's footprint grown by its ring (``Scene.cup_ring_units``)."""
    return in_grown_footprint(scene.cup, xy, scene.cup_ring_units)


def part_edge(saucer: Saucer) -> np.ndarray | None:
    """The relief rules' table of a disc's edge across its grid (:func:`saucerfab.model.relief.edge_lines`).

    The grid's vertices off the disc (its corners, which the export cuts away)
    with the disc's outward normal (radial) at each: (3, N, N) float64. None on
    a rectangle (the grid's border is its edge).
    """
    if not saucer.is_disc:
        return None
    grid = make_grid(saucer)
    gx, gy = np.meshgrid(grid.xs, grid.ys)  # row i at ys[i], as the heights
    off = ~saucer.on_saucer(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
    r = np.maximum(np.hypot(gx, gy), 1e-12)  # off the disc r > its radius; the guard is for the centre
    return edge_lines(off, np.stack([gx / r, gy / r], axis=-1), *grid.spacing)


def design_vertices(scene: Scene, xy: np.ndarray) -> np.ndarray:
    """(P,) bool: the grid points (P, 2) that carry the design (a rectangle: all; a disc: on it, clear of the cup)."""
    saucer = scene.saucer
    if not saucer.is_disc:
        return np.ones(np.asarray(xy).shape[0], bool)
    return saucer.on_saucer(xy) & ~near_cup(scene, xy)


def hidden_by_cup(scene: Scene, points: np.ndarray, samples: int = SIGHT_SAMPLES) -> np.ndarray:
    """(P,) bool: the cup stands between the design eye and these points (P, 3), model units.

    Only the stretch of each line of sight that passes the cup's bounding
    cylinder (its circumradius, from z = 0 to its rim) is sampled, ``samples``
    times; a sample inside the footprint is a hit (the cup is a closed body to the eye).
    """
    pts = np.asarray(points, np.float64)
    eye = np.asarray(scene.camera, np.float64)
    d = eye[None, :] - pts  # the point at t = 0, the eye at t = 1
    r = scene.cup.circumradius
    # the line's xy within the bounding circle: |p + t d|^2 <= r^2
    a = np.maximum(d[:, 0] ** 2 + d[:, 1] ** 2, 1e-30)
    b = 2 * (pts[:, 0] * d[:, 0] + pts[:, 1] * d[:, 1])
    c = pts[:, 0] ** 2 + pts[:, 1] ** 2 - r * r
    disc = b * b - 4 * a * c
    ok = disc >= 0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    t0, t1 = (-b - sq) / (2 * a), (-b + sq) / (2 * a)
    # and below the rim (z rises from the point to the eye when the eye is above it)
    dz = np.where(np.abs(d[:, 2]) < 1e-30, 1e-30, d[:, 2])
    tz_lo, tz_hi = np.sort(np.stack([(0.0 - pts[:, 2]) / dz, (scene.cup.height - pts[:, 2]) / dz]), axis=0)
    lo = np.maximum.reduce([t0, tz_lo, np.full_like(t0, 1e-9)])
    hi = np.minimum.reduce([t1, tz_hi, np.ones_like(t1)])
    out = np.zeros(pts.shape[0], bool)
    idx = np.flatnonzero(ok & (hi > lo))
    for k in (np.arange(samples) + 0.5) / samples:
        if idx.size == 0:
            break
        t = lo[idx] + k * (hi[idx] - lo[idx])
        q = pts[idx, :2] + t[:, None] * d[idx, :2]
        hit = np.asarray(scene.cup.contains(q), bool)
        out[idx[hit]] = True
        idx = idx[~hit]
    return out


def direct_vertices(scene: Scene, vertices: np.ndarray) -> np.ndarray:
    """(P,) bool: grid vertices (P, 3) the design eye can see directly as design (a rectangle: all)."""
    v = np.asarray(vertices, np.float64)
    keep = design_vertices(scene, v[:, :2])
    if scene.saucer.is_disc:
        idx = np.flatnonzero(keep)
        keep[idx[hidden_by_cup(scene, v[idx])]] = False
    return keep
