"""Compile the numba kernels of :mod:`saucerfab.check.kernels` on tiny inputs (``python -m saucerfab.warmup``).

Apart from the kernels so that they need not import the BVH that calls
them: the tiny tree here is a real :class:`~saucerfab.check.bvh.BVH`, so
the kernels compile for exactly the array types a check passes them.
"""

from __future__ import annotations

import numpy as np

from saucerfab.check.bvh import BVH
from saucerfab.check.kernels import components_uf, needs_exact_test, pair_intersections_fast, pair_search


def warm_up() -> list[str]:
    """Compile every kernel of :mod:`saucerfab.check.kernels` on tiny inputs; return their names."""
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
    nlen = np.sqrt((nrm * nrm).sum(axis=1))
    needs_exact_test(tri, fv, nrm, nlen, np.array([0]), np.array([1]), 1e-9)
    pair_intersections_fast(tri, fv, nrm, nlen, np.array([0]), np.array([1]), 1e-9)
    components_uf(3, np.array([0]), np.array([1]))
    return ["pair_search", "needs_exact_test", "pair_intersections_fast", "components_uf"]
