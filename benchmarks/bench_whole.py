"""The whole piece as the viewer sees it, before and after: every bundled pair, old code against this checkout.

    .venv/bin/python benchmarks/bench_whole.py --old 5de9582                       # every bundled pair
    .venv/bin/python benchmarks/bench_whole.py --old 5de9582 --pairs heart-star --pictures benchmarks/results/whole
    .venv/bin/python benchmarks/bench_whole.py --old HEAD --arm frames-only='--surround-weight 0'

For each pair, ``saucerfab design`` exactly as a user types it (defaults, no
quick verify) and ``saucerfab export --printer j55 --cup-diameter-mm 80
--formats obj`` by the old code (``--old``: a git revision, copied with ``git
archive``, its numba kernels compiled before the clock starts) and by this
checkout (and each ``--arm``), in alternating order; then *this* checkout's
``saucerfab verify`` (the same instrument for every arm) at 256 px, 16 spp
from the design eye and a viewer's two eyes. Per pair and arm it prints the
design's wall and CPU seconds, each frame's PSNR (design eye against the
picture; moved eyes against the flat print), and the design eye's whole
view: its PSNR against the ideal whole view, the stray share of the saucer
around the direct frame and of the mirror around the reflected frame, and
the reflected picture's share of the cup's width (:mod:`saucerfab.verify.wholeview`).

``--pictures DIR`` keeps each arm's ``design_whole.png`` there as
``<pair>_<arm>_whole.png``. Times are wall-clock on a shared machine: the
ratio within a pair is the figure (see ``bench_speed.py``).
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_design import machine  # noqa: E402
from bench_speed import _env, _load, design, old_copy  # noqa: E402

from saucerfab.samples import PAIRS  # noqa: E402
from saucerfab.verify import EyeSpec, verify_print  # noqa: E402

EYES = ("design", "left", "right")


def export(code: Path, design_dir: Path, print_dir: Path) -> None:
    """``saucerfab export`` of ``design_dir`` by the code in ``code`` (J55, OBJ, 80 mm cup; no check, no verify)."""
    subprocess.run([sys.executable, "-m", "saucerfab", "export", str(design_dir), "--printer", "j55",
                    "--cup-diameter-mm", "80", "--formats", "obj", "--out", str(print_dir), "--quiet",
                    "--no-verify", "--no-check"], cwd=code, env=_env(code), check=True, capture_output=True)


def scores(print_dir: Path, pictures: Path | None) -> dict:
    """This checkout's verify of ``print_dir`` from three eyes: frames' PSNR and the design eye's whole view."""
    res = verify_print(print_dir, eyes=EyeSpec("both"), res=256, spp=16, all_formats=False,
                       pictures_dir=pictures)
    out = {f"{v.view}/{v.eye}": v.psnr_db for v in res.files[0].views}
    whole = next(w for w in res.whole_views if w.eye == "design")
    out.update(whole_db=whole.psnr_db, stray_direct=whole.stray_direct, stray_reflected=whole.stray_reflected,
               width_share=whole.width_share)
    return out


def wide_pairs(folder: Path) -> dict[str, tuple[str, str]]:
    """Two pairs with a 2:1 picture, made from the bundled ones (two copies side by side), added to the pairs table."""
    import bench_speed
    from PIL import Image

    from saucerfab.samples import SAMPLES

    made = {}
    for name in ("direct_heart.png", "reflected_star.png"):
        one = Image.open(SAMPLES / name).convert("RGBA")
        two = Image.new("RGBA", (2 * one.width, one.height), (0, 0, 0, 0))
        two.paste(one, (0, 0))
        two.paste(one, (one.width, 0))
        made[name] = str(folder / f"two_{name}")
        two.save(made[name])
    wide = {"heart-2stars": ("direct_heart.png", made["reflected_star.png"]),
            "2hearts-star": (made["direct_heart.png"], "reflected_star.png")}
    PAIRS.update(wide)  # one table for this module and bench_speed's design() (absolute paths join as they are)
    bench_speed.PAIRS.update(wide)
    return wide


def direct_width_share(scene) -> float:  # noqa: ANN001 (a saucerfab.model.scene.Scene)
    """The direct picture's width over the saucer's visible width, along the picture's middle row (design eye).

    The saucer's footprint (at height 0; a disc's points on it) is projected into the direct camera; its image is cut by the
    row ``y_ndc = 0`` (the picture's middle); the picture spans ``2 * extent[0]`` of the NDC width.
    """
    from saucerfab.model.camera import Camera

    cam = Camera.from_scene(scene, "direct")
    (x0, x1), (y0, y1) = scene.saucer.x_range, scene.saucer.y_range
    t = np.linspace(0.0, 1.0, 4001)
    ys = y0 + t * (y1 - y0)
    xs_hit = []
    for y in ys:  # the footprint's row through the picture's middle: where the projection's y crosses 0
        pts = np.stack([np.linspace(x0, x1, 2001), np.full(2001, y), np.zeros(2001)], axis=1)
        ndc = cam.project(pts)
        xs_hit.append(np.where(scene.saucer.on_saucer(pts[:, :2])[:, None], ndc[:, :2], np.nan))  # a disc: on it
    grid = np.stack(xs_hit)  # (rows, cols, 2)
    near = np.abs(np.nan_to_num(grid[..., 1], nan=np.inf)) < 2.0 / cam.image_size
    width = float(grid[..., 0][near].max() - grid[..., 0][near].min())
    return 2.0 * scene.direct.extent[0] / width


