"""The HTML 3D viewer (``saucerfab.pages.viewer``) in a real, headless Chromium.

One small synthetic design is exported once (GLB + scene.json, bureau
profile, 80 mm cup). Its viewer page is opened in Debian's Chromium through
Playwright (software WebGL, see ``tests/browser.py``) with the scene's own
circular cup and with an ellipse and a prism cup edited into the scene dict.
Each page must load without console errors, set ``window.saucerViewerReady``,
draw a non-blank canvas, build the cup where scene.json says (file frame mm
-> three.js world m: (x, y, z) -> (x, z, -y) / 1000) and show the saucer's
colours reflected in it. The circle page is also orbited with the mouse.

Pages and screenshots are kept in ``out/test-artifacts/`` for a developer to
look at. Chromium comes from ``.ci/install-tools``; a missing browser fails
these tests (they must not be skipped in CI).
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
from importlib import resources
from pathlib import Path
from typing import Any

import browser
import numpy as np
import pytest
from PIL import Image

from saucerfab.errors import ConfigError, InputFileError, SceneFileError
from saucerfab.fabricate.pipeline import export_design
from saucerfab.fabricate.scene_file import PrintScene, scene_from_dict
from saucerfab.model.design_folder import synthetic_design
from saucerfab.pages.viewer import viewer_html

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "out" / "test-artifacts"

#: evaluated after the page is ready: where the viewer put things
STATE_JS = """(() => {
  const v = window.saucerViewers["saucer-3d"];
  const wall = v.cup.children[0].geometry;
  wall.computeBoundingBox();
  const cam = v.camera, pos = wall.attributes.position, p = new v.THREE.Vector3();
  const w = v.renderer.domElement.clientWidth, h = v.renderer.domElement.clientHeight;
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (let i = 0; i < pos.count; i++) {
    p.fromBufferAttribute(pos, i).project(cam);
    const x = (p.x + 1) / 2 * w, y = (1 - p.y) / 2 * h;
    x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
  }
  return {
    cupMin: wall.boundingBox.min.toArray(), cupMax: wall.boundingBox.max.toArray(),
    camera: cam.position.toArray(), fov: cam.fov, target: v.controls.target.toArray(),
    cupRect: [x0, y0, x1, y1], timings: window.saucerViewerTimings,
  };
})()"""


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, dict[str, Any]]:
    out = tmp_path_factory.mktemp("viewer") / "print"
    export_design(
        synthetic_design(resolution=24), out, printer="bureau", formats=["glb"], cup_diameter_mm=80
    )
    return (out / "saucer.glb").read_bytes(), json.loads((out / "scene.json").read_text(encoding="utf-8"))


def _parsed(scene: dict[str, Any]) -> PrintScene:
    """``scene`` (a scene.json dict, maybe edited) through the one parse the viewer takes its scene from."""
    return scene_from_dict(scene, "test scene.json")


def _page(name: str, fragment: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"viewer-{name}.html"
    path.write_text(
        "<!doctype html><html><head><meta charset='utf-8'>"
        f"<title>saucerfab viewer: {name}</title></head>"
        "<body style='margin:20px;font-family:system-ui,sans-serif'>"
        f"<h2>Viewer test page: {name}</h2>{fragment}<p>(end of page)</p></body></html>",
        encoding="utf-8",
    )
    return path


def _cup(scene: dict[str, Any], shape: str) -> dict[str, Any]:
    base = scene["cup"]
    common = {"center": base["center"], "bottom_z": base["bottom_z"], "height": base["height"]}
    if shape == "circle":
        return dict(base)
    if shape == "ellipse":
        return {"shape": "ellipse", **common, "semi_axes": [40.0, 28.0], "rotation_deg": 30.0}
    return {"shape": "prism", **common, "sides": 6, "circumradius": 40.0, "rotation_deg": 15.0}


def _expected_cup_box(cup: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The cup wall's bounding box in the three.js world (m, y up), from the dict alone."""
    cx, cy = cup["center"]
    if cup["shape"] == "prism":
        t = math.radians(cup["rotation_deg"])
        ang = t + 2 * np.pi * np.arange(cup["sides"]) / cup["sides"]
        x, y = cx + cup["circumradius"] * np.cos(ang), cy + cup["circumradius"] * np.sin(ang)
    else:
        a, b = (cup["radius"],) * 2 if cup["shape"] == "circle" else cup["semi_axes"]
        t = math.radians(cup.get("rotation_deg", 0.0))
        phi = np.linspace(0, 2 * np.pi, 7201)
        lx, ly = a * np.cos(phi), b * np.sin(phi)
        x = cx + np.cos(t) * lx - np.sin(t) * ly
        y = cy + np.sin(t) * lx + np.cos(t) * ly
    z0, z1 = cup["bottom_z"], cup["bottom_z"] + cup["height"]
    lo = np.array([x.min(), z0, -y.max()]) / 1000
    hi = np.array([x.max(), z1, -y.min()]) / 1000
    return lo, hi


