"""``saucerfab.check.check_mesh``: good files pass, each broken fixture fails for the right reason."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import zipfile
from pathlib import Path

import fixtures_check as fx
import numpy as np
import pytest

from saucerfab.check import Limits, Report, check_mesh
from saucerfab.errors import ConfigError
from saucerfab.model.profiles import load_profile


def codes(r: Report, severity: str | None = None) -> set[str]:
    return {f.code for f in r.findings if severity is None or f.severity == severity}


def assert_clean(r: Report) -> None:
    """Printable, with no errors and no warnings (info is fine)."""
    assert r.verdict == "printable", r.reason()
    assert r.exit_code == 0
    assert not r.errors and not r.warnings, [(f.code, f.message) for f in r.findings]


@pytest.fixture(scope="module")
def saucer() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return fx.saucer_solid(24)


@pytest.fixture(scope="module")
def png() -> bytes:
    return fx.png_bytes(2048, 2048)


# -- good files ---------------------------------------------------------------------


def test_textured_3mf_is_clean_with_stats(tmp_path: Path, saucer: tuple, png: bytes) -> None:
    V, F, uv = saucer
    p = fx.write_3mf(tmp_path / "s.3mf", V, F, uv=uv, texture=png)
    r = check_mesh(p, printer="j55")
    assert_clean(r)
    s = r.stats
    assert r.format == "3mf" and s["units"] == "millimeter" and s["units_stated"]
    assert s["triangles"] == len(F) and s["vertices"] == len(V) and s["shells"] == 1
    assert s["bbox_mm"]["size"] == pytest.approx([100, 100, V[:, 2].max()], abs=1e-4)
    assert s["volume_mm3"] > 0 and s["area_mm2"] > 2 * 100 * 100
    assert s["self_intersection_check"] == "full" and s["self_intersecting_pairs"] == 0
    assert s["min_wall_mm"] == pytest.approx(3.0, abs=0.05)  # the flat base is the thinnest wall
    assert s["textures"] == [{"name": "/3D/Texture/texture.png", "status": "ok", "width": 2048, "height": 2048,
                              "format": "PNG"}]
    assert s["coloured_fraction"] == 1.0 and s["colour"] == ["texture"]
    # 2048 px over the 100 mm top: 520 dpi, over half of j55's 600 dpi
    assert s["texture_dpi"] == pytest.approx(2048 / 100 * 25.4, rel=0.01)
    assert s["file_bytes"] == p.stat().st_size


def test_3mf_per_corner_uvs_colour_groups_and_units(tmp_path: Path) -> None:
    V, F = fx.box()
    corner = fx.box_uv(V)[F]
    r = check_mesh(fx.write_3mf(tmp_path / "c.3mf", V, F, corner_uv=corner, texture=fx.png_bytes()))
    assert_clean(r)
    r = check_mesh(fx.write_3mf(tmp_path / "g.3mf", V, F, colors=True))
    assert_clean(r)
    assert r.stats["colour"] == ["vertex"] and r.stats["coloured_fraction"] == 1.0
    r = check_mesh(fx.write_3mf(tmp_path / "i.3mf", V / 25.4, F, colors=True, unit="inch"))
    assert r.stats["units"] == "inch" and r.stats["unit_mm"] == 25.4
    assert r.stats["bbox_mm"]["size"] == pytest.approx([40, 30, 20], abs=1e-4)
    assert_clean(r)


def test_3mf_build_item_transform_is_applied(tmp_path: Path) -> None:
    V, F = fx.box()
    # 3MF's row-vector matrix: scale x by 2, then translate by (5, 6, 7)
    r = check_mesh(fx.write_3mf(tmp_path / "t.3mf", V, F, colors=True,
                                item_transform="2 0 0 0 1 0 0 0 1 5 6 7"))
    assert r.stats["bbox_mm"]["min"] == pytest.approx([5, 6, 7])
    assert r.stats["bbox_mm"]["size"] == pytest.approx([80, 30, 20])
    # a mirroring transform keeps the outward winding
    r = check_mesh(fx.write_3mf(tmp_path / "m.3mf", V, F, colors=True,
                                item_transform="-1 0 0 0 1 0 0 0 1 0 0 0"))
    assert_clean(r)


def test_3mf_slow_xml_path_gives_the_same_answer(tmp_path: Path, saucer: tuple, png: bytes) -> None:
    """Blocks the fast path declines (comments, single quotes) and reordered attributes read the same."""
    import re

    V, F, uv = saucer
    xml = fx.model_xml(V, F, uv=uv)
    slow = (xml.replace("<vertices>", "<vertices><!-- c -->").replace("<triangles>", "<triangles>\n<!-- c -->")
            .replace('texid="2">', 'texid="2"><!-- c -->'))
    slow = re.sub(r'<vertex x="([^"]*)" y="([^"]*)" z="([^"]*)"/>', r"<vertex z='\3' x='\1' y='\2'/>", slow)
    reordered = re.sub(r'<vertex x="([^"]*)" y="([^"]*)" z="([^"]*)"/>', r'<vertex y="\2" z="\3"  x="\1" />', xml)
    reordered = re.sub(r'<triangle v1="(\d+)" v2="(\d+)" v3="(\d+)" pid="3"',
                       r'<triangle pid="3" v3="\3" v1="\1" v2="\2"', reordered)
    # formatting that varies from element to element (the numpy path declines, the per-separator path reads it)
    ragged = xml.replace('" y="', '"\n   y="', 7).replace('" p2="', '"  p2="', 11).replace('<m:tex2coord u=', '<m:tex2coord\tu=', 5)
    a = check_mesh(fx.write_3mf(tmp_path / "a.3mf", V, F, uv=uv, texture=png))
    for name, text in (("slow", slow), ("reordered", reordered), ("ragged", ragged)):
        b = check_mesh(fx.write_3mf(tmp_path / f"{name}.3mf", V, F, texture=png, model=text))
        assert b.verdict == "printable", (name, b.reason())
        for key in ("triangles", "volume_mm3", "area_mm2", "bbox_mm", "texture_dpi", "coloured_fraction"):
            assert a.stats[key] == b.stats[key], (name, key)


@pytest.mark.parametrize("kind", ["stl", "stl_ascii", "obj", "ply", "ply_ascii", "wrl", "glb"])
def test_plain_formats_from_our_writers_are_clean(tmp_path: Path, kind: str, saucer: tuple) -> None:
    V, F, uv = saucer
    p = tmp_path / f"s.{kind.split('_')[0]}"
    if kind == "stl":
        fx.write_stl(p, V, F)
    elif kind == "stl_ascii":
        fx.write_stl(p, V, F, ascii=True)
    elif kind == "obj":
        fx.write_obj(p, V, F, uv=uv, texture=fx.png_bytes())
    elif kind == "ply":
        fx.write_ply(p, V, F, colors=True)
    elif kind == "ply_ascii":
        fx.write_ply(p, V, F, binary=False, uv=uv, texture="t.png")
        (tmp_path / "t.png").write_bytes(fx.png_bytes())
    elif kind == "wrl":
        fx.write_vrml(p, V, F, uv=uv, texture="t.png", translate=(1, 2, 3))
        (tmp_path / "t.png").write_bytes(fx.png_bytes())
    else:
        fx.write_glb(p, V, F, uv=uv, texture=fx.png_bytes())
    r = check_mesh(p)
    assert_clean(r)
    assert r.stats["triangles"] == len(F)
    assert r.stats["volume_mm3"] == pytest.approx(check_mesh(fx.write_stl(tmp_path / "ref.stl", V, F)).stats["volume_mm3"],
                                                  rel=1e-5)
    if kind == "wrl":
        assert r.stats["bbox_mm"]["min"] == pytest.approx([1, 2, 3])
    if kind not in ("stl", "stl_ascii"):
        assert r.stats["coloured_fraction"] == 1.0


def test_obj_quads_polygons_and_relative_indices_read_alike(tmp_path: Path) -> None:
    """All-quads (bulk path), mixed polygons with negative indices and comments (line path): same mesh."""
    V, _ = fx.box()
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    vs = "".join(f"v {x} {y} {z}\n" for x, y, z in V)
    (tmp_path / "q.obj").write_text(vs + "".join("f " + " ".join(str(i + 1) for i in q) + "\n" for q in quads))
    mixed = vs + "f -8 -5 -6 -7\n" + "".join("f " + " ".join(f"{i + 1}//1" for i in q) + " # quad\n" for q in quads[1:4])
    mixed += "f 3 4 8\nf 3 8 7\nf 4 1 5 8\n"
    (tmp_path / "m.obj").write_text(mixed)
    a, b = check_mesh(tmp_path / "q.obj"), check_mesh(tmp_path / "m.obj")
    assert_clean(a)
    assert_clean(b)
    for key in ("triangles", "volume_mm3", "area_mm2", "shells", "welded_vertices"):
        assert a.stats[key] == b.stats[key], key
    assert a.stats["triangles"] == 12 and a.stats["volume_mm3"] == pytest.approx(24000)


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "glb"])
def test_trimesh_written_files_are_clean(tmp_path: Path, fmt: str) -> None:
    trimesh = pytest.importorskip("trimesh")
    m = trimesh.creation.icosphere(subdivisions=3, radius=20.0)
    m.apply_translation([25, 25, 25])
    if fmt == "glb":
        m.apply_scale(0.001)  # glTF is metres
    p = tmp_path / f"sphere.{fmt}"
    m.export(p)
    r = check_mesh(p, printer="j55" if fmt != "glb" else "bureau")
    assert r.exit_code == 0, r.reason()
    assert not r.errors
    assert r.stats["volume_mm3"] == pytest.approx(4 / 3 * np.pi * 20**3, rel=0.02)
    assert r.stats["min_wall_mm"] == pytest.approx(40, rel=0.02)


def test_lib3mf_written_3mf_is_clean(tmp_path: Path) -> None:
    import ctypes

    lib3mf = pytest.importorskip("lib3mf")
    V, F = fx.box()
    w = lib3mf.get_wrapper()
    model = w.CreateModel()
    mesh = model.AddMeshObject()
    pos = [lib3mf.Position((ctypes.c_float * 3)(*map(float, v))) for v in V]
    tri = [lib3mf.Triangle((ctypes.c_uint * 3)(*map(int, f))) for f in F]
    mesh.SetGeometry(pos, tri)
    model.AddBuildItem(mesh, w.GetIdentityTransform())
    model.QueryWriter("3mf").WriteToFile(str(tmp_path / "lib.3mf"))
    r = check_mesh(tmp_path / "lib.3mf", printer="j55")
    assert r.exit_code == 0, r.reason()
    assert r.stats["volume_mm3"] == pytest.approx(24000, rel=1e-6)


def test_prusaslicer_written_3mf_is_read_and_its_missing_thumbnail_named(tmp_path: Path) -> None:
    """A real-world 3MF: PrusaSlicer's own export (metadata, config entries, its XML layout).

    Exported from the command line (no OpenGL: no thumbnail is rendered) it
    still names ``/Metadata/thumbnail.png`` in its root relationships. The
    3MF core spec (2.1.3) makes that a must-fail and lib3mf refuses the file,
    so it is not printable for exactly that one reason, with the fix named.
    """
    exe = shutil.which("prusa-slicer")
    assert exe, "prusa-slicer is installed by .ci/install-tools"
    V, F = fx.box()
    fx.write_stl(tmp_path / "box.stl", V, F)
    out = tmp_path / "box.3mf"
    proc = subprocess.run([exe, "--export-3mf", "-o", str(out), str(tmp_path / "box.stl")],
                          capture_output=True, text=True, timeout=120)
    assert out.exists(), proc.stderr[-2000:]
    r = check_mesh(out, printer="j55")
    assert codes(r, "error") == {"spec_violation"}, r.reason()
    assert "thumbnail" in r.reason() and "add the part or remove the relationship" in r.reason()
    assert "lib3mf_rejects" in codes(r, "info")  # lib3mf agrees; our own rule already says why
    assert r.stats["volume_mm3"] == pytest.approx(24000, rel=1e-4)


def test_saucerfab_exporters_output_passes(tmp_path: Path, saucer: tuple) -> None:
    """Every format saucerfab's own exporters write, checked as a bureau would."""
    pytest.importorskip("saucerfab.fabricate.export_3mf")
    from saucerfab.fabricate import registry
    from saucerfab.fabricate.textured import TexturedMesh

    V, F, uv = saucer
    mesh = TexturedMesh(
        name="saucer", vertices=V, faces=F, uvs=uv, face_uvs=F.copy(), texture_png=fx.png_bytes(1024, 1024),
        texture_px=1024, vertex_rgb=np.full((len(V), 3), 128, np.uint8),
    )
    for fmt, writer in registry.WRITERS.items():
        files = writer.load_writer()(mesh)
        for name, data in files.items():
            (tmp_path / name).write_bytes(data)
        mesh_file = tmp_path / f"saucer{writer.mesh_suffix}"
        r = check_mesh(mesh_file, printer="j55" if fmt != "glb" else "bureau")
        assert not r.errors, (fmt, r.reason())
        assert r.stats["triangles"] == len(F), fmt
        # glTF is y-up, so the GLB writer turns the part; compare sizes regardless of axis order
        assert sorted(r.stats["bbox_mm"]["size"]) == pytest.approx(sorted([100, 100, V[:, 2].max()]), abs=1e-3), fmt
        if fmt != "stl":
            assert r.stats["coloured_fraction"] == 1.0, fmt


