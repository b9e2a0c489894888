"""Verify reads a round print's top: the relief on the disc, not the cup's pocket floor or its rim (issue 44)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from saucerfab.fabricate.scene_file import read_scene_file
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.model.scene import CUP_RING_MM, disc_saucer, round_scene
from saucerfab.verify.printfolder import read_surface
from saucerfab.workflow import make_print


def test_the_round_prints_top_is_the_relief_around_the_seat(tmp_path: Path) -> None:
    scene = replace(round_scene(), saucer=disc_saucer(1.6, 40))
    folder = save_design(synthetic_design(scene, resolution=40, texture_size=64, seed=2), tmp_path / "design")
    res = make_print(folder, tmp_path / "print", printer="j55", formats=["obj"], verify=False, check=False)
    sc = read_scene_file(res.export.out / "scene.json")
    surface = read_surface(res.export.out / "saucer.obj", "obj", sc)
    tri = surface.vertices[surface.faces]
    centre = tri.mean(axis=1)
    r_cup = np.hypot(*(centre[:, :2] - np.asarray(sc.cup.center)).T)
    top = surface.top
    radius = 0.5 * sc.saucer_diameter
    # every top face lies on the disc and outside the cup's ring; the seat's flat floor is not top
    assert top.any() and (r_cup[top] <= radius + 1e-6).all()
    assert (r_cup[top] > 0.5 * sc.cup.width_mm + CUP_RING_MM - 0.5).all()
    floor = (np.abs(centre[:, 2] - sc.cup.bottom_z) < 1e-3) & (r_cup < 0.5 * sc.cup.width_mm)
    assert floor.any() and not (floor & top).any()
