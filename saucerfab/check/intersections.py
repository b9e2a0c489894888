"""Self-intersections: candidate pairs from the BVH, decided by the exact triangle-triangle test.

manifold3d's ``Manifold(mesh).status()`` only says whether the triangles
form an oriented 2-manifold; it accepts surfaces passing through each
other, so this check finds them itself: :meth:`~saucerfab.check.bvh.BVH.pair_chunks`
lists triangle pairs whose boxes overlap, within a work budget, and
:func:`~saucerfab.check.bvh.pair_intersections` (numpy) or, for large
meshes, :func:`~saucerfab.check.kernels.pair_intersections_fast` (numba)
decides each pair.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from saucerfab.check import bvh as bvh_mod
from saucerfab.check.bvh import BVH, cross3, dot3, pair_intersections, query_workers
from saucerfab.check.jit import have_numba
from saucerfab.check.limits import Limits
from saucerfab.check.places import fmt_pt, where
from saucerfab.check.report import Finding, finding

#: candidate pairs per narrow-phase chunk (bounds the temporary arrays to ~100 MB)
_PAIR_CHUNK = 150_000


def self_intersections(bvh: BVH, tri: np.ndarray, Fg: np.ndarray, gidx: np.ndarray, centroids: np.ndarray,
                        diag: float, limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    """Find pairs of sound faces that cross each other; appends findings, sets the self-intersection stats.

    Args:
        bvh: the tree over ``tri``.
        tri: (m, 3, 3) the sound faces' corners, mm; ``Fg`` (m, 3) their welded vertex indices, ``gidx``
            (m,) their indices in the file.
        centroids: (F, 3) every file face's centroid, mm (for the finding's place).
        diag: the bounding box's diagonal, mm (scales the tolerances).
    """
    eps = 1e-9 * diag
    m = len(tri)
    # The budget scales with the mesh (a sound mesh visits ~45 node pairs per triangle), capped by the
    # limit, so a pile of overlapping triangles ends quickly with a sampled, "partial" answer.
    budget = min(limits.max_pair_tests, 100 * m + 1_000_000)

    nrm = cross3(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    exact = lambda a, b: pair_intersections(tri, Fg, nrm, a, b, eps)
    if m >= bvh_mod.FAST_FROM_TRIANGLES and have_numba():
        # the same test pair by pair in numba: no temporaries per stage, and a flat bottom's millions of
        # coplanar neighbour pairs (sector and fold tests) cost microseconds each, not numpy passes
        from saucerfab.check.kernels import pair_intersections_fast

        nlen = np.sqrt(dot3(nrm, nrm))
        exact = lambda a, b: pair_intersections_fast(tri, Fg, nrm, nlen, a, b, eps)

    def narrow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        hit = exact(a, b)
        return np.stack([a[hit], b[hit]], axis=1)

    # The crossing pairs are reduced chunk by chunk to what the finding says (their count, the faces
    # they touch, the first pair in file order): a pile of overlapping triangles crosses itself tens of
    # millions of times, and keeping every pair cost gigabytes and seconds of sorting.
    n_pairs = 0
    crossed = np.zeros(len(centroids), dtype=bool)
    first: tuple[int, int] | None = None

    def reduce(pairs: np.ndarray) -> None:
        nonlocal n_pairs, first
        if not len(pairs):
            return
        fp = np.sort(gidx[pairs], axis=1)  # file face indices, lower first
        n_pairs += len(fp)
        crossed[fp.ravel()] = True
        k = np.lexsort((fp[:, 1], fp[:, 0]))[0]  # the first in file order, whatever order the search took
        cand = (int(fp[k, 0]), int(fp[k, 1]))
        if first is None or cand < first:
            first = cand

    # The exact tests are bounded too: at most a quarter of the node-pair budget (~25 candidate pairs per
    # triangle; a sound mesh has ~8), past which the answer is partial.
    tests_left = budget // 4
    cut = False

    def bounded(chunks: Iterable[tuple[np.ndarray, np.ndarray]]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        nonlocal tests_left, cut
        for a, b in chunks:
            if len(a) > tests_left:
                a, b, cut = a[:tests_left], b[:tests_left], True
            tests_left -= len(a)
            if len(a):
                yield a, b
            if cut:
                return

    workers = query_workers()
    chunks = bounded(_rechunk(bvh.pair_chunks(tol=eps, budget=budget), _PAIR_CHUNK))
    if workers > 1 and m > 20_000:
        # numpy releases the GIL in its loops: the search (this thread) and the exact tests (the pool)
        # overlap, and a second core is used where there is one; a few chunks in flight bound memory
        from concurrent.futures import Future, ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=workers) as ex:
            pending: list[Future[np.ndarray]] = []
            for a, b in chunks:
                pending.append(ex.submit(narrow, a, b))
                if len(pending) > 2 * workers:
                    reduce(pending.pop(0).result())
            for f in pending:
                reduce(f.result())
    else:
        for a, b in chunks:
            reduce(narrow(a, b))
    complete = bvh.pairs_complete and not cut
    stats["self_intersecting_pairs"] = n_pairs
    stats["self_intersection_check"] = "full" if complete else "partial"
    if not complete:
        out.append(finding("check_partial", "self-intersection search stopped at its work budget (Limits.max_pair_tests"
                                            f" = {limits.max_pair_tests:,}, scaled to the mesh): parts of the mesh "
                                            "crowd together so densely that not all pairs were compared"))
    if first is not None:
        f0, f1 = first
        out.append(finding(
            "self_intersections",
            f"{n_pairs:,} pairs of faces cross each other ({int(crossed.sum()):,} faces), first near "
            f"{fmt_pt(centroids[f0])}: faces {f0} and {f1}; union or repair the surfaces",
            where=where(centroids[f0], [f0, f1], count=n_pairs),
        ))


def _rechunk(chunks: Iterable[tuple[np.ndarray, np.ndarray]], size: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
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
