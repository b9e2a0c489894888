"""Issue 18 in one run: old and new default design times with verified quality, the first look, the rasterizer.

    .venv/bin/python benchmarks/bench_speed.py --old cdd73fc --arm paper='--method paper'   # every bundled pair
    .venv/bin/python benchmarks/bench_speed.py --old cdd73fc --pairs heart-star --no-render --no-first-look
    .venv/bin/python benchmarks/bench_speed.py --old HEAD --no-new --noise 2 --arm paper='--method paper'

For each pair, ``saucerfab design`` exactly as a user types it (defaults,
its quick verify included) by the old code (``--old``: a git revision,
copied with ``git archive`` and its numba kernels compiled before the clock
starts) and by this checkout, in alternating order (old first on the 1st,
3rd, ... pair, new first on the others, so that a drifting machine load
favours neither). Each design is exported for the J55 (OBJ, 80 mm cup) and
verified by *this* checkout's ``saucerfab verify`` at 256 px, 16 spp from
the design eye and a viewer's two eyes (the same instrument for both), and
each row gives design seconds, the stages' iterations and the PSNR per view
and eye. Then, in the same run, ``bench_first_look.py --repeat 3`` and
``bench_render.py --repeat 15 --torch-repeat 2`` (their own tables).

``--noise K``: per pair, K more designs of this checkout from a start moved
by a rounding-level amount (``perturbed_design.py``, seeds 1..K), verified
the same way: how far the verified pictures move by the optimizer's path
alone, the yardstick for any change that alters the path. With
``--arm-noise`` each ``--arm`` gets its K perturbed starts too (labels
``LABEL~1``..``LABEL~K``), and a last table compares each arm with the
default on the mean over the K + 1 starts of each: a change of method read
through the path noise rather than from one start of each.

Times are wall-clock on a shared machine: the ratio within a pair is the
figure; the load average is printed at each step. Beside each wall time,
the CPU seconds the design process used (user + system, from the children's
rusage): on this shared machine the wall time of the same iterations moved
by up to half between runs (session 20), so compare a design's CPU seconds
between runs to tell a slow spell from more work. The CPU ratio of old and
new is not the wall-time ratio: the new default keeps both cores busier.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the environment as the user gave it, before importing saucerfab sets its OpenMP
#: defaults (saucerfab/__init__.py): each design runs under it, so that the old
#: code and this checkout each choose their own, as for a user typing the command
USER_ENV = dict(os.environ)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_design import machine  # noqa: E402

from saucerfab.samples import PAIRS, SAMPLES  # noqa: E402
from saucerfab.verify import EyeSpec, verify_print  # noqa: E402

EYES = ("design", "left", "right")


def old_copy(rev: str, dest: Path) -> Path:
    """``rev`` of this repository as files in ``dest`` (``git archive``), its numba kernels compiled."""
    dest.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    subprocess.run([sys.executable, "-m", "saucerfab.warmup"], cwd=dest, env=_env(dest), check=True,
                   capture_output=True)
    return dest


def _env(code: Path) -> dict[str, str]:
    return {**USER_ENV, "PYTHONPATH": str(code)}


def design(code: Path, pair: str, out: Path, extra: list[str], noise_seed: int | None = None) -> dict:
    """``saucerfab design`` of ``pair`` by the code in ``code`` (as typed, plus ``extra``); seconds and stages.

    ``noise_seed``: through ``perturbed_design.py`` with that seed (its start moved by a rounding-level amount).
    """
    direct, reflected = PAIRS[pair]
    entry = (["-m", "saucerfab"] if noise_seed is None
             else [str(ROOT / "benchmarks" / "perturbed_design.py"), str(noise_seed)])
    cmd = [sys.executable, *entry, "design", "--direct", str(SAMPLES / direct), "--reflected",
           str(SAMPLES / reflected), "--out", str(out), "--quiet", *extra]
    t0, c0 = time.perf_counter(), _children_cpu()
    done = subprocess.run(cmd, cwd=code, env=_env(code), capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    seconds = time.perf_counter() - t0
    cpu_s = _children_cpu() - c0
    meta = json.loads((out / "design.json").read_text())
    stages = [(s["name"], s["iterations"], s.get("seconds", float("nan"))) for s in meta["metrics"]["stages"]]
    return {"seconds": seconds, "cpu_s": cpu_s, "stages": stages, "total_s": meta["metrics"].get("total_s")}


def _children_cpu() -> float:
    """User + system CPU seconds of this process's finished children.

    A second reading of a design's cost beside its wall time (see the module's docstring).
    """
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def verified(design_dir: Path, print_dir: Path) -> dict[str, float]:
    """Export for the J55 (OBJ) and verify at 256 px, 16 spp from three eyes: "view/eye" -> PSNR dB."""
    subprocess.run([sys.executable, "-m", "saucerfab", "export", str(design_dir), "--printer", "j55",
                    "--cup-diameter-mm", "80", "--formats", "obj", "--out", str(print_dir), "--quiet",
                    "--no-verify", "--no-check"], cwd=ROOT, env=_env(ROOT), check=True, capture_output=True)
    res = verify_print(print_dir, eyes=EyeSpec("both"), res=256, spp=16, all_formats=False)
    return {f"{v.view}/{v.eye}": v.psnr_db for v in res.files[0].views}


def _spread(d: list[float]) -> tuple[float, float, float, float, int]:
    """Changes in dB -> (mean, RMS, largest drop, largest gain, how many drop more than 0.5 dB)."""
    return (sum(d) / len(d), (sum(x * x for x in d) / len(d)) ** 0.5, min(d), max(d), sum(x < -0.5 for x in d))


def print_noise(rows: list[dict], k: int, arms: list[str]) -> None:
    """The path-noise table: per pair, view and eye, this checkout's default (``new``,
    else ``old``) and its K perturbed designs; then each ``--arm``'s change set
    against that spread."""
    base = "new" if "new" in rows[0] else "old"
    labels = [f"noise{j}" for j in range(1, k + 1)]
    print(f"\n### path noise: {base} and {k} rounding-level perturbed starts")
    print(f"| pair | view | eye | {base} dB | perturbed dB | change dB |")
    print("|---|---|---|---:|---|---|")
    deltas: dict[str, list[float]] = {e: [] for e in EYES}
    for r in rows:
        for view in ("direct", "reflected"):
            for e in EYES:
                b = r[base]["psnr"][f"{view}/{e}"]
                ps = [r[lab]["psnr"][f"{view}/{e}"] for lab in labels]
                deltas[e] += [p - b for p in ps]
                print(f"| {r['pair']} | {view} | {e} | {b:.1f} | " + " / ".join(f"{p:.1f}" for p in ps) + " | "
                      + " / ".join(f"{p - b:+.1f}" for p in ps) + " |")
    print()
    print("| eye | perturbed - default: mean dB | RMS dB | largest drop dB | largest gain dB | drops over 0.5 dB |")
    print("|---|---:|---:|---:|---:|---:|")
    for e in EYES:
        mean, rms, drop, gain, drops = _spread(deltas[e])
        print(f"| {e} | {mean:+.2f} | {rms:.2f} | {drop:+.1f} | {gain:+.1f} | {drops} of {len(deltas[e])} |")
    for arm in arms:
        print(f"\n{arm} against {base}, per eye (mean / RMS / largest drop / drops over 0.5 dB):")
        for e in EYES:
            d = [r[arm]["psnr"][f"{v}/{e}"] - r[base]["psnr"][f"{v}/{e}"] for r in rows
                 for v in ("direct", "reflected")]
            mean, rms, drop, _, drops = _spread(d)
            print(f"  {e}: {mean:+.2f} / {rms:.2f} / {drop:+.1f} / {drops} of {len(d)}")


def print_start_means(rows: list[dict], k: int, arms: list[str]) -> None:
    """Each ``--arm`` against this checkout's default, on the mean verified PSNR over K + 1 starts of each.

    One start of each moves a view by the path noise (``print_noise``); the
    mean over K + 1 starts moves by about 1/sqrt(K + 1) of it, so a change
    of method shows through it.
    """
    base = "new" if "new" in rows[0] else "old"
    base_runs = [base] + [f"noise{j}" for j in range(1, k + 1)]

    def mean(r: dict, runs: list[str], key: str) -> float:
        return sum(r[x]["psnr"][key] for x in runs) / len(runs)

    for arm in arms:
        runs = [arm] + [f"{arm}~{j}" for j in range(1, k + 1)]
        print(f"\n### {arm} against {base}: mean over {k + 1} starts of each")
        print(f"| pair | view | {base} dB: design / left / right eye | {arm} dB | change dB |")
        print("|---|---|---|---|---|")
        deltas: dict[str, list[float]] = {e: [] for e in EYES}
        for r in rows:
            for view in ("direct", "reflected"):
                b = [mean(r, base_runs, f"{view}/{e}") for e in EYES]
                a = [mean(r, runs, f"{view}/{e}") for e in EYES]
                for e, x, y in zip(EYES, b, a):
                    deltas[e].append(y - x)
                print(f"| {r['pair']} | {view} | " + " / ".join(f"{x:.1f}" for x in b) + " | "
                      + " / ".join(f"{y:.1f}" for y in a) + " | "
                      + " / ".join(f"{y - x:+.1f}" for x, y in zip(b, a)) + " |")
        secs = {lab: sum(r[x]["seconds"] for r in rows for x in rs) / len(rs)
                for lab, rs in ((base, base_runs), (arm, runs))}
        print(f"\nper eye (mean / largest drop / drops over 0.5 dB); seconds per start, all pairs: "
              f"{base} {secs[base]:.1f}, {arm} {secs[arm]:.1f}")
        for e in EYES:
            mean, _, drop, _, drops = _spread(deltas[e])
            print(f"  {e}: {mean:+.2f} / {drop:+.1f} / {drops} of {len(deltas[e])}")


def _load() -> str:
    return f"{os.getloadavg()[0]:.1f}"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", required=True, help="git revision of the old default (e.g. the commit before the change)")
    p.add_argument("--pairs", default="all", help=f"comma-separated or all: {', '.join(PAIRS)}")
    p.add_argument("--no-first-look", action="store_true")
    p.add_argument("--no-render", action="store_true")
    p.add_argument("--json", help="also write the rows as JSON here")
    p.add_argument("--arm", action="append", default=[], metavar="LABEL=OPTIONS",
                   help="one more configuration of this checkout, e.g. paper='--method paper' (repeatable)")
    p.add_argument("--no-new", action="store_true",
                   help="skip this checkout's default (when it is the old one, to compare only the --arm ones)")
    p.add_argument("--arm-noise", action="store_true",
                   help="with --noise K, K perturbed starts of every --arm too, and a table of means over the starts")
    p.add_argument("--noise", type=int, default=0, metavar="K",
                   help="K more designs per pair of this checkout from rounding-level perturbed starts "
                        "(perturbed_design.py): the optimizer's path noise in verified dB")
    args = p.parse_args()
    if args.noise < 0:
        p.error(f"--noise must be 0 or more designs per pair, got {args.noise}")
    if args.arm_noise and not (args.noise and args.arm):
        p.error("--arm-noise gives each --arm the --noise K perturbed starts: give --noise K and an --arm too")
    pairs = list(PAIRS) if args.pairs == "all" else args.pairs.split(",")
    extra_arms = [(a.split("=", 1)[0], ROOT, shlex.split(a.split("=", 1)[1])) for a in args.arm]
    print(f"machine: {machine()}; old = {args.old}, new = this checkout; start load {_load()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        old = old_copy(args.old, tmp / "old")
        # this checkout's kernels compiled too (a no-op when cached), so no design pays numba's compile
        subprocess.run([sys.executable, "-m", "saucerfab.warmup"], cwd=ROOT, env=_env(ROOT), check=True,
                       capture_output=True)
        for k, pair in enumerate(pairs):
            arms = [("old", old, [], None)] + ([] if args.no_new else [("new", ROOT, [], None)])
            arms += [(label, code, extra, None) for label, code, extra in extra_arms]
            arms += [(f"noise{j}", ROOT, [], j) for j in range(1, args.noise + 1)]
            if args.arm_noise:
                arms += [(f"{label}~{j}", code, extra, j) for label, code, extra in extra_arms
                         for j in range(1, args.noise + 1)]
            order = arms[k % len(arms):] + arms[:k % len(arms)]  # each arm first in turn
            row: dict = {"pair": pair}
            for label, code, extra, seed in order:
                out = tmp / pair / label
                d = design(code, pair, out / "design", extra, seed)
                d["load"] = _load()
                d["psnr"] = verified(out / "design", out / "print")
                row[label] = d
                print(f"{pair} {label}: {d['seconds']:.1f} s, CPU {d['cpu_s']:.1f} s (load {d['load']}), stages "
                      + ", ".join(f"{n} {i} it {s:.1f} s" for n, i, s in d["stages"]), flush=True)
            rows.append(row)
    print()
    for label in ([] if args.no_new else ["new"]) + [a[0] for a in extra_arms]:
        print(f"\n### {label} against old")
        print(f"| pair | old s | {label} s | {label} / old | CPU s old / {label} | CPU {label} / old "
              f"| old stages (it) | {label} stages (it) |")
        print("|---|---:|---:|---:|---:|---:|---|---|")
        for r in rows:
            o, n = r["old"], r[label]
            print(f"| {r['pair']} | {o['seconds']:.1f} | {n['seconds']:.1f} | {n['seconds'] / o['seconds']:.2f} | "
                  f"{o['cpu_s']:.1f} / {n['cpu_s']:.1f} | {n['cpu_s'] / o['cpu_s']:.2f} | "
                  + " / ".join(str(i) for _, i, _ in o["stages"]) + " | "
                  + " / ".join(str(i) for _, i, _ in n["stages"]) + " |")
        tot_o = sum(r["old"]["seconds"] for r in rows)
        tot_n = sum(r[label]["seconds"] for r in rows)
        cpu_o = sum(r["old"]["cpu_s"] for r in rows)
        cpu_n = sum(r[label]["cpu_s"] for r in rows)
        print(f"| all | {tot_o:.1f} | {tot_n:.1f} | {tot_n / tot_o:.2f} | {cpu_o:.1f} / {cpu_n:.1f} "
              f"| {cpu_n / cpu_o:.2f} | | |")
        print()
        print(f"| pair | view | old dB: design / left / right eye | {label} dB | change dB |")
        print("|---|---|---|---|---|")
        for r in rows:
            for view in ("direct", "reflected"):
                o = [r["old"]["psnr"][f"{view}/{e}"] for e in EYES]
                n = [r[label]["psnr"][f"{view}/{e}"] for e in EYES]
                print(f"| {r['pair']} | {view} | " + " / ".join(f"{x:.1f}" for x in o) + " | "
                      + " / ".join(f"{x:.1f}" for x in n) + " | "
                      + " / ".join(f"{b - a:+.1f}" for a, b in zip(o, n)) + " |")
    if args.noise:
        print_noise(rows, args.noise, [a[0] for a in extra_arms])
    if args.arm_noise:
        print_start_means(rows, args.noise, [a[0] for a in extra_arms])
    if args.json:
        Path(args.json).write_text(json.dumps({"old": args.old, "machine": machine(), "rows": rows}, indent=2))
    sys.stdout.flush()
    if not args.no_first_look:
        print(f"\n## first look (load {_load()})", flush=True)
        subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_first_look.py"), "--repeat", "3"], check=True)
    if not args.no_render:
        print(f"\n## rasterizer (load {_load()})", flush=True)
        subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_render.py"), "--repeat", "15",
                        "--torch-repeat", "2"], check=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
