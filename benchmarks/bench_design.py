"""Benchmark the whole design (issue 4): wall time per stage, iterations, and the ablation.

    .venv/bin/python benchmarks/bench_design.py                 # full default design (150x150, 512x512)
    .venv/bin/python benchmarks/bench_design.py --ablation      # + Figure 11's six settings
    .venv/bin/python benchmarks/bench_design.py --resolution 80 --image-size 256 --ablation
    .venv/bin/python benchmarks/bench_design.py --ablation --pairs all   # every bundled pair

Runs `run_design` on the bundled samples (by default direct_heart.png on the
saucer, reflected_star.png in the cup, waves base shape; ``--pairs`` picks
others from PAIRS) and prints a table per stage and, with --ablation,
E_visual (paper eq. 2 on hard renders against the inputs projected on the
base shape) and E_deform for each setting, per pair. The reference for the
time is the paper's: up to 30 minutes on a GTX 1080Ti.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from saucerfab.workflow import run_design  # noqa: E402
from saucerfab.optimize.request import DesignRequest  # noqa: E402

#: bundled graphic pairs (direct, reflected): the demo's, and two made of the
#: batch variants (non-square JPEG, 16-bit grey, palette with transparency)
from saucerfab.samples import GRAPHIC_PAIRS as PAIRS  # noqa: E402  (one list: saucerfab/samples.py)
from saucerfab.samples import SAMPLES  # noqa: E402


def machine() -> str:
    try:
        model = next(
            line.split(":", 1)[1].strip()
            for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines()
            if line.startswith("Model name")
        )
    except (StopIteration, OSError):
        model = platform.processor() or "unknown CPU"
    import os

    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def one(ablation: str, args: argparse.Namespace, tmp: Path, pair: str = "heart-star") -> dict:
    direct, reflected = PAIRS[pair]
    req = DesignRequest(
        SAMPLES / direct,
        SAMPLES / reflected,
        shape="waves",
        resolution=args.resolution,
        image_size=args.image_size,
        max_iters=args.max_iters,
        ablation=ablation,
        frames=args.frames,
        barrier_weight=args.barrier_weight,
    )
    t0 = time.perf_counter()
    design = run_design(req, tmp / pair / ablation, progress=lambda *a: None)
    wall = time.perf_counter() - t0
    return {"ablation": ablation, "pair": pair, "wall_s": wall, "metrics": design.metrics, "out": str(design.folder)}


#: settings the full method must beat (the issue's "Done when": without the
#: enhancement, or without the sparse stage)
MUST_BEAT = ("laplacian", "laplacian_sparse", "laplacian_bw")


def print_stages(full: dict) -> None:
    m = full["metrics"]
    print(f"\n{full['pair']}: full design {full['wall_s']:.1f} s wall (setup {m['setup_s']:.1f} s, texturing "
          f"{m['texturing_s']:.1f} s, previews {m['previews_s']:.1f} s)")
    print(f"{'stage':22s} {'iters':>6s} {'s':>7s} {'ms/it':>7s} {'E_visual':>10s} {'E_deform':>9s} {'conflict':>8s}")
    for st in m["stages"]:
        print(f"{st['name']:22s} {st['iterations']:6d} {st['seconds']:7.1f} "
              f"{1000 * st['seconds_per_iteration']:7.0f} {st['E_visual']:10.1f} {st['E_deform']:9.4f} "
              f"{100 * st['conflict_fraction']:7.1f}%")
    print(f"final E_visual {m['E_visual_final']:.1f}, E_deform {m['E_deform']:.4f}, "
          f"max |h - z| {m['max_abs_height_change']:.4f}", flush=True)


def print_ablation(rows: list[dict]) -> None:
    full = next(r for r in rows if r["ablation"] == "full")
    ef = full["metrics"]["E_visual_final"]
    print(f"\n{full['pair']}: ablation (Figure 11), E_visual = eq. 2 on hard textured renders, "
          "change against full:")
    print(f"{'setting':18s} {'E_visual':>10s} {'vs full':>8s} {'direct':>9s} {'reflected':>9s} "
          f"{'E_deform':>9s} {'wall s':>7s}")
    for r in sorted(rows, key=lambda r: r["metrics"]["E_visual_final"]):
        mm = r["metrics"]
        rel = 100 * (mm["E_visual_final"] / ef - 1)
        print(f"{r['ablation']:18s} {mm['E_visual_final']:10.1f} {rel:+7.1f}% {mm['E_visual_final_direct']:9.1f} "
              f"{mm['E_visual_final_reflected']:9.1f} {mm['E_deform']:9.4f} {r['wall_s']:7.1f}")
    beaten = [r["ablation"] for r in rows if r["ablation"] in MUST_BEAT and r["metrics"]["E_visual_final"] <= ef]
    checked = [r["ablation"] for r in rows if r["ablation"] in MUST_BEAT]
    if checked:
        verdict = "holds" if not beaten else f"does not hold: {', '.join(beaten)} at or below full"
        print(f"full below {', '.join(checked)}: {verdict}", flush=True)


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--resolution", type=int, default=150)
    p.add_argument("--image-size", type=int, default=512)
    p.add_argument("--max-iters", type=int, default=400)
    p.add_argument("--frames", default="contain")
    p.add_argument("--barrier-weight", type=float, default=DesignRequest.barrier_weight)
    p.add_argument("--ablation", action="store_true", help="also run Figure 11's six settings")
    p.add_argument("--keep", help="keep the design folders here (PAIR/SETTING)")
    p.add_argument("--settings", default="no_deform,laplacian,laplacian_bw,sparse_only,laplacian_sparse",
                   help="ablation settings to run besides full (comma-separated)")
    p.add_argument("--pairs", default="heart-star",
                   help=f"image pairs, comma-separated, or 'all': {', '.join(PAIRS)}")
    args = p.parse_args()
    pairs = list(PAIRS) if args.pairs == "all" else args.pairs.split(",")
    unknown = [x for x in pairs if x not in PAIRS]
    if unknown:
        p.error(f"unknown pair(s) {', '.join(unknown)}; choose from {', '.join(PAIRS)} or 'all'")
    print(f"machine: {machine()}")
    print(f"size: {args.resolution}x{args.resolution} heightfield, {args.image_size}px views, "
          f"max {args.max_iters} iterations per stage, frames={args.frames}, barrier weight {args.barrier_weight}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(args.keep) if args.keep else Path(d)
        for pair in pairs:
            full = one("full", args, tmp, pair)
            print_stages(full)
            if args.ablation:
                rows = [full] + [one(ab, args, tmp, pair) for ab in args.settings.split(",")]
                print_ablation(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
