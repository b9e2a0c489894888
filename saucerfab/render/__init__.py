"""Rendering: the camera convention, the differentiable soft rasterizer, hard previews.

* :class:`Camera` - the one camera/NDC/pixel convention (:mod:`saucerfab.model.camera`).
* :func:`soft_rasterize` - SoftRas soft rasterizer with gradients (:mod:`saucerfab.render.soft`,
  the op and the dispatch; its constants and parameters in :mod:`saucerfab.render.soft_common`);
  backends: compiled numba CPU kernels (:mod:`saucerfab.render.soft_numba`, the per-face
  setup and autograd glue; :mod:`saucerfab.render.soft_tiles`, the tiles and binning;
  :mod:`saucerfab.render.soft_kernels`, a tile forward and backward; :mod:`saucerfab.render._simd`)
  and vectorized torch (:mod:`saucerfab.render.soft_torch`, also the CUDA path).
* :func:`rasterize_hard`, :func:`render_textured`, :func:`render_face_colors_hard` -
  nearest-face rasterization for previews and visibility (:mod:`saucerfab.render.hard`);
  the bilinear texture lookup they and the bake share (:mod:`saucerfab.render.sampling`);
  the texels under 2-D triangles the texturing and the export's paint share (:mod:`saucerfab.render.texels`).

Only the camera is imported with the package; the rasterizers (and numba,
torch) load on first use, so ``from saucerfab.model.camera import Camera``
stays cheap.

Importing saucerfab (this package's parent) sets how torch's OpenMP workers
wait between torch ops (``saucerfab/__init__.py``), so that they do not take a
core from the numba kernels that follow; it counts when saucerfab is imported
before torch, as the CLI does.
"""

from __future__ import annotations

from typing import Any

from saucerfab.model.camera import Camera

__all__ = ["Camera", "rasterize_hard", "render_face_colors_hard", "render_textured", "soft_rasterize"]

_LAZY = {
    "soft_rasterize": "saucerfab.render.soft",
    "rasterize_hard": "saucerfab.render.hard",
    "render_face_colors_hard": "saucerfab.render.hard",
    "render_textured": "saucerfab.render.hard",
}


def __getattr__(name: str) -> Any:
    """Load the rasterizers on first use (PEP 562)."""
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'saucerfab.render' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
