"""The shading of the printed top's relief under a light, and the texture that prints it out (issue 45).

A print is a diffuse plastic: what a viewer sees of a texel is its albedo
times the light that reaches it. On a flat plate that light is smooth; on
the relief it is not: a slope facing the lamp is brighter, a groove sees
less of the room (ambient occlusion). ``saucerfab verify --light room``
scores each view against the picture times the light's *smooth* part
(:mod:`saucerfab.verify.litscore`), so what costs the print is the relief's
shading **pattern** ``P = S / smooth(S)``. This module computes ``S`` on
the printed top and divides the albedo by ``P`` as far as the printer's
range allows without a darker print (``export --shading-compensation``).

The model
---------
* **The surface.** The top is the grid ``xs_mm`` (Nx,) x ``ys_mm`` (Ny,)
  with ``heights_mm`` (Ny, Nx) (row ``i`` at ``ys_mm[i]``), each cell split
  into two flat triangles along the diagonal from (i, j) to (i + 1, j + 1),
  as the solid and the bake split them. Verify renders those flat faces
  without vertex normals, so the shading is computed **per triangle** (its
  centroid, its face normal): array shape (2, Ny - 1, Nx - 1), triangle 0
  the one below the diagonal (``s >= t`` in the cell's local coordinates,
  corners (i, j), (i, j + 1), (i + 1, j + 1)), triangle 1 the other. Points
  are marched over the same triangulated surface (:meth:`Relief.height_at`).
* **Beyond the part.** The grid is taken as it is: a round saucer's grid
  extends past the disc into corners the export cuts away
  (:func:`saucerfab.model.footprint.part_edge`); those corners still shade
  and occlude here. The cup is left out too (its shadow, the room it hides
  next to it, the light its metal throws back onto the slopes facing it):
  assumed smooth at the scale the pattern is measured on, not measured.
* **Ambient occlusion** (:func:`ambient_occlusion`): the cosine-weighted
  share of the sky a point sees, horizon-based: along each of ``directions``
  azimuths the surface is marched outwards (steps growing by
  :data:`STEP_GROWTH` from half a cell) for the highest elevation ``h``;
  the sky above ``max(h, the tangent plane)`` contributes, in closed form
  per azimuth for the tilted normal (:func:`_sky_above`). A flat plane, or
  any tilted plane, reads 1 (the tests hold it to the same integral done
  the slow, obvious way).
* **The lamp** (:func:`lamp_reading`): the area lamp as verify places it
  (:func:`saucerfab.verify.lighting.place_lamp`: one definition), split into
  ``split`` x ``split`` squares; each square's cosine integral
  ``cos(normal, to lamp) cos(lamp, to point) / r^2`` by a ``quad`` x
  ``quad`` rule, times its centre's visibility over the relief. In the
  lighting module's units: a white Lambertian paper lying flat at the cup's
  foot reads the lamp's power.
* **The room** (:data:`LIGHT_NAMES`): ``ambient``: the uniform environment
  alone, ``S = AO``; ``room``: verify's ``--light room``,
  ``S = ROOM_AMBIENT * AO + lamp``. Light bounced between facing slopes
  is left out: a first-order estimate of it made the heart-star export's
  lit scores 0.6-1.3 dB worse (``benchmarks/results/light_session26.txt``).
* **The pattern** (:func:`shading_pattern`): ``S`` over its normalized
  Gaussian low-pass on the plan, ``sigma`` = the top's longer side times
  :data:`saucerfab.verify.litscore.SMOOTH_SIGMA_FRACTION` (1/8): verify
  low-passes the white render with 1/8 of the view's frame, and a view's
  frame spans about the saucer (12.5 mm on a 100 mm saucer). The low-pass
  runs over the faces of one view at a time (the design's face views), as
  each of verify's pictures shows only its own faces.

Compensation
------------
:func:`compensate_page`: each top texel's linear albedo ``a`` (the sRGB
page linearised) becomes ``min(a / P^k / g, 1)``: ``k`` is
:data:`COMPENSATION_POWER`, ``g`` one factor for all texels and channels
(the colours keep their balance). All of ``P`` fits the printer's range only
if the whole top is darkened by the largest ``1 / P`` under a white
picture: on the heart-star default top, mostly white, a factor 3.5 and a
mean albedo 2.7x darker. Verify's lit score takes one gain per channel and
does not see that; a person does. So ``g`` is the smaller of the seen
texels' :data:`CLIP_PERCENTILE` th percentile (all but 0.5 % in range) and
the largest factor that keeps the top's mean linear albedo within
:data:`MAX_DARKENING` of the plain page's (at least 1). The texels still out
of range clip (white pictures on the dark slopes keep part of their
shading); ``k < 1`` corrects every slope less and clips fewer (18 % of the
heart-star top's texel channels at k 0.75, 23 % at 1). That design,
verified under the room light from the design eye (direct / reflected):
plain 26.4 / 24.4 dB, all of ``P`` 29.0 / 29.0, this rule (k 0.75, 1.3x
darker) 28.5 / 28.0; the other rules tried in
``benchmarks/results/light_session26.txt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.fabricate.atlas import AtlasLayout
from saucerfab.fabricate.bleed import linear_to_srgb, refill_gutter, srgb_to_linear
from saucerfab.verify.lighting import ROOM_AMBIENT, ROOM_LAMP, LampPlacement, place_lamp
from saucerfab.verify.litscore import SMOOTH_SIGMA_FRACTION

#: the lights ``--shading-compensation`` compensates (``off`` is the option's own)
LIGHT_NAMES: tuple[str, ...] = ("ambient", "room")
#: azimuths of the ambient occlusion's horizon search: on the heart-star default top (150 x 150 grid,
#: under the room light) 16 and 32 give patterns within 1.1 % of each other on 98 % of the triangles
#: (5 % at worst)
DIRECTIONS = 16
#: the march's steps grow by this factor, from half a grid cell: 40 steps cross a 150-cell grid
STEP_GROWTH = 1.15
#: the lamp is split into SPLIT x SPLIT squares, each with its own visibility ...
LAMP_SPLIT = 3
#: ... and a QUAD x QUAD rule for its cosine integral
LAMP_QUAD = 4
#: the global factor is at most the (100 - 0.5)th percentile of the seen texels' compensated values ...
CLIP_PERCENTILE = 99.5
#: ... and at most what darkens the top's mean linear albedo by this factor (module docstring)
MAX_DARKENING = 1.3
#: the page is divided by the pattern to this power (module docstring)
COMPENSATION_POWER = 0.75
#: top texels compensated at once (memory: about 60 bytes a texel)
CHUNK_TEXELS = 1 << 21


# --------------------------------------------------------------------------- the surface


@dataclass(frozen=True)
class Relief:
    """The triangulated top (module docstring): the grid and its heights, mm.

    Attributes:
        xs: (Nx,) increasing, evenly spaced x of the grid's columns, mm.
        ys: (Ny,) increasing, evenly spaced y of its rows, mm.
        heights: (Ny, Nx) z of the vertices, mm (row i at ys[i]).
    """

    xs: np.ndarray
    ys: np.ndarray
    heights: np.ndarray

    @staticmethod
    def of(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray) -> Relief:
        xs, ys = np.asarray(xs_mm, np.float64), np.asarray(ys_mm, np.float64)
        h = np.asarray(heights_mm, np.float64)
        if h.shape != (ys.size, xs.size) or xs.size < 2 or ys.size < 2:
            raise ValueError(f"heights {h.shape} must be (len(ys), len(xs)) = ({ys.size}, {xs.size}), at least 2 x 2")
        for name, v in (("xs_mm", xs), ("ys_mm", ys)):
            d = np.diff(v)
            # evenly to 0.1 %: the solid moves the outer lines by nanometres onto Clipper's grid
            if not (d > 0).all() or np.ptp(d) > 1e-3 * float(d.mean()):
                raise ValueError(f"{name} must be increasing and evenly spaced")
        return Relief(xs, ys, h)

    @property
    def dx(self) -> float:
        """The columns' spacing, mm."""
        return float(self.xs[-1] - self.xs[0]) / (self.xs.size - 1)

    @property
    def dy(self) -> float:
        """The rows' spacing, mm."""
        return float(self.ys[-1] - self.ys[0]) / (self.ys.size - 1)

    def height_at(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Heights (mm) of the triangulated surface at plan points ``x``, ``y`` (any one shape, mm), and
        whether each lies on the grid (outside: height NaN)."""
        fx = (np.asarray(x, np.float64) - self.xs[0]) / self.dx
        fy = (np.asarray(y, np.float64) - self.ys[0]) / self.dy
        nx, ny = self.xs.size, self.ys.size
        inside = (fx >= 0) & (fx <= nx - 1) & (fy >= 0) & (fy <= ny - 1)
        j = np.clip(np.floor(fx), 0, nx - 2).astype(np.int64)
        i = np.clip(np.floor(fy), 0, ny - 2).astype(np.int64)
        s, t = fx - j, fy - i
        h = self.heights
        a, b, c, d = h[i, j], h[i, j + 1], h[i + 1, j + 1], h[i + 1, j]
        z = np.where(s >= t, a + s * (b - a) + t * (c - b), a + t * (d - a) + s * (c - d))
        return np.where(inside, z, np.nan), inside


def face_points(relief: Relief) -> tuple[np.ndarray, np.ndarray]:
    """Centroids and unit normals of the top's triangles: two (2, Ny - 1, Nx - 1, 3) arrays, mm and unit.

    Triangle 0 of cell (i, j) has corners (i, j), (i, j + 1), (i + 1, j + 1); triangle 1 (i, j),
    (i + 1, j + 1), (i + 1, j) (module docstring).
    """
    h, dx, dy = relief.heights, relief.dx, relief.dy
    a, b, c, d = h[:-1, :-1], h[:-1, 1:], h[1:, 1:], h[1:, :-1]
    x0, y0 = np.meshgrid(relief.xs[:-1], relief.ys[:-1])
    cx = np.stack([x0 + 2 * dx / 3, x0 + dx / 3])
    cy = np.stack([y0 + dy / 3, y0 + 2 * dy / 3])
    cz = np.stack([(a + b + c) / 3, (a + c + d) / 3])
    gx = np.stack([(b - a) / dx, (c - d) / dx])  # each flat face's slope along x and y
    gy = np.stack([(c - b) / dy, (d - a) / dy])
    n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    return np.stack([cx, cy, cz], axis=-1), n / np.linalg.norm(n, axis=-1, keepdims=True)


def vertex_points(relief: Relief) -> tuple[np.ndarray, np.ndarray]:
    """The grid's vertices and their normals (central differences): two (Ny, Nx, 3) arrays, mm and unit."""
    x, y = np.meshgrid(relief.xs, relief.ys)
    gy, gx = np.gradient(relief.heights, relief.dy, relief.dx)
    n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    return np.stack([x, y, relief.heights], axis=-1), n / np.linalg.norm(n, axis=-1, keepdims=True)


def _points(relief: Relief, points: np.ndarray | None, normals: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    if points is None:
        return vertex_points(relief)
    if normals is None or np.shape(points) != np.shape(normals) or np.shape(points)[-1] != 3:
        raise ValueError("points and normals must both be given, (..., 3) of one shape")
    n = np.asarray(normals, np.float64)
    return np.asarray(points, np.float64), n / np.linalg.norm(n, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- horizons


def horizon(relief: Relief, p: np.ndarray, d: np.ndarray, enough: np.ndarray | None = None) -> np.ndarray:
    """The highest slope ``(z - p_z) / distance`` of the surface seen from points ``p`` along directions ``d``.

    Marched from half a cell out, steps growing by :data:`STEP_GROWTH`, until the grid ends or nothing
    further can rise higher (the relief's highest point at that distance is under the slope found).

    Args:
        p: (P, 3) points, mm. d: (P, 2) or (2,) unit plan directions.
        enough: (P,) a slope past which the exact value does not matter (a lamp's elevation: the point
            is in shadow); None: the exact highest slope.

    Returns:
        (P,) tangent of the horizon's elevation; -inf where the march left the grid at once.
    """
    p = np.asarray(p, np.float64)
    d = np.broadcast_to(np.asarray(d, np.float64), (p.shape[0], 2))
    best = np.full(p.shape[0], -np.inf)
    floor = np.full(p.shape[0], -np.inf) if enough is None else np.asarray(enough, np.float64)
    top = float(relief.heights.max())
    reach = math.hypot(relief.xs[-1] - relief.xs[0], relief.ys[-1] - relief.ys[0])
    live = np.arange(p.shape[0])
    t = 0.5 * min(relief.dx, relief.dy)
    while live.size and t <= reach:
        z, inside = relief.height_at(p[live, 0] + t * d[live, 0], p[live, 1] + t * d[live, 1])
        slope = np.where(inside, (z - p[live, 2]) / t, -np.inf)
        best[live] = np.maximum(best[live], slope)
        t *= STEP_GROWTH
        # nothing beyond t can rise above (top - p_z) / t: stop there, and where the march left the grid
        more = inside & ((top - p[live, 2]) / t > np.maximum(best[live], floor[live]))
        live = live[more]
    return best


def _sky_above(a: np.ndarray, b: np.ndarray, low: np.ndarray) -> np.ndarray:
    """``integral_low^(pi/2) max(a cos e + b sin e, 0) cos e de``: one azimuth's cosine-weighted sky.

    ``a`` = the normal's component along the azimuth, ``b`` its z (> 0), ``low`` the lowest elevation
    seen (rad); the integrand is positive above ``atan(-a / b)``, the tangent plane, where the lower
    limit is raised to. Antiderivative ``a (e/2 + sin 2e / 4) + b sin^2 e / 2``.
    """
    lo = np.maximum(low, np.arctan2(-a, b))

    def f(e: np.ndarray | float) -> np.ndarray:
        return a * (np.asarray(e) / 2 + np.sin(2 * np.asarray(e)) / 4) + b * np.sin(e) ** 2 / 2

    return f(np.pi / 2) - f(lo)


def ambient_occlusion(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray, directions: int = DIRECTIONS,
                      *, points: np.ndarray | None = None, normals: np.ndarray | None = None) -> np.ndarray:
    """The cosine-weighted share of the sky each point sees over the heightfield, in [0, 1].

    For each of ``directions`` (K) azimuths ``2 pi (k + 1/2) / K`` the horizon (:func:`horizon`) and
    the closed form :func:`_sky_above`; their sum times ``2 pi / K`` over pi (the whole hemisphere's
    cosine integral). What a uniform environment lights (ROOM_AMBIENT).

    Args:
        xs_mm, ys_mm, heights_mm: the grid (:class:`Relief`).
        points, normals: (..., 3) where to evaluate, mm, and the surface's normals there (e.g.
            :func:`face_points`); None: the grid's vertices (:func:`vertex_points`).

    Returns:
        (...) the points' shape ((Ny, Nx) for the vertices).
    """
    relief = Relief.of(xs_mm, ys_mm, heights_mm)
    p, n = _points(relief, points, normals)
    shape = p.shape[:-1]
    p, n = p.reshape(-1, 3), n.reshape(-1, 3)
    total = np.zeros(p.shape[0])
    for k in range(int(directions)):
        phi = 2.0 * np.pi * (k + 0.5) / directions
        d = np.array([math.cos(phi), math.sin(phi)])
        low = np.arctan(horizon(relief, p, d))  # -inf -> -pi/2: nothing in the way
        total += _sky_above(n[:, :2] @ d, n[:, 2], low)
    return np.clip(total * (2.0 / directions), 0.0, 1.0).reshape(shape)  # (2 pi / K) / pi


# --------------------------------------------------------------------------- the lamp


def lamp_reading(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray, lamp: LampPlacement, *,
                 points: np.ndarray | None = None, normals: np.ndarray | None = None, split: int = LAMP_SPLIT,
                 quad: int = LAMP_QUAD) -> np.ndarray:
    """What a white Lambertian surface reads under the lamp alone: ``L / pi * integral V cos cos / r^2 dA``.

    In the lighting module's units (:mod:`saucerfab.verify.lighting`: a white paper lying flat at the
    cup's foot reads the lamp's power). The lamp (one-sided, facing its target) is split into
    ``split`` x ``split`` squares, each integrated by a ``quad`` x ``quad`` midpoint rule and seen or
    hidden as a whole from its centre (:func:`horizon` towards it).

    Args:
        lamp: the lamp in the file frame (:func:`saucerfab.verify.lighting.place_lamp`).
        points, normals: as :func:`ambient_occlusion`.

    Returns:
        (...) the points' shape.
    """
    relief = Relief.of(xs_mm, ys_mm, heights_mm)
    p, n = _points(relief, points, normals)
    shape = p.shape[:-1]
    p, n = p.reshape(-1, 3), n.reshape(-1, 3)
    ln = lamp.target - lamp.center
    ln = ln / np.linalg.norm(ln)
    ref = np.array([0.0, 0.0, 1.0]) if abs(float(ln[2])) < 0.99 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(ln, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(ln, e1)
    side = lamp.size_mm / split
    total = np.zeros(p.shape[0])
    for u in range(split):
        for v in range(split):
            cu, cv = (u + 0.5) * side - lamp.size_mm / 2, (v + 0.5) * side - lamp.size_mm / 2
            k = ((np.arange(quad) + 0.5) / quad - 0.5) * side
            form = np.zeros(p.shape[0])
            for ku in k:
                for kv in k:
                    r = lamp.center + (cu + ku) * e1 + (cv + kv) * e2 - p  # (P, 3) to the lamp's point
                    r2 = np.sum(r * r, axis=1)
                    inv = 1.0 / np.sqrt(r2)
                    form += (np.clip(np.sum(n * r, axis=1) * inv, 0, None) * np.clip(-(r @ ln) * inv, 0, None) / r2)
            c = lamp.center + cu * e1 + cv * e2 - p
            flat = np.hypot(c[:, 0], c[:, 1])
            rise = c[:, 2] / np.maximum(flat, 1e-12)
            seen = horizon(relief, p, c[:, :2] / np.maximum(flat, 1e-12)[:, None], enough=rise) <= rise
            total += np.where(seen, form, 0.0) * (side / quad) ** 2
    return (lamp.radiance / math.pi * total).reshape(shape)


# --------------------------------------------------------------------------- the shading and its pattern


def light_frame(model_to_file: np.ndarray, camera_model: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The lighting frame's origin and direction in the file frame (as :mod:`saucerfab.verify.lit` reads them
    from scene.json): the cup's foot (its axis at its standing plane: the model's origin), (3,) mm, and
    the horizontal direction from it to the design eye, (2,) unit."""
    m = np.asarray(model_to_file, np.float64)
    foot = (m @ np.array([0.0, 0.0, 0.0, 1.0]))[:3]
    eye = (m @ np.array([*camera_model, 1.0]))[:3]
    toward = eye[:2] - foot[:2]
    norm = float(np.linalg.norm(toward))
    return foot, (toward / norm if norm > 0 else np.array([0.0, -1.0]))


def shading(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray, light: str, foot: np.ndarray,
            toward_xy: np.ndarray, directions: int = DIRECTIONS) -> np.ndarray:
    """``S`` of each top triangle under ``light`` (:data:`LIGHT_NAMES`), (2, Ny - 1, Nx - 1).

    ``ambient``: the ambient occlusion (a white surface under a uniform environment of radiance 1);
    ``room``: ``ROOM_AMBIENT * AO + lamp`` (verify's ``--light room``: :data:`~saucerfab.verify.lighting.ROOM_LAMP`
    placed by ``foot`` (3,) mm and ``toward_xy`` (2,), :func:`light_frame`).
    """
    if light not in LIGHT_NAMES:
        raise ValueError(f"light must be one of {LIGHT_NAMES}, got {light!r}")
    relief = Relief.of(xs_mm, ys_mm, heights_mm)
    pts, nrm = face_points(relief)
    ao = ambient_occlusion(relief.xs, relief.ys, relief.heights, directions, points=pts, normals=nrm)
    if light == "ambient":
        return ao
    lamp = place_lamp(ROOM_LAMP, foot, toward_xy)
    return ROOM_AMBIENT * ao + lamp_reading(relief.xs, relief.ys, relief.heights, lamp, points=pts, normals=nrm)


def smooth_sigma_mm(xs_mm: np.ndarray, ys_mm: np.ndarray) -> float:
    """The pattern's low-pass width: the top's longer side times verify's ``SMOOTH_SIGMA_FRACTION``, mm."""
    return float(max(xs_mm[-1] - xs_mm[0], ys_mm[-1] - ys_mm[0]) * SMOOTH_SIGMA_FRACTION)


def shading_pattern(s: np.ndarray, xs_mm: np.ndarray, ys_mm: np.ndarray, sigma_mm: float,
                    views: np.ndarray | None = None) -> np.ndarray:
    """``P = S / smooth(S)``, (2, Ny - 1, Nx - 1).

    The smooth part: a Gaussian of ``sigma_mm`` on the plan by normalized convolution over the
    triangles of one view (both triangles of a cell at its centre). Verify low-passes each view's
    picture, which shows that view's faces only: the direct picture the slopes facing the viewer, the
    cup the slopes facing it, lit very differently (on the heart-star default top under the room light,
    the reflected faces read 0.13-0.74, the direct ones 0.43-0.78, 5th-95th percentile). So with
    ``views`` (2, Ny - 1, Nx - 1) :class:`~saucerfab.model.design.FaceView` values, a face seen in
    one picture is held to that picture's faces around it, a face seen in both to the geometric
    mean of the two, any other to all faces; None: every face to all faces.
    """
    from scipy.ndimage import gaussian_filter

    from saucerfab.model.design import FaceView

    dx, dy = float(xs_mm[-1] - xs_mm[0]) / (len(xs_mm) - 1), float(ys_mm[-1] - ys_mm[0]) / (len(ys_mm) - 1)
    s = np.asarray(s, np.float64)
    sig = (sigma_mm / dy, sigma_mm / dx)

    def smooth(mask: np.ndarray) -> np.ndarray:
        den = gaussian_filter(mask.mean(axis=0), sig, mode="constant")
        num = gaussian_filter((s * mask).mean(axis=0), sig, mode="constant")
        return np.where(den > 1e-6, num / np.maximum(den, 1e-12), np.nan)[None]

    every = np.broadcast_to(smooth(np.ones(s.shape)), s.shape)
    if views is None:
        return s / np.maximum(every, 1e-9)
    v = np.asarray(views)
    both = v == FaceView.BOTH
    direct = np.broadcast_to(smooth((v == FaceView.DIRECT) | both), s.shape)
    reflected = np.broadcast_to(smooth((v == FaceView.REFLECTED) | both), s.shape)
    base = np.where(v == FaceView.DIRECT, direct, np.where(v == FaceView.REFLECTED, reflected, every))
    base = np.where(both, np.sqrt(direct * reflected), base)
    base = np.where(np.isfinite(base) & (base > 0), base, every)
    return s / np.maximum(base, 1e-9)


# --------------------------------------------------------------------------- the page


def texel_faces(layout: AtlasLayout, nx: int, ny: int, rows: slice | None = None) -> tuple[np.ndarray, ...]:
    """The top triangle under each top texel's centre: (triangle, cell row i, cell column j), each (h, top.w).

    The inverse of the layout's piecewise-linear planar map (:mod:`.atlas`): a texel centre's page x
    gives the grid's fractional column, its y the fractional row (rows run up the page).

    Args:
        nx, ny: the grid's columns and rows.
        rows: the top's texel rows to map (None: all ``top.h``).
    """
    t = layout.top
    r = np.arange(t.h)[rows if rows is not None else slice(None)]
    fx = np.interp(np.arange(t.x, t.x + t.w) + 0.5, layout.col_px, np.arange(nx, dtype=np.float64))
    fy = np.interp(t.y + r + 0.5, layout.row_px[::-1],
                   np.arange(ny, dtype=np.float64)[::-1])
    j = np.clip(np.floor(fx), 0, nx - 2).astype(np.int64)
    i = np.clip(np.floor(fy), 0, ny - 2).astype(np.int64)
    s, tt = fx - j, fy - i
    tri = (s[None, :] < tt[:, None]).astype(np.int64)  # 0 below the diagonal (s >= t)
    return tri, np.broadcast_to(i[:, None], tri.shape), np.broadcast_to(j[None, :], tri.shape)


def global_factor(lin: np.ndarray, divided: np.ndarray, seen: np.ndarray, percentile: float = CLIP_PERCENTILE,
                  max_darkening: float = MAX_DARKENING) -> float:
    """The compensation's one factor ``g`` (module docstring), from a sample of the top's texel channels.

    Args:
        lin: (N,) their plain linear albedo; divided: (N,) it over ``P^k``.
        seen: (N,) bool, those of a triangle some view sees: the ``percentile``'s (none: all).
        max_darkening: the mean of ``min(divided / g, 1)`` stays at least ``mean(lin) / max_darkening``.

    Returns:
        ``g >= 1``: the ``percentile``'s factor, or less, the largest that keeps the mean.
    """
    if not divided.size:
        return 1.0
    high = max(float(np.percentile(divided[seen] if seen.any() else divided, percentile)), 1.0)
    want = float(np.mean(lin, dtype=np.float64)) / max_darkening

    def mean_at(g: float) -> float:  # mean(min(d / g, 1)), falling as g grows
        return float(np.mean(np.minimum(divided, np.float32(g)), dtype=np.float64)) / g

    if mean_at(high) >= want:
        return high
    lo, hi = 1.0, high
    if mean_at(lo) < want:  # the division alone darkens the top that much: no further
        return 1.0
    for _ in range(24):  # to ~1e-7 of the factor
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mean_at(mid) >= want else (lo, mid)
    return lo


def compensate_page(page: np.ndarray, layout: AtlasLayout, pattern: np.ndarray, seen: np.ndarray | None = None, *,
                    power: float = COMPENSATION_POWER,
                    max_darkening: float = MAX_DARKENING) -> tuple[np.ndarray, dict[str, float]]:
    """The page with its top's linear albedo ``a`` made ``min(a / pattern^power / g, 1)``; gutter redone.

    Args:
        page: (S, S, 3) sRGB, uint8 (as the bake makes it) or float in [0, 1].
        pattern: (2, Ny - 1, Nx - 1) ``P`` per top triangle (:func:`shading_pattern`).
        seen: (2, Ny - 1, Nx - 1) bool, the triangles some view sees (None: all): the clip percentile's
            texels (a face no one sees may clip); the brightness is the whole top's.
        power, max_darkening: ``k`` and the bound of :func:`global_factor` (module docstring).

    Returns:
        The new page (``page``'s dtype) and ``{"global_factor", "clipped_share", "brightness_ratio"}``:
        the share of the top's texel channels clipped at 1, and the top's mean linear albedo over the
        plain page's.
    """
    _two, ny1, nx1 = pattern.shape
    t = layout.top
    src = page[t.y:t.y + t.h, t.x:t.x + t.w]
    lut = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0) if page.dtype == np.uint8 else None
    step = max(1, CHUNK_TEXELS // max(t.w, 1))
    chunks = [slice(r, min(r + step, t.h)) for r in range(0, t.h, step)]
    divisor = (np.asarray(pattern, np.float64) ** power).astype(np.float32)
    seen = np.ones(pattern.shape, bool) if seen is None else np.asarray(seen, bool)

    def divided(rows: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows' plain linear albedo, it over P^k (both (h, top.w, 3)) and their seen mask (h, top.w, 3)."""
        tri, i, j = texel_faces(layout, nx1 + 1, ny1 + 1, rows)
        lin = lut[src[rows]] if lut is not None else srgb_to_linear(src[rows])
        return lin, lin / divisor[tri, i, j][..., None], np.broadcast_to(seen[tri, i, j][..., None], lin.shape)

    # the factor from every texel of every row, or of a quarter of the rows of a large top (millions of texels)
    every = min(4, max(1, t.w * t.h // CHUNK_TEXELS))
    parts = [divided(slice(c.start, c.stop, every)) for c in chunks] or [(np.zeros(0),) * 3]
    lin_s, div_s, seen_s = (np.concatenate([p[k].ravel() for p in parts]) for k in range(3))
    factor = global_factor(lin_s, div_s, seen_s.astype(bool), max_darkening=max_darkening)
    del parts, lin_s, div_s, seen_s
    out = page.copy()
    region = out[t.y:t.y + t.h, t.x:t.x + t.w]
    clipped, plain_sum, new_sum = 0, 0.0, 0.0
    for rows in chunks:
        lin, div, _seen = divided(rows)
        div /= np.float32(factor)
        clipped += int(np.count_nonzero(div > 1.0))
        plain_sum += float(lin.sum(dtype=np.float64))
        new_sum += float(np.minimum(div, 1.0).sum(dtype=np.float64))
        srgb = linear_to_srgb(div)  # clips to [0, 1]
        region[rows] = np.clip(np.rint(srgb * 255.0), 0, 255).astype(np.uint8) if page.dtype == np.uint8 else srgb
    refill_gutter(out, layout)
    return out, {"global_factor": factor, "clipped_share": clipped / max(src.size, 1),
                 "brightness_ratio": new_sum / plain_sum if plain_sum > 0 else 1.0}


def compensate_top_shading(page: np.ndarray, layout: AtlasLayout, xs_mm: np.ndarray, ys_mm: np.ndarray,
                           heights_mm: np.ndarray, light: str, foot: np.ndarray, toward_xy: np.ndarray,
                           views: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """The export's page with its top compensated for the shading under ``light``, and its record.

    :func:`shading` -> :func:`shading_pattern` (per view
    with ``views``, the design's :class:`~saucerfab.model.design.FaceView` per top triangle,
    (2, Ny - 1, Nx - 1)) -> :func:`compensate_page` (its factor over the faces some view sees).

    Returns:
        The new (S, S, 3) page and export.json's ``shading`` block: the light (as verify names it), the
        low-pass width, the azimuths, the pattern's 5th and 95th percentiles (the
        seen triangles), the power ``k`` and the darkening bound, the global factor, the clipped share
        and the brightness ratio (the top's mean linear albedo over the plain page's).
    """
    from saucerfab.model.design import FaceView

    s = shading(xs_mm, ys_mm, heights_mm, light, foot, toward_xy)
    sigma = smooth_sigma_mm(xs_mm, ys_mm)
    pattern = shading_pattern(s, xs_mm, ys_mm, sigma, views)
    seen = None if views is None else np.asarray(views) != FaceView.NEITHER
    new, stats = compensate_page(page, layout, pattern, seen=seen)
    p5, p95 = np.percentile(pattern if seen is None or not seen.any() else pattern[seen], [5, 95])
    light_d: dict[str, Any] = {"kind": light, "ambient": 1.0 if light == "ambient" else ROOM_AMBIENT,
                               "lamp": None if light == "ambient" else ROOM_LAMP.to_dict()}
    record = {"light": light_d, "smooth_sigma_mm": round(sigma, 6), "directions": DIRECTIONS,
              "per_view": views is not None,
              "pattern_p5_p95": [round(float(p5), 6), round(float(p95), 6)],
              "power": COMPENSATION_POWER, "max_darkening": MAX_DARKENING,
              "global_factor": round(stats["global_factor"], 6), "clipped_share": round(stats["clipped_share"], 6),
              "brightness_ratio": round(stats["brightness_ratio"], 6)}
    return new, record


def face_views(face_view: np.ndarray | None, nx: int, ny: int) -> np.ndarray | None:
    """A design's per-face :class:`~saucerfab.model.design.FaceView` (2 (N-1)^2,), faces in
    :func:`saucerfab.model.heightfield.triangulate`'s order (cell by cell, its two triangles in this
    module's order), as (2, Ny - 1, Nx - 1); None when absent or of another grid."""
    if face_view is None:
        return None
    v = np.asarray(face_view)
    if v.size != 2 * (nx - 1) * (ny - 1):
        return None
    return v.reshape(ny - 1, nx - 1, 2).transpose(2, 0, 1)
