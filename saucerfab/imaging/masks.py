"""Foreground masks of the input pictures, and :func:`prepare_image` (load, fit, mask).

The subject of each input picture (what the enhanced targets of
:mod:`saucerfab.optimize.enhancement` paint in one colour) is found by
:func:`foreground_mask`, from, in this order of preference: a mask file the
user gives, the picture's alpha channel, or :func:`threshold_mask`, an
automatic colour-distance threshold against the plain background.
:func:`plain_background_share` says whether a threshold mask can be trusted.

:func:`prepare_image` loads a picture (:func:`saucerfab.imaging.images.load_image`),
fits it into its view frame (:func:`saucerfab.imaging.fitting.fit_square`) and masks
it there, giving the :class:`~saucerfab.imaging.images.ViewImage` the optimizer uses.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Literal, get_args

import numpy as np

from saucerfab.errors import ConfigError, ImageError, MaskError
from saucerfab.files.fileio import sha256_file
from saucerfab.imaging.fitting import FITS, fit_plane, fit_square
from saucerfab.imaging.images import (
    DEFAULT_MAX_BYTES,
    DEFAULT_MAX_PIXELS,
    LoadedImage,
    ViewImage,
    border_ring,
    estimate_background,
    flatten_alpha,
    intended_background,
    load_image,
)

#: a mask covering less than this fraction of the content (or more than
#: 1 - this) has no usable subject
MIN_FOREGROUND_FRACTION = 0.001

#: how a picture's subject is found (see :func:`foreground_mask`)
MaskMethod = Literal["auto", "alpha", "file", "threshold", "none"]
MASK_METHODS: tuple[str, ...] = get_args(MaskMethod)


def _disk(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None] ** 2 + r[None, :] ** 2) <= radius * radius + radius


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of ``values`` (any shape): the cut maximising between-class variance.

    Returns a value ``t`` such that ``values > t`` is the upper class.
    """
    v = np.asarray(values, np.float64).ravel()
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo:
        return hi
    hist, edges = np.histogram(v, bins=bins, range=(lo, hi))
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist).astype(np.float64)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    mu0 = m0 / np.maximum(w0, 1)
    mu1 = (m0[-1] - m0) / np.maximum(w1, 1)
    between = w0 * w1 * (mu0 - mu1) ** 2
    between[(w0 == 0) | (w1 == 0)] = -1.0
    return float(edges[int(np.argmax(between)) + 1])


def _remove_small(mask: np.ndarray, min_area: int, *, keep_border: bool) -> np.ndarray:
    """Drop connected components of ``mask`` smaller than ``min_area`` pixels.

    With ``keep_border`` components touching the image edge stay whatever
    their size (used for holes: background touching the edge is not a hole).
    """
    from scipy import ndimage

    labels, n = ndimage.label(mask)
    if n == 0:
        return mask
    areas = np.bincount(labels.ravel(), minlength=n + 1)
    small = areas < min_area
    small[0] = False
    if keep_border:
        edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        small[edge] = False
    return mask & ~small[labels]


def threshold_mask(rgb: np.ndarray, *, alpha: np.ndarray | None = None) -> np.ndarray:
    """Automatic foreground mask of an image on a plain background.

    1. Background colour b: :func:`estimate_background` (median of the outer ring).
    2. Colours smoothed by a Gaussian of 1 pixel (sensor/JPEG noise), then
       each pixel's Euclidean distance d from b in sRGB.
    3. Threshold: Otsu's on d, but never below ``3 * median(d on the ring)
       + 0.02`` (so an image with nothing but noisy background does not get
       half its noise called foreground).
    4. Clean-up: binary opening then closing with a disk of radius
       ``max(1, round(min(H, W) / 256))``, then foreground specks and
       enclosed holes smaller than ``max(16, 0.05 % of the pixels)`` removed.

    Args:
        rgb: (H, W, 3) float in [0, 1].
        alpha: optional (H, W); if given the colours are first composited
            over b, so transparent pixels count as background.
    Returns:
        (H, W) bool.
    """
    from scipy import ndimage

    rgb = np.asarray(rgb, np.float32)
    h, w = rgb.shape[:2]
    bg = estimate_background(rgb, alpha)
    if alpha is not None:
        rgb = flatten_alpha(rgb, alpha, bg)
    smooth = ndimage.gaussian_filter(rgb, sigma=(1.0, 1.0, 0.0), mode="nearest")
    d = np.sqrt(((smooth - bg.reshape(1, 1, 3)) ** 2).sum(axis=-1))
    floor = 3.0 * float(np.median(d[border_ring((h, w))])) + 0.02
    t = max(otsu_threshold(d), floor)
    mask = d > t
    r = max(1, int(round(min(h, w) / 256)))
    st = _disk(r)
    # Pad before the morphology: scipy treats outside pixels as background,
    # which would eat a subject that touches the image edge when closing.
    pad = r + 1
    m = np.pad(mask, pad, mode="edge")
    m = ndimage.binary_opening(m, structure=st)
    m = ndimage.binary_closing(m, structure=st)
    mask = m[pad:-pad, pad:-pad]
    min_area = max(16, int(0.0005 * h * w))
    mask = _remove_small(mask, min_area, keep_border=False)
    mask = ~_remove_small(~mask, min_area, keep_border=True)
    return mask


