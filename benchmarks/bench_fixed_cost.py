"""A design's fixed cost (everything but the optimizer's stages), old code against this checkout, interleaved.

    .venv/bin/python benchmarks/bench_fixed_cost.py --old HEAD --pairs rocket-chelsea,coffee-hubble --rounds 3

The whole-design time of ``bench_speed.py`` moves by 10-20 % between
identical runs on a shared two-core machine, mostly in the stages (the same
iterations took 18.9 and 24.0 s in two runs, 2026-12-03). A change to what a
design does besides optimizing (start-up, preparation, texturing, previews,
writing the folder, the quick verify) is read here instead: each design's
wall time less the seconds its stages report in ``design.json``, for
``saucerfab design`` exactly as a user types it (defaults, quick verify
included), old and new alternating (old first on odd rounds), so that a
drifting load favours neither. Medians over the rounds; the stage seconds are
printed too, as a check that the two ran the same optimisation.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from bench_speed import PAIRS, ROOT, _load as load, design, machine, old_copy  # also puts the checkout on sys.path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="git revision of the old code (e.g. HEAD before a change)")
    ap.add_argument("--pairs", default="rocket-chelsea,coffee-hubble", help=f"comma-separated: {', '.join(PAIRS)}")
    ap.add_argument("--rounds", type=int, default=3, help="designs per pair and code (default 3)")
    args = ap.parse_args(argv)
    pairs = args.pairs.split(",")
    unknown = [p for p in pairs if p not in PAIRS]
    if unknown:
        ap.error(f"unknown pair(s) {', '.join(unknown)}; choose from {', '.join(PAIRS)}")
    if args.rounds < 1:
        ap.error("--rounds must be at least 1")
    print(f"machine: {machine()}; old = {args.old}, new = this checkout; start load {load()}", flush=True)
    rows: dict[tuple[str, str], list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="saucerfab-fixed-") as tmp:
        root = Path(tmp)
        codes = {"old": old_copy(args.old, root / "old"), "new": ROOT}
        for pair in pairs:
            for r in range(args.rounds):
                order = ("old", "new") if r % 2 == 0 else ("new", "old")
                for label in order:
                    out = root / f"{pair}-{label}-{r}"
                    d = design(codes[label], pair, out, [])
                    stages = sum(s for _, _, s in d["stages"])
                    rows.setdefault((pair, label), []).append((d["seconds"], stages))
                    print(f"{pair} {label} round {r + 1}: {d['seconds']:.1f} s, stages {stages:.1f} s, "
                          f"fixed {d['seconds'] - stages:.2f} s (load {load()}) "
                          f"{time.strftime('%H:%M:%S')}", flush=True)
    print("\n| pair | code | wall s (median) | stages s | fixed s = wall - stages | fixed, each round |")
    print("|---|---|---:|---:|---:|---|")
    for pair in pairs:
        for label in ("old", "new"):
            runs = rows[(pair, label)]
            fixed = [w - s for w, s in runs]
            print(f"| {pair} | {label} | {statistics.median(w for w, _ in runs):.1f} | "
                  f"{statistics.median(s for _, s in runs):.1f} | {statistics.median(fixed):.2f} | "
                  f"{', '.join(f'{x:.2f}' for x in fixed)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
