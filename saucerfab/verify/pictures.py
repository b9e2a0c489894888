"""Verify's pictures: the ray-traced view, the reference and a difference heat map, side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.verify.results import REFERENCE_PICTURE, ViewScore, WholeViewScore

#: absolute difference (mean over RGB, sRGB units) shown at the top of the heat map's scale
HEAT_MAX = 0.5
#: grey of pixels not compared (the saucer is not seen fully there)
NOT_COMPARED = (0.35, 0.35, 0.35)


def difference_map(render: np.ndarray, ref: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(S, S, 3) float: |render - ref| averaged over RGB, 0..HEAT_MAX on ``magma``; grey outside ``region``."""
    from saucerfab.imaging.colormaps import colormap

    d = np.abs(np.asarray(render, np.float32) - np.asarray(ref, np.float32)).mean(axis=2)
    heat = colormap("magma", d / HEAT_MAX).astype(np.float32) / 255.0
    heat[~np.asarray(region, bool)] = NOT_COMPARED
    return heat


def view_picture(render: np.ndarray, ref: np.ndarray, region: np.ndarray, score: ViewScore) -> np.ndarray:
    """The three panels as one (H, W, 3) uint8 picture, titled with the scores."""
    from saucerfab.imaging.panels import side_by_side

    meant = "meant" if score.reference == REFERENCE_PICTURE else "a flat print, from this eye"
    return side_by_side(
        [
            (f"printed: {score.view}, {score.eye} eye", render),
            (meant, ref),
            (f"|difference| {score.psnr_db:.1f} dB, SSIM {score.ssim:.2f}", difference_map(render, ref, region)),
        ],
        height=max(256, render.shape[0]),
    )


def write_view_picture(folder: Path, stem: str, render: np.ndarray, ref: np.ndarray, region: np.ndarray,
                       score: ViewScore) -> Path:
    """Write :func:`view_picture` as ``folder/stem.png`` (atomically); returns the path."""
    from saucerfab.files.fileio import write_bytes_atomic
    from saucerfab.imaging.panels import to_png_bytes

    return write_bytes_atomic(folder / f"{stem}.png", to_png_bytes(view_picture(render, ref, region, score)))


def whole_picture(wv: Any, score: WholeViewScore) -> np.ndarray:
    """The whole view, its ideal and the stray map (:mod:`.wholeview`) as one (H, W, 3) uint8 picture, titled."""
    from saucerfab.imaging.panels import side_by_side
    from saucerfab.verify.wholeview import stray_map

    def pct(x: float) -> str:
        return "--" if x != x else f"{x * 100:.0f}%"

    return side_by_side(
        [
            (f"whole view, {score.eye} eye, {score.psnr_db:.1f} dB", wv.rgb),
            ("meant (grey: not scored)", wv.ideal),
            (f"stray: saucer {pct(score.stray_direct)}, mirror {pct(score.stray_reflected)}", stray_map(wv)),
        ],
        height=max(256, wv.rgb.shape[0]),
    )


def write_whole_picture(folder: Path, stem: str, wv: Any, score: WholeViewScore) -> Path:
    """Write :func:`whole_picture` as ``folder/stem.png`` (atomically); returns the path."""
    from saucerfab.files.fileio import write_bytes_atomic
    from saucerfab.imaging.panels import to_png_bytes

    return write_bytes_atomic(folder / f"{stem}.png", to_png_bytes(whole_picture(wv, score)))
