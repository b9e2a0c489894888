"""A cup size whose seat cannot be printed is refused by design, with the smallest that works (issue 42).

Item 3: the seat's wall between the cup's pocket and the saucer is the scene's
gap (it grows with the cup) less the clearance (it does not); design refuses a
size whose wall is under the printer's minimum, before any work, and names the
smallest size at which the export's wall reaches it. Item 5: the design's
verdict on the seat's walls and the export's come from one function
(:func:`saucerfab.fabricate.seat.seat_wall`), and the export no longer runs the
seat plate down the saucer's sides as a sliver the design warned of.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from saucerfab.check import check_mesh
from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.seat import seat_wall
from saucerfab.fabricate.solid import Solid, build_solid
from saucerfab.model.cups import parse_cup_spec
from saucerfab.model.design import Design
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.profiles import load_profile
from saucerfab.model.scene import Scene
from saucerfab.optimize.printable import preflight, print_target

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def scene_at(cup: str, cup_mm: float, n: int = 24) -> Scene:
    """The paper's scene with ``cup`` (a --cup spec) at ``cup_mm``, an ``n`` x ``n`` grid."""
    s = Scene()
    return replace(s, cup=parse_cup_spec(cup), saucer=replace(s.saucer, resolution=n), cup_diameter_mm=cup_mm)


def design_at(cup: str, cup_mm: float) -> Design:
    return synthetic_design(scene_at(cup, cup_mm), resolution=24, texture_size=16, seed=2)


def design_verdict(d: Design, printer: str = "j55") -> bool:
    """Whether design's preflight finds the seat's walls too thin (refused, or a note of thin walls)."""
    try:
        notes = preflight(print_target(d.scene, printer), d.scene, d.base_heights)
    except ConfigError as exc:
        return "seat" in str(exc)
    return any("thin" in n or "sliver" in n for n in notes)


def export_solid(d: Design, printer: str = "j55") -> Solid:
    return build_solid(d, d.scene.mm_per_unit, FabOptions(), load_profile(printer))


def export_verdict(s: Solid) -> bool:
    """Whether the export's own rule finds the seat's walls too thin (a warning under a warn profile)."""
    return any("seat" in w and "minimum wall" in w for w in s.warnings)


