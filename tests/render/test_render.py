"""soft_rasterize: agreement with the dense SoftRas reference, gradcheck, golden images, dispatch."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from render_reference import soft_rasterize_reference

from saucerfab.errors import ConfigError
from saucerfab.model.scene import Scene
from saucerfab.render import Camera, soft_rasterize

BACKENDS = ["torch", "numba"]

#: camera on -y looking at the origin with tan(angle) = 0.2: a world point
#: (X, Y, Z) has depth Y + 5 and NDC (X, Z) / (0.2 (Y + 5)); at Y = 0 NDC = (X, Z)
TAN = 0.2


def ndc_camera(size: int) -> Camera:
    return Camera((0.0, -5.0, 0.0), (0.0, 0.0, 0.0), math.degrees(math.atan(TAN)), size)


def world_from_ndc(ndc: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
    """(..., 2) NDC and (...,) depth -> (..., 3) world points of :func:`ndc_camera`."""
    s = depth * TAN
    return torch.stack([ndc[..., 0] * s, depth - 5.0, ndc[..., 1] * s], dim=-1)


def random_scene(n_faces: int, seed: int, spread: float = 1.2):
    """Separate random triangles (corners up to ``spread`` in NDC, so some cross the
    border), at depths 5..5.3 with a small tilt; float64."""
    g = torch.Generator().manual_seed(seed)
    ndc = (torch.rand(n_faces, 3, 2, generator=g, dtype=torch.float64) * 2 - 1) * spread
    depth = 5 + 0.3 * torch.rand(n_faces, 1, generator=g, dtype=torch.float64)
    depth = depth + 0.05 * torch.rand(n_faces, 3, generator=g, dtype=torch.float64)
    v = world_from_ndc(ndc, depth).reshape(-1, 3)
    f = torch.arange(3 * n_faces).reshape(n_faces, 3)
    c = torch.rand(n_faces, 3, generator=g, dtype=torch.float64)
    return v, f, c


def occlusion_scene():
    """A small near triangle in front of a large far one, plus one crossing the border."""
    ndc = torch.tensor(
        [
            [[-0.8, -0.7], [0.75, -0.6], [0.1, 0.8]],  # far, large
            [[-0.3, -0.25], [0.35, -0.3], [0.05, 0.4]],  # near, inside the far one
            [[0.6, 0.5], [1.4, 0.7], [0.8, 1.3]],  # crosses the top-right corner
        ],
        dtype=torch.float64,
    )
    depth = torch.tensor([[5.3, 5.32, 5.28], [5.0, 5.01, 4.99], [5.1, 5.1, 5.12]], dtype=torch.float64)
    v = world_from_ndc(ndc, depth).reshape(-1, 3)
    f = torch.arange(9).reshape(3, 3)
    c = torch.tensor([[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.2, 0.3, 0.9]], dtype=torch.float64)
    return v, f, c


SETTINGS = [
    dict(sigma=3e-3, gamma=1e-3, background=(0.2, 0.5, 0.9)),  # wide coverage, soft depth
    dict(sigma=2e-4, gamma=1e-4, background=(0.0, 0.0, 0.0)),  # SoftRas default gamma
    # far just behind the faces (depths 5..5.35): normalized inverse depths near eps,
    # so the background weight exp((2 eps - m)/gamma) competes with the faces, and
    # parts of faces beyond far leave the colour but not alpha
    dict(sigma=1e-3, gamma=1e-2, eps=1e-2, near=4.9, far=5.3, background=(0.3, 0.6, 0.1)),
]


def _loss_grads(fn, v, f, c, cam, kw, seed=0):
    v = v.clone().requires_grad_(True)
    c = c.clone().requires_grad_(True)
    image, alpha = fn(v, f, c, cam, **kw)
    g = torch.Generator().manual_seed(seed)  # CPU weights, the same for every device
    wi = torch.rand(image.shape, generator=g, dtype=image.dtype).to(image.device)
    wa = torch.rand(alpha.shape, generator=g, dtype=alpha.dtype).to(alpha.device)
    gv, gc = torch.autograd.grad((image * wi).sum() + (alpha * wa).sum(), (v, c))
    return image.detach().cpu(), alpha.detach().cpu(), gv.cpu(), gc.cpu()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("setting", range(len(SETTINGS)))
@pytest.mark.parametrize("scene", ["random", "occlusion"])
def test_matches_dense_reference(backend: str, setting: int, scene: str) -> None:
    kw = SETTINGS[setting]
    v, f, c = random_scene(12, seed=setting) if scene == "random" else occlusion_scene()
    cam = ndc_camera(16)
    ref = _loss_grads(soft_rasterize_reference, v, f, c, cam, kw)
    out = _loss_grads(lambda *a, **k: soft_rasterize(*a, backend=backend, **k), v, f, c, cam, kw)
    assert ref[1].max() > 0.99 and ref[1].min() < 0.01  # the scene covers and misses pixels
    for r, o in zip(ref, out):
        scale = max(1.0, float(r.abs().max()))
        np.testing.assert_allclose(o.numpy(), r.numpy(), rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("scene", ["random", "occlusion"])
def test_gradcheck(backend: str, scene: str) -> None:
    v, f, c = random_scene(5, seed=7) if scene == "random" else occlusion_scene()
    cam = ndc_camera(12)
    kw = SETTINGS[0]

    def fn(v: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return soft_rasterize(v, f, c, cam, backend=backend, **kw)

    v.requires_grad_(True)
    c.requires_grad_(True)
    assert torch.autograd.gradcheck(fn, (v, c), eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)


@pytest.mark.parametrize("backend", BACKENDS)
def test_occlusion_front_face_wins(backend: str) -> None:
    v, f, c = occlusion_scene()
    image, alpha = soft_rasterize(v, f, c, ndc_camera(32), sigma=1e-5, backend=backend)
    # pixel at NDC (0.05, 0.0): inside both the near (green) and far (red) faces
    j = round(((0.05 + 1) * 32 - 1) / 2)
    i = round(((1 - 0.0) * 32 - 1) / 2)
    np.testing.assert_allclose(image[i, j].numpy(), c[1].numpy(), atol=1e-6)
    assert float(alpha[i, j]) == pytest.approx(1.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_golden_triangle_pixel_centres_and_axes(backend: str) -> None:
    """World (-1, 0, 1), (0, 0, 1), (-1, 0, 0) is NDC (-1, 1), (0, 1), (-1, 0): the
    top-left half of the top-left quadrant. With S = 8 pixel (i, j) has its centre
    at x = (2j + 1)/8 - 1, y = 1 - (2i + 1)/8, inside iff i + j < 3, exactly on
    the hypotenuse iff i + j = 3 (coverage sigmoid(0) = 1/2)."""
    v = torch.tensor([[-1.0, 0.0, 1.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]], dtype=torch.float64)
    expected = np.zeros((8, 8))
    for i in range(8):
        for j in range(8):
            if i + j < 3:
                expected[i, j] = 1.0
            elif i + j == 3:
                expected[i, j] = 0.5
    for winding in ([0, 1, 2], [0, 2, 1]):  # no back-face culling
        f = torch.tensor([winding])
        c = torch.tensor([[1.0, 0.5, 0.25]], dtype=torch.float64)
        image, alpha = soft_rasterize(v, f, c, ndc_camera(8), sigma=1e-7, backend=backend)
        np.testing.assert_allclose(alpha.numpy(), expected, atol=1e-6)
        lit = expected > 0
        np.testing.assert_allclose(image.numpy()[lit], np.tile([1.0, 0.5, 0.25], (lit.sum(), 1)), atol=1e-9)
        np.testing.assert_allclose(image.numpy()[~lit], 0.0, atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_paper_camera_orientation(backend: str) -> None:
    """In the paper's direct view a world +x patch is on the right, a +z one at the top."""
    cam = Camera.from_scene(Scene(), "direct").with_size(64)

    def patch(cx: float, cy: float, cz: float) -> torch.Tensor:
        return torch.tensor([[cx - 0.05, cy - 0.05, cz], [cx + 0.05, cy - 0.05, cz], [cx, cy + 0.05, cz]])

    v = torch.cat([patch(0.3, -1.0, 0.0), patch(-0.3, -1.0, 0.0), patch(0.0, -1.0, 0.5)]).double()
    f = torch.arange(9).reshape(3, 3)
    c = torch.eye(3, dtype=torch.float64)  # red at +x, green at -x, blue up high
    image, _ = soft_rasterize(v, f, c, cam, backend=backend)
    rows, cols = [], []
    for k in range(3):
        ii, jj = np.nonzero(image[..., k].numpy() > 0.5)
        assert ii.size > 0
        rows.append(ii.mean())
        cols.append(jj.mean())
    assert cols[0] > 32 > cols[1]  # +x right of the centre, -x left
    assert rows[2] < rows[0] and rows[2] < rows[1]  # higher z is higher in the image


