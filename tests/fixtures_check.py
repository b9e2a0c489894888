"""Fixture meshes and minimal writers for the checker's tests and benchmark.

Everything is generated here: good meshes (boxes, a closed textured saucer
solid), minimal writers for textured 3MF, OBJ+MTL+PNG, PLY, VRML 2.0 and
STL written independently of saucerfab's own exporters, and the hostile
corpus (zip bombs, billion laughs, path traversal, decompression bombs...).
"""

from __future__ import annotations

import io
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_MAT = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02"

# -- meshes ---------------------------------------------------------------------


def box(size: tuple[float, float, float] = (40.0, 30.0, 20.0), origin: tuple[float, float, float] = (0, 0, 0)
        ) -> tuple[np.ndarray, np.ndarray]:
    """A closed box, outward normals: (8, 3) vertices, (12, 3) faces."""
    x, y, z = size
    V = np.array([[0, 0, 0], [x, 0, 0], [x, y, 0], [0, y, 0], [0, 0, z], [x, 0, z], [x, y, z], [0, y, z]], float)
    V += np.asarray(origin, float)
    F = np.array([
        [0, 2, 1], [0, 3, 2],  # bottom (-z)
        [4, 5, 6], [4, 6, 7],  # top (+z)
        [0, 1, 5], [0, 5, 4],  # y = 0
        [1, 2, 6], [1, 6, 5],  # x = x
        [2, 3, 7], [2, 7, 6],  # y = y
        [3, 0, 4], [3, 4, 7],  # x = 0
    ])
    return V, F


def box_uv(V: np.ndarray) -> np.ndarray:
    """Per-vertex UVs of a box from x and y (all inside [0, 1])."""
    lo, hi = V.min(axis=0), V.max(axis=0)
    return (V[:, :2] - lo[:2]) / (hi[:2] - lo[:2])


