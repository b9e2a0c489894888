"""scene.json read back (saucerfab.fabricate.scene_file): the writer's values, and clear errors for bad files.

A small synthetic design (8 x 8 grid, no seat) is made a solid for each cup
kind; ``scene_json_bytes`` writes its scene.json, ``read_scene_file`` must
give back the very numbers written (camera, views with their extents, cup,
footprint, scale, GLB matrix). A design's viewing dict (no solid) goes
through the same parse without a footprint. Broken files (too large, not
JSON, bad numbers, missing keys) raise ``SceneFileError`` naming the field
and the fix, and verify reports them with the same message.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from saucerfab.errors import InputFileError, SceneFileError
from saucerfab.fabricate.export_glb import Z_UP_TO_Y_UP
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.scene_file import (
    MAX_SCENE_JSON_BYTES,
    PrintScene,
    read_scene_file,
    scene_from_dict,
)
from saucerfab.fabricate.scene_json import scene_dict, scene_json_bytes, viewing_dict
from saucerfab.fabricate.solid import build_solid
from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.scene import FULL_EXTENT, Scene, ViewFrame

#: the cups of the round trip; the prism has a second reflected view with a 2:1 picture
CUPS = {
    "circle": Scene(cup=CircleCup(), cup_diameter_mm=90.0),
    "ellipse": Scene(cup=EllipseCup((0.45, 0.35), 20.0), cup_diameter_mm=90.0),
    "prism": replace(
        Scene(cup=PrismCup(6, 0.45, 10.0), cup_diameter_mm=90.0),
        reflected2=ViewFrame((0.05, 0.0, 0.12), 2.5, 256, (1.0, 0.5)),
    ),
}


def _write(scene: Scene, folder: Path) -> tuple[Path, dict[str, Any]]:
    """scene.json of ``scene``'s synthetic design written into ``folder``; returns its path and scene_dict."""
    solid = build_solid(synthetic_design(scene, resolution=8, texture_size=16), scene.mm_per_unit,
                        FabOptions(seat="none"))
    path = folder / "scene.json"
    path.write_bytes(scene_json_bytes(scene, solid))
    return path, scene_dict(scene, solid)


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The circle design's scene.json and its dict (a file to break in the error tests)."""
    return _write(CUPS["circle"], tmp_path_factory.mktemp("scene"))


def _same_viewing(back: PrintScene, d: dict[str, Any]) -> None:
    """``back`` holds exactly the viewing numbers of ``d`` (camera, views, cup, scale)."""
    assert back.camera == tuple(d["camera"]["position"])
    assert list(back.views) == list(d["views"])  # direct, reflected[, reflected2], in that order
    for name, v in d["views"].items():
        got = back.views[name]
        assert got.name == name
        assert got.target == tuple(v["target"])
        assert got.viewing_angle_deg == v["viewing_angle_deg"]
        assert got.extent == tuple(v["extent"])
    c = d["cup"]
    assert back.cup.shape == c["shape"]
    assert back.cup.center == tuple(c["center"])
    assert back.cup.bottom_z == c["bottom_z"] and back.cup.height == c["height"]
    assert back.cup.outline.height == c["height"]
    fields = {k: v for k, v in c.items() if k not in ("shape", "center", "bottom_z", "height")}
    assert back.cup.outline.file_fields(lambda length: length) == fields  # lengths already mm: the very numbers
    assert back.mm_per_unit == d["mm_per_unit"]


@pytest.mark.parametrize("kind", list(CUPS))
def test_a_written_scene_json_reads_back_to_the_same_values(tmp_path: Path, kind: str) -> None:
    scene = CUPS[kind]
    path, d = _write(scene, tmp_path)
    back = read_scene_file(path)
    _same_viewing(back, d)
    assert back.saucer_x == tuple(d["saucer"]["x_range"]) and back.saucer_y == tuple(d["saucer"]["y_range"])
    np.testing.assert_array_equal(back.glb_matrix, np.array(Z_UP_TO_Y_UP, np.float64).reshape(4, 4).T)
    assert back.cup.width_mm == pytest.approx(scene.cup_diameter_mm)
    assert dict(back.source) == json.loads(path.read_text(encoding="utf-8"))  # every key kept, as read
    if kind == "prism":
        assert back.views["reflected2"].extent == (1.0, 0.5)
        assert back.views["direct"].extent == FULL_EXTENT


@pytest.mark.parametrize("kind", list(CUPS))
def test_a_designs_viewing_dict_goes_through_the_same_parse_without_a_footprint(kind: str) -> None:
    scene = CUPS[kind]
    s = scene.mm_per_unit
    d = viewing_dict(scene, np.diag([s, s, s, 1.0]))
    back = scene_from_dict(d, "the design's viewing geometry", footprint=False)
    _same_viewing(back, d)
    assert back.saucer_x is None and back.saucer_y is None
    np.testing.assert_array_equal(back.glb_matrix, np.eye(4))  # no GLB node: the identity
    # a print's scene.json must have its footprint
    with pytest.raises(SceneFileError, match="'saucer' is missing or not an object"):
        scene_from_dict(d, "x")


def _broken(written: tuple[Path, dict[str, Any]], tmp_path: Path, edit: Any) -> Path:
    """A copy of the written scene.json with ``edit`` applied to its dict."""
    d = json.loads(written[0].read_text(encoding="utf-8"))
    edit(d)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(d), encoding="utf-8")
    return path


