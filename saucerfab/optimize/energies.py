"""The paper's energies (section 3.1, 3.4.1) and the proximal step, in torch.

Notation (paper): ``h`` (V,) current heights, ``z`` (V,) base heights,
``c`` (F, 3) per-face colours, ``delta`` the height bound, ``L`` the uniform
Laplacian of the grid mesh (:func:`saucerfab.heightfield.laplacian`).

* E_visual (eq. 2/7): ``sum ||target - rendered||_F^2`` over the views.
* E_deform (eq. 3): ``sum_i ((L z)_i - (L h)_i)^2``.
* E_barrier (eq. 4-5): ``sum_i phi(delta - (z_i - h_i)) + phi(delta + (z_i - h_i))
  + sum_{j,k} phi(c_jk) + phi(1 - c_jk)``, ``phi(x) = -log x`` for x > 0 else +inf.
* E_sparse (eq. 9): ``sum_i |h_i - h^e_i|``.
* prox (eq. 14-15): soft thresholding around ``h^e``.

Everything takes and returns torch tensors; energies are 0-d tensors so they
can be back-propagated.
"""

from __future__ import annotations

import numpy as np
import torch


def e_visual(rendered: list[torch.Tensor], targets: list[torch.Tensor]) -> torch.Tensor:
    """Squared Frobenius distance summed over views (eq. 2 / eq. 7).

    Args:
        rendered: per view an (S, S, 3) image.
        targets: per view an (S, S, 3) image of the same size.
    """
    # Accumulate in float64: a float32 sum over 1.5 M squared pixel errors
    # rounds by more than the changes the line search has to compare.
    total = rendered[0].new_zeros((), dtype=torch.float64)
    for r, t in zip(rendered, targets, strict=True):
        total = total + ((r - t) ** 2).sum(dtype=torch.float64)
    return total


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
        return ((self.lz - self.apply(h)) ** 2).sum(dtype=torch.float64)


def e_barrier(h: torch.Tensor, z: torch.Tensor, c: torch.Tensor, delta: float) -> torch.Tensor:
    """Log barriers for |z - h| < delta and 0 < c < 1 (eq. 4-5).

    Returns +inf when any variable is outside the open feasible box, as
    phi does; callers keep iterates strictly feasible (the line search).
    """
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
    d = x - center
    return center + torch.sign(d) * torch.clamp(d.abs() - threshold, min=0.0)


def feasible(h: torch.Tensor, z: torch.Tensor, c: torch.Tensor, delta: float) -> bool:
    """True when |z - h| < delta and 0 < c < 1 strictly (the barrier is finite)."""
    return bool(((z - h).abs() < delta).all() and (c > 0).all() and (c < 1).all())
