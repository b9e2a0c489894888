"""The saucer's reflection in a scene's mirror cup (paper, section 3.2).

The viewer sees a saucer point Q at its *virtual point* R, Q mirrored across
the cup wall's tangent line at the point T where the ray from the camera P
reflects (see :mod:`saucerfab.model.reflection` for the geometry and the solvers).
Which solver runs is the cup's business (:meth:`saucerfab.model.cups.Cup.reflect`);
this module applies it to a scene and a heightfield:

* :func:`reflect`: the xy part (T, R, validity) for saucer points, once per
  design, one :class:`MirrorPiece` per smooth cup or seen prism facet;
* :func:`reflected_mesh`: the saucer mesh as seen in each piece, for the
  reflected view's rasterizer;
* :func:`visible_region`: which saucer samples the mirror shows.

The per-shape names (:func:`reflect_bisection`, ...,
:func:`reflect_point_reference`) are the cup-typed entry points the tests
and the benchmark call; each hands over to the cup or to
:mod:`saucerfab.model.reflection`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.model.cups import CircleCup, Cup, EllipseCup, PrismCup
from saucerfab.model.reflection import MirrorPiece, Reference, circle_quartic, facet_frames
from saucerfab.model.scene import Scene

# --------------------------------------------------------------------------- per shape


def reflect_bisection(
    cup: CircleCup | EllipseCup, camera: tuple[float, float, float], xy: np.ndarray
) -> MirrorPiece:
    """Reflection in a smooth cup by bisection (the paper's, on the angle POT for a round cup; on the
    eccentric angle for an ellipse): its one piece (facet -1).

    Args:
        cup: the circle or ellipse cup (centred at the origin).
        camera: (3,) camera position P, model units.
        xy: (V, 2) saucer points Q, model units.
    """
    return cup.reflect(camera, xy)[0]


def reflect_circle_quartic(
    cup: CircleCup, camera: tuple[float, float, float], xy: np.ndarray
) -> MirrorPiece:
    """Eberly's analytic solution for a round cup, the cross-check of the bisection (see
    :func:`saucerfab.model.reflection.circle_quartic`)."""
    return circle_quartic(cup.radius, camera, xy)


def prism_facets(cup: PrismCup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Facets of a prism cup: start vertices (n, 2), edge vectors (n, 2), outward unit normals (n, 2).

    Facet k runs from outline vertex k to vertex k + 1 (counter-clockwise).
    """
    return facet_frames(cup.boundary())


def reflect_prism(
    cup: PrismCup, camera: tuple[float, float, float], xy: np.ndarray
) -> list[MirrorPiece]:
    """Reflection in each facet of a prism cup that faces the camera (see
    :func:`saucerfab.model.reflection.reflect_facets`).

    Args:
        cup: the prism cup.
        camera: (3,) camera position P, model units.
        xy: (V, 2) saucer points Q, model units.
    """
    return cup.reflect(camera, xy)


def reflect_point_reference(
    cup: Cup, camera: tuple[float, float, float], q_xy: tuple[float, float]
) -> Reference:
    """One point, plain Python: the slow, obvious reference of :func:`reflect`.

    Smooth cups: scalar bisection on the outline parameter over the arc both
    P and Q see. Prisms: a plane mirror per facet.

    Returns:
        ``[(facet, T, R, t_frac), ...]`` for every piece in which Q is validly
        reflected (xy tests only); empty when Q is not in the reflection.
    """
    return cup.reflect_reference(camera, q_xy)


# --------------------------------------------------------------------------- scene level


def reflect(scene: Scene, xy: np.ndarray) -> list[MirrorPiece]:
    """Reflect saucer points in ``scene``'s cup, seen from ``scene.camera``.

    Args:
        scene: the scene (camera and cup).
        xy: (V, 2) float64 saucer points Q, model units (e.g. ``Grid.xy()``).

    Returns:
        The cup's pieces (:meth:`saucerfab.model.cups.Cup.reflect`): one
        :class:`MirrorPiece` for a smooth cup (circle, ellipse); for a faceted
        one (prism), one per facet the camera sees (its front), in facet order.

    Raises:
        GeometryError: the camera is inside the cup, or a point is not finite.
    """
    return scene.cup.reflect(scene.camera, xy)


