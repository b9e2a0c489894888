"""Previews for people: PNG encoding, height-change maps, panels, energy plots, HTML.

Everything here makes pictures of results; nothing feeds back into the
design. Images go in as arrays in the usual orientation (row 0 at the top,
as :mod:`saucerfab.render.camera` defines) and come out as (H, W, 3) uint8
arrays or PNG bytes; writing files is the caller's job (atomically, with
:mod:`saucerfab.fileio`).

Matplotlib is imported lazily, inside the functions that plot, and used
through its object API (``Figure`` + the Agg canvas): no pyplot, no global
backend switch, no display needed, safe in worker processes.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from saucerfab.imageio import png_bytes

#: energy series drawn by :func:`energy_plot`, with their colours
ENERGY_KEYS = (
    ("E_total", "black"),
    ("E_visual", "tab:blue"),
    ("E_deform", "tab:orange"),
    ("E_sparse", "tab:green"),
)


# --------------------------------------------------------------------------- arrays and PNG


def as_uint8_rgb(image: np.ndarray) -> np.ndarray:
    """Any displayable image as (H, W, 3) uint8.

    Accepts (H, W) or (H, W, 1) grey, (H, W, 3) RGB or (H, W, 4) RGBA
    (composited over white), as bool (True = white), uint8, uint16 (full
    range), or float in [0, 1] (clipped, rounded).

    Raises:
        ValueError: another shape or dtype, or NaN/inf values.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {a.shape}")
    if a.dtype == bool:
        f = a.astype(np.float32)
    elif a.dtype == np.uint8:
        f = a.astype(np.float32) / 255.0
    elif a.dtype == np.uint16:
        f = a.astype(np.float32) / 65535.0
    elif np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)):
            raise ValueError("image holds NaN or infinite values")
        f = np.clip(a.astype(np.float32), 0.0, 1.0)
    else:
        raise ValueError(f"unsupported image dtype {a.dtype}")
    if f.ndim == 2:
        f = np.repeat(f[..., None], 3, axis=2)
    elif f.shape[2] == 4:
        alpha = f[..., 3:4]
        f = f[..., :3] * alpha + (1.0 - alpha)
    if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] == 3:
        return np.ascontiguousarray(a)  # exact, no round trip through float
    return np.round(f * 255.0).astype(np.uint8)


def to_png_bytes(image: np.ndarray) -> bytes:
    """PNG file bytes of ``image`` (anything :func:`as_uint8_rgb` takes), 8-bit RGB."""
    return png_bytes(as_uint8_rgb(image))


def _render_figure(fig) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(H, W, 3) uint8 pixels of a matplotlib Figure drawn by the Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def _figure_png(fig) -> bytes:  # type: ignore[no-untyped-def]
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


# --------------------------------------------------------------------------- height changes


def height_change_map(
    base: np.ndarray,
    heights: np.ndarray,
    delta: float,
    *,
    units: Literal["delta", "model"] = "delta",
    extent: tuple[float, float, float, float] | None = None,
    title: str | None = "|h - z|",
    size_px: tuple[int, int] = (480, 400),
    cmap: str = "viridis",
) -> np.ndarray:
    """Colour-coded absolute height change ``|h - z|`` (paper, Figure 8 bottom row).

    The saucer is drawn as the viewer sees it from the camera (which looks
    along +y): x to the right and the far edge (large y, the last grid row)
    at the top. The colour scale runs from 0 to the bound ``delta`` with a
    colourbar, in units of delta (0..1) or of the model.

    Args:
        base: (N, N) base heights z, model units; ``base[i, j]`` at
            ``y = ys[i]``, ``x = xs[j]`` (see :mod:`saucerfab.heightfield`).
        heights: (N, N) final heights h, model units.
        delta: the height bound, model units (> 0).
        units: colourbar in multiples of ``delta`` or in model units.
        extent: (x0, x1, y0, y1) of the footprint, model units, for the axes
            ticks; None: no ticks.
        title: figure title, or None.
        size_px: (width, height) of the picture, pixels.
        cmap: a perceptually uniform matplotlib colormap.
    Returns:
        (size_px[1], size_px[0], 3) uint8.
    """
    from matplotlib.figure import Figure

    z = np.asarray(base, np.float64)
    h = np.asarray(heights, np.float64)
    if z.shape != h.shape or z.ndim != 2:
        raise ValueError(f"base {z.shape} and heights {h.shape} must be the same (N, N) shape")
    if not (delta > 0 and math.isfinite(delta)):
        raise ValueError(f"delta must be a positive number, got {delta!r}")
    change = np.abs(h - z)
    scale = delta if units == "delta" else 1.0
    label = "|h - z| / delta" if units == "delta" else "|h - z| (model units)"
    dpi = 100
    fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    ax = fig.add_subplot(1, 1, 1)
    # origin="lower": grid row 0 (smallest y, nearest the viewer) at the
    # bottom, the far edge at the top, as seen from the camera.
    im = ax.imshow(
        change / scale,
        origin="lower",
        cmap=cmap,
        vmin=0.0,
        vmax=delta / scale,
        interpolation="nearest",
        extent=extent,
        aspect="equal",  # model units are the same along x and y
    )
    if extent is None:
        ax.set_xticks([])
        ax.set_yticks([])
    else:
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    if title:
        ax.set_title(title)
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label(label)
    fig.tight_layout()
    return _render_figure(fig)


