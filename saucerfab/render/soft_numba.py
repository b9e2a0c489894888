"""The compiled CPU backend of the soft rasterizer: per-face setup, chain rule, autograd glue.

The formulas are :mod:`saucerfab.render.soft`'s; this backend only organises
the work. The Function takes the world vertices (V, 3), the face colours and
the camera, projects the vertices with ``Camera.project_torch`` outside
autograd and returns the image and alpha; its backward returns dL/d(world
vertices) (the projection's chain rule in numba, :func:`_project_grad`: a
dozen small autograd ops per call cost more) and dL/dcolours. Handed ``camera=None`` it takes
vertices projected already (x_ndc, y_ndc, depth).

* Per-face setup (:func:`_face_setup`): corners, SoftRas's barycentric matrix
  (adjugate / clamped determinant) and inverse corner depths. Its chain rule
  (:func:`_face_grads`) and the scatter to vertices run in numba too: a few
  dozen small torch ops per call cost more than the setup itself.
* The faces are binned into tiles (:mod:`saucerfab.render.soft_tiles`) and
  each tile is rendered, forward and backward, by the kernels of
  :mod:`saucerfab.render.soft_kernels`.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit, prange

from saucerfab.render import soft_kernels
from saucerfab.render.soft_common import DET_EPS, SoftParams
from saucerfab.render.soft_tiles import JIT_OPTS, N_GRAD, make_bins, one_tile_chunks

if TYPE_CHECKING:
    import torch

    from saucerfab.model.camera import Camera


# --------------------------------------------------------------------------- per-face setup and chain rule


@njit(parallel=True, **JIT_OPTS)
def _face_setup(proj, faces, det_eps):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Per-face kernel inputs from the projected vertices (V, 3) = (x_ndc, y_ndc, depth).

    Returns corners ``cxy`` (F, 6), SoftRas's barycentric matrix ``inv`` (F, 9)
    (adjugate over the determinant clamped to magnitude >= det_eps, keeping its
    sign), ``iz`` (F, 3) = 1 / corner depth, and ``det`` (F,) unclamped.
    """
    n = faces.shape[0]
    dt = proj.dtype
    cxy = np.empty((n, 6), dt)
    inv = np.empty((n, 9), dt)
    iz = np.empty((n, 3), dt)
    det = np.empty(n, dt)
    for f in prange(n):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, x1, y1, x2, y2 = proj[a, 0], proj[a, 1], proj[b, 0], proj[b, 1], proj[c, 0], proj[c, 1]
        cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5] = x0, y0, x1, y1, x2, y2
        d = x2 * (y0 - y1) + x0 * (y1 - y2) + x1 * (y2 - y0)
        det[f] = d
        dc = max(d, det_eps) if d > 0 else min(d, -det_eps)
        inv[f, 0], inv[f, 1], inv[f, 2] = (y1 - y2) / dc, (x2 - x1) / dc, (x1 * y2 - x2 * y1) / dc
        inv[f, 3], inv[f, 4], inv[f, 5] = (y2 - y0) / dc, (x0 - x2) / dc, (x2 * y0 - x0 * y2) / dc
        inv[f, 6], inv[f, 7], inv[f, 8] = (y0 - y1) / dc, (x1 - x0) / dc, (x0 * y1 - x1 * y0) / dc
        iz[f, 0], iz[f, 1], iz[f, 2] = 1 / proj[a, 2], 1 / proj[b, 2], 1 / proj[c, 2]
    return cxy, inv, iz, det


@njit(parallel=True, **JIT_OPTS)
def _face_grads(  # type: ignore[no-untyped-def] # pragma: no cover - jit
    grad, face_start, cxy, inv, iz, det, det_eps, g_corner, g_col
):
    """Sum each face's entry slots (in entry order: deterministic) and apply the
    chain rule through :func:`_face_setup`: ``g_corner[f, k]`` = dL/d(x, y, depth)
    of corner k, ``g_col[f]`` = dL/dcolour."""
    for f in prange(cxy.shape[0]):
        g = np.zeros(N_GRAD, grad.dtype)
        for e in range(face_start[f], face_start[f + 1]):
            for j in range(N_GRAD):
                g[j] += grad[e, j]
        x0, y0, x1, y1, x2, y2 = cxy[f, 0], cxy[f, 1], cxy[f, 2], cxy[f, 3], cxy[f, 4], cxy[f, 5]
        d = det[f]
        dc = max(d, det_eps) if d > 0 else min(d, -det_eps)
        # inv = adj / dc: d inv = d adj / dc - inv d(dc) / dc, and dc is constant
        # where the clamp holds it (torch.clamp passes the gradient at the bound)
        g00, g01, g02 = g[6] / dc, g[7] / dc, g[8] / dc
        g10, g11, g12 = g[9] / dc, g[10] / dc, g[11] / dc
        g20, g21, g22 = g[12] / dc, g[13] / dc, g[14] / dc
        h = 0.0
        if (d > 0 and d >= det_eps) or (d <= 0 and d <= -det_eps):
            for j in range(9):
                h += g[6 + j] * inv[f, j]
            h /= dc
        g_corner[f, 0] = g[0] + g11 - g21 - g12 * y2 + g22 * y1 - h * (y1 - y2)
        g_corner[f, 1] = g[1] - g10 + g20 + g12 * x2 - g22 * x1 - h * (x2 - x1)
        g_corner[f, 3] = g[2] - g01 + g21 + g02 * y2 - g22 * y0 - h * (y2 - y0)
        g_corner[f, 4] = g[3] + g00 - g20 - g02 * x2 + g22 * x0 - h * (x0 - x2)
        g_corner[f, 6] = g[4] + g01 - g11 - g02 * y1 + g12 * y0 - h * (y0 - y1)
        g_corner[f, 7] = g[5] - g00 + g10 + g02 * x1 - g12 * x0 - h * (x1 - x0)
        # iz = 1 / depth
        g_corner[f, 2] = -g[15] * iz[f, 0] * iz[f, 0]
        g_corner[f, 5] = -g[16] * iz[f, 1] * iz[f, 1]
        g_corner[f, 8] = -g[17] * iz[f, 2] * iz[f, 2]
        g_col[f, 0], g_col[f, 1], g_col[f, 2] = g[18], g[19], g[20]


