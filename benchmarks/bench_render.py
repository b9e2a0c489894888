"""Benchmark of the soft rasterizer on the paper's setup (issue 3).

One iteration = what the optimizer does per step: heights (150 x 150,
float32, requires grad) -> direct-view vertices and reflected-view vertices
-> ``soft_rasterize`` of both views at 512 x 512 with per-face colours
(requires grad) -> an L2 image loss plus an alpha term -> backward through to
the heights and the colours. Timed for the numba backend and, on the same work
in the same run, the straightforward torch backend, at sigma 1e-5 and 1e-7.

The reflected view is the real one: ``saucerfab.model.mirror.reflect`` gives the
virtual points R = (r_x, r_y, h) of every saucer vertex in the cup (fixed xy,
height h) and ``reflected_mesh`` the faces that reflect validly at the
starting heights; their colours are the saucer faces' colours.

Usage::

    .venv/bin/python benchmarks/bench_render.py [--repeat 7] [--torch-repeat 2] [--write]

``--write`` records the table in ``benchmarks/results/render.md``.
"""

from __future__ import annotations

import saucerfab  # noqa: F401 - first, as in the CLI: its OpenMP wait settings must precede torch

import argparse  # noqa: E402
import os  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from saucerfab.model.heightfield import base_shape, make_grid, triangulate  # noqa: E402
from saucerfab.render import Camera, soft_rasterize  # noqa: E402
from saucerfab.render.soft_torch import count_candidate_pairs  # noqa: E402
from saucerfab.model.scene import Scene  # noqa: E402

def build_problem(dtype: torch.dtype = torch.float32):  # type: ignore[no-untyped-def]
    """The paper's setup.

    Returns ``(heights, views, colors, note)``: the (N, N) starting heights, a
    function ``views(h) -> [(vertices, faces, face_ids, camera), ...]`` (the
    direct view, then one reflected part per mirror piece; ``face_ids`` index
    the saucer faces, for their colours, None for all of them), the per-face
    colours and a note on the reflected geometry.
    """
    from saucerfab.model.mirror import reflect, reflected_mesh

    scene = Scene()
    n = scene.saucer.resolution
    grid = make_grid(scene.saucer)
    heights0 = base_shape("waves", n)
    xy = torch.as_tensor(grid.xy(), dtype=dtype)
    faces = torch.as_tensor(triangulate(n))
    pieces = reflect(scene, grid.xy())
    parts = [
        (torch.as_tensor(p.r_xy, dtype=dtype), torch.as_tensor(m.faces), torch.as_tensor(m.face_ids))
        for p, m in zip(pieces, reflected_mesh(scene, heights0, pieces))
    ]
    cam_d, cam_r = Camera.from_scene(scene, "direct"), Camera.from_scene(scene, "reflected")
    n_refl = sum(int(f.shape[0]) for _, f, _ in parts)
    note = (
        f"saucerfab.model.mirror.reflect in the paper's circular cup: {n_refl:,} of the "
        f"{faces.shape[0]:,} faces reflect validly"
    )

    def views(h: torch.Tensor) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, Camera]]:
        z = h.reshape(-1, 1)
        out = [(torch.cat([xy, z], dim=1), faces, None, cam_d)]
        out += [(torch.cat([r, z], dim=1), f, ids, cam_r) for r, f, ids in parts]
        return out

    heights = torch.as_tensor(heights0, dtype=dtype)
    colors = torch.full((faces.shape[0], 3), 0.5, dtype=dtype)
    return heights, views, colors, note


def iteration(heights, views, colors, targets, sigma, backend):  # type: ignore[no-untyped-def]
    """One optimizer step's rendering work; returns the gradients (heights, colours)."""
    h = heights.clone().requires_grad_(True)
    c = colors.clone().requires_grad_(True)
    loss = 0.0
    for (verts, faces, ids, cam), (ti, ta) in zip(views(h), targets):
        cf = c if ids is None else torch.index_select(c, 0, ids)
        image, alpha = soft_rasterize(verts, faces, cf, cam, sigma=sigma, backend=backend)
        loss = loss + ((image - ti) ** 2).sum() + ((alpha - ta) ** 2).sum()
    loss.backward()
    return h.grad, c.grad


