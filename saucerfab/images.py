"""Input images: safe loading, fitting into square view frames, foreground masks, enhancement.

The optimizer's two (or three) input images reach it through this module:

1. :func:`load_image` reads a PNG, JPEG or WebP file safely: the file size
   and the pixel count (from the header, before any pixel is decoded) are
   checked against limits, EXIF orientation is applied, an embedded ICC
   profile is converted to sRGB, and every pixel mode becomes ``rgb``
   (H, W, 3) float32 sRGB values in [0, 1] plus ``alpha`` (H, W) float32 or
   ``None``. Like the paper, everything works on sRGB values (no
   linearisation).
2. :func:`fit_square` puts an image of any aspect ratio into the square
   S x S view frame (the **fit rule**, below).
3. :func:`foreground_mask` finds the subject: the alpha channel, a mask
   file the user gives, or an automatic colour-distance threshold.
4. :func:`black_white_targets` and :func:`solid_colour_targets` make the
   enhanced target images of the paper (eq. 7-8; section 4, Figure 19).

:func:`prepare_image` does 1-3 in one call and returns a :class:`ViewImage`.

The fit rule
------------
An image W x H goes into the S x S frame (row 0 at the top, as in
:mod:`saucerfab.render.camera`) scaled by ``S / max(W, H)``, so its long
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

That is ``fit="pad"``, the default: the whole image is shown. ``fit="crop"``
(``saucerfab design --fit crop``, what designers expect for photographs)
scales by ``S / min(W, H)`` instead, so the short side spans the frame and
the long side's margins are cut off equally (the odd pixel at the
right/bottom); nothing is padded. A mask file follows its image's rule.
The background colour (``--background``) is also the colour transparency
is composited over, in the picture the design aims at and verify compares with.

Animated images (APNG, animated WebP) use their first frame; the
:class:`LoadedImage` carries a note saying so. A 16-bit RGB(A) PNG is
decoded by Pillow (13) at 8 bits per channel (noted); 16-bit grayscale
keeps its 16 bits.
"""

from __future__ import annotations

import io
import math
import os
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from saucerfab.errors import ConfigError, ImageError, MaskError
from saucerfab.fileio import sha256_file
from saucerfab.imageio import PixelLimitError, open_bounded

#: default limits for untrusted images (checked before decoding)
DEFAULT_MAX_PIXELS = 64_000_000
DEFAULT_MAX_BYTES = 200_000_000

#: the Pillow formats we decode; "MPO" is what Pillow calls a multi-picture
#: JPEG (phone cameras), whose first picture is the ordinary JPEG image
ACCEPTED_FORMATS = ("PNG", "JPEG", "WEBP")
_DECODED_FORMATS = ("PNG", "JPEG", "MPO", "WEBP")

#: black-white enhancement background (paper, section 3.4.1: "light blue")
LIGHT_BLUE = (0.0, 0.5, 1.0)
BLACK = (0.0, 0.0, 0.0)
WHITE = (1.0, 1.0, 1.0)
#: solid-colour enhancement foregrounds, in input order (paper, section 4)
SOLID_COLOURS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

#: width of the border ring the background colour is estimated from, as a
#: fraction of the image's short side
BORDER_RING_FRACTION = 0.02
#: a mask covering less than this fraction of the content (or more than
#: 1 - this) has no usable subject
MIN_FOREGROUND_FRACTION = 0.001

MaskMethod = Literal["auto", "alpha", "file", "threshold", "none"]

