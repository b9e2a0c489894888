"""The numba 3MF block parser (threemf_fast) against the reference numpy fast path of threemf.py.

Every block is read both ways: where the numba parser answers, it must be
exactly the reference's answer (coordinates bit for bit, triangle values,
attribute names); where it is not sure (single quotes, comments, entities,
blanks in values ...) it must hand the block back (None), and then what
``_parse_block`` returns, and what a whole file's read says, is the
reference's. Small files are forced onto the numba path by monkeypatching
the size thresholds.
"""

from __future__ import annotations

import random
import zipfile
from pathlib import Path

import fixtures_check as fx
import numpy as np
import pytest

from saucerfab.check.limits import DEFAULT_LIMITS, Limits
from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers import read_mesh
from saucerfab.check.readers import threemf_blocks as T
from saucerfab.check.readers import threemf_fast as F

TAGS = {"vertices": b"vertex", "triangles": b"triangle", "tex2coord": b"m:tex2coord"}


def reference(kind: str, content: bytes, prefix: bytes = b"") -> object:
    return T._parse_block(kind, content, prefix)  # fast=False: the reference


def same(a: object, b: object) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, tuple):
        assert isinstance(b, tuple)
        return a[1] == b[1] and same(a[0], b[0])
    assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
    # the reference's coordinates are a column-permuted (Fortran-ordered) copy, the numba parser's C-ordered
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a.view(np.uint8), b.view(np.uint8))


def both(kind: str, content: bytes, prefix: bytes = b"", *, taken: bool | None = None) -> object:
    """The numba answer (asserted equal to the reference's where it answers); ``taken``: whether it must."""
    ref = reference(kind, content, prefix)
    fast = F.parse_block(kind, content, prefix)
    if taken is not None:
        assert (fast is not None) == taken, (content[:200], fast)
    if fast is not None:
        assert ref is not None, content[:200]
        assert same(ref, fast), content[:200]
    return fast if fast is not None else ref


def elements(tag: bytes, rows: list[list[tuple[bytes, bytes]]], seps: list[bytes] | None = None,
             end: bytes = b"\n", lead: bytes = b"") -> bytes:
    """``<tag a="v" .../>`` elements; ``seps[i]`` goes before element i."""
    out = [lead]
    for i, row in enumerate(rows):
        out.append(seps[i % len(seps)] if seps else b"")
        out.append(b"<" + tag + b"".join(b' %s="%s"' % (n, v) for n, v in row) + b"/>")
    out.append(end)
    return b"".join(out)


# -- numbers --------------------------------------------------------------------

PLAIN = [b"0", b"-0", b"+0", b"0.0", b"-0.000000", b"1", b"-1", b"+1.5", b".5", b"-.5", b"5.", b"1e5", b"1E+05",
         b"1e-5", b"-2.5e-3", b"123456.789012", b"0.1", b"0.2", b"0.3", b"9007199254740993", b"1e22", b"1e23",
         b"4.9e-324", b"1.7976931348623157e308", b"00012.5000", b"3.141592653589793", b"1e-22", b"12345678901234567890",
         b"0.000000000000000000000000001", b"1e0", b"1e-0", b"1e+0", b"0e999999", b"2.2250738585072014e-308"]
HARD_OK = [b"inf", b"-inf", b"+inf", b"nan", b"-nan", b"Infinity", b"-Infinity", b"1e400", b"-1e400", b"1e-400",
           b"123456789012345678901234567890", b"1.00000000000000000000000001", b"INF", b"NaN", b"1_0"]
BROKEN = [b"", b"1.2.3", b"1e", b"1e+", b"--1", b"+-1", b"0x1A", b"1,5", b"abc", b"1f", b".", b"-", b"e5",
          b"1 ", b" 1", b"1\t2", b"1__0", b"_1", b"&#49;", b"1<", b"1>"]


