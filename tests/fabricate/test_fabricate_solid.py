"""Tests of saucerfab.fabricate.solid: the watertight solid, its base and cup seat, thin features."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from saucerfab.errors import MeshError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.solid import (
    OUTLINE_EPS_MM,
    Solid,
    block_mesh,
    boundary_loop,
    build_solid,
    canonical_order,
    check_features,
    footprint_on_clipper_grid,
    snap_to_footprint,
)
from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup
from saucerfab.model.design import Design
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.heightfield import make_grid, triangulate
from saucerfab.model.profiles import load_profile
from saucerfab.model.scene import Saucer, Scene


def flat_design(n: int = 12, scene: Scene | None = None) -> Design:
    """A design whose heights are all zero (the saucer's top is the cup's standing plane)."""
    d = synthetic_design(scene, resolution=n, texture_size=32)
    z = np.zeros((n, n))
    return replace(d, heights=z, base_heights=z)


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    t = v[f]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)


def assert_closed_manifold(solid: Solid) -> None:
    """Every directed edge appears once and its reverse once: closed, oriented, 2-manifold."""
    f = solid.faces
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert np.unique(e, axis=0).shape[0] == e.shape[0], "an edge is used twice in one direction"
    fwd = {tuple(x) for x in e.tolist()}
    assert all((b, a) in fwd for a, b in e.tolist()), "an edge has no opposite: the mesh is open"
    assert np.unique(solid.vertices, axis=0).shape[0] == solid.vertices.shape[0]


def top_z(solid: Solid, x: float, y: float) -> float:
    """Height of the solid's upper surface above (x, y) (vertical probe)."""
    tri = solid.vertices[solid.faces]
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    e1, e2, d = b - a, c - a, np.array([x, y]) - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-12
    safe = np.where(ok, det, 1.0)
    l1 = np.where(ok, (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / safe, -1)
    l2 = np.where(ok, (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / safe, -1)
    hit = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
    z = (1 - l1 - l2) * tri[:, 0, 2] + l1 * tri[:, 1, 2] + l2 * tri[:, 2, 2]
    return float(z[hit].max())


# --------------------------------------------------------------------------- block


def test_boundary_loop_is_the_border_counter_clockwise() -> None:
    n = 5
    loop = boundary_loop(n)
    assert loop.shape == (4 * (n - 1),) and np.unique(loop).shape == loop.shape
    i, j = loop // n, loop % n
    assert ((i == 0) | (i == n - 1) | (j == 0) | (j == n - 1)).all()
    # shoelace area of the loop in (x = j, y = i) is positive: counter-clockwise
    x, y = j.astype(float), i.astype(float)
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) == pytest.approx((n - 1) ** 2)


def test_block_mesh_is_closed_outward_with_the_analytic_volume() -> None:
    rng = np.random.default_rng(0)
    xs, ys = np.linspace(0, 30, 7), np.linspace(5, 20, 7)
    h = rng.uniform(1, 3, (7, 7))
    v, f, fid = block_mesh(xs, ys, h, z_bottom=-2.0)
    nt = 2 * 36
    assert (fid[:nt] == np.arange(nt)).all() and set(fid[nt:].tolist()) == {nt, nt + 1, nt + 2, nt + 3, nt + 4}
    # volume = integral of (h - z_bottom) over the plan, exact for the linear triangles
    tri = triangulate(7)
    gx, gy = np.meshgrid(xs, ys)
    p = np.stack([gx.ravel(), gy.ravel()], 1)[tri]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    want = float((area * ((h.ravel()[tri]).mean(axis=1) + 2.0)).sum())
    assert signed_volume(v, f) == pytest.approx(want, rel=1e-12)
    import trimesh

    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0


# --------------------------------------------------------------------------- solid


def test_flat_design_without_seat_is_a_box_of_exact_volume() -> None:
    d = flat_design(12)
    s = build_solid(d, d.scene.mm_per_unit, FabOptions(seat="none", base_thickness_mm=3.0))
    assert_closed_manifold(s)
    # 80 mm cup: 100 mm per unit; footprint 100 x 100 mm; bottom 3 mm below the flat top
    assert s.volume_mm3 == pytest.approx(100 * 100 * 3, rel=1e-9)
    assert s.bbox_mm == pytest.approx((100.0, 100.0, 3.0))
    assert s.vertices.min() == 0.0 and (s.vertices >= 0).all()
    assert s.is_top.sum() == 2 * 11**2  # nothing cut the top
    assert any("no cup seat" in w for w in s.warnings)


def test_bottom_is_lowered_under_the_lowest_point() -> None:
    d = flat_design(12)
    h = d.heights.copy()
    h[5, 5] = -0.1  # 10 mm below the standing plane
    d = replace(d, heights=h)
    s = build_solid(d, d.scene.mm_per_unit, FabOptions(seat="none", base_thickness_mm=3.0, min_thickness_mm=2.0))
    lowest_top = s.heights.min()
    assert lowest_top - s.bottom_z == pytest.approx(2.0, abs=1e-5)
    assert s.bottom_z == 0.0


def test_recess_seat_volume_matches_the_plate_minus_the_pocket() -> None:
    from scipy.spatial import ConvexHull

    d = flat_design(16)
    o = FabOptions(seat="recess", base_thickness_mm=3.0, seat_depth_mm=1.5, seat_clearance_mm=0.5, seat_rim_mm=4.0)
    with_seat = build_solid(d, d.scene.mm_per_unit, o)
    without = build_solid(d, d.scene.mm_per_unit, replace(o, seat="none"))
    assert_closed_manifold(with_seat)
    r_pocket, r_outer = 40 + 0.5, 40 + 0.5 + 4.0
    t = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    circle = np.stack([r_outer * np.cos(t), r_outer * np.sin(t)], 1)
    rect = np.array([[-50, -150], [50, -150], [50, -50], [-50, -50]], float)
    hull = ConvexHull(np.concatenate([circle, rect]))
    plate_area = hull.volume - 100 * 100  # the hull minus the saucer's footprint
    # the pocket lies wholly behind the saucer (y > -50 mm) for the paper's scene
    pocket_area = math.pi * r_pocket**2
    want = plate_area * (3.0 + 1.5) - pocket_area * 1.5
    assert with_seat.volume_mm3 - without.volume_mm3 == pytest.approx(want, rel=2e-3)
    seat = with_seat.seat
    assert seat.kind == "recess" and seat.top_z - seat.floor_z == pytest.approx(1.5)
    # probes: the pocket floor is the cup's standing plane, the rim is 1.5 mm higher
    cx, cy = seat.center_xy
    assert top_z(with_seat, cx, cy) == pytest.approx(seat.floor_z, abs=1e-5)
    assert top_z(with_seat, cx, cy + 40.25) == pytest.approx(seat.floor_z, abs=1e-5)
    assert top_z(with_seat, cx, cy + 42.5) == pytest.approx(seat.top_z, abs=1e-5)
    assert top_z(with_seat, cx + 42.5, cy) == pytest.approx(seat.top_z, abs=1e-5)
    assert np.hypot(*(seat.pocket - seat.center_xy).T).min() == pytest.approx(r_pocket, abs=0.01)


def test_ring_seat_rises_around_the_cup() -> None:
    d = flat_design(12)
    o = FabOptions(seat="ring", seat_depth_mm=2.0, seat_clearance_mm=1.0, seat_rim_mm=3.0)
    s = build_solid(d, d.scene.mm_per_unit, o)
    assert_closed_manifold(s)
    cx, cy = s.seat.center_xy
    floor = s.seat.floor_z
    assert top_z(s, cx, cy) == pytest.approx(floor, abs=1e-5)
    assert top_z(s, cx, cy + 40.5) == pytest.approx(floor, abs=1e-5)  # inside the clearance
    assert top_z(s, cx, cy + 42.5) == pytest.approx(floor + 2.0, abs=1e-5)  # on the ring
    assert top_z(s, cx + 42.5, cy) == pytest.approx(floor + 2.0, abs=1e-5)


@pytest.mark.parametrize(
    "cup",
    [PrismCup(sides=6, circumradius=0.45, rotation_deg=15.0), EllipseCup(semi_axes=(0.45, 0.35), rotation_deg=30.0)],
)
def test_prism_and_ellipse_cups_get_a_pocket_of_their_footprint(cup: object) -> None:
    scene = Scene(cup=cup, cup_diameter_mm=90.0)  # type: ignore[arg-type]
    d = synthetic_design(scene, resolution=16, texture_size=32)
    s = build_solid(d, scene.mm_per_unit, FabOptions())
    assert_closed_manifold(s)
    assert s.volume_mm3 > 0
    cx, cy = s.seat.center_xy
    mm = scene.mm_per_unit
    # just inside the cup's outline: the pocket floor; the outline grown by clearance + rim/2: the rim
    outline = cup.boundary(64) * mm  # type: ignore[attr-defined]
    for p in outline[::5]:
        rad = np.hypot(*p)
        inside = np.array([cx, cy]) + p * (rad - 0.2) / rad
        assert top_z(s, *inside) == pytest.approx(s.seat.floor_z, abs=1e-5)
        if p[1] > 0:  # the side away from the saucer
            out = np.array([cx, cy]) + p * (rad + 0.5 + 2.0 + 1.0) / rad
            assert top_z(s, *out) == pytest.approx(s.seat.top_z, abs=1e-5)


def test_top_faces_are_marked_and_keep_the_heightfield() -> None:
    d = synthetic_design(resolution=16, texture_size=32, seed=2)
    s = build_solid(d, d.scene.mm_per_unit, FabOptions())
    top = s.faces[s.is_top]
    t = s.vertices[top]
    (x0, x1), (y0, y1) = s.footprint
    cen = t.mean(axis=1)
    assert ((cen[:, 0] > x0) & (cen[:, 0] < x1) & (cen[:, 1] > y0) & (cen[:, 1] < y1)).all()
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] > 0).all()
    # the top's area is the heightfield's (manifold may split top faces on the seat side, never move them)
    gx, gy = np.meshgrid(s.grid_x, s.grid_y)
    g = np.stack([gx.ravel(), gy.ravel(), s.heights.ravel()], 1)[triangulate(16)]
    area = lambda q: 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1).sum()  # noqa: E731
    assert area(t) == pytest.approx(area(g), rel=1e-6)
    # every non-top face lies off the top surface (walls, bottom, seat)
    rest = s.vertices[s.faces[~s.is_top]].mean(axis=1)
    strictly_inside = (rest[:, 0] > x0 + 1e-3) & (rest[:, 0] < x1 - 1e-3) & (rest[:, 1] > y0 + 1e-3) & (rest[:, 1] < y1 - 1e-3)
    assert (rest[strictly_inside, 2] <= s.bottom_z + 1e-9).all()


