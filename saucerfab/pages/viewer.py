"""A self-contained, orbitable 3D view of an exported saucer and its mirror cup.

:func:`viewer_html` returns an HTML *fragment* for the body of a report page:
a canvas showing the printed part (``saucer.glb``) with orbit controls and the
mirror cup standing in its seat, reflecting the saucer. Everything is inline:
three.js r185 (vendored in ``saucerfab/data/viewer/``, see its README) goes in
as ``data:`` URLs in a ``<script type="importmap">``, the GLB as base64, so the
page works offline and from ``file://``.

Frames and units:

* ``scene`` is an export's ``scene.json`` (schema ``saucerfab.scene/1``) as
  read and checked by :mod:`saucerfab.fabricate.scene_file` (a
  :class:`~saucerfab.fabricate.scene_file.PrintScene`): the *file frame*,
  millimetres, z up. The page carries the file's object as it was read.
* The GLB's positions are the file frame in metres (mm / 1000); its one node
  rotates z-up into glTF's y-up. The viewer's three.js world is therefore
  metres, y up: a file point ``(x, y, z)`` mm sits at ``(x, z, -y) / 1000``.
  The cup, camera and targets from ``scene`` are mapped the same way.

The initial camera is the scene's camera, looking along the direct view's
axis, with a field of view wide enough for the whole saucer and cup; it
orbits about the point of that axis nearest the middle between saucer and
cup. The saucer is drawn unlit (its printed colours as they are in the
texture). The cup is a metal (metalness 1, roughness 0.02) whose environment
map is rendered once by a cube camera at the cup's centre, with the cup
hidden; reflection rays that go down are intersected with the saucer's mean
top height before the lookup (parallax correction), so the reflected picture
is close to what the real cylinder shows.

Page rules: the import map must come before any module script of the page
(browsers ignore a later one; the viewer then shows an error), so put the
fragment early or give the page no other module scripts. One viewer per page.
After the first frame the script sets ``window.saucerViewerReady = true``; on
failure it calls ``console.error`` and shows the message in place of the view.
"""

from __future__ import annotations

import base64
import functools
import json
import re
from importlib import resources
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, InputFileError
from saucerfab.fabricate.scene_file import CupSpec, PrintScene

#: import-map specifier -> vendored file in saucerfab/data/viewer
_MODULES: dict[str, str] = {
    "three": "three.module.min.js",
    "three/build/three.core.min.js": "three.core.min.js",
    "three/addons/loaders/GLTFLoader.js": "GLTFLoader.js",
    "three/addons/controls/OrbitControls.js": "OrbitControls.js",
    "three/addons/utils/BufferGeometryUtils.js": "BufferGeometryUtils.js",
    "three/addons/utils/SkeletonUtils.js": "SkeletonUtils.js",
}

#: straight pieces of a smooth cup's wall in the 3D view
WALL_SEGMENTS = 192
_ID_RE = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")


