"""The whole view in the optimizer (saucerfab.optimize.surround): cameras, weights, targets, energy, texture."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_optimize_texturing import red_and_blue

from saucerfab.errors import ConfigError
from saucerfab.model.camera import Camera
from saucerfab.model.design import FaceView
from saucerfab.model.heightfield import base_shape
from saucerfab.model.scene import Scene
from saucerfab.optimize.framing import fit_frames
from saucerfab.optimize.surround import (
    backgrounds_of,
    ideal_colors,
    inside_frame,
    outside_weights,
    surround_faces,
    whole_camera,
    whole_targets,
    whole_views,
)
from saucerfab.optimize.texturing import texture_saucer
from saucerfab.optimize.views import Rig

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def rig_and_base():
    n = 28
    scene = Scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=n))
    base = base_shape("waves", n)
    scene = fit_frames(scene, base, "inscribed")
    return scene, base, Rig(scene, base, image_size=64)


def test_whole_camera_takes_in_every_point_and_keeps_the_eye(rig_and_base) -> None:  # noqa: ANN001
    scene, base, rig = rig_and_base
    for view in rig.views:
        pts = view.vertices_np(base.reshape(-1))[np.unique(np.asarray(view.faces))]
        cam = whole_camera(view.camera, pts)
        ndc = cam.project(pts)
        assert cam.eye == view.camera.eye
        assert np.abs(ndc[:, :2]).max() <= 1.0
        # the bounding square with its margin: some point comes near the edge
        assert np.abs(ndc[:, :2]).max() > 0.9
        # about half the frame's pixel density
        density = cam.image_size / cam.tan_angle
        assert density == pytest.approx(view.camera.image_size / view.camera.tan_angle / 2, rel=0.1)


def test_outside_weights_are_zero_inside_the_frame_and_the_pixel_area_outside() -> None:
    frame = Camera((0.0, -5.5, 5.0), (0.0, -1.0, 0.0), 3.0, 64)
    whole = Camera(frame.eye, frame.target, 6.0, 48)
    w = outside_weights(whole, frame)
    area = ((2 * whole.tan_angle / 48) / (2 * frame.tan_angle / 64)) ** 2
    assert set(np.unique(w)) == {0.0, area}
    # the frame is the middle half of the whole view (tan 3 deg / tan 6 deg ~ 0.4993): about 24 x 24 pixels
    inside = int((w == 0).sum())
    assert 22 * 22 <= inside <= 26 * 26
    assert w[24, 24] == 0.0 and w[0, 0] == area and w[24, 0] == area
    # the frame itself: nothing outside
    assert not outside_weights(frame, frame).any()


def test_ideal_colours_are_the_picture_inside_the_frame_and_the_background_outside(rig_and_base) -> None:  # noqa: ANN001
    scene, base, rig = rig_and_base
    red = np.zeros((64, 64, 3))
    red[..., 0] = 1.0
    bg = np.array([0.2, 0.9, 0.3])
    for view in rig.views:
        cols = ideal_colors(view, base, red, bg, rig.num_faces)
        inside = np.zeros(rig.num_faces, bool)
        inside[np.asarray(view.face_src)[inside_frame(view, base)]] = True
        assert inside.any() and (~inside).any()
        assert np.allclose(cols[inside], [1.0, 0.0, 0.0])
        assert np.allclose(cols[~inside], bg)


def test_backgrounds_follow_the_design_background_or_the_border() -> None:
    img = np.full((16, 16, 3), 0.25)
    img[4:12, 4:12] = 0.9
    assert np.allclose(backgrounds_of({"direct": img})["direct"], 0.25)
    got = backgrounds_of({"direct": img}, "#ff0000")["direct"]
    assert np.allclose(got, [1.0, 0.0, 0.0])


def test_the_surround_energy_pulls_only_the_outside_towards_the_background(rig_and_base) -> None:  # noqa: ANN001
    scene, base, rig = rig_and_base
    wholes = whole_views(rig, base)
    assert [w.name for w in wholes] == ["direct", "reflected"]
    pics = {v.name: np.zeros((64, 64, 3)) for v in rig.views}  # black pictures on a white background
    bgs = {v.name: np.ones(3) for v in rig.views}
    sigma = 1e-5
    targets = whole_targets(wholes, base, pics, bgs, sigma, rig.num_faces, dtype=torch.float64)
    h = torch.as_tensor(base.reshape(-1), dtype=torch.float64)
    # every face black: the energy is the outside saucer, which should be white
    c = torch.zeros((rig.num_faces, 3), dtype=torch.float64, requires_grad=True)
    e = sum(w.energy(w.render(h, c, sigma), t) for w, t in zip(wholes, targets))
    assert float(e.detach()) > 0
    e.backward()
    g = c.grad.numpy()
    framed = np.zeros(rig.num_faces, bool)
    for view in rig.views:
        framed[np.asarray(view.face_src)[inside_frame(view, base)]] = True
    outside = np.zeros(rig.num_faces, bool)
    for w in wholes:
        outside[np.asarray(w.frame.face_src)[~inside_frame(w.frame, base)]] = True
    only_out = outside & ~framed
    # faces seen only outside the frames are pushed towards white (negative gradient on black)
    pushed = g[only_out].sum(axis=1)
    assert (pushed <= 1e-12).all() and (pushed < 0).sum() > 0.5 * only_out.sum()
    # and the target itself scores zero
    e0 = sum(w.energy(t, t) for w, t in zip(wholes, targets))
    assert float(e0) == 0.0


def test_gradcheck_of_the_surround_energy_on_a_tiny_rig() -> None:
    n = 6
    scene = Scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=n))
    base = base_shape("waves", n)
    rig = Rig(scene, base, image_size=16)
    wholes = whole_views(rig, base)
    pics = {v.name: np.full((16, 16, 3), 0.3) for v in rig.views}
    bgs = {v.name: np.array([0.9, 0.8, 0.7]) for v in rig.views}
    targets = whole_targets(wholes, base, pics, bgs, 1e-3, rig.num_faces, dtype=torch.float64)
    h0 = torch.as_tensor(base.reshape(-1), dtype=torch.float64)

    def energy(h, c):  # noqa: ANN001, ANN202
        return sum(w.energy(w.render(h, c, 1e-3), t) for w, t in zip(wholes, targets))

    h = (h0 + 0.01).requires_grad_(True)
    c = torch.full((rig.num_faces, 3), 0.5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(energy, (h, c), eps=1e-6, atol=1e-4, rtol=1e-3)


def test_texture_gives_faces_seen_only_around_the_frames_their_background(rig_and_base) -> None:  # noqa: ANN001
    scene, base, rig = rig_and_base
    t = 32
    red, blue = red_and_blue(t)
    plain = texture_saucer(rig, base, {"direct": red, "reflected": blue})
    wholes = whole_views(rig, base)
    visible = rig.visible_faces(base)
    framed = visible["direct"] | visible["reflected"]
    faces = surround_faces(rig, wholes, base, framed)
    assert faces["direct"].any() and faces["reflected"].any()
    assert not (faces["direct"] & faces["reflected"]).any() and not (faces["direct"] & framed).any()
    colours = [(faces["direct"], np.array([0.0, 1.0, 0.0])), (faces["reflected"], np.array([1.0, 1.0, 0.0]))]
    res = texture_saucer(rig, base, {"direct": red, "reflected": blue}, surround=colours)
    assert res.texture.shape == (t, 3 * t, 3)
    # the frames' texturing untouched: same cases and the same texels (UVs rescaled to three panels)
    assert np.array_equal(res.texture[:, : 2 * t], plain.texture)
    framed_cases = np.isin(plain.face_view, (FaceView.DIRECT, FaceView.REFLECTED, FaceView.BOTH))
    assert np.array_equal(res.face_view[framed_cases], plain.face_view[framed_cases])
    assert np.allclose(res.face_uvs[framed_cases, :, 0] * 3, plain.face_uvs[framed_cases, :, 0] * 2, atol=1e-5)
    # each surround face samples its own colour's stripe
    sur = res.face_view == FaceView.SURROUND
    assert sur.sum() == (faces["direct"] | faces["reflected"]).sum()
    for mask, colour in colours:
        uv = res.face_uvs[mask]
        col = res.texture[((1 - uv[..., 1]) * t).astype(int).clip(0, t - 1), (uv[..., 0] * 3 * t).astype(int)]
        assert (col == np.round(colour * 255)).all()
    # faces no one sees stay unknown (the bake continues their neighbours)
    assert (res.face_view == FaceView.NEITHER).sum() == (plain.face_view == FaceView.NEITHER).sum() - sur.sum()


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), True, "1"])
def test_the_request_refuses_a_bad_surround_weight(bad) -> None:  # noqa: ANN001
    from saucerfab.optimize.request import DesignRequest

    with pytest.raises(ConfigError, match="surround_weight"):
        DesignRequest(direct="a.png", reflected="b.png", surround_weight=bad)


def test_the_whole_view_is_on_for_the_full_method_and_off_for_the_papers_ablations() -> None:
    from saucerfab.optimize.request import SURROUND_WEIGHT, DesignRequest

    assert DesignRequest(direct="a.png", reflected="b.png").surround() == SURROUND_WEIGHT == 1.0
    assert DesignRequest(direct="a.png", reflected="b.png", surround_weight=0.0).surround() == 0.0
    assert DesignRequest(direct="a.png", reflected="b.png", ablation="laplacian").surround() == 0.0
    assert DesignRequest(direct="a.png", reflected="b.png", ablation="laplacian", surround_weight=0).surround() == 0.0
    with pytest.raises(ConfigError, match="--ablation laplacian runs the paper's Figure 11 setting.*give one of the two"):
        DesignRequest(direct="a.png", reflected="b.png", ablation="laplacian", surround_weight=1.0)
