"""End-to-end tests of ``saucerfab.fabricate.pipeline.export_design`` and ``saucerfab export``.

One small synthetic design (24 x 24 grid, 64 px checkerboard texture, a block
of faces no viewer sees) is exported once per test module in every format
with a 256 px atlas and a 30 mm cup; the tests then read the files back with
independent readers and outside tools:

* lib3mf in strict mode (zero warnings, a texture present),
* the Khronos glTF-Validator (zero errors),
* PrusaSlicer's CLI (loads 3MF and OBJ, reports them manifold, slices to G-code),
* trimesh (and pymeshlab for VRML): watertight, positive volume, same bounds,
* the texture: the colour under a triangle's centroid, read through each
  file's own UVs and PNG, equals the colour of the design's checkerboard there,
  computed from the design alone (point location in model space).

Outside tools are installed by ``.ci/install-tools``; a missing one fails
these tests (it must not be skipped in CI).
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from saucerfab.cli import main
from saucerfab.errors import ConfigError, DesignError, ExportError, MeshError
from saucerfab.fabricate.options import NEUTRAL_WALL_RGB, FabOptions
from saucerfab.fabricate.pipeline import ExportResult, export_design
from saucerfab.files.formats import FORMATS
from saucerfab.model.design import Design, FaceView
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.model.profiles import PrinterProfile, load_profile

ROOT = Path(__file__).resolve().parents[2]
GLTF_VALIDATOR = ROOT / "tools" / "node" / "node_modules" / "gltf-validator"
CUP_MM = 30.0
TEX = 64  # design texture edge; checker cells are TEX / 8 px
ATLAS = 256
NEITHER_BLOCK = (slice(8, 13), slice(10, 16))  # grid cells (rows, cols) no viewer sees

#: accepts every format, warns on thin features: the profile the tests export for
ALL_FORMATS = PrinterProfile(
    key="test",
    name="test printer",
    build_volume_mm=(300.0, 300.0, 200.0),
    min_wall_mm=1.0,
    min_feature_mm=0.3,
    dpi=300,
    max_texture_px=8192,
    accepted_formats=FORMATS,
    preferred_format="3mf",
)


def make_design() -> Design:
    """The synthetic design with a block of NEITHER faces."""
    d = synthetic_design(resolution=24, texture_size=TEX, seed=1)
    view = d.face_view.copy().reshape(23, 23, 2)
    view[NEITHER_BLOCK] = FaceView.NEITHER
    return replace(d, face_view=view.reshape(-1))


@pytest.fixture(scope="module")
def design() -> Design:
    return make_design()


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory, design: Design) -> ExportResult:
    out = tmp_path_factory.mktemp("export") / "out"
    steps: list[tuple[str, float]] = []
    res = export_design(
        design,
        out,
        printer=ALL_FORMATS,
        cup_diameter_mm=CUP_MM,
        formats=list(FORMATS),
        options=FabOptions(texture_px=ATLAS),
        progress=lambda s, f: steps.append((s, f)),
    )
    fracs = [f for _, f in steps]
    assert fracs == sorted(fracs) and abs(fracs[-1] - 1.0) < 1e-9
    return res


@pytest.fixture(scope="module")
def scene_json(exported: ExportResult) -> dict:
    return json.loads(exported.scene_json.read_text())


# --------------------------------------------------------------------------- helpers


def model_to_file(sj: dict) -> np.ndarray:
    return np.array(sj["model_to_file"], dtype=np.float64)


def expected_colours(design: Design, sj: dict, pts_file: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The design's colour at file-frame points on the top, from the design alone.

    Returns (K, 3) colours and a (K,) mask of points that are trustworthy:
    inside a face the viewer sees and at least 1.5 texels from a checker edge
    (where bilinear filtering blends two cells).
    """
    m = model_to_file(sj)
    xy = (pts_file[:, :2] - m[:2, 3]) / m[0, 0]  # model units
    v = design.vertices()[:, :2]
    tri = v[design.faces()]  # (F, 3, 2)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    d = xy[:, None, :] - a[None]
    l1 = (d[..., 0] * e2[None, :, 1] - d[..., 1] * e2[None, :, 0]) / det
    l2 = (e1[None, :, 0] * d[..., 1] - e1[None, :, 1] * d[..., 0]) / det
    inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
    assert inside.any(axis=1).all(), "a sample point lies off the saucer"
    f = inside.argmax(axis=1)
    k = np.arange(xy.shape[0])
    bary = np.stack([1 - l1[k, f] - l2[k, f], l1[k, f], l2[k, f]], axis=1)
    uv = np.einsum("ki,kij->kj", bary, design.face_uvs[f].astype(np.float64))
    px, py = uv[:, 0] * TEX, (1 - uv[:, 1]) * TEX
    cell = TEX / 8
    fx, fy = np.mod(px, cell), np.mod(py, cell)
    ok = (fx > 1.5) & (fx < cell - 1.5) & (fy > 1.5) & (fy < cell - 1.5)
    ok &= design.face_view[f] != FaceView.NEITHER
    col = design.texture[np.clip(py.astype(int), 0, TEX - 1), np.clip(px.astype(int), 0, TEX - 1)]
    return col.astype(np.int64), ok