# -- broken fixtures: each fails for the right code ------------------------------------


def _broken(kind: str) -> tuple[np.ndarray, np.ndarray]:
    V, F = fx.box()
    if kind == "open_box":
        return V, F[1:]
    if kind == "flipped_face":
        F = F.copy()
        F[5] = F[5][::-1]
        return V, F
    if kind == "inverted":
        return V, F[:, ::-1]
    if kind == "duplicate_faces":
        return V, np.concatenate([F, F[:1]])
    if kind == "degenerate":
        # an extra vertex in the middle of an edge, and a zero-area sliver along it
        V = np.concatenate([V, [[20.0, 0, 0]]])
        return V, np.concatenate([F, [[0, 8, 1]]])
    if kind == "repeated_index":
        return V, np.concatenate([F, [[0, 0, 1]]])
    if kind == "non_manifold_edge":
        # a second box touching the first along its vertical edge (40, 30, z): four faces on that edge
        V2, F2 = fx.box(origin=(40, 30, 0))
        VV = np.concatenate([V, V2[[1, 2, 3, 5, 6, 7]]])
        remap = np.array([2, 8, 9, 10, 6, 11, 12, 13])
        return VV, np.concatenate([F, remap[F2]])
    if kind == "fin":
        V = np.concatenate([V, [[20.0, -10, 10]]])
        return V, np.concatenate([F, [[0, 1, 8], [1, 0, 8]]])  # a zero-thickness fin on edge 0-1
    if kind == "two_shells":
        V2, F2 = fx.box(origin=(60, 0, 0))
        return np.concatenate([V, V2]), np.concatenate([F, F2 + 8])
    if kind == "self_intersection":
        V2, F2 = fx.box(origin=(10, 10, 10))
        return np.concatenate([V, V2]), np.concatenate([F, F2 + 8])
    if kind == "pinched_vertex":
        V2 = V + V[6]
        return np.concatenate([V, V2[1:]]), np.concatenate([F, np.where(F == 0, 6, F + 7)])
    if kind == "unreferenced":
        return np.concatenate([V, [[5.0, 5, 5]]]), F
    raise AssertionError(kind)


