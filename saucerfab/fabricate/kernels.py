"""Numba kernels of the texture bake (imported only by :mod:`.bake` when it runs).

Two loops that are gather-heavy and so slow in numpy (5 s and 3 s on a
4096 px atlas, against a few hundred milliseconds here):

* :func:`bake_cells` - per texel of the top region: face and barycentric
  coordinates from the cell fractions, interpolated design uv, bilinear
  texture sample. Its slow reference is
  :func:`saucerfab.fabricate.bake.bake_top_reference`.
* :func:`sor_sweeps` and :func:`residual` - red-black successive
  over-relaxation and the residual of the (masked) Poisson equation, the
  smoother and the residual of the multigrid in
  :func:`saucerfab.fabricate.bake.harmonic_fill`. Their reference is the
  direct sparse solve :func:`saucerfab.fabricate.bake.harmonic_fill_reference`.

Compiled code is cached on disk (``cache=True``), so only the first run on a
machine pays the compile time (about 2 s).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=False)
def bake_cells(
    col_j: np.ndarray,
    col_fx: np.ndarray,
    row_i: np.ndarray,
    row_fy: np.ndarray,
    n: int,
    face_uvs: np.ndarray,
    face_view: np.ndarray,
    texture: np.ndarray,
    out_rgb: np.ndarray,
    out_known: np.ndarray,
) -> None:
    """Fill ``out_rgb`` (h, w, 3) float32 and ``out_known`` (h, w) bool.

    Args:
        col_j, col_fx: (w,) cell column and fraction along +x of each texel column.
        row_i, row_fy: (h,) cell row and fraction along +y of each texel row.
        n: grid vertices per side.
        face_uvs: (F, 3, 2) float32 design texture coordinates per corner.
        face_view: (F,) uint8 FaceView; 0 (NEITHER) marks unknown texels.
        texture: (H, W, 3) float32 design texture, sRGB values 0..255.
    """
    th, tw = texture.shape[0], texture.shape[1]
    h, w = out_rgb.shape[0], out_rgb.shape[1]
    for r in prange(h):
        i = row_i[r]
        fy = row_fy[r]
        for c in range(w):
            fx = col_fx[c]
            k = i * (n - 1) + col_j[c]
            if fy > fx:  # (a, c, d) above the cell diagonal
                f = 2 * k + 1
                w0 = 1.0 - fy
                w1 = fx
                w2 = fy - fx
            else:  # (a, b, c)
                f = 2 * k
                w0 = 1.0 - fx
                w1 = fx - fy
                w2 = fy
            u = w0 * face_uvs[f, 0, 0] + w1 * face_uvs[f, 1, 0] + w2 * face_uvs[f, 2, 0]
            v = w0 * face_uvs[f, 0, 1] + w1 * face_uvs[f, 1, 1] + w2 * face_uvs[f, 2, 1]
            x = u * tw - 0.5
            y = (1.0 - v) * th - 0.5
            x0 = math.floor(x)
            y0 = math.floor(y)
            tx = x - x0
            ty = y - y0
            xa = min(max(int(x0), 0), tw - 1)
            xb = min(max(int(x0) + 1, 0), tw - 1)
            ya = min(max(int(y0), 0), th - 1)
            yb = min(max(int(y0) + 1, 0), th - 1)
            for ch in range(3):
                top = texture[ya, xa, ch] * (1.0 - tx) + texture[ya, xb, ch] * tx
                bot = texture[yb, xa, ch] * (1.0 - tx) + texture[yb, xb, ch] * tx
                out_rgb[r, c, ch] = top * (1.0 - ty) + bot * ty
            out_known[r, c] = face_view[f] != 0


@njit(parallel=True, cache=True)
def sor_sweeps(x: np.ndarray, rhs: np.ndarray, known: np.ndarray, sweeps: int, omega: float) -> None:
    """In-place red-black SOR sweeps of ``deg(p) x_p - sum_{q~p} x_q = rhs_p`` on unknown texels.

    4-neighbours inside the array only (zero normal derivative at the edge;
    ``deg`` is 2, 3 or 4). Rows of one colour are independent, so each
    half-sweep runs in parallel over rows.

    Args:
        x: (h, w, C) float32 values; known texels are never changed.
        rhs: (h, w, C) float32 right-hand side (zero for Laplace's equation).
        known: (h, w) bool.
    """
    h, w, nc = x.shape
    for _ in range(sweeps):
        for colour in range(2):
            for r in prange(h):
                for c in range((r + colour) % 2, w, 2):
                    if known[r, c]:
                        continue
                    for ch in range(nc):
                        s = rhs[r, c, ch]
                        cnt = 0
                        if r > 0:
                            s += x[r - 1, c, ch]
                            cnt += 1
                        if r < h - 1:
                            s += x[r + 1, c, ch]
                            cnt += 1
                        if c > 0:
                            s += x[r, c - 1, ch]
                            cnt += 1
                        if c < w - 1:
                            s += x[r, c + 1, ch]
                            cnt += 1
                        x[r, c, ch] += omega * (s / cnt - x[r, c, ch])


@njit(parallel=True, cache=True)
def residual(x: np.ndarray, rhs: np.ndarray, known: np.ndarray, out: np.ndarray) -> None:
    """``out = rhs - (deg x - sum of neighbours)`` on unknown texels, 0 on known ones."""
    h, w, nc = x.shape
    for r in prange(h):
        for c in range(w):
            for ch in range(nc):
                if known[r, c]:
                    out[r, c, ch] = 0.0
                    continue
                s = 0.0
                cnt = 0
                if r > 0:
                    s += x[r - 1, c, ch]
                    cnt += 1
                if r < h - 1:
                    s += x[r + 1, c, ch]
                    cnt += 1
                if c > 0:
                    s += x[r, c - 1, ch]
                    cnt += 1
                if c < w - 1:
                    s += x[r, c + 1, ch]
                    cnt += 1
                out[r, c, ch] = rhs[r, c, ch] - (cnt * x[r, c, ch] - s)
