"""Regenerate ``docs/round_3d.png``: the round saucer's 3D view from its print report (for the README).

    .venv/bin/python benchmarks/viewer_screenshot.py [--out docs/round_3d.png]
        [--design DIR | --print DIR] [--workdir DIR] [--printer j55]
        [--resolution N] [--image-size PX] [--max-iters N] [--timeout 300]

By default designs the bundled pair on the round saucer (``saucerfab design
--direct samples/direct_heart.png --reflected samples/reflected_star.png
--scene round``, the design's own options unless ``--resolution``,
``--image-size`` or ``--max-iters`` are given), exports it (``saucerfab export
DESIGN --printer j55 --formats 3mf,glb``), opens the export's ``report.html``
(its "In 3D" section holds the three.js view, :mod:`saucerfab.pages.viewer`)
in Debian's headless Chromium through Playwright (``tests/browser.py``) at
1200 x 900, waits for ``window.saucerViewerReady`` and saves a screenshot of
the view's canvas (``#saucer-3d-stage``) to ``--out``, re-saved with Pillow
(optimised; cut to 256 colours only if still over ``--max-kb``).

``--design DIR`` exports an existing design folder instead of designing;
``--print DIR`` opens an existing export folder (no design, no export).
Design and export go to ``--workdir`` (``design/``, ``print/``; kept), else
to a temporary folder that is removed at the end. Prints how long each step
took.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import browser  # tests/browser.py: Debian's Chromium through Playwright (after the path above)

#: the samples the README's pictures show: a heart on the saucer, a star in the cup
DIRECT = ROOT / "samples" / "direct_heart.png"
REFLECTED = ROOT / "samples" / "reflected_star.png"
#: the element of the report that holds the 3D view's canvas (viewer_html's default id + "-stage");
#: the outer "#saucer-3d" also holds the caption line under it
STAGE = "#saucer-3d-stage"
#: browser window, CSS px (device scale 1): the report's body is 72em wide at most, so the view is ~1136 px
VIEWPORT = (1200, 900)
#: polled until truthy: the viewer drew its first frame, or it failed (it sets saucerViewerError then)
SETTLED_JS = "() => window.saucerViewerReady === true || typeof window.saucerViewerError === 'string'"


def _saucerfab(args: list[str]) -> float:
    """Run ``python -m saucerfab ARGS`` in the repository; its output passes through. Returns seconds taken.

    Raises:
        SystemExit: the command failed (its own message is above).
    """
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "saucerfab", *args], cwd=ROOT, check=False)
    if done.returncode != 0:
        sys.exit(f"'saucerfab {' '.join(args)}' failed (exit {done.returncode}); its message is above")
    return time.monotonic() - t0


def design_round(folder: Path, *, resolution: int | None, image_size: int | None, max_iters: int | None) -> None:
    """Design heart (saucer) / star (cup) on the round saucer into ``folder`` (replaced if it holds a design).

    ``None`` options are left to the design's own defaults (the round scene's).
    """
    args = ["design", "--direct", str(DIRECT), "--reflected", str(REFLECTED), "--scene", "round",
            "-o", str(folder), "--force"]
    for flag, value in (("--resolution", resolution), ("--image-size", image_size), ("--max-iters", max_iters)):
        if value is not None:
            args += [flag, str(value)]
    print(f"design: {' '.join(args[1:])}", flush=True)
    print(f"design done after {_saucerfab(args):.1f} s", flush=True)


def export_print(design: Path, folder: Path, printer: str) -> None:
    """Export ``design`` for ``printer`` into ``folder`` (replaced if it holds an export).

    The printer's 3MF and a GLB: the report's 3D view reads back the first
    mesh it finds (OBJ, zip, 3MF, GLB in that order), here the 3MF; the GLB
    is there for anyone who wants to drop the part into another viewer.
    """
    args = ["export", str(design), "--printer", printer, "--formats", "3mf,glb", "--out", str(folder), "--force"]
    print(f"export: {' '.join(args[1:])}", flush=True)
    print(f"export done after {_saucerfab(args):.1f} s", flush=True)


def screenshot_view(print_dir: Path, *, timeout_s: float) -> bytes:
    """PNG bytes of the 3D view in ``print_dir/report.html`` once its first frame is drawn.

    Raises:
        SystemExit: no report, no 3D view in it, the viewer failed (its
            ``window.saucerViewerError``), it was not ready in ``timeout_s``,
            or it drew a blank canvas.
    """
    report = print_dir / "report.html"
    if not report.is_file():
        sys.exit(f"{report} does not exist: give --print an export folder (from 'saucerfab export')")
    if 'id="saucer-3d"' not in report.read_text(encoding="utf-8", errors="replace"):
        sys.exit(f"{report} has no 3D view: the export folder holds no OBJ, 3MF or GLB; export it again")
    t0 = time.monotonic()
    with browser.live_page(VIEWPORT) as (page, errors):
        # imported here: live_page has checked that Playwright is installed
        from playwright.sync_api import TimeoutError as PlaywrightTimeout

        page.goto(report.resolve().as_uri(), wait_until="load", timeout=60_000)
        try:
            page.wait_for_function(SETTLED_JS, timeout=timeout_s * 1000, polling=200)
        except PlaywrightTimeout:  # why it timed out is in the page's errors, if anywhere
            sys.exit(f"the 3D view of {report} was not ready after {timeout_s:g} s (raise --timeout); "
                     f"page errors: {errors or 'none'}")
        failed = page.evaluate("() => window.saucerViewerError || null")
        if failed:
            sys.exit(f"the 3D view of {report} failed: {failed}")
        timings = page.evaluate("() => window.saucerViewerTimings || {}")
        page.wait_for_timeout(300)  # a few more frames (the ready flag is set on the frame after the first)
        png = page.locator(STAGE).first.screenshot()
    print(f"3D view ready after {time.monotonic() - t0:.1f} s (viewer timings, ms: {timings})", flush=True)
    if errors:
        print("page errors:", *errors, sep="\n  ")
    if not browser.canvas_is_drawn(png):
        sys.exit(f"the 3D view of {report} is blank (one colour); look at it in a browser")
    return png


#: pixels kept around the piece when the view's empty sides are cut away
CROP_MARGIN_PX = 24


def crop_to_piece(image: Image.Image) -> Image.Image:
    """``image`` cut to the columns where something differs from the backdrop, plus a margin.

    The backdrop is the colour a little inside the left edge's middle (the canvas's corners are rounded).

    The view's canvas is wider than the piece; the README shows the piece.
    """
    a = np.asarray(image, np.int16)
    inner = a[8:-8]  # rows clear of the rounded corners
    differs = (np.abs(inner - a[a.shape[0] // 2, 8]).max(axis=2) > 8).any(axis=0)
    differs[:8] = differs[-8:] = False  # the canvas's own edge
    cols = np.flatnonzero(differs)
    if cols.size == 0:
        return image
    x0, x1 = max(0, int(cols[0]) - CROP_MARGIN_PX), min(image.width, int(cols[-1]) + 1 + CROP_MARGIN_PX)
    return image.crop((x0, 0, x1, image.height))


def save_small(png: bytes, out: Path, max_kb: float) -> tuple[int, int, int]:
    """Save ``png`` to ``out`` optimised; cut to 256 colours if still over ``max_kb`` KB.

    Returns:
        width and height in pixels, the file's size in bytes.
    """
    image = crop_to_piece(Image.open(io.BytesIO(png)).convert("RGB"))
    out.parent.mkdir(parents=True, exist_ok=True)
    image.save(out, optimize=True)
    if out.stat().st_size > max_kb * 1024:
        # a rendered view has smooth shading: an adaptive palette keeps it, at a third of the bytes
        image.quantize(256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    return image.width, image.height, out.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--design", type=Path, default=None, help="an existing design folder: export it, do not design")
    src.add_argument("--print", dest="print_dir", type=Path, default=None,
                     help="an existing export folder: open its report, do not design or export")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "round_3d.png")
    ap.add_argument("--workdir", type=Path, default=None,
                    help="where design/ and print/ go (kept); default: a temporary folder, removed")
    ap.add_argument("--printer", default="j55", help="printer of the export (a 'saucerfab printers' key)")
    ap.add_argument("--resolution", type=int, default=None, help="design option; default: the round scene's")
    ap.add_argument("--image-size", type=int, default=None, help="design option; default: the round scene's")
    ap.add_argument("--max-iters", type=int, default=None, help="design option; default: the design's own")
    ap.add_argument("--timeout", type=float, default=300, help="longest wait for the 3D view, s")
    ap.add_argument("--max-kb", type=float, default=400, help="PNG size above which it is cut to 256 colours")
    args = ap.parse_args()

    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="viewer-shot-") as tmp:
        work = args.workdir or Path(tmp)
        print_dir = args.print_dir
        if print_dir is None:
            design = args.design
            if design is None:
                design = work / "design"
                design_round(design, resolution=args.resolution, image_size=args.image_size,
                             max_iters=args.max_iters)
            elif not design.is_dir():
                sys.exit(f"{design} is not a folder: give --design a design folder (from 'saucerfab design')")
            print_dir = work / "print"
            export_print(design, print_dir, args.printer)
        png = screenshot_view(print_dir, timeout_s=args.timeout)
    width, height, size = save_small(png, args.out, args.max_kb)
    print(f"wrote {args.out} ({width} x {height} px, {size / 1024:.0f} KB; {time.monotonic() - t0:.1f} s in all)")


if __name__ == "__main__":
    main()