@njit(**JIT_OPTS)
def _scatter_vertices(g_corner, faces, n_vertices):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """(V, 3) sums of the corner gradients per vertex, in face order (deterministic)."""
    out = np.zeros((n_vertices, 3), g_corner.dtype)
    for f in range(faces.shape[0]):
        for k in range(3):
            v = faces[f, k]
            out[v, 0] += g_corner[f, 3 * k]
            out[v, 1] += g_corner[f, 3 * k + 1]
            out[v, 2] += g_corner[f, 3 * k + 2]
    return out


@njit(parallel=True, **JIT_OPTS)
def _project_grad(proj, g_proj, axes, w):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """dL/d(world points) (V, 3) from dL/d(projected points) (V, 3) through
    ``Camera.project_torch`` (``proj``: its output; ``axes`` (3, 3) and ``w``, the
    tangent of the half viewing angle, in their dtype): with ``t = depth w``, ``x = cam_0 / t``, ``y = cam_1 / t``, ``depth = cam_2``,
    dL/dcam = (gx / t, gy / t, g_depth - (gx x + gy y) w / t), and dL/dp = axes^T dL/dcam."""
    out = np.empty_like(g_proj)
    for v in prange(proj.shape[0]):
        x, y, depth = proj[v, 0], proj[v, 1], proj[v, 2]
        gx, gy, gz = g_proj[v, 0], g_proj[v, 1], g_proj[v, 2]
        t = depth * w
        k0, k1 = gx / t, gy / t
        k2 = gz - (k0 * x + k1 * y) * w
        for j in range(3):
            out[v, j] = axes[0, j] * k0 + axes[1, j] * k1 + axes[2, j] * k2
    return out


# --------------------------------------------------------------------------- torch glue


@dataclass(frozen=True)
class _Config:
    """What one call renders with: the image size S (pixels), the checked parameters
    and, when the Function is handed world points, the camera that projects them
    (None: the points are projected already, (x_ndc, y_ndc, depth))."""

    size: int
    params: SoftParams
    camera: "Camera | None" = None


_SCRATCH = threading.local()


def _scratch(name: str, size: int, dtype: np.dtype) -> np.ndarray:
    """A buffer of at least ``size`` elements of ``dtype``, this thread's own, reused
    from call to call (grown when too small), for what one backward call uses and
    drops: fresh multi-MiB arrays would come back from the allocator as new pages
    every call, a page fault per 4 KiB (about 2 ms per iteration). Not zeroed."""
    bufs = getattr(_SCRATCH, "bufs", None)
    if bufs is None:
        bufs = _SCRATCH.bufs = {}
    key = (name, np.dtype(dtype).str)
    buf = bufs.get(key)
    if buf is None or buf.shape[0] < size:
        buf = bufs[key] = np.empty(size, dtype)
    return buf


def scratch_nbytes() -> int:
    """Bytes this thread's reused backward buffers (:func:`_scratch`) hold now."""
    return sum(b.nbytes for b in getattr(_SCRATCH, "bufs", {}).values())


def _numpy(t: "torch.Tensor") -> np.ndarray:
    return t.detach().contiguous().numpy()


