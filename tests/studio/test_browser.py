"""The studio's page in a real, headless Chromium against the real server.

``python -m saucerfab studio`` is started in a subprocess on a fresh
workspace and a free port, with the token it makes itself; Debian's
Chromium (through Playwright, see ``tests/browser.py``) is shown the
sign-in form without it, signs in with the URL the server printed (which
leaves the address bar without the token), loads the page, is refused a bad upload with the
server's own message, uploads the bundled sample pictures, runs a tiny
design (16 x 16 heightfield, 48 px views, 6 iterations a stage) while the
progress and the first look show, checks the results, the 3D viewer
(``window.saucerViewerReady`` and a drawn canvas in its iframe), exports
for the J55 as 3MF, sees the printability findings and verify rows, and
downloads the print zip. Then it duplicates the design with a change
(the form is loaded with its options), cancels the copy, resumes it,
cancels it again and deletes it, reopens the first design from the history
and clears the form for a new one; then it signs out, and in again with the
token pasted into the sign-in form. The page must log no console error on
the way (apart from the one 400 the bad upload is answered with, and the
401 of the sign-in form itself).

Screenshots go to ``out/test-artifacts/studio/`` for a developer to look
at. Chromium comes from ``.ci/install-tools``; a missing browser fails the
test (it must not be skipped in CI).
"""

from __future__ import annotations

import json
import re
import time
import urllib.error
import urllib.request
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import browser
import pytest
from live_studio import free_port, http_get, printed_url, start_studio, stop_studio

from saucerfab.pages.labels import STAGE_LABELS

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
ARTIFACTS = ROOT / "out" / "test-artifacts" / "studio"


@dataclass(frozen=True)
class Studio:
    """The server under test: its address, the URL it printed (with its token), and the token."""

    base: str
    url: str
    token: str

    @property
    def auth(self) -> dict[str, str]:
        """The header a script signs in with."""
        return {"Authorization": f"token {self.token}"}


def _post(url: str, data: bytes, headers: dict[str, str]) -> tuple[int, dict[str, Any]]:
    req = urllib.request.Request(url, data=data, method="POST",
                                 headers={"Content-Type": "application/octet-stream", **headers})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


@pytest.fixture(scope="module")
def studio(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Studio]:
    tmp = tmp_path_factory.mktemp("studio")
    port = free_port()
    log = tmp / "server.log"
    proc = start_studio(tmp / "ws", port, log, sign_in=True)
    try:
        url = printed_url(log)
        token = url.split("?token=", 1)[1]
        assert url == f"http://127.0.0.1:{port}/?token={token}" and len(token) >= 32, url
        yield Studio(f"http://127.0.0.1:{port}", url, token)
        # the token was printed once (the banner) and never logged since, whatever the requests carried
        assert log.read_text(errors="replace").count(token) == 1, "the token is in the server's output again"
    finally:
        stop_studio(proc)
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        (ARTIFACTS / "server.log").write_text(log.read_text(errors="replace"), encoding="utf-8")


def _shot(page: Any, name: str) -> None:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.evaluate("() => window.scrollTo(0, 0)")  # the inputs column is sticky: shoot from the top
    page.screenshot(path=str(ARTIFACTS / f"{name}.png"), full_page=True)


def _images_loaded(page: Any, selector: str) -> int:
    """How many images matching ``selector`` have decoded pixels."""
    js = f"() => [...document.querySelectorAll({selector!r})].filter(i => i.complete && i.naturalWidth > 0).length"
    return int(page.evaluate(js))


def _shown_run(page: Any) -> str:
    """The id of the design the page shows (it keeps it in the address: ``#run=ID``)."""
    return str(page.evaluate("() => location.hash.slice('#run='.length)"))


def _wait(page: Any, what: str, check: Any, timeout_s: float, errors: list[str]) -> Any:
    """Poll ``check()`` until truthy; fail early on a page error, with what was awaited."""
    return browser.wait_for(page, what, check, timeout_s, errors, lambda es: [e for e in es if not _allowed(e)])


