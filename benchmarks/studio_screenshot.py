"""Regenerate ``docs/studio.png``: the studio page with a finished design (for the README).

    .venv/bin/python benchmarks/studio_screenshot.py [--out docs/studio.png] [--resolution 48]
        [--image-size 128] [--max-iters N] [--workspace DIR] [--timeout 1200]

Starts ``saucerfab studio`` on a fresh workspace (a temporary folder unless
``--workspace``) and a free port, drives Debian's headless Chromium through
Playwright (``tests/browser.py``) as a designer would: uploads the bundled
samples (``direct_heart.png`` on the saucer, ``reflected_star.png`` in the
cup), sets a moderate size (48 x 48 heightfield, 128 px views, the default
iterations), starts the design, waits for it, exports it for the J55 (3MF)
and takes a 1280 x 900 screenshot of the finished design with its results
and 3D print. Prints how long each step took.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "studio"))

import browser  # noqa: E402  (tests/browser.py: Debian's Chromium through Playwright)
from live_studio import free_port, start_studio, stop_studio  # noqa: E402  (tests/studio/live_studio.py)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "studio.png")
    ap.add_argument("--resolution", type=int, default=48)
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--max-iters", type=int, default=None, help="default: the design's own")
    ap.add_argument("--workspace", type=Path, default=None)
    ap.add_argument("--timeout", type=float, default=1200, help="longest wait for the design, s")
    args = ap.parse_args()

    tmp = tempfile.TemporaryDirectory(prefix="studio-shot-")
    workspace = args.workspace or Path(tmp.name) / "ws"
    port = free_port()
    t0 = time.monotonic()
    proc = start_studio(workspace, port, Path(tmp.name) / "server.log")
    print(f"server up after {time.monotonic() - t0:.1f} s (port {port}, workspace {workspace})")
    try:
        with browser.live_page((1280, 900)) as (page, errors):
            page.goto(f"http://127.0.0.1:{port}/", wait_until="load")
            page.wait_for_selector("body[data-ready='true']", timeout=30_000)
            page.set_input_files("#file-direct", str(ROOT / "samples" / "direct_heart.png"))
            page.set_input_files("#file-reflected", str(ROOT / "samples" / "reflected_star.png"))
            page.wait_for_function(
                "() => [...document.querySelectorAll('.dropzone .frame img')]"
                ".filter(i => i.naturalWidth > 0).length == 2"
            )
            page.locator("#advanced summary").click()
            page.fill("#resolution", str(args.resolution))
            page.fill("#image-size", str(args.image_size))
            if args.max_iters:
                page.fill("#max-iters", str(args.max_iters))
            page.locator("#advanced summary").click()
            page.fill("#title", "heart / star")
            t1 = time.monotonic()
            page.click("#start")
            page.wait_for_function(
                "() => ['done', 'failed', 'cancelled'].includes(document.querySelector('#run-status').textContent)",
                timeout=args.timeout * 1000, polling=500,
            )
            status = page.locator("#run-status").inner_text()
            print(f"design {status} after {time.monotonic() - t1:.1f} s")
            if status != "done":
                sys.exit(f"the design ended {status}: {page.locator('#run-error').inner_text()}")
            page.wait_for_function(
                "() => [...document.querySelectorAll('#results-gallery img')].every(i => i.naturalWidth > 0)"
            )
            page.locator("#viewer").scroll_into_view_if_needed()
            deadline = time.monotonic() + 120
            while not any(f.url.endswith("/viewer") and f.evaluate("() => window.saucerViewerReady === true")
                          for f in page.frames):
                if time.monotonic() > deadline:
                    sys.exit("the 3D viewer did not get ready in 120 s")
                page.wait_for_timeout(200)
            t2 = time.monotonic()
            page.select_option("#export-printer", "j55")
            page.check("#export-formats input[value='3mf']")
            page.click("#export-start")
            page.wait_for_selector("a[data-download='j55']", timeout=600_000)
            print(f"export (j55, 3MF) done after {time.monotonic() - t2:.1f} s")
            page.evaluate("() => { window.scrollTo(0, 0); document.querySelector('#design-form').scrollTop = 0; }")
            page.wait_for_timeout(500)  # let the viewer draw a few frames
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            # closing the event stream once the design is done aborts its request: not an error
            errors = [e for e in errors if "net::ERR_ABORTED" not in e]
            if errors:
                print("page errors:", *errors, sep="\n  ")
    finally:
        stop_studio(proc)
        tmp.cleanup()
    print(f"wrote {args.out} ({time.monotonic() - t0:.1f} s in all)")


if __name__ == "__main__":
    main()
