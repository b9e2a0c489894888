"""The numba OBJ parser (``saucerfab.check.readers.obj_fast``) against the numpy/regex reference in ``obj``.

Each file is read twice through ``read_obj``: once with every file trying
the numba parser and once with none (the reference). The two must give the same ``MeshData``, bit for
bit, or the same ``ReadError`` code; and files the fast path does not handle
must really fall back (checked by counting its successes).
"""

from __future__ import annotations

import random
import struct
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from saucerfab.check.limits import DEFAULT_LIMITS, Limits
from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers import obj, obj_fast

MTL = b"newmtl red\nKd 1 0 0\nnewmtl tex\nKd 1 1 1\nmap_Kd tex.png\n"


def _png() -> bytes:
    import fixtures_check as fx

    return fx.png_bytes(4, 4)


def _read(tmp_path: Path, data: bytes, fast: bool, monkeypatch: pytest.MonkeyPatch, limits: Limits = DEFAULT_LIMITS):
    monkeypatch.setattr(obj, "_try_fast_parser", lambda n_bytes: fast)
    p = tmp_path / "m.obj"
    p.write_bytes(data)
    try:
        return obj.read_obj(p, data, limits)
    except ReadError as exc:
        return exc


def _same(a, b) -> None:
    if isinstance(a, ReadError) or isinstance(b, ReadError):
        assert isinstance(a, ReadError) and isinstance(b, ReadError), (a, b)
        assert (a.code, a.message) == (b.code, b.message)
        return
    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert isinstance(x, np.ndarray) and isinstance(y, np.ndarray), f.name
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert x.tobytes() == y.tobytes(), f.name  # bit-equal, NaN and -0.0 included
        elif f.name == "textures":
            assert [(t.name, t.status, t.width, t.height) for t in x] == [(t.name, t.status, t.width, t.height) for t in y]
        elif f.name == "notes":
            assert [(n.code, n.message) for n in x] == [(n.code, n.message) for n in y]
        else:
            assert x == y, f.name


