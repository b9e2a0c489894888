"""Scores of a print under a real light (``saucerfab verify --light``, issue 45).

A lamp lights a print unevenly however it is made: the far side dimmer, a
slope facing the lamp brighter. What a print can be blamed for is the
pattern its relief adds to that. So each view is scored against the
reference picture lit by the light's **smooth part**:

1. ``white``: the print with every albedo white (:class:`~.lit.LitTracer`), the shading alone;
2. ``smooth``: ``white`` low-passed by normalized convolution over the pixels
   where the top is seen in the view's way (``G * (white m) / G * m``, ``m``
   those pixels, ``G`` a Gaussian of :data:`SMOOTH_SIGMA_FRACTION` of the
   frame: 32 px at 256), per channel: the light's falloff, not the relief's stripes;
3. ``reference_lit = reference * smooth * g`` in linear light (the reference's sRGB
   numbers made linear), ``g`` one gain per channel, the least-squares best over the
   compared pixels (it takes up the plastic's coat; ``smooth`` already holds the light's
   level and the cup's metal, which :attr:`~.results.LitViewScore.white_level` reports);
4. ``lit_psnr_db``: PSNR of the lit render against ``reference_lit``, both shown as sRGB
   (clipped to [0, 1], as a screen shows them), over the pixels the emitted score
   compares, less the render's own noise (:func:`~.metrics.psnr`): as the emitted
   colour pass, the picture is the mean of its two halves, each shown as sRGB, and
   half their difference estimates its noise (:func:`shown`). On the heart/star
   default export at 256 px from the design eye this reads 26.4 / 26.2 dB (direct)
   and 24.5 / 24.6 dB (reflected) at 16 / 64 samples a pixel (4: 26.7 and 22.9),
   where showing the halves' linear mean and carrying their difference through the
   curve's slope read 24.0 dB (reflected, 16 samples): the sRGB curve bends a noisy
   dark pixel's mean down.

The **shading pattern** is what the relief's shading alone does to a mid-grey
picture: PSNR of ``0.5 * white / smooth`` against 0.5 over the same pixels (noise
taken out likewise; 99 dB: no pattern above the render's noise), with the 5th
and 95th percentiles of ``white / smooth`` (mean over the channels; the render's
noise taken out of their spread, :func:`denoised_spread`). The same for a **flat
plate** over the saucer's footprint at the printed top's mean height
(:func:`~.lit.flat_plate`) under the same light, from the same eye, over the
pixels of the picture's rectangle where the plate is seen fully: the pattern no
print can avoid (the light's own falloff finer than ``G``, the cup's shadow and
glints; under the room light, none above the noise at 16 samples a pixel).

The **flat print** is that plate printed with the view's reference (each pixel's
plate point given the reference's colour there: the direct picture lying flat,
the reflected one as its anamorphic image), under the same light, scored as the
print is (:func:`flat_print`): the lit score a print without relief reaches
(``flat_print_lit_psnr_db``), the yardstick for the print's. What a flat print
misses of a perfect score: the plastic's coat, which adds the room's reflection
to every colour (one gain per channel cannot take up an added light: dark
colours lose most), the light's falloff finer than ``G``, the cup's shadow. It
is not a bound: a relief's slopes tilt the coat's reflection away from the
bright room (slopes facing the cup mirror the cup), so a print can score above
its flat print (measured: chelsea-coffee's reflected view, compensated, 30.4 dB
against the flat print's 23.6; ``benchmarks/results/light_session27.txt``). The
print is also compared with its flat print directly, both lit and shown as a
screen shows them, without a gain (``against_flat_print_psnr_db``): how far the
relief makes the print look from a flat print of the same pictures in that light.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.fabricate.scene_file import PrintScene, ViewSpec
from saucerfab.verify.lighting import (
    LightSpec,
    Metal,
    linear_to_srgb,
    plastic_dict,
    srgb_to_linear,
)
from saucerfab.verify.lit import LIT_INTEGRATOR, LitImage, LitTracer, flat_plate
from saucerfab.verify.metrics import psnr
from saucerfab.verify.printfolder import PrintedSurface
from saucerfab.verify.raytrace import FULL_COVERAGE, part_scene, render_part
from saucerfab.verify.results import LitViewScore

#: the smooth part's Gaussian, its sigma as a share of the frame's side
SMOOTH_SIGMA_FRACTION = 1.0 / 8.0


def smooth_part(white: np.ndarray, seen: np.ndarray, sigma_px: float) -> np.ndarray:
    """(S, S, 3) the light's smooth part: ``white`` (S, S, 3) low-passed by normalized convolution
    over ``seen`` (S, S) bool with a Gaussian of ``sigma_px``; NaN far from any seen pixel."""
    from scipy.ndimage import gaussian_filter

    m = np.asarray(seen, np.float64)
    den = gaussian_filter(m, sigma_px, mode="constant")
    out = np.empty(white.shape, np.float64)
    for c in range(white.shape[2]):
        num = gaussian_filter(np.asarray(white[..., c], np.float64) * m, sigma_px, mode="constant")
        out[..., c] = np.divide(num, den, out=np.full(den.shape, np.nan), where=den > 1e-9)
    return out


def best_gain(render: np.ndarray, base: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(3,) per channel the ``g`` minimising ``sum (render - g base)^2`` over ``region`` (0 where ``base`` is 0 there)."""
    m = np.asarray(region, bool)
    a = np.asarray(render, np.float64)[m]
    b = np.asarray(base, np.float64)[m]
    num, den = np.sum(a * b, axis=0), np.sum(b * b, axis=0)
    return np.divide(num, den, out=np.zeros(3), where=den > 0)


