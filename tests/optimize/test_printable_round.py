"""A round saucer the printer cannot make is refused before any work (issue 44).

Too wide for the printer's build area: refused naming the largest saucer
diameter that fits (the rectangle keeps its message, naming the largest cup).
Seat options wider than the ring around the cup that holds no design:
refused naming the options. The worst-case bounding box of a disc is its
diameter across, whatever the seat.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.model.profiles import load_profile
from saucerfab.model.scene import CUP_RING_MM, Scene, disc_saucer, round_scene
from saucerfab.optimize.printable import preflight, print_target, worst_case_bbox_mm


def small_round(diameter: float = 1.6, n: int = 32) -> Scene:
    return replace(round_scene(), saucer=disc_saucer(diameter, n))


def flat(scene: Scene) -> np.ndarray:
    return np.zeros((scene.saucer.resolution, scene.saucer.resolution))


def small_printer(tmp_path: Path, x: float, y: float, z: float = 150.0) -> Path:
    """A printer profile .toml with a build volume of x * y * z mm."""
    path = tmp_path / "tiny.toml"
    path.write_text(
        f'name = "Tiny"\nbuild_volume_mm = [{x}, {y}, {z}]\nmin_wall_mm = 1.0\nmin_feature_mm = 0.3\ndpi = 300\n'
        'max_texture_px = 4096\naccepted_formats = ["3mf", "glb"]\npreferred_format = "3mf"\n'
    )
    return path


def test_worst_case_bbox_of_a_disc_is_its_diameter() -> None:
    sc = small_round()
    base = flat(sc)
    for seat in ("recess", "ring", "none"):
        o = FabOptions(seat=seat)  # type: ignore[arg-type]
        x, y, z = worst_case_bbox_mm(sc, base, o)
        assert (x, y) == pytest.approx((160.0, 160.0))
        top = max(sc.saucer.delta * sc.mm_per_unit, o.seat_depth_mm if seat != "none" else 0.0)
        bottom = min(-o.base_thickness_mm, -sc.saucer.delta * sc.mm_per_unit - o.min_thickness_mm)
        assert z == pytest.approx(top - bottom)


def test_a_disc_wider_than_the_build_area_is_refused_naming_the_largest(tmp_path: Path) -> None:
    sc = small_round()  # 160 mm across
    for x, y, largest in ((150.0, 300.0, 150), (300.0, 155.5, 155)):
        target = print_target(sc, load_profile(small_printer(tmp_path, x, y)))
        with pytest.raises(ConfigError) as exc:
            preflight(target, sc, flat(sc))
        msg = str(exc.value)
        assert "round saucer is 160 mm across" in msg and "Tiny" in msg
        assert f"--saucer-diameter-mm {largest} or less, or another --printer" in msg
    # just fits: no refusal for its size
    target = print_target(sc, load_profile(small_printer(tmp_path, 160.0, 170.0)))
    preflight(target, sc, flat(sc))


def test_the_bundled_hp_refuses_the_default_round_saucer() -> None:
    sc = round_scene()  # 200 mm: the HP's build area is 190 mm deep
    with pytest.raises(ConfigError, match=r"--saucer-diameter-mm 190 or less, or another --printer"):
        preflight(print_target(sc, "hp_jf580"), sc, flat(sc))


def test_the_rectangle_keeps_its_message(tmp_path: Path) -> None:
    sc = Scene()
    sc = replace(sc, saucer=replace(sc.saucer, resolution=24))
    target = print_target(sc, load_profile(small_printer(tmp_path, 150.0, 150.0)))
    with pytest.raises(ConfigError) as exc:
        preflight(target, sc, flat(sc))
    assert "use --cup-diameter-mm" in str(exc.value) and "saucer-diameter" not in str(exc.value)


def test_seat_options_wider_than_the_ring_are_refused() -> None:
    sc = small_round()
    target = print_target(sc, "j55")
    preflight(target, sc, flat(sc), FabOptions())  # 0.5 + 4 mm: inside the 5 mm ring
    with pytest.raises(ConfigError) as exc:
        preflight(target, sc, flat(sc), FabOptions(seat_rim_mm=CUP_RING_MM))
    msg = str(exc.value)
    assert "ring" in msg and "cover the design" in msg and "--seat-rim-mm" in msg and "--seat-clearance-mm" in msg
    with pytest.raises(ConfigError, match="clearance"):
        preflight(target, sc, flat(sc), FabOptions(seat="none", seat_clearance_mm=CUP_RING_MM + 1))
    # without a rim, the rim's width does not count
    preflight(target, sc, flat(sc), FabOptions(seat="none", seat_rim_mm=10.0))

