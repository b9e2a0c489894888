"""The cup seat's outline rules: where the plate stops, and how thin its wall against the saucer is.

The seat (``FabOptions.seat``; built in :mod:`saucerfab.fabricate.solid`) is
a plate, the hull of the cup's footprint grown by clearance + rim and the
saucer's footprint, less the saucer's footprint, with a pocket of the cup's
footprint grown by the clearance. Two of its walls depend on the cup's size:

* beside the saucer: where the grown cup reaches past the saucer's sides
  the hull runs down them as a sliver that tapers to nothing; the plate is
  cut at the saucer's edge facing the cup (:func:`clip_to_cup_side`), so
  there is none;
* between the pocket and the saucer: the scene's gap between cup and saucer
  (it grows with the cup) less the clearance (it does not). :func:`seat_wall`
  measures it and the smallest cup at which it reaches a printer's minimum
  wall: one rule for the export (a problem, warned of or refused per the
  profile's ``thin_policy``) and the design's preflight (refused before any
  work, naming that size).

On a round saucer the seat is a pocket in the saucer itself
(:mod:`saucerfab.fabricate.round_solid`): it has no wall against a second
part, but it must stay inside the ring around the cup that holds no design
(:func:`seat_ring_problem`).

Lengths are model millimetres (model units times ``Scene.mm_per_unit``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.model.scene import CUP_RING_MM, Scene

#: vertices of the seat's offset outlines closer than this to the line through
#: their neighbours are dropped (``CrossSection.simplify``), mm
OUTLINE_EPS_MM = 1e-6


def cup_outline_mm(scene: Scene, mm_per_unit: float) -> np.ndarray:
    """The cup's footprint in model mm, (K, 2), counter-clockwise.

    A smooth outline gets enough segments that the chord error stays below
    5 micrometres, so the clearance is what the user asked for; a faceted
    one gives its corners whatever the count.
    """
    cup = scene.cup
    r = cup.circumradius * mm_per_unit
    seg = max(64, int(math.ceil(math.pi / math.acos(max(1.0 - 0.005 / r, -1.0)))))
    return cup.boundary(min(seg, 2048)) * mm_per_unit


def cross_section(poly: np.ndarray):  # -> manifold3d.CrossSection
    """``poly`` (K, 2) as a manifold3d ``CrossSection`` (its union rounds onto Clipper's ~7.5 nm grid)."""
    import manifold3d as m3d

    return m3d.CrossSection([np.ascontiguousarray(poly, dtype=np.float64)])


@dataclass(frozen=True)
class FacingEdge:
    """The saucer footprint's edge that faces the cup: its line parts the two footprints.

    Attributes:
        axis: 0 for an edge at constant x, 1 for one at constant y.
        line: the edge's coordinate on that axis, model mm.
        side: +1 when the cup lies at larger coordinates than the line, -1 when smaller.
        gap_mm: the cup's footprint's distance from the line, mm (> 0).
    """

    axis: int
    line: float
    side: int
    gap_mm: float


def facing_edge(outline_mm: np.ndarray, x_mm: tuple[float, float], y_mm: tuple[float, float]) -> FacingEdge | None:
    """The footprint edge whose line parts the cup's ``outline_mm`` (K, 2) from the saucer's
    rectangle ``x_mm`` x ``y_mm`` (model mm) by the widest gap; None when no edge's line parts
    them (a cup off a corner of the saucer: its seat keeps the plain hull)."""
    (x0, x1), (y0, y1) = (float(x_mm[0]), float(x_mm[1])), (float(y_mm[0]), float(y_mm[1]))
    lo, hi = outline_mm.min(axis=0), outline_mm.max(axis=0)
    best = max(
        (FacingEdge(0, x0, -1, x0 - float(hi[0])), FacingEdge(0, x1, 1, float(lo[0]) - x1),
         FacingEdge(1, y0, -1, y0 - float(hi[1])), FacingEdge(1, y1, 1, float(lo[1]) - y1)),
        key=lambda e: e.gap_mm,
    )
    return best if best.gap_mm > 0 else None


def clip_to_cup_side(cs, edge: FacingEdge | None):  # (CrossSection, ...) -> CrossSection
    """``cs`` less what lies past ``edge``'s line on the saucer's side: the seat never runs down the saucer's sides.

    The seat plate is the hull of the grown cup and the saucer's footprint,
    less the footprint. Where the grown cup reaches past the saucer's sides,
    the hull's edges run from it to the saucer's far corners just outside
    its side walls: a sliver that tapers to nothing, under any minimum wall
    over its whole length (0.06 mm at most and the saucer's length long for
    an 80 mm ``prism:6`` cup on the paper's saucer). Cut at the facing edge's
    line, the plate ends square beside the saucer's near corners instead.
    ``cs`` itself comes back when nothing lies past the line: every seat whose
    grown cup stays within the saucer's sides (the paper's 80 mm circle cup).
    """
    import manifold3d as m3d

    if edge is None or cs.is_empty():
        return cs
    bx0, by0, bx1, by1 = cs.bounds()
    a = edge.axis
    if edge.side > 0 and (bx0, by0)[a] >= edge.line - OUTLINE_EPS_MM:
        return cs
    if edge.side < 0 and (bx1, by1)[a] <= edge.line + OUTLINE_EPS_MM:
        return cs
    lo, hi = [bx0 - 1.0, by0 - 1.0], [bx1 + 1.0, by1 + 1.0]  # a box past the bounds, cut at the line
    if edge.side > 0:
        lo[a] = edge.line
    else:
        hi[a] = edge.line
    cut = cs ^ cross_section(np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]))
    # Clipper may round a crossing of the line a grid step off it (past the footprint's span, where
    # snap_to_footprint does not reach); the plate would then not meet the block face to face. The line
    # is on Clipper's grid, so the rebuilt outline keeps it.
    polys = [np.array(p, np.float64) for p in cut.to_polygons()]
    for p in polys:
        p[np.abs(p[:, a] - edge.line) <= OUTLINE_EPS_MM, a] = edge.line
    return m3d.CrossSection(polys)


