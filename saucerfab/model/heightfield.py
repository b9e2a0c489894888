"""Heightfield grids over the saucer: base shapes, loading, triangulation, Laplacian.

Grid convention (used everywhere in saucerfab):

* ``heights`` has shape (N, N); ``heights[i, j]`` is the height at
  ``x = xs[j]``, ``y = ys[i]``, with ``xs = linspace(x0, x1, N)`` and
  ``ys = linspace(y0, y1, N)`` (row index along y, column along x).
* Vertex index ``v = i * N + j``; vertices are ``(xs[j], ys[i], heights[i, j])``.
* Each grid cell is split into two triangles along the diagonal from
  (i, j) to (i+1, j+1); faces are counter-clockwise seen from +z, so face
  normals point up. There are ``2 (N-1)^2`` faces (44,402 at N = 150, the
  paper's count).

Heights are in model units. Base shapes are built with z >= 0 (the saucer's
lowest point sits on the base plane) and a modest amplitude; a user shape is
scaled by ``height_scale`` model units per unit of the file's values, and its
heights must then lie within ``MAX_RELIEF_PER_SIZE`` times the saucer's larger
side of zero (:func:`check_height_range`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from saucerfab.errors import ShapeError
from saucerfab.files.imageio import PixelLimitError, npy_header, open_bounded
from saucerfab.model.scene import Saucer

#: the largest shape file we parse (pixels of a PNG / elements of a .npy)
MAX_SHAPE_PIXELS = 4096 * 4096
#: a shape file's heights (after ``height_scale``) must lie within this many
#: times the saucer's larger side of z = 0. Far above any printable relief
#: (at the paper's scale a printer's build volume ends near 2 model units,
#: and the export refuses more), it is there for files in the wrong unit:
#: the design works in float32, which loses a 1/150 grid step beside heights
#: over about 1e5 units and overflows at 3.4e38 (a "starting point must be
#: strictly feasible" or "view axis is vertical" deep in the optimizer).
MAX_RELIEF_PER_SIZE = 100.0
#: model units per unit of a shape file's values (the default of load_shape and
#: of a design's ``height_scale``): the artists' saucers rise a few times the height bound delta
HEIGHT_SCALE = 0.1


@dataclass(frozen=True)
class Grid:
    """The saucer's sample positions.

    Attributes:
        xs: (N,) x coordinate of each column, model units.
        ys: (N,) y coordinate of each row, model units.
    """

    xs: np.ndarray
    ys: np.ndarray

    @property
    def n(self) -> int:
        return int(self.xs.shape[0])

    @property
    def spacing(self) -> tuple[float, float]:
        """(dx, dy) between neighbouring samples, model units."""
        return (float(self.xs[1] - self.xs[0]), float(self.ys[1] - self.ys[0]))

    def xy(self) -> np.ndarray:
        """Vertex xy positions, shape (N*N, 2), in vertex-index order."""
        gx, gy = np.meshgrid(self.xs, self.ys)
        return np.stack([gx.ravel(), gy.ravel()], axis=1)

    def vertices(self, heights: np.ndarray) -> np.ndarray:
        """Vertex positions (N*N, 3) for ``heights`` (N, N)."""
        return np.concatenate([self.xy(), np.asarray(heights, np.float64).reshape(-1, 1)], axis=1)


def make_grid(saucer: Saucer) -> Grid:
    """The grid of ``saucer``: ``resolution`` samples per side over its footprint."""
    n = saucer.resolution
    return Grid(np.linspace(*saucer.x_range, n), np.linspace(*saucer.y_range, n))


# --------------------------------------------------------------------------- base shapes
#
# Each takes unit coordinates u, v in [0, 1] (u along x, v along y) and
# returns heights in model units. Amplitudes are a few times delta, as the
# artists' saucers are: the optimizer may move each vertex by only delta.


def _plane(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.zeros_like(u)


def _waves(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    # The artists' corrugated saucer: ridges running along x, so the viewer
    # (looking along +y) sees their front slopes and the cup their backs.
    return 0.05 * (1.0 - np.cos(2 * np.pi * 6 * v))


def _tabula_scalata(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    # Sawtooth: steep faces towards the viewer, gentle backs (Kircher's tabula scalata).
    return 0.1 * np.mod(6 * v, 1.0)


def _ripples(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    r = np.hypot(u - 0.5, v - 0.5)
    return 0.04 * (1.0 + np.cos(2 * np.pi * 5 * r))


def _bowl(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    r2 = (u - 0.5) ** 2 + (v - 0.5) ** 2
    return 0.3 * r2


def _smooth_random(u: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    # A sum of random low-frequency cosines: smooth, seeded, reproducible.
    h = np.zeros_like(u)
    for _ in range(12):
        fx, fy = rng.uniform(0.5, 4.0, size=2)
        phx, phy = rng.uniform(0, 2 * np.pi, size=2)
        h += rng.uniform(0.3, 1.0) * np.cos(2 * np.pi * fx * u + phx) * np.cos(2 * np.pi * fy * v + phy)
    h -= h.min()
    return 0.1 * h / max(float(h.max()), 1e-12)


BASE_SHAPES: dict[str, Callable[[np.ndarray, np.ndarray, np.random.Generator], np.ndarray]] = {
    "plane": _plane,
    "waves": _waves,
    # the paper's own: six waves 10 units high across the rectangle, whatever RIDGE_DENSITY says
    "paper_waves": _waves,
    "tabula_scalata": _tabula_scalata,
    "ripples": _ripples,
    "bowl": _bowl,
    "smooth_random": _smooth_random,
}


#: the shapes whose ridges run across the line of sight (along x on a rectangle): around the cup on a disc
AROUND_THE_CUP = ("waves", "tabula_scalata")
#: those ridges are this many times as dense and 1 / this as high as the paper's (the same slopes,
#: which part what the eye sees from what the cup sees): a viewer's eyes, beside the design eye, see
#: the relief's parallax across the direct picture in proportion to its height. On the rectangle at
#: 2 (benchmarks/RESULTS.md, "The whole piece and design quality per pair"): from a viewer's eyes
#: +5.5 dB direct on heart-star and astronaut-rocket, for up to 3 dB from the design eye; on a disc
#: (rings) +2.8 to +4.0 dB from those eyes. ``paper_waves`` is the paper's shape as it was.
RIDGE_DENSITY = 2.0
#: ... on a rectangle only where its grid carries them: at least this many vertices a ridge (the
#: default 150 x 150 grid has 12.4 a ridge at RIDGE_DENSITY 2); a coarser grid keeps the paper's six
#: ridges (a quick 64-vertex design would have 5 vertices a ridge). A disc's grid always carries them.
MIN_VERTICES_PER_RIDGE = 10
#: the paper's ridges across its rectangle
PAPER_RIDGES = 6


def shape_coordinates(n: int, saucer: Saucer | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The (u, v) the built-in shapes take on an n x n grid, each (n, n).

    A rectangle: [0, 1] across each side, whatever its size (the paper's).
    A disc: model units from the cup's axis plus 0.5, so the shapes keep the
    paper's ridge spacing in millimetres however large the disc (its 200 mm
    would stretch a rectangle's six waves to twice their width and halve their
    slopes, which part what the eye sees from what the cup sees) and the
    round ones (ripples, bowl) stand centred on the cup.
    """
    if saucer is not None and saucer.is_disc:
        return np.meshgrid(0.5 + np.linspace(*saucer.x_range, n), 0.5 + np.linspace(*saucer.y_range, n))
    return np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))


