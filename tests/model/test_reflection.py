"""Tests of saucerfab.model.reflection: the solvers against the law of reflection in 3-D and their slow references.

``tests/model/test_mirror.py`` holds the solvers through :mod:`saucerfab.model.mirror`
for the scenes' cameras (the 2-D law, the quartic cross-check, a ray
trace). Here the module's own functions are called with random cameras all
around the cup: the full 3-D path P -> T -> Q obeys the law of reflection,
the vectorised solvers agree with the scalar references the module keeps,
and the results turn with the scene, do not depend on the chunking, and
keep float64.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from saucerfab.errors import ConfigError, GeometryError
from saucerfab.model.reflection import (
    _CHUNK,
    MirrorPiece,
    facet_frames,
    reference_conic,
    reference_facets,
    reflect_conic,
    reflect_facets,
    rotation_matrix,
    wrap_angle,
)

#: the mirrors: (a, b, rotation) of a smooth outline, or a prism's corners
CIRCLE = (0.4, 0.4, 0.0)
ELLIPSE = (0.5, 0.3, 35.0)


def prism_corners(sides: int, radius: float, rotation_deg: float) -> np.ndarray:
    t = math.radians(rotation_deg) + 2 * np.pi * np.arange(sides) / sides
    return radius * np.stack([np.cos(t), np.sin(t)], axis=1)


PENTAGON = prism_corners(5, 0.45, 10.0)
MIRRORS = ["circle", "ellipse", "pentagon"]


def solve(name: str, camera: tuple[float, float, float], xy: np.ndarray) -> list[MirrorPiece]:
    if name == "pentagon":
        return reflect_facets(PENTAGON, camera, xy)
    a, b, rot = CIRCLE if name == "circle" else ELLIPSE
    return [reflect_conic(a, b, rot, camera, xy)]


def reference(name: str, camera: tuple[float, float, float], q: tuple[float, float]) -> list:  # type: ignore[type-arg]
    if name == "pentagon":
        return reference_facets(PENTAGON, camera, q)
    a, b, rot = CIRCLE if name == "circle" else ELLIPSE
    return reference_conic(a, b, rot, camera, q)


def random_setup(seed: int, n: int = 400) -> tuple[tuple[float, float, float], np.ndarray, np.ndarray]:
    """A camera 1-8 outline radii away in any direction, saucer points around the cup, heights."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-np.pi, np.pi)
    dist = rng.uniform(1.0, 8.0)
    camera = (dist * math.cos(ang), dist * math.sin(ang), float(rng.uniform(0.5, 6.0)))
    pa = rng.uniform(-np.pi, np.pi, n)
    pr = rng.uniform(0.0, 2.5, n)
    xy = np.stack([pr * np.cos(pa), pr * np.sin(pa)], axis=1)
    return camera, xy, rng.uniform(-0.1, 0.3, n)


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def on_outline(name: str, t: np.ndarray) -> np.ndarray:
    """How far the points t (V, 2) are from the mirror's outline, in its own measure (0 on it)."""
    if name == "pentagon":
        verts, edges, normals = facet_frames(PENTAGON)
        # distance to the nearest facet line, for a point on a facet
        return np.min(np.abs(np.einsum("vkj,kj->vk", t[:, None, :] - verts[None], normals)), axis=1)
    a, b, rot = CIRCLE if name == "circle" else ELLIPSE
    local = t @ rotation_matrix(rot)
    return np.abs((local[:, 0] / a) ** 2 + (local[:, 1] / b) ** 2 - 1.0)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("name", MIRRORS)
