"""``verify --bleed`` (issue 45): the files' textures blurred as the printer prints them before the renders."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from verify_designs import painted_design

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.fabricate.pipeline import export_design
from saucerfab.model.profiles import load_profile
from saucerfab.verify.bleed import BLEED_OF_PRINTER, bleed_surface, bleed_width_mm
from saucerfab.verify.printfolder import PrintedSurface


@pytest.fixture(scope="module")
def a_print(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bleed") / "print"
    export_design(painted_design(0.0, resolution=20), out, printer="j55", formats=["obj"], cup_diameter_mm=80)
    return out


def test_the_width_is_the_printers_or_the_one_given(a_print: Path, tmp_path: Path) -> None:
    assert bleed_width_mm(a_print, None) is None
    assert bleed_width_mm(a_print, BLEED_OF_PRINTER) == load_profile("j55").colour_bleed_mm > 0
    assert bleed_width_mm(a_print, "0.25") == 0.25
    for bad in ("abc", "0", "-1", "5", "nan"):
        with pytest.raises(ConfigError, match="--bleed takes a width"):
            bleed_width_mm(a_print, bad)
    with pytest.raises(ConfigError, match="names no printer"):
        bleed_width_mm(tmp_path, BLEED_OF_PRINTER)


def _quad(step_at: int = 16, size: int = 32) -> PrintedSurface:
    """A 10 x 10 mm square of two triangles mapped to the page's left half (a step from black to white in it);
    the page's right half is another colour no chart holds. Each face corner has its own coordinate, as read."""
    v = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0], [0.0, 10.0, 0.0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]])
    page = np.zeros((size, size, 3), np.uint8)
    page[:, step_at // 2:size // 2] = 255
    page[:, size // 2:] = (0, 200, 0)
    return PrintedSurface(Path("quad.obj"), "obj", v, f, uv[f], np.zeros(2, np.int64), [page], np.ones(2, bool))


def test_bleeding_a_surface_blurs_within_its_chart_across_both_triangles() -> None:
    s = _quad()
    out = bleed_surface(s, sigma_mm=1.0).textures[0]
    row = out[5, :16, 0].astype(int)
    assert row[0] < 60 and row[15] > 200 and 60 < row[8] < 240  # the step (at texel 8) is smoothed ...
    assert (np.diff(row) >= 0).all()  # ... monotonically
    assert (out[:, 16:] == (0, 200, 0)).all()  # the page's texels in no chart are left as they are
    # the two triangles are one chart (their corners share coordinates): the blur is the same along the step,
    # on either side of the quad's diagonal
    assert np.abs(out[2, :16, 0].astype(int) - out[29, :16, 0].astype(int)).max() <= 2
    assert np.array_equal(bleed_surface(s, sigma_mm=1e-6).textures[0], s.textures[0])


def test_cli_bleed_renders_the_print_blurred_and_records_the_width(a_print: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    work = tmp_path / "print"
    shutil.copytree(a_print, work)
    args = ["verify", str(work), "--eyes", "design", "--res", "64", "--spp", "4", "--primary-only", "-q", "--json",
            "--min-psnr", "0", "--min-coverage", "0", "--max-stray", "1"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert "bleed_mm" not in plain  # the verify without it writes what it always did
    assert main([*args, "--bleed", "2", "-o", str(tmp_path / "b")]) == 0
    blurred = json.loads(capsys.readouterr().out)
    assert blurred["bleed_mm"] == 2.0
    psnr = {doc_name: {v["view"]: v["psnr_db"] for v in doc["files"][0]["views"]}
            for doc_name, doc in (("plain", plain), ("blurred", blurred))}
    assert psnr["blurred"]["direct"] < psnr["plain"]["direct"] - 1.0  # a 2 mm bleed costs the picture
    assert main(["verify", str(work), "--bleed", "x", "-o", str(tmp_path / "c")]) == 2
    assert "--bleed takes a width" in capsys.readouterr().err


def test_a_print_compensated_for_the_bleed_is_verified_as_it_prints(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # its pre-sharpened texture is only right blurred: read as written it would score its halos
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.verify.bleed import compensated_width

    folder = tmp_path / "print"
    export_design(painted_design(0.0, resolution=20), folder, printer="j55", formats=["obj"], cup_diameter_mm=80,
                  options=FabOptions(texture_px=512, bleed_compensation="on"))
    assert compensated_width(folder) == load_profile("j55").colour_bleed_mm
    args = ["verify", str(folder), "--eyes", "design", "--res", "48", "--spp", "4", "--primary-only",
            "--min-psnr", "0", "--min-coverage", "0", "--max-stray", "1"]
    assert main([*args, "--json", "-q", "-o", str(tmp_path / "a")]) == 0
    assert json.loads(capsys.readouterr().out)["bleed_mm"] == load_profile("j55").colour_bleed_mm
    assert main([*args, "-q", "-o", str(tmp_path / "b")]) == 0
    assert "(the texture was compensated for the printer's bleed)" in capsys.readouterr().out
    assert main([*args, "--bleed", "0.3", "--json", "-q", "-o", str(tmp_path / "c")]) == 0
    assert json.loads(capsys.readouterr().out)["bleed_mm"] == 0.3  # a width asked for wins
    doc = json.loads((folder / "export.json").read_text())
    doc["bleed"]["sigma_mm"] = "0.12; rm -rf /"  # a hand-edited record is not trusted
    (folder / "export.json").write_text(json.dumps(doc))
    assert compensated_width(folder) is None
