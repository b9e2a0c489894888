"""Compiled CPU kernels of the soft rasterizer (numba), wrapped in a torch autograd Function.

The formulas are :mod:`saucerfab.render.soft`'s; this module only organises
the work. torch projects the vertices (``Camera.project_torch``, autograd);
the Function takes the projected vertices (V, 3) and the face colours and
returns the image and alpha; its backward returns dL/d(projected vertices)
and dL/dcolours, and autograd carries the former through the projection.

* Per-face setup (:func:`_face_setup`): corners, SoftRas's barycentric matrix
  (adjugate / clamped determinant) and inverse corner depths. Its chain rule
  (:func:`_face_grads`) and the scatter to vertices run in numba too: a few
  dozen small torch ops per call cost more than the setup itself.
* Faces are binned into tiles of ``TILE_H x TILE_W`` pixels by their bounding
  boxes widened by the influence radius. Every tile is owned whole by one
  thread (``prange`` over tiles, busiest first, dealt one tile at a time as
  threads come free: :func:`_one_tile_chunks`), so pixels are written without
  atomics, and the result does not depend on the thread count or schedule.
  The gradient of each (face, tile) entry goes to its own slot; a face's slots
  are summed in a fixed order afterwards.
* The innermost loop runs over the pixels of one row of a face's box in whole
  groups of ``LANES``, branch-free (selects and masks; lanes past the box are
  masked out like skipped pairs), indexing one tile-local state array through
  a view with compile-time field offsets, and uses
  :func:`saucerfab.render._simd.vexp` instead of libm's exp: LLVM vectorizes it
  (AVX2: 8 float32 / 4 float64 lanes). ``error_model="numpy"`` removes the
  division-by-zero checks that would otherwise block that; ``fastmath`` is
  limited to FMA contraction (and reassociation in the lane sums of the
  backward), which keeps float64 results within 1e-12 of the torch backend.
* The forward keeps per pixel the softmax maximum and sum and the alpha
  product, and per (entry, row) the first and last lane whose pair is not
  skipped; the backward recomputes each pair's geometry on those lanes only
  (cheaper than storing millions of pairs).
* float32 denormals are flushed to zero on the worker threads while they
  render a tile (MXCSR restored afterwards).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit, prange, set_parallel_chunksize

from saucerfab.render._simd import ftz_on, ftz_restore, vexp
from saucerfab.render.soft import DET_EPS, WSUM_EPS, distance_threshold

if TYPE_CHECKING:
    import torch

    from saucerfab.render.camera import Camera

#: pixels per vectorized inner loop: one AVX2 register of float32
LANES = 8
#: tile size in pixels (wide: few faces' column spans are cut in two; the float64
#: state, 6 fields x TILE_H x SW x 8 bytes = 110 KiB, stays in L2)
TILE_W = 64
TILE_H = 32
#: row stride of the tile-local state: room for a lane group starting at the last column
SW = TILE_W + LANES
#: distance between the fields of the tile-local state
NLOC = TILE_H * SW
#: per-column gradient accumulators of the backward
N_ACC = 18
#: gradient slots per (face, tile): 6 corner xy, 9 barycentric matrix, 3 inverse depths, 3 colours
N_GRAD = 21

# index of each constant in the parameter vector K handed to the kernels
K_THR, K_INV_SIGMA, K_NEAR, K_FAR, K_INV_FR, K_INV_GAMMA, K_EPS, K_SUM0, K_BG = 0, 1, 2, 3, 4, 5, 6, 7, 8
K_WSUM, K_EE_MIN, K_ZERO, K_ONE, N_K = 11, 12, 13, 14, 15

_OPTS: dict[str, Any] = dict(error_model="numpy", cache=True, nogil=True, fastmath={"contract"})


# --------------------------------------------------------------------------- binning


@njit(**_OPTS)
def _face_boxes(cxy: np.ndarray, radius: float, size: int) -> np.ndarray:  # pragma: no cover - jit
    """(F, 4) int32 inclusive pixel boxes (row0, row1, col0, col1) of the widened faces.

    The same formula as :func:`saucerfab.render.soft_torch.face_pixel_boxes`
    (float64); an empty box has row1 < row0.
    """
    n = cxy.shape[0]
    out = np.empty((n, 4), np.int32)
    s = float(size)
    for f in range(n):
        x0, y0 = float(cxy[f, 0]), float(cxy[f, 1])
        x1, y1 = float(cxy[f, 2]), float(cxy[f, 3])
        x2, y2 = float(cxy[f, 4]), float(cxy[f, 5])
        lox, hix = min(x0, x1, x2), max(x0, x1, x2)
        loy, hiy = min(y0, y1, y2), max(y0, y1, y2)
        if not (np.isfinite(lox) and np.isfinite(hix) and np.isfinite(loy) and np.isfinite(hiy)):
            out[f, 0], out[f, 1], out[f, 2], out[f, 3] = 0, -1, 0, -1
            continue
        # clamp before rounding so far-off faces cannot overflow the integers
        c0 = math.ceil(min(max(((lox - radius + 1) * s - 1) / 2, -1.0), s))
        c1 = math.floor(min(max(((hix + radius + 1) * s - 1) / 2, -1.0), s))
        r0 = math.ceil(min(max(((1 - hiy - radius) * s - 1) / 2, -1.0), s))
        r1 = math.floor(min(max(((1 - loy + radius) * s - 1) / 2, -1.0), s))
        out[f, 0] = max(r0, 0)
        out[f, 1] = min(r1, size - 1)
        out[f, 2] = max(c0, 0)
        out[f, 3] = min(c1, size - 1)
    return out


@njit(**_OPTS)
def _bin_faces(box: np.ndarray, n_ty: int, n_tx: int):  # type: ignore[no-untyped-def] # pragma: no cover
    """Bin faces into tiles.

    Returns ``(tile_start (T+1,), tile_entry (E,), entry_face (E,), face_start (F+1,),
    row_start (E+1,))``: entry ids are numbered face by face (a face's entries are
    contiguous, so its gradient slots are summed in a fixed order), each tile's
    entries are in increasing face order, and entry e's rows within its tile have
    the slots row_start[e] .. row_start[e+1]-1 of the per-row valid ranges.
    """
    n = box.shape[0]
    n_tiles = n_ty * n_tx
    count = np.zeros(n_tiles + 1, np.int64)
    face_start = np.zeros(n + 1, np.int64)
    for f in range(n):
        r0, r1, c0, c1 = box[f, 0], box[f, 1], box[f, 2], box[f, 3]
        k = 0
        if r1 >= r0 and c1 >= c0:
            for ty in range(r0 // TILE_H, r1 // TILE_H + 1):
                for tx in range(c0 // TILE_W, c1 // TILE_W + 1):
                    count[ty * n_tx + tx + 1] += 1
                    k += 1
        face_start[f + 1] = face_start[f] + k
    tile_start = np.cumsum(count)
    n_entries = face_start[n]
    tile_entry = np.empty(n_entries, np.int64)
    entry_face = np.empty(n_entries, np.int64)
    row_start = np.zeros(n_entries + 1, np.int64)
    fill = tile_start[:-1].copy()
    e = 0
    for f in range(n):
        r0, r1, c0, c1 = box[f, 0], box[f, 1], box[f, 2], box[f, 3]
        if r1 >= r0 and c1 >= c0:
            for ty in range(r0 // TILE_H, r1 // TILE_H + 1):
                for tx in range(c0 // TILE_W, c1 // TILE_W + 1):
                    t = ty * n_tx + tx
                    tile_entry[fill[t]] = e
                    fill[t] += 1
                    entry_face[e] = f
                    rows = min(r1, ty * TILE_H + TILE_H - 1) - max(r0, ty * TILE_H) + 1
                    row_start[e + 1] = row_start[e] + rows
                    e += 1
    return tile_start, tile_entry, entry_face, face_start, row_start


# --------------------------------------------------------------------------- forward
#
# Tile-local per-pixel state: one array, field k of pixel (row i, column j of
# the tile) at k * NLOC + i * SW + j. One array with fields a compile-time
# constant apart lets LLVM prove the accesses independent; separate arrays
# would each need a run-time overlap check, more than it will emit. Rows are
# SW = TILE_W + LANES wide: a face's span of columns is processed in whole
# lane groups from its first column, and the lanes past the tile's last
# column land in the padding, which is never read back.


@njit(**_OPTS)
def _face_consts(f, cxy, ee_min, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Corner x, y and edge vectors of face f, and 1/|edge|^2 (degenerate edges
    project onto their start, as the torch backend's clamp makes them)."""
    ax0, ay0, ax1, ay1, ax2, ay2 = cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5]
    ex0, ey0 = ax1 - ax0, ay1 - ay0
    ex1, ey1 = ax2 - ax1, ay2 - ay1
    ex2, ey2 = ax0 - ax2, ay0 - ay2
    ie0 = one / max(ex0 * ex0 + ey0 * ey0, ee_min)
    ie1 = one / max(ex1 * ex1 + ey1 * ey1, ee_min)
    ie2 = one / max(ex2 * ex2 + ey2 * ey2, ee_min)
    return ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2


