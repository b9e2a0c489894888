"""Tests of the exporters one by one on a tiny textured tetrahedron, and of the registry."""

from __future__ import annotations

import io
import json
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from defusedxml import ElementTree

from saucerfab.errors import ExportError
from saucerfab.fabricate import registry
from saucerfab.fabricate.bake import png_bytes
from saucerfab.fabricate.export_3mf import NS_CORE, NS_MATERIAL, write_3mf
from saucerfab.fabricate.export_glb import split_vertices, write_glb
from saucerfab.fabricate.export_obj import write_obj
from saucerfab.fabricate.export_ply import write_ply
from saucerfab.fabricate.export_stl import write_stl
from saucerfab.fabricate.export_vrml import write_vrml
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, deterministic_zip


@pytest.fixture()
def tet() -> TexturedMesh:
    """A tetrahedron, outward faces, one UV seam (vertex 0 has two uvs)."""
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    uvs = np.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9], [0.5, 0.5], [0.2, 0.2]])
    fuv = np.array([[0, 2, 1], [0, 1, 3], [4, 3, 2], [1, 2, 3]], np.int64)
    img = np.zeros((8, 8, 3), np.uint8)
    img[:4, :, 0] = 255
    return TexturedMesh(
        name="tet", vertices=v, faces=f, uvs=uvs, face_uvs=fuv, texture_png=png_bytes(img), texture_px=8,
        vertex_rgb=np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]], np.uint8),
    )


def test_3mf_package_and_model(tet: TexturedMesh) -> None:
    files = write_3mf(tet)
    assert list(files) == ["tet.3mf"]
    zf = zipfile.ZipFile(io.BytesIO(files["tet.3mf"]))
    names = zf.namelist()
    assert names[0] == "[Content_Types].xml"
    assert set(names) == {"[Content_Types].xml", "_rels/.rels", "3D/3dmodel.model", "3D/_rels/3dmodel.model.rels", "3D/Textures/tet.png"}
    assert all(i.date_time == (1980, 1, 1, 0, 0, 0) for i in zf.infolist())
    assert zf.read("3D/Textures/tet.png") == tet.texture_png
    ct = ElementTree.fromstring(zf.read("[Content_Types].xml"))
    assert {d.get("Extension") for d in ct} == {"rels", "model", "png"}
    rels = ElementTree.fromstring(zf.read("3D/_rels/3dmodel.model.rels"))
    assert rels[0].get("Target") == "/3D/Textures/tet.png" and rels[0].get("Type").endswith("3dtexture")
    model = ElementTree.fromstring(zf.read("3D/3dmodel.model"))
    assert model.get("unit") == "millimeter" and model.get("requiredextensions") is None
    ns = {"c": NS_CORE, "m": NS_MATERIAL}
    tex = model.find("c:resources/m:texture2d", ns)
    assert tex.get("path") == "/3D/Textures/tet.png" and tex.get("contenttype") == "image/png"
    group = model.find("c:resources/m:texture2dgroup", ns)
    assert group.get("texid") == tex.get("id")
    coords = np.array([[float(c.get("u")), float(c.get("v"))] for c in group])
    np.testing.assert_allclose(coords, tet.uvs, atol=1e-7)
    obj = model.find("c:resources/c:object", ns)
    assert obj.get("pid") == group.get("id") and obj.get("type") == "model"
    verts = np.array([[float(v.get(k)) for k in "xyz"] for v in obj.find("c:mesh/c:vertices", ns)])
    np.testing.assert_allclose(verts, tet.vertices)
    tris = list(obj.find("c:mesh/c:triangles", ns))
    assert all(t.get("pid") == group.get("id") for t in tris)
    np.testing.assert_array_equal([[int(t.get(f"v{k}")) for k in (1, 2, 3)] for t in tris], tet.faces)
    np.testing.assert_array_equal([[int(t.get(f"p{k}")) for k in (1, 2, 3)] for t in tris], tet.face_uvs)
    assert model.find("c:build/c:item", ns).get("objectid") == obj.get("id")


def test_obj_mtl_png_and_zip(tet: TexturedMesh) -> None:
    files = write_obj(tet)
    assert set(files) == {"tet.obj", "tet.mtl", "tet.png"}
    text = files["tet.obj"].decode()
    assert text.count("\nv ") == 4 and text.count("\nvt ") == 5 and text.count("\nf ") == 4
    assert "f 1/1 3/3 2/2\n" in text and "f 1/5 4/4 3/3\n" in text  # 1-based, separate vt
    assert "map_Kd tet.png" in files["tet.mtl"].decode()
    zipped = write_obj(tet, FabOptions(obj_zip=True))
    assert list(zipped) == ["tet.zip"]
    zf = zipfile.ZipFile(io.BytesIO(zipped["tet.zip"]))
    assert {n: zf.read(n) for n in zf.namelist()} == files
    assert zf.getinfo("tet.png").compress_type == zipfile.ZIP_STORED


