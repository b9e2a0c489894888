"""Texels under 2-D triangles: which texel centres a triangle covers, with their barycentric coordinates.

Shared by the design's texturing (:mod:`saucerfab.optimize.texturing`: a face's
image in a picture panel) and the export's paint of the surfaces around the
top (:mod:`saucerfab.fabricate.sides`: a chart's triangle on the atlas page).
Pure numpy, vectorised over triangles in chunks.
"""

from __future__ import annotations

import numpy as np


#: texel candidates (row spans, one texel wider each side) one chunk may hold
CHUNK_TEXELS = 1 << 22


def raster_triangles_2d(
    tri: np.ndarray, width: int, height: int, chunk: int = 4096
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel centres inside 2-D triangles.

    Row by row: each row of a triangle's box is cut to the span between its
    edges (one texel wider each side), and only those texels are tested, so
    the work follows the texels covered, not the boxes (a long thin chart
    triangle lying diagonally on an atlas page has a box thousands of times
    its area). :func:`raster_triangles_2d_reference` tests every texel of
    every box; the two return the same arrays.

    Args:
        tri: (M, 3, 2) triangle corners in continuous pixel coordinates
            ``(column, row)``; texel (i, j)'s centre is (j + 0.5, i + 0.5).
        width, height: image size; texels outside are skipped.
        chunk: triangles per chunk at most.
    Returns:
        ``(flat_pixel (K,), tri_index (K,), bary (K, 3))``, ordered by
        triangle, then by row and column; a texel on a shared edge may be
        reported for both triangles.
    """
    tri = np.asarray(tri, np.float64)
    m = tri.shape[0]
    if m == 0:
        return _empty()
    lo, hi = _boxes(tri, width, height)
    pix_all, idx_all, bary_all = [], [], []
    start = 0
    while start < m:
        end = min(start + chunk, m)
        sel = np.arange(start, end)
        rows = tri[sel]
        ys = np.repeat(sel, hi[sel, 1] - lo[sel, 1] + 1)  # triangle of each (triangle, row) pair
        first = np.cumsum(hi[sel, 1] - lo[sel, 1] + 1) - (hi[sel, 1] - lo[sel, 1] + 1)
        row = lo[ys, 1] + (np.arange(ys.size) - np.repeat(first, hi[sel, 1] - lo[sel, 1] + 1))
        x0, x1 = _row_spans(rows[ys - start], row + 0.5)
        # a row the triangle misses has an empty (infinite) span: bounded before the cast, still empty
        x0, x1 = np.clip(x0, -2.0, width + 2.0), np.clip(x1, -2.0, width + 2.0)
        c0 = np.maximum(np.floor(x0 - 0.5).astype(np.int64) - 1, lo[ys, 0])
        c1 = np.minimum(np.ceil(x1 - 0.5).astype(np.int64) + 1, hi[ys, 0])
        n = np.maximum(c1 - c0 + 1, 0)
        if int(n.sum()) > CHUNK_TEXELS and end - start > 1:
            chunk = max(1, (end - start) // 2)  # too many candidates: smaller chunks from here
            continue
        k = np.repeat(np.arange(ys.size), n)
        col = c0[k] + (np.arange(k.size) - np.repeat(np.cumsum(n) - n, n))
        px, py = col, row[k]
        w0, w1, w2, keep = _inside(tri[ys[k]], px + 0.5, py + 0.5)
        pix_all.append(py[keep] * width + px[keep])
        idx_all.append(ys[k][keep])
        bary_all.append(np.stack([w0[keep], w1[keep], w2[keep]], axis=1))
        start = end
    return np.concatenate(pix_all), np.concatenate(idx_all), np.concatenate(bary_all)


def raster_triangles_2d_reference(
    tri: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`raster_triangles_2d` the obvious way: every texel of each triangle's box tested (the tests' reference)."""
    tri = np.asarray(tri, np.float64)
    if tri.shape[0] == 0:
        return _empty()
    lo, hi = _boxes(tri, width, height)
    pix_all, idx_all, bary_all = [], [], []
    for k in range(tri.shape[0]):
        gy, gx = np.mgrid[lo[k, 1]:hi[k, 1] + 1, lo[k, 0]:hi[k, 0] + 1]
        px, py = gx.ravel(), gy.ravel()
        w0, w1, w2, keep = _inside(np.repeat(tri[k:k + 1], px.size, axis=0), px + 0.5, py + 0.5)
        pix_all.append(py[keep] * width + px[keep])
        idx_all.append(np.full(int(keep.sum()), k, np.int64))
        bary_all.append(np.stack([w0[keep], w1[keep], w2[keep]], axis=1))
    return np.concatenate(pix_all), np.concatenate(idx_all), np.concatenate(bary_all)


def _empty() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))


def _boxes(tri: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's texel box, clipped to the image: ``lo``, ``hi`` (M, 2) ``(column, row)``, inclusive."""
    lo = np.clip(np.floor(tri.min(axis=1) - 0.5).astype(np.int64), 0, [width - 1, height - 1])
    hi = np.clip(np.ceil(tri.max(axis=1) - 0.5).astype(np.int64), 0, [width - 1, height - 1])
    return lo, hi


def _row_spans(t: np.ndarray, cy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the horizontal line ``y = cy`` (P,) crosses triangles ``t`` (P, 3, 2): ``(x_min, x_max)`` (P,).

    A line that misses a triangle gets an empty span (``x_min > x_max``); a
    degenerate one its whole box (the exact test decides).
    """
    x_min = np.full(cy.shape, np.inf)
    x_max = np.full(cy.shape, -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = t[:, i], t[:, j]
        y_lo, y_hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
        crosses = (cy >= y_lo) & (cy <= y_hi)
        dy = b[:, 1] - a[:, 1]
        flat = np.abs(dy) < 1e-12
        f = np.where(flat, 0.0, (cy - a[:, 1]) / np.where(flat, 1.0, dy))
        x = a[:, 0] + f * (b[:, 0] - a[:, 0])
        xa = np.where(flat, np.minimum(a[:, 0], b[:, 0]), x)
        xb = np.where(flat, np.maximum(a[:, 0], b[:, 0]), x)
        x_min = np.where(crosses, np.minimum(x_min, xa), x_min)
        x_max = np.where(crosses, np.maximum(x_max, xb), x_max)
    return x_min, x_max


def _inside(t: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Barycentrics ``w0, w1, w2`` (P,) of points (cx, cy) in triangles ``t`` (P, 3, 2), and which lie inside."""
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    ok_tri = np.abs(den) > 1e-12
    den = np.where(ok_tri, den, 1.0)
    w0 = ((b[:, 1] - c[:, 1]) * (cx - c[:, 0]) + (c[:, 0] - b[:, 0]) * (cy - c[:, 1])) / den
    w1 = ((c[:, 1] - a[:, 1]) * (cx - c[:, 0]) + (a[:, 0] - c[:, 0]) * (cy - c[:, 1])) / den
    w2 = 1 - w0 - w1
    eps = -1e-9
    return w0, w1, w2, ok_tri & (w0 >= eps) & (w1 >= eps) & (w2 >= eps)
