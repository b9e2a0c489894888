"""``saucerfab export``: a design folder -> print-ready files for a printer.

    saucerfab export DESIGN_DIR --out DIR [--printer j55] [--cup-diameter-mm 80] [--formats 3mf,obj,glb]

The printer and the cup size default to those the design was made for
(design.json), and the summary says which printer and why. A format the
printer does not take is refused before anything is written, unless
``--allow-format``: then it goes into ``DIR/other-formats/``, outside the
print set. An ``--out`` that holds an earlier export is replaced only with
``--force`` (the rule of every command that writes). Prints progress (stderr), a summary (size, triangles, volume, file sizes,
warnings) and the validity check of each written mesh file
(``saucerfab.check.check_mesh``). Exit code: 0 when written and every check
passes, the worst check's exit code otherwise (1 not printable, 2
unreadable), 2 for bad input (nothing written then) and when another export
is writing into the same ``--out`` (one at a time; the second stops at once).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

from saucerfab.fabricate.options import (
    BLEED_COMPENSATIONS,
    NEUTRAL_WALL_RGB,
    SEAT_KINDS,
    SHADING_COMPENSATIONS,
    FabOptions,
)
from saucerfab.files.formats import FORMATS, WRITERS, labels
from saucerfab.model.profiles import DEFAULT_PRINTER

HELP = f"turn a design into print-ready files ({labels(WRITERS.values())}) with scene.json"


def _rgb(text: str) -> tuple[int, int, int]:
    try:
        parts = tuple(int(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B integers, got {text!r}") from None
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers R,G,B, got {text!r}")
    return parts  # type: ignore[return-value]


def _default(name: str) -> str:
    """``FabOptions``'s default of option ``name`` as help texts show it (``3``, ``200,200,200``)."""
    v = next(f.default for f in fields(FabOptions) if f.name == name)
    return ",".join(map(str, v)) if isinstance(v, tuple) else f"{v:g}" if isinstance(v, float) else str(v)


def add_arguments(p: argparse.ArgumentParser) -> None:
    # FabOptions settings default to None ("not given"): run passes on only those given, so
    # each default is FabOptions' own (help texts read it from there)
    p.add_argument("design", help="the design folder (from 'saucerfab design')")
    p.add_argument("-o", "--out", required=True, help="output folder (new or empty; an earlier export needs --force)")
    p.add_argument("--force", action="store_true", help="replace the earlier export in --out")
    p.add_argument("--printer", default=None,
                   help="printer profile key or .toml path (default: the printer the design was made for, else "
                        f"{DEFAULT_PRINTER}; see 'saucerfab printers')")
    p.add_argument(
        "--cup-diameter-mm",
        type=float,
        default=None,
        help="width of the real cup in mm (circle: diameter; ellipse: 2a; prism: 2 x circumradius); "
        "default: the design's scene",
    )
    p.add_argument(
        "--formats",
        default=None,
        help=f"comma-separated: {', '.join(FORMATS)} (default: the printer's preferred format); a format the "
        "printer does not take is refused unless --allow-format",
    )
    p.add_argument("--allow-format", action="store_true",
                   help="write formats the printer does not take anyway, into OUT/other-formats/ (outside the print "
                        "set, checked without the printer)")
    p.add_argument("--texture-px", dest="texture_px", type=int,
                   help="atlas edge in pixels, a power of two (default: from the printer's dpi)")
    g = p.add_argument_group("solid and cup seat (millimetres)")
    g.add_argument("--base-mm", dest="base_thickness_mm", type=float, metavar="BASE_MM",
                   help=f"plate thickness under the cup's standing plane (default {_default('base_thickness_mm')})")
    g.add_argument("--min-thickness-mm", dest="min_thickness_mm", type=float,
                   help=f"material under the saucer's lowest point (default {_default('min_thickness_mm')})")
    g.add_argument("--seat", dest="seat", choices=SEAT_KINDS, help=f"cup seat kind (default {_default('seat')})")
    g.add_argument("--no-seat", action="store_true", help="same as --seat none")
    g.add_argument("--seat-depth-mm", dest="seat_depth_mm", type=float,
                   help=f"recess depth or ring height (default {_default('seat_depth_mm')})")
    g.add_argument("--seat-clearance-mm", dest="seat_clearance_mm", type=float,
                   help=f"gap around the cup's footprint (default {_default('seat_clearance_mm')})")
    g.add_argument("--seat-rim-mm", dest="seat_rim_mm", type=float,
                   help=f"plate width around the recess (default {_default('seat_rim_mm')})")
    g.add_argument("--saucer-rim-mm", dest="saucer_rim_mm", type=float, metavar="W",
                   help="a round saucer's raised rim: a ring W mm wide at its outer edge (refused with a rectangle; "
                        f"default {_default('saucer_rim_mm')}: none)")
    g.add_argument("--saucer-rim-height-mm", dest="saucer_rim_height_mm", type=float, metavar="H",
                   help="how far the rim's top stands above the highest relief under it (with --saucer-rim-mm; "
                        f"default {_default('saucer_rim_height_mm')})")
    c = p.add_argument_group("colour and files")
    c.add_argument("--wall-rgb", dest="wall_rgb", type=_rgb,
                   help="sRGB of walls, base and seat (default: the background the design meant around its direct "
                        "picture, its --background or else the picture's border colour, so the seat and walls do not "
                        f"stand out beside it; {','.join(map(str, NEUTRAL_WALL_RGB))} for a design without one)")
    c.add_argument("--no-inpaint", dest="inpaint", action="store_const", const="none",
                   help="leave unseen areas in the wall colour instead of continuing their neighbours' colours")
    c.add_argument("--bleed-compensation", dest="bleed_compensation", choices=BLEED_COMPENSATIONS,
                   help="pre-sharpen the texture for the printer's colour bleed (its profile's colour_bleed_mm), so "
                        f"the print's colours blur into the design's (default {_default('bleed_compensation')})")
    c.add_argument("--shading-compensation", dest="shading_compensation", choices=SHADING_COMPENSATIONS,
                   help="divide the texture by the shading the relief casts on itself under a light, so the print "
                        "lit by it shows the pictures evenly: ambient (a uniform room: the relief's ambient "
                        "occlusion) or room (verify --light room: that room and its lamp); the top comes out "
                        "at most 1.3x darker, and reads low in verify's emitted light "
                        f"(default {_default('shading_compensation')})")
    c.add_argument("--zip-obj", dest="obj_zip", action="store_const", const=True,
                   help="write OBJ + MTL + PNG as one zip (what bureaus ask for)")
    c.add_argument("--name", dest="name", help=f"file stem of the written files (default {_default('name')})")
    p.add_argument("--no-check", action="store_true", help="skip the validity check of the written files")
    p.add_argument("--no-verify", action="store_true",
                   help="skip the quick ray-traced verify of the print (see 'saucerfab verify' for a full one)")
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")


