"""Rendering: the camera convention, the differentiable soft rasterizer, hard previews.

* :class:`Camera` - the one camera/NDC/pixel convention (:mod:`saucerfab.render.camera`).
* :func:`soft_rasterize` - SoftRas soft rasterizer with gradients (:mod:`saucerfab.render.soft`);
  backends: compiled numba CPU kernels (:mod:`saucerfab.render.soft_numba`) and
  vectorized torch (:mod:`saucerfab.render.soft_torch`, also the CUDA path).
* :func:`rasterize_hard`, :func:`render_textured`, :func:`render_face_colors_hard` -
  nearest-face rasterization for previews and visibility (:mod:`saucerfab.render.hard`).

torch and numba are imported only when a function that needs them is called.
"""

from saucerfab.render.camera import Camera
from saucerfab.render.hard import rasterize_hard, render_face_colors_hard, render_textured
from saucerfab.render.soft import soft_rasterize

__all__ = ["Camera", "rasterize_hard", "render_face_colors_hard", "render_textured", "soft_rasterize"]
