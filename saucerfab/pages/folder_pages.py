"""``report.html``: one self-contained page per design folder and per print folder.

Each page is a pure function of its folder's files, so any command that
changes a folder rewrites the page (``design`` writes the design's,
``export`` and ``verify`` the print's). Pictures are inlined as data URIs
and the 3D view (:func:`saucerfab.pages.viewer.viewer_html`) carries three.js and
the model inline, so the page opens from disk with no network access.

* design report: the inputs as meant, masks and enhanced targets, the
  optimizer's views and composite, the height change, the energies and the
  stage table, the physical size, where to stand, and the saucer in 3D
  (its top surface, as designed);
* print report: the printer, files and sizes, where to stand, the verified
  views from every eye (ray-traced from the files, with their references
  and difference maps), the printability findings, and the printed part in
  3D read back from its file, with the mirror cup.
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, get_args

import numpy as np

from saucerfab.check.report import Severity
from saucerfab.files.imageio import png_bytes
from saucerfab.pages.html import Section, html_report
from saucerfab.pages.labels import design_name, energy_label, method_text, stage_label, stop_label

if TYPE_CHECKING:
    from saucerfab.fabricate.scene_file import PrintScene
    from saucerfab.model.design import Design

REPORT_NAME = "report.html"
#: texture edge of the 3D view's model (the page stays a few MB)
VIEWER_TEXTURE_PX = 1024
#: largest JSON file a report reads (verify.json, check.json)
_MAX_JSON_BYTES = 8 << 20
#: largest picture a report inlines
_MAX_PICTURE_BYTES = 16 << 20


#: the last few pictures :func:`_png` encoded, by content: ``saucerfab design`` writes
#: the design's page, then again with the quick verify's results, and the 3D view's
#: texture and the reference pictures are the same both times (about 0.15 s of encoding)
_PNG_CACHE: "OrderedDict[tuple[bytes, tuple[int, ...], int | None], bytes]" = OrderedDict()
_PNG_CACHE_ENTRIES = 8
_PNG_CACHE_LOCK = threading.Lock()  # pages may be written from several threads (the studio runs jobs on one)


def _png(rgb: np.ndarray, max_px: int | None = None) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 picture, resized to ``max_px`` square when larger."""
    from PIL import Image

    rgb = np.ascontiguousarray(rgb, np.uint8)
    key = (hashlib.blake2b(rgb.data, digest_size=20).digest(), rgb.shape, max_px)
    with _PNG_CACHE_LOCK:
        if key in _PNG_CACHE:
            _PNG_CACHE.move_to_end(key)
            return _PNG_CACHE[key]
    if max_px is not None and max(rgb.shape[:2]) > max_px:
        rgb = np.asarray(Image.fromarray(rgb).resize((max_px, max_px), Image.Resampling.LANCZOS))
    data = png_bytes(rgb)
    with _PNG_CACHE_LOCK:
        _PNG_CACHE[key] = data
        while len(_PNG_CACHE) > _PNG_CACHE_ENTRIES:
            _PNG_CACHE.popitem(last=False)
    return data


def _read(path: Path, cap: int) -> bytes | None:
    """A file's bytes if it exists and is at most ``cap`` bytes, else None."""
    try:
        if not path.is_file() or path.stat().st_size > cap:
            return None
        return path.read_bytes()
    except OSError:
        return None


def _json(path: Path) -> dict[str, Any] | None:
    data = _read(path, _MAX_JSON_BYTES)
    if data is None:
        return None
    try:
        d = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return None
    return d if isinstance(d, dict) else None


def _glb(vertices_mm: np.ndarray, faces: np.ndarray, corner_uv: np.ndarray, texture: np.ndarray) -> bytes:
    """A GLB (metres, y up, as exported) of a textured mesh for the 3D view."""
    from saucerfab.fabricate.export_glb import glb_bytes
    from saucerfab.fabricate.textured import TexturedMesh

    f = faces.shape[0]
    mesh = TexturedMesh(
        name="saucer",
        vertices=np.asarray(vertices_mm, np.float64),
        faces=np.asarray(faces, np.int64),
        uvs=np.asarray(corner_uv, np.float64).reshape(-1, 2),
        face_uvs=np.arange(3 * f, dtype=np.int64).reshape(f, 3),
        texture_png=_png(texture, VIEWER_TEXTURE_PX),
        texture_px=VIEWER_TEXTURE_PX,
        vertex_rgb=np.zeros((vertices_mm.shape[0], 3), np.uint8),
    )
    return glb_bytes(mesh)


