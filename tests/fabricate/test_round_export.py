"""A round saucer's export for every bundled printer, read back by outside readers (issue 44).

One small round design (160 mm disc, 48 x 48 grid, the paper's 80 mm cup) is
exported through ``saucerfab export`` for every bundled printer profile in 3MF
and GLB (a profile that does not take GLB writes it apart, ``--allow-format``),
and through :func:`saucerfab.workflow.make_print` for the J55 in every format; each file
is held to ``saucerfab check --strict``, the 3MF to lib3mf in strict mode and
the GLB to the Khronos glTF-Validator.

The atlas is 4096 px for every profile (over half of every profile's dpi on
the top) to keep the tests short.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from saucerfab.cli import main
from saucerfab.fabricate.options import FabOptions
from saucerfab.files.formats import FORMATS
from saucerfab.model.design import Design
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.model.footprint import part_edge
from saucerfab.model.heightfield import make_grid
from saucerfab.model.profiles import list_profiles
from saucerfab.model.relief import blunt_thin_crests
from saucerfab.model.scene import disc_saucer, round_scene
from saucerfab.workflow import make_print

ROOT = Path(__file__).resolve().parents[2]
GLTF_VALIDATOR = ROOT / "tools" / "node" / "node_modules" / "gltf-validator"
PROFILES = sorted(list_profiles())
ATLAS = "4096"
DIAMETER_MM = 160.0


def round_design() -> Design:
    """The base shape without random bumps, made printable for the strictest bundled printer (the bureau's
    2 mm wall) as the optimizer makes a design for its printer: on this coarse grid (3.4 mm steps) the rings
    stand as lips at the disc's edge, which an export for another printer would otherwise blunt and say so."""
    sc = replace(round_scene(), saucer=disc_saucer(DIAMETER_MM / 100.0, 48))
    d = synthetic_design(sc, resolution=48, texture_size=64, seed=3)
    s = sc.mm_per_unit
    step = float(make_grid(sc.saucer).spacing[0]) * s
    bureau = list_profiles()["bureau"]
    res = blunt_thin_crests(d.base_heights * s, step, step, bureau.min_feature_mm, min_wall=bureau.min_wall_mm,
                            edge=part_edge(sc.saucer))
    assert res.remaining == 0
    return replace(d, heights=res.heights / s)


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_design(round_design(), tmp_path_factory.mktemp("round") / "design")


def loud(findings: list[dict], ignore: set[str] = frozenset()) -> list[dict]:  # type: ignore[assignment]
    """The errors and warnings among a check's findings (what ``--strict`` fails on), less ``ignore``."""
    return [f for f in findings if f["severity"] in ("error", "warning") and f["code"] not in ignore]


