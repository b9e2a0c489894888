"""PLY reader (ASCII, binary little- and big-endian).

The header's element counts are checked against the bytes that follow
(each record's smallest size) and against the caps before any array is
made: a header claiming 10^9 vertices in a 1 kB file is "truncated" at once.
Fixed-size records are read with one ``np.frombuffer``; face records with a
list property take a bulk path when every list has the first record's
length (all triangles, the common case), else a bounded record-by-record path.

Colour: per-vertex ``red green blue``, per-face ``red green blue``, texture
coordinates per vertex (``s t``, ``u v``, ``texture_u texture_v``) or per
corner (MeshLab's ``texcoord`` list), with the texture named by a
``comment TextureFile name.png`` line (MeshLab's convention).
"""

from __future__ import annotations

import io
import itertools

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.safe import DiskResources, Resources

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
MAX_HEADER = 64 << 10


@dataclass
class _Prop:
    name: str
    type: str  # numpy code
    count_type: str | None = None  # list properties


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Prop] = field(default_factory=list)

    def min_size(self) -> int:
        return sum(np.dtype(p.count_type if p.count_type else p.type).itemsize for p in self.props)


def _header(data: bytes) -> tuple[str, list[_Element], list[str], int]:
    end = data.find(b"end_header", 0, MAX_HEADER)
    if end < 0:
        raise ReadError("malformed" if len(data) > MAX_HEADER else "truncated", "PLY header has no 'end_header'")
    nl = data.find(b"\n", end)
    if nl < 0:
        raise ReadError("truncated", "the PLY ends right after its header")
    text = data[:end].decode("ascii", "replace")
    lines = text.replace("\r", "").split("\n")
    if lines[0].strip() != "ply":
        raise ReadError("malformed", "PLY header does not start with 'ply'")
    fmt = None
    elements: list[_Element] = []
    comments: list[str] = []
    for line in lines[1:]:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] in ("comment", "obj_info"):
            comments.append(line.strip())
        elif tok[0] == "element" and len(tok) == 3:
            try:
                count = int(tok[2])
            except ValueError:
                raise ReadError("malformed", f"PLY element count {tok[2][:20]!r} is not an integer") from None
            if count < 0:
                raise ReadError("malformed", f"PLY element {tok[1]!r} has a negative count")
            elements.append(_Element(tok[1], count))
        elif tok[0] == "property" and elements:
            if len(tok) == 5 and tok[1] == "list" and tok[2] in _TYPES and tok[3] in _TYPES:
                elements[-1].props.append(_Prop(tok[4], _TYPES[tok[3]], _TYPES[tok[2]]))
            elif len(tok) == 3 and tok[1] in _TYPES:
                elements[-1].props.append(_Prop(tok[2], _TYPES[tok[1]]))
            else:
                raise ReadError("malformed", f"PLY property line {line.strip()[:60]!r} is not understood")
        else:
            raise ReadError("malformed", f"PLY header line {line.strip()[:60]!r} is not understood")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ReadError("malformed", f"PLY format {fmt!r} is not ascii/binary_little_endian/binary_big_endian")
    return fmt, elements, comments, nl + 1