def _make_function():  # type: ignore[no-untyped-def]
    import torch
    from torch.autograd.function import once_differentiable

    class SoftRasterizeNumba(torch.autograd.Function):
        """Autograd wrapper of the kernels: (projected vertices, colours) -> (image, alpha)."""

        @staticmethod
        def forward(ctx, points, colors, faces, cfg):  # type: ignore[no-untyped-def]
            a_proj, a_col, a_faces = _numpy(points), _numpy(colors), _numpy(faces)
            dtype = a_proj.dtype
            ctx.view = None
            if cfg.camera is not None:
                # torch's projection (the same float rounding as the torch backend's,
                # which float32 coverage near an edge amplifies), without autograd:
                # its chain rule is one numba loop, not a dozen small autograd ops
                cam = cfg.camera
                a_proj = _numpy(cam.project_torch(points))
                ctx.view = (np.ascontiguousarray(cam.axes(), dtype=dtype), dtype.type(cam.tan_angle))
            cxy, inv, iz, det = _face_setup(a_proj, a_faces, DET_EPS)
            s = cfg.size
            bins = make_bins(cxy, s, math.sqrt(cfg.params.threshold))
            K = soft_kernels.kernel_constants(cfg.params, dtype)
            image = np.empty((s, s, 3), dtype)
            alpha = np.empty((s, s), dtype)
            n_state = bins.py_tab.shape[0] * bins.wp
            st_m = np.empty(n_state, dtype)
            st_s = np.empty(n_state, dtype)
            st_p = np.empty(n_state, dtype)
            row_lo = np.empty(bins.row_start[-1], np.int32)
            row_hi = np.empty(bins.row_start[-1], np.int32)
            with one_tile_chunks():
                soft_kernels.forward(
                    bins.order, bins.n_tx, s, bins.wp, bins.tile_start, bins.tile_entry, bins.entry_face,
                    bins.row_start, bins.box, cxy, inv, iz, a_col, bins.px_tab, bins.py_tab, K,
                    image, alpha, st_m, st_s, st_p, row_lo, row_hi,
                )
            ctx.cfg = cfg
            ctx.torch_dtype = points.dtype
            ctx.n_vertices = a_proj.shape[0]
            ctx.arrays = (
                a_faces, a_proj, cxy, inv, iz, det, a_col, K, bins, image, st_m, st_s, st_p, row_lo, row_hi
            )
            return torch.from_numpy(image), torch.from_numpy(alpha)

        @staticmethod
        @once_differentiable
        def backward(ctx, g_image, g_alpha):  # type: ignore[no-untyped-def]
            a_faces, a_proj, cxy, inv, iz, det, a_col, K, bins, image, st_m, st_s, st_p, row_lo, row_hi = ctx.arrays
            cfg = ctx.cfg
            dtype = cxy.dtype
            gi = np.zeros_like(image) if g_image is None else _numpy(g_image.to(ctx.torch_dtype))
            ga = np.zeros(image.shape[:2], dtype) if g_alpha is None else _numpy(g_alpha.to(ctx.torch_dtype))
            n_entries = bins.tile_entry.shape[0]
            grad = _scratch("grad", n_entries * N_GRAD, dtype)[:n_entries * N_GRAD].reshape(n_entries, N_GRAD)
            buf = _scratch("bst", soft_kernels.backward_state_size(st_m.shape[0] // bins.wp, bins.wp), dtype)
            with one_tile_chunks():
                bst, wq = soft_kernels.backward_state(image, gi, ga, st_m, st_s, st_p, bins.wp, K, buf)
                soft_kernels.backward(
                    bins.order, bins.n_tx, cfg.size, bins.wp, bins.tile_start, bins.tile_entry, bins.entry_face,
                    bins.row_start, bins.box, cxy, inv, iz, a_col, bins.px_tab, bins.py_tab, K,
                    bst, wq, row_lo, row_hi, grad,
                )
            n_faces = cxy.shape[0]
            g_corner = np.empty((n_faces, 9), dtype)
            g_col = np.empty((n_faces, 3), dtype)
            _face_grads(grad, bins.face_start, cxy, inv, iz, det, DET_EPS, g_corner, g_col)
            g_proj = None
            if ctx.needs_input_grad[0]:
                g = _scatter_vertices(g_corner, a_faces, ctx.n_vertices)
                if ctx.view is not None:
                    g = _project_grad(a_proj, g, *ctx.view)
                g_proj = torch.from_numpy(g)
            g_colors = torch.from_numpy(g_col) if ctx.needs_input_grad[1] else None
            return g_proj, g_colors, None, None

    return SoftRasterizeNumba


_FUNCTION = None


def _function():  # type: ignore[no-untyped-def]
    global _FUNCTION
    if _FUNCTION is None:
        _FUNCTION = _make_function()
    return _FUNCTION


def soft_rasterize_numba(
    vertices: "torch.Tensor", faces: "torch.Tensor", face_colors: "torch.Tensor", camera: "Camera", params: SoftParams
) -> "tuple[torch.Tensor, torch.Tensor]":
    """The numba backend of :func:`saucerfab.render.soft_rasterize` (arguments checked there).

    Args:
        vertices: World positions, shape [V, 3], model units, CPU.
        faces: Vertex indices, shape [F, 3], int64.
        face_colors: RGB per face, shape [F, 3], same dtype as ``vertices``.
        camera: The view (S = ``camera.image_size``).
        params: The checked scalar parameters (plain floats).

    Returns:
        ``(image, alpha)``: shapes [S, S, 3] and [S, S], ``vertices.dtype``.
    """
    return _function().apply(vertices, face_colors, faces, _Config(camera.image_size, params, camera))