def test_canonical_order_does_not_depend_on_input_order() -> None:
    d = synthetic_design(resolution=10, texture_size=32)
    s = build_solid(d, d.scene.mm_per_unit, FabOptions())
    rng = np.random.default_rng(5)
    perm_v = rng.permutation(s.vertices.shape[0])
    inv = np.empty_like(perm_v)
    inv[perm_v] = np.arange(perm_v.size)
    perm_f = rng.permutation(s.faces.shape[0])
    f = inv[s.faces][perm_f]
    f = np.roll(f, 1, axis=1)  # rotated corners, same orientation
    v2, f2, t2 = canonical_order(s.vertices[perm_v], f, s.is_top[perm_f])
    np.testing.assert_array_equal(v2, s.vertices)
    np.testing.assert_array_equal(f2, s.faces)
    np.testing.assert_array_equal(t2, s.is_top)
    again = build_solid(d, d.scene.mm_per_unit, FabOptions())
    np.testing.assert_array_equal(again.vertices, s.vertices)
    np.testing.assert_array_equal(again.faces, s.faces)


def test_bad_scale_is_refused() -> None:
    d = flat_design(8)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(MeshError, match="mm_per_unit"):
            build_solid(d, bad)


# --------------------------------------------------------------------------- seat against the block
#
# Regressions: the seat's 2-D outlines (manifold3d CrossSection = Clipper2) are
# rounded onto a ~7.5 nm grid. Unless the block's border sits on that grid and
# edge crossings are snapped, the plate lies nanometres into the saucer (a
# sliver over its top, vertices that round onto one position) or beside it
# (the part falls apart). Scales like 88.89 mm per unit (an 80 mm prism cup of
# circumradius 0.45) and wide saucers exposed it.

