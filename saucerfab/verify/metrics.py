"""Image agreement over a region: PSNR, SSIM and the best whole-picture shift.

Images are (S, S, 3) float sRGB in [0, 1]; a region is an (S, S) bool mask
of the pixels compared (where the saucer is seen). Numbers follow the usual
definitions so they compare with other tools':

* PSNR = 10 log10(1 / MSE), MSE over the region's pixels and the three channels;
  given the renders' own sampling noise (``noise``: an unbiased estimate of its
  variance per pixel, :func:`~saucerfab.verify.raytrace.sampling_variance`), the
  MSE is the image's less that variance: a noisy render's expected squared
  error is its true error plus its noise variance, and the score is of the
  print, not of the sample count (16 samples per pixel read a photo 1.3 dB low);
* SSIM (Wang et al. 2004): Gaussian window sigma 1.5 px, K1 = 0.01,
  K2 = 0.03, data range 1, per channel, averaged over the region's pixels
  and the channels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: PSNR reported for identical images (MSE 0), dB
PSNR_CAP_DB = 99.0


def psnr(a: np.ndarray, b: np.ndarray, region: np.ndarray, noise: np.ndarray | None = None) -> float:
    """PSNR in dB of ``a`` against ``b`` over ``region`` (NaN for an empty region).

    ``noise``: (S, S, 3) or (S, S), the variance of ``a - b`` from sampling
    alone (both pictures' if both are renders), estimated without bias; its
    mean over the region is taken out of the MSE (never below 0).
    """
    m = np.asarray(region, bool)
    if not m.any():
        return float("nan")
    mse = float(np.mean((np.asarray(a, np.float64)[m] - np.asarray(b, np.float64)[m]) ** 2))
    if noise is not None:
        mse = max(mse - float(np.mean(np.asarray(noise, np.float64)[m])), 0.0)
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


def mse_grid_reference(a: np.ndarray, ref: np.ndarray, region: np.ndarray, k: int) -> np.ndarray:
    """(2k+1, 2k+1) MSE of ``a`` against ``ref`` moved by every (dx, dy) in [-k, k]^2, one shift at a time.

    ``[dy + k, dx + k]`` is the MSE over ``region`` & (inside the moved
    frame); ``inf`` where that leaves under half the region. The slow,
    obvious version of :func:`mse_grid` (tests hold the two together).
    """
    out = np.full((2 * k + 1, 2 * k + 1), np.inf)
    need = max(1, int(region.sum()) // 2)
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            r, inside = shifted(ref, dx, dy)
            m = region & inside
            if m.sum() >= need:
                out[dy + k, dx + k] = float(np.mean((a[m] - r[m]) ** 2))
    return out


def mse_grid(a: np.ndarray, ref: np.ndarray, region: np.ndarray, k: int) -> np.ndarray:
    """:func:`mse_grid_reference` for every shift at once, by FFT cross-correlation.

    With ``m`` the region, ``I`` the frame's indicator and ``r_s`` the
    reference moved by ``s`` (zero outside the frame), the sums over pixels
    ``N(s) = sum m I_s``, ``A(s) = sum m |a|^2 I_s``, ``B(s) = sum m |r_s|^2``
    and ``C(s) = sum m a . r_s`` are correlations, and
    ``MSE(s) = (A + B - 2 C) / (3 N)``.

    The correlations are products of spectra (scipy.fft: each operand's
    spectrum taken once, 9 transforms forward and 4 back, where
    ``scipy.signal.fftconvolve`` would take 18, and without the 0.7 s that
    importing scipy.signal adds to every design's quick verify).
    """
    from scipy import fft

    a = np.asarray(a, np.float64)
    r = np.asarray(ref, np.float64)
    m = np.asarray(region, np.float64)
    h, w = m.shape
    # linear (not circular) correlation: transforms at least the full output's size
    shape = [fft.next_fast_len(2 * h - 1, real=True), fft.next_fast_len(2 * w - 1, real=True)]

    def spectrum(f: np.ndarray) -> np.ndarray:
        return fft.rfft2(f, shape)

    def window(product: np.ndarray) -> np.ndarray:
        # full[(h-1) + dy, (w-1) + dx] = sum_x f(x) g(x - s): the shifts within k
        full = fft.irfft2(product, shape)
        return full[h - 1 - k : h + k, w - 1 - k : w + k]

    def flipped(g: np.ndarray) -> np.ndarray:
        return spectrum(g[::-1, ::-1])

    s_m, s_ones = spectrum(m), flipped(np.ones((h, w)))
    n = window(s_m * s_ones)
    a2 = window(spectrum(m * (a * a).sum(-1)) * s_ones)
    b2 = window(s_m * flipped((r * r).sum(-1)))
    c = window(sum(spectrum(m * a[..., ch]) * flipped(r[..., ch]) for ch in range(a.shape[2])))
    n = np.rint(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        mse = np.maximum(a2 + b2 - 2 * c, 0.0) / (a.shape[2] * n)
    mse[n < max(1, int(m.sum()) // 2)] = np.inf
    return mse


def best_shift(render: np.ndarray, ref: np.ndarray, region: np.ndarray, max_shift: int,
               noise: np.ndarray | None = None) -> Shift:
    """The integer shift within ``max_shift`` px that maximises PSNR over ``region``.

    ``noise``: the render's sampling noise (:func:`psnr`), taken out of the
    shifted picture's PSNR; the search itself is not changed by it (the
    noise is nearly the same whatever the shift: only the pixels compared change).

    A shift that leaves under half the region inside the moved frame is not
    a match, however well it agrees. All shifts are scored at once
    (:func:`mse_grid`); ties go to the smaller shift.
    """
    a = np.asarray(render, np.float32)
    r = np.asarray(ref, np.float32)
    m = np.asarray(region, bool)
    best = (0, 0)
    if max_shift > 0 and m.any():
        k = int(max_shift)
        grid = mse_grid(a, r, m, k)
        dy, dx = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
        # tiny tie-break towards no shift, far below any real difference in MSE
        order = np.lexsort(((dx**2 + dy**2).ravel(), np.round(grid.ravel(), 9)))
        i = int(order[0])
        best = (int(dx.ravel()[i]), int(dy.ravel()[i]))
    moved, inside = shifted(r, *best)
    region_after = m & inside
    return Shift(best[0], best[1], psnr(a, moved, region_after, noise), region_after)