# First bytes of formats people try; used only to word the error message.
_MAGIC = (
    (b"GIF8", "GIF"),
    (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"),
    (b"BM", "BMP"),
    (b"%PDF", "PDF"),
    (b"8BPS", "Photoshop PSD"),
    (b"\x00\x00\x01\x00", "ICO"),
)


@dataclass(frozen=True)
class LoadedImage:
    """An image as decoded from a file, before fitting.

    Attributes:
        rgb: (H, W, 3) float32 sRGB values in [0, 1]; row 0 is the top.
        alpha: (H, W) float32 opacity in [0, 1], or ``None`` when the file has
            no transparency (or only fully opaque pixels).
        path: the file it came from.
        format: Pillow's format name ("PNG", "JPEG", "MPO" or "WEBP").
        mode: Pillow's mode of the file's pixels ("RGB", "P", "I;16", ...).
        bit_depth: bits per sample stored in the file (1, 2, 4, 8 or 16; for
            a palette image, bits per palette index).
        notes: things a user should know (first frame of an animation used,
            EXIF rotation applied, precision lost, ICC profile converted...).
    """

    rgb: np.ndarray
    alpha: np.ndarray | None
    path: str
    format: str
    mode: str
    bit_depth: int
    notes: tuple[str, ...] = ()

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels, after EXIF orientation."""
        return (int(self.rgb.shape[1]), int(self.rgb.shape[0]))


@dataclass(frozen=True)
class ViewImage:
    """An input image fitted into its S x S view frame, with its foreground mask.

    Attributes:
        rgb: (S, S, 3) float32 sRGB in [0, 1] (not composited over anything;
            see :meth:`flattened`).
        alpha: (S, S) float32 in [0, 1] or ``None``; 0 in the padding.
        fill: (S, S) bool, True on padding pixels added by the fit rule.
        mask: (S, S) bool foreground mask (False on padding).
        background: (3,) float32, the padding colour (given or estimated).
        mask_source: where the mask came from: "alpha", "file" or "threshold".
        path: the image file.
        sha256: hex sha256 of the image file's bytes.
        source_size: (width, height) of the image before fitting.
        format, mode, bit_depth, notes: as in :class:`LoadedImage`.
    """

    rgb: np.ndarray
    alpha: np.ndarray | None
    fill: np.ndarray
    mask: np.ndarray
    background: np.ndarray
    mask_source: str
    path: str
    sha256: str
    source_size: tuple[int, int]
    format: str
    mode: str
    bit_depth: int
    notes: tuple[str, ...] = field(default=())

    @property
    def size(self) -> int:
        """S, the frame's side in pixels."""
        return int(self.rgb.shape[0])

    def flattened(self, colour: Sequence[float] | str | None = None) -> np.ndarray:
        """(S, S, 3) float32 RGB with alpha composited over ``colour``.

        ``colour`` defaults to :attr:`background`; this is the target image
        the optimizer compares renders against (the saucer has no
        transparency, so a transparent input shows whatever colour is chosen).
        """
        if self.alpha is None:
            return self.rgb.copy()
        c = self.background if colour is None else parse_colour(colour)
        return flatten_alpha(self.rgb, self.alpha, c)


# --------------------------------------------------------------------------- small helpers


def parse_colour(value: Sequence[float] | str | np.ndarray) -> np.ndarray:
    """A colour as (3,) float32 sRGB in [0, 1].

    Accepts three floats in [0, 1], or a ``"#rrggbb"`` / ``"rrggbb"`` string.

    Raises:
        ConfigError: anything else (the message shows the value).
    """
    if isinstance(value, str):
        s = value.strip().removeprefix("#")
        if len(s) != 6 or any(ch not in "0123456789abcdefABCDEF" for ch in s):
            raise ConfigError(f"colour {value!r} is not '#rrggbb' or three numbers in [0, 1]")
        return np.array([int(s[k : k + 2], 16) / 255.0 for k in (0, 2, 4)], np.float32)
    arr = np.asarray(value, dtype=np.float64).ravel()
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
        raise ConfigError(f"colour {value!r} is not '#rrggbb' or three numbers in [0, 1]")
    return arr.astype(np.float32)


def flatten_alpha(rgb: np.ndarray, alpha: np.ndarray | None, colour: Sequence[float]) -> np.ndarray:
    """Composite ``rgb`` (H, W, 3) with ``alpha`` (H, W) over a solid ``colour``.

    Returns (H, W, 3) float32 ``rgb * alpha + colour * (1 - alpha)``
    (straight, not premultiplied, alpha; sRGB values as the paper uses).
    """
    out = np.asarray(rgb, np.float32)
    if alpha is None:
        return out.copy()
    a = np.asarray(alpha, np.float32)[..., None]
    c = np.asarray(colour, np.float32).reshape(1, 1, 3)
    return (out * a + c * (1.0 - a)).astype(np.float32)


def _ring(shape: tuple[int, int], fraction: float = BORDER_RING_FRACTION) -> np.ndarray:
    """(H, W) bool: the outer ring ``ceil(fraction * min(H, W))`` pixels wide (>= 1)."""
    h, w = shape
    k = max(1, math.ceil(fraction * min(h, w)))
    ring = np.zeros((h, w), bool)
    ring[:k] = ring[-k:] = True
    ring[:, :k] = ring[:, -k:] = True
    return ring


def estimate_background(rgb: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """The background colour of an image: per-channel median of its outer 2 % ring.

    The median, not the mean, so a subject that touches the border over
    less than half the ring does not shift it. Where ``alpha`` is given,
    only ring pixels at least half opaque count (transparent pixels' colour
    is arbitrary); if there are none, the answer is white.

    Args:
        rgb: (H, W, 3) float values in [0, 1].
        alpha: (H, W) or None.
    Returns:
        (3,) float32.
    """
    ring = _ring(rgb.shape[:2])
    if alpha is not None:
        opaque = ring & (np.asarray(alpha) >= 0.5)
        if not opaque.any():
            # A subject on a transparent canvas: the colours under the
            # transparency mean nothing; white is what the renderer shows
            # where nothing is drawn, and the paper's inputs sit on white.
            return np.array(WHITE, np.float32)
        ring = opaque
    return np.median(np.asarray(rgb)[ring], axis=0).astype(np.float32)


# --------------------------------------------------------------------------- loading


def _sniff(head: bytes) -> str | None:
    for magic, name in _MAGIC:
        if head.startswith(magic):
            return name
    if head[4:8] == b"ftyp":
        return "HEIC/AVIF/MP4"
    stripped = head.lstrip()
    if stripped.startswith(b"<"):
        return "SVG/XML/HTML text"
    return None


def _png_bit_depth(head: bytes) -> int | None:
    """Bit depth from a PNG's IHDR (byte 24), or None if ``head`` is not a PNG."""
    if len(head) >= 26 and head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR":
        return int(head[24])
    return None


def _icc_to_srgb(im, notes: list[str]):  # type: ignore[no-untyped-def]
    """Convert an RGB, RGBA or CMYK image with an embedded ICC profile to sRGB.

    Designers' exports often carry Adobe RGB or Display P3 profiles; reading
    those values as sRGB shifts every colour. (An sRGB profile converts to
    itself within rounding.) Returns the (possibly new) image; on any
    trouble it keeps the pixels as they are and adds a note.
    """
    icc = im.info.get("icc_profile")
    if not icc or im.mode not in ("RGB", "RGBA", "CMYK"):
        return im
    try:
        from PIL import ImageCms

        src = ImageCms.ImageCmsProfile(io.BytesIO(icc))
        desc = (ImageCms.getProfileDescription(src) or "").strip() or "unnamed"
        alpha = im.getchannel("A") if im.mode == "RGBA" else None
        base = im.convert("RGB") if alpha is not None else im
        out = ImageCms.profileToProfile(
            base, src, ImageCms.createProfile("sRGB"),
            renderingIntent=ImageCms.Intent.PERCEPTUAL, outputMode="RGB",
        )
        if out is None:  # only with inPlace=True; kept for the type checker
            return im
        if alpha is not None:
            out.putalpha(alpha)
        out.info = dict(im.info)
        notes.append(f"colours converted to sRGB from the embedded ICC profile ({desc})")
        return out
    except Exception as exc:  # a damaged profile must not make the image unusable
        notes.append(f"ignored an embedded ICC profile that could not be used ({type(exc).__name__}: {exc})")
        return im


def _decode(im, notes: list[str]) -> tuple[np.ndarray, np.ndarray | None]:  # type: ignore[no-untyped-def]
    """Pixels of a loaded Pillow image as (rgb (H,W,3), alpha (H,W) or None) float32 in [0, 1]."""
    mode = im.mode
    transparency = im.info.get("transparency")
    if mode in ("I;16", "I;16L", "I;16B", "I;16N", "I"):
        # 16-bit grayscale: Pillow's convert("RGB") would clip at 255, so
        # scale the integers ourselves. A PNG never holds more than 16 bits.
        arr = np.asarray(im).astype(np.float32)
        gray = np.clip(arr / 65535.0, 0.0, 1.0)
        alpha = None
        if isinstance(transparency, int):  # tRNS: one fully transparent grey level
            alpha = (arr != transparency).astype(np.float32)
        return np.repeat(gray[..., None], 3, axis=2), alpha
    if mode == "F":
        raise ImageError("32-bit float images are not supported; save it as 8- or 16-bit")
    has_alpha = mode in ("RGBA", "LA", "PA", "La", "RGBa") or transparency is not None
    if mode in ("RGB", "RGBA", "CMYK"):
        im = _icc_to_srgb(im, notes)
    target = "RGBA" if has_alpha else "RGB"
    try:
        conv = im if im.mode == target else im.convert(target)
    except ValueError as exc:
        raise ImageError(f"pixel mode {mode!r} cannot be converted to RGB ({exc})") from None
    arr = np.asarray(conv)
    scale = np.float32(1.0 / 255.0)
    rgb = arr[..., :3].astype(np.float32) * scale
    alpha = arr[..., 3].astype(np.float32) * scale if has_alpha else None
    return rgb, alpha


def load_image(
    path: str | os.PathLike[str],
    *,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> LoadedImage:
    """Load a PNG, JPEG or WebP image safely as float sRGB values.

    Checks, in this order, before any pixel is decoded: the file exists and
    is at most ``max_bytes`` bytes; it is one of the accepted formats; its
    header's width x height is at most ``max_pixels`` (Pillow's own
    decompression-bomb guard, ``Image.MAX_IMAGE_PIXELS``, also applies and
    is reported the same way). Then it decodes the first frame, applies the
    EXIF orientation, converts an embedded non-sRGB ICC profile to sRGB and
    normalises the mode:

    ========================  ==========================================
    file                      result
    ========================  ==========================================
    RGB, CMYK (JPEG), YCbCr   rgb; alpha None
    RGBA, LA, PA              rgb (gray repeated); alpha
    L, 1-bit, P               rgb; alpha from a tRNS/transparency entry
    16-bit gray (I;16)        rgb = value / 65535 (16 bits kept)
    16-bit RGB(A) PNG         Pillow 13 decodes 8 bits per channel (noted)
    ========================  ==========================================

    A fully opaque alpha channel is dropped (alpha None, noted), so
    "RGBA but opaque" files behave as the RGB images they are.

    Args:
        path: the image file.
        max_pixels: the largest width x height accepted.
        max_bytes: the largest file size accepted.
    Returns:
        :class:`LoadedImage` with ``rgb`` (H, W, 3) float32 and ``alpha``
        (H, W) float32 or None, values in [0, 1].
    Raises:
        ImageError: missing, empty, too large, not an accepted image,
            truncated or damaged; the message names the file and the problem.
    """
    name = os.fspath(path)
    p = Path(name)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise ImageError(f"image {name!r} not found") from None
    except OSError as exc:
        raise ImageError(f"cannot read image {name!r}: {exc.strerror or exc}") from None
    if not p.is_file():
        raise ImageError(f"image {name!r} is not a file")
    if st.st_size == 0:
        raise ImageError(f"image {name!r} is empty (0 bytes)")
    if st.st_size > max_bytes:
        raise ImageError(
            f"image {name!r} is {st.st_size:,} bytes; the limit is {max_bytes:,}. "
            "Downscale or re-compress it."
        )
    try:
        with open(p, "rb") as fh:
            head = fh.read(64)
    except OSError as exc:
        raise ImageError(f"cannot read image {name!r}: {exc.strerror or exc}") from None

    from PIL import Image, ImageOps, UnidentifiedImageError

    notes: list[str] = []
    w = h = 0
    try:
        with open_bounded(p, ACCEPTED_FORMATS, max_pixels) as im:
            fmt = str(im.format)
            if fmt not in _DECODED_FORMATS:  # defensive: a plugin returned something else
                raise ImageError(f"image {name!r} is {fmt}; saucerfab reads PNG, JPEG and WebP")
            w, h = im.size
            if w <= 0 or h <= 0:
                raise ImageError(f"image {name!r} has no pixels ({w}x{h})")
            mode = im.mode
            png_depth = _png_bit_depth(head)
            if mode == "1":
                bit_depth = 1
            elif mode.startswith("I;16") or mode == "I":
                bit_depth = 16
            else:
                bit_depth = png_depth if png_depth in (1, 2, 4, 8, 16) else 8
            if bit_depth == 16 and not (mode.startswith("I;16") or mode == "I"):
                notes.append(f"16-bit {mode} PNG decoded at 8 bits per channel (Pillow's limit)")
            n_frames = int(getattr(im, "n_frames", 1) or 1)
            if n_frames > 1 and fmt != "MPO":
                notes.append(f"animated image with {n_frames} frames: the first frame is used")
            im.seek(0)  # counting frames must not leave us on another one
            im.load()
            # Cameras store pixels sideways and say how to turn them; the
            # turned image is what the user sees and means.
            orientation = im.getexif().get(0x0112, 1)
            work = im
            if orientation not in (None, 1):
                turned = ImageOps.exif_transpose(im)
                if turned is not None:
                    work = turned
                    notes.append(f"EXIF orientation {orientation} applied")
            rgb, alpha = _decode(work, notes)
    except PixelLimitError as exc:
        raise ImageError(
            f"image {name!r} is {exc.width}x{exc.height} = {exc.width * exc.height:,} pixels; "
            f"the limit is {max_pixels:,}. Downscale it first (a view frame is a few hundred pixels wide)."
        ) from None
    except ImageError as exc:
        msg = str(exc)
        if name not in msg:
            msg = f"image {name!r}: {msg}"
        raise ImageError(msg) from None
    except Image.DecompressionBombError as exc:
        raise ImageError(
            f"image {name!r} was refused as a possible decompression bomb: {exc} "
            f"(saucerfab's limit is {max_pixels:,} pixels). Downscale it first."
        ) from None
    except UnidentifiedImageError:
        kind = _sniff(head)
        what = f"a {kind} file" if kind else "not a PNG, JPEG or WebP image"
        raise ImageError(
            f"image {name!r} is {what}; saucerfab reads PNG, JPEG and WebP: convert it to PNG"
        ) from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error, zlib.error, IndexError) as exc:
        raise ImageError(
            f"cannot decode image {name!r}: {exc}. The file is truncated or damaged; export it again."
        ) from None
    except MemoryError:
        raise ImageError(
            f"not enough memory to decode image {name!r} ({w}x{h} pixels); downscale it first"
        ) from None
    if alpha is not None and float(alpha.min()) >= 1.0:
        notes.append("alpha channel is fully opaque; ignored")
        alpha = None
    return LoadedImage(
        rgb=np.ascontiguousarray(rgb, np.float32),
        alpha=None if alpha is None else np.ascontiguousarray(alpha, np.float32),
        path=name,
        format=fmt,
        mode=mode,
        bit_depth=bit_depth,
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------- fitting


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


#: fit rules of an image into its frame: "pad" shows the whole image (bands of
#: the background colour beside it), "crop" fills the frame (its margins cut off)
FITS = ("pad", "crop")


def fit_box(width: int, height: int, frame_w: int, frame_h: int, fit: str = "pad") -> tuple[int, int, int, int]:
    """Where the fit rule puts a ``width`` x ``height`` image in a frame.

    ``pad``: scale ``min(frame_w / width, frame_h / height)``, so the whole
    image lies inside; ``crop``: scale ``max(...)``, so it covers the frame
    and the box reaches past it (negative ``x0`` or ``y0``). Rounded sizes
    (>= 1), centred with the odd leftover pixel to the right/bottom.

    Returns:
        (x0, y0, w, h): left column, top row and size of the scaled image, pixels.
    """
    if fit not in FITS:
        raise ConfigError(f"fit must be one of {', '.join(FITS)}, got {fit!r}")
    if fit == "crop":
        s = max(frame_w / width, frame_h / height)
        w = max(frame_w, int(round(width * s)))
        h = max(frame_h, int(round(height * s)))
    else:
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
    fit: str = "pad",
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
    fit: str = "pad",
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
    bg = estimate_background(rgb, alpha) if background is None else parse_colour(background)
    return _fit_into(rgb, alpha, int(size), int(size), bg, fit)


# --------------------------------------------------------------------------- masks


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
    floor = 3.0 * float(np.median(d[_ring((h, w))])) + 0.02
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
    fit: str = "pad",
) -> tuple[np.ndarray, str]:
    """Foreground mask (H, W) bool of an image in its frame, and the method used."""
    if method not in ("auto", "alpha", "file", "threshold", "none"):
        raise ConfigError(f"unknown mask method {method!r}; use auto, alpha, file, threshold or none")
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
        x0, y0, bw, bh = fit_box(mw, mh, w, h, fit)
        mask = np.zeros((h, w), bool)
        _paste(mask, _resize_plane(cover, bw, bh) > 0.5, x0, y0)
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
    fit: str = "pad",
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
    bg = estimate_background(img.rgb, img.alpha) if background is None else parse_colour(background)
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


# --------------------------------------------------------------------------- enhancement


def _paint(mask: np.ndarray, fg: Sequence[float], bg: Sequence[float]) -> np.ndarray:
    """(H, W, 3) float32: ``fg`` where ``mask``, ``bg`` elsewhere (soft masks blend linearly)."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"a mask must be (H, W), got shape {m.shape}")
    f = np.asarray(fg, np.float32).reshape(1, 1, 3)
    b = np.asarray(bg, np.float32).reshape(1, 1, 3)
    if m.dtype == bool:
        return np.where(m[..., None], f, b).astype(np.float32)
    mf = np.clip(m.astype(np.float32), 0.0, 1.0)[..., None]
    return (b + mf * (f - b)).astype(np.float32)


def black_white_targets(direct_mask: np.ndarray, reflected_mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Black-white enhanced targets I_d^e, I_r^e (paper, section 3.4.1, eq. 7-8).

    The direct image's foreground becomes black (0, 0, 0), the reflected
    image's foreground white (1, 1, 1), and both backgrounds light blue
    (0, 0.5, 1), the colour farthest from both black and white.

    Args:
        direct_mask: (H, W) bool (or float coverage in [0, 1]) of the direct image.
        reflected_mask: (H', W') bool (or float) of the reflected image.
    Returns:
        (direct_e (H, W, 3), reflected_e (H', W', 3)) float32 sRGB.
    """
    return _paint(direct_mask, BLACK, LIGHT_BLUE), _paint(reflected_mask, WHITE, LIGHT_BLUE)


def solid_colour_targets(masks: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Solid-colour enhanced targets for the multi-reflection mode (paper, section 4, Fig. 19).

    The foregrounds of the input images are filled with red, green and blue
    in the order given, backgrounds with white. Pass the masks as
    ``[direct, reflected, reflected2]``.

    Args:
        masks: 1 to 3 masks, each (H, W) bool (or float coverage in [0, 1]).
    Returns:
        one (H, W, 3) float32 image per mask.
    """
    if not 1 <= len(masks) <= len(SOLID_COLOURS):
        raise ValueError(f"solid-colour enhancement takes 1 to 3 masks, got {len(masks)}")
    return [_paint(m, c, WHITE) for m, c in zip(masks, SOLID_COLOURS)]
