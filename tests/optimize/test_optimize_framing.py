"""The fitted view frames: contain, cover and inscribed (optimize/framing.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from saucerfab.model.heightfield import base_shape
from saucerfab.model.scene import paper_scene
from saucerfab.optimize.framing import fit_frames, largest_inscribed_square


def test_largest_inscribed_square_of_a_disk_and_of_a_triangle():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (40000, 2))
    disk = pts[(pts**2).sum(axis=1) <= 1.0]
    centre, half = largest_inscribed_square(disk)
    assert np.allclose(centre, 0.0, atol=0.03)
    assert half == pytest.approx(1 / math.sqrt(2), rel=0.06)  # the square inscribed in the unit circle
    assert half < 1 / math.sqrt(2)  # and never past it
    tri = pts[(pts[:, 1] >= -1) & (pts[:, 1] <= 1 - np.abs(pts[:, 0]) * 2 + 1)]  # apex at (0, 1), base y = -1
    tri = tri[tri[:, 1] <= 1 - 2 * np.abs(tri[:, 0])]
    centre, half = largest_inscribed_square(tri)
    # a square of side s under the apex: 2 - s >= s  -> s = 1 (half 0.5) sitting on the base
    assert half == pytest.approx(0.5, rel=0.08) and abs(centre[0]) < 0.05 and centre[1] == pytest.approx(-0.5, abs=0.06)


def test_inscribed_frames_lie_on_the_saucer_and_keep_the_camera():
    from saucerfab.model.camera import Camera

    scene = paper_scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=60))
    h = base_shape("plane", 60, 0)  # flat, so the corner rays below land on the heights the frames saw
    contain, inscribed = fit_frames(scene, h, "contain"), fit_frames(scene, h, "inscribed")
    assert inscribed.camera == scene.camera
    # the reflected frame shrinks (its corners no longer leave the saucer's reflection); the direct one barely
    assert inscribed.reflected.viewing_angle_deg < contain.reflected.viewing_angle_deg
    assert inscribed.direct.viewing_angle_deg == pytest.approx(contain.direct.viewing_angle_deg, rel=0.1)
    # every frame corner of the direct view falls on the saucer: cast the corner rays onto its plane
    cam = Camera.from_scene(inscribed, "direct")
    w, r = cam.tan_angle, cam.axes()
    (x0, x1), (y0, y1) = scene.saucer.x_range, scene.saucer.y_range
    for cx in (-0.98, 0.98):
        for cy in (-0.98, 0.98):
            d = r[2] + cx * w * r[0] + cy * w * r[1]
            t = (float(h.mean()) - cam.eye[2]) / d[2]
            p = np.asarray(cam.eye) + t * d
            assert x0 <= p[0] <= x1 and y0 <= p[1] <= y1, (cx, cy, p)


def test_unknown_frames_mode_is_refused():
    from saucerfab.errors import ConfigError

    with pytest.raises(ConfigError, match="inscribed"):
        fit_frames(paper_scene(), np.zeros((150, 150)), "zoom")
