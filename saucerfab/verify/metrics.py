"""Image agreement over a region: PSNR, SSIM and the best whole-picture shift.

Images are (S, S, 3) float sRGB in [0, 1]; a region is an (S, S) bool mask
of the pixels compared (where the saucer is seen). Numbers follow the usual
definitions so they compare with other tools':

* PSNR = 10 log10(1 / MSE), MSE over the region's pixels and the three channels;
* SSIM (Wang et al. 2004): Gaussian window sigma 1.5 px, K1 = 0.01,
  K2 = 0.03, data range 1, per channel, averaged over the region's pixels
  and the channels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: PSNR reported for identical images (MSE 0), dB
PSNR_CAP_DB = 99.0


def psnr(a: np.ndarray, b: np.ndarray, region: np.ndarray) -> float:
    """PSNR in dB of ``a`` against ``b`` over ``region`` (NaN for an empty region)."""
    m = np.asarray(region, bool)
    if not m.any():
        return float("nan")
    mse = float(np.mean((np.asarray(a, np.float64)[m] - np.asarray(b, np.float64)[m]) ** 2))
    return PSNR_CAP_DB if mse <= 10 ** (-PSNR_CAP_DB / 10) else float(10 * np.log10(1.0 / mse))


def ssim(a: np.ndarray, b: np.ndarray, region: np.ndarray, *, sigma: float = 1.5) -> float:
    """Mean SSIM of ``a`` against ``b`` over ``region`` (NaN for an empty region)."""
    from scipy.ndimage import gaussian_filter

    m = np.asarray(region, bool)
    if not m.any():
        return float("nan")
    c1, c2 = 0.01**2, 0.03**2
    vals = []
    for ch in range(a.shape[2]):
        x = np.asarray(a[..., ch], np.float64)
        y = np.asarray(b[..., ch], np.float64)

        def g(v: np.ndarray) -> np.ndarray:
            return gaussian_filter(v, sigma, mode="reflect", truncate=3.5)

        mx, my = g(x), g(y)
        vx, vy, cxy = g(x * x) - mx * mx, g(y * y) - my * my, g(x * y) - mx * my
        s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
        vals.append(float(s[m].mean()))
    return float(np.mean(vals))


@dataclass(frozen=True)
class Shift:
    """The whole-picture shift that best aligns a render with its reference.

    Attributes:
        dx, dy: pixels the reference is moved right and down to match.
        psnr_db: PSNR after the shift, over the pixels compared.
        region: (S, S) bool, the pixels compared after the shift (the
            render's region where the moved reference is inside its frame).
    """

    dx: int
    dy: int
    psnr_db: float
    region: np.ndarray


def shifted(ref: np.ndarray, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray]:
    """``ref`` moved ``dx`` right and ``dy`` down; (image, inside) with inside False where nothing moved in."""
    s0, s1 = ref.shape[:2]
    out = np.zeros_like(ref)
    inside = np.zeros((s0, s1), bool)
    ys, yd = (slice(0, s0 - dy), slice(dy, s0)) if dy >= 0 else (slice(-dy, s0), slice(0, s0 + dy))
    xs, xd = (slice(0, s1 - dx), slice(dx, s1)) if dx >= 0 else (slice(-dx, s1), slice(0, s1 + dx))
    out[yd, xd] = ref[ys, xs]
    inside[yd, xd] = True
    return out, inside


def _mse_grid(a: np.ndarray, ref: np.ndarray, region: np.ndarray, shifts: list[tuple[int, int]]) -> list[float]:
    out = []
    for dx, dy in shifts:
        r, inside = shifted(ref, dx, dy)
        m = region & inside
        n = int(m.sum())
        # a shift that leaves under half the region is not a match, however well it agrees
        out.append(float(np.mean((a[m] - r[m]) ** 2)) if n >= max(1, region.sum() // 2) else np.inf)
    return out


def best_shift(render: np.ndarray, ref: np.ndarray, region: np.ndarray, max_shift: int) -> Shift:
    """The integer shift within ``max_shift`` px that maximises PSNR over ``region``.

    Coarse to fine: every shift at half resolution, then the best one's
    neighbourhood at full resolution, so a 256 px view with a 26 px window
    takes a fraction of a second.
    """
    a = np.asarray(render, np.float32)
    r = np.asarray(ref, np.float32)
    m = np.asarray(region, bool)
    best = (0, 0)
    if max_shift > 0 and m.any():
        s = a.shape[0] - a.shape[0] % 2
        half = lambda v: v[:s, :s].reshape(s // 2, 2, s // 2, 2, *v.shape[2:]).mean(axis=(1, 3))
        a2, r2 = half(a), half(r)
        m2 = half(m[:s, :s].astype(np.float32)) > 0.999
        k = max(1, max_shift // 2)
        coarse = [(dx, dy) for dy in range(-k, k + 1) for dx in range(-k, k + 1)]
        errs = _mse_grid(a2, r2, m2, coarse)
        cx, cy = coarse[int(np.argmin(errs))]
        fine = [
            (dx, dy)
            for dy in range(2 * cy - 2, 2 * cy + 3)
            for dx in range(2 * cx - 2, 2 * cx + 3)
            if abs(dx) <= max_shift and abs(dy) <= max_shift
        ] + [(0, 0)]
        errs = _mse_grid(a, r, m, fine)
        best = fine[int(np.argmin(errs))]
    moved, inside = shifted(r, *best)
    region_after = m & inside
    return Shift(best[0], best[1], psnr(a, moved, region_after), region_after)
