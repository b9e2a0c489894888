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
    workers = query_workers()
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
            f"{fmt_pt(centroids[f0])}: faces {f0} and {f1}; union or repair the surfaces",
            where=where(centroids[f0], [f0, f1], count=len(pairs)),
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
