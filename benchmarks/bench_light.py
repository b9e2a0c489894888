"""``saucerfab verify --light room`` against the emitted verify on one bundled pair's default export (issue 45).

    .venv/bin/python benchmarks/bench_light.py                          # heart-star, design + export made here
    .venv/bin/python benchmarks/bench_light.py --print-dir /tmp/lx/p    # an export made before
    .venv/bin/python benchmarks/bench_light.py --pair chelsea-coffee --metal platinum

The export is the default one a user gets: ``saucerfab design --direct D
--reflected R --out DESIGN`` (every default) and ``saucerfab export DESIGN
--out PRINT --no-verify`` (the design's printer, its preferred format). Then
verify's library call at 256 px, 16 samples per pixel, from the design eye and
a viewer's two eyes, primary file only, once in emitted light, twice under
``--light room`` (the lit views from the design eye, the default) with two
seeds (the second renders the lit views with other samples: ``lit_seed``;
their difference is the lit scores' noise), and once with ``--lit-eyes
all`` (every eye lit), and prints per view and eye: the
emitted PSNR, the lit PSNR of both runs (their difference is the noise of the
lit score), a flat print's lit PSNR (the plate printed with the picture: the
same plastic and light without the relief), the gain (the cup's metal shows in the reflected views), the
shading pattern of the relief and of a flat plate (dB, and 5th-95th
percentiles of white / smooth), how bright a white print looks there, and
the wall times (the issue's target: the lit verify within 2x the emitted
one's on two cores).

``--shading-compensation room`` (or ``ambient``) adds a second arm: the same
design exported with that ``saucerfab export --shading-compensation``, verified
in emitted light and under ``--light room`` (seed 0, the design eye), and a
second table, uncompensated against compensated, per view and eye.
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

from bench_design import machine

from saucerfab.cli import main as cli
from saucerfab.samples import DEMO_PAIR, PAIRS, SAMPLES
from saucerfab.verify import EyeSpec, verify_print
from saucerfab.verify.lighting import DEFAULT_LIT_METAL, parse_light


def make_export(pair: str, tmp: Path) -> tuple[Path, str]:
    """The pair's default design and export in ``tmp``; (print folder, the commands)."""
    direct, reflected = PAIRS[pair]
    design, print_dir = tmp / "design", tmp / "print"
    t0 = time.perf_counter()
    if cli(["design", "--direct", str(SAMPLES / direct), "--reflected", str(SAMPLES / reflected),
            "--out", str(design), "--quiet"]) != 0:
        raise SystemExit(f"design failed for {pair}")
    if cli(["export", str(design), "--out", str(print_dir), "--quiet", "--no-verify"]) != 0:
        raise SystemExit(f"export failed for {pair}")
    print(f"design + export {time.perf_counter() - t0:.0f} s", flush=True)
    return print_dir, (f"saucerfab design --direct samples/{direct} --reflected samples/{reflected} --out D && "
                       "saucerfab export D --out P --no-verify")


