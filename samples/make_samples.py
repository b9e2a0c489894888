"""Generate saucerfab's bundled sample images (deterministic, Pillow drawing only).

Run from anywhere::

    python samples/make_samples.py            # writes next to this file
    python samples/make_samples.py --out DIR  # writes into DIR

Every image is drawn from geometry in this file: no downloads, no fonts,
no randomness, so the output is the same on every run (up to the PNG/JPEG
encoder's bytes; the pixels are identical for a given Pillow version).
Shapes are drawn at 4x and reduced with Lanczos so their edges are
anti-aliased. Bold, simple, high-contrast silhouettes on plain backgrounds
work best for mirror cup and saucer art (the paper uses cartoons and
silhouettes), so that is what these are.

Files (see README.md for what each is for):

* direct_heart.png       512x512 RGB    red heart on a plain cream background
* reflected_star.png     512x512 RGBA   golden star on a transparent background
* reflected2_moon.png    512x512 RGB    navy crescent moon on white (two-reflection mode)
* tree_gray16.png        384x384 16-bit grayscale pine tree on a soft gradient
* fish_wide.jpg          640x400 RGB    orange fish on pale blue (non-square JPEG)
* note_palette.png       256x256 P      black music note, palette + transparent index
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

SS = 4  # supersampling factor for anti-aliased edges

Point = tuple[float, float]


def _scaled(points: list[Point], k: float) -> list[Point]:
    return [(x * k, y * k) for x, y in points]


def draw_heart(d: ImageDraw.ImageDraw, cx: float, cy: float, width: float, colour: tuple[int, ...], grow: float = 0.0) -> None:
    """The geometric heart: a square turned 45 degrees with a disc on each upper side.

    ``width`` is the heart's width; ``grow`` pushes every edge outwards by
    that many pixels (drawing the heart grown in a dark colour, then the
    heart itself, gives a uniform outline). Centred at (cx, cy); y down.
    """
    h = width / (1 + math.sqrt(2))  # half-diagonal of the square
    cy = cy + 0.1036 * h  # centre the bounding box, not the square
    r = h / math.sqrt(2) + grow
    g = grow / math.sqrt(2)
    # The lower sides grown by `grow` (mitred at the tip) meet each disc where
    # it touches them, at the square's side corners; the upper half of the
    # square lies inside the discs.
    d.polygon(
        [
            (cx - h - g, cy + g),
            (cx, cy + h + 2 * g),
            (cx + h + g, cy + g),
            (cx + h / 2, cy - h / 2),
            (cx, cy - h),
            (cx - h / 2, cy - h / 2),
        ],
        fill=colour,
    )
    for sx in (-1, 1):
        mx, my = cx + sx * h / 2, cy - h / 2
        d.ellipse([(mx - r, my - r), (mx + r, my + r)], fill=colour)


def star_polygon(cx: float, cy: float, r_out: float, r_in: float, points: int = 5) -> list[Point]:
    """A regular star with one point straight up; y down."""
    pts = []
    for k in range(2 * points):
        r = r_out if k % 2 == 0 else r_in
        a = -math.pi / 2 + math.pi * k / points
        pts.append((cx + r * math.cos(a), cy + r * math.sin(a)))
    return pts


def _edge_distance(pts: list[Point], centre: Point) -> float:
    """Smallest distance from ``centre`` to the lines through the polygon's edges."""
    cx, cy = centre
    best = math.inf
    for (x0, y0), (x1, y1) in zip(pts, pts[1:] + pts[:1]):
        ex, ey = x1 - x0, y1 - y0
        best = min(best, abs(ex * (cy - y0) - ey * (cx - x0)) / math.hypot(ex, ey))
    return best


def _outlined(d: ImageDraw.ImageDraw, pts: list[Point], centre: Point, fill: tuple[int, ...], outline: tuple[int, ...], width: float) -> None:
    """A polygon in ``outline`` colour with its inset copy in ``fill`` on top.

    For a polygon whose edges all touch one circle around ``centre`` (any
    triangle about its incentre, a regular star about its centre), scaling
    about that centre moves every edge inwards by the same distance, so the
    outline has a uniform ``width`` with sharp corners. (Pillow's wide
    polygon outlines leave notches at sharp corners.)
    """
    k = 1.0 - width / _edge_distance(pts, centre)
    cx, cy = centre
    d.polygon(pts, fill=outline)
    d.polygon([(cx + (x - cx) * k, cy + (y - cy) * k) for x, y in pts], fill=fill)


def _incentre(pts: list[Point]) -> Point:
    (ax, ay), (bx, by), (cx, cy) = pts
    a, b, c = math.dist(pts[1], pts[2]), math.dist(pts[0], pts[2]), math.dist(pts[0], pts[1])
    return ((a * ax + b * bx + c * cx) / (a + b + c), (a * ay + b * by + c * cy) / (a + b + c))


def _draw_ss(size: tuple[int, int], mode: str, bg: tuple[int, ...], draw: Callable[[ImageDraw.ImageDraw, float], None]) -> Image.Image:
    """Draw at SS x the size with coordinates in final pixels, reduce with Lanczos."""
    w, h = size
    big = Image.new(mode, (w * SS, h * SS), bg)
    draw(ImageDraw.Draw(big), SS)
    # Pillow premultiplies RGBA while resizing, so transparent edges stay clean.
    return big.resize((w, h), Image.Resampling.LANCZOS)


