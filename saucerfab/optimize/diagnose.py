"""Whether the base shape defeats the method, and what to change (issue 42, item 13).

The method deforms the base shape by at most delta so that the faces the
viewer sees directly and those seen in the mirror cup carry different
colours (paper, sections 3-4). A face seen in both views (a *conflict*,
:class:`~saucerfab.model.design.FaceView` ``BOTH``) must serve two pictures, and
texturing gives it their average: the ghost of each picture in the other.
How many faces start in both views is set by the base shape and the fixed
mirror geometry alone, and the optimisation can part only some of them.

:func:`check_base_shape` measures the conflict share on the base shape
before any stage and, where it is over :data:`BASE_CONFLICT_LIMIT`, that of
the built-in shapes whose ridges run across the line of sight on the same
scene and grid; the shape is suspect (a note at once) where one of those
starts under the limit. :meth:`BaseShapeCheck.conclude` judges it with the
share after the design: a suspect shape still over
:data:`FINAL_CONFLICT_LIMIT` is named as the cause, with what to change.
Both are said as ``note:`` lines on stderr (as the print notes) and the
verdict is recorded in design.json as ``metrics.base_shape``.

Measured with :func:`~saucerfab.optimize.pipeline.optimize_design` (issue 42;
the heart/star pair unless said, the paper scene and cup, the defaults
otherwise; resolution x image size), the share in % of the seen faces in
both views on the base shape -> after the design:

=================  ===========  ===========  ===========  =====================
shape              40 x 96 px   60 x 160 px  80 x 256 px  150 x 512 (base only)
=================  ===========  ===========  ===========  =====================
waves (default)    8.9 -> 4.9   7.9 -> 2.9   8.6 -> 3.7   8.6
tabula_scalata     31.1 -> 13.2 29.5 -> 8.6  31.9 -> 12.1 3.1 (13.6 at 149)
egg crate (4x4)    40.7 -> 17.8 37.9 -> 15.6 37.3 -> 13.5 35.8
plane              42.2 -> 19.5 42.7 -> 17.5 41.0 -> 13.6 40.9
ripples            40.0 -> 18.2 35.1 -> 13.6              35.0
smooth_random      39.5 -> 15.2 41.7 -> 15.3              41.8
bowl               46.3 -> 22.1 47.6 -> 18.3              47.4
=================  ===========  ===========  ===========  =====================

With the tree/note pair at 40 x 96: waves 8.9 -> 7.1, the egg crate
40.7 -> 30.3, the others 24.2-33.8 after. At 24 x 64 and 32 x 80 waves
starts at 11.2-11.5 %, the egg crate at 37.5-41.8 %. The verified
reflected picture at 40 x 96 (design eye): waves 27.0 dB, the egg crate
21.1 dB; doubling delta (0.1) lifted the egg crate only to 22.8 dB (16.5 %
conflict), a steeper egg crate (--height-scale 0.2) to 21.6 dB. What parts
the views is orientation: ridges running along x (across the line of sight)
show their fronts to the eye and their backs to the cup; a 6-ridge shape
file of horizontal stripes starts at 8.9 % (12 ridges: 7.0 %), the same
stripes turned vertical at 39.2 %, 3 ridges at 31.4 % (40 x 96; at
150 x 512: 8.5, 5.6, 38.6, 33.8 %). A smoother shape is no cure: the plane
is among the worst.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.model.design import FRAMED_VIEWS, FaceView

if TYPE_CHECKING:
    from saucerfab.optimize.prepare import Prepared
    from saucerfab.optimize.views import ViewMeshes

#: share of the seen faces in both views on the base shape over which the shape is suspect:
#: waves starts at 7.9-11.5 % at every size measured, the egg crate at 35.6-41.8 % (table above)
BASE_CONFLICT_LIMIT = 0.20
#: share after the design over which a suspect base shape is named as the cause: waves ends at
#: 2.9-7.1 %, the egg crate at 13.5-30.3 % (table above)
FINAL_CONFLICT_LIMIT = 0.10
#: the built-in shapes whose ridges run across the line of sight, the hint's candidates
#: (each named only where it starts under :data:`BASE_CONFLICT_LIMIT` on the design's scene)
ACROSS_VIEW_SHAPES = ("waves", "tabula_scalata")


def conflict_share(face_view: np.ndarray) -> float:
    """Share (0..1) of the seen faces that are seen both directly and in a reflection.

    Args:
        face_view: (F,) :class:`~saucerfab.model.design.FaceView` per face.
    """
    fv = np.asarray(face_view)
    seen = int(np.isin(fv, FRAMED_VIEWS).sum())
    return float((fv == FaceView.BOTH).sum() / max(seen, 1))


def _base_conflict(rig: ViewMeshes, heights: np.ndarray) -> float:
    """The conflict share of ``rig``'s views at ``heights`` (N, N), model units."""
    from saucerfab.optimize.texturing import classify_faces

    return conflict_share(classify_faces(rig.visible_faces(heights)))


def _note(text: str) -> None:
    """Say ``text`` as one of the design's notes (stderr, as the print notes)."""
    print(f"  note: {text}", file=sys.stderr, flush=True)


def _pct(share: float) -> str:
    return f"{100 * share:.0f}%"


