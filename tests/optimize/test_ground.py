"""One ground under the piece (saucerfab.imaging.images.piece_ground): pictures whose border colours differ
share the direct picture's outside the frames, in the design, the export and verify's whole view alike."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from saucerfab.imaging.images import (
    ONE_GROUND_DISTANCE,
    colour_hex,
    piece_ground,
    recorded_background,
)

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
TINY = {"resolution": 16, "image_size": 48, "max_iters": 5}


def _framed(border: tuple[float, float, float], inside: tuple[float, float, float] = (0.9, 0.1, 0.1)) -> np.ndarray:
    """A (40, 40, 3) picture: ``border`` around a square of ``inside``."""
    img = np.empty((40, 40, 3))
    img[...] = border
    img[10:30, 10:30] = inside
    return img


def test_grounds_that_read_as_one_keep_their_own() -> None:
    grey = 1.0 - ONE_GROUND_DISTANCE / np.sqrt(3) + 0.01  # just within the distance of white
    assert piece_ground({"direct": _framed((1, 1, 1)), "reflected": _framed((grey,) * 3)}) is None


def test_grounds_far_apart_take_the_direct_pictures() -> None:
    white, navy = _framed((1, 1, 1)), _framed((18 / 255, 32 / 255, 54 / 255))
    assert piece_ground({"direct": white, "reflected": navy}) == "#ffffff"
    assert piece_ground({"direct": navy, "reflected": white}) == "#122036"
    # a prism's second reflection: any two far apart make one ground, the direct picture's
    assert piece_ground({"direct": white, "reflected": white, "reflected2": navy}) == "#ffffff"
    # the design's --background always wins
    assert piece_ground({"direct": white, "reflected": navy}, "#102030") == "#102030"


def test_the_recorded_ground_stands_where_no_background_is_given() -> None:
    assert recorded_background({"ground": "#102030"}) == "#102030"
    assert recorded_background({"background": "#ffffff", "ground": "#102030"}) == "#ffffff"
    assert recorded_background({"ground": "navy"}) is None  # damaged: each picture's own border colour
    assert recorded_background({}) is None


def test_prepare_gives_two_photographs_one_ground_and_two_graphics_their_own() -> None:
    from saucerfab.imaging.images import estimate_background
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest

    photos = prepare(DesignRequest(SAMPLES / "photos/astronaut.png", SAMPLES / "photos/rocket.jpg", **TINY))
    assert photos.ground == colour_hex(estimate_background(photos.texture["direct"]))
    assert any("border colours differ" in n and photos.ground in n for n in photos.print_notes)
    graphics = prepare(DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", **TINY))
    assert graphics.ground is None and not any("border colours differ" in n for n in graphics.print_notes)
    given = prepare(DesignRequest(SAMPLES / "photos/astronaut.png", SAMPLES / "photos/rocket.jpg",
                                  background="#336699", **TINY))
    assert given.ground == "#336699" and not any("border colours differ" in n for n in given.print_notes)


def test_the_design_records_the_ground_and_export_and_verify_read_it(tmp_path: Path) -> None:
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.imaging.images import parse_colour
    from saucerfab.model.design_folder import load_design
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.verify.wholeview import background_colours
    from saucerfab.workflow import run_design

    out = tmp_path / "d"
    run_design(DesignRequest(SAMPLES / "photos/astronaut.png", SAMPLES / "photos/rocket.jpg", **TINY), out,
               progress=lambda *a: None)
    params = json.loads((out / "design.json").read_text())["parameters"]
    assert params["background"] is None and params["ground"].startswith("#")
    design = load_design(out)
    # verify's whole view: one background for both views, the ground
    refs = {k: np.asarray(v, np.float64) / 255.0 for k, v in design.references.items()}
    bgs = background_colours(refs, recorded_background(design.parameters))
    assert np.allclose(bgs["direct"], bgs["reflected"]) and np.allclose(bgs["direct"], parse_colour(params["ground"]))
    # the export: the walls and what the cup shows of the plate take it too
    res = export_design(design, tmp_path / "p", printer="j55", cup_diameter_mm=80, formats=["ply"],
                        options=FabOptions(texture_px=512))
    opts = json.loads(res.summary_json.read_text())["options"]
    rgb = [round(float(c) * 255) for c in parse_colour(params["ground"])]
    assert opts["wall_rgb"] == opts["mirror_rgb"] == rgb


@pytest.mark.parametrize("background", [None, "#ffffff"])
def test_graphics_and_a_given_background_record_no_ground(background: str | None) -> None:
    from saucerfab.optimize.pipeline import _parameters
    from saucerfab.optimize.request import DesignRequest

    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", background=background)
    assert "ground" not in _parameters(req, {}, 1.0, [], None, None, None, background)
    if background is None:
        assert _parameters(req, {}, 1.0, [], None, None, None, "#102030")["ground"] == "#102030"
