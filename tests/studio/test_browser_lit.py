"""An export seen under the room light (issue 45), in a real headless Chromium against the real server.

The workspace holds a done run with a done export before the server starts
(``lit_run.py``: a flat saucer painted with the heart, for the bureau as OBJ),
so the one job here is the lit verify. The page opens that run: its export
card offers "See it under the room light" and nothing lit yet; the click
queues the job, the card shows its progress, then each view's picture under
the light beside its emitted one, with the lit PSNR and the shading pattern
figures in a table. The page logs no console error on the way.

The screenshot goes to ``out/test-artifacts/studio/lit-export.png`` for a
person to look at. Chromium comes from ``.ci/install-tools``; a missing
browser fails the test (``tests/conftest.py``).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import browser
import pytest
from lit_run import PRINTER, done_run_with_export
from live_studio import free_port, printed_url, start_studio, stop_studio

from saucerfab.studio.workspace import Workspace

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "out" / "test-artifacts" / "studio"


@pytest.fixture(scope="module")
def studio(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, str]]:
    """(the URL with the token the server printed, the id of the done run with its export)."""
    tmp = tmp_path_factory.mktemp("studio-lit")
    run_id = done_run_with_export(Workspace(tmp / "ws"))
    port = free_port()
    proc = start_studio(tmp / "ws", port, tmp / "server.log", sign_in=True)
    try:
        yield printed_url(tmp / "server.log"), run_id
    finally:
        stop_studio(proc)


def _wait(page: Any, what: str, check: Any, timeout_s: float, errors: list[str]) -> Any:
    return browser.wait_for(page, what, check, timeout_s, errors, _hard)


def _hard(errors: list[str]) -> list[str]:
    """Errors that are faults, not a request the page aborted itself (an <img> whose src it replaced)."""
    return [e for e in errors if "net::ERR_ABORTED" not in e]



def _loaded(page: Any, selector: str) -> int:
    """How many images matching ``selector`` have decoded pixels."""
    js = f"() => [...document.querySelectorAll({selector!r})].filter(i => i.complete && i.naturalWidth > 0).length"
    return int(page.evaluate(js))


def test_an_export_is_shown_under_the_room_light_beside_its_emitted_view(studio: tuple[str, str],
                                                                        chromium: None) -> None:
    url, run_id = studio
    t_start = time.monotonic()
    with browser.live_page((1280, 1000)) as (page, errors):
        page.goto(url, wait_until="load")  # signs in (the cookie), then the page
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        page.goto(url.split("?", 1)[0] + f"#run={run_id}", wait_until="load")
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        card = page.locator(f".export-card[data-printer='{PRINTER}']")
        ask = card.locator(f"button[data-lit='{PRINTER}']")
        _wait(page, "the export card's room-light button", lambda: ask.count() == 1, 20, errors)
        assert ask.inner_text() == "See it under the room light"
        assert card.locator(".lit-pair").count() == 0 and card.locator(".lit table").count() == 0  # not asked yet

        ask.click()
        seen = {"working": False}

        def lit_done() -> bool:
            text = card.locator(".lit").inner_text()
            if "Waiting for a worker" in text or "Rendering under the room light" in text:
                seen["working"] = True
            errs = card.locator(".lit .message.error")
            if errs.count():
                raise AssertionError(f"the verify under the room light failed: {errs.inner_text()}")
            return _loaded(page, ".lit-pair img") == 4

        _wait(page, "the views under the room light", lit_done, 60, errors)
        assert seen["working"], "the card never said the lit verify was queued or running"
        pairs = card.locator(".lit-pair")
        assert pairs.count() == 2  # the direct and the reflected view from the design eye
        for i in range(2):
            keys = pairs.nth(i).evaluate("p => [...p.querySelectorAll('figure')].map(f => f.dataset.key)")
            assert keys == ["emitted", "lit"], keys  # the emitted picture, the lit one beside it
            srcs = pairs.nth(i).evaluate("p => [...p.querySelectorAll('img')].map(i => i.getAttribute('src'))")
            assert srcs[0].endswith(".png") and not srcs[0].endswith("_lit.png") and srcs[1].endswith("_lit.png"), srcs
            # side by side: one row, the same height
            boxes = [pairs.nth(i).locator("img").nth(k).bounding_box() for k in range(2)]
            assert abs(boxes[0]["y"] - boxes[1]["y"]) < 2 and boxes[1]["x"] > boxes[0]["x"] + boxes[0]["width"] - 2
            assert abs(boxes[0]["height"] - boxes[1]["height"]) < 0.05 * boxes[1]["height"], boxes
        rows = card.locator(".lit table tr")
        assert rows.count() == 3, card.locator(".lit").inner_text()
        head = rows.nth(0).inner_text()
        assert "under the light (dB)" in head and "shading pattern (dB)" in head and "flat plate (dB)" in head
        direct = rows.nth(1).inner_text()
        assert direct.startswith("direct") and "×" in direct, direct
        caption = pairs.nth(0).locator("figcaption").nth(1).inner_text()
        assert "under the room light" in caption and "shading pattern" in caption, caption
        assert card.locator(f"button[data-lit='{PRINTER}']").count() == 0  # done: nothing more to ask for
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        card.locator(".lit").scroll_into_view_if_needed()
        card.screenshot(path=str(ARTIFACTS / "lit-export.png"))  # for a person to look at
        assert not _hard(errors), errors
    assert time.monotonic() - t_start < 60
