"""Bilinear texture lookup in the render package's UV convention (numpy only, cheap to import).

u runs left to right, v bottom to top, over the whole texture (u, v in
[0, 1]); texel (row r, column c) of an (H, W) texture has its centre at
``u = (c + 0.5)/W``, ``v = 1 - (r + 0.5)/H``. Lookups outside clamp to the
edge texels. The textured previews (:mod:`saucerfab.render.hard`), the
optimizer's targets and the texture bake (:mod:`saucerfab.fabricate.bake`)
all sample with :func:`sample_bilinear`.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def sample_bilinear(image: np.ndarray, uv: np.ndarray, dtype: Any = None) -> np.ndarray:
    """Bilinear samples of ``image`` at texture coordinates ``uv``, clamp-to-edge.

    Args:
        image: Shape [H, W, C], any numeric type; values are returned on their
            own scale (uint8 stays 0..255).
        uv: Texture coordinates, shape [..., 2] (u left to right, v bottom to top).
        dtype: The float type of the arithmetic and of the result; default the
            image's own float type, float32 for integer images (the bake's
            textures and pages).

    Returns:
        Samples, shape [..., C], ``dtype``.
    """
    img = np.asarray(image)
    if dtype is None:
        dtype = img.dtype if np.issubdtype(img.dtype, np.floating) else np.float32
    hgt, wid = img.shape[:2]
    x = uv[..., 0] * wid - 0.5  # texel centres at u = (c + 0.5)/W
    y = (1.0 - uv[..., 1]) * hgt - 0.5  # row 0 is the top, v = 1
    x0 = np.floor(x)
    y0 = np.floor(y)
    tx = (x - x0).astype(dtype)[..., None]
    ty = (y - y0).astype(dtype)[..., None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, wid - 1), np.clip(x0 + 1, 0, wid - 1)
    ya, yb = np.clip(y0, 0, hgt - 1), np.clip(y0 + 1, 0, hgt - 1)
    f = img if img.dtype == dtype else img.astype(dtype)
    top = f[ya, xa] * (1 - tx) + f[ya, xb] * tx
    bot = f[yb, xa] * (1 - tx) + f[yb, xb] * tx
    return top * (1 - ty) + bot * ty
