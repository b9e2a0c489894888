"""Batch manifests report every problem at once, with file and line (issue 42, item 9).

* a TOML and a CSV manifest with five different planted problems (a missing
  image, a ``..`` path, a duplicate id, an unknown option, an unknown printer)
  give ONE error naming all five, each as ``file:line: job 'id': ...``;
* a missing image is refused when the manifest loads: ``saucerfab batch``
  exits 2 before any job runs and writes nothing;
* a systematic mistake in ``[defaults]`` is listed once, and a long list is cut;
* the line scan places sub-tables and dotted keys, and skips multi-line strings;
* a job without ``printer`` or ``cup_diameter_mm`` gets the defaults
  ``saucerfab design`` / ``saucerfab export`` use.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from saucerfab.batch.jobs import load_payload
from saucerfab.batch.manifest import load_manifest
from saucerfab.batch.manifest_lines import MAX_PROBLEMS_SHOWN
from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.model.profiles import DEFAULT_PRINTER
from saucerfab.optimize.request import DesignRequest

# line numbers below count from the first line of these texts (no leading newline)
TOML = """\
[defaults]
printer = "j55"
cup_diameter_mm = 80

[[job]]
id = "cat-rose"
direct = "images/rosee.png"
reflected = "../outside.png"

[[job]]
id = "teapot"
design = "designs/teapot"
printer = "j5"

[[job]]
id = "Teapot"
design = "designs/teapot"

