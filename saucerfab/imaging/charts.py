"""Charts of a design drawn with Pillow: the energy plot and the height-change map.

A design's previews hold two charts (paper, Figure 8 bottom row and Figure
10). They are drawn here with Pillow's ``ImageDraw`` and its built-in
FreeType font rather than with matplotlib: importing matplotlib and laying
out two figures took 1.2-1.5 s of every ``saucerfab design`` (a twentieth of
the default design; issue 18), this takes a few tens of milliseconds. The
colour maps are :mod:`saucerfab.imaging.colormaps`.

Drawing is done at :data:`SUPERSAMPLE` times the asked size and reduced
(box filter), so that slanted lines are anti-aliased.

Coordinates: pixels, x to the right, y down, of the picture being drawn.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from saucerfab.imaging.colormaps import colormap

#: drawing scale: charts are drawn this many times larger, then reduced (anti-aliasing)
SUPERSAMPLE = 2

#: energy series drawn by :func:`energy_plot`, with their colours (matplotlib's
#: black, tab:blue, tab:purple, tab:orange, tab:green)
ENERGY_KEYS: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("E_total", (0, 0, 0)),
    ("E_visual", (31, 119, 180)),
    ("E_surround", (148, 103, 189)),
    ("E_deform", (255, 127, 14)),
    ("E_sparse", (44, 160, 44)),
)

INK = (0, 0, 0)
GRID = (226, 226, 226)
STAGE_LINE = (102, 102, 102)
STAGE_TEXT = (64, 64, 64)
PAGE = (255, 255, 255)

#: font sizes in pixels of the finished chart
TITLE_PX = 14
LABEL_PX = 12
TICK_PX = 10
SMALL_PX = 9

Box = tuple[float, float, float, float]  # (x0, y0, x1, y1), pixels


def font(size: float):  # type: ignore[no-untyped-def]
    """Pillow's built-in font at ``size`` px (its FreeType face), else its bitmap font."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=max(1, round(size)))
    except (OSError, ImportError, TypeError, ValueError):
        return ImageFont.load_default()


# --------------------------------------------------------------------------- axes


