"""``saucerfab check`` on the command line: exit codes, table, --json (schema-validated), --junit, start-up."""

from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from defusedxml import ElementTree

import fixtures_check as fx
from saucerfab.check import JSON_SCHEMA, REPORT_SCHEMA, check_mesh, reports_to_junit
from saucerfab.cli import main

# -- a small JSON Schema validator for the keywords our schema uses ---------------------
# (jsonschema is not a project dependency; where it is installed the documents are also checked with it)


class SchemaError(AssertionError):
    pass


def validate(doc: Any, schema: dict[str, Any], root: dict[str, Any] | None = None, at: str = "$") -> None:
    root = root or schema
    if "$ref" in schema:
        ref = schema["$ref"]
        assert ref.startswith("#/$defs/"), ref
        validate(doc, root["$defs"][ref.split("/")[-1]], root, at)
    if "oneOf" in schema:
        ok = 0
        for sub in schema["oneOf"]:
            try:
                validate(doc, sub, root, at)
                ok += 1
            except SchemaError:
                pass
        if ok != 1:
            raise SchemaError(f"{at}: matches {ok} of oneOf")
    if "const" in schema and doc != schema["const"]:
        raise SchemaError(f"{at}: {doc!r} != const {schema['const']!r}")
    if "enum" in schema and doc not in schema["enum"]:
        raise SchemaError(f"{at}: {doc!r} not in {schema['enum']}")
    if "type" in schema:
        types = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        pytypes = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}
        good = False
        for t in types:
            if t == "integer":
                good |= isinstance(doc, int) and not isinstance(doc, bool)
            elif t == "number":
                good |= isinstance(doc, (int, float)) and not isinstance(doc, bool)
            else:
                good |= isinstance(doc, pytypes[t])
        if not good:
            raise SchemaError(f"{at}: {doc!r} is not {types}")
    if isinstance(doc, (int, float)) and not isinstance(doc, bool):
        if "minimum" in schema and doc < schema["minimum"]:
            raise SchemaError(f"{at}: {doc} < minimum")
        if "maximum" in schema and doc > schema["maximum"]:
            raise SchemaError(f"{at}: {doc} > maximum")
        if "exclusiveMinimum" in schema and doc <= schema["exclusiveMinimum"]:
            raise SchemaError(f"{at}: {doc} <= exclusiveMinimum")
    if isinstance(doc, str) and "pattern" in schema and not re.search(schema["pattern"], doc):
        raise SchemaError(f"{at}: {doc!r} does not match {schema['pattern']}")
    if isinstance(doc, dict):
        for k in schema.get("required", []):
            if k not in doc:
                raise SchemaError(f"{at}: missing {k!r}")
        props = schema.get("properties", {})
        for k, v in doc.items():
            if k in props:
                validate(v, props[k], root, f"{at}.{k}")
            elif schema.get("additionalProperties") is False:
                raise SchemaError(f"{at}: unexpected key {k!r}")
    if isinstance(doc, list):
        if "minItems" in schema and len(doc) < schema["minItems"]:
            raise SchemaError(f"{at}: fewer than {schema['minItems']} items")
        if "maxItems" in schema and len(doc) > schema["maxItems"]:
            raise SchemaError(f"{at}: more than {schema['maxItems']} items")
        if "items" in schema:
            for i, v in enumerate(doc):
                validate(v, schema["items"], root, f"{at}[{i}]")


def validate_both(doc: Any, schema: dict[str, Any]) -> None:
    validate(doc, schema)
    try:
        import jsonschema
    except ImportError:
        return
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(doc)


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    V, F, uv = fx.saucer_solid(12)
    good = fx.write_3mf(tmp_path / "good.3mf", V, F, uv=uv, texture=fx.png_bytes(256, 256))
    Vb, Fb = fx.box()
    open_box = fx.write_stl(tmp_path / "open.stl", Vb, Fb[1:])
    V2, F2 = fx.box(origin=(60, 0, 0))
    two = fx.write_ply(tmp_path / "two.ply", np.concatenate([Vb, V2]), np.concatenate([Fb, F2 + 8]), colors=True)
    (tmp_path / "image.obj").write_bytes(fx.png_bytes())
    return {"good": good, "open": open_box, "two": two, "png": tmp_path / "image.obj"}


def test_exit_codes_are_the_worst_over_files(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(files["good"])]) == 0
    assert main(["check", str(files["good"]), str(files["two"])]) == 0  # a warning only
    assert main(["check", str(files["good"]), str(files["two"]), "--strict"]) == 1
    assert main(["check", str(files["good"]), str(files["open"])]) == 1
    assert main(["check", str(files["png"]), str(files["open"]), str(files["good"])]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1] == "3 files: 1 printable, 1 not printable, 1 unreadable (exit 2)"
    text = "\n".join(out)
    assert "not_watertight" in text and "not_a_mesh" in text
    assert "Traceback" not in text


