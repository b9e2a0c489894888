"""glTF 2.0 reader: binary GLB and JSON ``.gltf`` (with data: URIs or files beside it).

Every number in the JSON is the attacker's, so the reader type-checks each
field it uses and bounds every accessor against its buffer view and every
view against its buffer (offset + stride x (count - 1) + element size)
before making an array. Node hierarchies are priced before they are walked
(memoised per node, so a node listed by several parents costs one step):
instanced triangles, vertices, primitive instances and node visits count
against the caps, with a depth limit and cycle detection, before any array
is made; each mesh is decoded once however often it is instanced. Buffers
naming the same URI share one read, and all of a file's buffer bytes
together are bounded (``Limits.max_buffer_bytes``). Units are metres by the
glTF specification.

Colour: ``baseColorTexture`` via ``TEXCOORD_n``, ``COLOR_0`` vertex colours
and ``baseColorFactor`` material colours.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.safe import DiskResources, Resources, probe_texture

_COMPONENT = {5120: "i1", 5121: "u1", 5122: "i2", 5123: "u2", 5125: "u4", 5126: "f4"}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORM = {"i1": 127.0, "u1": 255.0, "i2": 32767.0, "u2": 65535.0}


def _bad(msg: str) -> ReadError:
    return ReadError("malformed", f"glTF: {msg}")


def _list(d: Any, key: str) -> list[Any]:
    v = d.get(key, []) if isinstance(d, dict) else None
    if not isinstance(v, list):
        raise _bad(f"'{key}' is not a list")
    return v


def _dict(v: Any, what: str) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise _bad(f"{what} is not an object")
    return v


def _whole(v: Any) -> int | None:
    """``v`` as an int when it is a JSON integer, written as ``3`` or ``3.0`` (JSON has one number type,
    and the glTF-Validator takes both); else None (booleans, fractions, strings, inf/nan)."""
    if isinstance(v, bool):
        return None
    if isinstance(v, int):
        return v
    if isinstance(v, float) and v.is_integer():
        return int(v)
    return None


def _int(d: dict[str, Any], key: str, default: int | None = None, what: str = "") -> int:
    v = _whole(d.get(key, default))
    if v is None:
        raise _bad(f"{what or key}: '{key}' is missing or not an integer")
    if v < 0:
        raise _bad(f"{what or key}: '{key}' is negative")
    return v


def _item(seq: list[Any], i: Any, what: str) -> dict[str, Any]:
    j = _whole(i)
    if j is None:
        raise _bad(f"a {what} index {i!r} is not an integer")
    i = j
    if not 0 <= i < len(seq):
        raise ReadError("index_out_of_range", f"glTF: {what} {i} does not exist (there are {len(seq)})")
    return _dict(seq[i], f"{what} {i}")


@dataclass
class _Prim:
    """One triangle primitive of a mesh, decoded once however many nodes instance it."""

    what: str
    V: np.ndarray
    F: np.ndarray
    uv: np.ndarray | None
    tex: np.ndarray | None
    col: np.ndarray | None


class _Gltf:
    def __init__(self, doc: Any, buffers: list[bytes | None], res: Resources, limits: Limits) -> None:
        self.doc = _dict(doc, "the glTF document")
        self.buffers = buffers
        self.res = res
        self.limits = limits
        self.b = MeshBuilder("glb", limits)
        self._buf_cache: dict[int, bytes] = {}
        # buffers naming the same URI share one read; all URIs together are bounded by Limits.max_buffer_bytes
        self._uri_cache: dict[str, bytes] = {}
        self.buffer_bytes = 0
        self._prims: dict[int, list[_Prim]] = {}
        self.visits = 0

    # ---- data
    def buffer(self, i: int) -> bytes:
        if i in self._buf_cache:
            return self._buf_cache[i]
        bufs = _list(self.doc, "buffers")
        d = _item(bufs, i, "buffer")
        length = _int(d, "byteLength", what=f"buffer {i}")
        uri = d.get("uri")
        if uri is None:
            data = self.buffers[i] if i < len(self.buffers) else None
            if data is None:
                raise _bad(f"buffer {i} has no uri and there is no GLB binary chunk for it")
        elif isinstance(uri, str):
            data = self._buffer_uri(uri, f"buffer {i}")
        else:
            raise _bad(f"buffer {i} uri is not a string")
        if len(data) < length:
            raise ReadError("truncated", f"glTF buffer {i} declares {length:,} bytes but has {len(data):,}")
        self._buf_cache[i] = data
        return data

    def _buffer_uri(self, uri: str, what: str) -> bytes:
        """The bytes ``uri`` names: read once however many buffers name it, all URIs within one budget."""
        if uri in self._uri_cache:
            return self._uri_cache[uri]
        left = self.limits.max_buffer_bytes - self.buffer_bytes
        cap = min(self.limits.max_file_bytes, left)
        if cap < self.limits.max_file_bytes:  # the file's budget binds: say so in any refusal
            what = f"{what} (with {left:,} bytes left of Limits.max_buffer_bytes for all buffers)"
        data = self._uri_bytes(uri, cap, what)
        self.buffer_bytes += len(data)
        self._uri_cache[uri] = data
        return data

    def _uri_bytes(self, uri: str, cap: int, what: str) -> bytes:
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if ";base64" not in head:
                raise ReadError("unsupported_format", f"glTF {what}: only base64 data URIs are read")
            if len(payload) * 3 // 4 > cap:
                raise ReadError("over_check_limit", f"glTF {what}: data URI over {cap:,} bytes")
            try:
                return base64.b64decode(payload, validate=True)
            except (binascii.Error, ValueError):
                raise _bad(f"{what}: data URI is not valid base64") from None
        return self.res.read(uri, cap, f"glTF {what}")

    def view_bytes(self, i: int) -> memoryview:
        bv = _item(_list(self.doc, "bufferViews"), i, "bufferView")
        buf = self.buffer(_int(bv, "buffer", what=f"bufferView {i}"))
        off = _int(bv, "byteOffset", 0, f"bufferView {i}")
        length = _int(bv, "byteLength", what=f"bufferView {i}")
        if off + length > len(buf):
            raise ReadError("truncated", f"glTF bufferView {i} runs past the end of its buffer")
        return memoryview(buf)[off : off + length]

    def accessor(self, i: int, what: str, want: tuple[int, ...] = (1, 2, 3, 4)) -> np.ndarray:
        """Accessor ``i`` as float64 (count, ncomp), normalized integers scaled to [0, 1] / [-1, 1]."""
        acc = _item(_list(self.doc, "accessors"), i, "accessor")
        count = _int(acc, "count", what=f"accessor {i}")
        typ = acc.get("type")
        ctype = acc.get("componentType")
        if typ not in _NCOMP or ctype not in _COMPONENT:
            raise _bad(f"accessor {i} has type {typ!r} / componentType {ctype!r}")
        ncomp = _NCOMP[typ]
        if ncomp not in want:
            raise _bad(f"accessor {i} ({what}) is {typ}, not what {what} needs")
        if "sparse" in acc:
            raise ReadError("unsupported_format", f"glTF accessor {i} is sparse; the checker does not read sparse accessors")
        if count > self.limits.max_vertices + 3 * self.limits.max_triangles:
            raise ReadError("over_check_limit", f"glTF accessor {i} has {count:,} elements, over the checker's limits")
        dt = np.dtype("<" + _COMPONENT[ctype])
        elem = ncomp * dt.itemsize
        if "bufferView" not in acc:
            return np.zeros((count, ncomp))
        bvi = _int(acc, "bufferView", what=f"accessor {i}")
        view = self.view_bytes(bvi)
        bv = _item(_list(self.doc, "bufferViews"), bvi, "bufferView")
        stride = _int(bv, "byteStride", elem, f"bufferView {bvi}") or elem
        if stride < elem:
            raise _bad(f"bufferView {bvi} byteStride {stride} is smaller than its elements ({elem} bytes)")
        off = _int(acc, "byteOffset", 0, f"accessor {i}")
        if count and off + stride * (count - 1) + elem > len(view):
            raise ReadError(
                "truncated",
                f"glTF accessor {i} ({count:,} x {typ}) runs past the end of bufferView {bvi} ({len(view):,} bytes)",
            )
        if count == 0:
            return np.zeros((0, ncomp))
        arr = np.ndarray((count, ncomp), dtype=dt, buffer=view, offset=off, strides=(stride, dt.itemsize))
        out = arr.astype(np.float64) if dt.kind == "f" else arr.astype(np.int64)
        if acc.get("normalized") and dt.kind != "f":
            out = np.maximum(out / _NORM[_COMPONENT[ctype]], -1.0)
        return out

    # ---- scene
    def read(self) -> MeshData:
        meshes = _list(self.doc, "meshes")
        nodes = _list(self.doc, "nodes")
        scenes = _list(self.doc, "scenes")
        if scenes:
            si = _int(self.doc, "scene", 0, "document")
            listed = _list(_item(scenes, si, "scene"), "nodes")
            roots = [_whole(r) for r in listed]
            if any(r is None for r in roots):
                raise _bad("a scene lists a node that is not an index")
            self._check_cost(nodes, roots)
            for r in roots:
                self._node(nodes, r, np.eye(4), 0, set())
        else:
            self.b.note("ignored_content", "glTF without scenes: every mesh was read once, untransformed")
            for mi in range(len(meshes)):
                self._mesh(meshes, mi, np.eye(4))
        return self.b.build(unit_mm=1000.0, units="meter", units_stated=True)

    def _check_cost(self, nodes: list[Any], roots: list[int]) -> None:
        """Refuse a scene whose instancing is over the caps, from node and accessor counts alone.

        A node may be listed by several parents (against the glTF rules, but
        exporters do it): each listing instances its whole subtree again, so
        a tree whose every node lists the next twice doubles per level. The
        cost of each node is memoised, so pricing takes one step per node
        and child link however large the total, like the 3MF and VRML
        readers' component and DEF/USE pricing.
        """
        memo: dict[int, tuple[int, int, int, int]] = {}
        mesh_memo: dict[int, tuple[int, int, int]] = {}
        tri = verts = parts = visits = 0
        for r in roots:
            t, v, p, n = self._node_cost(nodes, r, 0, set(), memo, mesh_memo)
            tri, verts, parts, visits = tri + t, verts + v, parts + p, visits + n
        lim = self.limits
        if tri > lim.max_triangles or verts > lim.max_vertices or parts > lim.max_parts:
            raise ReadError(
                "over_check_limit",
                f"the glTF scene instances {tri:,} triangles ({verts:,} vertices) in {parts:,} primitive instances "
                f"(a node listed by several parents counts once per listing), over the checker's limits "
                f"({lim.max_triangles:,} triangles, Limits.max_triangles / --max-triangles; {lim.max_vertices:,} "
                f"vertices, Limits.max_vertices; {lim.max_parts:,} parts, Limits.max_parts)",
            )
        if visits > lim.max_node_visits:
            raise ReadError(
                "over_check_limit",
                f"the glTF scene takes {visits:,} node visits to instance (a node listed by several parents is "
                f"visited once per listing), over the checker's limit of {lim.max_node_visits:,} "
                "(Limits.max_node_visits)",
            )

    def _node_cost(self, nodes: list[Any], i: int, depth: int, path: set[int],
                   memo: dict[int, tuple[int, int, int, int]], mesh_memo: dict[int, tuple[int, int, int]],
                   ) -> tuple[int, int, int, int]:
        """(triangles, vertices, primitive instances, node visits) of node ``i``'s subtree, memoised."""
        if i in memo:
            return memo[i]
        if depth > self.limits.max_nesting:
            raise ReadError("over_check_limit", f"glTF nodes nest deeper than {self.limits.max_nesting} "
                                                "(Limits.max_nesting)")
        if i in path:
            raise _bad(f"node {i} is its own ancestor (a cycle)")
        n = _item(nodes, i, "node")
        t = v = p = 0
        if "mesh" in n:
            mi = _int(n, "mesh", what=f"node {i}")
            if mi not in mesh_memo:
                mesh_memo[mi] = self._mesh_cost(mi)
            t, v, p = mesh_memo[mi]
        visits = 1
        path.add(i)
        for child in _list(n, "children"):
            c = _whole(child)
            if c is None:
                raise _bad(f"node {i} has a child that is not an index")
            ct, cv, cp, cn = self._node_cost(nodes, c, depth + 1, path, memo, mesh_memo)
            t, v, p, visits = t + ct, v + cv, p + cp, visits + cn
        path.discard(i)
        memo[i] = (t, v, p, visits)
        return memo[i]

    def _mesh_cost(self, mi: int) -> tuple[int, int, int]:
        """(triangles, vertices, triangle primitives) one instance of mesh ``mi`` adds, from accessor counts."""
        mesh = _item(_list(self.doc, "meshes"), mi, "mesh")
        accessors = _list(self.doc, "accessors")
        t = v = p = 0
        for pi, prim in enumerate(_list(mesh, "primitives")):
            what = f"glTF mesh {mi} primitive {pi}"
            prim = _dict(prim, f"mesh {mi} primitive {pi}")
            mode = _int(prim, "mode", 4, f"mesh {mi} primitive {pi}")
            if mode not in (4, 5, 6):
                continue
            attrs = _dict(prim.get("attributes", {}), f"mesh {mi} primitive {pi} attributes")
            if "POSITION" not in attrs:
                raise _bad(f"mesh {mi} primitive {pi} has no POSITION")
            nv = _int(_item(accessors, _int(attrs, "POSITION", what=what), "accessor"), "count", what=what)
            n_idx = nv
            if "indices" in prim:
                n_idx = _int(_item(accessors, _int(prim, "indices", what=what), "accessor"), "count", what=what)
            t += n_idx // 3 if mode == 4 else max(0, n_idx - 2)
            v += nv
            p += 1
        return t, v, p

    def _node(self, nodes: list[Any], i: int, parent: np.ndarray, depth: int, path: set[int]) -> None:
        self.visits += 1
        if self.visits > self.limits.max_node_visits:  # priced in _check_cost; a second guard on the walk itself
            raise ReadError("over_check_limit", f"the glTF scene takes over {self.limits.max_node_visits:,} node "
                                                "visits (Limits.max_node_visits)")
        if depth > self.limits.max_nesting:
            raise ReadError("over_check_limit", f"glTF nodes nest deeper than {self.limits.max_nesting}")
        if i in path:
            raise _bad(f"node {i} is its own ancestor (a cycle)")
        n = _item(nodes, i, "node")
        M = parent @ _node_matrix(n, i)
        if "mesh" in n:
            self._mesh(_list(self.doc, "meshes"), _int(n, "mesh", what=f"node {i}"), M)
        for child in _list(n, "children"):
            c = _whole(child)
            if c is None:
                raise _bad(f"node {i} has a child that is not an index")
            self._node(nodes, c, M, depth + 1, path | {i})

    def _mesh(self, meshes: list[Any], mi: int, M: np.ndarray) -> None:
        """One instance of mesh ``mi`` under transform ``M`` (its primitives decoded on first use)."""
        prims = self._prims.get(mi)
        if prims is None:
            prims = self._decode_mesh(meshes, mi)
            self._prims[mi] = prims
        mirrored = np.linalg.det(M[:3, :3]) < 0
        for pr in prims:
            self.b.reserve(len(pr.V), len(pr.F), pr.what)
            Vw = pr.V @ M[:3, :3].T + M[:3, 3]
            F = pr.F[:, ::-1] if mirrored else pr.F  # mirrored instance: keep outward winding
            uv = pr.uv[:, ::-1] if (mirrored and pr.uv is not None) else pr.uv
            self.b.add(Vw, F, corner_uv=uv, face_texture=pr.tex, face_colour=pr.col, what=pr.what)

    def _decode_mesh(self, meshes: list[Any], mi: int) -> list[_Prim]:
        """The triangle primitives of mesh ``mi``, read and range-checked, in the mesh's own coordinates."""
        mesh = _item(meshes, mi, "mesh")
        out: list[_Prim] = []
        for pi, prim in enumerate(_list(mesh, "primitives")):
            prim = _dict(prim, f"mesh {mi} primitive {pi}")
            mode = _int(prim, "mode", 4, f"mesh {mi} primitive {pi}")
            if mode not in (4, 5, 6):
                self.b.note("ignored_content", "glTF points and lines primitives were ignored")
                continue
            attrs = _dict(prim.get("attributes", {}), f"mesh {mi} primitive {pi} attributes")
            if "POSITION" not in attrs:
                raise _bad(f"mesh {mi} primitive {pi} has no POSITION")
            what = f"glTF mesh {mi} primitive {pi}"
            pos_acc = _item(_list(self.doc, "accessors"), _int(attrs, "POSITION", what=what), "accessor")
            nv = _int(pos_acc, "count", what=what)
            n_idx = nv
            if "indices" in prim:
                n_idx = _int(_item(_list(self.doc, "accessors"), _int(prim, "indices", what=what), "accessor"), "count", what=what)
            self.b.reserve(nv, n_idx // 3 if mode == 4 else max(0, n_idx - 2), what)
            V = self.accessor(attrs["POSITION"], "POSITION", (3,))
            if "indices" in prim:
                idx = self.accessor(prim["indices"], "indices", (1,)).ravel()
                if idx.dtype.kind == "f":
                    raise _bad(f"{what}: indices are floats")
            else:
                idx = np.arange(len(V), dtype=np.int64)
            F = _triangles(idx, mode, what)
            if F.size and (F.min() < 0 or F.max() >= len(V)):
                bad = int(F.max()) if F.max() >= len(V) else int(F.min())
                raise ReadError("index_out_of_range",
                                f"{what}: index {bad} but the primitive has {len(V):,} positions")
            uv = tex = col = None
            mat = None
            if "material" in prim:
                mat = _item(_list(self.doc, "materials"), _int(prim, "material", what=what), "material")
            pbr = _dict(mat.get("pbrMetallicRoughness", {}), "pbrMetallicRoughness") if mat else {}
            bct = pbr.get("baseColorTexture")
            if bct is not None:
                bct = _dict(bct, "baseColorTexture")
                tc = f"TEXCOORD_{_int(bct, 'texCoord', 0, 'baseColorTexture')}"
                ti = self._texture(_int(bct, "index", what="baseColorTexture"))
                if tc in attrs:
                    UV = self.accessor(attrs[tc], tc, (2,))
                    if len(UV) != len(V):
                        raise _bad(f"{what}: {tc} has {len(UV)} entries for {len(V)} positions")
                    uv = UV[F] if len(F) else np.zeros((0, 3, 2))
                    tex = np.full(len(F), ti, dtype=np.int32)
                    self.b.colour_kinds.add("texture")
                else:
                    self.b.note("ignored_content", f"{what} has a base colour texture but no {tc}")
            if "COLOR_0" in attrs:
                C = self.accessor(attrs["COLOR_0"], "COLOR_0", (3, 4))
                if len(C) != len(V):
                    raise _bad(f"{what}: COLOR_0 has {len(C)} entries for {len(V)} positions")
                col = np.ones(len(F), dtype=bool)
                self.b.colour_kinds.add("vertex")
            elif mat is not None and "baseColorFactor" in pbr:
                col = np.ones(len(F), dtype=bool)
                self.b.colour_kinds.add("material")
            out.append(_Prim(what, V, F, uv, tex, col))
        return out

    def _texture(self, ti: int) -> int:
        tex = _item(_list(self.doc, "textures"), ti, "texture")
        if "source" not in tex:
            return self.b.texture(f"<texture {ti}>", lambda: TextureInfo(
                name=f"texture {ti}", status="missing", message=f"glTF texture {ti} has no image source"))
        si = _int(tex, "source", what=f"texture {ti}")
        img = _item(_list(self.doc, "images"), si, "image")

        def load() -> TextureInfo:
            name = f"image {si}"
            if "bufferView" in img:
                try:
                    view = self.view_bytes(_int(img, "bufferView", what=name))
                except ReadError as exc:
                    return TextureInfo(name=name, status="unreadable", message=exc.message)
                if len(view) > self.limits.max_texture_bytes:
                    return TextureInfo(name=name, status="too_large", message=f"glTF {name} is over {self.limits.max_texture_bytes:,} bytes")
                return probe_texture(name, bytes(view), self.limits, budget=self.res.budget)
            uri = img.get("uri")
            if not isinstance(uri, str):
                return TextureInfo(name=name, status="missing", message=f"glTF {name} has neither bufferView nor uri")
            if uri.startswith("data:"):
                try:
                    return probe_texture(name, self._uri_bytes(uri, self.limits.max_texture_bytes, name), self.limits,
                                         budget=self.res.budget)
                except ReadError as exc:
                    return TextureInfo(name=name, status="unreadable", message=exc.message)
            return self.res.texture(uri)

        return self.b.texture(f"image {si}", load)


def _node_matrix(n: dict[str, Any], i: int) -> np.ndarray:
    try:
        if "matrix" in n:
            m = np.array(n["matrix"], dtype=np.float64)
            if m.shape != (16,):
                raise _bad(f"node {i} matrix is not 16 numbers")
            M = m.reshape(4, 4).T  # column-major
        else:
            t = np.array(n.get("translation", [0, 0, 0]), dtype=np.float64)
            q = np.array(n.get("rotation", [0, 0, 0, 1]), dtype=np.float64)
            s = np.array(n.get("scale", [1, 1, 1]), dtype=np.float64)
            if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
                raise _bad(f"node {i} translation/rotation/scale have the wrong lengths")
            x, y, z, w = q / (np.linalg.norm(q) or 1.0)
            R = np.array([
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ])
            M = np.eye(4)
            M[:3, :3] = R * s
            M[:3, 3] = t
    except (TypeError, ValueError):
        raise _bad(f"node {i} transform is not numbers") from None
    if not np.isfinite(M).all():
        raise _bad(f"node {i} transform has NaN or infinite entries")
    return M


def _triangles(idx: np.ndarray, mode: int, what: str) -> np.ndarray:
    idx = idx.astype(np.int64)
    if mode == 4:
        if len(idx) % 3:
            raise _bad(f"{what}: {len(idx)} indices is not a multiple of 3")
        return idx.reshape(-1, 3)
    if len(idx) < 3:
        return np.zeros((0, 3), dtype=np.int64)
    k = np.arange(len(idx) - 2)
    if mode == 5:  # strip: every other triangle swaps its first two corners to keep the winding
        a = np.where(k % 2 == 0, idx[k], idx[k + 1])
        b = np.where(k % 2 == 0, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], axis=1)
    return np.stack([np.full_like(k, idx[0]), idx[k + 1], idx[k + 2]], axis=1)  # fan


