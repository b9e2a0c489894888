"""glTF extensions ``saucerfab check`` reads (issue 15): Draco and meshopt compression, mesh
quantization, sparse accessors, texture transforms; and the glTF-Validator's valid files it used to refuse.

The compressed files in ``tests/data/gltf-compressed`` were made once from ``src.glb`` by independent
encoders (gltf-pipeline for Draco, gltfpack for meshopt and quantization; see its PROVENANCE.md), so
each must read to the source's triangles within its quantization step, with the same verdict.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import fixtures_check as fx
import numpy as np
import pytest
from scipy.spatial import cKDTree

from saucerfab.check import Limits, check_mesh
from saucerfab.check.readers import draco, meshopt, read_mesh

DATA = Path(__file__).resolve().parents[1] / "data" / "gltf-compressed"
VALIDATOR = Path(__file__).resolve().parents[1] / "data" / "conformance" / "gltf-validator" / "test"
UNREADABLE_OK = {"malformed", "truncated", "over_check_limit", "index_out_of_range", "unsupported_format",
                 "no_triangles"}


# -- helpers ---------------------------------------------------------------------------------------


def glb_parts(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + jlen])
    off = 20 + jlen
    blen = struct.unpack_from("<I", data, off)[0]
    return doc, data[off + 8 : off + 8 + blen]


def write_glb(path: Path, doc: dict, binb: bytes) -> Path:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binb = binb + b"\0" * (-len(binb) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binb), b"BIN\x00") + binb
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


def write_gltf(path: Path, doc: dict, blob: bytes) -> Path:
    """A .gltf with one data-URI buffer holding ``blob``."""
    doc = {"asset": {"version": "2.0"}, **doc}
    doc["buffers"] = [{"byteLength": len(blob),
                       "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}]
    path.write_text(json.dumps(doc))
    return path


class Blob:
    """A buffer built view by view (4-byte aligned), with the views and accessors naming it."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, raw: bytes) -> int:
        self.data.extend(b"\0" * (-len(self.data) % 4))
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)})
        self.data.extend(raw)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, ctype: int, typ: str, **kw: object) -> int:
        acc = {"bufferView": self.view(np.ascontiguousarray(arr).tobytes()), "componentType": ctype,
               "count": len(arr), "type": typ, **kw}
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def doc(self, **kw: object) -> dict:
        return {"bufferViews": self.views, "accessors": self.accessors, **kw}


def one_mesh(attrs: dict, indices: int | None, **prim: object) -> dict:
    p = {"attributes": attrs, **prim}
    if indices is not None:
        p["indices"] = indices
    return {"meshes": [{"primitives": [p]}]}


