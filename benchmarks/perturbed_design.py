"""``saucerfab design`` from a starting point moved by a rounding-level amount: the optimizer's path noise.

    .venv/bin/python benchmarks/perturbed_design.py SEED design --direct A.png --reflected B.png --out DIR ...

Everything as ``saucerfab design`` does it, except that the starting face
colours (0.5 grey) get uniform noise of at most :data:`AMOUNT` (about 17
float32 ulps at 0.5; the seed picks it). The optimizer's energies and
stages are unchanged, so the designs differ only by the path a few
last-bit differences send the solver down, as a rounding-level change of
any kernel does. ``bench_speed.py --noise K`` runs K of these per pair to
say how far the verified pictures move by that alone: the yardstick for a
change that alters the path (benchmarks/results/HISTORY.md, "The optimizer's path noise").
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: largest change of a starting colour (colours are in (0, 1))
AMOUNT = 1e-6


def main(argv: list[str]) -> int:
    import torch

    from saucerfab.cli import main as cli_main
    from saucerfab.optimize import pipeline

    if not argv or not argv[0].isdigit():
        print("usage: perturbed_design.py SEED design --direct A.png --reflected B.png --out DIR ... "
              "(SEED: a whole number >= 0)", file=sys.stderr)
        return 2
    seed, rest = int(argv[0]), argv[1:]
    start = pipeline._StageLoop.start

    def perturbed_start(self):  # type: ignore[no-untyped-def]
        h, c = start(self)
        g = torch.Generator().manual_seed(seed)
        return h, c + (torch.rand(c.shape, generator=g, dtype=c.dtype) * 2 - 1) * AMOUNT

    pipeline._StageLoop.start = perturbed_start  # type: ignore[method-assign]
    return cli_main(rest)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