def _colourful_fraction(png: bytes, rect: list[float]) -> float:
    """Share of strongly coloured pixels in the upper 80 % of ``rect`` (the cup, not the saucer)."""
    img = Image.open(io.BytesIO(png)).convert("RGB")
    x0, y0, x1, y1 = rect
    y_cut = y0 + 0.8 * (y1 - y0)
    box = (max(0, int(x0)), max(0, int(y0)), min(img.width, int(x1)), min(img.height, int(y_cut)))
    hsv = np.asarray(img.crop(box).convert("HSV"), dtype=float) / 255
    return float(((hsv[..., 1] > 0.4) & (hsv[..., 2] > 0.2)).mean())


def _check(result: browser.PageResult, cup: dict[str, Any], name: str) -> None:
    assert result.errors == [], "\n".join(result.errors)
    assert result.ready
    canvas = result.element_png("canvas")
    (ARTIFACTS / f"viewer-{name}-canvas.png").write_bytes(canvas)
    assert browser.canvas_is_drawn(canvas), f"blank canvas, see {ARTIFACTS / f'viewer-{name}-canvas.png'}"
    info = result.info
    lo, hi = _expected_cup_box(cup)
    np.testing.assert_allclose(info["cupMin"], lo, atol=5e-5)
    np.testing.assert_allclose(info["cupMax"], hi, atol=5e-5)
    # the saucer's picture is reflected in the cup (a bare mirror shows greys only)
    share = _colourful_fraction(canvas, info["cupRect"])
    assert share > 0.03, f"the cup shows no reflected colours ({share:.3f}), see {result.screenshot}"


def test_viewer_circle_cup_and_orbit(exported: tuple[bytes, dict[str, Any]], chromium: None) -> None:
    glb, scene = exported
    page = _page("circle", viewer_html(glb, _parsed(scene)))

    def orbit(pg: Any) -> dict[str, Any]:
        box = pg.locator("canvas").bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        pg.mouse.move(cx, cy)
        pg.mouse.down()
        pg.mouse.move(cx + 160, cy + 30, steps=6)
        pg.mouse.up()
        pg.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        png = pg.locator("canvas").screenshot()
        (ARTIFACTS / "viewer-circle-orbited.png").write_bytes(png)
        cam = pg.evaluate("() => window.saucerViewers['saucer-3d'].camera.position.toArray()")
        return {"png": png, "camera": cam}

    result = browser.open_page(page, ARTIFACTS / "viewer-circle.png", evaluate=STATE_JS, interact=orbit)
    _check(result, scene["cup"], "circle")
    info = result.info
    # the camera starts at scene.json's camera, mapped to the world
    x, y, z = scene["camera"]["position"]
    np.testing.assert_allclose(info["camera"], [x / 1000, z / 1000, -y / 1000], atol=1e-6)
    assert 2 * scene["views"]["direct"]["viewing_angle_deg"] < info["fov"] < 60
    # the whole cup is in sight
    x0, y0, x1, y1 = info["cupRect"]
    assert 0 <= x0 < x1 <= 960 and 0 <= y0 < y1 <= 480
    # dragging orbits about the target: the camera moves, its distance stays
    moved, target = np.array(result.interaction["camera"]), np.array(info["target"])
    start = np.array(info["camera"])
    assert np.linalg.norm(moved - start) > 0.05
    assert np.linalg.norm(moved - target) == pytest.approx(np.linalg.norm(start - target), rel=1e-3)
    before = np.asarray(Image.open(io.BytesIO(result.element_png("canvas"))).convert("L"), dtype=float)
    after = np.asarray(Image.open(io.BytesIO(result.interaction["png"])).convert("L"), dtype=float)
    assert np.abs(before - after).mean() > 2
    assert browser.canvas_is_drawn(result.interaction["png"])