def _nice_step(span: float, target: int = 6) -> float:
    """A step of 1, 2, 2.5 or 5 times a power of ten giving about ``target`` ticks over ``span``."""
    raw = span / max(target, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if m * power >= raw:
            return m * power
    return 10.0 * power


def _decimals(step: float) -> int:
    """Decimals that print every multiple of ``step`` exactly (0.25 -> 2, 2.5 -> 1, 50 -> 0)."""
    for d in range(0, 10):
        if abs(round(step * 10**d) - step * 10**d) < 1e-9 * max(1.0, step * 10**d):
            return d
    return 10


@dataclass(frozen=True)
class Axis:
    """One axis of a chart: its scale, its range (in the scale's own units) and its ticks.

    Attributes:
        scale: ``linear``; ``log`` (log10 of the value); ``symlog``
            (``sign(v) * log10(1 + |v| / linthresh)``: linear near 0, log
            beyond, for values of both signs).
        lo, hi: the visible range, in scaled units (``lo < hi``).
        linthresh: the symlog scale's linear range (> 0).
    """

    scale: Literal["linear", "log", "symlog"]
    lo: float
    hi: float
    linthresh: float = 1.0

    def scaled(self, v: np.ndarray) -> np.ndarray:
        """Values -> scaled units (NaN where the scale has no place for them: log of <= 0)."""
        v = np.asarray(v, np.float64)
        if self.scale == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(v > 0, np.log10(np.where(v > 0, v, 1.0)), np.nan)
        if self.scale == "symlog":
            return np.sign(v) * np.log10(1.0 + np.abs(v) / self.linthresh)
        return v

    def to_px(self, v: np.ndarray, p0: float, p1: float) -> np.ndarray:
        """Values -> pixels, ``lo`` at ``p0`` and ``hi`` at ``p1``."""
        return p0 + (self.scaled(v) - self.lo) / (self.hi - self.lo) * (p1 - p0)

    def ticks(self) -> list[tuple[float, str]]:
        """(value, label) of the major ticks inside the range; labels ``10^k`` are written ``10**k``."""
        if self.scale == "linear":
            step = _nice_step(self.hi - self.lo)
            d = _decimals(step)
            first = math.ceil(self.lo / step - 1e-9)
            out = []
            for k in range(first, first + 1000):
                v = k * step
                if v > self.hi + 1e-9 * step:
                    break
                out.append((v, f"{v:.{d}f}" if abs(v) > 1e-12 * step else f"{0:.{d}f}"))
            return out
        if self.scale == "log":
            k0, k1 = math.ceil(self.lo - 1e-9), math.floor(self.hi + 1e-9)
            every = max(1, math.ceil((k1 - k0 + 1) / 8))  # at most about 8 labels
            if k1 - k0 >= 1:
                return [(10.0**k, f"10**{k}") for k in range(k0, k1 + 1) if (k - k0) % every == 0]
            # less than a decade visible: 1, 2, 5 times powers of ten
            out = []
            for k in range(math.floor(self.lo) - 1, math.ceil(self.hi) + 1):
                for m in (1, 2, 5):
                    v = m * 10.0**k
                    if self.lo - 1e-9 <= math.log10(v) <= self.hi + 1e-9:
                        out.append((v, f"{v:g}"))
            return out
        # symlog: 0 and +-10**k beyond the linear range
        out = []
        if self.lo <= 0.0 <= self.hi:
            out.append((0.0, "0"))
        k_min = math.ceil(math.log10(self.linthresh) - 1e-9)
        for sign in (1.0, -1.0):
            for k in range(k_min, k_min + 40):
                v = sign * 10.0**k
                s = float(self.scaled(np.array(v)))
                if not (self.lo - 1e-9 <= s <= self.hi + 1e-9):
                    if abs(s) > max(abs(self.lo), abs(self.hi)):
                        break
                    continue
                out.append((v, ("-" if sign < 0 else "") + f"10**{k}"))
        if len(out) > 9:  # thin out the decades, keep 0
            out = [t for n, t in enumerate(sorted(out)) if t[0] == 0.0 or n % 2 == 0]
        return sorted(out)


def _fit_range(values: np.ndarray, margin: float = 0.05) -> tuple[float, float]:
    """(lo, hi) covering the finite ``values`` with ``margin`` of their span on each side."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    span = hi - lo
    if span <= 1e-12 * max(1.0, abs(hi)):
        pad = 0.5 if abs(hi) < 1e-12 else 0.05 * abs(hi)
        return lo - pad, hi + pad
    return lo - margin * span, hi + margin * span


# --------------------------------------------------------------------------- drawing helpers


class _Canvas:
    """A Pillow RGB picture drawn at :data:`SUPERSAMPLE` scale; sizes in the finished picture's pixels."""

    def __init__(self, size_px: tuple[int, int]) -> None:
        from PIL import Image, ImageDraw

        self.size = size_px
        self.s = SUPERSAMPLE
        self.image = Image.new("RGB", (size_px[0] * self.s, size_px[1] * self.s), PAGE)
        self.draw = ImageDraw.Draw(self.image)
        self._fonts: dict[float, Any] = {}

    def font(self, px: float):  # type: ignore[no-untyped-def]
        if px not in self._fonts:
            self._fonts[px] = font(px * self.s)
        return self._fonts[px]

    def _ink(self, text: str, px: float) -> tuple[float, float, float, float]:
        """(left, top, width, height) of ``text``'s ink drawn at (0, 0), drawing pixels."""
        box = self.draw.textbbox((0, 0), text, font=self.font(px), anchor="la")
        return box[0], box[1], box[2] - box[0], box[3] - box[1]

    def text_size(self, text: str, px: float) -> tuple[float, float]:
        """(width, height) of ``text``'s ink (plain, or ``10**k`` written as a power), finished pixels."""
        if "**" in text:
            base, exp = text.split("**", 1)
            w1, h1 = self.text_size(base, px)
            w2, h2 = self.text_size(exp, px * 0.75)
            return w1 + 1.0 + w2, max(h1 + 0.45 * h2, h2)
        return tuple(v / self.s for v in self._ink(text, px)[2:])  # type: ignore[return-value]

    def text(self, xy: tuple[float, float], text: str, px: float, *, anchor: str = "la",
             fill: tuple[int, int, int] = INK) -> Box:
        """Draw ``text``, its ink box anchored at ``xy`` as Pillow's ``anchor`` names (l/m/r, a/m/d);
        ``10**k`` is drawn as a power. Returns the ink box."""
        w, h = self.text_size(text, px)
        x = xy[0] - {"l": 0.0, "m": w / 2, "r": w}[anchor[0]]
        y = xy[1] - {"a": 0.0, "m": h / 2, "d": h}[anchor[1]]
        if "**" in text:
            base, exp = text.split("**", 1)
            wb, hb = self.text_size(base, px)
            self._put((x, y + h - hb), base, px, fill)
            self._put((x + wb + 1.0, y), exp, px * 0.75, fill)
        else:
            self._put((x, y), text, px, fill)
        return (x, y, x + w, y + h)

    def line_of_text(self, xy: tuple[float, float], text: str, px: float,
                     fill: tuple[int, int, int] = INK) -> Box:
        """``text`` as a line of type (its ascender at ``xy``'s y, so that names sit on one baseline); its box."""
        ascent, descent = self.font(px).getmetrics()
        width = self.draw.textlength(text, font=self.font(px)) / self.s
        self.draw.text((xy[0] * self.s, xy[1] * self.s), text, font=self.font(px), fill=fill, anchor="la")
        return (xy[0], xy[1], xy[0] + width, xy[1] + (ascent + descent) / self.s)

    def _put(self, xy: tuple[float, float], text: str, px: float, fill: tuple[int, int, int]) -> None:
        """Plain ``text`` with the top left of its ink at ``xy`` (finished pixels)."""
        left, top, _, _ = self._ink(text, px)
        self.draw.text((xy[0] * self.s - left, xy[1] * self.s - top), text, font=self.font(px), fill=fill)

    def vertical_text(self, xy: tuple[float, float], text: str, px: float) -> None:
        """``text`` turned 90 degrees counter-clockwise (read bottom to top), centred on ``xy``."""
        from PIL import Image, ImageDraw

        font = self.font(px)
        box = self.draw.textbbox((0, 0), text, font=font, anchor="la")
        tile = Image.new("RGB", (box[2] + 2, box[3] + 2), PAGE)
        ImageDraw.Draw(tile).text((1, 1), text, font=font, fill=INK)
        tile = tile.rotate(90, expand=True)
        self.image.paste(tile, (round(xy[0] * self.s - tile.width / 2), round(xy[1] * self.s - tile.height / 2)))

    def line(self, points: Sequence[tuple[float, float]], fill: tuple[int, int, int], width: float) -> None:
        pts = [(x * self.s, y * self.s) for x, y in points]
        self.draw.line(pts, fill=fill, width=max(1, round(width * self.s)), joint="curve" if len(pts) > 2 else None)

    def dashed_vline(self, x: float, y0: float, y1: float, fill: tuple[int, int, int], width: float,
                     dash: float = 4.0, gap: float = 2.5) -> None:
        y = y0
        while y < y1:
            self.line([(x, y), (x, min(y + dash, y1))], fill, width)
            y += dash + gap

    def rectangle(self, box: Box, *, outline: tuple[int, int, int] | None = INK,
                  fill: tuple[int, int, int] | None = None, width: float = 1.0) -> None:
        x0, y0, x1, y1 = (v * self.s for v in box)
        self.draw.rectangle((x0, y0, x1, y1), outline=outline, fill=fill,
                            width=max(1, round(width * self.s)))

    def paste(self, rgb: np.ndarray, box: Box) -> None:
        """``rgb`` (H, W, 3) uint8 scaled (nearest: each value a flat cell) into ``box``."""
        from PIL import Image

        x0, y0, x1, y1 = (round(v * self.s) for v in box)
        tile = Image.fromarray(np.ascontiguousarray(rgb)).resize((max(1, x1 - x0), max(1, y1 - y0)),
                                                                 Image.Resampling.NEAREST)
        self.image.paste(tile, (x0, y0))

    def finish(self) -> np.ndarray:
        """(H, W, 3) uint8 of the finished size."""
        return np.asarray(self.image.reduce(self.s)).copy()


def _axis_ticks(cv: _Canvas, axis: Axis, plot: Box, which: Literal["x", "y"], *, grid: bool) -> float:
    """Ticks, their labels and (``grid``) grid lines of ``axis`` along the plot's bottom or left side.

    Returns the width (y) or height (x) the labels took outside the plot, pixels.
    """
    x0, y0, x1, y1 = plot
    used = 0.0
    for v, label in axis.ticks():
        if which == "x":
            px = float(axis.to_px(np.array(v), x0, x1))
            if grid:
                cv.line([(px, y0), (px, y1)], GRID, 1.0)
            cv.line([(px, y1), (px, y1 + 3.5)], INK, 0.8)
            w, h = cv.text_size(label, TICK_PX)
            cv.text((px, y1 + 5.0), label, TICK_PX, anchor="ma")
            used = max(used, 5.0 + h)
        else:
            py = float(axis.to_px(np.array(v), y1, y0))
            if grid:
                cv.line([(x0, py), (x1, py)], GRID, 1.0)
            cv.line([(x0 - 3.5, py), (x0, py)], INK, 0.8)
            w, h = cv.text_size(label, TICK_PX)
            cv.text((x0 - 5.0, py), label, TICK_PX, anchor="rm")
            used = max(used, 5.0 + w)
    return used


def _label_width(cv: _Canvas, axis: Axis) -> float:
    return max((cv.text_size(label, TICK_PX)[0] for _, label in axis.ticks()), default=0.0)


def _overlaps(a: Box, b: Box) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


# --------------------------------------------------------------------------- energy plot


def _series(log: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    vals = []
    for row in log:
        v = row.get(key)
        try:
            vals.append(float(v) if v is not None else math.nan)
        except (TypeError, ValueError):
            vals.append(math.nan)
    return np.asarray(vals, np.float64)


def elapsed(log: Sequence[Mapping[str, Any]]) -> np.ndarray:
    """Elapsed seconds per row; a clock that restarts at a stage boundary is chained on.

    Without ``time_s`` in any row: the rows' ``iteration``.
    """
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


@dataclass
class EnergyLayout:
    """Where :func:`draw_energy_plot` put things, finished pixels (for tests and callers that annotate).

    Attributes:
        plot: the plotting area.
        stage_labels: one box per stage name, in stage order.
        legend: the legend's box, or None (nothing drawn).
        y_scale: the y axis's scale.
    """

    plot: Box
    stage_labels: list[Box] = field(default_factory=list)
    legend: Box | None = None
    y_scale: str = "linear"


def draw_energy_plot(
    log: Sequence[Mapping[str, Any]],
    *,
    title: str | None = "Energies over time",
    size_px: tuple[int, int] = (720, 420),
) -> tuple[np.ndarray, EnergyLayout]:
    """The optimizer's energies against time, per stage (paper, Figure 10), as pixels and their layout.

    Args:
        log: one mapping per iteration with ``stage`` (str), ``iteration``,
            ``time_s`` (seconds since the run started; a per-stage clock that
            restarts at each stage is chained on), and any of ``E_visual``,
            ``E_deform``, ``E_sparse``, ``E_total`` (missing or None: not
            drawn for that row).
        title: plot title or None.
        size_px: (width, height) in pixels.
    Returns:
        ((height, width, 3) uint8, :class:`EnergyLayout`). The y axis is
        logarithmic when every drawn value is positive, symmetric-log
        otherwise (the barrier terms can make the total negative); stage
        boundaries are dashed lines with the stage name.

    Raises:
        ValueError: an empty log, or a size under 160 x 120 pixels.
    """
    if not log:
        raise ValueError("energy_plot needs a non-empty log")
    if size_px[0] < 160 or size_px[1] < 120:
        raise ValueError(f"an energy plot needs at least 160 x 120 pixels, got {size_px[0]} x {size_px[1]}")
    x = elapsed(log)
    stages = [str(row.get("stage", "")) for row in log]
    starts = [0] + [k for k in range(1, len(stages)) if stages[k] != stages[k - 1]]
    spans = list(zip(starts, starts[1:] + [len(stages)]))
    series = {key: _series(log, key) for key, _ in ENERGY_KEYS}
    drawn = [(key, colour) for key, colour in ENERGY_KEYS if not np.isnan(series[key]).all()]
    values = np.concatenate([series[k][~np.isnan(series[k])] for k, _ in drawn]) if drawn else np.zeros(0)
    negative = bool((values < 0).any())
    if negative:
        nonzero = np.abs(values[values != 0])
        y_axis = Axis("symlog", 0.0, 1.0, float(nonzero.min()) if nonzero.size else 1.0)
    elif (values > 0).any():
        y_axis = Axis("log", 0.0, 1.0)
    else:
        y_axis = Axis("linear", 0.0, 1.0)
    # on a log axis an exact 0 (E_sparse at its stage's start, E_deform before
    # anything moved) is left out, not clamped: scaled() gives NaN there
    scaled = {k: y_axis.scaled(series[k]) for k, _ in drawn}
    y_lo, y_hi = _fit_range(np.concatenate(list(scaled.values())) if scaled else np.zeros(0))
    y_axis = Axis(y_axis.scale, y_lo, y_hi, y_axis.linthresh)
    x_lo, x_hi = _fit_range(x)
    x_axis = Axis("linear", x_lo, x_hi)

    cv = _Canvas(size_px)
    w, h = size_px
    top = 10.0 + (TITLE_PX + 10.0 if title else 0.0)
    left = 8.0 + LABEL_PX + 6.0 + _label_width(cv, y_axis) + 6.0
    plot = (left, top, w - 14.0, h - (8.0 + LABEL_PX + 6.0 + TICK_PX + 8.0))
    x0, y0, x1, y1 = plot
    layout = EnergyLayout(plot=plot, y_scale=y_axis.scale)
    _axis_ticks(cv, x_axis, plot, "x", grid=True)
    _axis_ticks(cv, y_axis, plot, "y", grid=True)
    if title:
        cv.text(((x0 + x1) / 2, 8.0), title, TITLE_PX, anchor="ma")
    has_time = not np.isnan(_series(log, "time_s")).all()
    cv.text(((x0 + x1) / 2, h - 6.0), "time (s)" if has_time else "iteration", LABEL_PX, anchor="md")
    cv.vertical_text((8.0 + LABEL_PX / 2, (y0 + y1) / 2), "energy", LABEL_PX)

    px = x_axis.to_px(x, x0, x1)
    points: list[tuple[float, float]] = []  # every drawn point, for the legend's placement
    for key, colour in drawn:
        py = y_axis.to_px(series[key], y1, y0)
        width = 1.4 if key == "E_total" else 1.1
        # one line per stage: a jump between stages (new sigma, new terms) is a
        # change of problem, not a step of the solver; NaN (missing, or 0 on a log
        # axis) breaks a line
        for a, b in spans:
            ok = np.isfinite(py[a:b]) & np.isfinite(px[a:b])
            run: list[tuple[float, float]] = []
            for xi, yi, good in zip(px[a:b], py[a:b], ok):
                if good:
                    run.append((float(xi), float(yi)))
                    continue
                _draw_run(cv, run, colour, width)
                run = []
            _draw_run(cv, run, colour, width)
            points.extend((float(xi), float(yi)) for xi, yi, good in zip(px[a:b], py[a:b], ok) if good)
    for n, k in enumerate(starts):
        bx = float(px[k])
        if not math.isfinite(bx):  # a row with neither time nor iteration: name the stage at the left
            bx = x0
        elif n > 0:
            cv.dashed_vline(bx, y0, y1, STAGE_LINE, 0.9)
        # short stages start close together: move a name down a row until it meets no earlier one
        ascent, descent = cv.font(SMALL_PX).getmetrics()
        th = (ascent + descent) / cv.s
        tw = cv.draw.textlength(stages[k], font=cv.font(SMALL_PX)) / cv.s
        lx = min(bx + 3.0, x1 - tw - 2.0)
        for row in range(len(starts)):
            box = (lx - 1.0, y0 + 2.0 + row * (th + 1.0), lx + tw + 1.0, y0 + 2.0 + row * (th + 1.0) + th)
            if not any(_overlaps(box, b) for b in layout.stage_labels):
                break
        layout.stage_labels.append(box)
        cv.line_of_text((box[0] + 1.0, box[1]), stages[k], SMALL_PX, fill=STAGE_TEXT)
    cv.rectangle(plot, width=0.8)
    if drawn:
        layout.legend = _legend(cv, drawn, plot, points, layout.stage_labels)
    return cv.finish(), layout


def _draw_run(cv: _Canvas, run: list[tuple[float, float]], colour: tuple[int, int, int], width: float) -> None:
    if len(run) >= 2:
        cv.line(run, colour, width)
    elif len(run) == 1:  # a one-row stage still shows
        (xx, yy), r = run[0], 1.8
        cv.draw.ellipse(((xx - r) * cv.s, (yy - r) * cv.s, (xx + r) * cv.s, (yy + r) * cv.s), fill=colour)


def _legend(cv: _Canvas, entries: Sequence[tuple[str, tuple[int, int, int]]], plot: Box,
            points: Sequence[tuple[float, float]], avoid: Sequence[Box]) -> Box:
    """A framed legend where it covers the fewest data points (and no stage name); its box."""
    row_h = SMALL_PX + 5.0
    text_w = max(cv.text_size(k, SMALL_PX)[0] for k, _ in entries)
    bw, bh = 6.0 + 22.0 + 5.0 + text_w + 6.0, 5.0 + row_h * len(entries) + 3.0
    x0, y0, x1, y1 = plot
    pad = 6.0
    xs = {"l": x0 + pad, "c": (x0 + x1 - bw) / 2, "r": x1 - pad - bw}
    ys = {"u": y0 + pad, "m": (y0 + y1 - bh) / 2, "d": y1 - pad - bh}
    # matplotlib's order of preference for "best"
    order = ("ur", "ul", "dl", "dr", "mr", "ml", "dc", "uc", "mc")
    pts = np.asarray(points, np.float64).reshape(-1, 2)

    def cost(box: Box) -> int:
        inside = ((pts[:, 0] >= box[0]) & (pts[:, 0] <= box[2]) & (pts[:, 1] >= box[1]) & (pts[:, 1] <= box[3]))
        return int(inside.sum()) + 10_000 * sum(_overlaps(box, b) for b in avoid)

    # min keeps the first of equal costs: the earliest place in the order wins ties
    boxes = [(xs[w[1]], ys[w[0]], xs[w[1]] + bw, ys[w[0]] + bh) for w in order]
    best = min(boxes, key=cost)
    cv.rectangle(best, outline=(204, 204, 204), fill=PAGE, width=0.8)
    for n, (key, colour) in enumerate(entries):
        yy = best[1] + 5.0 + row_h * n + row_h / 2 - 1.0
        cv.line([(best[0] + 6.0, yy), (best[0] + 28.0, yy)], colour, 1.4 if key == "E_total" else 1.1)
        cv.text((best[0] + 33.0, yy), key, SMALL_PX, anchor="lm")
    return best


def energy_plot(log: Sequence[Mapping[str, Any]], **options: Any) -> bytes:
    """PNG bytes of :func:`draw_energy_plot` (same arguments, defaults and errors)."""
    from saucerfab.files.imageio import png_bytes

    return png_bytes(draw_energy_plot(log, **options)[0])


# --------------------------------------------------------------------------- height changes


def height_change_map(base: np.ndarray, heights: np.ndarray, delta: float, **options: Any) -> np.ndarray:
    """The picture of :func:`draw_height_change_map` (same arguments, defaults and errors)."""
    return draw_height_change_map(base, heights, delta, **options)[0]


def draw_height_change_map(
    base: np.ndarray,
    heights: np.ndarray,
    delta: float,
    *,
    units: Literal["delta", "model"] = "delta",
    extent: tuple[float, float, float, float] | None = None,
    title: str | None = "|h - z|",
    size_px: tuple[int, int] = (480, 400),
    cmap: str = "viridis",
) -> tuple[np.ndarray, Box, Box]:
    """Colour-coded absolute height change ``|h - z|`` (paper, Figure 8 bottom row).

    The saucer is drawn as the viewer sees it from the camera (which looks
    along +y): x to the right and the far edge (large y, the last grid row)
    at the top, each grid vertex a flat cell. The colour scale runs from 0 to
    the bound ``delta`` with a colourbar, in units of delta (0..1) or of the
    model.

    Args:
        base: (N, M) base heights z, model units; ``base[i, j]`` at
            ``y = ys[i]``, ``x = xs[j]`` (see :mod:`saucerfab.model.heightfield`).
        heights: (N, M) final heights h, model units.
        delta: the height bound, model units (> 0).
        units: colourbar in multiples of ``delta`` or in model units.
        extent: (x0, x1, y0, y1) of the footprint, model units, for the axes
            ticks and the map's aspect; None: no ticks, square cells.
        title: title, or None.
        size_px: (width, height) of the picture, pixels (at least 160 x 120).
        cmap: a table of :mod:`saucerfab.imaging.colormaps`.
    Returns:
        ((size_px[1], size_px[0], 3) uint8, the map's box, the colourbar's box).

    Raises:
        ValueError: shapes that differ or are not 2-D, a ``delta`` that is not
            a positive number, an unknown ``cmap``, or too small a size.
    """
    z = np.asarray(base, np.float64)
    h = np.asarray(heights, np.float64)
    if z.shape != h.shape or z.ndim != 2:
        raise ValueError(f"base {z.shape} and heights {h.shape} must be the same (N, M) shape")
    if not (delta > 0 and math.isfinite(delta)):
        raise ValueError(f"delta must be a positive number, got {delta!r}")
    if size_px[0] < 160 or size_px[1] < 120:
        raise ValueError(f"a height-change map needs at least 160 x 120 pixels, got {size_px[0]} x {size_px[1]}")
    scale = delta if units == "delta" else 1.0
    vmax = delta / scale
    label = "|h - z| / delta" if units == "delta" else "|h - z| (model units)"
    # row 0 (smallest y, nearest the viewer) at the bottom, the far edge at the top
    cells = colormap(cmap, np.abs(h - z) / delta)[::-1]

    cv = _Canvas(size_px)
    w, hgt = size_px
    bar_axis = Axis("linear", 0.0, vmax)
    bar_room = 12.0 + 16.0 + 5.0 + _label_width(cv, bar_axis) + 6.0 + LABEL_PX + 8.0
    top = 8.0 + (TITLE_PX + 10.0 if title else 0.0)
    if extent is None:
        left, bottom = 8.0, 8.0
        aspect = z.shape[1] / z.shape[0]
        x_axis = y_axis = None
    else:
        x_axis = Axis("linear", float(extent[0]), float(extent[1]))
        y_axis = Axis("linear", float(extent[2]), float(extent[3]))
        left = 8.0 + LABEL_PX + 6.0 + _label_width(cv, y_axis) + 6.0
        bottom = 8.0 + LABEL_PX + 6.0 + TICK_PX + 8.0
        aspect = abs(extent[1] - extent[0]) / max(abs(extent[3] - extent[2]), 1e-300)
    room_w, room_h = w - left - bar_room, hgt - top - bottom
    map_w = min(room_w, room_h * aspect)
    map_h = map_w / aspect
    # centre the map and its colourbar together
    mx0 = left + (room_w - map_w) / 2
    my0 = top + (room_h - map_h) / 2
    plot = (mx0, my0, mx0 + map_w, my0 + map_h)
    cv.paste(cells, plot)
    cv.rectangle(plot, width=0.8)
    if title:
        cv.text(((plot[0] + plot[2]) / 2, 8.0), title, TITLE_PX, anchor="ma")
    if x_axis is not None and y_axis is not None:
        _axis_ticks(cv, x_axis, plot, "x", grid=False)
        _axis_ticks(cv, y_axis, plot, "y", grid=False)
        cv.text(((plot[0] + plot[2]) / 2, hgt - 6.0), "x", LABEL_PX, anchor="md")
        cv.vertical_text((8.0 + LABEL_PX / 2, (plot[1] + plot[3]) / 2), "y", LABEL_PX)
    bar = (plot[2] + 12.0, plot[1], plot[2] + 28.0, plot[3])
    ramp = colormap(cmap, np.linspace(1.0, 0.0, 256))[:, None, :]
    cv.paste(ramp, bar)
    cv.rectangle(bar, width=0.8)
    used = 0.0
    for v, text in bar_axis.ticks():
        py = float(bar_axis.to_px(np.array(v), bar[3], bar[1]))
        cv.line([(bar[2], py), (bar[2] + 3.5, py)], INK, 0.8)
        used = max(used, cv.text((bar[2] + 5.0, py), text, TICK_PX, anchor="lm")[2])
    cv.vertical_text((used + 6.0 + LABEL_PX / 2, (bar[1] + bar[3]) / 2), label, LABEL_PX)
    return cv.finish(), plot, bar