def top_faces(vertices: np.ndarray, faces: np.ndarray, sj: dict) -> np.ndarray:
    """Faces of the saucer's top: centroid strictly inside the footprint, facing up."""
    (x0, x1), (y0, y1) = sj["saucer"]["x_range"], sj["saucer"]["y_range"]
    tri = vertices[faces]
    cen = tri.mean(axis=1)
    nz = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    inside = (cen[:, 0] > x0 + 1e-3) & (cen[:, 0] < x1 - 1e-3) & (cen[:, 1] > y0 + 1e-3) & (cen[:, 1] < y1 - 1e-3)
    return np.flatnonzero(inside & (nz > 0))


def sample_nearest(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Texel under uv (u right, v up) by nearest lookup, (K, 3) int64."""
    h, w = image.shape[:2]
    c = np.clip((uv[:, 0] * w).astype(int), 0, w - 1)
    r = np.clip(((1 - uv[:, 1]) * h).astype(int), 0, h - 1)
    return image[r, c, :3].astype(np.int64)


def assert_texels_match(
    design: Design, sj: dict, vertices: np.ndarray, faces: np.ndarray, corner_uv: np.ndarray, image: np.ndarray
) -> None:
    """The file's texture under each top triangle's centroid equals the design's colour there.

    ``corner_uv`` is (F, 3, 2) in saucerfab's convention (v up).
    """
    top = top_faces(vertices, faces, sj)
    assert top.size > 500
    cen = vertices[faces[top]].mean(axis=1)
    want, ok = expected_colours(design, sj, cen)
    assert ok.sum() > 100
    got = sample_nearest(image, corner_uv[top].mean(axis=1))
    bad = np.abs(got - want).max(axis=1) > 2
    assert not (bad & ok).any(), f"{int((bad & ok).sum())} of {int(ok.sum())} texels differ from the design"


def volume_of(vertices: np.ndarray, faces: np.ndarray) -> float:
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def trimesh_watertight(vertices: np.ndarray, faces: np.ndarray) -> "object":
    """A trimesh of the positions merged exactly (UV seams split vertices in some formats)."""
    import trimesh

    m = trimesh.Trimesh(vertices, faces, process=False)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    return m


# --------------------------------------------------------------------------- the folder


def test_every_format_and_the_summaries_are_written(exported: ExportResult) -> None:
    out = exported.out
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["saucer.3mf", "saucer.obj", "saucer.mtl", "saucer.png", "saucer.glb", "saucer.ply", "saucer.wrl",
         "saucer.stl", "scene.json", "export.json"]
    )
    assert set(exported.files) == set(FORMATS)
    for paths in exported.files.values():
        assert all(p.is_file() and p.stat().st_size > 0 for p in paths)
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")], "temporary folders left behind"
    summary = json.loads(exported.summary_json.read_text())
    assert summary["triangles"] == exported.triangles > 1000
    assert summary["texture_px"] == exported.texture_px == ATLAS
    assert summary["files"]["saucer.3mf"]["bytes"] == (out / "saucer.3mf").stat().st_size
    assert "timings" not in summary  # timings vary; files must not
    assert exported.volume_mm3 > 0
    d = exported.to_dict()
    json.dumps(d)
    assert d["bbox_mm"] == list(exported.bbox_mm)
    # 30 mm cup: 0.4 units -> 15 mm radius, 37.5 mm per unit; the saucer is 1 x 1 units;
    # the seat (radius 15 + 0.5 clearance + 4 rim) is wider than the saucer
    assert exported.mm_per_unit == pytest.approx(CUP_MM / 0.8)
    sj = json.loads(exported.scene_json.read_text())
    assert np.diff(sj["saucer"]["x_range"])[0] == pytest.approx(37.5, abs=1e-6)
    assert exported.bbox_mm[0] == pytest.approx(2 * (15 + 0.5 + 4), abs=0.01)


def test_scene_json_has_the_schema_and_matches_the_files(exported: ExportResult, scene_json: dict, design: Design) -> None:
    sj = scene_json
    assert sj["schema"] == "saucerfab.scene/1" and sj["units"] == "mm"
    assert sj["camera"]["up"] == [0.0, 0.0, 1.0]
    for view in ("direct", "reflected"):
        v = sj["views"][view]
        assert set(v) == {"target", "viewing_angle_deg", "width", "height", "extent"}
        assert v["viewing_angle_deg"] == getattr(design.scene, view).viewing_angle_deg
    cup = sj["cup"]
    assert cup["shape"] == "circle" and set(cup) == {"shape", "center", "bottom_z", "height", "radius"}
    assert cup["radius"] == pytest.approx(CUP_MM / 2)
    m = model_to_file(sj)
    assert m.shape == (4, 4) and np.allclose(m[3], [0, 0, 0, 1])
    s = CUP_MM / 0.8
    assert np.allclose(np.diag(m)[:3], s)
    # the model's points land where the files put them
    cam = m @ np.array([*design.scene.camera, 1.0])
    assert np.allclose(sj["camera"]["position"], cam[:3], atol=1e-5)
    assert np.allclose(cup["center"], m[:2, 3], atol=1e-6) and cup["bottom_z"] == pytest.approx(m[2, 3], abs=1e-6)
    import trimesh

    stl = trimesh.load(exported.out / "saucer.stl")
    top = design.vertices() * s + m[:3, 3]  # the saucer's grid in file coordinates
    verts = {tuple(np.round(p, 3)) for p in stl.vertices}
    assert all(tuple(np.round(p, 3)) in verts for p in top[:: 37])
    assert stl.bounds[0].tolist() == [0.0, 0.0, 0.0]  # positive octant, from 0


def test_3mf_strict_lib3mf_zero_warnings_with_texture(exported: ExportResult, scene_json: dict, design: Design) -> None:
    import lib3mf

    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromFile(str(exported.out / "saucer.3mf"))
    assert reader.GetWarningCount() == 0, [reader.GetWarning(i) for i in range(reader.GetWarningCount())]
    assert model.GetUnit() == lib3mf.ModelUnit.MilliMeter
    textures = model.GetTexture2Ds()
    assert textures.MoveNext(), "no texture2d in the 3MF"
    tex = textures.GetCurrentTexture2D()
    att = tex.GetAttachment()
    png = bytes(att.WriteToBuffer()) if hasattr(att, "WriteToBuffer") else None
    if png is None:  # older bindings
        png = zipfile.ZipFile(exported.out / "saucer.3mf").read(att.GetPath().lstrip("/"))
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert image.shape == (ATLAS, ATLAS, 3)
    objs = model.GetMeshObjects()
    assert objs.MoveNext()
    obj = objs.GetCurrentMeshObject()
    assert obj.IsManifoldAndOriented()
    nv, nt = obj.GetVertexCount(), obj.GetTriangleCount()
    assert nt == exported.triangles
    verts = np.array([[p.Coordinates[k] for k in range(3)] for p in obj.GetVertices()], np.float64)
    tris = np.array([[t.Indices[k] for k in range(3)] for t in obj.GetTriangleIndices()], np.int64)
    assert verts.shape == (nv, 3) and verts.min() >= 0.0  # positive octant
    res_id, _prop, has_prop = obj.GetObjectLevelProperty()
    assert has_prop
    group = model.GetTexture2DGroupByID(res_id)
    uv = np.zeros((nt, 3, 2))
    for i in range(nt):
        props = obj.GetTriangleProperties(i)
        assert props.ResourceID == group.GetResourceID()
        for k in range(3):
            c = group.GetTex2Coord(props.PropertyIDs[k])
            uv[i, k] = (c.U, c.V)
    m = trimesh_watertight(verts, tris)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert np.allclose(m.bounds[1], exported.bbox_mm, atol=1e-4)
    assert volume_of(verts, tris) == pytest.approx(exported.volume_mm3, rel=1e-6)  # lib3mf keeps float32
    assert_texels_match(design, scene_json, verts, tris, uv, image)


def test_obj_round_trip(exported: ExportResult, scene_json: dict, design: Design) -> None:
    out = exported.out
    text = (out / "saucer.obj").read_text()
    assert "mtllib saucer.mtl" in text and "usemtl saucer" in text
    mtl = (out / "saucer.mtl").read_text()
    assert "Kd 1 1 1" in mtl and "map_Kd saucer.png" in mtl
    v = np.array([list(map(float, ln.split()[1:])) for ln in text.splitlines() if ln.startswith("v ")])
    vt = np.array([list(map(float, ln.split()[1:])) for ln in text.splitlines() if ln.startswith("vt ")])
    f = [[tuple(int(x) - 1 for x in c.split("/")) for c in ln.split()[1:]] for ln in text.splitlines() if ln.startswith("f ")]
    fa = np.array(f)  # (F, 3, 2): (position, uv) per corner
    faces, fuv = fa[..., 0], fa[..., 1]
    # watertight as written: unique positions, every edge used exactly twice, in opposite directions
    assert np.unique(v, axis=0).shape[0] == v.shape[0]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    assert np.unique(edges, axis=0).shape[0] == edges.shape[0]
    rev = {tuple(e) for e in edges[:, ::-1].tolist()}
    assert all(tuple(e) in rev for e in edges.tolist())
    import trimesh

    loaded = trimesh.load(out / "saucer.obj")
    assert isinstance(loaded.visual, trimesh.visual.TextureVisuals)
    assert loaded.visual.material.image is not None
    m = trimesh_watertight(loaded.vertices, loaded.faces)
    assert m.is_watertight and m.volume == pytest.approx(exported.volume_mm3, rel=1e-6)
    assert np.allclose(m.bounds[1], exported.bbox_mm, atol=1e-4)
    image = np.asarray(Image.open(out / "saucer.png").convert("RGB"))
    assert_texels_match(design, scene_json, v, faces, vt[fuv], image)


def test_glb_passes_the_khronos_validator_and_round_trips(exported: ExportResult, scene_json: dict, design: Design) -> None:
    assert (GLTF_VALIDATOR / "package.json").is_file(), "gltf-validator missing: run bash .ci/install-tools"
    script = (
        "const fs=require('fs');const v=require(process.argv[1]);"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])),{maxIssues:100})"
        ".then(r=>console.log(JSON.stringify(r.issues)),e=>{console.error(String(e));process.exit(3);});"
    )
    proc = subprocess.run(
        ["node", "-e", script, str(GLTF_VALIDATOR), str(exported.out / "saucer.glb")],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    issues = json.loads(proc.stdout)
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0, issues["messages"]

    import trimesh

    scene = trimesh.load(exported.out / "saucer.glb")
    geom = next(iter(scene.geometry.values()))
    # the mesh data are the file frame in metres; the node turns z-up into glTF's y-up
    mm = np.asarray(geom.vertices, np.float64) * 1000.0
    m = trimesh_watertight(mm, geom.faces)
    assert m.is_watertight and m.volume == pytest.approx(exported.volume_mm3, rel=1e-5)
    assert np.allclose(m.bounds[1], exported.bbox_mm, atol=1e-3)
    world = scene.to_geometry()
    ext = world.bounds[1] - world.bounds[0]
    assert np.allclose(ext * 1000, [exported.bbox_mm[0], exported.bbox_mm[2], exported.bbox_mm[1]], atol=1e-3)
    mat = geom.visual.material
    assert mat.metallicFactor == 0.0
    image = np.asarray(mat.baseColorTexture.convert("RGB"))
    uv = np.asarray(geom.visual.uv, np.float64)  # trimesh gives v up, like saucerfab
    assert_texels_match(design, scene_json, mm, geom.faces, uv[geom.faces], image)


def test_ply_vertex_colours_and_geometry(exported: ExportResult, scene_json: dict, design: Design) -> None:
    import trimesh

    ply = trimesh.load(exported.out / "saucer.ply")
    assert ply.is_watertight and ply.volume == pytest.approx(exported.volume_mm3, rel=1e-5)
    assert np.allclose(ply.bounds[1], exported.bbox_mm, atol=1e-3)
    rgb = np.asarray(ply.visual.vertex_colors)[:, :3].astype(np.int64)
    (x0, x1), (y0, y1) = scene_json["saucer"]["x_range"], scene_json["saucer"]["y_range"]
    p = np.asarray(ply.vertices, np.float64)
    top = (p[:, 0] > x0 + 1e-3) & (p[:, 0] < x1 - 1e-3) & (p[:, 1] > y0 + 1e-3) & (p[:, 1] < y1 - 1e-3)
    top &= p[:, 2] > scene_json["seat"]["base_z"] + 0.5
    want, ok = expected_colours(design, scene_json, p[top])
    # a vertex averages a quarter cell around it: require a margin of that in the checker too
    assert ok.sum() > 50
    close = np.abs(rgb[top] - want).max(axis=1) <= 8
    assert close[ok].mean() > 0.9
    walls = p[:, 2] < scene_json["seat"]["base_z"] + 1e-6  # the bottom
    assert (rgb[walls] == np.array(NEUTRAL_WALL_RGB)).all()


def test_vrml_reads_back_with_meshlab(exported: ExportResult, scene_json: dict, design: Design) -> None:
    import pymeshlab

    text = (exported.out / "saucer.wrl").read_text()
    assert text.startswith("#VRML V2.0 utf8\n")
    assert 'url [ "saucer.png" ]' in text
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(exported.out / "saucer.wrl"))
    mesh = ms.current_mesh()
    assert mesh.has_wedge_tex_coord()
    topo = ms.get_topological_measures()
    assert topo["boundary_edges"] == 0 and topo["is_mesh_two_manifold"]
    assert topo["connected_components_number"] == 1
    v = mesh.vertex_matrix()
    f = mesh.face_matrix()
    assert f.shape[0] == exported.triangles
    assert volume_of(v, f) == pytest.approx(exported.volume_mm3, rel=1e-5)
    assert np.allclose(v.max(axis=0), exported.bbox_mm, atol=1e-3)
    uv = mesh.wedge_tex_coord_matrix().reshape(-1, 3, 2)
    image = np.asarray(Image.open(exported.out / "saucer.png").convert("RGB"))
    assert_texels_match(design, scene_json, v, f, uv, image)


def test_prusaslicer_loads_and_slices_3mf_and_obj(exported: ExportResult, tmp_path: Path) -> None:
    exe = shutil.which("prusa-slicer")
    assert exe, "prusa-slicer missing: run bash .ci/install-tools"
    env = {**os.environ, "HOME": str(tmp_path)}
    files = [exported.out / "saucer.3mf", exported.out / "saucer.obj"]
    info = subprocess.run(
        [exe, "--datadir", str(tmp_path / "cfg"), "--loglevel", "1", "--info", *map(str, files)],
        capture_output=True, text=True, timeout=120, env=env,
    )
    assert info.returncode == 0, info.stderr
    blocks = info.stdout.split("[saucer.")[1:]
    assert len(blocks) == 2, info.stdout
    for block in blocks:
        assert "manifold = yes" in block, block
        assert f"number_of_facets = {exported.triangles}" in block
        size_x = float(next(ln for ln in block.splitlines() if ln.startswith("size_x")).split("=")[1])
        assert size_x == pytest.approx(exported.bbox_mm[0], abs=1e-3)
    for src in files:
        gcode = tmp_path / f"{src.name}.gcode"
        sl = subprocess.run(
            [exe, "--datadir", str(tmp_path / "cfg"), "--loglevel", "1", "--export-gcode",
             "--layer-height", "0.3", "--output", str(gcode), str(src)],
            capture_output=True, text=True, timeout=300, env=env,
        )
        assert sl.returncode == 0, sl.stdout + sl.stderr
        assert "error" not in (sl.stdout + sl.stderr).lower().replace("[trace]", "")
        text = gcode.read_text(errors="replace")
        assert text.count(";LAYER_CHANGE") >= int(exported.bbox_mm[2] / 0.3) - 2  # every layer of the part


def test_cup_seat_is_where_the_cup_stands(exported: ExportResult, scene_json: dict) -> None:
    """Vertical probes: the recess floor is the cup's standing plane, the rim is seat_depth higher."""
    import trimesh

    mesh = trimesh.load(exported.out / "saucer.stl")
    opts = FabOptions()
    cx, cy = scene_json["cup"]["center"]
    r = scene_json["cup"]["radius"]
    floor = scene_json["cup"]["bottom_z"]

    def top_z(x: float, y: float) -> float:
        tri = mesh.triangles
        a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
        e1, e2, d = b - a, c - a, np.array([x, y]) - a
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        ok = np.abs(det) > 1e-12
        l1 = np.where(ok, (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / np.where(ok, det, 1), -1)
        l2 = np.where(ok, (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / np.where(ok, det, 1), -1)
        hit = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        z = (1 - l1 - l2) * tri[:, 0, 2] + l1 * tri[:, 1, 2] + l2 * tri[:, 2, 2]
        return float(z[hit].max())

    assert top_z(cx, cy) == pytest.approx(floor, abs=1e-4)  # the cup's bottom centre
    for ang in np.linspace(0, 2 * np.pi, 7)[:-1]:
        d = np.array([np.cos(ang), np.sin(ang)])
        if cy + d[1] * (r + opts.seat_clearance_mm + opts.seat_rim_mm) < scene_json["saucer"]["y_range"][1]:
            continue  # that side of the seat meets the saucer
        inside = (cx, cy) + d * (r + opts.seat_clearance_mm * 0.5)
        rim = (cx, cy) + d * (r + opts.seat_clearance_mm + opts.seat_rim_mm * 0.5)
        assert top_z(*inside) == pytest.approx(floor, abs=1e-4)
        assert top_z(*rim) == pytest.approx(floor + opts.seat_depth_mm, abs=1e-4)
    assert scene_json["seat"]["floor_z"] == pytest.approx(floor)


def test_unseen_faces_get_a_smooth_continuation_not_grey(exported: ExportResult, scene_json: dict, design: Design) -> None:
    """Texels of NEITHER faces: colours of the surroundings, smoothly, never the wall grey."""
    from saucerfab.fabricate.atlas import layout_page

    image = np.asarray(Image.open(exported.out / "saucer.png").convert("RGB")).astype(np.float64)
    m = model_to_file(scene_json)
    s = m[0, 0]
    grid_x = (np.linspace(-0.5, 0.5, 24)) * s + m[0, 3]
    grid_y = (np.linspace(-1.5, -0.5, 24)) * s + m[1, 3]
    lay = layout_page(ATLAS, FabOptions().padding_px, grid_x, grid_y, design.heights * s + m[2, 3])
    rs, cs = NEITHER_BLOCK
    # texel box strictly inside the unseen block of cells
    c0, c1 = int(np.ceil(lay.col_px[cs.start])) + 1, int(np.floor(lay.col_px[cs.stop])) - 1
    r0, r1 = int(np.ceil(lay.row_px[rs.stop])) + 1, int(np.floor(lay.row_px[rs.start])) - 1
    block = image[r0:r1, c0:c1]
    assert block.shape[0] > 8 and block.shape[1] > 8
    grey = np.array(NEUTRAL_WALL_RGB, np.float64)
    assert (np.abs(block - grey).max(axis=2) > 3).mean() > 0.9
    # harmonic: the discrete Laplacian vanishes up to 8-bit rounding, although the
    # checker under these faces has hard edges (Laplacians in the hundreds)
    lap = 4 * block[1:-1, 1:-1] - block[:-2, 1:-1] - block[2:, 1:-1] - block[1:-1, :-2] - block[1:-1, 2:]
    assert np.abs(lap).mean() < 1.6 and np.abs(lap).max() <= 8, (np.abs(lap).mean(), np.abs(lap).max())
    # bounded by the colours around it (maximum principle), with rounding slack
    ring = np.concatenate([image[r0 - 3, c0:c1], image[r1 + 2, c0:c1], image[r0:r1, c0 - 3], image[r0:r1, c1 + 2]])
    assert (block.min(axis=(0, 1)) >= ring.min(axis=0) - 2).all()
    assert (block.max(axis=(0, 1)) <= ring.max(axis=0) + 2).all()
    assert exported.unseen_fraction == pytest.approx(60 / (2 * 23 * 23), rel=0.1)


def test_same_input_gives_identical_bytes(exported: ExportResult, design: Design, tmp_path: Path) -> None:
    again = export_design(
        design, tmp_path / "again", printer=ALL_FORMATS, cup_diameter_mm=CUP_MM,
        formats=list(FORMATS), options=FabOptions(texture_px=ATLAS),
    )
    for p in exported.out.iterdir():
        assert (again.out / p.name).read_bytes() == p.read_bytes(), p.name


def test_obj_zip_has_fixed_dates(design: Design, tmp_path: Path) -> None:
    res = export_design(
        design, tmp_path / "z", printer="bureau", cup_diameter_mm=CUP_MM, formats=["obj"],
        options=FabOptions(texture_px=ATLAS, obj_zip=True),
    )
    assert [p.name for p in res.files["obj"]] == ["saucer.zip"]
    with zipfile.ZipFile(res.files["obj"][0]) as zf:
        assert sorted(zf.namelist()) == ["saucer.mtl", "saucer.obj", "saucer.png"]
        assert all(i.date_time == (1980, 1, 1, 0, 0, 0) for i in zf.infolist())
        assert zf.testzip() is None


def test_preferred_format_and_printer_texture_size(design: Design, tmp_path: Path) -> None:
    res = export_design(design, tmp_path / "p", printer="j55", cup_diameter_mm=CUP_MM)
    assert res.formats == ["3mf"] and list(res.files) == ["3mf"]
    want = load_profile("j55").texture_px_for(37.5 / (7 / 8))
    assert res.texture_px == want
    res = export_design(design, tmp_path / "q", printer="j55", cup_diameter_mm=CUP_MM, formats="stl, 3MF",
                        options=FabOptions(texture_px=ATLAS))
    assert res.formats == ["stl", "3mf"]


# --------------------------------------------------------------------------- bad input


def _no_leftovers(parent: Path) -> None:
    assert not any(parent.iterdir()), sorted(p.name for p in parent.iterdir())


@pytest.mark.parametrize(
    "kwargs, error, needle",
    [
        ({"formats": ["3mf", "fbx"]}, ExportError, "unknown export format 'fbx'"),
        ({"formats": ["3mf", "step"], "printer": "bureau"}, ExportError, "unknown export format 'step'"),
        ({"cup_diameter_mm": 0.0}, ConfigError, "positive"),
        ({"cup_diameter_mm": -5.0}, ConfigError, "positive"),
        ({"cup_diameter_mm": float("nan")}, ConfigError, "positive"),
        ({"cup_diameter_mm": 2000.0}, ExportError, "build volume"),
        ({"printer": "no-such-printer"}, ConfigError, "unknown printer"),
        ({"options": FabOptions(texture_px=16384)}, ExportError, "texture_px"),
    ],
)
def test_bad_input_fails_cleanly_and_writes_nothing(
    design: Design, tmp_path: Path, kwargs: dict, error: type, needle: str
) -> None:
    parent = tmp_path / "parent"
    parent.mkdir()
    args = {"printer": "j55", "cup_diameter_mm": CUP_MM, "formats": ["3mf"], **kwargs}
    with pytest.raises(error, match=needle.replace("(", r"\(")):
        export_design(design, parent / "out", **args)
    _no_leftovers(parent)


def test_missing_design_folder(tmp_path: Path) -> None:
    with pytest.raises(DesignError, match="not found"):
        export_design(tmp_path / "nope", tmp_path / "out")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DesignError, match="not a design folder"):
        export_design(tmp_path / "empty", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_failing_writer_leaves_no_folder(design: Design, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from saucerfab.fabricate import registry

    real = registry.write_folder

    def boom(out, files):  # type: ignore[no-untyped-def]
        def fail_midway(*a, **k):  # the folder's files are half written when this raises
            raise OSError("disk full")

        monkeypatch.setattr(Path, "write_bytes", fail_midway)
        return real(out, files)

    monkeypatch.setattr(registry, "write_folder", boom)
    parent = tmp_path / "parent"
    parent.mkdir()
    with pytest.raises(ExportError, match="disk full"):
        export_design(design, parent / "out", printer="j55", cup_diameter_mm=CUP_MM, options=FabOptions(texture_px=ATLAS))
    monkeypatch.undo()
    _no_leftovers(parent)


def test_refuses_to_replace_an_unrelated_folder(design: Design, tmp_path: Path) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(ExportError, match="not a saucerfab export"):
        export_design(design, out, printer="j55", cup_diameter_mm=CUP_MM, options=FabOptions(texture_px=ATLAS))
    assert (out / "notes.txt").read_text() == "keep me"
    # a previous export is replaced
    first = export_design(design, tmp_path / "e", printer="j55", cup_diameter_mm=CUP_MM, options=FabOptions(texture_px=ATLAS))
    second = export_design(design, first.out, printer="j55", cup_diameter_mm=CUP_MM, formats=["stl"], options=FabOptions(texture_px=ATLAS))
    assert sorted(p.name for p in second.out.iterdir()) == ["export.json", "saucer.stl", "scene.json"]


def test_thin_features_are_blunted_or_refused_per_profile(tmp_path: Path) -> None:
    # a 4 mm cup makes the synthetic bumps 0.17 mm wide: thinner than any printer makes
    d = synthetic_design(resolution=24, texture_size=TEX, seed=1)
    # no seat: at 4 mm the cup stands 0.5 mm from the saucer, all of it the seat's clearance, and the
    # seat's wall there is a problem of its own (fabricate.seat.seat_wall, issue 42)
    opts = FabOptions(texture_px=ATLAS, seat="none", base_thickness_mm=1.0, min_thickness_mm=1.0)
    warn = replace(ALL_FORMATS, min_wall_mm=0.5)
    res = export_design(d, tmp_path / "w", printer=warn, cup_diameter_mm=4.0, formats=["stl"], options=opts)
    # the export blunts them with the optimizer's rule (saucerfab.model.relief) and says so
    assert any("no crest is narrower than" in w and "design with --printer" in w for w in res.warnings)
    assert json.loads(res.summary_json.read_text())["warnings"] == res.warnings
    refuse = replace(warn, thin_policy="refuse")
    ok = export_design(d, tmp_path / "r", printer=refuse, cup_diameter_mm=4.0, formats=["stl"], options=opts)
    assert ok.warnings == res.warnings
    # with no room under the height bound to blunt them, a refuse profile refuses
    spiky = replace(d, base_heights=d.heights, scene=d.scene.with_changes(saucer=replace(d.scene.saucer, delta=1e-9)))
    with pytest.raises(MeshError, match="too thin.*no room"):
        export_design(spiky, tmp_path / "x", printer=refuse, cup_diameter_mm=4.0, formats=["stl"], options=opts)
    assert not (tmp_path / "x").exists()
    warned = export_design(spiky, tmp_path / "y", printer=warn, cup_diameter_mm=4.0, formats=["stl"], options=opts)
    assert any("thinner than the minimum feature" in w for w in warned.warnings)


# --------------------------------------------------------------------------- CLI


def test_cli_export_prints_summary_and_checks(design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = save_design(design, tmp_path / "design")
    out = tmp_path / "out"
    code = main(["export", str(folder), "--printer", "j55", "--cup-diameter-mm", str(CUP_MM),
                 "--formats", "3mf,obj", "--texture-px", str(ATLAS), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "triangles" in captured.out and "volume" in captured.out and "saucer.3mf" in captured.out
    assert "[100.0%]" in captured.err  # progress
    assert "check" in captured.out
    assert (out / "saucer.3mf").is_file() and (out / "saucer.obj").is_file()
    code = main(["export", str(folder), "--formats", "fbx", "--out", str(tmp_path / "x")])
    captured = capsys.readouterr()
    assert code == 2 and "unknown export format 'fbx'" in captured.err and "Traceback" not in captured.err
    assert not (tmp_path / "x").exists()
    code = main(["export", str(tmp_path / "missing"), "--out", str(tmp_path / "y")])
    assert code == 2 and not (tmp_path / "y").exists()
    code = main(["export", str(folder), "--cup-diameter-mm", "-1", "--out", str(tmp_path / "y")])
    assert code == 2 and not (tmp_path / "y").exists()


def test_cli_export_json(design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = save_design(design, tmp_path / "design")
    code = main(["export", str(folder), "--printer", "bureau", "--cup-diameter-mm", str(CUP_MM), "--formats", "obj",
                 "--zip-obj", "--seat", "ring", "--texture-px", str(ATLAS), "--out", str(tmp_path / "o"), "--json", "-q"])
    captured = capsys.readouterr()
    assert captured.err == ""  # -q: no progress
    d = json.loads(captured.out)
    assert d["formats"] == ["obj"] and [Path(p).name for p in d["files"]["obj"]] == ["saucer.zip"]
    # the zip is checked as what the bureau unpacks; the exit code is the worst check's
    assert len(d["checks"]) == 1 and d["checks"][0]["path"].endswith("saucer.zip")
    assert d["checks"][0]["verdict"] in ("printable", "not printable")  # read, not "unreadable"
    assert code == d["exit_code"] == d["checks"][0]["exit_code"]
    assert json.loads((tmp_path / "o" / "scene.json").read_text())["seat"]["kind"] == "ring"


def test_cli_export_refuses_no_seat_with_an_explicit_seat(design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = save_design(design, tmp_path / "design")
    quick = ["--formats", "stl", "--texture-px", str(ATLAS), "--cup-diameter-mm", str(CUP_MM), "--no-check", "--no-verify", "-q"]
    for seat in ("ring", "recess"):
        code = main(["export", str(folder), "--no-seat", "--seat", seat, *quick, "-o", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2 and "--no-seat" in err and f"--seat {seat}" in err and "Traceback" not in err
        assert not (tmp_path / "o").exists()
    # --no-seat alone, or with --seat none, is no seat
    assert main(["export", str(folder), "--seat", "none", "--no-seat", *quick, "-o", str(tmp_path / "o")]) == 0
    assert json.loads((tmp_path / "o" / "export.json").read_text())["seat"]["kind"] == "none"
    capsys.readouterr()


def test_cli_export_refuses_to_replace_another_designs_export(design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = save_design(replace(design, inputs={"direct": {"file": "a.png", "sha256": "1" * 64}}), tmp_path / "a")
    b = save_design(replace(design, inputs={"direct": {"file": "b.png", "sha256": "2" * 64}}), tmp_path / "b")
    out = tmp_path / "print"
    quick = ["--formats", "stl", "--texture-px", str(ATLAS), "--cup-diameter-mm", str(CUP_MM), "--no-check", "--no-verify", "-q"]
    assert main(["export", str(a), *quick, "-o", str(out)]) == 0
    # the same design again: replaced only with --force, the rule of every command that writes
    assert main(["export", str(a), *quick, "-o", str(out)]) == 2
    assert "holds an earlier export of this design; add --force" in capsys.readouterr().err
    assert main(["export", str(a), *quick, "--force", "-o", str(out)]) == 0
    capsys.readouterr()
    before = (out / "export.json").read_bytes()
    code = main(["export", str(b), *quick, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and str(out) in err and "--force" in err and "a.png" in err
    assert (out / "export.json").read_bytes() == before  # the other design's export is untouched
    assert main(["export", str(b), *quick, "--force", "-o", str(out)]) == 0
    assert json.loads((out / "export.json").read_text())["design"]["inputs"]["direct"]["file"] == "b.png"
    capsys.readouterr()


# --------------------------------------------------------------------------- formats a profile does not list (issue 14)


def test_packaged_printer_profiles_are_the_source_ones() -> None:
    # saucerfab/data/printers is what an installed package reads; it must say what printers/ says
    source = {p.name: p.read_bytes() for p in sorted((ROOT / "printers").glob("*.toml"))}
    packaged = {p.name: p.read_bytes() for p in sorted((ROOT / "saucerfab" / "data" / "printers").glob("*.toml"))}
    assert source and packaged == source


@pytest.mark.parametrize("printer", ["j55", "j850"])
def test_stratasys_profiles_take_glb(design: Design, tmp_path: Path, printer: str) -> None:
    # GrabCAD Print (J55, J850) reads colour and texture from glTF/GLB: help.grabcad.com article 214
    assert "glb" in load_profile(printer).accepted_formats
    res = export_design(design, tmp_path / "g", printer=printer, cup_diameter_mm=CUP_MM, formats=["3mf", "glb"],
                        options=FabOptions(texture_px=ATLAS))
    assert res.formats == ["3mf", "glb"] and (res.out / "saucer.glb").is_file()
    assert not any("does not list" in w for w in res.warnings), res.warnings
    from saucerfab.check import check_mesh

    assert "format_not_accepted" not in check_mesh(res.out / "saucer.glb", printer=printer).codes


def test_a_format_the_profile_lacks_is_refused_or_set_apart(
    design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert "stl" not in load_profile("bureau").accepted_formats
    with pytest.raises(ExportError, match=r"Generic full-colour bureau does not take STL .*--allow-format"):
        export_design(design, tmp_path / "r", printer="bureau", cup_diameter_mm=CUP_MM, formats=["obj", "stl"],
                      options=FabOptions(texture_px=ATLAS, seat="ring"))
    assert not (tmp_path / "r").exists()
    res = export_design(design, tmp_path / "s", printer="bureau", cup_diameter_mm=CUP_MM, formats=["obj", "stl"],
                        options=FabOptions(texture_px=ATLAS, seat="ring"), allow_other_formats=True)
    assert res.formats == ["obj", "stl"] and res.other_formats == ["stl"]
    assert (res.out / "other-formats" / "saucer.stl").is_file() and not (res.out / "saucer.stl").exists()
    said = [w for w in res.warnings if "other-formats/" in w]
    assert len(said) == 1 and said[0].startswith("STL written into other-formats/ at your request"), said
    assert json.loads(res.summary_json.read_text())["warnings"] == res.warnings


def test_an_unknown_format_is_still_refused(design: Design, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ExportError, match=r"unknown export format 'fbx'; known: 3mf, obj, glb, ply, wrl, stl"):
        export_design(design, tmp_path / "u", printer="j55", cup_diameter_mm=CUP_MM, formats=["glb", "fbx"],
                      options=FabOptions(texture_px=ATLAS))
    assert not (tmp_path / "u").exists()
    folder = save_design(design, tmp_path / "design")
    code = main(["export", str(folder), "--formats", "3mf,fbx", "--no-check", "--no-verify", "-q", "-o", str(tmp_path / "v")])
    err = capsys.readouterr().err
    assert code == 2 and "unknown export format 'fbx'" in err and "Traceback" not in err
    assert not (tmp_path / "v").exists()


# --------------------------------------------------------------------------- the walls' colour (issue 43)


def test_walls_and_seat_take_the_background_meant_around_the_direct_picture(design: Design, tmp_path: Path) -> None:
    from saucerfab.fabricate.pipeline import surround_rgb

    cream = np.zeros((32, 32, 3), np.uint8)
    cream[...] = (250, 240, 220)
    cream[12:20, 12:20] = (200, 20, 40)  # a subject in the middle: the border is the background
    made = replace(design, references={"direct": cream, "reflected": cream})
    assert surround_rgb(made) == (250, 240, 220)
    assert surround_rgb(replace(made, parameters={**made.parameters, "background": "#102030"})) == (16, 32, 48)
    assert surround_rgb(design) == NEUTRAL_WALL_RGB  # no references: the neutral grey
    res = export_design(made, tmp_path / "p", printer=ALL_FORMATS, cup_diameter_mm=CUP_MM, formats=["ply"],
                        options=FabOptions(texture_px=ATLAS))
    summary = json.loads(res.summary_json.read_text())
    assert summary["options"]["wall_rgb"] == [250, 240, 220]  # recorded as the files carry it
    import trimesh

    mesh = trimesh.load(res.out / "saucer.ply", process=False)
    z = np.asarray(mesh.vertices)[:, 2]
    bottom = np.asarray(mesh.visual.vertex_colors)[z < z.min() + 1e-6, :3]
    assert (bottom == (250, 240, 220)).all()
    # told otherwise, the walls take the colour given
    res = export_design(made, tmp_path / "q", printer=ALL_FORMATS, cup_diameter_mm=CUP_MM, formats=["ply"],
                        options=FabOptions(texture_px=ATLAS, wall_rgb=(1, 2, 3)))
    assert json.loads(res.summary_json.read_text())["options"]["wall_rgb"] == [1, 2, 3]


def test_a_damaged_recorded_background_falls_back_alike_in_export_and_verify(design: Design) -> None:
    from saucerfab.fabricate.pipeline import surround_rgb
    from saucerfab.imaging.images import recorded_background
    from saucerfab.verify.wholeview import background_colours

    cream = np.zeros((32, 32, 3), np.uint8)
    cream[...] = (250, 240, 220)
    made = replace(design, references={"direct": cream}, parameters={**design.parameters, "background": "nonsense"})
    assert recorded_background(made.parameters) is None and recorded_background({"background": "#102030"}) == "#102030"
    assert surround_rgb(made) == (250, 240, 220)  # the picture's own border colour, not the neutral grey
    ideal = background_colours({"direct": cream / 255.0}, recorded_background(made.parameters))["direct"]
    assert tuple(int(round(v * 255)) for v in ideal) == (250, 240, 220)
