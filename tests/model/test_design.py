"""Tests of saucerfab.model.design: the design folder's round trip, atomic writes, bad folders."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from saucerfab.errors import DesignError
from saucerfab.model.cups import PrismCup
from saucerfab.model.design import Design, FaceView
from saucerfab.model.design_folder import SCHEMA, load_design, save_design, synthetic_design
from saucerfab.model.heightfield import triangulate
from saucerfab.model.scene import Scene


def assert_same(a: Design, b: Design) -> None:
    assert a.scene == b.scene
    np.testing.assert_array_equal(a.heights, b.heights)
    np.testing.assert_array_equal(a.base_heights, b.base_heights)
    np.testing.assert_array_equal(a.texture, b.texture)
    np.testing.assert_array_equal(a.face_uvs, b.face_uvs)
    np.testing.assert_array_equal(a.face_view, b.face_view)
    assert (a.parameters, a.metrics, a.inputs) == (b.parameters, b.metrics, b.inputs)


def test_synthetic_design_is_consistent() -> None:
    d = synthetic_design(resolution=12, texture_size=32, seed=3)
    d.validate()
    assert d.n == 12 and d.scene.saucer.resolution == 12
    np.testing.assert_array_equal(d.faces(), triangulate(12))
    assert d.vertices().shape == (144, 3)
    assert np.abs(d.heights - d.base_heights).max() <= d.scene.saucer.delta / 2
    assert (d.face_view == FaceView.DIRECT).all()
    assert ((d.face_uvs >= 0) & (d.face_uvs <= 1)).all()
    assert d.texture.shape == (32, 32, 3) and d.texture.dtype == np.uint8
    again = synthetic_design(resolution=12, texture_size=32, seed=3)
    np.testing.assert_array_equal(d.heights, again.heights)  # seeded


def test_save_load_round_trip(tmp_path: Path) -> None:
    d = synthetic_design(Scene(cup=PrismCup(6, 0.45, 30.0)), resolution=10, texture_size=16)
    d.metrics = {"stage": {"energy": 1.25}}
    d.inputs = {"direct": {"name": "a.png", "sha256": "0" * 64}}
    out = save_design(d, tmp_path / "design", previews={"direct.png": b"\x89PNG fake"})
    assert out == tmp_path / "design"
    back = load_design(out)
    assert_same(d, back)
    meta = json.loads((out / "design.json").read_text())
    assert meta["schema"] == SCHEMA
    # the recorded hashes are those of the files written
    for rel, digest in meta["file_sha256"].items():
        assert hashlib.sha256((out / rel).read_bytes()).hexdigest() == digest
    assert (out / "previews" / "direct.png").read_bytes() == b"\x89PNG fake"
    # overwriting an existing design replaces it whole
    d2 = synthetic_design(resolution=8, texture_size=16, seed=9)
    save_design(d2, out)
    assert_same(d2, load_design(out))
    assert not (out / "previews").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["design"]  # no temporaries left


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    d = synthetic_design(resolution=8, texture_size=16)
    target = tmp_path / "out"
    # a value that is not bytes fails in the middle of writing the folder
    with pytest.raises(TypeError):
        save_design(d, target, extra_files={"log.txt": "text, not bytes"})  # type: ignore[dict-item]
    assert list(tmp_path.iterdir()) == []
    # with an existing design in place, a failed write keeps the old one intact
    save_design(d, target)
    before = {p.relative_to(target): p.read_bytes() for p in target.rglob("*") if p.is_file()}
    with pytest.raises(TypeError):
        save_design(synthetic_design(resolution=8, seed=5), target, extra_files={"x": 1})  # type: ignore[dict-item]
    after = {p.relative_to(target): p.read_bytes() for p in target.rglob("*") if p.is_file()}
    assert before == after
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # an inconsistent design is refused before anything is written
    bad = synthetic_design(resolution=8)
    bad.face_view = bad.face_view[:-1]
    with pytest.raises(DesignError, match="face_view"):
        save_design(bad, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    return save_design(synthetic_design(resolution=8, texture_size=16), tmp_path / "d")


def test_missing_folder_and_files(tmp_path: Path, saved: Path) -> None:
    with pytest.raises(DesignError, match="not a design folder"):
        load_design(tmp_path / "nowhere")
    (saved / "face_uvs.npy").unlink()
    with pytest.raises(DesignError, match="lacks face_uvs.npy"):
        load_design(saved)


def _edit_json(folder: Path, fn) -> None:  # type: ignore[no-untyped-def]
    meta = json.loads((folder / "design.json").read_text())
    fn(meta)
    (folder / "design.json").write_text(json.dumps(meta))


@pytest.mark.parametrize(
    "corrupt, match",
    [
        (lambda f: (f / "design.json").write_text("{ not json"), "cannot read"),
        (lambda f: (f / "design.json").write_bytes(b"\xff\xfe{}"), "cannot read"),
        (lambda f: (f / "design.json").write_text("[1, 2]"), "schema None"),
        (lambda f: _edit_json(f, lambda m: m.update(schema="saucerfab.design/0")), "schema 'saucerfab.design/0'"),
        (lambda f: _edit_json(f, lambda m: m.pop("scene")), "scene"),
        (lambda f: _edit_json(f, lambda m: m["scene"].update(camera=[0, 0, 1])), "scene"),
        (lambda f: _edit_json(f, lambda m: m["scene"]["saucer"].update(resolution=9)), r"heights \(8, 8\) != \(9, 9\)"),
        (lambda f: (f / "heights.npy").write_bytes(b"garbage"), "cannot read"),
        (lambda f: np.save(f / "heights.npy", np.zeros((3, 3))), r"heights \(3, 3\)"),
        (lambda f: np.save(f / "heights.npy", np.full((8, 8), np.nan)), "NaN"),
        (lambda f: np.save(f / "heights.npy", np.array([["a"] * 8] * 8)), "heights"),
        (lambda f: np.save(f / "face_uvs.npy", np.zeros((10**6, 3, 2))), "larger than any design"),
        (lambda f: (f / "texture.png").write_bytes(b"\x89PNG\r\n\x1a\n broken"), "cannot read"),
    ],
)
def test_corrupt_design_raises_design_error(saved: Path, corrupt, match: str) -> None:  # type: ignore[no-untyped-def]
    corrupt(saved)
    with pytest.raises(DesignError, match=match):
        load_design(saved)


def test_the_intent_is_what_design_json_records_and_nothing_else() -> None:
    """Intent.of is the one reader of what a design was made for: keys only, a damaged value is None."""
    from saucerfab.model.design import Intent
    from saucerfab.model.eyes import parse_eyes

    scene = Scene()
    made = Intent.of({"printer": "hp_jf580", "eyes": "box:40,20,2", "print_target": {"printer_name": "HP"}}, scene)
    assert made.printer == "hp_jf580" and made.printer_name == "HP"
    assert made.eyes == parse_eyes("box:40,20,2")
    assert made.cup_diameter_mm == scene.cup_diameter_mm
    assert made.frames == {"direct": scene.direct, "reflected": scene.reflected}
    # a profile given as a .toml path is named by the key its print target records, never by the path
    assert Intent.of({"printer": "/tmp/my.toml", "print_target": {"printer": "mine"}}).printer == "mine"
    assert Intent.of({"printer": "../../etc/passwd"}).printer is None
    # the design eye alone, an unknown mode, no parameters at all: no eyes (verify's own default then)
    for params in ({"eyes": "design"}, {"eyes": "sideways"}, {}, None, [1, 2]):
        assert Intent.of(params).eyes is None
    both = Intent.of({"eyes": "both", "ipd_mm": 60.0}).eyes
    assert both is not None and both.ipd_mm == 60.0
    assert Intent.of({}).cup_diameter_mm is None and Intent.of({}).frames == {}


def test_a_design_carries_its_intent_its_folder_and_its_stages(tmp_path: Path) -> None:
    from saucerfab.model.design import StageRecord

    d = synthetic_design(resolution=12, texture_size=16)
    d.parameters.update({"printer": "j850"})
    d.metrics["stages"] = [{"name": "bw_sigma_large", "iterations": 7, "E_visual": 12.5, "E_deform": 0.25,
                            "conflict_fraction": 0.1, "stop_reason": "converged"},
                           {"name": "sparse", "iterations": 3, "E_visual": 11.0, "E_deform": 0.5,
                            "conflict_fraction": 0.05, "stop_reason": None, "seconds": 1.5}]
    assert d.folder is None
    loaded = load_design(save_design(d, tmp_path / "d"))
    assert loaded.folder == tmp_path / "d" and loaded.intent.printer == "j850"
    first, second = loaded.stage_records
    assert first == StageRecord("bw_sigma_large", 7, 12.5, 0.25, 0.1, "converged", None)
    assert second.seconds == 1.5 and second.stop_reason is None
    assert synthetic_design(resolution=12, texture_size=16).stage_records == ()
