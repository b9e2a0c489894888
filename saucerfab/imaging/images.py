"""Input images: safe loading, colours, the background meant around a picture.

The optimizer's two (or three) input images reach it through this module
and :mod:`saucerfab.imaging.masks`:

1. :func:`load_image` reads a PNG, JPEG or WebP file safely: the file size
   and the pixel count (from the header, before any pixel is decoded) are
   checked against limits, EXIF orientation is applied, an embedded ICC
   profile is converted to sRGB, and every pixel mode becomes ``rgb``
   (H, W, 3) float32 sRGB values in [0, 1] plus ``alpha`` (H, W) float32 or
   ``None``. Like the paper, everything works on sRGB values (no
   linearisation).
2. :func:`saucerfab.imaging.fitting.fit_square` puts an image of any aspect ratio
   into the square S x S view frame (the **fit rule**, :mod:`saucerfab.imaging.fitting`).
3. :func:`saucerfab.imaging.masks.foreground_mask` finds the subject: the alpha
   channel, a mask file the user gives, or an automatic colour-distance
   threshold.

:func:`saucerfab.imaging.masks.prepare_image` does 1-3 in one call and returns a
:class:`ViewImage`. The paper's enhanced targets made from the masks are
in :mod:`saucerfab.optimize.enhancement`.

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
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, ImageError, SaucerfabError
from saucerfab.files.imageio import PixelLimitError, open_bounded

#: default limits for untrusted images (checked before decoding)
DEFAULT_MAX_PIXELS = 64_000_000
DEFAULT_MAX_BYTES = 200_000_000

#: the Pillow formats we decode; "MPO" is what Pillow calls a multi-picture
#: JPEG (phone cameras), whose first picture is the ordinary JPEG image
ACCEPTED_FORMATS = ("PNG", "JPEG", "WEBP")
_DECODED_FORMATS = ("PNG", "JPEG", "MPO", "WEBP")

#: white, sRGB in [0, 1]: the background of a subject on a transparent canvas
#: (and of the solid-colour enhanced targets, saucerfab.optimize.enhancement)
WHITE = (1.0, 1.0, 1.0)
#: pictures whose border colours lie farther apart than this (Euclidean over the three sRGB channels in
#: [0, 1]) share one ground outside the frames (:func:`piece_ground`). Below verify's stray distance (0.25)
#: on purpose: tree-note's grey and white grounds, 0.17 apart, left white streaks of the cup's ground
#: across the saucer's grey (the slopes and plate the cup shows) that a person sees; heart-star's cream
#: and white, 0.07 apart, do not show.
ONE_GROUND_DISTANCE = 0.1

#: width of the border ring the background colour is estimated from, as a
#: fraction of the image's short side
BORDER_RING_FRACTION = 0.02
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

    Made by :func:`saucerfab.imaging.masks.prepare_image`.

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


def border_ring(shape: tuple[int, int], fraction: float = BORDER_RING_FRACTION) -> np.ndarray:
    """(H, W) bool: the outer ring ``ceil(fraction * min(H, W))`` pixels wide (>= 1)."""
    h, w = shape
    k = max(1, math.ceil(fraction * min(h, w)))
    ring = np.zeros((h, w), bool)
    ring[:k] = ring[-k:] = True
    ring[:, :k] = ring[:, -k:] = True
    return ring


def intended_background(
    picture: np.ndarray | None, background: Any = None, alpha: np.ndarray | None = None
) -> np.ndarray | None:
    """The background a design means around a picture: its ``--background`` if given, else the picture's border colour.

    One rule for the padding of a fitted picture (:func:`fit_square`,
    :func:`saucerfab.imaging.masks.prepare_image`), what verify's whole view expects
    outside a frame, and the colour the export gives the walls, base and cup
    seat (the last two take the colour a design.json records through
    :func:`recorded_background`).

    Args:
        picture: (H, W, 3) float picture in [0, 1], or None.
        background: ``#rrggbb`` or three floats in [0, 1], or None.
        alpha: (H, W) or None: only ring pixels at least half opaque count.

    Returns:
        (3,) float sRGB in [0, 1], or None when neither is known.

    Raises:
        ConfigError: ``background`` is not a colour.
    """
    if background is not None:
        return parse_colour(background)
    return None if picture is None else estimate_background(picture, alpha)


def colour_hex(colour: Sequence[float] | np.ndarray) -> str:
    """``#rrggbb`` of a (3,) sRGB colour in [0, 1] (clipped)."""
    return "#" + "".join(f"{round(float(c) * 255):02x}" for c in np.clip(np.asarray(colour, np.float64), 0, 1))


def piece_ground(pictures: dict[str, np.ndarray], background: str | None = None) -> str | None:
    """The one colour every view's surround aims at, ``#rrggbb``; None: each picture keeps its own.

    The design's ``--background`` when given. Else, when two pictures' border
    colours lie farther apart than :data:`ONE_GROUND_DISTANCE`, the direct
    picture's border colour (the first of ``pictures``): the plate the cup
    stands on is seen beside the cup and, in the mirror, under the reflected
    picture, so with two grounds one of the two surrounds shows the other's
    colour there (two photographs: 11-27 % of a surround); with one, neither.
    Pictures whose grounds already read as one colour keep their own, so no
    frame's edge shows against a slightly different ground.

    Args:
        pictures: view name -> (H, W, 3) float picture in [0, 1], the direct one first
            (alpha already flattened onto its background).
        background: the design's ``--background`` or None.
    """
    if background is not None:
        return background
    grounds = [estimate_background(np.asarray(p, np.float64)) for p in pictures.values()]
    apart = max((float(np.linalg.norm(a - b)) for i, a in enumerate(grounds) for b in grounds[i + 1:]), default=0.0)
    return colour_hex(grounds[0]) if apart > ONE_GROUND_DISTANCE else None


def recorded_background(parameters: Any) -> str | None:
    """The colour a design.json's ``parameters`` record for what lies outside the frames, or None.

    Its ``background`` (the design's ``--background``), else its ``ground``
    (the one ground :func:`piece_ground` chose for pictures whose border
    colours differ). None too for a value that is not a colour (design checked
    it, so only a damaged file has one): each picture's own border colour
    stands for it then, in the export's walls and in verify's whole view alike.
    """
    if not isinstance(parameters, dict):
        return None
    value = parameters.get("background")
    if value is None:
        value = parameters.get("ground")
    if value is None:
        return None
    try:
        parse_colour(value)
    except SaucerfabError:
        return None
    return value


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
    ring = border_ring(rgb.shape[:2])
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
