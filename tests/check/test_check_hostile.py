"""The checker on hostile and broken input: a clean one-line result (exit 2 or 1), never a traceback.

The corpus is generated here: zip bombs (honest and lying headers), billion
laughs, external entities, path traversal, PNG decompression bombs,
truncations, empty files, mislabelled files, garbage, headers claiming huge
counts, a 10-million-face STL, instancing bombs; plus a hypothesis fuzz test
mutating valid files of every format.
"""

from __future__ import annotations

import functools
import gzip
import io
import json
import os
import shutil
import struct
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fixtures_check as fx
from saucerfab.check import Limits, Report, check_mesh


def one_clean_result(r: Report, exit_codes: tuple[int, ...] = (1, 2)) -> Report:
    """The contract for bad input: a verdict, a known code, one-line messages, no checker failure."""
    assert isinstance(r, Report)
    assert r.exit_code in exit_codes, r.reason()
    assert "internal_error" not in r.codes, r.reason()
    assert all("\n" not in f.message for f in r.findings)
    json.dumps(r.to_dict(), allow_nan=False)
    return r


def only(r: Report, code: str) -> None:
    assert code in r.codes, r.reason()


# -- archives and XML --------------------------------------------------------------


def test_zip_bomb_is_cut_at_the_limit(tmp_path: Path) -> None:
    p = fx.zip_bomb_3mf(tmp_path / "bomb.3mf", inflated=64 << 20)
    assert p.stat().st_size < 1 << 20  # ~1000:1
    r = one_clean_result(check_mesh(p, limits=Limits(max_uncompressed_bytes=16 << 20)), (2,))
    only(r, "archive_too_large")


def test_zip_headers_lying_low_or_high(tmp_path: Path) -> None:
    p = fx.zip_bomb_3mf(tmp_path / "liar.3mf", inflated=32 << 20)
    fx.lie_about_sizes(p, "3D/3dmodel.model", claimed=1000)
    one_clean_result(check_mesh(p, limits=Limits(max_uncompressed_bytes=8 << 20)), (2,))
    V, F = fx.box()
    q = fx.write_3mf(tmp_path / "claims.3mf", V, F, colors=True)
    fx.lie_about_sizes(q, "3D/3dmodel.model", claimed=(1 << 32) - 2)
    r = one_clean_result(check_mesh(q), (2,))
    only(r, "archive_too_large")


def test_too_many_zip_entries(tmp_path: Path) -> None:
    V, F = fx.box()
    p = fx.write_3mf(tmp_path / "many.3mf", V, F, extra={f"junk/{i}.txt": b"x" for i in range(50)})
    only(one_clean_result(check_mesh(p, limits=Limits(max_zip_entries=20)), (2,)), "archive_too_large")


def test_billion_laughs_and_external_entities_are_refused(tmp_path: Path) -> None:
    only(one_clean_result(check_mesh(fx.billion_laughs_3mf(tmp_path / "lol.3mf")), (2,)), "xml_forbidden")
    only(one_clean_result(check_mesh(fx.external_entity_3mf(tmp_path / "xxe.3mf")), (2,)), "xml_forbidden")


def test_entity_in_rels_is_refused(tmp_path: Path) -> None:
    V, F = fx.box()
    p = fx.write_3mf(tmp_path / "r.3mf", V, F, colors=True)
    data = io.BytesIO()
    with zipfile.ZipFile(p) as src, zipfile.ZipFile(data, "w") as dst:
        for i in src.infolist():
            body = src.read(i)
            if i.filename == "_rels/.rels":
                body = b'<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "b">]>' + body.split(b"?>", 1)[1]
            dst.writestr(i, body)
    p.write_bytes(data.getvalue())
    only(one_clean_result(check_mesh(p), (2,)), "xml_forbidden")


