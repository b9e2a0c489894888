"""``saucerfab shapes``: list the built-in base shapes, or render one to PNG/NPY."""

from __future__ import annotations

import argparse
import io

import numpy as np

HELP = "list built-in base shapes; write one as .npy or 16-bit PNG"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", nargs="?", help="shape to write (omit to list)")
    p.add_argument("--resolution", type=int, default=150, help="vertices per side (default 150)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--out", help="output .npy (model units) or .png (16-bit, white = 0.1 units)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--json", action="store_true", help="list the shapes as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="list only the names; no 'wrote' line")


def run(args: argparse.Namespace) -> int:
    from saucerfab.errors import ConfigError
    from saucerfab.files.fileio import write_bytes_atomic
    from saucerfab.model.heightfield import BASE_SHAPES, base_shape
    from saucerfab.model.scene import MAX_GRID, MIN_GRID

    if not MIN_GRID <= args.resolution <= MAX_GRID:
        raise ConfigError(
            f"--resolution {args.resolution} is out of range; give {MIN_GRID} to {MAX_GRID} vertices per side"
        )
    if not args.name:
        if args.out:
            raise ConfigError("--out writes one shape: give its name (saucerfab shapes NAME --out FILE.png)")
        rows = {name: base_shape(name, 64, args.seed) for name in sorted(BASE_SHAPES)}
        if args.json:
            import json

            print(json.dumps({n: {"min_height": float(h.min()), "max_height": float(h.max()), "units": "model"}
                              for n, h in rows.items()}, indent=2))
        for name, h in rows.items() if not args.json else ():
            print(name if args.quiet else f"{name:16s} heights {h.min():.3f} .. {h.max():.3f} model units")
        return 0
    h = base_shape(args.name, args.resolution, args.seed)
    if not args.out:
        raise ConfigError("give --out FILE.npy or FILE.png to write the shape")
    from saucerfab.cli.outputs import refuse_existing

    refuse_existing("--out", args.out, args.force)
    buf = io.BytesIO()
    if args.out.lower().endswith(".npy"):
        np.save(buf, h)
    elif args.out.lower().endswith(".png"):
        from PIL import Image

        img = np.clip(np.rint(h[::-1] / 0.1 * 65535), 0, 65535).astype(np.uint16)
        Image.fromarray(img).save(buf, format="PNG")
    else:
        raise ConfigError(f"--out {args.out!r} must end in .npy or .png")
    write_bytes_atomic(args.out, buf.getvalue())
    if args.json:
        import json

        print(json.dumps({"wrote": args.out, "shape": args.name, "resolution": args.resolution}))
    elif not args.quiet:
        print(f"wrote {args.out}")
    return 0
