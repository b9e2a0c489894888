"""Tests of saucerfab.model.profiles: the bundled printers, a profile file's rules, $SAUCERFAB_PRINTERS.

How an export and the checker apply a profile is tested with them
(``tests/fabricate/``, ``tests/check/``); here what a profile file may say,
how a bad one is refused, where profiles are found, and the profile's own
two answers (does a part fit, how fine a texture).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import pytest

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.files.formats import FORMATS
from saucerfab.model.profiles import (
    DEFAULT_PRINTER,
    MAX_PROFILE_BYTES,
    THIN_POLICIES,
    PrinterProfile,
    list_profiles,
    load_profile,
)

ROOT = Path(__file__).resolve().parents[2]
BUNDLED = ROOT / "printers"
PACKAGED = ROOT / "saucerfab" / "data" / "printers"

#: the least a profile must say
MINIMAL: dict[str, Any] = {
    "name": "Test printer",
    "build_volume_mm": [200.0, 150.0, 100.0],
    "min_wall_mm": 1.0,
    "min_feature_mm": 0.5,
    "dpi": 300.0,
    "max_texture_px": 4096,
    "accepted_formats": ["OBJ", "3mf"],
    "preferred_format": "obj",
}


def toml_value(v: Any) -> str:
    """``v`` as a TOML value (strings, numbers with nan/inf, booleans, flat arrays)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return repr(v)


def write_profile(folder: Path, key: str = "test", drop: tuple[str, ...] = (), **changes: Any) -> Path:
    """A profile file ``<key>.toml``: :data:`MINIMAL` less ``drop``, with ``changes``."""
    d = {k: v for k, v in {**MINIMAL, **changes}.items() if k not in drop}
    path = folder / f"{key}.toml"
    path.write_text("".join(f"{k} = {toml_value(v)}\n" for k, v in d.items()), encoding="utf-8")
    return path


@pytest.fixture(autouse=True)
def _no_user_printers(monkeypatch: pytest.MonkeyPatch) -> None:
    """The tests see the bundled profiles only, whatever the machine's environment says."""
    monkeypatch.delenv("SAUCERFAB_PRINTERS", raising=False)


def test_every_bundled_profile_loads_and_validates() -> None:
    files = sorted(BUNDLED.glob("*.toml"))
    profiles = list_profiles()
    assert len(files) >= 5 and sorted(p.stem for p in files) == sorted(profiles)
    assert DEFAULT_PRINTER in profiles
    for path in files:
        prof = load_profile(path)
        assert prof == profiles[path.stem] == load_profile(path.stem) and prof.key == path.stem
        assert prof.name and set(prof.accepted_formats) <= set(FORMATS)
        assert prof.preferred_format in prof.accepted_formats and prof.thin_policy in THIN_POLICIES
        # an export's atlas is a power of two (FabOptions refuses others): the cap must be one too
        assert prof.max_texture_px & (prof.max_texture_px - 1) == 0
        for size_mm in (10.0, 80.0, 400.0):
            px = prof.texture_px_for(size_mm)
            assert px & (px - 1) == 0 and 256 <= px <= prof.max_texture_px


def test_the_packaged_copy_is_the_bundled_one() -> None:
    """``printers/`` (a checkout) and ``saucerfab/data/printers`` (the wheel) must not drift apart."""
    assert sorted(p.name for p in PACKAGED.glob("*.toml")) == sorted(p.name for p in BUNDLED.glob("*.toml"))
    for path in BUNDLED.glob("*.toml"):
        assert (PACKAGED / path.name).read_bytes() == path.read_bytes(), path.name


def test_a_minimal_profile_takes_the_defaults(tmp_path: Path) -> None:
    path = write_profile(tmp_path, "mini")
    assert load_profile(path) == PrinterProfile(
        key="mini", name="Test printer", build_volume_mm=(200.0, 150.0, 100.0), min_wall_mm=1.0,
        min_feature_mm=0.5, dpi=300.0, max_texture_px=4096, accepted_formats=("obj", "3mf"),
        preferred_format="obj", max_triangles=0, max_file_mb=0.0, thin_policy="warn", notes="",
    )


