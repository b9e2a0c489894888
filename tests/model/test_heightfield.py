"""Tests of saucerfab.model.heightfield: base shapes, loading, resampling, mesh, Laplacian."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from PIL import Image

from saucerfab.errors import ShapeError
from saucerfab.model.heightfield import (
    BASE_SHAPES,
    MAX_SHAPE_PIXELS,
    base_shape,
    face_normals,
    laplacian,
    load_shape,
    make_grid,
    resample,
    triangulate,
    vertex_neighbours,
)
from saucerfab.model.scene import Saucer

# --------------------------------------------------------------------------- grid and shapes


def test_grid_order() -> None:
    grid = make_grid(Saucer(resolution=5))
    assert grid.n == 5
    np.testing.assert_allclose(grid.xs, np.linspace(-0.5, 0.5, 5))
    np.testing.assert_allclose(grid.ys, np.linspace(-1.5, -0.5, 5))
    assert grid.spacing == pytest.approx((0.25, 0.25))
    xy = grid.xy()
    i, j = 3, 1
    np.testing.assert_allclose(xy[i * 5 + j], [grid.xs[j], grid.ys[i]])
    h = np.arange(25.0).reshape(5, 5)
    v = grid.vertices(h)
    assert v.shape == (25, 3)
    assert v[i * 5 + j, 2] == h[i, j]


@pytest.mark.parametrize("name", sorted(BASE_SHAPES))
def test_base_shapes_are_sane(name: str) -> None:
    h = base_shape(name, 33, seed=1)
    assert h.shape == (33, 33) and h.dtype == np.float64
    assert np.isfinite(h).all()
    assert h.min() >= -1e-12  # the lowest point sits on the base plane
    assert h.max() <= 0.2  # a few times delta, not a mountain
    if name != "plane":
        assert h.max() - h.min() > 0.01  # it has relief
    np.testing.assert_array_equal(h, base_shape(name, 33, seed=1))  # deterministic


def test_shape_specifics() -> None:
    assert not base_shape("plane", 9).any()
    waves = base_shape("waves", 25)
    # ridges run along x: every row (fixed y) is constant
    np.testing.assert_allclose(waves, waves[:, :1].repeat(25, axis=1))
    saw = base_shape("tabula_scalata", 61)
    assert (np.diff(saw[:, 0]) < 0).sum() >= 5  # the sawtooth's drops
    bowl = base_shape("bowl", 21)
    assert bowl[10, 10] == bowl.min() and bowl[0, 0] == bowl.max()
    a, b = base_shape("smooth_random", 20, seed=1), base_shape("smooth_random", 20, seed=2)
    assert not np.allclose(a, b)  # the seed matters
    assert base_shape("smooth_random", 20, seed=1).max() == pytest.approx(0.1)
    # names are forgiving about case and dashes
    np.testing.assert_array_equal(base_shape("Tabula-Scalata", 8), base_shape("tabula_scalata", 8))


def test_unknown_shape_name() -> None:
    with pytest.raises(ShapeError, match="unknown base shape 'volcano'.*waves"):
        base_shape("volcano", 8)
    with pytest.raises(ShapeError, match="unknown base shape"):
        load_shape("volcano", 8)


# --------------------------------------------------------------------------- resampling and loading


def test_resample() -> None:
    rng = np.random.default_rng(0)
    h = rng.uniform(size=(7, 7))
    same = resample(h, 7)
    np.testing.assert_array_equal(same, h)
    assert same is not h
    # bilinear resampling reproduces a bilinear function exactly, corners aligned
    r, c = np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 9), indexing="ij")
    f = 0.2 + 0.3 * r - 0.7 * c + 0.5 * r * c  # (5, 9)
    out = resample(f, 13)
    rr, cc = np.meshgrid(np.linspace(0, 1, 13), np.linspace(0, 1, 13), indexing="ij")
    np.testing.assert_allclose(out, 0.2 + 0.3 * rr - 0.7 * cc + 0.5 * rr * cc, atol=1e-12)
    down = resample(h, 4)
    assert down[0, 0] == h[0, 0] and down[-1, -1] == h[-1, -1]


def _png(path: Path, arr: np.ndarray) -> Path:
    """Write ``arr`` (uint8 gray or RGB, or uint16 gray) as a PNG file."""
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    path.write_bytes(buf.getvalue())
    return path


def test_load_png_8_bit(tmp_path: Path) -> None:
    img = np.array([[255, 255, 255], [128, 128, 128], [0, 0, 0]], dtype=np.uint8)  # white at the top
    h = load_shape(_png(tmp_path / "s.png", img), 3, height_scale=0.2)
    # image row 0 (top) is the far edge of the saucer: the last grid row
    np.testing.assert_allclose(h[:, 0], [0.0, 0.2 * 128 / 255, 0.2])
    assert (h == h[:, :1]).all()
    rgb = np.stack([img] * 3, axis=-1)
    np.testing.assert_allclose(load_shape(_png(tmp_path / "rgb.png", rgb), 3, height_scale=0.2), h)


def test_load_png_16_bit_and_resampling(tmp_path: Path) -> None:
    img = np.array([[65535, 0], [0, 32768]], dtype=np.uint16)
    path = _png(tmp_path / "s16.PNG", img)
    with Image.open(path) as im:
        assert im.mode.startswith("I")  # really a 16-bit file
    h = load_shape(path, 2, height_scale=0.1)
    np.testing.assert_allclose(h, [[0.0, 0.1 * 32768 / 65535], [0.1, 0.0]])
    big = load_shape(path, 5, height_scale=0.1)
    assert big.shape == (5, 5)
    np.testing.assert_allclose(big[[0, 0, -1, -1], [0, -1, 0, -1]], [0.0, 0.1 * 32768 / 65535, 0.1, 0.0])
    np.testing.assert_allclose(big[2, 2], np.mean([0.0, 0.1 * 32768 / 65535, 0.1, 0.0]))


def test_load_npy(tmp_path: Path) -> None:
    arr = np.linspace(0, 1, 12).reshape(3, 4)
    np.save(tmp_path / "a.npy", arr)
    h = load_shape(tmp_path / "a.npy", 3, height_scale=0.5)
    assert h.shape == (3, 3)
    np.testing.assert_allclose(h[:, 0], arr[:, 0] * 0.5)  # .npy rows are grid rows: no flip
    np.testing.assert_allclose(h[:, -1], arr[:, -1] * 0.5)
    np.save(tmp_path / "i.npy", np.arange(16, dtype=np.int16).reshape(4, 4))
    np.testing.assert_allclose(load_shape(tmp_path / "i.npy", 4, height_scale=1.0), np.arange(16).reshape(4, 4))
    # a name still reaches the built-ins
    np.testing.assert_array_equal(load_shape("waves", 6), base_shape("waves", 6))


def test_bad_shape_files(tmp_path: Path) -> None:
    with pytest.raises(ShapeError, match="not found"):
        load_shape(tmp_path / "missing.png", 8)
    (tmp_path / "fake.png").write_text("not an image")
    with pytest.raises(ShapeError, match="cannot read shape image"):
        load_shape(tmp_path / "fake.png", 8)
    good = io.BytesIO()
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8)).save(good, "PNG")
    (tmp_path / "cut.png").write_bytes(good.getvalue()[:200])
    with pytest.raises(ShapeError, match="cannot read shape image"):
        load_shape(tmp_path / "cut.png", 8)
    np.save(tmp_path / "three.npy", np.zeros((2, 2, 2)))
    with pytest.raises(ShapeError, match="2-D array"):
        load_shape(tmp_path / "three.npy", 8)
    np.save(tmp_path / "str.npy", np.array([["a", "b"], ["c", "d"]]))
    with pytest.raises(ShapeError, match="numeric"):
        load_shape(tmp_path / "str.npy", 8)
    nan = np.zeros((3, 3))
    nan[1, 1] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    with pytest.raises(ShapeError, match="1 NaN"):
        load_shape(tmp_path / "nan.npy", 8)
    np.save(tmp_path / "thin.npy", np.zeros((1, 5)))
    with pytest.raises(ShapeError, match="at least 2x2"):
        load_shape(tmp_path / "thin.npy", 8)
    (tmp_path / "junk.npy").write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(ShapeError, match="not a valid .npy"):
        load_shape(tmp_path / "junk.npy", 8)
    # a header claiming a huge array is refused before any data is read
    huge = io.BytesIO()
    np.lib.format.write_array_header_1_0(huge, {"descr": "<f8", "fortran_order": False, "shape": (5000, 5000)})
    (tmp_path / "huge.npy").write_bytes(huge.getvalue())
    with pytest.raises(ShapeError, match="limit"):
        load_shape(tmp_path / "huge.npy", 8)
    # truncated data behind a valid header
    cut = io.BytesIO()
    np.save(cut, np.zeros((10, 10)))
    (tmp_path / "cut.npy").write_bytes(cut.getvalue()[:-40])
    with pytest.raises(ShapeError, match="cannot read shape file"):
        load_shape(tmp_path / "cut.npy", 8)
    (tmp_path / "shape.txt").write_text("0 1\n1 0\n")
    with pytest.raises(ShapeError, match="must be a .png or .npy"):
        load_shape(tmp_path / "shape.txt", 8)
    np.save(tmp_path / "ok.npy", np.zeros((3, 3)))
    with pytest.raises(ShapeError, match="height_scale"):
        load_shape(tmp_path / "ok.npy", 8, height_scale=0.0)


def test_oversized_png_is_refused(tmp_path: Path) -> None:
    side = int(np.sqrt(MAX_SHAPE_PIXELS)) + 4
    buf = io.BytesIO()
    Image.new("L", (side, side)).save(buf, format="PNG")
    (tmp_path / "big.png").write_bytes(buf.getvalue())
    # refused from the header alone (Pillow may or may not warn first, by its own limit)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        with pytest.raises(ShapeError, match="limit"):
            load_shape(tmp_path / "big.png", 8)


# --------------------------------------------------------------------------- mesh


def test_triangulation_counts_and_orientation() -> None:
    assert triangulate(150).shape == (44402, 3)  # the paper's face count
    n = 7
    faces = triangulate(n)
    assert faces.shape == (2 * (n - 1) ** 2, 3) and faces.dtype == np.int64
    assert faces.min() == 0 and faces.max() == n * n - 1
    assert len({tuple(sorted(f)) for f in faces.tolist()}) == len(faces)  # no duplicates
    grid = make_grid(Saucer(resolution=n))
    flat = face_normals(grid.vertices(np.zeros((n, n))), faces)
    np.testing.assert_allclose(flat, np.tile([0.0, 0.0, 1.0], (len(faces), 1)), atol=1e-15)
    wavy = face_normals(grid.vertices(base_shape("waves", n)), faces)
    np.testing.assert_allclose(np.linalg.norm(wavy, axis=1), 1.0)
    assert (wavy[:, 2] > 0).all()
    # consistent orientation: every interior edge is used once in each direction
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    as_set = {tuple(e) for e in directed.tolist()}
    assert len(as_set) == len(directed)  # no directed edge twice
    interior = [e for e in as_set if (e[1], e[0]) in as_set]
    undirected = {tuple(sorted(e)) for e in as_set}
    boundary = len(undirected) - len(interior) // 2
    assert boundary == 4 * (n - 1)  # only the border edges are unpaired


def test_vertex_neighbours() -> None:
    n = 5
    nb = vertex_neighbours(n)
    assert len(nb) == n * n
    centre = 2 * n + 2
    assert sorted(nb[centre].tolist()) == sorted(
        [centre - 1, centre + 1, centre - n, centre + n, centre - n - 1, centre + n + 1]
    )
    assert len(nb[0]) == 3 and len(nb[n - 1]) == 2  # the diagonal runs through corner 0
    for v, ns in enumerate(nb):  # symmetric
        for u in ns:
            assert v in nb[u]


def _laplacian_reference(n: int, h: np.ndarray) -> np.ndarray:
    """h_i minus the mean over the mesh neighbours, by a plain loop."""
    nb = vertex_neighbours(n)
    return np.array([h[i] - h[ns].mean() for i, ns in enumerate(nb)])


def test_laplacian_on_known_functions() -> None:
    n = 9
    L = laplacian(n)
    assert sp.issparse(L) and L.format == "csr" and L.shape == (n * n, n * n)
    grid = make_grid(Saucer(resolution=n))
    x, y = grid.xy().T
    inner = np.zeros((n, n), bool)
    inner[1:-1, 1:-1] = True
    inner = inner.ravel()
    # rows sum to zero: constants map to zero everywhere
    np.testing.assert_allclose(L @ np.ones(n * n), 0.0, atol=1e-14)
    # linear functions vanish at every interior vertex
    lin = 0.3 + 2.0 * x - 1.5 * y
    np.testing.assert_allclose((L @ lin)[inner], 0.0, atol=1e-13)
    # x^2 and y^2: -(2/3) spacing^2 in the interior
    dx, dy = grid.spacing
    np.testing.assert_allclose((L @ x**2)[inner], -(2 / 3) * dx**2, rtol=1e-10)
    np.testing.assert_allclose((L @ y**2)[inner], -(2 / 3) * dy**2, rtol=1e-10)
    # the whole operator, border included, equals the plain-loop definition
    h = np.random.default_rng(1).normal(size=n * n)
    np.testing.assert_allclose(L @ h, _laplacian_reference(n, h), atol=1e-13)
    # diag(degree) L is the symmetric graph Laplacian D - A
    deg = np.array([len(v) for v in vertex_neighbours(n)], dtype=float)
    DL = (sp.diags(deg) @ L).toarray()
    np.testing.assert_allclose(DL, DL.T, atol=1e-13)
    np.testing.assert_allclose(np.diag(DL), deg)
