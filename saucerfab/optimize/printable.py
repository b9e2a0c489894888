"""The printer a design is made for: its rules at design time, in model units.

A design knows its physical scale (``Scene.cup_diameter_mm``, so one model
unit is ``Scene.mm_per_unit`` mm) and its printer (a profile from
:mod:`saucerfab.model.profiles`, the J55 unless asked otherwise). Before
any optimization :func:`preflight` refuses what cannot be printed whatever
the optimizer does (a part larger than the build volume at the worst heights
the height bound allows - a round saucer wider than the build area naming the
largest diameter that fits -, a round saucer's seat wider than the ring around
the cup that holds no design, seat or base walls under the printer's minimum wall -
the seat's wall against the saucer by the export's own rule,
:func:`saucerfab.fabricate.seat.seat_wall`, naming the smallest cup that works -
a base shape whose crests cannot be made printable inside the bound), each
with the fix. During the optimization :class:`CrestProjection` keeps every
iterate within the printer's minimum feature and wall (:mod:`saucerfab.model.relief`), so
the finished design exports for that printer as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.seat import seat_ring_problem, seat_wall
from saucerfab.model.footprint import part_edge
from saucerfab.model.heightfield import make_grid
from saucerfab.model.profiles import DEFAULT_PRINTER, PrinterProfile, load_profile
from saucerfab.model.relief import OPTIMIZER_TIGHTEN, blunt_thin_crests
from saucerfab.model.scene import Scene

#: share of delta kept between a projected vertex and its bound (the solver's
#: barrier needs iterates strictly inside the box)
BOUND_MARGIN = 1e-3


@dataclass(frozen=True)
class PrintTarget:
    """A design's printer and scale, and the rules they put on the heightfield.

    Attributes:
        profile: the printer profile.
        cup_diameter_mm: the real cup's width across its footprint, mm.
        mm_per_unit: millimetres per model unit.
        spacing_mm: (dx, dy) of the heightfield grid, mm.
        delta_mm: the height bound |h - z| < delta, mm.
    """

    profile: PrinterProfile
    cup_diameter_mm: float
    mm_per_unit: float
    spacing_mm: tuple[float, float]
    delta_mm: float

    @property
    def min_feature_units(self) -> float:
        """The printer's minimum feature in model units."""
        return self.profile.min_feature_mm / self.mm_per_unit

    @property
    def min_wall_units(self) -> float:
        """The printer's minimum wall in model units."""
        return self.profile.min_wall_mm / self.mm_per_unit

    @property
    def crests_can_be_thin(self) -> bool:
        """Whether a crest on this grid can be under the minimum feature (its spacing is under twice it).

        The wall rule (a tall crest is a wall) can bind on any grid.
        """
        return min(self.spacing_mm) < 2.0 * self.profile.min_feature_mm

    def to_dict(self) -> dict[str, Any]:
        """What design.json records (``parameters.print_target``)."""
        p = self.profile
        return {
            "printer": p.key,
            "printer_name": p.name,
            "cup_diameter_mm": self.cup_diameter_mm,
            "mm_per_unit": self.mm_per_unit,
            "min_feature_mm": p.min_feature_mm,
            "min_wall_mm": p.min_wall_mm,
            "grid_spacing_mm": list(self.spacing_mm),
            "delta_mm": self.delta_mm,
        }


def print_target(scene: Scene, printer: str | PrinterProfile = DEFAULT_PRINTER) -> PrintTarget:
    """The :class:`PrintTarget` of ``scene`` (its cup diameter) on ``printer``.

    Raises:
        ConfigError: unknown printer.
    """
    profile = printer if isinstance(printer, PrinterProfile) else load_profile(printer)
    grid = make_grid(scene.saucer)
    s = scene.mm_per_unit
    dx, dy = grid.spacing
    return PrintTarget(profile, float(scene.cup_diameter_mm), s, (dx * s, dy * s), scene.saucer.delta * s)


