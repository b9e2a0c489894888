"""Texturing (paper 3.4.2): the four face cases, UVs from projections, the both-case average."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from saucerfab.model.design import FRAMED_VIEWS, FaceView
from saucerfab.model.heightfield import base_shape
from saucerfab.model.scene import Scene
from saucerfab.optimize.texturing import classify_faces, texture_saucer
from saucerfab.optimize.views import Rig
from saucerfab.render.texels import raster_triangles_2d


def test_classify_faces_truth_table() -> None:
    d = np.array([True, True, False, False])
    r = np.array([True, False, True, False])
    got = classify_faces({"direct": d, "reflected": r})
    assert list(got) == [FaceView.BOTH, FaceView.DIRECT, FaceView.REFLECTED, FaceView.NEITHER]
    # a second reflected view counts as reflected too
    got2 = classify_faces({"direct": d, "reflected": np.zeros(4, bool), "reflected2": r})
    assert list(got2) == list(got)


def test_raster_triangles_2d_covers_texel_centres_exactly() -> None:
    # right triangle with legs 4 texels: centres (x+.5, y+.5) with x + y + 1 <= 4
    tri = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]])
    pix, ti, bary = raster_triangles_2d(tri, 8, 8)
    got = {(p % 8, p // 8) for p in pix}
    want = {(x, y) for x in range(8) for y in range(8) if (x + 0.5) + (y + 0.5) <= 4.0}
    assert got == want
    assert (ti == 0).all()
    pos = np.einsum("kc,kcd->kd", bary, tri[ti])
    cx = np.array([p % 8 for p in pix]) + 0.5
    cy = np.array([p // 8 for p in pix]) + 0.5
    assert np.allclose(pos, np.stack([cx, cy], 1))


@pytest.fixture(scope="module")
def small_rig():
    scene = Scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=24))
    base = base_shape("waves", 24)
    return scene, base, Rig(scene, base, image_size=96)


def red_and_blue(t: int) -> tuple[np.ndarray, np.ndarray]:
    """Two plain (t, t, 3) pictures in [0, 1]: red for the direct view, blue for the reflected one."""
    red = np.zeros((t, t, 3))
    red[..., 0] = 1.0
    blue = np.zeros((t, t, 3))
    blue[..., 2] = 1.0
    return red, blue


def test_four_cases_uvs_and_both_average(small_rig) -> None:  # noqa: ANN001
    scene, base, rig = small_rig
    t = 64
    red, blue = red_and_blue(t)
    res = texture_saucer(rig, base, {"direct": red, "reflected": blue})
    fv = res.face_view
    for case in (FaceView.NEITHER, *FRAMED_VIEWS):
        assert (fv == case).any(), f"no face in case {case.name}: the scene should produce all four"
    assert not (fv == FaceView.SURROUND).any()  # only with surround colours given
    assert res.texture.shape == (t, 2 * t, 3)
    u = res.face_uvs[..., 0]
    # direct-only (and neither) faces sample the left panel, reflected the right; a face seen in
    # both, the panel of the view it is larger in (ties: the reflected one, the paper's)
    samples = rig.face_samples(base, 2)
    larger_direct = (fv == FaceView.BOTH) & (samples["direct"] > samples["reflected"])
    assert larger_direct.any() and ((fv == FaceView.BOTH) & ~larger_direct).any()  # both kinds: a real test
    assert (u[(fv == FaceView.DIRECT) | (fv == FaceView.NEITHER) | larger_direct] <= 0.5 + 1e-6).all()
    assert (u[(fv == FaceView.REFLECTED) | ((fv == FaceView.BOTH) & ~larger_direct)] >= 0.5 - 1e-6).all()
    assert (res.face_panel == np.where(u.mean(axis=1) < 0.5, 0, 1)).all()
    # UVs are the projections: a direct face's corners map back to its NDC
    direct = rig.view("direct")
    ndc = direct.camera.project(direct.vertices_np(base.reshape(-1)))[:, :2]
    f = int(np.flatnonzero(fv == FaceView.DIRECT)[0])
    corners = ndc[rig.faces_np[f]]
    expect_u = np.clip((corners[:, 0] + 1) / 2, 0, 1) / 2
    expect_v = np.clip((corners[:, 1] + 1) / 2, 0, 1)
    assert np.allclose(res.face_uvs[f, :, 0], expect_u, atol=1e-6)
    assert np.allclose(res.face_uvs[f, :, 1], expect_v, atol=1e-6)
    # each panel: its picture, and a blend of red and blue under faces seen in both
    for panel, pure in ((res.texture[:, t:], [0, 0, 255]), (res.texture[:, :t], [255, 0, 0])):
        px = panel.reshape(-1, 3).astype(int)
        plain = (px == pure).all(axis=1)
        on_line = (px[:, 1] == 0) & (np.abs(px[:, 0] + px[:, 2] - 255) <= 1)
        assert plain.any() and (~plain).any() and on_line.all()


def _both_texels(res, t: int) -> dict[int, tuple[int, np.ndarray]]:  # noqa: ANN001
    """Per face seen in both views: (its panel, the texels of that panel it alone of them covers (flat indices))."""
    out = {}
    both = np.flatnonzero(res.face_view == FaceView.BOTH)
    for p in (0, 1):
        mine = both[res.face_panel[both] == p]
        uv = res.face_uvs[mine].astype(np.float64)
        tri = np.stack([(uv[..., 0] * 2 - p) * t, (1.0 - uv[..., 1]) * t], axis=-1)
        pix, ti, _ = raster_triangles_2d(tri, t, t)
        alone = np.bincount(pix, minlength=t * t) == 1
        out.update({int(mine[k]): (p, pix[(ti == k) & alone[pix]]) for k in range(mine.size)})
    return out


def test_a_face_seen_in_both_views_blends_them_by_its_share_of_each(small_rig,  # noqa: ANN001
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # the colour with the least squared error over both pictures: a sliver the eye barely sees directly
    # takes almost all of the reflected colour, and the reverse (the paper's rule, an even average, as an option)
    import saucerfab.optimize.texturing as texturing

    scene, base, rig = small_rig
    t = 64
    red, blue = red_and_blue(t)
    res = texture_saucer(rig, base, {"direct": red, "reflected": blue})
    samples = rig.face_samples(base, 2)
    panels = [res.texture[:, p * t:(p + 1) * t].reshape(-1, 3).astype(float) for p in (0, 1)]
    shares = {0: [], 1: []}
    for face, (p, texels) in _both_texels(res, t).items():
        if texels.size:
            want = samples["direct"][face] / (samples["direct"][face] + samples["reflected"][face])
            assert np.allclose(panels[p][texels, 0] / 255.0, want, atol=1.0 / 255), face
            shares[p].append(want)
    # faces on both panels, their shares differing: a real test
    assert len(shares[0]) >= 1 and min(shares[0]) > 0.5 and len(shares[1]) >= 3 and max(shares[1]) <= 0.5
    assert max(shares[0] + shares[1]) - min(shares[0] + shares[1]) > 0.2
    monkeypatch.setattr(texturing, "BOTH_WEIGHTING", "even")
    paper = texture_saucer(rig, base, {"direct": red, "reflected": blue})
    assert (paper.face_panel[paper.face_view == FaceView.BOTH] == 1).all()  # the paper's: the reflected panel
    assert (paper.texture[:, :t] == [255, 0, 0]).all()
    even = paper.texture[:, t:].reshape(-1, 3).astype(int)
    blended = ~(even == [0, 0, 255]).all(axis=1)
    assert (np.abs(even[blended] - [128, 0, 128]).max(axis=1) <= 1).all()
