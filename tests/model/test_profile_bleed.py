"""A printer profile's colour bleed (``colour_bleed_mm``): read from each bundled profile, sourced, validated."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from saucerfab.errors import ConfigError
from saucerfab.model.profiles import MAX_COLOUR_BLEED_MM, list_profiles, load_profile

BUNDLED = Path(__file__).resolve().parents[2] / "printers"

MINIMAL = """name = "Test printer"
build_volume_mm = [200.0, 150.0, 100.0]
min_wall_mm = 1.0
min_feature_mm = 0.5
dpi = 300.0
max_texture_px = 4096
accepted_formats = ["obj"]
preferred_format = "obj"
"""


@pytest.fixture(autouse=True)
def _no_user_printers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SAUCERFAB_PRINTERS", raising=False)


def test_every_bundled_profile_states_its_bleed_with_a_source_comment() -> None:
    profiles = list_profiles()
    for path in sorted(BUNDLED.glob("*.toml")):
        text = path.read_text(encoding="utf-8")
        assert "\ncolour_bleed_mm = " in text, path.name
        comment = text[text.index("# colour_bleed_mm:"):text.index("\ncolour_bleed_mm = ")]
        assert "Zeng et al., UIST 2021" in comment and "estimate" in comment, path.name
        assert 0 < profiles[path.stem].colour_bleed_mm <= MAX_COLOUR_BLEED_MM
    assert load_profile("j55").colour_bleed_mm == pytest.approx(0.12)
    # the J55's width from its source: a 600 um dot keeps 95 % of its contrast at its centre
    assert 0.6 / math.sqrt(8 * math.log(20)) == pytest.approx(0.12, abs=0.005)


def test_a_profile_without_it_has_no_bleed(tmp_path: Path) -> None:
    path = tmp_path / "mini.toml"
    path.write_text(MINIMAL, encoding="utf-8")
    assert load_profile(path).colour_bleed_mm == 0.0
    (tmp_path / "zero.toml").write_text(MINIMAL + "colour_bleed_mm = 0\n", encoding="utf-8")
    assert load_profile(tmp_path / "zero.toml").colour_bleed_mm == 0.0
    (tmp_path / "fine.toml").write_text(MINIMAL + "colour_bleed_mm = 0.2\n", encoding="utf-8")
    assert load_profile(tmp_path / "fine.toml").colour_bleed_mm == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("-0.1", "colour_bleed_mm must be 0 \\(none known\\) or a finite size up to 2 mm"),
        ("nan", "colour_bleed_mm must be 0"),
        ("inf", "colour_bleed_mm must be 0"),
        ("120", "got 120.0"),  # micrometres typed as millimetres
        ('"wide"', "has a bad value"),
    ],
)
def test_a_bad_bleed_is_refused_naming_the_file_and_the_rule(tmp_path: Path, value: str, match: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(MINIMAL + f"colour_bleed_mm = {value}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=match) as exc:
        load_profile(path)
    assert str(path) in str(exc.value)
