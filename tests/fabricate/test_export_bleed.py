"""The export's colour-bleed compensation (``--bleed-compensation``): off as before, on recorded and different."""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import ExportResult, export_design
from saucerfab.model.design import Design
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.model.profiles import PrinterProfile

ATLAS = 256

#: a small printer that bleeds: 0.3 mm on a ~100 mm part at 256 px is about 0.7 texels
BLEEDS = PrinterProfile(
    key="bleeds", name="bleeding printer", build_volume_mm=(300.0, 300.0, 200.0), min_wall_mm=1.0,
    min_feature_mm=0.3, dpi=300, max_texture_px=8192, accepted_formats=("3mf", "obj"), preferred_format="3mf",
    colour_bleed_mm=0.3,
)


@pytest.fixture(scope="module")
def design() -> Design:
    return synthetic_design(resolution=24, texture_size=64, seed=2)


def export(design: Design, out: Path, printer: PrinterProfile = BLEEDS, **options: object) -> ExportResult:
    return export_design(design, out, printer=printer, formats=["3mf", "obj"],
                         options=FabOptions(texture_px=ATLAS, **options))  # type: ignore[arg-type]


def files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def page_of(folder: Path) -> np.ndarray:
    with zipfile.ZipFile(folder / "saucer.3mf") as z:
        name = next(n for n in z.namelist() if n.endswith(".png"))
        return np.asarray(Image.open(io.BytesIO(z.read(name))).convert("RGB"))


def test_off_is_the_export_as_before_and_on_is_another_page_recorded(design: Design, tmp_path: Path) -> None:
    default = export(design, tmp_path / "default")
    off = export(design, tmp_path / "off", bleed_compensation="off")
    on = export(design, tmp_path / "on", bleed_compensation="on")
    assert files(default.out) == files(off.out)  # byte for byte
    summary_off = json.loads(off.summary_json.read_text())
    assert "bleed" not in summary_off and "bleed_compensation" not in summary_off["options"]  # as before the option
    assert "bleed" not in off.timings
    summary = json.loads(on.summary_json.read_text())
    assert summary["options"]["bleed_compensation"] == "on"
    assert summary["bleed"]["sigma_mm"] == BLEEDS.colour_bleed_mm
    assert summary["bleed"]["sigma_px"] == pytest.approx(summary["bleed"]["sigma_mm"] * summary["bleed"]["px_per_mm"],
                                                         rel=1e-4)
    assert summary["warnings"] == summary_off["warnings"]
    a, b = page_of(off.out), page_of(on.out)
    assert a.shape == b.shape and not np.array_equal(a, b)
    # only the top and its gutter change: the chart column (walls, base) keeps its colours
    assert np.array_equal(a[:, -ATLAS // 8 + 4:], b[:, -ATLAS // 8 + 4:])
    assert on.vertices == off.vertices and (on.out / "saucer.obj").read_bytes() == (off.out / "saucer.obj").read_bytes()


def test_on_for_a_printer_without_a_bleed_changes_nothing_and_says_so(design: Design, tmp_path: Path) -> None:
    plain = replace(BLEEDS, colour_bleed_mm=0.0)
    off = export(design, tmp_path / "off", printer=plain)
    on = export(design, tmp_path / "on", printer=plain, bleed_compensation="on")
    assert np.array_equal(page_of(off.out), page_of(on.out))
    assert any("states no colour_bleed_mm" in w for w in on.warnings)


def test_a_bad_setting_is_refused() -> None:
    with pytest.raises(ConfigError, match="bleed_compensation must be 'on' or 'off', got 'yes'"):
        FabOptions(bleed_compensation="yes")  # type: ignore[arg-type]


def test_the_cli_flag(design: Design, tmp_path: Path) -> None:
    folder = tmp_path / "design"
    save_design(design, folder)
    printer = tmp_path / "bleeds.toml"
    printer.write_text(
        'name = "bleeding printer"\nbuild_volume_mm = [300.0, 300.0, 200.0]\nmin_wall_mm = 1.0\n'
        'min_feature_mm = 0.3\ndpi = 300\nmax_texture_px = 8192\naccepted_formats = ["3mf"]\n'
        'preferred_format = "3mf"\ncolour_bleed_mm = 0.3\n', encoding="utf-8")
    out = tmp_path / "print"
    code = main(["export", str(folder), "-o", str(out), "--printer", str(printer), "--texture-px", str(ATLAS),
                 "--bleed-compensation", "on", "--no-check", "--no-verify", "-q"])
    assert code == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["options"]["bleed_compensation"] == "on" and summary["bleed"]["sigma_mm"] == 0.3
    with pytest.raises(SystemExit):
        main(["export", str(folder), "-o", str(tmp_path / "x"), "--bleed-compensation", "maybe"])
