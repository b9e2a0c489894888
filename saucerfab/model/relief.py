"""The saucer's relief against a printer's minimum feature and wall: two crest rules and their projection.

One rule, used by the optimizer (which keeps every iterate printable) and by
the export (which checks the part, and adapts a design made for a coarser
printer): a grid vertex is a *crest* along a mesh line (x, y, or the
triangulation's cell diagonal) when it rises at least ``min_feature`` above
both neighbours on that line (a lower crest is below what the printer
resolves anyway); a crest is *too thin* when its cross-section at half its
prominence is narrower than ``min_feature``. With the faces linear, a crest
``c`` between neighbours ``a >= b`` at distance ``L`` has prominence
``p = c - a`` and half-prominence width

    w = L * p/2 * (1/(c - a) + 1/(c - b)) = L/2 * (1 + (c - a)/(c - b)),

between ``L/2`` (a needle beside a cliff) and ``L`` (a symmetric spike). So
on a grid coarser than twice the minimum feature nothing is ever too thin,
and on a finer one only steep, lopsided crests are.

:func:`blunt_thin_crests` makes a heightfield meet the rule with small,
local moves inside the design's height bounds: a thin crest is lowered until
its prominence is just under ``min_feature`` (what the printer would make
of it anyway); where its lower bound stops that, its higher neighbour on the
offending line is raised instead. Sweeps repeat until nothing is thin (a
move can make a neighbour a thin crest), so the result satisfies
:func:`crest_widths` exactly, which is what the export checks.

The wall rule. A tall crest is a wall, whatever its half-height width: a
5 mm spike one grid step wide is a fin or a needle thinner than any printer's
minimum wall for most of its height. So a crest that drops at least
``min_wall`` on both sides of a mesh line must be at least ``min_wall`` wide
(times :data:`WALL_MARGIN`) at ``min_wall`` below its top
(:func:`wall_widths`; the profile is followed along the line for as many
vertices as that takes, and the saucer's border is a vertical wall, so a
border vertex standing above the inside is a lip). This is the test
``saucerfab check`` makes of thin spots (a thin spot within one minimum wall
of material at least that thick is relief, not a wall), written on the grid.
The projection lowers such a crest (bisection on its height) until the rule
holds.

A part cut from the grid by an outline across its cells (a round saucer:
the disc inscribed in the square grid) has its side at the outline, not at
the grid's border. The rules take an ``edge`` table (:func:`edge_lines`):
beyond the outline a vertex reads as the side's drop on a line that crosses
it nearly square on, and as open on an oblique one, and is never a crest
itself; the export lowers those vertices (:func:`lower_beyond_edge`) so that
no face rises into the cut, which would leave a lip no rule on the grid sees.

Units: any length unit, the same for heights and spacings (the optimizer
works in model units, the export in millimetres).

Speed: the optimizer projects every trial step, so the wall rule's walks run
in numba (:mod:`saucerfab.model.relief_kernels`); the numpy versions here
(:func:`wall_widths_reference`, :func:`bisect_tops_reference`) are their
references, equal bit for bit (tests/model/test_relief.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: a lowered crest keeps this share of the minimum feature as prominence (under
#: the rule's threshold with room for float rounding and the export's mm scaling)
PROMINENCE_MARGIN = 0.95

#: the wall rule asks this multiple of the minimum wall (the checker measures
#: along the surface normal, not across the grid line, and samples at random)
WALL_MARGIN = 1.25

#: a crest lowered by the wall rule is made this much wider than the rule asks
#: (the optimizer keeps heights in float32; the bisection ends on the boundary)
WALL_SLACK = 0.02

#: a crest lowered by the wall rule ends this share of the minimum wall below the
#: bisection's answer
SETTLE = 1e-4

#: how much stricter the optimizer holds the rules than the export checks them:
#: a design's heights are float32 model units, the export's float64 mm, and a
#: crest may rest exactly on a rule's threshold
OPTIMIZER_TIGHTEN = 1e-3

#: sweeps of :func:`blunt_thin_crests` before it gives up (each fixes every thin
#: crest found; later sweeps only mop up crests the moves created)
MAX_SWEEPS = 200


def _lines(h: np.ndarray, dx: float, dy: float) -> tuple[tuple[np.ndarray, np.ndarray, float, tuple[int, int]], ...]:
    """The three mesh lines through every interior vertex: (a, b, length, (di, dj) of b)."""
    return (
        (h[1:-1, :-2], h[1:-1, 2:], dx, (0, 1)),  # along x
        (h[:-2, 1:-1], h[2:, 1:-1], dy, (1, 0)),  # along y
        (h[:-2, :-2], h[2:, 2:], math.hypot(dx, dy), (1, 1)),  # the triangulation's diagonal
    )


def feature_crests_reference(
    h: np.ndarray, dx: float, dy: float, crest_p: float, feature_w: float, keep: float,
    edge: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The feature rule's findings on every interior vertex, in whole-grid numpy passes.

    A vertex is a thin crest on a mesh line when it stands at least ``crest_p``
    above both neighbours on the line and its width at half that prominence is
    under ``feature_w``. The reference of
    :func:`saucerfab.model.relief_kernels.feature_crests` (the same float64
    operations in the same order, bit for bit).

    Args:
        h: (N, M) float64 heights. dx, dy: grid spacing. keep: how far above the
            higher neighbour a thin crest is lowered to. edge: (3, N, M), the
            part's edge across the grid (:func:`edge_lines`): no vertex beyond
            it is a crest, nor one on a line to it (the wall rule judges the edge).

    Returns:
        ``target`` (N-2, M-2): the height each thin crest is lowered to (the
        lowest over its thin lines), ``inf`` elsewhere; ``thin`` (3, N-2, M-2)
        bool per line of :func:`_lines`; ``a_higher`` (3, N-2, M-2) bool: the
        line's first neighbour is at least as high as its second.
    """
    c = h[1:-1, 1:-1]
    off = _off(edge, h.shape)
    target = np.full(c.shape, np.inf)
    thin_lines, a_higher = [], []
    for (a, b, length, _), (off_a, off_b, _, _) in zip(_lines(h, dx, dy), _lines(off, dx, dy), strict=True):
        m = np.maximum(a, b)
        p = c - m
        with np.errstate(divide="ignore", invalid="ignore"):
            w = length * 0.5 * p * (1.0 / (c - a) + 1.0 / (c - b))
        thin = (p >= crest_p) & (w < feature_w) & ~(off[1:-1, 1:-1] | off_a | off_b)
        target = np.where(thin, np.minimum(target, m + keep), target)
        thin_lines.append(thin)
        a_higher.append(a >= b)
    return target, np.stack(thin_lines), np.stack(a_higher)