#: the browser logs a 4xx answer to fetch() as a console error: the bad upload's 400 is expected
_EXPECTED_400 = re.compile(r"Failed to load resource: the server responded with a status of 400")
#: ... and the sign-in form's own answer, a 401
_EXPECTED_401 = re.compile(r"Failed to load resource: the server responded with a status of 401")


#: the optimizer's keys as they would read if the page showed them raw ("bw_sigma_large", "bw sigma large",
#: "E_barrier", "E barrier", "max_iters"): the page shows people's words (saucerfab/pages/labels.py) instead
RAW_KEY = re.compile(
    r"\b(?:bw|plain)[_ ](?:free[_ ])?sigma|\bsigma[_ ](?:large|small)\b|\bE[_ ][a-z]+|\bmax[_ ]iters\b")
#: what the progress line said before the first look came
PREPARING = "preparing the first look"


def _allowed(error: str) -> bool:
    """Aborted requests are the page's own doing, not faults: the event stream it closes once a
    design is done, an <img> whose src it replaced before the picture came."""
    return "net::ERR_ABORTED" in error and error.startswith("request failed")


def _sign_in_form_shown(page: Any, errors: list[str]) -> None:
    """The page is the sign-in form (no studio, nothing of its API); the 401 it came with is no error, nor the
    requests of the page it replaced, aborted as it left."""
    page.locator("form[action='/login'] input[name='token']").wait_for(state="visible", timeout=10_000)
    assert page.locator("#design-form").count() == 0 and "Sign in" in page.inner_text("body")
    assert all(_EXPECTED_401.search(e) or _allowed(e) for e in errors), errors
    errors.clear()


