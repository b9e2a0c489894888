"""The checks: :func:`run_checks` runs them all on what a reader produced.

It takes a :class:`~saucerfab.check.meshdata.MeshData` and returns findings
and stats. The geometry and topology checks (finite coordinates, degenerate
and duplicate faces, open and non-manifold edges, pinched vertices, winding,
volume and shells) live here; the others have their own modules:
self-intersections (:mod:`.intersections`), thin walls (:mod:`.walls`),
the printer profile and units (:mod:`.fit`) and colour (:mod:`.colour`).
Checks that need a sound mesh are gated: with NaN coordinates no geometry
is measured; thin walls are only measured on a closed, consistently
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

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.check.bvh import BVH
from saucerfab.check.colour import colour_checks, texture_status
from saucerfab.check.fit import fit_checks, printer_file_checks, units_check
from saucerfab.check.intersections import self_intersections
from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshData
from saucerfab.check.places import fmt_pt, pt, where
from saucerfab.check.report import Finding, finding
from saucerfab.check.topology import face_geometry, topology, weld
from saucerfab.check.walls import thin_walls

if TYPE_CHECKING:
    from saucerfab.model.profiles import PrinterProfile

#: coordinates beyond this many millimetres count as unusable (see run_checks)
_ABSURD_MM = 1e9


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
    printer_file_checks(md, profile, m, file_bytes, out)

    # beyond 1e9 mm (1000 km) products of coordinates lose all precision or overflow: as unusable as NaN
    finite = np.isfinite(V).all(axis=1) & (np.abs(V) <= _ABSURD_MM).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        out.append(finding(
            "non_finite",
            f"{len(bad):,} vertices have NaN, infinite or absurd (beyond 1e9 mm) coordinates (first: vertex "
            f"{int(bad[0])}: {V[bad[0]].tolist()}); fix the exporter - no printer can place them",
            where=where(vertices=bad, count=len(bad)),
        ))
        out.append(finding("check_skipped", "geometry, topology, thin walls and colour area were not measured: "
                                            "coordinates are not finite"))
        texture_status(md, out)
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
        bbox_mm={"min": pt(lo), "max": pt(hi), "size": pt(size)},
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
            where=where(centroids[idx[0]], idx, count=len(idx)),
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
            f"near {fmt_pt(centroids[e0])})",
            where=where(centroids[e0], [o0, *extra[:9].tolist()], count=len(extra)),
        ))

    unref = int((~used).sum())
    stats["unreferenced_vertices"] = unref
    if unref:
        out.append(finding("unreferenced_vertices", f"{unref:,} vertices are used by no face (harmless, but bloat)",
                           where=where(vertices=np.flatnonzero(~used), count=unref)))

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
        self_intersections(bvh, tri, Fw[gidx], gidx, centroids, diag, limits, out, stats)
    required = profile.min_wall_mm if profile is not None else limits.min_wall_mm
    stats["min_wall_required_mm"] = required
    if bvh is not None and consistent and outward:
        thin_walls(bvh, tri, normals[gidx], areas[gidx], gidx, diag, required, profile, limits, out, stats)
    else:
        why = "the mesh is not closed and consistently oriented outward" if bvh is not None else "no sound faces"
        out.append(finding("check_skipped", f"wall thickness not measured: {why}"))

    if closed and limits.manifold3d_crosscheck:
        _manifold3d(Vu, Fw[~degenerate], out, stats)

    # ---- printer fit, units, colour
    fit_checks(size, profile, out)
    units_check(md, size, limits, out)
    colour_checks(md, areas, Fo, centroids, profile, limits, out, stats)
    return out, stats


def _edge_checks(topo: Any, Vu: np.ndarray, Fw: np.ndarray, out: list[Finding], stats: dict[str, Any]) -> bool:
    """Watertight, edge-manifold, vertex-manifold, consistent winding; True if closed and manifold."""
    ec = topo.edge_faces
    mids = (Vu[topo.edges[:, 0]] + Vu[topo.edges[:, 1]]) / 2 if len(topo.edges) else np.zeros((0, 3))

    def faces_on(edge_ids: np.ndarray) -> np.ndarray:
        return np.flatnonzero(np.isin(topo.face_edges, edge_ids[:10]).any(axis=1))

    boundary = np.flatnonzero(ec == 1)
    nonman = np.flatnonzero(ec > 2)
    pinched = np.flatnonzero(topo.vertex_fans > 1)
    flipped = np.flatnonzero(topo.flipped_edges)
    stats["boundary_edges"] = len(boundary)
    stats["non_manifold_edges"] = len(nonman)
    stats["flipped_edges"] = len(flipped)
    stats["non_manifold_vertices"] = len(pinched)
    # (code, edge or vertex ids, their points, whether to list the faces on them, the message given the first
    # one's place): a message is written only for a problem that is there
    problems: list[tuple[str, np.ndarray, np.ndarray, bool, Callable[[str], str]]] = [
        ("not_watertight", boundary, mids, True,
         lambda near: f"{len(boundary):,} open edges (used by one face only): the surface has holes, first near "
                      f"{near}; close them so the printer knows what is inside"),
        ("non_manifold_edges", nonman, mids, True,
         lambda near: f"{len(nonman):,} edges are shared by more than two faces (up to {int(ec.max())}), first near "
                      f"{near}"),
        ("non_manifold_vertices", pinched, Vu, False,
         lambda near: f"{len(pinched):,} vertices join separate fans of faces (pinched), first at {near}"),
        ("inconsistent_orientation", flipped, mids, True,
         lambda near: f"{len(flipped):,} edges join faces wound in opposite directions (flipped faces), first near "
                      f"{near}; make the winding consistent"),
    ]
    for code, ids, at, on_faces, message in problems:
        if len(ids):
            out.append(finding(code, message(fmt_pt(at[ids[0]])),
                               where=where(at[ids[0]], faces_on(ids) if on_faces else None, count=len(ids))))
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
            where=where(centroids[0], [0]),
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
            f"first near {fmt_pt(centroids[f0])}",
            where=where(centroids[f0], [f0], count=len(stray)),
        ))
        return False
    return True


def _shell_report(topo: Any, shell_vol: np.ndarray, centroids: np.ndarray, out: list[Finding]) -> None:
    """More than one shell: a warning naming the smallest."""
    if topo.shells > 1:
        counts = np.bincount(topo.shell)
        small = int(np.argmin(counts))
        f0 = int(np.flatnonzero(topo.shell == small)[0])
        out.append(finding(
            "multiple_shells",
            f"{topo.shells} separate shells; the smallest has {int(counts[small]):,} faces, near "
            f"{fmt_pt(centroids[f0])} (stray pieces, or parts meant to print separately?)",
            where=where(centroids[f0], [f0], count=topo.shells),
        ))


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
