"""Two reflected images with a prism cup (paper, section 4, Figures 17 and 19)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage
from test_mirror import CIRCLE, HEXAGON, WavySaucer, ray_trace, saucer_xy, scene_with

from saucerfab.errors import ConfigError
from saucerfab.model import mirror
from saucerfab.model.camera import Camera
from saucerfab.model.cups import PrismCup
from saucerfab.model.heightfield import base_shape, make_grid
from saucerfab.model.mirror import visible_region
from saucerfab.model.scene import ViewFrame, load_scene
from saucerfab.optimize.framing import fit_frames
from saucerfab.optimize.regions import (
    best_placement,
    facet_groups_overlap,
    placement_options,
    region_report,
    split_reflected_facets,
)

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def prism_scene(n: int = 48):
    scene = load_scene(SAMPLES / "scene_prism.toml")
    return replace(scene, saucer=replace(scene.saucer, resolution=n))


def test_region_split_matches_a_brute_force_ray_trace() -> None:
    n = 48
    scene = prism_scene(n)
    heights = WavySaucer(scene.saucer, n).h  # the surface the ray tracer hits
    groups = split_reflected_facets(scene, heights)
    # a reflected frame that sees both facet regions whole
    scene = fit_frames(scene, heights, "cover")
    _, _, q, facet = ray_trace(scene, stride=2)
    grid = make_grid(scene.saucer)
    dx, dy = grid.spacing
    j = np.clip(np.rint((q[:, 0] - grid.xs[0]) / dx).astype(int), 0, n - 1)
    i = np.clip(np.rint((q[:, 1] - grid.ys[0]) / dy).astype(int), 0, n - 1)
    for g in groups:
        traced = np.zeros((n, n), bool)
        sel = np.isin(facet, g)
        traced[i[sel], j[sel]] = True
        region = visible_region(scene, n, heights, facets=list(g), in_frame=False)
        assert traced.sum() > 30 and region.sum() > 30
        # every traced landing is in the module's region (up to one grid cell
        # at the region's rim, where the nearest sample may fall outside)
        grown = ndimage.binary_dilation(region, iterations=1)
        assert (traced & ~grown).sum() == 0
        # and the traced landings cover the region's interior
        inner = ndimage.binary_erosion(region, iterations=2)
        near_trace = ndimage.binary_dilation(traced, iterations=2)
        assert (inner & ~near_trace).sum() <= 0.02 * inner.sum()
    # the two groups' regions hardly overlap
    rep = region_report(scene, heights)
    assert rep.overlap < 0.05
    assert min(rep.area_fraction) > 0.05


def test_placement_options_and_the_choice() -> None:
    scene = prism_scene()
    opts = placement_options(scene)
    assert set(opts) == {"vertex_to_viewer", "facet_to_viewer"}
    diff = (opts["facet_to_viewer"].rotation_deg - opts["vertex_to_viewer"].rotation_deg) % 360
    assert diff == pytest.approx(180 / 6)
    chosen, name, reports = best_placement(scene)
    assert name in reports
    assert chosen.cup.rotation_deg == opts[name].rotation_deg
    assert all(reports[name].overlap <= r.overlap + 0.01 for r in reports.values())


# --------------------------------------------------------------------------- the facet split (moved from test_mirror.py with the code)


def test_split_reflected_facets_for_two_images() -> None:
    wide = ViewFrame((0.0, 0.0, 0.1), 15.0, 64)
    # a corner towards the viewer; the chain wrapping past facet 0; a chain of three
    for cup in (PrismCup(6, 0.45, 30.0), PrismCup(5, 0.45, -90.0), PrismCup(10, 0.45, 0.0)):
        scene = scene_with(cup, reflected=wide)
        heights = base_shape("waves", 24)
        groups = split_reflected_facets(scene, heights)
        assert len(groups) == 2 and all(groups)
        seen = [pc.facet for pc in mirror.reflect(scene, saucer_xy(scene, 4))]
        flat = groups[0] + groups[1]
        assert sorted(flat) == sorted(k for k in seen if mirror.visible_region(scene, None, heights, facets=[k]).any())
        # the chain runs left to right for the viewer: facet midpoints' image x increases
        verts, edges, _ = mirror.prism_facets(cup)
        cam = Camera.from_scene(scene, "reflected")
        mid_x = [float(cam.project(np.array([*(verts[k] + 0.5 * edges[k]), 0.5]))[0]) for k in flat]
        assert mid_x == sorted(mid_x)
        # no other cut of the chain overlaps less (brute force over the cuts)
        regions = [mirror.visible_region(scene, None, heights, facets=[k]) for k in flat]
        overlaps = []
        for cut in range(1, len(flat)):
            a = np.logical_or.reduce(regions[:cut])
            b = np.logical_or.reduce(regions[cut:])
            overlaps.append(int((a & b).sum()))
        a = np.logical_or.reduce(regions[: len(groups[0])])
        b = np.logical_or.reduce(regions[len(groups[0]) :])
        assert int((a & b).sum()) == min(overlaps)
        if cup.sides == 10:
            assert len(flat) == 3
        if cup.sides == 5:
            assert groups == [[4], [0]]
        fa, fb, both = facet_groups_overlap(scene, groups, heights)
        assert (fa, fb, both) == pytest.approx((a.mean(), b.mean(), (a & b).mean()))
        assert fa > 0 and fb > 0


def test_split_reflected_facets_errors() -> None:
    with pytest.raises(ConfigError, match="only a prism"):
        split_reflected_facets(scene_with(CIRCLE))
    # a flat facet faces the camera and the paper's narrow frame shows only it
    with pytest.raises(ConfigError, match="only 1 facet"):
        split_reflected_facets(scene_with(PrismCup(6, 0.45, 0.0)))
    with pytest.raises(ConfigError, match="two facet groups"):
        facet_groups_overlap(scene_with(HEXAGON), [[3]])


def _fg(img: np.ndarray, bg: np.ndarray) -> np.ndarray:
    return np.abs(img - bg).max(axis=-1) > 0.25


def test_two_reflection_design_shows_three_recognisable_views(tmp_path) -> None:  # noqa: ANN001
    from saucerfab.imaging.masks import prepare_image
    from saucerfab.model.design_folder import load_design
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.workflow import run_design

    out = tmp_path / "two"
    req = DesignRequest(
        SAMPLES / "direct_heart.png",
        SAMPLES / "reflected_star.png",
        reflected2=SAMPLES / "reflected2_moon.png",
        scene=str(SAMPLES / "scene_prism.toml"),
        frames="contain",
        resolution=48,
        image_size=96,
        max_iters=30,
    )
    run_design(req, out, progress=lambda *a: None)
    d = load_design(out)
    assert d.scene.reflected2 is not None
    from PIL import Image

    for view, path in (("direct", req.direct), ("reflected", req.reflected), ("reflected2", req.reflected2)):
        got = np.asarray(Image.open(out / "previews" / f"{view}_view.png").convert("RGB"), float) / 255
        want = prepare_image(path, got.shape[0])
        # the subject's silhouette reappears: IoU of foreground against the input's mask
        fg = _fg(got, want.background)
        iou = (fg & want.mask).sum() / max((fg | want.mask).sum(), 1)
        assert iou > 0.6, f"{view}: IoU {iou:.2f}"
    assert "prism_placement" in __import__("json").loads((out / "design.json").read_text())["metrics"]
    # ... and it exports to a valid, printable solid with a prism-shaped seat
    import json

    from saucerfab.check import check_mesh
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design

    res = export_design(out, tmp_path / "print", printer="j55", cup_diameter_mm=80, formats=["3mf"],
                        options=FabOptions(texture_px=512))
    (three_mf,) = res.files["3mf"]
    report = check_mesh(three_mf)
    assert report.findings is not None
    assert not [f for f in report.findings if f.severity == "error"], [f.message for f in report.findings]
    sj = json.loads((tmp_path / "print" / "scene.json").read_text())
    assert sj["cup"]["shape"] == "prism" and sj["cup"]["sides"] == 6
    assert set(sj["views"]) == {"direct", "reflected", "reflected2"}


def test_elliptic_cup_design_goes_through_to_a_printable_export(tmp_path) -> None:  # noqa: ANN001
    import json

    from saucerfab.check import check_mesh
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.model.design_folder import load_design
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.workflow import run_design

    out = tmp_path / "ellipse"
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", cup="ellipse:0.45,0.35,10",
                        resolution=24, image_size=64, max_iters=10)
    run_design(req, out, progress=lambda *a: None)
    d = load_design(out)
    assert d.scene.cup.kind == "ellipse"
    # the reflection in the elliptic mirror reaches the reflected view
    from PIL import Image

    refl = np.asarray(Image.open(out / "previews" / "reflected_view.png").convert("RGB"), float) / 255
    assert (np.abs(refl - 1.0).max(axis=-1) > 0.25).mean() > 0.05
    res = export_design(out, tmp_path / "print", printer="j55", cup_diameter_mm=80, formats=["3mf"],
                        options=FabOptions(texture_px=256))
    report = check_mesh(res.files["3mf"][0])
    assert not [f for f in report.findings if f.severity == "error"], [f.message for f in report.findings]
    sj = json.loads((tmp_path / "print" / "scene.json").read_text())
    assert sj["cup"]["shape"] == "ellipse" and sj["cup"]["rotation_deg"] == 10.0
