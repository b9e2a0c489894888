"""The workflow (issue 41): design -> export -> check -> verify -> report exists once.

The front doors (the commands, the batch, the studio, the demo) call
:mod:`saucerfab.workflow`, never a stage of the sequence themselves: an AST
scan of their imports and attribute uses. And :func:`make_print` on a tiny
synthetic design: its stages in order, its typed result, ``check.json`` only
where asked.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

from saucerfab.fabricate.options import FabOptions
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.workflow import STAGES, CheckedFile, PrintResult, make_print

PACKAGE = Path(__file__).resolve().parents[1] / "saucerfab"

#: the front doors: thin doors over the workflow
FRONT_DOORS = ("cli", "batch", "studio", "demo.py")

#: the stages of the sequence (and the old module that chained them) a front door must not call itself
STAGE_CALLS = frozenset({"optimize_design", "design_report", "export_design", "check_mesh", "verify_print", "finish_print",
                         "meshes_to_check"})
STAGE_MODULES = frozenset({"saucerfab.finish"})

#: uses allowed, each with its reason: ``saucerfab verify`` is the verify stage's own command (a full verify
#: of a print folder with the user's eyes and thresholds), not the sequence
ALLOWED = {("cli/verify.py", "verify_print")}


def stage_uses(source: str) -> list[str]:
    """The stages of :data:`STAGE_CALLS` (and modules of :data:`STAGE_MODULES`) ``source`` imports or reaches."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            found += [a.name for a in node.names if a.name in STAGE_CALLS]
            if node.module in STAGE_MODULES:
                found.append(node.module)
            found += [f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in STAGE_MODULES]
        elif isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name in STAGE_MODULES]
        elif isinstance(node, ast.Attribute) and node.attr in STAGE_CALLS:
            found.append(node.attr)  # pipeline.export_design(...), a module's attribute
    return found


def front_door_files() -> list[Path]:
    out: list[Path] = []
    for door in FRONT_DOORS:
        path = PACKAGE / door
        out += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return out


def test_the_scan_finds_a_door_that_calls_the_stages_itself() -> None:
    source = (
        "from saucerfab.fabricate.pipeline import export_design\n"
        "def run():\n"
        "    from saucerfab.check import check_mesh\n"
        "    import saucerfab.verify as v\n"
        "    v.verify_print('x')\n"
        "    from saucerfab import finish\n"
        "    from saucerfab.optimize.pipeline import optimize_design\n"
    )
    assert sorted(stage_uses(source)) == ["check_mesh", "export_design", "optimize_design", "saucerfab.finish",
                                          "verify_print"]
    assert stage_uses("from saucerfab.workflow import make_print, run_design, verify_design\n") == []


def test_no_front_door_calls_a_stage_of_the_sequence_itself() -> None:
    files = front_door_files()
    assert len(files) > 10  # the scan reads the doors (a renamed package would pass it empty)
    found = []
    for path in files:
        rel = path.relative_to(PACKAGE).as_posix()
        found += [f"{rel}: {use}" for use in stage_uses(path.read_text(encoding="utf-8")) if (rel, use) not in ALLOWED]
    assert not found, ("front doors calling a stage of design -> export -> check -> verify -> report themselves "
                       "(call saucerfab.workflow's run_design / make_print / finish_print / verify_design instead): "
                       + "; ".join(found))


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny synthetic design folder."""
    return save_design(synthetic_design(resolution=16, texture_size=64, seed=1),
                       tmp_path_factory.mktemp("design") / "design")


def test_make_print_exports_checks_and_reports_in_order(design_dir: Path, tmp_path: Path) -> None:
    told: list[str] = []
    done = make_print(design_dir, tmp_path / "print", printer="j55", cup_diameter_mm=80.0, formats=["obj", "3mf"],
                      options=FabOptions(texture_px=64), verify=False, on_stage=told.append)
    assert told == ["export", "check", "report"]  # the verify skipped, the report still written
    assert set(told) <= set(STAGES)
    assert isinstance(done, PrintResult) and done.export.out == tmp_path / "print"
    assert all(isinstance(c, CheckedFile) for c in done.checks)
    assert sorted(c.name for c in done.checks) == ["saucer.3mf", "saucer.obj"]
    assert done.check_exit_code == 0 and done.verify is None and done.notes == []
    doc = json.loads((tmp_path / "print" / "check.json").read_text(encoding="utf-8"))
    assert sorted(d["path"] for d in doc["files"]) == ["saucer.3mf", "saucer.obj"]
    assert (tmp_path / "print" / "report.html").is_file()


def test_make_print_leaves_check_json_out_where_asked(design_dir: Path, tmp_path: Path) -> None:
    """The batch keeps each file's check in its job folder: the print folder has no check.json then."""
    done = make_print(design_dir, tmp_path / "print", printer="j55", cup_diameter_mm=80.0, formats=["obj"],
                      options=FabOptions(texture_px=64, obj_zip=True), verify=False, write_check_json=False,
                      scratch=tmp_path)
    assert [c.name for c in done.checks] == ["saucer.zip/saucer.obj"]  # the zip's mesh, as the bureau unpacks it
    assert not (tmp_path / "print" / "check.json").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["print"]  # the unpacked zip went from the scratch folder


def test_the_trial_verify_of_a_design_is_for_the_printer_it_was_made_for(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """verify_design(design) without a printer uses the design's own (its intent), as export does."""
    import saucerfab.fabricate.pipeline as fab
    from saucerfab.errors import ExportError
    from saucerfab.model.design_folder import load_design
    from saucerfab.workflow import verify_design

    asked: list[str] = []

    def stop(design: object, out: object, *, printer: object = None, **kw: object) -> None:
        asked.append(printer.key)  # type: ignore[attr-defined]
        raise ExportError("stopped by the test")

    monkeypatch.setattr(fab, "export_design", stop)
    made = synthetic_design(resolution=12, texture_size=32)
    made.parameters["printer"] = "hp_jf580"
    design = load_design(save_design(made, tmp_path / "design"))
    for given, expected in ((None, "hp_jf580"), ("j850", "j850")):
        with pytest.raises(ExportError, match="stopped by the test"):
            verify_design(design, printer=given)
        assert asked.pop() == expected
    with pytest.raises(ExportError, match="with its folder"):
        verify_design(made)  # a design only in memory has no folder to write the verify into
