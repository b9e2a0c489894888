"""Which scene makes the largest pictures: the frames a design fits, over eye positions and saucer sizes.

    .venv/bin/python benchmarks/bench_scene_choice.py                  # the sweep, a table per picture shape
    .venv/bin/python benchmarks/bench_scene_choice.py --write-best DIR # and the best scenes as TOML files
    .venv/bin/python benchmarks/bench_scene_choice.py --round 160,200,240  # round saucers of these diameters

Issue 43, item 4: "a lower eye and a deeper saucer make [the mirror's image
of the saucer] taller, a wider saucer makes it wider". For every candidate
scene (the paper's camera moved in distance and height, the saucer's
rectangle widened and deepened; the cup, its size and the frames' rule are
the default's) this fits the frames exactly as ``saucerfab design`` does
(:func:`saucerfab.optimize.prepare.prepare`, default ``--frames
inscribed``) for a square pair and for a pair whose pictures are 2:1, and
measures, without designing:

* the reflected picture's width share: the reflected frame's width over the
  cup's visible width along the frame's middle row, both in the design
  eye's reflected camera (the measure of ``saucerfab verify``'s whole view,
  :func:`saucerfab.verify.wholeview.width_share`, taken on the frame the
  design fits instead of a render);
* the direct picture's share of the saucer's visible width along its middle
  row (``bench_whole.direct_width_share``);
* the frames' pixel density: the saucer's millimetres per frame pixel
  across the direct picture (a frame of 512 px spread over more saucer
  shows each millimetre with fewer pixels) and the heightfield's grid step
  in millimetres at the scene's resolution.

The issue's targets: 40 % (square) and 55 % (2:1) of the cup's width for the
reflected picture, 70 % of the saucer's width for a 2:1 direct picture. The
table sorts by the 2:1 reflected share. Whether a scene's designs are as good
inside and around the frames is the job of ``bench_whole.py --no-old --arm
LABEL='--scene FILE'`` on the scenes this writes with ``--write-best``.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_whole import direct_width_share, wide_pairs  # noqa: E402

from saucerfab.model.camera import Camera  # noqa: E402
from saucerfab.model.scene import Scene, paper_scene, scene_to_toml  # noqa: E402
from saucerfab.samples import PAIRS, SAMPLES  # noqa: E402

#: the candidates: the eye's distance in front of the cup's axis and height (model units; the paper's 5.5, 5),
#: the saucer's width along x and depth along y (the paper's 1 x 1, starting 0.1 in front of the cup's wall)
DISTANCES = (4.5, 5.5, 6.5)
HEIGHTS = (3.5, 4.25, 5.0, 6.0)
WIDTHS = (1.0, 1.25, 1.5)
DEPTHS = (1.0, 1.25)


def candidate(distance: float, height: float, width: float, depth: float) -> Scene:
    """The paper's scene with the eye at (0, -distance, height) and a ``width`` x ``depth`` saucer."""
    base = paper_scene()
    near = base.saucer.y_range[1]  # the saucer's edge by the cup stays where it is
    saucer = replace(base.saucer, x_range=(-width / 2, width / 2), y_range=(near - depth, near))
    return replace(base, camera=(0.0, -distance, height), saucer=saucer)


def reflected_width_share(scene: Scene) -> float:
    """The reflected frame's width over the cup's visible width along the frame's middle row (reflected camera)."""
    cam = Camera.from_scene(scene, "reflected")
    cup = scene.cup
    angles = np.linspace(0.0, 2 * np.pi, 721)
    levels = np.linspace(0.0, cup.height, 401)
    a, z = np.meshgrid(angles, levels)
    r = cup.width_units / 2  # a circle's radius (the default cup)
    pts = np.stack([r * np.cos(a).ravel(), r * np.sin(a).ravel(), z.ravel()], axis=1)
    ndc = cam.project(pts)
    near = np.abs(ndc[:, 1]) < 2.0 / cam.image_size
    if not near.any():
        return float("nan")
    return 2.0 * scene.reflected.extent[0] / float(np.ptp(ndc[near, 0]))


def mm_per_pixel(scene: Scene) -> float:
    """Millimetres of saucer per direct-frame pixel across the middle row (the picture's sharpness on the saucer)."""
    cam = Camera.from_scene(scene, "direct")
    x0, x1 = scene.saucer.x_range
    y = float(np.mean(scene.saucer.y_range))
    ndc = cam.project(np.array([[x0, y, 0.0], [x1, y, 0.0]]))
    pixels = abs(ndc[1, 0] - ndc[0, 0]) / 2.0 * cam.image_size
    return (x1 - x0) * scene.mm_per_unit / pixels


def fitted(scene: Scene, pair: tuple[str, str], folder: Path) -> Scene:
    """The scene with the frames ``saucerfab design`` fits for ``pair`` on it (no design run)."""
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest

    toml = folder / "scene.toml"
    toml.write_text(scene_to_toml(scene))
    direct, reflected = pair
    return prepare(DesignRequest(direct=SAMPLES / direct, reflected=SAMPLES / reflected, scene=str(toml))).scene


