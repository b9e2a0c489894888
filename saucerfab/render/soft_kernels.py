"""The numba kernels that render one tile of the soft rasterizer, forward and backward.

The formulas are :mod:`saucerfab.render.soft`'s; the tiles, their state
layout and the binning are :mod:`saucerfab.render.soft_tiles`'s; the per-face
setup and the autograd glue are :mod:`saucerfab.render.soft_numba`'s.

* Each (face, tile) entry's pairs are packed into a flat tile-local scratch,
  row after row (the forward: the box's rows cut to the tile; the backward:
  each row's first to last kept pair, which the forward records), with the
  8-lane vector copies of :mod:`saucerfab.render._simd`; the pairs are then
  rendered in full groups (the forward: :data:`GROUP`, two lane groups; the
  backward: ``LANES``) and the forward's state is blended back. A face's rows
  are short (1-4 pixels at sigma 1e-7, 5-9 at 1e-5), and a group per row left
  most lanes idle.
* The innermost loop runs over one group at a time (a loop of a fixed number
  of iterations, which LLVM vectorizes exactly that wide), branch-free
  (selects and masks; lanes past the entry's pairs are masked out like
  skipped pairs), indexing the scratch through a view with compile-time field
  offsets, and uses :func:`saucerfab.render._simd.vexp` instead of libm's
  exp. The per-pair pieces that both directions compute (barycentrics,
  nearest edge point, coverage) are small functions numba inlines into the
  loop (``inline="always"``), so the loop LLVM sees is the same as if they
  were written out.
* The forward keeps per pixel the softmax maximum and sum and the alpha
  product, and per (entry, row) the first and last lane whose pair is not
  skipped; the backward recomputes each pair's geometry on those lanes only
  (cheaper than storing millions of pairs), reading each pixel's state from
  one full-image array that :func:`backward_state` fills in a single pass.
* float32 denormals are flushed to zero on the worker threads while they
  render a tile (MXCSR restored afterwards).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from saucerfab.render._simd import (
    FIRST_BIT, LAST_BIT, blend8, copy8, fill8, ftz_on, ftz_restore, nonzero_mask8, sum8, vexp,
)
from saucerfab.render.soft_common import SoftParams, WSUM_EPS
from saucerfab.render.soft_tiles import JIT_OPTS, LANES, N_GRAD, NLOC, SW, TILE_H, TILE_W

#: pairs per iteration of the forward's pair loop: two lane groups (one AVX-512
#: register of float32, two AVX2 ones), the same bits as one. Forward alone, one
#: thread, both views: 35.2-37.0 -> 27.3-29.6 ms at sigma 1e-5 and 19.4-19.6 ->
#: 18.3-19.1 ms at 1e-7; compiled for AVX2 only (NUMBA_CPU_NAME=haswell)
#: 34.5-35.2 -> 26.1-27.4 and 18.9-19.5 -> 16.6-17.4 ms. The backward keeps single
#: lane groups: at two (its terms stored and added in the same order, to keep its
#: bits) it was 5-10 % faster at 1e-5 and 10-80 % slower at 1e-7.
GROUP = 2 * LANES
#: lanes of the kernels' flat scratch per field: every pair of one entry, and room
#: for the last pair group
NSCR = TILE_H * TILE_W + GROUP
# the 8-lane vector blocks of _simd (copy8, fill8, blend8, nonzero_mask8, sum8) move
# one lane group each
assert LANES == 8

# index of each constant in the parameter vector K handed to the kernels
K_THR, K_INV_SIGMA, K_NEAR, K_FAR, K_INV_FR, K_INV_GAMMA, K_EPS, K_SUM0, K_BG = 0, 1, 2, 3, 4, 5, 6, 7, 8
K_WSUM, K_EE_MIN, K_ZERO, K_ONE, N_K = 11, 12, 13, 14, 15

#: inlined into the caller: its lanes stay one vectorizable loop
_INLINE = dict(inline="always")


def kernel_constants(params: SoftParams, dtype: np.dtype) -> np.ndarray:
    """The parameter vector K (:data:`N_K`,) of the kernels, in the faces' dtype.

    Typed constants: a bare 0 or 1 in a kernel would promote float32 math to float64.
    """
    k = np.zeros(N_K, dtype)
    k[K_THR] = params.threshold
    k[K_INV_SIGMA] = 1.0 / params.sigma
    k[K_NEAR], k[K_FAR] = params.near, params.far
    k[K_INV_FR] = 1.0 / (params.far - params.near)
    k[K_INV_GAMMA] = 1.0 / params.gamma
    k[K_EPS] = params.eps
    k[K_SUM0] = math.exp(params.eps / params.gamma)
    k[K_BG:K_BG + 3] = params.background
    k[K_WSUM] = WSUM_EPS
    k[K_EE_MIN] = 1e-30
    k[K_ONE] = 1.0
    return k


# --------------------------------------------------------------------------- per face and per pair


@njit(**JIT_OPTS)
def _face_consts(f, cxy, inv, iz, col, ee_min, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """What the pair loops read of face f: corner x, y (6), edge vectors (6) and
    1/|edge|^2 (3; degenerate edges project onto their start, as the torch
    backend's clamp makes them), the barycentric matrix row by row (9), the
    inverse corner depths (3) and the colour (3)."""
    ax0, ay0, ax1, ay1, ax2, ay2 = cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5]
    ex0, ey0 = ax1 - ax0, ay1 - ay0
    ex1, ey1 = ax2 - ax1, ay2 - ay1
    ex2, ey2 = ax0 - ax2, ay0 - ay2
    ie0 = one / max(ex0 * ex0 + ey0 * ey0, ee_min)
    ie1 = one / max(ex1 * ex1 + ey1 * ey1, ee_min)
    ie2 = one / max(ex2 * ex2 + ey2 * ey2, ee_min)
    return (
        ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2,
        inv[f, 0], inv[f, 1], inv[f, 2], inv[f, 3], inv[f, 4], inv[f, 5], inv[f, 6], inv[f, 7], inv[f, 8],
        iz[f, 0], iz[f, 1], iz[f, 2], col[f, 0], col[f, 1], col[f, 2],
    )


@njit(**JIT_OPTS, **_INLINE)
def _entry_span(entry, entry_face, box, rt0, ct0):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Face of a tile entry and its box cut to the tile at (rt0, ct0): ``(f, ra, rb, ca, cb)``,
    inclusive rows and columns (empty when ``rb < ra`` or ``cb < ca``)."""
    f = entry_face[entry]
    ra, rb = max(box[f, 0], rt0), min(box[f, 1], rt0 + TILE_H - 1)
    ca, cb = max(box[f, 2], ct0), min(box[f, 3], ct0 + TILE_W - 1)
    return f, ra, rb, ca, cb


@njit(**JIT_OPTS, **_INLINE)
def _bary(px, i00, i10, i20, b0, b1, b2, zero, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Barycentrics ``w`` of the pixel at NDC x ``px`` on a row whose y terms are
    ``b_k = i_k1 py + i_k2``, and whether all ``0 < w_k < 1`` (inside)."""
    w0 = i00 * px + b0
    w1 = i10 * px + b1
    w2 = i20 * px + b2
    inside = (w0 > zero) & (w0 < one) & (w1 > zero) & (w1 < one) & (w2 > zero) & (w2 < one)
    return w0, w1, w2, inside


@njit(**JIT_OPTS, **_INLINE)
def _segment(px, hy, ax, ex, ey, ie, zero, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Nearest point of the edge from corner ``(ax, ay)`` along ``(ex, ey)`` to the pixel
    (``hy = py - ay``): its parameter ``t`` in [0, 1], the offset ``(dx, dy)`` from the
    pixel to it, and the squared distance."""
    hx = px - ax
    tt = min(max((hx * ex + hy * ey) * ie, zero), one)
    dx, dy = tt * ex - hx, tt * ey - hy
    return tt, dx, dy, dx * dx + dy * dy


@njit(**JIT_OPTS, **_INLINE)
def _nearer(px, hy, ax, ex, ey, ie, zero, one, d2, bt, bdx, bdy):  # type: ignore[no-untyped-def] # pragma: no cover
    """The nearer of the best edge point so far ``(d2, bt, bdx, bdy)`` and this edge's
    (:func:`_segment`): ``(this edge is nearer, d2, t, dx, dy)``; ties keep the earlier."""
    tt, dx, dy, dd = _segment(px, hy, ax, ex, ey, ie, zero, one)
    sel = dd < d2
    return sel, (dd if sel else d2), (tt if sel else bt), (dx if sel else bdx), (dy if sel else bdy)


@njit(**JIT_OPTS, **_INLINE)
def _coverage(xs, zero, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """``(sigmoid(xs), 1 - sigmoid(xs))`` with one exp of a non-positive argument."""
    ex = vexp(-abs(xs))
    rec = one / (one + ex)
    erec = ex * rec
    cov = rec if xs >= zero else erec
    unc = erec if xs >= zero else rec
    return cov, unc


@njit(**JIT_OPTS, **_INLINE)
def _clip01(w0, w1, w2, zero, one):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """The barycentrics clamped to [0, 1] (SoftRas's ``barycentric_clip`` before normalizing)."""
    return min(max(w0, zero), one), min(max(w1, zero), one), min(max(w2, zero), one)


@njit(**JIT_OPTS, **_INLINE)
def _pack_row(scr, total, px_tab, px0, py, state, s0, stride, count):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Append ``count`` pairs of one pixel row to the scratch at ``total``, 8 lanes at a time.

    Fields (NSCR apart): 0 the pixels' x (``px_tab[px0:]``), 1 their y
    (``py``), 2-7 the six state fields (``state[s0 + j * stride:]``, j = 0..5).
    Whole 8-lane vector copies: up to 7 lanes past ``count`` are written too,
    which the caller's padding absorbs and the next row (or nothing) overwrites.
    """
    for g0 in range(0, count, 8):
        d = total + g0
        copy8(scr, d, px_tab, px0 + g0)
        fill8(scr, NSCR + d, py)
        for j in range(6):
            copy8(scr, (2 + j) * NSCR + d, state, s0 + j * stride + g0)


# --------------------------------------------------------------------------- forward


@njit(**JIT_OPTS)
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

    # The pairs of one entry (its box's rows cut to the tile) are packed row after
    # row into a flat scratch, rendered in full lane groups, and their state
    # written back: small faces' rows (1-4 pixels at sigma 1e-7) no longer take a
    # lane group each. Scratch fields (NSCR apart): 0 px, 1 py, 2-7 the tile
    # state's 6 fields, 8 whether the pair is kept (for the rows' lo and hi).
    scr = np.zeros(9 * NSCR, K.dtype)
    for idx in range(tile_start[t], tile_start[t + 1]):
        entry = tile_entry[idx]
        f, ra, rb, ca, cbx = _entry_span(entry, entry_face, box, rt0, ct0)
        if rb < ra or cbx < ca:
            continue
        w = cbx - ca + 1
        total = 0
        for r in range(ra, rb + 1):
            q0 = (r - rt0) * SW + (ca - ct0)
            py = py_tab[r]
            # whole 8-lane vector copies: the lanes past the box lie in the row's
            # padding and land where the next row's copy or nothing reads them
            _pack_row(scr, total, px_tab, ca, py, st, q0, NLOC, w)
            total += w
        (ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2,
         i00, i01, i02, i10, i11, i12, i20, i21, i22, iz0, iz1, iz2, fr, fg, fb) = _face_consts(
            f, cxy, inv, iz, col, ee_min, one
        )
        n = (total + GROUP - 1) // GROUP * GROUP
        t32 = np.int32(total)
        # one pair group at a time, each a loop of GROUP iterations: LLVM then
        # vectorizes it exactly GROUP wide (for a loop of unknown length it picks
        # its own width and runs the rest in a narrower epilogue); lanes past the
        # total hold stale scratch and are masked out. A pixel occurs once per
        # entry, so the width changes no pixel's order of operations.
        for g0 in range(0, n, GROUP):
            # a view indexed by the loop counter plus constants: no negative-index
            # wraparound, so LLVM sees unit-stride accesses and vectorizes
            sv = scr[g0:]
            g32 = np.int32(g0)
            for lane in range(GROUP):
                px = sv[lane]
                py = sv[NSCR + lane]
                b0 = i01 * py + i02
                b1 = i11 * py + i12
                b2 = i21 * py + i22
                hy0, hy1, hy2 = py - ay0, py - ay1, py - ay2
                w0, w1, w2, inside = _bary(px, i00, i10, i20, b0, b1, b2, zero, one)
                # squared distance to the closed triangle = nearest of the three segments
                d2 = _segment(px, hy0, ax0, ex0, ey0, ie0, zero, one)[3]
                d2 = min(d2, _segment(px, hy1, ax1, ex1, ey1, ie1, zero, one)[3])
                d2 = min(d2, _segment(px, hy2, ax2, ex2, ey2, ie2, zero, one)[3])
                # int32 lane numbers: 64-bit ones would halve the vector width
                valid = (inside | (d2 < thr)) & (np.int32(lane) + g32 < t32)
                sv[8 * NSCR + lane] = one if valid else zero
                xs = (d2 if inside else -d2) * inv_sigma
                cov, unc = _coverage(xs, zero, one)
                sv[7 * NSCR + lane] = sv[7 * NSCR + lane] * (unc if valid else one)
                # perspective-correct depth from the clipped barycentrics
                wc0, wc1, wc2 = _clip01(w0, w1, w2, zero, one)
                sw = max(wc0 + wc1 + wc2, wsum_min)
                z = sw / (wc0 * iz0 + wc1 * iz1 + wc2 * iz2)
                rgb = valid & (z >= near) & (z <= far)
                zn = (far - z) * inv_fr
                # online softmax with SoftRas's running maximum, one exp per pair
                mo = sv[2 * NSCR + lane]
                dz = zn - mo
                e = vexp(-abs(dz) * inv_gamma)
                newmax = rgb & (dz > zero)
                scale = e if newmax else one
                term = (one if newmax else e) * cov
                term = term if rgb else zero
                sv[2 * NSCR + lane] = zn if newmax else mo
                sv[3 * NSCR + lane] = sv[3 * NSCR + lane] * scale + term
                sv[4 * NSCR + lane] = sv[4 * NSCR + lane] * scale + term * fr
                sv[5 * NSCR + lane] = sv[5 * NSCR + lane] * scale + term * fg
                sv[6 * NSCR + lane] = sv[6 * NSCR + lane] * scale + term * fb
        # write the state back (exactly the box's lanes of each row) and record,
        # per row, the first and last kept lane: all the backward has to visit
        total = 0
        rs = row_start[entry] - ra
        for r in range(ra, rb + 1):
            q0 = (r - rt0) * SW + (ca - ct0)
            for g0 in range(0, w, 8):
                for j in range(6):
                    blend8(st, j * NLOC + q0 + g0, scr, (2 + j) * NSCR + total + g0, w - g0)
            lo, hi = w, -1
            for g0 in range(0, w, 8):
                m = nonzero_mask8(scr, 8 * NSCR + total + g0, w - g0)
                if m:
                    lo = min(lo, g0 + FIRST_BIT[m])
                    hi = g0 + LAST_BIT[m]
            row_lo[rs + r] = lo
            row_hi[rs + r] = hi
            total += w

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


@njit(parallel=True, **JIT_OPTS)
def forward(
    order, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab,
    K, image, alpha, st_m, st_s, st_p, row_lo, row_hi,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Render every tile in ``order`` (:func:`_forward_tile`); run under
    :func:`saucerfab.render.soft_tiles.one_tile_chunks`."""
    for k in prange(order.shape[0]):
        old = ftz_on()
        _forward_tile(
            order[k], n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col,
            px_tab, py_tab, K, image, alpha, st_m, st_s, st_p, row_lo, row_hi,
        )
        ftz_restore(old)


# --------------------------------------------------------------------------- backward


def backward_state_size(hp: int, wp: int) -> int:
    """Elements of the buffer :func:`backward_state` fills for a padded ``hp x wp`` image."""
    return 6 * (wp + LANES) * hp


@njit(parallel=True, **JIT_OPTS)
def backward_state(image, g_image, g_alpha, st_m, st_s, st_p, wp, K, out):  # type: ignore[no-untyped-def] # pragma: no cover
    """What the backward reads of each pixel, from the forward's state and the incoming gradients.

    Fills ``out`` (at least :func:`backward_state_size` elements) and returns
    ``(bst, wq)``: ``bst``, its start, holds, row by row of the padded image (the
    forward's ``hp x wp``), 6 fields of ``wq = wp + LANES`` pixels each (field j of
    pixel (r, c) at ``(6 r + j) wq + c``; a tile's rows stay together in memory,
    and a lane group starting at any pixel stays inside its row): 0 the softmax
    maximum, 1-3 dL/dimage_k / sum, 4 sum_k dL/dimage_k image_k / sum,
    5 dL/dalpha prod(1 - D); 0 outside the image. One vectorized pass over rows.
    """
    size = image.shape[0]
    hp = st_m.shape[0] // wp
    wq = wp + LANES
    zero, one = K[K_ZERO], K[K_ONE]
    out = out[:6 * wq * hp]
    gi = g_image.reshape(-1)
    im = image.reshape(-1)
    ga = g_alpha.reshape(-1)
    for band in prange(hp // TILE_H):
        for r in range(band * TILE_H, band * TILE_H + TILE_H):
            o = out[6 * wq * r:]
            w = size if r < size else 0
            if r < size:
                gir, imr, gar = gi[3 * size * r:], im[3 * size * r:], ga[size * r:]
                mr, sr, pr = st_m[r * wp:], st_s[r * wp:], st_p[r * wp:]
                for c in range(size):
                    rs = one / sr[c]
                    a0, a1, a2 = gir[3 * c] * rs, gir[3 * c + 1] * rs, gir[3 * c + 2] * rs
                    o[c] = mr[c]
                    o[wq + c], o[2 * wq + c], o[3 * wq + c] = a0, a1, a2
                    o[4 * wq + c] = a0 * imr[3 * c] + a1 * imr[3 * c + 1] + a2 * imr[3 * c + 2]
                    o[5 * wq + c] = gar[c] * pr[c]
            for j in range(6):
                o[j * wq + w:(j + 1) * wq] = zero
    return out, wq


@njit(**JIT_OPTS)
def _backward_tile(
    t, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab, K,
    bst, wq, row_lo, row_hi, grad,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Gradients of tile ``t``'s pixels into the slots ``grad[entry]`` of its entries."""
    ty, tx = t // n_tx, t % n_tx
    rt0, ct0 = ty * TILE_H, tx * TILE_W
    zero, one = K[K_ZERO], K[K_ONE]
    two = one + one
    thr, inv_sigma, near, far = K[K_THR], K[K_INV_SIGMA], K[K_NEAR], K[K_FAR]
    inv_fr, inv_gamma, wsum_min, ee_min = K[K_INV_FR], K[K_INV_GAMMA], K[K_WSUM], K[K_EE_MIN]
    # The pairs of one entry are packed row after row into a flat scratch (the
    # forward's lo..hi of each row: a convex region meets a row in one run), so
    # the lane groups are full whatever the rows' spans (at sigma 1e-7 they are
    # 1-4 pixels: one group per entry instead of one per row). Scratch fields
    # (NSCR apart): 0 px, 1 py, then the pixel's 6 fields of :func:`backward_state`.
    scr = np.zeros(8 * NSCR, K.dtype)
    # Gradient accumulators, one per lane of a group, summed over the entry's
    # groups in order and reduced once per entry: slots 0-5 corner x, y;
    # 6-8 dL/dw_k * px, 9-11 dL/dw_k * py, 12-14 dL/dw_k (barycentric matrix
    # row k: x, y, constant coefficient); 15-17 inverse depths; 18-20 colours.
    acc = np.empty(N_GRAD * LANES, K.dtype)
    for idx in range(tile_start[t], tile_start[t + 1]):
        entry = tile_entry[idx]
        f, ra, rb, ca, cbx = _entry_span(entry, entry_face, box, rt0, ct0)
        for j in range(N_GRAD):
            fill8(acc, j * LANES, zero)
        total = 0
        if rb >= ra and cbx >= ca:
            rs = row_start[entry] - ra
            for r in range(ra, rb + 1):
                lo, hi = row_lo[rs + r], row_hi[rs + r]
                if hi < lo:
                    continue  # every pair of this row is skipped
                py = py_tab[r]
                # whole groups of 8 lanes, moved as vectors (copy8); the lanes past hi
                # (the row's next pixels, or its padding) are overwritten by the next
                # row or lie past the entry's total
                _pack_row(scr, total, px_tab, ca + lo, py, bst, 6 * wq * r + ca + lo, wq, hi - lo + 1)
                total += hi - lo + 1
        if total > 0:
            (ax0, ay0, ax1, ay1, ax2, ay2, ex0, ey0, ex1, ey1, ex2, ey2, ie0, ie1, ie2,
             i00, i01, i02, i10, i11, i12, i20, i21, i22, iz0, iz1, iz2, fr, fg, fb) = _face_consts(
                f, cxy, inv, iz, col, ee_min, one
            )
            # whole lane groups, each a loop of at most LANES iterations: LLVM vectorizes
            # it LANES wide (a partial group would run in its scalar remainder loop);
            # the lanes past the total hold stale scratch and are masked out
            n = (total + LANES - 1) // LANES * LANES
            t32 = np.int32(total)
            for g0 in range(0, n, LANES):
                sv = scr[g0:]
                g32 = np.int32(g0)
                for lane in range(min(n - g0, LANES)):
                    px = sv[lane]
                    py = sv[NSCR + lane]
                    b0 = i01 * py + i02
                    b1 = i11 * py + i12
                    b2 = i21 * py + i22
                    hy0, hy1, hy2 = py - ay0, py - ay1, py - ay2
                    w0, w1, w2, inside = _bary(px, i00, i10, i20, b0, b1, b2, zero, one)
                    # nearest segment, keeping which edge and where on it (t) for the gradient
                    bt, bdx, bdy, d2 = _segment(px, hy0, ax0, ex0, ey0, ie0, zero, one)
                    e1sel, d2, bt, bdx, bdy = _nearer(px, hy1, ax1, ex1, ey1, ie1, zero, one, d2, bt, bdx, bdy)
                    e2sel, d2, bt, bdx, bdy = _nearer(px, hy2, ax2, ex2, ey2, ie2, zero, one, d2, bt, bdx, bdy)
                    e1sel = e1sel & (not e2sel)
                    e0sel = not (e1sel | e2sel)
                    # int32 lane numbers: 64-bit ones would halve the vector width
                    valid = (inside | (d2 < thr)) & (np.int32(lane) + g32 < t32)
                    xs = (d2 if inside else -d2) * inv_sigma
                    cov, unc = _coverage(xs, zero, one)
                    wc0, wc1, wc2 = _clip01(w0, w1, w2, zero, one)
                    rsw = wc0 + wc1 + wc2
                    sw = max(rsw, wsum_min)
                    rnum = one / (wc0 * iz0 + wc1 * iz1 + wc2 * iz2)
                    z = sw * rnum
                    rgb = valid & (z >= near) & (z <= far)
                    zn = (far - z) * inv_fr
                    ez = vexp(min(zn - sv[2 * NSCR + lane], zero) * inv_gamma)
                    wf = cov * ez
                    wf = wf if rgb else zero  # the pair's softmax weight, shifted by the max
                    a0, a1, a2 = sv[3 * NSCR + lane], sv[4 * NSCR + lane], sv[5 * NSCR + lane]
                    gw = a0 * fr + a1 * fg + a2 * fb
                    gw = gw - sv[6 * NSCR + lane]  # dL/dweight * sum
                    # dL/dxs: alpha through prod(1 - D), colour through the weight
                    ga = sv[7 * NSCR + lane] * cov
                    gx = (ga if valid else zero) + gw * wf * unc
                    gd = two * gx * inv_sigma
                    gd = gd if inside else -gd  # d(sign d^2)/d(d^2)
                    u, v = gd * bdx, gd * bdy
                    omt = one - bt
                    k0 = (omt if e0sel else zero) + (bt if e2sel else zero)
                    k1 = (omt if e1sel else zero) + (bt if e0sel else zero)
                    k2 = (omt if e2sel else zero) + (bt if e1sel else zero)
                    acc[lane] += u * k0
                    acc[1 * LANES + lane] += v * k0
                    acc[2 * LANES + lane] += u * k1
                    acc[3 * LANES + lane] += v * k1
                    acc[4 * LANES + lane] += u * k2
                    acc[5 * LANES + lane] += v * k2
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
                    acc[6 * LANES + lane] += gw0 * px
                    acc[7 * LANES + lane] += gw1 * px
                    acc[8 * LANES + lane] += gw2 * px
                    acc[9 * LANES + lane] += gw0 * py
                    acc[10 * LANES + lane] += gw1 * py
                    acc[11 * LANES + lane] += gw2 * py
                    acc[12 * LANES + lane] += gw0
                    acc[13 * LANES + lane] += gw1
                    acc[14 * LANES + lane] += gw2
                    acc[15 * LANES + lane] += gnum * wc0
                    acc[16 * LANES + lane] += gnum * wc1
                    acc[17 * LANES + lane] += gnum * wc2
                    acc[18 * LANES + lane] += a0 * wf
                    acc[19 * LANES + lane] += a1 * wf
                    acc[20 * LANES + lane] += a2 * wf
        # each slot's 8 lanes summed in one fixed order (sum8)
        for j in range(6):
            grad[entry, j] = sum8(acc, j * LANES)
        for k in range(3):  # barycentric matrix row k: (x, y, 1) coefficients
            grad[entry, 6 + 3 * k] = sum8(acc, (6 + k) * LANES)
            grad[entry, 7 + 3 * k] = sum8(acc, (9 + k) * LANES)
            grad[entry, 8 + 3 * k] = sum8(acc, (12 + k) * LANES)
        for j in range(6):
            grad[entry, 15 + j] = sum8(acc, (15 + j) * LANES)


@njit(parallel=True, **JIT_OPTS)
def backward(
    order, n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col, px_tab, py_tab,
    K, bst, wq, row_lo, row_hi, grad,
):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """The gradient slots ``grad`` (E, N_GRAD) of every tile entry (:func:`_backward_tile`);
    run under :func:`saucerfab.render.soft_tiles.one_tile_chunks`."""
    for k in prange(order.shape[0]):
        old = ftz_on()
        _backward_tile(
            order[k], n_tx, size, wp, tile_start, tile_entry, entry_face, row_start, box, cxy, inv, iz, col,
            px_tab, py_tab, K, bst, wq, row_lo, row_hi, grad,
        )
        ftz_restore(old)