def _viewer_section(glb: bytes, scene: PrintScene, what: str) -> Section:
    from saucerfab.pages.viewer import viewer_html

    return Section(
        f"In 3D: {what}",
        "Drag to orbit, scroll to zoom. The view opens at the design eye; the cup is drawn as a mirror.",
        html=viewer_html(glb, scene),
    )


def _stand(where: dict[str, Any]) -> str:
    from saucerfab.verify.core import stand_sentence

    return stand_sentence(where)


# --------------------------------------------------------------------------- design folder


def _made_for(target: Mapping[str, Any] | None, printable: Mapping[str, Any] | None) -> str:
    """The design's printer and what its relief rules did, in one line (``-`` for older designs)."""
    if not target:
        return "- (made before designs knew their printer)"
    p = printable or {}
    left = int(p.get("thin_crest_vertices", 0)) + int(p.get("thin_wall_crest_vertices", 0))
    return (f"{target.get('printer_name')}: minimum feature {target.get('min_feature_mm')} mm, wall "
            f"{target.get('min_wall_mm')} mm; the optimizer blunted crests on {p.get('projection_active', 0)} of "
            f"{p.get('projection_calls', 0)} trial steps, "
            + ("none is left under them" if not left else f"{left} crest vertices are still under them"))


def design_viewer_section(design: Design, view_d: dict[str, Any] | None = None) -> Section:
    """The orbitable 3D view of a design's saucer top and its mirror cup (the design report's; the studio's viewer).

    Args:
        design: the design.
        view_d: its viewing dict in mm (:func:`saucerfab.fabricate.scene_json.viewing_dict`), when already made.
    """
    from saucerfab.fabricate.scene_file import scene_from_dict
    from saucerfab.fabricate.scene_json import viewing_dict

    s = design.scene.mm_per_unit
    if view_d is None:
        view_d = viewing_dict(design.scene, np.diag([s, s, s, 1.0]))
    # the same parse as a print's scene.json; a design has no solid, so no footprint yet
    scene = scene_from_dict(view_d, "the design's viewing geometry", footprint=False)
    return _viewer_section(
        _glb(design.vertices() * s, design.faces(), design.face_uvs.astype(np.float64), design.texture), scene,
        "the designed saucer top (before it is made a solid) and the cup",
    )


