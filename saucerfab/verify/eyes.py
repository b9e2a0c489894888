"""The eyes verify renders from: the shared definition in :mod:`saucerfab.eyes` (the optimizer uses it too)."""

from saucerfab.eyes import DEFAULT_BOX_STEPS, DEFAULT_IPD_MM, EYE_MODES, Eye, EyeSpec, eye_positions, parse_eyes, view_axes

__all__ = ["DEFAULT_BOX_STEPS", "DEFAULT_IPD_MM", "EYE_MODES", "Eye", "EyeSpec", "eye_positions", "parse_eyes", "view_axes"]