@pytest.mark.parametrize("kind, code, exit_code", [
    ("open_box", "not_watertight", 1),
    ("flipped_face", "inconsistent_orientation", 1),
    ("inverted", "inverted_normals", 1),
    ("duplicate_faces", "duplicate_faces", 1),
    ("degenerate", "degenerate_faces", 1),
    ("repeated_index", "degenerate_faces", 1),
    ("non_manifold_edge", "non_manifold_edges", 1),
    ("fin", "non_manifold_edges", 1),
    ("self_intersection", "self_intersections", 1),
    ("pinched_vertex", "non_manifold_vertices", 1),
    ("two_shells", "multiple_shells", 0),
    ("unreferenced", "unreferenced_vertices", 0),
])
@pytest.mark.parametrize("fmt", ["3mf", "obj", "ply"])
def test_broken_mesh_fails_for_its_reason(tmp_path: Path, kind: str, code: str, exit_code: int, fmt: str) -> None:
    V, F = _broken(kind)
    p = tmp_path / f"bad.{fmt}"
    if fmt == "3mf":
        fx.write_3mf(p, V, F, colors=True)
    elif fmt == "obj":
        fx.write_obj(p, V, F, vertex_colors=True)
    else:
        fx.write_ply(p, V, F, colors=True)
    r = check_mesh(p)
    assert code in codes(r), (kind, [(f.code, f.message) for f in r.findings])
    assert r.exit_code == exit_code, r.reason()
    if exit_code == 0:  # a warning: strict makes it fail
        assert code in codes(r, "warning")
        assert r.with_strict().exit_code == 1 and check_mesh(p, strict=True).verdict == "not printable"
    else:
        assert code in codes(r, "error")
    # a message says where, in millimetres, when there is a place to point at
    f = next(f for f in r.findings if f.code == code)
    assert "\n" not in f.message