def ridge_density(n: int) -> float:
    """How many times the paper's ridges the built-in ridged shapes have on an n x n rectangle grid."""
    return RIDGE_DENSITY if n >= MIN_VERTICES_PER_RIDGE * PAPER_RIDGES * RIDGE_DENSITY else 1.0


def base_shape(name: str, n: int, seed: int = 0, saucer: Saucer | None = None) -> np.ndarray:
    """A built-in base shape sampled on an n x n grid of ``saucer`` (:func:`shape_coordinates`), heights (n, n) in model units."""
    key = name.replace("-", "_").lower()
    if key not in BASE_SHAPES:
        raise ShapeError(
            f"unknown base shape {name!r}; built-in shapes are {sorted(BASE_SHAPES)}, "
            "or give a .png or .npy heightfield file"
        )
    u, v = shape_coordinates(n, saucer)
    if key in AROUND_THE_CUP:
        if saucer is not None and saucer.is_disc:
            # ridges across the line of sight on a rectangle are rings around the cup on a disc: v grows
            # towards the cup's axis (as a rectangle's v does towards the cup), so fronts face out, backs
            # the cup; measured from the disc's edge, where every such shape is at its lowest: a crest the
            # edge cut through would leave a fin of material thinner than any printer's wall between it
            # and the part's side
            v = RIDGE_DENSITY * (saucer.radius - np.hypot(u - 0.5, v - 0.5))
            density = RIDGE_DENSITY
        else:  # along the rectangle's depth, from its near edge as the paper's
            density = ridge_density(n)
            v = density * v
        return BASE_SHAPES[key](u, v, np.random.default_rng(seed)).astype(np.float64) / density
    return BASE_SHAPES[key](u, v, np.random.default_rng(seed)).astype(np.float64)


