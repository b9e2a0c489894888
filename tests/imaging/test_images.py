"""Tests of saucerfab.imaging.images and saucerfab.imaging.masks: loading every mode, limits, fitting, masks, samples."""

from __future__ import annotations

import importlib.util
import struct
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageCms

from saucerfab.errors import ConfigError, ImageError
from saucerfab.imaging.fitting import fit_box, fit_square
from saucerfab.imaging.images import (
    LoadedImage,
    ViewImage,
    estimate_background,
    flatten_alpha,
    load_image,
    parse_colour,
)
from saucerfab.imaging.masks import foreground_mask, otsu_threshold, prepare_image, threshold_mask

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


# --------------------------------------------------------------------------- helpers


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def raw_png(width: int, height: int, bit_depth: int, colour_type: int, rows: bytes, extra: bytes = b"") -> bytes:
    """A PNG written by hand (for what Pillow will not write: 16-bit RGB, bomb headers)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + _chunk(b"IHDR", ihdr)
        + extra
        + _chunk(b"IDAT", zlib.compress(rows))
        + _chunk(b"IEND", b"")
    )


def rows_of(arr: np.ndarray) -> bytes:
    """Filter-0 PNG scanlines of a big-endian (H, W[, C]) array."""
    return b"".join(b"\x00" + row.tobytes() for row in arr)


def rgb_test_array(h: int = 12, w: int = 20) -> np.ndarray:
    rng = np.random.default_rng(1)
    return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)


def disc(h: int, w: int, cy: float, cx: float, r: float) -> np.ndarray:
    yy, xx = np.mgrid[:h, :w]
    return (yy - cy) ** 2 + (xx - cx) ** 2 < r * r


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def loaded(rgb: np.ndarray, alpha: np.ndarray | None = None, path: str = "mem.png") -> LoadedImage:
    return LoadedImage(rgb=rgb.astype(np.float32), alpha=alpha, path=path, format="PNG", mode="RGB", bit_depth=8)


def icc_rgb_profile(red_xyz, green_xyz, blue_xyz, gamma: float = 2.2) -> bytes:
    """A minimal ICC v2 matrix/TRC RGB display profile (for the ICC conversion test)."""

    def s15(v: float) -> bytes:
        return struct.pack(">i", int(round(v * 65536)))

    def xyz(v) -> bytes:
        return b"XYZ \x00\x00\x00\x00" + b"".join(s15(c) for c in v)

    text = b"swapped red green\x00"
    desc = b"desc\x00\x00\x00\x00" + struct.pack(">I", len(text)) + text + b"\x00" * 8 + b"\x00\x00\x00" + b"\x00" * 67
    curv = b"curv\x00\x00\x00\x00" + struct.pack(">IH", 1, int(round(gamma * 256))) + b"\x00\x00"
    tags = [
        (b"desc", desc),
        (b"wtpt", xyz((0.9642, 1.0, 0.8249))),
        (b"rXYZ", xyz(red_xyz)),
        (b"gXYZ", xyz(green_xyz)),
        (b"bXYZ", xyz(blue_xyz)),
        (b"rTRC", curv),
        (b"gTRC", curv),
        (b"bTRC", curv),
    ]
    table_len = 4 + 12 * len(tags)
    offset = 128 + table_len
    table, body = struct.pack(">I", len(tags)), b""
    for sig, data in tags:
        data += b"\x00" * (-len(data) % 4)
        table += sig + struct.pack(">II", offset + len(body), len(data))
        body += data
    size = 128 + table_len + len(body)
    header = (
        struct.pack(">I", size)
        + b"\x00" * 4
        + struct.pack(">I", 0x02100000)
        + b"mntrRGB XYZ "
        + b"\x00" * 12
        + b"acsp"
        + b"\x00" * 24
        + b"\x00" * 4
        + s15(0.9642) + s15(1.0) + s15(0.8249)
        + b"\x00" * 4
        + b"\x00" * 16
        + b"\x00" * 28
    )
    assert len(header) == 128
    return header + table + body


# --------------------------------------------------------------------------- loading: modes


def test_rgb_png_exact(tmp_path):
    a = rgb_test_array()
    Image.fromarray(a).save(tmp_path / "a.png")
    im = load_image(tmp_path / "a.png")
    assert im.rgb.shape == (12, 20, 3) and im.rgb.dtype == np.float32
    assert im.alpha is None and im.format == "PNG" and im.mode == "RGB" and im.bit_depth == 8
    np.testing.assert_array_equal(np.round(im.rgb * 255).astype(np.uint8), a)
    assert im.size == (20, 12)


def test_rgba_png_keeps_straight_alpha(tmp_path):
    a = rgb_test_array()
    alpha = np.tile(np.linspace(0, 255, 20).astype(np.uint8), (12, 1))
    Image.fromarray(np.dstack([a, alpha])).save(tmp_path / "a.png")
    im = load_image(tmp_path / "a.png")
    np.testing.assert_allclose(im.alpha, alpha / 255.0, atol=1e-6)
    opaque = alpha > 0  # PNG keeps the colour of every pixel with alpha > 0
    np.testing.assert_allclose(im.rgb[opaque], a[opaque] / 255.0, atol=1e-6)


@pytest.mark.parametrize("mode", ["L", "LA"])
def test_grey_modes_repeat_the_grey(tmp_path, mode):
    g = np.arange(60, dtype=np.uint8).reshape(6, 10) * 4
    img = Image.fromarray(g)
    if mode == "LA":
        img = Image.merge("LA", [img, Image.fromarray(np.full((6, 10), 100, np.uint8))])
    img.save(tmp_path / "g.png")
    im = load_image(tmp_path / "g.png")
    for c in range(3):
        np.testing.assert_allclose(im.rgb[..., c], g / 255.0, atol=1e-6)
    if mode == "LA":
        np.testing.assert_allclose(im.alpha, 100 / 255.0, atol=1e-6)
    else:
        assert im.alpha is None


def test_one_bit_png(tmp_path):
    b = np.zeros((8, 8), bool)
    b[2:5, 3:7] = True
    Image.fromarray(b).save(tmp_path / "b.png")
    im = load_image(tmp_path / "b.png")
    assert im.mode == "1" and im.bit_depth == 1
    np.testing.assert_array_equal(im.rgb[..., 0] > 0.5, b)
    assert set(np.unique(im.rgb)) <= {0.0, 1.0}


def test_palette_with_transparent_index(tmp_path):
    p = Image.new("P", (10, 6), 0)
    p.putpalette([255, 255, 255, 200, 30, 40, 10, 200, 90] + [0] * 759)
    px = np.zeros((6, 10), np.uint8)
    px[1:4, 2:5] = 1
    px[4:, 6:] = 2
    p.putdata(px.ravel().tolist())
    p.save(tmp_path / "p.png", transparency=0)
    im = load_image(tmp_path / "p.png")
    assert im.mode == "P"
    np.testing.assert_array_equal(im.alpha, (px != 0).astype(np.float32))
    np.testing.assert_allclose(im.rgb[2, 3], np.array([200, 30, 40]) / 255.0, atol=1e-6)
    np.testing.assert_allclose(im.rgb[5, 8], np.array([10, 200, 90]) / 255.0, atol=1e-6)


def test_palette_without_transparency_has_no_alpha(tmp_path):
    Image.fromarray(rgb_test_array()).quantize(8).save(tmp_path / "p.png")
    im = load_image(tmp_path / "p.png")
    assert im.alpha is None and im.mode == "P"


def test_16bit_grey_keeps_16_bits(tmp_path):
    v = np.array([[0, 1000, 1001, 65535], [257, 30000, 40000, 12345]], np.uint16)
    Image.fromarray(v).save(tmp_path / "g16.png")
    im = load_image(tmp_path / "g16.png")
    assert im.mode == "I;16" and im.bit_depth == 16
    np.testing.assert_allclose(im.rgb[..., 1], v / 65535.0, atol=1e-7)
    # 1000 and 1001 differ by less than an 8-bit step: only 16-bit decoding tells them apart
    assert im.rgb[0, 2, 0] > im.rgb[0, 1, 0]


def test_16bit_grey_with_trns_transparency(tmp_path):
    v = np.array([[5, 7, 5], [9, 5, 11]], ">u2")
    data = raw_png(3, 2, 16, 0, rows_of(v), extra=_chunk(b"tRNS", struct.pack(">H", 5)))
    (tmp_path / "t.png").write_bytes(data)
    im = load_image(tmp_path / "t.png")
    np.testing.assert_array_equal(im.alpha, (v != 5).astype(np.float32))


def test_16bit_rgb_png_is_read_at_8_bits_with_a_note(tmp_path):
    v = np.zeros((2, 3, 3), ">u2")
    v[..., 0] = [[0, 30000, 65535], [1000, 2000, 60000]]
    v[..., 1] = 65535
    v[..., 2] = 12345
    (tmp_path / "c16.png").write_bytes(raw_png(3, 2, 16, 2, rows_of(v)))
    im = load_image(tmp_path / "c16.png")
    assert im.bit_depth == 16 and im.alpha is None
    np.testing.assert_allclose(im.rgb, v.astype(np.float64) / 65535.0, atol=1.0 / 255 + 1e-6)
    assert any("8 bits" in n for n in im.notes)


def test_jpeg_rgb(tmp_path):
    a = np.zeros((32, 48, 3), np.uint8)
    a[:, :24] = (200, 40, 30)
    a[:, 24:] = (20, 60, 220)
    Image.fromarray(a).save(tmp_path / "a.jpg", quality=95)
    im = load_image(tmp_path / "a.jpg")
    assert im.format == "JPEG" and im.alpha is None
    np.testing.assert_allclose(im.rgb[16, 5], a[16, 5] / 255.0, atol=0.04)
    np.testing.assert_allclose(im.rgb[16, 40], a[16, 40] / 255.0, atol=0.04)


def test_cmyk_jpeg(tmp_path):
    a = np.zeros((16, 32, 3), np.uint8)
    a[:, :16] = (230, 20, 20)
    a[:, 16:] = (250, 250, 250)
    Image.fromarray(a).convert("CMYK").save(tmp_path / "c.jpg", quality=95)
    im = load_image(tmp_path / "c.jpg")
    assert im.mode == "CMYK" and im.rgb.shape == (16, 32, 3)
    np.testing.assert_allclose(im.rgb[8, 4], a[8, 4] / 255.0, atol=0.06)
    np.testing.assert_allclose(im.rgb[8, 28], a[8, 28] / 255.0, atol=0.06)


def test_webp_lossless_with_alpha(tmp_path):
    a = rgb_test_array()
    alpha = np.full((12, 20), 255, np.uint8)
    alpha[:, :5] = 0
    Image.fromarray(np.dstack([a, alpha])).save(tmp_path / "a.webp", lossless=True, exact=True)
    im = load_image(tmp_path / "a.webp")
    assert im.format == "WEBP"
    np.testing.assert_array_equal(im.alpha, alpha / 255.0)
    np.testing.assert_allclose(im.rgb[:, 5:], a[:, 5:] / 255.0, atol=1e-6)


def test_fully_opaque_alpha_is_dropped_with_a_note(tmp_path):
    a = rgb_test_array()
    Image.fromarray(np.dstack([a, np.full((12, 20), 255, np.uint8)])).save(tmp_path / "o.png")
    im = load_image(tmp_path / "o.png")
    assert im.alpha is None and any("opaque" in n for n in im.notes)


@pytest.mark.parametrize("orientation,turn", [(3, 2), (6, -1), (8, 1)])
def test_exif_orientation_is_applied(tmp_path, orientation, turn):
    a = np.zeros((4, 6, 3), np.uint8)
    a[0, 0] = (255, 0, 0)  # a marker in the stored top-left corner
    a[3, 1] = (0, 255, 0)
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(a).save(tmp_path / "e.png", exif=exif)
    im = load_image(tmp_path / "e.png")
    # orientation 6 = "turn 90 degrees clockwise to display" = np.rot90(k=-1)
    expected = np.rot90(a, k=turn)
    np.testing.assert_array_equal(np.round(im.rgb * 255).astype(np.uint8), expected)
    assert any("EXIF orientation" in n for n in im.notes)


def test_animated_png_uses_first_frame_with_a_note(tmp_path):
    f1 = Image.new("RGB", (8, 8), (255, 0, 0))
    f2 = Image.new("RGB", (8, 8), (0, 0, 255))
    f1.save(tmp_path / "anim.png", save_all=True, append_images=[f2], duration=100)
    im = load_image(tmp_path / "anim.png")
    np.testing.assert_allclose(im.rgb[..., 0], 1.0)
    np.testing.assert_allclose(im.rgb[..., 2], 0.0)
    assert any("first frame" in n for n in im.notes)


def test_icc_profile_is_converted_to_srgb(tmp_path):
    # A profile whose "red" primary is sRGB's green and vice versa (D50 colorants):
    # a pure red pixel in that file is sRGB green.
    srgb_r, srgb_g, srgb_b = (0.4361, 0.2225, 0.0139), (0.3851, 0.7169, 0.0971), (0.1431, 0.0606, 0.7141)
    prof = icc_rgb_profile(srgb_g, srgb_r, srgb_b)
    a = np.zeros((4, 4, 3), np.uint8)
    a[..., 0] = 255
    Image.fromarray(a).save(tmp_path / "swap.png", icc_profile=prof)
    im = load_image(tmp_path / "swap.png")
    assert im.rgb[0, 0, 1] > 0.9 and im.rgb[0, 0, 0] < 0.15, im.rgb[0, 0]
    assert any("ICC" in n for n in im.notes)


def test_srgb_icc_profile_is_identity_and_bad_profile_is_ignored(tmp_path):
    a = rgb_test_array()
    srgb = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    Image.fromarray(a).save(tmp_path / "s.png", icc_profile=srgb)
    np.testing.assert_allclose(load_image(tmp_path / "s.png").rgb, a / 255.0, atol=1.01 / 255)
    Image.fromarray(a).save(tmp_path / "bad.png", icc_profile=b"not a profile" * 4)
    bad = load_image(tmp_path / "bad.png")
    np.testing.assert_allclose(bad.rgb, a / 255.0, atol=1e-6)
    assert any("ignored" in n for n in bad.notes)


# --------------------------------------------------------------------------- loading: refusals


def test_decompression_bomb_header_is_refused_before_decoding(tmp_path, monkeypatch):
    from PIL import ImageFile

    def no_decoding(self):  # type: ignore[no-untyped-def]
        raise AssertionError("pixels were decoded")

    monkeypatch.setattr(ImageFile.ImageFile, "load", no_decoding)
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(raw_png(100_000, 100_000, 8, 2, b"\x00" * 301))
    with pytest.raises(ImageError, match="bomb|pixels") as exc:
        load_image(bomb)
    assert "bomb.png" in str(exc.value)
    # under Pillow's own guard (even as saucerfab.model.heightfield lowers it) but
    # over ours: our limit, in our words
    big = tmp_path / "big.png"
    big.write_bytes(raw_png(3000, 3000, 8, 0, b"\x00" * 3001))
    with pytest.raises(ImageError, match=r"3000x3000 = 9,000,000 pixels; the limit is 1,000,000"):
        load_image(big, max_pixels=1_000_000)


def test_file_size_limit(tmp_path):
    p = tmp_path / "a.png"
    Image.fromarray(rgb_test_array(64, 64)).save(p)
    with pytest.raises(ImageError, match="bytes; the limit is 100"):
        load_image(p, max_bytes=100)


@pytest.mark.parametrize("suffix,fmt", [(".png", "PNG"), (".jpg", "JPEG"), (".webp", "WEBP")])
def test_truncated_file(tmp_path, suffix, fmt):
    full = tmp_path / f"full{suffix}"
    Image.fromarray(rgb_test_array(64, 64)).save(full, format=fmt)
    data = full.read_bytes()
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(ImageError, match="cut") as exc:
        load_image(cut)
    assert "truncated" in str(exc.value) or "damaged" in str(exc.value)


def test_not_an_image(tmp_path):
    t = tmp_path / "notes.png"
    t.write_text("this is text, not pixels")
    with pytest.raises(ImageError, match="notes.png.*not a PNG, JPEG or WebP"):
        load_image(t)
    g = tmp_path / "a.gif"
    Image.fromarray(rgb_test_array()).save(g)
    with pytest.raises(ImageError, match="GIF.*convert it to PNG"):
        load_image(g)


def test_missing_empty_and_directory(tmp_path):
    with pytest.raises(ImageError, match="not found"):
        load_image(tmp_path / "nope.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ImageError, match="empty"):
        load_image(tmp_path / "empty.png")
    with pytest.raises(ImageError, match="not a file"):
        load_image(tmp_path)


# --------------------------------------------------------------------------- fitting


def test_fit_box_rule():
    assert fit_box(200, 100, 64, 64) == (0, 16, 64, 32)
    # odd leftover: 30 x 100 -> 19 x 64 at column (64 - 19) // 2 = 22, 23 columns right
    assert fit_box(30, 100, 64, 64) == (22, 0, 19, 64)
    assert fit_box(50, 50, 64, 64) == (0, 0, 64, 64)
    assert fit_box(1, 1000, 16, 16) == (7, 0, 1, 16)  # never zero pixels wide


def test_fit_square_wide_image_is_centred_and_padded_with_its_background():
    img = np.zeros((100, 200, 3), np.float32)
    img[...] = (0.9, 0.8, 0.7)
    img[30:70, 80:120] = (0.1, 0.2, 0.3)
    rgb, alpha, fill = fit_square(img, 64)
    assert rgb.shape == (64, 64, 3) and alpha is None and fill.shape == (64, 64)
    assert fill[:16].all() and fill[48:].all() and not fill[16:48].any()
    np.testing.assert_allclose(rgb[fill], np.broadcast_to([0.9, 0.8, 0.7], (int(fill.sum()), 3)), atol=1e-6)
    # the dark square keeps its place: centre of the frame
    dark = rgb[..., 0] < 0.5
    rows, cols = np.nonzero(dark)
    assert abs(rows.mean() - 31.5) < 0.6 and abs(cols.mean() - 31.5) < 0.6


def test_fit_square_given_background_and_hex():
    img = np.full((10, 40, 3), 0.5, np.float32)
    rgb, _, fill = fit_square(img, 20, background="#ff0000")
    np.testing.assert_array_equal(rgb[fill], np.broadcast_to([1, 0, 0], (int(fill.sum()), 3)))
    rgb2, _, _ = fit_square(img, 20, background=(0.0, 0.25, 1.0))
    np.testing.assert_allclose(rgb2[0, 0], [0.0, 0.25, 1.0])


def test_fit_square_keeps_aspect_ratio():
    h, w = 90, 300
    d = disc(h, w, 45, 150, 40)
    img = np.where(d, 0.0, 1.0).astype(np.float32)  # (H, W) grey input
    rgb, _, _ = fit_square(img, 128)
    m = rgb[..., 0] < 0.5
    rows, cols = np.nonzero(m)
    height = rows.max() - rows.min() + 1
    width = cols.max() - cols.min() + 1
    assert abs(height - width) <= 1  # a disc stays a disc


def test_fit_square_downscaling_does_not_alias():
    # 1-pixel checkerboard: point sampling gives 0/1, an area-like filter grey
    cb = (np.indices((256, 256)).sum(axis=0) % 2).astype(np.float32)
    rgb, _, _ = fit_square(np.repeat(cb[..., None], 3, axis=2), 64)
    inner = rgb[4:-4, 4:-4, 0]
    assert abs(float(inner.mean()) - 0.5) < 0.02 and float(inner.std()) < 0.05


def test_fit_square_alpha_padding_is_transparent_and_edges_do_not_bleed():
    rgb = np.zeros((60, 120, 3), np.float32)
    rgb[...] = (0.0, 1.0, 0.0)  # garbage green under the transparency
    alpha = np.zeros((60, 120), np.float32)
    alpha[10:50, 30:90] = 1.0
    rgb[10:50, 30:90] = (1.0, 0.0, 0.0)
    out, a, fill = fit_square(loaded(rgb, alpha), 45)
    assert a is not None and (a[fill] == 0).all()
    visible = a > 0.05
    assert visible.any()
    assert float(out[visible][:, 1].max()) < 0.02  # no green fringe on the red subject


def test_fit_square_same_size_is_exact():
    a = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    rgb, alpha, fill = fit_square(a, 32)
    np.testing.assert_array_equal(rgb, a)
    assert alpha is None and not fill.any()


def test_estimate_background_is_robust_to_a_subject_on_the_border():
    img = np.full((100, 100, 3), 0.2, np.float32)
    img[:, :30] = 0.9  # the subject covers part of the left ring
    np.testing.assert_allclose(estimate_background(img), [0.2, 0.2, 0.2])
    # transparent ring: white
    np.testing.assert_allclose(estimate_background(img, np.zeros((100, 100), np.float32)), [1, 1, 1])


def test_parse_colour_and_flatten():
    np.testing.assert_allclose(parse_colour("#0080ff"), [0, 128 / 255, 1])
    for bad in ("#12345", "red", (0, 0), (0, 0, 2), (0, float("nan"), 0)):
        with pytest.raises(ConfigError):
            parse_colour(bad)
    rgb = np.zeros((2, 2, 3), np.float32)
    alpha = np.array([[0, 1], [0.5, 0.25]], np.float32)
    out = flatten_alpha(rgb, alpha, (1.0, 1.0, 1.0))
    np.testing.assert_allclose(out[..., 0], 1 - alpha)


# --------------------------------------------------------------------------- masks


def noisy_disc(h: int = 160, w: int = 160, sd: float = 0.08, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    d = disc(h, w, 70, 85, 38)
    img = np.where(d[..., None], [0.25, 0.35, 0.75], [0.92, 0.9, 0.85])
    img = np.clip(img + rng.normal(0, sd, img.shape), 0, 1).astype(np.float32)
    return img, d


def test_threshold_mask_noisy_disc():
    img, d = noisy_disc()
    m = foreground_mask(loaded(img), method="threshold")
    assert iou(m, d) > 0.95


def test_otsu_splits_two_modes():
    v = np.concatenate([np.full(100, 0.1), np.full(50, 0.8)])
    t = otsu_threshold(v)
    assert 0.1 <= t < 0.8
    assert ((v > t) == (v == 0.8)).all()


def test_threshold_mask_keeps_subjects_touching_the_border_and_drops_specks():
    img = np.ones((128, 128, 3), np.float32)
    img[:, :20] = 0.0  # a bar along the left edge
    img[60:63, 100:103] = 0.0  # a 3x3 speck: noise
    img[40:90, 50:90] = 0.1
    img[64:66, 69:71] = 1.0  # a 2x2 hole inside the block: noise
    m = threshold_mask(img)
    assert m[:, :20].all()
    assert not m[55:68, 95:108].any()
    assert m[41:89, 51:89].all()  # the block (its corners may round by a pixel)
    assert m[64:66, 69:71].all()  # the tiny hole is filled
    assert m[:, 22:48].sum() == 0  # the gap between bar and block stays background


def test_uniform_or_noise_only_image_has_no_foreground():
    rng = np.random.default_rng(3)
    flat = np.full((64, 64, 3), 0.7, np.float32)
    noise = np.clip(0.7 + rng.normal(0, 0.05, (64, 64, 3)), 0, 1).astype(np.float32)
    for img in (flat, noise):
        with pytest.raises(ImageError, match="no foreground.*mask file"):
            foreground_mask(loaded(img))


def test_alpha_mask_and_all_foreground_error():
    rgb = np.full((50, 50, 3), 0.5, np.float32)
    a = disc(50, 50, 25, 25, 15).astype(np.float32)
    m = foreground_mask(loaded(rgb, a))
    np.testing.assert_array_equal(m, a > 0.5)
    with pytest.raises(ImageError, match="no background"):
        foreground_mask(loaded(rgb, np.ones((50, 50), np.float32)), method="alpha")
    with pytest.raises(ImageError, match="no alpha"):
        foreground_mask(loaded(rgb), method="alpha")


def test_mask_file_is_resized_and_wins_over_alpha(tmp_path):
    rgb = np.full((80, 120, 3), 0.5, np.float32)
    alpha = np.ones((80, 120), np.float32)
    alpha[:, :10] = 0  # an alpha channel that says something else
    want = disc(80, 120, 40, 60, 25)
    small = disc(40, 60, 20, 30, 12.5)  # same proportions, half the size
    Image.fromarray((small * 255).astype(np.uint8)).save(tmp_path / "mask.png")
    m = foreground_mask(loaded(rgb, alpha), mask_path=tmp_path / "mask.png")
    assert iou(m, want) > 0.93
    # wrong proportions
    Image.fromarray(np.zeros((40, 40), np.uint8)).save(tmp_path / "square.png")
    with pytest.raises(ImageError, match="proportions"):
        foreground_mask(loaded(rgb), mask_path=tmp_path / "square.png")
    # an all-black mask file
    Image.fromarray(np.zeros((40, 60), np.uint8)).save(tmp_path / "black.png")
    with pytest.raises(ImageError, match="no foreground"):
        foreground_mask(loaded(rgb), mask_path=tmp_path / "black.png")
    with pytest.raises(ConfigError):
        foreground_mask(loaded(rgb), method="file")
    with pytest.raises(ConfigError):
        foreground_mask(loaded(rgb), method="magic")  # type: ignore[arg-type]


def test_prepare_image_non_square_mask_in_frame(tmp_path):
    img, d = noisy_disc(100, 200, sd=0.04)
    Image.fromarray((img * 255).astype(np.uint8)).save(tmp_path / "wide.png")
    Image.fromarray((d * 255).astype(np.uint8)).save(tmp_path / "wide_mask.png")
    v = prepare_image(tmp_path / "wide.png", 64, background="#000000")
    assert isinstance(v, ViewImage) and v.size == 64 and v.source_size == (200, 100)
    assert v.mask_source == "threshold" and not v.mask[v.fill].any()
    assert v.fill[:16].all() and v.fill[48:].all()
    # the black padding (far from the image's own background) is not foreground
    assert v.mask.sum() < 0.3 * (~v.fill).sum()
    v2 = prepare_image(tmp_path / "wide.png", 64, mask_path=tmp_path / "wide_mask.png")
    assert v2.mask_source == "file"
    assert iou(v.mask, v2.mask) > 0.85
    assert len(v.sha256) == 64
    # a mask file at the original size also fits a ViewImage through foreground_mask
    m3 = foreground_mask(v, mask_path=tmp_path / "wide_mask.png")
    np.testing.assert_array_equal(m3, v2.mask)


def test_view_image_flattened():
    rgb = np.zeros((4, 4, 3), np.float32)
    alpha = np.zeros((4, 4), np.float32)
    alpha[1:3, 1:3] = 1
    v = ViewImage(
        rgb=rgb, alpha=alpha, fill=np.zeros((4, 4), bool), mask=alpha > 0.5,
        background=np.array([1, 1, 1], np.float32), mask_source="alpha", path="x",
        sha256="0" * 64, source_size=(4, 4), format="PNG", mode="RGBA", bit_depth=8,
    )
    flat = v.flattened()
    assert flat[0, 0].tolist() == [1, 1, 1] and flat[1, 1].tolist() == [0, 0, 0]
    assert v.flattened("#0000ff")[0, 0].tolist() == [0, 0, 1]


# --------------------------------------------------------------------------- samples


def _make_samples_module():
    spec = importlib.util.spec_from_file_location("make_samples", SAMPLES / "make_samples.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules["make_samples"] = mod
    spec.loader.exec_module(mod)
    return mod


SAMPLE_FILES = {
    "direct_heart.png": ("threshold", "RGB"),
    "reflected_star.png": ("alpha", "RGBA"),
    "reflected2_moon.png": ("threshold", "RGB"),
    "tree_gray16.png": ("threshold", "I;16"),
    "fish_wide.jpg": ("threshold", "RGB"),
    "note_palette.png": ("alpha", "P"),
}


def test_committed_samples_match_the_generator(tmp_path):
    written = _make_samples_module().write_all(tmp_path)
    assert sorted(p.name for p in written) == sorted(SAMPLE_FILES)
    total = 0
    for p in written:
        committed = SAMPLES / p.name
        total += committed.stat().st_size
        with Image.open(committed) as a, Image.open(p) as b:
            assert a.mode == b.mode and a.size == b.size
            x, y = np.asarray(a).astype(np.int64), np.asarray(b).astype(np.int64)
        tol = 3 if p.suffix == ".jpg" else 0  # JPEG encoders may differ by a level or two
        assert np.abs(x - y).max() <= tol, p.name
    assert total < 400_000


@pytest.mark.parametrize("name", sorted(SAMPLE_FILES))
def test_samples_have_clear_subjects(name):
    source, mode = SAMPLE_FILES[name]
    v = prepare_image(SAMPLES / name, 128)
    assert v.mask_source == source and v.mode == mode
    frac = float(v.mask.mean())
    assert 0.08 < frac < 0.6, frac
    if name == "tree_gray16.png":
        assert v.bit_depth == 16
    if name == "fish_wide.jpg":
        assert v.fill.any() and v.source_size == (640, 400)


# --------------------------------------------------------------------------- fit rules (issue 14)


def test_crop_cuts_the_picture_to_its_content_and_pads_the_rest():
    from saucerfab.imaging.fitting import CONTENT_MARGIN, content_box, fit_box, fit_square

    assert fit_box(640, 400, 100, 100, "pad") == (0, 19, 100, 62)
    assert fit_box(640, 400, 100, 100, "crop") == fit_box(640, 400, 100, 100, "pad")  # cut first, then as pad
    # a word on a wide white canvas: crop keeps every letter and drops the empty canvas
    img = np.ones((60, 200, 3), np.float32)
    img[20:40, 50:150] = 0.0  # the "word": 100 x 20 px
    box = content_box(img, None, np.ones(3))
    m = int(np.ceil(CONTENT_MARGIN * 100))
    assert box == (50 - m, 20 - m, 150 + m, 40 + m)
    rgb, alpha, fill = fit_square(img, 52, fit="crop")
    assert alpha is None
    ink = rgb.mean(axis=-1) < 0.5
    cols, rows = np.flatnonzero(ink.any(axis=0)), np.flatnonzero(ink.any(axis=1))
    # the word spans the frame's width (its margin aside) and keeps its 5:1 shape
    assert cols[0] <= 2 and cols[-1] >= 49
    assert (cols[-1] - cols[0] + 1) / (rows[-1] - rows[0] + 1) == pytest.approx(5.0, rel=0.15)
    assert fill[:15].all() and fill[-15:].all()  # bands of the background above and below
    # nothing on the canvas: a clear error naming the fix
    with pytest.raises(Exception, match="no content to crop to.*--fit pad"):
        fit_square(np.ones((20, 30, 3), np.float32), 16, fit="crop")
    with pytest.raises(Exception, match="fit must be"):
        fit_box(10, 10, 5, 5, "stretch")


def test_design_fit_and_background_options(tmp_path):
    from saucerfab.errors import ConfigError
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest

    samples = Path(__file__).resolve().parents[2] / "samples"
    base = dict(resolution=16, image_size=64)
    pad = prepare(DesignRequest(samples / "fish_wide.jpg", samples / "reflected_star.png", **base))
    crop = prepare(DesignRequest(samples / "fish_wide.jpg", samples / "reflected_star.png", fit="direct=crop", **base))
    white = prepare(DesignRequest(samples / "fish_wide.jpg", samples / "reflected_star.png", background="#ffffff", **base))
    # the fish on its plain ground: crop cuts the empty margins, so the fish fills more of its frame
    assert crop.masks["direct"].sum() > 1.15 * pad.masks["direct"].sum()
    assert pad.scene.direct.extent == pytest.approx((1.0, 400 / 640))  # the whole 640 x 400 photograph
    assert crop.scene.direct.extent != pad.scene.direct.extent  # the frame takes the content's shape
    assert crop.masks["reflected"].sum() == pad.masks["reflected"].sum()  # the rule was for direct only
    assert np.allclose(white.render["direct"][0, 0], 1.0)
    # the star's transparent background shows the colour asked for
    assert np.allclose(white.render["reflected"][0, 0], 1.0)
    assert crop.render["reflected"].shape == pad.render["reflected"].shape
    for bad in ({"fit": "stretch"}, {"fit": "direct=zoom"}, {"fit": "left=crop"}, {"background": "blue"}):
        with pytest.raises(ConfigError):
            DesignRequest(samples / "fish_wide.jpg", samples / "reflected_star.png", **bad)