def test_studio_page_designs_exports_and_downloads(studio: Studio, chromium: None, tmp_path: Path) -> None:
    t_start = time.monotonic()
    with browser.live_page((1280, 900), accept_downloads=True) as (page, errors):
        # ---- without the token: the sign-in form; with the printed URL: the studio, and no token in the address ----
        page.goto(studio.base + "/", wait_until="load")
        _sign_in_form_shown(page, errors)
        _shot(page, "00-sign-in")
        page.goto(studio.url, wait_until="load")
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        assert page.url == studio.base + "/", page.url  # the redirect took the token out of the address
        assert studio.token not in page.evaluate("() => document.cookie + location.href")  # an HttpOnly cookie
        assert page.locator("#who").inner_text() == "admin" and page.locator("#sign-out button").is_visible()
        assert page.locator("#printer option").count() >= 1
        unlabelled = page.evaluate(
            "() => [...document.querySelectorAll('input, select, textarea')]"
            ".filter(e => !e.labels.length).map(e => e.id)"
        )
        assert not unlabelled, f"controls without a label: {unlabelled}"
        _shot(page, "01-empty")

        # ---- a text file called .png: the server's message in the page, no traceback ----
        bad = tmp_path / "notes.png"
        bad.write_text("these are my notes, not a picture\n", encoding="utf-8")
        status, body = _post(f"{studio.base}/api/uploads?role=direct&name=notes.png", bad.read_bytes(), studio.auth)
        assert status == 400 and body.get("error"), (status, body)
        n_before = len(errors)
        page.set_input_files("#file-direct", str(bad))
        box = page.locator("#form-error")
        box.wait_for(state="visible", timeout=10_000)
        shown = box.inner_text()
        assert body["error"] in shown, (shown, body["error"])
        assert "Traceback" not in page.content() and 'File "' not in shown
        expected = errors[n_before:]
        assert all(_EXPECTED_400.search(e) for e in expected), expected
        del errors[n_before:]

        # ---- the two pictures, fitted into their frames at once ----
        page.set_input_files("#file-direct", str(SAMPLES / "direct_heart.png"))
        page.set_input_files("#file-reflected", str(SAMPLES / "reflected_star.png"))
        _wait(page, "both fitted previews", lambda: _images_loaded(page, ".dropzone .frame img") == 2, 20, errors)
        _wait(page, "the large previews", lambda: _images_loaded(page, "#fitted-pair img") == 2, 20, errors)
        assert page.locator("#form-error").is_hidden()
        assert "fitted.png" in page.locator(".dropzone[data-role='direct'] .frame img").get_attribute("src")
        assert page.locator("#fit-rule").inner_text().strip(), "the framing rule is shown"

        # ---- a tiny design ----
        page.locator("#advanced summary").click()
        page.fill("#resolution", "16")
        page.fill("#image-size", "48")
        page.fill("#max-iters", "6")
        page.select_option("#printer", "j55")
        assert page.input_value("#method") == "auto"  # the default
        assert page.get_attribute("#max-iters", "placeholder") == "120/90 (auto), 120 (fast), 400 (paper)"  # the caps
        page.select_option("#method", "paper")  # the paper's three stages
        page.locator("#method-help").scroll_into_view_if_needed()
        page.screenshot(path=str(ARTIFACTS / "02-advanced.png"))  # the advanced options, for a person to look at
        _shot(page, "02-pictures")
        page.click("#start")
        page.locator("#run").wait_for(state="visible", timeout=20_000)

        seen: dict[str, Any] = {"stage": False, "look": False, "stale": None, "raw": set()}

        def progress_then_done() -> bool:
            status = page.locator("#run-status").inner_text()
            if status in ("failed", "cancelled", "interrupted"):
                raise AssertionError(f"the design ended {status}: {page.locator('#run-error').inner_text()}")
            # the looks first, then the line: the page sets both in one update, so a line read after the
            # looks were seen is that update's or a later one (read the other way round, an update landing
            # between the two reads showed a stale line beside new looks on a loaded machine)
            looks = page.locator("#looks").is_visible() and _images_loaded(page, "#looks-gallery img") >= 3
            line = page.locator("#progress-stage").inner_text()
            if not seen["stage"] and re.search(r"Stage \d+ of 3\b", line):
                seen["stage"] = True
            if looks and status == "running" and PREPARING in line:
                seen["stale"] = line  # the first look is shown, yet the line still waits for it
            if status == "running":
                seen["raw"] |= set(RAW_KEY.findall(page.locator("#progress").inner_text()))
            if not seen["look"] and looks:
                seen["look"] = True
                _shot(page, "03-running")
            return status == "done"

        _wait(page, "the design to finish", progress_then_done, 75, errors)
        assert seen["look"], "no preview (first look) appeared while the design ran"
        assert seen["stage"], "no stage progress appeared while the design ran"
        assert seen["stale"] is None, f"the progress line said {seen['stale']!r} with the first look shown"
        assert not seen["raw"], f"the progress showed the optimizer's keys: {seen['raw']}"

        # ---- results: the views, the height change, verify, the 3D print ----
        page.locator("#results").wait_for(state="visible", timeout=10_000)
        _wait(page, "the result images", lambda: _images_loaded(page, "#results-gallery img") >= 4, 20, errors)
        keys = page.evaluate("() => [...document.querySelectorAll('#results-gallery figure')].map(f => f.dataset.key)")
        assert {"composite", "direct", "reflected", "height_change"} <= set(keys), keys
        assert page.locator("#verify table tr").count() >= 2
        viewer = page.frame_locator("#viewer")
        page.locator("#viewer").scroll_into_view_if_needed()

        def viewer_frame() -> Any:
            for f in page.frames:
                if f.url.endswith("/viewer") and f.evaluate("() => window.saucerViewerReady === true"):
                    return f
            return None

        _wait(page, "the 3D viewer", viewer_frame, 45, errors)
        canvas = viewer.locator("canvas").first.screenshot()
        assert browser.canvas_is_drawn(canvas), "the 3D viewer's canvas is blank"
        page.locator("#stages summary").click()  # the stages the design ran, in people's words
        stages_text = page.locator("#stages").inner_text()
        for name in ("bw_sigma_large", "bw_sigma_small", "sparse"):  # --method paper, pictures with a subject
            assert STAGE_LABELS[name] in stages_text, (name, stages_text)
        assert not RAW_KEY.findall(page.locator("#run").inner_text()), page.locator("#run").inner_text()
        history = page.locator("#history li")
        _wait(page, "the design done in the history", lambda: "done" in " ".join(history.all_inner_texts()), 10, errors)
        assert history.count() == 1
        _shot(page, "04-done")

        # ---- export for the J55 as 3MF: findings, verify rows, the zip ----
        page.select_option("#export-printer", "j55")
        page.check("#export-formats input[value='3mf']")
        page.click("#export-start")
        link = page.locator("a[data-download='j55']")
        card = page.locator(".export-card[data-printer='j55']")

        def export_done() -> bool:
            if "failed" in card.locator(".badge").all_inner_texts():
                raise AssertionError(f"the export failed: {card.inner_text()}")
            return link.count() == 1

        _wait(page, "the export", export_done, 75, errors)
        assert card.locator(".findings li").count() >= 1, card.inner_text()
        assert "printable" in card.inner_text()
        counts = re.search(r"printable \(0 errors, 0 warnings, \d+ info findings?\)", card.inner_text())
        assert counts, card.inner_text()  # the check's counts, as the print's report says them
        assert card.locator("table.verify tr").count() >= 2, card.inner_text()
        _shot(page, "05-export")
        with page.expect_download(timeout=20_000) as info:
            link.click()
        zpath = tmp_path / "print.zip"
        info.value.save_as(zpath)
        with zipfile.ZipFile(zpath) as z:
            names = z.namelist()
        assert any(n.endswith(".3mf") for n in names), names

        # ---- duplicate with changes, cancel, resume, delete ----
        first_id = _shown_run(page)
        first_title = page.locator("#run-title").inner_text()
        page.click("#run-duplicate")
        assert page.locator("#duplicate-note").is_visible()
        assert page.input_value("#resolution") == "16" and page.input_value("#shape") == "waves"
        assert page.input_value("#method") == "paper"
        page.select_option("#shape", "bowl")
        page.fill("#max-iters", "150")  # long enough to be caught running
        page.click("#start")
        _wait(page, "the copy", lambda: _shown_run(page) != first_id, 20, errors)
        copy_id = _shown_run(page)
        status, body = http_get(f"{studio.base}/api/runs/{copy_id}", headers=studio.auth)
        record = json.loads(body)
        assert record["options"]["shape"] == "bowl" and record["options"]["resolution"] == 16, record["options"]
        assert record["options"]["method"] == "paper", record["options"]
        _wait(page, "the copy in the history", lambda: page.locator("#history li").count() == 2, 10, errors)

        def status_is(*wanted: str) -> bool:
            return page.locator("#run-status").inner_text() in wanted

        page.click("#run-cancel")
        _wait(page, "the copy to be cancelled", lambda: status_is("cancelled"), 30, errors)
        assert page.locator("#run-resume").is_visible()
        page.click("#run-resume")
        _wait(page, "the copy to be queued again", lambda: status_is("queued", "running"), 20, errors)
        page.click("#run-cancel")
        _wait(page, "the copy to be cancelled again", lambda: status_is("cancelled"), 30, errors)
        page.once("dialog", lambda dialog: dialog.accept())
        page.click("#run-delete")
        _wait(page, "the copy to be deleted", lambda: page.locator("#history li").count() == 1, 20, errors)
        assert page.locator("#run").is_hidden()
        assert http_get(f"{studio.base}/api/runs/{copy_id}", headers=studio.auth)[0] == 404
        assert http_get(f"{studio.base}/api/runs/{first_id}")[0] == 401  # and nothing without the token

        # ---- reopen the first design from the history; then a new, empty design ----
        page.click("#history li button")
        reopened = lambda: status_is("done") and page.locator("#results").is_visible()  # noqa: E731
        _wait(page, "the reopened design", reopened, 20, errors)
        assert page.locator("#run-title").inner_text() == first_title
        page.click("#new-design")
        assert page.locator("#welcome").is_visible() and page.locator("#run").is_hidden()
        assert page.locator(".dropzone.filled").count() == 0

        hard = [e for e in errors if not _allowed(e)]
        assert not hard, hard

        # ---- sign out: the sign-in form again; the token pasted into it: the studio and its designs again ----
        page.click("#sign-out button")
        _sign_in_form_shown(page, errors)
        page.fill("input[name='token']", "not-the-token-of-this-studio")
        page.click("#sign-in")
        page.locator("p.error").wait_for(state="visible", timeout=10_000)
        assert "That is not this studio's token" in page.locator("p.error").inner_text()
        _shot(page, "06-wrong-token")
        _sign_in_form_shown(page, errors)
        page.fill("input[name='token']", studio.token)
        page.click("#sign-in")
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        _wait(page, "the history after signing in again", lambda: page.locator("#history li").count() == 1, 10, errors)
        assert page.url == studio.base + "/", page.url
        hard = [e for e in errors if not _allowed(e)]
        assert not hard, hard
    assert time.monotonic() - t_start < 150


