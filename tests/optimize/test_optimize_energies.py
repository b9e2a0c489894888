"""Energies, prox and the DR solver against hand computations (paper eq. 2-15)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from saucerfab.model.heightfield import laplacian
from saucerfab.optimize.energies import DeformEnergy, e_barrier, e_sparse, e_visual, feasible, prox_l1
from saucerfab.optimize.solver import ProxSettings, SolverSettings, solve


def test_e_visual_is_sum_of_squares_over_views() -> None:
    a = torch.zeros(2, 2, 3)
    b = torch.zeros(2, 2, 3)
    b[0, 0, 0] = 0.5  # 0.25
    c = torch.ones(2, 2, 3)
    d = torch.ones(2, 2, 3)
    d[1, 1] = 0.0  # 3 channels * 1 = 3
    assert float(e_visual([a, c], [b, d])) == pytest.approx(3.25)


@pytest.mark.parametrize("weight", [1.0, 0.37])
def test_e_visual_value_and_gradient_are_the_plain_expression_bit_for_bit(weight: float) -> None:
    # e_visual's one-multiply backward against autograd through the expression it replaces
    g = torch.Generator().manual_seed(1)
    rendered = [torch.rand(16, 16, 3, generator=g) for _ in range(2)]
    targets = [torch.rand(16, 16, 3, generator=g) for _ in range(2)]
    grads = []
    for fused in (True, False):
        rs = [r.clone().requires_grad_(True) for r in rendered]
        if fused:
            e = e_visual(rs, targets)
        else:
            e = rs[0].new_zeros((), dtype=torch.float64)
            for r, t in zip(rs, targets):
                e = e + ((r - t) ** 2).sum(dtype=torch.float64)
        (weight * e).backward()
        grads.append((float(e.detach()), [r.grad for r in rs]))
    (v1, g1), (v2, g2) = grads
    assert v1 == v2 and all(torch.equal(a, b) for a, b in zip(g1, g2))
    # float64 gradcheck, both inputs (a target that requires grad gets the opposite gradient)
    r = torch.rand(3, 2, 3, dtype=torch.float64, generator=g, requires_grad=True)
    t = torch.rand(3, 2, 3, dtype=torch.float64, generator=g, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: e_visual([a], [b]), (r, t))


def test_e_deform_hand_computed_on_3x3() -> None:
    # n = 3: the centre vertex (index 4) has 6 mesh neighbours: 1, 3, 5, 7 and
    # the diagonal 0 and 8 (cells split from (i, j) to (i+1, j+1)).
    lap = laplacian(3)
    z = torch.zeros(9, dtype=torch.float64)
    h = torch.zeros(9, dtype=torch.float64)
    h[4] = 0.6
    E = DeformEnergy(lap, z)
    lh = E.apply(h).numpy()
    # (L h)_4 = 0.6 - 0 = 0.6; each neighbour j of 4 gets -0.6 / deg(j)
    assert lh[4] == pytest.approx(0.6)
    degs = np.asarray((lap != 0).sum(axis=1)).ravel() - 1
    expect = 0.6**2 + sum((0.6 / degs[j]) ** 2 for j in (0, 1, 3, 5, 7, 8))
    assert float(E(h)) == pytest.approx(expect)
    # heights shifted by a constant cost nothing
    assert float(E(z + 0.3)) == pytest.approx(0.0, abs=1e-24)


def test_barrier_matches_eq5_and_is_infinite_outside() -> None:
    z = torch.tensor([0.0, 0.1], dtype=torch.float64)
    h = torch.tensor([0.01, 0.1], dtype=torch.float64)
    c = torch.tensor([[0.5, 0.25, 0.75]], dtype=torch.float64)
    d = 0.05
    expect = 0.0
    for zi, hi in zip(z.tolist(), h.tolist()):
        expect += -math.log(d - (zi - hi)) - math.log(d + (zi - hi))
    for ci in c.reshape(-1).tolist():
        expect += -math.log(ci) - math.log(1 - ci)
    assert float(e_barrier(h, z, c, d)) == pytest.approx(expect)
    assert math.isinf(float(e_barrier(h + 0.06, z, c, d)))
    assert math.isinf(float(e_barrier(h, z, c * 0 + 1.0, d)))
    assert feasible(h, z, c, d) and not feasible(h + 0.06, z, c, d)


def test_e_sparse_and_prox_closed_form() -> None:
    he = torch.tensor([0.0, 1.0, 2.0, -1.0])
    x = torch.tensor([0.5, 1.05, 1.7, -1.0])
    assert float(e_sparse(x, he)) == pytest.approx(0.5 + 0.05 + 0.3)
    # lam * alpha = 0.1: shrink by 0.1 towards h^e, zero inside the band
    p = prox_l1(x, he, 0.1)
    assert torch.allclose(p, torch.tensor([0.4, 1.0, 1.8, -1.0]))
    # prox is the minimiser of eq. 14: check against a brute-force grid
    lam, alpha = 0.5, 0.2
    for xi, ci in [(0.3, 0.0), (-0.05, 0.0), (0.7, 0.5)]:
        grid = np.linspace(-1, 2, 300001)
        f = lam * np.abs(grid - ci) + (grid - xi) ** 2 / (2 * alpha)
        best = grid[np.argmin(f)]
        got = float(prox_l1(torch.tensor([xi]), torch.tensor([ci]), lam * alpha))
        assert got == pytest.approx(best, abs=1e-4)


def _quadratic_problem(n: int = 16, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    target_h = torch.rand(n, generator=g, dtype=torch.float64) * 0.2 - 0.1  # some beyond delta
    target_c = torch.rand(n, 3, generator=g, dtype=torch.float64)

    def objective(h: torch.Tensor, c: torch.Tensor):
        # the pipeline's shape: a data term plus the barrier of eq. 5
        e = 50 * ((h - target_h) ** 2).sum() + ((c - target_c) ** 2).sum()
        e = e + 1e-4 * e_barrier(h, torch.zeros_like(h), c, 0.05)
        return e, {"E_visual": float(e.detach())}

    return objective, target_h, target_c


@pytest.mark.parametrize("rule", ["global", "coordinate"])
def test_solver_keeps_every_iterate_strictly_feasible(rule: str) -> None:
    objective, target_h, _ = _quadratic_problem()
    z = torch.zeros_like(target_h)
    c0 = torch.full((target_h.shape[0], 3), 0.5, dtype=torch.float64)
    seen = []

    def cb(it, total, parts):  # noqa: ANN001
        seen.append(total)

    delta = 0.05
    settings = SolverSettings(max_iters=300, lr_h=0.01, lr_c=0.05, boundary_rule=rule)
    res = solve(objective, z.clone(), c0, z, delta, settings, callback=cb)
    assert feasible(res.h, z, res.c, delta)
    assert (res.h - z).abs().max() < delta
    # the energy never goes up (Armijo) and the unconstrained targets are approached
    assert all(b <= a + 1e-12 for a, b in zip(seen, seen[1:]))
    best = float(50 * ((target_h.clamp(-delta, delta) - target_h) ** 2).sum())
    assert seen[-1] - best < 0.1 * (seen[0] - best)
    inside = target_h.abs() < delta * 0.8
    assert torch.allclose(res.h[inside], target_h[inside], atol=1e-2)
    # targets beyond the bound push the heights against it, never past
    outside = target_h.abs() > delta
    assert ((res.h[outside] - z[outside]).abs() > 0.8 * delta).all()


def test_coordinate_rule_is_not_held_back_by_a_vertex_at_its_bound() -> None:
    # Vertex 0 rests 1e-8 from its bound and is pulled further out; the others
    # start at 0 with targets well inside. The global rule caps every step at
    # that 1e-8 (the sparse stage's stall); the coordinate rule caps only vertex 0.
    n, delta = 8, 0.05
    target = torch.full((n,), 0.03, dtype=torch.float64)
    target[0] = 1.0

    def objective(h: torch.Tensor, c: torch.Tensor):
        return ((h - target) ** 2).sum() + ((c - 0.5) ** 2).sum(), {}

    z = torch.zeros(n, dtype=torch.float64)
    h0 = z.clone()
    h0[0] = delta - 1e-8
    c0 = torch.full((n, 3), 0.5, dtype=torch.float64)
    moved = {}
    for rule in ("global", "coordinate"):
        res = solve(objective, h0, c0, z, delta, SolverSettings(max_iters=60, lr_h=0.005, boundary_rule=rule))
        assert feasible(res.h, z, res.c, delta)
        moved[rule] = float(res.h[1:].mean())
    assert 0.02 < moved["coordinate"] < 0.0301
    assert moved["global"] < 1e-5


def test_solver_stops_on_a_nonfinite_gradient() -> None:
    def objective(h: torch.Tensor, c: torch.Tensor):
        # the value is finite, the gradient of h is NaN (sqrt at 0)
        return (h.abs() * 0).sqrt().sum() + ((c - 0.5) ** 2).sum(), {}

    z = torch.zeros(4, dtype=torch.float64)
    c0 = torch.full((4, 3), 0.4, dtype=torch.float64)
    res = solve(objective, z.clone(), c0, z, 0.05, SolverSettings(max_iters=20))
    assert res.stop_reason == "nonfinite_gradient" and res.iterations == 1
    assert torch.equal(res.h, z)


def test_all_finite_checks_each_element_only_when_the_sum_is_not_finite() -> None:
    from saucerfab.optimize.solver import _all_finite

    big = torch.finfo(torch.float32).max
    assert _all_finite(torch.tensor([1.0, -2.0, 3.0]))
    assert _all_finite(torch.tensor([big, big, big]))  # the sum overflows, every element is finite
    assert _all_finite(torch.tensor([big, -big]))
    for bad in (float("nan"), float("inf"), -float("inf")):
        assert not _all_finite(torch.tensor([1.0, bad, 3.0]))
        assert not _all_finite(torch.tensor([big, big, bad]))
    assert not _all_finite(torch.tensor([float("inf"), -float("inf")]))  # inf - inf: NaN sum


def test_solver_ends_at_once_when_a_fresh_direction_is_rejected() -> None:
    # Every move raises the energy (|c - c0| outweighs the linear pull), so the
    # first line search fails. Its direction came from fresh moments, which a
    # retry would make again from the same iterate: the stage ends after one
    # line search, not max_rejections of them, and the iterate is the start.
    z = torch.zeros(4, dtype=torch.float64)
    c0 = torch.full((4, 3), 0.4, dtype=torch.float64)

    def objective(h: torch.Tensor, c: torch.Tensor):
        return (c - c0).abs().sum() + 0.1 * c.sum() + (h**2).sum(), {}

    settings = SolverSettings(max_iters=20, max_rejections=4, max_backtracks=3)
    res = solve(objective, z.clone(), c0, z, 0.05, settings)
    assert res.stop_reason == "no_descent" and res.iterations == 1
    assert res.evaluations == 1 + (settings.max_backtracks + 1)
    assert torch.equal(res.h, z) and torch.equal(res.c, c0)


def test_solver_rejects_infeasible_start() -> None:
    objective, target_h, _ = _quadratic_problem()
    z = torch.zeros_like(target_h)
    c0 = torch.full((target_h.shape[0], 3), 0.5, dtype=torch.float64)
    with pytest.raises(ValueError):
        solve(objective, z + 1.0, c0, z, 0.05, SolverSettings(max_iters=5))


def test_proximal_stage_moves_few_vertices() -> None:
    # Only two vertices feel a strong pull; the L1 term keeps the rest at h^e.
    n = 12
    pull = torch.zeros(n, dtype=torch.float64)
    pull[3], pull[7] = 1.0, -1.0

    def objective(h: torch.Tensor, c: torch.Tensor):
        e = -(pull * h).sum() * 20 + 0.01 * (h**2).sum() + ((c - 0.5) ** 2).sum()
        return e, {"E_visual": float(e.detach())}

    z = torch.zeros(n, dtype=torch.float64)
    c0 = torch.full((n, 3), 0.5, dtype=torch.float64)
    res = solve(
        objective, z.clone(), c0, z, 0.05, SolverSettings(max_iters=200, lr_h=0.01),
        prox=ProxSettings(center=z.clone(), lam=1.0, alpha=1.0),
    )
    moved = (res.h - z).abs() > 1e-9
    assert moved[3] and moved[7]
    assert int(moved.sum()) == 2
    assert res.h[3] > 0.02 and res.h[7] < -0.02


def test_stall_rule_judges_the_fall_per_render_over_its_window() -> None:
    from saucerfab.optimize.solver import _stalled

    # (renders so far, objective); floor 0, tol 1e-2: a 1 % fall per render is the line
    steady = [(k, 100.0 * 0.97**k) for k in range(20)]  # 3 % a render
    assert not _stalled(steady, 8, 1e-2, 0.0)
    flat = [(0, 100.0), (6, 99.9), (12, 99.8), (18, 99.7)]  # 0.3 % over 18 renders
    assert _stalled(flat, 16, 1e-2, 0.0)
    assert not _stalled(flat[:3], 16, 1e-2, 0.0)  # no mark 16 renders old yet: wait
    # the window reaches back to the latest mark at least `window` renders old (whole steps):
    # from (2, 100) to (20, 80) the fall is 20 % over 18 renders, above 1 % a render
    # (from (0, 200), 20 renders back, it would be 60 %: not the window)
    assert not _stalled([(0, 200.0), (2, 100.0), (17, 99.0), (20, 80.0)], 16, 1e-2, 0.0)
    assert _stalled([(0, 200.0), (2, 100.0), (17, 99.0), (20, 90.0)], 16, 1e-2, 0.0)  # 10 % over 18
    # the floor: a fall of 1 above a floor of 99 is 100 %
    assert not _stalled([(0, 100.0), (16, 99.0)], 16, 1e-2, 99.0)
    assert _stalled([(0, 100.0), (16, 99.0)], 16, 1e-2, 0.0)


def test_the_stall_rule_only_cuts_a_stage_short() -> None:
    """With the rule the stage is the same run stopped early: the same iterates up to its stop."""
    objective, target_h, _ = _quadratic_problem()
    z = torch.zeros_like(target_h)
    c0 = torch.full((target_h.shape[0], 3), 0.5, dtype=torch.float64)
    runs = {}
    for window in (0, 8):
        seen: list[float] = []
        settings = SolverSettings(max_iters=150, lr_h=0.01, lr_c=0.05, tol=1e-3, patience=10**6,
                                  stall_window=window)
        res = solve(objective, z.clone(), c0, z, 0.05, settings, callback=lambda it, e, p: seen.append(e))
        runs[window] = (res, seen)
    full, cut = runs[0], runs[8]
    assert full[0].stop_reason == "max_iters" and full[0].iterations == 150
    assert cut[0].stop_reason == "stalled" and 8 < cut[0].iterations < 150
    assert cut[0].evaluations < full[0].evaluations
    assert cut[1] == full[1][: len(cut[1])]


def test_stall_window_must_not_be_negative() -> None:
    with pytest.raises(ValueError, match="stall_window"):
        SolverSettings(stall_window=-1)
