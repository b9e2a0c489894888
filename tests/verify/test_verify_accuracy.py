"""Verify's own accuracy (issue 42, item 12): where its mirror puts the picture, and what its sample count reads.

* The reflection: a saucer with two sharp edges, ray-traced through the
  mirror by verify's renderer, is held to where the exact cylinder puts
  the edges (numpy, float64: :func:`verify_reference.cylinder_reflection`)
  to 0.01 px, at the coordinates an export writes and far from them. Before
  the render frame was centred on the cup, Mitsuba's float32 ray offsets
  (10-17 um there) made the mirror reflect like a cup 5-8 um wider: 0.023 px
  here, 0.089 px with the print 500 mm further out.
* The sampling: a photo-like print's PSNR at the default samples per pixel
  reads what a converged render reads, within 0.3 dB (a noisy render's
  squared error is its true error plus its noise variance: 0.59 dB low here
  before its noise was taken out).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from verify_reference import _bilinear, camera_frame, camera_rays, cylinder_reflection

from saucerfab.fabricate.scene_file import CupSpec, ViewSpec
from saucerfab.model.cups import cup_from_dict
from saucerfab.verify import DEFAULT_SPP, EyeSpec, verify_print
from saucerfab.verify.metrics import psnr
from saucerfab.verify.printfolder import PrintedSurface
from saucerfab.verify.raytrace import FULL_COVERAGE, PrintTracer, colour_halves

#: the coordinates ``saucerfab export --cup-diameter-mm 80`` writes for the default scene
#: (test_verify.py's ``flat_print``): the cup's axis 158 mm from the origin
SCENE = {
    "schema": "saucerfab.scene/1",
    "units": "mm",
    "camera": {"position": [50.0, -400.0, 503.0], "up": [0.0, 0.0, 1.0]},
    "views": {
        "direct": {"target": [50.0, 150.0, -77.0], "viewing_angle_deg": 4.5, "width": 512, "height": 512},
        "reflected": {"target": [50.0, 150.0, 13.0], "viewing_angle_deg": 3.0, "width": 512, "height": 512},
    },
    "cup": {"shape": "circle", "center": [50.0, 150.0], "bottom_z": 3.0, "height": 100.0, "radius": 40.0},
    "model_to_file": [[100.0, 0, 0, 50.0], [0, 100.0, 0, 150.0], [0, 0, 100.0, 3.0], [0, 0, 0, 1.0]],
    "mm_per_unit": 100.0,
    "saucer": {"x_range": [0.0, 100.0], "y_range": [0.0, 100.0]},
    "seat": {"kind": "recess", "floor_z": 3.0, "top_z": 4.5, "base_z": 0.0},
}
#: height of the synthetic saucer's flat top, mm
Z_TOP = 10.0


def _moved(offset: tuple[float, float, float]) -> dict:
    """:data:`SCENE` with everything moved by ``offset`` mm (the same print, placed elsewhere)."""
    s = json.loads(json.dumps(SCENE))
    ox, oy, oz = offset
    s["camera"]["position"] = list(np.add(s["camera"]["position"], offset))
    for v in s["views"].values():
        v["target"] = list(np.add(v["target"], offset))
    s["cup"]["center"] = [s["cup"]["center"][0] + ox, s["cup"]["center"][1] + oy]
    s["cup"]["bottom_z"] += oz
    s["saucer"] = {"x_range": list(np.add(s["saucer"]["x_range"], ox)), "y_range": list(np.add(s["saucer"]["y_range"], oy))}
    return s


def _cup(scene: dict) -> CupSpec:
    c = scene["cup"]
    outline = cup_from_dict({k: v for k, v in c.items() if k not in ("center", "bottom_z")}, c["shape"])
    return CupSpec(tuple(c["center"]), c["bottom_z"], c["height"], outline)


def _flat_top(scene: dict, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The saucer's footprint as one flat textured square at height ``z``: vertices (4, 3), faces, corner uv."""
    (x0, x1), (y0, y1) = scene["saucer"]["x_range"], scene["saucer"]["y_range"]
    vertices = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)  # u along x, v along y (v up)
    return vertices, faces, uv


# --------------------------------------------------------------------------- the reflection

#: render size and half angle of the zoomed reflected view (3 degrees at 256 px has these pixels)
EDGE_RES, EDGE_ANGLE = 128, 1.5
#: the saucer's sharp edges (mm from the footprint's corner): red left of x, green in front of y
EDGE_X, EDGE_Y = 44.0, 55.0
#: texels of the edge texture (0.1 mm each: the edges lie on texel boundaries)
EDGE_TEXELS = 1000


