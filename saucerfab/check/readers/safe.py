"""Hardened primitives the readers share: bounded files, archives, images, XML, paths.

Each function checks a size or count before the work it bounds:

* :func:`read_file_bounded` - the file size before reading it.
* :class:`SafeZip` - the end-of-central-directory record (entry count,
  directory size) before :mod:`zipfile` parses the directory; every entry
  name (absolute or ``..`` paths refuse the archive); and every extraction,
  read in chunks against a running uncompressed budget, because the sizes
  in zip headers are the attacker's to choose. The budget is the smaller of
  ``Limits.max_uncompressed_bytes`` and an inflation ratio to the archive's
  own size (:func:`inflation_budget`), so a bomb stops early.
* :func:`probe_texture` - the image header's pixel count before decoding,
  against the texture's limit and what is left of its file's
  :class:`TextureBudget`.
* :func:`parse_xml` - defusedxml with DTDs forbidden (so no entity
  expansion, no external entities), after a size and element-count check.
"""

from __future__ import annotations

import io
import os
import posixpath
import struct
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import ReadError, TextureInfo
from saucerfab.files.imageio import PixelLimitError, open_bounded

#: image formats Pillow may decode for a texture; the ones printer software
#: takes (PNG, JPEG) and a few that OBJ/VRML files in the wild use
TEXTURE_FORMATS = ("PNG", "JPEG", "BMP", "TGA", "WEBP", "GIF")


