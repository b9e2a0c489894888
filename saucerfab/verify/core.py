"""``verify_print``: ray-trace an exported print folder and score it against the inputs.

For each rendered file (the first of OBJ, 3MF, GLB in the folder from every
eye; any other of those formats from the design eye, as a cross-check that
the formats print alike), each view (direct, reflected, reflected2) and
each eye (:mod:`.eyes`):

1. render the view from the eye (:class:`~.raytrace.PrintTracer`), keeping
   the frame the design used (same target, same angle);
2. compare with the view's reference picture (the input as the designer
   meant it, resized to the render with a box filter) over the pixels of the
   picture's rectangle in the frame (``scene.json``'s ``extent``: a picture
   keeps its aspect, the square's rest is padding) where the saucer's top is
   seen - directly for the direct view, in the mirror for the reflected
   ones - and only pixels seen fully (coverage >= 0.999);
   the PSNR leaves out the render's own sampling noise (estimated from its
   two halves, :class:`~.raytrace.ViewRender`), so it reads the converged
   render's score at any sample count;
3. from a moved eye the reference is the **flat print** (:mod:`.flatprint`):
   the reference picture lying flat on the saucer, placed for the design
   eye, ray-traced from the moved eye. What any flat picture does from
   there (the tilted saucer's perspective, the mirror's anamorphosis) is in
   both; what the print adds (the relief's parallax, the conflicts) is
   what is scored. The older score is kept beside it: the reference picture
   itself after the best whole-picture shift (:func:`~.metrics.best_shift`,
   up to ``MAX_SHIFT_FRACTION`` of the frame), which no print can pass
   (a perfectly flat print scores 12-25 dB there);
4. coverage is the share of the picture's rectangle the saucer fills in that view;
5. from each eye, the primary file's **whole view** (:mod:`.wholeview`):
   everything of the piece the eye sees, against the ideal whole view (each
   picture in its frame, its background around it), with the stray share of
   each surround and the reflected picture's share of the cup's width.

6. under a real light (``--light room`` or ``lamp:...``, :mod:`.lighting`), the primary
   file's views from the design eye (or every eye: ``lit_eye_choice``) are also rendered with the saucer a plastic and the cup a
   metal, and scored against the reference under the light's smooth part, with the
   strength of the relief's own shading pattern beside a flat plate's (:mod:`.litscore`).
   These scores are reported, not passed or failed.

A view passes when its PSNR is at least ``min_psnr_db`` and its coverage at
least ``min_coverage``; a whole view when both its stray shares are at most
``max_stray``; the folder passes when every view and whole view of every eye does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.errors import ConfigError
from saucerfab.fabricate.scene_file import PrintScene
from saucerfab.imaging.images import recorded_background
from saucerfab.model.design import Intent
from saucerfab.model.eyes import EyeSpec, eye_positions
from saucerfab.verify.lighting import LightSpec, cup_metal, lit_eyes, parse_light
from saucerfab.verify.metrics import best_shift, psnr, ssim
from saucerfab.verify.printfolder import (
    VerifyInputError,
    design_parameters,
    find_mesh_files,
    folder_limits,
    load_print_scene,
    load_references,
    read_surface,
)
from saucerfab.verify.raytrace import FULL_COVERAGE
from saucerfab.verify.results import (
    REFERENCE_FLAT_PRINT,
    REFERENCE_PICTURE,
    FileScore,
    LitViewScore,
    VerifyResult,
    ViewScore,
    WholeViewScore,
)
from saucerfab.verify.wholeview import DEFAULT_MAX_STRAY

if TYPE_CHECKING:
    from saucerfab.verify.litscore import LitViews

#: default pass level per view, dB: a picture at 20 dB is plainly recognisable
#: with visible flaws; graphic designs print at 30 dB and more from the design eye
DEFAULT_MIN_PSNR_DB = 20.0
#: default least share of the picture's rectangle in its frame the saucer must fill in every view
DEFAULT_MIN_COVERAGE = 0.5
DEFAULT_RES = 256
DEFAULT_SPP = 16
#: largest whole-picture shift searched from a moved eye, as a share of the frame
MAX_SHIFT_FRACTION = 0.1
MAX_RES = 2048
MAX_SPP = 1024

#: progress(message, fraction done in [0, 1])
Progress = Callable[[str, float], None]


def where_to_stand(scene: PrintScene) -> dict[str, Any]:
    """The design eye relative to the cup of a print's scene (see :func:`stand_point`)."""
    return stand_point(scene.camera, scene.cup.center, scene.cup.bottom_z, scene.cup.width_mm)


