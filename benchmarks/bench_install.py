"""Benchmark: install size and time of each pip extra, each in a clean virtual environment.

    python3 benchmarks/bench_install.py [--installs core,design,verify,studio,cluster,all]
        [--torch torch==2.13.0] [--work /tmp/saucerfab-install] [--conformance] [--out FILE]

Run it with a plain Python (not the project's ``.venv``): every install is a
new ``python -m venv`` beside the others under ``--work``. The package is
built once into a wheel from a copy of the sources (the repository is left
as it is), then for each install:

* ``core``: ``pip install saucerfab.whl`` (the checker: ``saucerfab check``);
* an extra: ``pip install 'saucerfab.whl[EXTRA]'``; for ``design`` and ``all``
  the CPU build of torch first (``--torch``), as ``make install`` does, so pip
  never pulls the CUDA build on its own.

Measured: the wall time of the install commands (not the venv's creation)
and the venv's size on disk (``du``), less an empty venv's (pip and its
kin), so a row is what the install added. Each venv but the checker's is
removed after its row. ``--conformance`` then installs pytest (only pytest)
into the checker's venv and runs ``tests/check/test_conformance.py`` there,
and runs ``saucerfab design`` there to show its missing-extra message.

The times depend on where pip finds the wheels: on a machine with a local
wheel mirror or a warm cache they are mostly unpacking and compiling
bytecode; a first install from PyPI adds the download (torch's CPU wheel
alone is ~180 MB). Say which when quoting them.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INSTALLS = ("core", "design", "verify", "studio", "cluster", "all")
#: installs that bring torch: the CPU build goes in first, as the Makefile does
WITH_TORCH = ("design", "all")


def run(cmd: list[str], cwd: Path | None = None) -> float:
    """Run ``cmd`` (failing loudly); return its wall time, s."""
    t = time.perf_counter()
    subprocess.run(cmd, cwd=cwd, check=True)
    return time.perf_counter() - t


def size_bytes(path: Path) -> int:
    """Bytes on disk under ``path`` (``du -sb``: apparent sizes, as pip's wheels unpack them)."""
    out = subprocess.run(["du", "-sb", str(path)], capture_output=True, text=True, check=True).stdout
    return int(out.split()[0])


def build_wheel(work: Path) -> Path:
    """The saucerfab wheel, built from a copy of the sources (no build output lands in the repository)."""
    src = work / "src"
    shutil.rmtree(src, ignore_errors=True)
    src.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    junk = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    shutil.copytree(ROOT / "saucerfab", src / "saucerfab", ignore=junk)
    dist = work / "dist"
    shutil.rmtree(dist, ignore_errors=True)
    run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(src)])
    return next(dist.glob("saucerfab-*.whl"))


def make_venv(path: Path) -> Path:
    """A new venv at ``path`` (an old one is removed); its python."""
    shutil.rmtree(path, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True)
    return path / "bin" / "python"


def install(work: Path, wheel: Path, name: str, torch: str) -> tuple[float, int, int]:
    """Install ``name`` into a clean venv ``work/venv-NAME``; (seconds, bytes added, bytes of the empty venv)."""
    py = make_venv(work / f"venv-{name}")
    empty = size_bytes(py.parents[1])
    pip = [str(py), "-m", "pip", "install", "-q"]
    seconds = 0.0
    if name in WITH_TORCH and torch:
        seconds += run(pip + [torch])
    seconds += run(pip + [str(wheel) if name == "core" else f"{wheel}[{name}]"])
    return seconds, size_bytes(py.parents[1]) - empty, empty


def conformance(work: Path) -> list[str]:
    """Run the conformance tests and ``saucerfab design`` in the checker's venv; lines for the report."""
    venv = work / "venv-core"
    py = venv / "bin" / "python"
    lines = []
    run([str(py), "-m", "pip", "install", "-q", "pytest"])
    probe = ("import importlib.util as u, saucerfab; print(saucerfab.__file__); "
             "print([m for m in ('torch', 'numba', 'scipy', 'mitsuba', 'starlette', 'trimesh') if u.find_spec(m)])")
    # everything from outside the repository, so that the installed saucerfab is the one imported (not ./saucerfab)
    found = subprocess.run([str(py), "-c", probe], cwd=work, capture_output=True, text=True,
                           check=True).stdout.split("\n")
    lines.append(f"checker venv: saucerfab from {found[0]}; of torch, numba, scipy, mitsuba, starlette, trimesh "
                 f"installed: {found[1]}")
    t = time.perf_counter()
    done = subprocess.run([str(venv / "bin" / "pytest"), "-q", "-p", "no:cacheprovider",
                           str(ROOT / "tests" / "check" / "test_conformance.py")],
                          cwd=work, capture_output=True, text=True)
    lines.append(f"tests/check/test_conformance.py: exit {done.returncode} in {time.perf_counter() - t:.0f} s: "
                 + (done.stdout.strip().splitlines() or ["(no output)"])[-1])
    design = subprocess.run([str(venv / "bin" / "saucerfab"), "design", "--direct", "a.png", "--reflected", "b.png",
                             "-o", "d"], cwd=work, capture_output=True, text=True)
    lines.append(f"saucerfab design: exit {design.returncode}: {design.stderr.strip()}")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--installs", default=",".join(INSTALLS), help=f"comma-separated, of {', '.join(INSTALLS)}")
    ap.add_argument("--torch", default="torch==2.13.0", help="torch requirement installed first for design and all "
                    "('' for none: then pip picks torch itself)")
    ap.add_argument("--work", default="/tmp/saucerfab-install", help="folder of the wheel and the venvs")
    ap.add_argument("--conformance", action="store_true", help="run the conformance tests in the checker's venv")
    ap.add_argument("--keep", action="store_true", help="keep every venv (default: only the checker's)")
    ap.add_argument("--out", help="also write the report (markdown) to this file")
    args = ap.parse_args()
    names = [n for n in args.installs.split(",") if n]
    unknown = sorted(set(names) - set(INSTALLS))
    if unknown:
        ap.error(f"unknown installs {unknown}: choose from {', '.join(INSTALLS)}")
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()[0]
    wheel = build_wheel(work)
    rows = []
    empty = 0
    for name in names:
        seconds, added, empty = install(work, wheel, name, args.torch)
        spec = "saucerfab" if name == "core" else f"'saucerfab[{name}]'"
        first = f"{args.torch}, then " if name in WITH_TORCH and args.torch else ""
        rows.append(f"| {name} | `pip install {first}{spec}` | {added / 2**20:,.0f} | {seconds:.1f} |")
        print(rows[-1], flush=True)
        if name != "core" and not args.keep:
            shutil.rmtree(work / f"venv-{name}")
    config = subprocess.run([sys.executable, "-m", "pip", "config", "list"], capture_output=True, text=True).stdout
    sources = [ln for ln in config.splitlines() if "index" in ln or "find-links" in ln] or ["PyPI (no pip config)"]
    report = ["# Install size and time by pip extra (benchmarks/bench_install.py)", "",
              f"Python {sys.version.split()[0]}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average "
              f"{load:.2f} at the start; sizes are what each install added to an empty venv "
              f"(itself {empty / 2**20:,.0f} MiB: pip and setuptools). "
              f"Where pip found the wheels: {'; '.join(sources)}.", "",
              "| install | command | MiB | s |", "|---|---|---:|---:|", *rows]
    if args.conformance and "core" in names:
        report += ["", *conformance(work)]
    text = "\n".join(report) + "\n"
    print(text)
    if args.out:  # whole or not at all: a temporary file beside it, then renamed over it
        out = Path(args.out)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
