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

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from saucerfab.check.jit import have_numba

#: meshes with at least this many triangles use the numba kernels of :mod:`saucerfab.check.kernels`
#: (importing numba costs ~0.7 s of start-up: below this, numpy is done sooner)
FAST_FROM_TRIANGLES = 200_000


def query_workers() -> int:
    """Threads for the numpy-heavy queries (rays, pair tests): the cores this process may use, at most 4."""
    from saucerfab.files.machine import usable_cores

    return min(4, usable_cores())


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross is ~8x slower for this shape)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (..., 3) arrays."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


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
    pairs_complete: bool = field(default=True, compare=False)
    #: all levels in heap order, (3, 2**(D+1) - 1) float32: ``lo[d]`` is columns 2**d - 1 ... 2**(d+1) - 2
    #: (the levels above are views of these; the numba kernels take the flat form)
    flat_lo: np.ndarray | None = field(default=None, compare=False, repr=False)
    flat_hi: np.ndarray | None = field(default=None, compare=False, repr=False)

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
        # axis-major (3, P) float32, rounded outward: half the memory traffic of float64 in the
        # traversals, and a box may only grow, so no overlap or hit is lost
        lo32 = lo.T.astype(np.float32)
        hi32 = hi.T.astype(np.float32)
        with np.errstate(invalid="ignore", over="ignore"):
            lo = np.where(lo32 > lo.T, np.nextafter(lo32, np.float32(-np.inf)), lo32)
            hi = np.where(hi32 < hi.T, np.nextafter(hi32, np.float32(np.inf)), hi32)
        flat_lo = np.empty((3, 2 * P - 1), dtype=np.float32)
        flat_hi = np.empty((3, 2 * P - 1), dtype=np.float32)
        los = [flat_lo[:, (1 << d) - 1:(2 << d) - 1] for d in range(depth + 1)]
        his = [flat_hi[:, (1 << d) - 1:(2 << d) - 1] for d in range(depth + 1)]
        los[depth][...] = lo
        his[depth][...] = hi
        for d in range(depth - 1, -1, -1):
            np.minimum(los[d + 1][:, 0::2], los[d + 1][:, 1::2], out=los[d])
            np.maximum(his[d + 1][:, 0::2], his[d + 1][:, 1::2], out=his[d])
        return cls(lo=los, hi=his, leaf_tri=leaf_tri, depth=depth, flat_lo=flat_lo, flat_hi=flat_hi)

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
        workers: int = 1,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Nearest hit along each ray in (``t_min``, ``t_max[r]``], skipping triangle ``exclude[r]``.

        Returns (t (R,) with inf for no hit, triangle (R,) with -1, complete):
        ``complete`` is False when ``budget`` (box plus triangle tests) ran
        out; rays not reached keep inf. Rays go in chunks, in ``workers``
        threads, each chunk with its share of the budget.
        """
        R = len(origins)
        if t_max is None:
            t_max = np.full(R, np.inf)
        best = np.full(R, np.inf)
        hit = np.full(R, -1, dtype=np.int64)
        with np.errstate(divide="ignore"):
            inv = 1.0 / dirs
        starts = list(range(0, R, chunk))
        share = budget // max(1, len(starts))

        def run(s: int) -> bool:
            rays = np.arange(s, min(R, s + chunk))
            node = np.zeros(len(rays), dtype=np.int64)
            used = 0
            for d in range(1, self.depth + 1):
                rays = np.repeat(rays, 2)
                node = (np.repeat(node, 2) * 2) + np.tile([0, 1], len(node))
                used += len(rays)
                if used > share:
                    return False
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
                    return True
            t_idx = self.leaf_tri[node]
            keep = (t_idx >= 0) & (t_idx != exclude[rays])
            rays, t_idx = rays[keep], t_idx[keep]
            if used + len(rays) > share:
                return False
            t = ray_triangle(origins[rays], dirs[rays], tri[t_idx])
            ok = (t > t_min) & (t <= t_max[rays])
            rays, t, t_idx = rays[ok], t[ok], t_idx[ok]
            if len(rays):
                order = np.lexsort((t, rays))
                rays, t, t_idx = rays[order], t[order], t_idx[order]
                first = np.ones(len(rays), dtype=bool)
                first[1:] = rays[1:] != rays[:-1]
                best[rays[first]] = t[first]  # chunks own disjoint rays: no two threads write one entry
                hit[rays[first]] = t_idx[first]
            return True

        if workers > 1 and len(starts) > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(max_workers=workers) as ex:
                done = list(ex.map(run, starts))
        else:
            done = [run(s) for s in starts]
        return best, hit, all(done)

    # ---- pairs ------------------------------------------------------------
    def pair_chunks(self, tol: float, budget: int, chunk: int = 1 << 20) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Triangle pairs (i, j) whose boxes overlap (padded by ``tol``), in chunks of at most ~``chunk``.

        The numba search (:func:`saucerfab.check.kernels.pair_search`) for a
        large tree, :meth:`pair_chunks_numpy` below it: the same pairs (in
        another order) and the same budget rule.
        """
        if int((self.leaf_tri >= 0).sum()) < FAST_FROM_TRIANGLES or self.flat_lo is None or not have_numba():
            yield from self.pair_chunks_numpy(tol, budget, chunk)
            return
        from saucerfab.check.kernels import pair_search

        self.pairs_complete = True
        stack = np.zeros((4 * (self.depth + 2), 3), dtype=np.int64)  # a DFS leaves at most 3 siblings per level
        state = np.array([1, 0, 0, 12345], dtype=np.int64)  # the root pair (0, 0, level 0) is on the stack
        while state[0] > 0:
            out_i = np.empty(chunk, dtype=np.int64)
            out_j = np.empty(chunk, dtype=np.int64)
            k = pair_search(self.flat_lo, self.flat_hi, self.depth, self.leaf_tri, np.float32(tol), stack, state,
                            out_i, out_j, budget)
            if k:
                yield out_i[:k], out_j[:k]
        self.pairs_complete = not state[2]

    def pair_chunks_numpy(self, tol: float, budget: int,
                          chunk: int = 1 << 20) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """:meth:`pair_chunks` in numpy: the reference, and the quicker start for small meshes.

        Depth-first over slices of the frontier, so memory stays at a few
        chunks whatever the mesh size, and the caller can test each chunk
        while the search goes on. Work stays near ``budget`` node-pair
        tests: past it, each expansion goes on with a fixed random sixteenth
        of its children, so a pile of overlapping triangles still yields some
        of its crossings in bounded time. ``self.pairs_complete`` tells
        afterwards whether the search was exhaustive.
        """
        self.pairs_complete = True
        rng = np.random.default_rng(0)
        same_kids = (np.array([0, 0, 1]), np.array([0, 1, 1]))
        diff_kids = (np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1]))
        stack: list[tuple[np.ndarray, np.ndarray, int]] = [(np.zeros(1, np.int64), np.zeros(1, np.int64), 0)]
        used = 0
        while stack:
            a, b, d = stack.pop()
            if d == self.depth:
                keep = a != b
                ti, tj = self.leaf_tri[a[keep]], self.leaf_tri[b[keep]]
                ok = (ti >= 0) & (tj >= 0)
                if ok.any():
                    yield ti[ok], tj[ok]
                continue
            if 4 * len(a) > chunk:  # expanding would make a big array: halve, depth first
                h = len(a) // 2
                stack.append((a[h:], b[h:], d))
                stack.append((a[:h], b[:h], d))
                continue
            same = a == b
            # children of (a, a): (2a,2a), (2a,2a+1), (2a+1,2a+1); of (a, b), a<b: all four
            sa, da, db = 2 * a[same], 2 * a[~same], 2 * b[~same]
            a2 = np.concatenate([(sa[:, None] + same_kids[0]).ravel(), (da[:, None] + diff_kids[0]).ravel()])
            b2 = np.concatenate([(sa[:, None] + same_kids[1]).ravel(), (db[:, None] + diff_kids[1]).ravel()])
            if used > budget and len(a2) > 16:
                keep = np.sort(rng.choice(len(a2), size=max(16, len(a2) // 16), replace=False))
                a2, b2 = a2[keep], b2[keep]
                self.pairs_complete = False
            used += len(a2)
            lo, hi = self.lo[d + 1], self.hi[d + 1]
            ov = np.ones(len(a2), dtype=bool)
            for ax in range(3):
                la, ha, lb, hb = lo[ax, a2], hi[ax, a2], lo[ax, b2], hi[ax, b2]
                ov &= (la <= hb + tol) & (lb <= ha + tol)
            if ov.any():
                stack.append((a2[ov], b2[ov], d + 1))

    def overlapping_pairs(self, tol: float, budget: int) -> tuple[np.ndarray, np.ndarray, bool]:
        """All of :meth:`pair_chunks` at once: (i, j, complete)."""
        parts = list(self.pair_chunks(tol, budget))
        if not parts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), self.pairs_complete
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), self.pairs_complete)


