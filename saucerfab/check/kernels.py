"""numba kernels for the checker's large meshes: the BVH pair search and connected components.

The checker's numpy code (:mod:`saucerfab.check.bvh`, :mod:`saucerfab.check.topology`)
is the reference and serves small meshes: importing numba costs about 0.7 s
of start-up, more than a small file's whole check. Past
:data:`saucerfab.check.bvh.FAST_FROM_TRIANGLES` triangles the callers switch to these kernels, which give
the same answers (``tests/check/test_check_kernels.py`` holds the two together)
several times faster, without the numpy versions' frontier arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _find(parent: np.ndarray, x: int) -> int:
    while parent[x] != x:
        parent[x] = parent[parent[x]]  # path halving
        x = parent[x]
    return x


@njit(cache=True, nogil=True)
def components_uf(n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Component label (the smallest node id in it) of each of ``n`` nodes joined by edges ``u``-``v`` (int64).

    Union-find that always hangs the larger root under the smaller, so a
    root is its component's smallest id; ``parent[i] <= i`` throughout,
    so one ascending pass leaves every node pointing at its root.
    """
    parent = np.arange(n)
    for k in range(len(u)):
        a = _find(parent, u[k])
        b = _find(parent, v[k])
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    for i in range(n):
        parent[i] = parent[parent[i]]
    return parent


@njit(cache=True, nogil=True)  # the exact tests of earlier pairs run in threads meanwhile
def pair_search(lo: np.ndarray, hi: np.ndarray, depth: int, leaf_tri: np.ndarray, tol: float,
                stack: np.ndarray, state: np.ndarray, out_i: np.ndarray, out_j: np.ndarray,
                budget: int) -> int:
    """Resume a depth-first search for triangle pairs whose boxes overlap; fill ``out_i/out_j``, return the count.

    The tree is the BVH's complete binary tree in heap order: level ``d``'s
    node ``k`` is column ``2**d - 1 + k`` of ``lo`` / ``hi`` (3, 2**(depth+1) - 1),
    float32. ``stack`` (S, 3) holds pending (a, b, level) node pairs and
    ``state`` = [stack top, node-pair tests so far, incomplete flag, rng];
    both persist between calls, so a caller drains the search a buffer at a
    time (``out_i`` full: call again; ``state[0] == 0``: done). Past
    ``budget`` node-pair tests each child pair is kept with probability 1/16
    (an LCG with a fixed seed), as in :meth:`BVH.pair_chunks`, and the search
    is marked incomplete.
    """
    cap = len(out_i)
    n = 0
    top = state[0]
    used = state[1]
    rng = state[3]
    while top > 0 and n < cap:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        d = stack[top, 2]
        if d == depth:
            if a != b:
                ti = leaf_tri[a]
                tj = leaf_tri[b]
                if ti >= 0 and tj >= 0:
                    out_i[n] = ti
                    out_j[n] = tj
                    n += 1
            continue
        base = (1 << (d + 1)) - 1
        for c in range(4):
            if a == b:
                if c == 3:
                    break
                ca = 2 * a + (1 if c == 2 else 0)
                cb = 2 * a + (0 if c == 0 else 1)
            else:
                ca = 2 * a + (c >> 1)
                cb = 2 * b + (c & 1)
            used += 1
            if used > budget:
                rng = (rng * 1103515245 + 12345) & 0x7FFFFFFF  # an LCG in int64: no overflow, no zero trap
                if (rng >> 16) & 15 != 0:
                    state[2] = 1
                    continue
            ia = base + ca
            ib = base + cb
            if (lo[0, ia] <= hi[0, ib] + tol and lo[0, ib] <= hi[0, ia] + tol
                    and lo[1, ia] <= hi[1, ib] + tol and lo[1, ib] <= hi[1, ia] + tol
                    and lo[2, ia] <= hi[2, ib] + tol and lo[2, ib] <= hi[2, ia] + tol):
                stack[top, 0] = ca
                stack[top, 1] = cb
                stack[top, 2] = d + 1
                top += 1
    state[0] = top
    state[1] = used
    state[3] = rng
    return n


@njit(cache=True, nogil=True)
def _dist(p: np.ndarray, q: np.ndarray, n: np.ndarray, s: float) -> float:
    """(p - q) . n / s, in the order numpy's ``dot3(p - q, n / s)`` computes it (bit-identical)."""
    return (p[0] - q[0]) * (n[0] / s) + (p[1] - q[1]) * (n[1] / s) + (p[2] - q[2]) * (n[2] / s)