# --------------------------------------------------------------------------- loading


def resample(heights: np.ndarray, n: int) -> np.ndarray:
    """Bilinear resampling of a (H, W) heightfield to (n, n), corners aligned."""
    h = np.asarray(heights, dtype=np.float64)
    rows, cols = h.shape
    if (rows, cols) == (n, n):
        return h.copy()
    yi = np.linspace(0, rows - 1, n)
    xi = np.linspace(0, cols - 1, n)
    y0 = np.clip(np.floor(yi).astype(int), 0, max(rows - 2, 0))
    x0 = np.clip(np.floor(xi).astype(int), 0, max(cols - 2, 0))
    y1 = np.minimum(y0 + 1, rows - 1)
    x1 = np.minimum(x0 + 1, cols - 1)
    ty = (yi - y0)[:, None]
    tx = (xi - x0)[None, :]
    top = h[np.ix_(y0, x0)] * (1 - tx) + h[np.ix_(y0, x1)] * tx
    bot = h[np.ix_(y1, x0)] * (1 - tx) + h[np.ix_(y1, x1)] * tx
    return top * (1 - ty) + bot * ty


def _load_png(path: Path) -> np.ndarray:
    """(H, W) float64 heights in [0, 1] of an 8/16-bit PNG (white = 1), row 0 at the near edge (smallest y)."""
    from PIL import Image

    try:
        with open_bounded(path, ("PNG",), MAX_SHAPE_PIXELS) as im:
            mode = im.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):
                arr = np.asarray(im, dtype=np.float64)
                full = 65535.0
            elif mode in ("L", "LA", "P", "RGB", "RGBA", "1"):
                arr = np.asarray(im.convert("L"), dtype=np.float64)
                full = 255.0
            else:
                raise ShapeError(
                    f"shape image {str(path)!r} has mode {mode}; use 8- or 16-bit grayscale PNG"
                )
    except PixelLimitError as exc:
        raise ShapeError(
            f"shape image {str(path)!r} is {exc.width}x{exc.height}; the limit is "
            f"{MAX_SHAPE_PIXELS} pixels. Downscale it first."
        ) from None
    except (OSError, Image.DecompressionBombError, SyntaxError) as exc:
        raise ShapeError(f"cannot read shape image {str(path)!r}: {exc}") from None
    # Image rows run top to bottom; our rows run along +y. Row 0 of the image
    # is the far edge of the saucer (largest y), as on a map seen from above.
    return arr[::-1] / full


