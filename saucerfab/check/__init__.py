"""``saucerfab check``: is this coloured mesh printable? Safe on any file.

Public API (stable; the exporters and batch mode call it)::

    from saucerfab.check import check_mesh, reports_to_junit, reports_to_json

    report = check_mesh("saucer.3mf", printer="j55")      # -> Report
    report.verdict      # "printable" | "not printable" | "unreadable"
    report.exit_code    # 0 | 1 | 2
    report.findings     # [Finding(severity, code, message, where)]
    report.stats        # triangles, bbox_mm, volume_mm3, min_wall_mm, texture_dpi, ...
    report.to_dict()    # JSON schema "saucerfab.check/1" (see saucerfab.check.report)
    report.with_strict()  # warnings fail too

:func:`check_mesh` never raises for anything wrong with the *file*: an
unreadable, hostile or broken file gives a report with exit code 2 or 1 and
a one-line reason. It raises :class:`~saucerfab.errors.ConfigError` only for
a bad ``printer`` argument (the caller's mistake, not the file's).

This module imports only the light parts (report, limits); numpy, scipy,
Pillow and manifold3d load when the first file is checked, and torch never.
A 3MF package is also read by lib3mf, the 3MF Consortium's reader, in a
bounded child process (``saucerfab.check.readers.lib3mf_strict``; a fork
server started with the first 3MF, ~10-20 ms a file); its verdict becomes
``lib3mf_*`` findings. ``SAUCERFAB_LIB3MF=off`` turns that stage off.
"""

from __future__ import annotations

import os
import time
from typing import TYPE_CHECKING

from saucerfab.check.limits import DEFAULT_LIMITS, Limits
from saucerfab.check.report import (
    CODES,
    SCHEMA_ID,
    Finding,
    Report,
    reports_to_dict,
    reports_to_json,
    reports_to_junit,
    summary_line,
)
from saucerfab.check.schema import JSON_SCHEMA, REPORT_SCHEMA

if TYPE_CHECKING:
    from saucerfab.model.profiles import PrinterProfile

__all__ = [
    "CODES", "JSON_SCHEMA", "REPORT_SCHEMA", "SCHEMA_ID", "Finding", "Limits", "Report",
    "check_mesh", "check_many", "reports_to_dict", "reports_to_json", "reports_to_junit", "summary_line",
]


def _profile(printer: PrinterProfile | str | os.PathLike[str] | None) -> PrinterProfile | None:
    if printer is None:
        return None
    from saucerfab.model.profiles import PrinterProfile, load_profile

    if isinstance(printer, PrinterProfile):
        return printer
    return load_profile(printer)


def check_mesh(
    path: str | os.PathLike[str],
    *,
    printer: PrinterProfile | str | None = None,
    limits: Limits | None = None,
    strict: bool = False,
) -> Report:
    """Check one mesh file and return its :class:`Report`.

    Args:
        path: any 3MF, OBJ (+MTL+texture), STL, PLY, GLB/glTF or VRML 2.0 file.
        printer: a :class:`PrinterProfile`, a profile key (``"j55"``) or a
            path to a profile TOML; adds build-volume, polygon, file-size,
            format, wall-thickness and texture-resolution checks.
        limits: the checker's own bounds (file size, triangle cap, work
            budgets); :data:`DEFAULT_LIMITS` when None.
        strict: judge warnings as failures (``Report.with_strict`` does the
            same afterwards).
    """
    t0 = time.perf_counter()
    prof = _profile(printer)
    limits = limits or DEFAULT_LIMITS
    spath = os.fspath(path)
    key = prof.key if prof is not None else None
    try:
        file_bytes = os.stat(spath).st_size
    except OSError:
        file_bytes = None
    fmt: str | None = None
    try:
        from saucerfab.check.meshdata import ReadError
        from saucerfab.check.readers import read_mesh

        try:
            md = read_mesh(spath, limits)
        except ReadError as exc:
            f = Finding("error", exc.code, exc.message, exc.where)
            return Report.build(spath, fmt, [f], {"file_bytes": file_bytes}, printer=key, strict=strict,
                                elapsed_s=time.perf_counter() - t0)
        fmt = md.format
        if fmt == "3mf":  # a 3MF package the bounded reader read: lib3mf's verdict too, in a bounded child process
            from saucerfab.check.readers.lib3mf_strict import lib3mf_findings

            md.notes.extend(lib3mf_findings(spath, md.notes))
        import numpy as np

        from saucerfab.check.checks import run_checks

        # absurd but finite coordinates (1e300) overflow in products; the checks judge the results,
        # and numpy's RuntimeWarnings would only be noise on the console
        with np.errstate(all="ignore"):
            findings, stats = run_checks(md, prof, limits, file_bytes or 0)
    except MemoryError:
        f = Finding("error", "over_check_limit", "ran out of memory: the file is too large for this machine; "
                                                 "lower Limits.max_triangles or use a bigger machine")
        return Report.build(spath, fmt, [f], {"file_bytes": file_bytes}, printer=key, strict=strict,
                            elapsed_s=time.perf_counter() - t0)
    except RecursionError:
        f = Finding("error", "malformed", "the file nests too deeply to read")
        return Report.build(spath, fmt, [f], {"file_bytes": file_bytes}, printer=key, strict=strict,
                            elapsed_s=time.perf_counter() - t0)
    except Exception as exc:
        f = Finding("error", "internal_error", f"the checker failed: {type(exc).__name__}: {exc}")
        return Report.build(spath, fmt, [f], {"file_bytes": file_bytes}, printer=key, strict=strict,
                            elapsed_s=time.perf_counter() - t0)
    return Report.build(spath, fmt, findings, stats, printer=key, strict=strict, elapsed_s=time.perf_counter() - t0)


def check_many(
    paths: list[str | os.PathLike[str]],
    *,
    printer: PrinterProfile | str | None = None,
    limits: Limits | None = None,
    strict: bool = False,
) -> list[Report]:
    """:func:`check_mesh` for each path (the printer profile is loaded once)."""
    prof = _profile(printer)
    return [check_mesh(p, printer=prof, limits=limits, strict=strict) for p in paths]
