"""VRML 2.0 (VRML97) reader: IndexedFaceSet shapes under Transform/Group nodes.

What colour 3D printers read from VRML is shapes made of ``IndexedFaceSet``
with ``Coordinate`` points, optional ``TextureCoordinate`` and an
``ImageTexture`` or ``Color`` node; that is what this reader understands,
with ``DEF``/``USE`` sharing, ``Transform`` (translation, rotation, scale,
scaleOrientation, center), ``Group``-like nodes, ``Switch`` and ``LOD``.
Other geometry (Box, Sphere, ElevationGrid...), ``PROTO`` instances and
``Inline`` are skipped with a warning. Bulk number arrays (``point [...]``,
``coordIndex [...]``) are read with numpy in slices of 256 kB, counted
against the caps as they go (never one Python string per number of the
whole array); other tokens are counted and capped (``Limits.max_vrml_tokens``)
so a file of endless tokens ends quickly, and runs of blanks are skipped
without being copied. Instancing (DEF/USE) is priced per node before the
walk: triangles, shapes and node visits (``Limits.max_node_visits``).

Units: VRML97 nominally uses metres, but colour-printer software (ZPrint,
GrabCAD) reads VRML in millimetres, so the checker assumes millimetres and
warns when the size is implausible.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.safe import DiskResources, Resources

# blanks, commas and comments between tokens are skipped without taking their text (a bomb of spaces
# is one run, and copying it would double the file in memory); one match per token, the token in group 1
_SKIP = re.compile(r"(?:[ \t\r\n,]+|#[^\n\r]*)+")
_LEX = re.compile(r'(?:[ \t\r\n,]+|#[^\n\r]*)*("(?:[^"\\]|\\.)*"|[{}\[\]]|[^ \t\r\n,{}\[\]"#]+)?')
_NUMERIC_ARRAY = re.compile(r"[0-9eE.+\- \t\r\n,]*")
_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|0[xX][0-9a-fA-F]+")
_SEPARATOR = re.compile(r"[ \t\r\n,]")
_ARRAY_SLICE = 1 << 18  # characters of a number array converted at a time
_GROUPS = {"Group", "Transform", "Anchor", "Billboard", "Collision"}
_SKIPPED_GEOMETRY = {"Box", "Sphere", "Cylinder", "Cone", "ElevationGrid", "Extrusion", "Text", "PointSet", "IndexedLineSet"}


@dataclass
class Node:
    type: str
    fields: dict[str, Any] = field(default_factory=dict)


class _Parser:
    def __init__(self, text: str, limits: Limits) -> None:
        self.text = text
        self.pos = 0
        self.tokens = 0
        self.limits = limits
        self.defs: dict[str, Node] = {}
        self.protos = False
        self._peeked: str | None = None

    # ---- tokens
    def _next_raw(self) -> str | None:
        m = _LEX.match(self.text, self.pos)  # always matches: everything in it is optional
        if m is not None:
            self.pos = m.end()
        tok = m.group(1) if m is not None else None
        if tok is None:
            if self.pos >= len(self.text):
                return None
            raise ReadError("malformed", f"VRML: unexpected character at offset {self.pos}")
        self.tokens += 1
        if self.tokens > self.limits.max_vrml_tokens:
            raise ReadError("over_check_limit", f"VRML: more than {self.limits.max_vrml_tokens:,} tokens outside "
                                                "number arrays (Limits.max_vrml_tokens)")
        return tok

    def peek(self) -> str | None:
        if self._peeked is None:
            self._peeked = self._next_raw()
        return self._peeked

    def next(self) -> str | None:
        tok = self.peek()
        self._peeked = None
        return tok

    def expect(self, want: str) -> None:
        tok = self.next()
        if tok != want:
            raise ReadError(
                "truncated" if tok is None else "malformed",
                f"VRML: expected {want!r} but found {'the end of the file' if tok is None else repr(tok[:30])}",
            )

    # ---- grammar
    def scene(self) -> list[Node]:
        out: list[Node] = []
        while (tok := self.peek()) is not None:
            if tok in ("PROTO", "EXTERNPROTO"):
                self._skip_proto()
            elif tok == "ROUTE":
                for _ in range(4):
                    self.next()
            else:
                node = self.node(0)
                if node is not None:
                    out.append(node)
        return out

    def _skip_proto(self) -> None:
        kind = self.next()
        self.protos = True
        self.next()  # name
        self._skip_balanced("[", "]")
        if kind == "PROTO":
            self._skip_balanced("{", "}")
        else:
            tok = self.peek()
            if tok == "[":
                self._skip_balanced("[", "]")
            else:
                self.next()

    def _skip_balanced(self, open_: str, close: str) -> None:
        self.expect(open_)
        depth = 1
        while depth:
            tok = self.next()
            if tok is None:
                raise ReadError("truncated", f"VRML: the file ends inside a {open_}...{close} block")
            if tok == open_:
                depth += 1
            elif tok == close:
                depth -= 1

    def node(self, depth: int) -> Node | None:
        if depth > 4 * self.limits.max_nesting:
            raise ReadError("over_check_limit", "VRML nodes nest too deeply")
        tok = self.next()
        if tok is None:
            raise ReadError("truncated", "VRML: the file ends where a node should be")
        if tok == "NULL":
            return None
        if tok == "USE":
            name = self.next() or ""
            if name not in self.defs:
                raise ReadError("malformed", f"VRML: USE {name[:40]!r} before any DEF of it")
            return self.defs[name]
        name = None
        if tok == "DEF":
            name = self.next()
            tok = self.next()
        if tok is None or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", tok):
            raise ReadError("malformed", f"VRML: expected a node type, found {str(tok)[:30]!r}")
        node = Node(tok)
        self.expect("{")
        while True:
            t = self.peek()
            if t is None:
                raise ReadError("truncated", f"VRML: the file ends inside a {node.type} node")
            if t == "}":
                self.next()
                break
            if t in ("PROTO", "EXTERNPROTO"):
                self._skip_proto()
                continue
            if t == "ROUTE":
                for _ in range(4):
                    self.next()
                continue
            fname = self.next()
            assert fname is not None
            node.fields[fname] = self.value(depth)
        if name:
            self.defs[name] = node
        return node

    def value(self, depth: int) -> Any:
        tok = self.peek()
        if tok == "[":
            return self._list(depth)
        if tok in ("DEF", "USE", "NULL") or (tok is not None and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", tok)
                                             and tok not in ("TRUE", "FALSE", "IS")):
            # a node, unless the next token is not '{' (then it is the next field's name after an empty value)
            if tok in ("DEF", "USE", "NULL") or self._node_follows():
                return self.node(depth + 1)
        if tok == "IS":
            self.next()
            self.next()
            return None
        vals: list[Any] = []
        while (t := self.peek()) is not None:
            if t.startswith('"'):
                vals.append(_unquote(t))
            elif t in ("TRUE", "FALSE"):
                vals.append(t == "TRUE")
            elif _NUMBER.fullmatch(t):
                vals.append(float(int(t, 16)) if t[:2].lower() == "0x" else float(t))
            else:
                break
            self.next()
        return vals

    def _node_follows(self) -> bool:
        # look past the peeked word without consuming: a node type is followed by '{'
        skip = _SKIP.match(self.text, self.pos)
        pos = skip.end() if skip is not None else self.pos
        return self.text.startswith("{", pos)

    def _list(self, depth: int) -> Any:
        self.expect("[")
        # bulk number arrays: match in place (no copy of non-numeric lists, which may span the file)
        m = _NUMERIC_ARRAY.match(self.text, self.pos)
        if m is not None and m.end() < len(self.text) and self.text[m.end()] == "]":
            self.pos = m.end() + 1
            return self._numbers(m.start(), m.end())
        items: list[Any] = []
        while True:
            t = self.peek()
            if t is None:
                raise ReadError("truncated", "VRML: the file ends inside a [...] list")
            if t == "]":
                self.next()
                return items
            if t.startswith('"'):
                items.append(_unquote(t))
                self.next()
            elif t in ("TRUE", "FALSE"):
                items.append(t == "TRUE")
                self.next()
            elif _NUMBER.fullmatch(t):
                items.append(float(t) if t[:2].lower() != "0x" else float(int(t, 16)))
                self.next()
            else:
                items.append(self.node(depth + 1))


    def _numbers(self, start: int, end: int) -> np.ndarray:
        """The numbers in ``text[start:end]`` (blanks and commas only between them), a slice at a time.

        Converting the whole array at once made one Python string per number
        (~50 bytes each, 25 times the text for "10 10 10 ..."); slices cut at
        a separator keep that to a slice's worth, and the running count
        refuses an array longer than any the limits allow before converting
        the rest.
        """
        lim = self.limits
        cap = max(3 * lim.max_vertices, 4 * lim.max_triangles)  # points (x, y, z) or 'a b c -1' indices
        text = self.text
        parts: list[np.ndarray] = []
        n = 0
        pos = start
        while pos < end:
            stop = end
            if pos + _ARRAY_SLICE < end:
                sep = _SEPARATOR.search(text, pos + _ARRAY_SLICE, end)  # never cut a number in two
                stop = sep.start() if sep is not None else end
            piece = text[pos:stop].replace(",", " ").split()
            n += len(piece)
            if n > cap:
                raise ReadError(
                    "over_check_limit",
                    f"VRML: a number array holds over {cap:,} numbers, more than the checker's limits allow "
                    f"(3 x Limits.max_vertices coordinates, 4 x Limits.max_triangles indices); {raise_hint()}",
                )
            try:
                parts.append(np.array(piece, dtype=np.float64))
            except ValueError:
                raise ReadError("malformed", "VRML: a number array holds something that is not a number") from None
            pos = stop
        return np.concatenate(parts) if parts else np.zeros(0)


def _unquote(tok: str) -> str:
    return re.sub(r"\\(.)", r"\1", tok[1:-1])


def _nums(v: Any, what: str) -> np.ndarray:
    try:
        return np.asarray(v if v is not None else [], dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ReadError("malformed", f"VRML: {what} is not a list of numbers") from None


def _axis_angle(r: np.ndarray) -> np.ndarray:
    x, y, z, a = r
    n = np.linalg.norm([x, y, z])
    if n == 0:
        return np.eye(3)
    x, y, z = x / n, y / n, z / n
    c, s, C = np.cos(a), np.sin(a), 1 - np.cos(a)
    return np.array([
        [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
        [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
        [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
    ])


def _transform_matrix(n: Node) -> np.ndarray:
    def vec(name: str, default: list[float]) -> np.ndarray:
        v = _nums(n.fields.get(name, default), f"Transform {name}")
        if len(v) != len(default):
            raise ReadError("malformed", f"VRML: Transform {name} needs {len(default)} numbers")
        return v

    T, C = vec("translation", [0, 0, 0]), vec("center", [0, 0, 0])
    R = _axis_angle(vec("rotation", [0, 0, 1, 0]))
    SR = _axis_angle(vec("scaleOrientation", [0, 0, 1, 0]))
    S = np.diag(vec("scale", [1, 1, 1]))
    A = R @ SR @ S @ SR.T
    M = np.eye(4)
    M[:3, :3] = A
    M[:3, 3] = T + C - A @ C
    if not np.isfinite(M).all():
        raise ReadError("malformed", "VRML: a Transform has NaN or infinite values")
    return M


class _Walker:
    def __init__(self, res: Resources, limits: Limits) -> None:
        self.res = res
        self.limits = limits
        self.b = MeshBuilder("wrl", limits)
        self.visits = 0

    def cost(self, node: Any, memo: dict[int, tuple[int, int, int]], depth: int = 0) -> tuple[int, int, int]:
        """(triangles, shapes, node visits) walking ``node`` would take; memoised per node, so USE fan-outs are cheap."""
        if not isinstance(node, Node):
            return (0, 0, 0)
        key = id(node)
        if key in memo:
            return memo[key]
        if depth > self.limits.max_nesting:
            raise ReadError("over_check_limit", "VRML scene graph nests too deeply (Limits.max_nesting)")
        t = node.type
        total = (0, 0, 1)
        if t == "Shape":
            geo = node.fields.get("geometry")
            if isinstance(geo, Node) and geo.type == "IndexedFaceSet":
                ci = geo.fields.get("coordIndex")
                n = len(ci) if isinstance(ci, (list, np.ndarray)) else 0
                minus = int(np.count_nonzero(np.asarray(ci) == -1)) if n else 0
                total = (max(0, n - 3 * minus), 1, 1)
        else:
            kids: list[Any] = []
            if t in _GROUPS:
                kids = _children(node.fields.get("children"))
            elif t == "Switch":
                choice = _children(node.fields.get("choice"))
                w = _nums(node.fields.get("whichChoice", [-1]), "whichChoice")
                i = int(w[0]) if len(w) else -1
                kids = [choice[i]] if 0 <= i < len(choice) else []
            elif t == "LOD":
                kids = _children(node.fields.get("level"))[:1]
            for c in kids:
                a, b, v = self.cost(c, memo, depth + 1)
                total = (total[0] + a, total[1] + b, total[2] + v)
        memo[key] = total
        return total

    def walk(self, node: Any, M: np.ndarray, depth: int) -> None:
        if not isinstance(node, Node):
            return
        self.visits += 1  # priced before the walk; this guards the walk itself
        if self.visits > self.limits.max_node_visits or depth > self.limits.max_nesting:
            raise ReadError("over_check_limit", "VRML scene graph too large or too deep "
                                                "(Limits.max_node_visits/max_nesting)")
        t = node.type
        if t == "Shape":
            self.shape(node, M)
        elif t in _GROUPS:
            M2 = M @ _transform_matrix(node) if t == "Transform" else M
            for c in _children(node.fields.get("children")):
                self.walk(c, M2, depth + 1)
        elif t == "Switch":
            kids = _children(node.fields.get("choice"))
            w = _nums(node.fields.get("whichChoice", [-1]), "whichChoice")
            i = int(w[0]) if len(w) else -1
            if 0 <= i < len(kids):
                self.walk(kids[i], M, depth + 1)
        elif t == "LOD":
            kids = _children(node.fields.get("level"))
            if kids:
                self.walk(kids[0], M, depth + 1)
        elif t == "Inline":
            self.b.note("ignored_content", "VRML Inline nodes are not followed")

    def shape(self, node: Node, M: np.ndarray) -> None:
        geo = node.fields.get("geometry")
        if not isinstance(geo, Node):
            return
        if geo.type != "IndexedFaceSet":
            if geo.type in _SKIPPED_GEOMETRY:
                self.b.note("ignored_content", f"VRML {geo.type} geometry is not checked (only IndexedFaceSet)")
            else:
                self.b.note("ignored_content", f"VRML geometry {geo.type} (a PROTO?) is not checked")
            return
        f = geo.fields
        coord = f.get("coord")
        if not isinstance(coord, Node):
            return
        pts = _nums(coord.fields.get("point"), "Coordinate point")
        if len(pts) % 3:
            raise ReadError("malformed", "VRML: Coordinate point count is not a multiple of 3")
        V = pts.reshape(-1, 3)
        ci = _nums(f.get("coordIndex"), "coordIndex")
        self.b.reserve(len(V), _fan_count(ci), "VRML IndexedFaceSet")
        F, corner_of = _polygons(ci, "coordIndex")
        if not _bool(f.get("ccw"), True):
            F = F[:, ::-1]
            corner_of = corner_of[:, ::-1]
        A = M[:3, :3]
        if np.linalg.det(A) < 0:
            F = F[:, ::-1]
            corner_of = corner_of[:, ::-1]
        Vw = V @ A.T + M[:3, 3]
        m = len(F)
        uv = tex = col = None
        app = node.fields.get("appearance")
        texnode = app.fields.get("texture") if isinstance(app, Node) else None
        if isinstance(texnode, Node):
            ti = self._texture(texnode)
            uv = self._uvs(f, ci, corner_of, V, m)
            tex = np.full(m, ti, dtype=np.int32)
            self.b.colour_kinds.add("texture")
        if isinstance(f.get("color"), Node):
            col = np.ones(m, dtype=bool)
            self.b.colour_kinds.add("vertex" if _bool(f.get("colorPerVertex"), True) else "face")
        elif isinstance(app, Node) and isinstance(app.fields.get("material"), Node):
            if "diffuseColor" in app.fields["material"].fields:
                col = np.ones(m, dtype=bool)
                self.b.colour_kinds.add("material")
        self.b.add(Vw, F, corner_uv=uv, face_texture=tex, face_colour=col, what="VRML IndexedFaceSet")

    def _uvs(self, f: dict[str, Any], ci: np.ndarray, corner_of: np.ndarray, V: np.ndarray, m: int) -> np.ndarray:
        tcn = f.get("texCoord")
        if isinstance(tcn, Node):
            tp = _nums(tcn.fields.get("point"), "TextureCoordinate point")
            if len(tp) % 2:
                raise ReadError("malformed", "VRML: TextureCoordinate point count is odd")
            TP = tp.reshape(-1, 2)
            tci = _nums(f.get("texCoordIndex"), "texCoordIndex") if "texCoordIndex" in f else ci
            if len(tci) and len(tci) != len(ci):
                raise ReadError("malformed", "VRML: texCoordIndex does not parallel coordIndex")
            if not len(tci):
                tci = ci
            idx = tci[corner_of].astype(np.int64)
            if idx.size and (idx.min() < 0 or idx.max() >= len(TP)):
                raise ReadError("index_out_of_range", f"VRML: a texCoordIndex is outside the {len(TP)} texture coordinates")
            return TP[idx]
        # VRML's default mapping: s along the longest box side, t along the second, scaled by the longest
        lo, hi = V.min(axis=0), V.max(axis=0)
        order = np.argsort(-(hi - lo))
        size = float((hi - lo)[order[0]]) or 1.0
        st = np.stack([(V[:, order[0]] - lo[order[0]]) / size, (V[:, order[1]] - lo[order[1]]) / size], axis=1)
        vi = ci[corner_of].astype(np.int64)
        return st[vi]

    def _texture(self, tn: Node) -> int:
        if tn.type == "PixelTexture":
            return self.b.texture("<PixelTexture>", lambda: TextureInfo(name="PixelTexture", width=None, height=None))
        urls = tn.fields.get("url", [])
        urls = [u for u in (urls if isinstance(urls, list) else []) if isinstance(u, str)]
        if not urls:
            return self.b.texture("<no url>", lambda: TextureInfo(
                name="(no url)", status="missing", message=f"VRML {tn.type} has no url"))
        ref = urls[0]
        if re.match(r"^[A-Za-z][A-Za-z0-9+.-]*://", ref):
            return self.b.texture(ref, lambda: TextureInfo(
                name=ref, status="unsafe_path", message=f"texture url {ref[:80]!r} is remote; the checker does not fetch it"))
        return self.b.texture(ref, lambda: self.res.texture(ref))


def _bool(v: Any, default: bool) -> bool:
    if isinstance(v, list) and v and isinstance(v[0], bool):
        return v[0]
    return default


def _children(v: Any) -> list[Any]:
    if isinstance(v, Node):
        return [v]
    if isinstance(v, list):
        return [c for c in v if isinstance(c, Node)]
    return []


def _fan_count(ci: np.ndarray) -> int:
    """How many fan triangles :func:`_polygons` makes of a -1-separated index list (a k-gon: k - 2), exactly.

    (Half the list's length, the estimate before, refused an honest mesh
    of triangles - four indices each - at half ``Limits.max_triangles``.)
    """
    ends = np.flatnonzero(ci == -1)
    k = np.diff(np.concatenate([[-1], ends, [len(ci)]])) - 1  # polygon lengths, the trailing one too
    return int(np.maximum(k - 2, 0).sum())


def _polygons(ci: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles from a -1-separated index list, and the list position of each corner."""
    if ci.size and not np.array_equal(ci, np.round(ci)):
        raise ReadError("malformed", f"VRML: {what} holds non-integers")
    ci = ci.astype(np.int64)
    n = len(ci)
    # all triangles "a b c -1" (the common layout): no loop
    if n % 4 == 0 and n and (ci[3::4] == -1).all() and (ci.reshape(-1, 4)[:, :3] >= 0).all():
        pos = np.arange(n).reshape(-1, 4)[:, :3]
        return ci[pos], pos
    if n % 4 == 3 and n >= 3 and (ci[3::4] == -1).all() and (np.delete(ci, np.s_[3::4]) >= 0).all():
        pos = np.arange(n + 1).reshape(-1, 4)[:, :3]
        return np.append(ci, -1)[pos], pos
    ends = np.flatnonzero(ci == -1)
    starts = np.concatenate([[0], ends + 1])
    stops = np.concatenate([ends, [n]])
    tri_pos: list[np.ndarray] = []
    for s, e in zip(starts, stops):
        k = e - s
        if k >= 3:
            j = np.arange(1, k - 1)
            tri_pos.append(np.stack([np.full(k - 2, s), s + j, s + j + 1], axis=1))
    if (ci < -1).any():
        raise ReadError("index_out_of_range", f"VRML: {what} has an index below -1")
    if not tri_pos:
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3), dtype=np.int64)
    pos = np.concatenate(tri_pos)
    return ci[pos], pos