def _error(path: Path) -> str:
    with pytest.raises(SceneFileError) as err:
        read_scene_file(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and msg.endswith(
        "; re-export the design with 'saucerfab export' to get a valid scene.json"), msg
    return msg


def test_an_oversize_file_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = tmp_path / "scene.json"
    path.write_bytes(b" " * (MAX_SCENE_JSON_BYTES + 1))
    assert f"over {MAX_SCENE_JSON_BYTES:,} bytes" in _error(path)


@pytest.mark.parametrize("data", [b"\xff\x00{", b"{'schema': 1}", b"[" * 100000 + b"]" * 100000])
def test_a_file_that_is_not_json_is_a_clear_error(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "scene.json"
    path.write_bytes(data)
    assert "not valid JSON" in _error(path)


def test_an_unreadable_path_is_a_clear_error(tmp_path: Path) -> None:
    (tmp_path / "scene.json").mkdir()
    assert "cannot be read" in _error(tmp_path / "scene.json")


def _set(keys: str, value: Any) -> Any:
    """An edit that sets the dotted ``keys`` of the dict to ``value``."""
    *parents, last = keys.split(".")

    def edit(d: dict[str, Any]) -> None:
        for k in parents:
            d = d[k]
        d[last] = value
    return edit


def _drop(keys: str) -> Any:
    """An edit that removes the dotted ``keys``."""
    *parents, last = keys.split(".")

    def edit(d: dict[str, Any]) -> None:
        for k in parents:
            d = d[k]
        del d[last]
    return edit


@pytest.mark.parametrize(
    "edit, words",
    [
        (_set("schema", "saucerfab.scene/0"), "schema is 'saucerfab.scene/0', expected 'saucerfab.scene/1'"),
        (_set("units", "inch"), "units are 'inch'"),
        (_set("camera.position", [1.0, "2", 3.0]), "camera.position must be a finite number"),
        (_set("camera.position", [1.0, 2.0, True]), "camera.position must be a finite number"),
        (_set("camera.position", [1.0, 2.0, 1e8]), "(|x| <= 1e+07)"),
        (_set("camera.position", [1.0, 2.0]), "camera.position must be a list of 3 numbers"),
        (_set("views.direct.viewing_angle_deg", -3.0), "views.direct.viewing_angle_deg must be positive"),
        (_set("views.direct.viewing_angle_deg", 89.0), "is not below 89 degrees"),
        (_set("views.reflected.target", None), "views.reflected.target must be a list of 3 numbers"),
        (_set("views.reflected.extent", [0.5, 0.5]), "the larger 1"),
        (_set("cup.shape", "cone"), "cup.shape is 'cone'; known: circle, ellipse, prism"),
        (_set("cup.height", 0), "cup.height must be positive"),
        (_set("cup.radius", float("inf")), "cup.radius must be a finite number"),
        (_set("cup.radius", -5.0), "cup: "),  # the shape's own check
        (_set("saucer.x_range", [10.0, 0.0]), "min < max"),
        (_set("mm_per_unit", 0.0), "mm_per_unit must be positive"),
        (_set("glb.node_matrix_column_major", [0.0] * 16), "singular"),
    ],
)
def test_a_bad_number_is_a_clear_error(written: tuple[Path, dict[str, Any]], tmp_path: Path, edit: Any,
                                       words: str) -> None:
    assert words in _error(_broken(written, tmp_path, edit))


@pytest.mark.parametrize(
    "edit, words",
    [
        (_drop("camera"), "'camera' is missing or not an object"),
        (_drop("views"), "'views' is missing or not an object"),
        (_drop("views.direct"), "views.direct is missing"),
        (_drop("views.reflected"), "views.reflected is missing"),
        (_drop("views.direct.viewing_angle_deg"), "views.direct.viewing_angle_deg must be a finite number"),
        (_drop("cup"), "'cup' is missing or not an object"),
        (_drop("cup.center"), "cup.center must be a list of 2 numbers"),
        (_drop("saucer"), "'saucer' is missing or not an object"),
        (_drop("mm_per_unit"), "mm_per_unit must be a finite number"),
    ],
)
def test_a_missing_key_is_a_clear_error(written: tuple[Path, dict[str, Any]], tmp_path: Path, edit: Any,
                                        words: str) -> None:
    assert words in _error(_broken(written, tmp_path, edit))


def test_optional_keys_take_their_defaults(written: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    def old_file(d: dict[str, Any]) -> None:  # a file from before extents and without the GLB block
        for v in d["views"].values():
            del v["extent"]
        del d["glb"]

    back = read_scene_file(_broken(written, tmp_path, old_file))
    assert {v.extent for v in back.views.values()} == {FULL_EXTENT}
    np.testing.assert_array_equal(back.glb_matrix, np.eye(4))


def test_the_error_is_an_input_file_error_and_verify_says_the_same(
    written: tuple[Path, dict[str, Any]], tmp_path: Path,
) -> None:
    from saucerfab.verify.printfolder import VerifyInputError, load_print_scene

    path = _broken(written, tmp_path, _set("cup.shape", "cone"))
    msg = _error(path)
    assert issubclass(SceneFileError, InputFileError) and SceneFileError.exit_code == 2
    with pytest.raises(VerifyInputError) as err:
        load_print_scene(tmp_path)
    assert str(err.value) == msg
