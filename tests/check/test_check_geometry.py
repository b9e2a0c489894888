"""The checker's fast kernels against slow, obvious references (BVH, rays, triangle pairs, topology)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fixtures_check import box, saucer_solid
from saucerfab.check.bvh import BVH, cross3, ray_triangle, tri_tri_intersect
from saucerfab.check.topology import components, face_geometry, topology, weld

# -- slow references ---------------------------------------------------------------


def ref_ray_triangle(o: np.ndarray, d: np.ndarray, t: np.ndarray) -> float | None:
    """Ray-plane intersection, then a barycentric inside test: a different route than Moller-Trumbore."""
    n = np.cross(t[1] - t[0], t[2] - t[0])
    denom = float(np.dot(n, d))
    if abs(denom) < 1e-15:
        return None
    s = float(np.dot(n, t[0] - o)) / denom
    x = o + s * d
    area = np.dot(n, n)
    b = [np.dot(np.cross(t[(i + 2) % 3] - t[(i + 1) % 3], x - t[(i + 1) % 3]), n) / area for i in range(3)]
    return s if min(b) >= -1e-12 else None


def ref_tri_tri(a: np.ndarray, b: np.ndarray) -> bool:
    """Clip triangle a to b's plane (a segment), then clip that segment to b in b's plane; any length left?

    For generic, non-coplanar pairs sharing no vertex.
    """
    nb = np.cross(b[1] - b[0], b[2] - b[0])
    d = [float(np.dot(p - b[0], nb)) for p in a]
    pts = []
    for i in range(3):
        p, q = a[i], a[(i + 1) % 3]
        dp, dq = d[i], d[(i + 1) % 3]
        if dp == 0:
            pts.append(p)
        if (dp < 0 < dq) or (dq < 0 < dp):
            pts.append(p + (q - p) * dp / (dp - dq))
    if len(pts) < 2:
        return False
    p, q = pts[0], pts[1]
    lo, hi = 0.0, 1.0
    for i in range(3):  # clip p->q against b's three edge half-planes (inside: positive side)
        e0, e1 = b[i], b[(i + 1) % 3]
        m = np.cross(nb, e1 - e0)  # points inward for a counter-clockwise triangle about nb
        fp, fq = float(np.dot(p - e0, m)), float(np.dot(q - e0, m))
        if fp < 0 and fq < 0:
            return False
        if fp < 0 or fq < 0:
            t = fp / (fp - fq)
            if fp < 0:
                lo = max(lo, t)
            else:
                hi = min(hi, t)
    return hi - lo > 1e-9


def ref_pairs(tri: np.ndarray) -> set[tuple[int, int]]:
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    out = set()
    for i, j in itertools.combinations(range(len(tri)), 2):
        if (lo[i] <= hi[j]).all() and (lo[j] <= hi[i]).all():
            out.add((i, j))
    return out


# -- tests -----------------------------------------------------------------------


def test_cross3_matches_numpy() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    np.testing.assert_allclose(cross3(a, b), np.cross(a, b), rtol=1e-12, atol=1e-12)


def test_bvh_overlapping_pairs_equal_brute_force() -> None:
    rng = np.random.default_rng(2)
    c = rng.random((300, 3)) * 10
    tri = c[:, None, :] + rng.normal(scale=0.6, size=(300, 3, 3))
    i, j, complete = BVH.build(tri).overlapping_pairs(tol=0.0, budget=10**8)
    got = {(min(a, b), max(a, b)) for a, b in zip(i.tolist(), j.tolist())}
    assert complete
    assert got == ref_pairs(tri)
    assert len(got) == len(i)  # each pair once


def test_bvh_pair_budget_samples_and_reports_partial() -> None:
    rng = np.random.default_rng(3)
    tri = rng.random((2000, 3, 3))  # all in one unit cube: nearly every pair overlaps
    i, j, complete = BVH.build(tri).overlapping_pairs(tol=0.0, budget=20_000)
    assert not complete
    got = set(zip(i.tolist(), j.tolist()))
    assert 0 < len(got) < 200_000  # a sample of the ~2 million overlapping pairs
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    assert all((lo[a] <= hi[b]).all() and (lo[b] <= hi[a]).all() for a, b in list(got)[:500])


def test_first_hits_equal_brute_force() -> None:
    rng = np.random.default_rng(4)
    V, F, _ = saucer_solid(6)
    tri = V[F]
    o = rng.random((60, 3)) * [100, 100, 7]
    d = rng.normal(size=(60, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    excl = np.full(60, -1)
    t, hit, complete = BVH.build(tri).first_hits(tri, o, d, excl, t_min=1e-9, budget=10**8)
    assert complete
    assert np.isfinite(t).sum() > 15  # many rays start inside the solid and must hit it
    for r in range(60):
        best = min((s for k in range(len(tri)) if (s := ref_ray_triangle(o[r], d[r], tri[k])) is not None and s > 1e-9),
                   default=np.inf)
        assert t[r] == pytest.approx(best, rel=1e-9, abs=1e-9)
        if np.isfinite(best):
            assert ref_ray_triangle(o[r], d[r], tri[hit[r]]) == pytest.approx(best, rel=1e-9)


def test_pair_chunks_and_ray_threads_give_the_same_answers() -> None:
    V, F, _ = saucer_solid(100)  # ~39,000 triangles
    tri = V[F]
    bvh = BVH.build(tri)
    i1, j1, c1 = bvh.overlapping_pairs(tol=1e-7, budget=10**9)
    small = list(bvh.pair_chunks(tol=1e-7, budget=10**9, chunk=4096))
    assert c1 and bvh.pairs_complete and len(i1) > 100_000 and len(small) > 20
    assert max(len(p[0]) for p in small) <= 4096
    i2, j2 = np.concatenate([p[0] for p in small]), np.concatenate([p[1] for p in small])
    assert len(i2) == len(i1)
    assert set(zip(i1.tolist(), j1.tolist())) == set(zip(i2.tolist(), j2.tolist()))
    rng = np.random.default_rng(9)
    o = rng.random((3000, 3)) * [100, 100, 7]
    d = rng.normal(size=(3000, 3))
    excl = np.full(3000, -1)
    a = bvh.first_hits(tri, o, d, excl, t_min=1e-9, budget=10**9, workers=1)
    b = bvh.first_hits(tri, o, d, excl, t_min=1e-9, budget=10**9, workers=3)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_first_hits_respects_exclude_and_t_max() -> None:
    V, F = box((10, 10, 10))
    tri = V[F]
    o = np.array([[5.0, 5.0, 10.0]])  # on the top face (faces 2, 3)
    d = np.array([[0.0, 0.0, -1.0]])
    bvh = BVH.build(tri)
    t, hit, _ = bvh.first_hits(tri, o, d, np.array([2]), t_min=1e-6, budget=10**6)
    assert t[0] == pytest.approx(10.0) and hit[0] in (0, 1)
    t, hit, _ = bvh.first_hits(tri, o, d, np.array([2]), t_min=1e-6, budget=10**6, t_max=np.array([5.0]))
    assert np.isinf(t[0]) and hit[0] == -1


def test_ray_triangle_matches_reference() -> None:
    rng = np.random.default_rng(5)
    tri = rng.normal(size=(500, 3, 3))
    o = rng.normal(size=(500, 3)) * 3
    d = rng.normal(size=(500, 3))
    t = ray_triangle(o, d, tri)
    for k in range(500):
        ref = ref_ray_triangle(o[k], d[k], tri[k])
        if ref is None:
            assert np.isnan(t[k])
        else:
            assert t[k] == pytest.approx(ref, rel=1e-8, abs=1e-9)


def test_tri_tri_matches_clipping_reference_on_random_pairs() -> None:
    rng = np.random.default_rng(6)
    A = rng.normal(size=(3000, 3, 3))
    B = rng.normal(size=(3000, 3, 3)) + rng.normal(scale=0.5, size=(3000, 1, 3))
    fa = np.arange(9000).reshape(-1, 3)
    fb = fa + 9000
    got = tri_tri_intersect(A, B, fa, fb, 1e-12)
    ref = np.array([ref_tri_tri(A[k], B[k]) for k in range(3000)])
    assert 200 < ref.sum() < 2800  # a real mix of both answers
    assert (got == ref).all()


def test_tri_tri_shared_vertex_and_edge_cases() -> None:
    s = np.zeros(3)
    # a fan around s in the plane z = 0: neighbours, no overlap
    a = np.array([s, [1, 0, 0], [0, 1, 0]], float)
    b = np.array([s, [0, 1, 0], [-1, 0, 0]], float)
    # the same, but b's corner overlaps a's (coplanar, shared vertex)
    c = np.array([s, [1, 1, 0], [-1, 2, 0]], float)
    # shared vertex, b tilted down through a's interior
    d = np.array([s, [0.3, 0.3, 1], [0.3, 0.3, -1]], float)
    d[1:] += [0.2, 0.2, 0]
    # shared edge, folded flat onto the same side (coplanar fold)
    e = np.array([s, [1, 0, 0], [0.5, 0.5, 0]], float)
    # shared edge, bent up 90 degrees (an ordinary edge)
    f = np.array([s, [1, 0, 0], [0.5, 0, 1]], float)
    A = np.stack([a, a, a, a, a])
    B = np.stack([b, c, d, e, f])
    fa = np.tile([0, 1, 2], (5, 1))
    fb = np.array([[0, 2, 3], [0, 4, 5], [0, 6, 7], [0, 1, 8], [0, 1, 9]])
    np.testing.assert_array_equal(tri_tri_intersect(A, B, fa, fb, 1e-9), [False, True, True, True, False])


def test_tri_tri_coplanar_disjoint_and_overlapping() -> None:
    a = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)
    near = a + [2.5, 0, 0]  # apart
    touch = np.array([[2, 0, 0], [3, 0, 0], [2, 1, 0]], float) + [0, 0, 0]  # touches a's corner only
    over = a + [0.5, 0.5, 0]
    A = np.stack([a, a, a])
    B = np.stack([near, touch, over])
    fa = np.tile([0, 1, 2], (3, 1))
    fb = np.tile([3, 4, 5], (3, 1))
    np.testing.assert_array_equal(tri_tri_intersect(A, B, fa, fb, 1e-9), [False, False, True])


def test_components_match_scipy() -> None:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(8)
    for n, e in [(1, 0), (10, 0), (500, 300), (2000, 1900), (3000, 6000)]:
        u, v = rng.integers(0, n, e), rng.integers(0, n, e)
        lab = components(n, u, v)
        k, ref = connected_components(coo_matrix((np.ones(e), (u, v)), shape=(n, n)), directed=False)
        assert len(np.unique(lab)) == k
        # same partition: a bijection between labels
        pairs = set(zip(lab.tolist(), ref.tolist()))
        assert len(pairs) == k
        assert (lab <= np.arange(n)).all() and (lab[lab] == lab).all()  # labels are roots
    # a long path (diameter n) still converges
    n = 100_000
    lab = components(n, np.arange(n - 1), np.arange(1, n))
    assert (lab == 0).all()


def test_weld_merges_exact_duplicates_and_signed_zero() -> None:
    V = np.array([[0, 0, 0], [1, 2, 3], [-0.0, 0, 0], [1, 2, 3.0000001]])
    U, m = weld(V)
    assert len(U) == 3
    assert m[0] == m[2] and m[1] != m[3]


def test_topology_closed_box() -> None:
    V, F = box()
    t = topology(F, len(V))
    assert (t.edge_faces == 2).all() and len(t.edges) == 18
    assert not t.flipped_edges.any()
    assert (t.vertex_fans == 1).all()
    assert t.shells == 1
    area, _, vol = face_geometry(V, F)
    assert vol.sum() == pytest.approx(40 * 30 * 20)
    assert area.sum() == pytest.approx(2 * (40 * 30 + 40 * 20 + 30 * 20))


def test_topology_finds_pinched_vertex_flip_and_holes() -> None:
    V, F = box()
    # two boxes sharing one corner vertex: a pinched (non-manifold) vertex, one shell
    V2 = V + V[6]  # box 2's corner 0 sits on box 1's corner 6
    VV = np.concatenate([V, V2[1:]])
    F2 = np.where(F == 0, 6, F + 7)
    t = topology(np.concatenate([F, F2]), len(VV))
    assert t.vertex_fans[6] == 2 and (np.delete(t.vertex_fans, 6) == 1).all()
    assert t.shells == 1
    # one face flipped: its three edges are crossed the same way twice
    Ff = F.copy()
    Ff[3] = Ff[3][::-1]
    assert topology(Ff, 8).flipped_edges.sum() == 3
    # one face missing: three open edges
    assert (topology(F[1:], 8).edge_faces == 1).sum() == 3
