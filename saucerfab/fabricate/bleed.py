"""Colour bleed of a full-colour print: the texture as it prints, and the texture that prints as meant.

A PolyJet print's colour sits in translucent resin: light entering at one
point of the surface scatters under it and leaves a little further on, so
the printed colour is the texture blurred along the surface (the paper's own
prints are "blurred", section 5; Elek et al. 2017, Sumin et al. 2019 and
Nindel et al. 2021 model and measure the scattering). This module models that
blur as an isotropic Gaussian point spread of standard deviation
``sigma_mm`` on the surface (a printer profile's ``colour_bleed_mm``, whose
comment says where its width comes from) and pre-compensates it.

The model
---------
* **Linear light.** Scattering adds light, so the blur acts on linear
  reflectance, not on sRGB code values: a page (sRGB) is linearised (the sRGB
  transfer function), blurred, and encoded back. Blurring sRGB values would
  darken every edge between a light and a dark colour. First order: a halftoned
  ink layer over a scattering core filters light on the way in *and* out
  (the Yule-Nielsen effect of 2D printing), which this linear model leaves out.
* **Within a chart only.** Light does not cross from one part of the
  surface to an unrelated one next to it on the page, so each chart of the
  atlas (:class:`Chart`: a page rectangle, optionally a mask in it) is
  blurred on its own by *normalized convolution*: ``B x = G(M x) / G(M)``
  with ``G`` the Gaussian and ``M`` the chart's mask (a texel near the chart's
  edge averages over the chart texels around it only). Texels outside every
  chart stay as they are.
* **Texels, not millimetres.** The blur is ``sigma_mm * px_per_mm`` texels,
  one width for the whole chart. On the top that is right to first order:
  :mod:`.atlas` gives each column (row) of cells texels in proportion to the
  longest surface length across it, so texels follow the surface, but a flat
  face in a column that also holds a steep one gets more texels per mm than
  the steep one (the blur is then too narrow there, in texels), the density
  differs a little between x and y, and distances are measured on the page,
  not along the curved surface. :func:`top_px_per_mm` takes the area mean.
  On the default heart-star and fish-moon designs for the J55 (4096 px)
  that is 26.4 texels per mm (sigma 3.2 texels), where a column's steepest
  face has 10-13 (the blur there is about 2x too wide in texels) and a flat
  face in a steep column up to 60-86 (about 3x too narrow). A mesh read
  from files (:func:`mesh_charts`, for ``verify``) gives each chart its own
  mean density.
* **Thin ridges.** A band of one picture narrower than about 2 sigma
  between faces of the other mixes both all across. On those two designs
  such bands hold 59 and 4 texels (8 and 2 faces, a few texels each): a
  face's narrowest width is a cell's over sqrt(2) (0.47 mm on the plan at
  150 cells over 100 mm), twice 2 sigma (0.24 mm), so a band even one face
  wide is not thin; nothing is done about them.

Compensation
------------
:func:`compensate_bleed` looks for the texture ``x`` in the printer's colour
range (sRGB values in ``[0, 1]``) whose print is closest to the intended page
``t``: ``min 1/2 || enc(B dec(x)) - t ||_D^2`` over the box, with ``dec`` /
``enc`` the sRGB transfer function and its inverse and the norm weighted by
``D = G(M)`` (1 inside a chart, down to 1/4 at a rectangle's corner).

* The blur stays in linear light (the physics); the *error* is measured in
  sRGB, as ``saucerfab verify`` scores a print and closer to what the eye
  sees: in linear light the dark side of every edge hardly counts. On a
  crop of the heart-star page the linear-light objective won 0.7 dB
  (sRGB PSNR of the print), the sRGB one 2.6 dB, at the same five steps.
* The weight makes the gradient one plain convolution,
  ``dec'(x) G(enc'(B dec x) r)`` (``B^T D = G``): in linear light its
  Lipschitz constant is at most 1 (``G D^-1 G`` has non-negative entries
  and row sums ``G 1 <= 1``: Schur's test), and the transfer function's two
  slopes nearly cancel where the print is near the page; with a unit step
  the objective fell at every step in every case tried (lines, dots, steps
  and noise at 1.5 to 6 texels of blur).
* The method is the projected gradient (projected Landweber) with
  Nesterov's momentum (FISTA), starting at ``t``; it stops after
  :data:`MAX_ITERATIONS` steps or when no texel moved more than
  :data:`TOLERANCE` (half an 8-bit step) in one.
* ``method="wiener"`` is the alternative ``benchmarks/bench_bleed.py``
  compares it with: a Wiener filter of the linear light in the Fourier domain
  (reflected padding at the chart's edges), clipped to the box. It rings
  at the saturated edges of graphics and prints worse than no compensation
  (heart-star: 29.4 dB against 31.3 uncompensated).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from saucerfab.fabricate.atlas import AtlasLayout, Rect

#: the Gaussian is cut where it falls under exp(-8): 4 standard deviations
TRUNCATE = 4.0
#: steps of the projected gradient at most: on the heart-star export's top (4096 px page, 3.2 texels of
#: blur; 31.3 dB as printed uncompensated) the print gains 1.8 dB in 2 steps, 2.1 in 3, 2.3 in 5, 2.4 in 8
#: and 2.5 in 12; a step is two blurs and two powers of each channel (1.3 s a channel on one core of a
#: shared, loaded machine)
MAX_ITERATIONS = 5
#: the projected gradient stops when no texel moved more than this in a step (sRGB, 0..1: half an 8-bit step)
TOLERANCE = 0.5 / 255
#: the Wiener filter's noise-to-signal ratio: the smallest ``|H|^2`` it still inverts
WIENER_NSR = 1e-2
#: blur narrower than this (texels) changes no 8-bit colour: the page is left as it is
MIN_SIGMA_PX = 0.05

Method = Literal["landweber", "wiener"]
METHODS: tuple[str, ...] = ("landweber", "wiener")


@dataclass(frozen=True)
class Chart:
    """One connected piece of surface on the page.

    Attributes:
        rect: its bounding rectangle on the page (pixels).
        mask: (rect.h, rect.w) bool, the chart's texels within ``rect``; None: all of ``rect``.
        px_per_mm: this chart's texels per mm of surface; None: the one the caller gives for all charts.
    """

    rect: Rect
    mask: np.ndarray | None = None
    px_per_mm: float | None = None


def _chart(c: Rect | Chart) -> Chart:
    chart = c if isinstance(c, Chart) else Chart(c)
    if chart.mask is not None and chart.mask.shape != (chart.rect.h, chart.rect.w):
        raise ValueError(f"chart mask {chart.mask.shape} != its rectangle's ({chart.rect.h}, {chart.rect.w})")
    return chart


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] -> linear light in [0, 1] (IEC 61966-2-1), float32, same shape."""
    v = np.asarray(v, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB values in [0, 1], float32, same shape (values clipped to [0, 1] first)."""
    v = np.clip(np.asarray(v, np.float32), 0.0, 1.0)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055).astype(np.float32)


def _to_linear(page: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 sRGB or float sRGB in [0, 1] -> float32 linear light."""
    if page.dtype == np.uint8:
        lut = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0)
        return lut[page]
    return srgb_to_linear(page)


