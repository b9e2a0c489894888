"""``saucerfab design``: two images and a saucer shape -> a design folder."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from saucerfab.model.design import Design
    from saucerfab.model.scene import Scene
    from saucerfab.optimize.looks import Look

HELP = "optimize a saucer: direct + reflected image and a base shape -> design folder"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options; every design option defaults to None ("not given") and its default is DesignRequest's."""
    from saucerfab.model.cups import CUP_SPEC_USAGE
    from saucerfab.model.eyes import DEFAULT_IPD_MM
    from saucerfab.model.scene import PRESETS, default_scene, round_scene
    from saucerfab.optimize.energies import WEIGHTS
    from saucerfab.optimize.request import (
        ABLATIONS,
        COLOR_INITS,
        ENHANCEMENTS,
        FRAMES,
        METHODS,
        PRISM_PLACEMENTS,
        SURROUND_WEIGHT,
        DesignRequest,
    )
    from saucerfab.optimize.stages import STAGE_CAPS

    default = DesignRequest.default
    default_sizes = default_scene()  # the default scene's sizes
    round_ = round_scene()  # the round saucer's
    p.add_argument("--direct", required=True, help="image seen directly on the saucer")
    p.add_argument("--reflected", required=True, help="image seen in the mirror cup")
    p.add_argument("--reflected2", help="second reflected image (needs --cup prism:N)")
    p.add_argument("--shape", help=f"base shape: built-in name or .png/.npy (default {default('shape')})")
    p.add_argument("--height-scale", type=float,
                   help=f"model units per unit of a shape file (default {default('height_scale')})")
    p.add_argument("--scene", help=f"scene TOML or preset: {', '.join(PRESETS)} (default: {default('scene')}; "
                   "round: a round saucer with the cup at its centre)")
    p.add_argument("--cup", help=f"cup override: {CUP_SPEC_USAGE}")
    p.add_argument(
        "--printer",
        help="printer the design is made for: a profile name (see 'saucerfab printers') or a .toml; the "
        f"relief is kept within its minimum feature and a part that cannot fit it is refused now (default "
        f"{default('printer')})",
    )
    p.add_argument(
        "--cup-diameter-mm",
        type=float,
        help="the real cup's width across its footprint in mm: the design's physical scale (default: the "
        f"scene's, {default_sizes.cup_diameter_mm:g})",
    )
    p.add_argument(
        "--saucer-diameter-mm",
        type=float,
        metavar="D",
        help="a round saucer's diameter in mm (with --scene round; refused with a rectangle); its grid follows "
        f"the diameter unless --resolution is given (default: the scene's, {_round_mm(round_):g} for the "
        f"round scene's {round_.cup_diameter_mm:g} mm cup)",
    )
    p.add_argument("-o", "--out", required=True, help="design folder to write (an existing design needs --force)")
    p.add_argument("--force", action="store_true", help="replace the design already in --out")
    p.add_argument("--resolution", type=int,
                   help=f"heightfield vertices per side (default: the scene's, {default_sizes.saucer.resolution})")
    p.add_argument("--image-size", type=int,
                   help=f"rendered image size in pixels (default: the scene's, {default_sizes.direct.image_size})")
    p.add_argument(
        "--seed",
        type=int,
        help=f"seed of the random parts of a built-in base shape (default {default('seed')}; a shape file has none)",
    )
    p.add_argument("--direct-mask", help="foreground mask for the direct image (white = foreground)")
    p.add_argument("--reflected-mask", help="foreground mask for the reflected image")
    p.add_argument("--reflected2-mask", help="foreground mask for the second reflected image")
    for w in WEIGHTS:  # one option per declared weight of an energy term
        p.add_argument(w.option, type=float, help=f"{w.help} (default {w.default_text()})")
    p.add_argument(
        "--max-iters",
        type=int,
        help="iteration cap for every stage (default: the method's, for pictures with a clear subject / "
        "photographs: " + ", ".join(f"{m} {a}/{b}" for m, (a, b) in STAGE_CAPS.items())
        + "; a stage also stops when it converges)",
    )
    p.add_argument(
        "--ablation",
        choices=ABLATIONS,
        help=f"the paper's method ({default('ablation')}, the default) or one of Figure 11's ablations",
    )
    p.add_argument(
        "--method",
        choices=METHODS,
        help="how the full method runs: auto skips the small-sigma Laplacian stage for pictures with a clear "
        f"subject (the black-white enhancement; {STAGE_CAPS['auto'][0]} iterations a stage) and runs it for "
        f"photographs ({STAGE_CAPS['auto'][1]} a stage), which gain from it where the others do not; fast always "
        f"skips it; paper runs Algorithm 1's three stages as written, {STAGE_CAPS['paper'][0]} iterations each at "
        "most (measured in benchmarks/RESULTS.md, Design speed against its anchors). The ablations always run "
        "as the paper wrote them "
        f"(default {default('method')})",
    )
    p.add_argument(
        "--frames",
        choices=FRAMES,
        help="view frames: the largest square wholly on the saucer and wholly on its reflection, so each "
        "whole image is seen (inscribed); the largest square in the bounding box of each "
        "(contain: larger pictures, the reflected one's corners fall off the reflection); so the saucer fills "
        "each frame (cover); or the scene's own frames (scene: the paper's preset, which puts part of each "
        f"image off the saucer). Default {default('frames')}",
    )
    p.add_argument(
        "--prism-placement",
        choices=PRISM_PLACEMENTS,
        help="with --reflected2: turn the prism to the placement whose facet regions overlap least (auto), or "
        f"keep the cup's rotation (as_given). Default {default('prism_placement')}",
    )
    p.add_argument(
        "--color-init",
        choices=COLOR_INITS,
        help="starting face colours: grey (gray, the paper) or projected from the enhanced targets (projected, "
        f"Fig. 12 c). Default {default('color_init')}",
    )
    p.add_argument(
        "--no-times",
        action="store_true",
        help="leave wall-clock times out of the design folder (byte-identical reruns)",
    )
    p.add_argument(
        "--fit",
        metavar="RULE",
        help="what of each picture its frame shows, at that part's own aspect (a wide picture gets a wide "
        "frame): pad (the whole picture) or crop (cut to its content, the box of what differs from its "
        "background: a word keeps all its letters and loses the empty canvas); or per picture, e.g. "
        "direct=crop,reflected=pad. Default " + str(default("fit")),
    )
    p.add_argument(
        "--background",
        metavar="COLOUR",
        help="#rrggbb of the padding, of what transparent areas show and of the ground outside the frames "
        "(default: each picture's border colour; pictures whose border colours differ share the direct "
        "picture's as the ground outside the frames)",
    )
    p.add_argument(
        "--enhancement",
        choices=ENHANCEMENTS,
        help="conflict reduction of the full method: the paper's black-white enhancement (subject), none (the "
        "pictures as they are), or auto (subject when every picture has a clear subject - an alpha "
        "channel, a mask file, or a subject on a plain background - else none, as for full-bleed photos). "
        f"Default {default('enhancement')}",
    )
    p.add_argument(
        "--eyes",
        metavar="EYES",
        help="where the design is made to be seen from: design (the design eye alone, the paper's method), both "
        "(the design eye and a viewer's two eyes, --ipd-mm apart) or box:W,H[,N] (an N x N grid of eyes, W x H mm, "
        "around the design eye; N default 3); millimetres at the design's cup size. Each eye adds its own direct "
        "and reflected renders to every iteration (about 2x the time for both). The eyes 'saucerfab verify "
        f"--eyes' scores. Default {default('eyes')}",
    )
    p.add_argument(
        "--surround-weight",
        type=float,
        metavar="W",
        help="weight of the whole view around the pictures: the saucer seen outside the direct frame and its "
        "image in the cup outside the reflected frame aim at each picture's background, so neither picture "
        "shows as a ghost around the other; 0 scores the frames alone (the paper). Default "
        f"{SURROUND_WEIGHT:g} (0 with --ablation, whose settings are the paper's)",
    )
    p.add_argument(
        "--ipd-mm",
        type=float,
        help=f"distance between the viewer's eyes with --eyes both (default {DEFAULT_IPD_MM:g} mm)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout (progress stays on stderr)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--no-verify",
        action="store_true",
        help="skip the quick verify of a trial export (for --printer, OBJ) that shows in the design's report.html",
    )