def _size(n: int) -> str:
    for unit, f in (("MB", 1e6), ("kB", 1e3)):
        if n >= f:
            return f"{n / f:.1f} {unit}"
    return f"{n} B"


def given_options(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`FabOptions` settings the user gave, by field name (``--no-seat`` as ``seat="none"``).

    Raises:
        ConfigError: ``--no-seat`` together with ``--seat recess`` or ``ring``; ``--saucer-rim-height-mm``
            without a rim (``--saucer-rim-mm`` left out or 0).
    """
    from saucerfab.errors import ConfigError

    if args.no_seat and args.seat not in (None, "none"):
        raise ConfigError(
            f"--no-seat and --seat {args.seat} contradict each other; give --seat {args.seat} "
            "for a seat, or --no-seat (same as --seat none) for none, not both"
        )
    given = {f.name: getattr(args, f.name) for f in fields(FabOptions) if getattr(args, f.name, None) is not None}
    if given.get("saucer_rim_height_mm") is not None and not given.get("saucer_rim_mm"):
        raise ConfigError(
            f"--saucer-rim-height-mm {given['saucer_rim_height_mm']:g} is the raised rim's height, but no rim "
            "was asked for; add --saucer-rim-mm W (the rim's width) for a rim, or leave the height out"
        )
    if args.no_seat:
        given["seat"] = "none"
    return given


def _design_inputs(folder: Path) -> object:
    """The inputs recorded in a design folder's design.json, or None when it cannot be read."""
    try:
        return json.loads((folder / "design.json").read_text(encoding="utf-8")).get("inputs", {})
    except (OSError, ValueError, AttributeError):
        return None


def check_other_export(design: str, out: str, force: bool) -> None:
    """Refuse, unless ``force``, to replace ``out`` when it holds an earlier export.

    One rule for every command that writes a folder (``design`` refuses an
    existing design the same way): an earlier result is replaced only with
    ``--force``. The message says whose export it is (this design's, or
    another's, named by its input files).
    """
    from saucerfab.errors import ConfigError

    summary = Path(out) / "export.json"
    if force or not summary.is_file():
        return
    ours = _design_inputs(Path(design))
    if ours is None:
        return  # not a readable design: export_design says what is wrong with it
    try:
        theirs = json.loads(summary.read_text(encoding="utf-8"))["design"]["inputs"]
    except (OSError, ValueError, KeyError, TypeError):
        theirs = None
    # export.json was written with json.dumps(default=str): compare in that form
    if theirs is not None and json.loads(json.dumps(ours, default=str)) == theirs:
        raise ConfigError(
            f"--out {str(out)!r} holds an earlier export of this design; add --force to replace it, "
            "or give another --out"
        )
    if isinstance(theirs, dict):
        files = ", ".join(f"{k} {v.get('file')}" for k, v in sorted(theirs.items()) if isinstance(v, dict) and v.get("file"))
        what = f"an export of another design ({files or 'other inputs'})"
    else:
        what = "an export whose design cannot be read from its export.json"
    raise ConfigError(
        f"--out {str(out)!r} holds {what}; exporting {str(design)!r} there would remove its files. "
        "Give another --out, or add --force to replace it"
    )


def run(args: argparse.Namespace) -> int:
    from saucerfab.extras import require, require_verify

    require("design")  # the fabrication: said now, not by an import halfway through
    require_verify(args.no_verify)

    from saucerfab.fabricate.pipeline import export_lock

    given = given_options(args)
    # One export per --out at a time, held from the look at what --out holds
    # to the last line printed: the export replaces the folder whole, and the
    # check and verify read (and the report names) the files it wrote, which
    # a second export into the folder would remove.
    with export_lock(args.out):
        return _run_locked(args, given)


def _run_locked(args: argparse.Namespace, given: dict[str, Any]) -> int:
    """The export, check, verify and summary, with ``--out`` held by :func:`export_lock`."""
    from saucerfab.workflow import make_print

    check_other_export(args.design, args.out, args.force)
    options = FabOptions(**given)
    formats = [f for f in args.formats.split(",") if f.strip()] if args.formats is not None else None

    def progress(step: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[{fraction * 100:5.1f}%] {step}", file=sys.stderr, flush=True)

    def verify_progress(msg: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[verify {fraction * 100:5.1f}%] {msg}", file=sys.stderr, flush=True)

    done = make_print(args.design, args.out, printer=args.printer, cup_diameter_mm=args.cup_diameter_mm,
                      formats=formats, options=options, allow_other_formats=args.allow_format,
                      check=not args.no_check, verify=not args.no_verify, progress=progress,
                      verify_progress=verify_progress)
    result = done.export
    profile = result.profile
    checks = [(c.written, c.report) for c in done.checks]
    exit_code = done.check_exit_code
    if args.json:
        d = result.to_dict()
        d["checks"] = [
            {
                "path": str(p),
                "verdict": getattr(r, "verdict", None),
                "exit_code": getattr(r, "exit_code", None),
                "findings": [
                    {"severity": f.severity, "code": f.code, "message": f.message} for f in getattr(r, "findings", [])
                ],
            }
            for p, r in checks
        ]
        d["verify"] = done.verify.to_dict() if done.verify is not None else None
        d["notes"] = list(done.notes)
        d["exit_code"] = exit_code
        print(json.dumps(d, indent=2))
        return exit_code

    x, y, z = result.bbox_mm
    from saucerfab.fabricate.pipeline import PRINTER_SOURCES

    print(f"exported {args.design} -> {result.out} for {profile.name} ({profile.key}; "
          f"{PRINTER_SOURCES[result.printer_source]})")
    print(f"  part     {x:.1f} x {y:.1f} x {z:.1f} mm; cup {result.cup_diameter_mm:g} mm ({result.mm_per_unit:g} mm per model unit)")
    print(f"  solid    {result.triangles:,} triangles, {result.vertices:,} vertices, volume {result.volume_mm3 / 1000:.2f} cm3")
    print(
        f"  texture  {result.texture_px} x {result.texture_px} px; "
        f"{result.unseen_fraction * 100:.1f}% of the top unseen by the viewer "
        f"({'continued from neighbours' if options.inpaint == 'harmonic' else 'wall colour'})"
    )
    print("  files")
    for name, n in sorted(result.file_bytes.items()):
        print(f"    {name:28s} {_size(n):>10s}")
    for w in result.warnings:
        print(f"  warning: {w}")
    if checks:
        print("  check")
        for path, rep in checks:
            name = path.relative_to(result.out).as_posix() if path.is_relative_to(result.out) else path.name
            if rep is None:
                print(f"    {name:28s} not checked: saucerfab.check is not installed")
                continue
            findings = list(getattr(rep, "findings", []))
            errors = sum(1 for f in findings if getattr(f, "severity", "") == "error")
            warns = sum(1 for f in findings if getattr(f, "severity", "") == "warning")
            outside = " (outside the print set: checked without the printer)" if path.parent != result.out else ""
            print(f"    {name:28s} {rep.verdict} ({errors} errors, {warns} warnings){outside}")
            for f in findings:
                if getattr(f, "severity", "") in ("error", "warning"):
                    print(f"      {f.severity}: {getattr(f, 'message', f)}")
    if done.verify is not None:
        from saucerfab.verify import stand_sentence

        v = done.verify
        print(f"  verify   {v.files[0].path.name} ray-traced at {v.res} px ({v.seconds:.0f} s; "
              f"'saucerfab verify {result.out}' for a full one)")
        from saucerfab.cli.verify import view_line

        for s in v.files[0].views:
            print(f"    {view_line(s)}")
        print(f"  stand    {stand_sentence(v.where_to_stand)}")
    for note in done.notes:
        print(f"  note: {note}")
    print(f"  report   {result.out / 'report.html'}")
    return exit_code
