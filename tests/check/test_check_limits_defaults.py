"""The checker's default limits (issue 16): any single file judged in at most 10 s and 1 GiB.

The defaults bound the worst file within all of them together (500,000
triangles as a soup of 1.5 million vertices, one 8192 x 8192 texture);
``benchmarks/bench_check_hostile.py --large`` measures it. These tests hold
the cheap parts: a file over a cap is refused from its header, naming the
limit, the option that raises it and its price; the option raises the caps
that grow with a mesh; the self-intersection search bounds its exact tests.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path

import numpy as np
import pytest

import fixtures_check as fx
from saucerfab.check import Limits, check_mesh
from saucerfab.check.limits import COST_PER_MILLION_TRIANGLES
from saucerfab.check.readers import read_mesh


def sparse_binary_stl(path: Path, n: int) -> Path:
    """A binary STL whose header states ``n`` triangles and whose size matches (sparse: all zeros)."""
    with open(path, "wb") as fh:
        fh.write(b"header".ljust(80, b" ") + struct.pack("<I", n))
        fh.truncate(84 + 50 * n)
    return path


def test_defaults_keep_every_file_within_10_s_and_1_gib() -> None:
    """The measured budget (benchmarks/RESULTS.md, Checker budgets).

    500 k triangles, 3 vertices each, one 8192^2 texture.
    """
    lim = Limits()
    assert lim.max_triangles == 500_000 and lim.max_vertices == 3 * lim.max_triangles
    assert lim.max_total_texture_pixels == lim.max_texture_pixels == 8192 * 8192
    assert lim.max_file_bytes == 256 << 20 and lim.max_texture_bytes == 128 << 20
    assert lim.max_parts == 10_000


def test_one_triangle_over_the_default_is_refused_from_the_header(tmp_path: Path) -> None:
    n = Limits().max_triangles + 1
    p = sparse_binary_stl(tmp_path / "over.stl", n)
    t = time.perf_counter()
    r = check_mesh(p)
    assert time.perf_counter() - t < 2.0
    assert r.exit_code == 2 and r.codes == {"over_check_limit"}, r.reason()
    reason = r.reason()
    assert f"{n:,}" in reason and "Limits.max_triangles" in reason
    assert f"--max-triangles {n}" in reason and COST_PER_MILLION_TRIANGLES in reason  # how to raise it, and its price
    # PLY and OBJ headers and counts likewise
    ply = tmp_path / "over.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n" % n
                    + bytes(36 + 13 * n))
    r = check_mesh(ply)
    assert r.exit_code == 2 and "Limits.max_triangles" in r.reason() and "--max-triangles" in r.reason()


def test_the_option_raises_the_caps_that_grow_with_a_mesh(tmp_path: Path) -> None:
    base = Limits()
    n = base.max_triangles + 1
    lim = base.for_triangles(n)
    assert lim.max_triangles == n and lim.max_vertices == 3 * n
    assert lim.max_file_bytes >= base.max_file_bytes and lim.max_uncompressed_bytes >= base.max_uncompressed_bytes
    big = base.for_triangles(4 * base.max_triangles)
    assert big.max_file_bytes == 4 * base.max_file_bytes and big.max_vertices == 12 * base.max_triangles
    low = base.for_triangles(100)  # lowering the triangle cap leaves the others alone
    assert low.max_triangles == 100 and low.max_vertices == base.max_vertices
    with pytest.raises(ValueError):
        base.for_triangles(0)
    # the file one over the default is read with the option (an STL: three vertices a triangle)
    md = read_mesh(sparse_binary_stl(tmp_path / "over.stl", n), lim)
    assert len(md.faces) == n


def test_raised_to_never_lowers() -> None:
    base = Limits()
    same = base.raised_to(triangles=10, texture_px=64, file_bytes=10, inflated_bytes=10)
    assert same == base
    up = base.raised_to(triangles=2_000_000, texture_px=16384, file_bytes=3 << 30, inflated_bytes=5 << 30)
    assert up.max_triangles == 2_000_000 and up.max_vertices == 6_000_000
    assert up.max_texture_pixels == up.max_total_texture_pixels == 16384**2
    # a zip's entries are checked as files too: the larger of the two binds the file caps
    assert up.max_file_bytes == up.max_texture_bytes == 5 << 30 and up.max_uncompressed_bytes == 5 << 30
    assert base.raised_to(file_bytes=3 << 30).max_file_bytes == 3 << 30


def test_3mf_texture_coordinates_are_counted_apart_from_vertices(tmp_path: Path) -> None:
    """A textured 3MF soup of T triangles has 3 T vertices and 3 T texture coordinates: within max_vertices = 3 T."""
    V, F, uv = fx.saucer_solid(12)
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    p = fx.write_3mf(tmp_path / "soup.3mf", Vs, Fs, uv=uv[F].reshape(-1, 2), texture=fx.png_bytes())
    lim = Limits(max_triangles=len(F), max_vertices=3 * len(F))
    r = check_mesh(p, limits=lim)
    assert r.exit_code != 2, r.reason()
    r = check_mesh(p, limits=lim.with_(max_vertices=3 * len(F) - 1))
    assert r.exit_code == 2 and "Limits.max_vertices" in r.reason()


def test_exact_pair_tests_are_capped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A pile of overlapping triangles: the exact test sees at most a quarter of the node-pair budget."""
    from saucerfab.check import intersections

    seen = []
    real = intersections.pair_intersections

    def counting(tri, Fg, nrm, a, b, eps):  # type: ignore[no-untyped-def]
        seen.append(len(a))
        return real(tri, Fg, nrm, a, b, eps)

    monkeypatch.setattr(intersections, "pair_intersections", counting)
    rng = np.random.default_rng(11)
    V = rng.random((30_000, 3)) * 3
    F = np.arange(30_000).reshape(-1, 3)
    r = check_mesh(fx.write_stl(tmp_path / "pile.stl", V, F), limits=Limits(max_pair_tests=400_000))
    assert sum(seen) <= 100_000, sum(seen)
    assert r.stats["self_intersection_check"] == "partial" and "check_partial" in r.codes
    assert r.stats["self_intersecting_pairs"] > 0 and "self_intersections" in r.codes


