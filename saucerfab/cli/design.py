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
    p.add_argument("--out", required=True, help="design folder to write")
    p.add_argument("--resolution", type=int, help="heightfield vertices per side (default 150)")
    p.add_argument("--image-size", type=int, help="rendered image size in pixels (default 512)")
    p.add_argument("--seed", type=int, default=0)
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
        default="scene",
        choices=["scene", "contain", "cover"],
        help="view frames: the scene's (paper preset), or fitted so each image lands on the saucer (contain) "
        "or the saucer fills each frame (cover)",
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
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    from saucerfab.optimize.pipeline import run_design
    from saucerfab.optimize.request import DesignRequest

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
        frames=args.frames,
        prism_placement=args.prism_placement,
        color_init=args.color_init,
        record_times=not args.no_times,
    )
    quiet = (lambda *a: None) if args.quiet else None
    out = run_design(req, args.out, progress=quiet)
    import json

    meta = json.loads((out / "design.json").read_text())
    m = meta["metrics"]
    print(f"wrote {out}")
    for st in m.get("stages", []):
        print(
            f"  {st['name']:22s} {st['iterations']:4d} it  {st.get('seconds', float('nan')):6.1f} s  "
            f"E_visual {st['E_visual']:10.1f}  E_deform {st['E_deform']:.4f}  "
            f"conflict {100 * st['conflict_fraction']:.1f}%"
        )
    print(
        f"  final E_visual {m.get('E_visual_final', float('nan')):.1f}, max |h - z| "
        f"{m['max_abs_height_change']:.4f} (delta {meta['scene']['saucer']['delta']}), total {m.get('total_s', float('nan')):.1f} s"
    )
    print(f"  previews: {out / 'previews'}")
    return 0