@njit(cache=True, nogil=True)
def _one_side(d0: float, d1: float, d2: float, eps: float) -> bool:
    ge = d0 >= -eps and d1 >= -eps and d2 >= -eps
    le = d0 <= eps and d1 <= eps and d2 <= eps
    gt = d0 > eps or d1 > eps or d2 > eps
    lt = d0 < -eps or d1 < -eps or d2 < -eps
    return (ge and gt) or (le and lt)


@njit(cache=True, nogil=True)
def needs_exact_test(tri: np.ndarray, fv: np.ndarray, nrm: np.ndarray, nlen: np.ndarray,
                     a: np.ndarray, b: np.ndarray, eps: float) -> np.ndarray:
    """Which candidate pairs :func:`saucerfab.check.bvh.pair_intersections` could find crossing.

    The cheap first stages of that function, pair by pair: a pair is
    cleared (False) when a triangle is degenerate, when the two are the
    same face or share an edge without being coplanar, or when either lies
    wholly on one side of the other's plane. Every cleared pair is one the
    numpy function returns False for (the same float operations in the same
    order), so running it on the rest only saves time. tri (m, 3, 3), fv
    (m, 3) welded vertex ids, nrm (m, 3) normals of length nlen (m,),
    a / b (k,) candidate pairs; returns (k,) bool.
    """
    out = np.zeros(len(a), dtype=np.bool_)
    for k in range(len(a)):
        i = a[k]
        j = b[k]
        if not (nlen[i] > 0 and nlen[j] > 0):
            continue
        shared = 0
        lone = -1  # B's first corner not shared with A
        for cb in range(3):
            hit = fv[i, 0] == fv[j, cb] or fv[i, 1] == fv[j, cb] or fv[i, 2] == fv[j, cb]
            if not hit and lone < 0:
                lone = cb
        for ca in range(3):
            if fv[i, ca] == fv[j, 0] or fv[i, ca] == fv[j, 1] or fv[i, ca] == fv[j, 2]:
                shared += 1
        if shared >= 3:
            continue
        if shared == 2:
            if lone >= 0 and abs(_dist(tri[j, lone], tri[i, 0], nrm[i], nlen[i])) <= eps:
                out[k] = True  # coplanar fold: the exact test decides
            continue
        d0 = _dist(tri[j, 0], tri[i, 0], nrm[i], nlen[i])
        d1 = _dist(tri[j, 1], tri[i, 0], nrm[i], nlen[i])
        d2 = _dist(tri[j, 2], tri[i, 0], nrm[i], nlen[i])
        if abs(d0) <= eps and abs(d1) <= eps and abs(d2) <= eps:
            out[k] = True  # coplanar
            continue
        if _one_side(d0, d1, d2, eps):
            continue
        e0 = _dist(tri[i, 0], tri[j, 0], nrm[j], nlen[j])
        e1 = _dist(tri[i, 1], tri[j, 0], nrm[j], nlen[j])
        e2 = _dist(tri[i, 2], tri[j, 0], nrm[j], nlen[j])
        out[k] = not _one_side(e0, e1, e2, eps)
    return out



# -- the exact pair test, pair by pair (bvh.pair_intersections is its reference: same operations, same order) ----


@njit(cache=True, nogil=True)
def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple[float, float, float]:
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, nogil=True)
def _segment_hits(p: np.ndarray, q: np.ndarray, t: np.ndarray, eps: float) -> bool:
    """:func:`saucerfab.check.bvh.segment_hits_triangle` for one segment p-q (3,) and triangle t (3, 3)."""
    n0, n1, n2 = _cross(t[1, 0] - t[0, 0], t[1, 1] - t[0, 1], t[1, 2] - t[0, 2],
                        t[2, 0] - t[0, 0], t[2, 1] - t[0, 1], t[2, 2] - t[0, 2])
    nn2 = n0 * n0 + n1 * n1 + n2 * n2
    nn = np.sqrt(nn2)
    if not nn > 0:
        return False
    dp = ((p[0] - t[0, 0]) * n0 + (p[1] - t[0, 1]) * n1 + (p[2] - t[0, 2]) * n2) / nn
    dq = ((q[0] - t[0, 0]) * n0 + (q[1] - t[0, 1]) * n1 + (q[2] - t[0, 2]) * n2) / nn
    if not ((dp > eps and dq < -eps) or (dp < -eps and dq > eps)):
        return False
    r = dp / (dp - dq)
    x0 = p[0] + (q[0] - p[0]) * r
    x1 = p[1] + (q[1] - p[1]) * r
    x2 = p[2] + (q[2] - p[2]) * r
    for k in range(3):  # barycentric of x against edge k+1 -> k+2
        i = (k + 1) % 3
        j = (k + 2) % 3
        c0, c1, c2 = _cross(t[j, 0] - t[i, 0], t[j, 1] - t[i, 1], t[j, 2] - t[i, 2],
                            x0 - t[i, 0], x1 - t[i, 1], x2 - t[i, 2])
        if not (c0 * n0 + c1 * n1 + c2 * n2) / nn2 >= -1e-9:
            return False
    return True