def design_report(design: Design, previews: Mapping[str, bytes], folder: Path | None = None) -> str:
    """The HTML page of a design folder (titled by its input pictures, so it does not depend on the folder's name).

    Args:
        design: the design (as written or loaded).
        previews: PNG bytes by preview file name (``composite.png``...).
        folder: the design folder, when it exists: its ``verify/`` results
            (``saucerfab design``'s quick verify of a trial export) are shown.
    """
    from saucerfab import __version__
    from saucerfab.fabricate.scene_json import viewing_dict

    scene = design.scene
    metrics = design.metrics
    params = design.parameters
    s = scene.mm_per_unit
    m = np.diag([s, s, s, 1.0])
    view_d = viewing_dict(scene, m)
    from saucerfab.verify.core import stand_point

    cam, cup = view_d["camera"]["position"], view_d["cup"]
    where = stand_point(cam, cup["center"], cup["bottom_z"], scene.cup_diameter_mm)

    def pic(name: str) -> bytes | None:
        return previews.get(name)

    inputs = design.inputs
    summary = {
        "direct picture": inputs.get("direct", {}).get("file", "-"),
        "reflected picture": inputs.get("reflected", {}).get("file", "-"),
        **({"second reflected picture": inputs["reflected2"].get("file", "-")} if "reflected2" in inputs else {}),
        "base shape": inputs.get("shape", {}).get("builtin") or inputs.get("shape", {}).get("file", "-"),
        "cup": f"{scene.cup.kind}, {scene.cup_diameter_mm:g} mm wide",
        "saucer": f"{scene.saucer.size[0] * s:.0f} x {scene.saucer.size[1] * s:.0f} mm, relief bound "
                  f"{scene.saucer.delta * s:.2f} mm, {scene.saucer.resolution} x {scene.saucer.resolution} grid",
        "made for": _made_for(params.get("print_target"), metrics.get("printable")),
        "frames": str(params.get("frames", "-")),
        # the method as `saucerfab design` printed it (asked for, and what ran); "ablation" only when it is one
        "method": method_text(params),
        **({"ablation": f"{params['ablation']} (one of the paper's Figure 11 settings)"}
           if params.get("ablation", "full") != "full" else {}),
        "where to stand": _stand(where),
        "max |h - z|": f"{metrics.get('max_abs_height_change', float('nan')) * s:.3f} mm",
        "saucerfab": __version__,
    }
    sections = [Section("Design", table=summary)]
    sections.append(design_viewer_section(design, view_d))
    refs = [(f"{v} picture as meant", _png(img, 512)) for v, img in design.references.items()]
    targets = pic("inputs_targets.png")
    sections.append(Section(
        "Inputs, masks and enhanced targets",
        "Each picture as the design meant it (fitted into its frame, transparency over the background), "
        "its foreground mask, and the black-white target the first stages optimise towards.",
        images=refs + ([("inputs, masks and targets", targets)] if targets else []),
    ))
    views = [(cap, pic(name)) for cap, name in (
        ("what the viewer sees (optimizer's renderer)", "composite.png"),
        ("direct view", "direct_view.png"),
        ("reflected view", "reflected_view.png"),
        ("second reflected view", "reflected2_view.png"),
        ("inputs against results", "side_by_side.png"),
        ("optimised colours against targets", "optimized_colors.png"),
    )]
    sections.append(Section(
        "Views (the optimizer's own renders)",
        "These come from the optimizer's rasterizer. The print's own pictures, ray-traced from the exported "
        "files, are in the report 'saucerfab export' writes beside the print files.",
        images=[(c, b) for c, b in views if b],
    ))
    ver = verify_section(folder, note=(
        "A trial export of this design (OBJ, for the printer named in verify/verify.json), verified right "
        "after the design. ")) if folder is not None else None
    sections.append(ver or Section(
        "Verified: what the print shows",
        "Export the design ('saucerfab export'): the print folder's report.html shows the exported files "
        "ray-traced from the design eye and both eyes. ('saucerfab design' verifies a trial export itself "
        "unless --no-verify.)"))
    hc = pic("height_change.png")
    if hc:
        sections.append(Section("Height change", images=[("|h - z| over the saucer", hc)]))
    en = pic("energies.png")
    rows = [
        # the stage's label says its targets and sigma (the sparse stage's targets are those before it)
        [stage_label(str(st.get("name"))), st.get("iterations"), stop_label(str(st.get("stop_reason"))),
         f"{st.get('E_visual', float('nan')):.1f}", f"{st.get('E_deform', float('nan')):.4f}",
         f"{st['seconds']:.1f}" if "seconds" in st else "-"]
        for st in metrics.get("stages", [])
    ]
    sections.append(Section(
        "Energies and stages",
        images=[("energies over time", en)] if en else [],
        grid=(["stage", "iterations", "stopped", energy_label("E_visual"), energy_label("E_deform"),
               "seconds"], rows),
    ))
    return html_report(sections, title=f"saucerfab design: {design_name(design.inputs)}")


def write_design_report(folder: str | Path) -> Path:
    """Write ``folder/report.html`` for an existing design folder (atomically); returns its path."""
    from saucerfab.files.fileio import write_text_atomic
    from saucerfab.model.design_folder import load_design

    folder = Path(folder)
    previews = {p.name: p.read_bytes() for p in sorted((folder / "previews").glob("*.png"))
                if p.stat().st_size <= _MAX_PICTURE_BYTES}
    return write_text_atomic(folder / REPORT_NAME, design_report(load_design(folder), previews, folder))