@dataclass
class BaseShapeCheck:
    """The base shape's conflict share, measured before the stages (:func:`check_base_shape`).

    Attributes:
        shape: the shape as the design names it (a built-in's name, a file's name).
        base: conflict share on the base shape (0..1).
        delta: the height bound, model units.
        builtins: each of :data:`ACROSS_VIEW_SHAPES` but the shape itself -> its conflict share
            on the same scene and grid; measured only where ``base`` is over the limit.
    """

    shape: str
    base: float
    delta: float
    builtins: dict[str, float] = field(default_factory=dict)

    @property
    def better(self) -> list[tuple[float, str]]:
        """(share, name) of the measured built-ins that start under the limit here, lowest first."""
        return sorted((s, n) for n, s in self.builtins.items() if s <= BASE_CONFLICT_LIMIT)

    @property
    def suspect(self) -> bool:
        """Whether the base shape starts over :data:`BASE_CONFLICT_LIMIT` where a built-in starts under it.

        Where every across-the-view built-in starts over the limit too (a grid too coarse for their
        ridges: waves starts at 27.7 % with 16 vertices a side, 17.5 % with 20; or a scene of its own),
        the shape alone is not to blame, and nothing is said.
        """
        return self.base > BASE_CONFLICT_LIMIT and bool(self.better)

    def early_note(self) -> str:
        """The note said before the stages when the shape is suspect."""
        here = ", ".join(f"{n} {_pct(s)}" for s, n in self.better)
        return (f"base shape {self.shape!r} leaves {_pct(self.base)} of the saucer the viewer sees in both the "
                f"direct view and the cup's (the built-in {here} on this scene): where the two pictures differ "
                "there, each may show as a ghost in the other; the end of the run says whether the optimisation "
                "parted them")

    def conclude(self, face_views: Mapping[str, int]) -> dict[str, Any]:
        """Judge the base shape with the design's final face views; say the hint where it is the cause.

        Args:
            face_views: design.json's ``metrics.face_views``: FaceView name (lower case) -> faces.

        Returns:
            design.json's ``metrics.base_shape``: ``conflict_base`` and ``conflict_final``
            (shares, 0..1), their ``limits``, the built-in shapes' ``builtin_conflict_base``
            where measured, and ``verdict``: ``"ok"`` (the shape starts under the limit),
            ``"not_the_shape"`` (over, but so does every across-the-view built-in here),
            ``"overcome"`` (over, and the optimisation brought it under) or ``"cause"`` (still
            over: the base shape is the likely cause of ghosts), with ``hint`` then.
        """
        seen = sum(int(face_views.get(fv.name.lower(), 0)) for fv in FRAMED_VIEWS)
        final = int(face_views.get(FaceView.BOTH.name.lower(), 0)) / max(seen, 1)
        if self.base <= BASE_CONFLICT_LIMIT:
            verdict = "ok"
        elif not self.suspect:
            verdict = "not_the_shape"
        else:
            verdict = "cause" if final > FINAL_CONFLICT_LIMIT else "overcome"
        out: dict[str, Any] = {
            "shape": self.shape,
            "conflict_base": self.base,
            "conflict_final": final,
            "limits": {"base": BASE_CONFLICT_LIMIT, "final": FINAL_CONFLICT_LIMIT},
            "verdict": verdict,
        }
        if self.builtins:
            out["builtin_conflict_base"] = dict(self.builtins)
        if verdict == "cause":
            out["hint"] = self.hint(final)
            _note(out["hint"])
        return out

    def hint(self, final: float) -> str:
        """What the designer reads when the base shape is the cause: the numbers, why, and what to change."""
        use = " or ".join(f"--shape {n} ({_pct(s)} here)" for s, n in self.better)
        return (
            f"the base shape is the likely cause of ghosts: {self.shape!r} had {_pct(self.base)} of the saucer the "
            f"viewer sees in both the direct view and the cup's before the optimisation and {_pct(final)} after "
            f"the optimisation (limits {_pct(BASE_CONFLICT_LIMIT)} and {_pct(FINAL_CONFLICT_LIMIT)}); within the "
            f"height bound (delta {self.delta:g}) those faces cannot carry both pictures. Use {use}, or a shape "
            "of your own with ridges running along x, across the line of sight (horizontal stripes in a PNG or "
            ".npy, 6 or more), so their fronts face the eye and their backs the cup: bumps, and ridges along the "
            "line of sight, face both. A smoother shape does not help (a plane is among the worst), and a larger "
            "height bound (delta in the [saucer] table of a --scene TOML) helps far less"
        )


def check_base_shape(prep: Prepared, rig: ViewMeshes, shape: str, seed: int = 0) -> BaseShapeCheck:
    """Measure the base shape's conflict share before any stage; say a note at once when it is suspect.

    Torch-free and cheap: one hard render per view of the base shape; where its share is over the
    limit, one more per across-the-view built-in (about 0.2 s each at 150 x 512 px).

    Args:
        prep: the run's validated inputs (scene, base heights, reflected groups).
        rig: the run's views, built on ``prep.base``.
        shape: the request's shape (a built-in name or a file path; a file is named by its name only,
            as design.json names it).
        seed: the request's seed (for the built-in shapes measured beside it).
    """
    from saucerfab.model.heightfield import base_shape
    from saucerfab.optimize.views import ViewMeshes

    is_file = Path(str(shape)).suffix.lower() in (".png", ".npy")
    name = Path(shape).name if is_file else str(shape)
    check = BaseShapeCheck(name, _base_conflict(rig, prep.base), float(prep.scene.saucer.delta))
    if check.base > BASE_CONFLICT_LIMIT:
        n = prep.scene.saucer.resolution
        own = None if is_file else name.replace("-", "_").lower()  # a built-in's key (as base_shape reads it)
        for other in ACROSS_VIEW_SHAPES:
            if other != own:
                h = base_shape(other, n, seed, rig.scene.saucer)
                meshes = ViewMeshes(prep.scene, h, reflected_groups=prep.reflected_groups)
                check.builtins[other] = _base_conflict(meshes, h)
        if check.suspect:
            _note(check.early_note())
    return check
