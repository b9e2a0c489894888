"""The printable solid: the heightfield closed into a watertight part with a cup seat.

Frames. The design lives in model units (origin at the cup's bottom centre,
z up). Here everything is first scaled to millimetres by
``Scene.mm_per_unit`` (the "model-mm" frame: same origin and axes), then
translated into the positive octant (the *file* frame every exporter writes,
and ``scene.json`` describes): ``file = model * mm_per_unit + t`` with ``t``
chosen so the part's bounding box starts at (0, 0, 0). ``Solid.model_to_file``
is that 4x4 affine map.

Construction, all with manifold3d so the result is a guaranteed oriented
2-manifold:

* the *saucer block*: the N x N top grid (heights in mm), four vertical
  walls down to a flat bottom at ``z_bottom``, and that bottom; built as an
  explicit mesh (faces ids: one per top triangle, one per wall, one for the
  bottom, so manifold's simplification never merges top triangles).
* the *cup seat* (``FabOptions.seat``): a plate whose outline is the convex
  hull of the cup's footprint (grown by clearance + rim) and the saucer's
  footprint, minus that footprint, so it meets the block face to face and
  never covers the saucer's top; cut at the saucer's edge facing the cup,
  so it never runs down the saucer's sides
  (:func:`saucerfab.fabricate.seat.clip_to_cup_side`). ``recess``: the plate top is
  ``seat_depth_mm`` above the cup's standing plane and a pocket of the cup's
  footprint grown by the clearance is cut down to exactly that plane (model
  z = 0). ``ring``: the plate top is the standing plane and a ring rises
  around the pocket.
* union, difference; then manifold's status must be ``NoError`` *and* the
  volume positive (an inverted mesh also reports NoError).

A round saucer (``Saucer.is_disc``) takes the same block, cut to the disc
with its seat at the centre (:mod:`saucerfab.fabricate.round_solid`); its
file frame puts the disc's bounding square, rather than the part's bounding
box (the outline's chords lie up to ``round_solid.CHORD_MM`` inside it), at
x = y = 0, so the disc's centre is at (radius, radius).

Exact contact. The seat meets the block face to face, which manifold's
symbolic perturbation joins cleanly *only if the faces coincide exactly*.
The seat's outlines come from ``CrossSection`` (Clipper2), which rounds 2-D
coordinates onto a fixed grid (about 7.5 nm), so a plate built from the float
footprint would sit a few nanometres into the block (a sliver over the
saucer's top: vertices nanometres apart, which round onto one position) or
beside it (a part in pieces). Hence: the block's border columns/rows are put
on that grid (:func:`footprint_on_clipper_grid`); offset outlines are
``simplify``-ed (round joins leave vertex pairs 10 nm apart, which the hull
and the ring would keep differently); and the seat solids' vertices within
``OUTLINE_EPS_MM`` of the border are snapped onto it
(:func:`snap_to_footprint`: Clipper may round an edge crossing one grid step
off the edge).

Vertices and faces are then put in a canonical order (sorted positions,
rotated and sorted faces) so the same design always gives the same bytes,
whatever order manifold's parallel kernels emit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from saucerfab.errors import MeshError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.round_solid import check_rim, disc_part, rim_over_picture
from saucerfab.fabricate.seat import (
    OUTLINE_EPS_MM,
    clip_to_cup_side,
    cross_section,
    cup_outline_mm,
    facing_edge,
    seat_ring_problem,
    seat_wall,
)
from saucerfab.model.design import Design
from saucerfab.model.footprint import part_edge
from saucerfab.model.heightfield import make_grid, triangulate
from saucerfab.model.profiles import PrinterProfile
from saucerfab.model.relief import WALL_MARGIN, crest_widths, lower_beyond_edge, wall_widths

#: manifold's merge tolerance, mm: far below printer resolution, far above
#: the 10 nm rounding of written coordinates, so no two distinct vertices
#: can round onto one position
MERGE_TOLERANCE_MM = 1e-4


@dataclass(frozen=True)
class SeatInfo:
    """Where the cup stands, in file coordinates (mm).

    Attributes:
        kind: ``recess``, ``ring`` or ``none``.
        center_xy: (2,) the cup axis (on a round saucer: the disc's centre).
        floor_z: z of the cup's standing plane (model z = 0).
        top_z: z of the plate top around the recess (recess), of the ring
            top (ring), or ``floor_z`` (none); on a round saucer the rim's
            top (recess and ring, the same part there) or ``floor_z`` (none).
        pocket: (K, 2) outline of the recess / ring inside (cup footprint
            grown by the clearance), counter-clockwise; empty for ``none``
            (on a round saucer: the floor's outline for every kind).
    """

    kind: str
    center_xy: tuple[float, float]
    floor_z: float
    top_z: float
    pocket: np.ndarray


@dataclass(frozen=True)
class FeatureReport:
    """Crests (spikes, ridges) of the top thinner than the printer makes.

    Attributes:
        count: number of thin crest vertices.
        min_width_mm: width at half prominence of the thinnest crest
            (``inf`` when there is no crest at all).
        worst_xy_mm: model-mm (x, y) of the thinnest crest, or None.
    """

    count: int
    min_width_mm: float
    worst_xy_mm: tuple[float, float] | None


@dataclass(frozen=True)
class Solid:
    """A closed, outward-oriented triangle mesh in file coordinates.

    Attributes:
        vertices: (V, 3) float64 positions, mm, file frame, rounded to the
            options' decimals; all >= 0 (positive octant).
        faces: (F, 3) int64 vertex indices, counter-clockwise from outside.
        is_top: (F,) bool, the face lies on the saucer's top heightfield.
        model_to_file: (4, 4) affine map from model units to file mm.
        grid_x: (N,) file x of the design grid's columns, mm.
        grid_y: (N,) file y of the design grid's rows, mm.
        heights: (N, N) file z of the top grid vertices, mm.
        bottom_z: file z of the flat bottom (0).
        volume_mm3: enclosed volume, mm^3 (> 0).
        seat: where the cup stands.
        features: thin crest report.
        warnings: human-readable warnings (thin walls/features under ``warn``).
        disc_radius_mm: a round saucer's radius, mm (its centre is
            ``seat.center_xy``); None for the rectangle.
    """

    vertices: np.ndarray
    faces: np.ndarray
    is_top: np.ndarray
    model_to_file: np.ndarray
    grid_x: np.ndarray
    grid_y: np.ndarray
    heights: np.ndarray
    bottom_z: float
    volume_mm3: float
    seat: SeatInfo
    features: FeatureReport
    warnings: tuple[str, ...] = field(default=())
    disc_radius_mm: float | None = None

    @property
    def bbox_mm(self) -> tuple[float, float, float]:
        """Size (x, y, z) of the axis-aligned bounding box, mm."""
        ext = self.vertices.max(axis=0) - self.vertices.min(axis=0)
        return (float(ext[0]), float(ext[1]), float(ext[2]))

    @property
    def footprint(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((x0, x1), (y0, y1)) of the saucer's top in file mm (a round saucer's: the disc's bounding square)."""
        return (
            (float(self.grid_x[0]), float(self.grid_x[-1])),
            (float(self.grid_y[0]), float(self.grid_y[-1])),
        )


# --------------------------------------------------------------------------- checks


def check_features(
    heights_mm: np.ndarray, xs_mm: np.ndarray, ys_mm: np.ndarray, min_feature_mm: float,
    edge: np.ndarray | None = None,
) -> FeatureReport:
    """Crests thinner than ``min_feature_mm`` (and at least that tall); ``edge``: a round part's edge across
    the grid (:func:`saucerfab.model.footprint.part_edge`)."""
    dx = float(xs_mm[1] - xs_mm[0])
    dy = float(ys_mm[1] - ys_mm[0])
    w = crest_widths(heights_mm, dx, dy, min_feature_mm, edge)
    thin = w < min_feature_mm
    if not np.isfinite(w).any():
        return FeatureReport(0, math.inf, None)
    i, j = np.unravel_index(int(np.argmin(w)), w.shape)
    return FeatureReport(int(thin.sum()), float(w[i, j]), (float(xs_mm[j]), float(ys_mm[i])))


# --------------------------------------------------------------------------- block mesh


def boundary_loop(n: int) -> np.ndarray:
    """Vertex indices of the grid's border, counter-clockwise seen from +z, shape (4(n-1),).

    Starts at (i, j) = (0, 0) (x0, y0) and runs along +x, then +y, -x, -y.
    """
    i0 = np.zeros(n - 1, np.int64)
    r = np.arange(n - 1)
    front = i0 * n + r  # i = 0, j = 0..n-2
    right = r * n + (n - 1)  # j = n-1, i = 0..n-2
    back = (n - 1) * n + (n - 1 - r)  # i = n-1, j = n-1..1
    left = (n - 1 - r) * n  # j = 0, i = n-1..1
    return np.concatenate([front, right, back, left])


def block_mesh(
    xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray, z_bottom: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The saucer block: heightfield top, four walls, flat bottom (a fan).

    Returns:
        vertices (N*N + 4(N-1) + 1, 3) float64 mm; faces (F, 3) int64,
        outward; face_id (F,) uint32: top triangle k has id k (k < 2(N-1)^2),
        the walls ids T..T+3 (front, right, back, left) and the bottom T+4.
    """
    n = xs_mm.shape[0]
    gx, gy = np.meshgrid(xs_mm, ys_mm)
    top_v = np.stack([gx.ravel(), gy.ravel(), np.asarray(heights_mm, np.float64).ravel()], axis=1)
    loop = boundary_loop(n)
    m = loop.shape[0]
    bot_v = top_v[loop].copy()
    bot_v[:, 2] = z_bottom
    centre = np.array([[0.5 * (xs_mm[0] + xs_mm[-1]), 0.5 * (ys_mm[0] + ys_mm[-1]), z_bottom]])
    vertices = np.concatenate([top_v, bot_v, centre])
    top_f = triangulate(n)
    nt = top_f.shape[0]
    k = np.arange(m)
    a, b = loop, loop[(k + 1) % m]  # consecutive top border vertices (CCW)
    a2, b2 = n * n + k, n * n + (k + 1) % m  # the bottom vertices below them
    # (a, a', b') and (a, b', b): outward for a counter-clockwise loop (see module tests)
    walls = np.concatenate([np.stack([a, a2, b2], 1), np.stack([a, b2, b], 1)])
    side = np.concatenate([k // (n - 1), k // (n - 1)])
    c = n * n + m
    bottom = np.stack([np.full(m, c), b2, a2], axis=1)  # clockwise from above = facing down
    faces = np.concatenate([top_f, walls, bottom]).astype(np.int64)
    face_id = np.concatenate([np.arange(nt), nt + side, np.full(m, nt + 4)]).astype(np.uint32)
    return vertices, faces, face_id


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


# --------------------------------------------------------------------------- seat


def footprint_on_clipper_grid(xs_mm: np.ndarray, ys_mm: np.ndarray):  # -> (CrossSection, xs, ys)
    """The saucer's footprint rectangle and the grid, its border moved onto CrossSection's grid.

    manifold3d's ``CrossSection`` (Clipper2) computes in fixed-point
    integers: every boolean rounds 2-D coordinates onto a grid of 2**-27 mm
    (about 7.5 nm; manifold3d 3.5). A seat plate made by ``hull - footprint``
    therefore meets the block not at the block's float border but a few
    nanometres beside it: a sliver over the saucer's top (vertices a few
    nanometres apart, which then round onto one position) or a gap (the part
    falls apart). Moving the block's border columns/rows onto that grid (by
    at most a few nanometres) makes the plate's edges along the footprint
    bit-identical to the block's walls, so the union sees exact face contact,
    which manifold's symbolic perturbation joins cleanly. The rounding is
    idempotent, so every later CrossSection operation keeps those values.

    Returns:
        the footprint CrossSection, and copies of ``xs_mm`` / ``ys_mm`` whose
        first and last entries are the footprint's (rounded) edges.
    """
    import manifold3d as m3d

    rect = np.array(
        [[xs_mm[0], ys_mm[0]], [xs_mm[-1], ys_mm[0]], [xs_mm[-1], ys_mm[-1]], [xs_mm[0], ys_mm[-1]]],
        np.float64,
    )
    footprint = m3d.CrossSection([rect])  # the constructor's union rounds onto the grid
    x0, y0, x1, y1 = footprint.bounds()
    xs = np.array(xs_mm, np.float64)
    ys = np.array(ys_mm, np.float64)
    xs[0], xs[-1], ys[0], ys[-1] = x0, x1, y0, y1
    if not (np.all(np.diff(xs) > 0) and np.all(np.diff(ys) > 0)):
        raise MeshError("the saucer grid is too fine for manifold3d's 2-D precision; lower the resolution")
    return footprint, xs, ys


def snap_to_footprint(points: np.ndarray, xs_mm: np.ndarray, ys_mm: np.ndarray) -> np.ndarray:
    """Move points within ``OUTLINE_EPS_MM`` of the footprint's border exactly onto it.

    Clipper computes the crossing of an outline with a footprint edge in
    integers and may round it one grid step (about 7 nm) off that edge; the
    seat's faces along the saucer's walls would then be a hair skew to the
    block's walls and the union leaves vertices nanometres apart. Only points
    on (within the tolerance of) one of the rectangle's four edges move, each
    by at most the tolerance.

    Args:
        points: (..., 2 or 3) positions, model mm; x and y are used.
        xs_mm, ys_mm: the block's grid (the border is ``xs[0], xs[-1]``,
            ``ys[0], ys[-1]``).

    Returns:
        a snapped copy of ``points``.
    """
    p = np.array(points, np.float64, copy=True)
    x, y = p[..., 0], p[..., 1]
    eps = OUTLINE_EPS_MM
    (x0, x1), (y0, y1) = (xs_mm[0], xs_mm[-1]), (ys_mm[0], ys_mm[-1])
    along_y = (y >= y0 - eps) & (y <= y1 + eps)
    along_x = (x >= x0 - eps) & (x <= x1 + eps)
    for edge in (x0, x1):
        x[along_y & (np.abs(x - edge) <= eps)] = edge
    for edge in (y0, y1):
        y[along_x & (np.abs(y - edge) <= eps)] = edge
    return p


def seat_prism(cs, z0: float, z1: float, xs_mm: np.ndarray, ys_mm: np.ndarray):  # -> manifold3d.Manifold
    """``cs`` extruded from ``z0`` to ``z1`` (model mm), its vertices snapped onto the footprint's border."""
    import manifold3d as m3d

    m = m3d.Manifold.extrude(cs, z1 - z0).translate((0.0, 0.0, z0))
    return m.warp_batch(lambda p: snap_to_footprint(p, xs_mm, ys_mm))


