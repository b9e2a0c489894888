"""--eyes (issue 19): a rig per eye, its reflection against a brute-force ray trace, the multi-eye energy
against a hand sum of single-eye energies, the decal targets, the texture blend, the CLI and its refusals."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_mirror import CIRCLE, HEXAGON, hit_cup, scene_with

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.model.eyes import DEFAULT_IPD_MM, EyeSpec, eye_positions, eye_weights, parse_eyes
from saucerfab.model.heightfield import base_shape
from saucerfab.optimize.request import DesignRequest
from saucerfab.optimize.viewpoints import (
    EYE_IMAGE_SCALE,
    decal_height,
    decal_images,
    design_frame_ndc,
    eye_rigs,
    eye_scenes,
)
from saucerfab.optimize.views import ViewMeshes

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _small(cup=CIRCLE, n: int = 24, size: int = 32):  # type: ignore[no-untyped-def]
    scene = scene_with(cup)
    scene = replace(scene, saucer=replace(scene.saucer, resolution=n),
                    direct=replace(scene.direct, image_size=size), reflected=replace(scene.reflected, image_size=size))
    return scene, base_shape("waves", n)


def test_verify_and_design_share_one_definition_of_the_eyes() -> None:
    import saucerfab.verify as verify

    # verify takes the eyes from saucerfab.model.eyes itself (no re-export module of its own)
    assert verify.EyeSpec is EyeSpec and verify.parse_eyes is parse_eyes and DEFAULT_IPD_MM == 64.0
    assert parse_eyes("point").mode == parse_eyes("design").mode == "design"
    # one word for the design eye alone in every command; the older "point" is read as it
    assert DesignRequest.default("eyes") == "design" and DesignRequest.default("ipd_mm") is None
    assert DesignRequest("a.png", "b.png", eyes="point").eyes == "design"
    # model units and millimetres give the same eyes
    scene, _ = _small()
    s = scene.mm_per_unit
    mm = eye_positions(EyeSpec("both"), tuple(np.multiply(scene.camera, s)), tuple(np.multiply(scene.direct.target, s)))
    units = eye_positions(EyeSpec("both"), scene.camera, scene.direct.target, s)
    for a, b in zip(mm, units, strict=True):
        np.testing.assert_allclose(np.divide(a.position, s), b.position, atol=1e-12)
    assert np.linalg.norm(np.subtract(units[1].position, units[2].position)) * s == pytest.approx(64.0)
    assert eye_weights(units) == [0.5, 0.25, 0.25] and eye_weights(units[:1]) == [1.0]
    box = eye_positions(EyeSpec("box", box_mm=(40.0, 20.0)), scene.camera, scene.direct.target, s)
    assert len(box) == 9 and sum(eye_weights(box)) == pytest.approx(1.0)


@pytest.mark.parametrize("cup", [CIRCLE, HEXAGON], ids=["circle", "hexagon"])
def test_each_eyes_reflected_shape_against_a_brute_force_ray_trace(cup) -> None:  # noqa: ANN001
    """Every vertex of each eye's reflected view, at its virtual point R: the eye's ray towards R, reflected
    off the cup wall with the true 3-D normal (test_mirror's ray caster), passes through the saucer vertex."""
    scene, base = _small(cup)
    h = base.reshape(-1)
    shapes = []
    for eye in eye_rigs(scene, base, EyeSpec("both")):
        view = eye.rig.view("reflected")
        assert view.camera.eye == eye.scene.camera == tuple(eye.eye.position)
        r = view.vertices_np(h)
        q = np.concatenate([eye.rig.xy[np.asarray(view.vert_src)], h[np.asarray(view.vert_src), None]], axis=1)
        e = np.asarray(eye.scene.camera)
        d = (r - e) / np.linalg.norm(r - e, axis=1, keepdims=True)
        wall, nrm, hit, _ = hit_cup(scene.cup, e, d)
        assert hit.all()
        refl = d - 2.0 * np.einsum("ij,ij->i", d, nrm)[:, None] * nrm
        off = np.linalg.norm(np.cross(q - wall, refl), axis=1)  # distance of Q from the reflected ray
        assert off.max() < 1e-9, f"{eye.eye.name}: off by {off.max()}"
        assert len(view.vert_src) > 50
        shapes.append(dict(zip(np.asarray(view.vert_src).tolist(), map(tuple, view.xy))))
    # a curved mirror's reflected shape depends on the eye; a flat facet's virtual image does not
    common = set(shapes[0]) & set(shapes[1])
    moved = max(np.linalg.norm(np.subtract(shapes[0][k], shapes[1][k])) for k in common)
    assert moved > 1e-3 if cup is CIRCLE else moved < 1e-9


def test_the_decal_is_the_picture_on_a_flat_saucer_and_the_design_eyes_own_frame() -> None:
    scene, base = _small()
    flat = np.full_like(base, 0.03)
    eyes = eye_rigs(scene, flat, EyeSpec("both"))
    for eye in eyes:
        view = eye.rig.view("direct")
        # on a flat saucer at the decal's plane every eye's ray meets the vertex itself
        got = design_frame_ndc(scene, eye.scene, view, flat, 0.03)
        want = eyes[0].rig.view("direct").camera.project(view.vertices_np(flat))[:, :2]
        np.testing.assert_allclose(got, want, atol=1e-12)
    # for the design eye on the waves: its own projection (direct: exactly; mirror: the cup is flat at T)
    z0 = decal_height(base)
    for view in eyes[0].rig.views:
        got = design_frame_ndc(scene, scene, view, base, z0)
        want = view.camera.project(view.vertices_np(base))[:, :2]
        np.testing.assert_allclose(got, want, atol=1e-12 if view.name == "direct" else 2e-3)


def test_a_moved_eye_sees_the_picture_moved_as_the_verify_shift_finds() -> None:
    """The left eye's decal of a dot moves right in its frame (verify's shift of the left eye: +x)."""
    scene, base = _small(n=32, size=64)
    pic = np.ones((64, 64, 3))
    pic[28:36, 28:36] = 0.0
    eyes = eye_rigs(scene, base, EyeSpec("both"))
    cols = []
    for eye in eyes:
        d = decal_images(scene, eye, base, {"direct": pic, "reflected": pic}, decal_height(base), size=64)
        dark = d["direct"][..., 0] < 0.5
        cols.append(np.nonzero(dark)[1].mean())
    design, left, right = cols
    assert abs(design - 31.5) < 1.0
    assert left > design + 1 and right < design - 1


def test_the_multi_eye_energy_is_the_weighted_sum_of_single_eye_energies() -> None:
    """The pipeline's E_visual for --eyes both against single-eye rigs built here, float64, tiny sizes."""
    import torch

    from saucerfab.optimize.energies import e_visual
    from saucerfab.optimize.pipeline import _StageLoop
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.stages import ABLATION_STAGES
    from saucerfab.optimize.targets import blur_matched_targets
    from saucerfab.optimize.views import Rig

    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", resolution=12,
                        image_size=32, max_iters=2, eyes="both", w_large=1.0, w_small=1.0, lam=1.0, method="paper")
    prep = prepare(req)
    rig = Rig(prep.scene, prep.base)
    eyes = eye_rigs(prep.scene, prep.base, req.eye_spec(), rig_class=Rig, design_rig=rig)
    stages = ABLATION_STAGES["full"]
    loop = _StageLoop(req, prep, rig, stages, lambda *a: None, 1e9, 0.0, eyes)
    loop.dtype = torch.float64  # before any target is made
    spec = stages[0]
    targets = loop.targets_for(spec.targets, spec.sigma)
    objective = loop.objective(spec, [targets[v.name] for v in rig.views])
    gen = torch.Generator().manual_seed(3)
    h = torch.as_tensor(prep.base.reshape(-1), dtype=torch.float64) + 0.01 * torch.rand(rig.num_vertices, generator=gen, dtype=torch.float64)
    c = 0.1 + 0.8 * torch.rand((rig.num_faces, 3), generator=gen, dtype=torch.float64)
    _, parts = objective(h, c)

    hand = 0.0
    images = prep.enhanced
    mm = prep.scene.mm_per_unit
    for k, (name, dr, w) in enumerate([("design", 0.0, 0.5), ("left", -32.0, 0.25), ("right", 32.0, 0.25)]):
        right_axis = np.cross(np.subtract(prep.scene.direct.target, prep.scene.camera), (0, 0, 1))
        right_axis /= np.linalg.norm(right_axis)
        pos = tuple(np.add(prep.scene.camera, dr / mm * right_axis))
        sc = replace(prep.scene, camera=pos)
        size = 32 if k == 0 else int(32 * EYE_IMAGE_SCALE)
        one = Rig(sc, prep.base, image_size=size)
        if k == 0:
            pics = images
        else:
            pics = decal_images(prep.scene, eyes[k], prep.base, images, decal_height(prep.base))
        t = blur_matched_targets(one, prep.base, pics, spec.sigma, dtype=torch.float64)
        ev = float(e_visual(one.render(h, c, spec.sigma), [t[v.name] for v in one.views]))
        hand += w * (32 / size) ** 2 * ev
    assert parts["E_visual"] == pytest.approx(hand, rel=1e-9)


