"""A round saucer in the studio (issue 44): the scene choice and the saucer's diameter, through the API.

No worker runs (the client is outside its ``with`` block): a run the studio
takes stays queued, so these tests see what the form's options are checked
against (``check_options`` and ``validate_run``, the design's own ``prepare``).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from starlette.testclient import TestClient
from studio_helpers import TINY, TOKEN, pair, signed_in

from saucerfab.model.scene import CUP_RING_MM, MIN_DISC_BAND_MM, PRESETS, round_scene
from saucerfab.studio.app import create_app
from saucerfab.studio.auth import Auth
from saucerfab.studio.options import SCENE_LABELS


@pytest.fixture
def idle(tmp_path: Path) -> TestClient:
    """A signed-in client with no job queue running: runs stay queued."""
    return signed_in(create_app(tmp_path / "ws", auth=Auth.shared(TOKEN), grace_s=15))


def test_the_options_offer_every_scene_with_the_round_one_labelled(idle: TestClient) -> None:
    doc = idle.get("/api/options").json()
    scenes = {s["key"]: s for s in doc["scenes"]}
    assert list(scenes) == list(PRESETS) and doc["defaults"]["scene"] == "wide"
    assert scenes["round"]["label"] == SCENE_LABELS["round"] == "Round saucer, cup at the centre"
    assert scenes["round"]["round"] and not scenes["paper"]["round"] and not scenes["wide"]["round"]
    # what an empty diameter gets, per mm of cup: the page shows it for the cup's diameter given
    rnd = round_scene()
    assert scenes["round"]["saucer_per_cup"] * rnd.cup_diameter_mm == pytest.approx(
        2 * rnd.saucer.radius * rnd.mm_per_unit)


def test_a_round_run_with_its_diameter_is_taken_and_recorded(idle: TestClient) -> None:
    ids = pair(idle)
    r = idle.post("/api/runs", json={**ids, **TINY, "scene": "round", "saucer_diameter_mm": 180})
    assert r.status_code == 201, r.text
    run = r.json()
    assert run["options"]["scene"] == "round" and run["options"]["saucer_diameter_mm"] == 180
    # and without a diameter: the scene's
    assert idle.post("/api/runs", json={**ids, **TINY, "scene": "round"}).status_code == 201


def test_a_diameter_the_design_would_refuse_is_refused_with_its_message(idle: TestClient) -> None:
    ids = pair(idle)
    smallest = math.ceil(round_scene().cup_diameter_mm + 2 * (CUP_RING_MM + MIN_DISC_BAND_MM))
    bad = [
        ({"saucer_diameter_mm": 180}, "--saucer-diameter-mm is for a round saucer: add --scene round"),  # paper
        ({"scene": "wide", "saucer_diameter_mm": 180}, "is for a round saucer"),
        ({"scene": "round", "saucer_diameter_mm": smallest - 10}, f"give a saucer of at least {smallest} mm"),
        ({"scene": "round", "saucer_diameter_mm": -1}, "saucer_diameter_mm must be a positive number"),
        ({"scene": "round", "saucer_diameter_mm": "big"}, "option 'saucer_diameter_mm' must be a number"),
    ]
    for extra, words in bad:
        r = idle.post("/api/runs", json={**ids, **TINY, **extra})
        assert r.status_code == 400 and words in r.json()["error"], (extra, r.text)
    assert idle.get("/api/runs").json() == []  # nothing was made of the refusals