def worst_case_bbox_mm(scene: Scene, base: np.ndarray, options: FabOptions) -> tuple[float, float, float]:
    """The largest bounding box (x, y, z) in mm the exported part can have.

    Every height stays within ``base +- delta``; the seat plate spans the
    cup's footprint grown by the clearance and the rim; the base lies
    ``base_thickness_mm`` under the cup's standing plane and at least
    ``min_thickness_mm`` under the saucer's lowest point (as
    :func:`saucerfab.fabricate.solid.build_solid` builds it). A round
    saucer's part is its disc (the seat lies inside it), its top at least
    the seat's floor (z = 0) when it has no rim.
    """
    s = scene.mm_per_unit
    sc = scene.saucer
    if sc.is_disc:  # the disc's bounding square: the cylinder trims whatever of the seat reaches past it
        (x0, x1), (y0, y1) = (sc.x_range[0] * s, sc.x_range[1] * s), (sc.y_range[0] * s, sc.y_range[1] * s)
    else:
        seat = options.seat_clearance_mm + options.seat_rim_mm if options.seat != "none" else 0.0
        r = scene.cup.circumradius * s + seat
        x0, x1 = min(sc.x_range[0] * s, -r), max(sc.x_range[1] * s, r)
        y0, y1 = min(sc.y_range[0] * s, -r), max(sc.y_range[1] * s, r)
    top = (float(base.max()) + sc.delta) * s
    if options.seat != "none":
        top = max(top, options.seat_depth_mm)
    elif sc.is_disc:
        top = max(top, 0.0)  # the cup's floor
    bottom = min(-options.base_thickness_mm, (float(base.min()) - sc.delta) * s - options.min_thickness_mm)
    return (x1 - x0, y1 - y0, top - bottom)


def preflight(target: PrintTarget, scene: Scene, base: np.ndarray, options: FabOptions | None = None) -> list[str]:
    """Refuse a design its printer cannot make, before any optimization.

    Args:
        target: the printer and scale.
        scene: the scene (view frames already fitted).
        base: (N, N) base heights, model units.
        options: the solid's settings the export will use (default FabOptions()).

    Returns:
        notes for the user (nothing that stops the design).

    Raises:
        ConfigError: the part cannot fit the build volume (a round saucer
            wider than the build area: naming the largest diameter that
            fits), a wall is under the printer's minimum (the seat's against
            the saucer: naming the smallest cup size that works), a round
            saucer's seat options would cover its design, or the base shape's
            crests cannot be made as wide as the minimum feature inside the
            height bound; the message names the fix.
    """
    opts = options or FabOptions()
    p = target.profile
    bbox = worst_case_bbox_mm(scene, base, opts)
    if scene.saucer.is_disc and not p.fits((bbox[0], bbox[1], 0.0)):
        # the disc's bounding square must fit the build area: its side is the diameter
        largest = math.floor(min(p.build_volume_mm[:2]) + 1e-9)
        bx, by = p.build_volume_mm[:2]
        raise ConfigError(
            f"the round saucer is {bbox[0]:.0f} mm across, larger than {p.name}'s build area {bx:g} x {by:g} mm; "
            f"use --saucer-diameter-mm {largest} or less, or another --printer"
        )
    if not p.fits(bbox):
        # the largest cup that fits, in 1 % steps of the cup asked for
        ratio = 1.0
        for lo_ratio in np.linspace(1.0, 0.05, 96):
            test = scene.with_changes(cup_diameter_mm=target.cup_diameter_mm * float(lo_ratio))
            if p.fits(worst_case_bbox_mm(test, base, opts)):
                ratio = float(lo_ratio)
                break
        vol = " x ".join(f"{v:g}" for v in p.build_volume_mm)
        raise ConfigError(
            f"at a {target.cup_diameter_mm:g} mm cup the part can reach {bbox[0]:.0f} x {bbox[1]:.0f} x "
            f"{bbox[2]:.0f} mm, larger than {p.name}'s build volume {vol} mm; use --cup-diameter-mm "
            f"{math.floor(target.cup_diameter_mm * ratio):g} or less, or another --printer"
        )
    thin = opts.walls_under(p.min_wall_mm)
    if thin:
        raise ConfigError(f"for {p.name}: {'; '.join(thin)}; raise it in the export options")
    ring = seat_ring_problem(scene, opts)  # a round saucer's seat stands in the ring round the cup
    if ring is not None:
        raise ConfigError(ring)
    # the seat's wall against the saucer grows with the cup: the export's own rule (it counts a thin
    # one among its problems), so a design is never made at a size its export would call too thin
    seat = seat_wall(scene, target.mm_per_unit, opts, p.min_wall_mm)
    if seat is not None and seat.thin:
        raise ConfigError(f"for {p.name}: {seat.problem()}; use --cup-diameter-mm {seat.smallest_cup_mm} "
                          "or more, or another --printer")
    notes: list[str] = []
    res = CrestProjection(target, scene, base).blunt(base)
    if res.remaining:
        raise ConfigError(
            f"the base shape has {res.remaining} crests narrower than {p.name}'s minimum feature "
            f"{p.min_feature_mm:g} mm or minimum wall {p.min_wall_mm:g} mm that the height bound "
            f"({target.delta_mm:.2f} mm) leaves no room to blunt; smooth the shape, or use a larger "
            "--cup-diameter-mm"
        )
    if res.changed:
        notes.append(
            f"the base shape's crests are too thin for {p.name} at {res.changed} vertices; "
            f"the optimizer starts from them blunted (at most {res.max_change * target.mm_per_unit:.2f} mm)"
        )
    return notes


