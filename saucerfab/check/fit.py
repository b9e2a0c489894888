"""The printer profile's file rules and build volume, and whether the size is plausible (units).

Each check appends its findings to ``out``; without a printer profile only
the units check runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshData
from saucerfab.check.report import Finding, finding

if TYPE_CHECKING:
    from saucerfab.model.profiles import PrinterProfile


def printer_file_checks(md: MeshData, profile: PrinterProfile | None, m: int, file_bytes: int,
                         out: list[Finding]) -> None:
    """The profile's accepted formats, polygon limit (``m`` triangles) and file-size limit (``file_bytes``)."""
    if profile is None:
        return
    fmt = "glb" if md.format == "gltf" else md.format
    if fmt not in profile.accepted_formats:
        out.append(finding(
            "format_not_accepted",
            f"{profile.name} does not take {md.format.upper()} (it takes {', '.join(profile.accepted_formats)}; "
            f"prefer {profile.preferred_format})",
        ))
    if profile.max_triangles and m > profile.max_triangles:
        out.append(finding(
            "too_many_triangles",
            f"{m:,} triangles, over {profile.name}'s limit of {profile.max_triangles:,}; decimate the mesh",
        ))
    if profile.max_file_mb and file_bytes > profile.max_file_mb * 1e6:
        out.append(finding(
            "file_too_large",
            f"the file is {file_bytes / 1e6:.1f} MB, over {profile.name}'s limit of {profile.max_file_mb:g} MB",
        ))


def fit_checks(size: np.ndarray, profile: PrinterProfile | None, out: list[Finding]) -> None:
    """Whether the model's size (3,), mm, fits the profile's build volume, as it is or with its axes swapped."""
    if profile is None:
        return
    vol = np.array(profile.build_volume_mm, dtype=np.float64)
    fmt = " x ".join(f"{v:.1f}" for v in size)
    if (size <= vol).all():
        return
    if (np.sort(size) <= np.sort(vol)).all():
        out.append(finding("fits_rotated", f"{fmt} mm fits {profile.name}'s build volume only with axes swapped"))
        return
    out.append(finding(
        "exceeds_build_volume",
        f"{fmt} mm does not fit {profile.name}'s build volume "
        f"{' x '.join(f'{v:g}' for v in vol)} mm in any axis order; scale it down or split it",
    ))


def units_check(md: MeshData, size: np.ndarray, limits: Limits, out: list[Finding]) -> None:
    """A largest extent (``size`` (3,), mm) outside ``Limits.plausible_size_mm`` suggests wrong units."""
    big = float(size.max()) if size.size else 0.0
    lo, hi = limits.plausible_size_mm
    unit = "millimetres" if not md.units_stated else md.units
    if 0 < big < lo:
        out.append(finding(
            "units_suspect",
            f"the model is only {big:.4g} mm across (read in {unit}); if it was written in metres it is "
            f"{big * 1000:.4g} mm - check the export units",
        ))
    elif big > hi:
        out.append(finding(
            "units_suspect",
            f"the model is {big:,.0f} mm across (read in {unit}); "
            + ("glTF is in metres by specification - if it was written in millimetres, scale it by 0.001"
               if md.format in ("glb", "gltf") else "was it written in microns or with a wrong unit?"),
        ))
