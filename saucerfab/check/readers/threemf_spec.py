"""The 3MF specifications' names: namespaces, relationship and content types, extensions, value sets.

Written once for the 3MF reader (:mod:`.threemf`) and its rule checks
(:mod:`.threemf_rules`, :mod:`.threemf_resources`): 3MF Core Specification
1.3 and the Materials and Properties Extension 1.2.
"""

from __future__ import annotations

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

#: ElementTree's ``{namespace}`` prefixes of core and Materials tags
C = "{%s}" % NS_CORE
M = "{%s}" % NS_MAT
P = "{%s}" % NS_PROD

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


def kind_name(kind: str) -> str:
    """A resource kind for messages: ``a <colorgroup>``."""
    return KIND_NAMES.get(kind, f"a <{kind}>")


def local_name(tag: str) -> str:
    """An ElementTree tag without its ``{namespace}``."""
    return tag.rsplit("}", 1)[-1]