def saucer_solid(n: int = 40, size_mm: float = 100.0, base_mm: float = 3.0, amp_mm: float = 4.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed heightfield solid like a saucer design: wavy top, flat bottom, vertical sides.

    Returns (vertices, faces, per-vertex uv in [0, 1]). Triangles: 4 (n-1)^2 + 8 (n-1).
    """
    xs = np.linspace(0, size_mm, n)
    gx, gy = np.meshgrid(xs, xs)
    h = base_mm + amp_mm * (0.5 + 0.5 * np.sin(gx / size_mm * 6.0) * np.cos(gy / size_mm * 5.0))
    return heightfield_solid(h, xs, xs)


def heightfield_solid(h: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The closed solid under heights ``h`` (rows along ``ys``, columns along ``xs``, mm, all > 0).

    Flat bottom at z = 0, vertical sides. Returns (vertices, faces, per-vertex uv in [0, 1]).
    """
    ny, nx = h.shape
    gx, gy = np.meshgrid(xs, ys)
    top = np.stack([gx.ravel(), gy.ravel(), np.asarray(h, np.float64).ravel()], axis=1)
    bot = np.stack([gx.ravel(), gy.ravel(), np.zeros(nx * ny)], axis=1)
    V = np.concatenate([top, bot])
    m = nx * ny
    idx = np.arange(m).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    top_f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    bot_f = top_f[:, ::-1] + m
    ring = np.concatenate([idx[0, :-1], idx[:-1, -1], idx[-1, ::-1][:-1], idx[::-1, 0][:-1]])
    nxt = np.roll(ring, -1)
    # the ring runs counter-clockwise seen from +z, so side quads (top i, top j, bottom j, bottom i) face out
    side = np.concatenate([np.stack([ring, ring + m, nxt + m], 1), np.stack([ring, nxt + m, nxt], 1)])
    F = np.concatenate([top_f, bot_f, side])
    lo, hi = V[:, :2].min(axis=0), V[:, :2].max(axis=0)
    uv = (V[:, :2] - lo) / (hi - lo)
    return V, F, uv


def png_bytes(w: int = 64, h: int = 64, seed: int = 0) -> bytes:
    """An RGB PNG: gradients and a checkerboard (compresses well even when large)."""
    from PIL import Image

    yy, xx = np.indices((h, w))
    arr = np.stack([xx * 255 // max(w - 1, 1), yy * 255 // max(h - 1, 1),
                    ((xx // 16 + yy // 16 + seed) % 2) * 255], axis=2).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    return buf.getvalue()


# -- writers -------------------------------------------------------------------------


def model_xml(V: np.ndarray, F: np.ndarray, *, uv: np.ndarray | None = None, unit: str = "millimeter",
              texture_path: str = "/3D/Texture/texture.png", corner_uv: np.ndarray | None = None,
              colors: bool = False, extra_resources: str = "", item_transform: str | None = None) -> str:
    """A 3MF model document; textured when ``uv`` (per vertex) or ``corner_uv`` (m, 3, 2) is given."""
    res = [extra_resources]
    tri_attr = ["" for _ in range(len(F))]
    if uv is not None or corner_uv is not None:
        res.append(f'<m:texture2d id="2" path="{texture_path}" contenttype="image/png"/>')
        if corner_uv is not None:
            coords = corner_uv.reshape(-1, 2)
            tri_attr = [f' pid="3" p1="{3 * i}" p2="{3 * i + 1}" p3="{3 * i + 2}"' for i in range(len(F))]
        else:
            coords = uv
            tri_attr = [f' pid="3" p1="{a}" p2="{b}" p3="{c}"' for a, b, c in F]
        res.append('<m:texture2dgroup id="3" texid="2">'
                   + "".join(f'<m:tex2coord u="{u:.6f}" v="{v:.6f}"/>' for u, v in coords)
                   + "</m:texture2dgroup>")
    if colors:
        res.append('<m:colorgroup id="4"><m:color color="#FF0000"/><m:color color="#00FF00"/></m:colorgroup>')
        tri_attr = [' pid="4" p1="0" p2="1" p3="0"' for _ in range(len(F))]
    verts = "".join(f'<vertex x="{x:.6f}" y="{y:.6f}" z="{z:.6f}"/>' for x, y, z in V)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"{t}/>' for (a, b, c), t in zip(F, tri_attr))
    tr = f' transform="{item_transform}"' if item_transform else ""
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<model unit="{unit}" xml:lang="en-US" xmlns="{NS_CORE}" xmlns:m="{NS_MAT}">\n'
        f'<resources>{"".join(res)}<object id="1" type="model"><mesh><vertices>{verts}</vertices>'
        f'<triangles>{tris}</triangles></mesh></object></resources>\n'
        f'<build><item objectid="1"{tr}/></build>\n</model>\n'
    )


CONTENT_TYPES = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    '<Default Extension="png" ContentType="image/png"/></Types>'
)
RELS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>'
)

TEXTURE_RELS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    '<Relationship Target="%s" Id="rel1" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dtexture"/></Relationships>'
)


def write_3mf(path: Path, V: np.ndarray, F: np.ndarray, *, uv: np.ndarray | None = None,
              texture: bytes | None = None, model: str | None = None, extra: dict[str, bytes] | None = None,
              **kw: object) -> Path:
    """A 3MF package; pass ``texture`` (PNG bytes) with ``uv``, or ``model`` to write raw XML."""
    xml = model if model is not None else model_xml(V, F, uv=uv, **kw)  # type: ignore[arg-type]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", CONTENT_TYPES)
        z.writestr("_rels/.rels", RELS)
        z.writestr("3D/3dmodel.model", xml)
        if texture is not None:
            z.writestr("3D/Texture/texture.png", texture)
            # the 3D texture relationship a texture needs (Materials 6; lib3mf refuses a texture without it)
            z.writestr("3D/_rels/3dmodel.model.rels", TEXTURE_RELS % kw.get("texture_path", "/3D/Texture/texture.png"))
        for name, data in (extra or {}).items():
            z.writestr(name, data)
    return path


def write_obj(path: Path, V: np.ndarray, F: np.ndarray, *, uv: np.ndarray | None = None,
              texture: bytes | None = None, texture_name: str = "texture.png", vertex_colors: bool = False,
              write_texture: bool = True) -> Path:
    """OBJ (+ MTL + PNG when ``uv`` is given)."""
    lines = []
    if uv is not None:
        lines.append(f"mtllib {path.stem}.mtl")
        (path.parent / f"{path.stem}.mtl").write_text(f"newmtl mat0\nKd 1 1 1\nmap_Kd {texture_name}\n")
        if texture is not None and write_texture:
            (path.parent / texture_name).write_bytes(texture)
    for x, y, z in V:
        lines.append(f"v {x:.6f} {y:.6f} {z:.6f}" + (" 0.5 0.2 0.1" if vertex_colors else ""))
    if uv is not None:
        lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
        lines.append("usemtl mat0")
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in F]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ply(path: Path, V: np.ndarray, F: np.ndarray, *, binary: bool = True, colors: bool = False,
              uv: np.ndarray | None = None, texture: str | None = None) -> Path:
    """PLY with optional vertex colours and per-vertex UVs (s, t) + a TextureFile comment."""
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0"]
    if texture:
        head.append(f"comment TextureFile {texture}")
    head += [f"element vertex {len(V)}", "property float x", "property float y", "property float z"]
    if uv is not None:
        head += ["property float s", "property float t"]
    if colors:
        head += ["property uchar red", "property uchar green", "property uchar blue"]
    head += [f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"]
    out = ("\n".join(head) + "\n").encode()
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if uv is not None:
        fields += [("s", "<f4"), ("t", "<f4")]
    if colors:
        fields += [("r", "u1"), ("g", "u1"), ("b", "u1")]
    rec = np.zeros(len(V), dtype=fields)
    rec["x"], rec["y"], rec["z"] = V[:, 0], V[:, 1], V[:, 2]
    if uv is not None:
        rec["s"], rec["t"] = uv[:, 0], uv[:, 1]
    if colors:
        rec["r"], rec["g"], rec["b"] = 200, 100, 50
    if binary:
        frec = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", 3)])
        frec["n"] = 3
        frec["i"] = F
        out += rec.tobytes() + frec.tobytes()
    else:
        rows = [" ".join(str(v) for v in r) for r in rec.tolist()]
        rows += [f"3 {a} {b} {c}" for a, b, c in F]
        out += ("\n".join(rows) + "\n").encode()
    path.write_bytes(out)
    return path


def write_stl(path: Path, V: np.ndarray, F: np.ndarray, *, ascii: bool = False) -> Path:
    tri = V[F]
    if ascii:
        lines = ["solid test"]
        for t in tri:
            lines += ["facet normal 0 0 0", "outer loop"] + [f"vertex {x:.6e} {y:.6e} {z:.6e}" for x, y, z in t]
            lines += ["endloop", "endfacet"]
        lines.append("endsolid test")
        path.write_text("\n".join(lines) + "\n")
        return path
    rec = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    path.write_bytes(b"binary stl".ljust(80, b" ") + struct.pack("<I", len(F)) + rec.tobytes())
    return path


def write_vrml(path: Path, V: np.ndarray, F: np.ndarray, *, uv: np.ndarray | None = None,
               texture: str | None = None, translate: tuple[float, float, float] | None = None) -> Path:
    """A VRML 2.0 file: one Shape with an IndexedFaceSet (in a Transform when ``translate`` is given)."""
    app = ""
    if texture:
        app = f'appearance Appearance {{ texture ImageTexture {{ url "{texture}" }} }}'
    pts = ", ".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in V)
    idx = ", ".join(f"{a}, {b}, {c}, -1" for a, b, c in F)
    tc = ""
    if uv is not None:
        tc = f"texCoord TextureCoordinate {{ point [ {', '.join(f'{u:.6f} {v:.6f}' for u, v in uv)} ] }}"
    shape = (f"Shape {{ {app}\n geometry IndexedFaceSet {{ solid TRUE\n coord DEF C Coordinate {{ point [ {pts} ] }}\n"
             f" {tc}\n coordIndex [ {idx} ] }} }}")
    if translate is not None:
        shape = f"Transform {{ translation {translate[0]} {translate[1]} {translate[2]} children [ {shape} ] }}"
    path.write_text("#VRML V2.0 utf8\n# written by the saucerfab tests\n" + shape + "\n")
    return path