def test_the_texture_blend_keeps_what_every_eye_agrees_on() -> None:
    """A flat saucer: every eye wants the same texel colours on faces seen directly, so the blend keeps them."""
    from saucerfab.optimize.texturing import EyeViews, texture_saucer
    from saucerfab.optimize.views import Rig, visible_faces
    from saucerfab.render.texels import raster_triangles_2d

    scene, _ = _small(n=24, size=32)
    flat = np.full((24, 24), 0.03)
    rng = np.random.default_rng(0)
    images = {"direct": rng.uniform(size=(64, 64, 3)), "reflected": rng.uniform(size=(64, 64, 3))}
    eyes = eye_rigs(scene, flat, EyeSpec("both"), rig_class=Rig)
    plain = texture_saucer(eyes[0].rig, flat, images)
    others = [EyeViews(e.weight, e.rig, {v.name: design_frame_ndc(scene, e.scene, v, flat, 0.03) for v in e.rig.views})
              for e in eyes[1:]]
    blended = texture_saucer(eyes[0].rig, flat, images, eyes=others, design_weight=0.5)
    np.testing.assert_array_equal(plain.face_uvs, blended.face_uvs)
    # the texels under faces that no eye sees in the mirror: every eye wants the direct picture there
    in_mirror = np.zeros(len(plain.face_view), bool)
    for e in eyes:
        in_mirror |= visible_faces(e.rig, flat)["reflected"]
    uv = plain.face_uvs.astype(np.float64)
    tri = np.stack([uv[..., 0] * 2 * 64, (1 - uv[..., 1]) * 64], axis=-1)
    on_direct = np.flatnonzero(plain.face_panel == 0)
    pix, ti, _ = raster_triangles_2d(tri[on_direct], 64, 64)
    bad = np.zeros(64 * 64, bool)
    bad[pix[in_mirror[on_direct[ti]]]] = True
    good = np.zeros(64 * 64, bool)
    good[pix] = True
    good &= ~bad
    assert good.sum() > 300
    diff = plain.texture[:, :64].astype(int) - blended.texture[:, :64].astype(int)
    assert np.abs(diff.reshape(-1, 3)[good]).max() <= 1
    # where the eyes disagree (the mirror's decal moves with the eye; faces one eye sees in the mirror) texels blend
    assert (plain.texture != blended.texture).any()
    # ... unless the blend takes only colours that agree with the design eye's within 0: the design eye's texture
    import saucerfab.optimize.texturing as texturing

    old = texturing.EYE_BLEND_MAX_DIFF
    try:
        texturing.EYE_BLEND_MAX_DIFF = 0.0
        alone = texture_saucer(eyes[0].rig, flat, images, eyes=others, design_weight=0.5)
    finally:
        texturing.EYE_BLEND_MAX_DIFF = old
    np.testing.assert_array_equal(alone.texture, plain.texture)


