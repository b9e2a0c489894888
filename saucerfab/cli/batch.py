"""``saucerfab batch``: run a manifest of jobs (design when needed, export, check).

    saucerfab batch MANIFEST --out DIR [--workers N | --scheduler tcp://HOST:PORT]

Exit code 0 when every job is ok (outputs written and the check passed), 1
when any job failed (the report says which and why), 2 for a bad manifest or
option, 130 when interrupted (finished jobs are kept; run again to finish).
"""

from __future__ import annotations

import argparse
import os

HELP = "run many design/export/check jobs from a manifest (local processes or a Dask cluster)"

EPILOG = """\
The manifest (TOML or CSV) lists jobs: id, a design folder or the inputs of a
design run, printer, cup_diameter_mm, formats, design_options / export_options.
Paths are relative to the manifest's folder and may not leave it. See
samples/batch/README.md for the format and an example.

Each job is written to OUT/<id>/ atomically, with job.json (its key: inputs'
sha256, parameters, saucerfab version) last; a rerun skips complete jobs whose
key is unchanged. Reports: OUT/batch-report.json and OUT/batch-report.html.

--scheduler runs the same jobs on an existing Dask distributed cluster. The
jobs carry their input files as bytes and their outputs come back to this
command, which writes OUT: workers need saucerfab (same version) installed,
not a shared file system.
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = EPILOG
    p.add_argument("manifest", help="the manifest file (.toml or .csv)")
    p.add_argument("-o", "--out", required=True, help="output folder (one folder per job, plus the reports)")
    engine = p.add_mutually_exclusive_group()
    engine.add_argument(
        "-j",
        "--workers",
        type=int,
        default=None,
        help="local worker processes (default: the number of CPUs, at most the number of jobs; "
        "0 runs the jobs in this process)",
    )
    engine.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run the jobs on this Dask distributed scheduler instead of local processes",
    )
    p.add_argument("--threads-per-job", type=int, default=1, help="compute threads per job (default 1)")
    p.add_argument("--force", action="store_true", help="run every job, even those already complete")
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="check the manifest and inputs and list which jobs would run or be reused, then stop",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress display, no table")
    p.add_argument("--json", action="store_true", help="print the report JSON instead of the table")


def _sigterm_as_interrupt() -> None:
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):  # type: ignore[no-untyped-def]
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, handler)


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    from saucerfab.batch import load_manifest, plan_batch, run_batch
    from saucerfab.batch.report import LineDisplay, NullDisplay, RichDisplay, print_table

    manifest = load_manifest(args.manifest)
    out = Path(args.out)
    if args.dry_run:
        plan = plan_batch(manifest, out.resolve(), force=args.force)
        for p in plan:
            what = {"reuse": "complete, would be reused", "run": "would run"}.get(p.action, "")
            if p.action == "failed" and p.result is not None:
                what = f"would fail: {p.result.reason}"
            print(f"{p.job.id:24s} {p.job.kind:6s} {what}")
        return 0 if all(p.action != "failed" for p in plan) else 1
    from saucerfab.extras import require

    # every job exports and verifies (a dry run only reads the manifest and the inputs: the base install)
    require("design", "verify")
    if args.scheduler:
        require("cluster", subject="--scheduler")
    workers = args.workers
    if workers is None and not args.scheduler:
        workers = max(1, min(os.cpu_count() or 1, len(manifest.jobs)))
    if args.quiet or args.json:
        display = NullDisplay()
    elif sys.stderr.isatty():
        display = RichDisplay()
    else:
        display = LineDisplay()
    _sigterm_as_interrupt()
    result = run_batch(
        manifest,
        out,
        workers=workers or 0,
        scheduler=args.scheduler,
        force=args.force,
        threads_per_job=args.threads_per_job,
        display=display,
    )
    if args.json:
        print(result.report_json.read_text(encoding="utf-8"), end="")
    elif not args.quiet:
        print_table(result.outcomes)
        print(f"reports: {result.report_json}  {result.report_html}")
    return result.exit_code