def verify_section(folder: Path, *, note: str = "") -> Section | None:
    """The verify results in ``folder/verify/`` (verify.json and its pictures) as a section, or None."""
    from saucerfab.verify.results import SCHEMA

    ver = _json(folder / "verify" / "verify.json")
    if not (ver and ver.get("schema") == SCHEMA):
        return None
    rows, images = [], []
    for f in ver.get("files", []):
        for v in f.get("views", []):
            shift = v.get("shift_px") or [0, 0]
            rows.append([
                Path(str(f.get("path", ""))).name, v.get("view"), v.get("eye"), str(v.get("reference", "")),
                _db(v.get("psnr_db")), "-" if v.get("ssim") is None else f"{v['ssim']:.3f}",
                f"{100 * v.get('coverage', 0):.1f} %",
                "" if v.get("psnr_shift_db") is None else f"{_db(v.get('psnr_shift_db'))} ({shift[0]:+d}, {shift[1]:+d})",
                "pass" if v.get("passed") else "LOW",
            ])
            name = v.get("picture")
            if isinstance(name, str) and "/" not in name and "\\" not in name:
                data = _read(folder / "verify" / name, _MAX_PICTURE_BYTES)
                if data:
                    images.append((f"{Path(str(f.get('path', ''))).name}: {v.get('view')} view, {v.get('eye')} eye",
                                   data))
    whole_rows = []
    for w in ver.get("whole_views") or []:
        if not isinstance(w, Mapping):
            continue
        whole_rows.append([w.get("eye"), _db(w.get("psnr_db")), _pct(w.get("stray_direct")),
                           _pct(w.get("stray_reflected")), _pct(w.get("width_share")),
                           "pass" if w.get("passed") else "STRAY"])
        name = w.get("picture")
        if isinstance(name, str) and "/" not in name and "\\" not in name:
            data = _read(folder / "verify" / name, _MAX_PICTURE_BYTES)
            if data:
                images.append((f"the whole view from the {w.get('eye')} eye: render | ideal | stray (red on the "
                               "saucer, cyan in the mirror)", data))
    lit_text, lit_images = _lit_part(folder, ver)
    images.extend(lit_images)
    r = ver.get("renderer", {})
    whole = ""
    if whole_rows:
        table = "; ".join(f"{row[0]} eye {row[1]} dB, stray {row[2]} on the saucer and {row[3]} in the mirror, "
                          f"the reflected picture {row[4]} of the cup's width" for row in whole_rows)
        whole = (" The whole view (everything of the piece the eye sees, against each picture in its frame and "
                 "its background elsewhere; stray: the share of a frame's surround far from the background, "
                 f"passing at most {_pct(ver.get('max_stray'))}): {table}.")
    return Section(
        "Verified: what the print shows",
        note
        + f"Ray-traced from the exported files with Mitsuba {r.get('version', '?')} ({r.get('variant', '?')}, "
        f"{ver.get('res')} px, {ver.get('spp')} samples per pixel), the cup a perfect mirror, over the pixels "
        "where the saucer is seen (directly, or in the mirror). From the design eye each view is compared with "
        "the input as the design meant it. From a moved eye it is compared with the flat print: that picture "
        "lying flat on the saucer, placed for the design eye, ray-traced from the moved eye, so what any flat "
        "picture does from there (the tilted saucer's perspective, the mirror's distortion) is not counted and "
        "what the print adds (the relief's parallax) is; the last column is the older score against the input "
        "itself after the best whole-picture shift, which even a flat print fails. Pass level "
        f"{ver.get('min_psnr_db')} dB and {100 * float(ver.get('min_coverage', 0)):.0f} % coverage per view: "
        + ("every view passes." if ver.get("passed") else "some views are under it.") + whole + lit_text,
        images=images,
        grid=(["file", "view", "eye", "compared with", "PSNR dB", "SSIM", "coverage", "vs input, shifted dB (px)", ""],
              rows),
    )


