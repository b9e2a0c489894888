"""Make the compressed glTF test files of this folder (run once; the results are vendored).

1. ``src.glb`` is written here by plain Python: a closed UV sphere (radius 30 mm, 16 rings x 24
   segments, 720 triangles) with NORMAL, TEXCOORD_0, COLOR_0, an embedded 16 x 16 PNG as the
   base colour texture and a short node animation (rotation and translation keyframes). Its seam and pole vertices repeat positions exactly (different UVs), so the
   checker's weld makes it watertight.
2. The compressed variants are made from ``src.glb`` by independent encoders from the npm registry,
   installed outside the repository (``cd /tmp/npmtools && npm install gltf-pipeline gltfpack``):

       python tests/data/gltf-compressed/make_files.py /tmp/npmtools/node_modules/.bin

   ``gltf-pipeline`` (Cesium, Draco through Google's draco3d encoder) and ``gltfpack``
   (meshoptimizer, EXT_/KHR_meshopt_compression and KHR_mesh_quantization). The exact commands and
   the tool versions are written to ``PROVENANCE.md`` by this script.

Without the tools argument only ``src.glb`` is (re)written.
"""

from __future__ import annotations

import io
import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: output name -> (tool, arguments after the tool, what it exercises)
VARIANTS: dict[str, tuple[str, list[str], str]] = {
    "draco.glb": ("gltf-pipeline", ["-i", "src.glb", "-o", "draco.glb", "-d"],
                  "KHR_draco_mesh_compression, edgebreaker (default level 7)"),
    "draco-seq.glb": ("gltf-pipeline", ["-i", "src.glb", "-o", "draco-seq.glb", "-d",
                                        "--draco.compressionLevel", "0"],
                      "KHR_draco_mesh_compression, sequential encoding (level 0)"),
    "meshopt.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt.glb", "-cc"],
                    "EXT_meshopt_compression (v0 vertex codec) + KHR_mesh_quantization + KHR_texture_transform"),
    "meshopt-fallback.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt-fallback.glb", "-c", "-cf"],
                             ("EXT_meshopt_compression with uncompressed fallback views (the decoder's reference; "
                              "-cf cannot go with -cc)")),
    "meshopt-khr.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt-khr.glb", "-cc", "-ce", "khr"],
                        "KHR_meshopt_compression (v1 vertex codec) + KHR_mesh_quantization"),
    "meshopt-khr-fallback.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt-khr-fallback.glb", "-c", "-ce",
                                              "khr", "-cf"],
                                 "KHR_meshopt_compression with uncompressed fallback views"),
    "meshopt-noq.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt-noq.glb", "-cc", "-noq"],
                        "EXT_meshopt_compression of float data (no quantization)"),
    "meshopt-float.glb": ("gltfpack", ["-i", "src.glb", "-o", "meshopt-float.glb", "-cc", "-ce", "khr", "-vpf",
                                       "-vtf", "-vnf"],
                          "KHR_meshopt_compression of float attributes (EXPONENTIAL filter) and COLOR filter"),
    "quantized.glb": ("gltfpack", ["-i", "src.glb", "-o", "quantized.glb"],
                      "KHR_mesh_quantization only (no compression)"),
}


def sphere(radius: float = 0.03, rings: int = 16, segments: int = 24) -> dict[str, np.ndarray]:
    """A UV sphere as glTF wants it: per-vertex UV (seam column and pole rows repeated)."""
    pos, nrm, uv, col = [], [], [], []
    for i in range(rings + 1):
        th = np.pi * i / rings
        for j in range(segments + 1):
            ph = 2 * np.pi * (j % segments) / segments  # the seam column repeats column 0 exactly
            n = np.array([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)])
            if i in (0, rings):
                n = np.array([0.0, 1.0 if i == 0 else -1.0, 0.0])  # one pole position per row
            pos.append(n * radius)
            nrm.append(n)
            uv.append([j / segments, i / rings])
            col.append([0.5 + 0.5 * n[0], 0.5 + 0.5 * n[1], 0.5 + 0.5 * n[2], 1.0])
    w = segments + 1
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = i * w + j, i * w + j + 1, (i + 1) * w + j, (i + 1) * w + j + 1
            if i != 0:
                tris.append([a, b, c])  # outward: counter-clockwise seen from outside
            if i != rings - 1:
                tris.append([b, d, c])
    used, idx = np.unique(np.array(tris), return_inverse=True)  # drop the one unused vertex per pole row
    return {
        "POSITION": np.array(pos, np.float32)[used], "NORMAL": np.array(nrm, np.float32)[used],
        "TEXCOORD_0": np.array(uv, np.float32)[used], "COLOR_0": np.array(col, np.float32)[used],
        "indices": idx.astype(np.uint16 if len(used) < 65536 else np.uint32).ravel(),
    }


