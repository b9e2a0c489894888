"""``saucerfab verify PRINT_DIR``: ray-trace the exported files and score them against the inputs.

    saucerfab verify PRINT_DIR [--eyes design|both|box:W,H[,N]] [--res N] [--min-psnr DB] [--json]
                               [--light emitted|room|lamp:X,Y,Z,SIZE[,POWER]] [--cup-metal NAME] [--bleed [MM]]

Writes the pictures (ray-traced view, reference, difference heat map) and
``verify.json`` into ``PRINT_DIR/verify/``, the print folder's own (an
earlier verify there is replaced as a whole), or into ``--out DIR`` (an
earlier verify there is replaced only with ``--force``, the rule of every
command that writes). Exit code: 0 every view passed, 1 some view
is under ``--min-psnr`` or ``--min-coverage``, or a whole view's stray share
is over ``--max-stray``, 2 the folder or its files cannot be read (nothing
is written then). Without ``--eyes``, the eyes the design was made for
(else the design eye and a viewer's two). ``--light room`` (or a lamp) also
renders the print under that light, the saucer a plastic and the cup a
metal (``--cup-metal``), and prints one more line per view: its lit PSNR
and the strength of its shading pattern beside a flat plate's.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "ray-trace an export folder's files and score what the viewer sees against the inputs; exit 0/1/2"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from saucerfab.cli.schema_flag import add_schema_flag
    from saucerfab.model.eyes import DEFAULT_IPD_MM
    from saucerfab.verify.core import (
        DEFAULT_MIN_COVERAGE,
        DEFAULT_MIN_PSNR_DB,
        DEFAULT_RES,
        DEFAULT_SPP,
    )

    p.add_argument("folder", nargs="?", metavar="PRINT_DIR", help="a folder written by 'saucerfab export'")
    p.add_argument("--eyes", default=None, metavar="MODE",
                   help="default: the eyes the design was made for (its --eyes), else both. "
                        "design (the design eye alone), both (it and a viewer's two eyes) or "
                        "box:W,H[,N] (it and an N x N grid over W x H mm facing the saucer)")
    p.add_argument("--ipd-mm", type=float, default=None,
                   help=f"distance between the viewer's eyes for --eyes both (default {DEFAULT_IPD_MM:g} mm)")
    p.add_argument("--res", type=int, default=DEFAULT_RES, help=f"render size in pixels per side (default {DEFAULT_RES})")
    p.add_argument("--spp", type=int, default=DEFAULT_SPP, help=f"samples per pixel (default {DEFAULT_SPP})")
    p.add_argument("--min-psnr", type=float, default=DEFAULT_MIN_PSNR_DB,
                   help=f"pass level of every view from every eye, dB (default {DEFAULT_MIN_PSNR_DB:g})")
    p.add_argument("--min-coverage", type=float, default=DEFAULT_MIN_COVERAGE,
                   help=f"least share of each view's frame the saucer must fill (default {DEFAULT_MIN_COVERAGE:g})")
    from saucerfab.verify.wholeview import DEFAULT_MAX_STRAY, STRAY_DISTANCE, TARGET_MAX_STRAY

    p.add_argument("--max-stray", type=float, default=DEFAULT_MAX_STRAY,
                   help=f"highest stray share of the whole view from every eye: the share of the saucer seen outside "
                        f"a frame (directly, or in the mirror) farther than {STRAY_DISTANCE:g} from the background "
                        f"(default {DEFAULT_MAX_STRAY:g}, lenient; the aim is {TARGET_MAX_STRAY:g})")
    from saucerfab.verify.bleed import BLEED_OF_PRINTER
    from saucerfab.verify.lighting import CUP_METALS, DEFAULT_LIGHT, DEFAULT_LIT_EYES, DEFAULT_LIT_METAL, LIGHT_FORMS, LIT_EYES

    p.add_argument("--light", default=DEFAULT_LIGHT, metavar="LIGHT",
                   help=f"what lights the print: {LIGHT_FORMS}. emitted (the default): the texture as emitted light in a "
                        "perfect mirror, as always; room: a dim room and a soft lamp above and in front; a real light "
                        "adds the lit renders and scores (the saucer a semi-glossy plastic, the cup a metal)")
    p.add_argument("--cup-metal", default=None, metavar="NAME",
                   help=f"the cup's metal under a real --light: {', '.join(CUP_METALS)} (default {DEFAULT_LIT_METAL}; "
                        "with --light emitted only mirror)")
    p.add_argument("--lit-eyes", default=None, metavar="WHICH",
                   help=f"under a real --light, the eyes whose views are rendered lit: {' or '.join(LIT_EYES)} "
                        f"(default {DEFAULT_LIT_EYES}; each eye adds about the emitted verify's time for that eye)")
    p.add_argument("--bleed", nargs="?", const=BLEED_OF_PRINTER, default=None, metavar="MM",
                   help="render the print with its colours blurred as the printer prints them: the colour bleed of "
                        "the printer the folder was exported for (its profile's colour_bleed_mm), or MM given; "
                        "shows what an export's --bleed-compensation brings back. Default: the colours as written")
    p.add_argument("--primary-only", action="store_true",
                   help="render only the first of OBJ, 3MF, GLB (the others are rendered from the design eye by default)")
    p.add_argument("-o", "--out", metavar="DIR", help="where to write the pictures and verify.json (default PRINT_DIR/verify)")
    p.add_argument("--force", action="store_true", help="replace an earlier verify in --out")
    p.add_argument("--json", action="store_true", help="print the saucerfab.verify/3 JSON document on stdout")
    add_schema_flag(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")


def view_line(v) -> str:  # type: ignore[no-untyped-def]
    """One view's score for the quick verifies of ``design`` and ``export``: view, eye, dB, coverage, verdict."""
    psnr = "  -- " if v.psnr_db != v.psnr_db else f"{v.psnr_db:4.1f}"
    against = "" if v.reference == "picture" else " (against the flat print)"
    return (f"{v.view:10s} from the {v.eye:6s} eye  {psnr} dB, {v.coverage * 100:3.0f}% of the picture"
            f"{'' if v.passed else '  LOW'}{against}")


