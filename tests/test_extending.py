"""Adding a cup shape, a file format or an energy term touches what CONTRIBUTING.md says, and no more.

Each test follows one recipe of CONTRIBUTING.md ("How to add ...") and
then runs the product on what it added:

* a cup shape: a class registered in ``cups.CUP_CLASSES`` (in-process:
  every user looks the table up when it runs);
* a file format: one row in ``formats.TABLE`` plus its new writer and
  reader modules, in a copy of the package (the table is read when the
  package is imported), then an export and a check in a fresh process;
* an energy term: one declaration in ``optimize/energies.py`` and one
  ablation in ``optimize/stages.py``, in a copy of the package, then a
  tiny design in a fresh process.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
import pytest

from saucerfab.model import cups
from saucerfab.model.reflection import reference_facets, reflect_facets
from saucerfab.model.validate import check_positive

PACKAGE = Path(__file__).resolve().parents[1] / "saucerfab"
SAMPLES = PACKAGE.parent / "samples"


# --------------------------------------------------------------------------- a cup shape


@dataclass(frozen=True)
class RectangleCup:
    """A rectangular mirror box (four plane mirrors): the recipe's new class, written here as a user would."""

    width: float = 0.8
    depth: float = 0.6
    height: float = 1.0
    kind: Literal["rectangle"] = field(default="rectangle", init=False)

    faceted: ClassVar[bool] = True
    spec_usage: ClassVar[str] = "rectangle:W,D"
    spec_arity: ClassVar[tuple[int, int]] = (2, 2)

    def __post_init__(self) -> None:
        check_positive("cup width", self.width)
        check_positive("cup depth", self.depth)
        check_positive("cup height", self.height)

    @classmethod
    def from_spec(cls, nums: list[float], spec: str) -> RectangleCup:
        return cls(width=nums[0], depth=nums[1])

    @property
    def circumradius(self) -> float:
        return math.hypot(self.width, self.depth) / 2

    @property
    def inradius(self) -> float:
        return min(self.width, self.depth) / 2

    @property
    def width_units(self) -> float:
        return self.width

    def boundary(self, segments: int = 0) -> np.ndarray:
        w, d = self.width / 2, self.depth / 2
        return np.array([[w, -d], [w, d], [-w, d], [-w, -d]])  # counter-clockwise

    def wall(self, segments: int = 0) -> np.ndarray:
        c = self.boundary()
        ends = np.stack([c, np.roll(c, -1, axis=0)], axis=1)
        edge = ends[:, 1] - ends[:, 0]
        normal = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / np.linalg.norm(edge, axis=1, keepdims=True)
        return np.concatenate([ends, np.repeat(normal[:, None], 2, axis=1)], axis=2)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        return (np.abs(xy[..., 0]) < self.width / 2) & (np.abs(xy[..., 1]) < self.depth / 2)

    def reflect(self, camera: tuple[float, float, float], xy: np.ndarray) -> list[Any]:
        return reflect_facets(self.boundary(), camera, xy)

    def reflect_reference(self, camera: tuple[float, float, float], q_xy: tuple[float, float]) -> Any:
        return reference_facets(self.boundary(), camera, q_xy)

    def file_fields(self, to_mm: Any) -> dict[str, Any]:
        return {"width": to_mm(self.width), "depth": to_mm(self.depth)}


