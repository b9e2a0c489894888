"""``saucerfab batch``: many jobs (design when needed, export, check) in one run.

A manifest (:mod:`saucerfab.batch.manifest`) lists the jobs; the driver
(:mod:`saucerfab.batch.runner`) skips jobs already complete for the same
inputs, runs the rest on an engine (:mod:`saucerfab.batch.executors`: this
process, a local process pool, or a Dask distributed cluster), writes each
job's output folder atomically (:mod:`saucerfab.batch.jobs`) and reports
(:mod:`saucerfab.batch.report`).

Library use::

    from saucerfab.batch import run_batch
    result = run_batch("samples/batch/manifest.toml", "out/batch", workers=2)
    result.exit_code          # 0 when every job is ok
    result.outcome("teapot")  # status, check verdict, times, files

One job alone: :func:`saucerfab.batch.jobs.run_job`.
"""

from __future__ import annotations

from saucerfab.batch.jobs import JobResult, run_job
from saucerfab.batch.manifest import JobSpec, Manifest, load_manifest
from saucerfab.batch.report import BatchResult, JobOutcome
from saucerfab.batch.runner import plan_batch, run_batch

__all__ = [
    "BatchResult",
    "JobOutcome",
    "JobResult",
    "JobSpec",
    "Manifest",
    "load_manifest",
    "plan_batch",
    "run_batch",
    "run_job",
]
