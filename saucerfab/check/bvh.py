"""A numpy bounding-volume hierarchy: inward rays (wall thickness) and triangle-pair overlap.

The tree is a complete binary tree over triangles sorted by the Morton code
of their box centres, one triangle per leaf, so every level is one array
and traversal is breadth-first over whole frontiers at once (numpy has no
cheap per-ray recursion). Work is bounded by caller-given budgets: a
traversal that would exceed its budget stops and says so, which is how a
hostile mesh (every triangle in one spot) gives a partial result quickly
instead of a quadratic run.

Kept beside it: :func:`segment_hits_triangle` and :func:`tri_tri_intersect`,
the vectorised narrow-phase predicates, with slow per-pair references in
the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _part1by2(x: np.ndarray) -> np.ndarray:
    x = x.astype(np.uint64) & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


@dataclass
class BVH:
    """Boxes per level: ``lo[d]``, ``hi[d]`` are (3, 2**d), axis-major; leaves (level D) hold ``leaf_tri``."""

    lo: list[np.ndarray]
    hi: list[np.ndarray]
    leaf_tri: np.ndarray  # (2**D,) triangle index per leaf, -1 for padding
    depth: int

    @classmethod
    def build(cls, tri: np.ndarray) -> BVH:
        """Build over triangles ``tri`` (m, 3, 3)."""
        m = len(tri)
        tlo = tri.min(axis=1)
        thi = tri.max(axis=1)
        c = (tlo + thi) / 2
        cmin = c.min(axis=0) if m else np.zeros(3)
        span = (c.max(axis=0) - cmin) if m else np.ones(3)
        span[span <= 0] = 1.0
        q = np.clip(((c - cmin) / span * 1023.0), 0, 1023).astype(np.uint64)
        code = _part1by2(q[:, 0]) | (_part1by2(q[:, 1]) << np.uint64(1)) | (_part1by2(q[:, 2]) << np.uint64(2))
        order = np.argsort(code, kind="stable")
        depth = max(0, int(np.ceil(np.log2(max(m, 1)))))
        P = 1 << depth
        leaf_tri = np.full(P, -1, dtype=np.int64)
        leaf_tri[:m] = order
        lo = np.full((P, 3), np.inf)
        hi = np.full((P, 3), -np.inf)
        lo[:m] = tlo[order]
        hi[:m] = thi[order]
        lo, hi = np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T)  # axis-major (3, P)
        los = [lo]
        his = [hi]
        for _ in range(depth):
            lo = np.minimum(lo[:, 0::2], lo[:, 1::2])
            hi = np.maximum(hi[:, 0::2], hi[:, 1::2])
            los.append(lo)
            his.append(hi)
        return cls(lo=los[::-1], hi=his[::-1], leaf_tri=leaf_tri, depth=depth)

    # ---- rays -------------------------------------------------------------
    def first_hits(
        self,
        tri: np.ndarray,
        origins: np.ndarray,
        dirs: np.ndarray,
        exclude: np.ndarray,
        t_min: float,
        budget: int,
        t_max: np.ndarray | None = None,
        chunk: int = 512,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Nearest hit along each ray in (``t_min``, ``t_max[r]``], skipping triangle ``exclude[r]``.

        Returns (t (R,) with inf for no hit, triangle (R,) with -1, complete):
        ``complete`` is False when ``budget`` (box plus triangle tests) ran out;
        rays not reached keep inf.
        """
        R = len(origins)
        if t_max is None:
            t_max = np.full(R, np.inf)
        best = np.full(R, np.inf)
        hit = np.full(R, -1, dtype=np.int64)
        with np.errstate(divide="ignore"):
            inv = 1.0 / dirs
        used = 0
        for s in range(0, R, chunk):
            rays = np.arange(s, min(R, s + chunk))
            node = np.zeros(len(rays), dtype=np.int64)
            for d in range(1, self.depth + 1):
                rays = np.repeat(rays, 2)
                node = (np.repeat(node, 2) * 2) + np.tile([0, 1], len(node))
                used += len(rays)
                if used > budget:
                    return best, hit, False
                lo = self.lo[d]
                hi = self.hi[d]
                tnear = np.full(len(rays), -np.inf)
                tfar = t_max[rays].copy()
                with np.errstate(invalid="ignore"):
                    for ax in range(3):
                        o = origins[rays, ax]
                        iv = inv[rays, ax]
                        t1 = (lo[ax, node] - o) * iv
                        t2 = (hi[ax, node] - o) * iv
                        # NaN (0 * inf: a ray in a slab's plane) neither accepts nor rejects: fmin/fmax skip it
                        tnear = np.fmax(tnear, np.fmin(t1, t2))
                        tfar = np.fmin(tfar, np.fmax(t1, t2))
                keep = (tnear <= tfar) & (tfar >= t_min) & np.isfinite(lo[0, node])
                rays = rays[keep]
                node = node[keep]
                if not len(rays):
                    break
            if not len(rays):
                continue
            t_idx = self.leaf_tri[node]
            keep = (t_idx >= 0) & (t_idx != exclude[rays])
            rays, t_idx = rays[keep], t_idx[keep]
            used += len(rays)
            if used > budget:
                return best, hit, False
            t = ray_triangle(origins[rays], dirs[rays], tri[t_idx])
            ok = (t > t_min) & (t <= t_max[rays])
            rays, t, t_idx = rays[ok], t[ok], t_idx[ok]
            if len(rays):
                order = np.lexsort((t, rays))
                rays, t, t_idx = rays[order], t[order], t_idx[order]
                first = np.ones(len(rays), dtype=bool)
                first[1:] = rays[1:] != rays[:-1]
                best[rays[first]] = t[first]
                hit[rays[first]] = t_idx[first]
        return best, hit, True

    # ---- pairs ------------------------------------------------------------
    def overlapping_pairs(self, tol: float, budget: int) -> tuple[np.ndarray, np.ndarray, bool]:
        """Triangle pairs (i < j by leaf) whose boxes overlap (padded by ``tol``).

        Returns (i, j, complete); ``complete`` is False when the number of
        node pairs visited exceeded ``budget`` (then no pairs are returned
        from the unfinished part).
        """
        a = np.zeros(1, dtype=np.int64)
        b = np.zeros(1, dtype=np.int64)
        used = 0
        for d in range(1, self.depth + 1):
            same = a == b
            # children of (a, a): (2a,2a), (2a,2a+1), (2a+1,2a+1); of (a, b), a<b: all four
            aa, bb = a[same], b[~same]
            a2 = np.concatenate([2 * aa, 2 * aa, 2 * aa + 1, np.repeat(2 * a[~same], 2), np.repeat(2 * a[~same] + 1, 2)])
            b2 = np.concatenate([2 * aa, 2 * aa + 1, 2 * aa + 1, np.tile([0, 1], len(bb)) + np.repeat(2 * bb, 2),
                                 np.tile([0, 1], len(bb)) + np.repeat(2 * bb, 2)])
            used += len(a2)
            if used > budget:
                return np.zeros(0, np.int64), np.zeros(0, np.int64), False
            lo, hi = self.lo[d], self.hi[d]
            ov = np.ones(len(a2), dtype=bool)
            for ax in range(3):
                la, ha, lb, hb = lo[ax, a2], hi[ax, a2], lo[ax, b2], hi[ax, b2]
                ov &= (la <= hb + tol) & (lb <= ha + tol)
            a, b = a2[ov], b2[ov]
            if not len(a):
                break
        keep = a != b
        ti, tj = self.leaf_tri[a[keep]], self.leaf_tri[b[keep]]
        ok = (ti >= 0) & (tj >= 0)
        return ti[ok], tj[ok], True