def print_scores(result, out=None) -> None:  # type: ignore[no-untyped-def]
    """The per-view table of a :class:`~saucerfab.verify.VerifyResult` for people."""
    from saucerfab.verify import stand_sentence

    out = out if out is not None else sys.stdout
    print(f"verified {result.folder} (Mitsuba {result.renderer['version']}, {result.res} px, {result.spp} spp, "
          f"{result.seconds:.0f} s)", file=out)
    print(f"  where to stand: {stand_sentence(result.where_to_stand)}", file=out)
    for f in result.files:
        print(f"  {f.path.name}", file=out)
        for v in f.views:
            shift = ("" if v.psnr_shift_db != v.psnr_shift_db else
                     f"  against the flat print; the picture itself {v.psnr_shift_db:.1f} dB after a whole-picture shift "
                     f"of {v.shift_px[0]:+d},{v.shift_px[1]:+d} px")
            psnr = "   -- " if v.psnr_db != v.psnr_db else f"{v.psnr_db:5.1f}"
            print(f"    {v.view:10s} {v.eye:8s} {psnr} dB  SSIM {v.ssim:4.2f}  coverage {v.coverage * 100:5.1f}%  "
                  f"{'ok' if v.passed else 'LOW'}{shift}", file=out)
    if result.whole_views:
        print("  the whole view (everything the eye sees of the piece; stray: the saucer outside the frames far from "
              "the background)", file=out)

    def pct(x: float) -> str:
        return "  --" if x != x else f"{x * 100:3.0f}%"

    for w in result.whole_views:
        psnr = "   -- " if w.psnr_db != w.psnr_db else f"{w.psnr_db:5.1f}"
        print(f"    whole      {w.eye:8s} {psnr} dB  stray: saucer {pct(w.stray_direct)}, mirror {pct(w.stray_reflected)}  "
              f"reflected picture {pct(w.width_share)} of the cup's width  {'ok' if w.passed else 'STRAY'}", file=out)
    verdict = "every view passes" if result.passed else "some views are under the levels"
    print(f"  {verdict} (min {result.min_psnr_db:g} dB, coverage {result.min_coverage * 100:g}%, "
          f"stray at most {result.max_stray * 100:g}%; exit {result.exit_code})", file=out)