# --------------------------------------------------------------------------- build


def _blunt_for(
    profile: PrinterProfile, design: Design, hmm: np.ndarray, xs: np.ndarray, ys: np.ndarray, s: float,
    edge: np.ndarray | None = None,
) -> tuple[np.ndarray, str]:
    """``hmm`` with the crests under ``profile``'s minimum feature blunted, and what was done.

    A design made for this printer has none (the optimizer keeps them out,
    :mod:`saucerfab.optimize.printable`); one made for a finer printer (or
    before designs knew their printer) is adapted here with the same rule and
    the same moves, within the design's height bound, and the export says so.
    The printer would blunt those crests anyway; doing it in the file makes the
    part meet the profile, and ``saucerfab verify`` measures what it costs.

    Returns:
        (blunted heights (N, N) mm, a warning; "" when nothing changed).
    """
    from saucerfab.model.relief import blunt_thin_crests

    dx, dy = float(xs[1] - xs[0]), float(ys[1] - ys[0])
    base = np.asarray(design.base_heights, np.float64) * s
    d = design.scene.saucer.delta * s
    lo, hi = np.minimum(base - d, hmm), np.maximum(base + d, hmm)
    res = blunt_thin_crests(hmm, dx, dy, profile.min_feature_mm, lo, hi, min_wall=profile.min_wall_mm,
                            edge=edge)
    if not res.changed:
        return hmm, ""
    made_for = str(design.parameters.get("printer") or "no printer (an older design)")
    return res.heights, (
        f"{res.changed} relief vertices were moved (at most {res.max_change:.2f} mm) so that no crest is "
        f"narrower than {profile.name}'s minimum feature {profile.min_feature_mm:g} mm, nor a wall under its "
        f"minimum wall {profile.min_wall_mm:g} mm; the design was made for {made_for}: design with "
        f"--printer {profile.key} to let the optimizer account for it"
    )


