"""Tests of saucerfab.workflow's finish step: which files an export's check reads, its limits, and ``check.json``.

``tests/fabricate/test_export_check_limits.py`` holds the raised limits
against a lowered default on a real export; here :func:`meshes_to_check`
on hand-made folders (a zipped OBJ unpacked, a bad entry refused),
:func:`export_limits` never under the defaults, and :func:`finish_print`
on a tiny synthetic export: ``check.json`` without times, paths relative
to the folder, a file in ``other-formats/`` checked without the printer.
The quick verify (a ray trace) is left to ``tests/verify/``.
"""

from __future__ import annotations

import json
import re
import zipfile
from dataclasses import fields
from pathlib import Path
from types import SimpleNamespace

import pytest

from saucerfab.check.limits import DEFAULT_LIMITS, Limits
from saucerfab.errors import ExportError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import ExportResult, export_design
from saucerfab.fabricate.registry import OTHER_FORMATS_DIR
from saucerfab.model.design_folder import synthetic_design
from saucerfab.workflow import CheckedFile, PrintResult, export_limits, finish_print, meshes_to_check

OBJ_ZIP = {"saucer.obj": b"mtllib saucer.mtl\nv 0 0 0\n", "saucer.mtl": b"newmtl m\n", "saucer.png": b"\x89PNG"}


