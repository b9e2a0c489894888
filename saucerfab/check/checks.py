"""The checks: geometry, topology, printer profile, thin walls, colour, units.

:func:`run_checks` takes what a reader produced and returns findings and
stats. Checks that need a sound mesh are gated: with NaN coordinates no
geometry is measured; thin walls are only measured on a closed, consistently
oriented, outward-facing mesh (elsewhere "inside" means nothing), and each
skip is reported as a ``check_skipped`` info with the reason.

Self-intersections: manifold3d's ``Manifold(mesh).status()`` only says
whether the triangles form an oriented 2-manifold (every half-edge paired);
it accepts a mesh whose surfaces pass through each other, so it cannot
answer "no self-intersections". It is used here as an independent check of
manifoldness; self-intersections are found with the BVH in
:mod:`saucerfab.check.bvh` (a test shows manifold3d reporting NoError for
two interpenetrating boxes that this check flags).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.check import bvh as bvh_mod
from saucerfab.check.bvh import BVH, cross3, dot3, pair_intersections
from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshData
from saucerfab.check.report import Finding, finding
from saucerfab.check.topology import face_geometry, topology, weld

if TYPE_CHECKING:
    from saucerfab.profiles import PrinterProfile

_TEXTURE_CODES = {
    "missing": "texture_missing",
    "unreadable": "texture_unreadable",
    "too_large": "texture_too_large",
    "unsafe_path": "texture_path_unsafe",
}
_COLOUR_CAPABLE = {"3mf", "obj", "ply", "glb", "gltf", "wrl"}
#: coordinates beyond this many millimetres count as unusable (see run_checks)
_ABSURD_MM = 1e9
#: candidate pairs per narrow-phase chunk (bounds the temporary arrays to ~100 MB)
_PAIR_CHUNK = 150_000


def _workers() -> int:
    """Threads for the numpy-heavy kernels: the cores this process may use, at most 4."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(4, n))


def _pt(p: np.ndarray) -> list[float]:
    return [round(float(x), 4) for x in p]


def _where(point: np.ndarray | None = None, faces: Any = None, vertices: Any = None, count: int | None = None) -> dict[str, Any]:
    w: dict[str, Any] = {}
    if point is not None:
        w["point_mm"] = _pt(point)
    if faces is not None:
        w["faces"] = [int(f) for f in list(faces)[:10]]
    if vertices is not None:
        w["vertices"] = [int(v) for v in list(vertices)[:10]]
    if count is not None:
        w["count"] = int(count)
    return w


def _fmt_pt(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.2f}" for x in p) + ") mm"