def stand_point(
    eye: tuple[float, float, float] | list[float],
    cup_center: tuple[float, float] | list[float],
    cup_bottom_z: float,
    cup_width_mm: float,
) -> dict[str, Any]:
    """Where the viewer's eye must be, relative to the cup, in millimetres.

    ``distance_mm``: horizontal distance from the cup's axis; ``height_mm``:
    height above the cup's standing plane; ``direction_xy``: the horizontal
    direction from the cup to the eye in the file frame (the saucer lies on
    that side); ``straight_line_mm``: distance from the cup's bottom centre.
    """
    dx, dy, dz = eye[0] - cup_center[0], eye[1] - cup_center[1], eye[2] - cup_bottom_z
    horiz = math.hypot(dx, dy)
    return {
        "distance_mm": round(horiz, 1),
        "height_mm": round(dz, 1),
        "straight_line_mm": round(math.sqrt(horiz**2 + dz**2), 1),
        "direction_xy": [round(dx / horiz, 4), round(dy / horiz, 4)] if horiz > 0 else [0.0, 0.0],
        "cup_width_mm": round(cup_width_mm, 3),
    }


def stand_sentence(w: dict[str, Any]) -> str:
    """``where_to_stand`` as one line for people."""
    return (
        f"eye {w['distance_mm']:.0f} mm from the cup's axis on the saucer's side and {w['height_mm']:.0f} mm above "
        f"the cup's standing plane ({w['straight_line_mm']:.0f} mm from the cup's foot)"
    )


def resize_box(img: np.ndarray, size: int) -> np.ndarray:
    """(S, S, 3) -> (size, size, 3) float32 by pixel-area averaging (the render's box filter)."""
    from PIL import Image

    if img.shape[0] == size:
        return np.asarray(img, np.float32)
    planes = [
        np.asarray(Image.fromarray(np.ascontiguousarray(img[..., c], np.float32)).resize((size, size), Image.Resampling.BOX))
        for c in range(3)
    ]
    return np.clip(np.stack(planes, -1), 0.0, 1.0).astype(np.float32)


