"""Design folder -> print-ready files: the one entry point of the fabrication stage.

``export_design`` scales the design to millimetres (the user's cup diameter
overrides the scene's), builds the watertight solid with its cup seat
(:mod:`.solid`), lays out the UV atlas (:mod:`.atlas`), bakes the texture
(:mod:`.bake`), runs the requested exporters (:mod:`.registry`) and writes
the files with ``scene.json`` and an ``export.json`` summary into one folder,
atomically. Everything is checked before the folder is written, so bad
input never leaves a half-written folder.

Reproducible: the same design and options give byte-identical files (no
dates or random names in any file; fixed zip entry dates; canonical mesh
order). Timings are returned, never written.

One export per folder at a time: ``export_design`` replaces the whole folder,
so two exports into it at once would each report files the other then
removes. :func:`export_lock` holds the folder for the length of an export and
whatever reads its files afterwards (``saucerfab export`` holds it over the
export, the check and the verify); a second one fails at once.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab import __version__
from saucerfab.errors import ConfigError, DesignError, ExportError
from saucerfab.fabricate.options import FabOptions
from saucerfab.model.design import Design
from saucerfab.model.design_folder import load_design, reference_name
from saucerfab.model.profiles import DEFAULT_PRINTER, PrinterProfile, load_profile

Progress = Callable[[str, float], None]

#: relative weight of each step for the progress fraction (measured at 150x150 / 4096 px)
_STEPS = {"load": 0.02, "solid": 0.05, "atlas": 0.03, "bake": 0.3, "encode": 0.15, "write": 0.45}


@dataclass
class ExportResult:
    """What ``export_design`` wrote.

    Attributes:
        out: the output folder.
        printer: profile key.
        formats: formats written, in order (the print set's, then :attr:`other_formats`).
        files: format -> paths of its files (e.g. ``obj``: .obj, .mtl, .png).
        scene_json: path of ``scene.json``.
        summary_json: path of ``export.json``.
        triangles: triangles of the solid.
        vertices: vertices of the solid (shared positions).
        volume_mm3: enclosed volume, mm^3.
        bbox_mm: (x, y, z) size of the part, mm.
        texture_px: atlas edge, pixels.
        cup_diameter_mm: the physical cup width used.
        mm_per_unit: millimetres per model unit.
        file_bytes: file name -> size in bytes.
        unseen_fraction: share of the top's texels no viewer sees (inpainted).
        warnings: thin walls/features (under ``warn``), seat notes.
        timings: step -> seconds (not written to any file).
        printer_source: where the printer came from: ``given`` (the caller named it),
            ``design`` (the printer the design was made for) or ``default``
            (the design records none: :data:`~saucerfab.model.profiles.DEFAULT_PRINTER`).
        other_formats: formats the printer does not take, written on request into
            :data:`~saucerfab.fabricate.registry.OTHER_FORMATS_DIR` (outside the print set).
        profile: the printer profile exported for (not in :meth:`to_dict`).
    """

    out: Path
    printer: str
    formats: list[str]
    files: dict[str, list[Path]]
    scene_json: Path
    summary_json: Path
    triangles: int
    vertices: int
    volume_mm3: float
    bbox_mm: tuple[float, float, float]
    texture_px: int
    cup_diameter_mm: float
    mm_per_unit: float
    file_bytes: dict[str, int] = field(default_factory=dict)
    unseen_fraction: float = 0.0
    warnings: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    printer_source: str = "given"
    other_formats: list[str] = field(default_factory=list)
    profile: PrinterProfile | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready), paths as strings."""
        return {
            "out": str(self.out),
            "printer": self.printer,
            "printer_source": self.printer_source,
            "formats": list(self.formats),
            "other_formats": list(self.other_formats),
            "files": {k: [str(p) for p in v] for k, v in self.files.items()},
            "scene_json": str(self.scene_json),
            "summary_json": str(self.summary_json),
            "triangles": self.triangles,
            "vertices": self.vertices,
            "volume_mm3": self.volume_mm3,
            "bbox_mm": list(self.bbox_mm),
            "texture_px": self.texture_px,
            "cup_diameter_mm": self.cup_diameter_mm,
            "mm_per_unit": self.mm_per_unit,
            "file_bytes": dict(self.file_bytes),
            "unseen_fraction": self.unseen_fraction,
            "warnings": list(self.warnings),
            "timings": dict(self.timings),
        }


def export_lock_path(out: str | os.PathLike[str]) -> Path:
    """The lock file of the export folder ``out``: hidden, *beside* it (``.<name>.export.lock``).

    Not inside it: the export replaces the folder whole (a lock file in it
    would go with the old folder, and the next export would lock a new one).
    """
    out = Path(out).resolve()  # one lock however the folder is named (relative, via a link)
    return out.parent / f".{out.name}.export.lock"


@contextlib.contextmanager
def export_lock(out: str | os.PathLike[str]) -> Iterator[None]:
    """Hold the export folder ``out`` for one export; the lock file goes when done.

    Raises:
        ExportError: another export (another process, or another thread of
            this one) is writing ``out``.
    """
    from saucerfab.files.fileio import exclusive_lock

    lock = export_lock_path(out)
    # the lock lives in --out's parent, which may not exist yet: make it, and
    # take away again what was made when the export wrote nothing (bad input)
    made = [p for p in (lock.parent, *lock.parent.parents) if not p.exists()]
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ExportError(f"cannot create the folder of --out {str(out)!r}: {exc.strerror or exc}") from None

    def busy() -> ExportError:
        return ExportError(
            f"another saucerfab export is writing into {str(out)!r} right now; wait for it to finish "
            "or give another --out (two exports into one folder would remove each other's files)"
        )

    try:
        with exclusive_lock(lock, busy, remove=True):
            yield
    except OSError as exc:
        if exc.filename is not None and Path(exc.filename) == lock:
            raise ExportError(f"cannot lock --out {str(out)!r} ({str(lock)!r}): {exc.strerror or exc}") from None
        raise
    finally:
        for p in made:  # innermost first; a folder someone put anything in stays
            try:
                p.rmdir()
            except OSError:
                break


def _resolve_design(design: Design | str | os.PathLike[str]) -> Design:
    if isinstance(design, Design):
        design.validate()
        return design
    path = Path(design)
    if not path.is_dir():
        raise DesignError(f"design folder {str(path)!r} not found; make one with 'saucerfab design'")
    return load_design(path)


#: what :attr:`ExportResult.printer_source` says, in words
PRINTER_SOURCES = {
    "given": "as given",
    "design": "the printer the design was made for",
    "default": "the default printer: the design records none",
}


def export_printer(design: Design, printer: str | PrinterProfile | None) -> tuple[PrinterProfile, str]:
    """The profile to export ``design`` for, and where it came from (a key of :data:`PRINTER_SOURCES`).

    ``printer`` when given; else the printer the design was made for
    (:attr:`Design.intent`'s ``printer``); else :data:`~saucerfab.model.profiles.DEFAULT_PRINTER`.

    Raises:
        ConfigError: an unknown printer, or the design's own printer can no
            longer be loaded (a profile .toml moved away).
    """
    if printer is not None:
        return (printer if isinstance(printer, PrinterProfile) else load_profile(printer)), "given"
    made = design.intent.printer
    if made is None:
        return load_profile(DEFAULT_PRINTER), "default"
    try:
        return load_profile(made), "design"
    except ConfigError:
        raise ConfigError(
            f"the design was made for printer {made!r}, which is not among this installation's profiles "
            "(saucerfab printers); give --printer with a profile name or the profile's .toml path"
        ) from None


def surround_rgb(design: Design, view: str = "direct") -> tuple[int, int, int]:
    """The colour of the surfaces beside a picture by default: the background meant around ``view``'s picture.

    :func:`saucerfab.imaging.images.intended_background` of the design's reference of
    ``view`` and its ``--background``: a viewer sees the seat plate and the
    walls beside the direct picture (the walls' colour, ``view="direct"``), and
    the strip of plate the cup shows under the reflected one (``"reflected"``),
    where the design meant its background (a grey plate read as stray).
    :data:`~saucerfab.fabricate.options.NEUTRAL_WALL_RGB` for a design that
    records neither (a synthetic one).
    """
    from saucerfab.fabricate.options import NEUTRAL_WALL_RGB
    from saucerfab.imaging.images import intended_background, recorded_background

    ref = design.references.get(view)
    picture = None if ref is None else np.asarray(ref, np.float64) / 255.0
    c = intended_background(picture, recorded_background(design.parameters))
    if c is None:
        return NEUTRAL_WALL_RGB
    r, g, b = (int(round(float(v) * 255.0)) for v in np.clip(c, 0.0, 1.0))
    return (r, g, b)


def _resolve_cup(design: Design, cup_diameter_mm: float | None) -> Design:
    if cup_diameter_mm is None:
        return design
    v = cup_diameter_mm
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ConfigError(f"cup diameter must be a positive number of millimetres, got {v!r}")
    from dataclasses import replace

    return replace(design, scene=design.scene.with_changes(cup_diameter_mm=float(v)))


def export_design(
    design: Design | str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    printer: str | PrinterProfile | None = None,
    cup_diameter_mm: float | None = None,
    formats: Sequence[str] | None = None,
    options: FabOptions | None = None,
    progress: Progress | None = None,
    allow_other_formats: bool = False,
) -> ExportResult:
    """Export a design as print-ready files for ``printer``.

    Args:
        design: a :class:`Design` or a design folder.
        out: output folder (created, or replaced if it is a previous export).
        printer: profile key (``j55``), path to a profile TOML, or a profile; None:
            the printer the design was made for (:func:`export_printer`).
        cup_diameter_mm: the real cup's width (circle: diameter; ellipse: 2a;
            prism: 2 x circumradius), mm; None keeps the design's.
        formats: formats to write (keys or aliases of
            :data:`saucerfab.files.formats.WRITERS`); None: the profile's preferred format.
        options: solid, seat and texture settings.
        progress: called with (step name, overall fraction in [0, 1]).
        allow_other_formats: write formats the printer does not take, into
            :data:`~saucerfab.fabricate.registry.OTHER_FORMATS_DIR` (refused otherwise).

    Returns:
        An :class:`ExportResult`.

    Raises:
        DesignError: missing or broken design folder.
        ConfigError: bad cup diameter or options, unknown printer.
        ExportError: unknown format, one the printer does not take (without
            ``allow_other_formats``), part larger than the build volume, over the printer's triangle or file size limit,
            unusable output folder.
        MeshError: the solid cannot be built, or is too thin for a
            ``refuse`` profile.
    """
    from saucerfab.fabricate import registry

    timings: dict[str, float] = {}
    done = 0.0

    def step(name: str, t0: float, weight: float | None = None) -> float:
        """Record a finished step's time and report progress; returns a new start time."""
        nonlocal done
        timings[name] = time.perf_counter() - t0
        done += _STEPS.get(name, 0.0) if weight is None else weight
        if progress is not None:
            progress(name, min(done, 1.0))
        return time.perf_counter()

    t = time.perf_counter()
    opts = options or FabOptions()
    loaded = _resolve_design(design)
    profile, printer_source = export_printer(loaded, printer)
    if isinstance(formats, str):  # "3mf,obj" from a config file or a careless caller
        formats = formats.split(",")
    # one rule: a format the printer does not take is refused, or written outside the print set on request
    print_fmts, other_fmts = registry.normalize_formats(
        [profile.preferred_format] if formats is None else list(formats), profile.accepted_formats, profile.name,
        allow_other=allow_other_formats,
    )
    fmts = print_fmts + other_fmts
    format_warnings = [
        f"{f.upper()} written into {registry.OTHER_FORMATS_DIR}/ at your request (--allow-format): "
        f"{profile.name} does not take it, so it is not part of the print set"
        for f in other_fmts
    ]
    if opts.texture_px is not None and opts.texture_px > profile.max_texture_px:
        raise ExportError(
            f"texture_px {opts.texture_px} exceeds what {profile.name} accepts ({profile.max_texture_px} px)"
        )
    dsg = _resolve_cup(loaded, cup_diameter_mm)
    from dataclasses import replace as _replace

    # recorded resolved in export.json: the colours the files carry
    if opts.mirror_rgb is None:
        opts = _replace(opts, mirror_rgb=surround_rgb(dsg, "reflected") if opts.wall_rgb is None else opts.wall_rgb)
    if opts.wall_rgb is None:
        opts = _replace(opts, wall_rgb=surround_rgb(dsg))
    scene = dsg.scene
    t = step("load", t)

    from saucerfab.fabricate.atlas import TOP_SHARE, build_uvmap, layout_page
    from saucerfab.fabricate.bake import ATLAS_PNG_LEVEL, bake_page, vertex_colors
    from saucerfab.fabricate.scene_json import scene_json_bytes
    from saucerfab.fabricate.sides import balance, paint_sides, side_vertex_colours
    from saucerfab.fabricate.solid import build_solid
    from saucerfab.fabricate.textured import TexturedMesh
    from saucerfab.files.imageio import png_bytes_many

    solid = build_solid(dsg, scene.mm_per_unit, opts, profile)
    bbox = solid.bbox_mm
    if not profile.fits(bbox):
        vol = " x ".join(f"{v:g}" for v in profile.build_volume_mm)
        # a round saucer's size is the design's (its disc); a rectangle's scales with the cup
        fix = (f"design it for this printer (saucerfab design --printer {profile.key} makes the round saucer as "
               "large as it takes) or with a smaller --saucer-diameter-mm" if scene.saucer.is_disc
               else "use a smaller --cup-diameter-mm")
        raise ExportError(
            f"the part is {bbox[0]:.1f} x {bbox[1]:.1f} x {bbox[2]:.1f} mm, larger than "
            f"{profile.name}'s build volume {vol} mm; {fix}"
        )
    ntri = int(solid.faces.shape[0])
    if profile.max_triangles and ntri > profile.max_triangles:
        raise ExportError(f"the part has {ntri} triangles; {profile.name} takes at most {profile.max_triangles}")
    t = step("solid", t)

    (x0, x1), (y0, y1) = solid.footprint
    size_px = opts.texture_px or profile.texture_px_for(max(x1 - x0, y1 - y0) / TOP_SHARE)
    layout = layout_page(size_px, opts.padding_px, solid.grid_x, solid.grid_y, solid.heights)
    uvmap = build_uvmap(solid, layout)
    t = step("atlas", t)

    page, bake_stats = bake_page(dsg, layout, wall_rgb=opts.wall_rgb, inpaint=opts.inpaint)
    vrgb = vertex_colors(solid, uvmap, page, layout, opts.wall_rgb)
    shaded: dict[str, Any] | None = None
    if opts.shading_compensation != "off":  # after the vertex colours, before the bleed: sharpen what prints
        from saucerfab.fabricate.shading import (
            compensate_top_shading,
            face_views,
            light_frame,
        )

        t_shade = time.perf_counter()
        foot, toward = light_frame(solid.model_to_file, scene.camera)
        views = face_views(dsg.face_view, solid.grid_x.size, solid.grid_y.size)
        page, shaded = compensate_top_shading(page, layout, solid.grid_x, solid.grid_y, solid.heights,
                                              opts.shading_compensation, foot, toward, views)
        timings["shading"] = time.perf_counter() - t_shade
    bleed: dict[str, float] | None = None
    if opts.bleed_compensation == "on":  # after the vertex colours: they keep the design's (a cell, not a texel)
        from saucerfab.fabricate.bleed import compensate_top, sigma_px, top_px_per_mm

        t_bleed = time.perf_counter()
        density = top_px_per_mm(layout, solid.grid_x, solid.grid_y, solid.heights)
        bleed = {"sigma_mm": profile.colour_bleed_mm, "px_per_mm": round(density, 6),
                 "sigma_px": round(sigma_px(density, profile.colour_bleed_mm), 6)}
        if profile.colour_bleed_mm > 0:
            page = compensate_top(page, layout, density, profile.colour_bleed_mm)
        else:
            format_warnings.append(
                f"bleed compensation asked for, but {profile.name}'s profile states no colour_bleed_mm: "
                "nothing was compensated (add colour_bleed_mm to the profile)"
            )
        timings["bleed"] = time.perf_counter() - t_bleed
    if opts.mirror_rgb != opts.wall_rgb:  # what the cup shows of the plate: the reflected picture's background
        weight = balance(solid, scene)  # the two surrounds' sizes, once for the page and the vertices
        paint_sides(page, solid, uvmap, scene, opts.mirror_rgb, weight)
        side_vertex_colours(vrgb, solid, scene, opts.mirror_rgb, weight)
    t = step("bake", t)
    # split the step for the benchmark's table: top bake, unseen-area fill, the rest (page, vertex colours)
    timings["inpaint"] = bake_stats["inpaint_s"]
    timings["page"] = (timings["bake"] - bake_stats["bake_s"] - bake_stats["inpaint_s"] - timings.get("bleed", 0.0)
                       - timings.get("shading", 0.0))
    timings["bake"] = bake_stats["bake_s"]
    # the atlas and the reference pictures that travel with the print, encoded side by side
    refs = {reference_name(v): img for v, img in sorted(dsg.references.items())}
    encoded = png_bytes_many({"(atlas)": page, **refs}, ATLAS_PNG_LEVEL)
    png = encoded.pop("(atlas)")  # the rest, the references' files, go into `extra` below
    t = step("encode", t)

    mesh = TexturedMesh(
        name=opts.name,
        vertices=solid.vertices,
        faces=solid.faces,
        uvs=uvmap.uvs,
        face_uvs=uvmap.face_uvs,
        texture_png=png,
        texture_px=size_px,
        vertex_rgb=vrgb,
        decimals=opts.coord_decimals,
    )
    per_format: dict[str, dict[str, bytes]] = {}
    for fmt in fmts:
        files = registry.render(mesh, fmt, opts)
        # a format the printer does not take goes into its own subfolder, with its texture beside it
        per_format[fmt] = {f"{registry.OTHER_FORMATS_DIR}/{n}": d for n, d in files.items()} if fmt in other_fmts else files
        t = step(f"format:{fmt}", t, _STEPS["write"] * 0.8 / len(fmts))

    if profile.max_file_mb:
        for files in per_format.values():
            for name, data in files.items():
                if len(data) > profile.max_file_mb * 1e6:
                    raise ExportError(
                        f"{name} is {len(data) / 1e6:.1f} MB; {profile.name} takes at most "
                        f"{profile.max_file_mb:g} MB (lower --texture-px)"
                    )

    scene_bytes = scene_json_bytes(scene, solid)
    extra = {"scene.json": scene_bytes}
    # the pictures as the design meant them travel with the print, so 'saucerfab verify' needs only this folder
    extra.update(encoded)
    all_files = registry.merge_files(per_format, extra)
    summary = {
        "schema": "saucerfab.export/1",
        "saucerfab_version": __version__,
        "printer": {"key": profile.key, "name": profile.name},
        "formats": print_fmts,
        "other_formats": other_fmts,
        "cup_diameter_mm": scene.cup_diameter_mm,
        "mm_per_unit": scene.mm_per_unit,
        "triangles": ntri,
        "vertices": int(solid.vertices.shape[0]),
        "volume_mm3": round(solid.volume_mm3, 3),
        "bbox_mm": [round(b, 5) for b in bbox],
        "texture_px": size_px,
        "unseen_fraction": round(bake_stats["unseen_fraction"], 6),
        "seat": {"kind": solid.seat.kind, "floor_z_mm": round(solid.seat.floor_z, 6)},
        "options": opts.to_dict(),
        **({} if bleed is None else {"bleed": bleed}),  # only with the compensation on: off writes what it always did
        **({} if shaded is None else {"shading": shaded}),  # likewise
        "warnings": [*format_warnings, *solid.warnings],
        "files": {
            name: {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
            for name, data in sorted(all_files.items())
        },
        "design": {"inputs": dsg.inputs, "parameters": dsg.parameters},
    }
    all_files["export.json"] = (json.dumps(summary, indent=2, sort_keys=True, default=str) + "\n").encode()
    out_path = registry.write_folder(out, all_files)
    step("write", t, _STEPS["write"] * 0.2)

    return ExportResult(
        out=out_path,
        printer=profile.key,
        formats=fmts,
        files={fmt: [out_path / name for name in files] for fmt, files in per_format.items()},
        scene_json=out_path / "scene.json",
        summary_json=out_path / "export.json",
        triangles=ntri,
        vertices=int(solid.vertices.shape[0]),
        volume_mm3=solid.volume_mm3,
        bbox_mm=bbox,
        texture_px=size_px,
        cup_diameter_mm=scene.cup_diameter_mm,
        mm_per_unit=scene.mm_per_unit,
        file_bytes={name: len(data) for name, data in all_files.items()},
        unseen_fraction=bake_stats["unseen_fraction"],
        warnings=[*format_warnings, *solid.warnings],
        timings=timings,
        printer_source=printer_source,
        other_formats=other_fmts,
        profile=profile,
    )