def _feature_crests(
    h: np.ndarray, dx: float, dy: float, crest_p: float, feature_w: float, keep: float,
    edge: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`feature_crests_reference` by the numba kernel (one pass over the vertices)."""
    from saucerfab.model.relief_kernels import feature_crests

    # the lines' lengths in _lines' order, which the kernel's offsets (_DI, _DJ) follow
    lengths = np.array([length for _, _, length, _ in _lines(h, dx, dy)], np.float64)
    return feature_crests(np.ascontiguousarray(h, np.float64), _kernel_edge(edge, h.shape), lengths, float(crest_p),
                          float(feature_w), float(keep))


def crest_widths(heights: np.ndarray, dx: float, dy: float, min_height: float,
                 edge: np.ndarray | None = None) -> np.ndarray:
    """Width at half prominence of each crest vertex; ``inf`` where there is none.

    Args:
        heights: (N, M) heights, rows along y.
        dx, dy: grid spacing along x (columns) and y (rows), same unit.
        min_height: prominence below which a crest is ignored (the minimum feature).
        edge: (3, N, M), the part's edge across the grid (:func:`edge_lines`;
            as :func:`feature_crests_reference`). None: all part.

    Returns:
        (N, M) float64 widths (``inf`` for non-crests and the border), the
        smallest over the three mesh lines through the vertex.
    """
    h = np.asarray(heights, np.float64)
    width = np.full(h.shape, np.inf)
    c = h[1:-1, 1:-1]
    off = _off(edge, h.shape)
    inner = width[1:-1, 1:-1]
    for (a, b, length, _), (off_a, off_b, _, _) in zip(_lines(h, dx, dy), _lines(off, dx, dy), strict=True):
        p = c - np.maximum(a, b)
        crest = (p >= min_height) & ~(off[1:-1, 1:-1] | off_a | off_b)
        with np.errstate(divide="ignore", invalid="ignore"):
            w = length * 0.5 * p * (1.0 / (c - a) + 1.0 / (c - b))
        inner[...] = np.where(crest, np.minimum(inner, w), inner)
    return width


#: stands for the drop at the saucer's border (its side wall goes straight down) on
#: the x and y lines, which cross the border square on
_WALL = -1e30
#: beyond the border on the diagonal line: "higher", so the line is no crest there
#: (a diagonal leaves through a side wall obliquely: the material beside the wall
#: is as thick as the x or y line through it says, not as the slanted section)
_OPEN = 1e30

#: the three mesh lines: (di, dj, which spacing, what lies beyond the border)
_WALL_LINES = ((0, 1, "x", _WALL), (1, 0, "y", _WALL), (1, 1, "xy", _OPEN))


#: a line crossing the part's edge within this angle of square on reads the vertex beyond it as
#: the side wall; a more oblique one as open (the material beside the edge is as thick as the
#: squarer line through it says, as the diagonal at a rectangle's border). One of the three mesh
#: lines is always within 22.5 degrees of square on.
EDGE_SQUARE_DEG = 45.0


def edge_lines(off_part: np.ndarray, outward: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """What each vertex beyond a part's edge reads as on each mesh line (the rules' ``edge``).

    A part cut from the grid by an outline across its cells (a round saucer)
    ends in a vertical side wall at the outline. The rules read a vertex
    beyond it, on a line that crosses the outline nearly square on, as the
    drop of that wall (as beyond the grid's border, :data:`_WALL`), and on an
    oblique line as "higher" (:data:`_OPEN`: no crest on that line), which
    keeps a vertex at the outline's tangent points from reading as a wall
    of no width between two drops.

    Args:
        off_part: (N, M) bool, the vertices beyond the edge.
        outward: (N, M, 2) the outline's outward normal (x, y) near each vertex
            (a disc: the unit radial direction); read only beyond the edge.
        dx, dy: grid spacing along x (columns) and y (rows).

    Returns:
        (3, N, M) float64 per line of :data:`_WALL_LINES`: NaN on the part,
        :data:`_WALL` or :data:`_OPEN` beyond it.
    """
    off = np.asarray(off_part, bool)
    n = np.asarray(outward, np.float64)
    if n.shape != off.shape + (2,):
        raise ValueError(f"outward is {n.shape}, expected {off.shape + (2,)}")
    square = math.cos(math.radians(EDGE_SQUARE_DEG)) + 1e-9  # exactly 45 degrees is oblique, as at a border
    out = np.full((len(_WALL_LINES),) + off.shape, np.nan)
    for k, (di, dj, _, _) in enumerate(_WALL_LINES):
        d = np.array([dj * dx, di * dy]) / math.hypot(dj * dx, di * dy)
        across = np.abs(n[..., 0] * d[0] + n[..., 1] * d[1]) >= square
        out[k] = np.where(off, np.where(across, _WALL, _OPEN), np.nan)
    return out


#: the kernels' table of a grid that is all part (its border is its edge): read as no edge at all
_NO_EDGE = np.full((len(_WALL_LINES), 1, 1), np.nan)


def _edge(edge: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """(3, N, M) float64 :func:`edge_lines` table, or all NaN (a grid that is all part)."""
    if edge is None:
        return np.full((len(_WALL_LINES),) + tuple(shape), np.nan)
    e = np.ascontiguousarray(edge, np.float64)
    if e.shape != (len(_WALL_LINES),) + tuple(shape):
        raise ValueError(f"edge is {e.shape}, expected {(len(_WALL_LINES),) + tuple(shape)} (edge_lines)")
    return e


def _read_on(h: np.ndarray, edge: np.ndarray, line: int) -> np.ndarray:
    """(N, M) the heights as ``line`` reads them: beyond the part's edge, the ``edge`` table's wall or opening."""
    return np.where(np.isnan(edge[line]), h, edge[line])


def _kernel_edge(edge: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """The kernels' ``edge``: the checked table, or :data:`_NO_EDGE` (no table to read on every step)."""
    return _NO_EDGE if edge is None else _edge(edge, shape)


def _off(edge: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """(N, M) bool: the vertices beyond the part's edge in an :func:`edge_lines` table."""
    return ~np.isnan(_edge(edge, shape)[0])


def lower_beyond_edge(heights: np.ndarray, edge: np.ndarray) -> np.ndarray:
    """``heights`` with each vertex beyond the part's edge no higher than its lowest neighbour on the part.

    A part cut from the grid by an outline across its cells (a round saucer)
    keeps the faces that straddle the outline up to it. Where such a face rose
    outwards, the cut left a lip: the face's slope and the vertical side meet
    at an acute edge, a fin thinner than any printer's wall (a design's 0.014 mm
    at a round saucer's edge). Lowered so, every straddling face falls or stays
    level towards the side, and the part's edge is the vertical wall that
    :func:`wall_widths` reads beyond ``edge``. Vertices with no neighbour on
    the part are cut away whole and kept as they are.

    Args:
        heights: (N, M) heights. edge: (3, N, M), the part's edge across the grid (:func:`edge_lines`).
    Returns:
        (N, M) float64 heights; the part's own vertices unchanged.
    """
    h = np.asarray(heights, np.float64)
    off = _off(edge, h.shape)
    on = np.where(off, np.inf, h)
    padded = np.pad(on, 1, constant_values=np.inf)
    rows, cols = h.shape
    lowest = np.full(h.shape, np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                lowest = np.minimum(lowest, padded[1 + di:1 + di + rows, 1 + dj:1 + dj + cols])
    return np.where(off & np.isfinite(lowest), np.minimum(h, lowest), h)


def _length(which: str, dx: float, dy: float) -> float:
    return dx if which == "x" else dy if which == "y" else math.hypot(dx, dy)


def _wall_steps(depth: float, dx: float, dy: float) -> int:
    """Vertices followed along a line each way: enough to cover ``depth`` of width."""
    return int(math.ceil(depth / min(dx, dy))) + 1


def _walk_width(neighbour: Callable[[int, int], np.ndarray], top: np.ndarray, level: np.ndarray, length: float,
                k_max: int, plateau: bool = False, rise_tol: float = 0.0) -> np.ndarray:
    """Width at ``level`` of crests of height ``top`` along one line; ``neighbour(side, k)`` gives the heights
    ``k`` vertices away on ``side`` (+1 or -1), shaped like ``top``.

    ``inf`` where the line is no crest (the profile rises above ``top`` before
    it falls to ``level`` on a side) or does not fall to ``level`` within
    ``k_max`` vertices on a side (then it is at least that wide anyway).
    ``plateau``: a neighbour above ``top`` counts as at ``top`` (part of the
    crest) instead; the projection lowers a crest with this, so that it
    widens the crest rather than slipping a hair under a neighbour as high as
    itself (which would then be the thin crest, and so on, a hair per sweep).
    ``rise_tol``: a neighbour must be this much above ``top`` to end the crest
    (the rule jumps there, from a width to "no crest"; the optimizer keeps
    clear of the jump by more than its float32 rounding).
    """
    width = np.zeros(top.shape)
    for side in (1, -1):
        extent = np.full(top.shape, np.inf)
        done = np.zeros(top.shape, bool)
        prev = top.copy()
        for k in range(1, k_max + 1):
            n = neighbour(side, k)
            if plateau:
                n = np.minimum(n, top)
            higher = ~done & (n > top + rise_tol)
            width[higher] = np.inf  # no crest on this line
            done |= higher
            cross = ~done & (n <= level)
            if cross.any():
                frac = (prev[cross] - level[cross]) / np.maximum(prev[cross] - n[cross], 1e-300)
                extent[cross] = length * (k - 1 + np.clip(frac, 0.0, 1.0))
            done |= cross
            if done.all():
                break
            prev = np.where(done, prev, n)
        width = width + extent
    return width


def _line_tables(dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    """The kernels' view of :data:`_WALL_LINES`: each line's length and what lies beyond the border."""
    return (np.array([_length(which, dx, dy) for _, _, which, _ in _WALL_LINES]),
            np.array([beyond for _, _, _, beyond in _WALL_LINES]))


def wall_widths(heights: np.ndarray, dx: float, dy: float, depth: float, rise_tol: float = 0.0,
                edge: np.ndarray | None = None) -> np.ndarray:
    """Width of each crest at ``depth`` below its top (the wall rule); ``inf`` where it is no crest.

    Args:
        heights: (N, M) heights, rows along y.
        dx, dy: grid spacing along x (columns) and y (rows).
        depth: the minimum wall.
        rise_tol: how far above a crest a neighbour must be to end it (:func:`_walk_width`).
        edge: (3, N, M), the part's edge across the grid (a round saucer's
            corners, :func:`edge_lines`): the vertices beyond it are read as
            beyond a border, and are no crest themselves (the export lowers
            them so, :func:`lower_beyond_edge`). None: all part.

    Returns:
        (N, M) float64 widths, the smallest over the three mesh lines, border
        vertices included (beyond the border the side wall drops straight down).
        The numba kernel :func:`saucerfab.model.relief_kernels.wall_widths_grid`;
        :func:`wall_widths_reference` is the same in numpy, bit for bit.
    """
    from saucerfab.model.relief_kernels import wall_widths_grid

    lengths, beyond = _line_tables(dx, dy)
    h = np.ascontiguousarray(heights, np.float64)
    return wall_widths_grid(h, _kernel_edge(edge, h.shape), float(depth), lengths, beyond,
                            _wall_steps(depth * WALL_MARGIN, dx, dy), float(rise_tol))


def wall_widths_reference(heights: np.ndarray, dx: float, dy: float, depth: float,
                          rise_tol: float = 0.0, edge: np.ndarray | None = None) -> np.ndarray:
    """:func:`wall_widths` in whole-grid numpy passes (the kernel's reference)."""
    h = np.asarray(heights, np.float64)
    e = _edge(edge, h.shape)
    rows, cols = h.shape
    k_max = _wall_steps(depth * WALL_MARGIN, dx, dy)
    out = np.full(h.shape, np.inf)
    for line, (di, dj, which, beyond) in enumerate(_WALL_LINES):
        hp = np.pad(_read_on(h, e, line), k_max, constant_values=beyond)

        def shifted(side: int, k: int, _hp: np.ndarray = hp, _di: int = di, _dj: int = dj) -> np.ndarray:
            oi, oj = k_max + side * k * _di, k_max + side * k * _dj  # whole shifted views: no gathers
            return _hp[oi:oi + rows, oj:oj + cols]

        out = np.minimum(out, _walk_width(shifted, h, h - depth, _length(which, dx, dy), k_max, rise_tol=rise_tol))
    return np.where(np.isnan(e[0]), out, np.inf)


#: bisection rounds of the wall rule's lowering (2**-30 of the search interval)
BISECT_ROUNDS = 30


def bisect_tops_reference(h: np.ndarray, ii: np.ndarray, jj: np.ndarray, lo_vals: np.ndarray, depth: float,
                          want: float, k: int, dx: float, dy: float,
                          edge: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per thin crest (ii, jj) the highest top at which it is ``want`` wide ``depth`` below, in numpy.

    The reference of :func:`saucerfab.model.relief_kernels.bisect_tops`: the
    neighbours stay at ``h``, a neighbour above the trial top counts as at it.
    Returns (lo_top (K,), ok_low (K,): wide enough at its lowest allowed top).
    """
    e = _edge(edge, h.shape)
    padded = [(np.pad(_read_on(h, e, line), k, constant_values=beyond), di, dj, _length(which, dx, dy))
              for line, (di, dj, which, beyond) in enumerate(_WALL_LINES)]
    pi, pj = ii + k, jj + k

    def wide(top: np.ndarray) -> np.ndarray:
        w = np.full(top.shape, np.inf)
        for hp, di, dj, length in padded:
            def gather(side: int, step: int, _hp: np.ndarray = hp, _di: int = di, _dj: int = dj) -> np.ndarray:
                return _hp[pi + side * step * _di, pj + side * step * _dj]

            w = np.minimum(w, _walk_width(gather, top, top - depth, length, k, plateau=True))
        return w >= want

    hi_top = h[ii, jj].copy()  # too high (thin)
    # a crest never needs to come down further than a few walls (and lo may be -inf)
    lo_top = np.maximum(lo_vals, hi_top - 16.0 * depth)
    ok_low = wide(lo_top)
    for _ in range(BISECT_ROUNDS):
        mid = 0.5 * (hi_top + lo_top)
        w = wide(mid)
        lo_top = np.where(w, mid, lo_top)
        hi_top = np.where(w, hi_top, mid)
    return lo_top, ok_low


def _bisect_tops(h: np.ndarray, ii: np.ndarray, jj: np.ndarray, lo_vals: np.ndarray, depth: float,
                 want: float, k: int, dx: float, dy: float,
                 edge: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bisect_tops_reference` by the numba kernel (the same float operations)."""
    from saucerfab.model.relief_kernels import bisect_tops

    lengths, beyond = _line_tables(dx, dy)
    return bisect_tops(np.ascontiguousarray(h, np.float64), _kernel_edge(edge, h.shape), ii, jj,
                       np.ascontiguousarray(lo_vals, np.float64),
                       float(depth), float(want), k, lengths, beyond, BISECT_ROUNDS)


def _lower_until_wide(h: np.ndarray, lo: np.ndarray, dx: float, dy: float, depth: float,
                      want: float, rise_tol: float = 0.0, widths: np.ndarray | None = None,
                      edge: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lower each crest narrower than ``want`` at ``depth`` until it is ``WALL_SLACK`` wider (bisection).

    ``widths``: :func:`wall_widths` of ``h`` when the caller has them (they are not computed again).
    Returns (new h, stuck: crests even their lower bound leaves too narrow).
    """
    if widths is None:
        widths = wall_widths(h, dx, dy, depth, rise_tol, edge)
    thin = widths < want
    want = want * (1.0 + WALL_SLACK)  # so float32 rounding of the result cannot undo it
    k = _wall_steps(want, dx, dy)
    if not thin.any():
        return h, np.zeros(h.shape, bool)
    ii, jj = np.nonzero(thin)
    lo_top, ok_low = _bisect_tops(h, ii, jj, lo[ii, jj], depth, want, k, dx, dy, edge)
    out = h.copy()
    # a hair lower than the bisection's answer: the rule can jump there (a dip of exactly ``depth``
    # before a rise ends the crest), and the optimizer's float32 must not round back across it
    settled = np.maximum(lo[ii, jj], lo_top - SETTLE * depth)
    out[ii, jj] = np.where(ok_low, settled, np.maximum(lo[ii, jj], lo_top))
    stuck = np.zeros(h.shape, bool)
    stuck[ii[~ok_low], jj[~ok_low]] = True
    return out, stuck


@dataclass(frozen=True)
class BluntResult:
    """What :func:`blunt_thin_crests` did.

    Attributes:
        heights: (N, M) float64, the blunted heights.
        lowered: vertices moved down (thin crests).
        raised: vertices moved up (higher neighbours of crests resting on their lower bound).
        max_change: largest |change| of any vertex, the heights' unit.
        sweeps: sweeps run.
        remaining: thin crest vertices left (0 unless the bounds leave no way out).
    """

    heights: np.ndarray
    lowered: int
    raised: int
    max_change: float
    sweeps: int
    remaining: int

    @property
    def changed(self) -> int:
        return self.lowered + self.raised


def blunt_thin_crests(
    heights: np.ndarray,
    dx: float,
    dy: float,
    min_feature: float,
    lo: np.ndarray | None = None,
    hi: np.ndarray | None = None,
    *,
    min_wall: float | None = None,
    tighten: float = 0.0,
    max_sweeps: int = MAX_SWEEPS,
    edge: np.ndarray | None = None,
) -> BluntResult:
    """The heightfield with every crest thinner than ``min_feature`` blunted (module docstring).

    With ``min_wall`` the wall rule is kept too (:func:`wall_widths`).

    Args:
        heights: (N, M) heights, rows along y.
        dx, dy: grid spacing along x and y, the heights' unit.
        min_feature: the printer's minimum feature, the heights' unit.
        lo, hi: (N, M) bounds no vertex may leave (the design's ``z -/+ delta``,
            less a margin when the caller needs strict feasibility); None:
            unbounded. ``heights`` must lie within them.
        min_wall: the printer's minimum wall, the heights' unit; None: only the feature rule.
        tighten: hold the widths to ``(1 + tighten)`` times what the rules ask,
            so that a result computed in another unit or precision (the
            optimizer's float32 model units, the export's float64 mm) still
            meets them exactly (the optimizer uses :data:`OPTIMIZER_TIGHTEN`).
        max_sweeps: give up after this many sweeps (:data:`MAX_SWEEPS`).
        edge: (3, N, M), the part's edge across the grid (a round saucer's
            corners, :func:`edge_lines`): never crests, never moved, and read
            as the part's side (:func:`wall_widths`). None: all part.

    Returns:
        a :class:`BluntResult`; ``remaining > 0`` when the bounds made the rule
        impossible to meet at some vertices (the caller says so).
    """
    h0 = np.asarray(heights, np.float64)
    h = h0.copy()
    lo_a = np.full(h.shape, -np.inf) if lo is None else np.asarray(lo, np.float64)
    hi_a = np.full(h.shape, np.inf) if hi is None else np.asarray(hi, np.float64)
    keep = PROMINENCE_MARGIN * min_feature
    feature_w = min_feature * (1.0 + tighten)  # the width a crest of min_feature's prominence must have
    crest_p = min_feature * (1.0 - tighten)  # the prominence that makes a crest
    wall_w = None if min_wall is None else WALL_MARGIN * min_wall * (1.0 + tighten)
    rise = 0.0 if min_wall is None else tighten * min_wall  # near-equal neighbours belong to the crest
    down = np.zeros(h.shape, bool)
    up = np.zeros(h.shape, bool)
    sweeps = 0
    clean = False
    for sweeps in range(1, max_sweeps + 1):
        c = h[1:-1, 1:-1]
        target, thin_lines, a_higher = _feature_crests(h, dx, dy, crest_p, feature_w, keep, edge)
        thin_any = thin_lines.any(axis=0)
        # the wall rule's widths, computed once per sweep (this runs on every trial step of the optimizer)
        ww = None if min_wall is None else wall_widths(h, dx, dy, min_wall, rise, edge)
        wall_thin = ww is not None and bool((ww < wall_w).any())
        if not thin_any.any() and not wall_thin:
            clean = True
            break
        prev = h.copy()
        inner_lo = lo_a[1:-1, 1:-1]
        new_c = np.where(thin_any, np.maximum(target, inner_lo), c)
        down[1:-1, 1:-1] |= new_c < c
        # crests their lower bound holds up: raise the higher neighbour on each
        # thin line to just under the crest's prominence instead
        stuck = thin_any & (target < inner_lo)
        c_after = new_c
        h[1:-1, 1:-1] = new_c
        if stuck.any():
            n_cols = h.shape[1]
            flat_h = h.reshape(-1)  # a view: writes go into h
            for k, (_, _, _, (di, dj)) in enumerate(_lines(h, dx, dy)):
                sel = stuck & thin_lines[k]
                if not sel.any():
                    continue
                ii, jj = np.nonzero(sel)
                # neighbour a sits at (i - di, j - dj), b at (i + di, j + dj), full-grid indices
                side = np.where(a_higher[k][sel], -1, 1)
                ni, nj = ii + 1 + side * di, jj + 1 + side * dj
                flat = ni * n_cols + nj
                want = np.minimum(c_after[ii, jj] - keep, hi_a[ni, nj])
                before = flat_h[flat].copy()
                np.maximum.at(flat_h, flat, want)
                up.reshape(-1)[flat[flat_h[flat] > before]] = True
        if wall_thin:
            before_w = h.copy()
            # the widths still hold when the feature pass moved nothing
            h, _ = _lower_until_wide(h, lo_a, dx, dy, min_wall, wall_w, rise,
                                     widths=None if thin_any.any() else ww, edge=edge)
            down |= h < before_w
        if np.array_equal(h, prev):  # the bounds hold every thin crest where it is: no way out
            break
    remaining = 0
    if not clean:
        bad = crest_widths(h, dx, dy, crest_p, edge) < feature_w
        if min_wall is not None:
            bad |= wall_widths(h, dx, dy, min_wall, rise, edge) < wall_w
        remaining = int(bad.sum())
    change = np.abs(h - h0)
    return BluntResult(
        heights=h,
        lowered=int((down & (h < h0)).sum()),
        raised=int((up & (h > h0)).sum()),
        max_change=float(change.max()) if change.size else 0.0,
        sweeps=sweeps,
        remaining=remaining,
    )
