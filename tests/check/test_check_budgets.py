"""The checker's work and memory budgets on hostile files (issue 16): every one refused early and clearly.

Each hostile file is built here, small on disk (sparse files, deflate,
headers that claim more than they hold), by a builder that
``benchmarks/bench_check_hostile.py`` also uses at full size. The tests
assert the finding and its message (which must name the limit) and, where
the defect was memory, that the peak traced allocation stays bounded; they
never assert wall-clock times (the benchmark measures those).
"""

from __future__ import annotations

import gzip
import json
import struct
import tracemalloc
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import fixtures_check as fx
from saucerfab.check import Limits, Report, check_mesh

MIB = 1 << 20

# -- builders (also used by benchmarks/bench_check_hostile.py) -----------------------------------


def glb_with(path: Path, edit: Callable[[dict[str, Any]], None], src: Path | None = None) -> Path:
    """The GLB ``src`` (default: the tests' box) with its JSON changed by ``edit`` (the binary chunk kept)."""
    data = (src or fx.write_glb(path, *fx.box())).read_bytes()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + jlen])
    rest = data[20 + jlen :]
    edit(doc)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 20 + len(js) + len(rest))
                     + struct.pack("<I4s", len(js), b"JSON") + js + rest)
    return path


def gltf_shared_tree(path: Path, depth: int, mesh: bool = True, copies: int = 2) -> Path:
    """A GLB whose node i lists node i+1 ``copies`` times: copies**depth instances of the last node."""
    def edit(doc: dict[str, Any]) -> None:
        doc["nodes"] = [{"children": [i + 1] * copies} for i in range(depth)] + [{"mesh": 0} if mesh else {}]
    return glb_with(path, edit)


def gltf_fan(path: Path, levels: int = 3, children: int = 3000, mesh: bool = True) -> Path:
    """``levels`` nodes, each listing the next ``children`` times (3 x 3000: 9 million leaf instances)."""
    return gltf_shared_tree(path, levels - 1, mesh=mesh, copies=children)


def gltf_shared_buffers(path: Path, n_buffers: int, nbytes: int, n_files: int = 1) -> Path:
    """A .gltf whose ``n_buffers`` buffers name ``n_files`` sparse files of ``nbytes`` each (one triangle per buffer)."""
    for k in range(n_files):
        with open(path.parent / f"big{k}.bin", "wb") as fh:
            fh.truncate(nbytes)  # sparse: nothing on disk, ``nbytes`` of zeros when read
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "buffers": [{"uri": f"big{i % n_files}.bin", "byteLength": nbytes} for i in range(n_buffers)],
        "bufferViews": [{"buffer": i, "byteLength": 36} for i in range(n_buffers)],
        "accessors": [{"bufferView": i, "componentType": 5126, "count": 3, "type": "VEC3"} for i in range(n_buffers)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": i}} for i in range(n_buffers)]}],
    }
    path.write_text(json.dumps(doc))
    return path