def write_glb(path: Path, V: np.ndarray, F: np.ndarray, *, uv: np.ndarray | None = None,
              texture: bytes | None = None, scale: float = 0.001) -> Path:
    """A minimal GLB (positions scaled to metres by ``scale``), optionally textured with an embedded PNG."""
    import json

    pos = (V * scale).astype("<f4").tobytes()
    ind = F.astype("<u4").tobytes()
    chunks = [pos, ind]
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
             {"buffer": 0, "byteOffset": len(pos), "byteLength": len(ind)}]
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": len(V), "type": "VEC3",
         "min": (V * scale).min(0).tolist(), "max": (V * scale).max(0).tolist()},
        {"bufferView": 1, "componentType": 5125, "count": F.size, "type": "SCALAR"},
    ]
    prim: dict[str, object] = {"attributes": {"POSITION": 0}, "indices": 1}
    doc: dict[str, object] = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
                              "nodes": [{"mesh": 0}], "meshes": [{"primitives": [prim]}]}
    off = len(pos) + len(ind)
    if uv is not None:
        uvb = uv.astype("<f4").tobytes()
        chunks.append(uvb)
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(uvb)})
        acc.append({"bufferView": 2, "componentType": 5126, "count": len(uv), "type": "VEC2"})
        prim["attributes"] = {"POSITION": 0, "TEXCOORD_0": 2}
        off += len(uvb)
        if texture is not None:
            pad = (-off) % 4
            chunks.append(b"\0" * pad)
            off += pad
            chunks.append(texture)
            views.append({"buffer": 0, "byteOffset": off, "byteLength": len(texture)})
            off += len(texture)
            doc["images"] = [{"bufferView": 3, "mimeType": "image/png"}]
            doc["textures"] = [{"source": 0}]
            doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
            prim["material"] = 0
    binb = b"".join(chunks)
    binb += b"\0" * ((-len(binb)) % 4)
    doc["buffers"] = [{"byteLength": len(binb)}]
    doc["bufferViews"] = views
    doc["accessors"] = acc
    js = json.dumps(doc).encode()
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binb), b"BIN\x00") + binb
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


