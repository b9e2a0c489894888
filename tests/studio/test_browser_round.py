"""The studio's page offers the round saucer (issue 44), in a real headless Chromium against the real server.

The scene choice lists every preset, the round one as "Round saucer, cup at
the centre"; the saucer's diameter is asked for beside it only while a round
scene is chosen, its placeholder the scene's own for the cup's diameter given.
A diameter too small is refused with the design's message in the page; a
good one starts a tiny round design whose options hold the scene and the
diameter, and "Duplicate with changes" loads both back into the form.

Screenshots go to ``out/test-artifacts/studio/`` (``round-form.png``) for a
person to look at. Chromium comes from ``.ci/install-tools``; a missing
browser fails the test (``tests/conftest.py``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import browser
import pytest
from live_studio import free_port, start_studio, stop_studio

from saucerfab.model.scene import PRESETS, round_scene
from saucerfab.studio.options import SCENE_LABELS

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
ARTIFACTS = ROOT / "out" / "test-artifacts" / "studio"
#: the browser logs the refused run's 400 as a console error: expected once
_EXPECTED_400 = re.compile(r"Failed to load resource: the server responded with a status of 400")


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The address of a studio without sign-in (``--no-auth``) on a fresh workspace."""
    tmp = tmp_path_factory.mktemp("studio-round")
    port = free_port()
    proc = start_studio(tmp / "ws", port, tmp / "server.log")
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        stop_studio(proc)


def _wait(page: Any, what: str, check: Any, timeout_s: float, errors: list[str]) -> Any:
    return browser.wait_for(page, what, check, timeout_s, errors, _hard)


def _hard(errors: list[str]) -> list[str]:
    """Errors that are faults: not the expected 400, not a request the page aborted itself."""
    return [e for e in errors if not _EXPECTED_400.search(e) and "net::ERR_ABORTED" not in e]



def test_the_form_offers_the_round_saucer_and_its_diameter(base: str, chromium: None) -> None:
    rnd = round_scene()
    default_mm = 2 * rnd.saucer.radius * rnd.mm_per_unit
    per_cup = default_mm / rnd.cup_diameter_mm
    with browser.live_page((1280, 900)) as (page, errors):
        page.goto(base + "/", wait_until="load")
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        choices = page.evaluate("() => [...document.querySelectorAll('#scene option')].map(o => [o.value, o.text])")
        assert [k for k, _ in choices] == list(PRESETS), choices
        assert dict(choices)["round"] == SCENE_LABELS["round"] == "Round saucer, cup at the centre"
        assert page.input_value("#scene") == "wide" and page.locator("#saucer-diameter").is_hidden()

        # ---- round: the diameter shows, its placeholder the scene's for the cup given ----
        page.select_option("#scene", "round")
        assert page.locator("#saucer-diameter").is_visible()
        assert page.get_attribute("#saucer-diameter", "placeholder").startswith(f"{default_mm:g} ")
        page.fill("#cup-diameter", "100")
        assert page.get_attribute("#saucer-diameter", "placeholder").startswith(f"{per_cup * 100:g} ")
        page.fill("#cup-diameter", f"{rnd.cup_diameter_mm:g}")
        unlabelled = page.evaluate(
            "() => [...document.querySelectorAll('input, select, textarea')].filter(e => !e.labels.length).map(e => e.id)")
        assert not unlabelled, f"controls without a label: {unlabelled}"

        # ---- the pictures and a tiny design ----
        page.set_input_files("#file-direct", str(SAMPLES / "direct_heart.png"))
        page.set_input_files("#file-reflected", str(SAMPLES / "reflected_star.png"))
        _wait(page, "both fitted previews", lambda: page.evaluate(
            "() => [...document.querySelectorAll('.dropzone .frame img')].filter(i => i.complete && i.naturalWidth > 0)"
            ".length") == 2, 20, errors)
        page.locator("#advanced summary").click()
        page.fill("#resolution", "16")
        page.fill("#image-size", "48")
        page.fill("#max-iters", "4")
        page.locator("#verify-after").uncheck()
        page.fill("#saucer-diameter", "180")
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        page.evaluate("() => window.scrollTo(0, 0)")
        section = page.locator("section[aria-labelledby='h-object']")
        section.scroll_into_view_if_needed()
        section.screenshot(path=str(ARTIFACTS / "round-form.png"))  # for a person to look at

        # ---- too small: the design's own message, in the page ----
        page.fill("#saucer-diameter", "50")
        page.click("#start")
        box = page.locator("#form-error")
        box.wait_for(state="visible", timeout=20_000)
        assert "give a saucer of at least" in box.inner_text() and "--saucer-diameter-mm" in box.inner_text()

        # ---- a good one: the run records the scene and the diameter ----
        page.fill("#saucer-diameter", "180")
        page.click("#start")
        page.locator("#run").wait_for(state="visible", timeout=20_000)
        run_id = _wait(page, "the run in the address", lambda: page.evaluate("() => location.hash.slice(5)"), 10, errors)
        options = page.evaluate("async (id) => (await (await fetch(`/api/runs/${id}`)).json()).options", run_id)
        assert options["scene"] == "round" and options["saucer_diameter_mm"] == 180, options

        def finished() -> str | None:
            status = page.locator("#run-status").inner_text()
            return status if status in ("done", "failed", "cancelled", "interrupted") else None

        status = _wait(page, "the round design to finish", finished, 90, errors)
        assert status == "done", page.locator("#run-error").inner_text()

        # ---- duplicate with changes: the form gets the scene and the diameter back ----
        page.click("#run-duplicate")
        assert page.input_value("#scene") == "round" and page.input_value("#saucer-diameter") == "180"
        assert page.locator("#saucer-diameter").is_visible()
        page.select_option("#scene", "paper")  # a rectangle: no diameter asked for
        assert page.locator("#saucer-diameter").is_hidden()
        assert not _hard(errors), errors
