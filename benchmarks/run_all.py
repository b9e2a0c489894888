"""Run every benchmark in turn (``make bench``); each prints its own table.

The current figures go into ``benchmarks/RESULTS.md`` with the machine;
the per-topic detail is in ``benchmarks/results/``. Benchmarks time things,
so run them on a quiet machine: ratios against the reference measured in the
same run hold under load, absolute times do not.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ORDER = ["bench_mirror.py", "bench_render.py", "bench_render_floor.py", "bench_relief.py", "bench_design.py", "bench_first_look.py", "bench_sparse_stage.py", "bench_export.py", "bench_check.py", "bench_check_hostile.py", "bench_conformance.py", "bench_batch.py", "bench_verify.py"]


def main() -> int:
    failed = []
    for name in ORDER:
        print(f"\n=== {name} ===", flush=True)
        rc = subprocess.call([sys.executable, str(HERE / name)])
        if rc:
            failed.append(name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
