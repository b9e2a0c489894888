"""The flat print, a moved eye's reference: its geometry, what it shows the design eye, what it scores.

A moved eye is scored against the flat print (``saucerfab/verify/flatprint.py``):
the reference picture lying flat on the saucer, placed for the design eye.
These tests hold its parts to plain geometry and its score to what it is
for: a flat print scores high from every eye, a relief's parallax lowers
it, and from the design eye the flat print is the picture itself.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from verify_designs import painted_design

from saucerfab.fabricate.pipeline import export_design
from saucerfab.verify import EyeSpec, verify_print
from saucerfab.verify.core import resize_box
from saucerfab.verify.flatprint import FlatPrints, flat_print, plate_points
from saucerfab.verify.metrics import psnr
from saucerfab.verify.schema import JSON_SCHEMA
from saucerfab.verify.printfolder import find_mesh_files, load_print_scene, load_references, read_surface

RES = 64


def _export(design, out: Path) -> Path:
    export_design(design, out, printer="bureau", formats=["obj"], cup_diameter_mm=80)
    return out


@pytest.fixture(scope="module")
def prints(tmp_path_factory) -> dict[float, Path]:
    root = tmp_path_factory.mktemp("flat")
    return {a: _export(painted_design(a, resolution=40), root / f"a{a}") for a in (0.0, 0.02, 0.04)}


def _scene_and_surface(folder: Path):
    scene = load_print_scene(folder)
    fmt, path = find_mesh_files(folder)[0]
    return scene, read_surface(path, fmt, scene)


def _pixel_rays(eye, target, half_angle_deg: float, size: int) -> np.ndarray:
    """(S, S, 3) unit directions through the pixel centres: look-at, z up, row 0 at the top, +x right."""
    f = np.asarray(target, float) - np.asarray(eye, float)
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    k = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(k, -k)
    t = math.tan(math.radians(half_angle_deg))
    d = f + t * (x[..., None] * right + y[..., None] * up)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def test_plate_points_are_where_the_pixel_rays_meet_the_plane(prints):
    from saucerfab.verify.raytrace import PrintTracer

    scene, surface = _scene_and_surface(prints[0.0])
    view = scene.views["direct"]
    seen = PrintTracer(surface, scene.cup).render(scene.camera, view, RES, 16).direct >= 0.999  # not the mirror
    z0 = 12.5
    pts = plate_points(scene.cup, (-500.0, 700.0, -500.0, 700.0), z0, scene.camera, view, RES, 16)
    rays = _pixel_rays(scene.camera, view.target, view.viewing_angle_deg, RES)
    e = np.asarray(scene.camera)
    expect = e + ((z0 - e[2]) / rays[..., 2])[..., None] * rays
    full = pts["full"] & seen
    assert full.mean() > 0.5
    err = np.linalg.norm(pts["xyz"][full] - expect[full], axis=-1)
    # a pixel's mean point, not its centre's, but a plane's perspective is nearly linear over a
    # pixel (about 2 mm across here)
    assert np.percentile(err, 99) < 0.2, np.percentile(err, [50, 99])
    assert np.all(pts["xyz"][full, 2] == z0)


def test_a_jump_between_pixels_is_not_bridged():
    s = 8
    xyz = np.zeros((s, s, 3))
    xyz[..., 0], xyz[..., 1] = np.meshgrid(np.arange(s, dtype=float), np.arange(s, dtype=float))
    xyz[:, 4:, 0] += 100.0  # the right half seen in another facet, far away
    pts = {"xyz": xyz, "full": np.ones((s, s), bool)}
    flat = flat_print(pts, np.ones((s, s), bool), np.zeros((4, 4, 3), np.uint8), path=Path("jump"))
    assert flat.faces.shape[0] == 2 * (s - 1) * (s - 1) - 2 * (s - 1)  # every quad but the column across the jump
    span = np.ptp(flat.vertices[flat.faces][..., 0], axis=1)
    assert span.max() <= 1.0
    # every face faces up (Mitsuba's area lights emit on the front side only)
    e1 = flat.vertices[flat.faces[:, 1]] - flat.vertices[flat.faces[:, 0]]
    e2 = flat.vertices[flat.faces[:, 2]] - flat.vertices[flat.faces[:, 0]]
    assert np.all(np.cross(e1, e2)[:, 2] > 0)
    # each corner's texture coordinate is its pixel's centre in the frame (v up)
    r, c = 2, 5
    i = int(np.flatnonzero((flat.vertices[:, 0] == c + 100.0) & (flat.vertices[:, 1] == r))[0])
    f, corner = np.argwhere(flat.faces == i)[0]
    assert flat.corner_uv[f, corner] == pytest.approx([(c + 0.5) / s, 1 - (r + 0.5) / s])


@pytest.mark.parametrize("amplitude", [0.0, 0.04])
def test_from_the_design_eye_the_flat_print_is_the_picture(prints, amplitude):
    folder = prints[amplitude]
    scene, surface = _scene_and_surface(folder)
    refs = load_references(folder, list(scene.views))
    pictures = {v: np.round(img * 255).astype(np.uint8) for v, img in refs.items()}
    from saucerfab.verify.raytrace import PrintTracer

    tracer = PrintTracer(surface, scene.cup)
    regions = {}
    for name, view in scene.views.items():
        r = tracer.render(scene.camera, view, RES, 16)
        regions[name] = (r.direct if name == "direct" else r.reflected) >= 0.999
    flats = FlatPrints(surface, scene.cup, scene.camera, scene.views, pictures, regions, RES, 16)
    for name, view in scene.views.items():  # the reflected view too: the star is in the flat print, not the print
        rgb, seen = flats.render(name, scene.camera, view, RES, 16)
        both = seen & regions[name]
        # the plate spans the region's pixel centres, so its outer half pixel is missing (15 % of the
        # reflected view's 1,100 pixels at this size)
        assert both.sum() > 0.8 * regions[name].sum(), name
        assert psnr(rgb, resize_box(refs[name], RES), both) > 35.0, name
    # the plate lies at the mean height of the top the design eye sees
    z = surface.vertices[np.unique(surface.faces[surface.top]), 2]
    assert z.min() <= flats.heights["direct"] <= z.max()


def test_a_view_the_design_eye_does_not_see_has_no_flat_print(prints):
    folder = prints[0.0]
    scene, surface = _scene_and_surface(folder)
    pictures = {v: np.zeros((8, 8, 3), np.uint8) for v in scene.views}
    regions = {v: np.zeros((RES, RES), bool) for v in scene.views}
    flats = FlatPrints(surface, scene.cup, scene.camera, scene.views, pictures, regions, RES, 4)
    rgb, seen = flats.render("direct", scene.camera, scene.views["direct"], RES, 4)
    assert not seen.any() and rgb.shape == (RES, RES, 3)
    # nor does a file without a printed top (every face a wall): nothing to build, no error
    from dataclasses import replace

    bare = replace(surface, top=np.zeros_like(surface.top))
    everywhere = {v: np.ones((RES, RES), bool) for v in scene.views}
    flats = FlatPrints(bare, scene.cup, scene.camera, scene.views, pictures, everywhere, RES, 4)
    assert flats.heights == {} and not flats.render("reflected", scene.camera, scene.views["reflected"], RES, 4)[1].any()


def test_a_relief_s_parallax_is_what_a_moved_eye_loses(prints, tmp_path):
    scores = {}
    for a, folder in prints.items():
        result = verify_print(folder, eyes=EyeSpec("both"), res=RES, spp=4, all_formats=False,
                              pictures_dir=tmp_path / f"a{a}")
        scores[a] = result
        # painted for the design eye: it sees the heart whatever the relief
        assert result.score("direct").psnr_db > 28.0, (a, result.score("direct"))
        doc = json.loads(json.dumps(result.to_dict()))
        jsonschema.validate(doc, JSON_SCHEMA)
        assert {(v["eye"], v["reference"]) for v in doc["files"][0]["views"]} == {
            ("design", "picture"), ("left", "flat print"), ("right", "flat print")}
    for eye in ("left", "right"):
        flat, small, large = (scores[a].score("direct", eye) for a in (0.0, 0.02, 0.04))
        assert flat.psnr_db > 30.0, flat
        # the waves break the heart into slices from a moved eye, the more the higher they are
        assert flat.psnr_db > small.psnr_db + 1.0 > large.psnr_db + 2.0, (flat, small, large)
        # the older score cannot tell them apart as well: the perspective dominates it
        assert max(v.psnr_shift_db for v in (flat, small, large)) < flat.psnr_db - 5.0
    assert (tmp_path / "a0.04" / "left_direct.png").is_file()
