"""Numba kernels of the wall rule and the feature rule (imported by :mod:`saucerfab.model.relief` when it runs).

The optimizer projects every trial step onto printable relief
(:class:`saucerfab.optimize.printable.CrestProjection`), so the wall rule runs
hundreds of times a design. Written in numpy it is a handful of whole-grid
passes per line and step plus a bisection of 30 rounds whose each round is
about a hundred small numpy calls. Here each vertex walks its three mesh
lines in a plain loop: a whole projection step on the 150 x 150 grid took
2.2-5.9x less time (``benchmarks/bench_relief.py``; in a design the sparse
stage, whose spikes make thin crests, about 0.7x: benchmarks/results/HISTORY.md, "The relief projection").
The feature rule's pass (:func:`feature_crests`) was a dozen whole-grid numpy
operations per line and sweep, about 1.2 ms a projection step; here one loop.

The kernels do the same float64 operations, in the same order, as the numpy
code they replace, which stays in :mod:`saucerfab.model.relief` as their reference
(:func:`~saucerfab.model.relief.wall_widths_reference`,
:func:`~saucerfab.model.relief.bisect_tops_reference`,
:func:`~saucerfab.model.relief.feature_crests_reference`); the tests hold them
equal bit for bit, since an optimizer iterate that differs in the last bit
sends the solver down another path.

Compiled code is cached on disk (``cache=True``). The two wall-rule entry points run
their vertices (crests) on numba's worker threads: each result is computed
by one thread alone, so it does not depend on the thread count; with two
threads a projection step took 1.5-2x less than serial (1.7 against 2.7 ms
with nothing to blunt, 5.6 against 9.9 ms with 2 % spikes).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: the three mesh lines (along x, along y, the cell diagonal): grid offsets; their
#: lengths and what lies beyond the border come from the caller (relief._WALL_LINES)
_DI = (0, 1, 1)
_DJ = (1, 0, 1)


@njit(cache=True, error_model="numpy")
def feature_crests(h: np.ndarray, edge: np.ndarray, lengths: np.ndarray, crest_p: float, feature_w: float,
                   keep: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The feature rule's thin crests (relief.feature_crests_reference, bit for bit).

    Args:
        h: (N, M) float64 heights. edge: (3, N, M) float64, relief.edge_lines
            (not NaN: beyond the part's edge; no crest there, nor on a line that
            leaves the part). lengths: (3,) the lines' lengths.
    Returns:
        ``target`` (N-2, M-2), ``thin`` and ``a_higher`` (3, N-2, M-2) bool.
    """
    rows, cols = h.shape
    has_edge = edge.shape[1] * edge.shape[2] > 1  # a (3, 1, 1) table: no edge (relief._NO_EDGE)
    n, m = max(rows - 2, 0), max(cols - 2, 0)  # a grid under 3 x 3 has no interior vertex
    target = np.full((n, m), np.inf)
    thin = np.zeros((3, n, m), np.bool_)
    a_higher = np.zeros((3, n, m), np.bool_)
    # one thread: about 0.1 ms on 150 x 150, less than waking the workers costs
    for i in range(1, rows - 1):
        for j in range(1, cols - 1):
            c = h[i, j]
            t = np.inf
            for line in range(3):
                di, dj = _DI[line], _DJ[line]
                a, b = h[i - di, j - dj], h[i + di, j + dj]
                m = np.maximum(a, b)
                p = c - m
                # numpy's order: ((length * 0.5) * p) * (1 / (c - a) + 1 / (c - b)); 1/0 = inf
                w = lengths[line] * 0.5 * p * (1.0 / (c - a) + 1.0 / (c - b))
                on = not has_edge or (math.isnan(edge[0, i, j]) and math.isnan(edge[0, i - di, j - dj])
                                      and math.isnan(edge[0, i + di, j + dj]))
                is_thin = (p >= crest_p) and (w < feature_w) and on
                thin[line, i - 1, j - 1] = is_thin
                a_higher[line, i - 1, j - 1] = a >= b
                if is_thin:
                    t = np.minimum(t, m + keep)
            target[i - 1, j - 1] = t
    return target, thin, a_higher


