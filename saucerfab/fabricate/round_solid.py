"""The round saucer's part: the heightfield block cut to a disc, with the cup's seat at its centre.

A disc saucer (:attr:`saucerfab.model.scene.Saucer.is_disc`) is the circle
inscribed in the square heightfield grid, centred on the cup's axis (model
x = y = 0). :func:`saucerfab.fabricate.solid.build_solid` builds the same
block as for the rectangle (the N x N top, four walls, a flat bottom) and
hands it to :func:`disc_part`, which makes, all in model millimetres and all
with manifold3d::

    ((block + seat + rim) - pocket) ^ cylinder

* the *cylinder*: a prism over the disc's outline, a regular polygon whose
  vertices lie on the circle of the saucer's radius and whose chords stray
  from it by at most :data:`CHORD_MM` (the segment count comes from that
  error, as :func:`saucerfab.fabricate.seat.cup_outline_mm` chooses the
  cup's). The polygon is turned half a segment so no vertex lies on the
  square's walls (the disc touches them at four points): the cylinder then
  lies strictly inside the block's square, so its walls never meet the
  block's walls face to face. It reaches below the bottom and above the top,
  so the part's bottom and top stay the block's: the top faces are the
  heightfield's faces that survive (their face ids pass through the booleans,
  as for the rectangle) and the cylinder's wall is a side.
* the *seat* (``FabOptions.seat``), at the centre, inside the scene's cup
  ring (:data:`saucerfab.model.scene.CUP_RING_MM`, which holds no design;
  :func:`saucerfab.fabricate.seat.seat_ring_problem` lists options wider than
  it):

  - ``recess`` (the default): a pocket of the cup's footprint grown by
    ``seat_clearance_mm``, its floor exactly the cup's standing plane (model
    z = 0), walled by a rim ``seat_rim_mm`` wide whose top is
    ``seat_depth_mm`` above the floor; where the relief around is higher
    than the rim, the relief is the pocket's wall.
  - ``ring``: on a disc the same part as ``recess``. The rectangle's two
    kinds differ in what stands on its plate (a pocket sunk into it, or a
    ring raised from it); on a disc there is no plate, only the saucer
    itself, and a pocket walled by a rim *is* a ring standing round the
    cup's floor. ``scene.json`` and ``export.json`` record the kind asked for.
  - ``none``: the pocket's flat floor at z = 0 (the cup's footprint grown by
    the clearance) without the raised rim; where the relief around is higher
    than the floor it still walls it. Unlike the rectangle's ``none`` the cup
    needs no support (its floor is in the part, at the height the design
    assumes), so there is no warning.

  The seat's solid (the grown outline from just above the part's bottom up
  to the rim's top, or to the floor for ``none``) starts inside the block's
  material (:func:`seat_base_z`), so no face of it lies on the bottom.

* the *rim* (``FabOptions.saucer_rim_mm`` > 0; none by default): a ring
  ``saucer_rim_mm`` wide at the disc's outer edge, from inside the block's
  material (:func:`seat_base_z`) up to ``saucer_rim_height_mm`` above the
  highest point of the relief under it (:func:`relief_top_under`). Its inside is a
  polygon with its vertices on the circle of radius R - width (chords
  within :data:`CHORD_MM`); its outside reaches past the disc, so the
  cylinder cuts it and the part's side wall stays one wall. Its faces
  (top, inside wall) are sides, not top: the bake paints them with the
  sides' colours. :func:`check_rim` refuses a rim on a rectangle and one
  wide enough to reach the cup's ring; one narrower than the printer's
  minimum wall is a problem (``FabOptions.walls_under``).

Nothing here depends on the rectangle's exact-contact machinery
(:func:`saucerfab.fabricate.solid.footprint_on_clipper_grid`): no face of
the seat or the cylinder meets a face of the block face to face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.seat import OUTLINE_EPS_MM, cross_section, cup_outline_mm
from saucerfab.model.scene import CUP_RING_MM, Scene

#: the largest distance between the disc's outline polygon and its circle (the chords' sagitta), mm
CHORD_MM = 0.01
#: the least distance kept between the disc's outline and the heightfield grid's vertices and lines, mm
GRID_GAP_MM = 2e-3
#: the outline's radius is shrunk in steps of this until it keeps GRID_GAP_MM, at most NUDGE_STEPS times, mm
NUDGE_MM = 5e-4
NUDGE_STEPS = 40
#: how far the cylinder and the pocket's cut reach past the part's bottom and top, mm (any positive length)
OVERSHOOT_MM = 1.0


def disc_segments(radius_mm: float, chord_mm: float = CHORD_MM) -> int:
    """Sides of a regular polygon inscribed in a circle of ``radius_mm`` whose chords stray at most ``chord_mm``.

    The sagitta of a side is ``r (1 - cos(pi / n))``; ``n`` is rounded up to a
    multiple of 4 so the outline (and the part's bounding box) is the same
    along x and y.
    """
    r = float(radius_mm)
    n = math.ceil(math.pi / math.acos(max(1.0 - chord_mm / r, -1.0)))
    return max(16, 4 * math.ceil(n / 4))


def disc_outline_mm(radius_mm: float, chord_mm: float = CHORD_MM) -> np.ndarray:
    """The disc's outline about its centre, (n, 2) mm, counter-clockwise, every vertex at ``radius_mm``.

    Vertex k is at angle ``(k + 1/2) 2 pi / n``: half a segment off the axes,
    so the polygon lies strictly inside the square ``[-r, r]^2`` (by
    ``r (1 - cos(pi / n))``, at most ``chord_mm``) and never touches the
    heightfield block's walls.
    """
    n = disc_segments(radius_mm, chord_mm)
    a = (np.arange(n) + 0.5) * (2.0 * np.pi / n)
    return float(radius_mm) * np.stack([np.cos(a), np.sin(a)], axis=1)


def grid_gap_mm(outline: np.ndarray, xs_mm: np.ndarray, ys_mm: np.ndarray) -> float:
    """The least distance from the heightfield grid's vertices (``xs_mm`` x ``ys_mm``) to the sides of the
    polygon ``outline`` (n, 2), mm (only the vertices within two grid steps of its radii are measured)."""
    h = float(xs_mm[1] - xs_mm[0])
    r = np.hypot(outline[:, 0], outline[:, 1])
    gx, gy = np.meshgrid(xs_mm, ys_mm)
    rg = np.hypot(gx, gy)
    near = (rg > r.min() - 2.0 * h) & (rg < r.max() + 2.0 * h)  # the grid's vertices beside the outline
    p = np.stack([gx[near], gy[near]], axis=1)
    a, b = outline, np.roll(outline, -1, axis=0)
    ab = b - a
    t = np.clip(((p[:, None, :] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0.0, 1.0)
    return float(np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=-1).min())


def clear_outline_mm(radius_mm: float, xs_mm: np.ndarray, ys_mm: np.ndarray) -> np.ndarray:
    """:func:`disc_outline_mm` at the largest radius a little under ``radius_mm`` whose polygon keeps
    :data:`GRID_GAP_MM` from the grid (:func:`grid_gap_mm`; of :data:`NUDGE_STEPS` tries, the clearest).

    Where the polygon passes a hair from a grid vertex the cut leaves triangles of under a tenth of a
    square micrometre that a checker calls zero-area (``check``'s degenerate faces); shrinking the
    circle by micrometres moves it off them.
    """
    best, best_gap = disc_outline_mm(radius_mm), -1.0
    for k in range(NUDGE_STEPS + 1):
        outline = disc_outline_mm(radius_mm - k * NUDGE_MM)
        gap = grid_gap_mm(outline, xs_mm, ys_mm)
        if gap > best_gap:
            best, best_gap = outline, gap
        if gap >= GRID_GAP_MM:
            break
    return best


def clear_level(z_mm: float, block: object, reach_mm: float) -> float:
    """``z_mm`` raised by micrometres until no vertex of ``block`` (a manifold3d ``Manifold``, model mm) within
    ``reach_mm`` of the cup's axis lies within :data:`GRID_GAP_MM` of that height (of :data:`NUDGE_STEPS`
    tries, the clearest): the seat rim's flat top cuts the relief along its contour there, and a contour
    passing a hair from a vertex leaves triangles a checker calls zero-area."""
    v = np.asarray(block.to_mesh().vert_properties, np.float64)
    z = v[np.hypot(v[:, 0], v[:, 1]) <= reach_mm, 2]
    best, best_gap = float(z_mm), -1.0
    for k in range(NUDGE_STEPS + 1):
        level = float(z_mm) + k * NUDGE_MM
        gap = float(np.abs(z - level).min()) if z.size else math.inf
        if gap > best_gap:
            best, best_gap = level, gap
        if gap >= GRID_GAP_MM:
            break
    return best


def seat_base_z(z_bottom: float, options: FabOptions) -> float:
    """Where the seat's solid starts, model mm: inside the block's material everywhere, below z = 0.

    The block is solid from ``z_bottom`` up to its top, which lies at least
    ``min_thickness_mm`` above ``z_bottom``; ``z_bottom`` itself is at most
    ``-base_thickness_mm``. Half the smaller of the two above the bottom is
    therefore under the top everywhere and under the cup's standing plane,
    and off the bottom's plane (no coplanar faces to join).
    """
    return z_bottom + 0.5 * min(options.base_thickness_mm, options.min_thickness_mm)


def check_rim(scene: Scene, mm_per_unit: float, options: FabOptions) -> None:
    """Refuse a raised rim (``options.saucer_rim_mm``) the part cannot have; nothing without one.

    Raises:
        ConfigError: a rim asked for on a rectangle saucer (it only runs round
            a disc), or one so wide that its inside (R - width from the cup's
            axis) reaches the cup's footprint and its ring
            (:data:`saucerfab.model.scene.CUP_RING_MM`), where the seat
            stands; the message names the largest width that fits.
    """
    width = options.saucer_rim_mm
    if not width:
        return
    if not scene.saucer.is_disc:
        raise ConfigError(
            f"--saucer-rim-mm {width:g} asks for a raised rim round a round saucer's edge, but this design's "
            "saucer is a rectangle; leave --saucer-rim-mm out, or design with --scene round for a round saucer"
        )
    s = float(mm_per_unit)
    radius = scene.saucer.radius * s
    reach = float(np.hypot(*cup_outline_mm(scene, s).T).max())  # the cup's farthest point from its axis, mm
    room = radius - reach - CUP_RING_MM  # the rim's inside must stay farther out than this
    if width >= room - 1e-9:
        largest = math.floor(room * 100.0 - 1e-6) / 100.0  # just under: a width of `room` touches the ring
        raise ConfigError(
            f"--saucer-rim-mm {width:g} is too wide: the rim's inside, {radius - width:.2f} mm from the cup's axis, "
            f"would reach the cup ({reach:.2f} mm) and its {CUP_RING_MM:g} mm seat ring on the "
            f"{2.0 * radius:.1f} mm saucer; give --saucer-rim-mm {largest:g} or less"
        )


def rim_over_picture(scene: Scene, mm_per_unit: float, options: FabOptions, xs_mm: np.ndarray, ys_mm: np.ndarray,
                     heights_mm: np.ndarray) -> str | None:
    """A warning when the rim covers part of the direct picture; None without a rim or when it covers none.

    The design does not know the export's rim: a direct picture that reaches
    the disc's edge loses its outer ``saucer_rim_mm`` under it. Counted on the
    grid vertices under the ring that the design eye sees as design
    (:func:`saucerfab.model.footprint.direct_vertices`) inside the direct
    frame's picture (its ``extent``); the message says how near the edge the
    picture comes.

    Args:
        xs_mm, ys_mm: (N,) the grid's columns and rows, model mm.
        heights_mm: (N, N) the relief, model mm (row i at ``ys_mm[i]``).
    """
    from saucerfab.model.camera import Camera
    from saucerfab.model.footprint import direct_vertices

    width = options.saucer_rim_mm
    if not width or not scene.saucer.is_disc:
        return None
    s = float(mm_per_unit)
    radius = scene.saucer.radius * s
    gx, gy = np.meshgrid(xs_mm, ys_mm)
    pts = np.stack([gx.ravel(), gy.ravel(), np.asarray(heights_mm, np.float64).ravel()], axis=1) / s
    r = np.hypot(gx.ravel(), gy.ravel())
    band = np.flatnonzero((r > radius - width) & (r <= radius * (1.0 + 1e-9)))
    seen = band[direct_vertices(scene, pts[band])]
    ndc = Camera.from_scene(scene, "direct").project(pts[seen])
    ex, ey = scene.direct.extent
    covered = seen[(ndc[:, 2] > 0) & (np.abs(ndc[:, 0]) <= ex) & (np.abs(ndc[:, 1]) <= ey)]
    if covered.size == 0:
        return None
    gap = radius - float(r[covered].max())  # how near the edge the picture's grid vertices come, mm
    return (f"the direct picture reaches within {gap:.1f} mm of the round saucer's edge, so the {width:g} mm saucer "
            f"rim covers part of it ({covered.size} of its grid vertices; the rim's height hides a little more "
            "from the eye); a narrower --saucer-rim-mm, or none, covers less, and 'saucerfab verify' shows what it "
            "costs")


def relief_top_under(block: object, ring: object, z_bottom: float, z_top: float) -> float:
    """The highest point of the block's top over the 2-D region ``ring``, model mm.

    Exact for the triangulated relief: the block is cut to a prism over
    ``ring`` (a manifold3d ``CrossSection``) and the cut's highest vertex
    taken, whether a grid vertex or where a top triangle meets the ring's
    walls.

    Args:
        block: the saucer block (a manifold3d ``Manifold``), model mm.
        ring: the region, model mm (the rim's footprint on the disc).
        z_bottom, z_top: the block's bottom and highest point, model mm.
    """
    import manifold3d as m3d

    low, high = z_bottom - OVERSHOOT_MM, z_top + OVERSHOOT_MM
    cut = block ^ m3d.Manifold.extrude(ring, high - low).translate((0.0, 0.0, low))
    return float(cut.bounding_box()[5])


@dataclass(frozen=True)
class DiscPart:
    """What :func:`disc_part` built.

    Attributes:
        solid: the part (a lazy manifold3d ``Manifold``), model mm.
        pocket: (K, 2) the seat's pocket outline (the cup's footprint grown by
            the clearance), model mm, counter-clockwise.
        top_z: the seat rim's top over the cup's standing plane, mm
            (``seat_depth_mm``; 0 for ``none``).
        segments: sides of the disc's outline polygon.
        rim_top_z: the saucer rim's top, model mm (``saucer_rim_height_mm``
            over :func:`relief_top_under` the rim); None
            without a rim.
    """

    solid: object
    pocket: np.ndarray
    top_z: float
    segments: int
    rim_top_z: float | None = None


def disc_part(block: object, scene: Scene, mm_per_unit: float, options: FabOptions, z_bottom: float,
              z_top: float, grid_mm: tuple[np.ndarray, np.ndarray] | None = None) -> DiscPart:
    """The round part from the heightfield ``block`` (a manifold3d ``Manifold``, model mm).

    Args:
        block: the saucer block over the square grid, model mm.
        scene: the design's scene (a disc saucer, the cup at its centre).
        mm_per_unit: millimetres per model unit.
        options: the seat's kind and sizes, and the saucer rim's
            (:func:`check_rim` has passed them).
        z_bottom: the block's flat bottom, model mm (below 0).
        z_top: the block's highest point, model mm.
        grid_mm: the block's grid (xs, ys), model mm: the outlines keep clear of it
            (:func:`clear_outline_mm`); None: the exact circles.
    """
    import manifold3d as m3d

    s = float(mm_per_unit)
    radius = scene.saucer.radius * s
    outline = disc_outline_mm(radius) if grid_mm is None else clear_outline_mm(radius, *grid_mm)
    base = seat_base_z(z_bottom, options)
    parts = [block]
    rim_top = None
    if options.saucer_rim_mm > 0:
        inner_r = radius - options.saucer_rim_mm
        inside = cross_section(disc_outline_mm(inner_r) if grid_mm is None else clear_outline_mm(inner_r, *grid_mm))
        under = relief_top_under(block, cross_section(outline) - inside, z_bottom, z_top)
        rim_top = under + options.saucer_rim_height_mm
        # outside past the disc: the cylinder below cuts it on the part's own side wall
        ring = cross_section(disc_outline_mm(radius + OVERSHOOT_MM)) - inside
        parts.append(m3d.Manifold.extrude(ring, rim_top - base).translate((0.0, 0.0, base)))
    high = max(z_top, options.seat_depth_mm, rim_top or 0.0) + OVERSHOOT_MM
    low = z_bottom - OVERSHOOT_MM
    cylinder = m3d.Manifold.extrude(cross_section(outline), high - low).translate((0.0, 0.0, low))

    cup_cs = cross_section(cup_outline_mm(scene, s))
    # Clipper's round joins can leave vertex pairs ~1e-8 mm apart; simplify() drops them
    inner = (
        cup_cs.offset(options.seat_clearance_mm, m3d.JoinType.Round).simplify(OUTLINE_EPS_MM)
        if options.seat_clearance_mm > 0
        else cup_cs
    )
    if options.seat == "none":
        seat_cs, seat_top = inner, 0.0  # the floor alone: its top is the pocket's floor
    else:
        seat_cs = cup_cs.offset(options.seat_clearance_mm + options.seat_rim_mm, m3d.JoinType.Round).simplify(
            OUTLINE_EPS_MM
        )
        step = float(grid_mm[0][1] - grid_mm[0][0]) if grid_mm is not None else 1.0
        # the relief's vertices of the cells the seat's outline crosses: up to two grid steps past it
        reach = scene.cup.circumradius * s + options.seat_clearance_mm + options.seat_rim_mm + 2.0 * step
        seat_top = clear_level(options.seat_depth_mm, block, reach)
    parts.append(m3d.Manifold.extrude(seat_cs, seat_top - base).translate((0.0, 0.0, base)))
    cut = m3d.Manifold.extrude(inner, high)  # from the standing plane z = 0 up
    # the cylinder last: it trims a seat wider than the disc too (seat_ring_problem lists that)
    solid = (m3d.Manifold.batch_boolean(parts, m3d.OpType.Add) - cut) ^ cylinder
    polys = inner.to_polygons()
    pocket = np.asarray(max(polys, key=len), np.float64) if polys else np.zeros((0, 2))
    return DiscPart(solid=solid, pocket=pocket, top_z=float(seat_top), segments=int(outline.shape[0]),
                    rim_top_z=rim_top)
