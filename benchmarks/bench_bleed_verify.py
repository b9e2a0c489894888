"""Colour bleed as verify renders it: the default export with and without ``--bleed-compensation``, verified
with and without ``--bleed`` (issue 45).

    .venv/bin/python benchmarks/bench_bleed_verify.py [--pairs heart-star,fish-moon,tree-note] [--res 256]

For each pair: ``saucerfab design`` as typed (defaults, the J55), ``saucerfab export`` twice (compensation
off, the default, and on), and ``saucerfab verify --eyes design --primary-only`` of each export with the
colours as written and with the J55's bleed (``--bleed``). Prints the design eye's PSNR per view: what the
bleed costs the print, and what the compensation gives back of it (the issue asks 3 dB on the graphics).
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

from saucerfab.samples import PAIRS, pair_paths  # noqa: E402

GRAPHICS = ("heart-star", "fish-moon", "tree-note")


def saucerfab(*args: str) -> subprocess.CompletedProcess[str]:
    """``saucerfab ARGS`` in a child process (this checkout's code); its exit status is the caller's to judge."""
    return subprocess.run([sys.executable, "-m", "saucerfab", *args], cwd=ROOT, capture_output=True, text=True)


def psnr(folder: Path, out: Path, res: int, bleed: bool) -> dict[str, float]:
    """The design eye's PSNR per view of ``folder``'s primary file."""
    extra = ["--bleed"] if bleed else []
    proc = saucerfab("verify", str(folder), "--eyes", "design", "--primary-only", "--res", str(res), "--json",
                     "-q", "-o", str(out), *extra)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"verify {folder} failed: {proc.stderr}")
    return {v["view"]: v["psnr_db"] for v in json.loads(proc.stdout)["files"][0]["views"]}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", default=",".join(GRAPHICS), help=f"comma-separated: {', '.join(PAIRS)}")
    p.add_argument("--res", type=int, default=256, help="verify's render size (default 256)")
    args = p.parse_args()
    print(f"verify --res {args.res}, design eye; PSNR dB direct / reflected")
    print("| pair | compensation | as written | with the J55's bleed | export s |")
    print("|---|---|---|---|---:|")
    with tempfile.TemporaryDirectory(prefix="saucerfab-bleed-") as tmp_s:
        tmp = Path(tmp_s)
        for pair in args.pairs.split(","):
            direct, reflected = pair_paths(pair)
            design = tmp / pair / "design"
            if saucerfab("design", "--direct", str(direct), "--reflected", str(reflected), "-o", str(design),
                         "--no-verify", "-q").returncode != 0:
                raise SystemExit(f"design of {pair} failed")
            for comp in ("off", "on"):
                folder = tmp / pair / f"print-{comp}"
                t = time.perf_counter()
                if saucerfab("export", str(design), "-o", str(folder), "--no-verify", "-q",
                             "--bleed-compensation", comp).returncode != 0:
                    raise SystemExit(f"export of {pair} ({comp}) failed")
                secs = time.perf_counter() - t
                plain = psnr(folder, tmp / pair / f"v-{comp}", args.res, bleed=False)
                bled = psnr(folder, tmp / pair / f"v-{comp}-bleed", args.res, bleed=True)
                print(f"| {pair} | {comp} | {plain['direct']:.1f} / {plain['reflected']:.1f} | "
                      f"{bled['direct']:.1f} / {bled['reflected']:.1f} | {secs:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