@pytest.mark.parametrize("shape", ["ellipse", "prism"])
def test_viewer_other_cups(exported: tuple[bytes, dict[str, Any]], chromium: None, shape: str) -> None:
    glb, scene = exported
    scene = {**scene, "cup": _cup(scene, shape)}
    page = _page(shape, viewer_html(glb, _parsed(scene)))
    result = browser.open_page(page, ARTIFACTS / f"viewer-{shape}.png", evaluate=STATE_JS)
    _check(result, scene["cup"], shape)


def test_viewer_failure_is_shown(exported: tuple[bytes, dict[str, Any]], chromium: None) -> None:
    glb, scene = exported
    broken = glb[:12] + b"\x00" * 64  # a glTF header and nothing valid after it
    page = _page("broken", viewer_html(broken, _parsed(scene), element_id="broken-view"))
    result = browser.open_page(
        page,
        ARTIFACTS / "viewer-broken.png",
        timeout_s=20,
        elements=(),
        evaluate="document.getElementById('broken-view-error').textContent",
    )
    assert not result.ready
    message = "saucerfab 3D viewer failed: cannot read the saucer's GLB"
    assert any(message in e for e in result.errors), result.errors
    assert result.info.startswith(message)


def test_viewer_html_checks_its_arguments(exported: tuple[bytes, dict[str, Any]]) -> None:
    glb, raw = exported
    scene = _parsed(raw)
    with pytest.raises(InputFileError, match="binary glTF"):
        viewer_html(b"not a glb", scene)
    # a bad scene is refused by the one parse before it reaches the viewer
    with pytest.raises(SceneFileError, match="schema"):
        _parsed({**raw, "schema": "saucerfab.scene/0"})
    with pytest.raises(SceneFileError, match="cup.shape"):
        _parsed({**raw, "cup": {**raw["cup"], "shape": "cone"}})
    with pytest.raises(SceneFileError, match="'camera' is missing"):
        _parsed({k: v for k, v in raw.items() if k != "camera"})
    with pytest.raises(TypeError, match="PrintScene"):
        viewer_html(glb, raw)  # type: ignore[arg-type]  # a raw dict is not checked here: parse it first
    with pytest.raises(ConfigError, match="element_id"):
        viewer_html(glb, scene, element_id="a b\"><script>")
    with pytest.raises(ConfigError, match="height_px"):
        viewer_html(glb, scene, height_px=0)


def test_viewer_html_is_self_contained(exported: tuple[bytes, dict[str, Any]]) -> None:
    glb, scene = exported
    html = viewer_html(glb, _parsed({**scene, "note": "</script><b>"}))
    # no URL that would need the network; the vendored modules and the GLB are inline
    assert not re.search(r"(?:src|href)\s*=|https?://[^\s\"']*\.js", html)
    found = re.search(r'<script type="importmap">(.*?)</script>', html, re.DOTALL)
    assert found
    imports = json.loads(found.group(1))["imports"]
    assert set(imports) >= {
        "three",
        "three/addons/loaders/GLTFLoader.js",
        "three/addons/controls/OrbitControls.js",
    }
    assert all(u.startswith("data:text/javascript;base64,") for u in imports.values())
    assert base64.b64encode(glb).decode() in html
    assert html.count("</script>") == 2  # the scene's text cannot end the script early


def test_vendored_three_is_package_data() -> None:
    folder = resources.files("saucerfab") / "data" / "viewer"
    names = {p.name for p in folder.iterdir()}
    assert {"three.module.min.js", "three.core.min.js", "GLTFLoader.js", "OrbitControls.js",
            "BufferGeometryUtils.js", "SkeletonUtils.js", "LICENSE", "README.md"} <= names
    assert "MIT License" in (folder / "LICENSE").read_text(encoding="utf-8")
    for name in names - {"LICENSE", "README.md"}:
        text = (folder / name).read_text(encoding="utf-8")
        # data: URL modules cannot resolve relative specifiers
        assert not re.search(r"""(?:from|import)\s*['"]\.{1,2}/""", text), name