def png_16() -> bytes:
    from PIL import Image

    y, x = np.mgrid[0:16, 0:16]
    img = np.stack([x * 16, y * 16, ((x + y) % 2) * 255], axis=-1).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def write_src(path: Path) -> None:
    s = sphere()
    blob = bytearray()
    views, accessors = [], []

    def add(arr: np.ndarray, target: int | None) -> int:
        while len(blob) % 4:
            blob.append(0)
        v = {"buffer": 0, "byteOffset": len(blob), "byteLength": arr.nbytes}
        if target:
            v["target"] = target
        blob.extend(arr.tobytes())
        views.append(v)
        return len(views) - 1

    attrs = {}
    for name in ("POSITION", "NORMAL", "TEXCOORD_0", "COLOR_0"):
        a = s[name]
        acc = {"bufferView": add(a, 34962), "componentType": 5126, "count": len(a),
               "type": {2: "VEC2", 3: "VEC3", 4: "VEC4"}[a.shape[1]]}
        if name == "POSITION":
            acc["min"], acc["max"] = a.min(0).tolist(), a.max(0).tolist()
        accessors.append(acc)
        attrs[name] = len(accessors) - 1
    accessors.append({"bufferView": add(s["indices"], 34963), "componentType": {2: 5123, 4: 5125}[s["indices"].itemsize],
                      "count": len(s["indices"]), "type": "SCALAR"})
    index_acc = len(accessors) - 1
    img_view = add(np.frombuffer(png_16(), np.uint8), None)
    # a one-second turn and bob of the node: gltfpack compresses its keyframes with the QUATERNION and
    # EXPONENTIAL filters (the checker itself reads no animations; the decoder tests do)
    t = np.linspace(0.0, 1.0, 5, dtype=np.float32)
    ang = t * np.pi
    rot = np.stack([np.zeros_like(t), np.sin(ang / 2), np.zeros_like(t), np.cos(ang / 2)], axis=1).astype(np.float32)
    tra = np.stack([np.zeros_like(t), 0.01 * np.sin(ang), np.zeros_like(t)], axis=1).astype(np.float32)
    anim_acc = []
    for arr, typ in ((t, "SCALAR"), (rot, "VEC4"), (tra, "VEC3")):
        acc = {"bufferView": add(arr, None), "componentType": 5126, "count": len(arr), "type": typ}
        if typ == "SCALAR":
            acc["min"], acc["max"] = [float(arr.min())], [float(arr.max())]
        accessors.append(acc)
        anim_acc.append(len(accessors) - 1)
    while len(blob) % 4:
        blob.append(0)
    doc = {
        "asset": {"version": "2.0", "generator": "saucerfab tests/data/gltf-compressed/make_files.py"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "sphere"}],
        "meshes": [{"primitives": [{"attributes": attrs, "indices": index_acc, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": 33071, "wrapT": 33071}],
        "images": [{"bufferView": img_view, "mimeType": "image/png"}],
        "animations": [{"samplers": [{"input": anim_acc[0], "output": anim_acc[1]},
                                     {"input": anim_acc[0], "output": anim_acc[2]}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}},
                                     {"sampler": 1, "target": {"node": 0, "path": "translation"}}]}],
        "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}],
    }
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    out = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js) + 8 + len(blob))
    out += struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(blob), b"BIN\x00") + bytes(blob)
    path.write_bytes(out)


def tool_version(bin_dir: Path, tool: str) -> str:
    if tool == "gltfpack":
        r = subprocess.run([str(bin_dir / tool), "-v"], capture_output=True, text=True, check=False)
    else:
        r = subprocess.run([str(bin_dir / tool), "--version"], capture_output=True, text=True, check=True)
    return (r.stdout + r.stderr).strip().splitlines()[0]


def main() -> int:
    write_src(HERE / "src.glb")
    if len(sys.argv) < 2:
        return 0
    bin_dir = Path(sys.argv[1]).resolve()
    versions = {t: tool_version(bin_dir, t) for t in ("gltf-pipeline", "gltfpack")}
    lines = []
    for name, (tool, args, what) in VARIANTS.items():
        subprocess.run([str(bin_dir / tool), *args], cwd=HERE, check=True, capture_output=True)
        size = (HERE / name).stat().st_size
        lines.append(f"| `{name}` | {size:,} | `{tool} {' '.join(args)}` | {what} |")
    prov = (HERE / "PROVENANCE.md").read_text() if (HERE / "PROVENANCE.md").exists() else ""
    head = prov.split("<!-- generated -->")[0]
    table = "\n".join([
        "<!-- generated -->",
        f"Tools: gltf-pipeline `{versions['gltf-pipeline']}`, gltfpack `{versions['gltfpack']}` (npm registry).",
        "",
        "| file | bytes | command (in this folder) | exercises |",
        "|---|---:|---|---|",
        *lines,
        "",
    ])
    (HERE / "PROVENANCE.md").write_text(head + table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