WIDE = Saucer((-1.0, 1.0), (-1.5, -0.5), 24, 0.05)

SEAT_SCENES = {
    "prism-wide": Scene(cup=PrismCup(6, 0.45, -90.0), saucer=WIDE),  # 88.89 mm/unit: the reported design
    "prism7-wide": Scene(cup=PrismCup(7, 0.45, 0.0), saucer=WIDE),  # round joins leave 10 nm vertex pairs
    "ellipse-wide": Scene(cup=EllipseCup((0.45, 0.35), 30.0), saucer=WIDE, cup_diameter_mm=77.0),
    "circle-wide": Scene(cup=CircleCup(0.37), saucer=WIDE),  # 108.1 mm/unit
    "circle-default": Scene(cup=CircleCup(0.37)),
    "circle-paper": Scene(),  # 100 mm/unit: the footprint lies on the grid anyway
}


def assert_one_printable_body(s: Solid) -> None:
    """Closed 2-manifold, no two vertices at one position, one body, positive volume (also per trimesh)."""
    import trimesh

    assert_closed_manifold(s)
    m = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.body_count == 1
    assert s.volume_mm3 > 0 and m.volume == pytest.approx(s.volume_mm3, rel=1e-9)


def assert_top_is_the_heightfield(s: Solid, n: int) -> None:
    """The marked top faces cover exactly the designed heightfield: inside the footprint, same area, facing up."""
    t = s.vertices[s.faces[s.is_top]]
    (x0, x1), (y0, y1) = s.footprint
    cen = t.mean(axis=1)
    assert ((cen[:, 0] > x0) & (cen[:, 0] < x1) & (cen[:, 1] > y0) & (cen[:, 1] < y1)).all()
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] > 0).all()
    gx, gy = np.meshgrid(s.grid_x, s.grid_y)
    g = np.stack([gx.ravel(), gy.ravel(), s.heights.ravel()], 1)[triangulate(n)]
    area = lambda q: 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1).sum()  # noqa: E731
    assert area(t) == pytest.approx(area(g), rel=1e-6)  # coordinates are rounded to 10 nm
    # every top vertex is a grid vertex at its designed height, or lies on the border (where the
    # seat may split a top triangle's outer edge)
    v = t.reshape(-1, 3)
    j, i = np.searchsorted(s.grid_x, v[:, 0]), np.searchsorted(s.grid_y, v[:, 1])
    on_grid = (j < s.grid_x.size) & (i < s.grid_y.size)
    j, i = np.minimum(j, s.grid_x.size - 1), np.minimum(i, s.grid_y.size - 1)
    on_grid &= (s.grid_x[j] == v[:, 0]) & (s.grid_y[i] == v[:, 1])
    assert (v[on_grid, 2] == s.heights[i[on_grid], j[on_grid]]).all()
    border = np.isin(v[:, 0], (x0, x1)) | np.isin(v[:, 1], (y0, y1))
    assert (on_grid | border).all()