def _policy(profile: PrinterProfile | None, problems: list[str], warnings: list[str]) -> None:
    """Warn or refuse (``profile.thin_policy``) on below-minimum walls and features."""
    if not problems:
        return
    if profile is not None and profile.thin_policy == "refuse":
        raise MeshError(
            f"the part is too thin for {profile.name} (thin_policy = refuse): "
            + "; ".join(problems)
            + ". Use a larger cup diameter, thicker base/rim options, or a printer profile "
            "with thin_policy = \"warn\"."
        )
    warnings.extend(problems)


def build_solid(
    design: Design,
    mm_per_unit: float,
    options: FabOptions | None = None,
    profile: PrinterProfile | None = None,
) -> Solid:
    """Close ``design``'s heightfield into a watertight coloured-print-ready solid.

    Args:
        design: the design (heights in model units).
        mm_per_unit: millimetres per model unit (``Scene.mm_per_unit``, or the
            user's cup diameter / the cup's width in units).
        options: base and seat settings.
        profile: printer whose minimum wall and feature size are checked
            (warned about or refused per its ``thin_policy``); None skips.

    Raises:
        MeshError: manifold3d rejects the mesh, the volume is not positive,
            or the part is too thin for a ``refuse`` profile.
        ConfigError: a saucer rim the part cannot have (:func:`~saucerfab.fabricate.round_solid.check_rim`).
    """
    import manifold3d as m3d

    opts = options or FabOptions()
    if not (math.isfinite(mm_per_unit) and mm_per_unit > 0):
        raise MeshError(f"mm_per_unit must be positive, got {mm_per_unit}")
    check_rim(design.scene, mm_per_unit, opts)  # a raised rim: a round saucer's, narrower than its band
    grid = make_grid(design.scene.saucer)
    s = float(mm_per_unit)
    footprint, xs, ys = footprint_on_clipper_grid(grid.xs * s, grid.ys * s)
    hmm = np.asarray(design.heights, np.float64) * s
    edge = part_edge(design.scene.saucer)  # a round saucer's edge across the grid (its corners are cut away)
    if edge is not None:
        hmm = lower_beyond_edge(hmm, edge)  # no face rises into the cut: no fin at the edge
    z_bottom = min(-opts.base_thickness_mm, float(hmm.min()) - opts.min_thickness_mm)

    warnings: list[str] = []
    problems: list[str] = []
    features = FeatureReport(0, math.inf, None)
    disc = design.scene.saucer.is_disc
    ring = seat_ring_problem(design.scene, opts)  # a round saucer's seat over its design (None: fits)
    if ring is not None and profile is None:
        warnings.append(ring)
    if profile is not None:
        wall = profile.min_wall_mm
        problems.extend(opts.walls_under(wall))
        if ring is not None:
            problems.append(ring)
        sw = seat_wall(design.scene, s, opts, wall)
        if sw is not None and sw.thin:
            problems.append(f"{sw.problem()}: use --cup-diameter-mm {sw.smallest_cup_mm} or more, or --seat none")
        hmm, blunted = _blunt_for(profile, design, hmm, xs, ys, s, edge)
        if blunted:
            warnings.append(blunted)
        features = check_features(hmm, xs, ys, profile.min_feature_mm, edge)
        if features.count:
            x, y = features.worst_xy_mm or (0.0, 0.0)
            problems.append(
                f"{features.count} spike/ridge vertices are thinner than the minimum feature "
                f"{profile.min_feature_mm:g} mm (thinnest {features.min_width_mm:.3f} mm wide at "
                f"half height, model-mm x={x:.2f} y={y:.2f}) and the design's height bound leaves no room "
                "to blunt them; they may print blunted"
            )
        ww = wall_widths(hmm, float(xs[1] - xs[0]), float(ys[1] - ys[0]), wall, edge=edge)
        walls = int((ww < WALL_MARGIN * wall).sum())
        if walls:
            problems.append(
                f"{walls} relief crests are walls thinner than {WALL_MARGIN:g} x the minimum wall {wall:g} mm "
                f"at {wall:g} mm below their tops, and the design's height bound leaves no room to blunt them"
            )
        z_bottom = min(-opts.base_thickness_mm, float(hmm.min()) - opts.min_thickness_mm)
        _policy(profile, problems, warnings)

    verts, faces, face_id = block_mesh(xs, ys, hmm, z_bottom)
    n_top_in = 2 * (design.n - 1) ** 2
    # A reserved mesh id marks the block's triangles through the booleans;
    # with the per-triangle face ids it tells which output faces are top.
    block_id = int(m3d.Manifold.reserve_ids(1))
    block = m3d.Manifold(
        m3d.Mesh64(
            vert_properties=np.ascontiguousarray(verts, np.float64),
            tri_verts=np.ascontiguousarray(faces, np.uint32),
            face_id=face_id,
            run_index=np.array([0, faces.size], np.uint32),
            run_original_id=np.array([block_id], np.uint32),
        )
    )
    if block.status() != m3d.Error.NoError:
        raise MeshError(f"manifold3d rejected the saucer block: {block.status()}")

    cup_outline = cup_outline_mm(design.scene, s)
    solid = block
    kind = opts.seat
    top_z = 0.0
    pocket = np.zeros((0, 2))
    if disc:
        part = disc_part(block, design.scene, s, opts, z_bottom, float(hmm.max()), (xs, ys))
        solid, pocket, top_z = part.solid, part.pocket, part.top_z
        covered = rim_over_picture(design.scene, s, opts, xs, ys, hmm)
        if covered is not None:
            warnings.append(covered)
    elif kind != "none":
        cup_cs = cross_section(cup_outline)
        # Clipper's round joins can leave vertex pairs ~1e-8 mm apart; the hull keeps one
        # of a pair and the ring both, so the two outlines would differ by a sliver.
        # simplify() drops them (moving the outline by under OUTLINE_EPS_MM).
        inner = (
            cup_cs.offset(opts.seat_clearance_mm, m3d.JoinType.Round).simplify(OUTLINE_EPS_MM)
            if opts.seat_clearance_mm > 0
            else cup_cs
        )
        outer = cup_cs.offset(opts.seat_clearance_mm + opts.seat_rim_mm, m3d.JoinType.Round).simplify(
            OUTLINE_EPS_MM
        )
        if not (inner - footprint).area() >= inner.area() * (1 - 1e-9):
            warnings.append(
                "the cup's clearance outline overlaps the saucer's footprint; the seat is clipped there"
            )
        edge = facing_edge(cup_outline, (xs[0], xs[-1]), (ys[0], ys[-1]))
        plate_cs = clip_to_cup_side(m3d.CrossSection.batch_hull([outer, footprint]) - footprint, edge)
        pocket_cs = inner - footprint
        top_z = opts.seat_depth_mm
        if kind == "recess":
            plate = seat_prism(plate_cs, z_bottom, top_z, xs, ys)
            cut = seat_prism(pocket_cs, 0.0, top_z + 1.0, xs, ys)  # from the standing plane z = 0 up
            solid = m3d.Manifold.batch_boolean([block, plate], m3d.OpType.Add) - cut
        else:  # ring
            plate = seat_prism(plate_cs, z_bottom, 0.0, xs, ys)
            ring = seat_prism(clip_to_cup_side((outer - inner) - footprint, edge), 0.0, opts.seat_depth_mm, xs, ys)
            solid = m3d.Manifold.batch_boolean([block, plate, ring], m3d.OpType.Add)
        polys = pocket_cs.to_polygons()
        pocket = np.asarray(max(polys, key=len), np.float64) if polys else pocket

    solid = solid.set_tolerance(MERGE_TOLERANCE_MM)
    status = solid.status()
    volume = solid.volume()
    if status != m3d.Error.NoError or not volume > 0:
        raise MeshError(f"manifold3d could not build the solid: status {status}, volume {volume:g} mm^3")
    if len(solid.decompose()) != 1:
        raise MeshError("the solid fell apart into several pieces; check the seat options and the scene")

    mesh = solid.to_mesh64()
    v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
    f = np.asarray(mesh.tri_verts, np.int64)
    fid = np.asarray(mesh.face_id, np.int64)
    run_index = np.asarray(mesh.run_index, np.int64) // 3  # offsets into the flat tri_verts
    run_orig = np.asarray(mesh.run_original_id, np.int64)
    from_block = np.zeros(f.shape[0], bool)
    for r, oid in enumerate(run_orig):
        if oid == block_id:
            from_block[run_index[r] : run_index[r + 1]] = True
    is_top = from_block & (fid < n_top_in)

    # Into the positive octant, then round once so every format writes the same numbers.
    shift = -v.min(axis=0)
    if disc:  # the disc's bounding square from x = y = 0 (the polygon's chords lie inside it)
        shift[0], shift[1] = -xs[0], -ys[0]
    dec = opts.coord_decimals
    v = np.round(v + shift, dec) + 0.0  # + 0.0 turns -0.0 into 0.0
    v, f, is_top = canonical_order(v, f, is_top)
    if np.unique(v, axis=0).shape[0] != v.shape[0]:
        raise MeshError("two vertices of the solid round onto one position; raise coord_decimals")
    vol = _signed_volume(v, f)
    if not vol > 0:
        raise MeshError(f"the written solid would have volume {vol:g} mm^3; it is inverted or empty")

    m2f = np.eye(4)
    m2f[:3, :3] *= s
    m2f[:3, 3] = shift
    cx, cy = shift[0], shift[1]
    seat = SeatInfo(
        kind=kind,
        center_xy=(float(cx), float(cy)),
        floor_z=float(shift[2]),
        top_z=float(shift[2] + top_z) if kind != "none" else float(shift[2]),
        pocket=pocket + shift[:2] if pocket.size else pocket,
    )
    if kind == "none" and not disc:  # a disc's floor is in the part: the cup needs no support
        warnings.append(
            f"no cup seat: the cup must stand on a support {shift[2]:.2f} mm above the part's "
            "base plane so its bottom is where the design assumes"
        )
    return Solid(
        vertices=v,
        faces=f,
        is_top=is_top,
        model_to_file=m2f,
        grid_x=np.round(xs + shift[0], dec),
        grid_y=np.round(ys + shift[1], dec),
        heights=np.round(hmm + shift[2], dec),
        bottom_z=float(np.round(z_bottom + shift[2], dec)),
        volume_mm3=vol,
        seat=seat,
        features=features,
        warnings=tuple(warnings),
        disc_radius_mm=design.scene.saucer.radius * s if disc else None,
    )


def canonical_order(
    vertices: np.ndarray, faces: np.ndarray, is_top: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sort vertices by position and faces by (top first, vertex indices).

    Each face is rotated (orientation kept) to start at its smallest index.
    The result depends only on the geometry, not on the order a parallel
    kernel produced it in, which makes the written files reproducible.
    """
    order = np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))
    remap = np.empty_like(order)
    remap[order] = np.arange(order.shape[0])
    v = vertices[order]
    f = remap[faces]
    shift = np.argmin(f, axis=1)
    rows = np.arange(f.shape[0])[:, None]
    f = f[rows, (shift[:, None] + np.arange(3)[None, :]) % 3]
    forder = np.lexsort((f[:, 2], f[:, 1], f[:, 0], ~is_top))
    return v, f[forder], is_top[forder]
