"""Benchmark: the checker's worst cases on hostile files (issue 16) - time and peak memory per file.

    .venv/bin/python benchmarks/bench_check_hostile.py [--only NAME,...] [--large] [--timeout 120]
                                                      [--pythonpath DIR] [--out FILE]

Each hostile file of issue 16 is built at the size the issue measured it
(sparse files and deflate keep them small on disk; the builders are the
tests' own, from ``tests/check/test_check_budgets.py``), then checked by
``check_mesh`` with the default limits in a fresh Python process, one per
file, so that each figure is that file's alone: wall time of ``check_mesh``
itself and of the whole process, and the process's peak resident memory
(``/usr/bin/time``'s maximum resident set size: the interpreter and
numpy take about 45 MB of it before the file is opened). The target is at most 10 s
and 1 GiB per file. Honest meshes over the default ``Limits.max_triangles``
(1 million triangles in each format, 99,999 instances of a box) are among
them: refused from their headers.

``--large`` adds the worst files *within* every default limit together,
built at the limits themselves (``Limits()``): per format a closed mesh of
``max_triangles`` triangles; the same as a triangle soup of
``max_vertices`` vertices with one texture of ``max_texture_pixels``
(8192 x 8192); a GLB soup embedding a noisy texture near
``max_texture_bytes``; ASCII STL, ASCII PLY and OBJ soups padded to
``max_file_bytes``; a pile of ``max_triangles`` overlapping triangles
(self-intersection budget); ``max_parts`` parts sharing ``max_triangles`` in 3MF, GLB and VRML. They
cost what checking that much costs, and are what the defaults are chosen
by. A warm-up child compiles the numba kernels first, as ``make install``
does, so no case pays compile time.

``--pythonpath DIR`` runs the children against another source tree (a
``git archive`` of an older commit, say) for before/after figures; each
child is limited to 6 GiB of address space, so a runaway shows up as a
MemoryError rather than taking the machine's memory from others.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the builders live with the tests
sys.path.insert(0, str(ROOT / "tests" / "check"))  # (test_check_budgets)

import fixtures_check as fx  # noqa: E402
import test_check_budgets as hb  # noqa: E402

MIB = 1 << 20
CHILD_AS_LIMIT = 6 << 30

CHILD = r"""
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
from saucerfab.check import check_mesh
t = time.perf_counter()
r = check_mesh(sys.argv[1])
el = time.perf_counter() - t
verdict, _, rest = r.reason().partition(": ")
print(json.dumps({{"s": el, "exit": r.exit_code, "code": verdict, "message": rest}}))
"""


def machine() -> str:
    model = "?"
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10, check=False).stdout
        model = next((ln.split(":", 1)[1].strip() for ln in out.splitlines() if ln.startswith("Model name")), "?")
    except (OSError, subprocess.SubprocessError):
        pass
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / (1 << 30)
    return f"{model}, nproc {os.cpu_count()}, {mem:.0f} GiB; Python {platform.python_version()}"


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, timeout=10, check=False).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        one, five, fifteen = os.getloadavg()
        return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f}"


# -- the hostile files, at the sizes ------------------------------------------------


def _obj_plain(path: Path, n: int) -> Path:
    return hb.obj_indented_vertices(path, n, indent=b"")


def _obj_huge_index(path: Path) -> Path:
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n")
    return path


def _obj_index_zero(path: Path) -> Path:
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 -1 -2\nv 0 0 1\n")
    return path


def _textures_zip(path: Path, n: int, px: int) -> Path:
    png = fx.png_bytes(px, px)  # one encode, stored n times
    return hb.zipped_obj_with_textures(path, [png] * n)


def _vrml_tokens(path: Path, n_groups: int) -> Path:
    import gzip

    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(b"#VRML V2.0 utf8\n" + b"Group { } " * n_groups)
    return path


def _vertices_3mf(path: Path, n: int) -> Path:
    """A 3MF of ``n`` identical vertices (fast-path grammar) and one triangle: 27 bytes each, deflated 400:1."""
    head = (f'<?xml version="1.0"?><model unit="millimeter" xmlns="{fx.NS_CORE}"><resources><object id="1" '
            'type="model"><mesh><vertices>').encode()
    return hb.streamed_3mf(path, head, b'<vertex x="0" y="0" z="0"/>', n,
                           b'</vertices><triangles><triangle v1="0" v2="1" v3="2"/></triangles></mesh></object>'
                           b'</resources><build><item objectid="1"/></build></model>')


def _zipped(path: Path, name: str, body: bytes) -> Path:
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(name, body)
    return path


def _zipped_obj(path: Path, n: int) -> Path:
    """``n`` vertex lines of two-digit numbers and one face, zipped (~1000:1)."""
    return _zipped(path, "m.obj", b"v 10 10 10\n" * n + b"f 1 2 3\n")


def _zipped_ascii_ply(path: Path, n: int) -> Path:
    head = (f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n").encode()
    return _zipped(path, "m.ply", head + b"10 10 10\n" * n + b"3 0 1 2\n")


def _instances(path: Path, n: int) -> Path:
    def edit(doc: dict) -> None:  # type: ignore[type-arg]
        doc["nodes"] = [{"children": list(range(1, n + 1))}] + [
            {"mesh": 0, "translation": [0.05 * (i % 300), 0.05 * (i // 300), 0.0]} for i in range(n)]
    return hb.glb_with(path, edit)


#: (name, what, builder(folder) -> path); the issue's cases first, then the extras this fix also bounds
CASES: list[tuple[str, str, Callable[[Path], Path]]] = [
    ("gltf-tree-18", "GLB, every node lists the next twice, 18 deep (issue: 6.4 s)",
     lambda d: hb.gltf_shared_tree(d / "t18.glb", 18)),
    ("gltf-tree-20", "the same, 20 deep (issue: 24 s)", lambda d: hb.gltf_shared_tree(d / "t20.glb", 20)),
    ("gltf-tree-30", "the same, 30 deep (issue: over 120 s)", lambda d: hb.gltf_shared_tree(d / "t30.glb", 30)),
    ("gltf-tree-30-empty", "the same without a mesh at the leaf (2^31 node visits)",
     lambda d: hb.gltf_shared_tree(d / "t30e.glb", 30, mesh=False)),
    ("gltf-fan", "GLB, 3 nodes with 3000 repeated children (issue: 99.5 s)", lambda d: hb.gltf_fan(d / "fan.glb")),
    ("gltf-fan-empty", "the same without a mesh", lambda d: hb.gltf_fan(d / "fane.glb", mesh=False)),
    ("gltf-buffers-10", ".gltf, one 200 MB file named by 10 buffers (issue: 2.0 GB)",
     lambda d: hb.gltf_shared_buffers(d / "b10.gltf", 10, 200 * MIB)),
    ("gltf-buffers-40", "the same, 40 buffers (issue: ~7 GB, MemoryError)",
     lambda d: hb.gltf_shared_buffers(d / "b40.gltf", 40, 200 * MIB)),
    ("gltf-buffers-files", ".gltf, 10 buffers naming 10 different 200 MB files",
     lambda d: hb.gltf_shared_buffers(d / "bf.gltf", 10, 200 * MIB, n_files=10)),
    ("obj-16M-plain", "OBJ, 16 M vertex lines (over the limit of the time, 15 M) (issue: 2.4 s, 160 MB)",
     lambda d: _obj_plain(d / "plain.obj", 16_000_000)),
    ("obj-16M-indented", "the same lines led by two spaces (issue: 18 s, 2.6 GB)",
     lambda d: hb.obj_indented_vertices(d / "indented.obj", 16_000_000)),
    ("obj-huge-index", "OBJ, face index 99999999999999999999999 (issue: internal_error)",
     lambda d: _obj_huge_index(d / "huge.obj")),
    ("obj-index-zero", "OBJ, 'f 0 -1 -2' on the line-by-line path (issue: read as a later vertex)",
     lambda d: _obj_index_zero(d / "zero.obj")),
    ("3mf-zip-bomb", "3MF, 0.9 MB inflating to 900 MB of spaces (issue: 6.7 s, 2.8 GB)",
     lambda d: fx.zip_bomb_3mf(d / "bomb.3mf", inflated=900 * MIB)),
    ("3mf-zip-bomb-lying", "the same with its headers claiming 1,000 bytes (zipfile stops there: bad CRC)",
     lambda d: fx.lie_about_sizes(fx.zip_bomb_3mf(d / "liar.3mf", inflated=900 * MIB), "3D/3dmodel.model", 1000)),
    ("wrz-bomb", ".wrz, 1 GB of spaces gzipped to 1 MB (issue: 1.1 GB)",
     lambda d: hb.wrz_bomb(d / "bomb.wrz", 1000 * MIB)),
    ("zip-64-textures", "zipped OBJ with 64 textures of 8192 x 8192 (issue: 13-29 s)",
     lambda d: _textures_zip(d / "tex.zip", 64, 8192)),
    ("3mf-xml-elements", "3MF, 31 M empty elements (120 MiB) deflated to 0.1 MB",
     lambda d: hb.xml_element_bomb_3mf(d / "tree.3mf", 31_457_280)),
    ("3mf-14M-vertices", "3MF, 14 M vertices (fast-path grammar) deflated to 0.9 MB",
     lambda d: _vertices_3mf(d / "verts.3mf", 14_000_000)),
    ("wrz-number-array", ".wrz, one point array of 133 M numbers (400 MB) gzipped to 0.4 MB",
     lambda d: hb.wrz_number_array(d / "numbers.wrz", 133_000_000)),
    ("wrz-tokens", ".wrz, 1.6 M empty Group nodes (4.8 M tokens) gzipped to 31 kB",
     lambda d: _vrml_tokens(d / "tokens.wrz", 1_600_000)),
    ("zip-obj-16MiB", "zipped OBJ (32 kB): 1.5 M vertex lines, 16.5 MB, just under the free inflation",
     lambda d: _zipped_obj(d / "obj.zip", 1_500_000)),
    ("zip-obj-32MiB", "zipped OBJ (64 kB): 3 M vertex lines, 33 MB, past it",
     lambda d: _zipped_obj(d / "obj32.zip", 3_000_000)),
    ("zip-ply-16MiB", "zipped ASCII PLY (25 kB): 1.8 M vertices, 16.2 MB",
     lambda d: _zipped_ascii_ply(d / "ply.zip", 1_800_000)),
    ("glb-json-values", "GLB whose JSON holds 15 M empty objects (60 MB, within Limits.max_json_bytes)",
     lambda d: hb.glb_json_bomb(d / "json.glb", 15_000_000)),
]

def _plain(path: Path, textured: bool = True) -> Path:
    """A saucer-like closed heightfield solid of 999,996 triangles (wavy top, flat bottom) in ``path``'s format."""
    V, F, uv = fx.saucer_solid(n=500)
    write = {".glb": fx.write_glb, ".obj": fx.write_obj, ".3mf": fx.write_3mf, ".stl": fx.write_stl,
             ".ply": fx.write_ply}[path.suffix]
    if textured and path.suffix in (".glb", ".obj", ".3mf"):
        return write(path, V, F, uv=uv, texture=fx.png_bytes(512, 512))
    return write(path, V, F)