def run_checks(
    md: MeshData, profile: PrinterProfile | None, limits: Limits, file_bytes: int
) -> tuple[list[Finding], dict[str, Any]]:
    """All checks on one mesh; returns (findings, stats)."""
    out: list[Finding] = list(md.notes)
    V = md.vertices * md.unit_mm
    Fo = md.faces
    m, n = len(Fo), len(V)
    stats: dict[str, Any] = {
        "file_bytes": file_bytes,
        "units": md.units,
        "unit_mm": md.unit_mm,
        "units_stated": md.units_stated,
        "parts": md.parts,
        "triangles": m,
        "vertices": n,
        "welded_vertices": None,
        "shells": None,
        "bbox_mm": None,
        "volume_mm3": None,
        "area_mm2": None,
        "boundary_edges": None,
        "non_manifold_edges": None,
        "non_manifold_vertices": None,
        "flipped_edges": None,
        "degenerate_faces": None,
        "duplicate_faces": None,
        "unreferenced_vertices": None,
        "self_intersecting_pairs": None,
        "self_intersection_check": "skipped",
        "min_wall_mm": None,
        "min_wall_required_mm": None,
        "thin_wall_samples": 0,
        "thin_wall_fraction": None,
        "relief_thin_samples": 0,
        "manifold3d_status": None,
        "textures": [t.to_dict() for t in md.textures],
        "texture_px": max((max(t.width or 0, t.height or 0) for t in md.textures), default=None) or None,
        "texture_dpi": None,
        "texture_detailed_fraction": None,
        "uv_outside_faces": None,
        "coloured_fraction": 0.0,
        "colour": sorted(md.colour_kinds),
    }
    if not md.units_stated:
        out.append(finding("units", f"{md.format.upper()} states no units; read as millimetres"))
    _printer_file_checks(md, profile, m, file_bytes, out)

    # beyond 1e9 mm (1000 km) products of coordinates lose all precision or overflow: as unusable as NaN
    finite = np.isfinite(V).all(axis=1) & (np.abs(V) <= _ABSURD_MM).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        out.append(finding(
            "non_finite",
            f"{len(bad):,} vertices have NaN, infinite or absurd (beyond 1e9 mm) coordinates (first: vertex "
            f"{int(bad[0])}: {V[bad[0]].tolist()}); fix the exporter - no printer can place them",
            where=_where(vertices=bad, count=len(bad)),
        ))
        out.append(finding("check_skipped", "geometry, topology, thin walls and colour area were not measured: "
                                            "coordinates are not finite"))
        _texture_status(md, out)
        return out, stats

    # ---- topology on welded vertices
    Vu, vmap = weld(V)
    Fw = vmap[Fo]
    topo = topology(Fw, len(Vu))
    areas, normals, volterms = face_geometry(Vu, Fw)
    used = np.zeros(n, dtype=bool)
    used[Fo.reshape(-1)] = True
    lo, hi = V[used].min(axis=0), V[used].max(axis=0)
    size = hi - lo
    diag = float(np.linalg.norm(size)) or 1.0
    stats.update(
        welded_vertices=len(Vu), shells=topo.shells,
        bbox_mm={"min": _pt(lo), "max": _pt(hi), "size": _pt(size)},
        area_mm2=round(float(areas.sum()), 4),
    )
    centroids = Vu[Fw].mean(axis=1)

    zero_area = areas <= 1e-12 * diag * diag
    degenerate = topo.index_degenerate | zero_area
    stats["degenerate_faces"] = int(degenerate.sum())
    if degenerate.any():
        idx = np.flatnonzero(degenerate)
        out.append(finding(
            "degenerate_faces",
            f"{len(idx):,} faces have a repeated vertex or zero area (first: face {int(idx[0])})",
            where=_where(centroids[idx[0]], idx, count=len(idx)),
        ))

    srt = np.sort(Fw, axis=1)
    nd = ~topo.index_degenerate
    key = (srt[:, 0] * len(Vu) + srt[:, 1]) * len(Vu) + srt[:, 2] if len(Vu) < 2_000_000 else None
    if key is not None:
        _, first_idx, inv = np.unique(key[nd], return_index=True, return_inverse=True)
    else:
        _, first_idx, inv = np.unique(srt[nd], axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    nd_idx = np.flatnonzero(nd)
    original = np.full(m, -1, dtype=np.int64)
    original[nd_idx] = nd_idx[first_idx[inv]]  # the first face with the same three vertices
    is_extra_copy = np.zeros(m, dtype=bool)
    is_extra_copy[nd_idx] = nd_idx != original[nd_idx]
    stats["duplicate_faces"] = int(is_extra_copy.sum())
    if is_extra_copy.any():
        extra = np.flatnonzero(is_extra_copy)
        e0, o0 = int(extra[0]), int(original[extra[0]])
        out.append(finding(
            "duplicate_faces",
            f"{len(extra):,} faces repeat another face's three vertices (first: face {e0} repeats face {o0}, "
            f"near {_fmt_pt(centroids[e0])})",
            where=_where(centroids[e0], [o0, *extra[:9].tolist()], count=len(extra)),
        ))

    unref = int((~used).sum())
    stats["unreferenced_vertices"] = unref
    if unref:
        out.append(finding("unreferenced_vertices", f"{unref:,} vertices are used by no face (harmless, but bloat)",
                           where=_where(vertices=np.flatnonzero(~used), count=unref)))

    closed = _edge_checks(topo, Vu, Fw, out, stats)

    # ---- volume and orientation per shell
    shell_vol = np.bincount(topo.shell, weights=volterms, minlength=topo.shells)
    consistent = closed and not topo.flipped_edges.any()
    outward = False
    if consistent:
        total = float(shell_vol.sum())
        stats["volume_mm3"] = round(total, 4)
        outward = _orientation_checks(topo, shell_vol, Vu, Fw, centroids, out)
    _shell_report(topo, shell_vol, centroids, out)

    # ---- self-intersections and thin walls share one BVH over the sound faces
    good = ~degenerate & ~is_extra_copy
    gidx = np.flatnonzero(good)
    tri = Vu[Fw[gidx]]
    bvh = BVH.build(tri) if len(gidx) else None
    if bvh is not None:
        _self_intersections(bvh, tri, Fw[gidx], gidx, centroids, diag, limits, out, stats)
    required = profile.min_wall_mm if profile is not None else limits.min_wall_mm
    stats["min_wall_required_mm"] = required
    if bvh is not None and consistent and outward:
        _thin_walls(bvh, tri, normals[gidx], areas[gidx], gidx, diag, required, profile, limits, out, stats)
    else:
        why = "the mesh is not closed and consistently oriented outward" if bvh is not None else "no sound faces"
        out.append(finding("check_skipped", f"wall thickness not measured: {why}"))

    if closed and limits.manifold3d_crosscheck:
        _manifold3d(Vu, Fw[~degenerate], out, stats)

    # ---- printer fit, units, colour
    _fit_checks(size, profile, out)
    _units_check(md, size, limits, out)
    _colour_checks(md, areas, Fo, centroids, profile, limits, out, stats)
    return out, stats


def _edge_checks(topo: Any, Vu: np.ndarray, Fw: np.ndarray, out: list[Finding], stats: dict[str, Any]) -> bool:
    """Watertight, edge-manifold, vertex-manifold, consistent winding; True if closed and manifold."""
    ec = topo.edge_faces
    mids = (Vu[topo.edges[:, 0]] + Vu[topo.edges[:, 1]]) / 2 if len(topo.edges) else np.zeros((0, 3))

    def faces_on(edge_ids: np.ndarray) -> np.ndarray:
        return np.flatnonzero(np.isin(topo.face_edges, edge_ids[:10]).any(axis=1))

    boundary = np.flatnonzero(ec == 1)
    nonman = np.flatnonzero(ec > 2)
    flipped = np.flatnonzero(topo.flipped_edges)
    stats["boundary_edges"] = len(boundary)
    stats["non_manifold_edges"] = len(nonman)
    stats["flipped_edges"] = len(flipped)
    if len(boundary):
        out.append(finding(
            "not_watertight",
            f"{len(boundary):,} open edges (used by one face only): the surface has holes, first near "
            f"{_fmt_pt(mids[boundary[0]])}; close them so the printer knows what is inside",
            where=_where(mids[boundary[0]], faces_on(boundary), count=len(boundary)),
        ))
    if len(nonman):
        out.append(finding(
            "non_manifold_edges",
            f"{len(nonman):,} edges are shared by more than two faces (up to {int(ec.max())}), first near "
            f"{_fmt_pt(mids[nonman[0]])}",
            where=_where(mids[nonman[0]], faces_on(nonman), count=len(nonman)),
        ))
    pinched = np.flatnonzero(topo.vertex_fans > 1)
    stats["non_manifold_vertices"] = len(pinched)
    if len(pinched):
        out.append(finding(
            "non_manifold_vertices",
            f"{len(pinched):,} vertices join separate fans of faces (pinched), first at {_fmt_pt(Vu[pinched[0]])}",
            where=_where(Vu[pinched[0]], count=len(pinched)),
        ))
    if len(flipped):
        out.append(finding(
            "inconsistent_orientation",
            f"{len(flipped):,} edges join faces wound in opposite directions (flipped faces), first near "
            f"{_fmt_pt(mids[flipped[0]])}; make the winding consistent",
            where=_where(mids[flipped[0]], faces_on(flipped), count=len(flipped)),
        ))
    return not len(boundary) and not len(nonman) and not len(pinched)


def _orientation_checks(topo: Any, shell_vol: np.ndarray, Vu: np.ndarray, Fw: np.ndarray,
                        centroids: np.ndarray, out: list[Finding]) -> bool:
    """Outward normals: positive volume overall; a negative shell must be a void inside a positive one."""
    total = float(shell_vol.sum())
    if total <= 0:
        out.append(finding(
            "inverted_normals",
            f"the closed mesh has {'negative' if total < 0 else 'zero'} volume ({total:.4g} mm3): its normals point "
            "inward; flip every face",
            where=_where(centroids[0], [0]),
        ))
        return False
    # bounding boxes of shells, to tell voids (inside a positive shell) from inside-out parts
    sh = topo.shell
    lo = np.full((topo.shells, 3), np.inf)
    hi = np.full((topo.shells, 3), -np.inf)
    np.minimum.at(lo, sh, centroids)
    np.maximum.at(hi, sh, centroids)
    neg = np.flatnonzero(shell_vol < 0)
    pos = np.flatnonzero(shell_vol > 0)
    stray = [int(s) for s in neg if not any((lo[p] <= lo[s]).all() and (hi[s] <= hi[p]).all() for p in pos)]
    if stray:
        f0 = int(np.flatnonzero(sh == stray[0])[0])
        out.append(finding(
            "inverted_normals",
            f"{len(stray)} shell(s) are inside out (negative volume, not a void inside another shell), "
            f"first near {_fmt_pt(centroids[f0])}",
            where=_where(centroids[f0], [f0], count=len(stray)),
        ))
        return False
    return True


def _shell_report(topo: Any, shell_vol: np.ndarray, centroids: np.ndarray, out: list[Finding]) -> None:
    if topo.shells > 1:
        counts = np.bincount(topo.shell)
        small = int(np.argmin(counts))
        f0 = int(np.flatnonzero(topo.shell == small)[0])
        out.append(finding(
            "multiple_shells",
            f"{topo.shells} separate shells; the smallest has {int(counts[small]):,} faces, near "
            f"{_fmt_pt(centroids[f0])} (stray pieces, or parts meant to print separately?)",
            where=_where(centroids[f0], [f0], count=topo.shells),
        ))


def _self_intersections(bvh: BVH, tri: np.ndarray, Fg: np.ndarray, gidx: np.ndarray, centroids: np.ndarray,
                        diag: float, limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    eps = 1e-9 * diag
    m = len(tri)
    # The budget scales with the mesh (a sound mesh visits ~45 node pairs per triangle), capped by the
    # limit, so a pile of overlapping triangles ends quickly with a sampled, "partial" answer.
    budget = min(limits.max_pair_tests, 100 * m + 1_000_000)

    nrm = cross3(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    exact = lambda a, b: pair_intersections(tri, Fg, nrm, a, b, eps)
    if m >= bvh_mod.FAST_FROM_TRIANGLES:
        # the same test pair by pair in numba: no temporaries per stage, and a flat bottom's millions of
        # coplanar neighbour pairs (sector and fold tests) cost microseconds each, not numpy passes
        from saucerfab.check.kernels import pair_intersections_fast

        nlen = np.sqrt(dot3(nrm, nrm))
        exact = lambda a, b: pair_intersections_fast(tri, Fg, nrm, nlen, a, b, eps)

    def narrow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        hit = exact(a, b)
        return np.stack([a[hit], b[hit]], axis=1)

    found: list[np.ndarray] = []
    workers = _workers()
    chunks = _rechunk(bvh.pair_chunks(tol=eps, budget=budget), _PAIR_CHUNK)
    if workers > 1 and m > 20_000:
        # numpy releases the GIL in its loops: the search (this thread) and the exact tests (the pool)
        # overlap, and a second core is used where there is one; a few chunks in flight bound memory
        from concurrent.futures import Future, ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=workers) as ex:
            pending: list[Future[np.ndarray]] = []
            for a, b in chunks:
                pending.append(ex.submit(narrow, a, b))
                if len(pending) > 2 * workers:
                    found.append(pending.pop(0).result())
            found += [f.result() for f in pending]
    else:
        found = [narrow(a, b) for a, b in chunks]
    complete = bvh.pairs_complete
    pairs = np.concatenate(found) if found else np.zeros((0, 2), dtype=np.int64)
    stats["self_intersecting_pairs"] = len(pairs)
    stats["self_intersection_check"] = "full" if complete else "partial"
    if not complete:
        out.append(finding("check_partial", "self-intersection search stopped at its work budget (Limits.max_pair_tests"
                                            f" = {limits.max_pair_tests:,}, scaled to the mesh): parts of the mesh "
                                            "crowd together so densely that not all pairs were compared"))
    if len(pairs):
        fp = np.sort(gidx[pairs], axis=1)  # file face indices, lower first
        faces = np.unique(fp.ravel())
        first = np.lexsort((fp[:, 1], fp[:, 0]))[0]  # the first in file order, whatever order the search took
        f0, f1 = int(fp[first, 0]), int(fp[first, 1])
        out.append(finding(
            "self_intersections",
            f"{len(pairs):,} pairs of faces cross each other ({len(faces):,} faces), first near "
            f"{_fmt_pt(centroids[f0])}: faces {f0} and {f1}; union or repair the surfaces",
            where=_where(centroids[f0], [f0, f1], count=len(pairs)),
        ))


def _thin_walls(bvh: BVH, tri: np.ndarray, normals: np.ndarray, areas: np.ndarray, gidx: np.ndarray, diag: float,
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
    t, hit, complete = bvh.first_hits(tri, pts, dirs, f, t_min=1e-7 * diag, budget=budget, workers=_workers())
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
        relief = _beside_thick(bvh, tri, pts[cand], dirs[cand], t[cand], required, budget, diag,
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
    stats["thin_wall_fraction"] = round(float(thin.mean()), 5)
    if thin.any():
        sev = "warning"
        if (
            profile is not None
            and profile.thin_policy == "refuse"
            and float(thin.mean()) >= limits.thin_wall_error_fraction
        ):
            sev = "error"
        who = f"{profile.name}'s minimum" if profile is not None else "the minimum asked for"
        fi = gidx[f[ok][thin]]
        out.append(finding(
            "thin_walls",
            f"walls under {required:g} mm ({who}): {int(thin.sum())} of {int(ok.sum())} sampled points "
            f"({100 * thin.mean():.1f}% of the surface); thinnest {float(tt[i]):.3f} mm at {_fmt_pt(where_pt)}",
            severity=sev,  # type: ignore[arg-type]
            where=_where(where_pt, fi, count=int(thin.sum())),
        ))


#: in-plane directions probed around a thin spot for thick material beside it
RELIEF_DIRECTIONS = 8


def _beside_thick(bvh: BVH, tri: np.ndarray, pts: np.ndarray, dirs: np.ndarray, t: np.ndarray,
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
    own rule is the minimum feature, which the export holds: saucerfab.relief).
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
    exit_t, _, _ = bvh.first_hits(tri, mid, across, none, t_min=t_min, budget=share, workers=_workers())
    inside = exit_t > required
    probe = mid + required * across
    up, _, _ = bvh.first_hits(tri, probe, ray, none, t_min=t_min, budget=share, workers=_workers())
    down, _, _ = bvh.first_hits(tri, probe, -ray, none, t_min=t_min, budget=share, workers=_workers())
    thick = inside & np.isfinite(up) & np.isfinite(down) & (up + down >= required)
    return thick.reshape(k, probes).any(axis=1)


def _manifold3d(Vu: np.ndarray, F: np.ndarray, out: list[Finding], stats: dict[str, Any]) -> None:
    """manifold3d's verdict on manifoldness (not on self-intersection: it does not test that)."""
    try:
        import manifold3d
    except ImportError:  # optional: the topology checks above stand on their own
        return
    try:
        mesh = manifold3d.Mesh(vert_properties=np.ascontiguousarray(Vu, dtype=np.float32),
                               tri_verts=np.ascontiguousarray(F, dtype=np.uint32))
        status = manifold3d.Manifold(mesh).status()
    except (ValueError, TypeError, RuntimeError) as exc:
        stats["manifold3d_status"] = f"failed: {exc}"
        return
    name = getattr(status, "name", str(status)).split(".")[-1]
    stats["manifold3d_status"] = name
    if name != "NoError":
        out.append(finding("not_manifold", f"manifold3d rejects the mesh: {name}"))


def _rechunk(chunks: Any, size: int) -> Any:
    """Pairs from ``chunks`` regrouped into arrays of ``size`` (the last one smaller)."""
    buf_a: list[np.ndarray] = []
    buf_b: list[np.ndarray] = []
    n = 0
    for a, b in chunks:
        buf_a.append(a)
        buf_b.append(b)
        n += len(a)
        while n >= size:
            a, b = np.concatenate(buf_a), np.concatenate(buf_b)
            yield a[:size], b[:size]
            buf_a, buf_b, n = [a[size:]], [b[size:]], len(a) - size
    if n:
        yield np.concatenate(buf_a), np.concatenate(buf_b)


def _printer_file_checks(md: MeshData, profile: PrinterProfile | None, m: int, file_bytes: int,
                         out: list[Finding]) -> None:
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


def _fit_checks(size: np.ndarray, profile: PrinterProfile | None, out: list[Finding]) -> None:
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


def _units_check(md: MeshData, size: np.ndarray, limits: Limits, out: list[Finding]) -> None:
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


def _texture_status(md: MeshData, out: list[Finding]) -> None:
    for t in md.textures:
        if t.status != "ok":
            out.append(finding(_TEXTURE_CODES.get(t.status, "texture_unreadable"), t.message, where={"entry": t.name}))


def _colour_checks(md: MeshData, areas: np.ndarray, Fo: np.ndarray, centroids: np.ndarray,
                   profile: PrinterProfile | None, limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    _texture_status(md, out)
    if profile is not None and profile.max_texture_px:
        for t in md.textures:
            if t.status == "ok" and max(t.width or 0, t.height or 0) > profile.max_texture_px:
                out.append(finding(
                    "texture_too_large",
                    f"texture {t.name!r} is {t.width} x {t.height} px, over {profile.name}'s limit of "
                    f"{profile.max_texture_px} px a side; downscale it",
                    where={"entry": t.name},
                ))
    m = len(Fo)
    total = float(areas.sum())
    coloured = np.zeros(m, dtype=bool) if md.face_colour is None else md.face_colour.copy()
    if md.face_texture is not None and md.corner_uv is not None:
        textured = md.face_texture >= 0
        coloured |= textured
        uv = md.corner_uv[textured]
        tol = limits.uv_tolerance
        bad = ~np.isfinite(uv).all(axis=(1, 2)) | ((uv < -tol) | (uv > 1 + tol)).any(axis=(1, 2))
        tidx = np.flatnonzero(textured)
        stats["uv_outside_faces"] = int(bad.sum())
        if bad.any():
            fb = tidx[bad]
            finite_uv = uv[np.isfinite(uv).all(axis=(1, 2))]
            rng = (f" (u, v range {finite_uv[..., 0].min():.3g}..{finite_uv[..., 0].max():.3g}, "
                   f"{finite_uv[..., 1].min():.3g}..{finite_uv[..., 1].max():.3g})") if len(finite_uv) else ""
            out.append(finding(
                "uv_out_of_range",
                f"{len(fb):,} textured faces have texture coordinates outside [0, 1]{rng}: printers clamp or "
                f"wrap them differently, so the colour would be wrong; first near {_fmt_pt(centroids[fb[0]])}",
                where=_where(centroids[fb[0]], fb, count=len(fb)),
            ))
        _texture_dpi(md, areas, textured, profile, limits, out, stats)
    if total > 0:
        frac = float(areas[coloured].sum()) / total
    else:  # no face has area (all degenerate, reported above): the share of faces instead
        frac = float(coloured.mean()) if m else 0.0
    stats["coloured_fraction"] = round(frac, 5)
    if not md.colour_kinds:
        if md.format in _COLOUR_CAPABLE or profile is not None:
            out.append(finding("no_colour", f"the {md.format.upper()} carries no colour (no texture, vertex or "
                                            "material colours): it prints in the printer's default colour"))
    elif frac < 0.999 and (~coloured).any():
        un = np.flatnonzero(~coloured)
        out.append(finding(
            "partly_coloured",
            f"only {100 * frac:.1f}% of the surface carries colour; the rest prints in the default colour, "
            f"first uncoloured face near {_fmt_pt(centroids[un[0]])}",
            where=_where(centroids[un[0]], un, count=len(un)),
        ))


def _texture_dpi(md: MeshData, areas: np.ndarray, textured: np.ndarray, profile: PrinterProfile | None,
                 limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    """Texture resolution on the model: texels per inch, area-weighted median over textured faces."""
    assert md.corner_uv is not None and md.face_texture is not None
    ok_tex = np.array([t.status == "ok" and t.width and t.height for t in md.textures] + [False], dtype=bool)
    wh = np.array([[t.width or 0, t.height or 0] for t in md.textures] + [[0, 0]], dtype=np.float64)
    ti = md.face_texture
    sel = textured & ok_tex[ti] & (areas > 0)
    uv = md.corner_uv[sel]
    fin = np.isfinite(uv).all(axis=(1, 2))
    if not fin.any():
        return
    uv = uv[fin]
    idx = np.flatnonzero(sel)[fin]
    px = uv * wh[ti[idx]][:, None, :]
    e1, e2 = px[:, 1] - px[:, 0], px[:, 2] - px[:, 0]
    texel_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) / 2
    a = areas[idx]
    dpi = 25.4 * np.sqrt(texel_area / a)

    def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
        order = np.argsort(values)
        cum = np.cumsum(weights[order])
        return float(values[order][min(np.searchsorted(cum, q * cum[-1]), len(order) - 1)])

    # Leave out faces mapped at a deliberately tiny scale (plain walls an
    # exporter parks on a small patch): they need no resolution. The header
    # is all the checker decodes, so density is the only clue it has.
    best = weighted_quantile(dpi, a, 0.95)
    detailed = dpi >= limits.solid_colour_density * best
    med = weighted_quantile(dpi[detailed], a[detailed], 0.5)
    stats["texture_detailed_fraction"] = round(float(a[detailed].sum() / max(a.sum(), 1e-300)), 4)
    stats["texture_dpi"] = round(med, 1)
    if profile is not None:
        want = limits.texture_dpi_fraction * profile.dpi
        if med < want:
            out.append(finding(
                "texture_low_dpi",
                f"the texture gives {med:.0f} dpi on the model (area-weighted median over the detailed "
                f"faces), under "
                f"{limits.texture_dpi_fraction:g} x {profile.name}'s {profile.dpi:g} dpi; colours will look soft",
            ))
