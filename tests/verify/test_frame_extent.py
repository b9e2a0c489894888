"""A view's picture rectangle (``scene.json`` ``views.<name>.extent``): verify scores it, not the whole square.

A picture keeps its aspect: it covers the centred rectangle ``|x_ndc| <= ex``,
``|y_ndc| <= ey`` of its square frame, the rest being its background. The
print here is :data:`test_verify_accuracy.SCENE`'s flat saucer with a photo
painted from the design eye; its direct frame (4.5 degrees) reaches past the
saucer's far edge (the saucer spans ``y_ndc`` -0.98 to 0.43 there), so the
square's top band sees no saucer and a [1, 0.5] rectangle is mostly saucer.

* a bad extent is exit 2 with a message naming the key and the rule;
* the frame scores (pixels, coverage, region, from every eye) are the
  rectangle's: from the design eye, exactly the square's region cut to the
  rectangle, and the coverage its share of the rectangle (the square's is
  lower: its top band is off the saucer);
* the whole view counts the square's padding as surround (both surrounds
  grow, the reflected picture's width share shrinks with its width);
* no extent, [1, 1], and [1 - 5e-7, 1] score alike.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_verify_accuracy import SCENE, _painted, _photo, _write_print_folder

from saucerfab.cli import main
from saucerfab.fabricate.scene_file import ViewSpec
from saucerfab.model.scene import FULL_EXTENT
from saucerfab.verify import EyeSpec, verify_print
from saucerfab.verify.printfolder import VerifyInputError, load_print_scene

RES = 48
#: the rectangles of the test: the direct picture twice as wide as high, the reflected one a quarter as wide as high
#: (the mirror shows the saucer in a narrow column of its frame: a half-wide rectangle would cut little of it)
DIRECT_EXTENT, REFLECTED_EXTENT = [1.0, 0.5], [0.25, 1.0]


def _with_extents(folder: Path, extents: dict[str, object]) -> Path:
    """``folder``'s scene.json with ``views.<name>.extent`` set as given (None: the key removed)."""
    path = folder / "scene.json"
    scene = json.loads(path.read_text())
    for name, extent in extents.items():
        if extent is None:
            scene["views"][name].pop("extent", None)
        else:
            scene["views"][name]["extent"] = extent
    path.write_text(json.dumps(scene))
    return folder


def _folder(root: Path, extents: dict[str, object]) -> Path:
    """The photo print (same files every time), its scene.json given ``extents``."""
    photo = _photo(96, 1)
    refs = {"direct": np.round(photo * 255).astype(np.uint8),
            "reflected": np.round(_photo(96, 2) * 255).astype(np.uint8)}
    folder = _write_print_folder(root, SCENE, _painted(SCENE, photo, 300), refs)
    return _with_extents(folder, extents)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    """verify of the square print (design eye) and of the rectangles (design eye and a viewer's two eyes)."""
    root = tmp_path_factory.mktemp("extent")
    square = verify_print(_folder(root / "square", {}), eyes=EyeSpec("design"), res=RES, spp=4, all_formats=False)
    rect_folder = _folder(root / "rect", {"direct": DIRECT_EXTENT, "reflected": REFLECTED_EXTENT})
    rect = verify_print(rect_folder, eyes=EyeSpec("both"), res=RES, spp=4, all_formats=False,
                        pictures_dir=root / "rect_pictures")
    return {"square": square, "rect": rect, "rect_folder": rect_folder, "pictures": root / "rect_pictures"}


# --------------------------------------------------------------------------- reading


