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

Compiled code is cached on disk (``cache=True``, in ``__pycache__`` beside
this file or numba's user cache), so only the first run after installing or
changing this file pays the compile time (5-10 s on two cores). Only the two
kernels that touch every texel of the full atlas run in parallel; the
pyramid helpers are serial, which halves the compile time and costs little
(they run on the half- and quarter-size levels).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange  # prange is a plain range in the serial kernels


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

    ``rhs`` of shape (1, 1, C) means zero (Laplace's equation) and saves
    reading a full-size array of zeros on every sweep.

    4-neighbours inside the array only (zero normal derivative at the edge;
    ``deg`` is 2, 3 or 4). Rows of one colour are independent, so each
    half-sweep runs in parallel over rows.

    Args:
        x: (h, w, C) float32 values; known texels are never changed.
        rhs: (h, w, C) float32 right-hand side (zero for Laplace's equation).
        known: (h, w) bool.
    """
    h, w, nc = x.shape
    has_rhs = rhs.shape[0] == h and rhs.shape[1] == w
    for _ in range(sweeps):
        for colour in range(2):
            for r in prange(h):
                up = r > 0
                down = r < h - 1
                for c in range((r + colour) % 2, w, 2):
                    if known[r, c]:
                        continue
                    left = c > 0
                    right = c < w - 1
                    step = omega / (up + down + left + right)
                    for ch in range(nc):
                        s = rhs[r, c, ch] if has_rhs else 0.0
                        if up:
                            s += x[r - 1, c, ch]
                        if down:
                            s += x[r + 1, c, ch]
                        if left:
                            s += x[r, c - 1, ch]
                        if right:
                            s += x[r, c + 1, ch]
                        x[r, c, ch] = (1.0 - omega) * x[r, c, ch] + step * s


@njit(cache=True)
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


@njit(cache=True)
def coarsen(values: np.ndarray, known: np.ndarray, out: np.ndarray, out_known: np.ndarray, mean: bool) -> None:
    """One level down the pyramid: each coarse texel from its 2x2 children (those inside the array).

    ``mean``: ``out`` = mean of the known children, ``out_known`` = any child known
    (:func:`pool_known`); otherwise ``out`` = sum of all children, ``out_known`` =
    all children known (:func:`restrict_sum`). Shapes: ``values`` (h, w, C),
    ``out`` (ceil(h/2), ceil(w/2), C).
    """
    h, w, nc = values.shape
    ch, cw = out_known.shape
    for r in prange(ch):
        for c in range(cw):
            cnt = 0  # known children
            allk = True
            for ch_ in range(nc):
                out[r, c, ch_] = 0.0
            for dr in range(2):
                for dc in range(2):
                    rr = 2 * r + dr
                    cc = 2 * c + dc
                    if rr < h and cc < w:
                        if known[rr, cc]:
                            cnt += 1
                        else:
                            allk = False
                        if known[rr, cc] or not mean:
                            for ch_ in range(nc):
                                out[r, c, ch_] += values[rr, cc, ch_]
            if mean:
                out_known[r, c] = cnt > 0
                if cnt > 0:
                    for ch_ in range(nc):
                        out[r, c, ch_] /= cnt
            else:
                out_known[r, c] = allk


@njit(cache=True)
def pool_known(values: np.ndarray, known: np.ndarray, out: np.ndarray, out_known: np.ndarray) -> None:
    """2x2 pooling: ``out`` = mean of the known children, ``out_known`` = any child known.

    ``out`` is (ceil(h/2), ceil(w/2), C); children outside the array count as unknown.
    """
    coarsen(values, known, out, out_known, True)


@njit(cache=True)
def restrict_sum(r_fine: np.ndarray, known: np.ndarray, out: np.ndarray, out_known: np.ndarray) -> None:
    """2x2 restriction: ``out`` = sum of the children, ``out_known`` = all (existing) children known."""
    coarsen(r_fine, known, out, out_known, False)


@njit(cache=True)
def upsample_unknown(coarse: np.ndarray, known: np.ndarray, base: np.ndarray, out: np.ndarray) -> None:
    """``out`` = ``base`` on known texels, the bilinear 2x upsampling of ``coarse`` elsewhere.

    Cell-centred grids: fine texel i sits at coarse coordinate (i + 0.5) / 2 - 0.5.
    """
    h, w, nc = out.shape
    chh, cww = coarse.shape[0], coarse.shape[1]
    for r in prange(h):
        y = min(max((r + 0.5) / 2.0 - 0.5, 0.0), chh - 1.0)
        y0 = min(int(math.floor(y)), max(chh - 2, 0))
        y1 = min(y0 + 1, chh - 1)
        ty = y - y0
        for c in range(w):
            if known[r, c]:
                for k in range(nc):
                    out[r, c, k] = base[r, c, k]
                continue
            x = min(max((c + 0.5) / 2.0 - 0.5, 0.0), cww - 1.0)
            x0 = min(int(math.floor(x)), max(cww - 2, 0))
            x1 = min(x0 + 1, cww - 1)
            tx = x - x0
            for k in range(nc):
                a = coarse[y0, x0, k] * (1.0 - tx) + coarse[y0, x1, k] * tx
                b = coarse[y1, x0, k] * (1.0 - tx) + coarse[y1, x1, k] * tx
                out[r, c, k] = a * (1.0 - ty) + b * ty


@njit(cache=True)
def row_dots(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out[r, k] = sum_c a[r, c, k] * b[r, c, k]`` in float64 (sum the rows for the dot product)."""
    h, w, nc = a.shape
    for r in prange(h):
        for k in range(nc):
            s = 0.0
            for c in range(w):
                s += np.float64(a[r, c, k]) * np.float64(b[r, c, k])
            out[r, k] = s


def warm_up() -> list[str]:
    """Compile (or load from the cache) every kernel on tiny inputs; returns their names.

    For installers and CI images: run once after installing so the first
    export does not pay the compile time.
    """
    f32 = np.float32
    x = np.zeros((6, 6, 3), f32)
    known = np.zeros((6, 6), bool)
    known[0, 0] = True
    coarse = np.zeros((3, 3, 3), f32)
    coarse_known = np.zeros((3, 3), bool)
    bake_cells(
        np.zeros(6, np.int64), np.zeros(6), np.zeros(6, np.int64), np.zeros(6), 2,
        np.zeros((2, 3, 2), f32), np.zeros(2, np.uint8), np.zeros((4, 4, 3), f32), x.copy(), known.copy(),
    )
    sor_sweeps(x, x.copy(), known, 1, 1.5)
    sor_sweeps(x, np.zeros((1, 1, 3), f32), known, 1, 1.5)
    residual(x, x.copy(), known, x.copy())
    coarsen(x, known, coarse, coarse_known, True)
    pool_known(x, known, coarse, coarse_known)
    restrict_sum(x, known, coarse, coarse_known)
    upsample_unknown(coarse, known, x, x.copy())
    row_dots(x, x, np.zeros((6, 3)))
    return [
        "bake_cells", "sor_sweeps", "residual", "coarsen", "pool_known", "restrict_sum", "upsample_unknown", "row_dots"
    ]