#: honest meshes over the default max_triangles: refused from their headers (they were the --large cases
#: when the default was 5 M)
CASES += [
    ("gltf-100k-instances", "GLB (6 MB), 99,999 instances of a box: 1.2 M triangles",
     lambda d: _instances(d / "inst.glb", 99_999)),
    *[(f"plain-1M-{ext}", f"{ext.upper()}, a saucer-like solid of 1 M triangles" + (", textured" if ext in
       ("glb", "obj", "3mf") else ""), (lambda e: lambda d: _plain(d / f"big.{e}"))(ext))
      for ext in ("glb", "obj", "3mf", "stl", "ply")],
]


# -- the worst files within every default limit (--large) ---------------------------------------------------


def _limits():  # type: ignore[no-untyped-def]
    sys.path.insert(0, str(ROOT))
    from saucerfab.check.limits import Limits

    return Limits()


@functools.lru_cache(maxsize=None)
def _solid_at_limit() -> tuple:  # type: ignore[type-arg]
    """The saucer solid with the most triangles within ``max_triangles``: (V, F, uv)."""
    cap = _limits().max_triangles
    n = 2
    while 4 * n * n + 8 * n <= cap:  # 4 (n-1)^2 + 8 (n-1) triangles for n points a side
        n += 1
    return fx.saucer_solid(n=n)


