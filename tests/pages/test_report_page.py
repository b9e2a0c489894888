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
from html import escape as html_escape
from pathlib import Path

import browser
import numpy as np
import pytest
from PIL import Image

from saucerfab.cli import main
from saucerfab.pages.labels import STAGE_LABELS, STOP_LABELS

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
ARTIFACTS = Path(__file__).resolve().parents[2] / "out" / "test-artifacts"


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
                  "where to stand", "In 3D", "A trial export of this design"):
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


def test_print_report_shows_the_whole_view_from_each_eye(folders):
    _, print_dir = folders
    ver = json.loads((print_dir / "verify" / "verify.json").read_text())
    wholes = ver["whole_views"]
    assert [w["eye"] for w in wholes] == ["design", "left", "right"]
    html = (print_dir / "report.html").read_text(encoding="utf-8")
    assert "The whole view (everything of the piece the eye sees" in html
    for w in wholes:  # each eye's figures as the report rounds them, and its picture
        assert (f"{w['eye']} eye {w['psnr_db']:.1f} dB, stray {100 * w['stray_direct']:.0f} % on the saucer and "
                f"{100 * w['stray_reflected']:.0f} % in the mirror") in html, w
        assert f"the whole view from the {w['eye']} eye: render | ideal | stray" in html
        assert (print_dir / "verify" / w["picture"]).is_file()


def test_design_report_says_the_method_and_stages_in_the_clis_words(folders):
    design, _ = folders
    html = (design / "report.html").read_text(encoding="utf-8")
    # the method as asked and as run (the CLI prints "method auto (the default): ..."), not the ablation's "full"
    assert "<th>method</th><td>auto (the default): 2 stages (the small-sigma stage skipped" in html, html[:3000]
    assert "at most 10 iterations a stage" in html
    assert "<td>full</td>" not in html and "<th>ablation</th>" not in html
    # the stage table in people's words: the label, the stop reason, the energies' names
    assert f"<td>{html_escape(STAGE_LABELS['bw_sigma_large'])}</td>" in html
    assert f"<td>{STOP_LABELS['max_iters']}</td>" in html and "<th>image error</th>" in html
    for key in ("<td>bw_sigma_large</td>", "<td>max_iters</td>", "<th>E_visual</th>"):
        assert key not in html, key
    assert "<title>saucerfab design: direct_heart.png / reflected_star.png</title>" in html


def test_print_report_is_titled_by_the_design_and_printer(folders):
    _, print_dir = folders  # the folder is called "print": the title must not be
    html = (print_dir / "report.html").read_text(encoding="utf-8")
    title = "saucerfab print: direct_heart.png / reflected_star.png for Stratasys J55 Prime"
    assert f"<title>{title}</title>" in html and f"<h1>{title}</h1>" in html


def _finding(severity: str, code: str, message: str) -> dict:
    return {"severity": severity, "code": code, "message": message, "where": None}


def _check_json(*files: tuple[str, str, list[dict]]) -> str:
    return json.dumps({"schema": "saucerfab.check/1", "files": [
        {"path": p, "verdict": v, "exit_code": 0 if v == "printable" else 1, "findings": f} for p, v, f in files]})


def _printability(html: str) -> str:
    """The printability section of a page."""
    part = html.split("<h2>Printability (saucerfab check)</h2>", 1)[1]
    return part.split("</section>", 1)[0]


def test_print_report_with_only_info_findings_says_printable_with_counts(folders, tmp_path):
    from saucerfab.pages.folder_pages import export_report

    _, print_dir = folders
    folder = tmp_path / "print"
    shutil.copytree(print_dir, folder)
    (folder / "check.json").write_text(_check_json(
        ("saucer.3mf", "printable", [_finding("info", "lib3mf_reads", "lib3mf reads the file in strict mode")]),
        ("saucer.obj", "printable", [_finding("info", "units", "OBJ states no units; read as millimetres")]),
    ))
    section = _printability(export_report(folder))
    assert ("Printable: every file passes (2 files checked: 0 errors, 0 warnings, 2 info findings)."
            in section), section
    # the info findings are rows, as the studio lists them
    assert section.count("<tr>") == 3, section
    assert "<td>saucer.obj</td><td>printable</td><td>info</td><td>OBJ states no units" in section, section


def test_print_report_with_an_error_says_not_printable(folders, tmp_path):
    from saucerfab.pages.folder_pages import export_report

    _, print_dir = folders
    folder = tmp_path / "print"
    shutil.copytree(print_dir, folder)
    (folder / "check.json").write_text(_check_json(
        ("saucer.3mf", "not printable", [_finding("error", "not_watertight", "12 open edges"),
                                         _finding("warning", "thin_wall", "a wall of 0.2 mm")]),
        ("saucer.obj", "printable", []),
    ))
    section = _printability(export_report(folder))
    assert "Not printable: 1 of 2 files fail (2 files checked: 1 error, 1 warning, 0 info findings)." in section
    assert "<td>not_printable</td>" not in section and "12 open edges (not_watertight)" in section
    assert "<td>saucer.obj</td><td>printable</td><td>-</td><td>no findings</td>" in section, section
    (folder / "check.json").write_text(json.dumps({"schema": "saucerfab.check/1", "files": []}))
    assert "Not checked" in _printability(export_report(folder))


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
    from saucerfab.pages import folder_pages as report_page

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
