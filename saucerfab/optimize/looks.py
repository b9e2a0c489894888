"""Looks at a running design: quick hard renders written beside it while it runs (issue 18).

Every look shows the designer's own pictures on the saucer's shape at that
moment, coloured as the texturing step would colour it (each face from the
pictures of the views that see it: :func:`saucerfab.optimize.targets.projected_colors`
on the pictures as meant, ``Prepared.render``), so it is a preview of the
print so far:

* the **first look**, made as soon as the inputs are prepared, before torch
  is imported (on numpy views, :class:`saucerfab.optimize.views.ViewMeshes`):
  the base shape, before any optimisation;
* a **refined look** after each stage: the current heights.

The optimizer's own face colours are not shown: its first stages aim at the
black-white enhanced targets (a black subject on blue), which would only
confuse a designer watching the run; the shape is what the stages change.

Each look is the nearest-face render with one colour per face (as
:func:`saucerfab.render.render_face_colors_hard` draws it) of every view
(``direct``, ``reflected``, ``reflected2`` if any) and the composite
(:func:`saucerfab.optimize.previews.compose`), at most :data:`LOOK_SIZE`
pixels a side, written atomically as
``<stage>_<view>.png`` into the run's checkpoint folder
(``.<out name>.checkpoint/previews/``; the design folder itself is only
written, atomically, at the end). The checkpoint folder, looks included,
goes when the run finishes.

One file per stage and view, never overwritten within a run: a reader (a UI
polling the folder, or the ``look`` callback handed the paths) never sees a
set mixed from two stages, and the paths it was given stay valid for the
rest of the run.

A look draws no random numbers and shares no state with the optimisation
(it reads the prepared inputs, the rig and copies of the iterate), so the
design is the same byte for byte with or without it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from saucerfab.files.fileio import write_bytes_atomic

if TYPE_CHECKING:
    from saucerfab.model.camera import Camera
    from saucerfab.model.scene import Scene
    from saucerfab.optimize.prepare import Prepared
    from saucerfab.optimize.views import ViewMesh, ViewMeshes

#: look(stage, files, elapsed_s): stage "first_look" or a stage's name; files: name
#: ("direct", "reflected", "reflected2", "composite") -> PNG path; seconds since optimize_design started
Look = Callable[[str, dict[str, Path], float], None]

#: the stage name of the first look
FIRST_LOOK = "first_look"

#: the largest side of a look's images, pixels (the views are rendered at min(their size, this))
LOOK_SIZE = 256

#: zlib level of a look's PNGs: they are read once and removed with the checkpoint, so fast beats small
LOOK_PNG_LEVEL = 1


def look_colors(meshes: ViewMeshes, prep: Prepared, heights: np.ndarray) -> np.ndarray:
    """(F, 3) face colours in [0, 1]: the pictures as meant projected onto the saucer at ``heights``.

    The texturing step's rule (:func:`saucerfab.optimize.targets.projected_colors`)
    on ``prep.render``, the inputs fitted into their frames.

    Args:
        meshes: the views (a :class:`~saucerfab.optimize.views.Rig` or its torch-free part).
        heights: (N, N) saucer heights, model units.
    """
    from saucerfab.optimize.targets import projected_colors

    return projected_colors(meshes, np.asarray(heights, np.float64).reshape(meshes.n, meshes.n), prep.render)


def look_images(
    scene: Scene, rig: ViewMeshes, heights: np.ndarray, colors: np.ndarray, size: int = LOOK_SIZE
) -> dict[str, np.ndarray]:
    """Nearest-face renders of each view and the composite with per-face colours.

    Args:
        heights: (N, N) or (V,) saucer heights, model units.
        colors: (F, 3) saucer face colours in [0, 1].
        size: the largest image side, pixels (a view smaller than this keeps its own size).

    Returns:
        name (each view's, then ``"composite"``) -> (S, S, 3) float64 in [0, 1], row 0 at the top.
    """
    from saucerfab.optimize.previews import compose, scene_composite_camera
    from saucerfab.render.hard import PREVIEW_BACKGROUND, rasterize_hard

    h = np.asarray(heights, np.float64).reshape(-1)
    cols = np.clip(np.asarray(colors, np.float64), 0.0, 1.0)
    bg = np.asarray(PREVIEW_BACKGROUND)

    def paint(view: ViewMesh, verts: np.ndarray, faces: np.ndarray, cam: Camera) -> tuple[np.ndarray, ...]:
        fid, _, depth = rasterize_hard(verts, faces, cam)
        img = np.empty(fid.shape + (3,))
        img[:] = bg
        seen = fid >= 0
        img[seen] = cols[np.asarray(view.face_src)[fid[seen]]]
        return img, fid, depth

    out: dict[str, np.ndarray] = {}
    for view in rig.views:
        cam = view.camera.with_size(min(size, view.camera.image_size))
        if view.faces.shape[0] == 0:
            out[view.name] = np.ones((cam.image_size, cam.image_size, 3))
            continue
        out[view.name] = paint(view, view.vertices_np(h), np.asarray(view.faces), cam)[0]
    side = min(size, rig.views[0].camera.image_size)
    out["composite"] = compose(scene, rig, h.reshape(rig.n, rig.n), scene_composite_camera(scene, h, side), paint)
    return out


class Looks:
    """Writes the looks of one run into ``folder`` and reports each set to a callback.

    Args:
        folder: where the PNGs go (the checkpoint's ``previews/``).
        callback: called after each set is written, or None. An exception it
            raises is reported once on stderr and otherwise ignored: a
            viewer's fault must not cost the design.
        t_start: ``time.perf_counter()`` when the run started (elapsed_s counts from it).
        size: the largest image side, pixels.
    """

    def __init__(self, folder: Path, callback: Look | None, t_start: float, size: int = LOOK_SIZE) -> None:
        self.folder, self.callback, self.t_start, self.size = Path(folder), callback, t_start, size
        self._warned = False

    def first(self, prep: Prepared) -> dict[str, Path]:
        """The first look: the pictures projected onto the base shape, before any optimisation.

        Torch-free (numpy views, :class:`~saucerfab.optimize.views.ViewMeshes`),
        so it can come before torch is imported; the files written.
        """
        from saucerfab.optimize.views import ViewMeshes

        meshes = ViewMeshes(prep.scene, prep.base, reflected_groups=prep.reflected_groups)
        return self.show(FIRST_LOOK, prep, meshes, prep.base)

    def show(self, stage: str, prep: Prepared, rig: ViewMeshes, heights: np.ndarray) -> dict[str, Path]:
        """Render the pictures on the saucer at ``heights`` (N, N), write ``<stage>_<name>.png``, call the callback.

        Returns the files written. A file that cannot be written (a full disk)
        is left out with a note on stderr: the design goes on, and its own
        writes report the disk.
        """
        from saucerfab.files.imageio import png_bytes
        from saucerfab.imaging.panels import as_uint8_rgb

        files: dict[str, Path] = {}
        colors = look_colors(rig, prep, heights)
        for name, img in look_images(prep.scene, rig, heights, colors, self.size).items():
            path = self.folder / f"{stage}_{name}.png"
            try:
                files[name] = write_bytes_atomic(path, png_bytes(as_uint8_rgb(img), LOOK_PNG_LEVEL))
            except OSError as exc:
                print(f"  note: the look {path.name} was not written: {exc.strerror or exc}", file=sys.stderr)
        if self.callback is not None:
            try:
                self.callback(stage, files, time.perf_counter() - self.t_start)
            except Exception as exc:  # noqa: BLE001 - any fault of the viewer's; the design goes on
                if not self._warned:
                    self._warned = True
                    print(f"  warning: the look callback raised {type(exc).__name__}: {exc}; the design goes on "
                          "(looks are still written)", file=sys.stderr)
        return files