def ray_triangle(o: np.ndarray, d: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Moller-Trumbore, vectorised: distance along each ray to its triangle, NaN for a miss."""
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        eps = 1e-12
        hit = (np.abs(det) > 1e-300) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps)
        return np.where(hit, t, np.nan)


def segment_hits_triangle(p: np.ndarray, q: np.ndarray, tri: np.ndarray, eps_d: float) -> np.ndarray:
    """Segments p-q that properly cross the plane of ``tri`` at a point inside it (boundary included).

    Endpoints within ``eps_d`` of the plane do not count as crossing: a
    shared vertex lies in both triangles' planes, and touching is not a
    crossing.
    """
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(v1 - v0, v2 - v0)
    nn = np.linalg.norm(n, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = n / nn[:, None]
        dp = np.einsum("ij,ij->i", p - v0, nu)
        dq = np.einsum("ij,ij->i", q - v0, nu)
        cross = ((dp > eps_d) & (dq < -eps_d)) | ((dp < -eps_d) & (dq > eps_d))
        x = p + (q - p) * (dp / (dp - dq))[:, None]
        nn2 = nn * nn
        b0 = np.einsum("ij,ij->i", np.cross(v2 - v1, x - v1), n) / nn2
        b1 = np.einsum("ij,ij->i", np.cross(v0 - v2, x - v2), n) / nn2
        b2 = np.einsum("ij,ij->i", np.cross(v1 - v0, x - v0), n) / nn2
    inside = (b0 >= -1e-9) & (b1 >= -1e-9) & (b2 >= -1e-9)
    return cross & inside & (nn > 0)


def _coplanar_overlap(A: np.ndarray, B: np.ndarray, nrm: np.ndarray, eps: float) -> np.ndarray:
    """Coplanar triangle pairs whose interiors overlap (projected to the dominant plane).

    Overlap = some pair of edges properly crossing, or a vertex of one
    strictly inside the other; shared vertices and touching edges do not count.
    """
    ax = np.argmax(np.abs(nrm), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[ax]
    rows = np.arange(len(A))[:, None]
    a2 = np.stack([A[rows, k, keep] for k in range(3)], axis=1)  # (n, 3, 2)
    b2 = np.stack([B[rows, k, keep] for k in range(3)], axis=1)

    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    scale = eps * eps
    out = np.zeros(len(A), dtype=bool)
    for i in range(3):
        p, q = a2[:, i], a2[:, (i + 1) % 3]
        for j in range(3):
            r, s = b2[:, j], b2[:, (j + 1) % 3]
            o1, o2 = orient(p, q, r), orient(p, q, s)
            o3, o4 = orient(r, s, p), orient(r, s, q)
            out |= (((o1 > scale) & (o2 < -scale)) | ((o1 < -scale) & (o2 > scale))) & (
                ((o3 > scale) & (o4 < -scale)) | ((o3 < -scale) & (o4 > scale)))

    def strictly_inside(t: np.ndarray, pt: np.ndarray) -> np.ndarray:
        s = np.sign(orient(t[:, 0], t[:, 1], t[:, 2]))
        w = [orient(t[:, k], t[:, (k + 1) % 3], pt) * s for k in range(3)]
        return (w[0] > scale) & (w[1] > scale) & (w[2] > scale)

    for k in range(3):
        out |= strictly_inside(b2, a2[:, k]) | strictly_inside(a2, b2[:, k])
    return out


def tri_tri_intersect(A: np.ndarray, B: np.ndarray, shared: np.ndarray, eps_d: float) -> np.ndarray:
    """Which triangle pairs (A[k], B[k]) cross each other.

    ``shared`` is the number of vertex indices the two share (0, 1 or 2);
    sharing a vertex or an edge is not an intersection, crossing elsewhere
    is. Non-coplanar pairs intersect iff an edge of one crosses the other
    (the ends of the intersection segment lie on edges); coplanar pairs
    are tested in 2D; coplanar pairs sharing an edge intersect when they
    fold onto the same side of it.
    """
    n = len(A)
    out = np.zeros(n, dtype=bool)
    if n == 0:
        return out
    nA = np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    nB = np.cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        uA = nA / np.linalg.norm(nA, axis=1)[:, None]
        uB = nB / np.linalg.norm(nB, axis=1)[:, None]
    dB = np.einsum("ikj,ij->ik", B - A[:, :1], uA)  # distances of B's corners to A's plane
    dA = np.einsum("ikj,ij->ik", A - B[:, :1], uB)
    # one triangle wholly on one side of the other's plane (corners within eps_d of the plane,
    # like a shared vertex, are neutral): at most touching, never crossing
    sepB = ((dB >= -eps_d).all(axis=1) & (dB > eps_d).any(axis=1)) | ((dB <= eps_d).all(axis=1) & (dB < -eps_d).any(axis=1))
    sepA = ((dA >= -eps_d).all(axis=1) & (dA > eps_d).any(axis=1)) | ((dA <= eps_d).all(axis=1) & (dA < -eps_d).any(axis=1))
    coplanar = (np.abs(dB) <= eps_d).all(axis=1)
    live = ~(sepA | sepB) & ~coplanar & (shared < 2)
    idx = np.flatnonzero(live)
    if len(idx):
        a, b = A[idx], B[idx]
        hitk = np.zeros(len(idx), dtype=bool)
        for k in range(3):
            hitk |= segment_hits_triangle(a[:, k], a[:, (k + 1) % 3], b, eps_d)
            hitk |= segment_hits_triangle(b[:, k], b[:, (k + 1) % 3], a, eps_d)
        out[idx] = hitk
    cop = np.flatnonzero(coplanar & (shared < 2))
    if len(cop):
        out[cop] = _coplanar_overlap(A[cop], B[cop], nA[cop], eps_d)
    fold = np.flatnonzero(coplanar & (shared == 2))
    if len(fold):
        out[fold] = _folded(A[fold], B[fold], nA[fold], eps_d)
    return out


def _folded(A: np.ndarray, B: np.ndarray, nA: np.ndarray, eps: float) -> np.ndarray:
    """Coplanar pairs sharing an edge whose third corners lie on the same side of it (a fold)."""
    # find the shared edge by position: corners of B equal to corners of A
    eq = (np.abs(A[:, :, None, :] - B[:, None, :, :]).max(axis=3) <= eps)  # (n, 3, 3)
    inA = eq.any(axis=2)
    inB = eq.any(axis=1)
    ok = (inA.sum(axis=1) == 2) & (inB.sum(axis=1) == 2)
    rows = np.arange(len(A))
    a_lone = A[rows, np.argmin(inA, axis=1)]
    b_lone = B[rows, np.argmin(inB, axis=1)]
    shared_idx = np.argsort(inA, axis=1)[:, 1:]  # the two shared corners of A
    s = A[rows, shared_idx[:, 0]]
    t = A[rows, shared_idx[:, 1]]
    side_a = np.einsum("ij,ij->i", np.cross(t - s, a_lone - s), nA)
    side_b = np.einsum("ij,ij->i", np.cross(t - s, b_lone - s), nA)
    nn = np.linalg.norm(nA, axis=1)
    tol = eps * nn
    return ok & (((side_a > tol) & (side_b > tol)) | ((side_a < -tol) & (side_b < -tol)))
