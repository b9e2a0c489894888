"""Make the inputs of the sample batch manifest (deterministic; Pillow and numpy only).

    python samples/batch/make_batch_samples.py           # writes next to this file

Writes, under ``samples/batch/``:

* ``images/*.png``   small (96 x 96) bold silhouettes for the raw-input jobs,
  and ``images/broken.png``, a PNG cut off halfway (the deliberately bad job);
* ``shapes/dome.npy`` a base-shape heightfield file (32 x 32 float64);
* ``scenes/small_cup.toml`` a scene with a 60 mm cup (a scene file input);
* ``designs/*/``     three small design folders (``saucerfab.model.design_folder.synthetic_design``:
  a seeded shape and a colour checkerboard texture, made without the
  optimizer, 24 x 24 vertices) for the design-folder jobs.

Everything is drawn from the geometry below: the same bytes on every run for
a given numpy and Pillow.
"""

from __future__ import annotations

import argparse
import io
import math
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

SIZE = 96
SS = 4  # drawn at 4x, reduced with Lanczos: anti-aliased edges


def _canvas(bg: tuple[int, int, int]) -> tuple[Image.Image, ImageDraw.ImageDraw]:
    im = Image.new("RGB", (SIZE * SS, SIZE * SS), bg)
    return im, ImageDraw.Draw(im)


def _finish(im: Image.Image) -> bytes:
    small = im.resize((SIZE, SIZE), Image.Resampling.LANCZOS)
    buf = io.BytesIO()
    small.save(buf, format="PNG", optimize=False, compress_level=9)
    return buf.getvalue()


def _star(cx: float, cy: float, r_out: float, r_in: float, points: int = 5) -> list[tuple[float, float]]:
    pts = []
    for k in range(2 * points):
        r = r_out if k % 2 == 0 else r_in
        a = -math.pi / 2 + k * math.pi / points
        pts.append((cx + r * math.cos(a), cy + r * math.sin(a)))
    return pts


def images() -> dict[str, bytes]:
    s = SIZE * SS
    out = {}

    im, d = _canvas((250, 243, 224))  # a red disc with a white ring, on cream
    d.ellipse((0.2 * s, 0.2 * s, 0.8 * s, 0.8 * s), fill=(200, 30, 45))
    d.ellipse((0.38 * s, 0.38 * s, 0.62 * s, 0.62 * s), fill=(250, 243, 224))
    out["ring.png"] = _finish(im)

    im, d = _canvas((255, 255, 255))  # a golden star on white
    d.polygon(_star(s / 2, s / 2, 0.42 * s, 0.18 * s), fill=(235, 170, 20))
    out["star.png"] = _finish(im)

    im, d = _canvas((225, 238, 250))  # an orange fish on pale blue
    d.ellipse((0.15 * s, 0.32 * s, 0.7 * s, 0.68 * s), fill=(240, 120, 30))
    d.polygon([(0.62 * s, 0.5 * s), (0.88 * s, 0.3 * s), (0.88 * s, 0.7 * s)], fill=(240, 120, 30))
    d.ellipse((0.26 * s, 0.44 * s, 0.32 * s, 0.5 * s), fill=(20, 20, 40))
    out["fish.png"] = _finish(im)

    im, d = _canvas((255, 255, 255))  # a navy crescent moon on white
    d.ellipse((0.18 * s, 0.18 * s, 0.82 * s, 0.82 * s), fill=(25, 40, 95))
    d.ellipse((0.34 * s, 0.1 * s, 0.94 * s, 0.7 * s), fill=(255, 255, 255))
    out["moon.png"] = _finish(im)

    # The bad upload: a real PNG cut off halfway through its image data.
    whole = out["ring.png"]
    out["broken.png"] = whole[: len(whole) // 2]
    return out


def dome(n: int = 32) -> bytes:
    """A gentle dome, 0 at the rim and 0.08 model units high in the middle (float64 .npy)."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    h = 0.08 * np.clip(1 - (u**2 + v**2) / 2, 0, None) ** 2
    buf = io.BytesIO()
    np.save(buf, h.astype(np.float64), allow_pickle=False)
    return buf.getvalue()


SMALL_CUP_SCENE = """\
# The paper's scene for a 60 mm cup (model units are unchanged; only the
# print's millimetre scale differs).
preset = "paper"
cup_diameter_mm = 60.0
"""


def write(folder: Path) -> None:
    from saucerfab.model.design_folder import save_design, synthetic_design

    for name, data in images().items():
        p = folder / "images" / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
    (folder / "shapes").mkdir(exist_ok=True)
    (folder / "shapes" / "dome.npy").write_bytes(dome())
    (folder / "scenes").mkdir(exist_ok=True)
    (folder / "scenes" / "small_cup.toml").write_text(SMALL_CUP_SCENE, encoding="utf-8")
    for name, shape, seed in (("waves", "waves", 1), ("ripples", "ripples", 2), ("bowl", "bowl", 3)):
        save_design(synthetic_design(shape=shape, seed=seed, resolution=24, texture_size=64), folder / "designs" / name)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    write(ap.parse_args().out)


if __name__ == "__main__":
    main()