def test_path_traversal_entries_and_references(tmp_path: Path) -> None:
    only(one_clean_result(check_mesh(fx.traversal_3mf(tmp_path / "t.3mf")), (2,)), "archive_unsafe_path")
    V, F = fx.box()
    for evil in ("/../../etc/passwd", "../x.png"):
        xml = fx.model_xml(V, F, uv=fx.box_uv(V), texture_path=evil)
        r = one_clean_result(check_mesh(fx.write_3mf(tmp_path / "ref.3mf", V, F, model=xml)), (1,))
        only(r, "texture_path_unsafe")
    xml = fx.model_xml(V, F, colors=True).replace(
        '<build><item objectid="1"/>',
        '<build><item objectid="1" p:path="../../other.model" '
        'xmlns:p="http://schemas.microsoft.com/3dmanufacturing/production/2015/06"/>')
    only(one_clean_result(check_mesh(fx.write_3mf(tmp_path / "item.3mf", V, F, model=xml)), (2,)),
         "archive_unsafe_path")


def test_texture_symlink_out_of_the_folder_is_not_followed(tmp_path: Path) -> None:
    V, F = fx.box()
    outside = tmp_path / "secret"
    outside.mkdir()
    (outside / "s.png").write_bytes(fx.png_bytes())
    model = tmp_path / "model"
    model.mkdir()
    fx.write_obj(model / "m.obj", V, F, uv=fx.box_uv(V), texture=fx.png_bytes(), write_texture=False)
    os.symlink(outside / "s.png", model / "texture.png")
    only(one_clean_result(check_mesh(model / "m.obj"), (1,)), "texture_path_unsafe")


def test_component_instancing_bomb(tmp_path: Path) -> None:
    """Objects nesting 100 components each, four deep: 10^8 box instances, refused before any array is made."""
    V, F = fx.box()
    base = fx.model_xml(V, F, colors=True)
    comps = []
    for level in range(2, 6):
        inner = "".join(f'<component objectid="{level - 1}"/>' for _ in range(100))
        comps.append(f'<object id="{level}" type="model"><components>{inner}</components></object>')
    xml = base.replace("</resources>", "".join(comps) + "</resources>").replace(
        '<item objectid="1"/>', '<item objectid="5"/>')
    r = one_clean_result(check_mesh(fx.write_3mf(tmp_path / "inst.3mf", V, F, model=xml)), (2,))
    only(r, "over_check_limit")


def test_component_cycle(tmp_path: Path) -> None:
    V, F = fx.box()
    xml = fx.model_xml(V, F, colors=True).replace(
        "</resources>", '<object id="7" type="model"><components><component objectid="7"/></components>'
                        "</object></resources>").replace('<item objectid="1"/>', '<item objectid="7"/>')
    only(one_clean_result(check_mesh(fx.write_3mf(tmp_path / "cyc.3mf", V, F, model=xml)), (2,)),
         "over_check_limit")


# -- images --------------------------------------------------------------------------


def test_png_decompression_bomb_texture_is_not_decoded(tmp_path: Path) -> None:
    V, F = fx.box()
    bomb = fx.png_bomb(100_000, 100_000)
    assert len(bomb) < 100_000
    r = one_clean_result(check_mesh(fx.write_3mf(tmp_path / "pb.3mf", V, F, uv=fx.box_uv(V), texture=bomb)), (1,))
    only(r, "texture_too_large")
    assert r.stats["textures"][0]["width"] == 100_000  # from the header, never decoded


def test_png_named_obj_and_other_mislabelled_files(tmp_path: Path) -> None:
    (tmp_path / "image.obj").write_bytes(fx.png_bytes())
    only(one_clean_result(check_mesh(tmp_path / "image.obj"), (2,)), "not_a_mesh")
    (tmp_path / "bomb.stl").write_bytes(fx.png_bomb())
    only(one_clean_result(check_mesh(tmp_path / "bomb.stl"), (2,)), "not_a_mesh")
    (tmp_path / "doc.ply").write_bytes(b"%PDF-1.7\n" + os.urandom(500))
    only(one_clean_result(check_mesh(tmp_path / "doc.ply"), (2,)), "not_a_mesh")


# -- truncated, empty, garbage -------------------------------------------------------


