"""The relief rules at a part's edge across the grid (a round saucer's disc cut from the square grid).

The grid vertices beyond the edge (``off_part``) are read as beyond the grid's
border: the wall rule sees the part's vertical side there and no crest among
them, the feature rule leaves the edge to the wall rule, and the export lowers
them so that no face rises into the cut (``lower_beyond_edge``), which left a
0.014 mm fin at a round design's edge (tree-note on the J55, session 24).
"""

from __future__ import annotations

import numpy as np
import pytest

from saucerfab.model import relief
from saucerfab.model.relief import blunt_thin_crests, crest_widths, edge_lines, lower_beyond_edge, wall_widths


def _rough(seed: int, n: int = 23, m: int = 29) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h = np.cumsum(rng.normal(0, 0.6, size=(n, m)), axis=0) + rng.gamma(0.4, 2.0, size=(n, m))
    h[rng.random(h.shape) < 0.05] += 4.0
    return h


def _disc_edge(n: int, m: int, dx: float = 0.67, dy: float = 0.5) -> np.ndarray:
    """The rules' edge table of the ellipse inscribed in an (n, m) grid (a disc's corners cut away)."""
    y, x = np.mgrid[0:n, 0:m]
    u, v = (x - (m - 1) / 2) / ((m - 1) / 2), (y - (n - 1) / 2) / ((n - 1) / 2)
    r = np.maximum(np.hypot(u, v), 1e-12)
    return edge_lines(r > 1.0, np.stack([u / r, v / r], axis=-1), dx, dy)


def _off(edge: np.ndarray) -> np.ndarray:
    return ~np.isnan(edge[0])


@pytest.mark.parametrize("cut", [5, 11])
def test_vertices_off_the_part_read_exactly_as_beyond_the_grids_border(cut: int) -> None:
    # the columns from ``cut`` on are off the part: the rules on the rest equal the rules on the grid cut there
    # (a square grid: its diagonal meets the side at 45 degrees, oblique as at the border)
    h = _rough(3)
    off = np.zeros(h.shape, bool)
    off[:, cut:] = True
    off = edge_lines(off, np.broadcast_to([1.0, 0.0], h.shape + (2,)), 0.5, 0.5)  # a straight side along y
    for depth in (0.5, 1.0, 2.0):
        masked = wall_widths(h, 0.5, 0.5, depth, edge=off)
        assert np.array_equal(masked[:, :cut], wall_widths(h[:, :cut], 0.5, 0.5, depth))
        assert np.isinf(masked[:, cut:]).all()
    w = crest_widths(h, 0.5, 0.5, 0.3, off)
    cropped = crest_widths(h[:, :cut], 0.5, 0.5, 0.3)
    # inside as the cropped grid; off the part no crest (the last column on it keeps its line along the edge)
    assert np.array_equal(w[:, :cut - 1], cropped[:, :cut - 1]) and np.isinf(w[:, cut:]).all()


@pytest.mark.parametrize("seed", range(3))
def test_the_kernels_with_an_edge_equal_their_numpy_references_bit_for_bit(seed: int) -> None:
    h = _rough(seed)
    off = _disc_edge(*h.shape)
    for depth in (0.5, 1.0):
        for rise in (0.0, 1e-3):
            assert np.array_equal(wall_widths(h, 0.67, 0.5, depth, rise, off),
                                  relief.wall_widths_reference(h, 0.67, 0.5, depth, rise, off))
    ii, jj = np.nonzero(wall_widths(h, 0.67, 0.5, 1.0, edge=off) < 1.25)
    assert len(ii) > 3
    lo = h - 2.0
    k = relief._wall_steps(1.275, 0.67, 0.5)
    fast = relief._bisect_tops(h, ii, jj, lo[ii, jj], 1.0, 1.275, k, 0.67, 0.5, off)
    ref = relief.bisect_tops_reference(h, ii, jj, lo[ii, jj], 1.0, 1.275, k, 0.67, 0.5, off)
    assert np.array_equal(fast[0], ref[0]) and np.array_equal(fast[1], ref[1])
    fast = relief._feature_crests(h, 0.67, 0.5, 0.3, 0.4, 0.01, off)
    ref = relief.feature_crests_reference(h, 0.67, 0.5, 0.3, 0.4, 0.01, off)
    assert all(np.array_equal(f, r) for f, r in zip(fast, ref, strict=True))
    assert fast[1].any()