def _load_npy(path: Path) -> np.ndarray:
    """(H, W) float64 values of a 2-D numeric ``.npy`` file, its size checked from the header."""
    try:
        shape, dtype = npy_header(path)
    except (ValueError, OSError) as exc:
        raise ShapeError(f"{str(path)!r} is not a valid .npy file: {exc}") from None
    if len(shape) != 2:
        raise ShapeError(f"shape file {str(path)!r} must hold a 2-D array, got shape {shape}")
    if int(np.prod(shape)) > MAX_SHAPE_PIXELS:
        raise ShapeError(f"shape file {str(path)!r} has {shape} samples; the limit is {MAX_SHAPE_PIXELS}")
    if dtype.kind not in "fiu":
        raise ShapeError(f"shape file {str(path)!r} has dtype {dtype}; use a numeric array")
    try:
        return np.load(path, allow_pickle=False).astype(np.float64)
    except (ValueError, OSError) as exc:
        raise ShapeError(f"cannot read shape file {str(path)!r}: {exc}") from None


def check_height_scale(height_scale: float) -> None:
    """Refuse a ``height_scale`` that is not a positive, finite number.

    Raises:
        ShapeError: zero, negative, NaN, infinite or not a number.
    """
    if (
        isinstance(height_scale, bool)
        or not isinstance(height_scale, (int, float, np.floating, np.integer))
        or not math.isfinite(height_scale)
        or height_scale <= 0
    ):
        raise ShapeError(
            f"height_scale must be a positive number (model units per unit of the shape file's values), "
            f"got {height_scale!r}"
        )


def allowed_height(saucer: Saucer | None = None) -> float:
    """The largest |height| a shape file may give, model units: :data:`MAX_RELIEF_PER_SIZE`
    times the larger side of ``saucer`` (default: the paper's 1 x 1 saucer)."""
    return MAX_RELIEF_PER_SIZE * max((saucer or Saucer()).size)


def check_height_range(heights: np.ndarray, what: str, height_scale: float, saucer: Saucer | None = None) -> None:
    """Refuse heights (model units, finite) outside +-:func:`allowed_height` of z = 0.

    Raises:
        ShapeError: naming the range found and the range allowed.
    """
    limit = allowed_height(saucer)
    lo, hi = float(np.min(heights)), float(np.max(heights))
    if -limit <= lo and hi <= limit:
        return
    size = saucer or Saucer()
    w, d = size.size
    raise ShapeError(
        f"shape file {what} gives heights from {lo:.4g} to {hi:.4g} model units (its values times "
        f"height_scale {height_scale:g}); a saucer of {w:g} x {d:g} units takes heights within "
        f"+-{limit:g} ({MAX_RELIEF_PER_SIZE:g} times its larger side; a printable relief is far "
        "lower). Is the file in another unit? Give values of about [0, 1] (a 16-bit PNG's range), "
        "or a smaller height_scale (--height-scale)"
    )


def load_shape(
    source: str | os.PathLike[str],
    n: int,
    *,
    height_scale: float = HEIGHT_SCALE,
    seed: int = 0,
    saucer: Saucer | None = None,
) -> np.ndarray:
    """Load a base shape as (n, n) heights in model units.

    Args:
        source: a built-in shape name (see :data:`BASE_SHAPES`), or a path to
            an 8/16-bit grayscale PNG (white = ``height_scale``) or a 2-D
            ``.npy`` array (values multiplied by ``height_scale``).
        n: grid resolution (vertices per side).
        height_scale: model units per unit of the file's values (:data:`HEIGHT_SCALE`).
        seed: seed for the seeded shapes.
        saucer: the saucer the shape is for; a file's heights must lie within
            :func:`allowed_height` of it (default: the paper's saucer).

    Raises:
        ShapeError: unknown name, unreadable file, wrong dimensionality, NaN,
            heights out of range, a bad ``height_scale``.
    """
    check_height_scale(height_scale)  # before any reading: a bad option is refused at once
    text = os.fspath(source)
    path = Path(text)
    if path.suffix.lower() not in (".png", ".npy"):
        if path.exists() or os.sep in text:
            raise ShapeError(
                f"shape file {text!r} must be a .png or .npy heightfield; "
                f"or name a built-in shape: {sorted(BASE_SHAPES)}"
            )
        return base_shape(text, n, seed, saucer)
    if not path.is_file():
        raise ShapeError(f"shape file {text!r} not found")
    raw = _load_png(path) if path.suffix.lower() == ".png" else _load_npy(path)
    if raw.shape[0] < 2 or raw.shape[1] < 2:
        raise ShapeError(f"shape file {text!r} is {raw.shape}; it needs at least 2x2 samples")
    if not np.isfinite(raw).all():
        bad = int((~np.isfinite(raw)).sum())
        raise ShapeError(f"shape file {text!r} holds {bad} NaN or infinite value(s); fix or fill them")
    with np.errstate(over="ignore"):  # 1e300 x 10 is inf: reported as out of range below
        scaled = raw * float(height_scale)
    check_height_range(scaled, repr(text), float(height_scale), saucer)
    return resample(scaled, n)


