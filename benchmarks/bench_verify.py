"""Verified print quality of designs on the bundled pairs, and the speed of ``saucerfab verify``.

    .venv/bin/python benchmarks/bench_verify.py                      # the default design, every bundled pair
    .venv/bin/python benchmarks/bench_verify.py --design-args "--frames contain" --label contain
    .venv/bin/python benchmarks/bench_verify.py --pairs heart-star --resolution 60 --image-size 192   # quick

For each pair: ``saucerfab design`` exactly as a user types it (defaults,
plus ``--design-args``), ``saucerfab export --printer j55
--cup-diameter-mm 80 --formats obj``, then ``saucerfab verify``'s library
call at 256 px, 16 samples per pixel, from the design eye and a viewer's
two eyes (32 mm left and right), and prints one markdown table row per
pair and view: PSNR / SSIM / coverage from the design eye, each moved eye's
PSNR against the flat print (verify's score) and, in brackets, against the
picture after the best whole-picture shift (the score before the flat
print), with the design and verify wall times. The verify time is the issue's speed target (both views from
three eyes at 256 px within 60 s on 2 cores); the export's wall time of the
same design, in the same run, is printed beside it as the reference.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_design import machine  # noqa: E402

from saucerfab.cli import main as cli  # noqa: E402
from saucerfab.samples import GRAPHIC_PAIRS, PAIRS, PHOTO_PAIRS, SAMPLES  # noqa: E402  (one list)
from saucerfab.verify import EyeSpec, verify_print  # noqa: E402


def run_pair(pair: str, args: argparse.Namespace, tmp: Path) -> dict:
    direct, reflected = PAIRS[pair]
    design, print_dir = tmp / pair / "design", tmp / pair / "print"
    size = []
    if args.resolution:
        size += ["--resolution", str(args.resolution)]
    if args.image_size:
        size += ["--image-size", str(args.image_size)]
    cmd = ["design", "--direct", str(SAMPLES / direct), "--reflected", str(SAMPLES / reflected),
           "--out", str(design), "--quiet", *size, *shlex.split(args.design_args)]
    t0 = time.perf_counter()
    if cli(cmd) != 0:
        raise SystemExit(f"design failed for {pair}")
    t_design = time.perf_counter() - t0
    t0 = time.perf_counter()
    rc = cli(["export", str(design), "--printer", "j55", "--cup-diameter-mm", "80", "--formats", "obj",
              "--out", str(print_dir), "--quiet", "--no-verify", "--no-check"])
    t_export = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"export failed for {pair} (exit {rc})")
    res = verify_print(print_dir, eyes=EyeSpec("both"), res=args.res, spp=args.spp, all_formats=False,
                       pictures_dir=(Path(args.keep) / args.label / pair / "verify") if args.keep else None)
    printers = every_printer(design, tmp / pair) if args.all_printers else None
    decal = None
    if args.decal:
        from bench_eyes import decal_scores

        decal = decal_scores(design, res.renders, args.res)
    return {
        "pair": pair,
        "printers": printers,
        "command": " && ".join([
            f"saucerfab design --direct samples/{direct} --reflected samples/{reflected} --out D "
            + " ".join([*size, *shlex.split(args.design_args)]),
            "saucerfab export D --printer j55 --cup-diameter-mm 80 --formats obj --out P",
            f"saucerfab verify P --eyes both --res {args.res} --spp {args.spp} --primary-only",
        ]),
        "design_s": t_design,
        "export_s": t_export,
        "verify_s": res.seconds,
        "scores": {f"{v.view}/{v.eye}": v.to_dict() for v in res.files[0].views},
        "decal": decal,
    }


def every_printer(design: Path, tmp: Path) -> dict[str, dict]:
    """Export ``design`` for every bundled profile (its preferred format) and hold the check to --strict."""
    import contextlib
    import io

    from saucerfab.model.profiles import list_profiles

    out: dict[str, dict] = {}
    for key in list_profiles():
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
            rc = cli(["export", str(design), "--printer", key, "--no-verify", "--json", "-o", str(tmp / f"print_{key}")])
        doc = json.loads(buf.getvalue()) if rc == 0 else {}
        loud = [f"{f['severity']}: {f['message']}" for c in doc.get("checks", []) for f in c["findings"]
                if f["severity"] in ("error", "warning")]
        moved = [w for w in doc.get("warnings", []) if "relief vertices were moved" in w]
        out[key] = {"exit": rc, "strict_ok": rc == 0 and not loud, "findings": loud, "blunted": moved}
    return out


def printers_table(rows: list[dict]) -> str:
    keys = sorted({k for r in rows for k in (r.get("printers") or {})})
    out = ["| pair | " + " | ".join(keys) + " |", "|---|" + "---|" * len(keys)]
    for r in rows:
        cells = []
        for k in keys:
            e = (r.get("printers") or {}).get(k)
            cells.append("-" if e is None else ("exit 0, strict ok" if e["strict_ok"] else f"exit {e['exit']}, "
                                                  f"{len(e['findings'])} findings")
                         + (" (blunted)" if e and e["blunted"] else ""))
        out.append(f"| {r['pair']} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def table(rows: list[dict], label: str) -> str:
    """Per pair and view: the design eye's score, and each moved eye's against the flat print, with the
    older score against the picture after a whole-picture shift in brackets."""
    decal = any(r.get("decal") for r in rows)
    out = [
        (f"| pair ({label}) | view | design eye dB / SSIM / coverage | left eye dB (shifted picture dB) "
         "| right eye dB (shifted picture dB) "
         + ("| left / right eye vs the optimizer's decal dB " if decal else "") + "| design s | verify s |"),
        "|---|---|---|---|---|---|---|" + ("---|" if decal else ""),
    ]

    def db(v: dict, key: str = "psnr_db") -> str:
        return "-" if v.get(key) is None else f"{v[key]:.1f}"

    for r in rows:
        for view in ("direct", "reflected"):
            d, le, ri = (r["scores"][f"{view}/{e}"] for e in ("design", "left", "right"))
            out.append(
                f"| {r['pair']} | {view} | {db(d)} / {d['ssim']:.2f} / {100 * d['coverage']:.0f}% "
                f"| {db(le)} ({db(le, 'psnr_shift_db')}) | {db(ri)} ({db(ri, 'psnr_shift_db')}) "
                + (f"| {db(r['decal'][view + '/left'])} / {db(r['decal'][view + '/right'])} " if decal else "")
                + f"| {r['design_s']:.0f} | {r['verify_s']:.1f} |"
            )
    return "\n".join(out)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", default="all",
                   help=f"comma-separated, or graphics, photos, all: {', '.join(PAIRS)}")
    p.add_argument("--design-args", default="", help="extra 'saucerfab design' options, e.g. '--frames contain'")
    p.add_argument("--label", default="default", help="name of this configuration in the table")
    p.add_argument("--resolution", type=int, default=None, help="design --resolution (default: the design default)")
    p.add_argument("--image-size", type=int, default=None, help="design --image-size (default: the design default)")
    p.add_argument("--res", type=int, default=256)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--keep", help="keep the verify pictures here (LABEL/PAIR/verify)")
    p.add_argument("--json", help="also write the rows as JSON to this file")
    p.add_argument("--decal", action="store_true",
                   help="also score each moved eye against the picture lying flat on the saucer as that eye sees it "
                   "(bench_eyes.decal_scores: what the perspective of a tilted saucer does is not counted)")
    p.add_argument("--all-printers", action="store_true",
                   help="also export each design for every bundled printer and hold its check to --strict")
    args = p.parse_args()
    groups = {"all": list(PAIRS), "graphics": list(GRAPHIC_PAIRS), "photos": list(PHOTO_PAIRS)}
    pairs = groups.get(args.pairs) or args.pairs.split(",")
    unknown = [x for x in pairs if x not in PAIRS]
    if unknown:
        p.error(f"unknown pair(s) {', '.join(unknown)}; choose from {', '.join(PAIRS)}, graphics, photos or all")
    print(f"machine: {machine()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for pair in pairs:
            rows.append(run_pair(pair, args, Path(tmp)))
            print(f"{pair}: design {rows[-1]['design_s']:.0f} s, export {rows[-1]['export_s']:.1f} s, "
                  f"verify {rows[-1]['verify_s']:.1f} s", flush=True)
    print()
    for r in rows:
        print(f"{r['pair']}: {r['command']}")
    print(table(rows, args.label))
    if args.all_printers:
        print()
        print(printers_table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps({"label": args.label, "machine": machine(), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
