"""Thin walls: inward rays from area-weighted surface points, and the relief test for thin spots.

Only run on a closed, consistently oriented, outward mesh (elsewhere
"inside" means nothing; :func:`saucerfab.check.checks.run_checks` gates it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.check.bvh import BVH, query_workers
from saucerfab.check.limits import Limits
from saucerfab.check.places import fmt_pt, where
from saucerfab.check.report import Finding, finding

if TYPE_CHECKING:
    from saucerfab.model.profiles import PrinterProfile


def thin_walls(bvh: BVH, tri: np.ndarray, normals: np.ndarray, areas: np.ndarray, gidx: np.ndarray, diag: float,
                required: float | None, profile: PrinterProfile | None, limits: Limits,
                out: list[Finding], stats: dict[str, Any]) -> None:
    """Wall thickness by inward rays from area-weighted random surface points (fixed seed).

    Each ray starts on the surface and runs against the face normal; the
    distance to the first surface it meets that faces back at it is the
    local wall thickness. Sampling is by area, so the share of thin samples
    estimates the share of thin surface.
    """
    k = int(limits.thin_wall_samples)
    total = float(areas.sum())
    if k <= 0 or total <= 0:
        return
    rng = np.random.default_rng(20240601)
    f = rng.choice(len(tri), size=k, p=areas / total)
    r1, r2 = rng.random(k), rng.random(k)
    s1 = np.sqrt(r1)
    w = np.stack([1 - s1, s1 * (1 - r2), s1 * r2], axis=1)
    pts = np.einsum("kj,kjd->kd", w, tri[f])
    dirs = -normals[f]
    budget = min(limits.max_ray_tests, 2000 * k + 20 * len(tri))
    t, hit, complete = bvh.first_hits(tri, pts, dirs, f, t_min=1e-7 * diag, budget=budget, workers=query_workers())
    # A wall is measured where the ray meets a surface facing back at it (normals more than 120 degrees
    # apart). Near an edge whose faces meet at under 90 degrees the ray clips the neighbouring face at a
    # tiny distance; that is a corner, not a wall, unless the wedge is sharper than 60 degrees.
    ok = np.isfinite(t) & (hit >= 0)
    ok[ok] &= np.einsum("ij,ij->i", normals[f[ok]], normals[hit[ok]]) < -0.5
    stats["thin_wall_samples"] = int(ok.sum())
    if not complete:
        out.append(finding("check_partial", f"wall-thickness rays stopped at Limits.max_ray_tests "
                                            f"({limits.max_ray_tests:,}); {int(ok.sum())} of {k} points measured"))
    if not ok.any():
        return
    tt = t[ok]
    if required is not None and (tt < required).any():
        # a thin spot beside thick material is relief (a crest, a spike's tip, a sharp edge), not a wall
        idx = np.flatnonzero(ok)
        cand = idx[tt < required]
        relief = beside_thick(bvh, tri, pts[cand], dirs[cand], t[cand], required, budget, diag,
                               normals[f[cand]] + normals[hit[cand]])
        ok[cand[relief]] = False
        stats["relief_thin_samples"] = int(relief.sum())
        stats["thin_wall_samples"] = int(ok.sum())
        if not ok.any():
            return
        tt = t[ok]
    i = int(np.argmin(tt))
    where_pt = pts[ok][i]
    stats["min_wall_mm"] = round(float(tt[i]), 4)
    if required is None:
        return
    thin = tt < required
    share = float(thin.mean())
    stats["thin_wall_fraction"] = round(share, 5)
    if thin.any():
        # a printer's minimum wall is a rule of the printer: over more than the allowed share of the
        # surface (Limits.thin_wall_error_fraction) the part is not printable, whatever the profile's
        # thin_policy; a minimum asked for without a printer (--min-wall) only reports
        error = profile is not None and share > limits.thin_wall_error_fraction
        who = f"{profile.name}'s minimum" if profile is not None else "the minimum asked for"
        verdict = ""
        if profile is not None:
            verdict = (f", {'more' if error else 'no more'} than the {100 * limits.thin_wall_error_fraction:g}% "
                       f"a part may have{': not printable' if error else ''}")
        fi = gidx[f[ok][thin]]
        out.append(finding(
            "thin_walls",
            f"walls under {required:g} mm ({who}): {int(thin.sum())} of {int(ok.sum())} sampled points "
            f"({100 * share:.1f}% of the surface{verdict}); thinnest {float(tt[i]):.3f} mm at {fmt_pt(where_pt)}",
            severity="error" if error else "warning",
            where=where(where_pt, fi, count=int(thin.sum())),
        ))


#: in-plane directions probed around a thin spot for thick material beside it
RELIEF_DIRECTIONS = 8


def beside_thick(bvh: BVH, tri: np.ndarray, pts: np.ndarray, dirs: np.ndarray, t: np.ndarray,
                  required: float, budget: int, diag: float, normal_sum: np.ndarray | None = None) -> np.ndarray:
    """Which thin samples lie within ``required`` of material at least ``required`` thick.

    A sample at ``p`` measured thickness ``t`` along the inward ray ``r``; the
    material there spans the segment from ``p`` to ``p + t r``. From its
    midpoint ``m`` the test steps ``required`` (the minimum wall) inside the
    material in :data:`RELIEF_DIRECTIONS` directions across ``r`` (the
    segment from ``m`` may not leave the part) and measures the thickness
    along ``r`` there (both ways). When any of them is at least ``required``,
    the thin spot is the edge or tip of thicker material: the top of a crest,
    a spike's tip, a sharp edge, which a printer rounds off by up to its
    resolution but cannot break, so it is relief, not a wall (the relief's
    own rule is the minimum feature, which the export holds: saucerfab.model.relief).
    A thin wall (a sheet, a fin, a needle) stays thin for more than
    ``required`` in every direction across it, and stays a wall.

    A wedge (the two surfaces meet at an edge, their normals not opposite) is
    also probed along its bisector, away from the edge: ``-(n1 + n2)``, where
    the body that carries the edge lies (the directions across the ray can
    miss it by the wedge's half angle). A sheet's two normals cancel, so it
    gets no such probe.

    Args:
        pts, dirs, t: (K, 3), (K, 3) unit, (K,) the thin samples, their rays and thicknesses.
        required: the minimum wall, mm.
        normal_sum: (K, 3) the sum of the two surfaces' outward normals at each sample, or None.

    Returns:
        (K,) bool.
    """
    k = len(pts)
    if k == 0:
        return np.zeros(0, bool)
    # two unit vectors across each ray
    helper = np.where(np.abs(dirs[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    e1 = np.cross(dirs, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(dirs, e1)
    ang = 2 * np.pi * np.arange(RELIEF_DIRECTIONS) / RELIEF_DIRECTIONS
    across = np.cos(ang)[None, :, None] * e1[:, None, :] + np.sin(ang)[None, :, None] * e2[:, None, :]
    probes = RELIEF_DIRECTIONS
    if normal_sum is not None:
        length = np.linalg.norm(normal_sum, axis=1, keepdims=True)
        bis = np.where(length > 0.1, -normal_sum / np.maximum(length, 1e-12), e1)  # a sheet: one more across
        across = np.concatenate([across, bis[:, None, :]], axis=1)
        probes += 1
    across = across.reshape(-1, 3)
    mid = np.repeat(pts + 0.5 * t[:, None] * dirs, probes, axis=0)
    ray = np.repeat(dirs, probes, axis=0)
    none = np.full(len(mid), -1, np.int64)
    t_min = 1e-7 * diag
    share = max(budget // 4, 1)
    # the step from the midpoint must stay inside the part
    exit_t, _, _ = bvh.first_hits(tri, mid, across, none, t_min=t_min, budget=share, workers=query_workers())
    inside = exit_t > required
    probe = mid + required * across
    up, _, _ = bvh.first_hits(tri, probe, ray, none, t_min=t_min, budget=share, workers=query_workers())
    down, _, _ = bvh.first_hits(tri, probe, -ray, none, t_min=t_min, budget=share, workers=query_workers())
    thick = inside & np.isfinite(up) & np.isfinite(down) & (up + down >= required)
    return thick.reshape(k, probes).any(axis=1)