def _round_mm(scene: Scene) -> float:
    """A round scene's saucer diameter, mm (for the help text)."""
    return 2.0 * scene.saucer.radius * scene.mm_per_unit


def given_options(args: argparse.Namespace) -> dict[str, object]:
    """The DesignRequest fields the user gave on the command line (the others keep their defaults)."""
    from dataclasses import fields

    from saucerfab.optimize.request import DesignRequest

    given = {f.name: getattr(args, f.name) for f in fields(DesignRequest) if getattr(args, f.name, None) is not None}
    if args.no_times:
        given["record_times"] = False
    return given


def _json_summary(design: Design) -> dict:
    """What --json prints: the folder, the per-stage metrics and the final metrics."""
    stages = []
    for st in design.stage_records:
        row = {"name": st.name, "iterations": st.iterations, "E_visual": st.E_visual, "E_deform": st.E_deform,
               "stop_reason": st.stop_reason}
        if st.seconds is not None:
            row["seconds"] = st.seconds
        stages.append(row)
    m = design.metrics
    return {
        "design": str(design.folder),
        "enhancement": design.parameters.get("enhancement_used"),
        "stages": stages,
        "final": {
            "E_visual_final": m.get("E_visual_final"),
            "E_visual_final_against": "the original pictures (hard renders of the textured result), "
            "not the stages' blur-matched (often enhanced) targets",
            "max_abs_height_change": m.get("max_abs_height_change"),
        },
    }


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from saucerfab.extras import require, require_verify

    require("design")  # a missing extra is said now, not by an import minutes into the design
    require_verify(args.no_verify)

    from saucerfab.optimize.checkpoint import check_output_folder
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.workflow import run_design

    req = DesignRequest(**given_options(args))  # refuses bad or contradictory options before anything else
    # the library replaces an earlier design folder (batch reruns); the command asks for --force
    check_output_folder(Path(args.out), force=args.force)
    quiet = (lambda *a: None) if args.quiet else None
    design = run_design(req, args.out, progress=quiet, look=None if args.quiet else _first_look_line(args))
    verified = None if args.no_verify else _verify(design, req.printer, args)
    if args.json:
        import json

        doc = _json_summary(design)
        doc["verify"] = verified.to_dict(record_times=not args.no_times) if verified is not None else None
        print(json.dumps(doc, indent=2))
        return 0
    _print_summary(design)
    if verified is not None:
        from saucerfab.cli.verify import view_line
        from saucerfab.workflow import QUICK_TEXTURE_PX

        print(f"  verified a trial export ({req.printer}, OBJ, {QUICK_TEXTURE_PX} px atlas) at {verified.res} px:")

        for v in verified.files[0].views:
            print(f"    {view_line(v)}")
    print(f"  previews: {design.folder / 'previews'}; report: {design.folder / 'report.html'}")
    return 0