@pytest.mark.parametrize(
    "extent, words",
    [
        ([1.0, 0.0], "(0, 1]"),  # an empty rectangle
        ([1.0, -0.5], "(0, 1]"),
        ([1.2, 1.0], "(0, 1]"),  # wider than the frame
        ([0.5, 0.5], "the larger 1"),  # a picture that fills neither side of its frame
        ([1.0], "list of 2 numbers"),
        ("wide", "list of 2 numbers"),
        ([1.0, "half"], "finite number"),
        (None, "list of 2 numbers"),  # present but null is not 'missing'
    ],
)
def test_a_bad_extent_is_a_clear_error(tmp_path, extent, words):
    folder = _folder(tmp_path / "print", {})
    scene = json.loads((folder / "scene.json").read_text())
    scene["views"]["reflected"]["extent"] = extent
    (folder / "scene.json").write_text(json.dumps(scene))
    with pytest.raises(VerifyInputError) as err:
        load_print_scene(folder)
    msg = str(err.value)
    assert "views.reflected.extent" in msg and words in msg and "re-export" in msg, msg


def test_a_bad_extent_is_exit_2_from_the_command_line(tmp_path, capsys):
    folder = _folder(tmp_path / "print", {"direct": [0.3, 0.6]})
    rc = main(["verify", str(folder), "--eyes", "design", "--res", "32", "--spp", "1", "-q"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "views.direct.extent" in err and "the larger 1" in err and "[0.3, 0.6]" in err
    assert not (folder / "verify").exists()  # nothing written


def test_the_extent_is_read_and_the_larger_side_is_the_frames_edge(tmp_path):
    folder = _folder(tmp_path / "print", {"direct": [1.0, 0.5], "reflected": [0.25, 1.0 - 5e-7]})
    views = load_print_scene(folder).views
    assert views["direct"].extent == (1.0, 0.5)
    assert views["reflected"].extent == (0.25, 1.0)  # a writer's rounding of 1 is the frame's edge
    _with_extents(folder, {"direct": None, "reflected": None})
    assert {v.extent for v in load_print_scene(folder).views.values()} == {FULL_EXTENT}


def test_the_picture_mask_holds_the_pixel_centres_inside_the_rectangle():
    view = ViewSpec("direct", (0.0, 1.0, 0.0), 5.0, (1.0, 0.5))
    m = view.picture_mask(8)
    # row centres y = 1 - (2i + 1) / 8: 0.875, 0.625, 0.375, 0.125, ...: rows 2..5 lie within 0.5
    assert m.shape == (8, 8) and m.all(axis=1).tolist() == [False, False, True, True, True, True, False, False]
    assert m.any(axis=0).all()
    assert ViewSpec("direct", (0.0, 1.0, 0.0), 5.0).picture_mask(7).all()
    narrow = ViewSpec("direct", (0.0, 1.0, 0.0), 5.0, (0.25, 1.0)).picture_mask(48)
    assert narrow.sum() == 12 * 48 and (narrow == narrow[:, ::-1]).all()  # 12 columns, centred


# --------------------------------------------------------------------------- the frames


def test_the_frames_score_the_pictures_rectangle(runs):
    square, rect = runs["square"], runs["rect"]
    for view, extent in (("direct", DIRECT_EXTENT), ("reflected", REFLECTED_EXTENT)):
        mask = ViewSpec(view, (0.0, 1.0, 0.0), 1.0, tuple(extent)).picture_mask(RES)  # type: ignore[arg-type]
        sq, re_ = square.score(view, "design"), rect.score(view, "design")
        region_sq = square.renders[("design", view + ":region")]
        region = rect.renders[("design", view + ":region")]
        # the same render: the region is the square's, cut to the rectangle, pixel for pixel
        assert (region == (region_sq & mask)).all(), view
        assert re_.pixels == int((region_sq & mask).sum()) < sq.pixels, (view, re_.pixels, sq.pixels)
        # coverage is a share of the rectangle's pixels (partly seen pixels at the saucer's edge count in part)
        assert abs(re_.coverage - region.sum() / mask.sum()) < 0.05, (view, re_.coverage)
        # from every eye, nothing outside the rectangle is compared (the flat print's comparison included)
        for eye in ("design", "left", "right"):
            assert not (rect.renders[(eye, view + ":region")] & ~mask).any(), (view, eye)
            assert rect.score(view, eye).pixels > 0, (view, eye)
    # the direct square's top band sees no saucer: its coverage is low, the rectangle's much higher
    d_sq, d_rect = square.score("direct", "design"), rect.score("direct", "design")
    assert d_sq.coverage < 0.75 and d_rect.coverage > d_sq.coverage + 0.15, (d_sq.coverage, d_rect.coverage)
    # the direct rectangle is half the square's rows, but the square's top band saw no saucer: 2/3 of its pixels
    assert 0.55 < d_rect.pixels / d_sq.pixels < 0.75, (d_rect.pixels, d_sq.pixels)
    # the reflected rectangle, a quarter of the columns, cuts the sides off the mirror's column of saucer
    r_sq, r_rect = square.score("reflected", "design"), rect.score("reflected", "design")
    assert r_rect.pixels < 0.8 * r_sq.pixels and r_rect.coverage > 2 * r_sq.coverage, (r_rect, r_sq)


def test_the_side_by_side_picture_is_cropped_to_the_rectangle(runs):
    from PIL import Image

    # panels are scaled to one height: a [1, 0.5] picture's panels are twice as wide as a square's
    # and a [0.25, 1] picture's a quarter as wide
    wide = Image.open(runs["pictures"] / "design_direct.png").size
    narrow = Image.open(runs["pictures"] / "design_reflected.png").size
    assert wide[1] == narrow[1] and wide[0] > 5 * narrow[0], (wide, narrow)


# --------------------------------------------------------------------------- the whole view


def test_the_whole_views_surrounds_take_in_the_padding(runs):
    sq, rect = runs["square"].whole_views[0], runs["rect"].whole_views[0]
    assert sq.eye == rect.eye == "design"
    assert rect.pixels == sq.pixels  # the same pixels see the part: only what counts as framed changes
    (d_sq, m_sq), (d_rect, m_rect) = sq.surround_pixels, rect.surround_pixels
    # the direct square reaches the saucer's near edge: its surround is a thin margin; the rectangle
    # leaves the band below y_ndc = -0.5 (a third of the saucer's depth in the frame) to the surround
    assert d_rect > d_sq + 30 and d_rect > 3 * d_sq, (d_sq, d_rect)
    assert m_rect > m_sq, (m_sq, m_rect)
    # the reflected picture is narrower, and so is its share of the cup's width (a few whole-view pixels at 48 px:
    # 0.35 -> 0.23 measured)
    assert rect.width_share < 0.8 * sq.width_share, (sq.width_share, rect.width_share)


# --------------------------------------------------------------------------- older prints


def test_no_extent_scores_as_the_whole_square(tmp_path, runs):
    square = runs["square"]
    for extent in ([1.0, 1.0], [1.0 - 5e-7, 1.0]):
        folder = _folder(tmp_path / f"e{extent[0]}", {"direct": extent, "reflected": extent})
        assert {v.extent for v in load_print_scene(folder).views.values()} == {FULL_EXTENT}
        full = verify_print(folder, eyes=EyeSpec("design"), res=RES, spp=4, all_formats=False)
        for a, b in zip(square.files[0].views, full.files[0].views, strict=True):
            assert (a.view, a.pixels) == (b.view, b.pixels)
            np.testing.assert_array_equal([a.psnr_db, a.ssim, a.coverage], [b.psnr_db, b.ssim, b.coverage])
        w0, w1 = square.whole_views[0], full.whole_views[0]
        assert tuple(w0.surround_pixels) == tuple(w1.surround_pixels)
        # NaN (an empty surround) equals NaN here
        np.testing.assert_array_equal([w0.psnr_db, w0.stray_direct, w0.stray_reflected, w0.width_share],
                                      [w1.psnr_db, w1.stray_direct, w1.stray_reflected, w1.width_share])
