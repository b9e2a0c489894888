"""The differentiable soft rasterizer: public op, SoftRas constants, backend dispatch.

Semantics are those of SoftRas (Liu et al. 2019), as its CUDA kernel
``soft_rasterize_cuda_kernel.cu`` computes them with the defaults of its
``soft_rasterize`` (``dist_func='euclidean'``, ``aggr_func_rgb='softmax'``,
``aggr_func_alpha='prod'``, ``fill_back=True``, per-face colours). For one
pixel centre ``p`` (NDC, see :mod:`saucerfab.model.camera`) and one face
``f`` with projected corners ``(x_k, y_k, z_k)`` (``z_k`` = camera depth):

1. ``w`` = barycentric coordinates of ``p`` from the inverse of the 3x3
   matrix ``[[x_k], [y_k], [1]]``, whose determinant is clamped away from
   zero to magnitude ``>= 1e-10`` keeping its sign (SoftRas: ``1e-10``).
2. ``d`` = Euclidean NDC distance from ``p`` to the closed triangle; ``sign``
   = +1 when all ``0 < w_k < 1`` (inside), else -1.
3. The pair is skipped when ``sign < 0`` and ``d^2 >= log(1/dist_eps - 1) * sigma``
   (SoftRas converts ``dist_eps`` so; the coverage of a skipped pair would be
   below ``dist_eps``). Faces are never culled by winding (``fill_back=True``):
   the reflected saucer is mirrored, so its winding is flipped.
4. Coverage ``D = sigmoid(sign * d^2 / sigma)``.
5. Alpha: ``alpha = 1 - prod_f (1 - D_f)`` over the pairs not skipped.
6. Depth: ``w_clip = clamp(w, 0, 1) / max(sum(clamp(w, 0, 1)), 1e-5)``
   (SoftRas: ``1e-5``), ``z = 1 / sum_k (w_clip_k / z_k)`` (perspective-correct),
   pairs with ``z < near`` or ``z > far`` are left out of the colour (but not of
   alpha); normalized inverse depth ``zn = (far - z) / (far - near)``.
7. Colour: softmax over the pixel's pairs with weights
   ``D_f exp((zn_f - m) / gamma)`` and a background weight
   ``exp((2 eps - m) / gamma)``, ``m = max(eps, max_f zn_f)``:
   ``image = (bg * w_bg + sum_f w_f c_f) / (w_bg + sum_f w_f)``.
   The background weight follows the kernel, which starts the running sum at
   ``exp(eps / gamma)`` and the running maximum at ``eps``; the SoftRas paper
   writes ``exp(eps / gamma)`` unshifted, i.e. ``exp((eps - m) / gamma)``.
   At the paper's depths (``zn`` about 0.94) both are ``exp(-9.4e3)`` = 0.

Gradients are the exact derivatives of this forward function (what
``torch.autograd.gradcheck`` checks), including the depth's dependence on
the corners' x, y through ``w_clip``; SoftRas's hand-written backward drops
that term and divides the alpha gradient by ``max(1 - D, 1e-6)``.

Constants taken from SoftRas, all of them:

* defaults of ``soft_rasterize``: ``sigma_val = 1e-5``, ``gamma_val = 1e-4``,
  ``near = 1``, ``far = 100``, ``eps = 1e-3``, ``dist_eps = 1e-4``,
  ``background_color = [0, 0, 0]``; the paper's runs use them with sigma
  1e-5 and 1e-7;
* ``dist_eps -> log(1 / dist_eps - 1)`` (the Python wrapper), times ``sigma``
  in the kernel: the skip threshold on ``d^2``; faces are culled first by
  their bounding box widened by its square root (``check_border``), which
  never drops a pair the threshold keeps;
* ``1e-10``: the determinant clamp of ``forward_soft_rasterize_inv_cuda_kernel``
  (:data:`DET_EPS`);
* ``1e-5``: the clamp of the clipped barycentric sum in ``barycentric_clip``
  (:data:`WSUM_EPS`);
* the running softmax's start: sum ``exp(eps / gamma)``, maximum ``eps``;
* pixel centres ``x = (2 j + 1 - S) / S``, ``y = (2 (S - 1 - i) + 1 - S) / S``
  for image row ``i``: the same as :mod:`saucerfab.model.camera`'s
  convention (row 0 at the top).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

from saucerfab.errors import ConfigError
from saucerfab.render.soft_common import DEFAULTS, DET_EPS, WSUM_EPS, SoftParams, distance_threshold

if TYPE_CHECKING:
    import torch

    from saucerfab.model.camera import Camera

__all__ = ["DET_EPS", "WSUM_EPS", "Backend", "SoftParams", "distance_threshold", "select_backend", "soft_rasterize"]

Backend = Literal["auto", "torch", "numba"]


def select_backend(backend: str, device: "torch.device") -> str:
    """The backend that runs: ``"numba"`` or ``"torch"``.

    ``"auto"`` picks the compiled numba kernels for CPU tensors and the torch
    backend for any other device (CUDA: there it is the GPU path).

    Raises:
        ConfigError: an unknown backend, or ``"numba"`` for tensors not on the CPU.
    """
    if backend not in ("auto", "torch", "numba"):
        raise ConfigError(f"backend must be 'auto', 'torch' or 'numba', got {backend!r}")
    if backend == "auto":
        return "numba" if device.type == "cpu" else "torch"
    if backend == "numba" and device.type != "cpu":
        raise ConfigError(
            f"backend='numba' runs on the CPU, but the tensors are on {device}; "
            "use backend='auto' or 'torch', or move them with .cpu()"
        )
    return backend


def _check_tensors(vertices: "torch.Tensor", faces: "torch.Tensor", face_colors: "torch.Tensor") -> None:
    """Raise :class:`ConfigError` unless the mesh tensors have the shapes, dtypes and device the backends need."""
    import torch

    if not isinstance(vertices, torch.Tensor) or vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ConfigError(f"vertices must be a (V, 3) tensor, got {getattr(vertices, 'shape', type(vertices))}")
    if vertices.dtype not in (torch.float32, torch.float64):
        raise ConfigError(f"vertices must be float32 or float64, got {vertices.dtype}")
    if not isinstance(faces, torch.Tensor) or faces.ndim != 2 or faces.shape[1] != 3:
        raise ConfigError(f"faces must be an (F, 3) integer tensor, got {getattr(faces, 'shape', type(faces))}")
    if faces.dtype.is_floating_point or faces.dtype == torch.bool:
        raise ConfigError(f"faces must hold integer vertex indices, got {faces.dtype}")
    if (
        not isinstance(face_colors, torch.Tensor)
        or face_colors.ndim != 2
        or face_colors.shape != (faces.shape[0], 3)
    ):
        raise ConfigError(
            f"face_colors must be an (F, 3) tensor with F = {faces.shape[0]} faces, "
            f"got {getattr(face_colors, 'shape', type(face_colors))}"
        )
    if not face_colors.dtype.is_floating_point:
        raise ConfigError(f"face_colors must be floating point, got {face_colors.dtype}")
    if faces.device != vertices.device or face_colors.device != vertices.device:
        raise ConfigError(
            f"vertices ({vertices.device}), faces ({faces.device}) and face_colors "
            f"({face_colors.device}) must be on the same device"
        )
    if faces.numel():
        # numpy on the CPU: torch's integer min and max each wake its thread pool
        idx = faces.detach().numpy() if faces.device.type == "cpu" else faces
        lo, hi = int(idx.min()), int(idx.max())
        if lo < 0 or hi >= vertices.shape[0]:
            raise ConfigError(
                f"faces index vertices {lo}..{hi}, but there are {vertices.shape[0]} vertices"
            )


def _checked_params(p: SoftParams) -> SoftParams:
    """``p`` with plain Python floats, after checking each value's range.

    Raises:
        ConfigError: a parameter outside its range (or not a number).
    """
    for name, v in (("sigma", p.sigma), ("gamma", p.gamma)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{name} must be a positive number, got {v!r}")
    if not (isinstance(p.dist_eps, (int, float)) and 0 < p.dist_eps < 0.5):
        raise ConfigError(f"dist_eps must be in (0, 0.5) (a coverage level), got {p.dist_eps!r}")
    if not (math.isfinite(p.near) and math.isfinite(p.far) and 0 <= p.near < p.far):
        raise ConfigError(f"need 0 <= near < far, got near={p.near!r}, far={p.far!r}")
    if not math.isfinite(p.eps):
        raise ConfigError(f"eps must be a finite number, got {p.eps!r}")
    if len(tuple(p.background)) != 3 or not all(math.isfinite(float(c)) for c in p.background):
        raise ConfigError(f"background must be 3 finite numbers (RGB), got {p.background!r}")
    return SoftParams(
        sigma=float(p.sigma),
        gamma=float(p.gamma),
        background=tuple(float(c) for c in p.background),  # type: ignore[arg-type]
        near=float(p.near),
        far=float(p.far),
        eps=float(p.eps),
        dist_eps=float(p.dist_eps),
    )


def soft_rasterize(
    vertices: "torch.Tensor",
    faces: "torch.Tensor",
    face_colors: "torch.Tensor",
    camera: "Camera",
    *,
    sigma: float = DEFAULTS.sigma,
    gamma: float = DEFAULTS.gamma,
    background: tuple[float, float, float] = DEFAULTS.background,
    near: float = DEFAULTS.near,
    far: float = DEFAULTS.far,
    eps: float = DEFAULTS.eps,
    dist_eps: float = DEFAULTS.dist_eps,
    backend: Backend = "auto",
) -> "tuple[torch.Tensor, torch.Tensor]":
    """Soft-rasterize a mesh with per-face colours (SoftRas semantics, differentiable).

    The formulas and every constant taken from SoftRas are listed in the
    module docstring of :mod:`saucerfab.render.soft`. The camera convention
    (projection, row 0 at the top, pixel centres) is
    :mod:`saucerfab.model.camera`'s.

    Args:
        vertices: World positions, shape [V, 3], model units, float32 or
            float64; may require grad.
        faces: Vertex indices of the triangles, shape [F, 3], int64 (any
            integer type). Winding does not matter (no back-face culling).
        face_colors: RGB colour of each face, shape [F, 3], values in [0, 1];
            may require grad. Cast to ``vertices.dtype``.
        camera: The view; its ``image_size`` S sets the output size.
        sigma: SoftRas ``sigma_val``: width of the coverage sigmoid, squared
            NDC units (default 1e-5, SoftRas's default).
        gamma: SoftRas ``gamma_val``: softmax temperature over normalized
            inverse depth (default 1e-4, SoftRas's default).
        background: RGB background colour (SoftRas default black).
        near: Near depth, model units (SoftRas default 1).
        far: Far depth, model units (SoftRas default 100).
        eps: Background's normalized inverse depth (SoftRas default 1e-3).
        dist_eps: Coverage below which a pixel-face pair is skipped (SoftRas
            default 1e-4).
        backend: ``"auto"`` (the numba kernels for CPU tensors; for CUDA
            tensors the torch backend, the GPU path), ``"torch"`` (vectorized
            torch over bounding-box pixel-face pairs, autograd, any device) or
            ``"numba"`` (compiled CPU kernels; CPU tensors only).

    Returns:
        A tuple of tensors ``(image, alpha)``:

        - **image** - Colour, shape [S, S, 3], ``vertices.dtype``; ``image[i, j]``
          is row i (0 = top), column j (0 = left).
        - **alpha** - Coverage ``1 - prod(1 - D)``, shape [S, S].

    Raises:
        ConfigError: a tensor of the wrong shape, dtype or device, an index
            out of range, or a parameter outside its range.
    """
    import torch

    _check_tensors(vertices, faces, face_colors)
    params = _checked_params(SoftParams(sigma, gamma, background, near, far, eps, dist_eps))
    chosen = select_backend(backend, vertices.device)
    colors = face_colors.to(vertices.dtype)
    faces = faces.to(torch.int64)
    if chosen == "numba":
        from saucerfab.render.soft_numba import soft_rasterize_numba

        return soft_rasterize_numba(vertices, faces, colors, camera, params)
    from saucerfab.render.soft_torch import soft_rasterize_torch

    return soft_rasterize_torch(vertices, faces, colors, camera, params)
