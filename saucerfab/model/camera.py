"""The one camera convention of saucerfab (numpy and torch).

A view is a look-at camera at ``eye`` towards ``target`` with world up
``(0, 0, 1)`` and SoftRas's perspective:

* camera axes: ``forward = normalize(target - eye)``,
  ``right = normalize(forward x up)``, ``cam_up = right x forward``
  (right-handed: world +x is on the right of the image for the paper's
  camera, which looks along +y and down).
* projection (SoftRas ``perspective``): with ``depth = <v - eye, forward>``
  and ``w = tan(viewing_angle)``,
  ``x_ndc = <v - eye, right> / (depth * w)``, ``y_ndc = <v - eye, cam_up> / (depth * w)``.
  The frame is the square ``[-1, 1]^2`` in NDC; each input image covers it whole.
* pixels: an ``S x S`` image, row 0 at the top. Pixel (row i, column j) has
  its centre at ``x_ndc = (2 j + 1) / S - 1``, ``y_ndc = 1 - (2 i + 1) / S``.
  So ``image[i, j]`` is what the viewer sees there, the same orientation as
  the input images (PNG row 0 = top).

Unlike SoftRas's own ``look_at`` (a left-handed ``right = up x forward``),
images here need no flip to match what a viewer sees.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

WORLD_UP = (0.0, 0.0, 1.0)


@functools.lru_cache(maxsize=64)
def _look_at_axes(eye: tuple[float, ...], target: tuple[float, ...]) -> np.ndarray:
    """:meth:`Camera.axes` of a view, computed once per view: the renderers ask for it
    on every call, and numpy's cross products of 3-vectors cost ~0.1 ms each time."""
    e = np.asarray(eye, np.float64)
    fwd = np.asarray(target, np.float64) - e
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, WORLD_UP)
    n = np.linalg.norm(right)
    if n < 1e-12:
        raise ValueError("the view axis is vertical; the world up vector is undefined for it")
    right /= n
    up = np.cross(right, fwd)
    out = np.stack([right, up, fwd])
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Camera:
    """A look-at perspective camera (model units).

    Attributes:
        eye: (3,) camera position.
        target: (3,) point on the view axis.
        viewing_angle_deg: SoftRas half field of view, degrees.
        image_size: S, the image is S x S pixels.
    """

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    viewing_angle_deg: float
    image_size: int

    @classmethod
    def from_scene(cls, scene, view: str) -> "Camera":  # type: ignore[no-untyped-def]
        """The camera of ``scene``'s ``view`` ("direct", "reflected" or "reflected2";
        a scene without its own reflected2 frame uses the reflected one)."""
        frame = getattr(scene, view, None) or scene.reflected
        return cls(tuple(scene.camera), tuple(frame.target), frame.viewing_angle_deg, frame.image_size)

    def with_size(self, size: int) -> "Camera":
        return Camera(self.eye, self.target, self.viewing_angle_deg, size)

    @property
    def tan_angle(self) -> float:
        return math.tan(math.radians(self.viewing_angle_deg))

    def axes(self) -> np.ndarray:
        """(3, 3) float64 rotation, rows ``right, cam_up, forward`` (a fresh copy)."""
        return _look_at_axes(tuple(self.eye), tuple(self.target)).copy()

    def project(self, points: np.ndarray) -> np.ndarray:
        """Project (..., 3) world points to (..., 3) ``[x_ndc, y_ndc, depth]`` (numpy, float64)."""
        cam = (np.asarray(points, np.float64) - np.asarray(self.eye)) @ self.axes().T
        depth = cam[..., 2]
        w = self.tan_angle
        return np.stack([cam[..., 0] / (depth * w), cam[..., 1] / (depth * w), depth], axis=-1)

    def project_torch(self, points):  # type: ignore[no-untyped-def]
        """Differentiable :meth:`project` for a torch tensor (..., 3); same dtype/device."""
        import torch

        r = torch.as_tensor(self.axes(), dtype=points.dtype, device=points.device)
        eye = torch.as_tensor(self.eye, dtype=points.dtype, device=points.device)
        cam = (points - eye) @ r.T
        depth = cam[..., 2]
        w = self.tan_angle
        return torch.stack([cam[..., 0] / (depth * w), cam[..., 1] / (depth * w), depth], dim=-1)

    def pixel_ndc(self) -> tuple[np.ndarray, np.ndarray]:
        """NDC centres: ``x`` of each column (S,), ``y`` of each row (S,)."""
        s = self.image_size
        k = np.arange(s, dtype=np.float64)
        return (2 * k + 1) / s - 1, 1 - (2 * k + 1) / s

    def ndc_to_pixel(self, ndc_xy: np.ndarray) -> np.ndarray:
        """(..., 2) NDC -> (..., 2) continuous ``(column, row)`` pixel coordinates
        (pixel (i, j)'s centre is at column j + 0.5, row i + 0.5)."""
        s = self.image_size
        x = (np.asarray(ndc_xy)[..., 0] + 1) * s / 2
        y = (1 - np.asarray(ndc_xy)[..., 1]) * s / 2
        return np.stack([x, y], axis=-1)

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Rays through every pixel centre: origin (3,), unit directions (S, S, 3) [row, col]."""
        xs, ys = self.pixel_ndc()
        w = self.tan_angle
        r = self.axes()
        gx, gy = np.meshgrid(xs, ys)
        d = gx[..., None] * w * r[0] + gy[..., None] * w * r[1] + r[2]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return np.asarray(self.eye, np.float64), d
