"""3MF writer: core mesh + Materials and Properties extension (texture2d, texture2dgroup).

Written by hand because trimesh's 3MF writer drops colour. Package layout
(Open Packaging Conventions)::

    [Content_Types].xml
    _rels/.rels                      -> /3D/3dmodel.model (StartPart)
    3D/3dmodel.model                 unit="millimeter", one object, one build item
    3D/_rels/3dmodel.model.rels      -> the texture (3dtexture relationship)
    3D/Textures/<name>.png

The object's default property is the texture2dgroup; every triangle names
its corners' texture coordinates with ``p1 p2 p3`` (indices into the
group). 3MF texture coordinates have (0, 0) at the image's bottom left, as
saucerfab's do. The materials namespace is declared but not *required*, so
a consumer without colour support (PrusaSlicer) still loads the geometry.
Vertices are in the positive octant (the file frame of ``scene.json``).
"""

from __future__ import annotations

from xml.sax.saxutils import escape, quoteattr

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, deterministic_zip, fmt_rows, generator

NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_MATERIAL = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02"
REL_MODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
REL_TEXTURE = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dtexture"
CT_MODEL = "application/vnd.ms-package.3dmanufacturing-3dmodel+xml"
CT_RELS = "application/vnd.openxmlformats-package.relationships+xml"
CT_TEXTURE = "application/vnd.ms-package.3dmanufacturing-3dmodeltexture"

#: decimals of texture coordinates: 1e-7 of a 16384 px page is 0.002 px
UV_DECIMALS = 7


def content_types() -> str:
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
        f'<Default Extension="rels" ContentType="{CT_RELS}"/>'
        f'<Default Extension="model" ContentType="{CT_MODEL}"/>'
        f'<Default Extension="png" ContentType="{CT_TEXTURE}"/>'
        "</Types>\n"
    )


def _rels(target: str, rel_type: str, rel_id: str) -> str:
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
        f'<Relationship Target="{target}" Id="{rel_id}" Type="{rel_type}"/>'
        "</Relationships>\n"
    )


def model_xml(mesh: TexturedMesh, texture_path: str) -> str:
    """The ``3D/3dmodel.model`` document."""
    tex_id, group_id, obj_id = 1, 2, 3
    out: list[str] = [
        '<?xml version="1.0" encoding="UTF-8"?>\n',
        f'<model unit="millimeter" xml:lang="en-US" xmlns="{NS_CORE}" xmlns:m="{NS_MATERIAL}">\n',
        f' <metadata name="Title">{escape(mesh.name)}</metadata>\n',
        f' <metadata name="Application">{escape(generator())}</metadata>\n',
        " <resources>\n",
        f'  <m:texture2d id="{tex_id}" path={quoteattr(texture_path)} contenttype="image/png" '
        'tilestyleu="clamp" tilestylev="clamp" filter="linear"/>\n',
        f'  <m:texture2dgroup id="{group_id}" texid="{tex_id}">\n',
    ]
    out.extend(fmt_rows(mesh.uvs, UV_DECIMALS, template='   <m:tex2coord u="{}" v="{}"/>\n'))
    out.append("  </m:texture2dgroup>\n")
    out.append(
        f'  <object id="{obj_id}" type="model" name={quoteattr(mesh.name)} pid="{group_id}" pindex="0">\n'
        "   <mesh>\n    <vertices>\n"
    )
    out.extend(fmt_rows(mesh.vertices, mesh.decimals, template='     <vertex x="{}" y="{}" z="{}"/>\n'))
    out.append("    </vertices>\n    <triangles>\n")
    # pid on every triangle: the spec lets it default to the object's, but
    # lib3mf (and so GrabCAD-era readers built on it) then ignore p1..p3
    tri = f'     <triangle v1="{{}}" v2="{{}}" v3="{{}}" pid="{group_id}" p1="{{}}" p2="{{}}" p3="{{}}"/>\n'
    rows = [(*f, *t) for f, t in zip(mesh.faces.tolist(), mesh.face_uvs.tolist())]
    out.extend(tri.format(*r) for r in rows)
    out.append("    </triangles>\n   </mesh>\n  </object>\n </resources>\n")
    out.append(f' <build>\n  <item objectid="{obj_id}"/>\n </build>\n</model>\n')
    return "".join(out)


def write_3mf(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """The ``<name>.3mf`` package as bytes (one entry in the returned dict); no option changes it."""
    texture_path = f"/3D/Textures/{mesh.texture_name}"
    data = deterministic_zip(
        [
            ("[Content_Types].xml", content_types().encode(), True),
            ("_rels/.rels", _rels("/3D/3dmodel.model", REL_MODEL, "rel0").encode(), True),
            ("3D/3dmodel.model", model_xml(mesh, texture_path).encode(), True),
            ("3D/_rels/3dmodel.model.rels", _rels(texture_path, REL_TEXTURE, "rel1").encode(), True),
            (texture_path.lstrip("/"), mesh.texture_png, False),
        ]
    )
    return {f"{mesh.name}.3mf": data}