def read_ply(path: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """Read a PLY file's bytes (a texture comes from ``res``, default: beside ``path``)."""
    res = res or DiskResources(path.parent, limits)
    fmt, elements, comments, start = _header(data)
    body = memoryview(data)[start:]
    b = MeshBuilder("ply", limits)
    names = {e.name for e in elements}
    if "vertex" not in names or "face" not in names:
        raise ReadError("no_triangles", "the PLY has no 'vertex' and 'face' elements (a point cloud?)")
    # bound the counts before reading anything
    if fmt == "ascii":
        total = sum(e.count for e in elements)
        if total > body.nbytes // 2 + 1:  # every record takes at least "0\n"
            raise ReadError("truncated", f"the PLY header declares {total:,} records but the body has {body.nbytes:,} bytes")
    else:
        need = sum(e.count * e.min_size() for e in elements)
        if need > body.nbytes:
            raise ReadError(
                "truncated",
                f"the PLY header declares records needing at least {need:,} bytes but the body has {body.nbytes:,}",
            )
    for e in elements:
        if e.name == "vertex":
            b.reserve(e.count, 0, "the PLY vertex element")
        elif e.name == "face":
            b.reserve(0, e.count, "the PLY face element")
    parsed = _read_ascii(data, start, elements) if fmt == "ascii" else _read_binary(body, elements, fmt)
    return _assemble(res, parsed, elements, comments, b)


def _read_binary(body: memoryview, elements: list[_Element], fmt: str) -> dict[str, dict[str, np.ndarray | list]]:
    endian = "<" if fmt == "binary_little_endian" else ">"
    off = 0
    out: dict[str, dict[str, np.ndarray | list]] = {}
    for e in elements:
        if "vertex" in out and "face" in out:
            break  # later elements (edges, materials) do not matter
        if not any(p.count_type for p in e.props):
            dt = np.dtype([(f"p{i}", endian + p.type) for i, p in enumerate(e.props)])
            n_bytes = dt.itemsize * e.count
            if off + n_bytes > body.nbytes:
                raise ReadError("truncated", f"the PLY ends inside its {e.name!r} element")
            rec = np.frombuffer(body, dtype=dt, count=e.count, offset=off) if e.count else np.zeros(0, dt)
            out[e.name] = {p.name: rec[f"p{i}"] for i, p in enumerate(e.props)}
            off += n_bytes
            continue
        vals, off = _binary_lists(body, off, e, endian)
        out[e.name] = vals
    return out


def _binary_lists(body: memoryview, off: int, e: _Element, endian: str) -> tuple[dict[str, np.ndarray | list], int]:
    """An element with list properties: bulk when all lists match the first record's lengths."""
    # lengths of the first record's lists
    fields = []
    pos = off
    for i, p in enumerate(e.props):
        if p.count_type:
            cdt = np.dtype(endian + p.count_type)
            if pos + cdt.itemsize > body.nbytes:
                raise ReadError("truncated", f"the PLY ends inside its {e.name!r} element")
            n = int(np.frombuffer(body, cdt, 1, pos)[0]) if e.count else 0
            if n < 0 or n > 1024:
                break
            fields += [(f"n{i}", endian + p.count_type), (f"p{i}", endian + p.type, (n,))]
            pos += cdt.itemsize + n * np.dtype(p.type).itemsize
        else:
            fields.append((f"p{i}", endian + p.type))
            pos += np.dtype(p.type).itemsize
    else:
        dt = np.dtype(fields)
        if off + dt.itemsize * e.count <= body.nbytes:
            rec = np.frombuffer(body, dtype=dt, count=e.count, offset=off) if e.count else np.zeros(0, dt)
            ok = all((rec[f"n{i}"] == rec[f"n{i}"][0]).all() for i, p in enumerate(e.props) if p.count_type and e.count)
            if ok:
                vals: dict[str, np.ndarray | list] = {p.name: rec[f"p{i}"] for i, p in enumerate(e.props)}
                return vals, off + dt.itemsize * e.count
    # record by record (bounded by the count, which the caps already bounded)
    lists: dict[str, list] = {p.name: [] for p in e.props}
    pos = off
    try:
        for _ in range(e.count):
            for p in e.props:
                if p.count_type:
                    cdt = np.dtype(endian + p.count_type)
                    n = int(np.frombuffer(body, cdt, 1, pos)[0])
                    pos += cdt.itemsize
                    if n < 0:
                        raise ReadError("malformed", f"the PLY has a negative list length in {e.name!r}")
                    idt = np.dtype(endian + p.type)
                    lists[p.name].append(np.frombuffer(body, idt, n, pos))
                    pos += n * idt.itemsize
                else:
                    idt = np.dtype(endian + p.type)
                    lists[p.name].append(np.frombuffer(body, idt, 1, pos)[0])
                    pos += idt.itemsize
    except ValueError:
        raise ReadError("truncated", f"the PLY ends inside its {e.name!r} element") from None
    return {k: v for k, v in lists.items()}, pos


def _read_ascii(data: bytes, start: int, elements: list[_Element]) -> dict[str, dict[str, np.ndarray | list]]:
    total = sum(e.count for e in elements)
    # the first ``total`` lines after the header, read in place: a copy of the body, or the split's last
    # piece (everything after them), would hold up to the whole file twice more (issue 16)
    src = io.BytesIO(data)  # shares ``data``'s buffer
    src.seek(start)
    lines = [ln for ln in itertools.islice(src, total) if ln.strip()]
    if len(lines) < total:
        raise ReadError("truncated", f"the PLY body has {len(lines):,} records of the {total:,} its header declares")
    out: dict[str, dict[str, np.ndarray | list]] = {}
    at = 0
    for e in elements:
        rows = lines[at : at + e.count]
        at += e.count
        if "vertex" in out and "face" in out:
            break
        try:
            out[e.name] = _ascii_element(rows, e)
        except ValueError:
            raise ReadError("malformed", f"the PLY {e.name!r} element has a value that is not a number") from None
    return out


def _ascii_element(rows: list[bytes], e: _Element) -> dict[str, np.ndarray | list]:
    if not rows:
        return {p.name: np.zeros(0) for p in e.props}
    first = rows[0].split()
    # widths of the first record
    widths: list[int] = []
    pos = 0
    for p in e.props:
        if p.count_type:
            if pos >= len(first):
                raise ReadError("malformed", f"PLY {e.name!r} record is too short")
            n = int(float(first[pos]))
            widths.append(1 + n)
            pos += 1 + n
        else:
            widths.append(1)
            pos += 1
    tokens = b" ".join(rows).split()
    k = sum(widths)
    if len(tokens) == k * len(rows):
        arr = np.array(tokens, dtype=np.float64).reshape(len(rows), k)
        out: dict[str, np.ndarray | list] = {}
        col = 0
        uniform = True
        for p, w in zip(e.props, widths):
            if p.count_type:
                if not (arr[:, col] == w - 1).all():
                    uniform = False
                    break
                out[p.name] = arr[:, col + 1 : col + w]
            else:
                out[p.name] = arr[:, col]
            col += w
        if uniform:
            return out
    lists: dict[str, list] = {p.name: [] for p in e.props}
    for r in rows:
        tok = r.split()
        pos = 0
        for p in e.props:
            if pos >= len(tok):
                raise ReadError("malformed", f"PLY {e.name!r} record is too short: {r[:60]!r}")
            if p.count_type:
                n = int(float(tok[pos]))
                if n < 0 or pos + 1 + n > len(tok):
                    raise ReadError("malformed", f"PLY {e.name!r} list length {n} does not fit its record")
                lists[p.name].append(np.array(tok[pos + 1 : pos + 1 + n], dtype=np.float64))
                pos += 1 + n
            else:
                lists[p.name].append(float(tok[pos]))
                pos += 1
    return lists


def _assemble(
    res: Resources, parsed: dict[str, dict[str, np.ndarray | list]], elements: list[_Element],
    comments: list[str], b: MeshBuilder,
) -> MeshData:
    vert = parsed["vertex"]
    face = parsed["face"]
    try:
        V = np.stack([np.asarray(vert[a], dtype=np.float64) for a in ("x", "y", "z")], axis=1)
    except KeyError:
        raise ReadError("malformed", "the PLY vertex element lacks x, y or z") from None
    key = "vertex_indices" if "vertex_indices" in face else "vertex_index" if "vertex_index" in face else None
    if key is None:
        raise ReadError("malformed", "the PLY face element has no vertex_indices list")
    idx = face[key]
    tc = face.get("texcoord")
    fv, corner = _triangulate(idx)
    m = len(fv)
    if not np.issubdtype(fv.dtype, np.integer):
        if not np.array_equal(fv, np.round(fv)):
            raise ReadError("malformed", "PLY face indices are not integers")
        fv = fv.astype(np.int64)
    corner_uv = None
    face_tex = None
    face_col = None
    uvnames = next(((u, v) for u, v in _UV_NAMES if u in vert and v in vert), None)
    if tc is not None:
        corner_uv = _corner_texcoords(tc, corner, m)
    elif uvnames is not None:
        UV = np.stack([np.asarray(vert[uvnames[0]], np.float64), np.asarray(vert[uvnames[1]], np.float64)], axis=1)
        if len(fv) and (fv.min() >= 0) and fv.max() < len(UV):
            corner_uv = UV[fv]
    if corner_uv is not None:
        ref = next((c.split(None, 2)[2] for c in comments if c.split()[1:2] == ["TextureFile"] and len(c.split()) > 2), None)
        if ref is None:
            ti = b.texture("<none>", lambda: TextureInfo(
                name="(none named)", status="missing",
                message="the PLY has texture coordinates but names no texture ('comment TextureFile name.png')"))
        else:
            ti = b.texture(ref, lambda: res.texture(ref))
        face_tex = np.full(m, ti, dtype=np.int32)
        b.colour_kinds.add("texture")
    if all(c in vert for c in ("red", "green", "blue")):
        face_col = np.ones(m, dtype=bool)
        b.colour_kinds.add("vertex")
    elif all(c in face for c in ("red", "green", "blue")):
        face_col = np.ones(m, dtype=bool)
        b.colour_kinds.add("face")
    b.add(V, fv, corner_uv=corner_uv, face_texture=face_tex, face_colour=face_col, what="PLY")
    return b.build(units="millimeter (assumed; PLY has no units)")


def _triangulate(idx: np.ndarray | list) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles from the index lists, and for each triangle (record, c0, c1, c2) corner numbers."""
    if isinstance(idx, np.ndarray) and idx.ndim == 2:
        n, k = idx.shape
        if k < 3:
            return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 4), dtype=np.int64)
        ks = np.arange(1, k - 1)
        tri = np.stack([np.repeat(idx[:, :1], k - 2, axis=1), idx[:, ks], idx[:, ks + 1]], axis=2).reshape(-1, 3)
        rec = np.repeat(np.arange(n), k - 2)
        c = np.stack([rec, np.zeros_like(rec), np.tile(ks, n), np.tile(ks + 1, n)], axis=1)
        return tri, c
    tris: list[np.ndarray] = []
    corners: list[tuple[int, int, int, int]] = []
    for r, lst in enumerate(idx):
        a = np.asarray(lst)
        for j in range(1, len(a) - 1):
            tris.append(a[[0, j, j + 1]])
            corners.append((r, 0, j, j + 1))
    if not tris:
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 4), dtype=np.int64)
    return np.array(tris), np.array(corners, dtype=np.int64)


def _corner_texcoords(tc: np.ndarray | list, corner: np.ndarray, m: int) -> np.ndarray:
    out = np.full((m, 3, 2), np.nan)
    if isinstance(tc, np.ndarray) and tc.ndim == 2:
        tcs = tc.reshape(len(tc), -1, 2) if tc.shape[1] % 2 == 0 else None
        if tcs is None:
            raise ReadError("malformed", "the PLY texcoord list has an odd length")
        for j in range(3):
            col = corner[:, 1 + j]
            if col.size and col.max() >= tcs.shape[1]:
                raise ReadError("index_out_of_range", "a PLY face has fewer texcoords than corners")
            out[:, j] = tcs[corner[:, 0], col]
        return out
    for t, (r, a, bb, c) in enumerate(corner):
        lst = np.asarray(tc[r], dtype=np.float64)
        if len(lst) < 2 * (max(a, bb, c) + 1):
            raise ReadError("index_out_of_range", f"PLY face {r} has fewer texcoords than corners")
        pairs = lst.reshape(-1, 2)
        out[t] = pairs[[a, bb, c]]
    return out
