"""The reflection solvers: saucer points reflected in one convex vertical mirror (paper, section 3.2).

The cup is a vertical cylinder over a convex outline C (circle, ellipse, or a
regular n-gon prism whose facets are plane mirrors), standing on z = 0 with
its axis through the origin. Its normal is horizontal everywhere, so a
reflection keeps the vertical component of a ray's direction and the problem
is two-dimensional in xy:

* P is the camera, Q a saucer point, T the point on C where the ray from P
  reflects to reach Q, and R the *virtual point*: Q mirrored across the
  tangent line of C at T. R keeps Q's height.
* The viewer sees Q at R: P, T and R are collinear in xy, and in 3-D too once
  T is given its height ``P_z + (h - P_z) * |P T| / |P R|`` (reflection across
  a vertical plane keeps lengths and heights, so the broken path P -> T -> Q
  unfolds into the straight segment P -> R).

Because saucer vertices move only in z, the xy part (T, R, validity) is
computed once per design (:func:`saucerfab.model.mirror.reflect` asks the scene's
cup, whose ``reflect`` method calls a solver here); heights enter only through
:meth:`MirrorPiece.t_z`, :meth:`MirrorPiece.valid` and
:meth:`MirrorPiece.reflected_vertices`, which are cheap.

Smooth cups are solved by bisection on the outline parameter (the paper's
bisection on the angle POT, generalised). Parametrise C counter-clockwise by
``t`` (the polar angle for a circle, the eccentric angle for an ellipse), with
unit tangent ``tau(t)``. On the arc of C that both P and Q see (both in front
of the tangent line), the residual of the reflection law

    f(t) = < unit(P - T) + unit(Q - T), tau(t) >

is positive at the arc's clockwise end, negative at its counter-clockwise
end, and changes sign exactly once: with ``psi_X`` the angle from ``tau`` to
``X - T``, both ``psi_P`` and ``psi_Q`` strictly decrease along a convex
outline (``d psi / ds = sin(psi) / |X T| - curvature < 0``), which is the
content of the paper's Proposition 3.1, and ``sign f = sign(psi_P + psi_Q + pi)``.
The doubly-visible arc is exact in the eccentric angle because tangency and
the sides of a line survive the affine map that takes the ellipse to the unit
circle: the tangent points from X are at ``atan2(X') +- arccos(1 / |X'|)``
with ``X' = (x / a, y / b)`` in the cup's local frame.

Validity here is about the mirror only (Q outside the cup, T on the part of
the wall the camera sees, between bottom and rim). Which of several saucer
points along one reflected ray is seen is the reflected view's z-buffer's
business: depth along P -> R orders points as their distance from T along
the reflected ray does. A saucer rising between the camera and the cup wall
(the direct path P -> T blocked) is not modelled, as in the paper.

Eberly's analytic solution (a quartic) is kept for circles as an independent
cross-check (:func:`circle_quartic`), and a scalar, pure-Python bisection
(:func:`reference_conic`, :func:`reference_facets`) is the slow, obvious
reference that the tests and the benchmark compare with.

The solvers take the outline's numbers (semi-axes, corners), not cup
objects: :mod:`saucerfab.model.cups` imports them and each cup class calls its
solver, so this module knows no cup class (and imports none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from saucerfab.errors import ConfigError, GeometryError

#: bisection steps of the vectorised solver: the bracket starts below pi wide,
#: so after 18 halvings it is under 1.2e-5 rad; the false-position steps that
#: follow (error about |f''/f'| times the width times the previous error)
#: then take T to float64 round-off. Tests hold it to the 55-step scalar
#: bisection of reflect_point_reference.
BISECTION_STEPS = 18

#: false-position steps after the bisection (see _bisect)
_SECANT_STEPS = 2

#: steps of the scalar reference: pi / 2**55 < 1e-16 rad, below float64
#: resolution of the angle, so plain bisection alone reaches round-off
REFERENCE_STEPS = 55

#: smallest |P T| or |Q T| we divide by (model units); only reached when Q
#: lies on the outline, where the result is marked invalid anyway
_TINY = 1e-300

#: points per chunk of the vectorised solver (see _reflect_conic)
_CHUNK = 4096


@dataclass(frozen=True, eq=False)
class MirrorPiece:
    """The reflection of V saucer points in one smooth mirror.

    A piece is the whole outline of a circle or ellipse cup, or one facet of
    a prism. All arrays are float64 (``valid_xy`` bool), in model units.

    Attributes:
        t_xy: (V, 2) T, the reflection point on the cup outline.
        r_xy: (V, 2) R, Q mirrored across the tangent line at T.
        normal_xy: (V, 2) outward unit normal of the cup at T.
        t_frac: (V,) ``|P_xy T_xy| / |P_xy R_xy|`` in (0, 1): how far along the
            straight line P -> R the mirror point T lies.
        valid_xy: (V,) bool: Q outside the cup, T on the part of the outline
            the camera sees, Q in front of the tangent line at T, and for a
            prism T within the facet. Entries where it is False hold finite
            but meaningless values.
        facet: the prism facet index (its outline edge from vertex ``facet``
            to ``facet + 1``), or -1 for a smooth cup.
        camera: (3,) the camera position P the piece was computed for.
    """

    t_xy: np.ndarray
    r_xy: np.ndarray
    normal_xy: np.ndarray
    t_frac: np.ndarray
    valid_xy: np.ndarray
    facet: int
    camera: tuple[float, float, float]

    def _h(self, heights: np.ndarray) -> np.ndarray:
        h = np.asarray(heights, dtype=np.float64).reshape(-1)
        if h.shape[0] != self.t_frac.shape[0]:
            raise ConfigError(
                f"heights hold {h.shape[0]} values but the mirror piece has "
                f"{self.t_frac.shape[0]} vertices; pass one height per saucer vertex"
            )
        return h

    def t_z(self, heights: np.ndarray) -> np.ndarray:
        """Height of T, (V,), for vertex heights (V,) (or (N, N), flattened).

        P, T and R are collinear in 3-D with R at the vertex's height, so T's
        height interpolates between P_z and h by ``t_frac``.
        """
        pz = self.camera[2]
        return pz + (self._h(heights) - pz) * self.t_frac

    def valid(self, heights: np.ndarray, cup_height: float) -> np.ndarray:
        """(V,) bool: ``valid_xy`` and T between the cup's bottom and rim.

        Args:
            heights: (V,) vertex heights, model units.
            cup_height: height of the mirror wall, model units.
        """
        tz = self.t_z(heights)
        return self.valid_xy & (tz >= 0.0) & (tz <= cup_height)

    def reflected_vertices(self, heights: np.ndarray) -> np.ndarray:
        """(V, 3) virtual points R = (r_x, r_y, h) for vertex heights (V,)."""
        h = self._h(heights)
        return np.concatenate([self.r_xy, h[:, None]], axis=1)


# --------------------------------------------------------------------------- helpers


def _check_points(xy: np.ndarray) -> np.ndarray:
    pts = np.asarray(xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ConfigError(f"saucer points must have shape (V, 2), got {pts.shape}")
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise GeometryError(f"{bad} saucer point(s) hold NaN or infinite coordinates; fix the grid")
    return pts


def _check_camera(camera: tuple[float, ...] | np.ndarray) -> tuple[float, float, float]:
    cam = tuple(float(c) for c in np.asarray(camera, dtype=np.float64).reshape(-1))
    if len(cam) != 3 or not all(math.isfinite(c) for c in cam):
        raise GeometryError(f"the camera must be 3 finite coordinates, got {camera!r}")
    return cam  # type: ignore[return-value]


def rotation_matrix(rotation_deg: float) -> np.ndarray:
    """(2, 2) matrix rotating the cup's local frame into the model frame."""
    t = math.radians(rotation_deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), _TINY)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def _piece_from_t(
    camera: tuple[float, float, float],
    q: np.ndarray,
    t: np.ndarray,
    normal: np.ndarray,
    valid: np.ndarray,
    facet: int,
) -> MirrorPiece:
    """Assemble a piece from T (V, 2) and the unit normal (V, 2) at T."""
    p = np.array(camera[:2])
    r = q - 2.0 * np.einsum("ij,ij->i", q - t, normal)[:, None] * normal
    pt = np.linalg.norm(t - p, axis=1)
    pr = np.linalg.norm(r - p, axis=1)
    t_frac = pt / np.maximum(pr, _TINY)
    ok = valid & np.isfinite(r).all(axis=1) & np.isfinite(t_frac) & (pr > 0)
    # Invalid entries keep finite values so that renderers and autograd never
    # meet a NaN; the mask says they are not in the reflection.
    r = np.where(ok[:, None], r, q)
    t_frac = np.where(ok, t_frac, 1.0)
    return MirrorPiece(
        t_xy=t, r_xy=r, normal_xy=normal, t_frac=t_frac, valid_xy=ok, facet=facet, camera=camera
    )