def _good_files(tmp: Path) -> dict[str, Path]:
    V, F, uv = fx.saucer_solid(6)
    png = fx.png_bytes(32, 32)
    (tmp / "t.png").write_bytes(png)
    return {
        "3mf": fx.write_3mf(tmp / "g.3mf", V, F, uv=uv, texture=png),
        "obj": fx.write_obj(tmp / "g.obj", V, F, uv=uv, texture=png),
        "stl": fx.write_stl(tmp / "g.stl", V, F),
        "stla": fx.write_stl(tmp / "ga.stl", V, F, ascii=True),
        "ply": fx.write_ply(tmp / "g.ply", V, F, colors=True),
        "plya": fx.write_ply(tmp / "ga.ply", V, F, binary=False),
        "glb": fx.write_glb(tmp / "g.glb", V, F, uv=uv, texture=png),
        "wrl": fx.write_vrml(tmp / "g.wrl", V, F, uv=uv, texture="t.png"),
    }


def test_good_corpus_is_printable(tmp_path: Path) -> None:
    for kind, p in _good_files(tmp_path).items():
        r = check_mesh(p)
        assert r.exit_code == 0 and not r.errors, (kind, r.reason())


@pytest.mark.parametrize("fraction", [0.0, 0.02, 0.3, 0.5, 0.77, 0.99])
def test_truncated_files(tmp_path: Path, fraction: float) -> None:
    for kind, p in _good_files(tmp_path).items():
        data = p.read_bytes()
        cut = tmp_path / f"cut{p.suffix}"
        cut.write_bytes(data[: max(1, int(len(data) * fraction))])
        one_clean_result(check_mesh(cut))


def test_empty_file_and_missing_file(tmp_path: Path) -> None:
    for ext in (".3mf", ".obj", ".stl", ".ply", ".glb", ".wrl", ".xyz"):
        (tmp_path / f"e{ext}").write_bytes(b"")
        only(one_clean_result(check_mesh(tmp_path / f"e{ext}"), (2,)), "empty_file")
    only(one_clean_result(check_mesh(tmp_path / "nope.stl"), (2,)), "file_not_found")
    only(one_clean_result(check_mesh(tmp_path), (2,)), "file_not_found")


def test_random_garbage(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    for ext in (".3mf", ".obj", ".stl", ".ply", ".glb", ".wrl", ".bin"):
        for size in (1, 83, 84, 134, 4096, 100_000):
            p = tmp_path / f"g{size}{ext}"
            p.write_bytes(rng.integers(0, 256, size, dtype=np.uint8).tobytes())
            one_clean_result(check_mesh(p), (2,))
    (tmp_path / "text.obj").write_text("hello world\nthis is not a mesh\n" * 50)
    only(one_clean_result(check_mesh(tmp_path / "text.obj"), (2,)), "not_a_mesh")


# -- headers claiming huge counts; 10 million faces ---------------------------------


def test_headers_claiming_a_billion_elements(tmp_path: Path) -> None:
    p = tmp_path / "huge.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n"
                  b"property float y\nproperty float z\nelement face 2000000000\n"
                  b"property list uchar int vertex_indices\nend_header\n" + b"\0" * 64)
    only(one_clean_result(check_mesh(p), (2,)), "truncated")
    q = tmp_path / "huge_ascii.ply"
    q.write_bytes(p.read_bytes().replace(b"binary_little_endian", b"ascii"))
    only(one_clean_result(check_mesh(q), (2,)), "truncated")
    s = tmp_path / "huge.stl"
    s.write_bytes(b"x" * 80 + struct.pack("<I", 1_000_000_000) + b"\0" * 500)
    only(one_clean_result(check_mesh(s), (2,)), "truncated")
    g = fx.write_glb(tmp_path / "huge.glb", *fx.box())
    data = bytearray(g.read_bytes())
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(bytes(data[20 : 20 + jlen]))
    doc["accessors"][0]["count"] = 1_000_000_000
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = bytes(data[20 + jlen :])
    g.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js) + len(rest)) + struct.pack("<I4s", len(js), b"JSON")
                  + js + rest)
    one_clean_result(check_mesh(g), (2,))