@njit(cache=True, nogil=True)
def _proj(v0: float, v1: float, v2: float, drop: int) -> tuple[float, float]:
    if drop == 0:
        return v1, v2
    if drop == 1:
        return v0, v2
    return v0, v1


@njit(cache=True, nogil=True)
def _drop_axis(n: np.ndarray) -> int:
    """np.argmax(np.abs(n)): the first of the largest."""
    d = 0
    if abs(n[1]) > abs(n[d]):
        d = 1
    if abs(n[2]) > abs(n[d]):
        d = 2
    return d


@njit(cache=True, nogil=True)
def _coplanar_overlap(A: np.ndarray, B: np.ndarray, n: np.ndarray, eps: float) -> bool:
    """:func:`saucerfab.check.bvh._coplanar_overlap` for one pair: no separating edge normal in 2D."""
    drop = _drop_axis(n)
    P = np.empty((2, 3, 2))
    for c in range(3):
        P[0, c, 0], P[0, c, 1] = _proj(A[c, 0], A[c, 1], A[c, 2], drop)
        P[1, c, 0], P[1, c, 1] = _proj(B[c, 0], B[c, 1], B[c, 2], drop)
    for e in range(6):
        w = e // 3
        c = e % 3
        ex = P[w, (c + 1) % 3, 0] - P[w, c, 0]
        ey = P[w, (c + 1) % 3, 1] - P[w, c, 1]
        nx = -ey
        ny = ex
        la = np.sqrt(nx * nx + ny * ny)
        if la == 0:
            return False
        tol = eps * la
        amax = -np.inf
        amin = np.inf
        bmax = -np.inf
        bmin = np.inf
        for k in range(3):
            pa = P[0, k, 0] * nx + P[0, k, 1] * ny
            pb = P[1, k, 0] * nx + P[1, k, 1] * ny
            amax = max(amax, pa)
            amin = min(amin, pa)
            bmax = max(bmax, pb)
            bmin = min(bmin, pb)
        if amax <= bmin + tol or bmax <= amin + tol:
            return False
    return True


@njit(cache=True, nogil=True)
def _side(sgn: float, ux: float, uy: float, wx: float, wy: float) -> float:
    return sgn * (ux * wy - uy * wx) / max(np.sqrt(ux * ux + uy * uy), 1e-300)


@njit(cache=True, nogil=True)
def _strictly_in(sgn: float, ux: float, uy: float, vx: float, vy: float, wx: float, wy: float, tol: float) -> bool:
    return _side(sgn, ux, uy, wx, wy) > tol and _side(sgn, wx, wy, vx, vy) > tol


@njit(cache=True, nogil=True)
def _sectors_overlap(A: np.ndarray, B: np.ndarray, n: np.ndarray, ia: int, ib: int, eps: float) -> bool:
    """:func:`saucerfab.check.bvh._sectors_overlap` for one pair sharing corner ``ia`` of A, ``ib`` of B."""
    drop = _drop_axis(n)
    sgn = np.sign(n[drop])
    s = A[ia]
    a1x, a1y = _proj(A[(ia + 1) % 3, 0] - s[0], A[(ia + 1) % 3, 1] - s[1], A[(ia + 1) % 3, 2] - s[2], drop)
    a2x, a2y = _proj(A[(ia + 2) % 3, 0] - s[0], A[(ia + 2) % 3, 1] - s[1], A[(ia + 2) % 3, 2] - s[2], drop)
    b1x, b1y = _proj(B[(ib + 1) % 3, 0] - s[0], B[(ib + 1) % 3, 1] - s[1], B[(ib + 1) % 3, 2] - s[2], drop)
    b2x, b2y = _proj(B[(ib + 2) % 3, 0] - s[0], B[(ib + 2) % 3, 1] - s[1], B[(ib + 2) % 3, 2] - s[2], drop)
    tol = eps * np.sqrt(max(a1x * a1x + a1y * a1y, b1x * b1x + b1y * b1y))
    if not _side(sgn, a1x, a1y, a2x, a2y) > 0:  # orient each sector counter-clockwise
        a1x, a1y, a2x, a2y = a2x, a2y, a1x, a1y
    if not _side(sgn, b1x, b1y, b2x, b2y) > 0:
        b1x, b1y, b2x, b2y = b2x, b2y, b1x, b1y
    if (_strictly_in(sgn, a1x, a1y, a2x, a2y, b1x, b1y, tol) or _strictly_in(sgn, a1x, a1y, a2x, a2y, b2x, b2y, tol)
            or _strictly_in(sgn, b1x, b1y, b2x, b2y, a1x, a1y, tol)
            or _strictly_in(sgn, b1x, b1y, b2x, b2y, a2x, a2y, tol)):
        return True
    return (abs(_side(sgn, a1x, a1y, b1x, b1y)) <= tol and abs(_side(sgn, a2x, a2y, b2x, b2y)) <= tol
            and a1x * b1x + a1y * b1y > 0 and a2x * b2x + a2y * b2y > 0)


