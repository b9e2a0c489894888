"""The round saucer's printable part (issue 44): the disc's outline, the seat at its centre, scene.json.

A small round design (the paper's eye and 80 mm cup on a 160 mm disc, a 48 x 48
grid) is built into a solid per seat kind; the tests measure the part against
the scene: its side wall is the circle of the disc's radius (within the
chord error the outline is made to), the cup's pocket is centred on the
cup's axis as ``model_to_file`` maps it, and its floor is the cup's standing
plane (model z = 0).
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace

import numpy as np
import pytest
from test_fabricate_solid import assert_closed_manifold, top_z

from saucerfab.errors import MeshError, SceneFileError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.round_solid import CHORD_MM, disc_outline_mm, disc_segments
from saucerfab.fabricate.scene_file import read_scene_file, scene_from_dict
from saucerfab.fabricate.scene_json import scene_dict, scene_json_bytes
from saucerfab.fabricate.seat import seat_ring_problem
from saucerfab.fabricate.solid import Solid, build_solid
from saucerfab.model.design import Design
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.profiles import load_profile
from saucerfab.model.scene import CUP_RING_MM, Scene, disc_saucer, round_scene

N = 48
#: the disc's diameter in model units (160 mm at the paper's 100 mm per unit)
DIAMETER = 1.6


def round_design(n: int = N, scene: Scene | None = None) -> Design:
    """A smooth design (the base shape, no random bumps) on the round scene at a small grid."""
    sc = scene or replace(round_scene(), saucer=disc_saucer(DIAMETER, n))
    d = synthetic_design(sc, resolution=n, texture_size=32, seed=3)
    return replace(d, heights=d.base_heights.copy())


@pytest.fixture(scope="module")
def design() -> Design:
    return round_design()


@pytest.fixture(scope="module")
def solids(design: Design) -> dict[str, Solid]:
    return {seat: build_solid(design, design.scene.mm_per_unit, FabOptions(seat=seat))  # type: ignore[arg-type]
            for seat in ("recess", "ring", "none")}


def radius_mm(design: Design) -> float:
    return design.scene.saucer.radius * design.scene.mm_per_unit


def centre_of(s: Solid) -> np.ndarray:
    """The model's origin (the cup's axis at its standing plane) in the file frame."""
    return (s.model_to_file @ np.array([0.0, 0.0, 0.0, 1.0]))[:3]


# --------------------------------------------------------------------------- the outline


def test_the_outline_polygon_keeps_its_chords_within_the_error() -> None:
    for r in (40.0, 80.0, 100.0, 250.0):
        n = disc_segments(r)
        assert n % 4 == 0 and r * (1 - math.cos(math.pi / n)) <= CHORD_MM
        assert r * (1 - math.cos(math.pi / (n - 4))) > CHORD_MM  # no more sides than the error asks for
        p = disc_outline_mm(r)
        assert np.allclose(np.hypot(p[:, 0], p[:, 1]), r)
        # strictly inside the square the disc is inscribed in: no vertex on the block's walls
        assert np.abs(p).max() < r - 0.5 * r * (1 - math.cos(math.pi / n))
        assert 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]) > 0  # CCW


@pytest.mark.parametrize("seat", ["recess", "ring", "none"])
def test_the_part_is_a_disc_of_the_saucer_radius(design: Design, solids: dict[str, Solid], seat: str) -> None:
    s = solids[seat]
    r = radius_mm(design)
    c = centre_of(s)
    v = s.vertices
    dist = np.hypot(v[:, 0] - c[0], v[:, 1] - c[1])
    assert dist.max() <= r + 1e-5  # nothing outside the circle
    # the side wall: faces that stand vertical at the rim; every vertex of them is on the circle (a polygon
    # vertex, exactly) or on a chord between two (where the wall meets the top), within the chord error
    tri = v[s.faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    wall = (np.abs(nrm[:, 2]) < 1e-6) & (np.hypot(*(tri.mean(axis=1)[:, :2] - c[:2]).T) > r - 1.0)
    assert wall.sum() >= disc_segments(r)
    wall_v = np.unique(s.faces[wall].ravel())
    assert not s.is_top[wall].any()
    assert (np.abs(dist[wall_v] - r) <= CHORD_MM + 1e-5).all()
    # the bottom's outline is the polygon itself: its vertices on the circle
    bottom_v = wall_v[np.abs(v[wall_v, 2] - s.bottom_z) < 1e-9]
    assert bottom_v.size == disc_segments(r)
    assert np.allclose(dist[bottom_v], r, atol=1e-5)
    # the bounding box is the diameter (the chords lie at most the error inside it)
    assert s.bbox_mm[0] == pytest.approx(2 * r, abs=2 * CHORD_MM) and s.bbox_mm[0] <= 2 * r + 1e-5
    assert s.bbox_mm[1] == pytest.approx(s.bbox_mm[0], abs=1e-5)
    # the footprint and disc_radius_mm describe the disc; its bounding square starts at the origin
    assert s.disc_radius_mm == pytest.approx(r)
    (x0, x1), (y0, y1) = s.footprint
    assert (x0, y0) == (0.0, 0.0) and x1 == pytest.approx(2 * r, abs=1e-5) and y1 == pytest.approx(2 * r, abs=1e-5)
    assert v.min() >= 0.0


@pytest.mark.parametrize("seat", ["recess", "ring", "none"])
def test_the_round_part_is_one_closed_body(solids: dict[str, Solid], seat: str) -> None:
    import trimesh

    s = solids[seat]
    assert_closed_manifold(s)
    m = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.body_count == 1
    assert s.volume_mm3 > 0 and m.volume == pytest.approx(s.volume_mm3, rel=1e-9)


def test_top_faces_are_the_heightfield_on_the_disc(design: Design, solids: dict[str, Solid]) -> None:
    s = solids["recess"]
    c = centre_of(s)
    r = radius_mm(design)
    t = s.vertices[s.faces[s.is_top]]
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] > 0).all()
    v = t.reshape(-1, 3)
    # on the disc, and outside the pocket (the cup's footprint grown by the clearance)
    d = np.hypot(v[:, 0] - c[0], v[:, 1] - c[1])
    pocket_r = design.scene.cup.circumradius * design.scene.mm_per_unit + FabOptions().seat_clearance_mm
    assert d.max() <= r + 1e-5 and d.min() >= pocket_r - 0.01  # the pocket's outline: chords of its arcs
    # each top vertex lies on the heightfield: the grid's bilinear-per-triangle surface; grid vertices exactly
    j = np.clip(np.searchsorted(s.grid_x, v[:, 0]), 0, s.grid_x.size - 1)
    i = np.clip(np.searchsorted(s.grid_y, v[:, 1]), 0, s.grid_y.size - 1)
    on = (s.grid_x[j] == v[:, 0]) & (s.grid_y[i] == v[:, 1])
    assert on.sum() > 0.5 * v.shape[0]
    assert (v[on, 2] == s.heights[i[on], j[on]]).all()
    # most of the disc's top survives: its area is the grid's over the disc less the cup's ring
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    plan = math.pi * (r**2 - (pocket_r + FabOptions().seat_rim_mm) ** 2)
    assert plan * 0.98 < area < plan * 1.5


# --------------------------------------------------------------------------- the seat


@pytest.mark.parametrize("seat", ["recess", "ring", "none"])
def test_the_seat_is_at_the_cup_axis_with_its_floor_on_the_standing_plane(
    design: Design, solids: dict[str, Solid], seat: str
) -> None:
    s = solids[seat]
    o = FabOptions(seat=seat)  # type: ignore[arg-type]
    c = centre_of(s)
    assert s.seat.kind == seat
    assert s.seat.center_xy == pytest.approx(tuple(c[:2]), abs=1e-9)
    assert s.seat.floor_z == pytest.approx(c[2], abs=1e-9)
    # the pocket: the cup's footprint grown by the clearance, about the axis
    cup_r = design.scene.cup.circumradius * design.scene.mm_per_unit
    p = s.seat.pocket
    assert p.shape[0] >= 64
    assert np.allclose(np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]), cup_r + o.seat_clearance_mm, atol=0.01)
    assert p.mean(axis=0) == pytest.approx(c[:2], abs=1e-3)
    # the floor is the standing plane across the pocket, the cup's bottom at model z = 0
    for dx, dy in ((0.0, 0.0), (0.9 * cup_r, 0.0), (0.0, -0.9 * cup_r), (-0.6 * cup_r, 0.6 * cup_r)):
        assert top_z(s, c[0] + dx, c[1] + dy) == pytest.approx(s.seat.floor_z, abs=1e-5)
    # the rim (none: the relief alone) around it, in the ring that holds no design
    for a in np.linspace(0, 2 * np.pi, 12, endpoint=False):
        q = cup_r + o.seat_clearance_mm + 0.5 * o.seat_rim_mm
        z = top_z(s, c[0] + q * np.cos(a), c[1] + q * np.sin(a))
        if seat != "none":
            assert z >= s.seat.floor_z + o.seat_depth_mm - 1e-5
    assert s.seat.top_z == pytest.approx(s.seat.floor_z + (o.seat_depth_mm if seat != "none" else 0.0))
    assert not s.warnings  # a disc's floor is in the part: no support to warn of


def test_ring_on_a_disc_is_the_recess(solids: dict[str, Solid]) -> None:
    a, b = solids["recess"], solids["ring"]
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert solids["none"].volume_mm3 < a.volume_mm3  # no rim


def test_the_seat_is_built_where_the_design_is_not(design: Design) -> None:
    # a relief higher than the rim: the relief walls the pocket, whose floor stays the standing plane
    high = replace(design, heights=design.heights + 0.04)
    s = build_solid(high, high.scene.mm_per_unit, FabOptions())
    c = centre_of(s)
    assert top_z(s, c[0], c[1]) == pytest.approx(s.seat.floor_z, abs=1e-5)
    cup_r = design.scene.cup.circumradius * design.scene.mm_per_unit
    q = cup_r + 0.5 + 2.0
    assert top_z(s, c[0] + q, c[1]) > s.seat.floor_z + FabOptions().seat_depth_mm
    assert_closed_manifold(s)


@pytest.mark.parametrize("cup", ["ellipse:0.42,0.36", "prism:6,0.42"])
def test_other_cups_get_a_pocket_of_their_footprint_at_the_centre(cup: str) -> None:
    from saucerfab.model.cups import parse_cup_spec

    sc = replace(round_scene(), cup=parse_cup_spec(cup), saucer=disc_saucer(DIAMETER, N))
    s = build_solid(round_design(scene=sc), sc.mm_per_unit, FabOptions())
    assert_closed_manifold(s)
    c = centre_of(s)
    assert top_z(s, c[0], c[1]) == pytest.approx(s.seat.floor_z, abs=1e-5)
    assert s.seat.pocket.mean(axis=0) == pytest.approx(c[:2], abs=0.05)


def test_seat_options_wider_than_the_cup_ring_are_a_problem(design: Design) -> None:
    wide = FabOptions(seat_rim_mm=CUP_RING_MM)  # 0.5 + 5 mm: past the ring by the clearance
    msg = seat_ring_problem(design.scene, wide)
    assert msg is not None and "ring" in msg and "--seat-rim-mm" in msg and "cover the design" in msg
    assert seat_ring_problem(design.scene, FabOptions()) is None
    assert seat_ring_problem(design.scene, FabOptions(seat="none", seat_rim_mm=20.0)) is None  # no rim
    assert seat_ring_problem(design.scene, FabOptions(seat="none", seat_clearance_mm=5.5)) is not None
    assert seat_ring_problem(Scene(), wide) is None  # a rectangle's seat stands beside its saucer
    # the export lists it like its other problems: a warning, or refused for a "refuse" profile
    s = build_solid(design, design.scene.mm_per_unit, wide, load_profile("j55"))
    assert any("ring" in w for w in s.warnings)
    refuse = replace(load_profile("j55"), thin_policy="refuse")
    with pytest.raises(MeshError, match="ring"):
        build_solid(design, design.scene.mm_per_unit, wide, refuse)


# --------------------------------------------------------------------------- scene.json


def test_scene_json_records_the_disc_and_reads_back(design: Design, solids: dict[str, Solid], tmp_path) -> None:
    s = solids["recess"]
    d = scene_dict(design.scene, s)
    r = radius_mm(design)
    sau = d["saucer"]
    assert sau["outline"] == "disc" and sau["diameter"] == pytest.approx(2 * r)
    c = centre_of(s)
    assert sau["center"] == pytest.approx(list(c[:2]), abs=1e-6)
    assert sau["center"] == pytest.approx(d["cup"]["center"], abs=1e-6)
    path = tmp_path / "scene.json"
    path.write_bytes(scene_json_bytes(design.scene, s))
    back = read_scene_file(path)
    assert back.is_disc and back.saucer_outline == "disc"
    assert back.saucer_diameter == pytest.approx(2 * r) and back.saucer_center == pytest.approx(tuple(c[:2]))
    assert back.saucer_x == pytest.approx((0.0, 2 * r), abs=1e-5)


def test_a_rectangle_scene_json_has_no_outline_keys() -> None:
    d = synthetic_design(Scene(), resolution=12, texture_size=16)
    s = build_solid(d, d.scene.mm_per_unit, FabOptions())
    sj = scene_dict(d.scene, s)
    assert set(sj["saucer"]) == {"x_range", "y_range"} and s.disc_radius_mm is None
    back = scene_from_dict(json.loads(scene_json_bytes(d.scene, s)), "scene.json")
    assert not back.is_disc and back.saucer_center is None and back.saucer_diameter is None


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"outline": "oval"}, "saucer.outline is 'oval'; known: rectangle, disc"),
        ({"outline": 3}, "saucer.outline"),
        ({"diameter": None}, "saucer.diameter must be a finite number"),
        ({"diameter": -160.0}, "saucer.diameter must be positive"),
        ({"diameter": True}, "saucer.diameter must be a finite number"),
        ({"diameter": "1e999"}, "saucer.diameter must be a finite number"),
        ({"center": [80.0]}, "saucer.center must be a list of 2 numbers"),
        ({"center": [80.0, float("nan")]}, "saucer.center must be a finite number"),
        ({"center": [90.0, 80.0]}, "must fill its footprint"),
        ({"diameter": 150.0}, "must fill its footprint"),
        ({"outline": "rectangle"}, "saucer.diameter is a round saucer's"),
    ],
)
def test_a_malformed_outline_is_refused(design: Design, solids: dict[str, Solid], change: dict, words: str) -> None:
    good = scene_dict(design.scene, solids["recess"])
    scene_from_dict(copy.deepcopy(good), "scene.json")  # the untouched one reads
    bad = copy.deepcopy(good)
    bad["saucer"].update(change)
    with pytest.raises(SceneFileError) as exc:
        scene_from_dict(bad, "scene.json")
    assert words in str(exc.value) and "scene.json" in str(exc.value)


@pytest.mark.parametrize("n", [31, 61, 284])
def test_the_disc_cut_keeps_clear_of_the_grid_and_leaves_no_sliver(n: int) -> None:
    """A circle through grid vertices (31 and 61 a side: (9, 12) and (18, 24) steps from the centre lie on
    it) or whose polygon passes a hair from them (284: the HP's 190 mm disc) would leave triangles a checker
    calls zero-area;
    the outline keeps GRID_GAP_MM from every grid vertex and the part has no triangle near that small."""
    from saucerfab.fabricate.round_solid import GRID_GAP_MM, clear_outline_mm, grid_gap_mm
    from saucerfab.fabricate.solid import footprint_on_clipper_grid
    from saucerfab.model.heightfield import make_grid

    diameter = 1.9 if n == 284 else 2.0
    scene = replace(round_scene(), saucer=disc_saucer(diameter, n))
    s = scene.mm_per_unit
    grid = make_grid(scene.saucer)
    _, xs, ys = footprint_on_clipper_grid(grid.xs * s, grid.ys * s)
    radius = scene.saucer.radius * s
    if n == 284:  # the case that failed `check --strict` before the outline kept clear (0.3 um from a vertex)
        assert grid_gap_mm(disc_outline_mm(radius), xs, ys) < GRID_GAP_MM
    outline = clear_outline_mm(radius, xs, ys)
    assert grid_gap_mm(outline, xs, ys) >= GRID_GAP_MM
    assert radius - np.hypot(*outline.T).max() < 0.05  # micrometres, not a visible change
    d = synthetic_design(scene, resolution=n, texture_size=32, seed=4)
    d = replace(d, heights=d.base_heights.copy())  # the base shape without the random bumps, as a design's
    solid = build_solid(d, s, FabOptions())
    t = solid.vertices[solid.faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    diag = float(np.linalg.norm(np.ptp(solid.vertices, axis=0)))
    assert area.min() > 1e-11 * diag * diag  # ten times `check`'s zero-area bound (1e-12 diag^2)


def test_the_seat_rims_top_keeps_clear_of_the_relief_heights_around_it() -> None:
    """The rim's flat top cuts the relief along a contour; its level keeps GRID_GAP_MM from every relief height
    near the seat (a contour a hair from a vertex left a zero-area triangle on astronaut-rocket's 200 mm disc)."""
    from saucerfab.fabricate.round_solid import GRID_GAP_MM, NUDGE_MM, NUDGE_STEPS

    scene = replace(round_scene(), saucer=disc_saucer(2.0, 61))
    d = synthetic_design(scene, resolution=61, texture_size=32, seed=5)
    opts = FabOptions()
    s = scene.mm_per_unit
    # put relief vertices beside the seat at exactly the rim's height above the floor: the worst case
    g = np.linspace(-scene.saucer.radius, scene.saucer.radius, 61)
    r = np.hypot(*np.meshgrid(g, g))
    ring = (r * s > scene.cup.circumradius * s + 3.0) & (r * s < scene.cup.circumradius * s + 6.0)
    heights = d.heights.copy()
    heights[ring] = opts.seat_depth_mm / s
    solid = build_solid(replace(d, heights=heights), s, opts)
    level = solid.seat.top_z - solid.seat.floor_z
    assert opts.seat_depth_mm < level <= opts.seat_depth_mm + NUDGE_STEPS * NUDGE_MM + 1e-9
    near = (solid.heights - solid.seat.floor_z)[ring]
    assert np.abs(near - level).min() >= GRID_GAP_MM - 1e-9


def test_no_fin_where_the_relief_rises_into_the_discs_cut(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relief rising steeply outwards across the disc's edge (the grid's corner vertices beside it 4 mm up)
    was cut into a lip thinner than any wall (0.014 mm on tree-note's J55 export, session 24); the export
    lowers those vertices (lower_beyond_edge) and the checker finds no thin wall. Without the lowering it does."""
    import trimesh

    import saucerfab.fabricate.solid as solid_mod
    from saucerfab.check import check_mesh

    scene = replace(round_scene(), saucer=disc_saucer(DIAMETER, 61))
    d = round_design(61, scene)
    g = np.linspace(-scene.saucer.radius, scene.saucer.radius, 61)
    r = np.hypot(*np.meshgrid(g, g))
    step = g[1] - g[0]
    beyond = (r > scene.saucer.radius) & (r < scene.saucer.radius + 1.5 * step)
    heights = d.heights.copy()
    heights[beyond] += 4.0 / scene.mm_per_unit
    d = replace(d, heights=heights)
    profile = load_profile("j55")

    def thin_walls(tag: str) -> bool:
        solid = build_solid(d, scene.mm_per_unit, FabOptions(), profile)
        path = tmp_path / f"{tag}.stl"
        trimesh.Trimesh(solid.vertices, solid.faces, process=False).export(path)
        return "thin_walls" in check_mesh(path, printer=profile).codes

    assert not thin_walls("lowered")
    monkeypatch.setattr(solid_mod, "lower_beyond_edge", lambda h, edge: h)
    assert thin_walls("as_designed")