def display(lin: np.ndarray) -> np.ndarray:
    """Linear radiance (paper's units) as the sRGB picture a screen shows: clipped to [0, 1], float32."""
    return linear_to_srgb(np.clip(lin, 0.0, 1.0))


def shown(img: LitImage) -> tuple[np.ndarray, np.ndarray]:
    """``img`` as the sRGB picture a screen shows and its noise: (S, S, 3) the mean of its two halves each
    shown (:func:`display`), and (S, S, 3) the square of half their difference, an unbiased estimate of
    that mean's sampling variance (the halves are independent)."""
    a, b = display(img.rgb + img.half_diff), display(img.rgb - img.half_diff)
    return 0.5 * (a + b), np.square(0.5 * (a - b))


@dataclass(frozen=True)
class Pattern:
    """The shading pattern of one white render: ``db`` (PSNR of ``0.5 white / smooth`` against 0.5), and
    the 5th and 95th percentiles of ``white / smooth`` (mean over the channels) over the pixels compared."""

    db: float
    p5: float
    p95: float


def shading_pattern(white: LitImage, smooth: np.ndarray, region: np.ndarray) -> Pattern:
    """:class:`Pattern` of ``white`` against its ``smooth`` part over ``region`` (NaN when empty)."""
    m = np.asarray(region, bool) & np.all(np.isfinite(smooth), axis=2) & np.all(smooth > 0, axis=2)
    if not m.any():
        return Pattern(float("nan"), float("nan"), float("nan"))
    s = np.where(np.isfinite(smooth) & (smooth > 0), smooth, 1.0)
    ratio = white.rgb / s
    noise = 0.25 * np.square(white.half_diff / s)
    db = psnr(0.5 * ratio, np.full(ratio.shape, 0.5), m, noise)
    p5, p95 = np.percentile(denoised_spread(ratio.mean(axis=2)[m], (white.half_diff / s).mean(axis=2)[m]), [5, 95])
    return Pattern(float(db), float(p5), float(p95))


def denoised_spread(values: np.ndarray, half_diff: np.ndarray) -> np.ndarray:
    """``values`` (N,) drawn in towards their mean so that their variance is the render's less its noise.

    A pixel's value is its true value plus the render's noise, whose variance ``half_diff^2`` estimates
    (N,); the observed spread is wider than the print's. Each deviation from the mean is scaled by
    ``sqrt(max(V - noise, 0) / V)`` (``V`` the observed variance), so the percentiles read the print's
    spread, not the sample count's (a flat plate at 16 samples a pixel: 0.90-1.18x raw, 1.00-1.00x so).
    """
    mu = float(np.mean(values))
    v = float(np.var(values))
    if v <= 0.0:
        return values
    keep = math.sqrt(max(v - float(np.mean(np.square(half_diff))), 0.0) / v)
    return mu + (values - mu) * keep


