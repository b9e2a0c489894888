"""Batch throughput: the same small manifest with 1 and with 2 local worker processes (and a Dask cluster).

    .venv/bin/python benchmarks/bench_batch.py [--jobs 12] [--raw 2] [--repeat 3] [--texture-px 256] [--dask]

The manifest has ``--jobs`` design-folder jobs (export + check of a 40 x 40
synthetic design, 3MF) and ``--raw`` raw-input jobs (a real design at 24 x 24
vertices, 32 px views, 20 iterations per stage, then export + check). Each
configuration runs ``--repeat`` times into a fresh output folder (``--force``
semantics: nothing reused); the table gives the median wall time, jobs per
minute and the speed-up over 1 worker. The 1-worker pool is the plain
reference; ``in-process`` (``--workers 0``: no pool, no process start) shows
the pool's own overhead. Wall times include starting the pool's processes
(each imports saucerfab and, for raw jobs, torch), as a user sees them; the
in-process engine pays those imports once, in its first repetition only.
``--dask`` adds a two-worker Dask ``LocalCluster`` (processes, one thread
each), started once before the runs as a bureau's cluster would already be
running: its start is not timed, its workers' first imports are (first
repetition).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def cpu_seconds() -> float:
    """User + system CPU time of this process and its finished children."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def make_manifest(folder: Path, jobs: int, raw: int, texture_px: int) -> Path:
    import importlib.util

    from saucerfab.model.design_folder import save_design, synthetic_design

    spec = importlib.util.spec_from_file_location("mbs", ROOT / "samples/batch/make_batch_samples.py")
    assert spec and spec.loader
    mbs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mbs)
    (folder / "images").mkdir(parents=True)
    for name, data in mbs.images().items():
        (folder / "images" / name).write_bytes(data)
    shapes = ["waves", "ripples", "bowl", "smooth_random"]
    lines = [
        "[defaults]",
        'printer = "j55"',
        "cup_diameter_mm = 80",
        'formats = ["3mf"]',
        f"export_options = {{ texture_px = {texture_px} }}",
        "design_options = { resolution = 24, image_size = 32, max_iters = 20 }",
    ]
    for i in range(jobs):
        save_design(
            synthetic_design(shape=shapes[i % len(shapes)], seed=i, resolution=40, texture_size=128),
            folder / "designs" / f"d{i}",
        )
        lines += ["", "[[job]]", f'id = "design-{i}"', f'design = "designs/d{i}"']
    pairs = [("ring.png", "star.png"), ("fish.png", "moon.png")]
    for i in range(raw):
        a, b = pairs[i % len(pairs)]
        lines += [
            "",
            "[[job]]",
            f'id = "raw-{i}"',
            f'direct = "images/{a}"',
            f'reflected = "images/{b}"',
            f"design_options = {{ seed = {i} }}",
        ]
    path = folder / "manifest.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=12, help="design-folder jobs")
    ap.add_argument("--raw", type=int, default=2, help="raw-input jobs (design first)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--texture-px", type=int, default=256)
    ap.add_argument("--dask", action="store_true", help="also run on a two-worker Dask LocalCluster")
    args = ap.parse_args()

    from saucerfab.batch import run_batch

    total = args.jobs + args.raw
    print(f"machine: {cpu_model()}, nproc {os.cpu_count()}, Python {platform.python_version()}")
    print(f"manifest: {args.jobs} design-folder jobs + {args.raw} raw-input jobs, texture {args.texture_px} px")
    cluster = None
    if args.dask:
        from distributed import LocalCluster

        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with tempfile.TemporaryDirectory() as td:
        manifest = make_manifest(Path(td) / "batch", args.jobs, args.raw, args.texture_px)
        configs: list[tuple[str, int | str]] = [("in-process", 0), ("1 worker", 1), ("2 workers", 2)]
        if cluster is not None:
            configs.append(("Dask 2 workers", cluster.scheduler_address))
        times: dict[str, list[float]] = {name: [] for name, _ in configs}
        loads: dict[str, list[float]] = {name: [] for name, _ in configs}
        cpus: dict[str, list[float]] = {name: [] for name, _ in configs}
        for r in range(args.repeat):
            for name, workers in configs:  # interleaved, so drift in machine load hits all alike
                out = Path(td) / f"out-{name}-{r}"
                load0 = os.getloadavg()[0]
                cpu0 = cpu_seconds()
                t = time.perf_counter()
                if isinstance(workers, str):
                    result = run_batch(manifest, out, scheduler=workers)
                else:
                    result = run_batch(manifest, out, workers=workers)
                times[name].append(time.perf_counter() - t)
                cpus[name].append(cpu_seconds() - cpu0)
                loads[name].append((load0 + os.getloadavg()[0]) / 2)
                assert result.ok, [(o.id, o.reason) for o in result.outcomes if o.status != "ok"]
                print(
                    f"  run {r + 1}/{args.repeat} {name:14s} {times[name][-1]:7.2f} s wall "
                    f"{cpus[name][-1]:7.2f} s CPU  load {loads[name][-1]:.1f}",
                    flush=True,
                )
    if cluster is not None:
        cluster.close()
    ref = statistics.median(times["1 worker"])
    print()
    best = min(times["1 worker"])
    print(
        f"{'engine':14s} {'median s':>9s} {'min s':>7s} {'max s':>7s} {'jobs/h':>7s} "
        f"{'vs 1 worker':>12s} {'min vs min':>11s} {'CPU s':>6s} {'load':>5s}"
    )
    for name, _ in configs:
        med = statistics.median(times[name])
        print(
            f"{name:14s} {med:9.2f} {min(times[name]):7.2f} {max(times[name]):7.2f} "
            f"{3600 * total / med:7.0f} {ref / med:11.2f}x {best / min(times[name]):10.2f}x "
            f"{statistics.median(cpus[name]):6.1f} {statistics.median(loads[name]):5.1f}"
        )
    print("jobs/h and 'vs 1 worker' from medians; 'min vs min' compares the fastest runs;")
    print("CPU s: CPU time of the driver and its worker processes (median);")
    print("load: the 1-minute load average around each run (median) -- above nproc means other work shared the CPUs")


if __name__ == "__main__":
    main()