# -- hostile corpus ------------------------------------------------------------------


def zip_bomb_3mf(path: Path, inflated: int = 64 << 20) -> Path:
    """A valid-looking 3MF whose model part inflates to ``inflated`` bytes of spaces (ratio ~1000:1).

    Pass ``lie=True`` to :func:`lie_about_sizes` afterwards for headers that understate the size.
    """
    head = f'<?xml version="1.0"?><model unit="millimeter" xmlns="{NS_CORE}">'.encode()
    chunk = b" " * (1 << 20)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", CONTENT_TYPES)
        z.writestr("_rels/.rels", RELS)
        with z.open("3D/3dmodel.model", "w", force_zip64=True) as fh:
            fh.write(head)
            for _ in range(inflated >> 20):
                fh.write(chunk)
    return path


def billion_laughs_3mf(path: Path) -> Path:
    ents = '<!ENTITY lol "lol">' + "".join(
        f'<!ENTITY lol{i} "{("&lol" + (str(i - 1) if i > 1 else "") + ";") * 10}">' for i in range(1, 10))
    xml = (f'<?xml version="1.0"?>\n<!DOCTYPE model [{ents}]>\n'
           f'<model unit="millimeter" xmlns="{NS_CORE}"><metadata name="x">&lol9;</metadata>'
           '<resources/><build/></model>')
    return write_3mf(path, np.zeros((0, 3)), np.zeros((0, 3), int), model=xml)


def external_entity_3mf(path: Path) -> Path:
    xml = ('<?xml version="1.0"?>\n<!DOCTYPE model [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>\n'
           f'<model unit="millimeter" xmlns="{NS_CORE}"><metadata name="x">&xxe;</metadata>'
           '<resources/><build/></model>')
    return write_3mf(path, np.zeros((0, 3)), np.zeros((0, 3), int), model=xml)


def traversal_3mf(path: Path) -> Path:
    V, F = box()
    return write_3mf(path, V, F, extra={"../../evil.txt": b"pwned"})


def png_bomb(width: int = 100_000, height: int = 100_000) -> bytes:
    """A tiny PNG whose header claims ``width`` x ``height`` pixels (grey, 1 bit would be smaller; 8-bit is fine)."""
    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    comp = zlib.compressobj(9)
    row = b"\0" * (width + 1)
    data = comp.compress(row * 4) + comp.flush()  # only a few rows: the header is what matters
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b"")


def lie_about_sizes(path: Path, entry: str, claimed: int = 1000) -> Path:
    """Rewrite the central-directory (and local) uncompressed size of ``entry`` to ``claimed`` bytes."""
    data = bytearray(path.read_bytes())
    name = entry.encode()
    # central directory headers: signature PK\x01\x02, uncompressed size at +24, name length at +28, name at +46
    pos = data.find(b"PK\x01\x02")
    while pos >= 0:
        nlen = struct.unpack_from("<H", data, pos + 28)[0]
        xlen = struct.unpack_from("<H", data, pos + 30)[0]
        if bytes(data[pos + 46 : pos + 46 + nlen]) == name:
            if struct.unpack_from("<I", data, pos + 24)[0] == 0xFFFFFFFF:  # zip64: size in the extra field
                extra = pos + 46 + nlen
                struct.pack_into("<Q", data, extra + 4, claimed)
            else:
                struct.pack_into("<I", data, pos + 24, claimed)
        pos = data.find(b"PK\x01\x02", pos + 46 + nlen + xlen)
    path.write_bytes(bytes(data))
    return path