@pytest.fixture
def fast_hits(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """How many times the numba parser read a file (rather than leaving it to the reference)."""
    hits: list[int] = []
    real = obj_fast.parse

    def counting(data: bytes, limits: Limits):
        out = real(data, limits)
        hits.append(out is not None)
        return out

    monkeypatch.setattr(obj_fast, "parse", counting)
    return hits


def _both(tmp_path: Path, data: bytes, monkeypatch: pytest.MonkeyPatch, fast_hits: list[int],
          limits: Limits = DEFAULT_LIMITS) -> bool:
    """Assert both paths agree on ``data``; return whether the fast path read it."""
    (tmp_path / "m.mtl").write_bytes(MTL)
    (tmp_path / "tex.png").write_bytes(_png())
    ref = _read(tmp_path, data, False, monkeypatch, limits)
    n = len(fast_hits)
    got = _read(tmp_path, data, True, monkeypatch, limits)
    _same(got, ref)
    return bool(fast_hits[n]) if len(fast_hits) > n else False


def _grid(n: int = 4) -> tuple[list[str], list[tuple[int, int, int, int]]]:
    vs = [f"{x * 0.25:.6f} {y * 0.5:.6f} {(x * y) % 3 - 1.5:.6f}" for y in range(n) for x in range(n)]
    quads = [(y * n + x + 1, y * n + x + 2, (y + 1) * n + x + 2, (y + 1) * n + x + 1)
             for y in range(n - 1) for x in range(n - 1)]
    return vs, quads


def _obj(form: str = "v/t", quads: bool = False, vcol: bool = False, eol: str = "\n", lead: str = "",
         extra: str = "") -> bytes:
    vs, qs = _grid()
    lines = ["# a comment", "mtllib m.mtl", "o thing", ""]
    lines += [f"{lead}v {v}" + (" 0.5 0.25 1" if vcol else "") for v in vs]
    lines += [f"{lead}vt {i / 16:.4f} {1 - i / 16:.4f}" for i in range(len(vs))]
    lines += ["vn 0 0 1"]
    lines.append("usemtl tex")
    for i, q in enumerate(qs):
        if i == len(qs) // 2:
            lines.append("usemtl red")
        corners = [q] if quads else [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
        for c in corners:
            fmt = {"v": "{0}", "v/t": "{0}/{0}", "v/t/n": "{0}/{0}/1", "v//n": "{0}//1"}[form]
            lines.append(f"{lead}f " + " ".join(fmt.format(i) for i in c))
    lines.append(extra)
    return (eol.join(lines) + eol).encode()


@pytest.mark.parametrize("form", ["v", "v/t", "v/t/n", "v//n"])
@pytest.mark.parametrize("quads", [False, True])
def test_common_layouts_read_fast_and_alike(tmp_path, monkeypatch, fast_hits, form, quads) -> None:
    assert _both(tmp_path, _obj(form, quads), monkeypatch, fast_hits)


@pytest.mark.parametrize("kw", [{"vcol": True}, {"eol": "\r\n"}, {"lead": " \t "}, {"extra": "l 1 2"},
                                {"extra": "curv2 1 2"}, {"extra": "s off\ng g1\n\n#end"}, {"extra": "p 1"}])
def test_variants_read_fast_and_alike(tmp_path, monkeypatch, fast_hits, kw) -> None:
    assert _both(tmp_path, _obj("v/t", **kw), monkeypatch, fast_hits)


def test_blank_runs_trailing_blanks_and_cr_tails(tmp_path, monkeypatch, fast_hits) -> None:
    data = (b"v  1.5\t2   3  \nv 0 0 0\r\nv 1 0 0\rjunk here\nv 0 1 0 1\nvt 0 0\nvt 1 0 0\n"
            b"f 1/1  2/2\t3/2 \r\nf\t2/1 3/1 4/1\n\n")
    assert _both(tmp_path, data, monkeypatch, fast_hits)


@pytest.mark.parametrize("data", [
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n",  # negative indices
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 2 3 4\n",  # mixed polygons
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 2 3\n",  # mixed forms
    b"v 0 0 0 # c\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # a comment in a v line
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 # c\n",  # ... in an f line
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",  # too few corners
    b"v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # too few coordinates
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0\nf 1 2 3\n",
    b"v 0 0 0\nv 1 0 0\nv 0 1 x\nf 1 2 3\n",  # not a number
    b"v 0 0 0\nv 1 0 0\nv 0 1 0x1\nf 1 2 3\n",
    b"v 0 0 0\nv 1 0 0\nv 0 1 -\nf 1 2 3\n",
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 2 3\n",  # index 0
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",  # past the end
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/0 2/1 3/1\n",  # uv index 0
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n",  # absurd index
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/99999999999999999999999 2/1 3/1\n",
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2",  # truncated line at the end
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1/",
    b"v 0 0 0\nv 1 0 0\nv 0 1",
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\n",  # no faces
    b"vn 0 0 1\n# nothing\n",  # not a mesh
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\\\n 3 2 1\n",  # continued line
    b"v 0 0 0\x0b\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # other whitespace
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\x1c\nf 1 2 3\n",
    b"v 0 0 0\nv 1 0 0\nv 0 1 \xa00\nf 1 2 3\n",
    b"v 1 1  1\nv 1\x0b2 3 4 5\nv 0 0 0\nf 1 2 3\n",
])
def test_other_files_fall_back_or_agree(tmp_path, monkeypatch, fast_hits, data) -> None:
    _both(tmp_path, data, monkeypatch, fast_hits)


def test_what_falls_back(tmp_path, monkeypatch, fast_hits) -> None:
    # relative indices are read by the numba parser too (issue 16: 11 s for a 500,000-triangle soup before)
    assert _both(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n", monkeypatch, fast_hits)
    assert not _both(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -4\n", monkeypatch, fast_hits)  # before the first
    assert not _both(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -0 1 2\n", monkeypatch, fast_hits)
    assert not _both(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 2 3 4\n", monkeypatch, fast_hits)
    assert not _both(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 5\n", monkeypatch, fast_hits)


def test_missing_texcoords_are_a_warning_on_both_paths(tmp_path, monkeypatch, fast_hits) -> None:
    data = b"mtllib m.mtl\nusemtl tex\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 2/1 4/2 3/1\n"
    assert _both(tmp_path, data, monkeypatch, fast_hits)
    md = _read(tmp_path, data, True, monkeypatch)
    assert [n.code for n in md.notes] == ["texcoords_missing"]


def test_caps_are_checked_from_counts(tmp_path, monkeypatch, fast_hits) -> None:
    small = Limits(max_vertices=5, max_triangles=3)
    for data in (b"v 0 0 0\n" * 6 + b"f 1 2 3\n", b"v 0 0 0\n" * 3 + b"vt 0 0\n" * 6 + b"f 1 2 3\n",
                 b"v 0 0 0\n" * 3 + b"f 1 2 3\n" * 4, b"v 0 0 0\n" * 4 + b"f 1 2 3 4\n" * 2,
                 b" v 0 0 0\n" * 6 + b"f 1 2 3\n"):
        assert not _both(tmp_path, data, monkeypatch, fast_hits, small)
        assert _read(tmp_path, data, True, monkeypatch, small).code == "over_check_limit"


def _random_number(rng: random.Random) -> str:
    kind = rng.randrange(8)
    if kind == 0:
        return repr(rng.uniform(-1e3, 1e3))
    if kind == 1:
        x = struct.unpack("<d", struct.pack("<Q", rng.getrandbits(64)))[0]
        return repr(x) if np.isfinite(x) else "1e308"
    if kind == 2:
        return f"{rng.uniform(-10, 10):.{rng.randrange(0, 12)}f}"
    if kind == 3:
        return f"{rng.uniform(-1, 1):.{rng.randrange(0, 17)}e}".replace("e", rng.choice("eE"))
    if kind == 4:
        digits = "".join(rng.choice("0123456789") for _ in range(rng.randrange(1, 25)))
        cut = rng.randrange(0, len(digits) + 1)
        s = digits[:cut] + "." + digits[cut:]
        if rng.random() < 0.5:
            s += rng.choice("eE") + rng.choice(["", "+", "-"]) + str(rng.randrange(0, 40))
        return rng.choice(["", "+", "-"]) + s
    if kind == 5:
        return rng.choice(["0", "-0", "+0", "-0.0", ".5", "5.", "-.5", "+5.", "0e999", "1e-400", "1e400",
                           "9007199254740993", "9007199254740992", "1e22", "1e23", "123456789012345678e-5",
                           "00000000000000000000000001.5", "4.9e-324", "2.2250738585072014e-308"])
    if kind == 6:
        return rng.choice(["inf", "-inf", "nan", "Infinity", "1_0", "NaN"])
    return str(rng.randrange(-10**6, 10**6))


def test_numbers_are_bit_equal_to_the_reference(tmp_path, monkeypatch, fast_hits) -> None:
    rng = random.Random(7)
    lines = [f"v {_random_number(rng)} {_random_number(rng)} {_random_number(rng)}" for _ in range(3000)]
    lines += [f"vt {_random_number(rng)} {_random_number(rng)}" for _ in range(500)]
    lines += ["f 1/1 2/2 3/3"]
    assert _both(tmp_path, ("\n".join(lines) + "\n").encode(), monkeypatch, fast_hits)
    # the parsed values themselves, against float()
    toks = [_random_number(rng) for _ in range(20000)]
    data = ("\n".join(f"v {a} {b} {c}" for a, b, c in zip(toks[0::3], toks[1::3], toks[2::3])) + "\nf 1 2 3\n")
    md = _read(tmp_path, data.encode(), True, monkeypatch)
    want = np.array([float(t) for t in toks[: len(toks) // 3 * 3]]).reshape(-1, 3)
    assert md.vertices.tobytes() == want.tobytes()


def test_warm_up_runs() -> None:
    assert obj_fast.warm_up()


def test_numba_started_tells_a_cold_process_from_a_warm_one() -> None:
    """``saucerfab.check.jit.numba_started`` reads an attribute numba makes on first use: a
    fresh process says False until a kernel has run, then True (a numba release that
    renamed it would fail here, not quietly keep the slow parser)."""
    import subprocess
    import sys

    script = (
        "from saucerfab.check.jit import numba_started\n"
        "import numba\n"
        "before = numba_started()\n"
        "numba.njit(lambda x: x + 1)(1)\n"
        "print(before, numba_started())\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], check=True, capture_output=True, text=True, timeout=120)
    assert proc.stdout.split() == ["False", "True"]


@pytest.mark.parametrize("started", [False, True])
def test_the_fast_parser_is_tried_from_a_smaller_size_once_numba_has_started(
    started: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    import saucerfab.check.jit

    monkeypatch.setattr(saucerfab.check.jit, "numba_started", lambda: started)
    assert obj.FAST_OBJ_BYTES_WARM < obj.FAST_OBJ_BYTES
    assert obj._try_fast_parser(obj.FAST_OBJ_BYTES)
    assert not obj._try_fast_parser(obj.FAST_OBJ_BYTES_WARM - 1)
    assert obj._try_fast_parser(obj.FAST_OBJ_BYTES_WARM) is started
    assert obj._try_fast_parser(obj.FAST_OBJ_BYTES - 1) is started