def _script_json(value: Any) -> str:
    """JSON that is safe inside a ``<script>`` element (no ``</script>``, no ``<!--``)."""
    text = json.dumps(value, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


@functools.cache
def _import_map() -> str:
    """The ``<script type="importmap">`` element with every vendored module as a data: URL."""
    folder = resources.files("saucerfab") / "data" / "viewer"
    imports = {
        spec: "data:text/javascript;base64,"
        + base64.b64encode((folder / name).read_bytes()).decode("ascii")
        for spec, name in _MODULES.items()
    }
    return f'<script type="importmap">{_script_json({"imports": imports})}</script>'


def _cup_wall(cup: CupSpec) -> np.ndarray:
    """The wall of a ``scene.json`` cup (mm, about its axis): :meth:`saucerfab.model.cups.Cup.wall`, shape (S, 2, 4)."""
    return cup.outline.wall(WALL_SEGMENTS)


def viewer_html(
    glb: bytes,
    scene: PrintScene,
    *,
    element_id: str = "saucer-3d",
    height_px: int = 480,
) -> str:
    """An HTML fragment showing ``glb`` and the mirror cup of ``scene``, orbitable.

    Args:
        glb: the bytes of an export's ``saucer.glb`` (positions in metres,
            file frame, one node rotating z-up to y-up).
        scene: the same export's ``scene.json`` (mm, z up), as read by
            :func:`saucerfab.fabricate.scene_file.read_scene_file` (a design's
            viewing dict: :func:`~saucerfab.fabricate.scene_file.scene_from_dict`).
        element_id: id of the fragment's outer ``<div>``; the canvas's
            wrapper is ``{element_id}-stage``, the error box
            ``{element_id}-error``.
        height_px: the canvas's height in CSS pixels; its width follows the
            container.

    Returns:
        A fragment (``<div>``, import map, module script) for a page's body.

    Raises:
        InputFileError: ``glb`` is not a binary glTF.
        ConfigError: a bad element id or height.
        TypeError: ``scene`` is not a parsed scene (a raw dict: parse it first).
    """
    if not isinstance(glb, (bytes, bytearray, memoryview)) or bytes(glb[:4]) != b"glTF":
        raise InputFileError("viewer: glb must be the bytes of a binary glTF (starts with 'glTF')")
    if not _ID_RE.fullmatch(element_id):
        raise ConfigError(f"viewer: element_id must match {_ID_RE.pattern}, got {element_id!r}")
    if isinstance(height_px, bool) or not isinstance(height_px, int) or not 64 <= height_px <= 4096:
        raise ConfigError(f"viewer: height_px must be an integer in [64, 4096], got {height_px!r}")
    if not isinstance(scene, PrintScene):
        raise TypeError(
            f"viewer: scene must be a PrintScene (saucerfab.fabricate.scene_file.scene_from_dict or "
            f"read_scene_file), got {type(scene).__name__}"
        )
    script = (
        _SCRIPT.replace("__ROOT_ID__", _script_json(element_id))
        .replace("__SCENE__", _script_json(dict(scene.source)))  # the file's object, every key as read
        .replace("__CUP_WALL__", _script_json(_cup_wall(scene.cup).round(4).tolist()))
        .replace("__GLB_B64__", '"' + base64.b64encode(bytes(glb)).decode("ascii") + '"')
    )
    return _BODY.format(id=element_id, h=height_px) + _import_map() + script


_BODY = """\
<div id="{id}" class="saucer-viewer" data-ready="false" style="margin:1em 0">
  <div id="{id}-stage" style="position:relative;width:100%;height:{h}px;\
background:#e9edf1;border-radius:6px;overflow:hidden;touch-action:none">
    <div id="{id}-error" role="alert" style="display:none;position:absolute;inset:0;\
padding:1em;color:#8a1111;background:#fff4f4;font:14px/1.4 system-ui,sans-serif;\
white-space:pre-wrap;overflow:auto"></div>
  </div>
  <p style="margin:.4em 0 0;font:13px/1.4 system-ui,sans-serif;color:#555">\
Drag to orbit, scroll to zoom, right-drag to pan, double-click to reset; the cup is a mirror.</p>
</div>
"""

_SCRIPT = r"""<script type="module">
const ROOT_ID = __ROOT_ID__;
const SCENE = __SCENE__;
const CUP_WALL = __CUP_WALL__;
const GLB_B64 = __GLB_B64__;
const root = document.getElementById(ROOT_ID);
const stage = document.getElementById(ROOT_ID + "-stage");
const errorBox = document.getElementById(ROOT_ID + "-error");

function fail(err) {
  const msg = "saucerfab 3D viewer failed: " + (err && err.message ? err.message : String(err));
  console.error(msg, err);
  errorBox.textContent = msg;
  errorBox.style.display = "block";
  root.dataset.ready = "error";
  window.saucerViewerError = msg;
}

const timings = {};
const mark = (k) => { timings[k] = Math.round(performance.now()); };
window.saucerViewerTimings = timings;

async function main() {
  mark("start");
  let THREE, GLTFLoader, OrbitControls;
  try {
    THREE = await import("three");
    ({ GLTFLoader } = await import("three/addons/loaders/GLTFLoader.js"));
    ({ OrbitControls } = await import("three/addons/controls/OrbitControls.js"));
  } catch (e) {
    throw new Error("cannot load three.js from the page's import map (it must come before "
      + "every other module script of the page): " + (e && e.message));
  }
  mark("imported");
  const V = (x, y, z) => new THREE.Vector3(x, y, z);
  // file frame (mm, z up) -> three.js world (m, y up): (x, y, z) -> (x, z, -y) / 1000
  const W = (p) => V(p[0] / 1000, p[2] / 1000, -p[1] / 1000);
  const Wdir = (d) => V(d[0], d[2], -d[1]);

  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true });
  } catch (e) {
    throw new Error("WebGL is not available in this browser (" + (e && e.message) + ")");
  }
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  renderer.setSize(stage.clientWidth || 640, stage.clientHeight || 480);
  renderer.domElement.style.display = "block";
  renderer.domElement.addEventListener("webglcontextlost", (ev) => {
    ev.preventDefault();
    fail(new Error("the WebGL context was lost"));
  });
  stage.insertBefore(renderer.domElement, errorBox);

  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8a84, 2.0));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(0.4, 1.0, 0.6);
  scene.add(sun);

  // the saucer, drawn unlit so its printed colours look as printed
  const bytes = Uint8Array.fromBase64 ? Uint8Array.fromBase64(GLB_B64)
    : Uint8Array.from(atob(GLB_B64), (ch) => ch.charCodeAt(0));
  let gltf;
  try {
    gltf = await new GLTFLoader().parseAsync(bytes.buffer, "");
  } catch (e) {
    throw new Error("cannot read the saucer's GLB: " + (e && e.message));
  }
  const saucer = gltf.scene;
  mark("parsed");
  saucer.traverse((o) => {
    if (!o.isMesh) return;
    const old = o.material;
    o.material = new THREE.MeshBasicMaterial({
      map: old.map || null,
      color: old.color ? old.color.clone() : new THREE.Color(0xcccccc),
      vertexColors: !!o.geometry.attributes.color,
      side: old.side,
    });
    old.dispose();
  });
  scene.add(saucer);
  saucer.updateMatrixWorld(true);
  const saucerBox = new THREE.Box3().setFromObject(saucer);
  if (saucerBox.isEmpty()) throw new Error("the GLB has no geometry");

  // mean height of the saucer's upward faces inside the printed picture (world y)
  const sx = SCENE.saucer && SCENE.saucer.x_range, sy = SCENE.saucer && SCENE.saucer.y_range;
  let hSum = 0, aSum = 0;
  const a = V(0, 0, 0), b = V(0, 0, 0), c = V(0, 0, 0), n = V(0, 0, 0), e = V(0, 0, 0);
  saucer.traverse((o) => {
    if (!o.isMesh) return;
    const pos = o.geometry.attributes.position, idx = o.geometry.index;
    const count = idx ? idx.count : pos.count;
    for (let i = 0; i + 2 < count; i += 3) {
      const k = idx ? [idx.getX(i), idx.getX(i + 1), idx.getX(i + 2)] : [i, i + 1, i + 2];
      a.fromBufferAttribute(pos, k[0]).applyMatrix4(o.matrixWorld);
      b.fromBufferAttribute(pos, k[1]).applyMatrix4(o.matrixWorld);
      c.fromBufferAttribute(pos, k[2]).applyMatrix4(o.matrixWorld);
      n.subVectors(b, a).cross(e.subVectors(c, a));
      const area = n.length() / 2;
      if (area <= 0 || n.y < 1.4 * area) continue; // not facing up (> ~45 deg off)
      const cx = (a.x + b.x + c.x) / 3 * 1000, cy = -(a.z + b.z + c.z) / 3 * 1000;
      if (sx && (cx < sx[0] || cx > sx[1] || cy < sy[0] || cy > sy[1])) continue;
      hSum += area * (a.y + b.y + c.y) / 3;
      aSum += area;
    }
  });
  const saucerPlaneY = aSum > 0 ? hSum / aSum : saucerBox.max.y;

  // the mirror cup, built in the file frame and mapped to the world
  const cupDef = SCENE.cup;
  const z0 = cupDef.bottom_z, z1 = cupDef.bottom_z + cupDef.height;
  const [ccx, ccy] = cupDef.center;
  const ring = []; // [x, y, nx, ny] per wall vertex (mm, file frame), in pairs per segment
  // the wall's straight pieces with their outward normals, from the cup's own
  // shape (saucerfab.model.cups, Cup.wall), each end [x, y, nx, ny] in mm about the cup's axis
  for (const [p, q] of CUP_WALL) ring.push([ccx + p[0], ccy + p[1], p[2], p[3]], [ccx + q[0], ccy + q[1], q[2], q[3]]);
  const wallPos = [], wallNrm = [], lidPos = [];
  const lidZ = z1;
  const push = (arr, v) => arr.push(v.x, v.y, v.z);
  const centreTop = W([ccx, ccy, lidZ]);
  for (let i = 0; i < ring.length; i += 2) {
    const [p, q] = [ring[i], ring[i + 1]];
    const A = W([p[0], p[1], z0]), B = W([q[0], q[1], z0]);
    const C = W([q[0], q[1], z1]), D = W([p[0], p[1], z1]);
    const nA = Wdir([p[2], p[3], 0]), nB = Wdir([q[2], q[3], 0]);
    for (const [v, nv] of [[A, nA], [B, nB], [C, nB], [A, nA], [C, nB], [D, nA]]) {
      push(wallPos, v); push(wallNrm, nv);
    }
    push(lidPos, centreTop); push(lidPos, W([p[0], p[1], lidZ])); push(lidPos, W([q[0], q[1], lidZ]));
  }
  const wallGeo = new THREE.BufferGeometry();
  wallGeo.setAttribute("position", new THREE.Float32BufferAttribute(wallPos, 3));
  wallGeo.setAttribute("normal", new THREE.Float32BufferAttribute(wallNrm, 3));
  const lidGeo = new THREE.BufferGeometry();
  lidGeo.setAttribute("position", new THREE.Float32BufferAttribute(lidPos, 3));
  lidGeo.computeVertexNormals();

  // software WebGL (SwiftShader, llvmpipe) takes seconds to prefilter a big
  // cube map; a smaller one looks nearly the same at this size
  const gl = renderer.getContext();
  const dbg = gl.getExtension("WEBGL_debug_renderer_info");
  const glName = String(gl.getParameter(dbg ? dbg.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  const software = /swiftshader|llvmpipe|softpipe|software/i.test(glName);
  const probePos = W([ccx, ccy, (z0 + z1) / 2]);
  const cubeTarget = new THREE.WebGLCubeRenderTarget(software ? 128 : 512,
    { type: software ? THREE.UnsignedByteType : THREE.HalfFloatType });
  const cubeCamera = new THREE.CubeCamera(0.001, 50, cubeTarget);
  cubeCamera.position.copy(probePos);
  const mirror = new THREE.MeshStandardMaterial({
    color: 0xffffff, metalness: 1.0, roughness: 0.02, envMap: cubeTarget.texture,
  });
  // parallax correction: a reflection ray going down is cut with the saucer's
  // mean top plane and the cube map is read towards that point from the probe
  mirror.onBeforeCompile = (shader) => {
    shader.uniforms.saucerProbePos = { value: probePos };
    shader.uniforms.saucerPlaneY = { value: saucerPlaneY };
    shader.vertexShader = "varying vec3 vSaucerWorldPos;\n" + shader.vertexShader.replace(
      "#include <worldpos_vertex>",
      "#include <worldpos_vertex>\nvSaucerWorldPos = (modelMatrix * vec4(transformed, 1.0)).xyz;");
    const hook = "reflectVec = transformDirectionByInverseViewMatrix( reflectVec, viewMatrix );";
    const chunk = THREE.ShaderChunk.envmap_physical_pars_fragment;
    if (!chunk.includes(hook)) return; // another three.js: plain cube-map reflection
    shader.fragmentShader = shader.fragmentShader.replace("#include <envmap_physical_pars_fragment>", [
      "varying vec3 vSaucerWorldPos;",
      "uniform vec3 saucerProbePos;",
      "uniform float saucerPlaneY;",
      "vec3 saucerParallax( vec3 dir ) {",
      "  if ( dir.y < -1e-4 ) {",
      "    float t = ( saucerPlaneY - vSaucerWorldPos.y ) / dir.y;",
      "    if ( t > 0.0 ) return normalize( vSaucerWorldPos + t * dir - saucerProbePos );",
      "  }",
      "  return dir;",
      "}",
      chunk.replace(hook, hook + "\nreflectVec = saucerParallax( reflectVec );"),
    ].join("\n"));
  };
  const cup = new THREE.Group();
  cup.name = "cup";
  cup.add(new THREE.Mesh(wallGeo, mirror));
  cup.add(new THREE.Mesh(lidGeo, new THREE.MeshStandardMaterial({ color: 0x202326, roughness: 0.6 })));
  scene.add(cup);
  const cupBox = new THREE.Box3().setFromObject(cup);

  // a soft studio backdrop for the reflections (the cube camera's view only)
  const skyGeo = new THREE.SphereGeometry(20, 48, 24);
  const skyCol = [], sp = skyGeo.attributes.position;
  const top = new THREE.Color(0xf7f9fb), mid = new THREE.Color(0xdde3e9), low = new THREE.Color(0x8c959e);
  for (let i = 0; i < sp.count; i++) {
    const h = sp.getY(i) / 20;
    const col = h >= 0 ? mid.clone().lerp(top, Math.min(1, h * 1.5))
      : mid.clone().lerp(low, Math.min(1, -h * 3));
    skyCol.push(col.r, col.g, col.b);
  }
  skyGeo.setAttribute("color", new THREE.Float32BufferAttribute(skyCol, 3));
  const sky = new THREE.Mesh(skyGeo, new THREE.MeshBasicMaterial({
    vertexColors: true, side: THREE.BackSide, depthWrite: false,
  }));
  sky.position.set(saucerBox.getCenter(V(0, 0, 0)).x, saucerPlaneY, saucerBox.getCenter(V(0, 0, 0)).z);
  sky.renderOrder = -1;
  sky.visible = false; // shown only while the cube camera renders
  scene.add(sky);
  scene.background = new THREE.Color(0xeef1f4);

  // camera: the scene's, looking at the direct view's target, then turned by
  // the few degrees that centre saucer and cup in the picture
  const camPos = W(SCENE.camera.position);
  const axisTarget = W(SCENE.views.direct.target);
  const up = Wdir(SCENE.camera.up || [0, 0, 1]).normalize();
  const camera = new THREE.PerspectiveCamera(30, 1, 1e-3, 100);
  camera.position.copy(camPos);
  camera.up.copy(up);
  camera.lookAt(axisTarget);
  camera.updateMatrixWorld(true);
  // points that must be in sight: the cup's rims and (a sample of) the saucer's vertices
  const sightPts = [];
  for (let i = 0; i < wallPos.length; i += 3) sightPts.push(V(wallPos[i], wallPos[i + 1], wallPos[i + 2]));
  saucer.traverse((o) => {
    if (!o.isMesh) return;
    const pos = o.geometry.attributes.position, step = Math.max(1, Math.floor(pos.count / 20000));
    for (let i = 0; i < pos.count; i += step) {
      sightPts.push(V(0, 0, 0).fromBufferAttribute(pos, i).applyMatrix4(o.matrixWorld));
    }
  });
  const toCam = camera.matrixWorld.clone().invert();
  const ext = [Infinity, -Infinity, Infinity, -Infinity];
  for (const p of sightPts) {
    const q = p.clone().applyMatrix4(toCam), depth = Math.max(-q.z, 1e-6);
    const ah = Math.atan(q.x / depth), av = Math.atan(q.y / depth);
    ext[0] = Math.min(ext[0], ah); ext[1] = Math.max(ext[1], ah);
    ext[2] = Math.min(ext[2], av); ext[3] = Math.max(ext[3], av);
  }
  const aim = V(Math.tan((ext[0] + ext[1]) / 2), Math.tan((ext[2] + ext[3]) / 2), -1)
    .transformDirection(camera.matrixWorld);
  const mid3 = saucerBox.getCenter(V(0, 0, 0)).add(cupBox.getCenter(V(0, 0, 0))).multiplyScalar(0.5);
  const pivot = camPos.clone().addScaledVector(aim, mid3.clone().sub(camPos).dot(aim));
  const dist = pivot.distanceTo(camPos);
  camera.near = dist / 500;
  camera.far = dist * 40;
  camera.lookAt(pivot);
  const minFov = 2.3 * SCENE.views.direct.viewing_angle_deg;
  function fitFov(aspect) {
    // vertical fov (deg) that shows sightPts from the camera as it points now
    camera.updateMatrixWorld(true);
    const inv = camera.matrixWorld.clone().invert();
    let tv = 0, th = 0;
    const q = V(0, 0, 0);
    for (const p of sightPts) {
      q.copy(p).applyMatrix4(inv);
      const depth = Math.max(-q.z, 1e-6);
      tv = Math.max(tv, Math.abs(q.y) / depth);
      th = Math.max(th, Math.abs(q.x) / depth);
    }
    const half = Math.atan(Math.max(tv, th / aspect) * 1.06);
    return Math.min(100, Math.max(minFov, 2 * half * 180 / Math.PI));
  }

  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(pivot);
  controls.minDistance = dist * 0.05;
  controls.maxDistance = Math.min(dist * 6, 15);
  controls.update();
  controls.saveState();
  let touched = false;
  controls.addEventListener("start", () => { touched = true; });

  let pending = false;
  const render = () => renderer.render(scene, camera);
  const requestRender = () => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; render(); });
  };
  controls.addEventListener("change", requestRender);
  renderer.domElement.addEventListener("dblclick", () => { controls.reset(); touched = false; resize(); });

  function resize() {
    const w = Math.max(1, stage.clientWidth), h = Math.max(1, stage.clientHeight);
    renderer.setSize(w, h);
    camera.aspect = w / h;
    if (!touched) camera.fov = fitFov(camera.aspect);
    camera.updateProjectionMatrix();
    requestRender();
  }
  new ResizeObserver(resize).observe(stage);
  const w0 = Math.max(1, stage.clientWidth), h0 = Math.max(1, stage.clientHeight);
  camera.aspect = w0 / h0;
  camera.fov = fitFov(camera.aspect);
  camera.updateProjectionMatrix();
  renderer.setSize(w0, h0);

  mark("built");
  cup.visible = false;
  sky.visible = true;
  cubeCamera.update(renderer, scene);
  sky.visible = false;
  cup.visible = true;
  render();
  if (gl.isContextLost()) throw new Error("the WebGL context was lost while drawing");
  window.saucerViewers = Object.assign(window.saucerViewers || {}, {
    [ROOT_ID]: { THREE, renderer, scene, camera, controls, cup, saucer, render: requestRender },
  });
  // ready once the GPU has really finished the first frame (software GL takes seconds)
  await new Promise((resolve) => {
    const sync = gl.fenceSync(gl.SYNC_GPU_COMMANDS_COMPLETE, 0);
    gl.flush();
    const poll = () => {
      if (gl.getSyncParameter(sync, gl.SYNC_STATUS) === gl.SIGNALED) { gl.deleteSync(sync); resolve(); }
      else setTimeout(poll, 20);
    };
    poll();
  });
  mark("drawn");
  requestAnimationFrame(() => {
    root.dataset.ready = "true";
    window.saucerViewerReady = true;
  });
}

try {
  await main();
} catch (err) {
  fail(err);
}
</script>
"""