def test_a_cup_shape_is_one_class_in_the_table(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from dataclasses import replace

    from saucerfab.fabricate.scene_json import viewing_dict
    from saucerfab.model.cups import parse_cup_spec
    from saucerfab.model.mirror import reflect, reflect_point_reference
    from saucerfab.model.scene import load_scene, paper_scene, scene_to_toml
    from saucerfab.pages.viewer import _cup_wall
    from saucerfab.verify.printfolder import load_print_scene

    monkeypatch.setitem(cups.CUP_CLASSES, "rectangle", RectangleCup)
    cup = parse_cup_spec("rectangle:0.8,0.5")
    assert cup == RectangleCup(0.8, 0.5)
    scene = replace(paper_scene(), cup=cup)
    # the scene file round trip
    toml = tmp_path / "scene.toml"
    toml.write_text(scene_to_toml(scene))
    assert load_scene(toml) == scene
    # the reflection in its facets, against the slow reference, for points across the saucer
    xy = np.array([[-0.3, -1.2], [0.0, -0.9], [0.25, -0.6], [0.45, -0.55]])
    pieces = {pc.facet: pc for pc in reflect(scene, xy)}
    seen = 0
    for i, q in enumerate(xy):
        ref = {k: r for k, _, r, _ in reflect_point_reference(scene.cup, scene.camera, q)}
        assert {k for k, pc in pieces.items() if pc.valid_xy[i]} == set(ref)
        for k, r in ref.items():
            np.testing.assert_allclose(pieces[k].r_xy[i], r, atol=1e-10)
            seen += 1
    assert seen >= 3  # every point but the far corner one is seen in the front facet
    # scene.json: written by the export, read back by verify, drawn by the 3D viewer
    s = scene.mm_per_unit
    doc = viewing_dict(scene, np.diag([s, s, s, 1.0]))
    assert doc["cup"]["shape"] == "rectangle" and doc["cup"]["width"] == pytest.approx(s * 0.8)
    doc["saucer"] = {"x_range": [-0.5 * s, 0.5 * s], "y_range": [-1.5 * s, -0.5 * s]}
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    back = load_print_scene(tmp_path)
    assert back.cup.shape == "rectangle" and back.cup.width_mm == pytest.approx(doc["cup"]["width"])
    assert _cup_wall(back.cup).shape == (4, 2, 4)


# --------------------------------------------------------------------------- a file format and an energy term


def _copy_package(tmp_path: Path) -> Path:
    """A copy of the package (numba caches and their sources' times kept, so nothing compiles again)."""
    root = tmp_path / "src"
    shutil.copytree(PACKAGE, root / "saucerfab", ignore=shutil.ignore_patterns("*.pyc"))
    return root


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{path.name} no longer has {old!r}: update this test with the recipe"
    path.write_text(text.replace(old, new))


def _run(root: Path, code: str, cwd: Path, timeout: int = 600) -> str:
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def _changed(root: Path) -> set[str]:
    """The package's existing modules the copy changed."""
    return {
        str(p.relative_to(root / "saucerfab"))
        for p in (root / "saucerfab").rglob("*.py")
        if (PACKAGE / p.relative_to(root / "saucerfab")).is_file()
        and p.read_bytes() != (PACKAGE / p.relative_to(root / "saucerfab")).read_bytes()
    }


OFF_WRITER = '''
def write_off(mesh, options=None):
    lines = ["OFF", f"{len(mesh.vertices)} {len(mesh.faces)} 0"]
    lines += [" ".join(f"{x:.6f}" for x in v) for v in mesh.vertices]
    lines += ["3 " + " ".join(str(int(i)) for i in f) for f in mesh.faces]
    return {f"{mesh.name}.off": ("\\n".join(lines) + "\\n").encode()}
'''

OFF_READER = '''
import numpy as np
from saucerfab.check.meshdata import MeshBuilder
from saucerfab.check.readers.safe import ReadError


def read_off(path, data, limits, res=None):
    words = data.decode("ascii").split()
    if not words or words[0] != "OFF":
        raise ReadError("not an OFF file")
    nv, nf = int(words[1]), int(words[2])
    b = MeshBuilder("off", limits)
    b.reserve(nv, nf, "the OFF header")
    v = np.array(words[4:4 + 3 * nv], float).reshape(nv, 3)
    f = np.array(words[4 + 3 * nv:], np.int64).reshape(nf, 4)[:, 1:]
    b.add(v, f, what="OFF")
    return b.build(units="millimeter (assumed)")
'''


def test_a_file_format_is_one_row_and_its_own_modules(tmp_path: Path) -> None:
    root = _copy_package(tmp_path)
    (root / "saucerfab" / "fabricate" / "export_off.py").write_text(OFF_WRITER)
    (root / "saucerfab" / "check" / "readers" / "off.py").write_text(OFF_READER)
    _edit(
        root / "saucerfab" / "files" / "formats.py",
        '    Format("stl", "STL",',
        '    Format("off", "OFF", "Object File Format, no colour", (".off",),\n'
        '           writer=f"{_FAB}.export_off:write_off", reader=f"{_READ}.off:read_off", magic=(b"OFF",)),\n'
        '    Format("stl", "STL",',
    )
    assert _changed(root) == {"files/formats.py"}
    out = _run(root, """
import numpy as np
from pathlib import Path
from saucerfab.check import check_mesh
from saucerfab.cli import main
from saucerfab.fabricate.registry import render
from saucerfab.fabricate.textured import TexturedMesh
from saucerfab.files.imageio import png_bytes
v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float)
f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
mesh = TexturedMesh(name="tet", vertices=v, faces=f, uvs=np.zeros((1, 2)), face_uvs=np.zeros((4, 3), np.int64),
                    texture_png=png_bytes(np.zeros((8, 8, 3), np.uint8)), texture_px=8,
                    vertex_rgb=np.zeros((4, 3), np.uint8))
files = render(mesh, "off", None)
Path("tet.off").write_bytes(files["tet.off"])
Path("tet.bin").write_bytes(files["tet.off"])  # found by its magic bytes whatever its name
for name in ("tet.off", "tet.bin"):
    r = check_mesh(name)
    print(name, r.format, r.stats["triangles"], r.verdict)
main(["export", "--help"])
""", tmp_path)
    assert "tet.off off 4 printable" in out and "tet.bin off 4 printable" in out, out
    assert re.search(r"comma-separated: [^\n]*\boff\b", out), out  # the export's help lists it


def test_an_energy_term_is_one_declaration_and_one_stage(tmp_path: Path) -> None:
    root = _copy_package(tmp_path)
    energies = root / "saucerfab" / "optimize" / "energies.py"
    _edit(
        energies,
        '    Term("sparse",',
        '    Term("pull", (Weight("w_pull", "E_pull weight", rho_factor=0.1),),\n'
        '         lambda p: (lambda h, c: ((h - p.z) ** 2).sum())),\n'
        '    Term("sparse",',
    )
    _edit(
        root / "saucerfab" / "optimize" / "stages.py",
        '    # (f) the paper',
        '    "laplacian_pull": _lap("bw", "enhanced") + [StageSpec("pull", "enhanced", SIGMA_LARGE, "pull", "w_pull")],\n'
        '    # (f) the paper',
    )
    assert _changed(root) == {"optimize/energies.py", "optimize/stages.py"}
    out_dir = tmp_path / "design"
    _run(root, f"""
from saucerfab.cli import main
rc = main(["design", "--direct", {str(SAMPLES / "direct_heart.png")!r}, "--reflected", {str(SAMPLES / "reflected_star.png")!r},
           "--ablation", "laplacian_pull", "--w-pull", "0.5", "--resolution", "8", "--image-size", "16",
           "--max-iters", "2", "--no-verify", "--no-times", "-q", "-o", {str(out_dir)!r}])
raise SystemExit(rc)
""", tmp_path)
    meta = json.loads((out_dir / "design.json").read_text())
    last = meta["metrics"]["stages"][-1]
    assert last["regulariser"] == "pull" and last["weight"] == 0.5
    assert meta["parameters"]["w_pull"] == 0.5 and "E_pull" in last
    log = [json.loads(line) for line in (out_dir / "energy_log.jsonl").read_text().splitlines()]
    assert all("E_pull" in entry for entry in log)
