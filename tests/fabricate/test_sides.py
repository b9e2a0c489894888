"""The colour of the surfaces around the top (saucerfab.fabricate.sides): what the cup shows takes the
reflected picture's background, the rest the direct picture's."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import export_design
from saucerfab.fabricate.sides import shown_by_cup, surround_sizes, view_areas
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.footprint import hidden_by_cup
from saucerfab.model.scene import Scene

UP = np.array([0.0, 0.0, 1.0])


def test_view_areas_of_the_plate_around_the_cup() -> None:
    scene = Scene()  # a round cup of radius 0.4 at the origin, the eye at (0, -5.5, 5)
    pts = np.array([
        [0.0, -0.45, 0.01],   # the plate just in front of the cup: seen directly and in the cup
        [0.0, 0.6, 0.01],     # behind the cup: the cup hides it, and the mirror faces away from it
        [0.55, -0.1, 0.01],   # beside the cup: seen directly
    ])
    direct, mirror = view_areas(scene, pts, np.tile(UP, (3, 1)))
    assert direct[0] > 0 and mirror[0] > 0
    assert direct[1] == 0 and mirror[1] == 0
    assert direct[2] > 0
    # the cup's convex mirror shrinks what it shows: directly the patch looks larger
    assert mirror[0] < direct[0]
    assert list(hidden_by_cup(scene, pts)) == [False, True, False]


def test_a_wall_facing_away_from_the_cup_is_never_shown_by_it() -> None:
    scene = Scene()
    p = np.array([[0.0, -0.5, -0.05], [0.0, -0.5, -0.05]])
    n = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])  # towards the cup; away from it (towards the eye)
    direct, mirror = view_areas(scene, p, n)
    assert mirror[0] > 0 and direct[0] == 0  # the back of the saucer: the cup sees it, the eye does not
    assert mirror[1] == 0 and direct[1] > 0
    assert list(shown_by_cup(scene, p, n)) == [True, False]


def test_a_point_seen_both_ways_goes_to_the_surround_it_weighs_more_in() -> None:
    scene = Scene()
    p = np.array([[0.0, -0.45, 0.01]])
    direct, mirror = view_areas(scene, p, UP[None])
    ratio = float(mirror[0] / direct[0])
    assert shown_by_cup(scene, p, UP[None], balance=ratio * 0.9)[0]
    assert not shown_by_cup(scene, p, UP[None], balance=ratio * 1.1)[0]
    # a design's scene (frames fitted to the saucer): the mirror's surround is the smaller
    from saucerfab.model.heightfield import base_shape
    from saucerfab.optimize.framing import fit_frames

    fitted = fit_frames(replace(scene, saucer=replace(scene.saucer, resolution=24)), base_shape("waves", 24),
                        "inscribed")
    d, m = surround_sizes(fitted, np.array([[-0.5, 0.5], [-1.5, 0.5]]))
    assert 0 < m < d


@pytest.fixture(scope="module")
def two_backgrounds():
    design = synthetic_design(resolution=24, texture_size=64)
    white = np.full((32, 32, 3), 250, np.uint8)
    navy = np.zeros((32, 32, 3), np.uint8)
    navy[...] = (18, 32, 54)
    return replace(design, references={"direct": white, "reflected": navy})


def test_the_export_paints_what_the_cup_shows_in_the_reflected_background(two_backgrounds, tmp_path: Path) -> None:
    import trimesh

    res = export_design(two_backgrounds, tmp_path / "p", printer="j55", cup_diameter_mm=80, formats=["ply", "obj"],
                        options=FabOptions(texture_px=512))
    opts = json.loads(res.summary_json.read_text())["options"]
    assert opts["wall_rgb"] == [250, 250, 250] and opts["mirror_rgb"] == [18, 32, 54]
    page = np.asarray(__import__("PIL.Image", fromlist=["Image"]).open(res.out / "saucer.png").convert("RGB"))
    navy = (page == (18, 32, 54)).all(axis=-1)
    assert navy.any()
    # only in the charts' column (the top region holds the design's own texture)
    assert not navy[:, : int(page.shape[1] * 7 / 8) - 16].any()
    mesh = trimesh.load(res.out / "saucer.ply", process=False)
    cols = np.asarray(mesh.visual.vertex_colors)[:, :3]
    v = np.asarray(mesh.vertices)
    is_navy = (cols == (18, 32, 54)).all(axis=1)
    assert is_navy.any()
    # the navy vertices lie between the saucer and the cup: on the plate's side of the saucer, in front of the cup
    saucer_back = v[:, 1][~is_navy].min() + 100.0  # the saucer is 100 mm deep at 80 mm a cup (100 mm per unit)
    assert (v[is_navy, 1] >= saucer_back - 1e-6).all()
    # the bottom is never shown by the cup
    assert not is_navy[v[:, 2] < v[:, 2].min() + 1e-6].any()


def test_walls_given_a_colour_are_all_that_colour(two_backgrounds, tmp_path: Path) -> None:
    res = export_design(two_backgrounds, tmp_path / "q", printer="j55", cup_diameter_mm=80, formats=["ply"],
                        options=FabOptions(texture_px=512, wall_rgb=(1, 2, 3)))
    opts = json.loads(res.summary_json.read_text())["options"]
    assert opts["wall_rgb"] == [1, 2, 3] and opts["mirror_rgb"] == [1, 2, 3]


def test_the_same_backgrounds_paint_nothing(tmp_path: Path) -> None:
    design = synthetic_design(resolution=24, texture_size=64)
    white = np.full((32, 32, 3), 250, np.uint8)
    made = replace(design, references={"direct": white, "reflected": white})
    res = export_design(made, tmp_path / "w", printer="j55", cup_diameter_mm=80, formats=["ply"],
                        options=FabOptions(texture_px=512))
    opts = json.loads(res.summary_json.read_text())["options"]
    assert opts["wall_rgb"] == opts["mirror_rgb"] == [250, 250, 250]


@pytest.mark.parametrize("bad", [(1, 2), (0, 0, 256), (0.5, 0, 0), (True, 0, 0)])
def test_a_bad_mirror_colour_is_refused(bad) -> None:  # noqa: ANN001
    from saucerfab.errors import ConfigError

    with pytest.raises(ConfigError, match="mirror_rgb"):
        FabOptions(mirror_rgb=bad)


def test_the_surrounds_leave_out_the_pictures_rectangles_not_their_squares() -> None:
    from saucerfab.model.heightfield import base_shape
    from saucerfab.optimize.framing import fit_frames

    scene = replace(Scene(), saucer=replace(Scene().saucer, resolution=24))
    base = base_shape("waves", 24)
    footprint = np.array([[-0.5, 0.5], [-1.5, 0.45]])
    d1, m1 = surround_sizes(fit_frames(scene, base, "inscribed"), footprint)
    # 3:2 pictures: wider squares around smaller rectangles (areas in the direct camera's units, which
    # change with its frame: their ratio is what counts); the balance of the surrounds barely changes
    d2, m2 = surround_sizes(fit_frames(scene, base, "inscribed", aspects={"direct": 1.5, "reflected": 1.5}), footprint)
    assert m2 / d2 == pytest.approx(m1 / d1, rel=0.6)  # (subtracting the squares: 2.26 against 0.34)
    assert 0.25 < m2 / d2 < 0.75