def write_zip(path: Path, entries: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in entries.items():
            zf.writestr(name, data)
    return path


def test_plain_mesh_files_are_checked_where_they_are(tmp_path: Path) -> None:
    files = {
        "obj": [tmp_path / "saucer.obj", tmp_path / "saucer.mtl", tmp_path / "saucer.png"],
        "stl": [tmp_path / OTHER_FORMATS_DIR / "saucer.stl"],
    }
    with meshes_to_check(files) as meshes:
        assert [(m.written, m.name, m.path) for m in meshes] == [
            (files["obj"][0], "saucer.obj", files["obj"][0]),
            (files["stl"][0], "saucer.stl", files["stl"][0]),
        ]


def test_a_zipped_obj_is_checked_as_the_bureau_unpacks_it(tmp_path: Path) -> None:
    archive = write_zip(tmp_path / "saucer.zip", OBJ_ZIP)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    with meshes_to_check({"obj": [archive]}, scratch=scratch) as meshes:
        assert len(meshes) == 1
        m = meshes[0]
        assert (m.written, m.name, m.path.name) == (archive, "saucer.zip/saucer.obj", "saucer.obj")
        assert m.path.is_relative_to(scratch)
        for name, data in OBJ_ZIP.items():  # the MTL and PNG beside the OBJ, byte for byte
            assert (m.path.parent / name).read_bytes() == data
        unpacked = m.path.parent
    assert not unpacked.exists() and list(scratch.iterdir()) == []  # gone when the block ends


@pytest.mark.parametrize("entry", ["../evil.obj", "sub/saucer.obj", ".hidden.obj", "folder/", "a\\b.obj", "/abs.obj"])
def test_a_zip_entry_that_is_not_a_plain_name_is_refused(tmp_path: Path, entry: str) -> None:
    archive = write_zip(tmp_path / "saucer.zip", {**OBJ_ZIP, entry: b""})
    with pytest.raises(ExportError, match=re.escape(f"the export's saucer.zip holds an unexpected entry {entry!r}")):
        with meshes_to_check({"obj": [archive]}):
            pass
    assert not (tmp_path / "evil.obj").exists()


def test_a_format_without_its_mesh_file_is_an_export_error(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="the export wrote no .obj file for format 'obj'"):
        with meshes_to_check({"obj": [tmp_path / "saucer.mtl", tmp_path / "saucer.png"]}):
            pass
    archive = write_zip(tmp_path / "saucer.zip", {"saucer.mtl": b"", "saucer.png": b""})
    with pytest.raises(ExportError, match="wrote no .obj file"):
        with meshes_to_check({"obj": [archive]}):
            pass


def _never_lower(lim: Limits) -> None:
    for f in fields(Limits):
        got, default = getattr(lim, f.name), getattr(DEFAULT_LIMITS, f.name)
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            assert got >= default, f.name


def test_export_limits_are_the_defaults_for_a_small_export(tmp_path: Path) -> None:
    small = tmp_path / "saucer.stl"
    small.write_bytes(b"x" * 100)
    lim = export_limits(SimpleNamespace(files={"stl": [small, tmp_path / "gone.png"]}, triangles=12, texture_px=64))
    assert lim == DEFAULT_LIMITS  # raised to the export's sizes, never lowered to them


def test_export_limits_rise_to_a_large_export(tmp_path: Path) -> None:
    archive = write_zip(tmp_path / "saucer.zip", OBJ_ZIP)
    triangles = 3 * DEFAULT_LIMITS.max_triangles
    lim = export_limits(SimpleNamespace(files={"obj": [archive]}, triangles=triangles, texture_px=16384))
    assert lim.max_triangles == triangles and lim.max_texture_pixels == 16384**2
    assert lim.max_total_texture_pixels == 16384**2
    _never_lower(lim)


def test_finished_exit_code_is_the_worst_check() -> None:
    assert PrintResult().check_exit_code == 0
    done = PrintResult(checks=[CheckedFile(Path("a"), "a", SimpleNamespace(exit_code=1)),
                               CheckedFile(Path("b"), "b", None),
                               CheckedFile(Path("c"), "c", SimpleNamespace(exit_code=2))])
    assert done.check_exit_code == 2


@pytest.fixture(scope="module")
def export(tmp_path_factory: pytest.TempPathFactory) -> ExportResult:
    """A tiny export for the bureau: a zipped OBJ (its format) and an STL it does not take, in other-formats/."""
    out = tmp_path_factory.mktemp("finish") / "print"
    return export_design(synthetic_design(resolution=16, texture_size=64, seed=1), out, printer="bureau",
                         cup_diameter_mm=80.0, formats=["obj", "stl"],
                         options=FabOptions(texture_px=64, obj_zip=True), allow_other_formats=True)


def test_finish_print_writes_check_json_without_times_and_with_relative_paths(export: ExportResult) -> None:
    folder = Path(export.out)
    assert export.other_formats == ["stl"]
    assert export.files == {"obj": [folder / "saucer.zip"], "stl": [folder / OTHER_FORMATS_DIR / "saucer.stl"]}
    done = finish_print(export, export.profile, check=True, verify=False)
    assert done.verify is None and done.notes == []
    assert [c.written for c in done.checks] == [folder / "saucer.zip", folder / OTHER_FORMATS_DIR / "saucer.stl"]
    assert [c.name for c in done.checks] == ["saucer.zip/saucer.obj", "saucer.stl"]  # a zip's mesh by its entry
    assert done.check_exit_code == 0, [(c.name, c.report.reason()) for c in done.checks]
    text = (folder / "check.json").read_text(encoding="utf-8")
    doc = json.loads(text)
    assert doc["schema"] == "saucerfab.check/1"
    assert [d["path"] for d in doc["files"]] == ["saucer.zip", f"{OTHER_FORMATS_DIR}/saucer.stl"]
    assert [d["format"] for d in doc["files"]] == ["obj", "stl"]
    assert "elapsed_s" not in text  # no time anywhere: the folder is reproducible
    # the print set is checked for its printer; a file outside it is not for that printer
    assert [d["printer"] for d in doc["files"]] == ["bureau", None]
    assert all(d["verdict"] == "printable" for d in doc["files"])
    assert (folder / "report.html").is_file()
    # and the same folder gives the same bytes again
    finish_print(export, export.profile, check=True, verify=False)
    assert (folder / "check.json").read_text(encoding="utf-8") == text


def test_finish_print_without_check_writes_no_check_json(export: ExportResult) -> None:
    (Path(export.out) / "check.json").unlink(missing_ok=True)
    done = finish_print(export, export.profile, check=False, verify=False)
    assert done.checks == [] and not (Path(export.out) / "check.json").exists()