@dataclass
class CrestProjection:
    """The optimizer's projection onto heightfields with no crest under the minimum feature or wall.

    Called on every trial point (:func:`saucerfab.optimize.solver.solve`'s
    ``project``); keeps vertices inside ``z -+ delta`` by
    :data:`BOUND_MARGIN` of delta, so the barrier stays finite. A trial the
    bounds leave no printable neighbour for comes back as NaN, which the solver
    treats as infeasible (it backtracks). Counts what it did over the run
    (``calls``, ``active``: trials it changed, ``refused``).

    Attributes:
        target: the printer and scale.
        scene: the scene (its saucer grid and delta).
        base: (N, N) base heights z, model units.
    """

    target: PrintTarget
    scene: Scene
    base: np.ndarray
    calls: int = 0
    active: int = 0
    refused: int = 0
    max_change_units: float = 0.0
    _n: int = field(init=False, default=0)
    edge: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self._n = int(self.base.shape[0])
        grid = make_grid(self.scene.saucer)
        self._dx, self._dy = grid.spacing
        d = self.scene.saucer.delta
        self._lo = self.base - d * (1.0 - BOUND_MARGIN)
        self._hi = self.base + d * (1.0 - BOUND_MARGIN)
        self.edge = part_edge(self.scene.saucer)  # a round saucer's edge across the grid, for the rules

    def blunt(self, heights: np.ndarray):  # -> saucerfab.model.relief.BluntResult
        """:func:`saucerfab.model.relief.blunt_thin_crests` of (N, N) ``heights`` within this design's bounds."""
        h = np.asarray(heights, np.float64).reshape(self._n, self._n)
        # a vertex already nearer its bound than the margin may stay where it is
        lo = np.minimum(self._lo, h)
        hi = np.maximum(self._hi, h)
        return blunt_thin_crests(h, self._dx, self._dy, self.target.min_feature_units, lo, hi,
                                 min_wall=self.target.min_wall_units, tighten=OPTIMIZER_TIGHTEN,
                                 edge=self.edge)

    def __call__(self, h: Any) -> Any:
        """(V,) torch heights -> (V,) torch heights with no thin crest (same dtype)."""
        import torch

        self.calls += 1
        res = self.blunt(h.detach().cpu().numpy())
        if res.remaining:
            # the bounds leave no room to make this trial printable: give the solver an
            # infeasible point (NaN fails its feasibility test), so it backtracks to a
            # shorter step, which from a printable iterate is printable again
            self.refused += 1
            return torch.full_like(h, float("nan"))
        if not res.changed:
            return h
        self.active += 1
        self.max_change_units = max(self.max_change_units, res.max_change)
        return torch.as_tensor(res.heights.reshape(-1), dtype=h.dtype)

    def stats(self) -> dict[str, Any]:
        """What design.json records of the projection (``metrics.printable``)."""
        return {
            "projection_calls": self.calls,
            "projection_active": self.active,
            "projection_refused": self.refused,
            "max_projection_move_mm": self.max_change_units * self.target.mm_per_unit,
        }


def printable_metrics(target: PrintTarget, heights: np.ndarray, project: CrestProjection) -> dict[str, Any]:
    """The final heights against the printer's minimum feature (``metrics.printable`` of design.json)."""
    from saucerfab.model.relief import WALL_MARGIN, crest_widths, wall_widths

    dx, dy = target.spacing_mm
    hmm = np.asarray(heights) * target.mm_per_unit
    p = target.profile
    w = crest_widths(hmm, dx, dy, p.min_feature_mm, project.edge)
    ww = wall_widths(hmm, dx, dy, p.min_wall_mm, edge=project.edge)
    out: dict[str, Any] = {
        "printer": p.key,
        "thin_crest_vertices": int((w < p.min_feature_mm).sum()),
        "narrowest_crest_mm": float(w.min()) if np.isfinite(w).any() else None,
        "thin_wall_crest_vertices": int((ww < WALL_MARGIN * p.min_wall_mm).sum()),
        "narrowest_crest_at_min_wall_mm": float(ww.min()) if np.isfinite(ww).any() else None,
        "crests_can_be_thin": target.crests_can_be_thin,
    }
    out.update(project.stats())
    return out