def test_ten_million_face_stl_is_refused_quickly(tmp_path: Path) -> None:
    """A real 10-million-triangle binary STL (sparse on disk): refused from its header, nothing read."""
    p = tmp_path / "ten_million.stl"
    n = 10_000_000
    with open(p, "wb") as fh:
        fh.write(b"big".ljust(80, b" ") + struct.pack("<I", n))
        fh.truncate(84 + 50 * n)
    r = one_clean_result(check_mesh(p), (2,))
    only(r, "over_check_limit")
    assert "10,000,000" in r.reason() and "max-triangles" in r.reason()


def test_checker_limits_are_respected(tmp_path: Path) -> None:
    V, F, uv = fx.saucer_solid(10)
    p = fx.write_3mf(tmp_path / "s.3mf", V, F, uv=uv, texture=fx.png_bytes(300, 300))
    only(one_clean_result(check_mesh(p, limits=Limits(max_file_bytes=1000)), (2,)), "over_check_limit")
    only(one_clean_result(check_mesh(p, limits=Limits(max_triangles=100)), (2,)), "over_check_limit")
    r = one_clean_result(check_mesh(p, limits=Limits(max_texture_pixels=50_000)), (1,))
    only(r, "texture_too_large")
    o = fx.write_obj(tmp_path / "s.obj", V, F)
    only(one_clean_result(check_mesh(o, limits=Limits(max_vertices=50)), (2,)), "over_check_limit")
    r = check_mesh(p, limits=Limits(max_pair_tests=10, max_ray_tests=10))
    assert r.exit_code == 0 and "check_partial" in r.codes  # partial work, reported, still a result
    assert r.stats["self_intersection_check"] == "partial"


def test_triangle_soup_gives_a_bounded_partial_answer(tmp_path: Path) -> None:
    """20,000 random triangles in one small cube: the pair search samples, reports partial, finds crossings."""
    rng = np.random.default_rng(11)
    V = rng.random((60_000, 3)) * 10
    F = np.arange(60_000).reshape(-1, 3)
    r = one_clean_result(check_mesh(fx.write_stl(tmp_path / "soup.stl", V, F)), (1,))
    assert r.stats["self_intersection_check"] == "partial" and "check_partial" in r.codes
    assert r.stats["self_intersecting_pairs"] > 0 and "self_intersections" in r.codes


def test_gzip_bomb_vrml(tmp_path: Path) -> None:
    p = tmp_path / "bomb.wrz"
    with gzip.open(p, "wb", compresslevel=9) as fh:
        fh.write(b"#VRML V2.0 utf8\n")
        for _ in range(32):
            fh.write(b" " * (1 << 20))
    only(one_clean_result(check_mesh(p, limits=Limits(max_uncompressed_bytes=4 << 20)), (2,)), "archive_too_large")


def test_gltf_node_cycle_and_bad_types(tmp_path: Path) -> None:
    g = fx.write_glb(tmp_path / "c.glb", *fx.box())
    data = g.read_bytes()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + jlen])
    rest = data[20 + jlen :]

    def save(d: dict, name: str) -> Path:
        js = json.dumps(d).encode()
        js += b" " * (-len(js) % 4)
        q = tmp_path / name
        q.write_bytes(struct.pack("<4sII", b"glTF", 2, 20 + len(js) + len(rest)) + struct.pack("<I4s", len(js), b"JSON")
                      + js + rest)
        return q

    draco = json.loads(json.dumps(doc))
    draco["extensionsRequired"] = ["EXT_example_unknown_compression"]  # Draco itself is read now (issue 15)
    only(one_clean_result(check_mesh(save(draco, "draco.glb")), (2,)), "unsupported_format")
    cyc = json.loads(json.dumps(doc))
    cyc["nodes"] = [{"mesh": 0, "children": [1]}, {"children": [0]}]
    one_clean_result(check_mesh(save(cyc, "cyc.glb")), (2,))
    bad = json.loads(json.dumps(doc))
    bad["accessors"][0]["bufferView"] = "zero"
    one_clean_result(check_mesh(save(bad, "bad.glb")), (2,))
    off = json.loads(json.dumps(doc))
    off["accessors"][1]["byteOffset"] = 10**12
    one_clean_result(check_mesh(save(off, "off.glb")), (2,))
    js = json.dumps(doc)
    js = js[:-1] + ', "extras": ' + "[" * 100_000 + "]" * 100_000 + "}"  # too deep for any recursive parser
    js_b = js.encode() + b" " * (-len(js) % 4)
    q = tmp_path / "deep.glb"
    q.write_bytes(struct.pack("<4sII", b"glTF", 2, 20 + len(js_b) + len(rest)) + struct.pack("<I4s", len(js_b), b"JSON")
                  + js_b + rest)
    only(one_clean_result(check_mesh(q), (2,)), "malformed")


