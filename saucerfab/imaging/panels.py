"""Previews for people: PNG encoding, panels, overlays (and the charts of :mod:`saucerfab.imaging.charts`).

Everything here makes pictures of results; nothing feeds back into the
design. Images go in as arrays in the usual orientation (row 0 at the top,
as :mod:`saucerfab.model.camera` defines) and come out as (H, W, 3) uint8
arrays or PNG bytes; writing files is the caller's job (atomically, with
:mod:`saucerfab.files.fileio`). Everything is drawn with Pillow: no plotting
library, no display, safe in worker processes. The HTML pages that show
them are :mod:`saucerfab.pages`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from saucerfab.files.imageio import png_bytes
from saucerfab.imaging.charts import energy_plot, font, height_change_map

__all__ = [
    "as_uint8_rgb",
    "composite",
    "energy_plot",
    "height_change_map",
    "mask_overlay",
    "side_by_side",
    "to_png_bytes",
]

# --------------------------------------------------------------------------- arrays and PNG


def as_uint8_rgb(image: np.ndarray) -> np.ndarray:
    """Any displayable image as (H, W, 3) uint8.

    Accepts (H, W) or (H, W, 1) grey, (H, W, 3) RGB or (H, W, 4) RGBA
    (composited over white), as bool (True = white), uint8, uint16 (full
    range), or float in [0, 1] (clipped, rounded).

    Raises:
        ValueError: another shape or dtype, or NaN/inf values.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {a.shape}")
    if a.dtype == bool:
        f = a.astype(np.float32)
    elif a.dtype == np.uint8:
        f = a.astype(np.float32) / 255.0
    elif a.dtype == np.uint16:
        f = a.astype(np.float32) / 65535.0
    elif np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)):
            raise ValueError("image holds NaN or infinite values")
        f = np.clip(a.astype(np.float32), 0.0, 1.0)
    else:
        raise ValueError(f"unsupported image dtype {a.dtype}")
    if f.ndim == 2:
        f = np.repeat(f[..., None], 3, axis=2)
    elif f.shape[2] == 4:
        alpha = f[..., 3:4]
        f = f[..., :3] * alpha + (1.0 - alpha)
    if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] == 3:
        return np.ascontiguousarray(a)  # exact, no round trip through float
    return np.round(f * 255.0).astype(np.uint8)


def to_png_bytes(image: np.ndarray) -> bytes:
    """PNG file bytes of ``image`` (anything :func:`as_uint8_rgb` takes), 8-bit RGB."""
    return png_bytes(as_uint8_rgb(image))


# --------------------------------------------------------------------------- panels


def side_by_side(
    panels: Sequence[tuple[str, np.ndarray]],
    *,
    height: int = 256,
    gap: int = 8,
    title_px: int = 16,
    background: tuple[int, int, int] = (255, 255, 255),
) -> np.ndarray:
    """Images in a row, each scaled to ``height`` pixels high, with its title above.

    Args:
        panels: (title, image) pairs; images as :func:`as_uint8_rgb` takes.
        height: panel height in pixels (aspect ratios are kept).
        gap: pixels between and around panels.
        title_px: title font size in pixels.
    Returns:
        (H, W, 3) uint8 with ``H = height + title band + 2 gap``.
    """
    from PIL import Image, ImageDraw

    if not panels:
        raise ValueError("side_by_side needs at least one panel")
    face = font(title_px)
    band = title_px + 8
    tiles = []
    for _, img in panels:
        rgb = as_uint8_rgb(img)
        h, w = rgb.shape[:2]
        nw = max(1, round(w * height / h))
        pim = Image.fromarray(rgb)
        if (nw, height) != (w, h):
            # nearest for upscaling small renders keeps pixels honest;
            # Lanczos for shrinking avoids aliasing
            resample = Image.Resampling.NEAREST if height >= h else Image.Resampling.LANCZOS
            pim = pim.resize((nw, height), resample)
        tiles.append(pim)
    total_w = sum(t.width for t in tiles) + gap * (len(tiles) + 1)
    total_h = height + band + 2 * gap
    sheet = Image.new("RGB", (total_w, total_h), background)
    draw = ImageDraw.Draw(sheet)
    x = gap
    for (title, _), tile in zip(panels, tiles):
        text = str(title)
        # shorten titles wider than their panel rather than overlap the next one
        if draw.textlength(text, font=face) > tile.width:
            while len(text) > 1 and draw.textlength(text + "\u2026", font=face) > tile.width:
                text = text[:-1]
            text += "\u2026"
        draw.text((x, gap), text, fill=(0, 0, 0), font=face)
        sheet.paste(tile, (x, gap + band))
        x += tile.width + gap
    return np.asarray(sheet).copy()


def mask_overlay(
    image: np.ndarray,
    mask: np.ndarray,
    *,
    colour: tuple[float, float, float] = (1.0, 0.0, 0.0),
    opacity: float = 0.4,
    outline: bool = True,
) -> np.ndarray:
    """Show a foreground mask on its image: foreground tinted, its boundary drawn solid.

    Args:
        image: (H, W[, 3|4]) image as :func:`as_uint8_rgb` takes.
        mask: (H, W) bool, True on the foreground.
        colour: tint colour, floats in [0, 1].
        opacity: tint strength in [0, 1] over the foreground.
        outline: draw the mask's one-pixel inner boundary in ``colour``.
    Returns:
        (H, W, 3) uint8.
    """
    rgb = as_uint8_rgb(image).astype(np.float32) / 255.0
    m = np.asarray(mask, bool)
    if m.shape != rgb.shape[:2]:
        raise ValueError(f"mask {m.shape} does not match image {rgb.shape[:2]}")
    c = np.asarray(colour, np.float32).reshape(1, 1, 3)
    out = np.where(m[..., None], rgb * (1.0 - opacity) + c * opacity, rgb)
    if outline:
        from scipy import ndimage

        edge = m & ~ndimage.binary_erosion(m, border_value=1)
        out[edge] = c[0, 0]
    return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)


def composite(direct_view: np.ndarray, reflected_view: np.ndarray, reflected_alpha: np.ndarray) -> np.ndarray:
    """Alpha-blend the reflected layer over the direct layer, pixel by pixel.

    An image-level helper: both layers must already be in the same camera
    frame and size (e.g. the hard renderer's saucer layer and its cup layer
    as seen from the camera). The direct and reflected *view frames* of the
    optimizer are different cameras; pasting those together is not what a
    viewer sees.

    Args:
        direct_view: (S, S, 3) layer underneath.
        reflected_view: (S, S, 3) layer on top.
        reflected_alpha: (S, S) float in [0, 1] (or bool) coverage of the top layer.
    Returns:
        (S, S, 3) uint8.
    """
    lower = as_uint8_rgb(direct_view).astype(np.float32)
    upper = as_uint8_rgb(reflected_view).astype(np.float32)
    a = np.clip(np.asarray(reflected_alpha, np.float32), 0.0, 1.0)
    if lower.shape != upper.shape or a.shape != lower.shape[:2]:
        raise ValueError(f"layer shapes differ: {lower.shape}, {upper.shape}, alpha {a.shape}")
    out = lower * (1.0 - a[..., None]) + upper * a[..., None]
    return np.round(out).astype(np.uint8)