#: a background is "plain" when this share of its pixels lies within PLAIN_DISTANCE of its colour
PLAIN_SHARE = 0.85
PLAIN_DISTANCE = 0.12


def plain_background_share(view: ViewImage) -> float:
    """Share of a fitted image's background pixels (not mask, not padding) near its background colour.

    Distances are Euclidean in sRGB [0, 1]^3. A subject on a plain or
    transparent background gives about 1; a full-bleed photograph far less.
    """
    rgb = view.flattened()
    bg = ~view.mask & ~view.fill
    if not bg.any():
        return 0.0
    d = np.sqrt(((rgb[bg] - view.background.reshape(1, 3)) ** 2).sum(axis=-1))
    return float(np.mean(d < PLAIN_DISTANCE))


def _load_mask_file(mask_path: str | os.PathLike[str], max_pixels: int, max_bytes: int) -> tuple[np.ndarray, str]:
    """A mask file as (H, W) float32 coverage (white = 1) and its name."""
    m = load_image(mask_path, max_pixels=max_pixels, max_bytes=max_bytes)
    # Rec. 601 luma, the usual meaning of "white" in a grey mask; a
    # transparent pixel of a mask drawn on a transparent layer is background.
    cover = m.rgb @ np.array([0.299, 0.587, 0.114], np.float32)
    if m.alpha is not None:
        cover = cover * m.alpha
    return cover.astype(np.float32), m.path


def _check_fraction(mask: np.ndarray, content: np.ndarray, source: str, name: str) -> None:
    n = int(content.sum())
    frac = float(mask[content].sum()) / max(n, 1)
    if frac < MIN_FOREGROUND_FRACTION:
        what = "no foreground (everything is background)"
    elif frac > 1.0 - MIN_FOREGROUND_FRACTION:
        what = "no background (everything is foreground)"
    else:
        return
    raise MaskError(
        f"the {source} foreground mask of image {name!r} has {what}. Give a mask file "
        "(white = subject, black = background) or an image with a clear subject on a "
        "plain background or a transparent background."
    )