@pytest.mark.parametrize(
    "drop, changes, match",
    [
        (("dpi",), {}, r"lacks \['dpi'\]"),
        (("name", "dpi"), {}, r"lacks \['dpi', 'name'\]"),
        ((), {"colour": True}, r"has unknown key\(s\) \['colour'\]"),
        ((), {"accepted_formats": ["obj", "fbx"]}, r"accepted_formats must come from 3mf, .* \(unknown: fbx\)"),
        ((), {"preferred_format": "ply"}, r"preferred_format 'ply' must be one of accepted_formats \(obj, 3mf\)"),
        ((), {"thin_policy": "ignore"}, r"thin_policy must be warn\|refuse, got 'ignore'"),
        ((), {"max_texture_px": 128}, "max_texture_px must be a whole number >= 256, got 128"),
        ((), {"build_volume_mm": [200.0, 150.0]}, "build_volume_mm must be 3 finite positive sizes"),
        ((), {"build_volume_mm": [200.0, 0.0, 100.0]}, "build_volume_mm must be 3 finite positive sizes"),
        ((), {"min_wall_mm": 0.0}, "min_wall_mm must be finite and positive, got 0.0"),
        ((), {"dpi": "fine"}, "has a bad value"),
    ],
)
def test_a_bad_profile_is_a_config_error_naming_the_file_and_the_rule(
    tmp_path: Path, drop: tuple[str, ...], changes: dict[str, Any], match: str
) -> None:
    path = write_profile(tmp_path, "bad", drop, **changes)
    with pytest.raises(ConfigError) as exc:
        load_profile(path)
    msg = str(exc.value)
    assert str(path) in msg
    assert re.search(match, msg.replace(str(path), "<path>")), msg  # not matched by the test's folder name


def test_a_preferred_format_not_accepted_is_named(tmp_path: Path) -> None:
    path = write_profile(tmp_path, "pref", preferred_format="ply")
    with pytest.raises(ConfigError) as exc:
        load_profile(path)
    msg = str(exc.value).replace(str(path), "<path>")  # the test's folder name holds the words too
    assert re.search(r"preferred_format\b.{0,40}'ply'|'ply'.{0,40}\bpreferred_format", msg), msg


@pytest.mark.parametrize(
    "changes",
    [
        {"min_wall_mm": math.nan},
        {"dpi": math.inf},
        {"build_volume_mm": [200.0, math.inf, 100.0]},
        {"max_triangles": -5},
        {"max_file_mb": -1.0},
    ],
)
def test_a_number_that_is_not_a_size_is_refused(tmp_path: Path, changes: dict[str, Any]) -> None:
    with pytest.raises(ConfigError):
        load_profile(write_profile(tmp_path, "odd", **changes))


def test_bad_files_are_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="printer profile file .*missing.toml' not found"):
        load_profile(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text('name = "x\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="is not valid TOML"):
        load_profile(broken)
    big = write_profile(tmp_path, "big", notes="x" * MAX_PROFILE_BYTES)
    with pytest.raises(ConfigError, match="is over 100 kB; a profile is a few lines"):
        load_profile(big)


def test_an_unknown_printer_names_the_known_ones_and_the_fix() -> None:
    with pytest.raises(ConfigError) as exc:
        load_profile("no-such-printer")
    msg = str(exc.value)
    assert msg.startswith("unknown printer 'no-such-printer'; known: [")
    assert repr(DEFAULT_PRINTER) in msg and "'saucerfab printers'" in msg and "path to your own .toml" in msg


def test_saucerfab_printers_adds_profiles_and_wins_over_the_bundled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    write_profile(tmp_path, "mine", name="My own")
    write_profile(tmp_path, DEFAULT_PRINTER, name="My J55")  # same key as a bundled one: the user's folder comes first
    monkeypatch.setenv("SAUCERFAB_PRINTERS", str(tmp_path))
    profiles = list_profiles()
    assert profiles["mine"].name == "My own" and load_profile("mine") == profiles["mine"]
    assert load_profile(DEFAULT_PRINTER).name == "My J55"
    assert set(profiles) >= {p.stem for p in BUNDLED.glob("*.toml")}  # the bundled ones are still there
    assert main(["printers", "-q"]) == 0
    assert "mine" in capsys.readouterr().out.split()


def test_fits_turns_the_part_about_z_only() -> None:
    prof = PrinterProfile("t", "T", (300.0, 200.0, 100.0), 1.0, 0.5, 300.0, 4096, ("obj",), "obj")
    assert prof.fits((300.0, 200.0, 100.0)) and prof.fits((150.0, 280.0, 100.0))  # turned a quarter
    assert not prof.fits((301.0, 10.0, 10.0)) and not prof.fits((210.0, 210.0, 10.0))
    assert not prof.fits((10.0, 10.0, 101.0)) and not prof.fits((100.0, 10.0, 150.0))  # z stays up


@pytest.mark.parametrize(
    "size_mm, px",
    [(0.0, 256), (100.0, 256), (256.0, 256), (257.0, 512), (512.0, 512), (1000.0, 1024), (3000.0, 2048)],
)
def test_texture_px_for_is_the_power_of_two_at_the_dpi_capped(size_mm: float, px: int) -> None:
    # 25.4 dpi: one pixel per millimetre, so the wanted edge is the size in mm
    prof = PrinterProfile("t", "T", (300.0, 200.0, 100.0), 1.0, 0.5, 25.4, 2048, ("obj",), "obj")
    assert prof.texture_px_for(size_mm) == px
