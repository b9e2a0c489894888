"""The fit rule: how a picture goes into its square view frame.

An image W x H goes into the S x S frame (row 0 at the top, as in
:mod:`saucerfab.model.camera`) scaled by ``S / max(W, H)``, so its long
side spans the frame exactly and its aspect ratio is kept; the scaled size
is ``round(W * S / max(W, H))`` x ``round(H * S / max(W, H))`` (at least 1).
It is centred: the left/top offset is ``(S - w) // 2`` (an odd leftover
pixel goes to the right/bottom). Resampling is Lanczos (Pillow's, which
widens the kernel when shrinking, so downscaling integrates over the source
pixels like an area filter); colours are resampled premultiplied by alpha so
transparent pixels' hidden colours never bleed into the edge. The padding is
filled with the background colour: the one given, or the per-channel median
of the image's outer ring 2 % of the short side wide (at least 1 pixel).
Images with alpha get transparent padding (alpha 0; colour = that background).

That is ``fit="pad"``, the default: the whole image is shown, and the
design's frame takes the image's aspect (:mod:`saucerfab.optimize.framing`:
the padding bands lie outside the picture's rectangle). ``fit="crop"``
(``saucerfab design --fit crop``) first cuts the image to its content
(:func:`crop_to_content`: the box of the pixels that differ from its
background, a small margin around), then does as ``pad``: a word on a wide
canvas keeps all its letters and loses the empty canvas. A mask file follows
its image's rule (``pad`` only: a mask file does not say where the content is).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from saucerfab.errors import ConfigError, ImageError
from saucerfab.imaging.images import LoadedImage, ViewImage, colour_hex, intended_background


def _resize_plane(plane: np.ndarray, width: int, height: int) -> np.ndarray:
    """Lanczos-resize one (H, W) float plane to (height, width), float32.

    Pillow's float ("F") resampling widens the kernel by the shrink factor,
    so a large reduction averages over every source pixel (no aliasing).
    """
    from PIL import Image

    if plane.shape == (height, width):
        return plane.astype(np.float32, copy=True)
    im = Image.fromarray(np.ascontiguousarray(plane, np.float32))  # float32 2-D: mode "F"
    return np.asarray(im.resize((width, height), Image.Resampling.LANCZOS), dtype=np.float32)


#: fit rules of an image into its frame: "pad" shows the whole image (its frame takes the image's
#: aspect; bands of the background colour fill the square view around it), "crop" first cuts the
#: image to its content (the box of what differs from its background), then does as "pad"
FITS = ("pad", "crop")
#: a pixel is content (for "crop") when its colour lies farther than this from the background
#: (largest channel difference, 0..1), or it is at least half opaque where the image has alpha
CONTENT_DISTANCE = 0.12
#: the content box is widened by this share of its larger side on every side (a letter's edge
#: is not cut at its last pixel; the blur of the optimizer's renders has room)
CONTENT_MARGIN = 0.02


def content_box(rgb: np.ndarray, alpha: np.ndarray | None, background: np.ndarray) -> tuple[int, int, int, int] | None:
    """The box ``(x0, y0, x1, y1)`` (end exclusive, pixels) of an image's content, widened by
    :data:`CONTENT_MARGIN` and clipped to the image; None when nothing is content.

    Content: pixels at least half opaque (with ``alpha``) whose colour lies farther than
    :data:`CONTENT_DISTANCE` from ``background`` (3,); without alpha the colour rule alone.
    """
    far = np.abs(np.asarray(rgb, np.float32) - np.asarray(background, np.float32).reshape(1, 1, 3)).max(axis=-1)
    content = far > CONTENT_DISTANCE
    if alpha is not None:
        content &= np.asarray(alpha) >= 0.5
    rows, cols = np.flatnonzero(content.any(axis=1)), np.flatnonzero(content.any(axis=0))
    if rows.size == 0:
        return None
    h, w = content.shape
    m = int(math.ceil(CONTENT_MARGIN * max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)))
    return max(0, cols[0] - m), max(0, rows[0] - m), min(w, cols[-1] + 1 + m), min(h, rows[-1] + 1 + m)


def crop_to_content(img: LoadedImage, background: Sequence[float] | str | None = None) -> LoadedImage:
    """``img`` cut to its :func:`content_box` (the "crop" fit rule's first step).

    Raises:
        ImageError: nothing in the image differs from its background (an empty picture).
    """
    from dataclasses import replace

    bg = intended_background(img.rgb, background, img.alpha)
    box = content_box(img.rgb, img.alpha, bg)
    if box is None:
        hexa = colour_hex(bg)
        raise ImageError(
            f"image {img.path!r} has no content to crop to: every pixel lies within {CONTENT_DISTANCE} of its "
            f"background colour {hexa}; give --fit pad, or a picture with something on it"
        )
    x0, y0, x1, y1 = box
    alpha = None if img.alpha is None else img.alpha[y0:y1, x0:x1]
    return replace(img, rgb=img.rgb[y0:y1, x0:x1], alpha=alpha)


def fit_box(width: int, height: int, frame_w: int, frame_h: int, fit: str = FITS[0]) -> tuple[int, int, int, int]:
    """Where the fit rule puts a ``width`` x ``height`` image in a frame.

    Scale ``min(frame_w / width, frame_h / height)``, so the whole image lies
    inside (``crop`` too: its image is cut to its content first, by
    :func:`fit_square`). Rounded sizes (>= 1), centred with the odd leftover
    pixel to the right/bottom.

    Returns:
        (x0, y0, w, h): left column, top row and size of the scaled image, pixels.
    """
    if fit not in FITS:
        raise ConfigError(f"fit must be one of {', '.join(FITS)}, got {fit!r}")
    s = min(frame_w / width, frame_h / height)
    w = min(frame_w, max(1, int(round(width * s))))
    h = min(frame_h, max(1, int(round(height * s))))
    return (frame_w - w) // 2, (frame_h - h) // 2, w, h


def _paste(dest: np.ndarray, src: np.ndarray, x0: int, y0: int) -> None:
    """Put ``src`` into ``dest`` with its top-left corner at (x0, y0), cutting what falls outside."""
    h, w = src.shape[:2]
    fh, fw = dest.shape[:2]
    dx0, dy0 = max(0, x0), max(0, y0)
    dx1, dy1 = min(fw, x0 + w), min(fh, y0 + h)
    dest[dy0:dy1, dx0:dx1] = src[dy0 - y0 : dy1 - y0, dx0 - x0 : dx1 - x0]


def _fit_into(
    rgb: np.ndarray,
    alpha: np.ndarray | None,
    frame_w: int,
    frame_h: int,
    background: np.ndarray,
    fit: str = FITS[0],
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """The fit rule into a ``frame_w`` x ``frame_h`` frame (see the module docstring)."""
    src_h, src_w = rgb.shape[:2]
    x0, y0, w, h = fit_box(src_w, src_h, frame_w, frame_h, fit)
    out = np.empty((frame_h, frame_w, 3), np.float32)
    out[...] = background.reshape(1, 1, 3)
    fill = np.ones((frame_h, frame_w), bool)
    _paste(fill, np.zeros((h, w), bool), x0, y0)
    if alpha is None:
        planes = [_resize_plane(rgb[..., c], w, h) for c in range(3)]
        _paste(out, np.clip(np.stack(planes, axis=-1), 0.0, 1.0), x0, y0)
        return out, None, fill
    # Premultiplied resampling: a transparent pixel's (arbitrary) colour has
    # zero weight, so no dark or coloured fringe appears along the subject.
    a = np.clip(_resize_plane(alpha, w, h), 0.0, 1.0)
    pm = [_resize_plane(rgb[..., c] * alpha, w, h) for c in range(3)]
    safe = np.maximum(a, 1e-6)[..., None]
    col = np.clip(np.stack(pm, axis=-1) / safe, 0.0, 1.0)
    col = np.where(a[..., None] > 1e-6, col, background.reshape(1, 1, 3))
    _paste(out, col, x0, y0)
    out_a = np.zeros((frame_h, frame_w), np.float32)
    _paste(out_a, a, x0, y0)
    return out, out_a, fill


def _split(img: LoadedImage | np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(img, (LoadedImage, ViewImage)):
        return img.rgb, img.alpha
    arr = np.asarray(img)
    if arr.ndim == 3 and arr.shape[2] == 4:
        return arr[..., :3].astype(np.float32), arr[..., 3].astype(np.float32)
    if arr.ndim == 3 and arr.shape[2] == 3:
        return arr.astype(np.float32), None
    if arr.ndim == 2:
        return np.repeat(arr.astype(np.float32)[..., None], 3, axis=2), None
    raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {arr.shape}")


def fit_square(
    img: LoadedImage | np.ndarray,
    size: int,
    *,
    background: Sequence[float] | str | None = None,
    fit: str = FITS[0],
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Fit an image into the ``size`` x ``size`` view frame (the fit rule).

    Args:
        img: a :class:`LoadedImage`, or an array (H, W), (H, W, 3) or
            (H, W, 4) with float values in [0, 1].
        size: S, the frame's side in pixels (>= 1).
        background: padding colour (three floats in [0, 1] or ``"#rrggbb"``);
            None: estimated by :func:`estimate_background`.
    Returns:
        ``(rgb, alpha, fill)``: rgb (S, S, 3) float32 in [0, 1]; alpha
        (S, S) float32 (0 in the padding) or None when the image has none;
        fill (S, S) bool, True on padding pixels.
    """
    if not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"size must be a positive integer, got {size!r}")
    rgb, alpha = _split(img)
    bg = intended_background(rgb, background, alpha)
    if fit == "crop":  # the content's box, then the whole of it as "pad" does
        if not isinstance(img, LoadedImage):
            img = LoadedImage(rgb, alpha, "(array)", "array", "RGB", 8)
        cropped = crop_to_content(img, bg)
        rgb, alpha = cropped.rgb, cropped.alpha
    return _fit_into(rgb, alpha, int(size), int(size), bg, fit)


def fit_plane(plane: np.ndarray, frame_w: int, frame_h: int, fit: str = FITS[0]) -> np.ndarray:
    """One (H, W) float plane (a mask's coverage) put through the fit rule.

    Lanczos-resized to its :func:`fit_box` and placed in the frame; the
    padding is 0 (background). Returns (frame_h, frame_w) float32.
    """
    x0, y0, w, h = fit_box(plane.shape[1], plane.shape[0], frame_w, frame_h, fit)
    out = np.zeros((frame_h, frame_w), np.float32)
    _paste(out, _resize_plane(plane, w, h), x0, y0)
    return out