def ray_triangle(o: np.ndarray, d: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Moller-Trumbore, vectorised: distance along each ray to its triangle, NaN for a miss."""
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    p = cross3(d, e2)
    det = dot3(e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = dot3(s, p) * inv
        q = cross3(s, e1)
        v = dot3(d, q) * inv
        t = dot3(e2, q) * inv
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
    n = cross3(v1 - v0, v2 - v0)
    nn2 = dot3(n, n)
    nn = np.sqrt(nn2)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp = dot3(p - v0, n) / nn
        dq = dot3(q - v0, n) / nn
        cross = ((dp > eps_d) & (dq < -eps_d)) | ((dp < -eps_d) & (dq > eps_d))
        x = p + (q - p) * (dp / (dp - dq))[:, None]
        b0 = dot3(cross3(v2 - v1, x - v1), n) / nn2
        b1 = dot3(cross3(v0 - v2, x - v2), n) / nn2
        b2 = dot3(cross3(v1 - v0, x - v0), n) / nn2
    inside = (b0 >= -1e-9) & (b1 >= -1e-9) & (b2 >= -1e-9)
    return cross & inside & (nn > 0)


def _project2(P: np.ndarray, drop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """2D coordinates of points P (n, 3) with the axis ``drop`` (n,) removed (x, y of the rest, in order)."""
    keep = np.array([[1, 2], [0, 2], [0, 1]])[drop]
    rows = np.arange(len(P))
    return P[rows, keep[:, 0]], P[rows, keep[:, 1]]


def _coplanar_overlap(A: np.ndarray, B: np.ndarray, nrm: np.ndarray, eps: float) -> np.ndarray:
    """Coplanar triangle pairs whose interiors overlap: no separating axis among the 6 edge normals.

    Done in 2D (the plane projected along the normal's largest axis):
    triangles are convex, so they overlap iff no edge normal separates their
    projections; touching (within ``eps``) counts as separated. Axes are
    tried one by one on the pairs still overlapping, so well-apart
    neighbours leave after one or two.
    """
    drop = np.argmax(np.abs(nrm), axis=1)
    ax_, ay_ = zip(*(_project2(A[:, c], drop) for c in range(3)))
    bx_, by_ = zip(*(_project2(B[:, c], drop) for c in range(3)))
    ax, ay, bx, by = np.stack(ax_), np.stack(ay_), np.stack(bx_), np.stack(by_)  # (3, n)
    idx = np.arange(len(A))
    for px, py, c in [(ax, ay, 0), (ax, ay, 1), (ax, ay, 2), (bx, by, 0), (bx, by, 1), (bx, by, 2)]:
        if not len(idx):
            break
        ex = px[(c + 1) % 3, idx] - px[c, idx]
        ey = py[(c + 1) % 3, idx] - py[c, idx]
        nx, ny = -ey, ex  # the edge's normal in the plane
        la = np.sqrt(nx * nx + ny * ny)
        pa = ax[:, idx] * nx + ay[:, idx] * ny
        pb = bx[:, idx] * nx + by[:, idx] * ny
        tol = eps * la
        sep = (pa.max(axis=0) <= pb.min(axis=0) + tol) | (pb.max(axis=0) <= pa.min(axis=0) + tol) | (la == 0)
        idx = idx[~sep]
    out = np.zeros(len(A), dtype=bool)
    out[idx] = True
    return out


def tri_tri_intersect(A: np.ndarray, B: np.ndarray, fa: np.ndarray, fb: np.ndarray, eps_d: float) -> np.ndarray:
    """Which triangle pairs (A[k], B[k]) cross each other; ``fa``, ``fb`` are their vertex indices.

    The pairwise form of :func:`pair_intersections` (for tests and small uses).
    """
    n = len(A)
    tri = np.concatenate([A, B]).astype(np.float64)
    fv = np.concatenate([fa, fb])
    nrm = cross3(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return pair_intersections(tri, fv, nrm, np.arange(n), np.arange(n, 2 * n), eps_d)


def pair_intersections(tri: np.ndarray, fv: np.ndarray, nrm: np.ndarray, a: np.ndarray, b: np.ndarray,
                       eps_d: float) -> np.ndarray:
    """Which candidate pairs (tri[a[k]], tri[b[k]]) cross each other.

    ``fv`` are the triangles' (welded) vertex indices and ``nrm`` their
    normals (any length; zero for degenerate triangles, which never count).
    Sharing a vertex or an edge is not an intersection, crossing elsewhere
    is, and merely touching is not. Non-coplanar pairs intersect iff an edge
    of one crosses the other (the ends of the intersection segment lie on
    edges). Coplanar pairs: sharing no vertex, a separating-axis test in the
    plane; sharing one, whether their corners' sectors at it overlap;
    sharing an edge, whether they fold onto the same side of it. Tests run
    from cheapest to dearest on a shrinking set of pairs, and coordinates
    are gathered only for the pairs a test needs, since most candidates in
    a mesh are neighbours that one plane test clears.
    """
    n = len(a)
    out = np.zeros(n, dtype=bool)
    if n == 0:
        return out
    fa, fb = fv[a], fv[b]
    inA = np.zeros((n, 3), dtype=bool)
    inB = np.zeros((n, 3), dtype=bool)
    for i in range(3):
        for j in range(3):
            e = fa[:, i] == fb[:, j]
            inA[:, i] |= e
            inB[:, j] |= e
    shared = inA.sum(axis=1)
    nlen = np.sqrt(dot3(nrm, nrm))
    ok = (nlen[a] > 0) & (nlen[b] > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = nrm / nlen[:, None]

    # sharing an edge: only coplanar folds can overlap
    k = np.flatnonzero((shared == 2) & ok)
    if len(k):
        lone = tri[b[k], np.argmin(inB[k], axis=1)]  # B's corner off the shared edge
        cop = np.abs(dot3(lone - tri[a[k], 0], unit[a[k]])) <= eps_d
        if cop.any():
            kk = k[cop]
            out[kk] = _folded(tri[a[kk]], nrm[a[kk]], inA[kk], lone[cop], eps_d)

    # sharing one vertex or none: B's corners against A's plane first
    k = np.flatnonzero((shared < 2) & ok)
    if not len(k):
        return out
    ua, a0 = unit[a[k]], tri[a[k], 0]
    dB = [dot3(tri[b[k], c] - a0, ua) for c in range(3)]
    coplanar = (np.abs(dB[0]) <= eps_d) & (np.abs(dB[1]) <= eps_d) & (np.abs(dB[2]) <= eps_d)
    cop = k[coplanar]
    k = k[~coplanar & ~_separated(dB, eps_d)]
    if len(k):
        ub, b0 = unit[b[k]], tri[b[k], 0]
        dA = [dot3(tri[a[k], c] - b0, ub) for c in range(3)]
        k = k[~_separated(dA, eps_d)]
    if len(k):
        A, B = tri[a[k]], tri[b[k]]
        hitk = np.zeros(len(k), dtype=bool)
        for c in range(3):
            hitk |= segment_hits_triangle(A[:, c], A[:, (c + 1) % 3], B, eps_d)
            hitk |= segment_hits_triangle(B[:, c], B[:, (c + 1) % 3], A, eps_d)
        out[k] = hitk
    if len(cop):
        c0 = cop[shared[cop] == 0]
        if len(c0):
            out[c0] = _coplanar_overlap(tri[a[c0]], tri[b[c0]], nrm[a[c0]], eps_d)
        c1 = cop[shared[cop] == 1]
        if len(c1):
            ia = np.argmax(inA[c1], axis=1)
            ib = np.argmax(inB[c1], axis=1)
            out[c1] = _sectors_overlap(tri[a[c1]], tri[b[c1]], nrm[a[c1]], ia, ib, eps_d)
    return out


def _separated(d: list[np.ndarray], eps_d: float) -> np.ndarray:
    """A triangle wholly on one side of a plane, given its corners' distances; within eps_d is neutral.

    A shared vertex lies in both planes, so it must not count against
    separation; and a triangle only touching the plane cannot cross.
    """
    ge = (d[0] >= -eps_d) & (d[1] >= -eps_d) & (d[2] >= -eps_d)
    le = (d[0] <= eps_d) & (d[1] <= eps_d) & (d[2] <= eps_d)
    gt = (d[0] > eps_d) | (d[1] > eps_d) | (d[2] > eps_d)
    lt = (d[0] < -eps_d) | (d[1] < -eps_d) | (d[2] < -eps_d)
    return (ge & gt) | (le & lt)


def _sectors_overlap(A: np.ndarray, B: np.ndarray, nA: np.ndarray, ia: np.ndarray, ib: np.ndarray,
                     eps: float) -> np.ndarray:
    """Coplanar pairs sharing one vertex (corner ``ia`` of A, ``ib`` of B): do their corners there overlap?

    Two convex sectors around a point overlap iff one's boundary direction
    lies strictly inside the other, or they coincide; and if the corners
    overlap, so do the triangles, just next to the shared vertex. Done in 2D
    (projected along the normal's largest axis, orientation kept by its sign).
    """
    rows = np.arange(len(A))
    drop = np.argmax(np.abs(nA), axis=1)
    sgn = np.sign(nA[rows, drop])
    s = A[rows, ia]
    vecs = [A[rows, (ia + 1) % 3] - s, A[rows, (ia + 2) % 3] - s, B[rows, (ib + 1) % 3] - s, B[rows, (ib + 2) % 3] - s]
    (a1x, a1y), (a2x, a2y), (b1x, b1y), (b2x, b2y) = (_project2(v, drop) for v in vecs)
    scale = np.sqrt(np.maximum(a1x * a1x + a1y * a1y, b1x * b1x + b1y * b1y))
    tol = eps * scale

    def side(ux: np.ndarray, uy: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        # > 0: w lies counter-clockwise of u (about the normal), scaled by |w|
        return sgn * (ux * wy - uy * wx) / np.maximum(np.sqrt(ux * ux + uy * uy), 1e-300)

    def oriented(ux, uy, vx, vy):  # type: ignore[no-untyped-def]
        ccw = side(ux, uy, vx, vy) > 0
        return np.where(ccw, ux, vx), np.where(ccw, uy, vy), np.where(ccw, vx, ux), np.where(ccw, vy, uy)

    a1x, a1y, a2x, a2y = oriented(a1x, a1y, a2x, a2y)
    b1x, b1y, b2x, b2y = oriented(b1x, b1y, b2x, b2y)

    def strictly_in(ux, uy, vx, vy, wx, wy):  # type: ignore[no-untyped-def]
        return (side(ux, uy, wx, wy) > tol) & (side(wx, wy, vx, vy) > tol)

    over = (strictly_in(a1x, a1y, a2x, a2y, b1x, b1y) | strictly_in(a1x, a1y, a2x, a2y, b2x, b2y)
            | strictly_in(b1x, b1y, b2x, b2y, a1x, a1y) | strictly_in(b1x, b1y, b2x, b2y, a2x, a2y))
    same = ((np.abs(side(a1x, a1y, b1x, b1y)) <= tol) & (np.abs(side(a2x, a2y, b2x, b2y)) <= tol)
            & (a1x * b1x + a1y * b1y > 0) & (a2x * b2x + a2y * b2y > 0))
    return over | same


def _folded(A: np.ndarray, nA: np.ndarray, inA: np.ndarray, b_lone: np.ndarray, eps: float) -> np.ndarray:
    """Coplanar pairs sharing an edge whose third corners lie on the same side of it (a fold)."""
    rows = np.arange(len(A))
    a_lone = A[rows, np.argmin(inA, axis=1)]
    order = np.argsort(inA, axis=1, kind="stable")[:, 1:]  # A's two shared corners
    s = A[rows, order[:, 0]]
    t = A[rows, order[:, 1]]
    side_a = dot3(cross3(t - s, a_lone - s), nA)
    side_b = dot3(cross3(t - s, b_lone - s), nA)
    tol = eps * np.sqrt(dot3(nA, nA)) * np.sqrt(dot3(t - s, t - s))
    return ((side_a > tol) & (side_b > tol)) | ((side_a < -tol) & (side_b < -tol))
