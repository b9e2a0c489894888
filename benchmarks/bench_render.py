"""Benchmark of the soft rasterizer on the paper's setup (issue 3).

One iteration = what the optimizer does per step: heights (150 x 150,
float32, requires grad) -> direct-view vertices and reflected-view vertices
-> ``soft_rasterize`` of both views at 512 x 512 with per-face colours
(requires grad) -> an L2 image loss plus an alpha term -> backward through to
the heights and the colours. Timed for the numba backend and, on the same work
in the same run, the straightforward torch backend, at sigma 1e-5 and 1e-7.

The reflected view: ``saucerfab.mirror`` does not exist yet, so the saucer
mirrored across the plane y = -0.4 (the cup's front) stands in for it: a mesh of the same size and face count, with
flipped winding, seen through the reflected view frame.

Usage::

    .venv/bin/python benchmarks/bench_render.py [--repeat 7] [--torch-repeat 2] [--write]

``--write`` records the table in ``benchmarks/results_render.md``.
"""

from __future__ import annotations

import os

# torch's OpenMP workers must not spin (busy-wait) between torch ops while
# numba's workers run; libgomp reads this when torch is imported.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from saucerfab.heightfield import base_shape, make_grid, triangulate  # noqa: E402
from saucerfab.render import Camera, soft_rasterize  # noqa: E402
from saucerfab.render.soft_torch import count_candidate_pairs  # noqa: E402
from saucerfab.scene import Scene  # noqa: E402

MIRROR_PLANE_Y = -0.4


def build_problem(dtype: torch.dtype = torch.float32):  # type: ignore[no-untyped-def]
    """The paper's setup: returns (heights, make_views, faces, colors, cameras, reflected_note)."""
    scene = Scene()
    n = scene.saucer.resolution
    grid = make_grid(scene.saucer)
    heights0 = base_shape("waves", n)
    xy = torch.as_tensor(grid.xy(), dtype=dtype)
    faces = torch.as_tensor(triangulate(n))
    note = f"stand-in: the saucer mirrored across y = {MIRROR_PLANE_Y} (saucerfab/mirror.py not present yet)"

    def views(h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        direct = torch.cat([xy, h.reshape(-1, 1)], dim=1)
        mirrored = torch.cat(
            [xy[:, :1], 2 * MIRROR_PLANE_Y - xy[:, 1:2], h.reshape(-1, 1)], dim=1
        )
        return direct, mirrored

    heights = torch.as_tensor(heights0, dtype=dtype)
    colors = torch.full((faces.shape[0], 3), 0.5, dtype=dtype)
    cams = (Camera.from_scene(scene, "direct"), Camera.from_scene(scene, "reflected"))
    return heights, views, faces, colors, cams, note


def iteration(heights, views, faces, colors, cams, targets, sigma, backend):  # type: ignore[no-untyped-def]
    h = heights.clone().requires_grad_(True)
    c = colors.clone().requires_grad_(True)
    loss = 0.0
    for verts, cam, (ti, ta) in zip(views(h), cams, targets):
        image, alpha = soft_rasterize(verts, faces, c, cam, sigma=sigma, backend=backend)
        loss = loss + ((image - ti) ** 2).sum() + ((alpha - ta) ** 2).sum()
    loss.backward()
    return h.grad, c.grad


def timed(fn, repeat: int) -> list[float]:  # type: ignore[no-untyped-def]
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import numba

    return (
        f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, torch {torch.__version__}, "
        f"numba {numba.__version__} ({numba.config.NUMBA_NUM_THREADS} threads, "
        f"layer {numba.threading_layer() if _numba_ran else '?'})"
    )


_numba_ran = False


def main() -> None:
    global _numba_ran
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed numba iterations per sigma")
    ap.add_argument("--torch-repeat", type=int, default=2, help="timed torch iterations per sigma")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[1e-5, 1e-7])
    ap.add_argument("--write", action="store_true", help="write benchmarks/results_render.md")
    args = ap.parse_args()

    heights, views, faces, colors, cams, note = build_problem()
    rng = np.random.default_rng(0)
    targets = [
        (torch.as_tensor(rng.random((c.image_size, c.image_size, 3)), dtype=torch.float32),
         torch.ones(c.image_size, c.image_size))
        for c in cams
    ]
    rows = []
    for sigma in args.sigmas:
        pairs = sum(count_candidate_pairs(v, faces, cam, sigma) for v, cam in zip(views(heights), cams))
        work = (heights, views, faces, colors, cams, targets, sigma)
        iteration(*work, backend="numba")  # compile (or load the cache) and warm up
        _numba_ran = True
        tracemalloc.start()
        iteration(*work, backend="numba")
        numba_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        tn = timed(lambda: iteration(*work, backend="numba"), args.repeat)
        rss_numba = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        iteration(*work, backend="torch")
        tt = timed(lambda: iteration(*work, backend="torch"), args.torch_repeat)
        rss_torch = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        # the two backends on the same work: the gradients agree
        gn = iteration(*work, backend="numba")
        gt = iteration(*work, backend="torch")
        agree = max(float((a - b).abs().max() / b.abs().max().clamp_min(1e-30)) for a, b in zip(gn, gt))
        rows.append(dict(
            sigma=sigma, pairs=pairs, numba_ms=1e3 * statistics.median(tn), numba_min=1e3 * min(tn),
            torch_ms=1e3 * statistics.median(tt), numba_mib=numba_peak / 2**20,
            rss_numba=rss_numba, rss_torch=rss_torch, agree=agree,
        ))
        r = rows[-1]
        print(
            f"sigma {sigma:g}: pairs {pairs / 1e6:.2f} M | numba {r['numba_ms']:.1f} ms (min {r['numba_min']:.1f}) "
            f"| torch {r['torch_ms']:.0f} ms | x{r['torch_ms'] / r['numba_ms']:.0f} | numpy peak "
            f"{r['numba_mib']:.0f} MiB | max RSS after numba {rss_numba:.0f} MiB, after torch {rss_torch:.0f} MiB "
            f"| grad rel diff {agree:.1e}",
            flush=True,
        )
    text = report(rows, note, args)
    print(text)
    if args.write:
        out = Path(__file__).with_name("results_render.md")
        out.write_text(text)
        print(f"wrote {out}")


def report(rows: list[dict], note: str, args: argparse.Namespace) -> str:
    lines = [
        "# Soft rasterizer benchmark (benchmarks/bench_render.py)",
        "",
        f"Machine: {machine()}.",
        f"Command: `.venv/bin/python benchmarks/bench_render.py --repeat {args.repeat} "
        f"--torch-repeat {args.torch_repeat}{' --write' if args.write else ''}`",
        "",
        "One iteration: forward + backward of the direct and the reflected view (512 x 512 each), "
        "150 x 150 'waves' saucer (44,402 faces per view), float32, gradients through to the heights "
        f"and the face colours. Reflected view: {note}.",
        "",
        "| sigma | candidate pairs (both views) | numba ms/iter (median) | numba min | torch ms/iter "
        "| speed-up | numpy peak (numba iter) | max RSS after numba / after torch | grad rel. diff |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['sigma']:g} | {r['pairs'] / 1e6:.2f} M | {r['numba_ms']:.1f} | {r['numba_min']:.1f} "
            f"| {r['torch_ms']:.0f} | {r['torch_ms'] / r['numba_ms']:.0f}x | {r['numba_mib']:.0f} MiB "
            f"| {r['rss_numba']:.0f} / {r['rss_torch']:.0f} MiB | {r['agree']:.1e} |"
        )
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
