"""Open HTML pages in a real, headless Chromium (Debian's) through Playwright.

For the tests only. The browser is Debian's ``chromium`` package
(``/usr/bin/chromium``, or ``$SAUCERFAB_CHROMIUM``), installed by
``.ci/install-tools``; Playwright's own browser downloads are never used.
WebGL runs on SwiftShader (software, CPU only): ``--use-angle=swiftshader``
picks ANGLE's SwiftShader backend and ``--enable-unsafe-swiftshader`` allows
it for WebGL (Chromium otherwise refuses a software fallback). Note that
``--use-gl=swiftshader`` *disables* WebGL in current Chromium.

One browser is started on first use and shared by all pages of the process
(each page gets a fresh context); it is closed at exit.
"""

from __future__ import annotations

import atexit
import io
import os
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

CHROMIUM_ARGS = (
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)
INSTALL_HINT = "run .ci/install-tools (installs Debian's chromium) and `pip install -e .[dev]` (playwright)"


class BrowserUnavailable(RuntimeError):
    """Chromium or Playwright is missing; the message says how to install them."""


def chromium_path() -> Path:
    """The Chromium executable: ``$SAUCERFAB_CHROMIUM`` or ``/usr/bin/chromium``."""
    return Path(os.environ.get("SAUCERFAB_CHROMIUM") or "/usr/bin/chromium")


_state: dict[str, Any] = {}


def _browser() -> Any:
    if "browser" in _state:
        return _state["browser"]
    exe = chromium_path()
    if not (exe.is_file() and os.access(exe, os.X_OK)):
        raise BrowserUnavailable(f"no Chromium executable at {exe}; {INSTALL_HINT}")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError as exc:
        raise BrowserUnavailable(f"Playwright is not installed ({exc}); {INSTALL_HINT}") from None
    pw = sync_playwright().start()
    try:
        browser = pw.chromium.launch(executable_path=str(exe), headless=True, args=list(CHROMIUM_ARGS))
    except Exception as exc:
        pw.stop()
        raise BrowserUnavailable(f"Chromium at {exe} did not start: {exc}") from exc
    _state.update(pw=pw, browser=browser)
    atexit.register(_close)
    return browser


def _close() -> None:
    browser, pw = _state.pop("browser", None), _state.pop("pw", None)
    try:
        if browser is not None:
            browser.close()
    finally:
        if pw is not None:
            pw.stop()


@dataclass
class PageResult:
    """What happened when a page was opened.

    Attributes:
        errors: console errors, uncaught page errors and failed requests, in
            the order they came; empty for a clean page.
        warnings: console warnings.
        ready: whether ``wait_for`` became true before the timeout.
        screenshot: path of the full-page PNG.
        elements: PNG bytes of each requested element's screenshot, by selector.
        info: the value of the ``evaluate`` expression (None if not asked).
        interaction: what ``interact`` returned (None if not asked).
        seconds: time from navigation to ready (or timeout).
    """

    errors: list[str]
    warnings: list[str]
    ready: bool
    screenshot: Path
    elements: dict[str, bytes] = field(default_factory=dict)
    info: Any = None
    interaction: Any = None
    seconds: float = 0.0

    def element_png(self, selector: str = "canvas") -> bytes:
        """The PNG of the first element matching ``selector`` (asked for in ``open_page``)."""
        try:
            return self.elements[selector]
        except KeyError:
            raise KeyError(
                f"no screenshot of {selector!r}; pass it in open_page(..., elements=[...]); "
                f"have {sorted(self.elements)}"
            ) from None