def print_lit_scores(result, out=None) -> None:  # type: ignore[no-untyped-def]
    """One line per view under a real light (``--light``): lit PSNR and shading pattern; nothing in emitted light."""
    if result.light is None:
        return
    out = out if out is not None else sys.stdout
    lamp = result.light.get("lamp")
    where = "" if lamp is None else f", lamp {lamp['size_mm']:g} mm at {','.join(f'{c:g}' for c in lamp['xyz_mm'])} mm"
    print(f"  under the {result.light['kind']} light (the cup {result.light['cup_metal']['name']}{where}; "
          f"{result.lit_seconds:.0f} s): against the picture under the light's smooth part (a flat print of it; "
          "the print against that flat print); "
          "shading pattern of the relief (flat plate)", file=out)

    def db(x: float) -> str:
        return "  -- " if x != x else f"{x:5.1f}"

    for v in result.lit_views:
        print(f"    {v.view:10s} {v.eye:8s} {db(v.lit_psnr_db)} dB lit ({db(v.flat_print_lit_psnr_db).strip()} dB; "
              f"against it {db(v.against_flat_print_psnr_db).strip()} dB)  pattern {db(v.shading_pattern_db)} dB "
              f"(flat plate {db(v.flat_pattern_db)} dB), shading {v.shading_p5:.2f}-{v.shading_p95:.2f}x "
              f"(flat {v.flat_p5:.2f}-{v.flat_p95:.2f}x), a white print reads {v.white_level:.2f}", file=out)


def run(args: argparse.Namespace) -> int:
    import json

    from saucerfab.cli.schema_flag import schema_asked
    from saucerfab.errors import ConfigError
    from saucerfab.files.fileio import atomic_dir
    from saucerfab.model.eyes import DEFAULT_IPD_MM
    from saucerfab.verify import parse_eyes, verify_print
    from saucerfab.verify.schema import JSON_SCHEMA

    if schema_asked(args, JSON_SCHEMA, args.folder, "give the print folder to verify: saucerfab verify PRINT_DIR"):
        return 0
    from saucerfab.extras import require

    require("verify")  # after --schema, which prints without Mitsuba
    # not given: the eyes the design was made for, else both (verify_print reads them from export.json)
    if args.ipd_mm is not None and (args.eyes or "").strip().lower() != "both":
        raise ConfigError(f"--ipd-mm {args.ipd_mm:g} sets the distance between a viewer's two eyes; give it with "
                          "--eyes both, or drop it")
    ipd = DEFAULT_IPD_MM if args.ipd_mm is None else args.ipd_mm
    eyes = parse_eyes(args.eyes, ipd) if args.eyes is not None else None
    from saucerfab.verify.bleed import bleed_width_mm
    from saucerfab.verify.lighting import cup_metal, lit_eyes, parse_light

    light = parse_light(args.light)
    cup_metal(args.cup_metal, light)  # a metal in emitted light is refused before anything is rendered
    lit_eyes(args.lit_eyes, light)
    folder = Path(args.folder)
    out = Path(args.out) if args.out else folder / "verify"
    bleed_mm = bleed_width_mm(folder, args.bleed)

    def progress(msg: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[{fraction * 100:5.1f}%] {msg}", file=sys.stderr, flush=True)

    from saucerfab.verify.printfolder import VerifyInputError

    if not folder.is_dir():
        raise VerifyInputError(f"{folder} is not a folder; give the folder 'saucerfab export --out' wrote")
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not (out / "verify.json").is_file())):
        raise ConfigError(f"--out {str(out)!r} exists and is not an earlier verify folder; give a new or empty folder")
    if args.out and (out / "verify.json").is_file() and not args.force:
        raise ConfigError(f"--out {str(out)!r} holds an earlier verify; add --force to replace it, or give another --out")
    with atomic_dir(out) as tmp:
        result = verify_print(
            folder, eyes=eyes, res=args.res, spp=args.spp, min_psnr_db=args.min_psnr,
            min_coverage=args.min_coverage, max_stray=args.max_stray, pictures_dir=tmp, all_formats=not args.primary_only, progress=progress,
            light=light, metal=args.cup_metal, lit_eye_choice=args.lit_eyes, bleed_mm=bleed_mm,
        )
        doc = result.to_dict()
        (tmp / "verify.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    if out.resolve().parent == folder.resolve():
        from saucerfab.pages.folder_pages import refresh_export_report

        refresh_export_report(folder)
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print_scores(result)
        if result.bleed_mm is not None:
            print(f"  the colours blurred as printed: a bleed of {result.bleed_mm:g} mm"
                  + ("" if args.bleed is not None else " (the texture was compensated for the printer's bleed)"))
        print_lit_scores(result)
        if result.light is None:  # emitted light: a texture compensated for a light's shading reads low here
            from saucerfab.verify.printfolder import shading_note

            note = shading_note(folder)
            if note is not None:
                print(f"  {note}")
        print(f"  pictures and verify.json in {out}")
    return result.exit_code