# --------------------------------------------------------------------------- mesh


def triangulate(n: int) -> np.ndarray:
    """Faces (2 (n-1)^2, 3) int64 of the n x n grid, counter-clockwise from +z.

    Cell (i, j) with corners a = (i, j), b = (i, j+1), c = (i+1, j+1),
    d = (i+1, j) gives faces (a, b, c) and (a, c, d). Since +j is +x and +i
    is +y, both are counter-clockwise seen from above.
    """
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    b = a + 1
    c = a + n + 1
    d = a + n
    f1 = np.stack([a, b, c], axis=1)
    f2 = np.stack([a, c, d], axis=1)
    # interleave so the two faces of one cell are neighbours in memory
    return np.stack([f1, f2], axis=1).reshape(-1, 3).astype(np.int64)


def vertex_neighbours(n: int) -> list[np.ndarray]:
    """Mesh neighbours of each vertex of the triangulated n x n grid."""
    faces = triangulate(n)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    nbrs: list[list[int]] = [[] for _ in range(n * n)]
    for a, b in edges:
        nbrs[a].append(int(b))
        nbrs[b].append(int(a))
    return [np.array(sorted(x)) for x in nbrs]


def laplacian(n: int):  # -> scipy.sparse.csr_matrix
    """The uniform (umbrella) Laplacian of the triangulated n x n grid, (n^2, n^2) CSR.

    ``(L h)_i = h_i - mean_{j in N(i)} h_j`` over the mesh neighbours N(i)
    (4 axis neighbours plus the 2 along the cell diagonal in the interior).
    These are Sorkine et al.'s Laplacian coordinates restricted to z, which
    E_deform (paper eq. 3) compares: ``sum_i ((L z)_i - (L h)_i)^2``. They are
    unitless in the grid spacing, so E_deform is comparable across
    resolutions in the way the paper's reported values (about 0.2) are.

    Rows sum to zero, so L is zero on constants everywhere. On a linear
    function L is zero at every interior vertex, but not on the border,
    where the neighbours' mean lies off the vertex (corner (0, 0): at
    (2/3, 2/3) cells); E_deform applies the same L to z and h, so that is
    harmless. On f = x^2 in the interior L equals ``-(2/3) dx^2`` (the six
    neighbours' mean of x^2 exceeds x^2 by 4 dx^2 / 6).
    """
    import scipy.sparse as sp

    faces = triangulate(n)
    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2], faces[:, 1], faces[:, 2], faces[:, 0]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0], faces[:, 0], faces[:, 1], faces[:, 2]])
    adj = sp.coo_matrix((np.ones(rows.shape[0]), (rows, cols)), shape=(n * n, n * n)).tocsr()
    adj.data[:] = 1.0  # each undirected edge appears in two faces; keep it once
    deg = np.asarray(adj.sum(axis=1)).ravel()
    return (sp.identity(n * n, format="csr") - sp.diags(1.0 / deg) @ adj).tocsr()


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals (F, 3) for vertices (V, 3) and faces (F, 3)."""
    v = vertices[faces]
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    return nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
