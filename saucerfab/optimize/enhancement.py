"""The paper's enhanced targets (section 3.4.1, eq. 7-8; section 4, Figure 19).

Early stages of the optimizer aim at flat-coloured versions of the input
pictures rather than the pictures themselves: each picture's foreground
(subject) mask is painted in one colour and its background in another, so
the height field first learns where the subjects go.

* two views: :func:`black_white_targets`, the direct subject black, the
  reflected subject white, both backgrounds light blue;
* three views (multi-reflection): :func:`solid_colour_targets`, subjects red,
  green and blue, backgrounds white.

The masks come from :func:`saucerfab.imaging.masks.foreground_mask`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from saucerfab.imaging.images import WHITE

#: black-white enhancement background (paper, section 3.4.1: "light blue"),
#: the colour farthest from both black and white; sRGB in [0, 1]
LIGHT_BLUE = (0.0, 0.5, 1.0)
BLACK = (0.0, 0.0, 0.0)
#: solid-colour enhancement foregrounds, in input order (paper, section 4)
SOLID_COLOURS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _paint(mask: np.ndarray, fg: Sequence[float], bg: Sequence[float]) -> np.ndarray:
    """(H, W, 3) float32: ``fg`` where ``mask``, ``bg`` elsewhere (soft masks blend linearly)."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"a mask must be (H, W), got shape {m.shape}")
    f = np.asarray(fg, np.float32).reshape(1, 1, 3)
    b = np.asarray(bg, np.float32).reshape(1, 1, 3)
    if m.dtype == bool:
        return np.where(m[..., None], f, b).astype(np.float32)
    mf = np.clip(m.astype(np.float32), 0.0, 1.0)[..., None]
    return (b + mf * (f - b)).astype(np.float32)


def black_white_targets(direct_mask: np.ndarray, reflected_mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Black-white enhanced targets I_d^e, I_r^e (paper, section 3.4.1, eq. 7-8).

    The direct image's foreground becomes black (0, 0, 0), the reflected
    image's foreground white (1, 1, 1), and both backgrounds light blue
    (0, 0.5, 1), the colour farthest from both black and white.

    Args:
        direct_mask: (H, W) bool (or float coverage in [0, 1]) of the direct image.
        reflected_mask: (H', W') bool (or float) of the reflected image.
    Returns:
        (direct_e (H, W, 3), reflected_e (H', W', 3)) float32 sRGB.
    """
    return _paint(direct_mask, BLACK, LIGHT_BLUE), _paint(reflected_mask, WHITE, LIGHT_BLUE)


def solid_colour_targets(masks: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Solid-colour enhanced targets for the multi-reflection mode (paper, section 4, Fig. 19).

    The foregrounds of the input images are filled with red, green and blue
    in the order given, backgrounds with white. Pass the masks as
    ``[direct, reflected, reflected2]``.

    Args:
        masks: 1 to 3 masks, each (H, W) bool (or float coverage in [0, 1]).
    Returns:
        one (H, W, 3) float32 image per mask.
    """
    if not 1 <= len(masks) <= len(SOLID_COLOURS):
        raise ValueError(f"solid-colour enhancement takes 1 to 3 masks, got {len(masks)}")
    return [_paint(m, c, WHITE) for m, c in zip(masks, SOLID_COLOURS)]
