"""3MF reader: core spec plus the materials extension (textures, colour groups).

Our own reader rather than trimesh's, because a bureau's checker must bound
everything an archive can claim and must see the colour data:

* the zip goes through :class:`~saucerfab.check.readers.safe.SafeZip`
  (entry count, names, inflation budget);
* XML goes through defusedxml with DTDs forbidden;
* ``<vertices>``, ``<triangles>`` and ``<m:texture2dgroup>`` contents - the
  bulk of any real model - take a fast path (:mod:`.threemf_blocks`): a
  block that matches a strict grammar is read with numpy and replaced by a
  marker element before defusedxml parses the rest; it means exactly what
  an XML parser would read from it, so this changes speed, not meaning;
* components and build items are instanced with their transforms, with the
  nesting depth, part count and instanced triangle count bounded before
  arrays are made (a small mesh instanced a million times is refused);
* triangle properties (``pid``, ``p1``-``p3``, object ``pid``/``pindex``)
  resolve to texture coordinates, colours or base materials, every index
  range-checked;
* the package is judged against the 3MF core and Materials specifications
  as it is read (:mod:`saucerfab.check.readers.threemf_rules`): OPC
  relationships and content types decide the start part, each model part's
  nesting depth is scanned before it is parsed, and every broken MUST is a
  ``spec_violation`` finding (an error) rather than a refusal, so the mesh
  is still checked. A resource id defined twice keeps its first definition
  (faces naming a duplicated property group read uncoloured). Refused as
  ``unsupported_format``: a model that requires an extension the checker
  does not read, and a part encrypted with the Secure Content extension
  (``%3McF`` cipher data, or an ``encryptedfile`` relationship), which used
  to be called "not well-formed XML".

A 3MF read here is then also read by lib3mf, the 3MF Consortium's own
reader, in a bounded child process (:mod:`saucerfab.check.readers.lib3mf_strict`,
run by :func:`saucerfab.check.check_mesh`).
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.safe import (
    SafeZip,
    TextureBudget,
    parse_xml,
    probe_texture,
    read_texture_entry,
    zip_join,
)
from saucerfab.check.readers.threemf_blocks import Block, fast_blocks
from saucerfab.check.readers.threemf_grammar import TRI_ATTR_ORDER
from saucerfab.check.readers.threemf_resources import check_resources
from saucerfab.check.readers.threemf_rules import Rules
from saucerfab.check.readers.threemf_spec import CIPHER_MAGIC
from saucerfab.check.readers.threemf_spec import C as _C
from saucerfab.check.readers.threemf_spec import M as _M  # M alone is a transform matrix in this module
from saucerfab.check.readers.threemf_spec import P as _P
from saucerfab.check.readers.xmlscan import declared_encoding, root_namespaces, xml_too_deep

#: millimetres per 3MF unit
UNITS_MM = {"micron": 0.001, "millimeter": 1.0, "centimeter": 10.0, "inch": 25.4, "foot": 304.8, "meter": 1000.0}

# -- model structure ------------------------------------------------------------

_GROUP_TAGS = frozenset({_M + "texture2dgroup", _M + "colorgroup", _C + "basematerials", _M + "compositematerials",
                         _M + "multiproperties"})


@dataclass
class _Group:
    kind: str  # tex | color | base | other
    size: int
    coords: np.ndarray | None = None  # (k, 2) for tex
    texid: int | None = None


@dataclass
class _Part:
    name: str
    unit: str
    objects: dict[int, Any] = field(default_factory=dict)
    groups: dict[int, _Group] = field(default_factory=dict)
    textures: dict[int, str] = field(default_factory=dict)  # texture2d id -> archive path
    items: list[tuple[int, np.ndarray, str | None]] = field(default_factory=list)
    meshes: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray | None]] = field(default_factory=dict)
    ns: dict[str, str] = field(default_factory=dict)  # prefixes declared on <model>
    dup_ids: set[int] = field(default_factory=set)  # resource ids defined twice (the rules report them)


def _int_attr(el: Any, name: str, what: str) -> int | None:
    v = el.get(name)
    if v is None:
        return None
    try:
        n = int(v)
    except ValueError:
        raise ReadError("malformed", f"{what}: attribute {name}={v[:40]!r} is not an integer") from None
    if n < 0:
        raise ReadError("index_out_of_range", f"{what}: attribute {name}={n} is negative")
    return n


def _transform(text: str | None, what: str) -> np.ndarray:
    """3MF's 3x4 row-vector matrix as a 4x4 column-vector transform."""
    out = np.eye(4)
    if text is None:
        return out
    try:
        m = np.array(text.split(), dtype=np.float64)
    except ValueError:
        raise ReadError("malformed", f"{what}: transform {text[:60]!r} is not 12 numbers") from None
    if m.shape != (12,):
        raise ReadError("malformed", f"{what}: transform has {m.size} numbers, needs 12")
    if not np.isfinite(m).all():
        raise ReadError("malformed", f"{what}: transform has NaN or infinite entries")
    out[:3, :3] = m[:9].reshape(3, 3).T
    out[:3, 3] = m[9:]
    return out