@dataclass(frozen=True)
class SeatWall:
    """The seat's wall against the saucer: the plate (or ring) between the cup's pocket and the saucer.

    The gap between the cup's footprint and the saucer is a length of the
    scene, so it grows with the cup; the clearance (an export option, mm)
    does not. The wall is ``gap - clearance``: it thickens linearly with the
    cup's size, and ``smallest_cup_mm`` is where it reaches the minimum wall.

    Attributes:
        cup_mm: the cup's diameter (``Scene.cup_diameter_mm``'s meaning) it was measured at, mm.
        gap_mm: the cup's footprint's distance from the saucer's facing edge (its footprint when
            no edge faces the cup), mm.
        thickness_mm: ``gap_mm`` less the seat's clearance, mm (0 or less: the pocket reaches the saucer).
        min_wall_mm: the minimum wall it is held to, mm.
        smallest_cup_mm: the smallest whole-mm cup diameter at which the wall is at least ``min_wall_mm``.
    """

    cup_mm: float
    gap_mm: float
    thickness_mm: float
    min_wall_mm: float
    smallest_cup_mm: int

    @property
    def thin(self) -> bool:
        """Whether the wall is under the minimum (the export's rule: a problem, warned of or refused)."""
        return self.thickness_mm < self.min_wall_mm

    def problem(self) -> str:
        """What is thin and the cup size that makes it printable, in words (the fix is the caller's)."""
        if self.thickness_mm > 0:
            what = f"the seat's wall between the cup's pocket and the saucer is {self.thickness_mm:.2f} mm"
        else:
            what = "the cup's pocket reaches the saucer, so the seat's walls there taper to nothing"
        return (f"at a {self.cup_mm:g} mm cup {what}, under the minimum wall {self.min_wall_mm:g} mm "
                f"(the {self.gap_mm:.2f} mm between cup and saucer grows with the cup, the clearance does not); "
                f"a {self.smallest_cup_mm} mm cup is the smallest whose seat can be printed")


def seat_wall(scene: Scene, mm_per_unit: float, options: FabOptions, min_wall_mm: float) -> SeatWall | None:
    """The seat's wall against the saucer at ``mm_per_unit``; None when ``options`` have no seat.

    One rule for the export (:func:`saucerfab.fabricate.solid.build_solid`
    counts a thin one among its problems) and the design's preflight
    (:func:`saucerfab.optimize.printable.preflight` refuses it before any work).
    """
    if options.seat == "none" or scene.saucer.is_disc:
        # a disc's seat is a pocket in the saucer itself, walled by its rim (FabOptions.seat_rim_mm, checked
        # against the minimum wall with the solid's other walls): no gap between two parts to grow thin
        return None
    s = float(mm_per_unit)
    outline = cup_outline_mm(scene, s)
    (ux0, ux1), (uy0, uy1) = scene.saucer.x_range, scene.saucer.y_range
    x_mm, y_mm = (ux0 * s, ux1 * s), (uy0 * s, uy1 * s)
    edge = facing_edge(outline, x_mm, y_mm)
    if edge is not None:
        gap = edge.gap_mm
    else:
        dx = np.maximum(np.maximum(x_mm[0] - outline[:, 0], outline[:, 0] - x_mm[1]), 0.0)
        dy = np.maximum(np.maximum(y_mm[0] - outline[:, 1], outline[:, 1] - y_mm[1]), 0.0)
        gap = float(np.hypot(dx, dy).min())
    cup_mm = float(scene.cup.width_units) * s
    # the gap scales with the cup: the wall reaches min_wall_mm at cup_mm * (min_wall + clearance) / gap
    need = min_wall_mm + options.seat_clearance_mm
    smallest = math.ceil(cup_mm * need / max(gap, 1e-9) - 1e-9)  # a scene's cup never touches its saucer
    return SeatWall(cup_mm, gap, gap - options.seat_clearance_mm, float(min_wall_mm), smallest)


def seat_ring_problem(scene: Scene, options: FabOptions) -> str | None:
    """On a round saucer: the seat reaches past the cup's ring and would cover the design; None when it fits.

    The seat's outline is the cup's footprint grown by the clearance and the
    rim (the clearance alone for ``seat = "none"``: a floor without a rim);
    the ring around the footprint that holds no design is
    :data:`saucerfab.model.scene.CUP_RING_MM` wide. A rectangle's seat stands
    beside the saucer (None). One rule for the export (a problem, warned of
    or refused per the profile) and the design's preflight (refused before
    any work); the message names the options to change.
    """
    if not scene.saucer.is_disc:
        return None
    rim = options.seat_rim_mm if options.seat != "none" else 0.0
    width = options.seat_clearance_mm + rim
    if width <= CUP_RING_MM + 1e-9:
        return None
    what = (f"clearance and rim ({options.seat_clearance_mm:g} + {rim:g} = {width:g} mm)" if rim
            else f"clearance ({width:g} mm)")
    return (f"the cup seat's {what} reaches past the round saucer's {CUP_RING_MM:g} mm ring around the cup, "
            "which holds no design: the seat would cover the design; lower --seat-rim-mm or --seat-clearance-mm "
            f"so that the two add up to {CUP_RING_MM:g} mm or less")