def test_design_refuses_a_5_mm_cup_and_names_the_smallest_that_works(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "d"
    code = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected",
                 str(SAMPLES / "reflected_star.png"), "--cup-diameter-mm", "5", "--resolution", "24",
                 "--image-size", "64", "--max-iters", "1", "--no-verify", "-q", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "Traceback" not in err
    # the paper's cup (radius 0.4) stands 0.1 units from the saucer: 0.625 mm at 5 mm, less 0.5 mm clearance
    assert "seat's wall between the cup's pocket and the saucer is 0.12 mm" in err
    assert "minimum wall 1 mm" in err
    smallest = int(re.search(r"--cup-diameter-mm (\d+) or more", err).group(1))  # type: ignore[union-attr]
    assert smallest == 12  # (1 mm wall + 0.5 mm clearance) / 0.1 units = 15 mm per unit: a 12 mm cup


@pytest.mark.parametrize("printer, smallest", [("j55", 12), ("bureau", 20)])
def test_the_named_size_is_the_smallest_the_export_prints(printer: str, smallest: int) -> None:
    prof = load_profile(printer)
    for cup_mm, ok in ((smallest - 1, False), (smallest, True), (80, True)):
        d = design_at("circle", cup_mm)
        if ok:
            preflight(print_target(d.scene, printer), d.scene, d.base_heights)
        else:
            with pytest.raises(ConfigError, match=f"--cup-diameter-mm {smallest} or more"):
                preflight(print_target(d.scene, printer), d.scene, d.base_heights)
        sw = seat_wall(d.scene, d.scene.mm_per_unit, FabOptions(), prof.min_wall_mm)
        assert sw is not None and sw.thin is (not ok) and sw.smallest_cup_mm == smallest
    # at the smallest size the exported seat's wall, as the checker measures it, is the printer's minimum
    s = seat_wall(scene_at("circle", smallest), smallest / 0.8, FabOptions(), prof.min_wall_mm)
    assert s is not None and prof.min_wall_mm <= s.thickness_mm < prof.min_wall_mm + 0.1


def checked(s: Solid, tmp_path: Path, printer: str = "j55"):  # -> saucerfab.check.Report
    p = tmp_path / "solid.stl"
    trimesh.Trimesh(s.vertices, s.faces, process=False).export(p)
    return check_mesh(p, printer=printer)


@pytest.mark.parametrize("cup, cup_mm", [("prism:6", 80.0), ("circle", 80.0), ("prism:6", 10.0), ("circle", 10.0)])
def test_design_and_export_agree_on_the_seats_walls(cup: str, cup_mm: float) -> None:
    d = design_at(cup, cup_mm)
    assert design_verdict(d) == export_verdict(export_solid(d)) == (cup_mm < 12)


@pytest.mark.parametrize("cup", ["prism:6", "circle"])
def test_at_80_mm_the_seat_has_no_wall_under_the_minimum(cup: str, tmp_path: Path) -> None:
    """The 80 mm prism:6 cup's grown footprint reaches 0.06 mm past the paper saucer's sides.

    Its seat plate used to run down them as a sliver 0.04-0.06 mm thick (the
    design warned "exports will warn of thin walls"; the export did not): it
    now ends at the saucer's near edge. Nothing of the part lies beside the
    saucer, and the checker finds no wall under the J55's 1 mm.
    """
    d = design_at(cup, 80.0)
    s = export_solid(d)
    (x0, x1), (_, y1) = s.footprint
    centres = s.vertices[s.faces].mean(axis=1)
    beside = centres[centres[:, 1] < y1 - 1e-6]  # faces in front of the saucer's near edge
    assert beside[:, 0].min() >= x0 - 1e-6 and beside[:, 0].max() <= x1 + 1e-6
    r = checked(s, tmp_path)
    assert "thin_walls" not in r.codes and r.stats["min_wall_mm"] >= 1.0
    assert not design_verdict(d) and not export_verdict(s)


def test_where_the_seat_is_thin_the_checker_measures_what_the_rule_says(tmp_path: Path) -> None:
    # 10 mm: 12.5 mm per unit, the wall is 1.25 - 0.5 = 0.75 mm (and the few micrometres by which the
    # export's polygon of the circle stands inside it)
    d = design_at("circle", 10.0)
    sw = seat_wall(d.scene, d.scene.mm_per_unit, FabOptions(), 1.0)
    assert sw is not None and sw.thickness_mm == pytest.approx(0.75, abs=0.005)
    r = checked(export_solid(d), tmp_path)
    assert r.stats["min_wall_mm"] == pytest.approx(0.75, abs=0.02)
    assert np.isfinite(r.stats["thin_wall_fraction"])


@pytest.mark.parametrize("seat", ["recess", "ring"])
@pytest.mark.parametrize("x_range, y_range", [((-0.5, 0.5), (-1.5, -0.5)), ((-0.5, 0.5), (0.5, 1.5)),
                                              ((0.5, 1.5), (-0.5, 0.5)), ((-1.5, -0.5), (-0.5, 0.5))])
def test_the_seat_stops_at_the_saucer_whichever_side_it_lies(seat: str, x_range: tuple, y_range: tuple) -> None:
    # a 20 mm cup: the grown cup (14.5 mm) reaches 2 mm past the saucer's sides (12.5 mm) on every layout
    s0 = Scene()
    saucer = replace(s0.saucer, x_range=x_range, y_range=y_range, resolution=16)
    scene = replace(s0, saucer=saucer, cup_diameter_mm=20.0)
    d = synthetic_design(scene, resolution=16, texture_size=16)
    s = build_solid(d, scene.mm_per_unit, FabOptions(seat=seat))  # type: ignore[arg-type]
    m = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert m.is_watertight and m.body_count == 1
    (x0, x1), (y0, y1) = s.footprint
    # faces beside the saucer: within its span along one axis, outside it along the other (the sliver's
    # corners lie on the saucer's far corners and on the cup's side, its faces beside the saucer)
    v, eps = s.vertices[s.faces].mean(axis=1), 1e-6
    cx, cy = s.seat.center_xy
    along_x = (v[:, 0] > x0 + eps) & (v[:, 0] < x1 - eps)
    along_y = (v[:, 1] > y0 + eps) & (v[:, 1] < y1 - eps)
    if x0 <= cx <= x1:  # the cup stands in front of or behind the saucer: nothing left or right of it
        assert not (along_y & ((v[:, 0] < x0 - eps) | (v[:, 0] > x1 + eps))).any()
    else:
        assert not (along_x & ((v[:, 1] < y0 - eps) | (v[:, 1] > y1 + eps))).any()
