"""Designs for verify's tests: a saucer painted by projection from the design eye, flat or with waves.

A print whose texture is the picture projected from the design eye onto its
own top shows the design eye the picture exactly, whatever its relief; from a
moved eye a flat one shows the flat print and a wavy one shows the waves'
parallax on top of it.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from verify_reference import _bilinear

from saucerfab.model.camera import Camera
from saucerfab.model.design import Design
from saucerfab.model.design_folder import synthetic_design
from saucerfab.model.heightfield import make_grid

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def picture(name: str, size: int) -> np.ndarray:
    """A bundled sample fitted into a square of ``size`` px, transparency over white, float in [0, 1]."""
    from saucerfab.imaging.fitting import fit_square
    from saucerfab.imaging.images import flatten_alpha, load_image

    img = load_image(SAMPLES / name)
    rgb, alpha, _ = fit_square(img, size)
    return rgb if alpha is None else flatten_alpha(rgb, alpha, (1.0, 1.0, 1.0))


def painted_design(amplitude: float = 0.0, waves: float = 3.0, resolution: int = 20) -> Design:
    """A saucer of ``waves`` ridges across its depth (``amplitude`` model units; 0: flat) with the heart
    painted on it from the design eye; the star is the reflected view's reference (not painted)."""
    d = synthetic_design(shape="plane", resolution=resolution, texture_size=256)
    (x0, x1), (y0, y1) = d.scene.saucer.x_range, d.scene.saucer.y_range

    def height(y: np.ndarray) -> np.ndarray:
        return amplitude * np.sin(2.0 * np.pi * waves * (y - y0) / (y1 - y0))

    xy = make_grid(d.scene.saucer).xy()
    d = replace(d, heights=d.base_heights + height(xy[:, 1]).reshape(d.base_heights.shape))
    heart, star = picture("direct_heart.png", 256), picture("reflected_star.png", 256)
    cam = Camera.from_scene(d.scene, "direct")
    t = d.texture.shape[0]
    k = (np.arange(t) + 0.5) / t
    u, v = np.meshgrid(k, 1 - k)
    y = y0 + v * (y1 - y0)
    pts = np.stack([x0 + u * (x1 - x0), y, height(y)], -1)
    ndc = cam.project(pts)
    # pixel (col, row) of the heart in its frame -> texture coordinates of _bilinear
    tex = _bilinear(heart, (ndc[..., 0] + 1) / 2, (ndc[..., 1] + 1) / 2)
    outside = (np.abs(ndc[..., 0]) > 1) | (np.abs(ndc[..., 1]) > 1)
    tex[outside] = 1.0
    texture = np.round(np.clip(tex, 0, 1) * 255).astype(np.uint8)
    refs = {"direct": np.round(heart * 255).astype(np.uint8), "reflected": np.round(star * 255).astype(np.uint8)}
    return replace(d, texture=texture, references=refs)
