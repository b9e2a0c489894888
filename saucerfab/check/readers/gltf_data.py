"""glTF 2.0 data access: JSON fields type-checked, buffers, buffer views and accessors bounded.

The first half of the glTF reader (:mod:`saucerfab.check.readers.gltf` walks
the scene and decodes meshes on top of it). Every number in the JSON is the
attacker's, so each field is type-checked where it is used, and every
accessor is bounded against its buffer view and every view against its
buffer (offset + stride x (count - 1) + element size) before an array is
made. Buffers naming the same URI share one read, and all of a file's
buffer bytes together are bounded (``Limits.max_buffer_bytes``), decoded
meshopt views included (charged before decoding). Sparse accessors are read
with their counts and indices bounded; an accessor without a bufferView
reads as zeros.
"""

from __future__ import annotations

import base64
import binascii
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers.safe import Resources

_COMPONENT = {5120: "i1", 5121: "u1", 5122: "i2", 5123: "u2", 5125: "u4", 5126: "f4"}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORM = {"i1": 127.0, "u1": 255.0, "i2": 32767.0, "u2": 65535.0}
_INDEX_TYPES = (5121, 5123, 5125)
_MESHOPT = ("KHR_meshopt_compression", "EXT_meshopt_compression")


def _bad(msg: str) -> ReadError:
    return ReadError("malformed", f"glTF: {msg}")


def _list(d: Any, key: str) -> list[Any]:
    v = d.get(key, []) if isinstance(d, dict) else None
    if not isinstance(v, list):
        raise _bad(f"'{key}' is not a list")
    return v


def _dict(v: Any, what: str) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise _bad(f"{what} is not an object")
    return v


def _whole(v: Any) -> int | None:
    """``v`` as an int when it is a JSON integer, written as ``3`` or ``3.0`` (JSON has one number type,
    and the glTF-Validator takes both); else None (booleans, fractions, strings, inf/nan)."""
    if isinstance(v, bool):
        return None
    if isinstance(v, int):
        return v
    if isinstance(v, float) and v.is_integer():
        return int(v)
    return None


def _int(d: dict[str, Any], key: str, default: int | None = None, what: str = "") -> int:
    v = _whole(d.get(key, default))
    if v is None:
        raise _bad(f"{what or key}: '{key}' is missing or not an integer")
    if v < 0:
        raise _bad(f"{what or key}: '{key}' is negative")
    return v


def _item(seq: list[Any], i: Any, what: str) -> dict[str, Any]:
    j = _whole(i)
    if j is None:
        raise _bad(f"a {what} index {i!r} is not an integer")
    i = j
    if not 0 <= i < len(seq):
        raise ReadError("index_out_of_range", f"glTF: {what} {i} does not exist (there are {len(seq)})")
    return _dict(seq[i], f"{what} {i}")


