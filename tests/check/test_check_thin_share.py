"""Walls under a printer's minimum over more than a share of the surface are not printable (issue 42, item 3).

The share is ``Limits.thin_wall_error_fraction`` (0.5 %); it holds for every
printer profile, whatever its ``thin_policy``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import trimesh

from saucerfab.check import Limits, check_mesh
from saucerfab.check.limits import DEFAULT_LIMITS
from saucerfab.cli import main


def plate(tmp_path: Path, thickness_mm: float) -> Path:
    """A 40 x 40 mm plate ``thickness_mm`` thick, as STL."""
    p = tmp_path / f"plate_{thickness_mm:g}.stl"
    trimesh.creation.box(extents=(40.0, 40.0, thickness_mm)).export(p)
    return p


def thin_findings(doc: dict) -> list[dict]:
    return [f for f in doc["files"][0]["findings"] if f["code"] == "thin_walls"]


def test_a_plate_under_the_j55_minimum_is_not_printable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the J55's minimum wall is 1 mm and its thin_policy "warn": 0.3 mm over nearly all the surface
    thin = str(plate(tmp_path, 0.3))
    assert main(["check", thin, "--printer", "j55", "--json"]) == 1
    (f,) = thin_findings(json.loads(capsys.readouterr().out))
    assert f["severity"] == "error"
    share = f"{100 * DEFAULT_LIMITS.thin_wall_error_fraction:g}%"
    assert "walls under 1 mm (Stratasys J55 Prime's minimum)" in f["message"]
    assert f"more than the {share}" in f["message"] and "not printable" in f["message"]
    assert "thinnest 0.300 mm" in f["message"]
    # the table says so too
    assert main(["check", thin, "--printer", "j55"]) == 1
    out = capsys.readouterr().out
    assert "not printable" in out and "thin_walls" in out


def test_a_plate_thicker_than_the_minimum_is_printable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(plate(tmp_path, 3.0)), "--printer", "j55", "--strict", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert thin_findings(doc) == [] and doc["files"][0]["stats"]["thin_wall_fraction"] == 0.0


def test_under_the_share_thin_walls_stay_a_warning(tmp_path: Path) -> None:
    # the rule reads the limit: a plate 100 % thin is a warning only if the share allowed is all of it
    thin = plate(tmp_path, 0.3)
    r = check_mesh(thin, printer="j55", limits=Limits(thin_wall_error_fraction=1.0))
    (f,) = [f for f in r.findings if f.code == "thin_walls"]
    assert f.severity == "warning" and "no more than the 100%" in f.message
    assert r.exit_code == 0 and r.with_strict().exit_code == 1
    # a minimum asked for without a printer reports, never refuses
    r = check_mesh(thin, limits=Limits(min_wall_mm=1.0))
    assert [f.severity for f in r.findings if f.code == "thin_walls"] == ["warning"] and r.exit_code == 0