def _print_summary(design: Design) -> None:
    """The design's lines: the enhancement and method used, each stage, the final energies, the printer's rule."""
    print(f"wrote {design.folder}")
    par, m = design.parameters, design.metrics
    enh = par.get("enhancement_used") or {}
    if enh.get("strategy") in ("subject", "none"):
        what = "black-white enhancement" if enh["strategy"] == "subject" else "no enhancement (the pictures as they are)"
        print(f"  {what}: {enh.get('why', '')}")
    if par.get("method_used"):  # which stages ran, and why (the product's choice under the default, auto)
        from saucerfab.optimize.solver import SolverSettings
        from saucerfab.optimize.stages import SIGMA_SMALL

        names = [s["name"] for s in par.get("stages", [])]
        small = any(s["regulariser"] == "deform" and s["sigma"] == SIGMA_SMALL for s in par.get("stages", []))
        why = ""
        if par["method_used"] == "auto":
            why = (" (the small-sigma stage run: these pictures are used as they are)" if small
                   else " (the small-sigma stage skipped: these pictures have a clear subject)")
        print(f"  method {par['method_used']}{' (the default)' if par.get('method') == 'auto' else ''}: "
              f"{', '.join(names)}{why}, at most {par['max_iters_used']} iterations a stage"
              + (f" (or until {par['stall_window_used']} renders gain under {SolverSettings.tol * 100:g} % each)"
                 if par.get("stall_window_used") else ""))
    for st in design.stage_records:
        # --no-times leaves the times out of design.json: then no time column (not "nan s")
        secs = f"{st.seconds:6.1f} s  " if st.seconds is not None else ""
        print(
            f"  {st.name:22s} {st.iterations:4d} it  {secs}"
            f"E_visual {st.E_visual:10.1f}  E_deform {st.E_deform:.4f}  "
            f"conflict {100 * st.conflict_fraction:.1f}%"
        )
    total = f"total {m['total_s']:.1f} s" if "total_s" in m else "times not recorded (--no-times)"
    if "resumed_after_stage" in m:
        this_run = f"this run {m['this_run_s']:.1f} s, " if "this_run_s" in m else ""
        total += f"{' over all runs' if 'total_s' in m else ''} ({this_run}resumed after stage {m['resumed_after_stage']})"
    print(
        f"  final E_visual {m.get('E_visual_final', float('nan')):.1f} against the original pictures "
        "(the stages' E_visual is against their blur-matched, often enhanced, targets), max |h - z| "
        f"{m['max_abs_height_change']:.4f} (delta {design.scene.saucer.delta}), {total}"
    )
    pt = par.get("print_target") or {}
    pm = m.get("printable") or {}
    if pt:
        moved = pm.get("projection_active", 0)
        left = pm.get("thin_crest_vertices", 0) + pm.get("thin_wall_crest_vertices", 0)
        rule = (f"the optimizer blunted crests on {moved} of its {pm.get('projection_calls', 0)} trial steps"
                if moved else "no crest came near them")
        rule += "; none is left" if not left else f"; {left} crest vertices are still under them"
        print(f"  made for {pt['printer_name']}, cup diameter {pt['cup_diameter_mm']:g} mm ({pt['mm_per_unit']:g} mm "
              f"per unit, relief +-{pt['delta_mm']:.2f} mm): minimum feature {pt['min_feature_mm']:g} mm and wall "
              f"{pt['min_wall_mm']:g} mm; {rule}")


def _first_look_line(args: argparse.Namespace) -> Look:
    """A look callback that prints one stderr line for the first look: seconds since the command started."""
    import sys
    import time
    from pathlib import Path

    started = getattr(args, "_started", None)

    def look(stage: str, files: dict[str, Path], elapsed_s: float) -> None:
        if stage == "first_look" and files:
            since = time.perf_counter() - started if started is not None else elapsed_s
            folder = next(iter(files.values())).parent
            print(f"first look after {since:.1f} s: {folder}", file=sys.stderr, flush=True)

    return look


def _verify(design: Design, printer: str, args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The quick verify of a trial export, or None (with a note on stderr) when it cannot be made."""
    import sys

    from saucerfab.errors import SaucerfabError
    from saucerfab.workflow import verify_design

    def progress(msg: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[verify {fraction * 100:5.1f}%] {msg}", file=sys.stderr, flush=True)

    try:
        # the printer as given (a profile .toml path too), not only the key the design records
        return verify_design(design, printer=printer, record_times=not args.no_times, progress=progress)
    except SaucerfabError as exc:  # the design itself is complete; say why it was not verified
        print(f"  note: the design is not verified: {exc}", file=sys.stderr)
        return None