def scene(node: dict | None = None) -> dict:
    return {"scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, **(node or {})}]}


def codes(r) -> set[str]:
    return {f.code for f in r.findings}


def errors(r) -> set[str]:
    return {f.code for f in r.findings if f.severity == "error" or f.code in UNREADABLE_OK | {"internal_error"}}


def box_mm() -> tuple[np.ndarray, np.ndarray]:
    return fx.box()


# -- compressed files against their uncompressed source ---------------------------------------------

#: file -> (position tolerance mm, uv tolerance): the encoders' quantization steps
COMPRESSED = {
    "draco.glb": (0.05, 2e-3),  # gltf-pipeline defaults: 11-bit positions, 10-bit UVs
    "draco-seq.glb": (0.05, 2e-3),
    "meshopt.glb": (0.01, 1e-3),  # gltfpack defaults: 14-bit positions, 12-bit UVs
    "meshopt-fallback.glb": (0.01, 1e-3),
    "meshopt-khr.glb": (0.01, 1e-3),
    "meshopt-khr-fallback.glb": (0.01, 1e-3),
    "meshopt-float.glb": (1e-3, 2e-4),  # floats through the EXPONENTIAL filter (gltfpack keeps 12-16 mantissa bits)
    "meshopt-noq.glb": (1e-6, 1e-7),  # floats, lossless
    "quantized.glb": (0.01, 1e-3),
}


@pytest.fixture(scope="module")
def source():
    md = read_mesh(DATA / "src.glb", Limits())
    return md, check_mesh(DATA / "src.glb")


def _match(src, got, tol: float, uv_tol: float) -> None:
    """Every source triangle has one compressed triangle with the same corners, in the same cyclic order
    (same winding), within ``tol`` mm, and the same corner UVs within ``uv_tol``."""
    Vs, Fs = src.vertices * src.unit_mm, src.faces
    Vg, Fg = got.vertices * got.unit_mm, got.faces
    assert len(Fg) == len(Fs)
    cs, cg = Vs[Fs], Vg[Fg]  # (m, 3, 3) corners
    d, j = cKDTree(cg.mean(axis=1)).query(cs.mean(axis=1))
    assert d.max() < tol, d.max()
    assert len(np.unique(j)) == len(Fs)  # a bijection
    best = np.full(len(Fs), np.inf)
    rot = np.zeros(len(Fs), dtype=int)
    for k in range(3):
        e = np.abs(np.roll(cg[j], -k, axis=1) - cs).max(axis=(1, 2))
        rot = np.where(e < best, k, rot)
        best = np.minimum(best, e)
    assert best.max() < tol, best.max()  # a cyclic rotation matches: the winding is kept
    if src.corner_uv is not None:
        assert got.corner_uv is not None
        ug = np.stack([np.roll(got.corner_uv[jj], -k, axis=0) for jj, k in zip(j, rot)])
        assert np.abs(ug - src.corner_uv).max() < uv_tol, np.abs(ug - src.corner_uv).max()
        assert got.textures and got.textures[0].status == "ok"
    assert (got.face_colour is not None) == (src.face_colour is not None)


@pytest.mark.parametrize("name", sorted(COMPRESSED))
def test_compressed_file_reads_as_its_source(name: str, source) -> None:
    src_md, src_report = source
    tol, uv_tol = COMPRESSED[name]
    got = read_mesh(DATA / name, Limits())
    _match(src_md, got, tol, uv_tol)
    r = check_mesh(DATA / name)
    assert r.verdict == src_report.verdict == "printable", r.reason()
    assert errors(r) == errors(src_report) == set()
    assert r.stats["volume_mm3"] == pytest.approx(src_report.stats["volume_mm3"], rel=2e-3)


def test_vendored_files_are_small_and_described() -> None:
    prov = (DATA / "PROVENANCE.md").read_text()
    for name in COMPRESSED:
        assert (DATA / name).stat().st_size < 100_000
        assert f"`{name}`" in prov


# -- the meshopt decoder on the specification's examples and the encoder's own fallback data ---------


def _v0_stream(stride: int, count: int, blocks: list[bytes], baseline: bytes) -> bytes:
    tail = b"\0" * max(0, 32 - stride) + baseline
    return bytes([0xA0]) + b"".join(blocks) + tail


def test_spec_example_of_4bit_sentinel_deltas() -> None:
    # Appendix A: this 4-bit sentinel group encodes the deltas below (in 8-bit wraparound)
    group = bytes.fromhex("175ff0bc77a921003 4b5".replace(" ", ""))
    deltas = [-1, -4, -3, 26, -91, 0, -6, 6, -4, -4, 5, -5, 1, -1, 0, 0]
    byte0 = bytes([0b10]) + group  # one group, header mode 2 (4-bit) in version 0
    zeros = bytes([0])  # header mode 0: all deltas zero
    stream = _v0_stream(4, 16, [byte0, zeros, zeros, zeros], bytes([7, 0, 0, 0]))
    out = meshopt.decode(stream, 16, 4, "ATTRIBUTES", khr=False).reshape(16, 4)
    assert out[:, 0].tolist() == [(7 + s) % 256 for s in np.cumsum(deltas)]
    assert not out[:, 1:].any()
    with pytest.raises(meshopt.MeshoptError, match="ends before"):
        meshopt.decode(stream[:8] + stream[-32:], 16, 4, "ATTRIBUTES")
    with pytest.raises(meshopt.MeshoptError, match="left"):
        meshopt.decode(stream[:-32] + b"\0" + stream[-32:], 16, 4, "ATTRIBUTES")
    with pytest.raises(meshopt.MeshoptError, match="0xa0"):
        meshopt.decode(bytes([0xA1]) + stream[1:], 16, 4, "ATTRIBUTES", khr=False)  # version 1 is KHR's


def test_spec_varint_examples() -> None:
    # the README's third example, 0xff 0xa0 0x05 => 0x1fd005, reads the bytes most significant first,
    # against its own LEB128 rule and its second example: in LEB128 those bytes are 0x1507f
    # (and 0x1fd005 is 0x85 0xa0 0x7f)
    for raw, value in ((b"\x7f", 0x7F), (b"\x81\x04", 0x201), (b"\xff\xa0\x05", 0x1507F), (b"\x85\xa0\x7f", 0x1FD005)):
        v, pos, err = meshopt._varint(np.frombuffer(raw, np.uint8), 0, len(raw))
        assert (v, pos, err) == (value, len(raw), 0)
    v, pos, err = meshopt._varint(np.frombuffer(b"\xff" * 6, np.uint8), 0, 6)
    assert err == 6  # over five bytes


def _leb(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def test_index_sequence_mode_with_two_baselines_and_16_bit_wraparound() -> None:
    seq = [(0, 5), (1, 100), (0, 6), (1, 99), (0, 4), (1, 70000)]  # (baseline, value)
    last = [0, 0]
    raw = bytearray([0xD1])
    for b, value in seq:
        d = value - last[b]
        last[b] = value
        z = (d << 1) if d >= 0 else ((-d - 1) << 1) | 1  # zigzag
        raw += _leb((z << 1) | b)
    raw += b"\0" * 4
    out = meshopt.decode(bytes(raw), len(seq), 4, "INDICES").view("<u4")
    assert out.tolist() == [v for _, v in seq]
    out16 = meshopt.decode(bytes(raw), len(seq), 2, "INDICES").view("<u2")
    assert out16.tolist() == [v & 0xFFFF for _, v in seq]
    with pytest.raises(meshopt.MeshoptError):
        meshopt.decode(bytes(raw[:-5]) + b"\0" * 4, len(seq), 4, "INDICES")


def test_triangle_codec_rules() -> None:
    aux = bytes(16)
    # 0xf0 with codeaux[0] = 0x00: three new vertices; then 0x00: the newest edge (a, c) and a new vertex
    out = meshopt.decode(bytes([0xE1, 0xF0, 0x00]) + aux, 6, 4, "TRIANGLES").view("<u4")
    assert out.tolist() == [0, 1, 2, 0, 2, 3]
    with pytest.raises(meshopt.MeshoptError, match="edge FIFO"):
        meshopt.decode(bytes([0xE1, 0x00]) + aux, 3, 4, "TRIANGLES")  # no edge written yet
    with pytest.raises(meshopt.MeshoptError, match="vertex FIFO"):
        meshopt.decode(bytes([0xE1, 0xF0]) + bytes([0x10]) + bytes(15), 3, 4, "TRIANGLES")  # b from an empty FIFO
    with pytest.raises(meshopt.MeshoptError, match="code table"):
        meshopt.decode(bytes([0xE1, 0xF0]) + bytes(15) + b"\x01", 3, 4, "TRIANGLES")
    for bad in ((4, 2, "TRIANGLES", "NONE"), (3, 3, "TRIANGLES", "NONE"), (3, 2, "TRIANGLES", "OCTAHEDRAL"),
                (1, 6, "ATTRIBUTES", "NONE"), (1, 260, "ATTRIBUTES", "NONE"), (1, 4, "ATTRIBUTES", "QUATERNION"),
                (1, 4, "POINTS", "NONE"), (1, 4, "ATTRIBUTES", "SHARPEN")):
        with pytest.raises(meshopt.MeshoptError):
            meshopt.check_params(*bad)


def _rotl(v: int, r: int) -> int:
    return ((v << r) | (v >> ((32 - r) & 31))) & 0xFFFFFFFF


@pytest.mark.parametrize("r", [0, 5, 15])
def test_version_1_xor_channel_with_rotation(r: int) -> None:
    """A hand-made version 1 stream: 4-byte XOR deltas stored rotated left by r (channel mode 2 | r << 4),
    every byte literal (control 3). gltfpack 1.3 never rotates, so this is the only test of the direction."""
    rng = np.random.default_rng(r)
    count = 21  # one block, not a whole number of 16-element groups
    vals = [int(x) for x in rng.integers(0, 2**32, count, dtype=np.uint64)]
    base = int(rng.integers(0, 2**32))
    prev, stored = base, []
    for v in vals:
        stored.append(_rotl(v ^ prev, r))
        prev = v
    st = np.array(stored, "<u4").view(np.uint8).reshape(count, 4)
    blocks = bytes([0xFF]) + b"".join(st[:, k].tobytes() for k in range(4))  # control byte, 4 literal rows
    tail = b"\0" * (24 - 5) + struct.pack("<I", base) + bytes([2 | (r << 4)])
    out = meshopt.decode(bytes([0xA1]) + blocks + tail, count, 4, "ATTRIBUTES").view("<u4")
    assert out.tolist() == vals
    with pytest.raises(meshopt.MeshoptError, match="channel mode"):  # mode 0 with rotation bits is invalid
        meshopt.decode(bytes([0xA1]) + blocks + tail[:-1] + bytes([0x10]), count, 4, "ATTRIBUTES")


def test_compiled_kernels_agree_with_their_python_source() -> None:
    """numba's integer semantics differ from Python's (fixed width, unsigned bytes): the kernels run as
    plain Python (``py_func``) must give the compiled results on the vendored streams."""
    for name in ("meshopt.glb", "meshopt-khr.glb"):
        doc, binb = glb_parts(DATA / name)
        for bv in doc["bufferViews"]:
            key = next((k for k in bv.get("extensions", {}) if "meshopt" in k), None)
            if not key:
                continue
            e = bv["extensions"][key]
            src = np.frombuffer(binb, np.uint8, count=e["byteLength"], offset=e["byteOffset"])
            if e["mode"] == "ATTRIBUTES":
                a = np.zeros(e["count"] * e["byteStride"], np.uint8)
                b = a.copy()
                args = (src, e["count"], e["byteStride"], 0 if src[0] == 0xA0 else 1, meshopt._BITS)
                assert meshopt._vertex_kernel(*args, a) == meshopt._vertex_kernel.py_func(*args, b) == 0
            else:
                a = np.zeros(e["count"], np.uint32)
                b = a.copy()
                assert meshopt._triangle_kernel(src, e["count"], a) == meshopt._triangle_kernel.py_func(src, e["count"], b) == 0
            assert np.array_equal(a, b)


def _views(path: Path) -> dict[int, tuple[np.ndarray, dict, dict]]:
    doc, binb = glb_parts(path)
    out = {}
    for i, bv in enumerate(doc["bufferViews"]):
        key = next((k for k in bv.get("extensions", {}) if "meshopt" in k), None)
        if key:
            e = bv["extensions"][key]
            src = binb[e.get("byteOffset", 0) : e.get("byteOffset", 0) + e["byteLength"]]
            out[i] = (meshopt.decode(src, e["count"], e["byteStride"], e["mode"], e.get("filter", "NONE"),
                                     khr=key.startswith("KHR")), e, bv)
    return out


def _canon(tris: np.ndarray) -> list[tuple[int, ...]]:
    t = tris.reshape(-1, 3)
    r = np.argmin(t, axis=1)
    return sorted(tuple(np.roll(x, -k)) for x, k in zip(t.tolist(), r))


@pytest.mark.parametrize("name", ["meshopt-fallback.glb", "meshopt-khr-fallback.glb"])
def test_decoded_views_equal_the_encoders_fallback(name: str) -> None:
    doc, _ = glb_parts(DATA / name)
    fallback = (DATA / doc["buffers"][1]["uri"]).read_bytes()
    views = _views(DATA / name)
    assert {e["mode"] for _, e, _ in views.values()} == {"ATTRIBUTES", "TRIANGLES"}
    for out, e, bv in views.values():
        ref = np.frombuffer(fallback[bv["byteOffset"] : bv["byteOffset"] + bv["byteLength"]], np.uint8)
        if e["mode"] == "TRIANGLES":  # the codec keeps each triangle and its winding, rotating its corners
            dt = "<u2" if e["byteStride"] == 2 else "<u4"
            assert _canon(out.view(dt)) == _canon(ref.view(dt))
        else:
            assert np.array_equal(out, ref)
    heads = {glb_parts(DATA / name)[1][e["byteOffset"]] for _, e, _ in views.values() if e["mode"] == "ATTRIBUTES"}
    assert heads == ({0xA1} if "khr" in name else {0xA0})  # KHR files use the version 1 vertex codec


def test_filters_against_the_source() -> None:
    """OCTAHEDRAL normals, COLOR colours, QUATERNION and EXPONENTIAL keyframes, decoded, against src.glb."""
    sdoc, sbin = glb_parts(DATA / "src.glb")

    def src_acc(i: int, dt: str) -> np.ndarray:
        a = sdoc["accessors"][i]
        v = sdoc["bufferViews"][a["bufferView"]]
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        return np.frombuffer(sbin, dt, count=a["count"] * n, offset=v["byteOffset"]).reshape(a["count"], n)

    sattr = sdoc["meshes"][0]["primitives"][0]["attributes"]
    spos, snrm, scol = (src_acc(sattr[k], "<f4") for k in ("POSITION", "NORMAL", "COLOR_0"))
    tree = cKDTree(spos)
    for name in ("meshopt.glb", "meshopt-khr.glb", "meshopt-float.glb"):
        doc, _ = glb_parts(DATA / name)
        views = _views(DATA / name)
        attrs = doc["meshes"][0]["primitives"][0]["attributes"]

        def acc(key: str, doc: dict = doc, attrs: dict = attrs, views: dict = views) -> np.ndarray:
            a = doc["accessors"][attrs[key]]
            out, e, _ = views[a["bufferView"]]
            dt = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5126: "<f4"}[a["componentType"]]
            n = {"VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
            arr = np.ndarray((a["count"], n), dt, out.tobytes(), a.get("byteOffset", 0), (e["byteStride"], np.dtype(dt).itemsize))
            if a.get("normalized"):
                return np.maximum(arr / {"<i1": 127, "<u1": 255, "<i2": 32767, "<u2": 65535}[dt], -1.0)
            return arr.astype(np.float64)

        node = doc["nodes"][0]
        pos = acc("POSITION") * node.get("scale", [1, 1, 1]) + node.get("translation", [0, 0, 0])
        d, k = tree.query(pos)
        assert d.max() < 1e-5, (name, d.max())
        filters = {views[doc["accessors"][attrs[a]]["bufferView"]][1].get("filter", "NONE") for a in attrs}
        assert "OCTAHEDRAL" in filters or "EXPONENTIAL" in filters
        assert np.abs(acc("NORMAL") - snrm[k]).max() < 0.02
        assert np.abs(acc("COLOR_0") - scol[k]).max() < 2.5 / 255
        if name != "meshopt.glb":
            assert "COLOR" in filters
        # keyframes: a half turn about y and a bob of 10 mm, resampled at 30 Hz by gltfpack
        ch = {c["target"]["path"]: doc["animations"][0]["samplers"][c["sampler"]] for c in doc["animations"][0]["channels"]}
        def keys(i: int, dt: str, n: int, doc: dict = doc, views: dict = views) -> tuple[np.ndarray, dict]:
            a = doc["accessors"][i]
            out, e, _ = views[a["bufferView"]]
            return np.frombuffer(out.tobytes(), dt, count=a["count"] * n, offset=a.get("byteOffset", 0)).reshape(-1, n), e
        t, _ = keys(ch["rotation"]["input"], "<f4", 1)
        q, eq = keys(ch["rotation"]["output"], "<i2", 4)
        assert eq["filter"] == "QUATERNION"
        half = np.pi * t[:, 0] / 2
        assert np.abs(q / 32767.0 - np.stack([0 * half, np.sin(half), 0 * half, np.cos(half)], 1)).max() < 2e-3
        tr, et = keys(ch["translation"]["output"], "<f4", 3)
        assert et["filter"] == "EXPONENTIAL"
        tk = np.linspace(0, 1, 5)
        assert np.abs(tr[:, 1] - np.interp(t[:, 0], tk, 0.01 * np.sin(np.pi * tk))).max() < 1e-5


# -- corrupt and hostile streams: refused, never an internal error ------------------------------------


def _mutations(n: int, size: int, seed: int) -> list[tuple[str, int, int]]:
    rng = np.random.default_rng(seed)
    return [("flip" if k % 2 == 0 else "trunc", int(rng.integers(0, size)), int(rng.integers(0, 8))) for k in range(n)]


@pytest.mark.parametrize("name", ["meshopt.glb", "meshopt-khr.glb", "draco.glb", "draco-seq.glb"])
def test_flipped_and_truncated_streams_never_crash(name: str, tmp_path: Path) -> None:
    doc, binb = glb_parts(DATA / name)
    if "draco" in name:
        bvi = doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"]
        spans = [(doc["bufferViews"][bvi].get("byteOffset", 0), doc["bufferViews"][bvi]["byteLength"], bvi, None)]
    else:
        spans = [(e["byteOffset"], e["byteLength"], i, k) for i, bv in enumerate(doc["bufferViews"])
                 for k, e in bv.get("extensions", {}).items() if "meshopt" in k and i <= 5]
    seen: dict[str, int] = {}
    for m, (kind, at, bit) in enumerate(_mutations(24, 1 << 30, 7)):
        off, length, bvi, key = spans[m % len(spans)]
        b = bytearray(binb)
        d = json.loads(json.dumps(doc))
        if kind == "flip":
            p = off + at % length
            b[p] ^= 1 << bit
            b[off + (at * 7) % length] ^= 0xFF
        else:  # a stream cut short (its stated length shrinks with it)
            cut = 1 + at % (length - 1)
            tgt = d["bufferViews"][bvi] if key is None else d["bufferViews"][bvi]["extensions"][key]
            tgt["byteLength"] = cut
        r = check_mesh(write_glb(tmp_path / f"m{m}.glb", d, bytes(b)))
        cs = codes(r)
        assert "internal_error" not in cs, [f.message for f in r.findings]
        if r.verdict == "unreadable":
            assert cs & UNREADABLE_OK, cs
        seen[r.verdict] = seen.get(r.verdict, 0) + 1
    assert seen.get("unreadable", 0) >= 6, seen  # most cuts and many flips are caught by the stream's own rules


def test_meshopt_absurd_parameters(tmp_path: Path) -> None:
    doc, binb = glb_parts(DATA / "meshopt.glb")
    key = "EXT_meshopt_compression"

    def run(change, name: str, limits: Limits | None = None):
        d = json.loads(json.dumps(doc))
        change(d)
        r = check_mesh(write_glb(tmp_path / name, d, binb), limits=limits)
        assert r.verdict == "unreadable" and "internal_error" not in codes(r), r.reason()
        return r

    def huge_count(d: dict) -> None:
        for i in (1, 5):
            e = d["bufferViews"][i]["extensions"][key]
            e["count"] = 3 * 10**9
            d["bufferViews"][i]["byteLength"] = e["count"] * e["byteStride"]
        d["buffers"][1]["byteLength"] = 10**13

    r = run(huge_count, "huge.glb")
    assert codes(r) & {"malformed", "over_check_limit"}
    r = run(lambda d: d["bufferViews"][1]["extensions"][key].update(mode="FOO"), "mode.glb")
    assert "malformed" in codes(r) and "FOO" in r.reason()
    r = run(lambda d: d["bufferViews"][5]["extensions"][key].update(filter="OCTAHEDRAL"), "filt.glb")
    assert "malformed" in codes(r)
    r = run(lambda d: d["bufferViews"][1].update(byteLength=8), "parent.glb")
    assert "malformed" in codes(r) and "byteLength" in r.reason()
    # the decoded size counts against the file's buffer budget before anything is decoded
    r = run(lambda d: None, "budget.glb", Limits(max_buffer_bytes=1000))
    assert "over_check_limit" in codes(r) and "max_buffer_bytes" in r.reason()
    # the fallback placeholder (no uri) is never read for compressed views, but an uncompressed view
    # reading it is refused with a reason that says so
    def plain(d: dict) -> None:
        del d["bufferViews"][1]["extensions"]
    r = run(plain, "plain.glb")
    assert "malformed" in codes(r) and "fallback" in r.reason()


@pytest.mark.parametrize("name", ["meshopt.glb", "draco.glb"])
def test_odd_extension_json_is_refused_not_crashed(name: str, tmp_path: Path) -> None:
    doc, binb = glb_parts(DATA / name)
    if "draco" in name:
        ext = ["meshes", 0, "primitives", 0, "extensions", "KHR_draco_mesh_compression"]
        paths = [ext, [*ext, "bufferView"], [*ext, "attributes"], [*ext, "attributes", "POSITION"]]
    else:
        ext = ["bufferViews", 1, "extensions", "EXT_meshopt_compression"]
        paths = [ext] + [[*ext, f] for f in ("buffer", "byteOffset", "byteLength", "byteStride", "count", "mode")]
        paths += [["buffers", 1, "extensions", "EXT_meshopt_compression"]]
    paths += [["extensionsRequired", 0], ["materials", 0, "pbrMetallicRoughness", "baseColorTexture", "extensions"]]
    for k, path in enumerate(paths):
        for v in (None, "x", -1, 10**30, {}):
            d = json.loads(json.dumps(doc))
            node = d
            for key in path[:-1]:
                node = node[key]
            node[path[-1]] = v
            r = check_mesh(write_glb(tmp_path / f"p{k}.glb", d, binb))
            assert "internal_error" not in codes(r), (path, v, r.reason())


def _set_var32(stream: bytearray, at: int, value: int) -> bytearray:
    """The stream with the varUI32 at ``at`` replaced by ``value``."""
    end = at
    while stream[end] & 0x80:
        end += 1
    return stream[:at] + bytearray(_leb(value)) + stream[end + 1 :]


@pytest.mark.parametrize("name", ["draco.glb", "draco-seq.glb"])
def test_draco_counts_are_bounded_before_decoding(name: str, tmp_path: Path) -> None:
    doc, binb = glb_parts(DATA / name)
    ext = doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]
    bv = doc["bufferViews"][ext["bufferView"]]
    off, n = bv.get("byteOffset", 0), bv["byteLength"]
    stream = bytearray(binb[off : off + n])
    assert stream[:5] == b"DRACO" and stream[5:7] == b"\x02\x02"
    if stream[8] == 0:  # sequential: num_faces first
        faces_at = 11
    else:  # edgebreaker: traversal type, num_encoded_vertices, then num_faces
        rd = draco._Reader(bytes(stream), 12)
        rd.var32()
        faces_at = rd.pos

    def with_stream(s: bytes, name2: str, change=None):
        d = json.loads(json.dumps(doc))
        d["bufferViews"][ext["bufferView"]]["byteLength"] = len(s)
        b = binb[:off] + bytes(s) + binb[off + n :]
        shift = len(s) - n
        for v in d["bufferViews"]:
            if v.get("byteOffset", 0) > off:
                v["byteOffset"] += shift
        d["buffers"][0]["byteLength"] += shift
        if change:
            change(d)
        r = check_mesh(write_glb(tmp_path / name2, d, b))
        assert "internal_error" not in codes(r), r.reason()
        return r

    r = with_stream(_set_var32(stream, faces_at, 2**31), "faces.glb")
    assert r.verdict == "unreadable" and "malformed" in codes(r) and "states" in r.reason()
    r = with_stream(stream[:40], "short.glb")
    assert r.verdict == "unreadable" and codes(r) & {"malformed"}, r.reason()
    old = bytearray(stream)
    old[5:7] = b"\x01\x00"
    r = with_stream(old, "v1.glb")
    assert "unsupported_format" in codes(r)
    # accessor counts that disagree with the stream: priced first (absurd), then held against the stream
    prim = doc["meshes"][0]["primitives"][0]
    r = with_stream(stream, "acc.glb", lambda d: d["accessors"][prim["attributes"]["POSITION"]].update(count=10**9))
    assert "over_check_limit" in codes(r)
    r = with_stream(stream, "few.glb", lambda d: d["accessors"][prim["indices"]].update(count=30))
    assert "malformed" in codes(r)


# -- sparse accessors, quantized attributes, texture transforms (JSON fixtures) ------------------------


def test_sparse_accessors(tmp_path: Path) -> None:
    V, F = box_mm()
    ref = check_mesh(fx.write_glb(tmp_path / "box.glb", V, F))
    assert ref.verdict == "printable"
    # positions entirely from a sparse accessor without a bufferView (zeros underneath)
    b = Blob()
    ind = b.accessor(F.astype("<u2").ravel(), 5123, "SCALAR")
    b.accessors.append({"componentType": 5126, "count": 8, "type": "VEC3", "sparse": {
        "count": 8,
        "indices": {"bufferView": b.view(np.arange(8, dtype="<u1").tobytes()), "componentType": 5121},
        "values": {"bufferView": b.view((V * 0.001).astype("<f4").tobytes())}}})
    doc = b.doc(**scene(), **one_mesh({"POSITION": 1}, ind))
    r = check_mesh(write_gltf(tmp_path / "sparse.gltf", doc, bytes(b.data)))
    assert r.verdict == "printable", r.reason()
    assert r.stats["volume_mm3"] == pytest.approx(ref.stats["volume_mm3"])
    # a sparse accessor over a bufferView: two wrong corners replaced
    b = Blob()
    ind = b.accessor(F.astype("<u2").ravel(), 5123, "SCALAR")
    wrong = V.copy()
    wrong[[2, 6]] = 500.0
    base = b.view((wrong * 0.001).astype("<f4").tobytes())
    sp = {"count": 2, "indices": {"bufferView": b.view(np.array([2, 6], "<u4").tobytes()), "componentType": 5125},
          "values": {"bufferView": b.view((V[[2, 6]] * 0.001).astype("<f4").tobytes())}}
    b.accessors.append({"bufferView": base, "componentType": 5126, "count": 8, "type": "VEC3", "sparse": sp})
    doc = b.doc(**scene(), **one_mesh({"POSITION": 1}, ind))
    r = check_mesh(write_gltf(tmp_path / "over.gltf", doc, bytes(b.data)))
    assert r.verdict == "printable" and r.stats["volume_mm3"] == pytest.approx(ref.stats["volume_mm3"])

    def bad(change, code: str) -> None:
        d = json.loads(json.dumps(doc))
        change(d["accessors"][1]["sparse"])
        r = check_mesh(write_gltf(tmp_path / "bad.gltf", d, bytes(b.data)))
        assert r.verdict == "unreadable" and code in codes(r), r.reason()

    bad(lambda s: s.update(count=9), "malformed")  # more substitutions than elements
    bad(lambda s: s.update(count=0), "malformed")
    bad(lambda s: s["indices"].update(componentType=5126), "malformed")
    bad(lambda s: s.update(count=3), "truncated")  # the index view holds two
    bad(lambda s: s["indices"].update(bufferView=0), "malformed")  # indices 0, 2, 1...: not increasing
    bad(lambda s: s["indices"].update(byteOffset=4), "truncated")
    b.data[b.views[sp["indices"]["bufferView"]]["byteOffset"] + 4] = 9  # index 9 of 8
    r = check_mesh(write_gltf(tmp_path / "range.gltf", doc, bytes(b.data)))
    assert "index_out_of_range" in codes(r)


@pytest.mark.parametrize("kind", ["i16", "u16n", "i8n", "u8"])
def test_quantized_positions_with_the_node_scale(kind: str, tmp_path: Path) -> None:
    V, F = box_mm()
    size = V.max(0)
    ref = check_mesh(fx.write_glb(tmp_path / "box.glb", V, F))
    b = Blob()
    ind = b.accessor(F.astype("<u1").ravel(), 5121, "SCALAR")
    node: dict = {}
    if kind == "i16":  # millimetres as integers, the node scales them to metres
        pos = b.accessor(np.pad(V.astype("<i2"), ((0, 0), (0, 1))), 5122, "VEC3")
        b.views[-1]["byteStride"] = 8
        node = {"scale": [0.001] * 3}
    elif kind == "u16n":
        pos = b.accessor(np.pad(np.round(V / size * 65535).astype("<u2"), ((0, 0), (0, 1))), 5123, "VEC3",
                         normalized=True)
        b.views[-1]["byteStride"] = 8
        node = {"scale": (size * 0.001).tolist()}
    elif kind == "i8n":
        q = np.round((V / size * 2 - 1) * 127).astype("<i1")
        q[q == -127] = -128  # -128 reads as -1 too (clamped)
        pos = b.accessor(np.pad(q, ((0, 0), (0, 1))), 5120, "VEC3", normalized=True)
        b.views[-1]["byteStride"] = 4
        node = {"scale": (size * 0.0005).tolist(), "translation": (size * 0.0005).tolist()}
    else:  # unsigned bytes, not normalized: whole millimetres again
        pos = b.accessor(np.pad(V.astype("<u1"), ((0, 0), (0, 1))), 5121, "VEC3")
        b.views[-1]["byteStride"] = 4
        node = {"scale": [0.001] * 3}
    uvq = np.zeros((8, 4), "<u1")  # u8 normalized UVs, padded to the 4-byte element alignment
    uvq[:, :2] = np.round(fx.box_uv(V) * 255)
    uv_view = b.view(uvq.tobytes())
    b.views[uv_view]["byteStride"] = 4
    b.accessors.append({"bufferView": uv_view, "componentType": 5121, "count": 8, "type": "VEC2", "normalized": True})
    uv = len(b.accessors) - 1
    col = b.accessor(np.full((8, 4), 200, "<u1"), 5121, "VEC4", normalized=True)
    img = b.view(fx.png_bytes(64, 64))
    doc = b.doc(**scene(node), **one_mesh({"POSITION": pos, "TEXCOORD_0": uv, "COLOR_0": col}, ind, material=0),
                extensionsUsed=["KHR_mesh_quantization"], extensionsRequired=["KHR_mesh_quantization"],
                images=[{"bufferView": img, "mimeType": "image/png"}], textures=[{"source": 0}],
                materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}])
    p = write_gltf(tmp_path / f"{kind}.gltf", doc, bytes(b.data))
    r = check_mesh(p)
    assert r.verdict == "printable", r.reason()
    assert r.stats["volume_mm3"] == pytest.approx(ref.stats["volume_mm3"], rel=1e-6)
    assert r.stats["bbox_mm"]["size"] == pytest.approx(size.tolist(), abs=1e-6)
    md = read_mesh(p, Limits())
    assert np.nanmax(np.abs(md.corner_uv - fx.box_uv(V)[F])) < 1e-9
    assert md.face_colour is not None and md.face_colour.all()