@njit(cache=True)
def _line_width(h: np.ndarray, edge: np.ndarray, line: int, i: int, j: int, top: float, level: float,
                length: float, beyond: float, k_max: int, plateau: bool, rise_tol: float) -> float:
    """Width at ``level`` of the crest of height ``top`` at (i, j) along one line (relief._walk_width).

    ``edge`` (3, N, M): what a vertex beyond the part's edge reads as on each line (NaN: on the part);
    (3, 1, 1): the grid has no edge but its border."""
    di, dj = _DI[line], _DJ[line]
    rows, cols = h.shape
    has_edge = edge.shape[1] * edge.shape[2] > 1
    total = 0.0
    for side in (1, -1):
        extent = math.inf
        prev = top
        for k in range(1, k_max + 1):
            ii = i + side * k * di
            jj = j + side * k * dj
            if 0 <= ii < rows and 0 <= jj < cols:
                n = h[ii, jj]
                if has_edge and not math.isnan(edge[line, ii, jj]):
                    n = edge[line, ii, jj]
            else:
                n = beyond
            if plateau:
                n = np.minimum(n, top)
            if n > top + rise_tol:
                return math.inf  # no crest on this line
            if n <= level:
                frac = (prev - level) / max(prev - n, 1e-300)
                frac = min(max(frac, 0.0), 1.0)
                extent = length * (k - 1 + frac)
                break
            prev = n
        total = total + extent
    return total


@njit(cache=True)
def _vertex_width(h: np.ndarray, edge: np.ndarray, i: int, j: int, top: float, depth: float, lengths: np.ndarray,
                  beyond: np.ndarray, k_max: int, plateau: bool, rise_tol: float) -> float:
    """The smallest width over the three lines of a crest of height ``top`` at (i, j), ``depth`` below it."""
    level = top - depth
    w = math.inf
    for line in range(3):
        w = np.minimum(w, _line_width(h, edge, line, i, j, top, level, lengths[line], beyond[line],
                                      k_max, plateau, rise_tol))
    return w


@njit(cache=True, parallel=True)
def wall_widths_grid(h: np.ndarray, edge: np.ndarray, depth: float, lengths: np.ndarray, beyond: np.ndarray,
                     k_max: int, rise_tol: float) -> np.ndarray:
    """(N, M) float64 widths of every vertex's crest at ``depth`` below it (relief.wall_widths); ``inf`` beyond
    the part's edge (``edge`` (3, N, M), relief.edge_lines)."""
    out = np.empty(h.shape)
    has_edge = edge.shape[1] * edge.shape[2] > 1
    # rows on the worker threads: each vertex's width is its own, so the result does not
    # depend on the thread count (1.1 -> 0.6 ms on 150 x 150 with two)
    for i in prange(h.shape[0]):
        for j in range(h.shape[1]):
            if has_edge and not math.isnan(edge[0, i, j]):
                out[i, j] = math.inf  # cut away: no wall
            else:
                out[i, j] = _vertex_width(h, edge, i, j, h[i, j], depth, lengths, beyond, k_max, False, rise_tol)
    return out


@njit(cache=True, parallel=True)
def bisect_tops(h: np.ndarray, edge: np.ndarray, ii: np.ndarray, jj: np.ndarray, lo_vals: np.ndarray, depth: float,
                want: float, k_max: int, lengths: np.ndarray, beyond: np.ndarray,
                rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """Per thin crest (ii, jj): the highest top at which it is ``want`` wide ``depth`` below (bisection).

    The neighbours stay at ``h``; a neighbour above the trial top counts as at
    it (a plateau). Returns (lo_top (K,), ok_low (K,) bool: wide enough at its
    lowest allowed top), as relief.lower_until_wide_reference computes them.
    """
    k = ii.shape[0]
    lo_top = np.empty(k)
    ok_low = np.empty(k, np.bool_)
    for t in prange(k):  # each crest's bisection is its own
        i, j = ii[t], jj[t]
        hi = h[i, j]
        lo = np.maximum(lo_vals[t], hi - 16.0 * depth)
        ok_low[t] = _vertex_width(h, edge, i, j, lo, depth, lengths, beyond, k_max, True, 0.0) >= want
        for _ in range(rounds):
            mid = 0.5 * (hi + lo)
            if _vertex_width(h, edge, i, j, mid, depth, lengths, beyond, k_max, True, 0.0) >= want:
                lo = mid
            else:
                hi = mid
        lo_top[t] = lo
    return lo_top, ok_low
