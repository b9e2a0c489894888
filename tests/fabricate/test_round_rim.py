"""A round saucer's optional raised rim (issue 44): ``FabOptions.saucer_rim_mm`` and ``saucer_rim_height_mm``.

The rim is a ring at the disc's outer edge, from the part's base to a set
height above the highest relief under it, unioned into the one round part.
The tests build it on the small round design of ``test_round_solid`` (a
160 mm disc, 48 x 48 grid), tilted so the relief under the ring is highest
on one side, and measure it: its top against the relief without the rim,
its inner radius, the part closed and larger. Then the refusals (a
rectangle, a rim reaching the cup's ring, a rim under the printer's minimum
wall) and one ``saucerfab export`` with the option, checked ``--strict`` and
read back by lib3mf.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_fabricate_solid import assert_closed_manifold
from test_round_export import loud, read_3mf_strict
from test_round_export import round_design as printable_round_design
from test_round_solid import centre_of, radius_mm, round_design

from saucerfab.cli import main
from saucerfab.errors import ConfigError, MeshError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.round_solid import CHORD_MM, check_rim, rim_over_picture
from saucerfab.fabricate.solid import Solid, build_solid
from saucerfab.model.design import Design
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.model.heightfield import make_grid
from saucerfab.model.profiles import load_profile
from saucerfab.model.scene import CUP_RING_MM, Scene

WIDTH, HEIGHT = 6.0, 3.0


@pytest.fixture(scope="module")
def design() -> Design:
    """The round design, its relief tilted along x (0.02 units over the disc's radius: 2 mm at 100 mm a unit)."""
    d = round_design()
    xs = np.linspace(*d.scene.saucer.x_range, d.n)
    return replace(d, heights=d.heights + 0.025 * xs[None, :] / d.scene.saucer.radius)


@pytest.fixture(scope="module")
def plain(design: Design) -> Solid:
    return build_solid(design, design.scene.mm_per_unit, FabOptions())


@pytest.fixture(scope="module")
def rimmed(design: Design) -> Solid:
    return build_solid(design, design.scene.mm_per_unit,
                       FabOptions(saucer_rim_mm=WIDTH, saucer_rim_height_mm=HEIGHT))


def radial(s: Solid, points: np.ndarray) -> np.ndarray:
    """(P,) distance of file-frame points (P, >=2) from the cup's axis, mm."""
    c = centre_of(s)
    return np.hypot(points[:, 0] - c[0], points[:, 1] - c[1])


def top_vertices(s: Solid) -> np.ndarray:
    """(K, 3) the vertices of the saucer's top faces (the relief that survives), file mm."""
    return s.vertices[np.unique(s.faces[s.is_top].ravel())]


# --------------------------------------------------------------------------- the rim's shape


def test_the_rims_top_stands_the_asked_height_over_the_relief_under_it(
    design: Design, plain: Solid, rimmed: Solid
) -> None:
    r = radius_mm(design)
    dist = radial(rimmed, rimmed.vertices)
    on_rim = (dist > r - WIDTH + 0.05) & (dist <= r + 1e-5)
    top = rimmed.vertices[on_rim, 2].max()
    # the rim's top is flat: every rim vertex above the relief's own top is at that height
    assert np.allclose(rimmed.vertices[on_rim & (rimmed.vertices[:, 2] > plain.heights.max()), 2], top)
    # the relief under the ring, from the part without a rim: its top vertices in the ring are points of it;
    # the tilt puts its highest point at the disc's edge (+x): its last grid vertex there (the faces beyond
    # it fall to the cut, lower_beyond_edge)
    relief = top_vertices(plain)
    d = radial(plain, relief)
    in_ring = (d >= r - WIDTH) & (d <= r + 1e-5)
    under = relief[in_ring, 2].max()
    step = float(plain.grid_x[1] - plain.grid_x[0])
    assert relief[in_ring][np.argmax(relief[in_ring, 2]), 0] > centre_of(plain)[0] + r - step - 1e-6
    assert under > relief[:, 2].min() + 1.0
    assert top == pytest.approx(under + HEIGHT, abs=1e-5)  # the coordinates' rounding


def test_the_rims_inside_is_the_circle_of_radius_less_width(design: Design, rimmed: Solid) -> None:
    r = radius_mm(design)
    tri = rimmed.vertices[rimmed.faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    cen = tri.mean(axis=1)
    inside = (np.abs(nrm[:, 2]) < 1e-6) & (np.abs(radial(rimmed, cen) - (r - WIDTH)) < 1.0)
    assert inside.sum() >= 64
    # the wall faces the axis (its normal points inwards) and every vertex of it is on the circle, or on a
    # chord between two, within the chord error
    c = centre_of(rimmed)
    assert (np.einsum("ij,ij->i", nrm[inside, :2], cen[inside, :2] - c[:2]) < 0).all()
    wall_d = radial(rimmed, rimmed.vertices[np.unique(rimmed.faces[inside].ravel())])
    assert wall_d.max() <= r - WIDTH + 1e-5 and wall_d.min() >= r - WIDTH - CHORD_MM - 1e-5
    # the rim's faces are sides, never top: the bake paints them with the sides' colours
    assert not rimmed.is_top[inside].any()
    assert not rimmed.is_top[radial(rimmed, cen) > r - WIDTH + 0.01].any()
    # the relief inside the ring is untouched: the same top heights there
    far = top_vertices(rimmed)
    assert radial(rimmed, far).max() <= r - WIDTH + 1e-5


def test_the_rimmed_part_is_one_closed_body_larger_than_without(plain: Solid, rimmed: Solid) -> None:
    import trimesh

    assert_closed_manifold(rimmed)
    m = trimesh.Trimesh(rimmed.vertices, rimmed.faces, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.body_count == 1
    assert m.volume == pytest.approx(rimmed.volume_mm3, rel=1e-9)
    assert rimmed.volume_mm3 > plain.volume_mm3 + 1000.0  # a 6 mm ring round a 160 mm disc, mm above the relief
    # the same disc, seat and base: only the height grows
    assert rimmed.bbox_mm[:2] == pytest.approx(plain.bbox_mm[:2], abs=1e-9)
    assert rimmed.bottom_z == plain.bottom_z and rimmed.seat.center_xy == plain.seat.center_xy
    assert rimmed.seat.floor_z == plain.seat.floor_z and np.array_equal(rimmed.seat.pocket, plain.seat.pocket)
    assert rimmed.bbox_mm[2] > plain.bbox_mm[2]


def test_without_a_rim_nothing_changes(design: Design, plain: Solid) -> None:
    again = build_solid(design, design.scene.mm_per_unit, FabOptions(saucer_rim_mm=0.0, saucer_rim_height_mm=9.0))
    assert np.array_equal(again.vertices, plain.vertices) and np.array_equal(again.faces, plain.faces)
    # and the options record no rim: an export.json reads as before the rim existed
    assert "saucer_rim_mm" not in FabOptions().to_dict() and "saucer_rim_height_mm" not in FabOptions().to_dict()
    d = FabOptions(saucer_rim_mm=WIDTH).to_dict()
    assert d["saucer_rim_mm"] == WIDTH and d["saucer_rim_height_mm"] == FabOptions().saucer_rim_height_mm


def test_a_rim_over_the_direct_picture_is_warned_of(design: Design) -> None:
    s = design.scene.mm_per_unit
    g = make_grid(design.scene.saucer)
    # a direct frame aimed at the middle of the disc's front half: its picture stays about 9 mm off the edge
    sc = replace(design.scene, direct=replace(design.scene.direct, target=(0.0, 0.4, -0.8), viewing_angle_deg=1.2))

    def warning(width: float) -> str | None:
        return rim_over_picture(sc, s, FabOptions(saucer_rim_mm=width), g.xs * s, g.ys * s, design.heights * s)

    assert warning(6.0) is None and rim_over_picture(sc, s, FabOptions(), g.xs * s, g.ys * s, design.heights * s) \
        is None
    msg = warning(20.0)
    assert msg is not None and "covers part of it" in msg and "--saucer-rim-mm" in msg
    gap = float(re.search(r"within ([0-9.]+) mm", msg).group(1))
    assert 6.0 < gap < 20.0
    assert warning(gap - 0.1) is None and warning(gap + 0.1) is not None  # the gap named is where it begins
    # the export lists it among its warnings
    solid = build_solid(replace(design, scene=sc), s, FabOptions(saucer_rim_mm=20.0))
    assert solid.warnings == (msg,)


# --------------------------------------------------------------------------- refusals


@pytest.mark.parametrize(("key", "value", "words"), [
    ("saucer_rim_mm", -1.0, "saucer_rim_mm must be non-negative"),
    ("saucer_rim_mm", float("nan"), "saucer_rim_mm must be a finite number"),
    ("saucer_rim_height_mm", 0.0, "saucer_rim_height_mm must be positive"),
])
def test_bad_rim_options_are_refused(key: str, value: float, words: str) -> None:
    with pytest.raises(ConfigError, match=words):
        FabOptions(**{key: value})


def test_a_rim_on_a_rectangle_is_refused() -> None:
    d = synthetic_design(Scene(), resolution=12, texture_size=16)
    with pytest.raises(ConfigError) as exc:
        build_solid(d, d.scene.mm_per_unit, FabOptions(saucer_rim_mm=3.0))
    assert "--saucer-rim-mm 3" in str(exc.value) and "rectangle" in str(exc.value)
    assert "--scene round" in str(exc.value)
    check_rim(d.scene, d.scene.mm_per_unit, FabOptions())  # no rim: nothing to refuse


def test_a_rim_reaching_the_cups_ring_is_refused_naming_the_largest(design: Design) -> None:
    s = design.scene.mm_per_unit
    r = radius_mm(design)
    reach = design.scene.cup.circumradius * s
    room = r - reach - CUP_RING_MM  # 80 - 40 - 5 = 35 mm
    with pytest.raises(ConfigError) as exc:
        check_rim(design.scene, s, FabOptions(saucer_rim_mm=room))
    msg = str(exc.value)
    largest = math.floor(room * 100 - 1e-6) / 100
    assert "too wide" in msg and f"--saucer-rim-mm {largest:g} or less" in msg and "ring" in msg
    with pytest.raises(ConfigError, match="too wide"):
        build_solid(design, s, FabOptions(saucer_rim_mm=room + 10.0))
    check_rim(design.scene, s, FabOptions(saucer_rim_mm=largest))  # the largest named is taken


def test_a_rim_under_the_minimum_wall_is_a_problem(design: Design) -> None:
    thin = FabOptions(saucer_rim_mm=0.6)
    assert thin.walls_under(1.0) == ["saucer_rim_mm (the round saucer's raised rim) = 0.6 mm is below the "
                                     "minimum wall 1 mm"]
    assert FabOptions(saucer_rim_mm=1.0).walls_under(1.0) == [] and FabOptions().walls_under(1.0) == []
    j55 = load_profile("j55")  # a 1 mm wall, thin_policy warn
    assert j55.min_wall_mm == 1.0
    s = build_solid(design, design.scene.mm_per_unit, thin, j55)
    assert any("saucer_rim_mm" in w and "minimum wall" in w for w in s.warnings), s.warnings
    with pytest.raises(MeshError, match="saucer_rim_mm"):
        build_solid(design, design.scene.mm_per_unit, thin, replace(j55, thin_policy="refuse"))


# --------------------------------------------------------------------------- the CLI


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_design(printable_round_design(), tmp_path_factory.mktemp("rim") / "design")


def test_export_with_a_rim_checks_strict_and_reads_back(folder: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    import trimesh

    out = tmp_path / "out"
    rc = main(["export", str(folder), "--printer", "j55", "--formats", "3mf,glb", "--texture-px", "4096",
               "--saucer-rim-mm", "5", "--saucer-rim-height-mm", "2.5", "--no-verify", "--json", "-q",
               "-o", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    summary = json.loads(captured.out)
    # the synthetic design's direct frame (the paper's, aimed under the cup) reaches the disc's front edge
    assert len(summary["warnings"]) == 1 and "covers part of it" in summary["warnings"][0], summary["warnings"]
    for c in summary["checks"]:
        assert c["verdict"] == "printable" and not loud(c["findings"]), (c["path"], c["findings"])
    opts = json.loads((out / "export.json").read_text())["options"]
    assert opts["saucer_rim_mm"] == 5.0 and opts["saucer_rim_height_mm"] == 2.5
    assert main(["check", "--strict", "--printer", "j55", str(out / "saucer.3mf"), str(out / "saucer.glb")]) == 0
    capsys.readouterr()
    verts, tris = read_3mf_strict(out / "saucer.3mf")
    assert tris.shape[0] == summary["triangles"]
    m = trimesh.Trimesh(verts, tris, process=False)
    assert m.is_watertight and m.body_count == 1
    assert m.volume == pytest.approx(summary["volume_mm3"], rel=1e-5)
    # the rim: the part's highest points are at its edge, 5 mm wide
    c = 0.5 * (verts.max(axis=0) + verts.min(axis=0))
    d = np.hypot(verts[:, 0] - c[0], verts[:, 1] - c[1])
    high = d[verts[:, 2] > verts[:, 2].max() - 1e-6]
    assert high.min() == pytest.approx(80.0 - 5.0, abs=0.02) and high.max() == pytest.approx(80.0, abs=0.02)


@pytest.mark.parametrize(("extra", "words"), [
    (["--saucer-rim-height-mm", "2"], "no rim was asked for"),
    (["--saucer-rim-mm", "40"], "too wide"),
])
def test_export_refuses_contradictory_rim_options_before_writing(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], words: str
) -> None:
    out = tmp_path / "out"
    rc = main(["export", str(folder), "--formats", "3mf", "--no-verify", "-q", "-o", str(out), *extra])
    assert rc == 2 and words in capsys.readouterr().err
    assert not (out / "saucer.3mf").exists() and not (out / "export.json").exists()


def test_export_refuses_a_rim_on_a_rectangle(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = synthetic_design(Scene(), resolution=12, texture_size=16)
    folder = save_design(d, tmp_path / "design")
    rc = main(["export", str(folder), "--formats", "3mf", "--no-verify", "-q", "--saucer-rim-mm", "3",
               "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "rectangle" in err and "--saucer-rim-mm" in err
    assert not (tmp_path / "out" / "export.json").exists()