def direct_heart() -> Image.Image:
    """512x512 RGB: a bold red heart with a dark outline on plain cream."""

    def draw(d: ImageDraw.ImageDraw, k: float) -> None:
        draw_heart(d, 256 * k, 256 * k, 400 * k, (120, 10, 30), grow=12 * k)
        draw_heart(d, 256 * k, 256 * k, 400 * k, (215, 38, 61))

    return _draw_ss((512, 512), "RGB", (251, 247, 240), draw)


def reflected_star() -> Image.Image:
    """512x512 RGBA: a golden five-pointed star with a dark outline, transparent background."""

    def draw(d: ImageDraw.ImageDraw, k: float) -> None:
        pts = _scaled(star_polygon(256, 272, 236, 96), k)
        _outlined(d, pts, (256 * k, 272 * k), (244, 180, 0, 255), (110, 70, 0, 255), 12 * k)

    return _draw_ss((512, 512), "RGBA", (255, 255, 255, 0), draw)


def reflected2_moon() -> Image.Image:
    """512x512 RGB: a navy crescent moon (a disc minus an offset disc) on white."""

    def draw(d: ImageDraw.ImageDraw, k: float) -> None:
        d.ellipse([(66 * k, 66 * k), (446 * k, 446 * k)], fill=(29, 53, 87))
        d.ellipse([(176 * k, 26 * k), (496 * k, 346 * k)], fill=(255, 255, 255))

    return _draw_ss((512, 512), "RGB", (255, 255, 255), draw)


def tree_gray16() -> Image.Image:
    """384x384 16-bit grayscale: a dark pine tree on a soft vertical gradient.

    The gradient and the tree's shading are smooth ramps, which is what a
    16-bit file is for; coverage comes from a supersampled 8-bit drawing.
    """
    w = h = 384

    def draw(d: ImageDraw.ImageDraw, k: float) -> None:
        for top, half, bottom in ((40, 80, 170), (110, 120, 260), (180, 155, 330)):
            d.polygon(_scaled([(192, top), (192 - half, bottom), (192 + half, bottom)], k), fill=255)
        d.rectangle([(172 * k, 320 * k), (212 * k, 360 * k)], fill=255)

    cover_img = _draw_ss((w, h), "L", (0,), draw)
    cover = np.asarray(cover_img, np.float64) / 255.0
    rows = np.linspace(0.0, 1.0, h)[:, None]
    background = 0.93 - 0.06 * rows  # light grey, slightly darker at the bottom
    tree = 0.12 + 0.10 * rows  # deep grey-green in grey, lighter at the foot
    value = background * (1 - cover) + tree * cover
    return Image.fromarray(np.round(value * 65535).astype(np.uint16))


def fish_wide() -> Image.Image:
    """640x400 RGB: an orange fish with a black eye on a plain pale-blue background."""

    def draw(d: ImageDraw.ImageDraw, k: float) -> None:
        orange, dark = (240, 112, 20), (150, 60, 0)
        line = 10 * k
        for tri in ([(190, 200), (40, 80), (40, 320)], [(260, 130), (340, 40), (420, 130)]):  # tail, fin
            pts = _scaled(tri, k)
            _outlined(d, pts, _incentre(pts), orange, dark, line)
        d.ellipse([(120 * k, 100 * k), (580 * k, 300 * k)], fill=orange, outline=dark, width=round(line))
        d.ellipse([(478 * k, 160 * k), (510 * k, 192 * k)], fill=(10, 10, 10))  # eye

    return _draw_ss((640, 400), "RGB", (225, 238, 246), draw)


def note_palette() -> Image.Image:
    """256x256 palette image: a black quaver (music note); index 0 is transparent.

    Drawn directly in palette mode (no anti-aliasing: a palette with one
    transparent index cannot hold partial transparency).
    """
    im = Image.new("P", (256, 256), 0)
    im.putpalette([255, 255, 255, 20, 20, 20] + [0, 0, 0] * 254)
    d = ImageDraw.Draw(im)
    d.ellipse([(48, 168), (128, 222)], fill=1)  # note head
    d.rectangle([(112, 36), (126, 196)], fill=1)  # stem
    d.polygon([(126, 36), (190, 86), (186, 130), (126, 84)], fill=1)  # flag
    im.info["transparency"] = 0
    return im


def write_all(out: Path) -> list[Path]:
    """Write every sample into ``out``; returns the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    jobs: list[tuple[str, Image.Image, dict[str, object]]] = [
        ("direct_heart.png", direct_heart(), {"optimize": True}),
        ("reflected_star.png", reflected_star(), {"optimize": True}),
        ("reflected2_moon.png", reflected2_moon(), {"optimize": True}),
        ("tree_gray16.png", tree_gray16(), {"optimize": True}),
        ("fish_wide.jpg", fish_wide(), {"quality": 90, "subsampling": 0}),
        ("note_palette.png", note_palette(), {"optimize": True, "transparency": 0}),
    ]
    written = []
    for name, im, opts in jobs:
        path = out / name
        tmp = path.with_name(f".{name}.part")
        im.save(tmp, format="JPEG" if name.endswith(".jpg") else "PNG", **opts)
        tmp.replace(path)  # never leave a half-written sample behind
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    args = parser.parse_args(argv)
    for p in write_all(args.out):
        print(f"{p}  {p.stat().st_size:,} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
