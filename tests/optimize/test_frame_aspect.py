"""Frames that fit the picture: each picture's own aspect, recorded as the view's extent, through design and export."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from saucerfab.errors import ConfigError
from saucerfab.model.heightfield import base_shape
from saucerfab.model.scene import (
    ViewFrame,
    load_scene,
    paper_scene,
    scene_from_dict,
    scene_to_dict,
    scene_to_toml,
)
from saucerfab.optimize.framing import fit_frames, frame_area, frame_notes, largest_inscribed_rectangle


def test_the_largest_rectangle_of_an_aspect_in_a_wide_region() -> None:
    # points filling a 4 x 1 rectangle: the largest 2:1 rectangle is 2 x 1, the largest square 1 x 1
    gx, gy = np.meshgrid(np.linspace(-2, 2, 161), np.linspace(-0.5, 0.5, 41))
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
    centre, hw, hh = largest_inscribed_rectangle(xy, 2.0)
    assert hw / hh == pytest.approx(2.0)
    assert hh == pytest.approx(0.5, abs=0.05) and abs(centre[1]) < 0.05
    _, sw, sh = largest_inscribed_rectangle(xy, 1.0)
    assert sw == sh and sw == pytest.approx(0.5, abs=0.05)
    # a very wide one is limited by the region's width instead
    _, w8, h8 = largest_inscribed_rectangle(xy, 8.0)
    assert w8 == pytest.approx(2.0, abs=0.1) and h8 == pytest.approx(0.25, abs=0.02)


@pytest.fixture(scope="module")
def scene_and_base():
    sc = paper_scene()
    return replace(sc, saucer=replace(sc.saucer, resolution=48)), base_shape("waves", 48)


def test_a_wide_picture_gets_a_wide_frame_lying_on_the_saucer(scene_and_base) -> None:  # noqa: ANN001
    from saucerfab.model.camera import Camera

    scene, base = scene_and_base
    square = fit_frames(scene, base, "inscribed")
    wide = fit_frames(scene, base, "inscribed", aspects={"direct": 2.0, "reflected": 2.0})
    for name in ("direct", "reflected"):
        s, w = getattr(square, name), getattr(wide, name)
        assert s.extent == (1.0, 1.0)
        assert w.extent[0] == 1.0 and w.extent[1] == pytest.approx(0.5)
        # wider than the square picture, and not taller
        tw, ts = math.tan(math.radians(w.viewing_angle_deg)), math.tan(math.radians(s.viewing_angle_deg))
        assert tw > 1.1 * ts and tw * w.extent[1] <= ts * 1.01
    # the direct rectangle's corners lie on the saucer: rays through them hit the saucer's footprint
    cam = Camera.from_scene(wide, "direct")
    eye, d = np.asarray(cam.eye), cam.axes()
    t = cam.tan_angle
    for sx in (-1, 1):
        for sy in (-1, 1):
            ray = d[2] + sx * 0.98 * t * d[0] + sy * 0.98 * t * wide.direct.extent[1] * d[1]
            z = float(np.mean(base))
            p = eye + ray * (z - eye[2]) / ray[2]
            (x0, x1), (y0, y1) = scene.saucer.x_range, scene.saucer.y_range
            assert x0 <= p[0] <= x1 and y0 <= p[1] <= y1


def test_an_8_to_1_picture_is_fitted_whole_and_the_design_says_so(scene_and_base) -> None:  # noqa: ANN001
    scene, base = scene_and_base
    square = fit_frames(scene, base, "inscribed")
    long = fit_frames(scene, base, "inscribed", aspects={"direct": 1.0, "reflected": 8.0})
    assert long.reflected.extent[1] == pytest.approx(1 / 8)
    assert frame_area(long.reflected) < 0.5 * frame_area(square.reflected)
    notes = frame_notes(square, long, {"direct": 1.0, "reflected": 8.0})
    assert len(notes) == 1 and "reflected picture is 8.0:1" in notes[0] and "shown whole" in notes[0]


def test_a_view_extent_is_validated_and_round_trips(tmp_path: Path) -> None:
    for bad in ((0.5, 0.5), (1.0, 0.0), (1.2, 1.0), (1.0,)):
        with pytest.raises(ConfigError, match="extent"):
            ViewFrame((0.0, 0.0, 0.0), 3.0, 64, bad)
    scene = replace(paper_scene(), reflected=ViewFrame((0.0, 0.0, 0.1), 3.0, 64, (1.0, 0.5)))
    assert scene_from_dict(scene_to_dict(scene)) == scene
    path = tmp_path / "s.toml"
    path.write_text(scene_to_toml(scene))
    assert load_scene(path).reflected.extent == (1.0, 0.5)
    # an older scene without extents: square pictures
    d = scene_to_dict(scene)
    del d["reflected"]["extent"]
    assert scene_from_dict(d).reflected.extent == (1.0, 1.0)


def test_a_2_to_1_picture_keeps_its_aspect_through_design_and_export(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from PIL import Image

    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.samples import SAMPLES
    from saucerfab.workflow import run_design

    wide = np.full((40, 80, 3), 255, np.uint8)
    wide[10:30, 10:70] = (200, 30, 40)  # a red bar on white, 2:1
    Image.fromarray(wide).save(tmp_path / "wide.png")
    req = DesignRequest(direct=SAMPLES / "direct_heart.png", reflected=tmp_path / "wide.png", resolution=32,
                        image_size=64, max_iters=3, record_times=False)
    folder = run_design(req, tmp_path / "d", progress=lambda *a: None).folder
    meta = json.loads((folder / "design.json").read_text())
    assert meta["scene"]["reflected"]["extent"] == [1.0, 0.5]
    assert meta["scene"]["direct"]["extent"] == [1.0, 1.0]
    ref = np.asarray(Image.open(folder / "reference_reflected.png"))
    red = (ref[..., 0] > 150) & (ref[..., 1] < 100)
    rows, cols = np.flatnonzero(red.any(axis=1)), np.flatnonzero(red.any(axis=0))
    # the bar keeps its 3:1 shape, centred in the square reference (the picture's 2:1 band)
    assert (cols[-1] - cols[0] + 1) / (rows[-1] - rows[0] + 1) == pytest.approx(3.0, rel=0.1)
    res = export_design(folder, tmp_path / "p", printer="j55", cup_diameter_mm=80, formats=["obj"],
                        options=FabOptions(texture_px=256))
    views = json.loads((res.out / "scene.json").read_text())["views"]
    assert views["reflected"]["extent"] == [1.0, 0.5] and views["direct"]["extent"] == [1.0, 1.0]
    # verify scores the 2:1 picture's rectangle: half the square's rows, and the saucer fills it
    pytest.importorskip("mitsuba")
    from saucerfab.verify import EyeSpec, verify_print

    scores = {v.view: v for v in verify_print(res.out, eyes=EyeSpec("design"), res=48, spp=4,
                                              all_formats=False).files[0].views}
    assert scores["reflected"].pixels <= 0.5 * 48 * 48 < scores["direct"].pixels
    assert scores["reflected"].coverage > 0.9


def test_crop_of_an_empty_picture_or_with_a_mask_file_is_refused_before_any_work(tmp_path: Path) -> None:
    from PIL import Image

    from saucerfab.errors import SaucerfabError
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.samples import SAMPLES

    Image.fromarray(np.full((30, 60, 3), 240, np.uint8)).save(tmp_path / "blank.png")
    with pytest.raises(SaucerfabError, match="no content to crop to"):
        prepare(DesignRequest(SAMPLES / "direct_heart.png", tmp_path / "blank.png", fit="crop", resolution=16,
                              image_size=32))
    Image.fromarray(np.full((64, 64), 255, np.uint8)).save(tmp_path / "mask.png")
    with pytest.raises(ConfigError, match="--fit crop cuts the direct picture.*mask file"):
        prepare(DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", fit="crop",
                              direct_mask=tmp_path / "mask.png", resolution=16, image_size=32))


def test_e_visual_scores_only_the_pictures_rectangle() -> None:
    torch = pytest.importorskip("torch")
    from saucerfab.optimize.energies import e_visual
    from saucerfab.optimize.views import Rig

    scene = replace(paper_scene(), saucer=replace(paper_scene().saucer, resolution=12))
    scene = replace(scene, reflected=replace(scene.reflected, image_size=16, extent=(1.0, 0.5)),
                    direct=replace(scene.direct, image_size=16))
    rig = Rig(scene, base_shape("waves", 12))
    masks = rig.picture_masks()
    assert masks[0] is None  # the direct picture fills its square
    m = masks[1][..., 0].numpy()
    assert m.shape == (16, 16) and m[4:12].all() and not m[:4].any() and not m[12:].any()
    r = [torch.zeros(16, 16, 3), torch.zeros(16, 16, 3)]
    t = [torch.zeros(16, 16, 3), torch.zeros(16, 16, 3)]
    t[1][:4] = 1.0  # a difference in the padding band only: not scored
    assert float(e_visual(r, t, masks)) == 0.0
    t[1][8, 8] = 0.5  # inside the rectangle: scored
    assert float(e_visual(r, t, masks)) == pytest.approx(0.75)
    assert float(e_visual(r, t)) == pytest.approx(4 * 16 * 3 + 0.75)  # without masks: every pixel


def test_a_face_is_seen_in_a_frame_only_inside_its_pictures_rectangle() -> None:
    from saucerfab.optimize.views import ViewMeshes

    base = base_shape("waves", 24)
    scene = fit_frames(replace(paper_scene(), saucer=replace(paper_scene().saucer, resolution=24)), base, "inscribed")
    square = ViewMeshes(scene, base, image_size=64).visible_faces(base)
    half = replace(scene, direct=replace(scene.direct, extent=(1.0, 0.5)))
    banded = ViewMeshes(half, base, image_size=64).visible_faces(base)
    assert (banded["direct"] <= square["direct"]).all()  # a subset: the bands are the surround's
    assert 0.3 < banded["direct"].sum() / square["direct"].sum() < 0.7
    assert np.array_equal(banded["reflected"], square["reflected"])