@pytest.mark.parametrize("backend", BACKENDS)
def test_background_and_float32(backend: str) -> None:
    v, f, c = random_scene(6, seed=3, spread=0.5)
    cam = ndc_camera(16)
    i64, a64 = soft_rasterize(v, f, c, cam, sigma=1e-4, background=(0.1, 0.2, 0.3), backend=backend)
    i32, a32 = soft_rasterize(v.float(), f, c.float(), cam, sigma=1e-4, background=(0.1, 0.2, 0.3), backend=backend)
    assert i32.dtype == torch.float32 and a32.dtype == torch.float32
    assert i32.shape == (16, 16, 3) and a32.shape == (16, 16)
    np.testing.assert_allclose(i32.numpy(), i64.numpy(), atol=2e-3)
    np.testing.assert_allclose(a32.numpy(), a64.numpy(), atol=1e-4)
    empty = a64.numpy() == 0
    assert empty.any()
    np.testing.assert_allclose(i64.numpy()[empty], np.tile([0.1, 0.2, 0.3], (empty.sum(), 1)))


def test_auto_dispatch_uses_numba_on_cpu(monkeypatch: pytest.MonkeyPatch) -> None:
    import saucerfab.render.soft_numba as sn

    calls = []
    real = sn.soft_rasterize_numba

    def spy(*a, **k):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(sn, "soft_rasterize_numba", spy)
    v, f, c = random_scene(2, seed=1)
    soft_rasterize(v, f, c, ndc_camera(8))
    assert calls == [1]


