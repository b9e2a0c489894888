"""Fitting the view frames to where the saucer actually appears.

With the paper's preset the direct frame reaches past the saucer's far edge
(its top third shows the cup's foot, not the saucer) and the saucer's
reflection fills only about half of the reflected frame's width, so parts of
the input images fall where no saucer can show them. ``fit_frames`` keeps the
camera and re-aims each frame at the region the saucer covers in it:

* ``"contain"``: the largest square frame inside the region's bounding box,
  so the whole input image lands on the saucer (or its reflection);
* ``"cover"``: the smallest square frame containing the region, so the whole
  saucer is used and the image's margins fall off it.

``"contain"`` is the default of a design (``DesignRequest.frames``): the
paper's preset (``frames="scene"``) stays available, and measured with
``saucerfab verify`` it shows only 66 % of the direct picture and 31 % of the
reflected one on the saucer (benchmarks/RESULTS.md, Verify).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.heightfield import make_grid
from saucerfab.render.camera import Camera
from saucerfab.scene import Scene, ViewFrame


def _refit(cam: Camera, points: np.ndarray, mode: str) -> ViewFrame:
    eye = np.asarray(cam.eye, np.float64)
    frame_cam = cam
    for _ in range(3):  # the re-aimed axis changes the perspective slightly; iterate
        ndc = frame_cam.project(points)
        lo, hi = ndc[:, :2].min(axis=0), ndc[:, :2].max(axis=0)
        centre = (lo + hi) / 2
        half = (hi - lo) / 2
        side = float(half.min() if mode == "contain" else half.max())
        r = frame_cam.axes()
        w = frame_cam.tan_angle
        d = r[2] + centre[0] * w * r[0] + centre[1] * w * r[1]
        d /= np.linalg.norm(d)
        dist = float(np.linalg.norm(np.asarray(frame_cam.target) - eye))
        target = tuple(float(v) for v in eye + d * dist)
        angle = math.degrees(math.atan(w * side))
        frame_cam = Camera(cam.eye, target, angle, cam.image_size)
    return ViewFrame(frame_cam.target, frame_cam.viewing_angle_deg, cam.image_size)


def fit_frames(
    scene: Scene, heights: np.ndarray, mode: str = "contain", groups: list[list[int]] | None = None
) -> Scene:
    """A copy of ``scene`` whose frames are fitted to the saucer and its reflection.

    Args:
        heights: (N, N) base heights (the region barely depends on them).
        mode: "contain" or "cover" (see the module docstring).
        groups: prism facet groups of two reflected images: the reflected
            frame is fitted to the first group's region, ``reflected2`` to the second.
    """
    from saucerfab.mirror import reflect

    if mode not in ("contain", "cover"):
        raise ConfigError(f"frames mode must be 'contain' or 'cover', got {mode!r}")
    grid = make_grid(scene.saucer)
    h = np.asarray(heights, np.float64).reshape(-1)
    direct = _refit(Camera.from_scene(scene, "direct"), grid.vertices(h), mode)
    pieces = reflect(scene, grid.xy())

    def region(facets: list[int] | None) -> np.ndarray:
        pts = [
            p.reflected_vertices(h)[p.valid(h, scene.cup.height)]
            for p in pieces
            if facets is None or p.facet in facets
        ]
        allp = np.concatenate(pts) if pts else np.zeros((0, 3))
        if allp.shape[0] < 3:
            raise ConfigError("no part of the saucer is seen in the cup; move the saucer or the camera")
        return allp

    cam_r = Camera.from_scene(scene, "reflected")
    if groups is None:
        return replace(scene, direct=direct, reflected=_refit(cam_r, region(None), mode))
    return replace(
        scene,
        direct=direct,
        reflected=_refit(cam_r, region(groups[0]), mode),
        reflected2=_refit(cam_r, region(groups[1]), mode),
    )
