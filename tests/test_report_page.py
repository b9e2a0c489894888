"""report.html of design and print folders: contents, self-containment, and a real browser.

The pages are opened in Debian's headless Chromium (``tests/browser.py``);
the test asserts the 3D view drew something and the console stayed clean,
and keeps the screenshots in ``out/test-artifacts/`` to be looked at.
"""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import browser
from saucerfab.cli import main

SAMPLES = Path(__file__).resolve().parents[1] / "samples"
ARTIFACTS = Path(__file__).resolve().parents[1] / "out" / "test-artifacts"


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("report")
    design, print_dir = root / "design", root / "print"
    assert main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected",
                 str(SAMPLES / "reflected_star.png"), "--resolution", "20", "--image-size", "64",
                 "--max-iters", "10", "--frames", "contain", "--out", str(design), "--quiet"]) == 0
    assert main(["export", str(design), "--printer", "j55", "--cup-diameter-mm", "80",
                 "--formats", "3mf,obj", "--out", str(print_dir), "-q"]) == 0
    return design, print_dir


def _no_network(html: str) -> None:
    # nothing is fetched at view time: no http(s) URL is loaded by a tag or an import
    assert not re.search(r"""(src|href)\s*=\s*["']https?:""", html)
    assert not re.search(r"""(import|from)\s*\(?\s*["']https?:""", html)


def test_design_folder_has_a_self_contained_report(folders):
    design, _ = folders
    html = (design / "report.html").read_text(encoding="utf-8")
    _no_network(html)
    for words in ("Inputs, masks and enhanced targets", "Energies and stages", "Height change",
                  "where to stand", "In 3D", "bw_sigma_large", "A trial export of this design"):
        assert words in html, words
    assert html.count("data:image/png;base64,") >= 14  # previews, references and the six verify pictures
    ver = json.loads((design / "verify" / "verify.json").read_text())
    assert ver["printer"] == "j55" and len(ver["files"][0]["views"]) == 6


def test_export_writes_checks_verify_and_report(folders, capsys):
    _, print_dir = folders
    for name in ("check.json", "report.html", "verify/verify.json", "verify/design_direct.png",
                 "verify/left_reflected.png", "reference_direct.png", "reference_reflected.png"):
        assert (print_dir / name).is_file(), name
    ver = json.loads((print_dir / "verify" / "verify.json").read_text())
    assert ver["folder"] == "." and ver["files"][0]["path"] == "saucer.obj"
    assert {(v["view"], v["eye"]) for v in ver["files"][0]["views"]} == {
        (v, e) for v in ("direct", "reflected") for e in ("design", "left", "right")}
    html = (print_dir / "report.html").read_text(encoding="utf-8")
    _no_network(html)
    for words in ("Verified: what the print shows", "Printability (saucerfab check)", "saucer.3mf",
                  "whole-picture shift", "flat print", "where to stand"):
        assert words in html, words


def test_export_prints_the_quick_verify_and_no_verify_skips_it(folders, tmp_path, capsys):
    design, _ = folders
    out = tmp_path / "p"
    assert main(["export", str(design), "--formats", "obj", "--out", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    assert re.search(r"direct +from the design eye +\d+\.\d dB", text), text
    assert re.search(r"direct +from the left +eye +\d+\.\d dB.*\(against the flat print\)", text), text
    assert "stand    eye 550 mm from the cup's axis" in text
    out2 = tmp_path / "q"
    assert main(["export", str(design), "--formats", "obj", "--out", str(out2), "-q", "--no-verify"]) == 0
    assert "verify" not in capsys.readouterr().out.split("files")[0]
    assert not (out2 / "verify").exists() and (out2 / "report.html").is_file()


@pytest.mark.parametrize("which", ["design", "print"])
def test_report_opens_in_chromium_with_a_drawn_3d_view(folders, which):
    design, print_dir = folders
    page = (design if which == "design" else print_dir) / "report.html"
    if not browser.chromium_path().is_file():
        pytest.fail(f"Chromium is missing; {browser.INSTALL_HINT}")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    # a copy beside the artefacts, so the screenshot and the page it shows stay together
    shutil.copy(page, ARTIFACTS / f"report_{which}.html")
    result = browser.open_page(ARTIFACTS / f"report_{which}.html", ARTIFACTS / f"report_{which}.png",
                               viewport=(1200, 900), timeout_s=90)
    assert result.ready, result.errors
    assert not result.errors, result.errors
    assert browser.canvas_is_drawn(result.element_png("canvas"))
    (ARTIFACTS / f"report_{which}_3d.png").write_bytes(result.element_png("canvas"))


def test_png_reuses_an_encoding_only_for_the_same_pixels() -> None:
    from saucerfab import report_page

    rgb = np.random.default_rng(3).integers(0, 256, (40, 40, 3), dtype=np.uint8)
    first = report_page._png(rgb, 32)
    again = report_page._png(rgb.copy(), 32)
    assert again is first  # the cached bytes, by content
    changed = rgb.copy()
    changed[5, 7, 1] ^= 1
    assert report_page._png(changed, 32) != first
    assert report_page._png(rgb, None) != first  # another size is another picture
    with Image.open(io.BytesIO(first)) as im:
        assert im.size == (32, 32)
    for k in range(report_page._PNG_CACHE_ENTRIES + 2):  # bounded
        report_page._png(np.full((4, 4, 3), k, np.uint8))
    assert len(report_page._PNG_CACHE) == report_page._PNG_CACHE_ENTRIES