def test_normalized_32_bit_accessor_is_malformed_not_a_crash(tmp_path: Path) -> None:
    V, F = box_mm()
    b = Blob()
    ind = b.accessor(F.astype("<u4").ravel(), 5125, "SCALAR")
    pos = b.accessor(V.astype("<u4"), 5125, "VEC3", normalized=True)
    r = check_mesh(write_gltf(tmp_path / "n.gltf", b.doc(**scene(), **one_mesh({"POSITION": pos}, ind)), bytes(b.data)))
    assert r.verdict == "unreadable" and "malformed" in codes(r) and "normalized" in r.reason()


def _textured_box(tmp_path: Path, name: str, uv: np.ndarray, transform: dict | None, *, uv1: np.ndarray | None = None,
                  required: bool = True) -> Path:
    V, F = box_mm()
    b = Blob()
    ind = b.accessor(F.astype("<u2").ravel(), 5123, "SCALAR")
    pos = b.accessor((V * 0.001).astype("<f4"), 5126, "VEC3")
    attrs = {"POSITION": pos, "TEXCOORD_0": b.accessor(uv.astype("<f4"), 5126, "VEC2")}
    if uv1 is not None:
        attrs["TEXCOORD_1"] = b.accessor(uv1.astype("<f4"), 5126, "VEC2")
    img = b.view(fx.png_bytes(64, 64))
    info: dict = {"index": 0}
    ext = {}
    if transform is not None:
        info["extensions"] = {"KHR_texture_transform": transform}
        ext = {"extensionsUsed": ["KHR_texture_transform"]}
        if required:
            ext["extensionsRequired"] = ["KHR_texture_transform"]
    doc = b.doc(**scene(), **one_mesh(attrs, ind, material=0), **ext,
                images=[{"bufferView": img, "mimeType": "image/png"}], textures=[{"source": 0}],
                materials=[{"pbrMetallicRoughness": {"baseColorTexture": info}}])
    return write_gltf(tmp_path / name, doc, bytes(b.data))


