"""What ``saucerfab verify`` found: scores per view, per file, and the whole result (schema ``saucerfab.verify/3``;
a lit verify adds the optional ``light`` and ``lit_views``).

Plain data with their JSON form; :mod:`.core` makes them, :mod:`.pictures`
titles its pictures with them and the CLI prints them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab import __version__
from saucerfab.model.eyes import Eye

SCHEMA = "saucerfab.verify/3"

#: what a view was compared with: the design eye sees the reference picture itself
REFERENCE_PICTURE = "picture"
#: a moved eye sees the flat print: the picture lying flat on the saucer, seen from that eye (:mod:`.flatprint`)
REFERENCE_FLAT_PRINT = "flat print"


def _num(v: float, nd: int) -> float | None:
    """A finite number rounded for JSON; None for NaN."""
    return None if not math.isfinite(v) else round(float(v), nd)


@dataclass
class ViewScore:
    """One view of one file from one eye.

    Attributes:
        view: ``direct``, ``reflected`` or ``reflected2``.
        eye: the eye's name.
        psnr_db: PSNR against ``reference``, dB; NaN if nothing is seen.
        psnr_unshifted_db: PSNR against the reference picture itself, no shift, dB.
        ssim: mean SSIM against ``reference`` over the compared pixels.
        coverage: share of the picture's rectangle in its frame (``extent``) where the saucer is seen in this view.
        pixels: pixels compared.
        shift_px: (dx, dy) the reference picture was moved (right, down) for ``psnr_shift_db``.
        passed: psnr and coverage at least the levels asked for.
        picture: the side-by-side picture's file name, if written.
        reference: what the render was compared with: :data:`REFERENCE_PICTURE` (the
            design eye) or :data:`REFERENCE_FLAT_PRINT` (a moved eye).
        psnr_shift_db: a moved eye's PSNR against the reference picture after the best
            whole-picture shift (the score before the flat print, which even a perfectly
            flat print fails from a moved eye); NaN from the design eye.
    """

    view: str
    eye: str
    psnr_db: float
    psnr_unshifted_db: float
    ssim: float
    coverage: float
    pixels: int
    shift_px: tuple[int, int]
    passed: bool
    picture: str | None = None
    reference: str = REFERENCE_PICTURE
    psnr_shift_db: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "view": self.view,
            "eye": self.eye,
            "psnr_db": _num(self.psnr_db, 2),
            "psnr_unshifted_db": _num(self.psnr_unshifted_db, 2),
            "ssim": _num(self.ssim, 4),
            "coverage": round(float(self.coverage), 4),
            "pixels": int(self.pixels),
            "shift_px": [int(self.shift_px[0]), int(self.shift_px[1])],
            "passed": bool(self.passed),
            "picture": self.picture,
            "reference": self.reference,
            "psnr_shift_db": _num(self.psnr_shift_db, 2),
        }


@dataclass
class WholeViewScore:
    """The whole view from one eye (:mod:`.wholeview`): everything of the piece that eye sees.

    Attributes:
        eye: the eye's name.
        psnr_db: PSNR against the ideal whole view over the pixels that see the saucer's top, dB.
        stray_direct: share of the saucer seen directly outside the direct frame that is far from
            the direct picture's background (NaN when none is seen there).
        stray_reflected: the same for the mirror's image of the saucer outside the reflected frame.
        width_share: the reflected picture's width over the cup's visible width (same image row).
        pixels: pixels scored; surround_pixels: (direct, mirror) surround pixels.
        passed: both stray shares at most the level asked for.
        picture: the whole-view picture's file name, if written.
    """

    eye: str
    psnr_db: float
    stray_direct: float
    stray_reflected: float
    width_share: float
    pixels: int
    surround_pixels: tuple[int, int]
    passed: bool
    picture: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "eye": self.eye,
            "psnr_db": _num(self.psnr_db, 2),
            "stray_direct": _num(self.stray_direct, 4),
            "stray_reflected": _num(self.stray_reflected, 4),
            "width_share": _num(self.width_share, 4),
            "pixels": int(self.pixels),
            "surround_pixels": [int(self.surround_pixels[0]), int(self.surround_pixels[1])],
            "passed": bool(self.passed),
            "picture": self.picture,
        }


@dataclass
class LitViewScore:
    """One view from one eye under a real light (``verify --light``, :mod:`.litscore`).

    Attributes:
        view, eye: as :class:`ViewScore`.
        lit_psnr_db: PSNR of the lit render against the reference lit by the light's smooth part
            (one best gain per channel), over the emitted score's pixels, dB.
        gain_rgb: that gain per channel: the plastic's colour against the texture's under the
            smooth light (about 0.8-1: the coat's Fresnel loss; the smooth part holds the metal).
        white_level: mean of the white render over the compared pixels (linear, a white paper at the
            cup's foot reads the light's power + ambient): how bright a white print looks in this view
            (a reflected view's, through the cup's metal, about half a direct one's).
        shading_pattern_db: PSNR of 0.5 * white / smooth against 0.5: the relief's own shading on a
            mid-grey picture, dB (higher: weaker pattern).
        shading_p5, shading_p95: 5th and 95th percentiles of white / smooth.
        flat_pattern_db, flat_p5, flat_p95: the same for a flat plate under the same light.
        pixels: pixels compared.
        flat_print_lit_psnr_db: the lit PSNR of a flat print of the same picture under the same light,
            scored the same way (:func:`~.litscore.flat_print`): what a print without relief reaches, dB.
        against_flat_print_psnr_db: PSNR of the lit render against that flat print's, both under the
            light, no gain: how far the relief makes the print look from a flat print, dB.
        picture: the lit picture's file name, if written.
    """

    view: str
    eye: str
    lit_psnr_db: float
    gain_rgb: tuple[float, float, float]
    white_level: float
    shading_pattern_db: float
    shading_p5: float
    shading_p95: float
    flat_pattern_db: float
    flat_p5: float
    flat_p95: float
    pixels: int
    flat_print_lit_psnr_db: float = float("nan")
    against_flat_print_psnr_db: float = float("nan")
    picture: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "view": self.view,
            "eye": self.eye,
            "lit_psnr_db": _num(self.lit_psnr_db, 2),
            "flat_print_lit_psnr_db": _num(self.flat_print_lit_psnr_db, 2),
            "against_flat_print_psnr_db": _num(self.against_flat_print_psnr_db, 2),
            "gain_rgb": [_num(g, 4) for g in self.gain_rgb],
            "white_level": _num(self.white_level, 4),
            "shading_pattern_db": _num(self.shading_pattern_db, 2),
            "shading_p5": _num(self.shading_p5, 4),
            "shading_p95": _num(self.shading_p95, 4),
            "flat_pattern_db": _num(self.flat_pattern_db, 2),
            "flat_p5": _num(self.flat_p5, 4),
            "flat_p95": _num(self.flat_p95, 4),
            "pixels": int(self.pixels),
            "picture": self.picture,
        }


@dataclass
class FileScore:
    """The scores of one rendered file."""

    path: Path
    format: str
    views: list[ViewScore] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        # the file's name: it lies in the verified folder, which may be moved or sent on
        return {"path": self.path.name, "format": self.format, "views": [v.to_dict() for v in self.views]}


@dataclass
class VerifyResult:
    """What :func:`~saucerfab.verify.core.verify_print` found.

    Attributes:
        folder: the print folder.
        files: one entry per rendered file, the primary (fully rendered) first.
        eyes: every eye rendered (the design eye first).
        where_to_stand: the design eye relative to the cup (see :func:`~saucerfab.verify.core.where_to_stand`).
        res, spp: render size (pixels per side) and samples per pixel.
        min_psnr_db, min_coverage: the pass levels.
        passed: every view of every file from every eye passed.
        seconds: wall time of the whole verification.
        pictures_dir: where the pictures were written, or None.
        renderer: name, version and variant of the renderer.
        renders: the primary file's renders for reports and tests: (eye, view) -> (S, S, 3)
            rgb, and (eye, view + ":region") -> (S, S) bool, the pixels compared.
        whole_views: the primary file's whole view from each eye (:mod:`.wholeview`).
        max_stray: the highest stray share a whole view passes with.
        light: under ``verify --light`` other than ``emitted``: the light, the materials and the
            scoring (:meth:`~.litscore.LitViews.record`); None for the emitted verify (no key in the JSON).
        lit_views: the primary file's views under that light, each eye.
        lit_seconds: wall time of the lit renders and scores.
    """

    folder: Path
    files: list[FileScore]
    eyes: list[Eye]
    where_to_stand: dict[str, Any]
    res: int
    spp: int
    min_psnr_db: float
    min_coverage: float
    passed: bool
    seconds: float
    pictures_dir: Path | None
    renderer: dict[str, str]
    renders: dict[tuple[str, str], np.ndarray] = field(default_factory=dict, repr=False)
    whole_views: list[WholeViewScore] = field(default_factory=list)
    max_stray: float = float("nan")
    light: dict[str, Any] | None = None
    lit_views: list[LitViewScore] = field(default_factory=list)
    lit_seconds: float = float("nan")
    bleed_mm: float | None = None

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1

    def score(self, view: str, eye: str = "design") -> ViewScore | None:
        """The primary file's score of ``view`` from ``eye``."""
        for v in self.files[0].views if self.files else []:
            if v.view == view and v.eye == eye:
                return v
        return None

    def to_dict(self, *, record_times: bool = True) -> dict[str, Any]:
        """JSON-ready, schema ``saucerfab.verify/3``; without times when ``record_times`` is False."""
        d = {
            "schema": SCHEMA,
            "saucerfab_version": __version__,
            "folder": str(self.folder),
            "renderer": dict(self.renderer),
            "res": self.res,
            "spp": self.spp,
            "min_psnr_db": self.min_psnr_db,
            "min_coverage": self.min_coverage,
            "passed": self.passed,
            "exit_code": self.exit_code,
            "eyes": [
                {"name": e.name, "position_mm": [round(c, 3) for c in e.position], "offset_mm": list(e.offset_mm)}
                for e in self.eyes
            ],
            "where_to_stand": self.where_to_stand,
            "files": [f.to_dict() for f in self.files],
            "max_stray": _num(self.max_stray, 4),
            "whole_views": [w.to_dict() for w in self.whole_views],
        }
        if self.bleed_mm is not None:  # under --bleed only: a verify without it writes what it always did
            d["bleed_mm"] = self.bleed_mm
        if self.light is not None:  # a lit verify only: the emitted verify's document is as before
            d["light"] = {**self.light, **({"seconds": round(self.lit_seconds, 2)} if record_times else {})}
            d["lit_views"] = [v.to_dict() for v in self.lit_views]
        if record_times:
            d["seconds"] = round(self.seconds, 2)
        return d