def assert_seat_probes(s: Solid, scene: Scene, o: FabOptions) -> None:
    """Pocket floor on the standing plane at the cup's axis; rim / ring top just outside, away from the saucer."""
    cx, cy = s.seat.center_xy
    assert top_z(s, cx, cy) == pytest.approx(s.seat.floor_z, abs=1e-5)
    reach = float(scene.cup.boundary(256)[:, 1].max()) * scene.mm_per_unit  # type: ignore[attr-defined]
    rim_y = cy + reach + o.seat_clearance_mm + 0.5 * o.seat_rim_mm
    want = s.seat.floor_z + (o.seat_depth_mm if o.seat == "ring" else 0.0)
    assert top_z(s, cx, rim_y) == pytest.approx(s.seat.top_z if o.seat == "recess" else want, abs=1e-5)


@pytest.mark.parametrize("seat", ["recess", "ring", "none"])
@pytest.mark.parametrize("name", sorted(SEAT_SCENES))
def test_seat_meets_the_saucer_without_slivers_or_gaps(name: str, seat: str) -> None:
    scene = SEAT_SCENES[name]
    d = synthetic_design(scene, resolution=16, texture_size=32, seed=1)
    o = FabOptions(seat=seat)  # type: ignore[arg-type]
    s = build_solid(d, scene.mm_per_unit, o)
    assert_one_printable_body(s)
    assert_top_is_the_heightfield(s, 16)
    if seat != "none":
        assert_seat_probes(s, scene, o)
        assert s.seat.top_z - s.seat.floor_z == pytest.approx(o.seat_depth_mm)


