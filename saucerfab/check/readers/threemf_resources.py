"""The 3MF rules on ``<resources>``: ids, references, objects and the Materials extension.

Checked on what the bounded reader (:mod:`.threemf`) already parsed, each
broken MUST reported through :meth:`.threemf_rules.Rules.violation` as a
``spec_violation`` naming its section and the fix (core 3.4.2, 4, 5;
Materials 2-6): ids unique across every kind of resource in a model part;
references only to resources defined before them; object types;
``pid``/``pindex`` rules (``pindex`` needs ``pid``; objects with components
carry neither; base materials form no gradients); colours
``#RRGGBB``/``#RRGGBBAA``; base materials' names and colours; textures'
path and content type, tile styles and filter; texture groups' ``texid``;
composites (``matid`` a ``<basematerials>``, ``matindices`` in range,
values in [0, 1]); multiproperties (``pids`` present, naming property groups
defined before, at most one material and it first, at most one colour group,
no multiproperties; ``blendmethods``; ``pindices`` in range).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from saucerfab.check.readers.safe import zip_join
from saucerfab.check.readers.threemf_rules import Rules
from saucerfab.check.readers.threemf_spec import (
    BLEND_METHODS,
    CT_TEXTURE_ATTR,
    CT_TEXTURE_PARTS,
    FILTERS,
    NS_PROD,
    OBJECT_TYPES,
    PROPERTY_GROUPS,
    REL_TEXTURE,
    RESOURCE_KINDS,
    TILE_STYLES,
    C,
    M,
    kind_name,
    local_name,
)

_COLOR = re.compile(r"#[0-9A-Fa-f]{6}([0-9A-Fa-f]{2})?\Z")


def check_resources(rules: Rules, p: Any, res: Any) -> None:
    """Ids, references and the Materials extension's rules over one model part's ``<resources>``.

    ``p`` is the reader's part (``objects``, ``groups``, ``meshes``);
    rules on triangles use the property arrays the reader already made.
    """
    name = p.name
    kinds: dict[int, tuple[str, int]] = {}  # id -> (kind, position); the first definition
    for pos, el in enumerate(res):
        rid_s = el.get("id")
        kind = RESOURCE_KINDS.get(el.tag, local_name(el.tag))
        if rid_s is None:
            if el.tag in RESOURCE_KINDS:
                rules.violation(f"{name}: a <{local_name(el.tag)}> has no id (core 3.4.2): give it a unique id")
            continue
        try:
            rid = int(rid_s)
        except ValueError:
            continue  # the reader reports a bad id
        if rid in kinds:
            first = kinds[rid][0]
            rules.violation(f"{name}: resource id {rid} is used by {kind_name(first)} and again by "
                            f"{kind_name(kind)}; resource ids are unique within a model (core 3.4.2): renumber "
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
        want = " or ".join(kind_name(k) for k in sorted(allowed))
        if hit is None:
            rules.violation(f"{name}: {what} {attr}={rid} names no resource; it must name {want} ({section})")
            return None
        kind, at = hit
        if kind not in allowed:
            rules.violation(f"{name}: {what} {attr}={rid} names {kind_name(kind)}; it must name {want} "
                            f"({section}): point it at the right resource")
            return None
        if at > pos:
            rules.violation(f"{name}: {what} refers to resource {rid} before it is defined; 3MF is read forward "
                            "only, so define resources before their first use (core 3.4)")
        return kind

    for pos, el in enumerate(res):
        tag = el.tag
        rid = _int(el.get("id"))
        if tag == C + "basematerials":
            for i, b in enumerate(c for c in el if c.tag == C + "base"):
                if not (b.get("name") or "").strip():
                    rules.violation(f"{name}: base material {i} of <basematerials> {rid} has no name (core 5.1)")
                _colour(rules, name, b.get("displaycolor"), f"base material {i} of <basematerials> {rid}",
                        "displaycolor", "core 5.1.1")
        elif tag == M + "colorgroup":
            for i, c in enumerate(c for c in el if c.tag == M + "color"):
                _colour(rules, name, c.get("color"), f"colour {i} of <colorgroup> {rid}", "color", "Materials 2.1")
        elif tag == M + "texture2d":
            _texture2d(rules, name, el, rid)
        elif tag == M + "texture2dgroup":
            texid = _int(el.get("texid"))
            if el.get("texid") is None:
                rules.violation(f"{name}: <texture2dgroup> {rid} has no texid naming its <texture2d> (Materials 3): "
                                "add texid")
            else:
                ref(texid, pos, f"<texture2dgroup> {rid}", {"texture"}, "texid", "Materials 3")
        elif tag == M + "compositematerials":
            _composite(rules, name, el, rid, pos, ref, sizes)
        elif tag == M + "multiproperties":
            _multi(rules, name, el, rid, pos, ref, sizes, kinds)
        elif tag == C + "object":
            _object(rules, p, el, rid, pos, ref, sizes, kinds)


def _colour(rules: Rules, name: str, value: str | None, what: str, attr: str, section: str) -> None:
    if value is None:
        rules.violation(f"{name}: {what} has no {attr} ({section}): give it a colour such as #RRGGBB")
    elif not _COLOR.match(value.strip()):
        rules.violation(f"{name}: {what} has {attr}={value[:20]!r}, not a colour #RRGGBB or #RRGGBBAA ({section})")


def _texture2d(rules: Rules, name: str, el: Any, rid: int | None) -> None:
    what = f"<texture2d> {rid}"
    path = el.get("path")
    ct = (el.get("contenttype") or "").strip().lower()
    if el.get("contenttype") is None or ct not in CT_TEXTURE_ATTR:
        rules.violation(f"{name}: {what} has contenttype={el.get('contenttype')!r}; it must be image/png or "
                        "image/jpeg (Materials 6): set the image's type")
    if not (path or "").strip():
        rules.violation(f"{name}: {what} has no path naming its image part (Materials 6): add the path")
    else:
        target = zip_join("/", path)
        if target is not None and rules.zf.has(target):
            related = any(r.type == REL_TEXTURE and r.target is not None and r.target.lower() == target.lower()
                          and r.source.lower().endswith(".model") for r in rules.package.rels)
            if not related:
                rules.violation(f"{name}: the texture {path[:80]!r} is not the target of a 3D texture relationship "
                                "from the model part (Materials 6, core 2.1): add <Relationship Type=\""
                                f"{REL_TEXTURE}\" Target=\"{target and '/' + target}\"/> to the model's .rels part")
            pct = rules.package.content_type(target)
            if pct is None:
                rules.violation(f"{name}: the texture {path[:80]!r} has no content type in [Content_Types].xml "
                                "(core 2.1): add a Default for its extension")
            elif pct not in CT_TEXTURE_PARTS:
                rules.violation(f"{name}: the texture {path[:80]!r} has content type {pct!r} in "
                                "[Content_Types].xml; textures are image/png or image/jpeg (Materials 6)")
    for attr, allowed in (("tilestyleu", TILE_STYLES), ("tilestylev", TILE_STYLES), ("filter", FILTERS)):
        v = el.get(attr)
        if v is not None and v.strip() not in allowed:
            rules.violation(f"{name}: {what} has {attr}={v[:20]!r}, not one of {', '.join(sorted(allowed))} "
                            "(Materials 6)")


def _composite(rules: Rules, name: str, el: Any, rid: int | None, pos: int, ref: Any, sizes: dict[int, int]) -> None:
    what = f"<compositematerials> {rid}"
    if el.get("matid") is None:
        rules.violation(f"{name}: {what} has no matid naming the <basematerials> it mixes (Materials 4): add it")
        base = None
    else:
        base = _int(el.get("matid"))
        if ref(base, pos, what, {"base"}, "matid", "Materials 4") is None:
            base = None
    raw = el.get("matindices")
    idx = _ints(raw)
    if raw is None:
        rules.violation(f"{name}: {what} has no matindices listing the base materials it mixes (Materials 4): "
                        "add them")
    elif idx is None or not idx:
        rules.violation(f"{name}: {what} matindices={raw[:40]!r} is not a list of indices (Materials 4)")
    elif base is not None and base in sizes and max(idx) >= sizes[base]:
        rules.violation(f"{name}: {what} mixes base material {max(idx)} of <basematerials> {base}, which has "
                        f"{sizes[base]} (Materials 4)")
    comps = [c for c in el if c.tag == M + "composite"]
    if not comps:
        rules.violation(f"{name}: {what} has no <composite> elements (Materials 4)")
    for i, c in enumerate(comps):
        vals = _floats(c.get("values"))
        if vals is None:
            rules.violation(f"{name}: composite {i} of {what} has values={c.get('values')!r}, not a list of "
                            "numbers (Materials 4.1)")
            break
        if any(not (0.0 <= v <= 1.0) for v in vals):
            rules.violation(f"{name}: composite {i} of {what} has a value outside [0, 1] (Materials 4.1)")
            break


def _multi(rules: Rules, name: str, el: Any, rid: int | None, pos: int, ref: Any, sizes: dict[int, int],
           kinds: dict[int, tuple[str, int]]) -> None:
    what = f"<multiproperties> {rid}"
    raw = el.get("pids")
    pids = _ints(raw)
    if raw is None or not pids:
        rules.violation(f"{name}: {what} has no pids listing the property groups it layers (Materials 5): add them")
        return
    if pids is None:
        rules.violation(f"{name}: {what} pids={raw[:40]!r} is not a list of resource ids (Materials 5)")
        return
    layer_kinds: list[str | None] = []
    for j, pid in enumerate(pids):
        hit = kinds.get(pid)
        if hit is not None and hit[0] == "multi":
            rules.violation(f"{name}: {what} layers <multiproperties> {pid}; multiproperties must not contain "
                            "multiproperties (Materials 5): list that group's own layers instead")
            layer_kinds.append(None)
            continue
        layer_kinds.append(ref(pid, pos, f"{what} (layer {j})", {"base", "composite", "color", "tex"}, "pids",
                               "Materials 5: pids lists property groups"))
    materials = [k for k in layer_kinds if k in ("base", "composite")]
    if len(materials) > 1:
        rules.violation(f"{name}: {what} layers {len(materials)} materials (base or composite); a multiproperties "
                        "holds at most one (Materials 5): keep one material layer")
    elif materials and layer_kinds[0] not in ("base", "composite"):
        rules.violation(f"{name}: {what} has its material layer after a colour layer; the material must be the "
                        "first layer (Materials 5): move it to the front of pids")
    if layer_kinds.count("color") > 1:
        rules.violation(f"{name}: {what} layers {layer_kinds.count('color')} colour groups; a multiproperties holds "
                        "at most one (Materials 5): merge them or use a texture layer")
    blends = (el.get("blendmethods") or "").split()
    if len(blends) > max(len(pids) - 1, 0):
        rules.violation(f"{name}: {what} has {len(blends)} blendmethods for {len(pids)} layers; at most one per "
                        "layer after the first (Materials 5)")
    bad = [b for b in blends if b not in BLEND_METHODS]
    if bad:
        rules.violation(f"{name}: {what} blend method {bad[0][:20]!r} is not mix or multiply (Materials 5)")
    multis = [c for c in el if c.tag == M + "multi"]
    if not multis:
        rules.violation(f"{name}: {what} has no <multi> elements (Materials 5)")
    for i, c in enumerate(multis):
        raw_i = c.get("pindices")
        idx = _ints(raw_i) if raw_i is not None else None
        if raw_i is None or idx is None:
            rules.violation(f"{name}: <multi> {i} of {what} has pindices={raw_i!r}, not a list of indices "
                            "(Materials 5.1)")
            break
        over = [(j, k) for j, k in enumerate(idx[: len(pids)])
                if layer_kinds[j] is not None and pids[j] in sizes and k >= sizes[pids[j]]]
        if over:
            j, k = over[0]
            rules.violation(f"{name}: <multi> {i} of {what} uses entry {k} of {kind_name(str(layer_kinds[j]))[2:]} "
                            f"{pids[j]}, which has {sizes[pids[j]]} (valid 0..{sizes[pids[j]] - 1}; Materials 5.1)")
            break


def _object(rules: Rules, p: Any, el: Any, oid: int | None, pos: int, ref: Any, sizes: dict[int, int],
            kinds: dict[int, tuple[str, int]]) -> None:
    name = p.name
    what = f"object {oid}"
    otype = el.get("type", "model")
    if otype not in OBJECT_TYPES:
        rules.violation(f"{name}: {what} has type={otype[:30]!r}, not one of {', '.join(sorted(OBJECT_TYPES))} "
                        "(core 4)")
    pid_s, pindex_s = el.get("pid"), el.get("pindex")
    comps = el.find(C + "components")
    if comps is not None:
        if pid_s is not None or pindex_s is not None:
            rules.violation(f"{name}: {what} has components and a pid/pindex; objects made of components carry "
                            "no properties (core 4): move them to the component objects")
        for c in comps:
            if c.tag == C + "component" and not c.get("{%s}path" % NS_PROD):
                ref(_int(c.get("objectid")), pos, f"a component of {what}", {"object"}, "objectid", "core 4.2.1")
    if pindex_s is not None and pid_s is None:
        rules.violation(f"{name}: {what} has pindex but no pid; pid is required with pindex (core 4): name the "
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
            rules.violation(f"{name}: {int(grad.sum()):,} triangles of {what} blend base materials across "
                            "their corners (p1, p2, p3 differ); base materials form no gradients (core 4.1.4): "
                            "give each triangle one material, or use a composite", where={"faces": bad[:10].tolist()})

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