def read_glb(path: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """Read a binary glTF (GLB) file's bytes (external files, if any, come from ``res``)."""
    if len(data) < 20:
        raise ReadError("truncated", f"the GLB is {len(data)} bytes; its header alone needs 20")
    magic, version, length = struct.unpack("<4sII", data[:12])
    if version != 2:
        raise ReadError("unsupported_format", f"GLB version {version}; the checker reads glTF 2.0")
    if length > len(data):
        raise ReadError("truncated", f"the GLB header states {length:,} bytes but the file has {len(data):,}")
    off = 12
    doc_bytes = None
    binchunk = None
    while off + 8 <= length:
        clen, ctype = struct.unpack("<I4s", data[off : off + 8])
        if off + 8 + clen > length:
            raise ReadError("truncated", f"GLB chunk {ctype!r} runs past the end of the file")
        chunk = data[off + 8 : off + 8 + clen]
        if ctype == b"JSON" and doc_bytes is None:
            doc_bytes = chunk
        elif ctype == b"BIN\x00" and binchunk is None:
            binchunk = chunk
        off += 8 + clen  # chunk lengths include their padding
    if doc_bytes is None:
        raise _bad("the GLB has no JSON chunk")
    doc = _load_json(doc_bytes, limits)
    g = _Gltf(doc, [binchunk], res or DiskResources(path.parent, limits), limits)
    return g.read()


def read_gltf(path: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """Read a JSON glTF file's bytes; its buffers and images are data URIs or files from ``res``."""
    doc = _load_json(data, limits)
    g = _Gltf(doc, [], res or DiskResources(path.parent, limits), limits)
    g.b.fmt = "gltf"
    md = g.read()
    return md


def _load_json(raw: bytes, limits: Limits) -> Any:
    if len(raw) > limits.max_json_bytes:
        raise ReadError("over_check_limit", f"the glTF JSON is {len(raw):,} bytes, over Limits.max_json_bytes")
    # every JSON value becomes a Python object (~50-100 bytes; 3-byte "{}," items make 25x their size):
    # bound them by an upper count (containers and separators) before parsing
    values = raw.count(b"{") + raw.count(b"[") + raw.count(b",")
    if values > limits.max_json_values:
        raise ReadError(
            "over_check_limit",
            f"the glTF JSON holds up to {values:,} values, over the checker's limit of {limits.max_json_values:,} "
            "(Limits.max_json_values)",
        )
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _bad(f"the JSON is not valid: {exc}") from None
    except RecursionError:
        raise _bad("the JSON nests too deeply") from None
    asset = doc.get("asset") if isinstance(doc, dict) else None
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2"):
        raise ReadError("unsupported_format", "not a glTF 2.0 document (asset.version is not 2.x)")
    required = doc.get("extensionsRequired", [])
    if required:
        # Draco / meshopt compression and the like change what accessors mean; reading them as plain
        # data would report nonsense, so say plainly that the file needs what the checker lacks
        names = ", ".join(str(x)[:60] for x in required[:5]) if isinstance(required, list) else "?"
        raise ReadError("unsupported_format", f"the glTF requires extensions the checker does not read ({names}); "
                                              "export it without them")
    return doc
