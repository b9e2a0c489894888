"""Tests of saucerfab.fabricate.solid: the watertight solid, its base and cup seat, thin features."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from saucerfab.design import Design, synthetic_design
from saucerfab.errors import MeshError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.profiles import load_profile
from saucerfab.fabricate.solid import (
    Solid,
    block_mesh,
    boundary_loop,
    build_solid,
    canonical_order,
    check_features,
    crest_widths,
)
from saucerfab.heightfield import triangulate
from saucerfab.scene import EllipseCup, PrismCup, Scene


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


# --------------------------------------------------------------------------- thin walls and features


def test_crest_width_of_a_symmetric_spike_is_one_spacing() -> None:
    h = np.zeros((7, 7))
    h[3, 3] = 5.0
    w = crest_widths(h, dx_mm=0.4, dy_mm=0.6, min_height_mm=0.1)
    assert w[3, 3] == pytest.approx(0.4)  # along x; y gives 0.6, the diagonal hypot(0.4, 0.6)
    assert np.isinf(np.delete(w.ravel(), 3 * 7 + 3)).all()


def test_crest_width_of_an_asymmetric_crest() -> None:
    h = np.zeros((3, 3))
    h[:, 0], h[:, 1], h[:, 2] = 0.0, 10.0, 5.0  # a ridge along y, steeper on its left
    w = crest_widths(h, 1.0, 1.0, 0.1)
    # prominence 5; half height 7.5 is 0.25 to the left and 0.5 to the right
    assert w[1, 1] == pytest.approx(0.75)
    # a crest lower than min_height is no feature
    assert np.isinf(crest_widths(h, 1.0, 1.0, 6.0)[1, 1])


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