def test_cli_help_says_the_default_and_the_price(capsys: pytest.CaptureFixture[str]) -> None:
    from saucerfab.cli import main

    with pytest.raises(SystemExit):
        main(["check", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--max-triangles N" in out and f"default {Limits().max_triangles:,}" in out
    assert "1 GB of memory and 15 s per million triangles" in out


def test_vrml_is_read_up_to_max_triangles(tmp_path: Path) -> None:
    """A VRML triangle list ('a b c -1') of exactly max_triangles is read; one more is refused.

    (The pre-allocation check estimated half the index count - twice the triangles - and refused an
    honest VRML at half the limit.)
    """
    V, F, _ = fx.saucer_solid(12)
    p = fx.write_vrml(tmp_path / "m.wrl", V, F)
    assert len(read_mesh(p, Limits(max_triangles=len(F))).faces) == len(F)
    r = check_mesh(p, limits=Limits(max_triangles=len(F) - 1))
    assert r.exit_code == 2 and "Limits.max_triangles" in r.reason()


def _objects_3mf(path: Path, n: int, instanced: bool = True) -> Path:
    """A 3MF defining ``n`` box objects (two bulk blocks each), all built when ``instanced``, else only the first."""
    V, F = fx.box((1.0, 1.0, 1.0))
    verts = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for x, y, z in V)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in F)
    objs = "".join(f'<object id="{o + 1}" type="model"><mesh><vertices>{verts}</vertices><triangles>{tris}'
                   "</triangles></mesh></object>" for o in range(n))
    items = "".join(f'<item objectid="{o + 1}"/>' for o in range(n if instanced else 1))
    xml = (f'<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" xml:lang="en-US" xmlns="{fx.NS_CORE}">'
           f"<resources>{objs}</resources><build>{items}</build></model>")
    return fx.write_3mf(path, None, None, model=xml)  # type: ignore[arg-type]


def test_parts_are_bounded_and_3mf_blocks_with_them(tmp_path: Path) -> None:
    """Each part costs its reader time of its own: parts instanced, and 3MF bulk blocks defined (3 per part)."""
    lim = Limits(max_parts=10)
    assert check_mesh(_objects_3mf(tmp_path / "ten.3mf", 10), limits=lim).exit_code != 2
    r = check_mesh(_objects_3mf(tmp_path / "eleven.3mf", 11), limits=lim)
    assert r.exit_code == 2 and "Limits.max_parts" in r.reason() and "--max-triangles" in r.reason()
    # defined but never built: the blocks are parsed before anything is instanced, so they are counted too
    r = check_mesh(_objects_3mf(tmp_path / "defined.3mf", 16, instanced=False), limits=lim)
    assert r.exit_code == 2 and "blocks" in r.reason() and "Limits.max_parts" in r.reason(), r.reason()
    assert Limits().for_triangles(10 * Limits().max_triangles).max_parts == 10 * Limits().max_parts


