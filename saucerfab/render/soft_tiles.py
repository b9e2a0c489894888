"""Tiles of the compiled soft rasterizer: their layout, and the binning of faces into them.

Faces are binned into tiles of ``TILE_H x TILE_W`` pixels by their bounding
boxes widened by the influence radius ``sqrt(distance_threshold)``. Every
tile is owned whole by one thread (``prange`` over tiles, busiest first,
dealt one tile at a time as threads come free: :func:`one_tile_chunks`), so
pixels are written without atomics, and the result does not depend on the
thread count or schedule. The gradient of each (face, tile) entry goes to its
own slot (:data:`N_GRAD` of them); a face's slots are summed in a fixed order
afterwards. The kernels that render a tile are in
:mod:`saucerfab.render.soft_kernels`.

Tile-local per-pixel state: one array, field k of pixel (row i, column j of
the tile) at ``k * NLOC + i * SW + j``. One array with fields a compile-time
constant apart lets LLVM prove the accesses independent; separate arrays
would each need a run-time overlap check, more than it will emit. Rows are
``SW = TILE_W + LANES`` wide: a face's span of columns is processed in whole
lane groups from its first column, and the lanes past the tile's last column
land in the padding, which is never read back.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, set_parallel_chunksize

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
#: gradient slots per (face, tile): 6 corner xy, 9 barycentric matrix, 3 inverse depths, 3 colours
N_GRAD = 21

#: numba options of the kernels: ``error_model="numpy"`` removes the division-by-zero
#: checks that would block vectorization; ``fastmath`` is limited to FMA contraction,
#: which keeps float64 results within 1e-12 of the torch backend
JIT_OPTS: dict[str, Any] = dict(error_model="numpy", cache=True, nogil=True, fastmath={"contract"})


@njit(**JIT_OPTS)
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
        # every corner tested: min and max may pass over a NaN (its comparisons are false)
        finite = np.isfinite(x0) and np.isfinite(x1) and np.isfinite(x2)
        if not (finite and np.isfinite(y0) and np.isfinite(y1) and np.isfinite(y2)):
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


@njit(**JIT_OPTS)
def _bin_faces(box: np.ndarray, n_ty: int, n_tx: int):  # type: ignore[no-untyped-def] # pragma: no cover
    """Bin faces into tiles.

    Returns ``(tile_start (T+1,), tile_entry (E,), entry_face (E,), face_start (F+1,),
    row_start (E+1,))``: entry ids are numbered face by face (a face's entries are
    contiguous, so its gradient slots are summed in a fixed order), each tile's
    entries are in increasing face order, and entry e's rows within its tile have
    the slots row_start[e] .. row_start[e+1]-1 of the per-row valid ranges.

    One thread, face after face: a version laying the faces out on the worker
    threads from prefix sums (then a counting sort by tile) took 1.6 ms
    against 0.7-0.9 ms for the 57,457 entries of the bench's direct view.
    ``tests/render/test_soft_tiles.py`` holds it to a written-out reference.
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


@dataclass
class Bins:
    """The tiling of one forward call (reused by its backward).

    Attributes:
        box: (F, 4) int32 widened pixel boxes (row0, row1, col0, col1), inclusive.
        n_tx: Tiles per tile row.
        wp: Image width padded to whole tiles, pixels (the row stride of the
            full-image state arrays).
        order: (T,) int64 tiles, busiest first.
        tile_start, tile_entry, entry_face, face_start, row_start: As
            :func:`_bin_faces` returns them.
        px_tab: (wp + LANES,) NDC x of each column's pixel centre, the faces' dtype.
        py_tab: (tile rows x TILE_H,) NDC y of each row's pixel centre.
    """

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


def make_bins(cxy: np.ndarray, size: int, radius: float) -> Bins:
    """Bin the faces with corners ``cxy`` (F, 6) NDC into the tiles of an S = ``size`` image.

    ``radius`` (NDC units) widens each face's bounding box on every side:
    ``sqrt(distance_threshold)``, beyond which no pair is kept.
    """
    s = size
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
    return Bins(box, n_tx, wp, order, tile_start, tile_entry, entry_face, face_start, row_start, px_tab, py_tab)


@contextmanager
def one_tile_chunks() -> Iterator[None]:
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
