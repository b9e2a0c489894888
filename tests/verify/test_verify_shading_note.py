"""``verify`` in emitted light says when a print's colours are compensated for a light's shading (issue 45)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from verify_designs import painted_design

from saucerfab.cli import main
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import export_design
from saucerfab.verify.printfolder import shading_note

ROOM_NOTE = ("this print's colours are compensated for the room light's shading (export --shading-compensation room); "
             "verify it with --light room to score it as it will be seen")


@pytest.mark.parametrize(("options", "note"), [
    ({"shading_compensation": "room"}, ROOM_NOTE),
    ({"shading_compensation": "ambient"}, ROOM_NOTE.replace("room light's", "ambient light's")
     .replace("compensation room", "compensation ambient")),
    ({"shading_compensation": "off"}, None),
    ({}, None),
    ({"shading_compensation": "room; rm -rf /"}, None),  # a hand-edited record is not repeated
    ({"shading_compensation": ["room"]}, None),
])
def test_the_note_follows_export_json(tmp_path: Path, options: dict[str, object], note: str | None) -> None:
    (tmp_path / "export.json").write_text(json.dumps({"options": options}))
    assert shading_note(tmp_path) == note
    assert shading_note(tmp_path / "missing") is None


def test_verify_prints_it_in_emitted_light_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "print"
    export_design(painted_design(0.0, resolution=20), folder, printer="j55", formats=["obj"], cup_diameter_mm=80,
                  options=FabOptions(texture_px=256, shading_compensation="room"))
    args = ["verify", str(folder), "--eyes", "design", "--res", "48", "--spp", "4", "--primary-only", "-q",
            "--min-psnr", "0", "--min-coverage", "0", "--max-stray", "1"]
    assert main([*args, "-o", str(tmp_path / "emitted")]) == 0
    assert f"  {ROOM_NOTE}\n" in capsys.readouterr().out
    assert main([*args, "--light", "room", "-o", str(tmp_path / "room")]) == 0
    assert "compensated for the room light's shading" not in capsys.readouterr().out
    assert main([*args, "--json", "-o", str(tmp_path / "json")]) == 0
    assert "shading" not in capsys.readouterr().out  # the JSON document is as it was