class GltfData:
    """A glTF document's data: buffers (GLB chunk, data: URIs, files beside it), views and accessors."""

    def __init__(self, doc: Any, buffers: list[bytes | None], res: Resources, limits: Limits) -> None:
        self.doc = _dict(doc, "the glTF document")
        self.buffers = buffers
        self.res = res
        self.limits = limits
        self._buf_cache: dict[int, bytes] = {}
        self._view_cache: dict[int, memoryview] = {}
        # buffers naming the same URI share one read; all URIs together are bounded by Limits.max_buffer_bytes
        self._uri_cache: dict[str, bytes] = {}
        self.buffer_bytes = 0

    # ---- data
    def buffer(self, i: int, by: str = "") -> bytes:
        if i in self._buf_cache:
            return self._buf_cache[i]
        bufs = _list(self.doc, "buffers")
        d = _item(bufs, i, "buffer")
        length = _int(d, "byteLength", what=f"buffer {i}")
        uri = d.get("uri")
        if uri is None:
            data = self.buffers[i] if i < len(self.buffers) else None
            if data is None:
                exts = d.get("extensions")
                fallback = isinstance(exts, dict) and any(
                    isinstance(exts.get(k), dict) and exts[k].get("fallback") for k in _MESHOPT)
                what = f"glTF buffer {i} ({length:,} bytes{', read by ' + by if by else ''})"
                if fallback:
                    raise _bad(f"{what[5:]} is a meshopt fallback placeholder without data; only bufferViews "
                               "with the meshopt extension may name it")
                if i == 0 and self.buffers:
                    raise ReadError("truncated", f"{what} has no uri and the GLB has no binary chunk for it")
                # the glTF specification leaves a buffer without uri (other than a GLB's first) to
                # extensions: valid, but its bytes are not in this file and no extension read here fills them
                raise ReadError("unsupported_format", f"{what} has no uri and is not a GLB binary chunk, so its "
                                                      "data are not in the file (the glTF specification leaves such "
                                                      "buffers to extensions; the checker reads none that fills them)")
        elif isinstance(uri, str):
            data = self._buffer_uri(uri, f"buffer {i}")
        else:
            raise _bad(f"buffer {i} uri is not a string")
        if len(data) < length:
            raise ReadError("truncated", f"glTF buffer {i} declares {length:,} bytes but has {len(data):,}")
        self._buf_cache[i] = data
        return data

    def _buffer_uri(self, uri: str, what: str) -> bytes:
        """The bytes ``uri`` names: read once however many buffers name it, all URIs within one budget."""
        if uri in self._uri_cache:
            return self._uri_cache[uri]
        left = self.limits.max_buffer_bytes - self.buffer_bytes
        cap = min(self.limits.max_file_bytes, left)
        if cap < self.limits.max_file_bytes:  # the file's budget binds: say so in any refusal
            what = f"{what} (with {left:,} bytes left of Limits.max_buffer_bytes for all buffers)"
        data = self._uri_bytes(uri, cap, what)
        self.buffer_bytes += len(data)
        self._uri_cache[uri] = data
        return data

    def _uri_bytes(self, uri: str, cap: int, what: str) -> bytes:
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if ";base64" not in head:
                raise ReadError("unsupported_format", f"glTF {what}: only base64 data URIs are read")
            if len(payload) * 3 // 4 > cap:
                raise ReadError("over_check_limit", f"glTF {what}: data URI over {cap:,} bytes")
            try:
                return base64.b64decode(payload, validate=True)
            except (binascii.Error, ValueError):
                raise _bad(f"{what}: data URI is not valid base64") from None
        return self.res.read(uri, cap, f"glTF {what}")

    def _charge(self, nbytes: int, what: str) -> None:
        """Count ``nbytes`` of decoded data against ``Limits.max_buffer_bytes`` before making them."""
        left = self.limits.max_buffer_bytes - self.buffer_bytes
        if nbytes > left:
            raise ReadError("over_check_limit", f"glTF {what} would decode to {nbytes:,} bytes, over the "
                                                f"{left:,} bytes left of Limits.max_buffer_bytes for the file")
        self.buffer_bytes += nbytes

    def view_bytes(self, i: int) -> memoryview:
        if i in self._view_cache:
            return self._view_cache[i]
        bv = _item(_list(self.doc, "bufferViews"), i, "bufferView")
        exts = bv.get("extensions")
        key = next((k for k in _MESHOPT if isinstance(exts, dict) and k in exts), None)
        if key is not None:
            view = self._meshopt_view(i, bv, key)
        else:
            buf = self.buffer(_int(bv, "buffer", what=f"bufferView {i}"), f"bufferView {i}")
            off = _int(bv, "byteOffset", 0, f"bufferView {i}")
            length = _int(bv, "byteLength", what=f"bufferView {i}")
            if off + length > len(buf):
                raise ReadError("truncated", f"glTF bufferView {i} runs past the end of its buffer")
            view = memoryview(buf)[off : off + length]
        self._view_cache[i] = view
        return view

    def _meshopt_view(self, i: int, bv: dict[str, Any], key: str) -> memoryview:
        """BufferView ``i``'s bytes decoded from its meshopt stream (the fallback buffer is not read)."""
        from saucerfab.check.readers import meshopt

        what = f"bufferView {i} ({key})"
        m = _dict(bv["extensions"][key], what)
        count = _int(m, "count", what=what)
        stride = _int(m, "byteStride", what=what)
        mode = m.get("mode")
        filt = m.get("filter", "NONE")
        if not isinstance(mode, str) or not isinstance(filt, str):
            raise _bad(f"{what}: mode / filter are not strings")
        length = _int(bv, "byteLength", what=f"bufferView {i}")
        if count * stride != length:
            raise _bad(f"{what}: count {count:,} x byteStride {stride} is not the bufferView's byteLength {length:,}")
        if "byteStride" in bv and _int(bv, "byteStride", what=f"bufferView {i}") != stride:
            raise _bad(f"{what}: byteStride {stride} differs from the bufferView's {bv['byteStride']}")
        try:
            meshopt.check_params(count, stride, mode, filt)
        except meshopt.MeshoptError as exc:
            raise _bad(f"{what}: {exc}") from None
        bi = _int(m, "buffer", what=what)
        src_buf = _item(_list(self.doc, "buffers"), bi, "buffer")
        sexts = src_buf.get("extensions")
        if isinstance(sexts, dict) and any(isinstance(sexts.get(k), dict) and sexts[k].get("fallback") for k in _MESHOPT):
            raise _bad(f"{what} takes its compressed data from buffer {bi}, a fallback buffer")
        buf = self.buffer(bi, what)
        off = _int(m, "byteOffset", 0, what)
        clen = _int(m, "byteLength", what=what)
        if off + clen > len(buf):
            raise ReadError("truncated", f"glTF {what}: the compressed data run past the end of buffer {bi}")
        if clen < meshopt.min_stream_bytes(count, stride, mode):  # a stated size the stream cannot hold
            raise _bad(f"{what}: {clen:,} compressed bytes cannot hold {count:,} {mode} elements")
        self._charge(count * stride, what)
        try:
            out = meshopt.decode(memoryview(buf)[off : off + clen], count, stride, mode, filt,
                                 khr=key.startswith("KHR"))
        except meshopt.MeshoptError as exc:
            raise _bad(f"{what}: {exc}") from None
        return memoryview(out)

    def _acc(self, i: Any, what: str) -> dict[str, Any]:
        return _item(_list(self.doc, "accessors"), i, "accessor")

    def accessor(self, i: Any, what: str, want: tuple[int, ...] = (1, 2, 3, 4), *,
                 count_must: int | None = None) -> np.ndarray:
        """Accessor ``i`` as (count, ncomp): float64, or int64 for integers that are not normalized;
        normalized integers scaled to [0, 1] / [-1, 1] as KHR_mesh_quantization and the core spec say.

        ``count_must``: refuse (before reading) an accessor whose count differs (an attribute must
        have one entry per position)."""
        acc = self._acc(i, what)
        count = _int(acc, "count", what=f"accessor {i}")
        typ = acc.get("type")
        ctype = acc.get("componentType")
        if typ not in _NCOMP or ctype not in _COMPONENT:
            raise _bad(f"accessor {i} has type {typ!r} / componentType {ctype!r}")
        ncomp = _NCOMP[typ]
        if ncomp not in want:
            raise _bad(f"accessor {i} ({what}) is {typ}, not what {what} needs")
        if count_must is not None and count != count_must:
            raise _bad(f"accessor {i} ({what}) has {count:,} entries for {count_must:,} positions")
        if count > self.limits.max_vertices + 3 * self.limits.max_triangles:
            raise ReadError("over_check_limit", f"glTF accessor {i} has {count:,} elements, over the checker's limits "
                                                f"(Limits.max_vertices + 3 x Limits.max_triangles); {raise_hint()}")
        normalized = acc.get("normalized", False)
        if not isinstance(normalized, bool):
            raise _bad(f"accessor {i}: 'normalized' is not a boolean")
        if normalized and ctype in (5125, 5126):
            raise _bad(f"accessor {i} is normalized but of componentType {ctype} (only 8- and 16-bit integers are)")
        dt = np.dtype("<" + _COMPONENT[ctype])
        elem = ncomp * dt.itemsize
        if "bufferView" in acc:
            bvi = _int(acc, "bufferView", what=f"accessor {i}")
            view = self.view_bytes(bvi)
            bv = _item(_list(self.doc, "bufferViews"), bvi, "bufferView")
            stride = _int(bv, "byteStride", elem, f"bufferView {bvi}") or elem
            if stride < elem:
                raise _bad(f"bufferView {bvi} byteStride {stride} is smaller than its elements ({elem} bytes)")
            off = _int(acc, "byteOffset", 0, f"accessor {i}")
            if count and off + stride * (count - 1) + elem > len(view):
                raise ReadError(
                    "truncated",
                    f"glTF accessor {i} ({count:,} x {typ}) runs past the end of bufferView {bvi} ({len(view):,} bytes)",
                )
            if count:
                arr = np.ndarray((count, ncomp), dtype=dt, buffer=view, offset=off, strides=(stride, dt.itemsize))
            else:
                arr = np.zeros((0, ncomp), dtype=dt)
        else:
            arr = np.zeros((count, ncomp), dtype=dt)  # no bufferView: zeros (unless sparse says otherwise)
        if "sparse" in acc:
            arr = self._sparse(i, acc, arr, dt, ncomp, count)
        out = arr.astype(np.float64) if dt.kind == "f" else arr.astype(np.int64)
        if normalized:
            out = np.maximum(out / _NORM[_COMPONENT[ctype]], -1.0)
        return out

    def _sparse(self, i: int, acc: dict[str, Any], base: np.ndarray, dt: np.dtype, ncomp: int,
                count: int) -> np.ndarray:
        """``base`` with accessor ``i``'s sparse substitutions, bounded and range-checked."""
        what = f"accessor {i} sparse"
        sp = _dict(acc["sparse"], what)
        n = _int(sp, "count", what=what)
        if not 1 <= n <= count:
            raise _bad(f"{what}: count {n:,} is not between 1 and the accessor's count {count:,}")
        ind = _dict(sp.get("indices"), f"{what} indices")
        val = _dict(sp.get("values"), f"{what} values")
        ict = ind.get("componentType")
        if ict not in _INDEX_TYPES:
            raise _bad(f"{what}: indices componentType {ict!r} is not an unsigned integer type")
        idt = np.dtype("<" + _COMPONENT[ict])

        def packed(d: dict[str, Any], dtype: np.dtype, k: int, part: str) -> np.ndarray:
            bvi = _int(d, "bufferView", what=f"{what} {part}")
            view = self.view_bytes(bvi)
            off = _int(d, "byteOffset", 0, f"{what} {part}")
            if off + k * dtype.itemsize > len(view):
                raise ReadError("truncated", f"glTF {what} {part} ({k:,} x {dtype.itemsize} bytes) run past the "
                                             f"end of bufferView {bvi} ({len(view):,} bytes)")
            return np.frombuffer(view, dtype=dtype, count=k, offset=off)

        idx = packed(ind, idt, n, "indices").astype(np.int64)
        if n > 1 and not (np.diff(idx) > 0).all():
            raise _bad(f"{what}: indices are not strictly increasing")
        if idx[-1] >= count:
            raise ReadError("index_out_of_range", f"glTF {what}: index {int(idx[-1]):,} but the accessor has "
                                                  f"{count:,} elements")
        vals = packed(val, dt, n * ncomp, "values").reshape(n, ncomp)
        out = np.array(base, dtype=dt)  # a copy: never write into the file's buffer
        out[idx] = vals
        return out
