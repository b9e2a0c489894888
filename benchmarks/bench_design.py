"""Benchmark the whole design (issue 4): wall time per stage, iterations, and the ablation.

    .venv/bin/python benchmarks/bench_design.py                 # full default design (150x150, 512x512)
    .venv/bin/python benchmarks/bench_design.py --ablation      # + Figure 11's six settings
    .venv/bin/python benchmarks/bench_design.py --resolution 80 --image-size 256 --ablation

Runs `run_design` on the bundled samples (direct_heart.png on the saucer,
reflected_star.png in the cup, waves base shape) and prints a table per
stage and, with --ablation, E_visual (paper eq. 2 on hard renders against
the inputs projected on the base shape) and E_deform for each setting. The
reference for the time is the paper's: up to 30 minutes on a GTX 1080Ti.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from saucerfab.optimize.pipeline import run_design  # noqa: E402
from saucerfab.optimize.request import DesignRequest  # noqa: E402

SAMPLES = ROOT / "samples"


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


def one(ablation: str, args: argparse.Namespace, tmp: Path) -> dict:
    req = DesignRequest(
        SAMPLES / "direct_heart.png",
        SAMPLES / "reflected_star.png",
        shape="waves",
        resolution=args.resolution,
        image_size=args.image_size,
        max_iters=args.max_iters,
        ablation=ablation,
        frames=args.frames,
        barrier_weight=args.barrier_weight,
    )
    t0 = time.perf_counter()
    out = run_design(req, tmp / ablation, progress=lambda *a: None)
    wall = time.perf_counter() - t0
    meta = json.loads((out / "design.json").read_text())
    return {"ablation": ablation, "wall_s": wall, "metrics": meta["metrics"], "out": str(out)}


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--resolution", type=int, default=150)
    p.add_argument("--image-size", type=int, default=512)
    p.add_argument("--max-iters", type=int, default=400)
    p.add_argument("--frames", default="contain")
    p.add_argument("--barrier-weight", type=float, default=0.01)
    p.add_argument("--ablation", action="store_true", help="also run Figure 11's six settings")
    p.add_argument("--keep", help="copy the design folders here")
    p.add_argument("--settings", default="no_deform,laplacian,laplacian_bw,sparse_only,laplacian_sparse",
                   help="ablation settings to run besides full (comma-separated)")
    args = p.parse_args()
    print(f"machine: {machine()}")
    print(f"size: {args.resolution}x{args.resolution} heightfield, {args.image_size}px views, "
          f"max {args.max_iters} iterations per stage, frames={args.frames}, barrier weight {args.barrier_weight}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(args.keep) if args.keep else Path(d)
        print(flush=True)
        full = one("full", args, tmp)
        m = full["metrics"]
        print(f"\nfull design: {full['wall_s']:.1f} s wall (setup {m['setup_s']:.1f} s, texturing "
              f"{m['texturing_s']:.1f} s, previews {m['previews_s']:.1f} s)")
        print(f"{'stage':22s} {'iters':>6s} {'s':>7s} {'ms/it':>7s} {'E_visual':>10s} {'E_deform':>9s} {'conflict':>8s}")
        for st in m["stages"]:
            print(f"{st['name']:22s} {st['iterations']:6d} {st['seconds']:7.1f} "
                  f"{1000 * st['seconds_per_iteration']:7.0f} {st['E_visual']:10.1f} {st['E_deform']:9.4f} "
                  f"{100 * st['conflict_fraction']:7.1f}%")
        print(f"final E_visual {m['E_visual_final']:.1f}, E_deform {m['E_deform']:.4f}, "
              f"max |h - z| {m['max_abs_height_change']:.4f}")
        if args.ablation:
            rows = [full]
            for ab in args.settings.split(","):
                rows.append(one(ab, args, tmp))
            print("\nablation (Figure 11), E_visual = eq. 2 on hard textured renders:")
            print(f"{'setting':18s} {'E_visual':>10s} {'direct':>9s} {'reflected':>9s} {'E_deform':>9s} {'wall s':>7s}")
            for r in sorted(rows, key=lambda r: r["metrics"]["E_visual_final"]):
                mm = r["metrics"]
                print(f"{r['ablation']:18s} {mm['E_visual_final']:10.1f} {mm['E_visual_final_direct']:9.1f} "
                      f"{mm['E_visual_final_reflected']:9.1f} {mm['E_deform']:9.4f} {r['wall_s']:7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