@functools.lru_cache(maxsize=None)
def _soup_at_limit() -> tuple:  # type: ignore[type-arg]
    """The same solid as a triangle soup: three vertices (and UVs) of its own per triangle, (V, F, uv)."""
    V, F, uv = _solid_at_limit()
    assert 3 * len(F) <= _limits().max_vertices
    return V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3), uv[F].reshape(-1, 2)


@functools.lru_cache(maxsize=None)
def _big_texture(noisy: bool = False) -> bytes:
    """A PNG of ``max_texture_pixels`` (8192 x 8192): smooth (0.3 MB), or noisy (4 random bits a channel, ~100 MB,
    under ``max_texture_bytes``): the decode costs 256 MiB either way, the noisy one holds its bytes too."""
    import io

    from PIL import Image

    lim = _limits()
    px = int(lim.max_texture_pixels ** 0.5)
    if not noisy:
        return fx.png_bytes(px, px)
    arr = (np.random.default_rng(0).integers(0, 16, (px, px, 3), dtype=np.uint8) * 17)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG", compress_level=1)
    data = buf.getvalue()
    assert len(data) <= lim.max_texture_bytes, len(data)
    return data


def _at_limit(path: Path, soup: bool, texture: bytes | None) -> Path:
    V, F, uv = _soup_at_limit() if soup else _solid_at_limit()
    ext = path.suffix
    if ext == ".stl":
        return fx.write_stl(path, V, F)
    if ext == ".ply":
        return fx.write_ply(path, V, F)
    if ext == ".wrl":
        if texture is not None:
            (path.parent / "texture.png").write_bytes(texture)
        return fx.write_vrml(path, V, F, uv=uv if texture else None, texture="texture.png" if texture else None)
    write = {".glb": fx.write_glb, ".obj": fx.write_obj, ".3mf": fx.write_3mf}[ext]
    return write(path, V, F, uv=uv if texture else None, texture=texture)


