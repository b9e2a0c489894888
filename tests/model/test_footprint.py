"""The round saucer's design region: on the disc, clear of the cup, and what the cup hides from the eye.

The masks of :mod:`saucerfab.model.footprint` are held against a brute-force
ray cast: every point's line of sight to the eye marched in fine steps
against the cup's body, and distances to the cup's outline measured on a
dense polygon.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from saucerfab.errors import ConfigError, GeometryError
from saucerfab.model.cups import EllipseCup, PrismCup
from saucerfab.model.footprint import design_vertices, direct_vertices, hidden_by_cup, near_cup
from saucerfab.model.heightfield import make_grid
from saucerfab.model.scene import (
    CUP_RING_MM,
    MIN_DISC_BAND_MM,
    disc_saucer,
    load_scene,
    round_scene,
    scene_from_dict,
    scene_to_dict,
)


def _small_round(n: int = 41, **changes: object):  # -> Scene
    scene = round_scene()
    return replace(scene, saucer=disc_saucer(scene.saucer.size[0], n), **changes)


def _brute_hidden(scene, points: np.ndarray, steps: int = 4000) -> np.ndarray:  # noqa: ANN001
    """March each line of sight from the point to the eye in ``steps`` equal steps; a step in the cup's body hides it."""
    eye = np.asarray(scene.camera, np.float64)
    out = np.zeros(points.shape[0], bool)
    for t in np.linspace(1e-6, 1.0, steps):
        q = points + t * (eye - points)
        body = (q[:, 2] >= 0.0) & (q[:, 2] <= scene.cup.height)
        out |= body & np.asarray(scene.cup.contains(q[:, :2]), bool)
    return out