@njit(**_OPTS)
def _forward_tile(
    t, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab, K,
    image, alpha, st_m, st_s, st_p, row_lo, row_hi,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Render tile ``t``: write ``image``/``alpha``, the backward's per-pixel state and,
    per (entry, row), the first and last lane where the pair is not skipped."""
    ty, tx = t // n_tx, t % n_tx
    rt0, ct0 = ty * TILE_H, tx * TILE_W
    zero, one = K[K_ZERO], K[K_ONE]
    thr, inv_sigma, near, far = K[K_THR], K[K_INV_SIGMA], K[K_NEAR], K[K_FAR]
    inv_fr, inv_gamma, wsum_min, ee_min = K[K_INV_FR], K[K_INV_GAMMA], K[K_WSUM], K[K_EE_MIN]
    # fields: 0 running max, 1 running sum, 2-4 colour sums, 5 prod(1 - D).
    # SoftRas's start: maximum eps, sum exp(eps/gamma), colour background * sum.
    st = np.empty(6 * NLOC, K.dtype)
    for q in range(NLOC):
        st[q] = K[K_EPS]
        st[NLOC + q] = K[K_SUM0]
        st[2 * NLOC + q] = K[K_BG] * K[K_SUM0]
        st[3 * NLOC + q] = K[K_BG + 1] * K[K_SUM0]
        st[4 * NLOC + q] = K[K_BG + 2] * K[K_SUM0]
        st[5 * NLOC + q] = one

    for idx in range(tile_start[t], tile_start[t + 1]):
        entry = tile_entry[idx]
        f = entry_face[entry]
        ra, rb = max(box[f, 0], rt0), min(box[f, 1], rt0 + TILE_H - 1)
        ca, cbx = max(box[f, 2], ct0), min(box[f, 3], ct0 + TILE_W - 1)
        if rb < ra or cbx < ca:
            continue
        ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2 = _face_consts(
            f, cxy, ee_min, one
        )
        i00, i01, i02 = inv[f, 0], inv[f, 1], inv[f, 2]
        i10, i11, i12 = inv[f, 3], inv[f, 4], inv[f, 5]
        i20, i21, i22 = inv[f, 6], inv[f, 7], inv[f, 8]
        iz0, iz1, iz2 = iz[f, 0], iz[f, 1], iz[f, 2]
        fr, fg, fb = col[f, 0], col[f, 1], col[f, 2]
        # whole lane groups: a fixed-width loop without remainder; lanes past
        # the box (the last group's tail) are masked out like skipped pairs
        span = np.int32(cbx - ca + 1)
        n = (cbx - ca + LANES) // LANES * LANES
        n32, m32 = np.int32(n), np.int32(-1)
        pxv = px_tab[ca:]
        rs = row_start[entry] - ra
        for r in range(ra, rb + 1):
            py = py_tab[r]
            b0 = i01 * py + i02
            b1 = i11 * py + i12
            b2 = i21 * py + i22
            hy0, hy1, hy2 = py - ay0, py - ay1, py - ay2
            # a view indexed by the loop counter plus constants: no negative-index
            # wraparound, so LLVM sees unit-stride accesses and vectorizes
            sv = st[(r - rt0) * SW + (ca - ct0):]
            lo, hi = n32, m32
            for lane in range(n):
                px = pxv[lane]
                w0 = i00 * px + b0
                w1 = i10 * px + b1
                w2 = i20 * px + b2
                inside = (w0 > zero) & (w0 < one) & (w1 > zero) & (w1 < one) & (w2 > zero) & (w2 < one)
                # squared distance to the closed triangle = nearest of the three segments
                hx = px - ax0
                tt = min(max((hx * ex0 + hy0 * ey0) * ie0, zero), one)
                dx, dy = tt * ex0 - hx, tt * ey0 - hy0
                d2 = dx * dx + dy * dy
                hx = px - ax1
                tt = min(max((hx * ex1 + hy1 * ey1) * ie1, zero), one)
                dx, dy = tt * ex1 - hx, tt * ey1 - hy1
                d2 = min(d2, dx * dx + dy * dy)
                hx = px - ax2
                tt = min(max((hx * ex2 + hy2 * ey2) * ie2, zero), one)
                dx, dy = tt * ex2 - hx, tt * ey2 - hy2
                d2 = min(d2, dx * dx + dy * dy)
                # int32 lane numbers: 64-bit ones would halve the vector width
                l32 = np.int32(lane)
                valid = (inside | (d2 < thr)) & (l32 < span)
                lo = min(lo, l32 if valid else n32)
                hi = max(hi, l32 if valid else m32)
                xs = (d2 if inside else -d2) * inv_sigma
                ex = vexp(-abs(xs))
                rec = one / (one + ex)
                erec = ex * rec
                cov = rec if xs >= zero else erec  # sigmoid(xs)
                unc = erec if xs >= zero else rec  # 1 - sigmoid(xs)
                sv[5 * NLOC + lane] = sv[5 * NLOC + lane] * (unc if valid else one)
                # perspective-correct depth from the clipped barycentrics
                wc0 = min(max(w0, zero), one)
                wc1 = min(max(w1, zero), one)
                wc2 = min(max(w2, zero), one)
                sw = max(wc0 + wc1 + wc2, wsum_min)
                z = sw / (wc0 * iz0 + wc1 * iz1 + wc2 * iz2)
                rgb = valid & (z >= near) & (z <= far)
                zn = (far - z) * inv_fr
                # online softmax with SoftRas's running maximum, one exp per pair
                mo = sv[lane]
                dz = zn - mo
                e = vexp(-abs(dz) * inv_gamma)
                newmax = rgb & (dz > zero)
                scale = e if newmax else one
                term = (one if newmax else e) * cov
                term = term if rgb else zero
                sv[lane] = zn if newmax else mo
                sv[NLOC + lane] = sv[NLOC + lane] * scale + term
                sv[2 * NLOC + lane] = sv[2 * NLOC + lane] * scale + term * fr
                sv[3 * NLOC + lane] = sv[3 * NLOC + lane] * scale + term * fg
                sv[4 * NLOC + lane] = sv[4 * NLOC + lane] * scale + term * fb
            # the backward needs only the lanes from lo to hi of this row
            row_lo[rs + r] = lo
            row_hi[rs + r] = hi

    for r in range(rt0, min(rt0 + TILE_H, size)):
        for c in range(ct0, min(ct0 + TILE_W, size)):
            q = (r - rt0) * SW + (c - ct0)
            g = r * wp + c
            rs = one / st[NLOC + q]
            image[r, c, 0] = st[2 * NLOC + q] * rs
            image[r, c, 1] = st[3 * NLOC + q] * rs
            image[r, c, 2] = st[4 * NLOC + q] * rs
            alpha[r, c] = one - st[5 * NLOC + q]
            st_m[g] = st[q]
            st_s[g] = st[NLOC + q]
            st_p[g] = st[5 * NLOC + q]


@njit(parallel=True, **_OPTS)
def _forward(
    order, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab,
    K, image, alpha, st_m, st_s, st_p, row_lo, row_hi,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    # run under _one_tile_chunks (see there)
    for k in prange(order.shape[0]):
        old = ftz_on()
        _forward_tile(
            order[k], n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col,
            px_tab, py_tab, K, image, alpha, st_m, st_s, st_p, row_lo, row_hi,
        )
        ftz_restore(old)


# --------------------------------------------------------------------------- backward


@njit(error_model="numpy", cache=True, nogil=True, fastmath={"contract", "reassoc"})
def _lane_sum(a, n):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """sum(a[:n]); reassociation lets LLVM vectorize it (same code, same order: deterministic)."""
    tot = a[0] - a[0]
    for k in range(n):
        tot += a[k]
    return tot


@njit(error_model="numpy", cache=True, nogil=True, fastmath={"contract", "reassoc"})
def _lane_dot(a, b, n):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """sum(a[:n] * b[:n]), vectorized as :func:`_lane_sum`."""
    tot = a[0] - a[0]
    for k in range(n):
        tot += a[k] * b[k]
    return tot


@njit(**_OPTS)
def _backward_tile(
    t, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab, K,
    image, g_image, g_alpha, st_m, st_s, st_p, row_lo, row_hi, grad,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Gradients of tile ``t``'s pixels into the slots ``grad[entry]`` of its entries."""
    ty, tx = t // n_tx, t % n_tx
    rt0, ct0 = ty * TILE_H, tx * TILE_W
    zero, one = K[K_ZERO], K[K_ONE]
    two = one + one
    thr, inv_sigma, near, far = K[K_THR], K[K_INV_SIGMA], K[K_NEAR], K[K_FAR]
    inv_fr, inv_gamma, wsum_min, ee_min = K[K_INV_FR], K[K_INV_GAMMA], K[K_WSUM], K[K_EE_MIN]
    # fields (layout as in _forward_tile): 0 the softmax maximum, 1-3 dL/dimage / sum,
    # 4 sum_k dL/dimage_k image_k / sum, 5 dL/dalpha * prod(1 - D)
    st = np.zeros(6 * NLOC, K.dtype)
    for r in range(rt0, min(rt0 + TILE_H, size)):
        for c in range(ct0, min(ct0 + TILE_W, size)):
            q = (r - rt0) * SW + (c - ct0)
            g = r * wp + c
            rs = one / st_s[g]
            a0, a1, a2 = g_image[r, c, 0] * rs, g_image[r, c, 1] * rs, g_image[r, c, 2] * rs
            st[q] = st_m[g]
            st[NLOC + q], st[2 * NLOC + q], st[3 * NLOC + q] = a0, a1, a2
            st[4 * NLOC + q] = a0 * image[r, c, 0] + a1 * image[r, c, 1] + a2 * image[r, c, 2]
            st[5 * NLOC + q] = g_alpha[r, c] * st_p[g]

    # Gradient accumulators per column of the face's span, summed over its rows
    # elementwise (vectorizes without reassociation), reduced once per entry.
    # Slots 0-5: corner x, y; 6-8: sum of dL/dw_k (times px at the reduction:
    # the matrix row's x and constant terms); 9-11: sum of dL/dw_k * py;
    # 12-14: inverse depths; 15-17: colours.
    acc = np.zeros(N_ACC * SW, K.dtype)
    for idx in range(tile_start[t], tile_start[t + 1]):
        entry = tile_entry[idx]
        f = entry_face[entry]
        ra, rb = max(box[f, 0], rt0), min(box[f, 1], rt0 + TILE_H - 1)
        ca, cbx = max(box[f, 2], ct0), min(box[f, 3], ct0 + TILE_W - 1)
        if rb < ra or cbx < ca:
            for j in range(N_GRAD):
                grad[entry, j] = zero
            continue
        # a row's lanes start at its first unskipped pair (the forward's row_lo)
        # and may run up to LANES - 1 past the box; m covers every row's lanes
        m = min(cbx - ca + LANES, SW - (ca - ct0))
        ac = acc[ca - ct0:]  # accumulator j of column ca + k is ac[j * SW + k]
        for j in range(N_ACC):  # clear only the columns this entry uses
            ac[j * SW:j * SW + m] = zero
        rs = row_start[entry] - ra
        ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2 = _face_consts(
            f, cxy, ee_min, one
        )
        i00, i01, i02 = inv[f, 0], inv[f, 1], inv[f, 2]
        i10, i11, i12 = inv[f, 3], inv[f, 4], inv[f, 5]
        i20, i21, i22 = inv[f, 6], inv[f, 7], inv[f, 8]
        iz0, iz1, iz2 = iz[f, 0], iz[f, 1], iz[f, 2]
        fr, fg, fb = col[f, 0], col[f, 1], col[f, 2]
        for r in range(ra, rb + 1):
            lo, hi = row_lo[rs + r], row_hi[rs + r]
            if hi < lo:
                continue  # every pair of this row is skipped
            n = (hi - lo + LANES) // LANES * LANES
            last = np.int32(hi - lo)
            py = py_tab[r]
            b0 = i01 * py + i02
            b1 = i11 * py + i12
            b2 = i21 * py + i22
            hy0, hy1, hy2 = py - ay0, py - ay1, py - ay2
            sv = st[(r - rt0) * SW + (ca + lo - ct0):]
            av = ac[lo:]
            pxv = px_tab[ca + lo:]
            for lane in range(n):
                px = pxv[lane]
                w0 = i00 * px + b0
                w1 = i10 * px + b1
                w2 = i20 * px + b2
                inside = (w0 > zero) & (w0 < one) & (w1 > zero) & (w1 < one) & (w2 > zero) & (w2 < one)
                # nearest segment, keeping which edge and where on it (t) for the gradient
                hx = px - ax0
                tt = min(max((hx * ex0 + hy0 * ey0) * ie0, zero), one)
                dx, dy = tt * ex0 - hx, tt * ey0 - hy0
                d2 = dx * dx + dy * dy
                bt, bdx, bdy = tt, dx, dy
                hx = px - ax1
                tt = min(max((hx * ex1 + hy1 * ey1) * ie1, zero), one)
                dx, dy = tt * ex1 - hx, tt * ey1 - hy1
                dd = dx * dx + dy * dy
                e1sel = dd < d2
                d2 = dd if e1sel else d2
                bt = tt if e1sel else bt
                bdx = dx if e1sel else bdx
                bdy = dy if e1sel else bdy
                hx = px - ax2
                tt = min(max((hx * ex2 + hy2 * ey2) * ie2, zero), one)
                dx, dy = tt * ex2 - hx, tt * ey2 - hy2
                dd = dx * dx + dy * dy
                e2sel = dd < d2
                d2 = dd if e2sel else d2
                bt = tt if e2sel else bt
                bdx = dx if e2sel else bdx
                bdy = dy if e2sel else bdy
                e1sel = e1sel & (not e2sel)
                e0sel = not (e1sel | e2sel)
                # lanes past hi are pairs the forward masked out (beyond the box)
                valid = (inside | (d2 < thr)) & (np.int32(lane) <= last)
                xs = (d2 if inside else -d2) * inv_sigma
                ex = vexp(-abs(xs))
                rec = one / (one + ex)
                erec = ex * rec
                cov = rec if xs >= zero else erec
                unc = erec if xs >= zero else rec
                wc0 = min(max(w0, zero), one)
                wc1 = min(max(w1, zero), one)
                wc2 = min(max(w2, zero), one)
                rsw = wc0 + wc1 + wc2
                sw = max(rsw, wsum_min)
                rnum = one / (wc0 * iz0 + wc1 * iz1 + wc2 * iz2)
                z = sw * rnum
                rgb = valid & (z >= near) & (z <= far)
                zn = (far - z) * inv_fr
                ez = vexp(min(zn - sv[lane], zero) * inv_gamma)
                wf = cov * ez
                wf = wf if rgb else zero  # the pair's softmax weight, shifted by the max
                gw = sv[NLOC + lane] * fr + sv[2 * NLOC + lane] * fg + sv[3 * NLOC + lane] * fb
                gw = gw - sv[4 * NLOC + lane]  # dL/dweight * sum
                # dL/dxs: alpha through prod(1 - D), colour through the weight
                ga = sv[5 * NLOC + lane] * cov
                gx = (ga if valid else zero) + gw * wf * unc
                gd = two * gx * inv_sigma
                gd = gd if inside else -gd  # d(sign d^2)/d(d^2)
                u, v = gd * bdx, gd * bdy
                omt = one - bt
                k0 = (omt if e0sel else zero) + (bt if e2sel else zero)
                k1 = (omt if e1sel else zero) + (bt if e0sel else zero)
                k2 = (omt if e2sel else zero) + (bt if e1sel else zero)
                av[lane] += u * k0
                av[1 * SW + lane] += v * k0
                av[2 * SW + lane] += u * k1
                av[3 * SW + lane] += v * k1
                av[4 * SW + lane] += u * k2
                av[5 * SW + lane] += v * k2
                # depth: zn = (far - z)/(far - near), z = sw / num, num = sum_k wc_k iz_k,
                # sw = max(sum_k wc_k, wsum_min): with gzr = -dL/dz / num,
                # dL/dnum = gzr z and dL/dsw = -gzr
                gzr = gw * wf * inv_gamma * inv_fr * rnum
                gzr = gzr if rgb else zero
                # masked after the product: z is inf where float32 rounding clips
                # all three barycentrics of a sliver face to 0, and 0 * inf is NaN
                gnum = gzr * z
                gnum = gnum if rgb else zero
                zsub = gzr if rsw >= wsum_min else zero
                gw0 = gnum * iz0 - zsub
                gw1 = gnum * iz1 - zsub
                gw2 = gnum * iz2 - zsub
                # the clamp passes the gradient on [0, 1] (as torch.clamp does)
                gw0 = gw0 if (w0 >= zero) & (w0 <= one) else zero
                gw1 = gw1 if (w1 >= zero) & (w1 <= one) else zero
                gw2 = gw2 if (w2 >= zero) & (w2 <= one) else zero
                av[6 * SW + lane] += gw0
                av[7 * SW + lane] += gw1
                av[8 * SW + lane] += gw2
                av[9 * SW + lane] += gw0 * py
                av[10 * SW + lane] += gw1 * py
                av[11 * SW + lane] += gw2 * py
                av[12 * SW + lane] += gnum * wc0
                av[13 * SW + lane] += gnum * wc1
                av[14 * SW + lane] += gnum * wc2
                av[15 * SW + lane] += sv[NLOC + lane] * wf
                av[16 * SW + lane] += sv[2 * NLOC + lane] * wf
                av[17 * SW + lane] += sv[3 * NLOC + lane] * wf
        pxa = px_tab[ca:]
        for j in range(6):
            grad[entry, j] = _lane_sum(ac[j * SW:], m)
        for k in range(3):  # barycentric matrix row k: (x, y, 1) coefficients
            grad[entry, 6 + 3 * k] = _lane_dot(ac[(6 + k) * SW:], pxa, m)
            grad[entry, 7 + 3 * k] = _lane_sum(ac[(9 + k) * SW:], m)
            grad[entry, 8 + 3 * k] = _lane_sum(ac[(6 + k) * SW:], m)
        for j in range(6):
            grad[entry, 15 + j] = _lane_sum(ac[(12 + j) * SW:], m)


@njit(parallel=True, **_OPTS)
def _backward(
    order, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab,
    K, image, g_image, g_alpha, st_m, st_s, st_p, row_lo, row_hi, grad,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    # run under _one_tile_chunks (see there)
    for k in prange(order.shape[0]):
        old = ftz_on()
        _backward_tile(
            order[k], n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col,
            px_tab, py_tab, K, image, g_image, g_alpha, st_m, st_s, st_p, row_lo, row_hi, grad,
        )
        ftz_restore(old)


# --------------------------------------------------------------------------- per-face setup and chain rule


@njit(parallel=True, **_OPTS)
def _face_setup(proj, faces, det_eps):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Per-face kernel inputs from the projected vertices (V, 3) = (x_ndc, y_ndc, depth).

    Returns corners ``cxy`` (F, 6), SoftRas's barycentric matrix ``inv`` (F, 9)
    (adjugate over the determinant clamped to magnitude >= det_eps, keeping its
    sign), ``iz`` (F, 3) = 1 / corner depth, and ``det`` (F,) unclamped.
    """
    n = faces.shape[0]
    dt = proj.dtype
    cxy = np.empty((n, 6), dt)
    inv = np.empty((n, 9), dt)
    iz = np.empty((n, 3), dt)
    det = np.empty(n, dt)
    for f in prange(n):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, x1, y1, x2, y2 = proj[a, 0], proj[a, 1], proj[b, 0], proj[b, 1], proj[c, 0], proj[c, 1]
        cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5] = x0, y0, x1, y1, x2, y2
        d = x2 * (y0 - y1) + x0 * (y1 - y2) + x1 * (y2 - y0)
        det[f] = d
        dc = max(d, det_eps) if d > 0 else min(d, -det_eps)
        inv[f, 0], inv[f, 1], inv[f, 2] = (y1 - y2) / dc, (x2 - x1) / dc, (x1 * y2 - x2 * y1) / dc
        inv[f, 3], inv[f, 4], inv[f, 5] = (y2 - y0) / dc, (x0 - x2) / dc, (x2 * y0 - x0 * y2) / dc
        inv[f, 6], inv[f, 7], inv[f, 8] = (y0 - y1) / dc, (x1 - x0) / dc, (x0 * y1 - x1 * y0) / dc
        iz[f, 0], iz[f, 1], iz[f, 2] = 1 / proj[a, 2], 1 / proj[b, 2], 1 / proj[c, 2]
    return cxy, inv, iz, det


@njit(parallel=True, **_OPTS)
def _face_grads(  # type: ignore[no-untyped-def] # pragma: no cover - jit
    grad, face_start, cxy, inv, iz, det, det_eps, g_corner, g_col
):
    """Sum each face's entry slots (in entry order: deterministic) and apply the
    chain rule through :func:`_face_setup`: ``g_corner[f, k]`` = dL/d(x, y, depth)
    of corner k, ``g_col[f]`` = dL/dcolour."""
    for f in prange(cxy.shape[0]):
        g = np.zeros(N_GRAD, grad.dtype)
        for e in range(face_start[f], face_start[f + 1]):
            for j in range(N_GRAD):
                g[j] += grad[e, j]
        x0, y0, x1, y1, x2, y2 = cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5]
        d = det[f]
        dc = max(d, det_eps) if d > 0 else min(d, -det_eps)
        # inv = adj / dc: d inv = d adj / dc - inv d(dc) / dc, and dc is constant
        # where the clamp holds it (torch.clamp passes the gradient at the bound)
        g00, g01, g02 = g[6] / dc, g[7] / dc, g[8] / dc
        g10, g11, g12 = g[9] / dc, g[10] / dc, g[11] / dc
        g20, g21, g22 = g[12] / dc, g[13] / dc, g[14] / dc
        h = 0.0
        if (d > 0 and d >= det_eps) or (d <= 0 and d <= -det_eps):
            for j in range(9):
                h += g[6 + j] * inv[f, j]
            h /= dc
        g_corner[f, 0] = g[0] + g11 - g21 - g12 * y2 + g22 * y1 - h * (y1 - y2)
        g_corner[f, 1] = g[1] - g10 + g20 + g12 * x2 - g22 * x1 - h * (x2 - x1)
        g_corner[f, 3] = g[2] - g01 + g21 + g02 * y2 - g22 * y0 - h * (y2 - y0)
        g_corner[f, 4] = g[3] + g00 - g20 - g02 * x2 + g22 * x0 - h * (x0 - x2)
        g_corner[f, 6] = g[4] + g01 - g11 - g02 * y1 + g12 * y0 - h * (y0 - y1)
        g_corner[f, 7] = g[5] - g00 + g10 + g02 * x1 - g12 * x0 - h * (x1 - x0)
        # iz = 1 / depth
        g_corner[f, 2] = -g[15] * iz[f, 0] * iz[f, 0]
        g_corner[f, 5] = -g[16] * iz[f, 1] * iz[f, 1]
        g_corner[f, 8] = -g[17] * iz[f, 2] * iz[f, 2]
        g_col[f, 0], g_col[f, 1], g_col[f, 2] = g[18], g[19], g[20]


@njit(**_OPTS)
def _scatter_vertices(g_corner, faces, n_vertices):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """(V, 3) sums of the corner gradients per vertex, in face order (deterministic)."""
    out = np.zeros((n_vertices, 3), g_corner.dtype)
    for f in range(faces.shape[0]):
        for k in range(3):
            v = faces[f, k]
            out[v, 0] += g_corner[f, 3 * k]
            out[v, 1] += g_corner[f, 3 * k + 1]
            out[v, 2] += g_corner[f, 3 * k + 2]
    return out


# --------------------------------------------------------------------------- torch glue


@dataclass(frozen=True)
class _Config:
    size: int
    sigma: float
    gamma: float
    background: tuple[float, float, float]
    near: float
    far: float
    eps: float
    dist_eps: float

    def constants(self, dtype: np.dtype) -> np.ndarray:
        k = np.zeros(N_K, dtype)
        k[K_THR] = distance_threshold(self.sigma, self.dist_eps)
        k[K_INV_SIGMA] = 1.0 / self.sigma
        k[K_NEAR], k[K_FAR] = self.near, self.far
        k[K_INV_FR] = 1.0 / (self.far - self.near)
        k[K_INV_GAMMA] = 1.0 / self.gamma
        k[K_EPS] = self.eps
        k[K_SUM0] = math.exp(self.eps / self.gamma)
        k[K_BG:K_BG + 3] = self.background
        k[K_WSUM] = WSUM_EPS
        k[K_EE_MIN] = 1e-30
        k[K_ONE] = 1.0  # typed constants: a bare 0 or 1 would promote float32 math to float64
        return k


@dataclass
class _Bins:
    """The tiling of one forward call (reused by its backward)."""

    box: np.ndarray
    n_tx: int
    wp: int
    order: np.ndarray
    tile_start: np.ndarray
    tile_entry: np.ndarray
    entry_face: np.ndarray
    face_start: np.ndarray
    row_start: np.ndarray
    px_tab: np.ndarray
    py_tab: np.ndarray


def _make_bins(cxy: np.ndarray, cfg: _Config) -> _Bins:
    s = cfg.size
    radius = math.sqrt(distance_threshold(cfg.sigma, cfg.dist_eps))
    box = _face_boxes(cxy, radius, s)
    n_ty, n_tx = -(-s // TILE_H), -(-s // TILE_W)
    tile_start, tile_entry, entry_face, face_start, row_start = _bin_faces(box, n_ty, n_tx)
    # every tile is rendered (empty ones get the background); busiest first, so
    # the dynamic schedule ends with small tiles and the threads finish together
    order = np.argsort(-np.diff(tile_start), kind="stable").astype(np.int64)
    hp, wp = n_ty * TILE_H, n_tx * TILE_W
    # columns up to wp + LANES: lane groups may run past the last tile's last column
    k = np.arange(max(hp, wp + LANES), dtype=np.float64)
    px_tab = ((2 * k[:wp + LANES] + 1) / s - 1).astype(cxy.dtype)
    py_tab = (1 - (2 * k[:hp] + 1) / s).astype(cxy.dtype)
    return _Bins(box, n_tx, wp, order, tile_start, tile_entry, entry_face, face_start, row_start, px_tab, py_tab)


@contextmanager
def _one_tile_chunks() -> Iterator[None]:
    """Run the tile loops with chunks of one tile, dealt as threads come free.

    numba's default splits a ``prange`` into one contiguous share per thread:
    with the busiest-first tile order that hands one thread nearly all the
    work (measured: forward 43 ms on 2 threads vs 48 on one; 24 ms with
    chunks of one). The setting is per calling thread and restored after.
    It is set here rather than inside the kernels because numba cannot cache
    a function that calls ``set_parallel_chunksize`` or uses
    ``with parallel_chunksize``.
    """
    saved = set_parallel_chunksize(1)
    try:
        yield
    finally:
        set_parallel_chunksize(saved)


def _numpy(t: "torch.Tensor") -> np.ndarray:
    return t.detach().contiguous().numpy()


def _make_function():  # type: ignore[no-untyped-def]
    import torch
    from torch.autograd.function import once_differentiable

    class SoftRasterizeNumba(torch.autograd.Function):
        """Autograd wrapper of the kernels: (projected vertices, colours) -> (image, alpha)."""

        @staticmethod
        def forward(ctx, proj, colors, faces, cfg):  # type: ignore[no-untyped-def]
            a_proj, a_col, a_faces = _numpy(proj), _numpy(colors), _numpy(faces)
            dtype = a_proj.dtype
            cxy, inv, iz, det = _face_setup(a_proj, a_faces, DET_EPS)
            bins = _make_bins(cxy, cfg)
            s = cfg.size
            K = cfg.constants(dtype)
            image = np.empty((s, s, 3), dtype)
            alpha = np.empty((s, s), dtype)
            n_state = bins.py_tab.shape[0] * bins.wp
            st_m = np.empty(n_state, dtype)
            st_s = np.empty(n_state, dtype)
            st_p = np.empty(n_state, dtype)
            row_lo = np.empty(bins.row_start[-1], np.int32)
            row_hi = np.empty(bins.row_start[-1], np.int32)
            with _one_tile_chunks():
                _forward(
                    bins.order, bins.n_tx, s, bins.wp, bins.tile_start, bins.tile_entry, bins.entry_face,
                    bins.row_start, bins.box, cxy, inv, iz, a_col, bins.px_tab, bins.py_tab, K,
                    image, alpha, st_m, st_s, st_p, row_lo, row_hi,
                )
            ctx.cfg = cfg
            ctx.torch_dtype = proj.dtype
            ctx.n_vertices = a_proj.shape[0]
            ctx.arrays = (a_faces, cxy, inv, iz, det, a_col, K, bins, image, st_m, st_s, st_p, row_lo, row_hi)
            return torch.from_numpy(image), torch.from_numpy(alpha)

        @staticmethod
        @once_differentiable
        def backward(ctx, g_image, g_alpha):  # type: ignore[no-untyped-def]
            a_faces, cxy, inv, iz, det, a_col, K, bins, image, st_m, st_s, st_p, row_lo, row_hi = ctx.arrays
            cfg = ctx.cfg
            dtype = cxy.dtype
            gi = np.zeros_like(image) if g_image is None else _numpy(g_image.to(ctx.torch_dtype))
            ga = np.zeros(image.shape[:2], dtype) if g_alpha is None else _numpy(g_alpha.to(ctx.torch_dtype))
            grad = np.empty((bins.tile_entry.shape[0], N_GRAD), dtype)
            with _one_tile_chunks():
                _backward(
                    bins.order, bins.n_tx, cfg.size, bins.wp, bins.tile_start, bins.tile_entry, bins.entry_face,
                    bins.row_start, bins.box, cxy, inv, iz, a_col, bins.px_tab, bins.py_tab, K,
                    image, gi, ga, st_m, st_s, st_p, row_lo, row_hi, grad,
                )
            n_faces = cxy.shape[0]
            g_corner = np.empty((n_faces, 9), dtype)
            g_col = np.empty((n_faces, 3), dtype)
            _face_grads(grad, bins.face_start, cxy, inv, iz, det, DET_EPS, g_corner, g_col)
            g_proj = None
            if ctx.needs_input_grad[0]:
                g_proj = torch.from_numpy(_scatter_vertices(g_corner, a_faces, ctx.n_vertices))
            g_colors = torch.from_numpy(g_col) if ctx.needs_input_grad[1] else None
            return g_proj, g_colors, None, None

    return SoftRasterizeNumba


_FUNCTION = None


def _function():  # type: ignore[no-untyped-def]
    global _FUNCTION
    if _FUNCTION is None:
        _FUNCTION = _make_function()
    return _FUNCTION


def soft_rasterize_numba(
    vertices: "torch.Tensor",
    faces: "torch.Tensor",
    face_colors: "torch.Tensor",
    camera: "Camera",
    *,
    sigma: float,
    gamma: float,
    background: tuple[float, float, float],
    near: float,
    far: float,
    eps: float,
    dist_eps: float,
) -> "tuple[torch.Tensor, torch.Tensor]":
    """The numba backend of :func:`saucerfab.render.soft_rasterize` (arguments checked there).

    Args:
        vertices: World positions, shape [V, 3], model units, CPU.
        faces: Vertex indices, shape [F, 3], int64.
        face_colors: RGB per face, shape [F, 3], same dtype as ``vertices``.
        camera: The view (S = ``camera.image_size``).
        sigma, gamma, background, near, far, eps, dist_eps: As
            :func:`saucerfab.render.soft_rasterize`.

    Returns:
        ``(image, alpha)``: shapes [S, S, 3] and [S, S], ``vertices.dtype``.
    """
    proj = camera.project_torch(vertices)  # autograd carries the kernels' gradient to the world
    cfg = _Config(camera.image_size, sigma, gamma, background, near, far, eps, dist_eps)
    return _function().apply(proj, face_colors, faces, cfg)