[[job]]
id = "opts"
direct = "images/rose.png"
reflected = "images/cat.png"
design_options = { resolution = 40, colour = "red" }
"""

CSV = """\
# the same five problems, as CSV (comment lines count: line numbers are the file's)
id,design,direct,reflected,printer,cup_diameter_mm,design_options
cat-rose,,images/rosee.png,../outside.png,j55,80,
# a comment between rows
teapot,designs/teapot,,,j5,80,
Teapot,designs/teapot,,,j55,80,
opts,,images/rose.png,images/cat.png,j55,80,resolution=40; colour="red"
"""


def _folder(tmp_path: Path) -> Path:
    """A manifest folder with the inputs the planted manifests name correctly (and a file outside it)."""
    root = tmp_path / "batch"
    (root / "images").mkdir(parents=True)
    (root / "images" / "rose.png").write_bytes(b"rose")
    (root / "images" / "cat.png").write_bytes(b"cat")
    (root / "designs" / "teapot").mkdir(parents=True)
    (tmp_path / "outside.png").write_bytes(b"outside")  # exists: '..' is the only thing wrong with it
    return root


def _problem(message: str, prefix: str) -> str:
    """The one listed problem that starts with ``prefix`` (``m.toml:6: job 'x':``)."""
    found = [ln.strip() for ln in message.splitlines() if ln.strip().startswith(prefix)]
    assert len(found) == 1, (prefix, message)
    return found[0]


@pytest.mark.parametrize(
    "name, text, lines",
    [
        ("m.toml", TOML, {"missing": 7, "dotdot": 8, "printer": 13, "twice": 16, "first": 11, "option": 23}),
        ("m.csv", CSV, {"missing": 3, "dotdot": 3, "printer": 5, "twice": 6, "first": 5, "option": 7}),
    ],
)
def test_five_planted_problems_in_one_error_with_lines(
    tmp_path: Path, name: str, text: str, lines: dict[str, int]
) -> None:
    root = _folder(tmp_path)
    (root / name).write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as exc:
        load_manifest(root / name)
    msg = str(exc.value)
    assert "5 problem(s)" in msg and "nothing was run" in msg, msg

    missing = _problem(msg, f"{name}:{lines['missing']}: job 'cat-rose': direct image")
    assert "'images/rosee.png' not found" in missing and "check the name" in missing
    dotdot = _problem(msg, f"{name}:{lines['dotdot']}: job 'cat-rose': reflected")
    assert "'../outside.png'" in dotdot and "outside the manifest's folder" in dotdot
    printer = _problem(msg, f"{name}:{lines['printer']}: job 'teapot':")
    assert "unknown printer 'j5'" in printer and "saucerfab printers" in printer
    twice = _problem(msg, f"{name}:{lines['twice']}: job 'Teapot':")
    assert "used twice" in twice and f"{name}:{lines['first']}" in twice
    option = _problem(msg, f"{name}:{lines['option']}: job 'opts':")
    assert "unknown design option(s) ['colour']" in option


def test_a_missing_image_stops_the_batch_before_any_job_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _folder(tmp_path)
    m = root / "m.toml"
    m.write_text('[[job]]\nid = "a"\ndirect = "images/rosee.png"\nreflected = "images/cat.png"\nprinter = "j55"\n'
                 "cup_diameter_mm = 80\n", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["batch", str(m), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "m.toml:3: job 'a': direct image 'images/rosee.png' not found" in err, err
    assert not out.exists()  # nothing written: no job folder, no report


def test_a_mistake_in_defaults_is_listed_once_and_long_lists_are_cut(tmp_path: Path) -> None:
    root = _folder(tmp_path)
    jobs = "".join(f'[[job]]\nid = "j{i}"\ndesign = "designs/gone{i}"\n\n' for i in range(MAX_PROBLEMS_SHOWN + 30))
    m = root / "m.toml"
    m.write_text('[defaults]\nprinter = "j5"\ncup_diameter_mm = 80\n\n' + jobs, encoding="utf-8")
    with pytest.raises(ConfigError) as exc:
        load_manifest(m)
    msg = str(exc.value)
    # the unknown printer of [defaults]: once, at its own line, not once per job
    assert msg.count("unknown printer 'j5'") == 1 and "m.toml:2: [defaults]:" in msg, msg[:2000]
    assert f"{MAX_PROBLEMS_SHOWN + 31} problem(s)" in msg
    assert "m.toml:7: job 'j0': design folder 'designs/gone0' not found" in msg
    assert len(msg.splitlines()) == 1 + MAX_PROBLEMS_SHOWN + 1  # header, the first ones, "... and N more"
    assert msg.splitlines()[-1].strip() == "... and 31 more"


def test_printer_and_cup_size_default_as_in_design_and_export(tmp_path: Path) -> None:
    root = _folder(tmp_path)
    made_for = root / "designs" / "made-for-j850"
    made_for.mkdir()
    (made_for / "design.json").write_text(json.dumps({"parameters": {"print_target": {"printer": "j850"}}}))
    given = root / "designs" / "made-with-printer-mimaki"  # what 'saucerfab design --printer' was given
    given.mkdir()
    (given / "design.json").write_text(json.dumps({"parameters": {"printer": "mimaki_3duj553"}}))
    (root / "designs" / "teapot" / "design.json").write_text(json.dumps({"parameters": {}}))
    m = root / "m.csv"
    m.write_text(
        "id,design,direct,reflected\n"
        "raw,,images/rose.png,images/cat.png\n"
        "plain,designs/teapot,,\n"
        "j850,designs/made-for-j850,,\n"
        "mimaki,designs/made-with-printer-mimaki,,\n",
        encoding="utf-8",
    )
    raw, plain, j850, mimaki = load_manifest(m).jobs
    # a design run: saucerfab design's defaults (its printer, the scene's cup size)
    assert raw.printer == DesignRequest.default("printer") == DEFAULT_PRINTER
    assert raw.cup_diameter_mm is None
    request = load_payload(raw, root).request
    assert request["printer"] == DEFAULT_PRINTER and request["cup_diameter_mm"] is None
    # a design folder: export's defaults (the printer it was made for, else the default; its own cup size)
    assert plain.printer is None and plain.cup_diameter_mm is None
    assert load_payload(plain, root).printer.key == DEFAULT_PRINTER
    assert load_payload(j850, root).printer.key == "j850"
    assert load_payload(j850, root).cup_diameter_mm is None
    assert load_payload(mimaki, root).printer.key == "mimaki_3duj553"
    # a printer this machine does not know: that job fails when it runs, saying what to do
    (given / "design.json").write_text(json.dumps({"parameters": {"printer": "their-own"}}))
    with pytest.raises(ConfigError, match=r"unknown printer 'their-own'.*design\.json.*give the job a 'printer'"):
        load_payload(mimaki, root)


def test_lines_of_sub_tables_dotted_keys_and_multi_line_strings(tmp_path: Path) -> None:
    """The line scan places keys written every way TOML allows, and is not fooled by a
    multi-line string that looks like a job."""
    root = _folder(tmp_path)
    m = root / "m.toml"
    m.write_text(
        '[defaults]\nprinter = "j55"\n\n'  # 1-3
        '[[job]]\nid = "a"\ndesign = "designs/teapot"\n'  # 4-6
        'export_options.name = """\n[[job]]\nid = "not-a-job"\n"""\n'  # 7-10: a dotted key, a string
        'colour = "red"\n\n'  # 11
        '[[job]]\nid = "b"\ndirect = "images/rose.png"\nreflected = "images/cat.png"\n'  # 13-16
        "[job.design_options]\nresolution = 40\ncolour = 'red'\n",  # 17-19: a sub-table
        encoding="utf-8",
    )
    with pytest.raises(ConfigError) as exc:
        load_manifest(m)
    msg = str(exc.value)
    assert "m.toml:11: job 'a': unknown key(s) ['colour']" in msg, msg
    assert "m.toml:17: job 'b': unknown design option(s) ['colour']" in msg, msg
    # jobs written as an inline array: no headers to count, so the line of 'job'
    m.write_text('# one line of jobs\njob = [{ id = "a", design = "designs/gone" }]\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"1 problem\(s\).*\n  m\.toml:2: job 'a': design folder 'designs/gone' not found"):
        load_manifest(m)