def test_open_box_points_at_the_hole(tmp_path: Path) -> None:
    V, F = _broken("open_box")
    r = check_mesh(fx.write_3mf(tmp_path / "o.3mf", V, F, colors=True))
    f = next(f for f in r.findings if f.code == "not_watertight")
    assert f.where is not None and f.where["count"] == 3
    # the missing face is the bottom triangle (0, 2, 1): its edges lie in z = 0
    assert f.where["point_mm"][2] == pytest.approx(0.0)
    assert r.stats["boundary_edges"] == 3
    assert "thin_walls" not in codes(r) and any("wall thickness not measured" in x.message for x in r.findings)


def test_self_intersection_that_manifold3d_accepts(tmp_path: Path) -> None:
    """manifold3d's status is about manifoldness only: two interpenetrating closed boxes are NoError there."""
    manifold3d = pytest.importorskip("manifold3d")
    V, F = _broken("self_intersection")
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=V.astype(np.float32), tri_verts=F.astype(np.uint32)))
    assert m.status() == manifold3d.Error.NoError
    r = check_mesh(fx.write_3mf(tmp_path / "x.3mf", V, F, colors=True),
                   limits=Limits(manifold3d_crosscheck=True))
    assert "self_intersections" in codes(r, "error")
    assert r.stats["manifold3d_status"] == "NoError"
    assert r.stats["self_intersecting_pairs"] > 0