def read_file_bounded(path: Path, limit: int, what: str = "file") -> bytes:
    """The bytes of ``path``, refusing (``over_check_limit``) if it is over ``limit``."""
    try:
        size = path.stat().st_size
        if size > limit:
            raise ReadError("over_check_limit", f"{what} is {size:,} bytes, over the checker's limit of {limit:,}")
        with open(path, "rb") as fh:
            # read(n) allocates n bytes up front: ask for what the file holds (+1 to see it grow), not the limit
            data = fh.read(min(size, limit) + 1)
    except ReadError:
        raise
    except OSError as exc:
        raise ReadError("file_not_found", f"cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > limit:  # grew while we read it
        raise ReadError("over_check_limit", f"{what} is over the checker's limit of {limit:,} bytes")
    return data


def is_unsafe_relpath(name: str) -> bool:
    """True for a path that is absolute, has a drive, a NUL, or a ``..`` component."""
    if not name or "\x00" in name:
        return True
    n = name.replace("\\", "/")
    if n.startswith("/") or (len(n) > 1 and n[1] == ":") or n.startswith("//"):
        return True
    return any(part == ".." for part in n.split("/"))


def resolve_beside(base_dir: Path, ref: str) -> Path | None:
    """``ref`` (from inside a model file) resolved under ``base_dir``; None if it would escape.

    Model files name their textures and material libraries by relative path;
    a file from a stranger must not make the checker read ``/etc/shadow`` or
    ``../../secret.png``, so absolute paths, ``..`` and symlinks leaving the
    folder are refused.
    """
    if is_unsafe_relpath(ref):
        return None
    p = (base_dir / ref.replace("\\", "/")).resolve()
    try:
        p.relative_to(base_dir.resolve())
    except ValueError:
        return None
    return p


# -- archives ---------------------------------------------------------------

_EOCD = b"PK\x05\x06"
_EOCD64_LOC = b"PK\x06\x07"


def inflation_budget(limits: Limits, packed: int) -> tuple[int, str]:
    """(bytes a ``packed``-byte archive or gzip file may inflate to in total, why: the limit to name).

    The absolute budget alone lets a 0.2 MB bomb hand the checker 256 MB to
    hold and scan; real models deflate 4-10:1, so past a free allowance the
    budget is also ``max_inflation_ratio`` times the compressed size.
    """
    absolute = limits.max_uncompressed_bytes
    if limits.max_inflation_ratio > 0:
        by_ratio = max(limits.free_inflation_bytes, int(limits.max_inflation_ratio * packed))
        if by_ratio < absolute:
            return by_ratio, (
                f"{limits.max_inflation_ratio:g} times the {packed:,}-byte file (Limits.max_inflation_ratio; "
                f"the first {limits.free_inflation_bytes:,} bytes are free, Limits.free_inflation_bytes)"
            )
    return absolute, "Limits.max_uncompressed_bytes"


class SafeZip:
    """A zip archive opened with its entry count, names and sizes bounded.

    Part names compare case-insensitively (OPC, which 3MF uses, says so).
    """

    def __init__(self, data: bytes, limits: Limits) -> None:
        self.limits = limits
        self.budget, self.budget_reason = inflation_budget(limits, len(data))
        self._check_eocd(data)
        try:
            self.zf = zipfile.ZipFile(io.BytesIO(data))
            infos = self.zf.infolist()
        except zipfile.BadZipFile as exc:
            raise ReadError("malformed", f"not a valid zip archive: {exc}") from None
        except (OSError, EOFError, ValueError, NotImplementedError, struct.error, zlib.error) as exc:
            raise ReadError("truncated", f"the zip archive is damaged: {exc}") from None
        if len(infos) > limits.max_zip_entries:
            raise ReadError(
                "archive_too_large",
                f"the archive lists {len(infos):,} entries, over the checker's limit of "
                f"{limits.max_zip_entries:,} (Limits.max_zip_entries)",
            )
        self.names: dict[str, zipfile.ZipInfo] = {}
        declared = 0
        for info in infos:
            if is_unsafe_relpath(info.filename):
                raise ReadError(
                    "archive_unsafe_path",
                    f"archive entry {info.filename!r} has an absolute path or '..'; refusing the archive",
                    where={"entry": info.filename},
                )
            self.names[info.filename.lower().lstrip("/")] = info
            declared += max(0, info.file_size)
        if declared > self.budget:
            # headers can lie low (the bounded reads below catch that), and an
            # archive honestly this large is over the limit anyway: refuse early
            raise ReadError(
                "archive_too_large",
                f"the archive declares {declared:,} uncompressed bytes, over the checker's budget of "
                f"{self.budget:,}: {self.budget_reason}",
            )

    def _check_eocd(self, data: bytes) -> None:
        """Entry count and directory size from the end record, before zipfile parses the directory."""
        tail_start = max(0, len(data) - (22 + 65535))
        pos = data.rfind(_EOCD, tail_start)
        if pos < 0:
            raise ReadError("truncated", "zip archive without its end record (truncated or not a zip)")
        rec = data[pos : pos + 22]
        if len(rec) < 22:
            raise ReadError("truncated", "zip end record is cut short")
        _, _, _, _, n_entries, cd_size, cd_offset, _ = struct.unpack("<4s4H2LH", rec)
        loc = pos - 20
        if loc >= 0 and data[loc : loc + 4] == _EOCD64_LOC:
            (off64,) = struct.unpack("<Q", data[loc + 8 : loc + 16])
            rec64 = data[off64 : off64 + 56] if off64 < len(data) else b""
            if len(rec64) == 56 and rec64[:4] == b"PK\x06\x06":
                n_entries, cd_size = struct.unpack("<QQ", rec64[32:48])
        if n_entries > self.limits.max_zip_entries:
            raise ReadError(
                "archive_too_large",
                f"the archive lists {n_entries:,} entries, over the checker's limit of "
                f"{self.limits.max_zip_entries:,} (Limits.max_zip_entries)",
            )
        if cd_size > len(data):
            raise ReadError("truncated", "the zip directory is larger than the file (truncated archive)")

    def has(self, name: str) -> bool:
        return name.lower().lstrip("/") in self.names

    def entry_names(self) -> list[str]:
        return [i.filename for i in self.names.values()]

    def read(self, name: str, cap: int, what: str = "entry") -> bytes:
        """Extract one entry, at most ``cap`` bytes and within the archive's total budget."""
        info = self.names.get(name.lower().lstrip("/"))
        if info is None:
            raise ReadError("malformed", f"the archive has no entry {name!r}")
        limit = min(cap, self.budget)
        # BytesIO grows in place and hands its buffer over without a copy: the entry is held once
        out = io.BytesIO()
        try:
            with self.zf.open(info) as fh:
                while True:
                    chunk = fh.read(min(1 << 20, limit + 1 - out.tell()))
                    if not chunk:
                        break
                    out.write(chunk)
                    if out.tell() > limit:
                        raise ReadError(
                            "archive_too_large",
                            f"{what} {info.filename!r} inflates past {limit:,} bytes (zip bomb?); limit: "
                            + (self.budget_reason if limit == self.budget else f"{limit:,} bytes for this entry"),
                            where={"entry": info.filename},
                        )
        except ReadError:
            raise
        except RuntimeError as exc:  # encrypted entries
            raise ReadError("unsupported_format", f"{what} {info.filename!r}: {exc}") from None
        except NotImplementedError as exc:
            raise ReadError("unsupported_format", f"{what} {info.filename!r}: {exc}") from None
        except (zipfile.BadZipFile, OSError, EOFError, ValueError, struct.error, zlib.error) as exc:
            raise ReadError("truncated", f"{what} {info.filename!r} is damaged: {exc}") from None
        data = out.getvalue()
        del out
        self.budget -= len(data)
        return data


# -- XML --------------------------------------------------------------------


def parse_xml(data: bytes, what: str, limit: int, max_elements: int | None = None) -> Any:
    """An ElementTree root from untrusted ``data``: defusedxml, DTDs forbidden, size and element count bounded.

    ``max_elements`` bounds the tree by its number of ``<`` characters (an
    upper bound on elements): a tree costs ~100-400 bytes per element, so
    its byte size alone lets 4-byte ``<a/>`` elements take 25 times that.
    """
    import defusedxml
    import defusedxml.ElementTree as DET

    if len(data) > limit:
        raise ReadError("over_check_limit", f"{what} is {len(data):,} bytes of XML, over the limit of {limit:,}")
    if max_elements is not None:
        tags = data.count(b"<")
        if tags > max_elements:
            raise ReadError(
                "over_check_limit",
                f"{what} has {tags:,} XML tags to parse into a tree, over the checker's limit of "
                f"{max_elements:,} elements (Limits.max_xml_elements)",
            )
    try:
        return DET.fromstring(data, forbid_dtd=True, forbid_entities=True, forbid_external=True)
    except (defusedxml.DTDForbidden, defusedxml.EntitiesForbidden, defusedxml.ExternalReferenceForbidden) as exc:
        raise ReadError(
            "xml_forbidden",
            f"{what} has a DTD or entity declarations ({type(exc).__name__}); 3MF never needs them, refusing",
        ) from None
    except DET.ParseError as exc:
        raise ReadError("malformed", f"{what} is not well-formed XML: {exc}") from None
    except (ValueError, RecursionError, UnicodeError) as exc:
        raise ReadError("malformed", f"{what} is not usable XML: {exc}") from None


# -- images -----------------------------------------------------------------


def header_size(data: bytes) -> tuple[str, int, int] | None:
    """(format, width, height) read from a PNG or JPEG header without Pillow, or None.

    Pillow refuses to even open an image over twice its global pixel limit,
    and the report should still say how large the bomb claimed to be.
    """
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24 and data[12:16] == b"IHDR":
        w, h = struct.unpack(">II", data[16:24])
        return "PNG", int(w), int(h)
    if data[:3] == b"\xff\xd8\xff":
        i = 2
        while i + 9 < len(data) and i < 1 << 20:  # markers until the frame header
            if data[i] != 0xFF:
                return None
            marker = data[i + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
                i += 2
                continue
            (seg,) = struct.unpack(">H", data[i + 2 : i + 4])
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h, w = struct.unpack(">HH", data[i + 5 : i + 9])
                return "JPEG", int(w), int(h)
            i += 2 + seg
    return None


class TextureBudget:
    """What all of one file's textures may cost together: bytes read and pixels decoded.

    The per-texture limits alone let a file name 64 textures at the largest
    size each, 64 decodes of 1-2 s; every reader makes one budget per file
    and charges each texture before reading or decoding it.
    """

    def __init__(self, limits: Limits) -> None:
        self.bytes_left = limits.max_total_texture_bytes
        self.pixels_left = limits.max_total_texture_pixels

    def over_bytes(self, name: str, n: int) -> str | None:
        """Charge ``n`` bytes read; the refusal message if they are over what is left."""
        if n > self.bytes_left:
            return (f"texture {name!r} is {n:,} bytes, over the {max(self.bytes_left, 0):,} left of the file's "
                    "texture budget (Limits.max_total_texture_bytes); not read")
        self.bytes_left -= n
        return None

    def over_pixels(self, name: str, w: int, h: int) -> str | None:
        """Charge ``w`` x ``h`` pixels about to be decoded; the refusal message if over what is left."""
        if w * h > self.pixels_left:
            return (f"texture {name!r} is {w:,} x {h:,} pixels, over the {max(self.pixels_left, 0):,} pixels left of "
                    "the file's texture budget (Limits.max_total_texture_pixels); not decoded")
        self.pixels_left -= w * h
        return None


def probe_texture(name: str, data: bytes | None, limits: Limits, *, decode: bool = True,
                  budget: TextureBudget | None = None) -> TextureInfo:
    """Check a texture safely: size in bytes, then pixels from the header, then decode.

    ``budget`` is the file's :class:`TextureBudget` (None: only this texture's
    own limits apply). Never raises for a bad image; the returned status
    says what was wrong.
    """
    from PIL import Image, UnidentifiedImageError

    info = TextureInfo(name=name)
    if data is None:
        info.status, info.message = "missing", f"texture {name!r} is not there"
        return info
    if len(data) > limits.max_texture_bytes:
        info.status = "too_large"
        info.message = f"texture {name!r} is {len(data):,} bytes, over the checker's limit of {limits.max_texture_bytes:,}"
        return info
    if budget is not None and (msg := budget.over_bytes(name, len(data))) is not None:
        info.status, info.message = "too_large", msg
        return info
    head = header_size(data)
    charged = False
    if head is not None:
        info.image_format, info.width, info.height = head
        if head[1] * head[2] > limits.max_texture_pixels:
            info.status = "too_large"
            info.message = (
                f"texture {name!r} is {head[1]:,} x {head[2]:,} pixels by its header, over the checker's limit of "
                f"{limits.max_texture_pixels:,} pixels (decompression bomb?); not decoded"
            )
            return info
        if decode and budget is not None:
            charged = True
            if (msg := budget.over_pixels(name, head[1], head[2])) is not None:
                info.status, info.message = "too_large", msg
                return info
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # DecompressionBombWarning: we check pixels ourselves below
            with open_bounded(io.BytesIO(data), TEXTURE_FORMATS, limits.max_texture_pixels) as img:
                w, h = img.size
                info.width, info.height, info.image_format = int(w), int(h), img.format
                if w <= 0 or h <= 0:
                    info.status, info.message = "unreadable", f"texture {name!r} has no pixels ({w} x {h})"
                    return info
                # charged here for a format header_size does not read (BMP, GIF...)
                if (decode and budget is not None and not charged
                        and (msg := budget.over_pixels(name, w, h)) is not None):
                    info.status, info.message = "too_large", msg
                    return info
                if decode:
                    img.load()
                    if limits.keep_texture_pixels:
                        info.pixels = np.asarray(img.convert("RGB"), dtype=np.uint8)
    except PixelLimitError as exc:
        info.width, info.height, info.image_format = exc.width, exc.height, exc.format
        info.status = "too_large"
        info.message = (
            f"texture {name!r} is {exc.width:,} x {exc.height:,} pixels, over the checker's limit of "
            f"{limits.max_texture_pixels:,} pixels (decompression bomb?); not decoded"
        )
    except Image.DecompressionBombError as exc:
        info.status, info.message = "too_large", f"texture {name!r}: {exc}"
    except UnidentifiedImageError:
        info.status = "unreadable"
        info.message = f"texture {name!r} is not an image in a format printers take ({', '.join(TEXTURE_FORMATS)})"
    except (OSError, SyntaxError, ValueError, EOFError, MemoryError, struct.error, IndexError, TypeError,
            zlib.error) as exc:
        info.status, info.message = "unreadable", f"texture {name!r} cannot be decoded: {exc}"
    return info


def load_texture_file(base_dir: Path, ref: str, limits: Limits, budget: TextureBudget | None = None) -> TextureInfo:
    """A texture named by a model file on disk (OBJ map_Kd, PLY TextureFile, VRML url), charged to ``budget``."""
    p = resolve_beside(base_dir, ref)
    if p is None:
        return TextureInfo(
            name=ref, status="unsafe_path",
            message=f"texture path {ref!r} is absolute or leaves the model's folder; not read",
        )
    if not p.is_file():
        return TextureInfo(name=ref, status="missing", message=f"texture {ref!r} is not there (looked for {os.fspath(p)!r})")
    try:
        size = p.stat().st_size
        if size > limits.max_texture_bytes:
            return TextureInfo(
                name=ref, status="too_large",
                message=f"texture {ref!r} is {size:,} bytes, over the checker's limit of {limits.max_texture_bytes:,}",
            )
        if budget is not None and size > budget.bytes_left:  # refuse before reading it (probe_texture charges it)
            return TextureInfo(name=ref, status="too_large", message=str(budget.over_bytes(ref, size)))
        data = p.read_bytes()
    except OSError as exc:
        return TextureInfo(name=ref, status="unreadable", message=f"texture {ref!r} cannot be read: {exc.strerror}")
    return probe_texture(ref, data, limits, budget=budget)


def zip_join(base: str, ref: str) -> str | None:
    """An archive-internal reference resolved against the folder of part ``base``; None if it escapes."""
    ref = ref.replace("\\", "/")
    if "\x00" in ref:
        return None
    if ref.startswith("/"):
        joined = ref.lstrip("/")
    else:
        joined = posixpath.join(posixpath.dirname(base.lstrip("/")), ref)
    parts: list[str] = []
    for part in joined.split("/"):
        if part in ("", "."):
            continue
        if part == "..":
            return None  # escaping or not, '..' in a package reference is not something 3MF writers emit
        parts.append(part)
    return "/".join(parts) if parts else None


# -- resources a model file names (textures, material libraries, buffers) -------------


class Resources:
    """Where a model file's references resolve: its folder on disk, or its folder inside an archive.

    Readers ask for textures and side files by the name the model gives;
    every lookup is confined (no absolute paths, no ``..``) and bounded.
    One instance serves one model file, and its ``budget`` bounds all of
    that file's textures together.
    """

    budget: TextureBudget

    def texture(self, ref: str) -> TextureInfo:
        """The texture named ``ref``, checked (never raises)."""
        raise NotImplementedError

    def read(self, ref: str, cap: int, what: str) -> bytes:
        """The bytes of side file ``ref`` (at most ``cap``); raises ReadError if unsafe, missing or too big."""
        raise NotImplementedError


class DiskResources(Resources):
    """References resolved in the model file's folder."""

    def __init__(self, base_dir: Path, limits: Limits) -> None:
        self.base = base_dir
        self.limits = limits
        self.budget = TextureBudget(limits)

    def texture(self, ref: str) -> TextureInfo:
        return load_texture_file(self.base, ref, self.limits, self.budget)

    def read(self, ref: str, cap: int, what: str) -> bytes:
        p = resolve_beside(self.base, ref)
        if p is None:
            raise ReadError("archive_unsafe_path", f"{what} {ref[:80]!r} is absolute or leaves the model's folder")
        if not p.is_file():
            raise ReadError("truncated", f"{what} {ref[:80]!r} is not there")
        return read_file_bounded(p, cap, what)


def read_texture_entry(zf: SafeZip, target: str, name: str, limits: Limits, *,
                       damaged: str = "unreadable") -> bytes | TextureInfo:
    """The bytes of archive entry ``target``, a texture its model calls ``name``, or a TextureInfo saying why not.

    Never raises: an entry that is not there is ``missing``; one that
    inflates past ``Limits.max_texture_bytes`` or the archive's budget is
    ``too_large``; one that cannot be read (damaged, encrypted) gets the
    status ``damaged`` (the 3MF reader has always reported those as
    ``too_large``).
    """
    if not zf.has(target):
        return TextureInfo(name=name, status="missing", message=f"texture {name!r} is not in the archive")
    try:
        return zf.read(target, limits.max_texture_bytes, "texture")
    except ReadError as exc:
        return TextureInfo(name=name, status="too_large" if exc.code == "archive_too_large" else damaged,
                           message=exc.message)


class ZipResources(Resources):
    """References resolved beside an entry inside an archive (a zipped OBJ + MTL + PNG)."""

    def __init__(self, zf: SafeZip, entry: str, limits: Limits) -> None:
        self.zf = zf
        self.entry = entry
        self.limits = limits
        self.budget = TextureBudget(limits)

    def texture(self, ref: str) -> TextureInfo:
        target = zip_join(self.entry, ref)
        if target is None or is_unsafe_relpath(ref.lstrip("/")):
            return TextureInfo(name=ref, status="unsafe_path",
                               message=f"texture path {ref!r} is absolute or leaves the archive folder; not read")
        data = read_texture_entry(self.zf, target, ref, self.limits)
        if isinstance(data, TextureInfo):
            return data
        return probe_texture(ref, data, self.limits, budget=self.budget)

    def read(self, ref: str, cap: int, what: str) -> bytes:
        target = zip_join(self.entry, ref)
        if target is None or is_unsafe_relpath(ref.lstrip("/")):
            raise ReadError("archive_unsafe_path", f"{what} {ref[:80]!r} leaves the archive folder")
        if not self.zf.has(target):
            raise ReadError("truncated", f"{what} {ref[:80]!r} is not in the archive")
        return self.zf.read(target, cap, what)