def kernel_time(work) -> float:  # type: ignore[no-untyped-def]
    """Seconds one iteration spends inside the numba autograd Function (forward and
    backward, both views), from torch's profiler: the part that the threads share."""
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        iteration(*work, backend="numba")
    total_us = sum(
        e.self_cpu_time_total for e in prof.key_averages() if e.key.startswith("SoftRasterizeNumba")
    )
    return total_us * 1e-6


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


def _scratch_nbytes() -> int:
    """The numba backend's reused per-thread buffers (0 for versions without them)."""
    from saucerfab.render import soft_numba

    return int(getattr(soft_numba, "scratch_nbytes", lambda: 0)())


def main(argv: list[str] | None = None) -> int:
    global _numba_ran
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed numba iterations per sigma")
    ap.add_argument("--torch-repeat", type=int, default=2, help="timed torch iterations per sigma")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[1e-5, 1e-7])
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/render.md")
    args = ap.parse_args(argv)

    heights, views, colors, note = build_problem()
    rng = np.random.default_rng(0)
    targets = [
        (torch.as_tensor(rng.random((cam.image_size, cam.image_size, 3)), dtype=torch.float32),
         torch.ones(cam.image_size, cam.image_size))
        for _, _, _, cam in views(heights)
    ]
    rows = []
    for sigma in args.sigmas:
        pairs = sum(count_candidate_pairs(v, f, cam, sigma) for v, f, _, cam in views(heights))
        work = (heights, views, colors, targets, sigma)
        iteration(*work, backend="numba")  # compile (or load the cache) and warm up
        _numba_ran = True
        tracemalloc.start()
        iteration(*work, backend="numba")
        # plus the backward's buffers that the numba backend keeps and reuses from
        # call to call (allocated before tracing began, so not in the traced peak)
        numba_peak = tracemalloc.get_traced_memory()[1] + _scratch_nbytes()
        tracemalloc.stop()
        c0 = time.process_time()
        tn = timed(lambda: iteration(*work, backend="numba"), args.repeat)
        cpu_numba = (time.process_time() - c0) / args.repeat
        rss_numba = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        # the same on one thread: what the second core buys (when it is free)
        import numba

        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        t1 = timed(lambda: iteration(*work, backend="numba"), args.repeat)
        kernels_1t = kernel_time(work)
        numba.set_num_threads(threads)
        iteration(*work, backend="torch")
        c0 = time.process_time()
        tt = timed(lambda: iteration(*work, backend="torch"), args.torch_repeat)
        cpu_torch = (time.process_time() - c0) / args.torch_repeat
        rss_torch = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        # the two backends on the same work: the gradients agree
        gn = iteration(*work, backend="numba")
        gt = iteration(*work, backend="torch")
        agree = max(float((a - b).abs().max() / b.abs().max().clamp_min(1e-30)) for a, b in zip(gn, gt))
        rows.append(dict(
            sigma=sigma, pairs=pairs, numba_ms=1e3 * statistics.median(tn), numba_min=1e3 * min(tn),
            torch_ms=1e3 * statistics.median(tt), numba_mib=numba_peak / 2**20,
            numba_cpu=1e3 * cpu_numba, torch_cpu=1e3 * cpu_torch, numba_1t=1e3 * statistics.median(t1),
            kernels_1t=1e3 * kernels_1t,
            rss_numba=rss_numba, rss_torch=rss_torch, agree=agree,
        ))
        r = rows[-1]
        print(
            f"sigma {sigma:g}: pairs {pairs / 1e6:.2f} M | numba {r['numba_ms']:.1f} ms (min {r['numba_min']:.1f}, "
            f"CPU {r['numba_cpu']:.0f} ms; 1 thread {r['numba_1t']:.1f} ms, of it kernels {r['kernels_1t']:.1f} ms) "
            f"| torch {r['torch_ms']:.0f} ms (CPU {r['torch_cpu']:.0f}) "
            f"| x{r['torch_ms'] / r['numba_ms']:.0f} | numpy peak "
            f"{r['numba_mib']:.0f} MiB | max RSS after numba {rss_numba:.0f} MiB, after torch {rss_torch:.0f} MiB "
            f"| grad rel diff {agree:.1e}",
            flush=True,
        )
    text = report(rows, note, args)
    print(text)
    if args.write:
        out = Path(__file__).parent / "results" / "render.md"
        out.write_text(text)
        print(f"wrote {out}")
    return 0