@dataclass(frozen=True)
class LitComparison:
    """One view's lit score and the pictures behind it (:func:`compare_lit`).

    ``psnr_db``: the lit PSNR; ``gain``: (3,) the best gain per channel; ``white_level``: the white
    render's mean over the compared pixels; ``reference_lit``: (S, S, 3) linear, the reference under
    the smooth light; ``pattern``: the relief's shading pattern.
    """

    psnr_db: float
    gain: np.ndarray
    white_level: float
    reference_lit: np.ndarray
    pattern: Pattern


def compare_lit(lit: LitImage, white: LitImage, reference: np.ndarray, seen: np.ndarray, region: np.ndarray,
                sigma_px: float) -> LitComparison:
    """Score one lit view (module docstring).

    Args:
        lit, white: the lit and white renders. reference: (S, S, 3) sRGB in [0, 1], what the view
            should show (the emitted score's reference: the picture, or a moved eye's flat print).
        seen: (S, S) bool, where the top is seen fully in the view's way (the smooth part's support).
        region: (S, S) bool, the pixels compared (the emitted score's).
        sigma_px: the smooth part's Gaussian.
    """
    smooth = smooth_part(white.rgb, seen, sigma_px)
    m = np.asarray(region, bool) & np.all(np.isfinite(smooth), axis=2)
    base = srgb_to_linear(reference) * np.nan_to_num(smooth)
    gain = best_gain(lit.rgb, base, m)
    ref_lit = (base * gain).astype(np.float32)
    picture, noise = shown(lit)
    db = psnr(picture, display(ref_lit), m, noise)
    level = float(white.rgb[m].mean()) if m.any() else float("nan")
    return LitComparison(db, gain, level, ref_lit, shading_pattern(white, smooth, region))


def flat_print(black: LitImage, white: LitImage, reference: np.ndarray) -> LitImage:
    """The flat plate printed with ``reference`` (S, S, 3) sRGB in [0, 1], from its ``black`` and ``white``
    renders (the same view and samples count): ``black + a (white - black)`` per pixel, ``a`` the
    reference made linear (the plastic is linear in its albedo: :mod:`.lit`); its halves combine likewise."""
    a = srgb_to_linear(np.asarray(reference, np.float32))
    return LitImage((black.rgb + a * (white.rgb - black.rgb)).astype(np.float32),
                    (black.half_diff + a * (white.half_diff - black.half_diff)).astype(np.float32))