@njit(cache=True, nogil=True)
def _folded(A: np.ndarray, n: np.ndarray, sa: int, ta: int, lone_a: int, b_lone: np.ndarray, eps: float) -> bool:
    """:func:`saucerfab.check.bvh._folded` for one pair sharing A's edge sa-ta (in corner order)."""
    s = A[sa]
    t0, t1, t2 = A[ta, 0] - s[0], A[ta, 1] - s[1], A[ta, 2] - s[2]
    c0, c1, c2 = _cross(t0, t1, t2, A[lone_a, 0] - s[0], A[lone_a, 1] - s[1], A[lone_a, 2] - s[2])
    side_a = c0 * n[0] + c1 * n[1] + c2 * n[2]
    c0, c1, c2 = _cross(t0, t1, t2, b_lone[0] - s[0], b_lone[1] - s[1], b_lone[2] - s[2])
    side_b = c0 * n[0] + c1 * n[1] + c2 * n[2]
    tol = eps * np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    return (side_a > tol and side_b > tol) or (side_a < -tol and side_b < -tol)


@njit(cache=True, nogil=True)
def pair_intersections_fast(tri: np.ndarray, fv: np.ndarray, nrm: np.ndarray, nlen: np.ndarray,
                            a: np.ndarray, b: np.ndarray, eps: float) -> np.ndarray:
    """:func:`saucerfab.check.bvh.pair_intersections`, pair by pair: which pairs (tri[a[k]], tri[b[k]]) cross.

    The same tests in the same order with the same float operations (the
    tests compare the two on lattices full of coplanar, touching and
    edge-sharing pairs); the numpy function stays the reference and serves
    small meshes. tri (m, 3, 3), fv (m, 3) welded vertex ids, nrm (m, 3)
    normals of length nlen (m,); a / b (k,); returns (k,) bool.
    """
    out = np.zeros(len(a), dtype=np.bool_)
    keep = needs_exact_test(tri, fv, nrm, nlen, a, b, eps)
    for k in range(len(a)):
        if not keep[k]:
            continue
        i = a[k]
        j = b[k]
        A = tri[i]
        B = tri[j]
        in_a = np.zeros(3, dtype=np.bool_)
        in_b = np.zeros(3, dtype=np.bool_)
        for ca in range(3):
            for cb in range(3):
                if fv[i, ca] == fv[j, cb]:
                    in_a[ca] = True
                    in_b[cb] = True
        shared = int(in_a[0]) + int(in_a[1]) + int(in_a[2])
        if shared == 2:  # kept only when coplanar: a fold?
            lone_b = 0 if not in_b[0] else (1 if not in_b[1] else 2)
            lone_a = 0 if not in_a[0] else (1 if not in_a[1] else 2)
            sa = 0 if lone_a != 0 else 1
            ta = 2 if lone_a != 2 else 1
            out[k] = _folded(A, nrm[i], sa, ta, lone_a, B[lone_b], eps)
            continue
        # kept with shared < 2: coplanar, or straddling both planes
        s = nlen[i]
        coplanar = True
        for c in range(3):
            d = ((B[c, 0] - A[0, 0]) * (nrm[i, 0] / s) + (B[c, 1] - A[0, 1]) * (nrm[i, 1] / s)
                 + (B[c, 2] - A[0, 2]) * (nrm[i, 2] / s))
            if abs(d) > eps:
                coplanar = False
        if coplanar:
            if shared == 0:
                out[k] = _coplanar_overlap(A, B, nrm[i], eps)
            else:
                ia = 0 if in_a[0] else (1 if in_a[1] else 2)
                ib = 0 if in_b[0] else (1 if in_b[1] else 2)
                out[k] = _sectors_overlap(A, B, nrm[i], ia, ib, eps)
            continue
        hit = False
        for c in range(3):
            if (_segment_hits(A[c], A[(c + 1) % 3], B, eps) or _segment_hits(B[c], B[(c + 1) % 3], A, eps)):
                hit = True
                break
        out[k] = hit
    return out
