"""``saucerfab design``: two images and a saucer shape -> a design folder."""

from __future__ import annotations

import argparse

HELP = "optimize a saucer: direct + reflected image and a base shape -> design folder"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--direct", required=True, help="image seen directly on the saucer")
    p.add_argument("--reflected", required=True, help="image seen in the mirror cup")
    p.add_argument("--reflected2", help="second reflected image (needs --cup prism:N)")
    p.add_argument("--shape", default="waves", help="base shape: built-in name or .png/.npy (default waves)")
    p.add_argument("--height-scale", type=float, default=0.1, help="model units per unit of a shape file")
    p.add_argument("--scene", default="paper", help="scene TOML or preset (default: paper)")
    p.add_argument("--cup", help="cup override: circle[:R], ellipse:A,B[,ROT], prism:N[,R[,ROT]]")
    p.add_argument(
        "--printer",
        default="j55",
        help="printer the design is made for: a profile name (see 'saucerfab printers') or a .toml; the "
        "relief is kept within its minimum feature and a part that cannot fit it is refused now (default j55)",
    )
    p.add_argument(
        "--cup-diameter-mm",
        type=float,
        help="the real cup's width across its footprint in mm: the design's physical scale (default: the "
        "scene's, 80)",
    )
    p.add_argument("-o", "--out", required=True, help="design folder to write (an existing design needs --force)")
    p.add_argument("--force", action="store_true", help="replace the design already in --out")
    p.add_argument("--resolution", type=int, help="heightfield vertices per side (default 150)")
    p.add_argument("--image-size", type=int, help="rendered image size in pixels (default 512)")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the random parts of a built-in base shape (default 0; a shape file has none)",
    )
    p.add_argument("--direct-mask", help="foreground mask for the direct image (white = foreground)")
    p.add_argument("--reflected-mask", help="foreground mask for the reflected image")
    p.add_argument("--reflected2-mask", help="foreground mask for the second reflected image")
    p.add_argument("--w-large", type=float, help="E_deform weight at sigma 1e-5 (default 0.08 rho)")
    p.add_argument("--w-small", type=float, help="E_deform weight at sigma 1e-7 (default 0.2 rho)")
    p.add_argument("--lam", type=float, help="E_sparse weight (default 6e-5 rho)")
    p.add_argument(
        "--barrier-weight",
        type=float,
        default=0.01,
        help="weight of the log barriers (eq. 5); 1 = the paper as written (default 0.01, see RESULTS.md)",
    )
    p.add_argument("--max-iters", type=int, default=400, help="iteration cap per stage (default 400)")
    p.add_argument(
        "--ablation",
        default="full",
        choices=["full", "no_deform", "laplacian", "laplacian_bw", "sparse_only", "laplacian_sparse"],
        help="the paper's method (full) or one of Figure 11's ablations",
    )
    p.add_argument(
        "--frames",
        default=None,
        choices=["inscribed", "contain", "cover", "scene"],
        help="view frames: the largest square wholly on the saucer and wholly on its reflection, so each "
        "whole image is seen (inscribed, the default); the largest square in the bounding box of each "
        "(contain: larger pictures, the reflected one's corners fall off the reflection); so the saucer fills "
        "each frame (cover); or the scene's own frames (scene: the paper's preset, which puts part of each "
        "image off the saucer)",
    )
    p.add_argument(
        "--prism-placement",
        default="auto",
        choices=["auto", "as_given"],
        help="with --reflected2: turn the prism to the placement whose facet regions overlap least (auto)",
    )
    p.add_argument(
        "--color-init",
        default="gray",
        choices=["gray", "projected"],
        help="starting face colours: grey (the paper) or projected from the enhanced targets (Fig. 12 c)",
    )
    p.add_argument(
        "--no-times",
        action="store_true",
        help="leave wall-clock times out of the design folder (byte-identical reruns)",
    )
    p.add_argument(
        "--fit",
        default=None,
        metavar="RULE",
        help="how each picture fills its square frame: pad (the whole picture, bands of --background beside a "
        "non-square one; the default) or crop (the frame filled, the long side's margins cut off, as for "
        "photos); or per picture, e.g. direct=crop,reflected=pad",
    )
    p.add_argument(
        "--background",
        default=None,
        metavar="COLOUR",
        help="#rrggbb of the padding and of what transparent areas show (default: each picture's border colour)",
    )
    p.add_argument(
        "--enhancement",
        default=None,
        choices=["auto", "subject", "none"],
        help="conflict reduction of the full method: the paper's black-white enhancement (subject), none (the "
        "pictures as they are), or auto (the default: subject when every picture has a clear subject - an alpha "
        "channel, a mask file, or a subject on a plain background - else none, as for full-bleed photos)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout (progress stays on stderr)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--no-verify",
        action="store_true",
        help="skip the quick verify of a trial export (for --printer, OBJ) that shows in the design's report.html",
    )


#: weight option -> the StageSpec.weight it sets
WEIGHT_OPTIONS = {"--w-large": "w_large", "--w-small": "w_small", "--lam": "lam"}