def random_floats(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        x = rng.uniform(-1e3, 1e3) * 10.0 ** rng.randint(-8, 8)
        fmt = rng.choice(["%.6f", "%r", "%e", "%.17g", "%.3E", "%g", "%.12f", "%+.4f"])
        out.append((fmt % x).encode() if fmt != "%r" else repr(x).encode())
    return out


@pytest.mark.parametrize("kind", ["vertices", "tex2coord"])
def test_coordinates_bit_equal(kind: str) -> None:
    rng = random.Random(7)
    names = [b"x", b"y", b"z"] if kind == "vertices" else [b"u", b"v"]
    vals = random_floats(rng, 3000) + PLAIN * 3 + HARD_OK
    rng.shuffle(vals)
    k = len(names)
    vals = vals[: len(vals) // k * k]
    rows = [list(zip(names, vals[i:i + k])) for i in range(0, len(vals), k)]
    prefix = b"m:" if kind == "tex2coord" else b""
    got = both(kind, elements(TAGS[kind], rows), prefix, taken=True)
    assert isinstance(got, np.ndarray) and got.shape == (len(rows), k)


@pytest.mark.parametrize("value", PLAIN + HARD_OK)
def test_each_number(value: bytes) -> None:
    rows = [[(b"x", value), (b"y", b"1"), (b"z", value)], [(b"x", b"2"), (b"y", value), (b"z", b"-3")]]
    both("vertices", elements(b"vertex", rows), taken=True)


@pytest.mark.parametrize("value", BROKEN)
def test_broken_numbers_go_back(value: bytes) -> None:
    rows = [[(b"x", b"1"), (b"y", b"2"), (b"z", b"3")], [(b"x", b"2"), (b"y", value), (b"z", b"-3")]]
    both("vertices", elements(b"vertex", rows), taken=False)


@pytest.mark.parametrize("order", [(b"x", b"y", b"z"), (b"z", b"y", b"x"), (b"y", b"z", b"x")])
def test_attribute_order(order: tuple[bytes, ...]) -> None:
    rows = [[(n, b"%d.%d" % (i, j)) for j, n in enumerate(order)] for i in range(50)]
    got = both("vertices", elements(b"vertex", rows), taken=True)
    assert isinstance(got, np.ndarray)
    assert got[7].tolist() == [float(b"7.%d" % order.index(c)) for c in (b"x", b"y", b"z")]
    rows = [[(b"v", b"0.%d" % i), (b"u", b"1.%d" % i)] for i in range(20)]
    uv = both("tex2coord", elements(b"mat:tex2coord", rows), b"mat:", taken=True)
    assert isinstance(uv, np.ndarray) and uv[3].tolist() == [1.3, 0.3]


# -- triangles --------------------------------------------------------------------

TRI_SETS = [(b"v1", b"v2", b"v3"), (b"v1", b"v2", b"v3", b"pid"), (b"v1", b"v2", b"v3", b"pid", b"p1"),
            (b"v1", b"v2", b"v3", b"pid", b"p1", b"p2", b"p3"), (b"pid", b"p1", b"v3", b"v2", b"v1", b"p3", b"p2"),
            (b"v3", b"v1", b"v2", b"p1")]


@pytest.mark.parametrize("names", TRI_SETS)
def test_triangles(names: tuple[bytes, ...]) -> None:
    rng = random.Random(len(names))
    rows = [[(n, b"%d" % rng.choice([0, 1, 7, 10 ** rng.randint(0, 17), rng.randint(0, 10 ** 6)])) for n in names]
            for _ in range(500)]
    rows[3] = [(n, b"0000000000000000001") if i == 0 else (n, b"000000000000000001") for i, n in enumerate(names)]
    both("triangles", elements(b"triangle", rows), taken=False)  # 19 digits: the reference decides
    rows[3] = [(n, b"000000000000000001") for n in names]
    got = both("triangles", elements(b"triangle", rows), taken=True)
    assert isinstance(got, tuple) and got[1] == names and got[0].shape == (500, len(names))


@pytest.mark.parametrize("value", [b"+1", b"-1", b" 1", b"1 ", b"1.0", b"1e2", b"", b"0x1", b"999999999999999999999"])
def test_triangle_values_not_plain_go_back(value: bytes) -> None:
    rows = [[(b"v1", b"0"), (b"v2", b"1"), (b"v3", b"2")], [(b"v1", value), (b"v2", b"1"), (b"v3", b"2")]]
    both("triangles", elements(b"triangle", rows), taken=False)


@pytest.mark.parametrize("names", [(b"v1", b"v2"), (b"v1", b"v2", b"v3", b"v1"), (b"v1", b"v2", b"v3", b"p4"),
                                   (b"v1", b"v2", b"v3", b"PID")])
def test_triangle_names_the_reference_refuses(names: tuple[bytes, ...]) -> None:
    rows = [[(n, b"1") for n in names]] * 5
    both("triangles", elements(b"triangle", rows), taken=False)


# -- structure ----------------------------------------------------------------------

def xyz(i: int) -> list[tuple[bytes, bytes]]:
    return [(b"x", b"%d.5" % i), (b"y", b"-%d" % i), (b"z", b"1e%d" % (i % 5))]


@pytest.mark.parametrize("seps,end,lead", [
    ([b"\n"], b"\n", b""), ([b"\r\n  "], b"\r\n", b""), ([b"\t"], b"", b"\r\n"), ([b" ", b"\n\t\t", b"", b"\r\n"], b"  ", b""),
    ([b""], b"", b""),
])
def test_whitespace_between_elements(seps: list[bytes], end: bytes, lead: bytes) -> None:
    both("vertices", elements(b"vertex", [xyz(i) for i in range(40)], seps, end, lead), taken=True)


def test_whitespace_inside_elements() -> None:
    body = b"".join(b'<vertex\r\n x="%d"\t\ty="2"  z="3"\n/>' % i if i % 2 else b'<vertex x="%d" y="2" z="3" />' % i
                    for i in range(30))
    both("vertices", body, taken=True)


@pytest.mark.parametrize("body", [
    b"<vertex x='1' y='2' z='3'/>" * 3,  # single quotes
    b'<vertex x="1" y="2" z="3"/><!-- c --><vertex x="1" y="2" z="3"/>',  # comment
    b'<vertex x="1" y="2" z="3"/><vertex x="&#49;" y="2" z="3"/>',  # entity
    b'<vertex x="1" y="2" z="3"/><![CDATA[x]]>',  # CDATA
    b'<vertex x="1" y="2" z="3"/><?pi x?>',  # processing instruction
    b'<vertex x="1" y="2" z="3"/><vertex x="1" y="2"/>',  # missing attribute
    b'<vertex x="1" y="2" z="3"/><vertex x="1" y="2" z="3" w="4"/>',  # extra attribute
    b'<vertex x="1" y="2" z="3"/><vertex y="2" x="1" z="3"/>',  # order changes
    b'<vertex x="1" y="2" z="3"></vertex>',  # not self-closing
    b'<vertex x="1" y="2" z="3"/><vertexx x="1" y="2" z="3"/>',
    b'<vertex x="1" y="2" z="3"/>text',
    b'<vertex x = "1" y="2" z="3"/>',
    b'<vertex x="1"y="2" z="3"/>',
    b'<vertex x="1" y="2" z="3"/><vertex x="1" y="2" z="3"',  # truncated
    b'<vertex x="1" y="2" z="3"/><vertex x="1" y="2" z="3',
    b'<vertex x="1" y="2" z="3"/><vert',
    b'<vertex x="1" y="2" z="3"/ >',
    b'<vertex x="1" y="2" z="3" m:foo="1"/>',
    b'<vertex x="1" y="2" z="3" x="1"/>',
    b'  ', b'', b'<vertex/>',
    b'<vertex x="1" y="2" z="3"/>\x0c',  # a form feed is not XML whitespace
    b'<vertex\xa0x="1" y="2" z="3"/>',
])
def test_irregular_blocks_go_back(body: bytes) -> None:
    both("vertices", body, taken=False)


def test_prefix_must_match() -> None:
    rows = [[(b"u", b"0.5"), (b"v", b"1")]] * 4
    both("tex2coord", elements(b"m:tex2coord", rows), b"m:", taken=True)
    both("tex2coord", elements(b"m:tex2coord", rows), b"", taken=False)
    both("tex2coord", elements(b"tex2coord", rows), b"m:", taken=False)


# -- whole files: forced onto the numba path, against the reference ---------------------

def read_both(path: Path, monkeypatch: pytest.MonkeyPatch, limits: Limits = DEFAULT_LIMITS) -> tuple[object, object, int]:
    """(reference result or ReadError code, numba-path result or code, blocks the numba parser answered)."""
    def run() -> object:
        try:
            return read_mesh(path, limits)
        except ReadError as exc:
            return ("error", exc.code, exc.message)

    with monkeypatch.context() as m:
        m.setattr(T, "_use_fast", lambda n: False)
        ref = run()
    answered = []
    real = F.parse_block

    def spy(kind: str, content: bytes, prefix: bytes) -> object:
        got = real(kind, content, prefix)
        answered.append(got is not None)
        return got

    with monkeypatch.context() as m:
        m.setattr(T, "FAST_3MF_PART_BYTES", 0)
        m.setattr(T, "FAST_3MF_BLOCK_BYTES", 0)
        m.setattr(F, "parse_block", spy)
        fast = run()
    return ref, fast, sum(answered)


def assert_same_mesh(a: object, b: object) -> None:
    if isinstance(a, tuple) or isinstance(b, tuple):
        assert a == b
        return
    for name in ("vertices", "faces", "corner_uv", "face_texture", "face_colour"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            x, y = np.ascontiguousarray(x), np.ascontiguousarray(y)
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x.view(np.uint8), y.view(np.uint8)), name
    assert a.colour_kinds == b.colour_kinds and a.parts == b.parts and a.units == b.units
    assert [(n.code, n.message) for n in a.notes] == [(n.code, n.message) for n in b.notes]
    assert [(t.name, t.status) for t in a.textures] == [(t.name, t.status) for t in b.textures]


@pytest.mark.parametrize("style", ["uv", "corner_uv", "colors", "plain"])
def test_files_read_the_same(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, style: str) -> None:
    V, Fc, uv = fx.saucer_solid(n=12)
    kw: dict = {"uv": uv} if style == "uv" else {"colors": True} if style == "colors" else {}
    if style == "corner_uv":
        kw = {"corner_uv": uv[Fc]}
    png = fx.png_bytes() if style in ("uv", "corner_uv") else None
    p = fx.write_3mf(tmp_path / "a.3mf", V, Fc, texture=png, **kw)
    ref, fast, answered = read_both(p, monkeypatch)
    assert answered == (3 if png else 2)
    assert_same_mesh(ref, fast)


def rewrite(path: Path, out: Path, edit) -> Path:  # type: ignore[no-untyped-def]
    with zipfile.ZipFile(path) as z, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as w:
        for n in z.namelist():
            data = z.read(n)
            w.writestr(n, edit(data) if n == "3D/3dmodel.model" else data)
    return out


EDITS = {
    "crlf": lambda d: d.replace(b"/><", b"/>\r\n<"),
    "tabs": lambda d: d.replace(b'" ', b'"\t'),
    "single_quotes": lambda d: d.replace(b'x="0.000000"', b"x='0.000000'"),
    "comment": lambda d: d.replace(b"</vertices>", b"<!-- end --></vertices>"),
    "bad_number": lambda d: d.replace(b'y="0.000000"', b'y="0.0.0"', 1),
    "bad_index": lambda d: d.replace(b'v1="0"', b'v1="x"', 1),
    "index_out_of_range": lambda d: d.replace(b'v1="0"', b'v1="99999"', 1),
    "negative_index": lambda d: d.replace(b'v1="0"', b'v1="-1"', 1),
    "huge_index": lambda d: d.replace(b'v1="0"', b'v1="99999999999999999999999"', 1),
    "missing_v3": lambda d: d.replace(b' v3="', b' v4="', 1),
    "truncated": lambda d: d.replace(b"</triangles>", b"", 1),
    "exponents": lambda d: d.replace(b'z="', b'z="1e-3').replace(b'x="', b'x="-'),
    "inf": lambda d: d.replace(b'z="', b'z="inf', 1).replace(b'x="', b'x="-', 3),
    "uv_broken": lambda d: d.replace(b'u="0.000000"', b'u="0.0e"', 1),
    "p_out_of_range": lambda d: d.replace(b'p1="0"', b'p1="999999"', 1),
    "entity": lambda d: d.replace(b'x="0.000000"', b'x="&#48;"', 1),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_edited_files_same_verdict(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, edit: str) -> None:
    V, Fc, uv = fx.saucer_solid(n=10)
    p = fx.write_3mf(tmp_path / "a.3mf", V, Fc, uv=uv, texture=fx.png_bytes())
    q = rewrite(p, tmp_path / "b.3mf", EDITS[edit])
    ref, fast, _ = read_both(q, monkeypatch)
    assert_same_mesh(ref, fast)


def test_counts_over_limits_same_verdict(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    V, Fc, uv = fx.saucer_solid(n=10)
    p = fx.write_3mf(tmp_path / "a.3mf", V, Fc, uv=uv, texture=fx.png_bytes())
    for lim in (Limits(max_vertices=len(V) - 1), Limits(max_triangles=len(Fc) - 1)):
        ref, fast, answered = read_both(p, monkeypatch, lim)
        assert isinstance(ref, tuple) and ref[1] == "over_check_limit" and answered < 3  # refused before the block
        assert ref == fast


def test_conformance_samples_read_the_same(monkeypatch: pytest.MonkeyPatch) -> None:
    data = Path(__file__).resolve().parents[1] / "data" / "conformance" / "3mf-samples"
    files = sorted(data.rglob("*.3mf"))
    assert files
    total = 0
    for p in files:
        ref, fast, answered = read_both(p, monkeypatch)
        total += answered
        assert_same_mesh(ref, fast)
    assert total > 0


def test_thresholds_and_warm_up(monkeypatch: pytest.MonkeyPatch) -> None:
    assert F.warm_up() and F.ready()
    assert T._use_fast(0)  # loaded: every part's blocks from FAST_3MF_BLOCK_BYTES on
    monkeypatch.setattr(F, "ready", lambda: False)
    assert not T._use_fast(T.FAST_3MF_PART_BYTES - 1) and T._use_fast(T.FAST_3MF_PART_BYTES)
    body = elements(b"vertex", [xyz(i) for i in range(10)])
    calls = []
    monkeypatch.setattr(F, "parse_block", lambda *a: calls.append(a) or None)
    T._parse_block("vertices", body, b"", True)
    assert not calls  # a small block: the reference alone
    monkeypatch.setattr(T, "FAST_3MF_BLOCK_BYTES", len(body))
    assert same(T._parse_block("vertices", body, b"", True), reference("vertices", body))
    assert len(calls) == 1  # handed back (None), then read by the reference