def export_shaded(design: Path, out: Path, light: str) -> str:
    """The design exported again with ``--shading-compensation light`` into ``out``; the command."""
    t0 = time.perf_counter()
    if cli(["export", str(design), "--out", str(out), "--quiet", "--no-verify", "--shading-compensation", light]) != 0:
        raise SystemExit(f"export --shading-compensation {light} failed")
    print(f"export --shading-compensation {light} {time.perf_counter() - t0:.0f} s", flush=True)
    return f"saucerfab export D --out P2 --no-verify --shading-compensation {light}"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pair", default=DEMO_PAIR, choices=list(PAIRS))
    p.add_argument("--print-dir", help="verify this export instead of making the pair's")
    p.add_argument("--metal", default=DEFAULT_LIT_METAL, help="the cup's metal under the room light")
    p.add_argument("--res", type=int, default=256)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--keep", help="write the verify pictures under this folder (emitted/, room/)")
    p.add_argument("--shading-compensation", choices=("ambient", "room"),
                   help="a second arm: the design exported with this --shading-compensation, verified likewise")
    args = p.parse_args()
    if args.shading_compensation and args.print_dir:
        p.error("--shading-compensation exports the design made here: leave out --print-dir")
    print(f"machine: {machine()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        if args.print_dir:
            folder, made = Path(args.print_dir), f"(the export in {args.print_dir})"
        else:
            folder, made = make_export(args.pair, Path(tmp))
        keep = Path(args.keep) if args.keep else None
        common = {"eyes": EyeSpec("both"), "res": args.res, "spp": args.spp, "all_formats": False}
        emitted = verify_print(folder, pictures_dir=keep / "emitted" if keep else None, **common)
        room = parse_light("room")
        lit = [verify_print(folder, light=room, metal=args.metal, lit_seed=seed,
                            pictures_dir=keep / f"room{seed}" if keep else None, **common) for seed in (0, 1)]
        every = verify_print(folder, light=room, metal=args.metal, lit_eye_choice="all",
                             pictures_dir=keep / "room_all" if keep else None, **common)
        if args.shading_compensation:
            shaded = Path(tmp) / "print_shaded"
            shaded_made = export_shaded(Path(tmp) / "design", shaded, args.shading_compensation)
            import json

            block = json.loads((shaded / "export.json").read_text())["shading"]
            arm = [verify_print(shaded, pictures_dir=keep / "emitted_shaded" if keep else None, **common),
                   verify_print(shaded, light=room, metal=args.metal, lit_seed=0,
                                pictures_dir=keep / "room_shaded" if keep else None, **common)]
    print()
    print(f"pair {args.pair}: {made}")
    print(f"verify P --eyes both --res {args.res} --spp {args.spp} --primary-only "
          f"[--light room --cup-metal {args.metal} [--lit-eyes all]]")
    print()
    print("| view | eye | emitted dB | lit dB (seed 0 / 1) | a flat print lit dB | gain R,G,B | white print reads "
          "| pattern dB: relief (seed 1) (flat plate) | shading p5-p95: relief (flat plate) |")
    print("|---|---|---|---|---|---|---|---|---|")
    second = {(v.eye, v.view): v for v in lit[1].lit_views}
    for v0 in every.lit_views:
        v1 = second.get((v0.eye, v0.view))
        e = emitted.score(v0.view, v0.eye)
        lit_db = f"{v0.lit_psnr_db:.1f}" + ("" if v1 is None else f" / {v1.lit_psnr_db:.1f}")
        pattern = f"{v0.shading_pattern_db:.1f}" + ("" if v1 is None else f" ({v1.shading_pattern_db:.1f})")
        print(f"| {v0.view} | {v0.eye} | {e.psnr_db:.1f} | {lit_db} | {v0.flat_print_lit_psnr_db:.1f} | {', '.join(f'{g:.2f}' for g in v0.gain_rgb)} "
              f"| {v0.white_level:.3f} | {pattern} ({v0.flat_pattern_db:.1f}) "
              f"| {v0.shading_p5:.2f}-{v0.shading_p95:.2f} ({v0.flat_p5:.2f}-{v0.flat_p95:.2f}) |")
    print()
    print(f"wall time: emitted {emitted.seconds:.1f} s; --light room (design eye lit) {lit[0].seconds:.1f} s and "
          f"{lit[1].seconds:.1f} s (of which lit {lit[0].lit_seconds:.1f} s and {lit[1].lit_seconds:.1f} s): "
          f"{lit[0].seconds / emitted.seconds:.2f}x and {lit[1].seconds / emitted.seconds:.2f}x the emitted verify; "
          f"--lit-eyes all {every.seconds:.1f} s (lit {every.lit_seconds:.1f} s): {every.seconds / emitted.seconds:.2f}x")
    if args.shading_compensation:
        print()
        print(f"second arm: {shaded_made} (shading block: power {block['power']:g}, global factor "
              f"{block['global_factor']:.2f}, the top's mean linear albedo {block['brightness_ratio']:.3f}x the "
              f"plain one's, clipped {100 * block['clipped_share']:.2f} % of the top's texel channels, pattern p5-p95 "
              f"{block['pattern_p5_p95'][0]:.2f}-{block['pattern_p5_p95'][1]:.2f})")
        print()
        print("| view | eye | emitted dB: plain -> compensated | lit dB (seed 0): plain -> compensated "
              "| gain R,G,B compensated |")
        print("|---|---|---|---|---|")
        plain_lit = {(v.eye, v.view): v for v in lit[0].lit_views}
        for v in arm[1].lit_views:
            e0, e1 = emitted.score(v.view, v.eye), arm[0].score(v.view, v.eye)
            p0 = plain_lit[(v.eye, v.view)]
            print(f"| {v.view} | {v.eye} | {e0.psnr_db:.1f} -> {e1.psnr_db:.1f} | {p0.lit_psnr_db:.1f} -> "
                  f"{v.lit_psnr_db:.1f} | {', '.join(f'{g:.2f}' for g in v.gain_rgb)} |")
        for eye in ("left", "right"):
            for view in ("direct", "reflected"):
                e0, e1 = emitted.score(view, eye), arm[0].score(view, eye)
                print(f"| {view} | {eye} | {e0.psnr_db:.1f} -> {e1.psnr_db:.1f} | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