def _from_linear(lin: np.ndarray, like: np.ndarray) -> np.ndarray:
    """Linear light back to ``like``'s kind: uint8 sRGB (rounded) or float32 sRGB in [0, 1]."""
    s = linear_to_srgb(lin)
    if like.dtype == np.uint8:
        return np.clip(np.rint(s * 255.0), 0, 255).astype(np.uint8)
    return s


def sigma_px(px_per_mm: float, sigma_mm: float) -> float:
    """The bleed's standard deviation in texels: ``sigma_mm`` (mm) at ``px_per_mm`` texels per mm."""
    if not (math.isfinite(px_per_mm) and px_per_mm > 0 and math.isfinite(sigma_mm) and sigma_mm >= 0):
        raise ValueError(f"px_per_mm must be positive and sigma_mm non-negative, got {px_per_mm!r}, {sigma_mm!r}")
    return float(px_per_mm * sigma_mm)


class _ChartOp:
    """The blur of one chart (2D, one channel): ``conv`` is ``M G M``, ``blur`` is ``B = D^-1 G M``.

    Separable (two 1D passes, zero outside the chart's rectangle); a mask's
    texels outside it count as zero and come back as zero from ``conv``.
    """

    def __init__(self, h: int, w: int, mask: np.ndarray | None, s: float) -> None:
        self.s, self.mask = s, mask
        if mask is None:  # a rectangle's G(M) is the product of two 1D sums
            dy = self._pass(np.ones(h, np.float32), 0)
            dx = self._pass(np.ones(w, np.float32), 0)
            self.den = (dy[:, None] * dx[None, :]).astype(np.float32)
        else:
            self.m = mask.astype(np.float32)
            self.den = self._conv2(self.m)
            self.den[~mask] = 1.0  # never divided by there: outside the chart the caller keeps its texels

    def _pass(self, x: np.ndarray, axis: int) -> np.ndarray:
        from scipy import ndimage

        return ndimage.gaussian_filter1d(x, self.s, axis=axis, mode="constant", cval=0.0, truncate=TRUNCATE)

    def _conv2(self, x: np.ndarray) -> np.ndarray:
        return self._pass(self._pass(x, 0), 1)

    def conv(self, x: np.ndarray) -> np.ndarray:
        """(h, w) float32 -> ``M G M x``."""
        if self.mask is None:
            return self._conv2(x)
        y = self._conv2(x * self.m)
        y[~self.mask] = 0.0
        return y

    def blur(self, x: np.ndarray) -> np.ndarray:
        """(h, w) float32 -> ``B x`` on the chart (outside a mask: 0)."""
        return self.conv(x) / self.den


