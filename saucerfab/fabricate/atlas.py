"""The UV atlas of the whole solid: one texture page, two regions.

Conventions: the page is ``S x S`` pixels, row 0 at the top of the image.
Texture coordinates follow saucerfab's convention (``u`` left to right,
``v`` bottom to top): pixel (row r, column c) has its centre at
``u = (c + 0.5) / S``, ``v = 1 - (r + 0.5) / S``. Pixel positions below are
continuous: ``px`` counts pixels from the page's left edge, ``py`` from its
top edge.

* The *top* (the saucer's heightfield, where all the colour is) gets planar
  UVs in a rectangle covering most of the page: grid column ``j`` maps to
  ``col_px[j]`` and grid row ``i`` to ``row_px[i]`` (rows run up the page as
  ``y`` grows, like ``v``). The two maps are piecewise linear with
  breakpoints at the grid lines, so every grid cell - and with it each of its
  two triangles - is mapped *affinely*; a texel's face and barycentric
  coordinates are therefore found analytically (see :mod:`.bake`). The
  breakpoints are not evenly spaced: each column (row) of cells gets texels in
  proportion to the longest surface length across it, so steep ridges and
  the sawtooth faces of a tabula scalata are not starved of texels the way a
  plain xy projection starves them.
* Walls, base and seat get xatlas charts packed into the column at the
  page's right. They carry the neutral wall colour.

Both regions sit ``padding_px`` inside their cells, and the gutters are
filled by edge dilation in :mod:`.bake`, so bilinear filtering and mipmaps
never reach a background colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from saucerfab.fabricate.solid import Solid

#: share of the page edge kept for the top region (the rest is the chart column)
TOP_SHARE = 7 / 8
#: the side charts' texel density at most this share of the top's: they carry plain colours, and a file
#: checker takes faces under a tenth of the best density for plain (saucerfab.check.limits.Limits
#: .solid_colour_density), which a round saucer's large bottom in the chart column would pass
SIDE_DENSITY_SHARE = 0.05


@dataclass(frozen=True)
class Rect:
    """A pixel rectangle: columns ``[x, x + w)``, rows ``[y, y + h)`` (row 0 at the top)."""

    x: int
    y: int
    w: int
    h: int


@dataclass(frozen=True)
class AtlasLayout:
    """Where everything lies on the page.

    Attributes:
        size: page edge S, pixels.
        padding: gutter width, pixels.
        top: the top region.
        charts: the region holding the xatlas charts.
        col_px: (N,) continuous page x of each grid column, increasing,
            ``col_px[0] = top.x`` and ``col_px[-1] = top.x + top.w``.
        row_px: (N,) continuous page y of each grid row, *decreasing* (grid
            row 0, the saucer's front edge at the smallest y, is at the
            region's bottom), ``row_px[0] = top.y + top.h``, ``row_px[-1] = top.y``.
    """

    size: int
    padding: int
    top: Rect
    charts: Rect
    col_px: np.ndarray
    row_px: np.ndarray


@dataclass(frozen=True)
class UVMap:
    """Texture coordinates of a solid, indexed separately from positions.

    Attributes:
        uvs: (T, 2) float64 texture coordinates in [0, 1] (u right, v up).
        face_uvs: (F, 3) int64 indices into ``uvs`` for each face corner of
            ``Solid.faces``; positions stay shared, so the mesh stays watertight.
    """

    uvs: np.ndarray
    face_uvs: np.ndarray


def surface_density(heights_mm: np.ndarray, xs_mm: np.ndarray, ys_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface length per unit of plan length across each column and row of cells.

    Returns:
        (N-1,) for columns: ``max_i sqrt(1 + (dh/dx)^2)`` over the cell
        edges along x in that column; (N-1,) for rows likewise along y.
        Both >= 1 (1 on a flat saucer).
    """
    h = np.asarray(heights_mm, np.float64)
    sx = np.diff(h, axis=1) / np.diff(xs_mm)[None, :]
    sy = np.diff(h, axis=0) / np.diff(ys_mm)[:, None]
    return np.sqrt(1.0 + sx**2).max(axis=0), np.sqrt(1.0 + sy**2).max(axis=1)


def layout_page(
    size: int,
    padding: int,
    xs_mm: np.ndarray,
    ys_mm: np.ndarray,
    heights_mm: np.ndarray,
) -> AtlasLayout:
    """Plan the page for a top grid ``(xs_mm, ys_mm, heights_mm)``.

    The top rectangle keeps the aspect of the surface's (density-weighted)
    lengths along x and y, and is as large as the page allows next to a
    chart column ``(1 - TOP_SHARE) * size`` wide.
    """
    p = padding
    col_w = max(size - int(round(size * TOP_SHARE)), 4 * p)
    avail_w = size - col_w - 2 * p
    avail_h = size - 2 * p
    dens_x, dens_y = surface_density(heights_mm, xs_mm, ys_mm)
    len_x = np.concatenate([[0.0], np.cumsum(dens_x * np.diff(xs_mm))])
    len_y = np.concatenate([[0.0], np.cumsum(dens_y * np.diff(ys_mm))])
    aspect = len_x[-1] / len_y[-1]
    if aspect >= avail_w / avail_h:
        w, h = avail_w, max(1, int(round(avail_w / aspect)))
    else:
        w, h = max(1, int(round(avail_h * aspect))), avail_h
    top = Rect(p, p, w, h)
    charts = Rect(size - col_w + p, p, col_w - 2 * p, size - 2 * p)
    col_px = top.x + top.w * (len_x / len_x[-1])
    row_px = top.y + top.h * (1.0 - len_y / len_y[-1])
    col_px[0], col_px[-1] = top.x, top.x + top.w  # exact ends, whatever the rounding
    row_px[0], row_px[-1] = top.y + top.h, top.y
    return AtlasLayout(size, p, top, charts, col_px, row_px)


def top_uv(layout: AtlasLayout, grid_x: np.ndarray, grid_y: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Texture coordinates (K, 2) of points ``xy`` (K, 2) on the top (file mm).

    Piecewise linear in x and in y with the layout's breakpoints, so exact
    for grid vertices and for points on grid edges that manifold inserted.
    """
    px = np.interp(xy[:, 0], grid_x, layout.col_px)
    py = np.interp(xy[:, 1], grid_y, layout.row_px)
    s = float(layout.size)
    return np.stack([px / s, 1.0 - py / s], axis=1)


def _px_per_mm(vertices: np.ndarray, faces: np.ndarray, px: np.ndarray, corners: np.ndarray) -> float:
    """Texels per mm over a triangle set: sqrt(page area in px^2 / surface area in mm^2).

    Args: vertices (V, 3) mm; faces (F, 3) into them; px (T, 2) page pixels; corners (F, 3) into ``px``.
    """
    v = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()
    p = px[corners]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    page = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    return float(np.sqrt(page / area)) if area > 0 else 0.0


def chart_uvs(vertices: np.ndarray, faces: np.ndarray, region: "Rect", size: int,
              max_px_per_mm: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """xatlas charts for a (non-top) triangle set, placed in ``region``.

    Args:
        vertices: (V, 3) positions, mm.
        faces: (F, 3) indices into ``vertices``.
        region: where on the page the charts go.
        size: page edge, pixels.
        max_px_per_mm: the charts are scaled down to at most this density (None: as large as the region allows).

    Returns:
        uvs (T, 2) page texture coordinates and corner indices (F, 3) into them.
    """
    import xatlas

    used, inv = np.unique(faces, return_inverse=True)
    v = np.ascontiguousarray(vertices[used], np.float32)
    f = np.ascontiguousarray(inv.reshape(-1, 3), np.uint32)
    atlas = xatlas.Atlas()
    atlas.add_mesh(v, f)
    pack = xatlas.PackOptions()
    # xatlas's texel grid at (about) our pixel size, so its padding is real pixels
    pack.resolution = int(max(16, min(region.w, region.h)))
    pack.padding = 2
    pack.bilinear = True
    atlas.generate(xatlas.ChartOptions(), pack)
    _vmap, idx, uv = atlas[0]
    aw, ah = float(atlas.width), float(atlas.height)
    scale = min(region.w / aw, region.h / ah)
    # xatlas's uv are in [0, 1] over its own (aw x ah) texel grid, v counting
    # from its first row; put that grid, uniformly scaled, at the region's top
    # left (first row at the top), so every chart stays inside the region.
    corners = np.asarray(idx, np.int64).reshape(-1, 3)
    unit = np.stack([np.asarray(uv[:, 0], np.float64) * aw, np.asarray(uv[:, 1], np.float64) * ah], axis=1)
    if max_px_per_mm is not None:
        density = _px_per_mm(vertices, faces, unit * scale, corners)
        if density > max_px_per_mm:
            scale *= max_px_per_mm / density
    px = region.x + unit[:, 0] * scale
    py = region.y + unit[:, 1] * scale
    uvs = np.stack([px / size, 1.0 - py / size], axis=1)
    return uvs, corners


def build_uvmap(solid: Solid, layout: AtlasLayout) -> UVMap:
    """Texture coordinates for every face corner of ``solid``.

    Top faces share one uv per vertex (the planar map is continuous over the
    top); the rest get xatlas charts, with seams where xatlas cut them.
    """
    f = solid.faces
    top_f = f[solid.is_top]
    top_vid, top_inv = np.unique(top_f, return_inverse=True)
    uv_top = top_uv(layout, solid.grid_x, solid.grid_y, solid.vertices[top_vid, :2])
    face_uvs = np.zeros(f.shape, np.int64)
    face_uvs[solid.is_top] = top_inv.reshape(-1, 3)
    rest = ~solid.is_top
    if rest.any():
        top_density = _px_per_mm(solid.vertices, top_f, uv_top * layout.size, top_inv.reshape(-1, 3))
        uv_rest, idx_rest = chart_uvs(solid.vertices, f[rest], layout.charts, layout.size,
                                      SIDE_DENSITY_SHARE * top_density)
        face_uvs[rest] = idx_rest + uv_top.shape[0]
        uvs = np.concatenate([uv_top, uv_rest])
    else:
        uvs = uv_top
    return UVMap(uvs=uvs, face_uvs=face_uvs)