def test_glb_layout_and_split_vertices(tet: TexturedMesh) -> None:
    pos, uv, idx = split_vertices(tet)
    assert pos.shape[0] == 5  # vertex 0 is split at the seam
    np.testing.assert_array_equal(pos[idx], tet.vertices[tet.faces])
    np.testing.assert_array_equal(uv[idx], tet.uvs[tet.face_uvs])
    data = write_glb(tet)["tet.glb"]
    magic, version, length = struct.unpack("<4sII", data[:12])
    assert (magic, version, length) == (b"glTF", 2, len(data))
    jlen, jtype = struct.unpack("<I4s", data[12:20])
    assert jtype == b"JSON" and jlen % 4 == 0
    doc = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack("<I4s", data[20 + jlen : 28 + jlen])
    assert btype == b"BIN\x00" and blen % 4 == 0 and 28 + jlen + blen == len(data)
    assert doc["buffers"][0]["byteLength"] == blen
    assert all(v["byteOffset"] % 4 == 0 for v in doc["bufferViews"])
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0.0 and "baseColorTexture" in pbr
    acc = doc["accessors"][1]
    binary = data[28 + jlen :]
    view = doc["bufferViews"][acc["bufferView"]]
    p = np.frombuffer(binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]], "<f4").reshape(-1, 3)
    np.testing.assert_allclose(p, pos / 1000, rtol=1e-6)
    assert acc["min"] == [float(x) for x in p.min(axis=0)] and acc["max"] == [float(x) for x in p.max(axis=0)]
    tview = doc["bufferViews"][doc["accessors"][2]["bufferView"]]
    t = np.frombuffer(binary[tview["byteOffset"] : tview["byteOffset"] + tview["byteLength"]], "<f4").reshape(-1, 2)
    np.testing.assert_allclose(t[:, 1], 1 - uv[:, 1], atol=1e-7)  # glTF's v runs down the image
    img = doc["bufferViews"][doc["images"][0]["bufferView"]]
    assert binary[img["byteOffset"] : img["byteOffset"] + img["byteLength"]] == tet.texture_png


def test_ply_binary_round_trip(tet: TexturedMesh) -> None:
    data = write_ply(tet)["tet.ply"]
    head, body = data.split(b"end_header\n", 1)
    assert b"format binary_little_endian 1.0" in head and b"element vertex 4" in head
    vert = np.frombuffer(body[: 4 * 15], dtype=[("p", "<f4", 3), ("c", "u1", 3)])
    np.testing.assert_allclose(vert["p"], tet.vertices)
    np.testing.assert_array_equal(vert["c"], tet.vertex_rgb)
    face = np.frombuffer(body[4 * 15 :], dtype=[("n", "u1"), ("i", "<i4", 3)])
    assert (face["n"] == 3).all()
    np.testing.assert_array_equal(face["i"], tet.faces)


