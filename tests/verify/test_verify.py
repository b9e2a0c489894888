"""saucerfab verify: the ray trace of exported files, its scores, its CLI, and hostile folders.

The ray trace is held to a second, independent estimate
(``tests/verify_reference.py``: a numpy ray cast of a flat saucer and a
cylindrical cup from the design's own texture), in pixels and in the
reported PSNR.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from verify_designs import painted_design, picture
from verify_reference import cast

from saucerfab.cli import main
from saucerfab.fabricate.pipeline import export_design
from saucerfab.model.design import Design
from saucerfab.model.eyes import eye_positions
from saucerfab.verify import EyeSpec, parse_eyes, verify_print
from saucerfab.verify.core import FULL_COVERAGE, resize_box
from saucerfab.verify.metrics import PSNR_CAP_DB, best_shift, psnr, shifted, ssim

RES = 96


@pytest.fixture(scope="module")
def flat_print(tmp_path_factory) -> tuple[Path, Design]:
    design = painted_design(0.0)
    out = tmp_path_factory.mktemp("verify") / "print"
    export_design(design, out, printer="bureau", formats=["obj", "3mf", "glb"], cup_diameter_mm=80)
    return out, design


def _numpy_estimate(folder: Path, design: Design, view: str, eye) -> tuple[np.ndarray, np.ndarray]:
    scene = json.loads((folder / "scene.json").read_text())
    z_top = scene["model_to_file"][2][3] + scene["model_to_file"][2][2] * float(design.heights[0, 0])
    rgb, direct, refl = cast(scene, design.texture.astype(np.float64) / 255.0, z_top, eye, view, RES)
    return rgb, (direct if view == "direct" else refl)


def test_ray_trace_agrees_with_an_independent_numpy_ray_cast(flat_print, tmp_path):
    folder, design = flat_print
    result = verify_print(folder, eyes=EyeSpec("design"), res=RES, spp=16, pictures_dir=tmp_path, all_formats=False)
    for view in ("direct", "reflected"):
        rgb_n, cov_n = _numpy_estimate(folder, design, view, result.eyes[0].position)
        rgb_m = result.renders[("design", view)]
        region_m = result.renders[("design", view + ":region")]
        region_n = cov_n >= FULL_COVERAGE
        both = region_m & region_n
        iou = both.sum() / (region_m | region_n).sum()
        assert iou > 0.95, (view, iou)
        # the two renders of the same print agree pixel for pixel
        assert psnr(rgb_m, rgb_n, both) > 30.0, view
        # and the reported score agrees with the independent estimate within 1 dB
        ref = resize_box(design.references[view].astype(np.float32) / 255.0, RES)
        estimate = psnr(rgb_n, ref, region_n)
        reported = result.score(view, "design").psnr_db
        assert abs(reported - estimate) < 1.0, (view, reported, estimate)
        cov_reported = result.score(view, "design").coverage
        assert abs(cov_reported - cov_n.mean()) < 0.02, (view, cov_reported, cov_n.mean())
    # the direct view shows the heart it was textured with
    assert result.score("direct").psnr_db > 25.0


def test_every_textured_format_prints_alike(flat_print):
    folder, _ = flat_print
    result = verify_print(folder, eyes=EyeSpec("design"), res=64, spp=4, all_formats=True)
    assert [f.format for f in result.files] == ["obj", "3mf", "glb"]
    for view in ("direct", "reflected"):
        scores = [next(v.psnr_db for v in f.views if v.view == view) for f in result.files]
        assert max(scores) - min(scores) < 0.3, (view, scores)


def test_moved_eyes_are_scored_against_the_flat_print(flat_print):
    folder, _ = flat_print
    result = verify_print(folder, eyes=EyeSpec("both"), res=64, spp=4, all_formats=False)
    names = [e.name for e in result.eyes]
    assert names == ["design", "left", "right"]
    left, right = result.eyes[1].position, result.eyes[2].position
    assert math.dist(left, right) == pytest.approx(64.0)
    assert math.dist(left, result.eyes[0].position) == pytest.approx(32.0)
    assert len(result.files[0].views) == 6
    for v in result.files[0].views:
        if v.eye == "design":
            assert v.reference == "picture" and v.shift_px == (0, 0) and math.isnan(v.psnr_shift_db)
        else:
            assert v.reference == "flat print"
            assert v.psnr_shift_db >= v.psnr_unshifted_db - 1e-9  # the shift is chosen to help
    # this print is a flat print: from a moved eye its direct view is what the flat print shows,
    # though the tilted saucer's perspective keeps it far from the picture itself
    for eye in ("left", "right"):
        v = result.score("direct", eye)
        assert v.psnr_db > 30.0 and v.passed, v
        assert v.psnr_shift_db < v.psnr_db - 5.0, v


def test_prism_and_ellipse_cups_reflect_the_saucer(tmp_path):
    for cup in ("prism:6", "ellipse:0.45,0.35,20"):
        from saucerfab.model.cups import parse_cup_spec

        d = painted_design(0.0)
        d = replace(d, scene=replace(d.scene, cup=parse_cup_spec(cup)))
        out = tmp_path / cup.split(":")[0]
        export_design(d, out, printer="bureau", formats=["obj"], cup_diameter_mm=80)
        result = verify_print(out, eyes=EyeSpec("design"), res=48, spp=4)
        refl = result.score("reflected")
        assert refl.coverage > 0.05, (cup, refl)
        assert math.isfinite(refl.psnr_db)


# --------------------------------------------------------------------------- metrics and eyes


def test_psnr_ssim_and_shift_follow_their_definitions():
    rng = np.random.default_rng(0)
    a = rng.random((40, 40, 3)).astype(np.float32)
    m = np.ones((40, 40), bool)
    assert psnr(a, a, m) == PSNR_CAP_DB
    assert psnr(a, a + 0.1, m) == pytest.approx(20.0, abs=1e-4)  # MSE 0.01
    assert math.isnan(psnr(a, a, np.zeros((40, 40), bool)))
    assert ssim(a, a, m) == pytest.approx(1.0)
    assert ssim(a, 1 - a, m) < 0.0
    moved, inside = shifted(a, 3, -2)
    assert np.array_equal(moved[5, 10], a[7, 7]) and inside[5, 10] and not inside[-1, 0]
    sh = best_shift(moved, a, inside, max_shift=6)
    assert (sh.dx, sh.dy) == (3, -2)
    assert sh.psnr_db == PSNR_CAP_DB


def test_the_fft_shift_search_equals_the_one_shift_at_a_time_reference():
    from saucerfab.verify.metrics import mse_grid, mse_grid_reference

    rng = np.random.default_rng(3)
    for trial in range(3):
        a = rng.random((30, 34, 3))
        ref = rng.random((30, 34, 3))
        region = rng.random((30, 34)) > 0.3 * trial
        fast, slow = mse_grid(a, ref, region, 6), mse_grid_reference(a, ref, region, 6)
        assert np.array_equal(np.isinf(fast), np.isinf(slow))
        assert np.allclose(fast[np.isfinite(fast)], slow[np.isfinite(slow)], rtol=1e-9, atol=1e-12)


def test_eye_specs_parse_and_refuse_bad_values():
    assert parse_eyes("design").mode == "design"
    assert parse_eyes("BOTH", 60).ipd_mm == 60
    box = parse_eyes("box:40,20,3")
    assert box.box_mm == (40.0, 20.0) and box.box_steps == 3
    eyes = eye_positions(box, (0.0, -500.0, 500.0), (0.0, 0.0, 0.0))
    assert len(eyes) == 9 and eyes[0].name == "design"
    assert {e.offset_mm for e in eyes[1:]} == {(dx, du) for dx in (-20, 0, 20) for du in (-10, 0, 10)} - {(0, 0)}
    for bad in ("boxes", "box:1", "box:1,2,3,4", "box:-1,2", "box:5,5,1", "box:nan,1", "eyes"):
        with pytest.raises(Exception) as exc:
            parse_eyes(bad)
        assert "--eyes" in str(exc.value)
    with pytest.raises(Exception, match="ipd"):
        parse_eyes("both", 0)


# --------------------------------------------------------------------------- the CLI


def test_cli_writes_pictures_json_and_report_and_gates_on_levels(flat_print, tmp_path, capsys):
    folder, _ = flat_print
    work = tmp_path / "print"
    shutil.copytree(folder, work)
    rc = main(["verify", str(work), "--eyes", "design", "--res", "48", "--spp", "4", "--min-psnr", "0",
               "--min-coverage", "0", "--primary-only", "--json", "-q"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    import jsonschema

    from saucerfab.verify.schema import JSON_SCHEMA

    jsonschema.validate(doc, JSON_SCHEMA)
    assert doc["passed"] and {v["view"] for v in doc["files"][0]["views"]} == {"direct", "reflected"}
    assert (work / "verify" / "verify.json").is_file()
    assert (work / "verify" / "design_direct.png").is_file()
    assert (work / "report.html").is_file()
    rc = main(["verify", str(work), "--eyes", "design", "--res", "48", "--spp", "4", "--min-psnr", "99",
               "--primary-only", "-q"])
    out = capsys.readouterr().out
    assert rc == 1 and "LOW" in out and "where to stand" in out


def test_schema_prints(capsys):
    assert main(["verify", "--schema"]) == 0
    assert json.loads(capsys.readouterr().out)["properties"]["schema"]["const"] == "saucerfab.verify/3"


def _broken(folder: Path, tmp_path: Path, name: str, how) -> Path:
    work = tmp_path / name
    shutil.copytree(folder, work)
    how(work)
    return work


@pytest.mark.parametrize(
    "name, how, words",
    [
        ("no_scene", lambda p: (p / "scene.json").unlink(), "no scene.json"),
        ("garbage_scene", lambda p: (p / "scene.json").write_bytes(b"\xff\x00{"), "not valid JSON"),
        ("huge_scene", lambda p: (p / "scene.json").write_bytes(b" " * (2 << 20)), "over"),
        ("nan_camera", lambda p: (p / "scene.json").write_text(
            (p / "scene.json").read_text().replace('"position": [', '"position": [NaN, ', 1).replace(", 50.0,", ",", 1)),
         "camera.position"),
        ("deep_json", lambda p: (p / "scene.json").write_text("[" * 100000 + "]" * 100000), "not valid JSON"),
        ("bad_cup", lambda p: (p / "scene.json").write_text(
            (p / "scene.json").read_text().replace('"shape": "circle"', '"shape": "cone"')), "cup.shape"),
        ("no_reference", lambda p: (p / "reference_direct.png").unlink(), "reference_direct.png"),
        ("bomb_reference", lambda p: _bomb(p / "reference_direct.png"), "reference_direct.png"),
        ("garbage_obj", lambda p: [(p / n).write_bytes(b"\x00garbage" * 10) for n in ("saucer.obj",)]
         + [(p / n).unlink() for n in ("saucer.3mf", "saucer.glb")], "saucer.obj"),
        ("no_texture", lambda p: [(p / "saucer.png").unlink()] + [(p / n).unlink() for n in ("saucer.3mf", "saucer.glb")],
         "saucer.png"),
        ("no_mesh", lambda p: [(p / n).unlink() for n in ("saucer.obj", "saucer.3mf", "saucer.glb")], "no OBJ, 3MF or GLB"),
    ],
)
def test_a_broken_or_hostile_folder_is_exit_2_with_a_clear_message(flat_print, tmp_path, capsys, name, how, words):
    folder, _ = flat_print
    work = _broken(folder, tmp_path, name, how)
    before = sorted(p.name for p in work.iterdir())
    rc = main(["verify", str(work), "--eyes", "design", "--res", "32", "--spp", "1", "-q"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert words in err and "Traceback" not in err, err
    assert sorted(p.name for p in work.iterdir()) == before  # nothing written


def _bomb(path: Path) -> None:
    """A PNG whose header claims 100000 x 100000 pixels."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\x00" * 100)) + chunk(b"IEND", b""))