def test_wide_prism_design_is_reproducible() -> None:
    scene = SEAT_SCENES["prism-wide"]
    d = synthetic_design(scene, resolution=16, texture_size=32)
    a = build_solid(d, scene.mm_per_unit, FabOptions())
    b = build_solid(d, scene.mm_per_unit, FabOptions())
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.is_top, b.is_top)


@pytest.mark.parametrize("seat", ["recess", "ring"])
@pytest.mark.parametrize("mm_exact", [True, False])
def test_back_edge_above_below_and_on_the_seat_top(seat: str, mm_exact: bool) -> None:
    """The saucer's back edge alternates above, below and exactly at the plate's top."""
    if mm_exact:  # 128 mm per unit: heights * scale hit the plate top bit for bit
        scene = Scene(cup=PrismCup(6, 0.4375, -90.0), saucer=WIDE, cup_diameter_mm=112.0)
    else:
        scene = SEAT_SCENES["prism-wide"]
    n = 16
    d = synthetic_design(scene, resolution=n, texture_size=32, seed=4)
    mm = scene.mm_per_unit
    o = FabOptions(seat=seat)  # type: ignore[arg-type]
    plate_top = o.seat_depth_mm if seat == "recess" else 0.0
    h = np.clip(d.heights, -0.5 / mm, None)  # keep the bottom at -base_thickness: plate top exact
    h[-1] = plate_top / mm + np.resize([2.0, -2.0, 0.0, 0.3, 0.0, -0.3], n) / mm
    h[-2] = plate_top / mm + np.resize([0.0, 1.0, -1.0], n) / mm
    s = build_solid(replace(d, heights=h), mm, o)
    assert_one_printable_body(s)
    assert_top_is_the_heightfield(s, n)
    assert_seat_probes(s, scene, o)
    # just behind the back edge (beside the ring / pocket) the plate's top; just in front of it the saucer
    (x0, x1), (_, y1) = s.footprint
    beside = scene.cup.circumradius * mm + o.seat_clearance_mm + o.seat_rim_mm + 1.0
    cx = s.seat.center_xy[0]
    xs = np.concatenate([np.linspace(x0 + 1.0, cx - beside, 4), np.linspace(cx + beside, x1 - 1.0, 4)])
    for x in xs:
        behind = top_z(s, x, y1 + 1e-3)
        assert behind == pytest.approx(s.seat.top_z if seat == "recess" else s.seat.floor_z, abs=1e-5)
        j = np.searchsorted(s.grid_x, x) - 1
        t = (x - s.grid_x[j]) / (s.grid_x[j + 1] - s.grid_x[j])
        edge = (1 - t) * s.heights[-1, j] + t * s.heights[-1, j + 1]
        assert top_z(s, x, y1 - 1e-6) == pytest.approx(edge, abs=1e-4)


def test_clipped_seat_against_the_saucer_is_one_clean_body() -> None:
    """The clearance outline reaches into the saucer's footprint: the seat is clipped there, still one body."""
    scene = Scene(saucer=Saucer((-0.6, 0.7), (-1.4, -0.403), 16, 0.05), cup_diameter_mm=77.0)
    d = synthetic_design(scene, resolution=16, texture_size=32)
    for seat in ("recess", "ring"):
        s = build_solid(d, scene.mm_per_unit, FabOptions(seat=seat))  # type: ignore[arg-type]
        assert any("clipped" in w for w in s.warnings)
        assert_one_printable_body(s)
        assert_top_is_the_heightfield(s, 16)


def test_ring_crossing_the_saucer_side_is_snapped_onto_it() -> None:
    """A ring outline crossing the saucer's side wall: Clipper rounds that crossing a grid step off the wall."""
    scene = Scene(
        cup=PrismCup(5, 0.4685, 80.92), saucer=Saucer((-0.44, 0.145), (-0.94, -0.416), 12, 0.05), cup_diameter_mm=101.88
    )
    d = synthetic_design(scene, resolution=12, texture_size=32)
    d = replace(d, heights=np.zeros((12, 12)))  # the saucer's top is the ring's base plane
    o = FabOptions(seat="ring", seat_depth_mm=1.4, seat_clearance_mm=0.3, seat_rim_mm=5.7)
    s = build_solid(d, scene.mm_per_unit, o)
    assert_one_printable_body(s)


