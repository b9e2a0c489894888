"""STL reader (binary and ASCII); STL carries no units and no colour we trust.

Binary STL states its triangle count in the header; the count is checked
against the file size and the triangle cap before anything is read, so a
header claiming a billion triangles costs nothing. ASCII STL counts its
``vertex`` keywords first. Each facet has its own three vertices; the
checks weld identical positions.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError
from saucerfab.check.readers.safe import read_file_bounded

_BIN_DTYPE = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_NUM = rb"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?(?:nan|inf|infinity)"
_SOLID = re.compile(rb"\s*solid", re.IGNORECASE)
#: bytes lowered at a time to count keywords
_COUNT_SLICE = 16 << 20
_VERTEX = re.compile(rb"vertex[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")", re.IGNORECASE)


def binary_count(head: bytes) -> int | None:
    """The triangle count a binary STL header states, or None if too short."""
    if len(head) < 84:
        return None
    return int(struct.unpack("<I", head[80:84])[0])


def looks_binary(head: bytes, size: int) -> bool:
    """True when the size matches the header's triangle count exactly."""
    n = binary_count(head)
    return n is not None and size == 84 + 50 * n


def read_stl(path: Path, head: bytes, size: int, limits: Limits, data: bytes | None = None) -> MeshData:
    """Read an STL file (binary when its size matches its count, else ASCII); ``data``: its bytes if in memory."""
    b = MeshBuilder("stl", limits)
    n = binary_count(head)
    ascii_like = head.lstrip()[:5].lower() == b"solid" and b"facet" in head.lower()
    exact = n is not None and size == 84 + 50 * n
    if n is not None and (exact or not ascii_like):
        need = 84 + 50 * n
        if size < need:
            raise ReadError(
                "truncated",
                f"binary STL header states {n:,} triangles ({need:,} bytes) but the file has {size:,} bytes",
            )
        b.reserve(3 * n, n, "the STL")
        if data is not None:
            body = data[84 : 84 + 50 * n]
        else:
            with open(path, "rb") as fh:
                fh.seek(84)
                body = fh.read(50 * n)
        if len(body) < 50 * n:
            raise ReadError("truncated", "the STL ended while it was being read")
        if size > need:
            b.note("ignored_content", f"{size - need:,} bytes after the last STL triangle were ignored")
        recs = np.frombuffer(body, dtype=_BIN_DTYPE, count=n)
        V = recs["v"].reshape(-1, 3).astype(np.float64)
        b.add(V, np.arange(3 * n, dtype=np.int64).reshape(-1, 3), what="STL")
        return b.build(units="millimeter (assumed; STL has no units)")
    if data is None:
        data = read_file_bounded(path, limits.max_file_bytes, "STL file")
    return _read_ascii(data, b, limits)


def _count_words(data: bytes, words: tuple[bytes, ...]) -> list[int]:
    """Case-insensitive counts of ``words`` (no newline in them) in ``data``, lowering 16 MiB at a time.

    ``data.lower()`` whole would hold a second copy of the file (up to
    ``Limits.max_file_bytes``) for as long as the read takes.
    """
    counts = [0] * len(words)
    pos = 0
    while pos < len(data):
        end = data.rfind(b"\n", pos, pos + _COUNT_SLICE) + 1 if pos + _COUNT_SLICE < len(data) else len(data)
        if end <= pos:  # a line longer than a slice: a word may straddle; count up to the next newline
            nl = data.find(b"\n", pos + _COUNT_SLICE)
            end = len(data) if nl < 0 else nl + 1
        piece = data[pos:end].lower()
        for i, w in enumerate(words):
            counts[i] += piece.count(w)
        pos = end
    return counts


def _read_ascii(data: bytes, b: MeshBuilder, limits: Limits) -> MeshData:
    if not _SOLID.match(data):
        raise ReadError("malformed", "neither a binary STL (size does not match its count) nor an ASCII one ('solid')")
    n_vertex, n_facet = _count_words(data, (b"vertex", b"endfacet"))
    b.reserve(n_vertex, n_vertex // 3, "the ASCII STL")
    if n_facet == 0:
        raise ReadError("no_triangles", "the ASCII STL has no facets")
    vals = _VERTEX.findall(data)
    if len(vals) != n_vertex or n_vertex != 3 * n_facet:
        raise ReadError(
            "malformed",
            f"ASCII STL has {n_facet:,} facets but {len(vals):,} readable vertex lines of {n_vertex:,} "
            "(each facet needs exactly 3 'vertex x y z')",
        )
    if b"endsolid" not in data[-1024:].lower():
        raise ReadError("truncated", "the ASCII STL ends without 'endsolid'")
    V = np.array(vals, dtype=np.float64)
    b.add(V, np.arange(len(V), dtype=np.int64).reshape(-1, 3), what="STL")
    return b.build(units="millimeter (assumed; STL has no units)")
