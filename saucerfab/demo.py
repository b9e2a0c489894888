"""The end-to-end demo on the bundled samples: design, export, check.

``python -m saucerfab.demo --out out/demo`` (what ``make demo`` runs):

1. ``saucerfab design`` with ``samples/direct_heart.png`` on the saucer and
   ``samples/reflected_star.png`` in the cup, on the ``waves`` base shape,
   at the paper's full size (150 x 150, 512 x 512) unless ``--quick``;
2. ``saucerfab export`` of that design for the Stratasys J55 at an 80 mm cup
   as 3MF, OBJ, PLY and VRML (the formats GrabCAD Print takes);
3. ``saucerfab check`` of every written file;
4. ``saucerfab verify`` of the print folder: the exported OBJ ray-traced
   with Mitsuba from the design eye and a viewer's two eyes, each view
   scored against the inputs (pictures in ``out/demo/print/verify/``, the
   whole story in ``out/demo/print/report.html``).

The demo fails when a step fails to run (design, export, an unprintable or
unreadable file, a print folder verify cannot read); views under verify's
pass level are printed as such, and do not fail the demo: they are a
finding about the design (see ``saucerfab/verify/README.md``).

Each step is the CLI itself, called in-process, so the demo shows exactly
what a user would type (printed before each step).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from saucerfab.cli import main as cli
from saucerfab.samples import DEMO_PAIR, SAMPLES, pair_paths


def run(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m saucerfab.demo", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--quick", action="store_true", help="small sizes (60x60 grid, 192 px) for a fast look")
    p.add_argument("--samples", default=str(SAMPLES), help="folder with the sample images")
    args = p.parse_args(argv)
    out = Path(args.out)
    samples = Path(args.samples)
    direct, reflected = pair_paths(DEMO_PAIR, samples)
    size = ["--resolution", "60", "--image-size", "192", "--max-iters", "150"] if args.quick else []
    steps = [
        [
            "design",
            "--direct", str(direct),
            "--reflected", str(reflected),
            "--out", str(out / "design"),
            "--force",  # the demo's own folder from an earlier run
            *size,
        ],
        [
            "export", str(out / "design"),
            "--printer", "j55",
            "--cup-diameter-mm", "80",
            "--formats", "3mf,obj,ply,wrl",
            "--out", str(out / "print"),
        ],
    ]
    t0 = time.perf_counter()
    for step in steps:
        print("$ saucerfab " + " ".join(step), flush=True)
        rc = cli(step)
        if rc != 0:
            print(f"demo: step 'saucerfab {step[0]}' failed with exit code {rc}", file=sys.stderr)
            return rc
    files = sorted(
        str(f)
        for folder in ("print",)
        for f in (out / folder).rglob("*")
        if f.suffix.lower() in (".3mf", ".glb", ".ply", ".wrl", ".obj")
    )
    print("$ saucerfab check " + " ".join(files), flush=True)
    rc = cli(["check", *files, "--printer", "j55"])
    if rc != 0:
        return rc
    step = ["verify", str(out / "print")]
    print("$ saucerfab " + " ".join(step), flush=True)
    vrc = cli(step)
    if vrc == 2:
        return vrc
    print(f"demo finished in {time.perf_counter() - t0:.0f} s: previews in {out / 'design' / 'previews'}, "
          f"print files in {out / 'print'}, report {out / 'print' / 'report.html'}"
          + ("" if vrc == 0 else "; some views are under verify's pass level (printed above)"))
    return 0


if __name__ == "__main__":
    sys.exit(run())
