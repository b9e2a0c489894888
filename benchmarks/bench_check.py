"""Benchmark: ``saucerfab check`` on a 100,000-triangle textured 3MF (target: <= 2 s) and its start-up.

    .venv/bin/python benchmarks/bench_check.py [--runs 5] [--n 159] [--out benchmarks/results/check.md]

The file is a closed saucer-like solid (wavy heightfield top, flat base,
vertical sides; 4 (n-1)^2 + 8 (n-1) = 101,120 triangles at n = 159) with a
2048 x 2048 texture, written by saucerfab's own 3MF exporter (the tests'
minimal writer if that is not importable). Every check runs: reading with
all bounds, topology, volume, self-intersections, 4,096 thin-wall rays,
texture decode and dpi, against the j55 profile.

Timings:

* in-process ``check_mesh`` (warm: modules loaded), best and median of runs;
* the CLI end to end in a fresh interpreter (``python -m saucerfab check
  FILE``): what a CI job or bureau sees, including imports;
* CLI start-up alone (``saucerfab check --schema``) and whether torch, numba,
  matplotlib or trimesh were imported (they must not be);
* the plain reference in the same run: ``trimesh.load`` of the same mesh as
  binary STL (trimesh's 3MF reader needs lxml, which saucerfab does not
  depend on) plus trimesh's ``is_watertight``, ``is_winding_consistent``,
  ``volume`` - far fewer checks, no colour, no self-intersections, no walls;
* a few hostile inputs (10-million-face STL, zip bomb, PNG bomb) to show
  refusals are quick.

Numbers on a shared, noisy machine vary by tens of percent between runs;
the best of several runs is the fairest single figure.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the fixture writers live with the tests

import fixtures_check as fx  # noqa: E402


def machine() -> str:
    model = "?"
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        model = next((ln.split(":", 1)[1].strip() for ln in out.splitlines() if ln.startswith("Model name")), "?")
    except (OSError, subprocess.SubprocessError):
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{model}, nproc {os.cpu_count()}, load average {load:.2f} at start; Python {platform.python_version()}, "
            f"numpy {np.__version__}")


def write_fixture(tmp: Path, n: int) -> tuple[Path, Path, int]:
    V, F, uv = fx.saucer_solid(n)
    png = fx.png_bytes(2048, 2048)
    path = tmp / "saucer.3mf"
    try:
        from saucerfab.fabricate.export_3mf import write_3mf
        from saucerfab.fabricate.textured import TexturedMesh

        mesh = TexturedMesh(name="saucer", vertices=V, faces=F, uvs=uv, face_uvs=F.copy(), texture_png=png,
                            texture_px=2048, vertex_rgb=np.full((len(V), 3), 128, np.uint8))
        path.write_bytes(write_3mf(mesh)["saucer.3mf"])
        writer = "saucerfab.fabricate.export_3mf"
    except ImportError:
        fx.write_3mf(path, V, F, uv=uv, texture=png)
        writer = "tests/fixtures_check.write_3mf"
    stl = fx.write_stl(tmp / "saucer.stl", V, F)
    print(f"fixture: {len(F):,} triangles, {path.stat().st_size / 1e6:.1f} MB 3MF by {writer}")
    return path, stl, len(F)


def timed(fn, runs: int) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    """(best wall s, median wall s, CPU s of the best run) - CPU time, all threads, is what load cannot inflate."""
    ts = []
    for _ in range(runs):
        t, c = time.perf_counter(), time.process_time()
        fn()
        ts.append((time.perf_counter() - t, time.process_time() - c))
    best = min(ts)
    return best[0], statistics.median(w for w, _ in ts), best[1]


def cli(args: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of a fresh ``python -m saucerfab check ...``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "saucerfab", "check", *args], capture_output=True, check=False, timeout=300)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def cli_timed(args: list[str], runs: int) -> tuple[float, float, float]:
    ts = [cli(args) for _ in range(runs)]
    best = min(ts)
    return best[0], statistics.median(w for w, _ in ts), best[1]


def heavy_imports(path: Path) -> list[str]:
    code = ("import sys\nfrom saucerfab.cli import main\n"
            f"main(['check', {str(path)!r}, '--json'])\n"
            "print(sorted(m for m in ('torch', 'numba', 'matplotlib', 'trimesh', 'xatlas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300).stdout
    return eval(out.strip().splitlines()[-1])  # a list literal we printed ourselves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--n", type=int, default=159, help="grid side; 159 gives 101,120 triangles")
    ap.add_argument("--out", help="also write the table (markdown) to this file")
    args = ap.parse_args()

    from saucerfab.check import Limits, check_mesh

    rows: list[tuple[str, str, str, str, str]] = []

    def row(name: str, t: tuple[float, float, float], note: str = "", fmt: str = ".2f") -> None:
        rows.append((name, format(t[0], fmt), format(t[1], fmt), format(t[2], fmt), note))

    info = machine()
    print(info)
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        path3mf, stl, ntri = write_fixture(tmp, args.n)

        r = check_mesh(path3mf, printer="j55")  # warm: imports, caches
        assert r.exit_code == 0, r.reason()
        row(f"check_mesh, {ntri:,}-triangle textured 3MF, all checks (in-process, warm)",
            timed(lambda: check_mesh(path3mf, printer="j55"), args.runs), "target <= 2 s")
        row("check_mesh, same mesh as binary STL (no colour)", timed(lambda: check_mesh(stl, printer="j55"), args.runs))
        row("`python -m saucerfab check` on the 3MF, fresh process (imports included)",
            cli_timed([str(path3mf), "--printer", "j55"], args.runs), "target <= 2 s")
        heavy = heavy_imports(path3mf)
        row("CLI start-up: `python -m saucerfab check --schema`", cli_timed(["--schema"], args.runs),
            f"torch/numba/matplotlib/trimesh imported by a check: {heavy or 'none'}")

        try:
            import trimesh

            def ref() -> None:
                m = trimesh.load(stl, force="mesh")
                _ = (m.is_watertight, m.is_winding_consistent, m.volume, len(m.split(only_watertight=False)))

            ref()
            row("reference: trimesh.load(STL) + is_watertight, is_winding_consistent, volume, split",
                timed(ref, args.runs), "no colour, walls or self-intersections")
        except ImportError:
            rows.append(("reference: trimesh", "-", "-", "-", "trimesh not installed"))

        # hostile inputs: refusals are quick
        big = tmp / "ten_million.stl"
        with open(big, "wb") as fh:
            fh.write(b"big".ljust(80, b" ") + struct.pack("<I", 10_000_000))
            fh.truncate(84 + 50 * 10_000_000)
        row("10,000,000-face binary STL (500 MB, sparse): refused, exit 2", timed(lambda: check_mesh(big), 3),
            "over_check_limit", ".3f")
        bomb = fx.zip_bomb_3mf(tmp / "bomb.3mf", inflated=256 << 20)
        row(f"zip bomb 3MF ({bomb.stat().st_size / 1e3:.0f} kB -> 256 MB), 64 MB limit, exit 2",
            timed(lambda: check_mesh(bomb, limits=Limits(max_uncompressed_bytes=64 << 20)), 3), "archive_too_large",
            ".3f")
        fx.lie_about_sizes(bomb, "3D/3dmodel.model", claimed=1000)
        row("the same bomb with its header claiming 1 kB, exit 2",
            timed(lambda: check_mesh(bomb, limits=Limits(max_uncompressed_bytes=64 << 20)), 3), "bounded read", ".3f")
        V, F = fx.box()
        pb = fx.write_3mf(tmp / "pngbomb.3mf", V, F, uv=fx.box_uv(V), texture=fx.png_bomb(100_000, 100_000))
        row("3MF with a 100,000 x 100,000 px PNG texture (bomb), exit 1", timed(lambda: check_mesh(pb), 3),
            "texture_too_large", ".3f")
        Vs = np.random.default_rng(1).random((60_000, 3)) * 10
        soup = fx.write_stl(tmp / "soup.stl", Vs, np.arange(60_000).reshape(-1, 3))
        row("20,000-triangle random soup in a 10 mm cube (pair search samples), exit 1",
            timed(lambda: check_mesh(soup), 1), "check_partial")

    lines = [
        "| case | best wall s | median wall s | CPU s (best run) | note |",
        "|---|---:|---:|---:|---|",
        *[f"| {a} | {b} | {c} | {d} | {e} |" for a, b, c, d, e in rows],
    ]
    table = "\n".join(lines)
    print(table)
    if args.out:
        from saucerfab.files.fileio import write_text_atomic

        write_text_atomic(args.out, f"Machine: {info}\n\nCommand: `.venv/bin/python benchmarks/bench_check.py "
                                    f"--runs {args.runs}`\n\n{table}\n")


if __name__ == "__main__":
    main()