def read_vrml(path: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """Read a VRML 2.0 file's bytes (textures come from ``res``, default: beside ``path``)."""
    first = data[:64]
    if not first.startswith(b"#VRML V2.0"):
        if first.startswith(b"#VRML V1.0"):
            raise ReadError("unsupported_format", "VRML 1.0: the checker reads VRML 2.0 (VRML97); export VRML 2.0")
        raise ReadError("malformed", "a VRML file must start with '#VRML V2.0 utf8'")
    text = data.decode("utf-8", "replace")
    p = _Parser(text, limits)
    roots = p.scene()
    w = _Walker(res or DiskResources(path.parent, limits), limits)
    if p.protos:
        w.b.note("ignored_content", "VRML PROTO definitions were skipped; their instances are not checked")
    memo: dict[int, tuple[int, int, int]] = {}
    tri = shapes = visits = 0
    for r in roots:
        a, b, v = w.cost(r, memo)
        tri, shapes, visits = tri + a, shapes + b, visits + v
    if tri > limits.max_triangles or shapes > limits.max_parts:
        raise ReadError(
            "over_check_limit",
            f"the VRML scene instances about {tri:,} triangles in {shapes:,} shapes (DEF/USE), over the checker's "
            f"limits ({limits.max_triangles:,} triangles, Limits.max_triangles; {limits.max_parts:,} shapes, "
            f"Limits.max_parts); {raise_hint(tri if shapes <= limits.max_parts else None)}",
        )
    if visits > limits.max_node_visits:
        raise ReadError(
            "over_check_limit",
            f"the VRML scene takes {visits:,} node visits to instance (DEF/USE), over the checker's limit of "
            f"{limits.max_node_visits:,} (Limits.max_node_visits)",
        )
    for r in roots:
        w.walk(r, np.eye(4), 0)
    return w.b.build(units="millimeter (assumed; see the checker's VRML notes)")