def test_texture_transform_is_applied_to_the_uvs(tmp_path: Path) -> None:
    V, F = box_mm()
    uv = fx.box_uv(V)
    # the extension's own example: the lower left quadrant, rotated (offset [0, 1], rotation pi/2, scale 0.5)
    p = _textured_box(tmp_path, "example.gltf", uv, {"offset": [0, 1], "rotation": np.pi / 2, "scale": [0.5, 0.5]})
    md = read_mesh(p, Limits())
    got = {tuple(np.round(u, 9)) for u in md.corner_uv.reshape(-1, 2)}
    assert got == {(0.0, 1.0), (0.5, 1.0), (0.0, 0.5), (0.5, 0.5)}
    corners = {tuple(a): tuple(np.round(b, 9)) for a, b in zip(uv[F].reshape(-1, 2), md.corner_uv.reshape(-1, 2))}
    assert corners[(0.0, 0.0)] == (0.0, 1.0) and corners[(1.0, 1.0)] == (0.5, 0.5)
    assert corners[(1.0, 0.0)] == (0.0, 0.5) and corners[(0.0, 1.0)] == (0.5, 1.0)
    r = check_mesh(p)
    assert r.verdict == "printable" and "uv_out_of_range" not in codes(r), r.reason()
    # a transform that takes in-range UVs out of range is seen by the colour checks
    r = check_mesh(_textured_box(tmp_path, "out.gltf", uv, {"scale": [2, 2]}))
    assert "uv_out_of_range" in codes(r)
    # and one that brings out-of-range UVs (a quantized set, say) into range
    r = check_mesh(_textured_box(tmp_path, "in.gltf", uv * 4 - 1, {"offset": [0.25, 0.25], "scale": [0.25, 0.25]}))
    assert r.verdict == "printable" and "uv_out_of_range" not in codes(r), r.reason()
    # texCoord in the extension overrides the textureInfo's (TEXCOORD_0 here is far out of range)
    r = check_mesh(_textured_box(tmp_path, "tc.gltf", uv + 5, {"texCoord": 1}, uv1=uv))
    assert r.verdict == "printable" and "uv_out_of_range" not in codes(r), r.reason()
    r = check_mesh(_textured_box(tmp_path, "bad.gltf", uv, {"scale": [1, "x"]}))
    assert "malformed" in codes(r)