def _edge_print(scene: dict) -> PrintedSurface:
    (x0, x1), (y0, y1) = scene["saucer"]["x_range"], scene["saucer"]["y_range"]
    k = (np.arange(EDGE_TEXELS) + 0.5) / EDGE_TEXELS
    tex = np.zeros((EDGE_TEXELS, EDGE_TEXELS, 3), np.uint8)
    tex[:, k * (x1 - x0) < EDGE_X, 0] = 255
    tex[(1 - k) * (y1 - y0) < EDGE_Y, :, 1] = 255  # row 0 at the top: the far edge, v = 1
    vertices, faces, uv = _flat_top(scene, Z_TOP)
    return PrintedSurface(Path("edges"), "obj", vertices, faces, uv[faces], np.zeros(2, np.int64), [tex], np.ones(2, bool))


def _exact_crossings(scene: dict, view: ViewSpec, size: int, axis: int, value: float, sub: int = 8) -> np.ndarray:
    """(size,) where each pixel line's reflection crosses saucer ``x`` (axis 0, along rows) or ``y`` (1, along columns).

    Each line is the mean over ``sub`` lines across its pixel (a pixel's box
    filter), each solved by bisection on the exact cylinder; NaN where a
    line does not cross exactly once.
    """
    eye, c = scene["camera"]["position"], scene["cup"]
    lo_xy = (scene["saucer"]["x_range"][0], scene["saucer"]["y_range"][0])
    lines = np.arange(size)[:, None] + (np.arange(sub) + 0.5) / sub

    def f(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v = (q, lines) if axis == 0 else (lines, q)  # u right, v down, pixels
        d = camera_rays(eye, view.target, view.viewing_angle_deg, 2 * u / size - 1, 1 - 2 * v / size)
        _, p, dr, hit = cylinder_reflection(eye, d, c["center"], c["radius"])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (Z_TOP - p[..., 2]) / dr[..., 2]
        on_wall = (p[..., 2] >= c["bottom_z"]) & (p[..., 2] <= c["bottom_z"] + c["height"])
        return p[..., axis] + t * dr[..., axis] - lo_xy[axis] - value, hit & on_wall & (t > 0)

    grid = np.linspace(0.0, size, 4 * size + 1)
    vals, oks = zip(*(f(np.full(lines.shape, g)) for g in grid))
    val, ok = np.stack(vals), np.stack(oks)
    change = ok[:-1] & ok[1:] & (val[:-1] * val[1:] < 0)
    j = change.argmax(axis=0)
    lo, hi = grid[j], grid[j + 1]
    f_lo = np.take_along_axis(val, j[None], 0)[0]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)[0]
        same = np.sign(f_mid) == np.sign(f_lo)
        lo, f_lo, hi = np.where(same, mid, lo), np.where(same, f_mid, f_lo), np.where(same, hi, mid)
    return np.where(change.sum(axis=0) == 1, 0.5 * (lo + hi), np.nan).mean(axis=1)


def _measured_offsets(image: np.ndarray, full: np.ndarray, exact: np.ndarray, axis: int, half: int = 4) -> np.ndarray:
    """Rendered minus exact edge position (px) on each line whose window around the edge is seen fully.

    The rendered position is the window's start plus the sum of its values
    (an edge from 1 to 0 box-filtered over the pixels: exact at any sub-pixel
    position, unlike a 50 % crossing between pixel centres).
    """
    out = []
    for i, e in enumerate(exact):
        if not np.isfinite(e):
            continue
        a, b = int(np.floor(e)) - half, int(np.floor(e)) + half + 1
        if a < 0 or b > image.shape[0]:
            continue
        prof, seen = (image[i, a:b], full[i, a:b]) if axis == 0 else (image[a:b, i], full[a:b, i])
        if not seen.all():
            continue
        if prof[0] > 0.99 and prof[-1] < 0.01:
            out.append(a + prof.sum() - e)
        elif prof[0] < 0.01 and prof[-1] > 0.99:
            out.append(b - prof.sum() - e)
    return np.array(out)


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (400.0, 300.0, 0.0)], ids=["as exported", "500 mm further out"])
def test_the_mirror_puts_the_picture_where_the_exact_cylinder_does(offset):
    scene = _moved(offset)
    v = scene["views"]["reflected"]
    view = ViewSpec("reflected", tuple(v["target"]), EDGE_ANGLE)
    r = PrintTracer(_edge_print(scene), _cup(scene)).render(tuple(scene["camera"]["position"]), view, EDGE_RES, 64)
    full = r.reflected >= FULL_COVERAGE
    for axis, channel in ((0, 0), (1, 1)):  # saucer x's edge along rows, y's along columns
        exact = _exact_crossings(scene, view, EDGE_RES, axis, EDGE_X if axis == 0 else EDGE_Y)
        off = _measured_offsets(r.rgb[..., channel].astype(np.float64), full, exact, axis)
        assert off.size >= 30, (axis, off.size)
        # the edge is where the exact reflection puts it, on average (each line's sampling noise ~0.01 px)
        assert abs(off.mean()) < 0.01, (axis, off.mean(), off.std())
        assert np.abs(off).max() < 0.1, (axis, np.abs(off).max())