@pytest.mark.parametrize("kind, manifold3d_ok", [
    ("open_box", False), ("flipped_face", False), ("two_shells", True), ("pinched_vertex", True),
    # manifold3d pairs the four half-edges of an edge two boxes share and accepts it; a printer's
    # slicer does not know which box the edge belongs to, so the checker calls it non-manifold
    ("non_manifold_edge", True),
])
def test_topology_against_manifold3d(tmp_path: Path, kind: str, manifold3d_ok: bool) -> None:
    """Where manifold3d rejects a mesh the checker does too; where they differ, it is on purpose."""
    manifold3d = pytest.importorskip("manifold3d")
    V, F = _broken(kind)
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=V.astype(np.float32), tri_verts=F.astype(np.uint32)))
    assert (m.status() == manifold3d.Error.NoError) == manifold3d_ok
    r = check_mesh(fx.write_3mf(tmp_path / "k.3mf", V, F, colors=True))
    ours = not (codes(r) & {"not_watertight", "non_manifold_edges", "inconsistent_orientation"})
    assert ours == (manifold3d_ok and kind != "non_manifold_edge"), (kind, r.codes)
    V, F = fx.box()
    good = manifold3d.Manifold(manifold3d.Mesh(vert_properties=V.astype(np.float32), tri_verts=F.astype(np.uint32)))
    assert good.status() == manifold3d.Error.NoError


def test_self_intersections_agree_with_pymeshlab(tmp_path: Path) -> None:
    pymeshlab = pytest.importorskip("pymeshlab")
    V, F, _ = fx.saucer_solid(12)
    V2, F2 = fx.box((30, 30, 30), origin=(35, 35, -10))  # pokes through the saucer's bottom and top
    cases = [(V, F), (np.concatenate([V, V2]), np.concatenate([F, F2 + len(V)]))]
    for VV, FF in cases:
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=VV, face_matrix=FF.astype(np.int32)))
        ms.compute_selection_by_self_intersections_per_face()
        theirs = ms.current_mesh().face_selection_array()
        r = check_mesh(fx.write_stl(tmp_path / "p.stl", VV, FF))
        assert (r.stats["self_intersecting_pairs"] > 0) == bool(theirs.any())


def test_non_finite_coordinates(tmp_path: Path) -> None:
    V, F = fx.box()
    V = V.copy()
    V[3, 1] = np.nan
    r = check_mesh(fx.write_obj(tmp_path / "n.obj", V, F))
    assert r.exit_code == 1 and "non_finite" in codes(r, "error")
    assert r.findings[[f.code for f in r.findings].index("non_finite")].where["vertices"] == [3]
    V[3, 1] = np.inf
    r = check_mesh(fx.write_stl(tmp_path / "n.stl", V, F))
    assert "non_finite" in codes(r, "error")


def test_index_out_of_range_is_unreadable(tmp_path: Path) -> None:
    V, F = fx.box()
    F = F.copy()
    F[4, 1] = 99
    for p in (fx.write_3mf(tmp_path / "x.3mf", V, F, colors=True), fx.write_obj(tmp_path / "x.obj", V, F),
              fx.write_ply(tmp_path / "x.ply", V, F), fx.write_vrml(tmp_path / "x.wrl", V, F)):
        r = check_mesh(p)
        assert r.exit_code == 2 and r.verdict == "unreadable", (p, r.reason())
        assert codes(r) == {"index_out_of_range"}, p


# -- printer profile -------------------------------------------------------------------


def test_too_big_for_the_printer(tmp_path: Path) -> None:
    V, F = fx.box((400.0, 100.0, 50.0))
    p = fx.write_3mf(tmp_path / "big.3mf", V, F, colors=True)
    r = check_mesh(p, printer="j55")  # 335 x 335 x 190
    assert "exceeds_build_volume" in codes(r, "error") and r.exit_code == 1
    assert check_mesh(p, printer="j850").exit_code == 0  # 490 x 390 x 200
    V, F = fx.box((100.0, 100.0, 300.0))  # fits j55 lying down
    r = check_mesh(fx.write_3mf(tmp_path / "tall.3mf", V, F, colors=True), printer="j55")
    assert r.exit_code == 0 and "fits_rotated" in codes(r, "info")


def test_polygon_file_size_and_format_limits(tmp_path: Path, saucer: tuple) -> None:
    V, F, uv = saucer
    prof = load_profile("bureau")
    import dataclasses

    small = dataclasses.replace(prof, max_triangles=100, max_file_mb=0.001)
    p = fx.write_stl(tmp_path / "s.stl", V, F)
    r = check_mesh(p, printer=small)
    assert {"too_many_triangles", "file_too_large", "format_not_accepted"} <= codes(r, "error")
    assert r.printer == "bureau"


