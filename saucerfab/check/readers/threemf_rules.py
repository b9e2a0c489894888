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
  nesting depth bounded before parsing (:func:`.xmlscan.xml_too_deep`, a numpy scan:
  200,000 nested elements are refused in milliseconds, not parsed).
* **Model** (core 3.4): ``requiredextensions`` (unsupported: unreadable;
  :data:`.threemf_spec.SUPPORTED_EXTENSIONS`); metadata names present, well-known or
  prefixed with a declared namespace, not repeated.
* **Resources** (core 3.4.2, 4, 5; Materials 2-6): in
  :mod:`.threemf_resources`, reporting through :meth:`Rules.violation`.
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

from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers.safe import SafeZip, parse_xml, zip_join
from saucerfab.check.readers.threemf_spec import (
    CIPHER_MAGIC,
    CT_MODEL,
    KNOWN_EXTENSIONS,
    NS_RELS,
    NS_TYPES,
    NS_XML,
    NS_XSI,
    REL_ENCRYPTED,
    REL_KEYSTORE,
    REL_MODEL,
    REL_MUST_EXIST,
    REL_PRINTTICKET,
    REL_THUMBNAIL,
    SUPPORTED_EXTENSIONS,
    WELL_KNOWN_METADATA,
    C,
    local_name,
)
from saucerfab.check.readers.xmlscan import declared_encoding
from saucerfab.check.report import Finding, finding

#: spec_violation findings listed one by one; past this, one more says how many were left out
MAX_VIOLATIONS = 25

_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")



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
                    self.violation(f"{name}: <{local_name(el.tag)}> has an xml:space attribute, which 3MF markup must not "
                                   "use (core 2.3.4): remove it")
                elif a.startswith("{%s}" % NS_XSI) and "xsi" not in seen:
                    seen.add("xsi")
                    self.violation(f"{name}: <{local_name(el.tag)}> has an attribute from the xsi namespace "
                                   f"({local_name(a)}), which 3MF markup must not contain (core 2.3.2): remove it")

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

    # ---- build (core 3.4.3)
    def object_type_other(self, part: str, oid: int) -> None:
        """The build outputs object ``oid`` of ``part``, whose type is ``other``."""
        self.violation(
            f"{part}: the build outputs object {oid}, of type 'other'; build items must not reference objects "
            "of type other, directly or through components (core 3.4.3.1): change its type or remove the item")