class ReflectedMesh(NamedTuple):
    """The saucer mesh as seen in one mirror piece, ready for a rasterizer.

    Attributes:
        vertices: (V, 3) float64 virtual points R = (r_x, r_y, h) of all vertices.
        faces: (F', 3) int64 the saucer faces (``triangulate(N)`` rows) whose
            three vertices are valid in this piece.
        vertex_valid: (V,) bool, :meth:`MirrorPiece.valid` for these heights.
        face_ids: (F',) int64 index of each kept face in ``triangulate(N)``,
            to look up its colour.
        facet: the piece's facet (-1 for a smooth cup).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_valid: np.ndarray
    face_ids: np.ndarray
    facet: int


def _grid_for(scene: Scene, n: int):  # -> Grid
    from saucerfab.model.heightfield import make_grid

    return make_grid(replace(scene.saucer, resolution=n))


def reflected_mesh(
    scene: Scene, heights: np.ndarray, pieces: list[MirrorPiece] | None = None
) -> list[ReflectedMesh]:
    """The reflected saucer mesh, one part per mirror piece.

    Args:
        scene: the scene; the grid covers its saucer footprint.
        heights: (N, N) vertex heights, model units (grid order of
            :mod:`saucerfab.model.heightfield`).
        pieces: the result of ``reflect(scene, grid.xy())`` for this N, to
            skip recomputing it (the xy part never changes during a design).

    Returns:
        One :class:`ReflectedMesh` per piece; faces with any invalid vertex
        are left out (they are not in the reflected view).
    """
    from saucerfab.model.heightfield import triangulate

    h = np.asarray(heights, dtype=np.float64)
    if h.ndim != 2 or h.shape[0] != h.shape[1]:
        raise ConfigError(f"heights must be a square (N, N) array, got shape {h.shape}")
    n = h.shape[0]
    if pieces is None:
        pieces = reflect(scene, _grid_for(scene, n).xy())
    faces = triangulate(n)
    out = []
    for piece in pieces:
        vv = piece.valid(h, scene.cup.height)
        keep = vv[faces].all(axis=1)
        out.append(
            ReflectedMesh(
                vertices=piece.reflected_vertices(h),
                faces=faces[keep],
                vertex_valid=vv,
                face_ids=np.nonzero(keep)[0].astype(np.int64),
                facet=piece.facet,
            )
        )
    return out


def seen_by_piece(
    scene: Scene, n: int | None, heights: np.ndarray | None, in_frame: bool
) -> tuple[int, dict[int, np.ndarray]]:
    """Grid size and, per piece (by facet), which of the N*N samples it shows, (N*N,) bool.

    Args:
        scene: the scene.
        n: grid resolution (None: that of ``heights``, else the scene's).
        heights: (N, N) heights, model units (None: a flat saucer at z = 0).
        in_frame: also require R to project inside the reflected view's frame.
    """
    from saucerfab.model.camera import Camera

    if n is None:
        n = scene.saucer.resolution if heights is None else int(np.shape(heights)[0])
    n = int(n)
    h = np.zeros((n, n)) if heights is None else np.asarray(heights, dtype=np.float64)
    if h.shape != (n, n):
        raise ConfigError(f"heights have shape {h.shape}; expected ({n}, {n})")
    cam = Camera.from_scene(scene, "reflected")
    seen = {}
    for piece in reflect(scene, _grid_for(scene, n).xy()):
        ok = piece.valid(h, scene.cup.height)
        if in_frame:
            ndc = cam.project(piece.reflected_vertices(h))
            ok &= (ndc[:, 2] > 0) & (np.abs(ndc[:, 0]) <= 1) & (np.abs(ndc[:, 1]) <= 1)
        seen[piece.facet] = ok
    return n, seen


def visible_region(
    scene: Scene,
    n: int | None = None,
    heights: np.ndarray | None = None,
    *,
    facets: list[int] | None = None,
    in_frame: bool = True,
) -> np.ndarray:
    """Which saucer samples appear in the reflection, (N, N) bool.

    Args:
        scene: the scene.
        n: grid resolution (default: that of ``heights``, else the scene's).
        heights: (N, N) heights, model units (default: a flat saucer at z = 0).
        facets: for a prism, count only these facets (default: all); the
            region split of two reflected images (:mod:`saucerfab.optimize.regions`)
            uses one facet set each.
        in_frame: also require R to project inside the reflected view's frame
            (what the reflected image covers).
    """
    n, seen = seen_by_piece(scene, n, heights, in_frame)
    region = np.zeros(n * n, dtype=bool)
    for facet, ok in seen.items():
        if facets is None or facet in facets:
            region |= ok
    return region.reshape(n, n)