def test_the_3d_path_obeys_the_law_of_reflection(name: str, seed: int) -> None:
    camera, xy, h = random_setup(seed)
    p3 = np.array(camera)
    count = 0
    for piece in solve(name, camera, xy):
        for arr in (piece.t_xy, piece.r_xy, piece.normal_xy, piece.t_frac, piece.t_z(h)):
            assert arr.dtype == np.float64 and np.isfinite(arr).all()
        assert piece.valid_xy.dtype == bool
        v = piece.valid_xy
        count += int(v.sum())
        t3 = np.concatenate([piece.t_xy, piece.t_z(h)[:, None]], axis=1)[v]
        q3 = np.concatenate([xy, h[:, None]], axis=1)[v]
        n3 = np.concatenate([piece.normal_xy, np.zeros((len(xy), 1))], axis=1)[v]
        np.testing.assert_allclose(np.linalg.norm(n3, axis=1), 1.0, atol=1e-12)
        assert (on_outline(name, piece.t_xy[v]) < 1e-12).all()  # T on the mirror
        assert (np.einsum("ij,ij->i", p3 - t3, n3) > 0).all()  # the camera in front of it
        d_in = unit(t3 - p3)
        d_out = unit(q3 - t3)
        # the mirrored incoming direction is the outgoing one: equal angles, in the plane of the normal
        np.testing.assert_allclose(d_out, d_in - 2 * np.einsum("ij,ij->i", d_in, n3)[:, None] * n3, atol=1e-9)
        # the virtual point R unfolds the broken path: straight on from P through T, |PR| = |PT| + |TQ|
        r3 = piece.reflected_vertices(h)[v]
        np.testing.assert_allclose(unit(r3 - p3), d_in, atol=1e-9)
        np.testing.assert_allclose(
            np.linalg.norm(r3 - p3, axis=1), np.linalg.norm(t3 - p3, axis=1) + np.linalg.norm(q3 - t3, axis=1),
            rtol=1e-12,
        )
    assert count > 40, "too few reflected points: the check would be vacuous"


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("name", MIRRORS)
def test_the_fast_solvers_agree_with_the_slow_references(name: str, seed: int) -> None:
    camera, xy, _ = random_setup(100 + seed, n=300)
    pieces = {pc.facet: pc for pc in solve(name, camera, xy)}
    seen = 0
    for i, q in enumerate(xy):
        ref = {k: (t, r, f) for k, t, r, f in reference(name, camera, (float(q[0]), float(q[1])))}
        assert {k for k, pc in pieces.items() if pc.valid_xy[i]} == set(ref), f"point {q}"
        for k, (t, r, f) in ref.items():
            np.testing.assert_allclose(pieces[k].t_xy[i], t, atol=1e-10)
            np.testing.assert_allclose(pieces[k].r_xy[i], r, atol=1e-10)
            assert abs(pieces[k].t_frac[i] - f) < 1e-10
            seen += 1
    assert seen > 25


def test_turning_the_scene_turns_the_solution() -> None:
    """Rotating camera, points and ellipse together rotates T, R and normals and keeps t_frac and validity."""
    camera, xy, _ = random_setup(7)
    turn = 37.0
    m = rotation_matrix(turn)
    cam2 = (*(np.array(camera[:2]) @ m.T), camera[2])
    a, b, rot = ELLIPSE
    base = reflect_conic(a, b, rot, camera, xy)
    turned = reflect_conic(a, b, rot + turn, cam2, xy @ m.T)
    np.testing.assert_array_equal(turned.valid_xy, base.valid_xy)
    v = base.valid_xy
    assert v.sum() > 40
    for got, want in ((turned.t_xy, base.t_xy), (turned.r_xy, base.r_xy), (turned.normal_xy, base.normal_xy)):
        np.testing.assert_allclose(got[v], want[v] @ m.T, atol=1e-12)
    np.testing.assert_allclose(turned.t_frac[v], base.t_frac[v], atol=1e-12)
    # and a circle does not care how it is turned
    r = CIRCLE[0]
    np.testing.assert_allclose(reflect_conic(r, r, 73.0, camera, xy).t_xy, reflect_conic(r, r, 0.0, camera, xy).t_xy,
                               atol=1e-12)


def test_results_do_not_depend_on_the_chunks() -> None:
    """The solver works in chunks of _CHUNK points; a point's answer must not depend on its chunk."""
    camera, _, _ = random_setup(11)
    rng = np.random.default_rng(12)
    xy = rng.uniform(-2.0, 2.0, (_CHUNK + 300, 2))
    a, b, rot = ELLIPSE
    whole = reflect_conic(a, b, rot, camera, xy)
    tail = reflect_conic(a, b, rot, camera, xy[_CHUNK - 100:])  # these points sit at other places of the chunks
    for got, want in ((tail.t_xy, whole.t_xy), (tail.r_xy, whole.r_xy), (tail.t_frac, whole.t_frac)):
        np.testing.assert_array_equal(got, want[_CHUNK - 100:])


