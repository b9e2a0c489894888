"""The checker's numba kernels against their numpy references (``check/kernels.py`` vs ``bvh.py`` / ``topology.py``)."""

from __future__ import annotations

from pathlib import Path

import fixtures_check as fx
import numpy as np
import pytest

import saucerfab.check.bvh as bvh_mod
from saucerfab.check import check_mesh
from saucerfab.check.bvh import BVH
from saucerfab.check.kernels import components_uf
from saucerfab.check.topology import components_numpy


def _soup(n: int, seed: int) -> np.ndarray:
    """``n`` small random triangles in a unit cube (n, 3, 3): many overlapping boxes, some crossings."""
    rng = np.random.default_rng(seed)
    c = rng.random((n, 1, 3))
    return c + 0.04 * rng.standard_normal((n, 3, 3))


def _pair_keys(chunks: list[tuple[np.ndarray, np.ndarray]], n: int) -> np.ndarray:
    if not chunks:
        return np.zeros(0, np.int64)
    i = np.concatenate([c[0] for c in chunks])
    j = np.concatenate([c[1] for c in chunks])
    return np.sort(np.minimum(i, j) * n + np.maximum(i, j))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_union_find_labels_equal_the_numpy_components(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5000
    u = rng.integers(0, n, 3000)
    v = rng.integers(0, n, 3000)
    assert np.array_equal(components_uf(n, u, v), components_numpy(n, u, v))
    assert np.array_equal(components_uf(4, np.zeros(0, np.int64), np.zeros(0, np.int64)), np.arange(4))


@pytest.mark.parametrize("n, seed", [(1, 0), (2, 0), (3, 1), (300, 2), (2049, 3)])
def test_numba_pair_search_finds_exactly_the_numpy_pairs(n: int, seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    tri = _soup(n, seed)
    tree = BVH.build(tri)
    ref = list(tree.pair_chunks_numpy(1e-6, 10**12))
    assert tree.pairs_complete
    monkeypatch.setattr(bvh_mod, "FAST_FROM_TRIANGLES", 0)
    fast = list(tree.pair_chunks(1e-6, 10**12, chunk=97))  # a small buffer: the search resumes many times
    assert tree.pairs_complete
    assert np.array_equal(_pair_keys(fast, n), _pair_keys(ref, n))
    assert all(len(c[0]) <= 97 for c in fast)


def test_numba_pair_search_stops_near_its_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pile of triangles in one spot: past the budget the search samples and says it is partial."""
    rng = np.random.default_rng(5)
    tri = 0.5 + 1e-3 * rng.standard_normal((4000, 3, 3))  # every box overlaps every other
    tree = BVH.build(tri)
    monkeypatch.setattr(bvh_mod, "FAST_FROM_TRIANGLES", 0)
    got = sum(len(c[0]) for c in tree.pair_chunks(1e-9, 20_000))
    assert not tree.pairs_complete
    assert 0 < got < 4000 * 3999 // 2 // 10


def test_check_reports_alike_on_the_numba_and_numpy_paths(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    V, F = fx.box()
    p = fx.write_stl(tmp_path / "two.stl", np.concatenate([V, V + 0.5]), np.concatenate([F, F + len(V)]))
    ref = check_mesh(p).to_dict()
    monkeypatch.setattr(bvh_mod, "FAST_FROM_TRIANGLES", 0)
    fast = check_mesh(p).to_dict()
    for r in (ref, fast):
        r.pop("elapsed_s")
    assert fast == ref
    assert "self_intersections" in {f["code"] for f in fast["findings"]}


def _lattice_pairs(seed: int, flat: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tri, fv, normals, a, b): random triangles on a coarse lattice and 300k random pairs of them.

    Many pairs are coplanar, touching, or share a vertex or an edge; with
    ``flat`` a third of the triangles lie in one plane (as a saucer's bottom).
    """
    from saucerfab.check.bvh import cross3

    rng = np.random.default_rng(seed)
    P = rng.integers(0, 5, (300, 3)).astype(float) / 4
    if flat:
        P[:100, 2] = 0.0
    fv = np.concatenate([rng.integers(0, 100, (1500, 3)), rng.integers(0, 300, (1500, 3))])
    fv = fv[(fv[:, 0] != fv[:, 1]) & (fv[:, 1] != fv[:, 2]) & (fv[:, 0] != fv[:, 2])]
    tri = P[fv]
    nrm = cross3(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return tri, fv, nrm, rng.integers(0, len(fv), 300_000), rng.integers(0, len(fv), 300_000)


@pytest.mark.parametrize("seed, flat", [(7, False), (8, True)])
def test_the_numba_cull_never_clears_a_pair_the_exact_test_finds(seed: int, flat: bool) -> None:
    """cull + exact == exact alone."""
    from saucerfab.check.bvh import dot3, pair_intersections
    from saucerfab.check.kernels import needs_exact_test

    tri, fv, nrm, a, b = _lattice_pairs(seed, flat)
    ref = pair_intersections(tri, fv, nrm, a, b, 1e-9)
    keep = needs_exact_test(tri, fv, nrm, np.sqrt(dot3(nrm, nrm)), a, b, 1e-9)
    assert ref.any() and (~keep).sum() > len(a) // 4  # the cull does clear pairs, and the exact test finds some
    got = np.zeros(len(a), dtype=bool)
    got[keep] = pair_intersections(tri, fv, nrm, a[keep], b[keep], 1e-9)
    assert np.array_equal(got, ref)


@pytest.mark.parametrize("seed, flat", [(7, True), (8, True), (9, False)])
def test_the_numba_exact_test_equals_the_numpy_one(seed: int, flat: bool) -> None:
    """Pair by pair in numba == numpy's staged test, branch for branch (folds, sectors, coplanar, crossing)."""
    from saucerfab.check.bvh import dot3, pair_intersections
    from saucerfab.check.kernels import pair_intersections_fast

    tri, fv, nrm, a, b = _lattice_pairs(seed, flat)
    ref = pair_intersections(tri, fv, nrm, a, b, 1e-9)
    got = pair_intersections_fast(tri, fv, nrm, np.sqrt(dot3(nrm, nrm)), a, b, 1e-9)
    assert ref.sum() > 1000 and not ref.all()
    assert np.array_equal(got, ref)
