"""Two reflected images with a prism cup: facet groups, regions, placement (paper, Fig. 17).

A regular n-gon prism shows the camera several facets; each is a plane
mirror that reflects its own part of the saucer. Splitting the visible facets
into the camera's left and right halves gives two reflected images, each seen
in its own facet region of the cup. They work only where the saucer regions
the two groups reflect hardly overlap; the paper names two placements of the
prism (a vertex towards the viewer, or a facet towards the viewer) and uses
the better one. :func:`best_placement` measures both and picks it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.mirror import facet_groups_overlap, split_reflected_facets
from saucerfab.scene import PrismCup, Scene


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
    """The facet split of :func:`saucerfab.mirror.split_reflected_facets` and its overlap."""
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