def picture_box(mask: np.ndarray) -> tuple[slice, slice]:
    """The rows and columns of (S, S) ``mask``'s bounding box: a picture's rectangle
    (:meth:`~saucerfab.fabricate.scene_file.ViewSpec.picture_mask`) as slices, to crop a frame to the picture."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return slice(None), slice(None)
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _check_levels(res: int, spp: int, min_psnr_db: float, min_coverage: float, max_stray: float = DEFAULT_MAX_STRAY) -> None:
    if isinstance(res, bool) or not isinstance(res, int) or not 16 <= res <= MAX_RES:
        raise ConfigError(f"--res must be an integer in [16, {MAX_RES}] pixels, got {res!r}")
    if isinstance(spp, bool) or not isinstance(spp, int) or not 1 <= spp <= MAX_SPP:
        raise ConfigError(f"--spp must be an integer in [1, {MAX_SPP}], got {spp!r}")
    if not (isinstance(min_psnr_db, (int, float)) and math.isfinite(min_psnr_db)):
        raise ConfigError(f"--min-psnr must be a number of dB, got {min_psnr_db!r}")
    if not (isinstance(min_coverage, (int, float)) and 0 <= min_coverage <= 1):
        raise ConfigError(f"--min-coverage must be a share in [0, 1], got {min_coverage!r}")
    if isinstance(max_stray, bool) or not (isinstance(max_stray, (int, float)) and 0 <= max_stray <= 1):
        raise ConfigError(f"--max-stray must be a share in [0, 1] (the issue's target is 0.05), got {max_stray!r}")


def verify_print(
    folder: str | Path,
    *,
    eyes: EyeSpec | None = None,
    res: int = DEFAULT_RES,
    spp: int = DEFAULT_SPP,
    min_psnr_db: float = DEFAULT_MIN_PSNR_DB,
    min_coverage: float = DEFAULT_MIN_COVERAGE,
    max_stray: float = DEFAULT_MAX_STRAY,
    pictures_dir: str | Path | None = None,
    all_formats: bool = True,
    progress: Progress | None = None,
    light: LightSpec | None = None,
    metal: str | None = None,
    lit_eye_choice: str | None = None,
    lit_seed: int = 0,
    bleed_mm: float | None = None,
) -> VerifyResult:
    """Render the print folder's files and score each view from each eye.

    Args:
        folder: a folder written by ``saucerfab export``.
        eyes: which eyes (default: those the design was made for, when it was made for more than
            the design eye (:class:`saucerfab.model.design.Intent`); else the design eye and a viewer's two eyes).
        res: render size, pixels per side.
        spp: samples per pixel (the colour pass: two halves, :func:`~.raytrace.colour_halves`).
        min_psnr_db, min_coverage: pass levels per view.
        max_stray: highest stray share of either surround a whole view passes with (:mod:`.wholeview`).
        pictures_dir: where to write the side-by-side pictures (created;
            each written atomically); None writes none.
        all_formats: also render the other textured files from the design eye.
        progress: called with (message, fraction done).
        light: what lights the print (:mod:`.lighting`; default: the emitted texture, as
            before). A real light adds each view of the primary file from each eye rendered
            and scored under it (:mod:`.litscore`): ``lit_views`` and ``light`` of the result.
        metal: the cup's metal under that light (:data:`~.lighting.CUP_METALS`; default
            :data:`~.lighting.DEFAULT_LIT_METAL`); refused in emitted light but ``mirror``.
        lit_eye_choice: under a real light, the eyes whose views are rendered lit: ``design`` (the
            default) or ``all`` (:data:`~.lighting.LIT_EYES`).
        bleed_mm: blur every file's textures as a printer with this colour bleed prints them
            (:mod:`.bleed`) before any render; None: the files' colours as written, but for a
            print exported with its bleed compensated, which is blurred by its printer's.
        lit_seed: the lit renders' seed (another seed renders them with other samples: the lit
            scores' own noise, as the benchmark measures it).

    Returns:
        A :class:`VerifyResult`; its ``exit_code`` is 0 when every view passed.

    Raises:
        VerifyInputError: the folder or a file in it cannot be used (exit 2).
        ConfigError: bad options.
    """
    from saucerfab.verify.flatprint import FlatPrints
    from saucerfab.verify.raytrace import INTEGRATOR, PrintTracer, mitsuba, sampling_variance
    from saucerfab.verify.wholeview import WholeViews, background_colours

    t_start = time.perf_counter()
    _check_levels(res, spp, min_psnr_db, min_coverage, max_stray)
    light = light if light is not None else parse_light(None)
    cup = cup_metal(metal, light)
    lit_all = lit_eyes(lit_eye_choice, light) == "all"
    folder = Path(folder)
    if not folder.is_dir():
        raise VerifyInputError(f"{folder} is not a folder; give the folder 'saucerfab export --out' wrote")
    if bleed_mm is None:  # a texture pre-sharpened for the bleed is only right as it prints
        from saucerfab.verify.bleed import compensated_width

        bleed_mm = compensated_width(folder)
    scene = load_print_scene(folder)
    views = list(scene.views)
    full_refs = load_references(folder, views)
    refs = {v: resize_box(img, res) for v, img in full_refs.items()}
    # the flat prints' textures: the reference pictures as the files' textures are stored
    pictures8 = {v: np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8) for v, img in full_refs.items()}
    files = find_mesh_files(folder)
    if not files:
        raise VerifyInputError(
            f"{folder} holds no OBJ, 3MF or GLB file; verify renders textured print files "
            "(export with --formats obj or 3mf)"
        )
    if not all_formats:
        files = files[:1]
    # the eyes the design was made for (an eye box is verified over that box), else the design eye and a viewer's two
    made = design_parameters(folder)  # export.json's record of the design: its eyes and its background
    spec = eyes or Intent.of(made).eyes or EyeSpec()
    all_eyes = eye_positions(spec, scene.camera, scene.views["direct"].target)
    lit_jobs = (len(all_eyes) if lit_all else 1) * len(views) if light.lit else 0
    jobs = len(all_eyes) * (len(views) + 1) + (len(files) - 1) * len(views) + lit_jobs
    done = 0

    def step(msg: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(msg, done / max(jobs, 1))

    mi = mitsuba()
    pictures = Path(pictures_dir) if pictures_dir is not None else None
    if pictures is not None:
        pictures.mkdir(parents=True, exist_ok=True)
    scores: list[FileScore] = []
    wholes: list[WholeViewScore] = []
    lit_scores: list[LitViewScore] = []
    lit: LitViews | None = None
    renders: dict[tuple[str, str], np.ndarray] = {}
    max_shift = round(MAX_SHIFT_FRACTION * res)
    picture_masks = {v: scene.views[v].picture_mask(res) for v in views}  # each picture's rectangle in its frame
    for v, mask in picture_masks.items():
        if not mask.any():
            raise ConfigError(
                f"the {v} picture is a sliver of its frame (scene.json extent {list(scene.views[v].extent)}) and "
                f"holds no pixel centre at --res {res}; verify with a larger --res"
            )
    limits = folder_limits(folder)  # the export's own sizes, within what saucerfab exports
    for k, (fmt, path) in enumerate(files):
        surface = read_surface(path, fmt, scene, limits)
        if bleed_mm is not None:
            from saucerfab.verify.bleed import bleed_surface

            surface = bleed_surface(surface, bleed_mm)
        tracer = PrintTracer(surface, scene.cup)
        fs = FileScore(path, fmt)
        flats: FlatPrints | None = None
        if k == 0:
            whole = WholeViews(tracer, surface, scene, full_refs,
                               background_colours(full_refs, recorded_background(made)), res)
            if light.lit:
                from saucerfab.verify.litscore import LitViews

                lit = LitViews(surface, scene, light, cup, res, spp, seed=lit_seed)
        design_regions: dict[str, np.ndarray] = {}
        for eye in all_eyes if k == 0 else all_eyes[:1]:
            for view in views:
                r = tracer.render(eye.position, scene.views[view], res, spp)
                cov = r.coverage(view)
                # only the picture's rectangle is scored: the square's rest is padding, which may fall off the saucer
                in_picture = picture_masks[view]
                region = (cov >= FULL_COVERAGE) & in_picture
                ref = refs[view]
                noise = sampling_variance(r)  # the render's own noise is not the print's error
                p0 = psnr(r.rgb, ref, region, noise)
                if eye.name == "design":
                    design_regions[view] = region
                    p_shift, sh_dx, sh_dy, p1, reg1, ref1 = float("nan"), 0, 0, p0, region, ref
                    kind = REFERENCE_PICTURE
                else:
                    sh = best_shift(r.rgb, ref, region, max_shift, noise)
                    p_shift, sh_dx, sh_dy = sh.psnr_db, sh.dx, sh.dy
                    if flats is None:
                        flats = FlatPrints(surface, scene.cup, all_eyes[0].position, scene.views, pictures8,
                                           design_regions, res, spp)
                    flat = flats.render_view(view, eye.position, scene.views[view], res, spp)
                    ref1, reg1 = flat.rgb, region & (flat.coverage(view) >= FULL_COVERAGE)
                    p1 = psnr(r.rgb, ref1, reg1, sampling_variance(r, flat))  # two renders' noise, shared in part
                    kind = REFERENCE_FLAT_PRINT
                s = ssim(r.rgb, ref1, reg1)
                coverage = float(cov[in_picture].mean())  # the share of the picture's rectangle the saucer fills
                ok = math.isfinite(p1) and p1 >= min_psnr_db and coverage >= min_coverage
                score = ViewScore(view, eye.name, p1, p0, s, coverage, int(reg1.sum()), (sh_dx, sh_dy), ok,
                                  reference=kind, psnr_shift_db=p_shift)
                if pictures is not None:
                    from saucerfab.verify.pictures import write_view_picture

                    stem = f"{eye.name}_{view}" if k == 0 else f"{fmt}_{eye.name}_{view}"
                    box = picture_box(in_picture)  # the picture as scored, at its own aspect
                    score.picture = write_view_picture(pictures, stem, r.rgb[box], ref1[box], reg1[box], score).name
                if k == 0:
                    renders[(eye.name, view)] = r.rgb
                    renders[(eye.name, view + ":region")] = reg1
                    renders[(eye.name, view + ":reference")] = ref1
                fs.views.append(score)
                step(f"{path.name}: {view} view from the {eye.name} eye {score.psnr_db:.1f} dB")
                if k == 0 and lit is not None and (lit_all or eye is all_eyes[0]):
                    ls = lit.score(eye.name, eye.position, view, scene.views[view], cov >= FULL_COVERAGE, reg1, ref1,
                                   in_picture, pictures, picture_box(in_picture))
                    lit_scores.append(ls)
                    step(f"{path.name}: {view} view from the {eye.name} eye under the {light.kind} light "
                         f"{ls.lit_psnr_db:.1f} dB, shading pattern {ls.shading_pattern_db:.1f} dB")
            if k == 0:
                wholes.append(_whole_view(whole, eye.name, eye.position, spp, max_stray, pictures, renders))
                step(f"{path.name}: the whole view from the {eye.name} eye {wholes[-1].psnr_db:.1f} dB")
        scores.append(fs)
    passed = all(v.passed for f in scores for v in f.views) and all(w.passed for w in wholes)
    return VerifyResult(
        folder=folder,
        files=scores,
        eyes=all_eyes,
        where_to_stand=where_to_stand(scene),
        res=res,
        spp=spp,
        min_psnr_db=float(min_psnr_db),
        min_coverage=float(min_coverage),
        passed=passed,
        seconds=time.perf_counter() - t_start,
        pictures_dir=pictures,
        renderer={"name": "mitsuba", "version": str(mi.__version__), "variant": str(mi.variant()), "integrator": str(INTEGRATOR["type"])},
        renders=renders,
        whole_views=wholes,
        max_stray=float(max_stray),
        light=lit.record() if lit is not None else None,
        lit_views=lit_scores,
        lit_seconds=lit.seconds if lit is not None else float("nan"),
        bleed_mm=bleed_mm,
    )


def _whole_view(whole: Any, eye_name: str, eye: tuple[float, float, float], spp: int, max_stray: float,
                pictures: Path | None, renders: dict[tuple[str, str], np.ndarray]) -> WholeViewScore:
    """Render and score one eye's whole view (:class:`~.wholeview.WholeViews`), write its picture, keep its arrays."""
    wv = whole.render(eye, spp)
    strays = [x for x in (wv.stray_direct, wv.stray_reflected) if math.isfinite(x)]
    score = WholeViewScore(eye_name, wv.psnr_db, wv.stray_direct, wv.stray_reflected, wv.width_share, wv.pixels,
                           wv.surround_pixels(), all(x <= max_stray for x in strays))
    if pictures is not None:
        from saucerfab.verify.pictures import write_whole_picture

        score.picture = write_whole_picture(pictures, f"{eye_name}_whole", wv, score).name
    renders[(eye_name, "whole")] = wv.rgb
    renders[(eye_name, "whole:ideal")] = wv.ideal
    renders[(eye_name, "whole:stray")] = wv.stray
    return score
