"""Tests of saucerfab.model.mirror: the reflection law, the cross-checks, a brute-force ray trace.

The ray trace here shares nothing with the module under test: it follows
camera rays in 3-D, intersects them with the cup wall analytically (circle,
ellipse) or facet by facet (prism), reflects them with the true 3-D normal
and intersects the reflected rays with a triangulated wavy saucer. The
module's mapping must send every point hit back to the pixel the ray came
from, and its T must be the wall point the ray hit.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from saucerfab.errors import ConfigError, GeometryError
from saucerfab.model import mirror
from saucerfab.model.camera import Camera
from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup
from saucerfab.model.heightfield import base_shape, make_grid, triangulate
from saucerfab.model.scene import Saucer, Scene

CIRCLE = CircleCup(0.4, 1.0)
ELLIPSE = EllipseCup((0.45, 0.33), 20.0, 1.0)
HEXAGON = PrismCup(6, 0.45, 30.0, 1.0)
CUPS = {"circle": CIRCLE, "ellipse": ELLIPSE, "hexagon": HEXAGON}


def scene_with(cup, **kw) -> Scene:  # type: ignore[no-untyped-def]
    return Scene(cup=cup, **kw)


def saucer_xy(scene: Scene, n: int = 40) -> np.ndarray:
    return make_grid(replace(scene.saucer, resolution=n)).xy()


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


# --------------------------------------------------------------------------- reflection law


def check_laws(piece: mirror.MirrorPiece, xy: np.ndarray, heights: np.ndarray, cup) -> int:  # type: ignore[no-untyped-def]
    """Assert the reflection law, collinearity and |TQ| = |TR| on the valid points; return their count."""
    v = piece.valid_xy
    p3 = np.array(piece.camera)
    p = p3[:2]
    t, q, r, n = piece.t_xy[v], xy[v], piece.r_xy[v], piece.normal_xy[v]
    # T lies on the outline and n is its outward unit normal
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    if isinstance(cup, CircleCup):
        np.testing.assert_allclose(np.linalg.norm(t, axis=1), cup.radius, atol=1e-12)
        np.testing.assert_allclose(n, t / cup.radius, atol=1e-12)
    elif isinstance(cup, EllipseCup):
        th = math.radians(cup.rotation_deg)
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        loc = t @ rot
        a, b = cup.semi_axes
        np.testing.assert_allclose((loc[:, 0] / a) ** 2 + (loc[:, 1] / b) ** 2, 1.0, atol=1e-12)
        grad = unit(np.stack([loc[:, 0] / a**2, loc[:, 1] / b**2], axis=1)) @ rot.T
        np.testing.assert_allclose(n, grad, atol=1e-12)
    # angle of incidence == angle of reflection, on opposite sides of the normal
    up, uq = unit(p - t), unit(q - t)
    ang_in = np.arctan2(np.abs(cross2(n, up)), np.einsum("ij,ij->i", n, up))
    ang_out = np.arctan2(np.abs(cross2(n, uq)), np.einsum("ij,ij->i", n, uq))
    assert np.abs(ang_in - ang_out).max(initial=0.0) < 1e-9
    assert (cross2(n, up) * cross2(n, uq) <= 1e-15).all()
    assert (ang_in < math.pi / 2).all() and (ang_out < math.pi / 2).all()
    # |TQ| == |TR| and R is Q mirrored across the tangent line (same foot point)
    np.testing.assert_allclose(np.linalg.norm(q - t, axis=1), np.linalg.norm(r - t, axis=1), atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", q + r - 2 * t, n), 0.0, atol=1e-12)
    # P, T, R collinear in 3-D, with R at Q's height and T at t_z
    h = heights[v]
    t3 = np.concatenate([t, piece.t_z(heights)[v][:, None]], axis=1)
    r3 = np.concatenate([r, h[:, None]], axis=1)
    c = np.cross(t3 - p3, r3 - p3)
    sine = np.linalg.norm(c, axis=1) / (np.linalg.norm(t3 - p3, axis=1) * np.linalg.norm(r3 - p3, axis=1))
    assert sine.max(initial=0.0) < 1e-9  # ~1e-16 except at grazing incidence
    # and T between P and R
    assert ((piece.t_frac[v] > 0) & (piece.t_frac[v] < 1)).all()
    return int(v.sum())


@pytest.mark.parametrize("name", sorted(CUPS))
def test_reflection_laws_on_the_saucer(name: str) -> None:
    scene = scene_with(CUPS[name])
    xy = saucer_xy(scene)
    heights = base_shape("waves", 40).ravel()
    pieces = mirror.reflect(scene, xy)
    total = sum(check_laws(pc, xy, heights, scene.cup) for pc in pieces)
    assert total > 100  # the check is not vacuous
    for pc in pieces:
        for arr in (pc.t_xy, pc.r_xy, pc.normal_xy, pc.t_frac):
            assert np.isfinite(arr).all()


@settings(max_examples=40, deadline=None)
@given(
    cam_angle=st.floats(-math.pi, math.pi),
    cam_dist=st.floats(0.5, 20.0),
    a=st.floats(0.1, 1.0),
    b=st.floats(0.1, 1.0),
    rot=st.floats(-180.0, 180.0),
    seed=st.integers(0, 2**31),
)
def test_reflection_laws_random_scenes(
    cam_angle: float, cam_dist: float, a: float, b: float, rot: float, seed: int
) -> None:
    """Random cameras, cups and points anywhere around the cup (not only the saucer)."""
    rng = np.random.default_rng(seed)
    ell = EllipseCup((a, b), rot, 1.0)
    cam_r = max(a, b) * (1.0 + cam_dist)
    camera = (cam_r * math.cos(cam_angle), cam_r * math.sin(cam_angle), float(rng.uniform(0.2, 6)))
    ang = rng.uniform(-math.pi, math.pi, 300)
    dist = max(a, b) * rng.uniform(0.0, 4.0, 300)
    xy = np.stack([dist * np.cos(ang), dist * np.sin(ang)], axis=1)
    heights = rng.uniform(0.0, 0.2, 300)
    for cup, piece in (
        (ell, mirror.reflect_bisection(ell, camera, xy)),
        (CircleCup(a), mirror.reflect_bisection(CircleCup(a), camera, xy)),
    ):
        check_laws(piece, xy, heights, cup)
        assert not (piece.valid_xy & cup.contains(xy)).any()
        assert np.isfinite(piece.r_xy).all() and np.isfinite(piece.t_frac).all()
    prism = PrismCup(int(rng.integers(3, 9)), max(a, b), rot, 1.0)
    if not prism.contains(np.array(camera[:2])):
        for piece in mirror.reflect_prism(prism, camera, xy):
            check_laws(piece, xy, heights, prism)
            assert not (piece.valid_xy & prism.contains(xy)).any()


# --------------------------------------------------------------------------- cross-checks


def test_bisection_and_quartic_agree_for_the_circle() -> None:
    scene = scene_with(CIRCLE)
    rng = np.random.default_rng(3)
    xy = np.concatenate(
        [saucer_xy(scene, 30), rng.uniform(-1.5, 1.5, (2000, 2))], axis=0
    )
    bis = mirror.reflect_bisection(CIRCLE, scene.camera, xy)
    qua = mirror.reflect_circle_quartic(CIRCLE, scene.camera, xy)
    # the quartic leaves out only points (nearly) on the line OP, where it degenerates
    on_line = np.abs(xy[:, 0]) < 1e-6
    np.testing.assert_array_equal(qua.valid_xy, bis.valid_xy & ~on_line)
    both = qua.valid_xy
    assert both.sum() > 1500
    np.testing.assert_allclose(qua.t_xy[both], bis.t_xy[both], atol=1e-9)
    np.testing.assert_allclose(qua.r_xy[both], bis.r_xy[both], atol=1e-9)
    np.testing.assert_allclose(qua.t_frac[both], bis.t_frac[both], atol=1e-9)


@pytest.mark.parametrize("name", sorted(CUPS))
def test_vectorised_matches_the_scalar_reference(name: str) -> None:
    scene = scene_with(CUPS[name])
    rng = np.random.default_rng(5)
    xy = np.concatenate([saucer_xy(scene, 12), rng.uniform(-1.5, 1.5, (200, 2))])
    pieces = {pc.facet: pc for pc in mirror.reflect(scene, xy)}
    for i, q in enumerate(xy):
        ref = {k: (t, r, f) for k, t, r, f in mirror.reflect_point_reference(scene.cup, scene.camera, q)}
        valid = {k for k, pc in pieces.items() if pc.valid_xy[i]}
        assert valid == set(ref), f"point {q}: vectorised {valid}, reference {set(ref)}"
        for k, (t, r, f) in ref.items():
            np.testing.assert_allclose(pieces[k].t_xy[i], t, atol=1e-10)
            np.testing.assert_allclose(pieces[k].r_xy[i], r, atol=1e-10)
            assert abs(pieces[k].t_frac[i] - f) < 1e-10


def test_prism_pieces_are_the_facets_the_camera_sees() -> None:
    for rot in (0.0, 30.0, 17.0):
        cup = PrismCup(6, 0.45, rot, 1.0)
        scene = scene_with(cup)
        verts, _, normals = mirror.prism_facets(cup)
        p = np.array(scene.camera[:2])
        seen = [k for k in range(6) if (p - verts[k]) @ normals[k] > 0]
        pieces = mirror.reflect(scene, saucer_xy(scene, 10))
        assert [pc.facet for pc in pieces] == seen
        assert 2 <= len(seen) <= 3
        for pc in pieces:  # a plane mirror: one normal for the whole facet
            np.testing.assert_allclose(pc.normal_xy, np.broadcast_to(normals[pc.facet], pc.normal_xy.shape))


# --------------------------------------------------------------------------- degenerate cases and validity


def test_point_on_the_line_op_in_front_of_the_cup() -> None:
    camera = (0.0, -5.5, 5.0)
    piece = mirror.reflect_bisection(CIRCLE, camera, np.array([[0.0, -1.0]]))
    assert piece.valid_xy[0]
    np.testing.assert_allclose(piece.t_xy[0], [0.0, -0.4], atol=1e-12)
    np.testing.assert_allclose(piece.r_xy[0], [0.0, 0.2], atol=1e-12)  # -1 mirrored across y = -0.4
    np.testing.assert_allclose(piece.t_frac[0], 5.1 / 5.7, atol=1e-12)
    qua = mirror.reflect_circle_quartic(CIRCLE, camera, np.array([[0.0, -1.0]]))
    assert not qua.valid_xy[0] and np.isfinite(qua.r_xy).all()  # degenerate there: flagged, no NaN


@pytest.mark.parametrize("name", sorted(CUPS))
def test_invalid_points_are_flagged_and_finite(name: str) -> None:
    cup = CUPS[name]
    camera = (0.0, -5.5, 5.0)
    pts = np.array(
        [
            [0.0, 0.0],  # the cup's centre: inside
            [0.05, -0.1],  # inside
            [0.0, 1.2],  # on the line OP behind the cup: only the back of the cup faces it
            [-0.3, 0.9],  # behind the cup
            [0.0, -1.0],  # in front: valid
        ]
    )
    if name == "hexagon":
        # a facet faces the camera: with a corner there instead (rotation 30),
        # points on the axis are seen in neither facet
        pieces = mirror.reflect_prism(replace(cup, rotation_deg=0.0), camera, pts)
    else:
        pieces = mirror.reflect(scene_with(cup), pts)
    valid = np.zeros(len(pts), bool)
    for pc in pieces:
        valid |= pc.valid_xy
        assert np.isfinite(pc.t_xy).all() and np.isfinite(pc.r_xy).all() and np.isfinite(pc.t_frac).all()
    np.testing.assert_array_equal(valid, [False, False, False, False, True])


def test_point_on_the_outline_is_invalid_not_nan() -> None:
    pts = np.array([[0.0, -0.4], [0.4 * math.cos(-1.2), 0.4 * math.sin(-1.2)]])
    piece = mirror.reflect_bisection(CIRCLE, (0.0, -5.5, 5.0), pts)
    assert not piece.valid_xy.any()
    assert np.isfinite(piece.r_xy).all() and np.isfinite(piece.t_frac).all()


def test_t_above_the_rim_or_below_the_bottom_is_invalid() -> None:
    xy = np.array([[0.0, -1.0], [0.2, -0.8]])
    piece = mirror.reflect_bisection(CIRCLE, (0.0, -5.5, 5.0), xy)
    h = np.zeros(2)
    tz = piece.t_z(h)
    assert (tz > 0).all()
    assert piece.valid(h, cup_height=1.0).all()
    assert not piece.valid(h, cup_height=float(tz.min()) * 0.99).any()  # rim below T: invalid
    # a point far below the saucer sends T under the cup's bottom
    low = np.full(2, -20.0)
    assert (piece.t_z(low) < 0).all() and not piece.valid(low, 1.0).any()
    with pytest.raises(ConfigError, match="heights hold 3 values"):
        piece.t_z(np.zeros(3))


def test_camera_inside_the_cup_is_a_geometry_error() -> None:
    xy = np.array([[0.0, -1.0]])
    for fn, cup in (
        (mirror.reflect_bisection, CIRCLE),
        (mirror.reflect_circle_quartic, CIRCLE),
        (mirror.reflect_bisection, ELLIPSE),
        (mirror.reflect_prism, HEXAGON),
    ):
        with pytest.raises(GeometryError, match="inside"):
            fn(cup, (0.05, 0.0, 2.0), xy)  # type: ignore[operator]
    with pytest.raises(GeometryError, match="inside"):
        mirror.reflect_point_reference(CIRCLE, (0.0, 0.1, 1.0), (0.0, -1.0))


def test_bad_points_raise() -> None:
    scene = scene_with(CIRCLE)
    with pytest.raises(GeometryError, match="NaN"):
        mirror.reflect(scene, np.array([[0.0, -1.0], [np.nan, -1.0]]))
    with pytest.raises(ConfigError, match=r"shape \(V, 2\)"):
        mirror.reflect(scene, np.zeros((4, 3)))
    for cup in CUPS.values():  # no points: empty pieces, no error
        for pc in mirror.reflect(scene_with(cup), np.zeros((0, 2))):
            assert pc.r_xy.shape == (0, 2) and pc.valid(np.zeros(0), 1.0).shape == (0,)


# --------------------------------------------------------------------------- mesh helpers


@pytest.mark.parametrize("name", sorted(CUPS))
def test_reflected_mesh_keeps_faces_with_three_valid_vertices(name: str) -> None:
    scene = scene_with(CUPS[name])
    n = 20
    heights = base_shape("waves", n)
    parts = mirror.reflected_mesh(scene, heights)
    pieces = mirror.reflect(scene, saucer_xy(scene, n))
    faces = triangulate(n)
    assert [m.facet for m in parts] == [pc.facet for pc in pieces]
    for m, pc in zip(parts, pieces):
        vv = pc.valid(heights.ravel(), scene.cup.height)
        np.testing.assert_array_equal(m.vertex_valid, vv)
        np.testing.assert_array_equal(m.faces, faces[m.face_ids])
        np.testing.assert_array_equal(m.face_ids, np.nonzero(vv[faces].all(axis=1))[0])
        np.testing.assert_allclose(m.vertices[:, :2], pc.r_xy)
        np.testing.assert_allclose(m.vertices[:, 2], heights.ravel())
        assert m.faces.dtype == np.int64
    assert sum(len(m.faces) for m in parts) > 0
    with pytest.raises(ConfigError, match="square"):
        mirror.reflected_mesh(scene, np.zeros((4, 5)))


def test_visible_region() -> None:
    scene = scene_with(CIRCLE)
    n = 16
    region = mirror.visible_region(scene, n)
    assert region.shape == (n, n) and region.dtype == bool
    assert 0.5 < region.mean() < 1.0  # most of the saucer is in the reflection, not all of it
    no_frame = mirror.visible_region(scene, n, in_frame=False)
    assert (region <= no_frame).all()
    # brute force: the same samples are those whose R projects inside the frame
    cam = Camera.from_scene(scene, "reflected")
    pc = mirror.reflect(scene, saucer_xy(scene, n))[0]
    ndc = cam.project(pc.reflected_vertices(np.zeros(n * n)))
    inside = (np.abs(ndc[:, 0]) <= 1) & (np.abs(ndc[:, 1]) <= 1) & pc.valid(np.zeros(n * n), 1.0)
    np.testing.assert_array_equal(region.ravel(), inside)
    # a prism split by facets: the parts cover the whole region
    hexa = scene_with(PrismCup(6, 0.45, 0.0, 1.0))
    facets = [pc.facet for pc in mirror.reflect(hexa, saucer_xy(hexa, 4))]
    whole = mirror.visible_region(hexa, n)
    parts = [mirror.visible_region(hexa, n, facets=[k]) for k in facets]
    np.testing.assert_array_equal(np.logical_or.reduce(parts), whole)
    _, _, normals = mirror.prism_facets(hexa.cup)  # type: ignore[arg-type]
    front = facets.index(int(np.argmin(normals[:, 1])))  # the facet facing -y, the camera
    assert parts[front].mean() > 0.3
    with pytest.raises(ConfigError, match="expected"):
        mirror.visible_region(scene, n, np.zeros((3, 3)))


# --------------------------------------------------------------------------- brute-force ray trace


class WavySaucer:
    """A triangulated heightfield over the saucer rectangle, evaluated like the mesh.

    Heights are interpolated linearly on the two triangles of each grid cell
    (split along the (i, j) -> (i+1, j+1) diagonal, as ``triangulate``), so
    the ray hits the same surface a renderer of the saucer mesh would show.
    """

    def __init__(self, saucer: Saucer, n: int) -> None:
        self.x0, self.x1 = saucer.x_range
        self.y0, self.y1 = saucer.y_range
        self.n = n
        self.h = base_shape("waves", n) + 0.02 * base_shape("smooth_random", n, seed=4)

    def z(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface height at (x, y); NaN outside the rectangle."""
        u = (x - self.x0) / (self.x1 - self.x0) * (self.n - 1)
        v = (y - self.y0) / (self.y1 - self.y0) * (self.n - 1)
        inside = (u >= 0) & (u <= self.n - 1) & (v >= 0) & (v <= self.n - 1)
        j = np.clip(np.floor(u).astype(int), 0, self.n - 2)
        i = np.clip(np.floor(v).astype(int), 0, self.n - 2)
        fx, fy = u - j, v - i
        ha, hb = self.h[i, j], self.h[i, j + 1]
        hc, hd = self.h[i + 1, j + 1], self.h[i + 1, j]
        lower = ha + fx * (hb - ha) + fy * (hc - hb)  # triangle (a, b, c): fx >= fy
        upper = ha + fy * (hd - ha) + fx * (hc - hd)  # triangle (a, c, d): fy >= fx
        return np.where(inside, np.where(fx >= fy, lower, upper), np.nan)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hit of rays o + s d (M, 3) going down; returns points (M, 3) and a hit mask (M,)."""
        zmin, zmax = float(self.h.min()), float(self.h.max())
        s0 = np.maximum((zmax - o[:, 2]) / d[:, 2], 0.0)
        s1 = (zmin - 1e-9 - o[:, 2]) / d[:, 2]
        k = 400
        s = s0[:, None] + (s1 - s0)[:, None] * np.linspace(0, 1, k)[None, :]
        pts = o[:, None, :] + s[..., None] * d[:, None, :]
        g = pts[..., 2] - self.z(pts[..., 0], pts[..., 1])  # > 0 above the surface
        below = g <= 0  # NaN (off the saucer) compares False
        hit = below.any(axis=1)
        first = np.argmax(below, axis=1)
        rows = np.arange(len(o))
        lo = s[rows, np.maximum(first - 1, 0)]
        hi = s[rows, first]
        # the sample before the first one below must be above (not off the saucer)
        hit &= (first > 0) & (g[rows, np.maximum(first - 1, 0)] > 0)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            p = o + mid[:, None] * d
            gm = p[:, 2] - self.z(p[:, 0], p[:, 1])
            above = gm > 0
            lo = np.where(above, mid, lo)
            hi = np.where(above, hi, mid)
        pts = o + (0.5 * (lo + hi))[:, None] * d
        return pts, hit


def hit_cup(cup, eye: np.ndarray, d: np.ndarray, *, infinite: bool = False):  # type: ignore[no-untyped-def]
    """First intersection of rays eye + s d with the cup wall (3-D).

    Returns hit points (M, 3), outward unit normals (M, 3), a hit mask (M,)
    and the facet index of each hit (-1 for smooth cups). With ``infinite``
    the wall has no rim or bottom.
    """
    m = d.shape[0]
    if isinstance(cup, PrismCup):
        verts, _, normals = mirror.prism_facets(cup)
        best = np.full(m, np.inf)
        facet = np.full(m, -1)
        for k in range(cup.sides):
            v0, v1, n = verts[k], verts[(k + 1) % cup.sides], normals[k]
            den = d[:, :2] @ n
            s = ((v0 - eye[:2]) @ n) / np.where(den < 0, den, -1.0)
            pts = eye[:2] + s[:, None] * d[:, :2]
            lam = ((pts - v0) @ (v1 - v0)) / float((v1 - v0) @ (v1 - v0))
            ok = (den < 0) & (s > 0) & (lam >= 0) & (lam <= 1) & (s < best)
            best = np.where(ok, s, best)
            facet = np.where(ok, k, facet)
        hit = np.isfinite(best)
        s = np.where(hit, best, 0.0)
        nrm2 = np.where(hit[:, None], normals[np.maximum(facet, 0)], 0.0)
    else:
        if isinstance(cup, CircleCup):
            a = b = cup.radius
            th = 0.0
        else:
            (a, b), th = cup.semi_axes, math.radians(cup.rotation_deg)
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        o = (eye[:2] @ rot) / np.array([a, b])
        dd = (d[:, :2] @ rot) / np.array([a, b])
        qa = np.einsum("ij,ij->i", dd, dd)
        qb = dd @ o
        qc = float(o @ o) - 1.0
        disc = qb * qb - qa * qc
        hit = disc > 0
        s = (-qb - np.sqrt(np.where(hit, disc, 0.0))) / qa
        loc = o + s[:, None] * dd  # on the unit circle
        nrm2 = unit(np.stack([loc[:, 0] / a, loc[:, 1] / b], axis=1)) @ rot.T
        facet = np.full(m, -1)
        hit &= s > 0
    pts = eye + s[:, None] * d
    if not infinite:
        hit &= (pts[:, 2] >= 0) & (pts[:, 2] <= cup.height)
    nrm = np.concatenate([nrm2, np.zeros((m, 1))], axis=1)
    return pts, nrm, hit, facet


def ray_trace(scene: Scene, stride: int, *, infinite: bool = False):  # type: ignore[no-untyped-def]
    """Trace reflected-view pixel rays at 512x512 (every ``stride``-th row and column).

    Returns (pixel centres (M, 2) as (column, row), cup hits (M, 3), saucer
    hits (M, 3), facets (M,)) for the rays that reflect off the cup and land
    on the saucer.
    """
    cam = Camera.from_scene(scene, "reflected").with_size(512)
    eye, dirs = cam.rays()
    rows, cols = np.meshgrid(np.arange(0, 512, stride), np.arange(0, 512, stride), indexing="ij")
    d = dirs[rows, cols].reshape(-1, 3)
    pix = np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)
    wall, nrm, hit_wall, facet = hit_cup(scene.cup, eye, d, infinite=infinite)
    refl = d - 2.0 * np.einsum("ij,ij->i", d, nrm)[:, None] * nrm  # true 3-D reflection
    saucer = WavySaucer(scene.saucer, 48)
    q, hit_saucer = saucer.intersect(wall, refl)
    ok = hit_wall & hit_saucer
    return pix[ok], wall[ok], q[ok], facet[ok]


@pytest.mark.parametrize("name", sorted(CUPS))
def test_brute_force_ray_trace_lands_where_the_module_maps(name: str) -> None:
    scene = scene_with(CUPS[name])
    pix, wall, q, facet = ray_trace(scene, stride=4)
    assert len(q) > 1500, f"only {len(q)} rays reflected onto the saucer"
    cam = Camera.from_scene(scene, "reflected").with_size(512)
    pieces = {pc.facet: pc for pc in mirror.reflect(scene, q[:, :2])}
    if name == "hexagon":
        assert len(set(facet.tolist())) >= 2  # rays met more than one facet
    worst_px, worst_t = 0.0, 0.0
    for k, pc in pieces.items():
        sel = facet == k
        if not sel.any():
            continue
        h = q[sel, 2]
        # every point a ray reaches is in the module's reflection ...
        assert pc.valid(q[:, 2], scene.cup.height)[sel].all()
        # ... its R projects onto the pixel the ray left through ...
        r = pc.reflected_vertices(q[:, 2])[sel]
        px = cam.ndc_to_pixel(cam.project(r)[:, :2])
        worst_px = max(worst_px, float(np.linalg.norm(px - pix[sel], axis=1).max()))
        # ... and its T is the wall point the ray hit
        t3 = np.concatenate([pc.t_xy[sel], pc.t_z(q[:, 2])[sel][:, None]], axis=1)
        worst_t = max(worst_t, float(np.abs(t3 - wall[sel]).max()))
        assert np.isfinite(h).all()
    assert set(facet.tolist()) <= set(pieces)
    assert worst_px < 1e-6, f"mapping off by {worst_px} pixels"
    assert worst_t < 1e-9, f"T off by {worst_t} model units"


def test_ray_trace_above_the_rim_agrees_with_the_validity_mask() -> None:
    """With a short cup, rays hitting the (infinite) wall above the rim must be invalid in the module."""
    cup = CircleCup(0.4, 0.25)
    scene = scene_with(cup)
    pix, wall, q, _ = ray_trace(scene, stride=8, infinite=True)
    valid = mirror.reflect(scene, q[:, :2])[0].valid(q[:, 2], cup.height)
    above = wall[:, 2] > cup.height
    assert above.sum() > 100 and (~above).sum() > 100
    margin = np.abs(wall[:, 2] - cup.height) > 1e-9
    np.testing.assert_array_equal(valid[margin], ~above[margin])