class LitViews:
    """Renders and scores every view of one print under a light: the lit print, the white print and the
    flat plate (:mod:`.lit`), from any eye.

    Args:
        surface: the primary file as read. scene: its scene.json. light: a real light. metal: the cup's.
        res, spp: render size and samples per pixel (the emitted verify's).
        seed: the renders' seed (:meth:`~.lit.LitTracer.render`).
    """

    def __init__(self, surface: PrintedSurface, scene: PrintScene, light: LightSpec, metal: Metal, res: int,
                 spp: int, *, seed: int = 0) -> None:
        t0 = time.perf_counter()
        self.light, self.metal, self.res, self.spp, self.seed = light, metal, res, spp, seed
        self.tracer = LitTracer(surface, scene, light, metal)
        plate = flat_plate(surface, scene)
        self.plate = LitTracer(plate, scene, light, metal)
        self.plate_cover = part_scene(plate, scene.cup)  # where the plate is seen, directly or in the cup
        self.sigma_px = SMOOTH_SIGMA_FRACTION * res
        self.seconds = time.perf_counter() - t0  # building the scenes, then each view's renders and scores

    def score(self, eye_name: str, eye: tuple[float, float, float], view_name: str, view: ViewSpec,
              seen: np.ndarray, region: np.ndarray, reference: np.ndarray, in_picture: np.ndarray,
              pictures: Path | None, box: tuple[slice, slice]) -> LitViewScore:
        """Render ``view`` from ``eye`` lit, white and as the flat plate; score it (:func:`compare_lit`) and
        write ``<eye>_<view>_lit.png`` into ``pictures`` (cropped to ``box``, the picture's rectangle).

        Args:
            seen: (S, S) bool, where the print's top is seen fully in the view's way (the emitted render's coverage).
            region, reference: the emitted score's compared pixels and reference (sRGB).
            in_picture: (S, S) bool, the picture's rectangle in the frame.
        """
        t0 = time.perf_counter()
        res, spp = self.res, self.spp
        lit = self.tracer.render("lit", eye, view, res, spp, seed=self.seed)
        white = self.tracer.render("white", eye, view, res, spp, seed=self.seed)
        cmp = compare_lit(lit, white, reference, seen, region, self.sigma_px)
        plate_white = self.plate.render("white", eye, view, res, spp, seed=self.seed)
        plate_black = self.plate.render("black", eye, view, res, spp, seed=self.seed)
        cover = render_part(self.plate_cover, eye, view, res, spp)
        plate_seen = (cover.direct if view_name == "direct" else cover.reflected) >= FULL_COVERAGE
        plate_smooth = smooth_part(plate_white.rgb, plate_seen, self.sigma_px)
        flat = shading_pattern(plate_white, plate_smooth, plate_seen & in_picture)
        printed_flat = flat_print(plate_black, plate_white, reference)
        flat_cmp = compare_lit(printed_flat, plate_white, reference, plate_seen, region & plate_seen, self.sigma_px)
        # the print against its flat print, both under this light and shown as a screen shows them: the relief's
        # own cost, no gain (both are the same plastic); the two renders' noise taken out
        (seen_lit, noise_lit), (seen_flat, noise_flat) = shown(lit), shown(printed_flat)
        against_flat = psnr(seen_lit, seen_flat, region & plate_seen, noise_lit + noise_flat)
        score = LitViewScore(view_name, eye_name, cmp.psnr_db, tuple(float(g) for g in cmp.gain), cmp.white_level,
                             cmp.pattern.db, cmp.pattern.p5, cmp.pattern.p95, flat.db, flat.p5, flat.p95,
                             int(np.sum(region)), flat_print_lit_psnr_db=flat_cmp.psnr_db,
                             against_flat_print_psnr_db=against_flat)
        if pictures is not None:
            score.picture = write_lit_picture(pictures, f"{eye_name}_{view_name}_lit", score, lit.rgb[box],
                                              cmp.reference_lit[box], white.rgb[box], printed_flat.rgb[box])
        self.seconds += time.perf_counter() - t0
        return score

    def record(self) -> dict[str, Any]:
        """What the light, the materials and the scoring were, for verify.json's ``light``."""
        return {**self.light.to_dict(), "cup_metal": self.metal.to_dict(), "plastic": plastic_dict(),
                "integrator": dict(LIT_INTEGRATOR), "smooth_sigma_px": round(self.sigma_px, 3)}


def write_lit_picture(folder: Path, stem: str, score: LitViewScore, lit: np.ndarray, reference_lit: np.ndarray,
                      white: np.ndarray, flat_lit: np.ndarray) -> str:
    """Write the lit view, the reference under the smooth light, the shading alone and the flat print
    under the same light side by side as ``folder/stem.png`` (atomically); returns the file's name.
    Arrays are linear."""
    from saucerfab.files.fileio import write_bytes_atomic
    from saucerfab.imaging.panels import side_by_side, to_png_bytes

    img = side_by_side(
        [
            (f"lit: {score.view}, {score.eye} eye, {score.lit_psnr_db:.1f} dB", display(lit)),
            ("meant, under the light's smooth part", display(reference_lit)),
            (f"shading alone: pattern {score.shading_pattern_db:.1f} dB", display(white)),
            (f"a flat print, lit: {score.flat_print_lit_psnr_db:.1f} dB", display(flat_lit)),
        ],
        height=max(256, lit.shape[0]),
    )
    return write_bytes_atomic(folder / f"{stem}.png", to_png_bytes(img)).name