def _random_obj(rng: np.random.Generator, form: str, relative: bool, n_faces: int = 300, k: int = 0) -> bytes:
    """An OBJ interleaving v / vt / vn lines and faces of 1 to 7 corners, indices absolute or relative."""
    lines: list[str] = ["# random", "mtllib m.mtl"]
    nv = nvt = 0
    mats = ["a", "b", "c"]
    for f in range(n_faces):
        for _ in range(int(rng.integers(0, 4))):
            lines.append(f"v {rng.random():.4f} {rng.random():.4f} {rng.random():.4f}")
            nv += 1
        for _ in range(int(rng.integers(0, 4))):
            lines.append(f"vt {rng.random():.4f} {rng.random():.4f}")
            nvt += 1
        lines.append("vn 0 0 1")
        if rng.random() < 0.1:
            lines.append(f"usemtl {mats[int(rng.integers(0, 3))]}")
        if nv == 0:
            continue
        corners = []
        for _ in range(k or (int(rng.integers(1, 8)) if f else 3)):
            v = int(rng.integers(1, nv + 1))
            t = int(rng.integers(1, nvt + 3)) if nvt else 1  # now and then past the last vt: "missing"
            if relative and rng.random() < 0.7:
                v = v - nv - 1
                t = t - nvt - 1 if t <= nvt else t  # (one past the last stays absolute: 0 is no index)
            corners.append({"v": f"{v}", "v/t": f"{v}/{t}", "v/t/n": f"{v}/{t}/1", "v//n": f"{v}//1"}[form])
        lines.append("f " + " ".join(corners))
    for _ in range(3):
        lines.append(f"v {rng.random():.4f} {rng.random():.4f} {rng.random():.4f}")  # defined after the faces
    return ("\n".join(lines) + "\n").encode()


@pytest.mark.parametrize("form", ["v", "v/t", "v/t/n", "v//n"])
@pytest.mark.parametrize("relative", [False, True])
def test_mixed_polygons_and_relative_indices_read_in_bulk_as_line_by_line(form: str, relative: bool) -> None:
    """The numpy path for mixed polygon sizes and negative indices gives the line-by-line path's triangles."""
    from saucerfab.check.readers import obj

    for seed in range(6):
        data = _random_obj(np.random.default_rng(seed), form, relative)
        pay = [p for t, p in obj._F_OR_MTL.findall(data) if t == b"f"]
        nv, nvt = len(obj._V.findall(data)), len(obj._VT.findall(data))
        mats: list[bytes] = []
        mat, cur = [], -1
        for t, p in obj._F_OR_MTL.findall(data):
            if t == b"usemtl":
                if p.strip() not in mats:
                    mats.append(p.strip())
                cur = mats.index(p.strip())
            else:
                mat.append(cur)
        want = obj._faces_slow(data, nv, nvt, Limits())
        got = obj._faces_mixed(pay, np.array(mat, dtype=np.int64), nv, nvt, data, Limits(), form)
        assert got is not None, (form, relative, seed)
        for g, w in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(g, w)
        assert got[3] == want[3]


def test_a_relative_index_before_any_vertex_goes_to_the_line_by_line_path(tmp_path: Path) -> None:
    p = tmp_path / "bad.obj"
    p.write_bytes(b"v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n")
    r = check_mesh(p)
    assert r.exit_code == 2 and r.codes == {"index_out_of_range"}, r.reason()
    assert "OBJ face 0 refers to vertex -3" in r.reason()


@pytest.mark.parametrize("form", ["v", "v/t", "v/t/n", "v//n"])
def test_numba_parser_reads_relative_indices_as_the_reference(form: str) -> None:
    """Uniform faces with relative indices (``f -3 -2 -1``, streaming writers) take the numba parser too."""
    from saucerfab.check.readers import obj, obj_fast

    for seed in range(4):
        for k in (3, 4):
            data = _random_obj(np.random.default_rng(seed), form, True, k=k)
            nv, nvt = len(obj._V.findall(data)), len(obj._VT.findall(data))
            want = obj._faces_slow(data, nv, nvt, Limits())
            got = obj_fast.parse(data, Limits())
            assert got is not None, (form, seed, k)
            fv, ft, fmat, dropped = got[4], got[5], got[6], got[7]
            np.testing.assert_array_equal(fv, want[0])
            np.testing.assert_array_equal(ft, want[1])
            np.testing.assert_array_equal(fmat, want[2])
            assert dropped == want[3]
