"""The DR solver (paper, section 3.3) and its proximal variant (section 3.4.1).

Each iteration:

1. the gradient of the smooth objective at the current iterate (it was
   computed with the accepted trial of the previous iteration, so an
   accepted step costs one forward and one backward render);
2. an Adamax direction per variable group: ``m <- b1 m + (1 - b1) g``,
   ``u <- max(b2 u, |g| + eps)``, step ``lr / (1 - b1^t) * m / u``
   (torch.optim.Adamax's update, kept by hand so the line search can scale it);
3. for the sparse stage, the heights' step becomes a proximal gradient step
   (eq. 13-15) in Adamax's diagonal metric: with per-vertex step
   ``s_i = alpha * lr_h / u_i`` the trial point is ``x = h - s * m_hat`` and
   ``d^h = h - prox(x)``, where prox soft-thresholds ``x - h^e`` by
   ``lam * s_i``. So a vertex leaves ``h^e`` only where its smoothed visual
   gradient exceeds ``lam``: lam is compared with the gradient of E_visual,
   which scales with the compatibility score rho exactly as lam = 6e-5 rho does;
4. fraction to the boundary, so that every step the line search tries is
   strictly feasible (``|z - h| < delta``, ``0 < c < 1``: every barrier
   finite). ``boundary_rule="global"``: the line search starts at 99 % of the
   largest feasible multiple of the whole step. ``"coordinate"``: each
   coordinate of the step is cut to 99 % of its distance to the bound it
   moves towards, and the line search starts at 1. The sparse stage needs
   the latter: it starts from h^e, where vertices rest within 3e-8 of their
   bound, and the global rule caps every vertex's step at that distance
   (measured: accepted betas of 1e-5, no vertex moving 1e-4). The Laplacian
   stages keep the global rule, which stalls them at betas of 1e-3 to 1e-1
   once colours and heights near their bounds: with the coordinate rule
   they converge three times sooner and lower their own objective further
   (first stage: 114 iterations to E 12311 against 400 to 14681), yet the
   full method's final E_visual against the real images was 1.4-4.4 %
   worse on the three bundled pairs (benchmarks/results/HISTORY.md, "Design (issue 4)");
5. a backtracking line search on ``beta`` in {1, 1/2, 1/4, ...}: a trial is
   accepted when it is strictly feasible (checked again, against rounding)
   and the full objective decreases by Armijo's rule. If no trial is
   accepted the Adamax moments are reset, so the next direction is the
   plain (descent) gradient direction. If that one is rejected too, the
   stage ends ("no_descent"): it depends on the iterate alone, so a retry
   would render the same trials again (the designs are the same bits as
   with ``max_rejections`` retries; fish-moon: 28 renders fewer).

Stopping: the relative change of the objective is below ``tol`` (1e-4, the
paper's) for ``patience`` accepted iterations in a row, or ``max_iters``.
A patience above one keeps a single lucky flat step of the stochastic-looking
Adamax trajectory from ending a stage early; ``patience=1`` is the paper verbatim.
With ``stall_window`` = W > 0 a stage also ends when, over at least its last W
renders (accepted trials and rejected ones alike), the objective fell by
less than ``tol`` relative per render ("stalled"): a stage's tail where each
accepted step takes five or six halvings moves the picture by a fraction of a
percent for a third of the stage's renders (measured on rocket-chelsea's
sparse stage: its last 68 of 122 renders for 0.4 % of E_visual), a tail the
per-iteration rule misses because the rare accepted steps are not small.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from saucerfab.optimize.energies import e_sparse, feasible, prox_l1
from saucerfab.optimize.stages import MAX_ITERS

#: share of its distance to a bound that one step may take a coordinate (interior-point practice)
FRACTION_TO_BOUNDARY = 0.99

#: objective(h, c) -> (value with autograd graph, {name: float} parts)
Objective = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, dict[str, float]]]


@dataclass(frozen=True)
class SolverSettings:
    """Settings of one DR-solver stage.

    Attributes:
        lr_h: Adamax step for heights, model units per iteration.
        lr_c: Adamax step for colours, per iteration (colours in [0, 1]).
        beta1, beta2, eps: Adamax's constants (torch defaults).
        tol: relative energy change that ends the stage (paper: 1e-4).
        patience: consecutive iterations below ``tol`` needed to stop.
        max_iters: iteration cap.
        max_backtracks: halvings of the step before giving up on a direction.
        max_rejections: consecutive iterations without an accepted step
            (each with its moments reset) after which the stage ends: no
            descent is left at this step size. A rejected direction made from
            fresh moments ends the stage at once (a retry would repeat it).
        armijo: sufficient-decrease constant.
        optimize_heights: False keeps h fixed (texture-only ablations).
        boundary_rule: "global" or "coordinate": how a step is kept strictly
            inside the box constraints (module docstring, item 4).
        energy_floor: subtracted from the energy before taking the relative
            change (the barrier's minimum, a large constant: with 22,500
            vertices and 44,402 faces it is about 3e5, dwarfing E_visual, so
            a relative change of the raw energy would end a stage at once).
        stall_window: renders over which the objective must fall by ``tol``
            relative per render on average, else the stage ends (module
            docstring, Stopping); 0 turns the rule off (the paper's rules only).
    """

    lr_h: float = 2.5e-3
    lr_c: float = 2e-2
    beta1: float = 0.9
    beta2: float = 0.999
    eps: float = 1e-8
    tol: float = 1e-4
    patience: int = 3
    max_iters: int = MAX_ITERS
    max_backtracks: int = 6
    max_rejections: int = 4
    armijo: float = 1e-4
    optimize_heights: bool = True
    energy_floor: float = 0.0
    boundary_rule: str = "global"
    stall_window: int = 0

    def __post_init__(self) -> None:
        if self.boundary_rule not in ("global", "coordinate"):
            raise ValueError(f"boundary_rule must be 'global' or 'coordinate', got {self.boundary_rule!r}")
        if self.stall_window < 0:
            raise ValueError(f"stall_window must be 0 (off) or a number of renders, got {self.stall_window}")


@dataclass(frozen=True)
class ProxSettings:
    """The proximal step of a proximal term (eq. 13-15): by default the sparse-spike stage's E_sparse.

    Attributes:
        center: (V,) h^e, the heights after the enhanced stage.
        lam: lambda, weight of the term.
        alpha: the proximal step (paper: 0.2), in units of the Adamax step.
        name: the term's key in the logged parts.
        value: the term, ``value(h, center)`` -> 0-d tensor (E_sparse, eq. 9).
        operator: its proximal operator ``operator(x, center, threshold)`` (soft thresholding, eq. 15).
    """

    center: torch.Tensor
    lam: float
    alpha: float = 0.2
    name: str = "E_sparse"
    value: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] = e_sparse
    operator: Callable[..., torch.Tensor] = prox_l1


@dataclass
class SolveResult:
    """Outcome of one stage."""

    h: torch.Tensor
    c: torch.Tensor
    iterations: int
    energy: float
    converged: bool
    log: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    evaluations: int = 0
    stop_reason: str = ""


class _Adamax:
    def __init__(self, shapes: list[torch.Size], like: torch.Tensor, s: SolverSettings) -> None:
        self.s = s
        self.m = [torch.zeros(sh, dtype=like.dtype) for sh in shapes]
        self.u = [torch.zeros(sh, dtype=like.dtype) for sh in shapes]
        self.t = 0

    def reset(self) -> None:
        for m, u in zip(self.m, self.u):
            m.zero_()
            u.zero_()
        self.t = 0

    def update(self, grads: list[torch.Tensor]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Fold in ``grads``; return (bias-corrected m_hat, u) per group."""
        self.t += 1
        b1, b2 = self.s.beta1, self.s.beta2
        out_m, out_u = [], []
        for m, u, g in zip(self.m, self.u, grads):
            m.mul_(b1).add_(g, alpha=1 - b1)
            torch.maximum(u * b2, g.abs() + self.s.eps, out=u)
            out_m.append(m / (1 - b1**self.t))
            out_u.append(u)
        return out_m, out_u


def solve(
    objective: Objective,
    h0: torch.Tensor,
    c0: torch.Tensor,
    z: torch.Tensor,
    delta: float,
    settings: SolverSettings,
    *,
    prox: ProxSettings | None = None,
    callback: Callable[[int, float, dict[str, float]], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    project: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> SolveResult:
    """Minimise ``objective`` (+ ``lam * ||h - h^e||_1`` when ``prox``) from a feasible start.

    Args:
        objective: smooth part; returns the energy (with graph) and named parts.
        h0: (V,) feasible heights. c0: (F, 3) feasible colours in (0, 1).
        z: (V,) base heights; delta: the bound |z - h| < delta.
        settings: solver settings. prox: the sparse stage's L1 term.
        callback: called after each accepted iteration with (iteration, energy, parts).
        should_stop: polled each iteration (e.g. a time budget); True ends the stage.
        project: maps trial heights (V,) onto a constraint set the box cannot
            express (the printer's minimum feature, :mod:`saucerfab.model.relief`),
            keeping them inside the box; every trial is projected before it is
            judged, so every accepted iterate is in the set (projected line
            search). ``h0`` must already be in it.

    Returns:
        The last accepted iterate, detached.
    """
    if not feasible(h0, z, c0, delta):
        raise ValueError("the starting point must be strictly feasible")
    t0 = time.perf_counter()
    s = settings
    h = h0.detach().clone()
    c = c0.detach().clone()

    evaluations = 0

    def full(hh: torch.Tensor, cc: torch.Tensor) -> tuple[torch.Tensor, float, dict[str, float]]:
        nonlocal evaluations
        evaluations += 1
        hh = hh.detach().requires_grad_(s.optimize_heights)
        cc = cc.detach().requires_grad_(True)
        e, parts = objective(hh, cc)
        total = float(e.detach())
        if prox is not None:
            sp = float(prox.value(hh.detach(), prox.center))
            parts = {**parts, prox.name: sp}
            total += prox.lam * sp
        parts = {**parts, "E_total": total}
        e._saucerfab_inputs = (hh, cc)  # type: ignore[attr-defined]
        return e, total, parts

    adam = _Adamax([h.shape, c.shape], h, s)
    e, total, parts = full(h, c)
    if not math.isfinite(total):
        raise ValueError("the objective is not finite at the starting point")
    g_h, g_c = _gradients(e, h, c)
    # (renders so far, objective) at the start and after each accepted step: the stall rule's history
    marks: list[tuple[int, float]] = [(evaluations, total)]
    log: list[dict[str, float]] = []
    calm = 0
    rejected = 0
    converged = False
    reason = "max_iters"
    it = 0
    for it in range(1, s.max_iters + 1):
        if should_stop is not None and should_stop():
            reason = "stopped"
            break
        if not (_all_finite(g_h) and _all_finite(g_c)):
            # a renderer defect, not a property of the design: every direction
            # would be NaN and every trial rejected; stop and say so
            reason = "nonfinite_gradient"
            break
        (m_h, m_c), (u_h, u_c) = adam.update([g_h, g_c])
        step_c = s.lr_c * m_c / u_c  # m_c is already bias-corrected
        if not s.optimize_heights:
            d_h = torch.zeros_like(h)
        elif prox is None:
            d_h = s.lr_h * m_h / u_h
        else:
            step = prox.alpha * s.lr_h / u_h
            x = h - step * m_h
            d_h = h - prox.operator(x, prox.center, prox.lam * step)
        # fraction to the boundary (interior-point practice): every beta in
        # (0, beta_max] keeps the box constraints strictly satisfied
        if s.boundary_rule == "coordinate":
            d_h = _truncate_to_boundary(h, d_h, z - delta, z + delta)
            step_c = _truncate_to_boundary(c, step_c, 0.0, 1.0)
            beta = 1.0
        else:
            beta = min(1.0, FRACTION_TO_BOUNDARY * _max_feasible_step(h, d_h, z, delta, c, step_c))
        # directional derivative of the smooth part along -d (for Armijo)
        slope = float((g_h * d_h).sum() + (g_c * step_c).sum())
        accepted = False
        for _ in range(s.max_backtracks + 1):
            h_try = h - beta * d_h
            if project is not None and s.optimize_heights:
                h_try = project(h_try)
            c_try = c - beta * step_c
            if feasible(h_try, z, c_try, delta):
                e_try, tot_try, parts_try = full(h_try, c_try)
                if math.isfinite(tot_try) and tot_try <= total - s.armijo * beta * max(slope, 0.0):
                    accepted = True
                    break
            beta *= 0.5
        if not accepted:
            # A direction made from fresh moments (the first after a reset, or the
            # stage's first) is a function of the iterate alone, which a rejection
            # leaves as it was: a retry would render the same trials and be
            # rejected again, so the stage ends now with the same iterate it would
            # end with after the remaining rejections (up to 2 x 7 renders sooner).
            fresh = adam.t == 1
            adam.reset()
            calm = 0
            rejected += 1
            if rejected >= s.max_rejections or fresh:
                converged, reason = True, "no_descent"
                break
            continue
        rejected = 0
        g_h, g_c = _gradients(e_try, h, c)
        rel = abs(total - tot_try) / max(abs(total - s.energy_floor), 1e-30)
        h, c, total, parts = h_try.detach(), c_try.detach(), tot_try, parts_try
        entry = {"iteration": float(it), "beta": beta, "time_s": time.perf_counter() - t0, **parts}
        log.append(entry)
        if callback is not None:
            callback(it, total, parts)
        calm = calm + 1 if rel < s.tol else 0
        if calm >= s.patience:
            converged, reason = True, "tolerance"
            break
        marks.append((evaluations, total))
        if s.stall_window and _stalled(marks, s.stall_window, s.tol, s.energy_floor):
            converged, reason = True, "stalled"
            break
    return SolveResult(h, c, it, total, converged, log, time.perf_counter() - t0, evaluations, reason)


def _truncate_to_boundary(
    x: torch.Tensor, d: torch.Tensor, lo: torch.Tensor | float, hi: torch.Tensor | float
) -> torch.Tensor:
    """The step ``d`` (the update is ``x - d``) with each coordinate cut to at most
    :data:`FRACTION_TO_BOUNDARY` of its distance to the bound it moves towards.

    Shapes: x, d and tensor bounds alike. A coordinate moving away from its
    near bound is not limited. Per coordinate rather than one scale for the
    whole step: with one scale a single vertex resting a hair from its
    bound (distances of 3e-8 occur after a stage) caps every vertex's step
    at that hair, and the stage stalls (measured: accepted betas of 1e-5,
    no vertex moving 1e-4 in the sparse stage).
    """
    room_down = FRACTION_TO_BOUNDARY * (x - lo)  # d > 0 moves x down towards lo
    room_up = FRACTION_TO_BOUNDARY * (hi - x)
    return torch.where(d > 0, torch.minimum(d, room_down), torch.maximum(d, -room_up))


def _stalled(marks: list[tuple[int, float]], window: int, tol: float, floor: float) -> bool:
    """Whether the objective fell by less than ``tol`` relative per render over at least the last ``window`` renders.

    ``marks``: (renders so far, objective) at the start and after each accepted
    step, in order; the last is now. The window reaches back to the latest mark
    at least ``window`` renders old (so it spans whole steps); with none that
    old the rule waits.
    """
    n_now, e_now = marks[-1]
    for n_then, e_then in reversed(marks[:-1]):
        if n_now - n_then >= window:
            fell = (e_then - e_now) / max(abs(e_then - floor), 1e-30)
            return fell < tol * (n_now - n_then)
    return False


def _gradients(e: torch.Tensor, h: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Back-propagate ``e`` (from ``full``); (dE/dh (V,), dE/dc (F, 3)), zeros where unused."""
    e.backward()
    hh, cc = e._saucerfab_inputs  # type: ignore[attr-defined]
    g_h = hh.grad if hh.grad is not None else torch.zeros_like(h)
    g_c = cc.grad if cc.grad is not None else torch.zeros_like(c)
    return g_h, g_c


def _all_finite(t: torch.Tensor) -> bool:
    """Whether every element of ``t`` is finite.

    The sum is finite when every element is (one fast reduction, no boolean
    copy: this runs every iteration); only a non-finite sum, which an overflow
    of finite elements also gives, is checked element by element.
    """
    return math.isfinite(float(t.sum())) or bool(torch.isfinite(t).all())


def _max_feasible_step(
    h: torch.Tensor, d_h: torch.Tensor, z: torch.Tensor, delta: float, c: torch.Tensor, d_c: torch.Tensor
) -> float:
    """Largest beta with |z - (h - beta d_h)| <= delta and 0 <= c - beta d_c <= 1.

    Per coordinate the step may run until the bound it moves towards:
    ``(x - lo) / d`` when x decreases (d > 0), ``(hi - x) / -d`` when it
    increases; the smallest over all coordinates bounds beta. Written with
    ``where`` and one reduction (no boolean indexing: this runs every iteration).
    """
    inf = torch.tensor(float("inf"), dtype=h.dtype)
    best = inf
    for x, d, lo, hi in ((h, d_h, z - delta, z + delta), (c, d_c, 0.0, 1.0)):
        safe = torch.where(d == 0, torch.ones_like(d), d)
        to_lo = torch.where(d > 0, (x - lo) / safe, inf)
        to_hi = torch.where(d < 0, (hi - x) / -safe, inf)
        best = torch.minimum(best, torch.minimum(to_lo.min(), to_hi.min()))
    return max(float(best), 0.0)