# --------------------------------------------------------------------------- smooth outlines (circle, ellipse)


def _visible_arc(xs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre angle, half width and outside-flag of the arc of the unit circle seen from xs (..., 2).

    ``xs`` are points in the unit-circle frame (local coordinates divided by
    the semi-axes). Points on or inside the circle see nothing: half width 0
    and flag False.
    """
    r2 = np.einsum("...i,...i->...", xs, xs)
    outside = r2 > 1.0
    centre = np.arctan2(xs[..., 1], xs[..., 0])
    half = np.arccos(np.where(outside, 1.0 / np.sqrt(np.where(outside, r2, 1.0)), 1.0))
    return centre, half, outside


def _residual(
    px: float, py: float, qx: np.ndarray, qy: np.ndarray, a: float, b: float, c: np.ndarray, s: np.ndarray
) -> np.ndarray:
    """Reflection-law residual f at outline points (a c, b s) of the local ellipse, (V,).

    ``f = <unit(P - T) + unit(Q - T), (-a s, b c)>``: zero where the normal
    bisects the angle PTQ; positive before (clockwise of) the root on the
    doubly visible arc, negative after. The tangent is not normalised since
    its length is positive and smooth in t, which keeps sign and root.
    """
    tx, ty = a * c, b * s
    dpx, dpy = px - tx, py - ty
    dqx, dqy = qx - tx, qy - ty
    ip = 1.0 / np.maximum(np.sqrt(dpx * dpx + dpy * dpy), _TINY)
    iq = 1.0 / np.maximum(np.sqrt(dqx * dqx + dqy * dqy), _TINY)
    return (dpx * ip + dqx * iq) * (-a * s) + (dpy * ip + dqy * iq) * (b * c)


def _bisect(
    px: float,
    py: float,
    qx: np.ndarray,
    qy: np.ndarray,
    a: float,
    b: float,
    lo: np.ndarray,
    hi: np.ndarray,
    steps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Root of the residual on brackets [lo, hi] (radians, (V,)); returns (cos t, sin t), each (V,).

    The bracket is held as two unit vectors (cos, sin), and its midpoint is
    ``normalize(u_lo + u_hi)``: the exact angle bisector while the bracket is
    narrower than pi (it always is), at the cost of one square root instead
    of two trigonometric calls per step. After ``steps`` halvings (bracket
    < pi / 2**steps), ``_SECANT_STEPS`` false-position steps and a closing
    secant point remove the rest of the error (each step multiplies it by
    about the bracket width times |f'' / f'|); 22 residual evaluations in
    all instead of the 55 halvings plain bisection needs.
    """
    c_lo, s_lo, c_hi, s_hi = np.cos(lo), np.sin(lo), np.cos(hi), np.sin(hi)
    for _ in range(steps):
        c, s = c_lo + c_hi, s_lo + s_hi
        inv = 1.0 / np.sqrt(c * c + s * s)
        c *= inv
        s *= inv
        pos = _residual(px, py, qx, qy, a, b, c, s) > 0
        neg = ~pos
        np.copyto(c_lo, c, where=pos)
        np.copyto(s_lo, s, where=pos)
        np.copyto(c_hi, c, where=neg)
        np.copyto(s_hi, s, where=neg)
    # False-position steps between the bracket ends (f(lo) > 0 > f(hi) at a
    # true root), then a last secant point: each cuts the error by a factor
    # of about the bracket width times |f'' / f'|. Where the signs do not
    # bracket (invalid points), the midpoint is used.
    f_lo = _residual(px, py, qx, qy, a, b, c_lo, s_lo)
    f_hi = _residual(px, py, qx, qy, a, b, c_hi, s_hi)
    for k in range(_SECANT_STEPS + 1):
        span = f_lo - f_hi
        w = np.where(span > 0, f_lo / np.where(span > 0, span, 1.0), 0.5)
        np.clip(w, 0.0, 1.0, out=w)
        c = c_lo + w * (c_hi - c_lo)
        s = s_lo + w * (s_hi - s_lo)
        inv = 1.0 / np.sqrt(c * c + s * s)
        c *= inv
        s *= inv
        if k == _SECANT_STEPS:
            break
        f = _residual(px, py, qx, qy, a, b, c, s)
        pos = f > 0
        neg = ~pos
        np.copyto(c_lo, c, where=pos)
        np.copyto(s_lo, s, where=pos)
        np.copyto(f_lo, f, where=pos)
        np.copyto(c_hi, c, where=neg)
        np.copyto(s_hi, s, where=neg)
        np.copyto(f_hi, f, where=neg)
    return c, s


def _reflect_conic(
    camera: tuple[float, float, float],
    xy: np.ndarray,
    a: float,
    b: float,
    rotation_deg: float,
    steps: int = BISECTION_STEPS,
) -> MirrorPiece:
    """Vectorised bisection for the ellipse (a, b) rotated by ``rotation_deg`` (circle: a == b).

    Brackets each point's doubly visible arc on the eccentric angle (polar
    angle for a circle) and solves it with :func:`_bisect`.
    """
    rot = rotation_matrix(rotation_deg)
    p = np.array(camera[:2]) @ rot  # local frame: rotate by -rotation
    q = xy @ rot
    scale = np.array([a, b])
    phi_p, beta_p, p_out = _visible_arc(p / scale)
    if not bool(p_out):
        raise GeometryError(
            f"the camera {camera} stands inside or on the cup outline; move it outside the cup"
        )
    phi_q, beta_q, q_out = _visible_arc(q / scale)
    # The doubly visible arc, relative to P's centre angle. Each half width is
    # below pi / 2, so wrapping the centre difference to [-pi, pi) is exact.
    d = wrap_angle(phi_q - float(phi_p))
    lo = np.maximum(-float(beta_p), d - beta_q)
    hi = np.minimum(float(beta_p), d + beta_q)
    ok = q_out & (lo < hi)
    # Empty brackets (Q behind the cup or inside it) get a harmless one so the
    # loop stays branch-free; their result is masked out below.
    lo = np.where(ok, lo, -0.5) + float(phi_p)
    hi = np.where(ok, hi, 0.5) + float(phi_p)
    px, py = float(p[0]), float(p[1])
    c = np.empty(xy.shape[0])
    s = np.empty(xy.shape[0])
    # Chunks of a few thousand points keep the temporaries in cache and out
    # of the allocator's mmap/trim path, about 3x faster than whole arrays.
    for i in range(0, xy.shape[0], _CHUNK):
        sl = slice(i, i + _CHUNK)
        c[sl], s[sl] = _bisect(px, py, q[sl, 0], q[sl, 1], a, b, lo[sl], hi[sl], steps)
    t_local = np.stack([a * c, b * s], axis=1)
    n_local = _unit(np.stack([b * c, a * s], axis=1))  # gradient of (x/a)^2 + (y/b)^2
    t_xy = t_local @ rot.T
    n_xy = n_local @ rot.T
    # In front of the tangent line at T, for both P and Q (strict): grazing
    # rays and points on the outline are not in the reflection.
    front_q = np.einsum("ij,ij->i", xy - t_xy, n_xy) > 0
    front_p = np.einsum("ij,ij->i", np.array(camera[:2])[None, :] - t_xy, n_xy) > 0
    return _piece_from_t(camera, xy, t_xy, n_xy, ok & front_q & front_p, -1)



def reflect_conic(
    a: float, b: float, rotation_deg: float, camera: tuple[float, float, float], xy: np.ndarray
) -> MirrorPiece:
    """Reflection in an elliptic outline by bisection on the eccentric angle (Proposition 3.1 generalised).

    A circle of radius r is ``a = b = r``, ``rotation_deg = 0``: the
    bisection is then the paper's, on the angle POT.

    Args:
        a, b: semi-axes along the outline's local x and y, model units.
        rotation_deg: rotation of the local x axis from the model x axis.
        camera: (3,) camera position P, model units.
        xy: (V, 2) saucer points Q, model units.

    Returns:
        One :class:`MirrorPiece` (facet -1).
    """
    return _reflect_conic(_check_camera(camera), _check_points(xy), a, b, rotation_deg)


def circle_quartic(radius: float, camera: tuple[float, float, float], xy: np.ndarray) -> MirrorPiece:
    """Eberly's analytic solution for a round cup: an independent cross-check.

    In units of the radius, T = x P + y Q on the unit circle with Q's mirror
    image across the normal at T on the line PT. Eliminating x gives a
    quartic in y,

        |P|^2 n(y)^2 + 2 <P,Q> y n(y) d(y) + (|Q|^2 y^2 - 1) d(y)^2 = 0,
        n(y) = 1 + y - 2 |Q|^2 y^2,  d(y) = 1 + 2 <P,Q> y,  x = n(y) / d(y),

    solved for all points at once through the eigenvalues of the companion
    matrices; of the real roots the one with T on the unit circle and P and
    Q both in front of its tangent is kept, then polished by two Newton steps.
    The quartic degenerates when O, P and Q are collinear (its leading
    coefficient is ``4 |Q|^2 |P x Q|^2``); such points are marked invalid.
    Slow-ish (a batched 4x4 eigenproblem per point): for tests.

    Args:
        radius: the circle's radius (centre at the origin), model units.
        camera: (3,) camera position P, model units.
        xy: (V, 2) saucer points Q, model units.
    """
    camera = _check_camera(camera)
    xy = _check_points(xy)
    r = radius
    p = np.array(camera[:2]) / r
    q = xy / r
    A = float(p @ p)
    if A <= 1.0:
        raise GeometryError(f"the camera {camera} stands inside or on the cup; move it outside")
    B = q @ p
    C = np.einsum("ij,ij->i", q, q)
    cross2 = A * C - B * B  # |P x Q|^2
    c4 = 4 * C * cross2
    c3 = 4 * B * B - 4 * A * C
    c2 = A - 4 * A * C + 2 * B + C
    c1 = np.full_like(B, 2 * A) - 2 * B
    c0 = np.full_like(B, A - 1)
    degenerate = (np.abs(cross2) <= 1e-10 * A * np.maximum(C, 1e-300)) | (C <= 1.0)
    lead = np.where(degenerate, 1.0, c4)
    comp = np.zeros((xy.shape[0], 4, 4))
    comp[:, 1, 0] = comp[:, 2, 1] = comp[:, 3, 2] = 1.0
    comp[:, 0, 3] = -c0 / lead
    comp[:, 1, 3] = -c1 / lead
    comp[:, 2, 3] = -c2 / lead
    comp[:, 3, 3] = -c3 / lead
    roots = np.linalg.eigvals(comp)  # (V, 4) complex
    y = roots.real
    coeffs = np.stack([c0, c1, c2, c3, c4], axis=1)  # ascending

    def poly(yy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        val = np.zeros_like(yy)
        der = np.zeros_like(yy)
        for k in range(4, -1, -1):
            der = der * yy + val
            val = val * yy + coeffs[:, k : k + 1]
        return val, der

    for _ in range(2):  # Newton polish of every root's real part
        val, der = poly(y)
        y = np.where(np.abs(der) > 0, y - val / np.where(der == 0, 1.0, der), y)
    den = 1 + 2 * B[:, None] * y
    x = (1 + y - 2 * C[:, None] * y * y) / np.where(np.abs(den) > 1e-300, den, 1e-300)
    tx = x * p[0] + y * q[:, 0:1]
    ty = x * p[1] + y * q[:, 1:2]
    norm = np.hypot(tx, ty)
    on_circle = (np.abs(roots.imag) <= 1e-7 * (1 + np.abs(roots.real))) & (np.abs(norm - 1) < 1e-6)
    front_p = (p[0] - tx) * tx + (p[1] - ty) * ty > 0
    front_q = (q[:, 0:1] - tx) * tx + (q[:, 1:2] - ty) * ty > 0
    good = on_circle & front_p & front_q
    # Several candidates would only arise from round-off near tangency; take
    # the one closest to the unit circle.
    score = np.where(good, np.abs(norm - 1), np.inf)
    k = np.argmin(score, axis=1)
    rows = np.arange(xy.shape[0])
    found = np.isfinite(score[rows, k]) & ~degenerate
    tn = np.stack([tx[rows, k], ty[rows, k]], axis=1)
    tn = np.where(found[:, None], tn / np.maximum(norm[rows, k][:, None], _TINY), np.array([0.0, -1.0]))
    return _piece_from_t(camera, xy, tn * r, tn, found, -1)


# --------------------------------------------------------------------------- facets (prisms)


def facet_frames(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Facets of a convex polygon: start vertices (n, 2), edge vectors (n, 2), outward unit normals (n, 2).

    ``corners``: (n, 2) the outline's corners, counter-clockwise, model
    units. Facet k runs from corner k to corner k + 1, so its outward normal
    is the edge turned clockwise by 90 degrees.
    """
    v = corners
    e = np.roll(v, -1, axis=0) - v
    nrm = _unit(np.stack([e[:, 1], -e[:, 0]], axis=1))
    return v, e, nrm


def reflect_facets(
    corners: np.ndarray, camera: tuple[float, float, float], xy: np.ndarray
) -> list[MirrorPiece]:
    """Reflection in each facet of a prism (a convex polygon outline) that faces the camera.

    Each facet is a plane mirror: R is Q mirrored across the facet's line,
    T the intersection of the segment P -> R with that line, and
    ``t_frac = s`` where ``T = P + s (R - P)``. Facets whose front the camera
    does not see are omitted; ``valid_xy`` also requires Q in front of the
    facet (which puts it outside the convex prism) and T within the facet.

    Args:
        corners: (n, 2) the outline's corners, counter-clockwise, model units.
        camera: (3,) camera position P, model units.
        xy: (V, 2) saucer points Q, model units.
    """
    camera = _check_camera(camera)
    q = _check_points(xy)
    p = np.array(camera[:2])
    verts, edges, normals = facet_frames(corners)
    # outside a convex polygon means in front of at least one facet line
    if not bool((np.einsum("ij,ij->i", p - verts, normals) > 0).any()):
        raise GeometryError(
            f"the camera {camera} stands inside or on the prism cup; move it outside"
        )
    pieces = []
    for k in range(verts.shape[0]):
        v0, e, n = verts[k], edges[k], normals[k]
        dp = float((p - v0) @ n)
        if dp <= 0:  # the camera sees this facet's back (or edge-on)
            continue
        dq = (q - v0) @ n
        r = q - 2.0 * dq[:, None] * n
        # T = P + s (R - P) on the facet line: dp + s (dr - dp) = 0, dr = -dq
        front = dq > 0
        s = np.where(front, dp / np.where(front, dp + dq, 1.0), 1.0)
        t = p + s[:, None] * (r - p)
        lam = ((t - v0) @ e) / float(e @ e)
        within = (lam >= 0.0) & (lam <= 1.0)
        normal = np.broadcast_to(n, q.shape).copy()
        piece = _piece_from_t(camera, q, t, normal, front & within, k)
        # for a plane mirror s is exactly |PT| / |PR|; use it (no sqrt round-off)
        pieces.append(replace(piece, t_frac=np.where(piece.valid_xy, s, 1.0)))
    return pieces


# --------------------------------------------------------------------------- slow references
#
# One point, plain Python: the slow, obvious references of the vectorised
# solvers. Each returns ``[(facet, T, R, t_frac), ...]`` for every piece in
# which Q is validly reflected (xy tests only); empty when Q is not in the
# reflection.

#: what a slow reference returns: (facet, T, R, t_frac) per piece that reflects Q
Reference = list[tuple[int, tuple[float, float], tuple[float, float], float]]


def reference_facets(
    corners: np.ndarray, camera: tuple[float, float, float], q_xy: tuple[float, float]
) -> Reference:
    """Reference of :func:`reflect_facets`: a plane mirror per facet of the (n, 2) ``corners``."""
    px, py = float(camera[0]), float(camera[1])
    qx, qy = float(q_xy[0]), float(q_xy[1])
    out = []
    verts = np.asarray(corners, dtype=np.float64)
    n = verts.shape[0]
    for k in range(n):
        ax, ay = verts[k]
        bx, by = verts[(k + 1) % n]
        ex, ey = bx - ax, by - ay
        le = math.hypot(ex, ey)
        nx, ny = ey / le, -ex / le
        dp = (px - ax) * nx + (py - ay) * ny
        dq = (qx - ax) * nx + (qy - ay) * ny
        if dp <= 0 or dq <= 0:
            continue
        rx, ry = qx - 2 * dq * nx, qy - 2 * dq * ny
        s = dp / (dp + dq)
        tx, ty = px + s * (rx - px), py + s * (ry - py)
        lam = ((tx - ax) * ex + (ty - ay) * ey) / (le * le)
        if 0.0 <= lam <= 1.0:
            out.append((k, (tx, ty), (rx, ry), s))
    return out


def reference_conic(
    a: float, b: float, rotation_deg: float, camera: tuple[float, float, float], q_xy: tuple[float, float]
) -> Reference:
    """Reference of :func:`reflect_conic`: scalar bisection over the arc both P and Q see (module docstring)."""
    px, py = float(camera[0]), float(camera[1])
    qx, qy = float(q_xy[0]), float(q_xy[1])
    rot = math.radians(rotation_deg)
    cr, sr = math.cos(rot), math.sin(rot)
    # local frame (rotate by -rot)
    plx, ply = cr * px + sr * py, -sr * px + cr * py
    qlx, qly = cr * qx + sr * qy, -sr * qx + cr * qy

    def arc(x: float, y: float) -> tuple[float, float] | None:
        d = math.hypot(x / a, y / b)
        if d <= 1.0:
            return None
        return math.atan2(y / b, x / a), math.acos(1.0 / d)

    ap, aq = arc(plx, ply), arc(qlx, qly)
    if ap is None:
        raise GeometryError(f"the camera {camera} stands inside or on the cup; move it outside")
    if aq is None:
        return []
    d = (aq[0] - ap[0] + math.pi) % (2 * math.pi) - math.pi
    lo, hi = max(-ap[1], d - aq[1]), min(ap[1], d + aq[1])
    if not lo < hi:
        return []
    lo, hi = lo + ap[0], hi + ap[0]
    for _ in range(REFERENCE_STEPS):
        mid = 0.5 * (lo + hi)
        tx, ty = a * math.cos(mid), b * math.sin(mid)
        dp = math.hypot(plx - tx, ply - ty)
        dq = math.hypot(qlx - tx, qly - ty)
        f = ((plx - tx) / dp + (qlx - tx) / dq) * (-a * math.sin(mid)) + (
            (ply - ty) / dp + (qly - ty) / dq
        ) * (b * math.cos(mid))
        if f > 0:
            lo = mid
        else:
            hi = mid
    t = 0.5 * (lo + hi)
    tx, ty = a * math.cos(t), b * math.sin(t)
    nx, ny = b * math.cos(t), a * math.sin(t)
    ln = math.hypot(nx, ny)
    nx, ny = nx / ln, ny / ln
    dq = (qlx - tx) * nx + (qly - ty) * ny
    if dq <= 0 or (plx - tx) * nx + (ply - ty) * ny <= 0:
        return []
    rlx, rly = qlx - 2 * dq * nx, qly - 2 * dq * ny
    frac = math.hypot(plx - tx, ply - ty) / math.hypot(plx - rlx, ply - rly)
    # back to the model frame
    t_m = (cr * tx - sr * ty, sr * tx + cr * ty)
    r_m = (cr * rlx - sr * rly, sr * rlx + cr * rly)
    return [(-1, t_m, r_m, frac)]