def check_weights(args: argparse.Namespace) -> None:
    """Refuse a weight option that no stage of the chosen ablation uses (it would be ignored)."""
    from saucerfab.errors import ConfigError
    from saucerfab.optimize.stages import ABLATION_STAGES, weights_used

    used = weights_used(args.ablation)
    for option, key in WEIGHT_OPTIONS.items():
        if getattr(args, key) is None or key in used:
            continue
        takers = ", ".join(a for a in ABLATION_STAGES if key in weights_used(a))
        uses = ", ".join(o for o, k in WEIGHT_OPTIONS.items() if k in used) or "no weight option"
        raise ConfigError(
            f"{option} is not used by --ablation {args.ablation} (its stages use {uses}); "
            f"drop {option}, or choose an --ablation that uses it ({takers})"
        )


def _json_summary(out: object, meta: dict) -> dict:
    """What --json prints: the folder, the per-stage metrics and the final metrics."""
    m = meta["metrics"]
    stages = []
    for st in m.get("stages", []):
        row = {k: st.get(k) for k in ("name", "iterations", "E_visual", "E_deform", "stop_reason")}
        if "seconds" in st:
            row["seconds"] = st["seconds"]
        stages.append(row)
    return {
        "design": str(out),
        "enhancement": meta.get("parameters", {}).get("enhancement_used"),
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

    from saucerfab.optimize.pipeline import check_output_folder, run_design
    from saucerfab.optimize.request import DesignRequest

    check_weights(args)
    # the library replaces an earlier design folder (batch reruns); the command asks for --force
    check_output_folder(Path(args.out), force=args.force)
    req = DesignRequest(
        direct=args.direct,
        reflected=args.reflected,
        reflected2=args.reflected2,
        shape=args.shape,
        scene=args.scene,
        cup=args.cup,
        resolution=args.resolution,
        image_size=args.image_size,
        seed=args.seed,
        direct_mask=args.direct_mask,
        reflected_mask=args.reflected_mask,
        reflected2_mask=args.reflected2_mask,
        height_scale=args.height_scale,
        w_large=args.w_large,
        w_small=args.w_small,
        lam=args.lam,
        max_iters=args.max_iters,
        barrier_weight=args.barrier_weight,
        ablation=args.ablation,
        **({"frames": args.frames} if args.frames is not None else {}),
        **({"enhancement": args.enhancement} if args.enhancement is not None else {}),
        **({"fit": args.fit} if args.fit is not None else {}),
        **({"background": args.background} if args.background is not None else {}),
        printer=args.printer,
        cup_diameter_mm=args.cup_diameter_mm,
        prism_placement=args.prism_placement,
        color_init=args.color_init,
        record_times=not args.no_times,
    )
    quiet = (lambda *a: None) if args.quiet else None
    out = run_design(req, args.out, progress=quiet)
    import json

    meta = json.loads((out / "design.json").read_text())
    m = meta["metrics"]
    verified = None if args.no_verify else _verify(out, args)
    if args.json:
        doc = _json_summary(out, meta)
        doc["verify"] = verified.to_dict(record_times=not args.no_times) if verified is not None else None
        print(json.dumps(doc, indent=2))
        return 0
    print(f"wrote {out}")
    enh = meta.get("parameters", {}).get("enhancement_used") or {}
    if enh.get("strategy") in ("subject", "none"):
        what = "black-white enhancement" if enh["strategy"] == "subject" else "no enhancement (the pictures as they are)"
        print(f"  {what}: {enh.get('why', '')}")
    for st in m.get("stages", []):
        print(
            f"  {st['name']:22s} {st['iterations']:4d} it  {st.get('seconds', float('nan')):6.1f} s  "
            f"E_visual {st['E_visual']:10.1f}  E_deform {st['E_deform']:.4f}  "
            f"conflict {100 * st['conflict_fraction']:.1f}%"
        )
    total = f"total {m.get('total_s', float('nan')):.1f} s"
    if "resumed_after_stage" in m:
        total += (
            f" over all runs (this run {m.get('this_run_s', float('nan')):.1f} s, "
            f"resumed after stage {m['resumed_after_stage']})"
        )
    print(
        f"  final E_visual {m.get('E_visual_final', float('nan')):.1f} against the original pictures "
        "(the stages' E_visual is against their blur-matched, often enhanced, targets), max |h - z| "
        f"{m['max_abs_height_change']:.4f} (delta {meta['scene']['saucer']['delta']}), {total}"
    )
    pt = meta.get("parameters", {}).get("print_target") or {}
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
    if verified is not None:
        print(f"  verified a trial export ({args.printer}, OBJ) at {verified.res} px:")
        for v in verified.files[0].views:
            psnr = "  -- " if v.psnr_db != v.psnr_db else f"{v.psnr_db:4.1f}"
            print(f"    {v.view:10s} from the {v.eye:6s} eye  {psnr} dB, {v.coverage * 100:3.0f}% of the frame"
                  f"{'' if v.passed else '  LOW'}")
    print(f"  previews: {out / 'previews'}; report: {out / 'report.html'}")
    return 0


def _verify(out, args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The quick verify of a trial export, or None (with a note on stderr) when it cannot be made."""
    import sys

    from saucerfab.errors import SaucerfabError
    from saucerfab.finish import verify_design

    def progress(msg: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[verify {fraction * 100:5.1f}%] {msg}", file=sys.stderr, flush=True)

    try:
        return verify_design(out, printer=args.printer, record_times=not args.no_times, progress=progress)
    except SaucerfabError as exc:  # the design itself is complete; say why it was not verified
        print(f"  note: the design is not verified: {exc}", file=sys.stderr)
        return None
