"""Draco meshes of glTF's ``KHR_draco_mesh_compression``: bounded before decoding, decoded by DracoPy.

The decoding itself is Google's Draco decoder (DracoPy). What the checker adds is the bound: the
Draco stream states its face count and its vertex (or point) count near its start, after a fixed
header and optional metadata, so they are read here first (``stream_counts``) and the caller holds
them against the primitive's accessor counts, which the scene's cost pricing has already checked
against ``Limits``. Only then is the stream handed to the decoder, whose output is checked again.

The header layout (Draco bitstream 2.2, the version the glTF extension names as normative):
``"DRACO"``, major, minor, encoder type (1: triangular mesh), encoder method (0: sequential,
1: edgebreaker), flags (uint16, 0x8000: metadata follows). Sequential connectivity starts with
``num_faces`` and ``num_points`` (varUI32); edgebreaker connectivity with the traversal type (uint8),
``num_encoded_vertices`` and ``num_faces`` (varUI32).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np


class DracoError(ValueError):
    """A Draco stream the checker refuses (the message says why)."""

    def __init__(self, message: str, code: str = "malformed") -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class DracoCounts:
    """What a Draco mesh stream says it holds, read before decoding."""

    version: tuple[int, int]
    method: str  # "sequential" or "edgebreaker"
    faces: int
    vertices: int  # num_points (sequential) or num_encoded_vertices (edgebreaker)


class _Reader:
    def __init__(self, data: bytes, pos: int = 0) -> None:
        self.data = data
        self.pos = pos

    def u8(self) -> int:
        if self.pos >= len(self.data):
            raise DracoError("the Draco stream ends inside its header")
        v = self.data[self.pos]
        self.pos += 1
        return v

    def skip(self, n: int) -> None:
        if self.pos + n > len(self.data):
            raise DracoError("the Draco stream ends inside its metadata")
        self.pos += n

    def var32(self) -> int:
        v = 0
        for i in range(5):
            b = self.u8()
            v |= (b & 0x7F) << (7 * i)
            if b < 0x80:
                if v >= 1 << 32:
                    raise DracoError("a Draco varUI32 is over 32 bits")
                return v
        raise DracoError("a Draco varUI32 is longer than 5 bytes")


def _skip_metadata(r: _Reader, depth: int, max_depth: int) -> None:
    if depth > max_depth:
        raise DracoError(f"Draco metadata nests deeper than {max_depth}")
    entries = r.var32()
    if entries * 2 > len(r.data) - r.pos:  # each entry takes at least two size bytes
        raise DracoError("Draco metadata lists more entries than its stream has bytes")
    for _ in range(entries):
        r.skip(r.u8())
        r.skip(r.u8())
    subs = r.var32()
    if subs * 3 > len(r.data) - r.pos:
        raise DracoError("Draco metadata lists more sub-records than its stream has bytes")
    for _ in range(subs):
        r.skip(r.u8())
        _skip_metadata(r, depth + 1, max_depth)


def stream_counts(data: bytes, max_nesting: int = 32) -> DracoCounts:
    """The face and vertex counts a Draco mesh stream states, without decoding it."""
    if len(data) < 11 or data[:5] != b"DRACO":
        raise DracoError("the bufferView does not hold a Draco stream (no 'DRACO' signature)")
    major, minor, etype, method = data[5], data[6], data[7], data[8]
    (flags,) = struct.unpack_from("<H", data, 9)
    if (major, minor) != (2, 2):
        raise DracoError(f"Draco bitstream version {major}.{minor}; KHR_draco_mesh_compression streams are 2.2",
                         code="unsupported_format")
    if etype != 1:
        raise DracoError(f"the Draco stream is not a triangular mesh (encoder type {etype})")
    if method not in (0, 1):
        raise DracoError(f"unknown Draco encoder method {method}")
    r = _Reader(data, 11)
    if flags & 0x8000:
        n_att = r.var32()
        if n_att > len(data) - r.pos:
            raise DracoError("Draco metadata lists more attributes than its stream has bytes")
        for _ in range(n_att):
            r.var32()  # the attribute's id
            _skip_metadata(r, 0, max_nesting)
        _skip_metadata(r, 0, max_nesting)
    if method == 0:
        faces = r.var32()
        vertices = r.var32()
        return DracoCounts((major, minor), "sequential", faces, vertices)
    r.u8()  # traversal decoder type
    vertices = r.var32()
    faces = r.var32()
    return DracoCounts((major, minor), "edgebreaker", faces, vertices)


def decode(data: bytes) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """(faces (m, 3) int64, {attribute unique id: (n, components) array}) of a Draco mesh stream."""
    import DracoPy

    try:
        mesh = DracoPy.decode(bytes(data))
    except Exception as exc:
        # DracoPy says "not draco encoded" for every failure; the signature was checked, so it is corrupt
        raise DracoError(f"the Draco stream is corrupt: Google's Draco decoder refuses it ({type(exc).__name__})"
                         ) from None
    faces = getattr(mesh, "faces", None)
    if faces is None:
        raise DracoError("the Draco stream decodes to a point cloud, not a mesh")
    faces = np.asarray(faces).reshape(-1, 3).astype(np.int64)
    attrs: dict[int, np.ndarray] = {}
    for a in getattr(mesh, "attributes", []) or []:
        a = dict(a) if not isinstance(a, dict) else a
        uid = a.get("unique_id")
        arr = a.get("data")
        if uid is None or arr is None:
            continue
        arr = np.asarray(arr)
        attrs[int(uid)] = arr[:, None] if arr.ndim == 1 else arr.reshape(arr.shape[0], -1)
    return faces, attrs


def attribute(attrs: dict[int, Any], uid: int, what: str) -> np.ndarray:
    if uid not in attrs:
        raise DracoError(f"the Draco stream has no attribute with id {uid} (for {what})")
    return attrs[uid]
