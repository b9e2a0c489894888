"""Decoder of glTF's meshopt buffer-view compression (``EXT_meshopt_compression``, ``KHR_meshopt_compression``).

Written from the extensions' specifications (KhronosGroup/glTF, ``extensions/2.0/Vendor/
EXT_meshopt_compression`` and ``extensions/2.0/Khronos/KHR_meshopt_compression``, Appendix A
"Bitstream" and Appendix B "Filters"); both share one bitstream, KHR adding version 1 of the vertex
codec and the COLOR filter. There is no well-kept Python wheel of meshoptimizer's decoder (PyPI's
``meshoptimizer`` is an alpha source package that compiles C++), so the three codecs are numba
kernels here (a byte-by-byte walk is too slow in numpy: the group sizes depend on the bytes read) and
the four filters are numpy.

Every read is bounds-checked: a stream that ends early, leaves bytes between its last block and its
tail, reads a FIFO entry never written, uses a channel mode the specification does not define, or
has a varint over five bytes is refused with :class:`MeshoptError`. The output size
(``count * byteStride``) is the caller's to bound before calling (the glTF reader checks it against
the buffer view and ``Limits.max_buffer_bytes``); besides the output the decoders allocate one
attribute block of deltas (at most 64 KiB), a filtered copy of the output, or 4 bytes per index.

``decode(data, count, stride, mode, filter_)`` returns the decoded buffer view bytes.
"""

from __future__ import annotations

import numpy as np
from saucerfab.check.jit import njit  # numba's; plain Python where numba is not installed


class MeshoptError(ValueError):
    """A meshopt stream that breaks its specification (the message says how)."""


MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL", "COLOR")

_ERRORS = {
    1: "the stream ends before its data does",
    2: "bytes are left between the last block and the tail",
    3: "a vertex channel mode is not one the specification defines",
    4: "a triangle reads an edge FIFO entry that was never written",
    5: "a triangle reads a vertex FIFO entry that was never written",
    6: "a varint is longer than 5 bytes",
    7: "the 16-byte code table breaks its rules (last two bytes must be 0, no nibble 0xf)",
}

# bit widths of a group's deltas by its 2-bit header: version 0, version 1 control 0, version 1 control 1
_BITS = np.array([[0, 2, 4, 8], [0, 1, 2, 4], [1, 2, 4, 8]], dtype=np.int64)