def test_blunting_with_an_edge_by_the_kernels_equals_the_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    h = _rough(7, 40, 40)
    off = _disc_edge(40, 40, 0.67, 0.67)
    lo, hi = h - 1.5, h + 1.5
    fast = blunt_thin_crests(h, 0.67, 0.67, 0.3, lo, hi, min_wall=1.0, tighten=1e-3, edge=off)
    monkeypatch.setattr(relief, "wall_widths", relief.wall_widths_reference)
    monkeypatch.setattr(relief, "_bisect_tops", relief.bisect_tops_reference)
    monkeypatch.setattr(relief, "_feature_crests", relief.feature_crests_reference)
    ref = blunt_thin_crests(h, 0.67, 0.67, 0.3, lo, hi, min_wall=1.0, tighten=1e-3, edge=off)
    assert fast.lowered > 10 and (fast.lowered, fast.remaining, fast.sweeps) == (ref.lowered, ref.remaining, ref.sweeps)
    assert np.array_equal(fast.heights, ref.heights)
    assert np.array_equal(fast.heights[_off(off)], h[_off(off)])  # nothing beyond the edge is a crest: never moved


def test_a_lip_at_the_edge_is_a_wall_and_blunting_lowers_it() -> None:
    n = 21
    edge = _disc_edge(n, n, 0.67, 0.67)
    off = _off(edge)
    h = np.zeros((n, n))
    # the last vertex on the part along row 4 stands 3 mm above the inside: beyond it the side drops
    j = int(np.flatnonzero(~off[4])[-1])
    assert j < n - 1
    h[4, j] = 3.0
    h[off] = 5.0  # high ground beyond the edge is cut away: it holds nothing up
    assert wall_widths(h, 0.67, 0.67, 1.0, edge=edge)[4, j] < 1.25
    assert np.isinf(wall_widths(h, 0.67, 0.67, 1.0)[4, j])  # read as a slope up to the corner, it was no wall
    res = blunt_thin_crests(h, 0.67, 0.67, 0.3, min_wall=1.0, edge=edge)
    assert res.remaining == 0 and res.heights[4, j] < 3.0
    assert (wall_widths(res.heights, 0.67, 0.67, 1.0, edge=edge) >= 1.25).all()


def test_lowering_beyond_the_edge_keeps_the_part_and_slopes_every_cut_face_down() -> None:
    h = _rough(5, 31, 31)
    edge = _disc_edge(31, 31)
    off = _off(edge)
    out = lower_beyond_edge(h, edge)
    assert np.array_equal(out[~off], h[~off])
    pad_on = np.pad(np.where(off, np.inf, h), 1, constant_values=np.inf)
    touched = 0
    for i, j in zip(*np.nonzero(off), strict=True):
        lowest = pad_on[i:i + 3, j:j + 3].min()  # the lowest neighbour on the part (the vertex itself is inf)
        if np.isfinite(lowest):
            assert out[i, j] == min(h[i, j], lowest)
            touched += 1
        else:
            assert out[i, j] == h[i, j]  # wholly beyond the edge: cut away, kept
    assert touched > 20 and (out <= h).all()
    assert np.array_equal(lower_beyond_edge(out, edge), out)  # once is enough


def test_an_edge_table_of_another_shape_is_refused() -> None:
    with pytest.raises(ValueError, match="edge is"):
        wall_widths(np.zeros((5, 5)), 1.0, 1.0, 1.0, edge=_disc_edge(4, 5))
    with pytest.raises(ValueError, match="outward"):
        edge_lines(np.zeros((4, 5), bool), np.zeros((4, 5, 3)), 1.0, 1.0)


def test_a_tangent_point_of_the_disc_is_judged_across_the_edge_not_along_it() -> None:
    # the disc's lowest point: both neighbours along x are beyond the edge. Read as walls, it would be a
    # crest of no width at any height (the optimizer could never make it printable); along x the line runs
    # with the edge (open), and across it (y) the grid's border is the side
    n = 21
    edge = _disc_edge(n, n, 0.67, 0.67)
    c = n // 2
    assert _off(edge)[0, c - 1] and _off(edge)[0, c + 1] and not _off(edge)[0, c]
    h = np.zeros((n, n))
    assert np.isinf(wall_widths(h, 0.67, 0.67, 1.0, edge=edge)).all()
    res = blunt_thin_crests(h + 0.0, 0.67, 0.67, 0.3, min_wall=1.0, edge=edge)
    assert res.changed == 0 and res.remaining == 0
    h[0, c] = 3.0  # a lip standing at the tangent point: across the edge it is a wall
    assert wall_widths(h, 0.67, 0.67, 1.0, edge=edge)[0, c] < 1.25