def test_vrml_use_bomb_and_deep_nesting(tmp_path: Path) -> None:
    V, F = fx.box()
    base = fx.write_vrml(tmp_path / "b.wrl", V, F).read_text()
    shape = base.split("\n", 2)[2]
    text = "#VRML V2.0 utf8\nDEF G0 Group { children [ " + shape + " ] }\n"
    for i in range(1, 8):
        text += f"DEF G{i} Group {{ children [ " + " ".join(f"USE G{i - 1}" for _ in range(20)) + " ] }\n"
    (tmp_path / "use.wrl").write_text(text)
    only(one_clean_result(check_mesh(tmp_path / "use.wrl"), (2,)), "over_check_limit")
    (tmp_path / "deep.wrl").write_text("#VRML V2.0 utf8\n" + "Group { children [ " * 3000 + "] } " * 3000)
    one_clean_result(check_mesh(tmp_path / "deep.wrl"), (2,))
    (tmp_path / "v1.wrl").write_text("#VRML V1.0 ascii\nSeparator { }\n")
    only(one_clean_result(check_mesh(tmp_path / "v1.wrl"), (2,)), "unsupported_format")


# -- fuzzing ------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _corpus() -> dict[str, bytes]:
    """Good files of every format to mutate (a function, not a fixture: hypothesis prints fixtures)."""
    tmp = Path(tempfile.mkdtemp(prefix="saucerfab-fuzz-"))
    files = {k: p.read_bytes() for k, p in _good_files(tmp).items()}
    V, F, uv = fx.saucer_solid(6)
    files["xml"] = fx.model_xml(V, F, uv=uv).encode()  # fuzzed inside a freshly zipped 3MF
    shutil.rmtree(tmp, ignore_errors=True)
    return files


_EXT = {"3mf": ".3mf", "obj": ".obj", "stl": ".stl", "stla": ".stl", "ply": ".ply", "plya": ".ply", "glb": ".glb",
        "wrl": ".wrl", "xml": ".3mf"}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    kind=st.sampled_from(sorted(_EXT)),
    edits=st.lists(st.tuples(st.sampled_from(["flip", "cut", "insert", "delete", "dup"]),
                             st.floats(0, 1, allow_nan=False), st.binary(min_size=1, max_size=8)),
                   min_size=1, max_size=4),
)
def test_fuzzed_files_give_a_clean_result(tmp_path_factory: pytest.TempPathFactory, kind: str,
                                          edits: list[tuple[str, float, bytes]]) -> None:
    data = bytearray(_corpus()[kind])
    for op, where, blob in edits:
        i = int(where * max(len(data) - 1, 0))
        if op == "flip" and data:
            data[i] ^= blob[0] or 0x55
        elif op == "cut":
            del data[i:]
        elif op == "insert":
            data[i:i] = blob
        elif op == "delete":
            del data[i : i + len(blob)]
        elif op == "dup":
            data[i:i] = data[i : i + 64]
    tmp = tmp_path_factory.mktemp("case")
    p = tmp / f"f{_EXT[kind]}"
    if kind == "xml":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr("[Content_Types].xml", fx.CONTENT_TYPES)
            z.writestr("_rels/.rels", fx.RELS)
            z.writestr("3D/3dmodel.model", bytes(data))
        p.write_bytes(buf.getvalue())
    else:
        p.write_bytes(bytes(data))
    (tmp / "t.png").write_bytes(fx.png_bytes(8, 8))
    r = check_mesh(p, printer="j55")
    one_clean_result(r, (0, 1, 2))
