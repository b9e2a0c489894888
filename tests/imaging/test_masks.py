"""Tests of saucerfab.imaging.masks: each source of a picture's subject mask, exactly, on tiny synthetic pictures.

``tests/imaging/test_images.py`` holds the masks of noisy photographs and the
samples within a tolerance (IoU); here pictures small and crisp enough for
the exact mask to be known: a mask file's luma and transparency, the alpha
channel's cut at one half, the threshold on a plain background (and what
``auto`` picks), the share of foreground allowed, the fitted frame of
:func:`prepare_image`, and :func:`plain_background_share`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from saucerfab.errors import ConfigError, ImageError, MaskError
from saucerfab.imaging.images import LoadedImage, ViewImage
from saucerfab.imaging.masks import (
    MASK_METHODS,
    MIN_FOREGROUND_FRACTION,
    foreground_mask,
    plain_background_share,
    prepare_image,
    threshold_mask,
)

GREY = np.full((8, 12, 3), 0.5, np.float32)


def loaded(rgb: np.ndarray, alpha: np.ndarray | None = None) -> LoadedImage:
    return LoadedImage(rgb=rgb.astype(np.float32), alpha=alpha, path="mem.png", format="PNG", mode="RGB", bit_depth=8)


def rectangle(h: int, w: int, rows: slice, cols: slice) -> np.ndarray:
    m = np.zeros((h, w), bool)
    m[rows, cols] = True
    return m


def columns(w: int, h: int, true_cols: slice) -> np.ndarray:
    return rectangle(h, w, slice(None), true_cols)


def test_a_mask_file_is_foreground_where_its_luma_is_over_half(tmp_path: Path) -> None:
    grey = np.zeros((8, 12), np.uint8)
    grey[:, 0:3], grey[:, 3:6], grey[:, 6:9] = 127, 128, 255  # 127/255 < 0.5 < 128/255
    Image.fromarray(grey).save(tmp_path / "grey.png")
    np.testing.assert_array_equal(foreground_mask(loaded(GREY), mask_path=tmp_path / "grey.png"),
                                  columns(12, 8, slice(3, 9)))
    # Rec. 601 luma: pure green (0.587) is white enough, pure red (0.299) and blue (0.114) are not
    colour = np.zeros((8, 12, 3), np.uint8)
    colour[:, 0:4], colour[:, 4:8], colour[:, 8:12] = (255, 0, 0), (0, 255, 0), (0, 0, 255)
    Image.fromarray(colour).save(tmp_path / "colour.png")
    np.testing.assert_array_equal(foreground_mask(loaded(GREY), mask_path=tmp_path / "colour.png"),
                                  columns(12, 8, slice(4, 8)))
    # white drawn on a transparent layer: only the opaque white is the subject
    rgba = np.full((8, 12, 4), 255, np.uint8)
    rgba[:, :6, 3] = 0
    Image.fromarray(rgba, "RGBA").save(tmp_path / "layer.png")
    np.testing.assert_array_equal(foreground_mask(loaded(GREY), mask_path=tmp_path / "layer.png"),
                                  columns(12, 8, slice(6, 12)))


def test_an_alpha_channel_is_cut_at_one_half() -> None:
    alpha = np.tile(np.array([0.0, 0.5, 0.51, 1.0], np.float32), (8, 3))  # (8, 12)
    want = alpha > 0.5
    assert want.sum() == 48  # half opaque, and 0.5 itself is background
    np.testing.assert_array_equal(foreground_mask(loaded(GREY, alpha)), want)  # auto: some transparency, so alpha
    np.testing.assert_array_equal(foreground_mask(loaded(GREY, alpha), method="alpha"), want)


@pytest.mark.parametrize("size", [(24, 24), (32, 48), (64, 40), (100, 80)])
@pytest.mark.parametrize("background", [(1.0, 1.0, 1.0), (0.9, 0.85, 0.7), (0.0, 0.0, 0.0)])
def test_the_threshold_finds_a_crisp_subject_on_a_plain_background_exactly(
    size: tuple[int, int], background: tuple[float, float, float]
) -> None:
    h, w = size
    # a subject of a ninth of the picture (a much larger one may lose its corner pixels to the smoothing)
    want = rectangle(h, w, slice(h // 4, h // 4 + h // 3), slice(w // 4, w // 4 + w // 3))
    img = np.empty((h, w, 3), np.float32)
    img[:] = background
    img[want] = (0.2, 0.4, 0.9) if background != (0.0, 0.0, 0.0) else (0.9, 0.6, 0.1)
    np.testing.assert_array_equal(threshold_mask(img), want)
    np.testing.assert_array_equal(foreground_mask(loaded(img)), want)  # auto: no alpha, so the threshold


def test_transparent_pixels_are_background_to_the_threshold() -> None:
    rng = np.random.default_rng(0)
    img = rng.uniform(0.0, 1.0, (32, 32, 3)).astype(np.float32)  # noise where transparent: must not count
    want = rectangle(32, 32, slice(8, 20), slice(10, 26))
    img[want] = (0.1, 0.1, 0.1)
    alpha = want.astype(np.float32)
    np.testing.assert_array_equal(foreground_mask(loaded(img, alpha), method="threshold"), want)


def test_auto_reads_only_the_transparency_of_the_content() -> None:
    """The padding of a fitted picture is transparent; that alone is no subject outline, so auto thresholds."""
    fill = np.zeros((32, 32), bool)
    fill[:8], fill[24:] = True, True
    rgb = np.ones((32, 32, 3), np.float32)
    rgb[fill] = 0.0  # padding colour, far from the background: must not become foreground either
    want = rectangle(32, 32, slice(12, 20), slice(8, 24))
    rgb[want] = (0.8, 0.1, 0.1)
    view = ViewImage(rgb=rgb, alpha=(~fill).astype(np.float32), fill=fill, mask=np.zeros((32, 32), bool),
                     background=np.zeros(3, np.float32), mask_source="alpha", path="mem.png", sha256="0" * 64,
                     source_size=(32, 16), format="PNG", mode="RGBA", bit_depth=8)
    np.testing.assert_array_equal(foreground_mask(view), want)


def test_a_mask_must_leave_some_of_each() -> None:
    """Under MIN_FOREGROUND_FRACTION of the content foreground (or background) is no subject."""
    n = 40 * 40
    assert 1 / n < MIN_FOREGROUND_FRACTION < 2 / n  # one pixel is too few, two are enough
    rgb = np.full((40, 40, 3), 0.5, np.float32)
    alpha = np.zeros((40, 40), np.float32)
    alpha[0, 0] = 1.0
    with pytest.raises(MaskError, match="has no foreground .*Give a mask file"):
        foreground_mask(loaded(rgb, alpha))
    alpha[0, 1] = 1.0
    assert foreground_mask(loaded(rgb, alpha)).sum() == 2
    opaque = np.ones((40, 40), np.float32)
    opaque[0, 0] = 0.0
    with pytest.raises(MaskError, match="has no background"):
        foreground_mask(loaded(rgb, opaque))
    opaque[0, 1] = 0.0
    assert foreground_mask(loaded(rgb, opaque)).sum() == n - 2
    assert issubclass(MaskError, ImageError)


def test_unknown_methods_name_the_choices() -> None:
    assert MASK_METHODS == ("auto", "alpha", "file", "threshold", "none")
    with pytest.raises(ConfigError, match="unknown mask method 'magic'; use auto, alpha, file, threshold or none"):
        foreground_mask(loaded(GREY), method="magic")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="mask method 'file' needs a mask file"):
        foreground_mask(loaded(GREY), method="file")
    assert not foreground_mask(loaded(GREY), method="none").any()  # no subject wanted: nothing refused


def test_prepare_image_masks_in_the_fitted_frame(tmp_path: Path) -> None:
    """A 16 x 8 picture in a 16 px frame: padded by 4 rows above and below, the subject moved down with it."""
    rgba = np.zeros((8, 16, 4), np.uint8)
    rgba[..., :3] = 200
    rgba[2:6, 4:12] = (20, 40, 200, 255)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "pic.png")
    want = rectangle(16, 16, slice(6, 10), slice(4, 12))
    for method, source in (("auto", "alpha"), ("alpha", "alpha"), ("threshold", "threshold")):
        v = prepare_image(tmp_path / "pic.png", 16, mask_method=method)  # type: ignore[arg-type]
        assert v.mask_source == source and v.size == 16 and v.source_size == (16, 8)
        np.testing.assert_array_equal(v.fill, rectangle(16, 16, slice(0, 4), slice(None))
                                      | rectangle(16, 16, slice(12, 16), slice(None)))
        np.testing.assert_array_equal(v.mask, want)
    mask_file = np.zeros((8, 16), np.uint8)
    mask_file[:, :8] = 255  # the left half, whatever the picture shows
    Image.fromarray(mask_file).save(tmp_path / "left.png")
    v = prepare_image(tmp_path / "pic.png", 16, mask_path=tmp_path / "left.png")
    assert v.mask_source == "file"
    np.testing.assert_array_equal(v.mask, rectangle(16, 16, slice(4, 12), slice(0, 8)))
    v = prepare_image(tmp_path / "pic.png", 16, mask_method="none")
    assert v.mask_source == "none" and not v.mask.any()


def test_plain_background_share_counts_the_background_near_its_colour() -> None:
    rgb = np.ones((4, 4, 3), np.float32)
    mask = rectangle(4, 4, slice(0, 2), slice(0, 2))  # 4 subject pixels, 12 background
    rgb[3, :3] = 0.0  # 3 background pixels far from white
    rgb[2, 3] = 0.95  # near enough (distance 0.087 < 0.12)
    view = ViewImage(rgb=rgb, alpha=None, fill=np.zeros((4, 4), bool), mask=mask,
                     background=np.ones(3, np.float32), mask_source="threshold", path="mem.png", sha256="0" * 64,
                     source_size=(4, 4), format="PNG", mode="RGB", bit_depth=8)
    assert plain_background_share(view) == 9 / 12
    everything = replace(view, mask=np.ones((4, 4), bool))
    assert plain_background_share(everything) == 0.0  # no background at all: nothing plain about it
