"""numba kernels for the checker's large meshes: the BVH pair search and connected components.

The checker's numpy code (:mod:`saucerfab.check.bvh`, :mod:`saucerfab.check.topology`)
is the reference and serves small meshes: importing numba costs about 0.7 s
of start-up, more than a small file's whole check. Past
:data:`saucerfab.check.bvh.FAST_FROM_TRIANGLES` triangles the callers switch to these kernels, which give
the same answers (``tests/test_check_kernels.py`` holds the two together)
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


def warm_up() -> list[str]:
    """Compile every kernel here on tiny inputs (``python -m saucerfab.warmup``); return their names."""
    from saucerfab.check.bvh import BVH

    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0.5], [1, 0, -0.5], [0, 1, 0]]], dtype=np.float64)
    tree = BVH.build(tri)
    stack = np.zeros((4 * (tree.depth + 2), 3), dtype=np.int64)
    state = np.array([1, 0, 0, 12345], dtype=np.int64)
    out = np.empty(8, dtype=np.int64)
    assert tree.flat_lo is not None and tree.flat_hi is not None
    pair_search(tree.flat_lo, tree.flat_hi, tree.depth, tree.leaf_tri, np.float32(0.0), stack, state, out,
                out.copy(), 10)
    fv = np.array([[0, 1, 2], [3, 4, 5]])
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    needs_exact_test(tri, fv, nrm, np.sqrt((nrm * nrm).sum(axis=1)), np.array([0]), np.array([1]), 1e-9)
    components_uf(3, np.array([0]), np.array([1]))
    return ["pair_search", "needs_exact_test", "components_uf"]
