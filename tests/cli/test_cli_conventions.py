"""One set of conventions across the commands, and the export's printer and formats (issue 42).

Each test runs the CLI in-process through ``main(argv)`` and fails on the
behaviour the issue reported: export ignoring the design's printer, a format
the printer does not take written into the print set, ``nan s`` under
``--no-times``, commands without ``-q``/``--json``/``-o``/``--force``, a
table of box drawing in a pipe, and Pillow's raw warning before saucerfab's
message.
"""

from __future__ import annotations

import argparse
import json
import re
import struct
import warnings
import zlib
from dataclasses import replace
from pathlib import Path

import pytest

from saucerfab.cli import SUBCOMMANDS, build_parser, main
from saucerfab.model.design_folder import save_design, synthetic_design

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
#: export options that keep a test export small and fast
QUICK = ["--texture-px", "256", "--cup-diameter-mm", "30", "--no-verify", "-q"]
#: commands that write files or folders, and so take -o/--out and --force
WRITERS = ("design", "export", "verify", "check", "batch", "scene", "shapes")
#: the one command without -q/--json: a long-running server whose output is its request log
SERVERS = ("studio",)


def _design_folder(tmp_path: Path, printer: str | None) -> Path:
    """A small synthetic design folder that records ``printer`` as the one it was made for (None: none)."""
    d = synthetic_design(resolution=16, texture_size=32, seed=2)
    if printer is not None:
        d = replace(d, parameters={**d.parameters, "printer": printer})
    return save_design(d, tmp_path / "design")


def _options(command: str) -> set[str]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {s for a in sub.choices[command]._actions for s in a.option_strings}


# --------------------------------------------------------------------------- 1. the design's printer