def obj_indented_vertices(path: Path, n: int, indent: bytes = b"  ") -> Path:
    """An OBJ of ``n`` vertex lines, each led by ``indent`` (blanks the parser accepts), and one face."""
    with open(path, "wb") as fh:
        line = indent + b"v 0 0 0\n"
        block = line * 100_000
        for _ in range(n // 100_000):
            fh.write(block)
        fh.write(line * (n % 100_000))
        fh.write(b"f 1 2 3\n")
    return path


def wrz_bomb(path: Path, inflated: int, fill: bytes = b" ") -> Path:
    """A gzip VRML file inflating to about ``inflated`` bytes of ``fill`` after its header."""
    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(b"#VRML V2.0 utf8\n")
        block = fill * (MIB // len(fill))
        for _ in range(inflated // MIB):
            fh.write(block)
    return path


def wrz_number_array(path: Path, n_numbers: int) -> Path:
    """A gzip VRML file whose one Coordinate ``point`` array holds ``n_numbers`` tens.

    (Two digits: Python shares one-character strings, so zeros would split for free.)
    """
    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(b"#VRML V2.0 utf8\nShape { geometry IndexedFaceSet { coord Coordinate { point [ ")
        block = b"10 " * 100_000
        for _ in range(n_numbers // 100_000):
            fh.write(block)
        fh.write(b"10 " * (n_numbers % 100_000))
        fh.write(b"] } coordIndex [ 0 1 2 -1 ] } }\n")
    return path


def png_claiming(width: int, height: int) -> bytes:
    """A tiny PNG whose header claims ``width`` x ``height`` pixels (its data runs out after a few rows)."""
    return fx.png_bomb(width, height)


def zipped_obj_with_textures(path: Path, textures: list[bytes]) -> Path:
    """A bureau upload: one OBJ + MTL + one texture per material, zipped (stored, as PNGs usually are)."""
    V, F = fx.box()
    uv = fx.box_uv(V)
    obj = ["mtllib m.mtl"] + [f"v {x} {y} {z}" for x, y, z in V] + [f"vt {u} {v}" for u, v in uv]
    mtl = []
    for i in range(len(textures)):
        mtl += [f"newmtl m{i}", "Kd 1 1 1", f"map_Kd t{i}.png"]
    for k in range(max(len(F), len(textures))):  # every texture used by a face (the box's faces repeat past 12)
        a, b, c = F[k % len(F)]
        obj += [f"usemtl m{k % len(textures)}", f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}"]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        z.writestr("m.obj", "\n".join(obj) + "\n")
        z.writestr("m.mtl", "\n".join(mtl) + "\n")
        for i, png in enumerate(textures):
            z.writestr(f"t{i}.png", png)
    return path


def streamed_3mf(path: Path, head: bytes, unit: bytes, n: int, tail: bytes) -> Path:
    """A deflated 3MF whose model part is ``head + unit * n + tail``, written a block at a time (never held whole)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", fx.CONTENT_TYPES)
        z.writestr("_rels/.rels", fx.RELS)
        with z.open("3D/3dmodel.model", "w", force_zip64=True) as fh:
            fh.write(head)
            block = unit * 100_000
            for _ in range(n // 100_000):
                fh.write(block)
            fh.write(unit * (n % 100_000))
            fh.write(tail)
    return path


def xml_element_bomb_3mf(path: Path, n_elements: int) -> Path:
    """A 3MF whose model part holds ``n_elements`` empty elements (no fast path: parsed as a tree)."""
    head = f'<?xml version="1.0"?><model unit="millimeter" xmlns="{fx.NS_CORE}"><resources>'.encode()
    return streamed_3mf(path, head, b"<a/>", n_elements, b"</resources><build/></model>")


def glb_json_bomb(path: Path, n_values: int) -> Path:
    """A box GLB whose JSON carries ``n_values`` empty objects in ``extras``."""
    def edit(doc: dict[str, Any]) -> None:
        doc["extras"] = [{} for _ in range(n_values)]
    return glb_with(path, edit)


# -- helpers ---------------------------------------------------------------------------------


def refused(r: Report, code: str, *needles: str) -> str:
    """The one-line reason of a report refused with ``code``; every needle must be in it."""
    assert "internal_error" not in r.codes, r.reason()
    assert code in r.codes, r.reason()
    reason = r.reason()
    for n in needles:
        assert n in reason, reason
    return reason


def traced_peak(fn: Callable[[], Report]) -> tuple[Report, int]:
    """``fn()`` and the peak bytes Python allocated meanwhile (numpy's and Pillow's buffers included)."""
    tracemalloc.start()
    try:
        r = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return r, peak


@pytest.fixture
def node_visits(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[int]]:
    """Counts glTF node visits (transform builds); past 20,000 the walk fails, as a runaway walk would."""
    from saucerfab.check.readers import gltf

    real = gltf._node_matrix
    calls = [0]

    def counted(n: dict[str, Any], i: int) -> np.ndarray:
        calls[0] += 1
        if calls[0] > 20_000:
            raise RuntimeError("the glTF node walk ran past 20,000 visits")
        return real(n, i)

    monkeypatch.setattr(gltf, "_node_matrix", counted)
    yield calls


# -- 1. glTF nodes shared in a tree ------------------------------------------------------------------


def test_gltf_nodes_shared_in_a_tree_are_priced_before_walking(tmp_path: Path, node_visits: list[int]) -> None:
    """Every node lists the next twice, 30 deep: 2^30 box instances, refused by their count, no walk."""
    p = gltf_shared_tree(tmp_path / "tree.glb", depth=30)
    assert p.stat().st_size < 4096
    refused(check_mesh(p), "over_check_limit", f"{12 * 2**30:,} triangles", "Limits.max_triangles")
    assert node_visits[0] == 0


def test_gltf_shared_nodes_without_meshes_are_bounded_by_visits(tmp_path: Path, node_visits: list[int]) -> None:
    """The same tree with no mesh at the leaf: nothing to instance, but 2^31 - 1 node visits."""
    p = gltf_shared_tree(tmp_path / "empty_tree.glb", depth=30, mesh=False)
    refused(check_mesh(p), "over_check_limit", f"{2**31 - 1:,} node visits", "Limits.max_node_visits")
    assert node_visits[0] == 0


def test_gltf_three_nodes_with_3000_repeated_children(tmp_path: Path, node_visits: list[int]) -> None:
    refused(check_mesh(gltf_fan(tmp_path / "fan.glb")), "over_check_limit",
            f"{12 * 3000**2:,} triangles", "Limits.max_triangles")
    refused(check_mesh(gltf_fan(tmp_path / "fan_empty.glb", mesh=False)), "over_check_limit",
            f"{1 + 3000 + 3000**2:,} node visits", "Limits.max_node_visits")
    assert node_visits[0] == 0


def test_gltf_shared_nodes_within_the_limits_are_still_instanced(tmp_path: Path) -> None:
    """Sharing is not refused as such: 2^3 instances of the box are read, and the visit limit is a knob."""
    p = gltf_shared_tree(tmp_path / "small_tree.glb", depth=3)
    r = check_mesh(p)
    assert "internal_error" not in r.codes and r.exit_code in (0, 1), r.reason()
    assert r.stats["triangles"] == 12 * 8
    refused(check_mesh(p, limits=Limits(max_node_visits=10)), "over_check_limit", "15 node visits",
            "Limits.max_node_visits")


def test_gltf_node_cycle_is_refused_when_priced(tmp_path: Path, node_visits: list[int]) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["nodes"] = [{"children": [1, 1]}, {"children": [2]}, {"mesh": 0, "children": [1]}]
    refused(check_mesh(glb_with(tmp_path / "cycle.glb", edit)), "malformed", "cycle")
    assert node_visits[0] == 0


# -- 2. glTF buffers: one budget for all bytes read -------------------------------------------------


def test_gltf_buffers_naming_one_file_read_it_once(tmp_path: Path) -> None:
    """Ten buffers naming one 32 MB file: read once and shared (it was read and kept ten times)."""
    p = gltf_shared_buffers(tmp_path / "shared.gltf", n_buffers=10, nbytes=32 * MIB)
    r, peak = traced_peak(lambda: check_mesh(p))
    assert "internal_error" not in r.codes and r.stats["triangles"] == 10, r.reason()
    assert peak < 2 * 32 * MIB, f"peak {peak / MIB:.0f} MiB for one 32 MiB buffer file"


def test_gltf_buffers_have_one_budget_per_file(tmp_path: Path) -> None:
    """Four distinct 32 MB files against a 100 MB budget: refused, naming the limit, before the fourth is read."""
    p = gltf_shared_buffers(tmp_path / "four.gltf", n_buffers=4, nbytes=32 * MIB, n_files=4)
    r, peak = traced_peak(lambda: check_mesh(p, limits=Limits(max_buffer_bytes=100 * MIB)))
    refused(r, "over_check_limit", "Limits.max_buffer_bytes")
    assert peak < 100 * MIB + 16 * MIB


def test_gltf_data_uri_buffers_count_against_the_budget(tmp_path: Path) -> None:
    import base64

    payload = "data:application/octet-stream;base64," + base64.b64encode(bytes(36 * 1024)).decode()
    doc = json.loads(gltf_shared_buffers(tmp_path / "d.gltf", 4, 36 * 1024).read_text())
    for i, b in enumerate(doc["buffers"]):
        b["uri"] = payload + "A" * (4 * i)  # four distinct URIs of ~36 KB each
        b["byteLength"] = 36 * 1024
    (tmp_path / "d.gltf").write_text(json.dumps(doc))
    refused(check_mesh(tmp_path / "d.gltf", limits=Limits(max_buffer_bytes=100 * 1024)), "over_check_limit",
            "Limits.max_buffer_bytes")
    r = check_mesh(tmp_path / "d.gltf")
    assert r.stats["triangles"] == 4, r.reason()


# -- 3. the OBJ vertex count counts what the parser reads ------------------------------------------


@pytest.mark.parametrize("chunk", [None, 7, 64])
def test_obj_statement_count_matches_the_parser(monkeypatch: pytest.MonkeyPatch, chunk: int | None) -> None:
    """Counted exactly as the parser matches, also when the count runs in slices (tiny ones here)."""
    from saucerfab.check.readers import obj

    if chunk is not None:
        monkeypatch.setattr(obj, "_COUNT_CHUNK", chunk)
    data = (b"v 1 2 3\n  v 1 2 3\n\t\tv 1 2 3\r\n \t v\t1 2 3\nvt 0 0\n  vt 0 0\nvn 0 0 1\n# v 1 2 3\nxv 1 2 3\n"
            b"v\t4 5 6\n   f 1 2 3\n\tf 1 2 3\nf 1 2 3\nusemtl a\n f 1 2 3 4\nvp 1\n"
            b"v 0.123456789 0.123456789 0.123456789 0.5 0.5 0.5 # a line longer than a slice\n  v 1 1 1")
    for start in (b"", b"   v 9 9 9\n", b"\tf 1 2 3\n", b"v 1 1 1\n"):
        d = start + data
        assert obj._count_lines(d, b"v") == len(obj._V.findall(d))
        assert obj._count_lines(d, b"vt") == len(obj._VT.findall(d))
        assert obj._count_lines(d, b"f") == sum(1 for tag, _ in obj._F_OR_MTL.findall(d) if tag == b"f")
    plain = b"v 1 2 3\nv\t1 2 3\nvt 0 0\nf 1 2 3\n"  # no indented line: the fast count
    assert obj._count_lines(plain, b"v") == len(obj._V.findall(plain)) == 2


def test_obj_indented_vertices_over_the_limit_are_refused_before_parsing(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Vertex lines led by two spaces, over the vertex limit: refused by the count, no line parsed."""
    from saucerfab.check.readers import obj

    def no_parse(*a: object, **k: object) -> None:
        raise RuntimeError("vertex lines were parsed before the count refused them")

    monkeypatch.setattr(obj, "_floats", no_parse)
    p = obj_indented_vertices(tmp_path / "indented.obj", 30_000)
    refused(check_mesh(p, limits=Limits(max_vertices=20_000)), "over_check_limit", "30,000", "Limits.max_vertices")
    p = obj_indented_vertices(tmp_path / "tabbed.obj", 30_000, indent=b" \t")
    refused(check_mesh(p, limits=Limits(max_vertices=20_000)), "over_check_limit", "30,000")


# -- 4. OBJ indices ---------------------------------------------------------------------------


def test_obj_huge_index_is_out_of_range_not_a_crash(tmp_path: Path) -> None:
    head = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    for faces in ("f 1 2 99999999999999999999999\n",  # bulk path
                  "f 1 2 3\nf 1 2 -99999999999999999999999\n",  # line-by-line path (a negative index)
                  "f 1 2 3 4 99999999999999999999999\nf 1 2 3\n"):  # line-by-line path (mixed corner counts)
        p = tmp_path / "big.obj"
        p.write_text(head + faces)
        refused(check_mesh(p), "index_out_of_range")
    # a texture coordinate the file lacks (however absurd its index) only costs that face its UVs
    p.write_text(head + "f 1/1 2/1 3/99999999999999999999999\nvt 0 0\n")
    assert "texcoords_missing" in {f.code for f in check_mesh(p).findings}


def test_obj_index_zero_is_out_of_range_on_both_paths(tmp_path: Path) -> None:
    """OBJ indices count from 1; 0 must not be read as 'the next vertex' by the relative-index arithmetic."""
    p = tmp_path / "zero.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 -1 -2\nv 0 0 1\nf 1 2 3\n")  # negative: line-by-line path
    refused(check_mesh(p), "index_out_of_range", "vertex 0")
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 0 1 2\nf 1 2 3\n")  # bulk path
    refused(check_mesh(p), "index_out_of_range", "vertex 0")
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/0 2/1 -1/1\n")  # a texture index of 0
    refused(check_mesh(p), "index_out_of_range", "texture coordinate 0")


# -- 5. budgets within the documented limits ---------------------------------------------------


def test_zip_bomb_is_refused_by_its_inflation_ratio_with_bounded_memory(tmp_path: Path) -> None:
    """200 MB of spaces in a 0.2 MB 3MF: refused once past the ratio budget, never held whole."""
    p = fx.zip_bomb_3mf(tmp_path / "bomb.3mf", inflated=200 * MIB)
    assert p.stat().st_size < MIB
    r, peak = traced_peak(lambda: check_mesh(p))
    refused(r, "archive_too_large", "Limits.max_inflation_ratio")
    assert peak < 48 * MIB, f"peak {peak / MIB:.0f} MiB"


def test_gzip_vrml_bomb_is_refused_with_bounded_memory(tmp_path: Path) -> None:
    p = wrz_bomb(tmp_path / "bomb.wrz", 200 * MIB)
    r, peak = traced_peak(lambda: check_mesh(p))
    refused(r, "archive_too_large", "Limits.max_inflation_ratio")
    assert peak < 48 * MIB, f"peak {peak / MIB:.0f} MiB"


def test_inflation_ratio_leaves_ordinary_archives_alone(tmp_path: Path) -> None:
    """A real model compresses 4-10:1; with the ratio bound off, the absolute budget still holds."""
    V, F, uv = fx.saucer_solid(30)
    assert check_mesh(fx.write_3mf(tmp_path / "s.3mf", V, F, uv=uv, texture=fx.png_bytes())).exit_code == 0
    p = fx.zip_bomb_3mf(tmp_path / "bomb.3mf", inflated=40 * MIB)
    refused(check_mesh(p, limits=Limits(max_inflation_ratio=0, max_uncompressed_bytes=24 * MIB)),
            "archive_too_large", "Limits.max_uncompressed_bytes")


def test_texture_pixels_have_one_budget_per_file(tmp_path: Path) -> None:
    """Three textures claiming 8192 x 8192 each (the per-texture maximum): past the file's budget (one such image)."""
    p = zipped_obj_with_textures(tmp_path / "textures.zip", [png_claiming(8192, 8192)] * 3)
    r = check_mesh(p)
    refused(r, "texture_too_large", "Limits.max_total_texture_pixels")
    statuses = [t["status"] for t in r.stats["textures"]]
    assert statuses[2] == "too_large" and statuses[:2] != ["too_large"] * 2, statuses
    ok = zipped_obj_with_textures(tmp_path / "small.zip", [fx.png_bytes(64, 64, seed=i) for i in range(3)])
    assert "texture_too_large" not in check_mesh(ok).codes


def test_xml_tree_bomb_is_refused_by_its_element_count(tmp_path: Path) -> None:
    """1.2 million empty elements (4.8 MB, deflated to a few kB) would be a 1 GB element tree."""
    p = xml_element_bomb_3mf(tmp_path / "tree.3mf", 1_200_000)
    r, peak = traced_peak(lambda: check_mesh(p))
    refused(r, "over_check_limit", "Limits.max_xml_elements")
    assert peak < 64 * MIB, f"peak {peak / MIB:.0f} MiB"


def test_vrml_number_array_is_bounded_before_conversion(tmp_path: Path) -> None:
    """A million numbers in one array (3 MB of text): converted in bounded slices, then refused by count.

    Converted whole, the array made one Python string per number: ~75 MB at peak.
    """
    p = wrz_number_array(tmp_path / "points.wrz", 999_999)
    r, peak = traced_peak(lambda: check_mesh(p, limits=Limits(max_vertices=100_000)))
    refused(r, "over_check_limit", "Limits.max_vertices")
    assert peak < 40 * MIB, f"peak {peak / MIB:.0f} MiB"


def test_glb_json_with_millions_of_values_is_refused_before_parsing(tmp_path: Path) -> None:
    p = glb_json_bomb(tmp_path / "json.glb", 2_100_000)
    r, peak = traced_peak(lambda: check_mesh(p))
    refused(r, "over_check_limit", "Limits.max_json_values")
    assert peak < 64 * MIB, f"peak {peak / MIB:.0f} MiB"


def test_every_budget_is_a_documented_limit() -> None:
    """Each budget is a Limits field named in the checker's README (the messages name them too)."""
    readme = (Path(__file__).resolve().parents[2] / "saucerfab" / "check" / "README.md").read_text()
    for name in ("max_node_visits", "max_buffer_bytes", "max_inflation_ratio", "free_inflation_bytes",
                 "max_total_texture_pixels", "max_total_texture_bytes", "max_xml_elements", "max_json_values",
                 "max_vrml_tokens", "max_uncompressed_bytes"):
        assert hasattr(Limits(), name), name
        assert f"`{name}`" in readme, name


def test_limits_defaults_keep_their_meaning() -> None:
    """The public Limits API: keyword construction and with_() keep working, new budgets have defaults."""
    lim = Limits(max_triangles=1000).with_(max_node_visits=5)
    assert lim.max_triangles == 1000 and lim.max_node_visits == 5
    with pytest.raises(TypeError):
        Limits().with_(no_such_limit=1)
