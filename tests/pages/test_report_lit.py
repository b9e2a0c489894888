"""The print's report shows what ``verify --light`` and ``--bleed`` add (issue 45): the lit views and the bleed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from saucerfab.pages.folder_pages import verify_section
from saucerfab.verify.results import SCHEMA


def _folder(tmp_path: Path, extra: dict) -> Path:
    ver = tmp_path / "print" / "verify"
    ver.mkdir(parents=True)
    Image.fromarray(np.full((8, 8, 3), 128, np.uint8)).save(ver / "design_direct_lit.png")
    doc = {"schema": SCHEMA, "files": [], "res": 64, "spp": 4, "min_psnr_db": 20, "min_coverage": 0.5,
           "passed": True, "renderer": {"version": "3", "variant": "scalar_rgb"}, **extra}
    (ver / "verify.json").write_text(json.dumps(doc))
    return tmp_path / "print"


def test_the_lit_views_and_the_bleed_are_in_the_verify_section(tmp_path: Path) -> None:
    lit = {"view": "direct", "eye": "design", "lit_psnr_db": 26.4, "shading_pattern_db": 23.1,
           "flat_pattern_db": 99.0, "picture": "design_direct_lit.png"}
    folder = _folder(tmp_path, {"bleed_mm": 0.12, "light": {"kind": "room", "cup_metal": {"name": "chromium"}},
                                "lit_views": [lit, {**lit, "view": "reflected", "picture": "../escape.png",
                                                                "flat_print_lit_psnr_db": 30.04}]})
    section = verify_section(folder)
    assert section is not None
    assert "a colour bleed of 0.12 mm" in section.text
    assert "Under the room light" in section.text and "the cup chromium" in section.text
    assert "direct view, design eye: 26.4 dB under the light, shading pattern 23.1 dB (a flat plate 99.0 dB)" in (
        section.text)  # a document written before the flat print's score: none said
    assert "reflected view, design eye: 26.4 dB under the light (a flat print of it 30.0 dB)" in section.text
    captions = [c for c, _ in section.images]
    assert sum("under the room light" in c for c in captions) == 1  # a picture outside verify/ is never read


def test_an_emitted_verify_section_says_nothing_of_light_or_bleed(tmp_path: Path) -> None:
    section = verify_section(_folder(tmp_path, {}))
    assert section is not None and "light" not in section.text.lower().replace("flat print", "")
    assert "bleed" not in section.text
