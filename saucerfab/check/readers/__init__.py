"""Safe readers, one per format, and the dispatcher that picks one by content.

The format comes from the file's first bytes (magic numbers, headers), not
its name: a PNG named ``.obj`` is "not a mesh", and a 3MF named ``.stl`` is
read as 3MF with an ``extension_mismatch`` warning. Each reader raises
:class:`~saucerfab.check.meshdata.ReadError` with an unreadable code for
anything it cannot read, and bounds sizes and counts before allocating.

Which formats there are, their suffixes, magic numbers and readers are rows
of :data:`saucerfab.files.formats.TABLE`; this module only sniffs and dispatches
(and unpacks the containers: zip and gzip).
"""

from __future__ import annotations

import gzip
import io
import os
import zlib
from pathlib import Path

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import MeshData, ReadError
from saucerfab.check.readers.safe import Resources
from saucerfab.check.report import finding
from saucerfab.files.formats import READERS

#: file suffix -> format key used in reports and printer profiles
EXTENSIONS = {suffix: f.key for f in READERS.values() for suffix in f.suffixes}

_IMAGES = (
    (b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
    (b"%PDF", "a PDF document"), (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"),
    (b"\x7fELF", "an executable"), (b"MZ", "a Windows executable"), (b"Rar!", "a RAR archive"),
    (b"7z\xbc\xaf", "a 7-Zip archive"), (b"BZh", "a bzip2 file"), (b"\xfd7zXZ", "an xz file"),
)


def sniff(head: bytes, size: int, ext: str) -> str:
    """The format ``head`` (the first bytes) shows, or raise ``not_a_mesh``/``unsupported_format``."""
    from saucerfab.check.readers.stl import looks_binary

    for f in READERS.values():
        if head.startswith(f.magic):
            return f.key
    if head.startswith(b"\x1f\x8b"):
        return "gzip"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        raise ReadError("not_a_mesh", "the file is a WebP image, not a mesh")
    for magic, what in _IMAGES:
        if head.startswith(magic):
            raise ReadError("not_a_mesh", f"the file is {what}, not a mesh")
    if looks_binary(head, size):
        return "stl"
    stripped = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if stripped[:5].lower() == b"solid" and (b"facet" in head.lower() or size < len(head) + 1):
        return "stl"
    if stripped.startswith(b"{") and b'"asset"' in head or (ext == "gltf" and stripped.startswith(b"{")):
        return "gltf"
    if b"\x00" in head:
        if ext == "stl":
            return "stl"  # a binary STL whose size is off: its reader says how
        raise ReadError("not_a_mesh", "the file is binary data of no mesh format the checker knows")
    if ext == "stl" and stripped[:5].lower() == b"solid":
        return "stl"
    text_like = b"\nv " in head or head.startswith(b"v ") or b"\nf " in head or b"mtllib" in head or b"\nvt " in head
    if ext == "obj" or text_like:
        return "obj"
    if ext in READERS:
        return ext
    # worded as ever (not from the table): check reports stay byte-identical to earlier ones
    raise ReadError("not_a_mesh", "the content is not a mesh format the checker reads (3MF, OBJ, STL, PLY, GLB/glTF, VRML)")


def read_mesh(path: str | os.PathLike[str], limits: Limits) -> MeshData:
    """Read any supported mesh file safely; raise :class:`ReadError` if it cannot be read."""
    from saucerfab.check.readers.safe import read_file_bounded

    p = Path(path)
    try:
        if not p.is_file():
            raise ReadError("file_not_found", f"{os.fspath(p)!r} does not exist or is not a file")
        size = p.stat().st_size
    except OSError as exc:
        raise ReadError("file_not_found", f"cannot open {os.fspath(p)!r}: {exc.strerror or exc}") from None
    if size == 0:
        raise ReadError("empty_file", "the file is empty (0 bytes)")
    with open(p, "rb") as fh:
        head = fh.read(4096)
    name = p.name.lower()
    ext = EXTENSIONS.get(Path(name[:-3] if name.endswith(".gz") else name).suffix, "")
    fmt = sniff(head, size, ext)
    if size > limits.max_file_bytes:
        from saucerfab.check.readers.stl import binary_count, looks_binary

        # a binary STL is read by its header's count, not whole: its reader refuses it naming that count
        if not (fmt == "stl" and looks_binary(head, size) and (binary_count(head) or 0) > limits.max_triangles):
            raise ReadError(
                "over_check_limit",
                f"the file is {size:,} bytes, over the checker's limit of {limits.max_file_bytes:,} "
                f"(Limits.max_file_bytes); {raise_hint()}",
            )
    if fmt == "gzip":
        data = _gunzip(read_file_bounded(p, limits.max_file_bytes, "file"), limits)
        if not data.startswith(b"#VRML"):
            raise ReadError("not_a_mesh", "a gzip file that does not hold VRML (only .wrz/.wrl.gz are read compressed)")
        fmt = "wrl"
        md = READERS[fmt].load_reader()(p, data, limits, None)
    elif (path_reader := READERS[fmt].load_path_reader()) is not None:
        md = path_reader(p, head, size, limits)
    else:
        md = READERS[fmt].load_reader()(p, read_file_bounded(p, limits.max_file_bytes, "file"), limits, None)
    if ext and ext != md.format and not (ext == "glb" and md.format == "gltf") and not (ext == "3mf" and fmt == "3mf"):
        md.notes.insert(0, finding(
            "extension_mismatch",
            f"the file is named .{ext} but holds {md.format.upper()}"
            + (" in a zip" if fmt == "3mf" else "") + "; rename it so printer software reads it right",
        ))
    return md


def read_stl_bytes(p: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """An STL held in memory (from an archive), through the reader contract of :mod:`saucerfab.files.formats`."""
    from saucerfab.check.readers.stl import read_stl

    return read_stl(p, data[:4096], len(data), limits, data)


def read_gltf_json(p: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """A JSON glTF (the glTF reader builds it as ``glb``: say which it was)."""
    from saucerfab.check.readers.gltf import read_gltf

    md = read_gltf(p, data, limits, res)
    md.format = "gltf"
    return md


def read_zip(p: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """A 3MF package; or one OBJ/PLY/VRML/glTF/STL with its textures zipped together (a bureau upload).

    ``res`` is not used: a zip is read whole, never from inside another archive.
    """
    from saucerfab.check.readers.safe import SafeZip, ZipResources
    from saucerfab.check.readers.threemf import has_model_part, read_3mf

    zf = SafeZip(data, limits)
    if has_model_part(zf):
        md = read_3mf(zf, limits)
        md.format = "3mf"
        return md
    meshes = [n for n in zf.entry_names()
              if Path(n).suffix.lower() in EXTENSIONS and not n.startswith("__MACOSX/") and not n.endswith("/")]
    if not meshes:
        raise ReadError("not_a_mesh", "a zip archive with neither a 3MF model nor a mesh file")
    if len(meshes) > 1:
        raise ReadError("unsupported_format", f"the zip holds {len(meshes)} mesh files ({', '.join(meshes[:4])}); "
                                              "check them one at a time")
    entry = meshes[0]
    inner = zf.read(entry, limits.max_file_bytes, "mesh entry")
    if not inner:
        raise ReadError("empty_file", f"the zip's {entry!r} is empty")
    ext = EXTENSIONS[Path(entry).suffix.lower()]
    fmt = sniff(inner[:4096], len(inner), ext)
    if fmt in ("3mf", "gzip"):
        raise ReadError("unsupported_format", f"{entry!r} in the zip is itself compressed; unpack it first")
    md = READERS[fmt].load_reader()(p, inner, limits, ZipResources(zf, entry, limits))
    md.notes.append(finding("from_archive", f"{md.format.upper()} read from {entry!r} inside the zip, with its "
                                            "material library and textures from beside it in the archive"))
    return md


def _gunzip(raw: bytes, limits: Limits) -> bytes:
    """Decompress with the output bounded as it streams (a gzip bomb stops at the budget, not at its end).

    The budget is the archives' (:func:`~saucerfab.check.readers.safe.inflation_budget`):
    ``Limits.max_uncompressed_bytes``, and past ``Limits.free_inflation_bytes``
    at most ``Limits.max_inflation_ratio`` times the compressed size.
    """
    from saucerfab.check.readers.safe import inflation_budget

    budget, reason = inflation_budget(limits, len(raw))
    out = io.BytesIO()  # grows in place; getvalue() hands the buffer over without a copy
    try:
        with gzip.GzipFile(fileobj=io.BytesIO(raw)) as gz:
            while chunk := gz.read(1 << 20):
                out.write(chunk)
                if out.tell() > budget:
                    raise ReadError(
                        "archive_too_large",
                        f"the gzip file inflates past {budget:,} bytes (a gzip bomb?); limit: {reason}",
                    )
    except (OSError, EOFError, zlib.error) as exc:
        raise ReadError("truncated", f"the gzip data is damaged: {exc}") from None
    return out.getvalue()
