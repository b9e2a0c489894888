"""Image and array files: a bounded image open, PNG bytes, the ``.npy`` header.

The small helpers every reader and writer of pictures and arrays shares:

* :func:`open_bounded` opens an image from a list of formats and refuses one
  whose header claims more pixels than a limit, before any pixel is decoded;
* :func:`png_bytes` encodes saucerfab's PNGs (one set of encoder options, so
  a design folder or an export is byte-for-byte reproducible);
  :func:`png_bytes_many` several at once, on threads;
* :func:`npy_header` reads an ``.npy`` file's shape and dtype without its data.

Import-light on purpose (numpy here, Pillow inside the functions):
``saucerfab check`` uses it and must not import torch.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator, Mapping, Sequence
from typing import IO, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from PIL import Image

#: zlib level of saucerfab's PNGs (design folders, previews, reports). 3 rather than
#: Pillow's default 6: on a design's 2048 x 1024 texture and 1024 px references it
#: writes 3x faster (0.48 -> 0.16 s, 0.24 -> 0.08 s) for 7-8 % more bytes, which
#: was 1.5 s of a 25 s design (issue 18). The print atlas uses a faster one still
#: (:data:`saucerfab.fabricate.bake.ATLAS_PNG_LEVEL`)
PNG_COMPRESS_LEVEL = 3


class PixelLimitError(Exception):
    """An image's header claims more pixels than its reader's limit.

    Raised by :func:`open_bounded` before any pixel is decoded; every caller
    catches it and words the refusal for its own users.

    Attributes:
        format: Pillow's format name of the image ("PNG", "JPEG"...).
        width, height: the size its header claims, pixels.
        limit: the largest ``width * height`` the caller accepts.
    """

    def __init__(self, format: str, width: int, height: int, limit: int) -> None:
        super().__init__(f"{format} image of {width}x{height} pixels is over the limit of {limit:,} pixels")
        self.format, self.width, self.height, self.limit = format, width, height, limit


@contextlib.contextmanager
def open_bounded(
    source: str | os.PathLike[str] | IO[bytes], formats: Sequence[str], max_pixels: int
) -> Iterator[Image.Image]:
    """Open an image (header only) for a ``with`` block, its pixel count bounded.

    ``Image.open`` reads only the header, so the size check runs before any
    pixel is decoded; ``formats`` keeps Pillow from trying its dozens of
    other (less hardened) decoders on the bytes. Pillow's global
    decompression-bomb guard is left as it is and still applies: its error
    is raised; its warning (over ``Image.MAX_IMAGE_PIXELS`` but under twice
    it) is not shown, since ``max_pixels`` decides here and the caller says
    so in its own words (a raw ``warnings.warn`` line naming Pillow's source
    file would otherwise come before saucerfab's message).

    Args:
        source: a path or a binary file object.
        formats: Pillow format names accepted, e.g. ``("PNG",)``.
        max_pixels: the largest width x height accepted.
    Yields:
        the opened ``PIL.Image.Image`` (closed when the block ends).
    Raises:
        PixelLimitError: width x height is over ``max_pixels``.
        PIL.UnidentifiedImageError (an OSError): not one of ``formats``.
        OSError, PIL.Image.DecompressionBombError, ...: as ``Image.open`` raises.
    """
    import warnings

    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        im = Image.open(source, formats=list(formats))
    with im:
        if im.width * im.height > max_pixels:
            raise PixelLimitError(str(im.format), im.width, im.height, max_pixels)
        yield im


def png_bytes(rgb: np.ndarray, compress_level: int = PNG_COMPRESS_LEVEL) -> bytes:
    """PNG file bytes of an image (no timestamps: the same pixels give the same bytes).

    Args:
        rgb: (H, W, 3) sRGB (or (H, W) grey) values, converted to uint8.
        compress_level: zlib level 0-9 (no ``optimize`` pass, which would
            override it).
    """
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, np.uint8)).save(buf, format="PNG", compress_level=compress_level)
    return buf.getvalue()


#: most threads :func:`png_bytes_many` encodes on
PNG_THREADS_MAX = 8


def png_bytes_many(images: Mapping[str, np.ndarray], compress_level: int = PNG_COMPRESS_LEVEL) -> dict[str, bytes]:
    """:func:`png_bytes` of several images, encoded side by side on threads; the same bytes as one by one.

    Pillow's zlib encoder releases the GIL, so the threads run at once: on two
    cores a design's texture and two reference pictures took 0.17-0.19 s
    instead of 0.34 s. One thread per usable core (at most
    :data:`PNG_THREADS_MAX`), none for a single image.

    Args:
        images: name -> (H, W, 3) or (H, W) image, as :func:`png_bytes` takes.
    Returns:
        name -> PNG bytes, in the order of ``images``.
    """
    from saucerfab.files.machine import usable_cores

    names = list(images)
    threads = min(len(names), usable_cores(), PNG_THREADS_MAX)
    if threads <= 1:
        return {n: png_bytes(images[n], compress_level) for n in names}
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads, thread_name_prefix="saucerfab-png") as pool:
        encoded = list(pool.map(lambda n: png_bytes(images[n], compress_level), names))
    return dict(zip(names, encoded))


def npy_header(path: str | os.PathLike[str]) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) of an ``.npy`` file, read from its header alone (no data loaded).

    Lets a reader refuse a huge or non-numeric array before ``np.load``.

    Raises:
        OSError: the file cannot be read.
        ValueError: not an ``.npy`` file, or a damaged header.
    """
    with open(path, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        # public readers only: numpy 2.x moved the private _read_array_header
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = read(fh)
    return shape, dtype
