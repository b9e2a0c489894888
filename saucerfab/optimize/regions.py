"""Two reflected images with a prism cup: facet groups, regions, placement (paper, Fig. 17).

A regular n-gon prism shows the camera several facets; each is a plane
mirror that reflects its own part of the saucer. Splitting the visible facets
into the camera's left and right halves gives two reflected images, each seen
in its own facet region of the cup (:func:`split_reflected_facets` makes the
split). They work only where the saucer regions the two groups reflect
hardly overlap (:func:`facet_groups_overlap`); the paper names two
placements of the prism (a vertex towards the viewer, or a facet towards
the viewer) and uses the better one. :func:`best_placement` measures both
and picks it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.model.cups import PrismCup
from saucerfab.model.mirror import seen_by_piece
from saucerfab.model.reflection import facet_frames, wrap_angle
from saucerfab.model.scene import Scene


def split_reflected_facets(scene: Scene, heights: np.ndarray | None = None) -> list[list[int]]:
    """Split a prism's seen facets into two groups, one per reflected image.

    The facets the camera sees form a chain around the outline; the split
    is between two neighbours of that chain (so each image is seen in one
    connected part of the cup), at the cut where the saucer regions the two
    groups reflect (in frame, see :func:`saucerfab.model.mirror.visible_region`) overlap least,
    the more even split on a tie. A sample in both regions would have to
    show both images, so the overlap is what the designs must compromise on;
    :func:`facet_groups_overlap` reports it.

    Args:
        scene: a scene with a prism cup.
        heights: (N, N) heights (default: a flat saucer at the scene's resolution).

    Returns:
        ``[first, second]``: facet indices, each group in chain order,
        the first on the viewer's left.

    Raises:
        ConfigError: the cup has no facets (not a prism), or fewer than two of its facets
            reflect any of the saucer.
    """
    if not scene.cup.faceted:
        raise ConfigError(
            f"only a prism cup's facets split the reflection into two regions; the cup is a "
            f"{scene.cup.kind} (use e.g. --cup prism:6)"
        )
    _, seen = seen_by_piece(scene, None, heights, True)
    verts, edges, _ = facet_frames(scene.cup.boundary())
    cam = np.array(scene.camera[:2])
    # order the chain by the angle of each facet's midpoint around the axis,
    # measured from the direction of the camera (the seen facets lie within
    # +-90 degrees of it): seen from the camera, counter-clockwise runs from
    # the viewer's left to their right
    mids = verts + 0.5 * edges
    ref = math.atan2(cam[1], cam[0])
    ang = {k: float(wrap_angle(np.array(math.atan2(mids[k, 1], mids[k, 0]) - ref))) for k in seen}
    chain = sorted((k for k in seen if seen[k].any()), key=lambda k: ang[k])
    if len(chain) < 2:
        raise ConfigError(
            f"only {len(chain)} facet(s) of the {len(verts)}-sided prism reflect the saucer "
            "within the reflected frame; two reflected images need two. Rotate the prism "
            "(a corner towards the viewer) or widen the reflected view"
        )
    best: tuple[int, int, int] | None = None
    for cut in range(1, len(chain)):
        a = np.logical_or.reduce([seen[k] for k in chain[:cut]])
        b = np.logical_or.reduce([seen[k] for k in chain[cut:]])
        key = (int((a & b).sum()), abs(int(a.sum()) - int(b.sum())), cut)
        best = key if best is None or key < best else best
    assert best is not None  # chain has at least two facets
    return [chain[: best[2]], chain[best[2] :]]


def facet_groups_overlap(
    scene: Scene, groups: list[list[int]], heights: np.ndarray | None = None
) -> tuple[float, float, float]:
    """How the saucer regions reflected by facet groups share the saucer.

    Args:
        scene: a scene with a prism cup.
        groups: two lists of facet indices (e.g. from :func:`split_reflected_facets`).
        heights: (N, N) heights (default: a flat saucer at the scene's resolution).

    Returns:
        (fraction of the saucer samples in the first region, in the second,
        in both), each in [0, 1].
    """
    if len(groups) != 2:
        raise ConfigError(f"give two facet groups, got {len(groups)}")
    n, seen = seen_by_piece(scene, None, heights, True)
    regions = []
    for g in groups:
        r = np.zeros(n * n, dtype=bool)
        for k in g:
            if k in seen:
                r |= seen[k]
        regions.append(r)
    a, b = regions
    return float(a.mean()), float(b.mean()), float((a & b).mean())


@dataclass(frozen=True)
class RegionReport:
    """How two facet groups split the saucer.

    Attributes:
        groups: facet indices of the left and right group.
        area_fraction: (2,) share of the saucer's samples each group reflects.
        overlap: samples reflected by both groups, as a share of the smaller region.
    """

    groups: tuple[tuple[int, ...], tuple[int, ...]]
    area_fraction: tuple[float, float]
    overlap: float

    def to_dict(self) -> dict[str, object]:
        return {
            "groups": [list(g) for g in self.groups],
            "area_fraction": list(self.area_fraction),
            "overlap": self.overlap,
        }


def region_report(scene: Scene, heights: np.ndarray | None = None) -> RegionReport:
    """The facet split of :func:`split_reflected_facets` and its overlap."""
    groups = split_reflected_facets(scene, heights)
    a, b, both = facet_groups_overlap(scene, groups, heights)
    smaller = max(min(a, b), 1e-12)
    return RegionReport((tuple(groups[0]), tuple(groups[1])), (a, b), both / smaller if min(a, b) > 0 else 1.0)


def placement_options(scene: Scene) -> dict[str, PrismCup]:
    """The paper's two placements of the scene's prism (Figure 17).

    ``vertex_to_viewer``: an edge between two facets points at the camera;
    ``facet_to_viewer``: a facet squarely faces the camera.
    """
    cup = scene.cup
    # the two placements turn a regular n-gon about its axis: a prism's own parameters
    if not isinstance(cup, PrismCup):
        raise ConfigError(f"placement options exist for prism cups only; got a {cup.kind} cup")
    towards = math.degrees(math.atan2(scene.camera[1], scene.camera[0]))
    return {
        "vertex_to_viewer": replace(cup, rotation_deg=towards),
        "facet_to_viewer": replace(cup, rotation_deg=towards + 180.0 / cup.sides),
    }


def best_placement(
    scene: Scene, heights: np.ndarray | None = None
) -> tuple[Scene, str, dict[str, RegionReport]]:
    """Measure both placements and return the scene with the one of least overlap.

    Among placements whose overlap is within 1 % of the best, the one whose
    smaller region is larger wins (both images need room). A placement that
    shows the saucer in fewer than two facets is skipped.
    """
    reports: dict[str, RegionReport] = {}
    scenes: dict[str, Scene] = {}
    for name, cup in placement_options(scene).items():
        try:
            s = replace(scene, cup=cup)
            reports[name] = region_report(s, heights)
            scenes[name] = s
        except ConfigError:
            continue
    if not reports:
        raise ConfigError("neither prism placement shows facets on both sides of the viewer")
    least = min(r.overlap for r in reports.values())
    close = [k for k, r in reports.items() if r.overlap <= least + 0.01]
    pick = max(close, key=lambda k: min(reports[k].area_fraction))
    return scenes[pick], pick, reports