def _region(a: np.ndarray, r: Rect) -> np.ndarray:
    return a[r.y:r.y + r.h, r.x:r.x + r.w]


def bleed_page(page: np.ndarray, charts: Sequence[Rect | Chart], px_per_mm: float, sigma_mm: float) -> np.ndarray:
    """The page as it prints: each chart blurred on its own in linear light.

    Args:
        page: (H, W, 3) sRGB, uint8 or float in [0, 1].
        charts: the charts to blur (:class:`Chart`, or a :class:`~saucerfab.fabricate.atlas.Rect`
            for a whole rectangle); they must not overlap. Texels outside every chart are returned unchanged.
        px_per_mm: texels per millimetre of surface in the charts.
        sigma_mm: the bleed's standard deviation on the surface, mm (0: no bleed).

    Returns:
        (H, W, 3), the same dtype as ``page`` (uint8: rounded; float32 otherwise).
    """
    out = page.copy() if page.dtype == np.uint8 else np.asarray(page, np.float32).copy()
    for c in map(_chart, charts):
        s = sigma_px(px_per_mm if c.px_per_mm is None else c.px_per_mm, sigma_mm)
        if s < MIN_SIGMA_PX:
            continue
        lin = _to_linear(_region(page, c.rect))
        op = _ChartOp(c.rect.h, c.rect.w, c.mask, s)
        blurred = np.stack([op.blur(np.ascontiguousarray(lin[..., k])) for k in range(lin.shape[2])], axis=2)
        region = _region(out, c.rect)
        new = _from_linear(blurred, out)
        if c.mask is None:
            region[...] = new
        else:
            region[c.mask] = new[c.mask]
    return out


def bleed_page_reference(page: np.ndarray, charts: Sequence[Rect | Chart], px_per_mm: float,
                         sigma_mm: float) -> np.ndarray:
    """:func:`bleed_page` the slow, obvious way, in float64 (for the tests; small pages only).

    Every chart texel is the weighted mean of the chart texels within the
    kernel's reach (the same sampled, truncated Gaussian), summed shift by shift.

    Returns:
        (H, W, 3) float64 sRGB in [0, 1].
    """
    src = np.asarray(page, np.float64) / (255.0 if page.dtype == np.uint8 else 1.0)
    out = src.copy()
    lin_all = np.where(src <= 0.04045, src / 12.92, ((src + 0.055) / 1.055) ** 2.4)
    for c in map(_chart, charts):
        s = sigma_px(px_per_mm if c.px_per_mm is None else c.px_per_mm, sigma_mm)
        if s < MIN_SIGMA_PX:
            continue
        radius = int(TRUNCATE * s + 0.5)
        taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / s) ** 2)
        taps /= taps.sum()
        r = c.rect
        mask = np.ones((r.h, r.w), bool) if c.mask is None else c.mask
        lin = _region(lin_all, r) * mask[..., None]
        num = np.zeros_like(lin)
        den = np.zeros(mask.shape)
        pad_l = np.pad(lin, ((radius, radius), (radius, radius), (0, 0)))
        pad_m = np.pad(mask.astype(np.float64), radius)
        for i, wy in enumerate(taps):
            for j, wx in enumerate(taps):
                num += wy * wx * pad_l[i:i + r.h, j:j + r.w]
                den += wy * wx * pad_m[i:i + r.h, j:j + r.w]
        blurred = num / np.where(mask, den, 1.0)[..., None]
        enc = np.where(blurred <= 0.0031308, blurred * 12.92, 1.055 * np.clip(blurred, 0, 1) ** (1 / 2.4) - 0.055)
        _region(out, r)[mask] = enc[mask]
    return out


