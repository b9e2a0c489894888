"""The view rig's visibility: which saucer faces each view samples, kept per supersampling."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from saucerfab.model.heightfield import base_shape
from saucerfab.model.scene import Scene
from saucerfab.optimize.views import Rig, visible_faces
from saucerfab.render import rasterize_hard


def test_visible_faces_marks_every_sampled_face_and_keeps_the_last_per_supersample() -> None:
    scene = Scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=24))
    base = base_shape("waves", 24)
    rig = Rig(scene, base, image_size=96)
    h = base + 0.01 * np.sin(np.arange(base.size)).reshape(base.shape)
    for ss in (1, 2):
        got = visible_faces(rig, h, ss)
        for view in rig.views:  # the reference: the saucer faces behind the distinct ids of the face buffer
            fid, _, _ = rasterize_hard(view.vertices_np(h.reshape(-1)), view.faces,
                                       view.camera.with_size(view.camera.image_size * ss))
            want = np.zeros(rig.num_faces, bool)
            ids = np.unique(fid)
            want[np.asarray(view.face_src)[ids[ids >= 0]]] = True
            assert want.any() and np.array_equal(got[view.name], want)

    def fresh(heights: np.ndarray) -> dict[str, np.ndarray]:
        return visible_faces(Rig(scene, base, image_size=96), heights, 2)

    # asked again: the kept result, in fresh arrays (a caller writing into one does not change it)
    visible_faces(rig, h, 2)["direct"][:] = False
    for heights in (h, base, h):  # other heights are computed afresh
        got, want = visible_faces(rig, heights, 2), fresh(heights)
        assert all(np.array_equal(got[k], want[k]) for k in want)
