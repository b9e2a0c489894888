"""Round saucers for every bundled printer: design, export and `check --strict`, pair by pair (issue 44).

    .venv/bin/python benchmarks/bench_round_printers.py                       # every bundled pair
    .venv/bin/python benchmarks/bench_round_printers.py --pairs heart-star,chelsea-coffee

For each pair, ``saucerfab design --scene round`` as a user types it (defaults; the J55) and exports
for every bundled printer whose build area takes its 200 mm disc; for a printer that does not (the
HP's 190 mm), a design made for that printer (``--printer KEY``: the round scene's disc shrinks to the
largest it takes). Each export is checked with ``saucerfab check --strict --printer KEY``. Prints a
row per pair and printer: the export's and the check's exit status and seconds, and the disc's size.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from saucerfab.model.profiles import list_profiles, load_profile  # noqa: E402
from saucerfab.model.scene import round_scene  # noqa: E402
from saucerfab.samples import PAIRS, pair_paths  # noqa: E402


def run(args: list[str]) -> tuple[int, float]:
    """``saucerfab ARGS`` in a child process: (exit status, seconds)."""
    t = time.perf_counter()
    rc = subprocess.run([sys.executable, "-m", "saucerfab", *args], cwd=ROOT, capture_output=True).returncode
    return rc, time.perf_counter() - t


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", default="all", help=f"comma-separated or all: {', '.join(PAIRS)}")
    args = p.parse_args()
    pairs = list(PAIRS) if args.pairs == "all" else args.pairs.split(",")
    scene = round_scene()
    disc_mm = 2.0 * scene.saucer.radius * scene.mm_per_unit
    print("| pair | printer | disc mm | design s | export rc (s) | check --strict rc |")
    print("|---|---|---:|---:|---|---:|")
    failures = 0
    with tempfile.TemporaryDirectory(prefix="saucerfab-round-") as tmp_s:
        tmp = Path(tmp_s)
        for pair in pairs:
            direct, reflected = pair_paths(pair)
            designs: dict[str, tuple[Path, float]] = {}
            for key in sorted(list_profiles()):
                own = min(load_profile(key).build_volume_mm[:2]) < disc_mm  # the J55's design does not fit it
                made_for = key if own else "j55"
                if made_for not in designs:
                    folder = tmp / pair / f"design-{made_for}"
                    rc, secs = run(["design", "--direct", str(direct), "--reflected", str(reflected), "--scene",
                                    "round", "--printer", made_for, "-o", str(folder), "--no-verify", "-q"])
                    if rc != 0:
                        print(f"| {pair} | {key} | - | design failed (exit {rc}) | - | - |", flush=True)
                        failures += 1
                        continue
                    designs[made_for] = (folder, secs)
                folder, secs = designs[made_for]
                saucer = json.loads((folder / "design.json").read_text())["scene"]["saucer"]
                mm = (saucer["x_range"][1] - saucer["x_range"][0]) * scene.mm_per_unit
                out = tmp / pair / f"print-{key}"
                rc_e, t_e = run(["export", str(folder), "--printer", key, "-o", str(out), "--no-verify", "-q"])
                rc_c, _ = run(["check", "--strict", "--printer", key, "-q", str(out)]) if rc_e == 0 else (None, 0.0)
                failures += int(rc_e != 0 or rc_c != 0)
                whose = "" if made_for == key else f" ({made_for})"
                print(f"| {pair} | {key} | {mm:.0f} | {secs:.0f}{whose} | {rc_e} ({t_e:.0f}) | {rc_c} |", flush=True)
    print(f"\n{failures} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