def geometry(pairs: list[str]) -> None:
    """Print each pair's frames as a design fits them (no design run): the pictures' extents and the
    direct picture's share of the saucer's visible width."""
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.samples import SAMPLES

    print("| pair | direct extent | reflected extent | direct picture's share of the saucer's width |")
    print("|---|---|---|---:|")
    for pair in pairs:
        direct, reflected = PAIRS[pair]
        prep = prepare(DesignRequest(direct=SAMPLES / direct, reflected=SAMPLES / reflected))
        sc = prep.scene
        print(f"| {pair} | {sc.direct.extent[0]:.2f} x {sc.direct.extent[1]:.2f} | {sc.reflected.extent[0]:.2f} x "
              f"{sc.reflected.extent[1]:.2f} | {direct_width_share(sc):.0%} |", flush=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", default="HEAD", help="git revision of the code before the change")
    p.add_argument("--pairs", default="all", help=f"comma-separated or all: {', '.join(PAIRS)}")
    p.add_argument("--arm", action="append", default=[], metavar="LABEL=OPTIONS",
                   help="one more configuration of this checkout, e.g. frames-only='--surround-weight 0'")
    p.add_argument("--no-old", action="store_true",
                   help="only this checkout (and the --arm ones): the old code's figures come from an earlier run")
    p.add_argument("--pictures", type=Path, help="keep each arm's whole-view picture here")
    p.add_argument("--json", help="also write the rows as JSON here")
    p.add_argument("--geometry", action="store_true",
                   help="only the frames as a design fits them (no design): extents and the direct picture's "
                        "share of the saucer's visible width")
    p.add_argument("--wide", action="store_true",
                   help="two more pairs with a 2:1 picture made here (two stars side by side): heart-2stars "
                        "(reflected 2:1) and 2hearts-star (direct 2:1)")
    args = p.parse_args()
    pairs = list(PAIRS) if args.pairs == "all" else args.pairs.split(",")
    if args.wide:
        pairs += list(wide_pairs(Path(tempfile.mkdtemp(prefix="saucerfab-wide-"))))
    unknown = [x for x in pairs if x not in PAIRS]
    if unknown:
        p.error(f"unknown pairs {unknown}; known: {', '.join(PAIRS)}")
    if args.geometry:
        geometry(pairs)
        return 0
    print(f"machine: {machine()}; old = {args.old}, new = this checkout; start load {_load()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        subprocess.run([sys.executable, "-m", "saucerfab.warmup"], cwd=ROOT, env=_env(ROOT), check=True,
                       capture_output=True)
        arms = [] if args.no_old else [("old", old_copy(args.old, tmp / "old"), [])]
        arms += [("new", ROOT, [])]
        arms += [(a.split("=", 1)[0], ROOT, shlex.split(a.split("=", 1)[1])) for a in args.arm]
        for k, pair in enumerate(pairs):
            row: dict = {"pair": pair}
            for label, code, extra in arms[k % len(arms):] + arms[:k % len(arms)]:  # each arm first in turn
                out = tmp / pair / label
                d = design(code, pair, out / "design", ["--no-verify", *extra])
                export(code, out / "design", out / "print")
                pics = out / "verify" if args.pictures else None
                d.update(scores(out / "print", pics), load=_load())
                if args.pictures:
                    args.pictures.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(pics / "design_whole.png", args.pictures / f"{pair}_{label}_whole.png")
                row[label] = d
                print(f"{pair} {label}: {d['seconds']:.1f} s (CPU {d['cpu_s']:.1f} s, load {d['load']}); whole "
                      f"{d['whole_db']:.1f} dB, stray {d['stray_direct']:.1%} / {d['stray_reflected']:.1%}, "
                      f"width {d['width_share']:.0%}", flush=True)
            rows.append(row)
    labels = [a[0] for a in arms]
    print("\n| pair | code | design s (CPU s) | frames, design eye dB: direct / reflected | moved eyes dB "
          "(left, right): direct / reflected | whole view dB | stray: saucer / mirror | reflected picture's "
          "width |")
    print("|---|---|---:|---|---|---:|---|---:|")
    for r in rows:
        for label in labels:
            d = r[label]
            moved = " / ".join(f"{d[f'{v}/left']:.1f}, {d[f'{v}/right']:.1f}" for v in ("direct", "reflected"))
            print(f"| {r['pair']} | {label} | {d['seconds']:.1f} ({d['cpu_s']:.1f}) | {d['direct/design']:.1f} / "
                  f"{d['reflected/design']:.1f} | {moved} | {d['whole_db']:.1f} | {d['stray_direct']:.1%} / "
                  f"{d['stray_reflected']:.1%} | {d['width_share']:.0%} |")
    for label in ([] if args.no_old else labels[1:]):
        t_old = sum(r["old"]["seconds"] for r in rows)
        t_new = sum(r[label]["seconds"] for r in rows)
        c_old = sum(r["old"]["cpu_s"] for r in rows)
        c_new = sum(r[label]["cpu_s"] for r in rows)
        print(f"\n{label} / old, all pairs: design wall {t_new / t_old:.2f}x, CPU {c_new / c_old:.2f}x")
    if args.json:
        Path(args.json).write_text(json.dumps({"old": args.old, "machine": machine(), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
