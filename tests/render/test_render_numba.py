"""The compiled CPU kernels: tiling across many tiles, determinism, float32, building blocks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from saucerfab.model.heightfield import base_shape, make_grid, triangulate
from saucerfab.model.scene import Saucer, Scene
from saucerfab.render import Camera, soft_rasterize
from saucerfab.render.soft_tiles import LANES, TILE_H, TILE_W


def saucer_views(n: int, size: int, dtype: torch.dtype = torch.float64):
    """A small waves saucer in the paper's direct view and, mirrored across y = -0.4
    (flipped winding), in the reflected view; per-face colours."""
    scene = Scene()
    grid = make_grid(Saucer(resolution=n))
    v = torch.as_tensor(grid.vertices(base_shape("waves", n)), dtype=dtype)
    mirrored = v * torch.tensor([1.0, -1.0, 1.0], dtype=dtype) + torch.tensor([0.0, -0.8, 0.0], dtype=dtype)
    f = torch.as_tensor(triangulate(n))
    c = torch.as_tensor(np.random.default_rng(n).random((f.shape[0], 3)), dtype=dtype)
    cams = [Camera.from_scene(scene, k).with_size(size) for k in ("direct", "reflected")]
    return [(v, f, c, cams[0]), (mirrored, f, c, cams[1])]


def _run(v, f, c, cam, backend, **kw):  # type: ignore[no-untyped-def]
    v = v.clone().requires_grad_(True)
    c = c.clone().requires_grad_(True)
    image, alpha = soft_rasterize(v, f, c, cam, backend=backend, **kw)
    g = torch.Generator().manual_seed(5)
    loss = (image * torch.rand(image.shape, generator=g, dtype=image.dtype)).sum() + (
        alpha * torch.rand(alpha.shape, generator=g, dtype=alpha.dtype)
    ).sum()
    gv, gc = torch.autograd.grad(loss, (v, c))
    return [image.detach(), alpha.detach(), gv, gc]


@pytest.mark.parametrize("sigma", [1e-4, 1e-5])
def test_saucer_many_tiles_matches_torch_float64(sigma: float) -> None:
    # 72 px: several tiles each way and a partial last tile (72 is not a multiple of 64 or 16)
    assert 72 % TILE_W and 72 % TILE_H and TILE_W % LANES == 0
    for v, f, c, cam in saucer_views(16, 72):
        ref = _run(v, f, c, cam, "torch", sigma=sigma)
        out = _run(v, f, c, cam, "numba", sigma=sigma)
        assert ref[1].max() > 0.99 and (ref[1] == 0).any()
        for r, o in zip(ref, out):
            np.testing.assert_allclose(o.numpy(), r.numpy(), rtol=0, atol=1e-9 * max(1.0, float(r.abs().max())))


def test_float32() -> None:
    """float32 images match float64 to float32's resolution of the depth softmax
    (zn / gamma: a few 1e-4); gradients match the torch backend's in float32 (the
    float32 gradient itself is ill-conditioned where neighbouring faces meet at a
    pixel centre, for both backends alike)."""
    for v, f, c, cam in saucer_views(12, 64):
        ref64 = _run(v, f, c, cam, "numba", sigma=1e-4)
        ref32 = _run(v.float(), f, c.float(), cam, "torch", sigma=1e-4)
        out = _run(v.float(), f, c.float(), cam, "numba", sigma=1e-4)
        assert all(o.dtype == torch.float32 for o in out)
        np.testing.assert_allclose(out[0].double().numpy(), ref64[0].numpy(), atol=1e-3)
        np.testing.assert_allclose(out[1].double().numpy(), ref64[1].numpy(), atol=5e-5)
        for r, o, tol in zip(ref32, out, (1e-3, 1e-5, 1e-3, 1e-3)):
            np.testing.assert_allclose(o.numpy(), r.numpy(), atol=tol * max(1.0, float(r.abs().max())))


def test_deterministic_across_runs_and_thread_counts() -> None:
    import numba

    v, f, c, cam = saucer_views(14, 80, torch.float32)[0]
    a = _run(v, f, c, cam, "numba", sigma=1e-5)
    b = _run(v, f, c, cam, "numba", sigma=1e-5)
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        d = _run(v, f, c, cam, "numba", sigma=1e-5)
    finally:
        numba.set_num_threads(old)
    for x, y, z in zip(a, b, d):
        assert torch.equal(x, y) and torch.equal(x, z)


def test_no_faces_gives_background_and_zero_gradient() -> None:
    cam = Camera.from_scene(Scene(), "direct").with_size(16)
    v = torch.zeros(3, 3, dtype=torch.float64, requires_grad=True)
    c = torch.zeros(0, 3, dtype=torch.float64, requires_grad=True)
    image, alpha = soft_rasterize(v, torch.zeros(0, 3, dtype=torch.int64), c, cam, background=(0.5, 0.25, 1.0))
    np.testing.assert_array_equal(image.detach().numpy(), np.broadcast_to([0.5, 0.25, 1.0], (16, 16, 3)))
    assert float(alpha.detach().abs().max()) == 0.0
    (image.sum() + alpha.sum()).backward()
    assert float(v.grad.abs().max()) == 0.0


@pytest.mark.parametrize("dtype, lo, rtol", [(np.float32, -87.0, 2e-7), (np.float64, -700.0, 5e-16)])
def test_vexp_accuracy_and_underflow(dtype, lo: float, rtol: float) -> None:  # type: ignore[no-untyped-def]
    from numba import njit

    from saucerfab.render._simd import vexp

    @njit(error_model="numpy")
    def run(x, out):  # type: ignore[no-untyped-def]
        for i in range(x.size):
            out[i] = vexp(x[i])

    x = np.concatenate([np.linspace(lo, 0.0, 200001), [-0.0, -1e-30]]).astype(dtype)
    out = np.empty_like(x)
    run(x, out)
    ref = np.exp(x.astype(np.float64))
    np.testing.assert_allclose(out, ref, rtol=rtol, atol=0)
    far = np.array([-1e4, -np.inf, 2 * lo], dtype)
    run(far, out[:3])
    assert np.all(out[:3] == 0)  # flushed to zero below the normal range, never denormal


def test_ftz_restores_the_control_register() -> None:
    from numba import njit

    from saucerfab.render._simd import _X86, ftz_on, ftz_restore

    @njit
    def probe():  # type: ignore[no-untyped-def]
        old = ftz_on()
        mid = ftz_on()
        ftz_restore(old)
        after = ftz_on()
        ftz_restore(old)
        return old, mid, after

    old, mid, after = probe()
    if _X86:
        assert mid & 0x8040 == 0x8040 and after == old
        assert np.float32(1e-38) * np.float32(1e-3) != 0  # denormals work again in Python


def test_large_faces_across_tiles_match_torch_float64() -> None:
    """Faces many lane groups wide, cut by several tiles each way (150 px: 3 x 5 tiles):
    the kernels pack each (face, tile) entry's rows into runs of several 8-lane groups,
    in the forward and the backward; values and gradients as the torch backend's."""
    from tests.render.test_render import ndc_camera, random_scene

    v, f, c = random_scene(6, seed=3, spread=1.1)
    cam = ndc_camera(150)
    for sigma in (1e-3, 1e-5):
        ref = _run(v, f, c, cam, "torch", sigma=sigma)
        out = _run(v, f, c, cam, "numba", sigma=sigma)
        for r, o in zip(ref, out):
            np.testing.assert_allclose(o.numpy(), r.numpy(), rtol=0, atol=1e-9 * max(1.0, float(r.abs().max())))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_eight_lane_vector_blocks(dtype) -> None:  # type: ignore[no-untyped-def]
    """copy8, fill8, blend8 and nonzero_mask8 against the slices they stand for."""
    from numba import njit

    from saucerfab.render._simd import FIRST_BIT, LAST_BIT, blend8, copy8, fill8, nonzero_mask8

    @njit
    def run(dst, src, n):  # type: ignore[no-untyped-def]
        copy8(dst, 1, src, 5)
        fill8(dst, 12, src[0])
        blend8(dst, 22, src, 2, n)
        m = nonzero_mask8(src, 3, n)
        return m, FIRST_BIT[m], LAST_BIT[m]

    rng = np.random.default_rng(1)
    for n in range(-1, 11):
        src = rng.random(20).astype(dtype)
        src[rng.random(20) < 0.5] = 0
        dst = rng.random(40).astype(dtype)
        want = dst.copy()
        want[1:9] = src[5:13]
        want[12:20] = src[0]
        k = min(max(n, 0), 8)
        want[22:22 + k] = src[2:2 + k]
        m, first, last = run(dst, src, n)
        np.testing.assert_array_equal(dst, want)
        kept = [j for j in range(k) if src[3 + j] != 0]
        assert m == sum(1 << j for j in kept)
        assert (first, last) == ((kept[0], kept[-1]) if kept else (32, -1))