def _padded(path: Path, kind: str) -> Path:
    """The soup at the limits in an ASCII format, padded with blanks or comments to ``max_file_bytes``."""
    V, F, _ = _soup_at_limit()
    cap = _limits().max_file_bytes
    if kind == "stl":
        fx.write_stl(path, V, F, ascii=True)
    elif kind == "ply":
        fx.write_ply(path, V, F, binary=False)
    else:
        fx.write_obj(path, V, F)
    raw = path.read_bytes()
    extra = cap - len(raw)
    assert extra > 0, (kind, len(raw), cap)
    if kind == "stl":  # blanks inside the first facet (the reader's regex and counts must wade through them)
        i = raw.index(b"endloop")
        raw = raw[:i] + b" " * extra + raw[i:]
    elif kind == "ply":  # blank lines after the last record
        raw = raw + b"\n" * extra
    else:  # comment lines
        line = b"#" + b" " * 1022 + b"\n"
        raw = raw + line * (extra // len(line)) + b"#" * (extra % len(line))
    path.write_bytes(raw)
    return path


def _obj_relative(path: Path) -> Path:
    V, F, uv = _soup_at_limit()
    (path.parent / "m.mtl").write_text("newmtl mat0\nKd 1 1 1\nmap_Kd texture.png\n")
    (path.parent / "texture.png").write_bytes(fx.png_bytes(512, 512))
    lines = ["mtllib m.mtl", "usemtl mat0"]
    for t in range(len(F)):
        for c in range(3):
            x, y, z = V[3 * t + c]
            u, v = uv[3 * t + c]
            lines += [f"v {x:.6f} {y:.6f} {z:.6f}", f"vt {u:.6f} {v:.6f}", "vn 0 0 1"]
        lines.append("f -3/-3/-3 -2/-2/-2 -1/-1/-1")
    path.write_text("\n".join(lines) + "\n")
    return path


def _obj_mixed(path: Path) -> Path:
    V, F, _ = _soup_at_limit()
    fx.write_obj(path, V, F[1:])
    text = path.read_text()
    i = text.index("\nf ")
    path.write_text(text[:i] + "\nf 1 2 3 1" + text[i:])  # a quad (its second triangle degenerate)
    return path


def _3mf_tree(path: Path) -> Path:
    import re

    V, F, _ = _solid_at_limit()
    xml = fx.model_xml(V, F)
    xml = re.sub(r'<vertex x="([^"]*)" y="([^"]*)" z="([^"]*)"/>', r'<vertex z="\3" y="\2" x="\1"/>', xml)
    xml = re.sub(r'<triangle v1="(\d+)" v2="(\d+)" v3="(\d+)"/>', r'<triangle v3="\3" v2="\2" v1="\1"/>', xml)
    return fx.write_3mf(path, None, None, model=xml)  # type: ignore[arg-type]


def _pile(path: Path) -> Path:
    """``max_triangles`` triangles of ~1 mm thrown into a 2 mm cube: every one crosses hundreds of others."""
    n = _limits().max_triangles
    rng = np.random.default_rng(0)
    V = (rng.uniform(0, 2, (n, 1, 3)) + rng.normal(0, 1, (n, 3, 3))).reshape(-1, 3)
    return fx.write_stl(path, V, np.arange(3 * n).reshape(-1, 3))


LARGE: list[tuple[str, str, Callable[[Path], Path]]] = [
    *[(f"max-{ext}", f"{ext.upper()}, a closed saucer-like solid at max_triangles"
       + (", 512 px texture" if ext in ("glb", "obj", "3mf", "wrl") else ""),
       (lambda e: lambda d: _at_limit(d / f"m.{e}", False, fx.png_bytes(512, 512) if e in ("glb", "obj", "3mf", "wrl")
                                      else None))(ext))
      for ext in ("3mf", "obj", "glb", "wrl", "stl", "ply")],
    *[(f"soup-{ext}", f"{ext.upper()}, the same as a soup (3 vertices and UVs per triangle: max_vertices)"
       + (", one 8192 x 8192 texture" if ext in ("glb", "obj", "3mf", "wrl") else ""),
       (lambda e: lambda d: _at_limit(d / f"s.{e}", True, _big_texture() if e in ("glb", "obj", "3mf", "wrl")
                                      else None))(ext))
      for ext in ("3mf", "obj", "glb", "wrl", "ply")],
    ("soup-glb-noisy-texture", "GLB soup embedding a noisy 8192 x 8192 PNG (~100 MB, under max_texture_bytes)",
     lambda d: _at_limit(d / "n.glb", True, _big_texture(noisy=True))),
    ("soup-stl-ascii-padded", "ASCII STL soup at max_triangles, blanks up to max_file_bytes",
     lambda d: _padded(d / "a.stl", "stl")),
    ("soup-ply-ascii-padded", "ASCII PLY soup at max_triangles, blank lines up to max_file_bytes",
     lambda d: _padded(d / "a.ply", "ply")),
    ("soup-obj-padded", "OBJ soup at max_triangles, comment lines up to max_file_bytes",
     lambda d: _padded(d / "a.obj", "obj")),
    ("soup-obj-relative", "OBJ soup at max_triangles, v/vt/vn before each face 'f -3/-3/-3 -2/-2/-2 -1/-1/-1' "
     "(relative indices, as streaming writers write)", lambda d: _obj_relative(d / "r.obj")),
    ("soup-obj-mixed", "OBJ soup at max_triangles whose first face is a quad (faces of mixed sizes: not the "
     "numba parser's uniform form)", lambda d: _obj_mixed(d / "q.obj")),
    ("max-3mf-xml-tree", "3MF at max_triangles whose attributes are in another order (not the bulk grammar: "
     "parsed element by element)", lambda d: _3mf_tree(d / "t.3mf")),
    ("pile-stl", "binary STL, max_triangles overlapping triangles in a 2 mm cube (self-intersection budget)",
     lambda d: _pile(d / "pile.stl")),
    *[(f"parts-{ext}", f"{ext.upper()}, max_parts {what} of max_triangles / max_parts triangles each",
       (lambda e: lambda d: _parts(d / f"p.{e}"))(ext))
      for ext, what in (("3mf", "objects (build items)"), ("glb", "instances of one mesh"), ("wrl", "shapes"))],
]


def _parts(path: Path) -> Path:
    """``max_parts`` closed parts (double cones) sharing ``max_triangles``: what each part costs of its own."""
    lim = _limits()
    n, t = lim.max_parts, lim.max_triangles // lim.max_parts
    k = max(3, t // 2)  # a ring of k points and two apexes: 2 k triangles
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
    ring = np.stack([0.5 + 0.5 * np.cos(ang), 0.5 + 0.5 * np.sin(ang), np.full(k, 0.5)], axis=1)
    V = np.concatenate([ring, [[0.5, 0.5, 1.0], [0.5, 0.5, 0.0]]])
    i = np.arange(k)
    j = (i + 1) % k
    F = np.concatenate([np.stack([i, j, np.full(k, k)], 1), np.stack([j, i, np.full(k, k + 1)], 1)])
    offs = [((o % 300) * 1.5, (o // 300) * 1.5) for o in range(n)]
    if path.suffix == ".glb":
        def edit(doc: dict) -> None:  # type: ignore[type-arg]
            doc["nodes"] = [{"children": list(range(1, n + 1))}] + [
                {"mesh": 0, "translation": [0.001 * x, 0.001 * y, 0.0]} for x, y in offs]
            doc["scenes"] = [{"nodes": [0]}]
        return hb.glb_with(path, edit, src=fx.write_glb(path.with_suffix(".src.glb"), V, F))
    if path.suffix == ".wrl":
        idx = ", ".join(f"{a}, {b}, {c}, -1" for a, b, c in F)
        shapes = [
            "Shape { geometry IndexedFaceSet { coord Coordinate { point [ "
            + ", ".join(f"{x + ox:.4f} {y + oy:.4f} {z:.4f}" for x, y, z in V)
            + f" ] }} coordIndex [ {idx} ] }} }}" for ox, oy in offs]
        path.write_text("#VRML V2.0 utf8\n" + "\n".join(shapes) + "\n")
        return path
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in F)
    objs = "".join(
        f'<object id="{o + 1}" type="model"><mesh><vertices>'
        + "".join(f'<vertex x="{x + ox:.4f}" y="{y + oy:.4f}" z="{z:.4f}"/>' for x, y, z in V)
        + f"</vertices><triangles>{tris}</triangles></mesh></object>" for o, (ox, oy) in enumerate(offs))
    items = "".join(f'<item objectid="{o + 1}"/>' for o in range(n))
    xml = (f'<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" xml:lang="en-US" xmlns="{fx.NS_CORE}">'
           f"<resources>{objs}</resources><build>{items}</build></model>")
    return fx.write_3mf(path, None, None, model=xml)  # type: ignore[arg-type]


def warm_up(pythonpath: str | None) -> None:
    """Compile the checker's numba kernels once (cached beside the sources), so that no case pays for it."""
    env = dict(os.environ)
    env["PYTHONPATH"] = pythonpath or str(ROOT)
    subprocess.run([sys.executable, "-c", "from saucerfab.warmup import warm_up_check; warm_up_check()"],
                   env=env, cwd=pythonpath or str(ROOT), capture_output=True, timeout=600, check=False)


def run_child(path: Path, timeout: float, pythonpath: str | None) -> dict[str, object]:
    """Check ``path`` in a fresh interpreter under ``/usr/bin/time``: its result, wall times and own peak RSS.

    (``ru_maxrss`` of a process forked from this one would start at this
    process's size - the 8192 x 8192 PNG built for the texture case makes
    it gigabytes - so the peak is read from ``time``, whose own child is
    forked from a small process.)
    """
    env = dict(os.environ)
    env["PYTHONPATH"] = pythonpath or str(ROOT)
    code = CHILD.format(limit=CHILD_AS_LIMIT)
    timer = ["/usr/bin/time", "-f", "RSS_KB %M"] if Path("/usr/bin/time").exists() else []
    t = time.perf_counter()
    # cwd is where ``python -c`` looks first: the tree under test, not necessarily this one; a session of its
    # own, so that a timeout ends the checker too and not only ``time`` above it
    proc = subprocess.Popen([*timer, sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, cwd=pythonpath or str(ROOT), start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return {"s": None, "wall": time.perf_counter() - t, "rss_mb": None, "code": f"timeout {timeout:.0f} s",
                "message": "killed"}
    wall = time.perf_counter() - t
    err = stderr.decode(errors="replace").strip().splitlines()
    rss = next((int(ln.split()[1]) / 1024 for ln in reversed(err) if ln.startswith("RSS_KB ")), None)
    res: dict[str, object] = {"wall": wall, "rss_mb": rss}
    try:
        res.update(json.loads(stdout.decode().strip().splitlines()[-1]))
    except (ValueError, IndexError):
        last = [ln for ln in err if not ln.startswith(("RSS_KB ", "Command exited"))][-1:]
        res.update({"s": None, "code": f"crashed (rc {proc.returncode})", "message": last[0] if last else ""})
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated case names")
    ap.add_argument("--large", action="store_true", help="also the worst files within the default limits (slow)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per file")
    ap.add_argument("--pythonpath", help="run the children against this source tree instead")
    ap.add_argument("--out", help="also write the table (markdown) to this file")
    args = ap.parse_args()

    cases = CASES + (LARGE if args.large else [])
    if args.only:
        want = set(args.only.split(","))
        cases = [c for c in cases if c[0] in want]
    info = machine()
    warm_up(args.pythonpath)
    load_before = uptime()
    print(info)
    print(load_before)
    rows = []
    large = {c[0] for c in LARGE}
    worst_s = worst_mb = 0.0
    worst_large_s = worst_large_mb = 0.0
    with tempfile.TemporaryDirectory(prefix="saucerfab-hostile-") as td:
        for name, what, build in cases:
            d = Path(td) / name
            d.mkdir()
            path = build(d)
            size = sum(p.stat().st_blocks * 512 for p in d.iterdir())
            res = run_child(path, args.timeout, args.pythonpath)
            s = res.get("s")
            msg = str(res.get("message", ""))
            row = (name, what, f"{path.stat().st_size / 1e6:.2f} / {size / 1e6:.2f}",
                   "-" if s is None else f"{float(s):.2f}", f"{float(res['wall']):.2f}",
                   "-" if res.get("rss_mb") is None else f"{float(res['rss_mb']):.0f}",
                   f"{res.get('code')}" + (f": {msg[:100]}" if msg else ""))
            print(" | ".join(row), flush=True)
            rows.append(row)
            if name not in large:
                worst_s = max(worst_s, float(res["wall"]))
                worst_mb = max(worst_mb, float(res.get("rss_mb") or 0.0))
            else:
                worst_large_s = max(worst_large_s, float(res["wall"]))
                worst_large_mb = max(worst_large_mb, float(res.get("rss_mb") or 0.0))
            for p in d.iterdir():
                p.unlink()
    load_after = uptime()
    lines = [
        "| case | file | MB (size / on disk) | check_mesh s | process s | peak RSS MiB | result |",
        "|---|---|---:|---:|---:|---:|---|",
        *["| " + " | ".join(r).replace("\n", " ") + " |" for r in rows],
    ]
    table = "\n".join(lines)
    summary = (f"worst over the hostile cases: {worst_s:.2f} s (whole process) and {worst_mb:.0f} MiB peak RSS "
               f"(target 10 s, 1024 MiB)")
    if worst_large_s:
        summary += (f"; over the worst files within the limits (--large): {worst_large_s:.2f} s and "
                    f"{worst_large_mb:.0f} MiB")
    print(table)
    print(summary)
    print(load_after)
    if args.out:
        Path(args.out).write_text(f"Machine: {info}\n\nBefore: `{load_before}`\n\nAfter: `{load_after}`\n\n"
                                  f"{table}\n\n{summary}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
