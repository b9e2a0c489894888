"""Rendering: the camera convention, the differentiable soft rasterizer, hard previews."""

from saucerfab.render.camera import Camera

__all__ = ["Camera"]