def _decode(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sRGB values (float32, [0, 1]) -> (linear light, its derivative), one power for both."""
    q = (np.maximum(v, np.float32(0.04045)) + np.float32(0.055)) / np.float32(1.055)
    q14 = q ** np.float32(1.4)
    low = v <= 0.04045
    return (np.where(low, v / np.float32(12.92), q14 * q).astype(np.float32),
            np.where(low, np.float32(1 / 12.92), np.float32(2.4 / 1.055) * q14).astype(np.float32))


def _encode(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear light (float32) -> (sRGB values, their derivative), clipped to [0, 1] first; one power for both."""
    v = np.clip(v, 0.0, 1.0)
    knee = np.maximum(v, np.float32(0.0031308))
    p = knee ** np.float32(1 / 2.4)
    low = v <= 0.0031308
    return (np.where(low, np.float32(12.92) * v, np.float32(1.055) * p - np.float32(0.055)).astype(np.float32),
            np.where(low, np.float32(12.92), np.float32(1.055 / 2.4) * p / knee).astype(np.float32))


def _projected_gradient(op: _ChartOp, t: np.ndarray, iterations: int, tol: float) -> tuple[np.ndarray, int]:
    """FISTA on ``1/2 ||enc(B dec(x)) - t||_D^2`` over sRGB values ``0 <= x <= 1``; (x, steps taken).

    ``t``: (h, w) float32 sRGB of one channel. The gradient is
    ``dec'(x) * G(enc'(B dec x) * r)`` with ``r`` the residual (``D`` cancels
    ``B``'s normalisation, as in the linear case).
    """
    x = t.copy()
    x_prev = x
    tk = 1.0
    steps = 0
    for steps in range(1, iterations + 1):
        tk1 = (1.0 + math.sqrt(1.0 + 4.0 * tk * tk)) / 2.0
        y = np.clip(x + np.float32((tk - 1.0) / tk1) * (x - x_prev), 0.0, 1.0)
        lin, dlin = _decode(y)
        printed, dprinted = _encode(op.blur(lin))
        grad = dlin * op.conv((printed - t) * dprinted)
        x_prev, x = x, np.clip(y - grad, 0.0, 1.0)
        tk = tk1
        if float(np.max(np.abs(x - x_prev))) <= tol:
            break
    return x, steps


def _wiener(t: np.ndarray, mask: np.ndarray | None, s: float, nsr: float) -> np.ndarray:
    """Wiener deconvolution of one chart's channel (reflected padding), clipped to [0, 1]."""
    from scipy import fft, ndimage

    if mask is not None and not mask.all():  # outside the chart: the nearest chart texel's value
        idx = ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)
        t = t[idx[0], idx[1]]
    radius = int(TRUNCATE * s + 0.5)
    pad = 3 * radius
    big = np.pad(t, pad, mode="reflect" if min(t.shape) > pad else "edge")
    h, w = big.shape
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / s) ** 2)
    taps /= taps.sum()

    def transfer(n: int) -> np.ndarray:
        k = np.zeros(n)
        k[: radius + 1] = taps[radius:]
        k[n - radius:] = taps[:radius]  # centred at 0, circularly: a real, even transfer function
        return np.real(fft.fft(k))

    hy, hx = transfer(h), transfer(w)
    hxy = hy[:, None] * hx[None, : w // 2 + 1]
    spec = fft.rfft2(big.astype(np.float64), workers=-1)
    out = fft.irfft2(spec * hxy / (hxy * hxy + nsr), s=(h, w), workers=-1)[pad:pad + t.shape[0], pad:pad + t.shape[1]]
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def compensate_bleed(
    page: np.ndarray,
    charts: Sequence[Rect | Chart],
    px_per_mm: float,
    sigma_mm: float,
    *,
    method: Method = "landweber",
    iterations: int = MAX_ITERATIONS,
    tol: float = TOLERANCE,
    nsr: float = WIENER_NSR,
) -> np.ndarray:
    """The page pre-sharpened so that, bled (:func:`bleed_page`), it comes closest to ``page``.

    In linear light, within the printer's colour range, each chart and
    channel on its own (see the module's docstring for the objective and the
    two methods).

    Args:
        page: (H, W, 3) the intended page, sRGB uint8 or float in [0, 1].
        charts, px_per_mm, sigma_mm: as for :func:`bleed_page`.
        method: ``landweber`` (projected gradient, the default) or ``wiener`` (filter, then clip).
        iterations: most steps of ``landweber``.
        tol: ``landweber`` stops when no texel moved more than this (sRGB, 0..1) in a step.
        nsr: the Wiener filter's noise-to-signal ratio.

    Returns:
        (H, W, 3) of ``page``'s dtype; texels outside every chart unchanged.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    out = page.copy() if page.dtype == np.uint8 else np.asarray(page, np.float32).copy()
    for c in map(_chart, charts):
        s = sigma_px(px_per_mm if c.px_per_mm is None else c.px_per_mm, sigma_mm)
        if s < MIN_SIGMA_PX:
            continue
        region = _region(out, c.rect)
        if method == "landweber":
            src = _region(page, c.rect)
            want = src.astype(np.float32) / np.float32(255.0) if src.dtype == np.uint8 else np.asarray(src, np.float32)
            op = _ChartOp(c.rect.h, c.rect.w, c.mask, s)
            srgb = np.stack([_projected_gradient(op, np.ascontiguousarray(want[..., k]), iterations, tol)[0]
                             for k in range(want.shape[2])], axis=2)
            new = np.clip(np.rint(srgb * 255.0), 0, 255).astype(np.uint8) if out.dtype == np.uint8 else srgb
        else:
            lin = _to_linear(_region(page, c.rect))
            new = _from_linear(np.stack([_wiener(np.ascontiguousarray(lin[..., k]), c.mask, s, nsr)
                                         for k in range(lin.shape[2])], axis=2), out)
        if c.mask is None:
            region[...] = new
        else:
            region[c.mask] = new[c.mask]
    return out


# --------------------------------------------------------------------------- the export's page


def surface_area_mm2(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray) -> float:
    """Area (mm^2) of the top's heightfield (N, N) over the grid ``xs_mm`` (N,) x ``ys_mm`` (N,), two triangles a cell.

    The cells are split along the diagonal from (i, j) to (i + 1, j + 1), as
    :mod:`.bake` and the solid split them.
    """
    x, y = np.meshgrid(np.asarray(xs_mm, np.float64), np.asarray(ys_mm, np.float64))
    p = np.stack([x, y, np.asarray(heights_mm, np.float64)], axis=-1)
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
    t1 = np.linalg.norm(np.cross(b - a, c - a), axis=-1)
    t2 = np.linalg.norm(np.cross(c - a, d - a), axis=-1)
    return float(0.5 * (t1.sum() + t2.sum()))


def top_px_per_mm(layout: AtlasLayout, xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray) -> float:
    """The top region's mean texel density: ``sqrt(texels / surface mm^2)``, texels per mm."""
    return math.sqrt(layout.top.w * layout.top.h / surface_area_mm2(xs_mm, ys_mm, heights_mm))


def compensate_top(page: np.ndarray, layout: AtlasLayout, px_per_mm: float, sigma_mm: float) -> np.ndarray:
    """The export's page with its top region compensated (:func:`compensate_bleed`) and its gutter redone.

    The top is one chart (its planar map is continuous over the whole top).
    The side charts are left as they are: they carry plain colours at no
    more than :data:`~saucerfab.fabricate.atlas.SIDE_DENSITY_SHARE` of the
    top's texel density, where the bleed is a fraction of a texel. The gutter
    around the top repeats the new edge texels, as :func:`.bake.compose_page` makes it.

    Args:
        page: (S, S, 3) uint8, as :func:`.bake.bake_page` returns it.

    Returns:
        A new (S, S, 3) uint8 page.
    """
    out = compensate_bleed(page, [layout.top], px_per_mm, sigma_mm)
    refill_gutter(out, layout)
    return out


def refill_gutter(page: np.ndarray, layout: AtlasLayout) -> None:
    """Refill the gutter around the top region of ``page`` (S, S, 3) with its edge texels, in place, as
    :func:`.bake.compose_page` makes it: after a pass that changed the top's texels (this module's,
    :mod:`.shading`'s), so that a sample across the top's edge still reads the top's colour."""
    t, p, s = layout.top, layout.padding, layout.size
    r0, r1 = max(t.y - p, 0), min(t.y + t.h + p, s)
    c0, c1 = max(t.x - p, 0), min(t.x + t.w + p, s)
    top = _region(page, t).copy()
    page[r0:r1, c0:c1] = np.pad(top, ((t.y - r0, r1 - t.y - t.h), (t.x - c0, c1 - t.x - t.w), (0, 0)), mode="edge")


# --------------------------------------------------------------------------- a textured mesh, as verify reads it


def mesh_charts(vertices_mm: np.ndarray, faces: np.ndarray, uvs: np.ndarray, face_uvs: np.ndarray,
                size: int) -> list[Chart]:
    """The charts of a textured mesh on its ``size`` x ``size`` page, each with its own texel density.

    A chart is a set of faces joined through shared texture coordinates (the
    top's planar map is one; each xatlas chart of the walls another). Its mask
    is the texels whose centres its triangles cover; its density
    ``sqrt(page area / surface area)``, texels per mm.

    Args:
        vertices_mm: (V, 3) positions, mm. faces: (F, 3) indices into them.
        uvs: (T, 2) texture coordinates (u right, v up, in [0, 1]). face_uvs: (F, 3) indices into ``uvs``.
        size: the page's edge, pixels.
    """
    from scipy import sparse
    from scipy.sparse import csgraph

    from saucerfab.render.texels import raster_triangles_2d

    fu = np.asarray(face_uvs, np.int64)
    t = uvs.shape[0]
    edges = np.concatenate([fu[:, [0, 1]], fu[:, [1, 2]]])
    graph = sparse.coo_matrix((np.ones(edges.shape[0]), (edges[:, 0], edges[:, 1])), shape=(t, t))
    _n, uv_label = csgraph.connected_components(graph, directed=False)
    face_label = uv_label[fu[:, 0]]
    px = np.stack([uvs[:, 0] * size, (1.0 - uvs[:, 1]) * size], axis=1)
    tri = px[fu]  # (F, 3, 2)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    page_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    v = np.asarray(vertices_mm, np.float64)[faces]
    surface = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    charts: list[Chart] = []
    for label in np.unique(face_label):
        mine = np.flatnonzero(face_label == label)
        area = float(surface[mine].sum())
        if area <= 0:
            continue
        corners = tri[mine].reshape(-1, 2)
        c0, r0 = (int(math.ceil(q - 0.5)) for q in corners.min(axis=0))  # the first texel centre inside
        c1, r1 = (int(math.floor(q - 0.5)) for q in corners.max(axis=0))  # the last
        c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, size - 1), min(r1, size - 1)
        if c1 < c0 or r1 < r0:
            continue
        rect = Rect(c0, r0, c1 - c0 + 1, r1 - r0 + 1)
        density = math.sqrt(float(page_area[mine].sum()) / area)
        box = (corners.max(axis=0) - corners.min(axis=0)).prod()
        if abs(float(page_area[mine].sum()) - box) <= 1e-6 * box:
            # the triangles tile their box (an atlas's triangles do not overlap): the whole rectangle,
            # without rasterising the top's millions of texels
            charts.append(Chart(rect, None, density))
            continue
        pix, _ti, _bary = raster_triangles_2d(tri[mine], size, size)
        rows, cols = pix // size - rect.y, pix % size - rect.x
        keep = (rows >= 0) & (rows < rect.h) & (cols >= 0) & (cols < rect.w)
        mask = np.zeros((rect.h, rect.w), bool)
        mask[rows[keep], cols[keep]] = True
        if mask.any():
            charts.append(Chart(rect, mask, density))
    return charts


def bleed_mesh_texture(page: np.ndarray, vertices_mm: np.ndarray, faces: np.ndarray, uvs: np.ndarray,
                       face_uvs: np.ndarray, sigma_mm: float) -> np.ndarray:
    """A textured mesh's page as it prints (:func:`bleed_page` over :func:`mesh_charts`): what ``verify --bleed`` needs.

    Only the written files are needed (no design, no atlas layout): each chart
    is blurred by ``sigma_mm`` at its own texel density.

    Args:
        page: (S, S, 3) sRGB page, uint8 or float in [0, 1].
        vertices_mm, faces, uvs, face_uvs: the mesh, as :func:`mesh_charts` takes it.
        sigma_mm: the bleed's standard deviation, mm (a profile's ``colour_bleed_mm``).

    Returns:
        (S, S, 3) of ``page``'s dtype; texels in no chart (gutters, the unused page) unchanged.
    """
    if sigma_mm <= 0:
        return page.copy()
    charts = mesh_charts(vertices_mm, faces, uvs, face_uvs, page.shape[0])
    return bleed_page(page, charts, 1.0, sigma_mm)  # every chart carries its own density