def _lit_part(folder: Path, ver: Mapping[str, Any]) -> tuple[str, list[tuple[str, bytes]]]:
    """What ``verify --bleed`` and ``--light`` add to the section: a sentence, and the lit pictures."""
    text, images = "", []
    bleed = ver.get("bleed_mm")
    if isinstance(bleed, (int, float)) and not isinstance(bleed, bool):
        text += f" The colours were blurred as the printer prints them (a colour bleed of {bleed:g} mm)."
    light = ver.get("light")
    if not isinstance(light, Mapping):
        return text, images
    metal = light.get("cup_metal")
    metal_name = metal.get("name") if isinstance(metal, Mapping) else "?"
    lines = []
    for v in ver.get("lit_views") or []:
        if not isinstance(v, Mapping):
            continue
        flat_print = v.get("flat_print_lit_psnr_db")
        beside = f" (a flat print of it {_db(flat_print)} dB)" if isinstance(flat_print, (int, float)) else ""
        label = (f"{v.get('view')} view, {v.get('eye')} eye: {_db(v.get('lit_psnr_db'))} dB under the light{beside}, "
                 f"shading pattern {_db(v.get('shading_pattern_db'))} dB (a flat plate "
                 f"{_db(v.get('flat_pattern_db'))} dB)")
        lines.append(label)
        name = v.get("picture")
        if isinstance(name, str) and "/" not in name and "\\" not in name:
            data = _read(folder / "verify" / name, _MAX_PICTURE_BYTES)
            if data:
                images.append((f"under the {light.get('kind')} light, the cup {metal_name}: {label}", data))
    if lines:
        text += (f" Under the {light.get('kind')} light (the saucer a semi-glossy plastic, the cup {metal_name}; "
                 "each view against its picture under the light's smooth part, and the relief's own shading "
                 "pattern beside a flat plate's; higher is weaker): " + "; ".join(lines) + ".")
    return text, images


def _db(v: object) -> str:
    return "-" if not isinstance(v, (int, float)) else f"{v:.1f}"


def _pct(v: object) -> str:
    """A share (0..1) as a whole percentage, ``-`` when not a number."""
    return "-" if not isinstance(v, (int, float)) or v != v else f"{100 * v:.0f} %"


# --------------------------------------------------------------------------- print folder


def export_report(folder: str | Path) -> str:
    """The HTML page of a print folder (export.json, scene.json, verify/, check.json)."""
    from saucerfab.verify.core import where_to_stand
    from saucerfab.verify.printfolder import (
        find_mesh_files,
        folder_limits,
        load_print_scene,
        read_surface,
    )

    folder = Path(folder)
    summary = _json(folder / "export.json") or {}
    scene = load_print_scene(folder)
    where = where_to_stand(scene)
    bbox = summary.get("bbox_mm") or [float("nan")] * 3
    printer = summary.get("printer", {})
    table = {
        "printer": f"{printer.get('name', '-')} ({printer.get('key', '-')})",
        "part": f"{bbox[0]:.1f} x {bbox[1]:.1f} x {bbox[2]:.1f} mm",
        "cup": f"{scene.cup.shape}, {scene.cup.width_mm:g} mm wide, {scene.cup.height:g} mm mirror height",
        "where to stand": _stand(where),
        "triangles": f"{summary.get('triangles', 0):,}",
        "volume": f"{summary.get('volume_mm3', 0) / 1000:.2f} cm3",
        "texture": f"{summary.get('texture_px', '-')} px",
        "saucerfab": str(summary.get("saucerfab_version", "-")),
    }
    sections = [Section("Print", table=table)]
    files = summary.get("files", {})
    sections.append(Section(
        "Files",
        grid=(["file", "bytes", "sha256"], [[n, f"{d.get('bytes', 0):,}", str(d.get("sha256", ""))[:16]]
                                            for n, d in sorted(files.items())]),
    ))
    ver_section = verify_section(folder)
    if ver_section is None:
        from saucerfab.model.design_folder import reference_name

        why = (f"run 'saucerfab verify {folder.name}'" if (folder / reference_name("direct")).is_file() else
               "the design has no reference pictures (a synthetic design, or one made before 'saucerfab design' "
               "wrote them): design it again from its pictures, then export")
        ver_section = Section("Verified: what the print shows", f"Not verified: {why}.")
    sections.append(ver_section)
    chk = printability_section(_json(folder / "check.json"))
    if chk is not None:
        sections.append(chk)
    meshes = find_mesh_files(folder)
    if meshes:
        fmt, path = meshes[0]
        surf = read_surface(path, fmt, scene, folder_limits(folder))  # the export's own sizes
        tex_id = int(np.max(surf.face_texture)) if surf.face_texture.size else -1
        texture = surf.textures[max(tex_id, 0)] if surf.textures else np.full((1, 1, 3), 200, np.uint8)
        sections.insert(1, _viewer_section(
            _glb(surf.vertices, surf.faces, surf.corner_uv, texture), scene,
            f"{path.name} as read back from the file, with the mirror cup",
        ))
    return html_report(sections, title=print_title(summary, folder))


