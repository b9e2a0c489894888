"""What the API shows of a run's files: results of a finished design, an export's findings, the 3D viewer page.

Read-only views of the run folder (``design/``, ``exports/<printer>/``); every
URL points at the API's file route (``/api/runs/{id}/files/{path}``), which
serves only what :data:`SERVED_SUFFIXES` lists, from inside the run folder.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from saucerfab.files.fileio import write_text_atomic

#: the suffixes the file route serves, and their media types
SERVED_SUFFIXES = {
    ".png": "image/png", ".json": "application/json", ".html": "text/html; charset=utf-8",
    ".zip": "application/zip", ".3mf": "model/3mf", ".obj": "text/plain; charset=utf-8",
    ".glb": "model/gltf-binary", ".ply": "application/octet-stream", ".stl": "model/stl",
    ".wrl": "model/vrml", ".mtl": "text/plain; charset=utf-8",
}
#: the design's pictures the results show: API name -> preview file
RESULT_IMAGES = {
    "composite": "composite.png", "direct": "direct_view.png", "reflected": "reflected_view.png",
    "reflected2": "reflected2_view.png", "height_change": "height_change.png",
}
#: the viewer page's cache in the run folder
VIEWER_NAME = "viewer.html"
#: an export's verify under the room light, when asked for (:mod:`saucerfab.studio.lit`), beside its own ``verify/``
LIT_DIR = "verify_room"
#: the figures of a lit view (verify.json's ``lit_views``) the API passes on
LIT_FIELDS = ("view", "eye", "lit_psnr_db", "flat_print_lit_psnr_db", "shading_pattern_db", "flat_pattern_db", "shading_p5", "shading_p95",
              "flat_p5", "flat_p95", "white_level", "gain_rgb")
#: the largest JSON file read for the results, bytes
_MAX_JSON = 8 << 20


def _json(path: Path) -> dict[str, Any] | None:
    try:
        if path.stat().st_size > _MAX_JSON:
            return None
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return d if isinstance(d, dict) else None


def file_url(run_id: str, rel: str) -> str:
    """The API URL of file ``rel`` (posix, relative to the run folder)."""
    return f"/api/runs/{run_id}/files/{rel}"


def verify_rows(run_id: str, folder: Path, rel: str) -> list[dict[str, Any]]:
    """The views of ``folder/verify/verify.json`` (``rel``: that folder relative to the run) with picture URLs."""
    ver = _json(folder / "verify" / "verify.json")
    rows = []
    for f in (ver or {}).get("files", [])[:1]:
        for v in f.get("views", []) if isinstance(f, dict) else []:
            if not isinstance(v, dict):
                continue
            pic = v.get("picture")
            ok = isinstance(pic, str) and "/" not in pic and "\\" not in pic and (folder / "verify" / pic).is_file()
            rows.append({"view": v.get("view"), "eye": v.get("eye"), "reference": v.get("reference"),
                         "psnr_db": v.get("psnr_db"),
                         "coverage": v.get("coverage"), "passed": v.get("passed"),
                         "picture_url": file_url(run_id, f"{rel}/verify/{pic}") if ok else None})
    # the whole view from each eye (verify/3): everything of the piece the eye sees, against the ideal
    for w in (ver or {}).get("whole_views", []):
        if not isinstance(w, dict):
            continue
        pic = w.get("picture")
        ok = isinstance(pic, str) and "/" not in pic and "\\" not in pic and (folder / "verify" / pic).is_file()
        rows.append({"view": "whole", "eye": w.get("eye"), "reference": "whole view", "psnr_db": w.get("psnr_db"),
                     "stray": [w.get("stray_direct"), w.get("stray_reflected")], "width_share": w.get("width_share"),
                     "passed": w.get("passed"),
                     "picture_url": file_url(run_id, f"{rel}/verify/{pic}") if ok else None})
    return rows


def _picture(folder: Path, name: Any) -> bool:
    """Whether ``name`` (from a verify.json) is a bare file name of a picture in ``folder``."""
    return isinstance(name, str) and "/" not in name and "\\" not in name and (folder / name).is_file()


def lit_results(run_id: str, folder: Path, rel: str) -> dict[str, Any] | None:
    """The views of ``folder/verify_room/verify.json`` (``rel``: ``folder`` relative to the run), None if absent.

    Returns ``{"light": kind, "cup_metal": name, "res", "spp", "views": [...]}``, one view per
    ``lit_views`` entry: its figures (:data:`LIT_FIELDS`: lit PSNR and the shading pattern beside a flat
    plate's, dB; the shading's 5th-95th percentile range, x its smooth part; a white print's level)
    with ``lit_picture_url`` (the ``*_lit.png``) and, from the same verify's emitted render of that
    view and eye, ``emitted_psnr_db`` and ``emitted_picture_url``.
    """
    where = folder / LIT_DIR
    ver = _json(where / "verify.json")
    if ver is None or not isinstance(ver.get("light"), dict):
        return None
    emitted: dict[tuple[Any, Any], dict[str, Any]] = {}
    for f in ver.get("files", [])[:1]:
        for v in f.get("views", []) if isinstance(f, dict) else []:
            if isinstance(v, dict):
                emitted[(v.get("view"), v.get("eye"))] = v

    def url(name: Any) -> str | None:
        return file_url(run_id, f"{rel}/{LIT_DIR}/{name}") if _picture(where, name) else None

    views = []
    for lv in ver.get("lit_views", []):
        if not isinstance(lv, dict):
            continue
        ev = emitted.get((lv.get("view"), lv.get("eye")), {})
        views.append({**{k: lv.get(k) for k in LIT_FIELDS}, "lit_picture_url": url(lv.get("picture")),
                      "emitted_psnr_db": ev.get("psnr_db"), "emitted_picture_url": url(ev.get("picture"))})
    light = ver["light"]
    metal = light.get("cup_metal")
    return {"light": light.get("kind"), "cup_metal": metal.get("name") if isinstance(metal, dict) else None,
            "res": ver.get("res"), "spp": ver.get("spp"), "views": views}


def design_results(run_id: str, run_dir: Path) -> dict[str, Any] | None:
    """``results`` of a finished design: pictures, metrics, verify rows, report and viewer URLs (None if not done)."""
    design = run_dir / "design"
    meta = _json(design / "design.json")
    if meta is None:
        return None
    images = {k: file_url(run_id, f"design/previews/{name}") for k, name in RESULT_IMAGES.items()
              if (design / "previews" / name).is_file()}
    m = meta.get("metrics", {}) if isinstance(meta.get("metrics"), dict) else {}
    metrics = {k: m.get(k) for k in ("E_visual_final", "max_abs_height_change", "total_s") if k in m}
    metrics["stages"] = [{k: st.get(k) for k in ("name", "iterations", "E_visual", "E_deform", "stop_reason")}
                         for st in m.get("stages", []) if isinstance(st, dict)]
    enh = meta.get("parameters", {}).get("enhancement_used") if isinstance(meta.get("parameters"), dict) else None
    return {
        "images": images,
        "metrics": metrics,
        "enhancement": enh,
        "verify": verify_rows(run_id, design, "design"),
        "report_url": file_url(run_id, "design/report.html"),
        "viewer_url": f"/api/runs/{run_id}/viewer",
    }


def thumb_url(run_id: str, run_dir: Path, rec: dict[str, Any]) -> str | None:
    """The run's picture in the history: its composite when done, else its latest look, else its direct picture."""
    if (run_dir / "design" / "previews" / "composite.png").is_file():
        return file_url(run_id, "design/previews/composite.png")
    looks = sorted((run_dir / "looks").glob("*_composite.png"), key=lambda p: p.stat().st_mtime) \
        if (run_dir / "looks").is_dir() else []
    if looks:
        return file_url(run_id, f"looks/{looks[-1].name}")
    direct = rec.get("options", {}).get("direct")
    return f"/api/uploads/{direct}/thumb.png" if isinstance(direct, str) else None


def checks_summary(print_folder: Path) -> list[dict[str, Any]]:
    """check.json of a print folder, per file: {file, verdict, printable, counts, findings [{code, severity, message}]}.

    ``counts`` is {"error": n, "warning": n, "info": n} and ``counts_text`` says it in words, as the
    print's report.html does (:func:`saucerfab.pages.folder_pages.finding_counts`).
    """
    from saucerfab.pages.folder_pages import counts_text, finding_counts

    doc = _json(print_folder / "check.json")
    out = []
    for rep in (doc or {}).get("files", []):
        if isinstance(rep, dict):
            findings = [f for f in rep.get("findings", []) if isinstance(f, dict)]
            counts = finding_counts(findings)
            out.append({
                "file": str(rep.get("path", "")), "verdict": rep.get("verdict"),
                "printable": rep.get("verdict") == "printable",
                "counts": counts, "counts_text": counts_text(counts),
                "findings": [{k: f.get(k) for k in ("code", "severity", "message")} for f in findings],
            })
    return out


def export_details(run_id: str, run_dir: Path, printer: str, entry: dict[str, Any]) -> dict[str, Any]:
    """An export's record with its check findings, verify rows and URLs (what GET .../exports/{printer} answers)."""
    out = dict(entry, printer=printer)
    folder = run_dir / "exports" / printer
    if entry.get("status") == "done" and folder.is_dir():
        rel = f"exports/{printer}"
        out["check"] = checks_summary(folder)
        out["verify"] = verify_rows(run_id, folder, rel)
        out["report_url"] = file_url(run_id, f"{rel}/report.html")
        out["zip_url"] = f"/api/runs/{run_id}/exports/{printer}.zip"
        out["file_urls"] = {f: file_url(run_id, f"{rel}/{f}") for f in entry.get("files", [])
                            if Path(f).suffix.lower() in SERVED_SUFFIXES}
        lit = entry.get("lit")
        if isinstance(lit, dict):  # asked for (POST .../lit): its record, and its views once done
            shown = lit_results(run_id, folder, rel) if lit.get("status") == "done" else None
            out["lit"] = {**lit, **(shown or {})}
    return out


def viewer_page(run_dir: Path) -> Path:
    """The run's 3D viewer page (cached as ``viewer.html``, made again when the design is newer); returns its path.

    A bare page for the studio's iframe: only the design report's own view
    (:func:`saucerfab.pages.folder_pages.design_viewer_section`: the designed saucer
    top with its mirror cup, three.js inline, no network), 480 px tall, no
    margins, no headings.
    """
    import html

    from saucerfab.model.design_folder import load_design
    from saucerfab.pages.folder_pages import design_viewer_section
    from saucerfab.pages.labels import design_name

    design_dir = run_dir / "design"
    page = run_dir / VIEWER_NAME
    stamp = (design_dir / "design.json").stat().st_mtime
    if page.is_file() and page.stat().st_mtime >= stamp:
        return page
    design = load_design(design_dir)
    body = design_viewer_section(design).html or ""
    write_text_atomic(page, (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>saucerfab studio 3D: {html.escape(design_name(design.inputs))}</title>"
        "<style>body{margin:0;background:#f0f1f3}.saucer-viewer{margin:0!important}"
        ".saucer-viewer>p{padding:0 .6em .4em}</style></head>\n<body>\n" + body + "\n</body></html>\n"))
    return page