def test_dispatch_by_device() -> None:
    """"auto" takes the numba kernels on the CPU and the torch backend (the GPU path)
    elsewhere; the choice needs no CUDA device to test."""
    from saucerfab.render.soft import select_backend

    assert select_backend("auto", torch.device("cpu")) == "numba"
    assert select_backend("auto", torch.device("cuda", 0)) == "torch"
    assert select_backend("torch", torch.device("cpu")) == "torch"
    assert select_backend("torch", torch.device("cuda")) == "torch"
    with pytest.raises(ConfigError, match="CPU"):
        select_backend("numba", torch.device("cuda"))
    # forcing the torch backend on CPU tensors runs the code that CUDA tensors get
    v, f, c = random_scene(3, seed=2)
    a = soft_rasterize(v, f, c, ndc_camera(8), backend="torch")
    b = soft_rasterize(v, f, c, ndc_camera(8), backend="numba")
    np.testing.assert_allclose(a[0].numpy(), b[0].numpy(), atol=1e-12)


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_gpu_dispatch_matches_cpu() -> None:
    v, f, c = random_scene(8, seed=4)
    cam = ndc_camera(16)
    kw = SETTINGS[1]
    cpu = _loss_grads(lambda *a, **k: soft_rasterize(*a, backend="numba", **k), v, f, c, cam, kw)
    gpu = _loss_grads(soft_rasterize, v.cuda(), f.cuda(), c.cuda(), cam, kw)  # "auto": the torch backend
    for r, o in zip(cpu, gpu):
        np.testing.assert_allclose(o.numpy(), r.numpy(), atol=1e-9 * max(1.0, float(r.abs().max())))
    with pytest.raises(ConfigError, match="CPU"):
        soft_rasterize(v.cuda(), f.cuda(), c.cuda(), cam, backend="numba")


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(vertices=torch.zeros(3, 2)), "vertices"),
        (dict(vertices=torch.zeros(3, 3, dtype=torch.float16)), "float32 or float64"),
        (dict(faces=torch.tensor([[0, 1, 5]])), "index"),
        (dict(faces=torch.zeros(1, 3)), "integer"),
        (dict(face_colors=torch.zeros(2, 3)), "face_colors"),
        (dict(sigma=0.0), "sigma"),
        (dict(gamma=-1.0), "gamma"),
        (dict(dist_eps=0.7), "dist_eps"),
        (dict(near=5.0, far=1.0), "near"),
        (dict(backend="cuda"), "backend"),
    ],
)
def test_bad_arguments(change: dict, match: str) -> None:
    args = dict(
        vertices=torch.zeros(3, 3),
        faces=torch.tensor([[0, 1, 2]]),
        face_colors=torch.zeros(1, 3),
        camera=ndc_camera(8),
    )
    args.update({k: v for k, v in change.items() if k in args})
    kw = {k: v for k, v in change.items() if k not in args}
    with pytest.raises(ConfigError, match=match):
        soft_rasterize(**args, **kw)  # type: ignore[arg-type]


def test_sliver_face_gives_finite_gradients() -> None:
    """A near-degenerate face (det -1.1e-8 in NDC, float32): its barycentric matrix
    has entries near 1e6, and for pixels in its influence range the clipped float32
    barycentrics can all be 0, so the depth is inf there. Such pixels are masked out
    of the colour; the backward must not turn 0 * inf into NaN. The corners are the
    projected ones (x, y in NDC, depth) of the face where a full-size design met
    it: three NaN heights stopped the stage at once."""
    from saucerfab.render.soft_common import SoftParams
    from saucerfab.render.soft_numba import _Config, _function

    proj64 = torch.tensor(
        [[0.6611913, -0.7917993, 7.4207783], [0.6698888, -0.7778158, 7.423933], [0.67737514, -0.76578087, 7.414729]],
        dtype=torch.float32,
    ).double()
    f = torch.tensor([[0, 1, 2]])
    cfg = _Config(512, SoftParams(1e-5, 1e-4, (1.0, 1.0, 1.0), 1.0, 100.0, 1e-3, 1e-4))
    grads = {}
    for dtype in (torch.float32, torch.float64):
        proj = proj64.to(dtype).requires_grad_(True)
        col = torch.full((1, 3), 0.3, dtype=dtype, requires_grad=True)
        image, alpha = _function().apply(proj, col, f, cfg)
        ((image - 0.8) ** 2).sum().add((alpha**2).sum()).backward()
        assert torch.isfinite(image).all() and torch.isfinite(alpha).all(), dtype
        assert torch.isfinite(proj.grad).all() and torch.isfinite(col.grad).all(), dtype
        grads[dtype] = proj.grad.double()
    # float32 against float64 on the x, y gradients (the depth's is ~0 here)
    scale = grads[torch.float64][:, :2].abs().max()
    assert (grads[torch.float32][:, :2] - grads[torch.float64][:, :2]).abs().max() <= 0.05 * scale