def _outline_distance(scene, xy: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """Distance from each point (P, 2) to the cup's footprint (0 inside), on a dense outline."""
    poly = scene.cup.boundary(4096)
    d = np.linalg.norm(xy[:, None, :] - poly[None, :, :], axis=2).min(axis=1)
    return np.where(np.asarray(scene.cup.contains(xy), bool), 0.0, d)


@pytest.mark.parametrize(
    "cup",
    [None, EllipseCup(semi_axes=(0.45, 0.33), rotation_deg=20.0), PrismCup(sides=6, circumradius=0.42)],
    ids=["circle", "ellipse", "prism"],
)
def test_hidden_by_cup_matches_a_brute_force_ray_cast(cup) -> None:  # noqa: ANN001
    scene = _small_round() if cup is None else _small_round(cup=cup)
    rng = np.random.default_rng(3)
    pts = np.concatenate([rng.uniform(-1.0, 1.0, (3000, 2)), rng.uniform(0.0, 0.15, (3000, 1))], axis=1)
    pts = pts[~np.asarray(scene.cup.contains(pts[:, :2]), bool)]
    fast, brute = hidden_by_cup(scene, pts), _brute_hidden(scene, pts)
    # points whose line of sight only grazes the cup may differ; there are a handful at most
    assert (fast != brute).mean() < 0.003
    assert brute.sum() > 300 and (~brute).sum() > 300  # both kinds are there (behind the cup, and the rest)


def test_the_disc_design_region_against_distances() -> None:
    scene = _small_round(61)
    grid = make_grid(scene.saucer)
    xy = grid.xy()
    keep = design_vertices(scene, xy)
    r = np.hypot(xy[:, 0], xy[:, 1])
    ring = CUP_RING_MM / scene.mm_per_unit
    dist = _outline_distance(scene, xy)
    step = grid.spacing[0]
    on = r <= scene.saucer.radius + 1e-12
    # clear cases agree exactly; within a hair of the ring's edge either answer is right
    clear = (np.abs(dist - ring) > 0.03 * ring) & on
    assert np.array_equal(keep[clear], dist[clear] > ring)
    assert not keep[~on].any()  # the grid's corners are off the disc
    assert np.array_equal(near_cup(scene, xy)[clear], dist[clear] <= ring)
    assert keep.sum() > 0.5 * (np.pi * scene.saucer.radius**2 - np.pi * 0.45**2) / step**2


def test_direct_vertices_leave_out_what_the_cup_hides() -> None:
    scene = _small_round(61)
    grid = make_grid(scene.saucer)
    verts = grid.vertices(np.zeros((61, 61)))
    seen = direct_vertices(scene, verts)
    keep = design_vertices(scene, verts[:, :2])
    brute = _brute_hidden(scene, verts)
    assert not (seen & ~keep).any()
    assert np.mean(seen[keep] != ~brute[keep]) < 0.005
    # the front of the disc is seen, the middle of its back half is not
    front, back = verts[:, 1] < -0.6, (verts[:, 1] > 0.55) & (np.abs(verts[:, 0]) < 0.1)
    assert seen[front & keep].all() and not seen[back & keep].any()


def test_a_rectangle_keeps_every_vertex() -> None:
    scene = load_scene("paper")
    grid = make_grid(replace(scene.saucer, resolution=20))
    assert design_vertices(scene, grid.xy()).all()
    assert direct_vertices(scene, grid.vertices(np.zeros((20, 20)))).all()


def test_round_scene_reads_back_and_names_the_smallest_saucer() -> None:
    scene = round_scene()
    assert scene.saucer.is_disc and scene.saucer.x_range == scene.saucer.y_range
    assert scene_from_dict(scene_to_dict(scene)) == scene
    given = scene_from_dict({"preset": "round", "saucer": {"diameter": 1.8}}).saucer
    assert given.is_disc and given.radius == pytest.approx(0.9)
    smallest = 80.0 + 2 * (CUP_RING_MM + MIN_DISC_BAND_MM)
    with pytest.raises(GeometryError, match=f"at least {smallest:g} mm"):
        scene_from_dict({"preset": "round", "saucer": {"diameter": 1.05}})
    scene_from_dict({"preset": "round", "saucer": {"diameter": smallest / 100.0}})  # the smallest is accepted


@pytest.mark.parametrize(
    "table, match",
    [
        ({"saucer": {"outline": "oval"}}, "outline must be one of rectangle, disc"),
        ({"saucer": {"outline": "disc"}}, "needs its diameter"),
        ({"saucer": {"diameter": 1.6}}, "diameter is for a round saucer"),
        ({"preset": "round", "saucer": {"diameter": 1.6, "x_range": [-1, 1]}}, "not both"),
        ({"preset": "round", "saucer": {"diameter": -2}}, "positive number"),
        ({"saucer": {"outline": "disc", "x_range": [-1, 1], "y_range": [-1.5, 0.5]}}, "centred on the cup"),
    ],
)
def test_bad_disc_tables_are_refused(table: dict, match: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(ConfigError, match=match):
        scene_from_dict(table)


def test_ridged_shapes_run_around_the_cup_on_a_disc() -> None:
    """On a disc the waves are rings about the cup's axis, twice as dense and half as high as the paper's."""
    from saucerfab.model.heightfield import RIDGE_DENSITY, base_shape

    saucer = disc_saucer(2.0, 201)
    h = base_shape("waves", 201, 0, saucer)
    paper = base_shape("paper_waves", 150)
    assert h.max() == pytest.approx(0.1 / RIDGE_DENSITY, rel=1e-3) and paper.max() == pytest.approx(0.1, rel=1e-3)
    # equal heights at equal distances from the axis: the grid's symmetries map rings onto themselves
    assert np.allclose(h, np.rot90(h), atol=1e-12) and np.allclose(h, h.T, atol=1e-12)
    # along a radius, the ridges come every 1 / (6 RIDGE_DENSITY) model units (the paper: 6 across its 1 unit)
    profile = h[100, 100:]
    crests = np.flatnonzero((profile[1:-1] > profile[:-2]) & (profile[1:-1] >= profile[2:])) + 1
    assert np.diff(crests).mean() * 0.01 == pytest.approx(1 / (6 * RIDGE_DENSITY), rel=0.05)
    # the rectangle's shapes are unchanged by the disc's coordinates
    assert np.array_equal(base_shape("waves", 150, 0, load_scene("paper").saucer), base_shape("waves", 150))
    assert np.array_equal(base_shape("paper_waves", 150, 0, load_scene("paper").saucer), paper)


def test_the_rectangles_waves_are_the_papers_twice_as_dense_and_half_as_high() -> None:
    from saucerfab.model.heightfield import RIDGE_DENSITY, base_shape

    u, v = np.meshgrid(np.linspace(0, 1, 150), np.linspace(0, 1, 150))
    assert np.allclose(base_shape("paper_waves", 150), 0.05 * (1 - np.cos(2 * np.pi * 6 * v)), atol=1e-12)
    k = RIDGE_DENSITY
    assert np.allclose(base_shape("waves", 150), 0.05 / k * (1 - np.cos(2 * np.pi * 6 * k * v)), atol=1e-12)
    # a grid too coarse to carry them keeps the paper's
    assert np.array_equal(base_shape("waves", 64), base_shape("paper_waves", 64))