def test_progress_reads_in_peoples_words_once_the_first_look_is_in(studio: Studio, chromium: None) -> None:
    """The progress line and energies for a given progress.json, through the page's own RunView.

    A design's first look and its first stage report come a moment apart; here the progress
    document of that moment is given, so the line is tested every run, not only when a run is
    caught in between.
    """
    with browser.live_page((1000, 700)) as (page, errors):
        page.goto(studio.url, wait_until="load")  # signs in
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        shown = page.evaluate("""async () => {
            const { RunView } = await import("/static/run.js");  // the page's module: its labels are set
            const view = new RunView();
            view.show({ id: "20260101-000000-abcd", status: "running", title: "t" });
            const energies = { E_visual: 369712.3, E_deform: 0.01234, E_barrier: -1234.5, E_total: 369700.1 };
            const read = () => [document.querySelector("#progress-stage").textContent,
                                document.querySelector("#progress-energies").textContent];
            view.progress({ stage: null, stages: 3, stage_index: 0, energies: {}, looks: null });
            const before = read();
            view.progress({ stage: null, stages: 3, stage_index: 0, energies: {},
                            looks: { stage: "first_look", files: {} } });
            const after = read();
            view.progress({ stage: "bw_sigma_large", stages: 3, stage_index: 0, iteration: 2, max_iterations: 6,
                            energies, looks: { stage: "first_look", files: {} } });
            return { before, after, running: read() };
        }""")
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        page.locator("#progress").screenshot(path=str(ARTIFACTS / "progress-labels.png"))  # for a person to look at
        assert PREPARING in shown["before"][0], shown
        assert PREPARING not in shown["after"][0] and "First look ready" in shown["after"][0], shown
        line, values = shown["running"]
        assert line == f"Stage 1 of 3: {STAGE_LABELS['bw_sigma_large']}, iteration 2 of 6", shown
        assert "image error369,700" in values and "shape change0.01234" in values, values
        assert "barrier" not in values and "objective" not in values, values  # the barrier's logs mean nothing
        assert not RAW_KEY.findall(line + values), shown
        assert not [e for e in errors if not _allowed(e)], errors


def test_the_admins_history_names_other_users_designs(studio: Studio, chromium: None) -> None:
    """The admin's list holds everyone's designs: the page's own history marks each of another user's with
    its owner (and none of the admin's own)."""
    with browser.live_page((1000, 700)) as (page, errors):
        page.goto(studio.url, wait_until="load")
        page.wait_for_selector("body[data-ready='true']", timeout=20_000)
        shown = page.evaluate("""async () => {
            const { renderHistory } = await import("/static/history.js");
            const run = (id, owner) => ({ id, owner, title: `design ${id}`, status: "done", created: null });
            renderHistory([run("a", "alice"), run("b", "admin")], null, () => {}, "admin");
            return [...document.querySelectorAll("#history li")].map((li) => [
                li.querySelector(".history-owner").textContent,
                li.querySelector("button").getAttribute("aria-label")]);
        }""")
        assert shown == [[" · alice", "Open design design a (done, alice's)"], ["", "Open design design b (done)"]], shown
        assert not [e for e in errors if not _allowed(e)], errors