def _mask_in_frame(
    rgb: np.ndarray,
    alpha: np.ndarray | None,
    fill: np.ndarray | None,
    source_size: tuple[int, int],
    name: str,
    mask_path: str | os.PathLike[str] | None,
    method: str,
    max_pixels: int,
    max_bytes: int,
    fit: str = FITS[0],
) -> tuple[np.ndarray, str]:
    """Foreground mask (H, W) bool of an image in its frame, and the method used."""
    if method not in MASK_METHODS:
        raise ConfigError(
            f"unknown mask method {method!r}; use {', '.join(MASK_METHODS[:-1])} or {MASK_METHODS[-1]}"
        )
    h, w = rgb.shape[:2]
    if method == "none":  # no subject wanted (no enhancement): an empty mask, nothing to refuse
        return np.zeros((h, w), bool), "none"
    content = np.ones((h, w), bool) if fill is None else ~fill
    if method == "auto":
        if mask_path is not None:
            method = "file"  # what the user gave explicitly wins
        elif alpha is not None and bool((alpha[content] <= 0.5).any()):
            method = "alpha"
        else:
            method = "threshold"
    if method == "file":
        if mask_path is None:
            raise ConfigError("mask method 'file' needs a mask file")
        cover, mname = _load_mask_file(mask_path, max_pixels, max_bytes)
        mw, mh = cover.shape[1], cover.shape[0]
        sw, sh = source_size
        if abs(math.log((mw / mh) / (sw / sh))) > 0.02:
            raise ImageError(
                f"mask {mname!r} is {mw}x{mh} but image {name!r} is {sw}x{sh}: a mask must have "
                "its image's proportions (ideally its size)"
            )
        # The mask goes through the same fit rule as its image, so it lands
        # on the same pixels of the frame; padding is background.
        mask = fit_plane(cover, w, h, fit) > 0.5
        mask &= content
        _check_fraction(mask, content, "given", name)
        return mask, "file"
    if method == "alpha":
        if alpha is None:
            raise ImageError(f"image {name!r} has no alpha channel; use another mask method or give a mask file")
        mask = (alpha > 0.5) & content
        _check_fraction(mask, content, "alpha-channel", name)
        return mask, "alpha"
    # threshold: run on the content box only, so the padding (whatever its
    # colour) neither biases the background estimate nor becomes foreground
    rows = np.flatnonzero(content.any(axis=1))
    cols = np.flatnonzero(content.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    sub_a = None if alpha is None else alpha[r0:r1, c0:c1]
    mask = np.zeros((h, w), bool)
    mask[r0:r1, c0:c1] = threshold_mask(rgb[r0:r1, c0:c1], alpha=sub_a)
    mask &= content
    _check_fraction(mask, content, "automatic", name)
    return mask, "threshold"


def foreground_mask(
    img: LoadedImage | ViewImage,
    *,
    mask_path: str | os.PathLike[str] | None = None,
    method: MaskMethod = "auto",
    max_pixels: int = DEFAULT_MAX_PIXELS,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> np.ndarray:
    """The foreground (subject) mask of an image, in the image's own pixel frame.

    ``method="auto"`` picks, in this order:

    1. ``"file"`` when ``mask_path`` is given (explicit beats implicit): any
       image the loader reads; luma > 0.5 (white) is foreground, transparent
       is background. It must have the image's proportions (within 2 %) and
       is put through the same fit rule, so it covers the same pixels even
       when ``img`` is a fitted :class:`ViewImage` and the mask is at the
       original size.
    2. ``"alpha"`` when the image has an alpha channel with some
       transparent content: ``alpha > 0.5``.
    3. ``"threshold"``: :func:`threshold_mask` (distance from the estimated
       background colour, Otsu, small open/close, tiny specks and holes
       removed).

    Padding pixels of a :class:`ViewImage` are always background.

    Returns:
        (H, W) bool, True on the subject.
    Raises:
        ImageError: the mask has (almost) no foreground or no background
            (less than 0.1 % of either), a mask file is unreadable or of the
            wrong proportions, or ``method="alpha"`` without alpha.
        ConfigError: unknown ``method``, or ``"file"`` without ``mask_path``.
    """
    if isinstance(img, ViewImage):
        fill: np.ndarray | None = img.fill
        source_size = img.source_size
    else:
        fill, source_size = None, img.size
    mask, _ = _mask_in_frame(
        img.rgb, img.alpha, fill, source_size, img.path, mask_path, method, max_pixels, max_bytes
    )
    return mask


def prepare_image(
    path: str | os.PathLike[str],
    size: int,
    *,
    mask_path: str | os.PathLike[str] | None = None,
    mask_method: MaskMethod = "auto",
    background: Sequence[float] | str | None = None,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    max_bytes: int = DEFAULT_MAX_BYTES,
    loaded: LoadedImage | None = None,
    fit: str = FITS[0],
) -> ViewImage:
    """Load, fit into the ``size`` x ``size`` frame and mask one input image.

    ``loaded``: the image already decoded from ``path`` (by :func:`load_image`),
    so a caller that also fits it at another size decodes the file once.
    ``fit``: ``pad`` (the whole image, padded with ``background``) or
    ``crop`` (the frame filled, the image's margins cut off); a mask file
    follows its image's rule. ``background``: the padding and the colour
    transparency is composited over; None estimates it from the border.

    The mask is computed in the fitted frame (so the morphology's pixel
    sizes are relative to the frame the optimizer uses). See
    :func:`load_image`, :func:`fit_square` and :func:`foreground_mask`.

    Raises:
        ImageError: as those functions do; nothing is written anywhere.
    """
    img = loaded if loaded is not None else load_image(path, max_pixels=max_pixels, max_bytes=max_bytes)
    bg = intended_background(img.rgb, background, img.alpha)
    rgb, alpha, fill = fit_square(img, size, background=bg, fit=fit)
    mask, source = _mask_in_frame(
        rgb, alpha, fill, img.size, img.path, mask_path, mask_method, max_pixels, max_bytes, fit
    )
    return ViewImage(
        rgb=rgb,
        alpha=alpha,
        fill=fill,
        mask=mask,
        background=bg,
        mask_source=source,
        path=img.path,
        sha256=sha256_file(img.path),
        source_size=img.size,
        format=img.format,
        mode=img.mode,
        bit_depth=img.bit_depth,
        notes=img.notes,
    )
