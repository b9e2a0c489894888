"""The optimizer's projection onto printable relief: the numba wall kernels against their numpy reference.

    .venv/bin/python benchmarks/bench_relief.py [--repeat 15]

:class:`saucerfab.optimize.printable.CrestProjection` runs on every trial
step of every stage (611 times in a default heart-star design), so its time
is part of every iteration. The work here is what such a step sees: the
default saucer (``waves``, 150 x 150 vertices, the paper scene, J55 at an 80
mm cup) with the relief a design makes: a smooth random relief of
half ``delta`` and spikes of the full ``delta`` on a share of the vertices
(the sparse stage's; fixed seeds), projected with the optimizer's bounds and tightening. Each
configuration is timed in the same process, interleaved (kernels, numpy,
numpy, kernels, ...), and the two results are checked equal bit for bit.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_design import machine  # noqa: E402

from saucerfab.model import relief  # noqa: E402
from saucerfab.model.heightfield import base_shape  # noqa: E402
from saucerfab.optimize.printable import CrestProjection, print_target  # noqa: E402
from saucerfab.model.scene import paper_scene  # noqa: E402


def trial(share: float, seed: int = 0) -> tuple[CrestProjection, np.ndarray]:
    """The default design's projection and a trial height field with spikes on ``share`` of its vertices."""
    scene = paper_scene()
    n = scene.saucer.resolution
    base = base_shape("waves", n) * 1.0
    proj = CrestProjection(print_target(scene, "j55"), scene, base)
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    d = scene.saucer.delta * 0.998
    smooth = gaussian_filter(rng.normal(size=base.shape), 3.0)  # the Laplacian stages' gentle relief
    h = base + 0.5 * d * smooth / np.abs(smooth).max()
    spikes = rng.random(base.shape) < share  # the sparse stage's spikes
    h[spikes] = base[spikes] + rng.choice([-1.0, 1.0], spikes.sum()) * d
    return proj, h


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=15)
    args = p.parse_args()
    print(f"machine: {machine()}")
    print("| trial step | sweeps | vertices moved | kernels ms (median, min) | numpy ms (median, min) | numpy / kernels |")
    print("|---|---:|---:|---:|---:|---:|")
    fast = (relief.wall_widths, relief._bisect_tops)
    ref = (relief.wall_widths_reference, relief.bisect_tops_reference)
    for share in (0.0, 0.005, 0.02, 0.08):
        proj, h = trial(share)
        times: dict[str, list[float]] = {"kernels": [], "numpy": []}
        results = {}
        for k in range(args.repeat):
            for label in (("kernels", "numpy") if k % 2 == 0 else ("numpy", "kernels")):
                relief.wall_widths, relief._bisect_tops = fast if label == "kernels" else ref
                t0 = time.perf_counter()
                results[label] = proj.blunt(h)
                times[label].append(time.perf_counter() - t0)
        relief.wall_widths, relief._bisect_tops = fast
        a, b = results["kernels"], results["numpy"]
        if not np.array_equal(a.heights, b.heights):
            raise SystemExit("the kernels and the reference disagree")
        med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
        low = {k: min(v) * 1e3 for k, v in times.items()}
        print(f"| waves + spikes on {share:.1%} | {a.sweeps} | {a.changed} | {med['kernels']:.1f} ({low['kernels']:.1f}) "
              f"| {med['numpy']:.1f} ({low['numpy']:.1f}) | {med['numpy'] / med['kernels']:.1f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
