"""Batch manifests: TOML and CSV parsing, defaults, validation, paths kept inside the folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from saucerfab.batch.manifest import load_manifest, parse_options_cell, resolve_inside
from saucerfab.errors import ConfigError

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "batch"


def _write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def _inputs(folder: Path) -> None:
    (folder / "img").mkdir()
    (folder / "img" / "a.png").write_bytes(b"a")
    (folder / "img" / "b.png").write_bytes(b"b")
    (folder / "d").mkdir()


def test_sample_manifests_toml_and_csv_agree() -> None:
    a = load_manifest(SAMPLES / "manifest.toml")
    b = load_manifest(SAMPLES / "manifest.csv")
    assert len(a.jobs) >= 6
    assert a.jobs == b.jobs
    kinds = {j.kind for j in a.jobs}
    assert kinds == {"design", "raw"}
    for j in a.jobs:
        for p in [j.design, *j.files.values()]:
            if p is not None:
                assert p.is_relative_to(SAMPLES.resolve()) and p.exists(), p


def test_defaults_merge_and_job_values_win(tmp_path: Path) -> None:
    _inputs(tmp_path)
    m = load_manifest(
        _write(
            tmp_path,
            "m.toml",
            """
[defaults]
printer = "j55"
cup_diameter_mm = 80
formats = ["3mf"]
design_options = { resolution = 16, image_size = 32 }
export_options = { texture_px = 256 }

[[job]]
id = "a"
design = "d"

[[job]]
id = "b"
direct = "img/a.png"
reflected = "img/b.png"
printer = "bureau"
formats = ["OBJ", ".glb", "obj"]
design_options = { image_size = 24, seed = 3 }
export_options = { obj_zip = true }
""",
        ),
    )
    a, b = m.jobs
    assert a.kind == "design" and a.design == (tmp_path / "d").resolve()
    assert a.design_options == {}  # a design folder inherits no design-run options
    assert a.printer == "j55" and a.formats == ("3mf",) and a.export_options == {"texture_px": 256}
    assert b.kind == "raw" and b.printer == "bureau"
    assert b.formats == ("obj", "glb")
    assert b.design_options == {"resolution": 16, "image_size": 24, "seed": 3}
    assert b.export_options == {"texture_px": 256, "obj_zip": True}
    assert b.shape == "waves" and b.scene == "wide"
    assert set(b.files) == {"direct", "reflected"}


@pytest.mark.parametrize(
    "value",
    ["../outside.png", "img/../../outside.png", "/etc/passwd", "sub/../../../x"],
)
def test_paths_may_not_leave_the_manifest_folder(tmp_path: Path, value: str) -> None:
    root = tmp_path / "m"
    root.mkdir()
    (tmp_path / "outside.png").write_bytes(b"x")
    with pytest.raises(ConfigError, match="absolute path|outside the manifest's folder"):
        resolve_inside(root, value, "job #1 direct")
    _write(
        root,
        "m.toml",
        f'[[job]]\nid = "x"\nprinter = "j55"\ncup_diameter_mm = 80\ndirect = "{value}"\nreflected = "b.png"\n',
    )
    with pytest.raises(ConfigError, match="nothing was run") as exc:
        load_manifest(root / "m.toml")
    assert value in str(exc.value)


def test_symlink_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    root = tmp_path / "m"
    root.mkdir()
    (tmp_path / "secret").mkdir()
    os.symlink(tmp_path / "secret", root / "link")
    with pytest.raises(ConfigError, match="outside the manifest's folder"):
        resolve_inside(root, "link/design", "job")
    # a link that stays inside is fine
    (root / "real").mkdir()
    os.symlink(root / "real", root / "inner")
    assert resolve_inside(root, "inner", "job") == (root / "real").resolve()


def test_every_problem_is_listed(tmp_path: Path) -> None:
    _inputs(tmp_path)
    text = """
[[job]]
id = "ok"
printer = "j55"
cup_diameter_mm = 80
design = "d"

[[job]]
id = "bad id!"
printer = "j55"
cup_diameter_mm = 80
design = "d"

[[job]]
id = "OK"
printer = "j55"
cup_diameter_mm = 80
design = "d"

[[job]]
id = "fmt"
printer = "j55"
cup_diameter_mm = 80
design = "d"
formats = ["dwg"]

[[job]]
id = "both"
printer = "j55"
cup_diameter_mm = 80
design = "d"
direct = "img/a.png"