class _Reader:
    def __init__(self, zf: SafeZip, limits: Limits) -> None:
        self.zf = zf
        self.limits = limits
        self.parts: dict[str, _Part] = {}
        self.b = MeshBuilder("3mf", limits)
        self.marker_ns = "urn:saucerfab:check:block:" + secrets.token_hex(8)
        self._comp_cache: dict[tuple[str, int], list[tuple[_Part, int, np.ndarray]]] = {}
        self._cost_cache: dict[tuple[str, int], tuple[int, int, int]] = {}
        self.tex_budget = TextureBudget(limits)  # all of the package's textures together
        self.rules = Rules(zf)

    # ---- parts
    def part(self, name: str) -> _Part:
        key = name.lower()
        if key in self.parts:
            return self.parts[key]
        if len(self.parts) >= 64:
            raise ReadError("over_check_limit", "the 3MF references more than 64 model parts")
        if not self.zf.has(name):
            raise ReadError("malformed", f"the 3MF has no model part {name!r}")
        raw = self.zf.read(name, self.limits.max_xml_bytes, "model part")
        self.rules.check_encrypted(name, raw)
        self.rules.xml_prolog(raw, name)
        skeleton, blocks = fast_blocks(raw, self.marker_ns, self.limits)
        depth = xml_too_deep(skeleton, self.limits.max_xml_depth)
        if depth is not None:
            raise ReadError(
                "over_check_limit",
                f"model part {name!r} nests XML elements {depth:,} deep, over the checker's limit of "
                f"{self.limits.max_xml_depth} (a 3MF model nests about 6 deep; Limits.max_xml_depth); refused "
                "before parsing",
            )
        try:
            root = parse_xml(skeleton, f"model part {name!r}", self.limits.max_xml_tree_bytes,
                             self.limits.max_xml_elements)
        except ReadError as exc:
            enc = declared_encoding(raw)
            if exc.code == "malformed" and enc is not None and enc.upper().replace("_", "-") not in ("UTF-8", "UTF8"):
                raise ReadError("malformed", f"{exc.message} (it is declared as {enc}; 3MF XML must be UTF-8)") from None
            raise
        if root.tag != _C + "model":
            raise ReadError("malformed", f"model part {name!r} has root <{root.tag}>, not a 3MF core <model>")
        p = _Part(name=name, unit=root.get("unit", "millimeter"), ns=root_namespaces(raw))
        self.parts[key] = p
        self.rules.xml_attributes(skeleton, root, name)
        self.rules.model(name, root, p.ns)
        self._index(p, root, blocks)
        res = root.find(_C + "resources")
        if res is not None:
            check_resources(self.rules, p, res)
        return p

    def _block(self, el: Any, blocks: list[Block], kind: str) -> Any:
        """The fast-path block standing in ``el``, if any."""
        if len(el) == 1 and el[0].tag == "{%s}sfblk" % self.marker_ns:
            blk = blocks[int(el[0].get("i"))]
            if blk.kind == kind:
                return blk.values
        return None

    def _index(self, p: _Part, root: Any, blocks: list[Block]) -> None:
        res = root.find(_C + "resources")
        if res is not None:
            for el in res:
                rid = _int_attr(el, "id", f"<{el.tag.split('}')[-1]}> in {p.name}")
                if rid is None:
                    continue
                # a repeated id (the rules report it): the first definition of its kind stands; between two
                # property groups which one a triangle means is unknowable, and those faces read uncoloured
                if el.tag == _C + "object" and rid in p.objects or el.tag == _M + "texture2d" and rid in p.textures:
                    continue
                if rid in p.groups and el.tag in _GROUP_TAGS:
                    p.dup_ids.add(rid)
                    continue
                if el.tag == _C + "object":
                    p.objects[rid] = el
                elif el.tag == _M + "texture2d":
                    p.textures[rid] = el.get("path") or ""
                elif el.tag == _M + "texture2dgroup":
                    coords = self._block(el, blocks, "tex2coord")
                    if coords is None:
                        kids = [c for c in el if c.tag == _M + "tex2coord"]
                        try:
                            coords = np.array([(c.get("u"), c.get("v")) for c in kids], dtype=np.float64).reshape(-1, 2)
                        except (TypeError, ValueError):
                            raise ReadError("malformed", f"texture2dgroup {rid}: a tex2coord lacks a numeric u or v") from None
                    p.groups[rid] = _Group("tex", len(coords), coords=coords, texid=_int_attr(el, "texid", f"texture2dgroup {rid}"))
                elif el.tag == _M + "colorgroup":
                    p.groups[rid] = _Group("color", sum(1 for c in el if c.tag == _M + "color"))
                elif el.tag == _C + "basematerials":
                    p.groups[rid] = _Group("base", sum(1 for c in el if c.tag == _C + "base"))
                elif el.tag in (_M + "compositematerials", _M + "multiproperties"):
                    p.groups[rid] = _Group("other", len(el))
                    self.b.note("ignored_content", f"3MF {el.tag.split('}')[-1]}: faces using them count as coloured, "
                                                   "but the blended colour itself is not checked")
        build = root.find(_C + "build")
        if build is not None:
            for it in build:
                if it.tag != _C + "item":
                    continue
                oid = _int_attr(it, "objectid", "build item")
                if oid is None:
                    raise ReadError("malformed", "a 3MF build item has no objectid")
                p.items.append((oid, _transform(it.get("transform"), f"build item {oid}"), it.get(_P + "path")))
        for oid, obj in p.objects.items():
            mesh = obj.find(_C + "mesh")
            if mesh is not None:
                p.meshes[oid] = self._mesh(p, oid, mesh, blocks)

    def _mesh(self, p: _Part, oid: int, mesh: Any, blocks: list[Block]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        what = f"object {oid} in {p.name}"
        vel = mesh.find(_C + "vertices")
        tel = mesh.find(_C + "triangles")
        V = None if vel is None else self._block(vel, blocks, "vertices")
        if V is None:
            kids = [] if vel is None else [c for c in vel if c.tag == _C + "vertex"]
            self.b.reserve(len(kids), 0, what)
            try:
                V = np.array([(c.get("x"), c.get("y"), c.get("z")) for c in kids], dtype=np.float64).reshape(-1, 3)
            except (TypeError, ValueError):
                raise ReadError("malformed", f"{what}: a vertex lacks a numeric x, y or z") from None
        tri = None if tel is None else self._block(tel, blocks, "triangles")
        if tri is not None:
            vals, names = tri
            T = np.full((len(vals), 7), -1, dtype=np.int64)
            for j, n in enumerate(names):
                T[:, TRI_ATTR_ORDER.index(n)] = vals[:, j]
        else:
            kids = [] if tel is None else [c for c in tel if c.tag == _C + "triangle"]
            self.b.reserve(0, len(kids), what)
            try:
                T = np.array(
                    [[c.get(n.decode(), "-1") for n in TRI_ATTR_ORDER] for c in kids], dtype=np.int64
                ).reshape(-1, 7)
            except (TypeError, ValueError, OverflowError):
                raise ReadError("malformed", f"{what}: a triangle has a non-integer index") from None
            if (T[:, :3] < 0).any():
                raise ReadError("malformed", f"{what}: a triangle lacks v1, v2 or v3, or has a negative index")
        faces = T[:, :3]
        if len(faces) and (faces.max() >= len(V)):
            bad = int(np.flatnonzero((faces >= len(V)).any(axis=1))[0])
            raise ReadError(
                "index_out_of_range",
                f"{what}: triangle {bad} uses vertex {int(faces[bad].max())} but the object has {len(V):,} vertices",
                where={"faces": [bad]},
            )
        props = T[:, 3:] if (T[:, 3:] >= 0).any() else None
        return V, faces, props

    # ---- instancing
    def _components(self, p: _Part, oid: int, obj: Any) -> list[tuple[_Part, int, np.ndarray]]:
        """(part, object id, transform) of each component of ``obj``, parsed once."""
        key = (p.name.lower(), oid)
        if key in self._comp_cache:
            return self._comp_cache[key]
        out: list[tuple[_Part, int, np.ndarray]] = []
        comps = obj.find(_C + "components")
        for c in [] if comps is None else comps:
            if c.tag != _C + "component":
                continue
            cid = _int_attr(c, "objectid", f"component of object {oid}")
            if cid is None:
                raise ReadError("malformed", f"a component of object {oid} has no objectid")
            sub = p
            path = c.get(_P + "path")
            if path:
                target = zip_join("/", path)
                if target is None:
                    raise ReadError("archive_unsafe_path", f"component path {path!r} escapes the archive")
                sub = self.part(target)
            out.append((sub, cid, _transform(c.get("transform"), f"component of object {oid}")))
        self._comp_cache[key] = out
        return out

    def cost(self, p: _Part, oid: int, stack: tuple[tuple[str, int], ...] = ()) -> tuple[int, int, int]:
        """(triangles, vertices, mesh parts) instancing ``oid`` would make, without making them.

        Memoised per object, so a hierarchy that fans out to 10^12 triangles
        is priced in a few steps and refused before any array exists.
        """
        key = (p.name.lower(), oid)
        if key in self._cost_cache:
            return self._cost_cache[key]
        if key in stack:
            raise ReadError("over_check_limit", f"3MF components form a cycle through object {oid}")
        if len(stack) > self.limits.max_nesting:
            raise ReadError("over_check_limit", f"3MF components nest deeper than {self.limits.max_nesting}")
        obj = p.objects.get(oid)
        if obj is None:
            raise ReadError("malformed", f"3MF refers to object {oid}, which {p.name} does not define")
        if obj.get("type", "model") == "other":
            total = (0, 0, 0)
        elif oid in p.meshes:
            V, F, _ = p.meshes[oid]
            total = (len(F), len(V), 1)
        else:
            total = (0, 0, 0)
            for sub, cid, _ in self._components(p, oid, obj):
                t = self.cost(sub, cid, stack + (key,))
                total = (total[0] + t[0], total[1] + t[1], total[2] + t[2])
        self._cost_cache[key] = total
        return total

    def instance(self, p: _Part, oid: int, M: np.ndarray, depth: int) -> None:
        if depth > self.limits.max_nesting:
            raise ReadError("over_check_limit", f"3MF components nest deeper than {self.limits.max_nesting} (a cycle?)")
        obj = p.objects.get(oid)
        if obj is None:
            raise ReadError("malformed", f"3MF refers to object {oid}, which {p.name} does not define")
        otype = obj.get("type", "model")
        if otype == "other":
            self.rules.object_type_other(p.name, oid)
            return
        if oid in p.meshes:
            V, F, props = p.meshes[oid]
            self.b.reserve(len(V), len(F), f"object {oid}")
            self._emit(p, oid, obj, V, F, props, M)
            return
        comps = self._components(p, oid, obj)
        if not comps:
            self.b.note("ignored_content", f"3MF object {oid} has neither a mesh nor components (skipped)")
        for sub, cid, T in comps:
            self.instance(sub, cid, M @ T, depth + 1)

    def _emit(self, p: _Part, oid: int, obj: Any, V: np.ndarray, F: np.ndarray, props: np.ndarray | None, M: np.ndarray) -> None:
        A, t = M[:3, :3], M[:3, 3]
        Vw = V @ A.T + t if not np.array_equal(M, np.eye(4)) else V
        if np.linalg.det(A) < 0:
            F = F[:, ::-1]  # a mirroring transform turns the winding inside out; undo it
            props = None if props is None else props[:, [0, 3, 2, 1]]
        m = len(F)
        opid = _int_attr(obj, "pid", f"object {oid}")
        oidx = _int_attr(obj, "pindex", f"object {oid}")
        pid = np.full(m, -1, dtype=np.int64) if props is None else props[:, 0].copy()
        pc = np.full((m, 3), -1, dtype=np.int64) if props is None else props[:, 1:].copy()
        nopid = pid < 0
        if opid is not None:
            pid[nopid] = opid
            pc[nopid] = -1
        pc[:, 0] = np.where(pc[:, 0] < 0, oidx if oidx is not None else 0, pc[:, 0])
        pc[:, 1] = np.where(pc[:, 1] < 0, pc[:, 0], pc[:, 1])
        pc[:, 2] = np.where(pc[:, 2] < 0, pc[:, 0], pc[:, 2])
        uv = None
        tex = None
        col = None
        for g_id in np.unique(pid):
            g_id = int(g_id)
            if g_id < 0:
                continue
            if g_id in p.dup_ids:
                continue  # which of two resources is meant is unknowable: read uncoloured (spec_violation says why)
            sel = pid == g_id
            grp = p.groups.get(g_id)
            if grp is None:
                raise ReadError("malformed", f"object {oid}: property id {g_id} names no texture, colour or material group")
            idx = pc[sel]
            if idx.size and idx.max() >= grp.size:
                raise ReadError(
                    "index_out_of_range",
                    f"object {oid}: property index {int(idx.max())} in group {g_id}, which has {grp.size} entries",
                )
            if grp.kind == "tex":
                if uv is None:
                    uv = np.full((m, 3, 2), np.nan)
                    tex = np.full(m, -1, dtype=np.int32)
                assert grp.coords is not None
                uv[sel] = grp.coords[idx]
                tex[sel] = self._texture(p, grp.texid, g_id)
                self.b.colour_kinds.add("texture")
            else:
                if col is None:
                    col = np.zeros(m, dtype=bool)
                col[sel] = True
                self.b.colour_kinds.add({"color": "vertex", "base": "material"}.get(grp.kind, "material"))
        self.b.add(Vw, F, corner_uv=uv, face_texture=tex, face_colour=col, what=f"3MF object {oid}")

    def _texture(self, p: _Part, texid: int | None, gid: int) -> int:
        if texid is None or texid not in p.textures:
            return self.b.texture(
                f"<texture2d {texid}>",
                lambda: TextureInfo(name=f"texture2d {texid}", status="missing",
                                    message=f"texture2dgroup {gid} refers to texture2d {texid}, which is not defined"),
            )
        path = p.textures[texid]

        def load() -> TextureInfo:
            target = zip_join(p.name, path) if path else None
            if target is None:
                return TextureInfo(name=path, status="unsafe_path" if path else "missing",
                                   message=f"texture2d {texid} path {path!r} is empty or escapes the archive")
            data = read_texture_entry(self.zf, target, path, self.limits, damaged="too_large")
            if isinstance(data, TextureInfo):
                return data
            if data[:5] == CIPHER_MAGIC or target.lower() in self.rules.package.encrypted:
                return TextureInfo(name=path, status="unreadable",
                                   message=f"texture {path!r} is encrypted (3MF Secure Content); the checker cannot "
                                           "decrypt it")
            return probe_texture(path, data, self.limits, budget=self.tex_budget)

        return self.b.texture(path.lower(), load)


def has_model_part(zf: SafeZip) -> bool:
    """Whether an archive is a 3MF package (a relationship to a model part, or a ``.model`` entry)."""
    return zf.has("_rels/.rels") or any(n.lower().endswith(".model") for n in zf.entry_names())


def read_3mf(data: bytes | SafeZip, limits: Limits) -> MeshData:
    """Read a 3MF package from its bytes (or an already opened archive)."""
    zf = data if isinstance(data, SafeZip) else SafeZip(data, limits)
    r = _Reader(zf, limits)
    pkg = r.rules.read_package()
    assert pkg.start is not None  # read_package raises when there is none
    root = r.part(pkg.start)
    unit = root.unit
    if unit not in UNITS_MM:
        raise ReadError("malformed", f"3MF unit {unit[:40]!r} is not one of {sorted(UNITS_MM)}")
    if not root.items:
        raise ReadError("no_triangles", "the 3MF build has no items: nothing would be printed")
    items = []
    tri = vert = parts = 0
    for oid, M, path in root.items:
        p = root
        if path:
            target = zip_join("/", path)
            if target is None:
                raise ReadError("archive_unsafe_path", f"build item path {path!r} escapes the archive")
            p = r.part(target)
        t, v, n = r.cost(p, oid)
        tri, vert, parts = tri + t, vert + v, parts + n
        items.append((p, oid, M))
    if tri > limits.max_triangles or vert > limits.max_vertices or parts > limits.max_parts:
        raise ReadError(
            "over_check_limit",
            f"the 3MF build instances {tri:,} triangles in {parts:,} mesh parts, over the checker's limits "
            f"({limits.max_triangles:,} triangles, Limits.max_triangles; {limits.max_vertices:,} vertices, "
            f"Limits.max_vertices; {limits.max_parts:,} parts, Limits.max_parts)"
            + f"; {raise_hint(max(tri, -(-vert // 3)) if parts <= limits.max_parts else None)}",
        )
    for p, oid, M in items:
        r.instance(p, oid, M, 0)
    r.b.notes.extend(r.rules.done())
    return r.b.build(unit_mm=UNITS_MM[unit], units=unit, units_stated=True)
