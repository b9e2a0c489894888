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
together are bounded (``Limits.max_buffer_bytes``): that half, the data
access, is :mod:`saucerfab.check.readers.gltf_data`; this module walks the
scene and decodes meshes. Units are metres by the glTF specification.

Colour: ``baseColorTexture`` via ``TEXCOORD_n``, ``COLOR_0`` vertex colours
and ``baseColorFactor`` material colours.

Extensions read (and so accepted in ``extensionsRequired``; any other required
extension refuses the file as ``unsupported_format``):

* ``KHR_draco_mesh_compression``: the stream's stated face and vertex counts
  are held against the primitive's accessor counts (already priced against
  the caps) before DracoPy decodes it, and the decoded mesh again after.
* ``EXT_meshopt_compression`` / ``KHR_meshopt_compression``: a compressed
  bufferView is decoded (:mod:`.meshopt`) when an accessor first reads it,
  its ``count * byteStride`` bytes charged to ``Limits.max_buffer_bytes``
  before decoding; fallback buffers are never read for such views, so a
  fallback placeholder without a uri is fine.
* ``KHR_mesh_quantization``: integer POSITION / TEXCOORD / COLOR, normalized
  (i8 /127 clamped at -1, u8 /255, i16 /32767, u16 /65535) or not (the
  integer's value); node transforms carry the dequantization scale.
* ``KHR_texture_transform`` on ``baseColorTexture`` (offset, rotation, scale,
  texCoord): applied to the UVs the colour checks see.

Sparse accessors (with or without a bufferView) are read with their counts
and indices bounded (count at most the accessor's, indices strictly
increasing and in range). An accessor without a bufferView reads as zeros.
Primitives without POSITION and points/lines primitives are skipped with an
``ignored_content`` note; trailing indices of a triangle list that do not
make a whole triangle are ignored with a note.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.gltf_data import (
    _COMPONENT,
    _INDEX_TYPES,
    _MESHOPT,
    _NCOMP,
    _NORM,
    GltfData,
    _bad,
    _dict,
    _int,
    _item,
    _list,
    _whole,
)
from saucerfab.check.readers.safe import DiskResources, Resources, probe_texture

_DRACO = "KHR_draco_mesh_compression"
#: extensions the reader reads: a file may require them
SUPPORTED_EXTENSIONS = frozenset({_DRACO, *_MESHOPT, "KHR_mesh_quantization", "KHR_texture_transform"})


@dataclass
class _Prim:
    """One triangle primitive of a mesh, decoded once however many nodes instance it."""

    what: str
    V: np.ndarray
    F: np.ndarray
    uv: np.ndarray | None
    tex: np.ndarray | None
    col: np.ndarray | None


class _Gltf(GltfData):
    """The scene walk and mesh decoding on top of :class:`GltfData`."""

    def __init__(self, doc: Any, buffers: list[bytes | None], res: Resources, limits: Limits) -> None:
        super().__init__(doc, buffers, res, limits)
        self.b = MeshBuilder("glb", limits)
        self._prims: dict[int, tuple[_Prim, int] | None] = {}  # mesh -> its primitives merged, and how many
        self._queue: list[np.ndarray] = []  # transforms of a run of instances of one mesh, not yet added
        self._queue_mesh = -1
        self.visits = 0
        self.skipped: list[str] = []  # primitives skipped, for the reason when nothing is left

    def _skip(self, message: str, note: str | None = None) -> None:
        self.skipped.append(message)
        self.b.note("ignored_content", note or message)

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
                self._node(nodes, r, _IDENTITY, 0, set())
        else:
            self.b.note("ignored_content", "glTF without scenes: every mesh was read once, untransformed")
            for mi in range(len(meshes)):
                self._instance(mi, _IDENTITY)
        self._flush()
        if self.b.nf == 0 and self.skipped:  # say what was skipped: that is why there is nothing to check
            more = f"; and {len(self.skipped) - 3} more" if len(self.skipped) > 3 else ""
            raise ReadError("no_triangles", f"the file holds no triangles ({'; '.join(self.skipped[:3])}{more})")
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
                f"({lim.max_triangles:,} triangles, Limits.max_triangles; {lim.max_vertices:,} "
                f"vertices, Limits.max_vertices; {lim.max_parts:,} parts, Limits.max_parts)"
                + f"; {raise_hint(max(tri, -(-verts // 3)) if parts <= lim.max_parts else None)}",
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
                continue  # skipped when decoded (valid glTF: nothing to draw)
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
        local = _node_matrix(n, i)
        M = parent if local is None else parent @ local
        if "mesh" in n:
            self._instance(_int(n, "mesh", what=f"node {i}"), M)
        children = _list(n, "children")
        if children:
            path.add(i)
            for child in children:
                c = _whole(child)
                if c is None:
                    raise _bad(f"node {i} has a child that is not an index")
                self._node(nodes, c, M, depth + 1, path)
            path.discard(i)

    def _instance(self, mi: int, M: np.ndarray) -> None:
        """Queue one instance of mesh ``mi`` under transform ``M``; a run of one mesh's instances is added at once.

        Scenes that instance a part thousands of times (a tray of cups, a
        lattice) would otherwise pay numpy's per-call cost per instance; the
        queue keeps the file's order, so face indices are as if added one by one.
        """
        if self._queue and self._queue_mesh != mi:
            self._flush()
        if mi not in self._prims:
            self._prims[mi] = self._merged(self._decode_mesh(_list(self.doc, "meshes"), mi))
        self._queue_mesh = mi
        self._queue.append(M)
        merged = self._prims[mi]
        if merged is not None:  # the caps, as each instance comes (the walk was priced already; this is the guard)
            self.b.reserve(len(merged[0].V) * len(self._queue), len(merged[0].F) * len(self._queue), merged[0].what,
                           parts=merged[1] * len(self._queue))

    def _flush(self) -> None:
        """Add the queued instances of one mesh: every instance's vertices transformed in one product."""
        if not self._queue:
            return
        merged = self._prims[self._queue_mesh]
        Ms = np.stack(self._queue)
        self._queue = []
        if merged is None:
            return
        pr, parts = merged
        k, nv = len(Ms), len(pr.V)
        Vw = (np.einsum("kij,nj->kni", Ms[:, :3, :3], pr.V) + Ms[:, None, :3, 3]).reshape(-1, 3)
        F = np.broadcast_to(pr.F, (k, *pr.F.shape)) + (np.arange(k, dtype=np.int64) * nv)[:, None, None]
        mirrored = np.linalg.det(Ms[:, :3, :3]) < 0
        uv = None if pr.uv is None else np.broadcast_to(pr.uv, (k, *pr.uv.shape)).copy()
        if mirrored.any():  # a mirrored instance keeps its outward winding: each face's corners reversed
            F = F.copy()
            F[mirrored] = F[mirrored][:, :, ::-1]
            if uv is not None:
                uv[mirrored] = uv[mirrored][:, :, ::-1]
        tile = (lambda a: None if a is None else np.tile(a, k))
        self.b.add(Vw, F.reshape(-1, 3), corner_uv=None if uv is None else uv.reshape(-1, 3, 2),
                   face_texture=tile(pr.tex), face_colour=tile(pr.col), what=pr.what, parts=parts * k)

    @staticmethod
    def _merged(prims: list[_Prim]) -> tuple[_Prim, int] | None:
        """A mesh's primitives as one (vertices and faces in order, absent UVs/colours filled), and their count."""
        if not prims:
            return None
        if len(prims) == 1:
            return prims[0], 1
        offs = np.cumsum([0] + [len(p.V) for p in prims[:-1]])
        has = lambda name: any(getattr(p, name) is not None for p in prims)
        uv = np.concatenate([p.uv if p.uv is not None else np.full((len(p.F), 3, 2), np.nan) for p in prims]) \
            if has("uv") else None
        tex = np.concatenate([p.tex if p.tex is not None else np.full(len(p.F), -1, np.int32) for p in prims]) \
            if has("tex") else None
        col = np.concatenate([p.col if p.col is not None else np.zeros(len(p.F), bool) for p in prims]) \
            if has("col") else None
        one = _Prim(what=prims[0].what, V=np.concatenate([p.V for p in prims]),
                    F=np.concatenate([p.F + o for p, o in zip(prims, offs)]), uv=uv, tex=tex, col=col)
        return one, len(prims)

    def _decode_mesh(self, meshes: list[Any], mi: int) -> list[_Prim]:
        """The triangle primitives of mesh ``mi``, read and range-checked, in the mesh's own coordinates."""
        mesh = _item(meshes, mi, "mesh")
        out: list[_Prim] = []
        for pi, prim in enumerate(_list(mesh, "primitives")):
            prim = _dict(prim, f"mesh {mi} primitive {pi}")
            mode = _int(prim, "mode", 4, f"mesh {mi} primitive {pi}")
            if mode not in (4, 5, 6):
                self._skip(f"glTF mesh {mi} primitive {pi} is points or lines (mode {mode}) and was ignored",
                           "glTF points and lines primitives were ignored")
                continue
            attrs = _dict(prim.get("attributes", {}), f"mesh {mi} primitive {pi} attributes")
            what = f"glTF mesh {mi} primitive {pi}"
            if "POSITION" not in attrs:
                self._skip(f"{what} has no POSITION attribute and was ignored")
                continue
            pos_acc = self._acc(_int(attrs, "POSITION", what=what), what)
            nv = _int(pos_acc, "count", what=what)
            n_idx = nv
            if "indices" in prim:
                n_idx = _int(self._acc(_int(prim, "indices", what=what), what), "count", what=what)
            self.b.reserve(nv, n_idx // 3 if mode == 4 else max(0, n_idx - 2), what)
            exts = prim.get("extensions")
            draco = exts.get(_DRACO) if isinstance(exts, dict) else None
            if draco is not None:
                F, dattrs = self._draco(_dict(draco, f"{what} {_DRACO}"), attrs, prim, mode, nv, n_idx, what)
            else:
                dattrs = {}
                F = None

            def attr(name: str, want: tuple[int, ...], count: int | None, dattrs: dict[str, np.ndarray] = dattrs,
                     attrs: dict[str, Any] = attrs) -> np.ndarray:
                """An attribute: decoded from the Draco stream when it carries it, else its accessor."""
                if name in dattrs:
                    return dattrs[name]
                return self.accessor(attrs[name], name, want, count_must=count)

            V = attr("POSITION", (3,), None)
            if F is None:
                if "indices" in prim:
                    ia = self._acc(prim["indices"], "indices")
                    if ia.get("componentType") not in _INDEX_TYPES:
                        raise _bad(f"{what}: the indices accessor's componentType {ia.get('componentType')!r} is not "
                                   "an unsigned integer type")
                    idx = self.accessor(prim["indices"], "indices", (1,)).ravel()
                else:
                    idx = np.arange(len(V), dtype=np.int64)
                if mode == 4 and len(idx) % 3:
                    self.b.note("ignored_content", f"{what}: {len(idx) % 3} trailing indices that make no whole "
                                                   "triangle were ignored")
                    idx = idx[: len(idx) - len(idx) % 3]
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
                tt = _texture_transform(bct)
                tcn = _int(bct, "texCoord", 0, "baseColorTexture")
                if tt is not None and tt[3] is not None:
                    tcn = tt[3]
                tc = f"TEXCOORD_{tcn}"
                ti = self._texture(_int(bct, "index", what="baseColorTexture"))
                if tc in attrs:
                    UV = attr(tc, (2,), len(V))
                    if len(UV) != len(V):
                        raise _bad(f"{what}: {tc} has {len(UV)} entries for {len(V)} positions")
                    if tt is not None:
                        UV = _apply_texture_transform(UV, tt)
                    uv = UV[F] if len(F) else np.zeros((0, 3, 2))
                    tex = np.full(len(F), ti, dtype=np.int32)
                    self.b.colour_kinds.add("texture")
                else:
                    self.b.note("ignored_content", f"{what} has a base colour texture but no {tc}")
            if "COLOR_0" in attrs:
                C = attr("COLOR_0", (3, 4), len(V))
                if len(C) != len(V):
                    raise _bad(f"{what}: COLOR_0 has {len(C)} entries for {len(V)} positions")
                col = np.ones(len(F), dtype=bool)
                self.b.colour_kinds.add("vertex")
            elif mat is not None and "baseColorFactor" in pbr:
                col = np.ones(len(F), dtype=bool)
                self.b.colour_kinds.add("material")
            out.append(_Prim(what, V, F, uv, tex, col))
        return out

    def _draco(self, ext: dict[str, Any], attrs: dict[str, Any], prim: dict[str, Any], mode: int, nv: int,
               n_idx: int, what: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(faces, {attribute: values}) of a Draco-compressed primitive, bounded before decoding."""
        from saucerfab.check.readers import draco

        what = f"{what} ({_DRACO})"
        if mode not in (4, 5):
            raise _bad(f"{what}: mode {mode}; Draco primitives are triangles or triangle strips")
        ids = _dict(ext.get("attributes", {}), f"{what} attributes")
        if "POSITION" not in ids:
            raise _bad(f"{what}: the extension's attributes name no POSITION")
        for name in ids:
            if name not in attrs:
                raise _bad(f"{what}: attribute {name} is in the extension but not in the primitive")
        data = bytes(self.view_bytes(_int(ext, "bufferView", what=what)))
        # the faces the accessors promise (their counts were priced against the caps)
        want_faces = n_idx // 3 if mode == 4 else max(0, n_idx - 2)
        try:
            counts = draco.stream_counts(data, self.limits.max_nesting)
        except draco.DracoError as exc:
            raise ReadError(exc.code, f"glTF: {what}: {exc}") from None
        if counts.faces > want_faces or counts.vertices > nv:
            raise _bad(f"{what}: the Draco stream states {counts.faces:,} faces and {counts.vertices:,} vertices, "
                       f"more than its accessors declare ({want_faces:,} faces, {nv:,} positions)")
        try:
            F, by_id = draco.decode(data)
        except draco.DracoError as exc:
            raise ReadError(exc.code, f"glTF: {what}: {exc}") from None
        pos_id = _whole(ids["POSITION"])
        if pos_id not in by_id:
            raise _bad(f"{what}: the Draco stream has no attribute with id {ids['POSITION']!r} (for POSITION)")
        npts = len(by_id[pos_id])
        if len(F) > want_faces or npts > nv:
            raise _bad(f"{what}: the Draco stream decodes to {len(F):,} faces and {npts:,} points, more than its "
                       f"accessors declare ({want_faces:,} faces, {nv:,} positions)")
        out: dict[str, np.ndarray] = {}
        for name, uid in ids.items():
            u = _whole(uid)
            if u is None:
                raise _bad(f"{what}: attribute {name}'s id {uid!r} is not an integer")
            if u not in by_id:
                raise _bad(f"{what}: the Draco stream has no attribute with id {u} (for {name})")
            arr = by_id[u]
            acc = self._acc(attrs[name], name)
            typ = acc.get("type")
            if typ not in _NCOMP or arr.shape[1] != _NCOMP[typ] or len(arr) != npts:
                raise _bad(f"{what}: Draco attribute {u} ({name}) is {len(arr):,} x {arr.shape[1]}, not "
                           f"{npts:,} x {typ}")
            if arr.dtype.kind == "f":
                out[name] = arr.astype(np.float64)
            else:
                vals = arr.astype(np.int64)
                ct = _COMPONENT.get(acc.get("componentType"), "")
                out[name] = np.maximum(vals / _NORM[ct], -1.0) if acc.get("normalized") and ct in _NORM else vals
        return F, out

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


_IDENTITY = np.eye(4)
_TRS_KEYS = ("matrix", "translation", "rotation", "scale")


def _node_matrix(n: dict[str, Any], i: int) -> np.ndarray | None:
    """Node ``i``'s local transform (4, 4), or None for none (the common case, kept cheap)."""
    if not any(k in n for k in _TRS_KEYS):
        return None
    try:
        if "translation" in n and not any(k in n for k in ("matrix", "rotation", "scale")):
            # translation only (instanced parts are placed so): plain floats, no numpy per number
            t = n["translation"]
            if not isinstance(t, list) or len(t) != 3:
                raise _bad(f"node {i} translation/rotation/scale have the wrong lengths")
            tx, ty, tz = (float(x) for x in t)
            if not (math.isfinite(tx) and math.isfinite(ty) and math.isfinite(tz)):
                raise _bad(f"node {i} transform has NaN or infinite entries")
            M = _IDENTITY.copy()
            M[0, 3], M[1, 3], M[2, 3] = tx, ty, tz
            return M
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


def _texture_transform(info: dict[str, Any]) -> tuple[np.ndarray, float, np.ndarray, int | None] | None:
    """(offset, rotation, scale, texCoord or None) of a textureInfo's ``KHR_texture_transform``, or None."""
    exts = info.get("extensions")
    if not isinstance(exts, dict) or "KHR_texture_transform" not in exts:
        return None
    t = _dict(exts["KHR_texture_transform"], "KHR_texture_transform")
    try:
        off = np.array(t.get("offset", [0.0, 0.0]), dtype=np.float64)
        rot = float(t.get("rotation", 0.0))
        scale = np.array(t.get("scale", [1.0, 1.0]), dtype=np.float64)
    except (TypeError, ValueError):
        raise _bad("KHR_texture_transform offset/rotation/scale are not numbers") from None
    if off.shape != (2,) or scale.shape != (2,) or not (np.isfinite(off).all() and np.isfinite(scale).all()
                                                        and np.isfinite(rot)):
        raise _bad("KHR_texture_transform offset and scale must be two finite numbers, rotation one")
    tc = _int(t, "texCoord", what="KHR_texture_transform") if "texCoord" in t else None
    return off, rot, scale, tc


def _apply_texture_transform(uv: np.ndarray, tt: tuple[np.ndarray, float, np.ndarray, int | None]) -> np.ndarray:
    """UVs through ``translation * rotation * scale``. The rotation turns the UVs counter-clockwise in glTF's
    v-down UV space, as the extension's example and its implementations (Babylon.js, Blender, three.js,
    KhronosGroup/glTF#1563) have it: u' = cos*u + sin*v, v' = -sin*u + cos*v."""
    off, rot, scale, _ = tt
    c, s = np.cos(rot), np.sin(rot)
    su, sv = uv[:, 0] * scale[0], uv[:, 1] * scale[1]
    return np.stack([c * su + s * sv + off[0], -s * su + c * sv + off[1]], axis=1)


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
    if not isinstance(required, list):
        raise _bad("'extensionsRequired' is not a list")
    missing = [x for x in required if not (isinstance(x, str) and x in SUPPORTED_EXTENSIONS)]
    if missing:
        # other extensions may change what accessors or nodes mean; reading them as plain data would
        # report nonsense, so say plainly that the file needs what the checker lacks
        names = ", ".join(str(x)[:60] for x in missing[:5])
        raise ReadError("unsupported_format", f"the glTF requires extensions the checker does not read ({names}); "
                                              "export it without them")
    return doc