# --------------------------------------------------------------------------- the sampling


def _photo(size: int, seed: int = 0) -> np.ndarray:
    """(size, size, 3) float in [0, 1]: gradients, blotches and pixel grain, like a photo."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    img = np.stack([0.5 + 0.3 * np.sin(6 * x + 2 * c) * np.cos(4 * y - c) for c in range(3)], -1)
    img += 0.25 * np.stack([gaussian_filter(rng.standard_normal((size, size)), 2.0) for _ in range(3)], -1)
    img += 0.08 * rng.standard_normal((size, size, 3))
    return np.clip(img, 0.0, 1.0)


def _painted(scene: dict, picture: np.ndarray, texels: int) -> np.ndarray:
    """The saucer's texture: ``picture`` projected from the design eye onto the flat top (uint8)."""
    (x0, x1), (y0, y1) = scene["saucer"]["x_range"], scene["saucer"]["y_range"]
    v = scene["views"]["direct"]
    eye = np.asarray(scene["camera"]["position"], np.float64)
    fwd, right, up, w = camera_frame(eye, v["target"], v["viewing_angle_deg"])
    k = (np.arange(texels) + 0.5) / texels
    u, vv = np.meshgrid(k, 1 - k)  # row 0 at the top: v = 1
    rel = np.stack([x0 + u * (x1 - x0), y0 + vv * (y1 - y0), np.full_like(u, Z_TOP)], -1) - eye
    depth = rel @ fwd
    tex = _bilinear(picture, ((rel @ right) / depth / w + 1) / 2, ((rel @ up) / depth / w + 1) / 2)
    return np.round(np.clip(tex, 0.0, 1.0) * 255).astype(np.uint8)


def _write_print_folder(folder: Path, scene: dict, texture: np.ndarray, references: dict[str, np.ndarray]) -> Path:
    """A print folder as export writes it, by hand: scene.json, the references, a flat textured OBJ."""
    from PIL import Image

    folder.mkdir(parents=True)
    (folder / "scene.json").write_text(json.dumps(scene))
    for name, img in references.items():
        Image.fromarray(img).save(folder / f"reference_{name}.png")
    Image.fromarray(texture).save(folder / "saucer.png")
    (folder / "saucer.mtl").write_text("newmtl saucer\nKd 1 1 1\nmap_Kd saucer.png\n")
    vertices, faces, uv = _flat_top(scene, Z_TOP)
    lines = ["mtllib saucer.mtl", "o saucer", "usemtl saucer"]
    lines += [f"v {x} {y} {z}" for x, y, z in vertices] + [f"vt {u} {v}" for u, v in uv]
    lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in f) for f in faces]
    (folder / "saucer.obj").write_text("\n".join(lines) + "\n")
    return folder


@pytest.fixture(scope="module")
def photo_print(tmp_path_factory) -> Path:
    picture = _photo(192)
    refs = {"direct": np.round(picture * 255).astype(np.uint8), "reflected": np.zeros((8, 8, 3), np.uint8)}
    return _write_print_folder(tmp_path_factory.mktemp("photo") / "print", SCENE, _painted(SCENE, picture, 768), refs)


def test_the_default_sample_count_reads_what_a_converged_render_reads(photo_print):
    def direct(spp: int) -> float:
        result = verify_print(photo_print, eyes=EyeSpec("design"), res=96, spp=spp, all_formats=False)
        return result.score("direct", "design").psnr_db

    default, converged = direct(DEFAULT_SPP), direct(128)
    assert 30.0 < converged < 45.0, converged  # the picture prints, with the texture's own resampling error
    assert abs(default - converged) < 0.3, (default, converged)


def test_the_colour_halves_hold_their_sample_count_and_their_noise_is_the_variance():
    # each half is a count the sampler takes as it is (no warning, no rounding up), half of an even default
    assert [colour_halves(n) for n in (1, 2, 4, 16, 64, 256)] == [0, 1, 2, 8, 30, 121]
    from saucerfab.verify.raytrace import SAMPLER, mitsuba

    mi = mitsuba()
    for n in range(1, 300):
        h = colour_halves(n)
        assert 2 * h <= n and (h == 0 or mi.load_dict({"type": SAMPLER, "sample_count": h}).sample_count() == h), n
    # two noisy halves as the renderer makes them: their mean's PSNR, its noise taken out, reads the noiseless one's
    rng = np.random.default_rng(5)
    truth = rng.random((128, 128, 3))
    ref = truth + rng.choice([-0.03, 0.03], truth.shape)  # 30.5 dB
    a, b = (truth + rng.normal(0.0, 0.04, truth.shape) for _ in range(2))
    region = np.ones((128, 128), bool)
    clean = psnr(truth, ref, region)
    assert psnr((a + b) / 2, ref, region) < clean - 2.0
    assert psnr((a + b) / 2, ref, region, (a - b) ** 2 / 4) == pytest.approx(clean, abs=0.1)