def test_not_a_folder_and_bad_options_are_exit_2(tmp_path, capsys):
    assert main(["verify", str(tmp_path / "nope"), "-q"]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["verify", str(tmp_path), "--eyes", "sideways", "-q"]) == 2
    assert "--eyes" in capsys.readouterr().err
    assert main(["verify", str(tmp_path), "--res", "3", "-q"]) == 2
    assert main(["verify", "-q"]) == 2


def test_a_zipped_obj_is_verified_like_the_plain_one(flat_print, tmp_path):
    from saucerfab.fabricate.options import FabOptions

    folder, design = flat_print
    out = tmp_path / "zipped"
    export_design(design, out, printer="bureau", formats=["obj"], cup_diameter_mm=80, options=FabOptions(obj_zip=True))
    assert not list(out.glob("*.obj")) and list(out.glob("*.zip"))
    zipped = verify_print(out, eyes=EyeSpec("design"), res=48, spp=4)
    plain = verify_print(folder, eyes=EyeSpec("design"), res=48, spp=4, all_formats=False)
    assert zipped.files[0].format == "zip"
    for view in ("direct", "reflected"):
        assert abs(zipped.score(view).psnr_db - plain.score(view).psnr_db) < 0.3


def test_a_two_reflection_print_is_verified_in_all_three_views(tmp_path):
    from saucerfab.model.cups import parse_cup_spec

    d = painted_design(0.0)
    moon = np.round(picture("reflected2_moon.png", 256) * 255).astype(np.uint8)
    scene = replace(d.scene, cup=parse_cup_spec("prism:6"), reflected2=d.scene.reflected)
    d = replace(d, scene=scene, references={**d.references, "reflected2": moon})
    out = tmp_path / "prism2"
    export_design(d, out, printer="bureau", formats=["obj"], cup_diameter_mm=80)
    assert (out / "reference_reflected2.png").is_file()
    assert "reflected2" in json.loads((out / "scene.json").read_text())["views"]
    result = verify_print(out, eyes=EyeSpec("both"), res=48, spp=4)
    assert [v.view for v in result.files[0].views][:3] == ["direct", "reflected", "reflected2"]
    assert result.score("reflected2").coverage > 0.05
    # a moved eye sees each facet's flat print too (the plate is not bridged across facets)
    for view in ("reflected", "reflected2"):
        v = result.score(view, "left")
        assert v.reference == "flat print" and v.pixels > 0 and math.isfinite(v.psnr_db), v