def test_stl_binary(tet: TexturedMesh) -> None:
    data = write_stl(tet)["tet.stl"]
    assert not data.startswith(b"solid") and len(data) == 84 + 50 * 4
    assert struct.unpack("<I", data[80:84])[0] == 4
    rec = np.frombuffer(data[84:], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    np.testing.assert_allclose(np.linalg.norm(rec["n"], axis=1), 1, atol=1e-6)
    np.testing.assert_allclose(rec["n"][3], np.ones(3) / np.sqrt(3), atol=1e-6)  # the slanted face, outward


def test_vrml(tet: TexturedMesh) -> None:
    files = write_vrml(tet)
    assert files["tet.png"] == tet.texture_png
    text = files["tet.wrl"].decode()
    assert text.startswith("#VRML V2.0 utf8\n")
    ci = text.split("coordIndex [")[1].split("]")[0]
    ti = text.split("texCoordIndex [")[1].split("]")[0]
    assert ci.count("-1") == 4 and ti.count("-1") == 4
    assert "0 2 1 -1" in ci and "4 3 2 -1" in ti


def test_deterministic_zip_is_byte_stable() -> None:
    entries = [("a.txt", b"hello" * 100, True), ("b.png", b"\x89PNG....", False)]
    assert deterministic_zip(entries) == deterministic_zip(entries)
    zf = zipfile.ZipFile(io.BytesIO(deterministic_zip(entries)))
    assert [i.filename for i in zf.infolist()] == ["a.txt", "b.png"]
    assert (zf.getinfo("a.txt").external_attr >> 16) == 0o100644


def test_normalize_formats() -> None:
    acc = ("3mf", "obj", "wrl")
    assert registry.normalize_formats(["3MF", ".obj", "vrml", "3mf"], acc, "P") == (["3mf", "obj", "wrl"], [])
    with pytest.raises(ExportError, match="unknown export format 'fbx'"):
        registry.normalize_formats(["fbx"], acc, "P")
    # a known format the printer does not take is refused, or set apart on request (one rule)
    with pytest.raises(ExportError, match=r"P does not take GLB \(its profile lists 3mf, obj, wrl\).*--allow-format"):
        registry.normalize_formats(["glb", "3mf", ".GLB"], acc, "P")
    assert registry.normalize_formats(["glb", "3mf", ".GLB"], acc, "P", allow_other=True) == (["3mf"], ["glb"])
    with pytest.raises(ExportError, match="no export format"):
        registry.normalize_formats([], acc, "P")


def test_merge_files_refuses_conflicting_names() -> None:
    same = registry.merge_files({"obj": {"a.png": b"1"}, "wrl": {"a.png": b"1"}}, {"scene.json": b"{}"})
    assert same == {"a.png": b"1", "scene.json": b"{}"}
    with pytest.raises(ExportError, match="different 'a.png'"):
        registry.merge_files({"obj": {"a.png": b"1"}, "wrl": {"a.png": b"2"}}, {})


def test_write_folder(tmp_path: Path) -> None:
    out = registry.write_folder(tmp_path / "o", {"x.txt": b"1", "export.json": b"{}"})
    assert sorted(p.name for p in out.iterdir()) == ["export.json", "x.txt"]
    assert out.stat().st_mode & 0o055  # not owner-only like a bare mkdtemp
    (tmp_path / "file").write_text("x")
    with pytest.raises(ExportError, match="not a folder"):
        registry.write_folder(tmp_path / "file", {"x.txt": b"1"})
    with pytest.raises(ExportError, match="bad output file name"):
        registry.write_folder(tmp_path / "p", {"../x": b"1"})
    assert not (tmp_path / "p").exists()


def test_every_writer_is_registered(tet: TexturedMesh) -> None:
    from saucerfab.files.formats import FORMATS

    assert set(registry.WRITERS) == set(FORMATS)
    for fmt in FORMATS:
        files = registry.render(tet, fmt, FabOptions())
        assert any(name.endswith(registry.WRITERS[fmt].mesh_suffix) for name in files)


@pytest.mark.parametrize(
    "cup, keys",
    [
        ("circle", {"radius"}),
        ("ellipse", {"semi_axes", "rotation_deg"}),
        ("prism", {"sides", "circumradius", "rotation_deg"}),
    ],
)
def test_scene_json_cup_fields_per_shape(cup: str, keys: set[str]) -> None:
    from saucerfab.fabricate.scene_json import scene_dict
    from saucerfab.fabricate.solid import build_solid
    from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup
    from saucerfab.model.design_folder import synthetic_design
    from saucerfab.model.scene import Scene

    shapes = {"circle": CircleCup(), "ellipse": EllipseCup((0.45, 0.35), 20.0), "prism": PrismCup(6, 0.45, 10.0)}
    scene = Scene(cup=shapes[cup], cup_diameter_mm=90.0)
    d = synthetic_design(scene, resolution=8, texture_size=16)
    solid = build_solid(d, scene.mm_per_unit, FabOptions(seat="none"))
    sj = scene_dict(scene, solid)
    assert list(sj)[:6] == ["schema", "units", "camera", "views", "cup", "model_to_file"]
    assert set(sj["cup"]) == {"shape", "center", "bottom_z", "height"} | keys
    assert sj["cup"]["shape"] == cup
    s = scene.mm_per_unit
    if cup == "ellipse":
        assert sj["cup"]["semi_axes"] == pytest.approx([0.45 * s, 0.35 * s]) and sj["cup"]["rotation_deg"] == 20.0
    if cup == "prism":
        assert sj["cup"]["sides"] == 6 and sj["cup"]["circumradius"] == pytest.approx(0.45 * s)
    m = np.array(sj["model_to_file"])
    assert np.allclose(m[:3, :3], np.eye(3) * s)
    # the camera and targets are the model's points through the map
    assert np.allclose(sj["camera"]["position"], (m @ [*scene.camera, 1])[:3], atol=1e-5)
    assert np.allclose(sj["views"]["reflected"]["target"], (m @ [*scene.reflected.target, 1])[:3], atol=1e-5)