def test_table_names_files_and_reasons(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("saucerfab.cli.check.on_terminal", lambda: True)  # the table is for a terminal
    main(["check", str(files["open"]), "--printer", "j55"])
    out = capsys.readouterr().out
    assert "saucerfab check" in out and "not printable" in out
    assert "open edges" in out and " mm" in out
    assert out.strip().splitlines()[-1].startswith("1 file: 0 printable, 1 not printable")


def test_json_output_matches_the_schema(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["check", *map(str, files.values()), "--json", "--printer", "j55"])
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    validate_both(doc, JSON_SCHEMA)
    assert rc == doc["summary"]["exit_code"] == 2
    assert doc["schema"] == "saucerfab.check/1" and doc["printer"] == "j55"
    assert [f["verdict"] for f in doc["files"]] == ["printable", "not printable", "printable", "unreadable"]
    assert doc["summary"] == {"files": 4, "printable": 2, "not_printable": 1, "unreadable": 1, "exit_code": 2}
    assert "4 files:" in cap.err  # the summary goes to stderr, stdout stays pure JSON
    for f in doc["files"]:
        validate_both(f, REPORT_SCHEMA)
    # the schema is strict enough to catch a wrong document
    for mutate in (
        lambda d: d["files"][0].pop("verdict"),
        lambda d: d["files"][0].__setitem__("verdict", "fine"),
        lambda d: d["files"][0]["findings"].append({"severity": "error", "code": "no_such_code", "message": "x",
                                                     "where": None}),
        lambda d: d["files"][0]["stats"].__setitem__("triangles", -1),
        lambda d: d["files"][0]["stats"].__setitem__("surprise", 1),
        lambda d: d["summary"].__setitem__("exit_code", 3),
    ):
        bad = copy.deepcopy(doc)
        mutate(bad)
        with pytest.raises(SchemaError):
            validate(bad, JSON_SCHEMA)


def test_schema_flag_prints_the_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--schema"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(JSON_SCHEMA))


def test_junit_report(files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ci" / "check.xml"
    rc = main(["check", *map(str, files.values()), "--junit", str(out)])
    capsys.readouterr()
    assert rc == 2
    root = ElementTree.fromstring(out.read_bytes())
    assert root.tag == "testsuites"
    suite = root.find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("4", "1", "1")
    cases = {Path(c.get("name")).name: c for c in suite.findall("testcase")}
    assert set(cases) == {"good.3mf", "open.stl", "two.ply", "image.obj"}
    assert cases["open.stl"].find("failure").get("type") == "not_watertight"
    assert cases["image.obj"].find("error").get("type") == "not_a_mesh"
    assert cases["good.3mf"].find("failure") is None and cases["good.3mf"].find("error") is None
    assert "multiple_shells" in cases["two.ply"].find("system-out").text
    # an existing report is replaced only with --force (the rule of every command that writes)
    assert main(["check", str(files["two"]), "--strict", "--junit", str(out)]) == 2
    assert "exists; add --force" in capsys.readouterr().err
    rc = main(["check", str(files["two"]), "--strict", "--junit", str(out), "--force"])
    suite = ElementTree.fromstring(out.read_bytes()).find("testsuite")
    assert rc == 1 and suite.find("testcase/failure").get("type") == "multiple_shells"


def test_junit_stays_well_formed_with_hostile_names(tmp_path: Path) -> None:
    p = tmp_path / "we\x01ird<&>\"name.obj"
    p.write_bytes(b"v 1 2 3\x00\x1b[31m\nf 1 2 3\n")
    xml = reports_to_junit([check_mesh(p)])
    root = ElementTree.fromstring(xml.encode())
    assert root.find("testsuite/testcase").get("name").endswith('name.obj')


def test_bad_usage_is_a_clean_error(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check"]) == 2
    assert main(["check", str(files["good"]), "--printer", "no-such"]) == 2
    assert main(["check", str(files["good"]), "--max-triangles", "0"]) == 2
    err = capsys.readouterr().err
    assert "unknown printer 'no-such'" in err and "give one or more mesh files" in err
    assert "Traceback" not in err


def test_max_triangles_and_min_wall_options(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(files["good"]), "--max-triangles", "50"]) == 2
    assert "over_check_limit" in capsys.readouterr().out
    assert main(["check", str(files["good"]), "--min-wall", "10", "--strict"]) == 1
    assert "thin_walls" in capsys.readouterr().out


def test_check_starts_without_torch(files: dict[str, Path]) -> None:
    """A fresh interpreter running the CLI's check never imports torch (nor numba, matplotlib, trimesh)."""
    code = (
        "import sys\n"
        "from saucerfab.cli import main\n"
        f"rc = main(['check', {str(files['good'])!r}, '--json'])\n"
        "heavy = sorted(m for m in ('torch', 'numba', 'matplotlib', 'trimesh', 'xatlas') if m in sys.modules)\n"
        "print('HEAVY', heavy, rc, file=sys.stderr)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120)
    err = proc.stderr.decode("utf-8", "replace")
    assert "HEAVY [] 0" in err, err[-3000:]
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "saucerfab", "check", str(files["good"])],
                          capture_output=True, timeout=120)
    err = proc.stderr.decode("utf-8", "replace")
    assert proc.returncode == 0, err[-3000:]
    imported = {line.split("|")[-1].strip() for line in err.splitlines() if line.startswith("import time:")}
    assert "saucerfab.check" in imported and "torch" not in imported


def test_readme_lists_every_finding_code() -> None:
    from saucerfab.check import CODES

    text = (Path(__file__).resolve().parents[2] / "saucerfab" / "check" / "README.md").read_text()
    for code, (kind, meaning) in CODES.items():
        assert f"| `{code}` | {kind} | {meaning} |" in text, code


def test_table_names_a_location_once() -> None:
    import io

    from rich.console import Console

    from saucerfab.check.report import Finding, Report

    named = Finding("warning", "thin_walls", "thinnest 0.773 mm at (60.93, 74.92, 18.50) mm", {"point_mm": [60.93, 74.92, 18.5]})
    unnamed = Finding("error", "not_watertight", "3 open edges", {"point_mm": [1.0, 2.0, 3.0]})
    buf = io.StringIO()
    report = Report.build("a.3mf", "3mf", [named, unnamed], {})
    from saucerfab.check.report import render_table

    render_table([report], console=Console(file=buf, width=300, highlight=False))
    text = buf.getvalue()
    assert text.count("(60.93, 74.92, 18.50) mm") == 1
    assert "3 open edges  at (1.00, 2.00, 3.00) mm" in text


def _deep_files(root: Path) -> list[Path]:
    """The issue's layout: a printable saucer and an open box deep under runs/e1."""
    deep = root / "tmp" / "some" / "deep" / "folder" / "runs" / "e1"
    deep.mkdir(parents=True)
    V, F, uv = fx.saucer_solid(12)
    Vb, Fb = fx.box()
    return [
        fx.write_3mf(deep / "saucer.3mf", V, F, uv=uv, texture=fx.png_bytes(256, 256)),
        fx.write_stl(deep / "open_box_with_a_long_name.stl", Vb, Fb[1:]),
    ]


def _row_shown_whole(text: str, name: str, fmt: str, verdict: str) -> bool:
    """Some line holds the file name, its format and its verdict, none of them cut."""
    row = re.compile(re.escape(name) + r"\s.*\b" + fmt + r"\b.*(?<![\w-])" + re.escape(verdict) + r"(?![\w-])")
    return any(row.search(line) for line in text.splitlines())


def test_table_at_80_columns_keeps_verdicts_and_file_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _deep_files(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setattr("saucerfab.cli.check.on_terminal", lambda: True)  # the table is for a terminal
    saucer = "tmp/some/deep/folder/runs/e1/saucer.3mf"
    box = "tmp/some/deep/folder/runs/e1/open_box_with_a_long_name.stl"
    assert main(["check", saucer, box]) == 1
    out = capsys.readouterr().out
    assert _row_shown_whole(out, "saucer.3mf", "3mf", "printable"), out
    assert _row_shown_whole(out, "open_box_with_a_long_name.stl", "stl", "not printable"), out
    assert out.strip().splitlines()[-1] == "2 files: 1 printable, 1 not printable, 0 unreadable (exit 1)"


@pytest.mark.parametrize("width", [60, 80, 100, 120, 160, 300])
def test_table_fits_the_width_or_gives_one_line_per_file(tmp_path: Path, width: int) -> None:
    import io

    from rich.console import Console

    from saucerfab.check.report import render_table

    paths = _deep_files(tmp_path)
    reports = [check_mesh(p) for p in paths]
    buf = io.StringIO()
    render_table(reports, console=Console(file=buf, width=width, highlight=False, soft_wrap=False))
    text = buf.getvalue()
    table = [line for line in text.splitlines() if line[:1] in "┏┃┡│└"]
    assert all(len(line) <= width for line in table), text  # a table is never wider than the console
    assert _row_shown_whole(text, "saucer.3mf", "3mf", "printable"), text
    assert _row_shown_whole(text, "open_box_with_a_long_name.stl", "stl", "not printable"), text
    if width >= 200:
        assert table and str(paths[1]) in text  # room enough: the table, with the whole path


def test_shorten_middle_keeps_the_file_name() -> None:
    from saucerfab.check.report import shorten_middle

    path = "tmp/some/deep/folder/runs/e1/saucer.3mf"
    assert shorten_middle(path, 100) == path
    assert shorten_middle(path, 24) == "tmp/some/de\u20261/saucer.3mf"
    assert shorten_middle(path, 12) == "\u2026/saucer.3mf"
    assert shorten_middle(path, 5).endswith("/saucer.3mf")  # never the name itself
    assert shorten_middle("C:\\runs\\e1\\deep\\saucer.3mf", 16, "...") == "C:...\\saucer.3mf"
    for width in range(12, len(path)):
        short = shorten_middle(path, width)
        assert len(short) == width and short.endswith("/saucer.3mf")
