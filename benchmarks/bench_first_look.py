"""Time to the first look of ``saucerfab design`` (issue 18: "a first look in seconds").

    .venv/bin/python benchmarks/bench_first_look.py [--repeat 3] [--size default]

End to end: ``python -m saucerfab design`` on the default sample pair
(``samples/direct_heart.png`` + ``samples/reflected_star.png``) at the
default full size (150 x 150 vertices, 512 px views), timed from starting
the process to the stderr line "first look after ..." (the look callback
has then run); the process is then killed (the design itself is not
wanted). Best of ``--repeat``.

Parts: the same steps one by one in a fresh interpreter (best of
``--repeat`` per part): starting the interpreter, the CLI's imports and
parser, ``prepare`` (images, masks, enhancement, fitted frames), the views
as numpy meshes, the projected face colours (numba's import and cached
kernels included), the renders and the PNG writes; then importing torch,
which ``run_design`` does only after the first look. The target is 3 s on the 2-core development machine.
"""

from __future__ import annotations

import time

STARTED = time.time()  # when this interpreter ran its first line (a --child's start)
STARTED_PC = time.perf_counter()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
PAIR = ["--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png")]

#: the parts up to the first look, in order
PARTS = ("interpreter", "CLI imports + parser", "prepare", "views (numpy)", "projected colours", "renders",
         "PNG writes")


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def end_to_end(extra: list[str]) -> float:
    """Seconds from starting ``saucerfab design`` to its "first look after" line."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "saucerfab", "design", *PAIR, "-o", str(Path(tmp) / "d"),
                                 "--no-verify", *extra], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                text=True, env=_env(), cwd=ROOT)
        try:
            assert proc.stderr is not None
            for line in proc.stderr:
                if line.startswith("first look after"):
                    return time.perf_counter() - t0
            raise RuntimeError("saucerfab design ended without a first look")
        finally:
            proc.kill()
            proc.wait()


def child(extra: list[str]) -> None:
    """The steps to the first look one at a time; prints when it started and their seconds as JSON."""
    print(STARTED)
    t = [STARTED_PC]
    parts: dict[str, float] = {}

    def lap(name: str) -> None:
        t.append(time.perf_counter())
        parts[name] = t[-1] - t[-2]

    from saucerfab.cli import build_parser

    args = build_parser().parse_args(["design", *PAIR, "-o", "unused", *extra])
    lap("CLI imports + parser")
    import saucerfab.render  # noqa: F401 - as the CLI: before torch (saucerfab/__init__.py's OpenMP settings)
    from saucerfab.cli.design import given_options
    from saucerfab.files.fileio import write_bytes_atomic
    from saucerfab.files.imageio import png_bytes
    from saucerfab.optimize.looks import LOOK_PNG_LEVEL, look_colors, look_images
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.optimize.views import ViewMeshes
    from saucerfab.imaging.panels import as_uint8_rgb

    req = DesignRequest(**given_options(args))
    prep = prepare(req)
    lap("prepare")
    meshes = ViewMeshes(prep.scene, prep.base, reflected_groups=prep.reflected_groups)
    lap("views (numpy)")
    colors = look_colors(meshes, prep, prep.base)
    lap("projected colours")
    images = look_images(prep.scene, meshes, prep.base, colors)
    lap("renders")
    with tempfile.TemporaryDirectory() as tmp:
        for name, img in images.items():
            write_bytes_atomic(Path(tmp) / f"{name}.png", png_bytes(as_uint8_rgb(img), LOOK_PNG_LEVEL))
    lap("PNG writes")
    assert "torch" not in sys.modules, "the first look should come before torch is imported"
    import torch  # noqa: F401

    lap("import torch")
    print(json.dumps(parts))


def run_parts(extra: list[str]) -> dict[str, float]:
    """The parts in a fresh interpreter; "interpreter" is from starting it to its first line of Python."""
    t0 = time.time()  # the wall clock: comparable across the two processes
    out = subprocess.run([sys.executable, __file__, "--child", "--", *extra], capture_output=True, text=True,
                         env=_env(), cwd=ROOT, check=True)
    first, parts = out.stdout.strip().splitlines()[-2:]
    return {"interpreter": float(first) - t0, **json.loads(parts)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("extra", nargs="*", help="more `saucerfab design` options (after --), e.g. -- --image-size 256")
    a = ap.parse_args()
    if a.child:
        child(a.extra)
        return
    load = os.getloadavg()[0]
    ends = [end_to_end(a.extra) for _ in range(a.repeat)]
    runs = [run_parts(a.extra) for _ in range(a.repeat)]
    print(f"# first look: {platform.node()}, {os.cpu_count()} cores, load {load:.2f} -> {os.getloadavg()[0]:.2f}")
    print(f"saucerfab design {' '.join(a.extra) or '(defaults)'}: process start -> first look callback, "
          f"best of {a.repeat}: {min(ends):.2f} s (all: {', '.join(f'{x:.2f}' for x in ends)})")
    print("\n| part | best s |\n|---|---:|")
    total = 0.0
    for name in PARTS:
        best = min(r[name] for r in runs)
        total += best
        print(f"| {name} | {best:.3f} |")
    print(f"| sum of the parts | {total:.3f} |")
    print(f"| (then: import torch, after the first look) | {min(r['import torch'] for r in runs):.3f} |")


if __name__ == "__main__":
    main()
