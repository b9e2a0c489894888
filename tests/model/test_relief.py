"""Tests of saucerfab.model.relief (the minimum-feature rule and its projection) and
saucerfab.optimize.printable (the design's printer: preflight, projection in the optimizer)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from saucerfab.errors import ConfigError
from saucerfab.fabricate.options import FabOptions
from saucerfab.model import relief
from saucerfab.model.relief import PROMINENCE_MARGIN, WALL_MARGIN, blunt_thin_crests, crest_widths, wall_widths
from saucerfab.model.scene import Saucer, Scene
from saucerfab.optimize.printable import CrestProjection, preflight, print_target, worst_case_bbox_mm

# --------------------------------------------------------------------------- the rule


def test_crest_width_of_a_symmetric_spike_is_one_spacing() -> None:
    h = np.zeros((7, 7))
    h[3, 3] = 5.0
    w = crest_widths(h, dx=0.4, dy=0.6, min_height=0.1)
    assert w[3, 3] == pytest.approx(0.4)  # along x; y gives 0.6, the diagonal hypot(0.4, 0.6)
    assert np.isinf(np.delete(w.ravel(), 3 * 7 + 3)).all()


def test_crest_width_of_an_asymmetric_crest() -> None:
    h = np.zeros((3, 3))
    h[:, 0], h[:, 1], h[:, 2] = 0.0, 10.0, 5.0  # a ridge along y, steeper on its left
    w = crest_widths(h, 1.0, 1.0, 0.1)
    # prominence 5; half height 7.5 is 0.25 to the left and 0.5 to the right
    assert w[1, 1] == pytest.approx(0.75)
    # a crest lower than min_height is no feature
    assert np.isinf(crest_widths(h, 1.0, 1.0, 6.0)[1, 1])


def reference_widths(h: np.ndarray, dx: float, dy: float, mf: float) -> np.ndarray:
    """The rule written out vertex by vertex (the slow, obvious version)."""
    n, m = h.shape
    out = np.full(h.shape, np.inf)
    for i in range(1, n - 1):
        for j in range(1, m - 1):
            for (ai, aj), (bi, bj), length in (
                ((i, j - 1), (i, j + 1), dx),
                ((i - 1, j), (i + 1, j), dy),
                ((i - 1, j - 1), (i + 1, j + 1), math.hypot(dx, dy)),
            ):
                c, a, b = h[i, j], h[ai, aj], h[bi, bj]
                hi_n, lo_n = max(a, b), min(a, b)
                p = c - hi_n
                if p >= mf:
                    # half prominence reached at p/2 down each flank, linearly
                    w = length * (p / 2) / (c - hi_n) + length * (p / 2) / (c - lo_n)
                    out[i, j] = min(out[i, j], w)
    return out


def test_crest_widths_match_the_reference_on_random_relief() -> None:
    rng = np.random.default_rng(3)
    h = rng.gamma(0.5, 1.0, size=(14, 11))
    np.testing.assert_allclose(crest_widths(h, 0.7, 0.4, 0.6), reference_widths(h, 0.7, 0.4, 0.6), rtol=1e-12)


# --------------------------------------------------------------------------- the projection


def test_blunting_removes_every_thin_crest_with_small_local_moves() -> None:
    rng = np.random.default_rng(0)
    h = rng.normal(0.0, 0.3, size=(30, 30))
    h[rng.random(h.shape) < 0.05] += 2.0  # needles one vertex wide
    dx = dy = 0.4  # a symmetric needle is one spacing wide: under the 0.5 minimum
    mf = 0.5
    before = crest_widths(h, dx, dy, mf) < mf
    assert before.sum() > 10
    res = blunt_thin_crests(h, dx, dy, mf)
    assert res.remaining == 0
    assert not (crest_widths(res.heights, dx, dy, mf) < mf).any()
    moved = res.heights != h
    assert res.changed == int(moved.sum()) and res.lowered > 0
    # only thin crests (and what their moves made thin) move, and only down here (no bounds)
    assert res.raised == 0 and (res.heights[moved] < h[moved]).all()
    assert moved.sum() < 3 * before.sum()
    # a blunted crest keeps a prominence just under the threshold
    i, j = np.argwhere(before)[0]
    nb = [res.heights[i, j - 1], res.heights[i, j + 1], res.heights[i - 1, j], res.heights[i + 1, j]]
    assert res.heights[i, j] <= max(nb) + mf
    # idempotent, and nothing to do where nothing is thin
    again = blunt_thin_crests(res.heights, dx, dy, mf)
    assert again.changed == 0 and np.array_equal(again.heights, res.heights)


def test_blunting_stays_inside_the_bounds_and_raises_a_neighbour_when_held_up() -> None:
    h = np.zeros((5, 7))
    h[2, 3] = 3.0
    h[2, 2] = 1.0  # a lopsided crest: 0.5 * (1 + 2/3) = 0.83 wide along x
    lo = h - 0.2  # the crest may come down only 0.2
    hi = h + 5.0
    res = blunt_thin_crests(h, 1.0, 1.0, 1.0, lo, hi)
    assert res.remaining == 0 and res.raised >= 1
    assert (res.heights >= lo - 1e-12).all() and (res.heights <= hi + 1e-12).all()
    assert res.heights[2, 3] == pytest.approx(2.8)
    assert not (crest_widths(res.heights, 1.0, 1.0, 1.0) < 1.0).any()


def test_blunting_reports_what_the_bounds_make_impossible() -> None:
    h = np.zeros((5, 5))
    h[2, 2] = 3.0
    res = blunt_thin_crests(h, 0.5, 0.5, 1.0, h - 1e-9, h + 1e-9)
    assert res.remaining == 1
    assert np.abs(res.heights - h).max() <= 1.0001e-9
    assert res.sweeps < 10  # it stops once no move is left, not after MAX_SWEEPS


def test_prominence_margin_keeps_the_export_rule_met_after_scaling_to_mm() -> None:
    h = np.zeros((5, 5))
    h[2, 2], h[2, 1] = 0.05, 0.0
    mf_units = 0.5 / 100.0  # 0.5 mm at 100 mm per unit
    res = blunt_thin_crests(h, 0.0067, 0.0067, mf_units)
    assert PROMINENCE_MARGIN < 1
    assert not (crest_widths(res.heights * 100.0, 0.67, 0.67, 0.5) < 0.5).any()


# --------------------------------------------------------------------------- the wall rule


def reference_wall_widths(h: np.ndarray, dx: float, dy: float, depth: float) -> np.ndarray:
    """The wall rule written out: walk each line from each vertex until the profile falls ``depth``.

    Like the rule, the walk goes as far as 1.25 minimum walls takes (plus one
    vertex): a side that has not fallen by then is wide enough (``inf``).
    """
    k_max = math.ceil(depth * WALL_MARGIN / min(dx, dy)) + 1
    n, m = h.shape
    out = np.full(h.shape, np.inf)
    for i in range(n):
        for j in range(m):
            c = h[i, j]
            for di, dj, length, wall in ((0, 1, dx, True), (1, 0, dy, True), (1, 1, math.hypot(dx, dy), False)):
                width = 0.0
                for side in (1, -1):
                    prev, extent, k = c, math.inf, 0
                    while k < k_max:
                        k += 1
                        ii, jj = i + side * k * di, j + side * k * dj
                        if not (0 <= ii < n and 0 <= jj < m):
                            # beyond the border: a vertical side wall on x / y lines, nothing on the diagonal
                            extent = length * (k - 1) if wall else math.inf
                            if not wall:
                                width = math.inf
                            break
                        v = h[ii, jj]
                        if v > c:
                            width = math.inf  # rises above the top: no crest on this line
                            break
                        if v <= c - depth:
                            extent = length * (k - 1 + (prev - (c - depth)) / (prev - v))
                            break
                        prev = v
                    width += extent
                out[i, j] = min(out[i, j], width)
    return out


def test_wall_widths_match_the_reference_walk() -> None:
    rng = np.random.default_rng(5)
    h = np.cumsum(rng.normal(0, 0.6, size=(12, 13)), axis=0) + rng.gamma(0.4, 2.0, size=(12, 13))
    for depth in (0.5, 1.0, 2.0):
        np.testing.assert_allclose(wall_widths(h, 0.67, 0.5, depth), reference_wall_widths(h, 0.67, 0.5, depth),
                                   rtol=1e-12)


def _rough(seed: int, n: int = 23, m: int = 29) -> np.ndarray:
    """A rough field with needles: many thin crests and walls for both rules."""
    rng = np.random.default_rng(seed)
    h = np.cumsum(rng.normal(0, 0.6, size=(n, m)), axis=0) + rng.gamma(0.4, 2.0, size=(n, m))
    h[rng.random(h.shape) < 0.05] += 4.0
    return h


@pytest.mark.parametrize("seed", range(4))
def test_the_wall_kernels_equal_their_numpy_reference_bit_for_bit(seed: int) -> None:
    # the optimizer projects every trial step: a last-bit difference would send it down another path
    h = _rough(seed)
    for depth in (0.5, 1.0, 2.0):
        for rise in (0.0, 1e-3):
            assert np.array_equal(wall_widths(h, 0.67, 0.5, depth, rise),
                                  relief.wall_widths_reference(h, 0.67, 0.5, depth, rise))
    lo = h - np.random.default_rng(seed).uniform(0.0, 3.0, size=h.shape)
    lo[0, :] = -np.inf  # unbounded vertices too
    ii, jj = np.nonzero(wall_widths(h, 0.67, 0.5, 1.0) < 1.25)
    assert len(ii) > 5
    k = relief._wall_steps(1.275, 0.67, 0.5)
    fast = relief._bisect_tops(h, ii, jj, lo[ii, jj], 1.0, 1.275, k, 0.67, 0.5)
    ref = relief.bisect_tops_reference(h, ii, jj, lo[ii, jj], 1.0, 1.275, k, 0.67, 0.5)
    assert np.array_equal(fast[0], ref[0]) and np.array_equal(fast[1], ref[1])
    assert fast[1].any() and not fast[1].all()  # both outcomes exercised


@pytest.mark.parametrize("seed", range(4))
def test_the_feature_kernel_equals_its_numpy_reference_bit_for_bit(seed: int) -> None:
    h = _rough(seed)
    h[3:8, 4:9] = 1.25  # a plateau: equal neighbours divide by zero (inf and NaN widths)
    h[10, 10] = h[10, 9] = h[10, 11] = 7.0
    for dx, dy, crest_p, feature_w in ((0.67, 0.5, 0.3, 0.4), (0.5, 0.5, 1.0, 2.0), (1.0, 0.25, 0.0, 0.3)):
        fast = relief._feature_crests(h, dx, dy, crest_p, feature_w, 0.01)
        ref = relief.feature_crests_reference(h, dx, dy, crest_p, feature_w, 0.01)
        assert all(np.array_equal(f, r) for f, r in zip(fast, ref, strict=True))
        assert fast[1].dtype == ref[1].dtype == bool and fast[1].shape == (3, h.shape[0] - 2, h.shape[1] - 2)
    assert fast[1].any() and np.isfinite(fast[0]).any() and not np.isfinite(fast[0]).all()
    for shape in ((0, 0), (1, 5), (2, 2), (3, 2), (2, 7)):  # no interior vertex: empty findings, as numpy's
        fast = relief._feature_crests(np.zeros(shape), 0.5, 0.5, 0.3, 0.4, 0.01)
        ref = relief.feature_crests_reference(np.zeros(shape), 0.5, 0.5, 0.3, 0.4, 0.01)
        assert [a.shape for a in fast] == [a.shape for a in ref]


def test_blunting_by_the_kernels_equals_blunting_by_the_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    h = _rough(7, 40, 40)
    lo, hi = h - 1.5, h + 1.5
    fast = blunt_thin_crests(h, 0.67, 0.67, 0.3, lo, hi, min_wall=1.0, tighten=1e-3)
    monkeypatch.setattr(relief, "wall_widths", relief.wall_widths_reference)
    monkeypatch.setattr(relief, "_bisect_tops", relief.bisect_tops_reference)
    monkeypatch.setattr(relief, "_feature_crests", relief.feature_crests_reference)
    ref = blunt_thin_crests(h, 0.67, 0.67, 0.3, lo, hi, min_wall=1.0, tighten=1e-3)
    assert fast.sweeps > 1 and fast.lowered > 10
    assert np.array_equal(fast.heights, ref.heights)
    assert (fast.lowered, fast.raised, fast.sweeps, fast.remaining) == (ref.lowered, ref.raised, ref.sweeps,
                                                                         ref.remaining)


def test_a_tall_needle_is_a_wall_a_short_one_is_not() -> None:
    h = np.zeros((9, 9))
    h[4, 4] = 5.0  # 5 mm tall, one 0.67 mm step each side: 0.27 mm wide at 1 mm below its tip
    w = wall_widths(h, 0.67, 0.67, 1.0)
    assert w[4, 4] == pytest.approx(2 * 0.67 * 1.0 / 5.0)
    h[4, 4] = 0.9  # never falls 1 mm: no wall
    assert np.isinf(wall_widths(h, 0.67, 0.67, 1.0)).all()


def test_a_lip_at_the_border_is_a_wall_a_slope_along_it_is_not() -> None:
    h = np.zeros((6, 6))
    h[0, :] = 3.0  # the front row stands 3 mm above the inside: a lip against the side wall
    w = wall_widths(h, 1.0, 1.0, 1.0)
    assert w[0, 2] == pytest.approx(1.0 / 3.0)  # from the wall to where the slope is 1 mm down
    # the same heights rising across the border along x: the diagonal leaves through a wall, no lip
    g = np.tile(np.linspace(0.0, 5.0, 6), (6, 1))
    assert np.isinf(wall_widths(g, 1.0, 1.0, 1.0)[:, :-1]).all()


def test_blunting_with_the_wall_rule_leaves_no_needle_and_no_lip() -> None:
    rng = np.random.default_rng(1)
    h = rng.normal(0.0, 0.2, size=(40, 40))
    h[rng.random(h.shape) < 0.03] += 4.0  # needles
    h[0, 10:20] += 3.0  # a lip
    res = blunt_thin_crests(h, 0.67, 0.67, 0.3, min_wall=1.0)
    assert res.remaining == 0 and res.lowered > 0
    assert not (wall_widths(res.heights, 0.67, 0.67, 1.0) < WALL_MARGIN * 1.0).any()
    assert not (crest_widths(res.heights, 0.67, 0.67, 0.3) < 0.3).any()
    assert (res.heights <= h).all()  # only lowered (no bounds in the way)
    # the needles keep about the height their width allows, not flattened
    tallest = float((res.heights - np.median(h)).max())
    assert 1.0 < tallest < 3.0


# --------------------------------------------------------------------------- the design's printer


def small_scene(n: int = 40, cup_mm: float = 80.0) -> Scene:
    s = Scene()
    return s.with_changes(saucer=replace(s.saucer, resolution=n), cup_diameter_mm=cup_mm)


def test_print_target_in_model_units() -> None:
    t = print_target(small_scene(150), "bureau")
    assert t.mm_per_unit == pytest.approx(100.0)
    assert t.min_feature_units == pytest.approx(0.005)
    assert t.spacing_mm[0] == pytest.approx(100.0 / 149)
    assert t.delta_mm == pytest.approx(5.0)
    assert t.crests_can_be_thin  # 0.67 mm grid, 0.5 mm feature
    assert not print_target(small_scene(150), "j55").crests_can_be_thin  # 0.3 mm: half a spacing is wider
    d = t.to_dict()
    assert d["printer"] == "bureau" and d["min_feature_mm"] == 0.5
    with pytest.raises(ConfigError, match="unknown printer"):
        print_target(small_scene(), "no_such_printer")


def test_preflight_refuses_a_part_larger_than_the_build_volume_and_names_the_cup_that_fits() -> None:
    scene = small_scene(cup_mm=300.0)
    base = np.zeros((40, 40))
    with pytest.raises(ConfigError, match=r"build volume .*--cup-diameter-mm (\d+)") as exc:
        preflight(print_target(scene, "j55"), scene, base)
    fit = float(str(exc.value).split("--cup-diameter-mm ")[1].split()[0])
    smaller = small_scene(cup_mm=fit)
    assert print_target(smaller, "j55").profile.fits(worst_case_bbox_mm(smaller, base, FabOptions()))
    assert preflight(print_target(smaller, "j55"), smaller, base) == []


def test_preflight_refuses_walls_under_the_printers_minimum() -> None:
    scene = small_scene()
    with pytest.raises(ConfigError, match="seat_rim_mm = 1 mm is below the minimum wall 2 mm"):
        preflight(print_target(scene, "bureau"), scene, np.zeros((40, 40)), FabOptions(seat_rim_mm=1.0))


def test_preflight_blunts_a_spiky_base_shape_or_refuses_one_it_cannot() -> None:
    scene = small_scene(150)
    base = np.zeros((150, 150))
    base[10, 10], base[10, 9] = 0.04, 0.03  # a lopsided 4 mm needle on a 0.67 mm grid (0.42 mm wide)
    notes = preflight(print_target(scene, "bureau"), scene, base)
    assert len(notes) == 1 and "blunted" in notes[0]
    tight = scene.with_changes(saucer=replace(scene.saucer, delta=1e-6))
    with pytest.raises(ConfigError, match="crests narrower than .* minimum feature"):
        preflight(print_target(tight, "bureau"), tight, base)


def test_crest_projection_keeps_strict_feasibility_and_counts() -> None:
    scene = small_scene(150)
    base = np.zeros((150, 150))
    proj = CrestProjection(print_target(scene, "bureau"), scene, base)
    h = torch.zeros(150 * 150, dtype=torch.float32)
    assert proj(h) is h  # nothing to do: the same tensor back
    h2 = h.clone()
    h2[75 * 150 + 75] = 0.0499  # a lopsided needle at the top of the bound
    h2[75 * 150 + 74] = 0.04
    out = proj(h2)
    assert out.dtype == torch.float32 and float(out[75 * 150 + 75]) < 0.0499
    d = scene.saucer.delta
    assert float((out - torch.as_tensor(base.reshape(-1), dtype=torch.float32)).abs().max()) < d
    w = crest_widths(out.numpy().reshape(150, 150).astype(np.float64) * 100.0, *print_target(scene, "bureau").spacing_mm, 0.5)
    assert not (w < 0.5).any()
    assert proj.stats()["projection_calls"] == 2 and proj.stats()["projection_active"] == 1


def test_saucer_fixture_matches_the_paper() -> None:
    # the numbers these tests rely on: a 1 x 1 unit saucer, delta 0.05, an 0.8 unit cup
    s = Scene()
    assert isinstance(s.saucer, Saucer)
    assert s.saucer.size == (1.0, 1.0) and s.saucer.delta == 0.05 and s.mm_per_unit == pytest.approx(100.0)


#: a 13 x 13 patch of the default design of samples/photos chelsea.png / coffee.png (150 x 150,
#: made for the J55 at 80 mm: model units, float32 as heights.npy holds them), rows 107-119 and
#: columns 33-45: it holds a crest whose wall rule jumps (a dip of exactly one wall, then a rise)
JUMP_PATCH = [
    [0.0690689087, 0.0693144649, 0.0702251866, 0.0711560845, 0.0698682442, 0.0746380389, 0.0750074387, 0.0782382712, 0.0688619092, 0.069562681, 0.0732739344, 0.0731476471, 0.0727354363],
    [0.0867369398, 0.0856536105, 0.0859160349, 0.0876630917, 0.0901661217, 0.0947417393, 0.0960381627, 0.0947297215, 0.0959945694, 0.096182704, 0.096309416, 0.0956404433, 0.0921244398],
    [0.107275382, 0.103784807, 0.10413038, 0.1042566, 0.10627763, 0.110422753, 0.112928949, 0.120175652, 0.12019036, 0.112658173, 0.116227508, 0.116570279, 0.108673334],
    [0.127115414, 0.123816185, 0.116036177, 0.118096448, 0.116799042, 0.121505834, 0.129298881, 0.140265092, 0.140936047, 0.138927609, 0.131822705, 0.13206245, 0.127856582],
    [0.135973901, 0.134617835, 0.127684295, 0.130364209, 0.129416317, 0.128095284, 0.136935353, 0.148979858, 0.149019927, 0.149036363, 0.146829739, 0.124329261, 0.118091315],
    [0.124010555, 0.124014527, 0.138761714, 0.141451716, 0.13918893, 0.137580931, 0.129177868, 0.136781722, 0.140666589, 0.140597969, 0.139612019, 0.135663092, 0.130190462],
    [0.118844703, 0.117733993, 0.128610969, 0.131145224, 0.132128164, 0.130477786, 0.139177874, 0.13127245, 0.126954168, 0.126347274, 0.126656726, 0.125565842, 0.120970197],
    [0.0927152112, 0.104196981, 0.10419111, 0.106372066, 0.117231049, 0.122502923, 0.113423362, 0.11974211, 0.116566181, 0.118784018, 0.115974687, 0.113561831, 0.105584301],
    [0.0841526464, 0.0841764584, 0.0840935707, 0.0898137242, 0.0985842124, 0.0988384783, 0.0992373973, 0.100612238, 0.100910641, 0.103554636, 0.0958640724, 0.0930361748, 0.0915765688],
    [0.0737144649, 0.0737086535, 0.0733456984, 0.0733092427, 0.0738700554, 0.0773992762, 0.079971239, 0.0816099122, 0.0819590464, 0.0806667581, 0.0781805813, 0.0740774274, 0.0737961382],
    [0.0616356023, 0.0603348352, 0.0579145029, 0.0559749082, 0.0554383919, 0.056636434, 0.0593226999, 0.0620107204, 0.0623569824, 0.0620295517, 0.0621309057, 0.0619369969, 0.0619856939],
    [0.0495098606, 0.0478753932, 0.0441047773, 0.040176075, 0.037507154, 0.0370136611, 0.038891416, 0.041924715, 0.0450252928, 0.0495394543, 0.0494558923, 0.0494183972, 0.0494007654],
    [0.0370583832, 0.0367561392, 0.0323136747, 0.0267271567, 0.0225921627, 0.0197620261, 0.0187009983, 0.0222270116, 0.0252201241, 0.0332525223, 0.0369093157, 0.0339194201, 0.0348342955],
]


def test_a_crest_lowered_to_where_the_rule_jumps_stays_printable_in_float32() -> None:
    # the projection's answer for such a crest lies on the jump; the optimizer keeps float32
    # heights, and rounding must not carry the crest back across it (relief.SETTLE)
    h = np.array(JUMP_PATCH, np.float64)
    dx = dy = 1.0 / 149  # model units; 0.67 mm at 100 mm per unit
    res = blunt_thin_crests(h, dx, dy, 0.003, min_wall=0.01, tighten=1e-3)  # the J55 in model units
    assert res.changed
    as_f32 = res.heights.astype(np.float32).astype(np.float64)
    # as the export sees it: mm, float64, the rules untightened
    assert not (wall_widths(as_f32 * 100.0, dx * 100.0, dy * 100.0, 1.0) < WALL_MARGIN * 1.0).any()
    assert blunt_thin_crests(as_f32, dx, dy, 0.003, min_wall=0.01, tighten=1e-3).changed == 0


def test_preflight_has_no_sliver_to_warn_of_the_export_stops_the_seat_plate_at_the_saucer() -> None:
    # the paper scene: cup radius 0.4 units, saucer sides at +-0.5; clearance + rim 4.5 mm. At 30 mm
    # (37.5 mm per unit) the grown cup reaches 0.75 mm past the sides; the export's plate ends at the
    # saucer's near edge instead of running down them as a sliver (fabricate.seat.clip_to_cup_side),
    # so the design has nothing to warn of (issue 42, item 5: the design's warning and the export agree)
    base = np.zeros((40, 40))
    small = small_scene(cup_mm=30.0)
    assert preflight(print_target(small, "hp_jf580"), small, base) == []