def round_sizes(diameters: tuple[float, ...], shapes: dict[str, tuple[str, str]], tmp: Path) -> int:
    """The pictures' sizes on round saucers of ``diameters`` mm around the paper's cup (frames fitted, no design)."""
    from saucerfab.model.scene import disc_saucer, round_grid, round_scene

    print("| round saucer mm | reflected picture's width: square / 2:1 | direct picture's width of the disc's row: "
          "square / 2:1 | direct frame's half angle, square / 2:1 |")
    print("|---:|---|---|---|")
    for mm in diameters:
        base = round_scene()
        d = mm / base.mm_per_unit
        scene = replace(base, saucer=disc_saucer(d, round_grid(d)))
        fits = {k: fitted(scene, pair, tmp) for k, pair in shapes.items()}
        print(f"| {mm:.0f} | {reflected_width_share(fits['square']):.0%} / "
              f"{reflected_width_share(fits['reflected 2:1']):.0%} | {direct_width_share(fits['square']):.0%} / "
              f"{direct_width_share(fits['direct 2:1']):.0%} | {fits['square'].direct.viewing_angle_deg:.2f} / "
              f"{fits['direct 2:1'].direct.viewing_angle_deg:.2f} deg |", flush=True)
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write-best", type=Path, metavar="DIR",
                   help="write the best candidates' scene TOMLs here (best-<n>.toml, and paper.toml)")
    p.add_argument("--best", type=int, default=3, help="how many to write (default 3)")
    for name, values in (("distances", DISTANCES), ("heights", HEIGHTS), ("widths", WIDTHS), ("depths", DEPTHS)):
        p.add_argument(f"--{name}", type=lambda t: tuple(float(v) for v in t.split(",")), default=values,
                       help=f"comma-separated model units (default {','.join(map(str, values))})")
    p.add_argument("--round", type=lambda t: tuple(float(v) for v in t.split(",")), metavar="MM,...",
                   help="instead: round saucers (the `round` scene) of these diameters in mm, e.g. 160,200,240")
    args = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="saucerfab-scenes-"))
    wide = wide_pairs(tmp)  # heart-2stars (reflected 2:1), 2hearts-star (direct 2:1)
    shapes = {"square": PAIRS["heart-star"], "reflected 2:1": wide["heart-2stars"],
              "direct 2:1": wide["2hearts-star"]}
    if args.round:
        return round_sizes(args.round, shapes, tmp)
    rows = []
    for d, h, w, dp in itertools.product(args.distances, args.heights, args.widths, args.depths):
        scene = candidate(d, h, w, dp)
        try:
            fits = {k: fitted(scene, pair, tmp) for k, pair in shapes.items()}
        except Exception as exc:  # noqa: BLE001 (a candidate the design refuses is reported, not fatal)
            print(f"eye (0, -{d}, {h}), saucer {w} x {dp}: refused: {exc}", flush=True)
            continue
        row = {"distance": d, "height": h, "width": w, "depth": dp, "scene": scene,
               "refl_sq": reflected_width_share(fits["square"]), "refl_21": reflected_width_share(fits["reflected 2:1"]),
               "direct_21": direct_width_share(fits["direct 2:1"]), "direct_sq": direct_width_share(fits["square"]),
               "mm_px": mm_per_pixel(fits["square"]),
               "grid_mm": max(w, dp) * scene.mm_per_unit / (scene.saucer.resolution - 1),
               "tilt": math.degrees(math.atan2(h, d))}
        rows.append(row)
        print(f"eye (0, -{d}, {h}) {row['tilt']:.0f} deg, saucer {w} x {dp}: reflected {row['refl_sq']:.0%} square, "
              f"{row['refl_21']:.0%} 2:1; direct 2:1 {row['direct_21']:.0%}; {row['mm_px']:.2f} mm/px", flush=True)
    rows.sort(key=lambda r: -r["refl_21"])
    print("\n| eye (x, y, z) | looks down | saucer mm (w x d) | reflected picture's width: square / 2:1 | "
          "direct picture's width: square / 2:1 | mm per frame pixel | grid step mm |")
    print("|---|---:|---|---|---|---:|---:|")
    for r in rows:
        s = r["scene"]
        print(f"| (0, -{r['distance']}, {r['height']}) | {r['tilt']:.0f} deg | {r['width'] * s.mm_per_unit:.0f} x "
              f"{r['depth'] * s.mm_per_unit:.0f} | {r['refl_sq']:.0%} / {r['refl_21']:.0%} | {r['direct_sq']:.0%} / "
              f"{r['direct_21']:.0%} | {r['mm_px']:.2f} | {r['grid_mm']:.2f} |")
    if args.write_best:
        args.write_best.mkdir(parents=True, exist_ok=True)
        (args.write_best / "paper.toml").write_text(scene_to_toml(paper_scene()))
        for i, r in enumerate(rows[: args.best], 1):
            (args.write_best / f"best-{i}.toml").write_text(scene_to_toml(r["scene"]))
        print(f"\nwrote {args.best} scenes and paper.toml to {args.write_best}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