def print_title(summary: Mapping[str, Any], folder: Path) -> str:
    """A print report's title: the design's pictures and the printer (the folder's name only for an old export.json)."""
    design = summary.get("design")
    inputs = design.get("inputs") if isinstance(design, Mapping) else None
    name = design_name(inputs) if isinstance(inputs, Mapping) else folder.resolve().name
    printer = summary.get("printer")
    made_for = printer.get("name") if isinstance(printer, Mapping) else None
    return f"saucerfab print: {name}" + (f" for {made_for}" if made_for else "")


#: the check's severities, worst first ("error", "warning", "info")
SEVERITIES: tuple[str, ...] = get_args(Severity)


def finding_counts(findings: Iterable[Any]) -> dict[str, int]:
    """How many of a check report's findings (check.json's dicts) have each severity: {"error": n, ...}."""
    counts = dict.fromkeys(SEVERITIES, 0)
    for f in findings:
        sev = f.get("severity") if isinstance(f, Mapping) else None
        if sev in counts:
            counts[sev] += 1
    return counts


def counts_text(counts: Mapping[str, int]) -> str:
    """``0 errors, 0 warnings, 2 info findings`` (``finding_counts``' counts)."""
    e, w, i = (int(counts.get(k, 0)) for k in SEVERITIES)
    return (f"{e} error{'s' if e != 1 else ''}, {w} warning{'s' if w != 1 else ''}, "
            f"{i} info finding{'s' if i != 1 else ''}")


def printability_section(chk: Mapping[str, Any] | None) -> Section | None:
    """check.json (``saucerfab.check/1``) as a section: the verdict with the counts, then every finding as a row.

    Info findings are notes (the units an OBJ assumes, the 3MF reader that read the file), not faults:
    a print with only those is printable, and says so, as the studio does. Each file has a row even
    without findings. None when there is no check.json.
    """
    if not chk or not isinstance(chk.get("files"), list):
        return None
    title = "Printability (saucerfab check)"
    reports = [r for r in chk["files"] if isinstance(r, Mapping)]
    if not reports:
        return Section(title, "Not checked: saucerfab's checker was not available when the print was exported; "
                              "run 'saucerfab check' on the print files.")
    # files outside the print set (other-formats/<name>: formats the printer does not take, written on
    # request and checked without the printer) are listed, but the verdict is the print set's
    in_set = [r for r in reports if "/" not in str(r.get("path", ""))]
    counts = finding_counts(f for r in in_set for f in r.get("findings") or [])
    bad = [r for r in in_set if r.get("verdict") != "printable"]
    n = len(in_set)
    checked = f"{n} file{'s' if n != 1 else ''} checked: {counts_text(counts)}"
    verdict = (f"Printable: every file passes ({checked})." if not bad else
               f"Not printable: {len(bad)} of {n} files fail ({checked}).")
    if len(reports) > n:
        verdict += f" {len(reports) - n} more outside the print set, not for this printer."
    rows = []
    for r in reports:
        name = str(r.get("path", ""))  # relative to the print folder
        found = [f for f in r.get("findings") or [] if isinstance(f, Mapping)]
        rows += [[name, r.get("verdict"), f.get("severity"), f"{f.get('message')} ({f.get('code')})"] for f in found]
        if not found:
            rows.append([name, r.get("verdict"), "-", "no findings"])
    return Section(title, verdict + (" Info findings are notes, not faults." if counts["info"] else ""),
                   grid=(["file", "verdict", "severity", "finding"], rows))


def refresh_export_report(folder: str | Path) -> Path:
    """Write ``folder/report.html`` for a print folder (atomically); returns its path."""
    from saucerfab.files.fileio import write_text_atomic

    folder = Path(folder)
    return write_text_atomic(folder / REPORT_NAME, export_report(folder))