[[job]]
id = "badcup"
printer = "j55"
cup_diameter_mm = -5
design = "d"

[[job]]
id = "typo"
printer = "j55"
cup_diameter_mm = 80
design = "d"
colour = "red"

[[job]]
id = "opt"
printer = "j55"
cup_diameter_mm = 80
direct = "img/a.png"
reflected = "img/b.png"
design_options = { max_iters = 0 }

[[job]]
id = "exp"
printer = "j55"
cup_diameter_mm = 80
design = "d"
export_options = { texture_px = 300 }

[[job]]
id = "shape"
printer = "j55"
cup_diameter_mm = 80
direct = "img/a.png"
reflected = "img/b.png"
shape = "pyramid"

[[job]]
id = "half"
printer = "j55"
cup_diameter_mm = 80
direct = "img/a.png"
"""
    with pytest.raises(ConfigError) as exc:
        load_manifest(_write(tmp_path, "m.toml", text))
    msg = str(exc.value)
    assert "10 problem(s)" in msg
    for part in (
        "'bad id!'",
        "used twice",
        "unknown format(s) ['dwg']",
        "not both",
        "'cup_diameter_mm' must be a positive number of millimetres, got -5",
        "unknown key(s) ['colour']",
        "max_iters must be at least 1",
        "texture_px must be a power of two",
        "unknown base shape 'pyramid'",
        "missing ['reflected']",
    ):
        assert part in msg, part


def test_csv_manifest(tmp_path: Path) -> None:
    _inputs(tmp_path)
    text = (
        "# a comment line\n"
        "id,design,direct,reflected,printer,cup_diameter_mm,formats,design_options,export_options\n"
        "one,d,,,j55,80,3mf;obj,,texture_px=256; obj_zip=true\n"
        "two,,img/a.png,img/b.png,bureau,75.5,obj glb,resolution=16; height_scale=0.5; ablation=\"full\",\n"
    )
    m = load_manifest(_write(tmp_path, "m.csv", text))
    one, two = m.jobs
    assert one.formats == ("3mf", "obj") and one.export_options == {"texture_px": 256, "obj_zip": True}
    assert two.cup_diameter_mm == 75.5 and two.formats == ("obj", "glb")
    assert two.design_options == {"resolution": 16, "height_scale": 0.5, "ablation": "full"}
    with pytest.raises(ConfigError, match="unknown column"):
        load_manifest(_write(tmp_path, "bad.csv", "id,design,colour\na,d,red\n"))


def test_formats_are_named_as_on_the_command_line(tmp_path: Path) -> None:
    """The names --formats takes (any case, a leading dot, the vrml alias) mean the same in a manifest."""
    _inputs(tmp_path)
    text = "id,design,printer,cup_diameter_mm,formats\none,d,j55,80,VRML;.3mf;wrl\n"
    (job,) = load_manifest(_write(tmp_path, "m.csv", text)).jobs
    assert job.formats == ("wrl", "3mf")
    with pytest.raises(ConfigError, match=r"unknown format\(s\) \['gltf'\]"):
        load_manifest(_write(tmp_path, "bad.csv", "id,design,printer,cup_diameter_mm,formats\none,d,j55,80,gltf\n"))  # checked, not written


def test_options_cell() -> None:
    assert parse_options_cell("a=1; b = 2.5 ;c=true; d=word", "w") == {"a": 1, "b": 2.5, "c": True, "d": "word"}
    with pytest.raises(ConfigError, match="not key=value"):
        parse_options_cell("resolution", "w")


def test_structural_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="use a .toml or .csv"):
        load_manifest(_write(tmp_path, "m.yaml", "x"))
    with pytest.raises(ConfigError, match="not found"):
        load_manifest(tmp_path / "none.toml")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_manifest(_write(tmp_path, "a.toml", "[[job]\n"))
    with pytest.raises(ConfigError, match="lists no jobs"):
        load_manifest(_write(tmp_path, "b.toml", "[defaults]\nprinter='j55'\n"))
    with pytest.raises(ConfigError, match="unknown top-level"):
        load_manifest(_write(tmp_path, "c.toml", "[jobs]\nid='x'\n"))
    with pytest.raises(ConfigError, match="cannot set 'id'"):
        load_manifest(_write(tmp_path, "d.toml", "[defaults]\nid='x'\n[[job]]\nprinter='j55'\n"))