# --------------------------------------------------------------------------- panels


def _font(size: int):  # type: ignore[no-untyped-def]
    """Pillow's built-in font at ``size`` px (needs FreeType), else its bitmap font."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except (OSError, ImportError, TypeError, ValueError):
        return ImageFont.load_default()


def side_by_side(
    panels: Sequence[tuple[str, np.ndarray]],
    *,
    height: int = 256,
    gap: int = 8,
    title_px: int = 16,
    background: tuple[int, int, int] = (255, 255, 255),
) -> np.ndarray:
    """Images in a row, each scaled to ``height`` pixels high, with its title above.

    Args:
        panels: (title, image) pairs; images as :func:`as_uint8_rgb` takes.
        height: panel height in pixels (aspect ratios are kept).
        gap: pixels between and around panels.
        title_px: title font size in pixels.
    Returns:
        (H, W, 3) uint8 with ``H = height + title band + 2 gap``.
    """
    from PIL import Image, ImageDraw

    if not panels:
        raise ValueError("side_by_side needs at least one panel")
    font = _font(title_px)
    band = title_px + 8
    tiles = []
    for _, img in panels:
        rgb = as_uint8_rgb(img)
        h, w = rgb.shape[:2]
        nw = max(1, round(w * height / h))
        pim = Image.fromarray(rgb)
        if (nw, height) != (w, h):
            # nearest for upscaling small renders keeps pixels honest;
            # Lanczos for shrinking avoids aliasing
            resample = Image.Resampling.NEAREST if height >= h else Image.Resampling.LANCZOS
            pim = pim.resize((nw, height), resample)
        tiles.append(pim)
    total_w = sum(t.width for t in tiles) + gap * (len(tiles) + 1)
    total_h = height + band + 2 * gap
    sheet = Image.new("RGB", (total_w, total_h), background)
    draw = ImageDraw.Draw(sheet)
    x = gap
    for (title, _), tile in zip(panels, tiles):
        text = str(title)
        # shorten titles wider than their panel rather than overlap the next one
        if draw.textlength(text, font=font) > tile.width:
            while len(text) > 1 and draw.textlength(text + "\u2026", font=font) > tile.width:
                text = text[:-1]
            text += "\u2026"
        draw.text((x, gap), text, fill=(0, 0, 0), font=font)
        sheet.paste(tile, (x, gap + band))
        x += tile.width + gap
    return np.asarray(sheet).copy()


def mask_overlay(
    image: np.ndarray,
    mask: np.ndarray,
    *,
    colour: tuple[float, float, float] = (1.0, 0.0, 0.0),
    opacity: float = 0.4,
    outline: bool = True,
) -> np.ndarray:
    """Show a foreground mask on its image: foreground tinted, its boundary drawn solid.

    Args:
        image: (H, W[, 3|4]) image as :func:`as_uint8_rgb` takes.
        mask: (H, W) bool, True on the foreground.
        colour: tint colour, floats in [0, 1].
        opacity: tint strength in [0, 1] over the foreground.
        outline: draw the mask's one-pixel inner boundary in ``colour``.
    Returns:
        (H, W, 3) uint8.
    """
    rgb = as_uint8_rgb(image).astype(np.float32) / 255.0
    m = np.asarray(mask, bool)
    if m.shape != rgb.shape[:2]:
        raise ValueError(f"mask {m.shape} does not match image {rgb.shape[:2]}")
    c = np.asarray(colour, np.float32).reshape(1, 1, 3)
    out = np.where(m[..., None], rgb * (1.0 - opacity) + c * opacity, rgb)
    if outline:
        from scipy import ndimage

        edge = m & ~ndimage.binary_erosion(m, border_value=1)
        out[edge] = c[0, 0]
    return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)


def composite(direct_view: np.ndarray, reflected_view: np.ndarray, reflected_alpha: np.ndarray) -> np.ndarray:
    """Alpha-blend the reflected layer over the direct layer, pixel by pixel.

    An image-level helper: both layers must already be in the same camera
    frame and size (e.g. the hard renderer's saucer layer and its cup layer
    as seen from the camera). The direct and reflected *view frames* of the
    optimizer are different cameras; pasting those together is not what a
    viewer sees.

    Args:
        direct_view: (S, S, 3) layer underneath.
        reflected_view: (S, S, 3) layer on top.
        reflected_alpha: (S, S) float in [0, 1] (or bool) coverage of the top layer.
    Returns:
        (S, S, 3) uint8.
    """
    lower = as_uint8_rgb(direct_view).astype(np.float32)
    upper = as_uint8_rgb(reflected_view).astype(np.float32)
    a = np.clip(np.asarray(reflected_alpha, np.float32), 0.0, 1.0)
    if lower.shape != upper.shape or a.shape != lower.shape[:2]:
        raise ValueError(f"layer shapes differ: {lower.shape}, {upper.shape}, alpha {a.shape}")
    out = lower * (1.0 - a[..., None]) + upper * a[..., None]
    return np.round(out).astype(np.uint8)


# --------------------------------------------------------------------------- energies


def _series(log: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    vals = []
    for row in log:
        v = row.get(key)
        try:
            vals.append(float(v) if v is not None else math.nan)
        except (TypeError, ValueError):
            vals.append(math.nan)
    return np.asarray(vals, np.float64)


def _elapsed(log: Sequence[Mapping[str, Any]]) -> np.ndarray:
    """Elapsed seconds per row; a clock that restarts at a stage boundary is chained on."""
    t = _series(log, "time_s")
    if np.isnan(t).all():
        return _series(log, "iteration")
    t = np.where(np.isnan(t), 0.0, t)
    out = np.empty_like(t)
    offset = 0.0
    prev = -math.inf
    for k, v in enumerate(t):
        if v + offset < prev:  # the stage's own clock started again
            offset = prev
        out[k] = v + offset
        prev = out[k]
    return out


def energy_plot(
    log: Sequence[Mapping[str, Any]],
    *,
    title: str | None = "Energies over time",
    size_px: tuple[int, int] = (720, 420),
) -> bytes:
    """A plot of the optimizer's energies against time, per stage (paper, Figure 10).

    Args:
        log: one mapping per iteration with ``stage`` (str), ``iteration``,
            ``time_s`` (seconds since the run started; a per-stage clock that
            restarts at each stage is chained on), and any of ``E_visual``,
            ``E_deform``, ``E_sparse``, ``E_total`` (missing or None: not
            drawn for that row).
        title: plot title or None.
        size_px: (width, height) in pixels.
    Returns:
        PNG bytes. The y axis is logarithmic when every drawn value is
        positive, symmetric-log otherwise (the barrier terms can make the
        total negative); stage boundaries are dashed lines with the stage name.
    """
    from matplotlib.figure import Figure

    if not log:
        raise ValueError("energy_plot needs a non-empty log")
    x = _elapsed(log)
    stages = [str(row.get("stage", "")) for row in log]
    dpi = 100
    fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    ax = fig.add_subplot(1, 1, 1)
    # stage boundaries: where the stage name changes
    starts = [0] + [k for k in range(1, len(stages)) if stages[k] != stages[k - 1]]
    spans = list(zip(starts, starts[1:] + [len(stages)]))
    series = {key: _series(log, key) for key, _ in ENERGY_KEYS}
    finite = [y[~np.isnan(y)] for y in series.values()]
    values = np.concatenate(finite) if finite else np.zeros(0)
    negative = bool((values < 0).any())
    drawn = False
    for key, colour in ENERGY_KEYS:
        y = series[key]
        if np.isnan(y).all():
            continue
        if not negative:
            # on a log axis an exact 0 (E_sparse at its stage's start,
            # E_deform before anything moved) is left out, not clamped
            y = np.where(y > 0, y, np.nan)
        # one line per stage: a jump between stages (new sigma, new terms)
        # is a change of problem, not a step of the solver
        for n, (a, b) in enumerate(spans):
            ax.plot(
                x[a:b],
                y[a:b],
                color=colour,
                lw=1.4 if key == "E_total" else 1.1,
                marker="." if b - a == 1 else None,  # a one-row stage still shows
                label=key if n == 0 else None,
            )
        drawn = True
    if negative:
        nonzero = np.abs(values[values != 0])
        ax.set_yscale("symlog", linthresh=float(nonzero.min()) if nonzero.size else 1.0)
    elif drawn and np.nanmax(values, initial=0.0) > 0:
        ax.set_yscale("log")
    labels = []
    for n, k in enumerate(starts):
        if n > 0:
            ax.axvline(x[k], color="0.4", ls="--", lw=0.9)
        labels.append(ax.annotate(
            stages[k],
            xy=(x[k], 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(3, -12),
            textcoords="offset points",
            fontsize=8,
            color="0.25",
        ))
    has_time = not np.isnan(_series(log, "time_s")).all()
    ax.set_xlabel("time (s)" if has_time else "iteration")
    ax.set_ylabel("energy")
    if title:
        ax.set_title(title)
    if drawn:
        ax.legend(loc="best", fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    _stagger_labels(fig, labels)
    return _figure_png(fig)


def _stagger_labels(fig, labels: Sequence[Any]) -> None:  # type: ignore[no-untyped-def]
    """Move each stage label down a row until its box meets no earlier label's.

    Short stages start close together, so their names would print over
    each other on one row; measured after the layout, in pixels.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    placed: list[Any] = []
    for ann in labels:
        for row in range(len(labels)):
            ann.xyann = (3, -12 - 11 * row)
            box = ann.get_window_extent(renderer).padded(1.0)
            if not any(box.overlaps(b) for b in placed):
                break
        placed.append(box)