def open_page(
    html_path: str | os.PathLike[str],
    screenshot_path: str | os.PathLike[str],
    *,
    wait_for: str = "window.saucerViewerReady === true",
    timeout_s: float = 60,
    elements: Sequence[str] = ("canvas",),
    evaluate: str | None = None,
    interact: Callable[[Any], Any] | None = None,
    viewport: tuple[int, int] = (1000, 720),
) -> PageResult:
    """Open ``html_path`` (file://), wait for ``wait_for``, evaluate, take screenshots, interact.

    Waiting stops early, half a second after the first error, so a broken
    page does not cost the whole timeout. The screenshots are taken either
    way (an element that is absent is left out of ``elements``).

    Args:
        html_path: the page.
        screenshot_path: where the full-page PNG goes (folders are created).
        wait_for: a JavaScript expression polled until it is truthy.
        timeout_s: the longest wait, seconds.
        elements: CSS selectors whose first match is screenshotted too.
        evaluate: a JavaScript expression evaluated after the wait (its
            JSON-able value becomes ``PageResult.info``).
        interact: called with the Playwright page after the screenshots
            (to drag, scroll, take more screenshots); its return value
            becomes ``PageResult.interaction``. Errors it causes count.
        viewport: width, height in CSS pixels (device scale factor 1).

    Raises:
        BrowserUnavailable: no Chromium or no Playwright.
    """
    browser = _browser()
    url = Path(html_path).resolve().as_uri()
    shot = Path(screenshot_path)
    shot.parent.mkdir(parents=True, exist_ok=True)
    errors: list[str] = []
    warnings: list[str] = []
    size = {"width": viewport[0], "height": viewport[1]}
    context = browser.new_context(viewport=size, device_scale_factor=1)
    try:
        page = context.new_page()

        def on_console(msg: Any) -> None:
            if msg.type == "error":
                errors.append(f"console.error: {msg.text}")
            elif msg.type == "warning":
                warnings.append(msg.text)

        page.on("console", on_console)
        page.on("pageerror", lambda exc: errors.append(f"uncaught: {exc}"))
        page.on(
            "requestfailed",
            lambda req: errors.append(f"request failed: {req.url[:200]} ({req.failure})"),
        )
        t0 = time.monotonic()
        page.goto(url, wait_until="load", timeout=timeout_s * 1000)
        probe = f"() => {{ try {{ return !!({wait_for}); }} catch (e) {{ return false; }} }}"
        ready = False
        first_error: float | None = None
        while True:
            ready = bool(page.evaluate(probe))
            now = time.monotonic()
            if ready or now - t0 > timeout_s:
                break
            if errors and first_error is None:
                first_error = now
            if first_error is not None and now - first_error > 0.5:
                break
            page.wait_for_timeout(50)
        seconds = time.monotonic() - t0
        if not ready:
            errors.append(f"timed out after {seconds:.1f} s waiting for {wait_for}")
        info = page.evaluate(f"() => ({evaluate})") if evaluate else None
        page.screenshot(path=str(shot), full_page=True)
        pngs: dict[str, bytes] = {}
        for selector in elements:
            loc = page.locator(selector).first
            if loc.count():
                pngs[selector] = loc.screenshot()
        interaction = interact(page) if interact is not None else None
    finally:
        context.close()
    return PageResult(errors, warnings, ready, shot, pngs, info, interaction, seconds)


@contextmanager
def live_page(viewport: tuple[int, int] = (1280, 900), **context_args: Any) -> Iterator[tuple[Any, list[str]]]:
    """A fresh page of the shared browser for a page served over HTTP (``open_page`` opens files).

    Yields ``(page, errors)``: the Playwright page (navigate it yourself) and
    the list its console errors, uncaught page errors and failed requests
    are appended to as they come, from every frame of the page, each a line
    ``"console.error: ..."``, ``"uncaught: ..."`` or ``"request failed: URL (why)"``.
    ``context_args`` go to ``browser.new_context`` (e.g. ``accept_downloads=True``).
    The page's context is closed on exit.

    Raises:
        BrowserUnavailable: no Chromium or no Playwright.
    """
    browser = _browser()
    context = browser.new_context(
        viewport={"width": viewport[0], "height": viewport[1]}, device_scale_factor=1, **context_args
    )
    errors: list[str] = []
    try:
        page = context.new_page()
        page.on("console", lambda msg: errors.append(f"console.error: {msg.text}") if msg.type == "error" else None)
        page.on("pageerror", lambda exc: errors.append(f"uncaught: {exc}"))
        page.on("requestfailed", lambda req: errors.append(f"request failed: {req.url[:200]} ({req.failure})"))
        yield page, errors
    finally:
        context.close()


def canvas_is_drawn(png: bytes, *, min_std: float = 6.0, min_colours: int = 64) -> bool:
    """Whether a screenshot shows a real picture, not a blank or one-colour area.

    True when the standard deviation of the RGB values exceeds ``min_std``
    (0-255 scale) and more than ``min_colours`` distinct colours occur.
    """
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    if rgb.size == 0:
        return False
    colours = np.unique(rgb.reshape(-1, 3), axis=0).shape[0]
    return float(rgb.std()) > min_std and colours > min_colours


def wait_for(page: Any, what: str, check: Callable[[], Any], timeout_s: float, errors: list[str],
             faults: Callable[[list[str]], list[str]]) -> Any:
    """Poll ``check()`` every 100 ms until truthy and return its value; fail early on a page error
    (``faults(errors)``: the errors that are faults, not ones the test expects), naming what was awaited."""
    t0 = time.monotonic()
    while not (value := check()):
        hard = faults(errors)
        assert not hard, f"page errors while waiting for {what}: {hard}"
        assert time.monotonic() - t0 < timeout_s, f"timed out after {timeout_s} s waiting for {what}"
        page.wait_for_timeout(100)
    return value