def test_a_point_straight_in_front_of_a_facet_reflects_exactly() -> None:
    """A unit square facing -y: hand arithmetic for the plane mirror."""
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    camera = (0.0, -4.5, 2.0)
    pieces = reflect_facets(square, camera, np.array([[0.0, -1.5], [3.0, -1.5]]))
    assert [pc.facet for pc in pieces] == [0]  # only the bottom facet faces the camera
    pc = pieces[0]
    np.testing.assert_array_equal(pc.valid_xy, [True, False])  # the second's T falls beyond the facet's end
    np.testing.assert_allclose(pc.r_xy[0], [0.0, 0.5], atol=1e-15)  # -1.5 mirrored across y = -0.5
    np.testing.assert_allclose(pc.t_xy[0], [0.0, -0.5], atol=1e-15)
    assert pc.t_frac[0] == pytest.approx(4.0 / 5.0, abs=1e-15)
    assert reference_facets(square, camera, (0.0, -1.5)) == [(0, (0.0, -0.5), (0.0, 0.5), 0.8)]


def test_facet_frames_of_a_square() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # counter-clockwise
    verts, edges, normals = facet_frames(square)
    np.testing.assert_array_equal(verts, square)
    np.testing.assert_array_equal(edges, [[1, 0], [0, 1], [-1, 0], [0, -1]])
    np.testing.assert_array_equal(normals, [[0, -1], [1, 0], [0, 1], [-1, 0]])  # outward: the edge turned clockwise


def test_angles_and_rotations() -> None:
    np.testing.assert_allclose(wrap_angle(np.array([math.pi, -math.pi, 1.5 * math.pi, 0.25, -2.5 * math.pi])),
                               [-math.pi, -math.pi, -0.5 * math.pi, 0.25, -0.5 * math.pi], atol=1e-15)
    np.testing.assert_allclose(rotation_matrix(90.0) @ [1.0, 0.0], [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(rotation_matrix(-30.0) @ rotation_matrix(30.0), np.eye(2), atol=1e-15)


def test_mirror_piece_heights_by_hand() -> None:
    piece = MirrorPiece(
        t_xy=np.zeros((4, 2)), r_xy=np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0], [7.0, 8.0]]),
        normal_xy=np.tile([0.0, -1.0], (4, 1)), t_frac=np.array([0.5, 0.25, 0.5, 0.5]),
        valid_xy=np.array([True, True, True, False]), facet=-1, camera=(0.0, -5.0, 4.0),
    )
    h = np.array([[0.0, 2.0], [-4.0, 0.0]])  # an (N, N) grid is read flattened
    np.testing.assert_array_equal(piece.t_z(h), [2.0, 3.5, 0.0, 2.0])  # 4 + (h - 4) * t_frac
    # the rim and the bottom themselves count as the wall; the invalid entry stays invalid
    np.testing.assert_array_equal(piece.valid(h, cup_height=3.5), [True, True, True, False])
    np.testing.assert_array_equal(piece.valid(h, cup_height=3.0), [True, False, True, False])
    np.testing.assert_array_equal(piece.reflected_vertices(h)[:, 2], [0.0, 2.0, -4.0, 0.0])
    with pytest.raises(ConfigError, match="pass one height per saucer vertex"):
        piece.reflected_vertices(np.zeros(5))


@pytest.mark.parametrize("camera", [(0.0, -5.0), (0.0, math.nan, 5.0), (math.inf, -5.0, 5.0)])
def test_a_camera_must_be_three_finite_coordinates(camera: tuple[float, ...]) -> None:
    xy = np.array([[0.0, -1.0]])
    for call in (lambda: reflect_conic(0.4, 0.4, 0.0, camera, xy), lambda: reflect_facets(PENTAGON, camera, xy)):
        with pytest.raises(GeometryError, match="the camera must be 3 finite coordinates"):
            call()  # type: ignore[no-untyped-call]