def report(rows: list[dict], note: str, args: argparse.Namespace) -> str:
    load = os.getloadavg()
    lines = [
        "# Soft rasterizer benchmark (benchmarks/bench_render.py)",
        "",
        f"Machine: {machine()}. Load average at the end of the run: "
        f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min; other jobs share the cores).",
        f"Command: `.venv/bin/python benchmarks/bench_render.py --repeat {args.repeat} "
        f"--torch-repeat {args.torch_repeat}{' --write' if args.write else ''}`",
        "",
        "One iteration: forward + backward of the direct view (44,402 faces) and the reflected view "
        "(512 x 512 each) of the 150 x 150 'waves' saucer, float32, an L2 loss on image and alpha, "
        f"gradients through to the heights and the face colours. Reflected view: {note}.",
        "Wall times are medians of the timed iterations; CPU is the process CPU time per iteration "
        "(all threads), which other jobs on the machine disturb less than wall time. Max RSS is the "
        "process's peak so far (cumulative down the table). Grad rel. diff: the largest difference "
        "between the numba and torch gradients (heights and colours, float32) over the largest "
        "torch gradient.",
        "",
        "| sigma | candidate pairs (both views) | numba ms/iter | numba min | numba CPU ms "
        "| numba 1 thread ms | torch ms/iter | torch CPU ms | speed-up (wall) | numpy peak (numba iter, incl. reused buffers) "
        "| max RSS after numba / torch | grad rel. diff |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['sigma']:g} | {r['pairs'] / 1e6:.2f} M | {r['numba_ms']:.1f} | {r['numba_min']:.1f} "
            f"| {r['numba_cpu']:.0f} | {r['numba_1t']:.1f} | {r['torch_ms']:.0f} | {r['torch_cpu']:.0f} "
            f"| {r['torch_ms'] / r['numba_ms']:.0f}x | {r['numba_mib']:.0f} MiB "
            f"| {r['rss_numba']:.0f} / {r['rss_torch']:.0f} MiB | {r['agree']:.1e} |"
        )
    lines += [
        "",
        "Kernels: the time one single-threaded iteration spends in the numba forward and "
        "backward (torch profiler; it includes the serial binning, about 3 ms); the rest (projection, "
        "loss, autograd) is serial. "
        "Two free cores would take about (1 thread - kernels / 2):",
        "",
        "| sigma | 1 thread ms | of it kernels ms | estimate on 2 free cores ms |",
        "|---|---|---|---|",
    ]
    for r in rows:
        est = r["numba_1t"] - r["kernels_1t"] / 2
        lines.append(f"| {r['sigma']:g} | {r['numba_1t']:.1f} | {r['kernels_1t']:.1f} | {est:.0f} |")
    if all(r["numba_1t"] < 1.2 * r["numba_ms"] for r in rows):
        lines += [
            "",
            "In this run the second thread bought little (1-thread and 2-thread times are close "
            "and process CPU time is close to wall time): other jobs held the other core. "
            "The estimate above is then the better guide to an idle 2-core machine.",
        ]
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
