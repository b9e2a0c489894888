"""The 3MF specifications' MUST rules, checked on what the bounded 3MF reader already parsed.

:mod:`saucerfab.check.readers.threemf` reads the package within its budgets;
this module judges what it read against the 3MF Core Specification (1.3)
and the Materials and Properties Extension (1.2), the rules the 3MF
Consortium's must-fail files test. A broken rule is a ``spec_violation``
finding (error: printer software built on the Consortium's reader refuses
such files) whose message names the rule's section and the fix; a file is
unreadable only where the mesh itself cannot be read, and two cases are
refused as ``unsupported_format``: a model that *requires* an extension the
checker does not read, and a part encrypted with the Secure Content
extension.

Checked here:

* **OPC package** (core 2.1): ``[Content_Types].xml`` and ``_rels/.rels``
  exist; exactly one StartPart (3D model) relationship; thumbnail, print
  ticket and 3D texture targets exist; at most one print ticket per model
  part, and only from a model part; no relationship to anything outside
  the package (``TargetMode="External"``, ``C:/...``, ``http://...``);
  relationship ids unique and no repeated (type, target) pair per part;
  the model part's and textures' content types.
* **XML** (core 2.3): UTF-8 only; no ``xml:space``; no ``xsi:`` attributes;
  nesting depth bounded before parsing (:func:`xml_too_deep`, a numpy scan:
  200,000 nested elements are refused in milliseconds, not parsed).
* **Model** (core 3.4): ``requiredextensions`` (unsupported: unreadable;
  :data:`SUPPORTED_EXTENSIONS`); metadata names present, well-known or
  prefixed with a declared namespace, not repeated.
* **Resources** (core 3.4.2, 4, 5; Materials 2-6): ids unique across every
  kind of resource in a model part; references only to resources defined
  before them; object types; ``pid``/``pindex`` rules (``pindex`` needs
  ``pid``; objects with components carry neither;
  base materials form no gradients);
  colours ``#RRGGBB``/``#RRGGBBAA``; base materials' names and colours;
  textures' path and content type, tile styles and filter; texture groups'
  ``texid``; composites (``matid`` a ``<basematerials>``, ``matindices``
  in range, values in [0, 1]); multiproperties (``pids`` present, naming
  property groups defined before, at most one material and it first, at
  most one colour group, no multiproperties; ``blendmethods``; ``pindices``
  in range).
* **Build** (core 3.4.3): items reference no object of type ``other``,
  directly or through components.

Not checked here (left to lib3mf, :mod:`saucerfab.check.readers.lib3mf_strict`,
or to the geometry checks): the full XSD; that every texture is the target
of a 3D texture relationship; beam lattice, slice and other extensions'
own rules (a model that requires them is refused anyway).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers.safe import SafeZip, parse_xml, zip_join
from saucerfab.check.report import Finding, finding

NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_MAT = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02"
NS_PROD = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"
NS_RELS = "http://schemas.openxmlformats.org/package/2006/relationships"
NS_TYPES = "http://schemas.openxmlformats.org/package/2006/content-types"
NS_XML = "http://www.w3.org/XML/1998/namespace"
NS_XSI = "http://www.w3.org/2001/XMLSchema-instance"

REL_MODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
REL_THUMBNAIL = "http://schemas.openxmlformats.org/package/2006/relationships/metadata/thumbnail"
REL_PRINTTICKET = "http://schemas.microsoft.com/3dmanufacturing/2013/01/printticket"
REL_TEXTURE = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dtexture"
REL_KEYSTORE = ("http://schemas.microsoft.com/3dmanufacturing/2019/04/keystore",
                "http://schemas.microsoft.com/3dmanufacturing/2019/07/keystore")
REL_ENCRYPTED = "http://schemas.openxmlformats.org/package/2006/relationships/encryptedfile"
#: relationship types whose target part MUST be in the package (core 2.1.1)
REL_MUST_EXIST = {REL_MODEL: "3D model", REL_THUMBNAIL: "thumbnail", REL_PRINTTICKET: "print ticket",
                  REL_TEXTURE: "3D texture"}

CT_MODEL = "application/vnd.ms-package.3dmanufacturing-3dmodel+xml"
#: content types a texture part may have: the Materials extension's two, and the 3D texture type of core 1.0
CT_TEXTURE_PARTS = ("image/png", "image/jpeg", "application/vnd.ms-package.3dmanufacturing-3dmodeltexture")
CT_TEXTURE_ATTR = ("image/png", "image/jpeg")

#: extension namespaces the checker reads or may safely ignore when a model requires them:
#: materials (colour, textures), production (parts by path; UUIDs ignored), triangle sets (grouping only)
SUPPORTED_EXTENSIONS = {
    NS_CORE: "core",
    NS_MAT: "Materials and Properties",
    NS_PROD: "Production",
    "http://schemas.microsoft.com/3dmanufacturing/trianglesets/2021/07": "Triangle Sets",
}
#: well-known extensions the checker does not read, for messages
KNOWN_EXTENSIONS = {
    "http://schemas.microsoft.com/3dmanufacturing/beamlattice/2017/02": "Beam Lattice",
    "http://schemas.microsoft.com/3dmanufacturing/beamlattice/balls/2020/07": "Beam Lattice balls",
    "http://schemas.microsoft.com/3dmanufacturing/slice/2015/07": "Slice",
    "http://schemas.microsoft.com/3dmanufacturing/securecontent/2019/04": "Secure Content",
    "http://schemas.microsoft.com/3dmanufacturing/securecontent/2019/07": "Secure Content",
    "http://schemas.microsoft.com/3dmanufacturing/volumetric/2022/01": "Volumetric",
    "http://schemas.3mf.io/3dmanufacturing/implicit/2023/12": "Implicit",
    "http://schemas.microsoft.com/3dmanufacturing/displacement/2022/07": "Displacement",
    "http://schemas.3mf.io/3dmanufacturing/booleanoperations/2023/07": "Boolean Operations",
}

WELL_KNOWN_METADATA = frozenset({"Title", "Designer", "Description", "Copyright", "LicenseTerms", "Rating",
                                 "CreationDate", "ModificationDate", "Application"})
OBJECT_TYPES = frozenset({"model", "solidsupport", "support", "surface", "other"})
TILE_STYLES = frozenset({"wrap", "mirror", "clamp", "none"})
FILTERS = frozenset({"auto", "linear", "nearest"})
BLEND_METHODS = frozenset({"mix", "multiply"})

#: the first part of an encrypted part (3MF Secure Content, Appendix D)
CIPHER_MAGIC = b"%3McF"

#: spec_violation findings listed one by one; past this, one more says how many were left out
MAX_VIOLATIONS = 25

_COLOR = re.compile(r"#[0-9A-Fa-f]{6}([0-9A-Fa-f]{2})?\Z")
_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")
_START_TAG = re.compile(rb"<(?![?!])[^\s/>]+((?:\s+[^\s=/>]+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*)\s*/?>")
_XMLNS = re.compile(rb"""\sxmlns(?::([^\s=]+))?\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_ENCODING = re.compile(rb"""^<\?xml[^>]*?\sencoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_COMMENT_OR_CDATA = re.compile(rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>", re.S)

C = "{%s}" % NS_CORE
M = "{%s}" % NS_MAT

#: resource element tag -> kind
RESOURCE_KINDS = {
    C + "object": "object", C + "basematerials": "base", M + "colorgroup": "color", M + "texture2d": "texture",
    M + "texture2dgroup": "tex", M + "compositematerials": "composite", M + "multiproperties": "multi",
}
#: kinds a pid may name
PROPERTY_GROUPS = frozenset({"base", "color", "tex", "composite", "multi"})
KIND_NAMES = {"object": "an object", "base": "a <basematerials>", "color": "a <colorgroup>",
              "texture": "a <texture2d>", "tex": "a <texture2dgroup>", "composite": "a <compositematerials>",
              "multi": "a <multiproperties>"}


def _kind_name(kind: str) -> str:
    return KIND_NAMES.get(kind, f"a <{kind}>")


# -- cheap scans before parsing ---------------------------------------------------------------


def xml_too_deep(data: bytes, limit: int) -> int | None:
    """The nesting depth of ``data`` if it is over ``limit``, else None, without parsing it.

    A numpy pass over the ``<`` positions: ``</`` closes, ``<?``/``<!``
    neither, ``<name .../>`` neither, any other ``<`` opens (comments and
    CDATA sections are cut out first). An attribute value holding ``>``
    can only make the estimate deeper, never shallower, and no real 3MF
    comes near the limit. Cost: a few milliseconds per megabyte.
    """
    if data.count(b"<") <= limit:
        return None
    if b"<!--" in data or b"<![CDATA[" in data:
        data = _COMMENT_OR_CDATA.sub(b"", data)
    buf = np.frombuffer(data, np.uint8)
    lt = np.flatnonzero(buf == 60)
    if len(lt) <= limit:
        return None
    gt = np.flatnonzero(buf == 62)
    nxt = buf[np.minimum(lt + 1, len(buf) - 1)]
    close = np.searchsorted(gt, lt)
    before_gt = np.where(close < len(gt), buf[gt[np.minimum(close, len(gt) - 1)] - 1], 0)
    step = np.where(nxt == 47, -1, np.where((nxt == 63) | (nxt == 33) | (before_gt == 47), 0, 1)).astype(np.int32)
    depth = int(np.cumsum(step).max())
    return depth if depth > limit else None


def root_namespaces(data: bytes) -> dict[str, str]:
    """Prefix -> namespace URI declared on the root element's start tag ('' for the default namespace).

    ElementTree keeps no prefixes, and ``requiredextensions`` and metadata
    names are written with them; the root's start tag is read with a regex
    after skipping the XML declaration, comments and processing instructions.
    """
    head = data[: 1 << 16]
    pos = 0
    while True:
        pos = head.find(b"<", pos)
        if pos < 0:
            return {}
        if head.startswith(b"<!--", pos):
            end = head.find(b"-->", pos)
        elif head.startswith(b"<?", pos):
            end = head.find(b"?>", pos)
        elif head.startswith(b"<!", pos):
            end = head.find(b">", pos)
        else:
            break
        if end < 0:
            return {}
        pos = end + 1
    m = _START_TAG.match(head, pos)
    if m is None:
        return {}
    out: dict[str, str] = {}
    for x in _XMLNS.finditer(m.group(0)):
        prefix = (x.group(1) or b"").decode("utf-8", "replace")
        uri = (x.group(2) if x.group(2) is not None else x.group(3) or b"").decode("utf-8", "replace")
        out[prefix] = uri
    return out


def declared_encoding(data: bytes) -> str | None:
    """The encoding an XML declaration names (None: none named); a BOM other than UTF-8's counts as its encoding."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    elif data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "UTF-16"
    elif data[:4] in (b"\x00\x00\xfe\xff", b"\xff\xfe\x00\x00"):
        return "UTF-32"
    m = _ENCODING.match(data[:512])
    return m.group(1).decode("ascii") if m else None


# -- the rules --------------------------------------------------------------------------------


@dataclass
class Relationship:
    source: str  # the source part ('' for the package)
    rid: str
    type: str
    target: str | None  # the resolved part name, None when it leaves the package
    raw_target: str
    external: bool


@dataclass
class Package:
    """What the OPC layer says: the start part, content types, relationships, encrypted parts."""

    start: str | None = None
    defaults: dict[str, str] = field(default_factory=dict)  # extension (lower) -> content type
    overrides: dict[str, str] = field(default_factory=dict)  # part name (lower, no leading '/') -> content type
    rels: list[Relationship] = field(default_factory=list)
    encrypted: set[str] = field(default_factory=set)  # part names (lower)
    has_keystore: bool = False

    def content_type(self, part: str) -> str | None:
        key = part.lower().lstrip("/")
        if key in self.overrides:
            return self.overrides[key]
        ext = key.rsplit(".", 1)[-1] if "." in key.rsplit("/", 1)[-1] else ""
        return self.defaults.get(ext)


class Rules:
    """Collects ``spec_violation`` findings while the 3MF reader reads a package."""

    def __init__(self, zf: SafeZip) -> None:
        self.zf = zf
        self.findings: list[Finding] = []
        self._dropped = 0
        self.notes: list[Finding] = []  # warnings and information that are not violations
        self.package = Package()

    # ---- reporting
    def violation(self, message: str, where: dict[str, Any] | None = None, *, warning: bool = False) -> None:
        """A broken MUST (an error; ``warning`` for one that printer software, lib3mf included, reads anyway)."""
        if len(self.findings) >= MAX_VIOLATIONS:
            self._dropped += 1
            return
        self.findings.append(finding("spec_violation", message, where=where, severity="warning" if warning else None))

    def done(self) -> list[Finding]:
        """The findings, with one saying how many were left out past :data:`MAX_VIOLATIONS`."""
        out = list(self.findings)
        if self._dropped:
            out.append(finding("spec_violation", f"and {self._dropped:,} more violations of the 3MF specification "
                                                 "of the kinds above (only the first ones are listed)"))
        return out + self.notes

    # ---- OPC package (core 2.1)
    def read_package(self) -> Package:
        """Content types and relationships; sets :attr:`Package.start` (the model part to read)."""
        pk = self.package
        zf = self.zf
        if zf.has("[Content_Types].xml"):
            root = parse_xml(zf.read("[Content_Types].xml", 1 << 20, "content types"), "[Content_Types].xml", 1 << 20)
            for el in root:
                if el.tag == "{%s}Default" % NS_TYPES and el.get("Extension") is not None:
                    pk.defaults[el.get("Extension", "").lower()] = (el.get("ContentType") or "").strip().lower()
                elif el.tag == "{%s}Override" % NS_TYPES and el.get("PartName") is not None:
                    pk.overrides[el.get("PartName", "").lower().lstrip("/")] = (el.get("ContentType") or "").strip().lower()
        else:
            self.violation("the package has no [Content_Types].xml, which every OPC package (and so every 3MF) "
                           "needs (core 2.1); re-export the file")
        rel_files = [n for n in zf.entry_names() if re.fullmatch(r"(?:.*/)?_rels/[^/]*\.rels", n, re.I)]
        for name in sorted(rel_files, key=lambda n: (n.lower() != "_rels/.rels", n.lower()))[:64]:
            folder, base = name.rsplit("_rels/", 1)
            source = (folder + base[: -len(".rels")]).strip("/") if base.lower() != ".rels" else ""
            self._read_rels(name, source)
        root_rels = [r for r in pk.rels if r.source == ""]
        models = [r for r in root_rels if r.type == REL_MODEL.lower()]
        if not zf.has("_rels/.rels"):
            self.violation("the package has no _rels/.rels, so no StartPart relationship names its 3D model part "
                           "(core 2.1.1); re-export the file")
        elif not models:
            self.violation("_rels/.rels has no StartPart relationship to a 3D model part (type "
                           f"{REL_MODEL}); the 3MF core spec 2.1.1 requires one: re-export the file")
        elif len(models) > 1:
            self.violation(f"_rels/.rels names {len(models)} 3D model parts "
                           f"({', '.join(repr(r.raw_target) for r in models[:4])}); a 3MF has exactly one "
                           "StartPart relationship (core 2.1.1): keep one, and reach other model parts through it")
        if models:
            m = models[0]
            if m.target is None:
                raise ReadError("archive_unsafe_path", f"the 3MF start part {m.raw_target!r} escapes the archive")
            pk.start = m.target
        else:
            pk.start = next((n for n in zf.entry_names() if n.lower().endswith(".model")), None)
        if pk.start is None:
            raise ReadError("malformed", "the archive has no 3MF model part (is it a 3MF at all?)")
        ct = pk.content_type(pk.start)
        if zf.has(pk.start) and ct is not None and ct != CT_MODEL:
            self.violation(f"the model part {pk.start!r} has content type {ct!r} in [Content_Types].xml, not "
                           f"{CT_MODEL!r} (core 2.1.2, Appendix C)")
        pk.has_keystore = any(r.type in REL_KEYSTORE for r in root_rels)
        return pk

    def _read_rels(self, name: str, source: str) -> None:
        pk = self.package
        root = parse_xml(self.zf.read(name, 1 << 20, "relationships"), name, 1 << 20, 100_000)
        ids: set[str] = set()
        pairs: set[tuple[str, str]] = set()
        tickets = 0
        for el in root.iter("{%s}Relationship" % NS_RELS):
            rid, rtype, target = el.get("Id", ""), (el.get("Type") or "").strip().rstrip("/"), el.get("Target") or ""
            if rid in ids:
                self.violation(f"{name}: relationship id {rid!r} is used twice; OPC relationship ids are unique "
                               "within their part: rename one")
            ids.add(rid)
            external = (el.get("TargetMode") or "").lower() == "external" or bool(_SCHEME.match(target)) \
                or target.startswith("//")
            resolved = None if external else zip_join("/" + source if source else "/", target)
            rel = Relationship(source, rid, rtype.lower(), resolved, target, external)
            pk.rels.append(rel)
            if external or resolved is None:
                self.violation(f"{name}: relationship {rid!r} points outside the package ({target[:80]!r}); a 3MF "
                               "must not reference anything outside itself (core 2.1.1): put the part in the package",
                               where={"entry": name})
                continue
            key = (rel.type, resolved.lower())
            if key in pairs:
                self.violation(f"{name}: two relationships of type {rtype!r} to {target[:80]!r}; core 2.1.1 allows one")
            pairs.add(key)
            what = REL_MUST_EXIST.get(rel.type)
            if what is not None and rel.type != REL_MODEL.lower() and not self.zf.has(resolved):
                self.violation(f"{name}: the {what} relationship {rid!r} names {target[:80]!r}, which is not in the "
                               "package (core 2.1.1): add the part or remove the relationship",
                               where={"entry": name})
            if rel.type == REL_PRINTTICKET.lower():
                tickets += 1
                if not source.lower().endswith(".model"):
                    self.violation(f"{name}: a print ticket attached to {('/' + source) if source else 'the package'}; "
                                   "print tickets attach only to a 3D model part (core 2.1.4)")
            if rel.type == REL_THUMBNAIL.lower() and self.zf.has(resolved):
                ct = self.package.content_type(resolved)
                if ct is not None and ct not in ("image/png", "image/jpeg"):
                    self.violation(f"the thumbnail {target[:80]!r} has content type {ct!r}; thumbnails are PNG or "
                                   "JPEG (core 2.1.3)")
            if rel.type == REL_ENCRYPTED:
                pk.encrypted.add(resolved.lower())
        if tickets > 1:
            self.violation(f"{name}: {tickets} print tickets for one model part; core 2.1.4 allows at most one")

    def check_encrypted(self, part: str, data: bytes, what: str = "model part") -> None:
        """Refuse (``unsupported_format``) a part encrypted with the Secure Content extension."""
        if data[:5] == CIPHER_MAGIC or part.lower().lstrip("/") in self.package.encrypted:
            raise ReadError(
                "unsupported_format",
                f"the 3MF's {what} {part!r} is encrypted (3MF Secure Content extension); the checker cannot "
                "decrypt it: check the unencrypted file, or have the printer software that holds the key check it",
            )

    # ---- XML (core 2.3)
    def xml_prolog(self, data: bytes, name: str) -> None:
        enc = declared_encoding(data)
        if enc is not None and enc.replace("_", "-").upper() not in ("UTF-8", "UTF8"):
            self.violation(f"{name}: the XML is declared as {enc}; 3MF XML must be UTF-8 (core 2.3.2): re-save it as UTF-8")

    def xml_attributes(self, data: bytes, root: Any, name: str) -> None:
        """``xml:space`` and ``xsi:`` attributes (core 2.3.2, 2.3.4); the tree is walked only when the bytes hint at them."""
        space = b"xml:space" in data
        xsi = NS_XSI.encode() in data
        if not (space or xsi):
            return
        seen: set[str] = set()
        for el in root.iter():
            for a in el.attrib:
                if a == "{%s}space" % NS_XML and "space" not in seen:
                    seen.add("space")
                    self.violation(f"{name}: <{_local(el.tag)}> has an xml:space attribute, which 3MF markup must not "
                                   "use (core 2.3.4): remove it")
                elif a.startswith("{%s}" % NS_XSI) and "xsi" not in seen:
                    seen.add("xsi")
                    self.violation(f"{name}: <{_local(el.tag)}> has an attribute from the xsi namespace "
                                   f"({_local(a)}), which 3MF markup must not contain (core 2.3.2): remove it")

    # ---- model (core 3.4)
    def model(self, name: str, root: Any, ns: dict[str, str]) -> None:
        """Required extensions (unsupported: unreadable) and metadata."""
        req = (root.get("requiredextensions") or "").split()
        for prefix in req:
            uri = ns.get(prefix)
            if uri is None:
                raise ReadError("unsupported_format",
                                f"{name} requires the extension with prefix {prefix!r}, which its <model> does not "
                                "declare as a namespace, so the checker cannot tell what it needs (core 3.4)")
            if uri not in SUPPORTED_EXTENSIONS:
                ext = KNOWN_EXTENSIONS.get(uri, "an extension")
                raise ReadError("unsupported_format",
                                f"the 3MF requires the {ext} extension ({uri}), which the checker does not read; "
                                "a reader without it must not process the file (core 3.4): check it with software "
                                "that supports the extension, or export it without")
        for prefix in (root.get("recommendedextensions") or "").split():
            uri = ns.get(prefix, "")
            if uri not in SUPPORTED_EXTENSIONS:
                self.notes.append(finding(
                    "ignored_content",
                    f"the 3MF recommends the {KNOWN_EXTENSIONS.get(uri, 'extension')} {uri or repr(prefix)}, which "
                    "the checker does not read: what it adds was not checked"))
        metas = [el for el in root if el.tag == C + "metadata"]
        self._metadata(name, metas, ns, "the model")

    def _metadata(self, name: str, metas: list[Any], ns: dict[str, str], owner: str) -> None:
        seen: set[str] = set()
        for el in metas:
            key = el.get("name")
            if key is None or not key.strip():
                self.violation(f"{name}: a <metadata> element of {owner} has no name (core 3.4.1): name it, or "
                               "remove it")
                continue
            key = key.strip()
            if ":" in key:
                prefix = key.split(":", 1)[0]
                if prefix not in ns:
                    self.violation(f"{name}: metadata {key[:60]!r} uses the prefix {prefix!r}, which the <model> does "
                                   "not declare (core 3.4.1): declare the vendor namespace on <model>")
            elif key not in WELL_KNOWN_METADATA:
                self.violation(f"{name}: metadata {key[:60]!r} is neither a name the 3MF core spec defines "
                               f"({', '.join(sorted(WELL_KNOWN_METADATA))}) nor prefixed with a vendor namespace "
                               "(core 3.4.1): prefix it (vendor:Name, with xmlns:vendor on <model>) or remove it")
            if key in seen:
                self.violation(f"{name}: metadata {key[:60]!r} appears twice in {owner}; names are unique "
                               "(core 3.4.1): keep one")
            seen.add(key)

    # ---- resources (core 3.4.2, 4, 5; Materials 2-6)
    def resources(self, p: Any, res: Any) -> None:
        """Ids, references and the Materials extension's rules over one model part's ``<resources>``.

        ``p`` is the reader's part (``objects``, ``groups``, ``meshes``);
        rules on triangles use the property arrays the reader already made.
        """
        name = p.name
        kinds: dict[int, tuple[str, int]] = {}  # id -> (kind, position); the first definition
        for pos, el in enumerate(res):
            rid_s = el.get("id")
            kind = RESOURCE_KINDS.get(el.tag, _local(el.tag))
            if rid_s is None:
                if el.tag in RESOURCE_KINDS:
                    self.violation(f"{name}: a <{_local(el.tag)}> has no id (core 3.4.2): give it a unique id")
                continue
            try:
                rid = int(rid_s)
            except ValueError:
                continue  # the reader reports a bad id
            if rid in kinds:
                first = kinds[rid][0]
                self.violation(f"{name}: resource id {rid} is used by {_kind_name(first)} and again by "
                               f"{_kind_name(kind)}; resource ids are unique within a model (core 3.4.2): renumber "
                               "one and its references", where={"entry": name})
                continue
            kinds[rid] = (kind, pos)
        sizes = {gid: g.size for gid, g in p.groups.items()}

        def ref(rid: int | None, pos: int, what: str, allowed: frozenset[str] | set[str], attr: str,
                section: str) -> str | None:
            """Check a reference: it names a resource of an allowed kind defined before it; the kind, or None."""
            if rid is None:
                return None
            hit = kinds.get(rid)
            want = " or ".join(_kind_name(k) for k in sorted(allowed))
            if hit is None:
                self.violation(f"{name}: {what} {attr}={rid} names no resource; it must name {want} ({section})")
                return None
            kind, at = hit
            if kind not in allowed:
                self.violation(f"{name}: {what} {attr}={rid} names {_kind_name(kind)}; it must name {want} "
                               f"({section}): point it at the right resource")
                return None
            if at > pos:
                self.violation(f"{name}: {what} refers to resource {rid} before it is defined; 3MF is read forward "
                               "only, so define resources before their first use (core 3.4)")
            return kind

        for pos, el in enumerate(res):
            tag = el.tag
            rid = _int(el.get("id"))
            if tag == C + "basematerials":
                for i, b in enumerate(c for c in el if c.tag == C + "base"):
                    if not (b.get("name") or "").strip():
                        self.violation(f"{name}: base material {i} of <basematerials> {rid} has no name (core 5.1)")
                    self._colour(name, b.get("displaycolor"), f"base material {i} of <basematerials> {rid}",
                                 "displaycolor", "core 5.1.1")
            elif tag == M + "colorgroup":
                for i, c in enumerate(c for c in el if c.tag == M + "color"):
                    self._colour(name, c.get("color"), f"colour {i} of <colorgroup> {rid}", "color", "Materials 2.1")
            elif tag == M + "texture2d":
                self._texture2d(name, el, rid)
            elif tag == M + "texture2dgroup":
                texid = _int(el.get("texid"))
                if el.get("texid") is None:
                    self.violation(f"{name}: <texture2dgroup> {rid} has no texid naming its <texture2d> (Materials 3): "
                                   "add texid")
                else:
                    ref(texid, pos, f"<texture2dgroup> {rid}", {"texture"}, "texid", "Materials 3")
            elif tag == M + "compositematerials":
                self._composite(name, el, rid, pos, ref, sizes)
            elif tag == M + "multiproperties":
                self._multi(name, el, rid, pos, ref, sizes, kinds)
            elif tag == C + "object":
                self._object(p, el, rid, pos, ref, sizes, kinds)

    def _colour(self, name: str, value: str | None, what: str, attr: str, section: str) -> None:
        if value is None:
            self.violation(f"{name}: {what} has no {attr} ({section}): give it a colour such as #RRGGBB")
        elif not _COLOR.match(value.strip()):
            self.violation(f"{name}: {what} has {attr}={value[:20]!r}, not a colour #RRGGBB or #RRGGBBAA ({section})")

    def _texture2d(self, name: str, el: Any, rid: int | None) -> None:
        what = f"<texture2d> {rid}"
        path = el.get("path")
        ct = (el.get("contenttype") or "").strip().lower()
        if el.get("contenttype") is None or ct not in CT_TEXTURE_ATTR:
            self.violation(f"{name}: {what} has contenttype={el.get('contenttype')!r}; it must be image/png or "
                           "image/jpeg (Materials 6): set the image's type")
        if not (path or "").strip():
            self.violation(f"{name}: {what} has no path naming its image part (Materials 6): add the path")
        else:
            target = zip_join("/", path)
            if target is not None and self.zf.has(target):
                related = any(r.type == REL_TEXTURE and r.target is not None and r.target.lower() == target.lower()
                              and r.source.lower().endswith(".model") for r in self.package.rels)
                if not related:
                    self.violation(f"{name}: the texture {path[:80]!r} is not the target of a 3D texture relationship "
                                   "from the model part (Materials 6, core 2.1): add <Relationship Type=\""
                                   f"{REL_TEXTURE}\" Target=\"{target and '/' + target}\"/> to the model's .rels part")
                pct = self.package.content_type(target)
                if pct is None:
                    self.violation(f"{name}: the texture {path[:80]!r} has no content type in [Content_Types].xml "
                                   "(core 2.1): add a Default for its extension")
                elif pct not in CT_TEXTURE_PARTS:
                    self.violation(f"{name}: the texture {path[:80]!r} has content type {pct!r} in "
                                   "[Content_Types].xml; textures are image/png or image/jpeg (Materials 6)")
        for attr, allowed in (("tilestyleu", TILE_STYLES), ("tilestylev", TILE_STYLES), ("filter", FILTERS)):
            v = el.get(attr)
            if v is not None and v.strip() not in allowed:
                self.violation(f"{name}: {what} has {attr}={v[:20]!r}, not one of {', '.join(sorted(allowed))} "
                               "(Materials 6)")

    def _composite(self, name: str, el: Any, rid: int | None, pos: int, ref: Any, sizes: dict[int, int]) -> None:
        what = f"<compositematerials> {rid}"
        if el.get("matid") is None:
            self.violation(f"{name}: {what} has no matid naming the <basematerials> it mixes (Materials 4): add it")
            base = None
        else:
            base = _int(el.get("matid"))
            if ref(base, pos, what, {"base"}, "matid", "Materials 4") is None:
                base = None
        raw = el.get("matindices")
        idx = _ints(raw)
        if raw is None:
            self.violation(f"{name}: {what} has no matindices listing the base materials it mixes (Materials 4): "
                           "add them")
        elif idx is None or not idx:
            self.violation(f"{name}: {what} matindices={raw[:40]!r} is not a list of indices (Materials 4)")
        elif base is not None and base in sizes and max(idx) >= sizes[base]:
            self.violation(f"{name}: {what} mixes base material {max(idx)} of <basematerials> {base}, which has "
                           f"{sizes[base]} (Materials 4)")
        comps = [c for c in el if c.tag == M + "composite"]
        if not comps:
            self.violation(f"{name}: {what} has no <composite> elements (Materials 4)")
        for i, c in enumerate(comps):
            vals = _floats(c.get("values"))
            if vals is None:
                self.violation(f"{name}: composite {i} of {what} has values={c.get('values')!r}, not a list of "
                               "numbers (Materials 4.1)")
                break
            if any(not (0.0 <= v <= 1.0) for v in vals):
                self.violation(f"{name}: composite {i} of {what} has a value outside [0, 1] (Materials 4.1)")
                break

    def _multi(self, name: str, el: Any, rid: int | None, pos: int, ref: Any, sizes: dict[int, int],
               kinds: dict[int, tuple[str, int]]) -> None:
        what = f"<multiproperties> {rid}"
        raw = el.get("pids")
        pids = _ints(raw)
        if raw is None or not pids:
            self.violation(f"{name}: {what} has no pids listing the property groups it layers (Materials 5): add them")
            return
        if pids is None:
            self.violation(f"{name}: {what} pids={raw[:40]!r} is not a list of resource ids (Materials 5)")
            return
        layer_kinds: list[str | None] = []
        for j, pid in enumerate(pids):
            hit = kinds.get(pid)
            if hit is not None and hit[0] == "multi":
                self.violation(f"{name}: {what} layers <multiproperties> {pid}; multiproperties must not contain "
                               "multiproperties (Materials 5): list that group's own layers instead")
                layer_kinds.append(None)
                continue
            layer_kinds.append(ref(pid, pos, f"{what} (layer {j})", {"base", "composite", "color", "tex"}, "pids",
                                   "Materials 5: pids lists property groups"))
        materials = [k for k in layer_kinds if k in ("base", "composite")]
        if len(materials) > 1:
            self.violation(f"{name}: {what} layers {len(materials)} materials (base or composite); a multiproperties "
                           "holds at most one (Materials 5): keep one material layer")
        elif materials and layer_kinds[0] not in ("base", "composite"):
            self.violation(f"{name}: {what} has its material layer after a colour layer; the material must be the "
                           "first layer (Materials 5): move it to the front of pids")
        if layer_kinds.count("color") > 1:
            self.violation(f"{name}: {what} layers {layer_kinds.count('color')} colour groups; a multiproperties holds "
                           "at most one (Materials 5): merge them or use a texture layer")
        blends = (el.get("blendmethods") or "").split()
        if len(blends) > max(len(pids) - 1, 0):
            self.violation(f"{name}: {what} has {len(blends)} blendmethods for {len(pids)} layers; at most one per "
                           "layer after the first (Materials 5)")
        bad = [b for b in blends if b not in BLEND_METHODS]
        if bad:
            self.violation(f"{name}: {what} blend method {bad[0][:20]!r} is not mix or multiply (Materials 5)")
        multis = [c for c in el if c.tag == M + "multi"]
        if not multis:
            self.violation(f"{name}: {what} has no <multi> elements (Materials 5)")
        for i, c in enumerate(multis):
            raw_i = c.get("pindices")
            idx = _ints(raw_i) if raw_i is not None else None
            if raw_i is None or idx is None:
                self.violation(f"{name}: <multi> {i} of {what} has pindices={raw_i!r}, not a list of indices "
                               "(Materials 5.1)")
                break
            over = [(j, k) for j, k in enumerate(idx[: len(pids)])
                    if layer_kinds[j] is not None and pids[j] in sizes and k >= sizes[pids[j]]]
            if over:
                j, k = over[0]
                self.violation(f"{name}: <multi> {i} of {what} uses entry {k} of {_kind_name(str(layer_kinds[j]))[2:]} "
                               f"{pids[j]}, which has {sizes[pids[j]]} (valid 0..{sizes[pids[j]] - 1}; Materials 5.1)")
                break

    def _object(self, p: Any, el: Any, oid: int | None, pos: int, ref: Any, sizes: dict[int, int],
                kinds: dict[int, tuple[str, int]]) -> None:
        name = p.name
        what = f"object {oid}"
        otype = el.get("type", "model")
        if otype not in OBJECT_TYPES:
            self.violation(f"{name}: {what} has type={otype[:30]!r}, not one of {', '.join(sorted(OBJECT_TYPES))} "
                           "(core 4)")
        pid_s, pindex_s = el.get("pid"), el.get("pindex")
        comps = el.find(C + "components")
        if comps is not None:
            if pid_s is not None or pindex_s is not None:
                self.violation(f"{name}: {what} has components and a pid/pindex; objects made of components carry "
                               "no properties (core 4): move them to the component objects")
            for c in comps:
                if c.tag == C + "component" and not c.get("{%s}path" % NS_PROD):
                    ref(_int(c.get("objectid")), pos, f"a component of {what}", {"object"}, "objectid", "core 4.2.1")
        if pindex_s is not None and pid_s is None:
            self.violation(f"{name}: {what} has pindex but no pid; pid is required with pindex (core 4): name the "
                           "property group")
        gkind = ref(_int(pid_s), pos, what, PROPERTY_GROUPS, "pid", "core 4") if pid_s is not None else None
        mesh = p.meshes.get(oid) if oid is not None else None
        if mesh is None or mesh[2] is None:
            return
        props = mesh[2]  # (m, 4): pid, p1, p2, p3, -1 where absent
        # core 4 also says an object whose triangles carry properties MUST name a default pid/pindex; the
        # Consortium's own examples break that and lib3mf reads them, and it changes nothing printed: not checked
        tri_pids = np.unique(props[:, 0][props[:, 0] >= 0])
        for g in tri_pids[:64]:
            ref(int(g), pos, f"a triangle of {what}", PROPERTY_GROUPS, "pid", "core 4.1.4.1")
        base_ids = [g for g, (k, _) in kinds.items() if k == "base"]
        if base_ids:
            eff = np.where(props[:, 0] >= 0, props[:, 0], _int(pid_s) if gkind == "base" else -1)
            on_base = np.isin(eff, base_ids)
            p1 = props[:, 1]
            grad = on_base & (p1 >= 0) & (((props[:, 2] >= 0) & (props[:, 2] != p1)) | ((props[:, 3] >= 0) & (props[:, 3] != p1)))
            if grad.any():
                bad = np.flatnonzero(grad)
                self.violation(f"{name}: {int(grad.sum()):,} triangles of {what} blend base materials across "
                               "their corners (p1, p2, p3 differ); base materials form no gradients (core 4.1.4): "
                               "give each triangle one material, or use a composite", where={"faces": bad[:10].tolist()})

    # ---- build (core 3.4.3)
    def build_item(self, p: Any, oid: int, reach_other: str | None) -> None:
        if reach_other is not None:
            self.violation(f"{p.name}: build item for object {oid} outputs {reach_other}, of type 'other'; build "
                           "items must not reference objects of type other, directly or through components "
                           "(core 3.4.3.1): change its type or remove the item")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _int(v: str | None) -> int | None:
    if v is None:
        return None
    try:
        return int(v)
    except ValueError:
        return None


def _ints(v: str | None) -> list[int] | None:
    if v is None:
        return None
    try:
        out = [int(x) for x in v.split()[:100_000]]
    except ValueError:
        return None
    return None if any(x < 0 for x in out) else out


def _floats(v: str | None) -> list[float] | None:
    if v is None:
        return None
    try:
        return [float(x) for x in v.split()[:100_000]]
    except ValueError:
        return None