def test_footprint_is_put_on_the_cross_section_grid() -> None:
    import manifold3d as m3d

    scene = SEAT_SCENES["prism-wide"]
    grid = make_grid(scene.saucer)
    xs0, ys0 = grid.xs * scene.mm_per_unit, grid.ys * scene.mm_per_unit
    fp, xs, ys = footprint_on_clipper_grid(xs0, ys0)
    assert np.abs(xs - xs0).max() < 1e-8 and np.abs(ys - ys0).max() < 1e-8
    np.testing.assert_array_equal(xs[1:-1], xs0[1:-1])
    np.testing.assert_array_equal(ys[1:-1], ys0[1:-1])
    assert (ys0[-1] != ys[-1]) or (xs0[0] != xs[0])  # this scale is off the grid: something moved
    # the rounding is idempotent: the plate's edges along the footprint are the block's border, bit for bit
    assert m3d.CrossSection(fp.to_polygons()).bounds() == fp.bounds()
    plate = m3d.CrossSection.batch_hull([m3d.CrossSection.circle(44.5, 97), fp]) - fp
    p = np.concatenate(plate.to_polygons())
    near = np.abs(p[:, 1] - ys[-1]) < 1e-6
    assert near.sum() >= 2 and (p[near, 1] == ys[-1]).all()
    assert set(p[near, 0].tolist()) >= {xs[0], xs[-1]}


def test_snap_to_footprint_moves_only_points_on_the_border() -> None:
    xs, ys = np.array([0.0, 1.0, 10.0]), np.array([-5.0, 0.0, 5.0])
    e = 0.5 * OUTLINE_EPS_MM
    pts = np.array(
        [
            [10.0 - e, 2.0, 1.0],  # on the right edge: snapped
            [e, -5.0 + e, 0.0],  # at a corner: both snapped
            [3.0, 5.0 + e, 0.0],  # on the back edge: snapped
            [10.0 - e, 9.0, 0.0],  # on the line x = x1 but beyond the corner: kept
            [5.0, 2.0 + e, 0.0],  # inside: kept
            [10.0 - 3 * OUTLINE_EPS_MM, 2.0, 0.0],  # farther than the tolerance: kept
        ]
    )
    q = snap_to_footprint(pts, xs, ys)
    want = pts.copy()
    want[0, 0] = 10.0
    want[1, :2] = (0.0, -5.0)
    want[2, 1] = 5.0
    np.testing.assert_array_equal(q, want)
    assert pts[0, 0] == 10.0 - e  # a copy


# --------------------------------------------------------------------------- thin walls and features


def test_check_features_counts_thin_crests() -> None:
    h = np.zeros((9, 9))
    h[2, 2] = h[6, 5] = 1.0
    xs = np.linspace(0, 1.6, 9)  # 0.2 mm spacing
    rep = check_features(h, xs, xs, min_feature_mm=0.3)
    assert rep.count == 2 and rep.min_width_mm == pytest.approx(0.2)
    assert rep.worst_xy_mm in ((0.4, 0.4), (1.0, 1.2))
    assert check_features(h, xs * 2, xs * 2, 0.3).count == 0  # 0.4 mm wide: printable
    flat = check_features(np.zeros((5, 5)), xs[:5], xs[:5], 0.3)
    assert flat.count == 0 and math.isinf(flat.min_width_mm)


def test_thin_walls_warn_or_refuse() -> None:
    d = flat_design(8)
    j55 = load_profile("j55")  # warn, min wall 1.0
    s = build_solid(d, d.scene.mm_per_unit, FabOptions(base_thickness_mm=0.6, seat_rim_mm=0.5), j55)
    assert any("base_thickness_mm = 0.6" in w for w in s.warnings)
    assert any("seat_rim_mm = 0.5" in w for w in s.warnings)
    bureau = load_profile("bureau")  # refuse, min wall 2.0
    with pytest.raises(MeshError, match="min_thickness_mm"):
        build_solid(d, d.scene.mm_per_unit, FabOptions(base_thickness_mm=3.0, min_thickness_mm=1.5), bureau)
    ok = build_solid(d, d.scene.mm_per_unit, FabOptions(base_thickness_mm=3.0, min_thickness_mm=2.0), bureau)
    assert ok.warnings == ()