# --------------------------------------------------------------------------- HTML


@dataclass
class Section:
    """One section of an HTML report.

    Attributes:
        title: heading.
        text: paragraph text (plain text; escaped).
        images: (caption, image) pairs; image is PNG bytes (embedded as a
            data URI) or a relative path/URL string (linked as is).
        table: key -> value rows (values shown with ``str``), or None.
        grid: (column headings, rows) of a table with columns, or None.
        html: markup inserted as is after the images (trusted: made by
            saucerfab, e.g. the 3D viewer), or "".
    """

    title: str
    text: str = ""
    images: list[tuple[str, bytes | str]] = field(default_factory=list)
    table: Mapping[str, Any] | None = None
    grid: tuple[Sequence[str], Sequence[Sequence[Any]]] | None = None
    html: str = ""


_CSS = (
    "body{font-family:system-ui,sans-serif;margin:2em;max-width:72em;color:#222}"
    "h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em}"
    "figure{display:inline-block;margin:.5em 1em .5em 0;vertical-align:top}"
    "figure img{max-width:32em;border:1px solid #ddd}figcaption{font-size:.9em;color:#555}"
    "table{border-collapse:collapse}td,th{border:1px solid #ddd;padding:.2em .6em;text-align:left}"
)


def html_report(sections: Sequence[Section | Mapping[str, Any]], *, title: str = "saucerfab report") -> str:
    """A small self-contained HTML page: headings, text, images, key-value tables.

    Args:
        sections: :class:`Section` objects or mappings with the same keys.
        title: page title and top heading.
    Returns:
        The HTML document as a string (UTF-8 when written). PNG bytes are
        embedded as base64 data URIs, so the page works on its own; string
        image references are kept as relative links.
    """
    esc = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{esc(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
    ]
    for raw in sections:
        sec = raw if isinstance(raw, Section) else Section(**dict(raw))
        parts.append(f"<section><h2>{esc(sec.title)}</h2>")
        if sec.text:
            parts.append(f"<p>{esc(sec.text)}</p>")
        for caption, img in sec.images:
            if isinstance(img, (bytes, bytearray)):
                src = "data:image/png;base64," + base64.b64encode(bytes(img)).decode("ascii")
            else:
                src = esc(str(img), quote=True)
            parts.append(
                f'<figure><img src="{src}" alt="{esc(caption, quote=True)}">'
                f"<figcaption>{esc(caption)}</figcaption></figure>"
            )
        if sec.html:
            parts.append(sec.html)
        if sec.table:
            rows = "".join(
                f"<tr><th>{esc(str(k))}</th><td>{esc(str(v))}</td></tr>" for k, v in sec.table.items()
            )
            parts.append(f"<table>{rows}</table>")
        if sec.grid:
            heads, body = sec.grid
            head = "".join(f"<th>{esc(str(h))}</th>" for h in heads)
            rows = "".join("<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in r) + "</tr>" for r in body)
            parts.append(f"<table><tr>{head}</tr>{rows}</table>")
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