def test_supported_required_extensions_are_read_and_others_refused(tmp_path: Path) -> None:
    V, _ = box_mm()
    p = _textured_box(tmp_path, "t.gltf", fx.box_uv(V), {"offset": [0, 0]})
    assert check_mesh(p).verdict == "printable"
    doc = json.loads(p.read_text())
    doc["extensionsRequired"] = ["KHR_texture_transform", "EXT_example_unknown"]
    p.write_text(json.dumps(doc))
    r = check_mesh(p)
    assert "unsupported_format" in codes(r) and "EXT_example_unknown" in r.reason()
    assert "KHR_texture_transform" not in r.reason().split("(")[1]


# -- the glTF-Validator's valid files that were refused -----------------------------------------------


def test_validator_valid_files_once_refused(tmp_path: Path) -> None:
    mesh = VALIDATOR / "base" / "data" / "mesh"
    # a primitive without POSITION is valid glTF: skipped, so this file holds no triangles
    r = check_mesh(mesh / "primitive_no_position.gltf")
    assert "no_triangles" in codes(r) and "no POSITION" in r.reason(), r.reason()
    # four positions in TRIANGLES mode: one triangle, the fourth index ignored with a note
    r = check_mesh(mesh / "primitive_incompatible_mode.gltf")
    assert r.verdict != "unreadable" and "ignored_content" in codes(r)
    # an index accessor without a bufferView reads as zeros: degenerate faces, not "floats"
    r = check_mesh(mesh / "valid.gltf")
    assert r.verdict == "not printable" and "degenerate_faces" in codes(r)
    r = check_mesh(VALIDATOR / "ext" / "KHR_mesh_quantization" / "data" / "primitive" / "valid.gltf")
    assert r.verdict == "not printable" and "degenerate_faces" in codes(r)  # u8 zeros: a point, not a triangle
    # these two are valid, but the mesh's bytes are in a buffer with no uri in a .gltf, which the glTF
    # specification leaves to extensions: not in the file, so unreadable as an unsupported variant
    for name in ("unused_objects.gltf", "named_objects.gltf"):
        r = check_mesh(VALIDATOR / "base" / "data" / "root" / name)
        assert codes(r) & UNREADABLE_OK == {"unsupported_format"} and "not in the file" in r.reason(), r.reason()
    # an unused buffer without a uri is fine
    V, F = box_mm()
    g = fx.write_glb(tmp_path / "b.glb", V, F)
    doc, binb = glb_parts(g)
    doc["buffers"].append({"byteLength": 64})
    assert check_mesh(write_glb(tmp_path / "unused.glb", doc, binb)).verdict == "printable"
    # float indices are still refused, now with a reason naming them
    doc["accessors"][1]["componentType"] = 5126
    r = check_mesh(write_glb(tmp_path / "f.glb", doc, binb))
    assert "malformed" in codes(r) and "indices" in r.reason()