def export(folder: Path, key: str, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[dict, list[Path]]:
    """``saucerfab export`` in 3MF and GLB for ``key``; (its JSON summary, the 3MF and GLB paths)."""
    takes_glb = "glb" in list_profiles()[key].accepted_formats
    apart = [] if takes_glb else ["--allow-format"]
    rc = main(["export", str(folder), "--printer", key, "--formats", "3mf,glb", *apart, "--texture-px", ATLAS,
               "--no-verify", "--json", "-q", "-o", str(out)])
    captured = capsys.readouterr()
    assert rc in (0, 1), captured.err  # 1: a check's verdict; asserted on below
    glb = out / "saucer.glb" if takes_glb else out / "other-formats" / "saucer.glb"
    assert (out / "saucer.3mf").is_file() and glb.is_file()
    return json.loads(captured.out), [out / "saucer.3mf", glb]


def read_3mf_strict(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """lib3mf in strict mode: no warning, millimetres, a texture; the one mesh's (vertices, triangles)."""
    import lib3mf

    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromFile(str(path))
    assert reader.GetWarningCount() == 0, [reader.GetWarning(i) for i in range(reader.GetWarningCount())]
    assert model.GetUnit() == lib3mf.ModelUnit.MilliMeter
    assert model.GetTexture2Ds().MoveNext(), "no texture2d in the 3MF"
    meshes = model.GetMeshObjects()
    assert meshes.MoveNext()
    mesh = meshes.GetCurrentMeshObject()
    verts = np.array([[p.Coordinates[0], p.Coordinates[1], p.Coordinates[2]] for p in mesh.GetVertices()])
    tris = np.array([list(t.Indices) for t in mesh.GetTriangleIndices()], np.int64)
    assert not meshes.MoveNext(), "more than one mesh object"
    return verts, tris


def gltf_validate(path: Path) -> dict:
    """The Khronos glTF-Validator's issues for ``path`` (``numErrors``, ``numWarnings``, ``messages``)."""
    assert (GLTF_VALIDATOR / "package.json").is_file(), "gltf-validator missing: run bash .ci/install-tools"
    script = (
        "const fs=require('fs');const v=require(process.argv[1]);"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])),{maxIssues:100})"
        ".then(r=>console.log(JSON.stringify(r.issues)),e=>{console.error(String(e));process.exit(3);});"
    )
    proc = subprocess.run(["node", "-e", script, str(GLTF_VALIDATOR), str(path)], capture_output=True, text=True,
                          check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def assert_round_bounds(verts: np.ndarray, sj: dict) -> None:
    """The mesh (file mm) spans the disc: the diameter across, centred on the scene's cup."""
    ext = verts.max(axis=0) - verts.min(axis=0)
    assert ext[0] == pytest.approx(DIAMETER_MM, abs=0.03) and ext[1] == pytest.approx(DIAMETER_MM, abs=0.03)
    centre = 0.5 * (verts.max(axis=0) + verts.min(axis=0))
    assert centre[:2] == pytest.approx(sj["cup"]["center"], abs=1e-3)
    assert sj["saucer"]["center"] == sj["cup"]["center"]


@pytest.mark.parametrize("key", PROFILES)
def test_round_export_for_every_profile_reads_back_and_checks(
    folder: Path, key: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary, (path_3mf, path_glb) = export(folder, key, tmp_path / "out", capsys)
    assert not [w for w in summary["warnings"] if "--allow-format" not in w], summary["warnings"]
    assert json.loads((tmp_path / "out" / "export.json").read_text())["seat"]["kind"] == "recess"
    for c in summary["checks"]:  # the export's own check, with the printer
        assert c["verdict"] == "printable" and not loud(c["findings"]), (c["path"], c["findings"])
    sj = json.loads((tmp_path / "out" / "scene.json").read_text())
    assert sj["saucer"]["outline"] == "disc" and sj["saucer"]["diameter"] == DIAMETER_MM

    verts, tris = read_3mf_strict(path_3mf)
    assert tris.shape[0] == summary["triangles"]
    assert_round_bounds(verts, sj)

    issues = gltf_validate(path_glb)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
    import trimesh

    geom = next(iter(trimesh.load(path_glb).geometry.values()))
    m = trimesh.Trimesh(np.asarray(geom.vertices) * 1000.0, geom.faces, process=False)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    assert m.is_watertight and m.volume == pytest.approx(summary["volume_mm3"], rel=1e-5)
    assert_round_bounds(np.asarray(m.vertices), sj)

    # `saucerfab check --strict`, as a CI pipeline runs it (the GLB a profile does not take: without the printer)
    printed = [path_3mf, *([path_glb] if path_glb.parent == path_3mf.parent else [])]
    rc = main(["check", "--strict", "--printer", key, "--json", *map(str, printed)])
    report = json.loads(capsys.readouterr().out)
    for f in report["files"]:  # --strict: a warning makes the verdict "not printable"
        assert not loud(f["findings"]), (f["path"], f["findings"])
    assert rc == (1 if any(loud(f["findings"]) for f in report["files"]) else 0)
    if path_glb.parent != path_3mf.parent:
        assert main(["check", "--strict", str(path_glb)]) == 0
        capsys.readouterr()


def test_round_export_is_strict_clean_on_every_count(folder: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    _, (path_3mf, _glb) = export(folder, "bureau", tmp_path / "out", capsys)
    assert main(["check", "--strict", "--printer", "bureau", str(path_3mf)]) == 0


def test_make_print_writes_every_format_of_a_round_part(folder: Path, tmp_path: Path) -> None:
    import trimesh

    res = make_print(folder, tmp_path / "print", printer="j55", formats=list(FORMATS), verify=False,
                     options=FabOptions(texture_px=int(ATLAS)))
    assert sorted(res.export.formats) == sorted(FORMATS) and len(res.checks) == len(FORMATS)
    for c in res.checks:
        codes = {f.code for f in c.report.findings if f.severity in ("error", "warning")}
        assert c.report.verdict == "printable" and not codes, (c.name, codes)
    sj = json.loads((res.export.out / "scene.json").read_text())
    for name in ("saucer.stl", "saucer.ply", "saucer.obj"):
        m = trimesh.load(res.export.out / name, force="mesh", process=False)
        m.merge_vertices(merge_tex=True, merge_norm=True)
        assert m.is_watertight and m.volume == pytest.approx(res.export.volume_mm3, rel=1e-5), name
        assert_round_bounds(np.asarray(m.vertices), sj)


def test_a_round_part_too_large_for_the_printer_names_the_round_fix(tmp_path: Path) -> None:
    """A 200 mm round design exported for the HP (190 mm deep): the fix is the design's disc, not the cup."""
    from saucerfab.errors import ExportError

    sc = replace(round_scene(), saucer=disc_saucer(2.0, 32))
    folder = save_design(synthetic_design(sc, resolution=32, texture_size=32, seed=1), tmp_path / "design")
    with pytest.raises(ExportError, match="saucerfab design --printer hp_jf580 makes the round saucer"):
        make_print(folder, tmp_path / "print", printer="hp_jf580", formats=["3mf"], verify=False)
    assert not (tmp_path / "print").exists()
