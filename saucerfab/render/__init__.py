"""Rendering: the camera convention, the differentiable soft rasterizer, hard previews.

* :class:`Camera` - the one camera/NDC/pixel convention (:mod:`saucerfab.render.camera`).
* :func:`soft_rasterize` - SoftRas soft rasterizer with gradients (:mod:`saucerfab.render.soft`);
  backends: compiled numba CPU kernels (:mod:`saucerfab.render.soft_numba`) and
  vectorized torch (:mod:`saucerfab.render.soft_torch`, also the CUDA path).
* :func:`rasterize_hard`, :func:`render_textured`, :func:`render_face_colors_hard` -
  nearest-face rasterization for previews and visibility (:mod:`saucerfab.render.hard`).

torch is imported only when a function that needs it is called.

Importing this package sets ``OMP_WAIT_POLICY=PASSIVE`` unless the environment
already sets it: torch's OpenMP workers otherwise busy-wait after each torch
operation and take a core from the numba kernels that follow (libgomp reads the
variable when torch is first imported, so it helps when saucerfab.render is
imported before torch, as the CLI does).
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from saucerfab.render.camera import Camera  # noqa: E402
from saucerfab.render.hard import rasterize_hard, render_face_colors_hard, render_textured  # noqa: E402
from saucerfab.render.soft import soft_rasterize  # noqa: E402

__all__ = ["Camera", "rasterize_hard", "render_face_colors_hard", "render_textured", "soft_rasterize"]