def test_thin_wall_with_location_and_policy(tmp_path: Path) -> None:
    V, F = fx.box((50.0, 50.0, 0.6))  # a 0.6 mm plate
    p = fx.write_3mf(tmp_path / "plate.3mf", V, F, colors=True)
    # min wall 1.0, thin_policy warn: a wall under a printer's minimum over most of the surface is not
    # printable whatever the policy (issue 42; Limits.thin_wall_error_fraction)
    r = check_mesh(p, printer="j55")
    f = next(f for f in r.findings if f.code == "thin_walls")
    assert f.severity == "error" and r.exit_code == 1
    assert r.stats["min_wall_mm"] == pytest.approx(0.6, abs=1e-3)
    assert f.where is not None and len(f.where["point_mm"]) == 3
    assert r.stats["thin_wall_fraction"] > 0.9
    r = check_mesh(p, printer="bureau")  # min wall 2.0, refuse
    assert "thin_walls" in codes(r, "error") and r.exit_code == 1
    r = check_mesh(p, limits=Limits(min_wall_mm=1.0))  # a minimum asked for without a printer only warns
    f = next(f for f in r.findings if f.code == "thin_walls")
    assert f.severity == "warning" and r.exit_code == 0 and r.with_strict().exit_code == 1
    r = check_mesh(p, limits=Limits(min_wall_mm=0.5))
    assert "thin_walls" not in codes(r)
    r = check_mesh(p)  # no printer, no minimum: only the estimate
    assert "thin_walls" not in codes(r) and r.stats["min_wall_mm"] == pytest.approx(0.6, abs=1e-3)


def test_relief_crests_are_not_thin_walls_but_fins_are(tmp_path: Path) -> None:
    # a sawtooth top like the default design's waves: 0.5 mm rises per 0.67 mm step up to a crest,
    # then a 6 mm cliff; just under each crest the tooth is under 1 mm thick across its cliff
    ys = np.arange(0, 60.0, 0.67)
    xs = np.linspace(0, 30.0, 12)
    tooth = np.mod(np.arange(len(ys)), 12)
    h = 10.0 + 0.5 * tooth[:, None] * np.ones((1, len(xs)))
    V, F, _ = fx.heightfield_solid(h, xs, ys)
    r = check_mesh(fx.write_stl(tmp_path / "teeth.stl", V, F), printer="j55")
    assert "thin_walls" not in codes(r) and r.with_strict().exit_code == 0
    assert r.stats["relief_thin_samples"] > 0 and r.stats["min_wall_mm"] >= 1.0
    # a fin: one row 10 mm above its neighbours, 1 mm wide at its foot: thin for most of its height,
    # a third of the surface: not printable (issue 42)
    ys = np.arange(0, 10.0, 0.5)
    xs = np.linspace(0, 20.0, 9)
    h = np.full((len(ys), len(xs)), 5.0)
    h[10] = 15.0
    V, F, _ = fx.heightfield_solid(h, xs, ys)
    r = check_mesh(fx.write_stl(tmp_path / "fin.stl", V, F), printer="j55")
    f = next(f for f in r.findings if f.code == "thin_walls")
    assert f.severity == "error" and r.stats["min_wall_mm"] < 0.5
    assert r.stats["relief_thin_samples"] > 0  # its foot, beside the block, is relief


def test_unknown_printer_is_a_config_error(tmp_path: Path) -> None:
    V, F = fx.box()
    with pytest.raises(ConfigError, match="unknown printer"):
        check_mesh(fx.write_stl(tmp_path / "b.stl", V, F), printer="no-such-printer")


# -- colour --------------------------------------------------------------------------


def test_uv_outside_unit_square(tmp_path: Path) -> None:
    V, F = fx.box()
    uv = fx.box_uv(V) * 1.5 - 0.25
    r = check_mesh(fx.write_3mf(tmp_path / "uv.3mf", V, F, uv=uv, texture=fx.png_bytes()))
    assert "uv_out_of_range" in codes(r, "error") and r.exit_code == 1
    assert r.stats["uv_outside_faces"] == 12


def test_missing_and_broken_textures(tmp_path: Path) -> None:
    V, F = fx.box()
    uv = fx.box_uv(V)
    r = check_mesh(fx.write_3mf(tmp_path / "m.3mf", V, F, uv=uv, texture=None))
    assert "texture_missing" in codes(r, "error")
    r = check_mesh(fx.write_obj(tmp_path / "m.obj", V, F, uv=uv, texture=fx.png_bytes(), write_texture=False))
    assert "texture_missing" in codes(r, "error")
    r = check_mesh(fx.write_3mf(tmp_path / "b.3mf", V, F, uv=uv, texture=b"\x89PNG\r\n\x1a\n garbage"))
    assert "texture_unreadable" in codes(r, "error")
    assert r.stats["textures"][0]["status"] == "unreadable"
    r = check_mesh(fx.write_obj(tmp_path / "e.obj", V, F, uv=uv, texture_name="../outside.png"))
    assert "texture_path_unsafe" in codes(r, "error")


