"""The paper's energies (section 3.1, 3.4.1) and the proximal step, in torch.

Notation (paper): ``h`` (V,) current heights, ``z`` (V,) base heights,
``c`` (F, 3) per-face colours, ``delta`` the height bound, ``L`` the uniform
Laplacian of the grid mesh (:func:`saucerfab.model.heightfield.laplacian`).

* E_visual (eq. 2/7): ``sum ||target - rendered||_F^2`` over the views.
* E_deform (eq. 3): ``sum_i ((L z)_i - (L h)_i)^2``.
* E_barrier (eq. 4-5): ``sum_i phi(delta - (z_i - h_i)) + phi(delta + (z_i - h_i))
  + sum_{j,k} phi(c_jk) + phi(1 - c_jk)``, ``phi(x) = -log x`` for x > 0 else +inf.
* E_sparse (eq. 9): ``sum_i |h_i - h^e_i|``.
* prox (eq. 14-15): soft thresholding around ``h^e``.

Everything takes and returns torch tensors; energies are 0-d tensors so they
can be back-propagated.

The terms of the objective are declared here (:data:`TERMS`), each with the
weights that may scale it (:data:`WEIGHTS`): the design request's weight
fields, the ``saucerfab design`` weight options, the automatic rho-based
weights and the energy log's columns are all read from these declarations,
and :mod:`saucerfab.optimize.stages` says which stage uses which term.
torch is imported inside the functions, so the declarations can be read
without it (``saucerfab --help``, the batch manifest check).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import torch


def e_visual(rendered: list[torch.Tensor], targets: list[torch.Tensor],
             masks: list[torch.Tensor | None] | None = None) -> torch.Tensor:
    """Squared Frobenius distance summed over views (eq. 2 / eq. 7).

    Args:
        rendered: per view an (S, S, 3) image.
        targets: per view an (S, S, 3) image of the same size.
        masks: per view None (every pixel) or an (S, S, 1) 0/1 tensor: the pixels of
            the view's picture (its rectangle in the square view,
            :meth:`saucerfab.optimize.views.Rig.picture_masks`); None: every view whole.
    """
    import torch

    # Accumulate in float64: a float32 sum over 1.5 M squared pixel errors
    # rounds by more than the changes the line search has to compare.
    total = rendered[0].new_zeros((), dtype=torch.float64)
    squared_distance = _squared_distance()
    for k, (r, t) in enumerate(zip(rendered, targets, strict=True)):
        m = None if masks is None else masks[k]
        total = total + (squared_distance.apply(r, t) if m is None else (((r - t) * m) ** 2).sum(dtype=torch.float64))
    return total


_SQUARED_DISTANCE = None


def _squared_distance():  # type: ignore[no-untyped-def]
    """The autograd Function of one view's term: ``(r, t) -> ((r - t) ** 2).sum(dtype=float64)``.

    The forward is that expression, op for op (the same value, bit for bit).
    The backward is one multiply, ``dL/dr = (r - t) * 2g`` in r's dtype: the
    same bits as autograd's chain through the expression (its float64 scalar
    gradient broadcast and cast to float32, then pow's two multiplies; scaling
    by 2 is exact), without its three image-sized copies (about 1 ms of an
    iteration at 512 px). Built on first use: torch is imported lazily here.
    """
    global _SQUARED_DISTANCE
    if _SQUARED_DISTANCE is None:
        import torch
        from torch.autograd.function import once_differentiable

        class SquaredDistance(torch.autograd.Function):
            @staticmethod
            def forward(ctx, r, t):  # type: ignore[no-untyped-def]
                d = r - t
                ctx.save_for_backward(d)
                return (d**2).sum(dtype=torch.float64)

            @staticmethod
            @once_differentiable
            def backward(ctx, g):  # type: ignore[no-untyped-def]
                (d,) = ctx.saved_tensors
                g_r = d * (2 * g).to(d.dtype)
                return (g_r if ctx.needs_input_grad[0] else None), (-g_r if ctx.needs_input_grad[1] else None)

        _SQUARED_DISTANCE = SquaredDistance
    return _SQUARED_DISTANCE


class DeformEnergy:
    """E_deform(h) = ||L z - L h||^2 with a fixed sparse Laplacian (eq. 3).

    The Laplacian's rows are short (a vertex and its <= 6 mesh neighbours),
    so ``L h`` is a gather over a padded (V, K) neighbour table and a weighted
    sum: differentiable, deterministic, and free of torch's beta sparse API.

    Args:
        lap: scipy sparse (V, V) Laplacian.
        base: (V,) base heights z.
    """

    def __init__(self, lap, base: torch.Tensor) -> None:  # type: ignore[no-untyped-def]
        import torch

        csr = lap.tocsr()
        counts = np.diff(csr.indptr)
        k = int(counts.max())
        v = csr.shape[0]
        idx = np.tile(np.arange(v)[:, None], (1, k))  # padding points at the row itself...
        wts = np.zeros((v, k))  # ...with weight 0
        for r in range(k):
            has = counts > r
            idx[has, r] = csr.indices[csr.indptr[:-1][has] + r]
            wts[has, r] = csr.data[csr.indptr[:-1][has] + r]
        self.idx = torch.as_tensor(idx, dtype=torch.int64)
        self.wts = torch.as_tensor(wts, dtype=base.dtype)
        self.lz = self.apply(base.detach())

    def apply(self, h: torch.Tensor) -> torch.Tensor:
        """L h for (V,) h."""
        # index_select's backward is index_add (fast); h[idx] would go through
        # index_put with accumulate, which is slow on the CPU
        g = h.index_select(0, self.idx.reshape(-1)).view(self.idx.shape)
        return (g * self.wts.to(h.dtype)).sum(dim=1)

    def __call__(self, h: torch.Tensor) -> torch.Tensor:
        import torch

        return ((self.lz - self.apply(h)) ** 2).sum(dtype=torch.float64)


def e_barrier(h: torch.Tensor, z: torch.Tensor, c: torch.Tensor, delta: float) -> torch.Tensor:
    """Log barriers for |z - h| < delta and 0 < c < 1 (eq. 4-5).

    Returns +inf when any variable is outside the open feasible box, as
    phi does; callers keep iterates strictly feasible (the line search).
    """
    import torch

    dz = z - h
    cf = c.reshape(-1)
    # log of a non-positive number is -inf or NaN; one finiteness test at the
    # end replaces a synchronising test per term
    f64 = torch.float64  # sums in float64, as in e_visual
    total = -(
        torch.log(delta - dz).sum(dtype=f64)
        + torch.log(delta + dz).sum(dtype=f64)
        + torch.log(cf).sum(dtype=f64)
        + torch.log(1 - cf).sum(dtype=f64)
    )
    if not bool(torch.isfinite(total)):
        return h.new_tensor(float("inf"))
    return total


def barrier_floor(num_vertices: int, num_faces: int, delta: float) -> float:
    """The smallest value of E_barrier: all h at z, all colours at 0.5 (eq. 5)."""
    return -2.0 * num_vertices * np.log(delta) - 6.0 * num_faces * np.log(0.5)


def e_sparse(h: torch.Tensor, h_e: torch.Tensor) -> torch.Tensor:
    """E_sparse = sum |h - h^e| (eq. 9)."""
    return (h - h_e).abs().sum()


def prox_l1(x: torch.Tensor, center: torch.Tensor, threshold: float | torch.Tensor) -> torch.Tensor:
    """prox of ``psi(h) = lam * ||h - center||_1`` with step alpha, threshold = lam * alpha.

    ``threshold`` may be a tensor (a per-coordinate step, as in a diagonal metric).

    ``argmin_h psi(h) + ||h - x||^2 / (2 alpha)`` is soft thresholding of
    ``x - center`` by ``lam * alpha``, shifted back by ``center``. (Eq. 15 in
    the paper prints the offset ``x - h^e -+ lam alpha`` without adding
    ``h^e`` back; the minimiser of eq. 14 includes it.)
    """
    import torch

    d = x - center
    return center + torch.sign(d) * torch.clamp(d.abs() - threshold, min=0.0)


def feasible(h: torch.Tensor, z: torch.Tensor, c: torch.Tensor, delta: float) -> bool:
    """True when |z - h| < delta and 0 < c < 1 strictly (the barrier is finite)."""
    return bool(((z - h).abs() < delta).all() and (c > 0).all() and (c < 1).all())


# --------------------------------------------------------------------------- declared terms

#: an energy of a run: (h (V,), c (F, 3)) -> 0-d tensor; for a proximal term (h (V,), h^e (V,)) -> 0-d tensor
Energy = Callable[["torch.Tensor", "torch.Tensor"], "torch.Tensor"]


@dataclass(frozen=True)
class Weight:
    """A weight of an energy term that the user may set.

    Each declared weight is a field of :class:`~saucerfab.optimize.request.DesignRequest`
    and an option of ``saucerfab design`` (:attr:`option`). A weight with a
    ``rho_factor`` is chosen per stage (``StageSpec.weight``), is
    ``rho_factor * rho`` unless given (section 3.5) and is recorded in
    design.json's ``weights_used``; a weight without one has a fixed
    ``default`` and applies in every stage.

    Attributes:
        key: the request field, the CLI option (``--`` + key with ``-``) and the ``weights_used`` key.
        help: one line for ``--help``; the default is added from ``rho_factor`` / ``default``.
        rho_factor: the automatic weight's multiple of rho, or None for a fixed weight.
        default: a fixed weight's default (None for a rho weight: "not given").
        positive: the weight must be > 0 (else >= 0).
    """

    key: str
    help: str
    rho_factor: float | None = None
    default: float | None = None
    positive: bool = False

    @property
    def option(self) -> str:
        """The ``saucerfab design`` option, e.g. ``--w-large``."""
        return "--" + self.key.replace("_", "-")

    @property
    def per_stage(self) -> bool:
        """True for a rho weight that a stage chooses; False for a fixed weight of every stage."""
        return self.rho_factor is not None

    def default_text(self) -> str:
        """The default as ``--help`` says it: ``0.08 rho`` or ``0.01``."""
        return f"{self.rho_factor:g} rho" if self.rho_factor is not None else f"{self.default:g}"


@dataclass(frozen=True)
class Problem:
    """The fixed data of a run that the energies depend on besides (h, c).

    Attributes:
        z: (V,) base heights, model units (V = n * n).
        delta: the height bound |z - h| < delta, model units.
        n: heightfield vertices per side.
        num_faces: F, saucer faces.
    """

    z: torch.Tensor
    delta: float
    n: int
    num_faces: int


@dataclass(frozen=True)
class Term:
    """One energy of the objective ``E = E_visual + sum_k w_k E_k``.

    E_visual (the data term, weight 1) is not a Term: its targets are the
    stage's. Every smooth term is evaluated and logged in every stage, in
    :data:`TERMS` order, with weight 0 in a stage that neither uses it
    (``StageSpec.regulariser``) nor has a fixed weight for it; a proximal
    term is solved by the solver's proximal step (section 3.4.1) in the
    stages that use it, centred on the heights the stage starts from.

    Attributes:
        name: what a stage's ``regulariser`` calls it; ``E_<name>`` (:attr:`key`)
            names it in the energy log and the metrics.
        weights: the weights that may scale it (a stage picks one of the rho weights).
        make: builds the energy from the run's fixed data: ``make(problem) -> Energy``.
        prox: the proximal operator ``prox(x, center, threshold)`` of a proximal
            term; None for a smooth term.
        floor: the smallest value of the term, per unit weight (the solver's
            relative-change test subtracts the weighted floors), or None for 0.
        in_metrics: its value after each stage (and a smooth term's at the end)
            is reported in design.json's metrics.
    """

    name: str
    weights: tuple[Weight, ...]
    make: Callable[[Problem], Energy]
    prox: Callable[..., torch.Tensor] | None = None
    floor: Callable[[Problem], float] | None = None
    in_metrics: bool = True

    @property
    def key(self) -> str:
        """The term's name in the energy log and the metrics, e.g. ``E_deform``."""
        return f"E_{self.name}"


def _deform(p: Problem) -> Energy:
    from saucerfab.model.heightfield import laplacian

    deform = DeformEnergy(laplacian(p.n), p.z)
    return lambda h, c: deform(h)


def _barrier(p: Problem) -> Energy:
    return lambda h, c: e_barrier(h, p.z, c, p.delta)


#: the terms of the objective, in the order the energy log lists them
TERMS: tuple[Term, ...] = (
    Term(
        "deform",
        (
            Weight("w_large", "E_deform weight in the stages at the large sigma", rho_factor=0.08),
            Weight("w_small", "E_deform weight in the stages at the small sigma", rho_factor=0.2),
        ),
        _deform,
    ),
    Term(
        "barrier",
        (
            Weight(
                "barrier_weight",
                # why 0.01: DesignRequest's docstring (the paper's 1 blunts the black-white contrast)
                "weight of the log barriers (eq. 5); 1 = the paper as written, see "
                "benchmarks/results/HISTORY.md, Design",
                default=0.01,
                positive=True,
            ),
        ),
        _barrier,
        floor=lambda p: barrier_floor(p.n * p.n, p.num_faces, p.delta),
        in_metrics=False,
    ),
    Term("sparse", (Weight("lam", "E_sparse weight", rho_factor=6e-5),), lambda p: e_sparse, prox=prox_l1),
)

#: every declared weight, in :data:`TERMS` order
WEIGHTS: tuple[Weight, ...] = tuple(w for t in TERMS for w in t.weights)


def term(name: str) -> Term:
    """The declared term called ``name`` (``deform``...)."""
    for t in TERMS:
        if t.name == name:
            return t
    raise KeyError(name)