@njit(cache=True, nogil=True)
def _vertex_kernel(data, count, stride, version, bits, out):  # pragma: no cover - compiled
    n = data.shape[0]
    nch = stride // 4
    tail_size = stride + (nch if version == 1 else 0)
    tail_min = 32 if version == 0 else 24
    tail_pad = max(tail_size, tail_min)
    if n < 1 + tail_pad:
        return 1
    end = n - tail_pad
    tail = n - tail_size
    last = np.empty(stride, np.int64)
    for k in range(stride):
        last[k] = data[tail + k]
    chmode = np.zeros(nch, np.int64)
    chrot = np.zeros(nch, np.int64)
    if version == 1:
        for c in range(nch):
            b = np.int64(data[tail + stride + c])
            chmode[c] = b & 15
            chrot[c] = b >> 4
            if chmode[c] > 2 or (chmode[c] < 2 and chrot[c] != 0):
                return 3
    max_block = min((8192 // stride) & ~15, 256)
    buf = np.zeros(max_block * stride, np.int64)  # transposed deltas: byte k of element i at k * aligned + i
    pos = 1
    done = 0
    while done < count:
        be = min(count - done, max_block)
        groups = (be + 15) >> 4
        aligned = groups << 4
        ctrl_at = pos
        if version == 1:
            if pos + nch > end:
                return 1
            pos += nch
        for k in range(stride):
            base = k * aligned
            table = 0
            if version == 1:
                ctrl = (np.int64(data[ctrl_at + (k >> 2)]) >> ((k & 3) << 1)) & 3
                if ctrl == 3:  # literal deltas, one byte per element of the block (not rounded to groups)
                    if pos + be > end:
                        return 1
                    for i in range(be):
                        buf[base + i] = data[pos + i]
                    pos += be
                    continue
                if ctrl == 2:  # all deltas zero
                    for i in range(aligned):
                        buf[base + i] = 0
                    continue
                table = 1 + ctrl
            hsize = (groups + 3) >> 2
            if pos + hsize > end:
                return 1
            hdr = pos
            pos += hsize
            for g in range(groups):
                m = (np.int64(data[hdr + (g >> 2)]) >> ((g & 3) << 1)) & 3
                w = bits[table, m]
                o = base + (g << 4)
                if w == 0:
                    for i in range(16):
                        buf[o + i] = 0
                elif w == 8:
                    if pos + 16 > end:
                        return 1
                    for i in range(16):
                        buf[o + i] = data[pos + i]
                    pos += 16
                else:
                    nb = 2 * w  # 16 deltas of w bits
                    if pos + nb > end:
                        return 1
                    sentinel = (1 << w) - 1
                    ex = pos + nb
                    for i in range(16):
                        if w == 1:
                            v = (np.int64(data[pos + (i >> 3)]) >> (i & 7)) & 1
                        elif w == 2:
                            v = (np.int64(data[pos + (i >> 2)]) >> (6 - ((i & 3) << 1))) & 3
                        else:
                            v = (np.int64(data[pos + (i >> 1)]) >> (4 - ((i & 1) << 2))) & 15
                        if v == sentinel:
                            if ex >= end:
                                return 1
                            v = np.int64(data[ex])
                            ex += 1
                        buf[o + i] = v
                    pos = ex
        for c in range(nch):
            k0 = 4 * c
            mode = chmode[c]
            if mode == 0:  # byte deltas, zigzag
                for j in range(4):
                    k = k0 + j
                    p = last[k]
                    b0 = k * aligned
                    for i in range(be):
                        d = buf[b0 + i]
                        p = (p + ((d >> 1) ^ (-(d & 1)))) & 0xFF
                        out[(done + i) * stride + k] = p
                    last[k] = p
            elif mode == 1:  # 2-byte deltas, zigzag, little-endian
                for j in range(0, 4, 2):
                    k = k0 + j
                    p = last[k] | (last[k + 1] << 8)
                    b0 = k * aligned
                    b1 = (k + 1) * aligned
                    for i in range(be):
                        d = buf[b0 + i] | (buf[b1 + i] << 8)
                        p = (p + ((d >> 1) ^ (-(d & 1)))) & 0xFFFF
                        e = (done + i) * stride + k
                        out[e] = p & 0xFF
                        out[e + 1] = p >> 8
                    last[k] = p & 0xFF
                    last[k + 1] = p >> 8
            else:  # 4-byte xor deltas, stored rotated left by r: undo by rotating left by 32 - r
                r = (32 - chrot[c]) & 31
                p = last[k0] | (last[k0 + 1] << 8) | (last[k0 + 2] << 16) | (last[k0 + 3] << 24)
                for i in range(be):
                    d = (buf[k0 * aligned + i] | (buf[(k0 + 1) * aligned + i] << 8)
                         | (buf[(k0 + 2) * aligned + i] << 16) | (buf[(k0 + 3) * aligned + i] << 24))
                    d = ((d << r) | (d >> ((32 - r) & 31))) & 0xFFFFFFFF
                    p = d ^ p
                    e = (done + i) * stride + k0
                    out[e] = p & 0xFF
                    out[e + 1] = (p >> 8) & 0xFF
                    out[e + 2] = (p >> 16) & 0xFF
                    out[e + 3] = p >> 24
                for j in range(4):
                    last[k0 + j] = (p >> (8 * j)) & 0xFF
        done += be
    if pos != end:
        return 2
    return 0


@njit(cache=True, nogil=True)
def _varint(data, pos, end):  # pragma: no cover - compiled
    """(value, new position, error) of the LEB128 varint at ``pos`` (1-5 bytes, 32-bit wraparound)."""
    v = np.int64(0)
    for i in range(5):
        if pos >= end:
            return 0, pos, 1
        b = np.int64(data[pos])
        pos += 1
        v |= (b & 0x7F) << (7 * i)
        if b < 0x80:
            return v & 0xFFFFFFFF, pos, 0
    return 0, pos, 6


@njit(cache=True, nogil=True)
def _encoded(data, dpos, end, last, M):  # pragma: no cover - compiled
    """An index stored as a zigzag varint delta from ``last``: (index, new last, dpos, error code)."""
    v, dpos, err = _varint(data, dpos, end)
    if err:
        return last, last, dpos, err
    delta = (M ^ (v >> 1)) if (v & 1) else (v >> 1)
    last = (last + delta) & M
    return last, last, dpos, 0


@njit(cache=True, nogil=True)
def _triangle_kernel(data, count, out):  # pragma: no cover - compiled
    n = data.shape[0]
    tri = count // 3
    if n < 1 + tri + 16:
        return 1
    aux = n - 16
    if data[aux + 14] != 0 or data[aux + 15] != 0:
        return 7
    for i in range(16):
        if (data[aux + i] >> 4) == 15 or (data[aux + i] & 15) == 15:
            return 7
    end = aux
    dpos = 1 + tri
    ea = np.zeros(16, np.int64)
    eb = np.zeros(16, np.int64)
    vf = np.zeros(16, np.int64)
    e_head = 0
    e_n = 0
    v_head = 0
    v_n = 0
    nxt = np.int64(0)
    last = np.int64(0)
    M = 0xFFFFFFFF
    for t in range(tri):
        code = np.int64(data[1 + t])
        hi = code >> 4
        lo = code & 15
        if hi < 15:
            if hi >= e_n:
                return 4
            at = (e_head - 1 - hi) & 15
            a = ea[at]
            b = eb[at]
            push_c = True
            if lo == 0:
                c = nxt
                nxt = (nxt + 1) & M
            elif lo < 13:
                if lo >= v_n:
                    return 5
                c = vf[(v_head - 1 - lo) & 15]
                push_c = False
            elif lo == 13:
                c = (last - 1) & M
                last = c
            elif lo == 14:
                c = (last + 1) & M
                last = c
            else:
                c, last, dpos, err = _encoded(data, dpos, end, last, M)
                if err:
                    return err
            ea[e_head] = c
            eb[e_head] = b
            e_head = (e_head + 1) & 15
            ea[e_head] = a
            eb[e_head] = c
            e_head = (e_head + 1) & 15
            e_n = min(e_n + 2, 16)
            if push_c:
                vf[v_head] = c
                v_head = (v_head + 1) & 15
                v_n = min(v_n + 1, 16)
        else:
            if lo < 14:
                zw = np.int64(data[aux + lo])
                z = zw >> 4
                w = zw & 15
                a = nxt
                nxt = (nxt + 1) & M
                if z == 0:
                    b = nxt
                    nxt = (nxt + 1) & M
                else:
                    if z - 1 >= v_n:
                        return 5
                    b = vf[(v_head - z) & 15]
                if w == 0:
                    c = nxt
                    nxt = (nxt + 1) & M
                else:
                    if w - 1 >= v_n:
                        return 5
                    c = vf[(v_head - w) & 15]
                push_b = z == 0
                push_c = w == 0
            else:
                if dpos >= end:
                    return 1
                zw = np.int64(data[dpos])
                dpos += 1
                if zw == 0:
                    nxt = np.int64(0)
                z = zw >> 4
                w = zw & 15
                if lo == 14:
                    a = nxt
                    nxt = (nxt + 1) & M
                else:
                    a, last, dpos, err = _encoded(data, dpos, end, last, M)
                    if err:
                        return err
                if z == 0:
                    b = nxt
                    nxt = (nxt + 1) & M
                elif z < 15:
                    if z - 1 >= v_n:
                        return 5
                    b = vf[(v_head - z) & 15]
                else:
                    b, last, dpos, err = _encoded(data, dpos, end, last, M)
                    if err:
                        return err
                if w == 0:
                    c = nxt
                    nxt = (nxt + 1) & M
                elif w < 15:
                    if w - 1 >= v_n:
                        return 5
                    c = vf[(v_head - w) & 15]
                else:
                    c, last, dpos, err = _encoded(data, dpos, end, last, M)
                    if err:
                        return err
                push_b = z == 0 or z == 15
                push_c = w == 0 or w == 15
            ea[e_head] = b
            eb[e_head] = a
            e_head = (e_head + 1) & 15
            ea[e_head] = c
            eb[e_head] = b
            e_head = (e_head + 1) & 15
            ea[e_head] = a
            eb[e_head] = c
            e_head = (e_head + 1) & 15
            e_n = min(e_n + 3, 16)
            vf[v_head] = a
            v_head = (v_head + 1) & 15
            v_n = min(v_n + 1, 16)
            if push_b:
                vf[v_head] = b
                v_head = (v_head + 1) & 15
                v_n = min(v_n + 1, 16)
            if push_c:
                vf[v_head] = c
                v_head = (v_head + 1) & 15
                v_n = min(v_n + 1, 16)
        out[3 * t] = a
        out[3 * t + 1] = b
        out[3 * t + 2] = c
    if dpos != end:
        return 2
    return 0


@njit(cache=True, nogil=True)
def _index_kernel(data, count, out):  # pragma: no cover - compiled
    n = data.shape[0]
    if n < 1 + count + 4:  # every index takes at least one byte
        return 1
    end = n - 4
    pos = 1
    b0 = np.int64(0)
    b1 = np.int64(0)
    M = 0xFFFFFFFF
    for i in range(count):
        v, pos, err = _varint(data, pos, end)
        if err:
            return err
        d = (M ^ (v >> 2)) if (v & 2) else (v >> 2)
        if v & 1:
            b1 = (b1 + d) & M
            out[i] = b1
        else:
            b0 = (b0 + d) & M
            out[i] = b0
    if pos != end:
        return 2
    return 0


def _fail(code: int, mode: str) -> MeshoptError:
    return MeshoptError(f"{mode} stream: {_ERRORS.get(code, f'error {code}')}")


def check_params(count: int, stride: int, mode: str, filter_: str) -> None:
    """Refuse parameters the specification rules out (before any byte is decoded)."""
    if mode not in MODES:
        raise MeshoptError(f"mode {mode!r} is not one of {', '.join(MODES)}")
    if filter_ not in FILTERS:
        raise MeshoptError(f"filter {filter_!r} is not one of {', '.join(FILTERS)}")
    if mode == "ATTRIBUTES":
        if stride % 4 or not 4 <= stride <= 256:
            raise MeshoptError(f"ATTRIBUTES byteStride {stride} is not a multiple of 4 in 4..256")
    else:
        if stride not in (2, 4):
            raise MeshoptError(f"{mode} byteStride {stride} is not 2 or 4")
        if filter_ != "NONE":
            raise MeshoptError(f"{mode} cannot take filter {filter_}")
        if mode == "TRIANGLES" and count % 3:
            raise MeshoptError(f"TRIANGLES count {count} is not a multiple of 3")
    need = {"OCTAHEDRAL": (4, 8), "QUATERNION": (8,), "COLOR": (4, 8)}.get(filter_)
    if need and stride not in need:
        raise MeshoptError(f"filter {filter_} needs byteStride {' or '.join(map(str, need))}, not {stride}")
    if filter_ == "EXPONENTIAL" and stride % 4:
        raise MeshoptError(f"filter EXPONENTIAL needs a byteStride divisible by 4, not {stride}")


def min_stream_bytes(count: int, stride: int, mode: str) -> int:
    """The fewest bytes a valid stream of ``count`` elements can have (header and tail included)."""
    if mode == "TRIANGLES":
        return 1 + count // 3 + 16
    if mode == "INDICES":
        return 1 + count + 4
    return 1 + 24  # ATTRIBUTES: version 1's smallest tail


def decode(data: bytes | memoryview | np.ndarray, count: int, stride: int, mode: str, filter_: str = "NONE",
           *, khr: bool = True) -> np.ndarray:
    """The ``count * stride`` bytes (uint8 array) that the meshopt stream ``data`` decodes to.

    ``khr``: the stream comes from ``KHR_meshopt_compression`` (vertex codec versions 0 and 1, the
    COLOR filter); else from ``EXT_meshopt_compression`` (version 0 only, no COLOR).
    Raises :class:`MeshoptError` for a stream or parameters that break the specification.
    """
    check_params(count, stride, mode, filter_)
    if filter_ == "COLOR" and not khr:
        raise MeshoptError("filter COLOR is KHR_meshopt_compression's, not EXT_meshopt_compression's")
    src = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8, copy=False)
    if len(src) < min_stream_bytes(count, stride, mode):
        raise MeshoptError(f"{mode} stream of {len(src):,} bytes is too short for {count:,} elements")
    head = int(src[0])
    if mode == "ATTRIBUTES":
        if head == 0xA0:
            version = 0
        elif head == 0xA1 and khr:
            version = 1
        else:
            raise MeshoptError(f"ATTRIBUTES stream header 0x{head:02x} is not "
                               + ("0xa0 or 0xa1" if khr else "0xa0 (version 1 is KHR_meshopt_compression's)"))
        out = np.zeros(count * stride, dtype=np.uint8)
        if count:
            err = _vertex_kernel(src, count, stride, version, _BITS, out)
            if err:
                raise _fail(err, mode)
        return _filter(out, count, stride, filter_)
    want = 0xE1 if mode == "TRIANGLES" else 0xD1
    if head != want:
        raise MeshoptError(f"{mode} stream header 0x{head:02x} is not 0x{want:02x}")
    idx = np.zeros(count, dtype="<u4")  # the kernels' values are 32-bit (they wrap around)
    err = (_triangle_kernel if mode == "TRIANGLES" else _index_kernel)(src, count, idx)
    if err:
        raise _fail(err, mode)
    # 16-bit output wraps around, as the specification says
    return (idx & 0xFFFF).astype("<u2").view(np.uint8) if stride == 2 else idx.view(np.uint8)


def _round(x: np.ndarray) -> np.ndarray:
    """Round half away from zero (the filters' ``round``)."""
    return np.sign(x) * np.floor(np.abs(x) + 0.5)


def _filter(raw: np.ndarray, count: int, stride: int, filter_: str) -> np.ndarray:
    if filter_ == "NONE" or count == 0:
        return raw
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if filter_ == "OCTAHEDRAL":
            it = np.dtype("<i1") if stride == 4 else np.dtype("<i2")
            top = 127.0 if stride == 4 else 32767.0
            v = raw.view(it).reshape(count, 4)
            one = v[:, 2].astype(np.float32)
            x = v[:, 0] / one
            y = v[:, 1] / one
            z = np.float32(1.0) - np.abs(x) - np.abs(y)
            t = np.minimum(z, np.float32(0.0))
            x = x - np.copysign(t, x)
            y = y - np.copysign(t, y)
            n = np.sqrt(x * x + y * y + z * z)
            res = np.empty((count, 4), dtype=it)
            for k, comp in enumerate((x / n, y / n, z / n)):
                res[:, k] = np.clip(np.nan_to_num(_round(comp * np.float32(top))), -top, top)
            res[:, 3] = v[:, 3]
            return res.view(np.uint8).ravel()
        if filter_ == "QUATERNION":
            v = raw.view("<i2").reshape(count, 4).astype(np.int32)
            one = (v[:, 3] | 3).astype(np.float32)
            rng = np.float32(1.0 / np.sqrt(2.0))
            x = v[:, 0] / one * rng
            y = v[:, 1] / one * rng
            z = v[:, 2] / one * rng
            w = np.sqrt(np.maximum(np.float32(0.0), np.float32(1.0) - x * x - y * y - z * z))
            mc = v[:, 3] & 3
            res = np.empty((count, 4), dtype="<i2")
            rows = np.arange(count)
            for shift, comp in ((1, x), (2, y), (3, z), (0, w)):
                res[rows, (mc + shift) % 4] = np.clip(np.nan_to_num(_round(comp * np.float32(32767.0))), -32767, 32767)
            return res.view(np.uint8).ravel()
        if filter_ == "EXPONENTIAL":
            v = raw.view("<i4").astype(np.int64)
            e = v >> 24  # the top byte, signed (the int32 is signed and arithmetic shift keeps it)
            m = ((v & 0xFFFFFF) ^ 0x800000) - 0x800000  # the low 24 bits as a signed mantissa
            return np.ldexp(m.astype(np.float64), e).astype("<f4").view(np.uint8)
        # COLOR
        ut = np.dtype("<u1") if stride == 4 else np.dtype("<u2")
        it = np.dtype("<i1") if stride == 4 else np.dtype("<i2")
        top = 255.0 if stride == 4 else 65535.0
        u = raw.view(ut).reshape(count, 4)
        s = raw.view(it).reshape(count, 4)
        a_in = u[:, 3].astype(np.int64)
        msb = np.where(a_in > 0, np.floor(np.log2(np.maximum(a_in, 1))).astype(np.int64), -1)
        scale = (np.int64(1) << (msb + 1)) - 1
        yy = u[:, 0].astype(np.int64)
        co = s[:, 1].astype(np.int64)
        cg = s[:, 2].astype(np.int64)
        r = yy + co - cg
        g = yy + cg
        b = yy - co - cg
        a = a_in & (scale >> 1)
        a = (a << 1) | (a & 1)
        ss = np.float32(top) / scale.astype(np.float32)
        res = np.empty((count, 4), dtype=ut)
        for k, comp in enumerate((r, g, b, a)):
            res[:, k] = np.clip(np.nan_to_num(_round(comp.astype(np.float32) * ss)), 0, top)
        return res.view(np.uint8).ravel()


def warm_up() -> list[str]:
    """Compile (or load from numba's cache) the three kernels on tiny valid streams."""
    decode(bytes([0xA0]) + bytes(4 + 32), 1, 4, "ATTRIBUTES")
    decode(bytes([0xE1, 0xF0]) + bytes(16), 3, 2, "TRIANGLES")
    decode(bytes([0xD1, 0x00]) + bytes(4), 1, 4, "INDICES")
    return ["meshopt.vertex", "meshopt.triangles", "meshopt.indices"]