def test_texture_resolution_against_printer_dpi(tmp_path: Path) -> None:
    V, F = fx.box((200.0, 200.0, 20.0))
    uv = fx.box_uv(V)
    r = check_mesh(fx.write_3mf(tmp_path / "lo.3mf", V, F, uv=uv, texture=fx.png_bytes(256, 256)), printer="j55")
    assert "texture_low_dpi" in codes(r, "warning")
    assert r.stats["texture_dpi"] == pytest.approx(256 / 200 * 25.4, rel=0.2)


def test_partly_coloured_and_no_colour(tmp_path: Path) -> None:
    V, F = fx.box()
    xml = fx.model_xml(V, F, colors=True)
    # strip the colour from the first two triangles
    xml = xml.replace(' pid="4" p1="0" p2="1" p3="0"', "", 2)
    r = check_mesh(fx.write_3mf(tmp_path / "p.3mf", V, F, model=xml))
    assert "partly_coloured" in codes(r, "warning")
    assert 0 < r.stats["coloured_fraction"] < 1
    r = check_mesh(fx.write_3mf(tmp_path / "n.3mf", V, F))
    assert "no_colour" in codes(r, "info") and r.exit_code == 0


# -- units -----------------------------------------------------------------------------


def test_unit_plausibility(tmp_path: Path) -> None:
    V, F = fx.box((0.1, 0.08, 0.01))  # a saucer written in metres, read as millimetres
    r = check_mesh(fx.write_stl(tmp_path / "m.stl", V, F))
    f = next(f for f in r.findings if f.code == "units_suspect")
    assert "metres" in f.message and f.severity == "warning"
    V, F = fx.box((100.0, 80.0, 10.0))
    r = check_mesh(fx.write_glb(tmp_path / "mm.glb", V, F, scale=1.0))  # mm written as metres
    assert "units_suspect" in codes(r, "warning") and "0.001" in next(
        f.message for f in r.findings if f.code == "units_suspect")
    assert check_mesh(fx.write_glb(tmp_path / "ok.glb", V, F)).stats["bbox_mm"]["size"] == pytest.approx(
        [100, 80, 10], rel=1e-6)


def test_extension_mismatch_is_read_by_content(tmp_path: Path) -> None:
    V, F = fx.box()
    p = fx.write_3mf(tmp_path / "really3mf.stl", V, F, colors=True)
    r = check_mesh(p)
    assert r.format == "3mf" and "extension_mismatch" in codes(r, "warning")


# -- report ----------------------------------------------------------------------------


def test_report_to_dict_is_json_and_strict_round_trip(tmp_path: Path) -> None:
    V, F = _broken("two_shells")
    r = check_mesh(fx.write_3mf(tmp_path / "t.3mf", V, F, colors=True), printer="j55")
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert d["schema"] == "saucerfab.check/1" and d["printer"] == "j55" and d["verdict"] == "printable"
    s = r.with_strict()
    assert s.strict and s.verdict == "not printable" and s.exit_code == 1
    assert s.with_strict(False).exit_code == 0
    assert "multiple_shells" in s.reason()


def test_zip_of_only_a_texture_is_not_a_mesh(tmp_path: Path) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("image.png", fx.png_bytes())
    (tmp_path / "x.3mf").write_bytes(buf.getvalue())
    r = check_mesh(tmp_path / "x.3mf")
    assert r.exit_code == 2 and codes(r) == {"not_a_mesh"}


