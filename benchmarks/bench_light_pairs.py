"""Every bundled pair's default export under the room light, plain and shading-compensated (issue 45).

    .venv/bin/python benchmarks/bench_light_pairs.py                        # every bundled pair
    .venv/bin/python benchmarks/bench_light_pairs.py --pairs heart-star,astronaut-rocket --keep /tmp/lit

Per pair: the default design and export a user gets (``bench_light.make_export``:
every default, the design's printer and its preferred format), and the same
design exported again with ``--shading-compensation room``
(``bench_light.export_shaded``). Each export is verified by this checkout at
256 px, 16 samples a pixel, from the design eye, primary file only: in
emitted light (the default) and under ``--light room`` (the default cup metal,
seed 0). Per view it prints the emitted PSNR, the lit PSNR, the lit PSNR of a
flat print of the same picture under the same light (the same plastic without
the relief: :func:`saucerfab.verify.litscore.flat_print`), the print against
that flat print (both lit, no gain) and the relief's shading pattern,
plain -> compensated, and the plain export's verify times (the lit one against
the emitted one, design eye). ``bench_light.py`` measures the lit score's noise
(two seeds) and every eye lit on one pair; this table is the per-pair picture.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_design import machine  # noqa: E402
from bench_light import export_shaded, make_export  # noqa: E402
from bench_speed import _load  # noqa: E402

from saucerfab.samples import PAIRS  # noqa: E402
from saucerfab.verify import EyeSpec, verify_print  # noqa: E402
from saucerfab.verify.lighting import parse_light  # noqa: E402


def verified(folder: Path, keep: Path | None, label: str) -> tuple:
    """(emitted, room) verify results of ``folder`` from the design eye (pictures under ``keep/label``)."""
    common = dict(eyes=EyeSpec("design"), res=256, spp=16, all_formats=False)
    emitted = verify_print(folder, pictures_dir=keep / f"{label}_emitted" if keep else None, **common)
    room = verify_print(folder, light=parse_light("room"), lit_seed=0,
                        pictures_dir=keep / f"{label}_room" if keep else None, **common)
    return emitted, room


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", default="all", help=f"comma-separated or all: {', '.join(PAIRS)}")
    p.add_argument("--keep", type=Path, help="keep the verify pictures under this folder, per pair")
    args = p.parse_args()
    pairs = list(PAIRS) if args.pairs == "all" else args.pairs.split(",")
    unknown = [x for x in pairs if x not in PAIRS]
    if unknown:
        p.error(f"unknown pairs {unknown}; choose from {', '.join(PAIRS)}")
    print(f"machine: {machine()}; start load {_load()}", flush=True)
    rows = []
    for pair in pairs:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            plain, _ = make_export(pair, Path(tmp))
            shaded = Path(tmp) / "print_shaded"
            export_shaded(Path(tmp) / "design", shaded, "room")
            keep = args.keep / pair if args.keep else None
            before, after = verified(plain, keep, "plain"), verified(shaded, keep, "room")
            print(f"{pair}: {time.perf_counter() - t0:.0f} s (load {_load()}); verify of the plain export: emitted "
                  f"{before[0].seconds:.1f} s, --light room {before[1].seconds:.1f} s "
                  f"({before[1].seconds / before[0].seconds:.2f}x)", flush=True)
        for lit0 in before[1].lit_views:
            lit1 = next(v for v in after[1].lit_views if (v.view, v.eye) == (lit0.view, lit0.eye))
            e0, e1 = before[0].score(lit0.view, lit0.eye), after[0].score(lit0.view, lit0.eye)
            rows.append(f"| {pair} | {lit0.view} | {e0.psnr_db:.1f} -> {e1.psnr_db:.1f} | {lit0.lit_psnr_db:.1f} -> "
                        f"{lit1.lit_psnr_db:.1f} | {lit0.flat_print_lit_psnr_db:.1f} | "
                        f"{lit0.against_flat_print_psnr_db:.1f} -> {lit1.against_flat_print_psnr_db:.1f} | "
                        f"{lit0.shading_pattern_db:.1f} -> {lit1.shading_pattern_db:.1f} |")
    print()
    print("saucerfab design --direct D --reflected R --out X && saucerfab export X --out P --no-verify "
          "[--shading-compensation room]; verify P --eyes design --res 256 --spp 16 --primary-only [--light room]")
    print()
    print("| pair | view | emitted dB: plain -> compensated | room light dB: plain -> compensated "
          "| a flat print under the room light dB | the print against its flat print, lit, dB: plain -> compensated "
          "| shading pattern dB: plain -> compensated |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"end load {_load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
