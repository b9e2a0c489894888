"""What the soft rasterizer's dispatcher and both backends share: SoftRas's constants and parameters.

:mod:`saucerfab.render.soft` (the public op, which checks the arguments and
picks a backend), :mod:`saucerfab.render.soft_torch` and
:mod:`saucerfab.render.soft_numba` all import this module and nothing from
each other's top level; the formulas these constants belong to are listed in
:mod:`saucerfab.render.soft`'s docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: SoftRas's determinant clamp in its triangle preprocessing (``1e-10``)
DET_EPS = 1e-10
#: SoftRas's clamp of the clipped barycentric sum in ``barycentric_clip`` (``1e-5``)
WSUM_EPS = 1e-5


@dataclass(frozen=True)
class SoftParams:
    """The scalar parameters of one soft rasterization; the defaults are SoftRas's.

    Attributes:
        sigma: SoftRas ``sigma_val``: width of the coverage sigmoid, squared NDC units.
        gamma: SoftRas ``gamma_val``: softmax temperature over normalized inverse depth.
        background: RGB background colour, each in [0, 1].
        near: Near depth, model units.
        far: Far depth, model units.
        eps: Background's normalized inverse depth.
        dist_eps: Coverage below which a pixel-face pair is skipped.
    """

    sigma: float = 1e-5
    gamma: float = 1e-4
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    near: float = 1.0
    far: float = 100.0
    eps: float = 1e-3
    dist_eps: float = 1e-4

    @property
    def threshold(self) -> float:
        """:func:`distance_threshold` of these parameters (squared NDC units)."""
        return distance_threshold(self.sigma, self.dist_eps)


#: SoftRas's defaults (``soft_rasterize``'s keyword defaults read them from here)
DEFAULTS = SoftParams()


def distance_threshold(sigma: float, dist_eps: float) -> float:
    """Squared NDC distance beyond which a pixel outside a face is skipped.

    SoftRas's ``log(1 / dist_eps - 1) * sigma``: the ``d^2`` at which the
    coverage ``sigmoid(-d^2 / sigma)`` equals ``dist_eps``. At the defaults
    (``dist_eps = 1e-4``) it is ``9.21 sigma``: 2.5 pixels of a 512 image at
    ``sigma = 1e-5``, a quarter pixel at ``1e-7``.
    """
    return math.log(1.0 / dist_eps - 1.0) * sigma