def test_zipped_obj_upload_bundle(tmp_path: Path, saucer: tuple) -> None:
    """OBJ + MTL + PNG zipped as one file (what bureaus ask for) is read with its textures from the archive."""
    V, F, uv = saucer
    src = tmp_path / "src"
    src.mkdir()
    fx.write_obj(src / "part.obj", V, F, uv=uv, texture=fx.png_bytes(512, 512))
    bundle = tmp_path / "upload.zip"
    with zipfile.ZipFile(bundle, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(src.iterdir()):
            z.write(f, f"part/{f.name}")
    r = check_mesh(bundle, printer="bureau")
    assert r.format == "obj" and r.exit_code == 0, r.reason()
    assert "from_archive" in codes(r, "info")
    assert r.stats["textures"][0]["status"] == "ok" and r.stats["coloured_fraction"] == 1.0
    # the same bundle without its texture, or with two meshes, says so
    with zipfile.ZipFile(tmp_path / "notex.zip", "w") as z:
        z.write(src / "part.obj", "part.obj")
        z.write(src / "part.mtl", "part.mtl")
    assert "texture_missing" in codes(check_mesh(tmp_path / "notex.zip"), "error")
    with zipfile.ZipFile(tmp_path / "two.zip", "w") as z:
        z.write(src / "part.obj", "a.obj")
        z.write(src / "part.obj", "b.obj")
    r = check_mesh(tmp_path / "two.zip")
    assert r.exit_code == 2 and codes(r) == {"unsupported_format"}


def test_obj_without_its_material_library(tmp_path: Path) -> None:
    V, F = fx.box()
    p = fx.write_obj(tmp_path / "m.obj", V, F, uv=fx.box_uv(V), texture=fx.png_bytes())
    (tmp_path / "m.mtl").unlink()
    r = check_mesh(p)
    assert "texture_missing" in codes(r, "error") and "material library" in r.reason()


def test_every_face_of_zero_area_and_coloured_is_judged_not_a_crash(tmp_path: Path) -> None:
    # issue 15: three collinear coloured vertices gave internal_error: IndexError in the colour checks
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    F = np.array([[0, 1, 2]])
    r = check_mesh(fx.write_ply(tmp_path / "line.ply", V, F, colors=True))
    assert "internal_error" not in codes(r)
    assert r.stats["coloured_fraction"] == 1.0 and "partly_coloured" not in codes(r)


def test_obj_statements_continued_with_a_backslash_are_joined(tmp_path: Path) -> None:
    # issue 15: Rhino continues long face lines with a trailing backslash; that was "not an index"
    V, F = fx.box()
    lines = [f"v {x:.4f} {y:.4f} {z:.4f}" for x, y, z in V]
    for a, b, c in F + 1:
        lines.append(f"f {a} \\\n  {b} {c}")
    p = tmp_path / "rhino.obj"
    p.write_text("\n".join(lines) + "\n")
    r = check_mesh(p)
    assert r.verdict == "printable" and r.stats["triangles"] == len(F)
    assert "continued_lines" in codes(r, "info")
    crlf = tmp_path / "rhino_crlf.obj"
    crlf.write_bytes(p.read_bytes().replace(b"\n", b"\r\n"))
    assert check_mesh(crlf).stats["triangles"] == len(F)


def test_obj_faces_naming_texture_coordinates_it_lacks_are_a_warning(tmp_path: Path) -> None:
    # issue 15: `f 1/1 2/2 3/3` with no (or too few) vt lines was unreadable; the geometry is whole
    V, F = fx.box()
    p = fx.write_obj(tmp_path / "t.obj", V, F, uv=fx.box_uv(V), texture=fx.png_bytes())
    text = p.read_text()
    no_vt = "".join(line + "\n" for line in text.splitlines() if not line.startswith("vt "))
    for name, body in (("none.obj", no_vt),  # bulk path: uniform faces
                       ("relative.obj", no_vt + "f -1/-1 -2/-2 -3/-3\n")):  # line-by-line path
        q = tmp_path / name
        q.write_text(body)
        r = check_mesh(q)
        assert r.verdict != "unreadable", r.reason()
        assert "texcoords_missing" in codes(r, "warning")
        assert "partly_coloured" in codes(r) or "no_colour" in codes(r)
    bad = tmp_path / "zero.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/0 2/1 3/1\n")  # 0 is no OBJ index: still refused
    assert "index_out_of_range" in codes(check_mesh(bad))


def test_gltf_integers_written_as_floats_are_integers(tmp_path: Path) -> None:
    # issue 15: JSON has one number type; `"POSITION": 0.0` is an index to the glTF-Validator too
    import base64
    import json as _json

    V, F = fx.box()
    pos = V.astype("<f4").tobytes()
    idx = F.astype("<u4").tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(pos) + len(idx),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(pos + idx).decode()}],
        "bufferViews": [{"buffer": 0.0, "byteOffset": 0, "byteLength": len(pos)},
                        {"buffer": 0, "byteOffset": float(len(pos)), "byteLength": len(idx)}],
        "accessors": [
            {"bufferView": 0.0, "componentType": 5126.0, "count": float(len(V)), "type": "VEC3",
             "min": V.min(axis=0).tolist(), "max": V.max(axis=0).tolist()},
            {"bufferView": 1, "componentType": 5125, "count": F.size, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0.0}, "indices": 1.0}]}],
        "nodes": [{"mesh": 0.0}],
        "scenes": [{"nodes": [0.0]}],
        "scene": 0.0,
    }
    p = tmp_path / "floats.gltf"
    p.write_text(_json.dumps(doc))
    r = check_mesh(p)
    assert r.verdict == "printable", [f.message for f in r.findings]
    assert r.stats["triangles"] == len(F)
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 0.5  # a fraction is still refused
    p.write_text(_json.dumps(doc))
    assert check_mesh(p).verdict == "unreadable"
