"""Benchmark: reflecting every saucer vertex in the mirror cup (saucerfab.model.mirror.reflect).

For a circle, an ellipse and a hexagonal prism at the paper's 150 x 150 grid,
times the vectorised :func:`saucerfab.model.mirror.reflect` (best of several runs)
against the plain per-vertex Python loop :func:`reflect_point_reference`
(scalar bisection, or a plane mirror per facet) run on an evenly spread
subset and scaled up to the whole grid. Also times Eberly's quartic for the
circle. Checks on the way that the fast and slow results agree.

    .venv/bin/python benchmarks/bench_mirror.py [--resolution 150] [--write benchmarks/results/mirror.md]
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from saucerfab.model import mirror  # noqa: E402
from saucerfab.model.heightfield import make_grid  # noqa: E402
from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup
from saucerfab.model.scene import Scene  # noqa: E402


def machine() -> str:
    """CPU model name and core count, as lscpu and nproc report them."""
    model = platform.processor() or "unknown CPU"
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
                break
    except (OSError, subprocess.CalledProcessError):
        pass
    try:
        cores = subprocess.run(["nproc"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        cores = "?"
    return f"{model}, nproc {cores}"


def best_of(fn: Callable[[], object], repeats: int) -> float:
    """Smallest wall time of ``repeats`` calls, seconds."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=150, help="grid vertices per side (default 150)")
    ap.add_argument("--subset", type=int, default=1500, help="vertices for the Python loop (default 1500)")
    ap.add_argument("--repeats", type=int, default=7, help="runs of the vectorised code; the best counts")
    ap.add_argument("--write", help="also write the table as Markdown to this file")
    args = ap.parse_args(argv)

    cups = {
        "circle r=0.4": CircleCup(0.4),
        "ellipse 0.45x0.33 rot 20": EllipseCup((0.45, 0.33), 20.0),
        "hexagon prism R=0.45 rot 30": PrismCup(6, 0.45, 30.0),
    }
    rows = []
    for label, cup in cups.items():
        scene = Scene(cup=cup)
        xy = make_grid(replace(scene.saucer, resolution=args.resolution)).xy()
        v = xy.shape[0]
        mirror.reflect(scene, xy)  # warm-up
        t_fast = best_of(lambda: mirror.reflect(scene, xy), args.repeats)
        idx = np.linspace(0, v - 1, min(args.subset, v)).astype(int)
        pieces = {pc.facet: pc for pc in mirror.reflect(scene, xy)}
        ref: list = []

        def loop() -> None:
            ref[:] = [mirror.reflect_point_reference(cup, scene.camera, xy[i]) for i in idx]

        t_loop = best_of(loop, 3) * v / len(idx)
        # the two must agree, or the timing means nothing
        err = 0.0
        for i, res in zip(idx, ref):
            assert {k for k, pc in pieces.items() if pc.valid_xy[i]} == {r[0] for r in res}
            for k, _, r, _ in res:
                err = max(err, float(np.abs(pieces[k].r_xy[i] - r).max()))
        rows.append((label, "reflect (vectorised)", v, t_fast, t_loop / t_fast, err))
        rows.append((label, "Python loop (scaled)", v, t_loop, 1.0, 0.0))
        if isinstance(cup, CircleCup):
            t_q = best_of(lambda: mirror.reflect_circle_quartic(cup, scene.camera, xy), 2)
            q = mirror.reflect_circle_quartic(cup, scene.camera, xy)
            both = q.valid_xy & pieces[-1].valid_xy
            err_q = float(np.abs(q.r_xy[both] - pieces[-1].r_xy[both]).max())
            rows.append((label, "Eberly quartic (vectorised)", v, t_q, t_loop / t_q, err_q))

    head = "| cup | method | vertices | time ms | speed-up vs loop | max abs R diff vs fast |"
    lines = [head, "|---|---|---:|---:|---:|---:|"]
    for label, method, v, t, speed, err in rows:
        lines.append(f"| {label} | {method} | {v} | {t * 1e3:.1f} | {speed:.0f}x | {err:.1e} |")
    table = "\n".join(lines)
    info = (
        f"Machine: {machine()}; Python {platform.python_version()}, numpy {np.__version__}.\n"
        f"Command: `.venv/bin/python benchmarks/bench_mirror.py --resolution {args.resolution} "
        f"--subset {args.subset} --repeats {args.repeats}`"
    )
    print(info)
    print()
    print(table)
    if args.write:
        from saucerfab.files.fileio import write_text_atomic

        text = (
            "# Mirror reflection benchmark\n\n"
            "Reflection of every saucer vertex at the paper's grid (the xy part, computed once\n"
            "per design), best of the runs. The Python loop is the scalar reference (best of 3)\n"
            "run on an evenly spread subset and scaled to the whole grid. The last column is the\n"
            "largest difference of the virtual point R from the vectorised result (model units).\n\n"
            f"{info}\n\n{table}\n"
        )
        write_text_atomic(args.write, text)
        print(f"\nwrote {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