def test_export_uses_the_printer_the_design_was_made_for(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _design_folder(tmp_path, "hp_jf580")
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--no-check", *QUICK]) == 0
    out = capsys.readouterr().out
    assert "for HP Jet Fusion 580 Color (hp_jf580; the printer the design was made for)" in out, out
    summary = json.loads((tmp_path / "p" / "export.json").read_text())
    assert summary["printer"]["key"] == "hp_jf580"
    # told otherwise, it says so
    assert main(["export", str(folder), "-o", str(tmp_path / "q"), "--printer", "j55", "--no-check", *QUICK]) == 0
    assert "(j55; as given)" in capsys.readouterr().out


def test_export_of_a_design_without_a_printer_says_it_uses_the_default(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _design_folder(tmp_path, None)
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--no-check", *QUICK]) == 0
    assert "(j55; the default printer: the design records none)" in capsys.readouterr().out


# --------------------------------------------------------------------------- 4. formats the printer does not take


def test_a_format_the_printer_does_not_take_is_refused_before_writing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _design_folder(tmp_path, "bureau")  # the bureau's profile lists no STL
    out = tmp_path / "p"
    assert main(["export", str(folder), "-o", str(out), "--formats", "obj,stl", *QUICK]) == 2
    err = capsys.readouterr().err
    assert "does not take STL" in err and "--allow-format" in err, err
    assert not out.exists()


def test_allow_format_writes_it_outside_the_print_set_and_the_print_set_checks_clean(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _design_folder(tmp_path, "bureau")
    out = tmp_path / "p"
    code = main(["export", str(folder), "-o", str(out), "--formats", "obj,stl", "--allow-format", "--seat", "ring",
                 *QUICK])
    said = capsys.readouterr().out
    assert code == 0, said
    assert (out / "other-formats" / "saucer.stl").is_file() and not (out / "saucer.stl").exists()
    assert "STL written into other-formats/" in said
    summary = json.loads((out / "export.json").read_text())
    assert summary["formats"] == ["obj"] and summary["other_formats"] == ["stl"]
    # the print set (the folder's top level) passes the printer's own check
    assert main(["check", str(out), "--printer", "bureau", "-q"]) == 0


# --------------------------------------------------------------------------- 6. --no-times


def test_no_times_prints_no_nan(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected",
                 str(SAMPLES / "reflected_star.png"), "--resolution", "12", "--image-size", "32", "--max-iters", "2",
                 "--no-times", "--no-verify", "-q", "-o", str(tmp_path / "d")])
    out = capsys.readouterr().out
    assert code == 0
    assert not re.search(r"\bnan\b", out), out
    assert "times not recorded (--no-times)" in out


# --------------------------------------------------------------------------- 7. one set of conventions


@pytest.mark.parametrize("command", sorted(set(SUBCOMMANDS) - set(SERVERS)))
def test_every_command_takes_quiet_and_json(command: str) -> None:
    opts = _options(command)
    assert {"-q", "--quiet", "--json"} <= opts, (command, sorted(opts))


@pytest.mark.parametrize("command", WRITERS)
def test_every_command_that_writes_takes_out_and_force(command: str) -> None:
    assert {"-o", "--out", "--force"} <= _options(command), (command, sorted(_options(command)))


def test_export_replaces_an_earlier_export_only_with_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _design_folder(tmp_path, "j55")
    out = tmp_path / "p"
    assert main(["export", str(folder), "-o", str(out), "--no-check", *QUICK]) == 0
    assert main(["export", str(folder), "-o", str(out), "--no-check", *QUICK]) == 2
    assert "holds an earlier export of this design; add --force" in capsys.readouterr().err
    assert main(["export", str(folder), "-o", str(out), "--no-check", "--force", *QUICK]) == 0


def test_check_takes_a_folder_and_a_glob(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _design_folder(tmp_path, "j55")
    out = tmp_path / "p"
    assert main(["export", str(folder), "-o", str(out), "--formats", "3mf,ply", "--no-check", *QUICK]) == 0
    capsys.readouterr()
    assert main(["check", str(out), "--json"]) == 0
    by_folder = [Path(f["path"]).name for f in json.loads(capsys.readouterr().out)["files"]]
    assert by_folder == ["saucer.3mf", "saucer.ply"]
    assert main(["check", str(out / "*.ply"), "--json"]) == 0
    assert [Path(f["path"]).name for f in json.loads(capsys.readouterr().out)["files"]] == ["saucer.ply"]
    assert main(["check", str(out / "*.stl")]) == 2
    assert "no file matches" in capsys.readouterr().err
    assert main(["check", str(tmp_path / "design")]) == 2  # a folder with no mesh: said, not "0 files"
    assert "holds no mesh file" in capsys.readouterr().err


def test_check_out_writes_the_json_and_refuses_to_replace_without_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _design_folder(tmp_path, "j55")
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--no-check", *QUICK]) == 0
    capsys.readouterr()
    report = tmp_path / "check.json"
    assert main(["check", str(tmp_path / "p"), "-o", str(report), "-q"]) == 0
    assert json.loads(report.read_text())["schema"] == "saucerfab.check/1"
    assert capsys.readouterr().out.strip().splitlines() == ["1 file: 1 printable, 0 not printable, 0 unreadable (exit 0)"]
    assert main(["check", str(tmp_path / "p"), "-o", str(report)]) == 2
    assert main(["check", str(tmp_path / "p"), "-o", str(report), "--force", "-q"]) == 0


def test_design_and_verify_name_the_eyes_with_the_same_words() -> None:
    from saucerfab.model.eyes import EYES_USAGE, parse_eyes
    from saucerfab.optimize.request import DesignRequest

    for word in ("design", "both", "box:40,20"):
        assert DesignRequest("a.png", "b.png", eyes=word).eye_spec() == parse_eyes(word)
    assert DesignRequest.default("eyes") == "design"
    helps = {}
    for command in ("design", "verify"):
        sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
        helps[command] = next(a.help for a in sub.choices[command]._actions if "--eyes" in a.option_strings)
        assert "point" not in helps[command] and "design (the design eye alone" in helps[command], helps[command]
    assert EYES_USAGE == "design|both|box:W,H[,N]"


def test_verify_replaces_an_earlier_verify_in_out_only_with_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "v"
    out.mkdir()
    (out / "verify.json").write_text("{}")
    (tmp_path / "print").mkdir()
    assert main(["verify", str(tmp_path / "print"), "-o", str(out)]) == 2
    assert "holds an earlier verify; add --force" in capsys.readouterr().err


def test_scene_and_shapes_follow_the_rule(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = tmp_path / "scene.toml"
    assert main(["scene", "-o", str(toml), "-q"]) == 0 and toml.is_file()
    assert capsys.readouterr().out == ""
    assert main(["scene", "-o", str(toml)]) == 2
    assert main(["scene", "-o", str(toml), "--force", "-q"]) == 0
    assert main(["scene", "--json"]) == 0
    assert "saucer" in json.loads(capsys.readouterr().out)
    png = tmp_path / "w.png"
    assert main(["shapes", "waves", "--resolution", "16", "-o", str(png), "-q"]) == 0
    assert main(["shapes", "waves", "--resolution", "16", "-o", str(png)]) == 2
    capsys.readouterr()
    assert main(["shapes", "--json"]) == 0
    assert "waves" in json.loads(capsys.readouterr().out)
    assert main(["printers", "-q"]) == 0
    assert "j55" in capsys.readouterr().out.split()


# --------------------------------------------------------------------------- 8. check into a pipe


def test_check_into_a_pipe_is_one_line_per_finding(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import trimesh

    box = trimesh.creation.box((40.0, 30.0, 20.0))
    box.faces = box.faces[:-2]  # an open box: not watertight, an error finding
    stl = tmp_path / "a-long-folder-name-for-the-open-box" / "open_box.stl"
    stl.parent.mkdir()
    box.export(stl)
    monkeypatch.setenv("COLUMNS", "40")  # a narrow terminal size must not wrap a pipe's lines
    assert main(["check", str(stl), "--printer", "j55"]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert not any(ch in "".join(lines) for ch in "\u2500\u2502\u2503\u2501\u250f\u2517\u2554\u2550")  # no boxes
    *body, summary = lines
    assert summary.startswith("1 file: 0 printable, 1 not printable")
    assert body and all(line.startswith(f"{stl}: ") for line in body), lines
    assert any(line.startswith(f"{stl}: error not_watertight: ") for line in body), lines


# --------------------------------------------------------------------------- 10. Pillow's own warning


def _png_header(width: int, height: int) -> bytes:
    """A PNG of that size whose pixels are never there: Pillow reads its size (and judges a bomb) from the header."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


def test_a_huge_picture_gets_only_saucerfabs_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    big = tmp_path / "huge.png"
    big.write_bytes(_png_header(12_000, 12_000))  # 144 Mpx: over Pillow's warning level, under its error level
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        code = main(["design", "--direct", str(big), "--reflected", str(SAMPLES / "reflected_star.png"),
                     "-o", str(tmp_path / "d"), "-q", "--no-verify"])
    err = capsys.readouterr().err
    assert code == 2
    assert "12000x12000" in err and "Downscale it first" in err, err
    assert not [w for w in seen if "DecompressionBomb" in type(w.message).__name__ or "decompression" in str(w.message)]


# --------------------------------------------------------------------------- the rules at every door


def test_a_batch_manifest_refuses_a_format_its_printer_does_not_take_at_load(tmp_path: Path) -> None:
    from saucerfab.batch import load_manifest
    from saucerfab.errors import ConfigError

    _design_folder(tmp_path, "bureau")
    manifest = tmp_path / "m.toml"
    manifest.write_text('[[job]]\nid = "a"\ndesign = "design"\nprinter = "bureau"\nformats = ["obj", "stl"]\n')
    with pytest.raises(ConfigError, match=r"m\.toml:5: job 'a': printer 'bureau' does not take STL"):
        load_manifest(manifest)


def test_an_export_with_no_format_the_printer_takes_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _design_folder(tmp_path, "mimaki_3duj553")  # its profile lists no GLB
    out = tmp_path / "p"
    assert main(["export", str(folder), "-o", str(out), "--formats", "glb", "--allow-format", *QUICK]) == 2
    assert "the print set would be empty" in capsys.readouterr().err
    assert not out.exists()


def test_the_trial_verify_exports_a_format_the_printer_takes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import saucerfab.fabricate.pipeline as fab
    from saucerfab.errors import ExportError
    from saucerfab.workflow import verify_design

    asked: list[object] = []

    def stop(*args: object, formats: object = None, **kwargs: object) -> None:
        asked.append(formats)
        raise ExportError("stopped by the test")

    monkeypatch.setattr(fab, "export_design", stop)
    profiles = tmp_path / "profiles"
    profiles.mkdir()
    text = (Path(__file__).resolve().parents[2] / "printers" / "j55.toml").read_text()
    # a profile's key is its file's stem
    (profiles / "no_obj.toml").write_text(text.replace('accepted_formats = ["3mf", "obj", "wrl", "ply", "stl", "glb"]',
                                                       'accepted_formats = ["3mf", "wrl"]'))
    monkeypatch.setenv("SAUCERFAB_PRINTERS", str(profiles))
    from saucerfab.model.design_folder import save_design, synthetic_design

    design = save_design(synthetic_design(resolution=12, texture_size=32), tmp_path / "design")
    for printer, fmt in (("j55", "obj"), ("no_obj", "3mf")):
        with pytest.raises(ExportError, match="stopped by the test"):
            verify_design(design, printer=printer)
        assert asked.pop() == [fmt]


def test_check_globs_that_match_folders_check_their_meshes_and_skip_a_zip_of_pictures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import zipfile

    folder = _design_folder(tmp_path, "j55")
    for name in ("a", "b"):
        assert main(["export", str(folder), "-o", str(tmp_path / "prints" / name), "--no-check", *QUICK]) == 0
    with zipfile.ZipFile(tmp_path / "prints" / "a" / "pictures.zip", "w") as zf:
        zf.writestr("one.png", b"not a mesh")
    capsys.readouterr()
    assert main(["check", str(tmp_path / "prints" / "*"), "--json"]) == 0
    names = [Path(f["path"]).relative_to(tmp_path / "prints").as_posix()
             for f in json.loads(capsys.readouterr().out)["files"]]
    assert names == ["a/saucer.3mf", "b/saucer.3mf"]


def test_export_looks_a_recorded_printer_up_among_the_profiles_never_as_a_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = synthetic_design(resolution=16, texture_size=32, seed=2)
    d = replace(d, parameters={**d.parameters, "printer": "../elsewhere/mine.toml",
                               "print_target": {"printer": "mine"}})
    folder = save_design(d, tmp_path / "design")
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--no-check", *QUICK]) == 2
    err = capsys.readouterr().err
    assert "made for printer 'mine', which is not among this installation's profiles" in err, err


def test_a_design_json_whose_parameters_are_not_an_object_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _design_folder(tmp_path, "j55")
    meta = json.loads((folder / "design.json").read_text())
    meta["parameters"] = None
    (folder / "design.json").write_text(json.dumps(meta))
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--no-check", *QUICK]) == 2
    err = capsys.readouterr().err
    assert "'parameters' must be a JSON object" in err and "Traceback" not in err, err


def test_verify_renders_from_the_eyes_the_design_was_made_for(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import saucerfab.verify.core as core
    from saucerfab.model.design import Intent
    from saucerfab.model.eyes import parse_eyes

    def eyes_made_for(parameters):  # noqa: ANN001, ANN202
        return Intent.of(parameters).eyes
    from saucerfab.verify.printfolder import design_parameters

    assert eyes_made_for({"eyes": "box:40,20,2"}) == parse_eyes("box:40,20,2")
    assert eyes_made_for({"eyes": "both", "ipd_mm": 60.0}) == parse_eyes("both", 60.0)
    assert eyes_made_for({}) is None and eyes_made_for(None) is None and eyes_made_for({"eyes": "sideways"}) is None
    d = synthetic_design(resolution=16, texture_size=32, seed=2)
    d = replace(d, parameters={**d.parameters, "eyes": "box:40,20,2"},
                references={v: d.texture for v in ("direct", "reflected")})
    folder = save_design(d, tmp_path / "design")
    assert main(["export", str(folder), "-o", str(tmp_path / "p"), "--formats", "obj", "--no-check", *QUICK]) == 0
    assert design_parameters(tmp_path / "p")["eyes"] == "box:40,20,2"
    seen = []

    def stop(spec, *args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(spec)
        raise KeyboardInterrupt

    monkeypatch.setattr(core, "eye_positions", stop)
    for eyes, expected in ((None, parse_eyes("box:40,20,2")), (parse_eyes("design"), parse_eyes("design"))):
        with pytest.raises(KeyboardInterrupt):
            core.verify_print(tmp_path / "p", eyes=eyes)
        assert seen.pop() == expected


def test_verify_refuses_ipd_without_both(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "print").mkdir()
    assert main(["verify", str(tmp_path / "print"), "--ipd-mm", "60"]) == 2
    assert "give it with --eyes both" in capsys.readouterr().err
