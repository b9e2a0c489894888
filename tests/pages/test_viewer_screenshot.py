"""``benchmarks/viewer_screenshot.py`` (the README's round 3D view) on a tiny round print.

A synthetic round design (no optimization, 24 x 24 heightfield) is exported
as a GLB with a small atlas and its print report written; the script is run
with ``--print`` on it (no design, no export) in Debian's headless Chromium
(``tests/browser.py``; a missing browser fails, see ``conftest.chromium``).
It must save a drawn, small PNG of the view's canvas, and refuse a folder
without a report or without a 3D view with a message that says what to do.
"""

from __future__ import annotations

import importlib.util
import io
import sys
from pathlib import Path
from types import ModuleType

import browser
import pytest
from PIL import Image

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import export_design
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.scene import round_scene
from saucerfab.pages.folder_pages import refresh_export_report

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "viewer_screenshot.py"


def _script() -> ModuleType:
    """The benchmark script as a module (benchmarks/ is not a package)."""
    spec = importlib.util.spec_from_file_location("viewer_screenshot", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def round_print(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny round export folder with its report.html (GLB only, 256 px atlas)."""
    out = tmp_path_factory.mktemp("round-shot") / "print"
    export_design(synthetic_design(round_scene(), resolution=24), out, printer="j55", formats=["glb"],
                  options=FabOptions(texture_px=256))
    refresh_export_report(out)
    return out


def _run(monkeypatch: pytest.MonkeyPatch, *args: str) -> None:
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), *args])
    _script().main()


def test_the_script_saves_the_round_parts_3d_view(
    round_print: Path, chromium: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "docs" / "round_3d.png"
    _run(monkeypatch, "--print", str(round_print), "--out", str(out), "--timeout", "60")
    png = out.read_bytes()
    image = Image.open(io.BytesIO(png))
    # the canvas's stage (480 px high: viewer_html's default), its empty sides cut away: the piece
    # (a disc seen from about 42 degrees up, a cup on it) is wider than high, narrower than the stage
    assert 470 <= image.height <= 490 and image.height < image.width < 1000, image.size
    assert browser.canvas_is_drawn(png)
    assert len(png) < 400 * 1024


def test_a_folder_without_a_report_or_a_3d_view_is_refused_with_what_to_do(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(SystemExit, match="report.html does not exist: give --print an export folder"):
        _run(monkeypatch, "--print", str(tmp_path), "--out", str(tmp_path / "x.png"))
    (tmp_path / "report.html").write_text("<html><body>no viewer here</body></html>", encoding="utf-8")
    with pytest.raises(SystemExit, match="has no 3D view: the export folder holds no OBJ, 3MF or GLB"):
        _run(monkeypatch, "--print", str(tmp_path), "--out", str(tmp_path / "x.png"))
    assert not (tmp_path / "x.png").exists()