def test_eyes_both_designs_end_to_end_and_records_its_eyes(tmp_path) -> None:  # noqa: ANN001
    out = tmp_path / "d"
    rc = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
               "--out", str(out), "--resolution", "12", "--image-size", "32", "--max-iters", "2", "--eyes", "both",
               "--ipd-mm", "60", "--quiet", "--no-verify"])
    assert rc == 0
    meta = json.loads((out / "design.json").read_text())
    p = meta["parameters"]
    assert p["eyes"] == "both" and p["ipd_mm"] == 60.0
    assert [(e["name"], e["offset_mm"], e["weight"]) for e in p["eyes_used"]] == [
        ("design", [0.0, 0.0], 0.5), ("left", [-30.0, 0.0], 0.25), ("right", [30.0, 0.0], 0.25)]
    assert all("E_visual_eyes" in st for st in meta["metrics"]["stages"])


def test_eyes_point_leaves_the_design_folder_as_before(tmp_path) -> None:  # noqa: ANN001
    from saucerfab.workflow import run_design

    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", resolution=12, image_size=32,
                        max_iters=2, record_times=False)
    run_design(req, tmp_path / "a", progress=lambda *a: None)
    p = json.loads((tmp_path / "a" / "design.json").read_text())["parameters"]
    assert "eyes" not in p and "ipd_mm" not in p and "eyes_used" not in p


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(eyes="point", ipd_mm=60.0), "drop --ipd-mm"),
        (dict(ipd_mm=60.0), "drop --ipd-mm"),
        (dict(eyes="box:40,20", ipd_mm=60.0), "drop --ipd-mm"),
        (dict(eyes="both", ipd_mm=0.0), "ipd-mm"),
        (dict(eyes="both", ipd_mm=float("nan")), "ipd-mm"),
        (dict(eyes="sideways"), "--eyes"),
        (dict(eyes="box:40"), "box:W,H"),
        (dict(eyes="box:40,20,1"), "N must be"),
        (dict(eyes=3), "eyes must be"),
        (dict(eyes="both", ipd_mm="64"), "ipd_mm must be"),
        (dict(eyes="both", reflected2="x.png", cup="prism:6"), "reflected2"),
    ],
)
def test_bad_or_contradictory_eye_options_are_refused(kw, match) -> None:  # noqa: ANN001
    with pytest.raises(ConfigError, match=match):
        DesignRequest("a.png", "b.png", **kw)


def test_the_cli_refuses_ipd_without_both(tmp_path, capsys) -> None:  # noqa: ANN001
    rc = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
               "--out", str(tmp_path / "d"), "--ipd-mm", "60"])
    assert rc != 0
    assert "--ipd-mm" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_eye_scenes_keep_the_frames() -> None:
    scene, _ = _small()
    for eye, _, sc in eye_scenes(scene, EyeSpec("both")):
        assert sc.direct == scene.direct and sc.reflected == scene.reflected and sc.saucer == scene.saucer
        assert sc.camera == eye.position
    assert isinstance(eye_rigs(scene, _small()[1], EyeSpec("design"))[0].rig, ViewMeshes)
